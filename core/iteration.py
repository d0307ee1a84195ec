"""Steppable iterators: ``steps()`` is a generator, ``run()`` drains it.

An iterator's ``steps(problem, evaluator)`` yields a state object after every iteration (so a
caller can watch progress, checkpoint or stop early) and *returns* its :class:`Result`::

    it = fbia.iterator("levenberg_marquardt", x0={"E": 200.0, "nu": 0.4})
    for state in (gen := it.steps(problem, evaluator)):
        print(state)                      # or break: LM's it.stop(gen) gives the partial result
    result = it.result
"""

from __future__ import annotations

from collections.abc import Generator, Iterator
from typing import Any, Protocol, runtime_checkable

from .evaluator import Evaluator, SerialEvaluator
from .options import Configurable
from .problem import InverseProblem, Result


@runtime_checkable
class InverseIterator(Protocol):
    """An inverse-analysis algorithm (registry kind ``iterator``): ``steps`` yields after
    every iteration, ``run`` drains it."""

    def steps(self, problem: InverseProblem, evaluator: Evaluator) -> Iterator[Any]: ...

    def run(self, problem: InverseProblem, evaluator: Evaluator | None = None) -> Result: ...


class IteratorBase(Configurable):
    """Base class of iterators: subclasses implement :meth:`steps`."""

    #: The result of the last completed :meth:`steps` generator (also returned by :meth:`run`).
    result: Result | None = None

    def steps(self, problem: InverseProblem, evaluator: Evaluator) -> Generator[Any, None, Result]:
        raise NotImplementedError

    def run(self, problem: InverseProblem, evaluator: Evaluator | None = None) -> Result:
        """Run to the end and return the :class:`Result` (serial evaluation by default)."""
        own = evaluator is None
        ev: Evaluator = SerialEvaluator() if evaluator is None else evaluator
        try:
            gen = self.steps(problem, ev)
            while True:
                try:
                    next(gen)
                except StopIteration as stop:
                    self.result = stop.value
                    return stop.value
        finally:
            if own:
                ev.close()  # type: ignore[attr-defined]
