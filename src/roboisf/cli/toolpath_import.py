"""``roboisf toolpath import``: a CAM program (G-code, Sinumerik, APT/CL, x,y,z list) → a
toolpath CSV.

The work is :func:`roboisf.toolpath.importer.import_toolpath`; this module only reads the options
(mm, mm/min) and reports what was read.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError

__all__ = ["import_command", "parse_work_offsets"]


def parse_work_offsets(values: list[str] | None) -> dict[str, tuple[float, float, float]]:
    """``["G55=10,0,-20", …]`` (mm) → ``{"G55": (0.01, 0.0, -0.02)}`` (m)."""
    out: dict[str, tuple[float, float, float]] = {}
    for text in values or []:
        name, _, nums = text.partition("=")
        name = name.strip().upper()
        try:
            v = [float(x) for x in nums.split(",")]
        except ValueError:
            v = []
        if not name.startswith("G") or len(v) != 3 or not all(math.isfinite(x) for x in v):
            raise InputError(
                f"expected GNN=X,Y,Z (mm, machine coordinates), got {text!r}",
                field="--work-offset",
            )
        out[name] = (v[0] * 1e-3, v[1] * 1e-3, v[2] * 1e-3)
    return out


def import_command(
    program: Annotated[
        Path,
        typer.Argument(
            help="The CAM program: ISO/Fanuc/Haas G-code (.nc .gcode .tap …), Sinumerik (.mpf), "
            "APT/CL data (.apt .cls), or an x,y,z[,i,j,k] list (.xyz .txt .csv, any separator).",
            show_default=False,
        ),
    ],
    part: Annotated[
        Path,
        typer.Option(
            "--part",
            help="The nominal part (TOML, see 'roboisf part'): contact points and normals are its "
            "closest points to the ball centre.",
            show_default=False,
        ),
    ],
    tool_diameter: Annotated[
        float,
        typer.Option(
            help="Ball diameter [mm] (the study's [tool] ball_diameter).", show_default=False
        ),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "--output", "-o", help=f"Toolpath CSV to write. {FILE_HELP}", show_default=False
        ),
    ],
    fmt: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            help="auto | iso | sinumerik | apt | xyz. auto: by content (X= words or %_N_ → "
            "sinumerik, GOTO/ → apt, G/M/N words → iso, rows of numbers → xyz), then suffix.",
        ),
    ] = "auto",
    point: Annotated[
        str,
        typer.Option(
            help="Which point of the ball the program names: 'tip' (its lowest point: what CAM "
            "posts for a ball-end tool with the length set to the tip, the usual CNC set-up and "
            "roboisf's own programs) or 'center' (the ball centre, 'tool centre' output). A wrong "
            "choice shows as a gap of ≈ R between the ball and the part (warned).",
        ),
    ] = "tip",
    chord_tolerance: Annotated[
        float,
        typer.Option(
            help="Arcs (G02/G03, CIRCLE/) become chords at most this far from the arc [mm]."
        ),
    ] = 0.001,
    spacing: Annotated[
        float | None,
        typer.Option(
            help="Split forming moves longer than this [mm] evenly (long CAM lines → points "
            "every SPACING for the force and scan look-ups; at most 5 M points). Default: the "
            "points as programmed.",
        ),
    ] = None,
    rapid_rate: Annotated[
        float | None,
        typer.Option(
            help="Rapid traverse rate [mm/min] for the times. Default: rapids (G00 …) take no "
            "time; forming moves take length / feed.",
        ),
    ] = None,
    work_offset: Annotated[
        list[str] | None,
        typer.Option(
            metavar="GNN=X,Y,Z",
            help="A work offset's value in machine coordinates, 'G55=X,Y,Z' [mm] (repeat for "
            "each). Points under another offset are moved into the frame of the one active at "
            "the first move; without values they are taken as they are (warned).",
        ),
    ] = None,
    ignore_words: Annotated[
        str | None,
        typer.Option(
            help="Letters of extra axes to ignore with a warning, e.g. 'A,B' (default: a program "
            "with A/B/C/U/V/W words is refused, naming the line).",
        ),
    ] = None,
    origin: Annotated[
        str | None,
        typer.Option(
            metavar="X,Y,Z",
            help="Where the blank centre on the sheet top is in the program's coordinates "
            "[mm], when the program zero is elsewhere (e.g. on the machine table): subtracted "
            "from every point. Default: the program zero is the blank centre on the sheet.",
        ),
    ] = None,
    units: Annotated[
        str | None,
        typer.Option(
            help="Length unit of an x,y,z list: mm (default), m or in (refused for a G-code, "
            "Sinumerik or APT program: they declare their own)."
        ),
    ] = None,
    feed: Annotated[
        float | None,
        typer.Option(
            help="Feed [mm/min] of an x,y,z list (a list has none; default 750), and of a G-code "
            "program's feed moves before its first F word (a program posted without feeds; "
            "without --feed such a program is refused, naming the line).",
        ),
    ] = None,
    overwrite: Overwrite = False,
) -> None:
    """Import a CAM program as a roboisf toolpath CSV (contact, normal, centre, tip, laps, times).

    Forming points are the feed moves with the tip at or below the sheet plane z = 0 (program zero
    = blank centre on the sheet, z up); rapids and feed moves above the sheet (approach, retract)
    are dropped. Laps: z levels (step-down, with ramps and wiggles) or full turns about the
    part's axis (spiral), whatever the program's rounding. Times from
    the feeds. Everything ignored is listed; anything not understood is an error naming the line.
    See docs/toolpaths.md, "Importing a CAM program".

    Example: roboisf toolpath import cone.nc --part cone.toml --tool-diameter 10 -o cone.csv
    """
    from roboisf.cam.toolpath_csv import write_toolpath_csv
    from roboisf.parts import load_part
    from roboisf.parts.io import part_files
    from roboisf.toolpath.importer import ImportOptions, import_toolpath

    inputs = [program, *part_files(part)]
    if output.suffix.lower() != ".csv":
        raise InputError(
            "the import writes roboisf's toolpath CSV: give -o a .csv name (then 'roboisf "
            "toolpath' formats are written from a study or a part)",
            file=output,
        )
    output_file(output, "toolpath import", overwrite, inputs)
    for flag, v in (("--tool-diameter", tool_diameter), ("--chord-tolerance", chord_tolerance)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"must be > 0 mm, got {v:g}", field=flag)
    from roboisf.plausible import check_plausible

    check_plausible(tool_diameter, "ball_diameter", field="--tool-diameter")
    words = frozenset(w.strip().upper() for w in (ignore_words or "").split(",") if w.strip())
    bad = sorted(words - set("ABCUVW"))
    if bad:
        raise InputError(
            f"expected letters of A B C U V W, got {','.join(bad)}", field="--ignore-words"
        )
    shift = (0.0, 0.0, 0.0)
    if origin is not None:
        try:
            o = [float(v) for v in origin.split(",")]
        except ValueError:
            o = []
        if len(o) != 3 or not all(math.isfinite(v) for v in o):
            raise InputError(f"expected X,Y,Z in mm, got {origin!r}", field="--origin")
        shift = (o[0] * 1e-3, o[1] * 1e-3, o[2] * 1e-3)
    opts = ImportOptions(
        point=point.strip().lower(),
        fmt=fmt.strip().lower(),
        chord_tol=chord_tolerance * 1e-3,
        spacing=None if spacing is None else spacing * 1e-3,
        rapid_rate=None if rapid_rate is None else rapid_rate / 60e3,
        work_offsets=parse_work_offsets(work_offset),
        ignore_words=words,
        units=units,
        feed=None if feed is None else feed / 60e3,
        origin=shift,
    )
    nominal = load_part(part)
    tp = import_toolpath(program, nominal, tool_diameter / 2 * 1e-3, opts)
    write_toolpath_csv(tp, output, generator=f"roboisf toolpath import {program.name}")
    m = tp.meta
    for note in m["notes"]:  # type: ignore[attr-defined]
        state.info(f"note: {note}")
    for w in m["warnings"]:  # type: ignore[attr-defined]
        state.warn(str(w))
    feeds = ", ".join(f"{f:g}" for f in m["feeds_mm_min"])  # type: ignore[attr-defined]
    state.info(
        f"wrote {output}: {len(tp)} points from {m['format']} ({m['point']} programmed), "
        f"{tp.n_laps} laps ({m['laps_rule']}), {tp.path_length[-1]:.3f} m of path, "
        f"{tp.time[-1] / 60:.1f} min at {feeds} mm/min; {m['dropped_moves']} moves not forming "
        f"(rapids, above the sheet), ball within {float(m['gap_max']) * 1e3:.3f} mm of the part"  # type: ignore[arg-type]
    )
