"""The per-sample arithmetic of the online loop, compiled: C when it is built, else numba.

Two entry points, both writing only into arrays the caller allocated once
(:class:`roboisf.online.core.OnlineCompensator`), so a sample or a control cycle allocates
nothing:

:func:`sample_kernel` — one force-sensor sample ``W_s`` (sensor axes, about the sensor origin,
    the load on the tool, N and N·m) at time ``t`` with the robot at joint angles ``q``:
    ``W_c = W_s − tare − G(R_sensor_base)``, the tool's weight ``G`` (mass ``m`` at ``c`` in
    the sensor frame: ``f = m R_sensor_base g``, ``m = c × f``), then a first-order low-pass
    ``y ← y + α (W_c − y)``, ``α = 1 − exp(−2π f_c Δt)`` with the samples' own ``Δt`` (exact
    for any rate; the first sample initialises ``y``).
:func:`cycle_kernel` — one controller cycle at time ``t`` and joint angles ``q``: the filtered
    wrench moved to the tool tip in base axes (``W = blkdiag(R, R) X_ts y``, ``X_ts`` the
    wrench transform sensor → tip, ``R = R_base_tip(q)``), the deflection
    ``δ = J K_θ⁻¹ Jᵀ W + k_tip W`` (robot VJM at ``q`` plus tool and holder, base axes), the
    correction ``c = −R_base_workᵀ δ[:3]`` (work axes, m), then the dead band, the size limit,
    the rate limit and the watchdog (see :class:`roboisf.online.core.Limits`).

The forward kinematics and Jacobian are :func:`roboisf.robot.vjm_chain.chain_jacobian`: the
per-pose chain walk and tip Jacobian the batch kernel :mod:`roboisf.robot.vjm_numba` uses too
(same ``F``, ``sign``, ``offset`` and FANUC J2/J3 coupling ``c23``; tested against
:meth:`RobotModel.deflection` on an ABB and a FANUC preset).

Two compiled forms, the same bits (tests/test_native_online.py): C (``online_kernel.c`` beside
this file — setup.py builds every ``*_kernel.c`` —, built at install, called through
:mod:`roboisf.jit.native`: no numba in the process) when it is built and fresh, else numba
(group "online" of :mod:`roboisf.jit.background`, built at install too); without either the
kernels run as plain Python. The loop calls a kernel per sample and per cycle with the same
arrays each time (the compensator's own buffers): the C form checks a set of arrays once and
keeps their addresses as one block of pointers (:class:`_Arrays`), so a call passes three or
four scalars through ctypes — 1.6 µs a sample and 1.8 µs a cycle against numba's 1.9 and
2.4 µs (its dispatch of seventeen arguments), and no numba import (≈ 0.4 s) before the first.
"""

from __future__ import annotations

import ctypes
import math
import operator
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf import jit
from roboisf.jit import native

__all__ = [
    "COMPILED",
    "N_STATE",
    "STATUS_BAD_INPUT",
    "STATUS_DEADBAND",
    "STATUS_HOLD",
    "STATUS_IMPLAUSIBLE",
    "STATUS_LIMITED",
    "STATUS_NAMES",
    "STATUS_NO_SAMPLE",
    "STATUS_OK",
    "STATUS_RAMP",
    "STATUS_STOP",
    "S_BAD",
    "S_CYCLES",
    "S_HAVE",
    "S_LAST_BAD",
    "S_LAST_CYCLE",
    "S_LAST_SAMPLE",
    "S_STATUS",
    "S_STOP",
    "cycle_kernel",
    "fk_deflection",
    "sample_kernel",
]

F64 = NDArray[np.float64]

# indices into the state vector ``st``
S_HAVE = 0  # 1 once a sample has been filtered
S_LAST_SAMPLE = 1  # time of the last sample [s]
S_LAST_CYCLE = 2  # time of the last cycle [s]
S_STATUS = 3  # status bits of the last cycle
S_CYCLES = 4  # cycles run
S_LAST_BAD = 5  # time of the last implausible sample [s]
S_BAD = 6  # implausible samples rejected
S_STOP = 7  # 1: stopping — the correction ramps to zero whatever the force
N_STATE = 8

# status bits of a cycle (several may be set)
STATUS_OK = 0
STATUS_DEADBAND = 1  # the correction was inside the dead band: zero sent
STATUS_LIMITED = 2  # the size or rate limit cut the correction
STATUS_HOLD = 4  # watchdog: no fresh sample, correction held
STATUS_RAMP = 8  # watchdog: no fresh sample for long, correction ramped towards zero
STATUS_NO_SAMPLE = 16  # no sample yet
STATUS_BAD_INPUT = 32  # non-finite joint angles or wrench: correction held
STATUS_IMPLAUSIBLE = 64  # an implausible force sample within the hold time: correction held
STATUS_STOP = 128  # the loop is stopping: correction ramped to zero
STATUS_NAMES = {
    STATUS_DEADBAND: "deadband",
    STATUS_LIMITED: "limited",
    STATUS_HOLD: "hold",
    STATUS_RAMP: "ramp",
    STATUS_NO_SAMPLE: "no-sample",
    STATUS_BAD_INPUT: "bad-input",
    STATUS_IMPLAUSIBLE: "implausible-force",
    STATUS_STOP: "stopping",
}


_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: The C functions of ``online_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    # F, sign, offset, c23, kinv, q, W, d, R, scr
    "fk_deflection": (None, [_P, _P, _P, _D, _P, _P, _P, _P, _P, _P]),
    # the block of the arrays' addresses (_SAMPLE), c23, cutoff, t → 1 filtered, 0 dropped
    "sample_kernel": (_I, [_P, _D, _D, _D]),
    # the block of the arrays' addresses (_CYCLE), c23, t → the status bits
    "cycle_kernel": (_I, [_P, _D, _D]),
}

#: The name :func:`roboisf.jit.native.library` knows the C form by: its source is
#: ``online_kernel.c`` beside this file (``kernel.c`` would not be built: setup.py and
#: :func:`roboisf.jit.native.extensions` take every ``*_kernel.c``), its library
#: ``_online_kernel_c``.
NATIVE = "roboisf.online.online_kernel"


def _c() -> Any:
    """The C library of this module, or None (the numba kernels, or plain Python, serve)."""
    return native.library(NATIVE, SIGNATURES)


#: the kernels are compiled: their C form is built (:func:`_c`), or numba is installed and
#: built (:func:`roboisf.jit.ready`); else — without either, or on a cold kernel cache while
#: they build in the background — they run as (slower) plain Python, the chain walk too
COMPILED = jit.ready("online")
#: the C form serves (chosen at import; the numba kernels stay its fallback)
_C_FORM = _c() is not None

if COMPILED and jit.HAVE_NUMBA:  # numba's kernels: made (and numba imported) on first call
    from roboisf.robot.vjm_chain import chain_jacobian

    _jit: Callable[[Callable[..., Any]], Callable[..., Any]] = jit.njit(fastmath=False)
    jit.compile_notice(__file__)  # numba compiles these on first call: say so once
else:  # the chain walk as Python too: calling its numba functions would compile them
    chain_jacobian = jit.python_copy("roboisf.robot.vjm_chain").chain_jacobian

    def _jit(f: Callable[..., Any]) -> Callable[..., Any]:
        return f


@_jit
def _fk_deflection(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    q: F64,
    W: F64,
    d: F64,
    R: F64,
    scr: F64,
) -> None:  # pragma: no cover - compiled; tested against RobotModel.deflection
    """One pose: tip rotation ``R`` (3, 3) and robot deflection ``d`` (6,) = J K⁻¹ Jᵀ W.

    ``F`` (7, 4, 4) with the tool folded into ``F[6]``; ``c23`` the FANUC J2/J3 coupling
    (:class:`~roboisf.robot.kinematics.Chain`); ``q`` (6,) rad; ``W`` (6,) [N; N·m], base axes;
    ``scr`` (20, 6) scratch (rows 0–12 used). Base axes, at the tip. The chain walk is
    :func:`roboisf.robot.vjm_chain.chain_jacobian`, the batch kernel's.
    """
    oz = scr[0:6]
    Jl = scr[6:12]
    a = scr[12]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = chain_jacobian(F, sign, offset, c23, q, oz, Jl)
    for k in range(3):  # R_base_tip = R_base_6 · R_6_tip
        R[0, k] = r00 * F[6, 0, k] + r01 * F[6, 1, k] + r02 * F[6, 2, k]
        R[1, k] = r10 * F[6, 0, k] + r11 * F[6, 1, k] + r12 * F[6, 2, k]
        R[2, k] = r20 * F[6, 0, k] + r21 * F[6, 1, k] + r22 * F[6, 2, k]
    for j in range(6):
        tau = 0.0
        for i in range(6):
            tau += Jl[i, j] * W[i]
        a[j] = tau * kinv[j]
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += Jl[i, j] * a[j]
        d[i] = acc


@_jit
def _sample_kernel(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    R_tip_sensor: F64,
    X_ts: F64,
    grav: F64,
    tare: F64,
    plaus: F64,
    cutoff: float,
    t: float,
    W_s: F64,
    q: F64,
    st: F64,
    y: F64,
    scr: F64,
) -> bool:  # pragma: no cover - compiled; tested through OnlineCompensator
    """Filter one sensor sample into ``y`` (6,) (sensor axes, tare and tool weight removed).

    ``grav`` (7,): tool mass [kg], CoG in the sensor frame (3,) [m], gravity in base axes (3,)
    [m/s²]. ``q`` (6,) rad: the latest joint angles (orientation of the sensor). ``X_ts``
    (6, 6): the wrench transform sensor → tip (for the tip moment). ``plaus`` (4,): the
    plausibility bounds (:class:`roboisf.online.core.Plausibility`) — force magnitude [N],
    force band [N] and force rate [N/s] about the filtered force, tip moment [N·m] (inf: off).
    Returns False (sample dropped, filter unchanged) for a non-finite sample or time, a time
    not after the last sample's, or an implausible sample (then ``st[S_LAST_BAD]`` = ``t`` and
    ``st[S_BAD]`` counts it).
    """
    for i in range(6):
        if not math.isfinite(W_s[i]):
            return False
    if not math.isfinite(t) or (st[S_HAVE] > 0 and t <= st[S_LAST_SAMPLE]):
        return False
    W_c = scr[13]
    m = grav[0]
    if m != 0.0:
        R = scr[14:17, 0:3]
        _fk_deflection(F, sign, offset, c23, kinv, q, scr[19], scr[19], R, scr)
        # sensor axes: R_sensor_base = (R_base_tip R_tip_sensor)ᵀ
        for i in range(3):
            acc = 0.0
            for k in range(3):
                rbs = 0.0  # R_base_sensor[k, i]
                for l in range(3):
                    rbs += R[k, l] * R_tip_sensor[l, i]
                acc += rbs * grav[4 + k]
            W_c[i] = m * acc  # weight in sensor axes
        cx, cy, cz = grav[1], grav[2], grav[3]
        fx, fy, fz = W_c[0], W_c[1], W_c[2]
        W_c[3] = cy * fz - cz * fy
        W_c[4] = cz * fx - cx * fz
        W_c[5] = cx * fy - cy * fx
    else:
        for i in range(6):
            W_c[i] = 0.0
    for i in range(6):
        W_c[i] = W_s[i] - tare[i] - W_c[i]
    # plausibility: the force's magnitude, its distance from the filtered force (a band plus
    # the rate bound × the time since the last sample taken), the moment at the tool tip
    f2 = W_c[0] ** 2 + W_c[1] ** 2 + W_c[2] ** 2
    bad = f2 > plaus[0] * plaus[0]
    if st[S_HAVE] > 0 and not bad:
        d2 = (W_c[0] - y[0]) ** 2 + (W_c[1] - y[1]) ** 2 + (W_c[2] - y[2]) ** 2
        allowed = plaus[1]
        if plaus[2] > 0.0 and allowed < math.inf:
            allowed += plaus[2] * (t - st[S_LAST_SAMPLE])
        bad = d2 > allowed * allowed
    if not bad and plaus[3] < math.inf:
        m2 = 0.0
        for i in range(3, 6):
            acc = 0.0
            for k in range(6):
                acc += X_ts[i, k] * W_c[k]
            m2 += acc * acc
        bad = m2 > plaus[3] * plaus[3]
    if bad:
        st[S_BAD] += 1.0
        if not t <= st[S_LAST_BAD]:
            st[S_LAST_BAD] = t
        return False
    if st[S_HAVE] == 0:
        for i in range(6):
            y[i] = W_c[i]
        st[S_HAVE] = 1.0
    else:
        alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff * (t - st[S_LAST_SAMPLE]))
        for i in range(6):
            y[i] += alpha * (W_c[i] - y[i])
    st[S_LAST_SAMPLE] = t
    return True


@_jit
def _cycle_kernel(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    X_ts: F64,
    k_tip: F64,
    R_base_work: F64,
    lim: F64,
    t: float,
    q: F64,
    st: F64,
    y: F64,
    corr: F64,
    W_tip: F64,
    delta: F64,
    scr: F64,
) -> int:  # pragma: no cover - compiled; tested through OnlineCompensator
    """One control cycle: the correction ``corr`` (3,) m, work axes, updated in place.

    ``lim`` (6,): dead band [m], size limit [m], rate limit [m/s], cycle time [s], watchdog
    hold [s], watchdog ramp-down rate [m/s]. Writes the tip wrench ``W_tip`` (6,) and the
    deflection ``delta`` (6,) (base axes) used; returns the status bits.

    The rate limits act per unit of time: a cycle's step is at most ``rate · dt`` (the ramps
    ``ramp · dt``), ``dt`` the time since the last cycle, 0 for a time not after it, at most two
    cycles (one after a gap moves by no more than two cycles' worth; the first by one).
    """
    deadband, size, rate, cycle, hold, ramp = lim[0], lim[1], lim[2], lim[3], lim[4], lim[5]
    status = 0
    tgt = scr[18, 0:3]
    finite_q = True
    for i in range(6):
        if not math.isfinite(q[i]):
            finite_q = False
    age = t - st[S_LAST_SAMPLE]
    dt = t - st[S_LAST_CYCLE] if st[S_LAST_CYCLE] > -math.inf else cycle
    if not dt > 0.0:  # NaN, or not after the last cycle: no step at all
        dt = 0.0
    elif dt > 2.0 * cycle:
        dt = 2.0 * cycle
    step_max = rate * dt
    if st[S_STOP] > 0:
        status |= STATUS_STOP
        step_max = min(step_max, ramp * dt)
        for i in range(3):
            tgt[i] = 0.0
    elif not finite_q or not math.isfinite(t):
        status |= STATUS_BAD_INPUT
        for i in range(3):
            tgt[i] = corr[i]
    elif st[S_HAVE] == 0 or age > hold:
        # watchdog: hold the last correction for ``hold`` s, then ramp it to zero
        status |= STATUS_NO_SAMPLE if st[S_HAVE] == 0 else STATUS_HOLD
        if st[S_HAVE] == 0 or age > 2.0 * hold:
            status |= STATUS_RAMP
            step_max = min(step_max, ramp * dt)
            for i in range(3):
                tgt[i] = 0.0
        else:
            for i in range(3):
                tgt[i] = corr[i]
    elif t - st[S_LAST_BAD] < hold:
        # an implausible sample lately: hold what was sent until the force is plausible again
        status |= STATUS_IMPLAUSIBLE | STATUS_HOLD
        for i in range(3):
            tgt[i] = corr[i]
    else:
        R = scr[14:17, 0:3]
        Wb = scr[17]
        # tip axes: X_ts y; base axes: blkdiag(R, R)
        _fk_deflection(F, sign, offset, c23, kinv, q, scr[19], scr[19], R, scr)  # R only
        for i in range(6):
            acc = 0.0
            for k in range(6):
                acc += X_ts[i, k] * y[k]
            scr[13, i] = acc
        for i in range(3):
            f = 0.0
            mm = 0.0
            for k in range(3):
                f += R[i, k] * scr[13, k]
                mm += R[i, k] * scr[13, 3 + k]
            Wb[i] = f
            Wb[3 + i] = mm
        for i in range(6):
            W_tip[i] = Wb[i]
        _fk_deflection(F, sign, offset, c23, kinv, q, W_tip, delta, R, scr)
        for i in range(6):
            acc = 0.0
            for k in range(6):
                acc += k_tip[i, k] * W_tip[k]
            delta[i] += acc
        nrm = 0.0
        for i in range(3):  # −R_base_workᵀ δ
            acc = 0.0
            for k in range(3):
                acc += R_base_work[k, i] * delta[k]
            tgt[i] = -acc
            nrm += acc * acc
        nrm = math.sqrt(nrm)
        if not math.isfinite(nrm):
            status |= STATUS_BAD_INPUT
            for i in range(3):
                tgt[i] = corr[i]
        elif nrm < deadband:
            status |= STATUS_DEADBAND
            for i in range(3):
                tgt[i] = 0.0
        elif nrm > size:
            status |= STATUS_LIMITED
            for i in range(3):
                tgt[i] *= size / nrm
    # rate limit: the step from the last correction, then the size limit once more (rounding)
    s2 = 0.0
    for i in range(3):
        s2 += (tgt[i] - corr[i]) ** 2
    s = math.sqrt(s2)
    if s > step_max:
        f = step_max / s
        quiet = STATUS_HOLD | STATUS_RAMP | STATUS_NO_SAMPLE | STATUS_BAD_INPUT | STATUS_STOP
        if status & quiet == 0:
            status |= STATUS_LIMITED
        for i in range(3):
            corr[i] += f * (tgt[i] - corr[i])
    else:
        for i in range(3):
            corr[i] = tgt[i]
    n2 = 0.0
    for i in range(3):
        n2 += corr[i] ** 2
    if n2 > size * size:
        f = size / math.sqrt(n2) * (1.0 - 1e-12)
        for i in range(3):
            corr[i] *= f
    if math.isfinite(t) and not t <= st[S_LAST_CYCLE]:
        st[S_LAST_CYCLE] = t
    st[S_STATUS] = status
    st[S_CYCLES] += 1
    return status


#: Sets of arrays whose addresses an :class:`_Arrays` keeps (and so keeps alive): a loop uses
#: one; a test making compensators one after another a few.
_KEEP = 8


class _Arrays:
    """The addresses of a C kernel's array arguments, as one block of pointers made once per set
    of arrays (the compensator's buffers, allocated once): a call with the arrays of the call
    before tests each for identity with :attr:`last` (≈ 0.2 µs for 14: the wrappers do it
    inline), not ``a.ctypes.data`` each (≈ 0.9 µs).

    A set is checked when first seen: ndarrays of the shapes the kernel indexes, float64 in
    native byte order, C-contiguous, aligned, writeable where the kernel writes. A kept set
    holds the arrays themselves, so an address stays theirs (an array's buffer is fixed for its
    life; ``ndarray.resize`` refuses one referenced here). :meth:`address` returns None for a
    set that fails the check: the numba (or Python) form then serves that call, as it did every
    call before the C form.
    """

    def __init__(self, *specs: tuple[tuple[int, ...], bool]) -> None:
        self._specs = specs  # per array: (shape, written by the kernel)
        #: the set of the last call: its arrays, then the block's address, then the block
        self.last: tuple[Any, ...] | None = None
        self._known: dict[tuple[int, ...], tuple[Any, ...]] = {}
        self._lock = threading.Lock()

    def address(self, arrays: tuple[Any, ...]) -> int | None:
        """The address of the block of ``arrays``' data pointers (kept as :attr:`last`), or
        None (not for C)."""
        n = len(arrays)
        key = tuple(map(id, arrays))
        with self._lock:
            entry = self._known.get(key)
            if entry is None or not all(map(operator.is_, arrays, entry[:n])):
                if not all(map(_fits, arrays, self._specs)):
                    return None
                block = (ctypes.c_void_p * n)(*[a.ctypes.data for a in arrays])
                entry = (*arrays, ctypes.addressof(block), block)
                while len(self._known) >= _KEEP:
                    self._known.pop(next(iter(self._known)))
                self._known[key] = entry
            self.last = entry
        return int(entry[n])


_F8 = np.dtype(np.float64)


def _fits(a: Any, spec: tuple[tuple[int, ...], bool]) -> bool:
    """Whether C may take array ``a`` for an argument of ``spec`` (shape, written)."""
    shape, written = spec
    return (
        isinstance(a, np.ndarray)
        and a.dtype == _F8
        and a.shape == shape
        and a.flags.c_contiguous
        and a.flags.aligned
        and (a.flags.writeable or not written)
    )


_V, _M, _J, _S = ((6,), False), ((3, 3), False), ((6, 6), False), ((N_STATE,), True)
_FK = (((7, 4, 4), False), _V, _V, _V)  # F, sign, offset, kinv
#: sample_kernel's arrays: F, sign, offset, kinv, R_tip_sensor, X_ts, grav, tare, plaus, W_s, q,
#: st, y, scr
_SAMPLE = _Arrays(
    *_FK, _M, _J, ((7,), False), _V, ((4,), False), _V, _V, _S, ((6,), True), ((20, 6), True)
)
#: cycle_kernel's arrays: F, sign, offset, kinv, X_ts, k_tip, R_base_work, lim, q, st, y, corr,
#: W_tip, delta, scr
_CYCLE = _Arrays(
    *_FK, _J, _J, _M, _V, _V, _S, _V, ((3,), True), ((6,), True), ((6,), True), ((20, 6), True)
)
#: fk_deflection's arrays: F, sign, offset, kinv, q, W, d, R, scr (not kept: checked per call)
_FK_DEFLECTION = (*_FK, _V, _V, ((6,), True), ((3, 3), True), ((20, 6), True))


def _c_fk_deflection(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    q: F64,
    W: F64,
    d: F64,
    R: F64,
    scr: F64,
) -> None:
    """:func:`fk_deflection` in C (when its library is there and the arrays fit, else numba)."""
    lib = _c()
    arrays = (F, sign, offset, kinv, q, W, d, R, scr)
    if lib is None or not all(map(_fits, arrays, _FK_DEFLECTION)):
        _fk_deflection(F, sign, offset, c23, kinv, q, W, d, R, scr)
        return
    p = [a.ctypes.data for a in arrays]
    lib.fk_deflection(p[0], p[1], p[2], c23, *p[3:])


def _c_sample_kernel(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    R_tip_sensor: F64,
    X_ts: F64,
    grav: F64,
    tare: F64,
    plaus: F64,
    cutoff: float,
    t: float,
    W_s: F64,
    q: F64,
    st: F64,
    y: F64,
    scr: F64,
) -> bool:
    """:func:`sample_kernel` in C (when its library is there and the arrays fit, else numba)."""
    lib = _c()
    if lib is not None:
        k = _SAMPLE.last
        if (
            k is not None and F is k[0] and sign is k[1] and offset is k[2] and kinv is k[3]
            and R_tip_sensor is k[4] and X_ts is k[5] and grav is k[6] and tare is k[7]
            and plaus is k[8] and W_s is k[9] and q is k[10] and st is k[11] and y is k[12]
            and scr is k[13]
        ):  # fmt: skip
            block = k[14]  # the arrays of the call before (each call of the loop's)
        else:
            block = _SAMPLE.address(
                (F, sign, offset, kinv, R_tip_sensor, X_ts, grav, tare, plaus, W_s, q, st, y, scr)
            )
        if block is not None:
            return lib.sample_kernel(block, c23, cutoff, t) != 0
    return bool(
        _sample_kernel(
            F,
            sign,
            offset,
            c23,
            kinv,
            R_tip_sensor,
            X_ts,
            grav,
            tare,
            plaus,
            cutoff,
            t,
            W_s,
            q,
            st,
            y,
            scr,
        )
    )


def _c_cycle_kernel(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    X_ts: F64,
    k_tip: F64,
    R_base_work: F64,
    lim: F64,
    t: float,
    q: F64,
    st: F64,
    y: F64,
    corr: F64,
    W_tip: F64,
    delta: F64,
    scr: F64,
) -> int:
    """:func:`cycle_kernel` in C (when its library is there and the arrays fit, else numba)."""
    lib = _c()
    if lib is not None:
        k = _CYCLE.last
        if (
            k is not None and F is k[0] and sign is k[1] and offset is k[2] and kinv is k[3]
            and X_ts is k[4] and k_tip is k[5] and R_base_work is k[6] and lim is k[7]
            and q is k[8] and st is k[9] and y is k[10] and corr is k[11] and W_tip is k[12]
            and delta is k[13] and scr is k[14]
        ):  # fmt: skip
            block = k[15]  # the arrays of the call before (each call of the loop's)
        else:
            block = _CYCLE.address(
                (F, sign, offset, kinv, X_ts, k_tip, R_base_work, lim, q, st, y, corr, W_tip,
                 delta, scr)
            )  # fmt: skip
        if block is not None:
            return int(lib.cycle_kernel(block, c23, t))
    return int(
        _cycle_kernel(
            F,
            sign,
            offset,
            c23,
            kinv,
            X_ts,
            k_tip,
            R_base_work,
            lim,
            t,
            q,
            st,
            y,
            corr,
            W_tip,
            delta,
            scr,
        )
    )


# the public names: the C wrappers when the C form serves (each with the numba kernel's
# docstring, and its Python function as ``py_func``, as a numba kernel has), else the numba
# kernels (or the plain Python functions) themselves, as before the C form
fk_deflection: Callable[..., None] = _fk_deflection
sample_kernel: Callable[..., bool] = _sample_kernel
cycle_kernel: Callable[..., int] = _cycle_kernel
if _C_FORM:
    for _wrapper, _kernel in (
        (_c_fk_deflection, _fk_deflection),
        (_c_sample_kernel, _sample_kernel),
        (_c_cycle_kernel, _cycle_kernel),
    ):
        _wrapper.__doc__ = _kernel.__doc__
        vars(_wrapper)["py_func"] = getattr(_kernel, "py_func", _kernel)
    fk_deflection, sample_kernel, cycle_kernel = _c_fk_deflection, _c_sample_kernel, _c_cycle_kernel


def build() -> None:
    """Compile (and so cache) these kernels through their caller, one sample and one cycle of a
    compensator on a preset robot: the background builder of :mod:`roboisf.jit.background`
    (group "online")."""
    from roboisf.online.core import OnlineCompensator
    from roboisf.robot.presets import list_robots, load_robot

    robot = next(m for m in map(load_robot, list_robots()) if m.stiffness is not None)
    T = robot.default_placement if robot.default_placement is not None else np.eye(4)
    OnlineCompensator(robot, T, np.eye(6) * 1e-7).warm_up()
