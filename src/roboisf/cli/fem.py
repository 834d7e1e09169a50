"""``roboisf tool-stiffness`` and ``roboisf holder-stiffness``: 6×6 compliance JSON files.

Lengths in mm, moduli in GPa on the command line; the JSON file is SI.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError
from roboisf.io.atomic import check_not_input

if TYPE_CHECKING:  # the FE code (numpy, scipy) is imported by the command that runs
    from roboisf.fem.geometry import HolderSection
    from roboisf.fem.material import Material
    from roboisf.fem.result import ComplianceResult

__all__ = ["register"]

MM = 1e-3

# options both commands share
_E = typer.Option(210.0, "--E", help="Young's modulus (GPa).")
_NU = typer.Option(0.3, "--nu", help="Poisson's ratio.")
_METHOD = typer.Option("fe", help="fe (finite elements) or beam (Timoshenko).")
_NO_FE = typer.Option(False, "--no-fe", help="Same as --method beam.")
_CONVERGENCE = typer.Option(True, help="Also solve at 2× the element size (Richardson).")
_SOLVER = typer.Option("auto", help="auto, pardiso or superlu.")


def _material(E_gpa: float, nu: float, name: str = "steel") -> Material:
    from roboisf.fem.material import Material
    from roboisf.plausible import check_plausible

    # --E 210e9 (Pa for GPa) gave a tool 1e9 times too stiff, written without a word
    check_plausible(E_gpa, "youngs_modulus", field="--E")
    return Material(E=E_gpa * 1e9, nu=nu, name=name)


def _check_mm(flag: str, value: float | None, *, zero: bool = False) -> None:
    """A length option (mm) is finite and > 0 (≥ 0 with ``zero``), said in mm under its flag:
    the geometry's own check named its SI key (``mesh_size``, ``neck_length``) and value in m."""
    import math

    if value is None:
        return
    if not math.isfinite(value) or value < 0 or (value == 0 and not zero):
        raise InputError(f"must be {'≥' if zero else '>'} 0 mm, got {value:g}", field=flag)


def _json_output(output: Path) -> None:
    """The compliance file is JSON whatever its name says: ``-o t.csv`` wrote JSON into a .csv
    (and a spreadsheet or another tool then read it as a table); refused."""
    if output.suffix.lower() != ".json":
        raise InputError(
            f"the compliance is written as JSON: name the file .json, not "
            f"{output.suffix or '(no suffix)'!r}",
            file=output,
            field="--output",
        )


def _method(method: str, no_fe: bool) -> str:
    method = "beam" if no_fe else method.lower()
    if method not in ("fe", "beam"):
        raise InputError(f"--method must be fe or beam, got {method!r}", field="--method")
    return method


def _compute(
    geom: Any, how: str, mesh_size: float | None, convergence: bool, solver: str
) -> ComplianceResult:
    from roboisf.fem import beam_result, fe_compliance

    if how == "beam":
        return beam_result(geom)
    return fe_compliance(
        geom,
        None if mesh_size is None else mesh_size * MM,
        convergence=convergence,
        solver=solver,
        progress=state.progress(),
    )


def _summary(result: ComplianceResult, what: str) -> None:
    import numpy as np

    k = result.compliance
    state.info(
        f"{what} compliance about {np.round(result.reference_point * 1e3, 4).tolist()} mm "
        f"({result.method}): lateral {k[0, 0]:.4g} / {k[1, 1]:.4g} m/N, axial {k[2, 2]:.4g} m/N, "
        f"torsion {k[5, 5]:.4g} rad/(N·m)"
    )
    q = result.quality
    if "symmetry_error" in q:
        conv = q.get("mesh_convergence", {})
        state.info(
            f"  mesh {q['mesh_size'] * 1e3:.3g} mm, {q['n_dofs']} DOFs; symmetry error "
            f"{q['symmetry_error']:.1e}, load resultant error {q['resultant_error']:.1e}, "
            f"PNR min {min(q['pnr']):.3g}"
            + (
                f", Richardson error (lateral) {conv['richardson_error_lateral'] * 100:.3g} %"
                if conv
                else ""
            )
        )


def _write(result: ComplianceResult, output: Path, inputs: list[Path]) -> None:
    from roboisf.fem import save_compliance_json

    check_not_input(output, list(inputs))
    save_compliance_json(result, output)
    state.info(f"wrote {output}")


def _parse_section(text: str) -> HolderSection:
    from roboisf.fem.geometry import HolderSection

    parts = text.split(":")
    try:
        vals = [float(p) * MM for p in parts]
    except ValueError:
        vals = []
    if not 2 <= len(vals) <= 4:
        raise InputError(
            f"expected LENGTH:OUTER[:INNER[:OUTER_END]] in mm, got {text!r}", field="--section"
        )
    length, outer = vals[0], vals[1]
    inner = vals[2] if len(vals) > 2 else 0.0
    end = vals[3] if len(vals) > 3 else None
    # a holder no cell has (1e30 mm) would send gmsh into an endless mesh: refused first
    from roboisf.plausible import check_plausible

    for i, v in enumerate(vals):
        if i == 2 and v == 0:
            continue  # no bore
        check_plausible(
            v / MM, "holder_length" if i == 0 else "holder_diameter", field=f"--section {text}"
        )
    try:
        return HolderSection(length, outer, inner, end)
    except InputError as e:
        raise InputError(f"{e.message} (section {text!r})", field="--section") from None


def register(app: typer.Typer) -> None:
    """Add ``tool-stiffness`` and ``holder-stiffness`` to ``app``."""

    @app.command("tool-stiffness")
    def tool_stiffness(
        ball_diameter: float = typer.Option(10.0, help="Ball diameter (mm)."),
        length: float = typer.Option(60.0, help="Free length, clamped face to the tip (mm)."),
        shank_diameter: float | None = typer.Option(
            None, help="Shank diameter (mm) (default: ball)."
        ),
        neck_diameter: float | None = typer.Option(None, help="Neck diameter above the ball (mm)."),
        neck_length: float = typer.Option(0.0, help="Neck length from the ball centre (mm)."),
        taper_length: float = typer.Option(0.0, help="Neck-to-shank taper length (mm)."),
        step: Path | None = typer.Option(
            None, "--step", help="A STEP solid instead of the ball tool."
        ),
        clamped: list[str] = typer.Option([], "--clamped", help="STEP: clamped face label/number."),
        coupling: list[str] = typer.Option(
            [], "--coupling", help="STEP: coupling face label/number."
        ),
        reference: tuple[float, float, float] = typer.Option(
            (0.0, 0.0, 0.0), help="STEP: reference point x y z (mm)."
        ),
        youngs_modulus: float = _E,
        poisson: float = _NU,
        mesh_size: float | None = typer.Option(None, help="Element size (mm) (default R/3)."),
        method: str = _METHOD,
        no_fe: bool = _NO_FE,
        convergence: bool = _CONVERGENCE,
        solver: str = _SOLVER,
        output: Path = typer.Option(
            Path("tool_compliance.json"), "-o", "--output", help=f"JSON file. {FILE_HELP}"
        ),
        overwrite: Overwrite = False,
    ) -> None:
        """6×6 compliance of a ball-end tool (or a STEP body) about its tip, by six FE loads."""
        import numpy as np

        from roboisf.fem import BallEndTool, StepGeometry

        _json_output(output)
        output_file(output, "tool-stiffness", overwrite, [step])
        from roboisf.plausible import check_plausible

        for flag, v, bound in (
            ("--ball-diameter", ball_diameter, "ball_diameter"),
            ("--length", length, "free_length"),
            ("--shank-diameter", shank_diameter, "shank_diameter"),
            ("--neck-diameter", neck_diameter, "shank_diameter"),
        ):
            if v is not None:
                check_plausible(v, bound, field=flag)
        _check_mm("--mesh-size", mesh_size)
        _check_mm("--neck-length", neck_length, zero=True)
        _check_mm("--taper-length", taper_length, zero=True)
        if neck_diameter is not None and neck_length == 0:
            raise InputError(
                "a neck needs its length: give --neck-length (mm, from the ball centre)",
                field="--neck-diameter",
            )
        if neck_diameter is None and (neck_length > 0 or taper_length > 0):
            flag = "--neck-length" if neck_length > 0 else "--taper-length"
            raise InputError(f"{flag} needs --neck-diameter (mm)", field=flag)
        mat = _material(youngs_modulus, poisson)
        how = _method(method, no_fe)
        inputs: list[Path] = []
        geom: object
        if step is not None:
            if how == "beam":
                raise InputError("the beam model cannot read a STEP file", field="--method")
            if not clamped or not coupling:
                raise InputError(
                    "a STEP body needs --clamped and --coupling faces", field="--clamped"
                )
            if mesh_size is None:
                raise InputError("give --mesh-size for a STEP body", field="--mesh-size")
            geom = StepGeometry(
                step, tuple(clamped), tuple(coupling), np.array(reference) * MM, mat
            )
            inputs.append(step)
        else:
            geom = BallEndTool(
                ball_diameter * MM,
                length * MM,
                None if shank_diameter is None else shank_diameter * MM,
                None if neck_diameter is None else neck_diameter * MM,
                neck_length * MM,
                taper_length * MM,
                mat,
            )
        result = _compute(geom, how, mesh_size, convergence, solver)
        _summary(result, "tool")
        _write(result, output, inputs)

    @app.command("holder-stiffness")
    def holder_stiffness(
        section: list[str] = typer.Option(
            ...,
            "--section",
            help="LENGTH:OUTER[:INNER[:OUTER_END]] (mm), repeat from the nose upward.",
        ),
        coupling_diameter: float | None = typer.Option(
            None, help="Tool footprint on the nose face (mm) (default: whole nose face)."
        ),
        youngs_modulus: float = _E,
        poisson: float = _NU,
        mesh_size: float | None = typer.Option(
            None, help="Element size (mm) (default: a third of the thinnest section radius)."
        ),
        method: str = _METHOD,
        no_fe: bool = _NO_FE,
        convergence: bool = _CONVERGENCE,
        solver: str = _SOLVER,
        with_tool: Path | None = typer.Option(
            None, help="A tool compliance JSON: write tool + holder in series about the tool tip."
        ),
        output: Path = typer.Option(
            Path("holder_compliance.json"), "-o", "--output", help=f"JSON file. {FILE_HELP}"
        ),
        overwrite: Overwrite = False,
    ) -> None:
        """6×6 compliance of a stepped/tapered tool holder about its nose centre (or, with
        --with-tool, of tool + holder in series about the tool tip)."""
        from roboisf.fem import (
            ToolHolder,
            load_compliance_json,
            tool_holder_compliance,
        )

        _json_output(output)
        output_file(output, "holder-stiffness", overwrite, [with_tool])
        _check_mm("--coupling-diameter", coupling_diameter)
        _check_mm("--mesh-size", mesh_size)
        how = _method(method, no_fe)
        holder = ToolHolder(
            tuple(_parse_section(s) for s in section),
            None if coupling_diameter is None else coupling_diameter * MM,
            _material(youngs_modulus, poisson),
        )
        tool = None
        tool_length = 0.0
        if with_tool is not None:
            tool = load_compliance_json(with_tool)
            tool_length = tool.geometry.get("length")  # type: ignore[assignment]
            if not isinstance(tool_length, int | float) or tool_length <= 0:
                raise InputError(
                    "the tool file does not record its free length (geometry.length, m)",
                    file=with_tool,
                    field="geometry.length",
                )
        result = _compute(holder, how, mesh_size, convergence, solver)
        _summary(result, "holder")
        if tool is not None:
            result = tool_holder_compliance(tool, result, tool_length)
            _summary(result, "tool + holder")
        _write(result, output, [] if with_tool is None else [with_tool])
