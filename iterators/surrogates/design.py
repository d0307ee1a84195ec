"""The design of a GP-surrogate study: points of a scrambled Sobol sequence mapped to the inputs.

>>> import fbia
>>> from fbia.iterators.surrogates.design import sobol_design
>>> params = [fbia.Parameter("E", bounds=(100.0, 1000.0)), fbia.Parameter("nu", bounds=(0.0, 0.5))]
>>> sobol_design(params, 8, seed=0).shape
(8, 2)

A parameter with finite bounds gets the uniform map onto them; one without (or every input
with ``through_prior``) goes through its prior's inverse CDF (Paper B, Remark 7).  Used by
``gp_smc`` (the fixed design and the start of the adaptive one) and ``sobol_indices``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import qmc

from ...core.errors import ConfigError
from ...core.parameters import Parameter

FloatArray = NDArray[np.float64]


def finite_bounds(p: Parameter) -> bool:
    """Whether ``p`` has bounds and both are finite."""
    return p.bounds is not None and all(math.isfinite(b) for b in p.bounds)


def sobol_design(
    parameters: Sequence[Parameter], n: int, seed: int, start: int = 0, through_prior: bool = False
) -> FloatArray:
    """Points ``start .. start + n - 1`` of a scrambled Sobol sequence mapped to the inputs.

    Equal seeds give the same sequence, so a design of n points extends to n + m points by
    the next m points of the same sequence (Paper B, "Convergence over number of training
    points"). A parameter with finite bounds gets the uniform map onto them, else (or with
    ``through_prior``) its prior's inverse CDF (Remark 7).
    """
    sampler = qmc.Sobol(len(parameters), scramble=True, seed=seed)
    if start:
        sampler.fast_forward(start)
    with warnings.catch_warnings():  # any n is fine here: designs are extended point by point
        warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*")
        u = sampler.random(n)
    return unit_to_inputs(parameters, u, through_prior)


def unit_to_inputs(
    parameters: Sequence[Parameter], u: FloatArray, through_prior: bool
) -> FloatArray:
    """Points of the unit cube mapped to the inputs: uniformly onto finite bounds, or through
    the prior's inverse CDF (where there are no finite bounds, or always with
    ``through_prior`` when there is a prior)."""
    out = np.empty_like(u)
    for j, p in enumerate(parameters):
        if p.bounds is not None and finite_bounds(p) and not (through_prior and p.prior):
            lo, hi = p.bounds
            out[:, j] = lo + (hi - lo) * u[:, j]
        else:
            if p.prior is None:
                raise ConfigError("needs finite bounds or a prior for the design", p.name)
            out[:, j] = p.prior.ppf(np.clip(u[:, j], 1e-9, 1 - 1e-9))
    return out


def search_box(parameters: Sequence[Parameter], x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Lower and upper corners of the box in which to search or draw over the inputs: the
    bounds, or the range of the points ``x`` (rows of inputs) for an input without finite
    bounds."""
    lower, upper = np.min(x, axis=0), np.max(x, axis=0)
    for j, p in enumerate(parameters):
        if p.bounds is not None and finite_bounds(p):
            lower[j], upper[j] = p.bounds
    return lower, upper
