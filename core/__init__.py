"""fbia.core, the kernel: the contracts and values every other part of fbia builds on.

Errors, options, the plugin registry and its hooks, the three extension contracts
(the protocols ``ForwardModel``, ``Discrepancy`` and ``InverseIterator`` and the bases
``ForwardModelBase`` and ``MeasureBase`` in ``protocols``; ``IteratorBase`` and the
``Evaluator`` an iterator receives in ``iteration``), interfaces, observations, parameters
and priors, the inverse problem and its results, the likelihood and synthetic data.  It
imports nothing of fbia outside itself (``tests/test_architecture.py``), and no store,
executor, plotting or finite-element library: where runs happen is ``fbia.execution``, the
store ``fbia.storage``, the study application ``fbia.studies``, OCT scans ``fbia.imaging``.
"""

from . import parameters as priors
from .errors import ConfigError, FbiaError, ForwardModelError, MeasureError, PluginError
from .hookspecs import hookimpl
from .interface import Interface
from .iteration import Evaluator, IteratorBase
from .observation import (
    Coordinate,
    MeasurementPoints,
    Observation,
    Solution,
    coordinate_key,
)
from .options import Configurable, PluginOptions
from .parameters import Parameter, Prior
from .problem import Evaluation, InverseProblem, Result
from .protocols import Discrepancy, ForwardModel, ForwardModelBase, InverseIterator, MeasureBase
from .registry import Registry, forward_model, iterator, list_plugins, measure

__all__ = [
    "ConfigError",
    "Configurable",
    "Coordinate",
    "Discrepancy",
    "Evaluation",
    "Evaluator",
    "FbiaError",
    "ForwardModel",
    "ForwardModelBase",
    "IteratorBase",
    "ForwardModelError",
    "Interface",
    "InverseProblem",
    "InverseIterator",
    "MeasureBase",
    "MeasureError",
    "MeasurementPoints",
    "Observation",
    "Parameter",
    "PluginError",
    "PluginOptions",
    "Prior",
    "Registry",
    "Result",
    "Solution",
    "coordinate_key",
    "forward_model",
    "hookimpl",
    "iterator",
    "measure",
    "list_plugins",
    "priors",
]
