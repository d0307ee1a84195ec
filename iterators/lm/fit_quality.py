"""Whether a least-squares optimum can be trusted: bounds and the chi-square test of the fit.

A converged Levenberg-Marquardt run says only that the objective stopped decreasing. Two facts
of the optimum x* say whether the numbers mean what a user reads into them (issue 43):

* **A parameter at a bound.** The data want a value outside the allowed range (a synthetic
  truth outside the bounds, a unit slip, a wrong model): x* is then the constrained optimum,
  not an estimate, and the Gauss-Newton standard error of that parameter (which assumes an
  interior optimum) means nothing.
* **Residuals inconsistent with the stated noise.** With the likelihood's noise level sigma_k
  of each observation k (Paper B eq. 5; the problem's ``noise_std``) and its discrepancy D_k
  at x*, a right model and a right noise level give chi2 = sum_k D_k^2 / sigma_k^2 ~
  chi-square with nu = n - n_x degrees of freedom; an upper-tail probability below
  :data:`~fbia.core.likelihood.P_MISFIT` = 1e-3 says the residuals are sqrt(chi2 / nu) times
  the stated noise, so either the noise level or the model is wrong
  (:class:`~fbia.core.likelihood.ChiSquare`, shared with ``gp_smc``'s model check). Without a
  stated noise (no ``noise_std``, sigma_N inferred, a plain residual function) or with
  nu < 1 there is no test.

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

from ...core.likelihood import ChiSquare, chi_square
from ...core.problem import Evaluation

FloatArray = NDArray[np.float64]

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
    def test(self) -> ChiSquare | None:
        """The chi-square test of the fit, if there is one."""
        if self.chi2 is None or not self.dof or self.p_value is None:
            return None
        return ChiSquare(self.chi2, self.dof, self.p_value)

    @property
    def noise_ratio(self) -> float | None:
        """sqrt(chi2 / nu): the residuals in units of the stated noise (1 for a right fit)."""
        test = self.test
        return None if test is None else test.noise_ratio

    @property
    def misfit(self) -> bool:
        """Whether the residuals are inconsistent with the stated noise."""
        test = self.test
        return test is not None and test.misfit

    @property
    def causes(self) -> list[str]:
        """Why the optimum is not to be trusted, one line each (empty: nothing found)."""
        out = [
            f"at bound: {name} = {value:.6g} (its {side} bound)"
            for name, value, side in zip(
                self.at_bound, self.bound_values, self.bound_sides, strict=True
            )
        ]
        test = self.test
        if test is not None and test.misfit:
            out.append(test.cause())
        return out

    @property
    def trusted(self) -> bool:
        return not self.causes

    def describe(self) -> str:
        """One line for a summary: the chi-square test's figures, or why there is none."""
        test = self.test
        if test is None:
            return "no chi-square test (no stated noise, or no more measurements than parameters)"
        return (
            f"chi2 / nu = {test.chi2 / test.dof:.3g} (nu = {test.dof}), residuals "
            f"{test.noise_ratio:.3g}x the stated noise, p = {test.p_value:.3g}"
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
    return FitQuality(hits, values, sides, test.chi2, test.dof, test.p_value)
