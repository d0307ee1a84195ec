"""Gaussian-process surrogate of the log-likelihood (Paper B, appendix eq. 26-29, Remarks 9-10).

>>> import numpy as np
>>> from fbia.iterators.surrogates.gp import GpSurrogate
>>> rng = np.random.default_rng(0)
>>> x = rng.random((60, 2))
>>> log_lik = -((x[:, 0] - 0.4) ** 2 + 2 * (x[:, 1] - 0.6) ** 2) / 0.05
>>> gp = GpSurrogate(ard=True).fit(x, log_lik, rng=rng)
>>> bool(abs(gp.predict_mean(np.array([[0.4, 0.6]]))[0]) < 0.5)   # true maximum 0
True

The surrogate is a GP with constant prior mean m = min(L) - 1.0 (max(L) - min(L))
(Remark 10, so that the surrogate falls off far from the data), a Matérn 3/2 kernel (eq. 27)
with one length scale, or a product of 1-D Matérn 3/2 kernels with one length scale per input
(Remark 9, "ARD"), inputs standardised with the mean and standard deviation of the training
inputs (and, given ``axes``, rotated to the principal axes of a covariance, below), and a
fixed nugget variance sigma_n^2 = 1e-5 (max(L) - min(L)) (Paper B, §"Convergence over number
of training points"). Signal variance and length scales maximise the evidence
(eq. 29) with GPy's L-BFGS-B (default, with restarts from seeded initial guesses) or scaled
conjugate gradients.

Only the posterior mean (eq. 28a) is needed inside SMC: :meth:`GpSurrogate.predict_mean`
evaluates k(x*, X) alpha for all particles at once, with the weight vector
alpha = (K + sigma_n^2 I)^-1 (y - m) computed once after training; no variances.
:meth:`GpSurrogate.predict_mean_guarded` caps that mean at the largest training value plus a
margin (:func:`~fbia.iterators.smc.diagnostics.extrapolation_margin`, chi2_d(0.999) / 2 units
of L), counts the capped points in ``guard``, and :meth:`GpSurrogate.extrapolated_mass` gives
the posterior mass an SMC result puts where the cap bites: a sampler cannot be pulled into a
region where the surrogate invents evidence without it showing.

**Rotated inputs** (``fit(..., axes=cov)``): a product kernel has its length scales along the
input axes, so a posterior that is a narrow ridge across them (in Paper B's example 8 the
inflow against E_2: its principal standard deviations span 0.005 to 0.26 of the box) needs
short length scales in every input the ridge crosses, everywhere. Given a covariance of the
inputs (an adaptive design's current posterior), the standardised inputs u are rotated to its
principal axes, z = u V with C_u = V diag(lambda) V^T the covariance in units of u, so that
one length scale runs across the ridge and the others along it (the rotation of "active
subspace" and whitened-input GPs; Constantine 2015, ch. 4; Garnett, Osborne, Hennig 2014).
Measured on example 8's first 3396 adaptive runs (GP of D, ARD, held-out at the next 302
posterior draws): RMSE in L 6.8 on the input axes, 2.3 rotated (median |error| 0.89, 0.20).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...core.errors import ConfigError
from .guard import ExtrapolationGuard, GuardCounts
from .mean import SQRT3, KernelTerms, fused_mean
from .trend import QuadraticTrend

logger = logging.getLogger(__name__)

#: Entries of one block of the cross-kernel matrix k(x*, X) evaluated at once (memory bound).
_BLOCK = 1 << 18
OPTIMIZERS = ("lbfgsb", "scg")
#: Bounds of the length scales (standardised inputs) and of the signal variance (in units of
#: (max L - min L)^2) during training.
LENGTHSCALE_BOUNDS = (1e-3, 1e2)
VARIANCE_BOUNDS = (1e-4, 1e4)
#: a warm-started re-optimisation (an adaptive design's later rounds) with more training
#: points than this searches the hyperparameters on a random subset of this many points and
#: conditions on all of them: an evidence step costs ~ n^3, and hyperparameters that already
#: fit the earlier rounds move little (issue 42: at 992 runs of the 6 + 1-D case the 20 warm
#: component fits took 31 s on all points)
WARM_SUBSET = 300
#: what GPy's exact inference adds to the diagonal of K + sigma_n^2 I (scaled units): the
#: GPs conditioned without GPy add it too, so that they are the GPs it trained
GPY_JITTER = 1e-8


def blas_single_thread() -> contextlib.AbstractContextManager[Any]:
    """Limit BLAS to one thread (if ``threadpoolctl`` is installed).

    The matrices here are small to moderate (n_train <= a few thousand) and the machines are
    shared: threaded BLAS on an oversubscribed machine made GPy's training 10x slower.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _gpy() -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import GPy
    return GPy


def matern32_cross(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    lengthscale: NDArray[np.float64],
    variance: float,
    product: bool,
) -> NDArray[np.float64]:
    """Matérn 3/2 cross-covariance k(a, b) (eq. 27), shape (len(a), len(b)).

    ``product=False``: one kernel of the Euclidean distance scaled by one length scale
    (``lengthscale`` of length 1). ``product=True``: the product of 1-D Matérn 3/2 kernels,
    one length scale per dimension (Remark 9):
    k = sigma^2 prod_j (1 + sqrt3 |r_j|) exp(-sqrt3 sum_j |r_j|), r_j = (a_j - b_j) / l_j.
    """
    if not product:
        sa = a / lengthscale[0]
        sb = b / lengthscale[0]
        r2 = (sa * sa).sum(1)[:, None] + (sb * sb).sum(1)[None, :] - 2.0 * (sa @ sb.T)
        np.maximum(r2, 0.0, out=r2)
        r = np.sqrt(r2, out=r2)
        r *= SQRT3
        k = 1.0 + r
        np.negative(r, out=r)
        np.exp(r, out=r)
        k *= r
        k *= variance
        return k
    from .kernels import product_kernel  # compiled, one pass (GPy's import: on first use)

    sa = np.ascontiguousarray(a * (SQRT3 / lengthscale))
    sbt = np.ascontiguousarray((b * (SQRT3 / lengthscale)).T)
    return np.asarray(product_kernel(sa, sbt, float(variance)))


def principal_axes(cov: ArrayLike, x_std: NDArray[np.float64]) -> NDArray[np.float64]:
    """The eigenvectors (columns, orthonormal) of the covariance ``cov`` of the inputs in units
    of their standard deviations ``x_std``: the axes of :meth:`GpSurrogate.fit`'s ``axes``."""
    c = np.atleast_2d(np.asarray(cov, dtype=float))
    if c.shape != (len(x_std), len(x_std)) or not np.all(np.isfinite(c)):
        raise ConfigError(
            f"GP axes: a finite {len(x_std)} x {len(x_std)} covariance is needed, got {c.shape}",
            "gp",
        )
    c_u = c / np.outer(x_std, x_std)
    _, vectors = np.linalg.eigh(0.5 * (c_u + c_u.T))
    return np.asarray(vectors, dtype=np.float64)


def gaussian_paths(
    mean: NDArray[np.float64], cov: NDArray[np.float64], n_paths: int, rng: np.random.Generator
) -> tuple[NDArray[np.float64], float]:
    """``n_paths`` draws of N(mean, cov) as columns (M, K), and the jitter that was needed.

    Close points make the covariance numerically singular: the diagonal grows from 1e-12 of
    its largest entry by factors of 100 until the Cholesky factorisation succeeds (jitter up
    to 1e-4 of the largest variance), else the eigenvalues are clipped at zero (jitter NaN).
    """
    cov = 0.5 * (cov + cov.T)
    top = float(np.max(np.diag(cov), initial=0.0))
    z = rng.standard_normal((len(mean), n_paths))
    for rel in (0.0, 1e-12, 1e-10, 1e-8, 1e-6, 1e-4):
        jitter = rel * top
        try:
            chol = np.linalg.cholesky(cov + jitter * np.eye(len(mean)))
        except np.linalg.LinAlgError:
            continue
        return mean[:, None] + chol @ z, jitter
    vals, vecs = np.linalg.eigh(cov)
    return mean[:, None] + (vecs * np.sqrt(np.maximum(vals, 0.0))) @ z, math.nan


@dataclass(frozen=True)
class GpCovariance:
    """The posterior covariance of a GP among a fixed set of points (eq. 28b), in units of
    L^2, by blocks: c(a, b) = k(a, b) - v_a^T v_b with v = L^-1 k(X, .) solved once for all
    the points (:meth:`GpSurrogate.covariance_on`). An adaptive design's criterion needs a
    few blocks of it, not all of it (:func:`~fbia.iterators.gp_smc.adaptive.select_batch`)."""

    xs: NDArray[np.float64]  # the points, standardised
    v: NDArray[np.float64]  # L^-1 k(X, xs), (n_runs, points)
    lengthscale: NDArray[np.float64]
    variance_k: float  # the kernel's variance (standardised units)
    product: bool
    scale: float

    def block(self, rows: ArrayLike, cols: ArrayLike) -> NDArray[np.float64]:
        """c between the points ``rows`` and ``cols`` (index arrays), (len(rows), len(cols))."""
        i, j = np.asarray(rows), np.asarray(cols)
        k = matern32_cross(self.xs[i], self.xs[j], self.lengthscale, self.variance_k, self.product)
        return np.asarray((k - self.v[:, i].T @ self.v[:, j]) * self.scale**2)

    def variance(self, rows: ArrayLike) -> NDArray[np.float64]:
        """The diagonal of :meth:`block` at ``rows`` (the variance of :meth:`GpSurrogate.predict`,
        not clipped at 0)."""
        i = np.asarray(rows)
        return np.asarray((self.variance_k - np.sum(self.v[:, i] ** 2, axis=0)) * self.scale**2)

    def predictive_variance(self, rows: ArrayLike) -> NDArray[np.float64]:
        """The variance of :meth:`GpSurrogate.predict` at ``rows`` (clipped at 0)."""
        return np.maximum(self.variance(rows), 0.0)


def covariance_between(surrogate: Any, a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """The block between the rows of ``a`` and ``b`` of ``surrogate.covariance_on`` over
    both (one solve for both; one set when ``b is a``): ``posterior_covariance`` of the GP
    and of the residual emulator."""
    xa = np.atleast_2d(np.asarray(a, dtype=float))
    if b is a:
        rows = np.arange(len(xa))
        return np.asarray(surrogate.covariance_on(xa).block(rows, rows))
    xb = np.atleast_2d(np.asarray(b, dtype=float))
    cov = surrogate.covariance_on(np.vstack([xa, xb]))
    return np.asarray(cov.block(np.arange(len(xa)), np.arange(len(xa), len(xa) + len(xb))))


class GpSurrogate(ExtrapolationGuard):
    """GP regression model of the log-likelihood L(x) (Paper B, eq. 26-29).

    Parameters
    ----------
    ard
        One length scale per input as a product of 1-D Matérn 3/2 kernels (Remark 9) instead
        of a single length scale for all standardised inputs.
    optimizer
        ``"lbfgsb"`` (L-BFGS-B, default) or ``"scg"`` (scaled conjugate gradients).
    restarts
        Additional optimisations from random initial guesses around the data-based one (the
        best evidence wins); 0: only the data-based initial guess.
    max_iters
        Iteration limit of each optimisation.
    nugget_factor
        sigma_n^2 = nugget_factor (max L - min L) (Paper B: 1e-5), fixed.
    mean_offset
        m = min L - mean_offset (max L - min L) (Remark 10: 1.0).
    gpy_default
        Train the way GPy does by default (initial variance 1 and length scale 1, one
        optimisation, no restarts, no bounds); for comparison in benchmarks.
    subset
        With more training points than this, the restarts run on the first ``subset`` points
        (for a Sobol design a space-filling prefix; cost ~ n^3), and the best hyperparameters
        are refined on all points with at most ``polish_iters`` iterations.
    polish_iters
        Iteration limit of that refinement on all points.
    guard_margin
        Units of L above the largest training value where :meth:`predict_mean_guarded` caps
        the mean; ``None``: chi2_d(0.999) / 2 (12.2 for d = 7, see
        :func:`~fbia.iterators.smc.diagnostics.extrapolation_margin`).
    """

    def __init__(
        self,
        ard: bool = False,
        optimizer: str = "lbfgsb",
        restarts: int = 2,
        max_iters: int = 1000,
        nugget_factor: float = 1e-5,
        mean_offset: float = 1.0,
        gpy_default: bool = False,
        subset: int = 800,
        polish_iters: int = 60,
        guard_margin: float | None = None,
        trend: str = "constant",
    ) -> None:
        if optimizer not in OPTIMIZERS:
            raise ConfigError(
                f"unknown GP optimizer {optimizer!r}; valid: {', '.join(OPTIMIZERS)}", "gp"
            )
        if restarts < 0 or max_iters < 1:
            raise ConfigError(f"restarts must be >= 0 and max_iters >= 1, got {restarts}", "gp")
        if not nugget_factor > 0:
            raise ConfigError(f"nugget_factor must be positive, got {nugget_factor}", "gp")
        self.ard = bool(ard)
        self.optimizer = optimizer
        self.restarts = int(restarts)
        self.max_iters = int(max_iters)
        self.nugget_factor = float(nugget_factor)
        self.mean_offset = float(mean_offset)
        self.gpy_default = bool(gpy_default)
        if subset < 2 or polish_iters < 1:
            raise ConfigError(f"subset must be >= 2 and polish_iters >= 1, got {subset}", "gp")
        self.subset = int(subset)
        self.polish_iters = int(polish_iters)
        self.model: Any = None
        self.info: dict[str, Any] = {}
        self._chol: NDArray[np.float64] | None = None  # set when restored (from_state)
        #: orthogonal (d, d): standardised inputs u enter the kernel as u @ rotation (fit's axes)
        self.rotation: NDArray[np.float64] | None = None
        if guard_margin is not None and not guard_margin >= 0:
            raise ConfigError(f"guard_margin must be >= 0, got {guard_margin}", "gp")
        self.guard_margin = guard_margin
        if trend not in ("constant", "quadratic"):
            raise ConfigError(f"unknown GP trend {trend!r}; valid: constant, quadratic", "gp")
        self.trend_kind = trend
        self.trend: QuadraticTrend | None = None
        self.guard = GuardCounts()

    # -- training -------------------------------------------------------------------------
    def fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        rng: np.random.Generator | int | None = None,
        start: Mapping[str, Any] | None = None,
        axes: ArrayLike | None = None,
        optimise: bool = True,
    ) -> GpSurrogate:
        """Train on inputs ``x`` (n, d) and log-likelihood values ``y`` (n,); returns self.

        ``start``: the :meth:`hyperparameters` of an earlier fit on part of these data (an
        adaptive design's previous round) as the first initial guess, instead of the data-based
        one and the search on a subset; ``restarts`` perturb it. ``axes``: a (d, d) covariance
        of the inputs (in their units) whose principal axes the kernel's axes follow (module
        docstring); None: the input axes. ``optimise = False`` (with ``start``): keep those
        hyperparameters and only condition on the data (one Cholesky factorisation instead
        of an evidence maximisation, whose every step costs one; an adaptive design between
        its re-optimisations). Warm-started on more than :data:`WARM_SUBSET` points, the
        search runs on a random subset of that many and the GP is conditioned on all.
        Conditioning with given hyperparameters needs no GPy model (:meth:`_condition`).
        """
        if not optimise and start is None:
            raise ConfigError("a GP fit without optimisation needs start hyperparameters", "gp")
        with blas_single_thread():
            return self._fit(x, y, rng, start, axes, optimise)

    def _fit(
        self,
        x: ArrayLike,
        y: ArrayLike,
        rng: np.random.Generator | int | None,
        start: Mapping[str, Any] | None = None,
        axes: ArrayLike | None = None,
        optimise: bool = True,
    ) -> GpSurrogate:
        x = np.atleast_2d(np.asarray(x, dtype=float))
        y = np.asarray(y, dtype=float).ravel()
        if x.ndim != 2 or len(x) != len(y):
            raise ConfigError(f"GP training data: {x.shape} inputs for {y.shape} outputs", "gp")
        if len(y) < 2:
            raise ConfigError(f"the GP needs at least 2 training points, got {len(y)}", "gp")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ConfigError("GP training data must be finite", "gp")
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        t0 = time.perf_counter()
        self.info = {}
        self.x_train, self.y_train = x, y
        self.x_mean = x.mean(axis=0)
        self.x_std = x.std(axis=0)
        self.x_std[self.x_std == 0] = 1.0
        self.rotation = None if axes is None else principal_axes(axes, self.x_std)
        # the prior mean: Remark 10's constant, or a concave quadratic (gp_trend) plus 0
        self.trend = QuadraticTrend.fit(x, y) if self.trend_kind == "quadratic" else None
        y_fit = y if self.trend is None else y - self.trend(x)
        y_range = float(y_fit.max() - y_fit.min())
        # Output scale: the data are fitted as (y - m) / scale; the nugget stays
        # nugget_factor * range in units of L^2 (Paper B), i.e. nugget_factor * range / scale^2.
        self.scale = y_range if y_range > 0 else max(1.0, abs(float(y_fit.max())))
        self.mean_value = float(y.min() - self.mean_offset * y_range) if self.trend is None else 0.0
        self.nugget = self.nugget_factor * (y_range if y_range > 0 else self.scale)
        xs = self.standardise(x)
        ys = ((y_fit - self.mean_value) / self.scale)[:, None]
        # hyperparameters to condition on without an evidence maximisation: kept (optimise =
        # False), or searched on a random subset when warm-started on many points
        kept: tuple[float, NDArray[np.float64]] | None = None
        if not optimise and not self.gpy_default:
            assert start is not None
            kept = self._carried(start)
        elif start is not None and len(y) > WARM_SUBSET and not self.gpy_default:
            pick = np.sort(rng.choice(len(y), size=WARM_SUBSET, replace=False))
            pre = self._like().fit(x[pick], y[pick], rng, start=start, axes=axes)
            kept = self._carried(pre.hyperparameters())
            self.info["subset_search"] = pre.describe()
        if kept is not None:
            obj = self._condition(*kept)
            how = (
                f"{self.optimizer} on a subset of {WARM_SUBSET}"
                if optimise
                else "none (hyperparameters kept)"
            )
            return self._trained(t0, obj, how, [])
        model = self._gpy_model(xs, ys)
        self.model = model
        max_iters = self.max_iters
        starts: list[Any]
        if self.gpy_default:
            starts = [None]
        elif start is not None:
            starts = self._warm_starts(start, rng)
        elif len(y) > self.subset:
            # Hyperparameter search on a prefix of the design, then a refinement on all points.
            pre = self._like().fit(x[: self.subset], y[: self.subset], rng, axes=axes)
            starts = [self._carried(pre.hyperparameters())]
            max_iters = self.polish_iters
            self.info["subset_search"] = pre.describe()
        else:
            starts = self._initial_guesses(xs, ys, rng)
        best, best_obj, runs = None, math.inf, []
        for guess in starts:
            if guess is not None:
                self._set_hyper(*guess)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    model.optimize(self.optimizer, max_iters=max_iters, messages=False)
                except np.linalg.LinAlgError as exc:
                    runs.append({"start": guess, "error": str(exc)})
                    continue
            obj = float(model.objective_function())
            runs.append({"start": guess, "neg_log_evidence": obj})
            if math.isfinite(obj) and obj < best_obj:
                best, best_obj = model.param_array.copy(), obj
        if best is None:
            raise ConfigError("GP training failed from every initial guess", "gp")
        if not np.array_equal(model.param_array, best):
            model[:] = best
        self._precompute()
        return self._trained(t0, best_obj, self.optimizer, runs)

    def _gpy_model(self, xs: NDArray[np.float64], ys: NDArray[np.float64]) -> Any:
        """The GPy model whose evidence the hyperparameters maximise (eq. 29)."""
        gpy = _gpy()
        d = xs.shape[1]
        if self.ard:
            from .kernels import Matern32Product

            kern = Matern32Product(d)
        else:
            kern = gpy.kern.Matern32(d, ARD=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if not self.gpy_default:
                # Bounds keep the evidence maximisation away from the degenerate limit
                # l -> inf, sigma^2 -> inf that a nearly noise-free smooth L invites.
                kern.lengthscale.constrain_bounded(*LENGTHSCALE_BOUNDS, warning=False)
                kern.variance.constrain_bounded(*VARIANCE_BOUNDS, warning=False)
            noise = gpy.likelihoods.Gaussian(variance=self.nugget / self.scale**2)
            noise.variance.fix()
            # constraints and the fixed nugget are set on the parts before the model exists:
            # GPy conditions a model again (a Cholesky factorisation and an inverse) at every
            # change of a parameter or constraint, here once at construction
            return gpy.core.GP(xs, ys, kern, noise, name="gp")

    def _trained(
        self, t0: float, neg_log_evidence: float, how: str, runs: list[dict[str, Any]]
    ) -> GpSurrogate:
        """Record how the fit went (``info``); returns self."""
        self.info = {
            **self.info,
            "seconds": time.perf_counter() - t0,
            "n_train": len(self.y_train),
            "neg_log_evidence": neg_log_evidence,
            "optimizer": how,
            "restarts": len(runs),
            "runs": runs,
            **self.hyperparameters(),
        }
        logger.info(
            "GP fit: %d points, %s, %.2f s; signal variance %.4g, length scales %s, "
            "nugget %.3g, -log evidence %.6g",
            self.info["n_train"],
            how,
            self.info["seconds"],
            self.info["signal_variance"],
            "[" + ", ".join(f"{v:.3g}" for v in self.info["lengthscales"]) + "]",
            self.info["nugget_variance"],
            neg_log_evidence,
        )
        return self

    def _condition(self, variance: float, lengthscale: NDArray[np.float64]) -> float:
        """Condition on the training data with these hyperparameters (units of the scaled
        data): the Cholesky factor of K + sigma_n^2 I (+ :data:`GPY_JITTER`, GPy's jittered
        Cholesky: as its exact inference) and alpha, without a GPy model (a GPy model computes
        the inverse and the evidence's gradients too: 0.12 s against 0.02 s for 1000 points
        in 7-D); returns the negative log evidence."""
        from GPy.util.linalg import jitchol
        from scipy.linalg import cho_solve

        self.__dict__.pop("_terms", None)
        self.__dict__.pop("_kinv_diag", None)
        self._var = float(variance)
        self._ell = np.asarray(lengthscale, dtype=float)
        self._xs = self.standardise(self.x_train)
        k = matern32_cross(self._xs, self._xs, self._ell, self._var, self.ard)
        k[np.diag_indices_from(k)] += self.nugget / self.scale**2 + GPY_JITTER
        chol = np.asarray(jitchol(k), dtype=np.float64)
        self._chol = chol
        ys = (self.y_train - self.prior_mean(self.x_train)) / self.scale
        self._alpha = np.asarray(cho_solve((chol, True), ys))
        self.model = None
        n = len(ys)
        return float(
            0.5 * ys @ self._alpha + np.log(np.diag(chol)).sum() + 0.5 * n * math.log(2 * math.pi)
        )

    def _like(self) -> GpSurrogate:
        """An untrained GP with this one's settings (for a search on a subset)."""
        return GpSurrogate(
            ard=self.ard,
            optimizer=self.optimizer,
            restarts=self.restarts,
            max_iters=self.max_iters,
            nugget_factor=self.nugget_factor,
            mean_offset=self.mean_offset,
            subset=self.subset,
            trend=self.trend_kind,
        )

    def standardise(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The rows of ``x`` as the kernel sees them: standardised, then turned (axes)."""
        u = (np.asarray(x, dtype=float) - self.x_mean) / self.x_std
        return u if self.rotation is None else u @ self.rotation

    def _initial_guesses(self, xs, ys, rng) -> list[tuple[float, NDArray[np.float64]]]:
        """A data-based guess (signal variance = mean square of y - m, length scale = median
        distance to the nearest neighbour times 4, in standardised units), then log-uniform
        perturbations of it (a factor up to 10 either way)."""
        d = xs.shape[1]
        sub = xs[rng.choice(len(xs), size=min(len(xs), 500), replace=False)]
        dist = np.sqrt(((sub[:, None, :] - sub[None, :, :]) ** 2).sum(-1))
        np.fill_diagonal(dist, np.inf)
        nn = float(np.median(dist.min(axis=1)))
        ell0 = float(np.clip(4.0 * nn, 0.05, 10.0))
        var0 = float(np.clip(np.mean(ys**2), 1e-3, 1e3))
        n_ell = d if self.ard else 1
        guesses = [(var0, np.full(n_ell, ell0))]
        for _ in range(self.restarts):
            f_var = 10.0 ** rng.uniform(-1.0, 1.0)
            f_ell = 10.0 ** rng.uniform(-0.7, 0.7, size=n_ell)
            guesses.append((var0 * f_var, ell0 * f_ell))
        return guesses

    def _warm_starts(
        self, hp: Mapping[str, Any], rng: np.random.Generator
    ) -> list[tuple[float, NDArray[np.float64]]]:
        """Earlier hyperparameters in this fit's units (:meth:`_carried`), then ``restarts``
        log-uniform perturbations of them."""
        var, ells = self._carried(hp)
        guesses = [(var, ells)]
        for _ in range(self.restarts):
            f_ell = 10.0 ** rng.uniform(-0.5, 0.5, size=len(ells))
            guesses.append((var * 10.0 ** rng.uniform(-1.0, 1.0), guesses[0][1] * f_ell))
        return guesses

    def _carried(self, hp: Mapping[str, Any]) -> tuple[float, NDArray[np.float64]]:
        """Hyperparameters ``hp`` of another fit in this fit's units: the same variance in L^2
        and, with a product kernel, the length scales whose quadratic form R diag(l^-2) R^T
        (R: the kernel's axes) is the other fit's, moved to this fit's standardisation and
        read along this fit's axes (the axes turn between adaptive rounds, gp_axes)."""
        ratio = np.asarray(hp["x_std"], dtype=float) / self.x_std  # old std / new std
        ells = np.asarray(hp["lengthscales"], dtype=float)
        if not self.ard:
            ells = ells * ratio.mean()
        else:
            eye = np.eye(len(ratio))
            old = eye if hp.get("rotation") is None else np.asarray(hp["rotation"], dtype=float)
            new = eye if self.rotation is None else self.rotation
            precision = (old / ells**2) @ old.T / np.outer(ratio, ratio)
            ells = 1.0 / np.sqrt(np.einsum("ik,ij,jk->k", new, precision, new))
        var = float(np.clip(hp["signal_variance"] / self.scale**2, *VARIANCE_BOUNDS))
        return var, np.clip(ells, *LENGTHSCALE_BOUNDS)

    def _set_hyper(self, variance: float, lengthscale: NDArray[np.float64]) -> None:
        """Signal variance and length scales at once (GPy conditions the model once)."""
        values = np.array(self.model.param_array, dtype=float)
        values[0] = variance
        values[1 : 1 + len(lengthscale)] = lengthscale
        self.model[:] = values

    def hyperparameters(self) -> dict[str, Any]:
        """Signal variance (in L^2), length scales (standardised inputs), nugget, prior mean."""
        if self.model is not None:
            variance = float(self.model.kern.variance[0])
            ells = [float(v) for v in np.atleast_1d(self.model.kern.lengthscale)]
        else:  # trained (the GPy model is let go) or restored
            variance, ells = float(self._var), [float(v) for v in self._ell]
        return {
            "kernel": "matern32_product" if self.ard else "matern32",
            "signal_variance": variance * self.scale**2,
            "lengthscales": ells,
            "nugget_variance": self.nugget,
            "prior_mean": self.mean_value,
            "x_mean": self.x_mean.tolist(),
            "x_std": self.x_std.tolist(),
            **({} if self.rotation is None else {"rotation": self.rotation.tolist()}),
        }

    def _precompute(self) -> None:
        """alpha = (K + sigma_n^2 I)^-1 (y - m) / scale, the Cholesky factor of K + sigma_n^2
        I, the diagonal of its inverse (leave-one-out) and the kernel constants (eq. 28a);
        then the GPy model is let go: it holds several n x n matrices (K, its inverse, the
        gradient's), and a residual emulator has up to 20 such GPs (1.6 GB at 1000 runs,
        where these need 160 MB)."""
        self.__dict__.pop("_terms", None)
        hp = self.hyperparameters()
        posterior = self.model.posterior
        self._alpha = np.asarray(posterior.woodbury_vector, dtype=float).ravel()
        self._chol = np.array(posterior.woodbury_chol, dtype=float)
        self._kinv_diag = np.array(np.diag(posterior.woodbury_inv), dtype=float)
        self._ell = np.asarray(hp["lengthscales"], dtype=float)
        self._var = hp["signal_variance"] / self.scale**2
        self._xs = self.standardise(self.x_train)
        self.model = None

    # -- prediction -----------------------------------------------------------------------
    def kernel_terms(self) -> KernelTerms:
        """The posterior mean's terms for the compiled loops (:mod:`.mean`), built once."""
        if "_terms" not in self.__dict__:
            f = self.scale * self._var
            self._terms = KernelTerms.of(self.ard, self._ell, self._xs, self._alpha, f)
        return self._terms

    def predict_mean(self, x: ArrayLike, fused: bool | None = None) -> NDArray[np.float64]:
        """Posterior mean of L at the rows of ``x`` (M, d) (eq. 28a), all points at once.

        ``fused``: compiled numba loops (:mod:`.mean`; ``None``: from 64 points on;
        ``True``: always) or numpy blocks (``False``).
        """
        if not hasattr(self, "_alpha"):
            raise ConfigError("the GP surrogate is not trained yet (call fit)", "gp")
        xs = self.standardise(np.atleast_2d(x))
        if fused is not False and (fused or len(xs) >= 64):
            return self.prior_mean(x) + fused_mean(self.kernel_terms(), xs)
        out = np.empty(len(xs))
        rows = max(1, _BLOCK // max(1, len(self._xs)))
        for i in range(0, len(xs), rows):
            k = matern32_cross(xs[i : i + rows], self._xs, self._ell, self._var, self.ard)
            out[i : i + rows] = k @ self._alpha
        return self.prior_mean(x) + self.scale * out

    __call__ = predict_mean

    def prior_mean(self, x: ArrayLike) -> NDArray[np.float64]:
        """The GP's prior mean of L at the rows of ``x``: constant, or the quadratic trend."""
        if self.trend is None:
            return np.full(len(np.atleast_2d(x)), self.mean_value)
        return self.trend(np.atleast_2d(np.asarray(x, dtype=float)))

    def predict(self, x: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Posterior mean and variance of L (eq. 28a-b) (for the design, plots, checks)."""
        from scipy.linalg import solve_triangular

        if self._chol is None:
            raise ConfigError("the GP surrogate is not trained yet (call fit)", "gp")
        xs = self.standardise(np.atleast_2d(x))
        var_s = np.empty(len(xs))
        rows = max(1, _BLOCK // max(1, len(self._xs)))
        for i in range(0, len(xs), rows):
            k = matern32_cross(self._xs, xs[i : i + rows], self._ell, self._var, self.ard)
            v = solve_triangular(self._chol, k, lower=True)
            var_s[i : i + rows] = self._var - np.sum(v * v, axis=0)
        return self.predict_mean(x), np.maximum(var_s, 0.0) * self.scale**2

    def posterior_covariance(self, a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
        """Posterior covariance of L between the rows of ``a`` (M, d) and ``b`` (P, d)
        (eq. 28b off the diagonal), in units of L^2: what conditioning on a new run at a
        point of ``b`` removes from the variance at ``a`` (an adaptive design's criterion)."""
        return covariance_between(self, a, b)

    def covariance_on(self, x: ArrayLike) -> GpCovariance:
        """The posterior covariance among the rows of ``x``, its blocks computed on demand
        (:class:`GpCovariance`): the triangular solve against the runs done once for all of
        them, the prior kernel only for the blocks asked for."""
        from scipy.linalg import solve_triangular

        if self._chol is None:
            raise ConfigError("the GP surrogate is not trained yet (call fit)", "gp")
        xs = self.standardise(np.atleast_2d(x))
        # v = L^-1 k(X, .), L the Cholesky factor of K + sigma_n^2 I: the triangular solve
        # keeps the small variances near the data accurate, where the explicit inverse loses
        # them to cancellation
        v = solve_triangular(
            self._chol, matern32_cross(self._xs, xs, self._ell, self._var, self.ard), lower=True
        )
        return GpCovariance(xs, v, self._ell, self._var, self.ard, self.scale)

    def predict_joint(self, x: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Posterior mean (M,) and full covariance (M, M) of the latent L at the rows of ``x``
        (eq. 28a-b with x* a set of points), in units of L; for joint sample paths."""
        return self.predict_mean(x), self.posterior_covariance(x, x)

    def sample_paths(
        self, x: ArrayLike, n_paths: int, rng: np.random.Generator
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """``n_paths`` joint sample paths of L at the rows of ``x`` (M, K), L's posterior
        standard deviation there (M,) and the jitter of the factorisation (eq. 28a-b)."""
        mean, cov = self.predict_joint(x)
        paths, jitter = gaussian_paths(mean, cov, n_paths, rng)
        return paths, np.sqrt(np.maximum(np.diag(cov), 0.0)), jitter

    # -- quality --------------------------------------------------------------------------
    def loo(self) -> dict[str, float]:
        """Leave-one-out errors (:meth:`loo_predictions`)."""
        return self._errors(self.y_train - self.loo_predictions(), self.y_train, prefix="loo")

    def loo_predictions(self) -> NDArray[np.float64]:
        """Leave-one-out predictions in closed form: y_i - alpha_i / [(K + sigma_n^2 I)^-1]_ii."""
        if "_kinv_diag" not in self.__dict__:  # restored: from the Cholesky factor, once
            from scipy.linalg import solve_triangular

            assert self._chol is not None
            inv = solve_triangular(self._chol, np.eye(len(self._chol)), lower=True)
            self._kinv_diag = np.sum(inv * inv, axis=0)
        return np.asarray(self.y_train - self.scale * self._alpha / self._kinv_diag)

    def test_error(self, x: ArrayLike, y: ArrayLike) -> dict[str, float]:
        """Errors of the posterior mean at held-out points (Paper B Remark 9, Fig. 12)."""
        y = np.asarray(y, dtype=float).ravel()
        return self._errors(self.predict_mean(x) - y, y, prefix="test")

    @staticmethod
    def _errors(res: NDArray[np.float64], y: NDArray[np.float64], prefix: str) -> dict[str, float]:
        spread = float(np.linalg.norm(y - y.mean())) or 1.0
        return {
            f"{prefix}_n": len(res),
            f"{prefix}_l2": float(np.linalg.norm(res)),
            f"{prefix}_rmse": float(np.sqrt(np.mean(res**2))),
            f"{prefix}_max_abs": float(np.max(np.abs(res))),
            f"{prefix}_relative_l2": float(np.linalg.norm(res)) / spread,
        }

    # -- persistence ----------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """Everything needed to rebuild the trained surrogate without GPy (arrays + floats)."""
        hp = self.hyperparameters()
        return {
            "ard": self.ard,
            "x_train": self.x_train,
            "y_train": self.y_train,
            "x_mean": self.x_mean,
            "x_std": self.x_std,
            "lengthscales": np.asarray(hp["lengthscales"]),
            "signal_variance": hp["signal_variance"],
            "nugget_variance": self.nugget,
            "prior_mean": self.mean_value,
            "scale": self.scale,
            "trend": None if self.trend is None else self.trend.state(),
            **({} if self.rotation is None else {"rotation": self.rotation}),
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> GpSurrogate:
        """Rebuild a trained surrogate from :meth:`state` (conditioning by Cholesky in numpy)."""
        gp = cls(ard=bool(state["ard"]))
        gp.x_train = np.asarray(state["x_train"], dtype=float)
        gp.y_train = np.asarray(state["y_train"], dtype=float)
        gp.x_mean = np.asarray(state["x_mean"], dtype=float)
        gp.x_std = np.asarray(state["x_std"], dtype=float)
        if state.get("rotation") is not None:
            gp.rotation = np.asarray(state["rotation"], dtype=float)
        gp.scale = float(state["scale"])
        gp.mean_value = float(state["prior_mean"])
        if state.get("trend") is not None:
            gp.trend = QuadraticTrend.from_state(state["trend"])
            gp.trend_kind = "quadratic"
        gp.nugget = float(state["nugget_variance"])
        gp._condition(
            float(state["signal_variance"]) / gp.scale**2,
            np.asarray(state["lengthscales"], dtype=float),
        )
        gp.info = {"n_train": len(gp.y_train), "restored": True}
        return gp

    def describe(self) -> Mapping[str, Any]:
        return {k: v for k, v in self.info.items() if k != "runs"}
