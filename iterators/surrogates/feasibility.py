"""Where the forward model runs: a GP classifier of the design's failed runs.

A surrogate of L is trained on the runs that succeeded. Where the forward model fails (the
ALE mesh of a very soft biofilm tangles, Paper B Figs. 5-8: the grey crosses) it has no
data, and a GP interpolating across the failing region can put posterior mass there; Paper B
example 8 (6 + 1-D) did exactly that in fbia before this module: 7-8 of 8 check runs at
posterior draws failed. A parameter at which the model produces no state cannot have
produced the observed interface, so the posterior should stay where the model runs.

:class:`Feasibility` is GPy's GP classifier (Bernoulli likelihood with probit link,
expectation propagation; Rasmussen & Williams 2006, Sect. 3.6; the constraint classifier of
Gelbart et al. 2014, docs/references.md) with a Matérn 5/2 ARD kernel
on the outcomes ok / failed of the training runs, in the unit box of their inputs. With mu(x)
the posterior mean of its latent function, the SMC target gets the factor

    c(x) = min(1, 2 Phi(mu(x))),    log c = min(0, log 2 Phi(mu))

(:meth:`Feasibility.log_factor`): no penalty where the model is at least as likely to run as
to fail, nor away from every run, where the classifier knows nothing and mu reverts to 0;
inside the failing region c falls to 0 with the classifier's confidence. (Phi(mu) rather than
the predictive probability Phi(mu / sqrt(1 + s^2)): the variance costs O(m^2) per particle
and only moves the factor's steepness, not where it starts.) The factor belongs to the prior
side of the posterior (a region excluded, not evidence weighed): gp_smc adds it to the SMC's
log-likelihood, so particles carry it, and :mod:`fbia.iterators.surrogates.uncertainty` divides it
back out before it reweights by the GP's sample paths.

Cost: expectation propagation is O(n^3); the classifier is fitted on at most
:data:`MAX_POINTS` runs, every failed run (a random subset when there are more than half of
that) and the successful runs nearest to a failure (which place the boundary; far from it the
factor is 1 anyway). 600 of 2100 runs in 7-D: about 7 s (2 cores, shared). Predictions use
the fitted posterior (GPy's Woodbury vector) in numpy, so a restored result needs no GPy.

>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> x = rng.random((200, 2))
>>> f = Feasibility.fit(x, x[:, 0] > 0.3)        # the model fails for x_0 < 0.3
>>> np.round(f.log_factor(np.array([[0.8, 0.5], [0.05, 0.5]])), 1)   # runs / fails
array([ 0. , -4.4])
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from scipy.special import log_ndtr

FloatArray = NDArray[np.float64]

#: Largest number of runs the classifier is fitted on (EP is O(n^3): 600 runs in 7-D, about 7 s).
MAX_POINTS = 600
#: log P_ok is not taken below this (P_ok = 1e-300 is as good as zero for SMC).
LOG_FLOOR = -690.0
#: Points per block of the kernel matrix in predictions (CHUNK x MAX_POINTS floats).
CHUNK = 4096
LOG2 = math.log(2.0)


@dataclass(frozen=True)
class Feasibility:
    """The fitted classifier: its training inputs (unit box), Matérn 5/2 hyperparameters and
    the EP posterior's Woodbury vector (GPy's ``posterior.woodbury_vector``: the latent mean is
    k(x, X) @ it)."""

    lower: FloatArray  # (d,) the unit box of the inputs
    upper: FloatArray
    x: FloatArray  # (m, d) training inputs in the unit box
    lengthscales: FloatArray  # (d,)
    variance: float
    woodbury_vector: FloatArray  # (m,)
    n_runs: int  # runs the design had
    n_failed: int  # of which failed

    @classmethod
    def fit(cls, x: ArrayLike, ok: ArrayLike, max_points: int = MAX_POINTS) -> Feasibility:
        """Fit on the runs at the rows of ``x`` with outcomes ``ok`` (both classes needed)."""
        import GPy  # noqa: PLC0415  (heavy; only where a design had failed runs)

        x = np.asarray(x, dtype=float)
        ok = np.asarray(ok, dtype=bool)
        if ok.all() or not ok.any():
            raise ValueError("the classifier needs failed and successful runs")
        lower, upper = x.min(axis=0), x.max(axis=0)
        u = (x - lower) / np.where(upper > lower, upper - lower, 1.0)
        keep = _subset(u, ok, max_points)
        kernel = GPy.kern.Matern52(x.shape[1], ARD=True, lengthscale=0.2)
        # GPy's EP sweeps the sites in an order drawn from numpy's global generator: seed it
        # (the same fit every time) and give the caller its state back
        global_state = np.random.get_state()  # noqa: NPY002 (restored, not used)
        try:
            np.random.seed(0)  # noqa: NPY002
            model = GPy.models.GPClassification(u[keep], ok[keep, None].astype(float), kernel)
            model.optimize(messages=False, max_iters=200)
        finally:
            np.random.set_state(global_state)  # noqa: NPY002
        post = model.posterior
        return cls(
            lower=lower,
            upper=upper,
            x=u[keep],
            lengthscales=np.atleast_1d(np.asarray(kernel.lengthscale, dtype=float)).copy(),
            variance=float(kernel.variance[0]),
            woodbury_vector=np.asarray(post.woodbury_vector, dtype=float).ravel(),
            n_runs=len(ok),
            n_failed=int((~ok).sum()),
        )

    def latent_mean(self, z: ArrayLike) -> FloatArray:
        """The latent function's posterior mean at the rows of ``z`` (original units)."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        u = (z - self.lower) / np.where(self.upper > self.lower, self.upper - self.lower, 1.0)
        out = np.empty(len(u))
        for start in range(0, len(u), CHUNK):
            rows = slice(start, start + CHUNK)
            out[rows] = self._kernel(u[rows]) @ self.woodbury_vector
        return out

    def log_factor(self, z: ArrayLike) -> FloatArray:
        """log c = min(0, log 2 Phi(mu)): the factor of the SMC target (see the module)."""
        return np.minimum(0.0, np.maximum(log_ndtr(self.latent_mean(z)), LOG_FLOOR) + LOG2)

    def _kernel(self, u: FloatArray) -> FloatArray:
        """Matérn 5/2 with ARD lengthscales (GPy.kern.Matern52) between ``u`` and the
        training inputs, (n, m)."""
        a, b = u / self.lengthscales, self.x / self.lengthscales
        r2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * (a @ b.T)
        s = np.sqrt(5.0 * np.maximum(r2, 0.0))
        return self.variance * (1.0 + s + s * s / 3.0) * np.exp(-s)

    @property
    def dim(self) -> int:
        """Number of inputs the classifier takes (the leading columns of a particle)."""
        return int(self.x.shape[1])

    def describe(self) -> dict[str, Any]:
        """What the result records about the classifier."""
        return {
            "n_runs": self.n_runs,
            "n_failed": self.n_failed,
            "n_fitted": len(self.x),
            "lengthscales": [float(v) for v in self.lengthscales],
            "variance": self.variance,
        }

    def state(self) -> dict[str, Any]:
        """Arrays and numbers that :meth:`from_state` rebuilds the classifier from."""
        return {
            "lower": self.lower,
            "upper": self.upper,
            "x": self.x,
            "lengthscales": self.lengthscales,
            "variance": self.variance,
            "woodbury_vector": self.woodbury_vector,
            "n_runs": self.n_runs,
            "n_failed": self.n_failed,
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> Feasibility:
        arrays = ("lower", "upper", "x", "lengthscales", "woodbury_vector")
        return cls(
            **{k: np.asarray(state[k], dtype=float) for k in arrays},
            variance=float(state["variance"]),
            n_runs=int(state["n_runs"]),
            n_failed=int(state["n_failed"]),
        )


def fit_feasibility(x: ArrayLike, ok: ArrayLike) -> Feasibility | None:
    """The classifier of the runs at ``x`` with outcomes ``ok``; None when no run failed or
    none succeeded (nothing to classify)."""
    ok = np.asarray(ok, dtype=bool)
    if ok.all() or not ok.any():
        return None
    return Feasibility.fit(x, ok)


def feasibility_summary(f: Feasibility | None) -> dict[str, Any]:
    """The classifier in a surrogate's summary (``feasibility_*`` keys; none without one)."""
    return {} if f is None else {f"feasibility_{k}": v for k, v in f.describe().items()}


def feasibility_note(f: Feasibility | None) -> str:
    """The classifier in a result's message ("" without one)."""
    if f is None:
        return ""
    return (
        f"; {f.n_failed} of {f.n_runs} design runs failed: a GP classifier of them keeps the "
        "posterior where the forward model runs (failures = 'classify')"
    )


def _subset(u: FloatArray, ok: NDArray[np.bool_], max_points: int) -> NDArray[np.intp]:
    """At most ``max_points`` runs: the failed ones (a seeded random half at most) and the
    successful runs nearest to a failure."""
    failed, good = np.flatnonzero(~ok), np.flatnonzero(ok)
    if len(ok) <= max_points:
        return np.arange(len(ok))
    rng = np.random.default_rng(0)
    if len(failed) > max_points // 2:
        failed = np.sort(rng.choice(failed, max_points // 2, replace=False))
    distance, _ = cKDTree(u[failed]).query(u[good])
    good = good[np.argsort(distance, kind="stable")[: max_points - len(failed)]]
    return np.sort(np.concatenate([failed, good]))
