"""ABB Externally Guided Motion (EGM): protobuf messages over UDP.

The robot controller sends an ``EgmRobot`` every EGM cycle (4 ms) to the sensor's UDP port (the
``UCdevice`` of the controller's configuration): header (``seqno``, ``tm`` ms,
``mtype = MSGTYPE_DATA``), feedback joints (deg) and pose (mm, quaternion), and the planned
pose of the path. The sensor answers in one of the two EGM modes (ABB, *Application manual –
Externally Guided Motion*):

* **position guidance** (``EGMActPose`` + ``EGMRunPose``), the default here: an ``EgmSensor``
  with ``mtype = MSGTYPE_CORRECTION`` and ``planned.cartesian`` = the controller's planned pose
  with the correction added to its position (mm; orientation unchanged);
* **path correction** (``EGMActMove`` + ``EGMMoveL``): an ``EgmSensorPathCorr`` with
  ``mtype = MSGTYPE_PATH_CORRECTION``, ``pathCorr.pos`` = the correction (mm) and ``age`` (ms).
  ABB defines ``pathCorr.pos`` in the **sensor frame** that ``EGMActMove``'s ``SensorFrame``
  argument places on the tool; roboisf's module ``egm_config/roboisf_egm.mod`` passes the
  tool's own frame (``tool.tframe``), so the sensor frame is the TCP frame, and roboisf turns the
  work-axes correction into it with the TCP's planned orientation in the message
  (``c_tcp = R_work_tcpᵀ c_work``, ``EgmRobot.planned.cartesian.orient``). The controller's path
  planning stays in charge: this is the mode for a forming program.

Position guidance replaces the path: the controller goes where the sensor says. roboisf sends
``planned`` + correction, which is right only while ``planned`` is the program's path (the
simulated controller's assumption); a real program under ``EGMRunPose`` plans nothing, so
position guidance needs the path from the sensor side — use path correction (docs/online.md).

The messages are those of ABB's ``egm.proto`` (a wire-compatible subset written for roboisf,
``proto/roboisf_egm.proto``; generated module :mod:`roboisf.online.roboisf_egm_pb2`, protobuf
runtime ≥ 7.35). Corrections are in the work object of the EGM motion (roboisf's work frame).
"""

from __future__ import annotations

import numpy as np
from google.protobuf.message import DecodeError
from numpy.typing import NDArray

from roboisf.frames import quat_to_matrix
from roboisf.online import roboisf_egm_pb2 as pb
from roboisf.online.base import ProtocolError, RobotState

__all__ = ["EgmAdapter", "decode_robot", "encode_correction", "encode_robot", "to_sensor_frame"]

F64 = NDArray[np.float64]

CYCLE = 0.004
_MAX_PACKET = 4096


def decode_robot(data: bytes, msg: pb.EgmRobot | None = None) -> RobotState:
    """An ``EgmRobot`` → :class:`RobotState` (joints rad; planned pose m + quaternion).

    :class:`ProtocolError` when it does not parse, is not a data message, or lacks six finite
    feedback joints.
    """
    if len(data) > _MAX_PACKET:
        raise ProtocolError(f"EGM packet of {len(data)} bytes", field="packet")
    m = pb.EgmRobot() if msg is None else msg
    try:
        m.ParseFromString(data)
    except (DecodeError, RuntimeWarning) as e:
        raise ProtocolError(
            f"EGM packet does not parse as EgmRobot ({e})", field="packet"
        ) from None
    if m.header.mtype != pb.EgmHeader.MSGTYPE_DATA:
        raise ProtocolError(
            f"EGM message type {m.header.mtype}, expected MSGTYPE_DATA (2)", field="header.mtype"
        )
    j = m.feedBack.joints.joints
    if len(j) < 6:
        raise ProtocolError(
            f"EgmRobot with {len(j)} feedback joints, expected 6", field="feedBack.joints"
        )
    q = np.radians(np.array(j[:6], dtype=float))
    if not np.all(np.isfinite(q)):
        raise ProtocolError("non-finite feedback joints", field="feedBack.joints")
    planned = np.full(7, np.nan)
    if m.planned.HasField("cartesian") and m.planned.cartesian.HasField("pos"):
        p = m.planned.cartesian.pos
        planned[:3] = (p.x * 1e-3, p.y * 1e-3, p.z * 1e-3)
        if m.planned.cartesian.HasField("orient"):
            o = m.planned.cartesian.orient
            planned[3:] = (o.u0, o.u1, o.u2, o.u3)
    return RobotState(int(m.header.seqno), q, planned)


def encode_robot(seq: int, tm_ms: int, q: F64, planned: F64 | None = None) -> bytes:
    """What an ABB controller sends (the simulated controller): joints ``q`` (6,) rad, planned
    pose (7,) m + quaternion (w, x, y, z)."""
    m = pb.EgmRobot()
    m.header.seqno = seq & 0xFFFFFFFF
    m.header.tm = tm_ms & 0xFFFFFFFF
    m.header.mtype = pb.EgmHeader.MSGTYPE_DATA
    m.feedBack.joints.joints.extend(np.degrees(q).tolist())
    if planned is not None:
        c = m.planned.cartesian
        c.pos.x, c.pos.y, c.pos.z = (float(v) * 1e3 for v in planned[:3])
        c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = (float(v) for v in planned[3:])
    return m.SerializeToString()


def encode_correction(
    seq: int, tm_ms: int, correction: F64, planned: F64 | None, *, path_correction: bool = False
) -> bytes:
    """The sensor's reply for ``correction`` (3,) m (work axes).

    Position guidance: ``EgmSensor.planned.cartesian`` = ``planned`` (7,) with the correction
    added to its position (a :class:`ProtocolError` without a planned pose); path correction:
    ``EgmSensorPathCorr.pathCorr`` = the correction as given (the caller turns it into the
    sensor frame: :class:`EgmAdapter`) with ``age`` 0 ms (the correction is for the coming
    cycle).
    """
    c_mm = [float(v) * 1e3 for v in correction]
    if path_correction:
        pc = pb.EgmSensorPathCorr()
        pc.header.seqno = seq & 0xFFFFFFFF
        pc.header.tm = tm_ms & 0xFFFFFFFF
        pc.header.mtype = pb.EgmHeader.MSGTYPE_PATH_CORRECTION
        pc.pathCorr.pos.x, pc.pathCorr.pos.y, pc.pathCorr.pos.z = c_mm
        pc.pathCorr.age = 0
        return pc.SerializeToString()
    if planned is None or not np.all(np.isfinite(planned)):
        raise ProtocolError(
            "position guidance needs the controller's planned pose (EgmRobot.planned.cartesian)",
            field="planned",
        )
    m = pb.EgmSensor()
    m.header.seqno = seq & 0xFFFFFFFF
    m.header.tm = tm_ms & 0xFFFFFFFF
    m.header.mtype = pb.EgmHeader.MSGTYPE_CORRECTION
    c = m.planned.cartesian
    c.pos.x = float(planned[0]) * 1e3 + c_mm[0]
    c.pos.y = float(planned[1]) * 1e3 + c_mm[1]
    c.pos.z = float(planned[2]) * 1e3 + c_mm[2]
    c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = (float(v) for v in planned[3:])
    return m.SerializeToString()


def decode_sensor(data: bytes) -> tuple[int, F64]:
    """``(seqno, pose (7,))`` of an ``EgmSensor`` (position guidance; the simulated controller)
    — or ``(seqno, correction (3,) m + NaN)`` of an ``EgmSensorPathCorr``."""
    h = pb.EgmHeader()
    try:
        m = pb.EgmSensor()
        m.ParseFromString(data)
        h = m.header
        if h.mtype == pb.EgmHeader.MSGTYPE_PATH_CORRECTION:
            pc = pb.EgmSensorPathCorr()
            pc.ParseFromString(data)
            p = pc.pathCorr.pos
            return int(h.seqno), np.array([p.x, p.y, p.z, *(np.nan,) * 4]) * 1e-3
    except DecodeError as e:
        raise ProtocolError(f"EGM reply does not parse ({e})", field="packet") from None
    if h.mtype != pb.EgmHeader.MSGTYPE_CORRECTION or not m.planned.cartesian.HasField("pos"):
        raise ProtocolError("EGM reply without a planned pose", field="planned")
    c = m.planned.cartesian
    o = c.orient
    return int(h.seqno), np.array(
        [c.pos.x * 1e-3, c.pos.y * 1e-3, c.pos.z * 1e-3, o.u0, o.u1, o.u2, o.u3]
    )


def to_sensor_frame(correction: F64, planned: F64) -> F64:
    """A work-axes correction (3,) in the TCP frame of the planned pose (7,): ``R_work_tcpᵀ c``
    (EGM's path-correction sensor frame when ``EGMActMove`` is given ``tool.tframe``).
    :class:`ProtocolError` when the message has no planned orientation."""
    if not np.all(np.isfinite(planned[3:])):
        raise ProtocolError(
            "path correction in the tool frame needs the planned orientation "
            "(EgmRobot.planned.cartesian.orient)",
            field="planned",
        )
    return np.asarray(quat_to_matrix(planned[3:]).T @ correction, dtype=float)


class EgmAdapter:
    """Decode ``EgmRobot``, encode the reply (position guidance, or ``path_correction`` in the
    TCP frame: :func:`to_sensor_frame`)."""

    name = "egm"
    cycle = CYCLE

    def __init__(self, path_correction: bool = False) -> None:
        self.path_correction = path_correction
        self._msg = pb.EgmRobot()

    def decode(self, data: bytes) -> RobotState:
        return decode_robot(data, self._msg)

    def encode(self, state: RobotState, correction: F64) -> bytes:
        # the sensor's own sequence number; echoing the robot's lets a log pair them
        if self.path_correction:
            c = to_sensor_frame(correction, state.planned)
            return encode_correction(state.seq, 0, c, None, path_correction=True)
        return encode_correction(state.seq, 0, correction, state.planned)
