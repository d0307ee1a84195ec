"""The persistent study store: one SQLite file that holds every evaluation of a study.

>>> import fbia, tempfile, pathlib
>>> from fbia.core.store import StudyStore
>>> model = fbia.forward_model("analytic_mound_2d")
>>> obs = fbia.synthetic_observations(model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}],
...                                   noise_std=0.0, seed=0)
>>> problem = fbia.InverseProblem(model=model, measure=fbia.measure("cpp"), observations=obs,
...     parameters=[fbia.Parameter("E", bounds=(100, 800)),
...                 fbia.Parameter("nu", bounds=(-0.8, 0.5))], noise_std=0.01)
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> with StudyStore(folder / "store.sqlite") as store:
...     _ = store.bind(problem)
...     with fbia.SerialEvaluator(store=store) as ev:
...         first = ev.evaluate(problem, [{"E": 300.0, "nu": 0.2}])
...     with fbia.SerialEvaluator(store=store) as ev:     # a later session: nothing recomputed
...         again = ev.evaluate(problem, [{"E": 300.0, "nu": 0.2}])
...     len(store), again[0].distance == first[0].distance, ev.reused
(1, True, {0})

Every evaluation is one row, written in its own transaction the moment the run finishes (WAL
journal, ``synchronous=NORMAL``: a killed process loses nothing that was committed; only a
power cut or an OS crash may lose the last commits, never the file's consistency).  A row is
found again by its *key*: the SHA-256 of the problem hash and the exact input values
(``repr`` of every float, so equal means bit-equal).  The *problem hash* covers everything that
determines a run's outcome and nothing else (see :func:`problem_fingerprint`): the forward model
(class, version, options), the measure (class, version, options), the observations (their
coordinates, interface and point data, noise), the fixed inputs and the likelihood's noise.
Bounds, priors, the iterator and the executor are left out on purpose: changing them keeps every
stored run valid (e.g. a Sobol design extended from 200 to 400 points reuses the first 200).

Tables: ``meta`` (format, problem hash and fingerprint, creation time), ``sessions`` (one row per
``fbia run``: start and end, host, pid, fbia version, study file hash, executor, status) and
``evaluations`` (key, index, session, attempt, x, uncertain, status, message, residuals as
float64 bytes, distances, distance D, log-likelihood, wall time, worker, working folder,
artifacts, diagnostics, finish time).  Read it with any SQLite client, e.g.
``sqlite3 output/store.sqlite "select status, count(*) from evaluations group by status"``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import importlib.metadata
import json
import math
import os
import socket
import sqlite3
import sys
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from .errors import ConfigError
from .likelihood import gaussian_log_likelihood as _log_likelihood
from .likelihood import measurement_count, noise_levels
from .problem import Evaluation, InverseProblem, _jsonable

__all__ = [
    "STORE_FORMAT",
    "StoreMismatchError",
    "StoredRun",
    "StudyStore",
    "evaluation_key",
    "gaussian_log_likelihood",
    "problem_fingerprint",
    "problem_hash",
]

#: Written into ``meta``; a store of another format is refused, not misread.
STORE_FORMAT = "fbia-store-1"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS sessions (
    id INTEGER PRIMARY KEY,
    started TEXT NOT NULL,
    finished TEXT,
    status TEXT NOT NULL,
    host TEXT NOT NULL,
    pid INTEGER NOT NULL,
    fbia TEXT NOT NULL,
    study_sha256 TEXT,
    executor TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS evaluations (
    id INTEGER PRIMARY KEY,
    key TEXT NOT NULL UNIQUE,
    idx INTEGER NOT NULL,
    session INTEGER,
    attempt INTEGER NOT NULL DEFAULT 1,
    x TEXT NOT NULL,
    uncertain TEXT NOT NULL,
    status TEXT NOT NULL,
    message TEXT NOT NULL,
    residuals BLOB,
    distances TEXT,
    distance REAL,
    log_likelihood REAL,
    time REAL NOT NULL,
    worker TEXT,
    workdir TEXT,
    artifacts TEXT NOT NULL,
    diagnostics TEXT NOT NULL,
    finished TEXT NOT NULL
);
"""
_COLUMNS = (
    "key, idx, session, attempt, x, uncertain, status, message, residuals, distances, distance, "
    "log_likelihood, time, worker, workdir, artifacts, diagnostics, finished"
)


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _canonical(value: Any) -> str:
    """JSON with sorted keys and exact floats (``repr``): equal text means equal content."""
    return json.dumps(_jsonable(value), sort_keys=True, separators=(",", ":"), allow_nan=False)


# -- what determines a run ---------------------------------------------------------------------
def _class_version(obj: Any) -> dict[str, str]:
    """Class path and version of a plugin object: the version of the distribution named like
    its top-level package (``fbia``, ``fbia_mysolver``), else the module's ``__version__``."""
    cls = type(obj)
    top = cls.__module__.split(".")[0]
    try:
        version = importlib.metadata.version(top.replace("_", "-"))
    except importlib.metadata.PackageNotFoundError:
        mod = sys.modules.get(cls.__module__)
        version = str(getattr(mod, "__version__", "unversioned"))
    return {"class": f"{cls.__module__}.{cls.__qualname__}", "version": version}


def _options(obj: Any) -> dict[str, Any]:
    """A plugin's options; a file option (a ``Path``, e.g. ``mesh_file``) by its content."""
    opts = getattr(obj, "options", None)
    dump = getattr(opts, "model_dump", None)
    if not callable(dump):
        return {}
    out = dict(_jsonable(dump(mode="json")))
    for key, value in dump().items():
        if isinstance(value, Path):
            out[key] = _file_digest(value)
    return out


def _file_digest(path: Path) -> dict[str, Any]:
    """File name and SHA-256 of its bytes: moving a study folder keeps a store valid, editing
    the mesh file it names does not."""
    try:
        data = path.read_bytes()
    except OSError:
        return {"file": str(path), "sha256": None}
    return {"file": path.name, "sha256": hashlib.sha256(data).hexdigest()}


def _digest(*arrays: Any) -> str | None:
    arrays = tuple(a for a in arrays if a is not None)
    if not arrays:
        return None
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def problem_fingerprint(problem: InverseProblem) -> dict[str, Any]:
    """Everything that determines the outcome of one forward run and its comparison.

    Parts: ``model`` and ``measure`` (class, version, options), ``observations`` (per
    observation: coordinate, SHA-256 of the interface's vertices and cells and of the
    measurement points and directions, noise_std), ``fixed`` inputs and the likelihood's
    ``noise_std`` (the stored log-likelihood depends on it).  Parameter bounds and priors, the
    iterator and the executor are not part of it: they choose *which* runs are made, not what
    a run gives.
    """
    observations = []
    for obs in problem.observations:
        gamma = obs.interface
        mp = obs.measurement_points
        observations.append(
            {
                "coordinate": dict(obs.coordinate),
                "interface": None if gamma is None else _digest(gamma.vertices, gamma.cells),
                "points": None if mp is None else _digest(mp.points, mp.directions),
                "noise_std": obs.noise_std,
            }
        )
    return {
        "model": {**_class_version(problem.model), "options": _options(problem.model)},
        "measure": {**_class_version(problem.measure), "options": _options(problem.measure)},
        "observations": observations,
        "fixed": dict(problem.fixed),
        "noise_std": problem.noise_std,
    }


def problem_hash(fingerprint: Mapping[str, Any]) -> str:
    """SHA-256 of the canonical JSON of a :func:`problem_fingerprint`."""
    return hashlib.sha256(_canonical(fingerprint).encode()).hexdigest()


def evaluation_key(problem_sha: str, x: Mapping[str, float]) -> str:
    """The store key of one run: SHA-256 of the problem hash and the exact input values."""
    values = {str(k): float(v) for k, v in x.items()}
    return hashlib.sha256(f"{problem_sha}\n{_canonical(values)}".encode()).hexdigest()


def _describe_change(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """What differs between two fingerprints, in words (at most a few items per part)."""

    def values(a: Any, b: Any) -> str:
        text = f"{json.dumps(a)} -> {json.dumps(b)}"
        return text if len(text) <= 60 else text[:57] + "..."

    changes: list[str] = []
    for part in ("model", "measure"):
        a, b = old.get(part, {}), new.get(part, {})
        if a == b:
            continue
        if a.get("class") != b.get("class"):
            changes.append(f"{part} {a.get('class')} -> {b.get('class')}")
            continue
        if a.get("version") != b.get("version"):
            changes.append(f"{part} version {values(a.get('version'), b.get('version'))}")
        oa, ob = a.get("options", {}), b.get("options", {})
        keys = sorted(k for k in {*oa, *ob} if oa.get(k) != ob.get(k))
        if keys:
            shown = ", ".join(f"{k}: {values(oa.get(k), ob.get(k))}" for k in keys[:3])
            more = f" and {len(keys) - 3} more" if len(keys) > 3 else ""
            changes.append(f"{part} options ({shown}{more})")
    oa, ob = old.get("observations", []), new.get("observations", [])
    if len(oa) != len(ob):
        changes.append(f"number of observations {len(oa)} -> {len(ob)}")
    else:
        for k, (a, b) in enumerate(zip(oa, ob, strict=True)):
            what = [f for f in ("coordinate", "interface", "points", "noise_std") if a[f] != b[f]]
            if what:
                changes.append(f"observation {k + 1} ({', '.join(what)})")
    if old.get("fixed") != new.get("fixed"):
        changes.append(f"fixed inputs {values(old.get('fixed'), new.get('fixed'))}")
    if old.get("noise_std") != new.get("noise_std"):
        changes.append(f"likelihood noise_std {values(old.get('noise_std'), new.get('noise_std'))}")
    return changes or ["the problem description"]


# -- the likelihood stored with every run ------------------------------------------------------
def gaussian_log_likelihood(
    record: Evaluation, sigmas: Sequence[float] | None, count: int | None = None
) -> float | None:
    """Paper B eq. (5) of one record (:mod:`fbia.core.likelihood`), None without noise levels."""
    return None if sigmas is None else _log_likelihood(record, sigmas, count)


# -- the store ---------------------------------------------------------------------------------
class StoreMismatchError(ConfigError):
    """The store was made for another problem (model, measure, observations, ...)."""


@dataclass(frozen=True)
class StoredRun:
    """A finished run as read from the store: the record and what the store adds to it."""

    record: Evaluation
    key: str
    session: int | None
    attempt: int
    worker: str | None
    log_likelihood: float | None
    artifacts: dict[str, str]
    finished: str


class StudyStore:
    """One SQLite file with every evaluation of a study (see the module docstring).

    Parameters
    ----------
    path
        The database file (created with its folder if missing).
    lock
        Take an exclusive lock (a hidden file ``.<name>.lock`` beside it) so that two
        ``fbia run`` cannot write into one study at once; released when the store is closed
        or the process ends.
    fresh
        Delete what the file holds first (``fbia run --fresh``).
    """

    def __init__(self, path: str | Path, lock: bool = True, fresh: bool = False) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock: IO[str] | None = self._take_lock() if lock else None
        if fresh:  # under the lock: no other run is using the file
            for suffix in ("", "-wal", "-shm"):
                Path(f"{self.path}{suffix}").unlink(missing_ok=True)
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
            self._check_format()
        except sqlite3.DatabaseError as exc:
            self._release_lock()
            raise ConfigError(f"not a readable fbia store ({exc})", str(self.path)) from None
        self.hash: str | None = self._meta("problem_hash")
        self.session: int | None = None
        self._sigmas: list[float] | None = None
        self._uncertain: list[str] = []
        self._bound: list[InverseProblem] = []

    # -- opening ---------------------------------------------------------------------------
    def _take_lock(self) -> IO[str] | None:
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            return None
        lock = self.path.with_name(f".{self.path.name}.lock")
        fh = open(lock, "a+", encoding="utf-8")  # held open until close: the lock lives with it
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            who = fh.read().strip() or "another process"
            fh.close()
            raise ConfigError(
                f"the study store is in use by {who}: two runs cannot write one study at once "
                "(wait for it, or give this run another --output)",
                str(self.path),
            ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"fbia run pid {os.getpid()} on {socket.gethostname()}\n")
        fh.flush()
        return fh

    def _release_lock(self) -> None:
        if self._lock is not None:
            self._lock.close()  # closing the file releases the flock
            self._lock = None

    def _check_format(self) -> None:
        fmt = self._meta("format")
        if fmt is None:
            with self._transaction() as db:
                db.execute("INSERT OR IGNORE INTO meta VALUES ('format', ?)", (STORE_FORMAT,))
                db.execute("INSERT OR IGNORE INTO meta VALUES ('created', ?)", (_now(),))
        elif fmt != STORE_FORMAT:
            raise ConfigError(f"store format {fmt!r}, this fbia reads {STORE_FORMAT!r}")

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield self._db
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    def _meta(self, key: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def bind(self, problem: InverseProblem) -> str:
        """Tie the store to ``problem``: the first time, record its hash; later, check it.

        Returns the problem hash.  Raises :class:`StoreMismatchError` (a ConfigError) naming
        what changed when the store holds runs of a different problem.
        """
        if any(p is problem for p in self._bound):
            assert self.hash is not None
            return self.hash
        fingerprint = problem_fingerprint(problem)
        sha = problem_hash(fingerprint)
        if self.hash is None:
            with self._transaction() as db:
                db.execute("INSERT INTO meta VALUES ('problem_hash', ?)", (sha,))
                db.execute("INSERT INTO meta VALUES ('problem', ?)", (_canonical(fingerprint),))
            self.hash = sha
        elif sha != self.hash:
            old = json.loads(self._meta("problem") or "{}")
            n = len(self)
            raise StoreMismatchError(
                f"the store holds {n} evaluation{'s' if n != 1 else ''} of a different problem "
                f"(changed: {'; '.join(_describe_change(old, fingerprint))}); they cannot be "
                "reused: run with --fresh to start over, or write to another --output",
                str(self.path),
            )
        self._bound.append(problem)
        self._sigmas = noise_levels(problem)
        self._count = measurement_count(problem)
        self._uncertain = list(problem.uncertain_names)
        return sha

    @property
    def fingerprint(self) -> dict[str, Any] | None:
        """The stored problem fingerprint (None before the first :meth:`bind`)."""
        text = self._meta("problem")
        return None if text is None else dict(json.loads(text))

    def key(self, x: Mapping[str, float]) -> str:
        """The key of a run at ``x`` (the store must be bound to a problem)."""
        if self.hash is None:
            raise RuntimeError("bind the store to a problem first")
        return evaluation_key(self.hash, x)

    # -- sessions --------------------------------------------------------------------------
    def begin_session(self, executor: Mapping[str, Any], study_sha256: str | None = None) -> int:
        """Start a session (one ``fbia run``); rows written from now on carry its id."""
        from .version import __version__

        with self._transaction() as db:
            cur = db.execute(
                "INSERT INTO sessions (started, status, host, pid, fbia, study_sha256, executor) "
                "VALUES (?, 'running', ?, ?, ?, ?, ?)",
                (
                    _now(),
                    socket.gethostname(),
                    os.getpid(),
                    __version__,
                    study_sha256,
                    _canonical(dict(executor)),
                ),
            )
        self.session = int(cur.lastrowid or 0)
        return self.session

    def end_session(self, status: str) -> None:
        """Close the current session with ``status`` (done, interrupted, error)."""
        if self.session is None:
            return
        with self._transaction() as db:
            db.execute(
                "UPDATE sessions SET finished = ?, status = ? WHERE id = ?",
                (_now(), status, self.session),
            )
        self.session = None

    def sessions(self) -> list[dict[str, Any]]:
        """Every session, oldest first (a killed one keeps status ``running``)."""
        cur = self._db.execute("SELECT * FROM sessions ORDER BY id")
        names = [d[0] for d in cur.description]
        out = []
        for row in cur.fetchall():
            entry = dict(zip(names, row, strict=True))
            entry["executor"] = json.loads(entry["executor"])
            entry["evaluations"] = self._db.execute(
                "SELECT count(*) FROM evaluations WHERE session = ?", (entry["id"],)
            ).fetchone()[0]
            out.append(entry)
        return out

    # -- writing and reading ---------------------------------------------------------------
    def put(
        self,
        record: Evaluation,
        key: str | None = None,
        worker: str | None = None,
        artifacts: Mapping[str, str] | None = None,
    ) -> None:
        """Write one finished run in its own transaction (a repeated key is a retry: the row
        is replaced and its ``attempt`` counted up)."""
        key = key if key is not None else self.key(record.x)
        residuals = (
            None
            if record.residuals is None
            else np.ascontiguousarray(record.residuals, dtype="<f8").tobytes()
        )
        distance = record.distance
        loglik = gaussian_log_likelihood(record, self._sigmas, self._count)
        row = (
            key,
            record.index,
            self.session,
            1,
            _canonical(record.x),
            _canonical({n: record.x[n] for n in self._uncertain if n in record.x}),
            record.status,
            record.message,
            residuals,
            None if record.distances is None else _canonical(record.distances),
            distance if math.isfinite(distance) else None,
            None if loglik is None or not math.isfinite(loglik) else loglik,
            float(record.time),
            worker,
            record.workdir,
            _canonical(dict(artifacts or {})),
            _canonical(record.diagnostics),
            _now(),
        )
        with self._transaction() as db:
            db.execute(
                f"INSERT INTO evaluations ({_COLUMNS}) VALUES ({', '.join('?' * len(row))}) "
                "ON CONFLICT(key) DO UPDATE SET "
                + ", ".join(
                    f"{c} = excluded.{c}"
                    for c in _COLUMNS.split(", ")
                    if c not in ("key", "attempt")
                )
                + ", attempt = evaluations.attempt + 1",
                row,
            )

    def lookup(self, keys: Iterable[str]) -> dict[str, StoredRun]:
        """The stored runs among ``keys`` (missing keys are left out)."""
        wanted = list(dict.fromkeys(keys))
        out: dict[str, StoredRun] = {}
        for start in range(0, len(wanted), 500):
            chunk = wanted[start : start + 500]
            cur = self._db.execute(
                f"SELECT {_COLUMNS} FROM evaluations WHERE key IN ({', '.join('?' * len(chunk))})",
                chunk,
            )
            for row in cur.fetchall():
                run = self._run(row)
                out[run.key] = run
        return out

    def runs(self) -> list[StoredRun]:
        """Every stored run, in the order they were first written."""
        cur = self._db.execute(f"SELECT {_COLUMNS} FROM evaluations ORDER BY id")
        return [self._run(row) for row in cur.fetchall()]

    def records(self) -> list[Evaluation]:
        """Every stored record, in the order they were first written."""
        return [r.record for r in self.runs()]

    @staticmethod
    def _run(row: Sequence[Any]) -> StoredRun:
        (key, idx, session, attempt, x, _unc, status, message, residuals, distances, _dist,
         loglik, time, worker, workdir, artifacts, diagnostics, finished) = row  # fmt: skip
        record = Evaluation(
            index=int(idx),
            x={k: float(v) for k, v in json.loads(x).items()},
            status=str(status),
            message=str(message),
            residuals=None if residuals is None else np.frombuffer(residuals, dtype="<f8").copy(),
            distances=None if distances is None else [float(d) for d in json.loads(distances)],
            time=float(time),
            workdir=workdir,
            diagnostics=json.loads(diagnostics),
        )
        return StoredRun(
            record=record,
            key=str(key),
            session=session,
            attempt=int(attempt),
            worker=worker,
            log_likelihood=-math.inf if loglik is None and status != "ok" else loglik,
            artifacts=json.loads(artifacts),
            finished=str(finished),
        )

    def workdir_taken(self, workdir: str | Path) -> bool:
        """Whether a stored run owns this working folder."""
        row = self._db.execute(
            "SELECT 1 FROM evaluations WHERE workdir = ? LIMIT 1", (str(workdir),)
        ).fetchone()
        return row is not None

    def counts(self) -> dict[str, int]:
        """Number of stored runs per status."""
        cur = self._db.execute("SELECT status, count(*) FROM evaluations GROUP BY status")
        return {str(s): int(n) for s, n in cur.fetchall()}

    def __len__(self) -> int:
        return int(self._db.execute("SELECT count(*) FROM evaluations").fetchone()[0])

    def describe(self) -> dict[str, Any]:
        """For provenance: path, problem hash, counts per status, sessions."""
        return {
            "path": str(self.path),
            "format": STORE_FORMAT,
            "problem_hash": self.hash,
            "evaluations": len(self),
            "by_status": self.counts(),
            "sessions": self.sessions(),
        }

    # -- closing ---------------------------------------------------------------------------
    def close(self) -> None:
        if getattr(self, "_db", None) is not None:
            self._db.close()
            self._db = None  # type: ignore[assignment]
        self._release_lock()

    def __enter__(self) -> StudyStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
