"""Measures differentiated along a vertex motion (issue 30 item 3): d residuals = dr/dv · dv.

``cpp`` gives it analytically (``residuals_jvp``); ``ray`` and ``rkhs`` through the framework's
central difference of the measure alone (``fbia.iterators.tangents``).  Checked against
central differences of the residuals with a step 10x larger (O(h^2) apart; a larger step
crosses the kinks where cpp's closest point changes element), in 2-D and 3-D.
"""

import numpy as np
import pytest
from test_measures_common import bumpy_sphere, make, wavy_curve

import fbia
from fbia.iterators.tangents import directional_difference


def _pair(dim):
    """A simulated interface, an observation of another one, a smooth vertex motion."""
    if dim == 2:
        sim, seen = wavy_curve(0.3), wavy_curve(0.0)
        x = sim.vertices[:, 0]
        motion = np.c_[0.2 * np.cos(2 * x), np.sin(3 * x) + 0.5]
    else:
        seen = bumpy_sphere(0.02)
        # turned a little about an oblique axis: no vertex equidistant from two triangles
        # (the sphere's symmetry would give ties, where the distance has no derivative)
        from scipy.spatial.transform import Rotation

        turn = Rotation.from_rotvec(0.05 * np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0))
        sim = bumpy_sphere(0.05).with_vertices(turn.apply(bumpy_sphere(0.05).vertices.copy()))
        v = sim.vertices
        motion = np.c_[np.sin(v[:, 1]), np.cos(v[:, 0]), 0.5 + v[:, 2]]
    return sim, fbia.Observation(seen), motion


def _difference(measure, sim, obs, motion, h):
    plus = measure.residuals(sim.with_vertices(sim.vertices + h * motion), obs)
    minus = measure.residuals(sim.with_vertices(sim.vertices - h * motion), obs)
    return (plus - minus) / (2.0 * h)


@pytest.mark.parametrize("dim", [2, 3])
def test_cpp_residuals_jvp_is_exact(dim):
    sim, obs, motion = _pair(dim)
    cpp = make("cpp")
    exact = cpp.residuals_jvp(sim, obs, motion)
    assert exact.shape == cpp.residuals(sim, obs).shape
    reference = _difference(cpp, sim, obs, motion, 1e-7)
    assert np.abs(exact - reference).max() <= 1e-6 * np.abs(reference).max()
    # a vertex on the observed interface moves the residual by minus the normal (the measure's
    # angle-weighted pseudo-normal, within 1e-3 of the interface's vertex normal in 3-D)
    gamma = obs.interface
    on = fbia.Interface(gamma.vertices, gamma.cells)
    normals = gamma.vertex_normals
    jvp = cpp.residuals_jvp(on, obs, normals)
    assert np.allclose(jvp, -1.0, atol=1e-6 if dim == 2 else 1e-3)


@pytest.mark.parametrize("name", ["ray", "cpp", "rkhs"])
@pytest.mark.parametrize("dim", [2, 3])
def test_directional_difference_of_the_measure(name, dim):
    sim, obs, motion = _pair(dim)
    measure = make(name)
    got = directional_difference(measure, sim, obs, motion)
    size = float(np.ptp(sim.vertices, axis=0).max())
    reference = _difference(measure, sim, obs, motion, 1e-5 * size / np.abs(motion).max())
    scale = np.abs(reference).max()
    assert scale > 0.0
    assert np.abs(got - reference).max() <= 1e-5 * scale
