"""Tests of evio_lib.io.aedat4 on the real DAVIS346 sample (events, APS frames, IMU units) and on bad files."""
import numpy as np
import pytest

from evio_lib.io.aedat4 import STANDARD_GRAVITY, read_aedat4, us_to_seconds
from evio_lib.io.errors import DataFileError

SAMPLE = ("davis346_aedat4_sample", "sample.aedat4")


@pytest.fixture
def sample(real_data_dir):
    return real_data_dir.joinpath(*SAMPLE)


def test_us_to_seconds_is_correctly_rounded():
    us = np.array([1589163147368868, 1589163147538809, 7, 0], dtype=np.uint64)
    np.testing.assert_array_equal(us_to_seconds(us), [int(v) / 10**6 for v in us])


def test_real_sample_events_and_frames(sample):
    seq = read_aedat4(sample)
    seq.validate()
    assert seq.sensor_size == (346, 260) and seq.camera is None and seq.R_CtoI is None
    ev = seq.events
    assert ev.shape == (6676,)
    assert ev["t"][0] == 1589163147.368868 and ev["t"][-1] == 1589163147.538809
    assert ev["x"].max() < 346 and ev["y"].max() < 260 and set(np.unique(ev["p"])) == {-1, 1}
    np.testing.assert_array_equal(ev["x"][:2], [215, 226])
    np.testing.assert_array_equal(ev["p"][:2], [1, 1])
    assert seq.frames.shape == (4, 260, 346) and seq.frames.dtype == np.uint8 and seq.frames.std() > 1.0
    np.testing.assert_allclose(seq.frame_times - 1589163147.0, [0.365215, 0.405215, 0.445215, 0.485215], atol=1e-6)
    assert seq.metadata["n_triggers"] == 17 and seq.metadata["sensor_size"] == (346, 260)
    no_frames = read_aedat4(sample, load_frames=False)
    assert no_frames.frames.shape == (0, 260, 346) and len(no_frames.events) == 6676


def test_real_sample_imu_units(sample):
    imu = read_aedat4(sample).imu
    assert len(imu) == 160
    assert np.diff(imu.t).mean() == pytest.approx(1e-3, rel=0.01)  # about 1 kHz
    # first sample in the file: accelerometer (0.0276, -0.9951, 0.2590) g, gyroscope (0.778, -0.519, -0.015) deg/s
    np.testing.assert_allclose(imu.accel[0] / STANDARD_GRAVITY, [0.0276, -0.9951, 0.2590], atol=1e-3)
    np.testing.assert_allclose(np.rad2deg(imu.gyro[0]), [0.778, -0.519, -0.015], atol=1e-3)
    # the camera lies still: |a| close to 9.81 m/s^2 (this sensor reads about 1.03 g) and almost no rotation
    norm = np.linalg.norm(imu.accel, axis=1)
    assert norm.mean() == pytest.approx(9.81, abs=0.4) and norm.std() < 0.1
    assert np.abs(imu.gyro).max() < 0.05  # rad/s; in deg/s the raw values reach ~1


def test_missing_and_invalid_files(tmp_path):
    with pytest.raises(DataFileError, match=r"rec.aedat4: file not found at .*rec.aedat4 \(expected an AEDAT4 recording\)"):
        read_aedat4(tmp_path / "rec.aedat4")
    bad = tmp_path / "bad.aedat4"
    bad.write_bytes(b"#!AER-DAT2.0\r\n" + bytes(100))
    with pytest.raises(DataFileError, match=r"bad.aedat4: not a readable AEDAT4 file"):
        read_aedat4(bad)


class _FakeDecoder:
    """Stands in for aedat.Decoder: one event stream (8 x 6 sensor) and the packets given to the test."""

    packets: list = []

    def __init__(self, path):
        self.path = path

    def id_to_stream(self):
        return {0: {"type": "events", "width": 8, "height": 6}, 1: {"type": "imus"}}

    def __iter__(self):
        return iter(self.packets)


def _imu_packet(t_us):
    fields = ["t"] + [f"{s}_{a}" for s in ("accelerometer", "gyroscope") for a in "xyz"] + ["temperature"]
    imus = np.zeros(len(t_us), dtype=[(f, "<u8" if f == "t" else "<f4") for f in fields])
    imus["t"], imus["accelerometer_z"] = t_us, 1.0
    return {"stream_id": 1, "imus": imus}


def _event_packet(t_us):
    events = np.zeros(len(t_us), dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")])
    events["t"], events["on"] = t_us, True
    return {"stream_id": 0, "events": events}


def test_decoded_recording_that_is_no_valid_sequence_names_the_file(tmp_path, monkeypatch):
    aedat = pytest.importorskip("aedat")
    monkeypatch.setattr(aedat, "Decoder", _FakeDecoder)
    path = tmp_path / "dup.aedat4"
    path.write_bytes(b"not read by the fake decoder")
    monkeypatch.setattr(_FakeDecoder, "packets", [_event_packet([30, 10, 20]), _imu_packet([1000, 2000, 2000])])
    with pytest.raises(DataFileError, match=r"dup.aedat4: the recording is not a valid sequence \(imu.t must be strictly "
                                            r"increasing; got imu.t\[2\] = 0.002 after imu.t\[1\] = 0.002\)"):
        read_aedat4(path)
    monkeypatch.setattr(_FakeDecoder, "packets", [_event_packet([30, 10, 20]), _imu_packet([1000, 2000, 3000])])
    seq = read_aedat4(path)  # out-of-order events are sorted (and said so), the rest is valid
    assert seq.events["t"].tolist() == [1e-5, 2e-5, 3e-5] and seq.metadata["events_resorted"] is True
    seq.validate()
