"""The surface growth law of Paper A, eq. 9 (issue 15).

Eq. 9 is checked against a scalar evaluation of the formula on a prescribed state, for both
traction measures; zero coefficients give exactly zero growth.
"""

from __future__ import annotations

import numpy as np
import pytest

from fbia.plugins.growth.growth_law import (
    DAY,
    NODE_AREA,
    GrowthCoefficients,
    growth_displacement,
)

PAPER = GrowthCoefficients(k1g=6e4, k2g=5e-2, k3g=8e-2)  # Paper A, growth example


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


def test_zero_coefficients_give_zero_growth():
    normals, flux, traction = _state(30)
    zero = GrowthCoefficients(0.0, 0.0, 0.0)
    for measure in ("density", "nodal_force"):
        assert not np.any(growth_displacement(normals, flux, traction, zero, DAY, measure))
