"""The typed result of the ``gp_smc`` iterator (Paper B): design, surrogate, posterior.

:class:`GpSmcResult` is a :class:`~fbia.core.problem.Result` whose parts are typed records
instead of string keys: :class:`DesignRuns` (the design and what its forward runs
gave), :class:`AdaptiveDesign` (the rounds of the adaptive design), :class:`SurrogateFit`
(the GP and its errors), :class:`PosteriorCheck` (the surrogate
against forward runs at posterior draws), :class:`ParticlePosterior` (the weighted
particles and their summaries) and :class:`SmcSummary` (how the sampler ran).  The plots,
:func:`fbia.iterators.gp_smc.posterior.save_posterior` and
:func:`~fbia.iterators.gp_smc.posterior.hpd_mass`
read these attributes; ``to_dict()`` (``result.json``) writes them under ``"info"``.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ...core.parameters import Prior
from ...core.problem import Result, html_table, jsonable
from ...core.version import __version__
from ..surrogates.residuals import KeepsSurrogate
from ..surrogates.uncertainty import SurrogateUncertainty
from .adaptive import PosteriorChange
from .inference_data import inference_data
from .model_check import ModelCheck

FloatArray = NDArray[np.float64]

__all__ = [
    "AdaptiveDesign",
    "AdaptiveRound",
    "DesignRuns",
    "GpSmcResult",
    "MAP_RESAMPLINGS",
    "MAP_SUPPORT",
    "LaplaceApproximation",
    "ParticlePosterior",
    "PosteriorCheck",
    "SmcSummary",
    "SurrogateFit",
    "check_particles",
    "marginal_mode",
]


#: intervals of the weighted histogram whose heaviest one is a marginal's mode
MODE_BINS = 30


def marginal_mode(values: FloatArray, weights: FloatArray, bins: int = MODE_BINS) -> float:
    """The peak of a 1-D marginal of weighted particles (Paper B Fig. 13): the centre of the
    heaviest of ``bins`` equal intervals between the smallest and the largest value.

    >>> marginal_mode(np.array([1.0, 2.0, 2.1, 4.0]), np.array([0.1, 0.3, 0.3, 0.3]), bins=3)
    2.5
    """
    lo, hi = float(np.min(values)), float(np.max(values))
    if hi <= lo:
        return lo
    mass, edges = np.histogram(values, bins=bins, range=(lo, hi), weights=weights)
    k = int(np.argmax(mass))
    return float(0.5 * (edges[k] + edges[k + 1]))


@dataclass(frozen=True)
class DesignRuns:
    """The space-filling design and its forward runs (stage 1-2)."""

    points: FloatArray  # (n, d) Sobol points, x then theta
    log_likelihood: FloatArray  # (n,) L of eq. 5 per run, -inf where the run failed
    status: list[str]  # evaluation status per run
    train_mask: NDArray[np.bool_]  # True: training point, False: held-out test point

    @property
    def ok(self) -> NDArray[np.bool_]:
        return np.isfinite(self.log_likelihood)


@dataclass(frozen=True)
class AdaptiveRound:
    """One round of the adaptive design: the posterior on the surrogate of ``n_runs`` runs,
    how far it moved since the last round, and the error of that surrogate at the new batch's
    posterior draws (predicted before it was trained on them)."""

    round: int
    n_runs: int  # design runs the round's GP was trained on
    n_batch: int  # runs the round added
    mean: FloatArray  # posterior mean of every input (x, theta) on the round's surrogate
    std: FloatArray
    mean_shift: float  # largest move of a mean since the last round, in posterior std
    std_change: float  # largest |log| ratio of a std to the last round's
    validation_rmse: float  # in L, at the batch's posterior draws
    log_evidence: float
    evidence_change: float  # |change of log Z| since the last round
    floor: float  # the soft floor of the round's training values
    seconds: float
    validation_centred: float = float("nan")  # the same without its mean error (what counts)
    quantile_shift: float = float("inf")  # largest move of a 5/50/95 % quantile, in std
    ess_fraction: float = float("nan")  # the last posterior's reweighting: ESS new / old
    optimised: bool = True  # the GP's hyperparameters optimised (else kept, conditioned)
    validation_z: float = float("nan")  # rms of error / GP std there (1: calibrated)

    def describe(self) -> str:
        return (
            f"round {self.round}: GP on {self.n_runs} runs"
            f"{'' if self.optimised else ' (hyperparameters kept)'}, the last posterior "
            f"moved {self.mean_shift:.3g} std (quantiles {self.quantile_shift:.3g}), std "
            f"changed {self.std_change:.3g}, log Z {self.evidence_change:.3g}; surrogate "
            f"error {self.validation_centred:.3g} in L at new posterior draws (RMSE "
            f"{self.validation_rmse:.3g} with its mean, {self.validation_z:.3g} GP std); "
            f"{self.n_batch} runs added"
        )

    def to_record(self) -> dict[str, Any]:
        return {
            k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in asdict(self).items()
        }


@dataclass(frozen=True)
class AdaptiveDesign:
    """How the adaptive design went: its rounds and why it stopped (``converged``: the
    posterior stopped moving and the surrogate was right at new posterior draws;
    ``budget``: n_train runs were used first)."""

    n_initial: int
    rounds: list[AdaptiveRound]
    stop_reason: str
    floor: float  # the final GP's soft floor (L below it is compressed)
    #: what the last batch did to the last round's posterior (the stopping measures)
    final_change: PosteriorChange | None = None

    @property
    def converged(self) -> bool:
        return self.stop_reason == "converged"

    def note(self) -> str:
        """The design in the result message, with a warning when it ran out of runs."""
        n = len(self.rounds)
        if self.converged:
            return f"; adaptive design converged in {n} rounds"
        return (
            f"; the adaptive design did not converge within n_train runs ({n} rounds): "
            "the posterior may still change with more runs (raise n_train)"
        )


@dataclass(frozen=True)
class SurrogateFit(KeepsSurrogate):
    """The GP surrogate of L (stage 3): its description and errors, and what rebuilds it;
    the fitted surrogate itself for the plots and
    :func:`~fbia.iterators.gp_smc.posterior.hpd_mass` (:class:`KeepsSurrogate`)."""

    summary: dict[str, Any]  # kernel, hyperparameters, n_train, LOO and held-out errors
    state: dict[str, Any]  # GpSurrogate.from_state(state) gives the GP back
    best_x: FloatArray  # the training run of highest L
    best_log_likelihood: float


#: the largest spread of the surrogate's errors in L at posterior draws (their standard
#: deviation; a constant error cancels in the posterior) that counts as "well below 1": an
#: error varying by 0.5 changes posterior density ratios by up to a factor e^0.5 = 1.65, and
#: moves a posterior mean by at most about 0.5 posterior std (adaptive.centred_rmse)
RELIABLE_RMSE = 0.5
#: the largest share of posterior draws at which the forward model may fail: more (3 or more
#: of 8) says the posterior holds mass where the model produces no state (for a share of 10 %
#: in truth, 3 of 8 happens with probability 0.04)
RELIABLE_FAILED_SHARE = 0.25


@dataclass(frozen=True)
class PosteriorCheck:
    """Forward runs at ``n`` distinct posterior draws: the surrogate's error where the
    posterior is, in units of L (an error of order 1 changes posterior ratios by e)."""

    n: int
    n_failed: int
    x: FloatArray
    log_likelihood: FloatArray
    rmse: float
    max_abs: float
    mean_error: float
    #: why the draws were run: "check" (draws of the posterior) or "uncertainty" (draws of the
    #: posterior averaged over the GP's sample paths, which moved it: a repair's runs)
    cause: str = "check"

    @property
    def centred_rmse(self) -> float:
        """The errors' standard deviation (n - 1 in the denominator): the RMSE without the
        mean error, which cancels when the posterior is normalised; NaN for n < 2."""
        if self.n < 2:
            return float("nan")
        var = max(self.rmse**2 - self.mean_error**2, 0.0) * self.n / (self.n - 1)
        return float(np.sqrt(var))

    @property
    def reliable(self) -> bool:
        """Whether the spread of the surrogate's errors at the posterior draws is well below
        1 in L (:attr:`centred_rmse` < :data:`RELIABLE_RMSE`) and the model ran at all but a
        few of them (:data:`RELIABLE_FAILED_SHARE`); False when fewer than 2 draws could be
        checked."""
        return bool(self.n >= 2 and self.centred_rmse < RELIABLE_RMSE and not self.fails_often)

    @property
    def fails_often(self) -> bool:
        """Whether more than :data:`RELIABLE_FAILED_SHARE` of the draws failed."""
        return self.n_failed > RELIABLE_FAILED_SHARE * (self.n + self.n_failed)

    def note(self) -> str:
        """The check in the result message, with a warning when it failed."""
        if self.n == 0:
            return (
                f"; the surrogate could not be checked: all {self.n_failed} forward runs at "
                "posterior draws failed (the posterior is not reliable)"
            )
        text = (
            f"; surrogate error {self.centred_rmse:.3g} in L at {self.n} posterior draws "
            f"(RMSE {self.rmse:.3g} with the mean error {self.mean_error:.3g}, which cancels)"
        )
        if self.fails_often:
            text += (
                f"; the forward model failed at {self.n_failed} of {self.n + self.n_failed} "
                "posterior draws: the posterior holds mass where the model produces no state "
                "(the posterior is not reliable; failures = 'classify' keeps it where the "
                "model runs)"
            )
        elif not self.reliable:
            text += (
                f" (not well below 1, limit {RELIABLE_RMSE:g}: the posterior is not reliable; "
                "train on more runs)"
                if self.n >= 2
                else " (fewer than 2 draws could be checked: the posterior is not reliable)"
            )
        return text


@dataclass(frozen=True)
class LaplaceApproximation:
    """N(mean, cov) from the Hessian of the log-posterior at the MAP (Paper B Fig. 9a/c)."""

    mean: FloatArray
    hessian: FloatArray
    cov: FloatArray | None  # None where the Hessian is not negative definite
    negative_definite: bool


def principal_angle(a: FloatArray, b: FloatArray, width: FloatArray) -> float:
    """The angle [degrees, 0-90] between the principal axes (largest variance) of the 2-D
    covariances ``a`` and ``b``, in coordinates scaled by ``width`` (the design box: the axes
    of Paper B Fig. 9a), e.g. the Laplace approximation's against the particles' ("almost
    orthogonal" in the paper)."""
    scale = np.diag(1.0 / np.asarray(width, dtype=float))
    axes = [np.linalg.eigh(scale @ c @ scale)[1][:, -1] for c in (a, b)]
    cosine = min(1.0, abs(float(axes[0] @ axes[1])))
    return float(np.degrees(np.arccos(cosine)))


#: How many resamplings of the particles the histogram MAP's support is measured over
#: (:func:`~fbia.iterators.gp_smc.posterior.map_by_binning`).
MAP_RESAMPLINGS = 200

#: The least support (the share of resamplings that keep it) for which a parameter's interval
#: of the histogram MAP counts as determined by the particles; below it the result says so
#: (message, ``GpSmcResult.undetermined``) and a paper comparison of it does not agree.
MAP_SUPPORT = 0.9


@dataclass(frozen=True)
class ParticlePosterior:
    """The weighted particles of the last SMC step and their summaries (stage 5)."""

    names: list[str]  # x names, then theta names
    n_x: int
    particles: FloatArray  # (N, d)
    weights: FloatArray  # (N,), normalised
    log_likelihood: FloatArray  # (N,) L (surrogate or direct)
    log_prior: FloatArray  # (N,)
    log_evidence: float
    log_evidence_se: float
    mean: FloatArray  # of x
    cov: FloatArray  # of x
    mean_all: FloatArray  # of (x, theta)
    cov_all: FloatArray
    max_likelihood: FloatArray  # the particle of highest L
    credible_intervals: dict[str, list[float]]  # 2.5 %, 50 %, 97.5 % per input
    map: FloatArray  # of x
    map_method: str
    best_particle: FloatArray | None = None  # with theta: the particle of highest posterior
    laplace: LaplaceApproximation | None = None
    #: with theta, per x: the share of resamplings of the particles that keep the histogram
    #: MAP's interval (posterior.map_by_binning); None for the best particle's MAP
    map_support: FloatArray | None = None

    @property
    def std(self) -> FloatArray:
        return np.asarray(np.sqrt(np.diag(self.cov)))

    def undetermined_map(self) -> dict[str, float]:
        """The x whose histogram MAP interval fewer than :data:`MAP_SUPPORT` of the
        resamplings keep, with that share (none for the best particle's MAP)."""
        if self.map_support is None:
            return {}
        support = zip(self.names, map(float, self.map_support), strict=False)
        return {name: s for name, s in support if s < MAP_SUPPORT}

    @property
    def log_posterior(self) -> FloatArray:
        """L + log p, unnormalised."""
        return np.asarray(self.log_likelihood + self.log_prior)


def check_particles(
    where: str,
    names: Sequence[str],
    n_x: int,
    particles: FloatArray,
    weights: FloatArray,
    per_particle: Mapping[str, FloatArray],
) -> None:
    """ValueError naming the first array of weighted particles read back that does not fit
    (``where``: the prefix of the arrays' names): ``names`` distinct, 1 <= ``n_x`` <= d of
    them, ``particles`` (N, d) finite, a column per name, ``weights`` (N,) non-negative and
    summing to 1, each of ``per_particle`` (N,) without NaN or +inf."""
    d = len(names)
    if len(set(names)) != d:
        raise ValueError(f"{where}names {list(names)} holds a name twice")
    if not 1 <= n_x <= d:
        raise ValueError(f"{where}n_x is {n_x}, not 1 to {d} (the number of names)")
    if particles.ndim != 2 or particles.shape[1] != d or len(particles) == 0:
        raise ValueError(
            f"{where}particles has shape {particles.shape}, not (N, {d}): a column per name of "
            f"{list(names)}"
        )
    n = len(particles)
    if not np.all(np.isfinite(particles)):
        raise ValueError(f"{where}particles holds NaN or infinite values")
    if weights.shape != (n,):
        raise ValueError(f"{where}weights has shape {weights.shape}, not ({n},): one per particle")
    total = float(np.sum(weights))
    if not (np.all(weights >= 0.0) and abs(total - 1.0) <= 1e-6):
        raise ValueError(f"{where}weights are not non-negative numbers summing to 1 ({total:.6g})")
    for key, values in per_particle.items():
        if values.shape != (n,):
            raise ValueError(f"{where}{key} has shape {values.shape}, not ({n},): one per particle")
        if np.any(np.isnan(values) | (values == np.inf)):
            raise ValueError(f"{where}{key} holds NaN or +inf")


@dataclass(frozen=True)
class SmcSummary:
    """How the sampler ran (Algorithm 1)."""

    n_steps: int
    gammas: list[float]
    ess: list[float]
    acceptance: list[float]
    nfev_log_likelihood: int
    final_ess: float
    rejuvenate: str
    steps_with_moves: int
    #: the tabulated L's size and error at the final particles (fbia.iterators.smc.table)
    table: dict[str, Any] | None = None


@dataclass
class GpSmcResult(Result):
    """:class:`~fbia.core.problem.Result` of ``gp_smc``; ``x`` is the MAP.

    Attributes (besides those of ``Result``; None where the stage did not run)
    ----------
    names, n_x
        Input names (x, then theta) and the number of calibration parameters x.
    mode
        ``surrogate`` or ``direct``.
    priors
        The inputs' descriptions (name, unit, bounds, prior).
    design, adaptive, surrogate, check, uncertainty, posterior, smc
        The stages' records (see the module docstring); ``adaptive`` only with the
        adaptive design, ``uncertainty`` only with ``surrogate_uncertainty =
        "expected_posterior"`` (then ``posterior`` is the expected posterior).
    failed_checks
        RMSE in L of each check at posterior draws that failed and was repaired before
        ``check`` (gp_smc's ``check_repairs``; empty when the first check decided).
    seconds
        Wall time of the analysis.
    model_check
        Whether the model and the prior can explain the data (:mod:`.model_check`: posterior
        mass piled against a prior bound, the best forward run against the stated noise);
        its causes make a ``completed`` result ``unreliable``.
    """

    names: list[str] = field(default_factory=list)
    n_x: int = 0
    mode: str = "surrogate"
    priors: list[dict[str, Any]] = field(default_factory=list)
    design: DesignRuns | None = field(default=None, repr=False)
    adaptive: AdaptiveDesign | None = field(default=None, repr=False)
    surrogate: SurrogateFit | None = field(default=None, repr=False)
    check: PosteriorCheck | None = None
    uncertainty: SurrogateUncertainty | None = field(default=None, repr=False)
    posterior: ParticlePosterior | None = field(default=None, repr=False)
    smc: SmcSummary | None = field(default=None, repr=False)
    failed_checks: list[float] = field(default_factory=list)
    seconds: float = 0.0
    model_check: ModelCheck | None = None
    #: what every gp_smc result.json holds (fbia.load_result)
    required_fields: ClassVar[tuple[str, ...]] = ("names", "n_x", "mode", "posterior")

    def check_loaded(self) -> None:
        """The posterior's arrays against its names and particles (:func:`check_particles`)
        and its summaries' shapes; the design's arrays, one entry per design point."""
        post = self.posterior
        if post is not None:
            where = "info.posterior."
            per_particle = {"log_likelihood": post.log_likelihood, "log_prior": post.log_prior}
            check_particles(where, post.names, post.n_x, post.particles, post.weights, per_particle)
            d, n_x = len(post.names), post.n_x
            arrays = {
                "mean": (post.mean, (n_x,)),
                "cov": (post.cov, (n_x, n_x)),
                "mean_all": (post.mean_all, (d,)),
                "cov_all": (post.cov_all, (d, d)),
                "max_likelihood": (post.max_likelihood, (d,)),
                "map": (post.map, (n_x,)),
                "best_particle": (post.best_particle, (d,)),
                "map_support": (post.map_support, (n_x,)),
            }
            if post.laplace is not None:
                arrays["laplace.mean"] = (post.laplace.mean, (n_x,))
                arrays["laplace.hessian"] = (post.laplace.hessian, (n_x, n_x))
                arrays["laplace.cov"] = (post.laplace.cov, (n_x, n_x))
            for key, (values, shape) in arrays.items():
                if values is not None and values.shape != shape:
                    raise ValueError(f"{where}{key} has shape {values.shape}, not {shape}")
            for name in post.names:
                if len(post.credible_intervals.get(name, ())) != 3:
                    raise ValueError(f"{where}credible_intervals.{name} is not 3 numbers")
        design = self.design
        if design is not None:
            n = len(design.points)
            if design.points.ndim != 2:
                raise ValueError(f"info.design.points has shape {design.points.shape}, not (n, d)")
            sizes = {
                "log_likelihood": design.log_likelihood.shape,
                "status": (len(design.status),),
                "train_mask": design.train_mask.shape,
            }
            for key, shape in sizes.items():
                if shape != (n,):
                    raise ValueError(f"info.design.{key} has shape {shape}, not ({n},)")

    def summary(self) -> str:
        """The status line, the MAP, then per input (x, theta, sigma_N when inferred) the
        posterior mean, std and 95 % interval, and the adaptive design's rounds."""
        text = super().summary()
        post = self.posterior
        if post is None:
            return text
        lines = [text]
        if post.map_support is not None:
            kept = ", ".join(
                f"{n} {s * 100:.0f} %" for n, s in zip(post.names, post.map_support, strict=False)
            )
            loose = list(post.undetermined_map())
            lines.append(
                f"  MAP: {post.map_method}; each input's interval kept in: {kept}"
                + (
                    f"; not determined (< {MAP_SUPPORT * 100:.0f} %): {', '.join(loose)}"
                    if loose
                    else ""
                )
            )
        lines.append("  posterior (mean, std, 2.5 % / 50 % / 97.5 %):")
        std = np.sqrt(np.maximum(np.diag(post.cov_all), 0.0))
        for j, name in enumerate(post.names):
            lo, mid, hi = post.credible_intervals[name]
            lines.append(
                f"    {name:<12} {post.mean_all[j]:<12.6g} {std[j]:<12.4g} "
                f"{lo:.6g} / {mid:.6g} / {hi:.6g}"
            )
        if self.surrogate is not None:
            info = self.surrogate.summary
            lines.append(
                f"  surrogate: residual emulator, {info.get('components')} principal "
                f"components of {info.get('n_residuals')} residuals"
                if info.get("surrogate") == "residuals"
                else "  surrogate: GP of L (Paper B)"
            )
        if self.adaptive is not None:
            lines.append(
                f"  adaptive design: {self.adaptive.n_initial} start runs, "
                f"{len(self.adaptive.rounds)} rounds, stopped: {self.adaptive.stop_reason}"
            )
            lines.append(
                "    (moved: what the round's GP, refitted with the last batch, did to the last "
                "posterior, in std; error: the spread of the GP's errors at the batch's "
                "posterior draws, in L)"
            )
            for r in self.adaptive.rounds:
                lines.append(
                    f"    round {r.round:<3} runs {r.n_runs:<5} +{r.n_batch:<4} mean moved "
                    f"{r.mean_shift:<8.3g} quantiles {r.quantile_shift:<8.3g} std changed "
                    f"{r.std_change:<8.3g} error at new draws {r.validation_centred:.3g}"
                )
            change, rounds = self.adaptive.final_change, self.adaptive.rounds
            if change is not None and rounds:
                lines.append(
                    f"    the design's last GP, on {rounds[-1].n_runs + rounds[-1].n_batch} "
                    f"runs: mean moved {change.mean_shift:.3g}, quantiles "
                    f"{change.quantile_shift:.3g}, std changed {change.std_change:.3g}, "
                    f"log Z {change.evidence_change:.3g}"
                )
        return "\n".join(lines)

    def posterior_estimate(self) -> ParticlePosterior | None:
        """The posterior (its names, n_x, MAP and mean: :class:`fbia.core.problem.
        PosteriorEstimate`), None when the run produced none."""
        return self.posterior

    def quantities(self) -> dict[str, float]:
        """Besides :meth:`Result.quantities` (``x.<name>`` is the MAP): per input of the
        posterior (x, theta, an inferred sigma_N) ``map.<name>`` (x only), ``pm.<name>``
        (posterior mean), ``sd.<name>`` (posterior std), ``q2.5.<name>``, ``q97.5.<name>``
        (95 % interval), ``mode.<name>`` (peak of the 1-D marginal: :func:`marginal_mode`);
        with uncertain inputs ``map_support.<name>`` (x only: the share of resamplings of the
        particles that keep the histogram MAP's interval, :meth:`undetermined`);
        ``log_evidence``; ``check.rmse`` (the surrogate's error in L at the posterior draws);
        ``design.n_failed`` and per input ``design.failed_min.<name>``,
        ``design.failed_max.<name>``: where the design's failed runs lie (NaN if none failed);
        ``laplace.angle`` (two inputs): the angle between the principal axes of the Laplace
        approximation and of the particles in the design box's scale (:func:`principal_angle`)."""
        out = super().quantities()
        if self.check is not None:
            out["check.rmse"] = float(self.check.rmse)
        if self.design is not None:
            failed = self.design.points[~self.design.ok]
            out["design.n_failed"] = float(len(failed))
            for j, name in enumerate(self.names[: self.design.points.shape[1]]):
                column = failed[:, j]
                out[f"design.failed_min.{name}"] = float(column.min()) if len(column) else np.nan
                out[f"design.failed_max.{name}"] = float(column.max()) if len(column) else np.nan
        post = self.posterior
        if post is None:
            return out
        std = np.sqrt(np.maximum(np.diag(post.cov_all), 0.0))
        for j, name in enumerate(post.names):
            if j < len(post.map):
                out[f"map.{name}"] = float(post.map[j])
            if post.map_support is not None and j < len(post.map_support):
                out[f"map_support.{name}"] = float(post.map_support[j])
            out[f"pm.{name}"] = float(post.mean_all[j])
            out[f"sd.{name}"] = float(std[j])
            lo, _, hi = post.credible_intervals[name]
            out[f"q2.5.{name}"], out[f"q97.5.{name}"] = float(lo), float(hi)
            out[f"mode.{name}"] = marginal_mode(post.particles[:, j], post.weights)
        out["log_evidence"] = float(post.log_evidence)
        lap = post.laplace
        if lap is not None and lap.cov is not None and len(post.mean) == 2 and self.design:
            width = np.ptp(self.design.points[:, :2], axis=0)
            out["laplace.angle"] = principal_angle(lap.cov, post.cov, width)
        return out

    def undetermined(self) -> dict[str, str]:
        """``map.<name>`` of each x whose histogram MAP interval the particles do not decide:
        kept by fewer than :data:`MAP_SUPPORT` of the resamplings (the posterior is flat there
        at the bins' resolution, Paper B: 'a rough estimate')."""
        post = self.posterior
        if post is None:
            return {}
        n = MAP_RESAMPLINGS
        return {
            f"map.{name}": (
                f"the histogram MAP's interval of {name} is not determined: the heaviest cell "
                f"of a resampling of the particles keeps it in {s * 100:.0f} % of {n} (needed: "
                f"{MAP_SUPPORT * 100:.0f} %)"
            )
            for name, s in post.undetermined_map().items()
        }

    def units(self) -> dict[str, str]:
        """The inputs' units (from ``priors``, the inputs' descriptions)."""
        own = {str(p["name"]): str(p["unit"]) for p in self.priors if p.get("unit")}
        return {**super().units(), **own}

    def to_records(self) -> list[dict[str, Any]]:
        """The posterior summary as plain rows, one per input of the posterior (x, theta, an
        inferred sigma_N; :meth:`to_dataframe` wraps them): ``input``, ``unit``, ``map`` (x
        only, NaN for the rest), ``pm`` (posterior mean), ``std``, ``q2.5``, ``q50``,
        ``q97.5`` (the weighted particles' quantiles); as :meth:`summary` and
        :meth:`quantities` give them. No rows without a posterior."""
        post = self.posterior
        if post is None:
            return []
        units = self.units()
        std = np.sqrt(np.maximum(np.diag(post.cov_all), 0.0))
        rows = []
        for j, name in enumerate(post.names):
            lo, mid, hi = post.credible_intervals[name]
            rows.append(
                {
                    "input": name,
                    "unit": units.get(name, ""),
                    "map": float(post.map[j]) if j < len(post.map) else float("nan"),
                    "pm": float(post.mean_all[j]),
                    "std": float(std[j]),
                    "q2.5": float(lo),
                    "q50": float(mid),
                    "q97.5": float(hi),
                }
            )
        return rows

    def _html_body(self) -> str:
        """Per input the MAP, the posterior mean, std and 95 % interval with its unit, and how
        the posterior was made; without a posterior, the base's (the MAP, if any)."""
        records = self.to_records()
        if not records:
            return super()._html_body()
        head = ["input", "MAP", "PM", "std", "2.5 %", "97.5 %", "unit"]
        keys = ["input", "map", "pm", "std", "q2.5", "q97.5", "unit"]
        post = self.posterior
        assert post is not None
        table = [[r[k] for k in keys] for r in records]
        if post.map_support is not None:
            head.insert(2, "MAP support")
            for j, row in enumerate(table):
                row.insert(
                    2, f"{post.map_support[j] * 100:.0f} %" if j < len(post.map_support) else ""
                )
        parts = [html_table(head, table)]
        how = (
            f"{self.mode} mode, {len(post.weights)} particles, log evidence {post.log_evidence:.4g}"
        )
        if self.check is not None:
            how += self.check.note()
        parts.append(f"<p>{html.escape(how)}</p>")
        return "".join(parts)

    def to_inference_data(
        self, problem: Any = None, n_draws: int | None = None, seed: int = 0
    ) -> Any:
        """The posterior as an ``arviz.InferenceData`` (:mod:`.inference_data`): posterior,
        prior, log_likelihood, sample_stats (with the particles' weights and the SMC's
        diagnostics) and, given the ``problem``, observed_data; units per variable, fbia and
        plugin versions, study and seed as attributes (from ``provenance`` once ``fbia run``
        has written the result)."""
        post = self.posterior
        if post is None:
            raise ConfigError("this result has no posterior", "to_inference_data")
        priors, units = {}, {}
        for spec in self.priors:
            name = str(spec.get("name"))
            units[name] = str(spec.get("unit") or "-")
            if spec.get("prior"):
                bounds = spec.get("bounds")
                priors[name] = Prior.from_spec(
                    spec["prior"], None if bounds is None else tuple(bounds)
                )
        made = self.provenance or {}
        attrs = {
            "fbia_version": made.get("fbia", __version__),
            "plugins": made.get("plugins", []),
            "study": made.get("study_name") or made.get("study_file") or "",
            "seed": made.get("seed") if made.get("seed") is not None else -1,
            "inference_library": "fbia gp_smc (GP surrogate + SMC, Paper B)",
        }
        smc = {}
        if self.smc is not None:
            smc = {
                "smc_final_ess": self.smc.final_ess,
                "smc_tempering_steps": self.smc.n_steps,
                "smc_steps_with_moves": self.smc.steps_with_moves,
            }
        smc["log_evidence"] = float(post.log_evidence)
        observed = None
        if problem is not None:
            observed = {
                f"interface_{k}": np.asarray(o.interface.vertices)
                for k, o in enumerate(problem.observations, start=1)
                if o.interface is not None
            }
        return inference_data(
            post.names,
            post.particles,
            post.weights,
            post.log_likelihood,
            post.log_prior,
            seed=seed,
            n_draws=n_draws,
            priors=priors,
            units=units,
            attrs=attrs,
            smc=smc,
            observed=observed,
        )

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        parts: dict[str, Any] = {
            "names": self.names,
            "n_x": self.n_x,
            "mode": self.mode,
            "priors": self.priors,
            "failed_checks": self.failed_checks,
            "seconds": self.seconds,
        }
        parts_named = (
            "design",
            "adaptive",
            "surrogate",
            "check",
            "uncertainty",
            "posterior",
            "smc",
            "model_check",
        )
        for name in parts_named:
            value = getattr(self, name)
            parts[name] = None if value is None else asdict(value)
        out["info"] = {**out["info"], **jsonable(parts)}
        return out
