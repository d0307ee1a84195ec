"""Why an SMC run did not reach gamma = 1, and where a surrogate log-likelihood extrapolates.

>>> from fbia.iterators.smc.diagnostics import extrapolation_margin
>>> round(extrapolation_margin(7), 1)       # units of L above the best training value
12.2

A surrogate of the log-likelihood L (the GP of Paper B) is trustworthy only near its training
data. Where its mean rises far above the largest training value, the rise is an artefact of
the surrogate, not evidence, and a sampler that follows it reports a posterior the data do not
support. :func:`extrapolation_margin` says how far above the best training value the maximum
of L can plausibly lie: for a Gaussian likelihood in d dimensions, L_max - L(x) = chi2_d / 2
at posterior draws x, so a design with at least one point inside the posterior's 99.9 %
highest-density region has its best value within chi2_d(0.999) / 2 of the maximum (12.2 for
d = 7, 6.9 for d = 2). A 2000-point Sobol design on a box six posterior standard deviations
wide each way in 7-D has its best value 11.8 below the maximum: the margin is not generous.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .tempering import cycle_length, default_max_steps

#: Highest-density level of the posterior that the training design is assumed to reach.
EXTRAPOLATION_LEVEL = 0.999


def extrapolation_margin(dim: int, level: float = EXTRAPOLATION_LEVEL) -> float:
    """chi2_dim(level) / 2: how far (in units of L) the maximum of a Gaussian log-likelihood
    lies above the best point of a design that reaches its ``level`` highest-density region."""
    from scipy.stats import chi2

    return float(chi2.ppf(level, dim)) / 2.0


def training_range_note(
    loglik: NDArray[np.float64],
    weights: NDArray[np.float64],
    training_range: tuple[float, float],
    dim: int,
) -> str:
    """Whether the particles' log-likelihood lies far above a surrogate's training values."""
    lo, hi = training_range
    finite = np.isfinite(loglik)
    if not finite.any():
        return "no particle has a finite log-likelihood"
    top, bottom = float(loglik[finite].max()), float(loglik[finite].min())
    margin = extrapolation_margin(dim)
    text = (
        f"the surrogate was trained on log-likelihoods in [{lo:.4g}, {hi:.4g}] (spread "
        f"{hi - lo:.3g}); over the particles it spans [{bottom:.4g}, {top:.4g}] (spread "
        f"{top - bottom:.3g}"
        + (f", {(top - bottom) / (hi - lo):.2g} times the training spread)" if hi > lo else ")")
    )
    if top > hi + margin:
        above = float(weights[loglik > hi + margin].sum())
        return text + (
            f": {top - hi:.3g} above the largest training value, far beyond the margin "
            f"{margin:.3g} = chi2_{dim}({EXTRAPOLATION_LEVEL}) / 2, with {above:.1%} of the "
            "weight there. That is the surrogate extrapolating, not evidence: cap it "
            "(GpSurrogate.predict_mean_guarded) and add training points where the particles are"
        )
    return text + f": not above the largest training value + {margin:.3g} (no extrapolation)"


def gamma_growth_note(history: Sequence[dict[str, Any]], gamma: float, cycle: float) -> str:
    """How fast gamma grew per resampling cycle lately, and how many steps 1 would take."""
    at = [h["gamma"] for h in history if h["resampled"] and h["gamma"] > 0]
    if len(at) < 2:
        return "fewer than two resamplings: no rate of progress to extrapolate"
    recent = at[-4:]
    factor = (recent[-1] / recent[0]) ** (1.0 / (len(recent) - 1))
    if factor < 1.0 + 1e-6:
        return "gamma has stopped growing between resamplings"
    cycles = max(1, math.ceil(math.log(1.0 / gamma) / math.log(factor)))
    return (
        f"gamma grew by a factor {factor:.3g} per resampling cycle lately: gamma = 1 needs "
        f"about {cycles} more cycle{'s' if cycles > 1 else ''}, i.e. max_steps of at least "
        f"{len(history) + cycles * cycle:.0f}"
    )


def stall_message(
    *,
    gamma: float,
    max_steps: int,
    zeta: float,
    ess_min: float,
    loglik: NDArray[np.float64],
    log_w: NDArray[np.float64],
    history: Sequence[dict[str, Any]],
    dim: int,
    rejuvenate: str = "every_step",
    training_range: tuple[float, float] | None = None,
) -> str:
    """Why the tempering did not reach gamma = 1 within max_steps, and what to change."""
    finite = loglik[np.isfinite(loglik)]
    spread = float(np.ptp(finite)) if finite.size else math.nan
    weights = np.exp(log_w - float(log_w.max()))
    weights /= weights.sum()
    alive = int(np.sum(weights > 1e-3 / len(weights)))
    unique = len(np.unique(loglik))
    # resampling restarts the ESS at N; each step lowers it by the factor zeta, so one
    # resampling cycle takes log(ess_min) / log(zeta) steps
    cycle = cycle_length(zeta, ess_min)
    why = [
        f"no convergence to gamma = 1 in {max_steps} tempering steps (gamma = {gamma:.3g})",
        f"with zeta = {zeta:g} one resampling cycle takes about {cycle:.0f} steps",
        gamma_growth_note(history, gamma, cycle),
        f"the log-likelihood spans {spread:.3g} over the particles"
        if training_range is None
        else training_range_note(loglik, weights, training_range, dim),
    ]
    if unique < 0.1 * len(loglik):
        why.append(
            f"the particles have collapsed onto {unique} distinct points (raise "
            "n_rejuvenation or the proposal's reach)"
        )
    elif alive < 0.1 * len(log_w):
        why.append(f"only {alive} particles carry weight")
    remedy = (
        f"raise max_steps (None: 100 halvings of the ESS, {default_max_steps(zeta)} steps at "
        f"this zeta) or lower zeta{' (e.g. 0.95)' if zeta > 0.95 else ''} for fewer, larger steps"
    )
    if rejuvenate == "every_step" and cycle > 30:
        remedy += (
            "; with thousands of steps use rejuvenate = 'after_resampling' (moves only when "
            "resampling: the same weights for a fraction of the likelihood calls)"
        )
    if training_range is None:
        remedy += (
            "; a log-likelihood spread far beyond the training range of a surrogate is a "
            "surrogate artefact (pass training_range to check, or check it with n_check)"
        )
    why.append(remedy)
    return "; ".join(why)
