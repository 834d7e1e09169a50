"""The two compiled forms of a kernel module side by side in tests: its C library
(:mod:`roboisf.jit.native`) and its numba kernels."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import numpy as np

from roboisf.jit import native

_MISSING = object()


def c_library(module: Any) -> Any:
    """The C library of kernel module ``module`` (the module object; its ``_c()`` loads it);
    fails, naming the rebuild command, when it is not built or stale — ``pip install`` builds
    it, and CI's machine has a C compiler."""
    lib = module._c()
    assert lib is not None, (
        f"the C form of {module.__name__} is not built or is stale: "
        "python -m roboisf.jit.native (pip install -e . builds it too)"
    )
    return lib


@contextlib.contextmanager
def numba_form(*modules: str) -> Iterator[None]:
    """Within: the kernel modules ``modules`` (dotted names) run their numba kernels, as when
    their C library is not built."""
    saved = {m: native._loaded.get(m, _MISSING) for m in modules}
    for m in modules:
        native._loaded[m] = None
    try:
        yield
    finally:
        for m, v in saved.items():
            if v is _MISSING:
                native._loaded.pop(m, None)
            else:
                native._loaded[m] = v


def same_bits(got: Any, want: Any, *, nan_sign: bool = True) -> None:
    """``got`` and ``want`` (arrays, or tuples of them) of the same dtype and shape, the same
    bits: floats compared by their bit patterns where not NaN (so -0.0 is not 0.0), NaN where
    NaN, and — with ``nan_sign`` — the NaNs' signs too."""
    if isinstance(got, tuple | list):
        assert isinstance(want, tuple | list) and len(got) == len(want)
        for g, w in zip(got, want, strict=True):
            same_bits(g, w, nan_sign=nan_sign)
        return
    got, want = np.asarray(got), np.asarray(want)
    assert got.dtype == want.dtype and got.shape == want.shape, (got.dtype, want.dtype)
    if got.dtype.kind != "f":
        assert np.array_equal(got, want)
        return
    nan = np.isnan(got)
    assert np.array_equal(nan, np.isnan(want))
    bits = f"u{got.dtype.itemsize}"
    assert np.array_equal(got.view(bits)[~nan], want.view(bits)[~nan])
    if nan_sign:
        assert np.array_equal(np.signbit(got), np.signbit(want))
