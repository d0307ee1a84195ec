"""The three extension points of fbia: their contracts as code.

A forward model turns parameters into interfaces (:class:`ForwardModel`), a measure compares a
simulated interface with an observation (:class:`Discrepancy`), an iterator drives the inverse
analysis (:class:`InverseIterator`; the evaluator it receives is
:class:`fbia.core.iteration.Evaluator`).  Each contract is two classes:

* the **protocol** holds the members a plugin must write (**required**), as typed methods;
* the **base** (:class:`ForwardModelBase`, :class:`MeasureBase`; an iterator's is
  :class:`fbia.IteratorBase`, whose members below ``run`` are
  :class:`fbia.core.problem.IteratorMembers`) derives from its protocol and from
  :class:`fbia.Configurable` and holds every **optional** member with its default, as an
  attribute or a method; a member marked ``@final`` is the **framework**'s, which the plugin
  does not write.

A plugin class derives from its kind's base and overrides what it needs::

    class MySolverForwardModel(fbia.ForwardModelBase):
        class Options(fbia.PluginOptions): ...

        def parameter_names(self): ...

        def solve(self, parameters, coordinates, workdir): ...

The registry refuses a plugin class that does not derive from its kind's base or leaves a
required method unwritten (:func:`missing_methods`); the framework calls the optional members
directly, since the base guarantees them.  :func:`fbia.testing.contracts.contracts` reads the
members, their roles, defaults and docstrings from these classes as data, and the member
tables of ``docs/plugins.md`` are rendered from it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from .interface import Interface
from .observation import Coordinate, Observation, Solution
from .options import Configurable


@runtime_checkable
class ForwardModel(Protocol):
    """Parameters in, one interface per requested coordinate out: what a forward model
    writes.  Its optional members and their defaults are :class:`ForwardModelBase`'s."""

    def parameter_names(self) -> Sequence[str]:
        """Every model input it can vary."""
        ...

    def solve(
        self, parameters: Mapping[str, float], coordinates: Sequence[Coordinate], workdir: Path
    ) -> Solution:
        """An :class:`fbia.Solution` with one interface per coordinate; raises
        :class:`fbia.ForwardModelError` (and nothing else) when the run fails; inputs it is
        not given keep their option values."""
        ...


@runtime_checkable
class Discrepancy(Protocol):
    """A measure between a simulated interface and an observation (Paper B eq. 6-11): what a
    measure writes.  Its optional members and their defaults are :class:`MeasureBase`'s."""

    def residuals(self, simulated: Interface, observation: Observation) -> np.ndarray:
        """A finite vector whose squared norm is D²; raises :class:`fbia.MeasureError` for
        interfaces it cannot compare."""
        ...

    def distance(self, simulated: Interface, observation: Observation) -> float:
        """D, the norm of the residuals."""
        ...


@runtime_checkable
class InverseIterator(Protocol):
    """An inverse-analysis algorithm (registry kind ``iterator``): what an iterator writes.
    Its optional members and their defaults are :class:`fbia.core.problem.IteratorMembers`',
    the framework's :class:`fbia.IteratorBase` adds ``run``."""

    def steps(self, problem: Any, evaluator: Any) -> Iterator[Any]:
        """A generator; it asks ``evaluator.evaluate(problem, points)`` for runs (one
        :class:`fbia.Evaluation` per point, failed runs included; ``evaluator.slots`` says how
        many it makes at once: :class:`fbia.core.iteration.Evaluator`), yields a state after
        every iteration and returns an :class:`fbia.Result` with ``status``, ``success``,
        ``message`` and ``x``.  It does not count its runs: the framework stamps
        ``iterator``, ``nfev``, ``n_failed`` and ``evaluations`` on the result
        (:func:`fbia.core.iteration.drive`)."""
        ...


class ForwardModelBase(Configurable, ForwardModel):
    """The base of every forward model: its optional members, with their defaults.

    A model writes ``Options``, ``parameter_names()`` and ``solve(parameters, coordinates,
    workdir)`` (:class:`ForwardModel`) and overrides the members below that it offers; the
    others keep these defaults."""

    numerics_version: str | None = None
    """A string the store keys its runs by instead of the package's version (fbia's own
    declare ``"1"``); bump it when a change alters the numbers.  None: the package's
    version."""

    up_axis: Literal["z", "y"] | None = None
    """The axis of its 3-D interfaces along the height above the substratum; a study's OCT
    scan must map its height onto it (``height_axis``).  None: not declared."""

    @property
    def dim(self) -> int | None:
        """Its interfaces' dimension, 2 or 3: a class attribute, or a property where its
        options decide.  The base: None, seen on the first run."""
        return None

    def undeformed(self) -> Interface | None:
        """The unloaded interface, for synthetic point placement (``placement =
        "displacement"``) and a study's dimension check.  The base: None, it has none."""
        return None

    def tangent_inputs(self) -> Sequence[str]:
        """The inputs whose tangents ``solve(..., tangents=names)`` gives (an extra keyword
        of ``solve``): each interface's ``tangents[name]`` = d vertices / d name.  The base:
        none, ``()``."""
        return ()

    def prepare(self) -> None:
        """Build what every run needs (a mesh) once, in the process from which isolated runs
        are forked (``fbia.execution.isolation``), so they start warm.  The base: nothing."""

    def warm_state(self) -> Any:
        """What a finished run leaves for later runs to start from (picklable); an isolated
        run sends it back to the forking process, whose model takes it with
        :meth:`adopt_warm_state`.  The base: None, nothing."""
        return None

    def adopt_warm_state(self, state: Any) -> None:
        """Take the :meth:`warm_state` of another process.  The base: ignores it."""

    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]] | None:
        """``(parameters, coordinates)`` of a cheap, successful run, where the conformance kit
        and ``fbia init`` run it.  The base: None, none given (the kit then refuses the
        model, ``fbia init`` writes no study)."""
        return None


class MeasureBase(Configurable, Discrepancy):
    """The base of every measure: its optional members, with their defaults.

    A measure writes ``Options``, ``residuals(simulated, observation)`` and
    ``distance(simulated, observation)`` (:class:`Discrepancy`) and overrides the members
    below that it offers; the others keep these defaults."""

    numerics_version: str | None = None
    """A string the store keys its comparisons by instead of the package's version; bump it
    when a change alters the numbers.  None: the package's version."""

    measurements_per_observation: int | None = None
    """n of Paper B eq. 5 per observation.  None: the length of each run's residuals."""

    dims: tuple[int, ...] = (2, 3)
    """The dimensions of the interfaces it compares (the conformance kit tries those)."""

    mesh_dependent: bool = False
    """True: its residuals belong to the simulated mesh, one per simulated vertex (the
    conformance kit leaves out the residual-length and re-meshing checks)."""

    def residuals_jvp(
        self, simulated: Interface, observation: Observation, dvertices: np.ndarray
    ) -> np.ndarray | None:
        """d residuals for the vertex motion ``dvertices`` (an array of the vertices' shape),
        for a model's tangents.  The base: None, no closed form; fbia then takes a central
        difference of ``residuals`` along the motion
        (:func:`fbia.iterators.tangents.directional_difference`)."""
        return None


#: The protocol of each plugin kind: the methods a plugin of that kind writes.
PROTOCOLS: dict[str, type] = {
    "forward_model": ForwardModel,
    "measure": Discrepancy,
    "iterator": InverseIterator,
}


def required_methods(kind: str) -> list[str]:
    """The methods a plugin of ``kind`` must write: its protocol's, in order."""
    return [n for n, v in vars(PROTOCOLS[kind]).items() if callable(v) and not n.startswith("_")]


def missing_methods(kind: str, plugin: Any) -> list[str]:
    """The required methods of ``kind`` that ``plugin`` (a class or an instance) does not
    write: absent, not callable, or the protocol's own stub, which a base inherits."""
    cls = plugin if isinstance(plugin, type) else type(plugin)
    stubs = vars(PROTOCOLS[kind])
    return [
        m
        for m in required_methods(kind)
        if not callable(own := getattr(cls, m, None)) or own is stubs[m]
    ]
