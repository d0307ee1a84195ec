"""Cost of one 3-D ale_fsi forward run: direct solver against block-preconditioned GMRes.

    python benchmarks/bench_ale_fsi_3d.py                 # interface sizes 0.15, 0.1, 0.075 mm
    python benchmarks/bench_ale_fsi_3d.py --sizes 0.15    # some of them

One quasi-static run of ``geometry = "dome_3d"`` (E = 400 Pa, nu = 0.3, 100 mm^3/s, from rest,
one thread) per interface element size (channel size 2x it) and linear solver, each in a
fresh process so that its peak memory is its own: unknowns, wall and CPU time, assembly and
linear-solver time, Newton iterations and Jacobians, GMRes iterations per solve, peak resident
memory and the largest interface displacement (equal for both solvers to the Newton tolerance).

The machine is shared: CPU times are printed next to wall times.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

ONE_RUN = """
import json, resource, sys, tempfile, time
from fbia.plugins.ale_fsi import AleFsiForwardModel
size, linear_solver = float(sys.argv[1]), sys.argv[2]
model = AleFsiForwardModel(geometry="dome_3d", mesh_size=2 * size, interface_mesh_size=size,
                           linear_solver=linear_solver, warm_start=False)
t, cpu = time.perf_counter(), time.process_time()
sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tempfile.mkdtemp())
d = sol.diagnostics
inverse = model.solver._newton.inverse
print(json.dumps({
    "ndof": d["ndof"], "wall": time.perf_counter() - t, "cpu": time.process_time() - cpu,
    "assembly": d["assembly_time"], "solve": d["solve_time"],
    "newton": d["newton_iterations"], "jacobians": d["jacobians"],
    "gmres": getattr(inverse, "iterations", []),
    "memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    "max_displacement": d["max_displacement"][0],
}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.15, 0.1, 0.075])
    args = parser.parse_args()
    print(
        f"{'h_iface':>8} {'solver':>12} {'ndof':>7} {'wall s':>7} {'cpu s':>7} {'asm s':>6} "
        f"{'lin s':>6} {'newton':>6} {'jac':>4} {'gmres its':>10} {'MB':>6} {'max |d| mm':>12}"
    )
    for size in args.sizes:
        for linear_solver in ("direct", "block_gmres"):
            out = subprocess.run(
                [sys.executable, "-c", ONE_RUN, str(size), linear_solver],
                capture_output=True,
                text=True,
                check=True,
                env={**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"},
            )
            r = json.loads(out.stdout.strip().splitlines()[-1])
            its = f"{min(r['gmres'])}-{max(r['gmres'])}" if r["gmres"] else "-"
            print(
                f"{size:8.3f} {linear_solver:>12} {r['ndof']:7d} {r['wall']:7.1f} {r['cpu']:7.1f} "
                f"{r['assembly']:6.1f} {r['solve']:6.1f} {r['newton']:6d} {r['jacobians']:4d} "
                f"{its:>10} {r['memory_mb']:6.0f} {r['max_displacement']:12.8f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
