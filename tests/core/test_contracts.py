"""The three extension contracts (issue 28 item 3): one written contract per extension point,
read by the registry and the conformance kit; the framework keeps an iterator's books; a
plugin is pickled by its options when it says so."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import fbia
from fbia.core.iteration import RunBook, drive
from fbia.core.protocols import contracts, required_methods
from fbia.testing import tiny_problem


def test_the_contracts_are_read_from_the_protocols_docstrings():
    """Every member with its role, in order; a default for the optional ones."""
    read = contracts()
    roles = {kind: [(m.name, m.role) for m in members] for kind, members in read.items()}
    common = [("Options", "required"), ("requires", "optional"),
              ("__init__(options)", "framework"), ("pickle_options_only", "optional")]  # fmt: skip
    for kind in ("forward_model", "measure", "iterator"):
        assert roles[kind][:4] == common
    assert [n for n, _ in roles["forward_model"][4:]] == [
        "numerics_version", "dim", "up_axis", "parameter_names()", "undeformed()",
        "solve(parameters, coordinates, workdir)", "tangent_inputs()", "prepare()",
        "warm_state()", "adopt_warm_state(state)", "example_parameters()", "example_options()",
    ]  # fmt: skip
    assert [n for n, r in roles["iterator"] if r == "framework"] == [
        "__init__(options)", "result.iterator, nfev, n_failed, evaluations",
        "run(problem, evaluator=None)",
    ]  # fmt: skip
    defaults = {m.name: m.default for m in read["measure"] if m.role == "optional"}
    assert defaults["requires"] == "()" and defaults["dims"] == "(2, 3)"
    assert defaults["mesh_dependent"] == "False"
    assert "a difference" == defaults["residuals_jvp(simulated, observation, dvertices)"]


def test_the_registry_requires_the_contracts_methods():
    assert required_methods("forward_model") == ["parameter_names", "solve"]
    assert required_methods("measure") == ["residuals", "distance"]
    assert required_methods("iterator") == ["steps"]

    class NoSteps(fbia.Configurable):
        class Options(fbia.PluginOptions):
            pass

        def run(self, problem, evaluator=None):
            return None

    class Plugin:
        @fbia.hookimpl
        def register_iterators(self, register):
            register("no_steps", NoSteps)

    with pytest.raises(fbia.PluginError, match="lacks method.*steps"):
        fbia.Registry.load(entry_points=False, extra=[Plugin()])


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
