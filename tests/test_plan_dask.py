"""The Dask sweep gives exactly the serial scores (same code, same inputs)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.frames import make_transform, rpy_to_matrix
from roboisf.plan import placement_grid, plan_placements, problem_from_cell
from roboisf.robot import load_robot
from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, paper_cone_cell

FIELDS = (
    "status",
    "reason",
    "mean_abs",
    "max_abs",
    "mean_abs_normal",
    "mean_robot",
    "max_robot",
    "sigma_min",
    "max_joint_step",
)


def _same(a, b):
    assert a.order.tolist() == b.order.tolist()
    for x, y in zip(a.scores, b.scores, strict=True):
        for f in FIELDS:
            vx, vy = getattr(x, f), getattr(y, f)
            assert vx == vy or (isinstance(vx, float) and math.isnan(vx) and math.isnan(vy)), f
        if x.gamma is None:
            assert y.gamma is None
        else:
            assert np.array_equal(x.gamma, y.gamma)


@pytest.fixture(scope="module")
def problem():
    # an angled tool so that several tool rotations are really evaluated
    T_ft = make_transform(rpy_to_matrix([0.0, math.radians(30), 0.0]), [0.15, 0.0, 0.25])
    model = load_robot("irb7600-500-2.55").with_tool(T_ft)
    vc = paper_cone_cell(spacing=6e-3)
    return problem_from_cell(vc.cell, **vc.path_settings, model=model)[0]


def test_local_cluster_equals_serial(problem):
    # includes an unreachable candidate (6 m away)
    P = np.vstack(
        [placement_grid([1.4, 1.8], [0.0, 0.3], [0.4], [0.0, 0.5]), [[6.0, 0.0, 0.4, 0.0]]]
    )
    g = np.radians([0.0, 90.0, 180.0])
    serial = plan_placements(problem, P, g, baseline=PAPER_CELL_PLACEMENT, scheduler="serial")
    par = plan_placements(
        problem, P, g, baseline=PAPER_CELL_PLACEMENT, scheduler="local", n_workers=2, batch_size=3
    )
    _same(serial, par)
    assert par.scores[-1].status == "unreachable"


def test_existing_client_with_threads(problem):
    from dask.distributed import Client, LocalCluster

    P = placement_grid([1.4, 1.8], [0.0], [0.4, 0.8], [0.0])
    serial = plan_placements(problem, P, [0.0, 1.0], scheduler="serial")
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        par = plan_placements(problem, P, [0.0, 1.0], scheduler=client)
        assert client.status == "running"  # a client given by the caller stays open
    _same(serial, par)


def test_unreachable_scheduler_is_a_clear_error(problem):
    from roboisf.errors import InputError

    with pytest.raises(InputError, match="cannot reach the Dask scheduler"):
        plan_placements(problem, [[1.6, 0.0, 0.6, 0.0]], scheduler="tcp://127.0.0.1:1")
    # a misspelt scheduler (Dask's parser: "missing port number"), not a traceback
    with pytest.raises(InputError, match="expected 'threads', 'local' or a Dask") as e:
        plan_placements(problem, [[1.6, 0.0, 0.6, 0.0]], scheduler="thread")
    assert e.value.field == "--scheduler"


def test_threads_equal_serial(problem):
    # threads run the GIL-free serial kernels, the main thread the prange ones: same bits, in
    # placement order, including an unreachable candidate and several tool rotations
    P = np.vstack(
        [placement_grid([1.4, 1.8], [0.0, 0.3], [0.4], [0.0, 0.5]), [[6.0, 0.0, 0.4, 0.0]]]
    )
    g = np.radians([0.0, 90.0, 180.0])
    serial = plan_placements(problem, P, g, baseline=PAPER_CELL_PLACEMENT, scheduler="serial")
    for size in (1, 3, None):
        par = plan_placements(
            problem,
            P,
            g,
            baseline=PAPER_CELL_PLACEMENT,
            scheduler="threads",
            n_workers=2,
            batch_size=size,
        )
        _same(serial, par)
    assert par.scores[-1].status == "unreachable"


def test_auto_scheduler_is_threads_on_the_compiled_engine(problem):
    from dataclasses import replace

    from roboisf.plan.sweep import default_scheduler
    from roboisf.robot import vjm_kernel

    want = "threads" if vjm_kernel.use_numba("auto") else "local"
    assert default_scheduler(problem, cpus=8) == want
    # the numpy engine holds the GIL: Dask processes, but for two CPUs or fewer, where the
    # cluster's start costs more than the GIL (docs/speed.md)
    numpy_engine = replace(problem, model=problem.model.with_backend("numpy"))
    assert default_scheduler(numpy_engine, cpus=8) == "local"
    assert default_scheduler(numpy_engine, cpus=2) == "threads"
    assert default_scheduler(problem, cpus=2) == "threads"
    P = placement_grid([1.4, 1.8], [0.0], [0.4], [0.0])
    _same(
        plan_placements(problem, P, scheduler="serial"),
        plan_placements(problem, P, scheduler="auto", n_workers=2),
    )
