"""Batched forward kinematics and geometric Jacobians of a serial 6R chain.

A chain is stored as seven fixed transforms ``F_0 .. F_6`` and, per joint, a sign and an offset
mapping the controller angle ``q_i`` to the rotation about the local z-axis::

    θ_i = sign_i · q_i + offset_i
    θ_3 = sign_3 · (q_3 + couple23 · q_2) + offset_3      (FANUC's J2/J3 coupling; else 0)
    T_base_flange = F_0 Rz(θ_1) F_1 Rz(θ_2) F_2 … F_5 Rz(θ_6) F_6

Every kinematic description (OPW parameters, standard DH, a URDF) is converted to this one form,
so FK and the Jacobian are written once. All functions take ``q`` (N, 6) rad and work on the whole
batch with stacked-array arithmetic (no Python loop over N).

Jacobian convention: the geometric Jacobian at the tool tip, expressed in the base frame, rows
``[v; ω]``: ``[v; ω] = J q̇`` with ``v`` the velocity of the tip point. Column i is
``sign_i · [z_i × (p_tip − o_i); z_i]`` (z_i, o_i: axis and a point of joint i, base frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames.se3 import check_rigid

__all__ = [
    "Chain",
    "OPWGeometry",
    "chain_fk",
    "chain_fk_jacobian",
    "chain_from_dh",
    "chain_from_opw",
    "rz",
    "sweep",
]

F64 = NDArray[np.float64]


def rz(theta: float) -> F64:
    """(4, 4) rotation about z by ``theta`` rad."""
    c, s = np.cos(theta), np.sin(theta)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def _tr(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> F64:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _rx(alpha: float) -> F64:
    c, s = np.cos(alpha), np.sin(alpha)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


@dataclass(frozen=True, eq=False)
class Chain:
    """Fixed part of a 6R serial chain (see module docstring).

    F : (7, 4, 4) float — fixed transforms, translations in m
    sign : (6,) float — ±1, ``θ = sign·q + offset``
    offset : (6,) float, rad
    couple23 : float (−1, 0 or 1) — J2/J3 coupling:
        ``θ_3 = sign_3·(q_3 + couple23·q_2) + offset_3``. FANUC
        controllers measure J3 from the horizontal (a parallelogram drives the forearm), so the
        kinematic (relative) J3 angle is the pendant's J3 + J2: ``couple23 = 1``. 0 for ABB and
        KUKA. The Jacobian with respect to the controller angles then has column 2 = its
        uncoupled column 2 + ``couple23`` × column 3.
    """

    F: F64
    sign: F64
    offset: F64
    couple23: float = 0.0

    def __post_init__(self) -> None:
        F = np.asarray(self.F, dtype=float)
        sign = np.asarray(self.sign, dtype=float).reshape(-1)
        offset = np.asarray(self.offset, dtype=float).reshape(-1)
        if F.shape != (7, 4, 4) or not np.all(np.isfinite(F)):
            raise InputError(f"chain needs 7 finite 4×4 fixed transforms, got {F.shape}", field="F")
        check_rigid(F, "F")  # the chain's fixed transforms
        if sign.shape != (6,) or not np.all(np.isin(sign, (-1.0, 1.0))):
            raise InputError(f"sign must be 6 values of ±1, got {sign.tolist()}", field="sign")
        if offset.shape != (6,) or not np.all(np.isfinite(offset)):
            raise InputError("offset must be 6 finite angles (rad)", field="offset")
        if self.couple23 not in (-1.0, 0.0, 1.0):
            raise InputError(
                f"couple23 (J2/J3 coupling) must be -1, 0 or 1, got {self.couple23!r}",
                field="couple23",
            )
        for name, v in (("F", F), ("sign", sign), ("offset", offset)):
            v.setflags(write=False)
            object.__setattr__(self, name, v)
        object.__setattr__(self, "couple23", float(self.couple23))

    def theta(self, q: F64) -> F64:
        """Model angles ``θ = sign·q + offset`` (+ the J2/J3 coupling) (N, 6) rad."""
        th = q * self.sign + self.offset
        if self.couple23 != 0.0:
            th[:, 2] += self.sign[2] * self.couple23 * q[:, 1]
        return th

    def q_from_theta(self, theta: F64) -> F64:
        """Controller angles of model angles ``theta`` (N, 6) rad (the inverse of :meth:`theta`)."""
        q = (theta - self.offset) * self.sign
        if self.couple23 != 0.0:
            q[:, 2] -= self.couple23 * q[:, 1]
        return q


@dataclass(frozen=True)
class OPWGeometry:
    """Ortho-parallel-wrist parameters (m), Brandstötter, Angerer & Hofbaur 2014."""

    a1: float
    a2: float
    b: float
    c1: float
    c2: float
    c3: float
    c4: float

    def __post_init__(self) -> None:
        for k in ("a1", "a2", "b", "c1", "c2", "c3", "c4"):
            v = getattr(self, k)
            if not np.isfinite(v):
                raise InputError(f"OPW parameter must be finite, got {v}", field=k)
        if self.c2 <= 0 or self.c3 <= 0:
            raise InputError("OPW link lengths c2, c3 must be > 0", field="c2")


def chain_from_opw(
    g: OPWGeometry,
    sign: ArrayLike = (1, 1, 1, 1, 1, 1),
    offset: ArrayLike = (0, 0, 0, 0, 0, 0),
    couple23: float = 0.0,
) -> Chain:
    """Chain of an ortho-parallel robot with a spherical wrist (Brandstötter et al. 2014).

    At ``θ = 0`` the arm stands straight up: joint 1 about base z at the origin; joint 2 about y
    at (a1, b, c1); joint 3 about y at (a1, b, c1 + c2); joint 4 about z through
    (a1 + a2, b, ·); joint 5 about y at the wrist centre (a1 + a2, b, c1 + c2 + c3); joint 6
    about z; the flange c4 above the wrist centre with axes parallel to the base.
    """
    a1, a2, b, c1, c2, c3, c4 = g.a1, g.a2, g.b, g.c1, g.c2, g.c3, g.c4
    # joint frames at θ = 0 in base coordinates; a y-axis joint gets the frame Rx(-π/2)
    # (its z-axis is base y)
    A = [
        _tr(0, 0, 0),
        _tr(a1, b, c1) @ _rx(-np.pi / 2),
        _tr(a1, b, c1 + c2) @ _rx(-np.pi / 2),
        _tr(a1 + a2, b, c1 + c2),
        _tr(a1 + a2, b, c1 + c2 + c3) @ _rx(-np.pi / 2),
        _tr(a1 + a2, b, c1 + c2 + c3),
    ]
    M = _tr(a1 + a2, b, c1 + c2 + c3 + c4)
    Fl = [A[0]] + [np.linalg.inv(A[i]) @ A[i + 1] for i in range(5)] + [np.linalg.inv(A[5]) @ M]
    F = np.array(Fl)
    F[np.abs(F) < 1e-15] = 0.0
    return Chain(F, np.asarray(sign, float), np.asarray(offset, float), couple23)


def _block_rot(R: F64) -> F64:
    n = R.shape[0]
    B = np.zeros((n, 6, 6))
    B[:, :3, :3] = R
    B[:, 3:, 3:] = R
    return B


def rotate_6x6(k_b: ArrayLike, R_a_b: ArrayLike) -> F64:
    """Re-express 6×6 compliances (N, 6, 6) from axes *b* to axes *a*, same point."""
    R = np.broadcast_to(np.asarray(R_a_b, dtype=float), (np.shape(k_b)[0], 3, 3))
    B = _block_rot(R)
    return B @ np.asarray(k_b, dtype=float) @ np.swapaxes(B, 1, 2)


def rotate_6(v_b: ArrayLike, R_a_b: ArrayLike) -> F64:
    """Re-express [lin; ang] 6-vectors (N, 6) from axes *b* to axes *a*; ``R_a_b`` is one
    rotation (3, 3) or one per vector (N, 3, 3) (``robot deflect`` with a log in tip axes)."""
    v = np.asarray(v_b, dtype=float)
    R = np.asarray(R_a_b, dtype=float)
    out = np.empty_like(v)
    spec = "nij,nj->ni" if R.ndim == 3 else "ij,nj->ni"
    out[:, :3] = np.einsum(spec, R, v[:, :3])
    out[:, 3:] = np.einsum(spec, R, v[:, 3:])
    return out


def chain_from_dh(
    d: ArrayLike,
    a: ArrayLike,
    alpha: ArrayLike,
    offset: ArrayLike = (0, 0, 0, 0, 0, 0),
    sign: ArrayLike = (1, 1, 1, 1, 1, 1),
) -> Chain:
    """Chain from standard (distal) DH: ``T_{i-1,i} = Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)`` (m, rad)."""
    d, a, alpha = (np.asarray(x, dtype=float).reshape(-1) for x in (d, a, alpha))
    for name, v in (("d", d), ("a", a), ("alpha", alpha)):
        if v.shape != (6,):
            raise InputError(f"DH needs 6 values, got {v.size}", field=name)
    F = [np.eye(4)] + [_tr(z=d[i]) @ _tr(x=a[i]) @ _rx(alpha[i]) for i in range(6)]
    return Chain(np.array(F), np.asarray(sign, float), np.asarray(offset, float))


def chain_fk(chain: Chain, q: F64, T_flange_tip: F64 | None = None) -> F64:
    """Forward kinematics ``T_base_tip`` (N, 4, 4) for ``q`` (N, 6) rad."""
    R, p, _, _ = sweep(chain, q, T_flange_tip, want_axes=False)
    T = np.zeros((q.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    return T


def chain_fk_jacobian(chain: Chain, q: F64, T_flange_tip: F64 | None = None) -> tuple[F64, F64]:
    """``T_base_tip`` (N, 4, 4) and the tip Jacobian (N, 6, 6), base frame, rows [v; ω]."""
    R, p, z, o = sweep(chain, q, T_flange_tip, want_axes=True)
    assert z is not None and o is not None
    n = q.shape[0]
    T = np.zeros((n, 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    J = np.empty((n, 6, 6))
    r = p[:, None, :] - o  # (N, 6, 3)
    J[:, :3, :] = np.swapaxes(np.cross(z, r), 1, 2)
    J[:, 3:, :] = np.swapaxes(z, 1, 2)
    J *= chain.sign
    if chain.couple23 != 0.0:
        J[:, :, 1] += chain.couple23 * J[:, :, 2]
    return T, J


def sweep(
    chain: Chain, q: F64, T_flange_tip: F64 | None, *, want_axes: bool
) -> tuple[F64, F64, F64 | None, F64 | None]:
    """Walk the chain once: rotation (N,3,3), position (N,3), joint axes and origins (N,6,3).

    Works on component arrays (structure of arrays, each (N,) contiguous) and skips the zero
    entries of the fixed rotations (OPW/DH chains are mostly axis permutations): this is several
    times faster than stacked 3×3 matmuls.
    """
    n = q.shape[0]
    theta = chain.theta(q)
    c = np.cos(theta).T.copy()
    s = np.sin(theta).T.copy()
    F = chain.F
    R = [[np.full(n, F[0, a, b]) for b in range(3)] for a in range(3)]
    p = [np.full(n, F[0, a, 3]) for a in range(3)]
    z = o = None
    if want_axes:
        z = np.empty((n, 6, 3))
        o = np.empty((n, 6, 3))

    def mul(R: list[list[F64]], p: list[F64], Fi: F64) -> tuple[list[list[F64]], list[F64]]:
        t = Fi[:3, 3]
        p = [p[a] + _lin([(R[a][k], t[k]) for k in range(3)], n) for a in range(3)]
        R = [[_lin([(R[a][k], Fi[k, b]) for k in range(3)], n) for b in range(3)] for a in range(3)]
        return R, p

    for i in range(6):
        if i > 0:
            R, p = mul(R, p, F[i])
        if want_axes:
            assert z is not None and o is not None
            for a in range(3):
                z[:, i, a] = R[a][2]
                o[:, i, a] = p[a]
        ci, si = c[i], s[i]
        for a in range(3):
            x0, x1 = R[a][0], R[a][1]
            R[a][0] = ci * x0 + si * x1
            R[a][1] = ci * x1 - si * x0
    Ft = F[6] if T_flange_tip is None else F[6] @ T_flange_tip
    R, p = mul(R, p, Ft)
    Rm = np.empty((n, 3, 3))
    pm = np.empty((n, 3))
    for a in range(3):
        pm[:, a] = p[a]
        for b in range(3):
            Rm[:, a, b] = R[a][b]
    return Rm, pm, z, o


def _lin(terms: list[tuple[F64, float]], n: int) -> F64:
    """Σ coef·array over the terms with a non-zero coefficient (exact ±1 without a multiply)."""
    out: F64 | None = None
    for arr, coef in terms:
        if coef == 0.0:
            continue
        term = arr if coef == 1.0 else (-arr if coef == -1.0 else coef * arr)
        out = term.copy() if out is None and term is arr else (term if out is None else out + term)
    return np.zeros(n) if out is None else out


def opw_fk_jacobian(
    g: OPWGeometry,
    chain: Chain,
    q: F64,
    T_flange_tip: F64 | None = None,
    *,
    want_jacobian: bool = True,
    want_fk: bool = True,
) -> tuple[F64 | None, F64 | None]:
    """Closed-form FK and tip Jacobian of an OPW chain built by :func:`chain_from_opw`.

    Same results as :func:`chain_fk_jacobian` (tested), several times fewer array passes: the arm
    is solved in the vertical plane turned by θ1 (joints 2, 3 about that plane's y-axis, the wrist
    as Ry(θ2+θ3) Rz(θ4) Ry(θ5) Rz(θ6)), then rotated about base z once.
    """
    a1, a2, b, c1, c2, c3 = g.a1, g.a2, g.b, g.c1, g.c2, g.c3
    n = q.shape[0]
    th = chain.theta(q).T  # (6, N), contiguous rows
    c = np.cos(th)
    s = np.sin(th)
    c1_, s1_ = c[0], s[0]
    c2_, s2_ = c[1], s[1]
    c23 = c2_ * c[2] - s2_ * s[2]
    s23 = s2_ * c[2] + c2_ * s[2]
    c4_, s4_, c5_, s5_, c6_, s6_ = c[3], s[3], c[4], s[4], c[5], s[5]
    # M = Rz(θ4) Ry(θ5) Rz(θ6)
    c4c5 = c4_ * c5_
    s4c5 = s4_ * c5_
    m00 = c4c5 * c6_ - s4_ * s6_
    m01 = -c4c5 * s6_ - s4_ * c6_
    m02 = c4_ * s5_
    m10 = s4c5 * c6_ + c4_ * s6_
    m11 = -s4c5 * s6_ + c4_ * c6_
    m12 = s4_ * s5_
    m20 = -s5_ * c6_
    m21 = s5_ * s6_
    m22 = c5_
    # R_A = Ry(θ23) M (arm-plane axes): rows 0 and 2 mix, row 1 = M row 1
    r00 = c23 * m00 + s23 * m20
    r01 = c23 * m01 + s23 * m21
    r02 = c23 * m02 + s23 * m22
    r20 = c23 * m20 - s23 * m00
    r21 = c23 * m21 - s23 * m01
    r22 = c23 * m22 - s23 * m02
    # wrist centre (arm plane): o3 = (a1 + c2 s2, b, c1 + c2 c2)
    cx = a1 + c2 * s2_ + a2 * c23 + c3 * s23
    cz = c1 + c2 * c2_ - a2 * s23 + c3 * c23
    Ft = chain.F[6] if T_flange_tip is None else chain.F[6] @ T_flange_tip
    t = Ft[:3, 3]
    Rt = Ft[:3, :3]
    px = cx + r00 * t[0] + r01 * t[1] + r02 * t[2]
    py = b + m10 * t[0] + m11 * t[1] + m12 * t[2]
    pz = cz + r20 * t[0] + r21 * t[1] + r22 * t[2]
    # filled component-major (4, 4, N) / (6, 6, N) so every write is contiguous; returned as
    # (N, 4, 4) / (N, 6, 6) views
    bx = c1_ * px - s1_ * py  # tip position, base axes
    by = s1_ * px + c1_ * py
    T: F64 | None = None
    if want_fk:
        Tt = np.empty((4, 4, n))
        Tt[3, :3] = 0.0
        Tt[3, 3] = 1.0
        rows = ((r00, r01, r02), (m10, m11, m12), (r20, r21, r22))
        # tip rotation R_A Rt, then turn x/y rows by θ1
        for k in range(3):
            x, y, zz = (
                rows[a][0] * Rt[0, k] + rows[a][1] * Rt[1, k] + rows[a][2] * Rt[2, k]
                for a in range(3)
            )
            Tt[0, k] = c1_ * x - s1_ * y
            Tt[1, k] = s1_ * x + c1_ * y
            Tt[2, k] = zz
        Tt[0, 3] = bx
        Tt[1, 3] = by
        Tt[2, 3] = pz
        T = Tt.transpose(2, 0, 1)
    if not want_jacobian:
        return T, None
    Jt = np.empty((6, 6, n))
    # column 1: z = e_z through the origin → v = (−p_y, p_x, 0), ω = e_z
    np.negative(by, out=Jt[0, 0])
    Jt[1, 0] = bx
    Jt[2:5, 0] = 0.0
    Jt[5, 0] = 1.0
    # columns 2, 3: z = Rz(θ1) e_y = (−s1, c1, 0); v = Rz(θ1) (r_z, 0, −r_x)
    for i, (ox, oz) in ((1, (a1, c1)), (2, (a1 + c2 * s2_, c1 + c2 * c2_))):
        vx = pz - oz
        Jt[0, i] = c1_ * vx
        Jt[1, i] = s1_ * vx
        Jt[2, i] = ox - px
        np.negative(s1_, out=Jt[3, i])
        Jt[4, i] = c1_
        Jt[5, i] = 0.0
    # wrist columns through the wrist centre C = (cx, b, cz): v = z × (p − C)
    rx, ry, rz_ = px - cx, py - b, pz - cz
    z5x, z5z = -s4_ * c23, s4_ * s23
    for i, (zx, zy, zz) in ((3, (s23, None, c23)), (4, (z5x, c4_, z5z)), (5, (r02, m12, r22))):
        if zy is None:  # z4 = (s23, 0, c23)
            vx = -zz * ry
            vy = zz * rx - zx * rz_
            vz = zx * ry
            Jt[3, i] = c1_ * zx
            Jt[4, i] = s1_ * zx
        else:
            vx = zy * rz_ - zz * ry
            vy = zz * rx - zx * rz_
            vz = zx * ry - zy * rx
            Jt[3, i] = c1_ * zx - s1_ * zy
            Jt[4, i] = s1_ * zx + c1_ * zy
        Jt[5, i] = zz
        Jt[0, i] = c1_ * vx - s1_ * vy
        Jt[1, i] = s1_ * vx + c1_ * vy
        Jt[2, i] = vz
    for j in np.flatnonzero(chain.sign != 1.0):
        Jt[:, j] *= -1.0
    if chain.couple23 != 0.0:
        Jt[:, 1] += chain.couple23 * Jt[:, 2]
    return T, Jt.transpose(2, 0, 1)
