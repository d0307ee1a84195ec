"""Issue 14, defect 4: a full disk, a damaged or a read-only store is one line naming the file
and what to do (exit 1), never a traceback, and nothing stored before is lost.

A full disk is made real with a file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored) on a
subprocess: SQLite's writes then fail as they do on a full disk.
"""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import textwrap

import pytest
from _studies import write_study

from fbia.core.errors import StoreError
from fbia.storage.db import store_error
from fbia.storage.store import StudyStore

_FULL_DISK = textwrap.dedent(
    """
    import resource, signal, sys
    limit = int(sys.argv[1])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    from fbia.studies.cli import main
    sys.exit(main(sys.argv[2:]))
    """
)


def _run(tmp_path, *argv: str, limit: int | None = None) -> subprocess.CompletedProcess[str]:
    (tmp_path / "full.py").write_text(_FULL_DISK)
    head = ["full.py", str(limit)] if limit else ["-m", "fbia.studies.cli"]
    return subprocess.run(
        [sys.executable, *head, *argv], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )


def _one_line(proc: subprocess.CompletedProcess[str]) -> str:
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fbia: error: "), proc.stderr
    return lines[0]


def test_a_full_disk_is_one_line_and_the_stored_runs_are_resumed(tmp_path):
    write_study(tmp_path)
    full = _run(tmp_path, "run", "study.toml", limit=200_000)
    assert full.returncode == 1
    line = _one_line(full)
    assert "out/store.sqlite" in line and "disk" in line and "resume" in line
    with StudyStore(tmp_path / "out" / "store.sqlite") as store:
        kept = len(store)
    assert kept > 0
    again = _run(tmp_path, "run", "study.toml")
    assert again.returncode == 0, again.stderr
    assert f"holds {kept} forward runs" in again.stdout


def test_a_damaged_store_is_one_line(tmp_path):
    write_study(tmp_path)
    assert _run(tmp_path, "run", "study.toml").returncode == 0
    path = tmp_path / "out" / "store.sqlite"
    with open(path, "r+b") as fh:  # overwrite pages past the header
        fh.seek(8192)
        fh.write(b"\x13" * 16384)
    damaged = _run(tmp_path, "run", "study.toml")
    assert damaged.returncode == 1
    assert "store.sqlite: the store is damaged" in _one_line(damaged)


def test_a_file_that_is_no_database_is_one_line(tmp_path):
    write_study(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "store.sqlite").write_bytes(bytes(range(256)) * 64)
    proc = _run(tmp_path, "run", "study.toml")
    assert proc.returncode == 1
    assert "the store is damaged (file is not a database)" in _one_line(proc)


@pytest.mark.parametrize(
    ("sqlite_message", "advice"),
    [
        ("attempt to write a readonly database", "read-only"),
        ("database or disk is full", "is the disk full"),
        ("database disk image is malformed", "damaged"),
    ],
)
def test_sqlite_errors_say_what_to_do(tmp_path, sqlite_message, advice):
    err = store_error(tmp_path / "s.sqlite", sqlite3.OperationalError(sqlite_message))
    assert isinstance(err, StoreError) and isinstance(err, OSError)
    assert str(err).startswith(f"{tmp_path / 's.sqlite'}: ") and advice in str(err)
