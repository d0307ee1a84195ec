"""Speed and memory of the OCT segmentation (issue 18), run by hand:
``python benchmarks/bench_oct_segmentation.py``.

A synthetic 512 x 512 x 256 volume (fbia.testing.oct: a dome on a flat substratum, speckle of
2 looks, depth attenuation 2 /mm over 1.28 mm, voxels 5 x 10 x 10 um) as float32, segmented
with the default options and the attenuation compensated:

* wall-clock and CPU time of ``segment_oct`` (best of three runs), target <= 10 s; one run
  with ``attenuation="auto"`` (the estimate of mu and its cost);
* peak memory: the largest traced allocation during one run (tracemalloc, NumPy's arrays
  included; a separate run, since tracing slows it down) beside the volume's own size, and
  the process's peak resident set (``ru_maxrss``, volume and phantom generation included);
* how far the extracted vertices lie from the known dome (closest-point distances, in depth
  voxels), so the figure is of a segmentation that worked.

The CPU time is the better figure of the code's own cost on a loaded machine; the target
applies to wall-clock time.  Set ``OMP_NUM_THREADS=1`` for a figure independent of cores
(SciPy's filters and labelling and scikit-image's marching cubes run on one core anyway).
"""

from __future__ import annotations

import resource
import time
import tracemalloc

import numpy as np

import fbia
from fbia.imaging.oct import segment_oct
from fbia.measures import CppMeasure
from fbia.testing.oct import oct_phantom

SHAPE = (256, 512, 512)
VOXEL = (0.005, 0.01, 0.01)
MU = 2.0  # 1/mm
TARGET = 10.0  # s


def main() -> None:
    t0 = time.perf_counter()
    ph = oct_phantom(shape=SHAPE, voxel_size=VOXEL, attenuation=MU, seed=0)
    print(
        f"volume {SHAPE[0]} x {SHAPE[1]} x {SHAPE[2]} (depth, y, x) float32, "
        f"{ph.volume.nbytes / 2**20:.0f} MiB; made in {time.perf_counter() - t0:.1f} s"
    )
    walls, cpus = [], []
    seg = None
    for _ in range(3):
        w0, c0 = time.perf_counter(), time.process_time()
        seg = segment_oct(ph.volume, VOXEL, attenuation=MU)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    assert seg is not None
    wall, cpu = min(walls), min(cpus)
    verdict = "PASS" if wall <= TARGET else "MISS"
    print(
        f"{'segment_oct (best of 3)':<40s} wall {wall:7.2f} s  cpu {cpu:7.2f} s  "
        f"target <= {TARGET:g} s  {verdict}"
    )
    w0, c0 = time.perf_counter(), time.process_time()
    auto = segment_oct(ph.volume, VOXEL, attenuation="auto")
    wall_auto, cpu_auto = time.perf_counter() - w0, time.process_time() - c0
    print(
        f"{'segment_oct, attenuation=auto (one run)':<40s} wall {wall_auto:7.2f} s  "
        f"cpu {cpu_auto:7.2f} s  (estimated mu {auto.attenuation:.2f} /mm, true {MU:g})"
    )
    tracemalloc.start()
    segment_oct(ph.volume, VOXEL, attenuation=MU)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10  # kB on Linux
    print(
        f"{'peak memory of one run (tracemalloc)':<40s} {peak / 2**20:7.0f} MiB "
        f"({peak / ph.volume.nbytes:.1f} x the volume); process peak RSS {rss:.0f} MiB"
    )
    gamma = seg.interface
    truth = fbia.Observation(ph.surface(n=256))
    d = np.abs(CppMeasure().residuals(gamma, truth)) / VOXEL[0]
    print(
        f"{'surface':<40s} {len(gamma)} triangles; distance to the known dome [depth voxels]: "
        f"p95 {np.percentile(d, 95):.2f}, max {d.max():.2f}, rms {np.sqrt(np.mean(d**2)):.2f}"
    )


if __name__ == "__main__":
    main()
