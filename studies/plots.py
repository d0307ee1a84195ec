"""The study's own figures (matplotlib, Agg): the interfaces, the evaluations."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..core.observation import Solution
from ..core.problem import Evaluation, InverseProblem, Result
from ..figures import legend, pyplot

__all__ = ["plot_evaluations", "plot_interfaces"]


# -- plots -------------------------------------------------------------------------------------
def plot_interfaces(
    path: Path, problem: InverseProblem, solution: Solution | None, title: str = ""
) -> Path | None:
    """Observed (and simulated) 2-D interfaces of every state, and below them the measure's
    residuals at the simulated ones in µm (a misfit of micrometres is invisible on the mm
    axes of the interfaces); None for 3-D."""
    if problem.dim != 2:
        return None
    plt = pyplot()
    residuals = _residuals_um(problem, solution)
    if residuals:
        fig, (ax, rax) = plt.subplots(2, 1, figsize=(7, 5.5), gridspec_kw={"height_ratios": [2, 1]})
    else:
        fig, ax = plt.subplots(figsize=(7, 3.5))
        rax = None
    for k, obs in enumerate(problem.observations):
        colour = f"C{k % 10}"
        if obs.interface is not None:
            for j, curve in enumerate(obs.interface.curves()):
                ax.plot(
                    curve[:, 0],
                    curve[:, 1],
                    ".",
                    ms=3,
                    color=colour,
                    label=f"observed {obs.label()}" if j == 0 else None,
                )
        mp = obs.measurement_points
        if mp is not None:
            ax.plot(mp.points[:, 0], mp.points[:, 1], "x", color=colour, ms=5)
        if solution is not None:
            gamma = solution.interface(obs.coordinate)
            for j, curve in enumerate(gamma.curves()):
                ax.plot(
                    curve[:, 0],
                    curve[:, 1],
                    "-",
                    lw=1.2,
                    color=colour,
                    label=f"simulated {obs.label()}" if j == 0 else None,
                )
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    legend(ax, fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    if rax is not None:
        for k, r in residuals:
            obs = problem.observations[k]
            rms = float(np.sqrt(np.mean(r**2)))
            label = f"{obs.label()}: rms {rms:.3g} µm"
            rax.plot(np.arange(len(r)), r, ".-", ms=3, lw=0.8, color=f"C{k % 10}", label=label)
        rax.axhline(0.0, color="0.6", lw=0.6)
        rax.set_xlabel(f"residual index ({type(problem.measure).__name__})")
        rax.set_ylabel("residual [µm]")
        legend(rax, fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _residuals_um(problem: InverseProblem, solution: Solution | None) -> list[tuple[int, Any]]:
    """(observation index, residuals in µm) at the simulated interfaces, where the measure
    gives them (a measure that fails there, or gives none, is left out)."""
    if solution is None:
        return []
    out = []
    for k, obs in enumerate(problem.observations):
        try:
            r = np.asarray(problem.measure.residuals(solution.interface(obs.coordinate), obs))
        except Exception:  # a plot never stops a study: the report says what failed
            continue
        if r.ndim == 1 and 0 < len(r) <= 100_000 and np.all(np.isfinite(r)):
            out.append((k, 1000.0 * r))
    return out


def plot_evaluations(
    path: Path,
    records: Sequence[Evaluation],
    names: Sequence[str],
    units: Sequence[str] = (),
    truth: Mapping[str, float] | None = None,
) -> Path | None:
    """Distance D of every evaluation in order (log scale), and for two parameters the
    evaluated points in parameter space coloured by log10 D (failed runs as red crosses, the
    ground truth of synthetic data as a white cross)."""
    if not records:
        return None
    plt = pyplot()
    two = len(names) == 2
    fig, axes = plt.subplots(1, 2 if two else 1, figsize=(10 if two else 5.5, 4), squeeze=False)
    ok = [r for r in records if r.ok and r.distance > 0 and math.isfinite(r.distance)]
    bad = [r for r in records if not r.ok]
    ax = axes[0, 0]
    ax.semilogy([r.index for r in ok], [r.distance for r in ok], ".", ms=4)
    ax.set_xlabel("evaluation")
    ax.set_ylabel("D")
    ax.set_title(f"{len(records)} evaluations, {len(bad)} failed", fontsize=9)
    if two:
        units = list(units) + [""] * 2
        ax = axes[0, 1]
        x0 = [r.x.get(names[0], math.nan) for r in ok]
        x1 = [r.x.get(names[1], math.nan) for r in ok]
        sc = ax.scatter(x0, x1, c=np.log10([r.distance for r in ok]), s=10, cmap="viridis")
        fig.colorbar(sc, ax=ax, label="log10 D")
        if bad:
            ax.plot(
                [r.x.get(names[0], math.nan) for r in bad],
                [r.x.get(names[1], math.nan) for r in bad],
                "x",
                color="red",
                label="failed",
            )
        if truth and names[0] in truth and names[1] in truth:
            ax.plot([truth[names[0]]], [truth[names[1]]], "P", color="k", mfc="w", ms=10,
                    label="ground truth")  # fmt: skip
        legend(ax, fontsize=8)
        ax.set_xlabel(f"{names[0]} [{units[0]}]" if units[0] else names[0])
        ax.set_ylabel(f"{names[1]} [{units[1]}]" if units[1] else names[1])
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot(result: Result, problem: InverseProblem, folder: str | Path = "plots") -> list[Path]:
    """Draw ``result``'s figures into ``folder`` as ``fbia run`` does; returns their paths.

    The figures of the iterator that made it (``write_plots`` of the registered iterator named
    ``result.iterator``: LM search paths and error histories, gp_smc posterior and marginals,
    ...) and the evaluations plot of its forward runs.  ``problem`` is the one the result
    solved, for the parameters' units and priors and the ground truth of synthetic data
    (marked): ``fbia.load_study(study_file).problem``.

    >>> study = fbia.load_study("examples/flow_cell/study.toml")      # doctest: +SKIP
    >>> fbia.plot(fbia.load_result("examples/flow_cell/output"), study.problem)  # doctest: +SKIP
    """
    from ..core.registry import default_registry

    out = Path(folder)
    made: list[Path] = []
    if result.iterator:
        iterator = default_registry().create("iterator", result.iterator, {}, where="fbia.plot")
        made += [Path(p) for p in iterator.write_plots(result, problem, out)]
    units = [p.unit for p in problem.parameters]
    path = plot_evaluations(
        out / "evaluations.png", result.evaluations, problem.names, units, problem.truth
    )
    return made + ([path] if path is not None else [])
