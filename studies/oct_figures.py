"""Figures of an OCT segmentation, so that a user sees what :mod:`fbia.imaging.oct` segmented.

>>> from fbia.testing.oct import oct_phantom
>>> from fbia.imaging.oct import segment_oct
>>> ph = oct_phantom(shape=(24, 20, 20), seed=0)
>>> paths = write_segmentation_figures(segment_oct(ph.volume, ph.voxel_size), "oct_figures")
>>> [p.name for p in paths]
['oct_bscan.png', 'oct_surface.png']

``oct_bscan.png`` is the middle B-scan of the (cropped) input as scanned (before the window is
filled and the scan untilted) with the segmented interface (the top of the height map in
every A-scan, or marching cubes' cut where the surface keeps overhangs), the substratum's
surface as found (tilted with the scan) and the window's line when one was found;
``oct_surface.png`` a 3-D view of the extracted surface (matplotlib, Agg).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..figures import legend, pyplot
from ..imaging.oct import OctSegmentation

__all__ = ["write_segmentation_figures"]


def write_segmentation_figures(
    result: OctSegmentation, folder: str | Path, max_triangles: int = 20000
) -> list[Path]:
    """``oct_bscan.png``: the kept B-scan (input intensities times the attenuation
    compensation, shown up to their 99.5th percentile) with the segmented contour and
    the substratum line; ``oct_surface.png``: a 3-D view of the surface (at most
    ``max_triangles`` of its triangles, evenly picked).  Returns the two paths."""
    plt = pyplot()
    plt = pyplot()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    dz, _, dx = result.voxel_size
    z0, _, x0 = result.origin
    nz, nx = result.bscan.shape
    extent = (x0 * dx, (x0 + nx - 1) * dx, (z0 + nz - 1) * dz, z0 * dz)
    fig, ax = plt.subplots(figsize=(7, 4))
    gain = np.exp(result.attenuation * (z0 + np.arange(nz)) * dz)[:, None]
    image = result.bscan * gain
    vmax = float(np.percentile(image, 99.5))
    ax.imshow(image, cmap="gray", extent=extent, aspect="auto", vmin=0.0, vmax=vmax)
    xs = (x0 + np.arange(result.field.shape[1])) * dx
    lines = result.bscan_lines
    if result.surface_kind == "outer" and not any(result.tilt):
        # marching cubes' cut through this B-scan (overhangs and all): the threshold level
        ds = (z0 + np.arange(result.field.shape[0])) * dz
        ax.contour(xs, ds, result.field, levels=[result.threshold], colors="red", linewidths=1)
        ax.plot([], [], color="red", lw=1, label="segmented interface")
    elif lines.get("interface") is not None:
        top = np.asarray(lines["interface"])
        ax.plot(xs, top * dz, color="red", lw=1, label="segmented interface (top)")
    substratum = lines.get("substratum")
    if substratum is not None:
        ax.plot(xs, np.asarray(substratum) * dz, color="cyan", ls="--", lw=1, label="substratum")
    window = lines.get("window")
    if window is not None:
        ax.plot(xs, np.asarray(window) * dz, color="yellow", ls=":", lw=1.2, label="window")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("depth [mm]")
    ax.set_title(
        f"B-scan y index {result.bscan_row}; threshold {result.threshold:.3g}, "
        f"mu {result.attenuation:.3g} 1/mm; {result.surface_kind.replace('_', ' ')}",
        fontsize=9,
    )
    legend(ax, fontsize=8, loc="upper right")
    fig.tight_layout()
    bscan_path = folder / "oct_bscan.png"
    fig.savefig(bscan_path, dpi=120)
    plt.close(fig)

    gamma = result.interface
    cells = gamma.cells[:: max(1, int(math.ceil(len(gamma) / max_triangles)))]
    v = gamma.vertices
    fig = plt.figure(figsize=(7, 5))
    ax3 = fig.add_subplot(projection="3d")
    ax3.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=cells, cmap="viridis", lw=0)
    ax3.set_box_aspect(tuple(np.ptp(v, axis=0) + 1e-12))  # true proportions
    ax3.set_xlabel("x [mm]")
    ax3.set_ylabel("y [mm]")
    ax3.set_zlabel("height [mm]")
    ax3.set_title(f"segmented surface: {len(gamma)} triangles ({len(cells)} drawn)", fontsize=9)
    fig.tight_layout()
    surface_path = folder / "oct_surface.png"
    fig.savefig(surface_path, dpi=120)
    plt.close(fig)
    return [bscan_path, surface_path]
