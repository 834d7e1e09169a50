"""Sensor conditioning (issue #13 item 4, #14 item 3): tare, gravity compensation of the tool
below a flange sensor, identification of its mass and CoG, and the untared-bias warning.

The logs are built here from a known process wrench, a known offset and a known tool weight
(``W_meas = W_process + b + W_g(R)``), and the conditioning must give back the process wrench.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames import rpy_to_matrix
from roboisf.sensor import (
    G_WORLD,
    Conditioning,
    ToolLoad,
    condition_wrench,
    gravity_wrench,
    identify_tool_load,
    unloaded_samples,
)

MASS, COG = 4.2, np.array([0.012, -0.008, 0.095])  # kg, m (sensor frame)
BIAS = np.array([30.0, -12.0, 8.0, 0.6, -0.4, 0.15])  # N, N·m


def _process(t):
    """1.5 s unloaded approach, then a forming wrench ramping to ~450 N with lap ripple."""
    on = np.clip((t - 1.5) / 2.0, 0.0, 1.0)
    F = (
        np.column_stack(
            [80 * np.sin(2 * np.pi * t / 3), 60 * np.cos(2 * np.pi * t / 3), -450 + 0 * t]
        )
        * on[:, None]
    )
    M = np.column_stack([0.02 * F[:, 1], -0.02 * F[:, 0], 0.0 * t])
    return np.hstack([F, M])


def _orientation(t):
    """A tool that tilts and turns during the run (5-axis path): R_world_sensor(t)."""
    rpy = np.column_stack([np.pi + 0.3 * np.sin(t / 2), 0.2 * np.cos(t / 3), 0.5 * t])
    return rpy_to_matrix(rpy)


def _log(seed=0, noise=0.5):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 12, 1e-3)
    R = _orientation(t)
    W = _process(t) + BIAS + gravity_wrench(R, MASS, COG)
    W[:, :3] += rng.normal(scale=noise, size=(t.size, 3))
    W[:, 3:] += rng.normal(scale=noise * 5e-3, size=(t.size, 3))
    return t, W, R


def test_gravity_wrench_is_the_weight_at_the_cog():
    # sensor axes = world axes: weight straight down, moment r × F by hand
    W = gravity_wrench(np.eye(3), 2.0, [0.1, 0.0, 0.0])
    np.testing.assert_allclose(W, [0, 0, -2 * 9.80665, 0, 2 * 9.80665 * 0.1, 0], atol=1e-12)
    # sensor upside down (tool hanging below a flange pointing down): weight along +z_sensor
    Rx = rpy_to_matrix([np.pi, 0, 0])
    np.testing.assert_allclose(gravity_wrench(Rx, 1.0, [0, 0, 0])[:3], [0, 0, 9.80665], atol=1e-12)


def test_bias_and_tool_weight_are_removed_back_to_the_truth():
    t, W, R = _log()
    cond = Conditioning(tare="auto", tool=ToolLoad(MASS, COG, np.zeros(6)))
    out, notes, info = condition_wrench(t, W, cond, R_world_sensor=R, file=Path("rob.csv"))
    assert not notes
    window = info["window"]
    assert window is not None and window[1] < 1.5  # the unloaded approach only
    err = out - _process(t)
    # the tare's own noise (σ/√n) and the approach's gravity change are all that remain
    assert np.abs(err[:, :3]).max() < 3.0  # 0.5 N noise, ±6σ
    np.testing.assert_allclose(err[:, :3].mean(axis=0), 0.0, atol=0.1)
    np.testing.assert_allclose(err[:, 3:].mean(axis=0), 0.0, atol=1e-3)
    np.testing.assert_allclose(info["offset"], BIAS, atol=0.15)


def test_tare_without_gravity_model_leaves_the_weight_change():
    # a tare alone removes the weight at the tare pose only: the rest of the tilt stays
    t, W, R = _log()
    out, _, _ = condition_wrench(t, W, Conditioning(tare="auto"), R_world_sensor=R)
    err = out - _process(t)
    assert np.abs(err[:, :3].mean(axis=0)).max() > 1.0


def test_stated_window_tare():
    t, W, R = _log()
    cond = Conditioning(tare=(0.1, 1.0), tool=ToolLoad(MASS, COG, np.zeros(6)))
    _, _, info = condition_wrench(t, W, cond, R_world_sensor=R)
    np.testing.assert_allclose(info["offset"], BIAS, atol=0.15)
    with pytest.raises(InputError, match=r"tare window \[20, 30\] s holds no sample"):
        condition_wrench(t, W, Conditioning(tare=(20.0, 30.0)))


def test_untared_bias_is_flagged_with_file_and_size():
    t, W, R = _log()
    W_nograv = W - gravity_wrench(R, MASS, COG)
    _, notes, _ = condition_wrench(t, W_nograv, Conditioning(), file=Path("robot_forces.csv"))
    assert len(notes) == 1
    assert "robot_forces.csv" in notes[0] and "not tared" in notes[0]
    size = float(notes[0].split("|F| = ")[1].split(" N")[0])
    assert size == pytest.approx(np.linalg.norm(BIAS[:3]), rel=0.02)
    # a clean sensor raises nothing
    clean = _process(t) + np.random.default_rng(1).normal(scale=0.5, size=(t.size, 6)) * [
        1,
        1,
        1,
        5e-3,
        5e-3,
        5e-3,
    ]
    assert condition_wrench(t, clean, Conditioning())[1] == []


def test_log_that_starts_loaded_has_no_unloaded_part():
    t, W, _ = _log()
    late = t > 4.0
    assert unloaded_samples(t[late], W[late]) is None
    _, notes, _ = condition_wrench(t[late], W[late], Conditioning(tare="auto"), file=Path("f.csv"))
    assert "found no unloaded approach" in notes[0]


def test_identify_tool_load_from_unloaded_poses():
    rng = np.random.default_rng(5)
    R = rpy_to_matrix(
        np.array(
            [
                [np.pi, 0, 0],
                [np.pi + 0.6, 0, 0.3],
                [np.pi, 0.7, 1.0],
                [2.5, -0.5, 2.0],
                [np.pi, 0, 1.5],
            ]
        )
    )
    W = gravity_wrench(R, MASS, COG) + BIAS + rng.normal(scale=1e-3, size=(5, 6))
    load = identify_tool_load(R, W)
    assert load.observable == "all"
    assert load.mass == pytest.approx(MASS, abs=1e-3)
    np.testing.assert_allclose(load.cog, COG, atol=1e-3)
    np.testing.assert_allclose(load.offset, BIAS, atol=5e-3)


def test_identification_states_what_is_not_observable():
    # turning only about the vertical never changes gₛ: mass and offset cannot be separated
    R1 = rpy_to_matrix(np.array([[np.pi, 0, a] for a in (0.0, 1.0, 2.0)]))
    W1 = gravity_wrench(R1, MASS, COG) + BIAS
    with pytest.raises(InputError, match="cannot be told from the sensor offset"):
        identify_tool_load(R1, W1)
    # two orientations: the CoG along the change of gₛ between them is not seen
    R2 = rpy_to_matrix(np.array([[np.pi + a, 0, 0] for a in (0.0, 0.5)]))
    load = identify_tool_load(R2, gravity_wrench(R2, MASS, COG) + BIAS)
    assert load.observable != "all"
    assert load.mass == pytest.approx(MASS, rel=1e-9)
    assert np.allclose(G_WORLD, [0, 0, -9.80665])


def test_study_conditioning_takes_the_sensor_orientation_from_the_joints():
    """condition_study_log: a flange sensor's tool weight follows R_base_tip(q) at the toolpath
    point each sample is matched to (time + time_offset); the approach takes the first point."""
    from types import SimpleNamespace

    from roboisf.frames import make_transform, vertical_tool
    from roboisf.logs.forcelog import ForceLog
    from roboisf.study.sensors import condition_study_log

    rate, offset = 100.0, 2.0
    t_tp = np.linspace(0.0, 10.0, 201)
    # a tool tilting up to 25° and back along the path (FK of the logged joints)
    tilt = 0.45 * np.sin(np.pi * t_tp / 10.0)
    R_base_tip = vertical_tool(0.0) @ rpy_to_matrix(np.column_stack([tilt, 0 * tilt, 0 * tilt]))
    T_tip_sensor = make_transform(rpy_to_matrix([np.pi, 0.0, 0.3]), [0.0, 0.0, -0.19])
    forces = SimpleNamespace(
        mount="flange",
        pose=T_tip_sensor,
        time_offset=offset,
        tool_mass=MASS,
        tool_cog=tuple(COG),
        tare="auto",
        file=Path("rob.csv"),
    )
    study = SimpleNamespace(robot=SimpleNamespace(T_base_work=np.eye(4)))
    run = SimpleNamespace(forces=forces)
    tp = SimpleNamespace(time=t_tp, depth=np.full_like(t_tp, 1e-3))  # forming from its start
    t_log = np.arange(0.0, offset + 10.0, 1.0 / rate)
    k = np.clip(np.searchsorted(t_tp + offset, t_log, side="right") - 1, 0, len(t_tp) - 1)
    R_sensor = R_base_tip[k] @ T_tip_sensor[:3, :3]
    process = _process(t_log)  # unloaded for the first 1.5 s
    W = process + BIAS + gravity_wrench(R_sensor, MASS, COG)
    log = ForceLog(t_log, W, "sensor")
    out, notes = condition_study_log(
        study, run, log, vertical_tool(0.0), tp=tp, R_base_tip=R_base_tip
    )
    assert not notes
    np.testing.assert_allclose(out.wrench, process, atol=1e-9)
    # the toolpath's vertical tool instead of the joints: the tilt's weight change stays
    off, _ = condition_study_log(study, run, log, vertical_tool(0.0))
    assert np.abs(off.wrench[:, :3] - process[:, :3]).max() > 5.0


def test_a_log_that_starts_forming_has_no_unloaded_approach():
    """A log whose first laps form at a steady 100 N (a part starting 0.8 mm below the sheet
    plane) looked unloaded until the force changed: "not tared … set tare = auto", and tare =
    "auto" subtracted the forming force. With the log time where the tool starts to form, the
    approach ends there; a real approach before it is still found and tared."""
    from roboisf.sensor import Conditioning, condition_wrench

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 20.0, 0.01)
    W = rng.normal(0, 0.2, (t.size, 6))
    W[:, 2] += 100.0 + np.where(t > 8.0, 400.0, 0.0)  # steady forming, then deeper laps
    none, auto = Conditioning("none", None), Conditioning("auto", None)
    _, notes, _ = condition_wrench(t, W, none)
    assert any("not tared" in n for n in notes)  # without the path: the forming start looks free
    _, notes, info = condition_wrench(t, W, none, load_start=0.0)
    assert not notes and info["window"] is None
    out, notes, _ = condition_wrench(t, W, auto, load_start=0.0)
    assert out is W and "found no unloaded approach" in notes[0]  # nothing subtracted
    W[t < 3.0, 2] -= 100.0  # a real approach in the air before the path, with a 0 N zero
    W[t < 3.0, 0] += 12.0  # … and a 12 N offset on x
    out, notes, info = condition_wrench(t, W, auto, load_start=3.0)
    assert not notes and info["window"][1] < 3.0
    assert np.mean(out[t < 3.0, 0]) == pytest.approx(0.0, abs=0.1)
