"""Fabricated studies in the report's data contract, so the report tests need no analysis.

``make_study()`` builds a 71° cone (Ø87 mm opening, 0.5 mm step-down) with smooth synthetic fields
of roughly the paper's sizes (tool ≈ 0.14 mm in plane, springback ≈ 0.7 mm xy / 0.5 mm z, robot
compliance growing 0.3 → 1.3 mm with depth) and returns ``(per_point, contributions,
contributions_normal, summary)`` exactly as ``roboisf analyze`` hands them to the report.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

FACTORS = ("tool", "tool_holder", "springback", "robot_compliance")


def _table(vectors: dict[str, np.ndarray]) -> pd.DataFrame:
    """Paper's Table 5 from per-point (N, 3) vectors, mm: mean |δ| per axis, R_m (eq. 6), share."""
    rows = []
    for name, v in vectors.items():
        m = np.nanmean(np.abs(v), axis=0)
        rows.append([name, *m, float(np.sqrt(np.sum(m**2)))])
    total_rm = sum(r[4] for r in rows)
    total = np.nansum([vectors[f] for f in FACTORS], axis=0)
    mt = np.nanmean(np.abs(total), axis=0)
    rows = [[*r, 100.0 * r[4] / total_rm] for r in rows]
    rows.append(["total", *mt, float(np.sqrt(np.sum(mt**2))), 100.0])
    return pd.DataFrame(
        rows,
        columns=["factor", "mean_abs_dx", "mean_abs_dy", "mean_abs_dz", "R_m", "share_percent"],
    )


def square_lap(
    a: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Point at fraction ``t`` ∈ [0, 1) of the perimeter of the square of half-width ``a``,
    starting at (a, 0), counter-clockwise: ``x, y`` and the side's outward unit direction
    ``ex, ey`` (arc length ``8·a·t`` from the start)."""
    u = 8.0 * np.asarray(t, dtype=float)  # arc length in units of a
    a = np.broadcast_to(np.asarray(a, dtype=float), u.shape)
    x, y, ex, ey = (np.zeros_like(u) for _ in range(4))
    sides = [  # (start of the side in units of a, start point, direction of travel, outward)
        (0.0, (1.0, 0.0), (0.0, 1.0), (1.0, 0.0)),
        (1.0, (1.0, 1.0), (-1.0, 0.0), (0.0, 1.0)),
        (3.0, (-1.0, 1.0), (0.0, -1.0), (-1.0, 0.0)),
        (5.0, (-1.0, -1.0), (1.0, 0.0), (0.0, -1.0)),
        (7.0, (1.0, -1.0), (0.0, 1.0), (1.0, 0.0)),
    ]
    for u0, p0, d, e in sides:
        m = u >= u0
        x[m] = a[m] * (p0[0] + d[0] * (u[m] - u0))
        y[m] = a[m] * (p0[1] + d[1] * (u[m] - u0))
        ex[m], ey[m] = e
    return x, y, ex, ey


def make_study(
    n_laps: int = 200,
    points_per_lap: int = 150,
    *,
    truth: bool = True,
    measured_thickness: bool = True,
    seed: int = 0,
    name: str = "cone-71",
    shape: str = "cone",
) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """``shape="pyramid"``: a square 71° pyramid (43.5 mm top half-width, sharp corners), each lap
    ``points_per_lap`` points at equal arc length from the middle of the +x side,
    counter-clockwise; the fields use the wall's outward direction where the cone uses the radial
    one. The summary then names ``kind = "pyramid"`` and ``part_symmetry = 4``."""
    rng = np.random.default_rng(seed)
    alpha = np.radians(71.0)
    step = 102.97 / max(n_laps, 1) if n_laps < 150 else 0.5
    lap = np.repeat(np.arange(n_laps), points_per_lap)
    k = np.tile(np.arange(points_per_lap), n_laps)
    phi = 2 * np.pi * k / points_per_lap
    depth = step * (lap + 1) + step * k / points_per_lap  # a touch of spiral within the lap
    r = 43.5 - depth / np.tan(alpha)
    if shape == "pyramid":
        x, y, c, s = square_lap(r, k / points_per_lap)
        contact = np.column_stack([x, y, -depth])
        phi = np.arctan2(y, x) % (2 * np.pi)
    else:
        c, s = np.cos(phi), np.sin(phi)
        contact = np.column_stack([r * c, r * s, -depth])
    normal = np.column_stack(
        [-np.sin(alpha) * c, -np.sin(alpha) * s, np.full_like(c, np.cos(alpha))]
    )
    seg = np.linalg.norm(np.diff(contact, axis=0, prepend=contact[:1]), axis=1)
    time = np.cumsum(seg) / 12.5  # 750 mm/min

    n = len(lap)
    fz = 470.0 * (1 - np.exp(-depth / 6.0)) + rng.normal(0, 6, n)
    fr, ft = 0.32 * fz, 0.12 * fz
    radial = np.column_stack([c, s, np.zeros(n)])
    tangential = np.column_stack([-s, c, np.zeros(n)])
    f_cnc = radial * fr[:, None] + tangential * ft[:, None] + np.column_stack([0 * c, 0 * c, fz])
    f_rob = f_cnc * 0.96 + rng.normal(0, 4, (n, 3))
    m_cnc = rng.normal(0, 0.05, (n, 3)) + 0.002 * f_cnc[:, [1, 0, 2]]
    m_rob = m_cnc + rng.normal(0, 0.05, (n, 3))

    def dn(v: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", v, normal)

    d_tool = np.column_stack([9.34e-4 * f_rob[:, 0], 9.34e-4 * f_rob[:, 1], -4.45e-6 * f_rob[:, 2]])
    d_holder = np.column_stack(
        [1.07e-4 * f_rob[:, 0], 1.07e-4 * f_rob[:, 1], -9.45e-7 * f_rob[:, 2]]
    )
    sb = 0.72 * (0.7 + 0.3 * np.sin(depth / 20.0))
    d_spring = np.column_stack([sb * c, sb * s, 0.49 * (0.8 + 0.2 * np.cos(depth / 30.0))])
    mag = 0.3 + 1.0 * depth / 102.97
    d_robot = np.column_stack(
        [mag * (0.8 * c + 0.3), mag * 0.55 * s, 0.16 * (depth / 102.97) * np.cos(phi - 0.6)]
    )
    d_vjm = d_robot + np.column_stack([0.05 + 0.02 * c, -0.03 + 0.02 * s, 0.02 * np.ones(n)])

    noise = rng.normal(0, 0.025, n)
    cnc_n = dn(d_spring + d_tool + d_holder * 0) + noise
    rob_n = dn(d_spring + d_tool + d_holder + d_robot) + rng.normal(0, 0.025, n)
    holes = (depth > 40) & (depth < 46) & (np.degrees(phi) > 100) & (np.degrees(phi) < 125)
    cnc_valid = ~holes
    rob_valid = ~(
        holes | ((depth > 70) & (depth < 73) & (np.degrees(phi) > 250) & (np.degrees(phi) < 270))
    )

    df: dict[str, Any] = {
        "index": np.arange(n),
        "lap": lap,
        "time": time,
        "angle_deg": np.degrees(phi),
        "depth": depth,
        "contact_x": contact[:, 0],
        "contact_y": contact[:, 1],
        "contact_z": contact[:, 2],
        "normal_x": normal[:, 0],
        "normal_y": normal[:, 1],
        "normal_z": normal[:, 2],
        "wall_angle_deg": np.full(n, 71.0),
    }
    for run, f, m in (("cnc", f_cnc, m_cnc), ("robot", f_rob, m_rob)):
        for i, comp in enumerate("xyz"):
            df[f"{run}_F{comp}"] = f[:, i]
            df[f"{run}_M{comp}"] = m[:, i]
    for run, nval, valid, n_pts in (
        ("cnc", cnc_n, cnc_valid, rng.poisson(40, n)),
        ("robot", rob_n, rob_valid, rng.poisson(40, n)),
    ):
        vec = nval[:, None] * normal
        vec[~valid] = np.nan
        for i, comp in enumerate("xyz"):
            df[f"{run}_d{comp}"] = vec[:, i]
        df[f"{run}_dn"] = np.where(valid, nval, np.nan)
        df[f"{run}_n_points"] = np.where(valid, n_pts, 0)
        df[f"{run}_valid"] = valid

    est_noise = rng.normal(0, 0.008, n)
    terms = {
        "tool": d_tool,
        "tool_holder": d_holder,
        "springback": d_spring + est_noise[:, None] * normal,
        "robot_compliance": d_robot - est_noise[:, None] * normal,
        "vjm": d_vjm,
    }
    terms["delta"] = terms["robot_compliance"] - d_vjm
    for name_, v in terms.items():
        v = v.copy()
        if name_ == "springback":
            v[~cnc_valid] = np.nan
        if name_ in ("robot_compliance", "delta"):
            v[~(cnc_valid & rob_valid)] = np.nan
        for i, comp in enumerate("xyz"):
            df[f"{name_}_d{comp}"] = v[:, i]
        df[f"{name_}_dn"] = dn(v)
    df["thickness_predicted"] = 1.22 * np.cos(np.radians(df["wall_angle_deg"]))
    if measured_thickness:
        df["thickness_measured"] = (
            0.397
            + 0.8 * np.exp(-depth / 4.0)
            - 0.12 * np.exp(-((depth - 8) ** 2) / 20)
            + rng.normal(0, 0.01, n)
        )
    if truth:
        for name_, v in (
            ("tool", d_tool),
            ("tool_holder", d_holder),
            ("springback", d_spring),
            ("robot_compliance", d_robot),
        ):
            df[f"truth_{name_}_dn"] = dn(v)
    per_point = pd.DataFrame(df)

    valid = cnc_valid & rob_valid
    vecs = {f: terms[f][valid] for f in FACTORS}
    contributions = _table(vecs)
    contributions_normal = _table(
        {f: (dn(terms[f]) * valid)[valid, None] * normal[valid] for f in FACTORS}
    )

    delta = terms["delta"][valid].mean(axis=0)
    kstats = {}
    for key, mean in {
        "k_11": 1.9e-6,
        "k_22": 1.2e-6,
        "k_33": 4.1e-7,
        "k_23": -2.3e-7,
        "k_13": 1.1e-7,
        "k_44": 3.1e-6,
        "k_55": 2.9e-6,
        "k_66": 2.2e-6,
    }.items():
        kstats[key] = {
            "mean": mean,
            "std": abs(mean) * 0.08,
            "min": mean * 0.85,
            "max": mean * 1.15,
        }
    fc = {}
    for ax, row in zip(
        ("dx", "dy", "dz"), (f_rob.mean(0), f_rob.mean(0), f_rob.mean(0)), strict=True
    ):
        fc[ax] = {
            "Fx": float(1.9e-3 * abs(row[0]) + 0.2),
            "Fy": float(0.2e-3 * abs(row[1]) + 0.05),
            "Fz": float(-0.23e-3 * row[2] if ax == "dy" else 0.1e-3 * row[2]),
            "Mx": 4e-5,
            "My": -2e-5,
            "Mz": 1e-5,
        }
    summary: dict[str, Any] = {
        "study": name,
        "part": {
            "kind": "cone",
            "dims": {"wall_angle_deg": 71.0, "opening_diameter_mm": 87.0, "depth_mm": 102.97},
        }
        if shape != "pyramid"
        else {
            "kind": "pyramid",
            "dims": {"wall_angle_deg": 71.0, "top_length_mm": 87.0, "depth_mm": 102.97},
        },
        "robot": {
            "preset": "abb_irb7600_500_255",
            "placement": {"x_mm": 1800.0, "y_mm": 0.0, "z_mm": 600.0, "yaw_deg": 0.0},
        },
        "tool": {"diameter_mm": 10.0, "free_length_mm": 63.0},
        "units": {"length": "mm", "angle": "deg", "force": "N", "moment": "N*m", "time": "s"},
        "compliance_stats": kstats,
        "force_contributions": fc,
        "vjm_vs_experiment": {
            "x": float(delta[0]),
            "y": float(delta[1]),
            "z": float(delta[2]),
            "resultant": float(np.linalg.norm(delta)),
        },
        "contour_z": -11.0,
        "warnings": ["robot scan: 2 holes (3.1 % of the wall) — deviations there are left out"],
    }
    if shape == "pyramid":
        summary["part_symmetry"] = 4
    return per_point, contributions, contributions_normal, summary


def with_two_wall_angles(per_point: pd.DataFrame) -> pd.DataFrame:
    """A copy of a pyramid's ``per_point`` (``make_study(shape="pyramid")``) with 45° walls
    facing ±x and 65° walls facing ±y and their sine-law thickness: 1.22·cos 45° = 0.863 mm on
    one pair of walls, 0.516 mm on the other."""
    pp = per_point.copy()
    x_wall = np.abs(pp["normal_x"]) > np.abs(pp["normal_y"])
    pp["wall_angle_deg"] = np.where(x_wall, 45.0, 65.0)
    pp["thickness_predicted"] = 1.22 * np.cos(np.radians(pp["wall_angle_deg"]))
    return pp
