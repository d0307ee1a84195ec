"""Properties every built-in measure shares: registry, zero for identical interfaces, finite
values in 2-D and 3-D, distance = 2-norm of residuals (ray, cpp), picklable."""

import doctest
import importlib
import pickle

import numpy as np
import pytest

import fbia
from fbia.measures import CppMeasure, RayMeasure, RkhsMeasure

MEASURES = {"ray": RayMeasure, "cpp": CppMeasure, "rkhs": RkhsMeasure}


def wavy_curve(phase: float = 0.0, n: int = 120) -> fbia.Interface:
    x = np.linspace(0.0, 2.0, n)
    return fbia.Interface.polyline(np.c_[x, 0.1 + 0.05 * np.sin(3 * x + phase)])


def bumpy_sphere(amplitude: float = 0.0) -> fbia.Interface:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    v = np.asarray(s.vertices)
    r = 1.0 + amplitude * np.sin(3 * v[:, 0]) * np.cos(2 * v[:, 1])
    return fbia.Interface.surface(v * r[:, None], s.faces)


def make(name: str):
    return fbia.measure(name, sigma_w=0.2) if name == "rkhs" else fbia.measure(name)


def test_registry_lists_and_builds_the_three_measures():
    entries = {e.name: e for e in fbia.list_plugins("measure")}
    assert {"ray", "cpp", "rkhs"} <= set(entries)
    for name, cls in MEASURES.items():
        assert entries[name].factory is cls
        assert entries[name].plugin == "fbia.measures"
    assert isinstance(fbia.measure("ray", max_distance=0.5, miss_penalty=0.1), RayMeasure)
    with pytest.raises(fbia.ConfigError, match="unknown option 'max_dist'; valid options: "):
        fbia.measure("ray", max_dist=0.5)
    with pytest.raises(fbia.ConfigError, match="miss_penalty"):
        fbia.measure("ray", miss_penalty=-1.0)


@pytest.mark.parametrize("name", sorted(MEASURES))
@pytest.mark.parametrize("dim", [2, 3])
def test_identical_interfaces_give_zero(name, dim):
    gamma = wavy_curve() if dim == 2 else bumpy_sphere(0.05)
    twin = fbia.Interface(gamma.vertices.copy(), gamma.cells.copy())
    measure = make(name)
    r = measure.residuals(twin, fbia.Observation(gamma))
    tol = 1e-7 if name == "rkhs" else 1e-14  # rkhs: sqrt of round-off in D^2
    assert np.all(np.abs(r) <= tol)


@pytest.mark.parametrize("name", sorted(MEASURES))
@pytest.mark.parametrize("dim", [2, 3])
def test_perturbed_interfaces_give_finite_residuals_of_the_documented_length(name, dim):
    if dim == 2:
        observed, simulated = wavy_curve(), wavy_curve(phase=0.2, n=77)
    else:
        observed, simulated = bumpy_sphere(0.05), bumpy_sphere(0.08)
    obs = fbia.Observation(observed)
    measure = make(name)
    r = measure.residuals(simulated, obs)
    # rkhs: one residual per test point and component, fixed by the observation
    expected_len = {
        "ray": len(observed),
        "cpp": len(simulated.vertices),
        "rkhs": len(measure.residuals(observed, obs)),
    }[name]
    assert r.shape == (expected_len,) and np.all(np.isfinite(r))
    assert np.max(np.abs(r)) > 1e-4  # the perturbation is seen
    # rkhs: the vector's norm is D to the trapezoidal rule's accuracy, the others exactly
    rel = 1e-6 if name == "rkhs" else 1e-12
    assert measure.distance(simulated, obs) == pytest.approx(np.linalg.norm(r), rel=rel)
    clone = pickle.loads(pickle.dumps(measure))
    np.testing.assert_array_equal(clone.residuals(simulated, obs), r)


@pytest.mark.parametrize("name", ["ray", "cpp"])
def test_growing_sphere_is_negative_shrinking_is_positive(name):
    """A simulated interface outside the observed one (solid grew into the fluid) gives
    negative distances, one inside gives positive ones."""
    observed = bumpy_sphere()
    obs = fbia.Observation(observed)
    measure = make(name)
    grown = observed.with_vertices(observed.vertices * 1.1)
    shrunk = observed.with_vertices(observed.vertices * 0.9)
    assert np.all(measure.residuals(grown, obs) < 0)
    assert np.all(measure.residuals(shrunk, obs) > 0)


@pytest.mark.parametrize(
    "module",
    ["fbia.measures.ray", "fbia.measures.cpp", "fbia.measures.rkhs", "fbia.measures._geometry"],
)
def test_module_docstring_recipes_run(module):
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
