"""Error types of roboisf.

Every problem a user can fix (a bad file, a bad dimension, an unreachable pose) is raised as a
:class:`RoboisfInputError` subclass whose message names *where* (file, line, field) and *what was
expected*. The CLI turns these into a one-line message and exit code 2; anything else is a bug.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is not loaded by `roboisf --help` (tests/test_cli_startup.py)
    from numpy.typing import ArrayLike

__all__ = [
    "ConvergenceError",
    "InputError",
    "ResourceError",
    "RoboisfError",
    "UnreachableError",
    "short_indices",
]


class RoboisfError(Exception):
    """Base class of every error roboisf raises on purpose."""


class InputError(RoboisfError, ValueError):
    """A user-supplied value or file is not what roboisf expects.

    Parameters
    ----------
    message
        What is wrong and what was expected, e.g. ``"wall_angle must be in (0, 90) deg, got 95"``.
    file
        The offending file, if any.
    line
        1-based line number in ``file`` (data rows count from the header line as line 1).
    field
        The key, column or parameter name.
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | Path | None = None,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.message = message
        self.file = None if file is None else str(file)
        self.line = line
        self.field = field
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file + (f":{self.line}" if self.line is not None else ""))
        elif self.line is not None:
            where.append(f"line {self.line}")
        if self.field is not None:
            where.append(f"[{self.field}]")
        prefix = " ".join(where)
        return f"{prefix}: {self.message}" if prefix else self.message


class UnreachableError(InputError):
    """Poses that the robot cannot reach (out of workspace or joint limits).

    ``indices`` lists the offending toolpath points (0-based).
    """

    def __init__(self, message: str, indices: list[int] | None = None, **kw: object) -> None:
        self.indices = list(indices or [])
        super().__init__(message, **kw)  # type: ignore[arg-type]


class ResourceError(InputError):
    """The machine refused an operation: no space left, a name too long for the file system, no
    permission, a host that cannot be reached, not enough memory.

    Not a bug and not a bad value: the message names the path (or host) and what to do; the CLI
    prints it on one line and exits 2 like any other :class:`InputError`.
    """


class ConvergenceError(RoboisfError):
    """An iterative estimator (registration, fixed point, fit) did not converge.

    The message says what was tried and where it stopped.
    """


def short_indices(idx: ArrayLike, n: int = 8) -> str:
    """The indices an error message names: the first ``n`` of ``idx`` (any shape, flattened),
    comma-separated, then ``, … (K in all)`` when there are more — ``"3, 4, 9"``."""
    import numpy as np

    items: list[int] = [int(i) for i in np.asarray(idx).reshape(-1)]
    s = ", ".join(str(i) for i in items[:n])
    return s + (f", … ({len(items)} in all)" if len(items) > n else "")
