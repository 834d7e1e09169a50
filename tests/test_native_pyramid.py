"""The pyramid's closest-point kernel (roboisf.parts.pyramid_kernel): its C form against its
numba form bit for bit, both against the numpy query (tests/test_registration_speed_equiv.py
checks that one against the plain patch-by-patch form) to 1e-12 m field by field — the patch
chosen included, at the edges two patches share — and the tie rule both follow."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf.jit import HAVE_NUMBA
from roboisf.parts import Pyramid
from roboisf.parts import pyramid_kernel as pk
from roboisf.parts.axisymmetric import REGION_CODES, SurfaceQuery

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed (the oracle)")

PK = "roboisf.parts.pyramid_kernel"

PARTS = {
    # rounded corners whose cones reach their apex above the bottom (sharp edges below)
    "rounded": Pyramid(150e-3, 150e-3, math.radians(60.0), 50e-3, corner_radius=10e-3),
    # rounded all the way down (the bottom keeps a radius), rectangular, shallow
    "rect_rounded_shallow": Pyramid(160e-3, 110e-3, math.radians(45.0), 12e-3, corner_radius=30e-3),
    # sharp corners, two wall angles
    "sharp_two_angles": Pyramid(
        140e-3, 100e-3, math.radians(65.0), 40e-3, wall_angle_y=math.radians(50.0), corner_radius=0
    ),
    # no flange; corners of half the side: the walls are lines (two-vertex polygons)
    "round_opening_no_flange": Pyramid(
        100e-3, 100e-3, math.radians(60.0), 20e-3, corner_radius=50e-3, flange_width=0.0
    ),
}


def _points(part: Pyramid, n: int, seed: int) -> np.ndarray:
    """A scan-like cloud (feet of random points, 1 mm along their normals), a box 1 cm beyond
    the part, the points above the rim whose foot is the rim's edge (a tie of the wall and the
    flange), the corner cones' axes (their meridian direction undefined), the z axis, the
    bottom's corners and points at overflowing coordinates."""
    rng = np.random.default_rng(seed)
    lo, hi = part.bounds
    box = lo - 0.01 + rng.random((n, 3)) * (hi - lo + 0.02)
    q = part.closest_point(box, backend="numpy")
    near = q.point + rng.normal(0.0, 1e-3, n)[:, None] * q.normal
    ox, oy, rc = part.top_length / 2, part.top_width / 2, part.corner_radius
    b = np.linspace(0.5e-3, 5e-3, 10)
    rim = np.r_[
        np.c_[ox - 0.2 * b, np.zeros(10), b],
        np.c_[-(ox - 0.2 * b), 0.3 * (oy - rc) * np.ones(10), b],
        np.c_[0.5 * (ox - rc) * np.ones(10), oy - 0.2 * b, b],
    ]
    cx, cy = ox - rc, oy - rc
    axes = [[sx * cx, sy * cy, z] for sx in (1, -1) for sy in (1, -1) for z in (-0.002, 0.01)]
    bx, by, _ = part.section(part.depth)
    odd = [[0.0, 0.0, z] for z in (-0.1, -part.depth, 0.0, 0.05)]
    odd += [[bx, by, -part.depth], [-bx, by, -part.depth + 1e-4], [ox, oy, 0.0]]
    big = [[1e200, 0.0, 0.0], [1e160, 1e160, -1e170], [0.01, 0.0, 1e300]]
    return np.concatenate([near, box, rim, np.array(axes + odd + big)])


def _fields(q: SurfaceQuery) -> tuple[np.ndarray, ...]:
    return tuple(getattr(q, f.name) for f in fields(SurfaceQuery))


@pytest.mark.parametrize("name", list(PARTS))
@pytest.mark.parametrize("layout", ["C", "column slice", "reversed"])
def test_closest_c_equals_numba(name: str, layout: str) -> None:
    c_library(pk)
    part = PARTS[name]
    X = _points(part, 3000, seed=len(name))
    W = np.hstack([X[:, :1], X])
    Y = {"C": X, "column slice": W[:, 1:], "reversed": X[::-1]}[layout]
    with np.errstate(over="ignore", invalid="ignore"):
        got = part.closest_point(Y)
        with numba_form(PK):
            want = part.closest_point(Y, backend="numba")
    same_bits(_fields(got), _fields(want))
    # every region is reached (the flange where there is one), the walls and corners both;
    # no patch is at a finite distance from the points at overflowing coordinates (zeros)
    ok = np.isfinite(got.distance)
    assert (~ok).any() and not got.point[~ok].any()
    regions = set(np.unique(got.region[ok]).tolist())
    assert regions >= {REGION_CODES["wall"], REGION_CODES["bottom"]}
    assert (REGION_CODES["flange"] in regions) == (part.flange_width > 0)
    corner = ok & (got.region == REGION_CODES["wall"])
    corner &= np.abs(got.normal[:, :2]).min(axis=1) > 1e-3
    assert corner.any() == (part.corner_radius > 0)


@pytest.mark.parametrize("name", list(PARTS))
def test_compiled_is_the_numpy_query_to_rounding(name: str) -> None:
    part = PARTS[name]
    X = _points(part, 3000, seed=3)
    with np.errstate(over="ignore", invalid="ignore"):
        got = part.closest_point(X)
        want = part.closest_point(X, backend="numpy")
    for f, a, b in zip(fields(SurfaceQuery), _fields(got), _fields(want), strict=True):
        assert a.dtype == b.dtype, f.name
        if f.name == "region":
            assert np.array_equal(a, b)  # the same patch everywhere, at the shared edges too
        else:
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, err_msg=f.name)


def test_a_tie_goes_to_the_patch_listed_first(monkeypatch) -> None:
    """Points whose foot is an edge two patches share are at the same distance from both up to
    rounding: above the rim (the wall's top edge is the flange's inner one) and behind a sharp
    corner's edge (two walls). The patch listed first is taken — the wall, the x-wall — in
    both forms. With no margin (TIE = 0: the strict comparison of before) the rounding chose,
    and not always the first."""
    from roboisf.parts import pyramid

    wall = REGION_CODES["wall"]
    t = np.linspace(0.3e-3, 6e-3, 150)
    strict_differs = []
    for name, depths in (("rounded", (25e-3, 45e-3)), ("sharp_two_angles", (5e-3, 35e-3))):
        part = PARTS[name]
        ox, oy, rc = part.top_length / 2, part.top_width / 2, part.corner_radius
        y = np.linspace(-(oy - rc), oy - rc, t.size) * 0.9
        rim = np.r_[
            np.c_[ox - 0.2 * t, y, t], np.c_[-0.9 * (ox - rc) * np.sign(y), -oy + 0.2 * t, t]
        ]
        # behind the +x/+y corner's edge, equidistant from both walls' planes
        h = np.linspace(*depths, t.size)
        sx, sy, _ = np.array([part.section(v) for v in h]).T
        E = np.c_[sx, sy, -h]
        n1 = np.array([-math.sin(part.alpha_x), 0.0, math.cos(part.alpha_x)])
        n2 = np.array([0.0, -math.sin(part.alpha_y), math.cos(part.alpha_y)])
        u = (n1 + n2) / np.linalg.norm(n1 + n2)
        edge = E - t[:, None] * u
        X = np.r_[rim, edge]
        for backend in ("numpy", "auto"):
            q = part.closest_point(X, backend=backend)
            assert np.all(q.region == wall), (name, backend)
            n = t.size * 2
            np.testing.assert_allclose(q.distance[:n], np.tile(np.hypot(0.2 * t, t), 2), rtol=1e-9)
            np.testing.assert_allclose(q.point[n:], E, rtol=0, atol=1e-12)
            np.testing.assert_allclose(q.normal[n:], np.tile(n1, (t.size, 1)), rtol=0, atol=1e-15)
        with monkeypatch.context() as m:
            m.setattr(pyramid, "TIE", 0.0)
            strict = part.closest_point(X, backend="numpy")
        strict_differs.append(
            (strict.region != wall).any() or (strict.normal[2 * t.size :] != n1).any()
        )
    assert all(strict_differs), strict_differs  # what the margin is for


def test_closest_point_runs_the_c_form() -> None:
    """Pyramid.closest_point with the C form built goes through it (numba's kernel is not
    called); an empty query and a bad packing are handled."""
    c_library(pk)
    part = PARTS["rounded"]
    X = _points(part, 200, seed=5)[:-3]
    calls = []
    saved = pk._closest
    try:
        pk._closest = lambda *a: calls.append(1)  # type: ignore[assignment]
        q = part.closest_point(X, backend="numba")
    finally:
        pk._closest = saved
    assert not calls
    with numba_form(PK):
        r = part.closest_point(X, backend="numba")
    same_bits(_fields(q), _fields(r))
    empty = part.closest_point(np.empty((0, 3)))
    assert empty.point.shape == (0, 3) and empty.region.shape == (0,)
    prm, walls, uv, nv, codes = part._packed
    with pytest.raises(ValueError, match="packed"):
        pk.closest(X, (prm[:-1], walls, uv, nv, codes))
    with pytest.raises(ValueError, match="2 to"):
        pk.closest(X, (prm, walls, uv, nv * 0 + 1, codes))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        pk.closest(X[:, :2], part._packed)
