"""Sample interfaces (lengths in mm) with fbia's orientation: normals point from the solid
into the fluid."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from ..core.interface import Interface


def straight_line_2d(
    length: float = 1.0, n: int = 32, height: float = 0.0, slope: float = 0.0
) -> Interface:
    """The flat floor ``y = height + slope * x``, ``0 <= x <= length``, in ``n`` segments.

    Ordered upstream to downstream (solid below), so its normals point up into the fluid.
    """

    x = np.linspace(0.0, length, n + 1)
    return Interface.polyline(np.c_[x, height + slope * x])


def mound_2d(length: float = 1.0, height: float = 0.2, n: int = 64) -> Interface:
    """A smooth biofilm mound ``y = height * sin(pi x / length)**2`` on the channel floor.

    Ordered upstream to downstream (solid below), in ``n`` segments of equal x-extent.
    """

    x = np.linspace(0.0, length, n + 1)
    return Interface.polyline(np.c_[x, height * np.sin(np.pi * x / length) ** 2])


def circle_2d(radius: float = 0.3, n: int = 64, centre: Sequence[float] = (0.0, 0.0)) -> Interface:
    """A closed polygon with ``n`` vertices on a circle around a solid disc.

    Walked clockwise, so the solid lies on the right and the normals point outwards.
    """

    phi = -np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)  # clockwise
    pts = np.asarray(centre, dtype=float) + radius * np.c_[np.cos(phi), np.sin(phi)]
    return Interface.polyline(pts, closed=True)


def square_3d(
    size: float = 1.0, n: int = 8, height: float = 0.0, slope: Sequence[float] = (0.0, 0.0)
) -> Interface:
    """The plane ``z = height + slope[0] x + slope[1] y`` over ``[0, size]^2``.

    ``2 n^2`` triangles, ordered so that the normals point up (+z side is fluid).
    """

    t = np.linspace(0.0, size, n + 1)
    x, y = (a.ravel() for a in np.meshgrid(t, t, indexing="xy"))
    z = height + slope[0] * x + slope[1] * y
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = np.vstack([np.c_[a, b, c], np.c_[a, c, d]])
    return Interface.surface(np.c_[x, y, z], tris)


def sphere_3d(
    radius: float = 0.3, subdivisions: int = 2, centre: Sequence[float] = (0.0, 0.0, 0.0)
) -> Interface:
    """An icosphere (``trimesh.creation.icosphere``) around a solid ball; normals point out.

    ``subdivisions=2`` gives 320 triangles, each further level four times as many.
    """

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return Interface.surface(np.asarray(mesh.vertices) + np.asarray(centre), mesh.faces)
