"""A gp_smc posterior as an ``arviz.InferenceData``: the hand-off to ArviZ (issue 43 item 4).

``GpSmcResult.to_inference_data()`` (and ``posterior.nc``, which ``fbia run`` writes with the
``bayes`` extra installed) holds

* ``posterior``: one variable per input of the posterior (x, theta, an inferred sigma_N), one
  chain whose draws are the SMC's final particles. fbia's SMC resamples at gamma = 1 and then
  moves the particles, so they are equally weighted and ArviZ's plain mean over them is the
  weighted mean of ``result.summary()`` (to round-off). Weighted particles (the expected
  posterior of ``surrogate_uncertainty = "expected_posterior"``, reweighted over the GP's
  sample paths) are resampled systematically first, and the group's ``resampled`` attribute
  says so (their mean then differs from the summary's by the resampling's Monte Carlo error);
* ``prior``: as many draws from every input's prior (seeded);
* ``log_likelihood``: ``L`` (eq. 5, the surrogate's or the model's) at every draw;
* ``sample_stats``: ``lp`` (L + log p, the unnormalised log-posterior), ``log_prior`` and
  ``weight`` (the particle's normalised weight times the number of draws: 1 for equal
  weights); the SMC's own diagnostics as the group's attributes (``smc_final_ess``: the ESS
  of the last reweighting, ``smc_tempering_steps``, ``smc_steps_with_moves``,
  ``log_evidence``), since the MCMC diagnostics ArviZ computes (r_hat, ess_bulk) do not apply
  to SMC particles (``az.summary(data, kind="stats")`` leaves them out);
* ``observed_data``: the observed interfaces' vertices in mm, one variable per observation,
  when the problem is given;
* attributes of every group: ``fbia_version``, ``plugins`` (registry name and version of the
  model, measure and iterator), ``study``, ``seed``, and per variable ``units``.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ...core.parameters import Prior
from ..smc.sampler import systematic_resample

FloatArray = NDArray[np.float64]


def _arviz() -> Any:
    try:
        with warnings.catch_warnings():  # arviz 0.2x announces its refactor on import
            warnings.simplefilter("ignore", FutureWarning)
            import arviz
    except ImportError:
        raise ConfigError(
            "arviz is not installed (pip install 'fbia[bayes]')", "to_inference_data"
        ) from None
    return arviz


def equally_weighted(weights: FloatArray) -> bool:
    """Whether the particles' weights are equal (to round-off)."""
    w = np.asarray(weights, dtype=float)
    return bool(len(w) and float(np.ptp(w)) <= 1e-9 * float(np.max(w)))


def inference_data(
    names: Sequence[str],
    particles: FloatArray,
    weights: FloatArray,
    log_likelihood: FloatArray,
    log_prior: FloatArray,
    *,
    seed: int = 0,
    n_draws: int | None = None,
    priors: Mapping[str, Prior] | None = None,
    units: Mapping[str, str] | None = None,
    attrs: Mapping[str, Any] | None = None,
    smc: Mapping[str, float] | None = None,
    observed: Mapping[str, FloatArray] | None = None,
) -> Any:
    """The ``arviz.InferenceData`` of the module docstring from a posterior's arrays."""
    arviz = _arviz()
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    rng = np.random.default_rng(seed)
    resampled = not equally_weighted(w)
    idx = systematic_resample(w, rng) if resampled else np.arange(len(w))
    if n_draws is not None:
        idx = idx[rng.permutation(len(idx))[:n_draws]]
    parts = np.asarray(particles, dtype=float)[idx]
    loglik = np.asarray(log_likelihood, dtype=float)[idx][None]
    lprior = np.asarray(log_prior, dtype=float)[idx][None]
    weight = (np.full(len(idx), 1.0) if resampled else w[idx] * len(w))[None]
    prior_draws = {
        n: np.asarray(priors[n].rvs(len(idx), rng), dtype=float)[None]
        for n in names
        if priors and n in priors
    }
    text = {
        k: v if isinstance(v, (str, int, float)) else json.dumps(v)
        for k, v in (attrs or {}).items()
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        data = arviz.from_dict(
            posterior={n: parts[None, :, j] for j, n in enumerate(names)},
            prior=prior_draws or None,
            log_likelihood={"L": loglik},
            sample_stats={"lp": loglik + lprior, "log_prior": lprior, "weight": weight},
            observed_data=(
                {k: np.asarray(v, dtype=float) for k, v in observed.items()} if observed else None
            ),
        )
    for group in data.groups():
        data[group].attrs.update(text)
    data.posterior.attrs["resampled"] = int(resampled)
    for key, value in (smc or {}).items():
        data.sample_stats.attrs[key] = float(value)
    for group in ("posterior", "prior"):
        if hasattr(data, group):
            for n, unit in (units or {}).items():
                if n in data[group]:
                    data[group][n].attrs["units"] = unit or "-"
    if hasattr(data, "observed_data"):
        for k in data.observed_data.data_vars:
            data.observed_data[k].attrs["units"] = "mm"
    return data
