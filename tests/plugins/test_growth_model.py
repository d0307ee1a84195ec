"""The ``growth`` forward model (issue 15): time series of growth days, the growth law applied
to the FSI + transport state, reuse of that state keyed by what it depends on, bad input.

Coarse finger channel, quasi-steady (steady FSI + steady transport): about 1 s per growth step.
"""

from __future__ import annotations

import numpy as np
import pytest

import fbia

pytest.importorskip("ngsolve")

COARSE = {"mesh_size": 0.06, "interface_mesh_size": 0.012, "mode": "quasi_static"}
REFERENCE = {"K1g": 6e4, "K2g": 5e-2, "K3g": 8e-2}


def _curve(solution: fbia.Solution, day: int) -> np.ndarray:
    return np.asarray(solution.interfaces[fbia.coordinate_key({"day": day})].vertices)


@pytest.fixture(scope="module")
def model():
    return fbia.forward_model("growth", **COARSE)


@pytest.fixture(scope="module")
def days(model, tmp_path_factory):
    return model.solve(
        REFERENCE, [{"day": 0}, {"day": 1}, {"day": 2}], tmp_path_factory.mktemp("g")
    )


def test_one_day_is_eq9_applied_to_the_fsi_and_transport_state(model, days):
    assert not model._states  # two growth days: nothing is kept for reuse
    day0, day1 = _curve(days, 0), _curve(days, 1)
    # the same vertices, moved by the growth of eq. 9 only (day 0 is the FSI-deformed shape)
    assert day0.shape == day1.shape
    growth = np.linalg.norm(day1 - day0, axis=1)
    assert 0.5e-3 < growth.max() < 5e-3  # um-scale growth per day, as in Paper A
    d = days.diagnostics
    assert d["max_growth"] > 0 and d["max_erosion"] > 0  # grows downstream, erodes the tip
    assert len(d["uptake"]) == 2 and all(u > 0 for u in d["uptake"])


def test_days_accumulate_and_the_feet_stay_on_the_floor(days):
    day0, day1, day2 = (_curve(days, k) for k in (0, 1, 2))
    assert np.abs(day2 - day0).max() > np.abs(day1 - day0).max()
    for c in (day0, day1, day2):
        assert abs(c[0, 1]) < 1e-12 and abs(c[-1, 1]) < 1e-12


def test_zero_coefficients_leave_the_fsi_interface_unchanged(tmp_path):
    m = fbia.forward_model("growth", **COARSE)
    sol = m.solve({"K1g": 0.0, "K2g": 0.0, "K3g": 0.0}, [{"day": 0}, {"day": 1}], tmp_path)
    np.testing.assert_array_equal(_curve(sol, 1), _curve(sol, 0))


def test_the_state_is_reused_for_new_growth_coefficients_only(tmp_path):
    m = fbia.forward_model("growth", **COARSE)
    first = m.solve(REFERENCE, [{"day": 1}], tmp_path)
    assert not first.diagnostics["reused_state"]
    k = {"K1g": 3e4, "K2g": 1e-2, "K3g": 2e-1}
    again = m.solve(k, [{"day": 1}], tmp_path)
    assert again.diagnostics["reused_state"]
    fresh = fbia.forward_model("growth", **COARSE).solve(k, [{"day": 1}], tmp_path)
    np.testing.assert_allclose(_curve(again, 1), _curve(fresh, 1), rtol=0, atol=1e-12)
    stiffer = m.solve({**k, "E": 150.0}, [{"day": 1}], tmp_path)
    assert not stiffer.diagnostics["reused_state"]  # E changes the FSI state
    assert np.abs(_curve(stiffer, 1) - _curve(again, 1)).max() > 1e-5


def test_growth_is_linear_in_the_coefficients(tmp_path):
    """Eq. 9 is linear in K1g: the growth of the nutrient term alone doubles with it."""
    m = fbia.forward_model("growth", **COARSE)
    base = _curve(m.solve({"K1g": 0.0, "K2g": 0.0, "K3g": 0.0}, [{"day": 1}], tmp_path), 1)
    g1 = _curve(m.solve({"K1g": 3e4, "K2g": 0.0, "K3g": 0.0}, [{"day": 1}], tmp_path), 1) - base
    g2 = _curve(m.solve({"K1g": 6e4, "K2g": 0.0, "K3g": 0.0}, [{"day": 1}], tmp_path), 1) - base
    np.testing.assert_allclose(g2, 2.0 * g1, rtol=0, atol=1e-12)
    assert np.abs(g1).max() > 1e-4  # about 1 um: the nutrient growth of half the reference


@pytest.mark.parametrize(
    ("coordinates", "message"),
    [
        ([{"day": -1}], "whole number of growth periods"),
        ([{"day": 0.5}], "whole number of growth periods"),
        ([{"inflow_rate": 0.1}], "exactly 'day'"),
        ([], "no coordinates"),
    ],
)
def test_bad_coordinates_are_config_errors(model, tmp_path, coordinates, message):
    with pytest.raises(fbia.ConfigError, match=message):
        model.solve(REFERENCE, coordinates, tmp_path)


def test_unknown_parameters_and_d_for_both_phases(model, tmp_path):
    with pytest.raises(fbia.ConfigError, match="unknown parameter"):
        model.solve({"K4g": 1.0}, [{"day": 0}], tmp_path)
    params = model._check_parameters({"D": 1e-3})
    assert params["D_fluid"] == params["D_biofilm"] == 1e-3


def test_five_growth_days_keep_the_mesh_above_the_quality_threshold(tmp_path):
    """grow_mesh refuses a grown mesh below ``min_element_quality`` (ForwardModelError): five
    days of the example that finish are five admissible meshes."""
    m = fbia.forward_model("growth", **COARSE)
    sol = m.solve(REFERENCE, [{"day": 5}], tmp_path)
    growth = sol.diagnostics["growth"]
    assert len(growth) == 5
    assert all(0.5e-3 < g[0] < 5e-3 for g in growth)  # um-scale growth every day


def test_field_output_holds_the_nutrient_and_the_growth(tmp_path):
    import meshio

    m = fbia.forward_model("growth", **COARSE, write_vtu=True)
    sol = m.solve(REFERENCE, [{"day": 1}], tmp_path)
    (path,) = sol.fields.values()
    vtu = meshio.read(path)
    assert {"velocity", "pressure", "displacement", "phi", "growth"} <= set(vtu.point_data)
    phi = vtu.point_data["phi"]
    # consumed in the biofilm; P2 with SUPG may overshoot phi_in by a hair
    assert 0.0 < phi.min() < phi.max() <= 2.5e-11 * (1 + 1e-4)
    growth = np.linalg.norm(vtu.point_data["growth"][:, :2], axis=1)
    d = sol.diagnostics
    assert growth.max() == pytest.approx(max(d["max_growth"], d["max_erosion"]), rel=1e-12)


def test_erosion_that_eats_the_biofilm_is_a_forward_model_error_with_its_reason(tmp_path):
    m = fbia.forward_model("growth", **COARSE)
    with pytest.raises(fbia.ForwardModelError) as err:
        m.solve({**REFERENCE, "K2g": 50.0}, [{"day": 1}], tmp_path)
    assert err.value.reason in ("eroded_away", "growth_inverted", "growth_quality")


def test_transient_fsi_and_transport_agree_with_the_quasi_steady_variant(tmp_path):
    """5 s of ramped flow with the transport stepped on the moving mesh (Paper A's time
    scales) against steady FSI + transport: the grown interfaces differ by far less than the
    growth itself (0.02 um of about 1.6 um on the example)."""
    quasi = _curve(
        fbia.forward_model("growth", **COARSE).solve(REFERENCE, [{"day": 1}], tmp_path), 1
    )
    transient = fbia.forward_model("growth", **{**COARSE, "mode": "transient", "time_step": 0.5})
    sol = transient.solve(REFERENCE, [{"day": 1}], tmp_path)
    assert np.abs(_curve(sol, 1) - quasi).max() < 0.05 * sol.diagnostics["max_growth"]


def test_the_growth_of_a_day_is_eq9_of_the_kept_state(tmp_path):
    """With one growth step the FSI + transport state is kept: the day-1 interface minus the
    day-0 one is eq. 9 of its normals, fluxes and tractions over one day, node by node."""
    from fbia.plugins.growth.growth_law import NODE_AREA, GrowthCoefficients, growth_displacement

    m = fbia.forward_model("growth", **COARSE)
    sol = m.solve(REFERENCE, [{"day": 0}, {"day": 1}], tmp_path)
    (state,) = m._states.values()
    expected = growth_displacement(
        state.normals,
        state.flux,
        state.traction,
        GrowthCoefficients(6e4, 5e-2, 8e-2),
        86400.0,
        traction_measure="nodal_force",
        nodal_area=NODE_AREA,
    )
    assert np.all(state.flux > 0)  # nutrient enters the biofilm everywhere on the finger
    order = np.concatenate(state.chains)
    np.testing.assert_allclose(_curve(sol, 1) - _curve(sol, 0), expected[order], atol=1e-15)
