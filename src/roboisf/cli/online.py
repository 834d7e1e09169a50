"""``roboisf online``: the forming force, streamed, turned into the robot's path correction."""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Any

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file, study_inputs
from roboisf.errors import InputError
from roboisf.virtual.builtin import builtin_names, paper_scenario_names

__all__ = ["register"]

VIRTUAL = builtin_names()
SCENARIO_CELLS = paper_scenario_names()


def _floats(text: str | None, n: int, field: str) -> list[float] | None:
    if text is None:
        return None
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(
            f"expected {n} comma-separated numbers, got {text!r}", field=field
        ) from None
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise InputError(f"expected {n} finite comma-separated numbers, got {text!r}", field=field)
    return v


def _check_run(controller: str, duration: float, cycles: int | None, cycle: float) -> None:
    """--duration, --cycles and --cycle, before anything is started."""
    if not duration > 0:  # NaN too
        raise InputError(
            f"must be > 0 s (default: until Ctrl-C), got {duration}", field="--duration"
        )
    if cycles is not None and cycles < 1:
        raise InputError(f"must be ≥ 1, got {cycles}", field="--cycles")
    if not (math.isfinite(cycle) and cycle > 0):
        raise InputError(f"must be a cycle time > 0 ms, got {cycle}", field="--cycle")
    if controller == "egm" and (cycle < 4 or not math.isclose(cycle / 4, round(cycle / 4))):
        raise InputError(
            f"EGM cycles are multiples of 4 ms (EGMActMove \\SampleRate), got {cycle:g} ms",
            field="--cycle",
        )
    if controller == "rsi" and not any(math.isclose(cycle, c) for c in (4.0, 12.0)):
        raise InputError(
            f"RSI cycles are 4 ms (IPO_FAST) or 12 ms (IPO), got {cycle:g} ms", field="--cycle"
        )


def online(
    controller: str = typer.Option(
        ...,
        "--controller",
        "-c",
        help="egm (ABB Externally Guided Motion, position guidance; --path-correction for "
        "EGMPathCorr) | rsi (KUKA RSI, RKorr) | replay (the joint log of --sensor replay:STUDY, "
        "no network: what the loop would have sent on a part already formed).",
    ),
    sensor: str = typer.Option(
        "netft:127.0.0.1",
        "--sensor",
        "-s",
        help="netft:HOST[:PORT] (ATI Net F/T, RDT over UDP, port 49152) | replay:STUDY (the "
        "study's robot force log, released in real time).",
    ),
    output: Path | None = typer.Option(
        None,
        "--output",
        "-o",
        help=f"Per-cycle log, Parquet (units in column names); required but with --selftest. "
        f"{FILE_HELP}",
    ),
    overwrite: Overwrite = False,
    study: Path | None = typer.Option(
        None,
        "--study",
        help="The cell (robot, joint stiffness, placement, tool, holder, flange sensor pose) "
        "from a study folder. replay:STUDY implies it.",
    ),
    virtual: str | None = typer.Option(
        None, "--virtual", help=f"The cell of a virtual cell instead: {' | '.join(VIRTUAL)}."
    ),
    simulate: bool = typer.Option(
        False,
        "--simulate",
        help="Start a simulated controller (--controller's protocol) and Net F/T on localhost "
        "for the --virtual cell: try the loop without a robot.",
    ),
    form: Path | None = typer.Option(
        None,
        "--form",
        help="With --simulate: write the study of the part the loop formed (the virtual cell's "
        "robot run commanded along the corrections the simulated controller applied) into this "
        "folder; `roboisf analyze` it to see what the loop removed. The loop's compliance model "
        "is the cell's model: with --scenario the truth differs from it.",
    ),
    scenario: str | None = typer.Option(
        None,
        "--scenario",
        help=f"With --virtual {'|'.join(SCENARIO_CELLS)}: the cell's truth (e.g. `paper`, the "
        "paper's robot that differs from the VJM model the loop uses; docs/virtual-cell.md).",
    ),
    scan_points: int = typer.Option(
        300_000, "--scan-points", help="Points per simulated scan of --form's study."
    ),
    listen: str = typer.Option(
        "0.0.0.0:6510",
        "--listen",
        help="HOST:PORT where the controller's messages arrive (EGM UCdevice / RSI config).",
    ),
    duration: float = typer.Option(
        math.inf, "--duration", help="Stop after this many seconds (default: Ctrl-C)."
    ),
    cycles: int | None = typer.Option(None, "--cycles", help="Stop after this many cycles."),
    cycle: float = typer.Option(4.0, "--cycle", help="Controller cycle, ms (RSI: 4 or 12)."),
    cutoff: float = typer.Option(
        20.0,
        "--cutoff",
        help="Low-pass corner on the wrench, Hz; below half the sensor's sample rate (a "
        "replayed log's own, the simulated sensor's 1000 Hz; a Net F/T's is set on it, at most "
        "7000 Hz).",
    ),
    deadband: float = typer.Option(0.005, "--deadband", help="Corrections below are 0, mm."),
    max_correction: float = typer.Option(2.0, "--max-correction", help="Size limit, mm."),
    max_rate: float = typer.Option(20.0, "--max-rate", help="Rate limit, mm/s."),
    watchdog: float = typer.Option(
        50.0,
        "--watchdog",
        help="No usable force sample for this long: hold; twice as long: ramp to 0, ms; at "
        "least two --cycle, below 1000 (the ramp begins before a Net F/T silent for 2 s stops "
        "the loop).",
    ),
    ramp_rate: float | None = typer.Option(
        None,
        "--ramp-rate",
        help="Ramp to zero of the watchdog and of every stop, mm/s; at most --max-rate, which "
        "every step keeps. Default: 5 mm/s, or --max-rate if that is lower.",
    ),
    sensor_pose: str | None = typer.Option(
        None,
        "--sensor-pose",
        help="The F/T sensor in the flange frame: x,y,z,rx,ry,rz (mm, deg, fixed XYZ). "
        "Default: the study's robot force sensor; the flange itself otherwise.",
    ),
    load_on: str = typer.Option("tool", "--load-on", help="tool | workpiece (sensor's sign)."),
    tare: str | None = typer.Option(
        None, "--tare", help="Unloaded reading Fx,Fy,Fz,Mx,My,Mz (N, N·m), subtracted."
    ),
    tool_mass: float = typer.Option(0.0, "--tool-mass", help="Mass below the sensor, kg."),
    tool_cog: str = typer.Option("0,0,0", "--tool-cog", help="Its CoG in the sensor frame, mm."),
    counts: str = typer.Option(
        "1000000,1000000",
        "--counts",
        help="Net F/T counts per N and per N·m (cfgcpf, cfgcpt of the calibration).",
    ),
    path_correction: bool = typer.Option(
        False,
        "--path-correction",
        help="EGM path correction (EGMActMove + EGMMoveL: the controller's path planning stays "
        "in charge; the mode for a forming program). pathCorr is sent in EGM's sensor frame, "
        "the TCP frame when EGMActMove is given tool.tframe (the RAPID module "
        "roboisf/online/egm_config/roboisf_egm.mod). Without it: position guidance, the "
        "controller's planned pose + the correction (docs/online.md).",
    ),
    relative: bool = typer.Option(
        False,
        "--relative",
        help='RSI: send per-cycle increments (RSI_ON(#RELATIVE), HOLDON="0"); an increment '
        "in a reply that came late (the controller's Delay count) is sent again.",
    ),
    rsi_correction: str = typer.Option(
        "cartesian",
        "--rsi-correction",
        help="RSI: cartesian (<RKorr X Y Z A B C>, mm, a POSCORR object in the part's BASE) | "
        "joint (<AK A1…A6>, deg, an AXISCORR object: ROS-Industrial's layout). The matching "
        "configuration files and KRL program ship in roboisf/online/rsi_config (docs/online.md).",
    ),
    rsi_sentype: str = typer.Option(
        "ImFree", "--rsi-sentype", help="RSI: the configuration's SENTYPE (<Sen Type=…>)."
    ),
    realtime: int | None = typer.Option(
        None,
        "--realtime",
        metavar="PRIO",
        help="Run the loop with SCHED_FIFO priority PRIO (1–99): it answers ahead of every "
        "normal process (--simulate's devices stay at normal priority). Needs CAP_SYS_NICE or "
        "`ulimit -r` ≥ PRIO; refused → one warning, the loop runs at normal priority.",
    ),
    cpu: int | None = typer.Option(
        None,
        "--cpu",
        help="Pin the loop to this CPU (best one kept free of other work); --simulate's "
        "devices then run on the other CPUs.",
    ),
    selftest: bool = typer.Option(
        False,
        "--selftest",
        help="Measure this host instead of serving: wake-up latency and the loop's compute, "
        "once per --cycle for --selftest-seconds under --realtime/--cpu/--mlock, then PASS "
        "(exit 0) or FAIL (exit 1) against the budget, half the cycle. Needs the cell "
        "(--virtual or --study) and -c egm|rsi; no network.",
    ),
    selftest_seconds: float = typer.Option(
        10.0, "--selftest-seconds", help="How long --selftest measures, s."
    ),
    max_force: float | None = typer.Option(
        None,
        "--max-force",
        help="Plausibility: a force sample above this (tare and tool weight removed) is "
        "dropped and the correction held, N. Default: 2× the expected peak forming force (the "
        "study's robot force log, the virtual cell's force model); inf: no bound.",
    ),
    max_force_rate: float | None = typer.Option(
        None,
        "--max-force-rate",
        help="Plausibility: the fastest the force may change, N/s (a sample further from the "
        "filtered force than half the expected peak + this × the time since the last sample "
        "is dropped). Default: the expected peak in 50 ms.",
    ),
    max_tip_moment: float | None = typer.Option(
        None,
        "--max-tip-moment",
        help="Plausibility: the largest moment about the tool tip, N·m (a ball-end tool takes "
        "its load at the tip). Default: the expected peak × 20 mm.",
    ),
    mlock: bool = typer.Option(
        False,
        "--mlock",
        help="Lock the loop's memory in RAM (mlockall): no page faults in a cycle. Needs "
        "CAP_IPC_LOCK or a large enough `ulimit -l`; refused → one warning.",
    ),
) -> None:
    """Correct the robot while it forms: force stream → tip wrench → VJM + tool + holder
    compliance at the current joints → pre-deflection sent every controller cycle.

    Limits (never exceeded): --max-correction, --max-rate (per unit of the controller's time,
    whatever its message rate), --deadband; the watchdog holds and then ramps the correction to
    zero when the sensor goes quiet; an implausible force (--max-force, --max-force-rate,
    --max-tip-moment) is dropped and the correction held. Every stop (the end of --duration or
    --cycles, Ctrl-C, SIGTERM, a closed terminal unless under nohup, a controller silent for
    0.5 s, a Net F/T silent for 2 s, 25 late replies in a second, an error) first ramps the
    correction to zero at --ramp-rate, and says so. Every cycle is logged to -o (Parquet); the
    summary counts every episode. Lengths mm, angles deg.
    On a PC with a core to spare for the loop: --realtime 50 --cpu N --mlock (a 2-core VM
    cannot show what they give). See docs/online.md.
    """
    import numpy as np

    from roboisf.online import OnlineCompensator, SensorSetup, status_text
    from roboisf.online.loop import Loop, parse_address
    from roboisf.online.rt import Realtime

    kind, arg, study = _check_sources(controller, sensor, simulate, form, scenario, study, virtual)
    rt = Realtime(realtime, cpu, mlock)  # InputError for a priority or CPU that cannot be
    _check_run(controller, duration, cycles, cycle)
    limits = _limits(deadband, max_correction, max_rate, cycle, watchdog, ramp_rate)
    if rsi_correction not in ("cartesian", "joint"):
        raise InputError(
            f"must be cartesian or joint, got {rsi_correction!r}", field="--rsi-correction"
        )
    if simulate and rsi_correction == "joint":
        raise InputError(
            "the simulated controller takes Cartesian corrections only (RKorr)",
            field="--rsi-correction",
        )
    cpf, cpt = _floats(counts, 2, "--counts") or [1e6, 1e6]
    if not (cpf > 0 and cpt > 0):
        raise InputError(f"counts per N and per N·m must be > 0, got {counts!r}", field="--counts")
    user_plaus = {
        "--max-force": max_force,
        "--max-force-rate": max_force_rate,
        "--max-tip-moment": max_tip_moment,
    }
    for name, v in user_plaus.items():
        if v is not None and not v > 0:  # NaN, 0 and negatives
            raise InputError(f"must be > 0 (inf: no bound), got {v}", field=name)
    if kind == "netft":
        parse_address(arg, 49152, "--sensor", resolve=True)
    parse_address(listen, 6510, "--listen", resolve=True)
    # the sensor's settings are checked whether or not --simulate then replaces them
    user_sensor = _user_sensor(load_on, tare, tool_mass, tool_cog, cutoff)
    if simulate:
        from roboisf.online.sim import SENSOR_RATE

        _check_cutoff(cutoff, SENSOR_RATE, "the simulated Net F/T streams")
    elif kind == "netft":  # its rate is set on the sensor: refused above what any can stream
        from roboisf.online.netft import MAX_RATE

        _check_cutoff(cutoff, MAX_RATE, "a Net F/T streams at most")
    T_user = None if sensor_pose is None else _sensor_pose(sensor_pose)
    if simulate:
        _warn_simulated_sensor(tare, tool_mass, load_on, tool_cog, sensor_pose)
    elif kind == "replay":  # -c replay, and a live loop fed the study's logs
        _warn_replay_sensor(tare, tool_mass, load_on, tool_cog, sensor_pose)
    _claim_outputs(selftest, selftest_seconds, controller, simulate, form, output, overwrite, study)
    cell, setup, spec_pose = _load_cell(virtual, study, scenario, scan_points, form, cutoff)
    if T_user is not None:
        T_fs = T_user
    else:
        T_fs = spec_pose if spec_pose is not None else np.eye(4)
    if simulate:
        sensor_setup = setup.sensor  # the simulated sensor's tool, weight and tare
    else:
        sensor_setup = SensorSetup(T_fs, **user_sensor)

    if controller == "replay":
        assert output is not None
        plaus = _plausibility(
            _expected_peak(setup, study), max_force, max_force_rate, max_tip_moment
        )
        _replay(study, limits, plaus, cutoff, output)
        return

    adapter = _adapter(
        controller, path_correction, limits, relative, rsi_correction, rsi_sentype, cell
    )
    host, port = parse_address(listen, 6510, "--listen")
    if simulate:
        host, port = "127.0.0.1", 0
    src: Any
    if kind == "netft":
        shost, sport = parse_address(arg, 49152, "--sensor")
        src = (shost, 0 if simulate else sport)
    else:
        from roboisf.online.replay import ReplaySensor

        rep = _load_replay(Path(arg), cutoff)
        src = ReplaySensor(rep.force_time, rep.force)
        # the study's sensor (pose, sign), no tare, no weight: its log is tared and compensated
        # and was logged in that frame (--sensor-pose used to bring --tare and the tool's
        # weight along, removed a second time from every sample)
        sensor_setup = rep.sensor
    peak = _expected_peak(setup, study)
    plaus = _plausibility(peak, max_force, max_force_rate, max_tip_moment)
    oc = OnlineCompensator(cell.robot, cell.T_base_work, _k_tip(cell), sensor_setup, limits, plaus)
    if selftest:
        _selftest(oc, adapter, cell, setup, selftest_seconds, rt)
        return
    assert output is not None
    from roboisf.online.loop import RULES_OFF

    rules: dict[str, Any] = dict(RULES_OFF) if simulate else {}
    loop = Loop(oc, adapter, (host, port), src, counts=(cpf, cpt), realtime=rt, **rules)
    banner = (
        f"online: {adapter.name} on {loop.listen[0]}:{loop.listen[1]}, sensor {sensor}; "
        f"limits {max_correction:g} mm, {max_rate:g} mm/s, dead band {deadband * 1e3:g} µm; "
        f"plausible force ≤ {plaus.max_force:.4g} N, ≤ {plaus.max_force_rate:.4g} N/s, "
        f"tip moment ≤ {plaus.max_tip_moment:.4g} N·m"
        + (f" (expected peak {peak:.0f} N)" if math.isfinite(peak) else "")
    )
    sim_result: dict[str, Any] | None = None
    if simulate:
        sim_result = _run_simulated(
            loop, setup, controller, limits, duration, cycles, cpu, relative, banner
        )
    else:
        _run(loop, duration, cycles, status_text, banner)
    _report(loop, output, controller, sensor, sim_result, limits)
    if form is not None:
        _form(setup, sim_result, form)


def _report(
    loop: Any,
    output: Path,
    controller: str,
    sensor: str,
    sim_result: dict[str, Any] | None,
    limits: Any,
) -> None:
    """Write the per-cycle log and print the run's summary (and the simulated controller's)."""
    import numpy as np

    loop.log.write(
        output,
        {
            "controller": controller,
            "sensor": sensor,
            "corrections": "work axes",
            "wrench_and_deflection": "base axes, at the tool tip",
        },
    )
    for line in summary_lines(loop.counters, loop.log.data[:, 20], loop.log.data[:, 0]):
        state.info(line)
    state.info(f"log → {output}")
    if sim_result is not None:
        for w in sim_result.get("warnings", []):
            state.warn(w)
        rtt = sim_result["rtt"]
        got = np.isfinite(rtt)
        if got.any():
            from roboisf.online.sim import missed_causes

            mc = missed_causes(sim_result, cycle=limits.cycle)
            state.info(
                f"simulated controller: {mc['missed']} missed cycles of {sim_result['ran']} "
                f"({mc['controller']} its own scheduling, {mc['loop_late'] + mc['loop_lost']} "
                f"the loop's); round trip p50 {np.percentile(rtt[got], 50) * 1e3:.3f} ms, "
                f"p99 {np.percentile(rtt[got], 99) * 1e3:.3f} ms"
            )


def _check_sources(
    controller: str,
    sensor: str,
    simulate: bool,
    form: Path | None,
    scenario: str | None,
    study: Path | None,
    virtual: str | None,
) -> tuple[str, str, Path | None]:
    """The controller, the sensor (``kind``, its argument) and the cell (``--study`` or
    ``--virtual``) that go together; the study (``replay:STUDY`` implies it)."""
    if controller not in ("egm", "rsi", "replay"):
        raise InputError(f"must be egm, rsi or replay, got {controller!r}", field="--controller")
    kind, _, arg = sensor.partition(":")
    if kind not in ("netft", "replay") or not arg:
        raise InputError(
            f"expected netft:HOST[:PORT] or replay:STUDY, got {sensor!r}", field="--sensor"
        )
    if simulate and (virtual is None or kind != "netft" or controller == "replay"):
        raise InputError(
            "--simulate needs --virtual NAME, --controller egm|rsi and a netft sensor",
            field="--simulate",
        )
    if form is not None and not simulate:
        raise InputError(
            "--form needs --simulate (the part a simulated run formed)", field="--form"
        )
    if scenario is not None and virtual not in SCENARIO_CELLS:
        raise InputError(
            f"--scenario needs --virtual {'|'.join(SCENARIO_CELLS)}", field="--scenario"
        )
    if kind == "replay":
        study = Path(arg)
    if (study is None) == (virtual is None):
        raise InputError("give the cell: --study STUDY or --virtual NAME", field="--study")
    if virtual is not None and virtual not in builtin_names():
        raise InputError(
            f"must be one of {', '.join(builtin_names())}, got {virtual!r}", field="--virtual"
        )
    if controller == "replay" and kind != "replay":
        raise InputError("--controller replay needs --sensor replay:STUDY", field="--controller")
    return kind, arg, study


#: The largest --max-correction accepted [mm]: the robot's deflection under forming loads is
#: a few millimetres (the paper's IRB 7600: ≤ 2 mm), so a larger limit stops nothing.
MAX_CORRECTION_MM = 20.0
#: The default --ramp-rate [mm/s] (or --max-rate, when that is lower)
RAMP_RATE_MM_S = 5.0


def _limits(
    deadband: float,
    max_correction: float,
    max_rate: float,
    cycle: float,
    watchdog: float,
    ramp_rate: float | None,
) -> Any:
    """The loop's :class:`~roboisf.online.Limits` from the options (mm, mm/s, ms → SI); an
    error names the option. ``ramp_rate`` None: :data:`RAMP_RATE_MM_S`, or ``max_rate`` if
    lower."""
    from roboisf.online import Limits
    from roboisf.online.loop import SENSOR_TIMEOUT

    ramp_given = ramp_rate is not None
    if ramp_rate is None:
        ramp_rate = min(RAMP_RATE_MM_S, max_rate) if max_rate > 0 else RAMP_RATE_MM_S
    # each option in its own unit (Limits' own check says SI: "--max-rate: … got -0.001")
    for flag, v, unit, zero in (
        ("--deadband", deadband, "mm", True),
        ("--max-correction", max_correction, "mm", False),
        ("--max-rate", max_rate, "mm/s", False),
        ("--cycle", cycle, "ms", False),
        ("--watchdog", watchdog, "ms", False),
        ("--ramp-rate", ramp_rate, "mm/s", False),
    ):
        if not math.isfinite(v) or v < 0 or (v == 0 and not zero):
            raise InputError(f"must be {'≥' if zero else '>'} 0 {unit}, got {v:g}", field=flag)
    if deadband >= max_correction:
        # every correction below the dead band is sent as 0: at or above the size limit, all are
        raise InputError(
            f"a dead band of {deadband:g} mm at or above the size limit ({max_correction:g} mm) "
            "sends every correction as 0: the loop would never correct; the dead band is in mm "
            "(the default 0.005 mm is 5 µm)",
            field="--deadband",
        )
    if max_rate * cycle * 1e-3 > max_correction:
        # faster than the whole size limit within one cycle, a rate limit limits nothing
        raise InputError(
            f"{max_rate:g} mm/s lets the correction jump its whole size limit "
            f"({max_correction:g} mm) within one {cycle:g} ms cycle: no rate limit is left; at "
            f"most {max_correction / (cycle * 1e-3):g} mm/s with these settings (the default "
            "is 20 mm/s)",
            field="--max-rate",
        )
    if watchdog < 2.0 * cycle:
        # the controller asks once a cycle: a watchdog shorter than two of them holds or ramps
        # between samples that are on time, and the loop corrects (almost) never — refusing it
        # loosens no limit (the hold and the ramp stay in time)
        ok_in_s = 2.0 * cycle <= watchdog * 1e3 and 2.0 * watchdog < SENSOR_TIMEOUT
        slip = f"; it is {watchdog * 1e3:g} ms if it was written in s" if ok_in_s else ""
        raise InputError(
            f"{watchdog:g} ms is shorter than two controller cycles (2 × {cycle:g} ms): the "
            "watchdog would hold or ramp the correction between force samples that arrive on "
            f"time, and the loop would hardly correct; at least {2 * cycle:g} ms (the default "
            f"is 50 ms){slip}",
            field="--watchdog",
        )
    if 2.0 * watchdog * 1e-3 >= SENSOR_TIMEOUT:
        # the watchdog ramps after twice its time: from a second on, a silent Net F/T stops the
        # loop first, and a sensor streaming records the loop cannot use (faulty, implausible:
        # no stop for those) keeps the correction as long — no limit is loosened this way
        slip = f"; it is {watchdog * 1e-3:g} ms if it was written in µs" if watchdog >= 1e4 else ""
        raise InputError(
            f"{watchdog:g} ms: the watchdog would ramp the correction to zero only after "
            f"{2 * watchdog * 1e-3:g} s without a usable force sample, but a Net F/T silent for "
            f"{SENSOR_TIMEOUT:g} s stops the loop first (and one streaming faulty or implausible "
            f"records would keep the correction that long); below {SENSOR_TIMEOUT * 1e3 / 2:g} "
            f"ms, so that the ramp begins before that stop (the default is 50 ms){slip}",
            field="--watchdog",
        )
    if ramp_given and ramp_rate > max_rate:
        # every step of the correction, a ramp's too, keeps the rate limit: the ramp would run
        # at --max-rate, not at the rate asked for
        slip = (
            f"; it is {ramp_rate * 1e-3:g} mm/s if it was written in µm/s"
            if ramp_rate >= 1000 and ramp_rate * 1e-3 <= max_rate
            else ""
        )
        raise InputError(
            f"{ramp_rate:g} mm/s is faster than the rate limit (--max-rate {max_rate:g} mm/s), "
            f"which every step of the correction keeps: the ramp to zero would run at "
            f"{max_rate:g} mm/s, not {ramp_rate:g}; give at most {max_rate:g} mm/s or raise "
            f"--max-rate (the default ramp is {RAMP_RATE_MM_S:g} mm/s){slip}",
            field="--ramp-rate",
        )
    if max_correction > MAX_CORRECTION_MM:
        # the size limit is the loop's last guard: 2000 mm (2 m, or µm typed as mm) guards nothing
        raise InputError(
            f"a size limit of {max_correction:g} mm is no limit: a forming robot's deflection "
            f"is a few mm; at most {MAX_CORRECTION_MM:g} mm (the default is 2 mm)",
            field="--max-correction",
        )
    try:
        return Limits(
            deadband * 1e-3,
            max_correction * 1e-3,
            max_rate * 1e-3,
            cycle * 1e-3,
            watchdog * 1e-3,
            ramp_rate * 1e-3,
        )
    except InputError as e:
        raise InputError(e.message, field=f"--{str(e.field).replace('_', '-')}") from None


def _check_cutoff(cutoff: float, rate: float, source: str) -> None:
    """``--cutoff`` below half the force samples' rate (``source`` says whose)."""
    from roboisf.online.core import check_cutoff

    try:
        check_cutoff(cutoff, rate, source)
    except InputError as e:
        raise InputError(e.message, field="--cutoff") from None


def _load_replay(study: Path, cutoff: float) -> Any:
    """:func:`~roboisf.online.replay.load_replay`, a cutoff its force log's rate refuses named
    as ``--cutoff``."""
    from roboisf.online.replay import load_replay

    try:
        return load_replay(study, cutoff=cutoff)
    except InputError as e:
        if e.field != "cutoff":
            raise
        raise InputError(e.message, field="--cutoff") from None


def _user_sensor(
    load_on: str, tare: str | None, tool_mass: float, tool_cog: str, cutoff: float
) -> dict[str, Any]:
    """The F/T sensor's settings from the options (SI), checked as a
    :class:`~roboisf.online.SensorSetup` would; an error names the option."""
    import numpy as np

    from roboisf.online import SensorSetup
    from roboisf.plausible import check_plausible

    cog = _floats(tool_cog, 3, "--tool-cog")
    assert cog is not None
    tare_v = _floats(tare, 6, "--tare") or [0.0] * 6
    # magnitudes a cell has, the slip named (3200 kg: the tool in g; a sensor 100 m away)
    if math.isfinite(tool_mass) and tool_mass >= 0:
        check_plausible(tool_mass, "tool_mass", field="--tool-mass")
    for x in cog:
        check_plausible(x, "tool_cog", field="--tool-cog")
    for f in tare_v[:3]:
        check_plausible(f, "sensor_bias", field="--tare")
    user_sensor = dict(
        load_on=load_on,
        tare=np.array(tare_v),
        tool_mass=tool_mass,
        tool_cog=np.array(cog) * 1e-3,
        cutoff=cutoff,
    )
    try:
        SensorSetup(**user_sensor)  # type: ignore[arg-type]
    except InputError as e:
        flag = {"load_on": "--load-on", "tool_mass": "--tool-mass", "tool_cog": "--tool-cog"}
        raise InputError(e.message, field=flag.get(str(e.field), f"--{e.field}")) from None
    return user_sensor


def _sensor_pose(text: str) -> Any:
    """``--sensor-pose`` (mm, deg) → ``T_flange_sensor`` (m), its magnitudes checked: a sensor
    within 2 m of the flange, angles within ±720°."""
    from roboisf.frames.pose import XYZ_RPY_MM_DEG, parse_pose
    from roboisf.plausible import check_plausible

    T = parse_pose(text, XYZ_RPY_MM_DEG, field="--sensor-pose")
    v = _floats(text, 6, "--sensor-pose")
    assert v is not None
    for x in v[:3]:
        check_plausible(x, "sensor_position", field="--sensor-pose")
    for a in v[3:]:
        check_plausible(a, "angle", field="--sensor-pose")
    return T


def _given_sensor_options(
    tare: str | None, tool_mass: float, load_on: str, tool_cog: str, sensor_pose: str | None
) -> list[str]:
    return [
        f
        for f, v in (
            ("--tare", tare),
            ("--tool-mass", tool_mass or None),
            ("--load-on", None if load_on == "tool" else load_on),
            ("--tool-cog", None if tool_cog == "0,0,0" else tool_cog),
            ("--sensor-pose", sensor_pose),
        )
        if v is not None
    ]


def _warn_replay_sensor(
    tare: str | None, tool_mass: float, load_on: str, tool_cog: str, sensor_pose: str | None
) -> None:
    """A replayed study (``-c replay``, ``--sensor replay:STUDY``) reads the study's sensor and
    its logs as tared and weight-compensated: say which given sensor options it does not use."""
    given = _given_sensor_options(tare, tool_mass, load_on, tool_cog, sensor_pose)
    if given:
        state.warn(
            "--sensor replay:STUDY: the study's force sensor (pose, sign) is used and its log is "
            f"taken as tared and weight-compensated; {', '.join(given)} not"
        )


def _warn_simulated_sensor(
    tare: str | None, tool_mass: float, load_on: str, tool_cog: str, sensor_pose: str | None
) -> None:
    """--simulate uses the simulated sensor's settings: say which given options it ignores."""
    given = _given_sensor_options(tare, tool_mass, load_on, tool_cog, sensor_pose)
    if given:
        state.warn(
            f"--simulate: the simulated sensor's own tool, weight and tare are used; "
            f"{', '.join(given)} not"
        )


def _claim_outputs(
    selftest: bool,
    selftest_seconds: float,
    controller: str,
    simulate: bool,
    form: Path | None,
    output: Path | None,
    overwrite: Overwrite,
    study: Path | None,
) -> None:
    """Check the run's outputs (the log; --form's study) and claim them before anything is
    computed; --selftest writes none."""
    if selftest:
        if controller == "replay" or simulate or form is not None:
            raise InputError(
                "--selftest measures the host for -c egm|rsi; not with replay, --simulate "
                "or --form",
                field="--selftest",
            )
        if not (math.isfinite(selftest_seconds) and selftest_seconds > 0):
            raise InputError(f"must be > 0 s, got {selftest_seconds}", field="--selftest-seconds")
    elif output is None:
        raise InputError("the per-cycle log: give -o LOG.parquet", field="-o")
    if output is not None and output.suffix.lower() != ".parquet":
        raise InputError(f"the log is Parquet: expected a .parquet file, got {output}", field="-o")
    if output is not None and not selftest:
        output_file(output, "online", overwrite, study_inputs(study))
    if form is not None:
        from roboisf.cli.outputs import output_dir

        output_dir(form, "virtual-cell", overwrite)


def _load_cell(
    virtual: str | None,
    study: Path | None,
    scenario: str | None,
    scan_points: int,
    form: Path | None,
    cutoff: float,
) -> tuple[Any, Any, Any]:
    """The cell the loop corrects: ``(cell, setup, T_flange_sensor)`` — a built-in virtual
    cell's (with its simulation ``setup`` and sensor pose) or a study's (``setup`` None; the
    sensor pose of its robot run's flange sensor, else None)."""
    if virtual is not None:
        from roboisf.online.sim import virtual_setup
        from roboisf.virtual.builtin import make_builtin_cell

        cell_kw: dict[str, Any] = {"scan_points": scan_points if form is not None else 1000}
        if scenario is not None:
            from roboisf.virtual.truth import load_truth

            cell_kw["truth"] = load_truth(scenario=scenario, part=virtual)
        vc = make_builtin_cell(virtual, field="--virtual", **cell_kw)
        setup = virtual_setup(vc, cutoff=cutoff)
        return vc.cell, setup, setup.sensor.T_flange_sensor
    from roboisf.cell import cell_from_study
    from roboisf.study import load_study

    assert study is not None
    st = load_study(study)
    cell = cell_from_study(st)
    f = st.robot_run.forces
    return cell, None, cell.T_flange_tip @ f.pose if f.mount == "flange" else None


def _adapter(
    controller: str,
    path_correction: bool,
    limits: Any,
    relative: bool,
    rsi_correction: str,
    rsi_sentype: str,
    cell: Any,
) -> Any:
    """The controller's protocol: ABB EGM or KUKA RSI."""
    if controller == "egm":
        from roboisf.online.egm import EgmAdapter

        return EgmAdapter(path_correction)
    from roboisf.online.rsi import RsiAdapter

    return RsiAdapter(
        limits.cycle,
        relative,
        correction=rsi_correction,
        dq_dp=_dq_dp(cell),
        sentype=rsi_sentype,
    )


def _run_simulated(
    loop: Any,
    setup: Any,
    controller: str,
    limits: Any,
    duration: float,
    cycles: int | None,
    cpu: int | None,
    relative: bool,
    banner: str,
) -> dict[str, Any] | None:
    """Run the loop against the simulated controller and Net F/T on localhost; what the
    simulated controller saw (None if it did not report in time)."""
    from roboisf.online import status_text
    from roboisf.online.rt import Realtime, other_cpus
    from roboisf.online.sim import Simulation

    n = int(min(duration, 3600.0) / limits.cycle) if math.isfinite(duration) else 15_000
    n = min(n, cycles) if cycles is not None else n
    step = max(1, math.ceil(len(setup.q) / max(n, 1)))
    others = other_cpus(cpu)  # the loop alone real-time; the devices beside it, not on it
    sim_rt = Realtime(None, None, False, others) if others is not None else None
    with Simulation(
        setup,
        controller,
        loop.listen[1],
        n_cycles=n,
        cycle=limits.cycle,
        point_step=step,
        realtime=sim_rt,
        relative=relative and controller == "rsi",
    ) as sim:
        assert loop.ft is not None
        loop.ft.connect(("127.0.0.1", sim.sensor_port))

        why = f"the simulated controller's path of {n} cycles ended"
        if cycles is not None and n == cycles:
            why = f"{cycles} cycles run ({why})"
        elif math.isfinite(duration) and n == int(duration / limits.cycle):
            why = f"--duration {duration:g} s reached ({why})"

        def _finish() -> None:
            sim.result()  # its path has ended; it streams on, holding the last point, so the
            loop.stop(why)  # loop's stop ramps the correction to zero through its messages

        done = threading.Thread(target=_finish, daemon=True)
        done.start()
        # the controller's last cycle ends the run (--duration sets its cycle count), not
        # the loop's clock, which started before the controller's first message: cut by
        # the loop's clock, its last cycles went unanswered and counted as missed (and
        # --form's part needs the whole path)
        wait = duration + 60.0
        _run(loop, wait, cycles, status_text, banner)
        sim.stop.set()  # the loop has ended: the controller's hold ends (it has reported)
        done.join(30)
        result: dict[str, Any] | None = sim.result(timeout=0.1) if not done.is_alive() else None
        return result


def _selftest(oc: Any, adapter: Any, cell: Any, setup: Any, seconds: float, rt: Any) -> None:
    """``--selftest``: the host's verdict against the cycle budget (exit 1 on FAIL)."""
    import numpy as np

    from roboisf.online import egm, rsi
    from roboisf.online.selftest import selftest
    from roboisf.robot import ik_toolpath

    if setup is not None:
        q = np.asarray(setup.q[len(setup.q) // 2])
    else:
        q = ik_toolpath(cell.robot, np.zeros((1, 3)), cell.T_base_work).q[0]
    T = cell.robot.fk(q[None])[0]
    from roboisf.frames import matrix_to_quat

    planned = np.r_[T[:3, 3], matrix_to_quat(T[:3, :3])]
    msg = egm.encode_robot(1, 0, q, planned) if adapter.name == "egm" else rsi.encode_robot(4, q)
    state.info(
        f"selftest: {seconds:g} s, one {adapter.name} cycle of {oc.limits.cycle * 1e3:g} ms at "
        f"a time (realtime {rt.priority or 'off'}, cpu {rt.cpu if rt.cpu is not None else 'any'}"
        f", mlock {'on' if rt.mlock else 'off'})"
    )
    res = selftest(oc, adapter, msg, seconds=seconds, realtime=rt)
    for w in res.warnings:
        state.warn(w)
    for line in res.lines():
        state.info(line)
    if not res.passed:
        raise typer.Exit(1)


def _expected_peak(setup: Any, study: Path | None) -> float:
    """The expected peak forming force, N: the virtual cell's force model, or the study's robot
    force log (NaN when it has none)."""
    import numpy as np

    from roboisf.online.replay import expected_peak_force

    if setup is not None:
        return expected_peak_force(np.asarray(setup.wrench))
    if study is None:
        return math.nan
    from roboisf.logs.forcelog import read_force_log
    from roboisf.study import load_study

    spec = load_study(study).robot_run.forces
    return expected_peak_force(read_force_log(spec.file).wrench)


def _plausibility(peak: float, max_force: Any, rate: Any, moment: Any) -> Any:
    """The plausibility bounds: the options given, the rest from the expected peak force."""
    from roboisf.online import Plausibility

    base = Plausibility.from_expected(peak) if math.isfinite(peak) and peak > 0 else Plausibility()
    return Plausibility(
        base.max_force if max_force is None else max_force,
        base.force_band,
        base.max_force_rate if rate is None else rate,
        base.max_tip_moment if moment is None else moment,
    )


def summary_lines(c: Any, status: Any, t: Any) -> list[str]:
    """The run's summary: why it stopped and how the correction ended, what was dropped, and
    every episode of each status bit (count, longest)."""
    from roboisf.online import netft

    ended = (
        f"ramped to zero in {c.ramp_time:.2f} s"
        if c.ramped
        else f"NOT ramped to zero: left at {c.left_mm:.3f} mm (nothing answered the ramp; the "
        "controller's own timeout ends the motion)"
    )
    lines = [
        f"stopped: {c.stop_reason or 'not started'}; correction {ended}",
        f"{c.cycles} cycles, {c.samples} force samples; late replies {c.late_replies} "
        f"(max latency {c.max_latency * 1e3:.2f} ms); dropped: {c.bad_controller} bad "
        f"controller and {c.bad_sensor} bad sensor packets",
        f"sensor: {c.lost_sensor} records lost, {c.late_sensor} out of order or duplicated, "
        f"{c.sensor_resyncs} stream restarts followed, {c.implausible} implausible samples held, "
        f"{c.sensor_status} with a fault status"
        + (f" ({netft.status_text(c.sensor_status_bits)})" if c.sensor_status_bits else "")
        + (f", unreachable {c.sensor_unreachable}×" if c.sensor_unreachable else "")
        + (
            f", {c.unoriented} before the controller's first joint angles not used (the tool's "
            "weight needs them)"
            if c.unoriented
            else ""
        ),
    ]
    lines.append(_episodes_line(status, t))
    if c.status_lost:  # the summary may go where the status could not (stdout, not stderr)
        lines.append(f"status display dropped after it failed ({c.status_lost}); the loop went on")
    return lines


def _episodes_line(status: Any, t: Any) -> str:
    """Every episode of each status bit but the dead band's (count, longest)."""
    from roboisf.online.core import episodes

    shown = {k: v for k, v in episodes(status, t).items() if k != "deadband"}
    return "episodes: " + (
        ", ".join(f"{k} {n}× (longest {dt * 1e3:.0f} ms)" for k, (n, dt) in shown.items())
        if shown
        else "none (every cycle ok or in the dead band)"
    )


def _form(setup: Any, sim_result: dict[str, Any] | None, folder: Path) -> None:
    """The study of the part the simulated run formed (``--form``)."""
    from roboisf.online.sim import applied_per_point, form_study

    if sim_result is None:
        raise InputError(
            "the simulated controller did not report its corrections: no part to form",
            field="--form",
        )
    ran = int(sim_result["ran"])
    k, applied = sim_result["k"][:ran], sim_result["applied"][:ran]
    per_point = applied_per_point(setup, k, applied)
    n = len(setup.toolpath)
    reached = int(k[-1]) + 1 if ran else 0
    form_study(setup, per_point, folder)
    state.info(
        f"formed part → {folder} (study; `roboisf analyze {folder}`): corrections on "
        f"{reached} of {n} toolpath points"
        + ("" if reached >= n else " — the rest formed uncorrected (a longer --duration)")
    )


def _dq_dp(cell: Any) -> Any:
    """q (6,) rad → (6, 3) rad/m: the axis change per tip translation (work axes) at q."""
    import numpy as np

    e = np.eye(6)[:, :3]
    T_bw = cell.T_base_work

    def f(q: Any) -> Any:
        J = cell.robot.jacobian(np.asarray(q)[None], check_limits=False, T_base_work=T_bw)[0]
        return np.linalg.solve(J, e)

    return f


def _k_tip(cell: Any) -> Any:
    from roboisf.cell import tip_compliances

    _, _, k_t, k_th = tip_compliances(cell)
    return k_t + k_th


def _run(loop: Any, duration: float, cycles: int | None, status_text: Any, banner: str) -> None:
    """Serve with a live status line (a rich Live on a terminal, a line a second with -v)."""
    import numpy as np

    from roboisf.io.outdir import Interrupted

    def line(lp: Any) -> str:
        c = lp.counters
        k = lp.oc.correction * 1e3
        return (
            f"cycles {c.cycles}  samples {c.samples}  correction [{k[0]:+.3f} {k[1]:+.3f} "
            f"{k[2]:+.3f}] mm  |F| {np.linalg.norm(lp.oc.tip_wrench[:3]):.0f} N  "
            f"{status_text(lp.oc.status)}  bad {c.bad_controller}/{c.bad_sensor}  "
            f"late {c.late_sensor}"
        )

    try:
        state.info(banner)  # inside the try: a Ctrl-C from now on still writes the log
        if state.verbosity >= 1 and state.err.is_terminal:
            from rich.live import Live
            from rich.text import Text

            # no refresh thread: it would hold the interpreter while a packet waits; the loop
            # redraws itself, in the slack after a reply
            with Live(Text(""), console=state.err, auto_refresh=False, transient=True) as live:
                loop.run(
                    duration=duration,
                    cycles=cycles,
                    status=lambda lp: live.update(Text(line(lp)), refresh=True),
                    warn=state.warn,
                )
        else:
            loop.run(
                duration=duration,
                cycles=cycles,
                status=(lambda lp: state.debug(line(lp))),
                status_every=1.0,
                warn=state.warn,
            )
    except Interrupted:  # a signal before the loop served (run() handles its own)
        loop.close()
        loop.counters.stop_reason = "interrupted before the loop started"
        state.info("stopped (Ctrl-C); writing the log")


def _replay(study: Path | None, limits: Any, plaus: Any, cutoff: float, output: Path) -> None:
    import numpy as np
    import pandas as pd

    from roboisf.io.atomic import atomic_path
    from roboisf.online.replay import replay_study

    assert study is not None
    rep = _load_replay(study, cutoff)
    oc, out = replay_study(rep, limits, plaus)
    df = pd.DataFrame(
        {
            "t_s": out[:, 0],
            "corr_x_mm": out[:, 1] * 1e3,
            "corr_y_mm": out[:, 2] * 1e3,
            "corr_z_mm": out[:, 3] * 1e3,
            "fx_N": out[:, 4],
            "fy_N": out[:, 5],
            "fz_N": out[:, 6],
            "status": out[:, 7].astype(np.int64),
            "deflection_mm": out[:, 8] * 1e3,
            "compute_us": out[:, 9] * 1e6,
        }
    )
    with atomic_path(output) as tmp:
        df.to_parquet(tmp, index=False)
    state.info(
        f"replayed {len(df)} joint samples of {study}: correction up to "
        f"{np.linalg.norm(out[:, 1:4], axis=1).max() * 1e3:.3f} mm; {oc.implausible} implausible "
        f"force samples held; log → {output}"
    )
    state.info(_episodes_line(out[:, 7].astype(np.int64), out[:, 0]))


def register(app: typer.Typer) -> None:
    app.command("online")(online)
