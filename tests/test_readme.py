"""The README and the guides it hands on to (docs/guide.md, docs/command_line.md,
docs/plugins.md, read in that order as one document) cannot rot: their code blocks are run,
their excerpts checked against the files.

Fenced blocks, in order:

* ``python``: executed, one after another, in one namespace (like a doctest session), in a
  temporary working folder;
* ``pycon``: doctests in that same namespace;
* ``sh``: every ``fbia ...`` line is run through the command-line entry point in this process
  (``fbia run`` excepted: ``make demo`` runs it) and every ``make ...`` target must exist;
* ``toml``: must parse;
* a block right after ``<!-- readme-test: excerpt PATH -->`` is an excerpt of ``PATH``: its
  lines (``...`` marks an omission) must appear in that file in the same order;
* a block right after ``<!-- readme-test: skip -->`` (e.g. code for a planned feature) is left
  alone.
"""

from __future__ import annotations

import doctest
import re
import shlex
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

from fbia.studies.cli import main as fbia_main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: the README and the pages its details moved to, in reading order
PAGES = [README, *(ROOT / "docs" / n for n in ("guide.md", "command_line.md", "plugins.md"))]

_FENCE = re.compile(
    r"(?:<!-- readme-test: (?P<marker>[^>]*?) -->\n)?^```(?P<lang>\w*)\n(?P<body>.*?)^```$",
    re.M | re.S,
)


@dataclass(frozen=True)
class Block:
    lang: str
    body: str
    marker: str
    line: int
    page: str = "README.md"


def blocks() -> list[Block]:
    out = []
    for page in PAGES:
        text = page.read_text()
        name = page.relative_to(ROOT).as_posix()
        out += [
            Block(m["lang"], m["body"], (m["marker"] or "").strip(),
                  text.count("\n", 0, m.start()) + 1, name)
            for m in _FENCE.finditer(text)
        ]  # fmt: skip
    return out


def runnable(lang: str) -> list[Block]:
    return [b for b in blocks() if b.lang == lang and not b.marker]


def test_setup_is_exactly_make_demo_and_make_test():
    setup = README.read_text().split("## Set-up", 1)[1].split("\n## ", 1)[0]
    (block,) = [b for b in blocks() if b.body in setup]
    assert block.body.split("\n")[:-1] == ["make demo", "make test"]
    assert "Python 3.11" in setup and ".venv" in setup


def test_python_and_pycon_blocks_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "readme"}
    parser = doctest.DocTestParser()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    ran = 0
    for block in blocks():
        if block.marker or block.lang not in ("python", "pycon"):
            continue
        where = f"{block.page}, block at line {block.line}"
        if block.lang == "python":
            exec(compile(block.body, where, "exec"), namespace)  # noqa: S102 - the point
        else:
            test = parser.get_doctest(block.body, namespace, where, block.page, block.line)
            result = runner.run(test, clear_globs=False)
            assert result.failed == 0, f"{where}: doctest failed (output above)"
        ran += 1
    assert ran >= 4
    assert namespace["result"].success  # the Levenberg-Marquardt example converged


def test_excerpts_are_in_their_files():
    excerpts = [b for b in blocks() if b.marker.startswith("excerpt ")]
    assert len(excerpts) >= 4
    for block in excerpts:
        path = ROOT / block.marker.removeprefix("excerpt ").strip()
        lines = [ln.strip() for ln in path.read_text().splitlines()]
        pos = 0
        for wanted in (ln.strip() for ln in block.body.splitlines()):
            if wanted in ("", "..."):
                continue
            try:
                pos = lines.index(wanted, pos) + 1
            except ValueError:
                pytest.fail(
                    f"{block.page} line {block.line}: {wanted!r} is not in {path} (in order)"
                )


def cli_lines(prefix: str) -> list[list[str]]:
    out = []
    for block in runnable("sh"):
        for line in block.body.splitlines():
            command = line.split("#", 1)[0].strip()
            if command.startswith(prefix + " "):
                out.append(shlex.split(command))
    return out


def test_make_targets_exist():
    makefile = (ROOT / "Makefile").read_text()
    targets = {args[1] for args in cli_lines("make")}
    assert targets == {"demo", "test"}
    for target in targets:
        assert re.search(rf"^{target}:", makefile, re.M), f"Makefile has no target {target}"


def test_cli_lines_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    commands = cli_lines("fbia")
    assert {args[1] for args in commands} == {
        "validate",
        "forward",
        "run",
        "plugins",
        "reproductions",
        "schema",
        "init",
    }
    for args in commands:
        if args[1] == "init":  # writes its FILE: into the test's folder, then validates it
            args = [tmp_path / a if a.endswith(".toml") else a for a in args]
            assert fbia_main([str(a) for a in args[1:]]) == 0, capsys.readouterr().err
            assert fbia_main(["validate", str(args[-1])]) == 0, capsys.readouterr().err
            continue
        for arg in args[2:]:
            if arg.endswith(".toml"):
                assert (ROOT / arg).is_file(), f"README names a missing file {arg}"
        if args[1] in ("run", "reproductions"):
            continue  # minutes of work: `make demo` / `make reproduce` run them
        extra = ["--output", str(tmp_path / "forward")] if args[1] == "forward" else []
        assert fbia_main(args[1:] + extra) == 0, capsys.readouterr().err
    assert "analytic_mound_2d" in capsys.readouterr().out


def test_toml_blocks_parse():
    tables = [tomllib.loads(b.body) for b in blocks() if b.lang == "toml"]
    assert any(t.get("model", {}).get("name") == "mysolver" for t in tables)
