"""The three extension points of fbia: their written contracts.

A forward model turns parameters into interfaces (:class:`ForwardModel`), a measure compares a
simulated interface with an observation (:class:`Discrepancy`), an iterator drives the inverse
analysis (:class:`InverseIterator`; the evaluator it receives is
:class:`fbia.core.iteration.Evaluator`).  Each contract lists every member in
the order the framework uses it, as

* **required**: the plugin defines it;
* **optional**: the plugin may define it, else the framework assumes the default given;
* **framework**: provided for the plugin (by :class:`fbia.Configurable`, the base class every
  plugin inherits, or by the framework around it); the plugin does not write it.

:func:`contracts` reads the same lists from these docstrings as data: the registry checks a
plugin's required methods with it (:func:`required_methods`), and so does the conformance kit
(:mod:`fbia.testing`).  Nothing in fbia checks inheritance from these protocols, only members.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from .interface import Interface
from .observation import Coordinate, Observation, Solution


@dataclass(frozen=True)
class Member:
    """One member of an extension contract, as its protocol's docstring lists it: the name
    (``solve(parameters, coordinates, workdir)`` for a method), who provides it and, for an
    optional one, the default the framework assumes."""

    name: str
    role: Literal["required", "optional", "framework"]
    default: str = ""

    @property
    def attribute(self) -> str:
        """The attribute the plugin class carries (``solve`` for ``solve(...)``)."""
        return self.name.partition("(")[0]


_ITEM = re.compile(
    r"^\s*\* ``(?P<name>[^`]+)`` \((?P<role>required|optional|framework)"
    r"(?:, default (?P<default>``[^`]*``|[^,):]+))?",
    re.M,
)


def contract(protocol: type) -> tuple[Member, ...]:
    """The members a protocol's docstring lists (``* ``name`` (role[, default X])...``)."""
    return tuple(
        Member(m["name"], m["role"], (m["default"] or "").strip("`"))  # type: ignore[arg-type]
        for m in _ITEM.finditer(protocol.__doc__ or "")
    )


@functools.cache
def contracts() -> dict[str, tuple[Member, ...]]:
    """Kind -> its contract, read from the three protocols' docstrings (once)."""
    return {
        "forward_model": contract(ForwardModel),
        "measure": contract(Discrepancy),
        "iterator": contract(InverseIterator),
    }


def required_methods(kind: str) -> list[str]:
    """The methods a plugin of ``kind`` must define (the registry checks them)."""
    return [m.attribute for m in contracts()[kind] if m.role == "required" and "(" in m.name]


def missing_methods(kind: str, plugin: Any) -> list[str]:
    """The required methods of ``kind`` that ``plugin`` (a class or an instance) lacks."""
    return [m for m in required_methods(kind) if not callable(getattr(plugin, m, None))]


@runtime_checkable
class ForwardModel(Protocol):
    """Parameters in, one interface per requested coordinate out.

    Members, in the order the framework uses them:

    * ``Options`` (required): its options, a subclass of :class:`fbia.PluginOptions`.
    * ``requires`` (optional, default ``()``): modules it needs beyond fbia's core.
    * ``__init__(options)`` (framework, :class:`fbia.Configurable`): ``self.options``.
    * ``pickle_options_only`` (optional, default False): pickle by options only.
    * ``numerics_version`` (optional, default None): the store keys its runs by it.
    * ``dim`` (optional, default None: seen on the first run): its interfaces' dimension.
    * ``up_axis`` (optional, default None: not declared): the axis of its 3-D interfaces along
      the height above the substratum, ``"z"`` or ``"y"``; a study's OCT scan must map its
      height onto it (``height_axis``).
    * ``parameter_names()`` (required): every model input it can vary.
    * ``undeformed()`` (optional): the unloaded interface, for synthetic point placement.
    * ``solve(parameters, coordinates, workdir)`` (required): an :class:`fbia.Solution`
      with one interface per coordinate; raises :class:`fbia.ForwardModelError` (and nothing
      else) when the run fails; inputs it is not given keep their option values.
    * ``tangent_inputs()`` (optional, default ``()``): the inputs whose tangents ``solve(...,
      tangents=names)`` gives, each interface's ``tangents[name]`` = d vertices / d name.
    * ``prepare()`` (optional): build what every run needs (a mesh) once, in the process from
      which isolated runs are forked (``fbia.execution.isolation``), so they start warm.
    * ``warm_state()`` (optional, default None): what a finished run leaves for later runs to
      start from (picklable); an isolated run sends it back to the forking process, whose
      model takes it with ``adopt_warm_state(state)``.
    * ``adopt_warm_state(state)`` (optional): take the ``warm_state()`` of another process.
    * ``example_parameters()`` (optional): where the conformance kit runs it.
    * ``example_options()`` (optional, default ``{}``): the kit's options.
    """

    def parameter_names(self) -> Sequence[str]: ...

    def solve(
        self, parameters: Mapping[str, float], coordinates: Sequence[Coordinate], workdir: Path
    ) -> Solution: ...


@runtime_checkable
class Discrepancy(Protocol):
    """A measure between a simulated interface and an observation (Paper B eq. 6-11).

    Members, in the order the framework uses them:

    * ``Options`` (required): its options, a subclass of :class:`fbia.PluginOptions`.
    * ``requires`` (optional, default ``()``): modules it needs beyond fbia's core.
    * ``__init__(options)`` (framework, :class:`fbia.Configurable`): ``self.options``.
    * ``pickle_options_only`` (optional, default False): pickle by options only.
    * ``numerics_version`` (optional, default None): the store keys comparisons by it.
    * ``residuals(simulated, observation)`` (required): a finite vector whose squared norm is
      D²; raises :class:`fbia.MeasureError` for interfaces it cannot compare.
    * ``residuals_jvp(simulated, observation, dvertices)`` (optional, default a difference):
      d residuals for a vertex motion (default: a central difference of ``residuals``).
    * ``distance(simulated, observation)`` (required): D, the norm of the residuals.
    * ``measurements_per_observation`` (optional, default ``len(residuals)``): n of eq. 5.
    * ``example_options()`` (optional, default ``{}``): the kit's options.
    * ``dims`` (optional, default ``(2, 3)``): the dimensions the kit tries.
    * ``mesh_dependent`` (optional, default False): residuals that belong to the simulated
      mesh (the kit leaves out the residual-length and re-meshing checks).
    """

    def residuals(self, simulated: Interface, observation: Observation) -> np.ndarray: ...

    def distance(self, simulated: Interface, observation: Observation) -> float: ...


@runtime_checkable
class InverseIterator(Protocol):
    """An inverse-analysis algorithm (registry kind ``iterator``).

    Members, in the order the framework uses them:

    * ``Options`` (required): its options, a subclass of :class:`fbia.PluginOptions`; an
      option ``seed`` (an integer or None) is the seed of its random numbers, which ``fbia
      run`` records in the result's provenance beside the study's seed.
    * ``requires`` (optional, default ``()``): modules it needs beyond fbia's core.
    * ``__init__(options)`` (framework, :class:`fbia.Configurable`): ``self.options``.
    * ``pickle_options_only`` (optional, default False): pickle by options only.
    * ``result_type`` (optional, default :class:`fbia.Result`): the Result dataclass its
      ``steps`` return, which :func:`fbia.load_result` reads back.
    * ``steps(problem, evaluator)`` (required): a generator; it asks
      ``evaluator.evaluate(problem, points)`` for runs (one :class:`fbia.Evaluation` per point,
      failed runs included; :class:`fbia.core.iteration.Evaluator`, whose ``slots`` says how
      many it makes at once), yields a state after every iteration and returns an
      :class:`fbia.Result` with ``status``, ``success``, ``message`` and ``x``; it does not
      count its runs.
    * ``result.iterator, nfev, n_failed, evaluations`` (framework,
      :func:`fbia.core.iteration.drive`): the registered name, the runs the evaluator returned
      and how many failed, stamped on the result.
    * ``run(problem, evaluator=None)`` (framework, :class:`fbia.IteratorBase`): drives
      ``steps`` to the end (a serial evaluator when none is given) and returns the stamped
      result, also kept as ``self.result``.
    * ``write_files(result, folder)`` (optional, default: none): files beside
      ``result.json`` for other tools (``fbia run`` calls it); returns the paths.
    * ``write_plots(result, problem, folder)`` (optional, default: no figures): its figures
      (``fbia.plot`` and ``fbia run`` call it); returns the paths.
    """

    def steps(self, problem: Any, evaluator: Any) -> Iterator[Any]: ...

    def run(self, problem: Any, evaluator: Any = None) -> Any: ...
