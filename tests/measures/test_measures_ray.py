"""The ray measure (Paper A "Surface distance measure", Paper B eq. 6) against closed forms.

Sign rule: + when the intersection lies on the biofilm side of the observed interface
(against its normal, which points from the solid into the fluid), - towards the fluid.
"""

import numpy as np
import pytest

import fbia
from fbia.measures import RayMeasure


def circle(radius: float, n: int, centre=(0.0, 0.0)) -> fbia.Interface:
    """Regular n-gon inscribed in a circle, clockwise: solid inside, normals outward."""
    th = -np.arange(n) * 2 * np.pi / n
    return fbia.Interface.polyline(
        np.c_[centre[0] + radius * np.cos(th), centre[1] + radius * np.sin(th)], closed=True
    )


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


def convex_line_hits(p, u, normals, offsets):
    """Exact parameters where the line p + t u enters and leaves the convex polytope
    {x : n_f . x <= h_f} (every face a half-space): t_in = max over faces facing the line's
    back of (h - n.p)/(n.u), t_out = min over faces facing forward.  Independent of the
    measure's code; the polytope's boundary points on the line are exactly these two."""
    nu = normals @ u
    gap = offsets - normals @ p
    with np.errstate(divide="ignore"):
        ratio = gap / nu
    return ratio[nu < 0].max(), ratio[nu > 0].min()


def polygon_faces(gamma: fbia.Interface):
    n = gamma.normals
    return n, np.einsum("ij,ij->i", n, gamma.centres)


def flat_line(n: int = 10) -> fbia.Interface:
    x = np.linspace(0.0, 1.0, n + 1)
    return fbia.Interface.polyline(np.c_[x, np.zeros_like(x)])  # solid below y = 0


def test_circle_against_shifted_circle_along_normals():
    """Observed circle of radius R, points R(cos t, sin t), rays along the outward normal;
    simulated circle of radius R centred at (a, 0).  On the line p + s n:
    |(R + s) n - (a, 0)|^2 = R^2  =>  R + s = a cos t ± sqrt(R^2 - a^2 sin^2 t); the root of
    smaller |s| is s = a cos t + sqrt(R^2 - a^2 sin^2 t) - R, and the distance is -s (s > 0
    lies in the fluid).  The simulated n-gon lies between radii R cos(pi/n) and R, so it
    deviates from the circle by at most R (1 - cos(pi/n)) / cos(incidence)."""
    radius, shift, n_sim = 1.0, 0.1, 4096
    theta = np.linspace(0.0, 2 * np.pi, 12, endpoint=False) + 0.1
    normal = np.c_[np.cos(theta), np.sin(theta)]
    points = radius * normal
    obs = fbia.Observation(circle(radius, 256), points=points, directions=normal)
    simulated = circle(radius, n_sim, centre=(shift, 0.0))
    r = RayMeasure().residuals(simulated, obs)
    s = shift * np.cos(theta) + np.sqrt(radius**2 - shift**2 * np.sin(theta) ** 2) - radius
    bound = radius * (1 - np.cos(np.pi / n_sim)) / np.sqrt(1 - (shift / radius) ** 2)
    np.testing.assert_allclose(r, -s, atol=1.01 * bound, rtol=0)
    assert r[0] < 0 < r[6]  # simulated bulges out at theta ~ 0 (fluid), in at theta ~ pi
    # exactly, against the polygon itself
    normals, offsets = polygon_faces(simulated)
    for i in range(len(theta)):
        t_in, t_out = convex_line_hits(points[i], normal[i], normals, offsets)
        exact = t_in if abs(t_in) < abs(t_out) else t_out
        assert r[i] == pytest.approx(-exact, abs=1e-13)
    assert RayMeasure().distance(simulated, obs) == pytest.approx(np.linalg.norm(r), rel=1e-15)


def test_normals_default_to_the_observed_pseudo_normal_at_the_points():
    """At a vertex of a regular polygon the pseudo-normal is exactly radial."""
    observed = circle(1.0, 64)
    obs_given = fbia.Observation(observed, points=observed.vertices, directions=observed.vertices)
    obs_default = fbia.Observation(observed, points=observed.vertices)
    simulated = circle(1.3, 512)
    np.testing.assert_allclose(
        RayMeasure().residuals(simulated, obs_default),
        RayMeasure().residuals(simulated, obs_given),
        atol=1e-14,
    )


def test_vertical_and_oblique_rays_against_a_tilted_line():
    """Observed y = 0 (solid below); simulated y = h + s x.  Vertical rays: d = -(h + s x).
    Rays along (sin a, cos a): t cos a = h + s (x + t sin a)  =>  t = (h + s x)/(cos a - s sin a),
    d = -t.  A ray pointing down gives the same distances (the side comes from the normal)."""
    h, slope, alpha = 0.05, 0.3, 0.4
    x = np.array([0.13, 0.4, 0.77])
    points = np.c_[x, np.zeros_like(x)]
    simulated = fbia.Interface.polyline(
        [[-1.0, h - slope], [0.35, h + 0.35 * slope], [2.0, h + 2 * slope]]
    )
    up = np.tile([0.0, 1.0], (3, 1))
    oblique = np.tile([np.sin(alpha), np.cos(alpha)], (3, 1))
    measure = RayMeasure()
    expected_vertical = -(h + slope * x)
    for directions in (up, -up):
        obs = fbia.Observation(flat_line(), points=points, directions=directions)
        np.testing.assert_allclose(measure.residuals(simulated, obs), expected_vertical, atol=1e-15)
    obs = fbia.Observation(flat_line(), points=points, directions=oblique)
    expected = -(h + slope * x) / (np.cos(alpha) - slope * np.sin(alpha))
    np.testing.assert_allclose(measure.residuals(simulated, obs), expected, atol=1e-15)


def test_without_observed_interface_directions_point_into_the_fluid():
    simulated = fbia.Interface.polyline([[0.0, 0.2], [1.0, 0.2]])
    up = fbia.Observation(points=[[0.5, 0.0]], directions=[[0.0, 1.0]])
    down = fbia.Observation(points=[[0.5, 0.0]], directions=[[0.0, -1.0]])
    assert RayMeasure().residuals(simulated, up) == pytest.approx([-0.2], abs=1e-15)
    assert RayMeasure().residuals(simulated, down) == pytest.approx([0.2], abs=1e-15)


def test_a_ray_that_misses_raises_or_gets_the_penalty():
    simulated = fbia.Interface.polyline([[0.6, 0.2], [1.0, 0.2]])
    obs = fbia.Observation(flat_line(), points=[[0.8, 0.0], [0.3, 0.0]])
    with pytest.raises(fbia.MeasureError, match=r"measurement point 1 at \(0\.3, 0\)"):
        RayMeasure().residuals(simulated, obs)
    np.testing.assert_allclose(
        RayMeasure(miss_penalty=0.5).residuals(simulated, obs), [-0.2, 0.5], atol=1e-15
    )
    # max_distance: the hit at 0.2 is beyond 0.1
    with pytest.raises(fbia.MeasureError, match="within max_distance=0.1 mm"):
        RayMeasure(max_distance=0.1).residuals(
            simulated, fbia.Observation(flat_line(), points=[[0.8, 0.0]])
        )
    near = RayMeasure(max_distance=0.3).residuals(
        simulated, fbia.Observation(flat_line(), points=[[0.8, 0.0]])
    )
    np.testing.assert_allclose(near, [-0.2], atol=1e-15)


def test_several_intersections_take_the_smallest_magnitude():
    """A folded simulated curve meets the vertical line x = 0.5 at y = 0.3, 0.09, -0.12, 0.19,
    0.5; the smallest |t| is 0.09 (fluid side, d = -0.09).  Exact ties prefer the biofilm side."""
    folded = fbia.Interface.polyline(
        [[0.0, 0.3], [1.0, 0.3], [0.0, -0.12], [1.0, -0.12], [0.0, 0.5], [1.0, 0.5]]
    )
    obs = fbia.Observation(flat_line(), points=[[0.5, 0.0]])
    assert RayMeasure().residuals(folded, obs) == pytest.approx([-0.09], abs=1e-15)
    tie = fbia.Interface.polyline([[0.0, 0.1], [1.0, 0.1], [1.0, -0.1], [0.0, -0.1]])
    assert RayMeasure().residuals(tie, obs) == pytest.approx([0.1], abs=1e-15)


def test_a_ray_along_a_simulated_segment_takes_its_nearest_point():
    collinear = fbia.Interface.polyline([[0.5, 0.2], [0.5, 0.6]])
    obs = fbia.Observation(flat_line(), points=[[0.5, 0.0]])
    assert RayMeasure().residuals(collinear, obs) == pytest.approx([-0.2], abs=1e-15)


def test_without_measurement_points_every_observed_element_centre_is_used():
    observed = flat_line(7)
    obs = fbia.Observation(observed)
    r = RayMeasure().residuals(fbia.Interface.polyline([[-1.0, -0.04], [2.0, -0.04]]), obs)
    np.testing.assert_allclose(r, np.full(7, 0.04), atol=1e-15)


def test_bad_observations_are_config_errors():
    simulated = flat_line()
    with pytest.raises(fbia.ConfigError, match="without directions need an observed interface"):
        RayMeasure().residuals(simulated, fbia.Observation(points=[[0.5, 0.0]]))
    tangent = fbia.Observation(flat_line(), points=[[0.5, 0.0]], directions=[[1.0, 0.0]])
    with pytest.raises(fbia.ConfigError, match="direction 0 .* is tangent"):
        RayMeasure().residuals(simulated, tangent)
    with pytest.raises(fbia.ConfigError, match="simulated interface is 3-D"):
        RayMeasure().residuals(grid_plane(2, 0.0, 1.0), fbia.Observation(flat_line()))


def test_plane_against_tilted_plane_in_3d():
    """Observed z = 0 (normal +z), simulated z = h + s x.  Along the normal d = -(h + s x);
    along (sin a, 0, cos a): t = (h + s x) / (cos a - s sin a), d = -t."""
    h, slope, alpha = 0.05, 0.2, 0.3
    rng = np.random.default_rng(5)
    xy = rng.uniform(0.05, 0.95, (40, 2))
    points = np.c_[xy, np.zeros(40)]
    observed = grid_plane(4, 0.0, 1.0)
    simulated = grid_plane(3, -0.5, 1.5, lambda x, y: h + slope * x)
    r = RayMeasure().residuals(simulated, fbia.Observation(observed, points=points))
    np.testing.assert_allclose(r, -(h + slope * xy[:, 0]), atol=1e-14)
    tilt = np.tile([np.sin(alpha), 0.0, np.cos(alpha)], (40, 1))
    r = RayMeasure().residuals(
        simulated, fbia.Observation(observed, points=points, directions=tilt)
    )
    expected = -(h + slope * xy[:, 0]) / (np.cos(alpha) - slope * np.sin(alpha))
    np.testing.assert_allclose(r, expected, atol=1e-14)


def test_sphere_against_a_larger_concentric_sphere():
    """Rays from the vertices of an icosphere of radius R1 (exactly on the sphere) along the
    radial direction u meet a convex polyhedron around the origin where it leaves it:
    rho(u) = min over faces with n.u > 0 of h_f / (n.u) (exact), so d = -(rho(u) - R1);
    rho lies between the in-radius of the polyhedron and R2."""
    import trimesh

    r1, r2 = 1.0, 1.2
    inner = trimesh.creation.icosphere(subdivisions=2, radius=r1)
    outer = trimesh.creation.icosphere(subdivisions=3, radius=r2)
    observed = fbia.Interface.surface(inner.vertices, inner.faces)
    simulated = fbia.Interface.surface(outer.vertices, outer.faces)
    assert np.all(np.einsum("ij,ij->i", observed.normals, observed.centres) > 0)  # outward
    u = observed.vertices / np.linalg.norm(observed.vertices, axis=1)[:, None]
    points = r1 * u
    r = RayMeasure().residuals(simulated, fbia.Observation(observed, points=points, directions=u))
    n, off = simulated.normals, np.einsum("ij,ij->i", simulated.normals, simulated.centres)
    nu = u @ n.T
    with np.errstate(divide="ignore"):
        rho = np.where(nu > 0, off / nu, np.inf).min(axis=1)
    np.testing.assert_allclose(r, -(rho - r1), atol=1e-13)
    assert np.all(-r <= r2 - r1 + 1e-14) and np.all(-r >= off.min() - r1)
    # default rays (element centres along the element normals) land on the outer sphere too
    r_default = RayMeasure().residuals(simulated, fbia.Observation(observed))
    hits = observed.centres + (-r_default)[:, None] * observed.normals
    radii = np.linalg.norm(hits, axis=1)
    assert len(r_default) == len(observed)
    assert np.all(radii <= r2 + 1e-12) and np.all(radii >= off.min() - 1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_line_search_agrees_with_intersecting_every_element(dim):
    """The sampled KD-tree candidate search of line_intersections returns the same smallest
    |t| as testing the line against all elements, for random lines through a wavy interface
    with elements of very different sizes."""
    from fbia.measures._geometry import (
        _line_segment_params,
        _line_triangle_params,
        geometry_of,
        line_intersections,
    )

    rng = np.random.default_rng(8)
    if dim == 2:
        x = np.sort(np.r_[0.0, 2.0, rng.uniform(0.0, 2.0, 150)])
        gamma = fbia.Interface.polyline(np.c_[x, 0.2 * np.sin(5 * x)])
    else:
        gamma = grid_plane(10, 0.0, 2.0, lambda x, y: 0.2 * np.sin(3 * x) * np.cos(2 * y))
        v = gamma.vertices.copy()
        v[:, :2] += rng.uniform(-0.05, 0.05, (len(v), 2)) * (v[:, :2] % 2.0 != 0)
        gamma = gamma.with_vertices(v)
    n = 200
    p = np.c_[rng.uniform(0.0, 2.0, (n, dim - 1)), rng.uniform(-0.5, 0.5, n)]
    d = rng.normal(size=(n, dim))
    d[:, -1] += 2.0 * np.sign(d[:, -1])  # mostly steep lines, some shallow
    d /= np.linalg.norm(d, axis=1)[:, None]
    got = line_intersections(geometry_of(gamma), p, d)
    corners = gamma.element_points
    m = len(corners)
    pp, dd = np.repeat(p, m, axis=0), np.repeat(d, m, axis=0)
    cc = np.tile(corners, (n, 1, 1))
    if dim == 2:
        t = _line_segment_params(pp, dd, cc[:, 0], cc[:, 1])
    else:
        t = _line_triangle_params(pp, dd, cc[:, 0], cc[:, 1], cc[:, 2])
    t = t.reshape(n, m)
    with np.errstate(invalid="ignore"):
        best = np.where(np.isnan(t), np.inf, np.abs(t)).min(axis=1)
    expected = np.where(np.isfinite(best), best, np.nan)
    assert np.sum(np.isfinite(expected)) > n // 2
    np.testing.assert_allclose(np.abs(got), expected, rtol=1e-12)
