"""Make the synthetic OCT scan of this example and segment it (``python make_scan.py``).

1. ``ale_fsi`` in 3-D (``geometry = "dome_3d"`` at the recommended settings, :data:`MODEL_OPTIONS`)
   runs at the ground truth E = 400 Pa, nu = 0.3 with an inflow of 100 mm^3/s: a spherical-cap
   colony (radius 0.4 mm, height 0.4 mm) on the floor of a 2 x 1 x 1 mm duct, bent downstream.
2. Its deformed interface is imaged as an OCT-like volume by
   :func:`fbia.testing.oct.oct_volume_from_surface`: voxels of (dz, dy, dx) =
   :data:`VOXEL_SIZE`, partial volume, speckle (2 looks), Beer–Lambert attenuation
   (:data:`ATTENUATION`) and a noise floor, seeded.  Axes: the model's flow direction x is
   the scan's x, the model's span z is the scan's y, the model's height y is the scan's
   height above the substratum (:func:`fbia.imaging.oct.in_model_axes` with
   ``height_axis = "y"``, its own inverse).  Written as ``data/scan_loaded.npy`` (depth, y, x) with
   ``data/scan_loaded.json`` (voxel size, attenuation).
3. :func:`fbia.imaging.oct.segment_oct` segments it (Otsu threshold, marching cubes, the known
   attenuation compensated); the surface, mapped back to the model's axes, is the observed
   interface ``data/observed_100.ply`` of ``study_lm.toml`` and ``study_bayes.toml``
   (``study_lm_scan.toml`` reads the scan itself: ``[[observations]] oct = {...}``).
   The segmentation figures (a B-scan with the contour, a 3-D view) go to ``output/scan``.
4. The *unloaded* dome (no flow) is imaged the same way (another speckle seed),
   ``data/scan_unloaded.npy``, and :func:`fbia.plugins.ale_fsi.colony3d.colony_from_oct`
   segments it into ``data/unloaded.ply`` (model axes): the reference geometry
   (``geometry = "colony_3d"``, ``colony_surface``) of ``study_*_scan_geometry.toml``, so
   that the reference and the loaded surfaces carry the same segmentation bias.
5. The *matched truth* (:func:`make_matched_scan`, into ``data/matched/``): steps 1-4 with the
   truth computed by the calibration's own model family, ``geometry = "colony_3d"`` on the
   rest surface of step 1 (:data:`COLONY_OPTIONS`), so that no mismatch between the truth's
   and the model's family remains (at the recommended settings ``dome_3d`` bends 8 % more
   than ``colony_3d`` on the same rest dome, 26.2 against 24.1 um; 13 % on the coarse mesh);
   the files of ``study_lm_matched.toml`` (README, "nu free").

Seeded: the files are the same every time (up to the solver's rounding).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import fbia
from fbia.imaging.oct import OctSegmentation, in_model_axes, segment_oct
from fbia.plugins.ale_fsi.colony3d import colony_from_oct
from fbia.plugins.ale_fsi.options import RECOMMENDED_3D
from fbia.studies.oct_figures import write_segmentation_figures
from fbia.testing.oct import oct_volume_from_surface

HERE = Path(__file__).parent
TRUTH = {"E": 400.0, "nu": 0.3}
INFLOW = {"inflow_rate": 100.0}  # mm^3/s
#: the recommended 3-D settings (order 3, dome 0.15 mm, duct 0.2 mm, the linear mesh motion
#: within 0.15 mm of the dome, Newton to 1e-6: within 1 % of the converged dome,
#: benchmarks/bench_ale_fsi_3d.py)
MODEL_OPTIONS = {"geometry": "dome_3d", **RECOMMENDED_3D}
VOXEL_SIZE = (0.005, 0.01, 0.01)  # (dz, dy, dx) [mm]: 5 um axial, 10 um lateral
SHAPE = (100, 100, 160)  # (depth, y, x): 0.5 x 1.0 x 1.6 mm, the duct's x from 0 to 1.6 mm
ATTENUATION = 1.0  # 1/mm
#: The colony_3d options of the *_scan_geometry studies (colony_surface is set per call).
COLONY_OPTIONS = {
    "geometry": "colony_3d",
    "colony_resolution": 0.01,
    "colony_smoothing": 0.01,
    **RECOMMENDED_3D,
}
SEED = 18


def simulate(
    E: float,
    nu: float = TRUTH["nu"],
    coordinate: dict[str, float] = INFLOW,
    options: dict[str, object] | None = None,
) -> fbia.Interface:
    """The interface of the 3-D dome (or of ``options``' model) at (E, nu) and ``coordinate``."""
    model = fbia.forward_model("ale_fsi", **(MODEL_OPTIONS if options is None else options))
    (obs,) = fbia.synthetic_observations(model, {"E": E, "nu": nu}, [coordinate], 0.0, seed=0)
    return obs.interface


def save_scan(path: Path, volume: np.ndarray, voxel_size: tuple[float, float, float]) -> None:
    """The scan as .npy with a JSON of the same stem beside it (voxel size, attenuation), which
    ``[[observations]] oct = "..."`` reads."""
    np.save(path, volume)
    meta = {"voxel_size_mm": list(voxel_size), "attenuation_per_mm": ATTENUATION}
    path.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")


def make_scan(
    folder: Path,
    voxel_size: tuple[float, float, float] = VOXEL_SIZE,
    shape: tuple[int, int, int] = SHAPE,
    seed: int = SEED,
) -> OctSegmentation:
    """Steps 1-3 of the module docstring, the files written into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    loaded = simulate(TRUTH["E"])
    volume, _ = oct_volume_from_surface(
        in_model_axes(loaded, "y"), shape, voxel_size, attenuation=ATTENUATION, seed=seed
    )
    save_scan(folder / "scan_loaded.npy", volume, voxel_size)
    seg = segment_oct(volume, voxel_size=voxel_size, attenuation=ATTENUATION)
    in_model_axes(seg.interface, "y").write(folder / "observed_100.ply")
    loaded.write(folder / "simulated_truth_100.ply")
    # 4. the unloaded scan -> the reference geometry of the *_scan_geometry studies
    rest = simulate(TRUTH["E"], coordinate={"inflow_rate": 0.0})
    volume, _ = oct_volume_from_surface(
        in_model_axes(rest, "y"), shape, voxel_size, attenuation=ATTENUATION, seed=seed + 1
    )
    np.save(folder / "scan_unloaded.npy", volume)
    colony_from_oct(volume, voxel_size, folder / "unloaded.ply", attenuation=ATTENUATION)
    rest.write(folder / "simulated_truth_0.ply")
    return seg


def make_matched_scan(folder: Path, seed: int = SEED) -> OctSegmentation:
    """Step 5: the truth on the colony_3d mesh of ``folder/simulated_truth_0.ply``, imaged as
    in steps 2-4, into ``folder/matched``."""
    out = folder / "matched"
    out.mkdir(parents=True, exist_ok=True)
    options = {**COLONY_OPTIONS, "colony_surface": str(folder / "simulated_truth_0.ply")}
    truth = {}
    for rate, name in ((100.0, "simulated_truth_100.ply"), (0.0, "simulated_truth_0.ply")):
        truth[rate] = simulate(TRUTH["E"], coordinate={"inflow_rate": rate}, options=options)
        truth[rate].write(out / name)
    volume, _ = oct_volume_from_surface(
        in_model_axes(truth[100.0], "y"), SHAPE, VOXEL_SIZE, attenuation=ATTENUATION, seed=seed
    )
    save_scan(out / "scan_loaded.npy", volume, VOXEL_SIZE)  # study_lm_matched.toml reads it
    seg = segment_oct(volume, voxel_size=VOXEL_SIZE, attenuation=ATTENUATION)
    in_model_axes(seg.interface, "y").write(out / "observed_100.ply")
    volume, _ = oct_volume_from_surface(
        in_model_axes(truth[0.0], "y"), SHAPE, VOXEL_SIZE, attenuation=ATTENUATION, seed=seed + 1
    )
    colony_from_oct(volume, VOXEL_SIZE, out / "unloaded.ply", attenuation=ATTENUATION)
    return seg


def main() -> None:
    seg = make_scan(HERE / "data")
    make_matched_scan(HERE / "data")
    write_segmentation_figures(seg, HERE / "output" / "scan")
    print(
        f"wrote data/scan_loaded.npy, data/observed_100.ply ({seg.interface}), "
        "data/scan_unloaded.npy, data/unloaded.ply, data/matched/; "
        f"substratum row {seg.substratum_row}, threshold {seg.threshold:.3g}"
    )


if __name__ == "__main__":
    main()
