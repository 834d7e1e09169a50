"""Springback without a CNC twin (issue #27, item 3): a robot-only study analysed with the
springback as the residual after the modelled robot, tool and holder terms — "model-based" with
its uncertainty where the robot model holds, "not separable" where it does not."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from roboisf.cli.main import main
from roboisf.decompose.robot_only import SEPARABLE_TOL, springback_without_cnc
from roboisf.errors import InputError
from roboisf.study import load_study
from summary_check import validated

CELL = ["--step-down", "2", "--spacing", "4", "--scan-points", "100000"]
CELL += ["--force-rate", "50", "--joint-rate", "20"]


def _robot_only(folder: Path) -> None:
    """Drop the CNC run from a virtual-cell study (a cell without a CNC twin)."""
    p = folder / "study.toml"
    data = tomllib.loads(p.read_text())
    del data["runs"]["cnc"]
    p.write_text(tomli_w.dumps(data))


@pytest.fixture(scope="module")
def studies(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("robot-only")
    (d / "soft.toml").write_text("[robot]\njoint_stiffness_scale = 0.6\n")
    (d / "coupled.toml").write_text("[springback]\ndeflection_coupling = 0.5\n")
    for name, extra in (
        ("model", []),
        ("soft", ["--truth", str(d / "soft.toml")]),
        ("coupled", ["--truth", str(d / "coupled.toml")]),
    ):
        assert main(["-q", "virtual-cell", "cone", *CELL, *extra, "-o", str(d / name)]) == 0
        (d / name / ".roboisf-output.json").unlink()  # now the user's study, edited
        _robot_only(d / name)
        assert main(["-q", "analyze", str(d / name), "-o", str(d / f"R-{name}")]) == 0
    return d


def _summary(d: Path, name: str) -> dict:
    return validated(d / f"R-{name}" / "summary.json")


def test_the_study_loads_without_a_cnc_run(studies):
    st = load_study(studies / "model")
    assert not st.has_cnc and [r.name for r in st.robot_runs] == ["robot"]
    with pytest.raises(InputError, match="no CNC run"):
        _ = st.cnc


def test_springback_recovered_where_the_model_holds(studies):
    """The done-when: within 0.05 mm RMS of the truth, labelled model-based, with an interval."""
    s = _summary(studies, "model")
    sb = s["springback_model_based"]
    assert sb["label"] == "model-based" and sb["separable"]
    assert s["truth"]["springback_rms_error_mm"] < 0.05
    assert sb["mean_abs_dn_lo"] <= sb["mean_abs_dn"] <= sb["mean_abs_dn_hi"]
    assert 0 < sb["mean_sigma_dn"] < 0.05
    assert sb["beta_95"][0] <= 0 <= sb["beta_95"][1]
    assert "model-based" in (studies / "R-model" / "report.html").read_text()


@pytest.mark.parametrize(("name", "beta"), [("soft", 1 / 0.6 - 1), ("coupled", None)])
def test_not_separable_where_the_model_fails(studies, name, beta):
    """A robot 0.6× as stiff as its model leaves β = 1/0.6 − 1 of the VJM in the residual; a
    springback that recovers half the robot's deflection couples them: both not separable, and
    no springback number is given."""
    s = _summary(studies, name)
    sb = s["springback_model_based"]
    assert sb["label"] == "not separable" and not sb["separable"]
    assert sb["bias_bound_mm"] > SEPARABLE_TOL * 1e3
    assert "mean_abs_dn" not in sb and "truth" not in s
    if beta is not None:
        assert sb["beta_95"][0] <= beta + 0.01 and sb["beta_95"][1] >= beta - 0.01
    assert "not separable" in (studies / f"R-{name}" / "report.html").read_text()


def test_compensate_from_a_robot_only_study(studies, tmp_path):
    """The loop needs no CNC twin either: compensate reads the robot-only analysis."""
    out = tmp_path / "C"
    assert main(["-q", "compensate", str(studies / "model"), "--no-png", "-o", str(out)]) == 0
    s = json.loads((out / "compensation.json").read_text())
    assert s["mean_abs_dn_after_predicted_mm"] < 0.5 * s["mean_abs_dn_before_mm"]


def test_estimator_on_synthetic_laps():
    """Springback constant along each lap, a robot κ× the VJM: β = κ − 1 (its 95 % interval
    covers it in most noise draws); with κ = 1 the springback is returned within the noise and
    labelled model-based, with κ = 1.5 not separable."""
    laps, per = 30, 40
    lap = np.repeat(np.arange(laps), per)
    ang = np.tile(np.linspace(0, 2 * np.pi, per, endpoint=False), laps)
    n = np.column_stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)])
    v = 0.3e-3 * (1 + np.sin(ang))[:, None] * n  # the VJM, varying along a lap
    s = 1e-3 * (1 - np.exp(-lap / 5.0))
    z = np.zeros_like(v)
    ok = np.ones(lap.size, bool)
    for kappa in (1.0, 1.5):
        covered = 0
        for seed in range(20):
            rng = np.random.default_rng(seed)
            dn = s + kappa * np.einsum("ij,ij->i", v, n) + rng.normal(scale=5e-6, size=lap.size)
            est = springback_without_cnc(n, dn, z, z, v, ok, lap, n_boot=300)
            covered += est.beta_lo <= kappa - 1 <= est.beta_hi
            assert abs(est.beta - (kappa - 1)) < 0.01
            assert est.separable is (kappa == 1.0)
            if est.separable:
                assert np.sqrt(np.mean((est.springback_dn - s) ** 2)) < 2e-5
        assert covered >= 15
    with pytest.raises(InputError, match="shape"):
        springback_without_cnc(n, dn[:-1], z, z, v, ok, lap)


def test_a_compensated_run_without_a_cnc_run(studies, tmp_path):
    """A robot-only part formed with a compensated program: the commanded offset is a modelled
    term, so the springback is still recovered (without it the residual would carry the
    pre-deflection, −VJM along each lap: β ≈ −1, not separable)."""
    comp = tmp_path / "C"
    assert main(["-q", "compensate", str(studies / "model"), "--no-png", "-o", str(comp)]) == 0
    s2 = tmp_path / "S2"
    args = ["virtual-cell", "cone", *CELL, "--toolpath", str(comp / "compensated.csv")]
    assert main(["-q", *args, "-o", str(s2)]) == 0
    (s2 / ".roboisf-output.json").unlink()
    _robot_only(s2)
    assert main(["-q", "analyze", str(s2), "-o", str(tmp_path / "R")]) == 0
    s = validated(tmp_path / "R" / "summary.json")
    assert s["springback_model_based"]["separable"]
    assert s["modelled_mean_abs_dn_mm"]["command"] > 0.5
    assert s["measured_mean_abs_dn_mm"] < 0.5
    assert s["truth"]["springback_rms_error_mm"] < 0.05
