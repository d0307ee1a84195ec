"""Bayes -> Levenberg-Marquardt: start least squares from a posterior (thesis conclusion).

A Bayesian calibration (``gp_smc``) finds where the posterior mass is; Levenberg-Marquardt
then sharpens the point estimate with real forward runs and gives its local covariance.
:func:`posterior_starts` turns a ``gp_smc`` result -- the :class:`GpSmcResult` object, or
its ``result.json`` as written by ``fbia run`` -- into two initial guesses, the posterior
MAP and the posterior mean of the calibration parameters.

>>> # bayes = fbia.iterator("gp_smc", n_train=200).run(problem)
>>> # lm = fbia.iterator("levenberg_marquardt", x0=bayes)         # starts: MAP, mean
>>> # a study file: [iterator] options = { x0_from = "output_bayes/result.json" }
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ...core.errors import ConfigError
from ...core.problem import Result
from ..gp_smc.result import GpSmcResult

__all__ = ["POSTERIOR_LABELS", "posterior_starts"]

#: what the two starts are, in order
POSTERIOR_LABELS = ("posterior MAP", "posterior mean")


def posterior_starts(
    source: Result | Mapping[str, Any] | str | Path,
) -> list[dict[str, float]]:
    """``[MAP, mean]`` of the calibration parameters of a ``gp_smc`` result (the object, its
    ``to_dict()`` or the path of its ``result.json``); a ConfigError if it has no posterior."""
    where = "levenberg_marquardt: x0_from"
    if isinstance(source, (str, Path)):
        path = Path(source)
        where = f"{where} {path}"
        try:
            source = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise ConfigError(f"cannot read the result ({exc.strerror})", where) from None
        except ValueError as exc:
            raise ConfigError(f"not a result.json ({exc})", where) from None
    if isinstance(source, Result) and not isinstance(source, GpSmcResult):
        raise ConfigError(
            f"x0 is a {source.iterator or 'non-Bayesian'} result: only a gp_smc result has a "
            "posterior to start from",
            where,
        )
    if isinstance(source, GpSmcResult):
        post = source.posterior
        if post is None:
            raise ConfigError(f"the gp_smc result has no posterior ({source.status})", where)
        names = list(post.names[: post.n_x])
        map_x, mean_x = list(post.map), list(post.mean)
    else:
        info = source.get("info", {}) if isinstance(source, Mapping) else {}
        post_d = info.get("posterior") if isinstance(info, Mapping) else None
        if not isinstance(post_d, Mapping) or "map" not in post_d or "mean" not in post_d:
            raise ConfigError(
                "not the result of a Bayesian calibration (no posterior MAP and mean in it)",
                where,
            )
        n_x = int(post_d.get("n_x", len(post_d["map"])))
        names = list(post_d.get("names", info.get("names", [])))[:n_x]
        map_x, mean_x = list(post_d["map"]), list(post_d["mean"])
    if not names or len(map_x) != len(names) or len(mean_x) != len(names):
        raise ConfigError("the posterior's names and values do not match", where)
    return [
        {n: float(v) for n, v in zip(names, map_x, strict=True)},
        {n: float(v) for n, v in zip(names, mean_x, strict=True)},
    ]
