"""The closest-point-projection measure (Paper B eq. 7) against closed forms.

Sign rule: + for a simulated vertex on the biofilm side of the observed interface (against
its normal, which points from the solid into the fluid), - on the fluid side.
"""

import numpy as np
import pytest

import fbia
from fbia.measures import CppMeasure


def circle(radius: float, n: int, phase: float = 0.0) -> fbia.Interface:
    """Regular n-gon inscribed in a circle, clockwise: solid inside, normals outward."""
    th = phase - np.arange(n) * 2 * np.pi / n
    return fbia.Interface.polyline(radius * np.c_[np.cos(th), np.sin(th)], closed=True)


def grid_plane(n: int, lo: float, hi: float, height=lambda x, y: 0.0 * x) -> fbia.Interface:
    """z = height(x, y) over [lo, hi]^2 in 2 n^2 triangles, normals up (+z side is fluid)."""
    x, y = np.meshgrid(np.linspace(lo, hi, n + 1), np.linspace(lo, hi, n + 1), indexing="ij")
    x, y = x.ravel(), y.ravel()
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return fbia.Interface.surface(
        np.c_[x, y, height(x, y)], np.vstack([np.c_[a, b, c], np.c_[a, c, d]])
    )


def test_concentric_circles_exactly_and_with_the_sign_flipped_when_swapped():
    """Observed n-gon of radius R2, simulated vertices at radius R1 < R2 at the same angles.
    Each edge line lies at R2 cos(pi/n) from the centre, the vertex at R1 cos(pi/n) along the
    edge normal, and the foot of the perpendicular (R1 sin(pi/n) from the edge middle) is
    inside the edge: d = (R2 - R1) cos(pi/n), within (R2 - R1)(1 - cos(pi/n)) of R2 - R1, and
    positive (inside = biofilm).  Swapped, the closest point is the observed vertex itself:
    d = -(R2 - R1) exactly."""
    r1, r2, n = 1.0, 1.2, 64
    inner, outer = circle(r1, n), circle(r2, n)
    d = CppMeasure().residuals(inner, fbia.Observation(outer))
    np.testing.assert_allclose(d, (r2 - r1) * np.cos(np.pi / n), rtol=1e-12)
    assert np.all(np.abs(d - (r2 - r1)) <= (r2 - r1) * (1 - np.cos(np.pi / n)) * (1 + 1e-9))
    swapped = CppMeasure().residuals(outer, fbia.Observation(inner))
    np.testing.assert_allclose(swapped, -(r2 - r1), rtol=1e-12)


def test_circle_at_other_angles_matches_the_foot_point_formula():
    """A vertex at radius R1 and angle t inside the observed n-gon of radius R2: distance to
    the nearest edge R2 cos(pi/n) - R1 cos(t - phi_k), phi_k the direction of that edge's
    middle (nearest odd multiple of pi/n)."""
    r1, r2, n = 1.0, 1.1, 48
    phase = 0.0123
    sim = circle(r1, 200, phase=phase)
    d = CppMeasure().residuals(sim, fbia.Observation(circle(r2, n)))
    t = np.arctan2(sim.vertices[:, 1], sim.vertices[:, 0])
    step = 2 * np.pi / n
    phi = (np.floor(t / step) + 0.5) * step
    np.testing.assert_allclose(d, r2 * np.cos(np.pi / n) - r1 * np.cos(t - phi), rtol=1e-12)


def test_closest_point_inside_a_segment_not_at_a_vertex():
    """Against the single segment (0, 0)-(1, 0) (normal +y) the distances are the heights,
    which the segment end points would get wrong; beyond its end the end point counts."""
    observed = fbia.Interface.polyline([[0.0, 0.0], [1.0, 0.0]])
    simulated = fbia.Interface.polyline([[0.3, -0.2], [0.6, 0.1], [0.5, -0.05], [1.3, 0.4]])
    d = CppMeasure().residuals(simulated, fbia.Observation(observed))
    np.testing.assert_allclose(d, [0.2, -0.1, 0.05, -0.5], atol=1e-15)
    assert CppMeasure().distance(simulated, fbia.Observation(observed)) == pytest.approx(
        np.linalg.norm([0.2, 0.1, 0.05, 0.5]), rel=1e-15
    )


def test_sign_at_sharp_corners_uses_the_pseudo_normal():
    """Tent (0,0)-(1,3)-(2,0), solid below; its segment normals n1 ~ (-3, 1), n2 ~ (3, 1).
    q = apex + 0.1 u with u ~ (2.4, 1) lies in the apex's normal cone (the apex is the closest
    point of both segments) but n1 . u < 0: the element normal of segment 1 would call it
    biofilm, the pseudo-normal n1 + n2 correctly calls it fluid: d = -0.1.  Mirrored point
    likewise.  In the V-shaped valley (0,3)-(1,0)-(2,3) the point apex - 0.1 u lies in the
    solid below the reflex vertex: d = +0.1."""
    u = np.array([2.4, 1.0]) / np.hypot(2.4, 1.0)
    mirror = np.array([-1.0, 1.0])
    tent = fbia.Interface.polyline([[0.0, 0.0], [1.0, 3.0], [2.0, 0.0]])
    apex = np.array([1.0, 3.0])
    q = np.array([apex + 0.1 * u, apex + 0.1 * u * mirror])
    n1 = np.array([-3.0, 1.0])
    assert (q[0] - apex) @ n1 < 0  # the trap the element normal falls into
    d = CppMeasure().residuals(fbia.Interface.polyline(q), fbia.Observation(tent))
    np.testing.assert_allclose(d, [-0.1, -0.1], rtol=1e-12)
    valley = fbia.Interface.polyline([[0.0, 3.0], [1.0, 0.0], [2.0, 3.0]])
    bottom = np.array([1.0, 0.0])
    q = np.array([bottom - 0.1 * u, bottom - 0.1 * u * mirror])
    d = CppMeasure().residuals(fbia.Interface.polyline(q), fbia.Observation(valley))
    np.testing.assert_allclose(d, [0.1, 0.1], rtol=1e-12)


def test_plane_against_tilted_plane_in_3d_both_ways():
    """Observed z = 0 over [0, 1]^2 (normal +z), simulated z = h + s x over [0.2, 0.8]^2:
    d = -(h + s x) (above: fluid).  Swapped (observed tilted plane over [-1, 2]^2, simulated
    flat vertices): d = (h + s x) / sqrt(1 + s^2), positive (below the plane: biofilm)."""
    h, slope = 0.05, 0.3
    flat = grid_plane(4, 0.0, 1.0)
    tilted = grid_plane(5, 0.2, 0.8, lambda x, y: h + slope * x)
    d = CppMeasure().residuals(tilted, fbia.Observation(flat))
    np.testing.assert_allclose(d, -(h + slope * tilted.vertices[:, 0]), atol=1e-14)
    big_tilted = grid_plane(3, -1.0, 2.0, lambda x, y: h + slope * x)
    small_flat = grid_plane(5, 0.2, 0.8)
    d = CppMeasure().residuals(small_flat, fbia.Observation(big_tilted))
    x = small_flat.vertices[:, 0]
    np.testing.assert_allclose(d, (h + slope * x) / np.sqrt(1 + slope**2), atol=1e-14)


def _tent_3d() -> fbia.Interface:
    """A roof: faces x in [0, 1] rising to the ridge x = 1, z = 3, and x in [1, 2] falling,
    y in [0, 1]; normals upward/outward."""
    v = [[0, 0, 0], [1, 0, 3], [2, 0, 0], [0, 1, 0], [1, 1, 3], [2, 1, 0]]
    tri = [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]]
    return fbia.Interface.surface(np.array(v, dtype=float), tri)


def _pyramid() -> fbia.Interface:
    v = [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 1, 3]]
    tri = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
    return fbia.Interface.surface(np.array(v, dtype=float), tri)


def test_sign_at_a_sharp_ridge_and_apex_in_3d():
    """Ridge: as the 2-D tent, at y = 0.5 the closest point lies on the shared edge and the
    edge pseudo-normal (sum of the two face normals) decides.  Apex of a steep pyramid:
    u = 0.9 n_back + 0.1 n_front lies in the apex's normal cone, yet n_front . u < 0; the
    angle-weighted vertex pseudo-normal gives the fluid side.  Both: d = -0.1."""
    tent = _tent_3d()
    assert np.all(tent.normals[:, 2] > 0)
    u = np.array([2.4, 0.0, 1.0]) / np.hypot(2.4, 1.0)
    ridge = np.array([1.0, 0.5, 3.0])
    q = np.array([ridge + 0.1 * u, ridge + 0.1 * u * [-1, 1, 1], ridge + [0.0, 0.2, 0.0]])
    tri = [[0, 1, 2]]
    d = CppMeasure().residuals(fbia.Interface.surface(q, tri), fbia.Observation(tent))
    np.testing.assert_allclose(d, [-0.1, -0.1, 0.0], atol=1e-14)

    pyramid = _pyramid()
    normals = pyramid.normals
    front, back = normals[0], normals[2]  # faces y = 0 side and y = 2 side
    assert front[1] < 0 < back[1]
    u = 0.9 * back + 0.1 * front
    u /= np.linalg.norm(u)
    assert u @ front < 0
    apex = np.array([1.0, 1.0, 3.0])
    q = np.array([apex + 0.1 * u, apex - [0.0, 0.0, 0.5], apex + [0.3, 0.0, 0.0]])
    d = CppMeasure().residuals(fbia.Interface.surface(q, tri), fbia.Observation(pyramid))
    inside = 0.5 / np.hypot(3.0, 1.0)  # from (1, 1, 2.5) to a face of slope 3: 0.5 cos(atan 3)
    assert d[0] == pytest.approx(-0.1, rel=1e-12)
    assert d[1] == pytest.approx(inside, rel=1e-12)
    assert d[2] < 0


def test_region_restricts_the_vertices_and_is_validated():
    observed = fbia.Interface.polyline([[0.0, 0.0], [1.0, 0.0]])
    simulated = fbia.Interface.polyline([[0.1, 0.1], [0.5, -0.2], [0.9, 0.3]])
    d = CppMeasure(region=[[0.3, 0.95], [-1.0, 0.25]]).residuals(
        simulated, fbia.Observation(observed)
    )
    np.testing.assert_allclose(d, [0.2], atol=1e-15)
    with pytest.raises(fbia.ConfigError, match="axis 0: need finite low < high"):
        CppMeasure(region=[[1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(fbia.ConfigError, match="'region' has 3 axes but the interfaces are 2-D"):
        CppMeasure(region=[[0, 1]] * 3).residuals(simulated, fbia.Observation(observed))


def test_needs_an_observed_interface():
    with pytest.raises(fbia.ConfigError, match="no observed interface"):
        CppMeasure().residuals(
            circle(1.0, 8), fbia.Observation(points=[[1.0, 0.0]], directions=[[1.0, 0.0]])
        )


def test_search_is_exact_against_brute_force_on_random_points():
    """The KD-tree candidate search (k nearest centres, then a ball) returns the same
    distances as checking every element, for points near and far from a wavy surface."""
    from fbia.measures._geometry import _closest_on_triangles, closest_points, geometry_of

    rng = np.random.default_rng(2)
    surface = grid_plane(12, 0.0, 1.0, lambda x, y: 0.1 * np.sin(5 * x) * np.cos(4 * y))
    q = np.c_[rng.uniform(-0.3, 1.3, (300, 2)), rng.uniform(-0.5, 0.5, 300)]
    got = closest_points(geometry_of(surface), q).distance
    corners = surface.element_points
    m = len(corners)
    d2, _, _ = _closest_on_triangles(
        np.repeat(q, m, axis=0),
        np.tile(corners[:, 0], (len(q), 1)),
        np.tile(corners[:, 1], (len(q), 1)),
        np.tile(corners[:, 2], (len(q), 1)),
    )
    np.testing.assert_allclose(got, np.sqrt(d2.reshape(len(q), m).min(axis=1)), rtol=1e-13)


def test_closest_point_on_triangles_agrees_with_trimesh():
    """The vectorised region tests against trimesh's independent implementation, for random
    triangles and points in every Voronoi region (vertices, edges, face)."""
    import trimesh

    from fbia.measures._geometry import _closest_on_triangles

    rng = np.random.default_rng(4)
    tri = rng.normal(size=(2000, 3, 3))
    q = rng.normal(scale=2.0, size=(2000, 3))
    d2, point, region = _closest_on_triangles(q, tri[:, 0], tri[:, 1], tri[:, 2])
    expected = trimesh.triangles.closest_point(tri, q)
    np.testing.assert_allclose(point, expected, atol=1e-12)
    np.testing.assert_allclose(d2, np.sum((q - expected) ** 2, axis=1), atol=1e-12)
    assert set(np.unique(region)) == set(range(7))


def test_search_finds_a_long_element_behind_a_cluster_of_near_centres():
    """The closest element need not have one of the nearest centres: a 20 mm segment (centre
    8 mm away) passes 0.3 mm below the point, twenty short segments with centres 0.5 mm away
    lie above it."""
    x = np.linspace(7.0, 9.0, 21)
    observed = fbia.Interface.polylines(
        [[[-10.0, 0.0], [10.0, 0.0]]] + [[[xi, 0.8], [xi + 0.05, 0.8]] for xi in x]
    )
    d = CppMeasure().residuals(
        fbia.Interface.polyline([[8.0, 0.3], [8.0, 0.25]]), fbia.Observation(observed)
    )
    np.testing.assert_allclose(d, [-0.3, -0.25], rtol=1e-14)
