"""``roboisf demo``: both paper studies end to end, built atomically."""

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.io.rapid import read_rapid
from roboisf.io.toolpath_csv import read_toolpath_csv
from roboisf.report import read_headline

pytestmark = pytest.mark.slow


def test_demo_builds_both_studies_atomically(tmp_path):
    out = tmp_path / "demo"
    out.mkdir()
    (out / "stale.txt").write_text("old")
    argv = ["-q", "demo", "-o", str(out), "--scan-points", "150000", "--force-rate", "50"]
    assert main(argv) == 2  # not a demo result: refused before computing (docs/conventions.md)
    assert main([*argv, "--overwrite"]) == 0
    assert (out / "stale.txt").read_text() == "old"  # never touch a file roboisf did not write
    assert (out / "index.html").is_file()
    for name in ("cone-71", "vwacf"):
        sub = out / name
        for f in (
            "study/study.toml",
            "study/truth/per_point.parquet",
            "results/report.html",
            "results/contributions.csv",
            "programs/toolpath.mod",
            "programs/toolpath.src",
            "programs/toolpath.nc",
            "programs/toolpath.csv",
        ):
            assert (sub / f).is_file(), f"{name}/{f}"
        head = read_headline(sub / "results" / "report.html")
        assert 0 < head["robot_share_percent"] < 100
    cone = read_toolpath_csv(out / "cone-71" / "study" / "toolpath.csv")
    assert cone.n_laps == 206
    rapid = read_rapid(out / "cone-71" / "programs" / "toolpath.mod")
    assert np.abs(rapid.tip - cone.tip).max() <= 0.5e-6 + 1e-12
    assert [p.name for p in tmp_path.iterdir()] == ["demo"]  # no staging leftovers
