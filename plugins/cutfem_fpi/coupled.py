"""Partitioned fluid-poroelastic interaction on two meshes: flow | skeleton, Aitken relaxation.

* flow (:mod:`.flow`): Navier-Stokes in the channel and Darcy in the biofilm on a **fixed**
  background mesh of the channel, cut by the level set of the current (deformed) biofilm;
* skeleton (:mod:`.skeleton`): displacement and porosity on the biofilm's own fitted mesh in
  the reference configuration, loaded by the pore pressure and the fluid shear.

One coupling iteration: level set from the deformed boundary (signed distance of a densely
sampled polygon on a voxel grid) -> permeability ``k = J^-1 F K F^T`` with Kozeny-Carman ``K``
(eq. 11) moved to the background mesh -> flow solve -> pore pressure and shear moved to the
skeleton (evaluated at the deformed skeleton points) -> skeleton Newton -> Aitken-relaxed
update of the skeleton state.  Steady problem: no added-mass instability.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fbia.core.errors import ForwardModelError

from .flow import CutFlow, FlowSettings
from .skeleton import Skeleton, SkeletonSettings


@dataclass(frozen=True)
class CouplingSettings:
    """Numerics of the partitioned scheme (lengths in mm)."""

    tol: float = 1e-6  # interface displacement change that ends the coupling [mm]
    max_iter: int = 40
    omega0: float = 0.5  # first relaxation factor
    omega_max: float = 1.5
    samples_per_edge: int = 4  # polygon points per skeleton interface edge (level set)
    voxel_size: float = 0.004  # grid of the signed-distance level set [mm]


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


def skeleton_mesh_from_flow_cell(cell: Any) -> Any:
    """The biofilm part of an :func:`fbia.plugins.ale_fsi.geometry.build_flow_cell` mesh.

    Keeps the ``solid[_k]`` triangles (as one region ``solid``) and the ``interface`` and
    ``solid_fixed`` segments; straight-sided.
    """
    import netgen.meshing as nm
    import ngsolve as ngs

    from fbia.plugins.ale_fsi.geometry import mesh_arrays, solid_regions

    pts, regions, boundaries = mesh_arrays(cell)
    tris = np.vstack([regions[r] for r in solid_regions(cell)])
    used = np.unique(tris)
    renum = -np.ones(len(pts), dtype=np.int64)
    renum[used] = np.arange(len(used))
    ngmesh = nm.Mesh(dim=2)
    ngmesh.AddPoints(np.ascontiguousarray(pts[used]))
    idx = ngmesh.AddRegion("solid", dim=2)
    t = renum[tris].astype(np.int32)
    p = pts[used]
    a, b = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    cw = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0
    t[cw] = t[cw][:, [0, 2, 1]]
    ngmesh.AddElements(dim=2, index=idx, data=np.ascontiguousarray(t), base=0)
    for name in ("interface", "solid_fixed"):
        segs = boundaries[name]
        keep = np.all(renum[segs] >= 0, axis=1)
        idx = ngmesh.AddRegion(name, dim=1)
        s = np.ascontiguousarray(renum[segs[keep]].astype(np.int32))
        ngmesh.AddElements(dim=1, index=idx, data=s, base=0)
    return ngs.Mesh(ngmesh)


def channel_mesh(length: float, height: float, mesh_size: float) -> Any:
    """Background mesh of the empty channel: boundaries inflow, outflow, walls."""
    import ngsolve as ngs
    from netgen.occ import OCCGeometry, Rectangle, X, Y

    face = Rectangle(length, height).Face()
    face.edges.Min(X).name = "inflow"
    face.edges.Max(X).name = "outflow"
    face.edges.Min(Y).name = "walls"
    face.edges.Max(Y).name = "walls"
    return ngs.Mesh(OCCGeometry(face, dim=2).GenerateMesh(maxh=mesh_size))


class InterfaceSampler:
    """Ordered points on the skeleton interface (solid on the right, upstream first)."""

    def __init__(self, mesh: Any, per_edge: int) -> None:
        import ngsolve as ngs

        from fbia.plugins.ale_fsi.solver import interface_chains

        chains = interface_chains(mesh, ngs)
        if len(chains) != 1:
            raise ForwardModelError(
                f"the biofilm interface must be one open curve, got {len(chains)}", "bad_mesh"
            )
        verts = np.array([v.point for v in mesh.vertices])
        bnd = list(mesh.Elements(ngs.BND))
        pts = []
        for el, start in chains[0]:
            a, b = (v.nr for v in bnd[el].vertices)
            stop = b if a == start else a
            s = np.linspace(0.0, 1.0, per_edge, endpoint=False)[:, None]
            pts.append(verts[start] * (1 - s) + verts[stop] * s)
        el, start = chains[0][-1]
        a, b = (v.nr for v in bnd[el].vertices)
        pts.append(verts[b if a == start else a][None, :])
        self.reference = np.vstack(pts)
        self.mesh = mesh
        self._mp = mesh(self.reference[:, 0], self.reference[:, 1])
        if np.any(self._mp["nr"] < 0):
            raise ForwardModelError("interface points outside the skeleton mesh", "bad_mesh")

    def deformed(self, displacement: Any) -> NDArray[np.float64]:
        return self.reference + np.asarray(displacement(self._mp)).reshape(-1, 2)


def signed_distance_levelset(
    curve: NDArray[np.float64], length: float, height: float, h: float
) -> Any:
    """Voxel level set: signed distance to ``curve`` (negative in the biofilm).

    The biofilm is the region enclosed by the curve and the floor; the polygon is closed well
    below the floor, so the zero level inside the channel is the curve alone.
    """
    import ngsolve as ngs
    import shapely

    deep = -height
    ring = np.vstack([curve, [curve[-1, 0], deep], [curve[0, 0], deep]])
    poly = shapely.Polygon(ring)
    line = shapely.LineString(curve)
    nx = int(math.ceil(length / h)) + 1
    ny = int(math.ceil(height / h)) + 1
    xs = np.linspace(0.0, length, nx)
    ys = np.linspace(0.0, height, ny)
    X, Y = np.meshgrid(xs, ys)
    dist = shapely.distance(line, shapely.points(X.ravel(), Y.ravel()))
    inside = shapely.contains_xy(poly, X.ravel(), Y.ravel())
    sd = np.where(inside, -dist, dist).reshape(ny, nx)
    return ngs.VoxelCoefficient((0.0, 0.0), (length, height), sd, linear=True)


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
    ) -> None:
        import ngsolve as ngs

        self.ngs = ngs
        self.length, self.height = length, height
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
        self.flow: CutFlow | None = None
        self._flow_state: NDArray[np.float64] | None = None
        self._bg_vertices = np.array([v.point for v in background.vertices])

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
        Jphi = J * phi
        Kkc = self.K0 * (1 - phi0**2) / phi0**3 * Jphi**3 / (1 - Jphi**2)  # eq. 11
        k = (Kkc / J) * F * F.trans
        return ngs.CoefficientFunction((k[0, 0], k[0, 1], k[1, 1], phi))

    def _to_background(self) -> None:
        """Permeability and porosity at the background vertices (barycentric on the deformed
        skeleton mesh; nearest deformed skeleton vertex outside it)."""
        from scipy.spatial import cKDTree

        sk = self.skeleton
        mesh = sk.mesh
        verts = np.array([v.point for v in mesh.vertices])
        mp = mesh(verts[:, 0], verts[:, 1])
        vals = np.asarray(self._permeability_cf()(mp)).reshape(len(verts), 4)
        moved = verts + np.asarray(sk.displacement(mp)).reshape(-1, 2)
        tris = np.array([[v.nr for v in el.vertices] for el in mesh.Elements(self.ngs.VOL)])
        out = np.empty((len(self._bg_vertices), 4))
        found = np.zeros(len(self._bg_vertices), dtype=bool)
        # barycentric search, vectorised over the background vertices per skeleton triangle
        P = self._bg_vertices
        lo, hi = moved.min(axis=0) - 1e-9, moved.max(axis=0) + 1e-9
        cand = np.flatnonzero(np.all((P >= lo) & (P <= hi), axis=1))
        for tri in tris:
            a, b, c = moved[tri]
            T = np.array([b - a, c - a]).T
            lam = np.linalg.solve(T, (P[cand] - a).T).T
            l0 = 1.0 - lam.sum(axis=1)
            inside = (lam[:, 0] >= -1e-12) & (lam[:, 1] >= -1e-12) & (l0 >= -1e-12)
            idx = cand[inside]
            w = np.c_[l0[inside], lam[inside]]
            out[idx] = w @ vals[tri]
            found[idx] = True
        if not np.all(found):
            _, near = cKDTree(moved).query(P[~found])
            out[~found] = vals[near]
        self.k_bg.vec.FV().NumPy()[:] = out[:, :3].ravel()  # interleaved per vertex
        self.phi_bg.vec.FV().NumPy()[:] = out[:, 3]

    # -- one coupled solve -------------------------------------------------------------------
    def solve(self, inflow_rate: float, where: str) -> CouplingReport:
        """Coupled steady state at ``inflow_rate`` (mm^2/s), from the current skeleton state."""
        ngs = self.ngs
        cs = self.coupling
        rep = CouplingReport()
        sk = self.skeleton
        x = sk.state()
        r_old: NDArray[np.float64] | None = None
        omega = cs.omega0
        prof = 6.0 * inflow_rate / self.height**2 * ngs.y * (self.height - ngs.y)
        inflow = ngs.CoefficientFunction((prof, 0.0))
        wall = ngs.CoefficientFunction((0.0, 0.0))
        bc = self.bg.BoundaryCF({"inflow": inflow}, default=wall)
        curve_old = None
        for it in range(1, cs.max_iter + 1):
            sk.set_state(x)
            t0 = time.perf_counter()
            curve = self.sampler.deformed(sk.displacement)
            lset = signed_distance_levelset(curve, self.length, self.height, cs.voxel_size)
            t1 = time.perf_counter()
            self._to_background()
            kk = self.k_bg
            kmat = ngs.CoefficientFunction((kk[0], kk[1], kk[1], kk[2]), dims=(2, 2))
            t2 = time.perf_counter()
            if self.flow is None:
                self.flow = CutFlow(self.bg, lset, self.flow_settings, self._dirichlet, kmat)
            else:
                self.flow.set_level_set(lset)
                self.flow.set_permeability(kmat)
            t3 = time.perf_counter()
            frep = self.flow.solve(bc, where=f"{where}, coupling iteration {it}")
            rep.flow_iterations += frep.iterations
            t4 = time.perf_counter()
            # pore pressure and fluid shear at the deformed skeleton points
            mesh = sk.mesh
            mesh.SetDeformation(sk.displacement)
            try:
                sk.pressure.Set(self.flow.pore_pressure)
                n = ngs.specialcf.normal(2)  # out of the biofilm
                t = ngs.CoefficientFunction((-n[1], n[0]))
                gu = ngs.Grad(self.flow.velocity)
                tau = self.flow_settings.viscosity * (t * ((gu + gu.trans) * n))
                sk.shear.Set(tau, definedon=mesh.Boundaries("interface"))
            finally:
                mesh.UnsetDeformation()
            t5 = time.perf_counter()
            rep.skeleton_iterations += sk.solve(f"{where}, coupling iteration {it}")
            t6 = time.perf_counter()
            rep.times["level_set"] += (t1 - t0) + (t3 - t2)
            rep.times["transfer"] += (t2 - t1) + (t5 - t4)
            rep.times["flow"] += t4 - t3
            rep.times["skeleton"] += t6 - t5
            x_new = sk.state()
            r = x_new - x
            change = self._interface_change(curve, x_new)
            rep.changes.append(change)
            rep.iterations = it
            if not math.isfinite(change):
                raise ForwardModelError(f"{where}: coupling produced NaN", "coupling_diverged")
            if change < cs.tol:
                return rep
            if r_old is not None:
                dr = r - r_old
                denom = float(dr @ dr)
                if denom > 0:
                    omega = -omega * float(r_old @ dr) / denom
                omega = float(np.clip(omega, -cs.omega_max, cs.omega_max))
                if abs(omega) < 1e-3:
                    omega = cs.omega0
            rep.omegas.append(omega)
            x = x + omega * r
            r_old = r
            curve_old = curve
        del curve_old
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
