"""A user's 3-D biofilm colony on the floor of a duct: from a surface file to an ALE FSI mesh.

``geometry = "colony_3d"`` meshes the duct of ``dome_3d`` (``length x height x width``, floor
``y = 0``, flow along x) with the colony given as a triangulated surface in a file -- any
format meshio or trimesh reads (STL, PLY, OBJ, VTU), closed (with its base on the floor) or
open (the upper surface alone, as :func:`fbia.imaging.oct.segment_oct` writes it) -- in the
model's axes (x along the flow, y the height above the floor, z across).

Construction (:func:`build_colony_cell`):

1. the colony is a height field ``y = h(x, z)`` over the floor: :func:`colony_height_field`
   casts a vertical ray at every node of a grid of spacing ``resolution`` (mm) and keeps
   the highest hit; the fluid a ray crosses under the colony is under an overhang, which the
   height field fills: more than ``MAX_FILLED`` (2 %) of the colony's volume is a
   :class:`ConfigError` naming the file (a segmented surface's rough walls overhang a little);
2. the nodes where no ray meets the colony make the outside of its footprint; there ``h``
   continues below the floor with the slope at the nearest footprint node, so that the foot
   is where a smooth surface through the nodes crosses ``y = 0``; a Gaussian filter of width
   ``smoothing`` (mm) then smooths out the voxel steps of a segmented surface and keeps
   the spline of step 3 from ringing at a steep foot (the default 0.02 mm = the default
   grid spacing; it takes 3 % of the volume of a hemisphere of radius 0.4 mm);
3. an OCC B-spline surface interpolates the nodes (``SplineSurfaceInterpolation``), is
   extruded downwards into a solid and cut by the duct: the colony is the part above the
   floor; the fluid is the duct minus the colony; netgen meshes both (faces named as in
   :mod:`~fbia.plugins.ale_fsi.geometry3d`) and, as there, the fluid tetrahedra with all four
   vertices on no-slip faces are split (``split_locked_tets``; Boffi 1997).  Elements are
   straight-sided.

:func:`colony_from_oct` is the one step from an unloaded OCT scan to the ``colony_surface``
file: segment, map the OCT frame (x, y = span, z = height) to the model's (x, y = height,
z = span) by :func:`fbia.imaging.oct.in_model_axes`, write.

>>> from fbia.plugins.ale_fsi.colony3d import build_colony_cell
>>> mesh = build_colony_cell("colony.ply", interface_mesh_size=0.15)  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ...core.errors import ConfigError
from ...core.interface import Interface
from ..fem.flow_cell import FLUID, SOLID, check_mesh
from .geometry3d import connectivity_by_region, mesh_from_arrays_3d, split_locked_tets

if TYPE_CHECKING:
    import ngsolve

    from ...imaging.oct import OctSegmentation

logger = logging.getLogger(__name__)

__all__ = [
    "ColonyHeightField",
    "build_colony_cell",
    "colony_from_oct",
    "colony_field",
    "colony_height_field",
    "colony_solid",
]

#: Largest colony height as a fraction of the duct height (the fluid above must be meshable).
MAX_HEIGHT_FRACTION = 0.9
#: Largest volume under overhangs that the height field may fill, as a fraction of the colony's
#: (the rough near-vertical walls of a segmented surface overhang a little).
MAX_FILLED = 0.02
#: Smallest part of the colony kept, as a fraction of the largest part's volume.
MIN_PART = 0.01
#: Fewest triangles of a colony surface: it closes a volume with the floor, as the three sides
#: of a tetrahedron standing on it do at least (one triangle passed validate, then netgen
#: failed on the cell: issue 44).
MIN_TRIANGLES = 3
#: Most nodes of a colony's height field (4e6: 2000 x 2000, 0.5 mm at 0.25 um; a surface in um
#: read as mm would ask for 1e6 times more).
MAX_GRID_NODES = 4_000_000


@dataclass(frozen=True)
class ColonyHeightField:
    """The colony as a height field over a grid on the floor.

    Attributes
    ----------
    x, z
        Grid node coordinates along the flow and across it [mm].
    height
        ``h(x_i, z_j)`` [mm]: the colony's height on its footprint, continued below the
        floor outside it (step 2 of the module docstring; smoothed if asked), shape
        (len(x), len(z)).
    footprint
        Nodes under the colony (``height > 0``), shape (len(x), len(z)).
    """

    x: NDArray[np.float64]
    z: NDArray[np.float64]
    height: NDArray[np.float64]
    footprint: NDArray[np.bool_]

    @property
    def footprint_area(self) -> float:
        """Area of the footprint nodes' grid cells [mm^2]."""
        return float(self.footprint.sum()) * self._cell

    @property
    def volume(self) -> float:
        """Volume under the height field above the floor (midpoint rule) [mm^3]."""
        return float(np.clip(self.height, 0.0, None).sum()) * self._cell

    @property
    def _cell(self) -> float:
        return float((self.x[1] - self.x[0]) * (self.z[1] - self.z[0]))


def read_colony_surface(path: str | Path) -> Interface:
    """The triangulated colony surface in a file (3-D, any meshio/trimesh surface format)."""
    where = str(path)
    surface = Interface.read(path)
    if surface.dim != 3:
        raise ConfigError("a colony surface must be a 3-D triangle surface", where)
    return surface


def colony_height_field(
    surface: Interface,
    resolution: float,
    smoothing: float = 0.0,
    margin: float | None = None,
    within: tuple[float, float, float, float] | None = None,
    where: str = "colony surface",
) -> ColonyHeightField:
    """Sample the colony as a height field (steps 1-2 of the module docstring).

    Parameters
    ----------
    surface
        Triangulated colony surface in model axes [mm].
    resolution
        Grid spacing [mm].
    smoothing
        Standard deviation of the Gaussian filter on the height field [mm]; 0: none.
    margin
        Grid beyond the footprint's bounding box on every side [mm]; default
        ``3 resolution + 3 smoothing``.
    within
        ``(x_min, x_max, z_min, z_max)``: the grid keeps its nodes strictly inside this box
        (the duct's floor), and the footprint must not reach the outermost ones.
    """
    import trimesh
    from scipy import ndimage

    if not (resolution > 0 and smoothing >= 0):
        raise ConfigError("colony resolution must be > 0 and smoothing >= 0", where)
    v = surface.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    scale = float(np.abs(v).max()) or 1.0
    floor_tol = max(1e-3 * float(hi[1]), 1e-9 * scale)
    if hi[1] <= floor_tol:
        raise ConfigError("the colony surface lies on or below the floor y = 0: empty", where)
    pad = 3.0 * resolution + 3.0 * smoothing if margin is None else margin
    nx = int(np.ceil((hi[0] - lo[0] + 2 * pad) / resolution)) + 1
    nz = int(np.ceil((hi[2] - lo[2] + 2 * pad) / resolution)) + 1
    if nx * nz > MAX_GRID_NODES:
        raise ConfigError(
            f"the colony spans {hi[0] - lo[0]:.4g} x {hi[2] - lo[2]:.4g} mm: its height field "
            f"at colony_resolution {resolution} mm would have {nx * nz:.3g} nodes (at most "
            f"{MAX_GRID_NODES:.0e}); is the surface in mm (fbia's unit)?",
            where,
        )
    x = lo[0] - pad + resolution * np.arange(nx)
    z = lo[2] - pad + resolution * np.arange(nz)
    if within is not None:
        inset = 1e-6 * resolution
        x = x[(x > within[0] + inset) & (x < within[1] - inset)]
        z = z[(z > within[2] + inset) & (z < within[3] - inset)]
        if len(x) < 3 or len(z) < 3:
            raise ConfigError(
                f"the colony (x in [{lo[0]:.4g}, {hi[0]:.4g}], z in [{lo[2]:.4g}, "
                f"{hi[2]:.4g}] mm) lies outside the duct's floor {within} mm",
                where,
            )
    gx, gz = np.meshgrid(x, z, indexing="ij")
    origins = np.c_[gx.ravel(), np.full(gx.size, hi[1] + 1.0), gz.ravel()]
    directions = np.tile([0.0, -1.0, 0.0], (gx.size, 1))
    mesh = trimesh.Trimesh(surface.vertices, surface.cells, process=False)
    hits, ray, _ = mesh.ray.intersects_location(origins, directions, multiple_hits=True)
    hits = np.reshape(hits, (-1, 3))  # no hit at all: shape (0,)
    above = hits[:, 1] > floor_tol
    height = np.full(gx.size, -np.inf)
    np.maximum.at(height, ray[above], hits[above, 1])
    footprint = np.isfinite(height)
    if not footprint.any():
        raise ConfigError("the colony has an empty footprint: no vertical ray meets it", where)
    gaps = _gaps_under_overhangs(ray[above], hits[above, 1], gx.size, 1e-9 * scale)
    filled = float(gaps.sum()) * resolution**2
    volume = float(np.where(footprint, height, 0.0).sum()) * resolution**2
    if filled > MAX_FILLED * volume:
        k = int(np.argmax(gaps))
        raise ConfigError(
            f"the colony overhangs (e.g. over {gaps[k]:.3g} mm of fluid at x = "
            f"{gx.ravel()[k]:.4g}, z = {gz.ravel()[k]:.4g} mm); a height field y = h(x, z) "
            f"would fill {filled / volume:.1%} of its volume (at most {MAX_FILLED:.0%})",
            where,
        )
    footprint = footprint.reshape(gx.shape)
    h = height.reshape(gx.shape)
    # outside: the height of the nearest footprint node h_b mirrored about a foot half a
    # grid step beyond it, -h_b (2 d / resolution - 1) at distance d: the slope at the foot
    # carries on below the floor (a cubic spline through a steep edge followed by a shallow
    # extension would ring and lift islands above the floor)
    d, (i, j) = ndimage.distance_transform_edt(
        ~footprint, sampling=(resolution, resolution), return_indices=True
    )
    h = np.where(footprint, h, -h[i, j] * (2.0 * d / resolution - 1.0))
    if smoothing > 0:
        h = ndimage.gaussian_filter(h, smoothing / resolution, mode="nearest")
    reach = footprint | (h > 0)
    if within is not None and (reach[[0, -1], :].any() or reach[:, [0, -1]].any()):
        raise ConfigError(
            f"the colony (x in [{lo[0]:.4g}, {hi[0]:.4g}], z in [{lo[2]:.4g}, {hi[2]:.4g}] mm) "
            f"reaches the walls of the duct {within} mm (closer than the grid spacing "
            f"{resolution} mm); move it with colony_offset",
            where,
        )
    return ColonyHeightField(x, z, h, h > 0)


def _gaps_under_overhangs(
    ray: NDArray[np.int64], y: NDArray[np.float64], n: int, tol: float
) -> NDArray[np.float64]:
    """Fluid under overhangs along each vertical ray [mm]: with the hits above the floor
    sorted from the top, entering and leaving the colony by turns, the gaps between a leave
    and the next entry, and from a last leave down to the floor."""
    gaps = np.zeros(n)
    order = np.lexsort((-y, ray))
    ray, y = ray[order], y[order]
    starts = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], len(ray)], strict=True):
        if b - a < 2:
            continue
        hy = y[a:b]
        hy = hy[np.r_[True, np.abs(np.diff(hy)) > tol]]  # a ray through an edge hits twice
        leave, enter = hy[1::2], np.r_[hy[2::2], 0.0][: len(hy[1::2])]
        gaps[ray[a]] = float((leave - enter).sum())
    return gaps


#: Netgen's mesh gradings tried in turn after the one asked for, when netgen cannot mesh the
#: colony cell with it.  Whether netgen's volume mesher finishes a segmented colony changes
#: with the grading, without a pattern (measured on three segmented rest domes at 0.2 / 0.15
#: mm: each meshed at some of 0.2-0.4 and failed at others; the cause is not measured,
#: perhaps the thin wedge at the colony's foot); the sizes asked for are kept, and the
#: grading used is logged.  Deterministic in a fresh process (netgen's state after a failed
#: attempt changes the next one's outcome).
FALLBACK_GRADINGS = (0.25, 0.35, 0.2, 0.4)


def build_colony_cell(
    surface: str | Path | Interface,
    length: float = 2.0,
    height: float = 1.0,
    width: float = 1.0,
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    resolution: float = 0.02,
    smoothing: float = 0.02,
    mesh_size: float = 0.25,
    interface_mesh_size: float = 0.1,
    grading: float = 0.3,
) -> ngsolve.Mesh:
    """Mesh a duct with the colony of a surface file on its floor (module docstring).

    Parameters
    ----------
    surface
        The colony surface: a file (model axes, mm) or an :class:`Interface`.
    length, height, width
        Duct size in mm along x (flow), y (floor ``y = 0``) and z.
    offset
        Translation of the surface into the duct [mm].
    resolution, smoothing
        Height-field grid spacing and Gaussian smoothing width [mm]
        (:func:`colony_height_field`).
    mesh_size, interface_mesh_size
        Maximum element size in the duct and on the colony (and inside it), mm.
    grading
        Netgen's mesh grading (0..1); where netgen cannot mesh with it, the
        :data:`FALLBACK_GRADINGS` in turn (logged), else a :class:`ConfigError` naming each.
    """
    from netgen.occ import Box, Glue, OCCGeometry, Pnt, X, Y

    where = str(surface) if isinstance(surface, str | Path) else "colony surface"
    if not (length > 0 and height > 0 and width > 0):
        raise ConfigError(f"duct size must be positive, got {length} x {height} x {width}", where)
    if not (mesh_size > 0 and interface_mesh_size > 0):
        raise ConfigError("mesh sizes must be positive", where)
    field = colony_field(surface, length, height, width, offset, resolution, smoothing)
    box = Box(Pnt(0, 0, 0), Pnt(length, height, width))
    box.faces.name = "walls"
    box.faces.Min(X).name = "inflow"
    box.faces.Max(X).name = "outflow"
    colony = colony_solid(field, box, where)
    colony.faces.name = "interface"
    colony.faces.Min(Y).name = "solid_fixed"
    colony.faces.maxh = interface_mesh_size
    colony.mat(SOLID)
    fluid = box - colony
    fluid.mat(FLUID)
    failed: list[str] = []
    for g in (grading, *(g for g in FALLBACK_GRADINGS if g != grading)):
        said: list[str] = []
        try:
            # curvaturesafety 0.5: the spline's curvature, not the options, would set the size
            with _stderr_kept(said):
                ngmesh = OCCGeometry(Glue([fluid, colony])).GenerateMesh(
                    maxh=mesh_size, grading=g, curvaturesafety=0.5
                )
        except Exception as exc:  # netgen raises bare Exception/NgException subclasses
            text = " ".join("".join(said).split())
            failed.append(f"grading {g:g}: {exc}" + (f" ({text})" if text else ""))
            continue
        sys.stderr.write("".join(said))  # a mesh was made: what netgen said stays in sight
        if failed:
            logger.warning(
                "%s: netgen meshed the colony cell at grading %g, not at %s",
                where,
                g,
                "; ".join(failed),
            )
        return _with_named_regions(ngmesh, where)
    raise ConfigError(f"netgen could not mesh the colony cell: {' | '.join(failed)}", where)


@contextlib.contextmanager
def _stderr_kept(said: list[str]) -> Iterator[None]:
    """What netgen's C++ code writes to file descriptor 2 meanwhile, appended to ``said``
    instead of printed: when meshing fails, fbia's one line carries it (netgen printed
    "Meshing of domain 2 failed ..." before it)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as kept:
        os.dup2(kept.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            kept.seek(0)
            said.append(kept.read().decode("utf-8", "replace"))


def colony_field(
    surface: str | Path | Interface,
    length: float,
    height: float,
    width: float,
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    resolution: float = 0.02,
    smoothing: float = 0.02,
) -> ColonyHeightField:
    """The colony's height field in the duct: every check of :func:`build_colony_cell` short
    of meshing (``fbia validate`` runs it): the file reads as a 3-D triangle surface with
    finite vertices, moved by ``offset`` it samples as a height field on the duct's floor,
    away from its walls, not overhanging, of at least :data:`MIN_TRIANGLES` triangles, below
    the ceiling."""
    where = str(surface) if isinstance(surface, str | Path) else "colony surface"
    shape = surface if isinstance(surface, Interface) else read_colony_surface(surface)
    shape = shape.translated(np.asarray(offset, dtype=float))
    field = colony_height_field(
        shape, resolution, smoothing, within=(0.0, length, 0.0, width), where=where
    )
    n = len(shape.cells)
    if n < MIN_TRIANGLES:
        raise ConfigError(
            f"{n} triangle{'s' * (n != 1)}: a colony surface closes a volume with the floor, "
            f"which takes at least {MIN_TRIANGLES} (the sides of a tetrahedron on the floor)",
            where,
        )
    top = float(field.height.max())
    if top >= MAX_HEIGHT_FRACTION * height:
        raise ConfigError(
            f"the colony ({top:.4g} mm high) touches the ceiling: it must stay below "
            f"{MAX_HEIGHT_FRACTION:g} x the duct height {height} mm",
            where,
        )
    return field


def colony_solid(field: ColonyHeightField, duct: Any, where: str = "colony surface") -> Any:
    """The colony as an OCC solid: the B-spline surface through the height field's nodes,
    extruded downwards, cut by the duct (an OCC box with its floor at ``y = 0``)."""
    from netgen.occ import Glue, SplineSurfaceInterpolation, Vec

    xs, zs = np.meshgrid(field.x, field.z, indexing="ij")
    points = np.ascontiguousarray(np.stack([xs, field.height, zs], axis=-1))
    depth = 2.0 * float(np.abs(field.height).max()) + 1.0
    try:
        face = SplineSurfaceInterpolation(points)
        colony = face.Extrude(Vec(0, -depth, 0)) * duct
    except Exception as exc:  # netgen raises bare Exception/NgException subclasses
        raise ConfigError(f"OCC could not build the colony solid: {exc}", where) from None
    # a spline through a steep foot may ring into specks above the floor: keep the parts of
    # at least MIN_PART of the largest one's volume
    parts = list(colony.solids)
    biggest = max((p.mass for p in parts), default=0.0)
    parts = [p for p in parts if p.mass >= MIN_PART * biggest]
    if not parts:
        raise ConfigError("the colony's spline surface has no part above the floor", where)
    return parts[0] if len(parts) == 1 else Glue(parts)


def _with_named_regions(ngmesh: Any, where: str) -> ngsolve.Mesh:
    """The netgen mesh as an NGSolve mesh on the module's names, locked tetrahedra split."""
    pts = np.array(ngmesh.Coordinates(), dtype=float, copy=True)
    e3, e2 = ngmesh.Elements3D().NumPy(), ngmesh.Elements2D().NumPy()
    regions = connectivity_by_region(e3, ngmesh.GetRegionNames(dim=3), 4)
    boundaries = connectivity_by_region(e2, ngmesh.GetRegionNames(dim=2), 3)
    if SOLID not in regions or "interface" not in boundaries:
        raise ConfigError("netgen lost the colony (no solid region): check the surface", where)
    locked = np.vstack([c for n, c in boundaries.items() if n != "outflow"])
    pts, regions[FLUID] = split_locked_tets(pts, regions[FLUID], locked)
    mesh = mesh_from_arrays_3d(pts, regions, boundaries)
    check_mesh(mesh, where)
    return mesh


# -- the unloaded OCT scan as the reference geometry -------------------------------------------
def colony_from_oct(
    source: Any,
    voxel_size: tuple[float, float, float],
    path: str | Path,
    **options: Any,
) -> OctSegmentation:
    """Segment an (unloaded) OCT scan and write its surface, in model axes, to ``path``: the
    ``colony_surface`` of a ``colony_3d`` model whose reference geometry is the scan.

    ``source`` and ``options`` are those of :func:`fbia.imaging.oct.segment_oct` (an array or a
    .npy/.npz/TIFF/NRRD file; ``attenuation``, ``crop_mm``, ...); the scan's x and y (in mm
    from its voxel 0) become the model's x and z, so give the model the duct the scan
    shows, or move the colony by ``colony_offset``.  Returns the segmentation (for figures).
    """
    from ...imaging.oct import in_model_axes, segment_oct

    seg = segment_oct(source, voxel_size, **options)
    in_model_axes(seg.interface, "y").write(path)
    return seg
