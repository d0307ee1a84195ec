"""The pytest plugin of fbia (entry point ``pytest11: fbia``): the fixtures of the
conformance kit :mod:`fbia.testing`.

pytest imports this module at the start of every session in an environment where fbia is
installed, so it imports only pytest; the kit is imported by the fixture that is used.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from .core.registry import Registry
    from .testing import MeasureCase, PluginInstaller


@pytest.fixture
def fbia_registry() -> Registry:
    """The process-wide plugin registry (what ``fbia.list_plugins()`` lists)."""
    from .core.registry import default_registry

    return default_registry()


@pytest.fixture
def fbia_installer(tmp_path_factory: pytest.TempPathFactory) -> Iterable[PluginInstaller]:
    """Install plugin distributions (dist-info + entry points) for the duration of one test.

    ::

        def test_found(fbia_installer):
            fbia_installer.install("fbia-mysolver", "0.1.0",
                                   {"mysolver": "fbia_mysolver.plugin"}, source="src")
            assert "mysolver" in fbia_installer.registry().names("forward_model")
    """
    from .testing import PluginInstaller

    with pytest.MonkeyPatch.context() as mp:
        installer = PluginInstaller(tmp_path_factory.mktemp("fbia-site"), mp)
        try:
            yield installer
        finally:
            mp.undo()
            installer.cleanup()


@pytest.fixture
def fbia_measure_cases() -> list[MeasureCase]:
    """The 2-D and 3-D sample cases of :func:`fbia.testing.check_measure`."""
    from .testing import measure_cases

    return measure_cases()
