import math

import numpy as np
import pytest

from wheelloader.estimator import BucketPath, ParameterError, bezier_path, default_path, paper_paths, polyline_path


def test_default_path_matches_the_paper_sampling():
    path = default_path()
    assert len(path) == 281  # 4.67 s at 60 Hz
    assert path.duration == pytest.approx(4.67, abs=0.01)
    assert np.allclose(np.diff(path.t), 1 / 60)


def test_bezier_end_points_and_midpoint():
    path = bezier_path((0, 0), (1, 0), (1, 1), duration=1.0, rate=10)
    assert (path.x[0], path.z[0]) == (0, 0) and (path.x[-1], path.z[-1]) == pytest.approx((1, 1))
    # B(0.5) = 0.25 P0 + 0.5 P1 + 0.25 P2
    assert (path.x[5], path.z[5]) == pytest.approx((0.75, 0.25))


def test_blade_angle_profile_curls_smoothly():
    path = bezier_path((0, 0), (1, 0), (1, 1), angle_start=-0.1, angle_end=0.8, curl_from=0.5)
    assert path.blade_angle[0] == pytest.approx(-0.1) and path.blade_angle[-1] == pytest.approx(0.8)
    assert np.all(np.diff(path.blade_angle) >= -1e-15)
    assert np.max(np.abs(np.diff(path.blade_angle, 2))) < 1e-3


def test_paper_paths_are_distinct_and_resample():
    paths = paper_paths()
    assert len(paths) == 4 and len({p.name for p in paths}) == 4
    fine = paths[0].resample(600.0)
    assert len(fine) == 2801 and fine.x[-1] == pytest.approx(paths[0].x[-1])
    seg = polyline_path([(0, 0), (1, 0), (1, 1)], duration=2.0, rate=10)
    assert seg.x[10] == pytest.approx(1.0) and seg.z[10] == pytest.approx(0.0)


def test_bad_paths():
    with pytest.raises(ParameterError, match="increasing"):
        BucketPath([0, 0], [0, 1], [0, 0], [0, 0])
    with pytest.raises(ParameterError, match="NaN"):
        BucketPath([0, 1], [0, math.nan], [0, 0], [0, 0])
    with pytest.raises(ParameterError, match="differ in length"):
        BucketPath([0, 1, 2], [0, 1], [0, 0], [0, 0])
    with pytest.raises(ParameterError):
        bezier_path((0, 0), (1, 0), (1, math.inf))
