"""Benchmark: do the model's sensitivities cut gp_smc's forward runs? (issue 42, item 4)

A forward model with tangents (``ale_fsi``; here the closed-form mounds of ``bayes_models``,
whose tangents are their closed forms differentiated) gives with every run the Jacobian
J = dr/dz of the measure's residuals with respect to every input z (x and theta;
:class:`fbia.iterators.tangents.TangentProblem`, as Levenberg-Marquardt uses it). gp_smc's
``gradients = "tangents"`` gives them to the residual emulator as *indirect
gradient-enhanced* training data (Chung & Alonso 2002: "indirect GEK";
:func:`fbia.iterators.surrogates.residuals.tangent_runs`): every run at z_i with residuals
r_i adds d pseudo-runs at z_i + h_j e_j with residuals r_i + h_j J_i e_j, h_j = 0.02 x the
design's spread in input j, so that each component's GP sees the slope of its score in every
direction at every run (d + 1 values per run instead of 1). The GP itself is unchanged; a
GP with derivative observations (GPy's ``DiffKern``) would need the second derivatives of
fbia's product kernel.

For each case (``bench_bayes_targets``' rule, written down before the runs: every x mean
within 0.3 exact std, every std within x1.5), gp_smc runs without and with the tangents at
fixed budgets (the design run to its budget, ``adaptive_tol`` 1e-9, so that runs compare at
equal counts; + the 8 check runs) and with its own stopping rule from Sobol starts of 10
and 4 runs per input; the table prints runs, accuracy, status and fbia's own seconds side by
side. fbia makes the tangents its default only if they cut the runs to a right posterior
>= 2x at equal accuracy (issue 42).

    .venv/bin/python benchmarks/bench_bayes_gradients.py                  # all cases
    .venv/bin/python benchmarks/bench_bayes_gradients.py --case 7d --seeds 1
    .venv/bin/python benchmarks/bench_bayes_gradients.py --case flow_cell   # ale_fsi

The exit status is 0 whatever the result.

Measured on 2026-11-29 at 0d250d7 (2 cores shared with other benchmarks: the seconds are
inflated, the runs and accuracies are not), gp_smc seeds 0 and 1:

* ``2d_inflow`` (closed form, cpp, sigma_N 10 um): the smallest fixed budget with a right
  posterior: seed 0 36 runs without tangents (0.29 std off, ``unreliable``), 24 with (0.10,
  ``completed``); seed 1 52 without and 52 with (at 36 both wrong: 0.56 and 0.39 std off).
  Own stopping rule, 10 start runs per input: 61 and 100 runs without, 61 and 52 with; 4 per
  input: 50 and 50 without, 37 and 50 with. Means closer to the exact ones with tangents at
  every right budget (max 0.03-0.05 std against 0.06-0.09); fbia's own time 1.2-2.8x.
* ``flow_cell`` (``ale_fsi``, its own tangents; the reference: gp_smc without tangents on 170
  runs, ``completed``): right and ``completed`` from 52 runs without tangents (seed 1 at 52:
  right, ``unreliable``), from 36 with (both seeds); right at all from 36 / > 36 without, 24
  / 36 with. Own stopping rule (10 per input, seed 0): 72 runs without, 52 with.
* ``7d`` (closed form, cpp on 61 vertices, sigma_N 20 um; seed 0, not finished: stopped to
  leave the cores to example 8): at 50 runs 2.29 std off without tangents, 0.37 with (both
  wrong); at 70 without 0.77; an earlier run of the same pseudo-runs (a benchmark-side
  subclass before the option existed): at 100 runs 0.47 std off without (wrong), 0.07 with
  (right, ``completed``, 135 s own against 52 s), at 160 without 0.10 (right,
  ``unreliable``): about 1.6x fewer runs.

* example 8 (``examples/paper_b/heterogeneous/study_adaptive.toml``, ``ale_fsi`` 6 + 1-D,
  the RKHS distance; not a case of this script, run as the study with ``gradients =
  "tangents"``, ``n_train = 2000``): ``unreliable`` at 2008 runs, its design further from
  converging than without the tangents at the same runs (README.md there).

So the tangents cut the runs to a right posterior by about 1.3-1.6x, and make
the means more accurate at equal runs, at up to 2.8x fbia's own time (the emulator trains
on d + 1 times the points); issue 42's rule for a default is >= 2x, so ``gradients`` stays
``"off"`` by default.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from bayes_models import Moments, build_case, inflow_parameter  # next to this file
from bench_bayes_targets import (
    GRID,
    PIPELINE,
    REFERENCE,
    accuracy,
    exact_reference,
    resolve,
)

import fbia
from fbia.iterators.gp_smc.iterator import GpSmcIterator
from fbia.iterators.surrogates.residuals import TANGENT_STEP

#: fixed budgets per case (design runs to their end, + the 8 check runs)
BUDGETS = {"2d_inflow": (16, 24, 36, 52), "7d": (50, 70, 100, 160, 264)}
#: the own stopping rule: Sobol start runs per input, without and with the tangents (gp_smc's
#: default is 10 per input, Loeppky et al.; a run with tangents carries d + 1 values)
START_PER_INPUT = (10, 4)
CASES = {
    "2d_inflow": {"sigma_n": 0.01, "measure": "cpp", "n_points": 41},
    "7d": {"sigma_n": 0.02, "measure": "cpp", "n_points": 61},
}
#: the flow cell with ale_fsi (finite elements, its own tangents): E, nu under the uncertain
#: inflow, cpp measure, sigma_N 10 um; no exact posterior, so the reference is gp_smc without
#: tangents on REFERENCE_RUNS runs with a 4x stricter stopping rule (its status printed)
FLOW_CELL_BUDGETS = (16, 24, 36, 52)
REFERENCE_RUNS = 240
PIPELINE_FLOW_CELL = {"design": "adaptive", "n_check": 8}


class FlowCell:
    """``ale_fsi`` on the default flow cell (Paper B's example 7 set-up with the cpp measure):
    synthetic data at E = 400 Pa, nu = 0.3, inflow 100 mm^2/s with 1 um noise."""

    name = "flow_cell"

    def __init__(self) -> None:
        model = fbia.forward_model("ale_fsi", material="svk")
        truth = {"E": 400.0, "nu": 0.3, "inflow_rate": 100.0}
        obs = fbia.synthetic_observations(model, truth, [{}], noise_std=0.001, seed=0)
        self.problem = fbia.InverseProblem(
            model=model,
            measure=fbia.measure("cpp"),
            observations=obs,
            parameters=[
                fbia.Parameter("E", bounds=(100.0, 800.0), unit="Pa"),
                fbia.Parameter("nu", bounds=(-0.8, 0.5), unit="-"),
            ],
            uncertain=[inflow_parameter()],
            noise_std=0.01,
            truth=truth,
        )
        self.names = ["E", "nu", "inflow_rate"]


def run_once(case: Any, options: Mapping[str, Any], gradients: bool) -> dict[str, Any]:
    """One gp_smc run; its runs, moments, status and seconds excluding the forward runs."""
    opts, _ = resolve({**options, "gradients": "tangents" if gradients else "off"})
    it = GpSmcIterator(**opts)
    evaluator = fbia.SerialEvaluator()
    t0 = time.perf_counter()
    try:
        result = _drain(it, case.problem, evaluator)
    finally:
        seconds = time.perf_counter() - t0
        nfev = len(evaluator.history)
        forward = float(sum(ev.time for ev in evaluator.history))
        evaluator.close()
    post = result.posterior
    moments = Moments(list(post.names), np.asarray(post.mean_all), np.sqrt(np.diag(post.cov_all)))
    return {
        "nfev": nfev,
        "moments": moments,
        "status": result.status,
        "own": seconds - forward,
    }


def _drain(it: GpSmcIterator, problem: Any, evaluator: Any) -> Any:
    gen = it.steps(problem, evaluator)
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=[*CASES, "flow_cell", "all"], default="all")
    ap.add_argument("--seeds", type=int, default=2, help="gp_smc seeds per setting")
    args = ap.parse_args(argv)
    cases = [*CASES, "flow_cell"] if args.case == "all" else [args.case]
    print(f"fbia {fbia.__version__}; pseudo-run step {TANGENT_STEP} x the design's spread")
    rows = []
    for name in cases:
        if name == "flow_cell":
            case: Any = FlowCell()
            pipeline, budgets = PIPELINE_FLOW_CELL, FLOW_CELL_BUDGETS
            t0 = time.perf_counter()
            ref_run = run_once(
                case,
                {**pipeline, "n_train": REFERENCE_RUNS, "adaptive_tol": 0.025, "seed": 100},
                False,
            )
            exact = ref_run["moments"]
            print(
                f"\n=== flow_cell (ale_fsi, cpp, sigma_N 10 um): reference gp_smc without "
                f"tangents, {ref_run['nfev']} runs, {ref_run['status']}, "
                f"{time.perf_counter() - t0:.0f} s; mean {np.round(exact.mean, 4)}, std "
                f"{np.round(exact.std, 4)}"
            )
        else:
            case = build_case(name, **CASES[name])
            pipeline, budgets = PIPELINE[name], BUDGETS[name]
            ref = exact_reference(case, REFERENCE, GRID.get(name))
            exact = ref.grid if ref.grid is not None else ref.moments
            print(f"\n=== {name}: {CASES[name]}, exact reference {ref.seconds:.0f} s")
        n_x = len(case.problem.parameters)
        settings = [(b, {"adaptive_tol": 1e-9, "n_train": b - 8}) for b in budgets]
        n_inputs = len(case.names)
        for k in START_PER_INPUT:
            settings.append((f"own {k}/in", {"n_initial": k * n_inputs}))
        for label, extra in settings:
            for seed in range(args.seeds):
                for gradients in (False, True):
                    options = {**pipeline, **extra, "seed": seed}
                    out = run_once(case, options, gradients)
                    ok, shift, ratio = accuracy(exact, out["moments"], n_x)
                    worst = float(np.max(np.abs(np.log(ratio[:n_x]))))
                    row = (
                        f"{name:9s} {str(label):>8s} seed {seed} "
                        f"{'tangents' if gradients else 'plain   '}: {out['nfev']:4d} runs, "
                        f"max |dmean|/std {float(np.max(shift[:n_x])):.2f}, worst std factor "
                        f"{math.exp(worst):.2f} -> {'right' if ok else 'WRONG'}, "
                        f"{out['status']}, {out['own']:.0f} s own"
                    )
                    print("  " + row, flush=True)
                    rows.append(row)
    print()
    for row in rows:
        print("SUMMARY " + row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
