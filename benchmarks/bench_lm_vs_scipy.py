"""fbia's Levenberg–Marquardt beside scipy's ``least_squares`` on the flow cell's FSI problem
(issue 47: "a 2-D fit never slower than scipy's").

Run by hand::

    .venv/bin/python benchmarks/bench_lm_vs_scipy.py              # the eleven Table 1 starts
    .venv/bin/python benchmarks/bench_lm_vs_scipy.py --starts red brown

The problem is ``examples/flow_cell/study_fsi.toml``'s: ``ale_fsi`` (SVK, the default flow
cell and mesh), E and nu in the study's bounds ([100, 1500] Pa, [-0.8, 0.45]), the cpp
measure on the synthetic interface (truth E = 400 Pa, nu = 0.3, 1 um of noise, seed 1).  From
each of Paper A's eleven Table 1 starts (olive's nu = -0.9 lies outside the study's bounds and
is moved to the bound, -0.8), on a fresh model built outside the timing for each method and
start (so neither warm-starts from the other's states, nor from the state at the truth that
the synthetic observation was made from), serially:

* **fbia**: ``levenberg_marquardt`` with its defaults (robust mode, ``jacobian = "auto"``),
  the way a user runs the study; its forward runs as ``result.nfev``;
* **scipy**: ``scipy.optimize.least_squares(method="trf", jac="2-point")`` with the same
  bounds and x_scale = the bounds' widths, on r(x) = the problem's residuals (each call one
  forward run through the same ``InverseProblem.evaluate``; a failed run returns residuals of
  1 mm per entry, so trf steps back), every call counted.

Printed per start and in total: forward runs, wall time, the optimum, and fbia / scipy as
ratios; the optima's difference in fbia's standard errors (the same optimum: below 0.1).
Issue 47's target: fbia's wall time <= scipy's, with fewer runs and the same optima.

Measured 2026-11-29 at d2447d0 (2 cores, otherwise idle; the wall times
vary by ~20 % between runs of the same code): fbia 100 runs, 13.70 s; scipy 296 runs, 10.67 s;
0.34x the runs, **1.28x the wall time (not met)**, the same optimum from every start (E 398.09
Pa, nu 0.28803; 0.001 standard errors apart at most).  Per start fbia took 0.74-2.89x scipy's
time (black 2.92 s for 11 runs).  fbia's own time outside the model is 1-2 % of its wall time:
what costs is the model.  A profile of the red start (8 runs, 0.96 s): 0.54 s in the tangents
(per run 28 ms assembling the Jacobian at the converged state, 25 ms refining with Newton's
factorisation of an earlier state over 6-21 sweeps, 16 ms in three residual evaluations for
dR/dmu and dR/dlambda), 0.35 s in Newton; scipy's iteration costs one run of an LM step plus
two forward-difference runs that converge in chord steps (~15-20 ms each), below one tangent.
Tried and not kept: factorising afresh at the converged state instead of refining (four starts
three times each, 4.2-4.6 s against 4.4-5.2 s: within the noise); using Newton's
factorisation directly when it is of the converged state (never the case in these warm runs:
it lies 0.006-0.3 away in Newton's scaled norm, their last steps being chord steps; a second
A/B of the first cut on six starts, four times each: 6.77 s against 6.81 s).

Iterations: both take about seven (scipy's 21-30 runs are 3 per iteration).  The residual at
the optimum is the noise (|r| = 0.008 mm on 67 points), a large-residual problem on which
Gauss-Newton, and so both Levenberg-Marquardt codes, converge linearly: from red the
Gauss-Newton step falls 0.52, 0.41, 0.12, 0.034, 0.0037 standard errors per iteration, and
Bates and Watts' relative offset 0.42, 0.34, 0.14, 0.054, 0.0032, 2.5e-6 (black and gray
alike).  A relative-offset stop at 1e-3 (their usual value) saves no run here, at 1e-2 one
run per start.  Fewer iterations would need the second-order part of the Hessian (a secant
model of it, as NL2SOL's, Dennis, Gay and Welsch 1981): not tried.

Measured 2026-11-29 at ffa0d9b (2 cores shared with a reproduction loop, so the ratios, from
one run each, matter, not the seconds), fbia's options against scipy in the same run:

* ``jacobian = "forward"`` (what a cost-based "auto" would take for two parameters, the
  tangent costing more than two chord-step runs): six starts twice, 560 runs and 2.73x scipy's
  wall time (tangents: 108 runs, 1.44x), and optima up to 0.1 Pa off the tangents' and scipy's
  398.092 Pa (398.06-398.19). fbia's forward-difference mode needs about twice scipy's runs
  with the same 2-point Jacobians (50-61 per start against 21-32); why is not measured (one
  candidate: its central-difference end phase, ``final_jacobian = "central"``, 2 n_x runs per
  Jacobian once forward differences have converged). So "auto" by cost was not built: the
  forward-difference mode is the slower one here.
* The black start's 3 s (11 runs) are one failed run: the first step from E = 1000 Pa goes
  to the bound E = 100 Pa, where the biofilm cannot carry the flow (continuation fails at
  81 of 100 mm^2/s after 1.84 s). ``mu0 = 1`` (a first step about half the Gauss-Newton one;
  robust mode's default is 1e-2) avoids it: all eleven starts twice, 184 runs and **1.09x
  scipy's wall time** against 200 runs and 1.39x with the default, no failed run, the same
  optimum. Not kept as the default: NIST's MGH10 from start 1 then ends at the iteration
  limit (its plateau needs the long first step, ``test_lm_nist.py``); the study can set it.

Measured 2026-11-30 at 7f80bac (idle 2 cores, one run each; ``--options`` sets fbia's LM
options), why fbia's forward differences take twice scipy's runs, in two parts:

* the central-difference end phase (``final_jacobian = "central"``) costs 23-25 runs per start
  (red, blue, black, brown: 50, 57, 60, 61 runs with it, 27, 32, 35, 36 without), and after the
  last accepted step six rejected trial steps with growing damping precede the stop (red);
* the step: the default ``beta = 1e-3`` moves each parameter by 0.1 %, so a perturbed run needs
  Newton steps of its own (about 50 ms a run), while scipy's 2-point step (1.5e-8 relative)
  lands where the warm start converges in a chord step (about 14 ms: the median run of fbia's
  forward differences at such a step, below).  With
  ``--options jacobian=forward final_jacobian=forward alpha=0 beta=1e-6`` fbia takes 292 runs
  against scipy's 296 (0.99x) and 11.56 s against 9.01 s (1.28x), the same optimum from every
  start (0.001 std. errors apart); the tangents (the default) in the next run: 100 runs,
  11.87 s against 9.12 s (1.30x).  Without the black start both modes are within 6-11 % of
  scipy's wall time: black's one failed run (E = 100 Pa, continuation failing at 81 of 100
  mm^2/s) costs 1.6-1.8 s (1.59 s measured here, 1.84 s before), more than the other ten runs
  of that fit together.  What is left for "never slower than scipy" is that failed run's cost
  (the solver's continuation before it gives up; scipy's trf keeps its iterates strictly
  inside the bounds) or the step that reaches it.  Not changed: a default of 1e-6 holds only
  for models converged far below 1e-6 relative (ale_fsi's Newton is; Paper A's eq. 21 step is
  chosen for noisy ones), so a cost-based "auto" would need the model to state its accuracy.

Measured 2026-11-30 at 181e30d+ (idle, a background job paused): fbia 100 runs 11.25 s, scipy
296 runs 8.33 s, **1.35x (not met)**, the same optima; black 2.56 s against 0.76 s.  The
tangents' dR/dmu and dR/dlambda now difference the solid's terms alone: in interleaved pairs
1.32x / 1.26x before, 1.29x / 1.26x after -- not visible in 2-D, where a red start's 8 runs
(0.79 s) spend 0.28 s assembling 11 Jacobians (8 for the tangents, 26 ms each), 0.15 s in 161
back-substitutions (95 refinement sweeps) and 0.12 s in residuals.  Tried and not kept: GMRes
(NGSolve's ``GMResSolver``, fields weighted by their size) instead of the refinement sweeps,
83 iterations against 95 sweeps on the red start, no faster.  Black's failed run (E = 100 Pa)
is 0.4 s of a warm Newton that diverges over 5 Jacobians and 1.3-2.5 s of the continuation from
rest that reaches 80.9 of 100 mm^2/s before its corrector stalls; what would remove it is
still the step to the bound or a cheaper failure.

A cheaper failure, measured 2026-11-30 (a background job paused; this VM's speed moved by
~40 % within minutes, so interleaved pairs).  Near 81 mm^2/s the continuation's corrector
steps diverge, and each assembled three Jacobians before giving up.  Logging each step's
updates (black's failed run and E = 50 and 30 Pa from rest) showed that in every step that
failed, the chord update right after a fresh Newton step was not smaller than that step's
update (ratios 0.8-470), and in every step that converged it was at most 0.5 of it.
``ArclengthContinuation.max_chord_ratio`` (1, Deuflhard's natural monotonicity test) now ends a
corrector step there.  The continuation takes the same path and fails at the same rate
(80.88, 54.36, 38.78 mm^2/s), with 19 instead of 32, 25 instead of 35 and 26 instead of 36
Jacobians.  Black's failed run: 1.27 / 1.97 / 1.16 s against 1.87 / 2.34 / 1.73 s before
(medians of three, three interleaved pairs: 0.7x).  The 3-D dome's failed run at E = 108.74
Pa (recommended settings) takes the same path to its limit point at 93.22 mm^2/s with 24
instead of 31 factorisations (73.9 s against 77.5 s, one pair).  The whole benchmark, twice in
a slower hour: fbia 100 runs 18.79 / 18.66 s, scipy 296 runs 15.97 / 16.51 s, **1.18x / 1.13x
(not met)**, the same optima; black 2.52x / 2.09x, cyan (no failed run: its first steps go to
the nu bound and back, 0.13-0.37 s a run) 1.56x / 2.01x, the other nine 0.83-1.24x.

Measured 2026-11-30 (session f), after the model of each method and start became one that has
not run (before, the study's own model, which holds the state at the truth the synthetic
observation was made from): one run of the whole benchmark each way, back to back, on 2 cores
shared with a reproduction job: with the head start fbia 100 runs 14.48 s, scipy 296 runs 13.09
s (1.11x); without it the same 100 and 296 runs, 16.68 s against 14.00 s (**1.19x, not met**),
the same optima.  The runs and the optima do not depend on the head start; its effect on the
ratio is inside this VM's scatter (per start 0.62-3.34x in the second run).

Measured 2026-12-01 (session i; 2 cores shared with three reproduction jobs at nice 19, one run
of each, back to back), after robust mode's step to a far bound went halfway to it
(``trust_region.step_back``) and a rejected trial shrank the region below its own length:
before, fbia 100 runs 13.12 s, scipy 296 runs 10.63 s, **1.23x**, black 11 runs 3.06 s (its
failed run at the E bound); after, fbia 100 runs 12.85 s, scipy 296 runs 11.61 s, **1.11x
(not met)**, black 9 runs 1.00 s (1000 -> 550 Pa, no failed run), cyan 10 instead of 11 runs,
gray 12 instead of 11 and brown 9 instead of 8, the same optima (0.001 std. errors apart at
most).  With the step-back alone (MINPACK's shrink from min(radius, 10 plen)): 99 runs, 1.14x.
No failed run is left in any start; what remains is the cost of a run with its tangent
(0.1-0.2 s here against scipy's 0.03-0.04 s for a chord-step difference run) times fbia's 7-12
iterations, against scipy's 21-32 runs.

Measured idle 2026-12-01 (session i, 2 free cores), with the step-back: fbia 100 runs 9.62 s
and 9.94 s, scipy 296 runs 8.88 s and 8.73 s, **1.08x and 1.14x (not met)**, the same optima;
per start 0.84-1.50x (cyan 1.50x, brown 1.40x).  The tangent solves' refinement tolerance
(``ale_fsi.sensitivities.REFINE_TOL``, 1e-7) at 1e-4, monkeypatched (no code changed): on
red and black 17 runs either way, 111 refinement sweeps instead of 185, tangents 0.66 s
instead of 0.77 s, the same optimum; the whole benchmark once under load 1.04x; the tangent
tests' 1e-5 rule still holds (``tests/plugins/test_ale_fsi_tangents.py``).  Not kept yet: a
change of the model's code marks every ale_fsi row of the reproductions page as changed.

Measured idle 2026-12-01 (session j): the whole benchmark once, fbia 100 runs 10.95 s, scipy
296 runs 8.73 s, **1.25x (not met)**.  Where a run with its tangents goes (red and cyan,
instrumented): the Jacobian at the converged state 24-31 ms, the two refined solves 6-7 ms
each (4-21 sweeps for both), dR/dmu and dR/dlambda 0.4 ms each (the three solid-residual
evaluations are not worth cutting); the runs near the optimum take 2-4 Newton iterations
without a Jacobian and their tangents half to two thirds of their time.  Tried, fbia alone
on the eleven starts in interleaved pairs, not kept: (1) factorising the Jacobian at the
converged state before the tangent solves (exact solves, and the next run's chord): 8.40 /
9.62 s against 8.65 / 8.95 s;
(2) the refinement's tolerance: 1e-4 on the correction gave medians 9.66 against 11.83 s over
six pairs, but a stop on the estimated error (correction x q / (1 - q) <= 1e-6, q the last
contraction; the tangent tests pass) against the 1e-7 of now, six more pairs, 10.21 against
9.73 s with 31 % fewer sweeps (4176 against 6084): a sweep costs ~1.4 ms (~0.45 s per
benchmark saved at most), and the 1e-7 runs of the second six pairs took 9.0-10.3 s, so the
first pairs' gap was most likely this VM's drift, not the sweeps.  What is left is the
Jacobian assembly of each tangent (a third of a run) against scipy's runs of chord steps.

Measured idle 2026-12-01 (session l): the default model, fbia 100 runs 9.01 s, scipy 296 runs
8.37 s, **1.08x (not met)**.  Why the Jacobian costs what it does, on this problem's model (2-D,
P2/P1, 3 745 free dofs, one thread): the residual 2.2 ms, the Jacobian 24 ms (the fluid's
terms 22.5 of it), a factorisation 8.8 ms, a back-substitution 0.5 ms.  NGSolve linearises
an integrand by evaluating it along every trial component (about ten here), hence the 11x.
Tried and not kept: ``ngsglobals.symbolic_integrator_uses_diff`` (the same matrix, the same
time), the interpreted integrands without ``Compile()`` (36 ms), the fluid's linearisation
written out by hand as a bilinear form (the same matrix to 1.4e-14; compiled 30.5 ms, split by
trial field 21.0 ms against 21.9 ms), refining the tangents from the warm start's tangents
(1014 -> 929 sweeps over the eleven starts, 4.10 -> 3.94 s of tangents: the refinement's
contraction, not its start, sets the sweeps).

Machine code for the integrands (``--set model.options.native_code=true``, new: NGSolve's
``realcompile`` with a cache of the compiled objects, ``fbia.plugins.fem.native``): the
Jacobian 24 -> 7 ms, the residual 2.2 -> 0.7 ms.  Both methods run on the same model, so both
gain; four runs of the whole benchmark in turn, idle (default / native / default / native):
fbia 9.56 / 4.97 / 9.66 / 4.99 s, scipy 8.74 / 4.86 / 9.00 / 4.95 s: **1.09x / 1.02x / 1.07x /
1.01x**, the same runs and optima.  A 2-D calibration takes about half the time with native
code, but fbia's ratio to scipy moves only from ~1.08x to ~1.02x: the target is still not met.
Where fbia's time goes with native code (cProfile of four starts, 40 runs, 2.26 s): Newton
1.05 s (its Jacobians included), the tangents' refinement sweeps 0.46 s (0.8 ms a Pardiso
back-substitution through NGSolve's ctypes wrapper), the 69 Jacobian assemblies 0.56 s in all
(Newton's and the tangents'), the interface curves and the measure's closest points 0.13 s.

Pardiso without its matrix checker (``iparm[26] = 0``, ``fbia.plugins.fem.newton
.PARDISO_MATRIX_CHECK``: NGSolve's wrapper checks the CSR arrays at every call, every
back-substitution too; 0.52 -> 0.40 ms here, the same bits), then five runs each way in turn,
idle (2026-12-01, session l): with machine code fbia 4.63 / 4.50 / 4.79 / 4.49 / 4.87 s against
scipy 4.71 / 4.72 / 4.78 / 4.60 / 5.00 s, **0.98x / 0.95x / 1.00x / 0.98x / 0.97x**; with the
interpreted code (the default) 8.93 / 8.30 / 8.53 / 8.81 / 8.19 s against 8.51 / 8.18 / 8.17 /
8.23 / 7.70 s, **1.05x / 1.01x / 1.04x / 1.07x / 1.06x**; the same runs and optima throughout.
So fbia is no slower than scipy with machine code (median 0.98x, by less than this VM's
scatter), and 5 % slower with the default, interpreted code: the issue's target is not claimed
for the default.

Machine code the default (2026-12-01, session m; ``--set model.options.native_code=false``
gives the interpreted code): three runs in turn, idle, fbia 5.17 / 5.29 / 5.40 s against scipy
4.90 / 5.24 / 5.04 s, **1.05x / 1.01x / 1.07x (not met)**, the same runs and optima (0.001
std. errors apart); the interpreted code the same hour 9.98 against 9.41 s (1.06x).  The
default makes a 2-D calibration about 1.8x faster for its user, not fbia faster than scipy
(the same model serves both).  Where a native run's time goes (cProfile of four starts, 36
runs, 1.68 s): Pardiso 0.52 s (705 back-substitutions of ~0.38 ms, 21 factorisations), 57
Jacobian assemblies 0.37 s, residuals 0.16 s, the mesh-quality check 0.07 s.  A
back-substitution through NGSolve's ctypes wrapper costs what MKL's does (no overhead to cut).
Tried and not kept: (1) a warm start's first Jacobian taken from the tangents' Jacobian of the
state it starts from, moved to the new Lame constants (J(U; new) = J(U; old) + J_s(new) -
J_s(old), exact to 1e-16): 7 stand-ins in 100 runs, Jacobians 63 -> 56 but Newton iterations
485 -> 506 and refinement sweeps 1014 -> 1044, no gain; (2) Pardiso without weighted matching
(``iparm[12] = 0``, re-applied after NGSolve's ``Analyze``): in 2-D no gain to speak of, on
the 3-D dome a first factorisation in 1.2-1.3 s instead of 2.7-3.6 s, but the dome at order 3
with quadratic mesh motion (``bench_ale_fsi_3d.py --target``'s row) then stalls in
continuation at 35 mm^2/s, reproducibly: not robust; (3) 1/E or log E as the parameter for
scipy (5 starts: 41 Jacobians -> 36 / 40); (4) two right-hand sides in one Pardiso call
through NGSolve's MultiVector (14.3 ms against 2 x 7.8 ms: it loops).

Measured 2026-12-02 (session n, a fresh VM, idle, machine code the default): fbia 4.38 /
4.31 s against scipy 4.02 / 4.04 s, **1.09x / 1.06x (not met)**, the same 100 against 296
runs and optima.  Per start (``brown``, one run of each): fbia 9 runs, 59 Newton iterations, 4
Jacobians, 0.41 s of model time of which the tangents 0.20 s (132 refinement sweeps: a sweep
is a 0.44 ms back-substitution and a 0.16 ms product with ~0.1 ms around them); scipy 25 runs,
70 Newton iterations, 5 Jacobians, 0.29 s.  The late runs of fbia's start are close together
(E within 0.2 Pa) but chord with the factorisation of its fourth run, so each tangent pair
needs 15-16 sweeps (21-24 ms) for a run of 2-6 Newton iterations.  Factorising the converged
state's Jacobian before the tangents (what 3-D does since this session) gave 1.11 / 1.06 /
1.10x: no gain (a 2-D factorisation was measured at 8.8 ms in stop 68, about what the 15
sweeps it saves cost).  So with the same
iteration counts a tangent pair costs what scipy's two warm forward-difference runs cost on the
shared model: parity, not a lead.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from bench_ale_fsi import TABLE_1  # next to this file: Paper A Table 1 (E^0 [Pa], nu^0)
from scipy.optimize import least_squares

import fbia

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "examples/flow_cell/study_fsi.toml"
#: residual of a failed run for scipy (mm per entry: far worse than any solved interface)
FAILED_RESIDUAL = 1.0


#: ``--set`` overrides of the study for the calibrated model (both methods), e.g.
#: ``model.options.native_code=false`` (the interpreted integrands)
OVERRIDES: list[str] = []


def _fresh_problem() -> Any:
    """The study's problem on a model that has not run.  The study's own model made the
    synthetic observation and holds the state at the truth, a warm start no model calibrated
    against a scan has: the observation is the study's, the model another instance (with
    ``--set``'s overrides; the observation stays the study's)."""
    observed = fbia.load_study(STUDY).problem
    return dataclasses.replace(observed, model=fbia.load_study(STUDY, overrides=OVERRIDES).model)


def _start(problem: Any, label: str) -> dict[str, float]:
    """The Table 1 start inside the problem's bounds."""
    out = {}
    for p, v in zip(problem.parameters, TABLE_1[label], strict=True):
        lo, hi = p.bounds
        out[p.name] = float(min(max(v, lo), hi))
    return out


def run_fbia(label: str, options: dict[str, Any] | None = None) -> dict[str, Any]:
    problem = _fresh_problem()
    x0 = _start(problem, label)
    lm = fbia.iterator("levenberg_marquardt", x0=[x0], **(options or {}))
    t0 = time.perf_counter()
    result = lm.run(problem)
    wall = time.perf_counter() - t0
    return {
        "wall": wall,
        "runs": result.nfev,
        "x": result.x,
        "ok": bool(result.success),
        "stderr": result.stderr or {},
        "model": sum(e.time for e in result.evaluations),
    }


def run_scipy(label: str) -> dict[str, Any]:
    problem = _fresh_problem()
    names = [p.name for p in problem.parameters]
    lower = np.array([p.bounds[0] for p in problem.parameters])
    upper = np.array([p.bounds[1] for p in problem.parameters])
    calls = {"n": 0, "model": 0.0}
    n_r: list[int] = []

    def residuals(x: np.ndarray) -> np.ndarray:
        calls["n"] += 1
        ev = problem.evaluate(dict(zip(names, map(float, x), strict=True)), keep_solution=False)
        calls["model"] += ev.time
        if ev.ok and ev.residuals is not None:
            r = np.asarray(ev.residuals, dtype=float)
            n_r[:] = [len(r)]
            return r
        if not n_r:  # scipy needs the residual's length from its first call
            raise RuntimeError(f"scipy's first run, at the start, failed: {ev.message}")
        return np.full(n_r[0], FAILED_RESIDUAL)

    x0 = np.array(list(_start(problem, label).values()))
    t0 = time.perf_counter()
    res = least_squares(
        residuals, x0, jac="2-point", method="trf", bounds=(lower, upper), x_scale=upper - lower
    )
    wall = time.perf_counter() - t0
    return {
        "wall": wall,
        "runs": calls["n"],
        "x": dict(zip(names, map(float, res.x), strict=True)),
        "ok": bool(res.success),
        "model": calls["model"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", nargs="+", choices=list(TABLE_1), default=list(TABLE_1))
    parser.add_argument(
        "--options",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="fbia's LM options instead of its defaults (JSON values), e.g. jacobian=forward "
        "final_jacobian=forward alpha=0 beta=1e-6",
    )
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="overrides of the study for the calibrated model of both methods, as fbia run "
        "--set takes them, e.g. model.options.native_code=false",
    )
    args = parser.parse_args(argv)
    OVERRIDES[:] = args.set
    options = {}
    for item in args.options:
        key, _, value = item.partition("=")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            options[key] = value
    print(f"fbia's levenberg_marquardt options: {options or 'its defaults'}")
    print(f"the model: the study's{' with ' + ', '.join(args.set) if args.set else ''}")
    header = (
        f"{'start':7s} {'fbia runs':>9s} {'wall s':>7s} {'(model s)':>9s} {'scipy runs':>10s} "
        f"{'wall s':>7s} {'(model s)':>9s} {'runs x':>7s} {'wall x':>7s}  optima (fbia | scipy), "
        "difference in fbia's std. errors"
    )
    print(header)
    print("-" * len(header))
    total = {"fbia": [0, 0.0], "scipy": [0, 0.0]}
    worst = 0.0
    for label in args.starts:
        f, s = run_fbia(label, options), run_scipy(label)
        diff = max(
            (abs(f["x"][k] - s["x"][k]) / se for k, se in f["stderr"].items() if se > 0),
            default=float("nan"),
        )
        if f["ok"]:
            worst = max(worst, diff)
        for key, out in (("fbia", f), ("scipy", s)):
            total[key][0] += out["runs"]
            total[key][1] += out["wall"]
        xf = ", ".join(f"{v:.5g}" for v in f["x"].values())
        xs = ", ".join(f"{v:.5g}" for v in s["x"].values())
        print(
            f"{label:7s} {f['runs']:9d} {f['wall']:7.2f} {f['model']:9.2f} {s['runs']:10d} "
            f"{s['wall']:7.2f} {s['model']:9.2f} {f['runs'] / s['runs']:7.2f} "
            f"{f['wall'] / s['wall']:7.2f}  ({xf}{'' if f['ok'] else ' not converged'} | {xs}"
            f"{'' if s['ok'] else ' not converged'}), {diff:.3f}",
            flush=True,
        )
    (fr, fw), (sr, sw) = total["fbia"], total["scipy"]
    print("-" * len(header))
    print(
        f"{'total':7s} {fr:9d} {fw:7.2f} {'':9s} {sr:10d} {sw:7.2f} {'':9s} {fr / sr:7.2f} "
        f"{fw / sw:7.2f}  largest difference of converged optima: {worst:.3f} std. errors"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
