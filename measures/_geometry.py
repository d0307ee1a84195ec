"""Geometric kernels shared by the measures: closest points, line intersections, caches.

Everything is vectorised over query points and works for 2-D interfaces (segments) and 3-D
interfaces (triangles) alike.  Candidate elements are found with a KD-tree on the element
centres (:class:`scipy.spatial.cKDTree`): an element whose centre lies farther than
``r + radius_max`` from a point cannot come closer to it than ``r`` (``radius_max`` is the
largest centre-to-vertex distance of any element), so the searches are exact, not heuristic.

>>> import numpy as np
>>> from fbia.core.interface import Interface
>>> gamma = Interface.polyline([[0.0, 0.0], [1.0, 0.0]])          # solid below, normal +y
>>> hit = closest_points(geometry_of(gamma), np.array([[0.3, -0.2], [1.3, 0.4]]))
>>> hit.signed_distance.round(12).tolist()                         # + on the biofilm side
[0.2, -0.5]
"""

from __future__ import annotations

import itertools
import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..core.data_files import MAX_COORDINATE
from ..core.errors import ConfigError, MeasureError
from ..core.interface import Interface
from ..core.observation import Observation

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

T = TypeVar("T")

#: Relative tolerance on barycentric/segment parameters when testing whether a line meets an
#: element: a line through a shared vertex or edge hits every element that shares it.
_PARAM_TOL = 1e-12
#: Relative tolerance below which a line counts as parallel to an element.
_PARALLEL_TOL = 1e-13


class IdentityCache(Generic[T]):
    """A small least-recently-used cache keyed by object *identity*.

    :class:`~fbia.core.interface.Interface` has ``__slots__`` and no ``__hash__`` of its own
    content, and :class:`~fbia.core.observation.Observation` holds a dict, so neither can key a
    ``dict`` by value.  This cache keeps a strong reference to each key object, so an ``id``
    cannot be reused while its entry lives; ``maxsize`` bounds what is kept alive.
    """

    def __init__(self, maxsize: int = 4) -> None:
        self.maxsize = maxsize
        self._entries: OrderedDict[tuple[int, ...], tuple[tuple[Any, ...], T]] = OrderedDict()

    def get(self, keys: tuple[Any, ...], build: Any) -> T:
        """The value stored for the objects ``keys``; ``build()`` makes it on a miss."""
        ident = tuple(id(k) for k in keys)
        entry = self._entries.get(ident)
        if entry is not None and all(a is b for a, b in zip(entry[0], keys, strict=True)):
            self._entries.move_to_end(ident)
            return entry[1]
        value: T = build()
        self._entries[ident] = (keys, value)
        while len(self._entries) > self.maxsize:
            self._entries.popitem(last=False)
        return value

    def clear(self) -> None:
        self._entries.clear()

    def __len__(self) -> int:
        return len(self._entries)


class ElementGeometry:
    """Search data of one interface: element corners, centres, radii, KD-tree, pseudo-normals.

    Build it with :func:`geometry_of`, which caches it per interface object.
    """

    def __init__(self, interface: Interface) -> None:
        self.interface = interface
        self.dim = interface.dim
        self.corners: FloatArray = np.ascontiguousarray(interface.element_points)  # (m, dim, dim)
        self.centres: FloatArray = np.ascontiguousarray(interface.centres)
        self.radii: FloatArray = np.linalg.norm(
            self.corners - self.centres[:, None, :], axis=2
        ).max(axis=1)
        self.radius_max = float(self.radii.max())
        self.lower, self.upper = interface.bounds
        self.tree = cKDTree(self.centres)
        self._pseudo: FloatArray | None = None

    def __len__(self) -> int:
        return len(self.centres)

    @property
    def pseudo_normals(self) -> FloatArray:
        """Unit normal of every feature of every element, shape (m, n_features, dim).

        Features (the ``region`` codes of :func:`closest_points`): 2-D ``0`` segment interior,
        ``1``/``2`` first/second vertex; 3-D ``0`` face, ``1``/``2``/``3`` vertices a/b/c,
        ``4``/``5``/``6`` edges ab/bc/ca.  At a vertex or edge shared by several elements the
        normal is the pseudo-normal of Bærentzen & Aanæs (2005): the angle-weighted mean of the
        adjacent element normals at a vertex (in 2-D both angles are pi, so the plain mean),
        the mean of the two face normals at an edge.  With it the sign of
        ``(x - closest) . normal`` tells the side of ``x`` also where the closest point is a
        corner.  Vertices at equal coordinates are merged first, so surfaces read from STL
        files (one vertex copy per triangle) get the right pseudo-normals too.
        """
        if self._pseudo is None:
            self._pseudo = _pseudo_normals(self.interface)
        return self._pseudo


#: Search data of the most recently used interfaces (e.g. the simulated interface that the ray
#: measure meets again for the next observation or the next call).  Measures keep the search
#: data of observed interfaces in caches of their own, so these do not push them out.
_RECENT: IdentityCache[ElementGeometry] = IdentityCache(maxsize=2)


def geometry_of(
    interface: Interface, cache: IdentityCache[ElementGeometry] | None = None
) -> ElementGeometry:
    """The :class:`ElementGeometry` of ``interface``, from ``cache`` (default: a module-wide
    cache of the two most recently used interfaces) or built and stored there."""
    return (cache or _RECENT).get((interface,), lambda: ElementGeometry(interface))


def check_dimensions(measure: str, simulated: Interface, observation: Observation) -> None:
    """ConfigError if ``simulated`` is no Interface or differs from the observation in dim;
    MeasureError if a simulated coordinate's magnitude reaches ``MAX_COORDINATE`` (1e9 mm):
    distances, their squares and products would lose all precision or overflow (observed
    data is held to the same bound when it is read or an Observation is made)."""
    if not isinstance(simulated, Interface):
        raise ConfigError(
            f"the simulated interface must be an fbia.Interface, got {type(simulated).__name__}",
            f"{measure} measure",
        )
    if simulated.dim != observation.dim:
        raise ConfigError(
            f"simulated interface is {simulated.dim}-D but observation "
            f"{observation.label()!r} is {observation.dim}-D",
            f"{measure} measure",
        )
    largest = float(np.max(np.abs(simulated.vertices)))
    if not largest < MAX_COORDINATE:
        raise MeasureError(
            f"{measure} measure: the simulated interface has a coordinate of magnitude "
            f"{largest:.3g} mm, beyond the bound {MAX_COORDINATE:.0e} mm of any flow cell "
            "(a diverged forward run?)"
        )


def _normalise(v: FloatArray, fallback: FloatArray) -> FloatArray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = norm > 1e-300
    return np.where(ok, v / np.where(ok, norm, 1.0), fallback)


def _scatter_add(index: IntArray, values: FloatArray, n: int) -> FloatArray:
    """``out[index[k]] += values[k]`` for rows of ``values``, shape (n, values.shape[1])."""
    return np.stack(
        [np.bincount(index, weights=values[:, j], minlength=n) for j in range(values.shape[1])],
        axis=1,
    )


def merged_vertex_ids(vertices: FloatArray) -> IntArray:
    """An id per vertex, equal for vertices at exactly the same coordinates."""
    order = np.lexsort(vertices.T[::-1])
    sorted_v = vertices[order]
    new = np.r_[True, np.any(sorted_v[1:] != sorted_v[:-1], axis=1)]
    ids = np.empty(len(vertices), dtype=np.intp)
    ids[order] = np.cumsum(new) - 1
    return ids


def _pseudo_normals(interface: Interface) -> FloatArray:
    vid = merged_vertex_ids(interface.vertices)
    cells = vid[interface.cells]  # merged vertex ids
    normals = interface.normals
    nv = int(vid.max()) + 1
    if interface.dim == 2:
        acc = _scatter_add(cells.T.ravel(), np.tile(normals, (2, 1)), nv)
        pn = np.empty((len(cells), 3, 2))
        pn[:, 0] = normals
        pn[:, 1] = _normalise(acc[cells[:, 0]], normals)
        pn[:, 2] = _normalise(acc[cells[:, 1]], normals)
        return pn
    p = interface.element_points
    weighted = []
    for j in range(3):  # angle-weighted vertex normals
        u = p[:, (j + 1) % 3] - p[:, j]
        w = p[:, (j + 2) % 3] - p[:, j]
        cos = np.einsum("ij,ij->i", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        weighted.append(np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * normals)
    acc = _scatter_add(cells.T.ravel(), np.vstack(weighted), nv)
    local_edges = ((0, 1), (1, 2), (2, 0))
    pairs = np.vstack([np.sort(cells[:, list(e)], axis=1) for e in local_edges])
    keys = pairs[:, 0].astype(np.int64) * nv + pairs[:, 1]
    _, eid = np.unique(keys, return_inverse=True)
    eacc = _scatter_add(eid, np.tile(normals, (3, 1)), int(eid.max()) + 1)
    eid = eid.reshape(3, len(cells)).T
    pn = np.empty((len(cells), 7, 3))
    pn[:, 0] = normals
    for j in range(3):
        pn[:, 1 + j] = _normalise(acc[cells[:, j]], normals)
        pn[:, 4 + j] = _normalise(eacc[eid[:, j]], normals)
    return pn


# -- closest points ---------------------------------------------------------------------------
def _closest_on_segments(
    q: FloatArray, a: FloatArray, b: FloatArray
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Closest points of ``q`` on segments ``a``-``b`` (rowwise): squared distance, point,
    region."""
    e = b - a
    t = np.einsum("ij,ij->i", q - a, e) / np.einsum("ij,ij->i", e, e)
    region = np.where(t <= 0.0, 1, np.where(t >= 1.0, 2, 0))
    t = np.clip(t, 0.0, 1.0)
    cp = a + t[:, None] * e
    diff = q - cp
    return np.einsum("ij,ij->i", diff, diff), cp, region


def _closest_on_triangles(
    q: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Closest points of ``q`` on triangles ``abc`` (rowwise), Ericson's region tests (2005,
    "Real-Time Collision Detection", 5.1.5), vectorised; squared distance, point, region."""
    ab, ac = b - a, c - a

    def dot(x: FloatArray, y: FloatArray) -> FloatArray:
        return np.einsum("ij,ij->i", x, y)

    ap, bp, cp_ = q - a, q - b, q - c
    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp_), dot(ac, cp_)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    in_a = (d1 <= 0) & (d2 <= 0)
    in_b = (d3 >= 0) & (d4 <= d3)
    in_c = (d6 >= 0) & (d5 <= d6)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    on_ca = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    on_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    # precedence as in Ericson: vertex a, b, edge ab, vertex c, edge ca, edge bc, face
    region = np.zeros(len(q), dtype=np.intp)
    done = np.zeros(len(q), dtype=bool)
    for mask, code in ((in_a, 1), (in_b, 2), (on_ab, 4), (in_c, 3), (on_ca, 6), (on_bc, 5)):
        sel = mask & ~done
        region[sel] = code
        done |= sel
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ca = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        denom = 1.0 / (va + vb + vc)
        v, w = vb * denom, vc * denom
    point = a + v[:, None] * ab + w[:, None] * ac  # face region
    for code, value in (
        (1, a),
        (2, b),
        (3, c),
        (4, a + t_ab[:, None] * ab),
        (6, a + t_ca[:, None] * ac),
        (5, b + t_bc[:, None] * (c - b)),
    ):
        sel = region == code
        point[sel] = value[sel]
    diff = q - point
    return np.einsum("ij,ij->i", diff, diff), point, region


def _closest_pairs(
    geom: ElementGeometry, q: FloatArray, elements: IntArray
) -> tuple[FloatArray, FloatArray, IntArray]:
    corners = geom.corners[elements]
    if geom.dim == 2:
        return _closest_on_segments(q, corners[:, 0], corners[:, 1])
    return _closest_on_triangles(q, corners[:, 0], corners[:, 1], corners[:, 2])


@dataclass(frozen=True)
class ClosestPoints:
    """Result of :func:`closest_points` for n query points."""

    distance: FloatArray  #: unsigned distance to the interface, (n,)
    point: FloatArray  #: closest point on the interface, (n, dim)
    element: IntArray  #: element holding the closest point, (n,)
    region: IntArray  #: feature of that element (see ElementGeometry.pseudo_normals), (n,)
    normal: FloatArray  #: unit (pseudo-)normal at the closest point, (n, dim)
    signed_distance: FloatArray  #: + where the query lies on the biofilm (solid) side, (n,)


def _flatten(lists: Any, n: int) -> tuple[IntArray, IntArray]:
    """Object array of index lists -> (owner, index) pairs."""
    counts = np.fromiter((len(x) for x in lists), dtype=np.intp, count=n)
    flat = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.intp, count=int(counts.sum()))
    return np.repeat(np.arange(n), counts), flat


def _best_per_owner(owner: IntArray, key: FloatArray, n: int) -> IntArray:
    """Position (into ``owner``) of the smallest ``key`` of each owner 0..n-1 (all present)."""
    order = np.lexsort((key, owner))
    first = np.searchsorted(owner[order], np.arange(n))
    return order[first]


def closest_points(geom: ElementGeometry, query: FloatArray, k: int = 8) -> ClosestPoints:
    """Closest point on the interface of ``geom`` to every row of ``query`` (exact).

    The ``k`` elements with the nearest centres give an upper bound ``u`` of the distance;
    where an unvisited element could still be closer (nearest unvisited centre nearer than
    ``u + radius_max``), all elements with centres within that radius are checked.
    """
    q = np.ascontiguousarray(query, dtype=float)
    n, m = len(q), len(geom)
    k = min(k, m)
    dc, idx = geom.tree.query(q, k=k)
    dc = dc.reshape(n, k)
    idx = idx.reshape(n, k)
    if np.any(idx >= m):  # cKDTree's "no neighbour": distances overflowed or were NaN
        row = int(np.flatnonzero(np.any(idx >= m, axis=1))[0])
        raise MeasureError(
            f"no closest point found for the point {q[row].tolist()}: coordinates too large "
            "(or not finite) for float64 distances"
        )
    owner = np.repeat(np.arange(n), k)
    d2, cp, region = _closest_pairs(geom, q[owner], idx.ravel())
    best = _best_per_owner(owner, d2, n)
    dist2, point, elem, reg = d2[best], cp[best], idx.ravel()[best], region[best]
    if k < m:
        ub = np.sqrt(dist2)
        todo = np.flatnonzero(dc[:, -1] - geom.radius_max < ub)
        if len(todo):
            radius = ub[todo] * (1.0 + 1e-12) + geom.radius_max
            lists = geom.tree.query_ball_point(q[todo], radius, return_sorted=False)
            sub_owner, cand = _flatten(lists, len(todo))
            d2b, cpb, regb = _closest_pairs(geom, q[todo][sub_owner], cand)
            pick = _best_per_owner(sub_owner, d2b, len(todo))
            better = d2b[pick] < dist2[todo]
            rows = todo[better]
            pick = pick[better]
            dist2[rows], point[rows] = d2b[pick], cpb[pick]
            elem[rows], reg[rows] = cand[pick], regb[pick]
    dist = np.sqrt(dist2)
    normal = geom.pseudo_normals[elem, reg]
    side = np.einsum("ij,ij->i", q - point, normal)
    signed = np.where(side < 0.0, dist, -dist)  # biofilm side (against the normal) is +
    return ClosestPoints(dist, point, elem, reg, normal, signed)


# -- line intersections ------------------------------------------------------------------------
def _slab_range(
    p: FloatArray, d: FloatArray, lower: FloatArray, upper: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Parameter interval where the lines ``p + t d`` run inside the box ``[lower, upper]``."""
    t0 = np.full(len(p), -np.inf)
    t1 = np.full(len(p), np.inf)
    for ax in range(p.shape[1]):
        da = d[:, ax]
        moving = da != 0.0
        with np.errstate(divide="ignore"):
            ta = (lower[ax] - p[:, ax]) / da
            tb = (upper[ax] - p[:, ax]) / da
        lo = np.where(moving, np.minimum(ta, tb), -np.inf)
        hi = np.where(moving, np.maximum(ta, tb), np.inf)
        outside = ~moving & ((p[:, ax] < lower[ax]) | (p[:, ax] > upper[ax]))
        lo[outside], hi[outside] = np.inf, -np.inf
        t0 = np.maximum(t0, lo)
        t1 = np.minimum(t1, hi)
    return t0, t1


def _line_segment_params(p: FloatArray, d: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Line parameter of the point of segment ``a``-``b`` nearest ``p`` on the line, NaN if none.

    A line collinear with the segment meets it in an interval; its point of smallest
    ``|t|`` is returned.
    """
    e = b - a
    s = a - p
    den = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    elen = np.linalg.norm(e, axis=1)
    num_t = s[:, 0] * e[:, 1] - s[:, 1] * e[:, 0]
    num_u = s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]
    crossing = np.abs(den) > _PARALLEL_TOL * elen
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num_t / den
        u = num_u / den
    t = np.where(crossing & (u >= -_PARAM_TOL) & (u <= 1.0 + _PARAM_TOL), t, np.nan)
    # collinear overlap: the line lies on the segment's line
    scale = np.maximum(elen, np.linalg.norm(s, axis=1))
    collinear = ~crossing & (np.abs(num_u) <= _PARALLEL_TOL * np.maximum(scale, 1e-300))
    if np.any(collinear):
        ta = np.einsum("ij,ij->i", s[collinear], d[collinear])
        tb = np.einsum("ij,ij->i", (b - p)[collinear], d[collinear])
        lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
        t[collinear] = np.where(lo > 0.0, lo, np.where(hi < 0.0, hi, 0.0))
    return t


def _line_triangle_params(
    p: FloatArray, d: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray
) -> FloatArray:
    """Möller–Trumbore line/triangle intersection parameter ``t`` (``p + t d``), NaN if none.

    A line lying in the plane of a triangle does not count as meeting it (its neighbours
    out of that plane, if any, are met at their common edge).
    """
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    ok = np.abs(det) > _PARALLEL_TOL * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        f = 1.0 / det
        s = p - a
        u = f * np.einsum("ij,ij->i", s, h)
        qv = np.cross(s, e1)
        v = f * np.einsum("ij,ij->i", d, qv)
        t = f * np.einsum("ij,ij->i", e2, qv)
    inside = ok & (u >= -_PARAM_TOL) & (v >= -_PARAM_TOL) & (u + v <= 1.0 + _PARAM_TOL)
    return np.where(inside, t, np.nan)


def line_intersections(
    geom: ElementGeometry,
    points: FloatArray,
    directions: FloatArray,
    max_distance: float | None = None,
    prefer: FloatArray | None = None,
    samples_per_chunk: int = 20_000,
) -> FloatArray:
    """Parameter ``t`` of the intersection of smallest ``|t|`` of each line ``p + t d``.

    Parameters
    ----------
    geom
        The interface to intersect (its :class:`ElementGeometry`).
    points, directions
        Lines, shape (n, dim); directions must be unit vectors, so ``|t|`` is a length [mm].
    max_distance
        Only intersections with ``|t| <= max_distance`` count [mm]; ``None``: any.
    prefer
        Where two intersections have the same ``|t|`` with opposite signs, take the one whose
        ``t`` has the sign of ``prefer`` (per line); default: the positive one.
    samples_per_chunk
        Memory bound: lines are processed in groups of at most this many search samples.

    Returns
    -------
    t
        Shape (n,), NaN where the line meets nothing (within ``max_distance``).

    Notes
    -----
    Each line is clipped to the interface's bounding box (and to ``max_distance``) and
    sampled every ``2 radius_max``; the elements with centres within ``2 radius_max`` of a
    sample are all elements that can meet the line piece around it.
    """
    p = np.ascontiguousarray(points, dtype=float)
    d = np.ascontiguousarray(directions, dtype=float)
    n = len(p)
    out = np.full(n, np.nan)
    if n == 0:
        return out
    pref = np.ones(n) if prefer is None else np.where(np.asarray(prefer) < 0.0, -1.0, 1.0)
    pad = 1e-9 * float(np.linalg.norm(geom.upper - geom.lower)) + 1e-12
    t0, t1 = _slab_range(p, d, geom.lower - pad, geom.upper + pad)
    if max_distance is not None:
        t0 = np.maximum(t0, -max_distance)
        t1 = np.minimum(t1, max_distance)
    step = 2.0 * geom.radius_max
    live = np.flatnonzero(t1 >= t0)
    nsamp = np.zeros(n, dtype=np.intp)
    nsamp[live] = np.ceil((t1[live] - t0[live]) / step).astype(np.intp) + 1
    start = 0
    while start < len(live):
        stop = start + 1
        total = nsamp[live[start]]
        while stop < len(live) and total + nsamp[live[stop]] <= samples_per_chunk:
            total += nsamp[live[stop]]
            stop += 1
        rays = live[start:stop]
        start = stop
        owner = np.repeat(rays, nsamp[rays])
        offs = np.arange(len(owner)) - np.repeat(np.cumsum(nsamp[rays]) - nsamp[rays], nsamp[rays])
        tk = np.minimum(t0[owner] + offs * step, t1[owner])
        samples = p[owner] + tk[:, None] * d[owner]
        lists = geom.tree.query_ball_point(samples, step, return_sorted=False)
        sample_idx, elem = _flatten(lists, len(samples))
        if len(elem) == 0:
            continue
        ray = owner[sample_idx]
        key = np.unique(ray.astype(np.int64) * len(geom) + elem)
        ray, elem = key // len(geom), key % len(geom)
        corners = geom.corners[elem]
        if geom.dim == 2:
            t = _line_segment_params(p[ray], d[ray], corners[:, 0], corners[:, 1])
        else:
            t = _line_triangle_params(p[ray], d[ray], corners[:, 0], corners[:, 1], corners[:, 2])
        hit = np.isfinite(t)
        if max_distance is not None:
            hit &= np.abs(t) <= max_distance
        ray, t = ray[hit], t[hit]
        if len(t) == 0:
            continue
        # smallest |t| per ray; on a tie, the sign of `prefer`
        order = np.lexsort((-t * pref[ray], np.abs(t), ray))
        ray_sorted = ray[order]
        first = np.flatnonzero(np.r_[True, ray_sorted[1:] != ray_sorted[:-1]])
        out[ray_sorted[first]] = t[order][first]
    return out


def biofilm_side_sign(directions: FloatArray, normals: FloatArray) -> FloatArray:
    """+1 where ``directions`` point into the fluid (with the normal), -1 where against it."""
    return np.where(np.einsum("ij,ij->i", directions, normals) >= 0.0, 1.0, -1.0)


def cutoff_radius(sigma: float, truncation: float) -> float:
    """Distance beyond which the Gaussian kernel (eq. 10b) is below ``truncation``."""
    if truncation <= 0.0:
        return math.inf
    return sigma * math.sqrt(2.0 * math.log(1.0 / truncation))
