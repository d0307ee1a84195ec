"""Where the tests' files are: the tests folder (its data/, plugin_pkg/) and the repository
root.  The tests live in sub-folders that mirror the package (core/, execution/, storage/,
imaging/, studies/, plugins/, measures/, iterators/<family>/, testing/); the ones about the
whole package or the examples stay at the top."""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
