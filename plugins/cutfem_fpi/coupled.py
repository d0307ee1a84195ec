"""Partitioned fluid-poroelastic interaction on two meshes: flow | skeleton, quasi-Newton.

* flow (:mod:`.flow`): Navier-Stokes in the channel and Darcy in the biofilm on a **fixed**
  background mesh of the channel, cut by the level set of the current (deformed) biofilm;
* skeleton (:mod:`.skeleton`): displacement and porosity on the biofilm's own fitted mesh in
  the reference configuration (curved along the outline), loaded by the pore pressure and the
  fluid shear.

One coupling iteration: level set from the deformed boundary (P2 nodal interpolant of the
signed distance to a densely sampled polygon, :class:`NodalLevelSet`) -> permeability
``k = J^-1 F K F^T`` with Kozeny-Carman ``K`` (eq. 11) moved to the background mesh -> flow
solve -> pore pressure on the interface and shear moved to the skeleton (evaluated at the
deformed skeleton points), the pore pressure inside rebuilt from its interface values by
steady Darcy on the skeleton mesh (exact for any K, and the accurate part of the flow's
``p_d`` when ``K << h^2``, see :mod:`.flow`) -> skeleton Newton -> update of the skeleton
state by interface quasi-Newton (IQN-ILS) or Aitken relaxation.  Steady problem: no
added-mass instability.

Cost (Paper A example, default meshes): the flow dominates.  Its forms and the analysis of
its factorisation are kept while the cut elements do not change, Newton solves are inexact
in early coupling iterations, and the skeleton factorisation is analysed once; every
transfer between the meshes is continuous in the displacement, so the fixed-point map has no
noise floor that would stall the iteration.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ForwardModelError
from .flow import CutFlow, FlowSettings
from .skeleton import Skeleton, SkeletonSettings, kozeny_carman


@dataclass(frozen=True)
class CouplingSettings:
    """Numerics of the partitioned scheme (lengths in mm)."""

    tol: float = 1e-6  # interface displacement change that ends the coupling [mm]
    max_iter: int = 40
    omega0: float = 0.5  # first relaxation factor (both accelerations)
    omega_max: float = 1.5  # bound of Aitken's factor
    samples_per_edge: int = 4  # polygon points per skeleton interface edge (level set)
    voxel_size: float = 0.004  # grid of the signed-distance level set [mm]
    level_set: str = "nodal"  # "nodal": P2 interpolant on the background mesh; "voxel"
    acceleration: str = "iqn_ils"  # "iqn_ils" or "aitken"
    inexact: float = 0.1  # Newton tolerances: inexact * (last interface change) / height
    pore_pressure: str = "interface"  # skeleton pore pressure: "interface" or "volume"


@dataclass
class CouplingReport:
    iterations: int = 0
    omegas: list[float] = field(default_factory=list)
    changes: list[float] = field(default_factory=list)
    times: dict[str, float] = field(
        default_factory=lambda: {"level_set": 0.0, "flow": 0.0, "skeleton": 0.0, "transfer": 0.0}
    )
    flow_iterations: int = 0
    skeleton_iterations: int = 0


class InterfaceSampler:
    """Ordered points on the skeleton interface (solid on the right, upstream first):
    ``per_edge`` points per interface edge, on the (possibly curved) edge itself."""

    def __init__(self, mesh: Any, per_edge: int) -> None:
        import ngsolve as ngs

        from ..fem.flow_cell import interface_chains

        chains = interface_chains(mesh, ngs)
        if len(chains) != 1:
            raise ForwardModelError(
                f"the biofilm interface must be one open curve, got {len(chains)}", "bad_mesh"
            )
        # reference coordinate x of a segment runs from its second vertex (x = 0) to its
        # first (x = 1)
        s = np.linspace(0.0, 1.0, per_edge + 1)
        ir = ngs.IntegrationRule([(float(x),) for x in s], [0.0] * len(s))
        mapped = mesh.MapToAllElements(ir, ngs.BND)
        bnd = list(mesh.Elements(ngs.BND))
        take = []
        for el, start in chains[0]:
            first = bnd[el].vertices[0].nr == start
            local = (per_edge - np.arange(per_edge)) if first else np.arange(per_edge)
            take.append(el * len(s) + local)
        el, start = chains[0][-1]
        take.append(np.array([el * len(s) + (0 if bnd[el].vertices[0].nr == start else per_edge)]))
        self._mp = mapped[np.concatenate(take)]
        self.reference = np.asarray(ngs.CoefficientFunction((ngs.x, ngs.y))(self._mp)).reshape(
            -1, 2
        )
        self.mesh = mesh

    def deformed(self, displacement: Any) -> NDArray[np.float64]:
        return self.reference + np.asarray(displacement(self._mp)).reshape(-1, 2)


def polyline_distance(
    points: NDArray[np.float64], curve: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Euclidean distance of ``points`` (n, 2) to the polyline ``curve`` (m, 2), vectorised.

    The closest point of a densely sampled curve lies on a segment near the curve vertex
    nearest to the query point; the three segments on either side of that vertex are
    searched.  Exact where the curve is sampled finer than its distance to the point and to
    other parts of itself (on the biofilm interface: everywhere in the channel, checked
    against GEOS in the tests); elsewhere an upper bound.
    """
    c2 = np.einsum("si,si->s", curve, curve)
    offsets = np.arange(-3, 3)
    out = np.empty(len(points))
    block = max(1, 2_000_000 // len(curve))
    for i in range(0, len(points), block):
        p = points[i : i + block]
        # |p - c|^2 - |p|^2 without a BLAS call (a threaded GEMM would spin on a busy machine)
        cross = p[:, 0, None] * curve[None, :, 0] + p[:, 1, None] * curve[None, :, 1]
        nearest = np.argmin(c2[None, :] - 2.0 * cross, axis=1)
        seg = np.clip(nearest[:, None] + offsets, 0, len(curve) - 2)  # (n, 6)
        a = curve[seg]
        ab = curve[seg + 1] - a
        ap = p[:, None, :] - a
        t = (ap * ab).sum(axis=2) / np.maximum((ab * ab).sum(axis=2), 1e-300)
        diff = ap - np.clip(t, 0.0, 1.0)[..., None] * ab
        out[i : i + block] = np.sqrt(np.min((diff * diff).sum(axis=2), axis=1))
    return out


def signed_distance(
    points: NDArray[np.float64], curve: NDArray[np.float64], depth: float
) -> NDArray[np.float64]:
    """Signed distance of ``points`` to ``curve``, negative in the biofilm: the region enclosed
    by the curve and the floor (the polygon is closed ``depth`` below the floor, the height of
    the curve's feet, so that the zero level inside the channel is the curve alone)."""
    import shapely

    bottom = min(curve[0, 1], curve[-1, 1]) - depth
    ring = np.vstack([curve, [curve[-1, 0], bottom], [curve[0, 0], bottom]])
    poly = shapely.Polygon(ring)
    inside = shapely.contains_xy(poly, points[:, 0], points[:, 1])
    dist = polyline_distance(points, curve)
    return np.where(inside, -dist, dist)


def signed_distance_levelset(
    curve: NDArray[np.float64],
    length: float,
    height: float,
    h: float,
    origin: tuple[float, float] = (0.0, 0.0),
) -> Any:
    """Voxel level set on the channel ``origin + [0, length] x [0, height]``: the signed
    distance to ``curve`` (negative in the biofilm) on a grid of spacing ``h``, bilinear in
    between."""
    import ngsolve as ngs

    x0, y0 = origin
    nx = int(math.ceil(length / h)) + 1
    ny = int(math.ceil(height / h)) + 1
    X, Y = np.meshgrid(np.linspace(x0, x0 + length, nx), np.linspace(y0, y0 + height, ny))
    sd = signed_distance(np.c_[X.ravel(), Y.ravel()], curve, height).reshape(ny, nx)
    return ngs.VoxelCoefficient((x0, y0), (x0 + length, y0 + height), sd, linear=True)


class NodalLevelSet:
    """P2 level set on the background mesh: the nodal interpolant of the signed distance to a
    polyline (values at the vertices and edge midpoints).

    The second-order :class:`xfem.lsetcurv.LevelSetMeshAdaptation` works with the P2
    interpolant of whatever level set it is given, so this is what a finer voxel or an exact
    level set would give it too, at the cost of one distance evaluation per vertex and edge.
    """

    def __init__(self, mesh: Any) -> None:
        import ngsolve as ngs

        self.space = ngs.H1(mesh, order=2)
        nv, ne = mesh.nv, mesh.nedge
        if self.space.ndof != nv + ne:
            raise ForwardModelError("unexpected P2 dof layout of the background mesh", "bad_mesh")
        verts = np.array([v.point for v in mesh.vertices])
        self._edges = np.array([[v.nr for v in e.vertices] for e in mesh.edges])
        self._points = np.vstack([verts, verts[self._edges].mean(axis=1)])
        self._nv = nv
        # value of each edge's P2 bubble at its midpoint (NGSolve's hierarchical basis)
        gf = ngs.GridFunction(self.space)
        gf.vec.FV().NumPy()[:] = 0.0
        gf.vec.FV().NumPy()[nv:] = 1.0
        mid = self._points[nv:]
        self._bubble = np.asarray(gf(mesh(mid[:, 0], mid[:, 1]))).ravel()
        self._depth = float(np.ptp(verts[:, 1]))

    def __call__(self, curve: NDArray[np.float64]) -> Any:
        import ngsolve as ngs

        sd = signed_distance(self._points, curve, self._depth)
        nv, e = self._nv, self._edges
        gf = ngs.GridFunction(self.space)
        v = gf.vec.FV().NumPy()
        v[:nv] = sd[:nv]
        v[nv:] = (sd[nv:] - 0.5 * (sd[e[:, 0]] + sd[e[:, 1]])) / self._bubble
        return gf


class _Aitken:
    """Aitken's dynamic relaxation of the fixed-point iteration x <- x + omega (S(x) - x)."""

    def __init__(self, cs: CouplingSettings) -> None:
        self.cs = cs
        self.omega = cs.omega0
        self._r_old: NDArray[np.float64] | None = None

    def update(self, x: NDArray[np.float64], x_new: NDArray[np.float64]) -> NDArray[np.float64]:
        cs = self.cs
        r = x_new - x
        if self._r_old is not None:
            dr = r - self._r_old
            denom = float(dr @ dr)
            if denom > 0:
                self.omega = -self.omega * float(self._r_old @ dr) / denom
            self.omega = float(np.clip(self.omega, -cs.omega_max, cs.omega_max))
            if abs(self.omega) < 1e-3:
                self.omega = cs.omega0
        self._r_old = r
        return x + self.omega * r


class _IqnIls:
    """Interface quasi-Newton with an inverse Jacobian from a least-squares model (IQN-ILS,
    Degroote et al. 2009) on the skeleton state: the secant information of all iterations
    of this solve; relaxation ``omega0`` in the first one."""

    def __init__(self, cs: CouplingSettings) -> None:
        self.cs = cs
        self.omega = cs.omega0
        self._r: list[NDArray[np.float64]] = []
        self._xt: list[NDArray[np.float64]] = []

    def update(self, x: NDArray[np.float64], x_new: NDArray[np.float64]) -> NDArray[np.float64]:
        r = x_new - x
        self._r.append(r)
        self._xt.append(x_new)
        if len(self._r) == 1:
            self.omega = self.cs.omega0
            return x + self.omega * r
        V = np.array([self._r[-1] - ri for ri in self._r[:-1]]).T
        W = np.array([self._xt[-1] - xi for xi in self._xt[:-1]]).T
        c, *_ = np.linalg.lstsq(V, -r, rcond=1e-12)
        self.omega = 1.0
        return x_new + W @ c


class PoroFsiSolver:
    """The partitioned flow | skeleton solver on a background and a skeleton mesh."""

    def __init__(
        self,
        background: Any,
        skeleton_mesh: Any,
        length: float,
        height: float,
        flow_settings: FlowSettings,
        skeleton_settings: SkeletonSettings,
        coupling: CouplingSettings,
        outflow: str = "horizontal",
        origin: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        import ngsolve as ngs

        self.ngs = ngs
        self.length, self.height = length, height
        self.origin = (float(origin[0]), float(origin[1]))  # lower left corner of the channel
        self.bg = background
        self.coupling = coupling
        self.skeleton = Skeleton(skeleton_mesh, skeleton_settings)
        self.sampler = InterfaceSampler(skeleton_mesh, coupling.samples_per_edge)
        self.K0 = ngs.Parameter(1e-4)
        dy = "inflow|walls|outflow" if outflow == "horizontal" else "inflow|walls"
        self._dirichlet = ("inflow|walls", dy)
        self.flow_settings = flow_settings
        self.k_bg = ngs.GridFunction(ngs.H1(background, order=1, dim=3))  # kxx, kxy, kyy
        self.phi_bg = ngs.GridFunction(ngs.H1(background, order=1))
        self._grad_bg = ngs.GridFunction(ngs.H1(background, order=2, dim=4))  # recovered grad u
        kk = self.k_bg
        self._k_matrix = ngs.CoefficientFunction((kk[0], kk[1], kk[1], kk[2]), dims=(2, 2))
        self.flow: CutFlow | None = None
        self._bg_vertices = np.array([v.point for v in background.vertices])
        self._nodal_lset = NodalLevelSet(background) if coupling.level_set == "nodal" else None
        mesh = skeleton_mesh
        self._sk_vertices = np.array([v.point for v in mesh.vertices])
        self._sk_points = mesh(self._sk_vertices[:, 0], self._sk_vertices[:, 1])
        self._sk_triangles = np.array(
            [[v.nr for v in el.vertices] for el in mesh.Elements(ngs.VOL)]
        )
        self._sk_boundary = np.array([[v.nr for v in el.vertices] for el in mesh.Elements(ngs.BND)])
        self._k_cf: Any = None

    # -- material ----------------------------------------------------------------------------
    def set_material(self, E: float, nu: float, phi0: float, K: float) -> None:
        self.skeleton.set_material(E, nu, phi0)
        self.K0.Set(K)
        self.phi0 = phi0

    def _permeability_cf(self) -> Any:
        """Spatial permeability on the skeleton mesh, k = J^-1 F K F^T, K of eq. 11."""
        ngs = self.ngs
        d = self.skeleton.displacement
        phi = self.skeleton.porosity
        phi0 = self.skeleton.phi0
        F = ngs.Id(2) + ngs.Grad(d)
        J = ngs.Det(F)
        Kkc = self.K0 * kozeny_carman(J, phi, phi0)  # eq. 11
        k = (Kkc / J) * F * F.trans
        return ngs.CoefficientFunction((k[0, 0], k[0, 1], k[1, 1], phi))

    def level_set(self, curve: NDArray[np.float64]) -> Any:
        """Level set of the deformed biofilm on the background mesh (negative inside)."""
        if self._nodal_lset is not None:
            return self._nodal_lset(curve)
        return signed_distance_levelset(
            curve, self.length, self.height, self.coupling.voxel_size, self.origin
        )

    def _to_background(self) -> None:
        """Permeability and porosity at the background vertices: linear interpolation on the
        (straight-sided) deformed skeleton mesh, the closest boundary point outside it."""
        sk = self.skeleton
        if self._k_cf is None:
            self._k_cf = self._permeability_cf()
        mp = self._sk_points
        vals = np.asarray(self._k_cf(mp)).reshape(len(self._sk_vertices), 4)
        moved = self._sk_vertices + np.asarray(sk.displacement(mp)).reshape(-1, 2)
        tris = self._sk_triangles
        P = self._bg_vertices
        out = np.empty((len(P), 4))
        found = np.zeros(len(P), dtype=bool)
        corners = moved[tris]  # (m, 3, 2)
        tmin, tmax = corners.min(axis=1) - 1e-9, corners.max(axis=1) + 1e-9
        cand = np.flatnonzero(np.all((P >= tmin.min(axis=0)) & (P <= tmax.max(axis=0)), axis=1))
        a = corners[:, 0]
        Tinv = np.linalg.inv(np.stack([corners[:, 1] - a, corners[:, 2] - a], axis=2))
        block = max(1, 1_000_000 // len(tris))
        for i in range(0, len(cand), block):
            idx = cand[i : i + block]
            q = P[idx]
            # candidate triangles: bounding boxes that hold the point; then barycentric test
            inbox = np.all((q[:, None, :] >= tmin[None]) & (q[:, None, :] <= tmax[None]), axis=2)
            pi, tj = np.nonzero(inbox)
            lam = np.einsum("nij,nj->ni", Tinv[tj], q[pi] - a[tj])
            bary = np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)
            ok = np.all(bary >= -1e-12, axis=1)
            pi, tj, bary = pi[ok], tj[ok], bary[ok]
            pi, first = np.unique(pi, return_index=True)
            out[idx[pi]] = np.einsum("nj,njc->nc", bary[first], vals[tris[tj[first]]])
            found[idx[pi]] = True
        if not np.all(found):
            # outside the deformed mesh: the value at the closest point of its boundary, so
            # that the transfer stays continuous in the displacement
            q = P[~found]
            seg = self._sk_boundary
            a = moved[seg[:, 0]]
            ab = moved[seg[:, 1]] - a
            aq = q[:, None, :] - a[None]
            t = np.clip(np.einsum("nsi,si->ns", aq, ab) / np.einsum("si,si->s", ab, ab), 0, 1)
            dist = np.linalg.norm(aq - t[..., None] * ab[None], axis=2)
            j = np.argmin(dist, axis=1)
            tj = t[np.arange(len(q)), j][:, None]
            out[~found] = (1 - tj) * vals[seg[j, 0]] + tj * vals[seg[j, 1]]
        self.k_bg.vec.FV().NumPy()[:] = out[:, :3].ravel()  # interleaved per vertex
        self.phi_bg.vec.FV().NumPy()[:] = out[:, 3]

    def _loads_to_skeleton(self, flow: CutFlow) -> None:
        """Pore pressure and fluid shear evaluated at the deformed skeleton points.

        The shear uses a continuous velocity gradient: the P1 gradient of the P2 velocity
        averaged into P2 on the elements of the cut band.  The raw gradient jumps across
        background element edges, so evaluating it at the moving skeleton points would make
        the load jump whenever a point crosses an edge, and the coupling stall at that level
        (about 1e-5 mm on the default mesh).
        """
        ngs = self.ngs
        sk = self.skeleton
        g = ngs.Grad(flow.velocity)
        band = flow.els["fluid"] & flow.els["porous"]
        self._grad_bg.Set(
            ngs.CoefficientFunction((g[0, 0], g[0, 1], g[1, 0], g[1, 1])), definedonelements=band
        )
        e = self._grad_bg
        gu = ngs.CoefficientFunction((e[0], e[1], e[2], e[3]), dims=(2, 2))
        mesh = sk.mesh
        interface_only = self.coupling.pore_pressure == "interface"
        mesh.SetDeformation(sk.displacement)
        try:
            if interface_only:
                sk.pressure.Set(flow.pore_pressure, ngs.BND, definedon=mesh.Boundaries(sk.loaded))
            else:
                sk.pressure.Set(flow.pore_pressure)
            n = ngs.specialcf.normal(2)  # out of the biofilm
            t = ngs.CoefficientFunction((-n[1], n[0]))
            tau = self.flow_settings.viscosity * (t * ((gu + gu.trans) * n))
            sk.shear.Set(tau, definedon=mesh.Boundaries("interface"))
        finally:
            mesh.UnsetDeformation()
        if interface_only:
            sk.extend_pressure()

    # -- one coupled solve -------------------------------------------------------------------
    def solve(self, inflow_rate: float, where: str) -> CouplingReport:
        """Coupled steady state at ``inflow_rate`` (mm^2/s), from the current skeleton state.

        Fixed-point iteration x -> S(F(x)) on the skeleton state x (displacement, porosity),
        accelerated by Aitken's relaxation or by interface quasi-Newton (IQN-ILS).  The
        iteration is inexact: the flow and skeleton Newton tolerances follow the interface
        change of the previous iteration, ``inexact * change / height``, never below their
        final tolerances, so early iterations spend one or two Newton steps per field.
        """
        ngs = self.ngs
        cs = self.coupling
        rep = CouplingReport()
        sk = self.skeleton
        x = sk.state()
        accel = _Aitken(cs) if cs.acceleration == "aitken" else _IqnIls(cs)
        above = ngs.y - self.origin[1]  # height above the floor
        prof = 6.0 * inflow_rate / self.height**2 * above * (self.height - above)
        inflow = ngs.CoefficientFunction((prof, 0.0))
        wall = ngs.CoefficientFunction((0.0, 0.0))
        bc = self.bg.BoundaryCF({"inflow": inflow}, default=wall)
        fs, ss = self.flow_settings, sk.settings
        change = math.inf
        for it in range(1, cs.max_iter + 1):
            at = f"{where}, coupling iteration {it}"
            rel = cs.inexact * change / self.height
            sk.set_state(x)
            t0 = time.perf_counter()
            curve = self.sampler.deformed(sk.displacement)
            lset = self.level_set(curve)
            t1 = time.perf_counter()
            self._to_background()
            t2 = time.perf_counter()
            if self.flow is None:
                flow = self.flow = CutFlow(self.bg, lset, fs, self._dirichlet, self._k_matrix)
            else:
                flow = self.flow
                flow.set_level_set(lset)
                flow.set_permeability(self._k_matrix)
            t3 = time.perf_counter()
            frep = flow.solve(bc, where=at, tol=max(fs.newton_tol, min(rel, 1e-2)))
            rep.flow_iterations += frep.iterations
            t4 = time.perf_counter()
            self._loads_to_skeleton(flow)
            t5 = time.perf_counter()
            rep.skeleton_iterations += sk.solve(at, tol=max(ss.newton_tol, min(rel, 1e-2)))
            t6 = time.perf_counter()
            rep.times["level_set"] += (t1 - t0) + (t3 - t2)
            rep.times["transfer"] += (t2 - t1) + (t5 - t4)
            rep.times["flow"] += t4 - t3
            rep.times["skeleton"] += t6 - t5
            x_new = sk.state()
            change = self._interface_change(curve, x_new)
            rep.changes.append(change)
            rep.iterations = it
            if not math.isfinite(change):
                raise ForwardModelError(f"{where}: coupling produced NaN", "coupling_diverged")
            if change < cs.tol:
                return rep
            x_next = accel.update(x, x_new)
            sk.set_state(x_next)
            phi, J = sk._ranges()
            if not (0.0 < phi.min() and phi.max() < 1.0 and J.min() > 0.0):
                # an extrapolated state outside the admissible set: relax towards x_new
                x_next = x + cs.omega0 * (x_new - x)
                accel.omega = cs.omega0
            x = x_next
            rep.omegas.append(accel.omega)
        raise ForwardModelError(
            f"{where}: the flow | skeleton coupling did not converge in {cs.max_iter} "
            f"iterations (last interface change {rep.changes[-1]:.2e} mm)",
            "coupling_not_converged",
        )

    def _interface_change(self, curve: NDArray[np.float64], x_new: NDArray[np.float64]) -> float:
        sk = self.skeleton
        keep = sk.state()
        sk.set_state(x_new)
        new = self.sampler.deformed(sk.displacement)
        sk.set_state(keep)
        return float(np.max(np.linalg.norm(new - curve, axis=1)))

    def reset(self) -> None:
        """Undeformed skeleton and a zero flow state: every run starts from the same state."""
        self.skeleton.reset()
        if self.flow is not None:
            self.flow.gfx.vec[:] = 0.0

    def porosity_range(self) -> tuple[float, float]:
        ngs = self.ngs
        mesh = self.skeleton.mesh
        ir = ngs.IntegrationRule([(0, 0), (1, 0), (0, 1), (1 / 3, 1 / 3)], [0.0] * 4)
        phi = np.asarray(self.skeleton.porosity(mesh.MapToAllElements(ir, ngs.VOL))).ravel()
        return float(phi.min()), float(phi.max())

    def boundary_fluxes(self) -> tuple[float, float]:
        """(inflow, outflow) volume rates of the channel fluid (mm^2/s)."""
        ngs = self.ngs
        if self.flow is None:
            return 0.0, 0.0
        n = ngs.specialcf.normal(2)
        un = self.flow.velocity * n
        return (
            -float(ngs.Integrate(un, self.bg, definedon=self.bg.Boundaries("inflow"), order=6)),
            float(ngs.Integrate(un, self.bg, definedon=self.bg.Boundaries("outflow"), order=6)),
        )

    def interface_curve(self) -> NDArray[np.float64]:
        return self.sampler.deformed(self.skeleton.displacement)
