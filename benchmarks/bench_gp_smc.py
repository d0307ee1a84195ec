"""Benchmark: the surrogate stage of Paper B's last example at full size (issue 4).

n_train = 2000 Sobol training points in 6 + 1 dimensions (E_k, nu_k of three subdomains plus the
uncertain inflow rate), synthetic log-likelihood values, a product Matérn 3/2 GP (Remark 9),
then SMC with 10 000 particles, 30 rejuvenation steps and zeta = 0.998. Prints GP training time
(GPy's default training vs the tuned one, on the same data), held-out error, SMC time, tempering
steps, log-likelihood evaluations and peak memory.

    .venv/bin/python benchmarks/bench_gp_smc.py            # full size
    .venv/bin/python benchmarks/bench_gp_smc.py --quick    # small, for a smoke run

The side-by-side with the SMC library ``particles`` runs only where it is installed: it is
not a dependency, because particles 0.4 declares numpy < 2 (it runs with numpy 2):
``.venv/bin/pip install --no-deps particles==0.4 joblib``.

The synthetic L mimics the heterogeneous mound (Paper B Fig. 11): subdomain k with area share
w_k deforms with a_k = q / E_k (lean) and a_k (1 - 2 nu_k) (flattening); L is eq. 5 with
D^2 = sum_k w_k^2 [(a_k - a_k*)^2 + (a_k (1 - 2 nu_k) - a_k* (1 - 2 nu_k*))^2], sigma_N = 0.02.
"""

from __future__ import annotations

import argparse
import math
import resource
import time
import tracemalloc

import numpy as np

import fbia
from fbia.iterators.smc.sampler import SequentialMonteCarlo
from fbia.iterators.surrogates.design import sobol_design
from fbia.iterators.surrogates.gp import GpSurrogate

TRUTH = np.array([500.0, 0.2, 200.0, 0.1, 1000.0, 0.3, 100.0])  # Paper B heterogeneous example
SHARE = np.array([0.25, 0.6, 0.15])
SIGMA = 0.02


def parameters() -> list[fbia.Parameter]:
    out = []
    for k in range(1, 4):
        out.append(fbia.Parameter(f"E{k}", bounds=(100.0, 1500.0), unit="Pa"))
        out.append(fbia.Parameter(f"nu{k}", bounds=(-0.8, 0.5)))
    out.append(
        fbia.Parameter("inflow_rate", unit="mm^2/s", prior=fbia.priors.beta(2.6, 1.4, 0, 110))
    )
    return out


def synthetic_log_likelihood(z: np.ndarray) -> np.ndarray:
    """Eq. 5 with the D^2 of the module docstring (n = 6 features)."""

    def features(v: np.ndarray) -> np.ndarray:
        e, nu, q = v[:, 0:6:2], v[:, 1:6:2], v[:, 6:7]
        a = q / e
        return np.concatenate([SHARE * a, SHARE * a * (1 - 2 * nu)], axis=1)

    d2 = np.sum((features(z) - features(TRUTH[None])) ** 2, axis=1)
    return -3.0 * math.log(2 * math.pi * SIGMA**2) - d2 / (2 * SIGMA**2)


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes for a smoke run")
    ap.add_argument("--n-train", type=int, default=2000)
    ap.add_argument("--n-particles", type=int, default=10_000)
    ap.add_argument("--n-rej", type=int, default=30)
    ap.add_argument("--zeta", type=float, default=0.998)
    ap.add_argument(
        "--default-iters",
        type=int,
        default=15,
        help="iteration cap of GPy's default training (1000 in GPy; ~6 s each here)",
    )
    ap.add_argument("--skip-default", action="store_true", help="skip GPy's default training")
    ap.add_argument(
        "--skip-particles", action="store_true", help="skip the side-by-side with `particles`"
    )
    ap.add_argument(
        "--algorithm1-steps",
        type=int,
        default=50,
        help="also run Algorithm 1 (moves in every step) for this many tempering steps "
        "(0: to gamma = 1, about an hour at full size; -1: skip)",
    )
    args = ap.parse_args()
    if args.quick:
        args.n_train, args.n_particles, args.n_rej, args.zeta = 300, 1000, 5, 0.95
    params = parameters()
    n_test = 200
    design = sobol_design(params, args.n_train + n_test, seed=0)
    y = synthetic_log_likelihood(design)
    x_tr, y_tr, x_te, y_te = (
        design[: args.n_train],
        y[: args.n_train],
        design[args.n_train :],
        y[args.n_train :],
    )
    print(
        f"design: {args.n_train} training + {n_test} test Sobol points in {design.shape[1]} dims; "
        f"L in [{y_tr.min():.4g}, {y_tr.max():.4g}]"
    )

    rows = []
    trainings = [
        (
            f"GPy default (var=1, l=1, one L-BFGS-B run, max_iters={args.default_iters})",
            GpSurrogate(ard=True, gpy_default=True, max_iters=args.default_iters),
        ),
        (
            "tuned (data-based guess + 2 restarts on 800-point prefix, bounds, 20-iter polish)",
            GpSurrogate(ard=True, restarts=2, subset=800, polish_iters=20),
        ),
    ]
    for label, gp in trainings[1:] if args.skip_default else trainings:
        t0 = time.perf_counter()
        gp.fit(x_tr, y_tr, rng=np.random.default_rng(0))
        seconds = time.perf_counter() - t0
        err = gp.test_error(x_te, y_te)
        rows.append(
            (
                label,
                seconds,
                gp.info["neg_log_evidence"],
                err["test_relative_l2"],
                err["test_rmse"],
                gp,
            )
        )
        print(
            f"GP {label}: {seconds:.1f} s, -log evidence {gp.info['neg_log_evidence']:.6g}, "
            f"held-out relative L2 error {err['test_relative_l2']:.4f}, RMSE {err['test_rmse']:.4g}"
        )
    gp = min(rows, key=lambda r: r[2])[5]

    x1 = np.random.default_rng(1).uniform(size=(args.n_particles, 7)) * (
        design.max(0) - design.min(0)
    ) + design.min(0)
    t0 = time.perf_counter()
    gp.predict_mean(x1)
    t_pred = time.perf_counter() - t0
    print(f"GP mean at {args.n_particles} particles: {t_pred:.3f} s per call")

    runs = [("after_resampling", 0)]
    if args.algorithm1_steps >= 0:
        runs.append(("every_step", args.algorithm1_steps))
    for mode, max_steps in runs:
        post = run_smc(gp, params, args, mode, max_steps)
        if post is None:
            continue
        names = [p.name for p in params]
        print(
            "  posterior mean: "
            + ", ".join(f"{n}={v:.3g}" for n, v in zip(names, post.mean, strict=True))
        )
        print(
            "  truth:          "
            + ", ".join(f"{n}={v:.3g}" for n, v in zip(names, TRUTH, strict=True))
        )
    if not args.skip_particles:
        particles_side_by_side(params, args)


def run_smc(gp, params, args, mode: str, max_steps: int):
    """One SMC run; ``max_steps`` > 0 stops it after that many steps and prints the rate."""
    print(f"SMC, rejuvenate={mode!r}:")
    tracemalloc.start()
    sampler = SequentialMonteCarlo(
        gp.predict_mean,
        [p.prior for p in params],
        n_particles=args.n_particles,
        zeta=args.zeta,
        n_rejuvenation=args.n_rej,
        seed=0,
        names=[p.name for p in params],
        rejuvenate=mode,
    )
    t0 = time.perf_counter()
    gen = sampler.steps()
    while True:
        try:
            state = next(gen)
        except StopIteration as stop:
            post = stop.value
            break
        if state.step % 100 == 0:
            print(f"    {state}  ({time.perf_counter() - t0:.0f} s)", flush=True)
        if max_steps and state.step >= max_steps:
            t_part = time.perf_counter() - t0
            _, peak_py = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            print(
                f"  stopped after {state.step} steps at gamma = {state.gamma:.4g}: "
                f"{t_part:.1f} s ({t_part / state.step:.2f} s per step), {sampler.nfev} "
                f"log-likelihood evaluations; peak memory {peak_py / 2**20:.0f} MiB traced"
            )
            return None
    t_smc = time.perf_counter() - t0
    _, peak_py = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    moves = sum(h["moved"] for h in post.history)
    print(
        f"  {t_smc:.1f} s, {post.n_steps} tempering steps ({moves} with moves, "
        f"{sum(h['resampled'] for h in post.history)} resamplings), {post.nfev} log-likelihood "
        f"evaluations, final ESS {post.final_ess:.0f}, log-evidence {post.log_evidence:.4g} "
        f"+- {post.log_evidence_se:.2g}"
    )
    print(
        f"  peak memory: {peak_py / 2**20:.0f} MiB traced during SMC, "
        f"{peak_rss_mb():.0f} MiB peak RSS of the process"
    )
    return post


def particles_side_by_side(params, args) -> None:
    """Likelihood-evaluation counts: this SMC vs ``particles``' adaptive tempering.

    Both sample exp(L) p with the synthetic L itself (cheap), the same N, MH steps per move
    and ESS rule: particles' ``AdaptiveTempering`` resamples every step and picks the next
    exponent so that the ESS of the new weights is ESSrmin N, i.e. ESS_s = zeta ESS_(s-1)
    with ESSrmin = zeta; its moves are ``len_chain - 1`` random-walk MH steps with the
    weighted particle covariance (not waste-free, not adaptive).
    """
    print(f"side by side on the synthetic L itself (N = {args.n_particles}, zeta = {args.zeta}):")
    names = [p.name for p in params]
    for mode in ("after_resampling", "every_step"):
        sampler = SequentialMonteCarlo(
            synthetic_log_likelihood,
            [p.prior for p in params],
            n_particles=args.n_particles,
            zeta=args.zeta,
            n_rejuvenation=args.n_rej,
            seed=0,
            names=names,
            rejuvenate=mode,
        )
        t0 = time.perf_counter()
        post = sampler.run()
        print(
            f"  fbia SMC ({mode}): {post.n_steps} steps, {post.nfev} evaluations, "
            f"{time.perf_counter() - t0:.1f} s, mean " + ", ".join(f"{v:.3g}" for v in post.mean)
        )
    try:
        import particles
        from particles import distributions as dists
        from particles import smc_samplers as ssp
    except ImportError:
        print(
            "  particles: not installed (optional, not a dependency of fbia). particles 0.4 "
            "declares numpy < 2 but runs with numpy 2 (checked with numpy 2.4); install it with "
            "`.venv/bin/pip install --no-deps particles==0.4 joblib` to compare (a plain "
            "`pip install particles` resolves to the older 0.3 next to numpy >= 2)"
        )
        return
    law = {}
    for p in params:
        if p.name == "inflow_rate":
            law[p.name] = dists.LinearD(dists.Beta(a=2.6, b=1.4), a=110.0, b=0.0)
        else:
            law[p.name] = dists.Uniform(a=p.bounds[0], b=p.bounds[1])
    prior = dists.StructDist(law)
    count = [0]

    class Bridge(ssp.TemperingBridge):  # type: ignore[misc]
        def logtarget(self, theta):
            z = np.column_stack([theta[n] for n in names])
            count[0] += len(z)
            return synthetic_log_likelihood(z) + prior.logpdf(theta)

    move = ssp.AdaptiveMCMCSequence(len_chain=args.n_rej + 1, adaptive=False)
    fk = ssp.AdaptiveTempering(
        model=Bridge(base_dist=prior),
        ESSrmin=args.zeta,
        wastefree=False,
        move=move,
        max_iter=100_000,
    )
    np.random.seed(0)  # noqa: NPY002 (particles draws from numpy's global generator)
    alg = particles.SMC(fk=fk, N=args.n_particles, verbose=False)
    t0 = time.perf_counter()
    alg.run()
    mean = [np.average(alg.X.theta[n], weights=alg.W) for n in names]
    print(
        f"  particles {particles.__version__ if hasattr(particles, '__version__') else ''}"
        f" AdaptiveTempering: {alg.t} steps, {count[0]} evaluations, "
        f"{time.perf_counter() - t0:.1f} s, mean " + ", ".join(f"{v:.3g}" for v in mean)
    )


if __name__ == "__main__":
    main()
