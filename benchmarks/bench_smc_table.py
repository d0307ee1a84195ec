"""Benchmark: Algorithm 1 as published (every step rejuvenates) on a 2-D GP surrogate, with
the log-densities tabulated (issue 27, item 2).

Paper B's example 7 samples a 2-D posterior (E, nu) with 10 000 particles, 30 Metropolis-
Hastings steps in every tempering step and zeta = 0.998, on the GP mean of L trained on about
a thousand runs.  Here L is a narrow E-nu band like the one of Paper B Fig. 9a (a Gaussian in
the rotated coordinates, 3 Pa across the band), the GP is fbia's ``GpSurrogate`` on 1024 Sobol
points of it, and the priors are Paper B's uniform box E in [50, 1000] Pa, nu in [-0.8, 0.5].

The anchor is the posterior of the same GP mean by quadrature (a 2001 x 2001 grid of the box):
exact up to the quadrature's error, far below the Monte Carlo error.  One invocation prints, per
run: tempering steps, seconds, posterior mean and standard deviations beside the quadrature's
(as differences in posterior standard deviations and ratios), the table's error at the final
particles, and for the direct path (the GP mean at every move) the time of its first steps,
extrapolated to the run.  The target (under 60 s on 2 cores) is checked here, not in a test.

    .venv/bin/python benchmarks/bench_smc_table.py            # full size (about 1 min)

Measured (2 cores, load 1.3): 160 tempering steps in 5.3 s (33 ms per step, table built in
1.0 s), mean within 0.015 posterior sd of the quadrature, sd ratio 1.009, table error 5.5e-5
in L at the final particles; the GP mean itself 0.22 s per step (35 s for the run, 7x).
    .venv/bin/python benchmarks/bench_smc_table.py --quick    # smoke run
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np
from scipy.stats import qmc

import fbia
from fbia.iterators.smc.sampler import SequentialMonteCarlo
from fbia.iterators.surrogates.gp import GpSurrogate

LOWER = np.array([50.0, -0.8])
UPPER = np.array([1000.0, 0.5])


def log_likelihood(x: np.ndarray) -> np.ndarray:
    """A band E = 400 + 300 (nu - 0.3) +- 3 Pa, nu = 0.3 +- 0.2 along it."""
    across = (x[:, 0] - 400.0 - 300.0 * (x[:, 1] - 0.3)) / 3.0
    along = (x[:, 1] - 0.3) / 0.2
    return -0.5 * (across**2 + along**2)


def quadrature(f, n: int = 2001) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and standard deviations of exp(f) under the uniform box prior."""
    axes = [np.linspace(LOWER[j], UPPER[j], n) for j in range(2)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    values = np.concatenate([f(grid[i : i + 200_000]) for i in range(0, len(grid), 200_000)])
    w = np.exp(values - values.max())
    w /= w.sum()
    mean = w @ grid
    sd = np.sqrt(w @ (grid - mean) ** 2)
    return mean, sd


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes for a smoke run")
    ap.add_argument("--n-train", type=int, default=1024)
    ap.add_argument("--n-particles", type=int, default=10_000)
    ap.add_argument("--n-rej", type=int, default=30)
    ap.add_argument("--zeta", type=float, default=0.998)
    ap.add_argument("--table-points", type=int, default=1025)
    ap.add_argument("--direct-steps", type=int, default=3, help="steps of the direct path")
    args = ap.parse_args()
    if args.quick:
        args.n_train, args.n_particles, args.n_rej, args.zeta = 256, 1000, 5, 0.98
        args.table_points, args.direct_steps = 257, 1
    print(
        f"2-D band likelihood on a GP mean of {args.n_train} Sobol points; N = "
        f"{args.n_particles}, n_rej = {args.n_rej}, zeta = {args.zeta}; {os.cpu_count()} "
        f"cores, load average {os.getloadavg()[0]:.1f}"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        u = qmc.Sobol(2, scramble=True, seed=0).random(args.n_train)
    x = LOWER + u * (UPPER - LOWER)
    t0 = time.perf_counter()
    gp = GpSurrogate(ard=True, restarts=2).fit(x, log_likelihood(x), rng=0)
    print(f"GP trained in {time.perf_counter() - t0:.1f} s")
    mean, sd = quadrature(gp.predict_mean)
    print(f"quadrature of the GP mean: mean {mean.round(4)}, sd {sd.round(4)}")
    priors = [fbia.priors.uniform(lo, hi) for lo, hi in zip(LOWER, UPPER, strict=True)]

    def sampler(table_points: int | None) -> SequentialMonteCarlo:
        return SequentialMonteCarlo(
            gp.predict_mean,
            priors,
            n_particles=args.n_particles,
            zeta=args.zeta,
            n_rejuvenation=args.n_rej,
            seed=1,
            rejuvenate="every_step",
            table_points=table_points,
        )

    s = sampler(args.table_points)
    t0 = time.perf_counter()
    post = s.run()
    total = time.perf_counter() - t0
    steps = post.n_steps
    post_sd = np.sqrt(np.diag(post.cov))
    print("1. Algorithm 1 on the tabulated GP mean:")
    print(
        f"  {steps} tempering steps, {total:.1f} s ({1e3 * total / steps:.1f} ms per step; "
        f"table built in {post.table['seconds_build']:.2f} s)"
    )
    print(f"  (mean - quadrature) / sd: {((post.mean - mean) / sd).round(3)}")
    print(f"  sd / quadrature sd:       {(post_sd / sd).round(3)}")
    print(
        f"  table error at {post.table['n_checked']} final particles: largest "
        f"{post.table['max_abs_error']:.2g}, RMS {post.table['rmse']:.2g} (units of L)"
    )
    print(f"  target (under 60 s on 2 cores): {'met' if total < 60 else 'NOT met'}")
    if args.direct_steps:
        d = sampler(None)
        t0 = time.perf_counter()
        gen = d.steps()
        for _ in range(args.direct_steps):
            next(gen)
        per = (time.perf_counter() - t0) / args.direct_steps
        print("2. Algorithm 1 on the GP mean itself (first steps):")
        print(
            f"  {per:.2f} s per step: the {steps} steps of run 1 would take about "
            f"{per * steps:.0f} s; ratio direct / tabulated {per * steps / total:.0f}"
        )


if __name__ == "__main__":
    main()
