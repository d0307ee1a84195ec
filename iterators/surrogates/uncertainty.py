"""The GP surrogate's uncertainty in the posterior: the expected posterior E_f[pi_f] (issue 16).

SMC on the GP's posterior mean mu (Paper B, eq. 28a) ignores what the GP does not know: with a
starved design the mean-only posterior exp(mu) p can be too narrow and in the wrong place.
Here the GP posterior over L (eq. 28a-b) is kept. Every sample path f of it defines a
posterior pi_f(x) = exp(f(x)) p(x) / Z_f, normalised *per path*, and the result is their
average, the expected posterior

    pi_EP(x) = E_f[pi_f(x)] = E_f[exp(f(x)) p(x) / Z_f].

It is a mixture of probability distributions, so it cannot run away: the mass of a region
A, E_f[pi_f(A)], is at most eps plus the probability that a sample path puts more than eps
of its posterior into A. The expected likelihood E_f[exp f] = exp(mu + sigma^2 / 2),
normalised after the expectation, has no such bound: far from the training points sigma^2
is the GP's prior variance, huge for an L spanning thousands, and that posterior goes to the
corners of the box (tests/iterators/surrogates/test_gp_uncertainty.py shows both on the same
points).

Literature: Stuart & Teckentrup (2018, Math. Comp. 87, 721-753) bound the error of three
GP-based posteriors, the mean-based one, the random one pi_f ("sample") and the "marginal"
one proportional to E_f[exp f] p, i.e. the expected likelihood above, *not* what this module
computes. Roberts, Dietze & Huggins (2026, arXiv:2601.03532) call E_f[pi_f] the expected
posterior (EP), argue for it as the baseline, and show that the expected unnormalised
posterior breaks down when the surrogate's uncertainty is as non-uniform as a GP of the
log-likelihood makes it. Järvenpää et al. (2021, Bayesian Analysis 16, 147-178) model the
log-likelihood with a GP, as here, and treat the resulting log-normal uncertainty of the
unnormalised posterior. The GP's hyperparameters stay at their evidence maximum (eq. 29):
their own uncertainty is not included.

Estimator (self-normalised importance sampling, one weight vector per path):

1. a weighted particle set of a proposal q(x) ~ exp(g(x)) p(x) whose log-target g is the
   ``log_likelihood`` stored in its :class:`~fbia.iterators.smc.sampler.SmcResult` (the mean-only
   posterior: g = mu; :func:`tempered_proposal`: g = beta mu, wider; either + log c, the
   factor of where the forward model runs, :mod:`~fbia.iterators.surrogates.feasibility`);
2. ``n_points`` distinct particles of it (all, or a systematic resampling), base weights w;
3. ``n_paths`` joint sample paths f_k of the surrogate at these points (full posterior
   covariance, Cholesky with jitter);
4. per path, w_k ~ w exp(f_k + log c - g), normalised (the prior cancels); the result's weights are
   the average of the K normalised vectors.

:func:`marginalise_surrogate_uncertainty` first reweights the mean-only particles (a pilot,
enough when the GP knows L where the posterior is) and otherwise runs SMC on beta mu
(:func:`proposal_temperature`). Cost in 7-D with 1000 training points and 10 000 particles,
M = 2000, K = 200: 0.5-4 s for the reweighting (joint covariance and its Cholesky factor,
on a shared 2-core machine), plus, when the pilot is not enough, one SMC run on beta mu
(fewer tempering steps than the mean-only run).

The result is an :class:`~fbia.iterators.smc.sampler.SmcResult` (``summarise`` takes it) and a
:class:`SurrogateUncertainty` with the diagnostics: the ESS of the averaged weights, the
spread of the per-path posterior means (how far the GP's uncertainty moves the posterior),
the mass on the proposal's tail (a proposal too narrow for the GP's uncertainty) and words.

>>> import numpy as np, fbia
>>> from fbia.iterators.surrogates.gp import GpSurrogate
>>> from fbia.iterators.surrogates.uncertainty import marginalise_surrogate_uncertainty
>>> rng = np.random.default_rng(0)
>>> x = rng.random((40, 2))
>>> gp = GpSurrogate().fit(x, -((x - 0.5) ** 2).sum(1) / 0.02, rng=rng)
>>> priors = [fbia.priors.uniform(0.0, 1.0)] * 2
>>> post = fbia.smc(gp.predict_mean, priors, n_particles=1000, zeta=0.9, seed=1)
>>> ep, unc = marginalise_surrogate_uncertainty(post, gp, priors, rng, n_paths=100)
>>> bool(np.allclose(ep.mean, post.mean, atol=0.02)), unc.ok   # the GP knows this one well
(True, True)
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ...core.parameters import Prior
from ..smc.sampler import SmcResult, ess, smc
from .residuals import Surrogate

FloatArray = NDArray[np.float64]

__all__ = [
    "SurrogateUncertainty",
    "marginalise_surrogate_uncertainty",
    "proposal_temperature",
    "reweight_by_sample_paths",
    "tempered_proposal",
]

#: The proposal's tail: the particles of lowest log-target that hold this much of its mass.
TAIL = 0.05
#: More of the expected posterior than this on the proposal's tail: the proposal is too narrow.
MAX_TAIL_MASS = 0.2
#: Fewer effective points than this in the averaged weights: the result is noisy.
MIN_ESS = 100.0
#: The GP's uncertainty may move a posterior mean by this many std, or change a std by this
#: factor, before the mean-only posterior counts as unreliable (the accuracy gp_smc aims at).
MAX_SHIFT = 0.3
MAX_STD_RATIO = 1.5
#: A pilot on the mean-only particles that is at most this much wider is the result.
PILOT_RATIO = 1.2


@dataclass(frozen=True)
class SurrogateUncertainty:
    """What marginalising the GP's uncertainty did, and whether to trust it.

    Attributes
    ----------
    n_paths, n_points
        Joint GP sample paths and the distinct particles they were drawn at.
    ess
        Effective sample size of the averaged weights (the result's resolution).
    path_ess_median, path_ess_min
        ESS of the per-path weight vectors (how well the proposal fits each pi_f).
    mean_spread
        Standard deviation over the paths of the per-path posterior means, per input.
    mean_spread_relative
        ``mean_spread`` over the standard deviation of the expected posterior: near 0 the GP
        knows L well where the posterior is; near 1 its uncertainty moves the posterior by
        about its own width, each path's posterior being much narrower than their mixture
        (or carried by a few points only: see ``path_ess_median``).
    mean_shift_relative
        (mean of the expected posterior - mean of the mean-only posterior) / std of the
        expected posterior, per input (:func:`reweight_by_sample_paths`: of the proposal).
    std_ratio
        Standard deviation of the expected posterior over that of the mean-only posterior
        (:func:`reweight_by_sample_paths`: of the proposal), per input.
    tail_mass
        Mass of the expected posterior on the proposal's tail (its particles of lowest
        log-target holding :data:`TAIL` of its mass); above :data:`MAX_TAIL_MASS` the
        proposal does not reach far enough.
    sigma_median, sigma_max
        GP standard deviation of L at the points (median weighted by the expected posterior,
        and the largest), in units of L.
    log_evidence_spread
        Standard deviation over the paths of log Z_f.
    jitter
        Diagonal added to the GP covariance for its Cholesky factor, in units of L^2.
    seconds
        Wall time of the reweighting.
    temperature
        beta of the proposal exp(beta mu) p (1: the mean-only posterior).
    widenings
        How often the proposal was widened because of its tail mass.
    warnings
        What limits the result, in words (empty: nothing found).
    """

    n_paths: int
    n_points: int
    ess: float
    path_ess_median: float
    path_ess_min: float
    mean_spread: FloatArray
    mean_spread_relative: FloatArray
    mean_shift_relative: FloatArray
    std_ratio: FloatArray
    tail_mass: float
    sigma_median: float
    sigma_max: float
    log_evidence_spread: float
    jitter: float
    seconds: float
    warnings: list[str] = field(default_factory=list)
    temperature: float = 1.0
    widenings: int = 0

    @property
    def ok(self) -> bool:
        return not self.warnings

    @property
    def moves_posterior(self) -> bool:
        """Whether the GP's own uncertainty moves a mean by more than :data:`MAX_SHIFT`
        posterior std or changes a std by more than a factor :data:`MAX_STD_RATIO`: then the
        surrogate does not know where the posterior is, whatever its error at draws from it."""
        ratio = np.asarray(self.std_ratio, dtype=float)
        shift = np.abs(np.asarray(self.mean_shift_relative, dtype=float))
        return bool(
            np.any(shift > MAX_SHIFT)
            or np.any(ratio > MAX_STD_RATIO)
            or np.any(ratio < 1.0 / MAX_STD_RATIO)
        )

    def reliability_note(self) -> str:
        """For a result message: how far the GP's uncertainty moves the posterior."""
        ratio = float(np.max(self.std_ratio))
        shift = float(np.max(np.abs(self.mean_shift_relative)))
        text = (
            f"; averaged over the GP's sample paths the posterior widens by up to x{ratio:.3g} "
            f"and moves by up to {shift:.2g} std"
        )
        if self.moves_posterior:
            text += (
                " (the surrogate does not know where the posterior ends: the posterior is "
                "not reliable; raise n_train)"
            )
        return text

    def note(self) -> str:
        """One sentence for a result message."""
        spread = float(np.max(self.mean_spread_relative))
        text = (
            f"GP uncertainty marginalised over {self.n_paths} sample paths at "
            f"{self.n_points} points: the per-path posterior means spread by up to "
            f"{spread:.2g} posterior std, ESS {self.ess:.0f}"
        )
        return text + "".join(f"; {w}" for w in self.warnings)


def reweight_by_sample_paths(
    proposal: SmcResult,
    surrogate: Surrogate,
    rng: np.random.Generator,
    n_paths: int = 200,
    n_points: int = 2000,
) -> tuple[SmcResult, SurrogateUncertainty]:
    """The expected posterior E_f[pi_f] from the particles of one proposal (steps 2-4 above).

    Parameters
    ----------
    proposal
        SMC particles of exp(g) p, where g is their stored ``log_likelihood``: the mean-only
        posterior (g = mu), or :func:`tempered_proposal` (g = beta mu), whose support
        should cover where the sample posteriors go (``tail_mass`` says when it does not).
    surrogate
        The trained GP of L (eq. 28a-b).
    rng
        Generator of the subsampling and the sample paths.
    n_paths
        Number K of joint GP sample paths.
    n_points
        Largest number M of distinct particles (cost ~ M^3 / 3 + M^2 n_train).

    Returns
    -------
    The expected posterior as an :class:`SmcResult` (the M points, the averaged weights,
    ``log_likelihood`` = mu at the points, ``log_evidence`` = median over paths of log Z_f
    and ``log_evidence_se`` = its spread over paths; the tempering record is the
    proposal's), and the :class:`SurrogateUncertainty` diagnostics.
    """
    if n_paths < 2 or n_points < 2:
        raise ConfigError(f"n_paths and n_points must be >= 2, got {n_paths}, {n_points}", "ep")
    t0 = time.perf_counter()
    idx, base = _distinct_points(proposal, n_points, rng)
    x = proposal.particles[idx]
    # the proposal's log-likelihood carries the factor of where the model runs (a prior-side
    # term, gp_feasibility): it stays in the target, only the GP's mean is replaced by paths
    g = proposal.log_likelihood[idx] - surrogate.log_feasibility(x)
    paths, sigma, jitter = surrogate.sample_paths(x, n_paths, rng)
    mu = surrogate.predict_mean(x)
    with np.errstate(invalid="ignore", over="ignore"):
        log_w = np.log(base)[:, None] + (paths - g[:, None])  # (M, K)
    log_w = np.where(np.isnan(log_w), -np.inf, log_w)
    top = log_w.max(axis=0)
    w = np.exp(log_w - top)
    total = w.sum(axis=0)
    w /= total
    log_z = proposal.log_evidence + top + np.log(total)  # log Z_f per path
    weights = w.mean(axis=1)
    weights /= weights.sum()
    result = replace(
        proposal,
        particles=x,
        weights=weights,
        log_likelihood=mu,
        log_prior=proposal.log_prior[idx],
        log_evidence=float(np.median(log_z)),
        log_evidence_se=float(np.std(log_z)),
        gammas=list(proposal.gammas),
        ess=list(proposal.ess),
        acceptance=list(proposal.acceptance),
        history=list(proposal.history),
    )
    return result, _diagnose(x, base, g, w, weights, sigma, log_z, jitter, t0)


def _distinct_points(
    proposal: SmcResult, n_points: int, rng: np.random.Generator
) -> tuple[NDArray[np.intp], FloatArray]:
    """Indices of at most ``n_points`` distinct particles and their weights (sum 1): every
    distinct location (weights of duplicates summed), or a systematic resampling of them
    (weights = multiplicities / n_points)."""
    keep = np.flatnonzero(proposal.weights > 0)
    _, first, inverse = np.unique(
        proposal.particles[keep], axis=0, return_index=True, return_inverse=True
    )
    mass = np.zeros(len(first))
    np.add.at(mass, inverse.ravel(), proposal.weights[keep])
    mass /= mass.sum()
    if len(first) <= n_points:
        return keep[first], mass
    positions = (rng.random() + np.arange(n_points)) / n_points  # systematic resampling
    cumulative = np.cumsum(mass)
    cumulative[-1] = 1.0
    draws = np.minimum(np.searchsorted(cumulative, positions, side="right"), len(mass) - 1)
    chosen, counts = np.unique(draws, return_counts=True)
    return keep[first[chosen]], counts / n_points


def _diagnose(
    x: FloatArray,
    base: FloatArray,
    g: FloatArray,
    w: FloatArray,
    weights: FloatArray,
    sigma: FloatArray,
    log_z: FloatArray,
    jitter: float,
    t0: float,
) -> SurrogateUncertainty:
    """The diagnostics of :func:`reweight_by_sample_paths` (see their fields)."""
    n_points, n_paths = w.shape
    mean, std = _weighted(x, weights)
    q_mean, q_std = _weighted(x, base)
    path_means = w.T @ x  # (K, d)
    spread = path_means.std(axis=0)
    path_ess = w.sum(axis=0) ** 2 / np.sum(w * w, axis=0)
    order = np.argsort(g)
    cut = g[order][min(int(np.searchsorted(np.cumsum(base[order]), TAIL)), n_points - 1)]
    tail_mass = float(weights[g < cut].sum())  # empty for a flat proposal (g constant)
    order_s = np.argsort(sigma)
    cdf = np.cumsum(weights[order_s])
    sigma_median = float(sigma[order_s][min(int(np.searchsorted(cdf, 0.5)), n_points - 1)])
    n_eff = ess(np.log(np.maximum(weights, 1e-300)))
    warnings = []
    if n_eff < MIN_ESS:
        warnings.append(
            f"only {n_eff:.0f} effective points carry the expected posterior (raise "
            "n_points, or bring the proposal closer to it)"
        )
    if tail_mass > MAX_TAIL_MASS:
        warnings.append(
            f"{tail_mass:.0%} of the expected posterior lies on the proposal's "
            f"{TAIL:.0%} tail: the proposal is too narrow for the GP's uncertainty and the "
            "result is truncated (widen it: a lower temperature, or more widenings)"
        )
    return SurrogateUncertainty(
        n_paths=n_paths,
        n_points=n_points,
        ess=n_eff,
        path_ess_median=float(np.median(path_ess)),
        path_ess_min=float(np.min(path_ess)),
        mean_spread=spread,
        mean_spread_relative=spread / std,
        mean_shift_relative=(mean - q_mean) / std,
        std_ratio=std / q_std,
        tail_mass=tail_mass,
        sigma_median=sigma_median,
        sigma_max=float(sigma.max()),
        log_evidence_spread=float(np.std(log_z)),
        jitter=jitter,
        seconds=time.perf_counter() - t0,
        warnings=warnings,
    )


def marginalise_surrogate_uncertainty(
    post: SmcResult,
    surrogate: Surrogate,
    priors: Sequence[Prior],
    rng: np.random.Generator,
    n_paths: int = 200,
    n_points: int = 2000,
    temperature: float | None = None,
    max_widenings: int = 2,
    smc_options: Mapping[str, Any] | None = None,
) -> tuple[SmcResult, SurrogateUncertainty]:
    """The expected posterior E_f[pi_f] of the GP surrogate (module docstring), as particles.

    A pilot reweights ``post`` itself. If the pilot is barely wider than ``post`` and puts
    little mass on its tail, that is the result (no SMC run); else the proposal is
    exp(beta mu) p with beta from :func:`proposal_temperature`, divided by 4 and rerun
    while the expected posterior has more than :data:`MAX_TAIL_MASS` on its tail.

    Parameters
    ----------
    post
        The mean-only posterior: SMC on exp(mu) p (its ``log_likelihood`` is mu).
    surrogate
        The trained GP of L whose mean gave ``post``.
    priors
        The priors of that SMC run (for the tempered proposal).
    rng
        Generator of the proposal's SMC, the subsampling and the sample paths.
    n_paths, n_points
        Joint GP sample paths K and distinct particles M (see :func:`reweight_by_sample_paths`).
    temperature
        beta of the first proposal exp(beta mu) p instead of the pilot's choice (1: ``post``).
    max_widenings
        Largest number of reruns with beta / 4.
    smc_options
        Options of the proposal's :func:`fbia.smc` (default: as many particles as ``post``).

    Returns
    -------
    The expected posterior as an :class:`SmcResult` and its :class:`SurrogateUncertainty`
    (``mean_shift_relative`` and ``std_ratio`` against ``post``).
    """
    options = {"n_particles": len(post.weights), "names": post.names, **(smc_options or {})}

    def run(beta: float, widenings: int) -> tuple[SmcResult, SurrogateUncertainty]:
        proposal = post
        if beta < 1.0:
            proposal = tempered_proposal(surrogate, priors, beta, rng, **options)
        result, unc = reweight_by_sample_paths(proposal, surrogate, rng, n_paths, n_points)
        (mean, std), (ref_mean, ref_std) = _moments(result), _moments(post)
        return result, replace(
            unc,
            mean_shift_relative=(mean - ref_mean) / std,
            std_ratio=std / ref_std,
            temperature=min(beta, 1.0),
            widenings=widenings,
        )

    if temperature is None:
        result, unc = run(1.0, 0)  # the pilot
        if unc.tail_mass <= 0.5 * MAX_TAIL_MASS and np.max(unc.std_ratio) <= PILOT_RATIO:
            return result, unc
        beta = proposal_temperature(unc)
    else:
        beta = float(temperature)
    for widening in range(max_widenings + 1):
        result, unc = run(beta, widening)
        if unc.tail_mass <= MAX_TAIL_MASS:
            break
        beta = min(beta, 1.0) / 4.0
    return result, unc


def _moments(post: SmcResult) -> tuple[FloatArray, FloatArray]:
    """Weighted mean and standard deviation of the particles, per input."""
    return _weighted(post.particles, post.weights)


def _weighted(x: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    mean = w @ x
    return mean, np.sqrt(np.maximum(w @ (x - mean) ** 2, 1e-300))


def proposal_temperature(pilot: SurrogateUncertainty) -> float:
    """beta of the proposal exp(beta mu) p from a pilot (the mean-only posterior reweighted).

    exp(beta mu) p is wider than exp(mu) p by 1 / sqrt(beta) where mu is quadratic; the
    pilot's widest ``std_ratio`` r says how much wider the expected posterior is, as far
    as the mean-only particles reach: beta = 1 / (1.5 r)^2. When the pilot puts more than
    half its mass on the mean-only posterior's tail, r is truncated and beta is at most
    1 / (1 + s), s the GP's standard deviation of L there (``sigma_median``): in 2-D tests
    the expected posterior was wider than the mean-only one by about sqrt(s) (s = 7, 20,
    90: 2, 4 and 8 times; in 7-D, s = 5: 1.3 times).
    """
    beta = 1.0 / (1.5 * max(1.0, float(np.max(pilot.std_ratio)))) ** 2
    if pilot.tail_mass > 0.5:
        beta = min(beta, 1.0 / (1.0 + pilot.sigma_median))
    return beta


def tempered_proposal(
    surrogate: Surrogate,
    priors: Sequence[Prior],
    temperature: float,
    rng: np.random.Generator,
    **smc_options: Any,
) -> SmcResult:
    """SMC particles of exp(beta mu) p, beta = ``temperature`` in (0, 1]: the mean-only
    posterior widened (by 1 / sqrt(beta) where mu is quadratic); the stored
    ``log_likelihood`` is beta mu, the log-target :func:`reweight_by_sample_paths` divides
    out. ``smc_options`` go to :func:`fbia.smc` (n_particles, zeta, ...)."""
    if not 0.0 < temperature <= 1.0:
        raise ConfigError(f"temperature must lie in (0, 1], got {temperature}", "ep")
    return smc(
        lambda z: temperature * surrogate.predict_mean(z) + surrogate.log_feasibility(z),
        priors,
        rng=rng,
        **smc_options,
    )
