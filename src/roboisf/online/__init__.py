"""Online compensation: the forming force, streamed, turned into the robot's path correction.

:mod:`roboisf.online.core` (the streaming core), the protocol adapters
:mod:`~roboisf.online.egm` (ABB EGM), :mod:`~roboisf.online.rsi` (KUKA RSI),
:mod:`~roboisf.online.netft` (ATI Net F/T RDT), :mod:`~roboisf.online.replay` (a study's logs), the
simulated controller and sensor :mod:`~roboisf.online.sim` and the loop
:mod:`~roboisf.online.loop`. See ``docs/online.md``.
"""

from roboisf.online.core import Limits, OnlineCompensator, Plausibility, SensorSetup, status_text

__all__ = ["Limits", "OnlineCompensator", "Plausibility", "SensorSetup", "status_text"]
