"""The paper's error decomposition (Bharti et al. 2024, Tables 4–5), on per-toolpath-point arrays.

    δ_R = δc + δs + δt + δth                      (superposition, eq. 1)
    δs  = δ_CNC − δt,CNC                          (CNC taken as rigid)
    δc,exp = δ_robot − δs − δt,robot − δth,robot
    Δ   = δc,exp − δc,VJM

Two bookkeepings, both reported:

* **per-axis vectors (the paper's way)** — scan deviations are vectors ``dn · n`` (a scan only
  observes the normal component), the tool/holder/VJM deflections are full model vectors. The
  tangential parts of the model vectors do not cancel in the differences, so δs and δc,exp carry
  them; this is how the paper's Table 5 was built.
* **normal projection (what a scan observes)** — every term projected on the nominal normal; the
  decomposition is then exact for what the scans can see.

Shares: each factor's resultant mean deviation ``R_m = sqrt(mean|δx|² + mean|δy|² + mean|δz|²)``
(eq. 6) over the sum of the factors' R_m; the ``total`` row is the robot part's measured deviation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.scan.summary import resultant_mean_deviation

__all__ = [
    "FACTORS",
    "Decomposition",
    "contribution_rows",
    "decompose",
    "resultant_mean_deviation",
]

F64 = NDArray[np.float64]
B = NDArray[np.bool_]

#: Contribution factors, in report order.
FACTORS = ("tool", "tool_holder", "springback", "robot_compliance")


@dataclass(frozen=True)
class Decomposition:
    """Per-point contributions, (N, 3) vectors [m] and (N,) normal components [m].

    ``vectors[f]`` the paper's way, ``normal[f]`` projected on the nominal normal, for each factor
    in :data:`FACTORS` plus ``vjm``, ``delta`` (= robot_compliance − vjm), ``cnc`` and ``robot``
    (the measured deviations). ``valid`` marks points both scans cover and outside the rim band.
    """

    vectors: dict[str, F64]
    normal: dict[str, F64]
    valid: B
    n: F64


def decompose(
    normal: F64,
    dn_cnc: F64,
    dn_robot: F64,
    tool_cnc: F64,
    tool_robot: F64,
    holder_robot: F64,
    vjm: F64,
    valid: B,
    command: F64 | None = None,
) -> Decomposition:
    """Split the robot part's deviation into its contributions.

    Parameters
    ----------
    normal : (N, 3) — unit tool-side normals of the nominal at the toolpath points
    dn_cnc, dn_robot : (N,) m — measured normal deviations (+ material on the tool side)
    tool_cnc, tool_robot : (N, 3) m — tool-tip deflection by the tool, under each run's wrench
    holder_robot : (N, 3) m — tool-holder deflection at the tip, robot run (the CNC holder is
        taken as rigid, like the CNC)
    vjm : (N, 3) m — robot deflection predicted by the VJM
    valid : (N,) bool — points to use
    command : (N, 3) m, optional — the robot run's commanded tip minus the nominal tip (a
        compensated command): what the robot part deviates by design. What a scan sees of it,
        its normal part ``(command · n) n``, is taken out of the robot compliance term in both
        books and kept as ``vectors["command"]`` (zeros when None). Its tangential part moves
        the contact along the surface, which no scan observes: taken out of the per-axis book
        it would put the command's own (the model's) tangential deflection into the measured
        robot term, and a compensated run's per-axis robot share would jump against the first
        run's for the same robot (20 → 32 % on a virtual cone; docs/compensate.md §6).
    """
    n = np.asarray(normal, dtype=float)
    N = n.shape[0]
    for name, a, shape in (
        ("dn_cnc", dn_cnc, (N,)),
        ("dn_robot", dn_robot, (N,)),
        ("tool_cnc", tool_cnc, (N, 3)),
        ("tool_robot", tool_robot, (N, 3)),
        ("holder_robot", holder_robot, (N, 3)),
        ("vjm", vjm, (N, 3)),
        ("valid", valid, (N,)),
        *((("command", command, (N, 3)),) if command is not None else ()),
    ):
        if np.shape(a) != shape:
            raise InputError(f"expected shape {shape}, got {np.shape(a)}", field=name)
    cnc = dn_cnc[:, None] * n
    rob = dn_robot[:, None] * n
    springback = cnc - tool_cnc
    cmd = np.zeros_like(rob)
    if command is not None:  # what the scans can see of the command: its normal part
        cmd = np.einsum("ij,ij->i", np.asarray(command, dtype=float), n)[:, None] * n
    robot_c = rob - springback - tool_robot - holder_robot - cmd
    vectors = {
        "tool": tool_robot,
        "tool_holder": holder_robot,
        "springback": springback,
        "robot_compliance": robot_c,
        "vjm": vjm,
        "delta": robot_c - vjm,
        "cnc": cnc,
        "robot": rob,
        "command": cmd,
    }
    normal_c = {k: np.einsum("ij,ij->i", v, n) for k, v in vectors.items()}
    return Decomposition(vectors, normal_c, np.asarray(valid, dtype=bool), n)


def contribution_rows(d: Decomposition, *, projected: bool) -> list[dict[str, float | str]]:
    """Table 5 rows: ``factor, mean_abs_dx, mean_abs_dy, mean_abs_dz, R_m, share_percent`` [m, %].

    ``projected=True`` uses the normal projections as vectors ``dn · n``.
    """
    sel = d.valid
    if not np.any(sel):
        raise InputError("no toolpath point is covered by both scans outside the rim band")

    def vec(f: str) -> F64:
        if projected:
            return (d.normal[f][:, None] * d.n)[sel]
        return d.vectors[f][sel]

    rows: list[dict[str, float | str]] = []
    rms = {f: resultant_mean_deviation(vec(f)) for f in FACTORS}
    total = sum(rms.values())
    for f in (*FACTORS, "robot"):
        v = vec(f)
        m = np.mean(np.abs(v), axis=0)
        rows.append(
            {
                "factor": "total" if f == "robot" else f,
                "mean_abs_dx": float(m[0]),
                "mean_abs_dy": float(m[1]),
                "mean_abs_dz": float(m[2]),
                "R_m": float(np.sqrt(np.sum(m**2))),
                "share_percent": 100.0
                if f == "robot"
                else (100.0 * rms[f] / total if total > 0 else 0.0),
            }
        )
    return rows
