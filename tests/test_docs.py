"""``make docs`` builds the guides and the API reference from the docstrings without a warning
(issue 29 item 9; issue 43: without ``--quiet``, which hid griffe's warnings): the same
build, into the test's folder. The API pages show the three protocols, the likelihood,
``synthetic_observations``, ``load_result`` and every name of ``fbia.__all__``; every dotted
``fbia.`` name the docs and docstrings cite imports."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_architecture import PACKAGES

ROOT = Path(__file__).resolve().parents[1]


def test_the_api_reference_builds_without_warnings(tmp_path):
    yaml = pytest.importorskip("yaml")
    pytest.importorskip("mkdocstrings")
    tree = tmp_path / "tree" / "fbia"  # the package as installed (make package-tree)
    tree.mkdir(parents=True)
    for name in (*PACKAGES, "__init__.py"):
        (tree / name).symlink_to(ROOT / name)
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    config["docs_dir"] = str(ROOT / "docs")
    config["site_dir"] = str(tmp_path / "site")
    handler = config["plugins"][1]["mkdocstrings"]["handlers"]["python"]
    handler["paths"] = [str(tmp_path / "tree")]
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(config))
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(tmp_path / "mkdocs.yml")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "WARNING" not in done.stderr, done.stderr
    page = (tmp_path / "site" / "api" / "core" / "index.html").read_text()
    assert "InverseProblem" in page and "load_result" in page
    for name in ("ForwardModel", "Discrepancy", "InverseIterator", "synthetic_observations"):
        assert name in page, name
    assert "gaussian_log_likelihood" in page and "ChiSquare" in page
    front = (tmp_path / "site" / "api" / "fbia" / "index.html").read_text()
    import fbia

    missing = [n for n in fbia.__all__ if f"<code>{n}</code>" not in front]
    assert missing == [], missing


#: backticked dotted names, as Markdown and reST roles cite them (``fbia.x``, :func:`~fbia.x`)
_CITED = re.compile(r"`~?(fbia(?:\.[A-Za-z_][A-Za-z0-9_]*)+)")
#: dotted names that are files, not objects
_FILES = {"fbia.log"}


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


def test_every_dotted_name_the_docs_and_docstrings_cite_imports():
    sources = [*ROOT.glob("docs/*.md"), ROOT / "README.md"]
    for package in PACKAGES:
        sources += sorted((ROOT / package).rglob("*.py"))
    broken = sorted(
        f"{path.relative_to(ROOT)}: {name}"
        for path in sources
        for name in {m.group(1) for m in _CITED.finditer(path.read_text(encoding="utf-8"))}
        if name not in _FILES and not _resolves(name)
    )
    assert broken == []
