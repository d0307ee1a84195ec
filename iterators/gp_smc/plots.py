"""Figures of a gp_smc result, after Paper B Figs. 5-9 and 12-15 (matplotlib, Agg, no pyplot).

::

    paths = plot_gp_smc_result(result, problem, "output")   # or GpSmcIterator.write_plots

Files written (those that apply to the result):

=============================  ==================================================================
``surrogate_fields.png``       GP mean of L, normalised likelihood exp(L - max L) and GP standard
                               deviation over the first two parameters, training runs as circles,
                               failed runs as grey crosses (Figs. 5-7)
``gp_convergence.png``         GP likelihood for growing prefixes of the Sobol design (Fig. 8)
``gp_error.png``               error of the GP mean at held-out runs (or LOO) over n_train (Fig. 12)
``posterior.png``              weighted hexbin of the posterior of the first two parameters with
                               marginal histograms, KDE percentile lines, global Gaussian and
                               Laplace approximations, MAP and PM, priors (Fig. 9a/c/d)
``particles.png``              particles with weights as size and colour (Fig. 9b)
``marginals_1d.png``           1-D marginals with KDE and prior (Fig. 13)
``marginals_2d.png``           pairwise 2-D marginals with KDE percentile lines (Fig. 14)
``parallel_axes.png``          parallel-axis plot of particles over all parameters, theta and the
                               log-posterior (Fig. 15)
=============================  ==================================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray
from scipy.stats import chi2, gaussian_kde

from ...core.errors import ConfigError
from ...core.likelihood import noise_parameter
from ...core.parameters import Parameter
from ...core.problem import InverseProblem
from ...figures import legend
from ..smc.sampler import systematic_resample
from ..surrogates.gp import GpSurrogate
from .result import DesignRuns, GpSmcResult, ParticlePosterior, SurrogateFit

FloatArray = NDArray[np.float64]
#: Probability mass inside the KDE / Gaussian percentile lines.
LEVELS = (0.1, 0.5, 0.9)
_MAP_COLOUR, _PM_COLOUR, _PRIOR_COLOUR = "tab:green", "tab:orange", "tab:red"


FIGURES = (
    "surrogate_fields",
    "gp_convergence",
    "gp_error",
    "posterior",
    "particles",
    "marginals_2d",
    "marginals_1d",
    "parallel_axes",
)


def plot_gp_smc_result(
    result: GpSmcResult,
    problem: InverseProblem,
    folder: str | Path,
    figures: Sequence[str] | None = None,
) -> list[Path]:
    """Write the figures listed in the module docstring into ``folder``; return their paths.

    ``figures`` selects some of :data:`FIGURES` (default: all that apply to the result).
    """
    wanted = set(FIGURES if figures is None else figures)
    unknown = sorted(wanted - set(FIGURES))
    if unknown:
        raise ConfigError(
            f"unknown figure(s) {', '.join(unknown)}; valid: {', '.join(FIGURES)}", "write_plots"
        )
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    r = result
    inputs = [*problem.parameters, *problem.uncertain]
    out: list[Path] = []
    if result.status == "all_failed" or r.posterior is None:
        if r.design is not None and r.design.points.shape[1] >= 2:
            out.append(_design_only(r, inputs, folder))
        return out
    labels = [_label(p) for p in inputs]
    truth = dict(getattr(problem, "truth", None) or {})  # synthetic data: marked
    # the posterior's inputs: the design's, and sigma_N when it was inferred
    noise = noise_parameter(problem)
    sampled = inputs if noise is None else [*inputs, noise]
    sampled_labels = [_label(p) for p in sampled]
    n_x = int(_post(r).n_x)
    refits: dict[int, GpSurrogate | None] = {}
    surrogate = r.surrogate is not None
    if surrogate and n_x >= 2 and "surrogate_fields" in wanted:
        gp = _fit(r).surrogate()
        out.append(_surrogate_fields(gp, r, inputs, labels, folder))
    if surrogate and len(inputs) == 2 and "gp_convergence" in wanted:
        out.append(_gp_convergence(r, inputs, labels, folder, refits))
    if surrogate and "gp_error" in wanted:
        out.append(_gp_error(r, folder, refits))
    if n_x >= 2 and "posterior" in wanted:
        out.append(_posterior_2d(r, inputs, labels, folder, truth))
    if n_x >= 2 and "particles" in wanted:
        out.append(_particles(r, labels, folder))
    if n_x >= 2 and "marginals_2d" in wanted:
        out.append(_pairwise(r, sampled, sampled_labels, folder, truth))
    if "marginals_1d" in wanted:
        out.append(_marginals(r, sampled, sampled_labels, folder, truth))
    if "parallel_axes" in wanted:
        out.append(_parallel_axes(r, sampled_labels, folder))
    return out


# -- helpers ------------------------------------------------------------------------------------
def _post(r: GpSmcResult) -> ParticlePosterior:
    assert r.posterior is not None  # plots of the posterior only run with one
    return r.posterior


def _design(r: GpSmcResult) -> DesignRuns:
    assert r.design is not None  # surrogate-mode plots only
    return r.design


def _fit(r: GpSmcResult) -> SurrogateFit:
    assert r.surrogate is not None  # surrogate-mode plots only
    return r.surrogate


def _label(p: Parameter) -> str:
    return f"{p.name} [{p.unit}]" if p.unit else p.name


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=90, bbox_inches="tight")  # a long title on a narrow figure: not cut
    return path


def _box(p: Parameter, values: FloatArray) -> tuple[float, float]:
    if p.bounds is not None:
        return p.bounds
    lo, hi = float(np.min(values)), float(np.max(values))
    pad = 0.05 * (hi - lo or 1.0)
    return lo - pad, hi + pad


def _fixed_rest(r: GpSmcResult, inputs: Sequence[Parameter]) -> FloatArray:
    """Values of inputs 3.. in the 2-D sections: x at the MAP, theta at its prior median."""
    n_x = int(_post(r).n_x)
    rest = []
    for j, p in enumerate(inputs):
        if j < n_x:
            rest.append(float(np.asarray(_post(r).map)[j]))
        elif p.prior is not None:
            rest.append(float(p.prior.ppf(0.5)))
        else:
            assert p.bounds is not None  # a Parameter has a prior or bounds
            rest.append(float(np.mean(p.bounds)))
    return np.array(rest)


def _grid(inputs, r, n=80):
    particles = np.asarray(_post(r).particles)
    (a0, a1), (b0, b1) = _box(inputs[0], particles[:, 0]), _box(inputs[1], particles[:, 1])
    ga, gb = np.linspace(a0, a1, n), np.linspace(b0, b1, n)
    mesh_a, mesh_b = np.meshgrid(ga, gb)
    pts = np.tile(_fixed_rest(r, inputs), (mesh_a.size, 1))
    pts[:, 0], pts[:, 1] = mesh_a.ravel(), mesh_b.ravel()
    return mesh_a, mesh_b, pts


def _design_points(ax, r: GpSmcResult, train_only: bool = True) -> None:
    design = np.asarray(_design(r).points)
    ok = np.isfinite(np.asarray(_design(r).log_likelihood))
    mask = np.asarray(_design(r).train_mask) if train_only else np.ones(len(ok), bool)
    ax.scatter(
        design[mask & ok, 0],
        design[mask & ok, 1],
        s=10,
        facecolors="none",
        edgecolors="k",
        linewidths=0.5,
        label="training runs",
    )
    if np.any(mask & ~ok):
        ax.scatter(
            design[mask & ~ok, 0],
            design[mask & ~ok, 1],
            s=14,
            marker="x",
            c="0.55",
            linewidths=0.8,
            label="failed runs",
        )


def _section_note(inputs: Sequence[Parameter], r: GpSmcResult) -> str:
    if len(inputs) <= 2:
        return ""
    rest = _fixed_rest(r, inputs)
    pairs = zip(inputs[2:], rest[2:], strict=True)
    return "section at " + ", ".join(f"{p.name}={v:.3g}" for p, v in pairs)


# -- Figs. 5-7 ----------------------------------------------------------------------------------
def _surrogate_fields(gp, r, inputs, labels, folder) -> Path:
    mesh_a, mesh_b, pts = _grid(inputs, r)
    mean, var = gp.predict(pts)
    fields = [
        (mean, "GP mean of log-likelihood L (Fig. 6)", "viridis"),
        (np.exp(mean - mean.max()), "likelihood exp(L - max L) (Fig. 5)", "viridis"),
        (np.sqrt(var), "GP standard deviation of L (Fig. 7)", "magma"),
    ]
    fig = Figure(figsize=(16, 4.6))
    for ax, (values, title, cmap) in zip(fig.subplots(1, 3), fields, strict=True):
        cs = ax.contourf(mesh_a, mesh_b, values.reshape(mesh_a.shape), 30, cmap=cmap)
        fig.colorbar(cs, ax=ax)
        _design_points(ax, r)
        ax.set(xlabel=labels[0], ylabel=labels[1], title=title)
    legend(fig.axes[0], loc="lower right", fontsize=7)
    note = _section_note(inputs, r)
    fig.suptitle(f"GP surrogate on {gp.info.get('n_train', len(gp.y_train))} runs  {note}")
    fig.tight_layout()
    return _save(fig, folder / "surrogate_fields.png")


# -- Figs. 8 and 12 -----------------------------------------------------------------------------
#: the largest design prefix the figures refit a GP of L on (6000 runs in 3 inputs took more
#: than 7 min and 10 GB); a larger design's figures stop there and say so
_MAX_REFIT = 2000


def _prefix_sizes(n: int) -> list[int]:
    sizes = [s for s in (10, 20, 50, 100, 200, 500, 1000, 2000) if s < n]
    return [*sizes, n][-6:] if n <= _MAX_REFIT else sizes[-6:]


def _refit(r: GpSmcResult, n: int, cache: dict[int, GpSurrogate | None]) -> Any:
    if n not in cache:
        cache[n] = _fit_prefix(r, n)
    return cache[n]


def _fit_prefix(r: GpSmcResult, n: int) -> GpSurrogate | None:
    """The GP on the first ``n`` design points (one training, no restarts)."""
    design = np.asarray(_design(r).points)
    loglik = np.asarray(_design(r).log_likelihood)
    train = np.asarray(_design(r).train_mask)
    use = train & np.isfinite(loglik) & (np.arange(len(train)) < n)
    if use.sum() < 3:
        return None
    state = _fit(r).state
    return GpSurrogate(ard=bool(state["ard"]), restarts=0).fit(design[use], loglik[use], rng=0)


def _gp_convergence(r, inputs, labels, folder, refits) -> Path:
    n_train = int(np.sum(_design(r).train_mask))
    sizes = _prefix_sizes(n_train)
    fig = Figure(figsize=(13, 8))
    axes = fig.subplots(2, 3).ravel()
    mesh_a, mesh_b, pts = _grid(inputs, r, n=60)
    design = np.asarray(_design(r).points)
    ok = np.isfinite(np.asarray(_design(r).log_likelihood))
    for ax, n in zip(axes, sizes, strict=False):
        gp = _refit(r, n, refits)
        if gp is not None:
            mean = gp.predict_mean(pts)
            ax.contourf(
                mesh_a, mesh_b, np.exp(mean - mean.max()).reshape(mesh_a.shape), 30, cmap="viridis"
            )
        first = np.arange(len(design)) < n
        ax.scatter(
            design[first & ok, 0],
            design[first & ok, 1],
            s=8,
            facecolors="none",
            edgecolors="k",
            linewidths=0.5,
        )
        ax.scatter(design[first & ~ok, 0], design[first & ~ok, 1], s=12, marker="x", c="0.55")
        ax.set(title=f"n_train = {n}", xlabel=labels[0], ylabel=labels[1])
    for ax in axes[len(sizes) :]:
        ax.set_visible(False)
    fig.suptitle("Convergence of the GP likelihood over n_train (Paper B Fig. 8)")
    fig.tight_layout()
    return _save(fig, folder / "gp_convergence.png")


def _gp_error(r, folder, refits) -> Path:
    design = np.asarray(_design(r).points)
    loglik = np.asarray(_design(r).log_likelihood)
    train = np.asarray(_design(r).train_mask)
    test = ~train & np.isfinite(loglik)
    sizes = _prefix_sizes(int(train.sum()))
    errors, kind = [], "held-out" if test.any() else "leave-one-out"
    for n in sizes:
        gp = _refit(r, n, refits)
        if gp is None:
            errors.append(math.nan)
        elif test.any():
            errors.append(gp.test_error(design[test], loglik[test])["test_l2"])
        else:
            errors.append(gp.loo()["loo_l2"])
    fig = Figure(figsize=(6, 4.2))
    ax = fig.subplots()
    ax.loglog(sizes, errors, "o-")
    ax.set(
        xlabel="n_train",
        ylabel=f"L2 error of the GP mean of L ({kind})",
        title=f"GP error over n_train (Fig. 12), n_test = {int(test.sum())}"
        + (f"; refits up to {_MAX_REFIT} runs" if int(train.sum()) > _MAX_REFIT else ""),
    )
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return _save(fig, folder / "gp_error.png")


# -- Fig. 9 -------------------------------------------------------------------------------------
def _kde_levels(density: FloatArray, levels: Sequence[float]) -> list[float]:
    """Density thresholds whose super-level sets hold the fractions ``levels`` of the mass."""
    flat = np.sort(density.ravel())[::-1]
    cum = np.cumsum(flat)
    cum /= cum[-1]
    return sorted(float(flat[min(int(np.searchsorted(cum, q)), len(flat) - 1)]) for q in levels)


def _subsample(r: GpSmcResult, n: int = 2000) -> tuple[FloatArray, FloatArray]:
    particles = np.asarray(_post(r).particles)
    w = np.asarray(_post(r).weights)
    if len(w) <= n:
        return particles, w
    idx = np.argsort(w)[::-1][:n]
    return particles[idx], w[idx] / w[idx].sum()


def _kde_contours(ax, r, i: int, j: int, lim_a, lim_b) -> None:
    sub, w = _subsample(r)
    data = sub[:, [i, j]].T
    if np.any(np.std(data, axis=1) == 0):
        return
    kde = gaussian_kde(data, weights=w)
    ga, gb = np.linspace(lim_a[0], lim_a[1], 70), np.linspace(lim_b[0], lim_b[1], 70)
    mesh_a, mesh_b = np.meshgrid(ga, gb)
    dens = kde(np.vstack([mesh_a.ravel(), mesh_b.ravel()])).reshape(mesh_a.shape)
    lv = _kde_levels(dens, LEVELS)
    if len(set(lv)) == len(lv):
        cs = ax.contour(mesh_a, mesh_b, dens, levels=lv, colors="k", linewidths=1.0)
        ax.clabel(
            cs,
            fmt={lv_: f"{int(100 * q)}%" for lv_, q in zip(lv, LEVELS[::-1], strict=True)},
            fontsize=6,
        )


def _ellipses(ax, mean: FloatArray, cov: FloatArray, colour: str, label: str) -> None:
    vals, vecs = np.linalg.eigh(cov)
    if np.any(vals <= 0):
        return
    t = np.linspace(0, 2 * np.pi, 200)
    circle = np.vstack([np.cos(t), np.sin(t)])
    for k, q in enumerate(LEVELS):
        r = math.sqrt(chi2.ppf(q, 2))
        pts = mean[:, None] + vecs @ (np.sqrt(vals)[:, None] * r * circle)
        ax.plot(pts[0], pts[1], color=colour, lw=1.0, label=label if k == 0 else None)


def _prior_line(ax, p: Parameter, lim, vertical: bool = False) -> None:
    if p.prior is None:
        return
    g = np.linspace(lim[0], lim[1], 200)
    dens = p.prior.pdf(g)
    if vertical:
        ax.plot(dens, g, "--", color=_PRIOR_COLOUR, lw=1.0, label="prior")
    else:
        ax.plot(g, dens, "--", color=_PRIOR_COLOUR, lw=1.0, label="prior")


def _hist_kde(ax, values, w, lim, vertical: bool = False) -> None:
    bins = np.linspace(lim[0], lim[1], 41)
    ax.hist(
        values,
        bins=bins,
        weights=w,
        density=True,
        color="tab:blue",
        alpha=0.6,
        orientation="horizontal" if vertical else "vertical",
    )
    if np.std(values) > 0:
        kde = gaussian_kde(values, weights=w)
        g = np.linspace(lim[0], lim[1], 200)
        if vertical:
            ax.plot(kde(g), g, "k", lw=1.0)
        else:
            ax.plot(g, kde(g), "k", lw=1.0)


def _mark_truth(ax, inputs, truth, i: int, j: int | None = None) -> None:
    """The ground truth of synthetic data: a cross (2-D) or a dashed line (1-D)."""
    a = truth.get(inputs[i].name)
    if j is None:
        if a is not None:
            ax.axvline(a, color="k", ls="--", lw=0.9, label="ground truth")
        return
    b = truth.get(inputs[j].name)
    if a is not None and b is not None:
        ax.plot([a], [b], "P", color="k", mfc="w", ms=10, label="ground truth")


def _posterior_2d(r, inputs, labels, folder, truth) -> Path:
    particles = np.asarray(_post(r).particles)
    w = np.asarray(_post(r).weights)
    lim_a, lim_b = _box(inputs[0], particles[:, 0]), _box(inputs[1], particles[:, 1])
    fig = Figure(figsize=(8, 8))
    grid = fig.add_gridspec(
        2, 2, width_ratios=(4, 1), height_ratios=(1, 4), hspace=0.05, wspace=0.05
    )
    ax = fig.add_subplot(grid[1, 0])
    top = fig.add_subplot(grid[0, 0], sharex=ax)
    right = fig.add_subplot(grid[1, 1], sharey=ax)
    ax.hexbin(
        particles[:, 0],
        particles[:, 1],
        C=w,
        reduce_C_function=np.sum,
        gridsize=40,
        cmap="Blues",
        extent=(*lim_a, *lim_b),
        mincnt=1,
    )
    _kde_contours(ax, r, 0, 1, lim_a, lim_b)
    pm = np.asarray(_post(r).mean)[:2]
    _ellipses(
        ax,
        pm,
        np.asarray(_post(r).cov)[:2, :2],
        _PM_COLOUR,
        "global Gaussian approximation",
    )
    lap = _post(r).laplace
    x_map = np.asarray(_post(r).map)[:2]
    if lap is not None and lap.cov is not None:
        _ellipses(ax, x_map, np.asarray(lap.cov)[:2, :2], _MAP_COLOUR, "Laplace approximation")
    ax.plot(*x_map, "x", color=_MAP_COLOUR, ms=10, mew=2, label="MAP")
    ax.plot(*pm, "x", color=_PM_COLOUR, ms=10, mew=2, label="posterior mean")
    _mark_truth(ax, inputs, truth, 0, 1)
    ax.set(xlim=lim_a, ylim=lim_b, xlabel=labels[0], ylabel=labels[1])
    legend(ax, loc="lower right", fontsize=7)
    _hist_kde(top, particles[:, 0], w, lim_a)
    _prior_line(top, inputs[0], lim_a)
    _hist_kde(right, particles[:, 1], w, lim_b, vertical=True)
    _prior_line(right, inputs[1], lim_b, vertical=True)
    top.tick_params(labelbottom=False)
    right.tick_params(labelleft=False)
    theta = _post(r).names[int(_post(r).n_x) :]
    title = "posterior" + (f" under uncertain {', '.join(theta)} (marginal)" if theta else "")
    top.set_title(f"{title} (Paper B Fig. 9)")
    return _save(fig, folder / "posterior.png")


def _particles(r, labels, folder) -> Path:
    particles = np.asarray(_post(r).particles)
    w = np.asarray(_post(r).weights)
    order = np.argsort(w)
    fig = Figure(figsize=(6.5, 5))
    ax = fig.subplots()
    sc = ax.scatter(
        particles[order, 0],
        particles[order, 1],
        c=w[order],
        s=4 + 200 * w[order] / w.max(),
        cmap="viridis",
        alpha=0.7,
    )
    fig.colorbar(sc, ax=ax, label="weight")
    ax.set(xlabel=labels[0], ylabel=labels[1], title="SMC particles and weights (Fig. 9b)")
    fig.tight_layout()
    return _save(fig, folder / "particles.png")


# -- Figs. 13-15 --------------------------------------------------------------------------------
def _marginals(r, inputs, labels, folder, truth) -> Path:
    particles = np.asarray(_post(r).particles)
    w = np.asarray(_post(r).weights)
    d = particles.shape[1]
    cols = min(d, 3)
    rows = math.ceil(d / cols)
    fig = Figure(figsize=(4.5 * cols, 3.4 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for j in range(d):
        lim = _box(inputs[j], particles[:, j])
        _hist_kde(axes[j], particles[:, j], w, lim)
        _prior_line(axes[j], inputs[j], lim)
        _mark_truth(axes[j], inputs, truth, j)
        axes[j].set(xlabel=labels[j], ylabel="density")
    for ax in axes[d:]:
        ax.set_visible(False)
    legend(axes[0], fontsize=7)
    fig.suptitle("1-D marginals of the posterior (Paper B Fig. 13)")
    fig.tight_layout()
    return _save(fig, folder / "marginals_1d.png")


def _pairwise(r, inputs, labels, folder, truth) -> Path:
    particles = np.asarray(_post(r).particles)
    w = np.asarray(_post(r).weights)
    n_x = int(_post(r).n_x)
    pairs = [(i, j) for i in range(n_x) for j in range(i + 1, n_x)][:15]
    cols = min(len(pairs), 3)
    rows = math.ceil(len(pairs) / cols)
    fig = Figure(figsize=(4.6 * cols, 4 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, (i, j) in zip(axes, pairs, strict=False):
        lim_a, lim_b = _box(inputs[i], particles[:, i]), _box(inputs[j], particles[:, j])
        ax.hexbin(
            particles[:, i],
            particles[:, j],
            C=w,
            reduce_C_function=np.sum,
            gridsize=30,
            cmap="Blues",
            extent=(*lim_a, *lim_b),
            mincnt=1,
        )
        _kde_contours(ax, r, i, j, lim_a, lim_b)
        _mark_truth(ax, inputs, truth, i, j)
        ax.set(xlim=lim_a, ylim=lim_b, xlabel=labels[i], ylabel=labels[j])
    for ax in axes[len(pairs) :]:
        ax.set_visible(False)
    fig.suptitle("pairwise 2-D marginals, KDE lines at 10/50/90 % mass (Paper B Fig. 14)")
    fig.tight_layout()
    return _save(fig, folder / "marginals_2d.png")


def _parallel_axes(r, labels, folder, n_lines: int = 300) -> Path:
    particles = np.asarray(_post(r).particles)
    w = np.asarray(_post(r).weights)
    log_post = np.asarray(_post(r).log_likelihood) + np.asarray(_post(r).log_prior)
    idx = np.unique(systematic_resample(w, np.random.default_rng(0)))
    if len(idx) > n_lines:
        idx = idx[np.argsort(log_post[idx])[-n_lines:]]
    columns = np.column_stack([particles[idx], log_post[idx]])
    names = [*labels, "log posterior"]
    lo, hi = columns.min(axis=0), columns.max(axis=0)
    scaled = (columns - lo) / np.where(hi > lo, hi - lo, 1.0)
    fig = Figure(figsize=(1.6 * len(names) + 2, 4.5))
    ax = fig.subplots()
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    order = np.argsort(log_post[idx])
    colour = (log_post[idx] - log_post[idx].min()) / (np.ptp(log_post[idx]) or 1.0)
    for k in order:
        ax.plot(range(len(names)), scaled[k], color=cmap(colour[k]), lw=0.6, alpha=0.6)
    ax.set_xticks(range(len(names)), names, rotation=20)
    for j in range(len(names)):
        ax.axvline(j, color="k", lw=0.5)
        ax.text(j, -0.06, f"{lo[j]:.3g}", ha="center", va="top", fontsize=7)
        ax.text(j, 1.02, f"{hi[j]:.3g}", ha="center", va="bottom", fontsize=7)
    ax.set(ylim=(-0.12, 1.1), yticks=[], title="parallel axes: resampled particles (Fig. 15)")
    n_x = int(_post(r).n_x)
    if len(_post(r).names) > n_x:
        ax.axvspan(n_x - 0.5, len(_post(r).names) - 0.5, color="0.9", zorder=0)
    fig.tight_layout()
    return _save(fig, folder / "parallel_axes.png")


def _design_only(r, inputs, folder) -> Path:
    fig = Figure(figsize=(6, 5))
    ax = fig.subplots()
    _design_points(ax, r, train_only=False)
    ax.set(
        xlabel=_label(inputs[0]),
        ylabel=_label(inputs[1]) if len(inputs) > 1 else "",
        title="design: every forward run failed",
    )
    legend(ax, fontsize=7)
    return _save(fig, folder / "design.png")
