"""Bayes -> Levenberg-Marquardt: start least squares from a posterior (thesis conclusion).

A Bayesian calibration (``gp_smc``) finds where the posterior mass is; Levenberg-Marquardt
then sharpens the point estimate with real forward runs and gives its local covariance.
:func:`posterior_starts` turns a ``gp_smc`` result -- the result object (its
:meth:`~fbia.core.problem.Result.posterior_estimate`, the contract
:class:`~fbia.core.problem.PosteriorEstimate`), or its ``result.json`` as written by
``fbia run`` -- into two initial guesses, the posterior MAP and the posterior mean of the
calibration parameters.

>>> # bayes = fbia.iterator("gp_smc", n_train=200).run(problem)
>>> # lm = fbia.iterator("levenberg_marquardt", x0=bayes)         # starts: MAP, mean
>>> # a study file: [iterator] options = { x0_from = "output_bayes/result.json" }

A ``result.json`` is read strictly, when the options are made (``fbia validate``): a regular
file (never a FIFO or a device: not opened for long) of at most :data:`MAX_BYTES`, UTF-8 JSON
nested at most :data:`MAX_DEPTH` levels, whose ``info.posterior`` has ``names`` (distinct
strings), ``n_x`` (a whole number, at most the names) and ``map`` and ``mean`` (``n_x``
finite numbers each); anything else is one :class:`ConfigError` naming the file and the field.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ...core.data_files import regular_file_bytes
from ...core.errors import ConfigError
from ...core.problem import Result

__all__ = ["MAX_BYTES", "MAX_DEPTH", "POSTERIOR_LABELS", "posterior_starts"]

#: what the two starts are, in order
POSTERIOR_LABELS = ("posterior MAP", "posterior mean")
#: the largest result.json read (a gp_smc result of 10^5 particles in 10 inputs is ~40 MB)
MAX_BYTES = 1 << 30
#: the deepest nesting read (fbia's results nest 8 levels)
MAX_DEPTH = 100


def posterior_starts(
    source: Result | Mapping[str, Any] | str | Path,
) -> list[dict[str, float]]:
    """``[MAP, mean]`` of the calibration parameters of a ``gp_smc`` result (the object, its
    ``to_dict()`` or the path of its ``result.json``); a ConfigError if it has no posterior
    or one that is not as fbia writes it (the module docstring)."""
    where = "levenberg_marquardt: x0_from"
    if isinstance(source, (str, Path)):
        where = f"{where} {source}"
        source = _read_json(Path(source), where)
    if isinstance(source, Result):
        post = source.posterior_estimate()
        if post is None:
            raise ConfigError(
                f"x0 is a {source.iterator or 'given'} result without a posterior "
                f"({source.status}): only a Bayesian result with a posterior (gp_smc's, "
                "when it ran) can start least squares",
                where,
            )
        n_x, names = post.n_x, list(post.names)
        map_x, mean_x = list(map(float, post.map)), list(map(float, post.mean))
        key = "posterior"
    else:
        info = source.get("info", {}) if isinstance(source, Mapping) else {}
        post_d = info.get("posterior") if isinstance(info, Mapping) else None
        if not isinstance(post_d, Mapping) or "map" not in post_d or "mean" not in post_d:
            raise ConfigError(
                "not the result of a Bayesian calibration (no posterior MAP and mean in it)",
                where,
            )
        key = "info.posterior"
        names = post_d["names"] if "names" in post_d else info.get("names", [])
        map_x, mean_x = post_d["map"], post_d["mean"]
        n_x = post_d.get("n_x", len(map_x) if isinstance(map_x, list) else 0)
        if isinstance(n_x, bool) or not isinstance(n_x, int):
            raise ConfigError(f"{key}.n_x is {_shown(n_x)}, not a whole number", where)
        if not isinstance(names, list):
            raise ConfigError(f"{key}.names is {_shown(names)}, not a list of names", where)
    if not 1 <= n_x <= len(names):
        raise ConfigError(
            f"{key}.n_x = {n_x} does not count calibration parameters among its {len(names)} names",
            where,
        )
    names = names[:n_x]
    bad = next((n for n in names if not isinstance(n, str) or not n), None)
    if bad is not None:
        raise ConfigError(f"{key}.names holds {_shown(bad)}, not a parameter name", where)
    if len(set(names)) < len(names):
        raise ConfigError(f"{key}.names repeats a name: {', '.join(names)}", where)
    return [
        dict(zip(names, _finite(values, n_x, f"{key}.{field}", where), strict=True))
        for field, values in (("map", map_x), ("mean", mean_x))
    ]


def _finite(values: Any, n: int, name: str, where: str) -> list[float]:
    """``values`` as ``n`` finite floats (not booleans, strings or nested lists)."""
    if not isinstance(values, Sequence) or isinstance(values, str):
        raise ConfigError(f"{name} is {_shown(values)}, not a list of {n} numbers", where)
    if len(values) != n:
        raise ConfigError(f"{name} has {len(values)} values for {n} parameter names", where)
    out = []
    for k, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError(f"{name}[{k}] is {_shown(v)}, not a number", where)
        if not math.isfinite(float(v)):
            raise ConfigError(f"{name}[{k}] is {float(v)}, not a finite number", where)
        out.append(float(v))
    return out


def _shown(value: Any) -> str:
    text = json.dumps(value) if isinstance(value, (str, int, float, bool)) else ""
    kind = {dict: "an object", list: "a list", type(None): "null"}.get(type(value))
    return text[:40] if text else kind or type(value).__name__


def _read_json(path: Path, where: str) -> Any:
    """The JSON in the regular file ``path`` (see the module docstring)."""
    try:
        raw = regular_file_bytes(path, MAX_BYTES, where, "a result.json")
    except FileNotFoundError:
        raise ConfigError("cannot read the result (no such file)", where) from None
    try:
        data = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not a result.json (not UTF-8 at byte {exc.start})", where) from None
    except RecursionError:
        raise ConfigError(f"not a result.json (nested over {MAX_DEPTH} levels)", where) from None
    except ValueError as exc:  # JSONDecodeError, an integer of more than 4300 digits
        raise ConfigError(f"not a result.json ({exc})", where) from None
    if not isinstance(data, dict):
        raise ConfigError(f"not a result.json (its JSON is {_shown(data)})", where)
    if _depth(data) > MAX_DEPTH:
        raise ConfigError(f"not a result.json (nested over {MAX_DEPTH} levels)", where)
    return data


def _depth(data: Any) -> int:
    """How deep lists and objects nest in ``data`` (without recursion)."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, (dict, list)):
            deepest = max(deepest, depth)
            if depth <= MAX_DEPTH:
                items = value.values() if isinstance(value, dict) else value
                stack.extend((v, depth + 1) for v in items)
    return deepest
