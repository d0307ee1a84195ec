"""The plugin wiring: registration rules, entry points, and third-party plugins end to end.

A third-party plugin is a distribution with an entry point in the ``fbia`` group.  The tests
below install such distributions for one test only (``fbia_installer`` of fbia.testing writes
a real ``*.dist-info`` into a temporary folder on ``sys.path``) and find them through a fresh
``Registry.load()``, exactly as an installed package would be found, with no change to fbia.
"""

from __future__ import annotations

import importlib.metadata
import inspect
import sys
import tomllib
import types

import pytest
from _paths import ROOT, TESTS
from pydantic import BaseModel

import fbia
from fbia import testing as ft
from fbia.core import hookspecs
from fbia.core.registry import KINDS, Registry, default_registry

ROOT = ROOT
PLUGIN_PKG = TESTS / "plugin_pkg"
TEMPLATE = ROOT / "examples" / "third_party_plugin"


def plugin_module(name: str, **hooks: object) -> types.ModuleType:
    """A plugin module ``name`` whose attributes are ``hooks`` (functions)."""
    module = types.ModuleType(name)
    for attr, value in hooks.items():
        setattr(module, attr, value)
    return module


def registers(kind: str, *pairs: tuple[str, object]) -> object:
    """A hook implementation of ``register_<kind>s`` that registers ``pairs``."""

    def hook(register):  # type: ignore[no-untyped-def]
        for name, cls in pairs:
            register(name, cls)

    hook.__name__ = KINDS[kind]
    return fbia.hookimpl(hook)


class GoodMeasure(fbia.MeasureBase):
    class Options(fbia.PluginOptions):
        pass

    def residuals(self, simulated, observation):  # pragma: no cover - never called
        raise NotImplementedError

    def distance(self, simulated, observation):  # pragma: no cover - never called
        raise NotImplementedError


# ------------------------------------------------------------------------------------------
# Registration rules
# ------------------------------------------------------------------------------------------
def test_duplicate_name_raises_naming_both_plugins():
    first = plugin_module(
        "plugin_one", register_measures=registers("measure", ("dup", GoodMeasure))
    )
    second = plugin_module(
        "plugin_two", register_measures=registers("measure", ("dup", GoodMeasure))
    )
    with pytest.raises(fbia.PluginError) as info:
        Registry.load(entry_points=False, extra=[first, second])
    message = str(info.value)
    assert "measure name 'dup' is registered twice" in message
    assert "'plugin_one'" in message and "'plugin_two'" in message


def test_duplicate_of_a_builtin_name_names_the_builtin_distribution():
    clash = plugin_module(
        "my_plugin", register_measures=registers("measure", ("rkhs", GoodMeasure))
    )
    with pytest.raises(
        fbia.PluginError, match=r"'rkhs' is registered twice: by plugin .* \(fbia\)"
    ):
        Registry.load(extra=[clash])


def test_unknown_name_lists_the_valid_names():
    plugin = plugin_module(
        "two_measures",
        register_measures=registers("measure", ("alpha", GoodMeasure), ("beta", GoodMeasure)),
    )
    reg = Registry.load(entry_points=False, extra=[plugin])
    with pytest.raises(fbia.PluginError, match=r"^unknown measure 'gamma'; valid: alpha, beta$"):
        reg.get("measure", "gamma")
    with pytest.raises(fbia.PluginError, match=r"unknown forward model 'x'; valid: \(none"):
        reg.create("forward_model", "x")


def test_unknown_name_in_the_default_registry_lists_every_installed_one():
    with pytest.raises(fbia.PluginError) as info:
        fbia.measure("rhks")
    valid = str(info.value).split("valid: ")[1].split(", ")
    assert valid == [e.name for e in fbia.list_plugins("measure")] and "rkhs" in valid


class NoOptions(fbia.MeasureBase):
    Options = BaseModel  # type: ignore[assignment]  # a schema, not fbia.PluginOptions

    def residuals(self, simulated, observation): ...

    def distance(self, simulated, observation): ...


class NoMethods(fbia.MeasureBase):
    class Options(fbia.PluginOptions):
        pass

    def residuals(self, simulated, observation): ...


@pytest.mark.parametrize(
    ("cls", "rule"),
    [
        (NoOptions, r"measure 'bad' has no Options schema \(a subclass of fbia.PluginOptions\)"),
        (NoMethods, r"measure 'bad' lacks method\(s\) distance"),
    ],
    ids=["no-options", "no-distance"],
)
def test_class_without_options_or_methods_is_rejected(cls, rule):
    plugin = plugin_module("sloppy", register_measures=registers("measure", ("bad", cls)))
    with pytest.raises(fbia.PluginError, match=rf"^plugin 'sloppy': {rule}"):
        Registry.load(entry_points=False, extra=[plugin])


class OffBaseMeasure(fbia.Configurable):
    """A measure as fbia took it before issue 48: options and methods, not the base."""

    class Options(fbia.PluginOptions):
        pass

    def residuals(self, simulated, observation): ...

    def distance(self, simulated, observation): ...


class OffBaseModel:
    class Options(fbia.PluginOptions):
        pass

    def parameter_names(self): ...

    def solve(self, parameters, coordinates, workdir): ...


class OffBaseIterator(fbia.Configurable):
    class Options(fbia.PluginOptions):
        pass

    def steps(self, problem, evaluator): ...


@pytest.mark.parametrize(
    ("kind", "cls", "base"),
    [
        ("measure", OffBaseMeasure, "fbia.MeasureBase"),
        ("forward_model", OffBaseModel, "fbia.ForwardModelBase"),
        ("iterator", OffBaseIterator, "fbia.IteratorBase"),
    ],
    ids=["measure", "forward_model", "iterator"],
)
def test_a_class_off_its_kinds_base_is_refused_in_one_line(kind, cls, base):
    """The framework calls the base's optional members directly (issue 48 item 3), so the
    registry refuses a class that does not derive from it, naming plugin, kind and base."""
    plugin = plugin_module("offbase", **{KINDS[kind]: registers(kind, ("bad", cls))})
    with pytest.raises(fbia.PluginError) as info:
        Registry.load(entry_points=False, extra=[plugin])
    assert str(info.value) == (
        f"plugin 'offbase': {kind} 'bad': class {cls.__qualname__} does not derive from {base}"
    )


def test_a_class_off_its_base_is_exit_2_in_the_cli(fbia_installer, tmp_path, capsys):
    """An installed plugin whose class is off its base: every command that loads the registry
    says so in one line and exits with 2."""
    from fbia.studies.cli import main

    (tmp_path / "fbia_offbase.py").write_text(
        "import fbia\n\n\n"
        "class Lax(fbia.Configurable):\n"
        "    def residuals(self, simulated, observation): ...\n\n"
        "    def distance(self, simulated, observation): ...\n\n\n"
        "@fbia.hookimpl\n"
        "def register_measures(register):\n"
        '    register("lax", Lax)\n'
    )
    fbia_installer.install("fbia-offbase", "0.0.1", {"offbase": "fbia_offbase"}, tmp_path)
    assert main(["plugins"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("measure 'lax': class Lax does not derive from fbia.MeasureBase")
    assert "\n" not in err


def test_misspelled_hook_fails_loudly():
    @fbia.hookimpl
    def register_forward_model(register):  # the hook is register_forward_models
        register("never", GoodMeasure)

    typo = plugin_module("typo_plugin", register_forward_model=register_forward_model)
    with pytest.raises(fbia.PluginError, match=r"unknown hook 'register_forward_model'"):
        Registry.load(entry_points=False, extra=[typo])


def test_entry_point_that_does_not_import_is_a_plugin_error(fbia_installer):
    fbia_installer.install("fbia-broken", "0.0.1", {"broken": "fbia_no_such_module_xyz"})
    with pytest.raises(fbia.PluginError, match=r"group 'fbia' failed to load: .*no_such_module"):
        fbia_installer.registry()


# ------------------------------------------------------------------------------------------
# Meta-tests: entry points, hooks, the listing
# ------------------------------------------------------------------------------------------
def fbia_entry_points() -> dict[str, str]:
    dist = importlib.metadata.distribution("fbia")
    return {ep.name: ep.value for ep in dist.entry_points if ep.group == "fbia"}


def test_installed_entry_points_are_the_declared_ones():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    assert fbia_entry_points() == declared["fbia"], "stale install: run `pip install -e .`"


@pytest.mark.parametrize("name", sorted(fbia_entry_points()))
def test_every_declared_entry_point_loads_and_implements_a_hook(name):
    dist = importlib.metadata.distribution("fbia")
    (ep,) = [e for e in dist.entry_points if e.group == "fbia" and e.name == name]
    value = ep.value
    module = ep.load()
    hooks = [h for h in KINDS.values() if hasattr(getattr(module, h, None), "fbia_impl")]
    assert hooks, f"entry point {name} = {value} implements no fbia hook"


def test_every_hook_is_implemented_by_a_builtin_and_documented():
    reg = Registry.load()
    declared = sorted(
        n for n, f in inspect.getmembers(hookspecs, inspect.isfunction) if hasattr(f, "fbia_spec")
    )
    assert declared == sorted(KINDS.values())
    builtin = {p for p, d in reg.plugin_manager.list_plugin_distinfo() if d.project_name == "fbia"}
    guide = (ROOT / "docs" / "plugins.md").read_text()  # the plugin guide the README links
    for hook in declared:
        impls = getattr(reg.plugin_manager.hook, hook).get_hookimpls()
        assert any(i.plugin in builtin for i in impls), f"no built-in plugin implements {hook}"
        assert getattr(hookspecs, hook).__doc__, f"hook {hook} has no docstring"
        assert hook in guide, f"hook {hook} is not documented in docs/plugins.md"
    for kind in KINDS:
        assert any(e.distribution == "fbia" for e in reg.entries(kind)), f"no built-in {kind}"


def test_plugins_lists_builtins_with_distribution_and_version():
    version = importlib.metadata.version("fbia")
    assert version == fbia.__version__
    entries = [e for e in fbia.list_plugins() if e.distribution == "fbia"]
    assert {e.kind for e in entries} == set(KINDS)
    for e in entries:
        row = e.describe()
        assert set(row) == {
            "name", "kind", "class", "plugin", "distribution", "version", "missing"
        }  # fmt: skip
        assert row["missing"] == ""  # make test installs every extra
        assert (row["distribution"], row["version"]) == ("fbia", version)
        assert row["plugin"] in fbia_entry_points()  # registered through the entry points
        assert row["class"].startswith("fbia.")
    assert {"analytic_mound_2d", "ray", "cpp", "rkhs", "levenberg_marquardt"} <= {
        e.name for e in entries
    }


# ------------------------------------------------------------------------------------------
# Third-party plugins, out of tree
# ------------------------------------------------------------------------------------------
def test_out_of_tree_plugin_is_found_with_its_distribution(fbia_installer, tmp_path):
    assert "fbia_example_plugin" not in sys.modules
    fbia_installer.install(
        "fbia-example-plugin", "1.2.3", {"example": "fbia_example_plugin"}, source=PLUGIN_PKG
    )
    reg = fbia_installer.registry()
    model = reg.get("forward_model", "example_bump")
    measure = reg.get("measure", "example_bbox")
    for entry in (model, measure):
        assert (entry.plugin, entry.distribution, entry.version) == (
            "example",
            "fbia-example-plugin",
            "1.2.3",
        )
    assert model.factory.__module__ == "fbia_example_plugin"
    # the built-ins are still there, next to it
    assert {"analytic_mound_2d", "example_bump"} <= set(reg.names("forward_model"))
    # the default registry sees it too (and forgets it after the test)
    assert fbia.forward_model("example_bump", n_points=5).options.n_points == 5
    # and it passes the same conformance checks as fbia's own plugins
    solution = ft.check_registered(model, tmp_path / "model")
    assert solution.interface({"inflow_rate": 100.0}).vertices[20, 1] == pytest.approx(0.2)
    values = ft.check_registered(measure, tmp_path / "measure")
    # y = 0 against y = 0.02 + 0.02 x: the box moves up by 0.02 (bottom) and 0.04 mm (top)
    assert values["line_2d"]["simulated"] == pytest.approx(0.02 * 5**0.5)


def test_installed_plugin_leaves_no_trace(tmp_path):
    before_path, before_modules = list(sys.path), set(sys.modules)
    with pytest.MonkeyPatch.context() as mp:
        installer = ft.PluginInstaller(tmp_path, mp)
        installer.install(
            "fbia-example-plugin", "1.2.3", {"example": "fbia_example_plugin"}, source=PLUGIN_PKG
        )
        assert "example_bump" in [e.name for e in fbia.list_plugins("forward_model")]
        mp.undo()
        installer.cleanup()
    assert sys.path == before_path
    assert "fbia_example_plugin" not in sys.modules and set(sys.modules) >= before_modules
    assert "example_bump" not in default_registry().names("forward_model")
    with pytest.raises(fbia.PluginError, match="unknown forward model 'example_bump'"):
        fbia.forward_model("example_bump")


def test_write_dist_info_is_what_importlib_metadata_reads(tmp_path):
    dist_dir = ft.write_dist_info(tmp_path, "fbia-thing", "2.0", {"thing": "fbia_thing.plugin"})
    assert dist_dir.name == "fbia_thing-2.0.dist-info"
    dist = importlib.metadata.PathDistribution(dist_dir)
    assert (dist.metadata["Name"], dist.version) == ("fbia-thing", "2.0")
    assert [(e.group, e.name, e.value) for e in dist.entry_points] == [
        ("fbia", "thing", "fbia_thing.plugin")
    ]


# ------------------------------------------------------------------------------------------
# The template package examples/third_party_plugin
# ------------------------------------------------------------------------------------------
def template_project() -> dict:
    return tomllib.loads((TEMPLATE / "pyproject.toml").read_text())["project"]


def install_template(installer: ft.PluginInstaller) -> None:
    project = template_project()
    installer.install(
        project["name"], project["version"], project["entry-points"]["fbia"], TEMPLATE / "src"
    )


def test_template_plugin_is_found_and_conforms(fbia_installer, tmp_path):
    install_template(fbia_installer)
    entry = fbia_installer.registry().get("forward_model", "mysolver")
    assert (entry.distribution, entry.version) == ("fbia-mysolver", template_project()["version"])
    solution = ft.check_registered(entry, tmp_path)
    crest = solution.interface({"inflow_rate": 100.0}).vertices[30]
    assert crest[0] == pytest.approx(1.0 + 20.0 * (0.6 / 0.49) / (400.0 / 2.6) * 0.3)


class Outcomes:
    """A pytest plugin object that tallies the outcomes of a nested test session."""

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "call" or report.outcome != "passed":
            self.counts[report.outcome] = self.counts.get(report.outcome, 0) + 1


def test_template_own_tests_pass(fbia_installer, monkeypatch, tmp_path):
    """Runs examples/third_party_plugin/tests as a user would after `pip install -e .`.

    In this process (a second interpreter would spend seconds importing numpy and scipy),
    with the template installed by ``fbia_installer`` and its test module forgotten after.
    """
    install_template(fbia_installer)
    monkeypatch.chdir(TEMPLATE)
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    modules = set(sys.modules)
    outcomes = Outcomes()
    try:
        code = pytest.main(
            ["-q", "-p", "no:cacheprovider", f"--basetemp={tmp_path / 'inner'}", "tests"],
            plugins=[outcomes],
        )
    finally:
        for name in set(sys.modules) - modules:
            if getattr(sys.modules[name], "__file__", "").startswith(str(TEMPLATE)):
                del sys.modules[name]
    assert (code, outcomes.counts) == (pytest.ExitCode.OK, {"passed": 9})
