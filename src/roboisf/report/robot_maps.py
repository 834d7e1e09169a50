"""Robot stiffness-map figure (matplotlib, Agg backend; written atomically)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from roboisf.io.atomic import atomic_path
from roboisf.robot.maps import StiffnessMap

__all__ = ["plot_stiffness_map"]


def plot_stiffness_map(smap: StiffnessMap, path: str | Path, *, dpi: int = 120) -> Path:
    """Three panels (k_xx, k_yy, k_zz in µm/N, work axes) over the work-plane grid → PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), constrained_layout=True)
    ext = [smap.x[0] * 1e3, smap.x[-1] * 1e3, smap.y[0] * 1e3, smap.y[-1] * 1e3]
    for i, (ax, lab) in enumerate(zip(axes, ("k_xx", "k_yy", "k_zz"), strict=True)):
        data = np.ma.masked_invalid(smap.compliance[:, :, i] * 1e6)
        im = ax.imshow(data, origin="lower", extent=ext, cmap="viridis", aspect="equal")
        ax.set_title(f"{lab} [µm/N]")
        ax.set_xlabel("x_work [mm]")
        ax.set_ylabel("y_work [mm]")
        fig.colorbar(im, ax=ax, shrink=0.85)
    fig.suptitle(f"{smap.robot}: translational compliance at z = {smap.z * 1e3:.0f} mm (tool down)")
    out = Path(path)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return out
