"""The report in a real headless browser (Debian's chromium): it loads with no console errors, no
network access, every plot renders, and a screenshot is not blank.

Console errors are collected by a small script injected at the top of ``<head>`` of a copy of the
page (window ``error`` events — script errors and failed resource loads, capture phase —
unhandled promise rejections, ``console.error``) and read back from ``--dump-dom``; chromium's own
log of uncaught exceptions on stderr is checked as well. Name resolution is mapped to nothing
(``--host-resolver-rules``), so any attempt to reach the network fails loudly.
Skipped (with the reason) when no chromium is installed; CI installs it (``.ci/run``).
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from report_fixtures import make_study
from roboisf.report import FIGURES, HTML_FIGURES, figure_ids, write_index, write_report

pytestmark = pytest.mark.browser


def _chromium() -> str | None:
    explicit = os.environ.get("ROBOISF_CHROMIUM")
    if explicit:
        return explicit
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


CHROMIUM = _chromium()
if CHROMIUM is None:
    pytest.skip(
        "headless browser test: no chromium on PATH (apt-get install chromium, or set "
        "ROBOISF_CHROMIUM); CI installs it",
        allow_module_level=True,
    )

COLLECTOR = """<script>
window.__roboisf_errors = [];
(function () {
  var push = function (s) { window.__roboisf_errors.push(String(s)); };
  window.addEventListener('error', function (e) {
    var t = e.target;
    if (t && t !== window && (t.src || t.href)) { push('resource failed: ' + (t.src || t.href)); }
    else { push('error: ' + e.message + ' @' + e.filename + ':' + e.lineno); }
  }, true);
  window.addEventListener('unhandledrejection', function (e) { push('rejection: ' + e.reason); });
  var ce = console.error;
  console.error = function () { push('console.error: ' + Array.prototype.join.call(arguments, ' '));
                                return ce.apply(console, arguments); };
  window.addEventListener('load', function () {
    setTimeout(function () {
      var pre = document.createElement('pre');
      pre.id = '__roboisf_errors';
      pre.textContent = JSON.stringify(window.__roboisf_errors);
      document.body.appendChild(pre);
    }, 1000);
  });
})();
</script>"""


def _run(args: list[str], profile: Path) -> subprocess.CompletedProcess[str]:
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        "--disable-extensions",
        "--hide-scrollbars",
        "--mute-audio",
        "--host-resolver-rules=MAP * ~NOTFOUND",
        "--enable-logging=stderr",
        "--v=0",
        f"--user-data-dir={profile}",
        *args,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180, check=False)


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("browser")
    path = write_report(*make_study(n_laps=60, points_per_lap=80), out / "cone", png=False)
    write_index([path], out / "index.html")
    return path


@pytest.fixture(scope="module")
def cone_loaded(report, tmp_path_factory) -> tuple[str, list[str], Path]:
    """The cone's report loaded once for the load test and the screenshot test: chromium takes
    --dump-dom and --screenshot in one run (≈ 4.5 s of CPU per run, most of it rendering the
    page's plots). (DOM after JS ran, errors, screenshot.) The page is the collector's copy: a
    script in <head> and, a second after load, one <pre> appended at the end of the body —
    below the screenshot's 3200 px, and no ink of its own on the page's top."""
    root = tmp_path_factory.mktemp("cone_loaded")
    shot = root / "report.png"
    dom, errors, stderr = _load(
        report, root / "profile", window="1280,3200", extra=(f"--screenshot={shot}",)
    )
    assert shot.exists(), stderr[-3000:]
    return dom, errors, shot


def _uncaught(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if "CONSOLE" in ln and "Uncaught" in ln]


def _load(
    page: Path, profile: Path, *, window: str = "1280,2000", extra: tuple[str, ...] = ()
) -> tuple[str, list[str], str]:
    """Open a copy of ``page`` with the collector; return (DOM after JS ran, errors, stderr).
    ``extra``: more of chromium's headless actions in the same run (``--screenshot=…``)."""
    probe = page.with_name(f"probe-{page.name}")
    text = page.read_text(encoding="utf-8")
    probe.write_text(text.replace("<head>", "<head>" + COLLECTOR, 1), encoding="utf-8")
    result = _run(
        [
            "--virtual-time-budget=20000",
            f"--window-size={window}",
            *extra,
            "--dump-dom",
            probe.as_uri(),
        ],
        profile,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    dom = result.stdout
    m = re.search(r'<pre id="__roboisf_errors">(.*?)</pre>', dom, flags=re.S)
    assert m, "the page did not finish loading (no error report in the DOM)"
    errors = json.loads(html.unescape(m.group(1)))
    return dom, errors + _uncaught(result.stderr), result.stderr


def test_harness_sees_errors(tmp_path):
    """The checks below can fail: a script error, console.error and a network fetch are caught."""
    page = tmp_path / "broken.html"
    page.write_text(
        "<!DOCTYPE html><html><head><title>x</title></head><body>"
        "<script>console.error('boom');</script><script>undefinedFunction();</script>"
        '<img src="https://example.invalid/logo.png"></body></html>',
        encoding="utf-8",
    )
    _, errors, _ = _load(page, tmp_path / "profile")
    joined = "\n".join(errors)
    assert "console.error: boom" in joined
    assert "undefinedFunction" in joined
    assert "resource failed: https://example.invalid/logo.png" in joined


@pytest.mark.parametrize("part", ["cone", "pyramid"])
def test_page_loads_without_errors_and_every_plot_renders(part, request):
    ids = FIGURES if part == "cone" else figure_ids(round_part=False)
    if part == "cone":  # the run the screenshot test reads too
        dom, errors, _ = request.getfixturevalue("cone_loaded")
    else:  # the pyramid of the statements test, loaded once for both (stated_loaded)
        dom, errors, _ = request.getfixturevalue("stated_loaded")
    assert errors == [], errors

    starts = sorted((dom.index(f'id="fig-{fid}"'), fid) for fid in ids)
    assert [fid for _, fid in starts] == list(ids)  # page order
    for k, (pos, fid) in enumerate(starts):
        end = starts[k + 1][0] if k + 1 < len(starts) else len(dom)
        chunk = dom[pos:end]
        assert 'class="main-svg"' in chunk, f"{fid}: plotly did not render"
        # data drawn, not just empty axes: line/bar traces, heatmap image or polar traces
        assert re.search(r'class="(trace|hm|scatterlayer|barlayer)', chunk), f"{fid}: no trace"
    assert dom.count('class="plot-container plotly"') == len(HTML_FIGURES) + len(ids)


def test_screenshot_is_not_blank(cone_loaded):
    shot = cone_loaded[2]  # taken in the load test's chromium run (cone_loaded)
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)[..., :3]
    assert img.shape[:2] == (3200, 1280)
    grey = img.mean(axis=2)
    assert grey.std() > 0.1  # not a blank page
    # plots drew coloured ink: the factor and run colours, not only grey text on white
    saturation = img.max(axis=2) - img.min(axis=2)
    assert np.mean(saturation > 0.3) > 0.01
    keep = os.environ.get("ROBOISF_SCREENSHOT_DIR")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy(shot, Path(keep) / "report.png")


def test_index_page_loads(report, tmp_path):
    index = report.parent.parent / "index.html"
    result = _run(["--virtual-time-budget=3000", "--dump-dom", index.as_uri()], tmp_path / "p")
    assert result.returncode == 0
    assert 'href="cone/report.html"' in result.stdout
    assert _uncaught(result.stderr) == []


SEEN = """<script>
window.addEventListener('load', function () {
  setTimeout(function () {
    var out = {};
    var probes = [['kind', '#study-kind'], ['check', '.cards .card.warn'],
                  ['scope', '#analysis-scope'], ['part', '#fig-part_3d']];
    probes.forEach(function (p) {
      var el = document.querySelector(p[1]);
      if (!el) { out[p[0]] = null; return; }
      var r = el.getBoundingClientRect(), cs = getComputedStyle(el);
      out[p[0]] = {text: el.innerText, h: r.height, w: r.width, top: r.top + window.scrollY,
                   shown: cs.display !== 'none' && cs.visibility !== 'hidden'
                          && parseFloat(cs.opacity) > 0};
    });
    var part = document.querySelector('#fig-part_3d');
    out.canvas = part ? part.querySelectorAll('canvas').length : 0;
    out.traces = part && part.data ? part.data.length : 0;
    out.buttons = part ? part.querySelectorAll('.updatemenu-button').length : 0;
    // press the second term's button: only its trace is shown then
    var b = part ? part.querySelectorAll('.updatemenu-button')[1] : null;
    if (b) { b.dispatchEvent(new MouseEvent('click', {bubbles: true})); }
    setTimeout(function () {
      out.visible_after_click = part && part.data
        ? part.data.map(function (t) { return t.visible === true; }) : [];
      var pre = document.createElement('pre');
      pre.id = '__roboisf_seen';
      pre.textContent = JSON.stringify(out);
      document.body.appendChild(pre);
    }, 800);
  }, 1500);
});
</script>"""


@pytest.fixture(scope="module")
def stated_report(tmp_path_factory) -> Path:
    """A pyramid of a virtual cell whose robot is softer than its model: the model check fails,
    20 mm of rim band leave 30 % of the points."""
    out = tmp_path_factory.mktemp("browser_stated")
    pp, c, cn, s = make_study(n_laps=60, points_per_lap=80, shape="pyramid", name="soft")
    s = {
        **s,
        "truth": {"model_equals_truth": False, "truth_source": "soft.toml"},
        "vjm_check": {"ratio": 2.0, "ci_low": 1.98, "ci_high": 2.02, "verdict": "mismatch"},
        "n_points": len(pp),
        "n_points_used": int(0.3 * len(pp)),
        "rim_band_mm": 20.0,
    }
    return write_report(pp, c, cn, s, out / "soft", png=False)


@pytest.fixture(scope="module")
def stated_loaded(stated_report, tmp_path_factory) -> tuple[str, list[str], Path]:
    """The stated pyramid's report, with the SEEN probe, loaded once for the statements test and
    the pyramid's load test (one chromium run, ≈ 4.5 s of CPU, instead of two: a pyramid report
    of its own showed the same figures). (DOM after JS ran, errors, page.)"""
    page = stated_report.with_name("seen.html")
    page.write_text(
        stated_report.read_text(encoding="utf-8").replace("<head>", "<head>" + SEEN, 1),
        encoding="utf-8",
    )
    dom, errors, _ = _load(page, tmp_path_factory.mktemp("stated_loaded") / "profile")
    return dom, errors, page


def test_statements_are_visible_at_the_top_and_the_3d_view_renders(stated_loaded):
    """The headline's study kind, the model-check verdict, the rim band and the 3D view are on
    the rendered page, visible, and in that order before the figures."""
    dom, errors, _ = stated_loaded
    assert errors == [], errors
    m = re.search(r'<pre id="__roboisf_seen">(.*?)</pre>', dom, flags=re.S)
    assert m, "the probe did not run"
    seen = json.loads(html.unescape(m.group(1)))
    for key in ("kind", "check", "scope", "part"):
        assert seen[key] is not None, f"{key}: not on the page"
        assert seen[key]["shown"] and seen[key]["h"] > 10 and seen[key]["w"] > 200, seen[key]
    assert "Virtual cell" in seen["kind"]["text"]
    assert "model does not hold" in seen["check"]["text"] and "2.00" in seen["check"]["text"]
    assert "rim band: the top 20.0 mm" in seen["scope"]["text"]
    assert "30 %" in seen["scope"]["text"]
    assert seen["kind"]["top"] < seen["check"]["top"] < seen["scope"]["top"] < seen["part"]["top"]
    assert seen["kind"]["top"] < 300  # the first thing under the title
    # the 3D view drew: a WebGL canvas, one trace per term, a button per term
    assert seen["canvas"] >= 1 and seen["part"]["h"] > 400
    assert seen["traces"] == 6 and seen["buttons"] == 6
    assert seen["visible_after_click"] == [False, True, False, False, False, False]
