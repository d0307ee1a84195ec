"""Example 8's 10-bin MAP over GP seeds (issue 27 item 4).

    python examples/paper_b/heterogeneous/gp_seeds.py 1 2     # about 2 min per seed on 2 cores

``study.toml``'s design and runs (every forward run from its store), refitted with the GP's
restart guesses seeded by ``gp_seed`` = each argument (``study.toml`` itself: gp_seed = seed =
0), then SMC and the 10-bin MAP as the study does.  Prints the MAP and posterior mean per seed;
the README compares them with study.toml's.  Output: ``output_gp_seed_<k>/``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import fbia
from fbia.core.options import plugin_options

HERE = Path(__file__).resolve().parent


def main() -> None:
    study = fbia.load_study(HERE / "study.toml")
    options = plugin_options(study.iterator)
    store = study.store or (study.output / "store.sqlite")
    for k in map(int, sys.argv[1:] or ["1", "2"]):
        refit = dataclasses.replace(
            study,
            name=f"{study.name}, gp_seed {k}",
            iterator=fbia.iterator("gp_smc", **{**options, "gp_seed": k}),
            output=HERE / f"output_gp_seed_{k}",
            store=store,
            paper=None,
            figures=False,
        )
        result = fbia.run_study(refit, echo=lambda line: None)
        q = result.quantities()
        row = {n: q.get(f"map.{n}") for n in result.names} | {
            f"pm.{n}": q.get(f"pm.{n}") for n in result.names
        }
        print(json.dumps({"gp_seed": k, "status": result.status, **row}), flush=True)


if __name__ == "__main__":
    main()
