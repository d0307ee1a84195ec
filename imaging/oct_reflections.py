"""Flat reflections across an OCT scan: the flow cell's window and the substratum (issue 45).

A spectral-domain OCT scan of a biofilm in a flow cell shows up to two kinds of flat, thin,
bright lines across its A-scans: the flow cell's *window* near the top (its glass surfaces,
with the fluid under them) and the *substratum* under the biofilm (a glass slide's surface;
a membrane shows none: its signal fades into it).  Neither is parallel to the rows in
general: the sample is rarely mounted square to the beam.  :func:`find_reflections` finds
them as planes and :func:`classify` tells them apart; :mod:`fbia.imaging.oct` removes the
window and untilts the scan so that the substratum lies along a row.

Finding (:func:`find_reflections`):

1. every A-scan's *line score*: the log intensity, smoothed across the A-scans to average
   the speckle, minus the larger of the mean log intensities of the ``width`` rows above
   and under it beyond ``gap`` rows (the line's own spread): a thin line brighter than
   both sides scores high, the edge of a thick bright layer (the biofilm's top) does not;
2. in every A-scan, its local maxima scoring above ``log(MIN_LINE_CONTRAST)`` are candidates
   (at most :data:`CANDIDATES_PER_ASCAN`, the strongest);
3. planes through the candidates by RANSAC (scikit-image's :func:`~skimage.measure.ransac`,
   Fischler & Bolles 1981; the plane row = a + b j + c i, j and i the A-scan indices), each
   kept when its inliers lie in at least :data:`MIN_SUPPORT` of the A-scans and its slope
   is at most :data:`MAX_SLOPE` in mm per mm; its inliers go and the next plane is sought.

Telling them apart (:func:`classify`): the biofilm lies between the window and the
substratum.  Of the scan's bright voxels (above Otsu's threshold of the smoothed scan, the
lines' rows left out), a window has most *under* it and the substratum most *above* it.  The
substratum is the highest plane with most of the bright voxels above it that lies under
every window (a glass slide's lower surface, deeper, is not taken); the window is the lowest
plane with most of them under it that lies above the substratum.  A membrane scan has no
substratum plane: :func:`place_floor` then refuses and asks for ``substratum_depth``.

Using them (:func:`place_floor`, step 1 of :func:`fbia.imaging.oct.segment_oct`): the rows
down to the window's line and its spread take the median intensity of the fluid under it;
every A-scan is shifted along depth so that the substratum's plane lies along one row
(linear interpolation); the substratum's surface is the upper half-maximum edge of its line
in the median depth profile (a sharp reflection's surface; half the line's spread above its
centre for one blurred by the axial resolution), and the rows the line still brightens above
it (as far above its peak as it brightens the substratum's rows below it, and one row where
the scan was untilted: interpolation spreads a thin line over two rows) take the intensities
of the row above them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..core.errors import ConfigError

__all__ = [
    "CANDIDATES_PER_ASCAN",
    "Floor",
    "MAX_SLOPE",
    "MIN_LINE_CONTRAST",
    "MIN_SUPPORT",
    "Reflection",
    "classify",
    "find_reflections",
    "place_floor",
]

FloatArray = NDArray[np.float64]

#: the least ratio of a line's intensity to both of its sides' (geometric means) for it to be
#: a candidate in an A-scan
MIN_LINE_CONTRAST = 3.0
#: the strongest candidates kept per A-scan
CANDIDATES_PER_ASCAN = 3
#: the least share of the A-scans a plane must run through
MIN_SUPPORT = 0.3
#: the steepest plane taken for a reflection [mm depth per mm across]: a tilt of 17 degrees
MAX_SLOPE = 0.3
#: planes sought at most
MAX_PLANES = 4
#: A-scans a plane is sought on at most (every s-th along y and x beyond)
MAX_ASCANS = 128 * 128


@dataclass(frozen=True)
class Reflection:
    """A flat reflection across the scan: the plane row(j, i) = ``row`` + ``slope[0]`` (j -
    jc) + ``slope[1]`` (i - ic), rows and A-scan indices of the volume it was found in, (jc,
    ic) the centre of its lateral grid.

    Attributes
    ----------
    row
        Depth row at the field's centre (fractional).
    slope
        Rows per A-scan along y and along x.
    support
        Share of the A-scans with a candidate on the plane.
    contrast
        Median line contrast of those candidates (intensity over its sides', a ratio).
    bright_above
        Share of the scan's bright voxels above the plane (:func:`classify`).
    kind
        "window", "substratum" or "other".
    """

    row: float
    slope: tuple[float, float]
    support: float
    contrast: float
    bright_above: float = math.nan
    kind: Literal["window", "substratum", "other"] = "other"

    def rows(self, shape: tuple[int, int]) -> FloatArray:
        """The plane's row at every A-scan of a (ny, nx) grid."""
        ny, nx = shape
        j = np.arange(ny, dtype=np.float64)[:, None] - 0.5 * (ny - 1)
        i = np.arange(nx, dtype=np.float64)[None, :] - 0.5 * (nx - 1)
        return self.row + self.slope[0] * j + self.slope[1] * i

    def describe(self) -> str:
        """``row 25.0 (window; 97 % of the bright voxels under it)``."""
        tilt = "" if max(map(abs, self.slope)) < 1e-3 else ", tilted"
        where = (
            ""
            if math.isnan(self.bright_above)
            else f"; {100 * (1 - self.bright_above):.0f} % of the bright voxels under it"
        )
        return f"row {self.row:.1f} ({self.kind}{tilt}{where})"


class _Plane:
    """scikit-image's RANSAC model: row = a + b j + c i through (j, i, row) points."""

    def __init__(self, coef: FloatArray | None = None) -> None:
        self.coef = coef

    def __bool__(self) -> bool:
        return self.coef is not None

    @classmethod
    def from_estimate(cls, data: FloatArray) -> _Plane:
        a = np.c_[np.ones(len(data)), data[:, 0], data[:, 1]]
        coef, _, rank, _ = np.linalg.lstsq(a, data[:, 2], rcond=None)
        return cls(np.asarray(coef, dtype=np.float64) if rank == 3 else None)

    def residuals(self, data: FloatArray) -> FloatArray:
        assert self.coef is not None
        a, b, c = self.coef
        return np.abs(data[:, 2] - (a + b * data[:, 0] + c * data[:, 1]))


def line_scores(
    volume: NDArray[np.float32], gap: int, width: int, lateral: float
) -> NDArray[np.float32]:
    """Step 1 of the module docstring: log intensity minus the larger side's mean log
    intensity, (nz, ny, nx); ``lateral`` is the Gaussian sigma across A-scans [voxels]."""
    from scipy import ndimage

    smooth = ndimage.gaussian_filter(
        volume, sigma=(0.0, lateral, lateral), mode="nearest", truncate=3.0
    )
    floor = max(float(smooth.max()) * 1e-6, float(np.finfo(np.float32).tiny))
    log = np.log(np.maximum(smooth, np.float32(floor)))
    del smooth
    nz = log.shape[0]
    cum = np.concatenate([np.zeros((1, *log.shape[1:])), np.cumsum(log, axis=0, dtype=np.float64)])
    k = np.arange(nz)
    a_hi = np.clip(k - gap, 0, nz)
    a_lo = np.clip(k - gap - width, 0, nz)
    b_lo = np.clip(k + gap + 1, 0, nz)
    b_hi = np.clip(k + gap + 1 + width, 0, nz)
    n_a = (a_hi - a_lo)[:, None, None]
    n_b = (b_hi - b_lo)[:, None, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        above = np.where(n_a > 0, (cum[a_hi] - cum[a_lo]) / np.maximum(n_a, 1), -np.inf)
        below = np.where(n_b > 0, (cum[b_hi] - cum[b_lo]) / np.maximum(n_b, 1), -np.inf)
    side = np.maximum(above, below)
    score = np.where(np.isfinite(side), log - side, 0.0)
    return score.astype(np.float32)


def find_reflections(
    volume: NDArray[np.float32],
    voxel_size: tuple[float, float, float],
    gap: int,
    width: int,
    lateral: float,
    seed: int = 0,
) -> list[Reflection]:
    """The flat reflections of a (normalised) scan, highest first (module docstring).

    ``gap`` rows on either side of a line are its own spread (about an axial resolution),
    ``width`` rows beyond them its sides, ``lateral`` the Gaussian sigma across A-scans of the
    smoothing [voxels]."""
    from skimage.measure import ransac

    nz, ny, nx = volume.shape
    score = line_scores(volume, gap, width, lateral)
    peak = np.ones(score.shape, dtype=bool)
    peak[1:] &= score[1:] >= score[:-1]
    peak[:-1] &= score[:-1] > score[1:]
    peak &= score > math.log(MIN_LINE_CONTRAST)
    # at most CANDIDATES_PER_ASCAN per A-scan, the strongest
    ranked = np.where(peak, score, -np.inf)
    top = np.argsort(-ranked, axis=0)[:CANDIDATES_PER_ASCAN]
    rows = top.reshape(len(top), -1)
    cols = np.broadcast_to(np.arange(ny * nx), rows.shape)
    keep = np.isfinite(ranked.reshape(nz, -1)[rows, cols])
    k, c = rows[keep], cols[keep]
    strength = ranked.reshape(nz, -1)[k, c]
    j, i = np.divmod(c, nx)
    points = np.c_[j - 0.5 * (ny - 1), i - 0.5 * (nx - 1), k].astype(np.float64)
    dz, dy, dx = voxel_size
    limit = (MAX_SLOPE * dy / dz, MAX_SLOPE * dx / dz)  # rows per A-scan

    def flat_enough(model: _Plane, *_: object) -> bool:
        assert model.coef is not None
        return abs(model.coef[1]) <= limit[0] and abs(model.coef[2]) <= limit[1]

    found: list[Reflection] = []
    rng = np.random.default_rng(seed)
    left = np.ones(len(points), dtype=bool)
    tolerance = max(1.5, 0.5 * gap)
    for _ in range(MAX_PLANES):
        if left.sum() < max(3, MIN_SUPPORT * ny * nx):
            break
        data = points[left]
        model, inliers = ransac(
            data,
            _Plane,
            min_samples=3,
            residual_threshold=tolerance,
            is_model_valid=flat_enough,
            max_trials=300,
            rng=rng,
        )
        if model is None or inliers is None or not model:
            break
        on = np.flatnonzero(left)[inliers]
        support = len(np.unique(c[on])) / (ny * nx)
        if support < MIN_SUPPORT:
            break
        a, b, cc = model.coef
        found.append(
            Reflection(
                row=float(a),
                slope=(float(b), float(cc)),
                support=float(support),
                contrast=float(np.exp(np.median(strength[on]))),
            )
        )
        # the plane's candidates and their neighbours within the line's spread go
        near = np.abs(points[:, 2] - (a + b * points[:, 0] + cc * points[:, 1])) <= gap + 1
        left &= ~near
    return sorted(found, key=lambda r: r.row)


def classify(
    volume: NDArray[np.float32],
    planes: list[Reflection],
    gap: int,
    lateral: float,
    substratum_row: float | None = None,
) -> list[Reflection]:
    """``planes`` with their share of bright voxels above them and their kind (module
    docstring); with ``substratum_row`` given (the user's), only windows above it are
    sought and no plane is the substratum."""
    from scipy import ndimage
    from skimage.filters import threshold_otsu

    if not planes:
        return []
    nz, ny, nx = volume.shape
    smooth = ndimage.gaussian_filter(volume, sigma=(1.0, lateral, lateral), mode="nearest")
    k = np.arange(nz, dtype=np.float64)[:, None, None]
    on_line = np.zeros(volume.shape, dtype=bool)
    for p in planes:
        on_line |= np.abs(k - p.rows((ny, nx))[None]) <= gap + 1
    if substratum_row is not None:
        on_line |= k >= substratum_row - gap
    values = smooth[~on_line]
    if values.size < 2 or float(values.max()) <= float(values.min()):
        return [_with(p, math.nan, "other") for p in planes]
    bright = (smooth > threshold_otsu(values.astype(np.float64), nbins=256)) & ~on_line
    total = max(int(bright.sum()), 1)
    shares = []
    for p in planes:
        above = k < p.rows((ny, nx))[None]
        shares.append(float(np.count_nonzero(bright & above)) / total)
    kinds: list[Literal["window", "substratum", "other"]] = ["other"] * len(planes)
    if substratum_row is None:
        windows = [n for n, s in enumerate(shares) if s < 0.5]
        floor = [n for n, s in enumerate(shares) if s > 0.5]
        # the substratum: the highest plane with the biofilm above it
        chosen = floor[0] if floor else None
        if chosen is not None:
            kinds[chosen] = "substratum"
        for n in windows:
            if chosen is None or planes[n].row < planes[chosen].row:
                kinds[n] = "window"
    else:
        for n, s in enumerate(shares):
            if s < 0.5 and planes[n].row < substratum_row - gap:
                kinds[n] = "window"
    return [_with(p, s, kind) for p, s, kind in zip(planes, shares, kinds, strict=True)]


def _with(
    p: Reflection, share: float, kind: Literal["window", "substratum", "other"]
) -> Reflection:
    return Reflection(p.row, p.slope, p.support, p.contrast, share, kind)


@dataclass(frozen=True)
class Floor:
    """Where the biofilm's rows end and what was taken out above and along them (step 1).

    ``ks`` is the first row of the (cropped, untilted) scan under the substratum's surface,
    ``tilt`` (rows per A-scan along y and x) the substratum plane's slope taken out,
    ``window`` the window's plane when one was found."""

    ks: int
    tilt: tuple[float, float]
    window: Reflection | None
    reflections: tuple[Reflection, ...]
    z0: int  # the crop's first row in the full volume
    shape: tuple[int, int]  # (ny, nx) of the A-scan grid

    def shift(self, j: int, nx: int) -> NDArray[np.float64]:
        """Rows to add to an untilted row of B-scan ``j`` to find it in the scan (nx,)."""
        i = np.arange(nx, dtype=np.float64) - 0.5 * (nx - 1)
        jc = j - 0.5 * (self.shape[0] - 1)
        return np.asarray(self.tilt[0] * jc + self.tilt[1] * i)

    def lines_in_scan(self, j: int, nx: int) -> dict[str, NDArray[np.float64] | None]:
        """The substratum's surface and the window's line along B-scan ``j``, in rows of the
        full volume."""
        sub = self.ks - 0.5 + self.shift(j, nx) + self.z0
        window = None
        if self.window is not None:
            window = self.window.rows(self.shape)[j] + self.z0
        return {"substratum": sub, "window": window}


def place_floor(
    volume: NDArray[np.float32],
    origin: tuple[int, int, int],
    substratum_depth: float | None,
    substratum_tilt: tuple[float, float],
    window: bool,
    spacing: tuple[float, float, float],
    axial: float,
    lateral: tuple[float, float],
    where: str,
) -> tuple[Floor, NDArray[np.float32]]:
    """Step 1: the window filled with the fluid under it, the scan untilted along the
    substratum's plane, and where the biofilm's rows end (:class:`Floor`)."""
    nz, ny, nx = volume.shape
    dz = spacing[0]
    gap = max(1, math.ceil(axial))
    width = max(4, 2 * gap)
    # planes are found on every s-th A-scan (at most MAX_ASCANS of them), then put back on
    # the full grid: a plane needs no more, and the line scores cost 5 floats per voxel
    s = max(1, math.ceil(math.sqrt(ny * nx / MAX_ASCANS)))
    view = volume[:, ::s, ::s]
    sigma = max(1.0, min(lateral) / s)
    sub_spacing = (dz, spacing[1] * s, spacing[2] * s)
    found = find_reflections(view, sub_spacing, gap, width, sigma)
    given = None
    if substratum_depth is not None:
        given = int(math.floor(substratum_depth / dz + 1.0)) - origin[0]
        check_floor_row(given, origin[0], nz, where)
    planes = classify(view, found, gap, sigma, None if given is None else float(given))
    planes = [_on_full_grid(p, s, view.shape[1:], (ny, nx)) for p in planes]
    windows = [p for p in planes if p.kind == "window"] if window else []
    above = windows[-1] if windows else None
    k = np.arange(nz, dtype=np.float64)[:, None, None]
    if above is not None:
        line = above.rows((ny, nx))[None]
        band = (k > line + gap) & (k <= line + gap + width)
        fill = float(np.median(volume[band])) if band.any() else 0.0
        volume[k <= line + gap] = fill
    tilt = (0.0, 0.0)
    if given is None:
        substrata = [p for p in planes if p.kind == "substratum"]
        if not substrata:
            seen = "; ".join(p.describe() for p in planes) or "none"
            raise ConfigError(
                "substratum not found: no flat reflection across at least "
                f"{100 * MIN_SUPPORT:.0f} % of the A-scans has the biofilm above it (flat "
                f"reflections, rows of the scan: {_in_full(seen, origin[0])}); a membrane or "
                "a substratum without a reflection: give substratum_depth (mm below the "
                "first row)",
                where,
            )
        sub = substrata[0]
        if np.ptp(sub.rows((ny, nx))) > 0.1:
            tilt = sub.slope
            volume = untilt(volume, sub)
        ks, tail = line_edge(volume[:, ::s, ::s], sub.row, gap, width)
        if any(tilt):  # untilting spread the line over one more row in part of the A-scans
            tail = max(tail, 1)
    else:
        # the user's plane: its depth at the field's centre, its slopes in mm per mm
        slope = (substratum_tilt[0] * spacing[1] / dz, substratum_tilt[1] * spacing[2] / dz)
        plane = Reflection(float(given), slope, 1.0, math.nan, kind="substratum")
        if np.ptp(plane.rows((ny, nx))) > 0.1:
            tilt = slope
            volume = untilt(volume, plane)
        ks, tail = given, 0
    check_floor_row(ks, origin[0], nz, where)
    tail = min(tail, max(ks - 2, 0))
    if tail:
        # the rows the reflection still brightens take the row above them: within a
        # resolution cell of a bright line nothing is resolved, and the denoising filter
        # would carry the line up into the biofilm's rows
        volume[ks - tail : ks] = volume[ks - tail - 1]
    floor = Floor(ks, tilt, above, tuple(planes), origin[0], (ny, nx))
    return floor, volume


def _on_full_grid(p: Reflection, s: int, sub: tuple[int, ...], full: tuple[int, int]) -> Reflection:
    """A plane found on every ``s``-th A-scan (a grid of ``sub``) on the ``full`` grid."""
    if s == 1:
        return p
    by, bx = p.slope[0] / s, p.slope[1] / s
    # the full grid's centre in the sub-grid's indices, relative to the sub-grid's centre
    oy = 0.5 * (full[0] - 1) / s - 0.5 * (sub[0] - 1)
    ox = 0.5 * (full[1] - 1) / s - 0.5 * (sub[1] - 1)
    row = p.row + p.slope[0] * oy + p.slope[1] * ox
    return Reflection(row, (by, bx), p.support, p.contrast, p.bright_above, p.kind)


def _in_full(text: str, z0: int) -> str:
    return text if not z0 else f"{text} (crop rows; the crop starts at row {z0})"


def check_floor_row(ks: int, z0: int, nz: int, where: str) -> None:
    if not 2 <= ks < nz:
        raise ConfigError(
            f"substratum at row {ks + z0} leaves no biofilm rows above it in the volume (rows "
            f"{z0} to {z0 + nz - 1}); check depth_axis, crop or substratum_depth",
            where,
        )


def untilt(volume: NDArray[np.float32], plane: Reflection) -> NDArray[np.float32]:
    """Every A-scan shifted along depth (linear interpolation) so that ``plane`` lies along
    its row at the field's centre; one B-scan at a time (no coordinate array of the volume)."""
    from scipy import ndimage

    nz, ny, nx = volume.shape
    shift = plane.rows((ny, nx)) - plane.row
    out = np.empty_like(volume)
    k = np.arange(nz, dtype=np.float64)[:, None]
    i = np.broadcast_to(np.arange(nx, dtype=np.float64)[None, :], (nz, nx))
    for j in range(ny):
        coords = np.stack([k + shift[j][None, :], i])
        out[:, j, :] = ndimage.map_coordinates(volume[:, j, :], coords, order=1, mode="nearest")
    return out


def line_edge(volume: NDArray[np.float32], row: float, gap: int, width: int) -> tuple[int, int]:
    """The substratum's surface: the upper half-maximum edge of its reflection in the median
    depth profile of the untilted scan (the surface of a sharp reflection, and half the
    line's spread above its centre for a blurred one); returns the first row under it and
    the rows above it the reflection still brightens: as many above the peak as
    it brightens below it by a quarter over the level deeper down (a biofilm above it, which
    brightens the rows above whatever the line does, does not count)."""
    profile = np.median(volume.reshape(len(volume), -1), axis=1).astype(np.float64)
    nz = len(profile)
    lo, hi = max(0, int(round(row)) - gap), min(nz, int(round(row)) + gap + 1)
    peak = lo + int(np.argmax(profile[lo:hi]))
    side_rows = profile[max(0, peak - gap - width) : max(0, peak - gap)]
    side = float(np.median(side_rows)) if len(side_rows) else float(profile[: max(peak, 1)].min())
    half = 0.5 * (profile[peak] + side)
    k = peak
    while k > 0 and profile[k - 1] >= half:
        k -= 1
    if k == 0:
        edge = 0.0
    else:
        below, up = profile[k], profile[k - 1]
        edge = (k - 1) + (half - up) / (below - up) if below > up else float(k)
    ks = int(round(edge + 0.5))
    # the bleed: a reflection spreads up as far as down, and under it lies only the
    # substratum, so its spread is measured below the peak (rows brighter than a quarter
    # above the level deeper down) and taken off above it, from the peak up
    deep = profile[peak + gap + 1 : peak + gap + 1 + width]
    spread = 0
    if len(deep):
        level = float(np.median(deep))
        while peak + spread + 1 < nz and spread < gap and profile[peak + spread + 1] > 1.25 * level:
            spread += 1
    tail = max(0, ks - (peak - spread))
    return ks, tail
