"""``fbia init``: a commented template study file for a chosen model, measure and iterator.

The template is a study that validates and runs as written: synthetic data made by the model
at its own example parameters (``example_parameters()``, which every forward model provides
for the conformance kit), the same parameters calibrated within a factor of two of them,
and every option of the three plugins listed as a comment with its default, unit and
description (:meth:`fbia.core.options.PluginOptions.describe`), so that a user edits values
instead of looking names up.  How to switch to observed data is a commented
``[[observations]]`` block.

>>> text = study_template("analytic_mound_2d")
>>> "[model]" in text and 'name = "analytic_mound_2d"' in text
True
"""

from __future__ import annotations

import json
import math
import textwrap
from typing import Any

from ..core.errors import ConfigError
from ..core.registry import default_registry

__all__ = ["study_template"]

#: iterators whose target is the likelihood (they need sigma_N in ``[likelihood]``)
_LIKELIHOOD_ITERATORS = frozenset({"gp_smc", "sobol_indices", "surrogate_convergence"})


def _entry(kind: str, name: str, flag: str) -> Any:
    return default_registry().get(kind, name, where=flag)


def _toml(value: Any) -> str:
    """A TOML literal of an option's default (JSON's syntax is TOML's for these types)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else ("-inf" if value < 0 else "nan")
    if isinstance(value, dict):
        inner = ", ".join(f"{k} = {_toml(v)}" for k, v in value.items())
        return "{ " + inner + " }" if inner else "{}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return json.dumps(value, default=str)


def _options_block(title: str, factory: Any) -> list[str]:
    """``title``'s options as comments: ``# name = default``, then its description and unit."""
    described = factory.Options.describe()
    if not described:
        return [f"# ({title} has no options)"]
    lines = [
        f"# [{title}]   (to change an option: uncomment this line and the option's;"
        " each at its default)"
    ]
    for name, info in described.items():
        default = info["default"]
        if default is None or default == "(required)":
            value = "...   (not set)" if default is None else "...   (required)"
        else:
            value = _toml(default)
        unit = (
            f" [{info['unit']}]"
            if info["unit"] and f"[{info['unit']}]" not in str(info["description"])
            else ""
        )
        text = " ".join(str(info["description"]).split()) + unit
        lines.append(f"# {name} = {value}")
        lines += textwrap.wrap(text, 96, initial_indent="#     ", subsequent_indent="#     ")
    return lines


def _number(value: float) -> str:
    """A TOML float (``400.0``, not the integer ``400``)."""
    text = f"{value:.6g}"
    return text if any(c in text for c in ".en") else f"{text}.0"


def _bounds(factory: Any, name: str, value: float) -> tuple[float, float]:
    """A factor of two around a positive value, +-0.5 around others (a ratio such as nu),
    kept inside the limits the model's option of the same name declares (nu < 0.5, 0 <
    phi0 < 1), 0.1 % of the value short of an open limit."""
    low, high = (value / 2.0, value * 2.0) if value > 0 else (value - 0.5, value + 0.5)
    field = factory.Options.model_fields.get(name)
    margin = max(1e-3 * abs(value), 1e-3)
    for limit in getattr(field, "metadata", []):
        if getattr(limit, "gt", None) is not None:
            low = max(low, float(limit.gt) + margin)
        if getattr(limit, "ge", None) is not None:
            low = max(low, float(limit.ge))
        if getattr(limit, "lt", None) is not None:
            high = min(high, float(limit.lt) - margin)
        if getattr(limit, "le", None) is not None:
            high = min(high, float(limit.le))
    return low, high


def _unit(factory: Any, name: str) -> str:
    return str(factory.Options.describe().get(name, {}).get("unit") or "-")


def study_template(
    model: str,
    iterator: str = "levenberg_marquardt",
    measure: str = "ray",
    name: str = "my_study",
) -> str:
    """The text of a commented study file for ``model``, ``measure`` and ``iterator`` (names
    of installed plugins; an unknown one is a :class:`ConfigError` with a did-you-mean)."""
    m = _entry("forward_model", model, "--model").factory
    meas = _entry("measure", measure, "--measure").factory
    it = _entry("iterator", iterator, "--iterator").factory
    example = m.example_parameters()
    if example is None:
        raise ConfigError(
            f"model {model!r} provides no example_parameters(): write its study by hand "
            "(fbia schema gives the format)",
            "--model",
        )
    truth, coordinates = example
    truth = {k: float(v) for k, v in truth.items()}
    from ..core.version import __version__

    out = [
        f"# Study file written by `fbia init` (fbia {__version__}): {model} calibrated with",
        f"# {iterator} on the {measure} measure.  As written it runs: synthetic data made by the",
        "# model at its example parameters.  Edit, then:",
        "#   fbia validate study.toml && fbia run study.toml",
        "# Units: mm, s, Pa.  Every option of a plugin: fbia plugins --options NAME;",
        "# the study file's JSON Schema (for an editor): fbia schema.",
        "",
        "[study]",
        f"name = {json.dumps(name)}",
        "seed = 1                  # the same seed, the same result (noise draws, designs)",
        'output = "output"        # the output folder, beside this file',
        "",
        "[model]",
        f"name = {json.dumps(model)}",
        *_options_block("model.options", m),
        "",
    ]
    for pname, value in truth.items():
        low, high = _bounds(m, pname, value)
        out += [
            "[[parameters]]           # calibrated (a model option of this name is not used)",
            f"name = {json.dumps(pname)}",
            f'unit = "{_unit(m, pname)}"',
            f"bounds = [{_number(low)}, {_number(high)}]",
            f"initial = {_number(low + 0.25 * (high - low))}   # where a local iterator starts",
            "",
        ]
    truth_text = ", ".join(f"{k} = {_number(v)}" for k, v in truth.items())
    out += [
        "[synthetic]              # data made by the model at a ground truth, plus noise ...",
        f"truth = {{ {truth_text} }}",
        f"coordinates = {_toml(coordinates)}   # the observed states (e.g. inflow rates)",
        "noise_std = 0.0          # mm, along the interface normals",
        "",
        "# ... or observed data: delete [synthetic] and give one block per observed state:",
        "# [[observations]]",
        f"# coordinate = {_toml(coordinates[0]) if coordinates else '{}'}",
        '# interface = "data/observed.csv"   # 2-D: CSV x, y[, curve]; 3-D: STL, PLY, OBJ, VTU',
        '# points = "data/points.csv"        # optional: measurement points (the ray measure)',
        "# noise_std = 0.0005                # optional, mm",
        "",
        "[measure]",
        f"name = {json.dumps(measure)}",
        *_options_block("measure.options", meas),
        "",
    ]
    if iterator in _LIKELIHOOD_ITERATORS:
        out += [
            "[likelihood]             # Paper B eq. 5: the noise of the discrepancy",
            "noise_std = 0.001        # mm (sigma_N); or noise_prior = { ... } when unknown",
            "",
        ]
    out += [
        "[iterator]",
        f"name = {json.dumps(iterator)}",
        *_options_block("iterator.options", it),
        "",
        "[executor]",
        'kind = "processes"       # "serial", "processes" or "dask"',
        "workers = 2              # forward runs at a time",
        "",
    ]
    return "\n".join(out)
