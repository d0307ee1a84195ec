"""What a study writes: the evaluation log, progress, provenance, interfaces, tables and plots.

Everything that goes into a study's output folder is written here or by the study store
(:mod:`fbia.core.store`)::

    output/
      store.sqlite          every forward run of every session (the reference; see fbia.core.store)
      evaluations.jsonl     this session's records, one JSON line each, as the iterator gets them
                            (runs reused from the store included, marked "reused": true)
      fbia.log              what was printed, one line per record and batch, per session
      runs/                 one working folder per run (failed runs' kept; all with keep_runs)
      result.json           the Result (status, message, x, history, provenance, evaluations)
      report.txt            the summary and the discrepancy table printed at the end
      interfaces/           observed and simulated interfaces: CSV (2-D) and VTU (2-D, 3-D)
      plots/                interfaces.png, evaluations.png, and the iterator's own plots

>>> rows = [{"observation": "inflow_rate=100", "measure": "cpp", "D": 0.0012,
...          "n_residuals": 81, "max_abs_r": 0.004}]
>>> print(format_table(rows))
observation      measure  D       n_residuals  max_abs_r
---------------  -------  ------  -----------  ---------
inflow_rate=100  cpp      0.0012  81           0.004
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import os
import platform
import re
import shutil
import socket
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .interface import Interface
from .observation import Coordinate, Observation, Solution
from .problem import Evaluation, InverseProblem, _jsonable
from .registry import plugin_versions

__all__ = [
    "EvaluationLog",
    "RunProgress",
    "log_to_file",
    "discrepancy_rows",
    "format_table",
    "now",
    "plot_evaluations",
    "plot_interfaces",
    "provenance",
    "state_label",
    "write_interfaces",
]


def now() -> str:
    """The current time as an ISO 8601 string in UTC (for provenance)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


# -- the evaluation log ------------------------------------------------------------------------
class EvaluationLog:
    """Append-only log of evaluation records, one JSON object per line (``evaluations.jsonl``).

    Each record is written and flushed the moment it is handed over, so a study that stops
    (error, Ctrl-C, kill) keeps every evaluation that finished.  Opening a log truncates an
    existing file: the log is one session's readable copy; the study store
    (:class:`~fbia.core.store.StudyStore`) is what a resumed study reads.

    Parameters
    ----------
    path
        The JSONL file to write.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh: TextIO | None = self.path.open("w", encoding="utf-8")
        self.records: list[Evaluation] = []

    def append(self, record: Evaluation, **extra: Any) -> None:
        """Write one record (its index, x, status, message, residuals, D, time, workdir) and
        any ``extra`` keys (e.g. ``reused``, ``worker``)."""
        self.records.append(record)
        if self._fh is None:
            raise ValueError(f"evaluation log {self.path} is closed")
        line = json.dumps(_jsonable({**record.to_dict(), **extra}), allow_nan=False, default=str)
        self._fh.write(line + "\n")
        self._fh.flush()

    @property
    def n_failed(self) -> int:
        return sum(1 for r in self.records if not r.ok)

    def best(self) -> Evaluation | None:
        """The successful record with the smallest distance D, if any."""
        ok = [r for r in self.records if r.ok and math.isfinite(r.distance)]
        return min(ok, key=lambda r: r.distance) if ok else None

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> EvaluationLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- provenance --------------------------------------------------------------------------------
def provenance(
    *,
    study_path: Path | None = None,
    study_text: str | None = None,
    study_sha256: str | None = None,
    seed: int | None = None,
    seeds: Mapping[str, Any] | None = None,
    executor: Mapping[str, Any] | None = None,
    plugins: Sequence[Any] = (),
    started: str | None = None,
    finished: str | None = None,
    store: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Everything needed to tell later how a result was made.

    fbia, Python, numpy and scipy versions; the plugins used (registry name, class,
    distribution, version); the study file's path, text and SHA-256; the study's seed and
    every seed derived from it (``seeds``); the executor and its settings; host, platform,
    command line; start and end time (UTC); the store (path, model key, runs per status,
    the sessions that made them: a resumed result tells which runs came from which session).
    """
    import scipy

    from .version import __version__

    return {
        "fbia": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "plugins": plugin_versions(*plugins),
        "study_file": None if study_path is None else str(study_path),
        "study_sha256": study_sha256,
        "study_text": study_text,
        "seed": seed,
        "seeds": dict(seeds or {}),
        "executor": dict(executor or {}),
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "pid": os.getpid(),
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]] if sys.argv else [],
        "started": started,
        "finished": finished,
        "store": None if store is None else dict(store),
    }


# -- progress and the log file -----------------------------------------------------------------
@contextmanager
def log_to_file(path: Path, name: str = "fbia") -> Iterator[logging.Logger]:
    """Append the ``fbia`` logger's records (INFO and up) to ``path`` while inside."""
    logger = logging.getLogger(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    previous = logger.level
    logger.setLevel(logging.INFO)
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

    Every record goes to ``evaluations.jsonl`` (with ``reused`` and ``worker``) and to the log
    file.  On a terminal, a batch with runs to make shows a progress bar (done / failed /
    running, ETA; tqdm) that disappears when the batch is done.  Elsewhere (a file, a batch
    job's output) a batch that lasts longer than ``interval`` seconds gets a plain line every
    ``interval`` seconds (done, failed, running, time left) and one when it ends; quick
    batches print nothing.

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
        self.logger = logging.getLogger("fbia")
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
        self.logger.info(
            "batch %d: %d points, %d from the store, %d to run on %d worker(s)",
            self.batch,
            total,
            reused,
            to_run,
            self.slots,
        )
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
            self.logger.info(
                "eval %d %s (from the store)%s", record.index, record.status, _brief(record)
            )
            return
        self.totals["runs"] += 1
        self.done += 1
        self.failed += not record.ok
        self.totals["failed"] += not record.ok
        self.logger.info(
            "eval %d %s in %.3g s on %s%s",
            record.index,
            record.status,
            record.time,
            worker or "?",
            _brief(record),
        )
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


def _brief(record: Evaluation) -> str:
    if record.ok:
        return f", D = {record.distance:.6g}"
    return f": {record.message}" if record.message else ""


# -- interfaces --------------------------------------------------------------------------------
def state_label(coordinate: Coordinate) -> str:
    """A file-name-safe label of a coordinate, e.g. ``inflow_rate_100``."""
    if not coordinate:
        return "state"
    text = "_".join(f"{k}_{float(v):g}" for k, v in coordinate.items())
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", text)


def write_interfaces(
    folder: Path,
    problem: InverseProblem,
    solution: Solution | None,
    observed: bool = True,
) -> list[Path]:
    """Write the observed and the simulated interface of every state of ``problem``.

    2-D interfaces go to CSV (x, y, curve) and VTU, 3-D ones to VTU; measurement points to
    CSV.  Returns the paths written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def put(gamma: Interface, stem: str) -> None:
        if gamma.dim == 2:
            written.append(gamma.write(folder / f"{stem}.csv"))
        written.append(gamma.write(folder / f"{stem}.vtu"))

    labels = _observation_labels(problem.observations)
    if observed:
        for obs, label in zip(problem.observations, labels, strict=True):
            if obs.interface is not None:
                put(obs.interface, f"observed_{label}")
            mp = obs.measurement_points
            if mp is not None:
                written.append(mp.write(folder / f"points_{label}.csv"))
    if solution is not None:
        for coord in problem.coordinates():
            put(solution.interface(coord), f"simulated_{state_label(coord)}")
    return written


def _observation_labels(observations: Sequence[Observation]) -> list[str]:
    labels: list[str] = []
    for k, obs in enumerate(observations):
        label = state_label(obs.coordinate)
        if label in labels:
            label = f"{label}_{k}"
        labels.append(label)
    return labels


# -- tables ------------------------------------------------------------------------------------
def discrepancy_rows(
    problem: InverseProblem, solution: Solution, measure_name: str = ""
) -> list[dict[str, Any]]:
    """One row per observation: measure, distance D, number of residuals, max |r|, RMS of r.

    The RMS of r is Paper A's err_res (eq. 25) for that observation alone.
    """
    name = measure_name or type(problem.measure).__name__
    rows = []
    for obs in problem.observations:
        simulated = solution.interface(obs.coordinate)
        r = np.asarray(problem.measure.residuals(simulated, obs), dtype=float).ravel()
        d = float(problem.measure.distance(simulated, obs))
        rows.append(
            {
                "observation": obs.label(),
                "measure": name,
                "D": d,
                "n_residuals": int(r.size),
                "max_abs_r": float(np.max(np.abs(r))) if r.size else math.nan,
                "rms_r": float(np.sqrt(np.mean(r**2))) if r.size else math.nan,
            }
        )
    return rows


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """A plain-text table with a header line; floats in 6 significant digits."""
    if not rows:
        return "(no rows)"
    cols = list(columns) if columns is not None else list(rows[0])
    cells = [[_fmt(row.get(c, "")) for c in cols] for row in rows]
    widths = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(cols)]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)).rstrip(),
        "  ".join("-" * w for w in widths),
    ]
    for r in cells:
        lines.append("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    return "\n".join(lines)


def _fmt(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return "" if value is None else str(value)
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    return str(value)


# -- plots -------------------------------------------------------------------------------------
def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_interfaces(
    path: Path, problem: InverseProblem, solution: Solution | None, title: str = ""
) -> Path | None:
    """Observed (and simulated) 2-D interfaces of every state in one figure; None for 3-D."""
    if problem.dim != 2:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for k, obs in enumerate(problem.observations):
        colour = f"C{k % 10}"
        if obs.interface is not None:
            for j, curve in enumerate(obs.interface.curves()):
                ax.plot(
                    curve[:, 0],
                    curve[:, 1],
                    ".",
                    ms=3,
                    color=colour,
                    label=f"observed {obs.label()}" if j == 0 else None,
                )
        mp = obs.measurement_points
        if mp is not None:
            ax.plot(mp.points[:, 0], mp.points[:, 1], "x", color=colour, ms=5)
        if solution is not None:
            gamma = solution.interface(obs.coordinate)
            for j, curve in enumerate(gamma.curves()):
                ax.plot(
                    curve[:, 0],
                    curve[:, 1],
                    "-",
                    lw=1.2,
                    color=colour,
                    label=f"simulated {obs.label()}" if j == 0 else None,
                )
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_evaluations(
    path: Path, records: Sequence[Evaluation], names: Sequence[str], units: Sequence[str] = ()
) -> Path | None:
    """Distance D of every evaluation in order (log scale), and for two parameters the
    evaluated points in parameter space coloured by log10 D (failed runs as red crosses)."""
    if not records:
        return None
    plt = _pyplot()
    two = len(names) == 2
    fig, axes = plt.subplots(1, 2 if two else 1, figsize=(10 if two else 5.5, 4), squeeze=False)
    ok = [r for r in records if r.ok and r.distance > 0 and math.isfinite(r.distance)]
    bad = [r for r in records if not r.ok]
    ax = axes[0, 0]
    ax.semilogy([r.index for r in ok], [r.distance for r in ok], ".", ms=4)
    ax.set_xlabel("evaluation")
    ax.set_ylabel("D")
    ax.set_title(f"{len(records)} evaluations, {len(bad)} failed", fontsize=9)
    if two:
        units = list(units) + [""] * 2
        ax = axes[0, 1]
        x0 = [r.x.get(names[0], math.nan) for r in ok]
        x1 = [r.x.get(names[1], math.nan) for r in ok]
        sc = ax.scatter(x0, x1, c=np.log10([r.distance for r in ok]), s=10, cmap="viridis")
        fig.colorbar(sc, ax=ax, label="log10 D")
        if bad:
            ax.plot(
                [r.x.get(names[0], math.nan) for r in bad],
                [r.x.get(names[1], math.nan) for r in bad],
                "x",
                color="red",
                label="failed",
            )
            ax.legend(fontsize=8)
        ax.set_xlabel(f"{names[0]} [{units[0]}]" if units[0] else names[0])
        ax.set_ylabel(f"{names[1]} [{units[1]}]" if units[1] else names[1])
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def copy_fields(solution: Solution, folder: Path, root: Path | None = None) -> dict[str, Path]:
    """Copy the field files of a solution into ``folder``, unless they already lie below
    ``root`` (the output folder); files that a model named but did not write are left out."""
    out: dict[str, Path] = {}
    for name, src in solution.fields.items():
        src = Path(src)
        if not src.exists():
            continue
        if root is not None and src.resolve().is_relative_to(root.resolve()):
            out[name] = src
            continue
        folder.mkdir(parents=True, exist_ok=True)
        dst = folder / src.name
        if src.is_dir():
            shutil.copytree(src, dst, dirs_exist_ok=True)
        else:
            shutil.copy2(src, dst)
        out[name] = dst
    return out


def result_report(
    name: str, result: Any, output: Path, truth: Mapping[str, float] | None = None
) -> str:
    """The text printed at the end of a study and saved as ``report.txt``: the result's own
    ``summary()`` (iterator-specific: e.g. the multi-start table of Levenberg-Marquardt), the
    ground truth of synthetic data, and the discrepancy table at the result's ``x``."""
    lines = [f"== {name} ==", result.summary()]
    if truth:
        lines.append(
            "  ground truth of the synthetic data: "
            + ", ".join(f"{k} = {v:.6g}" for k, v in truth.items())
        )
    rows = result.info.get("discrepancy")
    if rows:
        where = "at x" if result.iterator else "of the forward run"
        lines += ["", f"discrepancy {where}:", format_table(rows)]
    lines += ["", f"output: {output}"]
    return "\n".join(lines)
