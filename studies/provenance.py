"""Provenance: what a result records about how it was made (versions, seeds, machine)."""

from __future__ import annotations

import datetime as _dt
import os
import platform
import socket
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..core.registry import plugin_versions

__all__ = ["now", "provenance", "source_commit"]


def now() -> str:
    """The current time as an ISO 8601 string in UTC (for provenance)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def source_commit() -> str:
    """The git commit of the fbia source that runs (``git rev-parse HEAD`` in the package's
    folder), with ``+dirty`` when tracked files differ from it; "" when fbia is not a git
    checkout (an installed wheel) or git is not there.  What ``paper.json`` records, so that
    the reproductions page says which code made each row."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
        if head.returncode != 0:
            return ""
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


# -- provenance --------------------------------------------------------------------------------
def provenance(
    *,
    study_path: Path | None = None,
    study_name: str | None = None,
    study_text: str | None = None,
    study_sha256: str | None = None,
    study_bases: Sequence[Mapping[str, str]] = (),
    study_overrides: Sequence[str] = (),
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
    distribution, version); the study file's path, text and SHA-256, the texts of the files it
    extends and its ``--set`` changes (the SHA-256 then over all of them); the study's seed and
    every seed derived from it (``seeds``); the executor and its settings; host, platform,
    command line; start and end time (UTC); the store (path, model key, runs per status,
    the sessions that made them: a resumed result tells which runs came from which session).
    """
    import scipy

    from ..core.version import __version__

    return {
        "fbia": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "plugins": plugin_versions(*plugins),
        "study_name": study_name,
        "study_file": None if study_path is None else str(study_path),
        "study_sha256": study_sha256,
        "study_text": study_text,
        # the files the study extends (path, text; nearest first) and its --set changes
        "study_bases": [dict(b) for b in study_bases],
        "study_overrides": list(study_overrides),
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


@dataclass(frozen=True)
class RunOutputs:
    """What a session wrote beside its result: the files, the discrepancy at the result's
    ``x`` (one table row per observation) and the warnings of the extras; a session's extras
    make a new one after each file (:meth:`adding`)."""

    files: Mapping[str, Any] = field(default_factory=dict)
    discrepancy: list[dict[str, Any]] | None = None
    warnings: tuple[str, ...] = ()

    def adding(self, files: Mapping[str, Any], warning: str | None = None) -> RunOutputs:
        """These outputs with more ``files`` and a ``warning`` (None: none)."""
        warnings = self.warnings if warning is None else (*self.warnings, warning)
        return replace(self, files={**self.files, **files}, warnings=warnings)


@dataclass
class RunRecord:
    """What the study runner records beside an iterator's result, written once with it as
    ``result.json``'s ``provenance`` (the iterator's own ``info`` stays the iterator's): how
    the result was made (:func:`provenance`), the problem and the session's outputs."""

    made: dict[str, Any]
    problem: dict[str, Any]
    outputs: RunOutputs = field(default_factory=RunOutputs)

    def to_dict(self) -> dict[str, Any]:
        outputs = self.outputs
        return {
            **self.made,
            "problem": self.problem,
            "files": dict(outputs.files),
            "discrepancy": outputs.discrepancy,
            "warnings": list(outputs.warnings),  # as result.json reads back
        }
