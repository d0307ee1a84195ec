"""Convergence of the GP surrogate of L over n_train on one Sobol design (Paper B Fig. 8).

Paper B studies how many forward runs the surrogate of the log-likelihood needs: the GP is
trained on growing prefixes n_train = 10, 20, 50, ... of one scrambled Sobol sequence (all
samples "are consecutive samples from the same Sobol sequence"), and its maximum-likelihood
point is compared with the ground truth (Fig. 8); the error at held-out points over n_train is
Fig. 12.  This iterator does that study in one go:

1. **Design**: the first ``max(n_train) + n_test`` points of the Sobol sequence of
   :func:`~fbia.iterators.surrogates.design.sobol_design` (the same points, seed for seed, as
   ``gp_smc`` with ``design = "sobol"``, so a study store shares the runs), one evaluator
   batch; the last ``n_test`` are held out.
2. **Per n_train**: the GP of :mod:`.surrogates.gp` (eq. 26-29) on the successful runs among
   the first n_train points; its maximum-likelihood point (the maximum of the GP mean over the
   inputs' box: the best of ``n_candidates`` Sobol candidates, polished by L-BFGS-B), the GP
   mean there, and its error at the held-out runs (RMSE, largest error, relative L2).

>>> import fbia
>>> it = fbia.iterator("surrogate_convergence", n_train=[10, 20, 50], n_test=20, seed=0)
>>> # result = it.run(problem); result.rows[-1].ml_point -> {'E': ..., 'nu': ...}

``write_plots`` draws ``surrogate_convergence.png`` (the ML point and the held-out error over
n_train) and ``surrogate_convergence_fields.png`` (exp(L - max L) of each GP over the first
two inputs with its runs, failed runs as grey crosses and the ML point: Fig. 8).
"""

from __future__ import annotations

import math
import time
from collections.abc import Generator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator
from scipy.optimize import minimize

from ..core.errors import ConfigError
from ..core.iteration import Evaluator, IteratorBase
from ..core.likelihood import gaussian_log_likelihood, measurement_count, noise_levels
from ..core.options import PluginOptions
from ..core.problem import InverseProblem, Result
from .convergence.result import ConvergenceRow, SurrogateConvergenceResult
from .surrogates.design import search_box, sobol_design
from .surrogates.gp import GpSurrogate

__all__ = ["ConvergenceRow", "SurrogateConvergenceIterator", "SurrogateConvergenceResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ConvergenceState:
    """What :meth:`SurrogateConvergenceIterator.steps` yields after each stage."""

    stage: str
    message: str


class SurrogateConvergenceIterator(IteratorBase):
    """The GP surrogate of L on growing prefixes of one Sobol design (see the module
    docstring)."""

    #: the extra it needs (fbia.core.extras)
    requires = ("GPy", "numba")

    #: the class of its results (fbia.load_result reads them back as it)
    result_type = SurrogateConvergenceResult

    class Options(PluginOptions):
        n_train: list[int] = Field(
            [10, 20, 50, 100, 200, 500],
            min_length=1,
            description="training sizes: prefixes of the Sobol design, increasing (Fig. 8) [-]",
        )
        n_test: int = Field(
            100,
            ge=0,
            le=100_000,
            description="held-out runs: the Sobol points after the largest n_train [-]",
        )
        seed: int = Field(0, description="seed of the Sobol scrambling (as gp_smc's) [-]")
        design_space: Literal["box", "prior"] = Field(
            "box",
            description="where Sobol points go: 'box' uniform in the bounds; 'prior' "
            "through the priors' inverse CDFs (as gp_smc's) [-]",
        )
        ard: bool = Field(False, description="one GP length scale per input [-]")
        gp_restarts: int = Field(
            2, ge=0, description="extra GP trainings from random initial guesses [-]"
        )
        nugget_factor: float = Field(
            1e-5, gt=0, description="nugget sigma_n^2 = factor (max L - min L) [-]"
        )
        mean_offset: float = Field(
            1.0, description="GP prior mean m = min L - offset (max L - min L) [-]"
        )
        n_candidates: int = Field(
            4096,
            ge=16,
            le=1_000_000,
            description="Sobol candidates for the maximum of the GP mean (then L-BFGS-B) [-]",
        )
        reference: dict[str, float] | None = Field(
            None,
            description="a point to compare the ML points with, e.g. the ground truth of "
            "synthetic data (every input by name) [input units]",
        )

        @field_validator("n_train")
        @classmethod
        def _increasing(cls, v: list[int]) -> list[int]:
            if any(n < 2 for n in v) or any(b <= a for a, b in zip(v, v[1:], strict=False)):
                raise ValueError(f"must be increasing sizes of at least 2, got {v}")
            if v[-1] > 100_000:
                raise ValueError(f"at most 100000 runs, got {v[-1]}")
            return v

    options: Options

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        return {"n_train": [8, 16], "n_test": 4, "n_candidates": 64, "gp_restarts": 0}

    def steps(
        self, problem: InverseProblem, evaluator: Evaluator
    ) -> Generator[ConvergenceState, None, SurrogateConvergenceResult]:
        o = self.options
        t0 = time.perf_counter()
        inputs = [*problem.parameters, *problem.uncertain]
        names = [p.name for p in inputs]
        reference = _reference(o.reference, names)
        sigmas, count = noise_levels(problem), measurement_count(problem)
        n_max = o.n_train[-1]
        x = sobol_design(inputs, n_max + o.n_test, o.seed, through_prior=o.design_space == "prior")
        yield ConvergenceState("design", f"{n_max} training + {o.n_test} test points (Sobol)")
        points = [dict(zip(names, map(float, row), strict=True)) for row in x]
        evaluations = list(evaluator.evaluate(problem, points))
        y = np.array([gaussian_log_likelihood(ev, sigmas, count) for ev in evaluations])
        ok = np.isfinite(y)
        n_failed = int((~ok).sum())
        yield ConvergenceState("forward_runs", f"{len(y)} forward runs, {n_failed} failed")
        index = np.arange(len(y))
        test = ok & (index >= n_max)
        lower, upper = search_box(inputs, x)
        candidates = sobol_design(inputs, o.n_candidates, o.seed + 1)
        rows: list[ConvergenceRow] = []
        for n in o.n_train:
            use = ok & (index < n)
            if use.sum() < 2:
                yield ConvergenceState("surrogate", f"n_train = {n}: fewer than 2 successful runs")
                continue
            gp = GpSurrogate(
                ard=o.ard,
                restarts=o.gp_restarts,
                nugget_factor=o.nugget_factor,
                mean_offset=o.mean_offset,
            ).fit(x[use], y[use], rng=np.random.default_rng(o.seed))
            ml, ml_value = _maximum(gp, candidates, lower, upper)
            err = gp.test_error(x[test], y[test]) if test.any() else {}
            rows.append(
                ConvergenceRow(
                    n_train=n,
                    n_used=int(use.sum()),
                    ml_point=dict(zip(names, map(float, ml), strict=True)),
                    ml_log_likelihood=ml_value,
                    test_rmse=float(err.get("test_rmse", math.nan)),
                    test_max_abs=float(err.get("test_max_abs", math.nan)),
                    test_relative_l2=float(err.get("test_relative_l2", math.nan)),
                    reference_distance=(
                        math.nan
                        if reference is None
                        else float(np.linalg.norm((ml - reference) / (upper - lower)))
                    ),
                    state=gp.state(),
                ).attach(gp)
            )
            yield ConvergenceState(
                "surrogate",
                f"n_train = {n}: ML point "
                + ", ".join(f"{k} = {v:.4g}" for k, v in rows[-1].ml_point.items())
                + f"; held-out RMSE {rows[-1].test_rmse:.3g} in L",
            )
        if rows:
            last = rows[-1]
            status = "completed" if test.any() else "unchecked"
            note = (
                f"; held-out RMSE {last.test_rmse:.3g} in L at {int(test.sum())} runs"
                if test.any()
                else "; no held-out runs (n_test = 0)"
            )
            message = (
                f"GP of L on {len(rows)} prefixes of the Sobol design (n_train up to "
                f"{last.n_train}, {last.n_used} successful runs){note}"
            )
        else:
            status = "all_failed"
            message = f"{n_failed} of {len(y)} forward runs failed: no GP could be trained"
        return SurrogateConvergenceResult(
            status=status,
            success=status == "completed",
            message=message,
            x=dict(rows[-1].ml_point) if rows else None,
            info={"seconds": time.perf_counter() - t0},
            names=names,
            rows=rows,
            points=x,
            log_likelihood=y,
            n_test=o.n_test,
            reference=None if o.reference is None else dict(o.reference),
        )

    @staticmethod
    def write_plots(result: Result, problem: InverseProblem, folder: Path) -> list[Path]:
        """``surrogate_convergence.png`` and ``surrogate_convergence_fields.png`` (Fig. 8)."""
        from .convergence.plots import plot_surrogate_convergence

        if not isinstance(result, SurrogateConvergenceResult) or not result.rows:
            return []
        return plot_surrogate_convergence(result, [*problem.parameters, *problem.uncertain], folder)


def _reference(reference: dict[str, float] | None, names: Sequence[str]) -> FloatArray | None:
    """The ``reference`` option as a vector in input order; every input must be given."""
    if reference is None:
        return None
    if sorted(reference) != sorted(names):
        raise ConfigError(
            f"gives {sorted(reference)}, the inputs are {list(names)}: give each once",
            "reference",
        )
    return np.array([float(reference[n]) for n in names])


def _maximum(
    gp: GpSurrogate, candidates: FloatArray, lower: FloatArray, upper: FloatArray
) -> tuple[FloatArray, float]:
    """The maximum of the GP mean in the box: the best candidate, polished by L-BFGS-B in
    the box's unit coordinates."""
    values = gp.predict_mean(candidates)
    start = (candidates[int(np.argmax(values))] - lower) / (upper - lower)

    def negative(u: FloatArray) -> float:
        return -float(gp.predict_mean((lower + u * (upper - lower))[None, :])[0])

    best = minimize(negative, start, method="L-BFGS-B", bounds=[(0.0, 1.0)] * len(start))
    u = best.x if best.fun <= negative(start) else start
    point = lower + np.clip(u, 0.0, 1.0) * (upper - lower)
    return point, -negative(u)
