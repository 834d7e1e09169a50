"""Bringing a force sensor's wrench to the tool tip, and back (the virtual cell writes logs).

Two mounts (``ForceSensorSpec.mount``):

* ``fixture`` — sensor fixed in the work frame at ``T_work_sensor`` (a dynamometer under the
  fixture). Its wrench, about the sensor origin in sensor axes, is rotated into work axes and its
  moment moved to the tool tip's current position ``p_tip`` (work frame):
  ``W_tip = shift(transform(W_s, T_work_sensor), from = 0_work, to = p_tip)``.
* ``flange`` — sensor carried by the robot, ``T_tip_sensor`` fixed: the wrench goes to the tip
  frame with ``transform(W_s, T_tip_sensor)`` and then into work axes with ``R_work_tip``.

``load_on = "workpiece"`` flips the sign so that every wrench inside roboisf is the sheet's load
on the tool (``docs/conventions.md``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.frames import invert, shift_wrench, transform_wrench
from roboisf.frames.se3 import make_transform
from roboisf.study.spec import ForceSensorSpec

__all__ = ["sensor_to_tip", "tip_to_sensor"]

F64 = NDArray[np.float64]


def sensor_to_tip(
    W_s: ArrayLike, sensor: ForceSensorSpec, tip_work: ArrayLike, R_work_tip: ArrayLike
) -> F64:
    """Sensor wrench (N, 6) [N, N·m] → the sheet's wrench on the tool about the tip, work axes.

    tip_work : (N, 3) m — tool-tip positions; R_work_tip : (3, 3) or (N, 3, 3).
    """
    W_s = np.asarray(W_s, dtype=float)
    sign = -1.0 if sensor.load_on == "workpiece" else 1.0
    if sensor.mount == "fixture":
        W_w = transform_wrench(W_s, sensor.pose)
        return sign * shift_wrench(W_w, np.zeros(3), np.asarray(tip_work, dtype=float))
    W_t = transform_wrench(W_s, sensor.pose)
    R = np.asarray(R_work_tip, dtype=float)
    return sign * transform_wrench(W_t, make_transform(R))


def tip_to_sensor(
    W_tip: ArrayLike, sensor: ForceSensorSpec, tip_work: ArrayLike, R_work_tip: ArrayLike
) -> F64:
    """Inverse of :func:`sensor_to_tip`: what the sensor would read."""
    W = np.asarray(W_tip, dtype=float)
    sign = -1.0 if sensor.load_on == "workpiece" else 1.0
    if sensor.mount == "fixture":
        W_w0 = shift_wrench(W, np.asarray(tip_work, dtype=float), np.zeros(3))
        return sign * transform_wrench(W_w0, invert(sensor.pose))
    R = np.asarray(R_work_tip, dtype=float)
    W_t = transform_wrench(W, make_transform(np.swapaxes(R, -1, -2)))
    return sign * transform_wrench(W_t, invert(sensor.pose))
