"""The core data types: Interface, MeasurementPoints, priors, Parameter, Observation,
InverseProblem (validation and the outcomes of ``evaluate`` with the analytic mound model)."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import meshio
import numpy as np
import pytest
from scipy import integrate, special, stats

import fbia
from fbia.core.interface import Interface

# -- helpers -----------------------------------------------------------------------------------


def _tetrahedron() -> Interface:
    """Closed unit tetrahedron surface with outward (solid -> fluid) normals."""
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return Interface.surface(v, t)


def _dome(n_rings: int = 3) -> Interface:
    return fbia.forward_model("analytic_mound_3d", n_rings=n_rings).undeformed()


def _facets(gamma: Interface) -> np.ndarray:
    """Order-independent, orientation-sensitive description: rows (centre, area vector)."""
    rows = np.c_[gamma.centres, gamma.area_vectors]
    return rows[np.lexsort(rows.T[::-1])]


# -- Interface: orientation and sizes ------------------------------------------------------------


def test_polyline_normals_are_the_tangent_turned_by_plus_90_degrees():
    # eq. 24b: walking with the solid on the right, the normal points left (into the fluid)
    pts = np.array([[0.0, 1.0], [0.0, 0.0], [2.0, 0.0]])  # down the wall, then along the floor
    gamma = Interface.polyline(pts)
    np.testing.assert_allclose(gamma.normals, [[1.0, 0.0], [0.0, 1.0]], atol=1e-15)
    np.testing.assert_allclose(gamma.sizes, [1.0, 2.0])
    # vertex normal at the corner: length-weighted mean of (1, 0) and (0, 1)
    np.testing.assert_allclose(gamma.vertex_normals[1], np.array([1.0, 2.0]) / math.sqrt(5.0))
    reverse = Interface.polyline(pts[::-1])
    np.testing.assert_allclose(reverse.normals, -gamma.normals[::-1], atol=1e-15)


def test_clockwise_closed_curve_has_outward_normals_and_encloses_its_area():
    square = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])  # clockwise
    gamma = Interface.polyline(square, closed=True)
    assert len(gamma) == 4 and gamma.measure == pytest.approx(4.0)
    outward = np.sign(gamma.centres - 0.5) * (np.abs(gamma.centres - 0.5) > 0.25)
    np.testing.assert_allclose(gamma.normals, outward, atol=1e-15)
    # divergence theorem: area = 1/2 sum c . a (eq. 24b normals point out of the solid)
    area = 0.5 * np.einsum("ij,ij->", gamma.centres, gamma.area_vectors)
    assert area == pytest.approx(1.0)


def test_triangle_normals_follow_the_right_hand_rule_and_areas():
    tri = Interface.surface([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0, 1, 2]])
    np.testing.assert_allclose(tri.normals, [[0.0, 0.0, 1.0]])
    assert tri.sizes[0] == pytest.approx(1.0)
    flipped = Interface.surface(tri.vertices, [[0, 2, 1]])
    np.testing.assert_allclose(flipped.normals, [[0.0, 0.0, -1.0]])


def test_closed_surface_area_vectors_sum_to_zero_and_give_the_volume():
    tet = _tetrahedron()
    np.testing.assert_allclose(tet.area_vectors.sum(axis=0), 0.0, atol=1e-15)
    assert np.einsum("ij,ij->", tet.centres, tet.area_vectors) / 3.0 == pytest.approx(1.0 / 6.0)
    assert tet.measure == pytest.approx(1.5 + math.sqrt(3.0) / 2.0)
    # outward: every normal points away from the centroid
    assert np.all(np.einsum("ij,ij->i", tet.normals, tet.centres - 0.25) > 0)


@pytest.mark.parametrize("times", [1, 2, 3])
def test_refined_polyline_keeps_geometry_and_measure(times):
    x = np.linspace(0.0, 2.0, 7)
    gamma = Interface.polyline(np.c_[x, np.sin(x)])
    fine = gamma.refined(times)
    assert len(fine) == len(gamma) * 2**times
    assert fine.measure == pytest.approx(gamma.measure, rel=1e-14)
    # every new vertex lies on the old polyline, the end points are unchanged
    poly = gamma.to_shapely()
    import shapely

    assert np.max(shapely.distance(shapely.points(fine.vertices), poly)) < 1e-14
    (curve,) = fine.curves()
    np.testing.assert_array_equal(curve[[0, -1]], gamma.vertices[[0, -1]])


def test_refined_surface_keeps_geometry_measure_and_orientation():
    dome = _dome(3)
    fine = dome.refined(2)
    assert len(fine) == 16 * len(dome)
    assert fine.measure == pytest.approx(dome.measure, rel=1e-13)
    np.testing.assert_allclose(
        fine.area_vectors.sum(axis=0), dome.area_vectors.sum(axis=0), atol=1e-14
    )
    # each child triangle has the normal of its parent: the set of normals is unchanged
    parents = {tuple(np.round(n, 10)) for n in dome.normals}
    assert {tuple(np.round(n, 10)) for n in fine.normals} <= parents


def test_curves_round_trip_several_open_and_closed_polylines():
    a = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    b = np.array([[3.0, 0.0], [3.5, 1.0], [4.0, 0.0], [4.5, 0.2]])
    two = Interface.polylines([a, b])
    got = two.curves()
    assert len(got) == 2
    np.testing.assert_array_equal(got[0], a)
    np.testing.assert_array_equal(got[1], b)
    ring = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])
    closed = Interface.polylines([ring, ring + 3.0], closed=True)
    got = closed.curves()
    assert len(got) == 2
    for curve, pts in zip(got, [ring, ring + 3.0], strict=True):
        np.testing.assert_array_equal(curve, np.vstack([pts, pts[:1]]))  # closed: repeats start
    assert Interface.polylines(got, closed=False).measure == pytest.approx(closed.measure)


# -- Interface: files ----------------------------------------------------------------------------


def test_csv_round_trip_is_exact_with_header_and_curve_ids(tmp_path):
    rng = np.random.default_rng(5)
    a = np.c_[np.sort(rng.uniform(0, 1, 9)), rng.uniform(0, 1, 9)]
    b = np.c_[np.sort(rng.uniform(2, 3, 5)), rng.uniform(0, 1, 5)]
    ring = np.array([[5.0, 0.0], [5.0, 1.0], [6.0, 1.0], [6.0, 0.0]])
    gamma = Interface.polylines([a, b])
    path = gamma.write(tmp_path / "gamma.csv")
    lines = path.read_text().splitlines()
    assert lines[0] == "x,y,curve"
    assert [ln.rsplit(",", 1)[1] for ln in lines[1:]] == ["0"] * 9 + ["1"] * 5
    back = Interface.read(path)
    np.testing.assert_array_equal(back.vertices, gamma.vertices)  # repr(): bit-exact
    np.testing.assert_array_equal(back.cells, gamma.cells)
    # a closed curve comes back closed (its repeated start point is not duplicated)
    loop = Interface.polylines([ring], closed=True)
    back = Interface.read(loop.write(tmp_path / "loop.csv"))
    np.testing.assert_array_equal(back.vertices, loop.vertices)
    np.testing.assert_array_equal(back.cells, loop.cells)


def test_csv_without_header_or_curve_column_reads_as_one_polyline(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("0.0, 0.0\n0.5, 0.25\n1.0, 0.0\n")
    gamma = Interface.read(path)
    assert gamma.dim == 2 and len(gamma) == 2
    np.testing.assert_array_equal(gamma.vertices[1], [0.5, 0.25])


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # meshio's STL sniffing
@pytest.mark.parametrize("suffix", [".vtu", ".vtk", ".ply", ".obj", ".stl"])
def test_surface_round_trip_through_meshio_is_exact(tmp_path, suffix):
    dome = fbia.forward_model("analytic_mound_3d", n_rings=3).solve(
        {"E": 300.0, "nu": 0.1}, [{"inflow_rate": 80.0}], tmp_path
    )
    gamma = dome.interface({"inflow_rate": 80.0})
    back = Interface.read(gamma.write(tmp_path / f"dome{suffix}"))
    assert back.dim == 3 and len(back) == len(gamma)
    # binary (vtu, vtk, ply) stores float64, ascii (obj, stl) writes repr(): all bit-exact
    np.testing.assert_array_equal(_facets(back), _facets(gamma))
    np.testing.assert_array_equal(
        np.unique(back.vertices, axis=0), np.unique(gamma.vertices, axis=0)
    )
    if suffix != ".stl":  # STL has no shared vertices: the reader may renumber them
        np.testing.assert_array_equal(back.vertices, gamma.vertices)
        np.testing.assert_array_equal(back.cells, gamma.cells)


def test_binary_stl_reads_to_float32_precision(tmp_path):
    gamma = _dome(3)
    path = tmp_path / "dome.stl"
    meshio.Mesh(gamma.vertices, [("triangle", gamma.cells)]).write(path, binary=True)
    back = Interface.read(path)
    assert len(back) == len(gamma)
    np.testing.assert_allclose(_facets(back), _facets(gamma), atol=1e-7)


def test_2d_interface_writes_vtu_as_lines(tmp_path):
    gamma = Interface.polyline([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]])
    mesh = meshio.read(gamma.write(tmp_path / "gamma.vtu"))
    np.testing.assert_array_equal(mesh.points[:, :2], gamma.vertices)
    np.testing.assert_array_equal(mesh.cells_dict["line"], gamma.cells)


@pytest.mark.parametrize(
    ("vertices", "cells", "message"),
    [
        ([[0.0, 0.0], [np.nan, 1.0]], [[0, 1]], "NaN or infinite"),
        ([0.0, 1.0, 2.0], [[0, 1]], r"shape \(n, 2\) or \(n, 3\), got \(3,\)"),
        ([[0.0, 0.0], [1.0, 1.0]], [[0, 1, 1]], r"cells of shape \(m, 2\), got \(1, 3\)"),
        ([[0.0, 0.0], [1.0, 1.0], [1.0, 1.0]], [[0, 1], [1, 2]], "1 element.s. of zero length"),
        ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], "1 element.s. of zero area"),
        ([[0.0, 0.0], [1.0, 1.0]], [[0, 2]], "refer to vertices that do not exist"),
        ([[0.0, 0.0], [1.0, 1.0]], np.zeros((0, 2)), "no elements"),
    ],
)
def test_invalid_interfaces_are_config_errors(vertices, cells, message):
    with pytest.raises(fbia.ConfigError, match=message):
        Interface(vertices, cells)


def test_file_errors_name_the_file(tmp_path):
    missing = tmp_path / "nowhere.csv"
    with pytest.raises(fbia.ConfigError, match=rf"^{missing}: file not found$"):
        Interface.read(missing)
    odd = tmp_path / "gamma.xyz"
    odd.write_text("0 0\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{odd}: unknown interface file type '.xyz'"):
        Interface.read(odd)
    nan = tmp_path / "nan.csv"
    nan.write_text("x,y\n0,0\n1,nan\n2,0\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{nan}: line 3: NaN or infinite value$"):
        Interface.read(nan)
    text = tmp_path / "text.csv"
    text.write_text("x,y\n0,0\n1,one\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{text}: line 3: .one. is not a number"):
        Interface.read(text)
    wide = tmp_path / "wide.csv"
    wide.write_text("0,0,0,0\n1,1,0,0\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{wide}: line 1: expected 2 or 3 columns \("):
        Interface.read(wide)
    dup = tmp_path / "dup.csv"
    dup.write_text("0,0\n1,1\n1,1\n2,0\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{dup}: interface has 1 element.s. of zero len"):
        Interface.read(dup)
    empty = tmp_path / "empty.csv"
    empty.write_text("x,y\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{empty}: no data rows after the header"):
        Interface.read(empty)
    broken = tmp_path / "broken.stl"
    broken.write_text("this is not a mesh\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{broken}: "):
        Interface.read(broken)
    with pytest.raises(fbia.ConfigError, match=r"dome.csv: CSV output is for 2-D"):
        _dome(2).write(tmp_path / "dome.csv")


# -- MeasurementPoints ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "dim", "directions"),
    [
        ("x,y\n0,1\n2,3\n", 2, None),
        ("0,1,2\n3,4,5\n", 3, None),
        ("x,y,dx,dy\n0,1,0,2\n2,3,3,4\n", 2, [[0.0, 1.0], [0.6, 0.8]]),
        ("0,1,2,0,0,5\n3,4,5,2,0,0\n", 3, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
    ],
)
def test_measurement_points_read_2_3_4_6_columns(tmp_path, text, dim, directions):
    path = tmp_path / "mp.csv"
    path.write_text(text)
    mp = fbia.MeasurementPoints.read(path)
    assert mp.dim == dim and len(mp) == 2
    if directions is None:
        assert mp.directions is None
    else:
        np.testing.assert_allclose(mp.directions, directions)  # normalised to unit length
    back = fbia.MeasurementPoints.read(mp.write(tmp_path / "again.csv"))
    np.testing.assert_array_equal(back.points, mp.points)
    if directions is not None:
        np.testing.assert_array_equal(back.directions, mp.directions)


def test_measurement_points_errors_name_file_and_row(tmp_path):
    path = tmp_path / "mp.csv"
    path.write_text("x,y,dx,dy\n0,1,0,1\n2,nan,0,1\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{path}: line 3: NaN or infinite value$"):
        fbia.MeasurementPoints.read(path)
    path.write_text("0,1,2,3,4\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{path}: line 1: expected 2, 3, 4 or 6 columns"):
        fbia.MeasurementPoints.read(path)
    path.write_text("0,1,0,0\n")
    with pytest.raises(fbia.ConfigError, match=rf"^{path}: measurement direction 0 is zero$"):
        fbia.MeasurementPoints.read(path)
    with pytest.raises(fbia.ConfigError, match="file not found"):
        fbia.MeasurementPoints.read(tmp_path / "missing.csv")


# -- priors --------------------------------------------------------------------------------------


def test_uniform_prior_moments_and_support():
    p = fbia.priors.uniform(100.0, 800.0)
    assert p.support == (100.0, 800.0)
    assert p.mean == pytest.approx(450.0)
    assert p.std == pytest.approx(700.0 / math.sqrt(12.0))
    assert p.pdf(300.0) == pytest.approx(1.0 / 700.0)
    assert p.logpdf(900.0) == -np.inf


def test_normal_and_truncated_normal_priors_against_closed_forms():
    n = fbia.priors.normal(1.0, 2.0)
    assert (n.mean, n.std, n.mode) == (pytest.approx(1.0), pytest.approx(2.0), 1.0)
    assert n.support == (-math.inf, math.inf)
    mu, sd, lo, hi = 0.3, 0.2, -0.8, 0.5
    t = fbia.priors.truncated_normal(mu, sd, lo, hi)
    a, b = (lo - mu) / sd, (hi - mu) / sd
    z = stats.norm.cdf(b) - stats.norm.cdf(a)
    pa, pb = stats.norm.pdf(a), stats.norm.pdf(b)
    mean = mu + sd * (pa - pb) / z
    var = sd**2 * (1 + (a * pa - b * pb) / z - ((pa - pb) / z) ** 2)
    assert t.support == pytest.approx((lo, hi))
    assert t.mean == pytest.approx(mean, rel=1e-12)
    assert t.std == pytest.approx(math.sqrt(var), rel=1e-10)
    assert t.mode == mu


def test_lognormal_prior_is_parametrised_by_the_moments_of_log_x():
    # Paper B: LN(E | mu_ln = 5.86, sigma_ln = 0.4), mode near 300 Pa
    p = fbia.priors.lognormal(5.86, 0.4)
    assert float(p.ppf(0.5)) == pytest.approx(math.exp(5.86))  # median e^mu_ln
    assert p.mean == pytest.approx(math.exp(5.86 + 0.08))
    assert p.std == pytest.approx(math.sqrt((math.exp(0.16) - 1.0) * math.exp(2 * 5.86 + 0.16)))
    assert p.mode == pytest.approx(math.exp(5.86 - 0.16))
    assert p.mode == pytest.approx(300.0, abs=2.0)
    assert p.support == (0.0, math.inf)


def test_bounds_truncate_a_prior_that_reaches_beyond_them():
    # Paper B's informed E prior LN(5.86, 0.4) on the design box [100, 800] Pa: the bounds are
    # hard, so the prior is the lognormal conditioned on them (about 2 % of its mass is cut)
    full = fbia.priors.lognormal(5.86, 0.4)
    E = fbia.Parameter("E", bounds=(100.0, 800.0), prior=full)
    p = E.prior
    assert p.truncation == (100.0, 800.0) and p.support == (100.0, 800.0)
    mass = float(full.dist.cdf(800.0) - full.dist.cdf(100.0))
    assert 0.975 < mass < 0.985
    x = np.array([150.0, 300.0, 799.0])
    np.testing.assert_allclose(p.logpdf(x), full.logpdf(x) - math.log(mass), rtol=1e-12)
    assert p.logpdf(900.0) == -np.inf and p.logpdf(90.0) == -np.inf
    assert integrate.quad(p.pdf, 100.0, 800.0)[0] == pytest.approx(1.0, rel=1e-9)
    mean = integrate.quad(lambda t: t * full.pdf(t), 100.0, 800.0)[0] / mass
    assert p.mean == pytest.approx(mean, rel=1e-9)
    np.testing.assert_allclose(p.ppf([0.0, 1.0]), [100.0, 800.0], rtol=1e-9)
    u = np.array([0.1, 0.5, 0.9])  # ppf inverts the truncated CDF
    lo = float(full.dist.cdf(100.0))
    np.testing.assert_allclose(p.ppf(u), full.ppf(lo + u * mass), rtol=1e-8)
    draws = p.rvs(4000, np.random.default_rng(1))
    assert draws.min() >= 100.0 and draws.max() <= 800.0
    np.testing.assert_array_equal(draws, p.rvs(4000, np.random.default_rng(1)))
    assert p.mode == full.mode and p.spec() == full.spec()
    again = pickle.loads(pickle.dumps(E))  # process pools ship parameters
    assert again == E and again.prior.ppf(0.5) == p.ppf(0.5)
    # a prior inside its bounds is kept as it is; one without mass inside them is an error
    beta = fbia.priors.beta(2.0, 2.0, lower=-0.8, upper=0.5)
    assert fbia.Parameter("nu", bounds=(-0.8, 0.5), prior=beta).prior is beta
    cut = fbia.Parameter("nu", bounds=(-0.5, 0.45), prior=beta).prior
    assert cut.truncation == (-0.5, 0.45) and cut.std < beta.std
    with pytest.raises(fbia.ConfigError, match=r"^E: the normal prior has no mass inside"):
        fbia.Parameter("E", bounds=(100.0, 800.0), prior=fbia.priors.normal(-1e6, 1.0))


def test_paper_b_beta_prior_on_poisson_ratio():
    # Paper B: B(nu | 43/13, 22/13) on [-0.8, 0.5]; its mode is -0.8 + 1.3 (30/13)/(39/13) = 0.2
    a, b = 43 / 13, 22 / 13
    p = fbia.priors.beta(a, b, lower=-0.8, upper=0.5)
    assert p.support == pytest.approx((-0.8, 0.5))
    assert p.mode == pytest.approx(0.2)
    assert p.mean == pytest.approx(-0.8 + 1.3 * a / (a + b))  # = 0.06
    assert p.std == pytest.approx(1.3 * math.sqrt(a * b / ((a + b) ** 2 * (a + b + 1))))
    x = 0.1
    u = (x + 0.8) / 1.3
    expected = u ** (a - 1) * (1 - u) ** (b - 1) / special.beta(a, b) / 1.3
    assert p.pdf(x) == pytest.approx(expected)
    # the grid maximum of the density is at the mode
    grid = np.linspace(-0.79, 0.49, 12801)
    assert grid[np.argmax(p.pdf(grid))] == pytest.approx(0.2, abs=1e-4)


def test_prior_rvs_and_ppf_are_reproducible_and_inside_the_support():
    p = fbia.priors.beta(2.6, 1.4, lower=0.0, upper=110.0)  # Paper B's inflow-rate prior
    assert p.mode == pytest.approx(88.0)
    x1 = p.rvs(1000, np.random.default_rng(3))
    x2 = p.rvs(1000, np.random.default_rng(3))
    np.testing.assert_array_equal(x1, x2)
    assert x1.min() >= 0.0 and x1.max() <= 110.0
    np.testing.assert_allclose(p.ppf([0.0, 1.0]), [0.0, 110.0])


def test_prior_from_spec_builds_each_kind_and_rejects_bad_specs():
    assert fbia.Prior.from_spec({"distribution": "normal", "mean": 1, "std": 2}).mean == 1.0
    u = fbia.Prior.from_spec({"distribution": "uniform"}, bounds=(100.0, 800.0))
    assert u.support == (100.0, 800.0)
    beta = fbia.Prior.from_spec({"distribution": "beta", "a": 2, "b": 3})
    assert beta.support == (0.0, 1.0)
    ln = fbia.Prior.from_spec({"distribution": "lognormal", "mu_ln": 0.0, "sigma_ln": 1.0})
    assert ln.spec() == {"distribution": "lognormal", "mu_ln": 0.0, "sigma_ln": 1.0}
    with pytest.raises(fbia.ConfigError, match=r"^distribution: unknown distribution 'gamma'; "):
        fbia.Prior.from_spec({"distribution": "gamma", "k": 1})
    with pytest.raises(fbia.ConfigError, match=r"unknown key\(s\) sigma for a normal prior"):
        fbia.Prior.from_spec({"distribution": "normal", "mean": 1, "sigma": 2})
    with pytest.raises(fbia.ConfigError, match=r"truncated_normal prior needs lower, upper"):
        fbia.Prior.from_spec({"distribution": "truncated_normal", "mean": 1, "std": 2})
    with pytest.raises(fbia.ConfigError, match="must be numbers"):
        fbia.Prior.from_spec({"distribution": "normal", "mean": "one", "std": 2})
    with pytest.raises(fbia.ConfigError, match="std > 0"):
        fbia.Prior.from_spec({"distribution": "normal", "mean": 1, "std": 0})
    with pytest.raises(fbia.ConfigError, match="lower < upper"):
        fbia.priors.uniform(1.0, 1.0)


# -- Parameter -----------------------------------------------------------------------------------


def test_parameter_defaults_and_validation():
    p = fbia.Parameter("E", bounds=(100, 800), unit="Pa", initial=400)
    assert p.bounds == (100.0, 800.0) and p.prior.kind == "uniform" and p.initial == 400.0
    nu = fbia.Parameter("nu", prior=fbia.priors.beta(2.0, 2.0, lower=-0.8, upper=0.5))
    assert nu.bounds == pytest.approx((-0.8, 0.5))  # from the prior's finite support
    free = fbia.Parameter("E", prior=fbia.priors.lognormal(5.86, 0.4))
    assert free.bounds is None and (free.lower, free.upper) == (-math.inf, math.inf)
    with pytest.raises(fbia.ConfigError, match=r"^E: lower bound 800.0 is not below upper"):
        fbia.Parameter("E", bounds=(800, 100))
    with pytest.raises(fbia.ConfigError, match=r"^nu: initial guess 0.7 lies outside bounds"):
        fbia.Parameter("nu", bounds=(-0.8, 0.5), initial=0.7)
    with pytest.raises(fbia.ConfigError, match=r"^E: bounds must be finite"):
        fbia.Parameter("E", bounds=(0, math.inf))
    with pytest.raises(fbia.ConfigError, match=r"^E: initial guess must be finite"):
        fbia.Parameter("E", bounds=(1, 2), initial=math.nan)
    with pytest.raises(fbia.ConfigError, match="must be a non-empty identifier"):
        fbia.Parameter("E modulus")
    assert fbia.Parameter("E", bounds=(1, 2)).describe()["prior"] == {
        "distribution": "uniform",
        "lower": 1.0,
        "upper": 2.0,
    }


# -- Observation and Solution --------------------------------------------------------------------


def test_observation_validation():
    line = Interface.polyline([[0.0, 0.0], [1.0, 0.0]])
    obs = fbia.Observation(line, {"inflow_rate": 100}, points=[[0.5, 0.0]], directions=[[0, 2]])
    assert obs.coordinate == {"inflow_rate": 100.0}
    np.testing.assert_array_equal(obs.measurement_points.directions, [[0.0, 1.0]])
    assert obs.key == fbia.coordinate_key({"inflow_rate": 100.0})
    assert obs.label() == "inflow_rate=100" and obs.dim == 2
    with pytest.raises(fbia.ConfigError, match="needs an interface, measurement points or both"):
        fbia.Observation(coordinate={"inflow_rate": 1.0})
    with pytest.raises(fbia.ConfigError, match="mixes a 2-D interface with 3-D points"):
        fbia.Observation(line, points=[[0.0, 0.0, 0.0]])
    with pytest.raises(fbia.ConfigError, match="noise_std must be a positive number, got 0"):
        fbia.Observation(line, noise_std=0)
    with pytest.raises(fbia.ConfigError, match=r"value of 'time' must be a number, got 'late'"):
        fbia.Observation(line, {"time": "late"})
    with pytest.raises(fbia.ConfigError, match=r"value of 'time' is not finite"):
        fbia.Observation(line, {"time": math.inf})
    with pytest.raises(fbia.ConfigError, match="directions must have the points' shape"):
        fbia.Observation(line, points=[[0.5, 0.0]], directions=[[0.0, 1.0, 0.0]])


def test_coordinate_key_is_order_independent_and_solution_lookup():
    assert fbia.coordinate_key({"b": 1, "a": 2}) == fbia.coordinate_key({"a": 2.0, "b": 1.0})
    line = Interface.polyline([[0.0, 0.0], [1.0, 0.0]])
    sol = fbia.Solution.from_pairs([({"inflow_rate": 50}, line)])
    assert sol.interface({"inflow_rate": 50.0}) is line
    assert sol.covers([{"inflow_rate": 50.0}]) and not sol.covers([{"inflow_rate": 60.0}])
    with pytest.raises(KeyError, match=r"no interface for coordinate \{'inflow_rate': 60.0\}"):
        sol.interface({"inflow_rate": 60.0})


# -- InverseProblem ------------------------------------------------------------------------------


class _VertexMeasure(fbia.MeasureBase):
    """Local test measure (not registered): vertex-wise differences of equal meshes.

    ``residuals`` are the coordinate differences of the simulated and the observed vertices
    (the analytic model keeps its connectivity); it raises MeasureError for a mesh of another
    size and a plain RuntimeError (a "bug") when asked to, to exercise every outcome.
    """

    def __init__(self, bug: bool = False) -> None:
        super().__init__()
        self.bug = bug

    def residuals(self, simulated: Interface, observation: fbia.Observation) -> np.ndarray:
        if self.bug:
            raise RuntimeError("measure bug")
        observed = observation.interface
        assert observed is not None
        if observed.vertices.shape != simulated.vertices.shape:
            raise fbia.MeasureError("meshes differ")
        return (simulated.vertices - observed.vertices).ravel()

    def distance(self, simulated: Interface, observation: fbia.Observation) -> float:
        return float(np.linalg.norm(self.residuals(simulated, observation)))


@pytest.fixture(scope="module")
def mound_problem_parts():
    model = fbia.forward_model(
        "analytic_mound_2d", n_points=31, failure_region={"E": (0.0, 150.0), "nu": (-1.0, 0.0)}
    )
    obs = fbia.synthetic_observations(
        model, {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], noise_std=0.0, seed=0
    )
    params = [fbia.Parameter("E", bounds=(50.0, 800.0)), fbia.Parameter("nu", bounds=(-0.8, 0.49))]
    return model, obs, params


def test_inverse_problem_validation_names_the_model_parameters(mound_problem_parts):
    model, obs, params = mound_problem_parts
    measure = _VertexMeasure()
    with pytest.raises(
        fbia.ConfigError,
        match=r"no parameter\(s\) 'G'; it knows: E, inflow_rate, load_scale, nu$",
    ):
        fbia.InverseProblem(model, measure, obs, [*params, fbia.Parameter("G", bounds=(1, 2))])
    with pytest.raises(fbia.ConfigError, match=r"parameter\(s\) named twice: E$"):
        fbia.InverseProblem(model, measure, obs, [*params, fbia.Parameter("E", bounds=(1, 2))])
    with pytest.raises(fbia.ConfigError, match=r"both varied and fixed: nu$"):
        fbia.InverseProblem(model, measure, obs, params, fixed={"nu": 0.3})
    with pytest.raises(fbia.ConfigError, match="at least one observation"):
        fbia.InverseProblem(model, measure, [], params)
    with pytest.raises(fbia.ConfigError, match="at least one parameter"):
        fbia.InverseProblem(model, measure, obs, [])
    with pytest.raises(fbia.ConfigError, match="noise_std must be a positive number"):
        fbia.InverseProblem(model, measure, obs, params, noise_std=-1.0)
    point3 = fbia.Observation(points=[[0.0, 0.0, 0.0]])
    with pytest.raises(fbia.ConfigError, match=r"observations mix dimensions \[2, 3\]"):
        fbia.InverseProblem(model, measure, [*obs, point3], params)


def test_inverse_problem_evaluate_outcomes_never_raise(mound_problem_parts, tmp_path):
    model, obs, params = mound_problem_parts
    problem = fbia.InverseProblem(model, _VertexMeasure(), obs, params, fixed={"load_scale": 1.0})
    assert problem.names == ["E", "nu"] and problem.coordinates() == [{"inflow_rate": 100.0}]

    ok = problem.evaluate({"E": 400.0, "nu": 0.3})
    assert ok.status == "ok" and ok.distance == 0.0 and ok.residuals.shape == (62,)
    assert ok.diagnostics["states"][0]["load_Pa"] == pytest.approx(10.08)

    off = problem.evaluate({"E": 500.0, "nu": 0.3}, workdir=tmp_path / "off")
    assert off.ok and off.distance > 1e-3 and off.workdir == str(tmp_path / "off")

    failed = problem.evaluate({"E": 100.0, "nu": -0.5})  # inside the failure region
    assert failed.status == "failed" and failed.residuals is None
    assert "simulated failure: mesh distortion" in failed.message
    assert failed.distance != failed.distance  # NaN without distances

    impossible = problem.evaluate({"E": -1.0, "nu": 0.3})
    assert impossible.status == "failed" and "must be positive" in impossible.message

    fewer = fbia.InverseProblem(
        fbia.forward_model("analytic_mound_2d", n_points=11), _VertexMeasure(), obs, params
    )
    assert fewer.evaluate({"E": 400.0, "nu": 0.3}).status == "measure_failed"

    buggy = fbia.InverseProblem(model, _VertexMeasure(bug=True), obs, params)
    rec = buggy.evaluate({"E": 400.0, "nu": 0.3})
    assert rec.status == "error" and rec.message == "RuntimeError: measure bug"

    unknown = problem.evaluate({"E": 400.0, "nu": 0.3, "G": 1.0})  # a ConfigError inside solve
    assert unknown.status == "error" and "unknown parameter(s) 'G'" in unknown.message


def test_inverse_problem_as_dict_and_vectors(mound_problem_parts):
    model, obs, params = mound_problem_parts
    unc = [fbia.Parameter("inflow_rate", prior=fbia.priors.beta(2.6, 1.4, 0.0, 110.0))]
    # An observation at {"inflow_rate": 100} would fix the rate: the uncertain one is ignored.
    with pytest.raises(fbia.ConfigError, match="inflow_rate also set by the observations"):
        fbia.InverseProblem(model, _VertexMeasure(), obs, params, uncertain=unc)
    obs = [fbia.Observation(o.interface, {}) for o in obs]  # the state is set by theta
    problem = fbia.InverseProblem(
        model, _VertexMeasure(), obs, params, uncertain=unc, fixed={"load_scale": 1.0}
    )
    np.testing.assert_array_equal(problem.lower, [50.0, -0.8])
    np.testing.assert_array_equal(problem.upper, [800.0, 0.49])
    full = problem.as_dict([400.0, 0.3], theta=[90.0])
    assert full == {"load_scale": 1.0, "E": 400.0, "nu": 0.3, "inflow_rate": 90.0}
    with pytest.raises(fbia.ConfigError, match=r"no value for parameter\(s\) nu"):
        problem.as_dict({"E": 1.0})
    with pytest.raises(fbia.ConfigError, match="expected 2 parameter values, got 3"):
        problem.as_dict([1.0, 2.0, 3.0])


def test_measurement_points_write_creates_folders(tmp_path):
    mp = fbia.MeasurementPoints([[0.0, 1.0]], [[0.0, 1.0]])
    path = mp.write(tmp_path / "deep" / "mp.csv")
    assert Path(path).read_text().splitlines()[0] == "x,y,dx,dy"
