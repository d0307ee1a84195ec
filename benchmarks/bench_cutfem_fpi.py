"""Accuracy and speed figures of the ``cutfem_fpi`` forward model (run by hand, one thread).

    .venv/bin/python benchmarks/bench_cutfem_fpi.py [mms|cold|sweep|table5|ale|all]

* ``mms``    -- manufactured Stokes-Darcy/Beavers-Joseph solution on n = 8..64: errors, rates;
* ``cold``   -- cold run (model built and solved in a fresh process state) of Paper A's
  poroelastic example (E = 300 Pa, phi0 = 0.25, K = 1e-4 mm^2, nu = 0.3, 100 mm^2/s) on the
  default meshes and on meshes with 4x the dofs: wall and CPU time, interface difference
  (Hausdorff distance), coupling iterations, dofs of both meshes, time split;
* ``sweep``  -- 10 runs over E in [150, 600] Pa and phi0 in [0.1, 0.6] (Latin hypercube from a
  seeded Generator) plus the 4 corners, default meshes, failures counted;
* ``table5`` -- Levenberg-Marquardt from the three initial guesses of Paper A Table 5 on noise-free
  synthetic data of the default model, robust and paper mode;
* ``ale``    -- cross-check with ``ale_fsi`` (same flow cell, neo-Hooke E = 300 Pa, nu = 0.3
  and 0.49): interface distance for K = 1e-4 ... 1e-12 mm^2.

Wall times depend on the load of the (shared, 2-core) machine; the load average is printed with
them and the CPU time of the process is the steadier figure.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

PAPER = {"E": 300.0, "nu": 0.3, "phi0": 0.25, "K": 1e-4}
LEVEL = {"inflow_rate": 100.0}


def _load() -> str:
    return "load average " + " ".join(f"{v:.1f}" for v in os.getloadavg())


def bench_mms() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_cutfem_flow import _mms_errors

    prev = None
    for n in (8, 16, 32, 64):
        t0 = time.perf_counter()
        e = _mms_errors(n, saffman=False)
        line = " ".join(f"{k}={v:.3e}" for k, v in e.items())
        if prev is not None:
            line += "  rates " + " ".join(f"{np.log2(prev[k] / e[k]):.2f}" for k in e)
        print(f"n={n:3d} {line}  ({time.perf_counter() - t0:.1f} s)")
        prev = e


def _run(opts: dict[str, Any], params: dict[str, float]) -> tuple[np.ndarray, dict, float, float]:
    """One run of a new model object (meshing included): curve, diagnostics, wall, CPU [s]."""
    from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel

    t0, c0 = time.perf_counter(), time.process_time()
    model = CutFemFpiForwardModel(**opts)
    with tempfile.TemporaryDirectory() as tmp:
        sol = model.solve(params, [LEVEL], tmp)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return sol.interface(LEVEL).vertices, sol.diagnostics, wall, cpu


def bench_cold() -> None:
    import shapely

    base: dict[str, Any] = {}
    fine = {"background_mesh_size": 0.025, "interface_mesh_size": 0.02}
    curves = {}
    for name, opts in (("default", base), ("4x dofs", fine)):
        curve, d, wall, cpu = _run(opts, PAPER)
        curves[name] = curve
        print(
            f"{name}: wall {wall:.2f} s, CPU {cpu:.2f} s ({_load()}), coupling iterations "
            f"{d['coupling_iterations'][0]}, Newton flow {d['flow_newton_iterations'][0]} "
            f"skeleton {d['skeleton_newton_iterations'][0]}, dofs flow {d['ndof_flow']} "
            f"skeleton {d['ndof_skeleton']}, time split "
            f"{ {k: round(v, 2) for k, v in d['time_split'].items()} }, setup "
            f"{d['setup_time']:.2f} s, max displacement {d['max_displacement'][0]:.4f} mm"
        )
    a, b = (shapely.LineString(c) for c in curves.values())
    print(f"interface distance default vs 4x dofs: {shapely.hausdorff_distance(a, b) * 1e3:.3f} um")


def sweep_points(seed: int = 7, n: int = 10) -> list[tuple[float, float]]:
    """A Latin hypercube of ``n`` points in [150, 600] Pa x [0.1, 0.6], then the 4 corners."""
    rng = np.random.default_rng(seed)
    E = 150.0 + 450.0 * (rng.permutation(n) + rng.uniform(size=n)) / n
    phi0 = 0.1 + 0.5 * (rng.permutation(n) + rng.uniform(size=n)) / n
    corners = [(150.0, 0.6), (150.0, 0.1), (600.0, 0.6), (600.0, 0.1)]
    return [(float(e), float(p)) for e, p in zip(E, phi0, strict=True)] + corners


def bench_sweep() -> None:
    from fbia.core.errors import ForwardModelError
    from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel

    model = CutFemFpiForwardModel()
    points = sweep_points()
    failures = 0
    for E, phi0 in points:
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            with tempfile.TemporaryDirectory() as tmp:
                d = model.solve({"E": E, "phi0": phi0}, [LEVEL], tmp).diagnostics
            print(
                f"E={E:6.1f} Pa phi0={phi0:.3f}: wall {time.perf_counter() - t0:.1f} s, CPU "
                f"{time.process_time() - c0:.1f} s, {d['coupling_iterations'][0]} iterations, "
                f"max displacement {d['max_displacement'][0]:.4f} mm, porosity "
                f"[{d['porosity_range'][0][0]:.3f}, {d['porosity_range'][0][1]:.3f}]"
            )
        except ForwardModelError as exc:
            failures += 1
            print(f"E={E:6.1f} Pa phi0={phi0:.3f}: FAILED ({exc})")
    print(f"failures: {failures}/{len(points)} ({_load()})")


def bench_table5(options: dict[str, Any] | None = None) -> None:
    import fbia
    from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel

    opts = {"coupling_tol": 1e-7, **(options or {})}
    obs = fbia.synthetic_observations(
        CutFemFpiForwardModel(**opts),
        {"E": 300.0, "phi0": 0.25},
        [LEVEL],
        noise_std=0.0,
        seed=1,
        points=12,
    )
    starts = [{"E": 400.0, "phi0": 0.2}, {"E": 400.0, "phi0": 0.4}, {"E": 300.0, "phi0": 0.6}]
    for mode in ("robust", "paper"):
        problem = fbia.InverseProblem(
            model=CutFemFpiForwardModel(**opts),
            measure=fbia.measure("ray"),
            observations=obs,
            parameters=[
                fbia.Parameter("E", bounds=(50.0, 2000.0), unit="Pa"),
                fbia.Parameter("phi0", bounds=(0.05, 0.9)),
            ],
        )
        t0 = time.perf_counter()
        result = fbia.iterator("levenberg_marquardt", x0=starts, mode=mode).run(problem)
        print(f"== mode {mode}: {time.perf_counter() - t0:.0f} s, {result.nfev} runs ({_load()})")
        for color, row in zip(("blue", "orange", "green"), result.starts, strict=True):
            x = row["x"] or {}
            print(
                f"{color:6s} x0 = {row['x0']}: {row['status']}, "
                + (f"E = {x['E']:.3f} Pa, phi0 = {x['phi0']:.5f}, " if x else "")
                + f"{row['iterations']} iterations, {row['nfev']} runs ({row['n_failed']} "
                f"failed); {row['message']}"
            )


def bench_ale(interface_mesh_size: float = 0.04) -> None:
    import shapely

    import fbia
    from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel

    for nu in (0.3, 0.49):
        t0 = time.perf_counter()
        ale = fbia.forward_model(
            "ale_fsi",
            material="neo_hooke",
            E=300.0,
            nu=nu,
            interface_mesh_size=interface_mesh_size,
            mesh_size=0.12,
        )
        with tempfile.TemporaryDirectory() as tmp:
            sol = ale.solve({}, [LEVEL], tmp)
        ref = sol.interface(LEVEL).vertices
        print(
            f"nu = {nu}: ale_fsi {time.perf_counter() - t0:.1f} s, max displacement "
            f"{sol.diagnostics['max_displacement'][0] * 1e3:.2f} um"
        )
        cut = CutFemFpiForwardModel(
            interface_mesh_size=interface_mesh_size, coupling_tol=1e-7, nu=nu
        )
        for K in (1e-4, 1e-6, 1e-8, 1e-10, 1e-12):
            t0 = time.perf_counter()
            with tempfile.TemporaryDirectory() as tmp:
                sol = cut.solve({"K": K}, [LEVEL], tmp)
            curve = sol.interface(LEVEL).vertices
            d = sol.diagnostics
            dist = shapely.hausdorff_distance(shapely.LineString(ref), shapely.LineString(curve))
            dmax = d["max_displacement"][0]
            print(
                f"  K = {K:.0e} mm^2: {time.perf_counter() - t0:.1f} s, max displacement "
                f"{dmax * 1e3:.2f} um, distance to ale_fsi {dist * 1e3:.2f} um "
                f"({100 * dist / dmax:.2f} % of the displacement), porosity "
                f"[{d['porosity_range'][0][0]:.3f}, {d['porosity_range'][0][1]:.3f}]"
            )


if __name__ == "__main__":
    import ngsolve

    ngsolve.SetNumThreads(1)
    what = sys.argv[1] if len(sys.argv) > 1 else "all"
    benches = {
        "mms": bench_mms,
        "cold": bench_cold,
        "sweep": bench_sweep,
        "table5": bench_table5,
        "ale": bench_ale,
    }
    for name, fn in benches.items():
        if what in (name, "all"):
            print(f"== {name}")
            fn()
