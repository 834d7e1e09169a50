"""The position alignment's C kernels (roboisf/sync/position_kernel.c) against their numba form,
bit for bit: the projection on a window of toolpath segments and the compiled tracking loop, on
the inputs position.py gives them (a C-order log, row slices of the toolpath's segments) and on
other layouts, degenerate segments and off-path samples."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from native_forms import c_library, numba_form
from roboisf.jit import background as jit_background
from roboisf.sync import position
from roboisf.sync import position_kernel as pk
from test_sync_kernel import _helix_log  # the same log: approach, pause, retract, restart

PK = "roboisf.sync.position_kernel"
ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not pk.HAVE_NUMBA, reason="numba not installed (the oracle)")


def _segments(tip: np.ndarray) -> tuple[np.ndarray, ...]:
    """The segment arrays as position._track makes them from a toolpath's tip."""
    D = np.diff(tip, axis=0)
    seglen = np.linalg.norm(D, axis=1)
    S = np.concatenate([[0.0], np.cumsum(seglen)])
    return tip[:-1], D, seglen**2, S[:-1], seglen


def _walk(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random-walk toolpath (200 points: a 50 mm lead-in and lead-out around a walk of 1 mm
    steps, one zero-length segment) and 500 samples near it, 20 before its start and 20 past
    its end (there the segment parameter is clipped at 0 and at 1)."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(scale=1e-3, size=(198, 3)), axis=0)
    tip = np.vstack([walk[0] - [0.05, 0, 0], walk, walk[-1] + [0, 0.05, 0]])
    tip[50] = tip[49]  # a zero-length segment
    P = tip[rng.integers(0, 200, 500)] + rng.normal(scale=5e-4, size=(500, 3))
    P[:20] = tip[0] - [0.01, 0, 0] * rng.uniform(1.0, 3.0, (20, 1))  # before the start
    P[20:40] = tip[-1] + [0, 0.01, 0] * rng.uniform(1.0, 3.0, (20, 1))  # past the end
    return tip, P


def _both_project(*args: Any) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, ...]]:
    got = pk.project_segments(*args)
    with numba_form(PK):
        assert pk._c() is None
        want = pk.project_segments(*args)
    return got, want


def _assert_same(got: tuple[np.ndarray, ...], want: tuple[np.ndarray, ...]) -> None:
    for g, w in zip(got, want, strict=True):
        assert g.dtype == w.dtype == np.float64
        assert np.array_equal(g, w, equal_nan=True)


# ---- project_segments ---------------------------------------------------------------------


def test_project_c_equals_numba_and_numpy() -> None:
    c_library(pk)
    tip, P = _walk(3)
    A, D, L2, S0, seglen = _segments(tip)
    got, want = _both_project(P, A, D, L2, S0, seglen)
    _assert_same(got, want)
    # the numpy path's operations are the same too (position._project_numpy)
    _assert_same(got, position._project_numpy(P, A, D, L2, S0, seglen))
    # the samples off the ends are nearest to the end points (u clipped to 0 and to 1)
    s, d = got
    assert np.all(s[:20] == S0[0]) and np.all(s[20:40] == S0[-1] + seglen[-1])
    assert np.all(d[:40] > 0.5e-3)


@pytest.mark.parametrize("layout", ["reversed P", "Fortran tip", "column slices", "strided"])
def test_project_c_equals_numba_on_other_layouts(layout: str) -> None:
    """Any layout numba accepts: a log read backwards, a Fortran-order toolpath
    (Toolpath.with_tip keeps its caller's array), columns of wider arrays, strided 1-D arrays."""
    c_library(pk)
    tip, P = _walk(5)
    A, D, L2, S0, seglen = _segments(tip)
    if layout == "reversed P":
        P = P[::-1]
    elif layout == "Fortran tip":
        A, D = _segments(np.asfortranarray(tip))[:2]
        P = np.asfortranarray(P)
        assert not A.flags.c_contiguous and not P.flags.c_contiguous
    elif layout == "column slices":
        wide = np.zeros((len(tip) - 1, 7))
        wide[:, 1:4], wide[:, 4:7] = A, D
        A, D = wide[:, 1:4], wide[:, 4:]
        Pw = np.zeros((len(P), 5))
        Pw[:, 2:] = P
        P = Pw[:, 2:]
    else:
        cols = np.zeros((len(S0), 3, 2))
        cols[:, 0, 1], cols[:, 1, 1], cols[:, 2, 1] = L2, S0, seglen
        L2, S0, seglen = cols[:, 0, 1], cols[:, 1, 1], cols[:, 2, 1]
        assert L2.strides == (48,)
    got, want = _both_project(P, A, D, L2, S0, seglen)
    _assert_same(got, want)
    c, n = _segments(tip), np.ascontiguousarray(P)
    _assert_same(got, pk.project_segments(n, *c))  # and the C-order answer


def test_project_windows_as_position_passes_them() -> None:
    """Row slices of the segments (the search window, the re-acquisition's 4 segments) and one
    sample (the re-acquisition's), one segment, no sample."""
    c_library(pk)
    tip, P = _walk(7)
    A, D, L2, S0, seglen = _segments(tip)
    for sl, rows in [(slice(30, 90), slice(0, 500)), (slice(47, 51), slice(3, 4))]:
        args = (P[rows], A[sl], D[sl], L2[sl], S0[sl], seglen[sl])
        _assert_same(*_both_project(*args))
    _assert_same(*_both_project(P, A[:1], D[:1], L2[:1], S0[:1], seglen[:1]))
    got, want = _both_project(P[:0], A, D, L2, S0, seglen)
    assert got[0].shape == got[1].shape == want[0].shape == (0,)


def test_project_degenerate_segments_and_nan() -> None:
    """Zero and NaN squared lengths (the kernel divides by 1 there), ties between two copies of
    a segment (the first wins), and a NaN sample (no segment nearer than inf: the window's
    first segment at u = 0, distance inf)."""
    c_library(pk)
    tip, P = _walk(11)
    A, D, L2, S0, seglen = (np.array(a) for a in _segments(tip))
    L2[::7] = 0.0  # a real segment with L2 = 0: u = r·D unscaled, so a different projection
    L2[3::11] = np.nan
    # a tie: segment 100 repeated at 150 with another arc length (the first must win)
    A[150], D[150], L2[150], seglen[150] = A[100], D[100], L2[100], seglen[100]
    S0[150] = S0[100] + 1.0
    P[40] = np.nan
    P[41, 1] = np.nan
    got, want = _both_project(P, A, D, L2, S0, seglen)
    _assert_same(got, want)
    s, d = got
    assert np.isinf(d[40]) and s[40] == S0[0] and np.isinf(d[41])
    assert not np.any(s >= S0[150]), "the tie must go to the first copy"
    near_100 = (s >= S0[100]) & (s <= S0[100] + seglen[100])
    assert near_100.any()
    # the L2 = 0 segments are not the numpy path's projection (which the kernel would give
    # with L2 = |D|²): the inputs do exercise that branch
    ref = position._project_numpy(P[42:], *_segments(tip))
    assert not np.array_equal(s[42:], ref[0])


# ---- track_blocks and the tracking loop ---------------------------------------------------


def _track_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count position._track's calls of the compiled loop (the C or numba form ran)."""
    calls: list[int] = []
    real = pk.track_blocks

    def counted(*args: Any) -> Any:
        calls.append(int(args[12]))
        return real(*args)

    monkeypatch.setattr(pk, "track_blocks", counted)
    return calls


@pytest.mark.parametrize("seed", [7, 11])
def test_track_c_equals_numba(monkeypatch: pytest.MonkeyPatch, seed: int) -> None:
    """position._track over the C loop and over the numba loop: the same bits, NaN where off
    the path; the loop stops for every re-acquisition (approach, retract, restart)."""
    c_library(pk)
    tip, S, P = _helix_log(seed)
    calls = _track_calls(monkeypatch)
    s_c = position._track(P, tip, S, position.OFF_PATH)
    n_c = len(calls)
    with numba_form(PK):
        s_n = position._track(P, tip, S, position.OFF_PATH)
    assert n_c >= 3 and len(calls) == 2 * n_c  # re-acquired in the Python loop, then resumed
    assert np.isnan(s_c[:50]).all() and np.isnan(s_c[6500:6800]).all()
    assert np.nanmax(s_c[6800:]) > S[2900] and np.isfinite(s_c).sum() > 7000
    assert np.array_equal(s_c, s_n, equal_nan=True)


def test_track_c_equals_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """And against the numpy path (no compiled kernel at all), to rounding: what
    tests/test_sync_kernel.py asks of the numba form (there its cold-cache switch no longer
    reaches the numpy path once the C form is built: :func:`roboisf.jit.ready` is then
    True)."""
    c_library(pk)
    tip, S, P = _helix_log(7)
    s_c = position._track(P, tip, S, position.OFF_PATH)
    monkeypatch.setattr(jit_background, "native_ready", lambda group: False)
    monkeypatch.setitem(jit_background._decided, "sync", False)
    calls = _track_calls(monkeypatch)
    s_np = position._track(P, tip, S, position.OFF_PATH)
    assert calls == []  # the numpy path ran
    assert np.array_equal(np.isnan(s_c), np.isnan(s_np))
    ok = np.isfinite(s_np)
    np.testing.assert_allclose(s_c[ok], s_np[ok], rtol=0, atol=1e-12)


def test_track_fortran_toolpath_c_equals_numba() -> None:
    """A Fortran-order toolpath tip (any layout reaches _track: Toolpath.with_tip): its
    segment starts are a strided view, the C form's general-stride path."""
    c_library(pk)
    tip, S, P = _helix_log(13)
    tipf = np.asfortranarray(tip)
    s_c = position._track(P, tipf, S, position.OFF_PATH)
    with numba_form(PK):
        s_n = position._track(P, tipf, S, position.OFF_PATH)
    assert np.array_equal(s_c, s_n, equal_nan=True)
    assert np.array_equal(s_c, position._track(P, tip, S, position.OFF_PATH), equal_nan=True)


def _direct(P: np.ndarray, tip: np.ndarray, /, **kw: Any) -> tuple[Any, ...]:
    """track_blocks called as position._track calls it (``kw`` overrides an argument)."""
    A, D, L2, S0, seglen = _segments(tip)
    a: dict[str, Any] = dict(
        P=P,
        travel=position._travel(P),
        A=A,
        D=D,
        L2=L2,
        S0=S0,
        seglen=seglen,
        tol=position.OFF_PATH,
        block=position.BLOCK,
        margin=position.MARGIN,
        max_block=position._MAX_BLOCK_SAMPLES,
        s=np.full(len(P), np.nan),
        k=60,
        s_prev=0.0,
        last_on=59,
    )
    a.update(kw)
    return tuple(a.values())


def _both_track(args: tuple[Any, ...]) -> tuple[tuple[int, float, int], np.ndarray]:
    """track_blocks' C and numba forms on the same arguments, each writing into its own s (a
    copy, or a new view from ``args[11]`` when that is a callable: a strided s stays strided):
    the same (k, s_prev, last_on) and the same progress written."""
    s_out = args[11]
    fresh = s_out if callable(s_out) else s_out.copy
    a_c = (*args[:11], fresh(), *args[12:])
    a_n = (*args[:11], fresh(), *args[12:])
    got = pk.track_blocks(*a_c)
    with numba_form(PK):
        want = pk.track_blocks(*a_n)
    assert got == want
    assert type(got[0]) is int and type(got[1]) is float and type(got[2]) is int
    assert np.array_equal(a_c[11], a_n[11], equal_nan=True)
    return got, a_c[11]


def test_track_blocks_direct_edges() -> None:
    """The kernel called directly: small blocks (a cap of 7 samples), the log's end reached,
    s_prev not yet finite and k at the end (returns at once), a NaN in the log (its travel is
    NaN from there: the block search runs to the end), strided s / travel / P."""
    c_library(pk)
    tip, S, P = _helix_log(17)
    s_prev = float(S[int(np.argmin(np.linalg.norm(tip - P[60], axis=1)))])
    # from sample 60 (on the path, after the approach) to the retract at 3000
    k, sp, lo = _both_track(_direct(P, tip, s_prev=s_prev))[0]
    assert 3000 <= k < 3100 and lo < 3000 and sp > s_prev
    # a block cap of 7 samples: a stop at the retract too
    assert 3000 <= _both_track(_direct(P, tip, s_prev=s_prev, max_block=7))[0][0] < 3100
    # from the restart to the end: k == M
    s_r = float(S[2100])
    (k2, _, lo2), s_w = _both_track(_direct(P, tip, k=6800, last_on=6799, s_prev=s_r))
    assert k2 == len(P) and lo2 == len(P) - 1 and np.isfinite(s_w[6800:]).all()
    # returns at once: not on the path yet, or nothing left
    args = _direct(P, tip, s_prev=-np.inf)
    assert _both_track(args)[0] == (60, -np.inf, 59)
    assert _both_track(_direct(P, tip, k=len(P)))[0] == (len(P), 0.0, 59)
    # a NaN sample: the travel is NaN from it on, so each later block's search key is NaN
    # (past every element: blocks of max_block samples, windows to the path's end) and the
    # retract, inside such a block, no longer stops the loop
    Pn = P.copy()
    Pn[1000, 0] = np.nan
    (kn, _, _), s_n = _both_track(_direct(Pn, tip, s_prev=s_prev))
    assert np.isnan(position._travel(Pn)[1000:]).all()
    assert kn == len(P) and np.isnan(s_n[1000]) and np.isfinite(s_n[1001:3000]).all()
    # strided output s, travel and log (views into wider arrays)
    tr = np.zeros((len(P), 3))
    tr[:, 1] = position._travel(P)
    Pw = np.zeros((len(P), 4))
    Pw[:, 1:] = P

    def s_strided() -> np.ndarray:
        s = np.full((len(P), 2), np.nan)[:, 1]
        assert s.strides == (16,)
        return s

    kw = dict(s=s_strided, travel=tr[:, 1], P=Pw[:, 1:], s_prev=s_prev)
    (ks, _, _), s_s = _both_track(_direct(P, tip, **kw))
    assert ks == k and np.isfinite(s_s[60:3000]).sum() > 2000


def test_track_blocks_tool_behind_the_window() -> None:
    """A log that goes back along the path by more than the window's margin + tol (10 mm
    segments of a straight path): the block is out of the window, the kernel stops for the
    caller's re-acquisition; a window one segment wider would hold it."""
    c_library(pk)
    tip = np.c_[np.arange(0.0, 0.1, 0.01), np.zeros(10), np.zeros(10)]
    P = np.zeros((50, 3))
    P[0, 0] = 0.0225  # the progress so far: 2.5 mm into segment 2
    P[1:, 0] = 0.0145  # 8 mm behind, on segment 1: 5.5 mm from the window's start (x = 20 mm)
    args = _direct(P, tip, k=1, s_prev=0.0225, last_on=0)
    (k, s_prev, last_on), s = _both_track(args)
    assert (k, s_prev, last_on) == (1, 0.0225, 0) and np.isnan(s).all()
    # with the tolerance at 6 mm the window's start point is within it: tracked, progress kept
    (k, s_prev, last_on), s = _both_track((*args[:7], 6e-3, *args[8:]))
    assert (k, s_prev, last_on) == (50, 0.0225, 49) and np.all(s[1:] == 0.0225)


def test_wrong_arrays_are_refused_before_c() -> None:
    """No wrong-typed or too short memory reaches C."""
    c_library(pk)
    tip, P = _walk(3)
    A, D, L2, S0, seglen = _segments(tip)
    with pytest.raises(TypeError):
        pk.project_segments(P.astype(np.float32), A, D, L2, S0, seglen)
    with pytest.raises(ValueError):
        pk.project_segments(P[:, :2], A, D, L2, S0, seglen)
    with pytest.raises(IndexError):
        pk.project_segments(P, A, D, L2, S0[:10], seglen)
    with pytest.raises(ValueError):
        pk.project_segments(P, A[:0], D[:0], L2[:0], S0[:0], seglen[:0])
    args = list(_direct(P, tip))
    args[11] = np.full(len(P), np.nan, dtype=np.float32)
    with pytest.raises(TypeError):
        pk.track_blocks(*args)
    args = list(_direct(P, tip))
    args[1] = args[1][:10]
    with pytest.raises(IndexError):
        pk.track_blocks(*args)
    with pytest.raises(ValueError):
        pk.track_blocks(*_direct(P, tip, max_block=0))


def test_alignment_without_numba() -> None:
    """With the C form built, the position alignment and the group's build run in a process
    that never imports numba, and jit.ready("sync") is True there."""
    c_library(pk)
    code = (
        "import sys\n"
        "from roboisf import jit\n"
        "from roboisf.sync import position_kernel as pk\n"
        "pk.build()\n"
        "assert jit.ready('sync')\n"
        "assert 'numba' not in sys.modules, 'numba imported'\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
