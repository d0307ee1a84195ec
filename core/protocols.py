"""The three extension points of fbia, as typing protocols.

A forward model turns parameters into interfaces, a measure (``Discrepancy``) compares a
simulated interface with an observation, an iterator drives the inverse analysis.  Plugins
implement them; nothing in fbia checks inheritance, only these methods.
"""

from __future__ import annotations

from collections.abc import Iterator as PyIterator
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from fbia.core.interface import Interface
from fbia.core.observation import Coordinate, Observation, Solution

if TYPE_CHECKING:
    from fbia.core.evaluator import Evaluator
    from fbia.core.problem import InverseProblem, Result


@runtime_checkable
class ForwardModel(Protocol):
    """Parameters in, one interface per requested coordinate out.

    ``solve`` raises :class:`fbia.ForwardModelError` (and nothing else) when the run fails.
    ``parameters`` holds every model input being varied (calibration and uncertain ones);
    inputs a model knows but is not given keep their option values.
    """

    def parameter_names(self) -> Sequence[str]: ...

    def solve(
        self, parameters: Mapping[str, float], coordinates: Sequence[Coordinate], workdir: Path
    ) -> Solution: ...


@runtime_checkable
class Discrepancy(Protocol):
    """A measure between a simulated interface and an observation (Paper B eq. 6-11)."""

    def residuals(self, simulated: Interface, observation: Observation) -> np.ndarray: ...

    def distance(self, simulated: Interface, observation: Observation) -> float: ...


@runtime_checkable
class Iterator(Protocol):
    """An inverse-analysis algorithm; ``steps`` yields after every iteration, ``run`` drains it."""

    def steps(self, problem: InverseProblem, evaluator: Evaluator) -> PyIterator[Any]: ...

    def run(self, problem: InverseProblem, evaluator: Evaluator | None = None) -> Result: ...
