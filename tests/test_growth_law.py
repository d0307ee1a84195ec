"""The surface growth law (Paper A eq. 9) and the finger channel (issue 15).

Coarse finger channels (Paper A growth example, 0.6 x 0.3 mm, finger 0.04 x 0.1 mm at
x0 = 0.2 mm).  Eq. 9 is checked against a scalar evaluation of the formula on a prescribed
state, for both traction measures; zero coefficients give exactly zero growth; the finger is
mirror symmetric and its interface chain, normals and nodal lengths are the polygon's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("ngsolve")

from fbia.plugins.ale_fsi.geometry import check_mesh  # noqa: E402
from fbia.plugins.growth.geometry import (  # noqa: E402
    finger_channel,
    finger_outline,
    interface_vertices,
    nodal_lengths,
    vertex_coordinates,
    vertex_normals,
)
from fbia.plugins.growth.growth_law import (  # noqa: E402
    DAY,
    NODE_AREA,
    GrowthCoefficients,
    growth_displacement,
)

PAPER = GrowthCoefficients(k1g=6e4, k2g=5e-2, k3g=8e-2)  # Paper A, growth example
X0 = 0.2


@pytest.fixture(scope="module")
def mesh():
    return finger_channel(mesh_size=0.06, interface_mesh_size=0.01, n_tip=8)


def _state(n: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, n)
    normals = np.c_[np.cos(angle), np.sin(angle)]
    flux = rng.uniform(0, 1e-12, n)  # mol/(mm^2 s)
    traction = rng.normal(0, 0.05, (n, 2))  # Pa
    return normals, flux, traction


def _eq9(normal, h, t, c, dt, area):
    """Eq. 9 for one vertex, written out with scalars."""
    nx, ny = normal
    tx, ty = t[0] * area, t[1] * area
    t_n = abs(tx * nx + ty * ny)
    t_t = abs(tx * ny - ty * nx)  # tangent (ny, -nx); the sign does not matter
    s = dt * (c.k1g * h - c.k2g * t_n - c.k3g * t_t)
    return s * nx, s * ny


@pytest.mark.parametrize("measure", ["density", "nodal_force"])
def test_growth_law_reproduces_eq9(measure):
    normals, flux, traction = _state(40)
    area = 1.0 if measure == "density" else NODE_AREA
    got = growth_displacement(normals, flux, traction, PAPER, DAY, measure)
    want = np.array([_eq9(normals[i], flux[i], traction[i], PAPER, DAY, area) for i in range(40)])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15 * np.abs(want).max())
    if measure == "nodal_force":  # a given per-vertex area replaces the stated one
        a = np.linspace(1e-6, 1e-4, 40)
        got = growth_displacement(normals, flux, traction, PAPER, DAY, measure, nodal_area=a)
        want = np.array(
            [_eq9(normals[i], flux[i], traction[i], PAPER, DAY, a[i]) for i in range(40)]
        )
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15 * np.abs(want).max())


def test_growth_law_signs_and_units():
    """Flux grows along n, traction erodes against it; the two measures differ by the area."""
    n = np.array([[0.0, 1.0], [1.0, 0.0]])
    pressure = np.array([[0.0, -0.02], [0.0, 0.01]])  # normal on vertex 0, shear on vertex 1
    grow = growth_displacement(n, np.array([5e-13, 5e-13]), 0 * pressure, PAPER, DAY)
    assert grow[0, 1] == pytest.approx(6e4 * 5e-13 * DAY) and grow[0, 0] == 0.0
    dens = growth_displacement(n, np.zeros(2), pressure, PAPER, DAY, "density")
    node = growth_displacement(n, np.zeros(2), pressure, PAPER, DAY, "nodal_force")
    assert dens[0, 1] == pytest.approx(-5e-2 * 0.02 * DAY)  # 86 mm: the density reading
    assert dens[1, 0] == pytest.approx(-8e-2 * 0.01 * DAY)
    np.testing.assert_allclose(node, NODE_AREA * dens, rtol=1e-12)
    with pytest.raises(ValueError, match="traction_measure"):
        growth_displacement(n, np.zeros(2), pressure, PAPER, DAY, "force")


def test_finger_outline_and_interface(mesh):
    p = finger_outline(n_tip=8)
    np.testing.assert_allclose(p[[0, -1]], [[0.18, 0.0], [0.22, 0.0]], atol=1e-15)
    assert p[:, 1].max() == pytest.approx(0.1)
    np.testing.assert_allclose(p[::-1] * (-1, 1) + (2 * X0, 0), p, atol=1e-15)  # mirror
    check_mesh(mesh)
    pts = vertex_coordinates(mesh)
    (chain,) = interface_vertices(mesh)
    x = pts[chain]
    assert x[0] == pytest.approx([0.18, 0.0]) and x[-1] == pytest.approx([0.22, 0.0])
    n = vertex_normals(pts, chain)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-12)
    assert n[0] == pytest.approx([-1.0, 0.0]) and n[-1] == pytest.approx([1.0, 0.0])
    assert n[np.argmax(x[:, 1])] == pytest.approx([0.0, 1.0])  # out of the biofilm at the apex
    length = nodal_lengths(pts, chain)
    perimeter = 2 * 0.08 + 8 * 2 * 0.02 * math.sin(math.pi / 16)  # the polygon's
    assert length.sum() == pytest.approx(perimeter, rel=1e-12)


def test_zero_coefficients_give_zero_growth():
    normals, flux, traction = _state(30)
    zero = GrowthCoefficients(0.0, 0.0, 0.0)
    for measure in ("density", "nodal_force"):
        assert not np.any(growth_displacement(normals, flux, traction, zero, DAY, measure))
