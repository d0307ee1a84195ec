"""Speed of the three interface measures on 3-D surfaces (run by hand: ``python
benchmarks/bench_measures.py``).

Prints each figure with its target and PASS/MISS:

* rkhs: two surfaces of 10 000 triangles each (a mound and the same mound moved by 0.01 mm),
  first call (which also computes and caches the observation's self-product) and a repeated
  call, for the kernel width of Paper B (0.005 mm, most element pairs skipped), 0.05 mm and
  1 mm (no pair skipped: the dense worst case); peak memory of the first call (tracemalloc);
* ray: 100 rays along the observed normals against a 100 000-triangle surface, time of a call
  after the first (which builds the search tree of the simulated surface);
* cpp: the 10 000 vertices of a simulated surface against a 100 000-triangle observed
  surface, after the first call (which builds the observed surface's search tree).

Each figure is the best of three runs (first calls: three fresh measure objects), wall-clock
and CPU time (``time.process_time``); on a loaded machine the CPU time is the better figure
of the code's own cost.  Targets apply to wall-clock time.
"""

from __future__ import annotations

import os
import time
import tracemalloc
from collections.abc import Callable

import numpy as np

import fbia
from fbia.measures import CppMeasure, RayMeasure, RkhsMeasure


def grid_surface(nx: int, ny: int, height: Callable[[np.ndarray, np.ndarray], np.ndarray]):
    """Height field z = height(x, y) over [0, 1]^2 with 2 nx ny triangles, normals up."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1), indexing="ij")
    x, y = x.ravel(), y.ravel()
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tri = np.vstack([np.c_[a, b, c], np.c_[a, c, d]])
    return fbia.Interface.surface(np.c_[x, y, height(x, y)], tri)


def mound(shift: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    return lambda x, y: 0.1 * np.exp(-((x - 0.5 - shift) ** 2 + (y - 0.5) ** 2) / 0.05)


def timed(fn: Callable[[], object], repeat: int = 3) -> tuple[float, float, object]:
    """Best wall-clock and best CPU time of ``repeat`` runs of ``fn`` (as timeit: the minimum
    is the figure least disturbed by other processes), and the last result."""
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus), out


def report(label: str, wall: float, cpu: float, target: float | None, extra: str = "") -> None:
    verdict = "" if target is None else ("PASS" if wall <= target else "MISS")
    tgt = "" if target is None else f"target <= {target:g} s  {verdict}"
    print(f"{label:<58s} wall {wall:7.3f} s  cpu {cpu:7.3f} s  {tgt}{extra}")


def bench_rkhs() -> None:
    observed = grid_surface(100, 50, mound(0.0))
    simulated = grid_surface(100, 50, mound(0.01))
    obs = fbia.Observation(observed)
    print(f"rkhs: {len(simulated)} vs {len(observed)} triangles")
    for sigma in (0.005, 0.05, 1.0):
        wall, cpu, value = timed(lambda s=sigma: RkhsMeasure(sigma_w=s).distance(simulated, obs))
        report(f"  sigma_w={sigma:g} mm, first call", wall, cpu, 1.0, f"  D={value:.6e}")
        measure = RkhsMeasure(sigma_w=sigma)
        measure.distance(simulated, obs)
        wall, cpu, _ = timed(lambda m=measure: m.distance(simulated, obs))
        report(f"  sigma_w={sigma:g} mm, repeated (observation cached)", wall, cpu, 1.0)
        tracemalloc.start()
        RkhsMeasure(sigma_w=sigma).distance(simulated, obs)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        print(f"  sigma_w={sigma:g} mm, peak traced memory of a first call: {peak / 2**20:.1f} MiB")


def bench_ray() -> None:
    observed = grid_surface(100, 50, mound(0.0))
    simulated = grid_surface(224, 224, mound(0.02))
    rng = np.random.default_rng(7)
    points = rng.uniform(0.1, 0.9, (100, 2))
    points = np.c_[points, mound(0.0)(points[:, 0], points[:, 1])]
    obs = fbia.Observation(observed, points=points)
    measure = RayMeasure()
    print(f"ray: {len(points)} rays against {len(simulated)} triangles")
    wall, cpu, _ = timed(lambda: RayMeasure().rays(obs), repeat=1)
    report("  observation set-up (normals at the points)", wall, cpu, None)
    wall, cpu, _ = timed(lambda: measure.residuals(simulated, obs), repeat=1)
    report("  first call (builds the simulated surface's tree)", wall, cpu, None)
    wall, cpu, r = timed(lambda: measure.residuals(simulated, obs))
    report("  call after the first", wall, cpu, 0.1, f"  max |d| = {np.abs(r).max():.4f} mm")


def bench_cpp() -> None:
    observed = grid_surface(224, 224, mound(0.0))
    simulated = grid_surface(99, 99, mound(0.02))
    obs = fbia.Observation(observed)
    measure = CppMeasure()
    print(f"cpp: {len(simulated.vertices)} vertices against {len(observed)} triangles")
    wall, cpu, _ = timed(lambda: measure.residuals(simulated, obs), repeat=1)
    report("  first call (builds the observed surface's tree)", wall, cpu, None)
    wall, cpu, r = timed(lambda: measure.residuals(simulated, obs))
    report("  call after the first", wall, cpu, 1.0, f"  max |d| = {np.abs(r).max():.4f} mm")


if __name__ == "__main__":
    print(
        f"fbia measures benchmark; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    bench_rkhs()
    bench_ray()
    bench_cpp()
