"""The plant registry (wheelloader.references.make_plant) and the saved-loop I/O (wheelloader.saved_loops)."""

from __future__ import annotations

import pytest

from wheelloader.estimator import ParameterError, WheelloaderError
from wheelloader.references import PLANT_NAMES, Plant, make_plant
from wheelloader.saved_loops import cycle_file, load_saved_cycle, save_cycle, saved_loops


@pytest.mark.parametrize("name", PLANT_NAMES)
def test_every_name_gives_a_plant_of_that_name(name):
    plant = make_plant(name)
    assert isinstance(plant, Plant) and plant.name == name


def test_settings_reach_the_plant():
    from wheelloader.references.dem import DemConfig, tiny_config

    assert make_plant("mpm", resolution=0.05, threads=2).settings.resolution == 0.05
    assert make_plant("mpm", resolution=0.05, threads=2).settings.threads == 2
    assert make_plant("dem", scenario="ci", threads=3).config == tiny_config(threads=3)
    assert make_plant("dem", threads=3).config == DemConfig(threads=3)
    assert make_plant("fee-env", sensor_noise=0.0).env_kwargs["sensor_noise"] == 0.0


def test_a_dem_plant_pickles():
    """Sweep units carry their plant to another process (Ray)."""
    import pickle

    plant = pickle.loads(pickle.dumps(make_plant("dem", scenario="ci")))
    assert plant.config.scale == 0.4


@pytest.mark.parametrize("name, settings, words", [
    ("mpm3", {}, "unknown plant 'mpm3'"),
    ("mpm", {"resolutoin": 0.02}, "resolutoin"),
    ("dem", {"scenario": "fine"}, "scenario must be one of"),
    ("dem", {"radious": 0.02}, "radious"),
])
def test_a_wrong_name_or_setting_is_named(name, settings, words):
    with pytest.raises(ParameterError, match=words):
        make_plant(name, **settings)


def _log():
    from wheelloader.estimator import synthetic_cycle

    return synthetic_cycle("gravel", noise=0.0)


def test_saved_cycles_round_trip_and_list_by_loop(tmp_path):
    log = _log()
    for strategy in ("ours", "fixed"):
        for k in (1, 2):
            save_cycle(tmp_path / "gravel" / "seed0" / strategy, k, log)
    assert load_saved_cycle(tmp_path / "gravel" / "seed0" / "ours", 3) is None
    assert load_saved_cycle(None, 1) is None
    back = load_saved_cycle(tmp_path / "gravel" / "seed0" / "ours", 2)
    assert back is not None and back.tangential.tolist() == log.tangential.tolist()
    loops = saved_loops(tmp_path)
    assert list(loops) == [("gravel", "seed0", "fixed"), ("gravel", "seed0", "ours")]
    assert loops[("gravel", "seed0", "ours")] == [cycle_file(tmp_path / "gravel" / "seed0" / "ours", k)
                                                  for k in (1, 2)]


def test_a_loop_with_a_missing_cycle_is_refused(tmp_path):
    save_cycle(tmp_path / "sand" / "seed1" / "ours", 1, _log())
    save_cycle(tmp_path / "sand" / "seed1" / "ours", 3, _log())
    with pytest.raises(WheelloaderError, match=r"cycles \[1, 3\]"):
        saved_loops(tmp_path)



def test_the_adaptation_benchmark_lists_plant_in_its_help():
    """``benchmarks/adaptation.py --help`` names ``--plant`` and its choices (the registry's); with a plant, the
    help is that of the plant loop's script, which the option runs."""
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "benchmarks" / "adaptation.py"
    own = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=300)
    assert own.returncode == 0 and "--plant {" + ",".join(PLANT_NAMES) + "}" in own.stdout
    plant = subprocess.run([sys.executable, str(script), "--plant", "fee-env", "--help"], capture_output=True,
                           text=True, timeout=300)
    assert plant.returncode == 0 and "plant_adaptation.py" in plant.stdout and "--soils" in plant.stdout
