"""Recognise an ortho-parallel robot with a spherical wrist (OPW) in a general 6R chain.

Given a :class:`~roboisf.robot.kinematics.Chain` (e.g. read from a URDF, joint values = controller
angles), :func:`fit_opw` finds OPW parameters (Brandstötter, Angerer & Hofbaur 2014) and the
controller map ``θ = sign·q + offset`` such that :func:`~roboisf.robot.kinematics.chain_from_opw`
gives the same tip poses. It reads the geometry at ``q = 0`` — joint 1 on the base z-axis;
joints 2 and 3 parallel and horizontal; axes 4, 5, 6 meeting at the wrist centre; the tip frame on
axis 6 with its z along it — solves the parameters and offsets in closed form for each of the
few discrete choices (which way the arm plane faces, the sign of axis 5), and accepts a candidate
only when FK agrees with the original chain to 1e-9 (m and rad) at 200 random configurations
within the limits. Anything else returns None (the robot then uses numerical IK).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.robot.kinematics import Chain, OPWGeometry, chain_fk, chain_from_opw

__all__ = ["TOL", "explain_opw", "fit_opw"]

F64 = NDArray[np.float64]

TOL = 1e-9


def _axes_at_zero(chain: Chain) -> tuple[F64, F64, F64]:
    """Joint axes z (6, 3), joint origins o (6, 3) and the tip pose (4, 4) at ``q = 0``."""
    T = np.eye(4)
    z = np.empty((6, 3))
    o = np.empty((6, 3))
    th = chain.theta(np.zeros((1, 6)))[0]
    for i in range(6):
        T = T @ chain.F[i]
        z[i] = T[:3, 2]
        o[i] = T[:3, 3]
        c, s = math.cos(th[i]), math.sin(th[i])
        Rz = np.eye(4)
        Rz[:2, :2] = [[c, -s], [s, c]]
        T = T @ Rz
    return z, o, T @ chain.F[6]


def _ry(a: float) -> F64:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz3(a: float) -> F64:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _line_meet(p1: F64, d1: F64, p2: F64, d2: F64) -> tuple[F64, float]:
    """Midpoint of the closest points of two lines and their distance."""
    w = p1 - p2
    b = float(d1 @ d2)
    den = 1.0 - b * b
    if den < 1e-12:
        return p1, math.inf
    t1 = (b * (d2 @ w) - (d1 @ w)) / den
    t2 = ((d2 @ w) - b * (d1 @ w)) / den
    a, c = p1 + t1 * d1, p2 + t2 * d2
    return 0.5 * (a + c), float(np.linalg.norm(a - c))


def _candidate(chain: Chain, s2: float, s5: float) -> tuple[OPWGeometry, F64, F64] | str:
    """OPW parameters, signs and offsets for the discrete choices ``s2``, ``s5``, or the reason
    the chain does not have the OPW structure (a phrase for "closed-form IK not available: …")."""
    z, o, T0 = _axes_at_zero(chain)
    sign = np.ones(6)
    off = np.zeros(6)
    sign[0] = round(float(z[0, 2]))
    if abs(abs(z[0, 2]) - 1) > 1e-9 or np.hypot(o[0, 0], o[0, 1]) > 1e-9:
        return "axis 1 is not the base z axis"
    # arm plane: axis 2 = s2 · (plane's y-axis) = s2 · Rz(ψ) e_y
    y2 = s2 * z[1]
    if abs(y2[2]) > 1e-9:
        return f"axis 2 is not horizontal (z component {y2[2]:.3g})"
    psi = math.atan2(-y2[0], y2[1])
    # q = 0 ↦ θ1 = ψ: the OPW arm plane at θ1 is Rz(θ1)
    off[0] = psi
    sign[1] = s2
    Rp = _rz3(psi).T  # base → arm-plane coordinates
    zz = z @ Rp.T
    oo = o @ Rp.T
    sign[2] = round(float(zz[2, 1]))
    if abs(abs(zz[2, 1]) - 1) > 1e-9:
        return "axes 2 and 3 are not parallel"
    a1, c1 = float(oo[1, 0]), float(oo[1, 2])
    d = oo[2] - oo[1]
    c2 = math.hypot(d[0], d[2])
    if c2 < 1e-9:
        return "axes 2 and 3 coincide"
    off[1] = math.atan2(d[0], d[2])
    # wrist centre: axes 4, 5 (and 6) meet
    C, dist = _line_meet(oo[3], zz[3], oo[4], zz[4])
    if dist > 1e-9:
        return f"axes 4 and 5 do not meet (they pass {dist:.3g} m apart): no spherical wrist"
    _, d6 = _line_meet(oo[5], zz[5], C, zz[3])
    if np.linalg.norm(np.cross(zz[5], C - oo[5])) > 1e-9 and d6 > 1e-9:
        return f"axis 6 misses the wrist centre by {d6:.3g} m: no spherical wrist"
    if abs(zz[3, 1]) > 1e-9:
        return "axis 4 leaves the arm plane"
    b = float(C[1])
    for s4 in (1.0, -1.0):
        th23 = math.atan2(s4 * zz[3, 0], s4 * zz[3, 2])
        v = _ry(th23).T @ (C - oo[2])  # (a2, ·, c3) in the forearm frame
        if v[2] > 0:
            break
    else:
        return "the wrist centre lies on axis 3"
    sign[3] = s4
    a2, c3 = float(v[0]), float(v[2])
    off[2] = th23 - off[1]
    # wrist orientation in the forearm frame: R = Rz(θ4) Ry(θ5) Rz(θ6) at q = 0
    Rf = _ry(th23).T @ Rp
    z5 = s5 * (Rf @ z[4])
    if abs(z5[2]) > 1e-9:
        return "axis 5 is not perpendicular to axis 4"
    off[3] = math.atan2(-z5[0], z5[1])
    sign[4] = s5
    z6 = Rf @ z[5]
    R4 = _rz3(off[3]).T @ z6  # = s6 (sin θ5, 0, cos θ5)
    tip = Rf @ T0[:3, 3] - Rf @ (Rp.T @ C)
    c4 = None
    for s6 in (1.0, -1.0):
        if float(tip @ (s6 * z6)) > 0:
            c4 = float(tip @ (s6 * z6))
            break
    if c4 is None or np.linalg.norm(tip - c4 * s6 * z6) > 1e-9:
        return "the tip frame's origin is not on axis 6 beyond the wrist centre"
    sign[5] = s6
    off[4] = math.atan2(s6 * R4[0], s6 * R4[2])
    Rw = _ry(off[4]).T @ _rz3(off[3]).T @ Rf @ T0[:3, :3]
    if abs(Rw[2, 2] - 1) > 1e-9:
        return "the tip frame's z axis is not along axis 6"
    off[5] = math.atan2(Rw[1, 0], Rw[0, 0])
    # parameters rounded to 1e-12 m (URDF decimals); the FK check of fit_opw has the last word
    r = [round(v, 12) + 0.0 for v in (a1, a2, b, c1, c2, c3, c4)]
    try:
        g = OPWGeometry(a1=r[0], a2=r[1], b=r[2], c1=r[3], c2=r[4], c3=r[5], c4=r[6])
    except InputError as e:
        return f"its OPW parameters are not valid ({e.message})"
    off = (off + np.pi) % (2 * np.pi) - np.pi
    off = np.round(off, 15)
    off[np.abs(off) < 1e-15] = 0.0
    return g, sign, off


def fit_opw(
    chain: Chain, q_min: F64, q_max: F64, *, n_check: int = 200, seed: int = 0
) -> tuple[Chain, OPWGeometry] | None:
    """``(chain_from_opw(g, sign, offset), g)`` equal to ``chain`` in FK, or None.

    Accepted only when position and orientation of the tip agree to 1e-9 (m, rad) at ``n_check``
    random configurations within ``[q_min, q_max]`` (rad) and at ``q = 0``.
    """
    return explain_opw(chain, q_min, q_max, n_check=n_check, seed=seed)[0]


def explain_opw(
    chain: Chain, q_min: F64, q_max: F64, *, n_check: int = 200, seed: int = 0
) -> tuple[tuple[Chain, OPWGeometry] | None, str]:
    """:func:`fit_opw` and, when it fails, why: the structural test that failed (axis 1 not the
    base z axis, no spherical wrist, the tip frame's z not along axis 6 …) or how far the best
    candidate's FK is from the chain's ("" when it fits)."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(q_min, -2 * np.pi)
    hi = np.minimum(q_max, 2 * np.pi)
    q = np.vstack([np.zeros(6), rng.uniform(lo, hi, (n_check, 6))])
    T_ref = chain_fk(chain, q)
    best: tuple[float, Chain, OPWGeometry] | None = None
    reasons: list[str] = []
    worst_fk = math.inf
    for s2 in (1.0, -1.0):
        for s5 in (1.0, -1.0):
            cand = _candidate(chain, s2, s5)
            if isinstance(cand, str):
                reasons.append(cand)
                continue
            g, sign, off = cand
            ch = chain_from_opw(g, sign, off)
            T = chain_fk(ch, q)
            dp = float(np.max(np.abs(T[:, :3, 3] - T_ref[:, :3, 3])))
            dr = float(np.max(np.abs(T[:, :3, :3] - T_ref[:, :3, :3])))
            if dp <= TOL and dr <= TOL:
                # of the equivalent descriptions, the one with the smallest offsets
                cost = float(np.sum(np.abs(off)))
                if best is None or cost < best[0] - 1e-9:
                    best = (cost, ch, g)
            else:
                worst_fk = min(worst_fk, max(dp, dr))
    if best is not None:
        return (best[1], best[2]), ""
    if math.isfinite(worst_fk):
        return None, (
            f"the nearest OPW description's FK differs from the chain by {worst_fk:.3g} (m or "
            f"rad; {TOL:g} accepted)"
        )
    # the reason of the choice that got furthest through the tests
    return None, max(reasons, key=_stage) if reasons else "no OPW structure"


#: the structural tests of :func:`_candidate`, in the order they are made
_STAGES = (
    "axis 1",
    "axis 2 is",
    "axes 2 and 3 are",
    "axes 2 and 3 coincide",
    "axes 4 and 5",
    "axis 6 misses",
    "axis 4 leaves",
    "the wrist centre",
    "axis 5 is",
    "the tip frame's origin",
    "the tip frame's z",
    "its OPW",
)


def _stage(reason: str) -> int:
    return next((i for i, s in enumerate(_STAGES) if reason.startswith(s)), -1)
