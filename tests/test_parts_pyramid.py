"""Pyramid: exact closest points against an independent dense sampling of its height field,
normals, signed distance, symmetry, errors and the TOML round trip."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from roboisf.errors import InputError
from roboisf.parts import Part, load_part, part_from_dict, save_part
from roboisf.parts.pyramid import Pyramid

rng = np.random.default_rng(12)

PYRAMIDS = {
    # rounded corners, the cones reach their apex above the bottom (sharp edges below)
    "square_r10": Pyramid(150e-3, 150e-3, math.radians(60.0), 50e-3, corner_radius=10e-3),
    # rounded all the way down: the bottom keeps a corner radius
    "rect_r30_shallow": Pyramid(160e-3, 110e-3, math.radians(45.0), 12e-3, corner_radius=30e-3),
    # sharp corners, two wall angles
    "rect_two_angles": Pyramid(
        140e-3, 100e-3, math.radians(65.0), 40e-3, wall_angle_y=math.radians(50.0), corner_radius=0
    ),
}


def height_field(p: Pyramid, xy):
    """Independent definition of the surface as a graph z = f(x, y) (flange included, NaN
    outside it): inside the opening the section at depth h is the opening shrunk by h / tan α."""
    x, y = np.abs(xy[:, 0]), np.abs(xy[:, 1])
    a, b, r = p.top_length / 2, p.top_width / 2, p.corner_radius
    qx, qy = x - (a - r), y - (b - r)
    sd = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0) - r
    if r > 0:
        z = np.maximum(-p.depth, math.tan(p.alpha_x) * sd)
    else:
        z = np.maximum(
            -p.depth,
            np.maximum(math.tan(p.alpha_x) * (x - a), math.tan(p.alpha_y) * (y - b)),
        )
    # flange: up to flange_width outside the opening (rounded by r + fw at the corners)
    fw = p.flange_width
    qx2, qy2 = x - (a - r), y - (b - r)
    sdo = np.hypot(np.maximum(qx2, 0), np.maximum(qy2, 0)) + np.minimum(np.maximum(qx2, qy2), 0)
    sdo -= r + fw
    z = np.where(sd >= 0, 0.0, z)
    return np.where(sdo <= 1e-12, z, np.nan)


def dense_samples(p: Pyramid, h=0.25e-3):
    lo, hi = p.bounds
    gx = np.arange(lo[0], hi[0] + h / 2, h)
    gy = np.arange(lo[1], hi[1] + h / 2, h)
    XY = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    z = height_field(p, XY)
    ok = np.isfinite(z)
    S = np.c_[XY[ok], z[ok]]
    # covering radius: every surface point is within h/√2 (in xy) of a grid node, and the
    # surface rises at most tan α over that
    steep = max(p.alpha_x, p.alpha_y)
    cover = h / math.sqrt(2) / math.cos(steep)
    return S, cover


@pytest.mark.parametrize("name", list(PYRAMIDS))
def test_closest_point_matches_dense_height_field(name):
    p = PYRAMIDS[name]
    S, cover = dense_samples(p)
    lo, hi = p.bounds
    X = rng.uniform(lo - np.array([0.01, 0.01, 0.02]), hi + np.array([0.01, 0.01, 0.03]), (3000, 3))
    # and points close to the surface (within 3 mm), where patch boundaries matter most
    near = S[rng.integers(0, len(S), 3000)] + rng.normal(0.0, 1.5e-3, (3000, 3))
    X = np.r_[X, near]
    q = p.closest_point(X)
    d_ref, _ = cKDTree(S).query(X)
    d = np.abs(q.distance)
    # the dense sample lies on the surface: the exact distance can only be smaller ...
    assert np.all(d <= d_ref + 1e-12)
    # ... and not by more than the sample's covering radius allows
    assert np.all(d_ref - d <= cover)
    # the returned point is on the surface (the independent height field) at that distance
    z_ref = height_field(p, q.point[:, :2])
    np.testing.assert_allclose(q.point[:, 2], z_ref, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(X - q.point, axis=1), d, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q.normal, axis=1), 1.0, atol=1e-14)


@pytest.mark.parametrize("name", list(PYRAMIDS))
def test_normals_and_signed_distance_off_the_surface(name):
    """Points P + t·n off interior surface points: distance t (signed), normal n, where n is
    the height field's own upward normal (−∇f, 1)/|·| by central differences."""
    p = PYRAMIDS[name]
    lo, hi = p.bounds
    xy = rng.uniform(lo[:2], hi[:2], (4000, 2))
    z = height_field(p, xy)
    ok = np.isfinite(z)
    xy, z = xy[ok], z[ok]
    e = 1e-7
    ex, ey = np.array([e, 0.0]), np.array([0.0, e])
    fx = (height_field(p, xy + ex) - height_field(p, xy - ex)) / (2 * e)
    fy = (height_field(p, xy + ey) - height_field(p, xy - ey)) / (2 * e)
    # keep points away from creases (both one-sided slopes agree)
    fx1 = (height_field(p, xy + ex) - z) / e
    fy1 = (height_field(p, xy + ey) - z) / e
    smooth = (np.abs(fx - fx1) < 1e-6) & (np.abs(fy - fy1) < 1e-6) & np.isfinite(fx + fy)
    xy, z, fx, fy = xy[smooth], z[smooth], fx[smooth], fy[smooth]
    n = np.c_[-fx, -fy, np.ones_like(fx)]
    n /= np.linalg.norm(n, axis=1)[:, None]
    P = np.c_[xy, z]
    q0 = p.closest_point(P)
    np.testing.assert_allclose(q0.distance, 0.0, atol=1e-12)
    np.testing.assert_allclose(q0.normal, n, atol=1e-6)
    np.testing.assert_allclose(q0.wall_angle, np.arccos(n[:, 2]), atol=1e-6)
    t = rng.uniform(-0.2e-3, 0.2e-3, len(P))
    q = p.closest_point(P + t[:, None] * n)
    # small offsets stay within the patch (a few may fall onto a neighbour near a crease)
    good = np.abs(q.distance - t) < 1e-12
    assert good.mean() > 0.97
    assert np.all(np.sign(q.distance[np.abs(t) > 1e-9]) == np.sign(t[np.abs(t) > 1e-9]))


def test_square_pyramid_symmetry_bounds_regions():
    p = PYRAMIDS["square_r10"]
    assert isinstance(p, Part)
    assert p.symmetry.order == 4
    assert PYRAMIDS["rect_r30_shallow"].symmetry.order == 2
    assert PYRAMIDS["rect_two_angles"].symmetry.order == 2
    assert (
        Pyramid(100e-3, 100e-3, 1.0, 20e-3, wall_angle_y=0.9, corner_radius=0).symmetry.order == 2
    )
    lo, hi = p.bounds
    np.testing.assert_allclose(lo, [-0.085, -0.085, -0.05])
    np.testing.assert_allclose(hi, [0.085, 0.085, 0.0])
    # a 90° turn maps the surface onto itself
    X = rng.uniform(lo, hi + np.array([0, 0, 0.02]), (500, 3))
    Xr = np.c_[-X[:, 1], X[:, 0], X[:, 2]]
    np.testing.assert_allclose(p.signed_distance(Xr), p.signed_distance(X), atol=1e-15)
    q = p.closest_point(np.array([[0.0, 0.0, 0.01], [0.0, 0.0, -0.06], [0.08, 0.0, 0.01]]))
    assert list(q.region) == [2, 2, 0]
    np.testing.assert_allclose(q.distance, [0.06, -0.01, 0.01])
    # a point on the corner cone's diagonal: wall angle 60°, depth below the rim
    c = p.top_length / 2 - p.corner_radius + p.corner_radius / math.sqrt(2) * 0.5
    h = p.corner_radius / 2 * math.tan(p.wall_angle)
    q = p.closest_point(np.array([[c, c, -h]]))
    assert q.region[0] == 1 and q.wall_angle[0] == pytest.approx(p.wall_angle)
    assert q.distance[0] == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"depth": 0.2}, "depth"),
        ({"wall_angle": math.radians(90)}, "wall_angle"),
        ({"corner_radius": 0.1}, "corner_radius"),
        ({"wall_angle_y": 0.9}, "corner_radius"),  # rounded corners need one angle
        ({"top_width": -1.0}, "top_width"),
        ({"flange_width": -1e-3}, "flange_width"),
    ],
)
def test_bad_dimensions(kwargs, field):
    with pytest.raises(InputError) as e:
        Pyramid(**kwargs)
    assert e.value.field == field


def test_pyramid_toml_round_trip(tmp_path):
    for p in PYRAMIDS.values():
        f = tmp_path / "p.toml"
        save_part(p, f)
        q = load_part(f)
        assert q == p
    bad = {"kind": "pyramid", "top_length": 100, "top_width": 100, "wall_angle": 60}
    with pytest.raises(InputError, match="depth"):
        part_from_dict(bad)
    with pytest.raises(InputError, match="corner_radius"):
        part_from_dict({**bad, "depth": 20, "corner_radius": 80})


@pytest.mark.parametrize("name", list(PYRAMIDS))
def test_inside_outside_matches_the_height_field(name):
    """Signed distance < 0 exactly where a point is in the material: below the height field
    (over the part's footprint), independently of the patch decomposition."""
    p = PYRAMIDS[name]
    lo, hi = p.bounds
    X = rng.uniform(lo - np.array([0, 0, 0.01]), hi + np.array([0, 0, 0.01]), (20000, 3))
    z = height_field(p, X[:, :2])
    X = X[np.isfinite(z) & (np.abs(X[:, 2] - z) > 1e-9)]
    z = height_field(p, X[:, :2])
    d = p.signed_distance(X)
    np.testing.assert_array_equal(d < 0, X[:, 2] < z)


def test_square_pyramid_with_half_side_corner_radius_is_the_cone():
    """Corner radius = half the side: four quarter cones make a full cone, and the walls have
    zero width; the exact distances must be the Cone part's (an independent generatrix code)."""
    from roboisf.parts import Cone

    a, d = math.radians(60.0), 30e-3
    p = Pyramid(100e-3, 100e-3, a, d, corner_radius=50e-3)
    c = Cone(100e-3, a, d)
    X = rng.uniform([-0.07, -0.07, -0.05], [0.07, 0.07, 0.02], (20000, 3))
    qp, qc = p.closest_point(X), c.closest_point(X)
    np.testing.assert_allclose(qp.distance, qc.distance, atol=1e-12)
    np.testing.assert_allclose(qp.point, qc.point, atol=1e-9)
