"""Running a study: the stages of ``fbia run`` (session, evaluator, iterator, files).

:func:`run_study` runs the iterator of a :class:`~fbia.studies.study.Study` (or one forward run
when it has none) and writes the output folder, resuming from its store;
:func:`forward_study` makes one forward run and writes its files.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

from ..core.errors import ConfigError, Terminated
from ..core.iteration import drive
from ..core.observation import Solution
from ..core.problem import Evaluation, InverseProblem, Result
from ..execution.evaluator import BatchEvaluator
from ..execution.executors import ExecutorSpec, evaluator_for
from ..storage.output_folder import OutputLock, clear_runs
from ..storage.store import StudyStore
from . import report
from .evaluation_log import EvaluationLog
from .paper import Comparison
from .plots import plot_evaluations, plot_interfaces
from .progress import RunProgress, log_to_file
from .provenance import RunOutputs, RunRecord, now
from .provenance import provenance as make_provenance
from .study import Study
from .study_report import SessionTimes, write_report
from .tables import discrepancy_rows

__all__ = ["STORE_NAME", "forward_study", "run_study", "study_seeds"]

logger = logging.getLogger(__name__)

#: a result and the same kind of result with its run record (:func:`_finish`)
R = TypeVar("R", bound=Result)

#: ``run_study``'s ``log_level``: what fbia.log records
LOG_LEVELS = {"info": logging.INFO, "debug": logging.DEBUG}

#: The study store's file name in the output folder.
STORE_NAME = "store.sqlite"


# -- running -----------------------------------------------------------------------------------
Echo = Callable[[str], None]


def forward_study(
    study: Study,
    values: Mapping[str, float] | None = None,
    output: str | Path | None = None,
    echo: Echo = print,
) -> Result:
    """One forward run at ``study.start_point(values)``, compared with every observation.

    Writes to ``output`` (default ``<study output>/forward``): ``evaluations.jsonl``, the
    model's working folder ``run/`` (with any field files), ``interfaces/`` (observed and
    simulated, CSV for 2-D and VTU), ``plots/interfaces.png`` (2-D), ``result.json`` and
    ``report.txt``; echoes the discrepancy table (measure, D, number of residuals, max |r|).
    """
    out = Path(output) if output is not None else study.output / "forward"
    return _forward(study, values, out, echo, started=now())


def _forward(
    study: Study, values: Mapping[str, float] | None, out: Path, echo: Echo, started: str
) -> Result:
    x = study.start_point(values)
    if (out / STORE_NAME).exists():
        raise ConfigError(
            f"holds a study ({STORE_NAME}): a forward run writes its own evaluations.jsonl "
            "and result.json and would replace the study's; give --output another folder",
            str(out),
        )
    with OutputLock(out, "fbia forward"):
        return _forward_locked(study, x, out, echo, started)


def _forward_locked(
    study: Study, x: dict[str, float], out: Path, echo: Echo, started: str
) -> Result:
    t0 = time.perf_counter()
    problem = study.problem
    _write_oct_records(study, out, echo)
    with EvaluationLog(out / "evaluations.jsonl") as log:
        ev = problem.evaluate(x, workdir=out / "run", index=0, keep_solution=True)
        log.append(ev)
    echo(f"forward run of {study.model_name} at {_point(ev.x)}: {ev.status} ({ev.time:.3g} s)")
    result = Result(
        status="forward" if ev.ok else ev.status,
        success=ev.ok,
        message=(
            "one forward run and its discrepancy (the study has no iterator)"
            if ev.ok
            else f"the forward run {_failure_word(ev)}: {ev.message}"
        ),
        x={n: ev.x[n] for n in problem.names if n in ev.x},
        nfev=1,
        n_failed=0 if ev.ok else 1,
        iterator="",
        evaluations=[ev],
        info={"inputs": ev.x},
    )
    outputs = RunOutputs()
    if ev.ok and ev.solution is not None:
        files = _write_solution(study, ev.solution, out, "forward run")
        outputs = RunOutputs(files, discrepancy_rows(problem, ev.solution, study.measure_name))
        echo(f"interfaces: {len(files['interfaces'])} files in {out / 'interfaces'}")
        for name, path in files.get("fields", {}).items():
            echo(f"field {name}: {path}")
    result, text = _finish(study, result, out, started, echo, outputs=outputs)
    times = SessionTimes(time.perf_counter() - t0, _forward_time(result), 1)
    _reports(study, result, out, text, times, echo, figures=_pngs(outputs.files))
    return result


def run_study(
    study: Study,
    output: str | Path | None = None,
    workers: int | None = None,
    echo: Echo = print,
    *,
    fresh: bool = False,
    retry_failed: bool = False,
    address: str | None = None,
    reuse_changed_code: bool = False,
    log_level: str = "info",
) -> Result:
    """Run a study and write its output folder (default: the study's ``output``).

    With an iterator: opens the study store, ``<output>/store.sqlite`` or the file that
    ``[study] store`` names (studies of one model may share it) (resuming: every run
    stored there for the same problem is reused, never run again), builds the evaluator from
    ``[executor]`` (``workers`` and ``address`` override it), drives the iterator step by step
    with a progress display, stores every evaluation the moment it finishes (and appends it to
    ``evaluations.jsonl``; ``fbia.log`` gets every line), then solves once more at the
    result's ``x`` and writes ``interfaces/``, ``plots/``, ``result.json`` (with provenance)
    and ``report.txt``.  Without an iterator: what :func:`forward_study` does, in ``output``.

    Parameters
    ----------
    fresh
        Delete the store (and the run folders) first and start over; refused (ConfigError)
        when the store holds runs that sessions of other study files made
        (:meth:`StudyStore.check_fresh`).
    retry_failed
        Run stored failed runs again (once) instead of reusing their failure.
    reuse_changed_code
        Reuse the stored runs although the model plugin's source changed since they were
        made (without it such a store is refused: :meth:`StudyStore.bind`).
    address
        Send the runs to the Dask scheduler at this address.
    log_level
        What ``fbia.log`` records of the ``fbia`` loggers: ``"info"`` or ``"debug"``.

    Raises
    ------
    ConfigError
        The store holds runs of a different model class, version or fixed inputs (the
        message says what changed; runs of this model class at other option values are
        kept beside this model's), or is in use by another run.

    On Ctrl-C or an error the evaluations finished so far are already stored; a
    ``result.json`` with status ``"interrupted"`` or ``"error"`` is written and the exception
    goes on to the caller.
    """
    if log_level not in LOG_LEVELS:
        raise ConfigError(f"log_level {log_level!r}: one of {', '.join(LOG_LEVELS)}", "run")
    out = Path(output) if output is not None else study.output
    started = now()
    if study.iterator is None:
        echo("the study has no [iterator]: one forward run at the start point")
        return _forward(study, None, out, echo, started)
    store_path = study.store if study.store is not None else out / STORE_NAME
    if study.synthetic is not None and study.synthetic.draws > 1:  # fbia.studies.draws

        def run_one(sub: Study, k: int) -> Result:
            return run_study(
                replace(sub, oct_records=()),  # _run_draws wrote them, once, into `out`
                sub.output,
                workers,
                echo,
                address=address,
                fresh=fresh and k == 0,
                retry_failed=retry_failed,
                reuse_changed_code=reuse_changed_code,
                log_level=log_level,
            )

        return _run_draws(study, out, store_path, run_one, echo, started)
    problem = study.problem
    executor = study.executor.with_workers(workers).with_address(address)
    identity = (str(study.path.resolve()), study.sha256)  # sessions record it; --fresh checks
    with OutputLock(out, "fbia run"), StudyStore(store_path, fresh=fresh, study=identity) as store:
        if fresh:
            clear_runs(out / "runs")
        with log_to_file(out / "fbia.log", level=LOG_LEVELS[log_level]):
            store.bind(problem, reuse_changed_code=reuse_changed_code)

            def say(line: str) -> None:
                echo(line)
                logger.info(line)

            _write_oct_records(study, out, say)
            return _run_stored(
                study, problem, executor, store, out, started, say, retry_failed, fresh
            )


def _run_draws(
    study: Study,
    out: Path,
    store: Path,
    run_one: Callable[[Study, int], Result],
    echo: Echo,
    started: str,
) -> Result:
    """A study over noise draws (:mod:`fbia.studies.draws`): every draw, then the result over
    them and its comparison with the paper, judged over the draws."""
    from .draws import run_draws

    t0 = time.perf_counter()
    with OutputLock(out, "fbia run"):
        _write_oct_records(study, out, echo)
        result = run_draws(study, out, store, run_one, echo)
        result, text = _finish(study, result, out, started, echo)
        wall = time.perf_counter() - t0
        times = SessionTimes(wall, result.forward_time, result.nfev)
        rows = None
        if study.paper is not None:
            from .draws import judge_draws

            rows = judge_draws(study.paper, result)
        _reports(study, result, out, text, times, echo, rows=rows)
    return result


def _write_oct_records(study: Study, out: Path, echo: Echo) -> None:
    """The record of each OCT scan's segmentation (:class:`~fbia.studies.study_oct.OctRecord`)
    into ``out``, the folder the command writes (``--output``), never while reading the study:
    called holding ``out``'s :class:`OutputLock`, so that a command the lock refuses changes
    none of the files of the run that holds it."""
    for record in study.oct_records:
        record.write(out)
        quality = record.scan.segmentation.quality
        echo(
            f"OCT scan of [[observations]] #{record.observation}: {out / record.folder} "
            f"({record.scan.segmentation.surface_kind}; {quality.note()})"
        )


@dataclass(frozen=True)
class _Session:
    """What the stages of one ``fbia run`` session read, fixed once the evaluator is made
    (:meth:`with_evaluator`: a new session with its description)."""

    study: Study
    problem: InverseProblem
    store: StudyStore
    out: Path
    started: str
    echo: Echo
    executor_info: Mapping[str, Any] = field(default_factory=dict)
    t0: float = field(default_factory=time.perf_counter)

    def with_evaluator(self, described: Mapping[str, Any]) -> _Session:
        """This session with what the evaluator says of itself (workers, a Dask cluster)."""
        return replace(self, executor_info={**self.executor_info, **described})

    def finish(
        self, result: Result, outputs: RunOutputs | None = None, quiet: bool = False
    ) -> tuple[Result, str]:
        return _finish(
            self.study,
            result,
            self.out,
            self.started,
            self.echo,
            self.executor_info,
            quiet=quiet,
            store=self.store,
            outputs=outputs,
        )


def _run_stored(
    study: Study,
    problem: InverseProblem,
    executor: ExecutorSpec,
    store: StudyStore,
    out: Path,
    started: str,
    echo: Echo,
    retry_failed: bool,
    fresh: bool,
) -> Result:
    """The stages of a session: announce, evaluate (saving what was computed on Ctrl-C or an
    error), check the result, save it, add the extra files, save it again."""
    _announce_resume(study, store, echo, retry_failed, fresh)
    session = _Session(study, problem, store, out, started, echo, executor.describe())
    log = EvaluationLog(out / "evaluations.jsonl")
    listener = RunProgress(log, echo)
    echo(
        f"running {study.iterator_name} on {study.model_name} with the {study.measure_name} "
        f"measure ({executor.label()}); evaluations go to {store.path}"
    )
    store.begin_session(session.executor_info, study.sha256)
    try:
        evaluator = evaluator_for(
            executor, out, store=store, listener=listener, retry_failed=retry_failed
        )
    except BaseException as exc:  # bad executor settings: the session ends with the error
        _save_partial(session, log, exc)
        raise
    # the evaluator stays open for the extras: a result's x that no run was made at is run on
    # a worker that is warm (BatchEvaluator.run_aside)
    with evaluator:
        try:
            session = session.with_evaluator(evaluator.describe())
            result = _evaluate(session, executor.kind, evaluator, log)
        except BaseException as exc:  # Ctrl-C or an error: keep what was computed, re-raise
            _save_partial(session, log, exc)
            raise
        store.end_session("done")
        return _after_the_runs(session, result, log, listener, evaluator)


def _after_the_runs(
    session: _Session,
    result: Result,
    log: EvaluationLog,
    listener: RunProgress,
    evaluator: BatchEvaluator,
) -> Result:
    """The stages after the iterator's runs: check the result, save it, add the extra files,
    save it again, report."""
    study, out, echo = session.study, session.out, session.echo
    log.close()
    totals = listener.totals
    echo(
        f"{totals['runs'] + totals['reused']} evaluations: {totals['runs']} run now "
        f"({totals['failed']} failed), {totals['reused']} taken from the store"
    )
    result = _checked(study, result)
    # result.json is written once, with the run record of the extras (files, discrepancy at
    # x, warnings: a plot that fails is reported, never fatal); stopped during the extras,
    # the result is written with what they had made.
    outputs = RunOutputs()
    try:
        for made in _extras(session, result, log, evaluator):
            outputs = made
    except BaseException:
        session.finish(result, outputs, quiet=True)
        raise
    result, text = session.finish(result, outputs)
    wall = time.perf_counter() - session.t0
    times = SessionTimes(wall, _forward_time(result), result.nfev, totals["reused"])
    _reports(study, result, out, text, times, echo, figures=_pngs(outputs.files))
    return result


def _pngs(files: Mapping[str, Any]) -> list[str]:
    """The files of a session's outputs (:class:`RunOutputs`), flat (the report keeps the
    images among them)."""
    flat: list[str] = []
    for v in files.values():
        items = v.values() if isinstance(v, dict) else v if isinstance(v, list) else [v]
        flat += [str(f) for f in items]
    return flat


def _forward_time(result: Result) -> float:
    """The summed wall time of the result's forward runs (stored ones with their own)."""
    return sum(e.time for e in result.evaluations if math.isfinite(e.time))


def _reports(
    study: Study,
    result: Result,
    out: Path,
    text: str,
    times: SessionTimes,
    echo: Echo,
    figures: Sequence[str] = (),
    rows: Sequence[Comparison] | None = None,
) -> None:
    """``paper.json`` (a study with a ``[paper]`` table: :mod:`fbia.studies.paper_report`,
    ``rows`` when judged otherwise, e.g. over noise draws), ``report.md`` and ``report.html``
    (:mod:`fbia.studies.study_report`)."""
    paper: list[str] = []
    title = ""
    if study.paper is not None:  # published numbers beside the result
        from .paper_report import paper_section, paper_title, write_paper_report

        record = write_paper_report(
            study,
            result,
            out,
            times.wall_time,
            reused=times.reused,
            rows=rows,
            forward_time=times.forward_time,
        )
        paper, title = paper_section(record), paper_title(study, record)
    md, page = write_report(
        study, result, out, times, text=text, figures=figures, paper=paper, title=title
    )
    if study.paper is not None:
        echo(f"comparison with {study.paper.source}: {md}")
    echo(f"report: {md} and {page.name}")


def _save_partial(session: _Session, log: EvaluationLog, exc: BaseException) -> None:
    """After Ctrl-C or an error: close the session and write the partial result, as far as
    the machine lets us (a full disk may refuse each step); never raises, so the first
    error is the one the user sees."""
    interrupted = isinstance(exc, KeyboardInterrupt)
    status = "interrupted" if interrupted else "error"
    if isinstance(exc, Terminated):
        message = "stopped by SIGTERM (e.g. a batch system's wall-time limit)"
    elif interrupted:
        message = "stopped by the user (Ctrl-C)"
    else:
        message = f"the iterator stopped with {type(exc).__name__}: {exc}"
    steps: list[tuple[str, Callable[[], object]]] = [
        ("closing the session in the store", lambda: session.store.end_session(status)),
        ("closing the evaluation log", log.close),
        (
            "writing the partial result",
            lambda: session.finish(_partial(session.study, log, status, message), quiet=True),
        ),
    ]
    for what, step in steps:
        try:
            step()
        except Exception as err:
            session.echo(f"warning: {what} failed: {' '.join(str(err).split())}")


def _evaluate(session: _Session, kind: str, evaluator: Any, log: EvaluationLog) -> Any:
    """Drive the iterator with ``evaluator`` (of the executor ``kind``; say where a Dask
    cluster is)."""
    study, echo, info = session.study, session.echo, session.executor_info
    progress = _Progress(echo, log, session.problem.names)
    if kind == "dask":
        where = (
            f"the Dask scheduler at {info['scheduler']}"
            if info["cluster"] == "scheduler"
            else f"a Dask {info['cluster']} cluster ({info['scheduler']})"
        )
        echo(
            f"{where}: {info['workers']} worker thread(s), ready after "
            f"{info['startup_seconds']:.3g} s"
        )
    assert study.iterator is not None
    name = study.iterator_name or ""
    result = _drive(study.iterator, session.problem, evaluator, progress, name)
    progress.last()
    return result


def _checked(study: Study, result: Any) -> Result:
    """The iterator's result (its books are the framework's: :func:`drive`)."""
    if not isinstance(result, Result):
        raise TypeError(
            f"iterator {study.iterator_name!r} returned {type(result).__name__}, not fbia.Result"
        )
    return _oct_verdict(study, result)


def _oct_verdict(study: Study, result: Result) -> Result:
    """``unreliable`` when an observation's OCT segmentation is not one surface (a calibration
    on it matches model vertices to pores: :class:`fbia.imaging.oct_structure.OctQuality`)."""
    notes = [
        f"OCT scan of [[observations]] #{r.observation}: {r.scan.segmentation.quality.note()}"
        for r in study.oct_records
        if not r.scan.segmentation.quality.one_surface
    ]
    if not notes:
        return result
    return replace(result, status="unreliable", message=f"{result.message}; {'; '.join(notes)}")


def _extras(
    session: _Session, result: Result, log: EvaluationLog, evaluator: BatchEvaluator
) -> Iterator[RunOutputs]:
    """The files beside the result, made one after the other: the interfaces and discrepancy
    at the result's x (the stored run at x, or one more forward run where x was not run, e.g.
    a posterior mean), the iterator's own plots, the evaluations plot.
    Yields what has been made so far after each (a new :class:`RunOutputs`, the last one all
    of it), so that a session stopped during them writes its result with what they made; a
    file that fails is a warning in them, never fatal."""
    study, problem, out, echo = session.study, session.problem, session.out, session.echo
    made = RunOutputs()

    def attempt(what: str, make: Callable[[], Any]) -> tuple[Any, str | None]:
        try:
            return make(), None
        except Exception as exc:  # a plugin's plotting or the last run: keep the result
            warning = f"{what} failed: {type(exc).__name__}: {exc}"
            echo(f"warning: {warning}")
            return None, warning

    if result.x and all(n in result.x for n in problem.names):
        stored = _stored_solution(session.store, problem, result.x)
        best = (
            Evaluation(index=0, x=dict(result.x), solution=stored)
            if stored is not None
            else _run_at(evaluator, problem, result.x, out / "best")
        )
        if best.ok and best.solution is not None:
            solution = best.solution
            rows = discrepancy_rows(problem, solution, study.measure_name)
            made = replace(made, discrepancy=rows)
            yield made
            title = f"{study.iterator_name} result"
            written, warning = attempt(
                "writing the interfaces", lambda: _write_solution(study, solution, out, title)
            )
            made = made.adding(written or {}, warning)
        else:
            warning = f"the forward run at the result's x {best.status}: {best.message}"
            echo(f"warning: {warning}")
            made = made.adding({}, warning)
        yield made
    if not study.figures:  # e.g. one noise draw of many (fbia.studies.draws)
        return
    iterator = study.iterator  # its own plots (the base's write_plots makes none)
    assert iterator is not None  # _extras follows the iterator's run
    plots, warning = attempt(
        "the iterator's plots", lambda: iterator.write_plots(result, problem, out / "plots")
    )
    made = made.adding({"iterator plots": [str(p) for p in plots]} if plots else {}, warning)
    yield made
    names, units = problem.names, [p.unit for p in problem.parameters]
    plot, warning = attempt(
        "the evaluations plot",
        lambda: plot_evaluations(
            out / "plots" / "evaluations.png", log.records, names, units, problem.truth
        ),
    )
    yield made.adding({} if plot is None else {"evaluations plot": str(plot)}, warning)


def _stored_solution(
    store: StudyStore, problem: InverseProblem, x: Mapping[str, float]
) -> Solution | None:
    """The solution of the stored run at exactly ``x`` (its interfaces, and its field files
    where its folder is kept), None if the store has no successful run there with every
    state's interface.  The result's own run instead of a repeat of it: the same interfaces
    the iterator compared, and no cold start of the model in this process when the runs were
    made by workers (a 3-D ``ale_fsi`` run: ~20 s against ~3 s warm).  The store is read under
    the binding its runs were made under (the session's, or the iterator's problem, e.g. LM's
    with tangents, which keys runs as ``problem`` does), not bound again."""
    key = store.key({str(n): float(v) for n, v in x.items()})
    run = store.lookup([key]).get(key)
    if run is None or not run.record.ok:
        return None
    solution = store.solution(key)
    if solution is None or not solution.covers(problem.coordinates()):
        return None
    return replace(solution, fields={k: Path(v) for k, v in run.artifacts.items()})


def _run_at(
    evaluator: BatchEvaluator, problem: InverseProblem, x: Mapping[str, float], workdir: Path
) -> Evaluation:
    """A run at ``x`` outside the study's books (``BatchEvaluator.run_aside``), its record
    with the solution (interfaces and field files) the worker sent back."""
    outcome = evaluator.run_aside(problem, x, workdir)
    ev = outcome.record
    if ev.ok and outcome.interfaces is not None:
        fields = {k: Path(v) for k, v in outcome.artifacts.items()}
        ev = replace(ev, solution=Solution(dict(outcome.interfaces), fields, ev.diagnostics))
    return ev


def _announce_resume(
    study: Study, store: StudyStore, echo: Echo, retry_failed: bool, fresh: bool
) -> None:
    """Say what the store already holds and what will be done with it."""
    if fresh:
        echo(f"starting over (--fresh): the store {store.path} was emptied")
    n = len(store)
    others = store.other_models()  # this model's class at other option values
    also = ""
    if others:
        values = "; ".join(v for v, _ in others)
        also = (
            f"{sum(k for _, k in others)} of the same model class with other option values "
            f"({values}), which are not reused"
        )
    if not n:
        if also:
            echo(f"store: {store.path} holds 0 forward runs of this model and {also}")
        return
    failed = n - store.counts().get("ok", 0)
    again = " (failed ones run again: --retry-failed)" if retry_failed and failed else ""
    echo(
        f"resuming: {store.path} holds {n} forward runs of this model ({failed} failed); "
        f"each is reused, not run again{again}{'; it also holds ' + also if also else ''}"
    )
    sessions = store.sessions()
    last = sessions[-1] if sessions else None
    if last is not None and last["study_sha256"] != study.sha256 and not others:
        echo(
            "note: the study file changed since the last run; its model did not, so the "
            "stored forward runs stay valid (compared anew if the measure or data changed)"
        )
    if last is not None and last["status"] == "running":
        echo(f"note: the last run (started {last['started']}) was stopped without a word")


def _drive(
    iterator: Any, problem: InverseProblem, evaluator: Any, progress: _Progress, name: str
) -> Any:
    """Step the iterator's ``steps()`` generator to its end; the books are the framework's
    (:func:`fbia.core.iteration.drive`)."""
    return drive(iterator, problem, evaluator, progress, name)


class _Progress:
    """One line per iterator step, at most one a second: evaluations, failures, best D."""

    def __init__(self, echo: Echo, log: EvaluationLog, names: Sequence[str]) -> None:
        self.echo, self.log, self.names = echo, log, list(names)
        self.t0 = self.shown = time.perf_counter()
        self.steps = 0
        self.pending = False

    def __call__(self, state: Any) -> None:
        self.steps += 1
        self.pending = True
        if time.perf_counter() - self.shown >= 1.0:
            self.show()

    def show(self) -> None:
        best = self.log.best()
        at = f", best D = {best.distance:.4g} at {_point(best.x, self.names)}" if best else ""
        self.echo(
            f"  step {self.steps:4d}  {time.perf_counter() - self.t0:7.1f} s  "
            f"{len(self.log.records)} evaluations ({self.log.n_failed} failed){at}"
        )
        self.shown = time.perf_counter()
        self.pending = False

    def last(self) -> None:
        if self.pending:
            self.show()


def _partial(study: Study, log: EvaluationLog, status: str, message: str) -> Result:
    best = log.best()
    names = [p.name for p in study.parameters]
    return Result(
        status=status,
        success=False,
        message=f"{message} after {len(log.records)} evaluations"
        + (" (x is the best evaluation so far)" if best else ""),
        x={n: best.x[n] for n in names if n in best.x} if best else None,
        nfev=len(log.records),
        n_failed=log.n_failed,
        iterator=study.iterator_name or "",
        evaluations=list(log.records),
    )


def _write_solution(study: Study, solution: Any, out: Path, title: str) -> dict[str, Any]:
    problem = study.problem
    files: dict[str, Any] = {
        "interfaces": [
            str(p) for p in report.write_interfaces(out / "interfaces", problem, solution)
        ]
    }
    fields = report.copy_fields(solution, out / "fields", root=out)
    if fields:
        files["fields"] = {k: str(v) for k, v in fields.items()}
    if not study.figures:
        return files
    png = plot_interfaces(out / "plots" / "interfaces.png", problem, solution, title)
    if png is not None:
        files["interfaces plot"] = str(png)
    return files


def _finish(
    study: Study,
    result: R,
    out: Path,
    started: str,
    echo: Echo,
    executor: Mapping[str, Any] | None = None,
    quiet: bool = False,
    store: StudyStore | None = None,
    outputs: RunOutputs | None = None,
) -> tuple[R, str]:
    """The run record (:class:`RunRecord`: provenance, problem, ``outputs``), written once with
    the result as ``result.json``; the iterator's files; ``report.txt``, echoed unless
    ``quiet``.  Returns the result with its record (a copy: the iterator's result is not
    changed) and the text of ``report.txt``."""
    problem = study.problem
    outputs = outputs or RunOutputs()
    made = make_provenance(
        study_path=study.path.resolve(),
        study_name=study.name,
        study_text=study.text,
        study_sha256=study.sha256,
        study_bases=[{"path": b.path, "text": b.text} for b in study.bases],
        study_overrides=study.overrides,
        seed=study.seed,
        seeds=study_seeds(study),
        executor=executor or {"kind": "serial", "workers": 1},
        plugins=[problem.model, problem.measure, study.iterator],
        started=started,
        finished=now(),
        store=None if store is None else store.describe(),
    )
    result = replace(result, provenance=RunRecord(made, problem.describe(), outputs).to_dict())
    result.save(out / "result.json")
    for path in study.iterator.write_files(result, out) if study.iterator is not None else ():
        echo(f"wrote {path}")
    truth = study.synthetic.truth if study.synthetic is not None else None
    text = report.result_report(study.name, result, out, truth)
    for folder in (out / "run", out / "best", out / "runs"):  # left empty: not worth a folder
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    (out / "report.txt").write_text(text + "\n", encoding="utf-8")
    if not quiet:
        echo(text)
    return result, text


def study_seeds(study: Study) -> dict[str, int | None]:
    """The study's seed and those derived from it: of the synthetic data and the iterator."""
    return {
        "study": study.seed,
        "synthetic": study.synthetic.seed if study.synthetic is not None else None,
        "iterator": None if study.iterator is None else study.iterator.seed,
    }


def _point(x: Mapping[str, float], names: Sequence[str] | None = None) -> str:
    keys = list(names) if names is not None else list(x)
    return ", ".join(f"{k} = {x[k]:.6g}" for k in keys if k in x)


def _failure_word(ev: Evaluation) -> str:
    return {
        "failed": "failed",
        "measure_failed": "could not be compared (measure failed)",
        "error": "raised an error",
    }.get(ev.status, ev.status)
