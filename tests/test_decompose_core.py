"""Decomposition arithmetic: exact recovery on synthetic superpositions, R_m by hand, shares."""

import numpy as np
import pytest

from roboisf.decompose import FACTORS, contribution_rows, decompose, resultant_mean_deviation
from roboisf.errors import InputError

rng = np.random.default_rng(11)


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def synthetic(N=500):
    n = unit(rng.normal(size=(N, 3)))
    truth = {
        "tool": rng.normal(scale=1e-4, size=(N, 3)),
        "tool_holder": rng.normal(scale=1e-5, size=(N, 3)),
        "springback": rng.normal(scale=5e-4, size=(N, 1)) * n,  # normal field, as scanned
        "robot_compliance": rng.normal(scale=4e-4, size=(N, 3)),
    }
    tool_cnc = truth["tool"] * 1.02
    dn_cnc = np.einsum("ij,ij->i", truth["springback"] + tool_cnc, n)
    total = sum(truth.values())
    dn_robot = np.einsum("ij,ij->i", total, n)
    return n, truth, tool_cnc, dn_cnc, dn_robot


def test_normal_components_are_recovered_exactly():
    n, truth, tool_cnc, dn_cnc, dn_robot = synthetic()
    d = decompose(
        n,
        dn_cnc,
        dn_robot,
        tool_cnc,
        truth["tool"],
        truth["tool_holder"],
        truth["robot_compliance"],
        np.ones(len(n), bool),
    )
    for f in FACTORS:
        np.testing.assert_allclose(d.normal[f], np.einsum("ij,ij->i", truth[f], n), atol=1e-15)
    np.testing.assert_allclose(d.normal["delta"], 0.0, atol=1e-15)


def test_resultant_mean_deviation_by_hand():
    v = np.array([[1.0, -2.0, 0.0], [-3.0, 2.0, 4.0]])
    # mean |x| = 2, mean |y| = 2, mean |z| = 2 → sqrt(12)
    assert resultant_mean_deviation(v) == pytest.approx(np.sqrt(12.0))


def test_contribution_rows_shares_sum_to_100_and_total_row():
    n, truth, tool_cnc, dn_cnc, dn_robot = synthetic()
    d = decompose(
        n,
        dn_cnc,
        dn_robot,
        tool_cnc,
        truth["tool"],
        truth["tool_holder"],
        truth["robot_compliance"],
        np.ones(len(n), bool),
    )
    for projected in (False, True):
        rows = contribution_rows(d, projected=projected)
        assert [r["factor"] for r in rows] == [*FACTORS, "total"]
        assert sum(r["share_percent"] for r in rows[:-1]) == pytest.approx(100.0)
        assert rows[-1]["R_m"] == pytest.approx(resultant_mean_deviation(dn_robot[:, None] * n))


def test_valid_mask_and_shapes():
    n, truth, tool_cnc, dn_cnc, dn_robot = synthetic(10)
    with pytest.raises(InputError, match="shape"):
        decompose(
            n,
            dn_cnc[:5],
            dn_robot,
            tool_cnc,
            truth["tool"],
            truth["tool_holder"],
            truth["robot_compliance"],
            np.ones(10, bool),
        )
    d = decompose(
        n,
        dn_cnc,
        dn_robot,
        tool_cnc,
        truth["tool"],
        truth["tool_holder"],
        truth["robot_compliance"],
        np.zeros(10, bool),
    )
    with pytest.raises(InputError, match="no toolpath point"):
        contribution_rows(d, projected=False)


def test_a_command_is_booked_by_what_a_scan_sees_of_it():
    """A compensated run's command: its normal part comes out of the robot term in both books
    (the part then deviates by it by design); its tangential part, which moves the contact along
    the surface and which no scan observes, changes nothing — else the per-axis robot term of a
    compensated run would carry the command's own tangential deflection, and its share would
    jump against the first run's for the same robot."""
    n, truth, tool_cnc, dn_cnc, dn_robot = synthetic()
    N = len(n)
    args = (tool_cnc, truth["tool"], truth["tool_holder"], truth["robot_compliance"])
    base = decompose(n, dn_cnc, dn_robot, *args, np.ones(N, bool))
    c_n = rng.normal(scale=1e-3, size=N)
    t = rng.normal(scale=1e-3, size=(N, 3))
    tangential = t - np.einsum("ij,ij->i", t, n)[:, None] * n
    command = c_n[:, None] * n + tangential
    d = decompose(n, dn_cnc, dn_robot + c_n, *args, np.ones(N, bool), command)
    for f in (*FACTORS, "vjm", "delta"):
        np.testing.assert_allclose(d.vectors[f], base.vectors[f], rtol=0, atol=1e-15)
        np.testing.assert_allclose(d.normal[f], base.normal[f], rtol=0, atol=1e-15)
    np.testing.assert_allclose(d.normal["command"], c_n, rtol=0, atol=1e-15)
    # the per-axis book adds up: the measured part = the four factors + the command seen
    parts = sum(d.vectors[f] for f in FACTORS) + d.vectors["command"]
    np.testing.assert_allclose(parts, d.vectors["robot"], rtol=0, atol=1e-15)
    shares = {r["factor"]: r["share_percent"] for r in contribution_rows(d, projected=False)}
    expect = {r["factor"]: r["share_percent"] for r in contribution_rows(base, projected=False)}
    assert shares == pytest.approx(expect, abs=1e-9)
