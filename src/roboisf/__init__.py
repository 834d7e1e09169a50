"""roboisf — geometric-error analysis, compensation and planning for robot and CNC incremental
sheet forming (after Bharti et al., Sci. Rep. 14:20291, 2024).

SI units inside (m, N, N·m, rad, s); frames in names (``T_base_tool``). See ``docs/``.
"""

from roboisf.errors import ConvergenceError, InputError, RoboisfError, UnreachableError

__version__ = "0.1.0"

__all__ = ["ConvergenceError", "InputError", "RoboisfError", "UnreachableError", "__version__"]
