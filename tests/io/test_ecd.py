"""Tests of evio_lib.io.ecd: the ECD text layout (read, write, exact round trip, errors with file and line)."""
import json
import os
import re

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.events.array import make_events
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import rot_to_quat
from evio_lib.io import ecd
from evio_lib.io.ecd import read_ecd, read_ecd_events, write_ecd
from evio_lib.io.errors import DataFileError
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence


def _simulated_sequence(rng: np.random.Generator, ns_grid: bool) -> Sequence:
    """A sequence with every part filled, like the simulator produces."""
    width, height = 40, 30
    cam = PinholeRadtan(fx=50.5, fy=51.25, cx=19.5, cy=14.5, width=width, height=height, k1=-0.3, k2=0.1, p1=1e-4, p2=-2e-4, k3=0.01)
    n = 5000
    t = np.sort(rng.uniform(0.0, 1.0, n))
    t = np.round(t, 9) if ns_grid else t
    t[10] = t[11]  # events may share a timestamp
    events = make_events(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice([-1, 1], n))
    frame_times = np.arange(5) * 0.2 + (0.0 if ns_grid else 1e-12 * np.pi)
    frames = rng.integers(0, 256, (5, height, width), dtype=np.uint8)
    t_imu = np.arange(200) * 0.005 + (0.0 if ns_grid else 1e-13)
    # the IMU truth is still in a random attitude R_ItoG, and the accelerometer reads gravity in it plus noise (the
    # reader checks the IMU against its truth); poses and velocities' digits still go through the files
    R_ItoG = Rotation.random(random_state=np.random.RandomState(2)).as_matrix()
    accel = rng.normal(size=(200, 3)) * 0.5 + R_ItoG.T @ [0.0, 0.0, 9.81]
    imu = ImuSamples(t_imu, rng.normal(size=(200, 3)) * 1e-2, accel)
    t_gt = np.arange(50) * 0.02 + (0.0 if ns_grid else 1 / 3)
    q_cam = rot_to_quat(Rotation.random(50, random_state=np.random.RandomState(1)).as_matrix())
    q_imu = rot_to_quat(np.repeat(R_ItoG.T[None], 50, axis=0))  # JPL q_GtoI: C(q) = R_GtoI
    gt_cam = GroundTruth(t_gt, rng.normal(size=(50, 3)), q_cam, body="camera")
    gt_imu = GroundTruth(t_gt, rng.normal(size=(50, 3)), q_imu, body="imu", v_BinG=rng.normal(size=(50, 3)) * 1e-3,
                         bias_gyro=rng.normal(size=(50, 3)) * 1e-3, bias_accel=rng.normal(size=(50, 3)) * 1e-2)
    metadata = {
        "imu_noise": {"gyroscope_noise_density": 1.6968e-4, "accelerometer_noise_density": 2.0e-3},
        "gravity_G": np.array([0.0, 0.0, -9.81]),
        "contrast_threshold": (0.2, 0.2),
        "simulator": "evio.sim",
        "seed": 42,
    }
    return Sequence("sim_rig", camera=cam, events=events, frame_times=frame_times, frames=frames, imu=imu,
                    groundtruth=gt_cam, groundtruth_imu=gt_imu,
                    R_CtoI=Rotation.from_euler("xyz", [0.1, -0.2, 1.5]).as_matrix(), p_CinI=np.array([0.01, -0.02, 0.003]),
                    metadata=metadata)


def _assert_same_groundtruth(a: GroundTruth, b: GroundTruth) -> None:
    assert a.body == b.body
    for name in ("t", "p_BinG", "q_GtoB", "v_BinG", "bias_gyro", "bias_accel"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize("ns_grid", [True, False])
def test_write_read_round_trip_is_exact(tmp_path, rng, ns_grid):
    seq = _simulated_sequence(rng, ns_grid)
    folder = write_ecd(seq, tmp_path / "seq")
    for name in ("events.txt", "imu.txt", "images.txt", "groundtruth.txt", "calib.txt", "groundtruth_imu.txt", "evio_sim.json"):
        assert (folder / name).is_file(), name
    back = read_ecd(folder)
    back.validate()
    np.testing.assert_array_equal(back.events, seq.events)
    np.testing.assert_array_equal(back.frames, seq.frames)
    np.testing.assert_array_equal(back.frame_times, seq.frame_times)
    np.testing.assert_array_equal(back.imu.t, seq.imu.t)
    np.testing.assert_array_equal(back.imu.gyro, seq.imu.gyro)
    np.testing.assert_array_equal(back.imu.accel, seq.imu.accel)
    _assert_same_groundtruth(back.groundtruth, seq.groundtruth)
    _assert_same_groundtruth(back.groundtruth_imu, seq.groundtruth_imu)
    np.testing.assert_array_equal(back.R_CtoI, seq.R_CtoI)
    np.testing.assert_array_equal(back.p_CinI, seq.p_CinI)
    assert back.camera == seq.camera and back.name == "sim_rig"
    assert back.metadata.keys() == seq.metadata.keys()
    np.testing.assert_array_equal(back.metadata["gravity_G"], seq.metadata["gravity_G"])
    assert back.metadata["contrast_threshold"] == (0.2, 0.2) and back.metadata["imu_noise"] == seq.metadata["imu_noise"]
    first_event = (folder / "events.txt").read_text().splitlines()[0].split()
    assert first_event[3] in ("0", "1")  # ECD polarity 0/1 on disk
    if ns_grid:
        assert len(first_event[0].split(".")[1]) == 9  # ECD style 9 decimals


def test_round_trip_minimal_sequence_keeps_unknown_size(tmp_path):
    seq = Sequence("bare", events=make_events([0.1, 0.1, 0.3], [500, 2, 3], [7, 900, 9], [1, -1, 1]))
    back = read_ecd(write_ecd(seq, tmp_path / "bare"))
    np.testing.assert_array_equal(back.events, seq.events)
    assert back.frames.shape == (0, 0, 0) and back.sensor_size is None
    assert back.imu is None and back.groundtruth is None and back.groundtruth_imu is None and back.camera is None
    assert back.R_CtoI is None and back.metadata == {}


def test_write_removes_stale_layout_files(tmp_path, rng):
    write_ecd(_simulated_sequence(rng, True), tmp_path / "f")
    small = Sequence("small", events=make_events([0.0], [1], [1], [1]), frames=np.zeros((0, 30, 40), np.uint8))
    back = read_ecd(write_ecd(small, tmp_path / "f"))
    assert back.imu is None and back.groundtruth is None and back.frames.shape == (0, 30, 40) and len(back.events) == 1
    assert not list((tmp_path / "f" / "images").glob("frame_*.png"))


def test_write_rejects_invalid_sequence(tmp_path):
    seq = Sequence("bad", events=make_events([0.0], [300], [1], [1]), camera=PinholeRadtan.davis240c())
    with pytest.raises(ValueError, match=r"events: event x out of range \[0, 240\)"):
        write_ecd(seq, tmp_path / "bad")
    with pytest.raises(ValueError, match="sequence must be a Sequence; got dict"):
        write_ecd({}, tmp_path / "bad")
    assert not (tmp_path / "bad").exists()  # checked before anything is written


def test_read_hand_written_folder(tmp_path):
    """Files written by hand in the documented ECD layout: checks the meaning of every column."""
    f = tmp_path / "hand"
    (f / "images").mkdir(parents=True)
    (f / "events.txt").write_text("0.100000000 3 4 1\n0.100000000 5 6 0\n0.250000000 239 179 1\n")
    (f / "imu.txt").write_text("0.0 0.1 0.2 9.8 0.01 0.02 0.03\n0.005 0.1 0.2 9.8 0.01 0.02 0.03\n")
    yaw90 = Rotation.from_euler("z", 90, degrees=True)  # camera orientation in the world, R_CtoG
    qx, qy, qz, qw = yaw90.as_quat().tolist()
    (f / "groundtruth.txt").write_text(f"0.5 1.0 2.0 3.0 {qx!r} {qy!r} {qz!r} {qw!r}\n")
    (f / "calib.txt").write_text("199.092366542 198.82882047 132.192071378 110.712660011 -0.368436311798 0.150947243557 "
                                 "-0.000296130534385 -0.000759431726241 0.0\n")
    image = (np.arange(180 * 240) % 251).astype(np.uint8).reshape(180, 240)
    cv2.imwrite(str(f / "images" / "frame_00000000.png"), image)
    (f / "images.txt").write_text("0.2 images/frame_00000000.png\n")
    seq = read_ecd(f)
    seq.validate()
    assert seq.camera == PinholeRadtan.davis240c()
    np.testing.assert_array_equal(seq.events["p"], [1, -1, 1])
    np.testing.assert_array_equal(seq.events["x"], [3, 5, 239])
    np.testing.assert_array_equal(seq.imu.accel[0], [0.1, 0.2, 9.8])  # ECD: accelerometer first
    np.testing.assert_array_equal(seq.imu.gyro[0], [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(seq.frames[0], image)
    np.testing.assert_array_equal(seq.frame_times, [0.2])
    np.testing.assert_allclose(seq.groundtruth.R_BtoG[0], yaw90.as_matrix(), atol=1e-12)
    np.testing.assert_array_equal(seq.groundtruth.p_BinG[0], [1.0, 2.0, 3.0])
    assert seq.metadata["sensor_size_source"] == "first frame" and seq.groundtruth.body == "camera"
    assert read_ecd(f, load_frames=False, load_events=False).frames.shape == (0, 180, 240)
    assert len(read_ecd(f, load_events=False).events) == 0


def test_real_slider_depth_slice(real_data_dir, tmp_path):
    path = real_data_dir / "ecd_slider_depth_slice" / "slider_seg.txt"
    events = read_ecd_events(path, sensor_size=(240, 180))
    assert events.shape == (50000,)
    assert events["t"][0] == 0.003811 and events["t"][-1] == 0.174156
    assert events["x"].max() == 239 and events["y"].max() == 179 and events["x"].min() == 0
    assert np.mean(events["p"] > 0) == pytest.approx(0.423, abs=0.001)
    np.testing.assert_array_equal(events["x"][:3], [96, 127, 4])
    np.testing.assert_array_equal(events["p"][:3], [-1, -1, -1])
    assert events["t"][1] == 0.003820001 and np.all(np.diff(events["t"]) >= 0)
    # the same file as events.txt of an ECD folder (a link, not a copy): DAVIS240C size assumed
    (tmp_path / "slider").mkdir()
    (tmp_path / "slider" / "events.txt").symlink_to(path)
    seq = read_ecd(tmp_path / "slider")
    assert seq.sensor_size == (240, 180) and seq.camera is None and seq.metadata["sensor_size_source"].startswith("assumed")
    np.testing.assert_array_equal(seq.events, events)


def _folder(tmp_path, **files):
    folder = tmp_path / "ecd"
    folder.mkdir(exist_ok=True)
    files.setdefault("events_txt", "0.1 1 2 1\n0.2 3 4 0\n")
    for key, text in files.items():
        (folder / key.replace("_txt", ".txt").replace("_json", ".json")).write_text(text)
    return folder


@pytest.mark.parametrize(
    "files, message",
    [
        ({"events_txt": "0.1 1 2 1\n0.2 3 4 0\n0.3 5 6\n"}, r"events.txt line 3: expected 4 columns \(t x y p\), got 3"),
        ({"events_txt": "0.1 1 2 1\n0.2 3 4 2\n"}, r"events.txt line 2: column 'p' value 2 is out of range: polarity must be 0 \(darker\) or 1"),
        ({"events_txt": "0.1 1 2 1\n0.2 3 4 -1\n"}, r"events.txt line 2: column 'p' value -1 is out of range"),
        ({"events_txt": "0.1 240 2 1\n"}, r"events.txt line 1: column 'x' value 240 is out of range: x must be an integer in \[0, 240\) for a 240 x 180 sensor"),
        ({"events_txt": "0.1 2 180 1\n"}, r"events.txt line 1: column 'y' value 180 is out of range: y must be an integer in \[0, 180\)"),
        ({"events_txt": "0.1 1.5 2 1\n"}, r"events.txt line 1: column 'x' must be an integer; got '1.5'"),
        ({"events_txt": "0.1 -3 2 1\n"}, r"events.txt line 1: column 'x' value -3 is out of range"),
        ({"events_txt": "0.1 1 2 1\n0.3 1 2 1\n0.2 1 2 1\n"}, r"events.txt line 3: timestamp 0.2 follows 0.3 .*sorted \(non-decreasing\)"),
        ({"events_txt": "0.1 1 2 1\nnan 1 2 1\n"}, r"events.txt line 2: column 't' must be a finite number"),
        ({"imu_txt": "0.0 0 0 9.8 0 0 0\n0.1 0 0 9.8 0 0 0\n0.1 0 0 9.8 0 0 0\n"}, r"imu.txt line 3: timestamp 0.1 follows 0.1 .*no duplicates"),
        ({"imu_txt": "0.0 0 0 9.8 0 0\n"}, r"imu.txt line 1: expected 7 columns \(t ax ay az gx gy gz\), got 6"),
        ({"imu_txt": "0.0 0 0 9.8 0 0 inf\n"}, r"imu.txt line 1: column 'gz' must be a finite number"),
        ({"groundtruth_txt": "0.0 0 0 0 0 0 1\n"}, r"groundtruth.txt line 1: expected 8 columns \(t px py pz qx qy qz qw\), got 7"),
        ({"calib_txt": "199 198 132 110 -0.36 0.15 0 0\n"}, r"calib.txt line 1: expected 9 columns \(fx fy cx cy k1 k2 p1 p2 k3\), got 8"),
        ({"calib_txt": "1 1 1 1 0 0 0 0 0\n1 1 1 1 0 0 0 0 0\n"}, r"calib.txt line 2: expected a single line"),
        ({"images_txt": "0.0 images/frame_00000000.png\n"}, r"images.txt line 1: image file images/frame_00000000.png not found"),
        ({"images_txt": "0.0\n"}, r"images.txt line 1: expected 2 columns \(t image_path\), got 1"),
        ({"groundtruth_imu_txt": "0 0 0 0 0 0 0 1 0\n"}, r"groundtruth_imu.txt line 1: expected 8, 11, 14 or 17 columns .* got 9"),
        ({"evio_sim_json": "{\n \"name\": \n"}, r"evio_sim.json line 3: invalid JSON"),
    ],
)
def test_read_errors_name_file_line_and_problem(tmp_path, files, message):
    folder = _folder(tmp_path, **files)
    with pytest.raises(DataFileError, match=message):
        read_ecd(folder)


def test_image_list_errors(tmp_path):
    folder = _folder(tmp_path)
    (folder / "images").mkdir()
    cv2.imwrite(str(folder / "images" / "a.png"), np.zeros((180, 240), np.uint8))
    cv2.imwrite(str(folder / "images" / "b.png"), np.zeros((10, 10), np.uint8))
    (folder / "images.txt").write_text("0.5 images/a.png\n0.5 images/a.png\n")
    with pytest.raises(DataFileError, match=r"images.txt line 2: timestamp 0.5 follows 0.5; t must be strictly increasing"):
        read_ecd(folder)
    (folder / "images.txt").write_text("0.5 images/a.png\n0.6 images/b.png\n")
    with pytest.raises(DataFileError, match=r"images.txt frame 1 \(b.png\): image size 10 x 10 differs from the sensor size 240 x 180"):
        read_ecd(folder)


def test_image_paths_with_spaces_and_a_sidecar_gravity_that_is_no_gravity(tmp_path):
    folder = _folder(tmp_path)
    (folder / "my images").mkdir()
    image = (np.arange(180 * 240) % 251).astype(np.uint8).reshape(180, 240)
    cv2.imwrite(str(folder / "my images" / "frame 0.png"), image)
    (folder / "images.txt").write_text("0.5 my images/frame 0.png\n")
    seq = read_ecd(folder)
    np.testing.assert_array_equal(seq.frames[0], image)
    (folder / "evio_sim.json").write_text(json.dumps({"metadata": {"gravity_G": [0, 0, 0]}}))
    with pytest.raises(DataFileError, match=r"^evio_sim.json: metadata.gravity_G = \[0.0, 0.0, 0.0\] has norm 0 m/s"):
        read_ecd(folder)
    (folder / "evio_sim.json").write_text(json.dumps({"metadata": {"gravity_G": "down"}}))
    with pytest.raises(DataFileError, match=r"^evio_sim.json: metadata.gravity_G must be 3 numbers"):
        read_ecd(folder)


def test_missing_files_and_folders(tmp_path):
    with pytest.raises(DataFileError, match="ECD folder not found"):
        read_ecd(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataFileError, match=r"events.txt: file not found at .*empty/events.txt"):
        read_ecd(tmp_path / "empty")
    with pytest.raises(DataFileError, match=r"slider.txt: file not found"):
        read_ecd_events(tmp_path / "slider.txt")


def test_sidecar_overrides_size_and_empty_events_file(tmp_path):
    folder = _folder(tmp_path, events_txt="", evio_sim_json=json.dumps({"name": "x", "sensor_size": [4, 3], "metadata": {}}))
    seq = read_ecd(folder)
    assert seq.sensor_size == (4, 3) and len(seq.events) == 0 and seq.name == "x"
    (folder / "events.txt").write_text("0.0 4 0 1\n")
    with pytest.raises(DataFileError, match=r"events.txt line 1: column 'x' value 4 is out of range: x must be an integer in \[0, 4\)"):
        read_ecd(folder)
    assert len(read_ecd(folder, sensor_size=(5, 3)).events) == 1
    with pytest.raises(ValueError, match=r"sensor_size must be \(width, height\) in positive whole pixels; got \(5, 0\)"):
        read_ecd(folder, sensor_size=(5, 0))


def _failing_groundtruth_writer(*args, **kwargs):
    raise OSError("disk full (simulated)")


def test_failed_write_into_new_folder_leaves_nothing(tmp_path, rng, monkeypatch):
    monkeypatch.setattr(ecd, "write_tum", _failing_groundtruth_writer)  # fails after events, IMU and frames
    with pytest.raises(OSError, match="disk full"):
        write_ecd(_simulated_sequence(rng, True), tmp_path / "new")
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("error", [OSError("disk full (simulated)"), KeyboardInterrupt()])
def test_failed_write_into_existing_folder_is_refused_by_read_ecd(tmp_path, rng, monkeypatch, error):
    folder = write_ecd(_simulated_sequence(rng, True), tmp_path / "f")
    (folder / "notes.txt").write_text("the user's file")

    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(ecd, "write_tum", fail)
    with pytest.raises(type(error)):
        write_ecd(_simulated_sequence(rng, False), folder)
    assert (folder / "events.txt").is_file() and (folder / ecd.INCOMPLETE_MARKER).is_file()  # half written ...
    with pytest.raises(DataFileError, match=r"ECD folder .*f is incomplete: a write_ecd into it failed or was interrupted"):
        read_ecd(folder)  # ... and never loaded as a recording
    assert (folder / "notes.txt").read_text() == "the user's file"
    monkeypatch.undo()
    seq = _simulated_sequence(rng, True)
    back = read_ecd(write_ecd(seq, folder))  # a complete write clears the marker
    np.testing.assert_array_equal(back.events, seq.events)
    assert not (folder / ecd.INCOMPLETE_MARKER).exists()


def test_invalid_input_writes_nothing(tmp_path):
    seq = Sequence("bad", events=make_events([0.0], [1], [1], [1]), metadata={"callback": print})
    with pytest.raises(ValueError, match=r"sequence\['metadata'\]\['callback'\] must be JSON-like"):
        write_ecd(seq, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="folder must be a folder path; .*file is a file"):
        write_ecd(Sequence("ok", events=make_events([0.0], [1], [1], [1])), tmp_path / "file")


def test_groundtruth_imu_quaternions_are_normalised_or_refused(tmp_path):
    """groundtruth_imu.txt: a quaternion within 1e-3 of unit norm is normalised; norm 2 names the file and line."""
    from evio_lib.io.ecd import _read_groundtruth_imu
    from evio_lib.io.errors import DataFileError

    path = tmp_path / "groundtruth_imu.txt"
    path.write_text("0.0 0 0 0 0 0 0 1.0005\n0.1 0 0 0 0 0 0 1\n")
    gt = _read_groundtruth_imu(path)
    assert abs(float(np.linalg.norm(gt.q_GtoB[0])) - 1.0) < 1e-12
    path.write_text("0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 2\n")
    with pytest.raises(DataFileError, match="line 2: quaternion"):
        _read_groundtruth_imu(path)


def test_read_frames_without_events(tmp_path, rng):
    seq = _simulated_sequence(rng, ns_grid=True)
    write_ecd(seq, tmp_path / "rec")
    (tmp_path / "rec" / "events.txt").unlink()
    back = ecd.read_ecd_frames(tmp_path / "rec")
    np.testing.assert_array_equal(back.frames, seq.frames)
    np.testing.assert_array_equal(back.frame_times, seq.frame_times)
    assert back.camera == seq.camera and len(back.events) == 0
    _assert_same_groundtruth(back.groundtruth, seq.groundtruth)
    (tmp_path / "rec" / "images.txt").unlink()
    with pytest.raises(DataFileError, match="images.txt"):
        ecd.read_ecd_frames(tmp_path / "rec")


def test_read_frames_of_the_real_slider(real_data_dir):
    seq = ecd.read_ecd_frames(real_data_dir / "ecd_slider_depth_slice")
    assert seq.frames.shape == (87, 180, 240) and seq.camera.fx == pytest.approx(335.419462958)
    assert seq.groundtruth is not None and seq.groundtruth.body == "camera"


@pytest.mark.parametrize("name, text", [
    ("images.txt", b"0.5 images/a.png\n0.6 \xe9t\xe9.png\n"),
    ("evio_sim.json", b'{"name": "\xff"}\n'),
    ("groundtruth_imu.txt", b"# t p q\n\xe9\n"),
    ("events.txt", b"0.1 1 2 1\n0.2 \xff 4 0\n"),
    ("calib.txt", b"199 198 132 110 -0.36 0.15 0 0 \xe9\n"),
])
def test_files_that_are_not_utf8_text_are_named_with_their_line(tmp_path, name, text):
    """A Latin-1 or binary byte in any text file of the folder is one error naming the file and its line, never the
    bare 'utf-8 codec can't decode' text that names neither."""
    folder = _folder(tmp_path)
    (folder / "images").mkdir()
    cv2.imwrite(str(folder / "images" / "a.png"), np.zeros((180, 240), np.uint8))
    (folder / name).write_bytes(text)
    with pytest.raises(DataFileError, match=rf"^{re.escape(name)} line (2|1)") as error:
        read_ecd(folder)
    assert "codec" not in str(error.value)


def test_a_damaged_frame_is_one_error_with_the_decoders_words_and_nothing_on_stderr(tmp_path, capfd):
    """libpng's own 'libpng error: IHDR: CRC error' line goes into the error, not onto the terminal before it."""
    folder = _folder(tmp_path)
    (folder / "images").mkdir()
    png = bytearray(cv2.imencode(".png", np.zeros((180, 240), np.uint8))[1].tobytes())
    png[20] ^= 0xFF  # the header chunk's CRC no longer matches
    (folder / "images" / "a.png").write_bytes(bytes(png))
    (folder / "images.txt").write_text("0.5 images/a.png\n")
    with pytest.raises(DataFileError, match=r"could not decode image a.png \(libpng error: IHDR: CRC error\)$"):
        read_ecd(folder)
    assert capfd.readouterr().err == ""


@pytest.mark.parametrize("sidecar, message", [
    ({"R_CtoI": "down"}, r"^evio_sim.json: R_CtoI must be a 3 x 3 rotation matrix .*got 'down' \(R_CtoI must be a "
                         r"numeric array"),
    ({"R_CtoI": [1, 2, 3]}, r"^evio_sim.json: R_CtoI must be .*\(R_CtoI must have shape \(\.\.\., 3, 3\); got \(3,\)\)"),
    ({"R_CtoI": [[[1, 0, 0], [0, 1, 0], [0, 0, 1]]] * 2}, r"^evio_sim.json: R_CtoI must be .*\(one, not a stack"),
    ({"R_CtoI": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, r"^evio_sim.json: R_CtoI .*det\(R_CtoI\) == 1 .*got det -1"),
    ({"p_CinI": "down"}, r"^evio_sim.json: p_CinI must be 3 numbers \[m\]"),
    ({"p_CinI": [0.1, 0.2]}, r"^evio_sim.json: p_CinI must be 3 numbers"),
    ({"metadata": "down"}, r"^evio_sim.json: metadata must be a JSON object; got str"),
    ({"metadata": {"imu_noise": "down"}}, r"^evio_sim.json: metadata.imu_noise must be an object of noise densities"),
])
def test_a_sidecar_value_of_the_wrong_form_is_refused_naming_the_file(tmp_path, sidecar, message):
    """Extrinsics and noise in evio_sim.json are checked where they are read: one error naming the file and the
    field, not a bare numpy text ('could not convert string to float') and never accepted silently."""
    folder = _folder(tmp_path, evio_sim_json=json.dumps(sidecar))
    with pytest.raises(DataFileError, match=message):
        read_ecd(folder)


def test_a_table_separated_by_commas_says_so(tmp_path):
    """imu.txt written as CSV: the error says what separates its values, not only '1 column'."""
    folder = _folder(tmp_path, imu_txt="0.0,0,0,9.8,0,0,0\n0.1,0,0,9.8,0,0,0\n")
    with pytest.raises(DataFileError, match=r"imu.txt line 1: expected 7 columns \(t ax ay az gx gy gz\), got 1 \(its "
                                            r"values are separated by ','; this format separates its columns by spaces\)"):
        read_ecd(folder)


def test_decoding_from_several_threads_leaves_stderr_where_it_was(tmp_path, capfd):
    """read_image points descriptor 2 elsewhere while it decodes; threads take turns, so stderr is the same after."""
    from concurrent.futures import ThreadPoolExecutor

    from evio_lib.io.image_files import read_image

    path = tmp_path / "a.png"
    cv2.imwrite(str(path), np.zeros((60, 80), np.uint8))
    with ThreadPoolExecutor(4) as pool:
        images = list(pool.map(lambda _: read_image(path)[0], range(200)))
    assert all(image is not None and image.shape == (60, 80) for image in images)
    os.write(2, b"still here\n")
    assert capfd.readouterr().err == "still here\n"
