"""The RKHS distance as a sum of squares: the residual vector of the ``rkhs`` measure.

The Gaussian kernel of Paper B eq. 10b, k(x, y) = exp(−|x − y|²/(2σ²)), is a convolution of
two Gaussians of width s = σ/√2 (on R^d)::

    k(x, y) = (π s²)^(−d/2) ∫ g(x − z) g(z − y) dz,      g(u) = exp(−|u|²/(2 s²)).

For the difference of two currents μ = S1 − S2 (eq. 11) that gives

    D² = ∫∫ k(x, y) dμ(x)·dμ(y) = (π s²)^(−d/2) ∫ |w(z)|² dz,   w(z) = ∫ g(z − x) dμ(x),

an integral of a smooth vector field w over space.  With the trapezoidal rule on a grid of
spacing h at fixed test points z_q, D² = Σ_q |r_q|² with r_q = (h/(√π s))^(d/2) w(z_q): a
residual vector whose squared norm is the currents distance, whose length and meaning do
not change from one simulated interface to the next (the Levenberg–Marquardt Jacobian needs
both).  The rule is spectrally accurate for Gaussians: the relative error of D² is about
2 exp(−π² s²/h²), 5e-9 for h = σ/2.

The test points are the grid points within ``reach`` + s·√(ln 1/truncation) of the observed
interface: w vanishes (to the truncation) farther out, as long as the simulated interface
stays within ``reach`` of the observed one.  Parts of it farther away are not seen by the
vector (its norm is then below D; ``distance`` is always the exact double sum).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

FloatArray = NDArray[np.float64]


def test_points(centres: FloatArray, spacing: float, radius: float) -> FloatArray:
    """The points of the grid ``spacing·Z^d`` within ``radius`` of any of ``centres``.

    The grid is anchored at the origin, so the same observation always gives the same
    points, in lexicographic order.
    """
    lo = np.floor((centres.min(axis=0) - radius) / spacing).astype(np.int64)
    hi = np.ceil((centres.max(axis=0) + radius) / spacing).astype(np.int64)
    tree = cKDTree(centres)
    axes = [np.arange(a, b + 1) * spacing for a, b in zip(lo, hi, strict=True)]
    kept = []
    # slab by slab along the first axis, so that the full box is never held in memory
    rest = np.stack(np.meshgrid(*axes[1:], indexing="ij"), axis=-1).reshape(-1, len(axes) - 1)
    for x0 in axes[0]:
        slab = np.column_stack([np.full(len(rest), x0), rest])
        d, _ = tree.query(slab, distance_upper_bound=radius)
        kept.append(slab[np.isfinite(d)])
    return np.concatenate(kept) if kept else np.empty((0, centres.shape[1]))


def count_test_points(centres: FloatArray, spacing: float, radius: float) -> int:
    """An upper bound of ``len(test_points(...))`` from the bounding box, computed cheaply."""
    extent = centres.max(axis=0) - centres.min(axis=0) + 2.0 * radius
    return int(np.prod(np.ceil(extent / spacing) + 1))


def smoothed_field(
    points: FloatArray, centres: FloatArray, vectors: FloatArray, s: float, cutoff: float
) -> FloatArray:
    """w(z_q) = Σ_i g(z_q − c_i) a_i with g of width s, pairs farther than ``cutoff`` left out;
    shape (len(points), dim)."""
    out = np.zeros((len(points), centres.shape[1]))
    if len(points) == 0 or len(centres) == 0:
        return out
    pairs = cKDTree(points).sparse_distance_matrix(cKDTree(centres), cutoff, output_type="ndarray")
    q, i, dist = pairs["i"], pairs["j"], pairs["v"]
    weights = np.exp(-(dist**2) / (2.0 * s * s))
    for k in range(centres.shape[1]):
        out[:, k] = np.bincount(q, weights=weights * vectors[i, k], minlength=len(points))
    return out


def residual_scale(spacing: float, s: float, dim: int) -> float:
    """(h/(√π s))^(d/2): r_q = scale · w(z_q)."""
    return float((spacing / (math.sqrt(math.pi) * s)) ** (dim / 2.0))
