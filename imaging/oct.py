"""OCT scans as observations: read a volume, segment the biofilm, extract its surface (issue 18).

>>> import fbia
>>> from fbia.testing.oct import oct_phantom
>>> ph = oct_phantom(shape=(24, 20, 20), seed=0)
>>> seg = segment_oct(ph.volume, voxel_size=ph.voxel_size)
>>> seg.substratum_row, round(seg.substratum_depth, 4), round(ph.substratum_depth, 4)
(20, 0.195, 0.195)
>>> obs = fbia.observation_from_oct(ph.volume, ph.voxel_size, {"inflow_rate": 0.0})
>>> obs.interface.dim
3

Optical coherence tomography images a biofilm as a stack of B-scans; fbia needs the
fluid–biofilm interface as a triangle surface (:class:`~fbia.core.interface.Interface`).

Axes.  The volume is an array whose *depth* axis (``depth_axis``, default 0) grows away from
the probe, towards the substratum at the bottom; the two other axes, in their array order,
are y and x.  A TIFF stack of B-scans, one page per y position with rows in depth, has shape
(ny, nz, nx): ``depth_axis=1``.  ``voxel_size`` is (dz, dy, dx) in mm, and crops are index
ranges (``crop``) or mm boxes (``crop_mm``) in the same (z, y, x) order.  The surface comes
out in fbia's frame (the one of the ``analytic_mound_3d`` dome): x and y from voxel index 0
of the full volume, z the height above the substratum, triangles ordered so that their
normals point out of the biofilm into the fluid.

Steps of :func:`segment_oct`:

0. intensities (:func:`normalise_intensities`): the (cropped) scan's least intensity is
   subtracted exactly and the rest divided by its range, so that every later step sees
   float32 values from 0 to 1 whatever the scan's scale, offset or dtype (measured on fbia's
   phantoms: times 1e-300 to 1e300, or as int64 near 2^58 or 2^58 plus the signal times
   2^35 to 2^42, into the bit-identical surface; quantised to uint16 or uint8, within a
   voxel of it with the Gaussian filter, 2.1 voxels with the median one on uint8).
   Thresholds, reported or given, stay in the scan's units;
1. window and substratum (:mod:`fbia.imaging.oct_reflections`; and a check of
   ``depth_axis``: a reflection that stands out three times more across another axis of the
   scan is an error naming that axis): the flat thin bright lines across the A-scans as
   planes, the window (the biofilm under it) filled with the fluid under it, the scan
   untilted along the substratum's plane (the biofilm above it), its surface at the upper
   half-maximum edge of its line, the rows the line bleeds into cleared; or
   ``substratum_depth`` (and ``substratum_tilt``) given by the user, as on a membrane, which
   shows no line and is refused without them; the rows under the surface are dropped;
2. denoising: a Gaussian filter (default) or a median filter;
3. depth-attenuation compensation: the intensity's excess over the scan's least one times
   ``exp(mu d)`` at depth d below the first row, the inverse of a Beer–Lambert decay
   ``exp(-mu d)`` with ``mu`` [1/mm] given by the user (0: none) or ``"auto"``: estimated from
   the biofilm's own decay (a rough estimate, see ``_estimate_attenuation``; give the value
   when it is known); the least intensity stands for a background that is not attenuated
   (the noise floor of :mod:`fbia.testing.oct`, an offset of the scan);
4. threshold: Otsu's (Otsu 1979) between biofilm and fluid, or a user value, of the
   processed intensity in the scan's units: the least intensity plus the denoised,
   compensated excess over it (with ``attenuation = 0``, the denoised intensity itself);
5. cleanup (:mod:`fbia.imaging.oct_surface`): only the biofilm connected to the substratum
   is kept, in parts of at least ``min_voxels`` voxels (speckle specks on it go); fluid
   pockets closed off from the top and the side walls are filled; then the outer boundary:
   fluid that reaches the bulk only through openings narrower than the ``resolution``
   (speckle voids, unresolved pores) is biofilm;
6. surface: marching cubes (Lorensen & Cline 1987; scikit-image's Lewiner variant) on the
   processed intensity at the threshold level over the outer boundary, so vertices lie
   between voxel centres where the intensity crosses it (the faces on the substratum plane
   dropped, none on the crop box's walls), kept where it is one surface
   (:func:`fbia.imaging.oct_structure.quality`), else the height map (where each A-scan
   first meets the outer boundary): ``surface = "auto"``, or either by name;
7. check (:func:`surface_degeneracy`): a surface of fewer than :data:`MIN_TRIANGLES`
   triangles, or whose footprint on the substratum covers less than :data:`MIN_FOOTPRINT`
   of the scan's lateral field of view, cannot be the biofilm's interface (a wrong substratum
   or threshold, a biofilm too small for the field) and is refused, so that no calibration
   starts from it;
8. what it says (:mod:`fbia.imaging.oct_structure`): the one-surface check and the
   structure parameters (thickness, biovolume, coverage, roughness, porosity).

Every refusal is one :class:`~fbia.core.errors.ConfigError` line, and the warnings of the
libraries called (NumPy, scikit-image) are either avoided (Otsu's histogram in double
precision) or that line, so nothing is printed before it.

:mod:`fbia.imaging.oct_reader` reads the volume;
:func:`fbia.studies.oct_figures.write_segmentation_figures` draws the B-scan as read with the
window, the substratum and the interface, and a 3-D view of the surface, so that a user sees
what was segmented; ``docs/oct_segmentation.md`` goes through the options for real scans.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, field_validator, model_validator

from ..core.errors import ConfigError
from ..core.extras import require
from ..core.interface import Interface
from ..core.observation import Coordinate, Observation
from ..core.options import PluginOptions
from .oct_reader import read_oct_volume
from .oct_reflections import Reflection, place_floor
from .oct_structure import OctQuality, OctStructure, quality, structure
from .oct_surface import (
    height_map,
    height_surface,
    keep_attached,
    marching_cubes_surface,
    outer_boundary,
    overhang_share,
)

__all__ = [
    "HeightAxis",
    "MIN_FOOTPRINT",
    "MIN_LEVELS",
    "MIN_TRIANGLES",
    "OctOptions",
    "OctSegmentation",
    "footprint_area",
    "in_model_axes",
    "normalise_intensities",
    "observation_from_oct",
    "segment_oct",
    "surface_degeneracy",
]

Crop = tuple[tuple[int, int] | None, tuple[int, int] | None, tuple[int, int] | None]
#: the fewest distinct intensities a scan must take to be segmented
#: (:func:`normalise_intensities`)
MIN_LEVELS = 32
#: processed intensities closer than this share of the greatest are one value (Otsu's
#: histogram cannot divide a narrower range into its bins)
_UNIFORM = 1e-9
CropMm = tuple[tuple[float, float] | None, tuple[float, float] | None, tuple[float, float] | None]
#: the forward model's axis along the height above the substratum (:func:`in_model_axes`)
HeightAxis = Literal["z", "y"]
#: the fewest triangles and the least footprint share of the scan's lateral field of view of
#: a segmented surface that can be a biofilm interface (:func:`surface_degeneracy`)
MIN_TRIANGLES = 20
MIN_FOOTPRINT = 0.05


class OctOptions(PluginOptions):
    """How :func:`segment_oct` reads and segments a volume (see the module docstring)."""

    depth_axis: int = Field(
        0, ge=0, le=2, description="array axis along depth (index grows towards the substratum)"
    )
    crop: Crop | None = Field(
        None,
        description=(
            "region of interest: one [start, stop) index pair (or None: all) per axis, in the "
            "order (z, y, x) after moving depth first"
        ),
    )
    crop_mm: CropMm | None = Field(
        None,
        description=(
            "region of interest in mm instead of indices: one [low, high] pair (or None) per "
            "axis (z = depth below the first row's centre, y, x); the voxels whose centres "
            "lie inside are kept"
        ),
    )
    attenuation: float | Literal["auto"] = Field(
        0.0, description="depth attenuation mu to compensate [1/mm], or 'auto' (estimated)"
    )
    denoise: Literal["gaussian", "median", "none"] = Field(
        "gaussian", description="denoising filter"
    )
    denoise_size: float = Field(
        1.0, gt=0, le=10, description="Gaussian sigma or median half-width [voxels]"
    )
    threshold: float | None = Field(
        None,
        description=(
            "biofilm/fluid threshold of the processed intensity, in the scan's units (the "
            "denoised intensity when attenuation is 0); None: Otsu"
        ),
    )
    min_contrast: float = Field(
        2.0,
        gt=1,
        description=(
            "least ratio of the mean biofilm to the mean fluid intensity (both above the "
            "scan's least intensity) for Otsu's split to count as biofilm (a lower one splits "
            "one population: no biofilm) [-]"
        ),
    )
    min_voxels: int = Field(
        27,
        ge=1,
        description="smallest biofilm part kept (connected voxels on the substratum; 27 = 3^3)",
    )
    substratum_depth: float | None = Field(
        None,
        ge=0,
        description="depth of the substratum below the first row [mm]; None: detect its "
        "reflection (refused when there is none, e.g. on a membrane)",
    )
    substratum_tilt: tuple[float, float] = Field(
        (0.0, 0.0),
        description="with substratum_depth: the substratum's slope, depth per lateral "
        "distance along y and along x [mm/mm] (substratum_depth is its depth at the field's "
        "centre); a found substratum's tilt is measured",
    )
    window: Literal["auto", "none"] = Field(
        "auto",
        description="'auto': a flat reflection with the biofilm under it (the flow cell's "
        "window) is found and everything down to it taken for fluid; 'none': not sought",
    )
    resolution: tuple[float, float] | None = Field(
        None,
        description="the scanner's (axial, lateral) resolution, FWHM [mm]; None: 2 voxels "
        "each way. Fluid reaching the bulk through openings narrower than it is biofilm "
        "(speckle voids, unresolved pores)",
    )
    surface: Literal["auto", "height_map", "outer"] = Field(
        "auto",
        description="'outer': marching cubes on the biofilm's outer boundary (overhangs "
        "kept); 'height_map': where each A-scan first meets the biofilm (overhangs covered); "
        "'auto': the outer boundary when it is one surface (no more than 2 % of its area "
        "hidden from the probe), else the height map",
    )

    @model_validator(mode="after")
    def _one_crop(self) -> Self:
        if self.crop is not None and self.crop_mm is not None:
            raise ValueError("give crop (indices) or crop_mm (mm), not both")
        return self

    @field_validator("attenuation", mode="before")
    @classmethod
    def _check_attenuation(cls, value: Any) -> float | str:
        if value == "auto":
            return "auto"
        try:
            mu = float(value)
        except (TypeError, ValueError):
            mu = math.nan
        if isinstance(value, bool) or not (math.isfinite(mu) and mu >= 0.0):
            raise ValueError("must be a finite number >= 0 [1/mm] or 'auto'")
        return mu

    @field_validator("crop_mm")
    @classmethod
    def _check_crop_mm(cls, value: CropMm | None) -> CropMm | None:
        for pair in value or ():
            if pair is not None and not (
                math.isfinite(pair[0]) and math.isfinite(pair[1]) and pair[0] < pair[1]
            ):
                raise ValueError(f"each [low, high] must be finite with low < high, got {pair}")
        return value

    @field_validator("crop")
    @classmethod
    def _check_crop(cls, value: Crop | None) -> Crop | None:
        for pair in value or ():
            if pair is not None and not 0 <= pair[0] < pair[1]:
                raise ValueError(f"each [start, stop) must have 0 <= start < stop, got {pair}")
        return value

    @field_validator("substratum_tilt")
    @classmethod
    def _check_tilt(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not all(math.isfinite(v) and abs(v) <= 1.0 for v in value):
            raise ValueError(f"must be two slopes between -1 and 1 [mm/mm], got {value}")
        return value

    @field_validator("resolution")
    @classmethod
    def _check_resolution(cls, value: tuple[float, float] | None) -> tuple[float, float] | None:
        if value is not None and not all(math.isfinite(v) and v > 0 for v in value):
            raise ValueError(f"must be two positive numbers (axial, lateral) in mm, got {value}")
        return value

    @field_validator("threshold")
    @classmethod
    def _check_threshold(cls, value: float | None) -> float | None:
        if value is not None and not math.isfinite(value):
            raise ValueError("must be finite")
        return value


@dataclass(frozen=True)
class OctSegmentation:
    """What :func:`segment_oct` found.

    Attributes
    ----------
    interface
        The fluid–biofilm surface [mm] (x, y, z = height above the substratum).
    voxel_size
        (dz, dy, dx) [mm].
    origin
        Index (z, y, x) of the crop's first voxel in the full volume.
    substratum_row
        First depth row (full volume) under the substratum surface.
    threshold
        Threshold of the processed intensity (Otsu's or the user's), in the scan's units
        (step 4 of the module docstring): given as ``threshold``, it segments the same.
    attenuation
        Attenuation coefficient compensated [1/mm].
    biofilm_voxels
        Voxels of the biofilm kept.
    bscan_row
        y index (full volume) of the B-scan kept for the figures.
    bscan
        That B-scan of the cropped input, shape (crop depth, crop nx), in double precision.
    field
        The same B-scan processed (window filled, untilted, denoised, compensated, cleaned),
        rows down to ``substratum_row``, in the scan's units (those of ``threshold``).
    surface_kind
        "height_map" or "outer" (option ``surface``).
    reflections
        The flat reflections found (:mod:`fbia.imaging.oct_reflections`), rows of the crop.
    tilt
        The substratum plane's slope taken out, rows per A-scan along y and x.
    window_row
        Row (full volume) of the window's reflection at the field's centre, if found.
    bscan_lines
        Along ``bscan``, in rows of the full volume: "substratum" (its surface), "window"
        (or None) and "interface" (the top of the segmented interface; NaN where bare).
    quality
        Whether the interface is one surface, and the share of the A-scans with fluid under
        their top (:class:`~fbia.imaging.oct_structure.OctQuality`).
    structure
        Thickness, biovolume, coverage, roughness, porosity
        (:class:`~fbia.imaging.oct_structure.OctStructure`).
    """

    interface: Interface
    voxel_size: tuple[float, float, float]
    origin: tuple[int, int, int]
    substratum_row: int
    threshold: float
    attenuation: float
    biofilm_voxels: int
    bscan_row: int
    bscan: NDArray[np.float64]
    field: NDArray[np.float64]
    surface_kind: Literal["height_map", "outer"]
    reflections: tuple[Reflection, ...]
    tilt: tuple[float, float]
    window_row: float | None
    bscan_lines: Mapping[str, NDArray[np.float64] | None]
    quality: OctQuality
    structure: OctStructure

    @property
    def substratum_depth(self) -> float:
        """Depth of the substratum surface below the first row's centre [mm]."""
        return (self.substratum_row - 0.5) * self.voxel_size[0]


def in_model_axes(surface: Interface, height_axis: HeightAxis = "z") -> Interface:
    """A segmented surface (x, y, z = height) in the axes of a forward model.

    ``"z"``: unchanged, fbia's frame (``analytic_mound_3d``).  ``"y"``: (x, height, y), the
    axes of ``ale_fsi``'s 3-D geometries (x along the flow, y up, z across the duct), so the
    scan's y is the model's z.  Swapping two axes mirrors the surface: the triangles are
    reversed to keep their normals pointing into the fluid.  The map is its own inverse, so
    ``in_model_axes(deformed, "y")`` also puts an ``ale_fsi`` surface in the scan's frame.
    """
    if height_axis == "z":
        return surface
    if height_axis != "y":
        raise ConfigError(f"height_axis must be 'z' or 'y', got {height_axis!r}", "in_model_axes")
    return Interface.surface(surface.vertices[:, [0, 2, 1]], surface.cells[:, ::-1])


# -- segmentation ------------------------------------------------------------------------------
def segment_oct(
    source: str | Path | ArrayLike,
    voxel_size: tuple[float, float, float],
    options: OctOptions | Mapping[str, Any] | None = None,
    **kwargs: Any,
) -> OctSegmentation:
    """Segment the biofilm in an OCT volume and extract the fluid–biofilm surface.

    Parameters
    ----------
    source
        A 3-D array or a file (see :func:`fbia.imaging.oct_reader.read_oct_volume`).
    voxel_size
        (dz, dy, dx) [mm].
    options, kwargs
        :class:`OctOptions`, as an instance, a mapping or keywords.
    """
    where = str(source) if isinstance(source, str | Path) else "oct volume"
    require(("skimage",), "OCT segmentation")
    opts = _options(options, kwargs, where)
    spacing = _voxel_size(voxel_size, where)
    full = read_oct_volume(source, opts.depth_axis)
    if opts.crop_mm is not None:
        scan, origin = _crop(full, _crop_indices(opts.crop_mm, spacing), "crop_mm", where)
    else:
        scan, origin = _crop(full, opts.crop, "crop", where)
    # 0. intensities of order 1 whatever the scan's scale, offset and dtype
    volume, least, span = normalise_intensities(scan, where)
    dz = spacing[0]
    axial, lateral = _resolution(opts, spacing)
    if opts.substratum_depth is None:
        _check_depth_axis(volume, opts.depth_axis, where)
    # 1. window and substratum: the window filled with fluid, the scan untilted, the rows
    #    from the substratum's reflection down dropped
    floor, volume = place_floor(
        volume,
        origin,
        opts.substratum_depth,
        opts.substratum_tilt,
        opts.window == "auto",
        spacing,
        axial,
        lateral,
        where,
    )
    ks = floor.ks
    # 2. denoise the rows above the substratum (its bright reflection would bleed upwards)
    #    into the field marching cubes reads, with one more row for the floor
    field = np.empty((ks + 1, *volume.shape[1:]), dtype=np.float32)
    above = field[:ks]
    _denoise(volume[:ks], above, opts.denoise, opts.denoise_size)
    # 3. compensate the decay exp(-mu d), d = depth below the full volume's first row
    depth = (np.arange(ks, dtype=np.float64) + origin[0]) * dz
    mu = (
        _estimate_attenuation(above, depth, opts.min_contrast, where)
        if opts.attenuation == "auto"
        else float(opts.attenuation)
    )
    if mu * depth[-1] > 30.0:
        raise ConfigError(
            f"attenuation {mu:g} 1/mm would amplify the deepest rows by "
            f"exp({mu * depth[-1]:.3g}) (more than e^30); check its unit (1/mm) and voxel_size",
            where,
        )
    above *= np.exp(mu * depth).astype(np.float32)[:, None, None]
    del volume  # the rows needed are in field

    def in_scan_units(value: float) -> float:  # a processed intensity, as the scan's
        return float(least) + span * value

    # 4. threshold (the user's is in the scan's units, like the one reported)
    lo, hi = float(above.min()), float(above.max())
    if opts.threshold is not None:
        t = (float(opts.threshold) - float(least)) / span
        if not lo < t < hi:
            raise ConfigError(
                f"threshold {opts.threshold:g} lies outside the processed intensities "
                f"({in_scan_units(lo):.4g} to {in_scan_units(hi):.4g}): give one between "
                "them, or none (Otsu's)",
                where,
            )
    else:
        t = _otsu(above, lo, hi, where)
    mask = above > t
    if not mask.any():
        raise ConfigError(
            f"no biofilm found: no voxel above the threshold {in_scan_units(t):.4g}", where
        )
    high = float(above[mask].mean(dtype=np.float64))
    low = float(above[~mask].mean(dtype=np.float64)) if not mask.all() else t
    if opts.threshold is None and high < opts.min_contrast * low:
        raise ConfigError(
            f"no biofilm found: Otsu's threshold {in_scan_units(t):.4g} splits one population "
            f"(class means {span * high:.4g} and {span * low:.4g} above the scan's least "
            f"intensity, ratio below min_contrast = {opts.min_contrast:g}); give a threshold "
            "if there is biofilm",
            where,
        )
    # 5. keep what hangs on the substratum, fill closed fluid pockets, then the outer
    #    boundary: fluid that reaches the bulk only through openings narrower than the
    #    resolution (speckle voids, unresolved pores) is biofilm
    solid = keep_attached(mask, opts.min_voxels)
    if not solid.any():
        raise ConfigError(
            f"no biofilm found: no part of at least {opts.min_voxels} voxels above the threshold "
            f"{in_scan_units(t):.4g} touches the substratum (row {ks + origin[0]})",
            where,
        )
    outer = outer_boundary(
        solid, (max(1.0, 0.5 * axial), max(1.0, 0.5 * lateral[0]), max(1.0, 0.5 * lateral[1]))
    )
    above[mask & ~outer] = min(low, t)
    above[~mask & outer] = max(high, t)
    # the substratum row mirrors the fluid above it about t: the floor crosses t half-way
    under = above[-1]
    field[ks] = np.where(under > t, under, 2.0 * t - under)
    # 6. the surface: the height map, or marching cubes on the outer boundary
    top_row = np.where(outer.any(axis=0), np.argmax(outer, axis=0), ks)
    overhangs = overhang_share(outer, top_row, max(1, math.ceil(axial)))
    thickness = height_map(field, t, top_row, ks, dz)
    yx = (origin[1], origin[2])
    kind: Literal["height_map", "outer"] = "height_map" if opts.surface == "height_map" else "outer"
    rejected: OctQuality | None = None
    if kind == "outer":
        surface = marching_cubes_surface(field, t, outer, ks, origin, spacing, where)
        check = quality(surface, thickness, yx, spacing, axial * dz, overhangs, "outer")
        if opts.surface == "auto" and not check.one_surface:
            # marching cubes wrapped what the probe does not see: the height map instead
            rejected = check
            kind = "height_map"
    if kind == "height_map":
        surface = height_surface(thickness, origin, spacing, where)
        check = quality(
            surface, thickness, yx, spacing, axial * dz, overhangs, "height_map", rejected
        )
    # 7. a surface that cannot be the biofilm's interface ends here, not in a calibration
    fov = (field.shape[1] * spacing[1], field.shape[2] * spacing[2])
    cause = surface_degeneracy(surface, fov)
    if cause is not None:
        otsu = "Otsu's threshold" if opts.threshold is None else "threshold"
        raise ConfigError(
            f"{cause}; the substratum or the threshold may be wrong, or a biofilm this small "
            f"needs crop_mm around it; segmentation: intensities {float(least):.4g} to "
            f"{float(least) + span:.4g}, substratum row {ks + origin[0]}, {otsu} "
            f"{in_scan_units(t):.4g}, attenuation {mu:g} 1/mm, denoise {opts.denoise} "
            f"{opts.denoise_size:g}",
            where,
        )
    # 8. what the segmentation says: structure parameters, and whether it is one surface
    parameters = structure(thickness, mask, outer, spacing)
    j = field.shape[1] // 2
    lines = floor.lines_in_scan(j, field.shape[2])
    interface_rows = np.where(top_row[j] < ks, ks - 0.5 - thickness[j] / dz, np.nan) + floor.shift(
        j, field.shape[2]
    )
    return OctSegmentation(
        interface=surface,
        voxel_size=spacing,
        origin=origin,
        substratum_row=ks + origin[0],
        threshold=in_scan_units(t),
        attenuation=float(mu),
        biofilm_voxels=int(np.count_nonzero(outer & mask)),
        bscan_row=j + origin[1],
        bscan=scan[:, j, :].astype(np.float64),
        field=float(least) + span * field[:, j, :].astype(np.float64),
        surface_kind=kind,
        reflections=floor.reflections,
        tilt=floor.tilt,
        window_row=None if floor.window is None else floor.window.row + origin[0],
        bscan_lines={**lines, "interface": interface_rows},
        quality=check,
        structure=parameters,
    )


def observation_from_oct(
    source: str | Path | ArrayLike,
    voxel_size: tuple[float, float, float],
    coordinate: Coordinate | None = None,
    noise_std: float | None = None,
    name: str = "",
    **options: Any,
) -> Observation:
    """An observation whose interface is segmented from an OCT volume (an array, or a
    .npy/.npz/TIFF/NRRD file) with voxel size (dz, dy, dx) [mm]; ``options`` are those of
    :class:`OctOptions`.  :func:`segment_oct` does the work and also returns what a figure of
    the segmentation needs (``fbia.observation_from_oct``)."""
    seg = segment_oct(source, voxel_size, **options)
    return Observation(seg.interface, coordinate or {}, noise_std=noise_std, name=name)


def footprint_area(surface: Interface) -> float:
    """Area of the biofilm's footprint on the substratum plane [mm^2]: the z-component of the
    sum of the area vectors of a segmented surface (normals into the fluid).  The surface,
    closed by its dropped floor faces and the (vertical) crop walls, bounds the biofilm, so
    its area vectors add up to those of the floor, reversed: the footprint, folds and
    overhangs counted once."""
    return float(surface.area_vectors[:, 2].sum())


def surface_degeneracy(surface: Interface, field_of_view: tuple[float, float]) -> str | None:
    """Why a segmented surface (x, y, z = height; normals into the fluid) cannot be the
    biofilm interface of a scan whose lateral field of view is ``field_of_view`` (its y and x
    extents [mm]), or None when it can.

    A surface is degenerate when it has fewer than :data:`MIN_TRIANGLES` (20) triangles, or
    when its footprint (:func:`footprint_area`) covers less than :data:`MIN_FOOTPRINT` (5 %)
    of the field of view.  Measured (issue 43) on fbia's phantoms
    (:func:`fbia.testing.oct.oct_phantom`, its default dome; 20 x 20 to 64 x 64 voxels
    laterally, seeds 0-3, attenuation 0, 2 and 5 1/mm compensated with the true or the
    estimated value): 836 to 7086 triangles over 29 to 36 % of the field; on the scans of
    ``examples/oct_3d/make_scan.py`` (loaded, unloaded, matched; its voxels and twice them):
    12329 to 49633 triangles over 31 to 32 %.  The floors lie about 40 and 6 times lower.
    Before the intensities were normalised (issue 44), the same phantoms times 1e-30, or
    times 2^58 stored as int64, segmented into 1 to 10 and 2 to 197 triangles covering at
    most 0.22 and 3.2 % of the field; some were specks scattered over 98 % of the lateral
    extent, so the vertices' span does not tell them apart (the footprint bounds it anyway),
    and some scales over-segmented instead, which no rule on the surface alone catches.  Now
    every scale segments alike, and what the check meets is a biofilm too small for the
    field (the phantom's dome shrunk to semi-axes of 0.1 mm, 3.1 % of a 0.96 mm field: a
    case for ``crop_mm``) or a wrong substratum or threshold.

    >>> square = Interface.surface([[0, 0, 0.01], [0.02, 0, 0.01], [0.02, 0.02, 0.01],
    ...                             [0, 0.02, 0.01]], [[0, 1, 2], [0, 2, 3]])
    >>> print(surface_degeneracy(square, (0.96, 0.96)))  # doctest: +ELLIPSIS
    the segmented surface is degenerate: 2 triangles covering 0.043 % of the scan's field ...
    """
    share = footprint_area(surface) / (field_of_view[0] * field_of_view[1])
    n = len(surface.cells)
    if n >= MIN_TRIANGLES and share >= MIN_FOOTPRINT:
        return None
    percent = f"{100 * share:.2g}" if abs(share) < 0.1 else f"{100 * share:.0f}"
    return (
        f"the segmented surface is degenerate: {n} triangle{'s' * (n != 1)} covering "
        f"{percent} % of the scan's field of view ({field_of_view[0]:.3g} x "
        f"{field_of_view[1]:.3g} mm); a biofilm interface has at least {MIN_TRIANGLES} "
        f"triangles over at least {100 * MIN_FOOTPRINT:g} % of it"
    )


def normalise_intensities(
    scan: NDArray[Any], where: str = "oct volume"
) -> tuple[NDArray[np.float32], Any, float]:
    """The intensities of ``scan`` (a volume in its own integer or floating dtype) as float32
    from 0 to 1, ``(I - least) / span``, with ``least`` (in the scan's dtype) and ``span``,
    the greatest intensity minus ``least``: step 0 of :func:`segment_oct`, which then sees the
    same numbers whatever the scan's scale, offset or dtype.

    ``least`` is removed exactly (in the scan's integer dtype, or in double or its own wider
    precision) before the values are rounded, so that an int64 scan near 2^58 keeps every
    step.  Refused, one line each: negative intensities (OCT intensities are linear, not log
    or dB), a constant scan, one of fewer than :data:`MIN_LEVELS` (32) distinct values (a
    mask, a coarse quantisation, or an offset its dtype cannot hold the signal on: fbia's
    phantom quantised to 32 levels or more segments within a voxel of its full-resolution
    surface, to 8-24 levels up to 5 voxels off, or its substratum or biofilm is lost), and
    voxels whose excess over ``least`` is under float32's smallest normal number (1.2e-38)
    of the span.

    >>> v = np.arange(64).reshape(4, 4, 4) * 3 + 5
    >>> a, least, span = normalise_intensities(v)
    >>> int(least), span, a.dtype.name, float(a.min()), float(a.max())
    (5, 189.0, 'float32', 0.0, 1.0)
    >>> same = [normalise_intensities(w)[0] for w in (2**58 + 2**40 * v, v * 1e-300, v * 1e300)]
    >>> all(np.array_equal(a, b) for b in same)
    True
    """
    least, greatest = scan.min(), scan.max()
    if least < 0:
        raise ConfigError(
            f"OCT intensities must be >= 0 (linear, not log or dB), got {least:.4g}", where
        )
    if greatest == least:
        raise ConfigError(
            f"volume is constant ({greatest:.6g} everywhere): nothing to segment", where
        )
    integer = np.issubdtype(scan.dtype, np.integer)
    work = np.dtype(np.float64) if integer else np.promote_types(scan.dtype, np.float64)
    span = work.type(greatest - least) if integer else work.type(greatest) - work.type(least)
    distinct = _distinct_values(scan)
    if distinct < MIN_LEVELS:
        step = 1 if integer else np.spacing(greatest)
        cause = (
            f"an offset of {least:.6g} swamps the signal ({span:.3g}) in {scan.dtype}, whose "
            f"steps there are {step:.3g}: store the scan with the offset subtracted"
            if not integer and span < MIN_LEVELS * step
            else "a mask, or a coarse quantisation? give the linear intensities"
        )
        raise ConfigError(
            f"the intensities take only {distinct} distinct values ({least:.10g} to "
            f"{greatest:.10g}), segmentation needs at least {MIN_LEVELS}: {cause}",
            where,
        )
    out = np.empty(scan.shape, dtype=np.float32)
    lost = 0
    tiny = np.finfo(np.float32).tiny
    for k in range(scan.shape[0]):  # row by row: no double-precision copy of the volume
        excess = (scan[k] - least).astype(work) if integer else scan[k].astype(work) - least
        out[k] = excess / span
        lost += int(np.count_nonzero((out[k] < tiny) & (excess > 0)))
    if lost:
        raise ConfigError(
            f"{lost} voxel(s) exceed the least intensity by under {tiny:.2g} of the range "
            f"({least:.4g} to {greatest:.4g}), which single precision does not hold: clip or "
            "crop out the brightest voxels",
            where,
        )
    return out, least, float(span)


def _distinct_values(scan: NDArray[Any]) -> int:
    """How many distinct values ``scan`` takes, or at least MIN_LEVELS: a lateral sample of
    about a million voxels, and the whole scan when the sample shows fewer."""
    stride = max(1, math.ceil(math.sqrt(scan.size / 1e6)))
    seen = len(np.unique(scan[:, ::stride, ::stride]))
    return seen if seen >= MIN_LEVELS or stride == 1 else len(np.unique(scan))


@contextmanager
def _no_library_warnings(step: str, where: str) -> Iterator[None]:
    """A numerical warning of the library calls inside (NumPy's, scikit-image's: overflow,
    an invalid value, a rank-deficient fit), which would print before fbia's own line and
    leave a result not to be trusted, is that line instead, naming the step."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            yield
        except RuntimeWarning as warning:
            raise ConfigError(f"{step} failed: {warning}", where) from None


def _options(options: Any, kwargs: Mapping[str, Any], where: str) -> OctOptions:
    if isinstance(options, OctOptions):
        if kwargs:
            raise TypeError("pass either an OctOptions instance or keyword options, not both")
        return options
    return OctOptions.parse({**dict(options or {}), **kwargs}, where=f"{where}: options")


def _voxel_size(voxel_size: Any, where: str) -> tuple[float, float, float]:
    try:
        size = tuple(float(v) for v in voxel_size)
    except (TypeError, ValueError):
        size = ()
    if len(size) != 3 or not all(math.isfinite(v) and v > 0 for v in size):
        raise ConfigError(
            f"voxel_size must be three positive numbers (dz, dy, dx) in mm, got {voxel_size!r}",
            where,
        )
    return size[0], size[1], size[2]


def _crop_indices(box: CropMm, spacing: tuple[float, float, float]) -> Crop:
    """Index ranges [start, stop) of the voxels whose centres ``k * d`` lie in ``box``."""
    out: list[tuple[int, int] | None] = []
    for r, d in zip(box, spacing, strict=True):
        if r is None:
            out.append(None)
        else:
            lo, hi = r
            out.append((max(0, math.ceil(lo / d - 1e-9)), math.floor(hi / d + 1e-9) + 1))
    return out[0], out[1], out[2]


def _crop(
    volume: NDArray[Any], crop: Crop | None, option: str, where: str
) -> tuple[NDArray[Any], tuple[int, int, int]]:
    ranges = list(crop) if crop is not None else [None, None, None]
    slices, origin = [], []
    for axis, (name, n, r) in enumerate(zip("zyx", volume.shape, ranges, strict=True)):
        start, stop = (0, n) if r is None else r
        if not (0 <= start < stop <= n):
            raise ConfigError(
                f"{option}: voxels [{start}, {stop}) of axis {name} leave the volume (0 to {n} "
                f"on that axis, shape {volume.shape})",
                where,
            )
        if stop - start < 3:
            raise ConfigError(f"axis {name} has {stop - start} voxel(s); at least 3 needed", where)
        slices.append(slice(start, stop))
        origin.append(start)
        del axis
    return volume[tuple(slices)], (origin[0], origin[1], origin[2])


def _plane_contrast(volume: NDArray[np.float32], axis: int = 0) -> NDArray[np.float64]:
    """How much each plane across ``axis`` stands out: the second difference of the log mean
    intensity of the planes along it, which an exponential decay leaves at zero (step 1 of the
    module docstring: the substratum is the plane that stands out most across depth)."""
    m = np.log(np.maximum(np.moveaxis(volume, axis, 0).mean(axis=(1, 2), dtype=np.float64), 1e-300))
    m = np.r_[m[1], m, m[-2]]  # the end planes compare with their one neighbour
    return m[1:-1] - 0.5 * (m[:-2] + m[2:])


def _reflection(volume: NDArray[np.float32], axis: int) -> float:
    """How much the brightest plane across ``axis`` stands out."""
    return float(np.max(_plane_contrast(volume, axis)))


def _check_depth_axis(volume: NDArray[np.float32], depth_axis: int, where: str) -> None:
    """The substratum's bright flat reflection lies across the depth axis: when it stands out
    3 times more across another axis of the scan (a clear one: a log step of 0.5 or more),
    ``depth_axis`` names the wrong one (on fbia's phantoms: 2.9 across depth, below 0.12
    across the others)."""
    seen = [_reflection(volume, a) for a in range(3)]  # depth first, then the others in order
    best = int(np.argmax(seen))
    if best != 0 and seen[best] >= 0.5 and seen[best] > 3.0 * max(seen[0], 0.0):
        original = [a for a in range(3) if a != depth_axis][best - 1]
        raise ConfigError(
            f"depth_axis = {depth_axis}, but the scan's bright flat reflection (the "
            f"substratum) lies across array axis {original} (it stands out {seen[best]:.2g} "
            f"there, {seen[0]:.2g} across axis {depth_axis}): depth_axis = {original}? (or "
            "give substratum_depth)",
            where,
        )


def _denoise(volume: NDArray[np.float32], out: NDArray[np.float32], kind: str, size: float) -> None:
    """``volume`` filtered into ``out`` (of its shape)."""
    from scipy import ndimage

    if kind == "gaussian":
        ndimage.gaussian_filter(volume, sigma=size, output=out, mode="nearest", truncate=3.0)
    elif kind == "median":
        ndimage.median_filter(volume, size=2 * max(1, round(size)) + 1, output=out, mode="nearest")
    else:
        out[...] = volume


def _otsu(values: NDArray[np.float32], lo: float, hi: float, where: str) -> float:
    """Otsu's threshold (Otsu 1979) of a sample of at most about 4 million of the processed
    intensities ``values`` (from ``lo`` to ``hi``), in double precision: the compensated
    intensities reach e^30, whose squared class means times squared counts overflow single
    precision, and the histogram needs a range its bins can divide."""
    from skimage.filters import threshold_otsu

    if not hi - lo > _UNIFORM * hi:
        raise ConfigError(
            "no biofilm found: the processed intensities above the substratum are one value "
            f"(they differ by under {_UNIFORM:g} of the greatest)",
            where,
        )
    step = max(1, int(math.ceil(math.sqrt(values.size / 4e6))))
    sample = values[:, ::step, ::step].astype(np.float64).ravel()  # 1-D: no "RGB image" warning
    with _no_library_warnings("Otsu's threshold", where):
        return float(threshold_otsu(sample, nbins=1024))


def _estimate_attenuation(
    g: NDArray[np.float32], depth: NDArray[np.float64], min_contrast: float, where: str
) -> float:
    """Attenuation mu [1/mm] for ``attenuation="auto"``: minus the slope of the log median
    intensity of the biofilm's interior over depth (a weighted least-squares line).  The
    biofilm of each row is the bright class of that row's own Otsu split (which a gain per
    row does not change), in rows where the two classes differ by ``min_contrast``; two
    erosions keep its interior, away from the blurred interface.  On ``fbia.testing.oct``
    volumes (2 looks, 0 to 8 /mm) it comes within about 1 /mm of the truth, lower when the
    noise floor dominates the deepest rows."""
    from scipy import ndimage
    from skimage.filters import threshold_otsu

    step = max(1, int(math.ceil(math.sqrt(g[0].size / 250_000))))
    sample = g[:, ::step, ::step]
    mask = np.zeros(sample.shape, dtype=bool)
    for k, row in enumerate(sample):
        lo, hi = float(row.min()), float(row.max())
        if not hi - lo > _UNIFORM * hi:
            continue
        with _no_library_warnings("attenuation 'auto': Otsu's split of a depth row", where):
            bright = row > threshold_otsu(row.astype(np.float64), nbins=256)
        if not bright.all() and row[bright].mean() >= min_contrast * row[~bright].mean():
            mask[k] = bright
    interior = ndimage.binary_erosion(mask, iterations=2)
    counts = interior.sum(axis=(1, 2))
    rows = np.flatnonzero(counts >= 20)
    med = np.array([np.median(sample[k][interior[k]]) for k in rows])
    rows, med = rows[med > 0.0], med[med > 0.0]  # a log needs it above the least intensity
    if len(rows) < 3:
        raise ConfigError(
            f"attenuation 'auto': only {len(rows)} depth row(s) show enough biofilm to fit a "
            "decay (3 needed); give the attenuation in 1/mm",
            where,
        )
    with _no_library_warnings("attenuation 'auto': the fit of the decay", where):
        slope = np.polyfit(depth[rows], np.log(med), 1, w=np.sqrt(counts[rows]))[0]
    return max(0.0, -float(slope))


def _resolution(
    opts: OctOptions, spacing: tuple[float, float, float]
) -> tuple[float, tuple[float, float]]:
    """The resolution (FWHM) in voxels: axial rows, lateral (y, x); 2 voxels when not given."""
    if opts.resolution is None:
        return 2.0, (2.0, 2.0)
    axial, lateral = opts.resolution
    return axial / spacing[0], (lateral / spacing[1], lateral / spacing[2])
