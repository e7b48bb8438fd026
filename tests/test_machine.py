import pytest

from wheelloader.estimator import Bucket, Loader, ParameterError


def test_defaults_and_round_trip():
    bucket, loader = Bucket(), Loader()
    assert bucket.capacity_per_width == pytest.approx(0.2)
    assert Bucket.from_dict(bucket.to_dict()) == bucket
    assert Loader.from_dict(loader.to_dict()) == loader


@pytest.mark.parametrize("kwargs", [{"width": 0.0}, {"edge_thickness": -0.01}, {"capacity": float("inf")},
                                    {"mass": "heavy"}])
def test_bad_bucket(kwargs):
    with pytest.raises(ParameterError):
        Bucket(**kwargs)


def test_unknown_field():
    with pytest.raises(ParameterError, match="unknown field"):
        Loader.from_dict({"max_force": 1.0})
