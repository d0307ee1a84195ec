"""The surrogate's check at posterior draws, and the repair of a check that failed.

After SMC on the surrogate, ``gp_smc`` runs the forward model at ``n_check`` distinct
posterior draws and measures the surrogate's error there in units of L (an error of order 1
changes posterior ratios by a factor e); a spread of the errors (their standard deviation: a
constant error cancels in the posterior) not below
:data:`~fbia.iterators.gp_smc.result.RELIABLE_RMSE` makes the result ``unreliable``.

The GP's own uncertainty is checked too (:mod:`fbia.iterators.surrogates.uncertainty`): when
the posterior averaged over its sample paths differs from the posterior, the GP puts mass
where no run has been, and only runs can say whether it is there. With the adaptive design
and budget left, ``n_check`` runs at draws of that averaged posterior join the design as a
repair (below) instead of ending the study as ``unreliable`` at once.

A check that fails has found where the surrogate is wrong inside the posterior, and its runs
are the most informative ones the design could get: with the adaptive design and budget left
(``n_train``), they join the training runs, the surrogate is refitted, SMC is run again and a
fresh check is drawn, at most ``check_repairs`` times. The result says how many repairs were
made and what the failed checks measured; only the last check decides the status, so a
repaired posterior is judged by runs it was not trained on, as every other. The fixed Sobol
design (Paper B's procedure) is never repaired. Measured with ``benchmarks/
bench_bayes_checks.py`` (issue 30): at the default budgets 1 right posterior of 15 said
``unreliable`` because its 8 check draws had a RMSE of 1.06 in L.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from ...core.problem import Evaluation
from ..smc.sampler import SmcResult
from ..surrogates.residuals import Surrogate
from .adaptive import distinct_draws
from .result import PosteriorCheck
from .run import Design, GpSmcState, SmcRun


@dataclass(frozen=True)
class CheckRuns:
    """A check and its forward runs' records (one per row of ``check.x``), which join the
    design when the check is repaired (:meth:`~.run.Design.extended`)."""

    check: PosteriorCheck
    records: tuple[Evaluation, ...]

    def repaired(self, design: Design) -> Design:
        """``design`` with the check's runs appended as training runs."""
        return design.extended(self.check.x, self.check.log_likelihood, self.records)


def posterior_check(
    run: SmcRun, post: SmcResult, gp: Surrogate, n_check: int, rng: np.random.Generator
) -> Generator[GpSmcState, None, CheckRuns]:
    """Forward runs at ``n_check`` distinct posterior draws: the surrogate's error there.

    The held-out Sobol points measure the error over the whole box; what decides whether the
    posterior is right is the error where the posterior mass is."""
    x = distinct_draws(post, n_check, rng)[:, : len(run.inputs)]
    evs, loglik = run.runs_at(x)
    ok = np.isfinite(loglik)
    err = gp.predict_mean(x[ok]) - loglik[ok]
    n_ok = int(ok.sum())
    check = PosteriorCheck(
        n=n_ok,
        n_failed=int((~ok).sum()),
        x=x,
        log_likelihood=loglik,
        rmse=float(np.sqrt(np.mean(err**2))) if n_ok else math.nan,
        max_abs=float(np.max(np.abs(err))) if n_ok else math.nan,
        mean_error=float(np.mean(err)) if n_ok else math.nan,
    )
    yield GpSmcState(
        "check",
        f"surrogate at {check.n} posterior draws: error {check.centred_rmse:.3g} in L "
        f"(RMSE {check.rmse:.3g})",
        run.record("check", **{k: v for k, v in asdict(check).items() if k != "x"}),
    )
    return CheckRuns(check, tuple(evs))


def repairable(
    check: PosteriorCheck, design: Design | None, adaptive: bool, n_train: int, done: int,
    limit: int,
) -> bool:  # fmt: skip
    """Whether a failed ``check`` (or the runs at draws of the posterior averaged over the
    GP's sample paths, ``cause = "uncertainty"``) is repaired (module docstring): the
    surrogate's error or its uncertainty, not failed runs, made it fail; an adaptive design;
    the runs fit into ``n_train``; fewer than ``limit`` repairs ``done``."""
    passed = check.reliable and check.cause == "check"
    if passed or check.n == 0 or check.fails_often:
        return False
    return room_for_repair(design, adaptive, n_train, len(check.x), done, limit)


def room_for_repair(
    design: Design | None, adaptive: bool, n_train: int, n_runs: int, done: int, limit: int
) -> bool:
    """Whether a repair of ``n_runs`` runs may be made: an adaptive design, the runs fit into
    ``n_train``, fewer than ``limit`` repairs ``done`` (before any of them is run)."""
    if design is None or not adaptive:
        return False
    return done < limit and int(design.train_mask.sum()) + n_runs <= n_train


def repair_note(failed: Sequence[float]) -> str:
    """For the result message: the failed checks that were repaired (their error in L)."""
    if not failed:
        return ""
    rmse = ", ".join(f"{r:.3g}" for r in failed)
    return (
        f"; {len(failed)} repair(s): a failed check at posterior draws, or draws where the "
        f"GP's sample paths moved the posterior (surrogate error there {rmse} in L): their "
        "runs joined the design and the posterior was computed again"
    )
