"""Aligning logs to the toolpath: by nominal time, by position (FK of a joint log), or by the
force signature (``[runs.X] sync`` in ``study.toml``; ``docs/study.md``, Alignment).

A real run's log clock drifts against the toolpath's nominal time (``path_length / feed``):
feed override, acceleration, pauses, a logger started early. Each method returns an
:class:`Alignment`, the log time at which the tool passed every toolpath point, monotone, with
a residual that says how well the log fits.
"""

from roboisf.sync.alignment import PAUSE_MIN, Alignment, first_passage, point_windows
from roboisf.sync.force import FORCE_RESIDUAL_MAX, align_by_force
from roboisf.sync.position import OFF_PATH, POSITION_RESIDUAL_MAX, align_by_position

__all__ = [
    "FORCE_RESIDUAL_MAX",
    "OFF_PATH",
    "PAUSE_MIN",
    "POSITION_RESIDUAL_MAX",
    "Alignment",
    "align_by_force",
    "align_by_position",
    "first_passage",
    "point_windows",
]
