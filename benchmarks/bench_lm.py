"""Forward evaluations to converge: fbia's LM (robust and paper mode) against scipy's lm and trf.

Run by hand or by ``make bench``::

    .venv/bin/python benchmarks/bench_lm.py            # all tables
    .venv/bin/python benchmarks/bench_lm.py --quick    # the NIST 'higher difficulty' set only

Every method counts *every* call of the residual function (scipy's ``nfev`` leaves out the
finite-difference calls of trf, so the calls are counted by a wrapper).  All methods use the
same forward-difference Jacobian, h_i = √ε·|x_i| on the NIST problems (fbia: alpha = 0,
beta = √ε; scipy: diff_step = √ε) and the same tolerances ftol = xtol = gtol = 1e-10.  Paper
mode has only eq. 29; it gets eps_grad = 1e-10·‖Jᵀr‖ at the start and at most 500 iterations.

Tables:

0. NIST StRD, both starts, to all digits: fbia's robust mode against MINPACK (scipy's
   ``least_squares(method="lm")``), both with xtol = ftol = gtol = 1e-15 and their default
   forward-difference step √ε; residual-function calls and the smallest LRE per problem and
   start, and whether fbia reaches what MINPACK reaches (LRE >= 6 where MINPACK gets >= 6,
   >= 4 where MINPACK gets >= 4).
1. NIST StRD, both starts: runs and the smallest log relative error (LRE) of the parameters
   (a method that stopped early shows a low LRE: its count is not a success).
2. The analytic flow-cell model (Paper A homogeneous example: E = 400 Pa, ν = 0.3, ray measure,
   12 measurement points) from the 11 starts of Paper A Table 1, with Paper A's perturbation
   α = 1e-5, β = 1e-3 (scipy: diff_step = 1e-3, no absolute part), the tolerances above
   (robust: without the absolute eq. 29a; paper mode: only eq. 29a, eps_grad = 1e-8) and bounds
   E in [50, 2000] Pa,
   ν in [-0.99, 0.49] (scipy's lm has no bounds: a run the model refuses counts as a residual
   of 1 m per point).  'rounds' are the sequential batches, the wall-clock time on a pool.
3. The bounded case: NIST Misra1a from start 1 with b1 <= 700.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares as scipy_least_squares

import fbia

HERE = Path(__file__).resolve().parent
SQRT_EPS = float(np.sqrt(np.finfo(float).eps))
TOL = 1e-10


def load_nist():
    spec = importlib.util.spec_from_file_location(
        "fbia_bench_nist", HERE.parent / "tests" / "data" / "nist_strd" / "nist.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


class Counted:
    """A residual function that counts its calls."""

    def __init__(self, fun):
        self.fun, self.calls = fun, 0

    def __call__(self, x):
        self.calls += 1
        return self.fun(x)


def run_fbia(fun, x0, bounds=None, **options):
    f = Counted(fun)
    res = fbia.least_squares(f, x0, bounds, **options)
    assert res.nfev == f.calls
    return res.x_array, f.calls, res.status, res


def run_scipy(fun, x0, method, bounds=None, diff_step=SQRT_EPS):
    f = Counted(fun)
    kw = {} if bounds is None else {"bounds": bounds}
    res = scipy_least_squares(
        f, x0, method=method, ftol=TOL, xtol=TOL, gtol=TOL, diff_step=diff_step,
        max_nfev=100_000, **kw,
    )  # fmt: skip
    return res.x, f.calls, "converged" if res.status > 0 else f"status {res.status}"


def paper_eps_grad(fun, x0):
    r = fun(np.asarray(x0, dtype=float))
    J = np.column_stack(
        [(fun(x0 + SQRT_EPS * max(abs(v), 1.0) * e) - r) / (SQRT_EPS * max(abs(v), 1.0))
         for v, e in zip(x0, np.eye(len(x0)), strict=True)]
    )  # fmt: skip
    return 1e-10 * float(np.linalg.norm(J.T @ r))


def nist_tight_table(nist, names):
    print("\n0. NIST StRD to all digits (xtol = ftol = gtol = 1e-15): fbia robust vs MINPACK")
    print("   calls / smallest LRE of the parameters; 'ok': fbia reaches what MINPACK reaches\n")
    print(f"{'problem':9s} {'st':>2s}  {'fbia':>14s}  {'MINPACK':>14s}  {'calls':>6s}  status")
    tight = 1e-15
    total_f = total_m = 0
    misses = []
    for name in names:
        p = nist.load(name)
        for s, x0 in ((1, p.start1), (2, p.start2)):
            x, nf, st, _ = run_fbia(
                p.residuals, x0, ftol=tight, xtol=tight, gtol=tight, max_iter=1000
            )
            f = Counted(p.residuals)
            m = scipy_least_squares(
                f, x0, method="lm", ftol=tight, xtol=tight, gtol=tight, max_nfev=100_000
            )
            lf, lm = p.lre(x).min(), p.lre(m.x).min()
            target = 6.0 if lm >= 6.0 else (4.0 if lm >= 4.0 else -math.inf)
            ok = lf >= target
            if not ok:
                misses.append((name, s))
            total_f, total_m = total_f + nf, total_m + f.calls
            print(
                f"{name:9s} {s:2d}  {nf:6d} / {lf:5.1f}  {f.calls:6d} / {lm:5.1f}  "
                f"{nf / f.calls:6.2f}  {'ok' if ok else 'MISS'} ({st})",
                flush=True,
            )
    print(
        f"\n   calls in all: fbia {total_f}, MINPACK {total_m} (ratio {total_f / total_m:.2f}); "
        f"fbia misses what MINPACK reaches on {len(misses)} pairs {misses}"
    )


def nist_table(nist, names):
    print("\n1. NIST StRD: residual-function calls to converge / smallest LRE of the parameters")
    print(f"   (forward differences h = √ε|x|, ftol = xtol = gtol = {TOL:g})\n")
    head = f"{'problem':9s} {'st':>2s}  {'fbia robust':>13s}  {'fbia paper':>13s}"
    head += f"  {'scipy lm':>13s}  {'scipy trf':>13s}"
    print(head)
    rows = []
    robust_opts = {"ftol": TOL, "xtol": TOL, "gtol": TOL, "max_iter": 1000}
    for name in names:
        p = nist.load(name)
        for s, x0 in ((1, p.start1), (2, p.start2)):
            out = {}
            x, n, _, _ = run_fbia(p.residuals, x0, **robust_opts)
            out["robust"] = (n, p.lre(x).min())
            eps = paper_eps_grad(p.residuals, x0)
            x, n, st, _ = run_fbia(p.residuals, x0, mode="paper", eps_grad=eps, max_iter=500)
            out["paper"] = (n, p.lre(x).min() if x is not None else -math.inf)
            for m in ("lm", "trf"):
                x, n, _ = run_scipy(p.residuals, x0, m)
                out[m] = (n, p.lre(x).min())
            rows.append((name, s, out))
            cells = [f"{n:6d} / {lre:4.1f}" for n, lre in out.values()]
            print(f"{name:9s} {s:2d}  " + "  ".join(f"{c:>13s}" for c in cells), flush=True)
    print()
    solved = {k: [r[2][k][1] >= 4.0 for r in rows] for k in ("robust", "paper", "lm", "trf")}
    for k in solved:
        total = sum(r[2][k][0] for r in rows)
        both = sum(
            r[2][k][0] for r in rows if all(r[2][m][1] >= 4.0 for m in ("robust", "lm", "trf"))
        )
        print(
            f"   {k:7s}: {total:6d} calls in all, {both:6d} on the cases robust, lm and trf all "
            f"solve; solved (LRE >= 4) {sum(solved[k]):2d} of {len(rows)}"
        )
    common = [r for r in rows if all(r[2][m][1] >= 4.0 for m in ("robust", "lm", "trf"))]
    not_more = sum(r[2]["robust"][0] <= min(r[2]["lm"][0], r[2]["trf"][0]) for r in common)
    ratio = np.median([r[2]["robust"][0] / min(r[2]["lm"][0], r[2]["trf"][0]) for r in common])
    print(
        f"   robust needs no more calls than the better of scipy's lm/trf in {not_more} of "
        f"{len(common)} cases all three solve; median ratio robust / best scipy = {ratio:.2f}"
    )


def flow_cell_table():
    print("\n2. Analytic flow-cell model (Paper A homogeneous example), Paper A Table 1 starts")
    print("   forward runs to converge (rounds = sequential batches), |E - 400| in Pa\n")
    model = fbia.forward_model("analytic_mound_2d")
    obs = fbia.synthetic_observations(
        model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], noise_std=0.0, seed=1, points=12
    )
    lower, upper = np.array([50.0, -0.99]), np.array([2000.0, 0.49])
    problem = fbia.InverseProblem(
        model=model,
        measure=fbia.measure("ray"),
        observations=obs,
        parameters=[
            fbia.Parameter("E", bounds=(lower[0], upper[0]), unit="Pa"),
            fbia.Parameter("nu", bounds=(lower[1], upper[1])),
        ],
    )
    n_r = len(problem.evaluate({"E": 400.0, "nu": 0.3}).residuals)

    def residuals(x):
        ev = problem.evaluate({"E": float(x[0]), "nu": float(x[1])}, keep_solution=False)
        return ev.residuals if ev.ok else np.full(n_r, 1000.0)  # 1 m per point

    starts = [(200, 0.4), (200, 0.0), (400, 0.45), (400, 0.0), (600, 0.4), (600, 0.0),
              (400, -0.3), (400, -0.6), (400, -0.9), (1000, 0.0), (1000, 0.4)]  # fmt: skip
    print(
        f"{'E0':>6s} {'nu0':>5s}  {'robust':>7s} {'rounds':>6s}  {'specul.':>7s} {'rounds':>6s}"
        f"  {'paper':>7s} {'rounds':>6s}  {'scipy lm':>8s}  {'scipy trf':>9s}  "
        f"{'|dE| robust':>11s} {'paper':>8s} {'lm':>8s} {'trf':>8s}"
    )
    totals = np.zeros(5, dtype=int)
    rounds = np.zeros(3, dtype=int)
    for e0, nu0 in starts:
        x0 = {"E": float(e0), "nu": float(nu0)}
        counts, errs, nrounds = [], [], []
        tight = {"ftol": TOL, "xtol": TOL, "gtol": TOL, "eps_grad": 0.0}
        for opts in (tight, {**tight, "speculative": True}, {"mode": "paper"}):
            gen_it = fbia.iterator("levenberg_marquardt", x0=x0, **opts)
            with fbia.SerialEvaluator() as ev:
                gen = gen_it.steps(problem, ev)
                k = sum(1 for _ in gen)
            res = gen_it.result
            counts.append(res.nfev)
            nrounds.append(k)
            errs.append(abs(res.x["E"] - 400.0) if res.x else math.inf)
        for m in ("lm", "trf"):
            b = None if m == "lm" else (lower, upper)
            x, n, _ = run_scipy(residuals, np.array([e0, nu0], float), m, b, diff_step=1e-3)
            counts.append(n)
            errs.append(abs(x[0] - 400.0))
        totals += counts
        rounds += nrounds
        print(
            f"{e0:6.0f} {nu0:5.2f}  {counts[0]:7d} {nrounds[0]:6d}  {counts[1]:7d} {nrounds[1]:6d}"
            f"  {counts[2]:7d} {nrounds[2]:6d}  {counts[3]:8d}  {counts[4]:9d}  "
            f"{errs[0]:11.1e} {errs[2]:8.1e} {errs[3]:8.1e} {errs[4]:8.1e}",
            flush=True,
        )
    print(
        f"{'total':>12s}  {totals[0]:7d} {rounds[0]:6d}  {totals[1]:7d} {rounds[1]:6d}  "
        f"{totals[2]:7d} {rounds[2]:6d}  {totals[3]:8d}  {totals[4]:9d}"
    )


def bounded_table(nist):
    print("\n3. Bounded case: NIST Misra1a from start 1 (500, 1e-4) with b1 <= 700\n")
    p = nist.load("Misra1a")
    bounds = (np.array([-np.inf, -np.inf]), np.array([700.0, np.inf]))
    opts = {"ftol": TOL, "xtol": TOL, "gtol": TOL}
    print(f"{'method':14s} {'calls':>6s}  {'LRE':>5s}  status")
    x, n, st, res = run_fbia(p.residuals, p.start1, bounds, **opts)
    print(f"{'fbia robust':14s} {n:6d}  {p.lre(x).min():5.1f}  {st}")
    x, n, st, res = run_fbia(p.residuals, p.start1, bounds, mode="paper")
    lre = f"{p.lre(x).min():5.1f}" if x is not None else "    -"
    print(f"{'fbia paper':14s} {n:6d}  {lre}  {st}: {res.message}")
    x, n, st, res = run_fbia(
        p.residuals, p.start1, bounds, mode="paper", mu_limit=1e30, max_iter=5000
    )
    lre = f"{p.lre(x).min():5.1f}" if x is not None else "    -"
    print(f"{'  no μ limit':14s} {n:6d}  {lre}  {st} (max_iter = 5000): still on the bound")
    for m in ("trf", "dogbox"):
        x, n, st = run_scipy(p.residuals, p.start1, m, bounds)
        print(f"{'scipy ' + m:14s} {n:6d}  {p.lre(x).min():5.1f}  {st}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="NIST higher difficulty only")
    args = parser.parse_args()
    nist = load_nist()
    names = nist.names()
    if args.quick:
        names = [n for n in names if nist.load(n).difficulty == "Higher"]
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # overflow on trial points
        nist_tight_table(nist, names)
        nist_table(nist, names)
        flow_cell_table()
        bounded_table(nist)
    print(f"\n({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
