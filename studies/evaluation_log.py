"""The evaluation log of a study session: ``evaluations.jsonl``, one JSON line per record."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, TextIO

from ..core.problem import Evaluation, jsonable

__all__ = ["EvaluationLog"]


# -- the evaluation log ------------------------------------------------------------------------
class EvaluationLog:
    """Append-only log of evaluation records, one JSON object per line (``evaluations.jsonl``).

    Each record is written and flushed the moment it is handed over, so a study that stops
    (error, Ctrl-C, kill) keeps every evaluation that finished.  Opening a log truncates an
    existing file: the log is one session's readable copy; the study store
    (:class:`~fbia.storage.store.StudyStore`) is what a resumed study reads.

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
        line = json.dumps(jsonable({**record.to_dict(), **extra}), allow_nan=False, default=str)
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
