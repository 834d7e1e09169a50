"""The toolpath generators' shortcuts give the bits of the plain computations they replace:
the stacked fixed-height closest point of a generatrix (generate.py's bisections), one ball
solve per height whatever the other heights, and the slicer's march in chunks."""

import math

import numpy as np
import pytest

import roboisf.toolpath.generate as generate
import roboisf.toolpath.slice as slicer
from roboisf.parts import VWACF, Cone, ProfilePart
from roboisf.parts.generatrix import Arc, Generatrix, Segment
from roboisf.toolpath import ball_position


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return (
        a.shape == b.shape
        and a.dtype == b.dtype
        and np.array_equal(a.reshape(-1).view(np.uint8), b.reshape(-1).view(np.uint8))
    )


def _multi_arc():
    """Flange, arc, segment, arc, bottom: two of each kind, wall primitives in between."""
    b0, b1 = 0.0, 1.0
    a1 = Arc(0.05, -0.01, 0.01, b0, b1)
    r1, z1, _ = a1.at(np.array([a1.length]))
    return Generatrix(
        (
            Segment(0.06, 0.0, 0.05, 0.0),
            a1,
            Segment(float(r1[0]), float(z1[0]), 0.02, -0.04),
            Arc(0.01, -0.03, 0.01, 0.5, 1.5),
            Segment(0.01, -0.05, 0.0, -0.05),
        ),
        ("flange", "wall", "wall", "wall", "bottom"),
    )


GENERATRICES = {
    "cone": lambda: Cone().generatrix,
    "cone_no_flange": lambda: Cone(flange_width=0.0).generatrix,
    "vwacf": lambda: VWACF().generatrix,
    "profile": lambda: (
        ProfilePart(
            r=(0.04, 0.035, 0.02, 0.015, 0.0), z=(0.0, -0.01, -0.02, -0.03, -0.03)
        ).generatrix
    ),
    "multi_arc": _multi_arc,
}


def _queries(g, rng):
    """Random meridian points, and the awkward ones: on every primitive, arc centres, the axis,
    signed zeros, NaN and infinities."""
    r = rng.uniform(-0.01, 0.07, 4000)
    z = rng.uniform(-0.12, 0.02, 4000)
    er, ez = [], []
    for p in g.primitives:
        rr, zz, _ = p.at(np.linspace(0.0, p.length, 9))
        er += list(rr)
        ez += list(zz)
        if isinstance(p, Arc):
            er.append(p.rc)
            ez.append(p.zc)
    # near-ties at every joint: on the bisector of the two tool-side normals (the ball that
    # touches wall and bottom at once), moved across it by 0 to 2e-12 m — the tie rule's scale
    for a, b in zip(g.primitives[:-1], g.primitives[1:], strict=True):
        qr, qz, qa = b.at(np.array([0.0]))
        _, _, pa = a.at(np.array([a.length]))
        n = np.array([-np.sin(pa[0]) - np.sin(qa[0]), np.cos(pa[0]) + np.cos(qa[0])])
        n /= np.hypot(*n)
        for t in (1e-4, 2e-3, 5e-3):
            for d in (-2e-12, -7e-13, -4e-13, -2e-13, 0.0, 2e-13, 4e-13, 7e-13, 2e-12):
                er.append(qr[0] + t * n[0] - d * n[1])
                ez.append(qz[0] + t * n[1] + d * n[0])
    er += [np.nan, 0.0, -0.0, np.inf, 0.01]
    ez += [0.0, np.nan, -0.0, -0.05, -np.inf]
    return np.r_[r, er], np.r_[z, ez]


@pytest.mark.parametrize("name", sorted(GENERATRICES))
def test_height_query_is_the_generatrix_closest_point_bit_for_bit(name):
    g = GENERATRICES[name]()
    r, z = _queries(g, np.random.default_rng(1))
    with np.errstate(invalid="ignore"):  # inf·0 at the infinite heights, as in Generatrix
        q = g.at_heights(z)
        for rr in (r, np.zeros_like(r), r[::-1].copy()):  # one query object, several radii
            ref = g.closest(rr, z)
            got = q.closest(rr)
            for a, b in zip(ref, got, strict=True):
                assert same_bits(np.asarray(a, dtype=b.dtype), b)
            # the signed distance generate.py's bisections take
            rp, zp, alpha = ref[0], ref[1], ref[2]
            nr, nz = -np.sin(alpha), np.cos(alpha)
            best = np.hypot(rr - rp, z - zp)
            side = (rr - rp) * nr + (z - zp) * nz
            assert same_bits(np.where(side < 0, -best, best), q.signed(rr))


@pytest.mark.parametrize("part", [Cone(), VWACF()], ids=["cone", "vwacf"])
def test_a_ball_solve_does_not_depend_on_the_other_heights(part):
    """step_down solves each lap's ball once and repeats it over the lap's points; spiral
    solves each distinct height once: both need a height's answer to be its own."""
    z = -np.r_[np.linspace(0.0, part.depth, 23), 0.3e-3, part.depth * 1.2]
    cr, fits = ball_position(part, 5e-3, z)
    for k in range(z.size):
        ck, fk = ball_position(part, 5e-3, z[k : k + 1])
        assert same_bits(cr[k : k + 1], ck) and fk[0] == fits[k]
    c0, f0 = ball_position(part, 5e-3, float(z[3]))  # a scalar height gives a 0-d answer
    assert np.ndim(c0) == 0 and same_bits(c0, cr[3]) and bool(f0) == fits[3]


def test_the_march_in_chunks_is_the_march_in_one_pass(monkeypatch):
    """Centres above the sheet plane march out to the first sample where the ball does not fit;
    evaluated in chunks (many rays), the bracket — and so every ray's answer — is the same."""
    part = Cone(opening_diameter=60e-3, wall_angle=math.radians(60.0), depth=20e-3)
    n = 1500
    rng = np.random.default_rng(3)
    zc = rng.uniform(0.5e-3, 4.5e-3, n)  # ball centres above the sheet: all rays march
    zc[::7] = -3e-3  # and some below, that do not
    angle = rng.uniform(0.0, 2.0 * math.pi, n)
    center = np.array([0.0, 0.0])
    runs = {}
    for split in (0, 10**9):
        monkeypatch.setattr(slicer, "_MARCH_SPLIT", split)
        runs[split] = slicer.ball_centre_rays(part, 5e-3, zc, angle, center=center)
    (rho_c, fits_c), (rho_1, fits_1) = runs[0], runs[10**9]
    assert same_bits(rho_c, rho_1) and np.array_equal(fits_c, fits_1)
    # and the march mattered: the rays stop inside the opening, not at the flange's edge
    assert fits_1.all() and (rho_1[zc > 0] < 30e-3).all()


@pytest.mark.parametrize("make", ["step_down", "spiral"])
def test_solving_in_chunks_changes_no_bit(monkeypatch, make):
    """The generator solves heights (and queries points) in chunks of _CHUNK: a path is the
    same whatever the chunk, down to chunks smaller than a lap (48 points: ~70 a lap here, and
    64 heights)."""

    def path():
        fn = getattr(generate, make)
        return fn(VWACF(), 5e-3, 2e-3, spacing=4e-3, max_wall_step=1e-3, clockwise=True)

    ref = path()
    monkeypatch.setattr(generate, "_CHUNK", 48)
    small = path()
    for name in ("contact", "normal", "wall_angle", "tip", "lap"):
        assert same_bits(getattr(ref, name), getattr(small, name)), name
