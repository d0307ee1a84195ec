"""Conformance of forward models: solves, fails cleanly, pickles, keeps its workdir."""

from __future__ import annotations

import copy
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import ForwardModelError
from ..core.interface import Interface
from ..core.observation import Solution, coordinate_key
from ..core.protocols import ForwardModelBase, missing_methods
from .errors import ConformanceError, fail


def check_forward_model(
    model: Any,
    parameters: Mapping[str, float],
    coordinates: Sequence[Mapping[str, float]],
    tmp_path: str | Path,
    failing_parameters: Mapping[str, float] | None = None,
    rtol: float = 1e-8,
) -> Solution:
    """Prove that ``model`` honours the forward-model protocol at ``parameters``.

    Checks that

    * it derives from :class:`fbia.ForwardModelBase` and writes the methods its contract
      requires (:class:`fbia.ForwardModel`);
    * ``parameter_names()`` is a sequence of distinct strings containing every key of
      ``parameters``;
    * ``solve(parameters, coordinates, workdir)`` returns an :class:`fbia.Solution` with an
      :class:`fbia.Interface` for every requested coordinate, all of one dimension, with finite
      vertices and unit normals;
    * ``solve`` leaves its inputs and the current directory unchanged;
    * the model is deterministic and independent of the order of the coordinates: a second run
      in a fresh working folder, with a copy of the parameters and the coordinates reversed,
      gives the same interfaces (same connectivity, vertices equal to ``rtol`` times the
      interface's size);
    * a model whose ``tangent_inputs()`` names inputs gives, with ``solve(...,
      tangents=names)`` for those of ``parameters``, tangents of the vertices' shape that
      agree with central differences of the model itself (step 1e-4 relative) to 1e-3 of
      their largest entry (a check of signs, scales and vertex order; a model's own tests
      verify the accuracy it claims);
    * with ``failing_parameters`` (a run known to fail), ``solve`` raises
      :class:`fbia.ForwardModelError` with a message, and nothing else.

    Returns the first :class:`fbia.Solution`.
    """

    tmp_path = Path(tmp_path)
    if not isinstance(model, ForwardModelBase):
        raise fail(model, "does not derive from fbia.ForwardModelBase")
    lacking = missing_methods("forward_model", model)
    if lacking:
        raise fail(model, f"lacks the method(s) its contract requires: {', '.join(lacking)}")
    names = model.parameter_names()
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise fail(model, f"parameter_names() must be a sequence of str, got {names!r}")
    if len(set(names)) != len(list(names)):
        raise fail(model, f"parameter_names() repeats a name: {list(names)}")
    unknown = [k for k in parameters if k not in names]
    if unknown:
        raise fail(
            model,
            f"the test parameters {unknown} are not in parameter_names() = {list(names)}",
        )
    if not coordinates:
        raise ValueError("check_forward_model needs at least one coordinate")

    def solve(
        params: Mapping[str, float], coords: Sequence[Mapping[str, float]], run: str, **kw: Any
    ) -> Any:
        tmp_path.mkdir(parents=True, exist_ok=True)
        workdir = Path(tempfile.mkdtemp(prefix=f"{run}_", dir=tmp_path))  # fresh and empty
        params_before, coords_before = copy.deepcopy(dict(params)), copy.deepcopy(list(coords))
        cwd = os.getcwd()
        try:
            return model.solve(params, coords, workdir, **kw)
        finally:
            if os.getcwd() != cwd:
                os.chdir(cwd)
                raise fail(model, f"solve() changed the current directory (run {run!r})")
            if dict(params) != params_before or list(coords) != coords_before:
                raise fail(model, "solve() modified the parameters or coordinates it was given")

    try:
        first = solve(parameters, coordinates, "run_a")
    except ConformanceError:
        raise
    except ForwardModelError as exc:
        raise fail(model, f"the example run at {dict(parameters)} failed: {exc}") from exc
    except Exception as exc:
        raise fail(
            model,
            f"the run at {dict(parameters)} raised {type(exc).__name__}: {exc} (a failed run "
            "must raise fbia.ForwardModelError)",
        ) from exc
    if not isinstance(first, Solution):
        raise fail(model, f"solve() must return fbia.Solution, got {type(first).__name__}")
    dims = set()
    for c in coordinates:
        key = coordinate_key(c)
        gamma = first.interfaces.get(key)
        if not isinstance(gamma, Interface):
            raise fail(
                model,
                f"solve() returned {type(gamma).__name__} instead of an Interface for the "
                f"requested coordinate {dict(c)}",
            )
        if not (
            np.all(np.isfinite(gamma.normals))
            and np.allclose(np.linalg.norm(gamma.normals, axis=1), 1.0)
        ):
            raise fail(model, f"the interface at {dict(c)} has non-finite or non-unit normals")
        dims.add(gamma.dim)
    if len(dims) != 1:
        raise fail(model, f"solve() mixes interface dimensions {sorted(dims)}")
    if not isinstance(first.diagnostics, Mapping):
        raise fail(model, "Solution.diagnostics must be a mapping")

    again = solve(copy.deepcopy(dict(parameters)), list(reversed(coordinates)), "run_b")
    for c in coordinates:
        a = first.interface(c)
        try:
            b = again.interface(c)
        except KeyError:
            raise fail(
                model, f"with the coordinates reversed, no interface for {dict(c)}"
            ) from None
        if a.dim != b.dim or a.cells.shape != b.cells.shape or not np.array_equal(a.cells, b.cells):
            raise fail(
                model,
                f"two runs with equal inputs give different meshes at {dict(c)} "
                f"({a!r} vs {b!r}); coordinates in reversed order in the second run",
            )
        lo, hi = a.bounds
        scale = float(np.max(hi - lo)) or 1.0
        dev = float(np.max(np.abs(a.vertices - b.vertices)))
        if dev > rtol * scale:
            raise fail(
                model,
                f"two runs with equal inputs differ at {dict(c)} by {dev:.3g} mm "
                f"(> {rtol:g} x size {scale:.3g} mm); coordinates in reversed order in the "
                "second run",
            )

    _check_tangents(model, parameters, coordinates, solve)

    if failing_parameters is not None:
        try:
            solve(failing_parameters, coordinates, "run_fail")
        except ForwardModelError as exc:
            if not str(exc).strip():
                raise fail(model, "ForwardModelError without a message") from exc
        except ConformanceError:
            raise
        except Exception as exc:
            raise fail(
                model,
                f"a failing run raised {type(exc).__name__}: {exc} instead of "
                "fbia.ForwardModelError",
            ) from exc
        else:
            raise fail(
                model, f"the run at {dict(failing_parameters)} was expected to fail but did not"
            )
    return first


def _check_tangents(
    model: ForwardModelBase,
    parameters: Mapping[str, float],
    coordinates: Sequence[Mapping[str, float]],
    solve: Any,
) -> None:
    """The tangents of the inputs in ``parameters`` against central differences (see
    :func:`check_forward_model`)."""
    offered = list(model.tangent_inputs())
    in_coordinates = {k for c in coordinates for k in c}
    names = [n for n in offered if n in parameters and n not in in_coordinates]
    if not names:
        return
    got = solve(parameters, coordinates, "run_tangents", tangents=names)
    for name in names:
        h = 1e-4 * max(abs(float(parameters[name])), 1.0)
        sides = [
            solve({**parameters, name: float(parameters[name]) + sign * h}, coordinates, "run_fd")
            for sign in (1.0, -1.0)
        ]
        for c in coordinates:
            gamma = got.interface(c)
            tangent = np.asarray(gamma.tangents.get(name, np.nan), dtype=float)
            if tangent.shape != gamma.vertices.shape or not np.all(np.isfinite(tangent)):
                raise fail(
                    model,
                    f"solve(..., tangents=[{name!r}]) gave no finite tangent of the vertices' "
                    f"shape {gamma.vertices.shape} at {dict(c)}",
                )
            fd = (sides[0].interface(c).vertices - sides[1].interface(c).vertices) / (2.0 * h)
            scale = max(float(np.abs(fd).max()), float(np.abs(tangent).max()), 1e-300)
            dev = float(np.abs(tangent - fd).max())
            if dev > 1e-3 * scale:
                raise fail(
                    model,
                    f"the tangent of {name} at {dict(c)} differs from a central difference of "
                    f"the model by {dev / scale:.2g} of its size (> 1e-3)",
                )


def example_run(cls: type[ForwardModelBase]) -> tuple[dict[str, float], list[dict[str, float]]]:
    """``cls.example_parameters()`` checked: (parameters, coordinates) of a cheap run."""
    out = cls.example_parameters()
    if out is None:
        raise fail(
            cls,
            "provides no example_parameters(); every forward model needs a classmethod "
            "example_parameters() -> (parameters, coordinates) of a cheap successful run",
        )
    try:
        params, coords = out
        params = {str(k): float(v) for k, v in dict(params).items()}
        coords = [{str(k): float(v) for k, v in dict(c).items()} for c in coords]
    except (TypeError, ValueError) as exc:
        raise fail(
            cls,
            f"example_parameters() must return (dict of floats, list of coordinate dicts): {exc}",
        ) from exc
    if not coords:
        raise fail(cls, "example_parameters() returns no coordinates")
    return params, coords
