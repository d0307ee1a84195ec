"""The rounds of ``gp_smc``'s adaptive design (the numerics are in :mod:`.adaptive`).

A Sobol start of ``n_initial`` runs (+ ``n_test`` held-out points), then per round: GP on
the runs so far (L with a soft floor; its hyperparameters optimised again only when the
design has grown by :data:`REOPTIMISE_GROWTH`, else kept and the GP conditioned on the new
runs) -> has the design converged? -> SMC on the GP mean (``round_particles``, a coarse
tempering that keeps its particles at gamma = 1/4 on the way) -> a batch of runs (posterior
draws, draws of the tempered posterior exp(mu / 4) p, the EIV rule) through the evaluator in
one call (parallel workers) -> the surrogate's error at the posterior draws, predicted
before they are used.

**Converged** means what the user gets stopped changing: the last round's posterior,
reweighted on its own particles from the surrogate that chose the batch to the one refitted
with it (:func:`~.adaptive.posterior_change`: no Monte Carlo noise between two SMC runs to
mistake for a change), moved no mean or 5/50/95 % quantile by ``adaptive_tol`` posterior std,
no std by a factor 1 + ``adaptive_tol`` and log Z by 0.5; the surrogate's error at the
batch's posterior draws, without its mean (:func:`~.adaptive.centred_rmse`: a constant
error cancels in the posterior), was below
:data:`~fbia.iterators.gp_smc.result.RELIABLE_RMSE`; and the posterior averaged over the
GP's sample paths does not differ from it (the GP must not be unsure where the posterior
ends). Otherwise the rounds go on until ``n_train`` runs are spent.
The last GP is always trained on every run; the final SMC (``n_particles``, ``zeta``, ...)
and the posterior check are the iterator's.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.iteration import Evaluator
from ...core.problem import Evaluation
from ..smc.sampler import SmcResult
from ..surrogates.design import sobol_design
from ..surrogates.feasibility import fit_feasibility
from ..surrogates.residuals import Surrogate
from ..surrogates.uncertainty import marginalise_surrogate_uncertainty
from .adaptive import (
    Moments,
    floor_depth,
    floored,
    posterior_change,
    select_batch,
    validation_error,
)
from .options import GpSmcOptions
from .result import RELIABLE_RMSE, AdaptiveDesign, AdaptiveRound
from .run import Design, GpSmcState, SmcRun, log_prior

logger = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: the rounds' SMC: a coarse tempering (its posterior only steers the design)
ROUND_ZETA = 0.9
ROUND_REJUVENATION = 5
ROUND_REJUVENATE = "after_resampling"
#: the rounds' check of the GP's sample paths: paths and distinct particles (the final check
#: takes 200 and 2000; the joint paths cost ~ points^3 per residual component)
ROUND_PATHS = 100
ROUND_POINTS = 1000
#: the tempering of the wide posterior exp(beta mu) p that a quarter of each batch is drawn
#: from (along a weakly identified direction it reaches 1 / sqrt(beta) = 2 times further):
#: the round's SMC keeps its particles at gamma = beta on its way to 1 (``keep_gamma``), so
#: they cost no second run (the factor of where the model runs, gp_feasibility, is tempered
#: with the mean there)
WIDE_TEMPERATURE = 0.25
#: the hyperparameters are optimised again when the design has grown by this factor since
#: they last were; in the rounds between, the surrogate keeps them and is only conditioned on
#: the new runs (hyperparameters change slowly with the data, and an evidence maximisation of
#: a residual emulator costs 20 GPs x tens of Cholesky factorisations)
REOPTIMISE_GROWTH = 1.5
#: fits the surrogate to (x, y) and the runs' records (a residual emulator uses their
#: residuals), warm-started from earlier hyperparameters when given, its kernel's axes along
#: the principal axes of a covariance when given (GpSurrogate.fit's axes), the
#: hyperparameters optimised (True) or kept and only conditioned on the runs (False)
FitGp = Callable[
    [
        FloatArray,
        FloatArray,
        Mapping[str, Any] | None,
        Sequence[Evaluation],
        FloatArray | None,
        bool,
    ],
    Surrogate,
]
#: SMC on a log-likelihood with a number of particles (the rounds' coarse settings), keeping
#: its particles at gamma = WIDE_TEMPERATURE (SmcResult.tempered)
Sample = Callable[[Callable[[FloatArray], FloatArray], int], SmcResult]


@dataclass
class AdaptiveOutcome:
    """What the rounds leave: every design run, the GP on all of them, the rounds."""

    design: Design
    gp: Surrogate | None  # None when fewer than 2 runs succeeded
    summary: AdaptiveDesign


def parallel_slots(evaluator: Evaluator) -> int:
    """Runs the evaluator makes at once (its ``slots``, :class:`fbia.core.iteration.Evaluator`),
    at least 1."""
    return max(1, int(evaluator.slots))


def batch_size(opts: GpSmcOptions, n_runs: int, slots: int) -> int:
    """The option, or a fifth of the runs so far, at least 4, a multiple of ``slots``."""
    if opts.batch_size:
        return opts.batch_size
    n = max(4, math.ceil(0.2 * n_runs))
    return slots * math.ceil(n / slots)


def adaptive_design(
    run: SmcRun, opts: GpSmcOptions, fit_gp: FitGp, sample: Sample
) -> Generator[GpSmcState, None, AdaptiveOutcome]:
    """The rounds (module docstring); yields a state per stage and round."""
    n_initial = opts.n_initial or 10 * len(run.inputs)
    n_initial = min(n_initial, opts.n_train)
    through_prior = opts.design_space == "prior"
    start = sobol_design(
        run.inputs, n_initial + opts.n_test, opts.seed, through_prior=through_prior
    )
    yield GpSmcState(
        "design",
        f"adaptive: {n_initial} Sobol start runs + {opts.n_test} test points, at most "
        f"{opts.n_train} runs",
        run.record("design", design="adaptive", n_initial=n_initial, n_test=opts.n_test),
    )
    evaluations, loglik = run.runs_at(start)
    train = np.arange(len(start)) < n_initial
    design = Design(start, loglik, train, tuple(evaluations))
    yield GpSmcState(
        "forward_runs",
        f"{len(evaluations)} forward runs, {run.n_failed} failed",
        run.record("forward_runs", nfev=len(evaluations), n_failed=run.n_failed),
    )
    slots = parallel_slots(run.evaluator)
    rng = np.random.default_rng([opts.seed, 3])
    rounds: list[AdaptiveRound] = []
    hyper: Mapping[str, Any] | None = None
    log_z: float | None = None
    gp: Surrogate | None = None
    floor = -math.inf
    axes: FloatArray | None = None  # gp_axes = "posterior": the last round's covariance
    optimised_at = 0  # design runs when the hyperparameters were last optimised
    last: tuple[SmcResult, float] | None = None  # the last round's posterior, its check
    while True:
        t0 = time.perf_counter()
        train, loglik = design.train_mask, design.log_likelihood
        use = train & design.ok
        if use.sum() < 2:
            summary = AdaptiveDesign(n_initial, rounds, "failed", floor)
            return AdaptiveOutcome(design, None, summary)
        l_max = float(loglik[use].max())
        floor = l_max - floor_depth(l_max, log_z)
        # a failed design run counts as an unlikely point (at the floor): the models fail at
        # extreme parameters, and the criterion must not send batch after batch there
        y = floored(loglik, floor)
        n_design = int(train.sum())
        optimise = hyper is None or n_design >= REOPTIMISE_GROWTH * optimised_at
        points = design.points[train]
        gp = fit_gp(points, y[train], hyper, design.training_records, axes, optimise)
        optimised_at = n_design if optimise else optimised_at
        if opts.failures == "classify":
            gp.feasibility = fit_feasibility(points, design.ok[train])
        target = gp.feasible(gp.predict_mean_guarded)
        change = None
        if last is not None:
            # what the last batch did to the last round's posterior, on its own particles
            reweighted, change = posterior_change(last[0], target)
            converged = change.settled(opts.adaptive_tol) and last[1] < RELIABLE_RMSE
            if converged and run.noise is None and opts.uncertainty_check:
                # and the GP's own uncertainty does not move the posterior either (the
                # final status's check; with sigma_N inferred the GP models its profile)
                converged = not _gp_unsure(gp, reweighted, run, opts, rng)
            logger.info(
                "design check on %d runs: the last posterior moved %.3g std (quantiles "
                "%.3g), std changed %.3g, surrogate error %.3g in L at its draws: %s",
                n_design,
                change.mean_shift,
                change.quantile_shift,
                change.std_change,
                last[1],
                "converged" if converged else f"not settled (tolerance {opts.adaptive_tol:g})",
            )
            if converged:
                reason = "converged"
                break
        if n_design >= opts.n_train:
            logger.info("design stops at its budget: %d runs (n_train)", n_design)
            reason = "budget"
            break
        post = sample(target, opts.round_particles)
        log_z = post.log_evidence
        moments = Moments.of(post)
        n_batch = min(batch_size(opts, n_design, slots), opts.n_train - n_design)
        wide = post.tempered  # the round's SMC passed through exp(mu / 4) p on its way
        batch, n_draws = select_batch(
            gp, post, n_batch, run.inputs, lambda z: log_prior(run.inputs, z), rng, wide
        )
        logger.debug(
            "design round %d: %d runs in the batch (%d posterior draws, the rest by "
            "variance), floor of L %.6g, hyperparameters %s",
            len(rounds) + 1,
            len(batch),
            n_draws,
            floor,
            "optimised" if optimise else "kept",
        )
        new, new_loglik = run.runs_at(batch)
        check = validation_error(gp, batch[:n_draws], new_loglik[:n_draws])
        design = design.extended(batch, new_loglik, new)
        last = (post, check.centred if check.n >= 2 else math.inf)
        entry = AdaptiveRound(
            round=len(rounds) + 1,
            n_runs=n_design,
            n_batch=len(batch),
            mean=moments.mean,
            std=moments.std,
            mean_shift=math.inf if change is None else change.mean_shift,
            std_change=math.inf if change is None else change.std_change,
            validation_rmse=check.rmse,
            log_evidence=log_z,
            evidence_change=math.inf if change is None else change.evidence_change,
            floor=floor,
            seconds=time.perf_counter() - t0,
            validation_centred=check.centred,
            validation_z=check.z_rms,
            quantile_shift=math.inf if change is None else change.quantile_shift,
            ess_fraction=math.nan if change is None else change.ess_fraction,
            optimised=optimise,
        )
        rounds.append(entry)
        hyper = gp.hyperparameters()
        if opts.gp_axes == "posterior":
            axes = np.atleast_2d(post.cov)
        yield GpSmcState("round", entry.describe(), run.record("round", **entry.to_record()))
    summary = AdaptiveDesign(n_initial, rounds, reason, floor, change)
    return AdaptiveOutcome(design, gp, summary)


def _gp_unsure(
    gp: Surrogate, post: SmcResult, run: SmcRun, opts: GpSmcOptions, rng: np.random.Generator
) -> bool:
    """Whether the posterior averaged over the GP's sample paths differs from the round's
    (gp_smc's uncertainty check, on the round's coarse posterior)."""
    _, uncertainty = marginalise_surrogate_uncertainty(
        post,
        gp,
        run.priors,
        rng,
        n_paths=ROUND_PATHS,
        n_points=ROUND_POINTS,
        smc_options={
            "n_particles": opts.round_particles,
            "zeta": ROUND_ZETA,
            "n_rejuvenation": ROUND_REJUVENATION,
            "rejuvenate": ROUND_REJUVENATE,
        },
    )
    return uncertainty.moves_posterior
