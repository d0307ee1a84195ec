"""Parameters and their prior distributions (built on ``scipy.stats``).

>>> import fbia
>>> E = fbia.Parameter("E", unit="Pa", bounds=(100.0, 800.0))        # uniform prior on bounds
>>> nu = fbia.Parameter("nu", bounds=(-0.8, 0.5),
...                     prior=fbia.priors.beta(43 / 13, 22 / 13, lower=-0.8, upper=0.5))
>>> round(float(nu.prior.mode), 3)                                   # Paper B: mode at 0.2
0.2
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ConfigError


@dataclass(frozen=True)
class Prior:
    """A univariate distribution: a frozen ``scipy.stats`` distribution plus its specification.

    Use the constructors in this module (:func:`uniform`, :func:`normal`,
    :func:`truncated_normal`, :func:`lognormal`, :func:`beta`) or :meth:`from_spec`.
    A :class:`Parameter` whose bounds cut the prior's support holds the prior truncated to
    them (:meth:`truncated`, ``scipy.stats.truncate``): ``truncation`` is then those bounds.
    """

    kind: str
    params: Mapping[str, float]
    dist: Any = field(repr=False, compare=False)
    mode: float = field(compare=False, default=math.nan)
    truncation: tuple[float, float] | None = None

    def logpdf(self, x: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(self.dist.logpdf(x), dtype=float)

    def pdf(self, x: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(self.dist.pdf(x), dtype=float)

    def ppf(self, u: ArrayLike) -> NDArray[np.float64]:
        """Inverse CDF: maps points of the unit interval (e.g. a Sobol design) to the prior."""
        if self.truncation is not None:
            return np.asarray(self.dist.icdf(np.asarray(u, dtype=float)), dtype=float)
        return np.asarray(self.dist.ppf(u), dtype=float)

    def rvs(self, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
        if self.truncation is not None:
            return np.asarray(self.dist.sample(size, rng=rng), dtype=float)
        return np.asarray(self.dist.rvs(size=size, random_state=rng), dtype=float)

    @property
    def support(self) -> tuple[float, float]:
        lo, hi = self.dist.support()
        return float(lo), float(hi)

    @property
    def mean(self) -> float:
        return float(self.dist.mean())

    @property
    def std(self) -> float:
        if self.truncation is not None:
            return float(self.dist.standard_deviation())
        return float(self.dist.std())

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        # scipy's truncated random variables do not pickle: rebuild from the specification
        return _rebuild, (self.kind, dict(self.params), self.truncation)

    def truncated(self, lower: float, upper: float) -> Prior:
        """This prior conditioned on ``[lower, upper]`` (itself if its support lies inside)."""
        lo, hi = self.support
        if lower <= lo and hi <= upper:
            return self
        lo, hi = max(lo, lower), min(hi, upper)
        _check(
            lo < hi and float(self.dist.cdf(hi) - self.dist.cdf(lo)) > 0.0,
            f"the {self.kind} prior has no mass inside the bounds [{lower}, {upper}]",
        )
        stats = _stats()
        frozen = self.dist
        names = [n.strip() for n in (frozen.dist.shapes or "").split(",") if n.strip()]
        kwds = dict(zip(names, frozen.args, strict=False)) | dict(frozen.kwds)
        loc, scale = kwds.pop("loc", 0.0), kwds.pop("scale", 1.0)
        variable = stats.make_distribution(frozen.dist)(**kwds) * scale + loc
        mode = min(max(self.mode, lo), hi) if math.isfinite(self.mode) else self.mode
        return Prior(
            self.kind,
            self.params,
            stats.truncate(variable, lb=lo, ub=hi),
            mode=mode,
            truncation=(lo, hi),
        )

    def spec(self) -> dict[str, Any]:
        """The specification as written in a study file: ``{"distribution": kind, ...}``."""
        return {"distribution": self.kind, **self.params}

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any], bounds: tuple[float, float] | None = None) -> Prior:
        """Build a prior from a study-file table, e.g. ``{distribution = "normal", mean = 1}``.

        ``uniform`` without ``lower``/``upper`` uses ``bounds``.
        """
        spec = dict(spec)
        kind = spec.pop("distribution", None)
        if kind not in _BUILDERS:
            raise ConfigError(
                f"unknown distribution {kind!r}; valid: {', '.join(sorted(_BUILDERS))}",
                "distribution",
            )
        if kind == "uniform" and not spec and bounds is not None:
            spec = {"lower": bounds[0], "upper": bounds[1]}
        builder, keys = _BUILDERS[kind]
        unknown = sorted(set(spec) - set(keys))
        missing = sorted(set(keys) - set(spec) - _OPTIONAL.get(kind, set()))
        if unknown:
            raise ConfigError(
                f"unknown key(s) {', '.join(unknown)} for a {kind} prior; valid: {', '.join(keys)}"
            )
        if missing:
            raise ConfigError(f"{kind} prior needs {', '.join(missing)}")
        try:
            values = {k: float(v) for k, v in spec.items()}
        except (TypeError, ValueError):
            raise ConfigError(f"{kind} prior parameters must be numbers, got {spec}") from None
        return builder(**values)


def _stats() -> Any:
    """``scipy.stats``, imported on first use: it costs about 2 s, ``import fbia`` should not."""
    from scipy import stats

    return stats


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise ConfigError(message)


def uniform(lower: float, upper: float) -> Prior:
    """Uniform on [lower, upper]."""
    _check(
        math.isfinite(lower) and math.isfinite(upper) and lower < upper,
        f"uniform prior needs lower < upper, got [{lower}, {upper}]",
    )
    return Prior(
        "uniform",
        {"lower": lower, "upper": upper},
        _stats().uniform(loc=lower, scale=upper - lower),
        mode=0.5 * (lower + upper),
    )


def normal(mean: float, std: float) -> Prior:
    """Normal N(mean, std²)."""
    _check(std > 0, f"normal prior needs std > 0, got {std}")
    return Prior("normal", {"mean": mean, "std": std}, _stats().norm(mean, std), mode=mean)


def truncated_normal(mean: float, std: float, lower: float, upper: float) -> Prior:
    """Normal N(mean, std²) truncated to [lower, upper] (``scipy.stats.truncnorm``)."""
    _check(std > 0, f"truncated normal prior needs std > 0, got {std}")
    _check(lower < upper, f"truncated normal prior needs lower < upper, got [{lower}, {upper}]")
    a, b = (lower - mean) / std, (upper - mean) / std
    return Prior(
        "truncated_normal",
        {"mean": mean, "std": std, "lower": lower, "upper": upper},
        _stats().truncnorm(a, b, loc=mean, scale=std),
        mode=min(max(mean, lower), upper),
    )


def lognormal(mu_ln: float, sigma_ln: float) -> Prior:
    """Log-normal: log x ~ N(mu_ln, sigma_ln²) (Paper B's parametrisation)."""
    _check(sigma_ln > 0, f"lognormal prior needs sigma_ln > 0, got {sigma_ln}")
    return Prior(
        "lognormal",
        {"mu_ln": mu_ln, "sigma_ln": sigma_ln},
        _stats().lognorm(s=sigma_ln, scale=math.exp(mu_ln)),
        mode=math.exp(mu_ln - sigma_ln**2),
    )


def beta(a: float, b: float, lower: float = 0.0, upper: float = 1.0) -> Prior:
    """Beta B(a, b) stretched onto [lower, upper] (Paper B: B(43/13, 22/13) on [-0.8, 0.5])."""
    _check(a > 0 and b > 0, f"beta prior needs a > 0 and b > 0, got a={a}, b={b}")
    _check(lower < upper, f"beta prior needs lower < upper, got [{lower}, {upper}]")
    if a > 1 and b > 1:
        mode = lower + (upper - lower) * (a - 1) / (a + b - 2)
    else:
        mode = math.nan
    return Prior(
        "beta",
        {"a": a, "b": b, "lower": lower, "upper": upper},
        _stats().beta(a, b, loc=lower, scale=upper - lower),
        mode=mode,
    )


_BUILDERS: dict[str, tuple[Any, tuple[str, ...]]] = {
    "uniform": (uniform, ("lower", "upper")),
    "normal": (normal, ("mean", "std")),
    "truncated_normal": (truncated_normal, ("mean", "std", "lower", "upper")),
    "lognormal": (lognormal, ("mu_ln", "sigma_ln")),
    "beta": (beta, ("a", "b", "lower", "upper")),
}
_OPTIONAL = {"beta": {"lower", "upper"}}


def _rebuild(
    kind: str, params: Mapping[str, float], truncation: tuple[float, float] | None
) -> Prior:
    """The prior of a specification (and truncation), for pickling."""
    prior: Prior = _BUILDERS[kind][0](**params)
    return prior if truncation is None else prior.truncated(*truncation)


@dataclass(frozen=True)
class Parameter:
    """A model input to calibrate (or, in ``InverseProblem.uncertain``, to marginalise).

    Parameters
    ----------
    name
        The name the forward model knows it by (e.g. ``"E"``, ``"nu"``, ``"inflow_rate"``).
    bounds
        Lower and upper bound; default: the prior's support when it is finite.
    prior
        A :class:`Prior`; default: uniform on ``bounds``.  Bounds are hard: a prior whose
        support reaches beyond them is truncated to them (renormalised, :meth:`Prior.truncated`).
    unit
        Unit, for reports and plots (e.g. ``"Pa"``, ``"mm^2/s"``).
    initial
        Initial guess for optimisers (must lie within the bounds).
    """

    name: str
    bounds: tuple[float, float] | None = None
    prior: Prior | None = None
    unit: str = ""
    initial: float | None = None

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("_", "a").isalnum():
            raise ConfigError(f"parameter name {self.name!r} must be a non-empty identifier")
        bounds = self.bounds
        if bounds is None and self.prior is not None:
            lo, hi = self.prior.support
            if math.isfinite(lo) and math.isfinite(hi):
                bounds = (lo, hi)
        if bounds is not None:
            if len(bounds) != 2:
                raise ConfigError(f"bounds must be [lower, upper], got {list(bounds)}", self.name)
            lo, hi = float(bounds[0]), float(bounds[1])
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ConfigError(f"bounds must be finite, got [{lo}, {hi}]", self.name)
            if not lo < hi:
                raise ConfigError(f"lower bound {lo} is not below upper bound {hi}", self.name)
            object.__setattr__(self, "bounds", (lo, hi))
        prior = self.prior
        if prior is None and self.bounds is not None:
            object.__setattr__(self, "prior", uniform(*self.bounds))
        elif prior is not None and self.bounds is not None:
            try:  # the bounds are hard: a prior reaching beyond them is cut at them
                object.__setattr__(self, "prior", prior.truncated(*self.bounds))
            except ConfigError as err:
                raise ConfigError(err.reason, self.name) from None
        if self.initial is not None:
            x0 = float(self.initial)
            if not math.isfinite(x0):
                raise ConfigError(f"initial guess must be finite, got {x0}", self.name)
            if self.bounds is not None and not self.bounds[0] <= x0 <= self.bounds[1]:
                raise ConfigError(
                    f"initial guess {x0} lies outside bounds [{self.bounds[0]}, {self.bounds[1]}]",
                    self.name,
                )
            object.__setattr__(self, "initial", x0)

    @property
    def lower(self) -> float:
        return -math.inf if self.bounds is None else self.bounds[0]

    @property
    def upper(self) -> float:
        return math.inf if self.bounds is None else self.bounds[1]

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description (for results and provenance)."""
        return {
            "name": self.name,
            "unit": self.unit,
            "bounds": list(self.bounds) if self.bounds else None,
            "prior": self.prior.spec() if self.prior else None,
            "initial": self.initial,
        }
