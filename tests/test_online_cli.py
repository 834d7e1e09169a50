"""``roboisf online``: bad input is one line and exit 2; replay of a study; the simulated run."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from roboisf.cli.main import main
from roboisf.parts import Cone
from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, build_study, virtual_cell


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--controller", "fanuc", "--virtual", "cone"], "--controller"),
        (["--controller", "egm", "--sensor", "usb:1", "--virtual", "cone"], "--sensor"),
        (["--controller", "egm"], "--study"),
        (["--controller", "egm", "--virtual", "dome"], "--virtual"),
        (
            ["--controller", "egm", "--virtual", "cone", "--simulate", "--sensor", "replay:x"],
            "--simulate",
        ),
        (["--controller", "replay", "--virtual", "cone"], "--controller"),
        (["--controller", "egm", "--virtual", "cone", "--form", "st"], "--form"),
        (["-c", "egm", "--virtual", "pyramid", "--scenario", "paper"], "--scenario"),
        (["-c", "egm", "--virtual", "cone", "--realtime", "0"], "--realtime"),
        (["-c", "egm", "--virtual", "cone", "--cpu", "4096"], "--cpu"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, args, needle):
    code = main(["online", *args, "-o", str(tmp_path / "log.parquet")])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err and "Traceback" not in err
    assert not (tmp_path / "log.parquet").exists()


def test_log_must_be_parquet(tmp_path, capsys):
    code = main(["online", "-c", "egm", "--virtual", "cone", "-o", str(tmp_path / "l.csv")])
    assert code == 2 and ".parquet" in capsys.readouterr().err


def test_replay_controller_writes_the_log_of_a_study(tmp_path):
    vc = virtual_cell(
        "cone-12",
        Cone(depth=12e-3),
        T_base_work=PAPER_CELL_PLACEMENT,
        step_down=1e-3,
        spacing=2e-3,
        scan_points=5000,
    )
    build_study(vc, tmp_path / "study")
    out = tmp_path / "replay.parquet"
    code = main(
        ["-q", "online", "-c", "replay", "-s", f"replay:{tmp_path / 'study'}", "-o", str(out)]
    )
    assert code == 0
    df = pd.read_parquet(out)
    corr = df[["corr_x_mm", "corr_y_mm", "corr_z_mm"]].to_numpy()
    assert len(df) > 100
    assert 0.05 < np.linalg.norm(corr, axis=1).max() <= 2.0  # a real, limited correction
    # a second run into the same file needs --overwrite
    assert (
        main(["-q", "online", "-c", "replay", "-s", f"replay:{tmp_path / 'study'}", "-o", str(out)])
        == 2
    )


@pytest.mark.slow
def test_simulated_run_from_the_command_line(tmp_path):
    out = tmp_path / "log.parquet"
    code = main(
        [
            "-q",
            "online",
            "-c",
            "egm",
            "--virtual",
            "cone",
            "--simulate",
            "--duration",
            "3",
            "--max-correction",
            "0.3",
            "-o",
            str(out),
        ]
    )
    assert code == 0
    df = pd.read_parquet(out)
    assert len(df) > 50
    corr = df[["corr_x_mm", "corr_y_mm", "corr_z_mm"]].to_numpy()
    assert np.linalg.norm(corr, axis=1).max() <= 0.3 * (1 + 1e-12)


def test_ctrl_c_ends_the_loop_and_writes_the_log(tmp_path):
    """SIGINT while serving: exit 0, the log (here of zero cycles) is written, one line says so."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    out = tmp_path / "int.parquet"
    src = str(Path(__file__).parents[1] / "src")
    code = (
        "from roboisf.cli.main import main; raise SystemExit(main(['online', '-c', 'rsi', "
        f"'--virtual', 'cone', '--listen', '127.0.0.1:0', '-o', {str(out)!r}]))"
    )
    env = {**os.environ, "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}
    p = subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        text=True,
    )
    assert p.stdout is not None
    line = p.stdout.readline()  # "online: rsi on 127.0.0.1:PORT …" once it serves
    assert line.startswith("online: rsi"), line
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    rest, err = p.communicate(timeout=60)
    assert p.returncode == 0, err
    assert "stopped: interrupted (Ctrl-C)" in rest and "Traceback" not in err
    assert len(pd.read_parquet(out)) == 0
