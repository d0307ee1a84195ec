"""Figures like Paper A Figs. 20-21 for the growth example (run by hand:
``python examples/growth/make_figures.py``; writes into ``examples/growth/output/figures``).

One forward run of ``growth`` at the reference coefficients (transient FSI + transport, one
growth day) with field output, then:

* ``nutrient.png``: the nutrient Phi on the deformed mesh around the finger (Fig. 20);
* ``interface.png``: the initial interface, the FSI-deformed one and the deformed and grown
  one (Fig. 21);
* ``displacements.png``: the FSI and the growth displacement along the interface, normal
  components, from the upstream foot over the tip to the downstream foot (the paper's "same
  order of magnitude").
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import meshio  # noqa: E402
import numpy as np  # noqa: E402

import fbia  # noqa: E402

HERE = Path(__file__).resolve().parent
REFERENCE = {"K1g": 6e4, "K2g": 5e-2, "K3g": 8e-2}


def main() -> None:
    out = HERE / "output" / "figures"
    out.mkdir(parents=True, exist_ok=True)
    model = fbia.forward_model("growth", write_vtu=True)
    work = Path(tempfile.mkdtemp(prefix="fbia-growth-figures-"))
    sol = model.solve(REFERENCE, [{"day": 0}, {"day": 1}], work)
    vtu = meshio.read(next(iter(sol.fields.values())))
    x = vtu.points[:, :2]
    d = vtu.point_data["displacement"][:, :2]
    g = vtu.point_data["growth"][:, :2]
    tri = vtu.cells_dict["triangle"]
    o = model.options

    fig, ax = plt.subplots(figsize=(7, 3.6))
    xd = x + d
    tpc = ax.tripcolor(xd[:, 0], xd[:, 1], tri, vtu.point_data["phi"], shading="gouraud")
    fig.colorbar(tpc, ax=ax, label="nutrient Φ [mol/mm³]")
    ax.set(aspect="equal", xlabel="x [mm]", ylabel="y [mm]", title="nutrient after 5 s of flow")
    ax.set_xlim(o.finger_x0 - 0.12, o.finger_x0 + 0.2)
    ax.set_ylim(0.0, 0.2)
    fig.savefig(out / "nutrient.png", dpi=150, bbox_inches="tight")
    plt.close(fig)

    day0 = sol.interfaces[fbia.coordinate_key({"day": 0})].vertices
    day1 = sol.interfaces[fbia.coordinate_key({"day": 1})].vertices
    initial = model.build_mesh_outline()
    fig, ax = plt.subplots(figsize=(4, 5))
    ax.plot(initial[:, 0], initial[:, 1], "k-", lw=1, label="initial")
    ax.plot(day0[:, 0], day0[:, 1], "b--", lw=1, label="FSI-deformed")
    ax.plot(day1[:, 0], day1[:, 1], "r-", lw=1, label="deformed and grown (1 day)")
    ax.set(aspect="equal", xlabel="x [mm]", ylabel="y [mm]", title="interface (Fig. 21)")
    ax.legend(loc="lower right", fontsize=8)
    fig.savefig(out / "interface.png", dpi=150, bbox_inches="tight")
    plt.close(fig)

    iface = np.flatnonzero(np.linalg.norm(g, axis=1) > 0)
    chain = day0 - 0.0  # ordered interface points of the FSI state
    order = np.argsort([np.argmin(np.linalg.norm(chain - (x[i] + d[i]), axis=1)) for i in iface])
    iface = iface[order]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(x[iface], axis=0), axis=1))]
    t = np.gradient(x[iface], axis=0)
    n = np.c_[-t[:, 1], t[:, 0]] / np.linalg.norm(t, axis=1)[:, None]  # out of the biofilm
    fig, ax = plt.subplots(figsize=(6, 3.2))
    ax.plot(s, 1e3 * np.sum(d[iface] * n, axis=1), "b-", label="FSI (normal)")
    ax.plot(s, 1e3 * np.sum(g[iface] * n, axis=1), "r-", label="growth, 1 day (normal)")
    ax.axhline(0.0, color="0.6", lw=0.5)
    ax.set(xlabel="arc length from the upstream foot [mm]", ylabel="displacement [µm]")
    ax.legend(fontsize=8)
    fig.savefig(out / "displacements.png", dpi=150, bbox_inches="tight")
    plt.close(fig)
    print(f"figures in {out}")


if __name__ == "__main__":
    main()
