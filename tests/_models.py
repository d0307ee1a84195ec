"""Small plugin classes for the tests of evaluators, study files and the CLI.

They live in an importable module (pytest puts ``tests/`` on ``sys.path``) so that worker
processes started with ``spawn`` can unpickle them.  They are registered only in registries
the tests build themselves (``Registry.load(extra=[PLUGIN])``), never globally.

``ToyMoundForwardModel``: a 2-D bump ``y(x) = (h / (E/400)) * sin(pi x) * (1 + nu * x)``
on ``x`` in [0, 1], with ``h = 0.1 * inflow_rate / 100`` [mm]: closed form, so every
evaluation has an exact expected value.  Its options make it fail on purpose:
``fail_above`` (ForwardModelError when E exceeds it), ``bug_above`` (RuntimeError),
``die_above`` (``os._exit`` of the process running it), ``interrupt_above``
(a real SIGINT to its own process, as Ctrl-C during a run), ``exit_above`` (``sys.exit`` with
status ``round(10 nu)``) and ``raise_interrupt_above`` (a KeyboardInterrupt raised by the
model itself, with no signal).  With ``rendezvous`` (a file path),
a run with E below ``wait_below`` creates ``<file>.waiting`` and waits for the file and then
0.5 s more, and a dying run first waits for ``<file>.waiting`` (when ``wait_below`` is set)
and creates the file: so the two are under way together when the worker dies.

Injected faults for the evaluation engine (``fault_rate``): a fraction of the inputs, chosen
by a hash of (E, nu) (:func:`injected_fault`), fails (ForwardModelError), hangs (starts a
``sleep 600`` solver, writes both process ids to ``hang.pids`` in the run's folder and waits
for it) or kills its own process (``os._exit(7)``), a third each.  ``delay`` makes every run
take that long (a stand-in for an expensive model).
"""

from __future__ import annotations

import hashlib
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Generator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field

import fbia
from fbia.core.hookspecs import hookimpl

X = np.linspace(0.0, 1.0, 21)


def toy_curve(E: float, nu: float, inflow_rate: float = 100.0) -> np.ndarray:
    """The exact toy interface, (21, 2) [mm]."""
    h = 0.1 * inflow_rate / 100.0 / (E / 400.0)
    return np.c_[X, h * np.sin(np.pi * X) * (1.0 + nu * X)]


class ToyMoundForwardModel(fbia.ForwardModelBase):
    """Closed-form 2-D test model with switchable failures (see the module docstring)."""

    dim = 2

    class Options(fbia.PluginOptions):
        inflow_rate: float = Field(100.0, gt=0, description="inflow rate [mm^2/s]")
        fail_above: float = Field(math.inf, description="E above which solve raises [Pa]")
        bug_above: float = Field(math.inf, description="E above which a RuntimeError [Pa]")
        die_above: float = Field(math.inf, description="E above which os._exit(3) [Pa]")
        interrupt_above: float = Field(math.inf, description="E above which Ctrl-C [Pa]")
        exit_above: float = Field(math.inf, description="E above which sys.exit [Pa]")
        raise_interrupt_above: float = Field(
            math.inf, description="E above which to raise KeyboardInterrupt [Pa]"
        )
        wait_below: float = Field(-math.inf, description="E below which to wait [Pa]")
        slow_above: float = Field(math.inf, description="E above which to sleep 30 s [Pa]")
        rendezvous: str = Field("", description="file a dying run creates first")
        delay: float = Field(0.0, ge=0, description="wall time every run takes [s]")
        fault_rate: float = Field(
            0.0, ge=0, lt=1, description="fraction of inputs with an injected fault [-]"
        )
        nan_above: float = Field(math.inf, description="E above which NaN coordinates [Pa]")
        odd_diagnostics: bool = Field(
            False, description="diagnostics with NaN, inf and objects JSON does not know"
        )
        pause_below: float = Field(-math.inf, description="E below which to sleep 0.6 s [Pa]")
        history: bool = Field(
            False,
            description="diagnostics 'earlier': the E of every earlier run of this model "
            "object (what a warm-starting model's result depends on) [-]",
        )

    def parameter_names(self) -> Sequence[str]:
        return ("E", "nu", "inflow_rate")

    def solve(
        self, parameters: Mapping[str, float], coordinates: Sequence[Mapping[str, float]], workdir
    ) -> fbia.Solution:
        E = parameters.get("E", 400.0)
        nu = parameters.get("nu", 0.3)
        if self.options.delay:
            time.sleep(self.options.delay)
        if E < self.options.pause_below:
            time.sleep(0.6)
        earlier = self.__dict__.setdefault("_earlier", [])
        earlier.append(E)
        fault = injected_fault(E, nu, self.options.fault_rate)
        if fault == "fail":
            raise fbia.ForwardModelError(f"injected failure at E = {E}")
        if fault == "exit":
            os._exit(7)
        if fault == "hang":
            solver = subprocess.Popen(["sleep", "600"])
            (Path(workdir) / "hang.pids").write_text(f"{os.getpid()} {solver.pid}\n")
            solver.wait()
        if E > self.options.slow_above:
            time.sleep(30.0)
        waiting = Path(f"{self.options.rendezvous}.waiting")
        if E > self.options.die_above:
            if self.options.rendezvous:
                # with a waiting run in the set-up, die only once it is under way too
                deadline = time.monotonic() + 30.0
                while (
                    self.options.wait_below > -math.inf
                    and not waiting.exists()
                    and time.monotonic() < deadline
                ):
                    time.sleep(0.01)
                Path(self.options.rendezvous).touch()
            os._exit(3)
        if E < self.options.wait_below:
            waiting.touch()
            deadline = time.monotonic() + 30.0
            while not Path(self.options.rendezvous).exists() and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.5)
        if E > self.options.interrupt_above:  # Ctrl-C in the middle of a run
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # the signal's handler raises KeyboardInterrupt in here
        if E > self.options.raise_interrupt_above:
            raise KeyboardInterrupt
        if E > self.options.exit_above:
            sys.exit(round(10 * nu))
        if E > self.options.bug_above:
            raise RuntimeError(f"toy bug at E = {E}")
        if E > self.options.fail_above:
            raise fbia.ForwardModelError(f"mesh distortion at E = {E}")
        (Path(workdir) / "toy.txt").write_text(f"E={E}\n")
        pairs = []
        for c in coordinates:
            q = c.get("inflow_rate", parameters.get("inflow_rate", self.options.inflow_rate))
            curve = toy_curve(E, nu, q)
            if E > self.options.nan_above:
                curve[len(curve) // 2, 1] = np.nan  # a diverged solve
            pairs.append((c, fbia.Interface.polyline(curve)))
        diagnostics: dict[str, Any] = {"E": E}
        if self.options.history:
            diagnostics["earlier"] = earlier[:-1]
        if self.options.odd_diagnostics:
            diagnostics.update(
                nan=np.float64("nan"),
                inf=np.float32("inf"),
                values=np.array([1.0, np.nan, -np.inf]),
                where=Path(workdir),
                kinds={"b", "a"},
                solver=object(),
            )
        return fbia.Solution.from_pairs(pairs, diagnostics=diagnostics)


def injected_fault(E: float, nu: float, rate: float) -> str | None:
    """The fault of the toy model at (E, nu): "fail", "hang", "exit" or None.

    u = the SHA-256 of repr(E), repr(nu) as a number in [0, 1); a fault when u < rate, its
    kind by u in thirds of [0, rate).
    """
    if rate <= 0:
        return None
    digest = hashlib.sha256(f"{E!r},{nu!r}".encode()).digest()
    u = int.from_bytes(digest[:8], "big") / 2.0**64
    if u >= rate:
        return None
    return ("fail", "hang", "exit")[min(2, int(3 * u / rate))]


class VerticalMeasure(fbia.MeasureBase):
    """Residuals: simulated minus observed y at the observed vertices (same x grid) [mm]."""

    class Options(fbia.PluginOptions):
        scale: float = Field(1.0, gt=0, description="factor on the residuals [-]")

    def residuals(self, simulated: fbia.Interface, observation: fbia.Observation) -> np.ndarray:
        assert observation.interface is not None
        obs = observation.interface.vertices
        y = np.interp(obs[:, 0], simulated.vertices[:, 0], simulated.vertices[:, 1])
        return self.options.scale * (y - obs[:, 1])

    def distance(self, simulated: fbia.Interface, observation: fbia.Observation) -> float:
        return float(np.linalg.norm(self.residuals(simulated, observation)))


class GridIterator(fbia.IteratorBase):
    """Evaluates an n x n grid over the bounds, one row per step; x = the smallest D."""

    class Options(fbia.PluginOptions):
        n: int = Field(3, ge=2, description="grid points per parameter [-]")
        seed: int = Field(0, description="unused here; shows that studies inject a seed")

    def steps(
        self, problem: fbia.InverseProblem, evaluator: Any
    ) -> Generator[int, None, fbia.Result]:
        axes = [
            np.linspace(lo, hi, self.options.n)
            for lo, hi in zip(problem.lower, problem.upper, strict=True)
        ]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
        records = []
        for row in np.array_split(grid, self.options.n):
            records += evaluator.evaluate(problem, [problem.as_dict(x) for x in row])
            yield len(records)
        ok = [r for r in records if r.ok]
        best = min(ok, key=lambda r: r.distance) if ok else None
        return fbia.Result(
            status="grid_done" if best else "all_failed",
            success=best is not None,
            message=f"evaluated {len(records)} grid points",
            x={n: best.x[n] for n in problem.names} if best else None,
            nfev=len(records),
            n_failed=sum(not r.ok for r in records),
            evaluations=records,
        )


class _Plugin:
    """The hook implementations that register the classes above (tests only)."""

    @hookimpl
    def register_forward_models(self, register):
        register("toy_mound", ToyMoundForwardModel)

    @hookimpl
    def register_measures(self, register):
        register("vertical", VerticalMeasure)

    @hookimpl
    def register_iterators(self, register):
        register("grid", GridIterator)


PLUGIN = _Plugin()


def toy_problem(**model_options: Any) -> fbia.InverseProblem:
    """The toy model against its own exact curve at E = 400 Pa, nu = 0.3."""
    obs = fbia.Observation(
        interface=fbia.Interface.polyline(toy_curve(400.0, 0.3)), coordinate={"inflow_rate": 100.0}
    )
    return fbia.InverseProblem(
        model=ToyMoundForwardModel(**model_options),
        measure=VerticalMeasure(),
        observations=[obs],
        parameters=[
            fbia.Parameter("E", bounds=(100.0, 800.0)),
            fbia.Parameter("nu", bounds=(-0.8, 0.5)),
        ],
    )


#: Two batches for the worker-assignment tests of the process pool and Dask (issue 48): the
#: first run (E = 100 Pa, below ``pause_below = 150``) takes 0.6 s longer than the others.
HISTORY_BATCHES = [
    [{"E": E, "nu": 0.3} for E in (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 250.0)],
    [{"E": E, "nu": 0.1} for E in (350.0, 450.0, 120.0)],
]


def expected_histories(
    batches: Sequence[Sequence[Mapping[str, float]]], workers: int
) -> list[list[list[float]]]:
    """What each run of ``batches`` reports as its process's earlier runs (the toy model's
    ``history`` option) when run k of a batch of n goes to ``workers_of_runs(n, workers)[k]``
    and each worker takes its runs in the batch's order."""
    from fbia.execution.local_executors import workers_of_runs

    ran: dict[int, list[float]] = {w: [] for w in range(workers)}  # E of each worker's runs
    expected: list[list[list[float]]] = []
    for batch in batches:
        expected.append([])
        for w, p in zip(workers_of_runs(len(batch), workers), batch, strict=True):
            expected[-1].append(list(ran[w]))
            ran[w].append(p["E"])
    return expected


#: A 4 x 4 grid (what GridIterator(n=4) evaluates on E in [100, 760] Pa, nu in [-0.8, 0.5])
#: where ``fault_rate = 0.2`` injects 4 faults (25 %): one failure, one hang, two exits.
FAULT_BOUNDS = ((100.0, 760.0), (-0.8, 0.5))
FAULT_GRID = [
    {"E": float(E), "nu": float(nu)}
    for E in np.linspace(*FAULT_BOUNDS[0], 4)
    for nu in np.linspace(*FAULT_BOUNDS[1], 4)
]


def check_injected_faults(records: Sequence[fbia.Evaluation], timeout: float) -> None:
    """Assert that every record of FAULT_GRID (rate 0.2) has the status and message of its
    fault, that the ok ones are exact, and that each hung run's processes were killed."""
    kinds = [injected_fault(x["E"], x["nu"], 0.2) for x in FAULT_GRID]
    assert sorted(k for k in kinds if k) == ["exit", "exit", "fail", "hang"]
    assert [r.x for r in records] == FAULT_GRID
    reference = toy_curve(400.0, 0.3)[:, 1]
    for r, kind in zip(records, kinds, strict=True):
        if kind is None:
            assert r.status == "ok", r.message
            exact = toy_curve(r.x["E"], r.x["nu"])[:, 1] - reference
            np.testing.assert_allclose(r.residuals, exact, atol=1e-15)
            continue
        assert r.status == "failed" and r.residuals is None
        if kind == "fail":
            assert r.message == f"injected failure at E = {r.x['E']}"
        elif kind == "exit":
            assert r.message.startswith(
                "the process running this evaluation died (exit status 7: e.g. os._exit"
            )
        else:
            assert r.message.startswith(f"time-out after {timeout:g} s: the run was stopped")
            assert timeout <= r.time < timeout + 5.0
            # the run's process and the solver it started were killed, not left running
            pids = [int(p) for p in (Path(r.workdir) / "hang.pids").read_text().split()]
            for pid in pids:
                assert not _alive_after(pid, KILL_GRACE), (
                    f"process {pid} of the hung run is still running"
                )


#: how long a killed process may take to be gone: SIGKILL is delivered asynchronously, and on
#: a loaded machine the kernel tears the process down a moment after the kill returned (seen
#: once in a fresh-clone CI run, never alone)
KILL_GRACE = 2.0


def _alive_after(pid: int, grace: float) -> bool:
    """Whether a process still runs ``grace`` seconds from now (it is polled until then)."""
    deadline = time.monotonic() + grace
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return _alive(pid)


def _alive(pid: int) -> bool:
    """Whether a process runs (a zombie, dead but not yet reaped by its parent, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:  # gone meanwhile, or no /proc
        return stat.parent.exists()


_DRIVER = """
import sys
sys.path.insert(0, {tests!r})
from _models import PLUGIN
from fbia.studies import study_file as study
from fbia.studies.cli import main
from fbia.core.registry import Registry
registry = Registry.load(extra=[PLUGIN])
study.default_registry = lambda: registry
if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
"""


def write_driver(folder: Path) -> Path:
    """``folder/drive.py``: the fbia command line with the toy plugins registered, for tests
    that need a process of its own (signals, ``kill -9``)."""
    path = Path(folder) / "drive.py"
    path.write_text(_DRIVER.format(tests=str(Path(__file__).resolve().parent)))
    return path
