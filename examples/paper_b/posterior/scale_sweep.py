"""Does one scale of the log-likelihood bring all three example-7 cases to Paper B's numbers?
(issue 27, item 1: the decisive question)

    python examples/paper_b/posterior/scale_sweep.py            # about 25 min on 2 cores
    python examples/paper_b/posterior/scale_sweep.py uniform    # one case

Paper B's readings that change the scale of D^2 (README.md) act on the posterior through one
number, the steepness of L = -D^2 / (2 sigma_N^2) (eq. 5): a factor on sigma_N^2 (the noise,
the element count n in eq. 5, unit-free normalisations of the currents) or a wider kernel
sigma_W (which also smooths).  This script runs the three studies of this folder (uniform,
informed, inflow; every forward run from their stores, only the checks at posterior draws run
anew) at

- sigma_N^2 = k * 0.0005 mm^2 for k = 1, 4, 16, 32, 64 (sigma_W = 0.005 mm), and
- sigma_W = 0.01 and 0.02 mm (sigma_N^2 = 0.0005 mm^2),

and tabulates MAP, posterior mean and std and the angle between the principal axes of the
Laplace approximation and of the particles (Fig. 9a: "almost orthogonal") beside the paper's.
Rule, written before the run: a setting brings a case to the paper when its MAP and PM
agree by the project's strict rule (E within 2 %, nu within 0.02); the answer is "yes" only
if one setting does so for all three cases.  Each setting's distance from the paper is also
given as the largest of |E - E_paper| / (0.02 E_paper) and |nu - nu_paper| / 0.02 over the
four numbers of a case (1: on the rule's edge).

Output: ``output_scale_sweep/`` (one folder per case and setting, read back instead of run
again when it holds a result) and ``scale_sweep.md``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import fbia

HERE = Path(__file__).resolve().parent
OUT = HERE / "output_scale_sweep"
SIGMA_N2 = 0.0005  # mm^2, Paper B

#: case -> (MAP, PM) in the paper, (E [Pa], nu)
PAPER = {
    "uniform": ((388.0, 0.266), (431.0, -0.0071)),
    "informed": ((361.0, 0.195), (377.0, 0.08)),
    "inflow": ((322.0, 0.09), (416.0, -0.09)),
}
#: name -> (factor on sigma_N^2, sigma_W [mm])
SETTINGS = {
    "paper": (1.0, 0.005),
    "sigma_N2 x4": (4.0, 0.005),
    "sigma_N2 x16": (16.0, 0.005),
    "sigma_N2 x32": (32.0, 0.005),
    "sigma_N2 x64": (64.0, 0.005),
    "sigma_W 0.01": (1.0, 0.01),
    "sigma_W 0.02": (1.0, 0.02),
}


def run_case(case: str, name: str, factor: float, sigma_w: float) -> dict[str, float]:
    study = fbia.load_study(HERE / f"study_{case}.toml")
    measure = fbia.measure("rkhs", sigma_w=sigma_w, residuals="distance")
    tag = name.replace(" ", "_").replace("^", "")
    variant = dataclasses.replace(
        study,
        name=f"example 7 {case}, {name}",
        noise_std=math.sqrt(factor * SIGMA_N2),
        measure=measure,
        output=OUT / case / tag,
        paper=None,
        figures=False,
    )
    done = variant.output / "result.json"  # a setting already run: read, not run again
    result = fbia.load_result(done) if done.is_file() else fbia.run_study(variant, echo=_quiet)
    q = result.quantities()
    return {
        "status": result.status,
        "map.E": q["map.E"],
        "map.nu": q["map.nu"],
        "pm.E": q["pm.E"],
        "pm.nu": q["pm.nu"],
        "sd.E": q["sd.E"],
        "sd.nu": q["sd.nu"],
        "laplace.angle": q.get("laplace.angle", math.nan),
    }


def _quiet(line: str) -> None:
    pass


def distance(case: str, row: dict[str, float]) -> float:
    (me, mn), (pe, pn) = PAPER[case]
    return max(
        abs(row["map.E"] - me) / (0.02 * me),
        abs(row["map.nu"] - mn) / 0.02,
        abs(row["pm.E"] - pe) / (0.02 * pe),
        abs(row["pm.nu"] - pn) / 0.02,
    )


def main() -> None:
    cases = sys.argv[1:] or list(PAPER)
    rows = []
    for name, (factor, sigma_w) in SETTINGS.items():
        for case in cases:
            print(f"== {case}: {name}", flush=True)
            row = run_case(case, name, factor, sigma_w)
            row["distance"] = distance(case, row)
            rows.append((name, case, row))
            print(row, flush=True)
    lines = [
        "# Example 7 over the scale of the log-likelihood",
        "",
        "Written by `scale_sweep.py` (its docstring states the rule). Distance: the largest "
        "deviation from the paper's MAP and PM in units of the strict rule (<= 1 agrees).",
        "",
        "| setting | case | status | MAP (E, nu) | PM (E, nu) | sd (E, nu) | Laplace angle [deg] "
        "| paper MAP | paper PM | distance |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, case, r in rows:
        (me, mn), (pe, pn) = PAPER[case]
        lines.append(
            f"| {name} | {case} | {r['status']} | ({r['map.E']:.1f}, {r['map.nu']:.3f}) | "
            f"({r['pm.E']:.1f}, {r['pm.nu']:.3f}) | ({r['sd.E']:.1f}, {r['sd.nu']:.3f}) | "
            f"{r['laplace.angle']:.0f} | ({me:g}, {mn:g}) | ({pe:g}, {pn:g}) | "
            f"{r['distance']:.1f} |"
        )
    settings_all = [
        name
        for name in SETTINGS
        if all(r["distance"] <= 1.0 for n, c, r in rows if n == name)
        and len([1 for n, _c, _r in rows if n == name]) == len(PAPER)
    ]
    lines += [
        "",
        "One setting for all three cases: "
        + (", ".join(settings_all) if settings_all else "none of those tried")
        + ".",
    ]
    OUT.mkdir(exist_ok=True)
    (OUT / "scale_sweep.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
