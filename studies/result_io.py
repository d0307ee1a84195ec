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
live object such as a surrogate's GP) stays at its default, or None where a field's
``metadata`` says ``in_file = False``.

The reader is strict (issue 44): a file that is not a result as fbia writes it is one
:class:`ConfigError` naming the file and the field, never a traceback, a hang or wrong data:

* a regular file (not a FIFO, a device or a link to one: never read) of at most
  :data:`MAX_RESULT_BYTES`, UTF-8 JSON, an object nested at most :data:`MAX_DEPTH` levels,
  whose numbers are finite (fbia writes NaN and infinities as ``"nan"``, ``"inf"``,
  ``"-inf"``; ``1e400`` or ``NaN`` in a file are not its own);
* written by this fbia or an earlier one (``provenance.fbia``): a later major or minor
  version may hold fields this one would misread, so it is refused naming both versions;
  an earlier one loads, the fields it lacks at their defaults;
* holding every field of the class its ``iterator`` names that every file of it holds: the
  class's ``required_fields`` (a ``gp_smc`` result labelled ``levenberg_marquardt`` has no
  ``starts``);
* every field of its declared type (a field's ``metadata["read_as"]`` refines an untyped
  one): ``true``/``false`` for a bool (not ``"false"``), a whole number for an int, a number
  or ``"nan"``/``"inf"`` for a float, a rectangular list of numbers for an array;
* consistent: no NaN or infinite ``x`` in a result whose ``success`` is true, no negative
  counts, the class's own ``check_loaded()`` (shapes against names, weights against
  particles), and its ``summary()``, ``quantities()``, ``to_records()`` and notebook view
  compute from it.

A ``Result`` subclass takes part through two optional members, as ``LMResult`` and
``GpSmcResult`` do: ``required_fields``, a class attribute naming the fields every file of
it holds, whichever fbia wrote it (so not a field added later); and ``check_loaded()``,
which raises ValueError ``"<field> <why>"`` where the fields read back contradict each
other.  (They are not members of the base class because the kernel's line budget,
tests/test_architecture.py, has no room for them.)
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, Union

import numpy as np

from ..core.data_files import regular_file_bytes
from ..core.errors import ConfigError
from ..core.problem import Result
from ..core.version import __version__

__all__ = [
    "MAX_DEPTH",
    "MAX_RESULT_BYTES",
    "FieldError",
    "from_dict",
    "load_result",
    "read_json",
    "result_type",
]

#: the largest result.json read (the example results are 0.1-10 MB)
MAX_RESULT_BYTES = 2 << 30
#: the deepest nesting read (fbia's results nest 8 levels; a plugin's diagnostics a few more)
MAX_DEPTH = 100
#: the largest magnitude of an int field (a count; beyond it quantities() overflows)
_MAX_INT = 2**63

_NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


class FieldError(ValueError):
    """A field of a result file that is not what its class declares: ``"<field> <why>"``."""

    def __init__(self, name: str, problem: str) -> None:
        super().__init__(f"{name or 'the file'} {problem}")


def load_result(source: str | Path) -> Result:
    """The typed result in ``source``: a ``result.json`` or an output folder holding one
    (checked as the module docstring says; a ConfigError naming the file and the field)."""
    path = Path(source)
    if path.is_dir():
        path = path / "result.json"
    try:
        data = read_json(path)
    except FileNotFoundError:
        raise ConfigError("no result.json there (run the study first)", str(path)) from None
    if "status" not in data:
        raise ConfigError("not an fbia result (no 'status')", str(path))
    try:
        _check_version(data)
        cls = result_type(data)
        _check_label(cls, data)
        result = from_dict(cls, data)
        _check_result(result)
    except ConfigError:
        raise
    except ValueError as exc:
        raise ConfigError(_one_line(str(exc)), str(path)) from None
    return result


def _one_line(text: str) -> str:
    """``text`` on one line (a key of a tampered file may hold a line break)."""
    return text.replace("\r", "\\r").replace("\n", "\\n")


def read_json(path: Path, limit: int | None = None) -> dict[str, Any]:
    """The JSON object in the regular file ``path``, at most ``limit`` bytes (default
    :data:`MAX_RESULT_BYTES`), nested at most :data:`MAX_DEPTH` levels, every number finite;
    a ConfigError naming the file (and the field) otherwise, FileNotFoundError where there
    is no file."""
    where = str(path)
    limit = MAX_RESULT_BYTES if limit is None else limit
    raw = regular_file_bytes(path, limit, where, "a file fbia writes")
    try:
        data = json.loads(raw.decode("utf-8"), parse_constant=float)
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 text (byte {exc.start})", where) from None
    except RecursionError:
        raise ConfigError(f"nested more than {MAX_DEPTH} levels deep", where) from None
    except ValueError as exc:  # JSONDecodeError, an integer of more than 4300 digits
        raise ConfigError(f"not JSON ({exc})", where) from None
    if not isinstance(data, dict):
        raise ConfigError(f"not a JSON object but {_json_kind(data)}", where)
    if not _plain(data):
        raise ConfigError(_one_line(_located_problem(data)), where)
    return data


def _plain(data: Any) -> bool:
    """Whether ``data`` nests at most :data:`MAX_DEPTH` levels and all its floats are finite
    (the fast pass; :func:`_located_problem` names the field when not)."""
    stack = [(data, 1)]
    while stack:
        value, depth = stack.pop()
        if depth > MAX_DEPTH:
            return False
        for item in value.values() if isinstance(value, dict) else value:
            if isinstance(item, (dict, list)):
                stack.append((item, depth + 1))
            elif isinstance(item, float) and not math.isfinite(item):
                return False
    return True


def _located_problem(data: Any) -> str:
    stack: list[tuple[Any, str, int]] = [(data, "", 1)]
    while stack:
        value, name, depth = stack.pop()
        if depth > MAX_DEPTH:
            shown = name if len(name) <= 60 else name[:57] + "..."
            return f"{shown} is nested more than {MAX_DEPTH} levels deep"
        if isinstance(value, float) and not math.isfinite(value):
            return (
                f"{name} is {value} (a number beyond the float range, or a NaN/Infinity "
                'literal; fbia writes "nan", "inf", "-inf")'
            )
        if isinstance(value, dict):
            stack.extend(
                (v, f"{name}.{k}" if name else str(k), depth + 1) for k, v in value.items()
            )
        elif isinstance(value, list):
            stack.extend((v, f"{name}[{i}]", depth + 1) for i, v in enumerate(value))
    return "holds a value fbia does not write"


def _check_version(data: Mapping[str, Any]) -> None:
    """FieldError when ``provenance.fbia`` is not a version or is a later release than this
    fbia (the module docstring says why an earlier one loads)."""
    made = data.get("provenance")
    written = made.get("fbia") if isinstance(made, Mapping) else None
    if written is None:  # a result saved from Python, without the runner's provenance
        return
    found = re.match(r"(\d+)\.(\d+)", written) if isinstance(written, str) else None
    if found is None:
        raise FieldError("provenance.fbia", f"is {_show(written)}, not a version")
    ours = re.match(r"(\d+)\.(\d+)", __version__)
    assert ours is not None
    release = (int(found[1]), int(found[2]))
    if release > (int(ours[1]), int(ours[2])):
        raise FieldError(
            "provenance.fbia",
            f"is {written}: written by a later fbia than this one ({__version__}), whose "
            f"fields this one may misread; load it with fbia {release[0]}.{release[1]} or later",
        )


def result_type(data: Mapping[str, Any]) -> type[Result]:
    """The class a result file's data load as (see the module docstring)."""
    if "draws" in data:
        from .draws import DrawsResult

        return DrawsResult
    name = data.get("iterator")
    if not name or not isinstance(name, str):
        return Result
    from ..core.registry import default_registry

    try:
        entry = default_registry().get("iterator", name)
    except ConfigError:
        return Result
    found = entry.factory.result_type
    return found if isinstance(found, type) and issubclass(found, Result) else Result


def _check_label(cls: type[Result], data: Mapping[str, Any]) -> None:
    """FieldError when the file lacks a field every result has (a dataclass field of
    ``Result`` without a default), or one that every file of ``cls`` holds (its
    ``required_fields``): then the data of another iterator under the label ``iterator``."""
    info = data.get("info")
    parts = info if isinstance(info, Mapping) else {}
    everyone = [f.name for f in dataclasses.fields(Result) if _required(f)]
    for name in everyone:
        if name not in data:
            raise FieldError(name, "is missing: not a result as fbia writes it")
    own = getattr(cls, "required_fields", ())
    missing = [n for n in own if n not in data and n not in parts]
    if missing:
        raise FieldError(
            "iterator",
            f"is {_show(data.get('iterator'))}, but the file has no {', '.join(missing)} of "
            f"a {cls.__name__}: the data of another iterator under its label?",
        )


def _check_result(result: Result) -> None:
    """FieldError (a ValueError from ``check_loaded``) where the fields of a result read back
    contradict each other, or its views cannot be computed from them."""
    if result.success and result.x:
        bad = [k for k, v in result.x.items() if not math.isfinite(v)]
        if bad:
            value = result.x[bad[0]]
            raise FieldError(f"x.{bad[0]}", f"is {value} in a result whose success is true")
    for name in ("nfev", "n_failed"):
        if getattr(result, name) < 0:
            raise FieldError(name, f"is {getattr(result, name)}, a negative count")
    check = getattr(result, "check_loaded", None)
    if check is not None:
        check()
    views = {
        "summary": result.summary,
        "quantities": result.quantities,
        "to_records": result.to_records,
        "_repr_html_": result._repr_html_,
    }
    for name, view in views.items():
        try:
            view()
        except (TypeError, ValueError, LookupError, AttributeError, ArithmeticError) as exc:
            raise FieldError(
                "", f"holds data its {name}() fails on ({type(exc).__name__}: {exc})"
            ) from None


def from_dict(cls: type[Any], data: Mapping[str, Any], where: str = "") -> Any:
    """An instance of the dataclass ``cls`` from ``data``, every field checked and converted
    by its declared type (or ``metadata["read_as"]``); a field missing at the top level is
    looked up in ``data["info"]``, where results keep their parts, e.g.
    ``GpSmcResult.posterior``.  A FieldError (a ValueError) names the first field that is
    not what it should be, or a field without a default that ``data`` lacks (except those
    whose ``metadata["in_file"]`` is False: None)."""
    hints = _type_hints(cls)
    info = data.get("info")
    parts = info if isinstance(info, Mapping) else {}
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.name in data:
            value, name = data[f.name], _join(where, f.name)
        elif f.name in parts:
            value, name = parts[f.name], _join(where, f"info.{f.name}")
        elif _required(f):
            if f.metadata.get("in_file", True):
                raise FieldError(_join(where, f.name), "is missing")
            kwargs[f.name] = None  # a live object the file does not hold
            continue
        else:
            continue
        kwargs[f.name] = _convert(f.metadata.get("read_as", hints.get(f.name, Any)), value, name)
    return cls(**kwargs)


def _required(f: dataclasses.Field[Any]) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


def _type_hints(cls: Any) -> dict[str, Any]:
    """The annotations of a class, resolved once (a result holds thousands of records)."""
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


_HINTS: dict[Any, dict[str, Any]] = {}


def _join(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name


def _convert(tp: Any, value: Any, name: str) -> Any:
    """``value`` as the type ``tp`` (FieldError naming ``name`` when it is not one)."""
    if tp is Any:
        return value if isinstance(value, (dict, list)) else _floats(value)
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        if value is None and len(options) < len(args):
            return None
        if len(options) == 1:
            return _convert(options[0], value, name)
        for option in options:
            try:
                return _convert(option, value, name)
            except FieldError:
                continue
        raise FieldError(name, f"is {_show(value)}, not {' or '.join(map(_expected, options))}")
    if value is None:
        raise FieldError(name, f"is null, not {_expected(tp)}")
    if origin is np.ndarray:
        return _array(args, value, name)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return from_dict(tp, _checked(value, Mapping, name), name)
    if typing.is_typeddict(tp):
        return _record(tp, _checked(value, Mapping, name), name)
    if origin in (list, Sequence) or tp is list:
        item = args[0] if args else Any
        return [
            _convert(item, v, f"{name}[{i}]") for i, v in enumerate(_checked(value, list, name))
        ]
    if origin is tuple:
        items = _checked(value, list, name)
        kinds = [args[0]] * len(items) if len(args) == 2 and args[1] is Ellipsis else list(args)
        if len(kinds) != len(items):
            raise FieldError(name, f"has {len(items)} items, not {len(kinds)}")
        return tuple(
            _convert(k, v, f"{name}[{i}]")
            for i, (k, v) in enumerate(zip(kinds, items, strict=True))
        )
    if origin in (dict, Mapping) or tp is dict:
        item = args[1] if len(args) > 1 else Any
        return {
            k: _convert(item, v, f"{name}.{k}") for k, v in _checked(value, Mapping, name).items()
        }
    if origin is Literal:
        if value not in args:
            raise FieldError(name, f"is {_show(value)}, not one of {', '.join(map(_show, args))}")
        return value
    return _scalar(tp, value, name)


def _scalar(tp: Any, value: Any, name: str) -> Any:
    if tp is bool:
        return _checked(value, bool, name)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int) or abs(value) >= _MAX_INT:
            raise FieldError(name, f"is {_show(value)}, not {_expected(int)}")
        return value
    if tp is float:
        if isinstance(value, str) and value in _NON_FINITE:
            return _NON_FINITE[value]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            try:
                return float(value)
            except OverflowError:
                pass
        raise FieldError(name, f"is {_show(value)}, not {_expected(float)}")
    if tp is str:
        return _checked(value, str, name)
    return value  # a type fbia's results do not use: as written


def _checked(value: Any, kind: type, name: str) -> Any:
    if not isinstance(value, kind):
        raise FieldError(name, f"is {_show(value)}, not {_expected(kind)}")
    return value


def _array(args: tuple[Any, ...], value: Any, name: str) -> np.ndarray:
    """A rectangular list of numbers (or of "nan", "inf") as a float array; of booleans as a
    bool array (the dtype the annotation gives)."""
    dtype = typing.get_args(args[1])[0] if len(args) > 1 else np.float64
    boolean = dtype in (bool, np.bool_)
    want = "an array of true/false" if boolean else "an array of numbers"
    items = _checked(value, list, name)
    try:
        quick = np.asarray(items)
    except ValueError:  # ragged
        raise FieldError(name, f"is not rectangular: not {want}") from None
    kind = quick.dtype.kind
    if quick.size == 0 or (boolean and kind == "b") or (not boolean and kind in "iuf"):
        try:
            return np.asarray(quick, dtype=dtype)
        except OverflowError:
            raise FieldError(name, f"holds a number beyond the float range: not {want}") from None
    if not boolean and kind in "UO":  # numbers with "nan"/"inf" strings: each one checked
        flat = _leaves(items)
        if all(_is_number(v) for v in flat):
            try:
                return np.asarray(_floats(items), dtype=dtype)
            except (ValueError, OverflowError):
                pass
    raise FieldError(name, f"is not {want} (a value of another type in it)")


def _leaves(items: list[Any]) -> list[Any]:
    out: list[Any] = []
    stack = [items]
    while stack:
        for v in stack.pop():
            (stack.append if isinstance(v, list) else out.append)(v)
    return out


def _is_number(v: Any) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool)) or v in ("nan", "inf", "-inf")


def _record(tp: Any, value: Mapping[str, Any], name: str) -> dict[str, Any]:
    """A TypedDict's keys checked (the required ones present, each of its type); other keys
    kept as written."""
    missing = sorted(tp.__required_keys__ - set(value))
    if missing:
        raise FieldError(_join(name, missing[0]), "is missing")
    hints = _type_hints(tp)
    out = dict(value)
    for key, kind in hints.items():
        if key in value:
            out[key] = _convert(kind, value[key], _join(name, key))
    return out


def _expected(tp: Any) -> str:
    origin = typing.get_origin(tp) or tp
    if origin is np.ndarray:
        return "an array"
    if dataclasses.is_dataclass(tp) or typing.is_typeddict(tp) or origin in (dict, Mapping):
        return "an object"
    names = {bool: "true or false", int: "a whole number", float: "a number", str: "a string"}
    if origin in names:
        return names[origin]
    return "a list" if origin in (list, tuple, Sequence) else getattr(tp, "__name__", str(tp))


def _show(value: Any) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


def _json_kind(value: Any) -> str:
    kinds = {list: "a list", str: "a string", bool: "true/false", type(None): "null"}
    return kinds.get(type(value), "a number")


def _floats(value: Any) -> Any:
    """The strings "nan", "inf", "-inf" (how results write them) as floats, recursively."""
    if isinstance(value, str):
        return _NON_FINITE.get(value, value)
    if isinstance(value, list):
        return [_floats(v) for v in value]
    return value
