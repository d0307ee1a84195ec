"""Conformance of iterators, on a tiny problem with a counting evaluator."""

from __future__ import annotations

import inspect
import json
import math
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..core.iteration import IteratorBase, RunBook, stamp
from ..core.parameters import Parameter
from ..core.problem import Evaluable, Evaluation, InverseProblem, Result
from ..core.protocols import missing_methods
from ..core.registry import forward_model
from ..core.registry import measure as make_measure
from ..core.synthetic import synthetic_observations
from ..execution.local_executors import SerialEvaluator
from .errors import fail


class CountingEvaluator:
    """Wraps an evaluator and counts the points it evaluates and the runs that failed."""

    def __init__(self, inner: Any = None) -> None:

        self.inner = SerialEvaluator() if inner is None else inner
        self.points = 0
        self.failed = 0
        self.batches = 0

    def evaluate(
        self, problem: Evaluable, points: Sequence[Mapping[str, float]]
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
    * it derives from :class:`fbia.IteratorBase` and writes the methods its contract
      requires (:class:`fbia.InverseIterator`);
    * the result says why it stopped: ``status`` and ``message`` are non-empty strings,
      ``success`` is a bool;
    * the framework's books (:func:`fbia.core.iteration.stamp`: ``iterator``, ``nfev``,
      ``n_failed``, ``evaluations``) match the points the evaluator was given and the runs that
      failed (failed runs are outcomes, not exceptions; the iterator does not count them);
    * ``x`` is None or a finite value for each parameter of the problem within its bounds;
    * ``to_dict()`` is plain JSON (no NaN), and :meth:`fbia.Result.save` writes the same;
    * ``run()`` reproduces the result (same status, nfev and x), and neither run touches
      numpy's global random state.

    Returns the result of the ``steps`` run.
    """

    global_state = _global_rng_state()
    it = iterator_factory()
    if not isinstance(it, IteratorBase):
        raise fail(it, "does not derive from fbia.IteratorBase")
    lacking = missing_methods("iterator", it)
    if lacking:
        raise fail(it, f"lacks the method(s) its contract requires: {', '.join(lacking)}")
    ev = CountingEvaluator()
    book = RunBook(ev)
    try:
        gen = it.steps(problem, book)
        if not inspect.isgenerator(gen):
            raise fail(it, f"steps() must be a generator, got {type(gen).__name__}")
        yields = 0
        while True:
            try:
                next(gen)
            except StopIteration as stop:
                result = stop.value
                break
            yields += 1
        if yields == 0:
            raise fail(it, "steps() returned without yielding a state")
    finally:
        ev.close()
    if not isinstance(result, Result):
        raise fail(it, f"steps() must return fbia.Result, got {type(result).__name__}")
    stamp(result, it, book)
    for attr in ("status", "message", "iterator"):
        value = getattr(result, attr)
        if not (isinstance(value, str) and value.strip()):
            raise fail(it, f"Result.{attr} must be a non-empty string, got {value!r}")
    if not isinstance(result.success, (bool, np.bool_)):
        raise fail(it, f"Result.success must be a bool, got {result.success!r}")
    if result.nfev != ev.points:
        raise fail(
            it, f"Result.nfev = {result.nfev} but the evaluator was given {ev.points} points"
        )
    if result.n_failed != ev.failed:
        raise fail(it, f"Result.n_failed = {result.n_failed} but {ev.failed} runs failed")
    if result.x is not None:
        shown = {k: float(v) for k, v in result.x.items()}
        if set(result.x) != set(problem.names):
            raise fail(it, f"Result.x has keys {sorted(result.x)}, the problem has {problem.names}")
        x = problem.vector(result.x)
        span = problem.upper - problem.lower
        if not np.all(np.isfinite(x)):
            raise fail(it, f"Result.x is not finite: {shown}")
        if np.any(x < problem.lower - 1e-9 * span) or np.any(x > problem.upper + 1e-9 * span):
            raise fail(it, f"Result.x = {shown} lies outside the bounds")
    try:
        as_dict = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise fail(it, f"Result.to_dict() is not plain JSON: {exc}") from exc
    with tempfile.TemporaryDirectory(dir=tmp_path) as tmp:
        saved = json.loads(result.save(Path(tmp) / "result.json").read_text())
    if saved != as_dict:
        raise fail(it, "Result.save() writes something other than Result.to_dict()")

    ev2 = CountingEvaluator()
    try:
        rerun = iterator_factory().run(problem, ev2)
    finally:
        ev2.close()
    if not isinstance(rerun, Result):
        raise fail(it, f"run() must return fbia.Result, got {type(rerun).__name__}")
    same_x = (rerun.x is None and result.x is None) or (
        rerun.x is not None
        and result.x is not None
        and set(rerun.x) == set(result.x)
        and all(math.isclose(rerun.x[k], result.x[k], rel_tol=1e-10) for k in result.x)
    )
    if rerun.status != result.status or rerun.nfev != result.nfev or not same_x:
        raise fail(
            it,
            "two runs with equal options differ: "
            f"({result.status}, nfev {result.nfev}, x {result.x}) vs "
            f"({rerun.status}, nfev {rerun.nfev}, x {rerun.x}); fix the seed in the options",
        )
    if _global_rng_state() != global_state:
        raise fail(it, "the run used numpy's global random state; take a Generator or a seed")
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
