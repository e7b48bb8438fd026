import json

import numpy as np
import pytest

from wheelloader.estimator import Bucket, CycleLogError, Pile, contact_state, default_path, preset, soil_forces
from wheelloader.estimator.cyclelog import CycleLog, load_path_csv, save_path_csv


@pytest.fixture()
def log():
    pile, bucket, path = Pile.trapezoid(), Bucket(), default_path()
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket)
    forces = soil_forces(preset("gravel"), state, bucket)
    return CycleLog(path, forces.tangential, forces.normal, pile, bucket, fill_volume=state.fill_volume,
                    pile_after=state.carve.pile, metadata={"soil": "gravel"})


def test_round_trip(tmp_path, log):
    target = tmp_path / "cycle.csv"
    log.save(target)
    back = CycleLog.load(target)
    assert np.array_equal(back.tangential, log.tangential) and np.array_equal(back.path.x, log.path.x)
    assert back.pile == log.pile and back.pile_after == log.pile_after and back.bucket == log.bucket
    assert back.metadata == {"soil": "gravel"}
    assert np.array_equal(back.fill_volume, log.fill_volume) and back.measured_load is None
    state = back.contact_state()
    assert np.allclose(soil_forces(preset("gravel"), state, back.bucket).tangential, log.tangential)


def test_refuses_to_overwrite(tmp_path, log):
    log.save(tmp_path / "c.csv")
    with pytest.raises(FileExistsError):
        log.save(tmp_path / "c.csv")
    log.save(tmp_path / "c.csv", overwrite=True)


def _write(tmp_path, text, sidecar=True):
    target = tmp_path / "bad.csv"
    target.write_text(text)
    if sidecar:
        meta = {"format": "wheelloader.cyclelog", "version": 1, "pile": Pile.trapezoid().to_dict(), "bucket": {},
                "metadata": {}}
        target.with_suffix(".json").write_text(json.dumps(meta))
    return target


GOOD_HEADER = "t,x,z,blade_angle,F_T,F_N\n"


@pytest.mark.parametrize("body,match", [
    ("t,x,z,F_T,F_N\n0,0,0,0,0\n1,0,0,0,0\n", "missing column"),
    (GOOD_HEADER + "0,0,0,0,1,1\n0.1,0,0,0,nan,1\n", "NaN"),
    (GOOD_HEADER + "0,0,0,0,1,1\n0,0,0,0,1,1\n", "not strictly increasing"),
    (GOOD_HEADER + "0,0,0,-5,1,1\n0.1,0,0,40,1,1\n", "radians"),
    (GOOD_HEADER + "0,0,0,0,1,1\n", "at least 2 data rows"),
    (GOOD_HEADER + "0,0,0,0,1,1\n0.1,0,0,0,abc,1\n", "not a number"),
    (GOOD_HEADER + "0,0,0,0,1,-1\n0.1,0,0,0,1,-2\n", "sign convention"),
    ("", "empty file"),
])
def test_bad_files_get_clear_errors(tmp_path, body, match):
    with pytest.raises(CycleLogError, match=match):
        CycleLog.load(_write(tmp_path, body))


def test_binary_file_directory_and_byte_order_mark(tmp_path):
    target = tmp_path / "bin.csv"
    target.write_bytes(bytes(range(128, 256)) * 8)
    with pytest.raises(CycleLogError, match="not a UTF-8 text CSV"):
        CycleLog.load(target)
    with pytest.raises(CycleLogError, match="is a directory"):
        load_path_csv(tmp_path)
    # a spreadsheet export starts with a byte-order mark: the first column is still 't'
    bom = tmp_path / "bom.csv"
    bom.write_text("\ufeff" + GOOD_HEADER + "0,0,0,0,1,1\n0.1,0.1,0,0,1,1\n", encoding="utf-8")
    assert len(load_path_csv(bom)) == 2


def test_repeated_time_message_is_plain(tmp_path):
    with pytest.raises(CycleLogError, match=r"\(t=0\.5 after 0\.5\)"):
        CycleLog.load(_write(tmp_path, GOOD_HEADER + "0.5,0,0,0,1,1\n0.5,0,0,0,1,1\n"))


def test_missing_sidecar_and_comments(tmp_path):
    target = _write(tmp_path, "# a comment\n" + GOOD_HEADER + "0,0,0,0,1,1\n0.1,0.1,0,0,1,1\n", sidecar=False)
    with pytest.raises(CycleLogError, match="sidecar"):
        CycleLog.load(target)
    assert len(load_path_csv(target)) == 2
    with pytest.raises(FileNotFoundError):
        CycleLog.load(tmp_path / "nope.csv")


def test_path_csv_round_trip(tmp_path):
    path = default_path()
    save_path_csv(path, tmp_path / "p.csv")
    assert np.array_equal(load_path_csv(tmp_path / "p.csv").blade_angle, path.blade_angle)
    with pytest.raises(FileExistsError):
        save_path_csv(path, tmp_path / "p.csv")


def test_constructor_validation(log):
    with pytest.raises(CycleLogError, match="one value per sample"):
        CycleLog(log.path, log.tangential[:-1], log.normal, log.pile)
    with pytest.raises(CycleLogError, match="NaN"):
        CycleLog(log.path, np.full(len(log.path), np.nan), log.normal, log.pile)


# ----------------------------------------------------------------- compressed logs (.csv.xz + .json.xz)
def test_compressed_round_trip_holds_the_same_bytes(tmp_path, log):
    """A ``.csv.xz`` log is the plain log's two files compressed: same bytes inside, same log read back."""
    import lzma

    from wheelloader.estimator.cyclelog import find_cycle_log, log_stem, sidecar_path

    log.save(tmp_path / "plain.csv")
    packed = log.save(tmp_path / "packed.csv.xz")
    assert sidecar_path(packed) == tmp_path / "packed.json.xz" and log_stem(packed) == "packed"
    assert lzma.decompress(packed.read_bytes()) == (tmp_path / "plain.csv").read_bytes()
    assert lzma.decompress((tmp_path / "packed.json.xz").read_bytes()) == (tmp_path / "plain.json").read_bytes()
    a, b = CycleLog.load(tmp_path / "plain.csv"), CycleLog.load(packed)
    assert b.path.name == "packed" and a.path.name == "plain"
    for name in ("tangential", "normal", "fill_volume"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert a.pile == b.pile and a.pile_after == b.pile_after and a.metadata == b.metadata
    # the plain name reads the compressed log when only that one is there; find_cycle_log prefers it
    assert np.array_equal(CycleLog.load(tmp_path / "packed.csv").normal, log.normal)
    assert find_cycle_log(tmp_path, "packed") == packed and find_cycle_log(tmp_path, "plain") == tmp_path / "plain.csv"
    assert find_cycle_log(tmp_path, "absent") is None
    with pytest.raises(FileExistsError):
        log.save(packed)


def test_cycle_log_files_lists_each_log_once(tmp_path, log):
    from wheelloader.estimator.cyclelog import cycle_log_files

    (tmp_path / "a" / "b").mkdir(parents=True)
    log.save(tmp_path / "a" / "b" / "cycle1.csv.xz")
    log.save(tmp_path / "a" / "b" / "cycle2.csv")
    log.save(tmp_path / "a" / "b" / "cycle2.csv.xz")  # both forms: the compressed one is listed
    assert cycle_log_files(tmp_path, "*/*/cycle*") == [tmp_path / "a" / "b" / "cycle1.csv.xz",
                                                       tmp_path / "a" / "b" / "cycle2.csv.xz"]


def test_a_damaged_compressed_log_is_a_clear_error(tmp_path, log):
    packed = log.save(tmp_path / "c.csv.xz")
    packed.write_bytes(b"not xz at all")
    with pytest.raises(CycleLogError, match="not an xz file"):
        CycleLog.load(packed)


def test_committed_saved_cycles_read_back_byte_for_byte(tmp_path):
    """A sample of the committed saved loop cycles (data/results/*/cycles, xz): read, written again plain, the
    files are the compressed ones' contents byte for byte, and written compressed, the very same xz bytes."""
    import lzma
    from pathlib import Path

    from wheelloader.estimator.cyclelog import cycle_log_files, sidecar_path

    root = Path(__file__).resolve().parents[1] / "data" / "results"
    runs = sorted(root.glob("*/cycles"))
    assert runs, "no saved cycles under data/results"
    for run in runs:
        saved = cycle_log_files(run, "**/*")
        assert saved and all(p.name.endswith(".csv.xz") for p in saved), run
        for packed in saved[:: max(1, len(saved) // 2)][:2]:  # the first and the middle one of each run
            back = CycleLog.load(packed)
            back.save(tmp_path / "c.csv", overwrite=True)
            back.save(tmp_path / "c.csv.xz", overwrite=True)
            assert (tmp_path / "c.csv").read_bytes() == lzma.decompress(packed.read_bytes()), packed
            assert (tmp_path / "c.json").read_bytes() == lzma.decompress(sidecar_path(packed).read_bytes()), packed
            assert (tmp_path / "c.csv.xz").read_bytes() == packed.read_bytes(), packed
