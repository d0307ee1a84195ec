"""Whether the model and the prior can explain the data: gp_smc's check of what no surrogate
check sees (issue 43 item 1).

A posterior can be right for its model, prior and noise level, and still not be an estimate a
user can take: when the data want values the prior excludes, or when no parameters of the
model reproduce the data within the stated noise. Two tests, on by default, each making a
``completed`` result ``unreliable`` (exit 3 from ``fbia run``) with its cause on one line:

* **Posterior mass piled against a prior bound.** For every sampled input with a bounded
  prior, the posterior mass within :data:`EDGE` (2 %) of the prior's range next to a bound;
  :data:`PILED_MASS` (a quarter) or more is piled there, more than 12 times what a flat
  marginal puts in that strip (measured: prior E in [100, 200] Pa with the data made at
  400 Pa put its 97.5 % quantile at 199.99 Pa and said ``completed``). A posterior that is
  merely broad, or peaked inside the range, stays far below it.
* **The best forward run against the stated noise.** The chi-square test of Levenberg-
  Marquardt's verdict (:class:`~fbia.core.likelihood.ChiSquare`, upper tail p < 1e-3) on the
  forward run with the smallest chi2 = sum_k D_k^2 / sigma_k^2 among all that gp_smc made
  (design, checks), with nu = n - (inputs of the posterior) degrees of freedom: if even the
  best run is inconsistent with the noise level, either that level or the model is wrong (the
  posterior then is narrower than the data justify). The design's runs lie around the
  posterior's mode, so the best of them is within a few units of chi2 of the optimum, far
  inside the test's margin (about 37 at nu = 80). Only with a stated noise (no test when
  sigma_N is inferred, which the posterior then reports).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...core.likelihood import ChiSquare, chi_square
from ...core.parameters import Parameter
from ...core.problem import Evaluation, InverseProblem

FloatArray = NDArray[np.float64]

#: the strip next to a bound, as a fraction of the prior's range
EDGE = 0.02
#: the posterior mass in that strip from which it counts as piled against the bound
PILED_MASS = 0.25


@dataclass(frozen=True)
class ModelCheck:
    """The two tests of the module docstring on a gp_smc posterior."""

    best_fit: ChiSquare | None = None  # the best forward run's test; None: no stated noise
    piled: tuple[str, ...] = ()  # inputs whose posterior piles against a bound
    piled_sides: tuple[str, ...] = ()  # "lower" or "upper"
    piled_mass: tuple[float, ...] = ()  # the posterior mass in the strip

    @property
    def causes(self) -> list[str]:
        """Why the posterior is not an estimate to take, one line each (empty: none)."""
        out = [
            f"the posterior of {name} piles against its {side} bound ({mass:.0%} of its mass "
            f"within {EDGE:.0%} of the prior's range): the data want values the prior excludes"
            for name, side, mass in zip(self.piled, self.piled_sides, self.piled_mass, strict=True)
        ]
        if self.best_fit is not None and self.best_fit.misfit:
            out.append("at the best forward run, " + self.best_fit.cause())
        return out


def piled_against_bounds(
    inputs: Sequence[Parameter], particles: FloatArray, weights: FloatArray
) -> tuple[tuple[str, ...], tuple[str, ...], tuple[float, ...]]:
    """The inputs (columns of ``particles``) whose posterior mass within :data:`EDGE` of the
    prior's range next to a bound is :data:`PILED_MASS` or more; their sides and masses."""
    names, sides, masses = [], [], []
    w = np.asarray(weights, dtype=float) / float(np.sum(weights))
    for j, p in enumerate(inputs):
        if p.prior is None:
            continue
        lo, hi = p.prior.support
        if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
            continue
        strip = EDGE * (hi - lo)
        column = particles[:, j]
        for side, near in (("lower", column <= lo + strip), ("upper", column >= hi - strip)):
            mass = float(w[near].sum())
            if mass >= PILED_MASS:
                names.append(p.name)
                sides.append(side)
                masses.append(mass)
    return tuple(names), tuple(sides), tuple(masses)


def best_run_fit(
    problem: InverseProblem, records: Sequence[Evaluation], n_inputs: int
) -> ChiSquare | None:
    """The chi-square test of the run with the smallest chi2 among ``records`` (None without
    stated noise, or when no run succeeded)."""
    tests = [t for t in (chi_square(problem, r, n_inputs) for r in records) if t is not None]
    return min(tests, key=lambda t: t.chi2) if tests else None


def model_check(
    problem: InverseProblem,
    inputs: Sequence[Parameter],
    particles: FloatArray,
    weights: FloatArray,
    records: Sequence[Evaluation],
) -> ModelCheck:
    """Both tests on the posterior's weighted ``particles`` over ``inputs`` (its first
    columns; an inferred sigma_N after them is not tested) and the forward runs ``records``."""
    names, sides, masses = piled_against_bounds(inputs, particles, weights)
    return ModelCheck(best_run_fit(problem, records, len(inputs)), names, sides, masses)
