"""The wire formats: EGM protobuf, KUKA RSI XML, ATI RDT records; malformed packets refused."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from roboisf.online import egm, netft, rsi
from roboisf.online.base import ProtocolError

Q = np.radians([10.0, -20.0, 30.0, 40.0, 50.0, 60.0])
PLANNED = np.array([1.2, 0.2, 0.3, 0.0, 0.0, 1.0, 0.0])
CORR = np.array([1e-4, -3e-5, -2.5e-4])
ONLINE = Path(__file__).parents[1] / "src" / "roboisf" / "online"


def _has_grpc_tools() -> bool:
    try:
        import grpc_tools  # noqa: F401
    except ImportError:
        return False
    return True


def _varint(v: int) -> bytes:
    out = b""
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out += bytes([b | 0x80])
        else:
            return out + bytes([b])


def _ld(field: int, payload: bytes) -> bytes:
    return _varint(field << 3 | 2) + _varint(len(payload)) + payload


def _dbl(field: int, v: float) -> bytes:
    return _varint(field << 3 | 1) + struct.pack("<d", v)


def test_egm_robot_parses_hand_encoded_wire_bytes():
    """An EgmRobot built byte by byte from the protobuf wire format with ABB's field numbers
    (header=1{seqno=1, tm=2, mtype=3}, feedBack=2{joints=1{joints=1}}, planned=3{cartesian=2
    {pos=1, orient=2}}) — independent of the generated module."""
    header = _varint(1 << 3) + _varint(77) + _varint(2 << 3) + _varint(1234)
    header += _varint(3 << 3) + _varint(2)
    joints = b"".join(_dbl(1, v) for v in np.degrees(Q))
    feedback = _ld(1, joints)
    pos = _dbl(1, 1200.0) + _dbl(2, 200.0) + _dbl(3, 300.0)
    orient = _dbl(1, 0.0) + _dbl(2, 0.0) + _dbl(3, 1.0) + _dbl(4, 0.0)
    planned = _ld(2, _ld(1, pos) + _ld(2, orient))
    unknown = _ld(9, _dbl(1, 5.0))  # measuredForce: not in roboisf's subset, skipped
    data = _ld(1, header) + _ld(2, feedback) + _ld(3, planned) + unknown
    s = egm.decode_robot(data)
    assert s.seq == 77
    np.testing.assert_allclose(s.q, Q)
    np.testing.assert_allclose(s.planned, PLANNED)


def test_egm_round_trip_and_correction():
    s = egm.decode_robot(egm.encode_robot(5, 100, Q, PLANNED))
    _seq, pose = egm.decode_sensor(egm.EgmAdapter().encode(s, CORR))
    np.testing.assert_allclose(pose[:3], PLANNED[:3] + CORR)
    np.testing.assert_allclose(pose[3:], PLANNED[3:])
    _, pc = egm.decode_sensor(egm.EgmAdapter(path_correction=True).encode(s, CORR))
    # EGMActMove's sensor frame is the TCP (tool.tframe): the planned TCP here is turned 180°
    # about the work y axis (quaternion 0, 0, 1, 0), so x and z change sign, y does not
    np.testing.assert_allclose(pc[:3], CORR * [-1, 1, -1], atol=1e-15)
    # a general orientation: the TCP-frame vector, rotated back, is the work-axes correction
    from roboisf.frames import matrix_to_quat, rpy_to_matrix

    R = rpy_to_matrix(np.radians([20.0, -35.0, 110.0]))
    s2 = egm.decode_robot(egm.encode_robot(6, 104, Q, np.r_[PLANNED[:3], matrix_to_quat(R)]))
    _, pc2 = egm.decode_sensor(egm.EgmAdapter(path_correction=True).encode(s2, CORR))
    np.testing.assert_allclose(R @ pc2[:3], CORR, atol=1e-12)
    with pytest.raises(ProtocolError, match="planned orientation"):
        egm.EgmAdapter(path_correction=True).encode(
            egm.decode_robot(egm.encode_robot(1, 0, Q)), CORR
        )
    with pytest.raises(ProtocolError, match="planned pose"):
        egm.EgmAdapter().encode(egm.decode_robot(egm.encode_robot(1, 0, Q)), CORR)


@pytest.mark.parametrize(
    "data",
    [b"", b"\xff\xff\xff", egm.encode_robot(1, 0, Q[:5]), b"\x0a\x02\x18\x03", b"x" * 5000],
)
def test_egm_malformed(data):
    with pytest.raises(ProtocolError):
        egm.decode_robot(data)


@pytest.mark.skipif(not _has_grpc_tools(), reason="grpcio-tools (the test extra) not installed")
def test_generated_egm_module_matches_its_proto(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "grpc_tools.protoc",
        f"-I{ONLINE / 'proto'}",
        f"--python_out={tmp_path}",
        str(ONLINE / "proto" / "roboisf_egm.proto"),
    ]
    subprocess.run(cmd, check=True)
    fresh = (tmp_path / "roboisf_egm_pb2.py").read_text()
    vendored = (ONLINE / "roboisf_egm_pb2.py").read_text()

    def body(s: str) -> str:  # the serialized descriptor is what defines the messages
        return next(line for line in s.splitlines() if "AddSerializedFile" in line)

    assert body(fresh) == body(vendored)


def test_rsi_round_trip_and_ipoc_echo():
    data = rsi.encode_robot(987654, Q, np.array([1200, 200, 300, 0, 90, 0.0]))
    s = rsi.decode_robot(data)
    assert s.seq == 987654
    np.testing.assert_allclose(s.q, Q, atol=1e-8)
    reply = rsi.RsiAdapter().encode(s, CORR)
    assert b'<Sen Type="ImFree">' in reply and b"<IPOC>987654</IPOC>" in reply
    ipoc, k = rsi.decode_reply(reply)
    assert ipoc == 987654
    np.testing.assert_allclose(k, CORR, atol=1e-9)


def test_rsi_relative_mode_sends_increments_that_sum_to_the_correction():
    a = rsi.RsiAdapter(relative=True)
    s = rsi.decode_robot(rsi.encode_robot(1, Q))
    total = np.zeros(3)
    for c in (CORR, 2 * CORR, -CORR):
        total += rsi.decode_reply(a.encode(s, c))[1]
        np.testing.assert_allclose(total, c, atol=3e-9)
    with pytest.raises(ProtocolError, match="4 ms"):
        rsi.RsiAdapter(cycle=0.010)


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"<Rob>",
        b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5"/><IPOC>1</IPOC></Rob>',
        b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="x"/><IPOC>1</IPOC></Rob>',
        b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="nan"/><IPOC>1</IPOC>'
        b"</Rob>",
        b'<Rob Type="KUKA"><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/></Rob>',
        b'<!DOCTYPE r [<!ENTITY a "aaaa">]><Rob Type="KUKA"><IPOC>&a;</IPOC></Rob>',
        b"<Sen/>",
    ],
)
def test_rsi_malformed(data):
    with pytest.raises(ProtocolError):
        rsi.decode_robot(data)


def test_rdt_request_and_records_match_the_manual_layout():
    req = netft.encode_request(netft.CMD_START_REALTIME, 1000)
    assert req == bytes.fromhex("12340002000003e8")
    assert netft.decode_request(req) == (2, 1000)
    W = np.array([12.5, -3.25, 400.0, 0.5, -0.125, 2.0])
    rec = netft.encode_record(7, 9, 0, W, 1e6, 1e6)
    assert len(rec) == 36
    assert struct.unpack(">IIIiiiiii", rec) == (
        7,
        9,
        0,
        12_500_000,
        -3_250_000,
        400_000_000,
        500_000,
        -125_000,
        2_000_000,
    )
    (r,) = netft.decode_records(rec, 1e6, 1e6)
    assert (r.rdt_sequence, r.ft_sequence, r.status) == (7, 9, 0)
    np.testing.assert_allclose(r.wrench, W)
    two = netft.decode_records(rec + rec, 1e6, 1e6)  # buffered mode: several per packet
    assert len(two) == 2


@pytest.mark.parametrize("data", [b"", b"\0" * 35, b"\0" * 37, b"\0" * 8])
def test_rdt_malformed(data):
    with pytest.raises(ProtocolError):
        netft.decode_records(data)


@pytest.mark.parametrize(
    "data", [b"\0" * 7, bytes.fromhex("43210002000003e8"), bytes.fromhex("12340009000003e8")]
)
def test_rdt_bad_request(data):
    with pytest.raises(ProtocolError):
        netft.decode_request(data)
