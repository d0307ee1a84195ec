"""What a study writes into its output folder, and where each part comes from.

::

    output/
      store.sqlite          every forward run of every session (fbia.storage.store)
      evaluations.jsonl     this session's records, one JSON line each, as the iterator gets them
                            (runs reused from the store included, marked "reused": true;
                            fbia.studies.evaluation_log; residual vectors longer than
                            fbia.core.problem.JSON_RESIDUALS_MAX only as n_residuals)
      fbia.log              what was printed, one line per record and batch, per session
                            (fbia.studies.progress)
      runs/                 one working folder per run (failed runs' kept; all with keep_runs)
      result.json           the Result (status, message, x, history, provenance
                            (fbia.studies.provenance), evaluations)
      report.txt            the summary and the discrepancy table printed at the end (here,
                            with fbia.studies.tables)
      report.md             status, times, that text, settings, figures, files, and the
      report.html           comparison with a [paper] table; the HTML self-contained
                            (fbia.studies.study_report, fbia.studies.paper_report)
      interfaces/           observed and simulated interfaces: CSV (2-D) and VTU (2-D, 3-D)
      plots/                interfaces.png, evaluations.png (fbia.studies.plots), and the
                            iterator's own plots

This module writes the interfaces, copies the model's field files and composes the report.
"""

from __future__ import annotations

import re
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.interface import Interface
from ..core.observation import Coordinate, Observation, Solution
from ..core.problem import InverseProblem
from .tables import format_table

__all__ = ["copy_fields", "result_report", "state_label", "write_interfaces"]


# -- interfaces --------------------------------------------------------------------------------
def state_label(coordinate: Coordinate) -> str:
    """A file-name-safe label of a coordinate, e.g. ``inflow_rate_100``."""
    if not coordinate:
        return "state"
    text = "_".join(f"{k}_{float(v):g}" for k, v in coordinate.items())
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", text)


def write_interfaces(
    folder: Path,
    problem: InverseProblem,
    solution: Solution | None,
    observed: bool = True,
) -> list[Path]:
    """Write the observed and the simulated interface of every state of ``problem``.

    2-D interfaces go to CSV (x, y, curve) and VTU, 3-D ones to VTU; measurement points to
    CSV.  Returns the paths written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def put(gamma: Interface, stem: str) -> None:
        if gamma.dim == 2:
            written.append(gamma.write(folder / f"{stem}.csv"))
        written.append(gamma.write(folder / f"{stem}.vtu"))

    labels = _observation_labels(problem.observations)
    if observed:
        for obs, label in zip(problem.observations, labels, strict=True):
            if obs.interface is not None:
                put(obs.interface, f"observed_{label}")
            mp = obs.measurement_points
            if mp is not None:
                written.append(mp.write(folder / f"points_{label}.csv"))
    if solution is not None:
        for coord in problem.coordinates():
            put(solution.interface(coord), f"simulated_{state_label(coord)}")
    return written


def _observation_labels(observations: Sequence[Observation]) -> list[str]:
    labels: list[str] = []
    for k, obs in enumerate(observations):
        label = state_label(obs.coordinate)
        if label in labels:
            label = f"{label}_{k}"
        labels.append(label)
    return labels


def copy_fields(solution: Solution, folder: Path, root: Path | None = None) -> dict[str, Path]:
    """Copy the field files of a solution into ``folder``, unless they already lie below
    ``root`` (the output folder); files that a model named but did not write are left out."""
    out: dict[str, Path] = {}
    for name, src in solution.fields.items():
        src = Path(src)
        if not src.exists():
            continue
        if root is not None and src.resolve().is_relative_to(root.resolve()):
            out[name] = src
            continue
        folder.mkdir(parents=True, exist_ok=True)
        dst = folder / src.name
        if src.is_dir():
            shutil.copytree(src, dst, dirs_exist_ok=True)
        else:
            shutil.copy2(src, dst)
        out[name] = dst
    return out


def result_report(
    name: str, result: Any, output: Path, truth: Mapping[str, float] | None = None
) -> str:
    """The text printed at the end of a study and saved as ``report.txt``: the result's own
    ``summary()`` (iterator-specific: e.g. the multi-start table of Levenberg-Marquardt), the
    ground truth of synthetic data, and the discrepancy table at the result's ``x``."""
    lines = [f"== {name} ==", result.summary()]
    if truth:
        lines.append(
            "  ground truth of the synthetic data: "
            + ", ".join(f"{k} = {v:.6g}" for k, v in truth.items())
        )
    rows = result.provenance.get("discrepancy")
    if rows:
        where = "at x" if result.iterator else "of the forward run"
        lines += ["", f"discrepancy {where}:", format_table(rows)]
    lines += ["", f"output: {output}"]
    return "\n".join(lines)
