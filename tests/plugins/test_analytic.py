"""The analytic mound forward models (fbia.plugins.analytic): closed forms, orientation,
monotone and identifiable response, failures, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

import fbia
from fbia.core.interface import Interface
from fbia.plugins.analytic import AnalyticMound2DForwardModel, AnalyticMound3DForwardModel

TRUTH = {"E": 400.0, "nu": 0.3}
Q = {"inflow_rate": 100.0}


def _solve(model, q: float = 100.0, **params: float) -> Interface:
    return model.solve({**TRUTH, **params}, [{"inflow_rate": q}], ".").interface({"inflow_rate": q})


def _signed_cpp(points: np.ndarray, gamma: Interface) -> np.ndarray:
    """Signed closest-point distances of ``points`` to the 2-D polyline ``gamma`` (+ = fluid)."""
    a, b = gamma.vertices[gamma.cells[:, 0]], gamma.vertices[gamma.cells[:, 1]]
    t = b - a
    s = np.einsum("pmk,mk->pm", points[:, None, :] - a, t) / np.einsum("mk,mk->m", t, t)
    foot = a + np.clip(s, 0.0, 1.0)[..., None] * t
    d = points[:, None, :] - foot
    dist = np.linalg.norm(d, axis=-1)
    j = dist.argmin(axis=1)
    rows = np.arange(len(points))
    sign = np.sign(np.einsum("pk,pk->p", d[rows, j], gamma.normals[j]))
    return sign * dist[rows, j]


def _deformation(gamma: Interface, ref: Interface) -> dict[str, float]:
    """Measures of how far ``gamma`` is from the undeformed ``ref`` (same connectivity)."""
    d1 = _signed_cpp(gamma.vertices, ref)
    d2 = _signed_cpp(ref.vertices, gamma)
    sym_diff = shapely.Polygon(gamma.vertices).symmetric_difference(shapely.Polygon(ref.vertices))
    return {
        "max_displacement": float(np.linalg.norm(gamma.vertices - ref.vertices, axis=1).max()),
        "cpp_rms_symmetric": float(np.sqrt(0.5 * np.mean(d1**2) + 0.5 * np.mean(d2**2))),
        "area_between": float(sym_diff.area),
        "rkhs_0.2mm": _rkhs(gamma, ref, 0.2),
    }


def _rkhs(g1: Interface, g2: Interface, sigma_w: float) -> float:
    """RKHS distance of two curves as currents with a Gaussian kernel (Paper B eq. 10-11)."""

    def inner(a: Interface, b: Interface) -> float:
        d2 = ((a.centres[:, None, :] - b.centres[None, :, :]) ** 2).sum(axis=-1)
        return float(np.sum(np.exp(-d2 / (2 * sigma_w**2)) * (a.area_vectors @ b.area_vectors.T)))

    return math.sqrt(max(inner(g1, g1) - 2 * inner(g1, g2) + inner(g2, g2), 0.0))


@pytest.fixture(scope="module")
def m2():
    return fbia.forward_model("analytic_mound_2d", n_points=81)


@pytest.fixture(scope="module")
def m3():
    return fbia.forward_model("analytic_mound_3d", n_rings=6)


# -- registry, options, protocol ---------------------------------------------------------------


def test_models_are_registered_through_the_entry_point():
    entries = {e.name: e for e in fbia.list_plugins("forward_model")}
    assert entries["analytic_mound_2d"].factory is AnalyticMound2DForwardModel
    assert entries["analytic_mound_3d"].factory is AnalyticMound3DForwardModel
    assert entries["analytic_mound_2d"].plugin == "fbia.analytic"
    for cls in (AnalyticMound2DForwardModel, AnalyticMound3DForwardModel):
        model = cls()
        assert isinstance(model, fbia.ForwardModel)
        assert tuple(model.parameter_names()) == ("E", "nu", "inflow_rate", "load_scale")
        # every option documents itself (units in brackets)
        for name, info in cls.Options.describe().items():
            assert info["description"], name


def test_options_are_validated_with_one_line_errors():
    with pytest.raises(fbia.ConfigError, match=r"unknown option 'hieght'; valid options: "):
        fbia.forward_model("analytic_mound_2d", hieght=0.4)
    with pytest.raises(fbia.ConfigError, match="must be below the channel height"):
        fbia.forward_model("analytic_mound_2d", height=1.2)
    with pytest.raises(fbia.ConfigError, match="leaves the channel"):
        fbia.forward_model("analytic_mound_2d", centre=0.1)
    with pytest.raises(fbia.ConfigError, match="must be below width/4"):
        fbia.forward_model("analytic_mound_2d", crest_shift=0.3)
    with pytest.raises(fbia.ConfigError, match="failure_region names unknown parameter 'G'"):
        fbia.forward_model("analytic_mound_2d", failure_region={"G": (0, 1)})
    with pytest.raises(fbia.ConfigError, match="footprint leaves the channel floor"):
        fbia.forward_model("analytic_mound_3d", centre_y=0.2)
    with pytest.raises(fbia.ConfigError, match="n_points"):
        fbia.forward_model("analytic_mound_2d", n_points=3)


# -- geometry ----------------------------------------------------------------------------------


def test_undeformed_mound_geometry_2d(m2):
    ref = m2.undeformed()
    v = ref.vertices
    assert len(v) == 81 and len(ref.curves()) == 1
    np.testing.assert_array_equal(v[[0, -1]], [[0.6, 0.0], [1.4, 0.0]])  # feet on the floor
    assert v[:, 1].max() == pytest.approx(0.5, abs=1e-3)  # crest height h
    assert v[np.argmax(v[:, 1]), 0] == pytest.approx(1.05, abs=0.01)  # crest at x0 + c
    np.testing.assert_allclose(ref.sizes, ref.measure / 80, rtol=1e-3)  # even in arc length
    # area under the half ellipse, pi a h / 2 (the crest shift is a shear: area unchanged),
    # converging at second order in the vertex spacing
    exact = math.pi * 0.4 * 0.5 / 2
    errors = []
    for n in (26, 51, 101):
        g = fbia.forward_model("analytic_mound_2d", n_points=n).undeformed()
        errors.append(exact - 0.5 * np.einsum("ij,ij->", g.centres, g.area_vectors))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(rates, 2.0, atol=0.05)


def test_undeformed_dome_geometry_3d():
    errors = []
    exact = 2.0 / 3.0 * math.pi * 0.4 * 0.4 * 0.5  # half ellipsoid
    for n in (4, 8, 16):
        dome = fbia.forward_model("analytic_mound_3d", n_rings=n).undeformed()
        assert len(dome) == 6 * n * n and len(dome.vertices) == 1 + 3 * n * (n + 1)
        # closed by the floor (z = 0 contributes nothing to sum c . a): the enclosed volume
        errors.append(exact - np.einsum("ij,ij->", dome.centres, dome.area_vectors) / 3.0)
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(rates, 2.0, atol=0.1)


def _edges(cells: np.ndarray) -> np.ndarray:
    return np.vstack([cells[:, [0, 1]], cells[:, [1, 2]], cells[:, [2, 0]]])


@pytest.mark.parametrize("q", [0.0, 100.0, 300.0])
@pytest.mark.parametrize("params", [TRUTH, {"E": 50.0, "nu": -0.95}])
def test_dome_is_consistently_oriented_with_its_rim_on_the_floor(m3, params, q):
    dome = _solve(m3, q, **params)
    edges = _edges(dome.cells)
    directed = {tuple(e) for e in edges}
    assert len(directed) == len(edges)  # no directed edge twice: consistent orientation
    boundary = [e for e in edges if (e[1], e[0]) not in directed]
    rim = np.unique(np.array(boundary))
    assert len(boundary) == 6 * 6  # one closed loop, the rim ring of n_rings = 6
    np.testing.assert_array_equal(dome.vertices[rim, 2], 0.0)  # bonded to the floor
    top = int(np.argmax(dome.vertices[:, 2]))
    assert dome.vertex_normals[top, 2] > 0.9  # the crest faces up into the fluid
    # closed by the floor, the surface encloses a positive volume: normals point outwards
    assert np.einsum("ij,ij->", dome.centres, dome.area_vectors) > 0.0
    if params is TRUTH:  # moderate deformation: still a graph over the floor, all normals up
        assert np.all(dome.normals[:, 2] > 0.0)
        centre = np.array([1.0, 0.5, 0.0])
        assert np.all(np.einsum("ij,ij->i", dome.normals, dome.centres - centre) > 0.0)


@pytest.mark.parametrize(
    "params",
    [{}, TRUTH, {"E": 50.0, "nu": -0.95}, {"E": 50.0, "nu": 0.49}, {"E": 2000.0, "nu": 0.0}],
)
@pytest.mark.parametrize("q", [100.0, 300.0, -100.0])
def test_normals_point_into_the_fluid_2d(m2, params, q):
    gamma = _solve(m2, q, **params)
    (curve,) = gamma.curves()
    assert curve[0, 0] < curve[-1, 0]  # upstream -> downstream
    solid = shapely.Polygon(curve)  # closed along the floor
    assert solid.is_valid and shapely.LineString(curve).is_simple
    eps = 1e-4
    outside = shapely.points(gamma.centres + eps * gamma.normals)
    inside = shapely.points(gamma.centres - eps * gamma.normals)
    assert not np.any(solid.contains(outside))
    assert np.all(solid.contains(inside))


# -- closed forms ------------------------------------------------------------------------------


def test_reference_state_against_the_closed_form(m2):
    """E = 400 Pa, nu = 0.3, q = 100 mm^2/s: the formulas of the module docstrings by hand."""
    load = 6e-3 * 100 / 0.5**2 + 12e-3 * 100 * 0.8 / 0.5**3  # tau_w + dp = 2.4 + 7.68 Pa
    assert load == pytest.approx(10.08)
    lean = 0.5 * math.tanh(6.0 * load / 400.0)
    bulk = 400.0 / (3.0 * (1.0 - 0.6))
    eps = 0.5 * math.tanh(3.0 * load / bulk)
    sol = m2.solve(TRUTH, [Q], ".")
    (state,) = sol.diagnostics["states"]
    assert state["load_Pa"] == pytest.approx(load, rel=1e-14)
    assert state["lean_mm"] == pytest.approx(lean, rel=1e-14)
    assert state["flattening"] == pytest.approx(eps, rel=1e-14)
    X, Y = m2.undeformed().vertices.T
    eta = Y / 0.5
    u = sol.interface(Q).vertices - m2.undeformed().vertices
    np.testing.assert_allclose(u[:, 0], lean * eta**2 - eps * (X - 1.05) * eta, atol=1e-15)
    np.testing.assert_allclose(u[:, 1], -eps * Y, atol=1e-15)
    # Paper A: maximum displacement about 5.3e-2 mm at this point; here it is of that order
    assert 0.05 < state["max_displacement_mm"] < 0.15
    assert state["max_displacement_mm"] == pytest.approx(np.linalg.norm(u, axis=1).max())


@pytest.mark.parametrize(("E", "nu", "q"), [(400.0, 0.3, 100.0), (80.0, -0.9, 250.0)])
def test_area_and_volume_change_match_the_closed_form(m2, m3, E, nu, q):
    """The deformation map has det F = (1 - eps Y/h)(1 - eps) in 2-D, (1 - eps Z/h)^2 (1 - eps)
    in 3-D; over the half ellipse / half ellipsoid that gives the ratios below."""
    params = {"E": E, "nu": nu}

    def area(g):
        return 0.5 * np.einsum("ij,ij->", g.centres, g.area_vectors)

    (state,) = m2.states(params, [{"inflow_rate": q}])
    eps = state.flattening
    ratio = area(_solve(m2, q, **params)) / area(m2.undeformed())
    assert ratio == pytest.approx((1 - eps) * (1 - 4 * eps / (3 * math.pi)), rel=2e-4)

    def volume(g):
        return np.einsum("ij,ij->", g.centres, g.area_vectors) / 3.0

    # the map is nonlinear in Z: large flattening needs a finer mesh (error O(n_rings^-2))
    dome = m3 if eps < 0.1 else fbia.forward_model("analytic_mound_3d", n_rings=24)
    (state,) = dome.states(params, [{"inflow_rate": q}])
    eps = state.flattening
    ratio = volume(_solve(dome, q, **params)) / volume(dome.undeformed())
    assert ratio == pytest.approx((1 - eps) * (1 - 0.75 * eps + eps**2 / 5), rel=1e-3)


def test_zero_inflow_gives_exactly_the_undeformed_shape(m2, m3):
    for model in (m2, m3):
        for params in (TRUTH, {"E": 50.0, "nu": -0.95}):
            gamma = _solve(model, 0.0, **params)
            np.testing.assert_array_equal(gamma.vertices, model.undeformed().vertices)
            np.testing.assert_array_equal(gamma.cells, model.undeformed().cells)
        no_load = model.solve({**TRUTH, "load_scale": 0.0}, [Q], ".").interface(Q)
        np.testing.assert_array_equal(no_load.vertices, model.undeformed().vertices)
        # the footing never moves
        loaded = _solve(model, 200.0, E=60.0, nu=-0.9)
        floor = model.undeformed().vertices[:, -1] == 0.0
        np.testing.assert_array_equal(loaded.vertices[floor], model.undeformed().vertices[floor])


def test_3d_load_uses_the_inflow_rate_per_channel_width():
    narrow = fbia.forward_model("analytic_mound_3d", n_rings=3)
    wide = fbia.forward_model("analytic_mound_3d", n_rings=3, channel_width=2.0, centre_y=1.0)
    a = narrow.solve(TRUTH, [{"inflow_rate": 100.0}], ".").diagnostics["states"][0]
    b = wide.solve(TRUTH, [{"inflow_rate": 200.0}], ".").diagnostics["states"][0]
    assert b["load_Pa"] == pytest.approx(a["load_Pa"]) == pytest.approx(10.08)
    assert b["max_displacement_mm"] == pytest.approx(a["max_displacement_mm"])


# -- monotone, saturating, identifiable ----------------------------------------------------------

MEASURES = ("max_displacement", "cpp_rms_symmetric", "area_between", "rkhs_0.2mm")


def _table(m2, points):
    ref = m2.undeformed()
    return np.array(
        [[_deformation(_solve(m2, q, E=E, nu=nu), ref)[k] for k in MEASURES] for E, nu, q in points]
    )


@pytest.mark.parametrize("E", [50.0, 400.0, 2000.0])
@pytest.mark.parametrize("nu", [-0.95, 0.3, 0.49])
def test_deformation_grows_monotonically_with_inflow(m2, E, nu):
    qs = [0.0, 10.0, 50.0, 100.0, 150.0, 250.0, 400.0]
    table = _table(m2, [(E, nu, q) for q in qs])
    assert np.all(table[0] == 0.0)
    assert np.all(np.diff(table, axis=0) > 0.0), dict(zip(MEASURES, table.T, strict=True))


@pytest.mark.parametrize("nu", [-0.95, -0.5, 0.0, 0.3, 0.49])
def test_softer_mounds_deform_more(m2, nu):
    Es = np.geomspace(2000.0, 50.0, 9)  # decreasing E
    table = _table(m2, [(E, nu, 100.0) for E in Es])
    assert np.all(np.diff(table, axis=0) > 0.0), dict(zip(MEASURES, table.T, strict=True))


@pytest.mark.parametrize("E", [50.0, 150.0, 400.0, 2000.0])
def test_more_auxetic_mounds_deform_more(m2, E):
    nus = np.linspace(0.49, -0.95, 9)  # decreasing nu
    table = _table(m2, [(E, nu, 100.0) for nu in nus])
    assert np.all(np.diff(table, axis=0) > 0.0), dict(zip(MEASURES, table.T, strict=True))


def test_3d_deformation_is_monotone_in_E_nu_and_inflow(m3):
    ref = m3.undeformed().vertices

    def dmax(E, nu, q):
        return np.linalg.norm(_solve(m3, q, E=E, nu=nu).vertices - ref, axis=1).max()

    assert np.all(np.diff([dmax(E, 0.3, 100.0) for E in (2000, 800, 400, 100, 50)]) > 0)
    assert np.all(np.diff([dmax(400, nu, 100.0) for nu in (0.49, 0.3, 0.0, -0.5, -0.95)]) > 0)
    assert np.all(np.diff([dmax(400, 0.3, q) for q in (0, 10, 100, 300, 1000)]) > 0)


def test_E_and_nu_are_identifiable_yet_coupled(m2):
    """Jacobian of the signed closest-point residuals (Paper B eq. 7) at E = 400 Pa, nu = 0.3
    w.r.t. (ln E, nu): full rank, condition number ~3.9, columns correlated (cos ~0.59)."""
    observed = _solve(m2, 100.0)

    def r(E, nu):
        return _signed_cpp(_solve(m2, 100.0, E=E, nu=nu).vertices, observed)

    np.testing.assert_array_equal(r(400.0, 0.3), 0.0)
    h = 1e-4
    j_lnE = (r(400.0 * math.exp(h), 0.3) - r(400.0 * math.exp(-h), 0.3)) / (2 * h)
    j_nu = (r(400.0, 0.3 + h) - r(400.0, 0.3 - h)) / (2 * h)
    sv = np.linalg.svd(np.c_[j_lnE, j_nu], compute_uv=False)
    assert sv[0] / sv[1] == pytest.approx(3.94, abs=0.05)
    cos = abs(j_lnE @ j_nu) / (np.linalg.norm(j_lnE) * np.linalg.norm(j_nu))
    assert cos == pytest.approx(0.594, abs=0.01)
    # in the raw units (Pa, -) the condition number is ~1.5e3
    raw = np.linalg.svd(np.c_[j_lnE / 400.0, j_nu], compute_uv=False)
    assert raw[0] / raw[1] == pytest.approx(1515.6, rel=0.01)


# -- inputs, failures, determinism ---------------------------------------------------------------


def test_inflow_rate_precedence_coordinate_over_parameter_over_option(m2):
    states = m2.states(
        {**TRUTH, "inflow_rate": 40.0}, [{"inflow_rate": 100.0}, {}, {"inflow_rate": 0.0}]
    )
    assert [s.inflow_rate for s in states] == [100.0, 40.0, 0.0]
    (default,) = m2.states({}, [{}])
    assert (default.E, default.nu, default.inflow_rate, default.load_scale) == (400, 0.3, 100, 1)
    sol = m2.solve(TRUTH, [{"inflow_rate": 50.0}, {"inflow_rate": 100.0}], ".")
    assert sol.covers([{"inflow_rate": 50.0}, {"inflow_rate": 100.0}])
    np.testing.assert_array_equal(sol.interface(Q).vertices, _solve(m2, 100.0).vertices)


def test_load_scale_and_inflow_rate_enter_the_load_as_a_product(m2):
    a = m2.solve({**TRUTH, "load_scale": 2.0}, [{"inflow_rate": 50.0}], ".")
    b = m2.solve(TRUTH, [{"inflow_rate": 100.0}], ".")
    np.testing.assert_allclose(
        a.interface({"inflow_rate": 50.0}).vertices, b.interface(Q).vertices, rtol=0, atol=1e-15
    )


def test_reversed_flow_leans_upstream(m2):
    ref = m2.undeformed().vertices
    fwd = _solve(m2, 100.0).vertices - ref
    rev = _solve(m2, -100.0).vertices - ref
    top = int(np.argmax(ref[:, 1]))
    assert fwd[top, 0] > 0.05 and rev[top, 0] < -0.05
    np.testing.assert_allclose(rev[:, 1], fwd[:, 1])  # flattening does not depend on the sign


@pytest.mark.parametrize("name", ["analytic_mound_2d", "analytic_mound_3d"])
def test_failure_region_raises_forward_model_error(name):
    model = fbia.forward_model(name, failure_region={"E": (0.0, 150.0), "nu": (-1.0, -0.2)})
    with pytest.raises(fbia.ForwardModelError, match=r"simulated failure: mesh distortion") as exc:
        model.solve({"E": 100.0, "nu": -0.5}, [Q], ".")
    assert exc.value.reason == "mesh_distortion"
    assert "E=100 in [0, 150]" in str(exc.value)
    model.solve({"E": 100.0, "nu": 0.0}, [Q], ".")  # one parameter outside: runs
    model.solve({"E": 200.0, "nu": -0.5}, [Q], ".")
    by_rate = fbia.forward_model(name, failure_region={"inflow_rate": (150.0, 1000.0)})
    by_rate.solve(TRUTH, [Q], ".")
    with pytest.raises(fbia.ForwardModelError, match="mesh distortion"):
        by_rate.solve(TRUTH, [Q, {"inflow_rate": 200.0}], ".")


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"E": 0.0}, r"Young's modulus must be positive, got E=0.0 Pa"),
        ({"E": -5.0}, "must be positive"),
        ({"nu": 0.5}, r"Poisson's ratio must lie in \(-1, 0.5\), got nu=0.5"),
        ({"nu": -1.0}, "must lie in"),
        ({"E": math.nan}, "non-finite input E=nan"),
        ({"inflow_rate": math.inf}, "non-finite input inflow_rate=inf"),
    ],
)
def test_impossible_inputs_are_failed_runs(m2, m3, params, message):
    for model in (m2, m3):
        with pytest.raises(fbia.ForwardModelError, match=message):
            model.solve({**TRUTH, **params}, [{}], ".")


def test_unknown_names_are_config_errors(m2):
    with pytest.raises(fbia.ConfigError, match=r"unknown parameter\(s\) 'G'; valid: E, nu"):
        m2.solve({"E": 400.0, "G": 1.0}, [Q], ".")
    with pytest.raises(fbia.ConfigError, match=r"unknown coordinate key\(s\) 'time'"):
        m2.solve(TRUTH, [{"time": 15.0}], ".")
    with pytest.raises(fbia.ConfigError, match="at least one coordinate"):
        m2.solve(TRUTH, [], ".")


def test_solve_is_deterministic(m2, m3):
    for model in (m2, m3):
        other = type(model)(model.options)
        a = model.solve(TRUTH, [Q, {"inflow_rate": 30.0}], ".")
        b = other.solve(TRUTH, [Q, {"inflow_rate": 30.0}], ".")
        for key in a.interfaces:
            np.testing.assert_array_equal(a.interfaces[key].vertices, b.interfaces[key].vertices)
        assert a.diagnostics == b.diagnostics


def test_write_fields_puts_readable_interfaces_in_the_workdir(tmp_path):
    for name, suffix in (("analytic_mound_2d", ".csv"), ("analytic_mound_3d", ".vtu")):
        model = fbia.forward_model(name, write_fields=True)
        wd = tmp_path / name
        sol = model.solve(TRUTH, [Q, {"inflow_rate": 0.0}], wd)
        assert sorted(sol.fields) == ["interface_0", "interface_1", "undeformed"]
        assert sol.fields["interface_0"] == wd / f"interface_0{suffix}"
        back = Interface.read(sol.fields["interface_0"])
        np.testing.assert_array_equal(back.vertices, sol.interface(Q).vertices)
        back0 = Interface.read(sol.fields["interface_1"])
        np.testing.assert_array_equal(back0.vertices, model.undeformed().vertices)
    assert fbia.forward_model("analytic_mound_2d").solve(TRUTH, [Q], tmp_path / "x").fields == {}


def test_models_pass_the_fbia_testing_conformance_checks(tmp_path):
    from fbia.testing import check_registered

    for entry in fbia.list_plugins("forward_model"):
        if entry.name.startswith("analytic_mound_"):
            solution = check_registered(entry, tmp_path / entry.name)
            assert solution.covers([{"inflow_rate": 50.0}, {"inflow_rate": 100.0}])
