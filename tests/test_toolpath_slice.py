"""Toolpaths on any part (roboisf.toolpath.slice): no gouge, touching, closed laps without
self-loops, lap counts, scallop spacing against the geometry, and a cross-check with the
axisymmetric generator on the cone."""

import math

import numpy as np
import pytest

from roboisf.parts import Cone, MeshPart
from roboisf.parts.pyramid import Pyramid
from roboisf.toolpath import step_down
from roboisf.toolpath.slice import scallop_step, sliced_spiral, sliced_step_down

R = 5e-3
SPACING = 1e-3


def elliptic_dome_stl(path, a=60e-3, b=40e-3, D=30e-3, d=25e-3, flange=10e-3, n_s=90, n_t=240):
    """An elliptic paraboloid pit z = −D (1 − (x/a)² − (y/b)²), flat bottom at −d, flat flange
    outside the ellipse, written as an STL in mm; a freeform (not axisymmetric) part."""
    import trimesh

    s_edge = 1.0 + flange / min(a, b)
    s = np.r_[np.linspace(0.0, 1.0, n_s + 1)[1:], np.linspace(1.0, s_edge, 8)[1:]]
    t = 2 * np.pi * np.arange(n_t) / n_t
    S, T = np.meshgrid(s, t, indexing="ij")
    x, y = a * S * np.cos(T), b * S * np.sin(T)
    z = np.maximum(-D * (1 - S**2), -d) * (S < 1)
    V = np.r_[[[0.0, 0.0, -d]], np.c_[x.ravel(), y.ravel(), z.ravel()]]
    F = [[0, 1 + j, 1 + (j + 1) % n_t] for j in range(n_t)]
    for i in range(len(s) - 1):
        for j in range(n_t):
            p, q = 1 + i * n_t + j, 1 + i * n_t + (j + 1) % n_t
            F += [[p, p + n_t, q + n_t], [p, q + n_t, q]]
    trimesh.Trimesh(V * 1e3, np.array(F), process=False).export(path)
    return path


@pytest.fixture(scope="module")
def dome(tmp_path_factory):
    return MeshPart.from_file(elliptic_dome_stl(tmp_path_factory.mktemp("dome") / "dome.stl"))


PYRAMIDS = {
    "rounded": Pyramid(120e-3, 90e-3, math.radians(60.0), 30e-3, corner_radius=8e-3),
    # sharp concave corners: the ball-centre offset must be trimmed there
    "sharp_two_angles": Pyramid(
        110e-3, 90e-3, math.radians(65.0), 25e-3, wall_angle_y=math.radians(50.0), corner_radius=0
    ),
}


def segments_cross(P):
    """True if the closed polygon P (n, 2) crosses itself (proper intersection of two
    non-adjacent edges, orientation test)."""
    A, B = P, np.roll(P, -1, axis=0)
    n = len(P)

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
            r[..., 0] - p[..., 0]
        )

    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))
    i, j = i[keep], j[keep]
    o1 = orient(A[i], B[i], A[j])
    o2 = orient(A[i], B[i], B[j])
    o3 = orient(A[j], B[j], A[i])
    o4 = orient(A[j], B[j], B[i])
    return bool(np.any((o1 * o2 < 0) & (o3 * o4 < 0)))


def check_path(part, tp, *, spacing=SPACING, closed=True, center=(0.0, 0.0), start=0.0):
    # every ball centre touches the nominal: distance R ± 1 µm, measured by closest_point
    d = part.closest_point(tp.center).distance
    assert np.all(np.abs(d - R) <= 1e-6), np.abs(d - R).max()
    # no gouge between points either: the chords, densified
    f = np.linspace(0.0, 1.0, 6)[1:-1]
    mid = tp.center[:-1, None, :] + f[None, :, None] * np.diff(tp.center, axis=0)[:, None, :]
    assert part.closest_point(mid.reshape(-1, 3)).distance.min() >= R - 1e-6
    # the contract: C = P + R n, T = C − R ẑ, contact on the nominal, unit normals
    np.testing.assert_allclose(tp.center, tp.contact + R * tp.normal, atol=1e-12)
    np.testing.assert_allclose(tp.tip[:, 2], tp.center[:, 2] - R, atol=1e-15)
    np.testing.assert_allclose(part.closest_point(tp.contact).distance, 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(tp.normal, axis=1), 1.0, atol=1e-12)
    # point spacing on the tip path
    assert np.linalg.norm(np.diff(tp.tip, axis=0), axis=1).max() <= spacing + 1e-9
    for k in range(tp.n_laps):
        C = tp.center[tp.lap == k]
        assert len(C) >= 8
        # each lap starts on the start ray
        v = C[0, :2] - center
        if np.hypot(*v) > 1e-6:
            assert math.atan2(v[1], v[0]) == pytest.approx(start, abs=1e-9)
        if closed:
            # the contour at the lap's height (after the step down from the lap above, which
            # has points only where a straight step would cut into a convex edge)
            level = C[-1, 2]
            on = np.abs(C[:, 2] - level) < 1e-9
            assert on[np.argmax(on) :].all()
            C = C[on]
            assert np.linalg.norm(C[-1] - C[0]) <= 1e-9  # lap closed: ends where it started
            C = C[:-1]
        # no self-loop, and counter-clockwise seen from +z
        xy = C[:, :2]
        area = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
        if area != 0 and closed:
            assert area > 0
            assert not segments_cross(xy)


@pytest.mark.parametrize("name", list(PYRAMIDS))
def test_pyramid_step_down(name):
    p = PYRAMIDS[name]
    tp = sliced_step_down(p, R, 0.5e-3, spacing=SPACING)
    check_path(p, tp)
    assert tp.n_laps == math.ceil(p.depth / 0.5e-3)
    assert tp.tip[:, 2].min() == pytest.approx(-p.depth, abs=1e-12)
    levels = np.array([tp.tip[tp.lap == k, 2][-1] for k in range(tp.n_laps)])
    np.testing.assert_allclose(np.diff(levels), -0.5e-3, atol=1e-12)
    assert not tp.meta.get("truncated")


def test_sharp_corners_are_trimmed_the_ball_touches_both_walls():
    """At a sharp concave corner the ball cannot reach the edge: its centre sits where the two
    walls' offsets meet, touching both (the trimmed offset), never beyond."""
    p = PYRAMIDS["sharp_two_angles"]
    tp = sliced_step_down(p, R, 1e-3, spacing=0.25e-3)
    lap = tp.lap == tp.n_laps // 2
    C = tp.center[lap]
    # both x- and y-wall offsets at every centre: d_x, d_y ≥ R, and near the corner both ≈ R
    ax, ay = p.alpha_x, p.alpha_y
    dx = (p.top_length / 2 + C[:, 2] / math.tan(ax) - np.abs(C[:, 0])) * math.sin(ax)
    dy = (p.top_width / 2 + C[:, 2] / math.tan(ay) - np.abs(C[:, 1])) * math.sin(ay)
    assert np.all(dx >= R - 1e-9) and np.all(dy >= R - 1e-9)
    corner = np.argmin(dx + dy)
    assert dx[corner] == pytest.approx(R, abs=0.3e-3) and dy[corner] == pytest.approx(R, abs=0.3e-3)


def test_pyramid_spiral_and_clockwise():
    p = PYRAMIDS["rounded"]
    tp = sliced_spiral(p, R, 1e-3, spacing=SPACING)
    check_path(p, tp, closed=False)
    assert np.all(np.diff(tp.tip[:, 2]) <= 1e-12)  # the tip only goes down
    assert tp.n_laps == math.ceil(p.depth / 1e-3)
    assert tp.tip[-1, 2] == pytest.approx(-p.depth, abs=1e-12)
    cw = sliced_step_down(p, R, 2e-3, spacing=SPACING, clockwise=True, start_angle=0.3)
    d = p.closest_point(cw.center).distance
    assert np.all(np.abs(d - R) <= 1e-6)
    xy = cw.center[cw.lap == 3][:, :2]
    area = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
    assert area < 0
    assert math.atan2(xy[0, 1], xy[0, 0]) == pytest.approx(0.3, abs=1e-9)


@pytest.mark.parametrize("name", [*PYRAMIDS, "dome"])
def test_the_last_lap_touches_the_wall_it_forms_not_the_flat_bottom(name, dome):
    """At the full depth the ball touches the flat bottom and the wall at once, and the contact
    fell on the bottom (normal ẑ, wall angle 0): the virtual cell's forming force there was 0 N
    between 662 N laps, which `online --simulate --virtual pyramid` held as an implausible
    drop, and force alignment read the lap's direction as turning back. The wall stops the ray
    and is formed: it is the contact, on the nominal, with C = P + R n exactly."""
    p = dome if name == "dome" else PYRAMIDS[name]
    tp = sliced_step_down(p, R, 1e-3, spacing=SPACING)
    last = np.abs(tp.tip[:, 2] + p.depth) < 1e-12  # the lap at the full depth
    assert last.sum() >= 8 and np.all(tp.lap[last] == tp.n_laps - 1)
    assert np.degrees(tp.wall_angle[last]).min() > 20.0, np.degrees(tp.wall_angle[last]).min()
    np.testing.assert_allclose(tp.center[last], (tp.contact + R * tp.normal)[last], atol=1e-12)
    np.testing.assert_allclose(p.closest_point(tp.contact[last]).distance, 0.0, atol=1e-9)
    # the wall's contact lies above the bottom by the ball's reach up that wall, R (1 − cos α)
    z = tp.contact[last, 2]
    np.testing.assert_allclose(z, -p.depth + R * (1 - np.cos(tp.wall_angle[last])), atol=1e-6)


def test_freeform_elliptic_dome_from_stl(dome):
    tp = sliced_step_down(dome, R, 1e-3, spacing=SPACING)
    check_path(dome, tp)
    assert tp.n_laps == math.ceil(dome.depth / 1e-3)
    sp = sliced_spiral(dome, R, 2e-3, spacing=SPACING)
    check_path(dome, sp, closed=False)


def test_cone_agrees_with_the_axisymmetric_generator():
    """Two independent methods: the generatrix bisection of generate.py and the ray/Newton
    slicer through closest_point only."""
    cone = Cone(opening_diameter=87e-3, wall_angle=math.radians(71.0), depth=40e-3)
    a = sliced_step_down(cone, R, 0.5e-3, spacing=SPACING)
    b = step_down(cone, R, 0.5e-3, spacing=SPACING)
    assert a.n_laps == b.n_laps
    for k in range(a.n_laps):
        # the lap's contour (not its step down from the lap above)
        on = (a.lap == k) & (np.abs(a.center[:, 2] - b.center[b.lap == k, 2][0]) < 1e-9)
        assert on.sum() >= 0.9 * (a.lap == k).sum()
        ra = np.hypot(*a.center[on, :2].T)
        rb = np.hypot(*b.center[b.lap == k, :2].T)
        assert np.abs(ra - rb.mean()).max() < 2e-6
        rca = np.hypot(*a.contact[on, :2].T)
        rcb = np.hypot(*b.contact[b.lap == k, :2].T)
        assert np.abs(rca - rcb.mean()).max() < 2e-6
        np.testing.assert_allclose(a.contact[on, 2], b.contact[b.lap == k, 2][0], atol=2e-6)


@pytest.mark.parametrize("h", [5e-6, 20e-6])
def test_scallop_spacing_matches_the_geometry(h):
    """Δz = 2 sin α sqrt(h (2R − h)); the cusp between two laps' balls on the mid x-wall,
    measured as the signed distance of the two circles' intersection to the nominal, is h."""
    p = Pyramid(120e-3, 120e-3, math.radians(55.0), 30e-3, corner_radius=8e-3)
    dz = scallop_step(h, R, p.wall_angle)
    tp = sliced_step_down(p, R, 2e-3, scallop_height=h, spacing=2e-3)
    levels = np.array([tp.tip[tp.lap == k, 2][-1] for k in range(tp.n_laps)])
    steps = -np.diff(levels)
    # away from the rim (where the ball rolls over the edge) and the bottom: the formula's Δz
    deep = (levels[:-1] < -2 * R) & (levels[1:] > -p.depth + 1e-9)
    np.testing.assert_allclose(steps[deep], dz, rtol=1e-9)
    # the cusp, from the geometry: circles of radius R about consecutive centres (y = 0 plane)
    for k in np.flatnonzero(deep)[::10]:
        c1 = tp.center[tp.lap == k][-1][[0, 2]]
        c2 = tp.center[tp.lap == k + 1][-1][[0, 2]]
        m, v = 0.5 * (c1 + c2), c2 - c1
        w = np.linalg.norm(v)
        perp = np.array([v[1], -v[0]]) / w
        cusp = [m + s * math.sqrt(R**2 - w**2 / 4) * perp for s in (1, -1)]
        # the one on the material side (further from the part's axis)
        cusp = max(cusp, key=lambda q: q[0])
        depth_cusp = p.signed_distance(np.array([[cusp[0], 0.0, cusp[1]]]))[0]
        assert depth_cusp == pytest.approx(h, rel=1e-6)


def test_bad_options():
    from roboisf.errors import InputError

    p = PYRAMIDS["rounded"]
    with pytest.raises(InputError, match="step-down"):
        sliced_step_down(p, R, 0.1)
    with pytest.raises(InputError) as e:
        sliced_step_down(p, R, 1e-3, scallop_height=6e-3)
    assert e.value.field == "scallop_height"
    small = Pyramid(20e-3, 20e-3, 1.2, 10e-3, corner_radius=0)
    with pytest.raises(InputError) as e:
        sliced_step_down(small, 20e-3, 10e-3)
    assert e.value.field == "tool_radius"
    # a ball that fits only in the upper part: the path stops where it stops fitting
    tp = sliced_step_down(small, 9.5e-3, 1e-3)
    assert tp.meta["truncated"] and tp.n_laps < 10
    z_last = tp.meta["reachable_tip_z"]
    assert small.signed_distance(np.array([[0.0, 0.0, z_last + 9.5e-3]]))[0] >= 9.5e-3 - 1e-12
    assert small.signed_distance(np.array([[0.0, 0.0, z_last - 1e-3 + 9.5e-3]]))[0] < 9.5e-3


def test_cli_toolpath_on_pyramid_and_mesh_part_files(tmp_path, dome):
    """`roboisf toolpath --part` takes any part file; the CSV keeps the toolpath contract."""
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.cli.main import main
    from roboisf.parts import save_part

    p = Pyramid(100e-3, 80e-3, math.radians(60.0), 12e-3, corner_radius=6e-3)
    toml = tmp_path / "pyr.toml"
    save_part(p, toml)
    out = tmp_path / "pyr.csv"
    args = ["--step-down", "1", "--tool-diameter", "10", "--spacing", "2"]
    assert main(["toolpath", "--part", str(toml), "-o", str(out), *args]) == 0
    tp = read_toolpath_csv(out)
    assert tp.n_laps == 12
    d = p.closest_point(tp.center).distance
    assert np.abs(d - R).max() < 2e-6  # the CSV rounds to its printed precision
    out2 = tmp_path / "pyr_scallop.csv"
    assert (
        main(
            [
                "toolpath",
                "--part",
                str(toml),
                "-o",
                str(out2),
                *args,
                "--scallop-height",
                "0.02",
                "--spiral",
            ]
        )
        == 0
    )
    assert read_toolpath_csv(out2).n_laps > 12
    # a mesh part file (the dome STL)
    mtoml = tmp_path / "dome.toml"
    save_part(dome, mtoml)
    out3 = tmp_path / "dome.nc"
    assert (
        main(
            [
                "toolpath",
                "--part",
                str(mtoml),
                "-o",
                str(out3),
                "--step-down",
                "2",
                "--spacing",
                "3",
            ]
        )
        == 0
    )
    assert out3.stat().st_size > 0
    # --max-wall-step is for axisymmetric parts: exit 2, no output
    bad = tmp_path / "bad.csv"
    assert main(["toolpath", "--part", str(toml), "-o", str(bad), "--max-wall-step", "1"]) == 2
    assert not bad.exists()


def test_level_contour_is_the_section_of_the_surface_and_of_its_offset():
    from roboisf.toolpath import level_contour

    p = PYRAMIDS["rounded"]
    z = -10e-3
    P = level_contour(p, z, n=720)
    np.testing.assert_allclose(p.signed_distance(P), 0.0, atol=1e-10)
    # the nominal section: the opening shrunk by |z| / tan α (corner radius shrunk alike)
    sx, sy, rc = p.section(-z)
    from roboisf.parts.pyramid import rounded_rectangle_closest

    _, sd = rounded_rectangle_closest(P[:, :2], sx, sy, rc)
    np.testing.assert_allclose(sd, 0.0, atol=1e-10)
    C = level_contour(p, z, offset=R, n=720)
    np.testing.assert_allclose(p.signed_distance(C), R, atol=1e-10)
    cone = Cone(opening_diameter=87e-3, wall_angle=math.radians(71.0), depth=40e-3)
    r = np.hypot(*level_contour(cone, -20e-3)[:, :2].T)
    np.testing.assert_allclose(r, 43.5e-3 - 20e-3 / math.tan(math.radians(71.0)), atol=1e-10)


def test_cli_never_overwrites_the_file_a_part_refers_to(tmp_path):
    from roboisf.cli.main import main

    prof = tmp_path / "profile.csv"
    prof.write_text("r,z\n40,0\n30,-10\n25,-20\n")
    toml = tmp_path / "p.toml"
    assert main(["part", "profile", str(prof), "-o", str(toml)]) == 0
    before = prof.read_text()
    assert main(["toolpath", "--part", str(toml), "-o", str(prof)]) == 2
    assert prof.read_text() == before
