"""KUKA RobotSensorInterface (RSI): XML over UDP, one exchange per interpolation cycle.

Every 4 ms (``IPO_FAST`` mode) or 12 ms (``IPO`` mode) the controller sends (KUKA,
*RobotSensorInterface* manual, the ``ETHERNET`` object; the element names are those of the RSI
configuration's ``<SEND>`` block)::

    <Rob Type="KUKA">
      <RIst X="…" Y="…" Z="…" A="…" B="…" C="…"/>     actual Cartesian pose (mm, deg)
      <RSol X="…" Y="…" Z="…" A="…" B="…" C="…"/>     planned Cartesian pose (mm, deg)
      <AIPos A1="…" A2="…" A3="…" A4="…" A5="…" A6="…"/>   actual axis angles (deg)
      <IPOC>123456</IPOC>
    </Rob>

and expects, within the cycle, the reply with the same ``IPOC``::

    <Sen Type="ImFree">
      <EStr>roboisf</EStr>
      <RKorr X="…" Y="…" Z="…" A="0" B="0" C="0"/>    correction (mm, deg)
      <IPOC>123456</IPOC>
    </Sen>

The ``RKorr`` correction is applied by the ``ST_CORRECTION`` / ``POSCORR`` object in the frame the
RSI configuration names (the ``BASE`` of the part: roboisf's work frame) and, depending on that
object, as an absolute offset or summed per cycle (relative). :func:`encode_reply` writes the
absolute correction; :class:`RsiAdapter` with ``relative=True`` sends the change since the last
reply instead. A reply that misses its cycle is counted by the controller as a late packet
(``Timeout`` after ``<RSIparameters>``' limit stops the robot).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

import numpy as np
from numpy.typing import NDArray

from roboisf.frames import abc_to_matrix, matrix_to_quat
from roboisf.online.base import ProtocolError, RobotState

__all__ = ["CYCLES", "RsiAdapter", "decode_robot", "encode_reply", "encode_robot"]

F64 = NDArray[np.float64]

#: RSI cycle times [s]: IPO_FAST and IPO
CYCLES = (0.004, 0.012)
_MAX_PACKET = 8192
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_CART = ("X", "Y", "Z", "A", "B", "C")
_DOCTYPE = re.compile(rb"<!(DOCTYPE|ENTITY)", re.IGNORECASE)


def _attrs(el: ET.Element | None, names: tuple[str, ...], what: str) -> F64:
    if el is None:
        raise ProtocolError(f"RSI message has no <{what}>", field=what)
    out = np.empty(len(names))
    for i, n in enumerate(names):
        v = el.get(n)
        if v is None:
            raise ProtocolError(f"<{what}> has no attribute {n}", field=what)
        try:
            out[i] = float(v)
        except ValueError:
            raise ProtocolError(f"<{what}> {n}={v!r} is not a number", field=what) from None
        if not math.isfinite(out[i]):
            raise ProtocolError(f"<{what}> {n}={v!r} is not finite", field=what)
    return out


def decode_robot(data: bytes) -> RobotState:
    """A controller message → :class:`RobotState` (joints rad from ``AIPos``; planned pose from
    ``RSol``, m and quaternion, NaN without it). :class:`ProtocolError` when malformed."""
    if len(data) > _MAX_PACKET:
        raise ProtocolError(f"RSI packet of {len(data)} bytes", field="packet")
    if _DOCTYPE.search(data):
        raise ProtocolError("RSI packet with a DTD or entity declaration", field="packet")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise ProtocolError(f"RSI packet is not XML ({e})", field="packet") from None
    if root.tag != "Rob":
        raise ProtocolError(f"RSI root element <{root.tag}>, expected <Rob>", field="Rob")
    ipoc = root.find("IPOC")
    if ipoc is None or ipoc.text is None or not ipoc.text.strip().isdigit():
        raise ProtocolError("RSI message without a numeric <IPOC>", field="IPOC")
    q = np.radians(_attrs(root.find("AIPos"), _AXES, "AIPos"))
    planned = np.full(7, np.nan)
    rsol = root.find("RSol")
    if rsol is not None:
        v = _attrs(rsol, _CART, "RSol")
        planned[:3] = v[:3] * 1e-3
        planned[3:] = matrix_to_quat(abc_to_matrix(np.radians(v[3:])))
    return RobotState(int(ipoc.text.strip()), q, planned)


def encode_robot(ipoc: int, q: F64, rist_mm_deg: F64 | None = None) -> bytes:
    """What a KUKA controller sends (the simulated controller): joints ``q`` (6,) rad."""
    qd = np.degrees(np.asarray(q, dtype=float))
    ax = " ".join(f'{n}="{v:.6f}"' for n, v in zip(_AXES, qd, strict=True))
    parts = ['<Rob Type="KUKA">']
    if rist_mm_deg is not None:
        c = " ".join(f'{n}="{v:.6f}"' for n, v in zip(_CART, rist_mm_deg, strict=True))
        parts.append(f"<RIst {c}/><RSol {c}/>")
    parts.append(f'<AIPos {ax}/><Delay D="0"/><IPOC>{int(ipoc)}</IPOC></Rob>')
    return "".join(parts).encode("ascii")


def encode_reply(ipoc: int, correction: F64, text: str = "roboisf") -> bytes:
    """The sensor's reply: ``RKorr`` X Y Z = ``correction`` (3,) m → mm, A B C = 0, the
    echoed ``IPOC``."""
    x, y, z = (float(v) * 1e3 for v in correction)
    return (
        f'<Sen Type="ImFree"><EStr>{text}</EStr>'
        f'<RKorr X="{x:.6f}" Y="{y:.6f}" Z="{z:.6f}" A="0.000000" B="0.000000" C="0.000000"/>'
        f"<IPOC>{int(ipoc)}</IPOC></Sen>"
    ).encode("ascii")


def decode_reply(data: bytes) -> tuple[int, F64]:
    """``(IPOC, correction (3,) m)`` of a reply (the simulated controller reads it)."""
    if _DOCTYPE.search(data) or len(data) > _MAX_PACKET:
        raise ProtocolError("bad RSI reply", field="packet")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise ProtocolError(f"RSI reply is not XML ({e})", field="packet") from None
    ipoc = root.find("IPOC")
    if root.tag != "Sen" or ipoc is None or ipoc.text is None or not ipoc.text.isdigit():
        raise ProtocolError("RSI reply needs <Sen> with a numeric <IPOC>", field="Sen")
    k = _attrs(root.find("RKorr"), _CART, "RKorr")
    return int(ipoc.text), k[:3] * 1e-3


class RsiAdapter:
    """Decode controller messages, encode replies (absolute, or ``relative`` per-cycle
    increments)."""

    name = "rsi"

    def __init__(self, cycle: float = 0.004, relative: bool = False) -> None:
        if not any(math.isclose(cycle, c) for c in CYCLES):
            raise ProtocolError(
                f"RSI cycles are 4 ms (IPO_FAST) or 12 ms (IPO), got {cycle * 1e3:g} ms",
                field="cycle",
            )
        self.cycle = cycle
        self.relative = relative
        self._sent = np.zeros(3)

    def decode(self, data: bytes) -> RobotState:
        return decode_robot(data)

    def encode(self, state: RobotState, correction: F64) -> bytes:
        if self.relative:
            inc = correction - self._sent
            self._sent[:] = correction
            return encode_reply(state.seq, inc)
        return encode_reply(state.seq, correction)
