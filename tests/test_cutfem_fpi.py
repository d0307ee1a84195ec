"""The ``cutfem_fpi`` forward model on a coarse flow cell: physics checks and the protocol.

One coupled run of Paper A's poroelastic example (E = 300 Pa, nu = 0.3, phi0 = 0.25,
K = 1e-4 mm^2) at inflow 0, 50 and 100 mm^2/s on the coarse conformance mesh.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("xfem")

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
    assert len(d["aitken_factors"][0]) == d["coupling_iterations"][0] - 1
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
