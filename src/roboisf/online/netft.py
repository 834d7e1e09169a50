"""ATI Net F/T: the Raw Data Transfer (RDT) protocol over UDP (port 49152).

The client sends a request of 8 bytes, big-endian (ATI, *Net F/T Installation and Operation
Manual*, section "UDP interface using RDT")::

    uint16 command_header = 0x1234
    uint16 command        (0 stop streaming, 2 start high-speed real-time streaming,
                           3 start high-speed buffered streaming, 0x42 set software bias)
    uint32 sample_count   (0 = stream until stopped)

and the sensor answers with records of 36 bytes, big-endian, one per UDP packet in real-time
mode (several in buffered mode)::

    uint32 rdt_sequence   (the packet counter)
    uint32 ft_sequence    (the sample counter of the sensor's internal clock)
    uint32 status         (0 = healthy; bits flag saturation and faults)
    int32  Fx Fy Fz Tx Ty Tz   (counts)

Force = counts / counts-per-force, torque = counts / counts-per-torque: the calibration's
``cfgcpf`` / ``cfgcpt`` (the sensor's web page or ``netftapi2.xml``); with the force unit N and
the torque unit N·m the Net F/T default is 1,000,000 counts per unit.
"""

from __future__ import annotations

import struct

import numpy as np
from numpy.typing import NDArray

from roboisf.online.base import ProtocolError

__all__ = [
    "CMD_BIAS",
    "CMD_START_BUFFERED",
    "CMD_START_REALTIME",
    "CMD_STOP",
    "DEFAULT_COUNTS",
    "PORT",
    "RECORD_SIZE",
    "RdtRecord",
    "decode_records",
    "decode_request",
    "encode_record",
    "encode_request",
]

F64 = NDArray[np.float64]

PORT = 49152
HEADER = 0x1234
CMD_STOP = 0x0000
CMD_START_REALTIME = 0x0002
CMD_START_BUFFERED = 0x0003
CMD_BIAS = 0x0042
COMMANDS = (CMD_STOP, CMD_START_REALTIME, CMD_START_BUFFERED, CMD_BIAS)
#: counts per N and per N·m of a Net F/T in its default configuration
DEFAULT_COUNTS = 1_000_000.0
_REQ = struct.Struct(">HHI")
_REC = struct.Struct(">IIIiiiiii")
RECORD_SIZE = _REC.size  # 36
_MAXC = 2**31 - 1


def encode_request(command: int, sample_count: int = 0) -> bytes:
    """The 8-byte RDT request."""
    if command not in COMMANDS:
        raise ProtocolError(f"unknown RDT command {command:#06x}", field="command")
    if not 0 <= sample_count < 2**32:
        raise ProtocolError("sample_count must fit 32 bits", field="sample_count")
    return _REQ.pack(HEADER, command, sample_count)


def decode_request(data: bytes) -> tuple[int, int]:
    """``(command, sample_count)`` of a request; :class:`ProtocolError` when malformed."""
    if len(data) != _REQ.size:
        raise ProtocolError(f"RDT request of {len(data)} bytes, expected 8", field="request")
    header, command, count = _REQ.unpack(data)
    if header != HEADER:
        raise ProtocolError(f"RDT header {header:#06x}, expected 0x1234", field="request")
    if command not in COMMANDS:
        raise ProtocolError(f"unknown RDT command {command:#06x}", field="request")
    return command, count


class RdtRecord:
    """One decoded record: counters, status and the wrench (6,) [N; N·m], sensor axes."""

    __slots__ = ("ft_sequence", "rdt_sequence", "status", "wrench")

    def __init__(self, rdt_sequence: int, ft_sequence: int, status: int, wrench: F64) -> None:
        self.rdt_sequence = rdt_sequence
        self.ft_sequence = ft_sequence
        self.status = status
        self.wrench = wrench


def encode_record(
    rdt_sequence: int,
    ft_sequence: int,
    status: int,
    wrench: F64,
    counts_per_force: float = DEFAULT_COUNTS,
    counts_per_torque: float = DEFAULT_COUNTS,
) -> bytes:
    """A 36-byte record of ``wrench`` (6,) [N; N·m] (counts rounded, saturated at int32)."""
    c = [
        min(_MAXC, max(-_MAXC - 1, round(float(w) * s)))
        for w, s in zip(wrench, (counts_per_force,) * 3 + (counts_per_torque,) * 3, strict=True)
    ]
    return _REC.pack(rdt_sequence & 0xFFFFFFFF, ft_sequence & 0xFFFFFFFF, status, *c)


def decode_records(
    data: bytes,
    counts_per_force: float = DEFAULT_COUNTS,
    counts_per_torque: float = DEFAULT_COUNTS,
) -> list[RdtRecord]:
    """The records of one RDT packet (36·n bytes); :class:`ProtocolError` when malformed."""
    if len(data) == 0 or len(data) % RECORD_SIZE:
        raise ProtocolError(
            f"RDT packet of {len(data)} bytes, expected a multiple of {RECORD_SIZE}",
            field="packet",
        )
    out = []
    for off in range(0, len(data), RECORD_SIZE):
        rs, fs, status, *c = _REC.unpack_from(data, off)
        w = np.array(c, dtype=float)
        w[:3] /= counts_per_force
        w[3:] /= counts_per_torque
        out.append(RdtRecord(rs, fs, status, w))
    return out
