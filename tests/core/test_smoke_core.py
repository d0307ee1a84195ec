"""First checks of the core types (more in the dedicated test modules)."""

import numpy as np
import pytest

import fbia


def test_polyline_normal_points_into_fluid_and_length():
    x = np.linspace(0.0, 2.0, 9)
    gamma = fbia.Interface.polyline(np.c_[x, np.zeros_like(x)])
    np.testing.assert_allclose(gamma.normals, np.tile([0.0, 1.0], (8, 1)), atol=1e-15)
    assert gamma.measure == pytest.approx(2.0)


def test_bounds_the_wrong_way_round_is_a_config_error_naming_the_parameter():
    with pytest.raises(
        fbia.ConfigError, match=r"^E: lower bound 800.0 is not below upper bound 100.0$"
    ):
        fbia.Parameter("E", bounds=(800.0, 100.0))
