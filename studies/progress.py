"""Progress of a study on the terminal, and ``fbia.log``: the ``fbia`` loggers' records.

The lines of ``fbia.log`` come from the modules that do the work, each on its own logger
(``fbia.execution.evaluator``: every batch and run, with the failure's reason;
``fbia.storage.store``: what a store holds and reuses; ``fbia.iterators.surrogates.gp``: GP
fits; ``fbia.iterators.gp_smc.adaptive_loop``: design rounds; ``fbia.iterators.smc.sampler``:
tempering; ``fbia.core.iteration``: an iterator's steps), and from what the study prints
(``fbia.studies.runner``)."""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..core.problem import Evaluation
from .evaluation_log import EvaluationLog

__all__ = ["LOG_FORMAT", "RunProgress", "log_to_file"]

#: a line of fbia.log: time, level, the logger's name (the module), the message
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


# -- progress and the log file -----------------------------------------------------------------
@contextmanager
def log_to_file(
    path: Path, name: str = "fbia", level: int = logging.INFO
) -> Iterator[logging.Logger]:
    """Append the ``fbia`` loggers' records (``level`` and up) to ``path`` while inside, each
    line with its logger's name."""
    logger = logging.getLogger(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter(LOG_FORMAT))
    previous = logger.level
    logger.setLevel(level)
    logger.addHandler(handler)
    try:
        yield logger
    finally:
        logger.removeHandler(handler)
        handler.close()
        logger.setLevel(previous)


def _duration(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


class RunProgress:
    """What a study shows and logs while forward runs go on (an evaluator's ``listener``).

    Every record goes to ``evaluations.jsonl`` (with ``reused`` and ``worker``; the evaluator
    logs it, :mod:`fbia.execution.evaluator`).  On a terminal, a batch with runs to make
    shows a progress bar (done / failed / running, ETA; tqdm) that disappears when the batch
    is done.  Elsewhere (a file, a batch job's output) a batch that lasts longer than
    ``interval`` seconds gets a plain line every ``interval`` seconds (done, failed,
    running, time left) and one when it ends; quick batches print nothing.

    Parameters
    ----------
    log
        The session's evaluation log.
    echo
        Where plain lines go (print).
    tty
        Show bars (default: whether stderr is a terminal).
    interval
        Seconds between plain progress lines.
    """

    def __init__(
        self,
        log: EvaluationLog,
        echo: Callable[[str], None] = print,
        tty: bool | None = None,
        interval: float = 10.0,
    ) -> None:
        self.log = log
        self.echo = echo
        self.tty = sys.stderr.isatty() if tty is None else tty
        self.interval = interval
        self.batch = 0
        self.totals = {"runs": 0, "reused": 0, "failed": 0}
        self._bar: Any = None
        self._lines = 0
        self.to_run = self.slots = self.done = self.failed = self.reused = 0
        self.t0 = self.shown = time.perf_counter()

    def batch_started(self, total: int, reused: int, to_run: int, slots: int) -> None:
        self.batch += 1
        self.to_run, self.slots, self.done, self.failed = to_run, max(1, slots), 0, 0
        self.reused = reused
        self.t0 = self.shown = time.perf_counter()
        self._lines = 0
        if to_run and self.tty:
            from tqdm import tqdm

            self._bar = tqdm(
                total=to_run,
                desc=f"batch {self.batch}",
                unit="run",
                leave=False,
                dynamic_ncols=True,
                file=sys.stderr,
            )
            self._bar.set_postfix_str(self._counts(), refresh=True)

    def _counts(self) -> str:
        running = min(self.slots, self.to_run - self.done)
        stored = f", {self.reused} from the store" if self.reused else ""
        return f"failed {self.failed}, running {running}{stored}"

    def eta(self) -> float | None:
        """Seconds left in this batch, from the pace of the finished runs (None before one)."""
        if not self.done:
            return None
        return (time.perf_counter() - self.t0) / self.done * (self.to_run - self.done)

    def record(self, record: Evaluation, reused: bool, worker: str | None) -> None:
        self.log.append(record, reused=reused, worker=worker)
        if reused:
            self.totals["reused"] += 1
            return
        self.totals["runs"] += 1
        self.done += 1
        self.failed += not record.ok
        self.totals["failed"] += not record.ok
        if self._bar is not None:
            self._bar.set_postfix_str(self._counts(), refresh=False)
            self._bar.update(1)
        elif time.perf_counter() - self.shown >= self.interval:
            self.line()

    def line(self) -> str:
        """Echo (and return) the plain progress line of the batch."""
        eta = self.eta()
        left = (
            f", about {_duration(eta)} left" if eta is not None and self.done < self.to_run else ""
        )
        text = f"  batch {self.batch}: {self.done}/{self.to_run} runs done, {self._counts()}{left}"
        self.echo(text)
        self.shown = time.perf_counter()
        self._lines += 1
        return text

    def batch_finished(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._lines:
            self.line()
