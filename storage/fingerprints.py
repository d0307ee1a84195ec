"""What a forward run and its comparison depend on: fingerprints and store keys.

Two layers, because they change for different reasons:

* a **forward run** depends on the model (class, version, options), the fixed inputs, the
  coordinates it is asked for (the distinct coordinates of the observations) and the input
  values x; its key is :func:`run_key`;
* its **comparison** with the observations depends on the measure (class, version, options)
  and the observed data (coordinates, interfaces, measurement points); its key is
  :func:`comparison_key`.

Neither depends on the likelihood's σ_N (the likelihood is computed when a run is read), on
bounds, priors, the iterator or the executor: changing those reuses every stored run, and
changing the measure or the observations reuses every stored forward run whose interfaces the
store holds (the comparison is recomputed, which is cheap).

A plugin's options are keyed by their *effective* values, every option with the value the
plugin runs with, its default resolved (issue 44): a release that changes an option's default
changes the key of a study relying on it, and a study that pins the old value keeps it.  The
fingerprint also names the options at their defaults (``defaults``, left out of the keys), so
that a refusal can say "its default then".

Keys are SHA-256 digests of canonical JSON (sorted keys, floats by ``repr``: equal text means
bit-equal values).  The functions work on fingerprint *dicts*, so a stored fingerprint gives
the same keys as the live problem it was made from (the store's migration relies on it).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.metadata
import io
import json
import os
import sys
import tokenize
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..core.data_files import read_meshio
from ..core.errors import ConfigError
from ..core.interface import Interface
from ..core.observation import coordinate_key
from ..core.options import plugin_options
from ..core.problem import InverseProblem, jsonable
from ..core.protocols import ForwardModelBase, MeasureBase

__all__ = [
    "CODE_PREFIX",
    "canonical",
    "class_code_digest",
    "code_digest",
    "code_digest_as_stored",
    "code_digest_like",
    "code_text",
    "digest_kind",
    "as_keyed_now",
    "comparison_key",
    "comparison_part",
    "coordinates_of",
    "default_options",
    "describe_change",
    "interface_digest",
    "model_part",
    "option_values",
    "problem_fingerprint",
    "run_key",
    "same_model_class",
]


def canonical(value: Any) -> str:
    """JSON with sorted keys and exact floats (``repr``): equal text means equal content."""
    return json.dumps(jsonable(value), sort_keys=True, separators=(",", ":"), allow_nan=False)


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


# -- plugins and data ----------------------------------------------------------------------------
def _class_version(obj: Any) -> dict[str, str]:
    """Class path and version of a plugin object.  The version is the plugin's declared
    ``numerics_version`` (``"numerics 1"``) when its class has one -- it changes only when the
    plugin's numbers do, so upgrading the package keeps the stores -- else the version of the
    distribution named like its top-level package (``fbia``, ``fbia_mysolver``), else the
    module's ``__version__``."""
    cls = type(obj)
    declared = _declared_numerics(cls)
    version = f"numerics {declared}" if declared is not None else _package_version(obj)
    return {"class": f"{cls.__module__}.{cls.__qualname__}", "version": version}


def _package_version(obj: Any) -> str:
    """The version of the distribution of the top-level package of ``obj`` (a plugin or its
    class): what stores keyed before plugins declared a numerics version."""
    cls = obj if isinstance(obj, type) else type(obj)
    top = cls.__module__.split(".")[0]
    try:
        return importlib.metadata.version(top.replace("_", "-"))
    except importlib.metadata.PackageNotFoundError:
        mod = sys.modules.get(cls.__module__)
        return str(getattr(mod, "__version__", "unversioned"))


def _options(obj: Any) -> dict[str, Any]:
    """Every option of a plugin with its effective value (its default resolved); a file option
    (a ``Path``, e.g. ``mesh_file``) by its content."""
    # inf and nan as strings, as canonical() does
    return _keyed(obj, jsonable(plugin_options(obj)))


def _keyed(obj: Any, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` (options of ``obj``) with each file option replaced by its content digest."""
    opts = getattr(obj, "options", None)
    out = dict(values)
    for key in out:
        value = getattr(opts, key, None)
        if isinstance(value, Path):
            out[key] = _file_digest(value)
    return out


# Mesh and surface formats keyed by their parsed content (points, cells, tags): meshio writes
# a timestamp into a PLY header, so regenerating the same surface changes its bytes.
_PARSED_SUFFIXES = frozenset({".msh", ".vtu", ".vtk", ".ply", ".stl", ".obj", ".off", ".xdmf"})


def _file_digest(path: Path) -> dict[str, Any]:
    """File name and SHA-256 of its content: of what meshio parses from a mesh or surface
    file (points, cell blocks, cell and point data, field data), else of its bytes.  Moving a
    study folder keeps a store valid, editing the mesh file it names does not, rewriting the
    same mesh with another header does not either."""
    parsed = _parsed_digest(path)
    if parsed is not None:
        return {"file": path.name, "content": parsed}
    digest = _bytes_digest(path)
    return {"file": path.name if digest else str(path), "sha256": digest}


def _parsed_digest(path: Path) -> str | None:
    """SHA-256 of a mesh file's parsed content (None: not a format meshio reads, or unreadable:
    the bytes key it)."""
    if path.suffix.lower() not in _PARSED_SUFFIXES:
        return None
    try:
        mesh = read_meshio(path)
    except ConfigError:  # unreadable: key the bytes (validation reports it)
        return None
    h = hashlib.sha256(str(_digest(np.asarray(mesh.points, dtype=float))).encode())
    for block in mesh.cells:
        h.update(f"{block.type}:{_digest(np.asarray(block.data, dtype=np.int64))}".encode())
    for group, values in (("cell", mesh.cell_data), ("point", mesh.point_data)):
        for name in sorted(values):
            arrays = values[name] if group == "cell" else [values[name]]
            h.update(f"{group}:{name}".encode())
            for a in arrays:
                h.update(str(_digest(np.asarray(a))).encode())
    h.update(
        canonical(
            jsonable({k: np.asarray(v).tolist() for k, v in mesh.field_data.items()})
        ).encode()
    )
    return h.hexdigest()


def _bytes_digest(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _digest(*arrays: Any) -> str | None:
    arrays = tuple(a for a in arrays if a is not None)
    if not arrays:
        return None
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def interface_digest(gamma: Interface) -> str:
    """SHA-256 of an interface's vertices and cells (an observation's part of a fingerprint)."""
    return str(_digest(gamma.vertices, gamma.cells))


def default_options(obj: Any) -> dict[str, Any]:
    """The options of plugin ``obj`` that are at their defaults, with their values as they
    appear in a fingerprint."""
    given = plugin_options(obj, exclude_defaults=True)
    values = jsonable(plugin_options(obj))
    return _keyed(obj, {k: v for k, v in values.items() if k not in given})


def as_keyed_now(
    part: Mapping[str, Any],
    obj: Any,
    plugin: str = "model",
    defaults: Sequence[str] | None = None,
) -> dict[str, Any]:
    """A stored model or comparison part (:func:`model_part`, :func:`comparison_part`) as this
    fbia keys its ``plugin`` ("model" or "measure") ``obj``, where the stored part tells:

    * the package version it was keyed by becomes ``obj``'s declared numerics version (this
      release's version, or an earlier one's for a plugin that declares its numerics now:
      the store's source digest still checks the code);
    * a file option keyed by its bytes is keyed by its parsed content when the bytes are the
      same;
    * an option of ``obj`` that the part does not record gets ``obj``'s value when that is
      its default now: an option added since (the plugin author's contract: a new option's
      default keeps the old behaviour), or in a part that recorded only the options that
      differed from their defaults (fbia before issue 44) one at its default then, which the
      caller may take only where the plugin's code is unchanged since;
    * an option the part records that ``obj`` no longer has is left out where it was at its
      default (``defaults``: the names of the part's options that were, when known).

    An option whose recorded value differs from ``obj``'s effective value stays as recorded:
    the keys then differ."""
    at_default = default_options(obj)
    out = json.loads(canonical(part))
    stored, now = out[plugin].get("version"), _class_version(obj)["version"]
    declares = now.startswith("numerics ")
    if stored == _package_version(obj) or (
        declares and isinstance(stored, str) and not stored.startswith("numerics ")
    ):
        out[plugin]["version"] = now
    options = out[plugin].get("options", {})
    current = getattr(obj, "options", None)
    for k, v in options.items():  # a file keyed by its bytes before fbia parsed it: same bytes
        path = getattr(current, k, None)
        if isinstance(v, dict) and isinstance(path, Path) and "sha256" in v:
            if v["sha256"] is not None and v["sha256"] == _bytes_digest(path):
                options[k] = _file_digest(path)
    names = set(plugin_options(obj))
    gone = set(defaults or ()) - names  # removed from the plugin, at their defaults then
    options = {k: v for k, v in options.items() if k not in gone}
    added = {k: v for k, v in at_default.items() if k not in options}
    out[plugin]["options"] = {**added, **options}
    return out


# -- the model plugin's source -------------------------------------------------------------------
def code_digest(obj: Any) -> dict[str, Any]:
    """The source of plugin ``obj``'s code: the class, the SHA-256 of each file's code (by its
    path relative to the plugin's folder: ``model.py``, ``../fem/newton.py``; the code without
    comments and docstrings, :func:`code_text`, so that documenting a model keeps its stores
    and its rows of the reproductions page) and one SHA-256 over them.  The files are the
    class's module and the modules of the plugin's own code it imports, transitively
    (:func:`_own_files`): editing a module of the plugin's package that the model does not
    import (an iterator, the registration in its ``__init__.py``) keeps the digest.  Code the
    plugin imports from elsewhere (fbia.core, numpy, NGSolve) is not included: their versions
    are in the run's provenance.  A plugin that declares a ``numerics_version`` also gets its
    package's version and that declaration: a new release of the package that declares the
    same numerics keeps the stores (an edit without a new version does not)."""
    return class_code_digest(type(obj))


def class_code_digest(cls: type, kind: str = "code") -> dict[str, Any]:
    """:func:`code_digest` of an instance of ``cls`` (the digest depends on the class only):
    what ``paper.json`` records and the reproductions page checks against the code now.
    ``kind = "bytes"``: of the files' bytes, as fbia recorded it before documentation left the
    digest (:func:`code_digest_like`)."""
    name = f"{cls.__module__}.{cls.__qualname__}"
    source = getattr(sys.modules.get(cls.__module__), "__file__", None)
    if source is None:
        return {"class": name, "files": {}, "sha256": ""}
    root, paths = _own_files(cls.__module__, Path(source).resolve())
    files = {Path(os.path.relpath(p, root)).as_posix(): _file_sha(p, kind) for p in paths}
    files = dict(sorted(files.items()))
    return {"class": name, "files": files, "sha256": _sha(canonical(files)), **_numerics(cls)}


def code_digest_as_stored(
    stored: Mapping[str, Any], obj: Any, code: dict[str, Any]
) -> dict[str, Any]:
    """``code`` (``obj``'s :func:`code_digest`), or when ``stored`` is a digest of an earlier
    kind (:func:`digest_kind`), ``obj``'s digest of that kind: so a store of a plugin whose
    files are unchanged keeps its runs after the upgrade (and records the new kind)."""
    return code if digest_kind(stored) == "code" else code_digest_like(stored, type(obj))


def digest_kind(stored: Mapping[str, Any]) -> str:
    """How a recorded code digest was made: ``"folder"`` (fbia before per-file digests: one
    SHA-256 of the plugin's folder, ``files`` its name), ``"bytes"`` (per file, of its bytes:
    fbia before documentation left the digest) or ``"code"`` (per file, of its code alone,
    :data:`CODE_PREFIX` before each)."""
    files = stored.get("files")
    if isinstance(files, str):
        return "folder"
    values = files.values() if isinstance(files, Mapping) else []
    return "code" if all(str(v).startswith(CODE_PREFIX) for v in values) else "bytes"


def code_digest_like(stored: Mapping[str, Any], cls: type) -> dict[str, Any]:
    """The digest of ``cls``'s code now, of the kind ``stored`` was made (:func:`digest_kind`):
    a record of an earlier fbia is compared with the same files read its way."""
    kind = digest_kind(stored)
    if kind == "folder":
        return _folder_digest(cls)
    return class_code_digest(cls, kind)


def _declared_numerics(cls: type) -> str | None:
    """The numerics version a model or measure class declares (its base's default: None); an
    iterator, whose code is digested for a paper's page too, declares none."""
    return cls.numerics_version if issubclass(cls, (ForwardModelBase, MeasureBase)) else None


def _numerics(cls: type) -> dict[str, str]:
    declared = _declared_numerics(cls)
    if declared is None:
        return {}
    # a release may change the code but declare the same numerics
    return {"version": _package_version(cls), "numerics": str(declared)}


#: The prefix of a file's digest of its code alone (:func:`code_text`); a recorded digest
#: without it is of the file's bytes (:func:`digest_kind`).
CODE_PREFIX = "code:"


def _file_sha(path: Path, kind: str = "code") -> str:
    if kind == "bytes":
        return _bytes_digest(path) or "(unreadable)"
    try:
        source = path.read_bytes()
    except OSError:
        return f"{CODE_PREFIX}(unreadable)"
    return CODE_PREFIX + (_code_sha(source) if path.suffix == ".py" else _sha_bytes(source))


def _sha_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@functools.lru_cache(maxsize=512)
def _code_sha(source: bytes) -> str:
    """SHA-256 of :func:`code_text` of a module's bytes (of the bytes if it does not parse),
    once per content in a process: the page checks 28 records against the same files."""
    text = code_text(source)
    return _sha_bytes(source if text is None else text)


def code_text(source: bytes) -> bytes | None:
    """A Python module's code without its documentation: the source with every comment and
    every docstring (of the module, its classes and functions) cut out, and the lines that
    leaves blank, or were blank, dropped (trailing blanks too), but inside a string that is
    not a docstring, whose text is kept as it stands; None when it does not parse (its bytes
    are digested then).

    What a run computes does not depend on them, so a documented plugin keeps the runs of
    its stores and its rows of the reproductions page.  Everything else stays, layout
    included: a string that is not a docstring (an error message, an option's description) is
    code, and so is indentation.  Comments come from :mod:`tokenize`, docstrings and strings
    from :mod:`ast`, all by their positions in the text, which do not change between Python
    versions as the dump of a syntax tree does."""
    try:
        tree = ast.parse(source)
        tokens = list(tokenize.tokenize(io.BytesIO(source).readline))
    except (SyntaxError, ValueError, tokenize.TokenError):
        return None
    text = source.decode(tokens[0].string if tokens else "utf-8")
    # the line breaks Python counts (not str.splitlines's form feeds and the like)
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")

    def column(line: int, offset: int) -> int:  # ast counts UTF-8 bytes, tokenize characters
        return len(lines[line - 1].encode()[:offset].decode())

    cuts = [(*tok.start, *tok.end) for tok in tokens if tok.type == tokenize.COMMENT]
    docstrings = set()
    kept_as_is: set[int] = set()  # lines of a string that spans lines (not a docstring)
    for node in ast.walk(tree):  # breadth first: a docstring's owner before the docstring
        last = getattr(node, "end_lineno", None)
        if isinstance(node, ast.Constant | ast.JoinedStr) and id(node) not in docstrings:
            if last is not None and last > node.lineno:
                kept_as_is.update(range(node.lineno, last + 1))
        elif isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            first = node.body[0] if node.body else None
            if (
                isinstance(first, ast.Expr)
                and isinstance(first.value, ast.Constant)
                and isinstance(first.value.value, str)
                and first.end_lineno is not None
                and first.end_col_offset is not None
            ):
                docstrings.add(id(first.value))
                cuts.append(
                    (
                        first.lineno,
                        column(first.lineno, first.col_offset),
                        first.end_lineno,
                        column(first.end_lineno, first.end_col_offset),
                    )
                )
    for line, col, end_line, end_col in sorted(cuts, reverse=True):
        if line == end_line:
            lines[line - 1] = lines[line - 1][:col] + lines[line - 1][end_col:]
        else:  # blanked, the line count kept
            lines[line - 1] = lines[line - 1][:col]
            lines[line : end_line - 1] = [""] * (end_line - 1 - line)
            lines[end_line - 1] = lines[end_line - 1][end_col:]
    kept = [
        line if number in kept_as_is else line.rstrip()
        for number, line in enumerate(lines, start=1)
        if number in kept_as_is or line.strip()
    ]
    return "\n".join(kept).encode()


def _own_files(module: str, path: Path) -> tuple[Path, list[Path]]:
    """The folder of the plugin whose class lives in ``module`` (file ``path``), and the files
    of its own code that module runs: itself and what it imports from the plugin's packages
    (:func:`_plugin_scope`), transitively.  Imports are read from the files with ``ast``,
    not from ``sys.modules``; a package counts its ``__init__.py`` only when it is imported
    itself (``import pkg``, ``from pkg import name`` of a name it defines), not for one of
    its submodules.  Imports inside functions count: a lazy import is code the model runs."""
    scope = _plugin_scope(module)
    folders = _package_folders(module, path)
    found = {module: path}
    todo = [module]
    while todo:
        name = todo.pop()
        for alternatives in _imports(found[name], name):
            target = _first_module(alternatives, scope, folders)
            if target is not None and target[0] not in found:
                found[target[0]] = target[1]
                todo.append(target[0])
    return folders.get(scope[0], path.parent), list(found.values())


def _plugin_scope(module: str) -> tuple[str, ...]:
    """The packages whose modules are a plugin's own code: a third party's top-level package
    (``fbia_mysolver``), or its module alone when it is a top-level module; for fbia's own
    models the plugin's package (``fbia.plugins.ale_fsi``) and ``fbia.plugins.fem``, the
    finite-element numerics and flow-cell geometry they share."""
    parts = module.split(".")
    if parts[0] != "fbia":
        return (parts[0],)
    if len(parts) > 2 and parts[1] == "plugins":
        return (".".join(parts[:3]), "fbia.plugins.fem")
    return (".".join(parts[:2]),)


def _package_folders(module: str, path: Path) -> dict[str, Path]:
    """The folder of each package ``module`` (file ``path``) is in, itself if a package,
    deepest first (the top-level folder need not be named like its package)."""
    parts = module.split(".")
    if path.name != "__init__.py":
        parts.pop()
    folders, folder = {}, path.parent
    while parts:
        folders[".".join(parts)] = folder
        parts.pop()
        folder = folder.parent
    return folders


def _imports(path: Path, module: str) -> list[tuple[str, ...]]:
    """What the file ``path`` of ``module`` imports, anywhere in it: per import the modules
    it may name, the submodule first (``from .a import b``: the submodule ``a.b``, else ``a``)."""
    try:
        tree = ast.parse(path.read_bytes())
    except (OSError, SyntaxError, ValueError):
        return []
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[tuple[str, ...]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(alias.name,) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(node, package)
            if base:
                out += [(f"{base}.{alias.name}", base) for alias in node.names]
    return out


def _absolute(node: ast.ImportFrom, package: str) -> str:
    """The absolute name of the module ``node`` imports from, inside ``package`` ('' when a
    relative import leaves the top-level package)."""
    if node.level == 0:
        return node.module or ""
    parts = package.split(".") if package else []
    if node.level > len(parts):
        return ""
    head = parts[: len(parts) - node.level + 1]
    return ".".join(head + ([node.module] if node.module else []))


def _first_module(
    names: tuple[str, ...], scope: tuple[str, ...], folders: Mapping[str, Path]
) -> tuple[str, Path] | None:
    """The first of ``names`` that is a module of the plugin's own code, with its file."""
    for name in names:
        if not any(name == s or name.startswith(f"{s}.") for s in scope):
            continue
        path = _module_file(name, folders)
        if path is not None:
            return name, path
    return None


def _module_file(name: str, folders: Mapping[str, Path]) -> Path | None:
    """The file of module ``name`` (a package's ``__init__.py``) under the deepest of the
    package ``folders`` it is in; None when there is none (a name, not a module)."""
    for package, folder in folders.items():
        if name != package and not name.startswith(f"{package}."):
            continue
        rest = name[len(package) + 1 :].split(".") if name != package else []
        base = folder.joinpath(*rest)
        candidates = [base / "__init__.py"] + ([base.with_suffix(".py")] if rest else [])
        return next((f for f in candidates if f.is_file()), None)
    return None


def _folder_digest(obj: Any) -> dict[str, Any]:
    """The code digest of fbia before per-file digests (of a plugin object or its class),
    kept to check the stores it wrote:
    the SHA-256 of every ``.py`` file of the folder of the class's module (the module alone
    when it is a top-level module or a module of ``fbia`` or ``fbia.plugins``), and of
    ``plugins/fem/`` for fbia's own models; ``files`` names the folder."""
    cls = obj if isinstance(obj, type) else type(obj)
    module = sys.modules.get(cls.__module__)
    source = getattr(module, "__file__", None)
    name = f"{cls.__module__}.{cls.__qualname__}"
    if source is None:
        return {"class": name, "files": "", "sha256": ""}
    path = Path(source).resolve()
    parent = cls.__module__.rpartition(".")[0]
    if path.name == "__init__.py" or parent not in ("", "fbia", "fbia.plugins"):
        root = path.parent
        files = sorted(root.rglob("*.py"))
    else:
        root, files = path.parent, [path]
    labels = [f.relative_to(root).as_posix() for f in files]
    if cls.__module__.startswith("fbia.plugins.") and root.name != "fem":
        shared = root.parent / "fem"
        fem = sorted(shared.rglob("*.py")) if shared.is_dir() else []
        files += fem
        labels += [f"../fem/{f.relative_to(shared).as_posix()}" for f in fem]
    h = hashlib.sha256()
    for f, label in zip(files, labels, strict=True):
        h.update(label.encode() + b"\0")
        try:
            h.update(f.read_bytes())
        except OSError:
            h.update(b"(unreadable)")
        h.update(b"\0")
    shown = str(root) if len(files) > 1 else str(path)
    return {"class": name, "files": shown, "sha256": h.hexdigest(), **_numerics(cls)}


# -- fingerprints --------------------------------------------------------------------------------
def problem_fingerprint(problem: InverseProblem) -> dict[str, Any]:
    """Everything that determines a run, its comparison and its likelihood, as one dict.

    Parts: ``model`` and ``measure`` (class, version, every option's effective value, and
    ``defaults``: the names of the options at their defaults), ``observations`` (per
    observation: coordinate, SHA-256 of the interface's vertices and cells and of the
    measurement points and directions, noise_std), ``fixed`` inputs and the likelihood's
    ``noise_std``.  :func:`model_part` and :func:`comparison_part` take out what runs and
    comparisons depend on.
    """
    observations = []
    for obs in problem.observations:
        gamma = obs.interface
        mp = obs.measurement_points
        observations.append(
            {
                "coordinate": dict(obs.coordinate),
                "interface": None if gamma is None else interface_digest(gamma),
                "points": None if mp is None else _digest(mp.points, mp.directions),
                "noise_std": obs.noise_std,
            }
        )
    return {
        "model": _plugin_part(problem.model),
        "measure": _plugin_part(problem.measure),
        "observations": observations,
        "fixed": dict(problem.fixed),
        "noise_std": problem.noise_std,
    }


def _plugin_part(obj: Any) -> dict[str, Any]:
    return {
        **_class_version(obj),
        "options": _options(obj),
        "defaults": sorted(default_options(obj)),
    }


def _keyed_part(plugin: Mapping[str, Any]) -> dict[str, Any]:
    """A plugin's part of a fingerprint without ``defaults``: the key does not depend on
    whether a value is the default or pinned to it."""
    return {k: v for k, v in plugin.items() if k != "defaults"}


def model_part(fingerprint: Mapping[str, Any]) -> dict[str, Any]:
    """What every forward run of the problem depends on besides x: model and fixed inputs."""
    return {"model": _keyed_part(fingerprint["model"]), "fixed": fingerprint["fixed"]}


def comparison_part(fingerprint: Mapping[str, Any]) -> dict[str, Any]:
    """What the comparison of a run with the observations depends on."""
    keep = ("coordinate", "interface", "points")
    return {
        "measure": _keyed_part(fingerprint["measure"]),
        "observations": [{k: o[k] for k in keep} for o in fingerprint["observations"]],
    }


def coordinates_of(fingerprint: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The distinct observation coordinates in order of first appearance (what a forward run
    is asked for, :meth:`InverseProblem.coordinates`)."""
    seen: dict[Any, dict[str, Any]] = {}
    for o in fingerprint["observations"]:
        seen.setdefault(coordinate_key(o["coordinate"]), dict(o["coordinate"]))
    return list(seen.values())


# -- keys ----------------------------------------------------------------------------------------
def run_key(
    model: Mapping[str, Any], coordinates: list[dict[str, Any]], x: Mapping[str, float]
) -> str:
    """The store key of one forward run: model part, coordinates and exact input values."""
    values = {str(k): float(v) for k, v in x.items()}
    return _sha(canonical({"model": model, "coordinates": coordinates, "x": values}))


def comparison_key(comparison: Mapping[str, Any]) -> str:
    """The key of a comparison (measure and observed data) of stored runs."""
    return _sha(canonical(comparison))


def model_key(model: Mapping[str, Any]) -> str:
    """The digest of a model part (a store holds runs of one model)."""
    return _sha(canonical(model))


def same_model_class(stored: Mapping[str, Any], model: Mapping[str, Any]) -> bool:
    """Whether two model parts are of one model class, version and fixed inputs (they may
    differ in their options' values only: a store holds the runs of both)."""
    a, b = stored.get("model", {}), model["model"]
    return (a.get("class"), a.get("version"), stored.get("fixed")) == (
        b.get("class"),
        b.get("version"),
        model.get("fixed"),
    )


def option_values(stored: Mapping[str, Any], model: Mapping[str, Any]) -> str:
    """The options of the model part ``stored`` whose values differ from ``model``'s, as
    ``name = value`` (an option ``model`` has and ``stored`` lacks: ``(no such option)``)."""
    a, b = stored["model"].get("options", {}), model["model"].get("options", {})
    names = sorted(k for k in {*a, *b} if a.get(k) != b.get(k))
    return ", ".join(f"{k} = {json.dumps(a[k]) if k in a else '(no such option)'}" for k in names)


#: an option a fingerprint leaves out: one at its default in a store written when only the
#: options that differed from their defaults were keyed, or one added to the plugin since
_DEFAULT = object()


# -- explaining a change -------------------------------------------------------------------------
def describe_change(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """What differs between two fingerprints, the stored ``old`` and ``new``, in words (at
    most a few items per part).  An option is named with both effective values, each marked
    when it is the plugin's default (``gain: 0.5 (default then) -> 1.0 (default now)``); one
    that ``old`` leaves out (at its default then, or added since) is a change only where
    ``new`` does not take its default."""
    changes: list[str] = []
    for part in ("model", "measure"):
        a, b = old.get(part, {}), new.get(part, {})
        if a == b:
            continue
        if a.get("class") != b.get("class"):
            changes.append(f"{part} {a.get('class')} -> {b.get('class')}")
            continue
        if a.get("version") != b.get("version"):
            changes.append(f"{part} version {_values(a.get('version'), b.get('version'))}")
        options = _changed_options(a, b)
        if options:
            more = f" and {len(options) - 3} more" if len(options) > 3 else ""
            changes.append(f"{part} options ({', '.join(options[:3])}{more})")
    oa, ob = old.get("observations", []), new.get("observations", [])
    if len(oa) != len(ob):
        changes.append(f"number of observations {len(oa)} -> {len(ob)}")
    else:
        for k, (a, b) in enumerate(zip(oa, ob, strict=True)):
            what = [f for f in ("coordinate", "interface", "points", "noise_std") if a[f] != b[f]]
            if what:
                changes.append(f"observation {k + 1} ({', '.join(what)})")
    if old.get("fixed") != new.get("fixed"):
        changes.append(f"fixed inputs {_values(old.get('fixed'), new.get('fixed'))}")
    if old.get("noise_std") != new.get("noise_std"):
        changes.append(
            f"likelihood noise_std {_values(old.get('noise_std'), new.get('noise_std'))}"
        )
    return changes or ["the problem description"]


def _changed_options(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """``name: old -> new`` for each option that differs between two plugin parts of
    fingerprints, in name order (see :func:`describe_change`)."""
    oa, ob = old.get("options", {}), new.get("options", {})
    da, db = set(old.get("defaults", ())), set(new.get("defaults", ()))
    out = []
    for k in sorted({*oa, *ob}):
        va, vb = oa.get(k, _DEFAULT), ob.get(k, _DEFAULT)
        if va == vb or (va is _DEFAULT and k in db) or (vb is _DEFAULT and k in da):
            continue
        then = _shown(va, "default then" if k in da else "")
        now = _shown(vb, "default now" if k in db else "", absent="(no such option now)")
        out.append(f"{k}: {then} -> {now}")
    return out


def _shown(value: Any, note: str = "", absent: str = "default") -> str:
    text = absent if value is _DEFAULT else json.dumps(value)
    text = text if len(text) <= 40 else text[:37] + "..."
    return f"{text} ({note})" if note and value is not _DEFAULT else text


def _values(a: Any, b: Any) -> str:
    return f"{_shown(a)} -> {_shown(b)}"
