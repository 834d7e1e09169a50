"""The paper's default part dimensions (SI), in a module without numpy so that the command line
can show them in ``--help`` without importing the geometry."""

from __future__ import annotations

__all__ = ["PAPER_SHEET_THICKNESS", "VWACF_DEFAULT_ARC_RADIUS"]

#: AA1050 sheet of the paper (Bharti et al. 2024), m.
PAPER_SHEET_THICKNESS = 1.22e-3

#: Default VWACF arc radius [m]. The paper's Fig. 2b (not in our text copy) gives the true value.
#: 39 mm is the largest arc a Ø10 mm ball can follow all the way to 90° on a Ø88.15 mm opening
#: (ball centre radius R0 − ρ − R_ball ≥ 0); the part is then 39 mm deep with a Ø10.15 mm bottom,
#: and a sheet that fractures at 83° does so 34 mm deep — the paper's VWACF springback "increases
#: at z = 30–35 mm and diminishes near the fracture area".
VWACF_DEFAULT_ARC_RADIUS = 39e-3
