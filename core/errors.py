"""Typed errors of fbia.

``ConfigError`` is bad input: its message says what is wrong and where (file, key), in one
line, so the CLI can print it and exit with status 2.  ``ForwardModelError`` is a forward run
that failed (divergence, mesh distortion, time-out): it is an *outcome*, recorded by the
evaluator, and the iterator decides what it means.  ``MeasureError`` is a discrepancy that
cannot be computed (e.g. a ray that meets nothing).
"""

from __future__ import annotations


class FbiaError(Exception):
    """Base class of all errors fbia raises on purpose."""


class ConfigError(FbiaError, ValueError):
    """Bad input: a study file, an option, a data file or an argument.

    Parameters
    ----------
    message
        What is wrong, in one line.
    where
        Where it is wrong, e.g. ``"study.toml: [[parameters]] E.bounds"``; prefixed to the
        message.
    """

    def __init__(self, message: str, where: str | None = None) -> None:
        self.where = where
        self.reason = message
        super().__init__(f"{where}: {message}" if where else message)

    def located(self, where: str) -> ConfigError:
        """The same error with ``where`` put in front of its current location."""
        inner = f"{where}: {self.where}" if self.where else where
        return ConfigError(self.reason, inner)


class PluginError(ConfigError):
    """A plugin that cannot be registered or found (duplicate or unknown name)."""


class StoreError(FbiaError, OSError):
    """The study store cannot be read or written (a full disk, a read-only or corrupted
    file); the message names the file and what to do, in one line.  What the store held
    before stays as it was: SQLite rolls back the transaction that failed."""


class ForwardModelError(FbiaError, RuntimeError):
    """A forward run failed; ``reason`` is a short machine-readable tag."""

    def __init__(self, message: str, reason: str = "failed") -> None:
        self.reason = reason
        super().__init__(message)


class MeasureError(FbiaError, RuntimeError):
    """A discrepancy could not be computed for a simulated interface (e.g. a ray missed it)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (what a batch system sends at its wall-time limit), raised like Ctrl-C so that
    a study stops its workers and saves what was computed."""
