"""Synthetic OCT-like volumes with a known biofilm surface, to verify the segmentation of
:mod:`fbia.imaging.oct` (issue 18, part 3).

>>> from fbia.testing.oct import oct_phantom
>>> ph = oct_phantom(shape=(24, 20, 20), seed=0)
>>> ph.volume.shape, ph.volume.dtype.name
((24, 20, 20), 'float32')
>>> round(float(ph.height(*ph.centre)), 4)    # the crest height H [mm]
0.0975

The volume has axes (depth z, y, x); depth index k grows away from the probe, towards the
substratum at the bottom.  Voxel centres lie at depth ``d_k = k dz``, ``y_j = j dy``,
``x_i = i dx`` [mm].  The substratum surface lies at depth ``d_s`` (half-way between two rows,
so that the brightest row starts exactly at it); a voxel's height above it is
``z = d_s - d_k``.  The intensity model, all factors seeded:

* mean level ``L = F + (B - F) c``, with ``c`` the fraction of the voxel's depth extent inside
  the biofilm ``0 < z <= h(x, y)`` (partial volume, so the phantom's surface is sub-voxel),
  ``B`` the biofilm level, ``F`` the fluid level; the row right under ``d_s`` is the bright
  substratum reflection ``R``; deeper rows are a dark shadow ``F / 2``;
* multiplicative speckle ``L * g`` with ``g ~ Gamma(looks, 1/looks)`` (mean 1; ``looks = 1``
  is fully developed speckle, an exponential law);
* Beer–Lambert depth attenuation ``exp(-mu d_k)`` of the whole signal;
* an additive noise floor ``n * e`` with ``e`` standard exponential (not attenuated).

The height field is the smooth dome ``h = H (1 - r^2)^2`` for ``r < 1``, with
``r^2 = ((x - x0) / a)^2 + ((y - y0) / b)^2`` (zero slope at its rim).

That phantom is easy (a flat bright substratum, moderate speckle, no pores).
:func:`realistic_oct_scan` (issue 45) images, in the same frame, what real spectral-domain
scans of biofilms show: fully developed speckle correlated over the resolution cell (dark
voids several voxels wide inside the biofilm), a rough biofilm of several clusters with
closed pores and sub-resolution channels, shadowing under thick clusters, a flow-cell window
reflection, a tilted glass substratum or a membrane one with no reflection line; its
:class:`RealisticScan` holds the truth (height field, substratum plane, pore masks), and
:func:`scan_family` names a set of realistic parameter combinations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..core.errors import ConfigError
from ..core.interface import Interface

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OctPhantom:
    """A synthetic OCT volume and the surface it was made from.

    Attributes
    ----------
    volume
        Intensities, shape (nz, ny, nx), float32, axes (depth, y, x).
    voxel_size
        (dz, dy, dx) [mm].
    substratum_depth
        Depth ``d_s`` of the substratum surface below the first row's centre [mm].
    crest
        Dome height H [mm]; ``centre`` (x0, y0) and ``semi_axes`` (a, b) [mm].
    """

    volume: NDArray[np.float32]
    voxel_size: tuple[float, float, float]
    substratum_depth: float
    crest: float
    centre: tuple[float, float]
    semi_axes: tuple[float, float]

    def height(self, x: FloatArray | float, y: FloatArray | float) -> FloatArray:
        """True height h(x, y) of the biofilm above the substratum [mm] (0 off the dome)."""
        r2 = ((np.asarray(x) - self.centre[0]) / self.semi_axes[0]) ** 2 + (
            (np.asarray(y) - self.centre[1]) / self.semi_axes[1]
        ) ** 2
        return self.crest * np.clip(1.0 - r2, 0.0, None) ** 2

    def surface(self, n: int = 64, min_height: float = 0.0) -> Interface:
        """The true dome as a triangulated height field over its footprint box (2 n^2
        triangles, normals up into the fluid); only triangles with every vertex higher than
        ``min_height`` [mm] are kept."""
        (x0, y0), (a, b) = self.centre, self.semi_axes
        xs, ys = np.linspace(x0 - a, x0 + a, n + 1), np.linspace(y0 - b, y0 + b, n + 1)
        x, y = np.meshgrid(xs, ys, indexing="ij")
        z = self.height(x, y)
        idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
        p, q = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
        r, s = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        tri = np.vstack([np.c_[p, q, r], np.c_[p, r, s]])
        tri = tri[np.all(z.ravel()[tri] > min_height, axis=1)]
        used, cells = np.unique(tri, return_inverse=True)  # only the vertices of kept triangles
        points = np.c_[x.ravel(), y.ravel(), z.ravel()][used]
        return Interface.surface(points, cells.reshape(tri.shape))


def oct_phantom(
    shape: tuple[int, int, int] = (48, 64, 64),
    voxel_size: tuple[float, float, float] = (0.01, 0.02, 0.02),
    crest: float | None = None,
    semi_axes: tuple[float, float] | None = None,
    rows_below: int = 4,
    biofilm: float = 1.0,
    fluid: float = 0.15,
    reflection: float = 4.0,
    looks: float = 2.0,
    attenuation: float = 0.0,
    noise_floor: float = 0.02,
    seed: int = 0,
) -> OctPhantom:
    """A dome-shaped biofilm on a flat substratum, imaged as described in the module docstring.

    Parameters
    ----------
    shape
        (nz, ny, nx) voxels, axes (depth, y, x).
    voxel_size
        (dz, dy, dx) [mm].
    crest
        Dome height H [mm]; default half the height between the top row and the substratum.
    semi_axes
        Footprint semi-axes (a, b) along x and y [mm]; default 0.35 of the lateral extents.
        The dome is centred in the volume.
    rows_below
        Rows under the substratum surface (the first of them is the bright reflection).
    biofilm, fluid, reflection
        Mean levels B, F and R [-].
    looks
        Speckle shape parameter (mean 1, relative standard deviation 1/sqrt(looks)).
    attenuation
        Depth attenuation mu of the intensity [1/mm].
    noise_floor
        Mean of the additive noise floor [-].
    seed
        Seed of the speckle and noise.
    """
    nz, ny, nx = shape
    dz, dy, dx = voxel_size
    d_s = (nz - rows_below - 0.5) * dz
    if crest is None:
        crest = 0.5 * d_s
    if semi_axes is None:
        semi_axes = (0.35 * nx * dx, 0.35 * ny * dy)
    centre = (0.5 * (nx - 1) * dx, 0.5 * (ny - 1) * dy)
    ph = OctPhantom(
        np.empty(0, np.float32), (dz, dy, dx), d_s, crest, centre, (semi_axes[0], semi_axes[1])
    )
    y, x = np.meshgrid(np.arange(ny) * dy, np.arange(nx) * dx, indexing="ij")
    levels = (biofilm, fluid, reflection)
    volume = _image(
        ph.height(x, y), shape, voxel_size, d_s, levels, looks, attenuation, noise_floor, seed
    )
    return OctPhantom(volume, (dz, dy, dx), d_s, crest, centre, (semi_axes[0], semi_axes[1]))


def oct_volume_from_surface(
    surface: Interface,
    shape: tuple[int, int, int],
    voxel_size: tuple[float, float, float],
    rows_below: int = 4,
    biofilm: float = 1.0,
    fluid: float = 0.15,
    reflection: float = 4.0,
    looks: float = 2.0,
    attenuation: float = 0.0,
    noise_floor: float = 0.02,
    seed: int = 0,
) -> tuple[NDArray[np.float32], float]:
    """An OCT-like volume of the biofilm under a triangulated surface, and its ``d_s`` [mm].

    ``surface`` is a height field in the frame of the module docstring: x and y from voxel
    index 0, z the height above the substratum (e.g. a forward model's deformed interface
    with its axes permuted to that frame).  Each voxel column's biofilm height h(x, y) is the
    surface linearly interpolated over its (x, y) projection (Delaunay triangulation of the
    vertices; 0 outside their convex hull, so the surface must not overhang), and the volume
    is imaged with the partial-volume, speckle, attenuation and noise-floor model of
    :func:`oct_phantom` (same parameters).
    """
    from scipy.interpolate import LinearNDInterpolator

    nz, ny, nx = shape
    dz, dy, dx = voxel_size
    v = surface.vertices
    if surface.dim != 3:
        raise ConfigError("needs a 3-D surface", "oct_volume_from_surface")
    d_s = (nz - rows_below - 0.5) * dz
    if v[:, 2].max() >= d_s:
        raise ConfigError(
            f"the surface ({v[:, 2].max():.3g} mm high) does not fit under the first row "
            f"(substratum {d_s:.3g} mm deep)",
            "oct_volume_from_surface",
        )
    y, x = np.meshgrid(np.arange(ny) * dy, np.arange(nx) * dx, indexing="ij")
    h = LinearNDInterpolator(v[:, :2], v[:, 2], fill_value=0.0)(x, y)
    h = np.clip(np.nan_to_num(h), 0.0, None)
    levels = (biofilm, fluid, reflection)
    volume = _image(h, shape, voxel_size, d_s, levels, looks, attenuation, noise_floor, seed)
    return volume, d_s


def _image(
    h: FloatArray,
    shape: tuple[int, int, int],
    voxel_size: tuple[float, float, float],
    d_s: float,
    levels: tuple[float, float, float],
    looks: float,
    attenuation: float,
    noise_floor: float,
    seed: int,
) -> NDArray[np.float32]:
    """The imaging model of the module docstring over the height field ``h`` (ny, nx) [mm]."""
    nz, ny, nx = shape
    dz = voxel_size[0]
    biofilm, fluid, reflection = levels
    rng = np.random.default_rng(seed)
    h32 = np.asarray(h, dtype=np.float32)
    depth = np.arange(nz, dtype=np.float32) * np.float32(dz)
    volume = np.empty(shape, dtype=np.float32)
    for k in range(nz):  # row by row: a 512 x 512 x 256 volume needs no float64 copy
        z = d_s - depth[k]
        if z < -dz:
            level = np.full((ny, nx), 0.5 * fluid, dtype=np.float32)
        elif z < 0.0:
            level = np.full((ny, nx), reflection, dtype=np.float32)
        else:
            # fraction of [z - dz/2, z + dz/2] below h (and above the substratum)
            inside = np.clip((h32 - (z - 0.5 * dz)) / dz, 0.0, 1.0)
            level = (fluid + (biofilm - fluid) * inside).astype(np.float32)
        speckle = rng.standard_gamma(looks, size=(ny, nx), dtype=np.float32) / np.float32(looks)
        floor = rng.standard_exponential(size=(ny, nx), dtype=np.float32)
        volume[k] = level * speckle * np.float32(np.exp(-attenuation * depth[k]))
        volume[k] += np.float32(noise_floor) * floor
    return volume


# -- a realistic scan (issue 45 item 1) --------------------------------------------------------

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))  # a Gaussian's FWHM over its sigma
FLUID = 0.02  # reflectivity of the fluid, pores and channels (biofilm: 1 on average)
WINDOW = 20.0  # peak intensity of the window reflection over the biofilm's level
GLASS = 8.0  # peak intensity of the glass substratum's reflection over the biofilm's level
MEMBRANE = 0.6  # reflectivity of a membrane substratum
MEMBRANE_EXTINCTION = 20.0  # 1/mm, round trip: the membrane's signal fades over ~50 um
ROUGHNESS = 0.25  # relative amplitude of the outer boundary's roughness
WINDOW_SHARE = 0.08  # the window's depth as a share of the volume's depth
SUBSTRATUM_SHARE = 0.82  # the substratum's depth at the field's centre, share of the depth


@dataclass(frozen=True)
class RealisticScan:
    """A realistic synthetic OCT scan of a biofilm and its truth (:func:`realistic_oct_scan`).

    Attributes
    ----------
    volume
        Intensities (nz, ny, nx), axes (depth, y, x), linear (not log), >= 0; float32, or
        uint8 as a scanner's 8-bit export.
    voxel_size
        (dz, dy, dx) [mm].
    resolution
        (axial, lateral) resolution: FWHM of the (amplitude) point-spread function [mm].
    height
        (ny, nx) true height of the biofilm's outer boundary above the substratum at every
        A-scan (voxel column centre ``x_i = i dx``, ``y_j = j dy``), measured along depth [mm];
        0 where the substratum is bare.  Pores and channels do not change it.
    substratum_row
        (ny, nx) depth of the substratum surface in rows (row k's centre is at depth k dz) at
        every A-scan: a tilted plane.
    substratum_depth
        Depth of the substratum surface at the field's centre below the first row's centre [mm].
    tilt
        The plane's slopes d(depth)/dy and d(depth)/dx [-].
    window_row
        Row of the flow-cell window's reflection, or None without a window.
    substratum
        ``"glass"`` (a bright reflection line, dark glass under it) or ``"membrane"`` (a
        scattering medium under the plane, no line).
    pores
        Share of the biofilm's volume under the outer boundary that is fluid: pores and
        channels (voxel count over the biofilm's volume in voxels).
    pore_mask
        (nz, ny, nx) voxels whose centre lies in a closed pore (an ellipsoid of fluid).
    channel_mask
        (nz, ny, nx) voxels of the channels: one-voxel-wide columns from a pore up through
        the outer boundary.
    """

    volume: NDArray[np.float32] | NDArray[np.uint8]
    voxel_size: tuple[float, float, float]
    resolution: tuple[float, float]
    height: FloatArray
    substratum_row: FloatArray
    substratum_depth: float
    tilt: tuple[float, float]
    window_row: float | None
    substratum: Literal["glass", "membrane"]
    pores: float
    pore_mask: NDArray[np.bool_] = field(repr=False)
    channel_mask: NDArray[np.bool_] = field(repr=False)

    def surface(self, n: int | None = None) -> Interface:
        """The true outer boundary as a triangulated height field (normals up, +z, into the
        fluid): x = i dx, y = j dy, z = the height above the substratum measured along depth
        (the untilted frame).  ``n`` None: every A-scan is a vertex (z = ``height``); else an
        (n + 1) x (n + 1) grid over the same field, heights interpolated linearly between the
        A-scans.  Only the triangles with at least one vertex above 0 are kept."""
        from scipy.interpolate import RegularGridInterpolator

        ny, nx = self.height.shape
        _, dy, dx = self.voxel_size
        xa, ya = np.arange(nx) * dx, np.arange(ny) * dy
        if n is None:
            xs, ys = xa, ya
            z = self.height.T  # indexed (x, y)
        else:
            if n < 1:
                raise ConfigError(f"n must be at least 1, got {n}", "RealisticScan.surface")
            xs, ys = np.linspace(0.0, xa[-1], n + 1), np.linspace(0.0, ya[-1], n + 1)
            x, y = np.meshgrid(xs, ys, indexing="ij")
            interp = RegularGridInterpolator((ya, xa), self.height)
            z = interp(np.c_[y.ravel(), x.ravel()]).reshape(x.shape)
        x, y = np.meshgrid(xs, ys, indexing="ij")
        mx, my = x.shape
        idx = np.arange(mx * my).reshape(mx, my)
        p, q = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
        r, s = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        tri = np.vstack([np.c_[p, q, r], np.c_[p, r, s]])
        tri = tri[np.any(z.ravel()[tri] > 0.0, axis=1)]
        used, cells = np.unique(tri, return_inverse=True)
        points = np.c_[x.ravel(), y.ravel(), z.ravel()][used]
        return Interface.surface(points, cells.reshape(tri.shape))

    def top_depth_rows(self) -> FloatArray:
        """(ny, nx) row (fractional) of the outer boundary's top in every A-scan, in the scan's
        own (tilted) frame: ``substratum_row - height / dz``; NaN where the substratum is bare."""
        top = self.substratum_row - self.height / self.voxel_size[0]
        return np.where(self.height > 0.0, top, np.nan)

    def height_errors(self, surface: Interface) -> FloatArray:
        """Height of every vertex of a segmented ``surface`` (x, y, z = height above the
        substratum) minus the true height at its A-scan (the nearest voxel column) [mm]:
        below -0.02, a vertex lies more than 20 um under the true top of its A-scan."""
        _, dy, dx = self.voxel_size
        v = surface.vertices
        ny, nx = self.height.shape
        j = np.clip(np.rint(v[:, 1] / dy).astype(int), 0, ny - 1)
        i = np.clip(np.rint(v[:, 0] / dx).astype(int), 0, nx - 1)
        return np.asarray(v[:, 2] - self.height[j, i])


def realistic_oct_scan(
    shape: tuple[int, int, int] = (160, 48, 96),
    voxel_size: tuple[float, float, float] = (0.0025, 0.01, 0.01),
    resolution: tuple[float, float] = (0.005, 0.015),
    looks: float = 1.0,
    snr_db: float = 25.0,
    attenuation: float = 8.0,
    pore_radius: float = 0.012,
    porosity: float = 0.1,
    channels: int = 3,
    substratum: Literal["glass", "membrane"] = "glass",
    tilt: tuple[float, float] = (0.0, 0.02),
    window: bool = True,
    dtype: str = "float32",
    heterogeneity: float = 0.3,
    seed: int = 0,
    height: FloatArray | None = None,
) -> RealisticScan:
    """A realistic spectral-domain OCT scan of a rough, porous biofilm in a flow cell.

    Axes (depth, y, x), depth index k growing away from the probe; voxel centres at depth
    ``d_k = k dz``, ``y_j = j dy``, ``x_i = i dx`` [mm].  The model, every random draw seeded
    (separate streams for the geometry, the pores, the heterogeneity, the speckle and the
    noise, so that e.g. ``looks`` or ``snr_db`` change nothing of the geometry):

    Geometry
        The flow-cell window's lower surface at depth ``d_w`` (row ``round(0.08 (nz - 1))``;
        the same depth is the geometry's reference without a window); the substratum is the
        plane ``d_s(x, y) = d_s0 + t_y (y - y_c) + t_x (x - x_c)`` through the field's centre
        ``(x_c, y_c)``, ``d_s0 = 0.82 (nz - 1) dz``.  The biofilm fills ``d_s - h <= d <= d_s``
        of each A-scan, ``h(x, y) = max_c H_c (1 - r_c^2)^2 (1 + 0.25 q(x, y))``: 3-8
        clusters (smooth mounds, zero slope at their rims) of random elliptic footprints
        (semi-axes 0.15-0.3 of the geometric mean of the field's extents), centres anywhere
        in the field, the tallest ``H_top = 0.5 (min d_s - d_w) / 1.25``, the others 0.35-1
        of it, drawn again (at most 50 times) until they cover 25-80 % of the field (the
        rest is bare); ``q`` is a smooth random roughness in [-1, 1] (12 random plane waves
        of wavelength 0.05-0.15 mm).  No overhangs: ``h`` at the A-scans is the truth
        (``height``), partial volumes along depth.
    Pores
        Axis-aligned ellipsoids of fluid, semi-axes ``pore_radius`` times 0.7-1.3 each,
        in the (height above the substratum, y, x) frame, centres drawn uniformly in the
        biofilm's volume and kept only when the whole ellipsoid lies at least one lateral
        resolution under ``h`` (over its footprint's bounding box) and one axial resolution
        above the substratum (closed pores), until they make ``porosity`` of the biofilm's
        volume (voxel centres inside; as near as fits in a thin film).  ``channels`` of them
        (at random) get a channel: a column one voxel wide (narrower than the lateral
        resolution) from the pore's topmost voxel up through the outer boundary.  Both are
        fluid; ``height`` ignores them.
    Reflectivity rho
        Fluid 0.02; biofilm ``1 + heterogeneity clip(t / 2, -1, 1)`` with ``t`` a smooth
        random field of unit variance (12 random plane waves in 3-D, wavelength 0.04-0.1
        mm): +-30 % by default; the window glass above ``d_w`` and the glass substratum
        under ``d_s`` 0 (only noise); a membrane substratum 0.6 under ``d_s``, with its own
        extinction 20/mm, so its signal fades into depth and nothing marks where it starts.
        Specular reflections, not speckled (a smooth surface reflects coherently): the
        window (peak 20) and the glass substratum (peak 8, under the film's extinction),
        each a field ``sqrt(R) g(d - d_0)`` with ``g`` the axial amplitude PSF (one
        resolution cell thick).
    Imaging
        Extinction ``A = exp(-tau)``, ``tau`` the integral above the voxel (its centre) of
        ``attenuation`` inside the biofilm (pores and channels excluded) and 20/mm inside a
        membrane (both round trip).  Each look's complex field is the white circular Gaussian
        field ``sqrt(rho A) w`` (E|w|^2 = 1) filtered by the Gaussian PSF whose amplitude
        FWHM is ``resolution`` in each axis, plus the specular fields; the filter is applied
        in Fourier space on the volume's periodic grid, with the exact sampled covariance of
        the continuous field (right even for a PSF under two voxels wide), so a uniform
        region's mean intensity is ``rho A``.  The intensity is ``|.|^2``, averaged over
        ``looks`` independent fields (a whole number; 1: fully developed speckle, exponential
        intensity, std/mean 1, a share ``1 - exp(-0.1)`` under a tenth of the mean; ``looks``
        L: a Gamma(L) law, std/mean ``L^-1/2``).  Speckle grains span the resolution cell:
        the intensity's autocorrelation coefficient at a lag ``s`` along an axis is
        ``2^(-4 (s / FWHM)^2)`` (1/16 at one FWHM), so the voxels under a fifth of the mean
        clump into dark voids of ~10 voxels inside the biofilm (~4 for uncorrelated speckle,
        default sampling).  A uniform region's intensity is thus ``rho A S``, ``S`` that
        speckle of mean 1; interfaces are blurred by the PSF, and a channel one voxel wide
        keeps about a quarter of the biofilm's mean level at the default sampling, which
        speckle makes hard to tell from a dark grain.  Plus an additive, uncorrelated noise
        floor, exponential of mean ``10^(-snr_db / 10)`` (the biofilm's mean level at its
        top is 1).
    Export
        ``dtype="uint8"``: ``round(255 I / I_999)`` clipped to 0-255, ``I_999`` the 99.9th
        percentile (linear, no log; the brightest 0.1 % saturate).

    Parameters
    ----------
    shape
        (nz, ny, nx) voxels, axes (depth, y, x); nz at least 40.
    voxel_size
        (dz, dy, dx) [mm].
    resolution
        (axial, lateral) FWHM of the amplitude PSF [mm].
    looks
        Independent speckle fields averaged (a whole number, at least 1).
    snr_db
        Mean biofilm intensity at its top over the noise floor's mean [dB].
    attenuation
        Extinction inside the biofilm, round trip [1/mm]; shadows under thick clusters.
    pore_radius
        Mean semi-axis of the closed pores [mm].
    porosity
        Target share of the biofilm's volume that is pore, in [0, 0.5) (0: none).
    channels
        Number of pores given a channel to the top surface.
    substratum
        ``"glass"`` or ``"membrane"``.
    tilt
        Slopes (d(depth)/dy, d(depth)/dx) of the substratum plane [-].
    window
        Whether the flow-cell window's reflection is in the scan.
    dtype
        ``"float32"`` or ``"uint8"``.
    heterogeneity
        Relative amplitude of the biofilm's smooth reflectivity heterogeneity [-].
    seed
        Seed (a non-negative integer) of every random draw.
    height
        The biofilm's outer boundary as a height map (ny, nx) above the substratum [mm]
        instead of the random clusters (:func:`realistic_volume_from_surface`: a forward
        model's interface); it must fit between the substratum and the window's depth.

    >>> scan = realistic_oct_scan(shape=(64, 16, 32), seed=0)
    >>> scan.volume.shape, scan.volume.dtype.name, scan.window_row
    ((64, 16, 32), 'float32', 5.0)
    """
    from scipy import fft as sfft

    where = "realistic_oct_scan"
    nz, ny, nx = (int(s) for s in shape)
    dz, dy, dx = (float(v) for v in voxel_size)
    res_a, res_l = (float(r) for r in resolution)
    if nz < 40 or ny < 4 or nx < 4:
        raise ConfigError(f"shape must be at least (40, 4, 4), got {tuple(shape)}", where)
    if min(dz, dy, dx, res_a, res_l) <= 0.0:
        raise ConfigError("voxel sizes and resolutions must be positive", where)
    if looks < 1 or looks != int(looks):
        raise ConfigError(f"looks must be a whole number of at least 1, got {looks}", where)
    if not 0.0 <= porosity < 0.5:
        raise ConfigError(f"porosity must lie in [0, 0.5), got {porosity}", where)
    if pore_radius <= 0.0 or channels < 0 or heterogeneity < 0.0 or attenuation < 0.0:
        raise ConfigError(
            "pore_radius must be positive; channels, heterogeneity and attenuation not negative",
            where,
        )
    if substratum not in ("glass", "membrane"):
        raise ConfigError(f"substratum must be 'glass' or 'membrane', got {substratum!r}", where)
    if dtype not in ("float32", "uint8"):
        raise ConfigError(f"dtype must be 'float32' or 'uint8', got {dtype!r}", where)
    if seed < 0:
        raise ConfigError(f"seed must not be negative, got {seed}", where)

    def rng(stream: int) -> np.random.Generator:
        return np.random.default_rng([seed, stream])

    # -- geometry: window, substratum plane, clusters -----------------------------------------
    xs, ys = np.arange(nx, dtype=np.float64) * dx, np.arange(ny, dtype=np.float64) * dy
    xc, yc = 0.5 * xs[-1], 0.5 * ys[-1]
    w_row = float(round(WINDOW_SHARE * (nz - 1)))
    d_w = w_row * dz
    d_s0 = SUBSTRATUM_SHARE * (nz - 1) * dz
    ty, tx = float(tilt[0]), float(tilt[1])
    d_s = d_s0 + ty * (ys[:, None] - yc) + tx * (xs[None, :] - xc)  # (ny, nx)
    if d_s.min() - d_w < 0.5 * (d_s0 - d_w) or d_s.max() > (nz - 4) * dz:
        raise ConfigError(
            f"the substratum plane (tilt {tilt}) leaves the volume: its depth spans "
            f"{d_s.min():.3g}-{d_s.max():.3g} mm, the window is at {d_w:.3g} mm and the "
            f"last row at {(nz - 1) * dz:.3g} mm",
            where,
        )
    if height is None:
        h = _clusters(xs, ys, 0.5 * (d_s.min() - d_w) / (1.0 + ROUGHNESS), rng(0))
    else:
        h = np.clip(np.asarray(height, dtype=np.float64), 0.0, None)
        if h.shape != (ny, nx) or not np.all(np.isfinite(h)):
            raise ConfigError(f"height must be a finite ({ny}, {nx}) map [mm]", where)
        if h.max() >= d_s.min() - d_w - 2.0 * res_a:
            raise ConfigError(
                f"the biofilm ({h.max():.3g} mm high) does not fit under the window "
                f"({d_s.min() - d_w:.3g} mm above the substratum's highest point): more rows",
                where,
            )
    depth = (np.arange(nz) * dz)[:, None, None]
    top = d_s - h
    occ_b = np.clip(
        (np.minimum(depth + 0.5 * dz, d_s) - np.maximum(depth - 0.5 * dz, top)) / dz, 0.0, 1.0
    ).astype(np.float32)  # biofilm share of each voxel's depth extent
    occ_s = np.clip((depth + 0.5 * dz - d_s) / dz, 0.0, 1.0).astype(np.float32)  # substratum
    occ_w = np.clip((d_w - (depth - 0.5 * dz)) / dz, 0.0, 1.0) if window else np.zeros(1)
    occ_w = np.broadcast_to(occ_w, (nz, 1, 1)).astype(np.float32)  # window glass

    # -- pores and channels -----------------------------------------------------------------
    pore_mask, channel_mask = _pores(
        h,
        d_s / dz,
        (dz, dy, dx),
        (res_a, res_l),
        pore_radius,
        porosity,
        channels,
        nz,
        rng(1),
    )
    fluid_in = pore_mask | channel_mask
    biofilm_volume = float(occ_b.sum(dtype=np.float64))
    share = float(occ_b[fluid_in].sum(dtype=np.float64)) / biofilm_volume if biofilm_volume else 0.0
    occ_b[fluid_in] = 0.0

    # -- reflectivity and extinction ------------------------------------------------------------
    rho_b = 1.0 + heterogeneity * np.clip(0.5 * _waves3(nz, ys, xs, dz, rng(2)), -1.0, 1.0)
    occ_f = np.clip(1.0 - occ_b - occ_s - occ_w, 0.0, 1.0)
    occ_f[fluid_in] = 1.0
    rho = np.float32(FLUID) * occ_f + rho_b * occ_b
    ext = np.float32(attenuation) * occ_b
    if substratum == "membrane":
        rho += np.float32(MEMBRANE) * occ_s
        ext += np.float32(MEMBRANE_EXTINCTION) * occ_s
    tau = (np.cumsum(ext, axis=0, dtype=np.float32) - 0.5 * ext) * np.float32(dz)
    amplitude = np.sqrt(rho * np.exp(-tau)).astype(np.float32)
    del rho, ext, tau, occ_f, rho_b, occ_s, occ_w

    # -- specular reflections (not speckled) ----------------------------------------------------
    sig_z = res_a / FWHM_PER_SIGMA
    specular = np.zeros((nz, ny, nx), dtype=np.float32)
    if window:
        specular += np.float32(np.sqrt(WINDOW)) * np.exp(-0.5 * ((depth - d_w) / sig_z) ** 2)
    if substratum == "glass":
        shade = np.exp(-attenuation * dz * occ_b.sum(axis=0, dtype=np.float64))
        specular += np.sqrt(GLASS * shade) * np.exp(-0.5 * ((depth - d_s) / sig_z) ** 2)

    # -- speckle: PSF-filtered circular Gaussian fields -------------------------------------------
    sigmas = (sig_z, res_l / FWHM_PER_SIGMA, res_l / FWHM_PER_SIGMA)
    gain = _psf_gain((nz, ny, nx), (dz, dy, dx), sigmas)
    speckle_rng = rng(3)
    intensity = np.zeros((nz, ny, nx), dtype=np.float32)
    for _ in range(int(looks)):
        w = np.empty((nz, ny, nx), dtype=np.complex64)
        w.real = speckle_rng.standard_normal((nz, ny, nx), dtype=np.float32)
        w.imag = speckle_rng.standard_normal((nz, ny, nx), dtype=np.float32)
        w *= amplitude * np.float32(np.sqrt(0.5))
        f = sfft.ifftn(sfft.fftn(w, workers=1) * gain, workers=1)
        f.real += specular
        intensity += f.real**2 + f.imag**2
    intensity /= np.float32(looks)
    noise = rng(4).standard_exponential((nz, ny, nx), dtype=np.float32)
    intensity += np.float32(10.0 ** (-snr_db / 10.0)) * noise

    volume: NDArray[np.float32] | NDArray[np.uint8] = intensity
    if dtype == "uint8":
        q = float(np.percentile(intensity, 99.9))
        volume = np.clip(np.rint(intensity * np.float32(255.0 / q)), 0, 255).astype(np.uint8)
    return RealisticScan(
        volume=volume,
        voxel_size=(dz, dy, dx),
        resolution=(res_a, res_l),
        height=h,
        substratum_row=d_s / dz,
        substratum_depth=float(d_s0),
        tilt=(ty, tx),
        window_row=w_row if window else None,
        substratum=substratum,
        pores=share,
        pore_mask=pore_mask,
        channel_mask=channel_mask,
    )


def realistic_volume_from_surface(
    surface: Interface,
    shape: tuple[int, int, int],
    voxel_size: tuple[float, float, float],
    **options: Any,
) -> RealisticScan:
    """A realistic scan (:func:`realistic_oct_scan`, ``options`` its keywords) of the biofilm
    under a triangulated surface in the frame of the module docstring (x and y from voxel
    index 0, z the height above the substratum, no overhangs; e.g. a forward model's
    deformed interface with its axes permuted to that frame, as for
    :func:`oct_volume_from_surface`): each A-scan's height is the surface linearly
    interpolated over its (x, y) projection, 0 outside the convex hull of its vertices."""
    from scipy.interpolate import LinearNDInterpolator

    if surface.dim != 3:
        raise ConfigError("needs a 3-D surface", "realistic_volume_from_surface")
    _, ny, nx = shape
    _, dy, dx = voxel_size
    v = surface.vertices
    y, x = np.meshgrid(np.arange(ny) * dy, np.arange(nx) * dx, indexing="ij")
    h = LinearNDInterpolator(v[:, :2], v[:, 2], fill_value=0.0)(x, y)
    h = np.clip(np.nan_to_num(h), 0.0, None)
    return realistic_oct_scan(shape=shape, voxel_size=voxel_size, height=h, **options)


def scan_family() -> dict[str, dict[str, Any]]:
    """Named keyword sets of :func:`realistic_oct_scan` (seed not included), each a realistic
    combination, together spanning the speckle contrast (looks 1 and 3), the SNR (15, 25 and
    35 dB), the pores (none; small: radius 12 um, 10 %; large: 20 um, 15 %), glass and
    membrane substrata, the tilt (0 and 0.03) and the window (on, off).  Every volume has the
    default 160 x 48 x 96 voxels (0.74 M) of 2.5 x 10 x 10 um."""
    small = {"pore_radius": 0.012, "porosity": 0.1, "channels": 3}
    large = {"pore_radius": 0.02, "porosity": 0.15, "channels": 4}
    none = {"porosity": 0.0, "channels": 0}
    flat, tilted = (0.0, 0.0), (0.0, 0.03)
    return {
        "glass_typical": dict(
            looks=1, snr_db=25.0, **small, substratum="glass", tilt=tilted, window=True
        ),
        "glass_clean_compounded": dict(
            looks=3, snr_db=35.0, **small, substratum="glass", tilt=flat, window=True
        ),
        "glass_noisy": dict(
            looks=1, snr_db=15.0, **small, substratum="glass", tilt=tilted, window=True
        ),
        "glass_large_pores": dict(
            looks=1, snr_db=25.0, **large, substratum="glass", tilt=flat, window=False
        ),
        "glass_dense_solid": dict(
            looks=1,
            snr_db=25.0,
            attenuation=12.0,
            **none,
            substratum="glass",
            tilt=(0.03, 0.0),
            window=True,
        ),
        "glass_uint8_export": dict(
            looks=1,
            snr_db=25.0,
            **small,
            substratum="glass",
            tilt=tilted,
            window=True,
            dtype="uint8",
        ),
        "membrane_typical": dict(
            looks=1, snr_db=25.0, **small, substratum="membrane", tilt=flat, window=True
        ),
        "membrane_noisy_tilted": dict(
            looks=1, snr_db=15.0, **small, substratum="membrane", tilt=tilted, window=True
        ),
        "membrane_compounded_large_pores": dict(
            looks=3, snr_db=35.0, **large, substratum="membrane", tilt=flat, window=False
        ),
        "membrane_solid_no_window": dict(
            looks=3, snr_db=25.0, **none, substratum="membrane", tilt=tilted, window=False
        ),
    }


def _waves(
    coords: tuple[NDArray[np.float64], ...],
    wavelengths: tuple[float, float],
    rng: np.random.Generator,
    m: int = 12,
) -> NDArray[np.float32]:
    """``sqrt(2 / m) sum cos(k . r + phi)`` over ``m`` plane waves of random directions,
    wavelengths and phases: a smooth random field of unit variance over the broadcast
    ``coords``."""
    dim = len(coords)
    direction = rng.standard_normal((m, dim))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    k = direction * (2.0 * np.pi / rng.uniform(*wavelengths, size=m))[:, None]
    phase = rng.uniform(0.0, 2.0 * np.pi, size=m)
    shape = np.broadcast_shapes(*(c.shape for c in coords))
    out = np.zeros(shape, dtype=np.float32)
    for km, pm in zip(k, phase, strict=True):
        arg = sum(
            (np.float32(kc) * c.astype(np.float32) for kc, c in zip(km, coords, strict=True)),
            start=np.float32(pm),
        )
        out += np.cos(arg)
    return out * np.float32(np.sqrt(2.0 / m))


def _waves3(
    nz: int, ys: FloatArray, xs: FloatArray, dz: float, rng: np.random.Generator
) -> NDArray[np.float32]:
    """The 3-D heterogeneity field t of :func:`realistic_oct_scan` on the voxel grid."""
    coords = (
        (np.arange(nz, dtype=np.float64) * dz)[:, None, None],
        ys[None, :, None],
        xs[None, None, :],
    )
    return _waves(coords, (0.04, 0.1), rng)


def _clusters(xs: FloatArray, ys: FloatArray, h_top: float, rng: np.random.Generator) -> FloatArray:
    """The rough height field h (ny, nx) [mm] of :func:`realistic_oct_scan`: 3-8 mounds,
    drawn until they cover 25-80 % of the field, times ``1 + 0.25 q`` (roughness)."""
    x, y = xs[None, :], ys[:, None]
    size = np.sqrt(xs[-1] * ys[-1])
    q = np.clip(0.5 * _waves((y, x), (0.05, 0.15), rng).astype(np.float64), -1.0, 1.0)
    for _ in range(50):
        n = int(rng.integers(3, 9))
        centres = rng.uniform((0.0, 0.0), (xs[-1], ys[-1]), size=(n, 2))
        semi = size * rng.uniform(0.15, 0.3, size=(n, 2))
        u = rng.uniform(0.35, 1.0, size=n)
        heights = h_top * u / u.max()
        h = np.zeros((len(ys), len(xs)))
        for (cx, cy), (a, b), hc in zip(centres, semi, heights, strict=True):
            r2 = ((x - cx) / a) ** 2 + ((y - cy) / b) ** 2
            h = np.maximum(h, hc * np.clip(1.0 - r2, 0.0, None) ** 2)
        if 0.25 <= np.mean(h > 0.0) <= 0.8:
            break
    return h * (1.0 + ROUGHNESS * q)


def _pores(
    h: FloatArray,
    s_row: FloatArray,
    voxel_size: tuple[float, float, float],
    resolution: tuple[float, float],
    radius: float,
    porosity: float,
    channels: int,
    nz: int,
    rng: np.random.Generator,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The closed pores' and the channels' voxel masks of :func:`realistic_oct_scan`."""
    ny, nx = h.shape
    dz, dy, dx = voxel_size
    res_a, res_l = resolution
    pore = np.zeros((nz, ny, nx), dtype=bool)
    channel = np.zeros((nz, ny, nx), dtype=bool)
    volume = float(h.sum()) / dz  # the biofilm's volume in voxels
    target = porosity * volume
    if target <= 0.0:
        return pore, channel
    per_pore = 4.0 / 3.0 * np.pi * radius**3 / (dz * dy * dx)
    budget = int(1000 + 1000 * target / per_pore)  # candidate centres at most
    weights = (h / h.sum()).ravel()
    tops: list[tuple[int, int, int]] = []  # each pore's topmost voxel (k, j, i)
    filled = 0
    ks = np.arange(nz)
    batch = 4096
    for _ in range(0, budget, batch):
        # a batch of candidates, uniform in the biofilm's volume; the cheap tests vectorised
        col = rng.choice(h.size, size=batch, p=weights)
        jc, ic = np.divmod(col, nx)
        zc = rng.uniform(0.0, 1.0, size=batch) * h[jc, ic]
        yc = (jc + rng.uniform(-0.5, 0.5, size=batch)) * dy
        xc = (ic + rng.uniform(-0.5, 0.5, size=batch)) * dx
        semi = radius * rng.uniform(0.7, 1.3, size=(batch, 3))
        ok = (zc - semi[:, 0] >= res_a) & (h[jc, ic] >= zc + semi[:, 0] + res_l)
        for n in np.flatnonzero(ok):
            if filled >= target:
                break
            rz, ry, rx = semi[n]
            j0, j1 = int(np.ceil((yc[n] - ry) / dy)), int(np.floor((yc[n] + ry) / dy))
            i0, i1 = int(np.ceil((xc[n] - rx) / dx)), int(np.floor((xc[n] + rx) / dx))
            if j0 < 0 or i0 < 0 or j1 >= ny or i1 >= nx or j1 < j0 or i1 < i0:
                continue  # the footprint leaves the field or holds no A-scan
            if h[j0 : j1 + 1, i0 : i1 + 1].min() < zc[n] + rz + res_l:
                continue  # not closed: too near the outer boundary somewhere
            sr = s_row[j0 : j1 + 1, i0 : i1 + 1]
            k0 = max(int(np.floor(sr.min() - (zc[n] + rz) / dz)), 0)
            k1 = min(int(np.ceil(sr.max() - (zc[n] - rz) / dz)), nz - 1)
            z = (sr[None] - ks[k0 : k1 + 1, None, None]) * dz  # height of each voxel centre
            yy = (np.arange(j0, j1 + 1) * dy - yc[n])[None, :, None]
            xx = (np.arange(i0, i1 + 1) * dx - xc[n])[None, None, :]
            inside = ((z - zc[n]) / rz) ** 2 + (yy / ry) ** 2 + (xx / rx) ** 2 <= 1.0
            if not inside.any():
                continue
            box = pore[k0 : k1 + 1, j0 : j1 + 1, i0 : i1 + 1]
            filled += int(np.count_nonzero(inside & ~box))
            box |= inside
            kk, jj, ii = np.nonzero(inside)
            first = int(np.argmin(kk))
            tops.append((k0 + int(kk[first]), j0 + int(jj[first]), i0 + int(ii[first])))
        if filled >= target:
            break
    for n in rng.permutation(len(tops))[: min(channels, len(tops))]:
        k, j, i = tops[n]
        top_row = s_row[j, i] - h[j, i] / dz  # the outer boundary's depth in rows
        k_top = max(int(np.floor(top_row + 0.5)), 0)  # the voxel holding the boundary
        column = channel[k_top:k, j, i]
        column |= ~pore[k_top:k, j, i]
    return pore, channel


def _psf_gain(
    shape: tuple[int, int, int],
    voxel_size: tuple[float, float, float],
    sigmas: tuple[float, float, float],
) -> NDArray[np.float32]:
    """The Fourier filter (on the volume's periodic grid) that turns white noise of unit
    variance into a field whose covariance is the sampled Gaussian ``exp(-s^2 / (4 sigma^2))``
    along each axis: the continuous field of a Gaussian PSF ``exp(-s^2 / (2 sigma^2))``,
    sampled exactly (unit variance; intensity correlation ``exp(-s^2 / (2 sigma^2))``)."""
    gain = np.ones(1, dtype=np.float64)
    for axis, (n, step, sigma) in enumerate(zip(shape, voxel_size, sigmas, strict=True)):
        lag = np.minimum(np.arange(n), n - np.arange(n)) * step  # periodic distance
        power = np.clip(np.fft.fft(np.exp(-(lag**2) / (4.0 * sigma**2))).real, 0.0, None)
        shape1 = [1, 1, 1]
        shape1[axis] = n
        gain = gain * np.sqrt(power).reshape(shape1)
    return gain.astype(np.float32)
