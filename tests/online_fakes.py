"""Fake devices for the online loop's tests, written from the public protocol definitions only.

They import nothing from roboisf: what they accept or send is what the definitions say, not what
roboisf's own codecs do.

* KUKA RSI — the ``ETHERNET`` object's configuration file (``<CONFIG>`` with ``SENTYPE``,
  ``<SEND>`` and ``<RECEIVE>`` element lists, a ``TAG="Elem.Attr"`` entry being attribute
  ``Attr`` of element ``<Elem>``; ``HOLDON``) as in the public RSI configuration of
  ROS-Industrial's ``kuka_rsi_hw_interface`` (repository ros-industrial/kuka_experimental,
  files ``kuka_rsi_hw_interface/krl/KR_C4/ros_rsi_ethernet.xml`` and ``ros_rsi.src``; the
  message layout ``<Rob Type="KUKA">`` … ``<IPOC>`` read there by ``rsi_state.h``, the reply
  ``<Sen Type="ImFree"><AK A1…A6/><IPOC/></Sen>`` written by ``rsi_command.h``). The
  configuration is *parsed* here, so the fake controller accepts exactly the reply that
  configuration defines.
* ATI Net F/T RDT — ATI manual 9620-05-NET FT, "UDP interface using RDT": the 8-byte request
  (``>HHI``: 0x1234, command, sample count) and the 36-byte record (``>IIIiiiiii``:
  rdt_sequence, ft_sequence, status, Fx Fy Fz Tx Ty Tz in counts), as the public ROS driver
  ``netft_rdt_driver`` reads it.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

# ------------------------------------------------------------------------------ KUKA RSI


@dataclass
class RsiConfig:
    """An RSI ``ETHERNET`` configuration file, parsed."""

    sentype: str
    send: list[str]  # the SEND tags (DEF_RIst, …)
    receive: list[tuple[str, str, int, bool]]  # (element, attribute, INDX, HOLDON)

    @classmethod
    def read(cls, path: str | Path) -> RsiConfig:
        root = ET.parse(path).getroot()
        assert root.tag == "ROOT", root.tag
        cfg = root.find("CONFIG")
        assert cfg is not None
        sentype = (cfg.findtext("SENTYPE") or "").strip()
        assert (cfg.findtext("ONLYSEND") or "").strip() == "FALSE"  # it expects answers
        send = [e.get("TAG", "") for e in root.iterfind("SEND/ELEMENTS/ELEMENT")]
        receive = []
        for e in root.iterfind("RECEIVE/ELEMENTS/ELEMENT"):
            tag = e.get("TAG", "")
            elem, _, attr = tag.partition(".")
            assert elem and attr and e.get("TYPE") == "DOUBLE", tag
            receive.append((elem, attr, int(e.get("INDX", "0")), e.get("HOLDON") == "1"))
        return cls(sentype, send, receive)


class RsiReplyError(ValueError):
    """A reply the configured ETHERNET object would not take."""


class FakeKuka:
    """A KUKA controller's RSI side for one configuration.

    ``message(q_deg)`` is the controller's message of the next cycle (IPOC in ms, the SEND
    block's elements); ``take(reply, late)`` settles that cycle with the sensor's reply: parsed
    strictly against the RECEIVE block (root ``<Sen Type=SENTYPE>``, every configured attribute
    present and numeric, nothing else but ``<IPOC>``, the IPOC echoed). An in-time reply sets
    the channels (``RSI_ON(#ABSOLUTE)``) or adds to them (``#RELATIVE``); a late one (``late``
    or ``None``) is dropped and counted in ``Delay``: the channels keep their value
    (``HOLDON=1``) or get 0 added (``HOLDON=0``).
    """

    def __init__(self, config: RsiConfig, *, relative: bool = False, cycle_ms: int = 4) -> None:
        self.cfg = config
        self.relative = relative
        self.cycle_ms = cycle_ms
        self.ipoc = 1000
        self.delay = 0
        self.channels = [0.0] * len(config.receive)  # the ETHERNET object's outputs, by INDX
        self.taken = 0

    def message(self, q_deg: list[float], pose: list[float] | None = None) -> bytes:
        self.ipoc += self.cycle_ms
        pose = pose or [1000.0, 0.0, 500.0, 0.0, 90.0, 0.0]
        parts = []
        cart = " ".join(f'{k}="{v:.4f}"' for k, v in zip("XYZABC", pose, strict=True))
        axes = " ".join(f'A{i + 1}="{v:.4f}"' for i, v in enumerate(q_deg))
        for tag in self.cfg.send:
            name = tag.removeprefix("DEF_")
            if name in ("RIst", "RSol"):
                parts.append(f"<{name} {cart}/>")
            elif name in ("AIPos", "ASPos"):
                parts.append(f"<{name} {axes}/>")
            elif name == "Delay":
                parts.append(f'<Delay D="{self.delay}"/>')
        return f'<Rob Type="KUKA">{"".join(parts)}<IPOC>{self.ipoc}</IPOC></Rob>'.encode()

    def parse(self, reply: bytes) -> dict[int, float]:
        """The channel values (by INDX) of a reply, or :class:`RsiReplyError`."""
        try:
            root = ET.fromstring(reply)
        except ET.ParseError as e:
            raise RsiReplyError(f"not XML: {e}") from None
        if root.tag != "Sen" or root.get("Type") != self.cfg.sentype:
            raise RsiReplyError(f"root <{root.tag} Type={root.get('Type')!r}>")
        wanted = {elem for elem, _, _, _ in self.cfg.receive} | {"IPOC"}
        extra = [c.tag for c in root if c.tag not in wanted]
        if extra:
            raise RsiReplyError(f"elements the configuration does not receive: {extra}")
        if (root.findtext("IPOC") or "").strip() != str(self.ipoc):
            raise RsiReplyError(f"IPOC {root.findtext('IPOC')!r}, expected {self.ipoc}")
        out = {}
        for elem, attr, indx, _ in self.cfg.receive:
            el = root.find(elem)
            if el is None or el.get(attr) is None:
                raise RsiReplyError(f"no {elem}.{attr}")
            out[indx] = float(el.get(attr, "nan"))
        return out

    def take(self, reply: bytes | None, late: bool = False) -> None:
        if reply is None or late:
            self.delay += 1
            return
        values = self.parse(reply)
        for elem_i, (_, _, indx, _) in enumerate(self.cfg.receive):
            v = values[indx]
            self.channels[elem_i] = self.channels[elem_i] + v if self.relative else v
        self.taken += 1


# ------------------------------------------------------------------------------ ATI Net F/T
_REQ = struct.Struct(">HHI")
_REC = struct.Struct(">IIIiiiiii")


def rdt_record(rdt_seq: int, ft_seq: int, status: int, wrench, cpf: float = 1e6, cpt: float = 1e6):
    """One 36-byte RDT record of ``wrench`` (N, N·m)."""
    counts = [round(w * (cpf if i < 3 else cpt)) for i, w in enumerate(wrench)]
    return _REC.pack(rdt_seq & 0xFFFFFFFF, ft_seq & 0xFFFFFFFF, status, *counts)


@dataclass
class FakeNetFT:
    """A Net F/T on 127.0.0.1 (a thread): on a start request (command 2) it streams one record
    every ``period`` s of ``wrench`` to the requester; command 0 stops. ``restart()`` begins a
    new stream from rdt_sequence 1 (a power cycle) without a request."""

    wrench: list[float] = field(default_factory=lambda: [0.0, 0.0, 500.0, 0.0, 0.0, 0.0])
    period: float = 1e-3
    requests: list[tuple[int, int]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.0005)
        self.port = self.sock.getsockname()[1]
        self.peer = None
        self.seq = 0
        self._stop = threading.Event()
        self._th = threading.Thread(target=self._serve, daemon=True)
        self._th.start()

    def restart(self) -> None:
        self.seq = 0

    def _serve(self) -> None:
        nxt = time.perf_counter()
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(64)
                header, cmd, count = _REQ.unpack(data)
                assert header == 0x1234
                self.requests.append((cmd, count))
                if cmd == 2:
                    self.peer = addr
                elif cmd == 0:
                    self.peer = None
            except (TimeoutError, BlockingIOError):
                pass
            except OSError:
                continue
            now = time.perf_counter()
            if self.peer is not None and now >= nxt:
                self.seq += 1
                try:
                    self.sock.sendto(rdt_record(self.seq, self.seq, 0, self.wrench), self.peer)
                except OSError:
                    pass
                nxt = max(nxt + self.period, now - 0.01)

    def close(self) -> None:
        self._stop.set()
        self._th.join(5)
        self.sock.close()
