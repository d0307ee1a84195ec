"""Take a result away: load what ``fbia run`` wrote, draw its figures, hand a posterior to ArviZ.

After ``make demo`` (which writes ``output/`` and ``output_bayes/`` here)::

    python examples/flow_cell/load_results.py                       # the Bayesian demo
    python examples/flow_cell/load_results.py output study.toml     # the LM demo

Arguments: the output folder (or its ``result.json``) and the study file that made it
(relative to this folder); figures go to ``<folder>/replotted``.  Reading the study file
makes its synthetic data again (one forward run): the figures need the problem for the
parameters' units and priors and mark its ground truth.
"""

from __future__ import annotations

import sys
from pathlib import Path

import fbia

HERE = Path(__file__).resolve().parent


def main(folder: Path, study_file: Path) -> list[Path]:
    result = fbia.load_result(folder)  # LMResult, GpSmcResult, ... as fbia run wrote it
    print(result.summary())
    print(f"status {result.status}, x = {result.x}, {result.nfev} forward runs")
    problem = fbia.load_study(study_file).problem
    paths = fbia.plot(result, problem, Path(folder) / "replotted")
    for path in paths:
        print(f"figure: {path}")
    posterior = Path(folder) / "posterior.nc"
    if posterior.is_file():  # gp_smc: the weighted particles as equally weighted draws
        import arviz as az

        data = az.from_netcdf(posterior)
        print(az.summary(data, kind="stats", hdi_prob=0.95))
        print(f"ArviZ groups: {', '.join(data.groups())}")
    return paths


if __name__ == "__main__":
    args = sys.argv[1:] or ["output_bayes", "study_bayes.toml"]
    main(HERE / args[0], HERE / (args[1] if len(args) > 1 else "study_bayes.toml"))
