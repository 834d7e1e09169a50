"""The compiled passes over a force log give the numpy forms' bits (issue #16)."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.logs import forcelog
from roboisf.sensor import conditioning

kernel = pytest.importorskip("roboisf.logs.forcelog_kernel")


def _log(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, n)) + 12.0
    W = rng.normal(scale=[300, 300, 900, 20, 20, 5], size=(n, 6))
    W[: n // 5] = rng.normal(scale=0.5, size=(n // 5, 6)) + np.array([1.0, -2, 3, 0.1, 0, -0.2])
    return t, W


def test_row_norms_same_bits() -> None:
    _, W = _log(50_000, 1)
    c = np.array([0.3, -1.7, 2.9])
    np.testing.assert_array_equal(kernel.row_norms(W, 0), np.linalg.norm(W[:, :3], axis=1))
    np.testing.assert_array_equal(kernel.row_norms(W, 3), np.linalg.norm(W[:, 3:], axis=1))
    np.testing.assert_array_equal(kernel.row_norms(W, 0, c), np.linalg.norm(W[:, :3] - c, axis=1))


def test_numpy_row_norms_same_bits() -> None:
    """The numpy form (a first run, the plain install): the same bits as ``np.linalg.norm``
    and the compiled kernel, with and without a centre, on the force and the moment columns,
    and on a non-contiguous (strided) wrench."""
    _, W = _log(50_000, 6)
    c = np.array([0.3, -1.7, 2.9])
    for X in (W, np.asfortranarray(W), W[::2]):
        np.testing.assert_array_equal(
            forcelog.row_norms_numpy(X, 0), np.linalg.norm(X[:, :3], axis=1)
        )
        np.testing.assert_array_equal(
            forcelog.row_norms_numpy(X, 3), np.linalg.norm(X[:, 3:], axis=1)
        )
        np.testing.assert_array_equal(
            forcelog.row_norms_numpy(X, 0, c), np.linalg.norm(X[:, :3] - c, axis=1)
        )
        np.testing.assert_array_equal(
            forcelog.row_norms_numpy(X, 0, c), kernel.row_norms(np.ascontiguousarray(X), 0, c)
        )


def test_running_integral_at_same_bits() -> None:
    t, W = _log(20_000, 2)
    full = forcelog._cumulative_integral(t, W)
    ks = np.unique(np.r_[0, 0, 1, np.random.default_rng(3).integers(0, len(t) - 1, 500), 19_998])
    np.testing.assert_array_equal(kernel.running_integral_at(t, W, ks), full[ks])


@pytest.mark.parametrize("overlap", [False, True])
def test_window_average_same_bits(monkeypatch: pytest.MonkeyPatch, overlap: bool) -> None:
    """Windows half-way between points (the alignment's) and overlapping, unsorted windows with
    zero-width ones: the compiled path equals the full running-sum path bit for bit."""
    t, W = _log(30_000, 4)
    rng = np.random.default_rng(5)
    if overlap:
        c = rng.uniform(t[0], t[-1], 2000)
        lo = np.clip(c - rng.uniform(0, 0.05, c.size), t[0], t[-1])
        hi = np.clip(c + rng.uniform(0, 0.05, c.size), t[0], t[-1])
        hi[::7] = lo[::7]  # zero width: interpolated value
    else:
        pt = np.sort(rng.uniform(t[0], t[-1], 3000))
        mid = 0.5 * (pt[1:] + pt[:-1])
        lo, hi = np.r_[pt[:1], mid], np.r_[mid, pt[-1:]]
    fast = forcelog.window_average(t, W, lo, hi)
    monkeypatch.setattr(forcelog, "_KERNEL", False)  # the numpy form
    np.testing.assert_array_equal(fast, forcelog.window_average(t, W, lo, hi))


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_chained_windows_share_their_ends(monkeypatch: pytest.MonkeyPatch, engine: str) -> None:
    """Windows that follow each other (each ends where the next begins), with zero-width ones
    among them, are integrated once per end: the same bits as each window on its own."""
    if engine == "numpy":
        monkeypatch.setattr(forcelog, "_KERNEL", False)
    t, W = _log(30_000, 8)
    pt = np.sort(np.random.default_rng(9).uniform(t[0], t[-1], 2500))
    pt[100:104] = pt[100]  # a pause: zero-width windows
    mid = 0.5 * (pt[1:] + pt[:-1])
    lo, hi = np.r_[pt[:1], mid], np.r_[mid, pt[-1:]]
    got = forcelog.window_average(t, W, lo, hi)
    one = np.vstack(
        [forcelog.window_average(t, W, lo[i : i + 1], hi[i : i + 1]) for i in range(len(lo))]
    )
    assert got.tobytes() == one.tobytes()


def test_unloaded_samples_and_condition_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    """The onset search (compiled distances) finds the same unloaded stretch, and a log with
    nothing to remove is returned as is (no copy)."""
    t, W = _log(40_000, 6)
    win = conditioning.unloaded_samples(t, W)
    assert win is not None and 5_000 < win.stop <= 8_000
    cond = conditioning.Conditioning("none", None)
    out, notes, info = conditioning.condition_wrench(t, W, cond)
    assert out is W and notes and info["bias"] is not None  # bias seen, warned, not removed
    tared, _, _ = conditioning.condition_wrench(t, W, conditioning.Conditioning("auto", None))
    assert tared is not W and np.all(W[0] != tared[0])
    monkeypatch.setattr(forcelog, "_KERNEL", False)
    assert conditioning.unloaded_samples(t, W) == win
    np.testing.assert_array_equal(
        conditioning.condition_wrench(t, W, conditioning.Conditioning("auto", None))[0], tared
    )


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_onset_same_numbers_as_the_distances(seed: int) -> None:
    """The compiled onset search (largest |F − level|, first row above the threshold it sets)
    gives the numpy form's span and row: a log read forwards and backwards, one never loaded
    (−1), one loaded from its first sample, a threshold set by the noise (5 σ) or the span."""
    _, W = _log(30_000, seed)
    level = np.array([1.0, -2.0, 3.0])
    flat = np.random.default_rng(seed).normal(scale=0.5, size=(5_000, 6))
    cases = [(W, level, 0.5), (W[::-1], level, 0.5), (flat, np.zeros(3), 0.5)]
    cases += [(W, np.zeros(3), 1e-12), (W[5_000:], level, 400.0)]
    for X, c, noise in cases:
        d = forcelog.row_norms_numpy(X, 0, c)
        above = d > max(5.0 * noise, 0.01 * float(d.max()))
        want = (float(d.max()), int(np.argmax(above)) if above.any() else -1)
        assert kernel.onset(X, c, noise) == want
    assert kernel.onset(flat, np.zeros(3), 0.5)[1] == -1


def test_row_norms_takes_the_numpy_form_on_a_cold_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    """One entry for both engines (the conditioning's distances, the log check's |F| and |M|):
    kernels not built yet → the numpy form, with the compiled pass's bits."""
    _, W = _log(20_000, 7)
    c = np.array([1.0, 2.0, -3.0])
    warm = forcelog.row_norms(W, 0, c)
    calls: list[int] = []
    numpy_form = forcelog.row_norms_numpy
    monkeypatch.setattr(forcelog, "_KERNEL", False)  # as log_kernel() decides on a cold cache
    monkeypatch.setattr(forcelog, "row_norms_numpy", lambda *a: calls.append(1) or numpy_form(*a))
    np.testing.assert_array_equal(conditioning._distances(W, c), warm)
    assert calls == [1]
