"""The segmented surface beside the simulated one at an estimate (``python figure.py 414.9``).

Runs the forward model of ``make_scan.py`` once at E (the argument, in Pa; nu at its true
0.3) and draws, in the model's axes (x along the flow, z across, height y above the floor):

* left: the height of the surface segmented from the OCT scan (``data/observed_100.ply``),
  with the contours of the simulated surface's height over it;
* middle: simulated minus segmented height [um] on the dome's footprint (both surfaces
  interpolated linearly over (x, z)), with its RMS in the title;
* right: the mid-plane profile z = 0.5 mm along the flow: the segmented and simulated
  surfaces, and the unloaded dome, so that the flow's bending stands beside the misfit.

Written to ``output/surfaces_E<E>.png``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from make_scan import HERE, INFLOW, MODEL_OPTIONS, TRUTH, simulate
from scipy.interpolate import LinearNDInterpolator

import fbia


def heights(surface: fbia.Interface, x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The surface's height y over the points (x, z), linear; NaN off its projection."""
    v = surface.vertices
    return np.asarray(LinearNDInterpolator(v[:, [0, 2]], v[:, 1])(x, z))


def unloaded() -> fbia.Interface:
    """The dome at rest (no inflow)."""
    model = fbia.forward_model("ale_fsi", **MODEL_OPTIONS)
    (obs,) = fbia.synthetic_observations(model, TRUTH, [{"inflow_rate": 0.0}], 0.0, seed=0)
    return obs.interface


def main(E: float) -> Path:
    observed = fbia.Interface.read(HERE / "data" / "observed_100.ply")
    simulated = simulate(E)
    x, z = np.meshgrid(np.linspace(0.35, 1.25, 181), np.linspace(0.05, 0.95, 181))
    h_obs, h_sim = heights(observed, x, z), heights(simulated, x, z)
    diff = 1e3 * (h_sim - h_obs)
    diff[~(np.nan_to_num(h_obs) > 0.01)] = np.nan  # the footprint, off the rim's thin edge
    rms = float(np.sqrt(np.nanmean(diff**2)))
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.4))
    im = ax[0].pcolormesh(x, z, h_obs, shading="auto", cmap="viridis")
    ax[0].contour(x, z, h_sim, levels=np.linspace(0.05, 0.35, 7), colors="w", linewidths=0.8)
    fig.colorbar(im, ax=ax[0], label="segmented height [mm]")
    ax[0].set_title("segmented (colour), simulated (contours)")
    lim = float(np.nanpercentile(np.abs(diff), 99))  # a few rim voxels go off the scale
    im = ax[1].pcolormesh(x, z, diff, shading="auto", cmap="RdBu_r", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=ax[1], label="simulated - segmented [um]")
    ax[1].set_title(f"height difference, RMS {rms:.1f} um")
    for a in ax[:2]:
        a.set_xlabel("x (flow) [mm]")
        a.set_ylabel("z (span) [mm]")
        a.set_aspect("equal")
    xs = np.linspace(0.35, 1.25, 400)
    zs = np.full_like(xs, 0.5)
    ax[2].plot(xs, heights(unloaded(), xs, zs), "k:", label="unloaded")
    ax[2].plot(xs, heights(observed, xs, zs), "C0-", label="segmented (OCT)")
    ax[2].plot(xs, heights(simulated, xs, zs), "C1--", label=f"simulated, E = {E:g} Pa")
    ax[2].set_xlabel("x (flow) [mm]")
    ax[2].set_ylabel("height [mm]")
    ax[2].set_title(f"mid-plane z = 0.5 mm, inflow {INFLOW['inflow_rate']:g} mm^3/s")
    ax[2].legend()
    fig.tight_layout()
    out = HERE / "output" / f"surfaces_E{E:g}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    print(f"wrote {out.relative_to(HERE)}: height RMS {rms:.2f} um")
    return out


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else TRUTH["E"])
