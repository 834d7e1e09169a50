"""The compiled position-alignment projection equals the numpy path (issue #16)."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.jit import background as jit_background
from roboisf.jit import native
from roboisf.sync import position, position_kernel

pytestmark = pytest.mark.skipif(not position_kernel.HAVE_NUMBA, reason="numba not installed")


def _segments(tip: np.ndarray) -> tuple[np.ndarray, ...]:
    D = np.diff(tip, axis=0)
    seglen = np.linalg.norm(D, axis=1)
    S = np.concatenate([[0.0], np.cumsum(seglen)])
    return tip[:-1], D, seglen**2, S[:-1], seglen


def test_project_kernel_equals_numpy() -> None:
    rng = np.random.default_rng(3)
    tip = np.cumsum(rng.normal(scale=1e-3, size=(200, 3)), axis=0)
    tip[50] = tip[49]  # a zero-length segment
    A, D, L2, S0, seglen = _segments(tip)
    P = tip[rng.integers(0, 200, 500)] + rng.normal(scale=5e-4, size=(500, 3))
    s_k, d_k = position_kernel.project_segments(P, A, D, L2, S0, seglen)
    s_n, d_n = position._project_numpy(P, A, D, L2, S0, seglen)
    # the same operations in the same order: the same bits
    np.testing.assert_array_equal(s_k, s_n)
    np.testing.assert_array_equal(d_k, d_n)


def test_track_compiled_equals_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """A helix path; the log pauses, leaves the path (retract), comes back and restarts."""
    th = np.linspace(0, 6 * np.pi, 3000)
    tip = np.c_[0.05 * np.cos(th), 0.05 * np.sin(th), -0.001 * th]
    S = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(tip, axis=0), axis=1))])
    rng = np.random.default_rng(7)
    walk = np.r_[np.linspace(0, 1200, 900), np.full(200, 1200.0), np.linspace(1200, 2999, 1500)]
    P = np.array([tip[int(i)] for i in walk]) + rng.normal(scale=2e-5, size=(len(walk), 3))
    P[:50] += [0, 0, 0.05]  # approach, off the path
    P[1000:1100] += [0, 0, 0.02]  # retract during the pause
    s_k = position._track(P, tip, S, position.OFF_PATH)
    monkeypatch.setitem(jit_background._decided, "sync", False)  # a cold kernel cache
    monkeypatch.setattr(native, "_suspended", 1)  # and no C form: the numpy path
    s_n = position._track(P, tip, S, position.OFF_PATH)
    assert np.isnan(s_n).any() and np.isfinite(s_n).sum() > 2000
    np.testing.assert_array_equal(np.isnan(s_k), np.isnan(s_n))
    np.testing.assert_array_equal(s_k, s_n)  # the projections are the same bits


def _helix_log(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A helix toolpath and a log that approaches, pauses (longer than one block of samples),
    retracts, comes back, and restarts from a later line after leaving the path."""
    th = np.linspace(0, 6 * np.pi, 3000)
    tip = np.c_[0.05 * np.cos(th), 0.05 * np.sin(th), -0.001 * th]
    S = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(tip, axis=0), axis=1))])
    rng = np.random.default_rng(seed)
    walk = np.r_[
        np.linspace(0, 1200, 900),
        np.full(5000, 1200.0),  # a pause longer than _MAX_BLOCK_SAMPLES
        np.linspace(1200, 1800, 600),
        np.linspace(1800, 1800, 300),  # leaves the path here (below) …
        np.linspace(2100, 2999, 900),  # … and restarts 300 points further on
    ]
    P = np.array([tip[int(i)] for i in walk]) + rng.normal(scale=2e-5, size=(len(walk), 3))
    P[:50] += [0, 0, 0.05]  # approach, off the path
    P[3000:3100] += [0, 0, 0.02]  # retract during the pause
    P[6500:6800] += [0, 0, 0.03]  # off the path before the restart
    return tip, S, P


@pytest.mark.parametrize("seed", [7, 11])
def test_track_loop_compiled_same_bits(monkeypatch: pytest.MonkeyPatch, seed: int) -> None:
    """The compiled tracking loop gives the same progress, bit for bit, as the Python loop over
    the compiled projection (the path before the loop was compiled), re-acquisitions included."""
    tip, S, P = _helix_log(seed)
    s_k = position._track(P, tip, S, position.OFF_PATH)
    monkeypatch.setattr(position, "_COMPILED_LOOP", False)
    s_p = position._track(P, tip, S, position.OFF_PATH)
    assert np.isnan(s_p[:50]).all() and np.isnan(s_p[6500:6800]).all()
    assert np.nanmax(s_p[6800:]) > S[2900] and np.isfinite(s_p).sum() > 7000
    np.testing.assert_array_equal(s_k, s_p)  # NaN where off the path, the same bits elsewhere
    monkeypatch.setitem(jit_background._decided, "sync", False)  # a cold kernel cache
    monkeypatch.setattr(native, "_suspended", 1)  # and no C form: the numpy path
    s_n = position._track(P, tip, S, position.OFF_PATH)
    np.testing.assert_array_equal(np.isnan(s_k), np.isnan(s_n))
    ok = np.isfinite(s_n)
    np.testing.assert_allclose(s_k[ok], s_n[ok], rtol=0, atol=1e-12)


def test_travel_is_the_norm_of_the_differences() -> None:
    """The logged travel built column by column: the bits of the running sum of
    ``np.linalg.norm(np.diff(P, axis=0), axis=1)`` (which it replaced), on a C and a strided
    array and the shortest logs."""
    rng = np.random.default_rng(11)
    P = np.cumsum(rng.normal(scale=1e-4, size=(20_000, 3)), axis=0) + np.array([0.4, -0.2, 0.1])
    for X in (P, P[::3], np.asfortranarray(P), P[:2], P[:1]):
        ref = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
        assert position._travel(X).tobytes() == ref.tobytes()
    assert position._travel(P[:0]).shape == (0,)
