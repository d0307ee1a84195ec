"""fbia: inverse analysis of coupled biofilm models from the shape of the fluid-biofilm interface.

>>> import fbia
>>> model = fbia.forward_model("analytic_mound_2d")
>>> obs = fbia.synthetic_observations(model, {"E": 400.0, "nu": 0.3},
...                                   [{"inflow_rate": 100.0}], noise_std=0.002, seed=0)
>>> problem = fbia.InverseProblem(model=model, measure=fbia.measure("rkhs", sigma_w=0.05),
...                               observations=obs, noise_std=0.002,
...                               parameters=[fbia.Parameter("E", bounds=(100.0, 800.0)),
...                                           fbia.Parameter("nu", bounds=(-0.8, 0.5))])

The package maps the repository folders ``core/``, ``plugins/``, ``measures/`` and
``iterators/`` to ``fbia.core``, ``fbia.plugins``, ``fbia.measures`` and ``fbia.iterators``.
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

from .core import *  # noqa: F403  (the public core types)
from .core import __all__ as _core_all
from .core.version import __version__

# Public names that live in modules imported on first use (they pull in heavier libraries).
_LAZY = {
    "synthetic_observations": "fbia.core.synthetic:synthetic_observations",
    "Study": "fbia.core.study:Study",
    "load_study": "fbia.core.study_file:load_study",
    "run_study": "fbia.core.runner:run_study",
    "forward_study": "fbia.core.runner:forward_study",
    "least_squares": "fbia.iterators.least_squares:least_squares",
    "smc": "fbia.iterators.smc:smc",
    "DaskEvaluator": "fbia.core.dask_executor:DaskEvaluator",
    "StudyStore": "fbia.core.store:StudyStore",
    "segment_oct": "fbia.core.oct:segment_oct",
    "load_result": "fbia.core.result_io:load_result",
    "plot": "fbia.core.plots:plot",
}

__all__ = [*_core_all, *_LAZY, "__version__"]

# A library configures no handlers: its modules log to ``fbia.<module>`` (progress at INFO);
# ``logging.basicConfig(level=logging.INFO)`` shows it, ``fbia run`` writes it to fbia.log.
logging.getLogger(__name__).addHandler(logging.NullHandler())


def __getattr__(name: str) -> Any:
    target = _LAZY.get(name)
    if target is None:
        raise AttributeError(f"module 'fbia' has no attribute {name!r}")
    module, attr = target.split(":")
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value
