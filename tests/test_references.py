"""No docstring, comment or option text names a module, object or file that does not exist
(issue 48: descriptions that named ``gp_residuals``, ``gp_adaptive``, ``.smc_plots`` long
after those modules had moved).

Two kinds of reference are checked in every module of the package:

* the cross-reference roles of the docstrings (``:mod:``, ``:class:``, ``:func:``, ...): an
  absolute target (``fbia.core.problem.Result``) must be a name defined in the package; a
  relative one (``.gp.GpSurrogate``, ``~.adaptive.posterior_change``) or a bare one (``Result``)
  must end some such name, as Sphinx resolves them;
* file paths ending in ``.py`` (``surrogates/residuals.py``, ``benchmarks/bench_lm.py``): a
  file of the repository must end with the path.

The names defined in the package are read from the source (modules, classes and the functions,
methods, attributes and constants they define), so nothing is imported.
"""

from __future__ import annotations

import ast
import builtins
import importlib
import re

from _paths import ROOT
from test_architecture import PACKAGES, module_name, package_files

ROLE = re.compile(r":(?:mod|class|func|meth|data|attr|exc|obj):`~?([.A-Za-z0-9_]+)`")
PY_PATH = re.compile(r"(?<![\w/.])((?:[\w.-]+/)*[A-Za-z_]\w*\.py)\b")
#: directories whose files a path may name besides the package's own
OTHER_FILES = ("tests", "benchmarks", "examples", "docs")
#: files of other projects that the package names, and whose they are
EXTERNAL = {"OCT_reader.py": "github.com/kai-neuhaus/OCT_file_tools (imaging/oct_reader.py)"}


def _defined_names() -> set[str]:
    """Every module, class, function, method, attribute and module-level name of the package,
    fully qualified."""
    names: set[str] = set()
    for path in package_files():
        module = module_name(path)
        names.add(module)
        tree = ast.parse(path.read_text(encoding="utf-8"))

        def visit(body: list[ast.stmt], prefix: str) -> None:
            for node in body:
                if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                    names.add(f"{prefix}.{node.name}")
                    if isinstance(node, ast.ClassDef):
                        visit(node.body, f"{prefix}.{node.name}")
                elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                    for t in targets:
                        for leaf in ast.walk(t):
                            if isinstance(leaf, ast.Name):
                                names.add(f"{prefix}.{leaf.id}")
                            elif isinstance(leaf, ast.Attribute) and isinstance(
                                leaf.value, ast.Name
                            ):
                                names.add(f"{prefix}.{leaf.attr}")  # self.x = ...
                elif isinstance(node, (ast.Import, ast.ImportFrom)):
                    for alias in node.names:  # re-exports: fbia.Result, fbia.smc, ...
                        names.add(f"{prefix}.{alias.asname or alias.name.split('.')[0]}")
                elif isinstance(node, (ast.If, ast.Try, ast.With)):
                    visit(getattr(node, "body", []), prefix)
            for node in body:  # instance attributes assigned in methods
                if isinstance(node, ast.FunctionDef):
                    for leaf in ast.walk(node):
                        if (
                            isinstance(leaf, ast.Attribute)
                            and isinstance(leaf.value, ast.Name)
                            and leaf.value.id == "self"
                            and isinstance(leaf.ctx, ast.Store)
                        ):
                            names.add(f"{prefix}.{leaf.attr}")

        visit(tree.body, module)
    return names


def _imported(target: str) -> bool:
    """Whether an absolute ``fbia.`` target is reachable by importing fbia and following
    attributes (the package re-exports its public names lazily); a dataclass field or an
    annotated attribute counts as an attribute."""
    parts = target.split(".")
    obj: object = None
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        rest = parts[i:]
        break
    else:
        return False
    for name in rest:
        if hasattr(obj, name):
            obj = getattr(obj, name)
            continue
        fields = getattr(obj, "__dataclass_fields__", {})
        notes = getattr(obj, "__annotations__", {})
        if name in fields or name in notes:
            return name == rest[-1]
        return False
    return True


def _resolves(target: str, names: set[str], suffixes: set[str]) -> bool:
    target = target.rstrip(".")
    if target.startswith("fbia."):
        return target in names or _imported(target)
    bare = target.lstrip(".")
    if bare in suffixes:
        return True
    # Class.member where the member is inherited: the class and the member both exist
    head, _, member = bare.rpartition(".")
    return bool(head) and head in suffixes and member in suffixes


def _suffixes(names: set[str]) -> set[str]:
    out = set()
    for name in names:
        parts = name.split(".")
        out.update(".".join(parts[i:]) for i in range(len(parts)))
    return out


def test_cross_references_name_what_exists() -> None:
    names = _defined_names()
    suffixes = _suffixes(names)
    # outside the package: the standard library and the libraries fbia builds on
    outside = (
        *("numpy", "scipy", "ngsolve", "netgen", "GPy", "pluggy", "dask", "shapely"),
        *("skimage", "xfem", "trimesh", "meshio", "arviz", "pydantic"),
    )
    broken = []
    for path in package_files():
        for m in ROLE.finditer(path.read_text(encoding="utf-8")):
            target = m.group(1)
            if target.split(".")[0] in outside or hasattr(builtins, target):
                continue
            if not _resolves(target, names, suffixes):
                broken.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert broken == []


def _file_tails() -> set[str]:
    """Every tail of every ``.py`` file of the repository, dotted (``gp_smc.adaptive_loop``)."""
    files = {
        p.relative_to(ROOT).as_posix()
        for d in ("", *PACKAGES, *OTHER_FILES)
        for p in ((ROOT / d).rglob("*.py") if d else ROOT.glob("*.py"))
        if ".venv" not in p.parts and "build" not in p.parts
    }
    return _suffixes({f.replace("/", ".").removesuffix(".py") for f in files})


def _names_a_file(ref: str, tails: set[str]) -> bool:
    """Whether the path ``ref`` (``surrogates/residuals.py``, ``../fem/newton.py``) is the end
    of a file's path in the repository, or a file of another project (:data:`EXTERNAL`)."""
    if ref in ("__init__.py", "setup.py", "conftest.py") or ref in EXTERNAL:
        return True
    while ref.startswith(("../", "./")):  # relative to the naming module's folder
        ref = ref.split("/", 1)[1]
    return ref.removeprefix("fbia/").replace("/", ".").removesuffix(".py") in tails


def test_file_paths_name_files_that_exist() -> None:
    tails = _file_tails()
    broken = [
        f"{path.relative_to(ROOT)}: {m.group(1)}"
        for path in package_files()
        for m in PY_PATH.finditer(path.read_text(encoding="utf-8"))
        if not _names_a_file(m.group(1), tails)
    ]
    assert broken == []


def test_the_checks_see_a_broken_reference() -> None:
    names = _defined_names()
    suffixes = _suffixes(names)
    assert _resolves(".surrogates.gp.GpSurrogate", names, suffixes)
    assert _resolves("fbia.core.problem.Result.posterior_estimate", names, suffixes)
    assert not _resolves(".gp_surrogate", names, suffixes)
    assert not _resolves("fbia.iterators.gp_residuals", names, suffixes)
    tails = _file_tails()
    assert _names_a_file("surrogates/residuals.py", tails)
    assert _names_a_file("../fem/newton.py", tails)
    assert not _names_a_file("gp_smc/gp_adaptive.py", tails)
    assert not _names_a_file("gp_residuals.py", tails)
