"""The three extension contracts (issue 28 item 3; as code, issue 48 item 3): each kind's
protocol holds what a plugin writes, its base what it may override with the defaults; the
registry, the conformance kit and the docs read the same classes; the framework keeps an
iterator's books; a plugin is pickled by its options when it says so."""

from __future__ import annotations

import pickle
import re

import numpy as np
import pytest
from _paths import ROOT

import fbia
from fbia.core.iteration import RunBook, drive
from fbia.core.protocols import missing_methods, required_methods
from fbia.testing import tiny_problem
from fbia.testing.contracts import contract_tables, contracts


def test_the_contracts_are_read_from_the_protocols_and_the_bases():
    """Every member with its role, in the order of the code; a default for the optional
    attributes; the framework's members are the ``@final`` ones."""
    read = contracts()
    roles = {kind: [(m.name, m.role) for m in members] for kind, members in read.items()}
    common = [("requires", "optional"), ("pickle_options_only", "optional"),
              ("example_options()", "optional")]  # fmt: skip
    assert roles["forward_model"][:3] == [
        ("Options", "required"), ("parameter_names()", "required"),
        ("solve(parameters, coordinates, workdir)", "required"),
    ]  # fmt: skip
    assert roles["measure"][3:6] == roles["iterator"][2:5] == common
    assert [n for n, _ in roles["forward_model"][6:]] == [
        "numerics_version", "up_axis", "dim", "undeformed()", "tangent_inputs()", "prepare()",
        "warm_state()", "adopt_warm_state(state)", "example_parameters()",
    ]  # fmt: skip
    assert [n for n, r in roles["iterator"] if r == "framework"] == [
        "seed", "run(problem, evaluator=None)"
    ]  # fmt: skip
    assert roles["evaluator"] == [
        ("evaluate(problem, points)", "required"), ("slots", "required")
    ]  # fmt: skip
    defaults = {m.name: m.default for m in read["measure"] if m.role == "optional"}
    assert defaults["requires"] == "()" and defaults["dims"] == "(2, 3)"
    assert defaults["mesh_dependent"] == "False"
    assert {m.name: m.default for m in read["iterator"]}["result_type"] == "Result"
    assert all(m.doc for members in read.values() for m in members)  # each one documented


def test_the_docs_member_tables_are_rendered_from_the_contracts():
    text = (ROOT / "docs" / "plugins.md").read_text(encoding="utf-8")
    found = re.search(r"<!-- contracts: begin [^>]*-->\n(.*)\n<!-- contracts: end -->", text, re.S)
    assert found, "docs/plugins.md has no generated member tables"
    assert found.group(1).strip() == contract_tables(), (
        "docs/plugins.md's member tables are stale; paste the output of python -c 'from "
        "fbia.testing.contracts import contract_tables; print(contract_tables())'"
    )


class _Minimal(fbia.ForwardModelBase):
    """A model that writes what its contract requires and nothing else."""

    class Options(fbia.PluginOptions):
        pass

    def parameter_names(self):
        return ["E"]

    def solve(self, parameters, coordinates, workdir):  # pragma: no cover - not run here
        raise fbia.ForwardModelError("not run")


def test_a_plugin_that_overrides_nothing_optional_has_the_bases_defaults():
    model = _Minimal()
    assert (model.dim, model.up_axis, model.numerics_version) == (None, None, None)
    assert (model.undeformed(), tuple(model.tangent_inputs()), model.warm_state()) == (
        None, (), None,
    )  # fmt: skip
    assert model.prepare() is None and model.adopt_warm_state(object()) is None
    assert _Minimal.example_parameters() is None and _Minimal.example_options() == {}
    measure = fbia.measure("ray")  # overrides dims, leaves the jvp to the framework
    observed = fbia.testing.circle_2d()
    assert measure.residuals_jvp(observed, None, observed.vertices) is None
    assert measure.measurements_per_observation is None and not measure.mesh_dependent
    it = fbia.iterator("levenberg_marquardt", x0={"E": 300.0, "nu": 0.2})
    assert it.write_files(None, ROOT) == [] and it.seed is None
    assert fbia.iterator("sobol_indices", seed=7).seed == 7  # its option, read by the base


def test_the_registry_requires_the_contracts_methods():
    assert required_methods("forward_model") == ["parameter_names", "solve"]
    assert required_methods("measure") == ["residuals", "distance"]
    assert required_methods("iterator") == ["steps"]
    assert missing_methods("forward_model", _Minimal) == []

    class NoSteps(fbia.IteratorBase):  # the protocol's stub, inherited, is not a method
        class Options(fbia.PluginOptions):
            pass

    assert missing_methods("iterator", NoSteps()) == ["steps"]

    class Plugin:
        @fbia.hookimpl
        def register_iterators(self, register):
            register("no_steps", NoSteps)

    with pytest.raises(fbia.PluginError, match="lacks method.*steps"):
        fbia.Registry.load(entry_points=False, extra=[Plugin()])


def test_an_inverse_problem_refuses_a_model_or_measure_off_its_base():
    problem = tiny_problem()

    class Plain:  # a duck-typed model, as fbia took it before issue 48
        def parameter_names(self):
            return problem.model.parameter_names()

        def solve(self, parameters, coordinates, workdir):  # pragma: no cover - refused first
            return problem.model.solve(parameters, coordinates, workdir)

    parts = dict(observations=problem.observations, parameters=problem.parameters)
    with pytest.raises(fbia.ConfigError, match=r"^the model Plain does not derive from fbia\.Fo"):
        fbia.InverseProblem(model=Plain(), measure=problem.measure, **parts)
    with pytest.raises(fbia.ConfigError, match=r"^the measure Plain does not derive from fbia\.Me"):
        fbia.InverseProblem(model=problem.model, measure=Plain(), **parts)


class _Silent(fbia.IteratorBase):
    """Asks for runs in three batches (one failing point among them) and counts nothing."""

    class Options(fbia.PluginOptions):
        pass

    def steps(self, problem, evaluator):
        for x in ([{"E": 300.0, "nu": 0.2}], [{"E": 400.0, "nu": 0.3}, {"E": 120.0, "nu": 0.3}]):
            evaluator.evaluate(problem, x)
            yield len(x)
        return fbia.Result(status="done", success=True, message="three runs")


def test_the_framework_stamps_the_books_on_a_result_whose_iterator_counted_nothing():
    problem = tiny_problem(failure_region={"E": (100.0, 150.0)})
    result = _Silent().run(problem)
    assert (result.nfev, result.n_failed) == (3, 1)
    assert [e.x["E"] for e in result.evaluations] == [300.0, 400.0, 120.0]
    assert result.iterator == "_Silent"  # not registered: its class name
    with fbia.SerialEvaluator() as ev:  # a book per drive: two drives on one evaluator
        first, again = drive(_Silent(), problem, ev), drive(_Silent(), problem, ev)
        assert first.nfev == again.nfev == 3 and again.evaluations[0].x["E"] == 300.0
        book = RunBook(ev)
        assert (book.nfev, book.n_failed, book.records) == (0, 0, [])  # its own, empty


def test_a_registered_iterator_gets_its_registered_name():
    problem = tiny_problem()
    it = fbia.iterator("sobol_indices", n_train=16, n_test=4, n_base=64, seed=0)
    result = it.run(problem)
    assert result.iterator == "sobol_indices"
    assert result.nfev == len(result.evaluations) > 0


def test_pickling_by_options_rebuilds_the_plugin_without_its_state():
    problem = tiny_problem(measure="ray")
    measure, obs = problem.measure, problem.observations[0]
    assert type(measure).pickle_options_only
    observed = obs.interface
    measure.residuals(observed, obs)  # fills its cache of rays
    copy = pickle.loads(pickle.dumps(measure))
    assert copy.options == measure.options and copy is not measure
    assert len(copy._rays) == 0 < len(measure._rays)
    np.testing.assert_array_equal(copy.residuals(observed, obs), measure.residuals(observed, obs))


def test_without_the_flag_a_plugin_pickles_its_whole_state():
    it = fbia.iterator("levenberg_marquardt", x0={"E": 300.0, "nu": 0.2})
    assert not type(it).pickle_options_only
    it.note = [1, 2, 3]
    copy = pickle.loads(pickle.dumps(it))
    assert copy.note == [1, 2, 3] and copy.options == it.options


def test_an_iterators_own_count_gives_way_to_the_books():
    class Lying(_Silent):
        def steps(self, problem, evaluator):
            result = yield from super().steps(problem, evaluator)
            result.nfev, result.n_failed, result.iterator = 99, 0, "other"
            return result

    problem = tiny_problem(failure_region={"E": (100.0, 150.0)})
    result = Lying().run(problem)
    assert (result.nfev, result.n_failed) == (3, 1)
    assert result.iterator == "other"  # unregistered and not named: what it said
    with fbia.SerialEvaluator() as ev:
        named = drive(Lying(), problem, ev, name="lying")  # as fbia run names it
    assert (named.nfev, named.iterator) == (3, "lying")


def test_settings_are_derived_from_options_in_one_place():
    """``settings_from``: same-named options, renamed ones, explicit values, defaults; a stale
    name is an error, not a silently ignored option."""
    import dataclasses

    from fbia.core.options import settings_from

    @dataclasses.dataclass(frozen=True)
    class Settings:
        tol: float = 1.0
        order: int = 2
        kind: str = "a"
        extra: int = 7

    class Options(fbia.PluginOptions):
        tol: float = 1e-6
        solver_order: int = 3
        kind: str = "b"

    o = Options()
    assert settings_from(o, Settings, {"order": "solver_order"}) == Settings(1e-6, 3, "b", 7)
    assert settings_from(o, Settings, kind="c").kind == "c"
    with pytest.raises(TypeError, match="no such field or option: ordr"):
        settings_from(o, Settings, {"ordr": "solver_order"})
    with pytest.raises(TypeError, match="no such field or option: order_of_solver"):
        settings_from(o, Settings, {"order": "order_of_solver"})
