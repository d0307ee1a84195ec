"""Synthetic observations (fbia.synthetic_observations): Paper B eq. 16 noise, Paper A points."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import fbia
from fbia.core.synthetic import synthetic_observations

TRUTH = {"E": 400.0, "nu": 0.3}
Q = {"inflow_rate": 100.0}


@pytest.fixture(scope="module")
def m2():
    return fbia.forward_model("analytic_mound_2d", n_points=2001)


@pytest.fixture(scope="module")
def exact(m2):
    return m2.solve(TRUTH, [Q], ".").interface(Q)


def test_top_level_name_is_this_function():
    assert fbia.synthetic_observations is synthetic_observations


def test_zero_noise_gives_the_exact_model_interface(m2, exact):
    coords = [{"inflow_rate": 50.0}, Q]
    obs = synthetic_observations(m2, TRUTH, coords, noise_std=0.0, seed=1, points=7)
    assert [o.coordinate for o in obs] == coords
    assert all(o.noise_std is None for o in obs)
    np.testing.assert_array_equal(obs[1].interface.vertices, exact.vertices)
    np.testing.assert_array_equal(obs[1].interface.cells, exact.cells)
    other = m2.solve(TRUTH, [{"inflow_rate": 50.0}], ".").interface({"inflow_rate": 50.0})
    np.testing.assert_array_equal(obs[0].interface.vertices, other.vertices)
    assert obs[1].name == "synthetic inflow_rate=100"


def test_same_seed_same_data_other_seed_other_data(m2):
    def make(seed):
        return synthetic_observations(m2, TRUTH, [Q], 0.01, seed, points=5)[0]

    a, b, c = make(7), make(np.random.default_rng(7)), make(8)
    np.testing.assert_array_equal(a.interface.vertices, b.interface.vertices)
    np.testing.assert_array_equal(a.measurement_points.points, b.measurement_points.points)
    assert not np.array_equal(a.interface.vertices, c.interface.vertices)
    # a generator is consumed: two calls with the same generator differ
    rng = np.random.default_rng(3)
    first = synthetic_observations(m2, TRUTH, [Q], 0.01, rng)[0].interface.vertices
    second = synthetic_observations(m2, TRUTH, [Q], 0.01, rng)[0].interface.vertices
    assert not np.array_equal(first, second)


def test_normal_noise_lies_along_the_vertex_normals_with_the_given_std(m2, exact):
    sigma = 0.002
    (obs,) = synthetic_observations(m2, TRUTH, [Q], sigma, seed=11)
    assert obs.noise_std is None and obs.coordinate == Q  # sigma_N is the problem's (eq. 5)
    delta = obs.interface.vertices - exact.vertices
    eps = np.einsum("ij,ij->i", delta, exact.vertex_normals)
    np.testing.assert_allclose(delta, eps[:, None] * exact.vertex_normals, atol=1e-15)
    # 2001 draws of N(0, sigma^2): the sample std is within 4 standard errors, mean too
    n = len(eps)
    assert abs(eps.std() / sigma - 1.0) < 4.0 / np.sqrt(2 * n)
    assert abs(eps.mean()) < 4.0 * sigma / np.sqrt(n)
    assert stats.kstest(eps / sigma, "norm").pvalue > 1e-3


def test_isotropic_noise_is_paper_b_eq_16(m2, exact):
    sigma = 0.002
    (obs,) = synthetic_observations(m2, TRUTH, [Q], sigma, seed=12, noise="isotropic")
    delta = obs.interface.vertices - exact.vertices
    n = len(delta)
    for column in delta.T:  # every coordinate: N(0, sigma^2)
        assert abs(column.std() / sigma - 1.0) < 4.0 / np.sqrt(2 * n)
    nx, ny = exact.vertex_normals.T
    tangential = nx * delta[:, 1] - ny * delta[:, 0]  # not only along the normals
    assert abs(tangential.std() / sigma - 1.0) < 4.0 / np.sqrt(2 * n)


def test_measurement_points_are_spread_evenly_with_normal_directions(m2, exact):
    (obs,) = synthetic_observations(m2, TRUTH, [Q], 0.0, seed=0, points=10)
    mp = obs.measurement_points
    assert len(mp) == 10 and mp.dim == 2
    # midpoints of 10 equal arc-length pieces of the exact interface
    seg = np.r_[0.0, np.cumsum(exact.sizes)]
    (curve,) = exact.curves()
    arclength = []
    for p in mp.points:
        d = np.linalg.norm(curve[:-1] - p, axis=1) + np.linalg.norm(curve[1:] - p, axis=1)
        k = int(np.argmin(d - exact.sizes))
        assert d[k] - exact.sizes[k] < 1e-12  # on segment k
        arclength.append(seg[k] + np.linalg.norm(p - curve[k]))
    np.testing.assert_allclose(arclength, (np.arange(10) + 0.5) * exact.measure / 10, rtol=1e-9)
    # directions: unit normals into the fluid, i.e. close to the segment normal there
    np.testing.assert_allclose(np.linalg.norm(mp.directions, axis=1), 1.0)
    near = np.argmin(np.linalg.norm(exact.centres[None] - mp.points[:, None], axis=2), axis=1)
    assert np.all(np.einsum("ij,ij->i", mp.directions, exact.normals[near]) > 0.999)


def test_noisy_points_move_along_their_directions(m2):
    clean = synthetic_observations(m2, TRUTH, [Q], 0.0, seed=0, points=400)[0]
    noisy = synthetic_observations(m2, TRUTH, [Q], 0.01, seed=5, points=400)[0]
    np.testing.assert_array_equal(
        noisy.measurement_points.directions, clean.measurement_points.directions
    )
    delta = noisy.measurement_points.points - clean.measurement_points.points
    eps = np.einsum("ij,ij->i", delta, clean.measurement_points.directions)
    np.testing.assert_allclose(
        delta, eps[:, None] * clean.measurement_points.directions, atol=1e-15
    )
    assert abs(eps.std() / 0.01 - 1.0) < 4.0 / np.sqrt(800)


def test_3d_observations_and_points():
    m3 = fbia.forward_model("analytic_mound_3d", n_rings=6)
    exact = m3.solve(TRUTH, [Q], ".").interface(Q)
    (obs,) = synthetic_observations(m3, TRUTH, [Q], 0.001, seed=2, points=20)
    assert obs.dim == 3 and len(obs.measurement_points) == 20
    delta = obs.interface.vertices - exact.vertices
    eps = np.einsum("ij,ij->i", delta, exact.vertex_normals)
    np.testing.assert_allclose(delta, eps[:, None] * exact.vertex_normals, atol=1e-15)
    clean = synthetic_observations(m3, TRUTH, [Q], 0.0, seed=2, points=20)[0].measurement_points
    # the first point is the crest, the others spread (farthest-point sampling) over vertices
    top = int(np.argmax(exact.vertices[:, 2]))
    np.testing.assert_array_equal(clean.points[0], exact.vertices[top])
    assert len(np.unique(clean.points, axis=0)) == 20
    idx = [int(np.flatnonzero((exact.vertices == p).all(axis=1))[0]) for p in clean.points]
    np.testing.assert_allclose(clean.directions, exact.vertex_normals[idx], atol=1e-15)
    gaps = np.linalg.norm(clean.points[:, None] - clean.points[None], axis=2)
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() > 0.1  # evenly spread: no two points closer than 0.1 mm on a 0.8 mm dome


def test_bad_arguments_and_failed_truth(m2):
    with pytest.raises(fbia.ConfigError, match="noise_std must be a finite number >= 0"):
        synthetic_observations(m2, TRUTH, [Q], -0.1, seed=0)
    with pytest.raises(fbia.ConfigError, match="noise must be 'normal' or 'isotropic'"):
        synthetic_observations(m2, TRUTH, [Q], 0.1, seed=0, noise="points")  # type: ignore[arg-type]
    with pytest.raises(fbia.ConfigError, match="points must be a positive integer"):
        synthetic_observations(m2, TRUTH, [Q], 0.1, seed=0, points=0)
    with pytest.raises(fbia.ConfigError, match="at least one coordinate"):
        synthetic_observations(m2, TRUTH, [], 0.1, seed=0)
    with pytest.raises(fbia.ConfigError, match="value of 'inflow_rate' must be a number"):
        synthetic_observations(m2, TRUTH, [{"inflow_rate": "fast"}], 0.1, seed=0)
    failing = fbia.forward_model("analytic_mound_2d", failure_region={"E": (0.0, 500.0)})
    with pytest.raises(
        fbia.ForwardModelError, match=r"failed at the ground truth .*mesh distortion"
    ):
        synthetic_observations(failing, TRUTH, [Q], 0.1, seed=0)


def test_points_placed_where_the_interface_moved_along_its_normal(m2, exact):
    # Paper A Fig. 3: points "evenly distributed in regions with significant displacement",
    # directions normal to the displaced interface
    obs = synthetic_observations(
        m2, TRUTH, [Q], noise_std=0.0, seed=1, points=10, placement="displacement"
    )[0]
    rest = m2.undeformed()
    u_n = np.abs(np.sum((exact.vertices - rest.vertices) * exact.vertex_normals, axis=1))
    moved = u_n >= 0.5 * u_n.max()
    mp = obs.measurement_points
    assert len(mp) == 10
    # every point lies on an edge whose two ends moved by at least half the largest motion
    nearest = np.argmin(np.linalg.norm(exact.vertices[None] - mp.points[:, None], axis=2), axis=1)
    assert moved[nearest].all()
    assert not moved.all()  # the criterion excludes part of the interface
    np.testing.assert_allclose(np.linalg.norm(mp.directions, axis=1), 1.0, rtol=1e-12)
    # a stricter threshold moves the points to where the interface moved most
    strict = synthetic_observations(
        m2,
        TRUTH,
        [Q],
        noise_std=0.0,
        seed=1,
        points=10,
        placement="displacement",
        significant=0.9,
    )[0]
    sp = strict.measurement_points.points
    near = np.argmin(np.linalg.norm(exact.vertices[None] - sp[:, None], axis=2), axis=1)
    assert (u_n[near] >= 0.85 * u_n.max()).all()
    assert not np.allclose(sp, mp.points)


def test_displacement_placement_needs_the_undeformed_interface(m2):
    class NoRest(fbia.ForwardModelBase):  # the base's undeformed(): none
        def __init__(self, model):
            super().__init__()
            self.model = model

        def parameter_names(self):
            return self.model.parameter_names()

        def solve(self, p, c, w):
            return self.model.solve(p, c, w)

    with pytest.raises(fbia.ConfigError, match="undeformed"):
        synthetic_observations(NoRest(m2), TRUTH, [Q], 0.0, 1, points=5, placement="displacement")
    with pytest.raises(fbia.ConfigError, match="significant"):
        synthetic_observations(m2, TRUTH, [Q], 0.0, 1, points=5, significant=1.5)
    with pytest.raises(fbia.ConfigError, match="placement"):
        synthetic_observations(m2, TRUTH, [Q], 0.0, 1, points=5, placement="random")
    with pytest.raises(fbia.ConfigError, match="give points"):
        synthetic_observations(m2, TRUTH, [Q], 0.0, 1, placement="displacement")
