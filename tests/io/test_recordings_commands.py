"""convert and reconstruct on ROS bags and HDF5 files: the same output as from the ECD folder, a window at a time."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("h5py")

from evio_lib.cli import main  # noqa: E402
from evio_lib.events.reconstruction.command import main_reconstruct  # noqa: E402
from evio_lib.io import event_source, hdf5, rosbag  # noqa: E402
from evio_lib.io.convert import write_ecd_streamed  # noqa: E402
from evio_lib.io.ecd import read_ecd, write_ecd  # noqa: E402


def _load_helpers():
    """The recording helpers of test_recordings.py (the tests folder is no package)."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("_recordings_helpers", Path(__file__).with_name("test_recordings.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module._same, module._sequence


_same, _sequence = _load_helpers()


@pytest.fixture(autouse=True)
def _small_blocks(tmp_path, monkeypatch):
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(event_source.EventSource, "chunk_events", 999)  # many blocks on a small recording
    monkeypatch.setattr(event_source, "INDEX_STRIDE", 128)


def test_convert_bag_to_ecd_and_cache(tmp_path, capsys):
    seq = _sequence("ns")
    bag = rosbag.write_rosbag(seq, tmp_path / "rec.bag")
    assert main(["convert", str(bag), "--out", str(tmp_path / "ecd"), "--quiet"]) == 0
    back = read_ecd(tmp_path / "ecd")
    _same(seq, back)
    assert back.metadata["topics"]["events"] == "/dvs/events"
    # events.txt written a block at a time is the file write_ecd writes
    write_ecd(seq, tmp_path / "whole")
    assert (tmp_path / "ecd" / "events.txt").read_bytes() == (tmp_path / "whole" / "events.txt").read_bytes()
    assert main(["convert", str(bag), "--out", str(tmp_path / "ecd"), "--quiet"]) == 2
    assert "already exists and is not empty; use --force" in capsys.readouterr().err
    assert main(["convert", str(bag), "--out", str(tmp_path / "cache_out"), "--format", "cache", "--quiet"]) == 0
    from evio_lib.pipeline.dataset import load_dataset

    data = load_dataset(tmp_path / "cache_out", need_events=True)
    assert data.kind == "cache"
    _same(seq, data.sequence)


def test_convert_h5_without_imu_and_refusals(tmp_path, capsys):
    seq = _sequence("us", start_us=1_600_000_000_000_000)
    path = hdf5.write_dsec_h5(seq.events, tmp_path / "events.h5", sensor_size=(240, 180))
    calib = tmp_path / "calib.txt"
    calib.write_text("200 200 120 90 0 0 0 0\n")
    assert main(["convert", str(path), "--out", str(tmp_path / "o"), "--calib", str(calib), "--quiet"]) == 0
    back = read_ecd(tmp_path / "o")
    _same(seq, back, ("events",))
    assert back.camera.fx == 200.0 and back.imu is None
    assert main(["convert", str(path), "--out", str(tmp_path / "p"), "--topics", "ecd"]) == 2
    assert "events.h5: the dsec layout holds one camera; --topics applies to MVSEC files" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()
    assert main(["run", str(path), "--calib", str(calib), "--frames", "mc-events"]) == 2
    err = capsys.readouterr().err
    assert "events.h5: the HDF5 (dsec) layout holds no IMU" in err and err.count("\n") == 1


@pytest.mark.parametrize("window", [[], ["--window-time", "0.05"], ["--adaptive"]], ids=["fraction", "time", "adaptive"])
def test_reconstruct_from_a_bag_equals_the_ecd_folder(tmp_path, window):
    seq = _sequence("ns", n=30000, region=(60, 40))  # dense enough for adaptive windows
    bag = rosbag.write_rosbag(seq, tmp_path / "rec.bag", events_per_message=4000)
    ecd = write_ecd(seq, tmp_path / "ecd")
    outs = []
    for source in (ecd, bag):
        out = tmp_path / f"out_{source.name}"
        fraction = [] if window else ["--window-fraction", "0.05"]
        assert main_reconstruct([str(source), "--out", str(out), "--method", "direct", "--quiet", *fraction,
                                 *window]) == 0
        outs.append(out)
    a, b = outs
    assert (a / "images.txt").read_text() == (b / "images.txt").read_text()
    names = sorted(p.name for p in (a / "images").iterdir())
    assert len(names) > 3
    assert all((a / "images" / n).read_bytes() == (b / "images" / n).read_bytes() for n in names)


def test_streamed_ecd_writer_matches_write_ecd_off_the_ns_grid(tmp_path):
    seq = _sequence("ns", n=2000)
    events = seq.events.copy()
    events["t"] = events["t"] - 1.6e9 + 1e-10 * np.arange(events.size) / 3  # off the nanosecond grid: "%r"
    events.sort(order="t", kind="stable")
    path = tmp_path / "e.npy"
    event_source.write_events_npy(path, [events])
    write_ecd_streamed(seq.__class__("x", events=event_source.open_events_npy(path), frames=np.zeros((0, 180, 240),
                                                                                                    np.uint8)),
                       tmp_path / "a")
    write_ecd(seq.__class__("x", events=events, frames=np.zeros((0, 180, 240), np.uint8)), tmp_path / "b")
    assert (tmp_path / "a" / "events.txt").read_bytes() == (tmp_path / "b" / "events.txt").read_bytes()
