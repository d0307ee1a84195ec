"""paper.json as fbia reproductions reads it: strictly (one line naming the file for a
foreign, mistyped, deeply nested, non-UTF-8 or non-regular file)."""

from __future__ import annotations

import json
import os

import pytest
from _studies import one_error_line

import fbia
from fbia.studies.cli import main
from fbia.studies.paper_report import write_summary


def test_summary_refuses_a_foreign_json(tmp_path):
    (tmp_path / "paper.json").write_text(json.dumps({"x": 1}))
    with pytest.raises(fbia.ConfigError, match="not a paper.json of fbia"):
        write_summary(tmp_path / "s.md", [tmp_path])


NOT = "not a paper.json of fbia:"


def _record(**changes):
    base = {
        "study": "s", "study_file": "s.toml", "source": "Paper A", "note": "", "status": "ok",
        "wall_time": 1.0, "forward_time": 1.0, "nfev": 1, "finished": "now", "rows": [],
    }  # fmt: skip
    return json.dumps({**base, **changes})


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (_record(wall_time="ten"), f"{NOT} wall_time is 'ten', not int or float"),
        (_record(forward_time=None), f"{NOT} forward_time is None, not int or float"),
        (_record(nfev=True), f"{NOT} nfev is True, not int"),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply: not a paper.json"),
        (b"\xff\xfe{", "not UTF-8 (byte 0)"),
    ],
    ids=["string-time", "null-time", "bool-count", "deep", "not-utf8"],
)
def test_the_summary_reads_paper_json_strictly(tmp_path, capsys, content, message):
    path = tmp_path / "paper.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    assert main(["reproductions", str(tmp_path / "s.md"), str(tmp_path)]) == 2
    assert one_error_line(capsys) == f"{path}: {message}"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_named_paper_json_is_refused_not_read(tmp_path, capsys):
    os.mkfifo(tmp_path / "paper.json")  # reading it would block forever
    assert main(["reproductions", str(tmp_path / "s.md"), str(tmp_path)]) == 2
    assert one_error_line(capsys) == f"{tmp_path / 'paper.json'}: not a regular file"
