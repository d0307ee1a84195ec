"""The structure of the package, read from its files (docs/architecture.md).

* Inside the package every import of fbia is relative, so the import graph can be read from
  the files (the folders map to ``fbia.*`` only through pyproject.toml).
* The graph has no cycle (imports inside functions and under TYPE_CHECKING included).
* The layers: which package may import which (``LAYERS``, as docs/architecture.md states
  them); the kernel imports nothing of fbia outside itself, and importing it loads no store,
  executor, plotting, GP or finite-element library.
* The kernel stays thin, iterators/ keeps its families in sub-packages.
* Size is a matter for review, not a gate (issue 48: the line budgets shaped modules, splits
  were made for a count and left seams): a module over :data:`MAX_LINES` lines of code, or a
  kernel over :data:`KERNEL_LINES`, is a :class:`SizeWarning` in the test summary, counted in
  lines of code (docstrings, comments and blank lines do not count).
"""

from __future__ import annotations

import ast
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = (
    "core",
    "execution",
    "storage",
    "figures",
    "imaging",
    "studies",
    "plugins",
    "measures",
    "iterators",
    "testing",
)
MAX_LINES = 600  # lines of code: docstrings, comments and blank lines do not count
#: the kernel's lines of code above which its size is worth a look (1987 when first counted so)
KERNEL_LINES = 2050


class SizeWarning(UserWarning):
    """A module or the kernel has grown past the size that is worth a look in review."""


def package_files() -> list[Path]:
    files = [ROOT / "__init__.py", ROOT / "pytest_plugin.py"]
    for d in PACKAGES:
        files += sorted((ROOT / d).rglob("*.py"))
    return files


def module_name(path: Path) -> str:
    parts = ["fbia", *path.relative_to(ROOT).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    modules = {module_name(f): f for f in package_files()}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    edges.add(sub if sub in modules else target)
        graph[name] = {e for e in edges if e in modules and e != name}
    return graph


def test_fbia_is_imported_relatively_inside_the_package():
    absolute = []
    for path in package_files():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.ImportFrom) and not node.level and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            if any(n == "fbia" or n.startswith("fbia.") for n in names):
                absolute.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert absolute == []


def test_the_import_graph_reads_from_the_files_and_has_no_cycle():
    graph = import_graph()
    assert sum(len(v) for v in graph.values()) > 150  # the arrows are there to be read
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle = path[path.index(nxt) :] + [nxt]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        path.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)


#: Which top-level package may import which (docs/architecture.md, "Layers"); a package may
#: always import itself.  ``fbia`` is the package root (the composition root: it re-exports
#: and wires), ``pytest_plugin`` the conformance kit's fixtures.
LAYERS: dict[str, set[str]] = {
    "core": set(),
    "figures": set(),
    "imaging": {"core"},
    "storage": {"core"},
    "execution": {"core", "storage"},
    "measures": {"core"},
    "plugins": {"core", "imaging"},
    "iterators": {"core", "execution", "figures"},
    "studies": {"core", "execution", "storage", "imaging", "figures"},
    "testing": {"core", "execution", "storage", "studies", "imaging"},
    "pytest_plugin": {"core", "testing"},
}


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "fbia"


def test_each_package_imports_only_the_layers_below_it():
    wrong = []
    for source, targets in import_graph().items():
        here = layer(source)
        if here == "fbia":
            continue
        for target in sorted(targets):
            there = layer(target)
            if there != here and there not in LAYERS[here]:
                wrong.append(f"{source} -> {target}")
    assert wrong == []


def test_plugins_do_not_import_each_other_except_the_shared_fem():
    """A model plugin reaches another only through the shared ``plugins/fem``; ``growth``,
    built on ``ale_fsi``, through its solver and options alone."""
    allowed = {("growth", "ale_fsi.solver"), ("growth", "ale_fsi.options")}
    wrong = []
    for source, targets in import_graph().items():
        if not source.startswith("fbia.plugins."):
            continue
        mine = source.split(".")[2]
        for target in targets:
            if not target.startswith("fbia.plugins.") or target == "fbia.plugins":
                continue
            theirs = target.split(".")[2]
            rest = ".".join(target.split(".")[2:])
            if theirs not in (mine, "fem") and (mine, rest) not in allowed:
                wrong.append(f"{source} -> {target}")
    assert wrong == []


def test_the_kernel_is_thin_and_light():
    modules = sorted((ROOT / "core").glob("*.py"))
    assert len(modules) <= 16, [p.name for p in modules]
    # lines of code, not docstrings or comments (issue 48: a budget must not push against the
    # kernel's documentation, which the contracts live in), and a note for review, not a gate
    lines = sum(code_lines(p.read_text(encoding="utf-8")) for p in modules)
    if lines > KERNEL_LINES:
        warnings.warn(
            f"the kernel (core/) has {lines} lines of code, over {KERNEL_LINES}: does all of it "
            "belong in the kernel?",
            SizeWarning,
            stacklevel=1,
        )
    code = (
        "import sys, fbia.core\n"
        "heavy = ('sqlite3', 'dask', 'distributed', 'GPy', 'ngsolve', 'netgen', 'matplotlib')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))\n"
        "print(sorted(m for m in sys.modules if m.startswith('fbia.') and\n"
        "             not m.startswith('fbia.core')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split("\n")[:2] == ["[]", "[]"], out.stdout


def test_iterators_keep_their_families_in_sub_packages():
    top = sorted(p.name for p in (ROOT / "iterators").glob("*.py"))
    assert len(top) <= 6, top


def code_lines(text: str) -> int:
    """Lines of ``text`` that hold code: not blank, not only a comment, not in a docstring
    (a size budget must not push against documentation, issue 48): a module's, class's or
    function's, or an attribute's (the string below an assignment, PEP 257, which documents
    a plugin base's optional members)."""
    docstrings: set[int] = set()
    for node in ast.walk(ast.parse(text)):
        body = getattr(node, "body", None)
        for k, stmt in enumerate(body if isinstance(body, list) else []):
            documents = k == 0 or isinstance(body[k - 1], ast.Assign | ast.AnnAssign)
            value = stmt.value if isinstance(stmt, ast.Expr) else None
            if documents and isinstance(value, ast.Constant) and isinstance(value.value, str):
                docstrings.update(range(stmt.lineno, (stmt.end_lineno or 0) + 1))
    return sum(
        1
        for i, line in enumerate(text.splitlines(), start=1)
        if i not in docstrings and line.strip() and not line.strip().startswith("#")
    )


def test_code_lines_leave_documentation_out():
    text = '"""Module\n\ndoc."""\n\n# a comment\ndef f():\n    """Doc."""\n    return 1\n'
    assert code_lines(text) == 2
    attribute = 'class A:\n    dims = (2, 3)\n    """The dims,\n    two lines."""\n'
    assert code_lines(attribute) == 2
    assert code_lines('def f():\n    x = 1\n    return x\n    "not a docstring"\n') == 4


def test_module_sizes_are_a_note_for_review():
    too_big = {}
    for path in package_files():
        lines = code_lines(path.read_text(encoding="utf-8"))
        if lines > MAX_LINES:
            too_big[path.relative_to(ROOT).as_posix()] = lines
    for rel, lines in sorted(too_big.items()):
        warnings.warn(
            f"{rel} has {lines} lines of code, over {MAX_LINES}: one concern still?",
            SizeWarning,
            stacklevel=1,
        )


def test_a_size_note_is_a_warning_not_a_failure(monkeypatch):
    # what the rules above do with a module or a kernel over the size: the test passes and
    # says so; under the size they say nothing
    here = sys.modules[__name__]
    monkeypatch.setattr(here, "MAX_LINES", 10)
    with pytest.warns(SizeWarning, match="lines of code, over 10"):
        test_module_sizes_are_a_note_for_review()
    monkeypatch.setattr(here, "KERNEL_LINES", 10)
    with pytest.warns(SizeWarning, match=r"the kernel \(core/\) has \d+ lines of code, over 10"):
        test_the_kernel_is_thin_and_light()
    monkeypatch.setattr(here, "MAX_LINES", 10**9)
    monkeypatch.setattr(here, "KERNEL_LINES", 10**9)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SizeWarning)
        test_module_sizes_are_a_note_for_review()
        test_the_kernel_is_thin_and_light()


def test_no_private_name_is_imported_across_modules():
    """A name with a leading underscore stays in its module (issue 48): what two modules share
    is public in one of them, or in a module of its own."""
    crossing = []
    for path in package_files():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                names = [a.name for a in node.names]
                private = [n for n in names if n.startswith("_") and not n.startswith("__")]
                crossing += [f"{path.relative_to(ROOT)}: {node.module} {n}" for n in private]
    assert crossing == []


#: The packages where the framework calls plugins: none probes a contract member with
#: ``getattr``/``hasattr`` (issue 48 item 3), since the kind's base guarantees every member.
CALLERS = ("core", "execution", "storage", "studies", "iterators", "testing")
#: The probes that stay, by file and member, each with why it is not a contract call.
PROBES_ALLOWED = {
    # check_options proves that a candidate class has an Options schema: a class without one
    # is what it reports, so the attribute may be missing
    ("testing/options.py", "Options"),
}


def contract_probes() -> list[str]:
    """``getattr(x, "<member>", ...)`` and ``hasattr(x, "<member>")`` in :data:`CALLERS`,
    for every member name of the contracts (read from their code), but the allowed ones."""
    from fbia.testing.contracts import contracts

    names = {m.attribute for members in contracts().values() for m in members}
    found = []
    for package in CALLERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if not (
                    isinstance(node, ast.Call)
                    and isinstance(node.func, ast.Name)
                    and node.func.id in ("getattr", "hasattr")
                    and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant)
                    and node.args[1].value in names
                ):
                    continue
                if (rel, node.args[1].value) not in PROBES_ALLOWED:
                    found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_contract_member_is_probed_with_getattr():
    """Call the member directly: the base carries its default (a new optional member goes
    on the base, not into a ``getattr(plugin, "x", default)`` at its caller)."""
    assert contract_probes() == []


def test_the_probe_rule_finds_a_probe(tmp_path, monkeypatch):
    here = sys.modules[__name__]
    (tmp_path / "core").mkdir()
    (tmp_path / "core" / "m.py").write_text('x = getattr(model, "tangent_inputs", None)\n')
    monkeypatch.setattr(here, "ROOT", tmp_path)
    monkeypatch.setattr(here, "CALLERS", ("core",))
    assert contract_probes() == ["core/m.py:1: getattr(model, 'tangent_inputs', None)"]
