"""Remark 1 and Table 3 over measurement-point layouts (issue 26).

    python examples/paper_a/heterogeneous/sweep_points.py     # about 10 min on 2 cores

Some of the heterogeneous example's numbers disagree for a cause not yet found: E_2 = 226 Pa
and E_3 = 510 Pa of Remark 1's step 2 lay outside fbia's ranges over 20 noise draws, and not
all three noise-free Table 3 starts converge (orange, and with QUEENS' mu rule green too, take
nu_1 to the bound); the homogeneous fit's E (323 Pa) is off as well, measured to move with the
layer cut (``sweep_layers.py``).  The layer cut is ruled out for the first three; the
candidate measured here is the layout of the measurement points, which Paper A shows only as a
picture (Fig. 10: normal to the interface, "two measurement points were chosen on the
interface of the stiffer footing layer").  The studies use 12 points evenly along the
interface (two on the footing layer).

For every layout of ``LAYOUTS`` the script runs, with the studies' layer cut,

- step 2 (``study_E_only_draws.toml``, its first 20 noise draws): fbia's 2.5-97.5 % range
  of each E_k,
- step 1 (``study_homogeneous_fit.toml``) on one draw (``make_data.py``'s noise seed),
- the noise-free Table 3 starts (``study_noise_free.toml``): how many converge,

and counts the layout's points on the footing layer (y < 0.0755 mm).  Rule, written before
the run: the layout explains a number when, at some layout, the paper's number lies inside
fbia's range (step 2), within the strict rule (step 1: E within 2 %), or all three Table 3
starts converge.  Otherwise the points are not the cause.  The last layout, ``fig10``, was
added after the first six had run: Fig. 10 as the text describes it, the homogeneous
example's ten points where the interface moved and two on the footing layer (on its upstream
and downstream flanks, at half its height), all normal to the interface.

Output: ``output_sweep_points/`` (a store per layout and study, ``points.md``).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

import fbia
from fbia.studies.draws import draw_seed, fresh_model

HERE = Path(__file__).resolve().parent
OUT = HERE / "output_sweep_points"
FOOTING = 0.0755  # mm, the studies' lower cut
TRUTH = {"E_1": 500.0, "nu_1": 0.2, "E_2": 200.0, "nu_2": 0.1, "E_3": 1000.0, "nu_3": 0.3}
NOISE_SEED = 20220417  # make_data.py's
DRAWS = 20  # noise draws of step 2 per layout (the first 20 of study_E_only_draws.toml's)

#: name -> (points, placement, significant)
LAYOUTS: dict[str, tuple[int, str, float]] = {
    "even_12": (12, "even", 0.5),  # the studies'
    "even_10": (10, "even", 0.5),
    "even_20": (20, "even", 0.5),
    "moved_10": (10, "displacement", 0.5),  # the homogeneous example's (Fig. 3)
    "moved_12_wide": (12, "displacement", 0.25),  # reaching down the flanks
    "moved_12_low": (12, "displacement", 0.1),  # nearly all of the moving interface
}


def synthetic(study: fbia.Study, layout: tuple[int, str, float]) -> fbia.Study:
    points, placement, significant = layout
    assert study.synthetic is not None
    draws = min(study.synthetic.draws, DRAWS)
    spec = dataclasses.replace(
        study.synthetic, points=points, placement=placement, significant=significant, draws=draws
    )
    return dataclasses.replace(study, synthetic=spec)


def footing_points(study: fbia.Study) -> int:
    """The layout's points on the footing layer, from the noise-free data of the truth."""
    spec = study.synthetic
    assert spec is not None
    (obs,) = fbia.synthetic_observations(
        study.model,
        TRUTH,
        [{"inflow_rate": 100.0}],
        noise_std=0.0,
        seed=0,
        points=spec.points,
        placement=spec.placement,
        significant=spec.significant,
    )
    assert obs.points is not None
    return int(np.sum(obs.points.points[:, 1] < FOOTING))


def run(study: fbia.Study, name: str, tag: str) -> fbia.Result:
    """The study on the layout ``name``, with a store of its own (one model per store)."""
    sub = dataclasses.replace(
        study,
        name=f"{study.name}, points {name}",
        output=OUT / name / tag,
        store=OUT / name / f"store_{tag}.sqlite",
        paper=None,
        figures=False,
    )
    return fbia.run_study(sub, echo=lambda line: None)


def one_layout(name: str) -> dict:
    layout = LAYOUTS[name]
    step2 = synthetic(fbia.load_study(HERE / "study_E_only_draws.toml"), layout)
    q2 = run(step2, name, "E_only_draws").quantities()
    free = synthetic(fbia.load_study(HERE / "study_noise_free.toml"), layout)
    q0 = run(free, name, "noise_free").quantities()
    hom = fbia.load_study(HERE / "study_homogeneous_fit.toml")
    points, placement, significant = layout
    (obs,) = fbia.synthetic_observations(
        step2.model,
        TRUTH,
        [{"inflow_rate": 100.0}],
        noise_std=1e-3,
        seed=NOISE_SEED,
        points=points,
        placement=placement,
        significant=significant,
    )
    q1 = run(dataclasses.replace(hom, observations=[obs]), name, "homogeneous_fit").quantities()
    return {
        "layout": name,
        "points": points,
        "placement": placement,
        "significant": significant,
        "footing_points": footing_points(free),
        "step2": {n: (q2[f"low.x.{n}"], q2[f"high.x.{n}"]) for n in ("E_1", "E_2", "E_3")},
        "step2_judged": q2["n_judged"],
        "step1": (q1["mean.E"], q1["mean.nu"]),
        "noise_free_converged": q0["n_converged"],
    }


def footing_pair(gamma: fbia.Interface, y: float) -> tuple[np.ndarray, np.ndarray]:
    """The first and the last point where the interface polyline crosses height ``y`` (the
    upstream and the downstream flank of the footing layer) and the unit normals there."""
    v, n = gamma.vertices, gamma.vertex_normals
    pts, nrm = [], []
    for a, b in gamma.cells:
        ya, yb = v[a, 1], v[b, 1]
        if (ya - y) * (yb - y) <= 0.0 and ya != yb:
            w = (y - ya) / (yb - ya)
            pts.append((1 - w) * v[a] + w * v[b])
            m = (1 - w) * n[a] + w * n[b]
            nrm.append(m / np.linalg.norm(m))
    order = np.argsort([p[0] for p in pts])
    pick = [order[0], order[-1]]
    return np.array([pts[i] for i in pick]), np.array([nrm[i] for i in pick])


def fig10_observations(model: object, sigma: float, seeds: list[int]) -> list[fbia.Observation]:
    """Paper A Fig. 10 as the text describes it: the homogeneous example's 10 points where
    the interface moved (``moved_10``) and two on the footing layer's flanks (half its
    height), normal to the interface; per seed the noise as ``fbia.synthetic_observations``
    draws it (first on the interface's vertices, then on the points)."""
    (clean,) = fbia.synthetic_observations(
        model,
        TRUTH,
        [{"inflow_rate": 100.0}],
        noise_std=0.0,
        seed=0,
        points=10,
        placement="displacement",
        significant=0.5,
    )
    assert clean.points is not None and clean.points.directions is not None
    extra, extra_dirs = footing_pair(clean.interface, 0.5 * FOOTING)
    points = np.vstack([clean.points.points, extra])
    dirs = np.vstack([clean.points.directions, extra_dirs])
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        gamma = clean.interface
        noisy = gamma.with_vertices(
            gamma.vertices
            + sigma * rng.standard_normal((len(gamma.vertices), 1)) * gamma.vertex_normals
        )
        mp = points + sigma * rng.standard_normal((len(points), 1)) * dirs
        out.append(
            fbia.Observation(
                interface=noisy,
                coordinate={"inflow_rate": 100.0},
                points=mp,
                directions=dirs,
                name=f"fig10 seed {seed}",
            )
        )
    return out


def fig10_layout() -> dict:
    """The sweep's rows for the Fig. 10 layout (its draws run one by one: the layout is not a
    ``[synthetic]`` placement)."""
    name = "fig10_moved_10_footing_2"
    step2 = fbia.load_study(HERE / "study_E_only_draws.toml")
    assert step2.synthetic is not None
    seeds = [draw_seed(step2.synthetic.seed, k) for k in range(DRAWS)]
    xs = []
    for k, obs in enumerate(fig10_observations(step2.model, 1e-3, seeds)):
        one = dataclasses.replace(
            step2, synthetic=None, observations=[obs], model=fresh_model(step2.model)
        )
        r = run(one, name, f"E_only_draw_{k:02d}")
        if r.success:
            xs.append([r.x[f"E_{i}"] for i in (1, 2, 3)])
    e = np.array(xs)
    free = fbia.load_study(HERE / "study_noise_free.toml")
    (clean,) = fig10_observations(free.model, 0.0, [0])
    q0 = run(
        dataclasses.replace(free, synthetic=None, observations=[clean]), name, "noise_free"
    ).quantities()
    (one,) = fig10_observations(step2.model, 1e-3, [NOISE_SEED])
    hom = fbia.load_study(HERE / "study_homogeneous_fit.toml")
    q1 = run(dataclasses.replace(hom, observations=[one]), name, "homogeneous_fit").quantities()
    return {
        "layout": name,
        "points": 12,
        "placement": "displacement + 2 footing",
        "significant": 0.5,
        "footing_points": 2,
        "step2": {
            f"E_{i}": (
                float(np.percentile(e[:, i - 1], 2.5)),
                float(np.percentile(e[:, i - 1], 97.5)),
            )
            for i in (1, 2, 3)
        },
        "step2_judged": float(len(xs)),
        "step1": (q1["mean.E"], q1["mean.nu"]),
        "noise_free_converged": q0["n_converged"],
    }


def main() -> None:
    rows = []
    for name in [*LAYOUTS, "fig10"]:
        print(f"== layout {name} {LAYOUTS.get(name, 'Fig. 10')}", flush=True)
        rows.append(fig10_layout() if name == "fig10" else one_layout(name))
        print(json.dumps(rows[-1]), flush=True)
    lines = [
        "# Remark 1 and Table 3 over measurement-point layouts",
        "",
        "Written by `sweep_points.py` (its docstring states the rule). Step 2: fbia's "
        "2.5-97.5 % range over 20 noise draws; step 1: one draw (make_data.py's seed), the "
        "mean of the two starts; Table 3: noise-free, the three starts.",
        "",
        "| layout | points | placement | significant | on the footing | E_1 range [Pa] | "
        "E_2 range (paper 226) | E_3 range (paper 510) | step 1: E (paper 323) | "
        "step 1: nu (paper 0.0656) | Table 3 converged (paper 3) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        s2 = r["step2"]
        lines.append(
            f"| {r['layout']} | {r['points']} | {r['placement']} | {r['significant']:g} | "
            f"{r['footing_points']} | "
            + " | ".join(f"{s2[n][0]:.1f}-{s2[n][1]:.1f}" for n in ("E_1", "E_2", "E_3"))
            + f" | {r['step1'][0]:.1f} | {r['step1'][1]:.4f} | {r['noise_free_converged']:g} |"
        )
    n = len(rows)
    inside2 = sum(r["step2"]["E_2"][0] <= 226.0 <= r["step2"]["E_2"][1] for r in rows)
    inside3 = sum(r["step2"]["E_3"][0] <= 510.0 <= r["step2"]["E_3"][1] for r in rows)
    within = sum(abs(r["step1"][0] - 323.0) <= 0.02 * 323.0 for r in rows)
    three = sum(r["noise_free_converged"] == 3 for r in rows)
    lines += [
        "",
        f"E_2 = 226 Pa inside fbia's range at {inside2} of {n} layouts; E_3 = 510 Pa at "
        f"{inside3}; the homogeneous fit's E within 2 % of 323 Pa at {within}; all three "
        f"Table 3 starts converge at {three}.",
    ]
    OUT.mkdir(exist_ok=True)
    (OUT / "points.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
