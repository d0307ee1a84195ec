"""The Gaussian static likelihood of Paper B (eq. 4-5), shared by the store and the iterators.

L(x, theta) = sum_k [ -n_k/2 log(2 pi sigma_k^2) - D_k^2 / (2 sigma_k^2) ]

over the observations k with discrepancy D_k (the measure's ``distance``) and noise level
sigma_k (the observation's ``noise_std``, else the problem's).  n_k is the number of single
measurements in D_k: the residual count (Paper B: n_mp for the ray, n_in for the cpp measure),
unless the measure declares a fixed number per observation (``measurements_per_observation``;
rkhs: 1, D itself, whatever the length of its residual vector).  With one sigma for all
observations n = the total count; with different sigmas it is taken as split evenly among
the observations.

When sigma_N is unknown (``InverseProblem.noise_prior``), it becomes an input of the
posterior with that prior (one sigma_N for all observations). L then depends on the forward
run only through S = sum_k D_k^2 and n, and on sigma_N in closed form; the surrogate models
the profile log-likelihood, L maximised over sigma_N (sigma^2 = S / n),

    L^(x) = max_sigma L(x, sigma) = -n/2 [log(2 pi S / n) + 1],

from which S = n / (2 pi) exp(-2 L^ / n - 1) and L(x, sigma) follow exactly
(:func:`profile_log_likelihood`, :func:`log_likelihood_from_profile`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ConfigError
from .parameters import Parameter
from .problem import Evaluation, InverseProblem

#: the name of sigma_N when it is inferred (an input of the posterior, in mm)
NOISE_NAME = "sigma_N"
#: the smallest S = sum D^2 per measurement the profile likelihood takes (mm^2): an exact fit
#: (S = 0) would make it infinite
MIN_SQUARED_DISTANCE = 1e-24


def noise_parameter(problem: InverseProblem) -> Parameter | None:
    """sigma_N as an input of the posterior when the problem infers it, else None."""
    prior = problem.noise_prior
    if prior is None:
        return None
    return Parameter(NOISE_NAME, prior=prior, unit="mm")  # bounds: the finite support


def noise_levels(problem: InverseProblem) -> list[float]:
    """sigma_N [mm] of every observation: its own ``noise_std``, else the problem's.

    Raises ConfigError when one has neither: there is no likelihood then."""
    out = []
    for obs in problem.observations:
        sigma = obs.noise_std if obs.noise_std is not None else problem.noise_std
        if sigma is None:
            raise ConfigError(
                "an observation has no noise_std and the problem has none: the Gaussian "
                "likelihood (Paper B eq. 5) needs sigma_N [mm]",
                "likelihood",
            )
        out.append(float(sigma))
    return out


def measurement_count(problem: InverseProblem) -> int | None:
    """n of eq. 5 over all observations when the measure fixes it per observation, else None
    (then it is the residual count of each record)."""
    per_observation = problem.measure.measurements_per_observation
    if per_observation is None:
        return None
    return int(per_observation) * len(problem.observations)


def gaussian_log_likelihood(
    record: Evaluation, sigmas: Sequence[float], count: int | None = None
) -> float:
    """Paper B eq. (5) for one evaluation record; ``-inf`` for a failed run.  ``count``: n
    (see :func:`measurement_count`), default the record's residual count."""
    if not record.ok or record.distances is None or record.residuals is None:
        return -math.inf
    dist = np.asarray(record.distances, dtype=float)
    sig = np.asarray(sigmas, dtype=float)
    n = len(record.residuals) if count is None else count
    if np.all(sig == sig[0]):
        return float(
            -0.5 * n * math.log(2 * math.pi * sig[0] ** 2) - np.sum(dist**2) / (2 * sig[0] ** 2)
        )
    n_k = n / len(dist)
    return float(np.sum(-0.5 * n_k * np.log(2 * math.pi * sig**2) - dist**2 / (2 * sig**2)))


def squared_distance(record: Evaluation, count: int | None = None) -> tuple[float, int]:
    """S = sum_k D_k^2 and n of one record (eq. 5); S = inf for a failed run."""
    if not record.ok or record.distances is None or record.residuals is None:
        return math.inf, 0
    n = len(record.residuals) if count is None else count
    return float(np.sum(np.asarray(record.distances, dtype=float) ** 2)), int(n)


def profile_log_likelihood(record: Evaluation, count: int | None = None) -> float:
    """L of eq. 5 maximised over one sigma_N for all observations (module docstring);
    ``-inf`` for a failed run."""
    s, n = squared_distance(record, count)
    if not math.isfinite(s) or n == 0:
        return -math.inf
    s = max(s, n * MIN_SQUARED_DISTANCE)
    return -0.5 * n * (math.log(2 * math.pi * s / n) + 1.0)


def log_likelihood_from_profile(
    profile: ArrayLike, n: int, sigma: ArrayLike
) -> NDArray[np.float64]:
    """Eq. 5 at noise ``sigma`` from the profile log-likelihood (elementwise): exact for the
    true profile, and what SMC evaluates on a surrogate of it."""
    profile = np.asarray(profile, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    with np.errstate(over="ignore"):
        s = n / (2 * math.pi) * np.exp(-2.0 * profile / n - 1.0)
    return np.asarray(-0.5 * n * np.log(2 * math.pi * sigma**2) - s / (2 * sigma**2))


#: chi2's upper tail below which residuals contradict the stated noise (1 right fit in 1000)
P_MISFIT = 1e-3


@dataclass(frozen=True)
class ChiSquare:
    """The goodness of fit of one run against the stated noise of eq. 5: a right model and
    noise level give chi2 = sum_k D_k^2 / sigma_k^2 ~ chi-square with nu = n - (fitted inputs)
    degrees of freedom; p its upper tail (only: residuals below the noise do not make a fit
    wrong). Used by Levenberg-Marquardt's verdict and gp_smc's model check."""

    chi2: float
    dof: int
    p_value: float

    @property
    def noise_ratio(self) -> float:
        """sqrt(chi2 / nu): the residuals in units of the stated noise (1 for a right fit)."""
        return math.sqrt(self.chi2 / self.dof)

    @property
    def misfit(self) -> bool:
        return self.p_value < P_MISFIT

    def cause(self) -> str:
        p = f"p = {self.p_value:.2g}" if self.p_value > 0 else "p < 1e-300"
        return (
            f"residuals {self.noise_ratio:.3g}x the stated noise (chi2 = {self.chi2:.4g} on "
            f"{self.dof} degrees of freedom, {p} < {P_MISFIT:g}): the noise level or the "
            "model is wrong"
        )


def chi_square(problem: object, record: Evaluation | None, n_fitted: int) -> ChiSquare | None:
    """The :class:`ChiSquare` of the run ``record``; None without a stated noise (sigma_N
    inferred or not given), for a failed run, or with nu < 1."""
    if not isinstance(problem, InverseProblem) or problem.noise_prior is not None:
        return None
    if record is None or not record.ok or record.distances is None or record.residuals is None:
        return None
    sigmas = [o.noise_std or problem.noise_std for o in problem.observations]
    if None in sigmas or len(sigmas) != len(record.distances):
        return None
    count = measurement_count(problem)
    dof = (len(record.residuals) if count is None else count) - n_fitted
    if dof < 1:
        return None
    d2 = np.asarray(record.distances, dtype=float) ** 2
    chi2 = float(np.sum(d2 / np.asarray(sigmas, dtype=float) ** 2))
    from scipy.stats import chi2 as chi2_distribution

    return ChiSquare(chi2, dof, float(chi2_distribution.sf(chi2, dof)))
