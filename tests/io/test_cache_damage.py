"""Damaged caches: an empty or truncated cached .npz is a clear CacheError for its loader, and every cache user deletes
it, says so in one note on stderr and makes it again (the result equals a fresh one).

Caches tried: the simulated recordings of pipeline.dataset.simulate_preset (empty, truncated, half-written zip
member), the homographic-adaptation labels of features.training.datasets, the reconstruction training samples.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from evio_lib.io.cache import CacheError, load_npz_arrays, load_sequence_npz
from evio_lib.sequence import Sequence


@pytest.fixture()
def private_cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("EVIO_CACHE_DIR", str(folder))
    return folder


def _damage(path, how: str) -> None:
    data = path.read_bytes()
    if how == "empty":
        path.write_bytes(b"")
    elif how == "truncated":  # e.g. a copy cut short, a full disk before the atomic write existed
        path.write_bytes(data[: len(data) // 2])
    elif how == "end_cut":  # only the zip's central directory missing
        path.write_bytes(data[:-40])
    elif how == "zeroed":  # a whole zip whose member holds zeros: numpy reads a wrong header or CRC
        middle = len(data) // 3
        path.write_bytes(data[:middle] + bytes(200) + data[middle + 200:])
    else:
        raise AssertionError(how)


def _assert_same(a: Sequence, b: Sequence) -> None:
    for name in ("events", "frame_times", "frames"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for name in ("t", "gyro", "accel"):
        np.testing.assert_array_equal(getattr(a.imu, name), getattr(b.imu, name), err_msg=name)
    np.testing.assert_array_equal(a.groundtruth.p_BinG, b.groundtruth.p_BinG)
    assert a.name == b.name and a.camera == b.camera


@pytest.mark.parametrize("how", ["empty", "truncated", "end_cut", "zeroed"])
def test_a_damaged_recording_cache_is_simulated_again_with_a_note(private_cache, capsys, how):
    from evio_lib.pipeline.dataset import sequence_cache_dir, simulate_preset

    fresh = simulate_preset("boxes_like", 0.2, seed=0)
    (path,) = sequence_cache_dir().glob("boxes_like_d0.2_seed0_m*_frames.npz")
    _damage(path, how)
    if how in ("empty", "truncated", "end_cut"):
        with pytest.raises(CacheError, match=r"boxes_like_d0.2_seed0_m[0-9a-f]{8}_frames.npz: (the file is empty|not a "
                                             r"readable "
                                             r"npz file .*truncated or damaged)"):
            load_sequence_npz(path)
    capsys.readouterr()
    again = simulate_preset("boxes_like", 0.2, seed=0)
    err = capsys.readouterr().err
    if how != "zeroed" or err:  # zeros in an uncompressed array member may leave a valid-looking file: then no note
        assert err.startswith(f"note: cache {path} was damaged (") and err.rstrip().endswith("; re-simulating"), err
        assert err.count("\n") == 1
        _assert_same(again, fresh)
    _assert_same(load_sequence_npz(path), fresh)  # re-made whole
    assert not list(path.parent.glob("*.tmp*")) and not list(path.parent.glob("tmp*"))


def test_load_npz_arrays_errors(tmp_path):
    np.savez(tmp_path / "ok.npz", a=np.arange(3))
    assert load_npz_arrays(tmp_path / "ok.npz")["a"].tolist() == [0, 1, 2]
    with pytest.raises(CacheError, match=r"ok.npz: missing entries \['b'\]; it has \['a'\]"):
        load_npz_arrays(tmp_path / "ok.npz", ("a", "b"))
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(CacheError, match="empty.npz: the file is empty") as info:
        load_npz_arrays(tmp_path / "empty.npz")
    assert isinstance(info.value, ValueError) and info.value.path == tmp_path / "empty.npz"
    with pytest.raises(ValueError, match="none.npz: file not found") as info:
        load_npz_arrays(tmp_path / "none.npz")
    assert not isinstance(info.value, CacheError)  # missing is not damaged


@pytest.mark.parametrize("how", ["empty", "truncated"])
def test_damaged_label_cache_is_relabelled_with_a_note(tmp_path, capsys, how):
    from evio_lib.features.training.datasets import load_labels, save_labels

    labels = [np.array([[1.0, 2.0], [3.0, 4.0]], np.float32), np.zeros((0, 2), np.float32)]
    path = save_labels(tmp_path / "labels_x.npz", labels, "fp")
    assert [k.tolist() for k in load_labels(path, "fp")] == [k.tolist() for k in labels]
    _damage(path, how)
    assert load_labels(path, "fp") is None  # counts as absent: labelled again
    err = capsys.readouterr().err
    assert err.startswith(f"note: cache {path} was damaged (") and "labelling the images again" in err
    assert not path.exists()


@pytest.mark.parametrize("how", ["empty", "truncated"])
def test_damaged_training_sample_cache_is_made_again(private_cache, capsys, how):
    from evio_lib.events.reconstruction.data import ReconstructionDataConfig, reconstruction_dataset

    config = ReconstructionDataConfig(height=32, width=32, duration=0.3, windows=3)
    fresh = reconstruction_dataset("val", 1, seed=0, config=config, workers=1)
    (path,) = private_cache.glob("reconstruction_val_*.npz")
    _damage(path, how)
    capsys.readouterr()
    again = reconstruction_dataset("val", 1, seed=0, config=config, workers=1)
    assert "was damaged" in capsys.readouterr().err
    for key in fresh:
        np.testing.assert_array_equal(again[key], fresh[key])
    assert load_npz_arrays(path).keys() == fresh.keys()


def test_a_folder_where_the_recording_cache_goes_is_named(private_cache):
    """A folder in the cache's place (made by hand or by another tool) is named, never a temporary file's error."""
    from evio_lib.pipeline.dataset import sequence_cache_dir, simulate_preset

    from evio_lib.sim.presets import SimulationConfig, recording_settings_digest

    digest = recording_settings_digest(SimulationConfig(preset="boxes_like", duration=0.5, trajectory_duration=60.0))
    blocker = sequence_cache_dir() / f"boxes_like_d0.5_seed0_m{digest}_frames.npz"
    blocker.mkdir(parents=True)
    with pytest.raises(ValueError, match=r"the recording cache .*boxes_like_d0.5_seed0_m[0-9a-f]{8}_frames.npz is a "
                                         r"folder, where "
                                         r"the simulated recording is to be stored; remove it"):
        simulate_preset("boxes_like", 0.5)
    assert blocker.is_dir() and list(blocker.parent.iterdir()) == [blocker]


def test_a_cache_folder_that_cannot_be_written_is_named_before_simulating(tmp_path, monkeypatch):
    """EVIO_CACHE_DIR naming a file: said before the simulation, naming the variable (it failed after the work,
    naming a folder the user never gave)."""
    from evio_lib.pipeline import dataset

    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("EVIO_CACHE_DIR", str(blocker))
    with pytest.raises(ValueError, match=r"cannot write the recording cache .*a_file/sequences \(EVIO_CACHE_DIR=.*"
                                         r"a_file\): Not a directory; set EVIO_CACHE_DIR to a writable folder"):
        dataset.simulate_preset("boxes_like", 0.5)
    assert blocker.read_text() == "not a folder"


def test_the_default_cache_folder_is_the_checkouts_or_the_users(monkeypatch, tmp_path):
    """$EVIO_CACHE_DIR first; from a checkout, its data/cache; an installed package, the user's cache folder."""
    from evio_lib.io import cache

    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "mine"))
    assert cache.default_cache_dir() == tmp_path / "mine"
    monkeypatch.delenv("EVIO_CACHE_DIR")
    repository = Path(cache.__file__).resolve().parents[2]
    assert cache.default_cache_dir() == repository / "data" / "cache"
    installed = tmp_path / "site-packages" / "evio_lib" / "io"
    installed.mkdir(parents=True)
    monkeypatch.setattr(cache, "__file__", str(installed / "cache.py"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.default_cache_dir() == tmp_path / "xdg" / "evio"
