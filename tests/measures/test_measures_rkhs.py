"""The RKHS (surface currents) measure against closed forms (Paper B eq. 10-11, 23).

Notation: an interface is the current ``S = sum_i a_i delta_{c_i}`` (element centres ``c_i``,
area vectors ``a_i``); ``<S, T> = sum_ij k(c_i, d_j) a_i . b_j`` with
``k(x, y) = exp(-|x - y|^2 / (2 sigma^2))`` and ``D^2 = <S1,S1> - 2<S1,S2> + <S2,S2>``.  Under
refinement the sums tend to the continuous ``<S, T> = ∫∫ k(x, y) n(x) . m(y) dx dy``.
"""

import pickle

import numpy as np
import pytest
from scipy.spatial.distance import cdist
from scipy.special import erf, ive

import fbia
from fbia.measures import RkhsMeasure
from fbia.measures.rkhs import Current, currents_product


def gaussian_square_integral(length: float, sigma: float) -> float:
    """``I(L) = ∫_0^L ∫_0^L exp(-(s - t)^2 / (2 sigma^2)) ds dt``.

    With ``u = s - t`` the double integral is ``2 ∫_0^L (L - u) exp(-u^2/(2 sigma^2)) du``,
    and ``∫_0^L exp(-u^2/(2 s^2)) du = s sqrt(pi/2) erf(L / (s sqrt 2))``,
    ``∫_0^L u exp(-u^2/(2 s^2)) du = s^2 (1 - exp(-L^2/(2 s^2)))``, so
    ``I(L) = L s sqrt(2 pi) erf(L / (s sqrt 2)) - 2 s^2 (1 - exp(-L^2 / (2 s^2)))``.
    """
    s = sigma
    return length * s * np.sqrt(2 * np.pi) * erf(length / (s * np.sqrt(2))) - 2 * s * s * (
        1 - np.exp(-(length**2) / (2 * s * s))
    )


def circle(radius: float, n: int, centre=(0.0, 0.0), phase: float = 0.0) -> fbia.Interface:
    """Regular n-gon inscribed in a circle, clockwise: solid inside, normals outward."""
    th = phase - np.arange(n) * 2 * np.pi / n
    return fbia.Interface.polyline(
        np.c_[centre[0] + radius * np.cos(th), centre[1] + radius * np.sin(th)], closed=True
    )


def square(n: int, length: float = 1.0, z: float = 0.0) -> fbia.Interface:
    """[0, L]^2 at height z in 2 n^2 triangles, normals +z."""
    x, y = np.meshgrid(np.linspace(0, length, n + 1), np.linspace(0, length, n + 1), indexing="ij")
    v = np.c_[x.ravel(), y.ravel(), np.full(x.size, z)]
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return fbia.Interface.surface(v, np.vstack([np.c_[a, b, c], np.c_[a, c, d]]))


def rates(errors: list[float]) -> np.ndarray:
    e = np.asarray(errors)
    return np.log2(e[:-1] / e[1:])


def brute_force_product(s: fbia.Interface, t: fbia.Interface, sigma: float, unit=False) -> float:
    """Eq. 11 cross term summed pair by pair with scipy's cdist: an independent reference."""
    a = s.normals if unit else s.area_vectors
    b = t.normals if unit else t.area_vectors
    k = np.exp(-cdist(s.centres, t.centres, "sqeuclidean") / (2 * sigma**2))
    return float(np.sum(k * (a @ b.T)))


def test_parallel_segments_converge_to_the_erf_closed_form_at_second_order():
    """Segments [0, L] x {0} and [0, L] x {d}, both with normal +y.

    ``n . m = 1`` and ``|x - y|^2 = (s - t)^2 + d^2``, so ``<S1,S2> = exp(-d^2/2s^2) I(L)``,
    ``<S1,S1> = <S2,S2> = I(L)`` and ``D^2 = 2 I(L) (1 - exp(-d^2 / (2 sigma^2)))``.  The
    double sum is the tensor midpoint rule of these integrals: error O(h^2).
    """
    length, d, sigma = 1.0, 0.1, 0.2
    exact = 2 * gaussian_square_integral(length, sigma) * (1 - np.exp(-(d**2) / (2 * sigma**2)))
    lower = fbia.Interface.polyline([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]])
    upper = lower.translated([0.0, d])
    measure = RkhsMeasure(sigma_w=sigma)
    errors = []
    for k in range(1, 7):
        obs = fbia.Observation(upper.refined(k))
        errors.append(abs(measure.distance(lower.refined(k), obs) ** 2 - exact) / exact)
    np.testing.assert_allclose(rates(errors)[-3:], 2.0, atol=0.01)
    assert errors[-1] < 3e-5


def test_concentric_circles_converge_to_the_bessel_closed_form_at_second_order():
    """Circles of radii R1, R2, same orientation.

    With ``psi = theta - phi``: ``n . m = cos psi``, ``|x - y|^2 = R1^2 + R2^2 - 2 R1 R2 cos psi``,
    and ``∫_0^{2pi} exp(z cos psi) cos psi dpsi = 2 pi I_1(z)``, so
    ``<S1,S2> = 4 pi^2 R1 R2 exp(-(R1^2+R2^2)/(2 s^2)) I_1(R1 R2 / s^2)
    = 4 pi^2 R1 R2 ive(1, R1 R2 / s^2) exp(-(R1 - R2)^2 / (2 s^2))`` (``ive`` = scaled I_1,
    no overflow).  Inscribed n-gons differ from the circles by O(n^-2).
    """
    r1, r2, sigma = 1.0, 1.1, 0.3

    def product(a, b):
        return (
            4
            * np.pi**2
            * a
            * b
            * ive(1, a * b / sigma**2)
            * np.exp(-((a - b) ** 2) / (2 * sigma**2))
        )

    exact = product(r1, r1) - 2 * product(r1, r2) + product(r2, r2)
    measure = RkhsMeasure(sigma_w=sigma)
    errors = []
    for n in (32, 64, 128, 256):
        d = measure.distance(circle(r1, n), fbia.Observation(circle(r2, n)))
        errors.append(abs(d**2 - exact) / exact)
    np.testing.assert_allclose(rates(errors), 2.0, atol=0.01)
    assert errors[-1] < 2e-4
    assert measure.inner_product(circle(r1, 256), circle(r2, 256)) == pytest.approx(
        product(r1, r2), rel=1e-4
    )


def test_parallel_squares_in_3d_converge_to_the_separable_closed_form():
    """Squares [0, L]^2 at z = 0 and z = d, normals +z.

    The kernel factorises over x, y, z: ``<S1,S2> = exp(-d^2/(2 s^2)) I(L)^2`` and
    ``D^2 = 2 I(L)^2 (1 - exp(-d^2 / (2 sigma^2)))``; the centroid rule on triangles is
    second-order accurate.
    """
    length, d, sigma = 1.0, 0.1, 0.25
    exact = (
        2 * gaussian_square_integral(length, sigma) ** 2 * (1 - np.exp(-(d**2) / (2 * sigma**2)))
    )
    bottom = square(4)
    top = bottom.translated([0.0, 0.0, d])
    measure = RkhsMeasure(sigma_w=sigma)
    errors = []
    for k in range(4):  # 32 ... 2048 triangles
        obs = fbia.Observation(top.refined(k))
        errors.append(abs(measure.distance(bottom.refined(k), obs) ** 2 - exact) / exact)
    np.testing.assert_allclose(rates(errors)[-2:], 2.0, atol=0.02)
    assert errors[-1] < 5e-4


@pytest.mark.parametrize("dim", [2, 3])
def test_identical_interfaces_have_zero_distance(dim):
    gamma = circle(1.0, 200) if dim == 2 else square(12)
    measure = RkhsMeasure(sigma_w=0.1)
    norm = np.sqrt(measure.inner_product(gamma, gamma))
    copy = fbia.Interface(gamma.vertices.copy(), gamma.cells.copy())
    assert measure.distance(copy, fbia.Observation(gamma)) <= 1e-7 * norm  # sqrt(round-off)
    assert not np.any(measure.residuals(gamma, fbia.Observation(gamma)))  # exactly zero


def test_reversed_orientation_flips_the_cross_term():
    """Reversing a curve flips its normals: ``<S1, -S2> = -<S1, S2>``, so
    ``D^2(G1, rev G2) = <S1,S1> + 2<S1,S2> + <S2,S2>``; in particular ``D(G, rev G) = 2|S|``
    and ``D^2(G1, G2) + D^2(G1, rev G2) = 2 (<S1,S1> + <S2,S2>)``."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1.0, 81)
    pts1 = np.c_[x, 0.05 * np.sin(6 * x)]
    pts2 = np.c_[x, 0.05 * np.sin(6 * x + 0.3) + 0.002 * rng.standard_normal(x.size)]
    g1, g2 = fbia.Interface.polyline(pts1), fbia.Interface.polyline(pts2)
    g2_rev = fbia.Interface.polyline(pts2[::-1])
    measure = RkhsMeasure(sigma_w=0.05)
    s11, s22 = measure.inner_product(g1, g1), measure.inner_product(g2, g2)
    s12 = measure.inner_product(g1, g2)
    d_same = measure.distance(g1, fbia.Observation(g2))
    d_rev = measure.distance(g1, fbia.Observation(g2_rev))
    assert d_rev**2 == pytest.approx(s11 + 2 * s12 + s22, rel=1e-12)
    assert d_same**2 + d_rev**2 == pytest.approx(2 * (s11 + s22), rel=1e-12)
    assert measure.distance(g1, fbia.Observation(fbia.Interface.polyline(pts1[::-1]))) == (
        pytest.approx(2 * np.sqrt(s11), rel=1e-12)
    )


def test_remeshing_the_same_curve_changes_the_distance_only_at_second_order():
    """A curve against its own refinement: not zero for the centre-point sums of eq. 11 (the
    quadratures differ), but ``D / |S|`` falls as h^2 for a straight line and a circle."""
    measure = RkhsMeasure(sigma_w=0.2)
    line = fbia.Interface.polyline([[0.0, 0.0], [1.0, 0.3]])
    rel_line, rel_circle = [], []
    for k in range(3, 7):
        coarse = line.refined(k + 1)
        norm = np.sqrt(measure.inner_product(coarse, coarse))
        rel_line.append(measure.distance(coarse, fbia.Observation(coarse.refined(1))) / norm)
        n = 16 * 2**k
        ring = circle(1.0, n)
        norm = np.sqrt(measure.inner_product(ring, ring))
        rel_circle.append(measure.distance(ring, fbia.Observation(circle(1.0, 2 * n))) / norm)
    np.testing.assert_allclose(rates(rel_line), 2.0, atol=0.05)
    np.testing.assert_allclose(rates(rel_circle), 2.0, atol=0.05)
    assert rel_line[-1] < 1e-3 and rel_circle[-1] < 1e-3


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("unit_normals", [False, True])
def test_blocked_truncated_sum_equals_the_brute_force_sum(dim, unit_normals):
    """Block skipping (kernel < 1e-18), tiling, symmetric self-products and the augmented
    matrix product reproduce the plain pairwise sum to 1e-12, for several block sizes."""
    rng = np.random.default_rng(11)
    if dim == 2:
        x = np.linspace(0.0, 3.0, 601)
        g1 = fbia.Interface.polyline(np.c_[x, 0.2 * np.sin(4 * x)])
        g2 = fbia.Interface.polyline(
            np.c_[x, 0.2 * np.sin(4 * x + 0.2)] + 0.001 * rng.random((601, 2))
        )
    else:
        g1 = square(16, length=2.0)
        v = g1.vertices.copy()
        v[:, 2] = 0.1 * np.sin(3 * v[:, 0]) + 0.01 * rng.random(len(v))
        g2 = g1.with_vertices(v)
    sigma = 0.04
    ref12 = brute_force_product(g1, g2, sigma, unit_normals)
    ref11 = brute_force_product(g1, g1, sigma, unit_normals)
    ref22 = brute_force_product(g2, g2, sigma, unit_normals)
    for block in (8, 37, 128):
        m = RkhsMeasure(sigma_w=sigma, unit_normals=unit_normals, block_size=block)
        c1, c2 = m.current(g1), m.current(g2)
        assert currents_product(c1, c2, sigma, m._cutoff) == pytest.approx(ref12, rel=1e-12)
        assert currents_product(c1, c1, sigma, m._cutoff, same=True) == pytest.approx(
            ref11, rel=1e-12
        )
        expected = np.sqrt(ref11 - 2 * ref12 + ref22)
        assert m.distance(g1, fbia.Observation(g2)) == pytest.approx(expected, rel=1e-9)
    skipped = RkhsMeasure(sigma_w=sigma, block_size=8)
    c1 = skipped.current(g1)
    assert c1.n_blocks > 10  # the test exercises block skipping ...
    gap = np.linalg.norm(c1.lower[:, None] - c1.lower[None, :], axis=2)
    assert np.any(gap > skipped._cutoff + 1.0)  # ... some block pairs are far apart


def test_unit_normals_weight_every_element_by_one():
    """``unit_normals=True`` (Paper B Fig. 1c): a polyline with 2 elements of lengths 1 and 3
    on the x axis has ``<S,S> = 1 + 1 + 2 k(c1, c2)`` instead of ``1 + 9 + 6 k(c1, c2)``."""
    gamma = fbia.Interface.polyline([[0.0, 0.0], [1.0, 0.0], [4.0, 0.0]])
    sigma = 1.5
    k12 = np.exp(-(2.0**2) / (2 * sigma**2))  # centres 0.5 and 2.5
    unit = RkhsMeasure(sigma_w=sigma, unit_normals=True)
    area = RkhsMeasure(sigma_w=sigma)
    assert unit.inner_product(gamma, gamma) == pytest.approx(2 + 2 * k12, rel=1e-14)
    assert area.inner_product(gamma, gamma) == pytest.approx(10 + 6 * k12, rel=1e-14)


def test_roundoff_guard_clips_tiny_negatives_and_raises_on_large_ones():
    assert RkhsMeasure._combine(1.0, 1.0 + 1e-14, 1.0) == 0.0
    assert RkhsMeasure._combine(1.0, 0.5, 1.0) == pytest.approx(1.0)
    with pytest.raises(RuntimeError, match="negative beyond round-off"):
        RkhsMeasure._combine(1.0, 1.1, 1.0)


def test_observation_self_product_is_cached_and_pickling_drops_the_cache():
    gamma = circle(1.0, 64)
    obs = fbia.Observation(gamma)
    measure = RkhsMeasure(sigma_w=0.2)
    d1 = measure.distance(circle(1.05, 64), obs)
    cached = measure._observed.get((gamma,), lambda: pytest.fail("self-product recomputed"))
    assert isinstance(cached[0], Current)
    assert measure.distance(circle(1.05, 64), obs) == d1
    clone = pickle.loads(pickle.dumps(measure))
    assert clone.options == measure.options and len(clone._observed) == 0
    assert clone.distance(circle(1.05, 64), obs) == d1


def test_options_are_validated():
    with pytest.raises(fbia.ConfigError, match="sigma_w"):
        fbia.measure("rkhs", sigma_w=0.0)
    with pytest.raises(fbia.ConfigError, match="unknown option 'sigma'"):
        fbia.measure("rkhs", sigma=0.1)
    assert RkhsMeasure().options.sigma_w == 0.005  # Paper B's value


def test_needs_an_observed_interface_of_the_same_dimension():
    obs_points = fbia.Observation(points=[[0.0, 0.0]], directions=[[0.0, 1.0]])
    with pytest.raises(fbia.ConfigError, match="no observed interface"):
        RkhsMeasure().distance(circle(1.0, 8), obs_points)
    with pytest.raises(fbia.ConfigError, match="2-D but observation"):
        RkhsMeasure().distance(circle(1.0, 8), fbia.Observation(square(2)))


# -- the residual vector: D^2 as a sum of squares ---------------------------------------------
@pytest.mark.parametrize(
    ("observed", "simulated", "sigma"),
    [
        (circle(1.0, 128), circle(1.02, 128, phase=0.01), 0.1),
        (circle(1.0, 128), circle(1.0, 128, centre=(0.05, -0.03)), 0.05),
        (square(16), square(12, z=0.05), 0.2),
    ],
    ids=["2-D grown", "2-D shifted", "3-D lifted, other mesh"],
)
def test_residual_vector_norm_is_the_distance(observed, simulated, sigma):
    """k = (pi s^2)^(-d/2) g_s * g_s with s = sigma/sqrt 2: the trapezoidal rule at the
    test points gives D^2 to about 2 exp(-pi^2/(2 spacing^2)) = 1e-8 (spacing 1/2)."""
    measure = RkhsMeasure(sigma_w=sigma)
    obs = fbia.Observation(observed)
    r = measure.residuals(simulated, obs)
    d = measure.distance(simulated, obs)
    assert np.linalg.norm(r) ** 2 == pytest.approx(d**2, rel=1e-7)
    # the length and meaning of the entries are the observation's, not the simulated mesh's
    assert r.shape == measure.residuals(observed, obs).shape
    assert not np.any(measure.residuals(observed, obs))


def test_residual_vector_converges_spectrally_with_the_test_point_spacing():
    observed, simulated = circle(1.0, 256), circle(1.0, 256, centre=(0.03, 0.0))
    obs = fbia.Observation(observed)
    d2 = RkhsMeasure(sigma_w=0.1).distance(simulated, obs) ** 2
    for spacing in (1.0, 0.75, 0.5):
        r = RkhsMeasure(sigma_w=0.1, spacing=spacing).residuals(simulated, obs)
        error = abs(np.linalg.norm(r) ** 2 - d2) / d2
        assert error <= 4 * np.exp(-(np.pi**2) / (2 * spacing**2)), (spacing, error)


def test_residual_vector_sees_the_simulated_interface_within_reach():
    observed = circle(1.0, 128)
    obs = fbia.Observation(observed)
    measure = RkhsMeasure(sigma_w=0.05)  # reach: 2 sigma_w = 0.1 mm
    near, far = circle(1.08, 128), circle(1.6, 128)
    assert np.linalg.norm(measure.residuals(near, obs)) == pytest.approx(
        measure.distance(near, obs), rel=1e-7
    )
    # 0.6 mm away the simulated current lies outside the test points: the vector holds the
    # observed part only, its norm is <S2,S2>^(1/2) < D (documented), distance stays exact
    r_far = np.linalg.norm(measure.residuals(far, obs))
    s22 = measure.inner_product(observed, observed)
    assert r_far == pytest.approx(np.sqrt(s22), rel=1e-6) and r_far < measure.distance(far, obs)
    wider = RkhsMeasure(sigma_w=0.05, reach=0.7)
    assert np.linalg.norm(wider.residuals(far, obs)) == pytest.approx(
        wider.distance(far, obs), rel=1e-7
    )


def test_residuals_distance_option_and_the_test_point_limit():
    obs = fbia.Observation(circle(1.0, 64))
    scalar = RkhsMeasure(sigma_w=0.1, residuals="distance")
    assert scalar.residuals(circle(1.1, 64), obs).tolist() == [
        scalar.distance(circle(1.1, 64), obs)
    ]
    with pytest.raises(fbia.ConfigError, match="needs .* test points .* max_test_points = 100"):
        RkhsMeasure(sigma_w=0.1, max_test_points=100).residuals(circle(1.1, 64), obs)
