"""AEDAT4 recordings through the pipeline: units converted and checked, damaged files, the calibration that the file
lacks (--calib), and ``run FILE.aedat4 --calib FILE`` end to end on the real DAVIS346 sample."""
import json
from pathlib import Path

import numpy as np
import pytest

from evio_lib import cli
from evio_lib.io.aedat4 import read_aedat4
from evio_lib.io.errors import DataFileError
from evio_lib.io.imu_checks import ImuUnitsError
from evio_lib.pipeline.dataset import load_dataset

SAMPLE = ("davis346_aedat4_sample", "sample.aedat4")
CALIB = "250.0 250.0 172.5 129.5 0.0 0.0 0.0 0.0\n"  # an assumed DAVIS346 lens (the file holds no calibration)


@pytest.fixture
def sample(real_data_dir):
    return real_data_dir.joinpath(*SAMPLE)


@pytest.fixture
def calib(tmp_path):
    path = tmp_path / "inputs" / "davis346_calib.txt"
    path.parent.mkdir()
    path.write_text(CALIB)
    return path


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _one_error_line(capsys, code: int) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("error: "), captured.err
    return lines[0]


def test_units_are_converted_and_checked(sample, calib):
    seq = read_aedat4(sample)
    # file: accelerometer (0.0276, -0.9951, 0.2590) g, gyroscope (0.778, -0.519, -0.015) deg/s in the first sample
    np.testing.assert_allclose(seq.imu.accel[0], np.array([0.0276, -0.9951, 0.2590]) * 9.80665, atol=1e-2)
    np.testing.assert_allclose(seq.imu.gyro[0], np.radians([0.778, -0.519, -0.015]), atol=1e-4)
    assert "accel * 9.80665 -> m/s^2, gyro * pi/180 -> rad/s" in seq.metadata["imu_units"]
    data = load_dataset(sample, calib=calib)
    assert data.kind == "aedat4" and data.sequence.camera.width == 346 and data.sequence.groundtruth is None
    assert any("accelerometer in g, gyroscope in deg/s" in n for n in data.notes)
    assert any("static initialisation" in n and "no error metrics" in n for n in data.notes)
    assert any("camera = IMU frame" in n for n in data.notes)
    assert any("ImuNoiseParams defaults" in n for n in data.notes)
    np.testing.assert_array_equal(data.R_CtoI, np.eye(3))


class _FakeDecoder:
    """Stands in for aedat.Decoder: one event stream (8 x 6) and an IMU whose values the test sets."""

    packets: list = []

    def __init__(self, path):
        self.path = path

    def id_to_stream(self):
        return {0: {"type": "events", "width": 8, "height": 6}, 1: {"type": "imus"}}

    def __iter__(self):
        return iter(self.packets)


def _imu_packet(accel, gyro, n=300):
    fields = ["t"] + [f"{s}_{a}" for s in ("accelerometer", "gyroscope") for a in "xyz"] + ["temperature"]
    imus = np.zeros(n, dtype=[(f, "<u8" if f == "t" else "<f4") for f in fields])
    imus["t"] = 1000 + 1000 * np.arange(n)  # 1 kHz
    for i, a in enumerate("xyz"):
        imus[f"accelerometer_{a}"], imus[f"gyroscope_{a}"] = accel[i], gyro[i]
    return {"stream_id": 1, "imus": imus}


@pytest.mark.parametrize("accel, gyro, message", [
    # a file written in m/s^2 (not g): 9.81 g after the conversion
    ((0.0, 0.0, 9.81), (0.5, -0.3, 0.1), r"median \|a\| = 96.2 is no specific force in m/s\^2"),
    # a gyro stored in hundredths of deg/s: a still sensor reads 57 'deg/s'
    ((0.0, -1.0, 0.0), (50.0, -30.0, 10.0), r"the gyro looks like it is in deg/s: where the accelerometer is still"),
    # an accelerometer in milli-g: 1000 'g'
    ((0.0, -1000.0, 0.0), (0.5, -0.3, 0.1), r"median \|a\| = 9807 is no specific force"),
])
def test_file_whose_imu_is_not_in_g_and_deg_per_s_is_refused(tmp_path, monkeypatch, accel, gyro, message):
    aedat = pytest.importorskip("aedat")
    monkeypatch.setattr(aedat, "Decoder", _FakeDecoder)
    events = np.zeros(3, dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")])
    events["t"] = [1000, 2000, 3000]
    monkeypatch.setattr(_FakeDecoder, "packets", [{"stream_id": 0, "events": events}, _imu_packet(accel, gyro)])
    path = tmp_path / "rec.aedat4"
    path.write_bytes(b"not read by the fake decoder")
    with pytest.raises(ImuUnitsError, match=r"rec.aedat4 IMU \(converted from g and deg/s\): .*" + message):
        read_aedat4(path)


@pytest.mark.parametrize("damage", ["truncated", "header offset", "header length", "packet"])
def test_damaged_file_is_one_error_naming_it(sample, tmp_path, capfd, damage):
    data = bytearray(sample.read_bytes())
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "header offset":  # the Rust decoder panics (pyo3 PanicException, a BaseException)
        data[18:22] = b"\xff\xff\xff\xff"
    elif damage == "header length":
        data[14:18] = b"\x00\x00\x00\x00"
    else:  # garbage inside an LZ4-compressed packet
        data[100_000:100_064] = b"\xff" * 64
    path = tmp_path / "damaged.aedat4"
    path.write_bytes(bytes(data))
    with pytest.raises(DataFileError, match=r"^damaged.aedat4: not a readable AEDAT4 file, damaged or truncated\? "):
        read_aedat4(path)
    assert "panicked" not in capfd.readouterr().err  # the decoder's panic message does not reach the terminal


def test_damaged_file_on_the_command_line(sample, tmp_path, capsys, calib):
    data = bytearray(sample.read_bytes())
    data[18:22] = b"\xff\xff\xff\xff"
    path = calib.parent / "damaged.aedat4"
    path.write_bytes(bytes(data))
    before = _tree(calib.parent)
    line = _one_error_line(capsys, cli.main(["run", str(path), "--calib", str(calib), "--quiet"]))
    assert line.startswith("error: damaged.aedat4: not a readable AEDAT4 file, damaged or truncated? (PanicException")
    assert _tree(calib.parent) == before


def test_missing_or_bad_calibration_is_refused(sample, tmp_path, capsys, calib):
    line = _one_error_line(capsys, cli.main(["run", str(sample), "--quiet"]))
    assert line == (f"error: {sample}: an AEDAT4 recording holds no camera calibration; give one with --calib FILE "
                    f"(one line fx fy cx cy k1 k2 p1 p2 [k3] in pixels, the ECD calib.txt format, e.g. from a Kalibr "
                    f"or OpenCV calibration of this camera)")
    bad = calib.parent / "bad_calib.txt"
    bad.write_text("250 250 400 129.5 0 0 0 0\n")  # cx beyond the 346 px width: another camera's calibration
    before = _tree(calib.parent)
    line = _one_error_line(capsys, cli.main(["run", str(sample), "--calib", str(bad), "--quiet"]))
    assert "bad_calib.txt (fx fy cx cy k1 k2 p1 p2 [k3]): principal point (cx, cy) = (400, 129.5) lies outside the " \
           "346 x 260 image" in line
    line = _one_error_line(capsys, cli.main(["run", str(sample), "--calib", str(calib.parent / "none.txt"),
                                             "--quiet"]))
    assert "none.txt: file not found" in line
    line = _one_error_line(capsys, cli.main(["run", "boxes_like", "--calib", str(calib), "--quiet"]))
    assert line == "error: --calib applies to recordings; the preset boxes_like knows its camera"
    assert _tree(calib.parent) == before


def test_run_end_to_end_with_calib(sample, tmp_path, capsys, calib):
    """0.17 s of a still DAVIS346: static initialisation over the first 0.1 s, then a trajectory without metrics."""
    out = tmp_path / "run"
    code = cli.main(["run", str(sample), "--calib", str(calib), "--quiet", "--no-figures", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "loaded sample (aedat4)" in captured.out and "initialisation: static" in captured.out
    rows = [line for line in (out / "trajectory.txt").read_text().splitlines() if not line.startswith("#")]
    assert len(rows) >= 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["dataset"]["kind"] == "aedat4" and metrics["metrics"]["init"] == "static"
    assert not any(key.startswith(("ate", "rmse", "drift")) for key in metrics["metrics"])  # no ground truth
    position = np.array([float(v) for v in rows[-1].split()[1:4]])
    assert np.linalg.norm(position) < 0.05  # the camera lies still: it stays where it started


def test_too_few_events_for_one_window_is_said(sample, capsys, calib):
    """The 0.16 s sample holds about 6 300 events after the first, fewer than one window of 0.5 H W = 44 980: the
    message gives the count, the window and the n that would fit (it said 'no events or frames there')."""
    line = _one_error_line(capsys, cli.main(["run", str(sample), "--calib", str(calib), "--frames", "events",
                                             "--quiet"]))
    assert "events in [" in line and "are fewer than one window of N_e = n H W = 44,980 events" in line
    assert "(window_fraction (--window-fraction) n = 0.5, 346 x 260 px); use n <= 0.0" in line
