"""The online loop's kernels' C form (``online_kernel.c``: roboisf.online.kernel's sample_kernel,
cycle_kernel and fk_deflection with vjm_chain's walk) against their numba form, bit for bit, on
scripted runs of a compensator (ABB and FANUC presets), and the dispatch that runs them without
numba."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf import jit
from roboisf.frames import make_transform, rpy_to_matrix
from roboisf.online import Limits, OnlineCompensator, Plausibility, SensorSetup
from roboisf.online import kernel as kn
from roboisf.robot.model import RobotModel
from roboisf.robot.presets import load_robot

SRC = Path(__file__).resolve().parents[1] / "src"
pytestmark = pytest.mark.skipif(not jit.HAVE_NUMBA, reason="numba not installed: the oracle")

ABB, FANUC = "irb6700-200-2.60", "r2000ic-210f"  # FANUC: the J2/J3 coupling (c23 = 1)
TOOL = make_transform(np.eye(3), [0.01, -0.02, 0.3])  # a spindle's offset (m)
# the sensor pose and tool of tests/test_online_core.py
SENSOR_POSE = make_transform(rpy_to_matrix([0.02, -0.03, math.radians(30)]), [0.004, -0.002, 0.03])
TARE = np.array([3.0, -2.0, 5.0, 0.1, -0.2, 0.05])
Q0 = np.array([0.1, 0.45, 0.15, 0.05, 0.7, -0.1])  # rad: a forming pose in front of the robot


def _same(a: Any, b: Any) -> None:
    """Same shape, the same bits (-0.0 is not 0.0; a NaN equals a NaN of either sign: the sign
    of a NaN from an operation follows its operands' order, which LLVM may swap)."""
    same_bits(a, b, nan_sign=False)


def _robot(name: str) -> RobotModel:
    m = replace(load_robot(name), T_flange_tip=TOOL)
    return m if m.stiffness is not None else m.with_stiffness(np.linspace(4e6, 4e5, 6))


#: the limits of the runs: a size limit a large force reaches (0.4 mm)
LIMITS = Limits(deadband=5e-6, max_correction=0.4e-3, max_rate=20e-3, cycle=4e-3,
                watchdog=0.05, ramp_rate=5e-3)  # fmt: skip


def _compensator(
    name: str, sensor: SensorSetup, plaus: Plausibility, lim: Limits = LIMITS
) -> OnlineCompensator:
    """A compensator of preset ``name`` working 2.2 m in front of it; tool + holder compliance
    at the tip of a spindle (m/N, rad/(N·m)), slightly coupled."""
    k = np.diag([2e-7, 2e-7, 5e-8, 1e-6, 1e-6, 4e-7])
    k[0, 4] = k[4, 0] = 3e-7
    k[1, 3] = k[3, 1] = -3e-7
    T = make_transform(rpy_to_matrix([0.0, 0.0, 0.1]), [2.2, 0.05, 0.2])
    return OnlineCompensator(_robot(name), T, k, sensor, lim, plaus)


Record = tuple[Any, ...]


def _script(oc: OnlineCompensator, rec: Callable[..., None]) -> None:
    """A run of the loop as the controller and the sensor drive it, through every path of the
    kernels (tests/test_online_core.py checks what they mean): ``rec(result, label)`` after each
    event."""
    rng = np.random.default_rng(5)
    X_st = np.linalg.inv(oc._X_ts)  # tip → sensor (with the sign of load_on)
    m, cog, g = oc._grav[0], oc._grav[1:4], oc._grav[4:7]
    weights: dict[bytes, np.ndarray] = {}

    def q_at(t: float) -> np.ndarray:  # the joints drift as the tool moves along the path
        return Q0 + 0.05 * np.sin(np.array([0.7, 1.1, 1.3, 0.9, 1.7, 2.3]) * t)

    def weight() -> np.ndarray:
        """The tool's weight as the sensor reads it at the joints the kernel orients it by (an
        independent chain: RobotModel.fk)."""
        key = oc._q.tobytes()
        if not np.isfinite(oc._q).all():  # (the kernel's weight is NaN)
            return np.zeros(6)
        if key not in weights:
            T = oc.robot.fk(oc._q.copy(), check_limits=False)[0]
            f = m * (T[:3, :3] @ oc._R_tip_sensor).T @ g
            weights[key] = np.concatenate([f, np.cross(cog, f)])
        return weights[key]

    def forming(fz: float) -> np.ndarray:
        """The sensor's reading of a forming force at the tip (N; tip axes), noisy."""
        W_tip = np.array([0.1 * fz, -0.05 * fz, fz, 0.0, 0.0, 0.0])
        W_tip += np.concatenate([rng.normal(0, 2.0, 3), rng.normal(0, 0.02, 3)])
        return X_st @ W_tip + TARE + weight()

    def sample(t: float, W: np.ndarray, label: str = "") -> None:
        rec(oc.sample(t, W), label)

    def cycle(t: float, q: np.ndarray | None = None, label: str = "") -> None:
        rec(oc.cycle(t, q_at(t) if q is None else q).copy(), label)

    t = 0.0
    cycle(t, label="before any sample")
    oc.set_joints(q_at(t))
    sample(t, np.array([1.0, 2.0, np.nan, 0.0, 0.0, 0.0]), "NaN wrench")
    sample(math.nan, forming(10.0), "NaN time")
    # the force rises from 0 to 1.5 kN in 0.6 s: dead band, then rate-limited, then the size
    # limit; 1 kHz samples with jittered times, 4 ms cycles
    for k in range(200):
        for _ in range(4):
            t += 1e-3
            sample(t + rng.uniform(-2e-4, 2e-4), forming(1500.0 * min(1.0, k / 150) ** 2))
        cycle(t)
    sample(float(oc.st[kn.S_LAST_SAMPLE]), forming(1500.0), "not after the last")
    # implausible samples (the bounds of the plausibility given, if any): a jump of the force,
    # a spike, a moment at the tip; the cycles hold
    for label, dW in (
        ("jump", [0, 0, 1000.0, 0, 0, 0]),
        ("spike", [0, 0, 4500.0, 0, 0, 0]),
        ("moment", [0, 0, 0, 60.0, -40.0, 0]),
    ):
        for _ in range(4):
            t += 1e-3
            sample(t, forming(1500.0) + X_st @ dW, label)
        cycle(t)
    # one out of order: after the last taken, before the last implausible (whose time stays)
    sample(t - 2e-3, forming(1500.0) * 4.0, "out of order")
    # the force falls back (the correction follows, rate-limited)
    for k in range(60):
        for _ in range(4):
            t += 1e-3
            sample(t, forming(1500.0 * (1.0 - k / 80)))
        cycle(t)
    q = q_at(t).copy()
    q[3] = np.nan
    cycle(t + 4e-3, q, "NaN joints")
    cycle(math.nan, q_at(t), "NaN time")
    cycle(math.inf, q_at(t), "inf time")
    t += 4e-3
    cycle(t)
    cycle(t, label="not after the last")
    cycle(t - 1e-3, label="before the last")
    # the sensor goes quiet: hold for 50 ms, then ramp to zero; the controller's gaps too (a
    # step of at most two cycles' worth)
    for k in range(45):
        t += 4e-3 if k % 9 else 13e-3
        cycle(t)
    # it comes back with a force much above the filtered one, taken: the band has grown by the
    # rate bound times the quiet time
    for k in range(40):
        for _ in range(4):
            t += 1e-3
            sample(t, forming(1500.0), "back" if k == 0 else "")
        cycle(t)
    # hostile buffers: a filtered wrench that overflows (the correction's size is not finite:
    # held); a correction above the size limit (cut to just under it)
    y = oc.filtered.copy()
    oc.filtered[:] = [1e308, -1e308, 1e308, 1e308, 1e308, 1e308]
    t += 4e-3
    cycle(t, label="overflow")
    oc.filtered[:] = y
    oc.correction[:] = [3e-4, -3e-4, 2e-4]
    t += 4e-3
    cycle(t, np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0]), "above the size")
    # the stop: the correction ramps to zero at the ramp rate, whatever the force
    oc.begin_stop()
    for _ in range(30):
        for _ in range(4):
            t += 1e-3
            sample(t, forming(1500.0))
        cycle(t, label="stop")
    # a sample at non-finite joints (the compensator passes them on, the kernel does not check
    # them): a weighed tool's is taken as NaN, and the filter holds NaN from then on
    oc.reset()
    oc.set_joints(np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0]))
    sample(t, forming(500.0), "NaN joints")
    sample(t + 1e-3, forming(500.0))
    cycle(t + 2e-3, label="after NaN joints")


def _run(name: str, sensor: SensorSetup, plaus: Plausibility, lim: Limits) -> list[Record]:
    """The script's records: per event its label, its result, then the state vector, the
    filter, the correction, the tip wrench, the deflection and the whole scratch."""
    oc = _compensator(name, sensor, plaus, lim)
    oc.warm_up()
    out: list[Record] = []

    def rec(result: Any, label: str) -> None:
        out.append(
            (label, np.asarray(result), oc.st.copy(), oc.filtered.copy(), oc.correction.copy(),
             oc.tip_wrench.copy(), oc.deflection.copy(), oc._scr.copy())
        )  # fmt: skip

    _script(oc, rec)
    return out


SCENARIOS = {
    # a weighed tool, the sensor's load on the tool; the bounds of a 1.5 kN study
    "abb-tool": (
        ABB,
        SensorSetup(SENSOR_POSE, tare=TARE, tool_mass=2.5, tool_cog=np.array([0.001, 0.0, 0.08])),
        Plausibility.from_expected(1500.0, tool_length=0.01),
        LIMITS,
    ),
    # the sensor under the workpiece (the opposite sign), a heavier tool; no bounds
    "fanuc-workpiece": (
        FANUC,
        SensorSetup(
            SENSOR_POSE,
            load_on="workpiece",
            tare=TARE,
            tool_mass=4.0,
            tool_cog=np.array([0.0, 0.01, 0.1]),
            cutoff=35.0,
        ),
        Plausibility(),
        LIMITS,
    ),
    # a tool without mass (no weight to orient: the chain is not walked for a sample); only the
    # magnitude and the moment bounded; a ramp faster than the rate limit (the rate limit is
    # the ramps' then)
    "fanuc-massless": (
        FANUC,
        SensorSetup(SENSOR_POSE, tare=TARE),
        Plausibility(max_force=2500.0, max_tip_moment=30.0),
        replace(LIMITS, max_rate=3e-3, ramp_rate=8e-3),
    ),
}


def test_the_c_form_is_built_and_serves() -> None:
    c_library(kn)
    assert kn.COMPILED and kn._C_FORM
    assert kn.sample_kernel is kn._c_sample_kernel and kn.cycle_kernel is kn._c_cycle_kernel
    assert kn.fk_deflection is kn._c_fk_deflection
    assert kn.NATIVE.endswith("_kernel")  # setup.py builds only "*_kernel.c"
    assert (SRC / "roboisf" / "online" / "online_kernel.c").is_file()
    assert jit.ready("online")  # from the C form: no numba
    # as a numba kernel, each has its Python function (tests/test_online_core.py uses them)
    assert kn.cycle_kernel.py_func is kn._cycle_kernel.py_func  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def runs() -> dict[str, tuple[list[Record], list[Record]]]:
    """Every scenario run in C and in numba (fresh compensators, the same script)."""
    c_library(kn)
    out = {}
    for key, args in SCENARIOS.items():
        c = _run(*args)
        with numba_form(kn.NATIVE):
            assert kn._c() is None
            nb = _run(*args)
        out[key] = (c, nb)
    return out


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_the_loop_in_c_equals_numba_bit_for_bit(key: str, runs: Any) -> None:
    c, nb = runs[key]
    assert len(c) == len(nb) > 1000
    for i, (a, b) in enumerate(zip(c, nb, strict=True)):
        assert a[0] == b[0]
        try:
            _same(a[1:], b[1:])
        except AssertionError as e:
            raise AssertionError(f"{key}: event {i} ({a[0] or 'plain'}) differs") from e


def _labelled(c: list[Record], label: str) -> list[Record]:
    out = [r for r in c if r[0] == label]
    assert out, label
    return out


def test_the_scripts_take_every_path(runs: Any) -> None:
    """What the runs compared went through: every status bit, every reason to drop a sample,
    the size limit cut at the end of a cycle, a NaN filter; else a wrong C port of a branch
    could pass unseen."""
    seen = {}
    for key, (c, _) in runs.items():
        status = [int(r[2][kn.S_STATUS]) for r in c if r[1].dtype != bool]
        assert kn.STATUS_OK in status, key
        seen[key] = int(np.bitwise_or.reduce(status))
        taken = [bool(r[1]) for r in c if r[1].dtype == bool]
        assert sum(taken) > 1000 and not all(taken)
        for label in ("NaN wrench", "NaN time", "not after the last"):
            assert not any(r[1] for r in _labelled(c, label) if r[1].dtype == bool), label
        bounded = key != "fanuc-workpiece"
        for label in ("jump", "spike", "moment"):  # each its own bound; none without bounds
            assert all(r[1] for r in _labelled(c, label)) != bounded, (key, label)
        assert (max(r[2][kn.S_BAD] for r in c) > 0) == bounded
        i = next(i for i, r in enumerate(c) if r[0] == "out of order")
        if bounded:  # rejected, counted; the time of the last implausible sample stays
            assert not c[i][1] and c[i][2][kn.S_BAD] == c[i - 1][2][kn.S_BAD] + 1
            assert c[i][2][kn.S_LAST_BAD] == c[i - 1][2][kn.S_LAST_BAD]
        assert all(r[1] for r in _labelled(c, "back")), key
        assert (seen[key] & kn.STATUS_IMPLAUSIBLE != 0) == bounded
        for label in ("NaN joints", "NaN time", "inf time", "overflow"):
            cycles = [r for r in _labelled(c, label) if r[1].dtype != bool]
            assert all(int(r[2][kn.S_STATUS]) & kn.STATUS_BAD_INPUT for r in cycles), (key, label)
        n = np.linalg.norm(_labelled(c, "above the size")[0][1])
        assert 0.4e-3 * (1 - 2e-12) < n < 0.4e-3, (key, n)  # cut, at the end of the cycle
        # the tool's weight walked the chain for a sample (scratch rows 0-12), or not (massless)
        weighed = key != "fanuc-massless"
        assert np.isnan(c[-1][3]).any() == weighed, key  # a NaN filter, from the NaN joints
        first = next(i for i, r in enumerate(c) if r[1].dtype == bool and r[1])
        walked = (c[first][7][:13] != c[first - 1][7][:13]).any()
        assert walked == weighed, key
    assert np.bitwise_or.reduce(list(seen.values())) == sum(kn.STATUS_NAMES), seen
    assert seen["fanuc-workpiece"] & seen["abb-tool"] & kn.STATUS_DEADBAND


# ---- fk_deflection on its own ------------------------------------------------------------


@pytest.mark.parametrize("name", [ABB, FANUC])
def test_fk_deflection_c_equals_numba(name: str) -> None:
    """Random poses within the limits and process wrenches; the layouts the kernels call it
    with: W and d one array (the weight's pass), R a (3, 3) array; joints far out (libm's
    sin/cos past 1e5 rad), NaN."""
    c_library(kn)
    m = _robot(name)
    F = m.chain.F.copy()
    F[6] = F[6] @ m.T_flange_tip
    sign = np.ascontiguousarray(m.chain.sign, dtype=float)
    offset = np.ascontiguousarray(m.chain.offset, dtype=float)
    kinv = np.ascontiguousarray(1.0 / m.joint_stiffness)
    c23 = float(m.chain.couple23)
    assert (c23 != 0.0) == (name == FANUC)
    rng = np.random.default_rng(9)
    q = rng.uniform(m.q_min, m.q_max, (64, 6))
    q[60, 4] = 2e5  # past the reduction's range
    q[61, 0] = -3.5e5
    q[62, 2] = np.nan
    q[63, 1] = np.inf
    W = np.column_stack([rng.normal(0, 400, (64, 3)), rng.normal(0, 30, (64, 3))])

    def run() -> tuple[np.ndarray, ...]:
        d, R, scr = np.zeros((64, 6)), np.zeros((64, 3, 3)), np.zeros((64, 20, 6))
        same = W.copy()  # W and d one array: d overwrites W
        for n in range(64):
            kn.fk_deflection(F, sign, offset, c23, kinv, q[n], W[n], d[n], R[n], scr[n])
            r, s = np.zeros((3, 3)), np.zeros((20, 6))
            kn.fk_deflection(F, sign, offset, c23, kinv, q[n], same[n], same[n], r, s)
        return d, R, scr, same

    c = run()
    with numba_form(kn.NATIVE):
        nb = run()
    _same(c, nb)
    assert np.isfinite(c[0][:60]).all() and np.isnan(c[0][62]).all()
    assert not np.array_equal(c[3][:60], W[:60])  # overwritten


def test_arrays_c_cannot_take_go_to_numba() -> None:
    """An array of another dtype, layout or shape than the C form's (numba takes them all): that
    call runs the numba kernel, whose numbers these are; the arrays of a call are checked once,
    their addresses kept for the calls after (a bounded number of sets)."""
    c_library(kn)
    oc = _compensator(ABB, SensorSetup(SENSOR_POSE, tool_mass=2.0), Plausibility())
    oc.set_joints(Q0)
    W = np.array([30.0, -20.0, 350.0, 0.3, -0.1, 0.05])
    assert oc.sample(0.0, W) and oc.sample(1e-3, 0.5 * W)
    inputs = {"F": oc._F, "sign": oc._sign, "offset": oc._offset, "c23": oc._c23,
              "kinv": oc._kinv, "X_ts": oc._X_ts, "k_tip": oc._k_tip_base,
              "R_base_work": oc._R_bw, "lim": oc._lim, "t": 0.004, "q": Q0.copy()}  # fmt: skip

    def cycle(inputs: dict[str, Any]) -> tuple[Any, ...]:
        st, y = oc.st.copy(), oc.filtered.copy()
        corr, Wt, d, scr = np.zeros(3), np.zeros(6), np.zeros(6), np.zeros((20, 6))
        status = kn.cycle_kernel(*inputs.values(), st, y, corr, Wt, d, scr)
        return np.int64(status), st, y, corr, Wt, d, scr

    def arrays(inputs: dict[str, Any]) -> tuple[Any, ...]:  # _CYCLE's
        a = [v for k, v in inputs.items() if k not in ("c23", "t")]
        return (*a, oc.st, oc.filtered, oc.correction, oc.tip_wrench, oc.deflection, oc._scr)

    want = cycle(inputs)
    assert kn._CYCLE.address(arrays(inputs)) is not None
    with numba_form(kn.NATIVE):
        _same(cycle(inputs), want)
    odd = {
        "R_base_work": np.asfortranarray(oc._R_bw),  # not C-contiguous
        "lim": (oc._lim * 1e3).astype(np.int64),  # Limits of ints: an int64 array
        "q": np.column_stack([Q0, Q0])[:, 0],  # a column: strided
        "X_ts": np.vstack([oc._X_ts, np.zeros(6)]),  # (7, 6)
    }
    for key, a in odd.items():
        bent = {**inputs, key: a}
        assert kn._CYCLE.address(arrays(bent)) is None, key
        got = cycle(bent)
        with numba_form(kn.NATIVE):
            _same(got, cycle(bent))
        if key != "lim":
            _same(got, want)
    # one set of arrays: one block, kept; new sets: new blocks, at most _KEEP of them
    a = arrays(inputs)
    first = kn._CYCLE.address(a)
    assert first is not None and kn._CYCLE.address(a) == first
    kept = [first]
    for _ in range(kn._KEEP - 1):  # (an evicted set's block is freed: its address reused)
        kept.append(kn._CYCLE.address((*a[:-1], np.zeros((20, 6)))))
    assert None not in kept and len(set(kept)) == kn._KEEP
    for _ in range(kn._KEEP):
        assert kn._CYCLE.address((*a[:-1], np.zeros((20, 6)))) is not None
    assert len(kn._CYCLE._known) == kn._KEEP
    ro = oc.st.copy()
    ro.flags.writeable = False
    assert kn._CYCLE.address((*a[:9], ro, *a[10:])) is None  # the kernel writes it


# ---- no numba ----------------------------------------------------------------------------


def _run_py(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    e = {**os.environ, "PYTHONPATH": str(SRC), **env}
    e.pop("ROBOISF_NATIVE", None)
    return subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True)


@pytest.mark.parametrize("numba_env", ["1", "0"])
def test_the_loop_runs_in_c_without_importing_numba(numba_env: str) -> None:
    """A compensator's samples and cycles with the C form: numba is not imported (nor, with
    ROBOISF_NUMBA=0, there at all); the group is ready without a builder."""
    c_library(kn)
    r = _run_py(
        "import sys\n"
        "from roboisf.jit import background as bg\n"
        "bg._start = lambda: sys.exit('a builder was started')\n"
        "import numpy as np\n"
        "from roboisf.online import kernel as kn\n"
        "from roboisf.online import OnlineCompensator, SensorSetup\n"
        "from roboisf.robot.presets import load_robot\n"
        "assert kn.COMPILED and kn._c() is not None\n"
        "m = load_robot('r2000ic-210f').with_stiffness(np.linspace(4e6, 4e5, 6))\n"
        "oc = OnlineCompensator(m, np.eye(4), np.eye(6) * 1e-7, SensorSetup(tool_mass=2.0))\n"
        "oc.warm_up()\n"
        "oc.set_joints(np.full(6, 0.3))\n"
        "for i in range(40):\n"
        "    oc.sample(i * 1e-3, np.array([0, 0, 300.0, 0, 0, 0]))\n"
        "    oc.cycle(i * 1e-3, np.full(6, 0.3))\n"
        "assert oc.status == kn.STATUS_OK and np.linalg.norm(oc.correction) > 5e-5\n"
        "from roboisf import jit\n"
        "assert jit.ready('online')\n"
        "assert 'numba' not in sys.modules\n"
        "print('ok')\n",
        ROBOISF_NUMBA=numba_env,
        ROBOISF_BACKGROUND_COMPILE="1",
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]
