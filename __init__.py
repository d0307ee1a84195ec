"""fbia: inverse analysis of coupled biofilm models from the shape of the fluid-biofilm interface.

>>> import fbia
>>> model = fbia.forward_model("analytic_mound_2d")
>>> obs = fbia.synthetic_observations(model, {"E": 400.0, "nu": 0.3},
...                                   [{"inflow_rate": 100.0}], noise_std=0.002, seed=0)
>>> problem = fbia.InverseProblem(model=model, measure=fbia.measure("rkhs", sigma_w=0.05),
...                               observations=obs, noise_std=0.002,
...                               parameters=[fbia.Parameter("E", bounds=(100.0, 800.0)),
...                                           fbia.Parameter("nu", bounds=(-0.8, 0.5))])

The repository folders are its sub-packages: the kernel ``core/`` (contracts and values),
``execution/`` (evaluators and executors), ``storage/`` (the study store), ``imaging/`` (OCT
scans, figure helpers), ``studies/`` (study files, the runner, reports, the CLI) and the
plugins ``plugins/``, ``measures/``, ``iterators/`` (docs/architecture.md).  This module is the
composition root: it re-exports the public names and wires the kernel's default evaluator.
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

from .core import *  # noqa: F403  (the public core types)
from .core import __all__ as _core_all
from .core.iteration import Evaluator, set_default_evaluator
from .core.version import __version__

# Public names that live in modules imported on first use (they pull in heavier libraries).
_LAZY = {
    "synthetic_observations": "fbia.core.synthetic:synthetic_observations",
    "Study": "fbia.studies.study:Study",
    "load_study": "fbia.studies.study_file:load_study",
    "run_study": "fbia.studies.runner:run_study",
    "forward_study": "fbia.studies.runner:forward_study",
    "least_squares": "fbia.iterators.least_squares:least_squares",
    "smc": "fbia.iterators.smc.sampler:smc",
    "BatchEvaluator": "fbia.execution.evaluator:BatchEvaluator",
    "SerialEvaluator": "fbia.execution.local_executors:SerialEvaluator",
    "ProcessPoolEvaluator": "fbia.execution.local_executors:ProcessPoolEvaluator",
    "make_evaluator": "fbia.execution.executors:make_evaluator",
    "DaskEvaluator": "fbia.execution.dask_executor:DaskEvaluator",
    "StudyStore": "fbia.storage.store:StudyStore",
    "segment_oct": "fbia.imaging.oct:segment_oct",
    "observation_from_oct": "fbia.imaging.oct:observation_from_oct",
    "load_result": "fbia.studies.result_io:load_result",
    "plot": "fbia.studies.plots:plot",
}

__all__ = [*_core_all, *_LAZY, "__version__"]

# A library configures no handlers: its modules log to ``fbia.<module>`` (progress at INFO);
# ``logging.basicConfig(level=logging.INFO)`` shows it, ``fbia run`` writes it to fbia.log.
logging.getLogger(__name__).addHandler(logging.NullHandler())


def _serial_evaluator() -> Evaluator:
    """``IteratorBase.run``'s evaluator when it is given none (the kernel names no executor)."""
    from .execution.local_executors import SerialEvaluator

    return SerialEvaluator()


set_default_evaluator(_serial_evaluator)


def __getattr__(name: str) -> Any:
    target = _LAZY.get(name)
    if target is None:
        raise AttributeError(f"module 'fbia' has no attribute {name!r}")
    module, attr = target.split(":")
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value
