"""Paper B Figs. 5-7 side by side for the three measures (run by hand after the three studies:
``python examples/paper_b/measures/make_figure.py``; writes ``measures.png`` here in
``output_figures/``).

Rows: the normalised likelihood exp(L - max L) (Fig. 5), the GP mean of L (Fig. 6), the GP
standard deviation of L (Fig. 7); columns: ray, cpp, rkhs.  Each GP is rebuilt from its
study's ``result.json`` (``GpSurrogate.from_state``); its forward runs (design and checks) are
circles, failed runs grey crosses, the ground truth a white star.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fbia.iterators.surrogates.gp import GpSurrogate  # noqa: E402

HERE = Path(__file__).resolve().parent
MEASURES = {"ray": "a  Euclidean distance (ray)", "cpp": "b  closest point (cpp)",
            "rkhs": "c  RKHS norm (rkhs)"}  # fmt: skip
TRUTH = (400.0, 0.3)


def _gp(result: dict) -> GpSurrogate:
    state = result["info"]["surrogate"]["state"]
    return GpSurrogate.from_state(
        {k: np.asarray(v) if isinstance(v, list) else v for k, v in state.items()}
    )


def main() -> None:
    e, nu = np.linspace(100.0, 800.0, 120), np.linspace(-0.8, 0.5, 120)
    mesh_e, mesh_nu = np.meshgrid(e, nu)
    grid = np.column_stack([mesh_e.ravel(), mesh_nu.ravel()])
    fig, axes = plt.subplots(3, 3, figsize=(14, 12), sharex=True, sharey=True)
    for col, (name, title) in enumerate(MEASURES.items()):
        path = HERE / f"output_{name}" / "result.json"
        if not path.exists():
            raise SystemExit(f"{path} is missing: run study_{name}.toml first")
        result = json.loads(path.read_text())
        mean, var = _gp(result).predict(grid)
        points = np.array([[ev["x"]["E"], ev["x"]["nu"]] for ev in result["evaluations"]])
        ok = np.array([ev["status"] == "ok" for ev in result["evaluations"]])
        fields = [
            (np.exp(mean - mean.max()), "likelihood exp(L - max L)", "jet"),
            (mean, "log-likelihood L (GP mean)", "viridis"),
            (np.sqrt(var), "GP standard deviation of L", "magma"),
        ]
        for row, (values, label, cmap) in enumerate(fields):
            ax = axes[row, col]
            cs = ax.contourf(mesh_e, mesh_nu, values.reshape(mesh_e.shape), 30, cmap=cmap)
            fig.colorbar(cs, ax=ax)
            ax.scatter(*points[ok].T, s=4, facecolors="none", edgecolors="k", linewidths=0.3)
            ax.scatter(*points[~ok].T, s=10, marker="x", c="0.6", linewidths=0.7)
            ax.plot(*TRUTH, "*", c="w", ms=10, mec="k")
            ax.set_title(f"{title}\n{label}" if row == 0 else label, fontsize=9)
            if row == 2:
                ax.set_xlabel("E [Pa]")
            if col == 0:
                ax.set_ylabel("nu [-]")
    fig.suptitle("Paper B Figs. 5-7 with fbia: n_train = 1000, sigma_N = 0.01 mm")
    fig.tight_layout()
    out = HERE / "output_figures"
    out.mkdir(exist_ok=True)
    fig.savefig(out / "measures.png", dpi=90)
    print(out / "measures.png")


if __name__ == "__main__":
    main()
