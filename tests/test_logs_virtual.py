"""The virtual cell's logs as Parquet (default) and CSV give the same analysis; a robot force log
rewritten the way an ATI Net F/T demo writes it — with a sensor offset, the tool's weight and an
unloaded approach — is tared and gravity-compensated back to the clean decomposition."""

from __future__ import annotations

import re

import numpy as np
import pytest

from roboisf.decompose.pipeline import analyze
from roboisf.frames import vertical_tool
from roboisf.logs.forcelog import read_force_log
from roboisf.sensor import gravity_wrench
from roboisf.study import load_study

BIAS = np.array([30.0, -12.0, 8.0, 0.6, -0.4, 0.15])  # N, N·m
MASS, COG_MM = 4.2, np.array([12.0, -8.0, 95.0])  # kg, mm (sensor frame)
APPROACH = 2.0  # s of unloaded approach before the toolpath starts


@pytest.fixture(scope="module")
def studies(small_cone_study, small_cone_study_csv):
    """The small paper cone with Parquet and CSV logs (tests/conftest.py, shared, read-only)."""
    return small_cone_study, small_cone_study_csv


def _shares(result):
    return result.contributions_normal.set_index("factor")["share_percent"]


def test_parquet_is_the_default_and_analyses_like_csv(studies, small_cone_analysis):
    pq, csv = studies
    assert (pq / "robot_forces.parquet").is_file() and (pq / "robot_joints.parquet").is_file()
    assert not list(pq.glob("*_forces.csv"))
    assert (csv / "robot_forces.csv").is_file()
    a, b = small_cone_analysis, analyze(csv)
    assert a.study.root.resolve() == pq.resolve()  # the shared analysis is of the Parquet study
    # float32 channels against 10-digit CSV: the same decomposition to far below a µm
    np.testing.assert_allclose(_shares(a), _shares(b), atol=1e-3)
    cols = [c for c in a.per_point.columns if c.startswith("robot_") and c.endswith("_dn")]
    assert cols
    np.testing.assert_allclose(a.per_point[cols], b.per_point[cols], atol=1e-5)


def _ati_log(study, dst, *, bias, mass):
    """The robot run's log as ATI's Net F/T demo writes it, with an unloaded approach."""
    st = load_study(study)
    run = st.robot_run
    log = read_force_log(study / run.forces.file)
    rate = 1.0 / float(np.median(np.diff(log.time)))
    n0 = round(APPROACH * rate)
    rng = np.random.default_rng(7)
    W = np.vstack([rng.normal(scale=0.3, size=(n0, 6)) * [1, 1, 1, 5e-3, 5e-3, 5e-3], log.wrench])
    R = (
        st.robot.T_base_work[:3, :3]
        @ vertical_tool(st.robot.tool_rotation)
        @ run.forces.pose[:3, :3]
    )
    W = W + bias + gravity_wrench(R, mass, COG_MM * 1e-3)
    lines = [
        "Start Time: 3/14/24 10:21 AM",
        f"RDT Sample Rate: {rate:g}",
        '"PLEASE NOTE: The sample rate is read from the Net F/T when the program starts."',
        "Force Units: N",
        "Counts per Unit Force: 1000000.0",
        "Torque Units: Nm",
        "Counts per Unit Torque: 1000000.0",
        "Status (hex), RDT Sequence, F/T Sequence, Fx, Fy, Fz, Tx, Ty, Tz, Time",
    ]
    for k, w in enumerate(W):
        cells = ",".join(f'"{v:.6f}"' for v in w)
        lines.append(f'"0x0","{1000 + k}","{70000 + 14 * k}",{cells},"Mar 14, 2024 10:21:07 AM"')
    dst.write_text("\n".join(lines) + "\n")
    return bias + gravity_wrench(R, mass, COG_MM * 1e-3)  # the unloaded reading


def _use_ati(study, name, extra):
    toml = study / "study.toml"
    text = toml.read_text()
    block = re.search(r"\[runs\.robot\.forces\]\n(.*?)(\n\[|\Z)", text, re.S)
    assert block is not None
    body = re.sub(r'file = "[^"]*"', f'file = "{name}"', block.group(1))
    body += f'\nformat = "ati"\ntime_offset = {APPROACH}\n' + extra
    toml.write_text(text[: block.start(1)] + body + text[block.end(1) :])


def test_ati_log_with_bias_and_tool_weight_recovers_the_clean_decomposition(
    studies, small_cone_analysis, tmp_path
):
    import shutil

    pq, _ = studies
    clean = small_cone_analysis
    s = tmp_path / "s"
    shutil.copytree(pq, s)
    _ati_log(s, s / "robot_ati.csv", bias=BIAS, mass=MASS)
    _use_ati(
        s,
        "robot_ati.csv",
        f'tare = "auto"\ntool_mass = {MASS}\ntool_cog = [{", ".join(map(str, COG_MM))}]\n',
    )
    got = analyze(s)
    np.testing.assert_allclose(_shares(got), _shares(clean), atol=1.0)  # percentage points
    assert not [w for w in got.summary.warnings if "not tared" in w]

    # the same log without conditioning: the 30 N offset and 41 N of weight are flagged
    s2 = tmp_path / "s2"
    shutil.copytree(pq, s2)
    unloaded = _ati_log(s2, s2 / "robot_ati.csv", bias=BIAS, mass=MASS)
    _use_ati(s2, "robot_ati.csv", "")
    raw = analyze(s2)
    flagged = [w for w in raw.summary.warnings if "not tared" in w]
    assert len(flagged) == 1 and "robot_ati.csv" in flagged[0]
    size = float(flagged[0].split("|F| = ")[1].split(" N")[0])
    # the size reported is the unloaded reading: offset plus the weight in sensor axes
    assert size == pytest.approx(np.linalg.norm(unloaded[:3]), rel=0.01)
    assert np.linalg.norm(unloaded[:3]) > 40.0
