"""Regenerate the data of Paper A's heterogeneous example with noise (``python make_data.py``).

The "measured" interface is ``ale_fsi`` (Saint Venant-Kirchhoff, default mesh) with the three
layers of ``LAYERS`` at Paper A's reference values E1 = 500, nu1 = 0.2, E2 = 200, nu2 = 0.1,
E3 = 1000, nu3 = 0.3 and inflow 100 mm^2/s, every vertex and measurement point moved along its
normal by Gaussian noise of 1e-3 mm (Paper A: "Gaussian noise with standard deviation 10^-3 mm
was added"), 12 measurement points with normal directions.  Seeded: the files are the same every
time; ``--seed S --out DIR`` writes another noise draw elsewhere (how far the optima move with
the draw: README.md).  The study files of the Remark 1 workflow (study_homogeneous_fit.toml,
study_E_only.toml, study_all_six.toml) read these files, so that the homogeneous fit sees the
heterogeneous data.
"""

import argparse
from pathlib import Path

import fbia

HERE = Path(__file__).parent
TRUTH = {"E_1": 500.0, "nu_1": 0.2, "E_2": 200.0, "nu_2": 0.1, "E_3": 1000.0, "nu_3": 0.3}
#: Paper A Fig. 9 as layers of the mound (height 0.5036 mm; Paper B's split at 15 % and 50 %
#: of the height): solid_1 the top (y > 0.2518 mm), solid_2 the middle, the rest (solid_3) the
#: footing layer (y < 0.0755 mm) -- the study files give the same polygons.
LAYERS = [
    [(0.0, 0.2518), (2.0, 0.2518), (2.0, 1.0), (0.0, 1.0)],
    [(0.0, 0.0755), (2.0, 0.0755), (2.0, 0.2518), (0.0, 0.2518)],
]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, default=20220417, help="noise draw (default: the files')")
    p.add_argument("--out", type=Path, default=HERE / "data", help="folder (default: data/)")
    args = p.parse_args()
    model = fbia.forward_model("ale_fsi", material="svk", subdomains=LAYERS)
    (obs,) = fbia.synthetic_observations(
        model, TRUTH, [{"inflow_rate": 100.0}], noise_std=1e-3, seed=args.seed, points=12
    )
    args.out.mkdir(parents=True, exist_ok=True)
    obs.interface.write(args.out / "observed_100.csv")
    obs.measurement_points.write(args.out / "points_100.csv")
    print(f"wrote {args.out}/observed_100.csv, {args.out}/points_100.csv")


if __name__ == "__main__":
    main()
