"""``fbia.least_squares``: the Levenberg–Marquardt iterator on a plain residual function.

The front end of :class:`~fbia.iterators.levenberg_marquardt.LevenbergMarquardtIterator`
for ``fun(x) -> r``, in the manner of ``scipy.optimize.least_squares``: it validates ``x0``,
``bounds`` and ``names``, dresses ``fun`` as a problem (:class:`ResidualFunctionProblem`) and
runs the iterator (one algorithm, one place).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import ConfigError, ForwardModelError
from ..core.iteration import Evaluator, drive
from ..core.parameters import Parameter
from ..core.problem import Evaluation
from ..execution.local_executors import SerialEvaluator
from .levenberg_marquardt import LevenbergMarquardtIterator
from .lm.result import LMResult

FloatArray = NDArray[np.float64]

__all__ = ["ResidualFunctionProblem", "least_squares"]

#: Finite-difference step of :func:`least_squares` (a function computed to machine precision).
_SQRT_EPS = float(np.sqrt(np.finfo(float).eps))


class ResidualFunctionProblem:
    """A plain residual function ``fun(x) -> r`` dressed as the problem the iterator expects.

    ``evaluate`` returns an :class:`~fbia.Evaluation`; a function that raises
    :class:`~fbia.ForwardModelError` or returns non-finite values gives a failed evaluation
    (the iterator decides); any other exception propagates (a bug in ``fun``).
    """

    def __init__(
        self,
        fun: Callable[..., ArrayLike],
        names: Sequence[str],
        lower: FloatArray,
        upper: FloatArray,
        args: Sequence[Any] = (),
        kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        self.fun = fun
        self.names = list(names)
        self.lower = lower
        self.upper = upper
        self.args = tuple(args)
        self.kwargs = dict(kwargs or {})
        self.parameters: Sequence[Parameter] = []  # no priors: nothing for run_view to drop
        self.uncertain: Sequence[Parameter] = []

    def evaluate(
        self,
        x: Mapping[str, float],
        workdir: str | Path | None = None,
        index: int = 0,
        keep_solution: bool = True,
    ) -> Evaluation:
        vec = np.array([float(x[n]) for n in self.names])
        ev = Evaluation(index=index, x={n: float(x[n]) for n in self.names})
        try:
            r = np.asarray(self.fun(vec, *self.args, **self.kwargs), dtype=float).ravel()
        except ForwardModelError as exc:
            ev.status, ev.message = "failed", str(exc) or type(exc).__name__
            return ev
        if not np.all(np.isfinite(r)):
            ev.status, ev.message = "failed", "the residual function returned NaN or inf"
            return ev
        ev.residuals = r
        ev.distances = [float(np.linalg.norm(r))]
        return ev


def least_squares(
    fun: Callable[..., ArrayLike],
    x0: ArrayLike,
    bounds: tuple[ArrayLike, ArrayLike] | None = None,
    *,
    args: Sequence[Any] = (),
    kwargs: Mapping[str, Any] | None = None,
    names: Sequence[str] | None = None,
    evaluator: Evaluator | None = None,
    **options: Any,
) -> LMResult:
    """Minimise ½‖fun(x)‖² with the Levenberg–Marquardt iterator of Paper A.

    Parameters
    ----------
    fun
        ``fun(x, *args, **kwargs) -> r``: the residual vector for a parameter vector x.
        Raise :class:`fbia.ForwardModelError` (or return NaN) where it cannot be evaluated.
    x0
        Initial guess, shape (n,); or several, shape (m, n), for a multi-start analysis.
    bounds
        ``(lower, upper)``, scalars or arrays of shape (n,), ``±inf`` for none (as in scipy).
    names
        Parameter names for the result (default ``x0, x1, ...``).
    evaluator
        Evaluator of the runs (default: serial, in this process).
    options
        Options of :class:`LevenbergMarquardtIterator` (``mode``, ``mu0``, ``max_iter``, ...).
        Two defaults differ, because a function computed to machine precision is not a
        forward model solved to a tolerance: the perturbation of eq. 21 is
        ``alpha = 0, beta = √ε ≈ 1.5e-8`` (MINPACK's choice) and, in robust mode, the
        absolute criterion ``eps_grad`` (eq. 29a) is off (``gtol`` is its scale-free
        counterpart; paper mode keeps eq. 29 as it is).

    Returns
    -------
    LMResult
        ``x`` by name, ``x_array`` in order, ``success``, ``status``, ``message``, ``nfev``
        (every call of ``fun``, including those of the finite differences), covariance, ...
    """
    starts = np.asarray(x0, dtype=float)
    if starts.ndim == 1:
        starts = starts[None, :]
    if starts.ndim != 2 or starts.shape[1] == 0:
        raise ConfigError(f"x0 must have shape (n,) or (m, n), got {np.shape(x0)}", "least_squares")
    n = starts.shape[1]
    labels = [f"x{i}" for i in range(n)] if names is None else [str(k) for k in names]
    if len(labels) != n or len(set(labels)) != n:
        raise ConfigError(f"names must be {n} distinct names, got {labels}", "least_squares")
    lower, upper = _bounds(bounds, n)
    if "x0" in options:
        raise ConfigError(
            "give the initial guess as the argument x0, not as an option", "least_squares"
        )
    defaults: dict[str, Any] = {"alpha": 0.0, "beta": _SQRT_EPS}
    if options.get("mode", "robust") == "robust":
        defaults["eps_grad"] = 0.0
    opts = {**defaults, **options}
    guesses = [dict(zip(labels, map(float, row), strict=True)) for row in starts]
    opts["x0"] = guesses[0] if len(guesses) == 1 else guesses
    iterator = LevenbergMarquardtIterator(
        LevenbergMarquardtIterator.Options.parse(opts, where="least_squares")
    )
    problem = ResidualFunctionProblem(fun, labels, lower, upper, args, kwargs)
    if evaluator is not None:
        return cast(LMResult, drive(iterator, problem, evaluator))
    with SerialEvaluator() as own:
        return cast(LMResult, drive(iterator, problem, own))


def _bounds(bounds: tuple[ArrayLike, ArrayLike] | None, n: int) -> tuple[FloatArray, FloatArray]:
    if bounds is None:
        return np.full(n, -np.inf), np.full(n, np.inf)
    try:
        lo, hi = bounds
        lower = np.broadcast_to(np.asarray(lo, dtype=float), (n,)).copy()
        upper = np.broadcast_to(np.asarray(hi, dtype=float), (n,)).copy()
    except (TypeError, ValueError):
        raise ConfigError(
            f"bounds must be (lower, upper) with scalars or {n} values each", "least_squares"
        ) from None
    if np.any(np.isnan(lower)) or np.any(np.isnan(upper)) or np.any(lower >= upper):
        raise ConfigError(
            f"bounds need lower < upper for every parameter, got {lower.tolist()} and "
            f"{upper.tolist()}",
            "least_squares",
        )
    return lower, upper
