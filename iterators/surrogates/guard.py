"""The extrapolation guard of a surrogate of L (both :class:`~.gp.GpSurrogate` and
:class:`~.residuals.ResidualSurrogate`).

L far above the best training run is an artefact of the surrogate, not evidence: inside SMC
the mean is capped at the largest training value + a margin (by default chi2_d(0.999) / 2,
:func:`~fbia.iterators.smc.diagnostics.extrapolation_margin`), the capped calls and points are
counted, and :meth:`ExtrapolationGuard.extrapolated_mass` says how much posterior mass sat at
the cap. :meth:`ExtrapolationGuard.feasible` adds the factor of :mod:`~.feasibility` (where
the forward model runs) to an SMC target when the design had failed runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..smc.diagnostics import extrapolation_margin
from .feasibility import Feasibility

if TYPE_CHECKING:
    from ..smc.sampler import SmcResult


@dataclass
class GuardCounts:
    """What :meth:`ExtrapolationGuard.predict_mean_guarded` capped: calls and points."""

    calls: int = 0
    capped_calls: int = 0
    points: int = 0
    capped_points: int = 0


class ExtrapolationGuard:
    """The guard on top of a surrogate's ``predict_mean``, ``x_train`` and ``y_train`` (L of
    the training runs); ``guard_margin``: units of L above the best run (None: the default)."""

    guard_margin: float | None
    guard: GuardCounts
    x_train: NDArray[np.float64]
    y_train: NDArray[np.float64]
    #: where the forward model runs (:mod:`~.feasibility`; None: every run succeeded, or
    #: gp_smc's ``failures = "ignore"``)
    feasibility: Feasibility | None = None
    #: why this surrogate stands in for the one asked for (gp_smc's ``surrogate = "auto"``
    #: falling back to the GP of L when the residuals cannot give it), "" otherwise
    note: str = ""

    def predict_mean(self, x: ArrayLike) -> NDArray[np.float64]:
        raise NotImplementedError

    @property
    def extrapolation_cap(self) -> float:
        """The largest credible L: the largest training value + ``guard_margin``."""
        margin = self.guard_margin
        if margin is None:
            margin = extrapolation_margin(self.x_train.shape[1])
        return float(self.y_train.max()) + margin

    def predict_mean_guarded(self, x: ArrayLike) -> NDArray[np.float64]:
        """:meth:`predict_mean` capped at :attr:`extrapolation_cap` (counted in ``guard``)."""
        mean = self.predict_mean(x)
        cap = self.extrapolation_cap
        n_capped = int(np.count_nonzero(mean > cap))
        self.guard.calls += 1
        self.guard.points += len(mean)
        self.guard.capped_calls += n_capped > 0
        self.guard.capped_points += n_capped
        return np.minimum(mean, cap) if n_capped else mean

    def log_feasibility(self, x: ArrayLike) -> NDArray[np.float64]:
        """log c(x) of :mod:`~.feasibility` at the rows of ``x`` (0 without a classifier);
        columns after the classifier's inputs (a sampled sigma_N) are ignored."""
        z = np.atleast_2d(np.asarray(x, dtype=float))
        if self.feasibility is None:
            return np.zeros(len(z))
        return self.feasibility.log_factor(z[:, : self.feasibility.dim])

    def feasible(
        self, log_likelihood: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    ) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
        """The SMC log-target ``log_likelihood(z) + log c(z)``: the posterior stays where the
        forward model runs."""
        if self.feasibility is None:
            return log_likelihood
        return lambda z: log_likelihood(z) + self.log_feasibility(z)

    def extrapolated_mass(self, result: SmcResult) -> float:
        """Posterior mass of an SMC result where the mean reaches :attr:`extrapolation_cap`
        (capped in a guarded run; 0: no extrapolation). The surrogate's inputs are the
        leading columns of the particles (a sampled sigma_N, whose L is not the surrogate's,
        comes after)."""
        mean = self.predict_mean(result.particles[:, : self.x_train.shape[1]])
        return float(result.weights[mean >= self.extrapolation_cap].sum())
