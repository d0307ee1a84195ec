"""fbia.core: data types, protocols, plugin registry, evaluators, study files and CLI."""

from fbia.core import parameters as priors
from fbia.core.errors import ConfigError, FbiaError, ForwardModelError, MeasureError, PluginError
from fbia.core.evaluator import Evaluator, ProcessPoolEvaluator, SerialEvaluator, make_evaluator
from fbia.core.hookspecs import hookimpl
from fbia.core.interface import Interface
from fbia.core.iteration import IteratorBase
from fbia.core.observation import (
    Coordinate,
    MeasurementPoints,
    Observation,
    Solution,
    coordinate_key,
)
from fbia.core.options import Configurable, PluginOptions
from fbia.core.parameters import Parameter, Prior
from fbia.core.problem import Evaluation, InverseProblem, Result
from fbia.core.protocols import Discrepancy, ForwardModel, Iterator
from fbia.core.registry import Registry, forward_model, iterator, measure, plugins

__all__ = [
    "ConfigError",
    "Configurable",
    "Coordinate",
    "Discrepancy",
    "Evaluation",
    "Evaluator",
    "FbiaError",
    "ForwardModel",
    "IteratorBase",
    "ForwardModelError",
    "Interface",
    "InverseProblem",
    "Iterator",
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
    "plugins",
    "priors",
]
