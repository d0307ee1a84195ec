"""Regenerate the data files of this example (``python make_data.py``).

The "observed" interfaces are the analytic 2-D mound (``analytic_mound_2d``, 81 vertices) at
the ground truth E = 400 Pa, nu = 0.3 for two inflow rates, 100 and 50 mm^2/s, each vertex
moved along its normal by Gaussian noise of standard deviation 0.5 um (0.0005 mm), with 12
measurement points (and their normal directions) per state for the ``ray`` measure.  Seeded,
so the files are the same every time.
"""

from pathlib import Path

import fbia

HERE = Path(__file__).parent
TRUTH = {"E": 400.0, "nu": 0.3}


def main() -> None:
    model = fbia.forward_model("analytic_mound_2d", n_points=81)
    observations = fbia.synthetic_observations(
        model,
        TRUTH,
        [{"inflow_rate": 100.0}, {"inflow_rate": 50.0}],
        noise_std=0.0005,
        seed=20240101,
        points=12,
    )
    for obs in observations:
        rate = int(obs.coordinate["inflow_rate"])
        obs.interface.write(HERE / "data" / f"observed_{rate}.csv")
        obs.measurement_points.write(HERE / "data" / f"points_{rate}.csv")
        print(f"wrote data/observed_{rate}.csv, data/points_{rate}.csv")


if __name__ == "__main__":
    main()
