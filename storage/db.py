"""The SQLite connection of a study store: every SQLite error becomes a one-line
:class:`~fbia.core.errors.StoreError` that names the file and says what to do.

A full disk, a read-only file or folder and a damaged file are facts about the machine, not
bugs: the user needs to know which file, what happened and whether anything was lost (no:
SQLite rolls back the transaction that failed, so the store keeps every run it held).

>>> import tempfile, pathlib
>>> db = connect(pathlib.Path(tempfile.mkdtemp()) / "s.sqlite")
>>> db.execute("SELECT 1").fetchone()
(1,)
>>> try:
...     db.execute("SELECT * FROM nowhere")
... except StoreError as exc:
...     print(str(exc).split(": ", 1)[1])
reading or writing failed (no such table: nowhere)
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..core.errors import StoreError

__all__ = ["StoreConnection", "connect", "store_error"]


def store_error(path: Path, exc: sqlite3.Error) -> StoreError:
    """``exc`` as a StoreError on ``path``, with what to do."""
    text = str(exc)
    low = text.lower()
    if "disk is full" in low or "disk i/o" in low:
        what = (
            f"the store could not be written ({text}): is the disk full? The runs stored "
            "so far are kept; free space and run again to resume"
        )
    elif "readonly" in low or "read-only" in low or "unable to open" in low:
        what = (
            f"the store cannot be written ({text}): the file or its folder is read-only; "
            "make it writable or give the run another --output"
        )
    elif "malformed" in low or "not a database" in low or "corrupt" in low:
        what = (
            f"the store is damaged ({text}); move it away (the study then starts over) or "
            "restore it from a copy"
        )
    else:
        what = f"reading or writing failed ({text})"
    return StoreError(f"{path}: {what}")


class StoreConnection(sqlite3.Connection):
    """A connection whose statements and fetches raise StoreError instead of sqlite3.Error."""

    path: Path

    def execute(self, sql: str, parameters: Any = (), /) -> Any:
        try:
            return _Cursor(super().execute(sql, parameters), self.path)
        except sqlite3.Error as exc:
            raise store_error(self.path, exc) from None

    def executescript(self, sql_script: str, /) -> Any:
        try:
            return super().executescript(sql_script)
        except sqlite3.Error as exc:
            raise store_error(self.path, exc) from None


class _Cursor:
    """A cursor whose fetches raise StoreError (a damaged page shows up when it is read)."""

    def __init__(self, cursor: sqlite3.Cursor, path: Path) -> None:
        self._cursor, self._path = cursor, path

    @property
    def lastrowid(self) -> int | None:
        return self._cursor.lastrowid

    @property
    def description(self) -> Any:
        return self._cursor.description

    def fetchone(self) -> Any:
        try:
            return self._cursor.fetchone()
        except sqlite3.Error as exc:
            raise store_error(self._path, exc) from None

    def fetchall(self) -> list[Any]:
        try:
            return self._cursor.fetchall()
        except sqlite3.Error as exc:
            raise store_error(self._path, exc) from None

    def __iter__(self) -> Iterator[Any]:
        return iter(self.fetchall())


def connect(path: Path) -> StoreConnection:
    """Open (or create) the SQLite file at ``path`` for a store (autocommit mode: the store
    opens its transactions itself)."""
    try:
        db = sqlite3.connect(
            path, isolation_level=None, check_same_thread=False, factory=StoreConnection
        )
    except sqlite3.Error as exc:
        raise store_error(path, exc) from None
    assert isinstance(db, StoreConnection)
    db.path = path
    return db
