"""Opening a study store of an earlier format: migrated in place, with a copy of the original.

Format ``fbia-store-1`` keyed every run by a hash of the whole problem (model, measure,
observations and the likelihood's σ_N) and kept no interfaces.  Its runs become format-2 runs
keyed by what a forward run depends on (:func:`fbia.storage.fingerprints.run_key`, computed from
the stored problem fingerprint), each with its comparison under the stored measure and
observations; the stored log-likelihoods are dropped (the likelihood is computed on read).  So
after the migration a change of σ_N reuses every run.  A change of the measure or of the
observations reruns the migrated runs, since format 1 kept no interfaces to compare anew.

Format ``fbia-store-2`` held the runs of one model part (meta ``model_key``); format 3 records
each run's model key (``runs.model``) and every model part bound (table ``models``), so that
runs of one model class at other option values share a store: a format-2 store's runs get its
model key.

The original file is copied first (``VACUUM INTO <name>.v1.sqlite``, ``.v2``); the migration
is one transaction, so an interrupted migration leaves the store as it was.

:func:`rekey` carries a store's runs over to the model part this fbia keys them by (every
option's effective value, :func:`fbia.storage.fingerprints.as_keyed_now`): same runs, new
keys, where the stored values agree with the current ones.  A store keyed by the options that
differed from their defaults (fbia before issue 44) says nothing of the values its runs had
for the others: it is re-keyed only while the model's code is unchanged since, so that no
default can have changed (:func:`unknown_defaults` says why not otherwise).
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError
from .fingerprints import (
    as_keyed_now,
    canonical,
    comparison_key,
    comparison_part,
    coordinates_of,
    describe_change,
    model_key,
    model_part,
    run_key,
)

__all__ = [
    "code_change",
    "comparison_rekey",
    "migrate",
    "model_change",
    "record_part",
    "rekey",
    "unknown_defaults",
]

_V1_COLUMNS = (
    "key, idx, session, attempt, x, uncertain, status, message, residuals, distances, "
    "time, worker, workdir, artifacts, diagnostics, finished"
)


def migrate(db: sqlite3.Connection, path: Path, found: str, target: str, schema: str) -> int:
    """Bring the store at ``path`` (open as ``db``) from format ``found`` to ``target``;
    returns the number of runs carried over."""
    steps = {"fbia-store-1": [_v1_to_v2, _v2_to_v3], "fbia-store-2": [_v2_to_v3]}
    if found not in steps or target != "fbia-store-3":
        raise ConfigError(f"store format {found!r}, this fbia reads {target!r}", str(path))
    version = found.rsplit("-", 1)[1]
    backup = path.with_name(f"{path.stem}.v{version}{path.suffix}")
    if not backup.exists():
        db.execute("VACUUM INTO ?", (str(backup),))
    db.execute("BEGIN IMMEDIATE")
    try:
        n = 0
        for step in steps[found]:
            n = step(db, schema)
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


def _v2_to_v3(db: sqlite3.Connection, schema: str) -> int:
    """Format 2 held the runs of one model part (meta ``model_key``); format 3 records each
    run's model key (column ``runs.model``) and every model part bound (table ``models``),
    so that runs of one model class at other option values can share the store."""
    columns = {row[1] for row in db.execute("PRAGMA table_info(runs)")}
    if "model" not in columns:
        db.execute("ALTER TABLE runs ADD COLUMN model TEXT")
    for statement in schema.split(";"):
        if statement.strip():
            db.execute(statement)
    meta = dict(db.execute("SELECT key, value FROM meta").fetchall())
    key = meta.get("model_key")
    if key is not None:
        db.execute("UPDATE runs SET model = ? WHERE model IS NULL", (key,))
        db.execute(
            "INSERT OR IGNORE INTO models VALUES (?, ?, ?, ?)",
            (key, meta.get("model", "{}"), meta.get("model_defaults"), meta.get("created", "")),
        )
    db.execute("UPDATE meta SET value = 'fbia-store-3' WHERE key = 'format'")
    return int(db.execute("SELECT count(*) FROM runs").fetchone()[0])


def rekey(
    db: sqlite3.Connection,
    old_model: dict[str, Any],
    coordinates: list[dict[str, Any]],
    new_model: dict[str, Any],
    comparisons: tuple[str, str] | None = None,
    defaults: Sequence[str] | None = None,
) -> int:
    """Give every run stored under ``old_model`` (at ``coordinates``) its key under
    ``new_model``, and the comparisons stored under the comparison key ``comparisons[0]``
    the key ``comparisons[1]``, in the caller's transaction; runs stored under other
    coordinates keep their keys.  ``defaults``: the names of ``new_model``'s options at their
    defaults, recorded as meta ``model_defaults``, which says that the part keys every
    option's value; None removes it (a part keyed by the options that differ from their
    defaults, as fbia before issue 44 wrote it).  Returns the number of runs re-keyed."""
    n = 0
    old_key, new_key = model_key(old_model), model_key(new_model)
    for key, x in db.execute("SELECT key, x FROM runs").fetchall():
        values = json.loads(x)
        if run_key(old_model, coordinates, values) != key:
            continue
        new = run_key(new_model, coordinates, values)
        db.execute("UPDATE runs SET key = ?, model = ? WHERE key = ?", (new, new_key, key))
        db.execute("UPDATE comparisons SET run_key = ? WHERE run_key = ?", (new, key))
        n += 1
    if comparisons is not None and comparisons[0] != comparisons[1]:
        db.execute(
            "UPDATE OR IGNORE comparisons SET comparison = ? WHERE comparison = ?",
            (comparisons[1], comparisons[0]),
        )
    db.execute("INSERT OR REPLACE INTO meta VALUES ('model_key', ?)", (new_key,))
    db.execute("INSERT OR REPLACE INTO meta VALUES ('model', ?)", (canonical(new_model),))
    recorded = None if defaults is None else canonical(defaults)
    if recorded is None:
        db.execute("DELETE FROM meta WHERE key = 'model_defaults'")
    else:
        db.execute("INSERT OR REPLACE INTO meta VALUES ('model_defaults', ?)", (recorded,))
    db.execute("DELETE FROM models WHERE key = ?", (old_key,))
    db.execute(
        "INSERT OR REPLACE INTO models VALUES (?, ?, ?, datetime('now'))",
        (new_key, canonical(new_model), recorded),
    )
    return n


def record_part(db: sqlite3.Connection, key: str, model: dict[str, Any], defaults: str) -> None:
    """Register the model part ``model`` under ``key`` in table ``models`` (a part registered
    before keeps its place and the names of its options at their defaults, ``defaults`` as
    JSON) and make it the part bound last (meta), in the caller's transaction."""
    db.execute(
        "INSERT INTO models VALUES (?, ?, ?, datetime('now')) ON CONFLICT(key) DO UPDATE SET "
        "defaults = coalesce(models.defaults, excluded.defaults)",
        (key, canonical(model), defaults),
    )
    db.execute("INSERT OR REPLACE INTO meta VALUES ('model_key', ?)", (key,))
    db.execute("INSERT OR REPLACE INTO meta VALUES ('model', ?)", (canonical(model),))
    db.execute(
        "INSERT OR REPLACE INTO meta VALUES ('model_defaults', "
        "(SELECT defaults FROM models WHERE key = ?))",
        (key,),
    )


def comparison_rekey(
    old: dict[str, Any], new: dict[str, Any], measure: Any
) -> tuple[str, str] | None:
    """(old, new) comparison key when the stored problem fingerprint ``old`` compares as
    ``new`` does with the ``measure``'s options as this fbia keys them
    (:func:`~fbia.storage.fingerprints.as_keyed_now`); else None, and the stored runs are
    compared anew from their interfaces.  The caller passes only a fingerprint that records
    every option's value (a measure's default may have changed since one that records the
    options differing from their defaults was written, and its code is not digested)."""
    if not old:
        return None
    stored = comparison_part(old)
    target = comparison_key(comparison_part(new))
    defaults = old["measure"].get("defaults")
    if comparison_key(as_keyed_now(stored, measure, "measure", defaults)) != target:
        return None
    return comparison_key(stored), target


def code_change(old: dict[str, Any], code: dict[str, Any], n: int) -> str | None:
    """Why a store's ``n`` runs, made by the model code ``old`` (a :func:`code_digest`), are
    not reused by the code ``code`` (None: they are), naming the files that changed.  A
    digest of fbia before per-file digests names a folder, and is compared with ``code`` of
    the same kind (:func:`code_digest_as_stored`)."""
    if n == 0 or old.get("class") != code["class"] or old.get("sha256") == code["sha256"]:
        return None
    released = old.get("version") is not None and old.get("version") != code.get("version")
    if released and code.get("numerics") is not None and old.get("numerics") == code["numerics"]:
        return None  # another release of the package, same declared numerics: its author's word
    return (
        f"the store holds {n} run{'s' if n != 1 else ''} made by other code of the model "
        f"plugin {code['class']} (its source changed since: "
        f"{_changed_files(old.get('files'), code['files'])}); they are not "
        "reused silently: run with --fresh to start over, or with --reuse-changed-code if "
        "the change leaves the results as they were"
    )


def _changed_files(old: Any, new: dict[str, str] | str, most: int = 6) -> str:
    """The files whose SHA-256 differ between two code digests' ``files``, added and removed
    ones marked (the folder, for a digest of fbia before per-file digests)."""
    if isinstance(new, str):
        return new
    was: dict[str, str] = old if isinstance(old, dict) else {}

    def marked(f: str) -> str:
        return f if f in was and f in new else f"{f} (added)" if f in new else f"{f} (removed)"

    names = [f for f in sorted({*was, *new}) if was.get(f) != new.get(f)]
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(marked(f) for f in names[:most]) + more if names else "its files"


def unknown_defaults(old: Mapping[str, Any], code: Mapping[str, Any], n: int) -> str | None:
    """Why the ``n`` runs of a store keyed by the options that differed from their defaults
    (fbia before issue 44), made by the model code ``old`` (a :func:`code_digest`), cannot
    be given keys with every option's value by the code ``code`` (None: they can).  Only
    unchanged code says that no default changed since: a new release with the same declared
    numerics and ``--reuse-changed-code`` vouch for the numbers, not for the defaults a study
    relies on."""
    if n == 0 or old.get("class") != code["class"] or old.get("sha256") == code["sha256"]:
        return None
    return (
        f"the store holds {n} run{'s' if n != 1 else ''} keyed by an earlier fbia by the "
        "options that differed from their defaults only, and the source of the model plugin "
        f"{code['class']} changed since ({_changed_files(old.get('files'), code['files'])}): "
        "whether a default they relied on changed cannot be checked, so they are not reused: "
        "run with --fresh to start over, or write to another --output (or run once with the "
        "plugin's code that made them, which records every option's value)"
    )


def model_change(
    old: dict[str, Any], new: dict[str, Any], n: int, pins: Mapping[str, Any] | None = None
) -> str:
    """Why a store's ``n`` runs of the problem fingerprint ``old`` are not reused for ``new``;
    ``pins``: the model options (name: the runs' value) that differ only because this study
    takes their defaults, which setting them to the runs' values would reuse."""
    pin = ""
    if pins:
        values = ", ".join(f"{k} = {json.dumps(v)}" for k, v in sorted(pins.items()))
        pin = f"set {values} in the model's options to reuse them, "
    return (
        f"the store holds {n} run{'s' if n != 1 else ''} of a different model "
        f"(changed: {'; '.join(describe_change(old, new))}); they cannot be "
        f"reused: {pin}run with --fresh to start over, or write to another --output"
    )
