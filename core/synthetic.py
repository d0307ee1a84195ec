"""Synthetic observations: the forward model at a ground truth plus Gaussian noise.

Paper B eq. 16: ``Y_obs,C = M(x_gt, theta_gt, C) + sigma_n,obs * eps`` with ``eps ~ N(0, I)``;
Paper A (homogeneous example) adds the noise to the measured points along their directions.

>>> import fbia
>>> model = fbia.forward_model("analytic_mound_2d")
>>> obs = fbia.synthetic_observations(model, {"E": 400.0, "nu": 0.3},
...                                   [{"inflow_rate": 100.0}], noise_std=0.001, seed=0,
...                                   points=12)
>>> obs[0].coordinate, obs[0].noise_std, len(obs[0].measurement_points)
({'inflow_rate': 100.0}, None, 12)

The data noise sigma_n,obs is not the likelihood's sigma_N (Paper B eq. 5, a modelling choice
that also covers discretisation and segmentation error: Paper B uses sigma_n,obs much smaller
than sigma_N), so the observations carry no ``noise_std``: sigma_N comes from the problem
(``InverseProblem(noise_std=...)``, ``[likelihood] noise_std`` in a study).
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .errors import ConfigError, ForwardModelError
from .interface import Interface
from .observation import Coordinate, Observation, check_coordinate
from .protocols import ForwardModelBase

FloatArray = NDArray[np.float64]


def synthetic_observations(
    model: ForwardModelBase,
    truth: Mapping[str, float],
    coordinates: Sequence[Coordinate],
    noise_std: float,
    seed: int | np.random.Generator,
    points: int | None = None,
    noise: Literal["normal", "isotropic"] = "normal",
    placement: Literal["even", "displacement"] = "even",
    significant: float = 0.5,
) -> list[Observation]:
    """Observations of ``model`` at the ground truth ``truth``, one per coordinate.

    The model runs once, at ``truth`` for all ``coordinates``, in a temporary folder.

    Parameters
    ----------
    model
        The forward model.
    truth
        The ground-truth inputs {name: value} (e.g. ``{"E": 400.0, "nu": 0.3}``).
    coordinates
        The observed states, e.g. ``[{"inflow_rate": 100.0}]``.
    noise_std
        Standard deviation sigma_n,obs of the Gaussian noise in mm (0: exact data).
    seed
        Seed or generator of the noise; equal seeds give equal observations.
    points
        If given, also ``points`` measurement points per state, picked evenly along the
        interface (2-D: evenly in arc length; 3-D: farthest-point sampling of the vertices,
        starting at the highest one), with the interface normals there as directions.
    noise
        ``"normal"``: a scalar N(0, noise_std^2) displacement along the unit vertex normal of
        every interface vertex and along the direction of every measurement point (Paper A);
        ``"isotropic"``: N(0, noise_std^2 I) on every coordinate (Paper B eq. 16 literally).
    placement
        Where the ``points`` go. ``"even"``: over the whole interface (above).
        ``"displacement"``: evenly over the parts of the interface that moved significantly
        along their normal, as Paper A places them ("evenly distributed in regions with
        significant displacement", directions normal to the displaced interface): 2-D, the
        edges whose normal displacement |u . n| (both end vertices) is at least
        ``significant`` times its largest value, points at the midpoints of ``points`` equal
        pieces of their total length; 3-D, farthest-point sampling of those vertices.  Needs
        the model's ``undeformed()`` interface (vertex for vertex the solution's).
    significant
        The threshold of ``placement = "displacement"``, a fraction in (0, 1).

    Returns
    -------
    list[Observation]
        One per coordinate, in order, each with its coordinate and ``noise_std=None`` (the
        likelihood's sigma_N is the problem's, see above). Each interface keeps the model's
        connectivity.

    Raises
    ------
    fbia.ConfigError
        Bad arguments.
    fbia.ForwardModelError
        The forward model failed at the ground truth.
    """
    try:
        sigma = float(noise_std)
    except (TypeError, ValueError):
        raise ConfigError(f"noise_std must be a number, got {noise_std!r}") from None
    if not (math.isfinite(sigma) and sigma >= 0.0):
        raise ConfigError(f"noise_std must be a finite number >= 0, got {noise_std!r}")
    if noise not in ("normal", "isotropic"):
        raise ConfigError(f"noise must be 'normal' or 'isotropic', got {noise!r}")
    if points is not None and (isinstance(points, bool) or not isinstance(points, int)):
        raise ConfigError(f"points must be a positive integer or None, got {points!r}")
    if points is not None and points < 1:
        raise ConfigError(f"points must be a positive integer or None, got {points!r}")
    if placement not in ("even", "displacement"):
        raise ConfigError(f"placement must be 'even' or 'displacement', got {placement!r}")
    if not (isinstance(significant, (int, float)) and 0.0 < float(significant) < 1.0):
        raise ConfigError(f"significant must be a fraction in (0, 1), got {significant!r}")
    if placement == "displacement" and points is None:
        raise ConfigError("placement 'displacement' places measurement points: give points")
    reference = _reference_interface(model) if placement == "displacement" else None
    coords = [check_coordinate(c, "synthetic_observations: coordinate") for c in coordinates]
    if not coords:
        raise ConfigError("synthetic_observations needs at least one coordinate")
    rng = np.random.default_rng(seed)

    with tempfile.TemporaryDirectory(prefix="fbia-synthetic-") as tmp:
        try:
            solution = model.solve(dict(truth), coords, Path(tmp))
        except ForwardModelError as exc:
            raise ForwardModelError(
                f"synthetic observations: the forward model failed at the ground truth "
                f"{dict(truth)}: {exc}",
                reason=exc.reason,
            ) from exc

    out = []
    for c in coords:
        gamma = solution.interface(c)
        noisy = gamma.with_vertices(
            gamma.vertices + _noise(rng, sigma, noise, gamma.vertex_normals)
        )
        mp, directions = None, None
        if points is not None:
            if reference is None:
                mp, directions = _pick_points(gamma, points)
            else:
                mp, directions = _pick_displaced(gamma, reference, points, float(significant))
            mp = mp + _noise(rng, sigma, noise, directions)
        label = ", ".join(f"{k}={v:g}" for k, v in c.items())
        out.append(
            Observation(
                interface=noisy,
                coordinate=c,
                points=mp,
                directions=directions,
                noise_std=None,
                name=f"synthetic {label}".strip(),
            )
        )
    return out


def _noise(rng: np.random.Generator, sigma: float, kind: str, directions: FloatArray) -> FloatArray:
    """sigma * eps along ``directions`` (kind "normal") or on every coordinate ("isotropic")."""
    n, dim = directions.shape
    if kind == "normal":
        return sigma * rng.standard_normal((n, 1)) * directions
    return sigma * rng.standard_normal((n, dim))


def _reference_interface(model: ForwardModelBase) -> Interface:
    """The model's unloaded interface, for ``placement = "displacement"``."""
    gamma = model.undeformed()
    if gamma is None:
        raise ConfigError(
            f"placement 'displacement' needs the model's undeformed() interface; "
            f"{type(model).__name__} has none (use placement 'even')"
        )
    if not isinstance(gamma, Interface):
        raise ConfigError(f"{type(model).__name__}.undeformed() must return an Interface")
    return gamma


def _pick_displaced(
    gamma: Interface, reference: Interface, n: int, significant: float
) -> tuple[FloatArray, FloatArray]:
    """``n`` points spread evenly over the significantly displaced part of ``gamma``."""
    if reference.vertices.shape != gamma.vertices.shape or not np.array_equal(
        reference.cells, gamma.cells
    ):
        raise ConfigError(
            "placement 'displacement': the model's undeformed() interface does not match the "
            f"solution's vertex for vertex ({len(reference.vertices)} vs {len(gamma.vertices)} "
            "vertices)"
        )
    u_n = np.abs(np.sum((gamma.vertices - reference.vertices) * gamma.vertex_normals, axis=1))
    if not u_n.max() > 0.0:
        raise ConfigError("placement 'displacement': the interface did not move at the truth")
    moved = u_n >= significant * u_n.max()
    if gamma.dim == 3:
        keep = np.flatnonzero(moved)
        if n > len(keep):
            raise ConfigError(
                f"points={n} exceeds the {len(keep)} significantly displaced vertices"
            )
        return _farthest_points(gamma.vertices[keep], gamma.vertex_normals[keep], n)
    edges = np.flatnonzero(moved[gamma.cells].all(axis=1))
    if len(edges) == 0:
        raise ConfigError("placement 'displacement': no interface edge moved significantly")
    return _points_along_curves(gamma, n, edges)


def _pick_points(gamma: Interface, n: int) -> tuple[FloatArray, FloatArray]:
    """``n`` points spread evenly over the interface and the unit normals there."""
    if gamma.dim == 2:
        return _points_along_curves(gamma, n)
    if n > len(gamma.vertices):
        raise ConfigError(
            f"points={n} exceeds the {len(gamma.vertices)} vertices of the 3-D interface"
        )
    return _farthest_points(gamma.vertices, gamma.vertex_normals, n)


def _farthest_points(v: FloatArray, normals: FloatArray, n: int) -> tuple[FloatArray, FloatArray]:
    """Farthest-point sampling of ``n`` of the vertices ``v`` (deterministic, evenly spread),
    starting at the highest one; their normals."""
    chosen = [int(np.argmax(v[:, 2]))]
    dist = np.linalg.norm(v - v[chosen[0]], axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(v - v[k], axis=1))
    idx = np.array(chosen)
    return v[idx].copy(), normals[idx]


def _points_along_curves(
    gamma: Interface, n: int, edges: NDArray[np.int64] | None = None
) -> tuple[FloatArray, FloatArray]:
    """Midpoints of ``n`` equal arc-length pieces of the polylines (of their ``edges`` only,
    in order, if given); interpolated vertex normals."""
    cells = gamma.cells if edges is None else gamma.cells[edges]
    sizes = gamma.sizes if edges is None else gamma.sizes[edges]
    p0 = gamma.vertices[cells[:, 0]]
    p1 = gamma.vertices[cells[:, 1]]
    ends: FloatArray = np.cumsum(sizes)
    s = (np.arange(n) + 0.5) * ends[-1] / n
    seg = np.minimum(np.searchsorted(ends, s), len(ends) - 1)
    w = 1.0 - (ends[seg] - s) / sizes[seg]
    pts = (1.0 - w)[:, None] * p0[seg] + w[:, None] * p1[seg]
    vn = gamma.vertex_normals
    nrm = (1.0 - w)[:, None] * vn[cells[seg, 0]] + w[:, None] * vn[cells[seg, 1]]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, nrm
