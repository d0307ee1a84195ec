"""How steep the RKHS log-likelihood is on one pair of interfaces (README.md, "Why is not
identified"): E = 450 vs 400 Pa at nu = 0.3 and 100 mm^2/s with ale_fsi (SVK, default mesh),
-L = D^2 / (2 sigma_N^2) at sigma_N^2 = 0.0005 mm^2 for length-weighted and unit normals and
for several kernel widths sigma_W, and the largest displacement at the truth.

Run:  python examples/paper_b/posterior/rkhs_scale.py   (two forward runs and one at rest, ~5 s)
"""

import numpy as np

import fbia

SIGMA_N2 = 0.0005  # mm^2 (Paper B)


def main() -> None:
    model = fbia.forward_model("ale_fsi", material="svk")

    def interface(e: float, inflow: float) -> fbia.Interface:
        obs = fbia.synthetic_observations(
            model, {"E": e, "nu": 0.3}, [{"inflow_rate": inflow}], noise_std=0.0, seed=0
        )
        return obs[0].interface

    truth, other, rest = interface(400.0, 100.0), interface(450.0, 100.0), interface(400.0, 0.0)
    observed = fbia.Observation(truth)
    lengths = np.linalg.norm(other.area_vectors, axis=1)
    print(f"{len(lengths)} interface elements, mean length {lengths.mean():.4f} mm")
    shift = np.linalg.norm(truth.vertices - rest.vertices, axis=1).max()
    print(f"largest displacement at the truth: {shift:.4f} mm")
    for unit in (False, True):
        measure = fbia.measure("rkhs", sigma_w=0.005, unit_normals=unit, residuals="distance")
        d = measure.distance(other, observed)
        kind = "unit normals" if unit else "length-weighted normals"
        print(f"sigma_W = 0.005 mm, {kind}: -L = {d**2 / (2 * SIGMA_N2):.4g}")
    for width in (0.0025, 0.005, 0.01, 0.02, 0.05):
        d = fbia.measure("rkhs", sigma_w=width, residuals="distance").distance(other, observed)
        print(f"sigma_W = {width} mm, length-weighted: -L = {d**2 / (2 * SIGMA_N2):.3g}")


if __name__ == "__main__":
    main()
