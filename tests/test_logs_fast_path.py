"""The log steps of ``analyze`` (alignment, forces to the tip) on their compiled paths give the
previous path's results on a study (issue #16): the Python tracking loop, ``RobotModel.fk`` and
the numpy window sums / norms as the reference."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from roboisf.cell import cell_from_study
from roboisf.decompose import pipeline
from roboisf.jit import native
from roboisf.logs import forcelog
from roboisf.robot import vjm_kernel
from roboisf.study.spec import load_study
from roboisf.sync import position, position_kernel
from roboisf.sync.run import align_run

pytestmark = pytest.mark.skipif(not position_kernel.HAVE_NUMBA, reason="numba not installed")


def _log_steps(folder: Path) -> tuple[dict[str, Any], list[np.ndarray], list[str]]:
    """What ``analyze`` does with the logs, step by step (pipeline.analyze's first part)."""
    study = load_study(folder)
    cell = cell_from_study(study)
    cnc, rob = study.cnc, study.robot_run
    tp = pipeline.study_toolpath(study, cnc, cell.part)
    logs = {
        r.name: (
            pipeline.read_run_force_log(study, r),
            None if r.joints is None else pipeline.read_run_joint_log(r),
        )
        for r in (cnc, rob)
    }
    aligned = {r.name: align_run(cell, r, tp, *logs[r.name]) for r in (cnc, rob)}
    warnings: list[str] = []
    W = [
        pipeline.run_tip_wrench(
            study,
            r,
            tp,
            warnings=warnings,
            alignment=None if r.sync == "time" else aligned[r.name].forces,
            log=logs[r.name][0],
        )
        for r in (cnc, rob)
    ]
    return aligned, W, warnings


def test_log_steps_equal_previous_path(
    small_cone_study: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fast, W_fast, notes_fast = _log_steps(small_cone_study)
    assert any(a.joints is not None for a in fast.values())  # a position-aligned run
    monkeypatch.setattr(position, "_COMPILED_LOOP", False)  # the Python tracking loop
    monkeypatch.setattr(vjm_kernel, "HAVE_NUMBA", False)  # RobotModel.fk for the joint log
    monkeypatch.setattr(forcelog, "_KERNEL", False)  # numpy norms and running sums
    monkeypatch.setattr(native, "_suspended", 1)  # and no C form (roboisf.jit.native) at all
    ref, W_ref, notes_ref = _log_steps(small_cone_study)
    assert notes_fast == notes_ref
    for name, a in fast.items():
        b = ref[name]
        assert a.method == b.method
        for x, y in ((a.forces, b.forces), (a.joints, b.joints)):
            if x is None or y is None:
                assert x is None and y is None
                continue
            # FK differs by ≤ 1e-12 m (the compiled sincos): a passage time by ≤ 1 ulp here
            for f in ("point_time", "lo", "hi"):
                np.testing.assert_allclose(getattr(x, f), getattr(y, f), rtol=0, atol=1e-9)
            np.testing.assert_allclose(x.residual, y.residual, rtol=0, atol=1e-12)
            assert x.offset == pytest.approx(y.offset, abs=1e-9)
            assert x.clock_scale == pytest.approx(y.clock_scale, rel=1e-12)
            assert x.pauses == pytest.approx(y.pauses, abs=1e-9)
    for a, b in zip(W_fast, W_ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)  # N, N·m
