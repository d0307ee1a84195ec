"""The 3-D Schäfer-Turek benchmark 3D-1Z (steady flow past a cylinder, Re = 20), for verification.

Schäfer & Turek 1996 define it in SI units: channel [0, 2.5] x [0, 0.41] x [0, 0.41] m, a
cylinder of diameter D = 0.1 m with axis along z through (0.5, 0.2), inflow
U(0, y, z) = 16 U_m y z (H - y)(H - z) / H^4 with U_m = 0.45 m/s, nu = 1e-3 m^2/s, rho = 1,
no-slip walls and cylinder, do-nothing outflow; c_D = 2 F_D / (rho U^2 D H) and
c_L = 2 F_L / (rho U^2 D H) with the mean velocity U = 4/9 U_m = 0.2 m/s.  Reference values:
tests/data/fsi/schaefer_turek_1996_3d.json (Schäfer & Turek 1996; Braack & Richter 2006).

>>> from fbia.plugins.ale_fsi import schaefer_turek_3d
>>> r = schaefer_turek_3d.solve(mesh_size=0.1, cylinder_mesh_size=0.02)   # doctest: +SKIP
>>> r.c_drag, r.c_lift                                                      # doctest: +SKIP
(6.1..., 0.009...)

This is a self-contained steady Navier-Stokes solve (P2/P1 Taylor-Hood, Newton on the
residual, sparse direct solver), not the ALE model: the obstacle is rigid and fixed, so the
ALE machinery would add only a zero displacement field.  It checks the same ingredients the 3-D
``ale_fsi`` uses (netgen/OCC 3-D meshes, Taylor-Hood on curved tetrahedra, the Newton solve,
forces on a boundary).  Drag and lift come from the residual of the weak form tested with a
velocity field equal to e_x (e_y) on the cylinder and zero on the other Dirichlet faces, the
"variational" force evaluation, more accurate than integrating the stress over the surface
(as in Braack & Richter 2006).  Coarse meshes can leave a P1 pressure at a box corner coupled
to no free velocity (Boffi 1997); such pressures are fixed to zero, see
:func:`_inf_sup_free_dofs`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from ...core.errors import ConfigError, ForwardModelError
from ..fem.newton import sparse_direct_solver

#: Geometry in m (Schäfer & Turek 1996, Fig. 3).
LENGTH = 2.5
HEIGHT = 0.41
CENTRE = (0.5, 0.2)
DIAMETER = 0.1
#: Flow data (Schäfer & Turek 1996, Sec. 2.2, case 3D-1Z).
U_MAX = 0.45
NU = 1e-3
RHO = 1.0
U_MEAN = 4.0 / 9.0 * U_MAX


@dataclass(frozen=True)
class SchaeferTurek3dResult:
    """Drag and lift coefficients of 3D-1Z on one mesh, with the cost of getting them."""

    c_drag: float
    c_lift: float
    ndof: int
    elements: int
    newton_iterations: int
    wall_time: float


def build_mesh(mesh_size: float, cylinder_mesh_size: float | None = None, order: int = 2) -> Any:
    """Tetrahedral mesh of the 3D-1Z channel, boundaries named inflow/outflow/walls/cylinder.

    Parameters
    ----------
    mesh_size
        Maximum element size in the channel (m).
    cylinder_mesh_size
        Element size on the cylinder surface (m); default ``mesh_size / 4``.
    order
        Geometry order of the curved cylinder faces.
    """
    import ngsolve
    from netgen.occ import Box, Cylinder, OCCGeometry, Pnt, X, Z

    h_cyl = cylinder_mesh_size if cylinder_mesh_size is not None else mesh_size / 4.0
    if min(mesh_size, h_cyl) <= 0:
        raise ConfigError("mesh sizes must be positive", "schaefer_turek_3d mesh")
    box = Box(Pnt(0, 0, 0), Pnt(LENGTH, HEIGHT, HEIGHT))
    box.faces.name = "walls"
    box.faces.Min(X).name = "inflow"
    box.faces.Max(X).name = "outflow"
    cyl = Cylinder(Pnt(CENTRE[0], CENTRE[1], 0.0), Z, r=DIAMETER / 2.0, h=HEIGHT)
    cyl.faces.name = "cylinder"
    cyl.faces.maxh = h_cyl
    shape = box - cyl
    ngmesh = OCCGeometry(shape).GenerateMesh(maxh=mesh_size)
    mesh = ngsolve.Mesh(ngmesh)
    mesh.Curve(order)
    return mesh


def solve(
    mesh_size: float,
    cylinder_mesh_size: float | None = None,
    linear_solver: str | None = None,
    tol: float = 1e-10,
    max_iterations: int = 12,
) -> SchaeferTurek3dResult:
    """Solve 3D-1Z on one mesh and return c_D and c_L (Schäfer & Turek 1996, Eq. for c_D, c_L).

    Newton starts from the Stokes solution; it stops when the Newton update's Euclidean norm
    falls below ``tol`` (the velocity is O(0.1) m/s).
    """
    import ngsolve as ng

    t0 = time.perf_counter()
    mesh = build_mesh(mesh_size, cylinder_mesh_size)
    solver = linear_solver or sparse_direct_solver()
    dirichlet = "inflow|walls|cylinder"
    V = ng.VectorH1(mesh, order=2, dirichlet=dirichlet)
    Q = ng.H1(mesh, order=1)
    X = V * Q
    (u, p), (v, q) = X.TnT()
    gfu = ng.GridFunction(X)
    vel = gfu.components[0]

    # steady Navier-Stokes: nu (grad u, grad v) + ((u.grad) u, v) - (p, div v) - (div u, q)
    # = 0; the gradient (not symmetric-gradient) form gives the do-nothing outflow of the
    # benchmark (Schäfer & Turek 1996, Sec. 2.2).
    stokes = NU * ng.InnerProduct(ng.grad(u), ng.grad(v)) - ng.div(v) * p - ng.div(u) * q
    a = ng.BilinearForm(X)
    a += (stokes + ng.InnerProduct(ng.grad(u) * u, v)) * ng.dx
    y, z = ng.y, ng.z
    inflow = ng.CoefficientFunction(
        (16.0 * U_MAX * y * z * (HEIGHT - y) * (HEIGHT - z) / HEIGHT**4, 0.0, 0.0)
    )

    free = _inf_sup_free_dofs(V, Q, X)

    # Stokes start
    s = ng.BilinearForm(X)
    s += stokes * ng.dx
    s.Assemble()
    vel.Set(inflow, definedon=mesh.Boundaries("inflow"))
    res = gfu.vec.CreateVector()
    res.data = -s.mat * gfu.vec
    gfu.vec.data += s.mat.Inverse(free, inverse=solver) * res

    du = gfu.vec.CreateVector()
    iterations = 0
    while True:
        iterations += 1
        a.Apply(gfu.vec, res)
        a.AssembleLinearization(gfu.vec)
        du.data = a.mat.Inverse(free, inverse=solver) * res
        gfu.vec.data -= du
        step = ng.Norm(du)
        if step < tol:
            break
        if iterations >= max_iterations:
            raise ForwardModelError(
                f"schaefer_turek_3d: Newton did not converge in {max_iterations} iterations "
                f"(|du| = {step:.2e})",
                "newton_max_iterations",
            )

    # variational forces: F_i = -r(u, p; w_i), w_i = e_i on the cylinder, 0 on the other
    # Dirichlet faces (interior values arbitrary; here the P2 extension by zero)
    forces = []
    w = ng.GridFunction(X)
    for direction in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        w.vec[:] = 0.0
        w.components[0].Set(
            ng.CoefficientFunction(direction), definedon=mesh.Boundaries("cylinder")
        )
        a.Apply(gfu.vec, res)
        forces.append(-RHO * ng.InnerProduct(res, w.vec))
    scale = 2.0 / (RHO * U_MEAN**2 * DIAMETER * HEIGHT)
    return SchaeferTurek3dResult(
        c_drag=scale * forces[0],
        c_lift=scale * forces[1],
        ndof=X.ndof,
        elements=mesh.ne,
        newton_iterations=iterations,
        wall_time=time.perf_counter() - t0,
    )


def _inf_sup_free_dofs(V: Any, Q: Any, X: Any) -> Any:
    """The free dofs of ``X = V x Q`` without the pressures that no free velocity sees.

    A tetrahedron at a corner where three Dirichlet faces meet can have all its P2 velocity
    dofs on the Dirichlet boundary; if such a corner vertex belongs to that tetrahedron only,
    its P1 pressure is not coupled to any free velocity and the saddle-point matrix is singular
    (the classical local failure of Taylor-Hood at corners, Boffi 1997).  That pressure is set
    to zero: it enters neither the momentum equations nor the forces on the cylinder.
    """
    import ngsolve as ng
    import numpy as np

    u, q = V.TrialFunction(), Q.TestFunction()
    b = ng.BilinearForm(trialspace=V, testspace=Q)
    b += ng.div(u) * q * ng.dx
    b.Assemble()
    rows, cols, vals = b.mat.COO()
    vfree = np.array(V.FreeDofs(), dtype=bool)
    keep = vfree[np.asarray(cols)] & (np.abs(np.asarray(vals)) > 0.0)
    seen = np.zeros(Q.ndof, dtype=bool)
    seen[np.asarray(rows)[keep]] = True
    free = ng.BitArray(X.FreeDofs())
    offset = V.ndof
    for i in np.flatnonzero(~seen):
        free[offset + int(i)] = False
    return free
