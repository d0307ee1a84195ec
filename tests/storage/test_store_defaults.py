"""A release that changes an option's default never reuses the runs made with the old one: it
reruns them, beside them in the same store, and a study that pins the old value reuses them
(issue 44 item 1).

The plugin is a third party's package written into the test's folder (``gain_plugin``: a model
with an option ``gain``, default 0.5, and a measure with an option ``scale``, both declaring
``numerics_version = "1"``), imported again after every edit, as its author would release it;
a new release is the package's version moved on (``_package_version``, as in
test_store_code.py), so the code check accepts the edited code as "another release, the same
numerics".  Before issue 44 the store keyed options by their difference from the current
defaults: a study relying on the default reused 3 runs made with gain = 0.5 for gain = 1.0.
A store holds the runs of one model class at any option values, each run under its model part
(column ``runs.model``, table ``models``).
"""

from __future__ import annotations

import importlib
import json
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
    """(indices reused, runs of this model in the store, distances) of the three POINTS."""
    with StudyStore(path) as store:
        store.bind(problem, **bind)
        with fbia.SerialEvaluator(store=store) as ev:
            records = ev.evaluate(problem, POINTS)
            return set(ev.reused), len(store), [r.distance for r in records]


def _per_model(path) -> list[int]:
    """The number of runs of each model part in the store, in the order first bound."""
    with sqlite3.connect(path) as db:
        rows = db.execute(
            "SELECT count(r.id) FROM models m LEFT JOIN runs r ON r.model = m.key "
            "GROUP BY m.key ORDER BY m.rowid"
        ).fetchall()
        orphans = db.execute("SELECT count(*) FROM runs WHERE model IS NULL").fetchone()[0]
    assert orphans == 0
    return [n for (n,) in rows]


def _meta(path, key):
    with sqlite3.connect(path) as db:
        row = db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
    return None if row is None else row[0]


@pytest.mark.parametrize("reuse_changed_code", [False, True])
def test_a_changed_default_reruns_the_runs_and_pinning_the_old_value_reuses_them(
    tmp_path, release, reuse_changed_code
):
    path = tmp_path / "s.sqlite"
    first = release("1.0.0")
    reused, n, made = _evaluate(path, _problem(first))
    assert (reused, n) == (set(), 3)
    second = release("1.1.0", gain="1.0")  # same numerics_version, another default
    relying = _problem(second)
    assert plugin_options(relying.model, exclude_defaults=True) == {}
    # relying on the new default: every run again, with the new default's numbers
    reused, n, now = _evaluate(path, relying, reuse_changed_code=reuse_changed_code)
    assert (reused, n) == (set(), 3) and now != made
    assert _evaluate(tmp_path / "fresh.sqlite", _problem(second))[2] == now
    assert _per_model(path) == [3, 3]
    # the new value set: the same model part as relying on it
    assert _evaluate(path, _problem(second, gain=1.0)) == ({0, 1, 2}, 3, now)
    # the runs' value pinned: every run reused, with its numbers, and nothing added
    assert _evaluate(path, _problem(second, gain=0.5)) == ({0, 1, 2}, 3, made)
    assert _per_model(path) == [3, 3]
    with StudyStore(path) as store:
        store.bind(_problem(second, gain=0.5))
        assert (len(store), store.counts(), store.total()) == (3, {"ok": 3}, 6)
        assert store.other_models() == [("gain = 1.0", 3)]
        assert [r.record.distance for r in store.runs()] == made


def test_a_changed_value_after_an_edit_needs_reuse_changed_code_and_runs_anew(tmp_path, release):
    """An edit without a release: --reuse-changed-code waives the code check; the options'
    values still choose the runs."""
    path = tmp_path / "s.sqlite"
    _, _, made = _evaluate(path, _problem(release("1.0.0")))
    edited = release("1.0.0", gain="1.0")
    for study in (_problem(edited, gain=0.5), _problem(edited)):
        with pytest.raises(fbia.ConfigError, match=r"made by other code of the model plugin"):
            _evaluate(path, study)  # the code check stands, and the store is left as it was
    assert _per_model(path) == [3]
    reused, n, now = _evaluate(path, _problem(edited), reuse_changed_code=True)
    assert (reused, n) == (set(), 3) and now != made
    reused, n, again = _evaluate(path, _problem(edited, gain=0.5), reuse_changed_code=True)
    assert (reused, n, again) == ({0, 1, 2}, 3, made)
    assert _per_model(path) == [3, 3]


def test_a_new_option_with_a_default_keeps_every_run_and_another_value_runs_anew(tmp_path, release):
    path = tmp_path / "s.sqlite"
    _, _, made = _evaluate(path, _problem(release("1.0.0")))
    grown = release(
        "1.1.0", options='        offset: float = Field(0.0, description="a new option [-]")'
    )
    assert _evaluate(path, _problem(grown)) == ({0, 1, 2}, 3, made)
    assert json.loads(_meta(path, "model"))["model"]["options"]["offset"] == 0.0
    assert _evaluate(path, _problem(grown, offset=0.5))[:2] == (set(), 3)
    assert _per_model(path) == [3, 3]
    assert _evaluate(path, _problem(grown)) == ({0, 1, 2}, 3, made)


def test_a_new_option_keeps_the_runs_of_every_model_part(tmp_path, release):
    """Each part of a store holding two is re-keyed when it is bound again."""
    path = tmp_path / "s.sqlite"
    first = release("1.0.0")
    _, _, half = _evaluate(path, _problem(first))
    _, _, whole = _evaluate(path, _problem(first, gain=1.0))
    grown = release(
        "1.1.0", options='        offset: float = Field(0.0, description="a new option [-]")'
    )
    assert _evaluate(path, _problem(grown, gain=1.0)) == ({0, 1, 2}, 3, whole)
    assert _evaluate(path, _problem(grown)) == ({0, 1, 2}, 3, half)
    assert _evaluate(path, _problem(grown, gain=1.0)) == ({0, 1, 2}, 3, whole)
    assert sorted(_per_model(path)) == [3, 3]


def test_a_removed_option_keeps_the_runs_made_at_its_default_only(tmp_path, release):
    offset = '        offset: float = Field(0.0, description="an option removed later [-]")'
    at_default, set_ = tmp_path / "default.sqlite", tmp_path / "set.sqlite"
    _, _, made = _evaluate(at_default, _problem(release("1.0.0", options=offset)))
    _evaluate(set_, _problem(release("1.0.0", options=offset), offset=0.5))
    shrunk = release("1.1.0")
    assert _evaluate(at_default, _problem(shrunk)) == ({0, 1, 2}, 3, made)
    assert _evaluate(set_, _problem(shrunk)) == (set(), 3, made)  # not reused: made anew
    with StudyStore(set_) as store:
        store.bind(_problem(shrunk))
        assert store.other_models() == [("offset = 0.5", 3)]


def _as_the_second_format(path) -> None:
    """Rewrite the store at ``path`` as fbia wrote it before runs recorded their model part
    (format 2: no column ``runs.model``, no table ``models``)."""
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("DROP INDEX runs_model")
    db.execute("ALTER TABLE runs DROP COLUMN model")
    db.execute("DROP TABLE models")
    db.execute("UPDATE meta SET value = 'fbia-store-2' WHERE key = 'format'")
    db.close()


def test_a_store_of_the_second_format_is_migrated_and_its_runs_kept(tmp_path, release):
    path = tmp_path / "s.sqlite"
    first = release("1.0.0")
    _, _, made = _evaluate(path, _problem(first))
    _as_the_second_format(path)
    key = _meta(path, "model_key")
    second = release("1.1.0", gain="1.0")
    reused, n, now = _evaluate(path, _problem(second))  # migrated, then the new default
    assert (reused, n) == (set(), 3) and now != made
    assert _meta(path, "format") == "fbia-store-3"
    assert _per_model(path) == [3, 3]
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT key FROM models ORDER BY rowid").fetchone() == (key,)
    with sqlite3.connect(tmp_path / "s.v2.sqlite") as backup:  # the original, as it was
        assert backup.execute("SELECT count(*) FROM runs").fetchone() == (3,)
        assert "model" not in {r[1] for r in backup.execute("PRAGMA table_info(runs)")}
    assert _evaluate(path, _problem(second, gain=0.5)) == ({0, 1, 2}, 3, made)


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
    assert _evaluate(path, _problem(release("1.1.0", gain="1.0")))[:2] == (set(), 3)
    assert _evaluate(path, _problem(release("1.1.0", gain="1.0"), gain=0.5))[:2] == ({0, 1, 2}, 3)


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


def test_fbia_run_reruns_a_changed_default_and_resumes_with_the_old_value_pinned(
    tmp_path, release, monkeypatch, capsys
):
    """The hostile tester's case from the command line: after the release, the study file
    relying on the new default runs every point again, saying in one line that the store's
    runs are of the old value, and is never told that "its model did not" change; setting the
    new value reuses those, pinning the old one the first ones."""
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

    store = tmp_path / "output" / "store.sqlite"
    registered(release("1.0.0"))
    assert run("")[0] == 0
    assert _per_model(store) == [9]
    registered(release("1.1.0", gain="1.0"))
    status, out, err = run("")
    assert status == 0 and err == "" and "its model did not" not in out
    announced = [line for line in out.splitlines() if "output/store.sqlite holds" in line]
    assert announced == [
        "store: output/store.sqlite holds 0 forward runs of this model and 9 of the same model "
        "class with other option values (gain = 0.5), which are not reused"
    ]
    assert "9 run now (0 failed), 0 taken from the store" in out
    assert _per_model(store) == [9, 9]
    also = "it also holds 9 of the same model class with other option values"
    status, out, _ = run("gain = 1.0")
    assert status == 0 and "9 taken from the store" in out
    assert f"(0 failed); each is reused, not run again; {also} (gain = 0.5)" in out
    status, out, _ = run("gain = 0.5")
    assert status == 0 and "9 taken from the store" in out
    assert "resuming: output/store.sqlite holds 9 forward runs of this model" in out
    assert f"{also} (gain = 1.0), which are not reused" in out
    assert _per_model(store) == [9, 9]
