"""Bad inputs of issue #11, one named test each: a clear InputError naming the file and the line
or key, never a traceback from a library or a crashed process."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.io.text import decode_utf8
from roboisf.logs.forcelog import ForceLog, read_force_log, write_force_log
from roboisf.parts import Cone
from roboisf.parts.io import load_part, read_profile_csv
from roboisf.robot.presets import _preset_dir
from roboisf.scan import check_units, read_scan, write_ply
from roboisf.study.checks import check_force_log, check_tool_radius
from roboisf.study.spec import StudyError, load_study
from roboisf.toolpath.generate import MAX_POINTS, estimate_points, spiral, step_down

PLY_HEAD = "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
PLY_HEAD += "property float y\nproperty float z\nend_header\n"


def _ply(path: Path, n_header: str, n_data: int = 3) -> Path:
    path.write_bytes(PLY_HEAD.format(n=n_header).encode() + np.zeros(3 * n_data, "<f4").tobytes())
    return path


# -- PLY / PCD headers -----------------------------------------------------------------------------
def test_ply_negative_element_count_is_refused_not_sigfpe(tmp_path):
    # in a child process: before the header check this killed the interpreter (SIGFPE, exit 136)
    f = _ply(tmp_path / "neg.ply", "-1")
    code = f"from roboisf.scan import read_scan; read_scan({str(f)!r})"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, (r.returncode, r.stderr)  # an exception, not a signal
    assert "InputError" in r.stderr and "neg.ply:3" in r.stderr
    assert "non-negative integer" in r.stderr


@pytest.mark.parametrize("count", ["1000000000000000", "99999999999999999999999"])
def test_ply_absurd_element_count_is_refused(tmp_path, count):
    f = _ply(tmp_path / "big.ply", count)
    with pytest.raises(InputError, match=r"big\.ply:3"):
        read_scan(f)


def test_ply_count_larger_than_the_data_is_refused(tmp_path):
    f = _ply(tmp_path / "short.ply", "10", n_data=3)
    with pytest.raises(InputError, match=r"short\.ply:3.*10 rows.*120 bytes.*36"):
        read_scan(f)


def test_ply_unknown_property_type_is_refused(tmp_path):
    f = tmp_path / "t.ply"
    f.write_bytes(PLY_HEAD.format(n=1).replace("float z", "float128 z").encode() + b"\0" * 12)
    with pytest.raises(InputError, match=r"t\.ply:6.*property"):
        read_scan(f)


def test_a_valid_ply_still_reads(tmp_path):
    f = _ply(tmp_path / "ok.ply", "3")
    assert read_scan(f).n_points == 3


@pytest.mark.parametrize("points", ["-5", "1e9", "abc"])
def test_pcd_bad_point_count_is_refused(tmp_path, points):
    f = tmp_path / "s.pcd"
    f.write_bytes(
        f"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS {points}\nDATA binary\n".encode()
        + b"\0" * 12
    )
    with pytest.raises(InputError, match=r"s\.pcd"):
        read_scan(f)


# -- scans ---------------------------------------------------------------------------------------
def test_zero_extent_scan_is_refused():
    pts = np.tile([0.01, 0.02, -0.03], (50, 1))
    with pytest.raises(InputError, match=r"scan\.ply.*zero extent.*50 point"):
        check_units(pts, 0.1, unit="mm", source="scan.ply")


def test_zero_extent_scan_through_the_cli(tmp_path):
    scan = tmp_path / "flat.ply"
    write_ply(np.tile([0.01, 0.0, -0.02], (20, 1)), scan)
    part = tmp_path / "cone.toml"
    assert main(["-q", "part", "cone", "-o", str(part)]) == 0
    out = tmp_path / "dev.parquet"
    assert main(["-q", "scan", "compare", str(scan), "--part", str(part), "-o", str(out)]) == 2
    assert not out.exists()


# -- encodings -----------------------------------------------------------------------------------
def test_decode_names_line_and_byte_offset():
    with pytest.raises(InputError, match=r"f\.csv:3.*0xe9 at byte offset 8"):
        decode_utf8(b"a,b\n1,2\n\xe9\n", file="f.csv")
    assert decode_utf8(b"\xef\xbb\xbfa", file="f.csv") == "a"


def test_latin1_profile_is_refused_with_line(tmp_path):
    f = tmp_path / "p.csv"
    f.write_bytes("r,z\n# mesur\xe9\n40,0\n30,-10\n".encode("latin-1"))
    with pytest.raises(InputError, match=r"p\.csv:2.*not UTF-8"):
        read_profile_csv(f)


def test_utf16_force_log_is_refused_with_line(tmp_path):
    f = tmp_path / "f.csv"
    f.write_bytes("# units: time=s force=N moment=N*m\ntime,Fx\n".encode("utf-16"))
    with pytest.raises(InputError, match=r"f\.csv:1.*not UTF-8.*UTF-16"):
        read_force_log(f)


@pytest.mark.parametrize("content", [b"", b"\r\n\r\n", b"\xef\xbb\xbf\n  \n"])
def test_empty_log_is_said_to_be_empty(tmp_path, content):
    """An empty force or joint log (a logger that never wrote, a failed copy) was refused as "no
    force-log format recognised: expected a header naming time, Fx …" — the user then hunts for
    a header problem in a file that has nothing."""
    from roboisf.logs.jointlog import read_joint_log

    f = tmp_path / "log.csv"
    f.write_bytes(content)
    for read, what in ((read_force_log, "force log"), (read_joint_log, "joint log")):
        with pytest.raises(InputError, match=rf"log\.csv: {what} is empty") as e:
            read(f)
        assert "recognised" not in str(e.value)


def test_bom_csv_is_accepted(tmp_path):
    f = tmp_path / "f.csv"
    log = ForceLog(np.array([0.0, 1.0]), np.ones((2, 6)) * 100, "sensor")
    write_force_log(log, f)
    f.write_bytes(b"\xef\xbb\xbf" + f.read_bytes())
    np.testing.assert_allclose(read_force_log(f).wrench, log.wrench)


PART = '[part]\nkind = "cone"\nopening_diameter = 87\nwall_angle = 71\ndepth = 50\n'


def test_bom_part_toml_is_accepted(tmp_path):
    f = tmp_path / "p.toml"
    f.write_bytes(b"\xef\xbb\xbf" + PART.encode())
    assert load_part(f).depth == pytest.approx(0.05)


def test_latin1_part_toml_is_refused(tmp_path):
    f = tmp_path / "p.toml"
    f.write_bytes((PART + "# r\xe9glage\n").encode("latin-1"))
    with pytest.raises(InputError, match=r"p\.toml:6.*byte offset"):
        load_part(f)


# -- study.toml ------------------------------------------------------------------------------------
STUDY = """[study]
name = "t"
[part]
kind = "cone"
opening_diameter = 87
wall_angle = 71
depth = 50
[tool]
ball_diameter = 10
compliance = "tool.json"
[tool_holder]
compliance = "holder.json"
offset = 66
[robot]
model = "irb7600-500-2.55"
placement = [1800, 0, 500, 0, 0, 0]
[runs.cnc]
machine = "cnc"
toolpath = "path.csv"
scan = "cnc.ply"
forces = { file = "cnc_f.csv", mount = "fixture", pose = [0, 0, -60, 0, 0, 0] }
[runs.robot]
machine = "robot"
toolpath = "path.csv"
scan = "robot.ply"
joints = "joints.csv"
forces = { file = "rob_f.csv", mount = "flange", pose = [0, 0, -190, 180, 0, 0] }
"""


def study(root: Path, text: str = STUDY, *, raw: bytes | None = None) -> Path:
    for f in ("path.csv", "cnc.ply", "robot.ply", "cnc_f.csv", "rob_f.csv", "joints.csv"):
        (root / f).write_text("x")
    for f in ("tool.json", "holder.json"):
        (root / f).write_text("x")
    (root / "study.toml").write_bytes(raw if raw is not None else text.encode())
    return root


def test_the_reference_study_loads(tmp_path):
    assert load_study(study(tmp_path)).name == "t"


def test_bom_study_is_accepted(tmp_path):
    s = load_study(study(tmp_path, raw=b"\xef\xbb\xbf" + STUDY.encode()))
    assert s.name == "t"


def test_latin1_study_is_refused_with_line_and_offset(tmp_path):
    raw = STUDY.replace('name = "t"', 'name = "\xe9tude"').encode("latin-1")
    with pytest.raises(InputError, match=r"study\.toml:2.*byte offset 16"):
        load_study(study(tmp_path, raw=raw))


@pytest.mark.parametrize(
    ("old", "new", "key", "expected"),
    [
        ('kind = "cone"', 'kind = ["cone"]', "part.kind", "unknown part kind"),
        ("[part]", '[units]\nlength = ["mm"]\n[part]', "units.length", "unknown unit"),
        ('file = "cnc_f.csv"', "file = 5", "runs.cnc.forces.file", "expected a file name"),
        ('name = "t"', "name = 3", "study.name", "expected a string"),
        ('toolpath = "path.csv"', "toolpath = true", "runs.cnc.toolpath", "expected a file"),
        ('machine = "cnc"', 'machine = ["cnc"]', "runs.cnc.machine", "expected one of"),
        ("ball_diameter = 10", 'ball_diameter = "10"', "tool.ball_diameter", "finite number"),
        ("offset = 66", 'offset = 66\nrigid = "no"', "tool_holder.rigid", "true or false"),
        ("offset = 66", "offset = 66\nrigid = 0", "tool_holder.rigid", "true or false"),
        ('scan = "cnc.ply"', 'scan = "cnc.ply"\nscan_unit = 1', "runs.cnc.scan_unit", "unit"),
    ],
    ids=lambda v: v if isinstance(v, str) and "." in v and " " not in v else None,
)
def test_wrong_value_types_name_the_key(tmp_path, old, new, key, expected):
    assert old in STUDY
    with pytest.raises(StudyError) as e:
        load_study(study(tmp_path, STUDY.replace(old, new, 1)))
    msg = str(e.value)
    assert f"[{key}]" in msg and expected in msg, msg


def test_part_that_is_not_a_table(tmp_path):
    text = 'part = "x"\n' + STUDY.replace("[part]", "[partx]")
    text = text.replace("[partx]\n", "").replace('kind = "cone"\n', "")
    for k in ("opening_diameter = 87\n", "wall_angle = 71\n", "depth = 50\n"):
        text = text.replace(k, "")
    with pytest.raises(StudyError, match=r"\[part\].*expected a table"):
        load_study(study(tmp_path, text))


def test_rigid_holder_must_be_a_boolean_true_still_works(tmp_path):
    text = STUDY.replace('compliance = "holder.json"\noffset = 66', "rigid = true")
    assert load_study(study(tmp_path, text)).holder.rigid is True


def test_robot_file_is_relative_to_the_study_folder(tmp_path, monkeypatch):
    root = tmp_path / "study"
    (root / "robots").mkdir(parents=True)
    preset = (_preset_dir() / "irb7600-500-2.55.toml").read_text(encoding="utf-8")
    (root / "robots" / "mine.toml").write_text(preset, encoding="utf-8")
    text = STUDY.replace('model = "irb7600-500-2.55"', 'model = "robots/mine.toml"')
    study(root, text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    s = load_study(root)
    assert Path(s.robot.model) == (root / "robots" / "mine.toml").resolve()
    from roboisf.cell import build_robot

    assert build_robot(s.robot.model).name  # loads from the study folder, not the cwd


def test_missing_robot_file_names_the_study_folder(tmp_path):
    text = STUDY.replace('model = "irb7600-500-2.55"', 'model = "robots/none.toml"')
    with pytest.raises(StudyError, match=r"\[robot\.model\].*relative to the study folder"):
        load_study(study(tmp_path, text))


def test_placement_out_of_reach_is_refused(tmp_path):
    text = STUDY.replace("placement = [1800, 0, 500", "placement = [1e9, 0, 500")
    with pytest.raises(StudyError, match=r"\[robot\.placement\[x\]\].*outside what a real cell"):
        load_study(study(tmp_path, text))
    text = STUDY.replace("placement = [1800, 0, 500", "placement = [5000, 0, 500")
    with pytest.raises(StudyError, match=r"\[robot\.placement\].*out of reach"):
        load_study(study(tmp_path, text))
    # in reach with the part's extent: 2.55 m + links is fine
    ok = STUDY.replace("placement = [1800, 0, 500", "placement = [2400, 0, 300")
    load_study(study(tmp_path, ok))


# -- plausibility across files ---------------------------------------------------------------------
def _tp():
    part = Cone(opening_diameter=0.06, wall_angle=math.radians(45), depth=0.01)
    return step_down(part, 5e-3, 2e-3, spacing=5e-3)


def test_ball_diameter_contradicting_the_toolpath(tmp_path):
    tp = _tp()
    check_tool_radius(10e-3, tp, study_file=tmp_path / "study.toml")  # Ø10, R = 5: fine
    with pytest.raises(InputError, match=r"\[tool\.ball_diameter\].*Ø10 mm ball"):
        check_tool_radius(12e-3, tp, study_file=tmp_path / "study.toml")


def _log(tp, scale=1.0, position=None, extra=0.0):
    t = np.linspace(0, tp.time[-1] + extra, 200)
    w = np.column_stack([0 * t + 50, 0 * t, 0 * t + 400, 0 * t + 2, 0 * t, 0 * t]) * scale
    return ForceLog(t, w, "sensor", Path("f.csv"), position)


def test_forces_1000_times_too_large_are_refused():
    tp = _tp()
    assert check_force_log(_log(tp), tp) == []
    with pytest.raises(InputError, match=r"f\.csv.*kN.*units"):
        check_force_log(_log(tp, 1000.0), tp)


def test_force_limits_are_on_the_99th_percentile_not_on_spikes():
    """A few samples above the limits (a spike, under 1 % of the log) pass; a log above them
    throughout is refused, forces and moments alike."""
    from roboisf.study.checks import FORCE_MAX, MOMENT_MAX

    tp = _tp()
    log = _log(tp)
    log.wrench[:1, 2] = 2 * FORCE_MAX  # 1 sample in 200
    log.wrench[1:2, 3] = 2 * MOMENT_MAX
    assert check_force_log(log, tp) == []
    log.wrench[:, 3] = 2 * MOMENT_MAX
    with pytest.raises(InputError, match=r"kN·m \(99th percentile of \|M\|\)"):
        check_force_log(log, tp)


def test_forces_1000_times_too_small_are_refused():
    tp = _tp()
    with pytest.raises(InputError, match=r"f\.csv.*no forming force"):
        check_force_log(_log(tp, 1e-3), tp)


def test_logged_positions_of_another_path_are_refused():
    tp = _tp()
    t = np.linspace(0, tp.time[-1], 200)
    on_path = np.column_stack([np.interp(t, tp.time, tp.tip[:, j]) for j in range(3)])
    assert check_force_log(_log(tp, position=on_path), tp) == []
    with pytest.raises(InputError, match=r"f\.csv.*another path"):
        check_force_log(_log(tp, position=on_path + np.array([0.02, 0.0, 0.0])), tp)


def test_a_log_much_longer_than_the_path_is_a_warning():
    tp = _tp()
    (w,) = check_force_log(_log(tp, extra=600.0), tp)
    assert "past the end of the toolpath" in w


# -- toolpath size -----------------------------------------------------------------------------
CONE = Cone(opening_diameter=0.087, wall_angle=math.radians(71), depth=0.10297)


def test_a_toolpath_too_large_is_refused_before_generating():
    # refused from the estimate: generating these 170 M points would exhaust the memory first
    with pytest.raises(InputError, match=r"\[step_down\].*about .* points.*GB.*limit"):
        step_down(CONE, 5e-3, 0.0001e-3)
    with pytest.raises(InputError, match=r"\[step_down\].*points"):
        spiral(CONE, 5e-3, 0.0001e-3)


def test_point_estimate_matches_the_generated_count():
    for step, spacing, wall in ((0.5e-3, 1e-3, None), (1e-3, 2e-3, 0.5e-3)):
        n = len(step_down(CONE, 5e-3, step, spacing=spacing, max_wall_step=wall))
        est = estimate_points(CONE, 5e-3, step, spacing, wall)
        assert abs(est / n - 1) < 0.15, (step, n, est)


def test_the_limit_can_be_raised_or_lifted():
    n = len(step_down(CONE, 5e-3, 5e-3, spacing=5e-3))
    with pytest.raises(InputError, match="limit of 100"):
        step_down(CONE, 5e-3, 5e-3, spacing=5e-3, max_points=100)
    assert len(step_down(CONE, 5e-3, 5e-3, spacing=5e-3, max_points=None)) == n
    assert MAX_POINTS >= 1_000_000


def test_cli_toolpath_with_a_tiny_step_down_exits_2(tmp_path):
    out = tmp_path / "p.csv"
    assert main(["-q", "toolpath", "cone", "--step-down", "0.0001", "-o", str(out)]) == 2
    assert not out.exists()


def test_sliced_paths_on_any_part_are_bounded_too(tmp_path, capsys):
    """The slicer (pyramids, meshes) estimates its size from the part's bounds before slicing:
    an upper estimate (≥ the generated count), refused above --max-points, which lifts it."""
    from roboisf.parts import Pyramid
    from roboisf.toolpath.slice import estimate_sliced_points, sliced_spiral, sliced_step_down

    pyr = Pyramid(60e-3, 40e-3, math.radians(55.0), 12e-3, corner_radius=5e-3)
    n = len(sliced_step_down(pyr, 5e-3, 2e-3, spacing=2e-3))
    assert n <= estimate_sliced_points(pyr, 2e-3, 2e-3) <= 3 * n
    for fn in (sliced_step_down, sliced_spiral):
        with pytest.raises(InputError, match=r"\[step_down\].*about .* points.*limit of 100"):
            fn(pyr, 5e-3, 2e-3, spacing=2e-3, max_points=100)
        with pytest.raises(InputError, match="points"):
            fn(pyr, 5e-3, 0.0001e-3)  # 120 k laps: refused before slicing
    part = tmp_path / "pyr.toml"
    assert main(["-q", "part", "pyramid", "--top-length", "60", "--top-width", "40",
                 "--depth", "12", "-o", str(part)]) == 0  # fmt: skip
    out = tmp_path / "p.csv"
    args = ["-q", "toolpath", "--part", str(part), "--step-down", "2", "--spacing", "2"]
    assert main([*args, "--max-points", "100", "-o", str(out)]) == 2
    assert "--max-points" in capsys.readouterr().err and not out.exists()
    assert main([*args, "--max-points", "1000000", "-o", str(out)]) == 0 and out.exists()


def test_latin1_point_list_is_refused_with_line(tmp_path):
    f = tmp_path / "s.xyz"
    f.write_bytes("x,y,z\n1,2,3\n4,5,6\n7,8,9\xb5\n".encode("latin-1"))
    with pytest.raises(InputError, match=r"s\.xyz:4.*not UTF-8"):
        read_scan(f)


def test_latin1_robot_file_of_a_study_is_refused(tmp_path):
    preset = (_preset_dir() / "irb7600-500-2.55.toml").read_text(encoding="utf-8")
    (tmp_path / "mine.toml").write_bytes(b"# r\xe9glages\n" + preset.encode())
    text = STUDY.replace('model = "irb7600-500-2.55"', 'model = "mine.toml"')
    with pytest.raises(StudyError, match=r"mine\.toml:1 \[robot\.model\].*not UTF-8"):
        load_study(study(tmp_path, text))
    (tmp_path / "mine.toml").write_bytes(b"\xef\xbb\xbf" + preset.encode())  # BOM: fine
    assert load_study(tmp_path).robot is not None


@pytest.mark.parametrize(
    ("table", "key", "expected"),
    [
        ('kind = ["cone"]', "part.kind", "unknown part kind"),
        ('kind = "profile"\nfile = 5', "part.file", "expected a non-empty string"),
        ('kind = "profile"\nr = "40, 30"\nz = [0, -10]', "part.r", "list of finite numbers"),
        ('kind = "profile"\nr = [40, true]\nz = [0, -10]', "part.r", "list of finite numbers"),
        (
            'kind = "cone"\nopening_diameter = "87"\nwall_angle = 71\ndepth = 5',
            "part.opening_d",
            "a number",
        ),
        ('kind = "mesh"\nfile = "m.stl"\nunit = 1', "part.unit", "expected a non-empty string"),
    ],
)
def test_part_toml_wrong_types_name_the_key(tmp_path, table, key, expected):
    f = tmp_path / "p.toml"
    f.write_text("[part]\n" + table + "\n")
    with pytest.raises(InputError) as e:
        load_part(f)
    assert f"[{key}" in str(e.value) and expected in str(e.value), str(e.value)


def test_part_table_that_is_not_a_table(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text('part = "x"\n')
    with pytest.raises(InputError, match=r"p\.toml.*\[part\]"):
        load_part(f)


def test_bom_profile_csv_is_accepted(tmp_path):
    f = tmp_path / "p.csv"
    f.write_bytes(b"\xef\xbb\xbfr,z\n40,0\n30,-10\n")
    r, z = read_profile_csv(f)
    np.testing.assert_allclose(np.column_stack([r, z]), [[0.04, 0.0], [0.03, -0.01]])


def test_pcd_with_a_signalling_nan_is_refused(tmp_path):
    # found by the fuzz test: float32 0xff908e23 warned "invalid value encountered in cast"
    f = tmp_path / "s.pcd"
    pts = np.zeros((2, 3), "<f4")
    raw = bytearray(pts.tobytes())
    raw[4:8] = b"\x23\x8e\x90\xff"
    head = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 2\nDATA binary\n"
    f.write_bytes(head.encode() + bytes(raw))
    with pytest.raises(InputError, match=r"s\.pcd.*NaN or inf"):
        read_scan(f)


def test_stl_with_a_nan_vertex_is_refused_before_trimesh_merges_it(tmp_path):
    # found by the fuzz test: trimesh's vertex merge cast NaN to int64 ("invalid value
    # encountered in cast") before our check saw the coordinates
    import struct
    import warnings

    f = tmp_path / "m.stl"
    tri = np.array([[[0, 0, 0], [10, 0, 0], [0, 10, 0]], [[10, 0, 0], [10, 10, 0], [0, np.nan, 0]]])
    out = b"\0" * 80 + struct.pack("<I", len(tri))
    for t in tri:
        out += struct.pack("<3f", 0, 0, 1) + t.astype("<f4").tobytes() + b"\0\0"
    f.write_bytes(out)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=r"m\.stl.*NaN or inf"):
            read_scan(f)
    # the same file without the NaN is read (the check is not what refuses every STL)
    tri[1, 2, 1] = 10
    out = b"\0" * 80 + struct.pack("<I", len(tri))
    for t in tri:
        out += struct.pack("<3f", 0, 0, 1) + t.astype("<f4").tobytes() + b"\0\0"
    f.write_bytes(out)
    assert read_scan(f).points.shape == (4, 3)


def test_stl_with_absurd_coordinates_is_refused_without_a_warning(tmp_path):
    # found by the fuzz test: a finite float32 near 1e38 overflowed trimesh's int64 merge keys
    import struct
    import warnings

    def stl(tri):
        out = b"\0" * 80 + struct.pack("<I", len(tri))
        for t in tri:
            out += struct.pack("<3f", 0, 0, 1) + np.asarray(t, "<f4").tobytes() + b"\0\0"
        return out

    f = tmp_path / "big.stl"
    f.write_bytes(stl([[[0, 0, 0], [10, 0, 0], [0, 3e37, 0]]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=r"big\.stl.*vertex coordinates up to 3e\+37"):
            read_scan(f)
    f.write_bytes(stl([[[0, 0, 0], [10, 0, 0], [0, 9e9, 0]]]))  # large, still a number trimesh keys
    assert read_scan(f).points.shape == (3, 3)
