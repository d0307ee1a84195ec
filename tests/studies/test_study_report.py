"""report.md and report.html for every study (fbia.studies.study_report, issue 43 item 3).

The built-in flow-cell study (examples/flow_cell/study.toml, two of its eleven starts) writes
both pages: the settings, the result, the discrepancy table and the figures, the HTML with
every figure embedded (the bytes of the PNG files), no script and nothing fetched from outside.
The browser check (the page rendered by headless Chromium with its figures) is in
test_report_browser.py (slow).
"""

from __future__ import annotations

import base64
import json
import re

from _paths import ROOT

from fbia.studies.cli import main
from fbia.studies.study_report import render_html

DEMO = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
STARTS = "x0 = [{ E = 200.0, nu = 0.4 }, { E = 1000.0, nu = 0.0 }]\n"


def _study(tmp_path, text: str = DEMO):
    text = re.sub(r"x0 = \[.*?\n\]\n", STARTS, text, flags=re.S)
    path = tmp_path / "study.toml"
    path.write_text(text)
    return path


def _embedded_images(page: str) -> list[bytes]:
    return [
        base64.b64decode(m)
        for m in re.findall(r'<img\b[^>]*\bsrc="data:image/png;base64,([^"]+)"', page)
    ]


def test_a_study_writes_report_md_and_a_self_contained_report_html(tmp_path):
    assert main(["run", str(_study(tmp_path))]) == 0
    out = tmp_path / "output"
    md = (out / "report.md").read_text()
    assert md.startswith("# flow_cell\n")
    status = json.loads((out / "result.json").read_text())["status"]
    assert status.startswith("converged_")  # the fit succeeds, and the report says how
    assert f"result: **{status}**" in md and "Not a result to use" not in md
    assert re.search(r"Measured: \d+\.\d s wall time of this session; the \d+ forward runs", md)
    for section in ("## Result", "## Settings", "## Figures", "## Files"):
        assert section in md
    assert "discrepancy at x:" in md  # report.txt's table, in the result section
    assert "ground truth of the synthetic data: E = 400, nu = 0.3" in md
    assert "- model `analytic_mound_2d`: n_points = 81" in md
    assert "- parameters: E in [50, 1500]; nu in [-0.95, 0.49]" in md
    figures = re.findall(r"!\[[^]]*\]\(([^)]+)\)", md)
    assert "plots/interfaces.png" in figures and "plots/evaluations.png" in figures
    assert "- `result.json`" in md and "- `report.txt`" in md and "sqlite-wal" not in md

    page = (out / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "<title>flow_cell</title>" in page
    assert "Content-Security-Policy" in page and "default-src 'none'" in page
    assert "<script" not in page
    assert not re.search(r'\bsrc="(?!data:)', page)  # nothing to fetch: every image inline
    assert _embedded_images(page) == [(out / f).read_bytes() for f in figures]
    assert "<h2>Settings</h2>" in page
    assert "discrepancy at x:" in page


def test_an_unreliable_result_leads_its_report_with_the_cause(tmp_path):
    """The truth outside the bounds (E = 3000 Pa, bounds [50, 1500]): the fit is at a bound,
    its status unreliable; the report says so before anything else."""
    text = DEMO.replace("truth = { E = 400.0, nu = 0.3 }", "truth = { E = 3000.0, nu = 0.3 }")
    assert main(["run", str(_study(tmp_path, text))]) == 3
    md = (tmp_path / "output" / "report.md").read_text()
    head = md.split("## Result")[0]
    assert "> **Not a result to use as it is (unreliable):** at bound: E = 1500" in head
    page = (tmp_path / "output" / "report.html").read_text()
    assert "<blockquote>" in page and "at bound: E = 1500" in page


def test_a_study_without_an_iterator_writes_its_report(tmp_path):
    """One forward run at the start point (no [iterator]): the report of that run."""
    text = DEMO[: DEMO.index("[iterator]")]
    assert main(["run", str(_study(tmp_path, text))]) == 0
    md = (tmp_path / "output" / "report.md").read_text()
    assert "result: **forward**" in md and "discrepancy of the forward run:" in md
    assert "![plots/interfaces.png](plots/interfaces.png)" in md
    assert len(_embedded_images((tmp_path / "output" / "report.html").read_text())) == 1


def test_an_image_outside_the_output_folder_is_not_embedded(tmp_path):
    secret = tmp_path / "secret.png"
    secret.write_bytes(b"\x89PNG not for the report")
    (tmp_path / "out").mkdir()
    page = render_html("![x](../secret.png)\n", tmp_path / "out", "t")
    assert 'src="../secret.png"' in page and "base64" not in page  # and the policy blocks it
