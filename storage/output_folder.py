"""What fbia may do in an output folder: one writer at a time, and ``--fresh`` deletes only
what fbia made.

The output path of a study may be any folder (``../`` included), so nothing here trusts the
path: a command that writes a folder holds its lock (``.fbia.lock``), so that ``fbia forward``
cannot truncate the log or replace the ``result.json`` of a study that is running there, and
``--fresh`` deletes only an fbia study store and run folders by fbia's own names
(``eval_000012``, ``eval_000012-2``).
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import sqlite3
from pathlib import Path
from typing import IO

from ..core.errors import ConfigError

__all__ = ["LOCK_NAME", "LockHeld", "OutputLock", "clear_runs", "is_fbia_store", "lock_file"]

#: the lock file a writing command holds in its output folder
LOCK_NAME = ".fbia.lock"

_RUN_FOLDER = re.compile(r"eval_\d{6,}(-\d+)?")


class LockHeld(Exception):
    """Another process holds the lock; ``holder`` is what it wrote into the lock file."""

    def __init__(self, holder: str) -> None:
        super().__init__(holder)
        self.holder = holder


def this_process() -> str:
    """``pid <n> on <host>``: who holds a lock."""
    return f"pid {os.getpid()} on {socket.gethostname()}"


def lock_file(path: Path, holder: str) -> IO[str] | None:
    """Take an exclusive lock (``flock``) on the file ``path`` and write ``holder`` into it;
    the lock lives as long as the returned handle is open (None where there are no POSIX
    locks).  Raises :class:`LockHeld` naming the process that has it."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        return None
    fh = open(path, "a+", encoding="utf-8")  # held open until released
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.seek(0)
        who = fh.read().strip() or "another fbia process"
        fh.close()
        raise LockHeld(who) from None
    fh.seek(0)
    fh.truncate()
    fh.write(f"{holder}\n")
    fh.flush()
    return fh


class OutputLock:
    """An exclusive lock on an output folder for one command (``fbia run``, ``fbia
    forward``), held until :meth:`release` or the end of the process; a ConfigError names
    the process that holds it."""

    def __init__(self, folder: Path, command: str) -> None:
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        try:
            self._fh = lock_file(folder / LOCK_NAME, f"{command} ({this_process()})")
        except LockHeld as held:
            raise ConfigError(
                f"the output folder is in use by {held.holder}; {command} would overwrite its "
                "files (wait for it, or give --output another folder)",
                str(folder),
            ) from None

    def release(self) -> None:
        if self._fh is not None:
            self._fh.close()  # closing the file releases the flock
            self._fh = None

    def __enter__(self) -> OutputLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def is_fbia_store(path: Path) -> bool:
    """Whether ``path`` is an SQLite file with an fbia store's ``meta`` table."""
    try:
        with open(path, "rb") as fh:
            if fh.read(16) != b"SQLite format 3\x00":
                return False
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            row = db.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()
        finally:
            db.close()
    except (OSError, sqlite3.Error):
        return False
    return row is not None and str(row[0]).startswith("fbia-store-")


def clear_runs(runs: Path) -> int:
    """Delete the run folders fbia made in ``runs`` (named ``eval_<index>[-<n>]``) and
    ``runs`` itself if nothing else is left; returns how many were deleted."""
    if not runs.is_dir():
        return 0
    gone = 0
    for child in runs.iterdir():
        if child.is_dir() and not child.is_symlink() and _RUN_FOLDER.fullmatch(child.name):
            shutil.rmtree(child, ignore_errors=True)
            gone += 1
    try:
        runs.rmdir()  # only if empty
    except OSError:
        pass
    return gone
