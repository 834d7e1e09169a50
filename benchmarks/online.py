"""Online compensation (issue #17): per-sample compute, UDP round trip, and the first part.

Targets: per-sample compute p99 ≤ 0.5 ms; end-to-end UDP round trip with the simulated
controller p99 ≤ 2 ms at 250 Hz (10 minutes: ``--minutes 10``), missed cycles counted; on the
virtual cell, ≥ 80 % of the compliance error removed on the first part and the online
correction within 5 µm of offline pre-deflection on the same forces.

Run by hand:  python benchmarks/online.py [--minutes 10] [--controller egm|rsi] [--part cone]
              [--cycles-per-point 1] [--skip-udp] [--skip-part]
              [--realtime PRIO] [--cpu N] [--sim-cpu N] [--mlock] [--no-quiet-gc]
              [--sim-processes 1|2] [--sim-realtime PRIO] [--spin MS]

A missed cycle is counted as EGM and RSI count it: the reply carrying the cycle's sequence
number has not arrived (the kernel's receive stamp) when the controller's next message is due;
the printout splits them into the loop's and the simulated controller's own (it sent too late).

The real-time settings go to the loop only (``--realtime``, ``--mlock``, ``--cpu``); the
simulated devices run at normal priority, on the CPUs other than the loop's when ``--cpu`` is
given (``--sim-cpu`` to choose; ``--sim-realtime`` gives them SCHED_FIFO too, the layout of the
session-4 runs). The simulated sensor and controller run in two processes (``--sim-processes 1``:
one process and thread), and the controller meets its cycle times absolutely (clock_nanosleep
to ``--spin`` ms before, then a busy-wait).

Timings on a shared machine are noisy: the UDP round trip measures the operating system's
scheduling as much as roboisf (a quiet machine with a core to spare for the loop is the fair
setting). The printout says how busy the machine was (load average) next to the numbers.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time

import numpy as np


def _pct(x: np.ndarray, scale: float = 1e3) -> str:
    p = np.percentile(x, [50, 99, 99.9]) * scale
    return f"p50 {p[0]:.3f}  p99 {p[1]:.3f}  p99.9 {p[2]:.3f}  max {x.max() * scale:.3f}"


def compute(setup, controller: str, n: int) -> np.ndarray:
    """Per cycle: 4 sensor samples + one cycle of the core; and with the codecs."""
    from roboisf.online import Limits, OnlineCompensator, egm, netft, rsi

    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, Limits(max_rate=1.0))
    oc.warm_up()
    adapter = egm.EgmAdapter() if controller == "egm" else rsi.RsiAdapter()
    k = np.arange(n) % len(setup.q)
    msgs = [
        egm.encode_robot(i, i * 4, setup.q[j], setup.planned[j])
        if controller == "egm"
        else rsi.encode_robot(i, setup.q[j])
        for i, j in enumerate(k[:2000])
    ]
    recs = [netft.encode_record(i, i, 0, setup.reading[j]) for i, j in enumerate(k[:2000])]
    core = np.empty(n)
    full = np.empty(n)
    pc = time.perf_counter
    for i in range(n):
        j = k[i]
        t = i * 4e-3
        W = setup.reading[j]
        q = setup.q[j]
        t0 = pc()
        oc.sample(t, W)
        oc.cycle(t + 1e-4, q)
        t1 = pc()
        (r,) = netft.decode_records(recs[i % 2000])
        oc.sample(t + 2e-4, r.wrench)
        st = adapter.decode(msgs[i % 2000])
        c = oc.cycle(t + 3e-4, st.q)
        adapter.encode(st, c)
        t2 = pc()
        core[i] = t1 - t0
        full[i] = t2 - t1
    return np.stack([core, full])


def udp(setup, controller: str, minutes: float, a):
    from roboisf.online import Limits, OnlineCompensator, egm, rsi
    from roboisf.online.loop import RULES_OFF, CycleLog, Loop
    from roboisf.online.rt import Realtime, other_cpus
    from roboisf.online.sim import Simulation

    n = int(minutes * 60 / 4e-3)
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, Limits())
    adapter = egm.EgmAdapter() if controller == "egm" else rsi.RsiAdapter()
    rt = Realtime(a.realtime, a.cpu, a.mlock)
    sim_cpus = (a.sim_cpu,) if a.sim_cpu is not None else other_cpus(a.cpu)
    sim_rt = (
        Realtime(a.sim_realtime, None, False, sim_cpus)
        if a.sim_realtime is not None or sim_cpus is not None
        else None
    )
    loop = Loop(
        oc,
        adapter,
        ("127.0.0.1", 0),
        ("127.0.0.1", 9),
        log=CycleLog(),
        realtime=rt,
        quiet_gc=not a.no_quiet_gc,
        **RULES_OFF,
    )
    step = max(1, len(setup.q) // n)
    # the controller's first message 1 s after it is up: the loop's own start (one garbage
    # collection, a fraction of a second on a busy machine) is over by then, as on a real cell,
    # where the loop listens before the robot starts EGM/RSI
    with Simulation(
        setup,
        controller,
        loop.listen[1],
        n_cycles=n,
        point_step=step,
        realtime=sim_rt,
        start_delay=1.0,
        processes=a.sim_processes,
        spin=a.spin * 1e-3,
    ) as sim:
        loop.ft.connect(("127.0.0.1", sim.sensor_port))

        def finish() -> None:
            sim.result()
            loop.stop()

        th = threading.Thread(target=finish, daemon=True)
        th.start()
        loop.run(duration=minutes * 60 + 60)
        th.join(30)
        res = sim.result(timeout=1)
    return res, loop


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--minutes", type=float, default=0.5, help="UDP run length (issue: 10)")
    ap.add_argument("--controller", choices=("egm", "rsi"), default="egm")
    ap.add_argument("--part", choices=("cone", "vwacf", "pyramid"), default="cone")
    ap.add_argument("--cycles-per-point", type=int, default=1)
    ap.add_argument("--samples", type=int, default=100_000, help="compute benchmark cycles")
    ap.add_argument("--skip-udp", action="store_true")
    ap.add_argument("--skip-part", action="store_true")
    ap.add_argument(
        "--realtime",
        type=int,
        default=None,
        metavar="PRIO",
        help="SCHED_FIFO priority for the loop and the simulated processes (needs CAP_SYS_NICE)",
    )
    ap.add_argument("--cpu", type=int, default=None, help="pin the loop to this CPU")
    ap.add_argument(
        "--sim-cpu",
        type=int,
        default=None,
        help="pin the simulated devices to this CPU (default: the CPUs other than --cpu's)",
    )
    ap.add_argument("--mlock", action="store_true", help="mlockall in the loop")
    ap.add_argument(
        "--sim-processes",
        type=int,
        choices=(1, 2),
        default=2,
        help="simulated sensor and controller in two processes (default) or one",
    )
    ap.add_argument(
        "--sim-realtime",
        type=int,
        default=None,
        metavar="PRIO",
        help="SCHED_FIFO for the simulated devices too (the session-4 layout)",
    )
    ap.add_argument(
        "--spin",
        type=float,
        default=0.3,
        metavar="MS",
        help="the simulated controller busy-waits this long before each send (ms)",
    )
    ap.add_argument(
        "--no-quiet-gc", action="store_true", help="leave the garbage collector automatic"
    )
    a = ap.parse_args(argv)

    from roboisf.online.rt import other_cpus
    from roboisf.online.sim import evaluate, form_online, virtual_setup
    from roboisf.virtual.cell import paper_cone_cell, paper_vwacf_cell, pyramid_cell

    makers = {"cone": paper_cone_cell, "vwacf": paper_vwacf_cell, "pyramid": pyramid_cell}
    print(
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (timings contended "
        "when the load exceeds the cores)"
    )
    setup = virtual_setup(makers[a.part](scan_points=1000))
    print(f"virtual cell {a.part}: {len(setup.q)} toolpath points")

    core, full = compute(setup, a.controller, a.samples)
    ok = np.percentile(core, 99) <= 0.5e-3
    print(
        f"per-sample compute, core (sample + cycle), ms: {_pct(core)}  "
        f"[target p99 ≤ 0.5 ms: {'met' if ok else 'NOT met'}]"
    )
    print(f"  with RDT decode + {a.controller} decode/encode, ms: {_pct(full)}")

    if not a.skip_udp:
        import resource

        cpu0 = time.process_time()
        wall0 = time.perf_counter()
        res, loop = udp(setup, a.controller, a.minutes, a)
        wall = time.perf_counter() - wall0
        cpu = time.process_time() - cpu0
        ch = resource.getrusage(resource.RUSAGE_CHILDREN)
        rtt = res["rtt"]
        got = np.isfinite(rtt)
        c = loop.counters
        comp = loop.log.data[:, 21] * 1e-6
        for w in loop.warnings + list(res.get("warnings", [])):
            print(f"warning: {w}")
        print(
            f"UDP at 250 Hz for {a.minutes:g} min ({len(rtt)} cycles; loop: realtime "
            f"{a.realtime or 'off'}, CPU {a.cpu}, mlock {'on' if a.mlock else 'off'}, quiet GC "
            f"{'off' if a.no_quiet_gc else 'on'}; simulated devices: {a.sim_processes} "
            f"process(es), realtime {a.sim_realtime or 'off'}, CPUs "
            f"{(a.sim_cpu,) if a.sim_cpu is not None else other_cpus(a.cpu) or 'any'}, spin "
            f"{a.spin:g} ms; load "
            f"average {os.getloadavg()[0]:.1f} at the end, contended): {c.samples} samples, "
            f"bad {c.bad_controller}/{c.bad_sensor}, late {c.late_sensor}; loop process CPU "
            f"{cpu:.1f} s in {wall:.1f} s wall, simulators' CPU {ch.ru_utime + ch.ru_stime:.1f} s"
        )
        print(
            "  missed cycle (as EGM/RSI count it): the reply with the cycle's sequence number "
            "had not arrived (kernel receive stamp"
            + ("" if res.get("stamped") else ": NOT available, read time used")
            + ") when the next cycle's message was due"
        )
        from roboisf.online.sim import missed_causes

        ran = int(res["ran"])
        mc = missed_causes(res)
        loop_missed = mc["loop_late"] + mc["loop_lost"]
        print(
            f"  missed: {mc['missed']} of {ran} ({mc['missed'] / max(ran, 1):.3%}) — the loop's "
            f"{loop_missed} ({mc['loop_late']} late, {mc['loop_lost']} never answered), the "
            f"simulated controller's own {mc['controller']} (it sent with < 2 ms of its cycle "
            f"left)  [issue: no missed cycle: {'met' if mc['missed'] == 0 else 'NOT met'}]"
        )
        if got.any():
            ok = np.percentile(rtt[got], 99) <= 2e-3
            print(
                f"  round trip, send → kernel arrival of the reply, ms: {_pct(rtt[got])}  "
                f"[target p99 ≤ 2 ms: {'met' if ok else 'NOT met'}]"
            )
            print(f"  loop compute per cycle (decode + core + encode + send), ms: {_pct(comp)}")
            lat = loop.log.data[:, 22] * 1e-6
            if np.isfinite(lat).all():
                print(
                    f"  loop latency, kernel arrival of the message → reply sent (its wake-up + "
                    f"compute), ms: {_pct(lat)}"
                )
            rd = res["read_late"][:ran]
            rd = rd[np.isfinite(rd)]
            if len(rd):
                print(f"  the simulated controller's wake-up after a reply arrived, ms: {_pct(rd)}")
        late = res["send_late"][:ran]
        print(
            f"  the simulated controller's own scheduling (send after its cycle start), ms: "
            f"{_pct(late)}"
        )
        if "wake_late" in res:
            wl = res["wake_late"][:ran]
            print(f"    of which its wake-up for the cycle (after the spin), ms: {_pct(wl)}")
        rl = res["rtt_late"][:ran]
        if np.isfinite(rl).any():
            print(f"  the late replies' round trip, ms: {_pct(rl[np.isfinite(rl)])}")
        # the loop's missed cycles, taken apart on the shared monotonic clock: when the loop
        # read the message (its wake-up after the send) and how long it took to answer
        rtt_a = np.asarray(res["rtt"])[:ran]
        own = np.isnan(rtt_a) & (4e-3 - late < 2e-3)
        mine = np.flatnonzero(np.isnan(rtt_a) & ~own)
        if len(mine):
            d = loop.log.data
            row = {int(s): i for i, s in enumerate(d[:, 1])}
            for j in mine[:10]:
                i = row.get(int(j) + 1)
                if i is None:
                    print(f"  the loop's missed cycle {j}: never answered (no log row)")
                    continue
                lat, comp_j = d[i, 22] * 1e-6, d[i, 21] * 1e-6
                arrived = loop.t0 + d[i, 0] - (lat - comp_j)  # in the loop's socket (kernel)
                print(
                    f"  the loop's missed cycle {j}: sent {late[j] * 1e3:.2f} ms into its cycle, "
                    f"in the loop's socket {(arrived - res['sent'][j]) * 1e3:.2f} ms later; the "
                    f"loop's latency {lat * 1e3:.2f} ms (compute {comp_j * 1e3:.2f} ms); reply "
                    f"arrived {rl[j] * 1e3:.2f} ms after the send"
                )
        print(
            f"  garbage collections in the loop: {c.gc_collections} (longest "
            f"{c.gc_max_pause * 1e3:.2f} ms)"
        )

    if not a.skip_part:
        t0 = time.perf_counter()
        run = form_online(setup, a.controller, cycles_per_point=a.cycles_per_point)
        ev = evaluate(setup, run)
        dt = time.perf_counter() - t0
        finite = np.isfinite(ev.offline_diff)
        print(
            f"first part ({a.part}, {a.cycles_per_point} cycle(s) per toolpath point, {dt:.0f} s):"
            f" compliance error RMS {ev.rms_before * 1e6:.1f} → {ev.rms_after * 1e6:.1f} µm, "
            f"{ev.removed:.1%} removed [target ≥ 80 %: {'met' if ev.removed >= 0.8 else 'NOT met'}]"
        )
        print(
            f"  vs offline pre-deflection on the loop's own wrenches: max "
            f"{np.max(ev.offline_diff[ev.steady]) * 1e6:.3f} µm where no limit acted "
            f"({ev.steady.mean():.0%} of points), max {np.max(ev.offline_diff[finite]) * 1e6:.3f}"
            f" µm over all points [target ≤ 5 µm]"
        )
        print(
            f"  vs offline on the true wrenches (adds filter + one-cycle lag), µm: "
            f"{_pct(ev.offline_true_diff, 1e6)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
