import math

import numpy as np
import pytest

from wheelloader.estimator import Bucket, ParameterError, Pile, contact_single, contact_state, default_path


def test_depth_is_perpendicular_distance_on_an_ideal_slope():
    alpha = math.radians(30.0)
    pile = Pile.ideal_slope(alpha, toe_x=0.0, length=4.0)
    x, z = np.array([1.5, 2.0]), np.array([0.2, 0.5])
    state = contact_state(x, z, np.zeros(2), pile, Bucket(), fill_volume=np.zeros(2))
    # distance from (x, z) to the line z = x tan(alpha): (x tan a - z) cos a
    expected = (x * math.tan(alpha) - z) * math.cos(alpha)
    assert np.allclose(state.depth, expected)
    assert np.allclose(state.alpha, alpha)
    assert np.allclose(state.rho, alpha)  # blade horizontal: rho = alpha - 0
    assert np.allclose(state.blade_length, np.minimum(expected / math.sin(alpha), Bucket().floor_length))


def test_depth_follows_a_carved_surface():
    pile = Pile.trapezoid()
    path = default_path()
    carved = pile.carve(path.x, path.z, 1.0, 0.2).pile
    x = np.array([0.8])
    z = np.array([carved.surface_height(0.8) - 0.05])
    on_carved = contact_state(x, z, np.zeros(1), carved, Bucket(), fill_volume=np.zeros(1))
    on_original = contact_state(x, z, np.zeros(1), pile, Bucket(), fill_volume=np.zeros(1))
    assert on_carved.depth[0] < on_original.depth[0]
    assert on_carved.depth[0] == pytest.approx(0.05 * math.cos(on_carved.alpha[0]))


def test_out_of_soil_and_scalar_path_agree():
    pile, bucket = Pile.trapezoid(), Bucket()
    path = default_path()
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket)
    assert state.depth[0] == 0.0 and state.depth[-1] == 0.0 and state.depth.max() > 0.1
    for i in range(0, len(path), 13):
        d, rho, alpha, l_t = contact_single(pile, path.x[i], path.z[i], path.blade_angle[i], bucket.floor_length)
        assert (d, rho, alpha, l_t) == pytest.approx(
            (state.depth[i], state.rho[i], state.alpha[i], state.blade_length[i]), abs=1e-12)


def test_fill_from_carving_and_load_weight():
    pile, bucket = Pile.trapezoid(), Bucket()
    path = default_path()
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket)
    assert state.fill_volume[-1] == pytest.approx(state.carve.in_bucket)
    assert state.fill_volume[-1] >= 0.8 * bucket.capacity
    assert np.allclose(state.load_weight(1500.0), 1500.0 * 9.81 * state.fill_volume)


def test_bad_inputs():
    pile, bucket = Pile.trapezoid(), Bucket()
    with pytest.raises(ParameterError, match="equal length"):
        contact_state([0, 1], [0], [0, 0], pile, bucket)
    with pytest.raises(ParameterError, match="NaN"):
        contact_state([0, float("nan")], [0, 0], [0, 0], pile, bucket)
    with pytest.raises(ParameterError, match="one value per sample"):
        contact_state([0, 1], [0, 0], [0, 0], pile, bucket, fill_volume=[0.0])
