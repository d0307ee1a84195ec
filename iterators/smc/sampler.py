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
evaluations when zeta is close to 1.

Which to use: ``"every_step"`` is Algorithm 1 as printed and costs N n_rej likelihood calls in
every tempering step; since the moves keep the particles on each tempered density, the ESS
falls slowly and a run needs few steps (Paper B's example 7 on the default flow cell: 129
steps at zeta = 0.998). On a GP mean of 1024 points in 2-D a step costs about 0.2 s, so 160
steps about 35 s; with L and the log-priors tabulated (``table_points``, at most three inputs
with bounded priors: :mod:`fbia.iterators.smc.table`) 33 ms (5.3 s in all,
``benchmarks/bench_smc_table.py``). Without a table in more dimensions a step on a 2000-point
7-D GP mean costs about 0.5 s.
``"after_resampling"`` moves once per cycle: the same settings finish in about ten seconds
(``benchmarks/bench_smc_paper_settings.py``). The default step limit (``max_steps=None``) is
100 halvings of the ESS, ceil(100 log 0.5 / log zeta) steps (at least 1000), about three
times what a 7-D posterior 10^4 times narrower than its prior needs; a run that hits it raises
an error that says why (rate of progress, collapsed particles, a surrogate extrapolating above
its training values) and what to change.
The log-evidence log p(Y) = sum_s log sum_i W_{s-1}^i exp((gamma_s - gamma_{s-1}) L_i) is a
by-product.

:class:`SequentialMonteCarlo` is steppable (``steps()`` yields an :class:`SmcState` per
tempering step and returns the :class:`SmcResult`); ``run()`` and :func:`smc` drain it.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...core.errors import ConfigError
from ...core.iteration import drain
from ...core.parameters import Prior
from .diagnostics import stall_message
from .table import LogTables, tabulable
from .tempering import (
    EssTempering,
    default_max_steps,
    ess,
    logsumexp,
    systematic_resample,
)

logger = logging.getLogger(__name__)

__all__ = [
    "SequentialMonteCarlo",
    "SmcResult",
    "SmcState",
    "ess",
    "logsumexp",
    "smc",
    "systematic_resample",
]

LogLikelihood = Callable[[NDArray[np.float64]], ArrayLike]

#: Proposal scale factor a + b * acceptance rate (Paper B ref. [37], Minson et al. 2013).
SCALE_A = 1.0 / 9.0
SCALE_B = 8.0 / 9.0
#: When the particles move: Algorithm 1 (every step) or resample-move.
REJUVENATE = ("every_step", "after_resampling")


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
    table
        With tabulated log-densities (``table_points``): the table's size, build time and
        its error against the real L at the final particles (:mod:`fbia.iterators.smc.table`);
        or ``{"note": why no table was used}``; None without ``table_points``.
    tempered
        With ``keep_gamma``: the weighted particles of the tempered density exp(gamma L) p at
        that gamma, after its step's moves (their ``log_likelihood`` is L, their
        ``log_evidence`` that of exp(gamma L) p); None otherwise.
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
    table: dict[str, Any] | None = None
    tempered: SmcResult | None = None

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
        """The ESS of the weights: of the last reweighting's, before the resampling at
        gamma = 1 made them equal (then ``ess[-1]``), or of the weights as they are."""
        w = self.weights
        if self.ess and len(w) and float(np.ptp(w)) <= 1e-12 * float(np.max(w)):
            return float(self.ess[-1])
        return ess(np.log(np.maximum(w, 1e-300)))

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
        Stop with an error after this many tempering steps. ``None``: 100 halvings of the
        ESS, ceil(100 log 0.5 / log zeta) steps and at least 1000 (34 623 at zeta = 0.998),
        about three times what a 7-D posterior 10^4 times narrower than its prior needs.
    rejuvenate
        ``"every_step"`` (Algorithm 1) or ``"after_resampling"``: Metropolis-Hastings moves
        only in the steps that resample and in the final step to gamma = 1. With zeta close to
        1 (thousands of steps) only ``"after_resampling"`` is affordable on a GP surrogate;
        ``"every_step"`` suits runs of few steps (zeta <= 0.95).
    training_range
        (min, max) of the log-likelihood values a surrogate was trained on: the error of a
        stalled run then says whether the particles sit far above them (extrapolation).
    table_points
        Tabulate L on a grid of this many points per input and the log-priors on fine 1-D
        grids, and run the moves in one compiled kernel (:mod:`fbia.iterators.smc.table`):
        for at most three inputs with bounded priors; the result's ``table`` gives the table's
        error against L at the final particles. None: L is called directly.
    keep_gamma
        A gamma in (0, 1) where the tempering stops on its way (a step ends exactly there)
        and whose weighted particles the result keeps as ``tempered``: a draw from exp(gamma
        L) p for free, instead of a second run (the adaptive design's wide draws).
    final_resample
        Resample at gamma = 1 before the last moves (default), so that the particles are
        equally weighted (ArviZ's plain mean over them is the weighted one). The adaptive
        design's rounds leave it off: the particles the moves leave in place would be
        duplicates there, and batches drawn from them repeat points (measured
        on the broad 6 + 1-D case at 1000 runs: E2's posterior std 1.34x the exact one with
        it in the rounds, 1.02x without).
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
        max_steps: int | None = None,
        rejuvenate: str = "every_step",
        training_range: tuple[float, float] | None = None,
        table_points: int | None = None,
        keep_gamma: float | None = None,
        final_resample: bool = True,
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
        if max_steps is not None and int(max_steps) < 1:
            raise ConfigError(f"max_steps must be >= 1 or None, got {max_steps}", "smc")
        self.max_steps = default_max_steps(self.zeta) if max_steps is None else int(max_steps)
        if training_range is not None and not training_range[0] <= training_range[1]:
            raise ConfigError(f"training_range must be (min, max), got {training_range}", "smc")
        self.training_range = training_range
        if table_points is not None and int(table_points) < 4:
            raise ConfigError(f"table_points must be >= 4 or None, got {table_points}", "smc")
        self.table_points = None if table_points is None else int(table_points)
        if keep_gamma is not None and not 0.0 < keep_gamma < 1.0:
            raise ConfigError(f"keep_gamma must lie in (0, 1), got {keep_gamma}", "smc")
        self.keep_gamma = keep_gamma
        self.final_resample = bool(final_resample)
        self.tables: LogTables | None = None
        self.nfev = 0
        self.n_nonfinite = 0
        #: One dict per tempering step so far (the result's ``history``; readable while
        #: :meth:`steps` runs, e.g. after stopping it early).
        self.history: list[dict[str, Any]] = []

    @property
    def dim(self) -> int:
        return len(self.priors)

    # -- densities ------------------------------------------------------------------------
    def log_prior(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """log p(x) = sum_j log p_j(x_j) for an array (M, d)."""
        if self.tables is not None:
            return self.tables.log_prior(x)
        out = np.zeros(len(x))
        for j, prior in enumerate(self.priors):
            if prior.kind == "uniform":  # scipy's numbers without its ~0.3 ms per call
                lo, hi = prior.params["lower"], prior.params["upper"]
                v = x[:, j]
                out += np.where((v >= lo) & (v <= hi), -math.log(hi - lo), -np.inf)
            else:
                out += prior.logpdf(x[:, j])
        return np.where(np.isnan(out), -np.inf, out)

    def _loglik(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        if len(x) == 0:
            return np.zeros(0)
        f = self.log_likelihood if self.tables is None else self.tables.log_likelihood
        values = np.asarray(f(x), dtype=float)
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
    def _stalled(
        self,
        gamma: float,
        loglik: NDArray[np.float64],
        log_w: NDArray[np.float64],
        history: Sequence[dict[str, Any]] = (),
    ) -> str:
        """Why the tempering did not reach gamma = 1 within max_steps, and what to change."""
        return stall_message(
            gamma=gamma,
            max_steps=self.max_steps,
            zeta=self.zeta,
            ess_min=self.ess_min,
            loglik=loglik,
            log_w=log_w,
            history=history,
            dim=self.dim,
            rejuvenate=self.rejuvenate,
            training_range=self.training_range,
        )

    def steps(self) -> Generator[SmcState, None, SmcResult]:
        """Run Algorithm 1; yield after each tempering step, return the :class:`SmcResult`."""
        rng, n = self.rng, self.n_particles
        table_note = self._build_tables()
        x = np.column_stack([p.rvs(n, rng) for p in self.priors]).astype(float)
        log_prior = self.log_prior(x)
        loglik = self._loglik(x)
        if not np.any(np.isfinite(loglik)):
            raise ConfigError("the log-likelihood is -inf or NaN at every prior draw", "smc")
        log_w = np.full(n, -math.log(n))  # normalised after every step
        ess_now = float(n)
        tempering = EssTempering(self.zeta, n)
        inc, u = np.empty(n), np.empty(n)
        gamma = 0.0
        gammas, ess_hist, accept_hist = [0.0], [float(n)], []
        history: list[dict[str, Any]] = []
        self.history = history
        log_evidence, log_evidence_var = 0.0, 0.0
        # the segment since the particles last moved or were resampled (evidence error)
        seg_start: NDArray[np.float64] | None = None
        seg_gamma, seg_ess, seg_log_z = 0.0, float(n), 0.0
        acceptance = 1.0
        step = 0
        tempered: SmcResult | None = None
        while gamma < 1.0:
            t0 = time.perf_counter()
            step += 1
            if step > self.max_steps:
                raise ConfigError(self._stalled(gamma, loglik, log_w, history), "smc")
            new_gamma = tempering.next_gamma(gamma, log_w, loglik, ess_now)
            if self.keep_gamma is not None and gamma < self.keep_gamma < new_gamma:
                new_gamma = self.keep_gamma  # a step ends exactly there (ESS above zeta's)
            t_gamma = time.perf_counter() - t0
            if seg_start is None:
                seg_start, seg_gamma, seg_ess, seg_log_z = log_w.copy(), gamma, ess_now, 0.0
            # Reweighting w_s = w_{s-1} exp((gamma_s - gamma_{s-1}) L) (L = -inf: weight 0), its
            # evidence factor sum_i W_{s-1}^i exp(...) and the ESS, in one exponential pass.
            np.multiply(loglik, new_gamma - gamma, out=inc)
            log_w += inc
            top = float(log_w.max())
            np.subtract(log_w, top, out=u)
            np.exp(u, out=u)
            s1 = float(u.sum())
            current_ess = s1 * s1 / float(u @ u)
            log_z_inc = top + math.log(s1)
            log_w -= log_z_inc
            log_evidence += log_z_inc
            seg_log_z += log_z_inc
            gamma = new_gamma
            # resample when the ESS fell below ess_min, and always at gamma = 1 (then moved):
            # the result's particles are equally weighted, so any tool's plain mean over them
            # (ArviZ's) is the weighted one, as with pymc's SMC
            resampled = current_ess < self.ess_min * n or (
                self.final_resample and gamma >= 1.0 and float(np.ptp(log_w)) > 1e-12
            )
            # the particles move in every step, or only when resampled, at gamma = 1 and at
            # keep_gamma (kept as a draw of the tempered density: moved, not only reweighted)
            move = self.n_rejuvenation > 0 and (
                self.rejuvenate == "every_step"
                or resampled
                or gamma >= 1.0
                or gamma == self.keep_gamma
            )
            if move or resampled or gamma >= 1.0:
                # Variance of the evidence factor of the steps since the particles last moved
                # or were resampled: one importance-sampling estimate with the same particles
                # (not independent steps), whose L has not changed since.
                ratio = np.exp((gamma - seg_gamma) * loglik - seg_log_z)
                w0 = np.exp(seg_start)
                log_evidence_var += float(np.sum(w0 * (ratio - 1.0) ** 2)) / max(seg_ess, 1.0)
                seg_start = None
            ess_now = current_ess
            if resampled:
                idx = systematic_resample(np.exp(log_w), rng)
                x, loglik, log_prior = x[idx], loglik[idx], log_prior[idx]
                log_w = np.full(n, -math.log(n))
                ess_now = float(n)
                tempering.invalidate()
            scale = SCALE_A + SCALE_B * acceptance
            t_move = time.perf_counter()
            if move:
                x, loglik, log_prior, acceptance = self._rejuvenate(
                    x, loglik, log_prior, log_w, gamma, scale
                )
                tempering.invalidate()
            t_move = time.perf_counter() - t_move
            gammas.append(gamma)
            ess_hist.append(current_ess)
            accept_hist.append(acceptance)
            if gamma == self.keep_gamma:
                tempered = SmcResult(
                    particles=x.copy(),
                    weights=np.exp(log_w - logsumexp(log_w)),
                    log_likelihood=loglik.copy(),
                    log_prior=log_prior.copy(),
                    log_evidence=log_evidence,
                    log_evidence_se=math.sqrt(log_evidence_var),
                    gammas=list(gammas),
                    ess=list(ess_hist),
                    acceptance=list(accept_hist),
                    nfev=self.nfev,
                    names=self.names,
                )
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
                    "seconds_gamma": t_gamma,
                    "seconds_move": t_move,
                }
            )
            logger.debug(
                "tempering step %d: gamma %.6g, ESS %.1f of %d, %s, acceptance %.2f, "
                "%d likelihood evaluations",
                step,
                gamma,
                current_ess,
                n,
                ("resampled, " if resampled else "") + ("moved" if move else "not moved"),
                acceptance,
                self.nfev,
            )
            yield SmcState(step, gamma, current_ess, resampled, acceptance, log_evidence, self.nfev)
        weights = np.exp(log_w - logsumexp(log_w))
        table = self._check_tables(x, weights, table_note)
        logger.info(
            "SMC: %d particles to gamma = 1 in %d tempering steps, %.2f s, %d likelihood "
            "evaluations, log evidence %.6g +- %.2g",
            n,
            len(gammas) - 1,
            time.perf_counter() - t0,
            self.nfev,
            log_evidence,
            math.sqrt(log_evidence_var),
        )
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
            table=table,
            tempered=tempered,
        )

    def _build_tables(self) -> str | None:
        """Tabulate L and the log-priors when ``table_points`` asks for it and the problem
        allows it; returns why not (None: built, or not asked for)."""
        self.tables = None
        if self.table_points is None:
            return None
        why = tabulable(self.priors)
        if why is None:
            try:
                self.tables = LogTables.build(self.log_likelihood, self.priors, self.table_points)
            except ValueError as exc:
                why = str(exc)
        return why

    def _check_tables(
        self, x: NDArray[np.float64], weights: NDArray[np.float64], note: str | None
    ) -> dict[str, Any] | None:
        """The table's error against the real L at up to 2000 distinct final particles."""
        if self.tables is None:
            return None if note is None else {"note": f"no table: {note}"}
        idx = np.unique(systematic_resample(weights, np.random.default_rng(0)))
        if len(idx) > 2000:
            idx = np.random.default_rng(1).choice(idx, 2000, replace=False)
        return {**self.tables.describe(), **self.tables.check(self.log_likelihood, x[idx])}

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
        if self.tables is not None:
            self.nfev += n * self.n_rejuvenation
            return self.tables.move(x, loglik, log_prior, factor, gamma, self.n_rejuvenation, rng)
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
    max_steps: int | None = None,
    rejuvenate: str = "every_step",
    training_range: tuple[float, float] | None = None,
    table_points: int | None = None,
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
        training_range=training_range,
        table_points=table_points,
    )
    return sampler.run()
