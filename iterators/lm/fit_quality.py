"""Whether a least-squares optimum can be trusted: bounds and the chi-square test of the fit.

A converged Levenberg-Marquardt run says only that the objective stopped decreasing. Two facts
of the optimum x* say whether the numbers mean what a user reads into them (issue 43):

* **A parameter at a bound.** The data want a value outside the allowed range (a synthetic
  truth outside the bounds, a unit slip, a wrong model): x* is then the constrained optimum,
  not an estimate, and the Gauss-Newton standard error of that parameter (which assumes an
  interior optimum) means nothing.
* **Residuals inconsistent with the stated noise.** With the likelihood's noise level sigma_k
  of each observation k (Paper B eq. 5; the problem's ``noise_std``) and its discrepancy D_k
  at x*, a model that is right and a noise level that is right give

      chi2 = sum_k D_k^2 / sigma_k^2  ~  chi-square with nu = n - n_x degrees of freedom,

  n the number of single measurements (:func:`fbia.core.likelihood.measurement_count`, else
  the residual count) and n_x the fitted parameters (linearised around x*, as the standard
  errors are). The fit is inconsistent with the noise when the upper tail probability
  p = P(chi2_nu >= chi2) is below :data:`P_MISFIT` = 1e-3: the residuals are
  sqrt(chi2 / nu) times the stated noise (:attr:`FitQuality.noise_ratio`), so either the
  noise level or the model is wrong, and the standard errors (scaled by the residuals) do not
  describe the stated noise either. Only the upper tail is tested: residuals smaller than the
  noise (noise-free synthetic data, a stated noise level that is an upper bound) do not make
  the optimum wrong. Without a stated noise (no ``noise_std``, sigma_N inferred, or a plain
  residual function) or with nu < 1 there is no test.

Either fact makes the result's status ``unreliable`` (:class:`FitQuality.causes` names it in
one line each), and ``fbia run`` then exits 3. lmfit reports the reduced chi-square and drops
the uncertainties of a parameter at a bound; scipy's ``least_squares`` marks it in
``active_mask``; this is the same information turned into the verdict.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...core.likelihood import measurement_count
from ...core.problem import Evaluation, InverseProblem

FloatArray = NDArray[np.float64]

#: the upper-tail probability of the chi-square statistic below which the residuals are
#: inconsistent with the stated noise (one fit in a thousand with a right model and noise
#: level is flagged)
P_MISFIT = 1e-3
#: a parameter within this fraction of its range of a bound is at the bound
BOUND_RTOL = 1e-9


@dataclass(frozen=True)
class FitQuality:
    """The verdict on a least-squares optimum (module docstring)."""

    at_bound: tuple[str, ...] = ()  # parameters on a bound at x*
    bound_values: tuple[float, ...] = ()  # the bound each of them is on
    bound_sides: tuple[str, ...] = ()  # "lower" or "upper"
    chi2: float | None = None  # sum_k D_k^2 / sigma_k^2 at x*; None: no stated noise
    dof: int | None = None  # nu = n - n_x
    p_value: float | None = None  # P(chi2_nu >= chi2)

    @property
    def noise_ratio(self) -> float | None:
        """sqrt(chi2 / nu): the residuals in units of the stated noise (1 for a right fit)."""
        if self.chi2 is None or not self.dof:
            return None
        return math.sqrt(self.chi2 / self.dof)

    @property
    def misfit(self) -> bool:
        """Whether the residuals are inconsistent with the stated noise (p < P_MISFIT)."""
        return self.p_value is not None and self.p_value < P_MISFIT

    @property
    def causes(self) -> list[str]:
        """Why the optimum is not to be trusted, one line each (empty: nothing found)."""
        out = [
            f"at bound: {name} = {value:.6g} (its {side} bound)"
            for name, value, side in zip(
                self.at_bound, self.bound_values, self.bound_sides, strict=True
            )
        ]
        if self.misfit:
            assert self.chi2 is not None and self.noise_ratio is not None
            p = f"p = {self.p_value:.2g}" if self.p_value else "p < 1e-300"
            out.append(
                f"residuals {self.noise_ratio:.3g}x the stated noise (chi2 = {self.chi2:.4g} "
                f"on {self.dof} degrees of freedom, {p} < {P_MISFIT:g}): "
                "the noise level or the model is wrong"
            )
        return out

    @property
    def trusted(self) -> bool:
        return not self.causes

    def describe(self) -> str:
        """One line for a summary: the chi-square test's figures, or why there is none."""
        if self.chi2 is None or not self.dof:
            return "no chi-square test (no stated noise, or no more measurements than parameters)"
        return (
            f"chi2 / nu = {self.chi2 / self.dof:.3g} (nu = {self.dof}), residuals "
            f"{self.noise_ratio:.3g}x the stated noise, p = {self.p_value:.3g}"
        )


def bound_hits(
    names: Sequence[str], x: FloatArray, lower: FloatArray, upper: FloatArray
) -> tuple[tuple[str, ...], tuple[float, ...], tuple[str, ...]]:
    """The parameters of ``x`` on a bound (within :data:`BOUND_RTOL` of the range), the
    bounds they are on and which ("lower", "upper")."""
    hits, values, sides = [], [], []
    for i, name in enumerate(names):
        span = upper[i] - lower[i]
        tol = BOUND_RTOL * (span if math.isfinite(span) else max(abs(x[i]), 1.0))
        for bound, side in ((lower[i], "lower"), (upper[i], "upper")):
            if math.isfinite(bound) and abs(x[i] - bound) <= tol:
                hits.append(name)
                values.append(float(bound))
                sides.append(side)
                break
    return tuple(hits), tuple(values), tuple(sides)


def chi_square(
    problem: object, record: Evaluation | None, n_x: int
) -> tuple[float, int, float] | None:
    """(chi2, nu, p) of the run ``record`` at the optimum against the noise levels the
    problem states (module docstring); None without stated noise or with nu < 1."""
    if not isinstance(problem, InverseProblem) or record is None or problem.noise_prior is not None:
        return None
    if not record.ok or record.distances is None or record.residuals is None:
        return None
    sigmas = [
        obs.noise_std if obs.noise_std is not None else problem.noise_std
        for obs in problem.observations
    ]
    if any(s is None for s in sigmas) or len(sigmas) != len(record.distances):
        return None
    count = measurement_count(problem)
    n = len(record.residuals) if count is None else count
    dof = n - n_x
    if dof < 1:
        return None
    d = np.asarray(record.distances, dtype=float)
    chi2 = float(np.sum(d**2 / np.asarray(sigmas, dtype=float) ** 2))
    from scipy.stats import chi2 as chi2_distribution

    return chi2, dof, float(chi2_distribution.sf(chi2, dof))


def fit_quality(
    names: Sequence[str],
    x: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    problem: object,
    record: Evaluation | None,
) -> FitQuality:
    """The verdict on the optimum ``x`` of ``problem`` whose run is ``record``."""
    hits, values, sides = bound_hits(names, x, lower, upper)
    test = chi_square(problem, record, len(names))
    if test is None:
        return FitQuality(hits, values, sides)
    chi2, dof, p = test
    return FitQuality(hits, values, sides, chi2, dof, p)
