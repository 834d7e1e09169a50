"""The fixture registration keeps a uniform sideways wall deflection; the flange one removes it."""

import math

import numpy as np
import pytest

from roboisf.frames import make_transform, rpy_to_matrix
from roboisf.parts import Cone
from roboisf.scan import register, synthetic_scan


@pytest.fixture(scope="module")
def shifted_wall_scan():
    cone = Cone(depth=0.05)
    dx = 0.15e-3  # the wall moved 0.15 mm along x (a robot pushed sideways); the flange did not

    def offset(z, phi):
        a = math.radians(71)
        # a translation by dx·x̂ seen along the tool-side normal (−sin α cos φ, ·, cos α)
        return np.where(z < -1e-9, -dx * math.sin(a) * np.cos(phi), 0.0)

    T = make_transform(rpy_to_matrix([math.radians(0.2), math.radians(-0.1), 0.0]), [0, 0, 0.5e-3])
    scan = synthetic_scan(cone, 200_000, offset=offset, noise=25e-6, T_scan_work=T, seed=3)
    return cone, scan, T


def test_fixture_registration_recovers_z_and_tilts_and_keeps_the_shift(shifted_wall_scan):
    cone, scan, T = shifted_wall_scan
    reg = register(scan.points, cone, "fixture")
    T_true = np.linalg.inv(T)
    np.testing.assert_allclose(reg.T_work_scan[:3, 3], T_true[:3, 3], atol=10e-6)
    np.testing.assert_allclose(reg.T_work_scan[:3, :3], T_true[:3, :3], atol=math.radians(0.01))
    assert abs(reg.T_work_scan[0, 3]) < 10e-6  # x is not fitted: the wall keeps its 0.15 mm


def test_flange_registration_absorbs_the_sideways_shift(shifted_wall_scan):
    cone, scan, _ = shifted_wall_scan
    reg = register(scan.points, cone, "flange")
    assert reg.T_work_scan[0, 3] == pytest.approx(-0.15e-3, abs=20e-6)
