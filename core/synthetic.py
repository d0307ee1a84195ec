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
from .protocols import ForwardModel

FloatArray = NDArray[np.float64]


def synthetic_observations(
    model: ForwardModel,
    truth: Mapping[str, float],
    coordinates: Sequence[Coordinate],
    noise_std: float,
    seed: int | np.random.Generator,
    points: int | None = None,
    noise: Literal["normal", "isotropic"] = "normal",
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
            mp, directions = _pick_points(gamma, points)
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


def _pick_points(gamma: Interface, n: int) -> tuple[FloatArray, FloatArray]:
    """``n`` points spread evenly over the interface and the unit normals there."""
    if gamma.dim == 2:
        return _points_along_curves(gamma, n)
    if n > len(gamma.vertices):
        raise ConfigError(
            f"points={n} exceeds the {len(gamma.vertices)} vertices of the 3-D interface"
        )
    v = gamma.vertices
    chosen = [int(np.argmax(v[:, 2]))]
    dist = np.linalg.norm(v - v[chosen[0]], axis=1)
    for _ in range(n - 1):  # farthest-point sampling: deterministic and evenly spread
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(v - v[k], axis=1))
    idx = np.array(chosen)
    return v[idx].copy(), gamma.vertex_normals[idx]


def _points_along_curves(gamma: Interface, n: int) -> tuple[FloatArray, FloatArray]:
    """Midpoints of ``n`` equal arc-length pieces of the polylines; interpolated vertex normals."""
    p0 = gamma.vertices[gamma.cells[:, 0]]
    p1 = gamma.vertices[gamma.cells[:, 1]]
    ends: FloatArray = np.cumsum(gamma.sizes)
    s = (np.arange(n) + 0.5) * ends[-1] / n
    seg = np.minimum(np.searchsorted(ends, s), len(ends) - 1)
    w = 1.0 - (ends[seg] - s) / gamma.sizes[seg]
    pts = (1.0 - w)[:, None] * p0[seg] + w[:, None] * p1[seg]
    vn = gamma.vertex_normals
    nrm = (1.0 - w)[:, None] * vn[gamma.cells[seg, 0]] + w[:, None] * vn[gamma.cells[seg, 1]]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, nrm
