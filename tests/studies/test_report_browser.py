"""report.html in a real browser (issue 43 item 3): headless Chromium from Debian's packages
(``make test-slow`` installs it and Playwright's driver, which drives it) opens the report of the
built-in flow-cell study from the file, as a colleague would from an e-mail, and every figure
renders (decoded, with its size), the tables are tables, and the page asks for nothing from
outside (no request but the file itself, no policy violation).
"""

from __future__ import annotations

import re
import shutil

import pytest
from _paths import ROOT

from fbia.studies.cli import main

pytestmark = pytest.mark.slow

CHROMIUM = "/usr/bin/chromium"
DEMO = (ROOT / "examples" / "flow_cell" / "study.toml").read_text()
STARTS = "x0 = [{ E = 200.0, nu = 0.4 }, { E = 1000.0, nu = 0.0 }]\n"
PAPER = """
[paper]
source = "Paper A, Table 2 (sigma = 1 um)"

[[paper.values]]
quantity = "x.E"
kind = "modulus"
paper = 400.0
unit = "Pa"
"""
# as the machine's probe starts it: without the background-networking flags Chromium tries to
# reach Google's hosts at every start
FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def test_report_html_renders_with_its_figures_in_chromium(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api", reason="make test-slow installs it")
    assert shutil.which(CHROMIUM), f"{CHROMIUM} missing: make test-slow installs Debian's chromium"
    study = tmp_path / "study.toml"
    study.write_text(re.sub(r"x0 = \[.*?\n\]\n", STARTS, DEMO, flags=re.S) + PAPER)
    assert main(["run", str(study)]) == 0
    page_file = tmp_path / "output" / "report.html"
    md = (tmp_path / "output" / "report.md").read_text()
    n_figures = len(re.findall(r"!\[[^]]*\]\(([^)]+)\)", md))
    assert n_figures >= 2

    requests: list[str] = []
    console: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=FLAGS)
        try:
            page = browser.new_page()
            page.on("request", lambda r: requests.append(r.url))
            page.on("console", lambda m: console.append(f"{m.type}: {m.text}"))
            page.goto(page_file.as_uri(), wait_until="load")
            images = page.evaluate(
                "Array.from(document.images).map(i => [i.complete, i.naturalWidth,"
                " i.naturalHeight, i.getBoundingClientRect().width])"
            )
            title = page.title()
            headings = page.eval_on_selector_all("h2", "hs => hs.map(h => h.textContent)")
            tables = page.eval_on_selector_all("table", "ts => ts.length")
            body_text = page.inner_text("body")
        finally:
            browser.close()
    assert title == "flow_cell: fbia beside Paper A, Table 2 (sigma = 1 um)"
    assert len(images) == n_figures
    for complete, width, height, shown in images:
        assert complete and width > 100 and height > 100 and shown > 100  # decoded and drawn
    assert {"Paper and fbia", "Rules", "Result", "Settings", "Figures", "Files"} <= set(headings)
    assert tables == 2  # the comparison with the paper and the rules
    assert "| x.E |" not in body_text  # rendered, not markdown source
    assert "discrepancy at x:" in body_text and "converged" in body_text
    assert [u for u in requests if not u.startswith(("file:", "data:"))] == []
    assert not [c for c in console if c.startswith("error")], console
