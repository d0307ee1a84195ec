"""Global sensitivity: Sobol' indices of the log-likelihood or the discrepancy, on a surrogate.

Paper B recommends a sensitivity analysis before a high-dimensional calibration: which inputs
(calibration parameters x and uncertain inputs theta) move the data fit at all?  The
first-order index ``S1_i`` is the share of the variance of the quantity that ``x_i`` explains
alone, the total index ``ST_i`` the share it takes part in (interactions included); an input
with ``ST_i`` near 0 can be fixed.  The variance is over the inputs' priors (a calibration
parameter without a prior: uniform on its bounds; the map is gp_design's ``unit_to_inputs``).

The stages (``fbia.iterator("sobol_indices", ...)``):

1. **Design**: ``n_train`` (+ ``n_test`` held-out) points of a scrambled Sobol sequence mapped
   through the input distributions, run through the evaluator (one batch);
2. **Surrogate**: the GP of :mod:`.surrogates.gp` (Paper B eq. 26-29) on the log-likelihood L
   (Paper B eq. 5) or on the discrepancy D of the measure (``quantity``); failed runs are left
   out; the held-out points measure its error, and a surrogate whose error is not small
   against the quantity's spread makes the status ``unreliable``;
3. **Indices**: Saltelli's sampling scheme with ``n_base`` base points (``n_base (d + 2)``
   surrogate evaluations) and the Jansen/Saltelli estimators with bootstrap confidence
   intervals, both from SALib (Herman & Usher 2017; Saltelli et al. 2010), on the surrogate's
   mean: no forward runs beyond the design.

:func:`sobol_indices` does stage 3 for any vectorised function (a check against closed-form
indices, e.g. the Ishigami function, in tests/iterators/test_sobol_indices.py).

>>> import fbia
>>> it = fbia.iterator("sobol_indices", n_train=64, n_base=512, seed=0)
>>> # result = it.run(problem); result.indices.st  -> total indices, one per input
"""

from __future__ import annotations

import html
import math
import time
import warnings
from collections.abc import Callable, Generator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field
from scipy.stats import qmc

from ..core.errors import ConfigError
from ..core.iteration import Evaluator, IteratorBase
from ..core.likelihood import gaussian_log_likelihood, measurement_count, noise_levels
from ..core.options import PluginOptions
from ..core.parameters import Parameter
from ..core.problem import InverseProblem, Result, html_table, jsonable
from ..figures import legend, pyplot
from .surrogates.design import unit_to_inputs
from .surrogates.gp import GpSurrogate

__all__ = ["SobolIndices", "SobolIndicesIterator", "SobolIndicesResult", "sobol_indices"]

FloatArray = NDArray[np.float64]

#: the largest held-out RMSE of the surrogate, relative to the quantity's standard deviation
#: over the design, for the indices to count as reliable
RELIABLE_RELATIVE_RMSE = 0.1


@dataclass(frozen=True)
class SobolIndices:
    """First-order and total Sobol' indices with the half-widths of their confidence
    intervals (bootstrap, level ``confidence``), one per input in ``names`` order."""

    names: list[str]
    s1: list[float]
    s1_conf: list[float]
    st: list[float]
    st_conf: list[float]
    confidence: float
    n_evaluations: int  # function evaluations of the Saltelli scheme

    def table(self) -> str:
        """The indices as a text table."""
        head = f"{'input':<14} {'S1':>8} {'± conf':>8} {'ST':>8} {'± conf':>8}"
        rows = [
            f"{n:<14} {a:8.3f} {b:8.3f} {c:8.3f} {d:8.3f}"
            for n, a, b, c, d in zip(
                self.names, self.s1, self.s1_conf, self.st, self.st_conf, strict=True
            )
        ]
        return "\n".join([head, *rows])


def sobol_indices(
    f: Callable[[FloatArray], FloatArray],
    parameters: Sequence[Parameter],
    n_base: int = 1024,
    seed: int = 0,
    confidence: float = 0.95,
    resamples: int = 200,
) -> SobolIndices:
    """Sobol' indices of the vectorised ``f`` (rows of inputs -> values) over the inputs'
    distributions, by SALib's Saltelli sampling and estimators (``n_base (d + 2)`` calls)."""
    from SALib.analyze import sobol as analyze
    from SALib.sample import sobol as sample

    d = len(parameters)
    names = [p.name for p in parameters]
    problem = {"num_vars": d, "names": names, "bounds": [[0.0, 1.0]] * d}
    # SALib seeds numpy's global generator: keep the caller's state as it was
    global_state = np.random.get_state()  # noqa: NPY002 (restored, not used)
    try:
        u = sample.sample(problem, n_base, calc_second_order=False, scramble=True, seed=seed)
        y = np.asarray(
            f(unit_to_inputs(parameters, np.asarray(u, dtype=float), through_prior=True)),
            dtype=float,
        )
        if not np.all(np.isfinite(y)):
            raise ConfigError("the function is not finite at every sample", "sobol_indices")
        res = analyze.analyze(
            problem,
            y,
            calc_second_order=False,
            conf_level=confidence,
            num_resamples=resamples,
            seed=seed,
        )
    finally:
        np.random.set_state(global_state)  # noqa: NPY002
    return SobolIndices(
        names=names,
        s1=[float(v) for v in res["S1"]],
        s1_conf=[float(v) for v in res["S1_conf"]],
        st=[float(v) for v in res["ST"]],
        st_conf=[float(v) for v in res["ST_conf"]],
        confidence=confidence,
        n_evaluations=len(y),
    )


@dataclass
class SobolIndicesResult(Result):
    """:class:`~fbia.core.problem.Result` of ``sobol_indices``: ``indices`` (None if the
    design failed), the ``quantity``, the surrogate's summary and its held-out error."""

    quantity: str = "log_likelihood"
    indices: SobolIndices | None = None
    surrogate: dict[str, Any] = field(default_factory=dict)
    test_relative_rmse: float = math.nan
    #: what every sobol_indices result.json holds (fbia.load_result)
    required_fields: ClassVar[tuple[str, ...]] = ("quantity", "indices")

    def check_loaded(self) -> None:
        """The indices and their intervals: one of each per input."""
        ind = self.indices
        if ind is not None:
            for key in ("s1", "s1_conf", "st", "st_conf"):
                if len(getattr(ind, key)) != len(ind.names):
                    raise ValueError(f"info.indices.{key} has not one value per input {ind.names}")

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        parts = {
            "quantity": self.quantity,
            "indices": None if self.indices is None else asdict(self.indices),
            "surrogate": self.surrogate,
            "test_relative_rmse": self.test_relative_rmse,
        }
        out["info"] = {**out["info"], **jsonable(parts)}
        return out

    def summary(self) -> str:
        text = super().summary()
        return text if self.indices is None else f"{text}\n{self.indices.table()}"

    def to_records(self) -> list[dict[str, Any]]:
        """The indices as plain rows, one per input (:meth:`to_dataframe` wraps them):
        ``input``, ``s1``, ``s1_conf``, ``st``, ``st_conf`` (the half-widths of the
        confidence intervals at ``indices.confidence``); no rows without indices."""
        ind = self.indices
        if ind is None:
            return []
        columns = zip(ind.names, ind.s1, ind.s1_conf, ind.st, ind.st_conf, strict=True)
        keys = ("input", "s1", "s1_conf", "st", "st_conf")
        return [dict(zip(keys, row, strict=True)) for row in columns]

    def _html_body(self) -> str:
        """The indices table and what they were computed from."""
        ind = self.indices
        if ind is None:
            return ""
        head = ["input", "S1", "± conf", "ST", "± conf"]
        keys = ("s1", "s1_conf", "st", "st_conf")
        rows = [[r["input"], *(f"{r[k]:.3f}" for k in keys)] for r in self.to_records()]
        rmse = self.test_relative_rmse
        check = (
            "no held-out runs"
            if math.isnan(rmse)
            else f"the surrogate's held-out RMSE is {rmse:.2g} of the quantity's spread"
        )
        about = (
            f"Sobol' indices of {self.quantity} on the surrogate ({ind.n_evaluations} "
            f"evaluations), {ind.confidence:.0%} confidence intervals; {check}"
        )
        return html_table(head, rows) + f"<p>{html.escape(about)}</p>"


@dataclass(frozen=True)
class SobolState:
    """What :meth:`SobolIndicesIterator.steps` yields after each stage."""

    stage: str
    message: str


class SobolIndicesIterator(IteratorBase):
    """Sobol' indices of L or D on a GP surrogate (see the module docstring)."""

    #: the extra it needs (fbia.core.extras)
    requires = ("GPy", "numba", "SALib")

    #: the class of its results (fbia.load_result reads them back as it)
    result_type = SobolIndicesResult

    class Options(PluginOptions):
        quantity: Literal["log_likelihood", "distance"] = Field(
            "log_likelihood",
            description="L of Paper B eq. 5 (needs sigma_N) or the measure's discrepancy D [-]",
        )
        n_train: int = Field(128, ge=4, le=100_000, description="forward runs of the design [-]")
        n_test: int = Field(
            16, ge=0, le=100_000, description="held-out forward runs for the surrogate error [-]"
        )
        n_base: int = Field(
            1024, ge=16, le=2**20, description="base samples N of Saltelli's scheme [-]"
        )
        confidence: float = Field(0.95, gt=0, lt=1, description="confidence level [-]")
        resamples: int = Field(200, ge=10, description="bootstrap resamples [-]")
        ard: bool = Field(True, description="one GP length scale per input [-]")
        seed: int = Field(0, description="seed of the design and of the sampling [-]")

    options: Options

    @classmethod
    def example_options(cls) -> dict[str, Any]:
        return {"n_train": 24, "n_test": 4, "n_base": 64, "resamples": 20, "seed": 0}

    def steps(
        self, problem: InverseProblem, evaluator: Evaluator
    ) -> Generator[SobolState, None, SobolIndicesResult]:
        o = self.options
        t0 = time.perf_counter()
        inputs = [*problem.parameters, *problem.uncertain]
        names = [p.name for p in inputs]
        sigmas = noise_levels(problem) if o.quantity == "log_likelihood" else []
        count = measurement_count(problem)
        sampler = qmc.Sobol(len(inputs), scramble=True, seed=o.seed)
        n_all = o.n_train + o.n_test
        with warnings.catch_warnings():  # any n is fine for a training design
            warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*")
            x = unit_to_inputs(inputs, sampler.random(n_all), through_prior=True)
        yield SobolState("design", f"{o.n_train} + {o.n_test} Sobol points")
        points = [dict(zip(names, map(float, row), strict=True)) for row in x]
        evaluations = list(evaluator.evaluate(problem, points))
        if o.quantity == "log_likelihood":
            y = np.array([gaussian_log_likelihood(ev, sigmas, count) for ev in evaluations])
        else:  # -D: the GP's prior mean sits below the data, i.e. far from it D is large
            y = np.array([-ev.distance if ev.ok else -math.inf for ev in evaluations])
        ok = np.isfinite(y)
        n_failed = int((~ok).sum())
        yield SobolState("forward_runs", f"{len(evaluations)} forward runs, {n_failed} failed")
        train = ok & (np.arange(n_all) < o.n_train)
        test = ok & (np.arange(n_all) >= o.n_train)
        if train.sum() < 4:
            return SobolIndicesResult(
                status="all_failed",
                success=False,
                message=f"{n_failed} of {len(evaluations)} forward runs failed: too few to train",
                quantity=o.quantity,
            )
        gp = GpSurrogate(ard=o.ard).fit(x[train], y[train], rng=o.seed)
        spread = float(np.std(y[train])) or 1.0
        rel = math.nan
        if test.any():
            err = gp.predict_mean(x[test]) - y[test]
            rel = float(np.sqrt(np.mean(err**2))) / spread
        yield SobolState("surrogate", f"GP on {int(train.sum())} runs; held-out RMSE {rel:.3g}")
        sign = 1.0 if o.quantity == "log_likelihood" else -1.0
        indices = sobol_indices(
            lambda z: sign * gp.predict_mean(z),
            inputs,
            n_base=o.n_base,
            seed=o.seed,
            confidence=o.confidence,
            resamples=o.resamples,
        )
        yield SobolState("indices", f"{indices.n_evaluations} surrogate evaluations")
        if math.isnan(rel):
            status, note = "unchecked", "; no held-out runs (n_test = 0): surrogate unchecked"
        elif rel > RELIABLE_RELATIVE_RMSE:
            status = "unreliable"
            note = (
                f"; the surrogate's held-out RMSE is {rel:.2g} of the quantity's spread (limit "
                f"{RELIABLE_RELATIVE_RMSE:g}): the indices are not reliable, train on more runs"
            )
        else:
            status, note = "completed", f"; surrogate held-out RMSE {rel:.2g} of the spread"
        order = np.argsort(indices.st)[::-1]
        top = ", ".join(f"{names[i]} {indices.st[i]:.2f}" for i in order[:3])
        return SobolIndicesResult(
            status=status,
            success=status == "completed",
            message=f"Sobol' indices of {o.quantity} (total: {top}){note}",
            indices=indices,
            surrogate=dict(gp.describe()),
            test_relative_rmse=rel,
            info={"seconds": time.perf_counter() - t0},
            quantity=o.quantity,
        )

    @staticmethod
    def write_plots(result: Result, problem: InverseProblem, folder: Path) -> list[Path]:
        """``sobol_indices.png``: S1 and ST per input with their confidence intervals."""
        if not isinstance(result, SobolIndicesResult) or result.indices is None:
            return []
        plt = pyplot()
        ind = result.indices
        folder.mkdir(parents=True, exist_ok=True)
        k = np.arange(len(ind.names))
        fig, ax = plt.subplots(figsize=(1.2 + 0.9 * len(k), 3.2))
        ax.bar(k - 0.2, ind.s1, 0.4, yerr=ind.s1_conf, capsize=3, label="first order S1")
        ax.bar(k + 0.2, ind.st, 0.4, yerr=ind.st_conf, capsize=3, label="total ST")
        ax.set_xticks(k, ind.names)
        ax.set(ylabel="Sobol' index", title=f"sensitivity of {result.quantity}")
        ax.axhline(0.0, color="0.5", lw=0.5)
        legend(ax, fontsize=8)
        path = folder / "sobol_indices.png"
        fig.savefig(path, dpi=150, bbox_inches="tight")
        plt.close(fig)
        return [path]
