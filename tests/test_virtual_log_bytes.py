"""What the virtual cell writes, smaller with nothing lost: force-sensor resolution (counts),
read back bit for bit, and an analysis that does not see it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roboisf.decompose.pipeline import analyze
from roboisf.errors import InputError
from roboisf.logs.forcelog import read_force_log
from roboisf.virtual.cell import (
    _interp_columns,
    _intervals,
    build_study,
    paper_cone_cell,
    quantize_wrench,
)

F_STEP, M_STEP = 2.0**-4, 2.0**-10


#: The small paper cone (tests/conftest.py's SMALL_CONE, checked in :func:`studies`).
SETTINGS = {
    "scan_points": 150_000,
    "force_rate": 50.0,
    "joint_rate": 20.0,
    "step_down": 2e-3,
    "spacing": 4e-3,
}


def _cell(**kw):
    return paper_cone_cell(**SETTINGS, **kw)


@pytest.fixture(scope="module")
def studies(tmp_path_factory, small_cone_settings, small_cone_study):
    """The cell's study at its default force resolution — the session's shared small cone,
    read-only (the same cell: built once for the session, not again here) — and at none."""
    assert small_cone_settings == SETTINGS
    root = tmp_path_factory.mktemp("bytes")
    cont = build_study(_cell(force_resolution=(0.0, 0.0)), root / "continuous")
    return small_cone_study, cont


def test_log_columns_are_np_interp_bit_for_bit():
    """The virtual logs' interpolation (one interval search for all columns) gives np.interp's
    numbers exactly: inside, on the knots, before the first and after the last time."""
    rng = np.random.default_rng(7)
    time = np.cumsum(rng.uniform(1e-3, 5e-2, 3000))
    values = rng.normal(size=(3000, 6)) * [1, 10, 100, 1e-3, 1e-2, 1]
    t = np.concatenate([np.arange(-0.1, time[-1] + 0.1, 7e-4), time[::7], [time[0], time[-1]]])
    got = _interp_columns(t, time, values)
    want = np.column_stack([np.interp(t, time, values[:, c]) for c in range(6)])
    np.testing.assert_array_equal(got, want)
    # a repeated time (a toolpath point held): no warning, np.interp's jump
    rep = np.array([0.0, 1.0, 1.0, 2.0])
    tt = np.array([-1.0, 0.5, 1.0, 1.5, 2.0, 3.0])
    vv = np.array([[0.0], [1.0], [3.0], [4.0]])
    np.testing.assert_array_equal(_interp_columns(tt, rep, vv)[:, 0], np.interp(tt, rep, vv[:, 0]))
    one = _interp_columns(t[:5], time[:1], values[:1])  # a single knot: constant
    np.testing.assert_array_equal(one, np.repeat(values[:1], 5, axis=0))
    # a log's increasing clock (the intervals counted, not searched): knots held, times on the
    # knots, before the first and after the last
    clock = np.arange(-0.1, time[-1] + 0.1, 7e-4)
    knots = np.sort(np.concatenate([time, time[::50], clock[100:110]]))  # repeats, shared times
    vk = rng.normal(size=(knots.size, 2))
    want = np.column_stack([np.interp(clock, knots, vk[:, c]) for c in range(2)])
    np.testing.assert_array_equal(_interp_columns(clock, knots, vk), want)
    j_counted = _intervals(clock, knots)[0]
    j_searched = np.clip(np.searchsorted(knots, clock, side="right") - 1, 0, knots.size - 2)
    np.testing.assert_array_equal(j_counted, j_searched)


@pytest.mark.parametrize("part", ["cone", "vwacf"])
def test_force_logs_in_blocks_are_the_whole_arrays(part, monkeypatch):
    """The synthesised logs computed in row blocks (ragged last block, the noise drawn block by
    block: force noise of every sample, then the moments') are the numbers of one block of the
    whole log — a flange sensor with calibration errors, a bias and the tool's weight included."""
    from dataclasses import replace

    import roboisf.virtual.cell as vc

    cell = vc.paper_scenario_cell(part, scan_points=20_000, force_rate=200.0)
    # a flange sensor with a bias, a gain, cross-talk and the tool's weight: the whole path
    sensor = replace(
        cell.truth,
        sensor_bias=np.array([3.0, -2.0, 5.0, 0.1, -0.05, 0.02]),
        sensor_gain=np.array([1.02, 0.98, 1.01, 1.0, 1.0, 0.99]),
        sensor_crosstalk=0.002 * (1 - np.eye(6)),
        tool_mass=2.5,
        tool_cog=np.array([0.01, 0.0, 0.15]),
    )
    cell = replace(cell, truth=sensor)
    truth = vc.simulate(cell)
    # the two sensors as build_study places them
    cnc = vc.ForceSensorSpec(Path("c.parquet"), "fixture", cell.fixture_sensor_pose, "workpiece")
    rob = vc.ForceSensorSpec(Path("r.parquet"), "flange", cell.T_tip_sensor, "tool")
    logs = {}
    for block in (977, 1 << 40):
        monkeypatch.setattr(vc, "_LOG_BLOCK", block)
        rng = np.random.default_rng(11)
        logs[block] = [
            vc._force_log(cell, truth.toolpath, truth.wrench_cnc, cnc, rng),
            vc._force_log(cell, truth.toolpath, truth.wrench_robot, rob, rng, cell.truth),
        ]
    for a, b in zip(logs[977], logs[1 << 40], strict=True):
        assert len(a) > 10 * 977
        np.testing.assert_array_equal(a.time, b.time)
        np.testing.assert_array_equal(a.wrench, b.wrench)


def test_quantize_wrench_rounds_to_the_nearest_count():
    W = np.array(
        [[0.03, -0.04, 1.0 / 32 + 1e-9, 0.0004, -0.0006, 0.00049], [500.1, 0, 0, 3.3, 0, 0]]
    )
    Q = quantize_wrench(W.copy(), (F_STEP, M_STEP))
    # by hand: 0.03 N → 0.0625 · round(0.48) = 0; −0.04 → −0.0625; 1/32⁺ → 0.0625
    np.testing.assert_array_equal(Q[0, :3], [0.0, -F_STEP, F_STEP])
    np.testing.assert_array_equal(Q[0, 3:], [0.0, -M_STEP, M_STEP])
    assert Q[1, 0] == 500.125 and Q[1, 3] == round(3.3 * 1024) / 1024
    assert np.all(np.abs(Q - W)[:, :3] <= F_STEP / 2) and np.all(np.abs(Q - W)[:, 3:] <= M_STEP / 2)
    np.testing.assert_array_equal(quantize_wrench(W.copy(), (0.0, 0.0)), W)  # 0: continuous


@pytest.mark.parametrize("bad", [(-1.0, 0.0), (0.0, float("nan")), (1.0,)])
def test_bad_force_resolution_is_refused(bad):
    with pytest.raises(InputError, match="force_resolution"):
        _cell(force_resolution=bad)


def test_force_logs_are_sensor_counts_read_back_exactly(studies):
    counts, cont = studies
    for name in ("cnc_forces.parquet", "robot_forces.parquet"):
        q = read_force_log(counts / name)
        c = read_force_log(cont / name)
        np.testing.assert_array_equal(q.time, c.time)
        # every value read back is an exact count of the resolution (float32 holds them exactly)
        np.testing.assert_array_equal(q.wrench[:, :3] / F_STEP, np.round(q.wrench[:, :3] / F_STEP))
        np.testing.assert_array_equal(q.wrench[:, 3:] / M_STEP, np.round(q.wrench[:, 3:] / M_STEP))
        # and the nearest count of the continuous reading (same seed: same noise), which the
        # float32 column keeps to 6e-8 relative
        tol = np.abs(c.wrench) * 2.0**-23
        assert np.all(np.abs(q.wrench[:, :3] - c.wrench[:, :3]) <= F_STEP / 2 + tol[:, :3])
        assert np.all(np.abs(q.wrench[:, 3:] - c.wrench[:, 3:]) <= M_STEP / 2 + tol[:, 3:])
        assert np.any(q.wrench != c.wrench)  # the resolution did act


def test_analysis_does_not_see_the_force_resolution(studies, small_cone_analysis):
    _, cont = studies
    a, b = small_cone_analysis, analyze(cont)  # a: analyze() of the counts' study, shared
    sa = a.contributions_normal.set_index("factor")["share_percent"]
    sb = b.contributions_normal.set_index("factor")["share_percent"]
    # 1/16 N against 2 N of noise: shares agree to far below the demo's 0.1-point budget
    np.testing.assert_allclose(sa, sb, atol=0.01)


def test_demo_programs_default_to_the_cells_machines(tmp_path):
    """RAPID for the ABB robot, G-code for the CNC; every dialect on request; each read back
    to the toolpath's tips (the readers are independent of the writers' layouts)."""
    from roboisf.cam.gcode import read_gcode
    from roboisf.cli.demo import DEMO_FORMATS, write_demo_programs
    from roboisf.programs.rapid import read_rapid
    from roboisf.virtual.cell import cell_toolpath

    cell = _cell()
    tp = cell_toolpath(cell)
    paths = write_demo_programs(cell, tp, tmp_path / "p")
    assert DEMO_FORMATS == ("rapid", "gcode")
    assert [p.name for p in paths] == ["toolpath.mod", "toolpath.nc"]
    assert sorted(p.suffix for p in (tmp_path / "p").iterdir()) == [".mod", ".nc"]
    rapid = read_rapid(paths[0])
    assert np.abs(rapid.tip - tp.tip).max() <= 0.5e-6 + 1e-12
    np.testing.assert_allclose(rapid.T_base_work, cell.cell.T_base_work, atol=1e-8)
    nc = read_gcode(paths[1])
    assert nc.tip.shape == tp.tip.shape and np.abs(nc.tip - tp.tip).max() <= 0.5e-6 + 1e-12
    every = write_demo_programs(
        cell, tp, tmp_path / "all", ("rapid", "gcode", "krl", "fanuc", "csv")
    )
    assert {p.suffix for p in every} == {".mod", ".nc", ".src", ".ls", ".csv"}
    with pytest.raises(InputError, match="unknown format 'abb'"):
        write_demo_programs(cell, tp, tmp_path / "bad", ("abb",))


@pytest.mark.parametrize("mount", ["fixture", "flange"])
def test_sensor_wrench_is_tip_to_sensor(mount):
    """The whole-log frame change agrees with the per-sample reference to rounding."""
    from roboisf.frames import make_transform, rpy_to_matrix, vertical_tool
    from roboisf.study.sensors import tip_to_sensor
    from roboisf.study.spec import ForceSensorSpec
    from roboisf.virtual.cell import sensor_wrench

    rng = np.random.default_rng(3)
    W = rng.normal(size=(500, 6)) * [300, 300, 500, 10, 10, 2]
    tip = rng.normal(size=(500, 3)) * 0.05
    R = vertical_tool(0.7)
    pose = make_transform(rpy_to_matrix([0.1, -0.2, 1.3]), [0.01, -0.02, -0.06])
    load_on = "workpiece" if mount == "fixture" else "tool"
    sensor = ForceSensorSpec(Path("f.parquet"), mount, pose, load_on)
    ref = tip_to_sensor(W, sensor, tip, R)
    np.testing.assert_allclose(sensor_wrench(W.copy(), sensor, tip, R), ref, rtol=0, atol=1e-10)
    assert np.abs(ref - W).max() > 1  # a real change of frame


def test_demo_error_stops_the_second_process(tmp_path):
    """An error in the main process's study (the cone's folder is taken) ends the demo at once
    with that error, and the VWACF's process — which would build for a minute — with it."""
    import multiprocessing
    import time

    from roboisf.cli.demo import build_demo

    (tmp_path / "cone-71").mkdir()
    t0 = time.perf_counter()
    with pytest.raises(FileExistsError):
        build_demo(tmp_path, scan_points=150_000, force_rate=50.0, jobs=2)
    assert multiprocessing.active_children() == []
    assert not (tmp_path / "vwacf" / "results").exists()  # stopped, not waited for
    assert time.perf_counter() - t0 < 60
    with pytest.raises(InputError, match="jobs"):
        build_demo(tmp_path, jobs=0)


def test_demo_error_stops_the_forked_second_process(tmp_path):
    """The same from a process that runs no other thread, where the VWACF's process is forked
    (roboisf.cli.demo._second_process_context), as the command line does."""
    import os
    import subprocess
    import sys

    (tmp_path / "cone-71").mkdir()
    code = (
        "import multiprocessing, sys, time\n"
        "from pathlib import Path\n"
        "from roboisf.cli.demo import _second_process_context, build_demo\n"
        "assert _second_process_context().get_start_method() == 'fork'\n"
        "t0 = time.perf_counter()\n"
        "try:\n"
        "    build_demo(Path(sys.argv[1]), scan_points=150_000, force_rate=50.0, jobs=2)\n"
        "except FileExistsError:\n"
        "    print('refused', multiprocessing.active_children(), time.perf_counter() - t0 < 60)\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path)],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        timeout=120,
    )
    assert run.stdout.strip() == "refused [] True", run.stderr
    assert not (tmp_path / "vwacf" / "results").exists()
