"""``report.md`` and ``report.html``: what a study found, for every study.

:func:`write_report` is called by :mod:`fbia.studies.runner` once a session's result is saved
(and, for a study with a ``[paper]`` table, compared: :mod:`fbia.studies.paper_report`). It
writes into the output folder

* ``report.md``: the result's status and message (its causes first when it is not to be
  trusted), the measured times, the result as printed at the end of the run (the iterator's
  summary, the ground truth of synthetic data, the discrepancy at the result's ``x``: the text of
  ``report.txt``), the warnings of the session, the segmentation of every OCT scan (kind of
  surface, one surface or not, structure parameters, its B-scan), the settings, the
  comparison with the paper
  when the study has one, the figures (inline) and the other files;
* ``report.html``: the same page rendered by Python-Markdown, self-contained so that a
  colleague can open it from an e-mail: the figures embedded as ``data:`` URIs, the style
  inline, no script (a Content-Security-Policy forbids scripts and every outside address).

Recipe::

    from fbia.studies.study_report import SessionTimes, write_report
    md, html = write_report(study, result, out, SessionTimes(wall_time=12.0,
                            forward_time=10.5, nfev=40), text=report_txt)
"""

from __future__ import annotations

import base64
import html
import mimetypes
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import markdown

from ..core.options import plugin_options
from ..core.problem import Result
from .study import Study

__all__ = ["HTML_NAME", "MARKDOWN_NAME", "SessionTimes", "settings_lines", "write_report"]

MARKDOWN_NAME = "report.md"
HTML_NAME = "report.html"


@dataclass(frozen=True)
class SessionTimes:
    """What one session cost: its wall time, the summed wall time of the result's forward runs
    (runs taken from the store count with the time they took when they ran) and how many of
    the result's ``nfev`` runs came from the store."""

    wall_time: float  # s
    forward_time: float  # s
    nfev: int
    reused: int = 0

    def sentence(self) -> str:
        reused = f" ({self.reused} runs taken from the store, not run again)" if self.reused else ""
        return (
            f"Measured: {self.wall_time:.1f} s wall time of this session{reused}; the "
            f"{self.nfev} forward runs of the result took {self.forward_time:.1f} s together "
            "(runs taken from the store count with the time they took when they ran)."
        )


def write_report(
    study: Study,
    result: Result,
    out: Path,
    times: SessionTimes,
    *,
    text: str,
    figures: Sequence[str | Path] = (),
    paper: Sequence[str] = (),
    title: str = "",
) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.html`` into ``out``; return their paths.

    ``text`` is the report printed at the end of the run (``report.txt``), ``figures`` the
    image files the session made, ``paper`` the markdown lines of the comparison with the
    paper (:func:`fbia.studies.paper_report.paper_section`), ``title`` the page's heading
    (default: the study's name)."""
    title = title or study.name
    page = _markdown(study, result, out, times, text, figures, paper, title)
    out.mkdir(parents=True, exist_ok=True)
    md_path = out / MARKDOWN_NAME
    md_path.write_text(page, encoding="utf-8")
    html_path = out / HTML_NAME
    html_path.write_text(render_html(page, out, title), encoding="utf-8")
    return md_path, html_path


def _markdown(
    study: Study,
    result: Result,
    out: Path,
    times: SessionTimes,
    text: str,
    figures: Sequence[str | Path],
    paper: Sequence[str],
    title: str,
) -> str:
    lines = [f"# {title}", "", f"Study file `{study.path.name}`; result: **{result.status}**."]
    if not result.success or result.status == "unreliable":
        lines += ["", f"> **Not a result to use as it is ({result.status}):** {result.message}"]
    else:
        lines += ["", result.message]
    lines += ["", times.sentence(), ""]
    lines += paper
    lines += ["## Result", "", "```text", text.rstrip("\n"), "```", ""]
    warnings = list(result.provenance.get("warnings", []) or [])
    if warnings:
        lines += ["## Warnings", "", *(f"- {w}" for w in warnings), ""]
    lines += _oct_lines(study, out)
    lines += ["## Settings", "", *settings_lines(study), ""]
    shown = _figures(figures, out)
    if shown:
        lines += ["## Figures", ""]
        for rel in shown:
            lines += [f"![{rel}]({rel})", "", f"*{rel}*", ""]
    files = _files(out)
    if files:
        lines += ["## Files", "", *(f"- `{f}`" for f in files), ""]
    return "\n".join(lines)


def _oct_lines(study: Study, out: Path) -> list[str]:
    """The segmentation of every OCT scan of the study: the kind of surface, whether it is
    one surface, the structure parameters, and its B-scan figure (window, substratum and
    interface drawn on the scan)."""
    if not study.oct_records:
        return []
    lines = ["## OCT segmentation", ""]
    for record in study.oct_records:
        seg = record.scan.segmentation
        st = seg.structure
        window = "none found" if seg.window_row is None else f"row {seg.window_row:.1f}"
        lines += [
            f"### [[observations]] #{record.observation}: `{record.scan.file.name}`",
            "",
            f"Surface: {seg.surface_kind.replace('_', ' ')}; {seg.quality.note()}. Substratum row "
            f"{seg.substratum_row}, tilt {seg.tilt[0]:.3g} / {seg.tilt[1]:.3g} rows per "
            f"A-scan (y / x); window {window}; threshold {seg.threshold:.4g}.",
            "",
            "| thickness mean (field / covered) | max | std | biovolume per area | coverage "
            "| Ra | Rq | Ra* | porosity |",
            "|---|---|---|---|---|---|---|---|---|",
            f"| {1000 * st.mean_thickness:.1f} / {1000 * st.mean_thickness_covered:.1f} um "
            f"| {1000 * st.max_thickness:.1f} um | {1000 * st.std_thickness:.1f} um "
            f"| {1000 * st.biovolume_per_area:.2f} um^3/um^2 | {100 * st.coverage:.0f} % "
            f"| {1000 * st.ra:.1f} um | {1000 * st.rq:.1f} um | {st.roughness_coefficient:.2f} "
            f"| {100 * st.porosity:.1f} % |",
            "",
        ]
        bscan = out / record.folder / "oct_bscan.png"
        if bscan.is_file():
            rel = Path(os.path.relpath(bscan, out)).as_posix()
            lines += [f"![{rel}]({rel})", "", f"*{rel}*", ""]
    return lines


def _figures(figures: Sequence[str | Path], out: Path) -> list[str]:
    """The images among ``figures`` that exist, relative to ``out``, once each, in order."""
    seen: list[str] = []
    for f in figures:
        path = Path(f)
        if path.suffix.lower() in (".png", ".svg", ".jpg", ".jpeg") and path.is_file():
            rel = Path(os.path.relpath(path, out)).as_posix()
            if rel not in seen:
                seen.append(rel)
    return seen


def _files(out: Path) -> list[str]:
    """The output folder's files and folders besides the reports (what else a reader finds)."""
    skip = {MARKDOWN_NAME, HTML_NAME}
    entries = sorted(
        p
        for p in out.iterdir()
        if p.name not in skip
        and not p.name.startswith(".")
        and not p.name.endswith(("-shm", "-wal", "-journal"))  # SQLite's, while it is open
    )
    return [p.name + ("/" if p.is_dir() else "") for p in entries]


def settings_lines(study: Study) -> list[str]:
    """The study's settings as markdown list items: model, measure and iterator options (those
    the study file sets, then those that differ from the default for another reason, e.g. a
    seed from the study), parameters, synthetic data, fixed inputs, executor and seed."""

    def opts(obj: Any, section: str) -> str:
        raw = study.raw.get(section, {})
        written = dict(raw.get("options", {})) if isinstance(raw, dict) else {}
        given = {**written, **plugin_options(obj, exclude_defaults=True)}
        text = ", ".join(f"{k} = {v!r}" for k, v in given.items())
        return f"{text}; the other options at their defaults" if text else "defaults"

    lines = [
        f"- model `{study.model_name}`: {opts(study.model, 'model')}",
        f"- measure `{study.measure_name}`: {opts(study.measure, 'measure')}",
    ]
    if study.iterator is not None:
        lines.append(f"- iterator `{study.iterator_name}`: {opts(study.iterator, 'iterator')}")
    params = "; ".join(
        f"{p.name} in [{p.bounds[0]:g}, {p.bounds[1]:g}]" if p.bounds else p.name
        for p in study.parameters
    )
    lines.append(f"- parameters: {params}")
    if study.synthetic is not None:
        s = study.synthetic
        truth = ", ".join(f"{k} = {v:g}" for k, v in s.truth.items())
        pts = f", {s.points} measurement points" if s.points else ""
        lines.append(
            f"- synthetic data: truth {truth}; noise {s.noise_std:g} mm ({s.noise}, seed "
            f"{s.seed}){pts}; states {s.coordinates}"
        )
    if study.fixed:
        lines.append(f"- fixed: {study.fixed}")
    lines.append(f"- executor: {study.executor.label()}; seed {study.seed}")
    return lines


# -- HTML --------------------------------------------------------------------------------------
_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 72rem; margin: 2rem auto; padding: 0 1rem;
       line-height: 1.45; color: #1b1b1b; }
table { border-collapse: collapse; margin: 1rem 0; font-size: 0.92rem; }
th, td { border: 1px solid #c8c8c8; padding: 0.25rem 0.5rem; text-align: left;
         vertical-align: top; }
th { background: #f0f0f0; }
pre { background: #f6f6f6; padding: 0.75rem; overflow-x: auto; font-size: 0.85rem; }
blockquote { border-left: 4px solid #c0392b; margin: 1rem 0; padding: 0.25rem 1rem;
             background: #fbeeee; }
img { max-width: 100%; border: 1px solid #ddd; }
"""

#: no script, nothing from outside the file: images only as data: URIs, style only inline
_POLICY = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"

_IMG_SRC = re.compile(r'(<img\b[^>]*?\bsrc=")([^"]+)(")')


def render_html(page: str, folder: Path, title: str) -> str:
    """The markdown ``page`` as one self-contained HTML document: the images it names
    (relative to ``folder``) embedded, the style inline."""
    body = markdown.markdown(page, extensions=["tables", "fenced_code"], output_format="html")
    body = _IMG_SRC.sub(lambda m: m.group(1) + _data_uri(folder, m.group(2)) + m.group(3), body)
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f'<meta http-equiv="Content-Security-Policy" content="{_POLICY}">\n'
        f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n"
        f"<body>\n{body}\n</body>\n</html>\n"
    )


def _data_uri(folder: Path, src: str) -> str:
    """An image file of ``folder`` as a ``data:`` URI (left as it is when it is not a file of
    the folder: the policy then keeps the browser from fetching it)."""
    path = (folder / html.unescape(src)).resolve()
    if not path.is_file() or not path.is_relative_to(folder.resolve()):
        return src
    kind = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    return f"data:{kind};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"
