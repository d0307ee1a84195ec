"""Installing a plugin distribution (dist-info and entry points) for the duration of a test."""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.registry import Registry, default_registry

if TYPE_CHECKING:  # the fixture that makes a PluginInstaller passes pytest's monkeypatch
    import pytest


def write_dist_info(
    site: str | Path,
    name: str,
    version: str,
    entry_points: Mapping[str, str],
    group: str = "fbia",
) -> Path:
    """Write ``<site>/<name>-<version>.dist-info`` as ``pip install`` would.

    ``METADATA`` carries Name and Version; ``entry_points.txt`` declares ``entry_points``
    (entry-point name -> module) under ``[group]``.  With ``site`` on ``sys.path``,
    ``importlib.metadata`` (and so the fbia registry) sees an installed distribution.
    """
    site = Path(site)
    dist = site / f"{name.replace('-', '_')}-{version}.dist-info"
    dist.mkdir(parents=True, exist_ok=False)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    lines = [f"[{group}]", *(f"{k} = {v}" for k, v in entry_points.items()), ""]
    (dist / "entry_points.txt").write_text("\n".join(lines))
    (dist / "RECORD").write_text("")
    return dist


@dataclass
class PluginInstaller:
    """Installs plugin distributions into a temporary site folder for one test.

    Made by the ``fbia_installer`` fixture, which undoes everything afterwards: ``sys.path``,
    the imported plugin modules and the cached default registry.
    """

    site: Path
    monkeypatch: pytest.MonkeyPatch
    roots: list[Path] = field(default_factory=list)

    def install(
        self,
        name: str,
        version: str,
        entry_points: Mapping[str, str],
        source: str | Path | None = None,
    ) -> Path:
        """Declare distribution ``name`` ``version`` with ``entry_points`` (group ``fbia``).

        ``source`` is a folder holding the plugin's modules; it goes on ``sys.path`` as an
        installed package's site folder would.  The default registry is reloaded on next use.
        """

        if not self.roots:
            self.monkeypatch.syspath_prepend(str(self.site))
            self.roots.append(self.site)
        dist = write_dist_info(self.site, name, version, entry_points)
        if source is not None:
            src = Path(source).resolve()
            self.monkeypatch.syspath_prepend(str(src))
            self.roots.append(src)
        importlib.invalidate_caches()
        default_registry.cache_clear()
        return dist

    def registry(self) -> Registry:
        """A fresh registry loaded from all entry points, including the installed ones."""

        return Registry.load()

    def cleanup(self) -> None:
        """Forget the modules imported from the installed folders and the cached registry."""
        if not self.roots:
            return

        roots = [str(r) for r in self.roots]
        for mod_name, module in list(sys.modules.items()):
            origin = getattr(module, "__file__", None) or ""
            if any(origin.startswith(r + os.sep) for r in roots):
                del sys.modules[mod_name]
        importlib.invalidate_caches()
        default_registry.cache_clear()
