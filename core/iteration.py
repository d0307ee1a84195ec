"""Steppable iterators: ``steps()`` is a generator, ``run()`` drains it.

An iterator's ``steps(problem, evaluator)`` yields a state object after every iteration (so a
caller can watch progress, checkpoint or stop early) and *returns* its :class:`Result`::

    it = fbia.iterator("levenberg_marquardt", x0={"E": 200.0, "nu": 0.4})
    for state in (gen := it.steps(problem, evaluator)):
        print(state)                      # or break: LM's it.stop(gen) gives the partial result
    result = it.result

:func:`drive` is how the framework runs one (``IteratorBase.run``, ``fbia run``, the
conformance kit): it hands ``steps`` an evaluator that keeps the books (:class:`RunBook`) and
stamps ``iterator``, ``nfev``, ``n_failed`` and ``evaluations`` on the result, so no iterator
counts its runs by hand.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Generator, Mapping, Sequence
from typing import Any, Protocol, TypeVar, final, runtime_checkable

from .problem import Evaluable, Evaluation, InverseProblem, IteratorMembers, Result
from .registry import default_registry

logger = logging.getLogger(__name__)

S = TypeVar("S")
R = TypeVar("R")


@runtime_checkable
class Evaluator(Protocol):
    """Evaluates batches of parameter points; results come back in the order of ``points``
    (``fbia.execution``: ``SerialEvaluator``, ``ProcessPoolEvaluator``, ``DaskEvaluator``).
    ``slots`` is how many runs it makes at once (1 for a serial one): an iterator that
    chooses its batch sizes (gp_smc's adaptive rounds) makes them multiples of it."""

    def evaluate(
        self, problem: Evaluable, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]:
        """One :class:`fbia.Evaluation` per point, in their order, failed runs included (a
        failure is an outcome, not an exception)."""
        ...

    @property
    def slots(self) -> int:
        """How many runs it makes at once (1 serially, the workers of a pool): a batch that
        is a multiple of it keeps every worker busy."""
        ...


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


class RunBook:
    """The evaluator an iterator's ``steps`` receives from :func:`drive`: it passes every
    batch to ``evaluator`` and keeps the records it returns, in order (the framework's books:
    ``records``, ``nfev``, ``n_failed``).  Other attributes are the wrapped evaluator's."""

    def __init__(self, evaluator: Evaluator) -> None:
        self.evaluator = evaluator
        self.records: list[Evaluation] = []

    def evaluate(
        self, problem: Evaluable, points: Sequence[Mapping[str, float]]
    ) -> list[Evaluation]:
        out = list(self.evaluator.evaluate(problem, points))
        self.records.extend(out)
        return out

    @property
    def nfev(self) -> int:
        return len(self.records)

    @property
    def n_failed(self) -> int:
        return sum(not e.ok for e in self.records)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.evaluator, name)


def drive(
    iterator: Any,
    problem: Any,
    evaluator: Evaluator,
    on_state: Callable[[Any], None] | None = None,
    name: str = "",
) -> Result:
    """Run ``iterator.steps(problem, ...)`` to its end (:func:`drain`) on ``evaluator`` through
    a :class:`RunBook`, and stamp the books on the result it returns: ``iterator`` (``name``,
    the name a study registered it under; else its name in the default registry; else what it
    set; else its class name), ``nfev``, ``n_failed`` and ``evaluations`` (every run the
    evaluator returned during ``steps``, in order)."""
    book = RunBook(evaluator)
    result: Result = drain(iterator.steps(problem, book), on_state, type(iterator).__name__)
    return stamp(result, iterator, book, name)


def stamp(result: Result, iterator: Any, book: RunBook, name: str = "") -> Result:
    """Write the framework's books on ``result`` (see :func:`drive`) and return it."""
    entry = None if name else default_registry().entry_for(iterator)
    registered = name or (entry.name if entry is not None else "")
    result.iterator = registered or result.iterator or type(iterator).__name__
    result.nfev, result.n_failed = book.nfev, book.n_failed
    result.evaluations = list(book.records)
    return result


class IteratorBase(IteratorMembers):
    """The base of every iterator: its optional members, with their defaults, and ``run``.

    An iterator writes ``Options`` and ``steps(problem, evaluator)``
    (:class:`fbia.InverseIterator`) and overrides the members of
    :class:`~fbia.core.problem.IteratorMembers` that it offers (``result_type``,
    ``write_files``, ``write_plots``, ``example_options``, ...); :meth:`run` is the
    framework's."""

    result: Result | None = None
    """The result of the last completed ``steps`` generator (also returned by :meth:`run`)."""

    @final
    def run(self, problem: InverseProblem, evaluator: Evaluator | None = None) -> Result:
        """Drive ``steps`` to the end (:func:`fbia.core.iteration.drive`; a serial evaluator
        when none is given) and return the stamped :class:`fbia.Result`, also kept as
        ``self.result``."""
        own = evaluator is None
        if evaluator is None:
            if _default_evaluator is None:
                raise RuntimeError("no default evaluator: pass one, e.g. fbia.SerialEvaluator()")
            evaluator = _default_evaluator()
        try:
            self.result = drive(self, problem, evaluator)
            return self.result
        finally:
            if own:
                evaluator.close()  # type: ignore[attr-defined]
