"""The checks that fit a registry entry."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..core.options import Configurable
from ..core.registry import PluginEntry
from .errors import fail
from .measures import check_measure
from .models import check_forward_model, example_run
from .options import check_options, example_options


def failing_run(
    cls: type[Configurable], parameters: Mapping[str, float]
) -> tuple[dict[str, Any], dict[str, float]] | None:
    """Options and parameters of a run that must fail, by the ``failure_region`` convention.

    A forward model whose ``Options`` have a ``failure_region`` ({parameter: [lo, hi]}: the
    run raises :class:`fbia.ForwardModelError` when every named parameter lies in its
    interval) can be made to fail on purpose.  Returns ``(options, failing_parameters)``: a
    region around the first of ``parameters`` moved by 10 %, which leaves ``parameters``
    themselves outside it; None if the model has no such option.
    """
    if "failure_region" not in cls.Options.model_fields:
        return None
    if not parameters:
        raise fail(cls, "example_parameters() gives no parameter to fail on")
    name, value = next(iter(parameters.items()))
    bad = value * 1.1 if value != 0.0 else 0.1
    half = 0.01 * abs(bad - value)
    return {"failure_region": {name: (bad - half, bad + half)}}, {**parameters, name: bad}


def check_registered(entry: PluginEntry, tmp_path: str | Path) -> Any:
    """Run the checks that fit a registry entry (``fbia.list_plugins()`` lists them).

    :func:`check_options` for every kind; for forward models :func:`check_forward_model` at
    ``example_parameters()``, including the failure path when the model has a
    ``failure_region`` option (:func:`failing_run`); for measures :func:`check_measure` in the
    dimensions of the class attribute ``dims`` (default 2 and 3), with the class attribute
    ``mesh_dependent`` (default False).  Instances are built from ``example_options()``.
    Iterators need a problem: use :func:`check_iterator` with :func:`tiny_problem`.  Returns
    what the kind's check returned (the iterator instance for iterators).
    """
    cls = entry.factory
    check_options(cls)
    opts = example_options(cls)
    if entry.kind == "forward_model":
        params, coords = example_run(cls)
        failing = failing_run(cls, params)
        if failing is None:
            model = cls(cls.Options.parse(opts))
            return check_forward_model(model, params, coords, tmp_path)
        model = cls(cls.Options.parse({**opts, **failing[0]}))
        return check_forward_model(model, params, coords, tmp_path, failing_parameters=failing[1])
    instance = cls(cls.Options.parse(opts))
    if entry.kind == "measure":
        return check_measure(instance)
    return instance
