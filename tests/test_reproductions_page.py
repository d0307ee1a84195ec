"""docs/reproductions.md is what the code computes today (issue 46 item 1), ``make test-slow``.

The studies of the page whose fresh run takes under a minute on 2 cores (their README's
measured times) run again from an empty store, and each one's verdict (rows that agree of
rows judged) and status must be the page's row.  A disagreement names the study and both
values: the page is stale (regenerate it: ``make reproduce``) or the code changed a result
(say so on the page).  The page's own marks (:func:`fbia.studies.paper_report.code_changes`:
which rows were made by code that has changed since) say which rows to expect there.

The forward-run count is not compared: it moves with the rounding of the linear algebra.
Measured with the same code (cd5cc8b) on 2026-11-30, ``study_sigma_1e-3.toml`` took 603 runs,
618 under ``MKL_CBWR=COMPATIBLE``, and 600 in the environment that made the page's row, with
the same verdict in all three (Paper A's LM stops where err_grad meets eps_grad, near
round-off, and a failed run's recovery follows another path).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fbia.studies.cli import main
from fbia.studies.paper import verdict
from fbia.studies.paper_report import PaperRecord

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "reproductions.md"
#: the page's studies under a minute, fresh (their READMEs' measured times)
HET, HOM = "examples/paper_a/heterogeneous", "examples/paper_a/homogeneous"
QUICK = {
    "paper_a_heterogeneous_homogeneous_fit": f"{HET}/study_homogeneous_fit.toml",
    "paper_a_heterogeneous_noise_free": f"{HET}/study_noise_free.toml",
    "paper_a_homogeneous_sigma_1e-3": f"{HOM}/study_sigma_1e-3.toml",
    "paper_a_homogeneous_robust": f"{HOM}/study_robust.toml",
    "growth": "examples/growth/study.toml",
}
ROW = re.compile(
    r"^\| \[(?P<study>[^\]]+)\]\(#[^)]*\) \| [^|]* \| (?P<agree>\d+ / \d+|stale) \| "
    r"(?P<status>[^|]+) \| [^|]* \| (?P<nfev>\d+) \("
)


def page_rows() -> dict[str, tuple[str, str]]:
    """The Studies table of the page: study -> (agree, status)."""
    rows = {}
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        m = ROW.match(line)
        if m:
            rows[m["study"]] = (m["agree"], m["status"].strip())
    return rows


def test_the_page_lists_every_quick_study() -> None:
    assert set(QUICK) <= set(page_rows())


@pytest.mark.slow
@pytest.mark.parametrize("study", sorted(QUICK))
def test_a_quick_study_run_today_gives_the_pages_row(study: str, tmp_path: Path) -> None:
    study_file = ROOT / QUICK[study]
    # none of them names a shared [study] store: the store is the output's, fresh here
    assert not re.search(r"^store\s*=", study_file.read_text(encoding="utf-8"), re.MULTILINE)
    out = tmp_path / "out"
    main(["run", str(study_file), "--output", str(out)])
    record = PaperRecord.read(out / "paper.json")
    good, judged = verdict(record.rows)
    now = (f"{good} / {judged}", record.status)
    assert now == page_rows()[study], (
        f"{study}: the page says (agree, status) = {page_rows()[study]}, a run today "
        f"gives {now}: regenerate docs/reproductions.md (make reproduce) or say why it moved"
    )


def test_the_pages_studies_keep_the_interpreted_integrands_their_rows_were_made_with() -> None:
    """Compiled integrands (``native_code``, the default of ``ale_fsi`` and ``growth`` since
    2026-12-01) solve the same problem but move a result's bits, so every study with a
    ``[paper]`` table whose model has the option says ``native_code = false``: the code its row
    on the page was made with.  When the page is made afresh with compiled code, drop the
    setting and this test."""
    from fbia.core.registry import default_registry
    from fbia.studies.study_sources import read_sources

    registry = default_registry()
    checked = []
    for path in sorted((ROOT / "examples").rglob("*.toml")):
        if path.name == "pyproject.toml" or "output" in path.parts:
            continue
        raw = read_sources(path).raw
        if "paper" not in raw or raw.get("study", {}).get("base_only"):
            continue
        model = raw["model"]
        options_class = registry.get("forward_model", model["name"]).factory.Options
        if "native_code" in options_class.model_fields:
            assert model.get("options", {}).get("native_code") is False, path
            checked.append(path)
    assert len(checked) >= 25  # Paper A's and B's ale_fsi studies and growth's
