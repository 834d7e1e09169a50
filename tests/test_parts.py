"""Parts: exact closest points (vs brute force), normals, sine law, TOML round trip, errors."""

import math

import numpy as np
import pytest

from roboisf import jit
from roboisf.errors import InputError
from roboisf.parts import (
    VWACF,
    Cone,
    ProfilePart,
    load_part,
    part_from_dict,
    save_part,
    sine_law_thickness,
)

rng = np.random.default_rng(3)


def dense_generatrix(part, n=200_001):
    """Brute-force reference: the generatrix sampled densely, primitive by primitive."""
    pts = []
    for p in part.generatrix.primitives:
        s = np.linspace(0.0, p.length, n // len(part.generatrix.primitives))
        r, z, _ = p.at(s)
        pts.append(np.c_[r, z])
    return np.concatenate(pts)


PARTS = [Cone(), VWACF(), ProfilePart(r=(0.04, 0.03, 0.02, 0.015), z=(0.0, -0.01, -0.03, -0.05))]


@pytest.mark.parametrize("part", PARTS, ids=["cone", "vwacf", "profile"])
def test_closest_point_matches_brute_force(part):
    """The numpy query against a dense sample (the compiled one against the numpy one:
    test_compiled_closest_point_is_the_numpy_query)."""
    X = np.c_[rng.uniform(-0.06, 0.06, (400, 2)), rng.uniform(-0.12, 0.01, 400)]
    q = part.closest_point(X, backend="numpy")
    ref = dense_generatrix(part)
    r = np.hypot(X[:, 0], X[:, 1])
    # 16 queries at a time: the minima of one 400 × 200 k array, without its 0.6 GB temporaries
    d_ref = np.concatenate(
        [
            np.min(
                np.hypot(
                    r[i : i + 16, None] - ref[None, :, 0], X[i : i + 16, 2:3] - ref[None, :, 1]
                ),
                axis=1,
            )
            for i in range(0, len(X), 16)
        ]
    )
    # the dense sample is an upper bound, within half its spacing (≤ ~1 µm here) of the exact
    assert np.all(np.abs(q.distance) <= d_ref + 1e-12)
    np.testing.assert_allclose(np.abs(q.distance), d_ref, atol=2e-6)
    # the returned point is on the surface and in the query's meridian plane
    np.testing.assert_allclose(np.linalg.norm(q.point - X, axis=1), np.abs(q.distance), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q.normal, axis=1), 1.0, atol=1e-14)


@pytest.mark.skipif(not jit.HAVE_NUMBA, reason="numba not installed")
@pytest.mark.parametrize("part", PARTS, ids=["cone", "vwacf", "profile"])
def test_compiled_closest_point_is_the_numpy_query(part):
    """roboisf.parts.axisym_kernel against the numpy query, field by field, at the awkward
    places too: on the axis (r = 0), exactly at the primitives' joints (corner ties go to the
    wall), at an arc's centre, on the surface, and far away."""
    g = part.generatrix
    joints = []
    for p in g.primitives:
        r, z, _ = p.at(np.array([0.0, p.length]))
        joints += [(r[0], 0.0, z[0]), (r[1], 0.0, z[1]), (0.0, r[1], z[1])]
    arcs = [(p.rc, 0.0, p.zc) for p in g.primitives if hasattr(p, "rc")]
    on_surface = part.surface_grid(20, 12)[0]
    X = np.concatenate(
        [
            np.c_[rng.uniform(-0.08, 0.08, (5000, 2)), rng.uniform(-0.15, 0.05, 5000)],
            np.c_[np.zeros((50, 2)), np.linspace(-0.2, 0.1, 50)],  # the axis
            np.asarray(joints + arcs, dtype=float).reshape(-1, 3),
            on_surface,
            [[5.0, -3.0, 2.0], [-1e3, 1e3, -1e3]],
        ]
    )
    a = part.closest_point(X, backend="numba")
    b = part.closest_point(X, backend="numpy")
    np.testing.assert_array_equal(a.region, b.region)
    for f in ("point", "normal", "distance", "wall_angle", "depth", "s"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-12, atol=1e-12, err_msg=f)


def test_closest_point_backend_is_checked():
    with pytest.raises(InputError, match="backend") as e:
        Cone().closest_point(np.zeros((1, 3)), backend="fast")
    assert e.value.field == "backend"


def interior_grid(part, n_s, n_phi):
    """Wall grid without its first and last rows: at the wall's edges the closest point is
    legitimately a corner shared with the flange or the bottom."""
    pts, nrm = part.surface_grid(n_s, n_phi)
    return pts[n_phi:-n_phi], nrm[n_phi:-n_phi]


def test_cone_surface_points_have_zero_distance_and_the_right_normal():
    cone = Cone()
    pts, nrm = interior_grid(cone, 50, 36)
    q = cone.closest_point(pts)
    np.testing.assert_allclose(q.distance, 0.0, atol=1e-15)
    np.testing.assert_allclose(q.normal, nrm, atol=1e-12)
    a = math.radians(71)
    # tool-side normal: inward (−r) and up, at 71° from the axis… i.e. n = (−sin α, cos α)
    phi = np.arctan2(pts[0, 1], pts[0, 0])
    expected = [-math.sin(a) * math.cos(phi), -math.sin(a) * math.sin(phi), math.cos(a)]
    np.testing.assert_allclose(q.normal[0], expected, atol=1e-12)
    assert np.all(q.region == 1)
    np.testing.assert_allclose(q.wall_angle, a, atol=1e-14)


def test_signed_distance_is_positive_on_the_tool_side():
    cone = Cone()
    pts, nrm = interior_grid(cone, 20, 12)
    for h in (1e-4, 2e-3):
        np.testing.assert_allclose(cone.signed_distance(pts + h * nrm), h, atol=1e-12)
        np.testing.assert_allclose(cone.signed_distance(pts - h * nrm), -h, atol=1e-12)


def test_vwacf_geometry():
    v = VWACF()  # Ø88.15, R 39 mm, 0 → 90°
    assert math.isclose(v.depth, 0.039, rel_tol=1e-12)
    r, a = v.wall_at_z(np.array([-0.039, -0.0195]))
    assert math.isclose(r[0], 0.044075 - 0.039, rel_tol=1e-12)
    assert math.isclose(a[0], math.pi / 2, rel_tol=1e-12)
    assert math.isclose(a[1], math.acos(0.5), rel_tol=1e-12)  # z = −ρ(1 − cos β)
    # a Ø10 ball still fits at the bottom: ball-centre radius R0 − ρ − R ≥ 0
    assert 0.044075 - 0.039 - 0.005 >= 0
    assert math.isclose(v.opening_radius, 0.044075)


def test_regions_flange_wall_bottom():
    cone = Cone()
    q = cone.closest_point([[0.050, 0, 0.001], [0.02, 0, -0.05], [0.001, 0, -0.2]])
    assert q.region.tolist() == [0, 1, 2]
    np.testing.assert_allclose(q.depth[2], 0.10297)


def test_sine_law():
    np.testing.assert_allclose(sine_law_thickness(math.radians(71), 1.22e-3), 0.397e-3, atol=1e-6)
    assert Cone().thickness(0.0) == pytest.approx(1.22e-3)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"opening_diameter": -1.0}, "opening_diameter"),
        ({"depth": 0.0}, "depth"),
        ({"wall_angle": math.radians(90)}, "wall_angle"),
        ({"wall_angle": math.radians(95)}, "wall_angle"),
        ({"depth": 0.2}, "depth"),  # reaches the axis
        ({"sheet_thickness": 0.0}, "sheet_thickness"),
    ],
)
def test_cone_bad_dimensions(kwargs, field):
    with pytest.raises(InputError) as e:
        Cone(**kwargs)
    assert e.value.field == field


def test_vwacf_arc_crossing_the_axis():
    with pytest.raises(InputError, match="crosses the axis"):
        VWACF(arc_radius=0.05)


@pytest.mark.parametrize(
    "r, z, msg",
    [
        ((0.04, 0.03, 0.02), (0.0, -0.01, -0.005), "goes up"),
        ((0.04, 0.01, -0.01), (0.0, -0.01, -0.02), "crosses the axis"),
        ((0.04, 0.045), (0.0, -0.01), "turns outwards"),
        ((0.04,), (0.0,), "at least two"),
        ((0.04, 0.03), (0.0, np.nan), "NaN"),
    ],
)
def test_profile_bad_generatrix(r, z, msg):
    with pytest.raises(InputError, match=msg):
        ProfilePart(r=r, z=z)


def test_part_toml_round_trip(tmp_path):
    for part in (Cone(), VWACF(arc_radius=0.035), Cone(wall_angle=math.radians(60), depth=0.05)):
        save_part(part, tmp_path / "p.toml")
        back = load_part(tmp_path / "p.toml")
        assert type(back) is type(part)
        pts = rng.uniform(-0.05, 0.05, (50, 3))
        np.testing.assert_allclose(back.signed_distance(pts), part.signed_distance(pts), atol=1e-15)


def test_profile_from_csv_relative_to_toml(tmp_path):
    (tmp_path / "gen.csv").write_text("r,z\n40,0\n30,-10\n20,-30\n")
    (tmp_path / "p.toml").write_text('[part]\nkind = "profile"\nfile = "gen.csv"\n')
    part = load_part(tmp_path / "p.toml")
    assert part.depth == pytest.approx(0.030)
    save_part(part, tmp_path / "q.toml")
    assert 'file = "gen.csv"' in (tmp_path / "q.toml").read_text()


def test_profile_csv_errors_name_the_line(tmp_path):
    (tmp_path / "gen.csv").write_text("r,z\n40,0\n30,abc\n")
    (tmp_path / "p.toml").write_text('[part]\nkind = "profile"\nfile = "gen.csv"\n')
    with pytest.raises(InputError) as e:
        load_part(tmp_path / "p.toml")
    assert e.value.line == 3 and "gen.csv" in str(e.value)
    (tmp_path / "gen.csv").write_text("")
    with pytest.raises(InputError, match="empty"):
        load_part(tmp_path / "p.toml")


def test_part_table_errors(tmp_path):
    with pytest.raises(InputError, match="unknown part kind"):
        part_from_dict({"kind": "hemisphere"})
    with pytest.raises(InputError, match="unknown key"):
        part_from_dict(
            {"kind": "cone", "opening_diameter": 87, "wall_angle": 71, "depth": 50, "x": 1}
        )
    with pytest.raises(InputError, match="missing key"):
        part_from_dict({"kind": "cone", "opening_diameter": 87})
    with pytest.raises(InputError, match="expected a number"):
        part_from_dict({"kind": "cone", "opening_diameter": "87", "wall_angle": 71, "depth": 50})
    p = tmp_path / "bad.toml"
    p.write_text("[part\n")
    with pytest.raises(InputError, match="TOML"):
        load_part(p)
    p.write_text('[part]\nkind = "cone"\nopening_diameter = 87\nwall_angle = 100\ndepth = 10\n')
    with pytest.raises(InputError) as e:
        load_part(p)
    assert "bad.toml" in str(e.value) and "wall_angle" in str(e.value)


def test_every_part_kind_implements_the_part_protocol():
    """Cone, VWACF, profile and mesh parts all satisfy :class:`roboisf.parts.Part`; bounds and
    symmetry are what their geometry says."""
    from roboisf.parts import VWACF, Cone, Part, tessellate

    cone = Cone(opening_diameter=87e-3, wall_angle=np.deg2rad(71.0), depth=102.97e-3)
    mesh = tessellate(cone, chordal_error=0.5e-3)
    for part in (cone, VWACF(opening_diameter=88.15e-3), mesh):
        assert isinstance(part, Part)
    lo, hi = cone.bounds
    assert hi[2] == 0.0 and lo[2] == pytest.approx(-102.97e-3)
    assert hi[0] == pytest.approx(87e-3 / 2 + cone.flange_width)
    assert cone.symmetry.continuous and cone.symmetry.angle == 0.0
    assert mesh.symmetry.order == 1 and mesh.symmetry.angle == pytest.approx(2 * np.pi)
    assert mesh.depth == pytest.approx(cone.depth, abs=1e-9)
