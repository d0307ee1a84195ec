"""Conformance of measures: a distance between interfaces, in 2-D and 3-D."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..core.interface import Interface
from ..core.observation import Observation
from ..core.protocols import MeasureBase, missing_methods
from .errors import fail
from .samples import circle_2d, mound_2d, sphere_3d, square_3d, straight_line_2d


@dataclass(frozen=True)
class MeasureCase:
    """An observation and two simulated interfaces at a small and a larger deviation.

    The observation holds both the observed interface and measurement points on it (with the
    observed vertex normals as directions), so that point-, projection- and surface-based
    measures all find what they need.  ``simulated`` and ``farther`` are meshed differently
    from the observed interface and from each other.
    """

    name: str
    observation: Observation
    simulated: Interface
    farther: Interface

    @property
    def dim(self) -> int:
        return self.observation.dim


def _case(name: str, observed: Interface, simulated: Interface, farther: Interface) -> MeasureCase:

    n = len(observed.vertices)
    interior = np.arange(n)
    if observed.dim == 2 and len(observed.curves()) == 1 and observed.curves()[0].shape[0] == n:
        interior = interior[1:-1]  # open curve: no rays from its end points
    elif observed.dim == 3:
        lo, hi = observed.bounds
        margin = 0.05 * (hi - lo)
        inside = np.all((observed.vertices >= lo + margin) | (hi - lo < 1e-12), axis=1) & np.all(
            (observed.vertices <= hi - margin) | (hi - lo < 1e-12), axis=1
        )
        interior = interior[inside]
    pick = interior[:: max(1, len(interior) // 12)]
    obs = Observation(
        interface=observed,
        coordinate={"inflow_rate": 100.0},
        points=observed.vertices[pick],
        directions=observed.vertex_normals[pick],
        name=name,
    )
    return MeasureCase(name, obs, simulated, farther)


def measure_cases(dims: Iterable[int] = (2, 3)) -> list[MeasureCase]:
    """The sample cases :func:`check_measure` uses: straight and curved, 2-D and 3-D.

    Sizes in mm: a 1 mm floor and a 0.2 mm high mound (elements about 0.015 mm), a circle
    and a sphere of radius 0.3 mm; deviations of 0.01 to 0.06 mm.  A measure with a length
    scale (e.g. an RKHS kernel width) should be given one of about 0.05 mm.
    """
    dims = set(dims)
    cases = []
    if 2 in dims:
        cases += [
            _case(
                "line_2d",
                straight_line_2d(n=48),
                straight_line_2d(n=37, height=0.02, slope=0.02),
                straight_line_2d(n=41, height=0.04, slope=0.04),
            ),
            _case(
                "mound_2d",
                mound_2d(height=0.2, n=64),
                mound_2d(height=0.23, n=53),
                mound_2d(height=0.28, n=71),
            ),
            _case(
                "circle_2d",
                circle_2d(0.3, n=96),
                circle_2d(0.32, n=80, centre=(0.01, 0.0)),
                circle_2d(0.36, n=88, centre=(0.02, 0.0)),
            ),
        ]
    if 3 in dims:
        cases += [
            _case(
                "square_3d",
                square_3d(0.4, n=12),
                square_3d(0.4, n=11, height=0.02, slope=(0.02, 0.01)),
                square_3d(0.4, n=13, height=0.04, slope=(0.04, 0.02)),
            ),
            _case(
                "sphere_3d",
                sphere_3d(0.2, 2),
                sphere_3d(0.22, 2, centre=(0.01, 0.0, 0.0)),
                sphere_3d(0.25, 1, centre=(0.02, 0.0, 0.0)).refined(1),
            ),
        ]
    if not cases:
        raise ValueError(f"no measure cases for dims {sorted(dims)}; valid: 2, 3")
    return cases


def _measure_values(
    measure: Any, gamma: Interface, obs: Observation, where: str
) -> tuple[NDArray[np.float64], float]:
    """Residuals and distance of ``gamma``, checked for type, shape and finiteness."""

    try:
        r = measure.residuals(gamma, obs)
        d = measure.distance(gamma, obs)
    except Exception as exc:
        raise fail(measure, f"{where} interface: {type(exc).__name__}: {exc}") from exc
    if not isinstance(r, np.ndarray) or r.ndim != 1:
        raise fail(
            measure,
            f"{where}: residuals must be a 1-D numpy array, got "
            f"{type(r).__name__} of shape {np.shape(r)}",
        )
    if not np.all(np.isfinite(r)):
        raise fail(measure, f"{where}: residuals are not all finite")
    if not isinstance(d, (float, np.floating)) or not math.isfinite(d) or d < 0:
        raise fail(measure, f"{where}: distance must be a finite float >= 0, got {d!r}")
    return r.astype(float, copy=False), float(d)


def check_measure(
    measure: Any,
    dims: Iterable[int] | None = None,
    cases: Sequence[MeasureCase] | None = None,
    rtol: float = 0.03,
    residual_rtol: float = 0.15,
    zero_tol: float = 1e-5,
    mesh_dependent: bool | None = None,
) -> dict[str, dict[str, float]]:
    """Prove that ``measure`` behaves like a distance between interfaces, in 2-D and 3-D.

    It checks that it has the methods its contract requires
    (:class:`fbia.Discrepancy`), and for every case of :func:`measure_cases` (or
    ``cases``) that

    * the residuals are a finite 1-D array and the distance a finite float >= 0;
    * the observed interface is at distance zero from itself (``distance`` and the residual
      norm below ``zero_tol`` times those of the simulated interface);
    * a different interface is at a positive distance, and a larger deviation (``farther``)
      at a larger one;
    * the residual vector has the same length for every simulated interface (the
      Levenberg-Marquardt Jacobian needs it), whatever its mesh;
    * re-meshing does not matter: the simulated interface refined once
      (:meth:`fbia.Interface.refined`, the same polygon or polyhedron) gives the distance and
      the residual norm to ``rtol`` (relative), and a residual vector that differs by at most
      ``residual_rtol`` times its norm (kernel measures sample fields whose quadrature
      depends on the mesh, hence the looser bound);
    * repeated calls give identical values.

    ``dims`` and ``mesh_dependent`` default to what the measure declares (its contract's
    optional members ``dims``, default ``(2, 3)``, and ``mesh_dependent``, default False). A
    measure whose residuals belong to the simulated mesh (one per simulated vertex, like the
    closest-point-projection distances of Paper B eq. 7) is declared with
    ``mesh_dependent = True``: the residual-length and re-meshing checks are then left out and
    all others kept.

    Returns ``{case: {"identical": D0, "simulated": D1, "refined": D1r, "farther": D2}}``.
    """

    if not isinstance(measure, MeasureBase):
        raise fail(measure, "does not derive from fbia.MeasureBase")
    lacking = missing_methods("measure", measure)
    if lacking:
        raise fail(measure, f"lacks the method(s) its contract requires: {', '.join(lacking)}")
    if dims is None:
        dims = tuple(measure.dims)
    if mesh_dependent is None:
        mesh_dependent = bool(measure.mesh_dependent)
    cases = measure_cases(dims) if cases is None else list(cases)
    out: dict[str, dict[str, float]] = {}
    for case in cases:
        obs = case.observation
        where = f"case {case.name!r}"

        r0, d0 = _measure_values(measure, obs.interface, obs, f"{where}, identical")  # type: ignore[arg-type]
        r1, d1 = _measure_values(measure, case.simulated, obs, f"{where}, simulated")
        r1b, d1b = _measure_values(measure, case.simulated, obs, f"{where}, simulated, repeated")
        rr, dr = _measure_values(
            measure, case.simulated.refined(1), obs, f"{where}, simulated, refined"
        )
        r2, d2 = _measure_values(measure, case.farther, obs, f"{where}, farther")
        if d1 <= 0.0:
            raise fail(measure, f"{where}: distance 0 between different interfaces")
        if not (d0 <= zero_tol * d1 and np.linalg.norm(r0) <= zero_tol * np.linalg.norm(r1)):
            raise fail(
                measure,
                f"{where}: an interface is not at distance zero from itself: D = {d0:.3g}, "
                f"|r| = {np.linalg.norm(r0):.3g} (vs D = {d1:.3g} for a different one)",
            )
        if not d2 > d1:
            raise fail(
                measure,
                f"{where}: a larger deviation gives no larger distance ({d2:.6g} <= {d1:.6g})",
            )
        if d1b != d1 or not np.array_equal(r1b, r1):
            raise fail(measure, f"{where}: repeated calls give different values")
        if not mesh_dependent:
            shapes = {r0.shape, r1.shape, rr.shape, r2.shape}
            if len(shapes) != 1:
                raise fail(
                    measure,
                    f"{where}: the residual length depends on the simulated mesh: "
                    f"{r0.shape[0]} (identical), {r1.shape[0]} (simulated), {rr.shape[0]} "
                    f"(refined), {r2.shape[0]} (farther)",
                )
            if abs(dr - d1) > rtol * d1:
                raise fail(
                    measure,
                    f"{where}: re-meshing the same geometry changes the distance from {d1:.6g} to "
                    f"{dr:.6g} (relative {abs(dr - d1) / d1:.2g} > {rtol:g})",
                )
            n1, nr = float(np.linalg.norm(r1)), float(np.linalg.norm(rr))
            if abs(nr - n1) > rtol * n1:
                raise fail(
                    measure,
                    f"{where}: re-meshing the same geometry changes the residual norm from "
                    f"{n1:.6g} to {nr:.6g} (relative {abs(nr - n1) / n1:.2g} > {rtol:g})",
                )
            change = float(np.linalg.norm(rr - r1))
            if change > residual_rtol * n1:
                raise fail(
                    measure,
                    f"{where}: re-meshing the same geometry changes the residual vector by "
                    f"{change:.3g} (> {residual_rtol:g} x its norm {n1:.3g})",
                )
        out[case.name] = {"identical": d0, "simulated": d1, "refined": dr, "farther": d2}
    return out
