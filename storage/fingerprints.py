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

Keys are SHA-256 digests of canonical JSON (sorted keys, floats by ``repr``: equal text means
bit-equal values).  The functions work on fingerprint *dicts*, so a stored fingerprint gives
the same keys as the live problem it was made from (the store's migration relies on it).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..core.data_files import read_meshio
from ..core.errors import ConfigError
from ..core.interface import Interface
from ..core.observation import coordinate_key
from ..core.options import plugin_options
from ..core.problem import InverseProblem, jsonable

__all__ = [
    "canonical",
    "code_digest",
    "default_options",
    "without_defaults",
    "comparison_key",
    "comparison_part",
    "coordinates_of",
    "describe_change",
    "interface_digest",
    "model_part",
    "problem_fingerprint",
    "run_key",
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
    declared = getattr(cls, "numerics_version", None)
    version = f"numerics {declared}" if declared is not None else _package_version(obj)
    return {"class": f"{cls.__module__}.{cls.__qualname__}", "version": version}


def _package_version(obj: Any) -> str:
    """The version of the distribution of ``obj``'s top-level package (what stores keyed
    before plugins declared a numerics version)."""
    cls = type(obj)
    top = cls.__module__.split(".")[0]
    try:
        return importlib.metadata.version(top.replace("_", "-"))
    except importlib.metadata.PackageNotFoundError:
        mod = sys.modules.get(cls.__module__)
        return str(getattr(mod, "__version__", "unversioned"))


def _options(obj: Any) -> dict[str, Any]:
    """A plugin's options that differ from their defaults (adding an option with a default to
    a plugin keeps every key); a file option (a ``Path``, e.g. ``mesh_file``) by its content."""
    # inf and nan as strings, as canonical() does
    out = dict(jsonable(plugin_options(obj, exclude_defaults=True)))
    opts = getattr(obj, "options", None)
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
    """The options of plugin ``obj`` that are at their defaults, with those values, as they
    appear in a fingerprint (what :func:`_options` leaves out)."""
    given = plugin_options(obj, exclude_defaults=True)
    return {k: v for k, v in jsonable(plugin_options(obj)).items() if k not in given}


def without_defaults(part: Mapping[str, Any], obj: Any, plugin: str = "model") -> dict[str, Any]:
    """A stored model or comparison part (:func:`model_part`, :func:`comparison_part`) with
    the options of its ``plugin`` ("model" or "measure") left out that are at ``obj``'s
    defaults now, and the package version it was keyed by replaced by ``obj``'s declared
    numerics version: the part a store written before options were keyed by their difference
    from the defaults (or before a defaulted option existed, or before the plugin declared its
    numerics version, or before a mesh file was keyed by its parsed content) would have
    today."""
    defaults = default_options(obj)
    out = json.loads(canonical(part))
    stored, now = out[plugin].get("version"), _class_version(obj)["version"]
    # Keyed by the package's version: this release's, or (for a plugin that now declares its
    # numerics) an earlier one's, whose code the store's source digest still checks.
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
    out[plugin]["options"] = {
        k: v for k, v in options.items() if not (k in defaults and v == defaults[k])
    }
    return out


def code_digest(obj: Any) -> dict[str, str]:
    """The source of plugin ``obj``'s code: the class, the files it comes from and their
    SHA-256.  The files are every ``.py`` file of the package the class's module belongs to
    (``fbia.plugins.ale_fsi`` -> ``ale_fsi/``, a third party's ``fbia_mysolver`` -> its
    folder), or the module alone when it is a top-level module or one of ``fbia.plugins``'
    single-file plugins; fbia's own models add ``plugins/fem/``, the finite-element numerics
    and flow-cell geometry they share.  Code the plugin imports from elsewhere (fbia.core,
    numpy, NGSolve) is not included: their versions are in the run's provenance.  A plugin that
    declares a ``numerics_version`` also gets its package's version and that declaration: a new
    release of the package that declares the same numerics keeps the stores (an edit without a new
    version does not)."""
    cls = type(obj)
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
        shared = root.parent / "fem"  # the finite-element numerics fbia's models share
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
    out = {"class": name, "files": shown, "sha256": h.hexdigest()}
    declared = getattr(cls, "numerics_version", None)
    if declared is not None:  # a release may change the code but declare the same numerics
        out.update(version=_package_version(obj), numerics=str(declared))
    return out


# -- fingerprints --------------------------------------------------------------------------------
def problem_fingerprint(problem: InverseProblem) -> dict[str, Any]:
    """Everything that determines a run, its comparison and its likelihood, as one dict.

    Parts: ``model`` and ``measure`` (class, version, options), ``observations`` (per
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
        "model": {**_class_version(problem.model), "options": _options(problem.model)},
        "measure": {**_class_version(problem.measure), "options": _options(problem.measure)},
        "observations": observations,
        "fixed": dict(problem.fixed),
        "noise_std": problem.noise_std,
    }


def model_part(fingerprint: Mapping[str, Any]) -> dict[str, Any]:
    """What every forward run of the problem depends on besides x: model and fixed inputs."""
    return {"model": fingerprint["model"], "fixed": fingerprint["fixed"]}


def comparison_part(fingerprint: Mapping[str, Any]) -> dict[str, Any]:
    """What the comparison of a run with the observations depends on."""
    keep = ("coordinate", "interface", "points")
    return {
        "measure": fingerprint["measure"],
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


#: an option a fingerprint leaves out: at its default
_DEFAULT = object()


# -- explaining a change -------------------------------------------------------------------------
def describe_change(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """What differs between two fingerprints, in words (at most a few items per part)."""

    def values(a: Any, b: Any) -> str:
        def shown(v: Any) -> str:
            return "default" if v is _DEFAULT else json.dumps(v)

        text = f"{shown(a)} -> {shown(b)}"
        return text if len(text) <= 60 else text[:57] + "..."

    changes: list[str] = []
    for part in ("model", "measure"):
        a, b = old.get(part, {}), new.get(part, {})
        if a == b:
            continue
        if a.get("class") != b.get("class"):
            changes.append(f"{part} {a.get('class')} -> {b.get('class')}")
            continue
        if a.get("version") != b.get("version"):
            changes.append(f"{part} version {values(a.get('version'), b.get('version'))}")
        oa, ob = a.get("options", {}), b.get("options", {})
        keys = sorted(k for k in {*oa, *ob} if oa.get(k, _DEFAULT) != ob.get(k, _DEFAULT))
        if keys:
            shown = ", ".join(
                f"{k}: {values(oa.get(k, _DEFAULT), ob.get(k, _DEFAULT))}" for k in keys[:3]
            )
            more = f" and {len(keys) - 3} more" if len(keys) > 3 else ""
            changes.append(f"{part} options ({shown}{more})")
    oa, ob = old.get("observations", []), new.get("observations", [])
    if len(oa) != len(ob):
        changes.append(f"number of observations {len(oa)} -> {len(ob)}")
    else:
        for k, (a, b) in enumerate(zip(oa, ob, strict=True)):
            what = [f for f in ("coordinate", "interface", "points", "noise_std") if a[f] != b[f]]
            if what:
                changes.append(f"observation {k + 1} ({', '.join(what)})")
    if old.get("fixed") != new.get("fixed"):
        changes.append(f"fixed inputs {values(old.get('fixed'), new.get('fixed'))}")
    if old.get("noise_std") != new.get("noise_std"):
        changes.append(f"likelihood noise_std {values(old.get('noise_std'), new.get('noise_std'))}")
    return changes or ["the problem description"]
