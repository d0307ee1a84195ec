"""Remark 1 over layer cuts, and step 3 from each draw's own step 2 (issue 26).

    python examples/paper_a/heterogeneous/sweep_layers.py           # about 6 min on 2 cores
    python examples/paper_a/heterogeneous/sweep_layers.py chain     # about 1 min more

Paper A gives its three layers only as a picture (Fig. 9); fbia cuts the mound at 15 and 50 %
of its height (``study_*.toml``, ``make_data.py``).  Three of Remark 1's numbers lie outside
what fbia finds there: E_2 = 226 Pa and E_3 = 510 Pa of step 2 (fbia's ranges over 20 noise
draws: 196-214 and 559-1440 Pa) and E = 323 Pa of the homogeneous fit (fbia: 278.6 Pa).  The
candidate "the layer cut" is measured here: for every cut of ``CUTS`` the script runs

- step 2 (``study_E_only_draws.toml``: E_k with nu = 0.1, its first 20 noise draws) and reports the
  2.5-97.5 % range of each E_k over the draws, and
- step 1 (``study_homogeneous_fit.toml``: one E and nu) on the layered model's data with the
  noise of ``make_data.py`` (its seed), and reports E and nu (mean over the two starts),

and reports which layer is the largest (Paper B on the same subdomains: "Omega_2 takes up the
largest portion of the biofilm").  Rule, written before the run: the cut explains a number
when, at some cut, the paper's number lies inside fbia's range (step 2) or within the strict
rule (step 1: E within 2 %).

``chain``: step 3 (``study_all_six_draws.toml``) with every draw started from its own step-2
result (E_k of that draw, nu = 0.1), as the paper chains its steps, instead of from the
paper's step-2 numbers: which draws give no result then.

Output: ``output_sweep_layers/`` (a store per cut, ``layers.md``, ``chain.md``).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import fbia
from fbia.studies.draws import draw_study

HERE = Path(__file__).resolve().parent
OUT = HERE / "output_sweep_layers"
HEIGHT = 0.5036  # mm, the mound's height (plugins/fem/outlines.py, "paper_a_facts")
TRUTH = {"E_1": 500.0, "nu_1": 0.2, "E_2": 200.0, "nu_2": 0.1, "E_3": 1000.0, "nu_3": 0.3}
NOISE_SEED = 20220417  # make_data.py's
DRAWS = 20  # noise draws of step 2 per cut (the first 20 of study_E_only_draws.toml's)

#: (lower cut, upper cut) as fractions of the height; the first is the studies'
CUTS = [(0.15, 0.50), (0.10, 0.40), (0.10, 0.50), (0.20, 0.50), (0.15, 0.60), (0.25, 0.60)]


def layers(lo: float, hi: float) -> list[list[tuple[float, float]]]:
    """solid_1 above ``hi``, solid_2 between, solid_3 (the footing) below ``lo``."""
    y_lo, y_hi = round(lo * HEIGHT, 4), round(hi * HEIGHT, 4)
    return [
        [(0.0, y_hi), (2.0, y_hi), (2.0, 1.0), (0.0, 1.0)],
        [(0.0, y_lo), (2.0, y_lo), (2.0, y_hi), (0.0, y_hi)],
    ]


def layer_areas(lo: float, hi: float) -> list[float]:
    from shapely.geometry import Polygon, box

    from fbia.plugins.fem.outlines import NAMED_OUTLINES

    mound = Polygon(NAMED_OUTLINES["paper_a_facts"])
    y_lo, y_hi = lo * HEIGHT, hi * HEIGHT
    bands = [(y_hi, 1.0), (y_lo, y_hi), (0.0, y_lo)]
    return [mound.intersection(box(0.0, a, 2.0, b)).area for a, b in bands]


def step2(tag: str, lo: float, hi: float) -> dict[str, tuple[float, float]]:
    study = fbia.load_study(HERE / "study_E_only_draws.toml")
    model = fbia.forward_model("ale_fsi", material="svk", subdomains=layers(lo, hi))
    assert study.synthetic is not None
    cut = dataclasses.replace(
        study,
        synthetic=dataclasses.replace(study.synthetic, draws=min(DRAWS, study.synthetic.draws)),
        name=f"E_only draws, cut {tag}",
        model=model,
        output=OUT / tag / "E_only_draws",
        store=OUT / tag / "store.sqlite",
        paper=None,
        figures=False,
    )
    result = fbia.run_study(cut, echo=lambda line: None)
    q = result.quantities()
    return {n: (q[f"low.x.{n}"], q[f"high.x.{n}"]) for n in ("E_1", "E_2", "E_3")}


def step1(tag: str, lo: float, hi: float) -> tuple[float, float]:
    data_model = fbia.forward_model("ale_fsi", material="svk", subdomains=layers(lo, hi))
    (obs,) = fbia.synthetic_observations(
        data_model, TRUTH, [{"inflow_rate": 100.0}], noise_std=1e-3, seed=NOISE_SEED, points=12
    )
    study = fbia.load_study(HERE / "study_homogeneous_fit.toml")
    cut = dataclasses.replace(
        study,
        name=f"homogeneous fit, cut {tag}",
        observations=[obs],
        output=OUT / tag / "homogeneous_fit",
        store=OUT / tag / "store_homogeneous.sqlite",
        paper=None,
        figures=False,
    )
    q = fbia.run_study(cut, echo=lambda line: None).quantities()
    return q["mean.E"], q["mean.nu"]


def sweep() -> None:
    rows = []
    for lo, hi in CUTS:
        tag = f"{round(lo * 100)}_{round(hi * 100)}"
        print(f"== cut at {lo:.0%} and {hi:.0%} of the height", flush=True)
        areas = layer_areas(lo, hi)
        ranges = step2(tag, lo, hi)
        e, nu = step1(tag, lo, hi)
        rows.append((lo, hi, areas, ranges, e, nu))
        print(json.dumps({"cut": [lo, hi], "areas": areas, "step2": ranges, "step1": [e, nu]}))
    lines = [
        "# Remark 1 over layer cuts",
        "",
        "Written by `sweep_layers.py` (its docstring states the rule). Step 2: fbia's "
        "2.5-97.5 % range over 20 noise draws; step 1: one draw (make_data.py's seed), the "
        "mean of the two starts.",
        "",
        "| cut (of the height) | areas Omega_1 / 2 / 3 [mm^2] | Omega_2 largest | "
        "E_1 range [Pa] | E_2 range (paper 226) | E_3 range (paper 510) | "
        "step 1: E (paper 323) | step 1: nu (paper 0.0656) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for lo, hi, areas, r, e, nu in rows:
        largest = areas[1] > max(areas[0], areas[2])
        lines.append(
            f"| {lo:.0%} / {hi:.0%} | {' / '.join(f'{a:.4f}' for a in areas)} | {largest} | "
            + " | ".join(f"{r[n][0]:.1f}-{r[n][1]:.1f}" for n in ("E_1", "E_2", "E_3"))
            + f" | {e:.1f} | {nu:.4f} |"
        )
    inside2 = sum(r["E_2"][0] <= 226.0 <= r["E_2"][1] for *_, r, _e, _n in rows)
    inside3 = sum(r["E_3"][0] <= 510.0 <= r["E_3"][1] for *_, r, _e, _n in rows)
    within = sum(abs(e - 323.0) <= 0.02 * 323.0 for *_, e, _n in rows)
    lines += [
        "",
        f"E_2 = 226 Pa inside fbia's range at {inside2} of {len(rows)} cuts; E_3 = 510 Pa at "
        f"{inside3}; the homogeneous fit's E within 2 % of 323 Pa at {within}.",
    ]
    OUT.mkdir(exist_ok=True)
    (OUT / "layers.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


def chain() -> None:
    """Step 3 from each draw's own step 2 (needs output_E_only_draws of study_E_only_draws)."""
    six = fbia.load_study(HERE / "study_all_six_draws.toml")
    step2_draws = HERE / "output_E_only_draws" / "draws"
    if not step2_draws.is_dir():
        sys.exit(f"run `fbia run {HERE / 'study_E_only_draws.toml'}` first")
    options = dict(mode="paper", alpha=1e-5, beta=1e-3, eps_grad=1e-8, max_iter=100)
    lines = [
        "# Remark 1, step 3 from each draw's own step 2",
        "",
        "| draw | step 2 status | start E_1 / E_2 / E_3 [Pa] | step 3 status | "
        "nu_1 / nu_2 / nu_3 at the end |",
        "|---|---|---|---|---|",
    ]
    assert six.synthetic is not None
    lost = chained = 0
    for k, folder in enumerate(sorted(step2_draws.iterdir())[: six.synthetic.draws]):
        own = json.loads((folder / "result.json").read_text(encoding="utf-8"))
        x = own["x"]
        if x is None:  # step 2 gave no result: nothing to chain from
            lines.append(f"| {k} | {own['status']} | - | - | - |")
            continue
        chained += 1
        x0 = {}
        for i in (1, 2, 3):
            x0[f"E_{i}"], x0[f"nu_{i}"] = x[f"E_{i}"], 0.1
        sub = draw_study(six, k, OUT / "chain", OUT / "chain" / "store.sqlite")
        lm = fbia.iterator("levenberg_marquardt", x0=x0, **options)
        sub = dataclasses.replace(sub, iterator=lm)
        result = fbia.run_study(sub, echo=lambda line: None)
        last = [h["x"] for h in result.history if h.get("x")][-1]
        lost += not result.success
        nus = " / ".join(f"{last[f'nu_{i}']:.3f}" for i in (1, 2, 3))
        starts = " / ".join(f"{x[f'E_{i}']:.1f}" for i in (1, 2, 3))
        lines.append(f"| {k} | {own['status']} | {starts} | {result.status} | {nus} |")
        print(lines[-1], flush=True)
    lines += ["", f"{lost} of {chained} draws give no result from their own step 2."]
    (OUT / "chain.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    chain() if sys.argv[1:] == ["chain"] else sweep()
