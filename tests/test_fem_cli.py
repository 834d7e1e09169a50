"""``roboisf tool-stiffness`` / ``roboisf holder-stiffness`` end to end."""

import json
import sys
import types

import numpy as np
import pytest

from roboisf.fem import load_compliance_json

try:
    from roboisf.cli.main import main
except ImportError:  # the toolpath CLI group is not on this branch yet: stand it in
    _stub = types.ModuleType("roboisf.cli.toolpath")
    _stub.register = lambda app: None  # type: ignore[attr-defined]
    sys.modules["roboisf.cli.toolpath"] = _stub
    from roboisf.cli.main import main


def test_tool_stiffness_beam(tmp_path):
    out = tmp_path / "tool.json"
    code = main(
        [
            "-q",
            "tool-stiffness",
            "--ball-diameter",
            "10",
            "--length",
            "60",
            "--no-fe",
            "-o",
            str(out),
        ]
    )
    assert code == 0
    res = load_compliance_json(out)
    assert res.method == "beam"
    assert 6.5e-7 < res.compliance[0, 0] < 7.5e-7
    assert res.geometry["length"] == pytest.approx(0.06)


def test_tool_stiffness_fe_and_holder_with_tool(tmp_path, capsys):
    tool = tmp_path / "tool.json"
    assert (
        main(
            [
                "tool-stiffness",
                "--ball-diameter",
                "10",
                "--length",
                "40",
                "--mesh-size",
                "4",
                "--no-convergence",
                "--solver",
                "superlu",
                "-o",
                str(tool),
            ]
        )
        == 0
    )
    printed = capsys.readouterr()
    assert "lateral" in printed.out and "symmetry error" in printed.out
    data = json.loads(tool.read_text())
    assert data["method"] == "fe" and data["quality"]["solver"] == "superlu"
    both = tmp_path / "both.json"
    assert (
        main(
            [
                "-q",
                "holder-stiffness",
                "--section",
                "30:25",
                "--section",
                "20:40:0:35",
                "--coupling-diameter",
                "10",
                "--mesh-size",
                "5",
                "--no-convergence",
                "--with-tool",
                str(tool),
                "-o",
                str(both),
            ]
        )
        == 0
    )
    res = load_compliance_json(both)
    kt = load_compliance_json(tool).compliance
    assert res.method == "assembly"
    assert res.compliance[0, 0] > kt[0, 0]
    assert np.allclose(res.compliance, res.compliance.T, rtol=0, atol=1e-12 * np.abs(kt).max())


@pytest.mark.parametrize(
    "argv",
    [
        ["tool-stiffness", "--ball-diameter", "0", "--no-fe"],
        ["tool-stiffness", "--length", "-5", "--no-fe"],
        ["tool-stiffness", "--nu", "0.5", "--no-fe"],
        ["tool-stiffness", "--method", "magic"],
        ["holder-stiffness", "--section", "30", "--no-fe"],
        ["holder-stiffness", "--section", "30:20:10", "--section", "30:40:25", "--no-fe"],
        [
            "tool-stiffness",
            "--step",
            "missing.step",
            "--clamped",
            "1",
            "--coupling",
            "2",
            "--mesh-size",
            "2",
        ],
    ],
)
def test_bad_input_exit_2_and_no_output(tmp_path, argv, capsys):
    out = tmp_path / "out.json"
    assert main([*argv, "-o", str(out)]) == 2
    assert "error" in capsys.readouterr().err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []
