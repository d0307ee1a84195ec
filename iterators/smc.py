"""Adaptive tempered sequential Monte Carlo (Paper B, Algorithm 1, eq. 12-15).

>>> import numpy as np, fbia
>>> priors = [fbia.priors.normal(0.0, 1.0), fbia.priors.normal(0.0, 1.0)]
>>> def log_likelihood(x):                 # vectorised: (N, d) -> (N,)
...     return -0.5 * np.sum((x - 1.0) ** 2, axis=1) / 0.5**2
>>> post = fbia.smc(log_likelihood, priors, n_particles=2000, seed=1)
>>> np.round(post.mean, 1)                 # exact posterior mean: 0.8 in each direction
array([0.8, 0.8])

The sampler moves N weighted particles from the prior p(x) to the posterior through the
tempered densities (eq. 15)

    pi_gamma(x) ~ exp(gamma L(x)) p(x),   0 = gamma_0 < gamma_1 < ... < gamma_S = 1.

Each step finds gamma_s by root finding so that the effective sample size (eq. 14) of the
reweighted particles is ESS_s = zeta ESS_{s-1}, goes to gamma = 1 when no smaller gamma does,
resamples (systematic) when ESS drops below ESS_min, and rejuvenates every particle with
``n_rejuvenation`` Metropolis-Hastings steps whose Gaussian proposal has the weighted particle
covariance scaled by ``(a + b * acceptance)**2`` with a = 1/9, b = 8/9 (Paper B ref. [37]).
With ``rejuvenate="after_resampling"`` the particles move only in the steps that resample
and in the last one (resample-move, Chopin 2002): the same weighted approximation of every
pi_gamma, since each move leaves pi_gamma invariant, at a fraction of the likelihood
evaluations when zeta is close to 1 (hundreds of tempering steps, a few resamplings).
The log-evidence log p(Y) = sum_s log sum_i W_{s-1}^i exp((gamma_s - gamma_{s-1}) L_i) is a
by-product.

:class:`SequentialMonteCarlo` is steppable (``steps()`` yields an :class:`SmcState` per
tempering step and returns the :class:`SmcResult`); ``run()`` and :func:`smc` drain it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from ..core.errors import ConfigError
from ..core.iteration import drain
from ..core.parameters import Prior

LogLikelihood = Callable[[NDArray[np.float64]], ArrayLike]

#: Proposal scale factor a + b * acceptance rate (Paper B ref. [37], Minson et al. 2013).
SCALE_A = 1.0 / 9.0
SCALE_B = 8.0 / 9.0
#: When the particles move: Algorithm 1 (every step) or resample-move.
REJUVENATE = ("every_step", "after_resampling")


def logsumexp(a: NDArray[np.float64]) -> float:
    """log sum exp(a) of a 1-D array, -inf when all entries are -inf.

    scipy.special.logsumexp gives the same numbers with ~0.3 ms of array-API overhead per
    call; an SMC run with zeta close to 1 calls this tens of thousands of times.
    """
    m = float(a.max()) if a.size else -math.inf
    if not math.isfinite(m):
        return m
    return m + math.log(float(np.exp(a - m).sum()))


def ess(log_weights: NDArray[np.float64]) -> float:
    """Effective sample size 1 / sum(w_i^2) of normalised weights (eq. 14), from log-weights."""
    m = float(log_weights.max()) if log_weights.size else -math.inf
    if not math.isfinite(m):
        return 0.0
    w = np.exp(log_weights - m)
    return float(w.sum() ** 2 / np.dot(w, w))


def systematic_resample(weights: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.intp]:
    """Indices of a systematic resampling of normalised ``weights`` (one uniform draw)."""
    n = len(weights)
    positions = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    return np.minimum(np.searchsorted(cumulative, positions, side="right"), n - 1)


@dataclass
class SmcState:
    """What one tempering step did (yielded by :meth:`SequentialMonteCarlo.steps`)."""

    step: int
    gamma: float
    ess: float
    resampled: bool
    acceptance: float
    log_evidence: float
    nfev: int

    def __str__(self) -> str:
        return (
            f"SMC step {self.step}: gamma = {self.gamma:.4g}, ESS = {self.ess:.1f}, "
            f"{'resampled, ' if self.resampled else ''}acceptance = {self.acceptance:.2f}"
        )


@dataclass
class SmcResult:
    """The weighted particle approximation of the posterior (eq. 12) and its by-products.

    Attributes
    ----------
    particles
        Particle locations, shape (N, d).
    weights
        Normalised weights (sum 1), shape (N,).
    log_likelihood, log_prior
        L and log p at every particle, shape (N,).
    log_evidence
        Estimate of log p(Y) = log of the integral of exp(L) p.
    log_evidence_se
        Rough standard error of ``log_evidence`` (treats the particles of each step as
        independent draws; an underestimate after many rejuvenations of few distinct particles).
    gammas, ess
        The tempering sequence gamma_0 = 0, ..., 1 and the ESS after each reweighting.
    acceptance
        Mean Metropolis-Hastings acceptance rate of each step's rejuvenation.
    nfev
        Number of points at which the log-likelihood was evaluated.
    names
        Parameter names (default ``x0, x1, ...``).
    history
        One dict per step: gamma, ess, resampled, moved, acceptance, scale, nfev, seconds.
    """

    particles: NDArray[np.float64]
    weights: NDArray[np.float64]
    log_likelihood: NDArray[np.float64]
    log_prior: NDArray[np.float64]
    log_evidence: float
    log_evidence_se: float
    gammas: list[float]
    ess: list[float]
    acceptance: list[float]
    nfev: int
    names: list[str]
    history: list[dict[str, Any]] = field(default_factory=list)

    @property
    def log_posterior(self) -> NDArray[np.float64]:
        """Unnormalised log-posterior L + log p at every particle."""
        return self.log_likelihood + self.log_prior

    @property
    def n_steps(self) -> int:
        return len(self.gammas) - 1

    @property
    def mean(self) -> NDArray[np.float64]:
        """Posterior mean (eq. 13 with h(x) = x)."""
        return np.asarray(self.weights @ self.particles)

    @property
    def cov(self) -> NDArray[np.float64]:
        """Posterior covariance (eq. 13), shape (d, d)."""
        dx = self.particles - self.mean
        return np.asarray((dx * self.weights[:, None]).T @ dx)

    @property
    def map(self) -> NDArray[np.float64]:
        """MAP estimate: the particle of highest posterior in the last step (Paper B)."""
        return np.asarray(self.particles[int(np.argmax(self.log_posterior))])

    @property
    def max_likelihood(self) -> NDArray[np.float64]:
        """The particle of highest likelihood in the last step."""
        return np.asarray(self.particles[int(np.argmax(self.log_likelihood))])

    @property
    def final_ess(self) -> float:
        return ess(np.log(np.maximum(self.weights, 1e-300)))

    def resample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` equally weighted draws from the particle approximation (systematic)."""
        idx = systematic_resample(self.weights, rng) if n == len(self.weights) else None
        if idx is None:
            idx = rng.choice(len(self.weights), size=n, p=self.weights)
        return np.asarray(self.particles[idx])


class SequentialMonteCarlo:
    """Adaptive tempered SMC sampler (Paper B, Algorithm 1).

    Parameters
    ----------
    log_likelihood
        Vectorised log-likelihood L: array (M, d) -> array (M,). Called only at points inside
        the prior support. NaN is treated as -inf (zero likelihood) and counted.
    priors
        One :class:`fbia.Prior` per dimension (independent priors; p(x) = prod p_j(x_j)).
    n_particles
        Number of particles N.
    zeta
        ESS reduction per step: ESS_s = zeta ESS_{s-1} (Paper B: 0.995, 0.998).
    n_rejuvenation
        Metropolis-Hastings steps per particle and tempering step (n_rej).
    ess_min
        Resampling threshold as a fraction of N (resample when ESS < ess_min N).
    seed
        Seed of the ``numpy.random.Generator`` (or pass ``rng``).
    rng
        An explicit generator (overrides ``seed``).
    names
        Parameter names for results and plots.
    max_steps
        Stop with an error after this many tempering steps.
    rejuvenate
        ``"every_step"`` (Algorithm 1) or ``"after_resampling"``: Metropolis-Hastings moves
        only in the steps that resample and in the final step to gamma = 1.
    """

    def __init__(
        self,
        log_likelihood: LogLikelihood,
        priors: Sequence[Prior],
        n_particles: int = 2000,
        zeta: float = 0.995,
        n_rejuvenation: int = 10,
        ess_min: float = 0.5,
        seed: int | None = None,
        rng: np.random.Generator | None = None,
        names: Sequence[str] | None = None,
        max_steps: int = 10_000,
        rejuvenate: str = "every_step",
    ) -> None:
        if not callable(log_likelihood):
            raise ConfigError("log_likelihood must be callable: (N, d) array -> (N,) array", "smc")
        priors = list(priors)
        if not priors or not all(isinstance(p, Prior) for p in priors):
            raise ConfigError("priors must be a non-empty list of fbia.Prior objects", "smc")
        if int(n_particles) < 2:
            raise ConfigError(f"n_particles must be at least 2, got {n_particles}", "smc")
        if not 0.0 < zeta < 1.0:
            raise ConfigError(f"zeta must lie in (0, 1), got {zeta}", "smc")
        if int(n_rejuvenation) < 0:
            raise ConfigError(f"n_rejuvenation must be >= 0, got {n_rejuvenation}", "smc")
        if not 0.0 <= ess_min <= 1.0:
            raise ConfigError(f"ess_min is a fraction of N in [0, 1], got {ess_min}", "smc")
        if names is not None and len(names) != len(priors):
            raise ConfigError(f"{len(names)} names for {len(priors)} priors", "smc")
        if rejuvenate not in REJUVENATE:
            raise ConfigError(
                f"unknown rejuvenate={rejuvenate!r}; valid: {', '.join(REJUVENATE)}", "smc"
            )
        self.rejuvenate = rejuvenate
        self.log_likelihood = log_likelihood
        self.priors = priors
        self.n_particles = int(n_particles)
        self.zeta = float(zeta)
        self.n_rejuvenation = int(n_rejuvenation)
        self.ess_min = float(ess_min)
        self.rng = rng if rng is not None else np.random.default_rng(seed)
        self.names = list(names) if names is not None else [f"x{i}" for i in range(len(priors))]
        self.max_steps = int(max_steps)
        self.nfev = 0
        self.n_nonfinite = 0

    @property
    def dim(self) -> int:
        return len(self.priors)

    # -- densities ------------------------------------------------------------------------
    def log_prior(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """log p(x) = sum_j log p_j(x_j) for an array (M, d)."""
        out = np.zeros(len(x))
        for j, prior in enumerate(self.priors):
            out += prior.logpdf(x[:, j])
        return np.where(np.isnan(out), -np.inf, out)

    def _loglik(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        if len(x) == 0:
            return np.zeros(0)
        values = np.asarray(self.log_likelihood(x), dtype=float)
        if values.shape != (len(x),):
            raise ConfigError(
                f"log_likelihood returned shape {values.shape} for {len(x)} points; "
                f"expected ({len(x)},)",
                "smc",
            )
        self.nfev += len(x)
        bad = np.isnan(values) | (values == np.inf)
        if np.any(bad):
            self.n_nonfinite += int(bad.sum())
            values = np.where(bad, -np.inf, values)
        return values

    # -- the algorithm --------------------------------------------------------------------
    def _next_gamma(self, gamma: float, log_w: NDArray[np.float64], loglik: NDArray[np.float64]):
        """gamma_s with ESS_s = zeta ESS_{s-1}, or 1 when no smaller one exists (Algorithm 1)."""
        target = self.zeta * ess(log_w)
        finite = np.isfinite(loglik)
        # Particles with L = -inf get weight 0 at any gamma > current gamma.
        lw, ll = log_w[finite], loglik[finite]

        def excess(g: float) -> float:
            # ESS of the reweighted particles: (sum w)^2 / sum w^2, one exp pass (this runs
            # ~20 times per tempering step, thousands of steps with zeta close to 1).  The
            # ESS does not depend on a common factor of the weights: shifting by the largest
            # new log-weight keeps the largest weight at 1, however small every likelihood
            # is (shifting by the previous weights underflowed to 0/0 below L = -700).
            z = lw + (g - gamma) * ll
            w = np.exp(z - float(z.max()))
            return float(w.sum() ** 2 / np.dot(w, w)) - target

        if excess(1.0) >= 0.0:
            return 1.0
        if excess(gamma) < 0.0:  # dropping the zero-likelihood particles already costs more
            return float(np.nextafter(gamma, 2.0))
        return float(brentq(excess, gamma, 1.0, xtol=1e-14, rtol=1e-10))

    def _stalled(
        self, gamma: float, loglik: NDArray[np.float64], log_w: NDArray[np.float64]
    ) -> str:
        """Why the tempering did not reach gamma = 1 within max_steps, and what to change."""
        finite = loglik[np.isfinite(loglik)]
        spread = float(np.ptp(finite)) if finite.size else math.nan
        alive = int(np.sum(np.exp(log_w) > 1e-3 / len(log_w)))
        unique = len(np.unique(loglik))
        # resampling restarts the ESS at N; each step lowers it by the factor zeta, so one
        # resampling cycle takes log(ess_min) / log(zeta) steps
        cycle = math.log(max(self.ess_min, 1e-3)) / math.log(self.zeta)
        why = [
            f"no convergence to gamma = 1 in {self.max_steps} tempering steps "
            f"(gamma = {gamma:.3g})",
            f"with zeta = {self.zeta:g} one resampling cycle takes about {cycle:.0f} steps",
            f"the log-likelihood spans {spread:.3g} over the particles",
        ]
        if unique < 0.1 * len(loglik):
            why.append(
                f"the particles have collapsed onto {unique} distinct points (raise "
                "n_rejuvenation or the proposal's reach)"
            )
        elif alive < 0.1 * len(log_w):
            why.append(f"only {alive} particles carry weight")
        why.append(
            "lower zeta (e.g. 0.95), use rejuvenate = 'after_resampling', or raise "
            "max_steps; a log-likelihood spread far beyond the training range of a surrogate "
            "is a surrogate artefact (check it with n_check)"
        )
        return "; ".join(why)

    def steps(self) -> Generator[SmcState, None, SmcResult]:
        """Run Algorithm 1; yield after each tempering step, return the :class:`SmcResult`."""
        rng, n = self.rng, self.n_particles
        x = np.column_stack([p.rvs(n, rng) for p in self.priors]).astype(float)
        log_prior = self.log_prior(x)
        loglik = self._loglik(x)
        if not np.any(np.isfinite(loglik)):
            raise ConfigError("the log-likelihood is -inf or NaN at every prior draw", "smc")
        log_w = np.zeros(n) - math.log(n)
        gamma = 0.0
        gammas, ess_hist, accept_hist, history = [0.0], [float(n)], [], []
        log_evidence, log_evidence_var = 0.0, 0.0
        seg_start: NDArray[np.float64] | None = None
        seg_inc, seg_log_z = np.zeros(n), 0.0
        acceptance = 1.0
        step = 0
        while gamma < 1.0:
            t0 = time.perf_counter()
            step += 1
            if step > self.max_steps:
                raise ConfigError(self._stalled(gamma, loglik, log_w), "smc")
            new_gamma = self._next_gamma(gamma, log_w, loglik)
            # Reweighting w_s = w_{s-1} exp((gamma_s - gamma_{s-1}) L) and the evidence factor.
            inc = np.where(np.isfinite(loglik), (new_gamma - gamma) * loglik, -np.inf)
            log_w_norm = log_w - logsumexp(log_w)
            log_z_inc = float(logsumexp(log_w_norm + inc))
            log_evidence += log_z_inc
            if seg_start is None:  # weights where the particles last moved or were resampled
                seg_start, seg_inc, seg_log_z = log_w_norm, np.zeros(n), 0.0
            seg_inc = seg_inc + inc
            seg_log_z += log_z_inc
            log_w = log_w_norm + inc
            log_w -= logsumexp(log_w)
            gamma = new_gamma
            current_ess = ess(log_w)
            resampled = False
            if current_ess < self.ess_min * n:
                idx = systematic_resample(np.exp(log_w), rng)
                x, loglik, log_prior = x[idx], loglik[idx], log_prior[idx]
                log_w = np.zeros(n) - math.log(n)
                resampled = True
            scale = SCALE_A + SCALE_B * acceptance
            move = self.n_rejuvenation > 0 and (
                self.rejuvenate == "every_step" or resampled or gamma >= 1.0
            )
            if move or resampled or gamma >= 1.0:
                # Variance of the evidence factor of the steps since the particles last moved
                # or were resampled: one importance-sampling estimate with the same particles
                # (not independent steps).
                ratio = np.exp(seg_inc - seg_log_z)
                w0 = np.exp(seg_start)
                log_evidence_var += float(np.sum(w0 * (ratio - 1.0) ** 2)) / max(
                    ess(seg_start), 1.0
                )
                seg_start = None
            if move:
                x, loglik, log_prior, acceptance = self._rejuvenate(
                    x, loglik, log_prior, log_w, gamma, scale
                )
            gammas.append(gamma)
            ess_hist.append(current_ess)
            accept_hist.append(acceptance)
            history.append(
                {
                    "step": step,
                    "gamma": gamma,
                    "ess": current_ess,
                    "resampled": resampled,
                    "moved": move,
                    "acceptance": acceptance,
                    "scale": scale,
                    "nfev": self.nfev,
                    "seconds": time.perf_counter() - t0,
                }
            )
            yield SmcState(step, gamma, current_ess, resampled, acceptance, log_evidence, self.nfev)
        weights = np.exp(log_w - logsumexp(log_w))
        return SmcResult(
            particles=x,
            weights=weights,
            log_likelihood=loglik,
            log_prior=log_prior,
            log_evidence=log_evidence,
            log_evidence_se=math.sqrt(log_evidence_var),
            gammas=gammas,
            ess=ess_hist,
            acceptance=accept_hist,
            nfev=self.nfev,
            names=self.names,
            history=history,
        )

    def run(self) -> SmcResult:
        """Run Algorithm 1 to gamma = 1 and return the :class:`SmcResult`."""
        return drain(self.steps())

    def _proposal_factor(self, x: NDArray[np.float64], log_w: NDArray[np.float64], scale: float):
        """Cholesky factor of scale^2 times the weighted particle covariance."""
        w = np.exp(log_w - logsumexp(log_w))
        mean = w @ x
        dx = x - mean
        cov = (dx * w[:, None]).T @ dx
        # Jitter relative to the spread keeps a collapsed dimension movable.
        spread = np.maximum(np.diag(cov), 1e-12 * np.maximum(1.0, np.abs(mean)) ** 2)
        cov = cov + 1e-10 * np.diag(spread)
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            vals, vecs = np.linalg.eigh(cov)
            chol = vecs * np.sqrt(np.maximum(vals, 1e-12 * spread.max()))
        return scale * chol

    def _rejuvenate(
        self,
        x: NDArray[np.float64],
        loglik: NDArray[np.float64],
        log_prior: NDArray[np.float64],
        log_w: NDArray[np.float64],
        gamma: float,
        scale: float,
    ):
        """n_rej Metropolis-Hastings steps targeting pi_gamma (eq. 15) for every particle."""
        rng = self.rng
        factor = self._proposal_factor(x, log_w, scale)
        n, d = x.shape
        accepted = 0
        for _ in range(self.n_rejuvenation):
            proposal = x + rng.standard_normal((n, d)) @ factor.T
            lp_new = self.log_prior(proposal)
            inside = np.isfinite(lp_new)
            ll_new = np.full(n, -np.inf)
            ll_new[inside] = self._loglik(proposal[inside])
            with np.errstate(invalid="ignore"):
                log_alpha = gamma * (ll_new - loglik) + (lp_new - log_prior)
            # A proposal of zero likelihood (L = -inf) is rejected unless gamma = 0.
            if gamma == 0.0:
                log_alpha = np.where(inside, lp_new - log_prior, -np.inf)
            log_alpha = np.where(np.isnan(log_alpha), -np.inf, log_alpha)
            accept = np.log(rng.random(n)) < log_alpha
            x = np.where(accept[:, None], proposal, x)
            loglik = np.where(accept, ll_new, loglik)
            log_prior = np.where(accept, lp_new, log_prior)
            accepted += int(accept.sum())
        return x, loglik, log_prior, accepted / (n * self.n_rejuvenation)


def smc(
    log_likelihood: LogLikelihood,
    priors: Sequence[Prior],
    n_particles: int = 2000,
    zeta: float = 0.995,
    n_rejuvenation: int = 10,
    ess_min: float = 0.5,
    seed: int | None = None,
    rng: np.random.Generator | None = None,
    names: Sequence[str] | None = None,
    max_steps: int = 10_000,
    rejuvenate: str = "every_step",
) -> SmcResult:
    """Sample exp(L(x)) p(x) with adaptive tempered SMC (Paper B, Algorithm 1).

    See :class:`SequentialMonteCarlo` for the parameters; returns the :class:`SmcResult`
    (particles, normalised weights, log-evidence, tempering history).
    """
    sampler = SequentialMonteCarlo(
        log_likelihood,
        priors,
        n_particles=n_particles,
        zeta=zeta,
        n_rejuvenation=n_rejuvenation,
        ess_min=ess_min,
        seed=seed,
        rng=rng,
        names=names,
        max_steps=max_steps,
        rejuvenate=rejuvenate,
    )
    return sampler.run()
