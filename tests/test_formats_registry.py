"""The one registry of file formats (roboisf.formats, issue #25).

Every force-log and joint-log profile with a writer round-trips through the registry: written
with its registered writer, detected by the readers' automatic detection as itself, and read back
by its registered reader equal to the log within the rounding its format states
(``FileFormat.rounding``: 9 decimals of a second and 10 significant digits of a wrench in the text
force logs, float32 values in Parquet, 9 decimals of a degree in the joint logs, …).
The registry itself: kinds, unique names, lazy loading, unknown names.
"""

from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.formats import (
    KINDS,
    FileFormat,
    file_formats,
    find_file_format,
    get_file_format,
    register_format,
    unregister_format,
)
from roboisf.logs.forcelog import ForceLog, detect_force_format, force_formats
from roboisf.logs.jointlog import detect_joint_format, joint_formats, unstated_units

FORCE_WRITERS = [f.name for f in file_formats("force_log") if f.writer is not None]
JOINT_WRITERS = [f.name for f in file_formats("joint_log") if f.writer is not None]
#: layouts of a 3-component dynamometer: their writers drop the moments (module docstrings)
THREE_COMPONENT = {"kistler", "dyno3"}


def _log(n=400, rate=500.0, seed=11):
    rng = np.random.default_rng(seed)
    t = 3.0 + np.arange(n) / rate
    W = rng.normal(scale=[100, 100, 400, 2, 2, 0.5], size=(n, 6))
    return ForceLog(t, W, "sensor")


def test_the_builtin_writers_are_registered():
    # the profiles the virtual cell offers are the registry's, not a list of its own
    assert {"roboisf", "parquet", "ati", "kistler", "dyno3", "generic"} <= set(FORCE_WRITERS)
    assert {"roboisf", "parquet", "abb", "kuka"} <= set(JOINT_WRITERS)
    from roboisf.virtual.logformats import force_profiles, joint_profiles

    assert set(force_profiles()) == set(FORCE_WRITERS) - {"parquet"}
    assert set(joint_profiles()) == set(JOINT_WRITERS) - {"parquet"}


@pytest.mark.parametrize("name", FORCE_WRITERS)
def test_every_force_log_writer_round_trips(tmp_path, name):
    fmt = get_file_format("force_log", name)
    log = _log()
    f = tmp_path / f"log{fmt.suffixes[0]}"
    assert fmt.writer is not None and fmt.reader is not None
    fmt.writer(log, f)
    assert detect_force_format(f)[0] == name  # automatic detection finds the writer's layout
    back = fmt.reader(f)
    r = fmt.rounding
    assert r is not None, f"{name}: a writer states its rounding"
    # the time axis may start at 0 (ATI: RDT sequence / rate): offsets compared, each rounded
    dt = 2 * r["time"] + 1e-12
    np.testing.assert_allclose(back.time - back.time[0], log.time - log.time[0], rtol=0, atol=dt)
    rel = r["value"] * (1 + 1e-6) + 1e-15
    np.testing.assert_allclose(back.force, log.force, rtol=rel, atol=0)
    assert back.moments_known is (name not in THREE_COMPONENT)
    if back.moments_known:
        np.testing.assert_allclose(back.moment, log.moment, rtol=rel, atol=0)


@pytest.mark.parametrize("name", JOINT_WRITERS)
def test_every_joint_log_writer_round_trips(tmp_path, name):
    fmt = get_file_format("joint_log", name)
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0, 20, size=50))
    q = np.radians(rng.uniform(-170, 170, size=(50, 6)))
    f = tmp_path / f"log{fmt.suffixes[0]}"
    assert fmt.writer is not None and fmt.reader is not None
    fmt.writer(f, t, q)
    assert detect_joint_format(f)[0] == name
    units = unstated_units(name)  # what a study must say for a layout that states no units
    back = fmt.reader(f, time_unit=units.get("time"), angle_unit=units.get("angle"))
    r = fmt.rounding
    assert r is not None, f"{name}: a writer states its rounding"
    np.testing.assert_allclose(back.time, t, rtol=0, atol=r["time"] * (1 + 1e-6) + 1e-12)
    np.testing.assert_allclose(back.q, q, rtol=0, atol=r["angle"] * (1 + 1e-6) + 1e-15)


def test_abb_states_no_units_so_reading_needs_them(tmp_path):
    f = tmp_path / "abb.csv"
    get_file_format("joint_log", "abb").writer(f, np.arange(3.0), np.zeros((3, 6)))  # type: ignore[misc]
    with pytest.raises(InputError, match="unit not declared"):
        get_file_format("joint_log", "abb").reader(f)  # type: ignore[misc]
    assert unstated_units("kuka") == {}  # KUKA's header names its units


def test_kinds_and_names():
    for f in file_formats():
        assert f.kind in KINDS
    keys = [(f.kind, f.name) for f in file_formats()]
    assert len(keys) == len(set(keys))
    ranks = [(f.rank, f.name) for f in file_formats("force_log")]
    assert ranks == sorted(ranks)
    with pytest.raises(ValueError, match="unknown format kind"):
        file_formats("mesh")
    with pytest.raises(InputError, match="unknown joint log format 'fanuc9'; expected one of"):
        get_file_format("joint_log", "fanuc9")


def test_a_registered_profile_is_offered_everywhere(tmp_path):
    """A toy force-log profile registered from outside is a study format, a virtual-cell
    profile and the writer behind ``write_force_log(profile=...)``; unregistered, it is gone."""
    from roboisf.logs.forcelog import write_force_log
    from roboisf.virtual.logformats import force_profiles

    written = []
    toy = FileFormat(
        name="toy",
        kind="force_log",
        label="toy",
        suffixes=(".toy",),
        writer=lambda log, path: written.append(path),
    )
    register_format(toy)
    try:
        assert "toy" in force_formats() and "toy" in force_profiles()
        write_force_log(_log(), tmp_path / "x.toy", profile="toy")
        assert written == [tmp_path / "x.toy"]
        assert find_file_format(tmp_path / "x.toy", "force_log") is toy
        with pytest.raises(ValueError, match="already registered"):
            register_format(toy)
    finally:
        unregister_format("force_log", "toy")
    assert "toy" not in force_formats()
    assert "toy" not in joint_formats()


def test_bad_format_definitions_are_refused():
    with pytest.raises(ValueError, match="kind"):
        FileFormat(name="x", kind="mesh", label="x")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="suffixes"):
        FileFormat(name="x", kind="scan", label="x", suffixes=("XYZ",))
    with pytest.raises(ValueError, match="identifier"):
        FileFormat(name="a-b", kind="scan", label="x")


def test_loading_the_registry_imports_no_numpy():
    # the CLI's help lists formats: registering them must stay cheap
    code = (
        "import sys\nfrom roboisf.formats import file_formats\nfile_formats()\n"
        "print('numpy' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_study_formats_lists_the_registry(capsys):
    from roboisf.cli.main import main

    toy = FileFormat(name="toylog", kind="joint_log", label="toy joint log", suffixes=(".toy",))
    register_format(toy)
    try:
        assert main(["study", "formats", "joint_log"]) == 0
        out = capsys.readouterr().out
        for f in file_formats("joint_log"):
            assert f.name in out
        assert "toylog" in out and "ati" not in out  # one kind only
    finally:
        unregister_format("joint_log", "toylog")
    assert main(["study", "formats", "mesh"]) == 2
    assert "unknown kind 'mesh'" in capsys.readouterr().err


def test_cam_import_detects_and_reads_through_the_registry(tmp_path):
    """A CAM format registered from outside is detected by its own test (before the suffix
    fallback), accepted by ImportOptions and read by its registered reader."""
    from roboisf.cam.camformat import CamSpec, head_lines
    from roboisf.toolpath.importer import (
        ImportOptions,
        cam_format_names,
        detect_toolpath_format,
        read_cam_moves,
    )

    assert cam_format_names() == ("sinumerik", "apt", "xyz", "iso")  # built in, detection order
    prog = tmp_path / "part.nc"  # an ISO suffix: only the content can say it is the toy's
    prog.write_text("TOYCAM 1\nMOVE 0 0 0\n")
    assert detect_toolpath_format(prog) == "iso"  # by suffix, as nothing else knows it
    seen = []

    def read(path, options, *, units, feed):
        seen.append((path, units, feed))
        return SimpleNamespace(meta={})

    toy = FileFormat(
        name="toycam",
        kind="cnc",
        label="toy CAM",
        suffixes=(".toy",),
        reader=read,
        detect=lambda p: head_lines(p)[0].startswith("TOYCAM"),
        rank=5,
        spec=CamSpec(),
    )
    register_format(toy)
    try:
        assert detect_toolpath_format(prog) == "toycam"
        assert "toycam" in cam_format_names()
        moves = read_cam_moves(prog, ImportOptions(fmt="auto"))
        assert moves.meta == {"format": "toycam"}
        assert seen and seen[0][0] == prog and seen[0][1] is None
        with pytest.raises(InputError, match="units applies to an x,y,z point list"):
            read_cam_moves(prog, ImportOptions(fmt="toycam", units="mm"))
    finally:
        unregister_format("cnc", "toycam")
    assert detect_toolpath_format(prog) == "iso"
    with pytest.raises(InputError, match="expected auto or one of sinumerik, apt, xyz, iso"):
        ImportOptions(fmt="toycam")


def test_scans_are_read_through_the_registry(tmp_path):
    """read_scan picks the reader by the registered suffixes; a scan format registered from
    outside is read (in the declared unit), and unregistered its suffix is refused by name."""
    from roboisf.scan.readers import read_scan, scan_formats

    sfx = scan_formats()
    assert sfx[".ply"] == "ply" and sfx[".e57"] == "e57" and sfx[".stl"] == "mesh"
    f = tmp_path / "cloud.toyscan"
    f.write_text("1 2 3\n4 5 6\n")

    def read(path, sample, seed):
        rows = [ln.split() for ln in path.read_text().splitlines()]
        return np.array(rows, dtype=float), None

    register_format(
        FileFormat(name="toyscan", kind="scan", label="toy", suffixes=(".toyscan",), reader=read)
    )
    try:
        cloud = read_scan(f, unit="mm")
        np.testing.assert_array_equal(cloud.points, [[1e-3, 2e-3, 3e-3], [4e-3, 5e-3, 6e-3]])
    finally:
        unregister_format("scan", "toyscan")
    with pytest.raises(InputError, match=r"unknown scan format '\.toyscan'; expected one of"):
        read_scan(f)
