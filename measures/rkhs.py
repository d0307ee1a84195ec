"""RKHS norm of the difference of two interfaces as surface currents (Paper B eq. 9-11, 23).

An interface is represented by its element centres ``c_i`` and area vectors ``a_i`` (unit
normal times element length in 2-D or area in 3-D).  With the Gaussian kernel of eq. 10b,

    <S, T> = sum_i sum_j k(c_i, d_j) a_i . b_j,    k(x, y) = exp(-|x - y|^2 / (2 sigma_W^2)),

and the distance is ``D = sqrt(<S1, S1> - 2 <S1, S2> + <S2, S2>)`` (eq. 11).  Because the
vectors carry the element sizes, the double sum is a quadrature of the continuous currents
inner product ``∫∫ k(x, y) n(x) . m(y) dx dy`` and converges to it under mesh refinement.

>>> import numpy as np, fbia
>>> x = np.linspace(0.0, 1.0, 41)
>>> obs = fbia.Observation(fbia.Interface.polyline(np.c_[x, np.zeros_like(x)]))
>>> measure = RkhsMeasure(sigma_w=0.1)
>>> measure.distance(fbia.Interface.polyline(np.c_[x, np.zeros_like(x)]), obs) < 1e-7
True
>>> round(measure.distance(fbia.Interface.polyline(np.c_[x, np.full_like(x, 0.01)]), obs), 6)
0.047978
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field
from scipy.spatial import cKDTree

from ..core.errors import ConfigError
from ..core.interface import Interface
from ..core.observation import Observation
from ..core.options import PluginOptions
from ..core.protocols import MeasureBase
from ._geometry import FloatArray, IdentityCache, check_dimensions, cutoff_radius
from ._rkhs_field import (
    count_test_points,
    residual_scale,
    smoothed_field,
    test_points,
)

#: |D^2| below this fraction of <S1,S1> + 2|<S1,S2>| + <S2,S2> is round-off; a more negative
#: D^2 cannot come from a positive definite kernel and is reported as a bug.
_ROUNDOFF = 1e-9
#: Exponents are clamped at this value before exp() (see currents_product).
_EXP_FLOOR = -200.0
#: Element pairs per tile of the blocked sums: 32768 pairs are 256 kB of float64, and BLAS
#: (OpenBLAS: below 262144 multiply-adds) runs a tile's products on one thread.
TILE_PAIRS = 32768


@dataclass(frozen=True)
class TestGrid:
    """The fixed test points of an observation and its own field there (see
    :mod:`fbia.measures._rkhs_field`): residuals ``scale · (w_sim(points) − w_obs)``."""

    points: FloatArray
    w_obs: FloatArray
    scale: float


@dataclass(frozen=True)
class Current:
    """A discrete surface current, its elements sorted into spatially compact blocks."""

    centres: FloatArray  # (m, dim), in block order
    vectors: FloatArray  # (m, dim), area vectors or unit normals, in block order
    starts: NDArray[np.intp]  # (n_blocks + 1,) first element of each block
    lower: FloatArray  # (n_blocks, dim) bounding box of each block
    upper: FloatArray

    @classmethod
    def of(cls, interface: Interface, unit_normals: bool, block_size: int) -> Current:
        centres = interface.centres
        vectors = interface.normals if unit_normals else interface.area_vectors
        # the leaves of a KD-tree are contiguous in tree.indices: a spatially compact order
        order = cKDTree(centres, leafsize=max(8, block_size // 2)).indices
        x = np.ascontiguousarray(centres[order])
        starts = np.r_[np.arange(0, len(x), block_size), len(x)].astype(np.intp)
        return cls(
            centres=x,
            vectors=np.ascontiguousarray(vectors[order]),
            starts=starts,
            lower=np.minimum.reduceat(x, starts[:-1], axis=0),
            upper=np.maximum.reduceat(x, starts[:-1], axis=0),
        )

    @property
    def n_blocks(self) -> int:
        return len(self.starts) - 1


def currents_product(
    s: Current, t: Current, sigma: float, cutoff: float = np.inf, same: bool = False
) -> float:
    """``<S, T> = sum_ij k(c_i, d_j) a_i . b_j`` with the Gaussian kernel (eq. 10b, 11).

    Block pairs whose bounding boxes are farther apart than ``cutoff`` are skipped.  With
    ``same=True`` (``t is s``) only block pairs ``J >= I`` are evaluated, the others by
    symmetry.  The rest is summed in tiles of ``s``'s block size times at most
    :data:`TILE_PAIRS` / block size columns: small enough to stay in cache and for BLAS to
    run them on one thread (no oversubscription when an evaluator runs one process per core).
    Squared distances come from one matrix product of augmented coordinates, taken relative
    to the centre of the row block so that round-off stays at about
    ``(block extent + cutoff)^2 / sigma^2`` machine epsilons.
    """
    dim = s.centres.shape[1]
    inv = 1.0 / sigma**2
    rows_max = int(np.diff(s.starts).max())
    cols_max = max(int(np.diff(t.starts).max()), TILE_PAIRS // rows_max)
    buf = np.empty(rows_max * cols_max)
    xa = np.empty((rows_max, dim + 2))
    ya = np.empty((cols_max, dim + 2))
    total = 0.0
    for i in range(s.n_blocks):
        # squared smallest and largest distances between block i's box and every box of t
        below = t.lower - s.upper[i]
        above = s.lower[i] - t.upper
        apart = np.maximum(np.maximum(below, above), 0.0)
        gap = np.einsum("ij,ij->i", apart, apart)
        far = np.maximum(t.upper - s.lower[i], s.upper[i] - t.lower)
        span = np.einsum("ij,ij->i", far, far)
        near = gap <= cutoff**2
        if same:
            near[:i] = False
        blocks = np.flatnonzero(near)
        if len(blocks) == 0:
            continue
        floor = 0.5 * inv * span > -_EXP_FLOOR  # blocks that may need the exponent floor
        lo, hi = s.starts[i], s.starts[i + 1]
        nr = hi - lo
        a = s.vectors[lo:hi]
        centre = s.centres[lo:hi].mean(axis=0)
        xl = s.centres[lo:hi] - centre
        xa[:nr, :dim] = xl * inv
        xa[:nr, dim] = -0.5 * inv * np.einsum("ij,ij->i", xl, xl)
        xa[:nr, dim + 1] = 1.0
        for b0, b1, weight in _column_chunks(blocks, t.starts, cols_max, i if same else -1):
            c0, c1 = t.starts[b0], t.starts[b1]
            nc = c1 - c0
            yl = t.centres[c0:c1] - centre
            ya[:nc, :dim] = yl
            ya[:nc, dim] = 1.0
            ya[:nc, dim + 1] = -0.5 * inv * np.einsum("ij,ij->i", yl, yl)
            g = buf[: nr * nc].reshape(nr, nc)
            np.matmul(xa[:nr], ya[:nc].T, out=g)  # -|x - y|^2 / (2 sigma^2)
            if floor[b0:b1].any():
                # exp() of very negative numbers takes a slow path and returns subnormal
                # numbers that slow the next product ~100-fold; values below e^-200 are moot.
                np.maximum(g, _EXP_FLOOR, out=g)
            np.exp(g, out=g)
            total += weight * float(np.einsum("ij,ij->", a, g @ t.vectors[c0:c1]))
    return total


def _column_chunks(
    blocks: NDArray[np.intp], starts: NDArray[np.intp], cols_max: int, diagonal: int
) -> list[tuple[int, int, float]]:
    """Block ranges ``(first, stop, weight)`` covering the sorted ``blocks``.

    Consecutive blocks are merged while they span at most ``cols_max`` columns.  Block
    ``diagonal`` (of a self-product) gets a range of its own with weight 1, all others
    weight 2 then.
    """
    out: list[tuple[int, int, float]] = []
    weight = 1.0 if diagonal < 0 else 2.0
    run_start = run_stop = -1
    for b in blocks.tolist():
        if b == diagonal:
            out.append((b, b + 1, 1.0))
            continue
        if run_start >= 0 and b == run_stop and starts[b + 1] - starts[run_start] <= cols_max:
            run_stop = b + 1
            continue
        if run_start >= 0:
            out.append((run_start, run_stop, weight))
        run_start, run_stop = b, b + 1
    if run_start >= 0:
        out.append((run_start, run_stop, weight))
    return out


class RkhsMeasure(MeasureBase):
    """RKHS (surface currents) distance between interfaces (Paper B eq. 10-11).

    ``D^2 = <S1, S1> - 2 <S1, S2> + <S2, S2>`` where ``S1`` is the simulated and ``S2`` the
    observed interface, each a sum over its elements of ``a_i delta_{c_i}`` (centre ``c_i``,
    area vector ``a_i``); the kernel is the RBF of eq. 10b/23 with width ``sigma_w``.  The
    value converges to the norm of the continuous currents under mesh refinement (second
    order for straight or smoothly curved interfaces).  Orientation matters: reversing one
    interface flips the sign of the cross term.

    ``sigma_w`` sets what is compared: features smaller than it are smoothed out, and
    interfaces farther apart than a few ``sigma_w`` no longer interact (for
    Levenberg–Marquardt from distant starts, choose it of the order of the displacements).
    Paper B uses 0.005 mm (about 10 % of the largest displacement, Sect. "Numerical
    examples"), the default here; elements should be no larger than about ``sigma_w`` for
    the sum to represent the integral well.

    The self-product ``<S2, S2>`` of each observed interface is computed once and cached.
    Distance: ``D`` (units in the Notes).  Residuals (``residuals = "vector"``, default): a
    vector whose squared norm is D², from the factorisation of the Gaussian kernel into two
    of width σ_W/√2 sampled at fixed test points around the observed interface
    (:mod:`fbia.measures._rkhs_field`), so that Levenberg–Marquardt has one residual per
    test point and component instead of one in all; equal to D to quadrature accuracy
    (about 1e-8 relative in D² at the default spacing) while the simulated interface stays
    within ``reach`` of the observed one.  ``residuals = "distance"`` gives ``np.array([D])``.
    Either way the Gaussian likelihood (Paper B eq. 5) counts D as one measurement per
    observation (:attr:`measurements_per_observation`).

    Notes
    -----
    With area vectors (default) ``D`` has units of length^(dim-1) (mm in 2-D, mm^2 in 3-D);
    with ``unit_normals=True`` (Paper B Fig. 1c: normals of equal length) it is a pure
    number that grows with the number of elements, so it is only comparable between meshes
    of the same resolution.
    """

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"
    pickle_options_only = True  # process pools and Dask rebuild it from its options

    class Options(PluginOptions):
        sigma_w: float = Field(
            0.005,
            gt=0,
            description=(
                "width sigma_W of the Gaussian kernel, eq. 10b [mm]; Paper B: 0.005 mm, "
                "about 10 % of the largest displacement"
            ),
        )
        unit_normals: bool = Field(
            False,
            description=(
                "weight each element by its unit normal (Paper B Fig. 1c) instead of its "
                "normal times length/area [-]"
            ),
        )
        block_size: int = Field(
            128,
            ge=8,
            le=4096,
            description=(
                "elements per spatial block [-]: blocks farther apart than the truncation "
                "radius are skipped, the rest is summed in tiles of block_size x "
                "max(block_size, 32768 / block_size) element pairs"
            ),
        )
        residuals: Literal["vector", "distance"] = Field(
            "vector",
            description=(
                "residual vector for least squares: 'vector', the kernel-smoothed difference "
                "of the currents at fixed test points (squared norm = D^2), or 'distance', "
                "the single number D [-]"
            ),
        )
        spacing: float = Field(
            0.5,
            gt=0,
            le=2.0,
            description=(
                "spacing of the test points of the residual vector, relative to sigma_w [-]; "
                "the relative error of D^2 is about 2 exp(-pi^2 / (2 spacing^2))"
            ),
        )
        reach: float | None = Field(
            None,
            gt=0,
            description=(
                "test points cover the observed interface to this distance plus the kernel's "
                "own range: the residual vector equals D while the simulated interface stays "
                "this close to the observed one [mm]; default 2 sigma_w"
            ),
        )
        max_test_points: int = Field(
            500_000,
            ge=1,
            description=(
                "refuse an observation that needs more test points than this (3-D with a "
                "small sigma_w): use residuals = 'distance' or a larger spacing [-]"
            ),
        )
        truncation: float = Field(
            1e-18,
            ge=0,
            lt=1e-3,
            description=(
                "skip blocks of element pairs whose kernel values are all below this "
                "(farther apart than sigma_w * sqrt(2 ln(1/truncation)), 9.1 sigma_w by "
                "default) [-]; 0: sum every pair"
            ),
        )

    options: Options
    dims = (2, 3)
    #: Paper B eq. 5 counts the currents distance D as one measurement per observation,
    #: whatever the length of the residual vector.
    measurements_per_observation = 1

    @classmethod
    def example_options(cls) -> dict[str, object]:
        """A kernel width that suits the sample interfaces of fbia.testing (about 1 mm in
        size, elements of about 0.015 mm)."""
        return {"sigma_w": 0.05}

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: object) -> None:
        super().__init__(options, **kwargs)
        self._observed: IdentityCache[tuple[Current, float]] = IdentityCache(maxsize=64)
        self._grids: IdentityCache[TestGrid] = IdentityCache(maxsize=64)

    # -- protocol ----------------------------------------------------------------------------
    def residuals(self, simulated: Interface, observation: Observation) -> np.ndarray:
        """A vector with squared norm D² (eq. 11), or ``np.array([D])`` (see the class)."""
        if self.options.residuals == "distance":
            return np.array([self.distance(simulated, observation)])
        check_dimensions("rkhs", simulated, observation)
        gamma = self._observed_interface(observation)
        grid = self._grids.get((gamma,), lambda: self._test_grid(gamma, observation))
        w = smoothed_field(
            grid.points, simulated.centres, self._vectors(simulated), *self._half_kernel
        )
        return np.asarray((grid.scale * (w - grid.w_obs)).ravel(), dtype=float)

    def distance(self, simulated: Interface, observation: Observation) -> float:
        """``D``, the RKHS norm of the difference of the two currents (eq. 10-11)."""
        check_dimensions("rkhs", simulated, observation)
        gamma = self._observed_interface(observation)
        s2, s22 = self._observed.get((gamma,), lambda: self._with_self_product(gamma))
        s1, s11 = self._with_self_product(simulated)
        s12 = currents_product(s1, s2, self.options.sigma_w, self._cutoff)
        return self._combine(s11, s12, s22)

    def inner_product(self, first: Interface, second: Interface) -> float:
        """``<S1, S2>`` of two interfaces (eq. 11 cross term)."""
        return currents_product(
            self.current(first), self.current(second), self.options.sigma_w, self._cutoff
        )

    def current(self, interface: Interface) -> Current:
        """The blocked current of ``interface`` under these options."""
        return Current.of(interface, self.options.unit_normals, self.options.block_size)

    # -- internals ---------------------------------------------------------------------------
    @staticmethod
    def _observed_interface(observation: Observation) -> Interface:
        gamma = observation.interface
        if gamma is None:
            raise ConfigError(
                f"observation {observation.label()!r} has no observed interface "
                "(only measurement points); use the ray measure or add an interface",
                "rkhs measure",
            )
        return gamma

    def _vectors(self, interface: Interface) -> FloatArray:
        return interface.normals if self.options.unit_normals else interface.area_vectors

    @property
    def _half_kernel(self) -> tuple[float, float]:
        """Width s = σ_W/√2 of the kernel's square root and the distance where it drops below
        the truncation."""
        s = self.options.sigma_w / math.sqrt(2.0)
        return s, cutoff_radius(s, self.options.truncation)

    def _test_grid(self, gamma: Interface, observation: Observation) -> TestGrid:
        o = self.options
        s, cutoff = self._half_kernel
        h = o.spacing * o.sigma_w
        reach = 2.0 * o.sigma_w if o.reach is None else o.reach
        # |w|² decays like exp(-d²/s²): below the truncation s·√(ln 1/truncation) away
        tail = s * math.sqrt(math.log(1.0 / o.truncation)) if o.truncation > 0 else 10.0 * s
        radius = reach + tail
        # the box around the interface bounds the work of finding the points near it
        n_box = count_test_points(gamma.centres, h, radius)
        points = test_points(gamma.centres, h, radius) if n_box <= 100 * o.max_test_points else None
        n = n_box if points is None else len(points)
        if n > o.max_test_points:
            raise ConfigError(
                f"observation {observation.label()!r} needs {n} test points for the residual "
                f"vector (sigma_w = {o.sigma_w:g} mm, spacing {o.spacing:g}), more than "
                f"max_test_points = {o.max_test_points}; use residuals = 'distance', a larger "
                "spacing or a larger max_test_points",
                "rkhs measure",
            )
        assert points is not None
        w_obs = smoothed_field(points, gamma.centres, self._vectors(gamma), s, cutoff)
        return TestGrid(points=points, w_obs=w_obs, scale=residual_scale(h, s, points.shape[1]))

    @property
    def _cutoff(self) -> float:
        return cutoff_radius(self.options.sigma_w, self.options.truncation)

    def _with_self_product(self, interface: Interface) -> tuple[Current, float]:
        cur = self.current(interface)
        return cur, currents_product(cur, cur, self.options.sigma_w, self._cutoff, same=True)

    @staticmethod
    def _combine(s11: float, s12: float, s22: float) -> float:
        d2 = s11 - 2.0 * s12 + s22
        if d2 < 0.0:
            scale = abs(s11) + 2.0 * abs(s12) + abs(s22)
            if -d2 > _ROUNDOFF * scale:
                raise RuntimeError(
                    f"rkhs measure: squared distance {d2:.3e} is negative beyond round-off "
                    f"(<S1,S1>={s11:.6e}, <S1,S2>={s12:.6e}, <S2,S2>={s22:.6e}); "
                    "this is a bug, please report it"
                )
            d2 = 0.0
        return float(np.sqrt(d2))
