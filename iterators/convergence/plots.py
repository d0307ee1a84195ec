"""Figures of a ``surrogate_convergence`` result (Paper B Figs. 8 and 12; matplotlib, Agg).

``surrogate_convergence.png``: per input, the ML point of the GP over n_train (the reference
as a dashed line), and the GP's error at the held-out runs over n_train.
``surrogate_convergence_fields.png``: for up to six sizes, the likelihood exp(L - max L) of
the GP over the first two inputs (a section at the ML point through the others), its training
runs as circles, failed runs as grey crosses, the ML point as a green cross (Fig. 8).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ...core.parameters import Parameter
from ...figures import legend
from ..surrogates.design import search_box
from .result import SurrogateConvergenceResult


def plot_surrogate_convergence(
    result: SurrogateConvergenceResult, inputs: Sequence[Parameter], folder: str | Path
) -> list[Path]:
    """Write both figures into ``folder`` (the fields only with two or more inputs)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = [_convergence(result, inputs, folder)]
    if len(inputs) >= 2:
        out.append(_fields(result, inputs, folder))
    return out


def _label(p: Parameter) -> str:
    return f"{p.name} [{p.unit}]" if p.unit else p.name


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def _convergence(r: SurrogateConvergenceResult, inputs: Sequence[Parameter], folder: Path) -> Path:
    sizes = [row.n_train for row in r.rows]
    fig = Figure(figsize=(4.2 * (len(inputs) + 1), 3.6))
    axes = fig.subplots(1, len(inputs) + 1)
    for ax, p in zip(axes, inputs, strict=False):
        ax.semilogx(sizes, [row.ml_point[p.name] for row in r.rows], "o-", c="tab:green")
        if r.reference is not None:
            ax.axhline(r.reference[p.name], ls="--", c="k", lw=0.8, label="reference")
            legend(ax, fontsize=7)
        ax.set(xlabel="n_train", ylabel=_label(p), title=f"ML point of the GP: {p.name}")
    ax = axes[-1]
    rmse = [row.test_rmse for row in r.rows]
    if np.any(np.isfinite(rmse)):
        ax.loglog(sizes, rmse, "o-", label="RMSE")
        ax.loglog(sizes, [row.test_max_abs for row in r.rows], "s--", label="largest error")
        legend(ax, fontsize=7)
    held_out = int(np.isfinite(r.log_likelihood[len(r.log_likelihood) - r.n_test :]).sum())
    ax.set(
        xlabel="n_train",
        ylabel="error of the GP mean of L",
        title=f"at {held_out} held-out runs (n_test = {r.n_test})",
    )
    ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("GP surrogate of L over n_train (Paper B Figs. 8, 12)")
    return _save(fig, folder / "surrogate_convergence.png")


def _fields(r: SurrogateConvergenceResult, inputs: Sequence[Parameter], folder: Path) -> Path:
    rows = r.rows[-6:]
    lower, upper = search_box(inputs, r.points)
    ga, gb = np.linspace(lower[0], upper[0], 60), np.linspace(lower[1], upper[1], 60)
    mesh_a, mesh_b = np.meshgrid(ga, gb)
    ok = np.isfinite(r.log_likelihood)
    index = np.arange(len(ok))
    fig = Figure(figsize=(13, 4.2 * ((len(rows) + 2) // 3)))
    axes = np.atleast_1d(fig.subplots((len(rows) + 2) // 3, min(3, len(rows)))).ravel()
    for ax, row in zip(axes, rows, strict=False):
        gp = row.surrogate()
        ml = np.array([row.ml_point[p.name] for p in inputs])
        pts = np.tile(ml, (mesh_a.size, 1))
        pts[:, 0], pts[:, 1] = mesh_a.ravel(), mesh_b.ravel()
        mean = gp.predict_mean(pts)
        field = np.exp(mean - mean.max()).reshape(mesh_a.shape)
        ax.contourf(mesh_a, mesh_b, field, 30, cmap="viridis")
        first = index < row.n_train
        ax.scatter(*r.points[first & ok, :2].T, s=8, facecolors="none", edgecolors="k", lw=0.5)
        ax.scatter(*r.points[first & ~ok, :2].T, s=12, marker="x", c="0.55")
        ax.plot(ml[0], ml[1], "x", c="tab:green", ms=10, mew=2.5, label="ML point")
        if r.reference is not None:
            ax.plot(r.reference[inputs[0].name], r.reference[inputs[1].name], "*", c="w", ms=9)
        ax.set(title=f"n_train = {row.n_train}", xlabel=_label(inputs[0]), ylabel=_label(inputs[1]))
    for ax in axes[len(rows) :]:
        ax.set_visible(False)
    fig.suptitle("likelihood exp(L - max L) of the GP over n_train (Paper B Fig. 8)")
    return _save(fig, folder / "surrogate_convergence_fields.png")
