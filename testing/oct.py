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
"""

from __future__ import annotations

from dataclasses import dataclass

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
