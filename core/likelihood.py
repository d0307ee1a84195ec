"""The Gaussian static likelihood of Paper B (eq. 4-5), shared by the store and the iterators.

L(x, theta) = sum_k [ -n_k/2 log(2 pi sigma_k^2) - D_k^2 / (2 sigma_k^2) ]

over the observations k with discrepancy D_k (the measure's ``distance``) and noise level
sigma_k (the observation's ``noise_std``, else the problem's).  n_k is the number of single
measurements in D_k: the residual count (Paper B: n_mp for the ray, n_in for the cpp measure),
unless the measure declares a fixed number per observation (``measurements_per_observation``;
rkhs: 1, D itself, whatever the length of its residual vector).  With one sigma for all
observations n = the total count; with different sigmas it is taken as split evenly among
the observations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .errors import ConfigError
from .problem import Evaluation, InverseProblem


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
    per_observation = getattr(problem.measure, "measurements_per_observation", None)
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
