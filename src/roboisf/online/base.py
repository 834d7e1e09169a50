"""What every controller adapter reads and writes, and the error of a bad packet."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError

__all__ = ["ProtocolError", "RobotState"]

F64 = NDArray[np.float64]


class ProtocolError(InputError):
    """A packet that is not what its protocol defines (the loop drops it and counts it)."""


@dataclass
class RobotState:
    """One message of a robot controller (SI).

    Attributes
    ----------
    seq : int — the controller's counter (EGM ``header.seqno``, RSI ``IPOC``)
    q : (6,) float, rad — joint angles, controller convention
    planned : (7,) float — the controller's planned pose: position (3,) m and unit quaternion
        (w, x, y, z), in the frame the corrections are in; NaN when the message has none
    delay : int — the controller's count of replies that came late (RSI ``<Delay D=…/>``,
        ``DEF_Delay``); −1 when the message has none
    """

    seq: int = 0
    q: F64 = field(default_factory=lambda: np.zeros(6))
    planned: F64 = field(default_factory=lambda: np.full(7, np.nan))
    delay: int = -1

    def __post_init__(self) -> None:
        self.delay = int(self.delay)
