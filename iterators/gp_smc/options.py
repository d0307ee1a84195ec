"""The options of ``gp_smc`` and the rules between them."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from ...core.options import PluginOptions
from ..surrogates.gp import OPTIMIZERS


class GpSmcOptions(PluginOptions):
    """The options of ``gp_smc`` (:class:`~fbia.iterators.gp_smc.iterator.GpSmcIterator`)."""

    mode: Literal["surrogate", "direct"] = Field(
        "surrogate",
        description="'surrogate': SMC on a GP of L trained on a Sobol design; 'direct': "
        "SMC calls the forward model (only for cheap models) [-]",
    )
    n_train: int = Field(
        200,
        ge=2,
        description="forward runs of the training design: with design = 'sobol' all of "
        "them, with 'adaptive' the most it may use (it stops earlier when the posterior "
        "has converged) [-]",
    )
    n_check: int = Field(
        8,
        ge=0,
        description="forward runs at distinct posterior draws after SMC, to measure the "
        "surrogate's error where the posterior is; a RMSE in L not below 0.5 makes the "
        "status 'unreliable' (surrogate mode; 0 skips the check, status 'unchecked') [-]",
    )
    check_repairs: int = Field(
        2,
        ge=0,
        description="with design = 'adaptive': when the check at posterior draws fails, or "
        "the GP's sample paths move the posterior (runs at draws of the averaged posterior), "
        "and n_train leaves room, those runs join the design, the surrogate is refitted and "
        "the posterior and a fresh check computed again, at most this often (0: never) [-]",
    )
    n_test: int = Field(
        0,
        ge=0,
        description="held-out forward runs (the next Sobol points) for the surrogate "
        "error (Paper B Remark 9 uses 100) [-]",
    )
    surrogate: Literal["auto", "residuals", "log_likelihood"] = Field(
        "auto",
        description="what the GP models: 'residuals': the measure's residual vectors "
        "(principal components, one GP each; L from the emulated residuals, "
        "surrogates/residuals.py), "
        "'log_likelihood': L itself (Paper B); 'auto': residuals where the measure's "
        "distance is the norm of residual vectors of one length and every observation has "
        "the same sigma_N, else L [-]",
    )
    failures: Literal["classify", "ignore"] = Field(
        "classify",
        description="failed forward runs: 'classify' keeps the posterior where the model runs "
        "(a GP classifier of the design's failed runs multiplies the SMC target by "
        "min(1, 2 P_ok), gp_feasibility); 'ignore' leaves them out of the surrogate and "
        "nothing else (Paper B) [-]",
    )
    design: Literal["adaptive", "sobol"] = Field(
        "adaptive",
        description="'adaptive': a small Sobol start, then rounds of SMC on the surrogate and "
        "batches of runs where the posterior is uncertain, until it converges "
        "(gp_smc/adaptive_loop.py); 'sobol': all n_train points of one Sobol design (Paper B) [-]",
    )
    design_space: Literal["box", "prior"] = Field(
        "box",
        description="where Sobol points go: 'box' uniform in the bounds; 'prior' through "
        "the priors' inverse CDFs (Remark 7) [-]",
    )
    n_initial: int = Field(
        0,
        ge=0,
        description="Sobol runs that start the adaptive design (0: 10 per input, Loeppky "
        "et al. 2009) [-]",
    )
    batch_size: int = Field(
        0,
        ge=0,
        description="runs per adaptive round (0: a fifth of the runs so far, at least 4 and "
        "a multiple of the evaluator's parallel workers) [-]",
    )
    adaptive_tol: float = Field(
        0.1,
        gt=0,
        description="the adaptive design stops when the last round's batch, refitted into "
        "the surrogate, moved no posterior mean or 5/50/95 % quantile by more than this many "
        "posterior std and no std by more than this fraction (measured on the round's own "
        "particles), and the spread of the surrogate's errors at the batch's posterior "
        "draws is below 0.5 in L [-]",
    )
    round_particles: int = Field(
        2000,
        ge=10,
        description="SMC particles in the rounds of the adaptive design (the final SMC uses "
        "n_particles) [-]",
    )
    gradients: Literal["off", "tangents"] = Field(
        "off",
        description="'tangents': every forward run also returns the Jacobian of the residuals "
        "with respect to every input (x and theta) from the model's tangents (ale_fsi in "
        "quasi-static mode), and the residual emulator trains on one pseudo-run per input "
        "and run from it, r(z + h e_j) = r(z) + h J e_j (indirect gradient enhancement, "
        "surrogates/residuals.py); needs the residual emulator [-]",
    )
    seed: int = Field(0, description="seed of the Sobol scrambling and of SMC [-]")
    gp_seed: int | None = Field(
        None,
        description="seed of the GP's restart guesses (eq. 29), None: seed; another value "
        "refits the surrogate on the same design (a new seed makes a new design) [-]",
    )
    ard: bool = Field(
        False,
        description="one GP length scale per input (product of 1-D Matérn 3/2 kernels, "
        "Remark 9) instead of one for all standardised inputs [-]",
    )
    gp_axes: Literal["inputs", "posterior"] = Field(
        "inputs",
        description="axes of the GP kernel's length scales: 'inputs' the standardised inputs "
        "(Paper B); 'posterior' (design = 'adaptive') from the second round on the principal "
        "axes of the last round's posterior covariance, so that a posterior that is a narrow "
        "ridge across the inputs gets one short length scale across it (rotated inputs in "
        "fbia.iterators.surrogates.gp) [-]",
    )
    gp_optimizer: Literal["lbfgsb", "scg"] = Field(
        "lbfgsb", description=f"evidence maximiser (eq. 29): one of {OPTIMIZERS} [-]"
    )
    gp_restarts: int = Field(
        2, ge=0, description="extra GP trainings from random initial guesses [-]"
    )
    gp_subset: int = Field(
        800,
        ge=2,
        description="above this many runs, the GP hyperparameter search runs on the first "
        "gp_subset design points and is refined on all [-]",
    )
    gp_polish_iters: int = Field(
        20, ge=1, description="iterations of that refinement on all points [-]"
    )
    gp_trend: Literal["constant", "quadratic"] = Field(
        "constant",
        description="the GP's prior mean: 'constant' (Remark 10) or 'quadratic' (a concave "
        "quadratic fitted to the best runs, so that the surrogate follows a tilted ridge "
        "beyond the runs; gp_trend; better in 2-D, worse in the 6 + 1-D benchmark) [-]",
    )
    nugget_factor: float = Field(
        1e-5, gt=0, description="nugget sigma_n^2 = factor (max L - min L) [-]"
    )
    mean_offset: float = Field(
        1.0, description="GP prior mean m = min L - offset (max L - min L) (Remark 10) [-]"
    )
    n_particles: int = Field(5000, ge=10, description="SMC particles N [-]")
    n_rejuvenation: int = Field(
        20, ge=0, description="Metropolis-Hastings steps per tempering step n_rej [-]"
    )
    zeta: float = Field(0.995, gt=0, lt=1, description="ESS_s = zeta ESS_(s-1) (Algorithm 1) [-]")
    ess_min: float = Field(
        0.5, ge=0, le=1, description="resample when ESS < ess_min N (fraction of N) [-]"
    )
    rejuvenate: Literal["every_step", "after_resampling"] = Field(
        "after_resampling",
        description="when particles move: only in steps that resample and the last one "
        "(resample-move: the same weighted approximation of every tempered density, "
        "10 000 particles at zeta = 0.998 in seconds) or every tempering step (Algorithm 1 "
        "as printed; thousands of steps at zeta close to 1 take hours) [-]",
    )
    smc_table: int | Literal["auto", "off"] = Field(
        "auto",
        description="tabulate L and the log-priors for the SMC moves (fbia.iterators."
        "smc_table: Algorithm 1 at 10 000 particles, 30 moves and zeta = 0.998 in seconds "
        "in 2-D): 'auto' does so with rejuvenate = 'every_step' for at most 3 sampled inputs "
        "with bounded priors (1025 points per input in 2-D, 101 in 3-D), a number gives the "
        "points per input, 'off' never [-]",
    )
    smc_table_tol: float = Field(
        0.05,
        gt=0,
        description="largest error of the table against L at the final particles; above it "
        "the result is unreliable [units of L]",
    )
    map_bins: int = Field(
        30, ge=2, description="intervals per x of the MAP histogram under theta (Remark 8) [-]"
    )
    laplace: bool = Field(True, description="Laplace approximation at the MAP (no theta only) [-]")
    max_smc_steps: int | None = Field(
        None,
        ge=1,
        description="limit of tempering steps (None: 100 halvings of the ESS, "
        "ceil(100 log 0.5 / log zeta), at least 1000) [-]",
    )
    uncertainty_check: bool = Field(
        True,
        description="compare the posterior with its average over the GP's sample paths "
        "(surrogates/uncertainty.py): if the GP's own uncertainty moves a mean by more than "
        "0.3 std or "
        "a std by more than a factor 1.5, runs at draws of the averaged posterior join the "
        "design (check_repairs, adaptive design) and, if it still does, the status is "
        "'unreliable' (surrogate mode, known sigma_N; a few seconds) [-]",
    )
    surrogate_uncertainty: Literal["none", "expected_posterior"] = Field(
        "none",
        description="'expected_posterior': the posterior averaged over joint sample paths of "
        "the GP (each normalised), so that credible intervals include what the surrogate "
        "does not know (surrogates/uncertainty.py); 'none': SMC on the GP mean (Paper B) [-]",
    )
