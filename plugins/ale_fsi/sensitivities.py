"""Tangents of the quasi-static ALE FSI state: d(interface vertices)/d(input), no new solve.

At a converged steady state R(U; p) = 0, so dU/dp = -(dR/dU)^-1 dR/dp: one linear solve per
input with the consistent Jacobian at that state (the derivative of the discrete model, as
dolfin-adjoint's tangent linear model; Nocedal & Wright 2006, sec. 8.2 on the cost).

* **dR/dp** for the material inputs: the residual is *linear* in each region's Lamé
  parameters (μ, λ) for both laws -- Saint Venant-Kirchhoff (thesis eq. 2.15)
  ``S = λ tr(E) I + 2μ E`` and neo-Hooke (eq. 2.18) ``S = μ (I - C^-1) + λ ln J C^-1`` --, so
  ``dR/dμ_r = R(μ_r + δ) - R(μ_r)`` divided by δ is exact up to rounding, and only the
  solid's terms of R (``solid_residual``) enter the difference; the chain rule of eq. 2.16
  gives E_r and ν_r.  For the **inflow rate** (quasi-static coordinate or input) the
  inflow's Dirichlet values move by ``g = dU_D/dq`` (the profile of a unit rate) and the free
  dofs follow from ``J_ff dU_f = -(J g)_f``.
* **dR/dU** is assembled at the converged state.  Newton's last factorisation is of a nearby
  iterate (chord steps follow it), so it serves as the solver of an iterative refinement
  against the exact Jacobian (no new factorisation); only when that does not contract is the
  Jacobian factorised afresh (``refactorised`` in the report).  A solver whose
  ``tangents_refactorise`` is true (``ale_fsi`` in 3-D with the direct solver, where a
  refactorisation costs less than the sweeps) factorises it first; one sweep then checks the
  solve.  Either way the factorisation of the converged state is the next solve's chord.
* The vertices of the interface are linear in the displacement dofs
  (:class:`~fbia.plugins.ale_fsi.postprocess.AleFsiPostprocess`: the displacement at the
  edge points in 2-D, at the vertices in 3-D), so dv/dp is the same map applied to dU/dp.

Transient runs give no tangents (``tangent_inputs()`` is empty there): an iterator falls back
to finite differences.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..fem.flow_cell import SOLID
from ..fem.newton import NewtonFailure, direct_solver_threads

__all__ = ["TangentReport", "material_inputs", "vertex_tangents"]

#: Refinement stops when the correction is below this fraction of the solution (per field,
#: max norm), far below the 1e-5 the tangents are verified to.
REFINE_TOL = 1e-7
REFINE_MAX = 25


@dataclass
class TangentReport:
    """What the tangents of one state cost."""

    refinements: int = 0
    refactorised: bool = False
    seconds: float = 0.0
    inputs: list[str] = field(default_factory=list)
    #: dU/dp (all dofs) of the last state's material inputs: the model's first-order
    #: prediction of a warm start at other inputs
    state_tangents: dict[str, NDArray[np.float64]] = field(default_factory=dict)


def material_inputs(regions: Sequence[str]) -> dict[str, tuple[str, str]]:
    """Input name -> (region, "E" | "nu"): ``E``, ``nu`` for one solid, else ``E_k``,
    ``nu_k`` per subdomain k."""
    if list(regions) == [SOLID]:
        return {"E": (SOLID, "E"), "nu": (SOLID, "nu")}
    out: dict[str, tuple[str, str]] = {}
    for k, region in enumerate(regions, start=1):
        out[f"E_{k}"] = (region, "E")
        out[f"nu_{k}"] = (region, "nu")
    return out


def _lame_derivatives(E: float, nu: float, which: str) -> tuple[float, float]:
    """(dμ/dp, dλ/dp) of eq. 2.16 for p = E or ν."""
    if which == "E":
        return 1.0 / (2.0 * (1.0 + nu)), nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return -E / (2.0 * (1.0 + nu) ** 2), E * (1.0 + 2.0 * nu**2) / (
        (1.0 + nu) * (1.0 - 2.0 * nu)
    ) ** 2


def vertex_tangents(
    solver: Any, post: Any, names: Sequence[str], report: TangentReport
) -> dict[str, NDArray[np.float64]]:
    """d vertices / d name for every name (the state of ``solver`` must be converged and
    quasi-static), in the vertex order of ``post.interface()``."""
    t0 = time.perf_counter()
    state = solver.state()
    solver.assemble_jacobian()  # the consistent Jacobian at the converged state
    free = solver.free_mask
    rhs: dict[str, NDArray[np.float64]] = {}
    dirichlet: dict[str, NDArray[np.float64]] = {}
    materials = material_inputs(solver.solids)
    derivs: dict[tuple[str, str], NDArray[np.float64]] = {}
    r0 = _solid_residual(solver)
    for name in names:
        if name == "inflow_rate":
            g = np.asarray(solver.load_direction(), dtype=float)
            rhs[name] = -_mult(solver, g)
            dirichlet[name] = g
            continue
        region, which = materials[name]
        E, nu = solver.materials[region]
        dmu, dlam = _lame_derivatives(E, nu, which)
        for lame_name in ("mu", "lam"):
            if (region, lame_name) not in derivs:
                derivs[region, lame_name] = _residual_derivative(solver, region, lame_name, r0)
        rhs[name] = -(dmu * derivs[region, "mu"] + dlam * derivs[region, "lam"])
    out = {}
    report.state_tangents = {}
    fresh = [False]  # factorised at this state
    reference = post.interface(deformed=False).vertices
    try:
        for name in names:
            du = _solve(solver, rhs[name], report, fresh)
            if name in dirichlet:
                du = np.where(free, du, dirichlet[name])
            else:
                report.state_tangents[name] = du
            solver.set_state(du)
            out[name] = post.interface(deformed=True).vertices - reference
    finally:
        solver.set_state(state)
    report.seconds += time.perf_counter() - t0
    report.inputs = list(names)
    return out


def _mult(solver: Any, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """J x with the assembled Jacobian."""
    vec = solver.vector.CreateVector()
    out = solver.vector.CreateVector()
    vec.FV().NumPy()[:] = x
    solver.matrix.Mult(vec, out)
    return np.array(out.FV().NumPy(), copy=True)


def _solid_residual(solver: Any) -> NDArray[np.float64]:
    res = solver.vector.CreateVector()
    solver.solid_residual(res)
    return np.array(res.FV().NumPy(), copy=True)


def _residual_derivative(
    solver: Any, region: str, which: str, r0: NDArray[np.float64]
) -> NDArray[np.float64]:
    """dR/dμ_r or dR/dλ_r: the residual is linear in each (module docstring), and only the
    solid's terms depend on them, so their difference alone is taken (in 2-D a tenth of a
    residual's cost, and no cancellation of the fluid's terms)."""
    param = solver.lame_parameter(region, which)
    value = float(param.Get())
    mu = float(solver.lame_parameter(region, "mu").Get())
    delta = abs(value) if value != 0.0 else mu
    try:
        param.Set(value + delta)
        r1 = _solid_residual(solver)
    finally:
        param.Set(value)
    return (r1 - r0) / delta


def _solve(
    solver: Any, b: NDArray[np.float64], report: TangentReport, fresh: list[bool]
) -> NDArray[np.float64]:
    """J^-1 b on the free dofs (zero elsewhere): Newton's factorisation refined against the
    assembled Jacobian; a fresh factorisation (once per state: ``fresh[0]`` says it is
    done) first where the solver asks for it, else where the refinement does not contract."""
    newton = solver.newton_solver
    free = solver.free_mask
    rhs = solver.vector.CreateVector()
    rhs.FV().NumPy()[:] = np.where(free, b, 0.0)
    x = None
    if newton.inverse is not None and (fresh[0] or not solver.tangents_refactorise):
        x = _refined(solver, newton, rhs, report)
    if x is None and not fresh[0]:
        newton.factorise("tangents")
        # of the converged state now: the best chord for the next solve as well
        fresh[0] = report.refactorised = True
        x = _refined(solver, newton, rhs, report)
    if x is None:
        raise NewtonFailure("tangents: the linear solve does not converge", "linear_solver")
    return np.asarray(x)


def _refined(solver: Any, newton: Any, rhs: Any, report: TangentReport) -> Any:
    """Iterative refinement of ``J x = rhs`` with the factorisation; None if it stalls.  The
    products with J and the solves run on the solver's threads (a serial product of the 3-D
    dome's Jacobian took 35 ms, as long as a back-substitution)."""
    x = rhs.CreateVector()
    r = rhs.CreateVector()
    jx = rhs.CreateVector()
    corr = rhs.CreateVector()
    free = solver.free_mask
    blocks = [idx for b in solver.field_blocks() if len(idx := b.start + np.flatnonzero(free[b]))]
    previous = np.inf
    with direct_solver_threads(newton.threads):
        x.data = newton.inverse * rhs
        for _ in range(REFINE_MAX):
            solver.matrix.Mult(x, jx)
            r.data = rhs - jx
            corr.data = newton.inverse * r
            x.data += corr
            report.refinements += 1
            xv, cv = x.FV().NumPy(), corr.FV().NumPy()
            # the correction relative to the solution, per field (velocity, displacement,
            # pressure)
            rel = max(
                float(np.abs(cv[i]).max()) / max(float(np.abs(xv[i]).max()), 1e-300) for i in blocks
            )
            if rel <= REFINE_TOL:
                return np.array(xv, copy=True)
            if not np.isfinite(rel) or rel > 0.5 * previous:
                return None
            previous = rel
    return None
