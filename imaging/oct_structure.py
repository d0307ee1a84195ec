"""What a segmented OCT scan says about the biofilm: structure parameters and the check that
the interface is one surface (issue 45 item 4).

The structure parameters are those OCT and confocal biofilm studies compare across
experiments (COMSTAT, Heydorn et al. 2000; the OCT flow-cell analyses of Wagner & Horn 2017),
computed from the segmentation's voxels and its thickness map T (the height of the biofilm's
outer boundary above the substratum at every A-scan, 0 where bare):

* thickness: the mean of T over the field and over the covered A-scans, its maximum and
  standard deviation;
* biovolume: the biofilm's voxels (inside its outer boundary, pores left out) times the
  voxel volume [mm^3], and per substratum area [mm^3/mm^2 = mm];
* substratum coverage: the share of the A-scans whose lowest row above the substratum is
  biofilm;
* roughness: Ra = mean |T - mean T|, Rq = sqrt(mean (T - mean T)^2) [mm], and COMSTAT's
  roughness coefficient Ra* = Ra / mean T [-];
* porosity: the share of the volume inside the outer boundary that is not biofilm (pores and
  voids the resolution cannot open to the fluid).

The check (:class:`OctQuality`): the share of the interface's area (and of its vertices)
hidden from the probe by more than one axial resolution cell (farther than that from the
surface the probe sees first: the outer boundary's thickness map).  A height map has none by
construction; marching cubes around speckle voids inside the biofilm puts most of a surface
there (issue 45: 78 % of the vertices of a real B-scan's surface lay more than 20 um under
the top), and the cpp measure would then match model vertices to pores: a surface with more
than :data:`MAX_DEEP_SHARE` of its area there is not one surface, and a study on it is
``unreliable``.  ``surface = "auto"`` (the default of :func:`fbia.imaging.oct.segment_oct`)
takes the height map instead of such an outer boundary.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..core.interface import Interface

__all__ = [
    "MAX_DEEP_SHARE",
    "MAX_OVERHANG_SHARE",
    "OctQuality",
    "OctStructure",
    "quality",
    "structure",
]

#: the largest share of an interface's area hidden from the probe (by more than one
#: axial resolution cell) for it to count as one surface.  Measured on marching cubes'
#: outer boundaries of the realistic family (30 scans) and of examples/oct_3d's dome: those
#: within 4.4 um RMS of the truth had 0.02-1.5 % of their area hidden, all others 3.9-61 %
#: (5.5-23.7 um RMS)
MAX_DEEP_SHARE = 0.02
#: the share of the covered A-scans with bulk fluid under their top (overhangs, or biofilm
#: shadowed under dense clusters) above which the quality note says so
MAX_OVERHANG_SHARE = 0.05


@dataclass(frozen=True)
class OctStructure:
    """Structure parameters of a segmented biofilm (module docstring); lengths in mm."""

    mean_thickness: float
    mean_thickness_covered: float
    max_thickness: float
    std_thickness: float
    biovolume: float  # mm^3
    biovolume_per_area: float  # mm^3 / mm^2
    coverage: float  # [-]
    ra: float
    rq: float
    roughness_coefficient: float  # [-]
    porosity: float  # [-]

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class OctQuality:
    """Whether a segmented interface is one surface (module docstring)."""

    deep_area_share: float  # of the area, hidden from the probe by more than a resolution cell
    deep_vertex_share: float  # of the vertices, the same
    depth_limit: float  # that cell [mm]
    overhang_share: float  # of the covered A-scans, with bulk fluid under their top
    surface_kind: str  # "height_map" or "outer"
    #: the outer boundary's check when surface = "auto" rejected it for the height map
    rejected: OctQuality | None = None

    @property
    def one_surface(self) -> bool:
        return self.deep_area_share <= MAX_DEEP_SHARE

    def note(self) -> str:
        """One line for a warning or a report."""
        share = f"{100 * self.deep_area_share:.1f} %"
        if self.one_surface:
            covered = ""
            if self.overhang_share > MAX_OVERHANG_SHARE and self.surface_kind == "height_map":
                covered = (
                    f"; {100 * self.overhang_share:.0f} % of the covered A-scans have fluid "
                    "under their top that reaches the bulk (overhangs, or biofilm shadowed "
                    "under dense clusters: attenuation), which the height map covers"
                )
            if self.rejected is not None:
                covered += (
                    f"; the outer boundary was not one surface ("
                    f"{100 * self.rejected.deep_area_share:.1f} % of its area hidden from the "
                    "probe): the height map instead"
                )
            return f"one surface: {share} of its area hidden from the probe{covered}"
        return (
            f"not one surface: {share} of the interface's area (more than "
            f"{100 * MAX_DEEP_SHARE:g} %) lies more than {1000 * self.depth_limit:.3g} um "
            "from what the probe sees first (speckle voids or pores wrapped by the surface, "
            "or wide overhangs): surface = 'height_map', a larger resolution or denoise_size"
        )

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "one_surface": self.one_surface}


def structure(
    thickness: NDArray[np.float64],
    biofilm: NDArray[np.bool_],
    outer: NDArray[np.bool_],
    spacing: tuple[float, float, float],
) -> OctStructure:
    """The parameters of the module docstring from the thickness map (ny, nx) [mm], the
    biofilm's voxels and its outer boundary's (nz, ny, nx; the last row the one right above
    the substratum)."""
    dz, dy, dx = spacing
    t = np.asarray(thickness, dtype=np.float64)
    covered = t > 0
    mean = float(t.mean())
    ra = float(np.mean(np.abs(t - mean)))
    inside = int(np.count_nonzero(outer))
    voxels = int(np.count_nonzero(biofilm & outer))
    area = t.size * dy * dx
    return OctStructure(
        mean_thickness=mean,
        mean_thickness_covered=float(t[covered].mean()) if covered.any() else 0.0,
        max_thickness=float(t.max()),
        std_thickness=float(t.std()),
        biovolume=voxels * dz * dy * dx,
        biovolume_per_area=voxels * dz * dy * dx / area,
        coverage=float(np.mean(biofilm[-1])) if len(biofilm) else 0.0,
        ra=ra,
        rq=float(np.sqrt(np.mean((t - mean) ** 2))),
        roughness_coefficient=ra / mean if mean > 0 else 0.0,
        porosity=1.0 - voxels / inside if inside else 0.0,
    )


def quality(
    surface: Interface,
    seen: NDArray[np.float64],
    origin: tuple[int, int],
    spacing: tuple[float, float, float],
    depth_limit: float,
    overhang_share: float,
    surface_kind: str,
    rejected: OctQuality | None = None,
) -> OctQuality:
    """How much of ``surface`` (x, y, z = height; normals into the fluid) lies hidden from
    the probe by more than ``depth_limit`` [mm]: farther than that from the surface the probe
    sees first, ``seen``, the thickness map (ny, nx) of the outer boundary [mm] over the
    A-scans from index ``origin`` (y, x).  A point's distance to it is taken to first order:
    its depth under the map (bilinear between A-scans) over sqrt(1 + |grad h|^2), the
    distance to the map's local tangent plane; so a steep flank or wall between two A-scans
    lies within half an A-scan of the map, a wall that leans over by less than a resolution
    cell within one cell, and a pore or speckle void the surface wraps, or the underside of
    a wide overhang, its depth under the top.  A height field (``surface_kind``
    "height_map") is the map itself: nothing lies under it.  (Measured against the depth
    under the top of the same A-scan alone: a dome bent by the flow, its downstream wall
    leaning over, had 7 % of its marching-cubes area more than a cell under the top, and no
    wrapped void.)"""
    if surface_kind == "height_map":  # a height field is its own top: nothing lies under it
        return OctQuality(
            0.0, 0.0, float(depth_limit), float(overhang_share), surface_kind, rejected
        )
    _, dy, dx = spacing
    h = np.asarray(seen, dtype=np.float64)
    ny, nx = h.shape
    v = surface.vertices
    centroids = v[surface.cells].mean(axis=1)
    area = np.linalg.norm(surface.area_vectors, axis=1)

    def hidden(p: NDArray[np.float64]) -> NDArray[np.bool_]:
        u = np.clip(p[:, 0] / dx - origin[1], 0.0, nx - 1.0)
        w = np.clip(p[:, 1] / dy - origin[0], 0.0, ny - 1.0)
        i = np.minimum(np.floor(u).astype(int), max(nx - 2, 0))
        j = np.minimum(np.floor(w).astype(int), max(ny - 2, 0))
        fu, fw = u - i, w - j
        i1, j1 = np.minimum(i + 1, nx - 1), np.minimum(j + 1, ny - 1)
        h00, h01, h10, h11 = h[j, i], h[j, i1], h[j1, i], h[j1, i1]
        top = (1 - fw) * ((1 - fu) * h00 + fu * h01) + fw * ((1 - fu) * h10 + fu * h11)
        hx = ((1 - fw) * (h01 - h00) + fw * (h11 - h10)) / dx
        hy = ((1 - fu) * (h10 - h00) + fu * (h11 - h01)) / dy
        depth = np.maximum(top - p[:, 2], 0.0)
        return np.asarray(depth / np.sqrt(1.0 + hx**2 + hy**2) > depth_limit)

    deep = hidden(centroids)
    deep_points = hidden(v)
    total = float(area.sum())
    return OctQuality(
        deep_area_share=float(area[deep].sum()) / total if total > 0 else 0.0,
        deep_vertex_share=float(np.mean(deep_points)) if len(v) else 0.0,
        depth_limit=float(depth_limit),
        overhang_share=float(overhang_share),
        surface_kind=surface_kind,
        rejected=rejected,
    )
