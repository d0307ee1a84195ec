"""fbia.core: data types, protocols, plugin registry, evaluators, study files and CLI."""

from . import parameters as priors
from .errors import ConfigError, FbiaError, ForwardModelError, MeasureError, PluginError
from .evaluator import BatchEvaluator, Evaluator
from .executors import make_evaluator
from .hookspecs import hookimpl
from .interface import Interface
from .iteration import InverseIterator, IteratorBase
from .local_executors import ProcessPoolEvaluator, SerialEvaluator
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
from .protocols import Discrepancy, ForwardModel
from .registry import Registry, forward_model, iterator, list_plugins, measure

__all__ = [
    "ConfigError",
    "Configurable",
    "Coordinate",
    "Discrepancy",
    "Evaluation",
    "BatchEvaluator",
    "Evaluator",
    "FbiaError",
    "ForwardModel",
    "IteratorBase",
    "ForwardModelError",
    "Interface",
    "InverseProblem",
    "InverseIterator",
    "MeasureError",
    "MeasurementPoints",
    "Observation",
    "Parameter",
    "PluginError",
    "PluginOptions",
    "Prior",
    "ProcessPoolEvaluator",
    "Registry",
    "Result",
    "SerialEvaluator",
    "Solution",
    "coordinate_key",
    "forward_model",
    "hookimpl",
    "iterator",
    "make_evaluator",
    "measure",
    "list_plugins",
    "priors",
]
