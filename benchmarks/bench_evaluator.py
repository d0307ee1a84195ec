"""Speed of the evaluation engine (run by hand: ``python benchmarks/bench_evaluator.py``).

Prints each figure, with its target and PASS/MISS where the issue sets one:

* **throughput**: 200 evaluations of a model that sleeps 0.5 s, in one batch, with 1 and 2
  workers for ``processes`` and ``dask`` (a LocalCluster, runs isolated in child processes as
  by default); wall time, parallel efficiency of 2 workers (T1 / (2 T2), target >= 90 %) and
  the share of the ideal n * 0.5 s / workers;
* **overhead per evaluation**: 400 evaluations of a no-op model (the closed-form toy model,
  about 0.2 ms), in one batch and in 40 batches of 10 (as Levenberg-Marquardt asks), for
  ``serial``, ``processes`` (2 workers) and ``dask`` (2 workers), each plain and isolated (every
  run in a forked child, as with a time-out); the pool's start and Dask's start-up
  (LocalCluster) are timed separately and left out;
* **store**: 100 000 records (81 residuals each, like the flow-cell demo) written one
  transaction each, then read back whole and looked up by key in batches of 1000; time per
  write and per read, file size.

Options: ``--quick`` (20 sleeps, 100 no-ops, 10 000 records: a smoke run in about a minute).
The model is the toy model of ``tests/_models.py`` (``delay`` option); worker processes find it
through ``sys.path``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import fbia  # noqa: E402
from fbia.storage.store import StudyStore  # noqa: E402

SLEEP = 0.5  # s per evaluation of the throughput model


def _problem(delay: float) -> fbia.InverseProblem:
    from _models import toy_problem

    return toy_problem(delay=delay)


def _points(n: int, seed: int = 0) -> list[dict[str, float]]:
    rng = np.random.default_rng(seed)
    return [
        {"E": float(E), "nu": float(nu)}
        for E, nu in zip(rng.uniform(100.0, 800.0, n), rng.uniform(-0.8, 0.5, n), strict=True)
    ]


def _evaluator(kind: str, workers: int, isolate: bool | None, root: Path) -> Any:
    options: dict[str, Any] = {"workdir": root, "keep_workdirs": False}
    if isolate is not None:
        options["isolate"] = isolate
    if kind != "serial":
        options["workers"] = workers
    return fbia.make_evaluator(kind, **options)


def _warm(ev: Any, problem: fbia.InverseProblem, workers: int) -> None:
    """Start the workers (and their isolation helpers): one run per worker, not timed."""
    ev.evaluate(problem, _points(workers, seed=99))


def throughput(n: int, root: Path) -> dict[tuple[str, int], float]:
    problem = _problem(SLEEP)
    print(f"\n== throughput: {n} evaluations of a model that sleeps {SLEEP} s, one batch")
    print(f"{'executor':10} {'workers':>7} {'wall [s]':>9} {'ideal [s]':>9} {'of ideal':>9}")
    walls: dict[tuple[str, int], float] = {}
    for kind in ("processes", "dask"):
        for workers in (1, 2):
            with _evaluator(kind, workers, None, root / f"{kind}{workers}") as ev:
                _warm(ev, problem, workers)
                t0 = time.perf_counter()
                records = ev.evaluate(problem, _points(n))
                wall = time.perf_counter() - t0
            assert all(r.ok for r in records)
            ideal = n * SLEEP / workers
            walls[kind, workers] = wall
            print(f"{kind:10} {workers:7d} {wall:9.2f} {ideal:9.2f} {ideal / wall:9.1%}")
    for kind in ("processes", "dask"):
        eff = walls[kind, 1] / (2 * walls[kind, 2])
        print(
            f"parallel efficiency of 2 workers, {kind}: {eff:.1%} (target >= 90 %: "
            f"{'PASS' if eff >= 0.9 else 'MISS'})"
        )
    return walls


def overhead(n: int, root: Path) -> None:
    problem = _problem(0.0)
    model = min(
        _timed(lambda x=x: problem.evaluate(x)) for x in _points(50, seed=5)
    )  # the model's own time, in this process
    print(f"\n== overhead per evaluation: {n} evaluations of a no-op model ({model * 1e3:.2f} ms)")
    print(
        f"{'executor':10} {'workers':>7} {'isolated':>8} {'start [s]':>9} "
        f"{'1 batch [ms]':>12} {'batches of 10 [ms]':>18}"
    )
    for kind, workers in (("serial", 1), ("processes", 2), ("dask", 2)):
        for isolate in (False, True):
            t0 = time.perf_counter()
            ev = _evaluator(kind, workers, isolate, root / f"o-{kind}-{isolate}")
            with ev:
                _warm(ev, problem, workers)
                start = time.perf_counter() - t0
                one = _timed(lambda ev=ev: ev.evaluate(problem, _points(n, seed=1))) / n
                pts = _points(n, seed=2)
                many = (
                    _timed(
                        lambda ev=ev, pts=pts: [
                            ev.evaluate(problem, pts[k : k + 10]) for k in range(0, n, 10)
                        ]
                    )
                    / n
                )
            yes = "yes" if isolate else "no"
            print(
                f"{kind:10} {workers:7d} {yes:>8} {start:9.2f} {one * 1e3:12.2f} {many * 1e3:18.2f}"
            )
    print("(start: evaluator creation up to the first finished run of every worker; with")
    print(" workers the figures are wall time per evaluation, runs going side by side)")


def dask_startup() -> None:
    print("\n== Dask start-up (a LocalCluster started for the study)")
    for workers in (1, 2):
        with fbia.make_evaluator("dask", workers=workers) as ev:
            print(f"LocalCluster of {workers} worker(s): ready after {ev.startup_time:.2f} s")


def _timed(fn: Any) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def store(n: int, root: Path) -> None:
    problem = dataclass_noise(_problem(0.0))
    rng = np.random.default_rng(0)
    path = root / "store.sqlite"
    print(f"\n== store: {n} records with 81 residuals each, one transaction per write")
    with StudyStore(path) as s:
        s.bind(problem)
        s.begin_session({"kind": "benchmark"})
        records = []
        for i in range(n):
            x = {"E": 100.0 + 700.0 * (i / n), "nu": float(rng.uniform(-0.8, 0.5))}
            r = rng.normal(0.0, 1e-3, 81)
            ok = i % 10 != 0
            records.append(
                fbia.Evaluation(
                    index=i,
                    x=x,
                    status="ok" if ok else "failed",
                    message="" if ok else "mesh distortion",
                    residuals=r if ok else None,
                    distances=[float(np.linalg.norm(r))] if ok else None,
                    time=0.5,
                    workdir=None if ok else f"runs/eval_{i:06d}",
                    diagnostics={"newton": 4},
                )
            )
        keys = [s.key(ev.x) for ev in records]
        t0 = time.perf_counter()
        for ev, key in zip(records, keys, strict=True):
            s.put(ev, key, worker="host:1234")
        write = time.perf_counter() - t0
        s.end_session("done")
        t0 = time.perf_counter()
        back = s.runs()
        read_all = time.perf_counter() - t0
        t0 = time.perf_counter()
        found = 0
        for k in range(0, n, 1000):
            found += len(s.lookup(keys[k : k + 1000]))
        lookup = time.perf_counter() - t0
    assert len(back) == n and found == n
    assert np.array_equal(back[1].record.residuals, records[1].residuals)
    size = sum(
        Path(f"{path}{sfx}").stat().st_size for sfx in ("", "-wal") if Path(f"{path}{sfx}").exists()
    )
    print(f"write: {write:.2f} s in all, {write / n * 1e6:.0f} us per record (own transaction)")
    print(f"read back all: {read_all:.2f} s, {read_all / n * 1e6:.1f} us per record")
    print(f"look up by key, batches of 1000: {lookup:.2f} s, {lookup / n * 1e6:.1f} us per record")
    print(f"file: {size / 2**20:.1f} MiB ({size / n:.0f} bytes per record)")


def dataclass_noise(problem: fbia.InverseProblem) -> fbia.InverseProblem:
    """The problem with a likelihood noise level (so that every write computes eq. 5)."""
    problem.noise_std = 0.001
    return problem


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="a smoke run with small counts")
    args = parser.parse_args()
    n_sleep, n_noop, n_store = (20, 100, 10_000) if args.quick else (200, 400, 100_000)
    with tempfile.TemporaryDirectory(prefix="fbia-bench-") as tmp:
        root = Path(tmp)
        dask_startup()
        overhead(n_noop, root)
        store(n_store, root)
        throughput(n_sleep, root)


if __name__ == "__main__":
    main()
