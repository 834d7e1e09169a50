"""The axisymmetric parts' closest-point kernel (roboisf.parts.axisym_kernel): its C form against
its numba form, bit for bit, on the parts of tests/test_parts.py and at the awkward places."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf.jit import HAVE_NUMBA
from roboisf.parts import VWACF, Cone, ProfilePart
from roboisf.parts import axisym_kernel as ak
from roboisf.parts.axisymmetric import REGION_CODES

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed (the oracle)")

AK = "roboisf.parts.axisym_kernel"

#: the parts of tests/test_parts.py: segments only (the cone, the profile) and an arc (VWACF)
PARTS = {
    "cone": Cone(),
    "vwacf": VWACF(),
    "profile": ProfilePart(r=(0.04, 0.03, 0.02, 0.015), z=(0.0, -0.01, -0.03, -0.05)),
}


def _points(part, n: int, seed: int) -> np.ndarray:
    """A scan-like cloud around the part (the surface ± a few mm, and a box around it), plus the
    axis (r = 0), the primitives' joints (ties between primitives), the arcs' centres (the arc
    query's special point), a point far away and a NaN point."""
    rng = np.random.default_rng(seed)
    g = part.generatrix
    surf = part.surface_grid(40, 24)[0]
    near = surf[rng.integers(0, surf.shape[0], n)] + rng.normal(scale=2e-3, size=(n, 3))
    box = np.c_[rng.uniform(-0.08, 0.08, (n, 2)), rng.uniform(-0.15, 0.05, n)]
    joints = []
    for p in g.primitives:
        r, z, _ = p.at(np.array([0.0, p.length]))
        joints += [(r[0], 0.0, z[0]), (r[1], 0.0, z[1]), (0.0, r[1], z[1])]
    arcs = [(p.rc, 0.0, p.zc) for p in g.primitives if hasattr(p, "rc")]
    # straight above and below an arc's centre (r = rc: the arc's angle of a zero ur)
    arcs += [
        (p.rc, 0.0, p.zc + dz) for p in g.primitives if hasattr(p, "rc") for dz in (-0.01, 0.01)
    ]
    axis = np.c_[np.zeros((30, 2)), np.linspace(-0.2, 0.1, 30)]
    odd = [[5.0, -3.0, 2.0], [-1e3, 1e3, -1e3], [np.nan, 0.01, -0.01]]
    return np.concatenate([near, box, np.array(joints + arcs).reshape(-1, 3), axis, odd])


def _same(got, want) -> None:
    assert len(got) == len(want) == 6
    # bit for bit: the sign of a zero (a foot on the axis, a point on the surface) and the NaN
    # point's distance included
    same_bits(got, want)


@pytest.mark.parametrize("name", list(PARTS))
@pytest.mark.parametrize("layout", ["C", "column slice", "reversed"])
def test_closest_c_equals_numba(name: str, layout: str) -> None:
    c_library(ak)
    part = PARTS[name]
    packed = ak.pack(part.generatrix, REGION_CODES)
    X = _points(part, 4000, seed=len(name))
    # the layouts closest_point passes on: whatever the caller's array is (np.asarray)
    W = np.hstack([X[:, :1], X])
    Y = {"C": X, "column slice": W[:, 1:], "reversed": X[::-1]}[layout]
    got = ak.closest(Y, packed)
    with numba_form(AK):
        want = ak.closest(Y, packed)
    _same(got, want)
    # the inputs reach every primitive (each wins somewhere) and the arcs' special point
    assert set(np.unique(got[5]).tolist()) == set(packed[3].tolist())
    # the NaN point (the last row of X): no primitive wins, the defaults, a NaN distance
    k = 0 if layout == "reversed" else -1
    assert np.isnan(got[2][k]) and np.array_equal(got[0][k], [0.0, 0.0, 0.0])
    if name == "vwacf":
        arc = packed[0] == ak.ARC
        # some feet on the arc's clamped ends and some inside it
        b0, b1 = packed[1][arc, 3][0], packed[1][arc, 4][0]
        on_arc = (got[3] > b0) & (got[3] < b1)
        assert on_arc.any() and (got[3] == b1).any()


def test_closest_edge_cases() -> None:
    c_library(ak)
    packed = ak.pack(Cone().generatrix, REGION_CODES)
    for X in (np.empty((0, 3)), np.array([[0.0, 0.0, -0.02]]), np.array([[0.01, -0.02, 0.0]])):
        got = ak.closest(X, packed)
        with numba_form(AK):
            want = ak.closest(X, packed)
        _same(got, want)
    # a segment of zero length divides by zero: numba raises (Python's error model), so does C
    kind, par, s0, code, order = packed
    bad = par.copy()
    bad[order[0], 2:4] = bad[order[0], 0:2]
    for form in ("c", "numba"):
        with numba_form(AK) if form == "numba" else contextlib.nullcontext():
            with pytest.raises(ZeroDivisionError):
                ak.closest(np.array([[0.02, 0.0, -0.01]]), (kind, bad, s0, code, order))
    with pytest.raises(IndexError):
        ak.closest(np.zeros((1, 3)), (kind, par, s0, code, order + 10))


def test_closest_point_runs_the_c_form() -> None:
    """Part.closest_point with the C form built goes through it (numba's kernel is not called)."""
    c_library(ak)
    X = _points(Cone(), 200, seed=5)[:-1]
    calls = []
    saved = ak._closest
    try:
        ak._closest = lambda *a: calls.append(1)  # type: ignore[assignment]
        q = Cone().closest_point(X, backend="numba")
    finally:
        ak._closest = saved
    assert not calls
    with numba_form(AK):
        r = Cone().closest_point(X, backend="numba")
    np.testing.assert_array_equal(q.point, r.point)
    np.testing.assert_array_equal(q.distance, r.distance)
