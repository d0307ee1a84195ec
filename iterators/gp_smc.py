"""Bayesian calibration with a GP surrogate of the log-likelihood and adaptive SMC (Paper B).

::

    import fbia
    it = fbia.iterator("gp_smc", n_train=200, n_particles=5000, n_rejuvenation=20,
                       zeta=0.995, seed=0)
    result = it.run(problem)                  # problem.noise_std = sigma_N [mm] (eq. 5)
    print(result.summary())                   # MAP, posterior mean, std
    it.write_plots(result, problem, "output")     # Paper B Figs. 5-9, 13-15
    fbia.iterators.gp_smc.save_posterior(result, "output")   # posterior.npz + posterior.json

The stages (each yields a :class:`GpSmcState`; ``steps()`` returns the :class:`Result`):

1. **Design**: the first ``n_train`` (+ ``n_test`` held-out) points of a scrambled, seeded
   Sobol sequence in the box of the calibration parameters x and the uncertain parameters
   theta (bounds; a theta without finite bounds, or every input with ``design="prior"``
   (Remark 7), goes through its prior's inverse CDF). A larger ``n_train`` with the same
   seed extends the design by the next points of the same sequence, and
   :meth:`GpSmcIterator.reuse` keeps an earlier result's runs so only the new points run.
   All forward runs go to the evaluator as one batch; failed runs are excluded from training
   and kept in the result (``Result.evaluations``, ``info["design_status"]``).
2. **Likelihood** (eq. 4-5): per observation k with noise sigma_k (``Observation.noise_std``,
   else ``problem.noise_std``), L = sum_k [-n_k/2 log(2 pi sigma_k^2) - D_k^2 / (2 sigma_k^2)],
   n_k the number of individual measurements (the residual count of the measure; 1 for rkhs).
3. **GP surrogate** of L (:mod:`fbia.iterators.gp_surrogate`, eq. 26-29, Remarks 9-10),
   its leave-one-out error and the error at the held-out Sobol points (Fig. 12).
   ``mode="direct"`` skips the surrogate and runs the forward model inside SMC (cheap models;
   every SMC batch goes to the evaluator, failed runs count as zero likelihood; the records
   stay in the evaluator, not in ``Result.evaluations``).
4. **SMC** (:mod:`fbia.iterators.smc`, Algorithm 1) on exp(gamma L(x, theta)) p(x) p(theta).
   The posterior under uncertainty q(x | Y) (eq. 3b) is the theta-marginal of the particles.
5. **Summaries**: MAP (best particle of the last step when there is no theta; the heaviest bin
   of a weighted histogram with ``map_bins`` intervals per x when theta is marginalised,
   Remark 8), maximum likelihood, posterior mean and covariance (the global Gaussian
   approximation), the Laplace approximation at the MAP (finite-difference Hessian on the
   surrogate), 1-D credible intervals.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Generator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field
from scipy.stats import qmc

from ..core.errors import ConfigError
from ..core.evaluator import Evaluator
from ..core.iteration import IteratorBase
from ..core.likelihood import gaussian_log_likelihood, measurement_count
from ..core.likelihood import noise_levels as _noise_levels
from ..core.options import PluginOptions
from ..core.parameters import Parameter, Prior
from ..core.problem import Evaluation, InverseProblem, Result
from .gp_surrogate import OPTIMIZERS, GpSurrogate
from .smc import SequentialMonteCarlo, SmcResult, SmcState

FloatArray = NDArray[np.float64]

#: Version tag of the posterior files written by :func:`save_posterior`.
POSTERIOR_FORMAT = "fbia-posterior-1"


@dataclass
class GpSmcState:
    """What :meth:`GpSmcIterator.steps` yields: the stage and its figures."""

    stage: Literal["design", "forward_runs", "surrogate", "smc", "check"]
    message: str
    data: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        return f"[{self.stage}] {self.message}"


def _check_note(check: Mapping[str, Any] | None) -> str:
    """The posterior check in the result message, with a warning when it failed."""
    if not check:
        return ""
    note = f"; surrogate RMSE {check['rmse']:.3g} in L at {check['n']} posterior draws"
    if not check["rmse"] < 1.0:
        note += " (not well below 1: the posterior is not reliable, train on more runs)"
    return note


# -- the likelihood (eq. 4-5) -------------------------------------------------------------------
def noise_levels(problem: InverseProblem) -> list[float]:
    """sigma_N of every observation: its own ``noise_std``, else ``problem.noise_std``."""
    sigmas = _noise_levels(problem)
    if sigmas is None:
        raise ConfigError(
            "an observation has no noise_std and the problem has none: the Gaussian "
            "likelihood (Paper B eq. 5) needs sigma_N [mm]",
            "gp_smc",
        )
    return sigmas


#: Gaussian static log-likelihood (eq. 5) of one evaluation record; -inf if it failed.
log_likelihood_of = gaussian_log_likelihood


# -- the design ---------------------------------------------------------------------------------
def _finite_bounds(p: Parameter) -> bool:
    return p.bounds is not None and all(math.isfinite(b) for b in p.bounds)


def sobol_design(
    parameters: Sequence[Parameter], n: int, seed: int, start: int = 0, through_prior: bool = False
) -> FloatArray:
    """Points ``start .. start + n - 1`` of a scrambled Sobol sequence mapped to the inputs.

    Equal seeds give the same sequence, so a design of n points extends to n + m points by
    the next m points of the same sequence (Paper B, "Convergence over number of training
    points"). A parameter with finite bounds gets the uniform map onto them, else (or with
    ``through_prior``) its prior's inverse CDF (Remark 7).
    """
    sampler = qmc.Sobol(len(parameters), scramble=True, seed=seed)
    if start:
        sampler.fast_forward(start)
    with warnings.catch_warnings():  # any n is fine here: designs are extended point by point
        warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*")
        u = sampler.random(n)
    out = np.empty_like(u)
    for j, p in enumerate(parameters):
        if p.bounds is not None and _finite_bounds(p) and not through_prior:
            lo, hi = p.bounds
            out[:, j] = lo + (hi - lo) * u[:, j]
        else:
            if p.prior is None:
                raise ConfigError("needs finite bounds or a prior for the design", p.name)
            out[:, j] = p.prior.ppf(np.clip(u[:, j], 1e-9, 1 - 1e-9))
    return out


class GpSmcIterator(IteratorBase):
    """Bayesian calibration under uncertainty: Sobol design, GP surrogate of L, SMC (Paper B).

    See the module docstring for the stages; the options are below.
    """

    class Options(PluginOptions):
        mode: Literal["surrogate", "direct"] = Field(
            "surrogate",
            description="'surrogate': SMC on a GP of L trained on a Sobol design; 'direct': "
            "SMC calls the forward model (only for cheap models) [-]",
        )
        n_train: int = Field(200, ge=2, description="forward runs of the training design [-]")
        n_check: int = Field(
            0,
            ge=0,
            description="forward runs at distinct posterior draws after SMC, to measure the "
            "surrogate's error where the posterior is (its RMSE in L should be well below 1; "
            "surrogate mode) [-]",
        )
        n_test: int = Field(
            0,
            ge=0,
            description="held-out forward runs (the next Sobol points) for the surrogate "
            "error (Paper B Remark 9 uses 100) [-]",
        )
        design: Literal["box", "prior"] = Field(
            "box",
            description="'box': Sobol points uniform in the bounds; 'prior': through the "
            "priors' inverse CDFs (Remark 7) [-]",
        )
        seed: int = Field(0, description="seed of the Sobol scrambling and of SMC [-]")
        ard: bool = Field(
            False,
            description="one GP length scale per input (product of 1-D Matérn 3/2 kernels, "
            "Remark 9) instead of one for all standardised inputs [-]",
        )
        gp_optimizer: Literal["lbfgsb", "scg"] = Field(
            "lbfgsb", description=f"evidence maximiser (eq. 29): one of {OPTIMIZERS} [-]"
        )
        gp_restarts: int = Field(
            2, ge=0, description="extra GP trainings from random initial guesses [-]"
        )
        gp_subset: int = Field(
            800,
            ge=2,
            description="above this many runs, the GP hyperparameter search runs on the first "
            "gp_subset design points and is refined on all [-]",
        )
        gp_polish_iters: int = Field(
            20, ge=1, description="iterations of that refinement on all points [-]"
        )
        nugget_factor: float = Field(
            1e-5, gt=0, description="nugget sigma_n^2 = factor (max L - min L) [-]"
        )
        mean_offset: float = Field(
            1.0, description="GP prior mean m = min L - offset (max L - min L) (Remark 10) [-]"
        )
        n_particles: int = Field(5000, ge=10, description="SMC particles N [-]")
        n_rejuvenation: int = Field(
            20, ge=0, description="Metropolis-Hastings steps per tempering step n_rej [-]"
        )
        zeta: float = Field(
            0.995, gt=0, lt=1, description="ESS_s = zeta ESS_(s-1) (Algorithm 1) [-]"
        )
        ess_min: float = Field(
            0.5, ge=0, le=1, description="resample when ESS < ess_min N (fraction of N) [-]"
        )
        rejuvenate: Literal["every_step", "after_resampling"] = Field(
            "every_step",
            description="when particles move: every tempering step (Algorithm 1) or only in "
            "steps that resample and the last one (resample-move; far fewer likelihood calls "
            "when zeta is close to 1) [-]",
        )
        map_bins: int = Field(
            30, ge=2, description="intervals per x of the MAP histogram under theta (Remark 8) [-]"
        )
        laplace: bool = Field(
            True, description="Laplace approximation at the MAP (no theta only) [-]"
        )
        max_smc_steps: int = Field(5000, ge=1, description="limit of tempering steps [-]")

    options: Options
    surrogate: GpSurrogate | None = None
    posterior: SmcResult | None = None

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """Options of a cheap instance (conformance tests, smoke runs)."""
        return {"n_train": 16, "n_particles": 200, "n_rejuvenation": 2, "zeta": 0.8, "seed": 0}

    # -- the algorithm ----------------------------------------------------------------------
    def steps(
        self, problem: InverseProblem, evaluator: Evaluator
    ) -> Generator[GpSmcState, None, Result]:
        opts = self.options
        t_start = time.perf_counter()
        sigmas = noise_levels(problem)
        count = measurement_count(problem)
        inputs = [*problem.parameters, *problem.uncertain]
        priors: list[Prior] = []
        for p in inputs:
            if p.prior is None:
                raise ConfigError("needs a prior distribution", p.name)
            priors.append(p.prior)
            if not _finite_bounds(p) and opts.design == "box" and p in problem.parameters:
                raise ConfigError(
                    "a calibration parameter needs finite bounds for the Sobol design "
                    "(or design = 'prior')",
                    p.name,
                )
        names = [p.name for p in inputs]
        n_x = len(problem.parameters)
        history: list[dict[str, Any]] = []

        def record(stage: str, **data: Any) -> dict[str, Any]:
            entry = {"stage": stage, "seconds": time.perf_counter() - t_start, **data}
            history.append(entry)
            return entry

        evaluations: list[Evaluation] = []
        info: dict[str, Any] = {"names": names, "n_x": n_x, "mode": opts.mode}
        if opts.mode == "surrogate":
            n_all = opts.n_train + opts.n_test
            design = sobol_design(inputs, n_all, opts.seed, through_prior=opts.design == "prior")
            yield GpSmcState(
                "design",
                f"{opts.n_train} training + {opts.n_test} test points (Sobol, seed {opts.seed})",
                record("design", n_train=opts.n_train, n_test=opts.n_test),
            )
            reused = self._reusable(design, names)
            points = [dict(zip(names, map(float, row), strict=True)) for row in design]
            evaluations = reused + list(evaluator.evaluate(problem, points[len(reused) :]))
            loglik = np.array([log_likelihood_of(ev, sigmas, count) for ev in evaluations])
            ok = np.isfinite(loglik)
            n_failed = int((~ok[len(reused) :]).sum())
            train = np.arange(n_all) < opts.n_train
            n_new = n_all - len(reused)
            yield GpSmcState(
                "forward_runs",
                f"{n_new} forward runs ({len(reused)} reused), {n_failed} failed",
                record("forward_runs", nfev=n_new, n_failed=n_failed, reused=len(reused)),
            )
            info.update(
                design=design,
                design_log_likelihood=loglik,
                design_status=[ev.status for ev in evaluations],
                train_mask=train,
            )
            use = train & ok
            if use.sum() < 2:
                return self._finish_failed(evaluations, history, info, n_failed, n_new)
            gp = GpSurrogate(
                ard=opts.ard,
                optimizer=opts.gp_optimizer,
                restarts=opts.gp_restarts,
                nugget_factor=opts.nugget_factor,
                mean_offset=opts.mean_offset,
                subset=opts.gp_subset,
                polish_iters=opts.gp_polish_iters,
            ).fit(design[use], loglik[use], rng=np.random.default_rng(opts.seed))
            self.surrogate = gp
            quality: dict[str, Any] = dict(gp.loo())
            test = ~train & ok
            if test.any():
                quality.update(gp.test_error(design[test], loglik[test]))
            info["gp"] = {**gp.describe(), **quality}
            best = int(np.argmax(np.where(use, loglik, -np.inf)))
            info["best_run"] = {"x": design[best], "log_likelihood": float(loglik[best])}
            info["gp_state"] = gp.state()
            yield GpSmcState(
                "surrogate",
                f"GP on {int(use.sum())} runs: LOO rel. error {quality['loo_relative_l2']:.3g}",
                record("surrogate", **{k: v for k, v in gp.describe().items()}, **quality),
            )
            log_likelihood: Callable[[FloatArray], FloatArray] = gp.predict_mean
            nfev = n_new
        else:
            n_failed = 0
            counter = {"nfev": 0, "failed": 0}

            def log_likelihood(x: FloatArray) -> FloatArray:
                # The forward model inside SMC: one batch per SMC call; failed runs have
                # zero likelihood (L = -inf) and are counted.
                pts = [dict(zip(names, map(float, row), strict=True)) for row in x]
                evs = evaluator.evaluate(problem, pts)
                counter["nfev"] += len(evs)
                counter["failed"] += sum(not ev.ok for ev in evs)
                return np.array([log_likelihood_of(ev, sigmas, count) for ev in evs])

        sampler = SequentialMonteCarlo(
            log_likelihood,
            priors,
            n_particles=opts.n_particles,
            zeta=opts.zeta,
            n_rejuvenation=opts.n_rejuvenation,
            ess_min=opts.ess_min,
            rng=np.random.default_rng([opts.seed, 1]),
            names=names,
            max_steps=opts.max_smc_steps,
            rejuvenate=opts.rejuvenate,
        )
        gen = sampler.steps()
        while True:
            try:
                state: SmcState = next(gen)
            except StopIteration as stop:
                post: SmcResult = stop.value
                break
            yield GpSmcState("smc", str(state), record("smc", **state.__dict__))
        self.posterior = post
        if opts.mode == "direct":
            nfev, n_failed = counter["nfev"], counter["failed"]
        elif opts.n_check:
            check, evs = self._posterior_check(problem, evaluator, post, gp, names, sigmas)
            evaluations = [*evaluations, *evs]
            nfev += len(evs)
            n_failed += check["n_failed"]
            info["posterior_check"] = check
            yield GpSmcState(
                "check",
                f"surrogate at {check['n']} posterior draws: RMSE {check['rmse']:.3g} in L",
                record("check", **{k: v for k, v in check.items() if k != "x"}),
            )
        info.update(self._summaries(post, n_x, log_likelihood, inputs))
        info.update(
            particles=post.particles,
            weights=post.weights,
            log_likelihood=post.log_likelihood,
            log_prior=post.log_prior,
            log_evidence=post.log_evidence,
            log_evidence_se=post.log_evidence_se,
            smc={
                "n_steps": post.n_steps,
                "gammas": post.gammas,
                "ess": post.ess,
                "acceptance": post.acceptance,
                "nfev_log_likelihood": post.nfev,
                "final_ess": post.final_ess,
                "rejuvenate": opts.rejuvenate,
                "steps_with_moves": sum(h["moved"] for h in post.history),
            },
            priors=[p.describe() for p in inputs],
            seconds=time.perf_counter() - t_start,
        )
        x_map = dict(zip(problem.names, map(float, info["map"]), strict=True))
        return Result(
            status="completed",
            success=True,
            message=(
                f"posterior from {opts.n_particles} particles in {post.n_steps} tempering "
                f"steps ({opts.mode}; {nfev} forward runs, {n_failed} failed)"
                + _check_note(info.get("posterior_check"))
            ),
            x=x_map,
            nfev=nfev,
            n_failed=n_failed,
            iterator="gp_smc",
            history=history,
            evaluations=evaluations,
            info=info,
        )

    def reuse(self, result: Result) -> GpSmcIterator:
        """Extend an earlier study: reuse the forward runs of ``result`` (same seed, design and
        inputs) and run only the new points of the same Sobol sequence (Paper B's n_train study).

        >>> # r200 = fbia.iterator("gp_smc", n_train=200).run(problem)
        >>> # r500 = fbia.iterator("gp_smc", n_train=500).reuse(r200).run(problem)  # 300 runs
        """
        if result.iterator != "gp_smc" or "design" not in result.info:
            raise ConfigError("can only reuse the result of a surrogate-mode gp_smc run", "reuse")
        self._previous = result
        return self

    _previous: Result | None = None

    def _reusable(self, design: FloatArray, names: list[str]) -> list[Evaluation]:
        """The leading evaluations of the reused result that match the new design's prefix."""
        prev = self._previous
        if prev is None:
            return []
        old = np.asarray(prev.info["design"])
        if list(prev.info["names"]) != names:
            raise ConfigError(
                f"the reused result has inputs {prev.info['names']}, this problem {names}", "reuse"
            )
        k = min(len(old), len(design))
        same = np.all(np.isclose(old[:k], design[:k], rtol=1e-12, atol=0.0), axis=1)
        n = k if same.all() else int(np.argmin(same))
        if n == 0:
            raise ConfigError(
                "the reused result's design is not a prefix of this one (other seed, bounds "
                "or design option?)",
                "reuse",
            )
        return list(prev.evaluations[:n])

    def _posterior_check(
        self,
        problem: InverseProblem,
        evaluator: Evaluator,
        post: SmcResult,
        gp: GpSurrogate,
        names: list[str],
        sigmas: list[float],
    ) -> tuple[dict[str, Any], list[Evaluation]]:
        """Forward runs at ``n_check`` distinct posterior draws: the surrogate's error there.

        The held-out Sobol points measure the error over the whole box; what decides whether
        the posterior is right is the error where the posterior mass is, in units of L (an
        error of order 1 changes posterior ratios by a factor e).
        """
        rng = np.random.default_rng([self.options.seed, 2])
        order = rng.choice(len(post.weights), size=len(post.weights), p=post.weights)
        _, first = np.unique(order, return_index=True)
        idx = order[np.sort(first)][: self.options.n_check]
        x = post.particles[idx]
        points = [dict(zip(names, map(float, row), strict=True)) for row in x]
        evs = list(evaluator.evaluate(problem, points))
        count = measurement_count(problem)
        loglik = np.array([log_likelihood_of(ev, sigmas, count) for ev in evs])
        ok = np.isfinite(loglik)
        err = gp.predict_mean(x[ok]) - loglik[ok]
        n_ok = int(ok.sum())
        return {
            "n": n_ok,
            "n_failed": int((~ok).sum()),
            "x": x,
            "log_likelihood": loglik,
            "rmse": float(np.sqrt(np.mean(err**2))) if n_ok else math.nan,
            "max_abs": float(np.max(np.abs(err))) if n_ok else math.nan,
            "mean_error": float(np.mean(err)) if n_ok else math.nan,
        }, evs

    def _finish_failed(self, evaluations, history, info, n_failed, nfev) -> Result:
        messages = sorted({ev.message for ev in evaluations if not ev.ok})[:3]
        n_bad = sum(not ev.ok for ev in evaluations)
        return Result(
            status="all_failed",
            success=False,
            message=(
                f"{n_bad} of {len(evaluations)} forward runs failed: fewer than 2 training "
                f"points for the GP (e.g. {'; '.join(messages)})"
            ),
            nfev=nfev,
            n_failed=n_failed,
            iterator="gp_smc",
            history=history,
            evaluations=evaluations,
            info=info,
        )

    # -- point estimates and summaries --------------------------------------------------------
    def _summaries(
        self, post: SmcResult, n_x: int, log_likelihood: Any, inputs: Sequence[Parameter]
    ) -> dict[str, Any]:
        opts = self.options
        x = post.particles[:, :n_x]
        w = post.weights
        mean = w @ x
        dx = x - mean
        cov = (dx * w[:, None]).T @ dx
        has_theta = post.particles.shape[1] > n_x
        out: dict[str, Any] = {
            "posterior_mean": mean,
            "posterior_cov": cov,
            "posterior_std": np.sqrt(np.diag(cov)),
            "posterior_mean_all": post.mean,
            "posterior_cov_all": post.cov,
            "max_likelihood": post.max_likelihood,
            "credible_intervals": {
                name: _weighted_quantiles(post.particles[:, j], w, [0.025, 0.5, 0.975])
                for j, name in enumerate(post.names)
            },
        }
        best = post.map[:n_x]
        if has_theta:
            out["map"] = map_by_binning(x, w, [inputs[j] for j in range(n_x)], opts.map_bins)
            out["map_method"] = f"histogram, {opts.map_bins} bins per parameter (Remark 8)"
            out["best_particle"] = post.map
        else:
            out["map"] = best
            out["map_method"] = "particle of highest posterior in the last SMC step"
            if opts.laplace and opts.mode == "surrogate":
                out["laplace"] = laplace_approximation(
                    lambda z: log_likelihood(z) + _log_prior(inputs, z), best, cov
                )
        return out

    # -- output ---------------------------------------------------------------------------------
    @staticmethod
    def write_plots(
        result: Result,
        problem: InverseProblem,
        folder: str | Path,
        figures: Sequence[str] | None = None,
    ) -> list[Path]:
        """Paper B's figures of a gp_smc result into ``folder`` (see :mod:`.smc_plots`)."""
        from .smc_plots import plot_gp_smc_result

        return plot_gp_smc_result(result, problem, folder, figures)


def _log_prior(inputs: Sequence[Parameter], z: FloatArray) -> FloatArray:
    out = np.zeros(len(z))
    for j, p in enumerate(inputs):
        assert p.prior is not None  # checked at the start of steps()
        out += p.prior.logpdf(z[:, j])
    return out


def _weighted_quantiles(values: FloatArray, weights: FloatArray, q: Sequence[float]) -> list[float]:
    order = np.argsort(values)
    cdf = np.cumsum(weights[order])
    cdf /= cdf[-1]
    return [float(values[order][min(int(np.searchsorted(cdf, qi)), len(cdf) - 1)]) for qi in q]


def map_by_binning(
    x: FloatArray, weights: FloatArray, parameters: Sequence[Parameter], bins: int
) -> FloatArray:
    """MAP of the theta-marginal: centre of the heaviest of ``bins`` intervals per parameter
    (Paper B Remark 8). The box is the parameters' bounds, else the particles' range; only
    occupied bins are counted, so any dimension works."""
    lo = np.array(
        [p.lower if math.isfinite(p.lower) else x[:, j].min() for j, p in enumerate(parameters)]
    )
    hi = np.array(
        [p.upper if math.isfinite(p.upper) else x[:, j].max() for j, p in enumerate(parameters)]
    )
    width = np.where(hi > lo, (hi - lo) / bins, 1.0)
    idx = np.clip(np.floor((x - lo) / width).astype(np.int64), 0, bins - 1)
    cells, inverse = np.unique(idx, axis=0, return_inverse=True)
    mass = np.zeros(len(cells))
    np.add.at(mass, inverse.ravel(), weights)
    return np.asarray(lo + (cells[int(np.argmax(mass))] + 0.5) * width)


def laplace_approximation(
    log_posterior: Any, x_map: FloatArray, scale: FloatArray
) -> dict[str, Any]:
    """Gaussian N(x_MAP, (-H)^-1) from a central finite-difference Hessian H of the
    log-posterior at the MAP (Paper B, Fig. 9a/c), steps 1e-3 of the posterior std."""
    d = len(x_map)
    h = 1e-3 * np.sqrt(np.maximum(np.diag(np.atleast_2d(scale)), 1e-300))
    pts = [x_map]
    for i in range(d):
        for j in range(d):
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                z = x_map.copy()
                z[i] += si * h[i]
                z[j] += sj * h[j]
                pts.append(z)
    vals = log_posterior(np.array(pts))
    hess = np.empty((d, d))
    k = 1
    for i in range(d):
        for j in range(d):
            fpp, fpm, fmp, fmm = vals[k : k + 4]
            hess[i, j] = (fpp - fpm - fmp + fmm) / (4 * h[i] * h[j])
            k += 4
    hess = 0.5 * (hess + hess.T)
    eig = np.linalg.eigvalsh(-hess)
    ok = bool(np.all(eig > 0) and np.all(np.isfinite(vals)))
    return {
        "mean": x_map,
        "hessian": hess,
        "cov": np.linalg.inv(-hess) if ok else None,
        "negative_definite": ok,
    }


def hpd_mass(result: Result, point: Mapping[str, float]) -> float:
    """Posterior mass of the highest-posterior-density region whose boundary passes through
    ``point`` (0: the point is the mode; near 1: it lies outside the bulk of the posterior).

    The log-posterior at ``point`` comes from the GP surrogate and the priors; the region's
    mass from the weighted particles. Defined for results without uncertain parameters.
    """
    info = result.info
    if "gp_state" not in info or len(info["names"]) != int(info["n_x"]):
        raise ConfigError(
            "hpd_mass needs a surrogate-mode result without uncertain parameters", "hpd_mass"
        )
    names = list(info["names"])
    missing = [n for n in names if n not in point]
    if missing:
        raise ConfigError(f"no value for {', '.join(missing)}", "hpd_mass")
    z = np.array([[float(point[n]) for n in names]])
    gp = GpSurrogate.from_state(info["gp_state"])
    log_prior = sum(
        float(Prior.from_spec(p["prior"]).logpdf(z[0, j])) for j, p in enumerate(info["priors"])
    )
    level = float(gp.predict_mean(z)[0]) + log_prior
    log_post = np.asarray(info["log_likelihood"]) + np.asarray(info["log_prior"])
    return float(np.sum(np.asarray(info["weights"])[log_post > level]))


# -- files that other tools read ------------------------------------------------------------------
def save_posterior(result: Result, folder: str | Path) -> tuple[Path, Path]:
    """Write ``posterior.npz`` (arrays) and ``posterior.json`` (description) into ``folder``.

    posterior.npz (format ``fbia-posterior-1``):

    ``names`` (d,) str: x names then theta names; ``n_x``: number of calibration parameters;
    ``particles`` (N, d) float; ``weights`` (N,) normalised; ``log_likelihood`` (N,) the
    (surrogate) L of eq. 5; ``log_prior`` (N,); ``log_posterior`` (N,) = L + log p
    (unnormalised); ``theta`` (N, d - n_x) the uncertain parameters; ``design`` (n, d) the
    Sobol design; ``design_log_likelihood`` (n,) L of each run (-inf: failed);
    ``design_ok`` (n,) bool; ``train_mask`` (n,) bool (False: held-out test point).

    posterior.json: format, names, units, priors, point estimates, log-evidence, GP
    hyperparameters and errors, SMC history. :func:`load_posterior` reads both back;
    :func:`to_inference_data` turns them into an ``arviz.InferenceData`` if arviz is installed.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    info = result.info
    names = list(info["names"])
    n_x = int(info["n_x"])
    particles = np.asarray(info["particles"])
    arrays: dict[str, Any] = {
        "format": np.array(POSTERIOR_FORMAT),
        "names": np.array(names),
        "n_x": np.array(n_x),
        "particles": particles,
        "weights": np.asarray(info["weights"]),
        "log_likelihood": np.asarray(info["log_likelihood"]),
        "log_prior": np.asarray(info["log_prior"]),
        "log_posterior": np.asarray(info["log_likelihood"]) + np.asarray(info["log_prior"]),
        "theta": particles[:, n_x:],
    }
    if "design" in info:
        arrays.update(
            design=np.asarray(info["design"]),
            design_log_likelihood=np.asarray(info["design_log_likelihood"]),
            design_ok=np.isfinite(np.asarray(info["design_log_likelihood"])),
            train_mask=np.asarray(info["train_mask"]),
        )
    npz = folder / "posterior.npz"
    np.savez_compressed(npz, **arrays)
    skip = {
        "particles",
        "weights",
        "log_likelihood",
        "log_prior",
        "design",
        "design_log_likelihood",
        "design_status",
        "train_mask",
        "gp_state",
    }
    from ..core.problem import _jsonable

    meta = {
        "format": POSTERIOR_FORMAT,
        "arrays": "posterior.npz",
        "status": result.status,
        "message": result.message,
        "x_map": result.x,
        **{k: v for k, v in info.items() if k not in skip},
    }
    js = folder / "posterior.json"
    js.write_text(json.dumps(_jsonable(meta), indent=1, default=str))
    return npz, js


def load_posterior(folder: str | Path) -> dict[str, Any]:
    """Read :func:`save_posterior`'s files: the npz arrays plus ``"meta"`` (the JSON)."""
    folder = Path(folder)
    with np.load(folder / "posterior.npz") as data:
        out: dict[str, Any] = {k: data[k] for k in data.files}
    if str(out.get("format")) != POSTERIOR_FORMAT:
        raise ConfigError(f"not an {POSTERIOR_FORMAT} file", str(folder / "posterior.npz"))
    out["names"] = [str(n) for n in out["names"]]
    out["meta"] = json.loads((folder / "posterior.json").read_text())
    return out


def to_inference_data(posterior: Mapping[str, Any], n_draws: int | None = None, seed: int = 0):
    """An ``arviz.InferenceData`` of equally weighted draws (systematic resampling) of a
    :func:`load_posterior` result, with log_likelihood and log_prior groups."""
    try:
        with warnings.catch_warnings():  # arviz 0.2x announces its refactor on import
            warnings.simplefilter("ignore", FutureWarning)
            import arviz
    except ImportError:
        raise ConfigError(
            "arviz is not installed (pip install arviz)", "to_inference_data"
        ) from None
    from .smc import systematic_resample

    w = np.asarray(posterior["weights"])
    rng = np.random.default_rng(seed)
    idx = systematic_resample(w, rng)
    if n_draws is not None:
        idx = idx[rng.permutation(len(idx))[:n_draws]]
    parts = np.asarray(posterior["particles"])[idx]
    return arviz.from_dict(
        posterior={n: parts[None, :, j] for j, n in enumerate(posterior["names"])},
        log_likelihood={"L": np.asarray(posterior["log_likelihood"])[idx][None]},
        prior={"log_prior": np.asarray(posterior["log_prior"])[idx][None]},
    )
