"""Paper A's poroelastic paths over measurement-point layouts (issue 26 item 4).

    python examples/paper_a/poroelastic/sweep_layouts.py      # about 15 min on 2 cores

Paper A reports two findings of this example that fbia's ``study.toml`` (12 points evenly
along the interface) does not reproduce: the orange start (400 Pa, phi0 = 0.4) drifts to the
bound phi_max = 0.9 and ends without result, and green (300 Pa, 0.6) needs many more steps
than blue (400 Pa, 0.2): 27 against 9.  The paper places its points "where the interface moves
most, one on the lower downstream bump" (Fig. 16) without coordinates, so this script runs the
study on several layouts of the synthetic measurement points and counts how often each finding
appears.  Rules, written before the run: orange "ends at the phi bound" when its result has
no parameters and its last iterate has phi0 >= 0.85, or its result lies on the phi bound;
green "needs >= 2x blue's steps" when both converge and green's iterations are at least twice
blue's.

Each layout is the study file with other ``[synthetic]`` points (``points``, ``placement``,
``significant``; ``placement = "displacement"`` puts them evenly over the parts of the
interface whose normal displacement is at least ``significant`` times its largest, i.e. where
it moves most, Fig. 16); all layouts share one store (``output_layouts/store.sqlite``) and
write ``output_layouts/<layout>/``; the table goes to ``output_layouts/layouts.md``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import fbia

HERE = Path(__file__).resolve().parent
OUT = HERE / "output_layouts"

#: name -> (points, placement, significant)
LAYOUTS: dict[str, tuple[int, str, float]] = {
    "even_12": (12, "even", 0.5),  # study.toml's until issue 26 moved it to moved_10
    "even_8": (8, "even", 0.5),
    "moved_10": (10, "displacement", 0.5),  # where it moves most (Fig. 16): study.toml's
    "moved_6": (6, "displacement", 0.5),
    "moved_10_wide": (10, "displacement", 0.25),  # reaching further down the flanks
    "moved_10_top": (10, "displacement", 0.75),  # only the most displaced part
    "moved_16_wide": (16, "displacement", 0.25),
}


def run_layout(name: str, points: int, placement: str, significant: float) -> dict:
    study = fbia.load_study(HERE / "study.toml")
    assert study.synthetic is not None
    synthetic = dataclasses.replace(
        study.synthetic, points=points, placement=placement, significant=significant
    )
    layout = dataclasses.replace(
        study,
        name=f"poroelastic layout {name}",
        synthetic=synthetic,
        output=OUT / name,
        store=OUT / "store.sqlite",
        paper=None,
        figures=False,
    )
    result = fbia.run_study(layout, echo=lambda line: None)
    q = result.quantities()
    starts = {s["label"]: s for s in result.starts}
    orange = starts["orange"]
    last_phi = [h["x"]["phi0"] for h in result.history if h["chain"] == 1][-1]
    at_bound = (orange["x"] is None and last_phi >= 0.85) or "phi0" in orange["at_bound"]
    blue, green = q["start.blue.iterations"], q["start.green.iterations"]
    both = q["start.blue.converged"] == 1 and q["start.green.converged"] == 1
    return {
        "layout": name,
        "points": points,
        "placement": placement,
        "significant": significant,
        "orange": orange["status"],
        "orange_last_phi0": last_phi,
        "orange_at_phi_bound": bool(at_bound),
        "blue_iterations": blue,
        "green_iterations": green,
        "green_2x_blue": bool(both and green >= 2 * blue),
    }


def main() -> None:
    names = sys.argv[1:] or list(LAYOUTS)
    rows = []
    for name in names:
        print(f"== layout {name} {LAYOUTS[name]}", flush=True)
        rows.append(run_layout(name, *LAYOUTS[name]))
        print(json.dumps(rows[-1]), flush=True)
    lines = [
        "# Poroelastic paths over measurement-point layouts",
        "",
        "Written by `sweep_layouts.py` (its docstring states the rules).",
        "",
        "| layout | points | placement | significant | orange | orange's last phi0 | "
        "orange at the phi bound | blue steps | green steps | green >= 2x blue |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['layout']} | {r['points']} | {r['placement']} | {r['significant']:g} | "
            f"{r['orange']} | {r['orange_last_phi0']:.3f} | {r['orange_at_phi_bound']} | "
            f"{r['blue_iterations']:g} | {r['green_iterations']:g} | {r['green_2x_blue']} |"
        )
    n = len(rows)
    lines += [
        "",
        f"Orange ends at the phi bound in {sum(r['orange_at_phi_bound'] for r in rows)} of {n} "
        f"layouts; green needs at least twice blue's steps in "
        f"{sum(r['green_2x_blue'] for r in rows)} of {n}.",
    ]
    OUT.mkdir(exist_ok=True)
    (OUT / "layouts.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
