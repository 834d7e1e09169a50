"""The streaming core: against RobotModel.deflection, the filter's exact step response, the
tool's weight, and the limits under hostile input."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from roboisf.cell import make_cell, tip_compliances
from roboisf.errors import InputError
from roboisf.frames import invert, make_transform, rpy_to_matrix, transform_wrench
from roboisf.online import Limits, OnlineCompensator, SensorSetup
from roboisf.online import kernel as kn
from roboisf.parts import Cone
from roboisf.robot import ik_toolpath


@pytest.fixture(scope="module")
def cell():
    return make_cell(Cone(), T_base_work=make_transform(p=[2.2, 0.0, 0.2]))


@pytest.fixture(scope="module")
def poses(cell):
    rng = np.random.default_rng(1)
    tips = np.column_stack(
        [rng.uniform(-0.04, 0.04, 6), rng.uniform(-0.04, 0.04, 6), rng.uniform(-0.08, 0, 6)]
    )
    return ik_toolpath(cell.robot, tips, cell.T_base_work).q


SENSOR_POSE = make_transform(rpy_to_matrix([0.02, -0.03, math.radians(30)]), [0.004, -0.002, 0.03])


def _sensor_reading(cell, q, W_work, sensor: SensorSetup):
    """What the flange sensor reads for the sheet's wrench ``W_work`` at the tip (work axes):
    an independent chain of the frames helpers."""
    T_base_tip = cell.robot.fk(q)[0]
    T_work_tip = invert(cell.T_base_work) @ T_base_tip
    R = T_work_tip[:3, :3]
    W_tip_axes = np.concatenate([R.T @ W_work[:3], R.T @ W_work[3:]])
    T_sensor_tip = invert(sensor.T_flange_sensor) @ cell.robot.T_flange_tip
    W_s = transform_wrench(W_tip_axes, T_sensor_tip)
    # the tool's weight, an external load m g at the CoG
    R_base_sensor = (cell.robot.fk(q)[0] @ invert(cell.robot.T_flange_tip))[:3, :3] @ (
        sensor.T_flange_sensor[:3, :3]
    )
    f_g = sensor.tool_mass * R_base_sensor.T @ np.array([0, 0, -9.80665])
    W_s = W_s + np.concatenate([f_g, np.cross(sensor.tool_cog, f_g)])
    sgn = -1.0 if sensor.load_on == "workpiece" else 1.0
    return sgn * W_s + sensor.tare


@pytest.mark.parametrize("load_on", ["tool", "workpiece"])
def test_correction_is_minus_the_offline_deflection(cell, poses, load_on):
    sensor = SensorSetup(
        SENSOR_POSE,
        load_on=load_on,
        tare=np.array([3.0, -2.0, 5.0, 0.1, -0.2, 0.05]),
        tool_mass=2.5,
        tool_cog=np.array([0.001, 0.0, 0.08]),
    )
    oc = OnlineCompensator.from_cell(cell, sensor, Limits(max_rate=1e3, deadband=0.0))
    _, _, k_t, k_th = tip_compliances(cell)
    rng = np.random.default_rng(2)
    for i, q in enumerate(poses):
        W = np.concatenate([rng.normal(0, 150, 3) + np.array([0, 0, 400.0]), rng.normal(0, 2, 3)])
        oc.reset()
        oc.set_joints(q)
        assert oc.sample(float(i), _sensor_reading(cell, q, W, sensor))
        c = oc.cycle(i + 1e-3, q)
        d = cell.robot.deflection(q, W, T_base_work=cell.T_base_work)[0] + (k_t + k_th) @ W
        assert oc.status == kn.STATUS_OK
        np.testing.assert_allclose(c, -d[:3], rtol=1e-9, atol=1e-12)
        assert np.linalg.norm(c) > 1e-4  # a real, sub-millimetre deflection


def test_weight_and_tare_removed_in_any_orientation(cell, poses):
    sensor = SensorSetup(
        SENSOR_POSE,
        tare=np.array([10.0, 0, -4, 0, 0.3, 0]),
        tool_mass=4.0,
        tool_cog=np.array([0.0, 0.01, 0.1]),
    )
    oc = OnlineCompensator.from_cell(cell, sensor, Limits(deadband=0.0))
    for q in poses:
        q = q + np.radians([0, 5, -10, 40, 30, 70])  # tilt the tool: the weight turns
        oc.reset()
        oc.set_joints(q)
        oc.sample(0.0, _sensor_reading(cell, q, np.zeros(6), sensor))
        np.testing.assert_allclose(oc.filtered, 0.0, atol=1e-10)


def test_low_pass_step_response_is_exact(cell, poses):
    fc = 15.0
    oc = OnlineCompensator.from_cell(cell, SensorSetup(cutoff=fc))
    oc.set_joints(poses[0])
    oc.sample(0.0, np.zeros(6))
    step = np.array([0, 0, 100.0, 0, 0, 0])
    t = 0.0
    rng = np.random.default_rng(3)
    for _ in range(200):  # jittered sample times: the filter uses each Δt
        t += rng.uniform(0.5e-3, 1.5e-3)
        oc.sample(t, step)
    np.testing.assert_allclose(oc.filtered[2], 100 * (1 - math.exp(-2 * math.pi * fc * t)))
    assert not oc.sample(t, step)  # not later than the last: dropped
    assert not oc.sample(t + 1e-3, np.array([0, 0, np.nan, 0, 0, 0]))


def test_limits_hold_under_hostile_input(cell, poses):
    lim = Limits(
        deadband=20e-6,
        max_correction=0.3e-3,
        max_rate=10e-3,
        cycle=4e-3,
        watchdog=0.02,
        ramp_rate=2e-3,
    )
    oc = OnlineCompensator.from_cell(cell, limits=lim)
    rng = np.random.default_rng(4)
    prev = np.zeros(3)
    t = 0.0
    seen = 0
    for k in range(3000):
        t += 4e-3
        phase = (k // 300) % 4
        if phase != 3:  # phase 3: the sensor stops
            for _ in range(4):
                W = rng.normal(0, 3000 if phase == 1 else 50, 6)
                if rng.random() < 0.01:
                    W[rng.integers(6)] = np.inf
                oc.sample(t + rng.uniform(-4e-3, 0), W)
        q = poses[k % len(poses)].copy()
        if rng.random() < 0.01:
            q[2] = np.nan
        c = oc.cycle(t, q).copy()
        seen |= oc.status
        assert np.all(np.isfinite(c))
        assert np.linalg.norm(c) <= lim.max_correction
        assert np.linalg.norm(c - prev) <= lim.max_rate * lim.cycle * (1 + 1e-9)
        prev = c
    for bit in (kn.STATUS_LIMITED, kn.STATUS_HOLD, kn.STATUS_RAMP, kn.STATUS_BAD_INPUT):
        assert seen & bit, bit


def test_watchdog_holds_then_ramps_to_zero(cell, poses):
    lim = Limits(max_rate=1.0, watchdog=0.05, ramp_rate=5e-3, cycle=4e-3)
    oc = OnlineCompensator.from_cell(cell, limits=lim)
    q = poses[0]
    oc.set_joints(q)
    oc.sample(0.0, np.array([0, 0, 400.0, 0, 0, 0]))
    c0 = oc.cycle(0.004, q).copy()
    assert np.linalg.norm(c0) > 1e-4
    t = 0.004
    while t < 0.096 - 1e-9:  # hold: no sample for ≤ 2 × watchdog (0.1 s)
        t += 0.004
        np.testing.assert_array_equal(oc.cycle(t, q), c0)
    n = np.linalg.norm(c0)
    steps = 0
    while np.linalg.norm(oc.correction) > 0:
        t += 0.004
        before = np.linalg.norm(oc.correction)
        oc.cycle(t, q)
        assert oc.status & kn.STATUS_RAMP
        assert before - np.linalg.norm(oc.correction) <= 5e-3 * 4e-3 * (1 + 1e-9)
        steps += 1
    assert steps == math.ceil(n / (5e-3 * 4e-3) - 1e-9)


def test_dead_band_sends_zero(cell, poses):
    oc = OnlineCompensator.from_cell(cell, limits=Limits(deadband=50e-6))
    oc.set_joints(poses[0])
    oc.sample(0.0, np.array([0, 0, 5.0, 0, 0, 0]))  # 5 N: a few µm
    np.testing.assert_array_equal(oc.cycle(0.004, poses[0]), 0.0)
    assert oc.status & kn.STATUS_DEADBAND


def test_per_sample_work_allocates_nothing(cell, poses):
    oc = OnlineCompensator.from_cell(cell)
    W = np.array([10, 20, 300.0, 0.1, 0.2, 0.3])
    q = poses[0]
    oc.warm_up()
    for i in range(50):
        oc.sample(i * 1e-3, W)
        oc.cycle(i * 1e-3, q)
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    for i in range(50, 5050):
        oc.sample(i * 1e-3, W)
        oc.cycle(i * 1e-3, q)
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    assert grown < 2048  # nothing that scales with the samples (5000 of them)


def test_bad_settings_are_input_errors(cell):
    with pytest.raises(InputError, match="max_correction"):
        Limits(max_correction=-1)
    with pytest.raises(InputError, match="cutoff"):
        SensorSetup(cutoff=0)
    with pytest.raises(InputError, match="load_on"):
        SensorSetup(load_on="sheet")


@pytest.mark.skipif(not kn.COMPILED, reason="numba not installed: only the Python form exists")
def test_python_fallback_gives_the_compiled_numbers(cell, poses):
    """Without numba the kernels run as plain Python: same code, same numbers."""
    oc = OnlineCompensator.from_cell(cell, SensorSetup(SENSOR_POSE, tool_mass=2.0))
    W = np.array([30.0, -20.0, 350.0, 0.3, -0.1, 0.05])
    oc.set_joints(poses[1])
    oc.sample(0.0, W)
    oc.sample(1e-3, 0.5 * W)
    args = (
        oc._F,
        oc._sign,
        oc._offset,
        oc._c23,
        oc._kinv,
        oc._X_ts,
        oc._k_tip_base,
        oc._R_bw,
        oc._lim,
        4e-3,
        poses[1].copy(),
    )
    outs = []
    for fn in (kn.cycle_kernel, kn.cycle_kernel.py_func):
        st, y = oc.st.copy(), oc.filtered.copy()
        corr, Wt, d, scr = np.zeros(3), np.zeros(6), np.zeros(6), np.zeros((20, 6))
        status = fn(*args, st, y, corr, Wt, d, scr)
        outs.append((status, corr, Wt, d))
    assert outs[0][0] == outs[1][0]
    for a, b in zip(outs[0][1:], outs[1][1:], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-18)


def _fk_deflection_vs_model(name, fk_deflection, n=8):
    """The online per-pose kernel against RobotModel (numpy engine: an independent Jacobian
    with its own J2/J3 coupling) at random configurations; returns the worst relative errors."""
    from roboisf.robot import load_robot

    robot = load_robot(name).with_stiffness(np.linspace(4e6, 4e5, 6))
    F = robot.chain.F.copy()
    F[6] = F[6] @ robot.T_flange_tip
    sign = np.ascontiguousarray(robot.chain.sign, dtype=float)
    offset = np.ascontiguousarray(robot.chain.offset, dtype=float)
    kinv = 1.0 / robot.joint_stiffness
    rng = np.random.default_rng(11)
    q = rng.uniform(-1.5, 1.5, (n, 6))
    W = np.column_stack([rng.normal(0, 400, (n, 3)), rng.normal(0, 30, (n, 3))])
    d_ref = robot.deflection(q, W, check_limits=False, backend="numpy")
    R_ref = robot.fk(q, check_limits=False)[:, :3, :3]
    err_d = err_R = 0.0
    for i in range(n):
        d, R, scr = np.zeros(6), np.zeros((3, 3)), np.zeros((20, 6))
        fk_deflection(F, sign, offset, float(robot.chain.couple23), kinv, q[i], W[i], d, R, scr)
        err_d = max(err_d, float(np.max(np.abs(d - d_ref[i])) / np.max(np.abs(d_ref[i]))))
        err_R = max(err_R, float(np.max(np.abs(R - R_ref[i]))))
    return robot.chain.couple23, err_d, err_R


@pytest.mark.parametrize("name", ["r2000ic-210f", "m900ib-700", "irb6700-200-2.60"])
def test_fk_deflection_equals_the_model_on_fanuc_and_abb(name, monkeypatch):
    """FANUC presets carry the J2/J3 coupling (c23 = 1): the online kernel must walk the same
    chain as the batch kernel, compiled and as plain Python."""
    from roboisf.robot import vjm_chain

    c23, err_d, err_R = _fk_deflection_vs_model(name, kn.fk_deflection)
    assert (c23 != 0.0) == name.startswith(("r2000", "m900"))
    assert err_d < 1e-12 and err_R < 1e-13
    if kn.COMPILED:  # the same code as plain Python, all the way down
        monkeypatch.setattr(vjm_chain, "sincos", vjm_chain.sincos.py_func)
        monkeypatch.setattr(vjm_chain, "chain_walk", vjm_chain.chain_walk.py_func)
        monkeypatch.setattr(vjm_chain, "tip_jacobian", vjm_chain.tip_jacobian.py_func)
        monkeypatch.setattr(kn, "chain_jacobian", vjm_chain.chain_jacobian.py_func)
        _, err_d, err_R = _fk_deflection_vs_model(name, kn.fk_deflection.py_func)
        assert err_d < 1e-12 and err_R < 1e-13


def test_online_kernel_runs_without_numba():
    """numba blocked in a fresh interpreter: the kernels are plain Python and give the model's
    deflection on a FANUC preset."""
    import os
    import pathlib
    import subprocess
    import sys

    import roboisf

    root = pathlib.Path(__file__).resolve().parents[1]  # `tests` importable from here
    src = str(pathlib.Path(roboisf.__file__).resolve().parents[1])  # this roboisf, not another
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, str(root)])}
    code = (
        "import sys; sys.modules['numba'] = None\n"
        "from roboisf.online import kernel as kn\n"
        "assert not kn.COMPILED\n"
        "import tests.test_online_core as t\n"
        "c23, e, r = t._fk_deflection_vs_model('r2000ic-210f', kn.fk_deflection, n=4)\n"
        "assert 'numba' not in sys.modules or sys.modules['numba'] is None\n"
        "print(c23, e, r)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=root,
        env=env,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    c23, e, r = (float(v) for v in out.stdout.split())
    assert c23 == 1.0 and e < 1e-12 and r < 1e-13
