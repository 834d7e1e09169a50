"""``roboisf demo``: the built-in demonstration.

Interim version (toolpaths only): the paper's cone (Ø87 mm, 71°, 102.97 mm deep) and VWACF
(Ø88.15 mm, default 39 mm arc, 0° → 90°), Ø10 mm ball, 0.5 mm step, 750 mm/min, written in every
supported format. The folder is built in a staging folder and moved into place when complete.

A later issue replaces :func:`build_demo` with the full virtual-cell demo; the command, the
``-o`` folder handling and the atomic staging stay.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from roboisf.cli.console import state
from roboisf.cli.toolpath import warn_truncated
from roboisf.frames.se3 import make_transform
from roboisf.io.atomic import staged_directory
from roboisf.io.export import FORMAT_SUFFIXES, write_toolpath
from roboisf.io.program import RobotTool
from roboisf.parts import VWACF, AxisymmetricPart, Cone, save_part
from roboisf.progress import Progress, task
from roboisf.toolpath import step_down

__all__ = ["DEMO_PARTS", "DEMO_PLACEMENT", "build_demo", "register"]

#: The paper's two parts.
DEMO_PARTS: dict[str, AxisymmetricPart] = {
    "cone": Cone(87e-3, math.radians(71.0), 102.97e-3),
    "vwacf": VWACF(88.15e-3),
}

#: Illustrative work-object placement for the robot programs: blank centre 1.8 m in front of an
#: IRB 7600 base and 0.6 m up, axes parallel to the base (replace with your cell's calibration).
DEMO_PLACEMENT = make_transform(np.eye(3), [1.8, 0.0, 0.6])


def build_demo(folder: Path, progress: Progress | None = None) -> list[Path]:
    """Write the demo files into ``folder`` (which exists and is empty); return them."""
    written: list[Path] = []
    tool = RobotTool(length=0.2, mass=2.0)
    with task(progress, "toolpaths", total=len(DEMO_PARTS) * (1 + len(FORMAT_SUFFIXES))) as advance:
        for name, part in DEMO_PARTS.items():
            sub = folder / name
            sub.mkdir()
            save_part(part, sub / "part.toml")
            written.append(sub / "part.toml")
            tp = step_down(part, tool_radius=5e-3, step_down=0.5e-3)
            warn_truncated(tp, 10.0)
            advance(1)
            for fmt, suffixes in FORMAT_SUFFIXES.items():
                out = sub / f"toolpath{suffixes[0]}"
                write_toolpath(tp, out, fmt, T_base_work=DEMO_PLACEMENT, tool=tool)
                written.append(out)
                if fmt == "krl":
                    written.append(out.with_suffix(".dat"))
                advance(1)
            state.info(
                f"{name}: {len(tp)} points, {tp.n_laps} laps, depth {part.depth * 1e3:.2f} mm, "
                f"{tp.time[-1] / 60:.1f} min at 750 mm/min"
            )
    return written


def register(app: typer.Typer) -> None:
    """Add ``roboisf demo`` to ``app``."""

    @app.command("demo")
    def _demo(
        output: Annotated[
            Path, typer.Option("--output", "-o", help="Folder to create (replaced if it exists).")
        ] = Path("roboisf-demo"),
    ) -> None:
        """Write the paper's cone and VWACF toolpaths in every format (CSV, G-code, RAPID, KRL)."""
        with staged_directory(output) as stage:
            files = build_demo(stage, state.progress())
        state.info(f"wrote {len(files)} files to {output}/")
