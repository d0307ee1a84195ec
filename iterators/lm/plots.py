"""Figures of a Levenberg–Marquardt analysis (Paper A Figs. 4-8, 11-13, 17-18, 22-23).

>>> import numpy as np, fbia, tempfile
>>> from fbia.iterators.lm.plots import plot_lm_result
>>> t = np.linspace(0.0, 4.0, 20)
>>> res = fbia.least_squares(lambda b: b[0] * np.exp(-b[1] * t) - 3.0 * np.exp(-0.7 * t),
...                          [[1.0, 1.0], [5.0, 0.2]], names=["a", "k"])
>>> sorted(p.name for p in plot_lm_result(res, None, tempfile.mkdtemp()))
['lm_errors.png', 'lm_search_paths.png']

* ``lm_search_paths.png`` (two parameters): the path of every start in parameter space, one
  marker per iteration (declined steps as crosses), over filled contours of log10(err_res)
  interpolated between every evaluation of the run (a triangulation of the scattered points).
* ``lm_parameter_paths.png`` (one or more than two parameters): each parameter over the
  iterations, one line per start.
* ``lm_errors.png``: err_res (eq. 25), err_grad (eq. 24) and μ over the iterations on log
  scales (μ = 0, a Gauss–Newton step of the robust mode, is left out).

Matplotlib is used through its object interface with the Agg canvas: no pyplot state, no
display needed.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...figures import legend
from .result import LMResult

FloatArray = NDArray[np.float64]


def plot_lm_result(result: LMResult, problem: Any, folder: str | Path) -> list[Path]:
    """Write the search paths and the error histories of ``result`` as PNG files.

    Parameters
    ----------
    result
        The result of :class:`~fbia.iterators.levenberg_marquardt.LevenbergMarquardtIterator`
        or :func:`~fbia.iterators.least_squares.least_squares`.
    problem
        The inverse problem (for parameter units and bounds) or None.
    folder
        Output folder (created if needed).

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    names = list(result.names)
    units = _units(problem, names)
    truth = dict(getattr(problem, "truth", None) or {})  # synthetic data: marked in the paths
    chains = sorted({h["chain"] for h in result.history})
    files = [_errors(result, chains, out / "lm_errors.png")]
    if len(names) == 2:
        path = out / "lm_search_paths.png"
        files.append(_paths_2d(result, chains, names, units, path, truth))
    elif names:
        path = out / "lm_parameter_paths.png"
        files.append(_paths_1d(result, chains, names, units, path, truth))
    return files


def _units(problem: Any, names: list[str]) -> dict[str, str]:
    units = {n: "" for n in names}
    for p in getattr(problem, "parameters", ()) or ():
        name, unit = str(getattr(p, "name", "")), str(getattr(p, "unit", "") or "")
        if name in units and unit:
            units[name] = f" [{unit}]"
    return units


def _figure(nrows: int, ncols: int, size: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    # fixed margins: a layout engine costs more than drawing these small figures
    fig.subplots_adjust(left=0.09, right=0.97, bottom=0.12, top=0.9, wspace=0.32, hspace=0.4)
    return fig, axes


def _colour(chain: int) -> Any:
    from matplotlib import colormaps

    return colormaps["tab10" if chain < 10 else "tab20b"](chain % (10 if chain < 10 else 20))


def _accepted(result: LMResult, chain: int) -> list[dict[str, Any]]:
    return [h for h in result.history if h["chain"] == chain and h["accepted"]]


def _label(result: LMResult, chain: int) -> str:
    row = next((s for s in result.starts if s["start"] == chain + 1), None)
    if row is None:
        return f"start {chain + 1}"
    x0 = ", ".join(f"{v:.3g}" for v in row["x0"].values())
    return f"start {chain + 1} ({x0}): {row['status']}"


def _errors(result: LMResult, chains: list[int], path: Path) -> Path:
    fig, axes = _figure(1, 3, (13.0, 4.0))
    keys = [
        ("err_res", "err_res (eq. 25)"),
        ("err_grad", "err_grad (eq. 24)"),
        ("mu", "μ (0 = Gauss–Newton step, not shown)"),
    ]
    for ax, (key, title) in zip(axes[0], keys, strict=True):
        for c in chains:
            hist = _accepted(result, c)
            it = np.array([h["iteration"] for h in hist], dtype=float)
            val = np.array([np.nan if h[key] is None else h[key] for h in hist], dtype=float)
            val[~(val > 0)] = np.nan  # log scale: zeros (μ of Gauss–Newton steps) left out
            ax.plot(it, val, "o-", ms=3, color=_colour(c), label=_label(result, c))
        ax.set_yscale("log")
        ax.set_xlabel("iteration")
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
    legend(axes[0][0], fontsize=7)
    fig.savefig(path, dpi=110)
    return path


def _paths_2d(
    result: LMResult,
    chains: list[int],
    names: list[str],
    units: dict[str, str],
    path: Path,
    truth: dict[str, float],
) -> Path:
    fig, axes = _figure(1, 1, (7.0, 5.5))
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.1, top=0.93)
    ax = axes[0][0]
    a, b = names
    pts = [
        (e.x[a], e.x[b], float(np.linalg.norm(e.residuals) / math.sqrt(len(e.residuals))))
        for e in result.evaluations
        if e.ok and e.residuals is not None and a in e.x and b in e.x
    ]
    if len(pts) >= 3:
        _contour(fig, ax, np.array(pts))
    for c in chains:
        hist = _accepted(result, c)
        xs = [h["x"][a] for h in hist]
        ys = [h["x"][b] for h in hist]
        ax.plot(xs, ys, "o-", ms=4, color=_colour(c), label=_label(result, c))
        if xs:
            ax.plot(xs[:1], ys[:1], "s", ms=7, color=_colour(c))
            ax.plot(xs[-1:], ys[-1:], "*", ms=12, color=_colour(c), mec="k")
        declined = [h for h in result.history if h["chain"] == c and not h["accepted"]]
        ax.plot(
            [h["x"][a] for h in declined],
            [h["x"][b] for h in declined],
            "x",
            ms=5,
            color=_colour(c),
        )
    if a in truth and b in truth:
        ax.plot([truth[a]], [truth[b]], "P", ms=11, color="k", mfc="w", label="ground truth")
    ax.set_xlabel(a + units[a])
    ax.set_ylabel(b + units[b])
    ax.set_title("search paths (square: start, star: result, cross: declined step)")
    legend(ax, fontsize=7)
    fig.savefig(path, dpi=110)
    return path


def _contour(fig: Any, ax: Any, pts: FloatArray) -> None:
    """Filled contours of log10(err_res) over scattered evaluations (triangulated in
    coordinates scaled to the unit square, so that E ~ 400 and ν ~ 0.3 mesh alike)."""
    from matplotlib.tri import Triangulation

    xy = np.unique(pts, axis=0)
    lo, hi = xy[:, :2].min(axis=0), xy[:, :2].max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    unit = (xy[:, :2] - lo) / span
    try:
        tri = Triangulation(unit[:, 0], unit[:, 1])
    except (ValueError, RuntimeError):  # all points on a line: no contour to draw
        return
    if len(tri.triangles) == 0:
        return
    z = np.log10(np.maximum(xy[:, 2], np.finfo(float).tiny))
    scaled = Triangulation(xy[:, 0], xy[:, 1], tri.triangles)
    filled = ax.tricontourf(scaled, z, levels=20, cmap="viridis", alpha=0.6)
    fig.colorbar(filled, ax=ax, label="log10 err_res (evaluations)")


def _paths_1d(
    result: LMResult,
    chains: list[int],
    names: list[str],
    units: dict[str, str],
    path: Path,
    truth: dict[str, float],
) -> Path:
    n = len(names)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = _figure(rows, cols, (4.2 * cols, 3.2 * rows))
    flat = [ax for row in axes for ax in row]
    for ax, name in zip(flat, names, strict=False):
        for c in chains:
            hist = _accepted(result, c)
            ax.plot(
                [h["iteration"] for h in hist],
                [h["x"][name] for h in hist],
                "o-",
                ms=3,
                color=_colour(c),
                label=_label(result, c),
            )
        if name in truth:
            ax.axhline(truth[name], color="k", ls="--", lw=0.8, label="ground truth")
        ax.set_xlabel("iteration")
        ax.set_ylabel(name + units[name])
        ax.grid(True, alpha=0.3)
    for ax in flat[n:]:
        ax.set_visible(False)
    legend(flat[0], fontsize=7)
    fig.savefig(path, dpi=110)
    return path
