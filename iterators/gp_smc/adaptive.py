"""Adaptive sequential design of the GP surrogate of L: where the next forward runs go.

``gp_smc`` with ``design = "adaptive"`` (the default) starts from a small Sobol design and
then repeats rounds of: GP on the runs so far -> SMC on the surrogate -> a batch of new
forward runs where they make the posterior most certain -> refit, until the posterior stops
changing and the surrogate is right at posterior draws (the loop is in
:mod:`fbia.iterators.gp_smc.adaptive_loop`; this module holds its numerics):

* **The batch** (:func:`select_batch`): half are distinct draws from the current surrogate
  posterior (they put runs where the posterior mass is, and before they are used for
  training they measure the surrogate's error there, :func:`validation_error`); a quarter
  are draws from the tempered surrogate posterior exp(mu / 4) p, which reaches twice as far
  along weakly identified directions (a ridge such as E against the inflow rate, along which
  the surrogate's mean falls off only because no run has gone there yet: without them the
  posterior of the benchmark's 6 + 1-D case came out up to 46 % too narrow); the last
  quarter maximise the expected reduction of the integrated variance of the unnormalised
  posterior exp(f(x)) p(x) under the GP f of L (the "EIV" rule of Järvenpää et al. 2019),

      R(x*) = integral p(x)^2 e^(2 mu(x) + s^2(x)) (e^(tau^2(x; x*)) - 1) dx,
      tau^2(x; x*) = c(x, x*)^2 / (s^2(x*) + sigma_n^2),

  with mu, s^2 the GP mean and variance of L and c its posterior covariance; the integral is
  an importance-sampling sum over the particles of the current posterior (which are drawn
  from exp(mu) p), and the candidates are those particles and the same particles pushed
  outward by the posterior's own covariance (so that a batch can look just beyond the
  current posterior). Within a batch the choice is greedy: after each point the GP
  covariances are conditioned on it (the variance update needs no forward run; the
  "kriging believer" batch of Ginsbourger et al. 2010).
* **The floor** (:func:`soft_floor`): L far below its maximum carries no posterior mass but
  spans orders of magnitude (L ~ -D^2 / 2 sigma_N^2), which would force the GP to spend
  its variance, nugget and length scales on it. The GP is trained on L with a soft floor
  T units below the best run: unchanged above, compressed logarithmically below (still
  decreasing, so the ordering is kept). T is chosen so the floored region cannot hold more
  than 1e-3 of the evidence (:func:`floor_depth`); this is the thresholding of low
  log-density values that GP surrogates of log-posteriors use (Acerbi 2018, VBMC).
* **Stopping** (:func:`posterior_change`, :func:`centred_rmse`): the last round's posterior,
  reweighted on its own particles from the surrogate that chose the batch to the one refitted
  with it, moved no mean or 5/50/95 % quantile by ``tol`` posterior standard deviations, no
  standard deviation by a factor 1 + ``tol`` and log Z by 0.5, and the surrogate's error at
  the batch's posterior draws (predicted before they were used), without its mean, is below
  :data:`~fbia.iterators.gp_smc.result.RELIABLE_RMSE`. Reweighting the same particles
  measures what the new runs changed and nothing else: two separate SMC runs also differ by
  their Monte Carlo noise, of the order of the 0.1-std tolerance for the rounds' coarse SMC
  on a broad 6 + 1-D posterior, where a design so compared used all of its 1000 runs with
  an accurate surrogate (issue 42; the noise's share of its round-to-round moves was
  inferred, not logged).

References: Järvenpää, Gutmann, Vehtari, Marttinen (2019), Bayesian Analysis 14(2) 595-622;
Ginsbourger, Le Riche, Carraro (2010), in Computational Intelligence in Expensive
Optimization Problems, 131-162; Acerbi (2018), NeurIPS 31; Loeppky, Sacks, Welch (2009),
Technometrics 51(4) 366-376 (the 10 d runs of the start). emukit (experimental-design loops
on GPy models) was looked at first: its loop owns the calls of the simulator, which in fbia
go through the evaluator (batches, store, resume), and its acquisitions are optimised over a
box by gradients, while this criterion is a sum over SMC particles; only the idea of a
greedy batch with fantasised variances is shared.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ...core.parameters import Parameter
from ..smc.sampler import SmcResult
from ..surrogates.residuals import Surrogate

FloatArray = NDArray[np.float64]

#: the smallest depth of the floor below the best run, in units of L
MIN_FLOOR_DEPTH = 20.0
#: log of the largest share of the evidence the floored region may hold
FLOOR_MASS = math.log(1e-3)
#: the shares of a batch drawn from the posterior and from the wide (tempered) posterior;
#: the rest follows the EIV rule
SHARE_DRAWS = 0.5
SHARE_WIDE = 0.25
#: candidates and integration points of the criterion: its cost is ~ (their sum) x n_train^2
#: per component of a residual emulator for the covariances, and ~ their product for the greedy
#: updates (issue 42: 1000 and 500 made it a third of fbia's own time at 1000 runs in
#: 6 + 1-D; the integral over 250 posterior draws ranks candidates to a few per cent)
N_CANDIDATES = 500
N_INTEGRATION = 250


def soft_floor(y: FloatArray, floor: float) -> FloatArray:
    """L above ``floor`` unchanged, below it ``floor - log(1 + floor - L)``."""
    y = np.asarray(y, dtype=float)
    below = y < floor
    out = y.copy()
    out[below] = floor - np.log1p(floor - y[below])
    return out


def floored(loglik: FloatArray, floor: float) -> FloatArray:
    """What the surrogate is trained on: L with the soft floor, a failed run (L = -inf) at
    the floor (the models fail at extreme parameters: not a region to send runs to)."""
    loglik = np.asarray(loglik, dtype=float)
    return soft_floor(np.where(np.isfinite(loglik), loglik, floor), floor)


def floor_depth(l_max: float, log_evidence: float | None) -> float:
    """How far below the best run the floor goes: deep enough that the floored region, whose
    prior mass is at most 1, holds at most 1e-3 of the evidence Z = integral e^L p
    (L_max - T <= log Z + log 1e-3), and never less than :data:`MIN_FLOOR_DEPTH`."""
    if log_evidence is None or not math.isfinite(log_evidence):
        return MIN_FLOOR_DEPTH
    return max(MIN_FLOOR_DEPTH, l_max - log_evidence - FLOOR_MASS)


@dataclass(frozen=True)
class Moments:
    """Mean and standard deviation of every input (x, then theta) under a posterior."""

    mean: FloatArray
    std: FloatArray

    @classmethod
    def of(cls, post: SmcResult) -> Moments:
        return cls(post.mean, np.sqrt(np.maximum(np.diag(post.cov), 0.0)))


def distinct_draws(post: SmcResult, n: int, rng: np.random.Generator) -> FloatArray:
    """Up to ``n`` distinct particles drawn in proportion to their weights."""
    order = rng.choice(len(post.weights), size=len(post.weights), p=post.weights)
    _, first = np.unique(order, return_index=True)
    return np.asarray(post.particles[order[np.sort(first)][:n]])


@dataclass(frozen=True)
class Validation:
    """A surrogate against forward runs it was not trained on (posterior draws)."""

    n: int  # points with finite L
    rmse: float  # of the GP mean against L
    centred: float  # the same without the mean error (:func:`centred_rmse`)
    z_rms: float  # root mean square of error / GP standard deviation (1: calibrated)


def validation_error(gp: Surrogate, x: FloatArray, log_likelihood: FloatArray) -> Validation:
    """The surrogate's errors in L at points it was not trained on (finite L only), and how
    they compare with its own standard deviation there."""
    ok = np.isfinite(log_likelihood)
    if not ok.any():
        return Validation(0, math.nan, math.nan, math.nan)
    mean, var = gp.predict(x[ok])
    err = mean - log_likelihood[ok]
    z = err / np.sqrt(np.maximum(var, 1e-300))
    return Validation(
        int(ok.sum()),
        float(np.sqrt(np.mean(err**2))),
        centred_rmse(err),
        float(np.sqrt(np.mean(z**2))),
    )


def centred_rmse(errors: FloatArray) -> float:
    """The spread of a surrogate's errors in L at posterior draws (their standard deviation,
    n - 1 in the denominator): what changes the posterior. An error that is the same
    everywhere cancels when the posterior is normalised, and an error e(x) that varies moves
    a posterior mean by at most sd(e^e) / E(e^e) ~ sd(e) of its posterior standard
    deviations (Cauchy-Schwarz: |Cov(x, w)| <= std(x) sd(w)). NaN for fewer than 2."""
    errors = np.asarray(errors, dtype=float)
    return float(np.std(errors, ddof=1)) if len(errors) >= 2 else math.nan


@dataclass(frozen=True)
class PosteriorChange:
    """How a refitted surrogate changes a posterior, measured on that posterior's own
    particles (:func:`posterior_change`): free of the Monte Carlo noise that two separate SMC
    runs differ by."""

    mean_shift: float  # largest |change of a mean| in posterior std
    std_change: float  # largest |log| ratio of a std
    quantile_shift: float  # largest move of a 5, 50 or 95 % quantile, in posterior std
    evidence_change: float  # |change of log Z|
    ess_fraction: float  # ESS of the new weights over the ESS of the old ones

    def settled(self, tol: float) -> bool:
        """Whether the posterior stopped moving: means and quantiles within ``tol`` std, std
        within a factor 1 + ``tol``, log Z within :data:`EVIDENCE_TOL`, and the new weights
        still spread over at least :data:`MIN_ESS_FRACTION` of the particles (else the
        particles no longer describe the new posterior and nothing is measured)."""
        return bool(
            self.mean_shift < tol
            and self.quantile_shift < tol
            and self.std_change < math.log1p(tol)
            and self.evidence_change < EVIDENCE_TOL
            and self.ess_fraction >= MIN_ESS_FRACTION
        )


#: the largest change of log Z between rounds that counts as "the evidence stopped changing"
EVIDENCE_TOL = 0.5
#: reweighted particles with fewer effective ones than this share of before: not converged
MIN_ESS_FRACTION = 0.5
#: the quantiles whose moves :class:`PosteriorChange` measures
QUANTILES = (0.05, 0.5, 0.95)


def posterior_change(
    post: SmcResult, target: Callable[[FloatArray], FloatArray]
) -> tuple[SmcResult, PosteriorChange]:
    """``post`` (SMC on an earlier surrogate: its ``log_likelihood`` is that target at the
    particles) reweighted to the log-target ``target`` of a refitted surrogate, w_i ~ w_i
    exp(target(x_i) - old_i), and how its moments, quantiles and evidence changed."""
    new = np.asarray(target(post.particles), dtype=float)
    with np.errstate(invalid="ignore"):
        delta = new - post.log_likelihood
    delta = np.where(np.isfinite(delta), delta, -np.inf)
    log_w = np.log(np.maximum(post.weights, 1e-300)) + delta
    top = float(np.max(log_w))
    if not math.isfinite(top):
        change = PosteriorChange(math.inf, math.inf, math.inf, math.inf, 0.0)
        return post, change
    w = np.exp(log_w - top)
    total = float(w.sum())
    w /= total
    # log Z_new / Z_old = log sum_i W_i exp(delta_i), W the old normalised weights
    d_log_z = top + math.log(total)
    reweighted = replace(
        post,
        weights=w,
        log_likelihood=new,
        log_evidence=post.log_evidence + d_log_z,
    )
    old, now = Moments.of(post), Moments.of(reweighted)
    old_std = np.maximum(old.std, 1e-300)
    shift = float(np.max(np.abs(now.mean - old.mean) / old_std))
    spread = float(np.max(np.abs(np.log(np.maximum(now.std, 1e-300) / old_std))))
    q_old = _weighted_quantiles(post.particles, post.weights)
    q_new = _weighted_quantiles(post.particles, w)
    q_shift = float(np.max(np.abs(q_new - q_old) / old_std))
    ess_fraction = float(np.sum(post.weights**2) / np.sum(w**2))  # ESS new / ESS old
    change = PosteriorChange(shift, spread, q_shift, abs(d_log_z), ess_fraction)
    return reweighted, change


def _weighted_quantiles(x: FloatArray, w: FloatArray) -> FloatArray:
    """The :data:`QUANTILES` of every column of ``x`` under weights ``w``, (3, d)."""
    out = np.empty((len(QUANTILES), x.shape[1]))
    for j in range(x.shape[1]):
        order = np.argsort(x[:, j], kind="stable")
        cdf = np.cumsum(w[order])
        idx = np.minimum(np.searchsorted(cdf, np.asarray(QUANTILES) * cdf[-1]), len(cdf) - 1)
        out[:, j] = x[order[idx], j]
    return out


def select_batch(
    gp: Surrogate,
    post: SmcResult,
    n_points: int,
    inputs: Sequence[Parameter],
    log_prior: Callable[[FloatArray], FloatArray],
    rng: np.random.Generator,
    wide: SmcResult | None = None,
) -> tuple[FloatArray, int]:
    """The next batch: ``n_points`` points, the first ``n_draws`` of them posterior draws,
    then draws from ``wide`` (the tempered surrogate posterior, which reaches along weakly
    identified directions the posterior has not followed yet), the rest chosen by the greedy
    EIV rule (module docstring); returns (points, n_draws)."""
    n_draws = max(1, round(n_points * SHARE_DRAWS))
    draws = distinct_draws(post, n_draws, rng)
    n_draws = len(draws)
    parts = [draws]
    n_wide = min(round(n_points * SHARE_WIDE), n_points - n_draws) if wide is not None else 0
    if wide is not None and n_wide > 0:
        parts.append(distinct_draws(wide, n_wide, rng))
    n_eiv = n_points - sum(len(p) for p in parts)
    if n_eiv > 0:
        integ = distinct_draws(post, N_INTEGRATION, rng)
        cand = _candidates(post, inputs, log_prior, rng)
        parts.append(_greedy_eiv(gp, integ, cand, n_eiv, log_prior))
    return np.vstack(parts), n_draws


def _candidates(
    post: SmcResult,
    inputs: Sequence[Parameter],
    log_prior: Callable[[FloatArray], FloatArray],
    rng: np.random.Generator,
) -> FloatArray:
    """Posterior particles and the same particles pushed by N(0, 4 cov) (inside the prior's
    support): where the posterior is and just beyond it."""
    base = distinct_draws(post, N_CANDIDATES // 2, rng)
    cov = np.atleast_2d(post.cov)
    jitter = 1e-12 * np.maximum(np.diag(cov).max(), 1e-300) * np.eye(len(cov))
    chol = np.linalg.cholesky(4.0 * cov + jitter)
    pushed = base + rng.standard_normal(base.shape) @ chol.T
    for j, p in enumerate(inputs):
        if p.bounds is not None:
            pushed[:, j] = np.clip(pushed[:, j], *p.bounds)
    pushed = pushed[np.isfinite(log_prior(pushed))]
    return np.vstack([base, pushed])


def _greedy_eiv(
    gp: Surrogate,
    integ: FloatArray,
    cand: FloatArray,
    n: int,
    log_prior: Callable[[FloatArray], FloatArray],
) -> FloatArray:
    """``n`` candidates chosen one by one, each maximising the expected reduction of the
    integrated variance of exp(f) p over the integration points, the GP conditioned on the
    ones chosen before (variances only: they do not depend on the runs' results)."""
    m, n_cand = len(integ), len(cand)
    # one covariance for both sets (each GP solves against the runs once), of which only the
    # blocks the criterion uses are formed: integration points x candidates, the candidates'
    # variances, and the rows of the candidates picked (first order in a residual emulator's
    # scores, as the criterion's tau^2 is defined)
    cov = gp.covariance_on(np.vstack([integ, cand]))
    at_integ, at_cand = np.arange(m), np.arange(m, m + n_cand)
    mu = gp.predict_mean(integ)
    s2 = cov.predictive_variance(at_integ)  # the variance of gp.predict
    # integration points are draws from exp(mu) p: weight p^2 e^(2 mu + s2) / (e^mu p)
    log_w = mu + s2 + log_prior(integ)
    log_w -= log_w.max()
    c_ic = cov.block(at_integ, at_cand)  # (M, C)
    var_c = cov.variance(at_cand)  # the diagonal of the candidates' block
    nugget = gp.nugget
    picked: list[int] = []
    rows: list[tuple[FloatArray, float]] = []  # the conditioned rows of the picks so far
    for _ in range(min(n, n_cand)):
        s2_c = np.maximum(var_c, 0.0)
        tau2 = c_ic**2 / (s2_c + nugget)[None, :]
        # log sum_m w_m (e^tau2 - 1), stable for tau2 from 0 to hundreds
        log_gain = np.log(np.expm1(np.minimum(tau2, 700.0)) + 1e-300) + log_w[:, None]
        top = log_gain.max(axis=0)
        score = top + np.log(np.exp(log_gain - top).sum(axis=0))
        score[picked] = -np.inf
        best = int(np.argmax(score))
        picked.append(best)
        # condition on a run at cand[best]: c(a, b) -= c(a, x*) c(x*, b) / (s2(x*) + nugget),
        # the row c(x*, .) of the candidates' block conditioned on the picks before
        row = cov.block(at_cand[best : best + 1], at_cand)[0]
        for earlier, denom_earlier in rows:
            row -= earlier[best] * earlier / denom_earlier
        denom = s2_c[best] + nugget
        c_ic -= np.outer(c_ic[:, best], row) / denom
        var_c -= row**2 / denom
        rows.append((row, denom))
    return np.asarray(cand[picked])
