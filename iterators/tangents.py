"""The Jacobian of the residuals from the forward model's tangents: J = dr/dv · dv/dx.

Shared by the iterators that use a model's sensitivities: Levenberg–Marquardt (``jacobian =
"tangent"``) and gp_smc (``gradients = "tangents"``: the residual emulator's pseudo-runs).

A forward model that declares ``tangent_inputs()`` returns, when asked with
``solve(..., tangents=names)``, the derivative of every interface vertex with respect to each
named input (:attr:`fbia.Interface.tangents`; ``ale_fsi``: one back-substitution per input
with the Jacobian of the converged Newton system, :mod:`fbia.plugins.ale_fsi.sensitivities`).
The measure turns a vertex motion into a residual change (``residuals_jvp``: analytic in
``cpp``; otherwise a central difference of the measure alone along the motion, no forward
run), so one forward run gives r and J (Levenberg–Marquardt's ``jacobian = "tangent"``)
where forward differences (Paper A eq. 21-23) take n_x + 1.

:class:`TangentProblem` is an :class:`fbia.InverseProblem` whose runs ask for the tangents
and whose records carry J (``Evaluation.jacobian``); the store keeps the tangents with the
interfaces, so a resumed study computes J from them again without a forward run
(:meth:`TangentProblem.jacobian_from`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..core.errors import ConfigError, MeasureError
from ..core.interface import Interface
from ..core.observation import Coordinate, Observation, Solution
from ..core.problem import Evaluation, InverseProblem

__all__ = ["TangentProblem", "directional_difference", "residual_jacobian"]

#: Largest vertex motion of the directional difference, relative to the interface's size: the
#: truncation error is O(h²), the rounding error O(ε/h), both far below the tangents' own.
RELATIVE_STEP = 1e-6


def directional_difference(
    measure: Any, simulated: Interface, observation: Observation, dvertices: NDArray[np.float64]
) -> NDArray[np.float64]:
    """d residuals along the vertex motion ``dvertices`` by a central difference of the
    measure (two evaluations of ``residuals``, no forward run)."""
    size = float(np.ptp(simulated.vertices, axis=0).max()) or 1.0
    largest = float(np.abs(dvertices).max())
    if largest == 0.0:
        return np.zeros(len(measure.residuals(simulated, observation)))
    h = RELATIVE_STEP * size / largest
    plus = measure.residuals(
        simulated.with_vertices(simulated.vertices + h * dvertices), observation
    )
    minus = measure.residuals(
        simulated.with_vertices(simulated.vertices - h * dvertices), observation
    )
    plus, minus = np.asarray(plus, dtype=float), np.asarray(minus, dtype=float)
    if plus.shape != minus.shape:
        raise MeasureError(
            "the residual vector changed length along a vertex motion: no derivative"
        )
    return (plus - minus) / (2.0 * h)


def residual_jacobian(
    problem: InverseProblem, solution: Solution, names: Sequence[str]
) -> NDArray[np.float64] | None:
    """dr/dx (n_r, len(names)) over all observations, in the order of
    :meth:`~fbia.InverseProblem.discrepancy`; None when an interface lacks a tangent."""
    measure = problem.measure
    blocks = []
    for obs in problem.observations:
        simulated = solution.interface(obs.coordinate)
        if not all(n in simulated.tangents for n in names):
            return None
        cols = []
        for n in names:
            dv = np.asarray(simulated.tangents[n], dtype=float)
            if dv.shape != simulated.vertices.shape:
                raise ConfigError(
                    f"the tangent of {n} has shape {dv.shape}, the vertices "
                    f"{simulated.vertices.shape}",
                    "forward model tangents",
                )
            col = measure.residuals_jvp(simulated, obs, dv)
            if col is None:  # no closed form (the base's): a difference of the measure
                col = directional_difference(measure, simulated, obs, dv)
            cols.append(np.asarray(col, dtype=float).ravel())
        blocks.append(np.column_stack(cols))
    return np.vstack(blocks)


@dataclasses.dataclass
class TangentProblem(InverseProblem):
    """An inverse problem whose runs ask the model for the tangents of ``tangent_names`` and
    whose records carry J = dr/dx in that order (``Evaluation.jacobian``)."""

    tangent_names: tuple[str, ...] = ()

    @classmethod
    def of(
        cls,
        problem: InverseProblem,
        names: Sequence[str],
        where: str = "levenberg_marquardt: jacobian",
        instead: str = "jacobian = 'forward' or 'central'",
    ) -> TangentProblem:
        """``problem`` with the tangents of ``names`` asked for; ConfigError (at ``where``,
        suggesting ``instead``) if the model does not give them."""
        missing = [n for n in names if n not in problem.model.tangent_inputs()]
        if missing:
            raise ConfigError(
                f"the forward model {type(problem.model).__name__} gives no tangents for "
                f"{', '.join(missing)}; use {instead}",
                where,
            )
        fields = {f.name: getattr(problem, f.name) for f in dataclasses.fields(InverseProblem)}
        return cls(**fields, tangent_names=tuple(names))

    def solve(self, full: dict[str, float], coords: Sequence[Coordinate], wd: Path) -> Solution:
        return self.model.solve(full, coords, wd, tangents=list(self.tangent_names))  # type: ignore[call-arg]

    def jacobian_from(self, solution: Solution) -> NDArray[np.float64] | None:
        """J at a run from its interfaces' tangents (a stored run's too); None without them."""
        return residual_jacobian(self, solution, self.tangent_names)

    def evaluate(
        self,
        x: Mapping[str, float],
        workdir: str | Path | None = None,
        index: int = 0,
        keep_solution: bool = True,
    ) -> Evaluation:
        ev = super().evaluate(x, workdir, index, keep_solution=True)
        if ev.ok and ev.solution is not None:
            try:
                ev.jacobian = self.jacobian_from(ev.solution)
            except MeasureError as exc:  # the iterator falls back to differences
                ev.diagnostics["tangent_jacobian"] = f"not available: {exc}"
            ev.jacobian_names = self.tangent_names if ev.jacobian is not None else ()
        if not keep_solution:
            ev.solution = None
        return ev
