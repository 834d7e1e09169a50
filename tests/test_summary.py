"""``summary.json`` as typed, versioned value objects: one serialiser, one reader with clear
errors, and the published JSON Schema generated from the dataclasses (docs/summary.md)."""

from __future__ import annotations

import dataclasses
import json

import jsonschema
import pytest

from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.summary import (
    SCHEMA_VERSION,
    AnalysisSummary,
    RobotInfo,
    RobotOnlySummary,
    ToolInfo,
    Units,
    dumps,
    from_json,
    json_schema,
    read_summary,
    schema_text,
)
from summary_check import SCHEMA_FILE, minimal_summary, schema


def test_the_published_schema_is_the_generated_one():
    # regenerate with: python -c "from roboisf.summary import schema_text; \
    #   open('docs/summary.schema.json', 'w').write(schema_text())"
    assert SCHEMA_FILE.read_text(encoding="utf-8") == schema_text()
    jsonschema.Draft202012Validator.check_schema(json_schema())
    props = json_schema()["$defs"]["AnalysisSummary"]["properties"]
    assert props["schema_version"]["const"] == SCHEMA_VERSION
    assert "[mm]" in props["rim_band_mm"]["description"]  # units in the field docs
    fields = [f.name for f in dataclasses.fields(AnalysisSummary)]
    assert sorted(props) == sorted(fields)


def test_the_serialiser_writes_the_version_first_and_optional_sections_only_when_set():
    s = minimal_summary()
    data = json.loads(dumps(s))
    assert list(data)[:3] == ["schema_version", "study", "description"]
    assert data["schema_version"] == SCHEMA_VERSION
    assert "truth" not in data and "robot_run" not in data and "iterations" not in data
    assert data["identified_stiffness"] is None  # a null field is written, not left out
    assert data["vjm_vs_experiment"] == {"x": 0.5, "resultant": None}  # NaN as null
    assert dumps(s).startswith('{\n  "schema_version": 1,\n  "study": "s"')  # indent 2
    t = dataclasses.replace(s, truth={"rms_error_dn_mm": {}}, robot_run="robot")
    keys = list(json.loads(dumps(t)))
    assert keys[-2:] == ["truth", "robot_run"]


def test_the_reader_reads_what_the_serialiser_writes(tmp_path):
    s = minimal_summary(robot_run="robot", iterations=[{"run": "robot", "mean_abs_dn_mm": 0.2}])
    f = tmp_path / "summary.json"
    f.write_text(dumps(s), encoding="utf-8")
    back = read_summary(tmp_path)  # the results folder or the file
    assert isinstance(back, AnalysisSummary)
    assert back.robot == s.robot and back.tool == s.tool and back.units == s.units
    assert back.robot_run == "robot" and back.iterations == s.iterations
    assert back.vjm_vs_experiment["resultant"] is None
    assert dumps(back) == f.read_text(encoding="utf-8")
    ro = RobotOnlySummary(
        study="s",
        run="robot",
        kind="robot-only",
        robot="irb",
        joint_angles="ik",
        springback_model_based={"separable": False, "beta": float("nan")},
        modelled_mean_abs_dn_mm={"tool": 0.1},
        measured_mean_abs_dn_mm=0.2,
        warnings=[],
    )
    back_ro = from_json(dumps(ro))
    assert isinstance(back_ro, RobotOnlySummary) and back_ro.run == "robot"
    assert back_ro.springback_model_based["beta"] is None  # valid JSON: no NaN literal
    for obj in (s, ro):
        jsonschema.Draft202012Validator(schema()).validate(json.loads(dumps(obj)))


@pytest.mark.parametrize(
    ("edit", "field", "words"),
    [
        (lambda d: d.update(schema_version=SCHEMA_VERSION + 1), "schema_version", "re-run"),
        (lambda d: d.pop("schema_version"), "schema_version", "before summaries were versioned"),
        (lambda d: d.pop("n_points"), "n_points", "missing field"),
        (lambda d: d["tool"].update(ball_diameter_mm="ten"), "tool.ball_diameter_mm", "number"),
        (lambda d: d["tool"].pop("method"), "tool.method", "missing field"),
        (lambda d: d.update(warnings=["ok", 3]), "warnings[1]", "a string"),
        (lambda d: d.update(n_points=3.5), "n_points", "an integer"),
        (lambda d: d.update(diagnosis_forces_corrected=1), "diagnosis_forces_corrected", "true"),
        (lambda d: d.update(extra=1), "extra", "unknown field"),
        (lambda d: d["robot"].update(placement_T_base_work_m=[[1, "x"]]), "placement", "number"),
    ],
)
def test_a_file_of_another_version_or_a_bad_field_is_named(tmp_path, edit, field, words):
    data = json.loads(dumps(minimal_summary()))
    edit(data)
    f = tmp_path / "summary.json"
    f.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(InputError) as e:
        read_summary(f)
    msg = str(e.value)
    assert str(f) in msg and field in (e.value.field or "") and words in msg, msg
    assert "\n" not in msg
    # the schema refuses the same file (it is not looser than the reader)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.Draft202012Validator(schema()).validate(data)


@pytest.mark.parametrize(("text", "words"), [("{", "not JSON"), ("[1]", "a JSON object")])
def test_a_file_that_is_not_a_summary_is_named(tmp_path, text, words):
    f = tmp_path / "summary.json"
    f.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=words) as e:
        read_summary(f)
    assert str(f) in str(e.value)
    with pytest.raises(InputError, match="cannot read"):
        read_summary(tmp_path / "none.json")


def test_history_add_refuses_a_summary_of_another_version(tmp_path, capsys):
    res = tmp_path / "res"
    res.mkdir()
    for name in ("per_point.parquet", "contributions.csv", "contributions_normal.csv"):
        (res / name).write_text("")
    data = json.loads(dumps(minimal_summary()))
    data["schema_version"] = 0
    (res / "summary.json").write_text(json.dumps(data), encoding="utf-8")
    code = main(["history", "add", str(res), "--db", str(tmp_path / "h.db")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "summary.json [schema_version]" in err and "re-run roboisf analyze" in err
    assert not (tmp_path / "h.db").exists()


def test_compensate_reads_the_robot_run_through_the_reader(tmp_path):
    from roboisf.compensate.study import _check_results_run

    (tmp_path / "summary.json").write_text(dumps(minimal_summary(robot_run="robot_2")))
    _check_results_run(tmp_path, "robot_2")
    with pytest.raises(InputError, match="robot run 'robot_2', not 'robot'"):
        _check_results_run(tmp_path, "robot")
    data = json.loads(dumps(minimal_summary()))
    del data["schema_version"]  # an output of an older roboisf
    (tmp_path / "summary.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="schema_version"):
        _check_results_run(tmp_path, "robot")


def test_every_field_is_documented():
    text = (SCHEMA_FILE.parent / "summary.md").read_text(encoding="utf-8")
    for cls in (AnalysisSummary, RobotInfo, ToolInfo, Units, RobotOnlySummary):
        assert f"### `{cls.__name__}`" in text
        for f in dataclasses.fields(cls):
            assert f"| `{f.name}` |" in text, f"{cls.__name__}.{f.name} not in docs/summary.md"
