"""The C kernels' loader (roboisf.jit.native), numba's lazy kernels (roboisf.jit.shim.LazyKernel)
and the force log's C form against its numba form, bit for bit."""

from __future__ import annotations

import ctypes
import importlib.util
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from native_forms import c_library, numba_form
from roboisf.jit import native
from roboisf.logs import forcelog_kernel as fk

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "roboisf"
FK = "roboisf.logs.forcelog_kernel"


def _log(n: int, seed: int = 0) -> np.ndarray:
    """A wrench log (n, 6) as a 1 kHz sensor gives it: a loaded stretch between two unloaded
    ones, noise of a few tenths of a newton."""
    rng = np.random.default_rng(seed)
    W = rng.normal(0.0, 0.3, (n, 6))
    a, b = n // 5, 4 * n // 5
    W[a:b, 2] -= 600.0 + 40.0 * np.sin(np.linspace(0.0, 30.0, b - a))
    W[a:b, 0] += 120.0
    return W


# ---- the force log's C form against its numba form -------------------------------------


@pytest.mark.parametrize("layout", ["C", "reversed", "column slice"])
def test_row_norms_c_equals_numba(layout: str) -> None:
    c_library(fk)
    W = _log(20_001)
    X = {"C": W, "reversed": W[::-1], "column slice": W[:, 1:]}[layout]
    for j, centre in [(0, None), (3 if X.shape[1] >= 6 else 2, np.array([0.1, -0.2, 3.0]))]:
        got = fk.row_norms(X, j, centre)
        with numba_form(FK):
            want = fk.row_norms(X, j, centre)
        assert np.array_equal(got, want)
        # and the arithmetic is the one of np.linalg.norm's (three terms, left to right)
        c = np.zeros(3) if centre is None else centre
        assert np.array_equal(got, np.linalg.norm(X[:, j : j + 3] - c, axis=1))


@pytest.mark.parametrize("backwards", [False, True])
def test_onset_c_equals_numba_and_finds_the_load(backwards: bool) -> None:
    c_library(fk)
    W = _log(50_000, seed=1)
    X = W[::-1] if backwards else W
    centre = np.median(W[:1000, :3], axis=0)
    got = fk.onset(X, centre, 0.3)
    with numba_form(FK):
        want = fk.onset(X, centre, 0.3)
    assert got == want
    assert 9_000 <= got[1] <= 10_001  # the load starts at n/5 from either end
    # never loaded: no onset; a NaN sample never becomes the span (max as Python takes it)
    Q = _log(1000, seed=2)[:200]
    Q[:, :3] = 0.01
    Q[50, 1] = np.nan
    for noise in (0.3, 0.0):
        got = fk.onset(Q, np.zeros(3), noise)
        with numba_form(FK):
            assert got == fk.onset(Q, np.zeros(3), noise)
    assert fk.onset(np.empty((0, 6)), np.zeros(3), 0.1) == (0.0, -1)


def test_running_integral_at_c_equals_numba() -> None:
    c_library(fk)
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.9e-3, 1.1e-3, 30_000))  # a clock with jitter
    y = _log(30_000, seed=4)
    ks = np.unique(np.concatenate(([0, 0 + 1, 29_999], rng.integers(0, 30_000, 500))))
    for tt, yy in [(t, y), (t, y[:, :3]), (t[::2], y[::2, ::2])]:
        k = ks[ks < tt.shape[0]]
        got = fk.running_integral_at(tt, yy, k)
        with numba_form(FK):
            want = fk.running_integral_at(tt, yy, k)
        assert np.array_equal(got, want)
    with pytest.raises(IndexError):
        fk.running_integral_at(t, y, np.array([30_000]))


def test_a_wrong_dtype_never_reaches_c() -> None:
    c_library(fk)
    with pytest.raises(TypeError, match="float64"):
        fk.row_norms(_log(10).astype(np.float32))


# ---- the loader -------------------------------------------------------------------------


def _package_copy(tmp_path: Path) -> Path:
    """A package folder holding only the force log's C source, built in place."""
    pkg = tmp_path / "roboisf"
    (pkg / "logs").mkdir(parents=True)
    shutil.copy(PACKAGE / "logs" / "forcelog_kernel.c", pkg / "logs")
    assert native.build_inplace(pkg) == []
    return pkg


def test_a_library_of_another_source_or_switched_off_is_not_loaded(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pkg = _package_copy(tmp_path)
    monkeypatch.setattr(native, "_PACKAGE", pkg)
    monkeypatch.setattr(native, "_loaded", {})
    assert native.library(FK, fk.SIGNATURES) is not None
    # switched off
    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setenv(native.ENV, "0")
    assert native.library(FK, fk.SIGNATURES) is None
    monkeypatch.delenv(native.ENV)
    # a function the module calls is missing: not this version
    monkeypatch.setattr(native, "_loaded", {})
    assert native.library(FK, {"no_such_kernel": (None, [])}) is None
    # the source edited since the build: stale
    src = pkg / "logs" / "forcelog_kernel.c"
    src.write_text(src.read_text() + "\n/* edited */\n")
    monkeypatch.setattr(native, "_loaded", {})
    assert native.library(FK, fk.SIGNATURES) is None
    # rebuilt: fresh again (read from a copy: this process holds the old library by its name)
    assert native.build_inplace(pkg, only=[src]) == []
    built = native._find(src)
    assert built is not None
    shutil.copy(built, tmp_path / "rebuilt.so")
    sha = ctypes.c_char_p.in_dll(ctypes.CDLL(str(tmp_path / "rebuilt.so")), "roboisf_source_sha256")
    assert sha.value == native.source_sha256(src).encode()


def test_the_status_says_built_stale_missing_and_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pkg = _package_copy(tmp_path)
    (pkg / "scan").mkdir()
    (pkg / "scan" / "knn_kernel.c").write_bytes((PACKAGE / "scan" / "knn_kernel.c").read_bytes())
    assert native.status(pkg) == {FK: "built", "roboisf.scan.knn_kernel": "missing"}
    assert native.describe(pkg) == (
        "C kernels: 1 of 2 built, 1 missing (no C compiler at install? pip install -v shows "
        "why); numba or numpy serves the others"
    )
    src = pkg / "logs" / "forcelog_kernel.c"
    src.write_text(src.read_text() + "\n/* edited */\n")
    assert native.status(pkg)[FK] == "stale"
    assert "1 stale (their sources edited: python -m roboisf.jit.native rebuilds)" in (
        native.describe(pkg)
    )
    monkeypatch.setenv(native.ENV, "0")
    assert native.describe(pkg) == f"C kernels: switched off ({native.ENV}=0)"


def test_a_failing_compile_is_reported_and_leaves_no_library(tmp_path: Path) -> None:
    pkg = tmp_path / "roboisf"
    (pkg / "scan").mkdir(parents=True)
    (pkg / "scan" / "broken_kernel.c").write_text("this is not C;\n")
    failures = native.build_inplace(pkg)
    assert len(failures) == 1 and "broken_kernel.c" in failures[0]
    assert list((pkg / "scan").iterdir()) == [pkg / "scan" / "broken_kernel.c"]


def test_every_c_source_is_an_extension_of_setup_py() -> None:
    spec = importlib.util.spec_from_file_location("roboisf_setup", ROOT / "setup.py")
    assert spec is not None and spec.loader is not None
    setup_py = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(setup_py)
    exts = {e.name: e for e in setup_py.c_extensions()}
    sources = sorted(PACKAGE.rglob("*_kernel.c"))
    assert "roboisf.logs._forcelog_kernel_c" in exts
    assert len(exts) == len(sources)
    for src in sources:
        name = native.extension_name(src)
        assert exts[name].sources == [str(src.relative_to(ROOT))]
        assert exts[name].optional
        macro = dict(exts[name].define_macros)["ROBOISF_SOURCE_SHA256"]
        assert macro == f'"{native.source_sha256(src)}"'


# ---- numba made on first use -------------------------------------------------------------


def _run(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    e = {**os.environ, "PYTHONPATH": str(PACKAGE.parent), **env}
    return subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True)


def test_importing_kernel_modules_does_not_import_numba_calling_a_kernel_does() -> None:
    r = _run(
        "import sys\n"
        "import roboisf.scan.knn_kernel, roboisf.parts.mesh_kernel, roboisf.sync.position_kernel\n"
        "import roboisf.robot.fk_numba, roboisf.robot.ik_numba, roboisf.robot.vjm_numba\n"
        "from roboisf.logs import forcelog_kernel as fk\n"
        "assert 'numba' not in sys.modules, 'imported'\n"
        "import numpy as np\n"
        "W = np.arange(12.0).reshape(4, 3)\n"
        "out = np.empty(4)\n"
        "fk._row_norms(W, 0, np.zeros(3), out)  # the numba kernel itself\n"
        "assert 'numba' in sys.modules\n"
        "assert np.array_equal(out, np.linalg.norm(W, axis=1))\n"
        "print(type(fk._row_norms).__name__, fk._row_norms.signatures)\n"
    )
    assert r.returncode == 0, r.stderr
    # the module's name now holds numba's dispatcher itself (bound at the first call)
    assert r.stdout.startswith("CPUDispatcher [(")


def test_a_kernel_calling_kernels_of_other_modules_compiles_on_first_use() -> None:
    # tip_positions' numba kernel calls vjm_chain's chain_walk, which calls sincos: each is a
    # LazyKernel until the first call binds them in their modules' globals
    r = _run(
        "import numpy as np\n"
        "from roboisf.robot import fk_numba, vjm_chain\n"
        "from roboisf.jit.shim import LazyKernel\n"
        "assert isinstance(vjm_chain.chain_walk, LazyKernel)\n"
        "F = np.tile(np.eye(4), (7, 1, 1)); F[:, 2, 3] = 0.1\n"
        "out = np.empty((3, 3))\n"
        "fk_numba._rows(F, np.ones(6), np.zeros(6), 0.0, np.eye(4), np.zeros((3, 6)), out, 0, 3)\n"
        "assert not isinstance(vjm_chain.chain_walk, LazyKernel)\n"
        "print(out[0])\n",
        ROBOISF_BACKGROUND_COMPILE="0",
    )
    assert r.returncode == 0, r.stderr
    assert np.allclose(np.array(r.stdout.strip(" []\n").split(), dtype=float), [0, 0, 0.7])


def test_a_lazy_kernel_pickles_by_reference() -> None:
    assert pickle.loads(pickle.dumps(fk._onset)) is fk._onset
