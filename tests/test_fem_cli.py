"""``roboisf tool-stiffness`` / ``roboisf holder-stiffness`` end to end."""

import json

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.fem import load_compliance_json


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


def test_tool_stiffness_from_a_step_file(tmp_path):
    from roboisf.fem import step_faces
    from roboisf.fem.mesh import gmsh_session

    step = tmp_path / "rod.step"
    with gmsh_session() as (gmsh, _):
        gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, 40, 5)
        gmsh.model.occ.synchronize()
        gmsh.write(str(step))
    planes = {r["face"]: r["bbox_mm"] for r in step_faces(step) if r["type"] == "Plane"}
    top = next(f for f, bb in planes.items() if bb[2] > 39)
    bottom = next(f for f, bb in planes.items() if bb[5] < 1)
    out = tmp_path / "rod.json"
    argv = [
        "-q",
        "tool-stiffness",
        "--step",
        str(step),
        "--clamped",
        str(top),
        "--coupling",
        str(bottom),
        "--reference",
        "0",
        "0",
        "-10",
        "--mesh-size",
        "4",
        "--no-convergence",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    res = load_compliance_json(out)
    assert np.allclose(res.reference_point, [0, 0, -0.01])
    assert res.geometry["type"] == "step" and res.geometry["clamped"] == [str(top)]
    # about a point 10 mm below the end face: the beam with that reference point (lever arm)
    from roboisf.fem import STEEL, beam_compliance
    from roboisf.fem.geometry import ShaftSegment

    beam = beam_compliance(
        [ShaftSegment(0, 0.04, 0.01, 0.01)], STEEL, reference_point=[0, 0, -0.01]
    )
    assert abs(res.compliance[0, 0] / beam[0, 0] - 1) < 0.02
    assert (
        res.compliance[0, 0]
        > 1.8 * beam_compliance([ShaftSegment(0, 0.04, 0.01, 0.01)], STEEL)[0, 0]
    )
    # the STEP file is an input: -o onto it is refused and the file is left alone
    before = step.read_bytes()
    argv[-1] = str(step)
    assert main(argv) == 2
    assert step.read_bytes() == before


@pytest.mark.parametrize(
    ("argv", "hint"),
    [
        (["tool-stiffness", "--no-fe", "--E", "210e9"], "it is 210 GPa if it was written in Pa"),
        (["tool-stiffness", "--no-fe", "--E", "210000"], "it is 210 GPa if it was written in MPa"),
        (["holder-stiffness", "--no-fe", "--section", "100:50", "--E", "2.1e11"], "in Pa"),
    ],
)
def test_youngs_modulus_in_pa_is_refused(tmp_path, argv, hint, capsys):
    """--E is in GPa: 210e9 (Pa) was accepted and wrote a compliance 1e9 times too small
    (7e-16 m/N for the paper's tool); now one line naming --E and the unit slip, exit 2."""
    out = tmp_path / "out.json"
    assert main([*argv, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "[--E]" in err and hint in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["tool-stiffness", "--mesh-size", "-1"], "[--mesh-size]: must be > 0 mm, got -1"),
        (["tool-stiffness", "--neck-length", "-1"], "[--neck-length]: must be ≥ 0 mm, got -1"),
        (["tool-stiffness", "--neck-diameter", "8"], "[--neck-diameter]: a neck needs its length"),
        (["tool-stiffness", "--neck-length", "5"], "[--neck-length]: --neck-length needs"),
        (["holder-stiffness", "--section", "40:30", "--coupling-diameter", "-1"],
         "[--coupling-diameter]: must be > 0 mm, got -1"),
    ],
)  # fmt: skip
def test_a_length_option_is_refused_in_mm_under_its_flag(tmp_path, argv, said, capsys):
    """The geometry's own check named its SI key and value in m ("[mesh_size]: … in m, got
    -0.001", "[neck_length]: … got 0.0" for a neck diameter without a length)."""
    out = tmp_path / "out.json"
    assert main([*argv, "--no-fe", "-o", str(out)]) == 2
    assert said in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("cmd", [["tool-stiffness"], ["holder-stiffness", "--section", "40:30"]])
def test_the_compliance_file_must_be_named_json(tmp_path, cmd, capsys):
    """-o t.csv wrote JSON into a .csv; refused, nothing written."""
    out = tmp_path / "t.csv"
    assert main([*cmd, "--no-fe", "-o", str(out)]) == 2
    assert "[--output]" in capsys.readouterr().err and not out.exists()
