"""Fused, chunked VJM evaluation: FK → tip Jacobian → ``τ = JᵀW`` → ``δ = J K⁻¹ τ`` (→ ``k_c``).

One entry point, :func:`vjm_eval`, behind :meth:`RobotModel.deflection`,
:meth:`RobotModel.compliance`, :func:`roboisf.robot.vjm_batch` and ``roboisf.plan``. Two engines
give the same numbers (≤ 1e-14 relative, tested on every preset):

``"numba"`` (the default: the compiled engine)
    one compiled loop over the poses that walks the chain of
    :mod:`roboisf.robot.kinematics` (seven fixed transforms ``F_0 .. F_6``, the tool folded into
    ``F_6``; ``θ = sign·q + offset``) in scalar registers and writes only the results: no
    temporary arrays. Called from the main thread it runs on every core: chunks of whole
    blocks of 1,024 poses (about four per core) on a thread pool
    (:func:`roboisf.jit.run_chunks`; the kernel releases the GIL); called from any other thread
    (a Dask worker, a thread pool) the same loop runs serially without the GIL, so the caller's
    own parallelism is not oversubscribed. Two compiled forms of it, the same bits: C
    (``vjm_kernel.c``, built at install, called through :mod:`roboisf.jit.native` — no numba in
    the process; it also holds :func:`roboisf.robot.fk_numba.tip_positions`' pass, the IK of
    :mod:`roboisf.robot.ik_numba` and the margin test of
    :func:`roboisf.robot.singularity.margin_ok`) when it is
    built and fresh (:func:`use_c`), else numba (:mod:`roboisf.robot.vjm_numba`, imported — so
    numba too — only on first use, compiled then and cached on disk, ``cache=True``).
``"numpy"``
    the vectorised closed-form / chain-walk Jacobian of :mod:`roboisf.robot.kinematics` on
    chunks of :data:`CHUNK` poses (memory bounded by the chunk), ~3× slower.

``backend="auto"`` picks the C form when it is built, else numba when it is importable and its
kernels are cached (:func:`use_numba`). No BLAS call is made by either engine;
:func:`single_blas_thread` pins OpenBLAS/MKL to one thread for batched numpy work that is
already parallel (the plan's placements).
"""

from __future__ import annotations

import ctypes
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from roboisf import jit
from roboisf.errors import InputError
from roboisf.jit import native, run_chunks
from roboisf.progress import Progress, task

__all__ = [
    "BACKENDS",
    "CHUNK",
    "HAVE_NUMBA",
    "VJMResult",
    "check_backend",
    "margin_c",
    "margin_numpy",
    "single_blas_thread",
    "use_c",
    "use_numba",
    "vjm_eval",
]

F64 = NDArray[np.float64]


#: numba is installed (imported only when the compiled engine is first used).
HAVE_NUMBA = jit.HAVE_NUMBA

#: Engines accepted by ``backend=``.
BACKENDS = jit.BACKENDS
#: Poses per chunk of the numpy engine (its temporaries stay in cache).
CHUNK = 4096
#: Poses per kernel call (progress is reported between calls).
_CALL = 1 << 20


_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: The C functions of ``vjm_kernel.c`` (:func:`roboisf.jit.native.library`): ``fk_rows`` is
#: :func:`roboisf.robot.fk_numba._rows`, ``vjm_rows`` :func:`roboisf.robot.vjm_numba._rows`,
#: ``margin_rows`` :func:`roboisf.robot.vjm_numba._margin_rows`; ``flange_rows``, ``tip_rows``,
#: ``continuous`` and ``path_vjm_rows`` the kernels of :mod:`roboisf.robot.ik_numba`.
SIGNATURES: dict[str, native.Signature] = {
    # F, sign, offset, c23, T, q, out, s, e
    "fk_rows": (None, [_P, _P, _P, _D, _P, _P, _P, _I, _I]),
    # F, sign, offset, c23, kinv, q, W, one_w, s, e, d, k, J, margin, ok
    "vjm_rows": (None, [_P, _P, _P, _D, _P, _P, _P, _I, _I, _I, _P, _P, _P, _P, _P]),
    # the IK of roboisf.robot.ik_numba: _flange_rows, _tip_rows, _continuous, _vjm_rows
    # T, geo, flags, sign, offset, c23, q, ok, s, e
    "flange_rows": (None, [_P, _P, _P, _P, _P, _D, _P, _P, _I, _I]),
    # A, B, tip, gam, n_gam, geo, flags, sign, offset, c23, q, ok, T_tip, s, e
    "tip_rows": (None, [_P, _P, _P, _P, _I, _P, _P, _P, _P, _D, _P, _P, _P, _I, _I]),
    # q, n, q_min, q_max → all within the limits (0/1)
    "continuous": (ctypes.c_int64, [_P, _I, _P, _P]),
    # F, sign, offset, c23, kinv, q, W_work, n_w, A, C_tool, gam, n_gam, margin, rb, W_base, d,
    # margin_ok, d_robot, d_total, abs_total, steps, nrm, abs_robot, abs_normal, s, e
    "path_vjm_rows": (
        None,
        [_P, _P, _P, _D, _P, _P, _P, _I, _P, _P, _P, _I, _P, _D, *[_P] * 10, _I, _I],
    ),
    # ik_numba._atan2_many (y, x, out, n) and _wrap_many (x, out, n), for the tests
    "atan2_many": (None, [_P, _P, _P, _I]),
    "wrap_many": (None, [_P, _P, _I]),
    # vjm_numba._margin_rows: Js, lin_scale, c, ok, s, e
    "margin_rows": (None, [_P, _D, _D, _P, _I, _I]),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


def use_c(backend: str) -> bool:
    """True when ``backend`` ("auto", "numba" or "numpy") asks for the compiled engine and its
    C form is built and fresh: no numba, no :func:`roboisf.jit.ready` (group "robot" lists no
    C form, so asking it checks numba's cache) and no background builder. The C form serves
    every kernel of the group: the FK and VJM passes, the IK and the margin test."""
    return check_backend(backend) != "numpy" and _c() is not None


def check_backend(backend: str, field: str = "backend") -> str:
    """Validate a ``backend`` name; ``"numba"`` needs numba installed."""
    return jit.check_backend(backend, field=field, have_numba=HAVE_NUMBA)


def use_numba(backend: str) -> bool:
    """True when ``backend`` ("auto", "numba" or "numpy") resolves to the numba engine (the
    callers of the C form ask :func:`use_c` first).

    The first time, imports :mod:`roboisf.robot.vjm_numba`; if numba is installed but fails to
    import, "auto" falls back to numpy and "numba" is an :class:`InputError` saying why. While
    the compiled kernels are not cached yet, "auto" resolves to numpy and starts their build in
    a background process (:func:`roboisf.jit.ready`, group "robot"): no first run waits for the
    compiler.
    """
    global HAVE_NUMBA
    if check_backend(backend) == "numpy" or not HAVE_NUMBA:
        return False
    if backend == "auto":
        if not jit.ready("robot"):  # not built yet: numpy serves, a background process builds
            return False
    try:
        import roboisf.robot.vjm_numba  # noqa: F401
    except ImportError as e:  # pragma: no cover - a broken numba install
        if backend == "numba":
            raise InputError(
                f"backend 'numba': numba fails to import ({e})", field="backend"
            ) from None
        HAVE_NUMBA = False
        return False
    return True


class VJMResult(NamedTuple):
    """What :func:`vjm_eval` computed (base axes, at the tip); None where not asked.

    d : (N, 6) [m; rad] — deflection ``J K⁻¹ Jᵀ W``
    k : (N, 6, 6) or None — compliance ``J K⁻¹ Jᵀ``
    J : (N, 6, 6) or None — tip Jacobian
    margin_ok : (N,) bool or None — ``σ_min(J_s) > threshold`` (exact elimination test of
        :func:`roboisf.robot.singularity.margin_ok`)
    """

    d: F64
    k: F64 | None
    J: F64 | None
    margin_ok: NDArray[np.bool_] | None


def vjm_eval(
    F_tip: F64,
    sign: F64,
    offset: F64,
    kinv: F64,
    q: F64,
    W: F64,
    jacobian: Callable[[F64], F64],
    *,
    want_compliance: bool = False,
    want_jacobian: bool = False,
    margin: tuple[float, float] | None = None,
    backend: str = "auto",
    chunk: int = CHUNK,
    progress: Progress | None = None,
    label: str = "VJM deflection",
    couple23: float = 0.0,
) -> VJMResult:
    """δ (N, 6), and k_c, J, the singularity-margin test when asked, for validated inputs.

    F_tip : (7, 4, 4) — the chain's fixed transforms with ``T_flange_tip`` folded into the last
    sign, offset : (6,) — ``θ = sign·q + offset``
    kinv : (6,) rad/(N·m) — ``1 / K_θ``
    q : (N, 6) rad (already checked); W : (N, 6) [N; N·m], or a (N, 6) broadcast of one wrench
    jacobian : the numpy engine's Jacobian of a chunk of angles (m, 6) → (m, 6, 6)
    margin : (length scale (m), threshold) — test ``σ_min(J_s) > threshold`` per pose, ``J_s``
        the Jacobian with its linear rows divided by the length scale
    chunk : poses per chunk of the numpy engine (bounds its temporaries)
    couple23 : FANUC J2/J3 coupling of the chain (:class:`~roboisf.robot.kinematics.Chain`);
        the numpy engine's ``jacobian`` includes it already
    """
    if chunk < 1:
        raise InputError(f"chunk must be ≥ 1, got {chunk}", field="chunk")
    if margin is not None and not (
        math.isfinite(margin[0]) and margin[0] > 0 and math.isfinite(margin[1]) and margin[1] >= 0
    ):
        raise InputError(
            f"singularity margin needs a length scale > 0 m and a threshold ≥ 0, got {margin}",
            field="margin",
        )
    n = q.shape[0]
    d = np.empty((n, 6))
    k = np.empty((n, 6, 6)) if want_compliance else None
    J = np.empty((n, 6, 6)) if want_jacobian else None
    ok = None if margin is None else np.empty(n, dtype=np.bool_)
    lin_scale, c = (1.0, 0.0) if margin is None else (1.0 / margin[0], float(margin[1]) ** 2)
    if use_c(backend):
        rows = _c_rows(
            F_tip, sign, offset, kinv, q, W, float(couple23), (lin_scale, c), d, k, J, ok
        )
        with task(progress, label, n) as advance:
            for s in range(0, n, _CALL):
                e = min(n, s + _CALL)
                rows(s, e)
                advance(e - s)
        return VJMResult(d, k, J, ok)
    if use_numba(backend):
        from roboisf.robot import vjm_numba as nb

        one = W.strides[0] == 0 or n == 0
        Wc = nb._c64(W[:1] if one else W)
        qc = nb._c64(q)
        args = (nb._c64(F_tip), nb._c64(sign), nb._c64(offset), float(couple23), nb._c64(kinv))
        kern = nb.kernel()
        none = np.empty((0, 6, 6))
        no_ok = np.empty(0, dtype=np.bool_)
        mg = np.array([lin_scale, c])
        with task(progress, label, n) as advance:
            for s in range(0, n, _CALL):
                e = min(n, s + _CALL)
                kern(
                    *args,
                    qc[s:e],
                    Wc if one else Wc[s:e],
                    d[s:e],
                    none if k is None else k[s:e],
                    none if J is None else J[s:e],
                    mg,
                    no_ok if ok is None else ok[s:e],
                )
                advance(e - s)
        return VJMResult(d, k, J, ok)
    with task(progress, label, n) as advance:
        for s in range(0, n, chunk):
            e = min(n, s + chunk)
            Jc = jacobian(q[s:e])
            _numpy_chunk(Jc, W[s:e], kinv, d[s:e], None if k is None else k[s:e])
            if J is not None:
                J[s:e] = Jc
            if ok is not None:
                Js = Jc.copy()
                Js[:, :3] *= lin_scale
                ok[s:e] = margin_numpy(Js, c)
            advance(e - s)
    return VJMResult(d, k, J, ok)


def _c_rows(
    F_tip: F64,
    sign: F64,
    offset: F64,
    kinv: F64,
    q: F64,
    W: F64,
    c23: float,
    margin: tuple[float, float],
    d: F64,
    k: F64 | None,
    J: F64 | None,
    ok: NDArray[np.bool_] | None,
) -> Callable[[int, int], None]:
    """The C form of the numba engine's kernel call: ``rows(s, e)`` writes poses ``s:e`` of
    ``d``, ``k``, ``J``, ``ok`` (allocated by :func:`vjm_eval`: C-contiguous, N rows) — on every
    core from the main thread, in the calling thread from any other (as
    :func:`roboisf.robot.vjm_numba.kernel`), in chunks of :func:`~roboisf.robot.vjm_numba.chunk`
    poses (the rows are independent: the chunks do not change the numbers)."""
    from roboisf.robot.vjm_numba import _c64, chunk  # helpers only: numba is not imported

    lib = _c()
    n = q.shape[0]
    one = W.strides[0] == 0 or n == 0 or W.shape[0] == 1  # one wrench for every pose
    Wc = _c64(W[:1] if one else W)
    qc = _c64(q)
    F, sg, of, kv = (_c64(a) for a in (F_tip, sign, offset, kinv))
    mg = np.array(margin, dtype=np.float64)
    if (
        F.shape != (7, 4, 4)
        or sg.shape != (6,)
        or of.shape != (6,)
        or kv.shape != (6,)
        or qc.shape != (n, 6)
        or Wc.ndim != 2
        or Wc.shape[1] != 6
        or Wc.shape[0] < (min(n, 1) if one else n)
    ):
        raise ValueError(
            f"vjm_eval: F (7, 4, 4), sign/offset/kinv (6,), q (N, 6), W (N or 1, 6) expected, "
            f"got {F.shape}, {sg.shape}, {of.shape}, {kv.shape}, {qc.shape}, {W.shape}"
        )
    for a, shape, dtype in (
        (d, (n, 6), np.float64),
        (k, (n, 6, 6), np.float64),
        (J, (n, 6, 6), np.float64),
        (ok, (n,), np.bool_),  # one byte, 0 or 1
    ):
        if a is not None and not (
            a.shape == shape and a.dtype == dtype and a.flags.c_contiguous and a.flags.writeable
        ):
            raise ValueError(f"vjm_eval: output {shape} {dtype.__name__} C-contiguous expected")
    c23 = float(c23)
    one_w = int(one)

    def span(s: int, e: int) -> None:
        # the pointers taken here, from arrays this closure holds: alive during the call
        lib.vjm_rows(
            F.ctypes.data,
            sg.ctypes.data,
            of.ctypes.data,
            c23,
            kv.ctypes.data,
            qc.ctypes.data,
            Wc.ctypes.data,
            one_w,
            s,
            e,
            d.ctypes.data,
            None if k is None else k.ctypes.data,
            None if J is None else J.ctypes.data,
            mg.ctypes.data,
            None if ok is None else ok.ctypes.data,
        )

    def rows(s: int, e: int) -> None:
        run_chunks(lambda a, b: span(s + a, s + b), e - s, chunk(e - s), any_thread=False)

    return rows


def margin_c(Js: F64, lin_scale: float, c: float) -> NDArray[np.bool_]:
    """:func:`roboisf.robot.vjm_numba.margin_numba` in C (``margin_rows``; :func:`use_c` is
    true): the margin test of Jacobians (N, 6, 6), chunked as that one."""
    from roboisf.robot.vjm_numba import _c64, chunk  # helpers only: numba is not imported

    lib = _c()
    Jc = _c64(Js)
    if Jc.ndim != 3 or Jc.shape[1:] != (6, 6):
        raise ValueError(f"margin: Jacobians (N, 6, 6) expected, got {Jc.shape}")
    n = Jc.shape[0]
    ok = np.empty(n, dtype=np.bool_)
    ls, cc = float(lin_scale), float(c)
    run_chunks(
        lambda s, e: lib.margin_rows(Jc.ctypes.data, ls, cc, ok.ctypes.data, s, e),
        n,
        chunk(n),
        any_thread=False,
    )
    return ok


def margin_numpy(Js: F64, c: float) -> NDArray[np.bool_]:
    """The elimination of :func:`margin_pivots_ok` vectorised over scaled Jacobians (N, 6, 6):
    component-major arrays, no per-pose LAPACK call."""
    Jt = np.ascontiguousarray(Js.transpose(1, 2, 0))  # (6 rows, 6 cols, N)
    n = Js.shape[0]
    M = np.empty((6, 6, n))
    for i in range(6):
        for j in range(i, 6):
            v = np.einsum("kn,kn->n", Jt[:, i], Jt[:, j])
            M[i, j] = v
            M[j, i] = v
    for i in range(6):
        M[i, i] -= c
    ok = np.ones(n, dtype=bool)
    for p in range(6):
        piv = M[p, p]
        ok &= piv > 0.0
        if p == 5:
            break
        inv = 1.0 / np.where(piv > 0.0, piv, 1.0)
        lk = M[p + 1 :, p] * inv  # (m, N)
        M[p + 1 :, p + 1 :] -= lk[:, None, :] * M[p, p + 1 :][None, :, :]
    return ok


def _numpy_chunk(J: F64, W: F64, kinv: F64, d: F64, k: F64 | None) -> None:
    """One chunk of the numpy engine: δ into ``d`` (m, 6), k_c into ``k`` (m, 6, 6) if given."""
    Jt = np.ascontiguousarray(J.transpose(1, 2, 0))  # (6, 6, m) component-major
    A = Jt * kinv[None, :, None]
    tau = np.einsum("ain,an->in", Jt, W.T)
    d[:] = np.einsum("ain,in->na", A, tau)
    if k is not None:
        kt = np.empty((6, 6, J.shape[0]))
        for a in range(6):
            for b in range(a, 6):
                v = kt[a, b]
                np.einsum("in,in->n", A[a], Jt[b], out=v)
                if a != b:
                    kt[b, a] = v
        k[:] = kt.transpose(2, 0, 1)


_CONTROLLER: list[tuple[int, Any]] = []  # (modules imported then, the controller)


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Pin the BLAS libraries numpy/scipy loaded (OpenBLAS, MKL, …) to one thread inside.

    For batched numpy work that is already parallel (Dask workers, the plan's placements): idle
    BLAS threads spin and steal the cores. Uses ``threadpoolctl``; a no-op when it is missing.
    The controller (1–8 ms to make: it lists the process's libraries) is kept until modules
    were imported since: a BLAS loaded later — MKL, with ``pypardiso`` for the FE — is pinned
    too (a controller made before it left MKL on all its threads).
    """
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        yield
        return
    n_modules = len(sys.modules)
    if not _CONTROLLER or _CONTROLLER[0][0] != n_modules:
        _CONTROLLER[:] = [(n_modules, ThreadpoolController())]
    with _CONTROLLER[0][1].limit(limits=1, user_api="blas"):
        yield
