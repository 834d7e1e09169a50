"""Link compliance of the virtual cell's robot: the arm links as Timoshenko beams.

The paper's VJM (and ``roboisf.robot``) takes the links as rigid and puts all compliance in the
joints; the paper names the rigid links as its model's missing part. The virtual cell's truth can
add them (``[robot] link_compliance = true``): each main arm link is a straight prismatic beam
clamped at its proximal joint and loaded at its distal end by the wrench the tool carries. Small
deflections superpose, so the tip deflection is the joint VJM plus, for every link,

    W_e = [f; m + (p_tip − p_e) × f]            the tip wrench moved to the link's end p_e
    [δ_e; θ_e] = R C_beam Rᵀ W_e                the link end's deflection (base axes)
    δ_tip += δ_e + θ_e × (p_tip − p_e)          carried rigidly to the tip

``C_beam`` is the cantilever compliance at the free end in the beam's frame (x along the beam,
y the bending axis of the arm plane, z = x × y): axial ``L/EA``; bending ``L³/3EI + L/κGA``
(Timoshenko shear) with the rotation coupling ``L²/2EI``; rotation ``L/EI``; torsion ``L/GJ``.

The IRB 7600's link sections are not published. :data:`IRB7600_LINKS` is an estimate, stated as
such: the lower arm (joint 2 → joint 3, 1.075 m) a hollow cast box 320 × 220 mm with 16 mm
walls, the upper arm (joint 3 → wrist centre, 1.069 m) a cast tube Ø240 mm with 14 mm walls, both
nodular cast iron EN-GJS-400-15 (E = 169 GPa, G = 65 GPa) — outlines scaled from the robot's
product-specification drawings, wall thicknesses typical of cast arms. With them the links add
about 10 % to the joint VJM's deflection of the paper's cell (``docs/virtual-cell.md``), the
order reported for heavy industrial robots (the joints dominate).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.robot import RobotModel
from roboisf.robot.kinematics import rotate_6, sweep

__all__ = [
    "IRB7600_LINKS",
    "BeamSection",
    "LinkBeam",
    "beam_chain_deflection",
    "cantilever_compliance",
    "link_deflection",
]

F64 = NDArray[np.float64]


def _rot6(v: F64, R: F64) -> F64:
    """[lin; ang] (N, 6) re-expressed by per-pose rotations R (N, 3, 3)."""
    return np.concatenate(
        [np.einsum("nij,nj->ni", R, v[:, :3]), np.einsum("nij,nj->ni", R, v[:, 3:])], axis=1
    )


@dataclass(frozen=True)
class BeamSection:
    """A prismatic beam's section and material (SI).

    Attributes
    ----------
    area : float, m² — A
    I_bend : float, m⁴ — second moment for bending in the arm plane (about the joint axis)
    I_out : float, m⁴ — second moment for bending out of the arm plane
    J_torsion : float, m⁴ — torsion constant
    E, G : float, Pa — Young's and shear modulus
    shear_factor : float — Timoshenko κ (0.5 thin-walled box/tube; inf: Euler–Bernoulli)
    """

    area: float
    I_bend: float
    I_out: float
    J_torsion: float
    E: float
    G: float
    shear_factor: float = 0.5

    def __post_init__(self) -> None:
        for k in ("area", "I_bend", "I_out", "J_torsion", "E", "G", "shear_factor"):
            v = getattr(self, k)
            if not v > 0:
                raise InputError(f"must be > 0, got {v}", field=f"section.{k}")

    @classmethod
    def hollow_box(cls, depth: float, width: float, wall: float, E: float, G: float) -> BeamSection:
        """A thin-walled rectangle ``depth`` (in the arm plane) × ``width`` with ``wall`` [m]."""
        if not 0 < 2 * wall < min(depth, width):
            raise InputError(f"wall {wall} m does not fit the box", field="section.wall")
        h, b, hi, bi = depth, width, depth - 2 * wall, width - 2 * wall
        A = b * h - bi * hi
        I_bend = (b * h**3 - bi * hi**3) / 12
        I_out = (h * b**3 - hi * bi**3) / 12
        # Bredt: J = 4 A_m² t / perimeter of the mid-line
        Am = (h - wall) * (b - wall)
        J = 4 * Am**2 * wall / (2 * ((h - wall) + (b - wall)))
        return cls(A, I_bend, I_out, J, E, G)

    @classmethod
    def tube(cls, diameter: float, wall: float, E: float, G: float) -> BeamSection:
        """A round tube, outer ``diameter`` and ``wall`` [m]."""
        if not 0 < 2 * wall < diameter:
            raise InputError(f"wall {wall} m does not fit the tube", field="section.wall")
        ro, ri = diameter / 2, diameter / 2 - wall
        A = math.pi * (ro**2 - ri**2)
        Ib = math.pi * (ro**4 - ri**4) / 4
        return cls(A, Ib, Ib, 2 * Ib, E, G)


@dataclass(frozen=True)
class LinkBeam:
    """One arm link: the beam from joint ``start`` to the origin of joint ``end`` (0-based
    joint indices of the chain), with its section."""

    name: str
    start: int
    end: int
    section: BeamSection


_E_CAST, _G_CAST = 169e9, 65e9
#: The IRB 7600's arm links (estimated sections, see the module docstring).
IRB7600_LINKS: tuple[LinkBeam, ...] = (
    LinkBeam("lower arm", 1, 2, BeamSection.hollow_box(0.320, 0.220, 0.016, _E_CAST, _G_CAST)),
    LinkBeam("upper arm", 2, 4, BeamSection.tube(0.240, 0.014, _E_CAST, _G_CAST)),
)


def cantilever_compliance(length: float, s: BeamSection) -> F64:
    """(6, 6) compliance of a cantilever's free end in the beam frame (x along the beam, y the
    in-plane bending axis, z = x × y), ordered [δ; θ] × [f; m], SI."""
    L, E, G = length, s.E, s.G
    C = np.zeros((6, 6))
    C[0, 0] = L / (E * s.area)
    C[3, 3] = L / (G * s.J_torsion)
    shear = L / (s.shear_factor * G * s.area)
    # force along z bends about y (the in-plane axis): I_bend; θy = −L²/2EI · Fz
    C[2, 2] = L**3 / (3 * E * s.I_bend) + shear
    C[4, 4] = L / (E * s.I_bend)
    C[2, 4] = C[4, 2] = -(L**2) / (2 * E * s.I_bend)
    # force along y bends about z: I_out; θz = +L²/2EI · Fy
    C[1, 1] = L**3 / (3 * E * s.I_out) + shear
    C[5, 5] = L / (E * s.I_out)
    C[1, 5] = C[5, 1] = L**2 / (2 * E * s.I_out)
    return C


def beam_chain_deflection(
    starts: F64,
    ends: F64,
    bend_axes: F64,
    sections: Sequence[BeamSection],
    tip: F64,
    wrench: F64,
) -> F64:
    """Tip deflection (N, 6) [m; rad] from the bending of clamped beams in series.

    Parameters
    ----------
    starts, ends : (N, B, 3) m — each beam's clamped start and loaded end
    bend_axes : (N, B, 3) — the in-plane bending axis (y of the beam frame; made orthogonal to
        the beam)
    sections : B sections
    tip : (N, 3) m — where the wrench acts and the deflection is wanted
    wrench : (N, 6) [N; N·m] — applied to the tip, same axes
    """
    out = np.zeros((tip.shape[0], 6))
    for b, sec in enumerate(sections):
        axis = ends[:, b] - starts[:, b]
        L = np.linalg.norm(axis, axis=1)
        if np.any(L <= 0):
            raise InputError("a link beam has zero length", field=f"beam {b}")
        x = axis / L[:, None]
        y = bend_axes[:, b] - np.einsum("ij,ij->i", bend_axes[:, b], x)[:, None] * x
        y /= np.linalg.norm(y, axis=1)[:, None]
        z = np.cross(x, y)
        R = np.stack([x, y, z], axis=2)  # (N, 3, 3): beam axes in base
        r = tip - ends[:, b]
        We = np.concatenate([wrench[:, :3], wrench[:, 3:] + np.cross(r, wrench[:, :3])], axis=1)
        Wl = _rot6(We, np.swapaxes(R, 1, 2))
        # beams of one chain have the same length in every pose; allow per-pose lengths anyway
        C = np.stack([cantilever_compliance(float(Li), sec) for Li in np.unique(L)])
        idx = np.searchsorted(np.unique(L), L)
        dl = np.einsum("nij,nj->ni", C[idx], Wl)
        de = _rot6(dl, R)
        out[:, :3] += de[:, :3] + np.cross(de[:, 3:], r)
        out[:, 3:] += de[:, 3:]
    return out


def link_deflection(
    model: RobotModel,
    q: ArrayLike,
    wrench: ArrayLike,
    T_base_work: ArrayLike | None = None,
    links: Sequence[LinkBeam] = IRB7600_LINKS,
) -> F64:
    """The links' share of the tip deflection (N, 6) [m; rad] at configurations ``q`` (N, 6) rad
    for tip wrenches (N, 6) [N; N·m]; both in work axes when ``T_base_work`` (4, 4) is given,
    else base axes. Add it to :meth:`RobotModel.deflection` (the joints' share)."""
    qv = model.check_q(q, limits=False)
    W = np.broadcast_to(np.asarray(wrench, dtype=float), (qv.shape[0], 6)).copy()
    R_bw = None
    if T_base_work is not None:
        R_bw = np.asarray(T_base_work, dtype=float)[:3, :3]
        W = rotate_6(W, R_bw)
    _, p, z, o = sweep(model.chain, qv, model.T_flange_tip, want_axes=True)
    assert z is not None and o is not None
    starts = np.stack([o[:, lk.start] for lk in links], axis=1)
    ends = np.stack([o[:, lk.end] for lk in links], axis=1)
    axes = np.stack([z[:, lk.start] for lk in links], axis=1)
    d = beam_chain_deflection(starts, ends, axes, [lk.section for lk in links], p, W)
    if R_bw is not None:
        d = rotate_6(d, R_bw.T)
    return d
