"""The toolpath value object, below every file format: :class:`Toolpath` (tool tip, ball
centre, normals, feed, laps; SI) and :func:`tool_points`.

It sits under :mod:`roboisf.cam`, :mod:`roboisf.logs` and :mod:`roboisf.programs` (which read and
write it) and under :mod:`roboisf.toolpath` (which generates and imports it), so no format imports a
package above it.
"""

from __future__ import annotations

from roboisf.path.toolpath import Toolpath, tool_points

__all__ = ["Toolpath", "tool_points"]
