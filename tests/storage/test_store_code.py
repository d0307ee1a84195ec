"""A store never gives back runs of edited model code silently, and keeps its runs when a
plugin gains an option with a default (issue 29 item 2).

The plugin is a module written into the test's folder (a subclass of the toy model of
tests/_models.py) and imported again after every edit, as a plugin author would edit theirs.
"""

from __future__ import annotations

import importlib
import json
import sqlite3
import sys

import pytest
from _models import toy_problem

import fbia
from fbia.storage.fingerprints import (
    canonical,
    code_digest,
    coordinates_of,
    model_part,
    problem_fingerprint,
)
from fbia.storage.migration import rekey
from fbia.storage.store import StudyStore

POINTS = [{"E": 200.0, "nu": 0.1}, {"E": 400.0, "nu": 0.3}, {"E": 700.0, "nu": 0.2}]

PLUGIN = """\
from pathlib import Path

from pydantic import Field

from _models import ToyMoundForwardModel


class Edited(ToyMoundForwardModel):
{attrs}
    class Options(ToyMoundForwardModel.Options):
{options}

    def solve(self, parameters, coordinates, workdir):
{body}
        return super().solve(parameters, coordinates, workdir)
"""


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """``plugin(options, body)``: write the module ``edited_plugin`` and import it afresh."""
    monkeypatch.syspath_prepend(str(tmp_path))

    def write(options: str = "        pass", body: str = "        pass", attrs: str = ""):
        text = PLUGIN.format(options=options, body=body, attrs=attrs)
        (tmp_path / "edited_plugin.py").write_text(text)
        sys.modules.pop("edited_plugin", None)
        importlib.invalidate_caches()
        return importlib.import_module("edited_plugin").Edited

    yield write
    sys.modules.pop("edited_plugin", None)


def _problem(model_class):
    base = toy_problem()
    return fbia.InverseProblem(
        model=model_class(),
        measure=base.measure,
        observations=base.observations,
        parameters=base.parameters,
    )


def _evaluate(path, problem, **bind):
    with StudyStore(path) as store:
        store.bind(problem, **bind)
        with fbia.SerialEvaluator(store=store) as ev:
            ev.evaluate(problem, POINTS)
            return set(ev.reused), len(store)


def test_an_edited_plugin_is_refused_until_the_user_says_the_results_stay(tmp_path, plugin):
    path = tmp_path / "s.sqlite"
    assert _evaluate(path, _problem(plugin())) == (set(), 3)
    # the same code, imported again: every run reused
    assert _evaluate(path, _problem(plugin())) == ({0, 1, 2}, 3)
    # the author edits the model: the store refuses, naming the plugin and the way out
    edited = plugin(body="        parameters = dict(parameters)")
    with pytest.raises(fbia.ConfigError) as info:
        _evaluate(path, _problem(edited))
    message = str(info.value)
    assert message.startswith(f"{path}: the store holds 3 runs made by other code of the model ")
    assert "plugin edited_plugin.Edited (its source changed since: " in message
    assert "edited_plugin.py)" in message
    assert "--fresh" in message and "--reuse-changed-code" in message
    # the user says the change keeps the results: reused, and the new code is recorded
    assert _evaluate(path, _problem(edited), reuse_changed_code=True) == ({0, 1, 2}, 3)
    assert _evaluate(path, _problem(edited)) == ({0, 1, 2}, 3)
    # another edit is refused again
    with pytest.raises(fbia.ConfigError, match="made by other code"):
        _evaluate(path, _problem(plugin(body="        parameters = {**parameters}")))


def test_a_new_option_with_a_default_keeps_every_run(tmp_path, plugin):
    path = tmp_path / "s.sqlite"
    assert _evaluate(path, _problem(plugin())) == (set(), 3)
    grown = plugin(options='        scale: float = Field(1.0, description="a new option [-]")')
    # re-keyed with the new option at its default (its author's contract: it keeps the old
    # behaviour); only the code changed
    assert _evaluate(path, _problem(grown), reuse_changed_code=True) == ({0, 1, 2}, 3)
    # the new option set to another value is another model part: its runs are made anew
    assert _evaluate(path, _problem(lambda: grown(scale=2.0))) == (set(), 3)


def test_a_store_keyed_with_every_option_is_rekeyed_and_reused(tmp_path):
    """Stores written before fbia left the options at their defaults out of the keys (every
    option in the key, no code digest recorded) keep their runs: the first bind re-keys them,
    an option added to the plugin since at its default."""
    path = tmp_path / "s.sqlite"
    problem = toy_problem(fail_above=650.0)
    assert _evaluate(path, problem) == (set(), 3)
    fingerprint = problem_fingerprint(problem)
    new = json.loads(canonical(model_part(fingerprint)))
    old = json.loads(canonical(model_part(fingerprint)))
    del old["model"]["options"]["odd_diagnostics"]  # an option the plugin did not have then
    assert old != new
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("BEGIN")
    assert rekey(db, new, coordinates_of(fingerprint), old) == 3
    db.execute("DELETE FROM meta WHERE key = 'code'")
    db.execute("COMMIT")
    db.close()
    assert _evaluate(path, toy_problem(fail_above=650.0)) == ({0, 1, 2}, 3)
    with sqlite3.connect(path) as db:
        (model,) = db.execute("SELECT value FROM meta WHERE key = 'model'").fetchone()
    assert model == canonical(new)


def test_the_code_digest_covers_what_the_model_imports_and_only_it(plugin):
    from fbia.plugins.ale_fsi.model import AleFsiForwardModel

    digest = code_digest(AleFsiForwardModel())
    assert digest["class"] == "fbia.plugins.ale_fsi.model.AleFsiForwardModel"
    files = set(digest["files"])
    # model.py imports ..fem.flow_cell and, inside a method, .solver, which imports
    # ..fem.newton and .forms
    assert {"model.py", "solver.py", "forms.py", "../fem/flow_cell.py", "../fem/newton.py"} <= files
    # not the registration nor the benchmark geometries, which the model does not import
    assert not files & {"__init__.py", "turek_hron.py", "schaefer_turek_3d.py"}
    assert all(sha.startswith("code:") and len(sha) == 5 + 64 for sha in digest["files"].values())
    assert len(digest["sha256"]) == 64
    analytic = code_digest(fbia.forward_model("analytic_mound_2d"))["files"]
    assert set(analytic) == {"mound_2d.py", "_mechanics.py"}  # not mound_3d.py
    # a top-level module: that file alone, not the top-level module _models it imports
    assert list(code_digest(plugin()())["files"]) == ["edited_plugin.py"]
    assert list(code_digest(toy_problem().model)["files"]) == ["_models.py"]


def test_a_package_upgrade_keeps_the_runs_of_a_plugin_with_a_numerics_version(
    tmp_path, plugin, monkeypatch
):
    from fbia.storage import fingerprints

    path = tmp_path / "s.sqlite"
    declared = plugin(attrs='    numerics_version = "1"')
    assert _evaluate(path, _problem(declared)) == (set(), 3)
    monkeypatch.setattr(fingerprints, "_package_version", lambda obj: "9.9.9")  # an upgrade
    assert _evaluate(path, _problem(declared)) == ({0, 1, 2}, 3)


def test_a_store_keyed_by_the_package_version_is_rekeyed_to_the_numerics_version(tmp_path, plugin):
    path = tmp_path / "s.sqlite"
    assert _evaluate(path, _problem(plugin())) == (set(), 3)  # keyed by "unversioned"
    declared = plugin(attrs='    numerics_version = "1"')  # the author declares it
    assert _evaluate(path, _problem(declared), reuse_changed_code=True) == ({0, 1, 2}, 3)
    with sqlite3.connect(path) as db:
        (model,) = db.execute("SELECT value FROM meta WHERE key = 'model'").fetchone()
    assert '"version":"numerics 1"' in model


def test_a_store_keyed_by_an_earlier_release_is_rekeyed_and_its_code_checked(
    tmp_path, plugin, monkeypatch
):
    """A store written by release 0.1.0 of a package, before its plugin declared a numerics
    version, and read by release 0.2.0 that declares one: the same model, not a different
    one (fbia 0.2.0 on its demo's stores); the source digest still decides whether the runs
    are reused, so the user says the change leaves the results as they were."""
    from fbia.storage import fingerprints

    path = tmp_path / "s.sqlite"
    monkeypatch.setattr(fingerprints, "_package_version", lambda obj: "0.1.0")
    assert _evaluate(path, _problem(plugin())) == (set(), 3)
    monkeypatch.setattr(fingerprints, "_package_version", lambda obj: "0.2.0")
    declared = plugin(attrs='    numerics_version = "1"')
    with pytest.raises(fbia.ConfigError, match="other code of the model plugin"):
        _evaluate(path, _problem(declared))
    assert _evaluate(path, _problem(declared), reuse_changed_code=True) == ({0, 1, 2}, 3)


def _ply(path, comment, z=0.0):
    """An ASCII PLY triangle written with a header ``comment`` (meshio writes a timestamp)."""
    path.write_text(
        "ply\nformat ascii 1.0\n"
        f"comment {comment}\n"
        "element vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        f"0 0 0\n1 0 0\n0 1 {z}\n3 0 1 2\n"
    )
    return path


SURFACE_OPTION = '        surface: Path | None = Field(None, description="a surface file")'


def _surface_plugin(plugin):
    return plugin(options=SURFACE_OPTION)


def test_a_mesh_file_is_keyed_by_its_content_not_its_header(tmp_path, plugin):
    """Rewriting the same surface (another header comment) reuses every run; moving one of
    its vertices is another model (issue 29 item 2: file options keyed on parsed content)."""
    path = tmp_path / "s.sqlite"
    model = _surface_plugin(plugin)
    surface = _ply(tmp_path / "surface.ply", "written 2026-11-27 10:00")
    assert _evaluate(path, _problem(lambda: model(surface=surface))) == (set(), 3)
    _ply(surface, "written 2026-11-28 12:34:56 by another run")
    assert _evaluate(path, _problem(lambda: model(surface=surface))) == ({0, 1, 2}, 3)
    _ply(surface, "written again", z=0.5)  # another surface: its runs are made anew
    assert _evaluate(path, _problem(lambda: model(surface=surface))) == (set(), 3)


def test_a_store_keyed_by_a_mesh_files_bytes_is_rekeyed_when_the_bytes_are_the_same(
    tmp_path, plugin
):
    from fbia.storage import fingerprints

    path = tmp_path / "s.sqlite"
    model = _surface_plugin(plugin)
    surface = _ply(tmp_path / "surface.ply", "one header")
    problem = _problem(lambda: model(surface=surface))
    fingerprint = problem_fingerprint(problem)
    new = json.loads(canonical(model_part(fingerprint)))
    assert set(new["model"]["options"]["surface"]) == {"file", "content"}
    old = json.loads(canonical(model_part(fingerprint)))  # the key of an earlier fbia
    old["model"]["options"]["surface"] = {
        "file": "surface.ply",
        "sha256": fingerprints._bytes_digest(surface),
    }
    assert _evaluate(path, problem) == (set(), 3)
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("BEGIN")
    assert rekey(db, new, coordinates_of(fingerprint), old) == 3
    db.execute("COMMIT")
    db.close()
    assert _evaluate(path, _problem(lambda: model(surface=surface))) == ({0, 1, 2}, 3)
    # with other bytes the old key is not carried over: another model
    rewritten = _problem(lambda: model(surface=_ply(surface, "another header")))
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("BEGIN")
    assert rekey(db, new, coordinates_of(fingerprint), old) == 3
    db.execute("COMMIT")
    db.close()
    assert _evaluate(path, rewritten) == (set(), 3)  # not reused: made anew


def test_a_new_release_with_the_same_numerics_keeps_the_runs_an_edit_does_not(
    tmp_path, plugin, monkeypatch
):
    """Issue 31 item 5 with issue 29 item 2: a store written by the previous release of a
    plugin package resumes with 0 reruns when the new release declares the same
    numerics_version, although its code changed; the same edit without a new version (a
    user editing the installed plugin) is refused, and so is a release that declares other
    numerics (another model: another key)."""
    from fbia.storage import fingerprints

    path = tmp_path / "s.sqlite"
    monkeypatch.setattr(fingerprints, "_package_version", lambda obj: "1.0.0")
    first = plugin(attrs='    numerics_version = "1"')
    assert _evaluate(path, _problem(first)) == (set(), 3)
    edited = plugin(
        attrs='    numerics_version = "1"', body="        parameters = dict(parameters)"
    )
    with pytest.raises(fbia.ConfigError, match="made by other code"):
        _evaluate(path, _problem(edited))  # edited, same version: refused
    monkeypatch.setattr(fingerprints, "_package_version", lambda obj: "1.0.1")  # released
    assert _evaluate(path, _problem(edited)) == ({0, 1, 2}, 3)  # 0 reruns
    bumped = plugin(
        attrs='    numerics_version = "2"', body="        parameters = dict(parameters)"
    )
    monkeypatch.setattr(fingerprints, "_package_version", lambda obj: "1.1.0")
    with pytest.raises(fbia.ConfigError, match="different model"):
        _evaluate(path, _problem(bumped))


# -- a plugin package: the model's modules, not the rest of the package (issue 43 item 6) -------
MODEL = """\
from _models import ToyMoundForwardModel

from .helper import SCALE
{imports}

class Scaled(ToyMoundForwardModel):
    def solve(self, parameters, coordinates, workdir):
        from . import lazy  # a lazy import: code the model runs too

        parameters = lazy.shift({{k: SCALE * v for k, v in parameters.items()}})
        return super().solve(parameters, coordinates, workdir)
"""

PACKAGE = {
    "__init__.py": "from .iterator import Stepper\nfrom .model import Scaled\n",
    "iterator.py": "class Stepper:\n    pass\n",
    "helper.py": "SCALE = 1.0\n",
    "lazy.py": "def shift(parameters):\n    return dict(parameters)\n",
    "model.py": MODEL.format(imports=""),
}


@pytest.fixture
def package(tmp_path, monkeypatch):
    """``package(edits)``: write the package ``third_party_fsi`` (the files of ``PACKAGE``,
    and of ``edits`` instead) and import its model afresh, as an author would edit theirs."""
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    folder = tmp_path / "third_party_fsi"
    folder.mkdir()

    def forget():
        for name in [m for m in sys.modules if m.split(".")[0] == "third_party_fsi"]:
            del sys.modules[name]

    def write(edits: dict[str, str] | None = None):
        for name, text in {**PACKAGE, **(edits or {})}.items():
            (folder / name).write_text(text)
        forget()
        importlib.invalidate_caches()
        return importlib.import_module("third_party_fsi.model").Scaled

    yield write
    forget()


def _stored_code(path):
    with sqlite3.connect(path) as db:
        (text,) = db.execute("SELECT value FROM meta WHERE key = 'code'").fetchone()
    return json.loads(text)


def _store_code(path, code):
    with sqlite3.connect(path) as db:
        db.execute("UPDATE meta SET value = ? WHERE key = 'code'", (canonical(code),))


def test_editing_a_module_the_model_does_not_import_keeps_its_runs(tmp_path, package):
    path = tmp_path / "s.sqlite"
    assert set(code_digest(package()())["files"]) == {"model.py", "helper.py", "lazy.py"}
    assert _evaluate(path, _problem(package())) == (set(), 3)
    # the plugin's iterator and its registration change: not the model's code
    unrelated = {
        "iterator.py": "class Stepper:\n    steps = 2  # more steps\n",
        "__init__.py": PACKAGE["__init__.py"] + "# registered above\n",
    }
    assert _evaluate(path, _problem(package(unrelated))) == ({0, 1, 2}, 3)
    # a module the model imports changes: refused, naming that file
    helper = {"helper.py": "SCALE = 1.0 * 1.0\n"}
    with pytest.raises(fbia.ConfigError, match=r"its source changed since: helper\.py\)"):
        _evaluate(path, _problem(package(helper)))
    lazy = {"lazy.py": PACKAGE["lazy.py"] + "EDITED = True\n"}
    with pytest.raises(fbia.ConfigError, match=r"its source changed since: lazy\.py\)"):
        _evaluate(path, _problem(package(lazy)))
    # the model imports one more module, then no longer: added and removed files named
    grown = {
        "model.py": MODEL.format(imports="from .extra import OFFSET"),
        "extra.py": "OFFSET = 0\n",
    }
    with pytest.raises(fbia.ConfigError, match=r"since: extra\.py \(added\), model\.py\)"):
        _evaluate(path, _problem(package(grown)))
    assert _evaluate(path, _problem(package(grown)), reuse_changed_code=True) == ({0, 1, 2}, 3)
    with pytest.raises(fbia.ConfigError, match=r"since: extra\.py \(removed\), model\.py\)"):
        _evaluate(path, _problem(package({"extra.py": "OFFSET = 0\n"})))


def test_a_store_with_a_folder_digest_keeps_its_runs_while_the_folder_is_unchanged(
    tmp_path, package
):
    """A store written before per-file digests recorded one SHA-256 of the plugin's folder:
    compared with that folder's digest now, it keeps its runs when the folder is unchanged
    (and gets the new digest), and is refused naming the folder when not (it cannot say
    which file changed), as before."""
    from fbia.storage import fingerprints

    path = tmp_path / "s.sqlite"
    assert _evaluate(path, _problem(package())) == (set(), 3)
    folder_digest = fingerprints._folder_digest(package()())
    assert folder_digest["files"] == str((tmp_path / "third_party_fsi").resolve())
    _store_code(path, folder_digest)  # as fbia before per-file digests wrote it
    assert _evaluate(path, _problem(package())) == ({0, 1, 2}, 3)
    assert _stored_code(path) == code_digest(package()())  # rewritten in the new format
    _store_code(path, folder_digest)
    edited = package({"iterator.py": "class Stepper:\n    steps = 2\n"})
    with pytest.raises(fbia.ConfigError) as info:
        _evaluate(path, _problem(edited))
    assert f"(its source changed since: {folder_digest['files']})" in str(info.value)
    assert _evaluate(path, _problem(edited), reuse_changed_code=True) == ({0, 1, 2}, 3)
    assert _stored_code(path) == code_digest(edited())
    assert _evaluate(path, _problem(edited)) == ({0, 1, 2}, 3)


def test_documenting_the_model_keeps_its_runs_and_a_store_of_byte_digests_is_upgraded(
    tmp_path, package
):
    """The digest is of each file's code without its comments and docstrings
    (:func:`~fbia.storage.fingerprints.code_text`): documenting a model keeps its stores; a
    string that is not a docstring, or the layout of the code, is code.  A store that recorded
    the files' bytes (fbia before) keeps its runs while the bytes are unchanged and records
    the new form, after which documenting keeps them too."""
    from fbia.storage import fingerprints

    path = tmp_path / "s.sqlite"
    assert _evaluate(path, _problem(package())) == (set(), 3)
    documented = {
        "helper.py": '"""The scale."""\n\nSCALE = 1.0  # of the inputs\n\n# the end\n',
        "lazy.py": 'def shift(parameters):\n    """Shift them."""\n    return dict(parameters)\n',
    }
    assert _evaluate(path, _problem(package(documented))) == ({0, 1, 2}, 3)
    for code in ('SCALE = 1.0\nNOTE = "a string"\n', "if True:\n    SCALE = 1.0\n"):
        with pytest.raises(fbia.ConfigError, match=r"its source changed since: helper\.py\)"):
            _evaluate(path, _problem(package({"helper.py": code})))
    # a store of the bytes' digests, as fbia before wrote it
    bytes_digest = fingerprints.class_code_digest(package(), kind="bytes")
    assert fingerprints.digest_kind(bytes_digest) == "bytes"
    _store_code(path, bytes_digest)
    assert _evaluate(path, _problem(package())) == ({0, 1, 2}, 3)
    assert _stored_code(path) == code_digest(package()())  # rewritten in the new form
    assert _evaluate(path, _problem(package(documented))) == ({0, 1, 2}, 3)
    _store_code(path, bytes_digest)  # the same bytes' digest, the files since documented
    with pytest.raises(fbia.ConfigError, match=r"since: helper\.py, lazy\.py\)"):
        _evaluate(path, _problem(package(documented)))


def test_code_text_drops_comments_and_docstrings_only():
    from fbia.storage.fingerprints import code_text

    source = (
        '"""Module doc."""\n'
        "import os  # a comment\n\n"
        "class A:\n"
        '    """Class doc\n    over lines: # not a comment."""\n\n'
        '    x = "not a doc"  # trailing\n'
        "    def f(self):  # c\n"
        '        """f doc, é"""\n'
        '        return "# not a comment, é"\n'
        'def g(): """one line"""; return 1\n'
    )
    assert (
        code_text(source.encode())
        == (
            "import os\n"
            "class A:\n"
            '    x = "not a doc"\n'
            "    def f(self):\n"
            '        return "# not a comment, é"\n'
            "def g(): ; return 1"
        ).encode()
    )
    assert code_text(b"def broken(:\n") is None  # does not parse: its bytes are digested
    # a string that spans lines is code, blank lines and trailing blanks included
    template = 'T = """a  \n\nb"""  # c\n'
    assert code_text(template.encode()) == b'T = """a  \n\nb"""  '
    assert code_text(template.replace("\n\n", "\n").encode()) != code_text(template.encode())
    # a comment or docstring added, removed or rewrapped leaves the text as it was
    plain = b"def f(x):\n    return x\n"
    documented = b'def f(x):\n    """Long\n    docs."""\n    # why\n\n    return x  # x\n'
    assert code_text(plain) == code_text(documented) == b"def f(x):\n    return x"
