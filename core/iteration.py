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
from collections.abc import Callable, Generator, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol, TypeVar, runtime_checkable

from .options import Configurable
from .problem import Evaluable, Evaluation, InverseProblem, Result

logger = logging.getLogger(__name__)

S = TypeVar("S")
R = TypeVar("R")


@runtime_checkable
class Evaluator(Protocol):
    """Evaluates batches of parameter points; results come back in the order of ``points``
    (``fbia.execution``: ``SerialEvaluator``, ``ProcessPoolEvaluator``, ``DaskEvaluator``)."""

    def evaluate(
        self, problem: Evaluable, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]: ...


#: What :meth:`IteratorBase.run` evaluates with when it is given no evaluator: a factory of
#: evaluators, set by the package root (``fbia/__init__.py``: the serial evaluator of
#: ``fbia.execution``), so the kernel names no executor.
_default_evaluator: Callable[[], Evaluator] | None = None


def set_default_evaluator(factory: Callable[[], Evaluator]) -> None:
    """Set the factory :meth:`IteratorBase.run` builds its evaluator with when none is given."""
    global _default_evaluator
    _default_evaluator = factory


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
        if evaluator is None:
            if _default_evaluator is None:
                raise RuntimeError("no default evaluator: pass one, e.g. fbia.SerialEvaluator()")
            evaluator = _default_evaluator()
        try:
            self.result = drain(self.steps(problem, evaluator), name=type(self).__name__)
            return self.result
        finally:
            if own:
                evaluator.close()  # type: ignore[attr-defined]
