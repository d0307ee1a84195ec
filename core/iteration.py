"""Steppable iterators: ``steps()`` is a generator, ``run()`` drains it.

An iterator's ``steps(problem, evaluator)`` yields a state object after every iteration (so a
caller can watch progress, checkpoint or stop early) and *returns* its :class:`Result`::

    it = fbia.iterator("levenberg_marquardt", x0={"E": 200.0, "nu": 0.4})
    for state in (gen := it.steps(problem, evaluator)):
        print(state)                      # or break: LM's it.stop(gen) gives the partial result
    result = it.result
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Generator, Iterator
from pathlib import Path
from typing import Any, Protocol, TypeVar, runtime_checkable

from .evaluator import Evaluator
from .local_executors import SerialEvaluator
from .options import Configurable
from .problem import InverseProblem, Result

logger = logging.getLogger(__name__)

S = TypeVar("S")
R = TypeVar("R")


def drain(
    gen: Generator[S, None, R], on_state: Callable[[S], None] | None = None, name: str = ""
) -> R:
    """Run a ``steps()`` generator to its end and return what it returns; ``on_state`` sees
    every state it yields, and the logger ``fbia.core.iteration`` gets it at INFO (prefixed
    by the iterator's ``name``): the progress of an iterator run from Python, shown with
    ``logging.basicConfig(level=logging.INFO)``.  The generator is closed if anything raises
    on the way."""
    prefix = f"{name}: " if name else ""
    try:
        while True:
            try:
                state = next(gen)
            except StopIteration as stop:
                result: R = stop.value
                logger.info("%sdone", prefix)
                return result
            logger.info("%s%s", prefix, state)
            if on_state is not None:
                on_state(state)
    finally:
        gen.close()


@runtime_checkable
class InverseIterator(Protocol):
    """An inverse-analysis algorithm (registry kind ``iterator``): ``steps`` yields after
    every iteration, ``run`` drains it."""

    def steps(self, problem: InverseProblem, evaluator: Evaluator) -> Iterator[Any]: ...

    def write_files(self, result: Result, folder: Path) -> list[Path]:
        """Files of ``result`` beside its ``result.json`` that other tools read (``fbia run``
        calls it; ``gp_smc``: the posterior as npz + JSON and as an ArviZ netCDF file);
        returns the paths written (none by default)."""
        return []

    def run(self, problem: InverseProblem, evaluator: Evaluator | None = None) -> Result: ...


class IteratorBase(Configurable):
    """Base class of iterators: subclasses implement :meth:`steps`."""

    #: The result of the last completed :meth:`steps` generator (also returned by :meth:`run`).
    result: Result | None = None
    #: The class of its results: :func:`fbia.load_result` reads a ``result.json`` of this
    #: iterator back as it (a dataclass subclass of :class:`Result`).
    result_type: type[Result] = Result

    def steps(self, problem: InverseProblem, evaluator: Evaluator) -> Generator[Any, None, Result]:
        raise NotImplementedError

    def run(self, problem: InverseProblem, evaluator: Evaluator | None = None) -> Result:
        """Run to the end and return the :class:`Result` (serial evaluation by default)."""
        own = evaluator is None
        ev: Evaluator = SerialEvaluator() if evaluator is None else evaluator
        try:
            self.result = drain(self.steps(problem, ev), name=type(self).__name__)
            return self.result
        finally:
            if own:
                ev.close()  # type: ignore[attr-defined]
