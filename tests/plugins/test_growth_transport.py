"""Verification of the nutrient transport of the ``growth`` plugin (Paper A eq. 5-8).

1-D slabs (one row of triangles) against closed forms and an independent 1-D solve, a
manufactured solution on a moving (ALE) mesh, the nutrient balance on an ``ale_fsi`` flow
cell and the convergence of the interface flux (eq. 7).
"""

from __future__ import annotations

import numpy as np
import pytest

ngs = pytest.importorskip("ngsolve")

from fbia.core.errors import ForwardModelError  # noqa: E402
from fbia.plugins.fem.flow_cell import mesh_from_arrays  # noqa: E402
from fbia.plugins.growth.transport import NutrientTransport, TransportSettings  # noqa: E402

D = 2.5e-3  # mm^2/s
PHI_IN = 2.5e-11  # mol/mm^3
L = 0.1  # slab (biofilm) thickness, mm


def slab(n_solid: int, n_fluid: int = 0, fluid_length: float = 0.0):
    """Fluid [0, a] then biofilm [a, a + L], one row of 2 n triangles, inflow at x = 0."""
    xs = np.linspace(0.0, L, n_solid + 1) + fluid_length
    if n_fluid:
        xs = np.r_[np.linspace(0.0, fluid_length, n_fluid + 1)[:-1], xs]
    n = len(xs) - 1
    top = n + 1
    pts = np.array([(x, y) for y in (0.0, L / n_solid) for x in xs])
    regions: dict[str, list] = {"fluid": [], "solid": []}
    bnds: dict[str, list] = {"inflow": [(top, 0)], "walls": [], "solid_fixed": [(n, top + n)]}
    for i in range(n):
        fluid = i < n_fluid
        regions["fluid" if fluid else "solid"] += [
            (i, i + 1, top + i + 1),
            (i, top + i + 1, top + i),
        ]
        bnds["walls" if fluid else "solid_fixed"] += [(i, i + 1), (top + i + 1, top + i)]
    if n_fluid:
        bnds["interface"] = [(n_fluid, top + n_fluid)]
    regions = {k: v for k, v in regions.items() if v}
    bnds = {k: v for k, v in bnds.items() if v}
    return mesh_from_arrays(pts, regions, bnds, check=False), [n_fluid, top + n_fluid]


def rel_l2(mesh, gf, exact, length=L) -> float:
    """Root-mean-square error over the slab relative to phi_in."""
    height = max(p[1] for p in (v.point for v in mesh.vertices))
    err = ngs.Integrate((gf - exact) ** 2, mesh, order=10) / (length * height)
    return float(np.sqrt(err) / PHI_IN)


def rates(errors: list[float]) -> np.ndarray:
    return np.log2(np.array(errors[:-1]) / np.array(errors[1:]))


# -- 1. Monod reaction-diffusion in a slab ----------
def test_first_order_limit_matches_cosh_at_optimal_rate():
    """Phi << K2R: R = (K1R/K2R) Phi, Phi = phi_in cosh(m (L - x)) / cosh(m L)."""
    k2r = 1e6 * PHI_IN
    k = 36.0 * D / L**2  # m L = 6
    m = np.sqrt(k / D)
    exact = PHI_IN * ngs.cosh(m * (L - ngs.x)) / np.cosh(m * L)
    errors = []
    for n in (4, 8, 16):
        mesh, _ = slab(n)
        tr = NutrientTransport(mesh, TransportSettings(k1r=k * k2r, k2r=k2r))
        tr.solve_steady()
        errors.append(rel_l2(mesh, tr.phi, exact))
    assert errors[-1] < 2e-4
    assert np.all(rates(errors) > 2.6), (errors, rates(errors))  # P2: h^3


def test_zero_order_limit_is_the_parabola():
    """Phi >> K2R: R = K1R, Phi = phi_in - K1R/D (L x - x^2/2) (P2 holds it exactly, up to
    the O(K2R/Phi) model error)."""
    k1r = 1.0 * D * PHI_IN / L**2  # Phi(L) = phi_in / 2
    mesh, _ = slab(4)
    tr = NutrientTransport(mesh, TransportSettings(k1r=k1r, k2r=1e-6 * PHI_IN))
    tr.solve_steady()
    exact = PHI_IN - k1r / D * (L * ngs.x - ngs.x**2 / 2)
    assert rel_l2(mesh, tr.phi, exact) < 1e-5


def test_zero_order_penetration_depth():
    """Phi reaches 0 at delta = sqrt(2 D phi_in / K1R) = L/2; beyond it no nutrient is left:
    Phi = K1R/(2D) (delta - x)^2 for x < delta.  K2R = 1e-2 phi_in smooths the front (the
    K2R continuation of the solver brings Newton there)."""
    delta = L / 2
    k1r = 2 * D * PHI_IN / delta**2
    exact = ngs.IfPos(delta - ngs.x, k1r / (2 * D) * (delta - ngs.x) ** 2, 0.0)
    errors = []
    for n in (8, 16, 32):
        mesh, _ = slab(n)
        tr = NutrientTransport(mesh, TransportSettings(k1r=k1r, k2r=1e-2 * PHI_IN))
        tr.solve_steady()
        errors.append(rel_l2(mesh, tr.phi, exact))
    assert errors[-1] < 0.02, errors  # the model error of K2R/phi_in = 1e-2 dominates


def monod_reference(k1r: float, k2r: float):
    """Independent fine 1-D solve of D Phi'' = K1R Phi/(K2R + Phi), Phi(0) = phi_in,
    Phi'(L) = 0 (scipy's collocation solve_bvp, in units of phi_in)."""
    from scipy.integrate import solve_bvp

    a, b = k1r / (D * PHI_IN), k2r / PHI_IN

    def rhs(x, y):
        return np.vstack([y[1], a * y[0] / (b + np.maximum(y[0], 0.0))])

    def bc(ya, yb):
        return np.array([ya[0] - 1.0, yb[1]])

    x = np.linspace(0, L, 201)
    sol = solve_bvp(
        rhs, bc, x, np.vstack([np.ones_like(x), np.zeros_like(x)]), tol=1e-10, max_nodes=100000
    )
    assert sol.success
    return sol


def test_full_monod_against_fine_1d_solve():
    """Paper A Table 6 coefficients (K2R = 0.12 phi_in): observed h^3 against solve_bvp."""
    s = TransportSettings()
    ref = monod_reference(s.k1r, s.k2r)
    errors = []
    for n in (4, 8, 16):
        mesh, _ = slab(n)
        tr = NutrientTransport(mesh, s)
        tr.solve_steady()
        ir_x = np.linspace(0, L, 401)
        phi_h = np.array([tr.phi(mesh(x, 0.0)) for x in ir_x])
        errors.append(float(np.sqrt(np.mean((phi_h / PHI_IN - ref.sol(ir_x)[0]) ** 2))))
    assert errors[-1] < 1e-4, errors
    assert np.all(rates(errors) > 2.5), (errors, rates(errors))


# -- 4. the interface flux ----------
def test_interface_flux_converges_to_the_exact_flux():
    """Fluid [0, a] (D_fluid) then biofilm (D_biofilm, first order): Phi linear in the fluid,
    A cosh(m (a + L - x)) in the biofilm; h = D_b A m sinh(m L) > 0 into the biofilm."""
    a, d_f, d_b = 0.05, 4e-3, 2e-3
    k2r = 1e6 * PHI_IN
    m = 4.0 / L
    k1r = m**2 * d_b * k2r
    # flux continuity: d_f (phi_in - A cosh(mL)) / a = d_b A m sinh(mL)
    A = PHI_IN * d_f / a / (d_f / a * np.cosh(m * L) + d_b * m * np.sinh(m * L))
    h_exact = d_b * A * m * np.sinh(m * L)
    errors = []
    for n in (2, 4, 8, 16):
        mesh, verts = slab(n, n_fluid=n, fluid_length=a)
        tr = NutrientTransport(
            mesh, TransportSettings(d_fluid=d_f, d_biofilm=d_b, k1r=k1r, k2r=k2r)
        )
        tr.solve_steady()
        h = tr.interface_flux(verts)
        assert h.shape == (2,)
        errors.append(float(np.max(np.abs(h / h_exact - 1.0))))
        bal = tr.balance()
        assert bal["inflow"] == pytest.approx(bal["consumption"], rel=1e-8, abs=0.0)
        # all of it enters the biofilm: the lumped flux sums to the uptake exactly
        assert bal["inflow"] == pytest.approx(np.sum(h) * L / n / 2, rel=1e-8, abs=0.0)
        assert bal["uptake"] == pytest.approx(bal["consumption"], rel=1e-8, abs=0.0)
    # measured: 1.3e-2, 3.7e-3, 1.1e-3, 3.0e-4 (rates 1.8, 1.8, 1.9)
    assert errors[-1] < 6e-4, errors
    assert np.all(rates(errors) > 1.6), (errors, rates(errors))


# -- 2. manufactured solution on a moving mesh ----------
def square(n: int, region: str = "fluid", boundary: str = "inflow"):
    """Unit square, one region, every boundary one name (default: fluid, Dirichlet inflow)."""
    xs = np.linspace(0.0, 1.0, n + 1)
    pts = np.array([(x, y) for y in xs for x in xs])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    tris = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = idx[j, i], idx[j, i + 1], idx[j + 1, i + 1], idx[j + 1, i]
            tris += [(a, b, c), (a, c, d)]
    bnd = [(idx[0, i], idx[0, i + 1]) for i in range(n)] + [
        (idx[n, i + 1], idx[n, i]) for i in range(n)
    ]
    bnd += [(idx[j, n], idx[j + 1, n]) for j in range(n)] + [
        (idx[j + 1, 0], idx[j, 0]) for j in range(n)
    ]
    return mesh_from_arrays(pts, {region: tris}, {boundary: bnd}, check=False)


VEL = (1.0, 0.5)  # mm/s, divergence free
D_MMS = 0.02


def exact_phi(x, y, t=0.0):
    """Phi(x, y, t) = 1 + 0.5 sin(pi x) cos(pi y) cos(t) with its gradient and Laplacian."""
    pi = np.pi
    s, c = ngs.sin(pi * x) * ngs.cos(pi * y), ngs.cos(t)
    value = 1.0 + 0.5 * s * c
    grad = (
        0.5 * pi * ngs.cos(pi * x) * ngs.cos(pi * y) * c,
        -0.5 * pi * ngs.sin(pi * x) * ngs.sin(pi * y) * c,
    )
    lap = -(pi**2) * s * c
    dt = -0.5 * s * ngs.sin(t)
    return value, grad, lap, dt


def bump(amplitude):
    """Mesh displacement d(X) = amplitude sin(pi X) sin(pi Y) (1, 0.5) (0 on the boundary)."""
    b = amplitude * ngs.sin(np.pi * ngs.x) * ngs.sin(np.pi * ngs.y)
    return ngs.CF((b, 0.5 * b)), b


def test_ale_advection_diffusion_steady_optimal_rates():
    """A deformed mesh with mesh velocity w: (v - w) . grad Phi - D lap Phi = f on Omega(d),
    Phi exact on the boundary, f composed with x = X + d(X).  Pe_h up to 3: SUPG on."""
    disp, b = bump(0.1)
    w = ngs.CF((0.3 * b / 0.1, -0.2 * b / 0.1))  # an arbitrary mesh velocity field
    x, y = ngs.x + disp[0], ngs.y + disp[1]
    value, grad, lap, _ = exact_phi(x, y)
    c = (VEL[0] - w[0], VEL[1] - w[1])
    f = c[0] * grad[0] + c[1] * grad[1] - D_MMS * lap
    errors = {}
    for stabilise in (True, False):
        errors[stabilise] = []
        for n in (4, 8, 16):
            mesh = square(n)
            s = TransportSettings(d_fluid=D_MMS, phi_in=1.0, stabilise=stabilise)
            tr = NutrientTransport(mesh, s, source=f, inflow_value=value)
            tr.set_flow(ngs.CF(VEL), disp, w)
            tr.solve_steady()
            J = ngs.Det(ngs.Id(2) + ngs.Grad(tr.displacement))
            errors[stabilise].append(
                float(np.sqrt(ngs.Integrate((tr.phi - value) ** 2 * J, mesh, order=8)))
            )
    for stabilise, err in errors.items():
        assert err[-1] < 2e-4, (stabilise, err)
        assert np.all(rates(err) > 2.8), (stabilise, err, rates(err))  # P2: h^3


def test_supg_removes_the_wiggles_of_a_boundary_layer():
    """c = (1, 0), D = 1e-3, Phi = 1 on the left and 0 on the right (exponential layer of
    width D at x = 1), mesh Peclet number |c| h / (2 D) = 31 (P2, h = 1/16): Galerkin
    oscillates through the whole square, SUPG stays accurate away from the layer."""
    d_fluid = 1e-3
    x = np.repeat(np.linspace(0.0, 0.7, 36), 9)
    y = np.tile(np.linspace(0.1, 0.9, 9), 36)
    exact = (1.0 - np.exp((x - 1.0) / d_fluid)) / (1.0 - np.exp(-1.0 / d_fluid))
    error, top = {}, {}
    for stabilise in (True, False):
        mesh = square(8)
        s = TransportSettings(d_fluid=d_fluid, phi_in=1.0, stabilise=stabilise)
        tr = NutrientTransport(mesh, s, inflow_value=ngs.IfPos(0.999 - ngs.x, 1.0, 0.0))
        tr.set_flow(ngs.CF((1.0, 0.0)))
        tr.solve_steady()
        values = np.array([tr.phi(mesh(a, b)) for a, b in zip(x, y, strict=True)])
        error[stabilise] = float(np.max(np.abs(values - exact)))
        top[stabilise] = float(tr.phi.vec.FV().NumPy()[: mesh.nv].max())
    # measured: SUPG 1.1e-2 (vertex max 1.0), Galerkin 1.6 (vertex max 1.32)
    assert error[True] < 0.03 and error[False] > 0.5, error
    assert top[True] < 1.1 < top[False], top


def test_ale_transient_first_order_in_time():
    """Backward Euler on the mesh d(X, t) = 0.1 sin(pi t) bump, w = (d^n+1 - d^n)/dt: the
    error at T = 0.4 halves with dt (P2 on a fine enough mesh)."""
    mesh = square(12)
    T = 0.4
    errors = []
    for steps in (4, 8, 16):
        dt = T / steps
        tp = ngs.Parameter(0.0)
        disp_of = lambda t: bump(0.1 * np.sin(np.pi * t))[0]  # noqa: E731
        disp_t = bump(0.1 * ngs.sin(np.pi * tp))[0]
        x, y = ngs.x + disp_t[0], ngs.y + disp_t[1]
        value, grad, lap, dphidt = exact_phi(x, y, tp)
        f = dphidt + VEL[0] * grad[0] + VEL[1] * grad[1] - D_MMS * lap  # Eulerian form
        tr = NutrientTransport(
            mesh, TransportSettings(d_fluid=D_MMS, phi_in=1.0), source=f, inflow_value=value
        )
        tr.phi.Set(value)
        for k in range(1, steps + 1):
            t0, t1 = (k - 1) * dt, k * dt
            tp.Set(t1)
            w = (disp_of(t1) - disp_of(t0)) / dt
            tr.set_flow(ngs.CF(VEL), disp_of(t1), w)
            tr.step(dt)
        J = ngs.Det(ngs.Id(2) + ngs.Grad(tr.displacement))
        errors.append(float(np.sqrt(ngs.Integrate((tr.phi - value) ** 2 * J, mesh, order=8))))
        bal = tr.balance()
        assert abs(bal["residual"]) < 1e-3 * abs(bal["source"]) + 1e-6, bal
    assert np.all(np.abs(rates(errors) - 1.0) < 0.25), (errors, rates(errors))


def test_moving_biofilm_keeps_its_content():
    """Eq. 5b without consumption in a closed biofilm that swells and shears, d(X, t) =
    0.2 t (X^2, X Y): the content int Phi dx is conserved by the ALE form (the Phi div w
    term), up to the backward-Euler error, which halves with dt."""
    mesh = square(6, region="solid", boundary="solid_fixed")
    s = TransportSettings(k1r=0.0, d_biofilm=0.01, phi_in=1.0)
    X, Y = ngs.x, ngs.y

    def disp(t: float):
        return ngs.CF((0.2 * t * X**2, 0.2 * t * X * Y))

    drift = []
    for steps in (4, 8):
        tr = NutrientTransport(mesh, s)
        tr.phi.Set(1.0 + 0.5 * ngs.cos(np.pi * X))
        J0 = 1.0
        content0 = ngs.Integrate(tr.phi * J0, mesh, order=8)
        dt = 1.0 / steps
        for k in range(1, steps + 1):
            tr.set_flow(None, disp(k * dt), (disp(k * dt) - disp((k - 1) * dt)) / dt)
            tr.step(dt)
            bal = tr.balance()
            assert abs(bal["storage"]) < 0.05 * content0, bal  # d/dt content ~ 0
        J = ngs.Det(ngs.Id(2) + ngs.Grad(tr.displacement))
        drift.append(abs(ngs.Integrate(tr.phi * J, mesh, order=8) / content0 - 1.0))
    # measured: 1.1e-2, 5.9e-3 (first order in dt)
    assert drift[-1] < 0.6 * drift[0] and drift[-1] < 1e-2, drift


# -- 3. global balance on the flow cell ----------
def test_balance_on_the_flow_cell_shrinks_with_the_mesh():
    from fbia.plugins.ale_fsi.solver import AleFsiSolver, SolverSettings
    from fbia.plugins.fem.flow_cell import build_flow_cell

    residuals = []
    for h in (0.12, 0.06):
        mesh = build_flow_cell(
            length=1.0,
            height=0.5,
            outline=[(0.3, 0.0), (0.4, 0.1), (0.5, 0.12), (0.6, 0.0)],
            mesh_size=h,
            interface_mesh_size=h / 3,
        )
        fsi = AleFsiSolver(mesh, SolverSettings())
        fsi.set_materials({r: (400.0, 0.3) for r in fsi.solids})
        fsi.solve_steady(0.1)
        tr = NutrientTransport(mesh, TransportSettings())
        tr.set_flow(fsi.velocity, fsi.displacement)
        tr.solve_steady()
        bal = tr.balance()
        assert bal["consumption"] > 0.0 and bal["inflow"] > bal["outflow"] > 0.0, bal
        residuals.append(abs(bal["residual"]) / bal["consumption"])
        assert bal["uptake"] == pytest.approx(bal["consumption"], rel=1e-8, abs=0.0)
    # measured: 5.2e-4, 1.0e-4 of the consumption (1.8e-5 at h = 0.03)
    assert residuals[-1] < 0.5 * residuals[0] and residuals[-1] < 5e-4, residuals
    # transient from Phi = phi_in: the biofilm empties, the storage rate is negative
    steady = tr.phi.vec.FV().NumPy().copy()
    tr.phi.Set(PHI_IN)
    for _ in range(2):
        tr.step(0.5)
        bal = tr.balance()
        assert bal["storage"] < -0.5 * bal["consumption"] < 0.0, bal
        assert abs(bal["residual"]) < 1e-3 * bal["consumption"], bal  # measured 2e-5, 4e-5
        J = ngs.Det(ngs.Id(2) + ngs.Grad(tr.displacement))
        solid = mesh.Materials("solid")
        stored = ngs.Integrate((tr.phi - tr.phi_old) / 0.5 * J, mesh, definedon=solid, order=8)
        uptake = bal["consumption"] + stored  # what enters the biofilm (w = 0 here)
        assert bal["uptake"] == pytest.approx(uptake, rel=1e-6, abs=0.0)  # up to quadrature
    tr.step(1e4)  # a long step lands on the quasi-steady state
    assert np.max(np.abs(tr.phi.vec.FV().NumPy() - steady)) < 1e-3 * PHI_IN


def test_newton_failure_is_a_forward_model_error():
    mesh, _ = slab(4)
    tr = NutrientTransport(mesh, TransportSettings(newton_tol=1e-30))
    with pytest.raises(ForwardModelError) as err:
        tr.solve_steady()
    assert err.value.reason.startswith("transport_")
    mesh = square(2)
    tr = NutrientTransport(mesh, TransportSettings())
    before = tr.phi.vec.FV().NumPy().copy()
    tr.set_flow(ngs.CF((float("nan"), 0.0)))
    with pytest.raises(ForwardModelError) as err:
        tr.step(0.1)
    assert err.value.reason == "transport_nan"
    assert np.array_equal(tr.phi.vec.FV().NumPy(), before)  # the state is kept
