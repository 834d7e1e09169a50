"""KUKA RobotSensorInterface (RSI): XML over UDP, one exchange per interpolation cycle.

Every 4 ms (``IPO_FAST``) or 12 ms (``IPO``) the controller's ``ETHERNET`` object sends the
elements its configuration's ``<SEND>`` block lists; with the ``DEF_`` elements of the
configuration roboisf ships (``rsi_config/roboisf_rsi_ethernet.xml``)::

    <Rob Type="KUKA">
      <RIst X="…" Y="…" Z="…" A="…" B="…" C="…"/>     actual Cartesian pose (mm, deg)
      <RSol X="…" Y="…" Z="…" A="…" B="…" C="…"/>     planned Cartesian pose (mm, deg)
      <AIPos A1="…" … A6="…"/>                         actual axis angles (deg)
      <ASPos A1="…" … A6="…"/>                         planned axis angles (deg)
      <Delay D="…"/>                                   replies that came late, counted
      <IPOC>123456</IPOC>                              the cycle's time stamp (ms)
    </Rob>

and expects, within the cycle, a reply with the same ``IPOC`` whose elements are the
configuration's ``<RECEIVE>`` block: a ``TAG="RKorr.X"`` entry is the attribute ``X`` of the
element ``<RKorr>``. The root is ``<Sen Type="…">`` with the configuration's ``SENTYPE``. Two
corrections, by option (:class:`RsiAdapter` ``correction``):

* ``"cartesian"`` — ``<RKorr X Y Z A B C/>`` (mm, deg), into an ``POSCORR`` object working in
  the part's ``BASE`` (roboisf's work frame);
* ``"joint"`` — ``<AK A1 … A6/>`` (deg), into an ``AXISCORR`` object: the layout of the public
  configuration ROS-Industrial's ``kuka_rsi_hw_interface`` uses; roboisf turns the Cartesian
  correction ``c`` into axis corrections ``Δq = J⁻¹ [c; 0]`` at the message's joint angles.

``RSI_ON(#ABSOLUTE)`` applies each reply as the whole correction; ``RSI_ON(#RELATIVE)`` adds each
reply to the sum (``relative=True``). The controller drops a reply that missed its cycle (it
counts it in ``Delay``; with ``HOLDON="0"`` the object then adds nothing): in relative mode
:class:`RsiAdapter` reads ``Delay`` and sends the increment it lost again, so the increments that
arrive always sum to the correction (:meth:`RsiAdapter.encode`). ``docs/online.md`` describes the
configuration files and the KRL program (``rsi_config/``).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames import abc_to_matrix, matrix_to_quat
from roboisf.online.base import ProtocolError, RobotState

__all__ = [
    "CORRECTIONS",
    "CYCLES",
    "RsiAdapter",
    "config_files",
    "decode_reply",
    "decode_robot",
    "encode_reply",
    "encode_robot",
]

F64 = NDArray[np.float64]

#: RSI cycle times [s]: IPO_FAST and IPO
CYCLES = (0.004, 0.012)
#: the reply's correction element by kind: (element, attributes, unit)
CORRECTIONS = {
    "cartesian": ("RKorr", ("X", "Y", "Z", "A", "B", "C")),
    "joint": ("AK", ("A1", "A2", "A3", "A4", "A5", "A6")),
}
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


def _parse(data: bytes, what: str) -> ET.Element:
    if len(data) > _MAX_PACKET:
        raise ProtocolError(f"RSI {what} of {len(data)} bytes", field="packet")
    if _DOCTYPE.search(data):
        raise ProtocolError(f"RSI {what} with a DTD or entity declaration", field="packet")
    try:
        return ET.fromstring(data)
    except ET.ParseError as e:
        raise ProtocolError(f"RSI {what} is not XML ({e})", field="packet") from None


def _ipoc(root: ET.Element) -> int:
    ipoc = root.find("IPOC")
    if ipoc is None or ipoc.text is None or not ipoc.text.strip().isdigit():
        raise ProtocolError("RSI message without a numeric <IPOC>", field="IPOC")
    return int(ipoc.text.strip())


def decode_robot(data: bytes) -> RobotState:
    """A controller message → :class:`RobotState` (joints rad from ``AIPos``; planned pose from
    ``RSol``, m and quaternion, NaN without it; ``Delay D``, −1 without it).
    :class:`ProtocolError` when malformed."""
    root = _parse(data, "packet")
    if root.tag != "Rob":
        raise ProtocolError(f"RSI root element <{root.tag}>, expected <Rob>", field="Rob")
    seq = _ipoc(root)
    q = np.radians(_attrs(root.find("AIPos"), _AXES, "AIPos"))
    planned = np.full(7, np.nan)
    rsol = root.find("RSol")
    if rsol is not None:
        v = _attrs(rsol, _CART, "RSol")
        planned[:3] = v[:3] * 1e-3
        planned[3:] = matrix_to_quat(abc_to_matrix(np.radians(v[3:])))
    delay = -1
    d = root.find("Delay")
    if d is not None:
        dv = d.get("D", "")
        if not dv.strip().isdigit():
            raise ProtocolError(f"<Delay> D={dv!r} is not a count", field="Delay")
        delay = int(dv)
    return RobotState(seq, q, planned, delay)


def encode_robot(
    ipoc: int,
    q: F64,
    rist_mm_deg: F64 | None = None,
    *,
    delay: int | None = None,
) -> bytes:
    """What a KUKA controller sends (the simulated controller): joints ``q`` (6,) rad as
    ``AIPos`` and ``ASPos``, the pose as ``RIst`` and ``RSol`` when given, ``Delay``."""
    qd = np.degrees(np.asarray(q, dtype=float))
    ax = " ".join(f'{n}="{v:.6f}"' for n, v in zip(_AXES, qd, strict=True))
    parts = ['<Rob Type="KUKA">']
    if rist_mm_deg is not None:
        c = " ".join(f'{n}="{v:.6f}"' for n, v in zip(_CART, rist_mm_deg, strict=True))
        parts.append(f"<RIst {c}/><RSol {c}/>")
    parts.append(f"<AIPos {ax}/><ASPos {ax}/>")
    parts.append(f'<Delay D="{int(delay or 0)}"/><IPOC>{int(ipoc)}</IPOC></Rob>')
    return "".join(parts).encode("ascii")


def encode_reply(
    ipoc: int, values: F64, *, correction: str = "cartesian", sentype: str = "ImFree"
) -> bytes:
    """The sensor's reply: ``cartesian`` — ``RKorr`` X Y Z = ``values`` (3,) m → mm, A B C = 0;
    ``joint`` — ``AK`` A1…A6 = ``values`` (6,) rad → deg; the echoed ``IPOC``."""
    tag, names = CORRECTIONS[correction]
    v = np.asarray(values, dtype=float)
    if correction == "cartesian":
        out = [*(float(x) * 1e3 for x in v[:3]), 0.0, 0.0, 0.0]
    else:
        out = [math.degrees(float(x)) for x in v[:6]]
    attrs = " ".join(f'{n}="{x:.6f}"' for n, x in zip(names, out, strict=True))
    return f'<Sen Type="{sentype}"><{tag} {attrs}/><IPOC>{int(ipoc)}</IPOC></Sen>'.encode("ascii")


def decode_reply(data: bytes, correction: str = "cartesian") -> tuple[int, F64]:
    """``(IPOC, values)`` of a reply (the simulated controller reads it): ``cartesian`` —
    the correction (3,) m; ``joint`` — the axis corrections (6,) rad."""
    root = _parse(data, "reply")
    if root.tag != "Sen":
        raise ProtocolError("RSI reply needs <Sen> with a numeric <IPOC>", field="Sen")
    ipoc = _ipoc(root)
    tag, names = CORRECTIONS[correction]
    k = _attrs(root.find(tag), names, tag)
    return ipoc, (k[:3] * 1e-3 if correction == "cartesian" else np.radians(k))


def config_files() -> dict[str, Path]:
    """The RSI configuration files and KRL program roboisf ships (``rsi_config/``), by name."""
    root = resources.files("roboisf.online") / "rsi_config"
    return {p.name: Path(str(p)) for p in root.iterdir() if p.is_file() and p.name[0] != "_"}


class RsiAdapter:
    """Decode controller messages, encode replies.

    Parameters
    ----------
    cycle : float, s — 0.004 (IPO_FAST) or 0.012 (IPO)
    relative : bool — send increments (``RSI_ON(#RELATIVE)``) instead of the whole correction
    correction : ``"cartesian"`` (``RKorr``) or ``"joint"`` (``AK``)
    dq_dp : callable, q (6,) rad → (6, 3) rad/m — the axis change per tip translation (work
        axes) at ``q``; required for ``"joint"``
    sentype : the configuration's ``SENTYPE`` (``<Sen Type=…>``)

    In relative mode each reply carries ``target − sent``, ``sent`` the sum of the increments the
    controller took: when a message's ``Delay`` count has grown by more than the cycles the loop
    never saw (their ``IPOC`` gap), the last reply came late and was dropped, so its increment
    is taken back out of ``sent`` and goes out again in this reply.
    """

    name = "rsi"

    def __init__(
        self,
        cycle: float = 0.004,
        relative: bool = False,
        *,
        correction: str = "cartesian",
        dq_dp: Callable[[F64], F64] | None = None,
        sentype: str = "ImFree",
    ) -> None:
        if not any(math.isclose(cycle, c) for c in CYCLES):
            raise ProtocolError(
                f"RSI cycles are 4 ms (IPO_FAST) or 12 ms (IPO), got {cycle * 1e3:g} ms",
                field="cycle",
            )
        if correction not in CORRECTIONS:
            raise InputError(
                f"must be cartesian (RKorr) or joint (AK), got {correction!r}", field="correction"
            )
        if correction == "joint" and dq_dp is None:
            raise InputError("joint corrections need the robot's Jacobian", field="dq_dp")
        if not re.fullmatch(r"[A-Za-z0-9_]+", sentype):
            raise InputError(f"must be a plain name, got {sentype!r}", field="sentype")
        self.cycle = cycle
        self.relative = relative
        self.correction = correction
        self.sentype = sentype
        self._dq_dp = dq_dp
        n = 3 if correction == "cartesian" else 6
        self._sent = np.zeros(n)  # relative: the sum of increments the controller took
        self._pending = np.zeros(n)  # relative: the last reply's increment, not yet confirmed
        self._last_ipoc = -1
        self._last_delay = -1
        self.resent = 0  # relative: increments sent again after a late reply

    def decode(self, data: bytes) -> RobotState:
        return decode_robot(data)

    def _values(self, state: RobotState, correction: F64) -> F64:
        if self.correction == "cartesian":
            return np.asarray(correction, dtype=float)
        assert self._dq_dp is not None
        return np.asarray(self._dq_dp(state.q), dtype=float) @ correction

    def encode(self, state: RobotState, correction: F64) -> bytes:
        v = self._values(state, correction)
        if not self.relative:
            return encode_reply(state.seq, v, correction=self.correction, sentype=self.sentype)
        if self._last_delay >= 0 and state.delay > self._last_delay:
            step = max(1, round(self.cycle * 1e3))  # IPOC counts ms
            unseen = max(0, (state.seq - self._last_ipoc) // step - 1)
            if state.delay - self._last_delay > unseen:  # our last reply was among the late
                self._sent -= self._pending
                self.resent += 1
        self._last_delay, self._last_ipoc = state.delay, state.seq
        # on the wire's own grid (6 decimals of mm or deg): the controller sums exactly what
        # was sent, so rounding never adds up either
        scale = 1e3 if self.correction == "cartesian" else 180.0 / math.pi
        inc = np.round((v - self._sent) * scale, 6) / scale
        self._sent += inc
        self._pending = inc
        return encode_reply(state.seq, inc, correction=self.correction, sentype=self.sentype)
