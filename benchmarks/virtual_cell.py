"""The virtual cell's force logs: synthesis CPU and bytes, against the previous path in one run.

Run by hand:  PYTHONPATH=src python benchmarks/virtual_cell.py

For the paper cone with the ``paper`` scenario (1 kHz over the whole forming time, ~2.3 M
samples per log, both sensors):

* synthesis — the sensors' frame change per sample (``roboisf.study.sensors.tip_to_sensor``,
  tall ``W @ A`` products; the previous path) vs :func:`roboisf.virtual.cell.sensor_wrench` (one
  wide (6, 6) product), on the same interpolated wrenches; the results agree to 1e-10;
* bytes — the Parquet log with continuous readings vs the sensors' counts (1/16 N, 1/1024 N·m,
  ``VirtualCell.force_resolution``), the same noise draw.

CPU time (``time.process_time``, all threads) and wall time, best of 3; ratios are what to read
on a shared machine (say "contended" with the load average printed).
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from roboisf.frames import vertical_tool
from roboisf.logs.forcelog import write_force_log
from roboisf.study.sensors import tip_to_sensor
from roboisf.study.spec import ForceSensorSpec
from roboisf.virtual.cell import (
    _force_log,
    _interp_columns,
    _log_times,
    paper_scenario_cell,
    sensor_wrench,
    simulate,
)


def best(fn, repeat=3):
    cpu = wall = math.inf
    out = None
    for _ in range(repeat):
        c, w = time.process_time(), time.perf_counter()
        out = fn()
        cpu, wall = min(cpu, time.process_time() - c), min(wall, time.perf_counter() - w)
    return cpu, wall, out


def main() -> None:
    print(f"load average {os.getloadavg()} (2 cores shared: contended unless ~0)")
    cell = paper_scenario_cell("cone")
    truth = simulate(cell)
    tp = truth.toolpath
    t = _log_times(tp, cell.force_rate)
    W = _interp_columns(t, tp.time, truth.wrench_cnc)
    tip = _interp_columns(t, tp.time, tp.tip)
    R = vertical_tool(cell.tool_rotation)
    sensors = {
        "fixture": ForceSensorSpec(
            Path("cnc_forces.parquet"), "fixture", cell.fixture_sensor_pose, "workpiece"
        ),
        "flange": ForceSensorSpec(
            Path("robot_forces.parquet"), "flange", cell.T_tip_sensor, "tool"
        ),
    }
    print(f"cone: {len(tp)} toolpath points, {t.size} log samples per sensor")
    for name, sensor in sensors.items():
        c0, w0, ref = best(lambda s=sensor: tip_to_sensor(np.array(W), s, np.array(tip), R))
        c1, w1, new = best(lambda s=sensor: sensor_wrench(np.array(W), s, tip, R))
        err = float(np.abs(new - ref).max())
        print(
            f"frame change {name:8s} tip_to_sensor {c0:6.3f} s CPU ({w0:6.3f} wall)   "
            f"sensor_wrench {c1:6.3f} s CPU ({w1:6.3f} wall)   ratio {c0 / c1:5.1f}x   "
            f"max diff {err:.1e}"
        )
    with tempfile.TemporaryDirectory() as d:
        sizes = {}
        for label, res in (("continuous", (0.0, 0.0)), ("counts", cell.force_resolution)):
            c = dataclasses.replace(cell, force_resolution=res)
            log = _force_log(c, tp, truth.wrench_cnc, sensors["fixture"], np.random.default_rng(0))
            f = Path(d) / f"{label}.parquet"
            cpu, wall, _ = best(lambda lg=log, f=f: write_force_log(lg, f))
            sizes[label] = f.stat().st_size
            print(
                f"parquet {label:10s} {sizes[label] / 1e6:6.1f} MB   write {cpu:5.2f} s CPU "
                f"({wall:5.2f} wall)"
            )
        print(f"bytes ratio continuous/counts {sizes['continuous'] / sizes['counts']:.2f}x")


if __name__ == "__main__":
    main()
