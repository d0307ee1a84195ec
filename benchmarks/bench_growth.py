"""Speed of the ``growth`` forward model (issue 15), run by hand:
``python benchmarks/bench_growth.py``.

On the default example mesh (Paper A's finger channel), each figure beside its anchor, the
``ale_fsi`` run of the same mesh and mode from the same process:

* one growth forward run, cold (transient: 5 s of FSI + transport, one growth step), target
  <= 10 s, against a transient ``ale_fsi`` run over the same 5 s;
* Levenberg-Marquardt from the four Table 6 starts (examples/growth/study.toml), target
  <= 2 min with the reuse of the FSI + transport state;
* five growth periods (five transient FSI + transport solves, five grown meshes), target
  <= 60 s;
* the quasi-steady variant of the first figure, and how far its grown interface lies from the
  transient one after one day.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import fbia

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = {"K1g": 6e4, "K2g": 5e-2, "K3g": 8e-2}


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="fbia-bench-growth-"))
    growth = fbia.forward_model("growth")
    o = growth.options
    fsi = fbia.forward_model(
        "ale_fsi",
        mode="transient",
        E=o.E,
        inflow_rate=o.inflow_rate,
        channel_length=o.channel_length,
        channel_height=o.channel_height,
        outline=[list(p) for p in growth.build_mesh_outline()],
        smooth_outline=False,
        curved=False,
        mesh_size=o.mesh_size,
        interface_mesh_size=o.interface_mesh_size,
        time_step=o.time_step,
        ramp_time=o.ramp_time,
    )
    one, t_growth = _timed(lambda: growth.solve(REFERENCE, [{"day": 1}], tmp / "g1"))
    _, t_fsi = _timed(lambda: fsi.solve({}, [{"time": o.fsi_period}], tmp / "f1"))
    print(
        f"one growth run (cold, transient 5 s + 1 step): {t_growth:6.2f} s   target <= 10 s  "
        f"{'PASS' if t_growth <= 10 else 'MISS'}   ale_fsi alone {t_fsi:6.2f} s  "
        f"ratio {t_growth / t_fsi:.2f}"
    )
    quasi = fbia.forward_model("growth", mode="quasi_static")
    qs, t_qs = _timed(lambda: quasi.solve(REFERENCE, [{"day": 1}], tmp / "q1"))
    key = fbia.coordinate_key({"day": 1})
    gap = np.abs(qs.interfaces[key].vertices - one.interfaces[key].vertices).max()
    print(
        f"quasi-steady variant: {t_qs:6.2f} s; its day-1 interface lies {gap * 1e3:.3f} um "
        "from the transient one"
    )
    proc, t_lm = _timed(
        lambda: subprocess.run(
            [
                sys.executable,
                "-m",
                "fbia.studies.cli",
                "run",
                str(ROOT / "examples/growth/study.toml"),
                "--output",
                str(tmp / "lm"),
                "--fresh",
            ],
            capture_output=True,
            text=True,
            check=True,
        )
    )
    print(
        f"LM from the four Table 6 starts (fbia run, incl. start-up): {t_lm:6.1f} s   "
        f"target <= 120 s  {'PASS' if t_lm <= 120 else 'MISS'}"
    )
    five = fbia.forward_model("growth")
    sol, t_five = _timed(lambda: five.solve(REFERENCE, [{"day": 5}], tmp / "g5"))
    print(
        f"five growth periods: {t_five:6.1f} s   target <= 60 s  "
        f"{'PASS' if t_five <= 60 else 'MISS'}   ({t_five / 5 / t_fsi:.2f} x ale_fsi per period); "
        f"growth per day {[round(g[0] * 1e3, 2) for g in sol.diagnostics['growth']]} um"
    )


if __name__ == "__main__":
    main()
