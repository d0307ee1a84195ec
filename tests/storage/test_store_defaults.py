"""A release that changes an option's default never reuses the runs made with the old one, and
a study that pins the old value reuses them (issue 44 item 1).

The plugin is a third party's package written into the test's folder (``gain_plugin``: a model
with an option ``gain``, default 0.5, and a measure with an option ``scale``, both declaring
``numerics_version = "1"``), imported again after every edit, as its author would release it;
a new release is the package's version moved on (``_package_version``, as in
test_store_code.py), so the code check accepts the edited code as "another release, the same
numerics".  Before issue 44 the store keyed options by their difference from the current
defaults: a study relying on the default reused 3 runs made with gain = 0.5 for gain = 1.0.
"""

from __future__ import annotations

import importlib
import json
import re
import sqlite3
import sys
from types import ModuleType

import pytest
from _models import PLUGIN, toy_problem

import fbia
from fbia.core.hookspecs import hookimpl
from fbia.core.options import plugin_options
from fbia.core.problem import jsonable
from fbia.core.registry import Registry
from fbia.storage import fingerprints
from fbia.storage.fingerprints import (
    canonical,
    comparison_key,
    comparison_part,
    coordinates_of,
    model_part,
    problem_fingerprint,
)
from fbia.storage.migration import rekey
from fbia.storage.store import StudyStore
from fbia.studies import study_file as study_module
from fbia.studies.cli import main

POINTS = [{"E": 200.0, "nu": 0.1}, {"E": 400.0, "nu": 0.3}, {"E": 700.0, "nu": 0.2}]

MODEL = """\
from pydantic import Field

from _models import ToyMoundForwardModel


class Gained(ToyMoundForwardModel):
    numerics_version = "1"

    class Options(ToyMoundForwardModel.Options):
        gain: float = Field({gain}, gt=0, description="factor on the modulus [-]")
{options}

    def solve(self, parameters, coordinates, workdir):
        parameters = {{**parameters, "E": self.options.gain * parameters["E"]}}
        return super().solve(parameters, coordinates, workdir)
"""

MEASURE = """\
from pydantic import Field

from _models import VerticalMeasure


class Scaled(VerticalMeasure):
    numerics_version = "1"

    class Options(VerticalMeasure.Options):
        scale: float = Field({scale}, gt=0, description="factor on the residuals [-]")
"""


@pytest.fixture
def release(tmp_path, monkeypatch):
    """``release(version, gain=..., options=..., scale=...)``: write the package
    ``gain_plugin`` with these defaults (``options``: more option lines of the model) as its
    release ``version``, and import it afresh."""
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    folder = tmp_path / "gain_plugin"
    folder.mkdir()

    def forget():
        for name in [m for m in sys.modules if m.split(".")[0] == "gain_plugin"]:
            del sys.modules[name]

    def write(version: str, gain: str = "0.5", options: str = "", scale: str = "1.0") -> ModuleType:
        (folder / "__init__.py").write_text(
            "from .measure import Scaled\nfrom .model import Gained\n"
        )
        (folder / "model.py").write_text(MODEL.format(gain=gain, options=options))
        (folder / "measure.py").write_text(MEASURE.format(scale=scale))
        forget()
        importlib.invalidate_caches()
        monkeypatch.setattr(fingerprints, "_package_version", lambda obj: version)
        return importlib.import_module("gain_plugin")

    yield write
    forget()


def _problem(plugin: ModuleType, measure: dict | None = None, **options) -> fbia.InverseProblem:
    base = toy_problem()
    return fbia.InverseProblem(
        model=plugin.Gained(**options),
        measure=plugin.Scaled(**(measure or {})),
        observations=base.observations,
        parameters=base.parameters,
    )


def _evaluate(path, problem, **bind):
    """(indices reused, runs in the store, distances) of the three POINTS."""
    with StudyStore(path) as store:
        store.bind(problem, **bind)
        with fbia.SerialEvaluator(store=store) as ev:
            records = ev.evaluate(problem, POINTS)
            return set(ev.reused), len(store), [r.distance for r in records]


def _meta(path, key):
    with sqlite3.connect(path) as db:
        row = db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
    return None if row is None else row[0]


CHANGED = "model options (gain: 0.5 (default then) -> 1.0 (default now))"
PIN = "set gain = 0.5 in the model's options to reuse them, run with --fresh"


@pytest.mark.parametrize("reuse_changed_code", [False, True])
def test_a_changed_default_is_another_model_and_pinning_the_old_value_reuses_the_runs(
    tmp_path, release, reuse_changed_code
):
    path = tmp_path / "s.sqlite"
    first = release("1.0.0")
    reused, n, made = _evaluate(path, _problem(first))
    assert (reused, n) == (set(), 3)
    second = release("1.1.0", gain="1.0")  # same numerics_version, another default
    for study in (_problem(second), _problem(second, gain=1.0)):  # relying on it, or set
        assert plugin_options(study.model, exclude_defaults=True) == {}
        with pytest.raises(fbia.ConfigError) as info:
            _evaluate(path, study, reuse_changed_code=reuse_changed_code)
        message = str(info.value)
        assert message.startswith(f"{path}: the store holds 3 runs of a different model ")
        assert f"(changed: {CHANGED}); they cannot be reused: {PIN}" in message
        assert "\n" not in message
    # the new default gives other numbers: a fresh store runs them
    reused, n, fresh = _evaluate(tmp_path / "fresh.sqlite", _problem(second))
    assert (reused, n) == (set(), 3) and fresh != made
    # the runs' value pinned: every run reused, with its numbers, and nothing added
    assert _evaluate(path, _problem(second, gain=0.5)) == ({0, 1, 2}, 3, made)


def test_the_new_value_set_explicitly_after_an_edit_is_refused_with_reuse_changed_code(
    tmp_path, release
):
    """An edit without a release: --reuse-changed-code waives the code check, never the
    options' values."""
    path = tmp_path / "s.sqlite"
    assert _evaluate(path, _problem(release("1.0.0")))[:2] == (set(), 3)
    edited = release("1.0.0", gain="1.0")
    with pytest.raises(fbia.ConfigError, match=r"made by other code of the model plugin"):
        _evaluate(path, _problem(edited, gain=0.5))  # the code check stands
    with pytest.raises(fbia.ConfigError, match=re.escape(CHANGED)):
        _evaluate(path, _problem(edited, gain=1.0), reuse_changed_code=True)
    reused, n, _ = _evaluate(path, _problem(edited, gain=0.5), reuse_changed_code=True)
    assert (reused, n) == ({0, 1, 2}, 3)


def test_a_new_option_with_a_default_keeps_every_run_and_another_value_is_refused(
    tmp_path, release
):
    path = tmp_path / "s.sqlite"
    _, _, made = _evaluate(path, _problem(release("1.0.0")))
    grown = release(
        "1.1.0", options='        offset: float = Field(0.0, description="a new option [-]")'
    )
    assert _evaluate(path, _problem(grown)) == ({0, 1, 2}, 3, made)
    assert json.loads(_meta(path, "model"))["model"]["options"]["offset"] == 0.0
    with pytest.raises(
        fbia.ConfigError, match=r"model options \(offset: 0.0 \(default then\) -> 0.5\)\)"
    ):
        _evaluate(path, _problem(grown, offset=0.5))


def test_a_removed_option_keeps_the_runs_made_at_its_default_only(tmp_path, release):
    offset = '        offset: float = Field(0.0, description="an option removed later [-]")'
    at_default, set_ = tmp_path / "default.sqlite", tmp_path / "set.sqlite"
    _, _, made = _evaluate(at_default, _problem(release("1.0.0", options=offset)))
    _evaluate(set_, _problem(release("1.0.0", options=offset), offset=0.5))
    shrunk = release("1.1.0")
    assert _evaluate(at_default, _problem(shrunk)) == ({0, 1, 2}, 3, made)
    with pytest.raises(fbia.ConfigError, match=r"\(offset: 0.5 -> \(no such option now\)\)"):
        _evaluate(set_, _problem(shrunk))


def test_a_changed_measure_default_compares_the_stored_runs_anew(tmp_path, release):
    path = tmp_path / "s.sqlite"
    _, _, made = _evaluate(path, _problem(release("1.0.0")))
    reused, n, now = _evaluate(path, _problem(release("1.1.0", scale="2.0")))
    assert (reused, n) == ({0, 1, 2}, 3)  # no forward run: their interfaces are stored
    assert now == [2.0 * d for d in made]
    assert _evaluate(path, _problem(release("1.1.0", scale="2.0"), {"scale": 1.0}))[2] == made


def _as_an_earlier_fbia_wrote_it(path, problem) -> None:
    """Rewrite the store at ``path``, bound to ``problem``, as fbia wrote it before issue 44:
    the keys, the model part and the problem fingerprint with the options that differ from
    their defaults only, and no ``model_defaults``."""
    fingerprint = problem_fingerprint(problem)
    old = json.loads(canonical(fingerprint))
    for plugin in ("model", "measure"):
        part = old[plugin]
        defaults = part.pop("defaults")
        part["options"] = {k: v for k, v in part["options"].items() if k not in defaults}
    # what fbia.storage.fingerprints._options keyed before issue 44
    earlier = jsonable(plugin_options(problem.model, exclude_defaults=True))
    assert old["model"]["options"] == json.loads(canonical(earlier))
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("BEGIN")
    comparisons = (
        comparison_key(comparison_part(fingerprint)),
        comparison_key(comparison_part(old)),
    )
    coordinates = coordinates_of(fingerprint)
    assert rekey(db, model_part(fingerprint), coordinates, model_part(old), comparisons) == 3
    db.execute("UPDATE meta SET value = ? WHERE key = 'problem'", (canonical(old),))
    db.execute("COMMIT")
    db.close()


def test_a_store_of_an_earlier_fbia_is_rekeyed_while_the_code_is_unchanged(tmp_path, release):
    path = tmp_path / "s.sqlite"
    first = release("1.0.0")
    _, _, made = _evaluate(path, _problem(first, delay=0.0, fail_above=650.0))
    _as_an_earlier_fbia_wrote_it(path, _problem(first, fail_above=650.0))
    assert _meta(path, "model_defaults") is None
    # the same code: no default can have changed, the runs are re-keyed with every value
    problem = _problem(release("1.0.0"), fail_above=650.0)
    assert _evaluate(path, problem) == ({0, 1, 2}, 3, made)
    assert _meta(path, "model") == canonical(model_part(problem_fingerprint(problem)))
    assert "gain" in json.loads(_meta(path, "model_defaults"))


@pytest.mark.parametrize("reuse_changed_code", [False, True])
def test_a_store_of_an_earlier_fbia_is_refused_once_the_code_changed(
    tmp_path, release, reuse_changed_code
):
    """Whether the new release changed a default the runs relied on cannot be told from a
    store that recorded the options differing from their defaults only."""
    path = tmp_path / "s.sqlite"
    first = release("1.0.0")
    _evaluate(path, _problem(first))
    _as_an_earlier_fbia_wrote_it(path, _problem(first))
    for second in (release("1.1.0", gain="1.0"), release("1.1.0", gain="0.50")):
        with pytest.raises(fbia.ConfigError) as info:
            _evaluate(path, _problem(second, gain=0.5), reuse_changed_code=reuse_changed_code)
        message = str(info.value)
        assert message.startswith(f"{path}: the store holds 3 runs keyed by an earlier fbia by ")
        assert "gain_plugin.model.Gained changed since (model.py)" in message
        assert "whether a default they relied on changed cannot be checked" in message
        assert "--fresh" in message and "\n" not in message
    # with the code that made them, the store is re-keyed; then the release is checked as usual
    assert _evaluate(path, _problem(release("1.0.0")))[:2] == ({0, 1, 2}, 3)
    with pytest.raises(fbia.ConfigError, match=re.escape(CHANGED)):
        _evaluate(path, _problem(release("1.1.0", gain="1.0")))


STUDY = """\
[model]
name = "gained"
options = {{ {options} }}

[[parameters]]
name = "E"
bounds = [100.0, 800.0]

[[parameters]]
name = "nu"
bounds = [-0.8, 0.5]

[synthetic]
truth = {{ E = 400.0, nu = 0.3 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]

[measure]
name = "vertical"

[iterator]
name = "grid"

[executor]
kind = "serial"
"""


def test_fbia_run_refuses_a_changed_default_and_resumes_with_the_old_value_pinned(
    tmp_path, release, monkeypatch, capsys
):
    """The hostile tester's case from the command line: after the release, the study file
    setting the new value (or relying on it) is refused in one line, with or without
    --reuse-changed-code, and is never told that "its model did not" change."""
    monkeypatch.chdir(tmp_path)

    def registered(plugin: ModuleType) -> None:
        class Gained:
            @hookimpl
            def register_forward_models(self, register):
                register("gained", plugin.Gained)

        registry = Registry.load(extra=[PLUGIN, Gained()])
        monkeypatch.setattr(study_module, "default_registry", lambda: registry)

    def run(options: str, *flags: str) -> tuple[int, str, str]:
        (tmp_path / "study.toml").write_text(STUDY.format(options=options))
        status = main(["run", "study.toml", *flags])
        out, err = capsys.readouterr()
        return status, out, err

    registered(release("1.0.0"))
    assert run("")[0] in (0, 3)
    with sqlite3.connect(tmp_path / "output" / "store.sqlite") as db:
        n = db.execute("SELECT count(*) FROM runs").fetchone()[0]
    assert n == 9
    registered(release("1.1.0", gain="1.0"))
    for options, flags in (("", ()), ("gain = 1.0", ("--reuse-changed-code",))):
        status, out, err = run(options, *flags)
        assert status == 2 and "its model did not" not in out
        assert err.startswith("fbia: error: output/store.sqlite: the store holds 9 runs of a ")
        assert CHANGED in err and err.count("\n") == 1
    status, out, _ = run("gain = 0.5")
    assert status in (0, 3)
    assert "resuming: output/store.sqlite holds 9 forward runs of this model" in out
    assert "9 taken from the store" in out
