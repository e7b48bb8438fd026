import math

import numpy as np
import pytest

from wheelloader.estimator import PAPER_BOUNDS, PARAMETER_NAMES, PRESET_NAMES, ParameterError, SoilParams, preset
from wheelloader.estimator.soil import as_soil, validate_bounds


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_presets_are_valid_and_inside_paper_bounds(name):
    soil = preset(name)
    assert soil.out_of_bounds() == []
    assert soil.check_bounds() is soil


def test_table2_values_are_used_for_the_algoryx_soils():
    assert preset("gravel").gamma == 1474.0 and preset("gravel").phi == 0.7679
    assert preset("modified_sand").gamma == 1874.5 and preset("modified_sand").phi == 0.5934
    assert preset("dirt").cohesion == 2100.0 and preset("dirt").adhesion == 2500.0
    # Table 4 estimates where Algoryx has no counterpart
    assert preset("gravel").k_c == 1274.0 and preset("gravel").n == 1.21


def test_preset_name_normalisation_and_unknown():
    assert preset("Modified-Sand") == preset("modified_sand")
    with pytest.raises(ParameterError, match="unknown soil preset"):
        preset("granite")


def test_degrees_are_caught_with_a_hint():
    with pytest.raises(ParameterError, match="looks like degrees"):
        preset("gravel").replace(phi=44.0)


@pytest.mark.parametrize("field,value", [("gamma", -1.0), ("cohesion", -5.0), ("n", 0.0), ("k_phi", float("nan")),
                                         ("delta", "0.3")])
def test_invalid_values_raise(field, value):
    with pytest.raises(ParameterError, match=field):
        preset("sand").replace(**{field: value})


def test_array_and_dict_round_trip():
    soil = preset("dirt")
    assert SoilParams.from_array(soil.to_array()) == soil
    assert SoilParams.from_dict(soil.to_dict()) == soil
    assert as_soil("dirt") == soil and as_soil(soil.to_dict()) == soil
    with pytest.raises(ParameterError, match="missing"):
        SoilParams.from_dict({"gamma": 1500.0})
    with pytest.raises(ParameterError, match="expected 8"):
        SoilParams.from_array([1.0, 2.0])


def test_sinkage_modulus_is_the_identifiable_combination():
    soil = preset("gravel")
    assert soil.sinkage_modulus(0.02) == pytest.approx(1274.0 / 0.02 + 177.4)
    other = soil.replace(k_c=0.0, k_phi=soil.sinkage_modulus(0.02))
    assert other.sinkage_modulus(0.02) == pytest.approx(soil.sinkage_modulus(0.02))
    with pytest.raises(ParameterError):
        soil.sinkage_modulus(0.0)


def test_paper_bounds_match_section_IIIA():
    assert PAPER_BOUNDS["gamma"] == (1297.0, 2345.0)
    assert PAPER_BOUNDS["k_c"] == (0.0, 10_000.0)
    assert PAPER_BOUNDS["k_phi"] == (0.0, 5_000_000.0)
    assert PAPER_BOUNDS["phi"][1] == pytest.approx(math.radians(45.0))
    assert list(PAPER_BOUNDS) == list(PARAMETER_NAMES)


def test_bounds_validation():
    assert validate_bounds({"gamma": (1400, 1500)})["gamma"] == (1400.0, 1500.0)
    with pytest.raises(ParameterError, match="inverted"):
        validate_bounds({"gamma": (2000, 1500)})
    with pytest.raises(ParameterError, match="unknown parameter"):
        validate_bounds({"density": (1, 2)})
    with pytest.raises(ParameterError, match="finite"):
        validate_bounds({"n": (0.1, np.inf)})
    # bounds outside the domain SoilParams accepts are rejected up front
    with pytest.raises(ParameterError, match="look like degrees"):
        validate_bounds({"phi": (0.0, 45.0)})
    with pytest.raises(ParameterError, match="> 0"):
        validate_bounds({"gamma": (0.0, 3000.0)})
    with pytest.raises(ParameterError, match=">= 0"):
        validate_bounds({"cohesion": (-1.0, 10.0)})
    assert validate_bounds({"delta": (0.0, 1.5)})["delta"] == (0.0, 1.5)
    with pytest.raises(ParameterError, match="outside bounds"):
        preset("gravel").check_bounds({"gamma": (1500.0, 1600.0)})
