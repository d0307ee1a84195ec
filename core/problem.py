"""The inverse problem, the record of one evaluation, the result of an iterator, and the
members an iterator may declare (:class:`IteratorMembers`, beside ``result_type``'s default).

>>> import fbia
>>> model = fbia.forward_model("analytic_mound_2d")
>>> truth = {"E": 400.0, "nu": 0.3}
>>> obs = fbia.synthetic_observations(model, truth, [{"inflow_rate": 100.0}], noise_std=0.0, seed=1)
>>> problem = fbia.InverseProblem(model=model, measure=fbia.measure("cpp"), observations=obs,
...     parameters=[fbia.Parameter("E", bounds=(100, 800)),
...                 fbia.Parameter("nu", bounds=(-0.8, 0.5))])
>>> ev = problem.evaluate(truth)
>>> ev.ok, round(ev.distance, 12)
(True, 0.0)
"""

from __future__ import annotations

import html
import json
import math
import shutil
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, final, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ConfigError, ForwardModelError, MeasureError
from .interface import NonFiniteInterfaceError
from .observation import Coordinate, Observation, Solution, coordinate_key
from .options import Configurable, plugin_options
from .parameters import Parameter, Prior
from .protocols import ForwardModelBase, InverseIterator, MeasureBase

#: Evaluation outcomes.  ``failed``: the forward model raised ForwardModelError;
#: ``measure_failed``: the measure could not compare (MeasureError); ``error``: the plugin
#: raised something it should not have (a bug, reported with its type).
STATUSES = ("ok", "failed", "measure_failed", "error")
#: residual vectors longer than this stay out of a record's JSON (``result.json``,
#: ``evaluations.jsonl``; the store keeps them in binary): rkhs's default residual vector has
#: about 30 000 entries per run on the flow cell, which made a 1000-run study's two files
#: 600-760 MB. ``n_residuals`` and the distances D are always written.
JSON_RESIDUALS_MAX = 2000


@dataclass
class Evaluation:
    """The record of one forward run and its comparison with every observation."""

    index: int
    x: dict[str, float]
    status: str = "ok"
    message: str = ""
    residuals: NDArray[np.float64] | None = None
    distances: list[float] | None = None
    time: float = 0.0
    workdir: str | None = None
    diagnostics: dict[str, Any] = field(default_factory=dict)
    solution: Solution | None = field(default=None, repr=False)
    #: dr/dx (n_r, n): columns in the order of :attr:`jacobian_names`, from the model's
    #: tangents (``fbia.iterators.tangents``); None when the run gave none
    jacobian: NDArray[np.float64] | None = field(default=None, repr=False)
    jacobian_names: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def distance(self) -> float:
        """D over all observations: the 2-norm of the per-observation distances (eq. 6/7)."""
        if self.distances is None:
            return math.nan
        return float(np.linalg.norm(self.distances))

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "x": self.x,
            "status": self.status,
            "message": self.message,
            # NaN/inf (an "error" record of a measure that returned them) as strings, so
            # that Result.save (allow_nan=False) never fails on a record.
            "residuals": (
                None
                if self.residuals is None or len(self.residuals) > JSON_RESIDUALS_MAX
                else jsonable(self.residuals)
            ),
            "n_residuals": None if self.residuals is None else len(self.residuals),
            "distances": jsonable(self.distances),
            "time": self.time,
            "workdir": self.workdir,
            "diagnostics": jsonable(self.diagnostics),
        }


@runtime_checkable
class Evaluable(Protocol):
    """What an evaluator runs: an :class:`InverseProblem`, or the residual function of
    ``fbia.least_squares`` dressed as one.  ``parameters`` and ``uncertain`` (their priors)
    are what a worker may leave behind (:func:`fbia.execution.isolation.run_view`)."""

    parameters: Sequence[Parameter]
    uncertain: Sequence[Parameter]

    def evaluate(
        self,
        x: Mapping[str, float],
        workdir: str | Path | None = None,
        index: int = 0,
        keep_solution: bool = True,
    ) -> Evaluation: ...


class ProblemLike(Evaluable, Protocol):
    """A problem with named parameters in a box: what the Levenberg-Marquardt iterator needs
    (:class:`InverseProblem`, or ``fbia.least_squares``'s
    :class:`~fbia.iterators.least_squares.ResidualFunctionProblem`)."""

    @property
    def names(self) -> list[str]: ...

    @property
    def lower(self) -> NDArray[np.float64]: ...

    @property
    def upper(self) -> NDArray[np.float64]: ...


@dataclass
class InverseProblem:
    """Forward model + measure + observations + parameters: what an iterator solves.

    Parameters
    ----------
    model
        A forward model (a :class:`~fbia.core.protocols.ForwardModelBase`).
    measure
        A measure (a :class:`~fbia.core.protocols.MeasureBase`).
    observations
        The observed states; their coordinates are the states every forward run computes.
    parameters
        The calibration parameters x (names the model knows), with bounds and priors.
    uncertain
        Uncertain model inputs θ with prior distributions (Paper B eq. 3a-3b).
    noise_std
        Standard deviation σ_N of the likelihood noise in mm (Paper B eq. 5); observations may
        override it with their own ``noise_std``.
    noise_prior
        A prior on σ_N [mm] when it is not known: Bayesian iterators then infer it (one σ_N
        for all observations; instead of ``noise_std``, and observations without their own).
    fixed
        Model inputs held at given values in every run (e.g. ``{"inflow_rate": 100.0}``).
    truth
        The ground truth of synthetic observations, by name (plots mark it; no iterator
        reads it).
    """

    model: ForwardModelBase
    measure: MeasureBase
    observations: Sequence[Observation]
    parameters: Sequence[Parameter]
    uncertain: Sequence[Parameter] = ()
    noise_std: float | None = None
    fixed: Mapping[str, float] = field(default_factory=dict)
    noise_prior: Prior | None = None
    truth: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        self.observations = list(self.observations)
        self.parameters = list(self.parameters)
        self.uncertain = list(self.uncertain)
        self.fixed = dict(self.fixed)
        for role, plugin, base in (
            ("model", self.model, ForwardModelBase),
            ("measure", self.measure, MeasureBase),
        ):
            if not isinstance(plugin, base):  # the framework calls the base's members directly
                name = type(plugin).__name__
                raise ConfigError(f"the {role} {name} does not derive from fbia.{base.__name__}")
        if not self.observations:
            raise ConfigError("an inverse problem needs at least one observation")
        if not self.parameters:
            raise ConfigError("an inverse problem needs at least one parameter")
        for obs in self.observations:
            if not isinstance(obs, Observation):
                raise ConfigError(
                    f"observations must be fbia.Observation, got {type(obs).__name__}"
                )
        names = [p.name for p in [*self.parameters, *self.uncertain]]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ConfigError(f"parameter(s) named twice: {', '.join(dupes)}")
        clash = sorted(set(names) & set(self.fixed))
        if clash:
            raise ConfigError(f"parameter(s) both varied and fixed: {', '.join(clash)}")
        known = set(self.model.parameter_names())
        unknown = [n for n in [*names, *self.fixed] if n not in known]
        if unknown:
            raise ConfigError(
                f"the forward model has no parameter(s) {', '.join(map(repr, unknown))}; "
                f"it knows: {', '.join(sorted(known))}"
            )
        for p in self.uncertain:
            if p.prior is None:
                raise ConfigError("an uncertain parameter needs a prior distribution", p.name)
        if self.noise_std is not None and not (
            self.noise_std > 0 and math.isfinite(self.noise_std)
        ):
            raise ConfigError(f"noise_std must be a positive number, got {self.noise_std}")
        if self.noise_prior is not None:
            self._check_noise_prior()
        # A coordinate fixes its inputs per state, so varying the same input would be ignored
        # silently (e.g. an uncertain inflow rate with observations at {"inflow_rate": 100}).
        coordinate_names = {k for o in self.observations for k in o.coordinate}
        overlap = sorted(coordinate_names & set(names))
        if overlap:
            raise ConfigError(
                f"parameter(s) {', '.join(overlap)} also set by the observations' coordinates; "
                "a coordinate fixes its value in each state, so the parameter would have no "
                "effect: drop it from the coordinates (e.g. an uncertain inflow rate with "
                "coordinate {}) or from the parameters"
            )
        dims = {o.dim for o in self.observations}
        if len(dims) > 1:
            raise ConfigError(f"observations mix dimensions {sorted(dims)}")

    def _check_noise_prior(self) -> None:
        """A prior on sigma_N: positive support, and no known sigma_N beside it."""
        prior = self.noise_prior
        if not isinstance(prior, Prior):
            raise ConfigError(
                f"noise_prior must be an fbia.Prior, got {type(prior).__name__}", "noise_prior"
            )
        if not prior.support[0] >= 0.0:
            raise ConfigError(
                f"a prior on sigma_N needs positive support, this one starts at "
                f"{prior.support[0]:g} (use lognormal, or bounds above 0)",
                "noise_prior",
            )
        if self.noise_std is not None or any(o.noise_std is not None for o in self.observations):
            raise ConfigError(
                "sigma_N is either known (noise_std) or inferred (noise_prior), not both",
                "noise_prior",
            )

    # -- names and vectors -------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        """Names of the calibration parameters x, in order."""
        return [p.name for p in self.parameters]

    @property
    def uncertain_names(self) -> list[str]:
        return [p.name for p in self.uncertain]

    @property
    def dim(self) -> int:
        """Spatial dimension of the observations."""
        return self.observations[0].dim

    @property
    def lower(self) -> NDArray[np.float64]:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> NDArray[np.float64]:
        return np.array([p.upper for p in self.parameters])

    def as_dict(
        self, x: ArrayLike | Mapping[str, float], theta: ArrayLike | None = None
    ) -> dict[str, float]:
        """The full model input {name: value}: calibration x, uncertain θ and fixed inputs."""
        if isinstance(x, Mapping):
            out = {n: float(x[n]) for n in self.names if n in x}
            missing = [n for n in self.names if n not in x]
            if missing:
                raise ConfigError(f"no value for parameter(s) {', '.join(missing)}")
            extra = [k for k in x if k not in self.names and k not in self.uncertain_names]
            if extra:
                raise ConfigError(
                    f"unknown parameter(s) {', '.join(extra)}; valid: {', '.join(self.names)}"
                )
            out.update({n: float(x[n]) for n in self.uncertain_names if n in x})
        else:
            vec = np.asarray(x, dtype=float).ravel()
            if len(vec) != len(self.names):
                raise ConfigError(f"expected {len(self.names)} parameter values, got {len(vec)}")
            out = dict(zip(self.names, map(float, vec), strict=True))
        if theta is not None:
            tv = np.asarray(theta, dtype=float).ravel()
            out.update(zip(self.uncertain_names, map(float, tv), strict=True))
        return {**self.fixed, **out}

    def vector(self, values: Mapping[str, float]) -> NDArray[np.float64]:
        return np.array([float(values[n]) for n in self.names])

    def coordinates(self) -> list[dict[str, float]]:
        """Distinct coordinates of the observations, in order of first appearance."""
        seen: dict[Any, dict[str, float]] = {}
        for obs in self.observations:
            seen.setdefault(obs.key, dict(obs.coordinate))
        return list(seen.values())

    # -- evaluation --------------------------------------------------------------------------
    def discrepancy(self, solution: Solution) -> tuple[NDArray[np.float64], list[float]]:
        """Residual vector over all observations (Paper A eq. 19) and D per observation."""
        res, dist = [], []
        for obs in self.observations:
            simulated = solution.interface(obs.coordinate)
            r = np.asarray(self.measure.residuals(simulated, obs), dtype=float).ravel()
            res.append(r)
            dist.append(float(self.measure.distance(simulated, obs)))
        return np.concatenate(res), dist

    def evaluate(
        self,
        x: Mapping[str, float],
        workdir: str | Path | None = None,
        index: int = 0,
        keep_solution: bool = True,
    ) -> Evaluation:
        """Run the forward model at ``x`` (full input dict) and compare with the observations.

        Never raises for a failed run: the outcome is in ``Evaluation.status``.
        """
        x = {k: float(v) for k, v in x.items()}
        full = {**self.fixed, **x}
        tmp = None
        if workdir is None:
            tmp = tempfile.mkdtemp(prefix="fbia-eval-")
            wd = Path(tmp)
        else:
            wd = Path(workdir)
            wd.mkdir(parents=True, exist_ok=True)
        ev = Evaluation(index=index, x=x, workdir=None if tmp else str(wd))
        t0 = time.perf_counter()
        try:
            coords = self.coordinates()
            solution = self.solve(full, coords, wd)
            missing = [c for c in coords if coordinate_key(c) not in solution.interfaces]
            if missing:
                raise _PluginBug(f"forward model returned no interface for coordinate(s) {missing}")
            ev.diagnostics = jsonable(dict(solution.diagnostics), lenient=True)  # always storable
            if keep_solution:  # kept when the measure fails too: the forward run succeeded
                ev.solution = solution
            ev.residuals, ev.distances = self.discrepancy(solution)
            if not (np.all(np.isfinite(ev.residuals)) and np.all(np.isfinite(ev.distances))):
                raise _PluginBug("the measure returned NaN or infinite values")
        except ForwardModelError as exc:
            ev.status, ev.message = "failed", str(exc) or type(exc).__name__
        except NonFiniteInterfaceError:  # from the model's interfaces: its solve diverged
            ev.status = "failed"
            ev.message = (
                "the forward model returned an interface with NaN or infinite coordinates "
                "(a diverged solve?)"
            )
        except MeasureError as exc:
            ev.status, ev.message = "measure_failed", str(exc)
        except Exception as exc:  # a plugin bug: recorded with its type, never silent
            ev.status, ev.message = "error", f"{type(exc).__name__}: {exc}"
        finally:
            ev.time = time.perf_counter() - t0
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
        return ev

    def solve(self, full: dict[str, float], coords: Sequence[Coordinate], wd: Path) -> Solution:
        """The forward run of :meth:`evaluate` (``fbia.iterators.tangents`` adds tangents)."""
        return self.model.solve(full, coords, wd)

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description of the problem (for results and provenance)."""
        return {
            "model": type(self.model).__name__,
            "model_options": plugin_options(self.model),
            "measure": type(self.measure).__name__,
            "measure_options": plugin_options(self.measure),
            "parameters": [p.describe() for p in self.parameters],
            "uncertain": [p.describe() for p in self.uncertain],
            "fixed": self.fixed,
            "noise_std": self.noise_std,
            "noise_prior": None if self.noise_prior is None else self.noise_prior.spec(),
            "observations": [
                {"label": o.label(), "coordinate": dict(o.coordinate), "noise_std": o.noise_std}
                for o in self.observations
            ],
        }


class _PluginBug(Exception):
    pass


def jsonable(value: Any, lenient: bool = False) -> Any:
    """``value`` in plain JSON types: numpy scalars and arrays, paths, dataclasses and sets
    converted; NaN and infinities as the strings ``"nan"``, ``"inf"``, ``"-inf"``.  Any other
    object is left as it is (JSON then refuses it), or with ``lenient`` written as its
    ``repr``: whatever a plugin puts in ``diagnostics`` can be stored."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, lenient) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v, lenient) for v in value]
    if isinstance(value, (set, frozenset)):
        return sorted((jsonable(v, lenient) for v in value), key=repr)
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), lenient)
    if isinstance(value, np.generic):
        return jsonable(value.item(), lenient)
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, Path):
        return str(value)
    if is_dataclass(value) and not isinstance(value, type):
        return jsonable(asdict(value), lenient)
    return repr(value) if lenient else value


class PosteriorEstimate(Protocol):
    """The point estimates of a posterior that another iterator may start from (Levenberg-
    Marquardt's ``x0`` from a Bayesian result: :mod:`fbia.iterators.lm.handoff`): the inputs'
    ``names`` (the first ``n_x`` are the calibration parameters, the rest uncertain inputs)
    and the posterior's ``map`` and ``mean`` of those ``n_x``."""

    @property
    def names(self) -> Sequence[str]: ...
    @property
    def n_x(self) -> int: ...
    @property
    def map(self) -> NDArray[np.float64]: ...
    @property
    def mean(self) -> NDArray[np.float64]: ...


@dataclass
class Result:
    """What an iterator returns: why it stopped, what it found, and every evaluation.

    Attributes
    ----------
    status
        A short tag (``"converged_gradient"``, ``"iteration_limit"``, ``"all_failed"``, ...).
    success
        Whether the iterator reached what it set out to do.
    message
        Why it stopped, in words a user understands.
    x
        The point estimate (LM optimum, MAP, ...) by name, or None.
    nfev, n_failed
        Forward evaluations made, and how many of them failed.
    history
        One dict per iteration (iterator-specific keys).
    evaluations
        Every evaluation record, in order.
    info
        Iterator-specific results (covariance, particles, ...).
    provenance
        fbia and plugin versions, seed, host, times (filled by the study runner).
    """

    status: str
    success: bool
    message: str
    x: dict[str, float] | None = None
    nfev: int = 0
    n_failed: int = 0
    iterator: str = ""
    history: list[dict[str, Any]] = field(default_factory=list)
    evaluations: list[Evaluation] = field(default_factory=list, repr=False)
    info: dict[str, Any] = field(default_factory=dict, repr=False)
    provenance: dict[str, Any] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict[str, Any]:
        plain = ("status", "success", "message", "x", "nfev", "n_failed", "iterator")
        out = {k: getattr(self, k) for k in plain}
        out.update({k: jsonable(getattr(self, k)) for k in ("history", "info", "provenance")})
        return {**out, "evaluations": [e.to_dict() for e in self.evaluations]}

    def posterior_estimate(self) -> PosteriorEstimate | None:
        """The posterior's point estimates, for a result that has a posterior (a Bayesian
        iterator's result overrides this); None here."""
        return None

    def save(self, path: str | Path) -> Path:
        """Write the result as JSON."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False, default=str))
        return path

    def quantities(self) -> dict[str, float]:
        """The numbers a study may compare with a paper (``[paper]``, :mod:`fbia.studies.paper`):
        ``x.<name>`` per parameter of the point estimate, ``converged`` (1 if ``success``,
        else 0), ``nfev`` and ``n_failed``; iterators' results add their own."""
        out = {f"x.{k}": float(v) for k, v in (self.x or {}).items()}
        out.update(converged=float(self.success), nfev=float(self.nfev))
        out["n_failed"] = float(self.n_failed)
        return out

    def undetermined(self) -> dict[str, str]:
        """Names of :meth:`quantities` whose value the result's own diagnostics say it does
        not determine, each with why (e.g. a histogram MAP decided by Monte Carlo noise); a
        paper comparison judges them "no" with that reason. None here; iterators' results
        add theirs."""
        return {}

    def summary(self) -> str:
        lines = [f"{self.iterator or 'result'}: {self.status} - {self.message}"]
        if self.x:
            lines.append("  " + ", ".join(f"{k} = {v:.6g}" for k, v in self.x.items()))
        lines.append(f"  {self.nfev} forward evaluations, {self.n_failed} failed")
        return "\n".join(lines)

    def units(self) -> dict[str, str]:
        """The inputs' units where the result knows them (from the problem ``fbia run``
        records in ``provenance``; ``gp_smc`` keeps its own)."""
        problem = self.provenance.get("problem") or {}
        specs = [*(problem.get("parameters") or []), *(problem.get("uncertain") or [])]
        return {str(s["name"]): str(s["unit"]) for s in specs if s.get("unit")}

    def to_records(self) -> list[dict[str, Any]]:
        """The result's main table as plain rows (dicts with the same keys), which
        :meth:`to_dataframe` wraps: here ``parameter`` and ``value`` of ``x``; iterators'
        results give their own (one row per start, per input of a posterior, ...)."""
        return [{"parameter": k, "value": float(v)} for k, v in (self.x or {}).items()]

    def to_dataframe(self) -> Any:
        """:meth:`to_records` as a ``pandas.DataFrame`` (pandas: the ``tables`` extra)."""
        try:
            import pandas
        except ImportError:
            raise ImportError(
                "to_dataframe needs pandas, which is not installed: pip install 'fbia[tables]'"
            ) from None
        return pandas.DataFrame(self.to_records())

    def _repr_html_(self) -> str:
        """The result in a notebook: the status, marked when it is not a success, and the
        message first, then the main quantities (:meth:`_html_body`) and the forward runs;
        every text escaped, no external CSS or JavaScript."""
        status = html.escape(f"{self.iterator or 'result'}: {self.status}")
        message = html.escape(self.message)
        first = (
            f"<p><b>{status}</b> &mdash; {message}</p>"
            if self.success
            else f'<p style="color:#b00020"><b>&#9888; {status}</b> (not a success) &mdash; '
            f"{message}</p>"
        )
        runs = f"<p>{self.nfev} forward runs, {self.n_failed} failed</p>"
        return f'<div class="fbia-result">{first}{self._html_body()}{runs}</div>'

    def _html_body(self) -> str:
        """The main quantities as HTML, for :meth:`_repr_html_`: here ``x`` as a table."""
        units, head = self.units(), ["parameter", "value", "unit"]
        rows = [[k, v, units.get(k, "")] for k, v in (self.x or {}).items()]
        if not units:  # a unit column only where the result knows units
            head, rows = head[:-1], [row[:-1] for row in rows]
        return html_table(head, rows) if rows else ""


class IteratorMembers(Configurable, InverseIterator):
    """The members an iterator may declare, with their defaults: the base of
    :class:`fbia.IteratorBase`, which adds ``run``.  Derive an iterator from
    :class:`fbia.IteratorBase`; the registry checks for this class, since it sits below
    :mod:`fbia.core.iteration` (``IteratorBase.run`` names its result through the registry),
    and it lives beside :class:`Result`, ``result_type``'s default."""

    result_type: ClassVar[type[Result]] = Result
    """The :class:`Result` dataclass its ``steps`` return, which :func:`fbia.load_result`
    reads a ``result.json`` of this iterator back as."""

    def write_files(self, result: Any, folder: Path) -> list[Path]:
        """Files beside ``result.json`` for other tools (``fbia run`` calls it); returns their
        paths.  The base: none."""
        return []

    def write_plots(self, result: Any, problem: Any, folder: Path) -> list[Path]:
        """Its figures of ``result`` (``fbia.plot`` and ``fbia run`` call it); returns their
        paths.  The base: none."""
        return []

    @property
    @final
    def seed(self) -> int | None:
        """The seed of its random numbers, which ``fbia run`` draws from the study's seed and
        records in the result's provenance: its option ``seed`` where its ``Options`` declare
        one (an integer, or None: unseeded), else None (it draws none)."""
        seed = dict(self.options).get("seed")
        return seed if isinstance(seed, int) else None


def html_table(head: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """``rows`` under ``head`` as a self-contained HTML table (for a result's notebook view):
    every cell escaped, floats as ``%.6g``, None and NaN as a dash."""

    def cell(tag: str, value: Any) -> str:
        if value is None or (isinstance(value, float | np.floating) and math.isnan(value)):
            text = "-"
        else:
            text = f"{value:.6g}" if isinstance(value, float | np.floating) else str(value)
        return f'<{tag} style="text-align:left;padding:1px 8px">{html.escape(text)}</{tag}>'

    lines = [[cell("th", h) for h in head], *([cell("td", v) for v in row] for row in rows)]
    body = "".join(f"<tr>{''.join(line)}</tr>" for line in lines)
    return f'<table style="border-collapse:collapse">{body}</table>'
