"""The options of :class:`~fbia.iterators.levenberg_marquardt.LevenbergMarquardtIterator`:
Paper A's algorithm and the robust mode, their tolerances, finite-difference steps and
initial guesses (including a Bayesian result's posterior, :mod:`.handoff`), with the
rules that tie them together.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, PrivateAttr, model_validator

from ...core.options import PluginOptions
from ...core.problem import Result
from .handoff import POSTERIOR_LABELS, posterior_starts

__all__ = ["LMOptions"]

_ROBUST_ONLY = ("ftol", "xtol", "gtol", "scaling", "speculative", "final_jacobian")


class LMOptions(PluginOptions):
    """Options of :class:`LevenbergMarquardtIterator` (units in every description)."""

    x0: dict[str, float] | list[dict[str, float]] | None = Field(
        None,
        description="initial guess {name: value} in the parameters' units, or a list of "
        "them for a multi-start analysis (Paper A Tables 1, 3-6); default: the "
        "parameters' `initial` values",
    )
    x0_labels: list[str] | None = Field(
        None,
        description="names of the starts in x0, shown in the result (set to 'posterior MAP', "
        "'posterior mean' when x0 is a gp_smc result) [-]",
    )
    x0_from: Path | None = Field(
        None,
        description="result.json of a Bayesian calibration (gp_smc): start from its "
        "posterior MAP and posterior mean (instead of x0), read when the options are made "
        "[path]",
    )
    mode: Literal["robust", "paper"] = Field(
        "robust",
        description="'robust': improved algorithm (declines steps that increase the "
        "residual, projects steps onto near bounds and goes halfway to far ones, survives failed "
        "runs); 'paper': Paper A "
        "exactly as published",
    )
    alpha: float | dict[str, float] = Field(
        1e-5,
        description="absolute part α of the finite-difference perturbation "
        "δx_i = α + β·x_i (Paper A eq. 21; robust mode uses |x_i|), in each parameter's "
        "unit; one number or {name: value}; with α = 0, δx_i = β where x_i = 0",
    )
    beta: float = Field(
        1e-3, ge=0.0, description="relative part β of the perturbation (eq. 21) [-]"
    )
    mu0: float | None = Field(
        None,
        gt=0.0,
        description="initial damping μ0 of eq. 18, relative to diag(JᵀJ) [-]; default 1 "
        "in paper mode (the default of QUEENS, where Paper A's algorithm was implemented), "
        "1e-2 in robust mode (where it sets the first trust region: the length of the "
        "first step)",
    )
    mu_limit: float = Field(
        1e6,
        gt=1.0,
        description="paper mode: damping limit factor, the run ends without result when "
        "μ > μ0·mu_limit (Paper A: 1e6) [-]; the robust mode ends on xtol instead",
    )
    declined_mu: Literal["kept", "restored"] = Field(
        "kept",
        description="paper mode: μ after a step declined at the bounds (eq. 28). 'kept': "
        "the doubled μ goes on into the next iteration (QUEENS); 'restored': the doubling "
        "serves the proposal only, and the next iteration starts from the μ before it (the "
        "text doubles μ^k 'and a new step is proposed', and says nothing of μ^(k+1)) [-]",
    )
    eps_grad: float = Field(
        1e-8,
        ge=0.0,
        description="eq. 29a: converged when err_grad = ‖Jᵀr‖ < eps_grad; unit "
        "[r]²/[x], mixed over the parameters as in the paper; 0 disables",
    )
    eps_res: float = Field(
        0.0,
        ge=0.0,
        description="eq. 29b: converged when err_res = ‖r‖/√n_r < eps_res, in the unit "
        "of the residuals (mm); 0 disables",
    )
    max_iter: int = Field(
        100, ge=0, description="eq. 29c: largest number of LM iterations (steps taken)"
    )
    ftol: float = Field(
        1e-8,
        ge=0.0,
        description="robust mode: converged when a step reduces ‖r‖² by a fraction "
        "below ftol (actual and predicted) [-]",
    )
    xtol: float = Field(
        1e-8,
        ge=0.0,
        description="robust mode: converged when the trust region ‖D Δx‖ shrinks below "
        "xtol·‖D x‖ (D: Jacobian column norms, so each parameter counts by its effect on "
        "r) [-]",
    )
    gtol: float = Field(
        1e-8,
        ge=0.0,
        description="robust mode: converged when r is orthogonal to every column of J "
        "within gtol (largest |cos| of the angle) [-]",
    )
    scaling: Literal["adaptive", "marquardt"] = Field(
        "adaptive",
        description="robust mode: damping matrix D² of eq. 18: 'marquardt' = "
        "diag(JᵀJ) of the current J (as in the paper), 'adaptive' = largest squared "
        "column norms of J seen so far (Moré 1978; robust for insensitive parameters)",
    )
    speculative: bool = Field(
        False,
        description="robust mode: evaluate a trial point together with its n_x "
        "perturbations in one batch (n_x+1 runs per round, like the paper: fewer rounds "
        "on a pool, n_x runs wasted per declined step); default: the trial point first",
    )
    final_jacobian: Literal["central", "forward"] = Field(
        "central",
        description="robust mode: Jacobian of the last iterations. 'central': once "
        "ftol, xtol or gtol hold with forward differences, go on with central "
        "differences (2 n_x runs per J, step δx·β^(-1/3)) until they hold again, so that "
        "the result is as accurate as the residuals allow, not only as the forward-"
        "difference J does; 'forward': stop at the first convergence",
    )
    jacobian: Literal["auto", "tangent", "forward", "central"] = Field(
        "auto",
        description="robust mode: how J is computed. 'tangent': from the forward model's "
        "tangents (one run per iteration, no finite differences; the model must give them: "
        "ale_fsi in quasi-static mode); 'forward': forward differences (n_x + 1 runs per "
        "iteration, then final_jacobian); 'central': central differences throughout (2 n_x "
        "+ 1 runs); 'auto' (default): 'tangent' where the model gives tangents for every "
        "parameter, else 'forward'.  Paper mode always uses forward differences (eq. 21-23)",
    )
    max_nfev: int | None = Field(
        None,
        ge=1,
        description="stop after this many forward runs in total (checked after each batch)",
    )
    uncertain_values: dict[str, float] | None = Field(
        None,
        description="values at which to hold the problem's uncertain parameters θ "
        "(least squares has no place for distributions), in their units",
    )
    fit_rtol: float = Field(
        0.05,
        ge=0.0,
        description="multi-start: optima whose err_res is within this fraction of the "
        "best one fit 'equally well' [-]",
    )
    agree_rtol: float = Field(
        0.01,
        gt=0.0,
        description="multi-start: equally good optima disagree when a parameter differs "
        "by more than agree_rtol·max(|x|, α/β) [-]",
    )

    #: the posterior MAP and mean read from x0_from when the options were made
    _x0_from_starts: list[dict[str, float]] | None = PrivateAttr(None)

    @property
    def x0_from_starts(self) -> list[dict[str, float]] | None:
        """The starts ``x0_from`` gave (``[MAP, mean]``, :data:`.handoff.POSTERIOR_LABELS`),
        read and checked when the options were made (``fbia validate``); None without it."""
        return self._x0_from_starts

    @model_validator(mode="before")
    @classmethod
    def _posterior_as_x0(cls, data: Any) -> Any:
        """x0 = a gp_smc result (or its to_dict()): start from its posterior MAP and mean."""
        if isinstance(data, Mapping):
            x0 = data.get("x0")
            if isinstance(x0, Result) or (isinstance(x0, Mapping) and "info" in x0):
                data = {**data, "x0": posterior_starts(x0), "x0_labels": list(POSTERIOR_LABELS)}
        return data

    @model_validator(mode="after")
    def _paper_mode_is_the_paper(self) -> LMOptions:
        if self.mode == "paper":
            extra = [k for k in _ROBUST_ONLY if k in self.model_fields_set]
            if extra:
                raise ValueError(
                    f"option(s) {', '.join(extra)} apply to mode='robust' only; "
                    "mode='paper' is Paper A's algorithm as published"
                )
        elif "mu_limit" in self.model_fields_set:
            raise ValueError(
                "option mu_limit applies to mode='paper' only; the robust mode ends when "
                "the steps fall below xtol"
            )
        elif "declined_mu" in self.model_fields_set:
            raise ValueError(
                "option declined_mu applies to mode='paper' only (the damping after a step "
                "declined at the bounds, Paper A eq. 28)"
            )
        if self.mode == "paper" and self.jacobian not in ("auto", "forward"):
            raise ValueError(
                f"jacobian = {self.jacobian!r} applies to mode='robust' only; Paper A's "
                "algorithm differentiates by forward differences (eq. 21-23)"
            )
        alphas = self.alpha if isinstance(self.alpha, dict) else {"alpha": self.alpha}
        bad = {k: v for k, v in alphas.items() if not v >= 0}
        if bad:
            raise ValueError(f"alpha must be >= 0, got {bad}")
        if self.beta == 0 and not all(v > 0 for v in alphas.values()):
            raise ValueError("alpha and beta are both zero: no finite-difference step")
        if isinstance(self.x0, list) and not self.x0:
            raise ValueError("x0 is an empty list of initial guesses")
        if self.x0 is not None and self.x0_from is not None:
            raise ValueError("give x0 or x0_from, not both")
        if self.x0_from is not None:  # read now: a bad file is found before any run
            self._x0_from_starts = posterior_starts(self.x0_from)
        n_starts = len(self.x0) if isinstance(self.x0, list) else 1
        if self.x0_labels is not None and len(self.x0_labels) != n_starts:
            raise ValueError(f"x0_labels names {len(self.x0_labels)} starts, x0 has {n_starts}")
        return self
