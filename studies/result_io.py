"""Results back from their files: :func:`load_result` reads a ``result.json`` as its type.

``fbia run`` writes every result as JSON (:meth:`Result.save`).  :func:`load_result` turns
such a file (or the output folder holding it) back into the typed result the iterator
returned -- :class:`~fbia.iterators.lm.result.LMResult`, ``GpSmcResult``,
``SobolIndicesResult``, ``SurrogateConvergenceResult``, the ``DrawsResult`` of a study over
noise draws -- with its ``summary()``, ``quantities()`` and arrays as numpy arrays:

>>> # result = fbia.load_result("examples/flow_cell/output")       # or .../result.json
>>> # print(result.summary()); result.posterior.mean                 # a gp_smc result

Which class: the registered iterator named in the file's ``iterator`` declares it as its
``result_type`` (the iterator contract, docs/architecture.md); a file of an iterator that is
not installed, or that declares none, loads as the base :class:`Result`.  The conversion is
generic: every dataclass field found in the file is converted to its declared type (nested
dataclasses, numpy arrays, ``"nan"``/``"inf"`` strings back to floats); what the file does not
hold (a forward run's :class:`Solution`, residual vectors longer than the JSON limit, a
live object such as a surrogate's GP) stays at its default, or None where it has none.
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Union

import numpy as np

from ..core.errors import ConfigError
from ..core.problem import Evaluation, Result

__all__ = ["from_dict", "load_result", "result_type"]

_NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def load_result(source: str | Path) -> Result:
    """The typed result in ``source``: a ``result.json`` or an output folder holding one."""
    path = Path(source)
    if path.is_dir():
        path = path / "result.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError("no result.json there (run the study first)", str(path)) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"not a readable result file ({exc})", str(path)) from None
    if not isinstance(data, dict) or "status" not in data:
        raise ConfigError("not an fbia result (no 'status')", str(path))
    cls = result_type(data)
    try:
        return from_dict(cls, data)
    except (TypeError, ValueError, KeyError) as exc:
        raise ConfigError(f"cannot be read as a {cls.__name__} ({exc})", str(path)) from None


def result_type(data: Mapping[str, Any]) -> type[Result]:
    """The class a result file's data load as (see the module docstring)."""
    if "draws" in data:
        from .draws import DrawsResult

        return DrawsResult
    name = str(data.get("iterator") or "")
    if not name:
        return Result
    from ..core.registry import default_registry

    try:
        entry = default_registry().get("iterator", name)
    except ConfigError:
        return Result
    found = getattr(entry.factory, "result_type", None)
    return found if isinstance(found, type) and issubclass(found, Result) else Result


def from_dict(cls: type[Any], data: Mapping[str, Any]) -> Any:
    """An instance of the dataclass ``cls`` from ``data`` (its fields converted by type; a
    field missing at the top level is looked up in ``data["info"]``, where results keep their
    parts, e.g. ``GpSmcResult.posterior``)."""
    hints = typing.get_type_hints(cls)
    info = data.get("info")
    merged = {**info, **data} if isinstance(info, Mapping) else dict(data)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.name in merged:
            kwargs[f.name] = _convert(hints.get(f.name, Any), merged[f.name], f.name)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            kwargs[f.name] = None  # a required field the file does not hold (a live object)
    return cls(**kwargs)


def _convert(tp: Any, value: Any, name: str = "") -> Any:
    if value is None or tp is Any:
        return _floats(value) if tp is Any and not isinstance(value, (dict, list)) else value
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        for option in (a for a in args if a is not type(None)):
            try:
                return _convert(option, value, name)
            except (TypeError, ValueError, KeyError):
                continue
        return value
    if origin is np.ndarray:
        dtype = typing.get_args(args[1])[0] if len(args) > 1 else float
        if not isinstance(value, list):
            raise TypeError(f"{name}: not an array")
        return np.asarray(_floats(value), dtype=dtype)
    if tp is Evaluation:
        return _evaluation(value)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if not isinstance(value, Mapping):
            raise TypeError(f"{name}: not a mapping")
        return from_dict(tp, value)
    if origin in (list, Sequence) or tp is list:
        if not isinstance(value, list):
            raise TypeError(f"{name}: not a list")
        item = args[0] if args else Any
        return [_convert(item, v, name) for v in value]
    if origin is tuple:
        return tuple(_floats(value))
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise TypeError(f"{name}: not a mapping")
        item = args[1] if len(args) > 1 else Any
        return {k: _convert(item, v, name) for k, v in value.items()}
    if tp is float:
        return float(_floats(value))
    if tp is int:
        return int(value)
    if tp is bool:
        return bool(value)
    return value


def _floats(value: Any) -> Any:
    """The strings "nan", "inf", "-inf" (how results write them) as floats, recursively."""
    if isinstance(value, str):
        return _NON_FINITE.get(value, value)
    if isinstance(value, list):
        return [_floats(v) for v in value]
    return value


def _evaluation(data: Mapping[str, Any]) -> Evaluation:
    residuals = data.get("residuals")
    return Evaluation(
        index=int(data["index"]),
        x={k: float(_floats(v)) for k, v in data["x"].items()},
        status=str(data.get("status", "ok")),
        message=str(data.get("message", "")),
        residuals=None if residuals is None else np.asarray(_floats(residuals), dtype=float),
        distances=None if data.get("distances") is None else _floats(data["distances"]),
        time=float(_floats(data.get("time", 0.0))),
        workdir=data.get("workdir"),
        diagnostics=dict(data.get("diagnostics") or {}),
    )
