"""Robot elastostatics throughput: FK + Jacobian + δ (and k_c) for 2,000,000 configurations.

Run by hand:  PYTHONPATH=src python benchmarks/robot_throughput.py [--n 2000000]

``RobotModel.deflection`` (what users and ``roboisf.plan`` call) on every engine — the fused
kernel's C form (``robot/vjm_kernel.c``, :mod:`roboisf.jit.native`) and its numba form
(:mod:`roboisf.robot.vjm_numba`), and the chunked numpy fallback — and
``RobotModel.compliance``, side by side with a per-pose pinocchio loop doing the same work (FK,
frame Jacobian, δ = J K⁻¹ Jᵀ W) IN THE SAME RUN; the loop is timed on a subset and extrapolated
(said in the printout). Also the kernel's cold compile / cache load, IK along a 100,000-point
toolpath on both IK engines against py-opw-kinematics in the same run (``--ik-only``: just
that), and the peak memory.
Targets (issue #16, 2 idle cores): deflection ≥ 3 M poses/s and ≥ 20× the pinocchio loop.
On a shared machine the wall-clock figures are contended: the CPU-time ratios are printed too.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from roboisf.frames import make_transform
from roboisf.jit import native
from roboisf.robot import ik_toolpath, load_robot, to_urdf, vjm_kernel


def _pin_loop(pin, pm, pd, fid, q, W, kinv, out):  # type: ignore[no-untyped-def]
    """Per pose: FK, frame Jacobian (tip, base axes), δ = J K⁻¹ Jᵀ W."""
    for i in range(q.shape[0]):
        pin.forwardKinematics(pm, pd, q[i])
        pin.updateFramePlacements(pm, pd)
        J = pin.computeFrameJacobian(pm, pd, q[i], fid, pin.LOCAL_WORLD_ALIGNED)
        out[i] = J @ (kinv * (J.T @ W[i]))


def _best(f, repeat):  # type: ignore[no-untyped-def]
    """Best wall and CPU time of ``repeat`` calls (the machine may be shared)."""
    t_best = c_best = np.inf
    out = None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = f()
        t_best = min(t_best, time.perf_counter() - t0)
        c_best = min(c_best, time.process_time() - c0)
    return t_best, c_best, out


def _ik_section(m, repeat):  # type: ignore[no-untyped-def]
    """IK along a 100,000-point cone toolpath: both engines, and py-opw-kinematics (the peer:
    its batch IK with the closest-to-previous branch choice) on the same flange poses."""
    from roboisf.frames import invert
    from roboisf.parts import Cone
    from roboisf.robot import tool_poses
    from roboisf.toolpath import step_down

    tp = step_down(Cone(), spacing=0.3e-3)
    tip = np.resize(tp.tip, (100_000, 3))
    n = len(tip)
    print(f"IK along a {n:,}-point toolpath (load {os.getloadavg()[0]:.1f}: contended if > ~0.5)")
    engines = ["numba", "numpy"] if vjm_kernel.HAVE_NUMBA else ["numpy"]
    rate: dict[str, float] = {}
    cpu: dict[str, float] = {}
    q_ref = None
    for engine in engines:
        ik_toolpath(m, tip[:1000], backend=engine)  # compile / load the kernels
        t_no, c_no, r = _best(
            lambda e=engine: ik_toolpath(m, tip, singular_threshold=None, backend=e), repeat
        )
        t_ik, c_ik, rs = _best(lambda e=engine: ik_toolpath(m, tip, backend=e), repeat)
        rate[engine], cpu[engine] = n / t_no, n / c_no
        print(
            f"IK {engine}: {n / t_no:,.0f} points/s wall, {n / c_no:,.0f} per CPU-second "
            f"({c_no / n * 1e6:.2f} µs CPU/point); with the singularity check {t_ik:.3f} s "
            f"wall, {c_ik:.3f} s CPU (target ≤ 2 s); {int(rs.near_singular.sum())} flagged"
        )
        if q_ref is None:
            q_ref = r.q
        else:
            print(f"max |q_numba − q_{engine}| = {np.abs(q_ref - r.q).max():.1e} rad")
    try:
        from py_opw_kinematics import KinematicModel, Robot
        from scipy.spatial.transform import RigidTransform
    except ImportError:
        print("py-opw-kinematics not installed: no peer ratio")
        return
    g = m.opw
    s = m.chain.sign
    km = KinematicModel(
        a1=g.a1,
        a2=g.a2,
        b=g.b,
        c1=g.c1,
        c2=g.c2,
        c3=g.c3,
        c4=g.c4,
        offsets=tuple(float(x) for x in -m.chain.offset * s),
        flip_axes=tuple(bool(x < 0) for x in s),
    )
    robot = Robot(km, degrees=False)
    T_fl = tool_poses(tip, m.default_placement) @ invert(m.T_flange_tip)
    poses = RigidTransform.from_matrix(T_fl)
    start = tuple(float(x) for x in q_ref[0])  # type: ignore[index]
    t_p, c_p, q_p = _best(lambda: robot.batch_inverse(poses, current_joints=start), repeat)
    print(
        f"py-opw-kinematics batch_inverse: {n / t_p:,.0f} points/s wall, {n / c_p:,.0f} per "
        f"CPU-second; max |Δq| to roboisf (wrapped) "
        f"{np.abs(np.angle(np.exp(1j * (q_p - q_ref)))).max():.1e} rad"
    )
    for engine in engines:
        print(
            f"ratio IK {engine} / py-opw-kinematics = {rate[engine] * t_p / n:.1f}× wall-clock, "
            f"{cpu[engine] * c_p / n:.1f}× per CPU-second"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=2_000_000)
    ap.add_argument("--pin-subset", type=int, default=50_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--ik-only", action="store_true", help="Run only the IK section.")
    args = ap.parse_args()
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0.0, 0.0, 0.3]))
    if args.ik_only:
        _ik_section(m, args.repeat)
        return
    rng = np.random.default_rng(0)
    q = rng.uniform(m.q_min, m.q_max, (args.n, 6))
    W = rng.normal(size=(args.n, 6)) * [300, 300, 500, 10, 10, 10]
    n = args.n
    print(
        f"{n:,} poses, IRB 7600 + 300 mm tool; {os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.1f} (above ~0.5 the wall-clock figures are contended)"
    )

    rates: dict[str, float] = {}
    cpu_rates: dict[str, float] = {}
    d_ref = None
    # the compiled path's two forms: C (roboisf.jit.native, what runs when it is built) and
    # numba (its fallback, the C forms suspended); both through backend="numba" ("compiled")
    engines = (["C"] if vjm_kernel._c() is not None else []) + (
        ["numba", "numpy"] if vjm_kernel.HAVE_NUMBA else ["numpy"]
    )

    def run(engine: str, qq: np.ndarray, ww: np.ndarray) -> np.ndarray:
        if engine == "numba":
            with native.suspended():
                return m.deflection(qq, ww, backend="numba")
        return m.deflection(qq, ww, backend="numpy" if engine == "numpy" else "numba")

    for engine in engines:
        t0 = time.perf_counter()
        run(engine, q[:1000], W[:1000])
        if engine in ("C", "numba"):
            print(
                f"{engine} kernel: first call {time.perf_counter() - t0:.2f} s "
                "(numba: its import and cache load, or a cold compile)"
            )
        t, c, d = _best(lambda e=engine: run(e, q, W), args.repeat)
        rates[engine], cpu_rates[engine] = n / t, n / c
        d_ref = d if d_ref is None else d_ref
        print(
            f"RobotModel.deflection [{engine:5s}]: {t:.3f} s = {n / t:,.0f} poses/s "
            f"(CPU {c:.3f} s; {n / c:,.0f} poses per CPU-second)"
        )
    assert d_ref is not None
    t, c, _ = _best(lambda: m.compliance(q), 1)
    print(f"RobotModel.compliance [auto ]: {t:.3f} s = {n / t:,.0f} poses/s (k_c (N, 6, 6) kept)")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS so far {peak_mb:.0f} MB (inputs {2 * q.nbytes / 1e6:.0f} MB)")

    try:
        import pinocchio as pin
    except ImportError:
        print("pinocchio not installed: no peer comparison")
        return
    with tempfile.TemporaryDirectory() as td:
        f = Path(td) / "r.urdf"
        f.write_text(to_urdf(m))
        pm = pin.buildModelFromUrdf(str(f))
    pd = pm.createData()
    fid = pm.getFrameId("tip")
    kinv = 1.0 / m.joint_stiffness
    ns = min(args.pin_subset, n)
    d_pin = np.empty((ns, 6))
    t_pin, c_pin, _ = _best(
        lambda: _pin_loop(pin, pm, pd, fid, q[:ns], W[:ns], kinv, d_pin), args.repeat
    )
    rate_pin, cpu_pin = ns / t_pin, ns / c_pin
    print(
        f"pinocchio loop: {ns:,} poses in {t_pin:.3f} s = {rate_pin:,.0f} poses/s "
        f"(timed on a subset; {n:,} poses extrapolated to {n / rate_pin:.1f} s)"
    )
    print(f"max |δ_roboisf − δ_pinocchio| = {np.abs(d_ref[:ns] - d_pin).max():.2e} (m, rad)")
    for engine in engines:
        print(
            f"ratio {engine} / pinocchio = {rates[engine] / rate_pin:.1f}× wall-clock, "
            f"{cpu_rates[engine] / cpu_pin:.1f}× per CPU-second"
        )
    best = "C" if "C" in rates else "numba"
    if best in rates:
        ok = rates[best] >= 3e6 and rates[best] / rate_pin >= 20
        print(
            f"targets (2 idle cores): ≥ 3,000,000 poses/s and ≥ 20× pinocchio: "
            f"{'met' if ok else 'not met in this run'}"
        )

    _ik_section(m, args.repeat)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {peak_mb:.0f} MB (target ≤ 2048 MB)")


if __name__ == "__main__":
    main()
