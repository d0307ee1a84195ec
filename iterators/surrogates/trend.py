"""A concave quadratic trend under the GP of L: how the surrogate extrapolates.

A GP with a constant prior mean falls back to that constant one length scale away from the
data (Paper B Remark 10 puts it below every training value). Where a posterior is a long or
tilted ridge (E against the inflow rate, whose ratio is all the data see), the surrogate then
ends the ridge wherever the runs end, and the posterior comes out too narrow. A log-likelihood
is concave near its maximum, so the prior mean here is a concave quadratic fitted to the runs
near the top (least squares on all d (d + 3) / 2 + 1 terms, cross terms included so that a
tilted ridge is followed; its Hessian projected onto the negative definite matrices); the GP
models what the quadratic misses. Far from the data the surrogate then falls off like a
Gaussian log-likelihood instead of jumping to a constant. This is the "negative quadratic"
prior mean of GP surrogates of log-densities (Acerbi 2018, VBMC, which uses a diagonal one).

>>> import numpy as np
>>> from fbia.iterators.surrogates.trend import QuadraticTrend
>>> x = np.random.default_rng(0).random((40, 2))
>>> y = -((x[:, 0] - 0.3) ** 2) / 0.02 - ((x[:, 1] - 0.6) ** 2) / 0.05
>>> trend = QuadraticTrend.fit(x, y)
>>> bool(np.allclose(trend(x), y))
True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: the training points the quadratic is fitted to: those within this many units of L of the
#: best one (at least 3 per coefficient; else the best ones)
TOP = 30.0
#: the least curvature kept in any direction, relative to the largest (negative definite)
MIN_CURVATURE = 1e-6


@dataclass(frozen=True)
class QuadraticTrend:
    """m(x) = c + g.u + u^T H u / 2 with u = (x - center) / scale and H negative definite."""

    center: FloatArray
    scale: FloatArray
    c: float
    g: FloatArray
    h: FloatArray

    def __call__(self, x: FloatArray) -> FloatArray:
        u = (np.atleast_2d(np.asarray(x, dtype=float)) - self.center) / self.scale
        return np.asarray(self.c + u @ self.g + 0.5 * np.einsum("ij,jk,ik->i", u, self.h, u))

    @classmethod
    def fit(cls, x: FloatArray, y: FloatArray) -> QuadraticTrend:
        """Least squares on the top runs (module docstring), then the Hessian made negative
        definite and the constant and linear terms refitted with it fixed."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        y = np.asarray(y, dtype=float)
        n, d = x.shape
        n_coef = 1 + d + d * (d + 1) // 2
        order = np.argsort(-y)
        top = order[: max(int(np.sum(y >= y.max() - TOP)), min(n, 3 * n_coef))]
        center = x[top].mean(axis=0)
        scale = x[top].std(axis=0)
        scale[scale == 0] = 1.0
        u = (x[top] - center) / scale
        iu, ju = np.triu_indices(d)
        quad = u[:, iu] * u[:, ju]
        a = np.column_stack([np.ones(len(top)), u, quad])
        coef = np.linalg.lstsq(a, y[top], rcond=None)[0]
        h = np.zeros((d, d))
        h[iu, ju] = coef[1 + d :]
        h = h + h.T  # diagonal doubled: u^T H u / 2 = sum_i<=j coef_ij u_i u_j
        vals, vecs = np.linalg.eigh(h)
        floor = MIN_CURVATURE * max(float(np.max(np.abs(vals))), 1e-12)
        h = (vecs * np.minimum(vals, -floor)) @ vecs.T
        rest = y[top] - 0.5 * np.einsum("ij,jk,ik->i", u, h, u)
        lin = np.linalg.lstsq(np.column_stack([np.ones(len(top)), u]), rest, rcond=None)[0]
        return cls(center, scale, float(lin[0]), lin[1:], h)

    def state(self) -> dict[str, Any]:
        return {"center": self.center, "scale": self.scale, "c": self.c, "g": self.g, "h": self.h}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> QuadraticTrend:
        return cls(
            np.asarray(state["center"], dtype=float),
            np.asarray(state["scale"], dtype=float),
            float(state["c"]),
            np.asarray(state["g"], dtype=float),
            np.asarray(state["h"], dtype=float),
        )
