"""Pydantic models of study-file sections, and their errors as one located line each.

A section model states the keys of a TOML table, their types and simple bounds; the reader
(:mod:`fbia.studies.study_file`) adds what depends on other sections (known parameter names,
files, priors).  :func:`parse_section` turns the first validation error into a
:class:`~fbia.core.errors.ConfigError` in the form the plugin options use, located at the
key: ``study.toml: [executor] timeout: must be positive, got -1``.

>>> parse_section(LikelihoodSection, {"noise_std": 0.01}, "study.toml: [likelihood]")
LikelihoodSection(noise_std=0.01, noise_prior=None)
>>> parse_section(LikelihoodSection, {"sigma": 0.01}, "study.toml: [likelihood]")
... # doctest: +ELLIPSIS
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: study.toml: [likelihood]: unknown key 'sigma'; valid keys: ...
"""

from __future__ import annotations

import math
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import pydantic
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from ..core.errors import ConfigError
from ..execution.cluster_options import check_cluster_options
from ..execution.isolation import isolation_mode

_T = TypeVar("_T")

__all__ = [
    "checked",
    "is_path_type",
    "CLUSTERS",
    "NOISE_KINDS",
    "ExecutorSection",
    "LikelihoodSection",
    "ObservationSection",
    "PaperSection",
    "PaperValueSection",
    "ParameterSection",
    "PluginSection",
    "StudySection",
    "SyntheticSection",
    "UncertainSection",
    "as_number",
    "as_table",
    "kind_of",
    "parse_section",
]

#: ``cluster`` values of [executor] (kept in step with fbia.execution.dask_executor.CLUSTERS,
#: which is not imported here so that reading a study file never imports Dask)
CLUSTERS = ("local", "slurm", "pbs", "sge", "lsf", "htcondor", "moab", "oar")
#: how [synthetic] noise is added (fbia.synthetic_observations): along the normals (Paper A)
#: or on every coordinate (Paper B eq. 16)
NOISE_KINDS = ("normal", "isotropic")


def kind_of(value: Any) -> str:
    """A TOML value's kind in words: ``a table``, ``an array``, ``a string``, ..."""
    return {
        dict: "a table",
        list: "an array",
        str: "a string",
        bool: "a boolean",
        int: "an integer",
        float: "a number",
    }.get(type(value), type(value).__name__)


def as_number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"expected a number, got {kind_of(value)} {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {value!r}")
    return float(value)


def _integer(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"expected an integer, got {kind_of(value)} {value!r}")
    return value


def _string(value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"expected a non-empty string, got {kind_of(value)} {value!r}")
    return value


def _flag(value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"expected true or false, got {value!r}")
    return value


def _any_string(value: Any) -> str:
    if not isinstance(value, str):
        raise ValueError(f"expected a string, got {kind_of(value)}")
    return value


def _pair(value: Any) -> tuple[float, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise ValueError(f"expected [lower, upper], got {value!r}")
    return as_number(value[0]), as_number(value[1])


def _folder(value: str) -> str:
    if not value.strip():
        raise ValueError('an empty folder name (give a folder, e.g. "output")')
    return _no_control(value, "folder name")


def _no_control(value: str, what: str = "file name") -> str:
    """A path without control characters: NUL cannot be in one, a newline is a typo."""
    bad = next((c for c in value if ord(c) < 32 or ord(c) == 127), None)
    if bad is not None:
        raise ValueError(f"a control character ({bad!r}) in the {what} {value!r}")
    return value


def as_table(value: Any) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ValueError(f"expected a table, got {kind_of(value)}")
    return value


Number = Annotated[float, BeforeValidator(as_number)]
Integer = Annotated[int, BeforeValidator(_integer)]
Text = Annotated[str, BeforeValidator(_string)]
Flag = Annotated[bool, BeforeValidator(_flag)]
Table = Annotated[dict[str, Any], BeforeValidator(as_table)]
Label = Annotated[str, BeforeValidator(_any_string)]
Folder = Annotated[str, BeforeValidator(lambda v: _folder(_string(v)))]
FileName = Annotated[str, BeforeValidator(lambda v: _no_control(_string(v)))]
Pair = Annotated[tuple[float, float], BeforeValidator(_pair)]


class Section(BaseModel):
    """Base of the section models: unknown keys are errors, values are not coerced."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class PluginSection(Section):
    """``[model]``, ``[measure]``, ``[iterator]``: a registered name and its options."""

    name: Text
    options: Table = Field(default_factory=dict)


class ParameterSection(Section):
    """One ``[[parameters]]`` table (the reader checks names, bounds order and priors)."""

    name: Text
    unit: Label = ""
    bounds: Pair | None = None
    initial: Number | None = None
    prior: Table | None = None


class UncertainSection(Section):
    """One ``[[uncertain]]`` table."""

    name: Text
    unit: Label = ""
    bounds: Pair | None = None
    prior: Table | None = None


class ObservationSection(Section):
    """One ``[[observations]]`` table (the reader reads the files)."""

    coordinate: Table = Field(default_factory=dict)
    interface: Text | None = None
    oct: Any = None  # an OCT scan: a file or a table, checked by fbia.studies.study_oct
    points: Text | None = None
    noise_std: Annotated[Number, Field(gt=0)] | None = None
    name: Label = ""

    @model_validator(mode="after")
    def _one_surface(self) -> ObservationSection:
        if self.interface is not None and self.oct is not None:
            raise _KeyError("oct", "give 'interface' (a surface file) or 'oct' (a scan), not both")
        return self


class StudySection(Section):
    name: Text | None = None
    seed: Annotated[Integer, Field(ge=0)] = 0
    output: Folder = "output"
    store: FileName | None = None  # the study store's file; default <output>/store.sqlite
    # a study file this one extends (its tables merged under this one's, relative to this
    # file; fbia.studies.study_sources): read before the sections, not a setting of the study
    extends: FileName | None = None
    # true: the file holds what a family of variants shares, no study by itself (not inherited)
    base_only: bool = False


class LikelihoodSection(Section):
    noise_std: Annotated[Number, Field(gt=0)] | None = None
    noise_prior: Table | None = None  # a prior table: sigma_N is inferred


class SyntheticSection(Section):
    truth: Table
    coordinates: Any  # a table or an array of tables: checked by the reader
    noise_std: Annotated[Number, Field(ge=0)] = 0.0
    noise: Literal["normal", "isotropic"] = "normal"
    points: Annotated[Integer, Field(ge=1, le=10_000_000)] | None = None
    placement: Literal["even", "displacement"] = "even"
    significant: Annotated[Number, Field(gt=0, lt=1)] = 0.5
    seed: Annotated[Integer, Field(ge=0)] | None = None
    draws: Annotated[Integer, Field(ge=1, le=100_000)] = 1  # noise draws (fbia.studies.draws)

    @model_validator(mode="after")
    def _noisy_draws(self) -> SyntheticSection:
        if self.draws > 1 and self.noise_std == 0:
            raise _KeyError("draws", "draws > 1 needs noise_std > 0: exact data draw alike")
        return self


class ExecutorSection(Section):
    kind: Literal["serial", "processes", "dask"] = "processes"
    workers: Annotated[Integer, Field(ge=1)] | None = None
    keep_runs: Flag | None = None
    timeout: Annotated[Number, Field(gt=0)] | None = None
    isolate: Flag | None = None
    address: Text | None = None
    cluster: Literal["local", "slurm", "pbs", "sge", "lsf", "htcondor", "moab", "oar"] = "local"
    cluster_options: Table = Field(default_factory=dict)

    @model_validator(mode="after")
    def _consistent(self) -> ExecutorSection:
        given = self.model_fields_set
        try:  # the executors' own rule
            isolation_mode(self.timeout, self.isolate, default=False)
        except ConfigError as exc:
            raise _KeyError("isolate", exc.reason) from None
        dask_only = [k for k in ("address", "cluster", "cluster_options") if k in given]
        if dask_only and self.kind != "dask":
            raise _KeyError(
                dask_only[0],
                f'{", ".join(dask_only)} only for kind = "dask" (kind is {self.kind!r})',
            )
        try:  # a study file never runs code or opens the network
            check_cluster_options(self.cluster, self.cluster_options)
        except ConfigError as exc:
            raise _KeyError("cluster_options", exc.reason) from None
        if self.address is not None and (
            self.workers is not None or "cluster" in given or self.cluster_options
        ):
            raise _KeyError(
                "address",
                "a scheduler address names a running cluster: workers, cluster and "
                "cluster_options do not apply",
            )
        return self


class PaperValueSection(Section):
    """One ``[[paper.values]]`` table: a published number beside a quantity of the result
    (``kind`` is checked against fbia.studies.paper.KINDS, which gives its rule)."""

    quantity: Text
    kind: Text
    paper: Number | None = None
    unit: Label = ""
    above: Text | None = None
    below: Text | None = None
    label: Label = ""
    why: Label = ""


class PaperSection(Section):
    """``[paper]``: where the published numbers come from, and the numbers."""

    source: Text
    note: Label = ""
    values: list[Table] = Field(default_factory=list)


class _KeyError(ValueError):
    """A cross-key rule that failed, and the key it is reported at."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


S = TypeVar("S", bound=Section)

_LITERAL_NAMES = {"kind": "executor", "cluster": "cluster", "noise": "noise"}


def parse_section(model: type[S], value: Any, where: str) -> S:
    """Validate one TOML table; the first problem becomes one located ConfigError."""
    if not isinstance(value, dict):
        raise ConfigError(f"expected a table, got {kind_of(value)}", where)
    valid = list(model.model_fields)
    unknown = [k for k in value if k not in model.model_fields]
    if unknown:
        plural = "s" if len(unknown) > 1 else ""
        raise ConfigError(
            f"unknown key{plural} {', '.join(map(repr, unknown))}; valid keys: {', '.join(valid)}",
            where,
        )
    try:
        return model(**value)
    except pydantic.ValidationError as exc:
        err = exc.errors()[0]
        raise ConfigError(*_message(err, where)) from None


def _message(err: Any, where: str) -> tuple[str, str]:
    """(message, location) of a pydantic error dict."""
    loc = [str(p) for p in err["loc"] if not str(p).startswith("function-")]
    key = loc[0] if loc else ""
    cause = err.get("ctx", {}).get("error")
    if isinstance(cause, _KeyError):
        return str(cause), f"{where} {cause.key}"
    at = f"{where} {key}" if key else where
    kind, value = err["type"], err.get("input")
    if kind == "missing":
        return f"missing key {key!r}", where
    if kind == "value_error":
        return str(cause if cause is not None else err["msg"]), at
    if kind == "greater_than":
        return f"must be positive, got {value!r}", at
    if kind == "greater_than_equal":
        bound = err["ctx"]["ge"]
        if bound == 0:
            return f"must not be negative, got {value!r}", at
        return f"must be at least {bound}, got {value!r}", at
    if kind == "literal_error":
        options = err["ctx"]["expected"].replace("'", "").replace(" or ", ", ")
        return f"unknown {_LITERAL_NAMES.get(key, key)} {value!r}; valid: {options}", at
    return f"{err['msg']} (got {value!r})", at


def checked(check: Callable[[Any], _T], value: Any, where: str) -> _T:
    """A value through a section-schema check, its complaint as a located ConfigError."""
    try:
        return check(value)
    except ValueError as exc:
        raise ConfigError(str(exc), where) from None


def is_path_type(annotation: Any) -> bool:
    """Whether an option's type is ``Path`` or a union with it (``Path | None``)."""
    return annotation is Path or Path in typing.get_args(annotation)


#: pydantic's names of numeric bounds -> JSON Schema's
_BOUND_KEYWORDS = {
    "ge": "minimum",
    "gt": "exclusiveMinimum",
    "le": "maximum",
    "lt": "exclusiveMaximum",
}


def _standard_bounds(schema: Any) -> Any:
    """``schema`` with pydantic's ``ge``/``gt``/``le``/``lt`` as JSON Schema's ``minimum``,
    ``exclusiveMinimum``, ``maximum``, ``exclusiveMaximum``: pydantic writes its own names
    for a bound on an ``Annotated`` type with a validator before it (``Number``, ``Integer``),
    which JSON Schema validators ignore."""
    if isinstance(schema, list):
        return [_standard_bounds(s) for s in schema]
    if not isinstance(schema, dict):
        return schema
    numeric = schema.get("type") in ("number", "integer")
    return {
        (_BOUND_KEYWORDS[k] if numeric and k in _BOUND_KEYWORDS else k): (
            v if numeric and k in _BOUND_KEYWORDS else _standard_bounds(v)
        )
        for k, v in schema.items()
    }


def study_json_schema(sections: dict[str, str]) -> dict[str, Any]:
    """A JSON Schema (draft 2020-12) of a study file, for editors that check TOML against
    one (Taplo, Even Better TOML): every section's keys, types, bounds (as ``minimum``,
    ``exclusiveMinimum``, ``maximum``, ``exclusiveMaximum``) and descriptions from
    the models above; a plugin's ``options`` is an open table (``fbia plugins --options NAME``
    lists them); ``sections`` names the top-level tables (``study_file.SECTIONS``)."""
    tables: dict[str, type[Section]] = {
        "study": StudySection,
        "model": PluginSection,
        "measure": PluginSection,
        "iterator": PluginSection,
        "likelihood": LikelihoodSection,
        "synthetic": SyntheticSection,
        "executor": ExecutorSection,
        "paper": PaperSection,
    }
    arrays: dict[str, type[Section]] = {
        "parameters": ParameterSection,
        "uncertain": UncertainSection,
        "observations": ObservationSection,
    }
    properties: dict[str, Any] = {}
    for name, text in sections.items():
        if name in tables:
            schema = _standard_bounds(tables[name].model_json_schema())
        elif name in arrays:
            schema = {"type": "array", "items": _standard_bounds(arrays[name].model_json_schema())}
        else:  # fixed: name = value
            schema = {"type": "object", "additionalProperties": {"type": "number"}}
        properties[name] = {**schema, "description": text}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "fbia study file",
        "type": "object",
        # a variant ([study] extends) takes what it leaves out from its base, and a base
        # ([study] base_only = true) leaves out what its variants say: their tables are
        # checked for names and types, what a whole study must have only for the others
        "properties": _optional(properties),
        "if": {"not": {"required": ["study"], "properties": {"study": _PARTIAL}}},
        "then": {"required": ["model"], "properties": _required_only(properties)},
        "additionalProperties": False,
    }


#: a [study] table of a file that is not a whole study: a variant or a base
_PARTIAL = {
    "anyOf": [
        {"required": ["extends"]},
        {"required": ["base_only"], "properties": {"base_only": {"const": True}}},
    ]
}


def _required_only(properties: dict[str, Any]) -> dict[str, Any]:
    """Of each property's schema only what a whole study must have: its ``required`` lists
    (types and bounds are checked once, by the partial schema every file meets)."""
    return {name: _required_of(schema) for name, schema in properties.items()}


def _required_of(schema: dict[str, Any]) -> dict[str, Any]:
    kept: dict[str, Any] = {k: schema[k] for k in ("required",) if k in schema}
    if isinstance(schema.get("properties"), dict):
        kept["properties"] = _required_only(schema["properties"])
    if isinstance(schema.get("items"), dict):
        kept["items"] = _required_of(schema["items"])
    return kept


def _optional(schema: Any) -> Any:
    """``schema`` without any ``required`` list (a variant's partial tables)."""
    if isinstance(schema, dict):
        return {k: _optional(v) for k, v in schema.items() if k != "required"}
    if isinstance(schema, list):
        return [_optional(v) for v in schema]
    return schema
