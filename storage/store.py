"""The persistent study store: one SQLite file that holds every forward run of a study.

>>> import fbia, tempfile, pathlib
>>> from fbia.storage.store import StudyStore
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

Two layers (:mod:`fbia.storage.fingerprints`): a **forward run** is keyed by what it depends on
(model class, version and every option's effective value, fixed inputs, requested coordinates,
input values) and stored with the interfaces it gave; its **comparison** with the observations
(residuals and distances) is keyed by the measure and the observed data.  The likelihood is not
stored: it is computed from the distances when a run is read (:mod:`fbia.core.likelihood`).  So
a change of σ_N, bounds, priors, iterator or executor reuses every stored run, and a change of
the measure or the observations reuses every forward run and recomputes only its comparison
(from the stored interfaces).  A store holds the runs of one model class, at any option values:
every run records its model part (model key), so binding the store to other option values,
set or a default that changed since the runs were made, adds a model part whose runs are made
anew beside the others, which are kept and not reused (a study that sets their values reuses
them).  Binding it to another model class, version or other fixed inputs is an error that
says what changed.  :func:`len`, :meth:`StudyStore.counts` and :meth:`StudyStore.runs` concern
the model part bound, :meth:`StudyStore.total` every run.

Every run is written in its own transaction the moment it finishes (WAL journal,
``synchronous=NORMAL``: a killed process loses nothing that was committed).  Tables: ``meta``
(format, the model part bound last: its key, fingerprint and the names of its options at their
defaults, the last problem bound, the model's code digest, creation time), ``models`` (every
model part bound: key, fingerprint, options at their defaults, time added), ``sessions`` (one
row per ``fbia run``: start and end, host, pid, fbia version, study file hash, executor,
status), ``runs`` (key, model key, index, session, attempt, x, uncertain, status, message,
wall time, worker, working folder, artifacts, diagnostics, finish time, interfaces as an
``.npz``) and ``comparisons``
(run key, comparison key, status, message, residuals as float64 bytes, distances).  Read it
with any SQLite client, e.g.
``sqlite3 output/store.sqlite "select model, status, count(*) from runs group by 1, 2"``.
Stores of earlier formats (``fbia-store-1``, ``fbia-store-2``) are migrated when opened
(:mod:`fbia.storage.migration`).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import logging
import os
import socket
import sqlite3
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..core.errors import ConfigError, MeasureError, StoreError
from ..core.interface import Interface
from ..core.observation import CoordinateKey, Solution
from ..core.problem import Evaluation, InverseProblem
from .db import connect
from .fingerprints import (
    as_keyed_now,
    canonical,
    code_digest,
    code_digest_as_stored,
    comparison_key,
    comparison_part,
    coordinates_of,
    model_key,
    model_part,
    option_values,
    problem_fingerprint,
    run_key,
    same_model_class,
)
from .interface_blob import pack_interfaces, unpack_interfaces
from .migration import (
    code_change,
    comparison_rekey,
    migrate,
    model_change,
    record_part,
    rekey,
    unknown_defaults,
)
from .output_folder import LockHeld, is_fbia_store, lock_file, this_process

__all__ = ["STORE_FORMAT", "StoreMismatchError", "StoredRun", "StudyStore"]

logger = logging.getLogger(__name__)

#: Written into ``meta``; a store of an unknown format is refused, not misread.
STORE_FORMAT = "fbia-store-3"

SCHEMA = """
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
    executor TEXT NOT NULL,
    study_file TEXT
);
CREATE TABLE IF NOT EXISTS models (
    key TEXT PRIMARY KEY,
    part TEXT NOT NULL,
    defaults TEXT,
    added TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY,
    key TEXT NOT NULL UNIQUE,
    model TEXT,
    idx INTEGER NOT NULL,
    session INTEGER,
    attempt INTEGER NOT NULL DEFAULT 1,
    x TEXT NOT NULL,
    uncertain TEXT NOT NULL,
    status TEXT NOT NULL,
    message TEXT NOT NULL,
    time REAL NOT NULL,
    worker TEXT,
    workdir TEXT,
    artifacts TEXT NOT NULL,
    diagnostics TEXT NOT NULL,
    finished TEXT NOT NULL,
    interfaces BLOB
);
CREATE INDEX IF NOT EXISTS runs_model ON runs (model);
CREATE TABLE IF NOT EXISTS comparisons (
    run_key TEXT NOT NULL,
    comparison TEXT NOT NULL,
    status TEXT NOT NULL,
    message TEXT NOT NULL,
    residuals BLOB,
    distances TEXT,
    PRIMARY KEY (run_key, comparison)
);
"""
_RUN_COLUMNS = (
    "key, idx, session, attempt, x, uncertain, status, message, time, worker, workdir, "
    "artifacts, diagnostics, finished"
)


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _floats(array: np.ndarray | None) -> bytes | None:
    return None if array is None else np.ascontiguousarray(array, dtype="<f8").tobytes()


# -- the store ---------------------------------------------------------------------------------
class StoreMismatchError(ConfigError):
    """The store holds runs of another model (class, version or fixed inputs; options whose
    recorded values cannot be checked), or made by other code of the model plugin."""


@dataclass(frozen=True)
class StoredRun:
    """A finished run as read from the store: the record and what the store adds to it."""

    record: Evaluation
    key: str
    session: int | None
    attempt: int
    worker: str | None
    artifacts: dict[str, str]
    finished: str


@dataclass(frozen=True)
class _Binding:
    """What :meth:`StudyStore.bind` derives from the problem."""

    problem: InverseProblem
    model: dict[str, Any]
    coordinates: list[dict[str, Any]]
    comparison: str
    uncertain: list[str]


class StudyStore:
    """One SQLite file with every forward run of a study (see the module docstring).

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
    study
        The study file of this run (its resolved path) and its SHA-256: every session
        records them, and ``fresh`` refuses a store that holds runs of other study files'
        sessions (studies that name the same store share it): :meth:`check_fresh`.
    """

    def __init__(
        self,
        path: str | Path,
        lock: bool = True,
        fresh: bool = False,
        study: tuple[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        self.study = study
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock: IO[str] | None = self._take_lock() if lock else None
        if fresh and self.path.exists():  # under the lock: no other run is using the file
            if not is_fbia_store(self.path):
                self._release_lock()
                raise ConfigError(
                    "--fresh deletes only an fbia study store, and this file is none (or is "
                    "damaged): move it away yourself",
                    str(self.path),
                )
            try:
                self.check_fresh()
            except ConfigError:
                self._release_lock()
                raise
            for suffix in ("", "-wal", "-shm"):
                Path(f"{self.path}{suffix}").unlink(missing_ok=True)
        try:
            self._db = connect(self.path)  # SQLite errors are one-line StoreErrors
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._open_format()
        except BaseException:
            self.close()
            raise
        #: the model key the store is tied to (None until the first :meth:`bind`)
        self.hash: str | None = self._meta("model_key")
        self.session: int | None = None
        self._binding: _Binding | None = None

    # -- opening ---------------------------------------------------------------------------
    def _take_lock(self) -> IO[str] | None:
        try:
            lock = self.path.with_name(f".{self.path.name}.lock")
            return lock_file(lock, f"fbia run {this_process()}")
        except LockHeld as held:
            raise ConfigError(
                f"the study store is in use by {held.holder}: two runs cannot write one study "
                "at once (wait for it, or give this run another --output)",
                str(self.path),
            ) from None

    def _release_lock(self) -> None:
        if self._lock is not None:
            self._lock.close()  # closing the file releases the flock
            self._lock = None

    def check_fresh(self) -> None:
        """Refuse ``--fresh`` (a ConfigError naming the other study files) when the file
        holds forward runs made by sessions of other study files than :attr:`study`: a
        session with its study file recorded is this study's when it is the same file;
        one without (stores of an fbia that recorded none) when it had the same SHA-256.  Runs are
        keyed by the model, not by the study, so deleting only "this study's" runs has no
        meaning: the user deletes the file by hand, or gives the study a store of its own."""
        if self.study is None:
            return
        db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
        try:
            columns = {row[1] for row in db.execute("PRAGMA table_info(sessions)")}
            file_col = "study_file" if "study_file" in columns else "NULL"
            sha_col = "study_sha256" if "study_sha256" in columns else "NULL"
            rows = db.execute(
                f"SELECT s.{file_col}, s.{sha_col}, count(r.id) FROM sessions s "
                "JOIN runs r ON r.session = s.id GROUP BY s.id"
            ).fetchall()
            total = db.execute("SELECT count(*) FROM runs").fetchone()[0]
        except sqlite3.Error:
            return  # a store too damaged to tell: opening it reports that
        finally:
            db.close()
        mine_file, mine_sha = self.study
        others: dict[str, int] = {}
        for file, sha, n in rows:
            if file == mine_file or (file is None and sha == mine_sha):
                continue
            name = file or "a study file it did not record (an earlier fbia)"
            others[name] = others.get(name, 0) + n
        if others:
            raise ConfigError(
                f"--fresh would delete the runs of other studies too: {sum(others.values())} "
                f"of its {total} forward runs were made by {'; '.join(others)}; give this "
                "study a store of its own ([study] store), or delete the file by hand to start "
                "every study that shares it over",
                str(self.path),
            )

    def _open_format(self) -> None:
        self._db.execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT)")
        fmt = self._meta("format")
        if fmt is not None and fmt != STORE_FORMAT:
            migrate(self._db, self.path, fmt, STORE_FORMAT, SCHEMA)
        else:
            self._db.executescript(SCHEMA)
        if fmt is None:
            with self._transaction() as db:
                db.execute("INSERT OR IGNORE INTO meta VALUES ('format', ?)", (STORE_FORMAT,))
                db.execute("INSERT OR IGNORE INTO meta VALUES ('created', ?)", (_now(),))
        columns = {row[1] for row in self._db.execute("PRAGMA table_info(sessions)")}
        if "study_file" not in columns:  # a store of an fbia that did not record it
            with self._transaction() as db:
                db.execute("ALTER TABLE sessions ADD COLUMN study_file TEXT")

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield self._db
            self._db.execute("COMMIT")  # may fail too (a full disk): then roll back
        except BaseException:
            if self._db.in_transaction:
                with contextlib.suppress(StoreError):
                    self._db.execute("ROLLBACK")
            raise

    def _meta(self, key: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def bind(self, problem: InverseProblem, reuse_changed_code: bool = False) -> str:
        """Tie the store to ``problem``: the first time, record its model; later, check it.

        Returns the model key.  A model part bound before (a study pinning the values of
        earlier runs) is bound again, and its runs are reused.  Other option values of the
        same model class, whether set or a default that changed, add a model part: its runs
        are made anew beside the stored ones, which are kept and not reused
        (:meth:`other_models`).  A store keyed another way is re-keyed where its recorded
        values agree with the current ones (:meth:`_rekey_or_add`).  Raises
        :class:`StoreMismatchError` (a ConfigError) naming what changed when the store holds
        runs of another model class, version or fixed inputs, or runs made by other code of
        the model plugin (its source files changed, :func:`code_digest`) unless
        ``reuse_changed_code``, which waives the code check only.  The measure, the
        observations and the likelihood may differ from earlier sessions.
        """
        if self._binding is not None and self._binding.problem is problem:
            assert self.hash is not None
            return self.hash
        fingerprint = problem_fingerprint(problem)
        model = model_part(fingerprint)
        key = model_key(model)
        code = code_digest(problem.model)
        defaults = canonical(fingerprint["model"]["defaults"])
        parts = self._parts()
        checked = False
        if self.hash is None:
            with self._transaction() as db:
                record_part(db, key, model, defaults)
            self.hash = key
            logger.info("store %s: new, for model %s", self.path, code["class"])
        elif key in parts:  # the part bound last, or another one bound before
            then = parts[key][1]  # None: keyed by an earlier fbia, every option
            with self._transaction() as db:
                record_part(db, key, model, defaults if then is None else canonical(then))
            self.hash = key
        else:
            checked = self._rekey_or_add(
                fingerprint, model, problem, code, parts, reuse_changed_code
            )
        if not checked:
            self._check_code(problem.model, code, reuse_changed_code)
        counts = self.counts()
        if counts:
            logger.info(
                "store %s holds %d runs of model %s (%s); stored runs are reused",
                self.path,
                sum(counts.values()),
                code["class"],
                ", ".join(f"{n} {status}" for status, n in sorted(counts.items())),
            )
        with self._transaction() as db:
            db.execute(
                "INSERT OR REPLACE INTO meta VALUES ('problem', ?)", (canonical(fingerprint),)
            )
            db.execute("INSERT OR REPLACE INTO meta VALUES ('code', ?)", (canonical(code),))
        self._binding = _Binding(
            problem=problem,
            model=model,
            coordinates=coordinates_of(fingerprint),
            comparison=comparison_key(comparison_part(fingerprint)),
            uncertain=list(problem.uncertain_names),
        )
        return key

    def _parts(self) -> dict[str, tuple[dict[str, Any], list[str] | None]]:
        """Every model part bound (key: the part, the names of its options at their defaults
        or None for a part keyed by an earlier fbia), the part bound last first."""
        rows = self._db.execute("SELECT key, part, defaults FROM models ORDER BY rowid").fetchall()
        parts = {str(k): (json.loads(p), None if d is None else json.loads(d)) for k, p, d in rows}
        if self.hash is None:
            return parts
        last = parts.get(self.hash)
        if last is None:  # a part recorded in meta only (a store written by hand)
            then = self._meta("model_defaults")
            last = (
                json.loads(self._meta("model") or "{}"),
                None if then is None else json.loads(then),
            )
        return {self.hash: last, **parts}

    def _rekey_or_add(
        self,
        fingerprint: dict[str, Any],
        model: dict[str, Any],
        problem: InverseProblem,
        code: dict[str, Any],
        parts: Mapping[str, tuple[dict[str, Any], list[str] | None]],
        reuse_changed_code: bool,
    ) -> bool:
        """Re-key a stored model part to ``model`` where, as this fbia keys it
        (:func:`as_keyed_now`), it is ``model``; else add ``model`` as a part of its own
        where a stored part is of the same model class (version and fixed inputs) and differs
        in option values only: the store then holds runs of both, and reuses each part's
        runs for that part only; else refuse the store naming what changed.

        A stored part records every option's value when its defaults are recorded (this
        fbia) or meta ``code`` is not (fbia before it left the defaults out of the keys; the
        fbia in between re-keyed every store it opened and recorded its code): an option it
        lacks was added since, and is re-keyed at its default.  A part of the fbia in between
        records the options that differed from their defaults only: it is re-keyed only while
        the model's code is unchanged since, so that no default can have changed.

        Returns whether the code check (:meth:`_check_code`) was made: before a part is
        added, so that a refused store is left as it was."""
        old = json.loads(self._meta("problem") or "{}")
        recorded = self._meta("code")
        n = self.total()
        key = model_key(model)
        candidates = {}
        for part_key, (stored, then) in parts.items():
            if then is None and recorded is not None:
                was = json.loads(recorded)
                why = unknown_defaults(was, code_digest_as_stored(was, problem.model, code), n)
                if why is not None:
                    raise StoreMismatchError(why, str(self.path))
            candidate = as_keyed_now(stored, problem.model, "model", then)
            candidates[part_key] = candidate
            if model_key(candidate) != key:
                continue
            every_option = then is not None or recorded is None
            pair = comparison_rekey(old, fingerprint, problem.measure) if every_option else None
            with self._transaction() as db:
                rekey(
                    db, stored, coordinates_of(old), model, pair, fingerprint["model"]["defaults"]
                )
            self.hash = key
            logger.info("store %s re-keyed: its model part as this fbia keys it", self.path)
            return False
        others = {k: c for k, c in candidates.items() if same_model_class(c, model)}
        if not others:
            raise StoreMismatchError(model_change(old, fingerprint, n), str(self.path))
        self._check_code(problem.model, code, reuse_changed_code)
        with self._transaction() as db:
            record_part(db, key, model, canonical(fingerprint["model"]["defaults"]))
        self.hash = key
        logger.info(
            "store %s: model %s at other option values (%s): its %d stored runs at the "
            "others are kept and not reused",
            self.path,
            code["class"],
            "; ".join(option_values(c, model) for c in others.values()),
            n,
        )
        return True

    def other_models(self) -> list[tuple[str, int]]:
        """The other model parts of the bound model's class with runs in the store: (how
        their options differ from the bound part's, e.g. ``"gain = 0.5"``, number of runs)."""
        b = self._bound()
        out = []
        for part_key, (stored, then) in self._parts().items():
            if part_key == self.hash:
                continue
            candidate = as_keyed_now(stored, b.problem.model, "model", then)
            if not same_model_class(candidate, b.model):
                continue
            n = self._db.execute(
                "SELECT count(*) FROM runs WHERE model = ?", (part_key,)
            ).fetchone()[0]
            if n:
                out.append((option_values(candidate, b.model), int(n)))
        return out

    def _check_code(self, model: Any, code: dict[str, Any], reuse: bool) -> None:
        text = self._meta("code")
        if text is None:
            return
        old = json.loads(text)
        message = code_change(old, code_digest_as_stored(old, model, code), self.total())
        if message is not None and reuse:
            logger.warning("%s: reused as asked (--reuse-changed-code)", message.split(";")[0])
        elif message is not None:
            raise StoreMismatchError(message, str(self.path))

    @property
    def fingerprint(self) -> dict[str, Any] | None:
        """The fingerprint of the problem last bound (None before the first :meth:`bind`)."""
        text = self._meta("problem")
        return None if text is None else dict(json.loads(text))

    def _bound(self) -> _Binding:
        if self._binding is None:
            raise RuntimeError("bind the store to a problem first")
        return self._binding

    def key(self, x: Mapping[str, float]) -> str:
        """The key of a forward run at ``x`` (the store must be bound to a problem)."""
        b = self._bound()
        return run_key(b.model, b.coordinates, x)

    # -- sessions --------------------------------------------------------------------------
    def begin_session(self, executor: Mapping[str, Any], study_sha256: str | None = None) -> int:
        """Start a session (one ``fbia run``); rows written from now on carry its id."""
        from ..core.version import __version__

        with self._transaction() as db:
            cur = db.execute(
                "INSERT INTO sessions (started, status, host, pid, fbia, study_sha256, executor, "
                "study_file) VALUES (?, 'running', ?, ?, ?, ?, ?, ?)",
                (
                    _now(),
                    socket.gethostname(),
                    os.getpid(),
                    __version__,
                    study_sha256,
                    canonical(dict(executor)),
                    None if self.study is None else self.study[0],
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
                "SELECT count(*) FROM runs WHERE session = ?", (entry["id"],)
            ).fetchone()[0]
            out.append(entry)
        return out

    # -- writing ---------------------------------------------------------------------------
    def put(
        self,
        record: Evaluation,
        key: str | None = None,
        worker: str | None = None,
        artifacts: Mapping[str, str] | None = None,
        interfaces: Mapping[CoordinateKey, Interface] | None = None,
    ) -> None:
        """Write one finished run and its comparison in one transaction (a repeated key is a
        retry: the row is replaced and its ``attempt`` counted up).  ``interfaces``: what the
        forward model gave, kept so that another measure can be applied later; with them the
        run counts as solved and its status is the comparison's."""
        b = self._bound()
        key = key if key is not None else self.key(record.x)
        solved = interfaces is not None or record.ok or record.status == "measure_failed"
        row = (
            key,
            record.index,
            self.session,
            1,
            canonical(record.x),
            canonical({n: record.x[n] for n in b.uncertain if n in record.x}),
            "ok" if solved else record.status,
            "" if solved else record.message,
            float(record.time),
            worker,
            record.workdir,
            canonical(dict(artifacts or {})),
            canonical(record.diagnostics),
            _now(),
        )
        blob = None if interfaces is None else pack_interfaces(interfaces)
        with self._transaction() as db:
            db.execute(
                f"INSERT INTO runs ({_RUN_COLUMNS}, interfaces, model) "
                f"VALUES ({', '.join('?' * (len(row) + 2))}) ON CONFLICT(key) DO UPDATE SET "
                + ", ".join(
                    f"{c} = excluded.{c}"
                    for c in [*_RUN_COLUMNS.split(", "), "interfaces", "model"]
                    if c not in ("key", "attempt")
                )
                + ", attempt = runs.attempt + 1",
                (*row, blob, self.hash),
            )
            db.execute("DELETE FROM comparisons WHERE run_key = ?", (key,))
            if solved:
                self._put_comparison(db, key, record.status, record.message, record)

    def _put_comparison(
        self, db: sqlite3.Connection, key: str, status: str, message: str, record: Evaluation
    ) -> None:
        db.execute(
            "INSERT OR REPLACE INTO comparisons VALUES (?, ?, ?, ?, ?, ?)",
            (
                key,
                self._bound().comparison,
                status,
                message,
                _floats(record.residuals),
                None if record.distances is None else canonical(record.distances),
            ),
        )

    # -- reading ---------------------------------------------------------------------------
    def lookup(self, keys: Iterable[str]) -> dict[str, StoredRun]:
        """The stored runs among ``keys`` with their comparison under the bound problem.

        A solved run without that comparison is compared now, from its stored interfaces,
        and the comparison is stored; one without interfaces (migrated from the first store
        format) is left out, so it runs again.
        """
        wanted = list(dict.fromkeys(keys))
        out: dict[str, StoredRun] = {}
        for start in range(0, len(wanted), 500):
            chunk = wanted[start : start + 500]
            for run in self._select(f"r.key IN ({', '.join('?' * len(chunk))})", chunk):
                out[run.key] = run
        logger.debug("store lookup: %d of %d runs stored", len(out), len(wanted))
        return out

    def solution(self, key: str) -> Solution | None:
        """The stored interfaces (and tangents) of run ``key``; None without them."""
        row = self._db.execute("SELECT interfaces FROM runs WHERE key = ?", (key,)).fetchone()
        return None if row is None or row[0] is None else unpack_interfaces(row[0])

    def runs(self) -> list[StoredRun]:
        """Every stored run of the model part bound with its comparison under the bound
        problem (unbound: the part and problem bound last), in the order first written."""
        return self._select("r.model IS ?", [self.hash])

    def _comparison(self) -> str | None:
        if self._binding is not None:
            return self._binding.comparison
        fingerprint = self.fingerprint
        return None if fingerprint is None else comparison_key(comparison_part(fingerprint))

    def _select(self, where: str, args: Sequence[Any]) -> list[StoredRun]:
        cur = self._db.execute(
            f"SELECT {', '.join('r.' + c for c in _RUN_COLUMNS.split(', '))}, "
            "r.interfaces IS NOT NULL, c.status, c.message, c.residuals, c.distances "
            "FROM runs r LEFT JOIN comparisons c ON c.run_key = r.key AND c.comparison = ? "
            f"WHERE {where} ORDER BY r.id",
            [self._comparison(), *args],
        )
        out = []
        for row in cur.fetchall():
            run = self._run(row)
            if run is None and row[6] == "ok" and row[14] and self._binding is not None:
                run = self._compare_stored(row)
            if run is not None:
                out.append(run)
        return out

    def _compare_stored(self, row: Sequence[Any]) -> StoredRun | None:
        """Compare a stored solved run with the bound problem's observations and keep it."""
        solution = self.solution(str(row[0]))
        assert solution is not None
        record = Evaluation(
            index=int(row[1]), x={k: float(v) for k, v in json.loads(row[4]).items()}
        )
        try:
            record.residuals, record.distances = self._bound().problem.discrepancy(solution)
            if not (
                np.all(np.isfinite(record.residuals)) and np.all(np.isfinite(record.distances))
            ):
                raise ValueError("the measure returned NaN or infinite values")
        except MeasureError as exc:
            record.status, record.message = "measure_failed", str(exc)
            record.residuals = record.distances = None
        except Exception as exc:  # a plugin bug, recorded as the evaluation would record it
            record.status, record.message = "error", f"{type(exc).__name__}: {exc}"
            record.residuals = record.distances = None
        with self._transaction() as db:
            self._put_comparison(db, str(row[0]), record.status, record.message, record)
        row = (*row[:15], record.status, record.message, _floats(record.residuals),
               None if record.distances is None else canonical(record.distances))  # fmt: skip
        return self._run(row)

    @staticmethod
    def _run(row: Sequence[Any]) -> StoredRun | None:
        """A stored run from a joined row; None for a solved run without its comparison."""
        (key, idx, session, attempt, x, _unc, status, message, time, worker, workdir,
         artifacts, diagnostics, finished, _has_interfaces, c_status, c_message, residuals,
         distances) = row  # fmt: skip
        if status == "ok" and c_status is None:
            return None
        solved = status == "ok"
        record = Evaluation(
            index=int(idx),
            x={k: float(v) for k, v in json.loads(x).items()},
            status=str(c_status if solved else status),
            message=str(c_message if solved else message),
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
            artifacts=json.loads(artifacts),
            finished=str(finished),
        )

    def workdir_taken(self, workdir: str | Path) -> bool:
        """Whether a stored run owns this working folder."""
        row = self._db.execute(
            "SELECT 1 FROM runs WHERE workdir = ? LIMIT 1", (str(workdir),)
        ).fetchone()
        return row is not None

    def counts(self) -> dict[str, int]:
        """Number of stored forward runs of the model part bound (unbound: bound last) per
        status (``ok``: the model gave interfaces)."""
        cur = self._db.execute(
            "SELECT status, count(*) FROM runs WHERE model IS ? GROUP BY status", (self.hash,)
        )
        return {str(s): int(n) for s, n in cur.fetchall()}

    def __len__(self) -> int:
        """The number of stored forward runs of the model part bound (unbound: bound last)."""
        row = self._db.execute("SELECT count(*) FROM runs WHERE model IS ?", (self.hash,))
        return int(row.fetchone()[0])

    def total(self) -> int:
        """The number of stored forward runs of every model part."""
        return int(self._db.execute("SELECT count(*) FROM runs").fetchone()[0])

    def describe(self) -> dict[str, Any]:
        """For provenance: path, format, model key, counts per status, sessions."""
        return {
            "path": str(self.path),
            "format": STORE_FORMAT,
            "model_key": self.hash,
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
