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

The ``status`` word is the Net F/T's *system status code* (the manual's table; :data:`STATUS_BITS`
names each bit, :func:`status_text` decodes a word): 0 is healthy, bit 31 summarises an error,
bit 17 is a saturated transducer or an A/D error. A record with a non-zero status is not used.

``rdt_sequence`` counts the packets of one stream; it restarts when the sensor is power cycled
or streaming is restarted, and wraps at 2³². :class:`SequenceTracker` follows it: lost records
(a gap), out-of-order and duplicate ones (behind the last, dropped) and restarts (far behind the
last, or several in a row: followed at once, not dropped as late).

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
    "MAX_RATE",
    "PORT",
    "RECORD_SIZE",
    "STATUS_BITS",
    "RdtRecord",
    "SequenceTracker",
    "decode_records",
    "decode_request",
    "encode_record",
    "encode_request",
    "status_text",
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
#: Hz — the fastest a Net F/T streams RDT records (the manual: "up to 7000 Hz"); the rate a
#: sensor streams at is set on it (its web page), so the loop knows no closer bound at start
MAX_RATE = 7000.0
_REQ = struct.Struct(">HHI")
_REC = struct.Struct(">IIIiiiiii")
RECORD_SIZE = _REC.size  # 36
_MAXC = 2**31 - 1


#: the Net F/T system status code, bit → meaning (ATI manual 9620-05-NET FT, "System Status
#: Code"; bits 0 and 15 are not used)
STATUS_BITS: dict[int, str] = {
    31: "error (summary)",
    30: "CPU or RAM error",
    29: "digital board error",
    28: "analog board error",
    27: "serial link error",
    26: "program memory check failed",
    25: "halted: configuration error",
    24: "settings validation error",
    23: "configuration does not match the calibration",
    22: "network error",
    21: "CAN error",
    20: "RDT error",
    19: "EtherNet/IP error",
    18: "DeviceNet error",
    17: "transducer saturated or A/D error",
    16: "monitor condition latched",
    14: "watchdog timeout",
    13: "stack check error",
    12: "EEPROM error",
    11: "flash error",
    10: "analog board watchdog timeout",
    9: "strain gage excitation current too high",
    8: "strain gage excitation current too low",
    7: "artificial analog ground out of range",
    6: "analog supply too high",
    5: "analog supply too low",
    4: "serial link data unavailable",
    3: "reference voltage or power monitor error",
    2: "internal temperature error",
    1: "HTTP error",
}


def status_text(status: int) -> str:
    """``"healthy"`` or the meanings of the set bits of a status word, ``"; "``-joined (an
    unnamed bit as ``bit N``)."""
    if status == 0:
        return "healthy"
    return "; ".join(STATUS_BITS.get(b, f"bit {b}") for b in range(31, -1, -1) if status >> b & 1)


class SequenceTracker:
    """Follows ``rdt_sequence`` (mod 2³²) across losses, reordering, wraps and restarts.

    :meth:`accept` says whether a record is new: one up to ``max_gap`` ahead of the last is
    taken (the records between count as ``lost``; 2³² − 1 → 0 is one step); one at or behind
    the last by up to ``window`` is ``out_of_order`` (a duplicate or a late packet: dropped) —
    unless ``resync_after`` of them come in a row; anything else (further behind, or further
    ahead) is a restarted stream (``resyncs``): taken, and followed from there.
    """

    __slots__ = (
        "_behind",
        "last",
        "lost",
        "max_gap",
        "out_of_order",
        "resync_after",
        "resyncs",
        "window",
    )

    def __init__(self, window: int = 64, resync_after: int = 3, max_gap: int = 1 << 16) -> None:
        self.window = window
        self.resync_after = resync_after
        self.max_gap = max_gap
        self.last = -1
        self.lost = 0
        self.out_of_order = 0
        self.resyncs = 0
        self._behind = 0

    def accept(self, seq: int) -> bool:
        """True: a new record (take it); False: out of order or a duplicate (drop it)."""
        if self.last < 0:
            self.last = seq
            return True
        ahead = (seq - self.last) & 0xFFFFFFFF
        if 0 < ahead <= self.max_gap:
            self.lost += ahead - 1
            self.last = seq
            self._behind = 0
            return True
        if ((self.last - seq) & 0xFFFFFFFF) <= self.window:
            self._behind += 1
            if self._behind < self.resync_after:
                self.out_of_order += 1
                return False
            self.out_of_order -= self.resync_after - 1  # they were the new stream's start
        self.resyncs += 1
        self.last = seq
        self._behind = 0
        return True


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
