"""Conformance of every registered plugin (fbia.testing), and proof that each check bites.

The first part is parametrized over the default registry, so a plugin added to any entry point
of the ``fbia`` group is checked without touching this file.  The second part runs the checks
on small doubles that break one rule each and asserts the check names that rule: a check that
cannot fail would prove nothing.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pytest
from pydantic import BaseModel, Field

import fbia
from fbia import testing as ft
from fbia.core.registry import default_registry

ENTRIES = {kind: fbia.list_plugins(kind) for kind in ("forward_model", "measure", "iterator")}


def _params(kind: str) -> list[Any]:
    return [pytest.param(e, id=e.name) for e in ENTRIES[kind]]


# ------------------------------------------------------------------------------------------
# Every registered plugin
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "entry", [pytest.param(e, id=f"{e.kind}:{e.name}") for e in fbia.list_plugins()]
)
def test_options_schema_rejects_unknown_keys(entry):
    names = ft.check_options(entry.factory)
    assert names == sorted(entry.factory.Options.model_fields)


@pytest.mark.parametrize("entry", _params("forward_model"))
def test_forward_model_conforms(entry, tmp_path):
    cls = entry.factory
    params, coords = ft.example_run(cls)
    model = default_registry().create("forward_model", entry.name, ft.example_options(cls))
    solution = ft.check_forward_model(model, params, coords, tmp_path)
    assert solution.covers(coords)


@pytest.mark.parametrize("entry", _params("forward_model"))
def test_forward_model_failure_is_a_forward_model_error(entry, tmp_path):
    cls = entry.factory
    params, coords = ft.example_run(cls)
    fail = ft.failing_run(cls, params)
    if fail is None:
        pytest.skip(f"{entry.name} has no failure_region option to fail on purpose")
    options, failing = fail
    model = default_registry().create(
        "forward_model", entry.name, {**ft.example_options(cls), **options}
    )
    ft.check_forward_model(model, params, coords, tmp_path, failing_parameters=failing)


@pytest.mark.parametrize("entry", _params("measure"))
def test_measure_conforms(entry):
    cls = entry.factory
    measure = default_registry().create("measure", entry.name, ft.example_options(cls))
    values = ft.check_measure(measure)  # in its dims, by its mesh_dependent
    assert all(v["farther"] > v["simulated"] > 0.0 for v in values.values())


@pytest.mark.parametrize("entry", _params("iterator"))
def test_iterator_conforms(entry, tmp_path):
    cls = entry.factory
    problem = ft.tiny_problem(failure_region={"E": (100.0, 130.0)})
    result = ft.check_iterator(
        lambda: default_registry().create("iterator", entry.name, ft.example_options(cls)),
        problem,
        tmp_path,
    )
    assert result.nfev > 0


def test_every_kind_has_a_registered_plugin():
    assert {kind: bool(entries) for kind, entries in ENTRIES.items()} == {
        "forward_model": True,
        "measure": True,
        "iterator": True,
    }


# ------------------------------------------------------------------------------------------
# Doubles: a good one of each kind, and variants that break one rule each
# ------------------------------------------------------------------------------------------
X = np.linspace(0.0, 1.0, 17)


class GoodModel(fbia.ForwardModelBase):
    """y = a (q / 100) x (1 - x) [mm]; fails (ForwardModelError) for a > 1 mm."""

    class Options(fbia.PluginOptions):
        scale: float = Field(1.0, description="multiplier of the amplitude [-]")

    def parameter_names(self) -> Sequence[str]:
        return ("a",)

    def curve(self, a: float, coordinate: Mapping[str, float]) -> np.ndarray:
        return np.c_[X, self.options.scale * a * coordinate["q"] / 100.0 * X * (1.0 - X)]

    def solve(self, parameters, coordinates, workdir):
        a = parameters["a"]
        if a > 1.0:
            raise fbia.ForwardModelError(f"a = {a} mm too large")
        pairs = [(c, fbia.Interface.polyline(self.curve(a, c))) for c in coordinates]
        return fbia.Solution.from_pairs(pairs)


GOOD_RUN = ({"a": 0.5}, [{"q": 50.0}, {"q": 100.0}])


class RaisesValueError(GoodModel):
    def solve(self, parameters, coordinates, workdir):
        if parameters["a"] > 1.0:
            raise ValueError("negative Jacobian")
        return super().solve(parameters, coordinates, workdir)


class MissesCoordinate(GoodModel):
    def solve(self, parameters, coordinates, workdir):
        return super().solve(parameters, coordinates[:1], workdir)


class Noisy(GoodModel):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.calls = 0

    def solve(self, parameters, coordinates, workdir):
        self.calls += 1
        return super().solve({"a": parameters["a"] * (1 + 1e-6 * self.calls)}, coordinates, workdir)


class OrderDependent(GoodModel):
    """Pairs the n-th result with the n-th coordinate of a sorted list (a classic bug)."""

    def solve(self, parameters, coordinates, workdir):
        ordered = sorted(coordinates, key=lambda c: c["q"])
        pairs = [
            (c, fbia.Interface.polyline(self.curve(parameters["a"], o)))
            for c, o in zip(coordinates, ordered, strict=True)
        ]
        return fbia.Solution.from_pairs(pairs)


class ChangesDirectory(GoodModel):
    def solve(self, parameters, coordinates, workdir):
        os.chdir(workdir)
        return super().solve(parameters, coordinates, workdir)


class MutatesParameters(GoodModel):
    def solve(self, parameters, coordinates, workdir):
        parameters["a"] = 0.25
        return super().solve(parameters, coordinates, workdir)


class NeverFails(GoodModel):
    def solve(self, parameters, coordinates, workdir):
        return super().solve({"a": min(parameters["a"], 1.0)}, coordinates, workdir)


class WithTangents(GoodModel):
    """Gives d vertices / da (the curve is linear in a); ``sign`` -1 gets it wrong."""

    sign = 1.0

    def tangent_inputs(self):
        return ["a"]

    def solve(self, parameters, coordinates, workdir, tangents=()):
        solution = super().solve(parameters, coordinates, workdir)
        for c in coordinates:
            gamma = solution.interface(c)
            slope = self.curve(1.0, c) - self.curve(0.0, c)
            gamma.tangents = {n: self.sign * slope for n in tangents}
        return solution


class WrongTangents(WithTangents):
    sign = -1.0


def test_check_forward_model_checks_tangents_against_differences(tmp_path):
    solution = ft.check_forward_model(WithTangents(), *GOOD_RUN, tmp_path)
    assert solution.interface({"q": 50.0}).tangents == {}  # the first run asks for none
    with pytest.raises(ft.ConformanceError, match=r"the tangent of a at \{'q': 50.0\} differs"):
        ft.check_forward_model(WrongTangents(), *GOOD_RUN, tmp_path)


def test_check_forward_model_passes_a_good_model(tmp_path):
    solution = ft.check_forward_model(
        GoodModel(), *GOOD_RUN, tmp_path, failing_parameters={"a": 2.0}
    )
    np.testing.assert_allclose(solution.interface({"q": 100.0}).vertices[8, 1], 0.125)


@pytest.mark.parametrize(
    ("model", "rule"),
    [
        (
            RaisesValueError(),
            r"raised ValueError: negative Jacobian instead of .*ForwardModelError",
        ),
        (MissesCoordinate(), r"returned NoneType instead of an Interface .*\{'q': 100.0\}"),
        (Noisy(), r"two runs with equal inputs differ at \{'q': 50.0\} by 6.25e-08 mm"),
        (OrderDependent(), r"two runs with equal inputs differ .* coordinates in reversed order"),
        (ChangesDirectory(), r"solve\(\) changed the current directory"),
        (MutatesParameters(), r"solve\(\) modified the parameters"),
        (NeverFails(), r"the run at \{'a': 2.0\} was expected to fail but did not"),
    ],
    ids=lambda v: None if isinstance(v, str) else type(v).__name__,
)
def test_check_forward_model_names_the_broken_rule(model, rule, tmp_path):
    cwd = os.getcwd()
    try:
        with pytest.raises(ft.ConformanceError, match=rule) as info:
            ft.check_forward_model(model, *GOOD_RUN, tmp_path, failing_parameters={"a": 2.0})
    finally:
        os.chdir(cwd)
    assert str(info.value).startswith(f"{__name__}.{type(model).__name__}: ")


def test_example_run_is_required_of_forward_models():
    with pytest.raises(ft.ConformanceError, match=r"GoodModel: provides no example_parameters"):
        ft.example_run(GoodModel)


def test_failing_run_moves_the_first_parameter_out_of_the_example_point():
    class WithRegion(GoodModel):
        class Options(fbia.PluginOptions):
            failure_region: dict[str, tuple[float, float]] | None = Field(
                None, description="parameters boxes where runs fail"
            )

    assert ft.failing_run(GoodModel, {"a": 0.5}) is None
    options, failing = ft.failing_run(WithRegion, {"a": 0.5, "b": 2.0})
    assert failing == {"a": pytest.approx(0.55), "b": 2.0}
    lo, hi = options["failure_region"]["a"]
    assert lo < 0.55 < hi and not lo <= 0.5 <= hi


class CentroidMeasure(fbia.MeasureBase):
    """Difference of the length/area-weighted centroids [mm]: a crude but honest measure."""

    class Options(fbia.PluginOptions):
        pass

    @staticmethod
    def centroid(gamma: fbia.Interface) -> np.ndarray:
        return (gamma.sizes[:, None] * gamma.centres).sum(axis=0) / gamma.measure

    def residuals(self, simulated, observation):
        return self.centroid(simulated) - self.centroid(observation.interface)

    def distance(self, simulated, observation):
        return float(np.linalg.norm(self.residuals(simulated, observation)))


class OffsetMeasure(CentroidMeasure):
    def distance(self, simulated, observation):
        return super().distance(simulated, observation) + 1e-3


class PerVertexMeasure(CentroidMeasure):
    """Distance of every simulated vertex to the nearest observed vertex (cpp-like)."""

    def residuals(self, simulated, observation):
        gaps = simulated.vertices[:, None, :] - observation.interface.vertices[None, :, :]
        return np.linalg.norm(gaps, axis=2).min(axis=1)

    def distance(self, simulated, observation):
        return float(np.linalg.norm(self.residuals(simulated, observation)))


class ElementCountMeasure(CentroidMeasure):
    """Scales the distance with the element count: mesh-dependent."""

    def distance(self, simulated, observation):
        n = len(simulated) / len(observation.interface)
        return n * super().distance(simulated, observation)


class ListMeasure(CentroidMeasure):
    def residuals(self, simulated, observation):
        return list(super().residuals(simulated, observation))


class BlindMeasure(CentroidMeasure):
    def residuals(self, simulated, observation):
        return np.zeros(observation.dim)

    def distance(self, simulated, observation):
        return 0.0


class SaturatingMeasure(CentroidMeasure):
    def distance(self, simulated, observation):
        return min(super().distance(simulated, observation), 0.005)


def test_check_measure_passes_a_good_measure_in_2d_and_3d():
    values = ft.check_measure(CentroidMeasure())
    assert sorted(values) == ["circle_2d", "line_2d", "mound_2d", "sphere_3d", "square_3d"]
    # the tilted line y = 0.02 + 0.02 x against y = 0: centroid shift (0, 0.03) mm
    assert values["line_2d"]["simulated"] == pytest.approx(0.03, rel=1e-12)
    assert values["line_2d"]["refined"] == pytest.approx(0.03, rel=1e-12)


@pytest.mark.parametrize(
    ("measure", "rule"),
    [
        (OffsetMeasure(), r"case 'line_2d': an interface is not at distance zero from itself"),
        (PerVertexMeasure(), r"residual length depends on the simulated mesh: 49 .*, 38 .*, 75"),
        (ElementCountMeasure(), r"re-meshing the same geometry changes the distance"),
        (ListMeasure(), r"residuals must be a 1-D numpy array, got list"),
        (BlindMeasure(), r"distance 0 between different interfaces"),
        (SaturatingMeasure(), r"case 'line_2d': a larger deviation gives no larger distance"),
    ],
    ids=lambda v: None if isinstance(v, str) else type(v).__name__,
)
def test_check_measure_names_the_broken_rule(measure, rule):
    with pytest.raises(ft.ConformanceError, match=rule):
        ft.check_measure(measure, dims=(2,))


def test_mesh_dependent_measures_skip_only_the_mesh_checks():
    values = ft.check_measure(PerVertexMeasure(), dims=(2,), mesh_dependent=True)
    assert values["line_2d"]["identical"] == 0.0
    with pytest.raises(ft.ConformanceError, match="not at distance zero"):
        ft.check_measure(OffsetMeasure(), dims=(2,), mesh_dependent=True)


def test_sample_interfaces_point_their_normals_into_the_fluid():
    assert np.allclose(ft.straight_line_2d().normals, [0.0, 1.0])
    circle = ft.circle_2d(radius=0.3, n=64)
    outward = circle.centres / np.linalg.norm(circle.centres, axis=1)[:, None]
    assert np.allclose(circle.normals, outward)  # a chord's normal is radial at its midpoint
    sphere = ft.sphere_3d(radius=0.3, subdivisions=2)
    assert len(sphere) == 320
    assert np.all(np.einsum("ij,ij->i", sphere.normals, sphere.centres) > 0.0)
    assert np.allclose(ft.square_3d(n=3).normals, [0.0, 0.0, 1.0])
    mound = ft.mound_2d(length=1.0, height=0.2, n=64)
    assert mound.vertices[32, 1] == pytest.approx(0.2) and mound.normals[32, 1] > 0.99


class GridIterator(fbia.IteratorBase):
    """Evaluates an n x n grid over the bounds, one row per step; x = the best point."""

    class Options(fbia.PluginOptions):
        n: int = Field(3, ge=2, description="grid points per parameter [-]")

    def points(self, problem):
        axes = [np.linspace(p.lower, p.upper, self.options.n) for p in problem.parameters]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
        return [problem.as_dict(g) for g in grid]

    def steps(self, problem, evaluator):
        records = []
        pts = self.points(problem)
        for k in range(0, len(pts), self.options.n):
            records += evaluator.evaluate(problem, pts[k : k + self.options.n])
            yield len(records)
        ok = [r for r in records if r.ok]
        best = min(ok, key=lambda r: r.distance)
        return fbia.Result(
            status="grid_done",
            success=True,
            message=f"evaluated all {len(records)} grid points",
            x={n: best.x[n] for n in problem.names},
            nfev=len(records),
            n_failed=len(records) - len(ok),
            iterator="grid",
            evaluations=records,
        )


class StepslessIterator(GridIterator):
    steps = None  # its contract requires steps(problem, evaluator)


class UnsavableIterator(GridIterator):
    def steps(self, problem, evaluator):
        result = yield from super().steps(problem, evaluator)
        result.info["model"] = problem.model
        return result


class GlobalRngIterator(GridIterator):
    def steps(self, problem, evaluator):
        np.random.random()  # noqa: NPY002 - the bug under test
        return (yield from super().steps(problem, evaluator))


class UnseededIterator(GridIterator):
    def points(self, problem):
        rng = np.random.default_rng()
        return [problem.as_dict(rng.uniform(problem.lower, problem.upper)) for _ in range(6)]


class OutOfBoundsIterator(GridIterator):
    def steps(self, problem, evaluator):
        result = yield from super().steps(problem, evaluator)
        result.x = {n: 2 * problem.upper[i] + 1 for i, n in enumerate(problem.names)}
        return result


class EagerIterator(GridIterator):
    def steps(self, problem, evaluator):
        gen = super().steps(problem, evaluator)
        try:
            while True:
                next(gen)
        except StopIteration as stop:
            return stop.value


@pytest.fixture
def toy_problem():
    q100 = {"q": 100.0}
    obs = fbia.Observation(fbia.Interface.polyline(GoodModel().curve(0.4, q100)), q100)
    return fbia.InverseProblem(
        model=GoodModel(),
        measure=CentroidMeasure(),
        observations=[obs],
        parameters=[fbia.Parameter("a", bounds=(0.0, 1.5))],
    )


def test_check_iterator_passes_a_good_iterator(toy_problem, tmp_path):
    result = ft.check_iterator(lambda: GridIterator(n=4), toy_problem, tmp_path)
    # grid 0, 0.5, 1, 1.5: a = 1.5 fails, the best of the others is 0.5 (truth 0.4)
    assert (result.nfev, result.n_failed, result.x) == (4, 1, {"a": 0.5})


@pytest.mark.parametrize(
    ("cls", "rule"),
    [
        (StepslessIterator, r"lacks the method\(s\) its contract requires: steps"),
        (UnsavableIterator, r"Result.to_dict\(\) is not plain JSON"),
        (GlobalRngIterator, r"used numpy's global random state"),
        (UnseededIterator, r"two runs with equal options differ"),
        (OutOfBoundsIterator, r"Result.x = \{'a': 4.0\} lies outside the bounds"),
        (EagerIterator, r"steps\(\) must be a generator, got Result"),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else None,
)
def test_check_iterator_names_the_broken_rule(cls, rule, toy_problem, tmp_path):
    state = np.random.get_state()  # noqa: NPY002 - restored: other tests see no difference
    try:
        with pytest.raises(ft.ConformanceError, match=rule):
            ft.check_iterator(lambda: cls(n=3), toy_problem, tmp_path)
    finally:
        np.random.set_state(state)  # noqa: NPY002


class LaxOptions(BaseModel):
    scale: float = Field(1.0, description="[-]")


class NoSchema(GoodModel):
    Options = LaxOptions  # type: ignore[assignment]


class Undocumented(GoodModel):
    class Options(fbia.PluginOptions):
        scale: float = 1.0


class SwallowsKeys(GoodModel):
    def __init__(self, options: Any = None, /, **kwargs: Any) -> None:
        known = {k: v for k, v in kwargs.items() if k in self.Options.model_fields}
        super().__init__(options, **known)


@pytest.mark.parametrize(
    ("cls", "rule"),
    [
        (NoSchema, r"NoSchema: has no Options schema"),
        (Undocumented, r"option\(s\) scale have no description"),
        (SwallowsKeys, r"SwallowsKeys\(\*\*options\) accepts the unknown key"),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else None,
)
def test_check_options_names_the_broken_rule(cls, rule):
    with pytest.raises(ft.ConformanceError, match=rule):
        ft.check_options(cls)


def test_check_options_passes_and_lists_the_options():
    assert ft.check_options(GoodModel) == ["scale"]


def test_checks_are_importable_without_pytest_running_them(tmp_path):
    """fbia.testing is usable from a plain script: the checks need no fixture."""
    assert ft.__name__ == "fbia.testing"
    assert ft.check_forward_model.__module__ == "fbia.testing.models"
    assert ft.check_forward_model(GoodModel(), *GOOD_RUN, tmp_path).covers(GOOD_RUN[1])


def test_fbia_testing_imports_and_checks_without_pytest():
    """A plugin author can run the conformance checks in a plain script (issue 29 item 8)."""
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['pytest'] = None\n"
        "import fbia, fbia.testing as ft\n"
        "import tempfile\n"
        "ft.check_forward_model(fbia.forward_model('analytic_mound_2d'), {'E': 400.0, "
        "'nu': 0.3}, [{'inflow_rate': 100.0}], tempfile.mkdtemp())\n"
        "print('ok')\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().endswith("ok")
