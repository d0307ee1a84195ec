"""Two of the three extension points of fbia, as typing protocols.

A forward model turns parameters into interfaces, a measure (``Discrepancy``) compares a
simulated interface with an observation; the third, an iterator that drives the inverse
analysis, is :class:`fbia.core.iteration.InverseIterator` (it needs the problem and the
evaluator, which need these two).  Plugins implement them; nothing in fbia checks
inheritance, only these methods.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from .interface import Interface
from .observation import Coordinate, Observation, Solution


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
