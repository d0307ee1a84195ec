"""What the stages of one ``gp_smc`` run share, what they yield, and the status rule."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ...core.iteration import Evaluator
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
from ..surrogates.uncertainty import SurrogateUncertainty
from .result import PosteriorCheck

FloatArray = NDArray[np.float64]


@dataclass
class GpSmcState:
    """What :meth:`GpSmcIterator.steps` yields: the stage and its figures."""

    stage: Literal["design", "forward_runs", "round", "surrogate", "smc", "check"]
    message: str
    data: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        return f"[{self.stage}] {self.message}"


@dataclass
class SmcRun:
    """What the stages of one :meth:`~fbia.iterators.gp_smc.iterator.GpSmcIterator.steps`
    share: the problem, the evaluator, the inputs (x then theta) and the design's records.
    Its run counts (``nfev``, ``n_failed``, for the stages' messages) are kept by
    :meth:`evaluate` alone; the result's are the framework's books."""

    problem: InverseProblem
    evaluator: Evaluator
    inputs: list[Parameter]
    t_start: float
    history: list[dict[str, Any]] = field(default_factory=list)
    evaluations: list[Evaluation] = field(default_factory=list)
    _runs: list[int] = field(default_factory=lambda: [0, 0], repr=False)  # done, failed

    def __post_init__(self) -> None:
        self.count = measurement_count(self.problem)
        self.noise = noise_parameter(self.problem)
        self.sigmas = [] if self.noise is not None else noise_levels(self.problem)
        self.noise_n: int | None = self.count  # n of eq. 5 when sigma_N is inferred

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

    def joint(
        self, design_l: Callable[[FloatArray], FloatArray]
    ) -> Callable[[FloatArray], FloatArray]:
        """L on the posterior's inputs from the design quantity (L of x and theta, or its
        profile over sigma_N, which then is the last column)."""
        if self.noise is None:
            return design_l
        d = len(self.inputs)

        def log_likelihood(z: FloatArray) -> FloatArray:
            assert self.noise_n is not None
            return log_likelihood_from_profile(design_l(z[:, :d]), self.noise_n, z[:, d])

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
        evs = list(self.evaluator.evaluate(self.problem, points))
        self._runs[0] += len(evs)
        self._runs[1] += sum(not ev.ok for ev in evs)
        return evs

    @property
    def nfev(self) -> int:
        """Forward runs asked for so far."""
        return self._runs[0]

    @property
    def n_failed(self) -> int:
        """Of them, the failed ones."""
        return self._runs[1]

    def log_likelihoods(self, evaluations: Sequence[Evaluation]) -> FloatArray:
        """What the surrogate models, per record (-inf where the run failed): Paper B eq. 5,
        or its profile over sigma_N when sigma_N is inferred."""
        if self.noise is None:
            return np.array(
                [gaussian_log_likelihood(ev, self.sigmas, self.count) for ev in evaluations]
            )
        if self.noise_n is None:  # n of the measure: the residual count of a successful run
            ok = [ev for ev in evaluations if ev.ok and ev.residuals is not None]
            if ok:
                self.noise_n = squared_distance(ok[0])[1]
        return np.array([profile_log_likelihood(ev, self.noise_n) for ev in evaluations])

    def forward_log_likelihood(self, x: FloatArray) -> FloatArray:
        """L by forward runs (``mode="direct"``): one batch per SMC call; failed runs have
        zero likelihood (L = -inf)."""
        return self.log_likelihoods(self.evaluate(x))


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
