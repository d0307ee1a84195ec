"""Bayesian calibration with a GP surrogate of the log-likelihood and adaptive SMC (Paper B).

::

    import fbia
    it = fbia.iterator("gp_smc", n_train=200, n_particles=5000, n_rejuvenation=20,
                       zeta=0.995, seed=0)   # adaptive design, at most 200 forward runs
    result = it.run(problem)                  # problem.noise_std = sigma_N [mm] (eq. 5)
    print(result.summary())                   # MAP, posterior mean, std
    it.write_plots(result, problem, "output")     # Paper B Figs. 5-9, 13-15
    fbia.iterators.gp_smc.posterior.save_posterior(result, "output")  # posterior.npz + .json

The stages (each yields a :class:`GpSmcState`; ``steps()`` returns the typed
:class:`~fbia.iterators.gp_smc.result.GpSmcResult`; posterior statistics and files are in
:mod:`fbia.iterators.gp_smc.posterior`):

1. **Design**: ``design = "adaptive"`` (default; :mod:`fbia.iterators.gp_smc.adaptive_loop`):
   ``n_initial`` Sobol runs, then rounds of GP -> SMC on the surrogate -> a batch of runs
   at posterior draws and where they reduce the posterior's uncertainty most
   (:mod:`fbia.iterators.gp_smc.adaptive`), one evaluator call per batch, until the posterior
   and the evidence stop changing and the surrogate is right at new posterior draws, or
   ``n_train`` runs are spent (``result.adaptive`` has the rounds). ``design = "sobol"``
   (Paper B): the first ``n_train`` (+ ``n_test`` held-out) points of a scrambled, seeded
   Sobol sequence in the box of the calibration parameters x and the uncertain parameters
   theta (bounds; a theta without finite bounds, or every input with
   ``design_space="prior"`` (Remark 7), goes through its prior's inverse CDF). A larger
   ``n_train`` with the same seed extends the design by the next points of the same
   sequence, and :meth:`GpSmcIterator.reuse` keeps an earlier result's runs so only the new
   points run (``Result.evaluations`` holds the runs of this run, ``result.design`` every
   design point with its status). Failed runs are excluded from training (the adaptive design
   keeps them at its floor) and kept in the result (``Result.evaluations``,
   ``result.design.status``); with
   ``failures = "classify"`` (default) a GP classifier of them multiplies the SMC target by
   min(1, 2 P_ok), so the posterior stays where the forward model runs
   (:mod:`fbia.iterators.surrogates.feasibility`).
2. **Likelihood** (eq. 4-5): per observation k with noise sigma_k (``Observation.noise_std``,
   else ``problem.noise_std``), L = sum_k [-n_k/2 log(2 pi sigma_k^2) - D_k^2 / (2 sigma_k^2)],
   n_k the number of individual measurements (the residual count of the measure; 1 for rkhs).
3. **Surrogate** of L, its leave-one-out error and the error at the held-out Sobol points
   (Fig. 12); inside SMC its mean is capped a little above the best training value
   (extrapolation guard). ``surrogate = "auto"`` (default) emulates the measure's residual
   vectors with GPs of their principal components and computes L from the emulated
   residuals (:mod:`fbia.iterators.surrogates.residuals`): the residuals are smooth in the
   parameters where L is a thin ridge, so far fewer runs give the same accuracy (2-D under
   the uncertain inflow: 52-100 runs instead of not converging within 100; 6 + 1-D:
   221-264 runs). Where residuals cannot give L (observations with different sigma_N, a distance
   that is not the norm of residual vectors of one length) it falls back to Paper B's GP of
   L (:mod:`fbia.iterators.surrogates.gp`, eq. 26-29, Remarks 9-10) and says so;
   ``surrogate = "log_likelihood"`` always uses that GP (to reproduce the paper).
   ``mode="direct"`` skips the surrogate and runs the forward model inside SMC (cheap models;
   every SMC batch goes to the evaluator, failed runs count as zero likelihood; the records
   are ``Result.evaluations``, as every run of every iterator).
4. **SMC** (:mod:`fbia.iterators.smc.sampler`, Algorithm 1) on exp(gamma L(x, theta)) p(x) p(theta).
   The posterior under uncertainty q(x | Y) (eq. 3b) is the theta-marginal of the particles.
5. **Summaries**: MAP (best particle of the last step when there is no theta; the heaviest bin
   of a weighted histogram with ``map_bins`` intervals per x when theta is marginalised,
   Remark 8, with the share of resamplings of the particles that keep each interval: below
   90 % the message and ``undetermined()`` say it is not determined), maximum likelihood,
   posterior mean and covariance (the global Gaussian approximation), the Laplace
   approximation at the MAP (finite-difference Hessian on the surrogate), 1-D credible
   intervals.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Generator, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ...core.iteration import Evaluator, IteratorBase
from ...core.parameters import Parameter
from ...core.problem import Evaluation, InverseProblem, Result
from ...execution.resources import check_memory
from ..smc.sampler import SequentialMonteCarlo, SmcResult, SmcState
from ..smc.table import table_note, table_points
from ..surrogates.design import finite_bounds, sobol_design
from ..surrogates.feasibility import feasibility_note, feasibility_summary, fit_feasibility
from ..surrogates.gp import GpSurrogate
from ..surrogates.residuals import ResidualSurrogate, Surrogate, residual_link, tangent_runs
from ..surrogates.uncertainty import SurrogateUncertainty, marginalise_surrogate_uncertainty
from ..tangents import TangentProblem
from .adaptive import floored, soft_floor
from .adaptive_loop import (
    ROUND_REJUVENATE,
    ROUND_REJUVENATION,
    ROUND_ZETA,
    WIDE_TEMPERATURE,
    adaptive_design,
)
from .check import posterior_check, repair_note, repairable, room_for_repair
from .model_check import model_check
from .options import GpSmcOptions
from .posterior import summarise, write_posterior_files
from .result import (
    MAP_RESAMPLINGS,
    MAP_SUPPORT,
    AdaptiveDesign,
    GpSmcResult,
    ParticlePosterior,
    SmcSummary,
    SurrogateFit,
)
from .run import Checked, Design, Fitted, GpSmcState, SmcRun, log_prior, run_status

FloatArray = NDArray[np.float64]


class GpSmcIterator(IteratorBase):
    """Bayesian calibration under uncertainty: Sobol design, GP surrogate of L, SMC (Paper B).

    See the module docstring for the stages; the options are below.
    """

    #: the extra it needs (fbia.core.extras)
    requires = ("GPy", "numba")

    #: the class of its results (fbia.load_result reads them back as it)
    result_type = GpSmcResult

    Options = GpSmcOptions

    options: GpSmcOptions

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        """Options of a cheap instance (conformance tests, smoke runs)."""
        return {"n_train": 16, "n_particles": 200, "n_rejuvenation": 2, "zeta": 0.8, "seed": 0}

    # -- the algorithm ----------------------------------------------------------------------
    def _check_memory(self, n_x: int) -> None:
        """Refuse sizes the machine cannot hold, before any run: the GP's kernel matrices
        (a few n^2 doubles), the cross-covariance of n_particles with the design and the
        particle arrays."""
        o = self.options
        n = o.n_train + o.n_test
        need = 8.0 * (4.0 * n * n + o.n_particles * n + 30.0 * o.n_particles * (n_x + 1))
        check_memory(
            need,
            f"n_train = {o.n_train}, n_particles = {o.n_particles}",
            "gp_smc options",
            "lower n_train or n_particles",
        )

    def steps(
        self, problem: InverseProblem, evaluator: Evaluator
    ) -> Generator[GpSmcState, None, GpSmcResult]:
        """The stages (module docstring), each over the typed values the last one returned:
        the surrogate on its design (surrogate mode), the posterior with its checks and
        repairs, the result."""
        run = self._run(problem, evaluator)
        fitted: Fitted | None = None
        if self.options.mode == "surrogate":
            outcome = yield from self._surrogate(run)
            if isinstance(outcome, GpSmcResult):  # fewer than 2 runs succeeded
                return outcome
            fitted = outcome
        checked = yield from self._checked_posterior(run, fitted)
        return self._result(run, checked)

    def _run(self, problem: InverseProblem, evaluator: Evaluator) -> SmcRun:
        """What the stages share (:class:`~.run.SmcRun`), once the options that need the
        problem are checked and the sizes fit the machine."""
        opts = self.options
        inputs = self._inputs(problem)
        if opts.gradients == "tangents":
            problem = self._with_tangents(problem, inputs)
        run = SmcRun(problem, evaluator, inputs, time.perf_counter())
        if opts.surrogate_uncertainty != "none" and (opts.mode != "surrogate" or run.noise):
            raise ConfigError(
                "needs mode = 'surrogate' and a known sigma_N (noise_std, not noise_prior)",
                "surrogate_uncertainty",
            )
        if opts.gp_axes != "inputs" and (opts.mode != "surrogate" or opts.design != "adaptive"):
            raise ConfigError(
                "follows the posterior of an adaptive design's rounds: needs mode = "
                "'surrogate' and design = 'adaptive'",
                "gp_axes",
            )
        self._check_memory(run.n_x)
        return run

    def _surrogate(self, run: SmcRun) -> Generator[GpSmcState, None, Fitted | GpSmcResult]:
        """Stages 1-3: the design (Sobol or adaptive) and its runs, the surrogate on them and
        its errors; the ``all_failed`` result when fewer than 2 runs succeeded."""
        opts = self.options
        adaptive: AdaptiveDesign | None = None
        if opts.design == "sobol":
            design = yield from self._design_stage(run)
            use = design.train_mask & design.ok
            gp = (
                None
                if use.sum() < 2
                else self._fit_gp(
                    run,
                    design.points[use],
                    design.log_likelihood[use],
                    None,
                    [design.records[i] for i in np.flatnonzero(use)],
                )
            )
            if gp is not None and opts.failures == "classify":
                train = design.train_mask
                gp.feasibility = fit_feasibility(design.points[train], design.ok[train])
        else:
            outcome = yield from adaptive_design(
                run,
                opts,
                lambda x, y, s, recs, axes, opt: self._fit_gp(run, x, y, s, recs, axes, opt),
                lambda ll, n: self._round_smc(run, ll, n),
            )
            design, gp, adaptive = outcome.design, outcome.gp, outcome.summary
        if gp is None:
            return self._finish_failed(run, design)
        floor = None if adaptive is None else adaptive.floor
        fit = yield from self._surrogate_stage(run, design, gp, floor)
        return Fitted(design, gp, fit, adaptive)

    def _checked_posterior(
        self, run: SmcRun, fitted: Fitted | None
    ) -> Generator[GpSmcState, None, Checked]:
        """Stage 4 and the checks: SMC on the surrogate (or the forward model), the check at
        posterior draws and the GP's sample paths, and the repairs of a failed one (their
        runs join the design, the surrogate is refitted, SMC again: :mod:`.check`)."""
        opts = self.options
        post = yield from self._smc_stage(run, self._target(run, fitted), _trained(run, fitted))
        check, failed = None, list[float]()
        wanted = opts.surrogate_uncertainty == "expected_posterior"
        uncertain = fitted is not None and run.noise is None and (wanted or opts.uncertainty_check)
        expected, uncertainty = post, None
        while fitted is not None and opts.n_check:
            design, gp, adaptive = fitted.design, fitted.gp, fitted.adaptive
            rng = np.random.default_rng([opts.seed, 2, *([len(failed)] if failed else [])])
            checked = yield from posterior_check(run, post, gp, opts.n_check, rng)
            check = checked.check
            budget, limit = opts.n_train, opts.check_repairs
            repair = checked
            if check.reliable and uncertain:
                expected, uncertainty = self._uncertainty(run, post, gp)
                room = room_for_repair(
                    design, adaptive is not None, budget, opts.n_check, len(failed), limit
                )
                if uncertainty.moves_posterior and opts.uncertainty_check and room:
                    # the GP's sample paths put posterior mass where no run has been: runs at
                    # draws of that averaged posterior say whether it is there
                    repair = yield from posterior_check(run, expected, gp, opts.n_check, rng)
                    repair = replace(repair, check=replace(repair.check, cause="uncertainty"))
            if repair is checked and check.reliable:
                break
            if not repairable(
                repair.check, design, adaptive is not None, budget, len(failed), limit
            ):
                break
            # the runs join the design (their own records) and train the surrogate
            failed.append(repair.check.centred_rmse)
            design = repair.repaired(design)
            assert adaptive is not None  # repairable: only an adaptive design
            gp = self._refit(run, design, gp, post, adaptive.floor)
            fit = yield from self._surrogate_stage(run, design, gp, adaptive.floor)
            fitted = Fitted(design, gp, fit, adaptive)
            post = yield from self._smc_stage(run, self._target(run, fitted), _trained(run, fitted))
            expected, uncertainty = post, None
        if uncertain and uncertainty is None:
            assert fitted is not None
            expected, uncertainty = self._uncertainty(run, post, fitted.gp)
        return Checked(fitted, post, expected if wanted else post, check, failed, uncertainty)

    @staticmethod
    def _target(run: SmcRun, fitted: Fitted | None) -> Callable[[FloatArray], FloatArray]:
        """The SMC target: L (or its profile over sigma_N) where the forward model runs, from
        the surrogate's mean or from forward runs (mode = "direct")."""
        if fitted is None:
            return run.joint(run.forward_log_likelihood)
        gp = fitted.gp
        return gp.feasible(run.joint(gp.predict_mean_guarded, fitted.design.records))

    def _result(self, run: SmcRun, checked: Checked) -> GpSmcResult:
        """Stage 5: the posterior's summaries, the status from the checks and the model
        check, the message saying why."""
        opts = self.options
        fitted, post, particles = checked.fitted, checked.post, checked.particles
        gp = None if fitted is None else fitted.gp
        adaptive = None if fitted is None else fitted.adaptive
        check, uncertainty = checked.check, checked.uncertainty
        wanted = opts.surrogate_uncertainty == "expected_posterior"
        laplace = opts.laplace and opts.mode == "surrogate" and not wanted
        target = self._target(run, fitted)
        posterior = summarise(
            particles,
            run.n_x,
            run.sampled,
            opts.map_bins,
            (lambda z: target(z) + log_prior(run.sampled, z)) if laplace else None,
            opts.seed,
        )
        status = run_status(opts.mode, check, uncertainty)
        tabled, coarse = table_note(post.table, opts.smc_table_tol)
        status = "unreliable" if coarse else status
        # can the model and the prior explain the data at all (gp_smc/model_check.py)
        n_in = len(run.inputs)
        reused = [] if fitted is None else fitted.design.records[: fitted.design.reused]
        model = model_check(
            run.problem,
            run.inputs,
            particles.particles[:, :n_in],
            particles.weights,
            [*reused, *run.runs],
        )
        status = "unreliable" if model.causes and status == "completed" else status
        return GpSmcResult(
            status=status,
            success=status == "completed",
            message=(
                "".join(f"{cause} - " for cause in model.causes)
                + f"posterior from {opts.n_particles} particles in {post.n_steps} tempering "
                f"steps ({opts.mode}; {run.nfev} forward runs, {run.n_failed} failed)"
                + ("" if gp is None or not gp.note else f"; {gp.note}")
                + ("" if adaptive is None else adaptive.note())
                + ("" if check is None else check.note())
                + repair_note(checked.failed)
                + _noise_note(run, posterior)
                + _map_note(posterior)
                + ("" if gp is None else _extrapolation_note(post, gp))
                + ("" if gp is None else feasibility_note(gp.feasibility))
                + ("" if uncertainty is None or not wanted else "; " + uncertainty.note())
                + ("" if uncertainty is None else uncertainty.reliability_note())
                + tabled
                + (
                    "; the surrogate was not checked at posterior draws (n_check = 0): "
                    "nothing says whether this posterior is right"
                    if status == "unchecked"
                    else ""
                )
            ),
            x=dict(zip(run.problem.names, map(float, posterior.map), strict=True)),
            history=run.history,
            names=run.sampled_names,
            n_x=run.n_x,
            mode=opts.mode,
            priors=[p.describe() for p in run.sampled],
            design=None if fitted is None else fitted.design.result(),
            adaptive=adaptive,
            surrogate=None if fitted is None else fitted.fit,
            check=check,
            failed_checks=checked.failed,
            uncertainty=uncertainty,
            posterior=posterior,
            model_check=model,
            smc=SmcSummary(
                n_steps=post.n_steps,
                gammas=list(post.gammas),
                ess=list(post.ess),
                acceptance=list(post.acceptance),
                nfev_log_likelihood=post.nfev,
                final_ess=float(post.final_ess),
                rejuvenate=opts.rejuvenate,
                steps_with_moves=sum(h["moved"] for h in post.history),
                table=post.table,
            ),
            seconds=time.perf_counter() - run.t_start,
        )

    def _uncertainty(
        self, run: SmcRun, post: SmcResult, gp: Surrogate
    ) -> tuple[SmcResult, SurrogateUncertainty]:
        """The posterior averaged over the GP's sample paths and how it differs from ``post``
        (:mod:`fbia.iterators.surrogates.uncertainty`)."""
        return marginalise_surrogate_uncertainty(
            post,
            gp,
            run.sampled_priors,
            np.random.default_rng([self.options.seed, 5]),
            smc_options=self._smc_settings(len(run.sampled_priors)),
        )

    def write_files(self, result: Result, folder: Path) -> list[Path]:
        """The posterior's files
        (:func:`~fbia.iterators.gp_smc.posterior.write_posterior_files`)."""
        return write_posterior_files(result, folder, self.options.seed)

    def _with_tangents(self, problem: InverseProblem, inputs: list[Parameter]) -> InverseProblem:
        """``problem`` whose runs also give J = dr/dz for every input (gradients =
        "tangents": pseudo-runs of the residual emulator)."""
        opts = self.options
        if opts.mode != "surrogate" or opts.surrogate == "log_likelihood":
            raise ConfigError(
                "trains the residual emulator: needs mode = 'surrogate' and surrogate = "
                "'residuals' or 'auto'",
                "gradients",
            )
        names = [p.name for p in inputs]
        return TangentProblem.of(problem, names, "gradients", "gradients = 'off'")

    def _inputs(self, problem: InverseProblem) -> list[Parameter]:
        """x then theta; each needs a prior, and x finite bounds for the box design."""
        inputs = [*problem.parameters, *problem.uncertain]
        for p in inputs:
            if p.prior is None:
                raise ConfigError("needs a prior distribution", p.name)
            if (
                not finite_bounds(p)
                and self.options.design_space == "box"
                and p in problem.parameters
            ):
                raise ConfigError(
                    "a calibration parameter needs finite bounds for the Sobol design "
                    "(or design = 'prior')",
                    p.name,
                )
        return inputs

    def _design_stage(self, run: SmcRun) -> Generator[GpSmcState, None, Design]:
        """Stages 1-2: the Sobol design (reusing an earlier result's runs) and its runs."""
        opts = self.options
        n_all = opts.n_train + opts.n_test
        points = sobol_design(
            run.inputs, n_all, opts.seed, through_prior=opts.design_space == "prior"
        )
        yield GpSmcState(
            "design",
            f"{opts.n_train} training + {opts.n_test} test points (Sobol, seed {opts.seed})",
            run.record("design", n_train=opts.n_train, n_test=opts.n_test),
        )
        reused = self._reusable(points, run.names)
        new = run.evaluate(points[len(reused) :])
        loglik = run.log_likelihoods([*reused, *new])
        n_failed = int((~np.isfinite(loglik[len(reused) :])).sum())
        yield GpSmcState(
            "forward_runs",
            f"{len(new)} forward runs ({len(reused)} reused), {n_failed} failed",
            run.record("forward_runs", nfev=len(new), n_failed=n_failed, reused=len(reused)),
        )
        return Design(points, loglik, np.arange(n_all) < opts.n_train, (*reused, *new), len(reused))

    def _fit_gp(
        self,
        run: SmcRun,
        x: FloatArray,
        y: FloatArray,
        start: Mapping[str, Any] | None,
        records: Sequence[Evaluation],
        axes: FloatArray | None = None,
        optimise: bool = True,
    ) -> Surrogate:
        """The surrogate on the runs ``records`` at ``x`` (``y``: what a GP of L is trained
        on): the residual emulator (option ``surrogate``) or the GP of eq. 26-29; ``start``:
        earlier hyperparameters (a round of the adaptive design), which then also take one
        restart instead of ``gp_restarts`` (the residual emulator's components none);
        ``axes``: a covariance whose principal axes the kernel follows (option
        ``gp_axes``); ``optimise = False``: keep ``start`` and only condition on the runs."""
        opts = self.options
        # a warm start (a round of the adaptive design) takes one restart for the GP of L and
        # none for the residual emulator's components (up to 20 GPs, each warm from its own)
        restarts = opts.gp_restarts if start is None else min(1, opts.gp_restarts)
        warm = start if start and "components" in start else None  # a residual emulator's
        rng = np.random.default_rng(opts.seed if opts.gp_seed is None else opts.gp_seed)
        link, note = None, ""
        if opts.surrogate != "log_likelihood":
            sigmas = None if run.noise is not None else run.sigmas
            link, residuals, why = residual_link(records, sigmas, run.noise_n(records))
            if link is None and opts.surrogate == "residuals":
                raise ConfigError(f"the residual emulator cannot give L: {why}", "surrogate")
            note = "" if link else f"GP of L (residuals not usable: {why})"
            if link is None and opts.gradients == "tangents":
                note += "; the runs' tangents unused (no residual emulator)"
        if link is not None:
            if opts.gradients == "tangents":
                x, residuals = tangent_runs(x, residuals, records)
            return ResidualSurrogate(
                link,
                ard=opts.ard,
                optimizer=opts.gp_optimizer,
                restarts=0 if warm else opts.gp_restarts,
                subset=opts.gp_subset,
                polish_iters=opts.gp_polish_iters,
            ).fit(x, residuals, rng=rng, start=warm, axes=axes, optimise=optimise or not warm)
        gp_start = None if warm else start  # a residual emulator's hyperparameters fit no GP of L
        gp = GpSurrogate(
            ard=opts.ard,
            optimizer=opts.gp_optimizer,
            restarts=restarts,
            nugget_factor=opts.nugget_factor,
            mean_offset=opts.mean_offset,
            subset=opts.gp_subset,
            polish_iters=opts.gp_polish_iters,
            trend=opts.gp_trend,
        ).fit(x, y, rng=rng, start=gp_start, axes=axes, optimise=optimise or not gp_start)
        gp.note = note
        return gp

    def _refit(
        self, run: SmcRun, design: Design, gp: Surrogate, post: SmcResult, floor: float
    ) -> Surrogate:
        """The surrogate on every training run of ``design``, from ``gp``'s hyperparameters
        (a repaired check, :mod:`.check`); its kernel along ``post``'s axes with gp_axes =
        "posterior", the feasibility classifier refitted with failures = "classify"."""
        train = design.train_mask
        records = design.training_records
        axes = np.atleast_2d(post.cov) if self.options.gp_axes == "posterior" else None
        y = floored(design.log_likelihood, floor)
        # a repair adds n_check runs: the hyperparameters stay, the surrogate is conditioned
        new = self._fit_gp(
            run, design.points[train], y[train], gp.hyperparameters(), records, axes, False
        )
        if self.options.failures == "classify":
            new.feasibility = fit_feasibility(design.points[train], design.ok[train])
        return new

    def _round_smc(
        self, run: SmcRun, log_likelihood: Callable[[FloatArray], FloatArray], n_particles: int
    ) -> SmcResult:
        """A coarse SMC for a round of the adaptive design (its posterior only picks the next
        runs and tells whether the design has converged)."""
        opts = self.options
        return SequentialMonteCarlo(
            log_likelihood,
            run.priors,
            n_particles=n_particles,
            zeta=ROUND_ZETA,
            n_rejuvenation=ROUND_REJUVENATION,
            rejuvenate=ROUND_REJUVENATE,
            ess_min=opts.ess_min,
            rng=np.random.default_rng([opts.seed, 4]),
            max_steps=opts.max_smc_steps,
            keep_gamma=WIDE_TEMPERATURE,
            final_resample=False,  # its weighted particles steer the design, no file
        ).run()

    def _surrogate_stage(
        self, run: SmcRun, design: Design, gp: Surrogate, floor: float | None
    ) -> Generator[GpSmcState, None, SurrogateFit]:
        """Stage 3: the GP on the successful training runs, its LOO and held-out errors
        (against L with the adaptive design's soft ``floor``, which the GP was trained on)."""
        use = design.train_mask & design.ok
        quality: dict[str, Any] = dict(gp.loo())
        test = ~design.train_mask & design.ok
        if test.any():
            held_out = design.log_likelihood[test]
            if floor is not None:
                held_out = soft_floor(held_out, floor)
            quality.update(gp.test_error(design.points[test], held_out))
        best = int(np.argmax(np.where(use, design.log_likelihood, -np.inf)))
        fit = SurrogateFit(
            summary={**gp.describe(), **quality, **feasibility_summary(gp.feasibility)},
            state={
                **gp.state(),
                "feasibility": None if gp.feasibility is None else gp.feasibility.state(),
            },
            best_x=design.points[best],
            best_log_likelihood=float(design.log_likelihood[best]),
        ).attach(gp)
        yield GpSmcState(
            "surrogate",
            f"GP on {int(use.sum())} runs: LOO rel. error {quality['loo_relative_l2']:.3g}",
            run.record("surrogate", **{k: v for k, v in gp.describe().items()}, **quality),
        )
        return fit

    def _smc_settings(self, dim: int) -> dict[str, Any]:
        """The sampler's settings from the options (the final SMC and its tempered twin)."""
        opts = self.options
        return {
            "table_points": table_points(opts.smc_table, opts.rejuvenate, dim),
            "n_particles": opts.n_particles,
            "zeta": opts.zeta,
            "n_rejuvenation": opts.n_rejuvenation,
            "ess_min": opts.ess_min,
            "max_steps": opts.max_smc_steps,
            "rejuvenate": opts.rejuvenate,
        }

    def _smc_stage(
        self,
        run: SmcRun,
        log_likelihood: Callable[[FloatArray], FloatArray],
        training_range: tuple[float, float] | None,
    ) -> Generator[GpSmcState, None, SmcResult]:
        """Stage 4: adaptive tempered SMC (Algorithm 1) on exp(gamma L) p; the surrogate's
        training range goes into the message of a run that stalls."""
        sampler = SequentialMonteCarlo(
            log_likelihood,
            run.sampled_priors,
            rng=np.random.default_rng([self.options.seed, 1]),
            names=run.sampled_names,
            training_range=training_range,
            **self._smc_settings(len(run.sampled_priors)),
        )
        gen = sampler.steps()
        while True:
            try:
                state: SmcState = next(gen)
            except StopIteration as stop:
                post: SmcResult = stop.value
                break
            yield GpSmcState("smc", str(state), run.record("smc", **state.__dict__))
        return post

    def _finish_failed(self, run: SmcRun, design: Design) -> GpSmcResult:
        evaluations = design.records
        messages = sorted({ev.message for ev in evaluations if not ev.ok})[:3]
        n_bad = sum(not ev.ok for ev in evaluations)
        return GpSmcResult(
            status="all_failed",
            success=False,
            message=(
                f"{n_bad} of {len(evaluations)} forward runs failed: fewer than 2 training "
                f"points for the GP (e.g. {'; '.join(messages)})"
            ),
            history=run.history,
            names=run.names,
            n_x=run.n_x,
            mode=self.options.mode,
            priors=[p.describe() for p in run.inputs],
            design=design.result(),
            seconds=time.perf_counter() - run.t_start,
        )

    # -- extending an earlier study ------------------------------------------------------------
    def reuse(self, result: Result) -> GpSmcIterator:
        """Extend an earlier study: reuse the forward runs of ``result`` (same seed, design and
        inputs) and run only the new points of the same Sobol sequence (Paper B's n_train study).

        >>> # r200 = fbia.iterator("gp_smc", design="sobol", n_train=200).run(problem)
        >>> # r500 = fbia.iterator("gp_smc", design="sobol", n_train=500).reuse(r200).run(problem)

        Only for ``design = "sobol"``: an adaptive design picks its points from its own
        rounds (a study file's store reuses every run it already has either way).
        """
        if not isinstance(result, GpSmcResult) or result.design is None:
            raise ConfigError("can only reuse the result of a surrogate-mode gp_smc run", "reuse")
        if self.options.design != "sobol" or result.adaptive is not None:
            raise ConfigError(
                "reuse extends a fixed Sobol design: set design = 'sobol' for both runs", "reuse"
            )
        self._previous = result
        return self

    _previous: GpSmcResult | None = None

    def _reusable(self, design: FloatArray, names: list[str]) -> list[Evaluation]:
        """The leading evaluations of the reused result that match the new design's prefix."""
        prev = self._previous
        if prev is None:
            return []
        assert prev.design is not None
        old = prev.design.points
        if list(prev.names) != names:
            raise ConfigError(
                f"the reused result has inputs {prev.names}, this problem {names}", "reuse"
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

    # -- output ---------------------------------------------------------------------------------
    @staticmethod
    def write_plots(
        result: Result,
        problem: InverseProblem,
        folder: str | Path,
        figures: Sequence[str] | None = None,
    ) -> list[Path]:
        """Paper B's figures of a gp_smc result into ``folder`` (see :mod:`.plots`)."""
        from .plots import plot_gp_smc_result

        assert isinstance(result, GpSmcResult)
        return plot_gp_smc_result(result, problem, folder, figures)


def _noise_note(run: SmcRun, posterior: ParticlePosterior) -> str:
    """sigma_N's marginal posterior in the result message, when it was inferred."""
    if run.noise is None:
        return ""
    lo, mid, hi = posterior.credible_intervals[run.noise.name]
    return f"; sigma_N = {mid:.3g} mm (95 % interval {lo:.3g} .. {hi:.3g} mm, inferred)"


def _map_note(posterior: ParticlePosterior) -> str:
    """The inputs whose histogram MAP interval the particles do not decide (Remark 8's MAP
    under uncertain inputs: posterior.map_by_binning), in the result message."""
    loose = [f"{name} ({s * 100:.0f} %)" for name, s in posterior.undetermined_map().items()]
    if not loose:
        return ""
    return (
        f"; the histogram MAP is not determined in {', '.join(loose)}: the heaviest cell of a "
        f"resampling of the particles keeps its interval in fewer than "
        f"{MAP_SUPPORT * 100:.0f} % of {MAP_RESAMPLINGS} (the posterior is flat there at "
        "this resolution)"
    )


def _extrapolation_note(post: SmcResult, gp: Surrogate) -> str:
    """A warning when posterior mass sits where the GP mean was capped (above the largest
    training value + its margin: a surrogate artefact, not evidence)."""
    mass = gp.extrapolated_mass(post)
    if mass < 0.01:
        return ""
    return (
        f"; {mass:.0%} of the posterior lies where the surrogate extrapolates above its "
        "training values (capped there): add runs there, or check the result"
    )


def _trained(run: SmcRun, fitted: Fitted | None) -> tuple[float, float] | None:
    """The surrogate's training range of L for the SMC's messages (known sigma_N only)."""
    if fitted is None or run.noise is not None:
        return None
    return float(fitted.gp.y_train.min()), float(fitted.gp.y_train.max())
