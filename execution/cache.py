"""The run cache in front of every executor: stored runs are reused, not run again.

:class:`RunCache` wraps a :class:`~fbia.storage.store.StudyStore` for an evaluator: for a batch
of requested points it says which are stored (their records are returned as they are; a
stored failure is a finished run too, unless ``retry_failed``, which runs each stored failure
once more), which are asked for twice in the batch (run once) and which must run; every
finished run is written to the store the moment it finishes (:meth:`RunCache.record`), so a
killed study loses nothing that finished.  A problem that asks for the model's tangents
(:class:`AsksTangents`) gets J of a stored run from its stored tangents; a run stored without
them runs again (one run, where differences would take n_x).  The executors (serial, process
pool, Dask) know nothing of stores: they run what the cache leaves them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ..core.errors import MeasureError
from ..core.observation import Solution
from ..core.problem import Evaluation, InverseProblem
from ..storage.store import StudyStore
from .isolation import RunOutcome

__all__ = ["AsksTangents", "Plan", "RunCache"]


@runtime_checkable
class AsksTangents(Protocol):
    """A problem whose records carry J from the model's tangents
    (:class:`fbia.iterators.tangents.TangentProblem`)."""

    tangent_names: tuple[str, ...]

    def jacobian_from(self, solution: Solution) -> NDArray[np.float64] | None: ...


@dataclass
class Plan:
    """What to do with one batch: ``reused`` records by request index, the points ``to_run``
    (index, inputs), and ``copies`` (index, index of the same point earlier in the batch)."""

    reused: dict[int, Evaluation] = field(default_factory=dict)
    to_run: list[tuple[int, dict[str, float]]] = field(default_factory=list)
    copies: list[tuple[int, int]] = field(default_factory=list)


class RunCache:
    """Store lookup, de-duplication and retry of failed runs (see the module docstring)."""

    def __init__(self, store: StudyStore, retry_failed: bool = False) -> None:
        self.store = store
        self.retry_failed = retry_failed
        self._keys: dict[int, str] = {}  # request index -> store key, until the run is stored
        self._retried: set[str] = set()

    def plan(self, problem: InverseProblem, requests: list[tuple[int, dict[str, float]]]) -> Plan:
        """Sort a batch of numbered requests into reused, to run and copies."""
        self.store.bind(problem)
        keys = [self.store.key(x) for _, x in requests]
        stored = self.store.lookup(keys)
        plan = Plan()
        first: dict[str, int] = {}
        for (i, x), key in zip(requests, keys, strict=True):
            run = stored.get(key)
            retry = (
                run is not None
                and self.retry_failed
                and not run.record.ok
                and key not in self._retried
            )
            reuse = None if run is None else dataclasses.replace(run.record, index=i, x=x)
            if reuse is not None and isinstance(problem, AsksTangents) and reuse.ok:
                # a run stored without tangents runs again for them: one run, not n_x more
                if not self._tangent_jacobian(problem, reuse, key):
                    reuse = None
            if reuse is not None and not retry:
                plan.reused[i] = reuse
            elif key in first:
                plan.copies.append((i, first[key]))
            else:
                if retry:
                    self._retried.add(key)
                first[key] = i
                self._keys[i] = key
                plan.to_run.append((i, x))
        return plan

    def _tangent_jacobian(self, problem: AsksTangents, record: Evaluation, key: str) -> bool:
        """Give a stored run its J from its stored tangents; False for a run stored without
        them (or whose measure cannot differentiate them)."""
        solution = self.store.solution(key)
        try:
            jacobian = None if solution is None else problem.jacobian_from(solution)
        except MeasureError:
            jacobian = None
        if jacobian is not None:
            record.jacobian, record.jacobian_names = jacobian, problem.tangent_names
        return jacobian is not None

    def record(self, outcome: RunOutcome) -> None:
        """Store a run that has just finished (with its interfaces, for later comparisons)."""
        ev = outcome.record
        self.store.put(
            ev,
            self._keys.pop(ev.index, None),
            outcome.worker,
            outcome.artifacts,
            outcome.interfaces,
        )

    def workdir_taken(self, workdir: str | Path) -> bool:
        """Whether a stored run owns this working folder (it is then never reused)."""
        return self.store.workdir_taken(workdir)
