"""Benchmark: does gp_smc's status say when its posterior is wrong? (issues 30 and 42)

gp_smc reports ``completed`` or ``unreliable`` from its own diagnostics: the surrogate's RMSE
in L at forward runs at posterior draws (``RELIABLE_RMSE``), the share of failed runs there,
and the posterior averaged over the GP's sample paths (``MAX_SHIFT``, ``MAX_STD_RATIO`` in
``fbia.iterators.surrogates.uncertainty``).  Those limits are only useful if they separate
right posteriors from wrong ones.  This benchmark measures that against exact posteriors: for
every configuration below (a case of ``bayes_models``, a measure, sigma_N and gp_smc options;
some with the default budget, some starved so that the posterior can be wrong) and several
gp_smc seeds, it calls a posterior

* **right** by the rule of ``bench_bayes_targets`` written down before the runs: every
  posterior mean of x within 0.3 exact posterior std of the exact one and every std within a
  factor 1.5 (theta, the inflow, is not judged: the targets concern q(x | Y));
* **wrong** otherwise,

and prints the confusion table of (right, wrong) x (completed, unreliable) with the two rates
that matter: right posteriors that say ``completed`` (the checks do not cry wolf) and wrong
posteriors that say ``unreliable`` (the checks catch them; a wrong ``completed`` is a silently
wrong result).  The exact reference is ``fbia.smc`` on the vectorised eq. 5 (two seeds,
20 000 particles, checked converged), as in ``bench_bayes_targets``.

The configurations are issue 42's family of problems with exact posteriors at its budgets
(<= 100 runs in 2-D, <= 200 in 2 + 1-D, <= 1000 in 6 + 1-D): sharp (the layered mound of
``bayes_models``), broad and weakly identified (``7d_cpp_broad``: E1, E3 posterior std
24-26 % of their prior range, the nu_k 0.15-0.37, only E2 sharp), banana-shaped and
bimodal (``bayes_models.ShapeMapModel``, 2-D and 2 + 1-D), with the ray and cpp measures;
then starved and stopped-early runs that can be wrong.  Up to three inputs the exact
reference is quadrature on a grid (a bimodal posterior's mode weights exactly), beyond it
``fbia.smc`` on the vectorised eq. 5 (two seeds).

    .venv/bin/python benchmarks/bench_bayes_checks.py            # all configurations
    .venv/bin/python benchmarks/bench_bayes_checks.py --quick    # smoke run, < 1 min
    .venv/bin/python benchmarks/bench_bayes_checks.py --only 7d_cpp --seeds 2

The exit status is 0 whatever the rates.

Measured on 2026-11-29 at 554e986 (the rounds' SMC moving only when it resamples, the EIV
batch's covariance blocks on demand; gp_smc seeds 0-2 and 3-4 in two processes on the same 2
cores, 66 + 61 min; 19 configurations x 5 seeds = 95 runs):

* at issue 42's budgets (14 configurations: sharp, broad, banana, bimodal; 2-D, 2 + 1-D,
  6 + 1-D; ray, cpp and rkhs): 70 right posteriors of 70 (max 0.16 std off, std factors
  <= 1.28), all 70 ``completed`` (check error spreads <= 0.42 in L), with 32-100 runs in
  2-D, 44-143 in 2 + 1-D, 185-378 in 6 + 1-D (the broad case 221-316);
* starved: 11 wrong (0.42-3.4 std off), all ``unreliable`` (check errors 4.6-1190 in L);
  4 right by luck, ``unreliable`` (errors 2.9-10.2);
* stopped by a short budget: 10 right, 3 ``completed`` (errors <= 0.37), 7 ``unreliable``
  (0.70-12.1);
* silently wrong: 0 of 95. Right posteriors that say ``completed``: 70 of 70 at the budgets,
  73 of 84 over all configurations (87 %; the 11 others are the starved and short runs'
  right-by-luck posteriors, whose surrogates were 0.70-12 in L off at the check draws).

Measured on 2026-11-29 at b8decc2 (issue 42's cost cuts: warm hyperparameter searches on 300
runs, conditioning without GPy, joint EIV covariances over 500 candidates; gp_smc seeds 0-2,
17 configurations, 51 runs; 59 min with other benchmarks on the same 2 cores):

* at issue 42's budgets (12 configurations): 36 right posteriors of 36 (max 0.09 std off,
  std factors <= 1.10), all 36 ``completed``, with 32-43 runs in 2-D, 44-120 in 2 + 1-D,
  264-378 in 6 + 1-D (the broad case 316-378);
* starved: 7 wrong, all ``unreliable``; 2 right by luck, ``unreliable``;
* stopped by a short budget (120 and 150 runs in 6 + 1-D): 6 right, all ``unreliable``
  (check error spreads 0.87-2.0 in L: the design had not converged; at f52487b 4 of 10 such
  runs said ``completed`` with spreads 0.31-0.47);
* silently wrong: 0 of 51. Right posteriors that say ``completed``: 36 of 36 at the budgets,
  36 of 44 over all configurations.

That run had the candidates' variances of the EIV rule with the residual emulator's
second-order term (reverted at f3f79ea, example 8 showed why); after the revert,
``--only 2d_inflow_cpp banana_inflow_cpp 7d_cpp 7d_cpp_broad --seeds 1``: 4 of 4 right and
``completed`` (77, 52, 264, 316 runs; max 0.05 std off).

The RKHS configurations (``2d_rkhs``, ``banana_rkhs``; sigma_W = 0.01 mm, D as the residual;
quadrature references on 200 x 200 points through the measure itself) were added after that
run: ``--only 2d_rkhs banana_rkhs --seeds 3``, 6 right posteriors of 6 (max 0.18 std off, std
factors <= 1.32), all ``completed``, with 70-98 runs (<= 100).

Measured on 2026-11-29 at f52487b (idle 2 cores; gp_smc seeds 0-2, then 3-4 with
``--first-seed 3 --seeds 2``: 17 configurations x 5 seeds = 85 runs; 25 + 19 min, the exact
references included), issue 42's family and rule:

* at issue 42's budgets (12 configurations: sharp, broad, banana, bimodal; 2-D, 2 + 1-D,
  6 + 1-D; ray and cpp): 60 right posteriors of 60 (max 0.11 std off, std factors <= 1.10),
  all 60 ``completed``, with 32-43 runs in 2-D, 44-120 in 2 + 1-D, 155-452 in 6 + 1-D; the
  broad 6 + 1-D case (``7d_cpp_broad``) 155-324 runs, 18-36 s excluding them;
* starved (fixed Sobol designs of 30 and 150 runs): 11 wrong posteriors (0.4-3.4 std off,
  std factors 1.6-10), all 11 ``unreliable`` (check errors 4.6-1190 in L); 4 right by luck
  (0.13-0.22 std off), ``unreliable`` (errors 2.9-10.2 in L: nothing vouches for them);
* stopped by a short budget (adaptive, 120 and 150 runs): 10 right, 4 of them ``completed``
  (check errors 0.31-0.47 in L), 6 ``unreliable`` (errors 0.71-1.78);
* silently wrong (wrong and ``completed``): 0 of 85. Right posteriors that say
  ``completed``: 60 of 60 at the budgets, 64 of 74 over all configurations.

Before issue 42's changes (232d7bb, the broad case alone, the machine shared): the broad
6 + 1-D case used all 1000 runs without its design converging (its rule compared two SMC
runs, Monte Carlo noise included; inferred, not logged), 609 s excluding runs, 2.85 GB.
With the new stopping rule but sample paths still by the delta method (during issue 42) its
right posterior said ``unreliable`` (x8.9 widening).

Measured on 2026-11-28 (idle 2 cores, gp_smc seeds 0-2, 10 configurations, 30 runs; 18 min),
with the repair of failed checks (gp_smc ``check_repairs = 2``):

* at the issues' budgets (2d_inflow ray and cpp, 7d ray and cpp, 7d ray at sigma_N = 2 um):
  15 right posteriors (max 0.08 std off, std factors <= 1.04), all 15 ``completed``.  Before
  the repair one of them said ``unreliable`` (7d_ray_sharp seed 2: right to 0.03 std, its 8
  check draws had a RMSE of 1.06 in L); now its failed check's runs join the design and a
  fresh check passes (272 runs instead of 264);
* starved (fixed Sobol designs of 30 and 150 runs): 7 wrong posteriors (0.4-3.4 std off,
  std factors 1.6-10), all 7 ``unreliable`` (check RMSE 5-1200 in L); 2 right by luck
  (0.20, 0.23 std off), ``unreliable`` (RMSE 5.9, 10.9);
* stopped by a short budget (adaptive, 120 and 150 runs): 1 wrong, ``unreliable``; 5 right,
  all ``unreliable`` (the GP's sample paths widen the posterior x2-8 and move it 0.8-1.7
  std: the design had not converged, so nothing vouches for them);
* silently wrong (wrong and ``completed``): 0 of 30.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bayes_models import build_case, grid_posterior  # next to this file
from bench_bayes_targets import (
    QUICK_REFERENCE,
    REFERENCE,
    TARGET_FACTOR,
    TARGET_SHIFT,
    Reference,
    accuracy,
    exact_reference,
    resolve,
    run_pipeline,
)

import fbia


@dataclass(frozen=True)
class Config:
    """One calibration problem and the gp_smc options it runs with."""

    label: str
    case: str
    measure: str
    sigma_n: float
    options: dict[str, Any] = field(default_factory=dict)
    n_points: int = 41  # vertices of the model's interface (cpp: residuals per run)


#: issue 42's budgets in forward runs, design + the 8 check runs: <= 100 in 2-D, <= 200 in
#: 2 + 1-D, <= 1000 in 6 + 1-D
N_TRAIN = {2: 92, 3: 192, 7: 992}
_2D, _3D, _7D = (
    {"n_train": N_TRAIN[2]},
    {"n_train": N_TRAIN[3]},
    {"n_train": N_TRAIN[7], "ard": True},
)

#: the configurations: the family of issue 42 at its budgets (sharp, broad and weakly
#: identified, banana-shaped, bimodal; 2-D, 2 + 1-D, 6 + 1-D; ray and cpp), then starved and
#: stopped-early runs that can be wrong
CONFIGS = (
    Config("2d_ray", "2d", "ray", 0.01, _2D),
    Config("banana_ray", "banana", "ray", 0.01, _2D),
    Config("bimodal_cpp", "bimodal", "cpp", 0.01, _2D),
    Config("2d_inflow_ray", "2d_inflow", "ray", 0.01, _3D),
    Config("2d_inflow_cpp", "2d_inflow", "cpp", 0.002, _3D),
    Config("banana_inflow_cpp", "banana_inflow", "cpp", 0.01, _3D),
    Config("bimodal_inflow_ray", "bimodal_inflow", "ray", 0.01, _3D),
    # the RKHS distance of surface currents (eq. 11; sigma_W = 0.01 mm, D as the residual)
    Config("2d_rkhs", "2d", "rkhs", 0.01, _2D),
    Config("banana_rkhs", "banana", "rkhs", 0.01, _2D),
    Config("7d_ray", "7d", "ray", 0.01, _7D),
    Config("7d_cpp", "7d", "cpp", 0.002, _7D),
    Config("7d_ray_sharp", "7d", "ray", 0.002, _7D),
    # broad and weakly identified: E1, E3 posterior std 24-26 % of the prior range, nu_k
    # 0.15-0.37, only E2 sharp
    Config("7d_cpp_broad", "7d", "cpp", 0.02, _7D, n_points=61),
    Config("7d_cpp61", "7d", "cpp", 0.002, _7D, n_points=61),
    # starved: a fixed Sobol design far below what the posterior needs
    Config("2d_inflow_ray_starved", "2d_inflow", "ray", 0.01, {"design": "sobol", "n_train": 30}),
    Config("2d_inflow_cpp_starved", "2d_inflow", "cpp", 0.002, {"design": "sobol", "n_train": 30}),
    Config("7d_cpp_starved", "7d", "cpp", 0.002, {"design": "sobol", "n_train": 150, "ard": True}),
    # stopped early: the adaptive design with a budget below its convergence
    Config("7d_ray_short", "7d", "ray", 0.01, {"n_train": 120, "ard": True}),
    Config("7d_cpp_short", "7d", "cpp", 0.002, {"n_train": 150, "ard": True}),
)
#: points per input of the RKHS cases' quadrature (the quadrature of the ray 2-D case moves
#: by < 0.01 std from 150 to 300 points per input: test_bench_bayes_targets)
RKHS_GRID = 200
#: --quick: small SMC settings and two cheap configurations
QUICK = {"n_particles": 500, "n_rejuvenation": 3, "zeta": 0.8}
QUICK_CONFIGS = ("2d_inflow_ray", "2d_inflow_ray_starved")


@dataclass
class Outcome:
    config: str
    seed: int
    right: bool
    status: str
    shift: float  # worst |dmean| / exact std over x
    ratio: float  # worst std ratio (max(r, 1/r)) over x
    rmse: float  # the check's RMSE in L at posterior draws
    centred: float  # the same without the mean error (a constant error leaves the posterior)
    widen: float  # the sample-path check: largest std ratio (expected / mean-only posterior)
    move: float  # and largest |mean shift| / std
    runs: int
    seconds: float
    repairs: int = 0  # failed checks repaired before the last (gp_smc's check_repairs)


#: exact references by (case, measure, sigma_N): configurations of one problem share theirs
_REFERENCES: dict[tuple[str, str, float, int], Any] = {}


def run_config(config: Config, seeds: list[int], quick: bool) -> list[Outcome]:
    case = build_case(
        config.case, sigma_n=config.sigma_n, measure=config.measure, n_points=config.n_points
    )
    n_x = len(case.problem.parameters)
    settings = QUICK_REFERENCE if quick else REFERENCE
    key = (config.case, config.measure, config.sigma_n, config.n_points)
    if key not in _REFERENCES and config.measure == "rkhs":
        # the RKHS likelihood has no vectorised form (one measure call per point): quadrature
        # alone, on a grid of RKHS_GRID per input (two inputs only), is the reference
        t0 = time.perf_counter()
        moments = grid_posterior(case, 60 if quick else RKHS_GRID)
        _REFERENCES[key] = Reference(moments, [moments, moments], time.perf_counter() - t0)
    if key not in _REFERENCES:
        # up to 3 inputs: quadrature on a grid is the reference (SMC's pooled seeds beside
        # it; a bimodal posterior's mode weights are what quadrature gets exactly)
        grid = None if len(case.names) > 3 else ((60, 40) if quick else (300, 120))
        ref = exact_reference(
            case, settings, (grid[0], grid[1] if len(case.names) == 3 else None) if grid else None
        )
        if ref.grid is not None:
            ref.moments = ref.grid
        _REFERENCES[key] = ref
    ref = _REFERENCES[key]
    a, b = ref.seeds
    spread = float(np.max(np.abs(a.mean - b.mean) / ref.moments.std))
    agreement = "quadrature only" if a is b else f"seeds differ by {spread:.3f} std"
    print(
        f"\n=== {config.label}: case {config.case}, {config.measure} measure, sigma_N "
        f"{config.sigma_n} mm, gp_smc {config.options}; exact reference {ref.seconds:.0f} s "
        f"({agreement})",
        flush=True,
    )
    out = []
    for seed in seeds:
        options = {"design": "adaptive", "n_check": 8, **config.options, "seed": seed}
        if quick:
            options.update(QUICK)
        opts, _ = resolve(options)
        run = run_pipeline(case, config.label, opts, [])
        if run.moments is None:
            print(f"  seed {seed}: no result ({run.error})")
            continue
        right, shifts, ratios = accuracy(ref.moments, run.moments, n_x)
        shift = float(shifts[:n_x].max())
        ratio = float(np.maximum(ratios, 1 / ratios)[:n_x].max())
        res = run.result
        check, unc = res.check, res.uncertainty
        rmse = float("nan") if check is None else float(check.rmse)
        centred = float(check.centred_rmse) if check else math.nan
        widen = math.nan if unc is None else float(np.max(unc.std_ratio))
        move = math.nan if unc is None else float(np.max(np.abs(unc.mean_shift_relative)))
        repairs = len(getattr(res, "failed_checks", []))
        outcome = Outcome(
            config.label, seed, right, res.status, shift, ratio, rmse, centred, widen, move,
            run.nfev, run.seconds_excluding_runs, repairs,
        )  # fmt: skip
        print(
            f"  seed {seed}: {'right' if right else 'WRONG'} (max |dmean|/std {shift:.2f}, "
            f"worst std factor {ratio:.2f}), status {res.status!r}: check RMSE {rmse:.3g} "
            f"(centred {centred:.3g}), sample paths widen x{widen:.3g}, move {move:.2g} std; "
            f"{run.nfev} runs ({repairs} failed checks repaired), "
            f"{run.seconds_excluding_runs:.0f} s excl. runs",
            flush=True,
        )
        out.append(outcome)
    return out


def confusion(outcomes: list[Outcome]) -> str:
    def count(right: bool, status: str) -> int:
        return sum(1 for o in outcomes if o.right == right and o.status == status)

    statuses = sorted({o.status for o in outcomes} | {"completed", "unreliable"})
    lines = [f"  {'':<8}" + "".join(f"{s:>12}" for s in statuses)]
    for right in (True, False):
        word = "right" if right else "wrong"
        lines.append(f"  {word:<8}" + "".join(f"{count(right, s):>12}" for s in statuses))
    n_right = sum(o.right for o in outcomes)
    n_wrong = len(outcomes) - n_right
    ok_right, caught = count(True, "completed"), count(False, "unreliable")
    lines.append(
        f"  right posteriors that say 'completed': {ok_right} of {n_right}; wrong posteriors "
        f"that say 'unreliable': {caught} of {n_wrong}; silently wrong (wrong and "
        f"'completed'): {count(False, 'completed')}"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    labels = [c.label for c in CONFIGS]
    ap.add_argument("--only", choices=labels, nargs="+", help="these configurations")
    ap.add_argument("--seeds", type=int, default=3, help="gp_smc seeds 0 .. n-1 per config")
    ap.add_argument(
        "--first-seed",
        type=int,
        default=0,
        help="start the seeds here (first-seed .. first-seed + seeds - 1): more seeds later",
    )
    ap.add_argument("--quick", action="store_true", help="small sizes: a smoke run")
    args = ap.parse_args(argv)
    chosen = args.only or (QUICK_CONFIGS if args.quick else labels)
    print(
        f"fbia {fbia.__version__}; {len(os.sched_getaffinity(0))} usable cores; rule: right = "
        f"every x mean within {TARGET_SHIFT} exact std and std within x{TARGET_FACTOR}"
    )
    t0 = time.perf_counter()
    outcomes: list[Outcome] = []
    for config in CONFIGS:
        if config.label in chosen:
            seeds = list(range(args.first_seed, args.first_seed + args.seeds))
            outcomes += run_config(config, seeds, args.quick)
    print(f"\nall runs ({time.perf_counter() - t0:.0f} s):")
    print(confusion(outcomes))
    for label in chosen:
        mine = [o for o in outcomes if o.config == label]
        words = ", ".join(f"{'right' if o.right else 'wrong'}/{o.status}" for o in mine)
        print(f"  {label}: {words}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
