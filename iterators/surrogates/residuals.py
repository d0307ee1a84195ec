"""Gaussian-process emulator of the forward runs' residual vectors, and L from it.

Paper B's surrogate is a GP of the log-likelihood L itself. L = C - |r|^2 / (2 sigma_N^2)
(eq. 5) is a sharply peaked function of the parameters when the noise is small: along a
weakly identified direction (E against the inflow rate) its ridge is long and thin, and a
stationary GP of L needs many runs to follow it. The residuals r(x) of the measure are smooth
functions of the parameters (the interface moves smoothly with E, nu and the load), so a GP
emulator of r and L computed from the emulated residuals is far more accurate for the same
runs: "output emulation" with a principal-component basis (Higdon, Gattiker, Williams &
Rightley 2008; see docs/references.md).

Here u = r / sigma_N (dimensionless; L = C - |u|^2 / 2, with C = -n/2 log(2 pi sigma_N^2)),
or u = r [mm] when sigma_N is inferred (then the quantity emulated for the posterior is the
profile log-likelihood L^ = -n/2 (log(2 pi |u|^2 / n) + 1), see fbia.core.likelihood). The
centred training vectors u_i - mean are decomposed by SVD; the leading k components (until
the mean squared truncation error is below :data:`TRUNCATION`, at most
:data:`MAX_COMPONENTS`) each get a :class:`~fbia.iterators.surrogates.gp.GpSurrogate` of
their scores. The mean of L is the plug-in L(u^), u^ the emulated mean; variances and
covariances of L (for the adaptive design and the GP-uncertainty check) are first order in
the scores' GP uncertainty (delta method) plus the exact second-order variance term.

:class:`ResidualSurrogate` has the methods of ``GpSurrogate`` that gp_smc uses (mean,
guarded mean, variance, joint covariance, LOO and held-out errors, state), so the adaptive
design, the checks and the result work on either.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...core.errors import ConfigError
from ...core.likelihood import MIN_SQUARED_DISTANCE
from ...core.problem import Evaluation
from .feasibility import Feasibility
from .gp import GpCovariance, GpSurrogate, covariance_between, gaussian_paths
from .guard import ExtrapolationGuard, GuardCounts
from .mean import fused_means

FloatArray = NDArray[np.float64]

#: the mean squared truncation error of u (per run, in units of sigma_N^2) below which no
#: more principal components are added: an error delta u changes L by about |u| |delta u|,
#: 0.05 near a posterior with 20 measurement points
TRUNCATION = 1e-4
#: at most this many components (each one GP)
MAX_COMPONENTS = 20
#: nugget of the component GPs, relative to the range of their scores (nearly interpolating)
COMPONENT_NUGGET = 1e-6
#: |r|^2 must equal sum_k D_k^2 to this relative tolerance; ray and cpp meet it exactly, the
#: rkhs measure's residual vector only as far as its truncated eigen-decomposition reaches
#: (1e-9 with sigma_W = 0.05 mm on the stand-in; off by 0.5 % median, up to 14 %, with
#: sigma_W = 0.005 mm on ale_fsi's interfaces, where "auto" falls back to the GP of L)
DISTANCE_TOL = 1e-6
#: at least this many successful runs per component GP
MIN_RUNS = 3
#: a component whose uncertainty adds less than this to the variance of L (units of L^2) at
#: every point is not sampled in :meth:`ResidualSurrogate.sample_paths` (sd 0.003 in L)
PATH_VARIANCE = 1e-5


def residual_vectors(evaluations: Sequence[Evaluation]) -> tuple[FloatArray, str]:
    """The residual vector r of every record, NaN rows for failed runs; and why
    the residuals cannot stand for L ("" when they can): eq. 5 needs sum_k D_k^2 = |r|^2
    and a residual vector of one length for every run."""
    rows: list[FloatArray | None] = []
    length: int | None = None
    for ev in evaluations:
        if not ev.ok or ev.residuals is None or ev.distances is None:
            rows.append(None)
            continue
        r = np.asarray(ev.residuals, dtype=float).ravel()
        if length is None:
            length = len(r)
        if len(r) != length:
            return np.empty((0, 0)), (
                f"the residual vectors differ in length between runs ({length}, {len(r)})"
            )
        if not np.all(np.isfinite(r)):
            return np.empty((0, 0)), "a residual vector holds NaN or infinite entries"
        s = float(np.sum(np.asarray(ev.distances, dtype=float) ** 2))
        if not math.isclose(float(r @ r), s, rel_tol=DISTANCE_TOL, abs_tol=1e-300):
            return np.empty((0, 0)), "the measure's distance is not the norm of its residuals"
        rows.append(r)
    if length is None:
        return np.empty((len(evaluations), 0)), ""
    out = np.full((len(evaluations), length), np.nan)
    for i, row in enumerate(rows):
        if row is not None:
            out[i] = row
    return out, ""


#: the step of a pseudo-run from a run's Jacobian (:func:`tangent_runs`), a fraction of the
#: design's spread (standard deviation) in that input: short against the component GPs'
#: length scales (0.3-3 spreads), so that the pair carries the slope, and long against the
#: nugget, so that the GP sees it
TANGENT_STEP = 0.02


def tangent_runs(
    x: FloatArray, residuals: FloatArray, records: Sequence[Evaluation]
) -> tuple[FloatArray, FloatArray]:
    """The runs at the rows of ``x`` with ``residuals`` (n, m), and for every successful run
    whose record carries the Jacobian J = dr/dz (``Evaluation.jacobian``, (m, d) in the order
    of the columns of ``x``) one pseudo-run per input j, at z + h_j e_j with residuals
    r + h_j J e_j, h_j = :data:`TANGENT_STEP` times the design's spread in input j: the
    "indirect" gradient-enhanced GP (Chung & Alonso 2002), whose GP sees the slope of every
    component in every direction at every run without derivative kernels. The error of the
    first-order step, O(h^2 r''), is far below the emulator's."""
    x = np.atleast_2d(np.asarray(x, dtype=float))
    residuals = np.atleast_2d(np.asarray(residuals, dtype=float))
    steps = TANGENT_STEP * np.where(np.std(x, axis=0) > 0, np.std(x, axis=0), 1.0)
    xs, rs = [x], [residuals]
    for i, ev in enumerate(records):
        jac = ev.jacobian
        if jac is None or not ev.ok or not np.all(np.isfinite(residuals[i])):
            continue
        jac = np.asarray(jac, dtype=float)
        if jac.shape != (residuals.shape[1], x.shape[1]):
            raise ConfigError(
                f"a run's Jacobian has shape {jac.shape}, its residuals and inputs need "
                f"{(residuals.shape[1], x.shape[1])}",
                "gradients",
            )
        xs.append(x[i] + np.diag(steps))
        rs.append(residuals[i] + (jac * steps).T)
    return np.vstack(xs), np.vstack(rs)


@dataclass(frozen=True)
class ResidualLink:
    """How the residual vectors r of the runs give what the surrogate stands for: u = r /
    ``sigma``; L = ``constant`` - |u|^2 / 2 (sigma_N known), or with ``constant`` None the
    profile over sigma_N, L^ = -n/2 (log(2 pi sigma^2 |u|^2 / n) + 1), n = ``count`` (sigma
    is then only a scale: the rms residual of the best run)."""

    sigma: float
    constant: float | None
    count: int | None


def residual_link(
    records: Sequence[Evaluation],
    sigmas: Sequence[float] | None,
    count: int | None,
) -> tuple[ResidualLink | None, FloatArray, str]:
    """The link for runs ``records`` with noise ``sigmas`` per observation (None: sigma_N is
    inferred) and n of eq. 5 ``count`` (None: the residual count), and the runs' residual
    vectors (:func:`residual_vectors`, what the emulator is fitted to); or None and why the
    residuals cannot stand for L."""
    none = np.empty((0, 0))
    if sigmas is not None and any(s != sigmas[0] for s in sigmas):
        return None, none, "the observations have different sigma_N"
    r, why = residual_vectors(records)
    if why:
        return None, none, why
    ok = np.all(np.isfinite(r), axis=1) if r.size else np.zeros(len(r), dtype=bool)
    if not ok.any():
        return None, none, "no successful run"
    n = count if count is not None else r.shape[1]
    if sigmas is not None:
        sigma = float(sigmas[0])
        return ResidualLink(sigma, -0.5 * n * math.log(2.0 * math.pi * sigma**2), None), r, ""
    best = float(np.min(np.sum(r[ok] ** 2, axis=1)))
    scale = math.sqrt(max(best / max(n, 1), MIN_SQUARED_DISTANCE))
    return ResidualLink(scale, None, n), r, ""


@dataclass(frozen=True)
class ResidualCovariance:
    """The covariance of L among a fixed set of points under a residual emulator, by blocks:
    sum_j (dL/dt_j)(a) c_j(a, b) (dL/dt_j)(b), the components' covariances c_j first order in
    the scores (:meth:`ResidualSurrogate.posterior_covariance`), each component solved once
    (:meth:`ResidualSurrogate.covariance_on`)."""

    grad: FloatArray  # dL/dt_j at the points, (points, components)
    components: tuple[GpCovariance, ...]

    def block(self, rows: ArrayLike, cols: ArrayLike) -> FloatArray:
        """The covariance between the points ``rows`` and ``cols`` (index arrays)."""
        i, j = np.asarray(rows), np.asarray(cols)
        out = np.zeros((len(i), len(j)))
        for c, comp in enumerate(self.components):
            out += self.grad[i, c, None] * comp.block(i, j) * self.grad[None, j, c]
        return out

    def variance(self, rows: ArrayLike) -> FloatArray:
        """The diagonal of :meth:`block` at ``rows`` (first order)."""
        i = np.asarray(rows)
        var = np.column_stack([comp.variance(i) for comp in self.components])
        return np.asarray(np.sum(self.grad[i] ** 2 * var, axis=1))

    def predictive_variance(self, rows: ArrayLike) -> FloatArray:
        """The variance of :meth:`ResidualSurrogate.predict` at ``rows``: the first-order
        term and the second-order sum_j s_j^4 / 2 (the components' variances clipped at 0
        as there)."""
        i = np.asarray(rows)
        var = np.column_stack([np.maximum(comp.variance(i), 0.0) for comp in self.components])
        return np.asarray(np.sum(self.grad[i] ** 2 * var + 0.5 * var**2, axis=1))


class ResidualSurrogate(ExtrapolationGuard):
    """L of eq. 5 (or its profile over sigma_N) from a GP emulator of the residuals.

    Parameters
    ----------
    link
        What the residuals give (:class:`ResidualLink`).
    ard, optimizer, restarts, max_iters, subset, polish_iters
        Of each component's :class:`GpSurrogate`.
    guard_margin
        As for ``GpSurrogate``: units of L above the best run where the guarded mean is capped.
    """

    kind = "residuals"

    def __init__(
        self,
        link: ResidualLink,
        ard: bool = False,
        optimizer: str = "lbfgsb",
        restarts: int = 2,
        max_iters: int = 1000,
        subset: int = 800,
        polish_iters: int = 60,
        guard_margin: float | None = None,
    ) -> None:
        if link.constant is None and not link.count:
            raise ConfigError("the profile log-likelihood needs the count n of eq. 5", "gp")
        self.link = link
        self.ard = bool(ard)
        self._optimizer = optimizer
        self._restarts = int(restarts)
        self._max_iters = int(max_iters)
        self._subset = int(subset)
        self._polish_iters = int(polish_iters)
        self.guard_margin = guard_margin
        self.guard = GuardCounts()
        self.components: list[GpSurrogate] = []
        self.info: dict[str, Any] = {}
        #: the nugget of L for the adaptive design's criterion (a run at a point leaves
        #: essentially no variance there)
        self.nugget = 1e-8

    # -- L from u -------------------------------------------------------------------------
    def log_likelihood(self, half_sq: FloatArray) -> FloatArray:
        """L (or L^) from Q = |u|^2 / 2."""
        if self.link.constant is not None:
            return np.asarray(self.link.constant - half_sq)
        n = float(self.link.count or 1)
        s = np.maximum(2.0 * half_sq * self.link.sigma**2, n * MIN_SQUARED_DISTANCE)
        return np.asarray(-0.5 * n * (np.log(2.0 * math.pi * s / n) + 1.0))

    def _slope(self, half_sq: FloatArray) -> FloatArray:
        """dL / dQ."""
        if self.link.constant is not None:
            return np.full_like(half_sq, -1.0)
        n = float(self.link.count or 1)
        return np.asarray(-0.5 * n / np.maximum(half_sq, 1e-300))

    # -- training -------------------------------------------------------------------------
    def fit(
        self,
        x: ArrayLike,
        r: ArrayLike,
        rng: np.random.Generator | int | None = None,
        start: Mapping[str, Any] | None = None,
        axes: ArrayLike | None = None,
        optimise: bool = True,
    ) -> ResidualSurrogate:
        """Train on inputs ``x`` (n, d) and residual vectors ``r`` (n, m) (rows with NaN:
        failed runs, left out); ``start``: an earlier fit's :meth:`hyperparameters`; ``axes``:
        a covariance of the inputs whose principal axes every component's kernel follows
        (:meth:`GpSurrogate.fit`); ``optimise = False``: the basis, the mean and each
        component's hyperparameters of ``start`` are kept, and the components are only
        conditioned on the data (without a basis in ``start`` a new one is computed and
        every component optimised)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        u = np.atleast_2d(np.asarray(r, dtype=float)) / self.link.sigma
        ok = np.all(np.isfinite(u), axis=1) if u.size else np.zeros(len(x), dtype=bool)
        if ok.sum() < MIN_RUNS:
            raise ConfigError(
                f"the residual emulator needs at least {MIN_RUNS} successful runs, "
                f"got {int(ok.sum())}",
                "gp",
            )
        x, u = x[ok], u[ok]
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.x_train = x
        kept = None if optimise or start is None else start.get("basis")
        if start is not None and kept is not None and np.shape(kept)[1] == u.shape[1]:
            # conditioned only: the components stay the same functions (the basis and mean of
            # the fit whose hyperparameters they keep), so those hyperparameters still fit them
            self.u_mean = np.asarray(start["u_mean"], dtype=np.float64)
            self.basis = np.asarray(kept, dtype=np.float64)
            centred = u - self.u_mean
            outside = centred - (centred @ self.basis.T) @ self.basis
            k = len(self.basis)
            tail = np.zeros(k + 1)
            tail[k] = float(np.sum(outside**2)) / len(u)
        else:
            optimise = True
            self.u_mean = u.mean(axis=0)
            centred = u - self.u_mean
            _, sing, vt = np.linalg.svd(centred, full_matrices=False)
            tail = np.append(np.cumsum((sing**2)[::-1])[::-1], 0.0) / len(u)
            k = next((j for j in range(len(sing) + 1) if tail[j] < TRUNCATION), len(sing))
            k = int(min(max(k, 1), MAX_COMPONENTS, len(sing)))
            self.basis = np.asarray(vt[:k])  # (k, m), orthonormal rows
        self._set_mean_parts()
        scores = centred @ self.basis.T
        starts = list((start or {}).get("components", []))
        self.components = []
        self.__dict__.pop("_shared", None)
        for j in range(k):
            warm = starts[j] if j < len(starts) else None
            gp = self._component()
            fitted = gp.fit(
                x, scores[:, j], rng=rng, start=warm, axes=axes, optimise=optimise or not warm
            )
            self.components.append(fitted)
        self.y_train = self.log_likelihood(0.5 * np.sum(u * u, axis=1))
        self.truncation = float(tail[k])
        self.info = {
            "surrogate": "residuals",
            "kernel": "matern32_product" if self.ard else "matern32",  # of each component
            "n_train": len(x),
            "n_residuals": u.shape[1],
            "components": k,
            "truncation_mse": self.truncation,
            "seconds": float(sum(gp.info.get("seconds", 0.0) for gp in self.components)),
        }
        return self

    def _component(self) -> GpSurrogate:
        """An untrained GP of one component's scores (prior mean mid-range, tiny nugget)."""
        return GpSurrogate(
            ard=self.ard,
            optimizer=self._optimizer,
            restarts=self._restarts,
            max_iters=self._max_iters,
            nugget_factor=COMPONENT_NUGGET,
            mean_offset=-0.5,
            subset=self._subset,
            polish_iters=self._polish_iters,
        )

    def hyperparameters(self) -> dict[str, Any]:
        """Each component's hyperparameters, with the basis and mean they belong to (a fit
        that only conditions on new runs keeps all three)."""
        return {
            "components": [gp.hyperparameters() for gp in self.components],
            "basis": self.basis,
            "u_mean": self.u_mean,
        }

    # -- prediction -----------------------------------------------------------------------
    def _scores(self, x: ArrayLike) -> FloatArray:
        """The components' posterior means at the rows of ``x`` (M, k): product kernels in one
        compiled call for all of them (:func:`~.mean.fused_means`), else one by one."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        first = self.components[0]
        if len(x) >= 64 and self.ard and self._shared_inputs():
            raw = fused_means([gp.kernel_terms() for gp in self.components], first.standardise(x))
            prior = np.column_stack([gp.prior_mean(x) for gp in self.components])
            return np.asarray(prior + raw)
        return np.column_stack([gp.predict_mean(x) for gp in self.components])

    def _shared_inputs(self) -> bool:
        """Whether every component standardises (and rotates) its inputs alike (one fit of
        the same runs: then the standardised particles are computed once)."""
        if "_shared" not in self.__dict__:
            a = self.components[0]
            eye = np.eye(len(a.x_mean))
            self._shared = all(
                np.array_equal(gp.x_mean, a.x_mean)
                and np.array_equal(gp.x_std, a.x_std)
                and np.array_equal(
                    eye if gp.rotation is None else gp.rotation,
                    eye if a.rotation is None else a.rotation,
                )
                for gp in self.components
            )
        return bool(self._shared)

    def _set_mean_parts(self) -> None:
        """The mean vector's coordinates in the basis and its squared part outside it."""
        self._mean_coef = self.basis @ self.u_mean
        sq = float(self.u_mean @ self.u_mean - self._mean_coef @ self._mean_coef)
        self._mean_perp_sq = max(sq, 0.0)

    def _half_sq(self, t: FloatArray) -> FloatArray:
        """|u^|^2 / 2 for scores t (rows), u^ = mean + t basis, without forming u^:
        |mean_perp|^2 + |mean_coef + t|^2 (orthonormal basis)."""
        return np.asarray(0.5 * (self._mean_perp_sq + np.sum((self._mean_coef + t) ** 2, axis=1)))

    def predict_mean(self, x: ArrayLike) -> FloatArray:
        """L at the emulated mean residuals (plug-in), all rows of ``x`` at once."""
        return self.log_likelihood(self._half_sq(self._scores(x)))

    __call__ = predict_mean

    def _gradients(
        self, x: ArrayLike, t: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """The plug-in L and dL / dt_j (M, k) at the rows of ``x`` (``t``: their scores,
        when already predicted)."""
        t = self._scores(x) if t is None else t
        half_sq = self._half_sq(t)
        # dQ / dt_j = u^ . v_j = (mean . v_j) + t_j (orthonormal basis)
        dq = self._mean_coef[None, :] + t
        return self.log_likelihood(half_sq), self._slope(half_sq)[:, None] * dq

    def predict(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Mean (plug-in) and variance of L: sum_j (dL/dt_j)^2 s_j^2 + sum_j s_j^4 / 2 (the
        second-order term, exact for L = C - Q)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        per_component = [gp.predict(x) for gp in self.components]
        t = np.column_stack([m for m, _ in per_component])
        var = np.column_stack([v for _, v in per_component])
        mean, grad = self._gradients(x, t)
        return mean, np.asarray(np.sum(grad**2 * var + 0.5 * var**2, axis=1))

    def posterior_covariance(self, a: ArrayLike, b: ArrayLike) -> FloatArray:
        """Covariance of L between the rows of ``a`` and ``b`` (first order in the scores)."""
        return covariance_between(self, a, b)

    def covariance_on(self, x: ArrayLike) -> ResidualCovariance:
        """The covariance of L among the rows of ``x`` by blocks, first order in the scores
        (:class:`ResidualCovariance`): each component's solve done once for all the points."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        _, grad = self._gradients(x)
        return ResidualCovariance(grad, tuple(gp.covariance_on(x) for gp in self.components))

    def predict_joint(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Mean (M,) and covariance (M, M) of L at the rows of ``x``; the diagonal carries
        the second-order variance of :meth:`predict` too."""
        mean, grad = self._gradients(x)
        cov = np.zeros((len(mean), len(mean)))
        second = np.zeros(len(mean))
        for j, gp in enumerate(self.components):
            c = gp.posterior_covariance(x, x)
            cov += grad[:, j, None] * c * grad[None, :, j]
            second += 0.5 * np.diag(c) ** 2
        cov[np.diag_indices_from(cov)] += second
        return mean, cov

    def sample_paths(
        self, x: ArrayLike, n_paths: int, rng: np.random.Generator
    ) -> tuple[FloatArray, FloatArray, float]:
        """``n_paths`` joint sample paths of L at the rows of ``x`` (M, K), L's standard
        deviation over them (M,) and the largest jitter of the factorisations.

        Each component's scores are drawn jointly from its GP (the components are
        independent), and L of every path is computed from its residuals exactly,
        L = C - |u|^2 / 2 (or the profile): never above the best fit, with the skew that a
        large |u^| gives it. The first-order (delta-method) variance of :meth:`predict`
        makes L symmetric instead, with an upper tail far from the runs that L cannot have,
        where sample paths then invent posterior mass."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        t = np.empty((len(x), len(self.components), n_paths))
        jitter = 0.0
        means, var = self._scores(x), np.empty((len(x), len(self.components)))
        for j, gp in enumerate(self.components):
            var[:, j] = gp.predict(x)[1]
        _, grad = self._gradients(x, means)
        # a component whose uncertainty changes L by less than PATH_VARIANCE (in L^2) at
        # every point keeps its mean: its joint paths (a Cholesky factorisation of M x M)
        # would change no path
        varies = np.max(grad**2 * var + 0.5 * var**2, axis=0) >= PATH_VARIANCE
        for j, gp in enumerate(self.components):
            if not varies[j]:
                t[:, j, :] = means[:, j, None]
                continue
            mean, cov = gp.predict_joint(x)
            t[:, j, :], jit = gaussian_paths(mean, cov, n_paths, rng)
            jitter = max(jitter, jit) if math.isfinite(jit) else math.nan
        coef = self._mean_coef[None, :, None] + t
        half_sq = 0.5 * (self._mean_perp_sq + np.sum(coef * coef, axis=1))  # (M, K)
        paths = self.log_likelihood(half_sq)
        return paths, np.std(paths, axis=1), jitter

    # -- quality --------------------------------------------------------------------------
    def loo(self) -> dict[str, float]:
        """Leave-one-out errors in L: each score's closed-form LOO prediction, L from them."""
        t = np.column_stack([gp.loo_predictions() for gp in self.components])
        res = self.log_likelihood(self._half_sq(t)) - self.y_train
        return GpSurrogate._errors(res, self.y_train, prefix="loo")

    def test_error(self, x: ArrayLike, y: ArrayLike) -> dict[str, float]:
        y = np.asarray(y, dtype=float).ravel()
        return GpSurrogate._errors(self.predict_mean(x) - y, y, prefix="test")

    def describe(self) -> Mapping[str, Any]:
        return dict(self.info)

    # -- persistence ----------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """Everything needed to rebuild the emulator without GPy."""
        return {
            "kind": "residuals",
            "sigma": self.link.sigma,
            "constant": self.link.constant,
            "count": self.link.count,
            "ard": self.ard,
            "x_train": self.x_train,
            "y_train": self.y_train,
            "u_mean": self.u_mean,
            "basis": self.basis,
            "truncation": self.truncation,
            "components": [gp.state() for gp in self.components],
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> ResidualSurrogate:
        count, constant = state.get("count"), state.get("constant")
        link = ResidualLink(
            float(state["sigma"]),
            None if constant is None else float(constant),
            None if count is None else int(count),
        )
        out = cls(link, ard=bool(state["ard"]))
        out.x_train = np.asarray(state["x_train"], dtype=float)
        out.y_train = np.asarray(state["y_train"], dtype=float)
        out.u_mean = np.asarray(state["u_mean"], dtype=float)
        out.basis = np.atleast_2d(np.asarray(state["basis"], dtype=float))
        out.truncation = float(state["truncation"])
        out._set_mean_parts()
        out.components = [GpSurrogate.from_state(s) for s in state["components"]]
        out.info = {
            "surrogate": "residuals",
            "n_train": len(out.x_train),
            "components": len(out.components),
            "restored": True,
        }
        return out


Surrogate = GpSurrogate | ResidualSurrogate


def restore_surrogate(state: Mapping[str, Any]) -> Surrogate:
    """The trained surrogate of a result's ``SurrogateFit.state``, whichever kind."""
    surrogate: Surrogate = (
        ResidualSurrogate.from_state(state)
        if state.get("kind") == "residuals"
        else GpSurrogate.from_state(state)
    )
    if state.get("feasibility") is not None:
        surrogate.feasibility = Feasibility.from_state(state["feasibility"])
    return surrogate


class KeepsSurrogate:
    """Mixin of a (frozen) result record with a surrogate's ``state``: the run keeps the
    fitted surrogate itself with the record (:meth:`attach`: not a field, so not written to
    ``result.json``), and :meth:`surrogate` gives it to plots and checks, rebuilding it from
    ``state`` only for a record read back from its file, once."""

    state: Mapping[str, Any]

    def attach(self, surrogate: Any) -> Any:
        """Keep the fitted ``surrogate`` with this record (in this process only)."""
        self.__dict__["_live"] = surrogate
        return self

    def surrogate(self) -> Any:
        """The fitted surrogate: the run's own, else rebuilt once from ``state``."""
        if self.__dict__.get("_live") is None:
            self.attach(restore_surrogate(self.state))
        return self.__dict__["_live"]
