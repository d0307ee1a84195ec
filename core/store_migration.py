"""Opening a study store of an earlier format: migrated in place, with a copy of the original.

Format ``fbia-store-1`` keyed every run by a hash of the whole problem (model, measure,
observations and the likelihood's σ_N) and kept no interfaces.  Its runs become format-2 runs
keyed by what a forward run depends on (:func:`fbia.core.fingerprints.run_key`, computed from
the stored problem fingerprint), each with its comparison under the stored measure and
observations; the stored log-likelihoods are dropped (the likelihood is computed on read).  So
after the migration a change of σ_N reuses every run.  A change of the measure or of the
observations reruns the migrated runs, since format 1 kept no interfaces to compare anew.

The original file is copied first (``VACUUM INTO <name>.v1.sqlite``); the migration is one
transaction, so an interrupted migration leaves the format-1 store as it was.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from .errors import ConfigError
from .fingerprints import (
    canonical,
    comparison_key,
    comparison_part,
    coordinates_of,
    model_key,
    model_part,
    run_key,
)

__all__ = ["migrate"]

_V1_COLUMNS = (
    "key, idx, session, attempt, x, uncertain, status, message, residuals, distances, "
    "time, worker, workdir, artifacts, diagnostics, finished"
)


def migrate(db: sqlite3.Connection, path: Path, found: str, target: str, schema: str) -> int:
    """Bring the store at ``path`` (open as ``db``) from format ``found`` to ``target``;
    returns the number of runs carried over."""
    if found != "fbia-store-1" or target != "fbia-store-2":
        raise ConfigError(f"store format {found!r}, this fbia reads {target!r}", str(path))
    backup = path.with_name(f"{path.stem}.v1{path.suffix}")
    if not backup.exists():
        db.execute("VACUUM INTO ?", (str(backup),))
    db.execute("BEGIN IMMEDIATE")
    try:
        n = _v1_to_v2(db, schema)
    except BaseException:
        db.execute("ROLLBACK")
        raise
    db.execute("COMMIT")
    return n


def _v1_to_v2(db: sqlite3.Connection, schema: str) -> int:
    row = db.execute("SELECT value FROM meta WHERE key = 'problem'").fetchone()
    rows = db.execute(f"SELECT {_V1_COLUMNS} FROM evaluations ORDER BY id").fetchall()
    db.execute("ALTER TABLE evaluations RENAME TO evaluations_v1")
    for statement in schema.split(";"):
        if statement.strip():
            db.execute(statement)
    if row is not None:
        fingerprint = json.loads(row[0])
        model = model_part(fingerprint)
        coordinates = coordinates_of(fingerprint)
        comparison = comparison_key(comparison_part(fingerprint))
        db.execute("INSERT OR REPLACE INTO meta VALUES ('model_key', ?)", (model_key(model),))
        db.execute("INSERT OR REPLACE INTO meta VALUES ('model', ?)", (canonical(model),))
        for (_, idx, session, attempt, x, uncertain, status, message, residuals, distances,
             time, worker, workdir, artifacts, diagnostics, finished) in rows:  # fmt: skip
            key = run_key(model, coordinates, json.loads(x))
            solved = status in ("ok", "measure_failed")
            db.execute(
                "INSERT INTO runs (key, idx, session, attempt, x, uncertain, status, message, "
                "time, worker, workdir, artifacts, diagnostics, finished, interfaces) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, NULL)",
                (key, idx, session, attempt, x, uncertain, "ok" if solved else status,
                 "" if solved else message, time, worker, workdir, artifacts, diagnostics,
                 finished),
            )  # fmt: skip
            if solved:
                db.execute(
                    "INSERT INTO comparisons VALUES (?, ?, ?, ?, ?, ?)",
                    (key, comparison, status, message, residuals, distances),
                )
    db.execute("DELETE FROM meta WHERE key = 'problem_hash'")
    db.execute("UPDATE meta SET value = 'fbia-store-2' WHERE key = 'format'")
    db.execute("DROP TABLE evaluations_v1")
    return len(rows)
