"""fbia.testing: conformance checks and pytest fixtures for fbia plugins.

Its fixtures (:mod:`fbia.pytest_plugin`, registered as the pytest plugin ``fbia``) are
available in every test session of an environment where fbia is installed.  A third-party
plugin package proves that its classes behave like fbia's own with a few lines::

    from fbia.testing import check_forward_model, check_measure, check_options


    def test_my_solver_conforms(tmp_path):
        model = MySolverForwardModel(timeout=60.0)
        check_options(MySolverForwardModel)
        check_forward_model(model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path,
                            failing_parameters={"E": 1.0, "nu": 0.3})

    def test_my_measure_conforms():
        check_measure(MyMeasure(), dims=(2,))

Every check raises :class:`ConformanceError` (an ``AssertionError``) with a message that names
the plugin class and the rule it broke; each returns what it computed so that a test can go on
asserting.  The helpers :func:`straight_line_2d`, :func:`mound_2d`, :func:`circle_2d`,
:func:`square_3d` and :func:`sphere_3d` build sample interfaces (lengths in mm) with the
orientation fbia uses: normals point from the solid into the fluid.

Iterators are checked on a problem, e.g. ``check_iterator(lambda: MyIterator(seed=0),
tiny_problem())``.  Fixtures: ``fbia_registry`` (the default registry), ``fbia_installer``
(installs a plugin distribution for one test) and ``fbia_measure_cases``.

Plugin classes may offer optional class attributes that the conformance tests of fbia (and
:func:`check_registered`) use:

``example_parameters()``
    Forward models: ``(parameters, coordinates)`` of a cheap, successful run.  Every registered
    forward model must provide it.
``example_options()``
    Any kind: the options (a dict) of a cheap instance for conformance runs, e.g. a coarse
    mesh, a measure length scale that suits the sample interfaces of :func:`measure_cases`,
    or a small number of particles.
``dims``, ``mesh_dependent``
    Measures: the spatial dimensions supported (default ``(2, 3)``), and whether the residuals
    belong to the simulated mesh (see :func:`check_measure`; default False).

pytest loads only the fixtures of :mod:`fbia.pytest_plugin` at start-up; this module (numpy,
trimesh, the fbia sub-modules) is imported when a test uses it.
"""

from __future__ import annotations

import copy
import importlib
import inspect
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
from numpy.typing import NDArray

from .core.errors import ConfigError, ForwardModelError
from .core.evaluator import SerialEvaluator
from .core.interface import Interface
from .core.observation import Observation, Solution, coordinate_key
from .core.options import Configurable, PluginOptions
from .core.parameters import Parameter
from .core.problem import Evaluation, InverseProblem, Result
from .core.registry import PluginEntry, Registry, default_registry, forward_model
from .core.registry import measure as make_measure
from .core.synthetic import synthetic_observations

__all__ = [
    "ConformanceError",
    "CountingEvaluator",
    "MeasureCase",
    "PluginInstaller",
    "check_forward_model",
    "check_iterator",
    "check_measure",
    "check_options",
    "check_registered",
    "circle_2d",
    "example_options",
    "example_run",
    "failing_run",
    "measure_cases",
    "mound_2d",
    "sphere_3d",
    "square_3d",
    "straight_line_2d",
    "tiny_problem",
    "write_dist_info",
]


class ConformanceError(AssertionError):
    """A plugin breaks a rule of its protocol; the message names the plugin and the rule."""


def _fail(obj: Any, rule: str) -> ConformanceError:
    cls = obj if isinstance(obj, type) else type(obj)
    return ConformanceError(f"{cls.__module__}.{cls.__qualname__}: {rule}")


# ------------------------------------------------------------------------------------------
# Sample interfaces (mm)
# ------------------------------------------------------------------------------------------
def straight_line_2d(
    length: float = 1.0, n: int = 32, height: float = 0.0, slope: float = 0.0
) -> Interface:
    """The flat floor ``y = height + slope * x``, ``0 <= x <= length``, in ``n`` segments.

    Ordered upstream to downstream (solid below), so its normals point up into the fluid.
    """

    x = np.linspace(0.0, length, n + 1)
    return Interface.polyline(np.c_[x, height + slope * x])


def mound_2d(length: float = 1.0, height: float = 0.2, n: int = 64) -> Interface:
    """A smooth biofilm mound ``y = height * sin(pi x / length)**2`` on the channel floor.

    Ordered upstream to downstream (solid below), in ``n`` segments of equal x-extent.
    """

    x = np.linspace(0.0, length, n + 1)
    return Interface.polyline(np.c_[x, height * np.sin(np.pi * x / length) ** 2])


def circle_2d(radius: float = 0.3, n: int = 64, centre: Sequence[float] = (0.0, 0.0)) -> Interface:
    """A closed polygon with ``n`` vertices on a circle around a solid disc.

    Walked clockwise, so the solid lies on the right and the normals point outwards.
    """

    phi = -np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)  # clockwise
    pts = np.asarray(centre, dtype=float) + radius * np.c_[np.cos(phi), np.sin(phi)]
    return Interface.polyline(pts, closed=True)


def square_3d(
    size: float = 1.0, n: int = 8, height: float = 0.0, slope: Sequence[float] = (0.0, 0.0)
) -> Interface:
    """The plane ``z = height + slope[0] x + slope[1] y`` over ``[0, size]^2``.

    ``2 n^2`` triangles, ordered so that the normals point up (+z side is fluid).
    """

    t = np.linspace(0.0, size, n + 1)
    x, y = (a.ravel() for a in np.meshgrid(t, t, indexing="xy"))
    z = height + slope[0] * x + slope[1] * y
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = np.vstack([np.c_[a, b, c], np.c_[a, c, d]])
    return Interface.surface(np.c_[x, y, z], tris)


def sphere_3d(
    radius: float = 0.3, subdivisions: int = 2, centre: Sequence[float] = (0.0, 0.0, 0.0)
) -> Interface:
    """An icosphere (``trimesh.creation.icosphere``) around a solid ball; normals point out.

    ``subdivisions=2`` gives 320 triangles, each further level four times as many.
    """

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return Interface.surface(np.asarray(mesh.vertices) + np.asarray(centre), mesh.faces)


# ------------------------------------------------------------------------------------------
# Options
# ------------------------------------------------------------------------------------------
def check_options(cls: type) -> list[str]:
    """Prove that ``cls`` has an ``Options`` schema a study file can be checked against.

    Checks that ``cls.Options`` is a :class:`fbia.PluginOptions`; that every option has a
    description (which states its unit); that an unknown key is rejected with a one-line
    :class:`fbia.ConfigError` naming the key and all valid keys, by ``Options.parse`` and,
    for a :class:`fbia.Configurable`, by the constructor ``cls(**options)``.

    Returns the option names.
    """

    options = getattr(cls, "Options", None)
    if not (isinstance(options, type) and issubclass(options, PluginOptions)):
        raise _fail(cls, "has no Options schema (a subclass of fbia.PluginOptions)")
    names = sorted(options.model_fields)
    undocumented = [n for n, f in options.model_fields.items() if not (f.description or "").strip()]
    if undocumented:
        raise _fail(
            cls,
            f"option(s) {', '.join(undocumented)} have no description; document each option "
            "and its unit with pydantic.Field(description=...)",
        )
    bad_key = "no_such_option_xyz"
    attempts: list[tuple[str, Callable[[], Any]]] = [
        ("Options.parse", lambda: options.parse({bad_key: 1.0}, where="conformance")),
    ]
    if issubclass(cls, Configurable):  # the Configurable convention: Cls(**options)
        attempts.append((f"{cls.__name__}(**options)", lambda: cls(**{bad_key: 1.0})))
    for label, attempt in attempts:
        try:
            attempt()
        except ConfigError as exc:
            message = str(exc)
            if "\n" in message:
                raise _fail(
                    cls, f"{label}: the error for an unknown key spans lines: {message!r}"
                ) from None
            missing = [n for n in [bad_key, *names] if n not in message]
            if missing:
                raise _fail(
                    cls,
                    f"{label}: the error for an unknown key does not name "
                    f"{', '.join(missing)}: {message!r}",
                ) from None
        except Exception as exc:
            raise _fail(
                cls,
                f"{label}: an unknown key raised {type(exc).__name__}: {exc} "
                "instead of fbia.ConfigError",
            ) from exc
        else:
            raise _fail(cls, f"{label} accepts the unknown key {bad_key!r}")
    return names


def example_options(cls: type) -> dict[str, Any]:
    """The options of a cheap instance of ``cls``: ``cls.example_options()`` or ``{}``."""
    hook = getattr(cls, "example_options", None)
    if hook is None:
        return {}
    opts = hook()
    if not isinstance(opts, Mapping):
        raise _fail(cls, f"example_options() must return a dict, got {type(opts).__name__}")
    return dict(opts)


# ------------------------------------------------------------------------------------------
# Forward models
# ------------------------------------------------------------------------------------------
def check_forward_model(
    model: Any,
    parameters: Mapping[str, float],
    coordinates: Sequence[Mapping[str, float]],
    tmp_path: str | Path,
    failing_parameters: Mapping[str, float] | None = None,
    rtol: float = 1e-8,
) -> Solution:
    """Prove that ``model`` honours the forward-model protocol at ``parameters``.

    Checks that

    * ``parameter_names()`` is a sequence of distinct strings containing every key of
      ``parameters``;
    * ``solve(parameters, coordinates, workdir)`` returns an :class:`fbia.Solution` with an
      :class:`fbia.Interface` for every requested coordinate, all of one dimension, with finite
      vertices and unit normals;
    * ``solve`` leaves its inputs and the current directory unchanged;
    * the model is deterministic and independent of the order of the coordinates: a second run
      in a fresh working folder, with a copy of the parameters and the coordinates reversed,
      gives the same interfaces (same connectivity, vertices equal to ``rtol`` times the
      interface's size);
    * with ``failing_parameters`` (a run known to fail), ``solve`` raises
      :class:`fbia.ForwardModelError` with a message, and nothing else.

    Returns the first :class:`fbia.Solution`.
    """

    tmp_path = Path(tmp_path)
    names = model.parameter_names()
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise _fail(model, f"parameter_names() must be a sequence of str, got {names!r}")
    if len(set(names)) != len(list(names)):
        raise _fail(model, f"parameter_names() repeats a name: {list(names)}")
    unknown = [k for k in parameters if k not in names]
    if unknown:
        raise _fail(
            model,
            f"the test parameters {unknown} are not in parameter_names() = {list(names)}",
        )
    if not coordinates:
        raise ValueError("check_forward_model needs at least one coordinate")

    def solve(params: Mapping[str, float], coords: Sequence[Mapping[str, float]], run: str) -> Any:
        tmp_path.mkdir(parents=True, exist_ok=True)
        workdir = Path(tempfile.mkdtemp(prefix=f"{run}_", dir=tmp_path))  # fresh and empty
        params_before, coords_before = copy.deepcopy(dict(params)), copy.deepcopy(list(coords))
        cwd = os.getcwd()
        try:
            return model.solve(params, coords, workdir)
        finally:
            if os.getcwd() != cwd:
                os.chdir(cwd)
                raise _fail(model, f"solve() changed the current directory (run {run!r})")
            if dict(params) != params_before or list(coords) != coords_before:
                raise _fail(model, "solve() modified the parameters or coordinates it was given")

    try:
        first = solve(parameters, coordinates, "run_a")
    except ConformanceError:
        raise
    except ForwardModelError as exc:
        raise _fail(model, f"the example run at {dict(parameters)} failed: {exc}") from exc
    except Exception as exc:
        raise _fail(
            model,
            f"the run at {dict(parameters)} raised {type(exc).__name__}: {exc} (a failed run "
            "must raise fbia.ForwardModelError)",
        ) from exc
    if not isinstance(first, Solution):
        raise _fail(model, f"solve() must return fbia.Solution, got {type(first).__name__}")
    dims = set()
    for c in coordinates:
        key = coordinate_key(c)
        gamma = first.interfaces.get(key)
        if not isinstance(gamma, Interface):
            raise _fail(
                model,
                f"solve() returned {type(gamma).__name__} instead of an Interface for the "
                f"requested coordinate {dict(c)}",
            )
        if not (
            np.all(np.isfinite(gamma.normals))
            and np.allclose(np.linalg.norm(gamma.normals, axis=1), 1.0)
        ):
            raise _fail(model, f"the interface at {dict(c)} has non-finite or non-unit normals")
        dims.add(gamma.dim)
    if len(dims) != 1:
        raise _fail(model, f"solve() mixes interface dimensions {sorted(dims)}")
    if not isinstance(first.diagnostics, Mapping):
        raise _fail(model, "Solution.diagnostics must be a mapping")

    again = solve(copy.deepcopy(dict(parameters)), list(reversed(coordinates)), "run_b")
    for c in coordinates:
        a = first.interface(c)
        try:
            b = again.interface(c)
        except KeyError:
            raise _fail(
                model, f"with the coordinates reversed, no interface for {dict(c)}"
            ) from None
        if a.dim != b.dim or a.cells.shape != b.cells.shape or not np.array_equal(a.cells, b.cells):
            raise _fail(
                model,
                f"two runs with equal inputs give different meshes at {dict(c)} "
                f"({a!r} vs {b!r}); coordinates in reversed order in the second run",
            )
        lo, hi = a.bounds
        scale = float(np.max(hi - lo)) or 1.0
        dev = float(np.max(np.abs(a.vertices - b.vertices)))
        if dev > rtol * scale:
            raise _fail(
                model,
                f"two runs with equal inputs differ at {dict(c)} by {dev:.3g} mm "
                f"(> {rtol:g} x size {scale:.3g} mm); coordinates in reversed order in the "
                "second run",
            )

    if failing_parameters is not None:
        try:
            solve(failing_parameters, coordinates, "run_fail")
        except ForwardModelError as exc:
            if not str(exc).strip():
                raise _fail(model, "ForwardModelError without a message") from exc
        except ConformanceError:
            raise
        except Exception as exc:
            raise _fail(
                model,
                f"a failing run raised {type(exc).__name__}: {exc} instead of "
                "fbia.ForwardModelError",
            ) from exc
        else:
            raise _fail(
                model, f"the run at {dict(failing_parameters)} was expected to fail but did not"
            )
    return first


def example_run(cls: type) -> tuple[dict[str, float], list[dict[str, float]]]:
    """``cls.example_parameters()`` checked: (parameters, coordinates) of a cheap run."""
    hook = getattr(cls, "example_parameters", None)
    if hook is None:
        raise _fail(
            cls,
            "provides no example_parameters(); every forward model needs a classmethod "
            "example_parameters() -> (parameters, coordinates) of a cheap successful run",
        )
    out = hook()
    try:
        params, coords = out
        params = {str(k): float(v) for k, v in dict(params).items()}
        coords = [{str(k): float(v) for k, v in dict(c).items()} for c in coords]
    except (TypeError, ValueError) as exc:
        raise _fail(
            cls,
            f"example_parameters() must return (dict of floats, list of coordinate dicts): {exc}",
        ) from exc
    if not coords:
        raise _fail(cls, "example_parameters() returns no coordinates")
    return params, coords


# ------------------------------------------------------------------------------------------
# Measures
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MeasureCase:
    """An observation and two simulated interfaces at a small and a larger deviation.

    The observation holds both the observed interface and measurement points on it (with the
    observed vertex normals as directions), so that point-, projection- and surface-based
    measures all find what they need.  ``simulated`` and ``farther`` are meshed differently
    from the observed interface and from each other.
    """

    name: str
    observation: Observation
    simulated: Interface
    farther: Interface

    @property
    def dim(self) -> int:
        return self.observation.dim


def _case(name: str, observed: Interface, simulated: Interface, farther: Interface) -> MeasureCase:

    n = len(observed.vertices)
    interior = np.arange(n)
    if observed.dim == 2 and len(observed.curves()) == 1 and observed.curves()[0].shape[0] == n:
        interior = interior[1:-1]  # open curve: no rays from its end points
    elif observed.dim == 3:
        lo, hi = observed.bounds
        margin = 0.05 * (hi - lo)
        inside = np.all((observed.vertices >= lo + margin) | (hi - lo < 1e-12), axis=1) & np.all(
            (observed.vertices <= hi - margin) | (hi - lo < 1e-12), axis=1
        )
        interior = interior[inside]
    pick = interior[:: max(1, len(interior) // 12)]
    obs = Observation(
        interface=observed,
        coordinate={"inflow_rate": 100.0},
        points=observed.vertices[pick],
        directions=observed.vertex_normals[pick],
        name=name,
    )
    return MeasureCase(name, obs, simulated, farther)


def measure_cases(dims: Iterable[int] = (2, 3)) -> list[MeasureCase]:
    """The sample cases :func:`check_measure` uses: straight and curved, 2-D and 3-D.

    Sizes in mm: a 1 mm floor and a 0.2 mm high mound (elements about 0.015 mm), a circle
    and a sphere of radius 0.3 mm; deviations of 0.01 to 0.06 mm.  A measure with a length
    scale (e.g. an RKHS kernel width) should be given one of about 0.05 mm.
    """
    dims = set(dims)
    cases = []
    if 2 in dims:
        cases += [
            _case(
                "line_2d",
                straight_line_2d(n=48),
                straight_line_2d(n=37, height=0.02, slope=0.02),
                straight_line_2d(n=41, height=0.04, slope=0.04),
            ),
            _case(
                "mound_2d",
                mound_2d(height=0.2, n=64),
                mound_2d(height=0.23, n=53),
                mound_2d(height=0.28, n=71),
            ),
            _case(
                "circle_2d",
                circle_2d(0.3, n=96),
                circle_2d(0.32, n=80, centre=(0.01, 0.0)),
                circle_2d(0.36, n=88, centre=(0.02, 0.0)),
            ),
        ]
    if 3 in dims:
        cases += [
            _case(
                "square_3d",
                square_3d(0.4, n=12),
                square_3d(0.4, n=11, height=0.02, slope=(0.02, 0.01)),
                square_3d(0.4, n=13, height=0.04, slope=(0.04, 0.02)),
            ),
            _case(
                "sphere_3d",
                sphere_3d(0.2, 2),
                sphere_3d(0.22, 2, centre=(0.01, 0.0, 0.0)),
                sphere_3d(0.25, 1, centre=(0.02, 0.0, 0.0)).refined(1),
            ),
        ]
    if not cases:
        raise ValueError(f"no measure cases for dims {sorted(dims)}; valid: 2, 3")
    return cases


def _measure_values(
    measure: Any, gamma: Interface, obs: Observation, where: str
) -> tuple[NDArray[np.float64], float]:
    """Residuals and distance of ``gamma``, checked for type, shape and finiteness."""

    try:
        r = measure.residuals(gamma, obs)
        d = measure.distance(gamma, obs)
    except Exception as exc:
        raise _fail(measure, f"{where} interface: {type(exc).__name__}: {exc}") from exc
    if not isinstance(r, np.ndarray) or r.ndim != 1:
        raise _fail(
            measure,
            f"{where}: residuals must be a 1-D numpy array, got "
            f"{type(r).__name__} of shape {np.shape(r)}",
        )
    if not np.all(np.isfinite(r)):
        raise _fail(measure, f"{where}: residuals are not all finite")
    if not isinstance(d, (float, np.floating)) or not math.isfinite(d) or d < 0:
        raise _fail(measure, f"{where}: distance must be a finite float >= 0, got {d!r}")
    return r.astype(float, copy=False), float(d)


def check_measure(
    measure: Any,
    dims: Iterable[int] = (2, 3),
    cases: Sequence[MeasureCase] | None = None,
    rtol: float = 0.03,
    residual_rtol: float = 0.15,
    zero_tol: float = 1e-5,
    mesh_dependent: bool = False,
) -> dict[str, dict[str, float]]:
    """Prove that ``measure`` behaves like a distance between interfaces, in 2-D and 3-D.

    For every case of :func:`measure_cases` (or ``cases``) it checks that

    * the residuals are a finite 1-D array and the distance a finite float >= 0;
    * the observed interface is at distance zero from itself (``distance`` and the residual
      norm below ``zero_tol`` times those of the simulated interface);
    * a different interface is at a positive distance, and a larger deviation (``farther``)
      at a larger one;
    * the residual vector has the same length for every simulated interface (the
      Levenberg-Marquardt Jacobian needs it), whatever its mesh;
    * re-meshing does not matter: the simulated interface refined once
      (:meth:`fbia.Interface.refined`, the same polygon or polyhedron) gives the distance and
      the residual norm to ``rtol`` (relative), and a residual vector that differs by at most
      ``residual_rtol`` times its norm (kernel measures sample fields whose quadrature
      depends on the mesh, hence the looser bound);
    * repeated calls give identical values.

    A measure whose residuals belong to the simulated mesh (one per simulated vertex, like the
    closest-point-projection distances of Paper B eq. 7) is declared with
    ``mesh_dependent=True``: the residual-length and re-meshing checks are then left out and
    all others kept.

    Returns ``{case: {"identical": D0, "simulated": D1, "refined": D1r, "farther": D2}}``.
    """

    cases = measure_cases(dims) if cases is None else list(cases)
    out: dict[str, dict[str, float]] = {}
    for case in cases:
        obs = case.observation
        where = f"case {case.name!r}"

        r0, d0 = _measure_values(measure, obs.interface, obs, f"{where}, identical")  # type: ignore[arg-type]
        r1, d1 = _measure_values(measure, case.simulated, obs, f"{where}, simulated")
        r1b, d1b = _measure_values(measure, case.simulated, obs, f"{where}, simulated, repeated")
        rr, dr = _measure_values(
            measure, case.simulated.refined(1), obs, f"{where}, simulated, refined"
        )
        r2, d2 = _measure_values(measure, case.farther, obs, f"{where}, farther")
        if d1 <= 0.0:
            raise _fail(measure, f"{where}: distance 0 between different interfaces")
        if not (d0 <= zero_tol * d1 and np.linalg.norm(r0) <= zero_tol * np.linalg.norm(r1)):
            raise _fail(
                measure,
                f"{where}: an interface is not at distance zero from itself: D = {d0:.3g}, "
                f"|r| = {np.linalg.norm(r0):.3g} (vs D = {d1:.3g} for a different one)",
            )
        if not d2 > d1:
            raise _fail(
                measure,
                f"{where}: a larger deviation gives no larger distance ({d2:.6g} <= {d1:.6g})",
            )
        if d1b != d1 or not np.array_equal(r1b, r1):
            raise _fail(measure, f"{where}: repeated calls give different values")
        if not mesh_dependent:
            shapes = {r0.shape, r1.shape, rr.shape, r2.shape}
            if len(shapes) != 1:
                raise _fail(
                    measure,
                    f"{where}: the residual length depends on the simulated mesh: "
                    f"{r0.shape[0]} (identical), {r1.shape[0]} (simulated), {rr.shape[0]} "
                    f"(refined), {r2.shape[0]} (farther)",
                )
            if abs(dr - d1) > rtol * d1:
                raise _fail(
                    measure,
                    f"{where}: re-meshing the same geometry changes the distance from {d1:.6g} to "
                    f"{dr:.6g} (relative {abs(dr - d1) / d1:.2g} > {rtol:g})",
                )
            n1, nr = float(np.linalg.norm(r1)), float(np.linalg.norm(rr))
            if abs(nr - n1) > rtol * n1:
                raise _fail(
                    measure,
                    f"{where}: re-meshing the same geometry changes the residual norm from "
                    f"{n1:.6g} to {nr:.6g} (relative {abs(nr - n1) / n1:.2g} > {rtol:g})",
                )
            change = float(np.linalg.norm(rr - r1))
            if change > residual_rtol * n1:
                raise _fail(
                    measure,
                    f"{where}: re-meshing the same geometry changes the residual vector by "
                    f"{change:.3g} (> {residual_rtol:g} x its norm {n1:.3g})",
                )
        out[case.name] = {"identical": d0, "simulated": d1, "refined": dr, "farther": d2}
    return out


# ------------------------------------------------------------------------------------------
# Iterators
# ------------------------------------------------------------------------------------------
class CountingEvaluator:
    """Wraps an evaluator and counts the points it evaluates and the runs that failed."""

    def __init__(self, inner: Any = None) -> None:

        self.inner = SerialEvaluator() if inner is None else inner
        self.points = 0
        self.failed = 0
        self.batches = 0

    def evaluate(
        self, problem: InverseProblem, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]:
        out = self.inner.evaluate(problem, points)
        self.batches += 1
        self.points += len(points)
        self.failed += sum(not e.ok for e in out)
        return list(out)

    def close(self) -> None:
        close = getattr(self.inner, "close", None)
        if close is not None:
            close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def _global_rng_state() -> tuple[Any, ...]:
    """numpy's legacy global random state (to prove that a plugin leaves it alone)."""

    state = np.random.get_state(legacy=False)  # noqa: NPY002
    inner = state["state"]
    return (inner["key"].tobytes(), inner["pos"], state["has_gauss"], state["gauss"])


def check_iterator(
    iterator_factory: Callable[[], Any],
    problem: InverseProblem,
    tmp_path: str | Path | None = None,
) -> Result:
    """Prove that an iterator runs a problem to a :class:`fbia.Result` it can account for.

    ``iterator_factory()`` must build a fresh iterator with fixed options (and a fixed seed if
    it draws random numbers).  Checks that

    * ``steps(problem, evaluator)`` is a generator that yields at least once and returns a
      :class:`fbia.Result` (so a caller can watch, checkpoint and stop);
    * the result says why it stopped: ``status`` and ``message`` are non-empty strings,
      ``success`` is a bool, ``iterator`` names the iterator;
    * ``nfev`` and ``n_failed`` equal the points the evaluator was given and the runs that
      failed (failed runs are outcomes, not exceptions);
    * ``x`` is None or a finite value for each parameter of the problem within its bounds;
    * ``to_dict()`` is plain JSON (no NaN), and :meth:`fbia.Result.save` writes the same;
    * ``run()`` reproduces the result (same status, nfev and x), and neither run touches
      numpy's global random state.

    Returns the result of the ``steps`` run.
    """

    global_state = _global_rng_state()
    it = iterator_factory()
    ev = CountingEvaluator()
    try:
        gen = it.steps(problem, ev)
        if not inspect.isgenerator(gen):
            raise _fail(it, f"steps() must be a generator, got {type(gen).__name__}")
        yields = 0
        while True:
            try:
                next(gen)
            except StopIteration as stop:
                result = stop.value
                break
            yields += 1
        if yields == 0:
            raise _fail(it, "steps() returned without yielding a state")
    finally:
        ev.close()
    if not isinstance(result, Result):
        raise _fail(it, f"steps() must return fbia.Result, got {type(result).__name__}")
    for attr in ("status", "message", "iterator"):
        value = getattr(result, attr)
        if not (isinstance(value, str) and value.strip()):
            raise _fail(it, f"Result.{attr} must be a non-empty string, got {value!r}")
    if not isinstance(result.success, (bool, np.bool_)):
        raise _fail(it, f"Result.success must be a bool, got {result.success!r}")
    if result.nfev != ev.points:
        raise _fail(
            it, f"Result.nfev = {result.nfev} but the evaluator was given {ev.points} points"
        )
    if result.n_failed != ev.failed:
        raise _fail(it, f"Result.n_failed = {result.n_failed} but {ev.failed} runs failed")
    if result.x is not None:
        shown = {k: float(v) for k, v in result.x.items()}
        if set(result.x) != set(problem.names):
            raise _fail(
                it, f"Result.x has keys {sorted(result.x)}, the problem has {problem.names}"
            )
        x = problem.vector(result.x)
        span = problem.upper - problem.lower
        if not np.all(np.isfinite(x)):
            raise _fail(it, f"Result.x is not finite: {shown}")
        if np.any(x < problem.lower - 1e-9 * span) or np.any(x > problem.upper + 1e-9 * span):
            raise _fail(it, f"Result.x = {shown} lies outside the bounds")
    try:
        as_dict = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise _fail(it, f"Result.to_dict() is not plain JSON: {exc}") from exc
    with tempfile.TemporaryDirectory(dir=tmp_path) as tmp:
        saved = json.loads(result.save(Path(tmp) / "result.json").read_text())
    if saved != as_dict:
        raise _fail(it, "Result.save() writes something other than Result.to_dict()")

    ev2 = CountingEvaluator()
    try:
        rerun = iterator_factory().run(problem, ev2)
    finally:
        ev2.close()
    if not isinstance(rerun, Result):
        raise _fail(it, f"run() must return fbia.Result, got {type(rerun).__name__}")
    same_x = (rerun.x is None and result.x is None) or (
        rerun.x is not None
        and result.x is not None
        and set(rerun.x) == set(result.x)
        and all(math.isclose(rerun.x[k], result.x[k], rel_tol=1e-10) for k in result.x)
    )
    if rerun.status != result.status or rerun.nfev != result.nfev or not same_x:
        raise _fail(
            it,
            "two runs with equal options differ: "
            f"({result.status}, nfev {result.nfev}, x {result.x}) vs "
            f"({rerun.status}, nfev {rerun.nfev}, x {rerun.x}); fix the seed in the options",
        )
    if _global_rng_state() != global_state:
        raise _fail(it, "the run used numpy's global random state; take a Generator or a seed")
    return result


def tiny_problem(
    failure_region: Mapping[str, tuple[float, float]] | None = None,
    measure: str = "cpp",
    seed: int = 0,
) -> InverseProblem:
    """A two-parameter problem that any iterator solves in a blink (built-in plugins only).

    ``analytic_mound_2d`` (21 points) observed once at ``inflow_rate`` 100 mm^2/s from the
    ground truth E = 400 Pa, nu = 0.3 with 1e-3 mm of noise (``seed``), compared with the
    measure ``measure``; parameters ``E`` in [100, 800] Pa (initial 250) and ``nu`` in
    [-0.5, 0.45] (initial 0.1).  ``failure_region`` (e.g. ``{"E": (100.0, 150.0)}``) makes
    the runs there fail, as soft biofilms do in Paper B (Fig. 5).
    """

    truth_model = forward_model("analytic_mound_2d", n_points=21)
    obs = synthetic_observations(
        truth_model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], noise_std=1e-3, seed=seed
    )
    model = forward_model(
        "analytic_mound_2d",
        n_points=21,
        failure_region=None if failure_region is None else dict(failure_region),
    )
    return InverseProblem(
        model=model,
        measure=make_measure(measure),
        observations=obs,
        noise_std=1e-3,
        parameters=[
            Parameter("E", bounds=(100.0, 800.0), unit="Pa", initial=250.0),
            Parameter("nu", bounds=(-0.5, 0.45), initial=0.1),
        ],
    )


# ------------------------------------------------------------------------------------------
# Registered plugins
# ------------------------------------------------------------------------------------------
def failing_run(
    cls: type, parameters: Mapping[str, float]
) -> tuple[dict[str, Any], dict[str, float]] | None:
    """Options and parameters of a run that must fail, by the ``failure_region`` convention.

    A forward model whose ``Options`` have a ``failure_region`` ({parameter: [lo, hi]}: the
    run raises :class:`fbia.ForwardModelError` when every named parameter lies in its
    interval) can be made to fail on purpose.  Returns ``(options, failing_parameters)``: a
    region around the first of ``parameters`` moved by 10 %, which leaves ``parameters``
    themselves outside it; None if the model has no such option.
    """
    options = getattr(cls, "Options", None)
    if options is None or "failure_region" not in getattr(options, "model_fields", {}):
        return None
    if not parameters:
        raise _fail(cls, "example_parameters() gives no parameter to fail on")
    name, value = next(iter(parameters.items()))
    bad = value * 1.1 if value != 0.0 else 0.1
    half = 0.01 * abs(bad - value)
    return {"failure_region": {name: (bad - half, bad + half)}}, {**parameters, name: bad}


def check_registered(entry: PluginEntry, tmp_path: str | Path) -> Any:
    """Run the checks that fit a registry entry (``fbia.list_plugins()`` lists them).

    :func:`check_options` for every kind; for forward models :func:`check_forward_model` at
    ``example_parameters()``, including the failure path when the model has a
    ``failure_region`` option (:func:`failing_run`); for measures :func:`check_measure` in the
    dimensions of the class attribute ``dims`` (default 2 and 3), with the class attribute
    ``mesh_dependent`` (default False).  Instances are built from ``example_options()``.
    Iterators need a problem: use :func:`check_iterator` with :func:`tiny_problem`.  Returns
    what the kind's check returned (the iterator instance for iterators).
    """
    cls = entry.factory
    check_options(cls)
    opts = example_options(cls)
    if entry.kind == "forward_model":
        params, coords = example_run(cls)
        fail = failing_run(cls, params)
        if fail is None:
            model = cls(cls.Options.parse(opts))
            return check_forward_model(model, params, coords, tmp_path)
        model = cls(cls.Options.parse({**opts, **fail[0]}))
        return check_forward_model(model, params, coords, tmp_path, failing_parameters=fail[1])
    instance = cls(cls.Options.parse(opts))
    if entry.kind == "measure":
        return check_measure(
            instance,
            dims=getattr(cls, "dims", (2, 3)),
            mesh_dependent=bool(getattr(cls, "mesh_dependent", False)),
        )
    return instance


# ------------------------------------------------------------------------------------------
# Installing a plugin distribution for the duration of a test
# ------------------------------------------------------------------------------------------
def write_dist_info(
    site: str | Path,
    name: str,
    version: str,
    entry_points: Mapping[str, str],
    group: str = "fbia",
) -> Path:
    """Write ``<site>/<name>-<version>.dist-info`` as ``pip install`` would.

    ``METADATA`` carries Name and Version; ``entry_points.txt`` declares ``entry_points``
    (entry-point name -> module) under ``[group]``.  With ``site`` on ``sys.path``,
    ``importlib.metadata`` (and so the fbia registry) sees an installed distribution.
    """
    site = Path(site)
    dist = site / f"{name.replace('-', '_')}-{version}.dist-info"
    dist.mkdir(parents=True, exist_ok=False)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    lines = [f"[{group}]", *(f"{k} = {v}" for k, v in entry_points.items()), ""]
    (dist / "entry_points.txt").write_text("\n".join(lines))
    (dist / "RECORD").write_text("")
    return dist


@dataclass
class PluginInstaller:
    """Installs plugin distributions into a temporary site folder for one test.

    Made by the ``fbia_installer`` fixture, which undoes everything afterwards: ``sys.path``,
    the imported plugin modules and the cached default registry.
    """

    site: Path
    monkeypatch: pytest.MonkeyPatch
    roots: list[Path] = field(default_factory=list)

    def install(
        self,
        name: str,
        version: str,
        entry_points: Mapping[str, str],
        source: str | Path | None = None,
    ) -> Path:
        """Declare distribution ``name`` ``version`` with ``entry_points`` (group ``fbia``).

        ``source`` is a folder holding the plugin's modules; it goes on ``sys.path`` as an
        installed package's site folder would.  The default registry is reloaded on next use.
        """

        if not self.roots:
            self.monkeypatch.syspath_prepend(str(self.site))
            self.roots.append(self.site)
        dist = write_dist_info(self.site, name, version, entry_points)
        if source is not None:
            src = Path(source).resolve()
            self.monkeypatch.syspath_prepend(str(src))
            self.roots.append(src)
        importlib.invalidate_caches()
        default_registry.cache_clear()
        return dist

    def registry(self) -> Registry:
        """A fresh registry loaded from all entry points, including the installed ones."""

        return Registry.load()

    def cleanup(self) -> None:
        """Forget the modules imported from the installed folders and the cached registry."""
        if not self.roots:
            return

        roots = [str(r) for r in self.roots]
        for mod_name, module in list(sys.modules.items()):
            origin = getattr(module, "__file__", None) or ""
            if any(origin.startswith(r + os.sep) for r in roots):
                del sys.modules[mod_name]
        importlib.invalidate_caches()
        default_registry.cache_clear()
