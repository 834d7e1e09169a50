"""Tare, gravity compensation and bias detection of a force log (see :mod:`roboisf.sensor`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError

__all__ = [
    "G_WORLD",
    "Conditioning",
    "ToolLoad",
    "UnloadedStretch",
    "condition_wrench",
    "gravity_wrench",
    "identify_tool_load",
    "unloaded_samples",
    "unloaded_stretches",
]

F64 = NDArray[np.float64]

#: Standard gravity along −z of the world (robot base) frame, m/s².
G_WORLD = np.array([0.0, 0.0, -9.80665])

#: An unloaded-part mean |F| below this is noise, not a bias worth a warning (N).
BIAS_FORCE_MIN = 2.0
#: … and |M| below this (N·m).
BIAS_MOMENT_MIN = 0.2


def _skew(v: F64) -> F64:
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = np.zeros_like(x)
    return np.stack(
        [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2
    )


def gravity_wrench(R_world_sensor: ArrayLike, mass: float, cog: ArrayLike) -> F64:
    """The wrench the tool's weight puts on the sensor, sensor axes, about the sensor origin.

    ``W_g = [m gₛ; r_c × m gₛ]`` with ``gₛ = R_world_sensorᵀ g_world``.

    Parameters
    ----------
    R_world_sensor : (3, 3) or (N, 3, 3) — sensor orientation in the world (gravity) frame
    mass : kg — mass below the sensor (tool, holder, adapter)
    cog : (3,) m — its centre of gravity in the sensor frame

    Returns
    -------
    (6,) or (N, 6) [N, N·m]
    """
    R = np.asarray(R_world_sensor, dtype=float)
    g_s = np.einsum("...ji,j->...i", R, G_WORLD)  # Rᵀ g
    F = mass * g_s
    M = np.cross(np.asarray(cog, dtype=float), F)
    return np.concatenate([F, M], axis=-1)


@dataclass(frozen=True)
class ToolLoad:
    """Tool mass and centre of gravity below a flange sensor, with the sensor offset.

    Attributes
    ----------
    mass : kg
    cog : (3,) m, sensor frame
    offset : (6,) [N, N·m] — the zero offset b identified with them (zeros when given)
    observable : str — what the poses determined ("all", or which parts were not observable)
    residual : float, N — RMS force residual of the fit (0 when given)
    """

    mass: float
    cog: F64
    offset: F64
    observable: str = "all"
    residual: float = 0.0


def identify_tool_load(R_world_sensor: ArrayLike, W_meas: ArrayLike) -> ToolLoad:
    """Mass, centre of gravity and zero offset from unloaded readings in several orientations.

    Linear least squares on ``θ = [b_F, b_M, m, p = m r_c]``::

        F = b_F + m gₛ                      (3 rows per pose)
        M = b_M + p × gₛ = b_M − [gₛ]× p    (3 rows per pose)

    Observability: ``m`` and ``b_F`` need gₛ to change between poses (two orientations); ``p``
    (with ``b_M``) needs the changes of gₛ to span two dimensions — with two orientations the
    component of ``p`` along their gₛ difference is not observable (set to its minimum-norm
    value, reported in ``observable``). In practice: three or more orientations, tilted ≥ 30°
    apart about different axes; turning about the vertical alone changes nothing.

    Parameters
    ----------
    R_world_sensor : (K, 3, 3) — orientations of the unloaded poses
    W_meas : (K, 6) [N, N·m] — mean reading at each pose

    Raises
    ------
    InputError
        fewer than two distinct orientations (the mass cannot be told from the offset).
    """
    R = np.asarray(R_world_sensor, dtype=float).reshape(-1, 3, 3)
    W = np.asarray(W_meas, dtype=float).reshape(-1, 6)
    if R.shape[0] != W.shape[0]:
        raise InputError(f"{R.shape[0]} orientations but {W.shape[0]} readings", field="poses")
    g_s = np.einsum("kji,j->ki", R, G_WORLD)
    k = R.shape[0]
    A = np.zeros((6 * k, 10))
    eye = np.eye(3)
    for i in range(k):
        A[6 * i : 6 * i + 3, 0:3] = eye
        A[6 * i : 6 * i + 3, 6] = g_s[i]
        A[6 * i + 3 : 6 * i + 6, 3:6] = eye
        A[6 * i + 3 : 6 * i + 6, 7:10] = -_skew(g_s[i])
    spread = np.linalg.svd(g_s - g_s.mean(axis=0), compute_uv=False)
    if spread[0] < 1e-3 * 9.80665:
        raise InputError(
            "the tool's mass cannot be told from the sensor offset with one orientation: give "
            "unloaded readings in ≥ 2 (better ≥ 3) orientations, or the mass and CoG",
            field="poses",
        )
    # columns of p along directions that gₛ never leaves are not observable: minimum-norm
    theta, *_ = np.linalg.lstsq(A, W.reshape(-1), rcond=1e-9)
    sv = np.linalg.svd(A, compute_uv=False)
    rank = int(np.sum(sv > 1e-9 * sv[0]))
    observable = (
        "all"
        if rank == 10
        else (
            "centre of gravity along the one direction the poses changed gravity in (set to its "
            "minimum-norm value); add a pose tilted about another axis"
        )
    )
    m = float(theta[6])
    p = theta[7:10]
    res = A @ theta - W.reshape(-1)
    rms = float(np.sqrt(np.mean(res.reshape(k, 6)[:, :3] ** 2)))
    cog = p / m if abs(m) > 1e-12 else np.zeros(3)
    return ToolLoad(m, cog, theta[:6].copy(), observable, rms)


@dataclass(frozen=True)
class Conditioning:
    """How a force log is conditioned (study ``[runs.X.forces]``: ``tare``, ``tool_mass``,
    ``tool_cog``).

    tare : "none" | "auto" | (t0, t1) s — subtract the mean reading (less the gravity wrench,
        when a tool load is given) over the unloaded approach found automatically, or over the
        stated window of the log's clock
    tool : ToolLoad | None — tool mass and CoG below a flange sensor (gravity compensation)
    """

    tare: Literal["none", "auto"] | tuple[float, float] = "none"
    tool: ToolLoad | None = None


def _distances(W: F64, level: F64) -> F64:
    """``|F − level|`` per sample (N,) for the force columns of ``W`` (N, ≥3)
    (:func:`roboisf.logs.forcelog.row_norms`: the bits of ``np.linalg.norm(F − level,
    axis=1)``)."""
    from roboisf.logs.forcelog import row_norms

    return row_norms(W, 0, level)


def _onset(W: F64, level: F64, noise: float) -> tuple[float, int]:
    """(span, onset): the largest ``|F − level|`` of the log and the first sample above
    ``max(5 noise, 0.01 span)`` (−1: none). Compiled, two passes without the (N,) distances
    (:func:`roboisf.logs.forcelog_kernel.onset`; three calls a log: the tare's and the
    unloaded stretches' at both ends, 24 → ~6 ms each on 2.3 M samples), else from
    :func:`_distances` — the same numbers."""
    from roboisf.logs.forcelog import log_kernel

    kern = log_kernel()
    if kern is not None:
        return kern.onset(W, level, noise)
    dev = _distances(W, level)
    span = float(dev.max())
    above = dev > max(5.0 * noise, 0.01 * span)
    return span, int(np.argmax(above)) if above.any() else -1


#: The fewest samples of an unloaded approach used to tare or to judge a zero.
UNLOADED_MIN_SAMPLES = 25


def unloaded_samples(time: F64, W: F64, *, min_samples: int = UNLOADED_MIN_SAMPLES) -> slice | None:
    """The unloaded approach at the start of a log: samples before the force onset.

    σ is the noise of the first ``min_samples`` samples; the onset is the first sample whose
    force departs from their level by more than ``max(5 σ, 1 % of the log's force range)``.
    The samples before it are accepted as unloaded only if

    * there are at least ``min_samples`` of them,
    * they are flat: the mean of their last fifth differs from the mean of their first fifth by
      less than 2 σ (a log whose forming force ramps up from zero at once has no unloaded part),
    * their level is below 25 % of the force range.

    Otherwise None: the log has no unloaded part to tare on or to check.
    """
    Wf = np.asarray(W, dtype=float)
    F = Wf[:, :3]
    n = F.shape[0]
    if n < 2 * min_samples:
        return None
    head = F[:min_samples]
    level = np.median(head, axis=0)
    noise = float(np.sqrt(np.mean(np.var(head, axis=0)))) + 1e-12
    span, onset = _onset(Wf, level, noise)
    if onset < 0:
        return None  # never loaded: no forming in this log
    # stop a little before the onset: the rise starts below the threshold
    stop = onset - max(1, onset // 10)
    if stop < min_samples:
        return None
    if np.linalg.norm(level) > 0.25 * span:
        return None
    k = max(1, stop // 5)
    drift = float(np.linalg.norm(F[stop - k : stop].mean(axis=0) - F[:k].mean(axis=0)))
    if drift > 2.0 * noise:
        return None
    return slice(0, stop)


#: Blocks an unloaded stretch is cut into for the standard error of its mean (a sensor's noise
#: is correlated over neighbouring samples; block means of ≥ 1/16 of a stretch are close to
#: independent).
UNLOADED_BLOCKS = 16


@dataclass(frozen=True)
class UnloadedStretch:
    """A stretch of a force log with the tool off the sheet (:func:`unloaded_stretches`).

    where : "start" (before the force's onset) or "end" (after the force falls away);
    t0, t1 : s, the log's own clock; n : samples in it;
    blocks : (B, 6) [N, N·m] the reading's means over B consecutive equal blocks of the
        stretch, in the axes of whoever made them (the sensor's; :meth:`map` moves them);
    tared : True when this stretch was the tare window — its mean is zero by construction and
        tells nothing about the sensor;
    on_path : True when the stretch lies on the toolpath (the log has too little before or after
        it): the tool already forms there, with a force below the detection threshold.
    """

    where: str
    t0: float
    t1: float
    n: int
    blocks: F64
    tared: bool = False
    on_path: bool = False

    @property
    def mean(self) -> F64:
        """(6,) the mean reading over the stretch."""
        return np.asarray(self.blocks.mean(axis=0))

    @property
    def se(self) -> F64:
        """(6,) standard error of :attr:`mean`, from the spread of the block means."""
        B = self.blocks
        return np.asarray(B.std(axis=0, ddof=1) / np.sqrt(len(B)))

    def map(self, f: Callable[[F64], F64]) -> UnloadedStretch:
        """The same stretch with ``f`` (a linear map of (B, 6) wrenches, e.g. sensor → tip axes)
        applied to its block means."""
        return replace(self, blocks=np.asarray(f(self.blocks), dtype=float))


def unloaded_stretches(
    time: ArrayLike,
    W: ArrayLike,
    *,
    min_samples: int = 25,
    path: tuple[float, float] | None = None,
) -> list[UnloadedStretch]:
    """The stretches of a log with the tool off the sheet: its start before the force's onset
    and its end after the force falls away (a retract), each found as
    :func:`unloaded_samples` finds the start (the end: the same on the reversed log).

    time : (N,) s; W : (N, 6) [N, N·m]; path : (t0, t1) s on the log's clock, when the tool
    was on the toolpath (its first and last point): the start stretch ends before t0 and the
    end stretch begins after t1 — a part whose first laps form with a force below the noise
    threshold would otherwise lend them to the start. A stretch shorter than ``min_samples`` or
    than :data:`UNLOADED_BLOCKS` × 4 samples is left out. Stretches between passes (the tool
    lifted mid-log) are not looked for.
    """
    t = np.asarray(time, dtype=float)
    Wf = np.asarray(W, dtype=float)
    n = len(t)
    out = []
    for where in ("start", "end"):
        win = (
            unloaded_samples(t, Wf, min_samples=min_samples)
            if where == "start"
            else unloaded_samples(t[::-1], Wf[::-1], min_samples=min_samples)
        )
        if win is None:
            continue
        i0, i1 = (0, win.stop) if where == "start" else (n - win.stop, n)
        on_path = False
        if path is not None:
            # off the path only, unless that leaves too little: then the stretch is the path's
            # first (last) moments at a force below the threshold, and says so
            j0, j1 = (i0, min(i1, int(np.searchsorted(t, path[0], "left"))))
            if where == "end":
                j0, j1 = (max(i0, int(np.searchsorted(t, path[1], "right"))), i1)
            if j1 - j0 >= max(min_samples, 4 * UNLOADED_BLOCKS):
                i0, i1 = j0, j1
            else:
                on_path = True
        if i1 - i0 < 4 * UNLOADED_BLOCKS:
            continue
        blocks = np.stack([b.mean(axis=0) for b in np.array_split(Wf[i0:i1], UNLOADED_BLOCKS)])
        out.append(
            UnloadedStretch(where, float(t[i0]), float(t[i1 - 1]), i1 - i0, blocks, on_path=on_path)
        )
    if len(out) == 2 and out[1].t0 <= out[0].t1:
        return out[:1]  # never loaded in between: one stretch, not two
    return out


def _window(time: F64, t0: float, t1: float, file: Path | None) -> slice:
    i0, i1 = int(np.searchsorted(time, t0, "left")), int(np.searchsorted(time, t1, "right"))
    if not (t1 > t0) or i1 - i0 < 1:
        raise InputError(
            f"tare window [{t0:g}, {t1:g}] s holds no sample of the log (it runs "
            f"{time[0]:.3f} … {time[-1]:.3f} s)",
            file=file,
            field="tare",
        )
    return slice(i0, i1)


def condition_wrench(
    time: ArrayLike,
    W_meas: ArrayLike,
    cond: Conditioning,
    *,
    R_world_sensor: ArrayLike | None = None,
    R_index: ArrayLike | None = None,
    file: Path | None = None,
    load_start: float | None = None,
) -> tuple[F64, list[str], dict[str, object]]:
    """Remove the tool's weight and the zero offset from a sensor reading.

    ``W = W_meas − W_g(R(t)) − b`` with ``b = mean over the tare window of (W_meas − W_g(R))``
    (``b = 0`` without a tare). Without a tare, the unloaded approach (if one is found) is
    checked: a mean there above 2 N / 0.2 N·m is reported as an untared bias.

    Parameters
    ----------
    time : (N,) s; W_meas : (N, 6) [N, N·m] sensor axes
    cond : what to do
    R_world_sensor : (3, 3), (N, 3, 3), or (P, 3, 3) with ``R_index`` — sensor orientation,
        needed with ``cond.tool``
    R_index : (N,) int, optional — sample i's orientation is ``R_world_sensor[R_index[i]]`` (a
        few orientations shared by many samples: the gravity wrench is computed once for each)
    file : the log, for messages
    load_start : s, the log time from which the tool forms (its first toolpath point below the
        sheet plane), when known: the unloaded approach ends there. A log that starts forming,
        at a force steady enough to look unloaded, has none — its first laps were tared away by
        ``tare = "auto"`` and reported as an untared bias of 100 N on a clean cell

    Returns
    -------
    W : (N, 6) conditioned reading (``W_meas`` itself, not a copy, when nothing is removed)
    warnings : list of str — an untared bias seen in the unloaded part, a tare asked for that
        found no unloaded approach
    info : dict — ``offset`` (6,) removed, ``window`` (t0, t1) s or None, ``bias`` (6,) seen
    """
    t = np.asarray(time, dtype=float)
    W = np.asarray(W_meas, dtype=float)  # copied below only if something is removed
    name = file.name if file is not None else "force log"
    notes: list[str] = []
    if cond.tool is not None:
        if R_world_sensor is None:
            raise InputError("gravity compensation needs the sensor orientation", file=file)
        W_g = gravity_wrench(R_world_sensor, cond.tool.mass, cond.tool.cog)
        W = W - (W_g if R_index is None else W_g[np.asarray(R_index, dtype=np.intp)])
    info: dict[str, object] = {"offset": np.zeros(6), "window": None, "bias": None}
    win: slice | None
    if isinstance(cond.tare, tuple):
        win = _window(t, float(cond.tare[0]), float(cond.tare[1]), file)
    else:
        win = unloaded_samples(t, W)
        if win is not None and load_start is not None:
            stop = min(int(win.stop), int(np.searchsorted(t, load_start, side="left")))
            win = slice(0, stop) if stop >= UNLOADED_MIN_SAMPLES else None
    if win is not None:
        b = W[win].mean(axis=0)
        info["window"] = (float(t[win][0]), float(t[win][-1]))
        if cond.tare == "none":
            info["bias"] = b
            fb, mb = float(np.linalg.norm(b[:3])), float(np.linalg.norm(b[3:]))
            if fb > BIAS_FORCE_MIN or mb > BIAS_MOMENT_MIN:
                notes.append(
                    f"{name}: the unloaded start of the log ({t[win][0]:.2f}–{t[win][-1]:.2f} s) "
                    f"reads |F| = {fb:.3g} N, |M| = {mb:.3g} N·m, not tared — a sensor offset"
                    + (" or the tool's weight" if cond.tool is None else "")
                    + ' is in every force; set tare = "auto" (or a window) for this log'
                )
        else:
            W = W - b
            info["offset"] = b
    elif cond.tare == "auto":
        notes.append(
            f'{name}: tare = "auto" found no unloaded approach at the start of the log (it '
            "starts loaded, or forming on the toolpath); not tared — give tare = [t0, t1] s"
        )
    return W, notes, info
