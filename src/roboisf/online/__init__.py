"""Online compensation: the forming force, streamed, turned into the robot's path correction.

:mod:`roboisf.online.core` (the streaming core), the protocol adapters
:mod:`~roboisf.online.egm` (ABB EGM), :mod:`~roboisf.online.rsi` (KUKA RSI),
:mod:`~roboisf.online.netft` (ATI Net F/T RDT), :mod:`~roboisf.online.replay` (a study's logs), the
simulated controller and sensor :mod:`~roboisf.online.sim` (their processes:
:mod:`~roboisf.online.devices`) and the loop :mod:`~roboisf.online.loop`. See ``docs/online.md``.

The names below load their module on first use (PEP 562): a simulated device's process imports
the codecs without the core's robot model.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.online.core import (
        Limits,
        OnlineCompensator,
        Plausibility,
        SensorSetup,
        status_text,
    )

_WHERE = {
    "core": ("Limits", "OnlineCompensator", "Plausibility", "SensorSetup", "status_text"),
}
__all__ = ["Limits", "OnlineCompensator", "Plausibility", "SensorSetup", "status_text"]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
