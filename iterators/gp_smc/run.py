"""What the stages of one ``gp_smc`` run share, what they yield, and the status rule."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from itertools import chain
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ...core.iteration import Evaluator, RunBook
from ...core.likelihood import (
    gaussian_log_likelihood,
    log_likelihood_from_profile,
    measurement_count,
    noise_levels,
    noise_parameter,
    profile_log_likelihood,
    squared_distance,
)
from ...core.parameters import Parameter, Prior
from ...core.problem import Evaluation, InverseProblem
from ..smc.sampler import SmcResult
from ..surrogates.residuals import Surrogate
from ..surrogates.uncertainty import SurrogateUncertainty
from .result import AdaptiveDesign, DesignRuns, PosteriorCheck, SurrogateFit

FloatArray = NDArray[np.float64]


@dataclass
class GpSmcState:
    """What :meth:`GpSmcIterator.steps` yields: the stage and its figures."""

    stage: Literal["design", "forward_runs", "round", "surrogate", "smc", "check"]
    message: str
    data: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        return f"[{self.stage}] {self.message}"


@dataclass(frozen=True)
class Design:
    """The design's runs so far, one forward-run record per point (issue 48: one run, one
    record): the points (x then theta), L per run (-inf where it failed, what the surrogate is
    trained on), which rows train the surrogate (False: a held-out test point) and the runs'
    records themselves. The stages return a new one (:meth:`extended`) instead of appending to
    a list beside the arrays, so a row's point, L and record cannot part."""

    points: FloatArray  # (n, d)
    log_likelihood: FloatArray  # (n,)
    train_mask: NDArray[np.bool_]  # (n,)
    records: tuple[Evaluation, ...]  # (n,)
    #: how many of the leading records came from an earlier result (GpSmcIterator.reuse),
    #: not from this run's evaluator
    reused: int = 0

    def __post_init__(self) -> None:
        n = len(self.points)
        if not (len(self.log_likelihood) == len(self.train_mask) == len(self.records) == n):
            raise ValueError(
                f"a design needs one L, mask entry and record per point: {n} points, "
                f"{len(self.log_likelihood)} L, {len(self.train_mask)} mask entries, "
                f"{len(self.records)} records"
            )

    @property
    def ok(self) -> NDArray[np.bool_]:
        return np.isfinite(self.log_likelihood)

    @property
    def training_records(self) -> list[Evaluation]:
        """The records of the training rows, in order (what a residual emulator is fitted
        to, beside ``points[train_mask]``)."""
        return [self.records[i] for i in np.flatnonzero(self.train_mask)]

    def extended(
        self, points: FloatArray, log_likelihood: FloatArray, records: Sequence[Evaluation]
    ) -> Design:
        """This design with runs at ``points`` appended as training rows."""
        return replace(
            self,
            points=np.vstack([self.points, points]),
            log_likelihood=np.concatenate([self.log_likelihood, log_likelihood]),
            train_mask=np.concatenate([self.train_mask, np.ones(len(points), dtype=bool)]),
            records=(*self.records, *records),
        )

    def result(self) -> DesignRuns:
        """What the result keeps of it (:class:`~.result.DesignRuns`: the records are the
        result's ``evaluations``)."""
        return DesignRuns(
            points=self.points,
            log_likelihood=self.log_likelihood,
            status=[ev.status for ev in self.records],
            train_mask=self.train_mask,
        )


@dataclass(frozen=True)
class SmcRun:
    """What the stages of one :meth:`~fbia.iterators.gp_smc.iterator.GpSmcIterator.steps`
    share, fixed for the run: the problem, the evaluator, the inputs (x then theta) and the
    noise model. The runs made so far are the framework's book
    (:class:`fbia.core.iteration.RunBook`, the evaluator ``drive`` hands to ``steps``; one is
    put around any other evaluator): :attr:`runs`, :attr:`nfev`, :attr:`n_failed` read it,
    and :meth:`evaluate` is the one place the stages ask for runs. ``history`` is the stages'
    log (what they yield, in order)."""

    problem: InverseProblem
    evaluator: Evaluator
    inputs: list[Parameter]
    t_start: float
    history: list[dict[str, Any]] = field(default_factory=list)
    book: RunBook = field(init=False, repr=False)
    count: int | None = field(init=False)
    noise: Parameter | None = field(init=False)
    sigmas: list[float] = field(init=False)

    def __post_init__(self) -> None:
        book = self.evaluator if isinstance(self.evaluator, RunBook) else RunBook(self.evaluator)
        object.__setattr__(self, "book", book)
        object.__setattr__(self, "count", measurement_count(self.problem))
        noise = noise_parameter(self.problem)
        object.__setattr__(self, "noise", noise)
        object.__setattr__(self, "sigmas", [] if noise is not None else noise_levels(self.problem))

    @property
    def sampled(self) -> list[Parameter]:
        """The posterior's inputs: x, theta, and sigma_N when it is inferred."""
        return self.inputs if self.noise is None else [*self.inputs, self.noise]

    @property
    def sampled_names(self) -> list[str]:
        return [p.name for p in self.sampled]

    @property
    def sampled_priors(self) -> list[Prior]:
        return [p.prior for p in self.sampled if p.prior is not None]

    def noise_n(self, records: Sequence[Evaluation] = ()) -> int | None:
        """n of eq. 5 when sigma_N is inferred: the measure's count, else the residual count
        of a successful run (of ``records``, else of the runs so far; the same for every run
        of one measure); None before any run succeeded."""
        if self.count is not None:
            return self.count
        for ev in chain(records, self.runs):
            if ev.ok and ev.residuals is not None:
                return squared_distance(ev)[1]
        return None

    def joint(
        self, design_l: Callable[[FloatArray], FloatArray], records: Sequence[Evaluation] = ()
    ) -> Callable[[FloatArray], FloatArray]:
        """L on the posterior's inputs from the design quantity (L of x and theta, or its
        profile over sigma_N, which then is the last column; its n from ``records``, the
        surrogate's training runs, or from the runs ``design_l`` makes)."""
        if self.noise is None:
            return design_l
        d = len(self.inputs)

        n = self.noise_n(records)  # known once a run succeeded: looked up once, not per call

        def log_likelihood(z: FloatArray) -> FloatArray:
            nonlocal n
            profile = design_l(z[:, :d])
            if n is None:  # mode = "direct": n from the first runs design_l made
                n = self.noise_n()
            if n is None:  # no run succeeded yet: every profile is -inf
                return np.full(len(z), -np.inf)
            return log_likelihood_from_profile(profile, n, z[:, d])

        return log_likelihood

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.inputs]

    @property
    def n_x(self) -> int:
        return len(self.problem.parameters)

    @property
    def priors(self) -> list[Prior]:
        return [p.prior for p in self.inputs if p.prior is not None]

    def record(self, stage: str, **data: Any) -> dict[str, Any]:
        entry = {"stage": stage, "seconds": time.perf_counter() - self.t_start, **data}
        self.history.append(entry)
        return entry

    def evaluate(self, x: FloatArray) -> list[Evaluation]:
        """Forward runs at the rows of ``x`` (the one place the stages ask for runs)."""
        points = [dict(zip(self.names, map(float, row), strict=True)) for row in x]
        return list(self.book.evaluate(self.problem, points))

    @property
    def runs(self) -> list[Evaluation]:
        """Every run this run has made, in order (the book's records)."""
        return self.book.records

    @property
    def nfev(self) -> int:
        """Forward runs asked for so far."""
        return self.book.nfev

    @property
    def n_failed(self) -> int:
        """Of them, the failed ones."""
        return self.book.n_failed

    def log_likelihoods(self, evaluations: Sequence[Evaluation]) -> FloatArray:
        """What the surrogate models, per record (-inf where the run failed): Paper B eq. 5,
        or its profile over sigma_N when sigma_N is inferred."""
        if self.noise is None:
            return np.array(
                [gaussian_log_likelihood(ev, self.sigmas, self.count) for ev in evaluations]
            )
        n = self.noise_n(evaluations)
        return np.array([profile_log_likelihood(ev, n) for ev in evaluations])

    def runs_at(self, x: FloatArray) -> tuple[list[Evaluation], FloatArray]:
        """Forward runs at the rows of ``x``, each with its L (:meth:`log_likelihoods`): what
        the design's rounds and the checks add, one record and one L per run."""
        records = self.evaluate(x)
        return records, self.log_likelihoods(records)

    def forward_log_likelihood(self, x: FloatArray) -> FloatArray:
        """L by forward runs (``mode="direct"``): one batch per SMC call; failed runs have
        zero likelihood (L = -inf)."""
        return self.runs_at(x)[1]


@dataclass(frozen=True)
class Fitted:
    """What the design stages leave in surrogate mode: the design with its runs, the
    surrogate on them, its errors (:class:`~.result.SurrogateFit`) and the adaptive design's
    rounds (None for a fixed Sobol design)."""

    design: Design
    gp: Surrogate
    fit: SurrogateFit
    adaptive: AdaptiveDesign | None


@dataclass(frozen=True)
class Checked:
    """What the posterior stage leaves: the surrogate as the last repair left it (None in
    ``mode = "direct"``), the SMC posterior, the particles the result summarises (the
    posterior averaged over the GP's sample paths with ``surrogate_uncertainty =
    "expected_posterior"``, else ``post``), the last check, the failed checks' errors (their
    runs repaired the design) and the GP-sample-path check."""

    fitted: Fitted | None
    post: SmcResult
    particles: SmcResult
    check: PosteriorCheck | None
    failed: list[float]
    uncertainty: SurrogateUncertainty | None


def run_status(
    mode: str, check: PosteriorCheck | None, uncertainty: SurrogateUncertainty | None = None
) -> str:
    """``completed`` (direct SMC, or a surrogate whose error at posterior draws is well below
    1 in L and whose own uncertainty does not move the posterior), ``unreliable`` (either
    fails) or ``unchecked`` (the check was switched off)."""
    if mode != "surrogate":
        return "completed"
    if uncertainty is not None and uncertainty.moves_posterior:
        return "unreliable"
    if check is None:
        return "unchecked"
    return "completed" if check.reliable else "unreliable"


def log_prior(inputs: Sequence[Parameter], z: FloatArray) -> FloatArray:
    """log p(x) + log p(theta) at the rows of ``z`` (independent priors)."""
    out = np.zeros(len(z))
    for j, p in enumerate(inputs):
        assert p.prior is not None  # checked at the start of steps()
        out += p.prior.logpdf(z[:, j])
    return out
