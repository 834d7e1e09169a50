"""``roboisf plan``: outputs, the acceptance figure in the output, bad input (exit 2, no output)."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from roboisf.cli.main import main
from roboisf.cli.plan import parse_range
from roboisf.errors import InputError
from roboisf.parts import Cone
from roboisf.parts.io import save_part
from roboisf.virtual.cell import build_study, paper_cone_cell

SMALL = ["--x-range", "1400:2200:3", "--y-range", "0,300", "--z-range", "200", "--serial"]


@pytest.fixture(scope="module")
def cone_toml(tmp_path_factory):
    p = tmp_path_factory.mktemp("part") / "cone.toml"
    save_part(Cone(), p)
    return p


def test_plan_part_writes_ranked_outputs(cone_toml, tmp_path, capsys):
    out = tmp_path / "plan"
    code = main(["plan", "--part", str(cone_toml), *SMALL, "-o", str(out)])
    assert code == 0
    for f in ("placements.csv", "plan.json", "plan.html", "stiffness_map.png", "placement_map.png"):
        assert (out / f).is_file(), f
    df = pd.read_csv(out / "placements.csv", comment="#")
    assert len(df) == 6
    ok = df[df.status == "ok"]
    assert list(ok["rank"].astype(int)) == list(range(1, len(ok) + 1))
    assert ok["mean_abs_mm"].is_monotonic_increasing
    doc = json.loads((out / "plan.json").read_text())
    s = doc["summary"]
    # the paper-like placement is the default baseline for the IRB 7600; the best beats it
    assert s["baseline placement x,y,z [mm], yaw [deg]"] == [2200.0, -500.0, 200.0, 0.0]
    assert s["best mean robot |δ| [mm]"] < s["baseline mean robot |δ| [mm]"]
    assert s["mean robot |δ| reduction vs baseline [%]"] > 20
    html = (out / "plan.html").read_text()
    assert "Placement and tool rotation" in html and "data:image/png;base64" in html
    # the 13-column table and the summary scroll inside the card, long values wrap (no overflow)
    assert '<div class="scroll"><table class="data">' in html
    assert '<div class="scroll"><dl class="kv">' in html
    assert "#plan .scroll{max-width:100%;overflow-x:auto}" in html
    assert "overflow-wrap:anywhere" in html
    # each caption names what its figure draws, with units: the second map draws the robot's
    # compliance in µm/N, and its caption said "robot stiffness"; every δ is the ball centre's
    caps = [c.split("</figcaption>")[0] for c in html.split("<figcaption>")[1:]]
    assert len(caps) == 2
    assert caps[0].startswith("predicted mean robot |δ| [mm] at the ball centre")
    assert caps[1].startswith("robot translational compliance k_xx, k_yy, k_zz [µm/N]")
    assert not any("stiffness" in c for c in caps)
    lead = html.split('<p class="lead">')[-1].split("</p>")[0]
    assert "|δ| [mm] of the ball centre" in lead and "tool tip" not in lead
    captured = capsys.readouterr()
    text = captured.out
    assert "% lower" in text
    # the best (x = 1400, y = 0) is on the grid's x and y edges: said, on the page too
    for axis, v in (("x", 1400), ("y", 0)):
        note = f"lies at the low end of the searched {axis} range ({axis} = {v} mm)"
        assert note in captured.err and note in html
    assert "searched z range" not in html  # one z value: no edge to speak of
    # ranks whole, the grid's millimetres at 0.1 ("1.000" and "1400.000" before)
    first = html[html.index("<tbody>") :].split("</tr>")[0]
    assert first.startswith("<tbody><tr><td>1</td><td>") and ".000</td>" not in first[:60]


def test_one_yaw_is_one_candidate_and_a_worse_best_is_said_higher(cone_toml, tmp_path, capsys):
    """--yaw-range 0:360:3 ranked yaw 0 and 360, one placement, as two candidates; a best
    placement worse than the baseline read "(-63.9 % lower …)"."""
    out = tmp_path / "plan"
    # one placement farther out than the baseline (2200, -500, 200): worse than it
    args = ["plan", "--part", str(cone_toml), "--x-range", "2200", "--y-range", "-1000",
            "--z-range", "400", "--yaw-range", "0:360:3", "--serial", "-o", str(out)]  # fmt: skip
    assert main(args) == 0
    df = pd.read_csv(out / "placements.csv", comment="#")
    assert len(df) == 1 and df["yaw_deg"].tolist() == [0.0]
    captured = capsys.readouterr()
    text = captured.out
    assert "1 yaw(s) 360° from another left out" in text
    # yaws 0 and 180 left: a round part's yaw is no degree of freedom (the 360° one went first)
    assert "evaluated yaw 0° only (2 → 1 placements)" in captured.err
    assert "% higher" in text and "-" not in text.split("% higher")[0].split("(")[-1]


def test_a_round_parts_top_ten_are_ten_distinct_placements(cone_toml, tmp_path, capsys):
    """The cone at yaws 0, 45 and 90°: the top 10 listed each x, y, z three times with the same
    numbers (yaw does not change a round part). Now ten distinct placements, and it is said."""
    out = tmp_path / "plan"
    grid = ["--x-range", "1200:1600:5", "--y-range", "0,200", "--z-range", "400"]
    args = ["plan", "--part", str(cone_toml), *grid, "--yaw-range", "0:90:3", "--serial"]
    assert main([*args, "-o", str(out)]) == 0
    xyz = ["x_mm", "y_mm", "z_mm"]
    df = pd.read_csv(out / "placements.csv", comment="#")
    assert len(df) == 10 and (df.status == "ok").all() and not df.duplicated(xyz).any()
    assert (df["yaw_deg"] == 0.0).all()
    captured = capsys.readouterr()
    shown = [ln.split()[1:5] for ln in captured.out.splitlines() if ln[:4].strip().isdigit()]
    assert len(shown) == 10 and len({tuple(r[:3]) for r in shown}) == 10
    note = "yaw: the part is round"
    doc = json.loads((out / "plan.json").read_text())
    assert any(n.startswith(note) and "(30 → 10 placements)" in n for n in doc["notes"])
    html = (out / "plan.html").read_text()
    assert note in html and note in captured.err
    body = html[html.index("<tbody>") : html.index("</tbody>")]
    rows = [r.split("</td><td>")[1:4] for r in body.split("</tr>")[:-1]]
    assert len(rows) == 10 and len({tuple(r) for r in rows}) == 10


def test_a_round_parts_yaws_as_tool_rotations_show_on_the_terminal(cone_toml, tmp_path, capsys):
    """The cone, an off-axis tool, yaws 0, 45 and 90°: the yaws become tool rotations of one
    placement per x, y, z, but the terminal's table had no γ column (the chosen rotation was
    only in the CSV and on the page), and its count line said "9 placements × 1 tool rotations"
    — the grid asked for, not the 3 × 3 evaluated."""
    out = tmp_path / "plan"
    grid = ["--x-range", "1200:1600:3", "--y-range", "0", "--z-range", "400"]
    args = ["plan", "--part", str(cone_toml), *grid, "--yaw-range", "0:90:3", "--serial"]
    assert main([*args, "--tool", "150,0,350", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "3 placements × 3 tool rotations evaluated (of 9 × 1 asked for" in text, text
    assert "9 placements × 1 tool rotations" not in text
    lines = text.splitlines()
    head = next(ln for ln in lines if ln.startswith("rank"))
    assert head.split()[:6] == ["rank", "x", "y", "z", "yaw", "γ"], head
    shown = [ln.split() for ln in lines if ln[:4].strip().isdigit()]
    df = pd.read_csv(out / "placements.csv", comment="#")
    df = df[df.status == "ok"].sort_values("rank")
    assert len(shown) == len(df) == 3
    for row, (_, r) in zip(shown, df.iterrows(), strict=True):
        lo, hi = round(r["gamma_min_deg"]), round(r["gamma_max_deg"])
        assert row[5] == (f"{lo:g}" if lo == hi else f"{lo:g}..{hi:g}"), (row, r)
    # one tool rotation evaluated: no γ column, the count line as before
    assert main([*args, "-o", str(tmp_path / "coaxial")]) == 0
    text = capsys.readouterr().out
    assert "3 placements × 1 tool rotations evaluated (of 9 × 1 asked for" in text, text
    head = next(ln for ln in text.splitlines() if ln.startswith("rank"))
    assert "γ" not in head
    grid = ["--x-range", "1400", "--y-range", "0", "--z-range", "400", "--serial"]
    assert main(["plan", "--part", str(cone_toml), *grid, "-o", str(tmp_path / "one")]) == 0
    assert "1 placements × 1 tool rotations evaluated, " in capsys.readouterr().out


def test_plan_default_scheduler_is_named(cone_toml, tmp_path):
    # (equality of the schedulers' scores: tests/test_plan_dask.py)
    from roboisf.robot import vjm_kernel

    out = tmp_path / "plan"
    grid = ["--x-range", "1400,2200", "--y-range", "0", "--z-range", "200", "--workers", "2"]
    assert main(["plan", "--part", str(cone_toml), *grid, "-o", str(out)]) == 0
    doc = json.loads((out / "plan.json").read_text())
    # what ran is named, not "auto": threads with the compiled engine or on ≤ 2 CPUs, Dask
    # processes otherwise
    from roboisf.jit import cores

    want = "threads" if vjm_kernel.use_numba("auto") or cores() <= 2 else "local"
    assert doc["summary"]["scheduler"] == want
    assert doc["summary"]["feasible"] == 2


def test_plan_study(tmp_path):
    study = tmp_path / "study"
    build_study(
        paper_cone_cell(spacing=6e-3, scan_points=20000, force_rate=50.0, joint_rate=50.0), study
    )
    out = tmp_path / "plan"
    code = main(
        [
            "plan",
            "--study",
            str(study),
            "--x-range",
            "1600,2200",
            "--y-range",
            "0",
            "--z-range",
            "200",
            "--serial",
            "-o",
            str(out),
        ]
    )
    assert code == 0
    doc = json.loads((out / "plan.json").read_text())
    s = doc["summary"]
    assert "robot-run forces, robot, tool and holder" in s["input"]
    assert s["best placement x,y,z [mm], yaw [deg]"][0] == 1600.0
    assert s["mean robot |δ| reduction vs baseline [%]"] > 0
    # the study's tool and holder compliance is in the total (it was left out: "robot only"
    # whatever --no-tool-compliance said); with that flag, the total is the robot's
    grid = ["--x-range", "1600,2200", "--y-range", "0", "--z-range", "200", "--serial"]
    out2 = tmp_path / "plan-robot"
    args = ["plan", "--study", str(study), *grid, "--no-tool-compliance", "-o", str(out2)]
    assert main(args) == 0
    doc2 = json.loads((out2 / "plan.json").read_text())
    assert "robot only" in doc2["summary"]["input"]
    with_tool, robot_only = doc["candidates"][0], doc2["candidates"][0]
    assert with_tool["mean_robot_mm"] == pytest.approx(robot_only["mean_robot_mm"], rel=1e-12)
    assert robot_only["mean_abs_mm"] == pytest.approx(robot_only["mean_robot_mm"], rel=1e-12)
    assert with_tool["mean_abs_mm"] > 1.05 * with_tool["mean_robot_mm"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--x-range", ""], "empty range"),
        (["--x-range", "1400:2200:0"], "positive integer"),
        (["--x-range", "1400:2200:-3"], "positive integer"),
        (["--x-range", "2200:1400:3"], "stop < start"),
        (["--x-range", "a,b"], "start:stop:count"),
        (["--workers", "0"], "--workers"),
        (["--tool-rotations", "0:90:0"], "positive integer"),
        (["--x-range", "6000,7000"], "none of the"),
        (["--objective", "median"], "--objective"),
    ],
)
def test_plan_bad_input(cone_toml, tmp_path, capsys, args, message):
    out = tmp_path / "plan"
    base = ["--y-range", "0", "--z-range", "200", "--serial"]
    code = main(["plan", "--part", str(cone_toml), *base, *args, "-o", str(out)])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_plan_part_on_a_urdf_robot_takes_the_baseline_as_its_placement(tmp_path, capsys):
    """A URDF robot has no default placement: ``plan --part`` refused it even with --baseline and
    every range given (``[T_base_work]: … give T_base_work``, an option plan does not have). The
    baseline now places the cell; without one, the error names --baseline."""
    from pathlib import Path

    urdf = Path(__file__).parent / "data" / "urdf" / "m900ia260l.urdf"
    part = tmp_path / "cone.toml"
    save_part(Cone(depth=20e-3), part)
    K = tmp_path / "K.toml"
    K.write_text("[stiffness]\nK = [3.7e6, 4.8e6, 4.0e6, 6.4e5, 7.6e5, 4.7e5]\n")
    base = ["plan", "--part", str(part), "--robot", str(urdf), "--stiffness", str(K), "--serial"]
    grid = ["--x-range", "1800,2200", "--y-range", "0", "--z-range", "300"]
    out = tmp_path / "plan"
    assert main([*base, *grid, "--baseline", "2000,0,300,0", "-o", str(out)]) == 0
    s = json.loads((out / "plan.json").read_text())["summary"]
    assert s["baseline placement x,y,z [mm], yaw [deg]"] == [2000.0, 0.0, 300.0, 0.0]
    capsys.readouterr()
    out2 = tmp_path / "plan2"
    assert main([*base, *grid, "-o", str(out2)]) == 2
    err = capsys.readouterr().err
    assert "[--baseline]" in err and "no default placement" in err and "T_base_work" not in err
    assert not out2.exists()


def test_plan_needs_one_source(cone_toml, tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["plan", "-o", str(out)]) == 2
    assert main(["plan", "--part", str(cone_toml), "--study", str(tmp_path), "-o", str(out)]) == 2
    assert "exactly one of --part or --study" in capsys.readouterr().err
    assert not out.exists()


def test_parse_range():
    assert parse_range("0:90:4", "f").tolist() == [0.0, 30.0, 60.0, 90.0]
    assert parse_range("5", "f").tolist() == [5.0]
    assert parse_range("5:5:1", "f").tolist() == [5.0]
    with pytest.raises(InputError, match="count 1"):
        parse_range("0:5:1", "f")
    with pytest.raises(InputError, match="finite"):
        parse_range("1,inf", "f")


@pytest.mark.parametrize("own_process", [True, False])
def test_only_the_console_script_sets_the_heap_policy(
    cone_toml, tmp_path, monkeypatch, own_process
):
    """``roboisf plan`` keeps freed memory for its next placement (a process-wide allocator
    setting): in its own process only — ``main()`` called inside another program (as here)
    leaves that program's allocator alone."""
    from roboisf.cli.console import state
    from roboisf.jit import heap

    calls: list[int] = []
    monkeypatch.setattr(heap, "hold_freed_memory", lambda: calls.append(1) or True)
    monkeypatch.setattr(state, "own_process", own_process)
    small = ["--x-range", "1800", "--y-range", "0", "--z-range", "200", "--serial"]
    assert main(["plan", "--part", str(cone_toml), *small, "-o", str(tmp_path / "p")]) == 0
    assert calls == ([1] if own_process else [])
    assert state.own_process is own_process  # main() does not set it; entry() does


def test_the_console_script_marks_its_process_as_the_commands(monkeypatch):
    import signal

    import roboisf.cli.main as cli_main
    from roboisf.cli.console import state

    seen: list[bool] = []
    monkeypatch.setattr(cli_main, "main", lambda: seen.append(state.own_process) or 0)
    monkeypatch.setattr(state, "own_process", False)
    # the console script freezes the garbage collector's objects once the command is done
    # (its shutdown skips them); not this test process's
    monkeypatch.setattr(cli_main.gc, "freeze", lambda: seen.append("frozen"))
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(SystemExit) as e:
            cli_main.entry()
    finally:
        for s, h in handlers.items():  # entry() ignores both signals once it has decided
            signal.signal(s, h)
    assert e.value.code == 0 and seen == [True, "frozen"]


def test_the_console_script_exits_with_the_objects_frozen(tmp_path):
    import subprocess
    import sys

    code = (
        "import atexit, gc, sys\n"
        "atexit.register(lambda: print('frozen at exit:', gc.get_freeze_count() > 0))\n"
        "from roboisf.cli.main import entry\n"
        "sys.argv = ['roboisf', '--version']\n"
        "entry()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "frozen at exit: True" in r.stdout


@pytest.mark.parametrize("own_process", [True, False])
def test_a_command_freezes_its_imports_only_in_its_own_process(monkeypatch, own_process):
    import gc

    from roboisf.cli.console import state

    calls: list[int] = []
    monkeypatch.setattr(gc, "freeze", lambda: calls.append(1))
    monkeypatch.setattr(state, "own_process", own_process)
    state.imports_done()
    assert calls == ([1] if own_process else [])


def test_analyze_freezes_its_imports_before_the_analysis(monkeypatch, tmp_path, small_cone_study):
    # the console script's analyze: the libraries' objects frozen once imported, before the
    # analysis allocates (its full collections then skip them)
    import roboisf.cli.analyze as cli_analyze
    from roboisf.cli.console import state
    from roboisf.cli.main import main

    order: list[str] = []
    monkeypatch.setattr(state, "imports_done", lambda: order.append("frozen"))

    def fake_analyze(*a, **k):
        order.append("analysis")
        raise KeyboardInterrupt  # stop here: main() reports it as exit 130

    monkeypatch.setattr(cli_analyze, "_analyze_runs", fake_analyze)
    code = main(["-q", "analyze", str(small_cone_study), "-o", str(tmp_path / "out")])
    assert code == 130 and order == ["frozen", "analysis"]


@pytest.mark.parametrize("command", ["plan", "predict"])
def test_help_states_the_default_placement_used(command, capsys):
    """The help said the default baseline/placement was (2200,0,200,0) while the IRB 7600's is
    PAPER_CELL_PLACEMENT, 0.5 m to the robot's right: (2200,-500,200,0)."""
    from roboisf.cell import PAPER_CELL_PLACEMENT

    x, y, z = (round(float(v) * 1e3) for v in PAPER_CELL_PLACEMENT[:3, 3])
    assert main([command, "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert f"({x},{y},{z},0)" in text
    assert "(2200,0,200,0)" not in text
