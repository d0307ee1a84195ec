"""Fixtures shared by the test modules (helpers without pytest live in _models.py and
_studies.py)."""

from __future__ import annotations

import pytest
from _studies import write_study


@pytest.fixture
def study_file(tmp_path, monkeypatch):
    """The small valid study of _studies.py in a fresh working folder (the current one)."""
    monkeypatch.chdir(tmp_path)
    return write_study(tmp_path)
