"""The robot term's fits share their per-lap column sums (``diagnose._LapSums``): the same bits
as summing each fit's normal equations on its own (``check.lap_normal_equations``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from roboisf.decompose import diagnose
from roboisf.decompose.check import lap_index, lap_normal_equations
from test_diagnosis_drift import _cone, _fit


def test_shared_sums_equal_each_fits_own_in_any_column_order():
    rng = np.random.default_rng(3)
    n, L = 900, 9
    inv, _ = lap_index(np.sort(rng.integers(0, L, n)))
    a, b, c = (rng.normal(size=n) * s for s in (1e-4, 3.0, 0.2))
    y, y2 = rng.normal(size=n), rng.normal(size=n)
    sums = diagnose._LapSums(inv, L)
    # the same columns in other orders and company, a column twice, another right-hand side
    for cols, rhs in (([a, b], y), ([b, a, c], y), ([c, a], y2), ([a, a, b], y)):
        X = np.column_stack(cols)
        scale = np.linalg.norm(X, axis=0)
        G, h = sums.normal_equations(cols, scale, rhs)
        G0, h0 = lap_normal_equations(X / scale, rhs, inv, L)
        assert np.array_equal(G, G0) and np.array_equal(h, h0)
    assert len(sums._sums) < 3 + 2 + 3 + 3 + 1 + 2 + 1 + 3 + 2  # some were shared


@pytest.mark.parametrize("case", ["clean", "drift and tilt"])
def test_the_robot_terms_fit_is_the_same_with_shared_sums(monkeypatch, case):
    c = _cone()
    x = c["Aj"].sum(axis=1)
    y = 1.2 * x + c["noise"]
    if case != "clean":  # the drift's and the tilt's columns: all four fits run
        y = y + (c["normal"][:, :2] @ np.array([0.3e-3, -0.1e-3])) * c["tau"]
    shared = _fit(c, y)
    counted: list[int] = []
    real = diagnose._LapSums.normal_equations

    def each_own(self, cols, scale, rhs):  # the plain path, and how many fits came here
        counted.append(len(cols))
        return lap_normal_equations(np.column_stack(cols) / scale, rhs, self.inv, self.L)

    monkeypatch.setattr(diagnose._LapSums, "normal_equations", each_own)
    own = _fit(c, y)
    monkeypatch.setattr(diagnose._LapSums, "normal_equations", real)
    assert len(counted) >= (8 if case != "clean" else 4)  # the fits went through the sums
    _same(shared, own, "fit")


def _same(u, v, where: str) -> None:
    """Every number of ``u`` and ``v`` equal to the last bit (NaN equal to NaN)."""
    if dataclasses.is_dataclass(u):
        for f in dataclasses.fields(u):
            _same(getattr(u, f.name), getattr(v, f.name), f"{where}.{f.name}")
    elif isinstance(u, np.ndarray) or isinstance(u, float):
        assert np.array_equal(u, v, equal_nan=True), where
    elif isinstance(u, (tuple, list)):
        assert len(u) == len(v), where
        for i, (a, b) in enumerate(zip(u, v, strict=True)):
            _same(a, b, f"{where}[{i}]")
    else:
        assert u == v, where
