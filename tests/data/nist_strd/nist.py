"""NIST StRD nonlinear regression problems: data, starts, certified values, model functions.

The JSON files next to this module are parsed copies of the NIST certified files
(https://www.itl.nist.gov/div898/strd/nls/nls_main.shtml); the models are written out below as
Python functions (no ``eval`` of the model strings).  ``test_lm_nist.py`` checks every model
against the certified residual sum of squares, so a typo here cannot go unnoticed.

>>> p = load("Misra1a")
>>> round(float(p.residuals(p.certified) @ p.residuals(p.certified)), 8)
0.12455139
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy import arctan, cos, exp, pi, sin

HERE = Path(__file__).resolve().parent

Model = Callable[[np.ndarray, dict[str, np.ndarray]], np.ndarray]


def _misra1a(b, d):
    return b[0] * (1 - exp(-b[1] * d["x"]))


def _rational_cubic(b, d):
    x = d["x"]
    return (b[0] + b[1] * x + b[2] * x**2 + b[3] * x**3) / (
        1 + b[4] * x + b[5] * x**2 + b[6] * x**3
    )


def _chwirut(b, d):
    x = d["x"]
    return exp(-b[0] * x) / (b[1] + b[2] * x)


def _lanczos(b, d):
    x = d["x"]
    return b[0] * exp(-b[1] * x) + b[2] * exp(-b[3] * x) + b[4] * exp(-b[5] * x)


def _gauss(b, d):
    x = d["x"]
    return (
        b[0] * exp(-b[1] * x)
        + b[2] * exp(-((x - b[3]) ** 2) / b[4] ** 2)
        + b[5] * exp(-((x - b[6]) ** 2) / b[7] ** 2)
    )


MODELS: dict[str, Model] = {
    "Misra1a": _misra1a,
    "BoxBOD": _misra1a,
    "Chwirut1": _chwirut,
    "Chwirut2": _chwirut,
    "Lanczos1": _lanczos,
    "Lanczos2": _lanczos,
    "Lanczos3": _lanczos,
    "Gauss1": _gauss,
    "Gauss2": _gauss,
    "Gauss3": _gauss,
    "Hahn1": _rational_cubic,
    "Thurber": _rational_cubic,
    "DanWood": lambda b, d: b[0] * d["x"] ** b[1],
    "Misra1b": lambda b, d: b[0] * (1 - (1 + b[1] * d["x"] / 2) ** (-2)),
    "Misra1c": lambda b, d: b[0] * (1 - (1 + 2 * b[1] * d["x"]) ** (-0.5)),
    "Misra1d": lambda b, d: b[0] * b[1] * d["x"] * (1 + b[1] * d["x"]) ** (-1),
    "Kirby2": lambda b, d: (
        (b[0] + b[1] * d["x"] + b[2] * d["x"] ** 2) / (1 + b[3] * d["x"] + b[4] * d["x"] ** 2)
    ),
    "Nelson": lambda b, d: b[0] - b[1] * d["x1"] * exp(-b[2] * d["x2"]),
    "MGH17": lambda b, d: b[0] + b[1] * exp(-d["x"] * b[3]) + b[2] * exp(-d["x"] * b[4]),
    "Roszman1": lambda b, d: b[0] - b[1] * d["x"] - arctan(b[2] / (d["x"] - b[3])) / pi,
    "ENSO": lambda b, d: (
        b[0]
        + b[1] * cos(2 * pi * d["x"] / 12)
        + b[2] * sin(2 * pi * d["x"] / 12)
        + b[4] * cos(2 * pi * d["x"] / b[3])
        + b[5] * sin(2 * pi * d["x"] / b[3])
        + b[7] * cos(2 * pi * d["x"] / b[6])
        + b[8] * sin(2 * pi * d["x"] / b[6])
    ),
    "MGH09": lambda b, d: (
        b[0] * (d["x"] ** 2 + d["x"] * b[1]) / (d["x"] ** 2 + d["x"] * b[2] + b[3])
    ),
    "Rat42": lambda b, d: b[0] / (1 + exp(b[1] - b[2] * d["x"])),
    "Rat43": lambda b, d: b[0] / (1 + exp(b[1] - b[2] * d["x"])) ** (1 / b[3]),
    "MGH10": lambda b, d: b[0] * exp(b[1] / (d["x"] + b[2])),
    "Eckerle4": lambda b, d: (b[0] / b[1]) * exp(-0.5 * ((d["x"] - b[2]) / b[1]) ** 2),
    "Bennett5": lambda b, d: b[0] * (b[1] + d["x"]) ** (-1 / b[2]),
}

#: NIST's response for Nelson is log(y).
_LOG_RESPONSE = {"Nelson"}


@dataclass(frozen=True)
class NistProblem:
    name: str
    difficulty: str
    start1: np.ndarray
    start2: np.ndarray
    certified: np.ndarray
    certified_std: np.ndarray
    rss: float
    data: dict[str, np.ndarray]
    y: np.ndarray
    model: Model

    def residuals(self, b: np.ndarray) -> np.ndarray:
        """Model minus data (the residual vector of Paper A eq. 19)."""
        return self.model(np.asarray(b, dtype=float), self.data) - self.y

    def lre(self, estimate: np.ndarray) -> np.ndarray:
        """Log relative error −log10(|estimate − certified| / |certified|), capped at 11."""
        est = np.asarray(estimate, dtype=float)
        with np.errstate(divide="ignore"):
            rel = np.abs(est - self.certified) / np.abs(self.certified)
            return np.minimum(-np.log10(rel), 11.0)


def names() -> list[str]:
    """The problems in NIST's order (lower, average, higher difficulty)."""
    lines = (HERE / "index.csv").read_text().splitlines()[1:]
    return [line.split(",")[0] for line in lines if line]


def load(name: str) -> NistProblem:
    raw = json.loads((HERE / f"{name}.json").read_text())
    cols = {k: np.asarray(v, dtype=float) for k, v in raw["data"].items()}
    y = cols.pop("y")
    if name in _LOG_RESPONSE:
        y = np.log(y)
    return NistProblem(
        name=name,
        difficulty=raw["difficulty"],
        start1=np.asarray(raw["start1"], dtype=float),
        start2=np.asarray(raw["start2"], dtype=float),
        certified=np.asarray(raw["certified_values"], dtype=float),
        certified_std=np.asarray(raw["certified_std_dev"], dtype=float),
        rss=float(raw["residual_sum_of_squares"]),
        data=cols,
        y=y,
        model=MODELS[name],
    )


def rss_lre(problem: NistProblem, estimate: np.ndarray) -> float:
    r = problem.residuals(estimate)
    rel = abs(float(r @ r) - problem.rss) / problem.rss
    return 11.0 if rel == 0 else min(-math.log10(rel), 11.0)
