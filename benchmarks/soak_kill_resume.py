"""Kill/resume soak (issue 14): ``kill -9`` a running study at random moments, resume it, and
count what held (run by hand: ``python benchmarks/soak_kill_resume.py [--trials N]``).

For each executor set-up (serial, serial isolated, process pool, process pool isolated, Dask
LocalCluster) and each trial: start ``fbia run`` on Levenberg-Marquardt with two starts on the
toy model of ``tests/_models.py`` (0.05 s per run) in a subprocess, send SIGKILL to the study
process at a random moment (seeded), then run the same command again until it finishes.  A
trial is

* **clean** when the resumed run exits 0, nothing printed a traceback, every run stored
  before the kill is still stored and unchanged, none was run again, the result is the
  uninterrupted one (same x, status, evaluations) and no worker process outlived its study
  by more than 10 s;
* **traceback** when either process printed a Python traceback;
* **lost** when a stored run vanished or changed, or one was run again;
* **orphans** when a worker process of the killed study was still alive 10 s later.

Prints one row per set-up (tried / clean / traceback / lost / orphans / runs reused) and the
totals; the goal is every row clean, nothing lost.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
sys.path.insert(0, str(TESTS))

from _models import write_driver  # noqa: E402  (the toy plugins' command line)

STUDY = """\
[study]
seed = 2
[model]
name = "toy_mound"
options = {{ delay = 0.05 }}
[[parameters]]
name = "E"
bounds = [100.0, 800.0]
[[parameters]]
name = "nu"
bounds = [-0.8, 0.5]
[synthetic]
truth = {{ E = 450.0, nu = 0.15 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]
noise_std = 0.001
[measure]
name = "vertical"
[iterator]
name = "levenberg_marquardt"
options = {{ x0 = [ {{ E = 200.0, nu = 0.4 }}, {{ E = 700.0, nu = -0.5 }} ] }}
[executor]
{executor}
"""


SETUPS = {
    "serial": 'kind = "serial"',
    "serial isolated": 'kind = "serial"\nisolate = true',
    "processes": 'kind = "processes"\nworkers = 2',
    "processes isolated": 'kind = "processes"\nworkers = 2\nisolate = true',
    "dask local": 'kind = "dask"\nworkers = 2',
}


def _rows(store: Path) -> dict[str, tuple]:
    if not store.is_file():
        return {}
    db = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        rows = db.execute(
            "SELECT key, x, status, interfaces, worker, attempt, finished FROM runs"
        ).fetchall()
    except sqlite3.OperationalError as exc:
        if "no such table" in str(exc):  # killed while the store was being created
            return {}
        raise
    finally:
        db.close()
    return {r[0]: r for r in rows}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _essence(folder: Path) -> dict:
    result = json.loads((folder / "output" / "result.json").read_text())
    return {
        "status": result["status"],
        "x": result["x"],
        "points": [ev["x"] for ev in result["evaluations"]],
    }


def _run(folder: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "drive.py", "run", "toy.toml"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=600,
    )


def trial(folder: Path, executor: str, kill_after: float, reference: dict) -> dict[str, bool]:
    write_driver(folder)
    (folder / "toy.toml").write_text(STUDY.format(executor=executor))
    # stderr to a file: children of the killed study may hold a pipe open
    with open(folder / "stderr1.txt", "w") as err_file:
        proc = subprocess.Popen(
            [sys.executable, "drive.py", "run", "toy.toml"],
            cwd=folder,
            stdout=subprocess.DEVNULL,
            stderr=err_file,
            start_new_session=True,
        )
        time.sleep(kill_after)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    time.sleep(0.5)  # what its children print as they notice
    err1 = (folder / "stderr1.txt").read_text()
    store = folder / "output" / "store.sqlite"
    before = _rows(store)
    workers = {
        int(r[4].rsplit(":", 1)[1])
        for r in before.values()
        if r[4] and r[4].rsplit(":", 1)[1].isdigit() and int(r[4].rsplit(":", 1)[1]) != proc.pid
    }
    deadline = time.monotonic() + 10.0
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    orphans = any(_alive(p) for p in workers)
    for p in workers:  # do not let one trial's orphans slow the next
        if _alive(p):
            os.kill(p, signal.SIGKILL)
    resumed = _run(folder)
    after = _rows(store)
    lost = any(after.get(k) != v for k, v in before.items()) or any(
        r[5] != 1 for r in after.values()
    )
    traceback = "Traceback" in err1 or "Traceback" in resumed.stderr
    same = resumed.returncode == 0 and _essence(folder) == reference
    return {
        "clean": same and not traceback and not lost and not orphans,
        "traceback": traceback,
        "lost": lost,
        "orphans": orphans,
        "reused": len(before),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=6, help="kills per executor set-up")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--setups", nargs="*", default=list(SETUPS), choices=list(SETUPS))
    args = ap.parse_args()
    rng = random.Random(args.seed)
    print(
        f"{'set-up':20s} {'tried':>5s} {'clean':>5s} {'trace':>5s} {'lost':>5s} "
        f"{'orphan':>6s} {'reused':>6s}"
    )
    totals = [0, 0, 0, 0, 0, 0]
    for name in args.setups:
        executor = SETUPS[name]
        with tempfile.TemporaryDirectory(prefix="fbia-soak-") as tmp:
            ref = Path(tmp) / "reference"
            ref.mkdir()
            write_driver(ref)
            (ref / "toy.toml").write_text(STUDY.format(executor=executor))
            t0 = time.monotonic()
            done = _run(ref)
            duration = time.monotonic() - t0
            if done.returncode != 0:
                sys.exit(f"{name}: the uninterrupted study failed:\n{done.stderr}")
            reference = _essence(ref)
            row = [0, 0, 0, 0, 0, 0]
            for k in range(args.trials):
                folder = Path(tmp) / f"trial{k}"
                folder.mkdir()
                outcome = trial(folder, executor, rng.uniform(0.5, duration), reference)
                shutil.rmtree(folder, ignore_errors=True)
                row[0] += 1
                for i, key in enumerate(("clean", "traceback", "lost", "orphans"), start=1):
                    row[i] += int(outcome[key])
                row[5] += int(outcome["reused"])
        totals = [a + b for a, b in zip(totals, row, strict=True)]
        print(f"{name:20s} {row[0]:5d} {row[1]:5d} {row[2]:5d} {row[3]:5d} {row[4]:6d} {row[5]:6d}")
    print(
        f"{'total':20s} {totals[0]:5d} {totals[1]:5d} {totals[2]:5d} {totals[3]:5d} "
        f"{totals[4]:6d} {totals[5]:6d}"
    )


if __name__ == "__main__":
    main()
