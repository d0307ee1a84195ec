"""The ale_fsi forward model on the default flow cell (coarse meshes, one NGSolve thread).

Physical checks of the quasi-static monolithic ALE FSI solver: rest at zero inflow, monotone
deformation in the inflow rate and in 1/E, mass conservation with the solid exactly at rest,
warm starts that do not change the answer, small-strain agreement of SVK and neo-Hooke,
interface orientation, failures as ForwardModelError, the LM starts of Paper A Table 1, a
limit point of the steady branch found and reported, heterogeneous subdomains, user-mesh round
trip, VTU output and transient mode.  Turek-Hron is in test_ale_fsi_turek_hron.py.
"""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("ngsolve")

import fbia  # noqa: E402
from fbia.plugins.ale_fsi import AleFsiForwardModel  # noqa: E402
from fbia.plugins.fem.outlines import DEFAULT_OUTLINE  # noqa: E402

COARSE = {"mesh_size": 0.2, "interface_mesh_size": 0.06}

#: Paper A, Table 1: initial guesses (E [Pa], nu) of the LM runs of the homogeneous example
TABLE_1 = {
    "blue": (200.0, 0.4),
    "orange": (200.0, 0.0),
    "green": (400.0, 0.45),
    "red": (400.0, 0.0),
    "purple": (600.0, 0.4),
    "brown": (600.0, 0.0),
    "pink": (400.0, -0.3),
    "gray": (400.0, -0.6),
    "olive": (400.0, -0.9),
    "cyan": (1000.0, 0.0),
    "black": (1000.0, 0.4),
}


@pytest.fixture(scope="module")
def model() -> AleFsiForwardModel:
    return AleFsiForwardModel(**COARSE, warm_start=False)


def _max_disp(sol: fbia.Solution, coordinates: list[dict[str, float]]) -> list[float]:
    """Largest interface displacement (mm) per coordinate, from the diagnostics."""
    assert len(sol.diagnostics["max_displacement"]) == len(coordinates)
    return [float(d) for d in sol.diagnostics["max_displacement"]]


@pytest.fixture(scope="module")
def reference(model, tmp_path_factory) -> fbia.Interface:
    """The undeformed interface (zero inflow) on the coarse mesh."""
    sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 0.0}], tmp_path_factory.mktemp("r"))
    return sol.interface({"inflow_rate": 0.0})


def test_import_and_registration_do_not_import_ngsolve():
    code = (
        "import sys, fbia.plugins.ale_fsi as p; "
        "m = p.AleFsiForwardModel(mesh_size=0.1); "
        "print(m.parameter_names(), 'ngsolve' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['E', 'nu', 'inflow_rate'] False"


def test_registered_through_the_hook():
    import fbia.plugins.ale_fsi as plugin
    from fbia.core.registry import Registry

    registry = Registry.load(entry_points=False, extra=[plugin])
    made = registry.create("forward_model", "ale_fsi", {"mesh_size": 0.3})
    assert isinstance(made, AleFsiForwardModel) and made.options.mesh_size == 0.3
    with pytest.raises(fbia.ConfigError, match="mesh_sise"):
        registry.create("forward_model", "ale_fsi", {"mesh_sise": 0.3})


def test_every_option_states_its_unit():
    for name, f in AleFsiForwardModel.Options.model_fields.items():
        assert f.description and f.description.rstrip().endswith("]"), name


def test_zero_inflow_gives_zero_displacement(model, reference):
    sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 0.0}], "unused")
    assert sol.diagnostics["max_displacement"] == [0.0]
    assert sol.diagnostics["newton_iterations"] <= 1
    # the undeformed interface is the outline from the upstream to the downstream foot
    v = reference.vertices
    np.testing.assert_allclose(v[0], DEFAULT_OUTLINE[0], atol=1e-12)
    np.testing.assert_allclose(v[-1], DEFAULT_OUTLINE[-1], atol=1e-12)


def test_interface_has_the_solid_on_its_right(model, reference, tmp_path):
    import shapely

    sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path)
    gamma = sol.interface({"inflow_rate": 100.0})
    solid = shapely.Polygon(np.vstack([gamma.vertices, gamma.vertices[:1]]))
    assert solid.is_valid and solid.area > 0.2
    outside = gamma.centres + 1e-3 * gamma.normals  # a step along the normal leaves the solid
    inside = gamma.centres - 1e-3 * gamma.normals
    assert not any(solid.contains(shapely.points(outside)))
    assert all(solid.contains(shapely.points(inside)))
    # the flow pushes the mound downstream
    shift = gamma.vertices - reference.vertices
    assert shift[:, 0].mean() > 0.01


def test_deformation_grows_with_inflow_and_compliance(model, reference, tmp_path):
    coords = [{"inflow_rate": r} for r in (100.0, 25.0, 50.0)]  # any order
    sol = model.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path)
    d100, d25, d50 = _max_disp(sol, coords)
    by_rate = [d25, d50, d100]
    for c, d in zip(coords, (d100, d25, d50), strict=True):
        moved = np.linalg.norm(sol.interface(c).vertices - reference.vertices, axis=1).max()
        assert moved == pytest.approx(d, rel=1e-12)
    assert by_rate[0] > 0.003 and np.all(np.diff(by_rate) > 0), by_rate
    # super-linear: the load grows faster than linearly with the inflow (convection, Re ~ 100)
    assert by_rate[2] > 2.0 * by_rate[1]
    one = [{"inflow_rate": 100.0}]
    by_e = [
        _max_disp(model.solve({"E": e, "nu": 0.3}, one, tmp_path), one)[0]
        for e in (800.0, 400.0, 250.0)
    ]
    assert np.all(np.diff(by_e) > 0), by_e
    assert by_e[1] == pytest.approx(by_rate[2], rel=1e-8)
    # the rough size of Paper A's reference (max 5.3e-2 mm at E = 400 Pa, 100 mm^2/s)
    assert 0.02 < by_e[1] < 0.08


def test_fluid_mass_is_conserved(model, tmp_path):
    model.solve({"E": 300.0, "nu": 0.2}, [{"inflow_rate": 80.0}], tmp_path)
    solver, post = model.solver, model.postprocess
    q_in = -post.flux("inflow")
    q_out = post.flux("outflow")
    q_gamma = post.flux("interface")
    assert q_in == pytest.approx(80.0, rel=1e-12)  # the parabolic profile is exact in P2
    assert q_out == pytest.approx(q_in, rel=1e-7)
    # quasi-static: the solid and the interface are at rest exactly (eq. 2.28), their velocity
    # dofs are no unknowns -- and no fluid crosses the interface
    assert q_gamma == 0.0
    V = solver.fes.components[0]
    on_solid = np.array(V.GetDofs(solver.mesh.Materials("solid")))
    assert np.all(solver.velocity.vec.FV().NumPy()[on_solid] == 0.0)
    free = np.array(solver.fes.FreeDofs())
    assert solver.ndof == free.sum() - (free[: V.ndof] & on_solid).sum()


def test_warm_start_does_not_change_the_answer(tmp_path):
    warm = AleFsiForwardModel(**COARSE)  # warm_start=True is the default
    coords = [{"inflow_rate": 60.0}, {"inflow_rate": 100.0}]
    first = warm.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path)
    assert first.diagnostics["warm_start"] is False
    near = {"E": 400.0 * (1 + 1e-4), "nu": 0.3}
    w = warm.solve(near, coords, tmp_path)
    cold = AleFsiForwardModel(**COARSE, warm_start=False).solve(near, coords, tmp_path)
    assert w.diagnostics["warm_start"] is True
    assert w.diagnostics["newton_iterations"] < cold.diagnostics["newton_iterations"]
    for c in coords:
        dev = np.abs(w.interface(c).vertices - cold.interface(c).vertices).max()
        assert dev < 1e-10  # mm; deformation ~ 5e-2 mm
    # and the warm result still sees the parameter change
    change = np.abs(w.interface(coords[1]).vertices - first.interface(coords[1]).vertices).max()
    assert change > 1e-7


def test_svk_and_neo_hooke_differ_only_at_second_order_in_the_load(tmp_path):
    # Both laws linearise to Hooke's law (eq. 2.15, 2.18): at small inflow (Stokes regime,
    # load ~ rate) the displacement is linear in the rate and the difference of the two
    # interfaces quadratic, so it grows 4x when the rate doubles.  The fluid's inertia adds a
    # part O(Re) to the linearity error (default mound: 0.8 % from 0.25 to 0.5 mm^2/s, 0.3 %
    # from 0.1 to 0.2), hence the small rates.
    coords = [{"inflow_rate": r} for r in (0.1, 0.2, 0.4)]
    shapes = {}
    for material in ("svk", "neo_hooke"):
        m = AleFsiForwardModel(**COARSE, material=material, warm_start=False)
        sol = m.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path)
        shapes[material] = [sol.interface(c).vertices for c in coords]
        d = sol.diagnostics["max_displacement"]
        assert d[1] / d[0] == pytest.approx(2.0, rel=5e-3)
    diff = [np.abs(a - b).max() for a, b in zip(shapes["svk"], shapes["neo_hooke"], strict=True)]
    order = np.log2(np.array(diff[1:]) / np.array(diff[:-1]))
    np.testing.assert_allclose(order, 2.0, atol=0.1)
    assert diff[-1] < 1e-3 * max(d)


def test_failures_are_forward_model_errors(model, tmp_path):
    with pytest.raises(fbia.ForwardModelError, match="outside") as info:
        model.solve({"E": 400.0, "nu": 0.55}, [{"inflow_rate": 50.0}], tmp_path)
    assert info.value.reason == "invalid_parameter"
    with pytest.raises(fbia.ForwardModelError) as info:
        model.solve({"E": 30.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path)
    assert info.value.reason in {
        "newton_divergence",
        "limit_point",
        "ale_jacobian",
        "solid_jacobian",
        "element_quality",
    }
    with pytest.raises(fbia.ConfigError, match="unknown parameter"):
        model.solve({"G": 1.0}, [{"inflow_rate": 50.0}], tmp_path)
    with pytest.raises(fbia.ConfigError, match="inflow_rate"):
        model.solve({"E": 400.0}, [{"time": 1.0}], tmp_path)
    with pytest.raises(fbia.ConfigError, match="both a parameter and a coordinate"):
        model.solve({"inflow_rate": 60.0}, [{"inflow_rate": 50.0}], tmp_path)
    # the model is usable after a failure
    ok = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 10.0}], tmp_path)
    assert ok.diagnostics["max_displacement"][0] > 0


def test_paper_a_table1_starts_solve(model, tmp_path):
    # Every LM start of Paper A's homogeneous example (SVK, 100 mm^2/s) gives a steady state
    one = [{"inflow_rate": 100.0}]
    d = {
        name: model.solve({"E": E, "nu": nu}, one, tmp_path).diagnostics["max_displacement"][0]
        for name, (E, nu) in TABLE_1.items()
    }
    # the deformation falls with E at fixed nu ...
    assert d["orange"] > d["red"] > d["brown"] > d["cyan"] > 0
    assert d["blue"] > d["purple"] > d["black"]
    # ... and with nu at fixed E (the auxetic starts bulge least)
    assert d["green"] > d["red"] > d["pink"] > d["gray"] > d["olive"] > 0
    # E * d grows towards Hooke's law's constant (the soft mound stiffens as it bends: 2.4 %
    # from brown to cyan on this mesh), which stiff material reaches under the same load
    assert 400.0 * d["red"] < 600.0 * d["brown"] < 1000.0 * d["cyan"]
    stiff = [
        E * model.solve({"E": E, "nu": 0.0}, one, tmp_path).diagnostics["max_displacement"][0]
        for E in (1e4, 2e4)
    ]
    assert 1000.0 * d["cyan"] < stiff[0]
    assert stiff[0] == pytest.approx(stiff[1], rel=5e-3)


def test_a_limit_point_is_reported_and_the_branch_below_it_solves(tmp_path):
    # E = 30 Pa cannot carry 100 mm^2/s: the compressed downstream foot of the SVK mound softens
    # until the branch of steady states turns back; continuation finds that limit point.  On
    # fig2_sketch (on the default paper_a_facts mound the continuation at 30 Pa ends with
    # newton_divergence instead: the detector does not see the turn there, not investigated)
    model = AleFsiForwardModel(**COARSE, outline="fig2_sketch", warm_start=False)
    with pytest.raises(fbia.ForwardModelError) as info:
        model.solve({"E": 30.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path)
    assert info.value.reason == "limit_point"
    message = str(info.value)
    limit = float(re.search(r"limit point near ([0-9.]+) mm\^2/s", message).group(1))
    assert 15.0 < limit < 60.0
    assert "Saint Venant-Kirchhoff softens" in message
    # just below it the steady states exist; the foot's compression accelerates towards it
    states = [
        model.solve({"E": 30.0, "nu": 0.3}, [{"inflow_rate": f * limit}], tmp_path).diagnostics
        for f in (0.95, 0.99)
    ]
    assert states[1]["max_displacement"][0] > states[0]["max_displacement"][0]
    assert states[1]["min_det_f_solid"] < states[0]["min_det_f_solid"] - 0.1


def test_a_failed_run_ends_its_corrector_steps_early(tmp_path, monkeypatch):
    # E = 100 Pa cannot carry 100 mm^2/s on the default mound either (the first LM step from
    # Table 1's black start reaches it): the continuation fails near 81 mm^2/s.  Its corrector
    # steps near there diverge; the monotonicity test ends each after one Jacobian instead of
    # three (ArclengthContinuation.max_chord_ratio), the continuation taking the same path
    # and failing at the same rate
    from fbia.plugins.fem.continuation import ArclengthContinuation
    from fbia.plugins.fem.newton import NewtonSolver

    factorised = [0]
    factorise = NewtonSolver.factorise

    def counted(self, *args, **kwargs):
        factorised[0] += 1
        return factorise(self, *args, **kwargs)

    monkeypatch.setattr(NewtonSolver, "factorise", counted)
    outcome = {}
    for ratio in (ArclengthContinuation.max_chord_ratio, float("inf")):
        monkeypatch.setattr(ArclengthContinuation, "max_chord_ratio", ratio)
        factorised[0] = 0
        model = AleFsiForwardModel(**COARSE, warm_start=False)
        with pytest.raises(fbia.ForwardModelError) as info:
            model.solve({"E": 100.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path)
        where = re.search(r"continuation failed at ([0-9.]+) mm\^2/s", str(info.value))
        outcome[ratio] = (info.value.reason, float(where.group(1)), factorised[0])
    (reason, rate, jacobians), (reason_before, rate_before, jacobians_before) = outcome.values()
    assert reason == reason_before == "newton_divergence"
    assert 70.0 < rate == rate_before < 90.0
    assert jacobians <= 0.75 * jacobians_before  # measured: 28 against 42


def test_a_continuation_that_succeeds_keeps_its_state_under_the_monotonicity_test(monkeypatch):
    # the other side: where the branch reaches the requested rate (E = 100 Pa at 80 mm^2/s,
    # just below the fold near 81; continuation from rest, as after a failed warm start), the
    # test only ends corrector steps that fail anyway: the state is the same bit for bit, with
    # fewer Jacobians, and it is Newton's straight from rest
    from fbia.plugins.ale_fsi.solver import AleFsiSolver, SolverSettings
    from fbia.plugins.fem.continuation import ArclengthContinuation
    from fbia.plugins.fem.flow_cell import build_flow_cell

    mesh = build_flow_cell(**COARSE)

    def solver():
        out = AleFsiSolver(mesh, SolverSettings())
        out.set_materials({"solid": (100.0, 0.3)})
        return out

    runs = []
    for ratio in (ArclengthContinuation.max_chord_ratio, float("inf")):
        monkeypatch.setattr(ArclengthContinuation, "max_chord_ratio", ratio)
        followed = solver()
        report = followed.solve_steady(80.0, direct=False)
        runs.append((followed.state(), report.jacobians))
    (state, jacobians), (state_before, jacobians_before) = runs
    np.testing.assert_array_equal(state, state_before)
    assert jacobians < jacobians_before  # measured: 20 against 25
    direct = solver()
    direct.solve_steady(80.0)
    np.testing.assert_allclose(state, direct.state(), rtol=0.0, atol=1e-6 * np.abs(state).max())


def test_bad_geometry_is_a_config_error():
    with pytest.raises(fbia.ConfigError, match="floor"):
        AleFsiForwardModel(outline=[(0.5, 0.1), (0.8, 0.4), (1.1, 0.0)]).build_mesh()
    with pytest.raises(fbia.ConfigError, match="not both"):
        AleFsiForwardModel(mesh_file="x.msh", subdomains=[[(0, 0), (1, 0), (1, 1)]])


def test_heterogeneous_subdomains(tmp_path):
    # Paper A Fig. 9: a footing layer, a large middle, a top layer (SVK, Paper A values)
    layers = [
        [(0.0, -0.1), (2.0, -0.1), (2.0, 0.08), (0.0, 0.08)],
        [(0.0, 0.08), (2.0, 0.08), (2.0, 0.36), (0.0, 0.36)],
    ]
    het = AleFsiForwardModel(**COARSE, subdomains=layers, warm_start=False)
    assert het.parameter_names() == ["E_1", "nu_1", "E_2", "nu_2", "E_3", "nu_3", "inflow_rate"]
    assert het.solver.solids == ["solid_1", "solid_2", "solid_3"]
    coords = [{"inflow_rate": 100.0}]
    paper = {"E_1": 500.0, "nu_1": 0.2, "E_2": 200.0, "nu_2": 0.1, "E_3": 1000.0, "nu_3": 0.3}
    d_paper = het.solve(paper, coords, tmp_path).diagnostics["max_displacement"][0]
    uniform = {k: (400.0 if k.startswith("E") else 0.3) for k in paper}
    d_uniform = het.solve(uniform, coords, tmp_path).diagnostics["max_displacement"][0]
    # the same uniform material on the layered mesh matches the homogeneous model
    homo = AleFsiForwardModel(**COARSE, warm_start=False)
    d_homo = homo.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path).diagnostics["max_displacement"][
        0
    ]
    assert d_uniform == pytest.approx(d_homo, rel=0.03)
    # a soft middle layer makes the mound more compliant than a uniform 400 Pa one
    assert d_paper > d_uniform
    softer_top = dict(paper, E_3=300.0)
    assert het.solve(softer_top, coords, tmp_path).diagnostics["max_displacement"][0] > d_paper


def test_user_mesh_round_trip_gives_the_same_answer(tmp_path):
    from fbia.plugins.fem.flow_cell import write_mesh

    model = AleFsiForwardModel(**COARSE, curved=False, warm_start=False)  # files: straight
    path = write_mesh(model.solver.mesh, tmp_path / "cell.msh")
    user = AleFsiForwardModel(mesh_file=path, warm_start=False)
    coords = [{"inflow_rate": 100.0}]
    a = model.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path).interface(coords[0])
    b = user.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path).interface(coords[0])
    assert a.vertices.shape == b.vertices.shape
    assert np.abs(a.vertices - b.vertices).max() < 1e-10


def test_vtu_output_and_interface_forces(tmp_path):
    import meshio

    m = AleFsiForwardModel(**COARSE, write_vtu=True, warm_start=False)
    sol = m.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path)
    path = sol.fields["vtu_0"]
    data = meshio.read(path)
    assert {"velocity", "pressure", "displacement", "interface_force"} <= set(data.point_data)
    assert set(np.unique(data.cell_data["subdomain"][0])) == {0, 1}
    # the nodal interface forces add up to the fluid force on the biofilm
    total = data.point_data["interface_force"][:, :2].sum(axis=0)
    np.testing.assert_allclose(total, sol.diagnostics["fluid_force"][0], rtol=1e-10)
    assert total[0] > 0  # drag pushes downstream
    umax = np.linalg.norm(data.point_data["velocity"], axis=1).max()
    assert 150.0 < umax < 500.0  # mean 100 mm/s, accelerated over the mound


def test_transient_mode_reaches_the_quasi_static_state(tmp_path):
    rate = 50.0
    opts = dict(COARSE, warm_start=False)
    static = AleFsiForwardModel(**opts).solve({}, [{"inflow_rate": rate}], tmp_path)
    trans = AleFsiForwardModel(
        **opts, mode="transient", time_step=0.1, ramp_time=0.5, inflow_rate=rate
    )
    times = [{"time": 1.5}, {"time": 0.25}, {"time": 0.0}]
    sol = trans.solve({}, times, tmp_path)
    full = static.diagnostics["max_displacement"][0]
    end, mid, rest = sol.diagnostics["max_displacement"]
    assert rest == 0.0  # at rest at t = 0
    # half-way up the cosine ramp the inflow is rate/2: about half the final deformation
    assert 0.3 * full < mid < 0.7 * full
    # a second after the ramp (backward Euler) the state is the quasi-static one
    ref = static.interface({"inflow_rate": rate}).vertices
    np.testing.assert_allclose(sol.interface({"time": 1.5}).vertices, ref, rtol=0, atol=1e-5 * full)
    assert end == pytest.approx(full, rel=1e-5)


def test_conformance_checks_of_fbia_testing(tmp_path):
    from fbia import testing as ft

    assert ft.check_options(AleFsiForwardModel) == sorted(AleFsiForwardModel.Options.model_fields)
    params, coords = ft.example_run(AleFsiForwardModel)
    model = AleFsiForwardModel(**ft.example_options(AleFsiForwardModel))
    failing = {"E": 20.0, "nu": 0.3}  # far too soft for 100 mm^2/s: the solid collapses
    solution = ft.check_forward_model(model, params, coords, tmp_path, failing_parameters=failing)
    assert solution.covers(coords)


def test_pickled_model_rebuilds_its_mesh_and_gives_the_same_answer(model, tmp_path):
    import pickle

    coords = [{"inflow_rate": 40.0}]
    a = model.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path).interface(coords[0])
    clone = pickle.loads(pickle.dumps(model))  # what a process pool ships to its workers
    assert clone.options == model.options and clone._solver is None
    b = clone.solve({"E": 400.0, "nu": 0.3}, coords, tmp_path).interface(coords[0])
    assert np.abs(a.vertices - b.vertices).max() < 1e-12


def test_undeformed_interface_and_named_outline(model, reference):
    # undeformed(): the reference configuration, vertex for vertex the zero-inflow solution
    rest = model.undeformed()
    np.testing.assert_array_equal(rest.cells, reference.cells)
    assert np.abs(rest.vertices - reference.vertices).max() < 1e-12
    assert model.dim == 2 and AleFsiForwardModel(geometry="dome_3d").dim == 3
    # the default outline has a name; naming it gives the same mesh
    named = AleFsiForwardModel(**COARSE, outline="paper_a_facts", warm_start=False).undeformed()
    np.testing.assert_array_equal(named.vertices, rest.vertices)
    with pytest.raises(ValueError, match="fig2_sketch, paper_a_facts"):
        AleFsiForwardModel(outline="no_such_outline")


def test_the_default_flow_cell_has_its_own_interface_size_and_the_thesis_vertex_count():
    # paper_a_facts meshes its interface at 0.057 mm unless told: 67 vertices (Paper B:
    # n_in = 66); an outline given as points (or another name) keeps its own size
    default = AleFsiForwardModel(warm_start=False)
    assert default.options.interface_size == 0.057 and default.options.interface_mesh_size is None
    assert len(default.undeformed().vertices) == 67
    points = [list(p) for p in DEFAULT_OUTLINE]
    assert AleFsiForwardModel(outline=points).options.interface_size == 0.03
    assert AleFsiForwardModel(outline="fig2_sketch").options.interface_size == 0.03
    assert AleFsiForwardModel(interface_mesh_size=0.05).options.interface_size == 0.05
    assert AleFsiForwardModel(geometry="dome_3d").options.interface_size == 0.03


def test_synthetic_points_where_the_flow_cell_moved(model, tmp_path):
    # Paper A Fig. 3: the points go to the parts of the interface that moved significantly
    (obs,) = fbia.synthetic_observations(
        model,
        {"E": 400.0, "nu": 0.3},
        [{"inflow_rate": 100.0}],
        0.0,
        1,
        points=10,
        placement="displacement",
    )
    gamma = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path).interface(
        {"inflow_rate": 100.0}
    )
    u_n = np.abs(
        np.sum((gamma.vertices - model.undeformed().vertices) * gamma.vertex_normals, axis=1)
    )
    pts = obs.measurement_points.points
    near = np.argmin(np.linalg.norm(gamma.vertices[None] - pts[:, None], axis=2), axis=1)
    assert len(pts) == 10 and (u_n[near] >= 0.5 * u_n.max()).all()


def test_csr_positions_finds_the_entries_asked_for_and_refuses_others():
    """The positions of given (row, column) entries in a CSR pattern, in the order asked, as
    a brute-force lookup finds them; an entry outside the pattern is an error."""
    import scipy.sparse as sp

    from fbia.plugins.ale_fsi.forms import csr_positions

    rng = np.random.default_rng(3)
    pattern = sp.random(200, 150, density=0.08, format="csr", random_state=rng)
    pattern.sort_indices()
    ptr, cols = pattern.indptr.astype(np.int64), pattern.indices.astype(np.int64)
    rows_of = np.repeat(np.arange(200, dtype=np.int64), np.diff(ptr))
    pick = rng.choice(len(cols), size=300, replace=False)  # some rows asked for, some not
    got = csr_positions(ptr, cols, (200, 150), rows_of[pick], cols[pick])
    assert np.array_equal(got, pick)
    absent = next(c for c in range(150) if c not in set(cols[ptr[7] : ptr[8]]))
    with pytest.raises(RuntimeError, match="sparsity pattern"):
        csr_positions(ptr, cols, (200, 150), np.array([7]), np.array([absent]))


def _stored(E: float, nu: float, rate: float, state: list[float]):
    return ({"E": E, "nu": nu}, rate, np.array(state, dtype=float), {})


def test_secant_prediction_is_the_affine_interpolant_of_the_nearest_states():
    from fbia.plugins.ale_fsi.model import _secant

    # states linear in E and nu: the prediction is exact, inside and (a little) outside
    def u(E: float, nu: float) -> list[float]:
        return [E / 100.0, 2.0 * nu - E / 400.0]

    store = [_stored(E, nu, 100.0, u(E, nu)) for E, nu in [(300, 0.3), (350, 0.3), (300, 0.2)]]
    store.append(_stored(320.0, 0.3, 60.0, [9.0, 9.0]))  # another rate: not used
    for E, nu in [(325.0, 0.25), (360.0, 0.3), (310.0, 0.32)]:
        assert np.allclose(_secant(store, {"E": E, "nu": nu}, 100.0), u(E, nu))
    # one input moved: the secant through the two nearest states
    line = [_stored(E, 0.3, 100.0, u(E, 0.3)) for E in (300.0, 350.0, 500.0)]
    assert np.allclose(_secant(line, {"E": 330.0, "nu": 0.3}, 100.0), u(330.0, 0.3))


def test_secant_prediction_refuses_what_it_cannot_span_or_would_extrapolate_far():
    from fbia.plugins.ale_fsi.model import _secant

    one = [_stored(300.0, 0.3, 100.0, [1.0])]
    assert _secant(one, {"E": 320.0, "nu": 0.3}, 100.0) is None  # one state: no secant
    line = [_stored(E, 0.3, 100.0, [E]) for E in (300.0, 350.0)]
    assert _secant(line, {"E": 320.0, "nu": 0.25}, 100.0) is None  # nu never moved
    assert _secant(line, {"E": 320.0, "nu": 0.3}, 60.0) is None  # no state at that rate
    # from the nearest state (350) along the span to 300: weight -2 at 450, -4 at 550
    assert _secant(line, {"E": 450.0, "nu": 0.3}, 100.0) is not None
    assert _secant(line, {"E": 550.0, "nu": 0.3}, 100.0) is None  # too far out
    twins = [_stored(300.0, 0.3, 100.0, [1.0]), _stored(300.0, 0.3, 100.0, [1.0])]
    assert _secant(twins, {"E": 320.0, "nu": 0.3}, 100.0) is None  # no span in E


def test_a_warm_run_between_two_states_starts_from_their_secant(tmp_path, monkeypatch):
    """Two runs without tangents, then one between them: started from the secant through
    their states it takes fewer Newton steps than from the nearest state, to the same
    interface."""
    import fbia.plugins.ale_fsi.model as ale_model

    coords = [{"inflow_rate": 100.0}]
    iterations, interfaces = {}, {}
    for kind in ("nearest", "secant"):
        if kind == "nearest":
            monkeypatch.setattr(ale_model, "_secant", lambda *a: None)
        else:
            monkeypatch.undo()
        m = AleFsiForwardModel(**COARSE)
        for E in (300.0, 350.0):
            m.solve({"E": E, "nu": 0.3}, coords, tmp_path)
        sol = m.solve({"E": 325.0, "nu": 0.3}, coords, tmp_path)
        assert sol.diagnostics["warm_start"] is True
        iterations[kind] = sol.diagnostics["newton_iterations"]
        interfaces[kind] = sol.interface(coords[0]).vertices
    assert iterations["secant"] < iterations["nearest"], iterations
    assert np.abs(interfaces["secant"] - interfaces["nearest"]).max() < 1e-9  # mm
