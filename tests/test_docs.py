"""``make docs`` builds the guides and the API reference from the docstrings without a warning
(issue 29 item 9): the same build, into the test's folder."""

from __future__ import annotations

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
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "-f",
         str(tmp_path / "mkdocs.yml")],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == ""
    page = (tmp_path / "site" / "api" / "core" / "index.html").read_text()
    assert "InverseProblem" in page and "load_result" in page
