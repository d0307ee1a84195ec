"""``paper.json`` and the paper's section of ``report.md`` for a study with a ``[paper]`` table,
and the summary page.

:func:`write_paper_report` is called by :func:`fbia.studies.runner.run_study` when the study has
a ``[paper]`` table (:mod:`fbia.studies.paper`): it compares the result with the paper and
writes ``paper.json`` (the rows and times, typed: :class:`PaperRecord`) into the output folder;
:func:`paper_section` gives the section **Paper and fbia** of the study's ``report.md``
(:mod:`fbia.studies.study_report`): the verdict, the table **quantity | paper | fbia |
difference | rel. | agrees? | why** and the rules.

Each row is judged by the rule of its kind (:data:`fbia.studies.paper.KINDS`); both pages state
the rules once, generated from that table (:func:`rules_table`), so text and code cannot
drift.  A result flagged unreliable (or without success) agrees with nothing.

:func:`write_summary` (``fbia reproductions OUT.md DIR ...``) collects every ``paper.json``
below the given folders into one page (``docs/reproductions.md``): the rules, per study the
source, the verdict (rows that agree of rows judged), the times and the full table, so that
the page reads on its own where the output folders are not checked in; and per example the
section ``## Measured times`` of its README (the wall time of a fresh run, which a session
that took its runs from the store cannot measure).  A ``paper.json`` written before the rules
by kind (its rows carry their own ``rule`` and ``tolerance``) is listed as *stale*, without
its verdicts: run its study again.

So that the page cannot go stale silently (issue 46), ``paper.json`` records the git commit
of the fbia source that made it (:func:`fbia.studies.provenance.source_commit`) and the code
of the study's model, measure and iterator (:func:`plugin_code`: the SHA-256 of each file of
their code, :func:`fbia.storage.fingerprints.class_code_digest`); the page gives every study
the commit and whether that code is what runs now (:func:`code_changes`: the roles and files
that changed since), and says so in bold where it is not, or where the record is of an fbia
that did not record it.  ``tests/test_reproductions_page.py`` (``make test-slow``) reruns the
studies under a minute and compares their verdicts and run counts with the page's.
"""

from __future__ import annotations

import importlib
import json
import logging
import math
import os
import re
import typing
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError
from ..core.problem import Result
from ..storage.fingerprints import class_code_digest, code_digest, code_digest_like, digest_kind
from .paper import DRAWS_RULE, KINDS, Comparison, compare, verdict
from .provenance import source_commit
from .study import Study
from .study_report import MARKDOWN_NAME, SessionTimes
from .study_sources import read_sources

__all__ = [
    "PaperRecord",
    "code_changes",
    "paper_section",
    "paper_title",
    "plugin_code",
    "published_numbers",
    "rules_table",
    "write_paper_report",
    "write_summary",
]

RECORD_NAME = "paper.json"

logger = logging.getLogger(__name__)
#: the section of an example's README that the summary page copies (fresh-run wall times)
TIMES_HEADING = "Measured times"


@dataclass(frozen=True)
class PaperRecord:
    """What ``paper.json`` holds: one study's comparison with the paper, and its times."""

    study: str
    study_file: str
    source: str
    note: str
    status: str
    wall_time: float  # s, this session (start to the end of the extras)
    forward_time: float  # s, summed wall time of the result's forward runs (stored ones too)
    nfev: int
    finished: str
    rows: tuple[Comparison, ...]
    reused: int = 0  # runs this session took from the store instead of running them
    stale: str = ""  # why the rows are not shown (set on reading a record of an older fbia)
    #: the git commit of the fbia source that made the record (+dirty: with local changes)
    commit: str = ""
    #: the code of the study's model, measure and iterator (storage.fingerprints'
    #: class_code_digest, by role): the page marks a row whose code has changed since
    code: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        skip = ("rows", "stale")
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in skip}
        out["rows"] = [r.to_dict() for r in self.rows]
        return out

    @classmethod
    def read(cls, path: Path) -> PaperRecord:
        """The record in ``path``; one written under the per-row rules before ``KINDS``
        comes back stale, without its rows (their verdicts were lenient)."""
        if not path.is_file():  # a FIFO or a device would block the reader
            raise ConfigError("not a regular file", str(path))
        if path.stat().st_size > MAX_RECORD_BYTES:
            raise ConfigError(f"larger than {MAX_RECORD_BYTES} bytes: not a paper.json", str(path))
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(data, dict):
                raise TypeError("not a JSON object")
            raw_rows = data.pop("rows")
            _check_types(data)
            if any("rule" in r["value"] for r in raw_rows):
                return cls(**data, rows=(), stale=STALE)
            rows = tuple(Comparison.from_dict(r) for r in raw_rows)
            return cls(**data, rows=rows)
        except UnicodeDecodeError as exc:
            raise ConfigError(f"not UTF-8 (byte {exc.start})", str(path)) from None
        except RecursionError:
            raise ConfigError("nested too deeply: not a paper.json", str(path)) from None
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ConfigError(f"not a paper.json of fbia: {exc}", str(path)) from None


#: the largest paper.json read (a record is a few kB)
MAX_RECORD_BYTES = 10_000_000


def _check_types(data: dict[str, Any]) -> None:
    """TypeError naming the first field of a record with the wrong type (or a non-finite
    time), before anything formats it."""
    hints = typing.get_type_hints(PaperRecord)
    for name, value in data.items():
        hint = hints.get(name)
        if hint not in (str, int, float):
            continue
        kinds: tuple[type, ...] = (int, float) if hint is float else (hint,)
        if isinstance(value, bool) or not isinstance(value, kinds):
            raise TypeError(f"{name} is {value!r}, not {' or '.join(k.__name__ for k in kinds)}")
        if isinstance(value, float) and not math.isfinite(value):
            raise TypeError(f"{name} is {value!r}, not a finite number")


#: what the summary says of a paper.json written before the rules by kind
STALE = (
    "written by an older fbia, whose [paper] rows chose their own rules and tolerances: its "
    "verdicts are not shown; run the study again to judge it by the rules above"
)


def write_paper_report(
    study: Study,
    result: Result,
    out: Path,
    wall_time: float,
    reused: int = 0,
    rows: Sequence[Comparison] | None = None,
    forward_time: float | None = None,
) -> PaperRecord:
    """Compare ``result`` with ``study.paper``; write ``paper.json`` and return its record
    (``reused``: how many runs the session took from the store; ``rows``: the comparison
    when made otherwise, e.g. over noise draws; ``forward_time``: the summed time of the
    forward runs when ``result`` does not hold them).  :func:`paper_section` gives the
    record's section of ``report.md``."""
    spec = study.paper
    assert spec is not None
    if rows is None:
        rows = compare(
            spec, result.quantities(), result.status, result.success, result.undetermined()
        )
    rows = tuple(rows)
    forward = forward_time
    if forward is None:
        forward = sum(e.time for e in result.evaluations if math.isfinite(e.time))
    record = PaperRecord(
        study=study.name,
        study_file=str(study.path.resolve()),
        source=spec.source,
        note=spec.note,
        status=result.status,
        wall_time=wall_time,
        forward_time=forward,
        nfev=result.nfev,
        finished=str(result.provenance.get("finished", "")),
        rows=rows,
        reused=reused,
        commit=source_commit(),
        code=plugin_code(study),
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / RECORD_NAME).write_text(json.dumps(record.to_dict(), indent=1), encoding="utf-8")
    return record


def plugin_code(study: Study) -> dict[str, Any]:
    """The code digest of the study's model, measure and iterator (by role)."""
    plugins = {"model": study.model, "measure": study.measure, "iterator": study.iterator}
    return {role: code_digest(obj) for role, obj in plugins.items() if obj is not None}


def code_changes(code: dict[str, Any]) -> list[str]:
    """The roles whose code differs now from the recorded digests ``code`` (a class that is
    gone counts as changed), each with the files that changed: ``["model (solver.py)"]``."""
    changed = []
    for role, digest in sorted(code.items()):
        name = str(digest.get("class", ""))
        try:
            now = code_digest_like(digest, _recorded_class(digest))  # of the record's kind
        except (ImportError, AttributeError, ValueError):
            changed.append(f"{role} ({name} is gone)")
            continue
        if now.get("sha256") == digest.get("sha256"):
            continue
        old, new = digest.get("files", {}), now.get("files", {})
        files = sorted(f for f in set(old) | set(new) if old.get(f) != new.get(f))
        changed.append(f"{role} ({', '.join(files) or 'its version'})")
    return changed


def _recorded_class(digest: dict[str, Any]) -> type:
    """The class a recorded code digest names (ImportError, AttributeError or ValueError when
    it is gone)."""
    module, _, qualname = str(digest.get("class", "")).rpartition(".")
    return getattr(importlib.import_module(module), qualname)


def code_in_current_form(path: Path, code: dict[str, Any]) -> dict[str, Any]:
    """``code`` (a record's digests, by role, of code that has not changed since:
    :func:`code_changes` is empty) in this fbia's form, written back to the record ``path``
    where it was of an earlier kind (the files' bytes, :func:`~fbia.storage.fingerprints.
    digest_kind`): the same files, digested without their documentation, so that documenting
    the code later keeps the row "unchanged", as a store records the new form when it is
    bound."""
    old = {role: d for role, d in code.items() if digest_kind(d) != "code"}
    if not old:
        return code
    current = dict(code)
    for role, digest in old.items():
        current[role] = class_code_digest(_recorded_class(digest))
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        data["code"] = current
        path.write_text(json.dumps(data, indent=1), encoding="utf-8")
    except OSError as exc:  # a record that cannot be written keeps the old form, and its row
        logger.warning("%s: its code digests stay in the old form (%s)", path, exc)
        return code
    logger.info("%s: code digests recorded without documentation (the files are unchanged)", path)
    return current


def paper_title(study: Study, record: PaperRecord) -> str:
    """The heading of the report of a study with a ``[paper]`` table."""
    return f"{study.name}: fbia beside {record.source}"


def paper_section(record: PaperRecord) -> list[str]:
    """The comparison with the paper as markdown lines of ``report.md``: the verdict, the
    note, the table and the rules."""
    good, judged = verdict(record.rows)
    flagged = next((r.reason for r in record.rows if r.reason), "")
    draws = (
        f" over {record.rows[0].n_draws} noise draws"
        if record.rows and record.rows[0].n_draws
        else ""
    )
    tail = f" ({flagged}: every judged row counts as no)." if flagged else "."
    lines = ["## Paper and fbia", ""]
    lines += [f"{good} of {judged} published numbers agree by the rule of their kind{draws}{tail}"]
    lines += [""]
    if record.note:
        lines += [record.note, ""]
    lines += [*comparison_table(record.rows), ""]
    lines += ["## Rules", "", *rules_table(), ""]
    return lines


def _times(record: PaperRecord) -> str:
    times = SessionTimes(record.wall_time, record.forward_time, record.nfev, record.reused)
    return times.sentence()


def rules_table() -> list[str]:
    """The rules, one per kind of quantity, as a markdown table (from ``KINDS``)."""
    out = [
        "Every published number is judged by the one rule of its kind (f: fbia, p: the paper). "
        "A result whose status is `unreliable`, or that is not a success, agrees with "
        "nothing: every judged row of its study counts as no.",
        "",
        "| kind | for | agrees when |",
        "|---|---|---|",
    ]
    for name, kind in KINDS.items():
        formula = kind.formula.replace("|", "\\|")
        out.append(f"| `{name}` | {kind.covers} | {kind.criterion}: {formula} |")
    out += [
        "",
        f"Noisy data are judged {DRAWS_RULE}; the table then gives fbia's median and "
        "[2.5 %, 97.5 %] range.",
    ]
    return out


def comparison_table(rows: Sequence[Comparison]) -> list[str]:
    """The markdown table of a comparison: quantity | paper | fbia | difference | rel. |
    agrees? | why (rel.: f/p for kind ``scale``)."""
    out = [
        "| quantity | paper | fbia | difference | rel. | agrees? | why |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        v = r.value
        unit = f" {v.unit}" if v.unit else ""
        paper = f"{_num(v.paper)}{unit}" if v.paper is not None else "-"
        if v.than is not None:
            ref = f" ({_num(r.reference)})" if r.reference is not None else ""
            paper = f"{v.criterion()}{ref}"
        fbia = f"{_num(r.fbia)}{unit}"
        if r.n_draws and v.than is not None:  # over draws: the share that holds
            fbia = f"{_num(r.fbia)} (holds in {100 * (r.high or 0.0):.0f} % of {r.n_draws} draws)"
        elif r.n_draws:  # over draws: the median and the central 95 % range
            fbia = f"{_num(r.fbia)} [{_num(r.low)}, {_num(r.high)}]{unit} ({r.n_draws} draws)"
        diff = "" if r.abs_diff is None else _num(r.abs_diff)
        rel = "" if r.rel_diff is None else f"{100 * r.rel_diff:+.3g} %"
        if v.kind == "scale" and r.rel_diff is not None:
            rel = f"f/p = {1 + r.rel_diff:.3g}"
        mark = {True: "yes", False: "**no**", None: "-"}[r.agrees]
        agrees = mark
        if r.agrees is not None:
            rule = v.criterion()
            if r.n_draws:
                rule = "holds in half the draws" if v.than is not None else "inside the range"
            agrees = f"{mark}: {r.reason}" if r.reason else f"{mark} ({rule})"
        why = v.why.replace("|", "\\|")
        out.append(f"| {v.name} | {paper} | {fbia} | {diff} | {rel} | {agrees} | {why} |")
    return out


def _num(x: float | None) -> str:
    if x is None or not math.isfinite(x):
        return "no result" if x is not None else "-"
    return f"{x:.4g}"


def _rel(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path, start)).as_posix()


def write_summary(target: str | Path, folders: Sequence[str | Path]) -> tuple[Path, int]:
    """Collect every ``paper.json`` below ``folders`` into the markdown page ``target``.

    Returns the page and the number of studies on it.  Study files with a ``[paper]`` table
    below ``folders`` that have no ``paper.json`` are listed as not run, records whose study
    file has no ``[paper]`` table any more are left out (and listed); no record at all is an
    error (a summary of nothing would hide that the examples were not run).
    """
    target = Path(target)
    if target.suffix.lower() != ".md":
        raise ConfigError(
            "the summary is a markdown page: give a file name ending in .md", str(target)
        )
    records: list[tuple[Path, PaperRecord]] = []
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise ConfigError("not a folder", str(folder))
        records += [(p, PaperRecord.read(p)) for p in sorted(folder.rglob(RECORD_NAME))]
    if not records:
        raise ConfigError(
            f"no {RECORD_NAME} below them: run the examples first (make reproduce)",
            ", ".join(str(f) for f in folders),
        )
    _check_target(target, records, [Path(f) for f in folders])
    records, left_out = _current(records)
    not_run = _not_run(folders, records)
    lines = [
        "# Reproductions of the papers' examples",
        "",
        "Generated by `fbia reproductions` from the `paper.json` files that `fbia run` writes "
        "beside `report.md` for every study with a `[paper]` table (`make reproduce` runs "
        "them all and regenerates this page). Each table puts the published number beside "
        "fbia's, with the verdict by the rule of its kind and, where they differ, the "
        'measured cause or "cause not found" and what was measured. Forward-run counts, and '
        "values that sit at round-off (a noise-free residual, how many starts end at a bound), "
        "move with the machine's linear algebra: the same code took 600, 603 and 618 runs for "
        "`study_sigma_1e-3.toml` in three environments (2026-11-30); the rows where that "
        "moves a verdict say so.",
        "",
        "## Rules",
        "",
        *rules_table(),
        "",
        "## Studies",
        "",
        "| study | source | agree | status | wall time of the last session | forward runs "
        "(their summed time) | made by the code of |",
        "|---|---|---|---|---|---|---|",
    ]
    root = target.parent.resolve()
    changes = {id(rec): code_changes(rec.code) for _, rec in records}
    for path, rec in records:
        if not changes[id(rec)]:
            code_in_current_form(path, rec.code)
    for _, rec in records:
        good, judged = verdict(rec.rows)
        agree = "stale" if rec.stale else f"{good} / {judged}"
        lines.append(
            f"| [{rec.study}](#{_anchor(rec.study)}) | {rec.source} | {agree} | "
            f"{rec.status} | {rec.wall_time:.0f} s{' (resumed)' if rec.reused else ''} | "
            f"{rec.nfev} ({rec.forward_time:.0f} s) | {_made_by(rec, changes[id(rec)])} |"
        )
    numbers = published_numbers([rec for _, rec in records])
    judged_all = len(numbers)
    good_all = sum(all(v) for v in numbers.values())
    judgements = sum(len(v) for v in numbers.values())
    if judged_all:
        by_paper: dict[str, list[int]] = {}
        for key, agrees in numbers.items():
            tally = by_paper.setdefault(key[0], [0, 0])
            tally[0] += all(agrees)
            tally[1] += 1
        parts = [
            f"{paper}: {g} of {j} ({100 * g / j:.0f} %)"
            for paper, (g, j) in sorted(by_paper.items())
            if j
        ]
        once = (
            ""
            if judgements == judged_all
            else f" Each published number is counted once ({judgements} judgements over "
            "the studies): a number that several studies judge (a Table 2 row over one "
            "draw and over many, Table 6 with one and four growth steps a day) agrees when "
            "it agrees in every one of them."
        )
        lines += [
            "",
            f"In all: {good_all} of {judged_all} judged published numbers agree "
            f"({100 * good_all / judged_all:.0f} %)"
            + (f"; {'; '.join(parts)}." if len(parts) > 1 else ".")
            + once,
        ]
    if not_run:
        lines += ["", "Studies with a `[paper]` table that have no `paper.json` (not run yet):", ""]
        lines += [f"- `{_rel_or_abs(f, root)}`" for f in not_run]
    if left_out:
        lines += [
            "",
            "Left out: `paper.json` files whose study file has no `[paper]` table (any more):",
            "",
        ]
        lines += [f"- `{_rel_or_abs(f, root)}`" for f in left_out]
    lines += _measured_times([path for path, _ in records], [Path(f) for f in folders], root)
    for path, rec in records:
        study_file = _rel_or_abs(Path(rec.study_file), root)
        report = _rel_or_abs(path.parent / MARKDOWN_NAME, root)
        lines += [
            "",
            f"## {rec.study}",
            "",
            f"{rec.source}. Study file [{study_file}]({study_file}); full report "
            f"`{report}` (written by the run, not checked in). Result status: {rec.status}; "
            f"finished {rec.finished}.",
            "",
            _times(rec),
            "",
            _provenance_line(rec, changes[id(rec)]),
            "",
        ]
        if rec.stale:
            lines.append(f"This `paper.json` is stale: {rec.stale}.")
            continue
        if rec.note:
            lines += [rec.note, ""]
        lines += comparison_table(rec.rows)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return target, len(records)


def published_numbers(
    records: Sequence[PaperRecord],
) -> dict[tuple[str, str, float | None, str | None, str | None], list[bool]]:
    """Every published number the records judge, once: by its paper (the source's first
    part, "Paper A"), quantity, published value and ordering, with the verdict of each
    study that judges it."""
    numbers: dict[tuple[str, str, float | None, str | None, str | None], list[bool]] = {}
    for rec in records:
        paper = rec.source.split(",")[0].strip() or "other"
        for row in rec.rows:
            if row.agrees is None:
                continue
            v = row.value
            key = (paper, v.quantity, v.paper, v.above, v.below)
            numbers.setdefault(key, []).append(bool(row.agrees))
    return numbers


def _made_by(rec: PaperRecord, changed: list[str]) -> str:
    """The Studies table's cell: the commit, and whether the code changed since."""
    commit = f"`{rec.commit[:7]}{'+dirty' if rec.commit.endswith('+dirty') else ''}`"
    if not rec.code:
        return "not recorded: **rerun**"
    if changed:
        return f"{commit}; **changed since: {', '.join(c.split(' ')[0] for c in changed)}**"
    return f"{commit}, unchanged"


def _provenance_line(rec: PaperRecord, changed: list[str]) -> str:
    """The sentence of a study's section that says which code made its rows."""
    if not rec.code:
        return (
            "**Which code made these rows is not recorded** (a `paper.json` of fbia before "
            "issue 46): they may not be what the code computes today; run the study again."
        )
    made = f"Made at commit `{rec.commit or 'unknown'}`"
    if changed:
        return (
            f"{made}. **The code has changed since**: {'; '.join(changed)}: these rows may "
            "not be what the code computes today; run the study again."
        )
    return f"{made}; the code of its model, measure and iterator is unchanged since."


def _has_paper(study_file: Path) -> bool:
    """Whether a study file (still) has a ``[paper]`` table."""
    try:  # a variant's [paper] may be its base's (fbia.studies.study_sources)
        return "paper" in read_sources(study_file).raw
    except (ConfigError, OSError, ValueError, UnicodeDecodeError):
        return False


def _current(
    records: list[tuple[Path, PaperRecord]],
) -> tuple[list[tuple[Path, PaperRecord]], list[Path]]:
    """The records whose study file still has a ``[paper]`` table, and the others' paths."""
    keep: list[tuple[Path, PaperRecord]] = []
    left_out: list[tuple[Path, PaperRecord]] = []
    for path, rec in records:
        (keep if _has_paper(Path(rec.study_file)) else left_out).append((path, rec))
    return keep, [path for path, _ in left_out]


def _not_run(folders: Sequence[str | Path], records: list[tuple[Path, PaperRecord]]) -> list[Path]:
    """Study files with a ``[paper]`` table below ``folders`` that no record comes from."""
    done = {Path(rec.study_file).resolve() for _, rec in records}
    files = sorted({f.resolve() for d in folders for f in Path(d).rglob("study*.toml")})
    return [f for f in files if f not in done and _has_paper(f)]


def _check_target(
    target: Path, records: list[tuple[Path, PaperRecord]], folders: Sequence[Path]
) -> None:
    """The page is written to none of the files the summary reads or links to (a
    ``paper.json``, its study file and ``report.md``, an example's README), nor to
    something that is not a regular file (a FIFO would block the write)."""
    if target.is_symlink() or (target.exists() and not target.is_file()):
        raise ConfigError("not a regular file: the summary is not written through it", str(target))
    read = {p.resolve() for p, _ in records}
    read |= {(p.parent / MARKDOWN_NAME).resolve() for p, _ in records}
    read |= {Path(rec.study_file).resolve() for _, rec in records}
    read |= {f / "README.md" for f in _examples([p for p, _ in records], folders)}
    if target.resolve() in read:
        raise ConfigError(
            "is a file the summary reads or links to: give another page to write", str(target)
        )


def _examples(records: Sequence[Path], folders: Sequence[Path]) -> list[Path]:
    """The example of each record: the nearest folder above it holding a README.md, within
    ``folders``."""
    tops = [f.resolve() for f in folders]
    examples: list[Path] = []
    for path in records:
        folder = path.resolve().parent
        while not (folder / "README.md").is_file() and folder not in tops:
            if folder.parent == folder:
                break
            folder = folder.parent
        if (folder / "README.md").is_file() and folder not in examples:
            examples.append(folder)
    return examples


def _measured_times(records: Sequence[Path], folders: Sequence[Path], root: Path) -> list[str]:
    """Per example (:func:`_examples`) its README's section ``## Measured times``: the wall
    time of a fresh run, which a session that took its runs from the store cannot measure.
    Links rebased to ``root``."""
    lines: list[str] = []
    for folder in _examples(records, folders):
        section = _section(folder / "README.md", TIMES_HEADING)
        if section:
            link, name = _rel_or_abs(folder, root), _rel_or_abs(folder, Path.cwd().resolve())
            rebased = [_rebase_links(line, folder, root) for line in section]
            lines += ["", f"### [{name}]({link}/README.md)", "", *rebased]
    if lines:
        lines = [
            "",
            f"## {TIMES_HEADING} per example",
            "",
            "The wall time of a fresh run of each example, as its README states it (the table "
            "above gives each study's last session, which may have taken its runs from the "
            "store).",
            *lines,
        ]
    return lines


def _section(readme: Path, heading: str) -> list[str]:
    """The body of the ``## heading`` section of a markdown file (empty if it has none)."""
    body: list[str] | None = None
    try:
        text = readme.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 (byte {exc.start})", str(readme)) from None
    for line in text.splitlines():
        if body is not None and line.startswith("## "):
            break
        if body is not None:
            body.append(line)
        elif line.strip() == f"## {heading}":
            body = []
    while body and not body[0].strip():
        body.pop(0)
    while body and not body[-1].strip():
        body.pop()
    return body or []


def _rebase_links(line: str, start: Path, root: Path) -> str:
    """``line`` with its relative markdown links, written from ``start``, made relative to
    ``root``."""

    def rebase(match: re.Match[str]) -> str:
        link = match.group(1)
        if "://" in link or link.startswith(("#", "/", "mailto:")):
            return match.group(0)
        path, _, anchor = link.partition("#")
        new = _rel(Path(os.path.normpath(start / path)), root)
        return f"]({new}{'#' + anchor if anchor else ''})"

    return re.sub(r"\]\(([^)\s]+)\)", rebase, line)


def _anchor(title: str) -> str:
    """GitHub's anchor of a heading."""
    keep = "".join(c for c in title.lower() if c.isalnum() or c in " -_")
    return keep.replace(" ", "-")


def _rel_or_abs(path: Path, root: Path) -> str:
    try:
        return _rel(path.resolve(), root)
    except ValueError:
        return path.as_posix()
