"""``roboisf scan …``: compare a laser scan with the nominal part (and a toolpath)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from roboisf.cli.console import state
from roboisf.cli.lazy import FullHelpGroup
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError

__all__ = ["register"]

scan_app = typer.Typer(
    help="Laser scans vs the nominal part: registration and signed deviation vectors.",
    no_args_is_help=True,
    cls=FullHelpGroup,
)


@scan_app.command("compare")
def compare(
    scan: Path = typer.Argument(..., help="Scan file: PLY, PCD, XYZ/CSV/TXT, STL/OBJ."),
    part: Path = typer.Option(..., "--part", "-p", help="Part TOML (cone, vwacf, profile, mesh)."),
    output: Path = typer.Option(
        ...,
        "--output",
        "-o",
        help="Deviation table: .parquet or .csv. Per toolpath point with --toolpath, else per "
        f"scan point (selected wall points). {FILE_HELP}",
    ),
    overwrite: Overwrite = False,
    toolpath: Path | None = typer.Option(
        None,
        "--toolpath",
        "-t",
        help="Toolpath: deviations per contact point. A roboisf toolpath CSV, or a CAM program "
        "(G-code, Sinumerik .mpf, APT/CL, x,y,z list; it names the ball tip) imported against "
        "--part with --tool-diameter.",
    ),
    tool_diameter: float | None = typer.Option(
        None,
        "--tool-diameter",
        help="Ball diameter [mm], to import a CAM program given as --toolpath.",
    ),
    register: str = typer.Option(
        "fixture",
        "--register",
        "-r",
        help="Registration, any part: fixture (default, as analyze: z and the two tilts from "
        "the flange) | flange (z, tilts from the flange; x, y, rz from the wall) | "
        "axisymmetric | icp (6 DOF on the surface) | none. A symmetry about z (declared, or "
        "detected on a mesh) locks rz (continuous) or makes it defined modulo 360°/n (n-fold; "
        "reported).",
    ),
    rz_hint: float | None = typer.Option(
        None,
        "--rz-hint",
        help="n-fold symmetric part: report the rotation about z nearest to this angle, "
        "degrees (default: nearest to 0, |rz| ≤ 180°/n).",
    ),
    rim_band: float | None = typer.Option(
        None,
        help="Rim band excluded below the sheet plane, mm (sheet bending at the clamp). "
        "Default: min(20, 0.6 × part depth) — the paper's 20 mm, capped on shallow parts.",
    ),
    unit: str = typer.Option("mm", "--unit", "-u", help="Length unit of the scan file."),
    max_distance: float = typer.Option(
        3.0, help="Points farther from the nominal are not the part [mm]."
    ),
    radius: float = typer.Option(1.0, help="Radius around each contact's normal line [mm]."),
    min_points: int = typer.Option(5, help="Fewer scan points at a contact: a hole."),
    estimator: str = typer.Option("median", help="Robust average: median | trimmed."),
    outlier_k: int = typer.Option(8, help="Neighbours of the outlier filter (0: off)."),
    outlier_std: float = typer.Option(3.0, help="Outlier threshold in standard deviations."),
    bin_width: float = typer.Option(0.5, help="z-level bin width of the summary [mm]."),
    contour_z: float = typer.Option(-11.0, help="Contour of the polar summary [mm]."),
    angle_bin: float = typer.Option(5.0, help="Angle bin of the polar summary [deg]."),
    sample: int | None = typer.Option(
        None, help="Mesh scans (STL/OBJ): sample this many points on the faces."
    ),
    summary: Path | None = typer.Option(
        None, help="JSON summary path (default: next to the output, <stem>.summary.json)."
    ),
    points_output: Path | None = typer.Option(
        None, "--points", help="Also write the per-scan-point table (.parquet or .csv)."
    ),
) -> None:
    """Signed deviations of a scan from the nominal, per scan point and per toolpath point.

    Sign: dn > 0 where the scanned material sits on the tool side of the nominal; the vector
    (dx, dy, dz) = dn · n along the nominal's tool-side normal, work frame, mm.
    """
    from roboisf.parts.io import load_part
    from roboisf.scan.compare import CompareOptions, compare_scan
    from roboisf.scan.output import (
        POINT_COLUMNS,
        TOOLPATH_COLUMNS,
        point_table,
        toolpath_table,
        write_summary_json,
        write_table,
    )
    from roboisf.scan.readers import read_scan

    summary_path = summary or output.with_name(output.stem + ".summary.json")
    outputs = [output, summary_path] + ([points_output] if points_output else [])
    inputs: list[str | Path] = [scan, part]
    if toolpath:
        inputs.append(toolpath)
    from roboisf.io.atomic import check_not_input

    for out in outputs:
        check_not_input(out, inputs)
    if len({p.resolve() for p in outputs}) < len(outputs):
        raise InputError("the output, summary and --points files must differ", file=output)
    for out in outputs:
        output_file(out, "scan compare", overwrite, inputs)
    for out in [output] + ([points_output] if points_output else []):
        if out.suffix.lower() not in (".parquet", ".pq", ".csv"):
            raise InputError("expected a .parquet or .csv table", file=out)
    nominal = load_part(part)
    tp = None
    if toolpath is not None:
        from roboisf.toolpath.importer import read_toolpath_file

        if tool_diameter is not None and not (math.isfinite(tool_diameter) and tool_diameter > 0):
            raise InputError(
                f"expected a ball diameter > 0 mm, got {tool_diameter}", field="--tool-diameter"
            )
        ball_r = None if tool_diameter is None else tool_diameter * 0.5e-3
        tp = read_toolpath_file(toolpath, nominal, ball_r)
    opts = CompareOptions(
        register=register,
        rim_band=None if rim_band is None else rim_band * 1e-3,
        max_distance=max_distance * 1e-3,
        outlier_k=outlier_k,
        outlier_std=outlier_std,
        radius=radius * 1e-3,
        min_points=min_points,
        estimator=estimator,
        bin_width=bin_width * 1e-3,
        contour_z=contour_z * 1e-3,
        angle_bin=math.radians(angle_bin),
        register_kwargs={} if rz_hint is None else {"rz_hint": math.radians(rz_hint)},
    )
    progress = state.progress()
    cloud = read_scan(scan, unit=unit, sample=sample)
    state.debug(f"read {cloud.n_points} points from {scan}")
    tp_src = str(toolpath) if toolpath else None
    res = compare_scan(
        cloud,
        nominal,
        toolpath=tp,
        toolpath_source=tp_src,
        options=opts,
        progress=progress,
        consume=True,  # the raw points freed once sorted: cloud.points is not used below
    )
    reg = res.registration
    if reg.dof:
        state.info(
            f"registration {reg.method}: shift {shift_mm(reg.translation)} mm, "
            f"tilt {math.degrees(reg.tilt):.4f}°, rms {reg.rms * 1e3:.4f} mm, "
            f"overlap {reg.overlap:.1%}"
        )
        state.info(f"registration {reg.describe()}")
    if res.toolpath is not None:
        t = res.toolpath
        if (~t.valid).any():
            state.warn(
                f"{int((~t.valid).sum())} of {t.valid.size} toolpath points have no deviation "
                "(rim band or holes in the scan): valid = false"
            )
        write_table(toolpath_table(t), output, TOOLPATH_COLUMNS, "toolpath_deviations")
    assert res.points is not None  # compare_scan's own result keeps them
    if res.toolpath is None:
        write_table(point_table(res.points), output, POINT_COLUMNS, "point_deviations")
    if points_output is not None:
        write_table(point_table(res.points), points_output, POINT_COLUMNS, "point_deviations")
    s = res.summary()
    s["inputs"] = {"scan": str(scan), "part": str(part), "toolpath": tp_src, "unit": unit}
    write_summary_json(s, summary_path)
    pts = s["points"]
    state.info(
        f"{res.counts['used']} wall points: mean |dn| {pts['mean_abs_dn_mm']:.4f} mm, "
        f"R_m {pts['R_m_mm']:.4f} mm → {output}, {summary_path}"
    )


def register(app: typer.Typer) -> None:
    """Add the ``scan`` command group to the root app."""
    app.add_typer(scan_app, name="scan")


def shift_mm(translation: Any) -> str:
    """ "x, y, z" of a registration's translation (3,) m in mm to 0.1 µm — a locked shift left
    at ±1e-13 m by a tilt about the flange reads 0.0000, not -0.0000."""
    return ", ".join(f"{round(float(v) * 1e3, 4) + 0.0:.4f}" for v in translation)
