"""``roboisf part``: write a part TOML file (the nominal geometry other commands reuse).

Examples::

    roboisf part cone --opening-diameter 87 --wall-angle 71 --depth 102.97 -o cone.toml
    roboisf part vwacf --opening-diameter 88.15 --arc-radius 40 -o vwacf.toml
    roboisf part profile profile.csv -o part.toml     # the TOML refers to the CSV
    roboisf part pyramid --top-length 150 --top-width 150 --wall-angle 60 --depth 50 \\
        --corner-radius 10 -o pyramid.toml
    roboisf part mesh dome.stl -o dome.toml           # or .obj/.ply/.step/.iges
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from roboisf import parts  # lazy: the geometry loads when a command builds a part
from roboisf.cli.console import state
from roboisf.cli.lazy import FullHelpGroup
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError
from roboisf.io.atomic import check_not_input
from roboisf.parts.defaults import PAPER_SHEET_THICKNESS, VWACF_DEFAULT_ARC_RADIUS

if TYPE_CHECKING:  # the geometry (numpy, scipy) is imported by the command that runs
    from roboisf.parts import AxisymmetricPart, Part

__all__ = ["register"]

Output = Annotated[
    Path, typer.Option("--output", "-o", help=f"Part file to write (.toml). {FILE_HELP}")
]
# part dimensions, shared with ``roboisf toolpath`` (mm, deg)
ConeDiameter = Annotated[float, typer.Option(help="Wall diameter at the sheet [mm].")]
WallAngle = Annotated[float, typer.Option(help="Wall angle, 0 < α < 90 [deg].")]
Depth = Annotated[float, typer.Option(help="Part depth [mm].")]
VwacfDiameter = ConeDiameter
ArcRadius = Annotated[float, typer.Option(help="Radius of the circular-arc generatrix [mm].")]
FinalWallAngle = Annotated[float, typer.Option(help="Wall angle at the bottom [deg].")]
ProfileCsv = Annotated[Path, typer.Argument(help="Generatrix CSV with header r,z (mm), rim first.")]
Sheet = Annotated[float, typer.Option(help="Initial sheet thickness [mm].")]
Flange = Annotated[float, typer.Option(help="Flange width outside the opening [mm].")]

TopLength = Annotated[float, typer.Option(help="Opening along x at the sheet plane [mm].")]
TopWidth = Annotated[float, typer.Option(help="Opening along y at the sheet plane [mm].")]
PyrWallAngle = Annotated[
    float, typer.Option(help="Wall angle of the x-walls (and y-walls), 0 < α < 90 [deg].")
]
PyrWallAngleY = Annotated[
    float | None,
    typer.Option(
        help="Wall angle of the y-walls [deg] (default: --wall-angle; needs "
        "--corner-radius 0 if different)."
    ),
]
CornerRadius = Annotated[
    float,
    typer.Option(
        help="Rounding of the opening's corners about vertical axes [mm]; it shrinks with the "
        "wall (corners are cones of the wall angle, sharp below depth r·tan α)."
    ),
]
MeshFile = Annotated[
    Path, typer.Argument(help="Nominal surface: STL, OBJ, PLY, or STEP/IGES (tessellated).")
]
MeshUnit = Annotated[str, typer.Option(help="Length unit of the mesh coordinates (mm, m, in).")]
MeshOrient = Annotated[
    str,
    typer.Option(help="'up': flip faces so normals point up (tool side); 'winding': keep them."),
]
Tolerance = Annotated[
    float,
    typer.Option(
        help="STEP/IGES only: max. distance of the tessellation from the CAD surface [mm]."
    ),
]

part_app = typer.Typer(
    help="Write a part file (TOML, mm and degrees).", no_args_is_help=True, cls=FullHelpGroup
)


def _save(make: Callable[[], Part], output: Path, inputs: list[Path], overwrite: bool) -> Part:
    if output.suffix.lower() != ".toml":
        raise InputError("a part file must end in .toml", file=output)
    check_not_input(output, inputs)
    output_file(output, "part", overwrite, inputs)
    part = make()
    parts.save_part(part, output)
    state.info(f"wrote {output}: {part.kind}, depth {part.depth * 1e3:.3f} mm")
    return part


@part_app.command("cone")
def _cone(
    output: Output,
    opening_diameter: ConeDiameter = 87.0,
    wall_angle: WallAngle = 71.0,
    depth: Depth = 102.97,
    sheet_thickness: Sheet = PAPER_SHEET_THICKNESS * 1e3,
    flange_width: Flange = 10.0,
    overwrite: Overwrite = False,
) -> None:
    """Truncated cone (defaults: the paper's Ø87 mm, 71°, 102.97 mm)."""
    _save(
        lambda: parts.Cone(
            opening_diameter * 1e-3,
            math.radians(wall_angle),
            depth * 1e-3,
            sheet_thickness=sheet_thickness * 1e-3,
            flange_width=flange_width * 1e-3,
        ),
        output,
        [],
        overwrite,
    )


@part_app.command("vwacf")
def _vwacf(
    output: Output,
    opening_diameter: VwacfDiameter = 88.15,
    arc_radius: ArcRadius = VWACF_DEFAULT_ARC_RADIUS * 1e3,
    final_wall_angle: FinalWallAngle = 90.0,
    sheet_thickness: Sheet = PAPER_SHEET_THICKNESS * 1e3,
    flange_width: Flange = 10.0,
    overwrite: Overwrite = False,
) -> None:
    """Variable-wall-angle frustum (defaults: Ø88.15 mm, 39 mm arc, 0° → 90°)."""
    _save(
        lambda: parts.VWACF(
            opening_diameter * 1e-3,
            arc_radius * 1e-3,
            math.radians(final_wall_angle),
            sheet_thickness=sheet_thickness * 1e-3,
            flange_width=flange_width * 1e-3,
        ),
        output,
        [],
        overwrite,
    )


@part_app.command("profile")
def _profile(
    profile: ProfileCsv,
    output: Output,
    sheet_thickness: Sheet = PAPER_SHEET_THICKNESS * 1e3,
    flange_width: Flange = 10.0,
    overwrite: Overwrite = False,
) -> None:
    """Part from a generatrix CSV; the TOML stores the CSV's path relative to itself."""

    def make() -> AxisymmetricPart:
        from roboisf.parts import ProfilePart, read_profile_csv

        r, z = read_profile_csv(profile)
        rel = os.path.relpath(profile.resolve(), output.resolve().parent)
        return ProfilePart(
            r=tuple(r),
            z=tuple(z),
            source=Path(rel).as_posix(),
            sheet_thickness=sheet_thickness * 1e-3,
            flange_width=flange_width * 1e-3,
        )

    _save(make, output, [profile], overwrite)


@part_app.command("pyramid")
def _pyramid(
    output: Output,
    top_length: TopLength = 150.0,
    top_width: TopWidth = 150.0,
    wall_angle: PyrWallAngle = 60.0,
    depth: Depth = 50.0,
    corner_radius: CornerRadius = 10.0,
    wall_angle_y: PyrWallAngleY = None,
    sheet_thickness: Sheet = PAPER_SHEET_THICKNESS * 1e3,
    flange_width: Flange = 10.0,
    overwrite: Overwrite = False,
) -> None:
    """Truncated pyramid, square or rectangular, flat bottom (docs/parts.md)."""
    _save(
        lambda: parts.Pyramid(
            top_length * 1e-3,
            top_width * 1e-3,
            math.radians(wall_angle),
            depth * 1e-3,
            wall_angle_y=None if wall_angle_y is None else math.radians(wall_angle_y),
            corner_radius=corner_radius * 1e-3,
            sheet_thickness=sheet_thickness * 1e-3,
            flange_width=flange_width * 1e-3,
        ),
        output,
        [],
        overwrite,
    )


@part_app.command("mesh")
def _mesh(
    mesh: MeshFile,
    output: Output,
    unit: MeshUnit = "mm",
    orient: MeshOrient = "up",
    tolerance: Tolerance = 0.01,
    sheet_thickness: Sheet = PAPER_SHEET_THICKNESS * 1e3,
    overwrite: Overwrite = False,
) -> None:
    """Any part from a mesh or CAD file (work frame: sheet plane z = 0, part below); the TOML
    stores the file's path relative to itself. The surface must be the tool-side surface."""

    def make() -> Part:
        from roboisf.parts import MeshPart

        rel = Path(os.path.relpath(mesh.resolve(), output.resolve().parent)).as_posix()
        return MeshPart.from_file(
            mesh,
            unit=unit,
            orient=orient,
            sheet_thickness=sheet_thickness * 1e-3,
            source=rel,
            tolerance=tolerance * 1e-3,
        )

    lo, hi = _save(make, output, [mesh], overwrite).bounds
    if abs(hi[2]) > 0.1e-3 or lo[2] >= 0:
        state.warn(
            f"the mesh spans z = {lo[2] * 1e3:.3f} … {hi[2] * 1e3:.3f} mm; roboisf expects the "
            "work frame: the sheet plane at z = 0 and the part below it"
        )


def register(app: typer.Typer) -> None:
    """Add ``roboisf part`` to ``app``."""
    app.add_typer(part_app, name="part")
