"""The result of ``surrogate_convergence``: one row per n_train (the GP, its ML point and its
held-out error) and the design it was trained on."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ...core.problem import Result, jsonable
from ..surrogates.residuals import KeepsSurrogate

__all__ = ["ConvergenceRow", "SurrogateConvergenceResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ConvergenceRow(KeepsSurrogate):
    """The GP trained on the first ``n_train`` design points (the fitted GP itself for the
    plots: :class:`KeepsSurrogate`)."""

    n_train: int
    n_used: int  # successful runs among them (the GP's training set)
    ml_point: dict[str, float]  # maximum of the GP mean over the box
    ml_log_likelihood: float  # the GP mean there
    test_rmse: float  # error of the GP mean at the held-out runs, in L (nan: none)
    test_max_abs: float
    test_relative_l2: float  # ||error|| / ||L_test - mean L_test||
    reference_distance: float  # |ML point - reference| in units of the box (nan: none)
    #: the GP (GpSurrogate.state), not in result.json (read back: None)
    state: dict[str, Any] = field(repr=False, compare=False, metadata={"in_file": False})

    def to_dict(self) -> dict[str, Any]:
        """The row without the GP's state (for result.json)."""
        return {k: v for k, v in asdict(self).items() if k != "state"}


@dataclass
class SurrogateConvergenceResult(Result):
    """:class:`~fbia.core.problem.Result` of ``surrogate_convergence``: one
    :class:`ConvergenceRow` per n_train, the design and which of its points are held out."""

    names: list[str] = field(default_factory=list)
    rows: list[ConvergenceRow] = field(default_factory=list)
    points: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    log_likelihood: FloatArray = field(default_factory=lambda: np.zeros(0))
    n_test: int = 0
    reference: dict[str, float] | None = None
    #: what every surrogate_convergence result.json holds (fbia.load_result)
    required_fields: ClassVar[tuple[str, ...]] = ("rows", "n_test")

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        parts = {
            "names": self.names,
            "rows": [row.to_dict() for row in self.rows],
            "points": self.points,
            "log_likelihood": self.log_likelihood,
            "n_test": self.n_test,
            "reference": self.reference,
        }
        out["info"] = {**out["info"], **jsonable(parts)}
        return out

    def check_loaded(self) -> None:
        """Every row's ML point over ``names`` (the table's columns)."""
        for i, row in enumerate(self.rows):
            if not set(self.names) <= set(row.ml_point):
                raise ValueError(f"info.rows[{i}].ml_point has no value of each of {self.names}")

    def quantities(self) -> dict[str, float]:
        """Besides :meth:`Result.quantities` (``x.<name>`` is the ML point of the largest
        n_train): per row ``n_train.<n>.<name>`` (its ML point), ``n_train.<n>.distance``
        (|ML point - reference| in box units, NaN without a reference), ``.test_rmse``,
        ``.test_max_abs``, ``.test_relative_l2`` (held-out error in L), ``.n_used`` and
        ``.ml_log_likelihood``; for every smaller row ``a``, ``n_train.<n>.gain_over.<a>``,
        the held-out relative L2 error at ``a`` over the one at ``n`` (how much the larger
        design gained: 1 none, 2 half the error; Fig. 12); ``n_test``."""
        out = super().quantities()
        for r in self.rows:
            key = f"n_train.{r.n_train}"
            out.update({f"{key}.{name}": float(v) for name, v in r.ml_point.items()})
            out[f"{key}.distance"] = float(r.reference_distance)
            out[f"{key}.test_rmse"] = float(r.test_rmse)
            out[f"{key}.test_max_abs"] = float(r.test_max_abs)
            out[f"{key}.test_relative_l2"] = float(r.test_relative_l2)
            out[f"{key}.n_used"] = float(r.n_used)
            out[f"{key}.ml_log_likelihood"] = float(r.ml_log_likelihood)
        for i, r in enumerate(self.rows):
            for a in self.rows[:i]:
                gain = a.test_relative_l2 / r.test_relative_l2 if r.test_relative_l2 else math.nan
                out[f"n_train.{r.n_train}.gain_over.{a.n_train}"] = float(gain)
        out["n_test"] = float(self.n_test)
        return out

    def table(self) -> str:
        """One line per n_train: runs used, ML point, GP mean there, held-out error."""
        head = f"{'n_train':>7} {'used':>5} " + " ".join(f"{n:>10}" for n in self.names)
        head += f" {'L at ML':>10} {'test RMSE':>10} {'test rel':>9}"
        if self.reference is not None:
            head += f" {'|ML-ref|':>9}"
        lines = [head]
        for r in self.rows:
            line = f"{r.n_train:>7} {r.n_used:>5} " + " ".join(
                f"{r.ml_point[n]:>10.4g}" for n in self.names
            )
            line += f" {r.ml_log_likelihood:>10.4g} {r.test_rmse:>10.3g} {r.test_relative_l2:>9.3g}"
            if self.reference is not None:
                line += f" {r.reference_distance:>9.3g}"
            lines.append(line)
        return "\n".join(lines)

    def summary(self) -> str:
        text = super().summary()
        return text if not self.rows else f"{text}\n{self.table()}"
