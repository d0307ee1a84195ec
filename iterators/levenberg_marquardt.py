"""Levenberg–Marquardt inverse analysis (Paper A eq. 16-29), on a problem or a plain function.

On an inverse problem (the residual vector r of eq. 19 comes from the measure, over all
observations)::

    import fbia
    lm = fbia.iterator("levenberg_marquardt", x0=[{"E": 200.0, "nu": 0.4},
                                                  {"E": 600.0, "nu": 0.0}])
    with fbia.ProcessPoolEvaluator(workers=3) as ev:      # the n_x + 1 runs of a Jacobian
        result = lm.run(problem, ev)                       # run side by side
    print(result.summary())                               # optimum, std. errors, correlation,
    lm.write_plots(result, problem, "output")             # AIC/BIC, multi-start table

    for state in (gen := lm.steps(problem, ev)):           # or step by step
        print(state)
        if state.nfev > 200:
            result = lm.stop(gen)                          # partial result, status "stopped"
            break

On a plain residual function, like ``scipy.optimize.least_squares`` (same iterator):

>>> import numpy as np, fbia
>>> t = np.linspace(0.0, 4.0, 20)
>>> y = 3.0 * np.exp(-0.7 * t)
>>> res = fbia.least_squares(lambda b: b[0] * np.exp(-b[1] * t) - y, [1.0, 1.0],
...                          bounds=([0.0, 0.0], [10.0, 5.0]))
>>> res.success, np.round(res.x_array, 8).tolist()
(True, [3.0, 0.7])

``mode="paper"`` runs the algorithm exactly as Paper A describes it (including its known
weaknesses: it can stall on a bound and gives no result when a forward run fails);
``mode="robust"`` (default) is the improved variant described in
:mod:`fbia.iterators.lm.chains`.

Status tags of the result (``success`` is True for the first three):

``unreliable``          converged, but a parameter is at a bound or the residuals are
                        inconsistent with the stated noise (chi-square test,
                        :mod:`fbia.iterators.lm.fit_quality`): ``success`` False, as for a
                        ``gp_smc`` result so flagged; the message names the cause,
                        ``info["convergence"]`` keeps the tag below, ``fbia run`` exits 3.
                        Calibrations only: on a plain residual function an active bound is
                        a constrained optimum (``result.quality.at_bound``, as scipy's
                        ``active_mask``)

``converged_gradient``  err_grad < eps_grad (eq. 29a), or r ⟂ J within gtol (robust)
``converged_residual``  err_res < eps_res (eq. 29b), or ‖r‖² stopped decreasing (ftol, robust)
``converged_step``      no step larger than xtol reduces err_res (robust)
``plateau``             robust: converged only because a column of J vanished (the residuals
                        stopped depending on a parameter), from both first trust regions
``iteration_limit``     max_iter iterations (eq. 29c); x is the best iterate
``damping_limit``       paper: μ > μ0·mu_limit, no result; robust: the steps shrank to nothing
                        because the runs fail there, x is the best point found
``run_failed``          paper: a forward run failed, no result (Paper A, "Deterministic
                        character")
``singular``            paper: JᵀJ + μ diag(JᵀJ) is singular, no result
``start_failed``        robust: the run at the initial guess failed
``all_failed``          every forward run failed
``evaluation_limit``    max_nfev runs; ``stopped``: :meth:`LevenbergMarquardtIterator.stop`
``plugin_error``        a plugin raised an unexpected exception (a bug, never retried)
``no_result``           multi-start: no start gave a result, for different reasons
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Generator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..core.errors import ConfigError
from ..core.iteration import Evaluator, IteratorBase
from ..core.options import settings_from
from ..core.problem import Evaluation, InverseProblem, ProblemLike
from .lm.chains import LMChain, LMSettings, Outcome, PaperChain, err_res_of
from .lm.fit_quality import fit_quality
from .lm.handoff import POSTERIOR_LABELS
from .lm.options import LMOptions
from .lm.result import FitStatistics, LMResult, LMState, compare_starts
from .lm.robust import RobustChain
from .tangents import TangentProblem

FloatArray = NDArray[np.float64]


#: Options that only the robust mode knows.
class _StopRequested(Exception):
    """Thrown into a running :meth:`LevenbergMarquardtIterator.steps` by its ``stop``."""


class LevenbergMarquardtIterator(IteratorBase):
    """Levenberg–Marquardt optimisation of the least-squares objective (Paper A eq. 16).

    Each iteration evaluates the forward model at x and at n_x perturbed points
    (eq. 21-23, one batch for the evaluator), computes the step of eq. 18 and stops on
    eq. 29a-c.  Several initial guesses run as independent chains whose batches share the
    evaluator; the result compares their optima.  See :mod:`fbia.iterators.lm.chains` for the
    ``paper`` and ``robust`` modes.
    """

    #: the class of its results (fbia.load_result reads them back as it)
    result_type = LMResult

    Options = LMOptions

    options: LMOptions

    # -- the iteration ----------------------------------------------------------------------
    def steps(
        self, problem: ProblemLike, evaluator: Evaluator
    ) -> Generator[LMState, None, LMResult]:
        """Run the chains; yield an :class:`LMState` after every batch; return the result.

        ``problem`` is an :class:`~fbia.InverseProblem` (or anything with ``names``,
        ``lower``, ``upper``, ``parameters``, ``uncertain`` and ``evaluate``).
        """
        names = list(problem.names)
        lower = np.asarray(problem.lower, dtype=float)
        upper = np.asarray(problem.upper, dtype=float)
        extra = self._uncertain_inputs(problem)
        starts = self._starts(problem, names, lower, upper)
        jacobian = self._jacobian_kind(problem, names)
        stated = problem  # its noise levels judge the fit (lm.fit_quality)
        if jacobian == "tangent":
            problem = TangentProblem.of(problem, names)  # type: ignore[arg-type]
        settings = self._settings(names, jacobian)
        kind = PaperChain if settings.mode == "paper" else RobustChain
        chains: list[LMChain] = [
            kind(i, x, lower, upper, settings, names) for i, x in enumerate(starts)
        ]
        gens = {c.index: c.run() for c in chains}
        pending = {i: next(g) for i, g in gens.items()}
        evaluations: list[Evaluation] = []
        n_r: int | None = None
        rounds = 0
        try:
            while pending:
                order = list(pending.items())
                points = [p for _, batch in order for p in batch]
                inputs = [{**dict(zip(names, map(float, p), strict=True)), **extra} for p in points]
                records = evaluator.evaluate(problem, inputs)
                evaluations.extend(records)
                bug = next((e for e in records if e.status == "error"), None)
                if bug is not None:
                    for c in chains:
                        c.finish(
                            "plugin_error", f"a plugin raised an unexpected error: {bug.message}"
                        )
                    break
                for e in records:
                    if e.ok and e.residuals is not None:
                        if n_r is None:
                            n_r = len(e.residuals)
                        elif len(e.residuals) != n_r:
                            raise ConfigError(
                                f"the residual vector changed length from {n_r} to "
                                f"{len(e.residuals)} between runs; Levenberg-Marquardt needs the "
                                "same residuals r (eq. 19) in every run"
                            )
                pos = 0
                for idx, batch in order:
                    outs = [_outcome(e, names) for e in records[pos : pos + len(batch)]]
                    pos += len(batch)
                    try:
                        pending[idx] = gens[idx].send(outs)
                    except StopIteration:
                        del pending[idx]
                rounds += 1
                budget = self.options.max_nfev
                if pending and budget is not None and len(evaluations) >= budget:
                    for idx in pending:
                        chains[idx].finish(
                            "evaluation_limit",
                            f"evaluation limit: {len(evaluations)} forward runs >= max_nfev = "
                            f"{budget}",
                        )
                    break
                try:
                    yield self._state(rounds, evaluations, chains)
                except _StopRequested:
                    for idx in pending:
                        chains[idx].finish("stopped", "stopped on request")
                    break
        finally:
            for g in gens.values():
                g.close()
        self.result = self._result(chains, evaluations, settings, stated)
        return self.result

    def stop(self, gen: Generator[LMState, None, LMResult]) -> LMResult:
        """End a running :meth:`steps` generator and return its partial result ("stopped")."""
        state = inspect.getgeneratorstate(gen)
        if state == inspect.GEN_CREATED:
            gen.close()
            self.result = LMResult(
                status="stopped",
                success=False,
                message="stopped before the first evaluation",
                iterator="levenberg_marquardt",
            )
            return self.result
        if state == inspect.GEN_CLOSED:
            if self.result is None:
                raise RuntimeError("the LM generator ended without a result")
            assert isinstance(self.result, LMResult)
            return self.result
        try:
            gen.throw(_StopRequested())
        except StopIteration as done:
            self.result = done.value
            return done.value
        raise RuntimeError("the LM generator did not stop")  # pragma: no cover

    def write_plots(self, result: LMResult, problem: Any, folder: str | Path) -> list[Path]:
        """Search paths and error histories as PNG files (see :func:`plot_lm_result`)."""
        from .lm.plots import plot_lm_result

        return plot_lm_result(result, problem, folder)

    # -- set-up ---------------------------------------------------------------------------------
    def _uncertain_inputs(self, problem: Any) -> dict[str, float]:
        where = "levenberg_marquardt"
        unc = [p.name for p in getattr(problem, "uncertain", ())]
        given = dict(self.options.uncertain_values or {})
        missing = [n for n in unc if n not in given]
        if missing:
            raise ConfigError(
                f"the problem has uncertain parameter(s) {', '.join(missing)}, which "
                "Levenberg-Marquardt cannot treat (it fits x only): hold them at values with "
                "the option uncertain_values or make them fixed inputs",
                where,
            )
        unknown = [n for n in given if n not in unc]
        if unknown:
            raise ConfigError(
                f"uncertain_values names {', '.join(unknown)}, which are not uncertain "
                f"parameters of the problem (those are: {', '.join(unc) or 'none'})",
                where,
            )
        return {n: float(given[n]) for n in unc}

    def _starts(
        self, problem: Any, names: list[str], lower: FloatArray, upper: FloatArray
    ) -> list[FloatArray]:
        x0 = self.options.x0
        if self.options.x0_from_starts is not None:
            x0 = self.options.x0_from_starts
        if x0 is None:
            params = list(getattr(problem, "parameters", ()))
            missing = [p.name for p in params if p.initial is None]
            if missing or not params:
                raise ConfigError(
                    f"no initial guess for {', '.join(missing) or 'the parameters'}: give the "
                    "option x0 or Parameter(initial=...)",
                    "levenberg_marquardt",
                )
            guesses = [{p.name: float(p.initial) for p in params}]
            labels = ["initial"]
        elif isinstance(x0, dict):
            guesses, labels = [x0], ["x0"]
        else:
            guesses, labels = list(x0), [f"x0[{k}]" for k in range(len(x0))]
        out = []
        for guess, where in zip(guesses, labels, strict=True):
            where = f"levenberg_marquardt.{where}"
            missing = [n for n in names if n not in guess]
            unknown = [k for k in guess if k not in names]
            if missing:
                raise ConfigError(f"no value for parameter(s) {', '.join(missing)}", where)
            if unknown:
                raise ConfigError(
                    f"unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(names)}", where
                )
            x = np.array([float(guess[n]) for n in names])
            for i, n in enumerate(names):
                if not (math.isfinite(x[i]) and lower[i] <= x[i] <= upper[i]):
                    raise ConfigError(
                        f"initial guess {n} = {x[i]} lies outside the bounds "
                        f"[{lower[i]}, {upper[i]}]",
                        where,
                    )
            out.append(x)
        return out

    def _jacobian_kind(self, problem: Any, names: list[str]) -> str:
        """How J is computed (option ``jacobian``): ``"auto"`` is ``"tangent"`` in robust mode
        when the problem's model gives tangents for every parameter, else ``"forward"``."""
        o = self.options
        if o.mode == "paper":
            return "forward"
        if o.jacobian != "auto":
            if o.jacobian == "tangent" and not isinstance(problem, InverseProblem):
                raise ConfigError(
                    "jacobian = 'tangent' needs an InverseProblem whose forward model gives "
                    "tangents",
                    "levenberg_marquardt: jacobian",
                )
            return o.jacobian
        if not isinstance(problem, InverseProblem):  # fbia.least_squares: a plain function
            return "forward"
        return "tangent" if set(names) <= set(problem.model.tangent_inputs()) else "forward"

    def _settings(self, names: list[str], jacobian: str = "forward") -> LMSettings:
        o = self.options
        if isinstance(o.alpha, dict):
            unknown = [k for k in o.alpha if k not in names]
            if unknown:
                raise ConfigError(
                    f"alpha names unknown parameter(s) {', '.join(unknown)}; valid: "
                    f"{', '.join(names)}",
                    "levenberg_marquardt",
                )
            default = type(o).model_fields["alpha"].default
            alpha = np.array([float(o.alpha.get(n, default)) for n in names])
        else:
            alpha = np.full(len(names), float(o.alpha))
        mu0 = o.mu0 if o.mu0 is not None else (1.0 if o.mode == "paper" else 1e-2)
        return settings_from(o, LMSettings, alpha=alpha, mu0=mu0, jacobian=jacobian)

    # -- reporting --------------------------------------------------------------------------------
    @staticmethod
    def _state(rounds: int, evaluations: list[Evaluation], chains: list[LMChain]) -> LMState:
        return LMState(
            round=rounds,
            nfev=len(evaluations),
            n_failed=sum(not e.ok for e in evaluations),
            chains=[
                {
                    "start": c.index + 1,
                    "iteration": c.iterations,
                    "x": None if c.x is None else dict(zip(c.names, map(float, c.x), strict=True)),
                    "err_res": c.err_res,
                    "err_grad": c.err_grad,
                    "mu": c.mu,
                    "status": c.status,
                }
                for c in chains
            ],
        )

    def _result(
        self,
        chains: list[LMChain],
        evaluations: list[Evaluation],
        settings: LMSettings,
        problem: ProblemLike | None = None,
    ) -> LMResult:
        names = list(chains[0].names)
        rows: list[dict[str, Any]] = []
        for c in chains:
            has_x = c.x is not None and c.r is not None
            x = (
                dict(zip(names, map(float, c.x), strict=True))
                if c.x is not None and has_x
                else None
            )
            at_bound = (
                [n for i, n in enumerate(names) if c.x[i] in (c.lower[i], c.upper[i])]
                if c.x is not None
                else []
            )
            rows.append(
                {
                    "start": c.index + 1,
                    "x0": dict(zip(names, map(float, c.x0), strict=True)),
                    "status": c.status,
                    "success": c.success,
                    "message": c.message,
                    "x": x,
                    "err_res": c.err_res if has_x else None,
                    "err_grad": c.err_grad if has_x else None,
                    "mu": c.mu,
                    "iterations": c.iterations,
                    "nfev": c.nfev,
                    "n_failed": c.n_failed,
                    "at_bound": at_bound,
                }
            )
        best, warnings = compare_starts(
            rows, names, settings.typical, self.options.fit_rtol, self.options.agree_rtol
        )
        nfev = len(evaluations)
        n_failed = sum(not e.ok for e in evaluations)
        history = [h for c in chains for h in c.history]
        common: dict[str, Any] = {
            "nfev": nfev,
            "n_failed": n_failed,
            "iterator": "levenberg_marquardt",
            "history": history,
            "evaluations": evaluations,
            "names": names,
            "starts": rows,
            "warnings": warnings,
            "info": {
                "mode": settings.mode,
                "jacobian": settings.jacobian,
                "jacobians": {
                    k: sum(c.j_sources.get(k, 0) for c in chains)
                    for k in ("tangent", "forward", "central")
                },
                "options": self.options.model_dump(),
            },
        }
        labels = self.options.x0_labels or (
            list(POSTERIOR_LABELS) if self.options.x0_from is not None else None
        )
        if labels:  # e.g. Bayes -> LM: say which start was which
            common["info"]["start_labels"] = list(labels)
            for row, label in zip(rows, labels, strict=False):
                row["label"] = label
        if best is None:
            if nfev > 0 and n_failed == nfev:
                status = "all_failed"
                message = f"all {nfev} forward runs failed; first: {evaluations[0].message}"
            elif len({c.status for c in chains}) == 1:
                status = chains[0].status
                message = (
                    chains[0].message
                    if len(chains) == 1
                    else (f"no start gave a result: {chains[0].message}")
                )
            else:
                status = "no_result"
                message = "no start gave a result: " + "; ".join(
                    f"start {c.index + 1}: {c.message}" for c in chains
                )
            if len(chains) == 1 and chains[0].x_last is not None:
                common["info"]["x_last"] = dict(
                    zip(names, map(float, chains[0].x_last), strict=True)
                )
            iterations = chains[0].iterations if len(chains) == 1 else 0
            return LMResult(
                status=status, success=False, message=message, iterations=iterations, **common
            )
        c = chains[best]
        assert c.x is not None and c.r is not None and c.J is not None and c.jac_x is not None
        message = c.message
        if len(chains) > 1:
            n_ok = sum(r["success"] for r in rows)
            message = f"{n_ok} of {len(chains)} starts converged; best: start {best + 1}: {message}"
        n_r, n_x = c.J.shape
        if n_r < n_x:
            warnings.append(
                f"only {n_r} residual(s) for {n_x} parameters: the optimum is not determined "
                "and there is no covariance; use a measure with a residual vector (eq. 19), "
                "e.g. ray or cpp"
            )
        if warnings:
            message += " - WARNING: " + "; ".join(warnings)
        stats = FitStatistics.of(c.J, c.r)
        # the verdict on the optimum: a parameter at a bound, residuals against the stated
        # noise (chi-square); either makes the status "unreliable" (lm/fit_quality.py)
        record = next(
            (
                e
                for e in reversed(evaluations)
                if e.ok and e.residuals is not None and np.array_equal(e.residuals, c.r)
            ),
            None,
        )
        quality = fit_quality(names, c.x, c.lower, c.upper, problem, record)
        status, success = c.status, c.success
        # on a calibration (an InverseProblem) the bounds are the range the parameters may
        # take; on a plain residual function (fbia.least_squares) they are constraints of the
        # problem, an active one a constrained optimum as in scipy (quality records it)
        if quality.causes and isinstance(problem, InverseProblem):
            message = "; ".join(quality.causes) + " - " + message
            status = "unreliable" if c.success else c.status
            success = False
        common["info"]["convergence"] = c.status
        # standard errors: none for a parameter at a bound (the Gauss-Newton covariance
        # assumes an interior optimum) or from a start that never moved (no optimum)
        stderr = None
        if stats.stderr is not None and c.iterations > 0:
            stderr = {
                n: float(se)
                for n, se in zip(names, stats.stderr, strict=True)
                if n not in quality.at_bound
            }
        return LMResult(
            status=status,
            success=success,
            message=message,
            x=rows[best]["x"],
            err_res=c.err_res,
            err_grad=c.err_grad,
            mu=c.mu,
            iterations=c.iterations,
            residuals=c.r,
            jac=c.J,
            jac_x=dict(zip(names, map(float, c.jac_x), strict=True)),
            sigma2=stats.sigma2,
            cov=stats.cov,
            corr=stats.corr,
            stderr=stderr,
            cov_rank=stats.cov_rank,
            aic=stats.aic,
            bic=stats.bic,
            quality=quality,
            **common,
        )


def _outcome(e: Evaluation, names: list[str]) -> Outcome:
    if e.ok and e.residuals is not None:
        tangent = e.jacobian if e.jacobian_names == tuple(names) else None
        return Outcome(np.asarray(e.residuals, dtype=float), jacobian=tangent)
    return Outcome(None, f"{e.status}: {e.message}")


__all__ = ["LMResult", "LMState", "LevenbergMarquardtIterator", "err_res_of"]
