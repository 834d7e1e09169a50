from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class EgmHeader(_message.Message):
    __slots__ = ("seqno", "tm", "mtype")
    class MessageType(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        MSGTYPE_UNDEFINED: _ClassVar[EgmHeader.MessageType]
        MSGTYPE_COMMAND: _ClassVar[EgmHeader.MessageType]
        MSGTYPE_DATA: _ClassVar[EgmHeader.MessageType]
        MSGTYPE_CORRECTION: _ClassVar[EgmHeader.MessageType]
        MSGTYPE_PATH_CORRECTION: _ClassVar[EgmHeader.MessageType]
    MSGTYPE_UNDEFINED: EgmHeader.MessageType
    MSGTYPE_COMMAND: EgmHeader.MessageType
    MSGTYPE_DATA: EgmHeader.MessageType
    MSGTYPE_CORRECTION: EgmHeader.MessageType
    MSGTYPE_PATH_CORRECTION: EgmHeader.MessageType
    SEQNO_FIELD_NUMBER: _ClassVar[int]
    TM_FIELD_NUMBER: _ClassVar[int]
    MTYPE_FIELD_NUMBER: _ClassVar[int]
    seqno: int
    tm: int
    mtype: EgmHeader.MessageType
    def __init__(self, seqno: _Optional[int] = ..., tm: _Optional[int] = ..., mtype: _Optional[_Union[EgmHeader.MessageType, str]] = ...) -> None: ...

class EgmCartesian(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class EgmQuaternion(_message.Message):
    __slots__ = ("u0", "u1", "u2", "u3")
    U0_FIELD_NUMBER: _ClassVar[int]
    U1_FIELD_NUMBER: _ClassVar[int]
    U2_FIELD_NUMBER: _ClassVar[int]
    U3_FIELD_NUMBER: _ClassVar[int]
    u0: float
    u1: float
    u2: float
    u3: float
    def __init__(self, u0: _Optional[float] = ..., u1: _Optional[float] = ..., u2: _Optional[float] = ..., u3: _Optional[float] = ...) -> None: ...

class EgmEuler(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class EgmClock(_message.Message):
    __slots__ = ("sec", "usec")
    SEC_FIELD_NUMBER: _ClassVar[int]
    USEC_FIELD_NUMBER: _ClassVar[int]
    sec: int
    usec: int
    def __init__(self, sec: _Optional[int] = ..., usec: _Optional[int] = ...) -> None: ...

class EgmPose(_message.Message):
    __slots__ = ("pos", "orient", "euler")
    POS_FIELD_NUMBER: _ClassVar[int]
    ORIENT_FIELD_NUMBER: _ClassVar[int]
    EULER_FIELD_NUMBER: _ClassVar[int]
    pos: EgmCartesian
    orient: EgmQuaternion
    euler: EgmEuler
    def __init__(self, pos: _Optional[_Union[EgmCartesian, _Mapping]] = ..., orient: _Optional[_Union[EgmQuaternion, _Mapping]] = ..., euler: _Optional[_Union[EgmEuler, _Mapping]] = ...) -> None: ...

class EgmJoints(_message.Message):
    __slots__ = ("joints",)
    JOINTS_FIELD_NUMBER: _ClassVar[int]
    joints: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, joints: _Optional[_Iterable[float]] = ...) -> None: ...

class EgmPlanned(_message.Message):
    __slots__ = ("joints", "cartesian", "externalJoints", "time")
    JOINTS_FIELD_NUMBER: _ClassVar[int]
    CARTESIAN_FIELD_NUMBER: _ClassVar[int]
    EXTERNALJOINTS_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    joints: EgmJoints
    cartesian: EgmPose
    externalJoints: EgmJoints
    time: EgmClock
    def __init__(self, joints: _Optional[_Union[EgmJoints, _Mapping]] = ..., cartesian: _Optional[_Union[EgmPose, _Mapping]] = ..., externalJoints: _Optional[_Union[EgmJoints, _Mapping]] = ..., time: _Optional[_Union[EgmClock, _Mapping]] = ...) -> None: ...

class EgmPathCorr(_message.Message):
    __slots__ = ("pos", "age")
    POS_FIELD_NUMBER: _ClassVar[int]
    AGE_FIELD_NUMBER: _ClassVar[int]
    pos: EgmCartesian
    age: int
    def __init__(self, pos: _Optional[_Union[EgmCartesian, _Mapping]] = ..., age: _Optional[int] = ...) -> None: ...

class EgmFeedBack(_message.Message):
    __slots__ = ("joints", "cartesian", "externalJoints", "time")
    JOINTS_FIELD_NUMBER: _ClassVar[int]
    CARTESIAN_FIELD_NUMBER: _ClassVar[int]
    EXTERNALJOINTS_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    joints: EgmJoints
    cartesian: EgmPose
    externalJoints: EgmJoints
    time: EgmClock
    def __init__(self, joints: _Optional[_Union[EgmJoints, _Mapping]] = ..., cartesian: _Optional[_Union[EgmPose, _Mapping]] = ..., externalJoints: _Optional[_Union[EgmJoints, _Mapping]] = ..., time: _Optional[_Union[EgmClock, _Mapping]] = ...) -> None: ...

class EgmRobot(_message.Message):
    __slots__ = ("header", "feedBack", "planned")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    FEEDBACK_FIELD_NUMBER: _ClassVar[int]
    PLANNED_FIELD_NUMBER: _ClassVar[int]
    header: EgmHeader
    feedBack: EgmFeedBack
    planned: EgmPlanned
    def __init__(self, header: _Optional[_Union[EgmHeader, _Mapping]] = ..., feedBack: _Optional[_Union[EgmFeedBack, _Mapping]] = ..., planned: _Optional[_Union[EgmPlanned, _Mapping]] = ...) -> None: ...

class EgmSensor(_message.Message):
    __slots__ = ("header", "planned")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    PLANNED_FIELD_NUMBER: _ClassVar[int]
    header: EgmHeader
    planned: EgmPlanned
    def __init__(self, header: _Optional[_Union[EgmHeader, _Mapping]] = ..., planned: _Optional[_Union[EgmPlanned, _Mapping]] = ...) -> None: ...

class EgmSensorPathCorr(_message.Message):
    __slots__ = ("header", "pathCorr")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    PATHCORR_FIELD_NUMBER: _ClassVar[int]
    header: EgmHeader
    pathCorr: EgmPathCorr
    def __init__(self, header: _Optional[_Union[EgmHeader, _Mapping]] = ..., pathCorr: _Optional[_Union[EgmPathCorr, _Mapping]] = ...) -> None: ...
