"""The virtual cell's in-place and reordered computations give the plain expressions' numbers.

The study builder's formed-surface fields, scan sampling, hole cutting and force quantisation
are written for speed (in place, queries reordered, a per-mesh sampler kept); each is checked
here, bit for bit, against the plain expression it replaces.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.parts import Pyramid
from roboisf.scan import synthetic as syn
from roboisf.scan.readers import sample_faces
from roboisf.virtual.cell import paper_vwacf_cell, pyramid_cell, quantize_wrench, simulate
from roboisf.virtual.formed import NormalField, PointField


def _plain_normal_field(f: NormalField, s, phi):
    s, phi = np.asarray(s, dtype=float), np.asarray(phi, dtype=float)
    A = f.phi.size
    u = np.mod(phi + np.pi, 2 * np.pi) / (2 * np.pi) * A
    j0 = np.floor(u).astype(np.int64) % A
    j1 = (j0 + 1) % A
    fu = u - np.floor(u)
    i1 = np.clip(np.searchsorted(f.s_laps, s, side="right"), 1, f.s_laps.size - 1)
    i0 = i1 - 1
    fs = np.clip((s - f.s_laps[i0]) / (f.s_laps[i1] - f.s_laps[i0]), 0.0, 1.0)
    g = f.grid
    v0 = g[i0, j0] * (1 - fu) + g[i0, j1] * fu
    v1 = g[i1, j0] * (1 - fu) + g[i1, j1] * fu
    return np.asarray(v0 * (1 - fs) + v1 * fs, dtype=float)


@pytest.fixture(scope="module")
def vwacf_field():
    cell = paper_vwacf_cell(step_down=1e-3, spacing=2e-3)
    tr = simulate(cell)
    return cell.part, NormalField.from_toolpath(cell.part, tr.toolpath, tr.dn_robot)


def test_normal_field_is_the_plain_bilinear_formula(vwacf_field):
    _, f = vwacf_field
    rng = np.random.default_rng(0)
    s = rng.uniform(-5e-3, 0.06, 5000)
    phi = rng.uniform(-10.0, 10.0, 5000)
    s[:3] = f.s_laps[:3]  # on a lap and at the grid's angles exactly
    phi[:3] = f.phi[:3]
    for args in ((s, phi), (0.01, 0.3), (0.02, phi[:7]), (s[:7], 1.0), (s[:6, None], phi[:4])):
        got = f(*args)
        want = _plain_normal_field(f, *args)
        assert got.shape == want.shape
        assert np.array_equal(got, want)


def test_point_field_answers_do_not_depend_on_the_queries_order():
    cell = pyramid_cell(step_down=2e-3, spacing=3e-3)
    tr = simulate(cell)
    pf = PointField.from_toolpath(tr.toolpath, tr.dn_robot)
    rng = np.random.default_rng(1)
    X = rng.uniform(-0.06, 0.06, (20_000, 3))
    X[:, 2] = rng.uniform(-0.045, 0.002, 20_000)
    dist, idx = pf._tree.query(X, k=list(range(1, pf.k + 1)))
    w = 1.0 / np.maximum(dist, 1e-9) ** 2
    plain = np.sum(w * pf.dn[idx], axis=1) / np.sum(w, axis=1)
    plain = plain * np.clip(X[:, 2] / pf.z_first, 0.0, 1.0)
    assert np.array_equal(pf(X), plain)  # sorted queries (≥ 4096 points)
    assert np.array_equal(pf(X[:100]), plain[:100])  # as given
    perm = rng.permutation(len(X))
    assert np.array_equal(pf(X[perm]), plain[perm])


def test_face_sampler_draws_the_points_of_sample_faces():
    part = Pyramid(80e-3, 60e-3, math.radians(55.0), 25e-3, corner_radius=8e-3)
    V, F = syn.height_field_mesh(part, 1e-3)
    for seed in (0, 3):
        want, _ = sample_faces(V, F, 7001, seed)
        assert np.array_equal(syn._sample_faces(syn._face_sampler(V, F), 7001, seed), want)
    with pytest.raises(Exception, match="no triangle with a non-zero area"):
        syn._face_sampler(np.zeros((3, 3)), np.array([[0, 1, 2]]))


def test_holes_cut_the_points_the_plain_norm_cuts():
    rng = np.random.default_rng(2)
    P = rng.uniform(-0.05, 0.05, (20_000, 3))
    c = np.array([0.01, -0.02, 0.0])
    r = 4e-3
    # points on the edge of the hole's square, exactly at the radius, at the centre
    P[0] = c + np.array([r, 0.0, 0.0])
    P[1] = c + np.array([r * (1 + 1e-9), 0.0, 0.0])
    P[2] = c + np.array([0.0, -r, 0.0])
    P[3] = c
    P[4] = c + np.array([r / math.sqrt(2), r / math.sqrt(2), 0.0])
    P[5] = c + np.array([0.0, 0.0, r])
    cases = [
        [(c, r)],
        [(c, r), (P[10], 2e-3)],
        [(c, 0.0)],
        [(c, -1.0)],
        [(c, 1e-200)],
        [(c, float("nan"))],
        [(np.array([np.nan, 0.0, 0.0]), r)],
        [(c, np.inf)],
    ]
    for holes in cases:
        plain = np.ones(len(P), dtype=bool)
        for centre, radius in holes:
            plain &= np.linalg.norm(P - np.asarray(centre, dtype=float), axis=1) > radius
        keep = syn._outside_holes(P, holes)
        got = np.ones(len(P), dtype=bool) if keep is None else keep
        assert np.array_equal(got, plain), holes
    Q = P.copy()
    Q[7] = [np.nan, c[1], c[2]]  # a NaN point is inside every hole (its norm is NaN)
    plain = np.linalg.norm(Q - c, axis=1) > r
    assert np.array_equal(syn._outside_holes(Q, [(c, r)]), plain)


def test_quantize_whole_rows_as_per_block():
    rng = np.random.default_rng(3)
    W = rng.normal(scale=300.0, size=(5000, 6))
    W[:5] = [0.5 * 2.0**-4, -1.5 * 2.0**-4, 2.5 * 2.0**-10, -0.0, 1e-30, 7.0]  # halves: to even
    for res in ((2.0**-4, 2.0**-10), (0.1, 0.003), (2.0**-4, 0.0), (0.0, 0.0)):
        for A in (W.copy(), np.asfortranarray(W)):
            plain = A.copy()
            for cols, step in ((slice(0, 3), res[0]), (slice(3, 6), res[1])):
                if step > 0:
                    plain[:, cols] = np.round(plain[:, cols] / step) * step
            got = quantize_wrench(A, res)
            assert got is A
            assert np.array_equal(got, plain) and np.array_equal(np.signbit(got), np.signbit(plain))
