"""A model that raises SystemExit or KeyboardInterrupt itself gives a failed record, the same
under every executor; a real Ctrl-C still stops the study (issue 14, defect 11).

``sys.exit(0)`` in a model used to end ``fbia run`` with status 0 under the serial executor,
and the same fault gave different records on the pool, in isolated runs and on Dask.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from _models import toy_problem

import fbia
from fbia.execution.isolation import escaped_message

EXECUTORS: dict[str, Callable[[Path], fbia.BatchEvaluator]] = {
    "serial": lambda wd: fbia.SerialEvaluator(workdir=wd),
    "serial isolated": lambda wd: fbia.SerialEvaluator(workdir=wd, isolate=True),
    "processes": lambda wd: fbia.ProcessPoolEvaluator(workers=2, workdir=wd),
    "processes isolated": lambda wd: fbia.ProcessPoolEvaluator(workers=2, workdir=wd, isolate=True),
    "dask": lambda wd: fbia.make_evaluator("dask", workers=1, workdir=wd, isolate=False),
    "dask isolated": lambda wd: fbia.make_evaluator("dask", workers=1, workdir=wd),
}
# exit_above = 500: sys.exit(round(10 nu)); raise_interrupt_above = 700: KeyboardInterrupt
BATCH = [
    {"E": 300.0, "nu": 0.3},
    {"E": 600.0, "nu": 0.0},
    {"E": 650.0, "nu": 0.3},
    {"E": 750.0, "nu": 0.3},
    {"E": 400.0, "nu": 0.2},
]
EXPECTED = [
    ("ok", ""),
    ("failed", escaped_message(SystemExit(0))),
    ("failed", escaped_message(SystemExit(3))),
    ("failed", escaped_message(KeyboardInterrupt())),
    ("ok", ""),
]


@pytest.mark.parametrize("kind", list(EXECUTORS))
def test_sys_exit_and_keyboard_interrupt_in_a_model_are_the_same_failed_records(tmp_path, kind):
    problem = toy_problem(exit_above=500.0, raise_interrupt_above=700.0)
    with EXECUTORS[kind](tmp_path) as ev:
        records = ev.evaluate(problem, BATCH)
        assert [(r.status, r.message) for r in records] == EXPECTED
        assert [r.x for r in records] == BATCH
        # the executor is still usable
        assert [r.status for r in ev.evaluate(problem, [{"E": 450.0, "nu": 0.1}])] == ["ok"]


def test_the_messages_say_what_the_model_did():
    assert escaped_message(SystemExit(0)).startswith(
        "the forward model raised SystemExit(0) (sys.exit or exit() in the model"
    )
    assert "KeyboardInterrupt, with no Ctrl-C to the study" in escaped_message(KeyboardInterrupt())


def test_a_real_ctrl_c_during_a_serial_run_still_stops_the_batch(tmp_path):
    # interrupt_above: the model sends SIGINT to its own process, as a terminal's Ctrl-C does
    seen: list[str] = []
    with fbia.SerialEvaluator(workdir=tmp_path, on_record=lambda r: seen.append(r.status)) as ev:
        with pytest.raises(KeyboardInterrupt):
            ev.evaluate(toy_problem(interrupt_above=500.0), BATCH)
    assert seen == ["ok"]


class _CatchingModel(fbia.ForwardModelBase):
    """Turns whatever it catches, Ctrl-C included, into a failed run."""

    dim = 2

    class Options(fbia.PluginOptions):
        pass

    def parameter_names(self) -> tuple[str, ...]:
        return ("E", "nu")

    def solve(self, parameters, coordinates, workdir):  # type: ignore[no-untyped-def]
        import os
        import signal
        import time

        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)
        except BaseException as exc:
            raise fbia.ForwardModelError(f"caught {type(exc).__name__}") from None
        raise AssertionError("no KeyboardInterrupt")


def test_a_ctrl_c_that_the_model_catches_still_stops_the_batch(tmp_path):
    problem = toy_problem()
    problem.model = _CatchingModel()
    with fbia.SerialEvaluator(workdir=tmp_path) as ev:
        with pytest.raises(KeyboardInterrupt):
            ev.evaluate(problem, BATCH[:1])
