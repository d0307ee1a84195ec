"""Algorithm 1 at the paper's settings in seconds: the log-densities tabulated, the moves fused.

Paper B's Algorithm 1 rejuvenates every particle with ``n_rej`` Metropolis-Hastings steps in
*every* tempering step; at 10 000 particles and 30 steps that is 300 000 log-likelihood values
per tempering step.  On a 2-D GP mean of 1024 runs one step costs about 0.2 s, and the numpy
loop of the moves alone about 35 ms.  For a posterior over at most three inputs with a
bounded prior, :class:`LogTables` makes both cheap (``benchmarks/bench_smc_table.py``: 33 ms
per step in all, 7 times faster, the posterior within 0.015 sd of quadrature):

* the log-likelihood L is evaluated once on a regular grid over the prior's box (six cells
  beyond it on every side) and represented by the cubic B-spline that interpolates it
  (coefficients by :func:`scipy.ndimage.spline_filter`; its value is the one
  :func:`scipy.ndimage.map_coordinates` gives with ``order=3``), an interpolation error of
  order h^4 L'''' for grid spacing h;
* every prior's log-density is tabulated on a fine 1-D grid of 8193 points over its support
  (linear interpolation, error h^2/8 |(log p)''|: below 1e-4 for Paper B's beta and log-normal
  priors; uniform priors exactly);
* one numba kernel runs all ``n_rej`` moves of a particle in one pass (parallel over the
  particles), with the normal and exponential variates drawn beforehand from the sampler's
  numpy generator, so a run is reproducible from its seed on any number of threads.

The sampler uses the table for every value of L (the tempering weights and the moves see one
function), and :meth:`LogTables.check` measures the table against the real L at the final
particles: its largest error, in units of L, is what the result reports (an error of 0.05
changes posterior ratios by 5 %).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import spline_filter

from ...core.parameters import Prior

__all__ = [
    "MAX_TABLE_DIM",
    "LogTables",
    "default_table_points",
    "table_note",
    "table_points",
    "tabulable",
]

FloatArray = NDArray[np.float64]

#: the most inputs a table serves (a grid of n^d values)
MAX_TABLE_DIM = 3
#: cells beyond the prior's box on each side: the spline's support needs one, and the
#: boundary condition of the coefficients (mirror, an O(h^2) error at the grid's edge) decays
#: by a factor 0.268 per cell inward, to 4e-4 of it at the box
_PAD = 6
#: points of the 1-D log-prior tables
_PRIOR_POINTS = 8193


def default_table_points(dim: int) -> int:
    """Grid points per input of the L table: about a million values in all (1-D: 65 537,
    2-D: 1025, 3-D: 101)."""
    return {1: 65537, 2: 1025, 3: 101}[dim]


def table_points(option: int | str, rejuvenate: str, dim: int) -> int | None:
    """Points per input for a sampler from an iterator's ``smc_table`` option: ``"auto"``
    tabulates where the moves cost most (every step) and a table can serve (``dim`` <= 3)."""
    if option == "off":
        return None
    if option == "auto":
        ok = rejuvenate == "every_step" and 1 <= dim <= MAX_TABLE_DIM
        return default_table_points(dim) if ok else None
    return int(option)


def table_note(table: dict[str, Any] | None, tol: float) -> tuple[str, bool]:
    """What a result says of its sampler's table, and whether the table was too coarse (its
    error at the final particles above ``tol``, in units of L)."""
    if not table:
        return "", False
    if "note" in table:
        return f"; SMC without a table ({table['note'].removeprefix('no table: ')})", False
    err = float(table["max_abs_error"])
    text = (
        f"; L tabulated for the SMC ({table['points_per_input']} points per input), its "
        f"largest error at {table['n_checked']} final particles {err:.2g}"
    )
    if not err <= tol:
        return text + f" > smc_table_tol = {tol:g}: raise smc_table or set it 'off'", True
    return text, False


def tabulable(priors: Sequence[Prior]) -> str | None:
    """Why ``priors`` cannot be served by a table (None: they can)."""
    if len(priors) > MAX_TABLE_DIM:
        return f"{len(priors)} inputs (a table serves at most {MAX_TABLE_DIM})"
    for p in priors:
        lo, hi = p.support
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return f"the {p.kind} prior has an unbounded support ({lo}, {hi})"
    return None


@dataclass
class LogTables:
    """L on a grid (cubic B-spline coefficients) and the log-priors on 1-D grids."""

    lower: FloatArray  # (d,) the prior box
    upper: FloatArray
    grid_lower: FloatArray  # (d,) the first grid point (the box less _PAD cells)
    inv_step: FloatArray  # (d,) 1 / grid spacing
    coeffs: FloatArray  # the spline coefficients, shape (n_1, ..., n_d)
    prior_inv_step: FloatArray  # (d,) 1 / spacing of the log-prior grids, which start at lower
    prior_values: FloatArray  # (d, _PRIOR_POINTS) log p_j on its grid (-inf outside)
    points: int
    seconds_build: float

    @classmethod
    def build(
        cls,
        log_likelihood: Callable[[FloatArray], ArrayLike],
        priors: Sequence[Prior],
        points: int,
        chunk: int = 65536,
    ) -> LogTables:
        """Evaluate L on the grid (in chunks of ``chunk`` points) and the log-priors."""
        t0 = time.perf_counter()
        d = len(priors)
        lower = np.array([p.support[0] for p in priors], dtype=float)
        upper = np.array([p.support[1] for p in priors], dtype=float)
        step = (upper - lower) / (points - 1)
        grid_lower = lower - _PAD * step
        n = points + 2 * _PAD
        axes = [grid_lower[j] + step[j] * np.arange(n) for j in range(d)]
        mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
        values = np.empty(len(mesh))
        for start in range(0, len(mesh), chunk):
            part = mesh[start : start + chunk]
            values[start : start + chunk] = np.asarray(log_likelihood(part), dtype=float)
        if not np.all(np.isfinite(values)):
            bad = int((~np.isfinite(values)).sum())
            raise ValueError(f"L is not finite at {bad} of the {len(values)} grid points")
        coeffs = spline_filter(values.reshape((n,) * d), order=3, mode="mirror")
        p_step = (upper - lower) / (_PRIOR_POINTS - 1)
        prior_values = np.empty((d, _PRIOR_POINTS))
        for j, p in enumerate(priors):
            v = lower[j] + p_step[j] * np.arange(_PRIOR_POINTS)
            prior_values[j] = np.nan_to_num(p.logpdf(v), nan=-np.inf)
        return cls(
            lower=lower,
            upper=upper,
            grid_lower=grid_lower,
            inv_step=1.0 / step,
            coeffs=np.ascontiguousarray(coeffs, dtype=float),
            prior_inv_step=1.0 / p_step,
            prior_values=prior_values,
            points=int(points),
            seconds_build=time.perf_counter() - t0,
        )

    @property
    def dim(self) -> int:
        return len(self.lower)

    def log_likelihood(self, x: FloatArray) -> FloatArray:
        """The tabulated L at the rows of ``x`` (-inf outside the prior's box)."""
        x = np.ascontiguousarray(x, dtype=float)
        out = np.empty(len(x))
        from .table_kernels import spline_many

        spline_many(self.coeffs.reshape(-1), self._shape(), self.grid_lower, self.inv_step,
                     self.lower, self.upper, x, out)  # fmt: skip
        return out

    def log_prior(self, x: FloatArray) -> FloatArray:
        """The tabulated log p at the rows of ``x`` (-inf outside the support)."""
        x = np.ascontiguousarray(x, dtype=float)
        out = np.empty(len(x))
        from .table_kernels import prior_many

        prior_many(self.prior_values, self.lower, self.prior_inv_step, x, out)
        return out

    def move(
        self,
        x: FloatArray,
        loglik: FloatArray,
        log_prior: FloatArray,
        factor: FloatArray,
        gamma: float,
        n_moves: int,
        rng: np.random.Generator,
    ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """``n_moves`` Metropolis-Hastings steps for every particle (proposal x + factor z,
        target exp(gamma L) p); returns the moved particles, their L and log p, and the
        acceptance rate."""
        n, d = x.shape
        z = rng.standard_normal((n, n_moves, d))
        e = rng.standard_exponential((n, n_moves))  # -log u of the acceptance test
        x, loglik, log_prior = x.copy(), loglik.copy(), log_prior.copy()
        accepted = np.zeros(n, dtype=np.int64)
        from .table_kernels import moves

        moves(self.coeffs.reshape(-1), self._shape(), self.grid_lower, self.inv_step,
               self.lower, self.upper, self.prior_values, self.prior_inv_step,
               np.ascontiguousarray(factor, dtype=float), z, e, float(gamma), x, loglik,
               log_prior, accepted)  # fmt: skip
        return x, loglik, log_prior, float(accepted.sum()) / (n * max(n_moves, 1))

    def check(
        self, log_likelihood: Callable[[FloatArray], ArrayLike], x: FloatArray
    ) -> dict[str, float]:
        """The table against the real L at the rows of ``x``: largest and RMS error."""
        if len(x) == 0:
            return {"n_checked": 0, "max_abs_error": math.nan, "rmse": math.nan}
        err = self.log_likelihood(x) - np.asarray(log_likelihood(x), dtype=float)
        err = err[np.isfinite(err)]
        return {
            "n_checked": int(len(err)),
            "max_abs_error": float(np.max(np.abs(err))) if len(err) else math.nan,
            "rmse": float(np.sqrt(np.mean(err**2))) if len(err) else math.nan,
        }

    def describe(self) -> dict[str, float]:
        return {"points_per_input": self.points, "seconds_build": self.seconds_build}

    def _shape(self) -> NDArray[np.int64]:
        return np.array(self.coeffs.shape, dtype=np.int64)
