"""Accuracy and speed figures of the ``cutfem_fpi`` forward model (run by hand).

    .venv/bin/python benchmarks/bench_cutfem_fpi.py [mms|cold|sweep|all]

* ``mms``   -- manufactured Stokes-Darcy/Beavers-Joseph solution on n = 8..64: errors, rates;
* ``cold``  -- cold run of Paper A's poroelastic example (E = 300 Pa, phi0 = 0.25,
  K = 1e-4 mm^2, nu = 0.3, 100 mm^2/s) on a default and a 4x-dof mesh: interface difference,
  coupling iterations, dofs, time split;
* ``sweep`` -- 10 runs over E in [150, 600] Pa and phi0 in [0.1, 0.6] (Sobol-free fixed grid
  from a seeded Generator), failures counted.
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np


def bench_mms() -> None:
    sys.path.insert(0, "tests")
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


def _run(opts: dict, params: dict) -> tuple[np.ndarray, dict, float]:
    from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel

    model = CutFemFpiForwardModel(**opts)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        sol = model.solve(params, [{"inflow_rate": 100.0}], tmp)
    return sol.interface({"inflow_rate": 100.0}).vertices, sol.diagnostics, time.perf_counter() - t0


def bench_cold() -> None:
    import shapely

    params = {"E": 300.0, "nu": 0.3, "phi0": 0.25, "K": 1e-4}
    base = {"background_mesh_size": 0.05, "interface_mesh_size": 0.04}
    fine = {"background_mesh_size": 0.025, "interface_mesh_size": 0.02, "voxel_size": 0.002}
    curves = {}
    for name, opts in (("default", base), ("4x dofs", fine)):
        curve, d, wall = _run(opts, params)
        curves[name] = curve
        print(
            f"{name}: wall {wall:.2f} s, coupling iterations {d['coupling_iterations']}, "
            f"dofs flow {d['ndof_flow']} skeleton {d['ndof_skeleton']}, "
            f"times { ({k: round(v, 2) for k, v in d['time_split'].items()}) }, "
            f"max displacement {d['max_displacement'][0]:.4f} mm"
        )
    a, b = (shapely.LineString(c) for c in curves.values())
    print(f"interface distance default vs 4x dofs: {shapely.hausdorff_distance(a, b) * 1e3:.2f} um")


def bench_sweep(seed: int = 7) -> None:
    from fbia.core.errors import ForwardModelError

    rng = np.random.default_rng(seed)
    failures = 0
    for E, phi0 in zip(rng.uniform(150, 600, 10), rng.uniform(0.1, 0.6, 10), strict=True):
        try:
            _, d, wall = _run(
                {"background_mesh_size": 0.05, "interface_mesh_size": 0.04},
                {"E": float(E), "phi0": float(phi0)},
            )
            print(f"E={E:6.1f} phi0={phi0:.3f}: {wall:.1f} s, {d['coupling_iterations']} it")
        except ForwardModelError as exc:
            failures += 1
            print(f"E={E:6.1f} phi0={phi0:.3f}: FAILED ({exc})")
    print(f"failures: {failures}/10")


if __name__ == "__main__":
    import ngsolve

    ngsolve.SetNumThreads(1)
    what = sys.argv[1] if len(sys.argv) > 1 else "all"
    for name, fn in (("mms", bench_mms), ("cold", bench_cold), ("sweep", bench_sweep)):
        if what in (name, "all"):
            print(f"== {name}")
            fn()
