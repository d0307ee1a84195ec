"""The ``cutfem_fpi`` forward model on a coarse flow cell: physics checks and the protocol.

One coupled run of Paper A's poroelastic example (E = 300 Pa, nu = 0.3, phi0 = 0.25,
K = 1e-4 mm^2) at inflow 0, 50 and 100 mm^2/s on the coarse conformance mesh.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("xfem")

import fbia  # noqa: E402
from fbia.core.errors import ConfigError, ForwardModelError  # noqa: E402
from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel  # noqa: E402

LEVELS = [{"inflow_rate": 100.0}, {"inflow_rate": 0.0}, {"inflow_rate": 50.0}]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    model = CutFemFpiForwardModel(**CutFemFpiForwardModel.example_options())
    params = {"E": 300.0, "nu": 0.3, "phi0": 0.25, "K": 1e-4}
    sol = model.solve(params, LEVELS, tmp_path_factory.mktemp("cutfem"))
    return model, sol


def test_zero_inflow_gives_zero_deformation(run) -> None:  # type: ignore[no-untyped-def]
    model, sol = run
    ref = model.solver.sampler.reference
    assert np.array_equal(sol.interface(LEVELS[1]).vertices, ref)
    assert sol.diagnostics["max_displacement"][1] == 0.0
    assert sol.diagnostics["porosity_range"][1] == pytest.approx([0.25, 0.25], abs=1e-12)


def test_undeformed_is_the_reference_and_points_go_where_it_moved(run) -> None:  # type: ignore[no-untyped-def]
    """undeformed(): point for point the zero-inflow interface; with it, synthetic points can
    be placed where the interface moved (Paper A Fig. 16: where it moves most)."""
    model, sol = run
    rest = model.undeformed()
    assert np.array_equal(rest.vertices, sol.interface(LEVELS[1]).vertices) and model.dim == 2
    moved = sol.interface(LEVELS[0]).vertices - rest.vertices
    u_n = np.abs(np.sum(moved * sol.interface(LEVELS[0]).vertex_normals, axis=1))
    (obs,) = fbia.synthetic_observations(
        model,
        {"E": 300.0, "nu": 0.3, "phi0": 0.25, "K": 1e-4},
        LEVELS[:1],
        0.0,
        1,
        points=6,
        placement="displacement",
    )
    pts = obs.measurement_points.points
    nearest = np.argmin(np.linalg.norm(rest.vertices[None] - pts[:, None], axis=2), axis=1)
    assert len(pts) == 6 and np.all(u_n[nearest] >= 0.4 * u_n.max())  # 0.5: the edges' own


def test_biofilm_bends_downstream_more_with_more_flow(run) -> None:  # type: ignore[no-untyped-def]
    model, sol = run
    ref = model.solver.sampler.reference
    d100 = sol.interface(LEVELS[0]).vertices - ref
    d50 = sol.interface(LEVELS[2]).vertices - ref
    top = np.argmax(ref[:, 1])
    assert d100[top, 0] > 0.02 and d50[top, 0] > 0.005  # mm, towards the outflow
    assert d100[top, 0] > 2.0 * d50[top, 0]  # inertia: more than linear in the inflow
    assert np.all(np.abs(d100[[0, -1]]) < 1e-12)  # the feet are clamped


def test_conservation(run) -> None:  # type: ignore[no-untyped-def]
    """Inflow = outflow, and the net flux into the biofilm vanishes (steady pore fluid)."""
    _, sol = run
    for rate, (q_in, q_out), net in zip(
        (100.0, 0.0, 50.0),
        sol.diagnostics["inflow_outflow_flux"],
        sol.diagnostics["interface_flux"],
        strict=True,
    ):
        assert q_in == pytest.approx(rate, abs=1e-9 * 100)
        assert q_out == pytest.approx(rate, abs=1e-9 * 100)
        assert abs(net) < 1e-10 * 100


def test_porosity_opens_upstream_closes_downstream(run) -> None:  # type: ignore[no-untyped-def]
    """Paper A Fig. 14b: stretched upstream part opens, compressed downstream foot closes."""
    model, _ = run  # the solver holds the last level solved: 100 mm^2/s
    sk = model.solver.skeleton
    up = float(sk.porosity(sk.mesh(0.6, 0.15)))
    down = float(sk.porosity(sk.mesh(1.15, 0.05)))
    assert up > 0.3 > 0.25 > down


def test_coupling_diagnostics(run) -> None:  # type: ignore[no-untyped-def]
    _, sol = run
    d = sol.diagnostics
    assert d["coupling_iterations"][1] == 1
    assert 2 <= d["coupling_iterations"][0] <= 20
    assert len(d["relaxation_factors"][0]) == d["coupling_iterations"][0] - 1
    assert len(d["interface_changes"][0]) == d["coupling_iterations"][0]
    assert d["interface_changes"][0][-1] < 1e-5 < d["interface_changes"][0][0]  # coupling_tol
    assert d["ndof_flow"] > 1000 and d["ndof_skeleton"] > 100
    assert set(d["time_split"]) == {"level_set", "flow", "skeleton", "transfer"}


def test_quasi_2d_coordinate_equals_plane_rate(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Paper A: 1 mm^3/s over a 0.01 mm thick channel is 100 mm^2/s in plane strain."""
    model = CutFemFpiForwardModel(**CutFemFpiForwardModel.example_options())
    assert model._levels([{"inflow_volume_rate": 1.0}], {"inflow_rate": 0.0}) == [100.0]
    with pytest.raises(ConfigError, match="inflow_rate"):
        model._levels([{"time": 1.0}], {"inflow_rate": 0.0})


def test_bad_input() -> None:
    with pytest.raises(ConfigError, match="voxel_sise"):
        CutFemFpiForwardModel(voxel_sise=0.1)
    model = CutFemFpiForwardModel(**CutFemFpiForwardModel.example_options())
    with pytest.raises(ConfigError, match="unknown parameter"):
        model.solve({"Young": 1.0}, [{}], ".")
    with pytest.raises(ForwardModelError, match="phi0"):
        model.solve({"phi0": 1.2}, [{}], ".")
    bad_outlines = {
        "floor": [(0.5, 0.1), (0.8, 0.3), (1.1, 0.0)],
        "upstream": [(1.1, 0.0), (0.8, 0.3), (0.5, 0.0)],
        "itself": [(0.5, 0.0), (1.0, 0.3), (0.6, 0.3), (0.9, 0.1), (1.1, 0.0)],
    }
    for match, outline in bad_outlines.items():
        with pytest.raises(ConfigError, match=match):
            _ = CutFemFpiForwardModel(outline=outline).solver
    # a named outline, as ale_fsi takes it (the poroelastic example: "paper_a_facts"); an
    # unknown name is named in the error with the names there are
    from fbia.plugins.fem.outlines import NAMED_OUTLINES

    named = CutFemFpiForwardModel(outline="paper_a_facts")._outline()
    np.testing.assert_array_equal(named, np.array(NAMED_OUTLINES["paper_a_facts"]))
    with pytest.raises(ConfigError, match="unknown outline 'paper_b'; named outlines: fig2"):
        CutFemFpiForwardModel(outline="paper_b")


def test_protocol_conformance(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from fbia.testing import check_forward_model

    model = CutFemFpiForwardModel(**CutFemFpiForwardModel.example_options())
    params, coords = CutFemFpiForwardModel.example_parameters()
    check_forward_model(model, params, coords[1:], tmp_path, failing_parameters={"phi0": 1.5})


def test_registers_through_hook() -> None:
    import fbia.plugins.cutfem_fpi as pkg

    got = {}
    pkg.register_forward_models(lambda name, cls: got.setdefault(name, cls))
    assert got == {"cutfem_fpi": CutFemFpiForwardModel}


def test_curved_biofilm_mesh_follows_the_outline_spline() -> None:
    """Interface samples of the biofilm mesh (h = 0.08 mm) against a fine one: straight sides
    miss the spline by ~5 um, second- and third-order geometry by ~1 and ~0.07 um."""
    import shapely

    from fbia.plugins.cutfem_fpi.coupled import InterfaceSampler
    from fbia.plugins.cutfem_fpi.meshes import biofilm_mesh
    from fbia.plugins.cutfem_fpi.model import POROELASTIC_OUTLINE
    from fbia.plugins.fem.outlines import NAMED_OUTLINES

    outline = np.array(NAMED_OUTLINES[POROELASTIC_OUTLINE])
    fine = InterfaceSampler(biofilm_mesh(outline, True, 0.01, 3), 4).reference
    line = shapely.LineString(fine)
    errors = []
    for order in (1, 2, 3):
        pts = InterfaceSampler(biofilm_mesh(outline, True, 0.08, order), 4).reference
        assert np.allclose(pts[[0, -1]], outline[[0, -1]], atol=1e-12)  # upstream foot first
        errors.append(float(np.max(shapely.distance(line, shapely.points(pts)))))
    assert errors[0] > 4 * errors[1] > 40 * errors[2]
    assert errors[1] < 1.5e-3


def test_quasi_newton_and_inexact_coupling_agree_with_exact_aitken(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The default coupling (IQN-ILS, inexact Newton solves) and exact Aitken iterations
    (every flow and skeleton solve converged to its final tolerance) reach the same
    interface to within the coupling tolerance; the quasi-Newton needs fewer iterations."""
    import shapely

    opts = {**CutFemFpiForwardModel.example_options(), "coupling_tol": 1e-7}
    params = {"E": 300.0, "nu": 0.3, "phi0": 0.25, "K": 1e-4}
    level = [{"inflow_rate": 100.0}]
    sols = {}
    for name, extra in (
        ("iqn", {}),
        ("aitken", {"acceleration": "aitken", "coupling_inexact": 0.0}),
    ):
        model = CutFemFpiForwardModel(**opts, **extra)
        sols[name] = model.solve(params, level, tmp_path)
    a, b = (shapely.LineString(s.interface(level[0]).vertices) for s in sols.values())
    assert shapely.hausdorff_distance(a, b) < 1e-7  # mm, the coupling tolerance
    its = {k: s.diagnostics["coupling_iterations"][0] for k, s in sols.items()}
    assert its["iqn"] < its["aitken"]


def test_transfer_to_the_background_is_linear_inside_and_continuous_outside() -> None:
    """Permeability/porosity move to the background vertices by linear interpolation on the
    deformed skeleton mesh (exact for a field linear in the deformed position) and, outside
    it, take the value at the closest boundary point, so the transfer has no jumps."""
    import ngsolve as ngs
    import shapely

    model = CutFemFpiForwardModel(**CutFemFpiForwardModel.example_options())
    solver = model.solver
    sk = solver.skeleton
    sk.displacement.Set(ngs.CF((0.05 * ngs.y**2, -0.02 * ngs.x * ngs.y)))
    d = sk.displacement
    X, Y = ngs.x + d[0], ngs.y + d[1]
    fields = (1.0 + 2.0 * X - Y, 0.5 * X, 3.0 * Y, X + Y)
    solver._k_cf = ngs.CF(fields)
    solver._to_background()
    got = np.c_[solver.k_bg.vec.FV().NumPy().reshape(-1, 3), solver.phi_bg.vec.FV().NumPy()]
    P = solver._bg_vertices

    def linear(q: np.ndarray) -> np.ndarray:
        x, y = q[:, 0], q[:, 1]
        return np.c_[1.0 + 2.0 * x - y, 0.5 * x, 3.0 * y, x + y]

    verts = solver._sk_vertices + np.asarray(d(solver._sk_points)).reshape(-1, 2)
    tris = shapely.MultiPolygon([shapely.Polygon(verts[t]) for t in solver._sk_triangles])
    body = shapely.union_all(tris.geoms)
    inside = shapely.contains_xy(body, P[:, 0], P[:, 1])
    assert inside.sum() > 20
    assert np.allclose(got[inside], linear(P[inside]), atol=1e-12)
    outside = ~inside & (shapely.distance(body, shapely.points(P)) < 0.2)
    closest = shapely.get_coordinates(
        shapely.shortest_line(body.boundary, shapely.points(P[outside]))
    )[::2]
    assert np.allclose(got[outside], linear(closest), atol=1e-9)


def test_vtu_fields(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """write_vtu: one background and one skeleton file per coordinate, with the documented
    point data, consistent with the diagnostics."""
    import meshio

    model = CutFemFpiForwardModel(**CutFemFpiForwardModel.example_options(), write_vtu=True)
    sol = model.solve({}, [{"inflow_rate": 100.0}], tmp_path)
    flow = meshio.read(sol.fields["vtu_flow_0"])
    skel = meshio.read(sol.fields["vtu_skeleton_0"])
    assert set(flow.point_data) == {
        "velocity",
        "pressure",
        "pore_pressure",
        "level_set",
        "porosity",
    }
    assert set(skel.point_data) == {"displacement", "porosity", "pore_pressure"}
    dmax = sol.diagnostics["max_displacement"][0]
    vertex_max = np.max(np.linalg.norm(skel.point_data["displacement"], axis=1))
    assert 0.9 * dmax < vertex_max < 1.01 * dmax
    assert np.all(flow.point_data["velocity"][flow.point_data["level_set"] < 0] == 0.0)
