"""Tests of evio_lib.pipeline.dataset: what DATASET means, the cache, extrinsics and their sources."""
import numpy as np
import pytest

from evio_lib.geometry.rotation import so3_exp
from evio_lib.io.ecd import write_ecd
from evio_lib.pipeline.dataset import load_dataset, read_kalibr_extrinsics, sequence_cache_dir, simulate_preset


def test_preset_is_cached_and_read_back_identical(boxes_aps):
    files = list(sequence_cache_dir().glob("boxes_like_d3_seed0_m*_frames.npz"))
    assert len(files) == 1
    again = load_dataset("boxes_like", duration=3.0)
    np.testing.assert_array_equal(again.sequence.frames, boxes_aps.sequence.frames)
    np.testing.assert_array_equal(again.sequence.imu.accel, boxes_aps.sequence.imu.accel)
    assert boxes_aps.kind == "preset" and boxes_aps.notes[0].startswith("extrinsics: from the recording")
    np.testing.assert_allclose(boxes_aps.R_CtoI, boxes_aps.sequence.R_CtoI)


def test_cache_names_carry_a_digest_of_every_setting(boxes_aps):
    """The cache name carries a digest of every setting but which sensors were simulated: a recording of the same
    preset, duration and seed made with another APS noise (an older simulator) has another name, so it is never read
    back; the events and the frames-only recordings share it."""
    import dataclasses

    from evio_lib.sim.aps import ApsParams
    from evio_lib.sim.presets import SimulationConfig, recording_settings_digest

    config = SimulationConfig(preset="boxes_like", duration=3.0, trajectory_duration=60.0, seed=0, with_events=False)
    digest = recording_settings_digest(config)
    assert [f.name for f in sequence_cache_dir().glob("boxes_like_d3_seed0_m*_frames.npz")] == [
        f"boxes_like_d3_seed0_m{digest}_frames.npz"]
    assert recording_settings_digest(dataclasses.replace(config, with_events=True)) == digest
    noisier = dataclasses.replace(config, aps=ApsParams(read_noise_sigma=0.01, shot_noise_scale=0.003))
    assert recording_settings_digest(noisier) != digest
    assert recording_settings_digest(dataclasses.replace(config, seed=1)) != digest


def test_preset_duration_is_the_start_of_the_whole_motion(boxes_aps):
    """3 s of the preset is the first 3 s of the 60 s recording, not the whole motion squeezed into 3 s."""
    longer = simulate_preset("boxes_like", 4.0, 0)
    t = boxes_aps.sequence.groundtruth.t
    np.testing.assert_allclose(longer.groundtruth.p_BinG[: len(t)], boxes_aps.sequence.groundtruth.p_BinG, atol=1e-9)


def test_preset_start_takes_a_later_stretch_of_the_same_motion(boxes_aps):
    """start = 2 s: the stretch [2, 3] s of the motion, its ground truth that of the recording from 0 s there, cached
    under its own name; a start past the motion, or a stretch ending after it, is refused."""
    later = load_dataset("boxes_like", duration=1.0, start=2.0)
    gt, full = later.sequence.groundtruth, boxes_aps.sequence.groundtruth
    assert gt.t[0] >= 2.0 and gt.t[-1] <= 3.0 + 1e-9 and later.sequence.imu.t[0] >= 2.0
    k = np.searchsorted(full.t, gt.t[0])
    np.testing.assert_allclose(full.t[k:k + 50], gt.t[:50], atol=1e-9)
    np.testing.assert_allclose(full.p_BinG[k:k + 50], gt.p_BinG[:50], atol=1e-9)
    assert list(sequence_cache_dir().glob("boxes_like_d1_seed0_start2_m*_frames.npz"))
    with pytest.raises(ValueError, match=r"start of boxes_like must be in \[0, 60\) s"):
        load_dataset("boxes_like", start=60.0)
    with pytest.raises(ValueError, match=r"ends after its motion"):
        load_dataset("boxes_like", start=59.0, duration=2.0)


def test_aps_exposure_blurs_the_frames_and_names_its_own_recording(pipeline_cache):
    """aps_exposure_s: the same motion, IMU and ground truth; frames at the exposure's middle, blurred more by a
    longer exposure where the camera moves fast; cached under its own name, and 10 ms is the default's recording.
    With events, the default recording's events join this exposure's frames, equal to a whole simulation."""
    import cv2

    def sharpness(frames):  # mean |Laplacian|: the fine detail that motion blur removes
        return float(np.mean([np.abs(cv2.Laplacian(f.astype(np.float32), cv2.CV_32F)).mean() for f in frames]))

    short = load_dataset("boxes_like", duration=0.3, start=52.0).sequence  # the violent end
    long = load_dataset("boxes_like", duration=0.3, start=52.0, aps_exposure_s=0.03).sequence
    np.testing.assert_array_equal(long.imu.gyro, short.imu.gyro)
    np.testing.assert_array_equal(long.groundtruth.p_BinG, short.groundtruth.p_BinG)
    np.testing.assert_allclose(long.frame_times - short.frame_times, (0.03 - 0.01) / 2, atol=1e-9)
    assert sharpness(long.frames) < 0.85 * sharpness(short.frames)
    names = sorted(p.name for p in sequence_cache_dir().glob("boxes_like_d0.3_seed0_start52_m*_frames.npz"))
    assert len(names) == 2
    again = load_dataset("boxes_like", duration=0.3, start=52.0, aps_exposure_s=0.01).sequence  # the default's
    np.testing.assert_array_equal(again.frames, short.frames)
    assert len(list(sequence_cache_dir().glob("boxes_like_d0.3_seed0_start52_m*_frames.npz"))) == 2
    # with events: the default recording's events beside this exposure's frames, equal to a whole simulation
    both = load_dataset("boxes_like", duration=0.3, start=52.0, aps_exposure_s=0.03, need_events=True).sequence
    whole = simulate_preset("boxes_like", 0.3, 0, with_events=True, start=52.0, aps_exposure_s=0.03, cache=False)
    for name in ("events", "frames", "frame_times"):
        np.testing.assert_array_equal(getattr(both, name), getattr(whole, name))
    np.testing.assert_array_equal(both.imu.accel, whole.imu.accel)
    assert both.metadata == whole.metadata and both.metadata["config"]["aps"]["exposure_s"] == 0.03
    events_files = list(sequence_cache_dir().glob("boxes_like_d0.3_seed0_start52_m*_events.npz"))
    assert len(events_files) == 1  # the default's: no second events file for the other exposure
    for bad in (0.0, -0.01, 0.05, float("nan"), True, "0.02"):
        with pytest.raises(ValueError, match=r"aps_exposure_s must be a number of seconds > 0 and at most one frame "
                                             r"interval, 1/24 s \(0.04166\)"):
            load_dataset("boxes_like", duration=0.3, start=52.0, aps_exposure_s=bad)
    with pytest.raises(ValueError, match="--aps-exposure applies to simulated presets"):
        load_dataset(str(pipeline_cache), aps_exposure_s=0.02)


def test_speed_plays_the_preset_faster_and_names_its_own_recording(tmp_path, monkeypatch, pipeline_cache):
    """speed: the preset's motion played faster; start and duration are seconds of the faster motion, whose whole
    lasts the preset's length / speed; cached under its own name; the run's notes say so; refused for a folder."""
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))  # its own recordings: other tests count theirs
    from evio_lib.sim.trajectory import boxes_like

    data = load_dataset("boxes_like", duration=0.3, start=26.0, speed=2.0)
    seq = data.sequence
    truth = boxes_like(60.0, seed=0).evaluate(2.0 * seq.imu.t)  # the preset's [52, 52.6] s, in 0.3 s
    np.testing.assert_allclose(seq.groundtruth_imu.p_BinG, boxes_like(60.0, seed=0).evaluate(
        2.0 * seq.groundtruth_imu.t).p_IinG, atol=1e-12)
    residual = seq.imu.gyro - 2.0 * truth.w_I  # the doubled rate, plus a nearly constant bias and the noise
    assert np.abs(residual - np.median(residual, axis=0)).mean() < 0.02 < np.abs(truth.w_I).mean()
    assert seq.frame_times[0] == pytest.approx(26.0 + 0.005) and len(seq.frames) == 7  # 24 Hz of played time
    assert any("played at speed 2 (rates x 2, accelerations x 4; its whole motion lasts 30 s)" in n for n in data.notes)
    assert [p.name.split("_m")[0] for p in sequence_cache_dir().glob("*.npz")] == ["boxes_like_d0.3_seed0_start26_speed2"]
    assert not any("speed" in n for n in load_dataset("boxes_like", duration=0.3, start=52.0, speed=1.0).notes)
    with pytest.raises(ValueError, match=r"start of boxes_like must be in \[0, 30\) s \(where in the preset's motion "
                                         r"played at speed 2"):
        load_dataset("boxes_like", duration=0.3, start=30.0, speed=2.0)
    with pytest.raises(ValueError, match=r"ends after its motion played at speed 2 \(0-30 s\)"):
        load_dataset("boxes_like", duration=2.0, start=29.0, speed=2.0)
    for bad in (0.0, 8.0, float("nan"), True, "2"):
        with pytest.raises(ValueError, match=r"speed must be a number in \[0.25, 4\]"):
            load_dataset("boxes_like", duration=0.3, speed=bad)
    with pytest.raises(ValueError, match="--speed applies to simulated presets"):
        load_dataset(str(pipeline_cache), speed=2.0)


@pytest.mark.parametrize("dataset, message", [
    ("no_such_preset", "neither a preset"),
    (__file__, "is a file"),
])
def test_bad_dataset_names_the_problem(dataset, message):
    with pytest.raises(ValueError, match=message):
        load_dataset(dataset)


def test_bad_duration_is_refused(pipeline_cache):
    with pytest.raises(ValueError, match=r"duration of boxes_like must be in \(0, 60\]"):
        load_dataset("boxes_like", duration=61.0)


def _ecd_folder(seq, folder, keep_sidecar=True):
    write_ecd(seq, folder)
    if not keep_sidecar:
        (folder / "evio_sim.json").unlink()
    return folder


def test_ecd_folder_without_sidecar_assumes_camera_equals_imu(boxes_aps, tmp_path):
    folder = _ecd_folder(boxes_aps.sequence.slice_time(0.0, 1.0), tmp_path / "rec", keep_sidecar=False)
    (folder / "events.txt").write_text("")  # an ECD folder needs events.txt; APS runs do not read it
    data = load_dataset(folder)
    assert data.kind == "ecd"
    np.testing.assert_array_equal(data.R_CtoI, np.eye(3))
    assert any("assumed camera = IMU frame" in n for n in data.notes)
    assert any("IMU noise: not in the recording" in n for n in data.notes)


def test_ecd_folder_without_imu_is_refused(boxes_aps, tmp_path):
    folder = _ecd_folder(boxes_aps.sequence.slice_time(0.0, 1.0), tmp_path / "rec")
    (folder / "imu.txt").unlink()
    with pytest.raises(ValueError, match="no IMU samples"):
        load_dataset(folder)
    (folder / "imu.txt").write_text("0.1 0.0 0.0 9.81 0.0 0.0 0.0\n")
    with pytest.raises(ValueError, match="holds one IMU sample"):
        load_dataset(folder)


def test_a_folder_named_like_a_preset_is_refused_by_its_bare_name(tmp_path, monkeypatch):
    (tmp_path / "boxes_like").mkdir()
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=r"names both the simulated preset and the folder .*boxes_like; write "
                                         r"./boxes_like for the recording"):
        load_dataset("boxes_like", duration=1.0)
    with pytest.raises(ValueError, match="events.txt"):     # ./boxes_like is the folder (an empty one here)
        load_dataset("./boxes_like")


def test_events_asked_of_a_folder_without_events(boxes_aps, tmp_path):
    folder = _ecd_folder(boxes_aps.sequence.slice_time(0.0, 1.0), tmp_path / "rec")
    (folder / "events.txt").write_text("")
    with pytest.raises(ValueError, match="no events"):
        load_dataset(folder, need_events=True, need_frames=False)


def test_kalibr_extrinsics_invert_T_cam_imu(tmp_path):
    R_CtoI = so3_exp(np.array([0.3, -1.2, 0.4]))
    p_CinI = np.array([0.01, -0.02, 0.05])
    T_cam_imu = np.eye(4)
    T_cam_imu[:3, :3], T_cam_imu[:3, 3] = R_CtoI.T, -R_CtoI.T @ p_CinI  # x_C = R_ItoC (x_I - p_CinI)
    rows = "\n".join(f"  - [{', '.join(repr(float(v)) for v in row)}]" for row in T_cam_imu)
    path = tmp_path / "camchain.yaml"
    path.write_text(f"cam0:\n  camera_model: pinhole\n  T_cam_imu:\n{rows}\n")
    R, p = read_kalibr_extrinsics(path)
    np.testing.assert_allclose(R, R_CtoI, atol=1e-12)
    np.testing.assert_allclose(p, p_CinI, atol=1e-12)
    # and the point maps back: x_I = R_CtoI x_C + p_CinI
    x_I = np.array([1.0, 2.0, 3.0])
    x_C = T_cam_imu[:3, :3] @ x_I + T_cam_imu[:3, 3]
    np.testing.assert_allclose(R @ x_C + p, x_I, atol=1e-12)


@pytest.mark.parametrize("text, message", [
    ("cam0:\n  intrinsics: [1, 2]\n", "no T_cam_imu"),
    ("T_cam_imu: [[1, 0], [0, 1]]\n", "4 x 4"),
    ("T_cam_imu: [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n", "not a rotation"),
    ("T_cam_imu: [[1, 0\n", "not a readable YAML"),
])
def test_bad_extrinsics_files(tmp_path, text, message):
    path = tmp_path / "x.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_kalibr_extrinsics(path)


def test_extrinsics_override(boxes_aps, tmp_path):
    path = tmp_path / "x.yaml"
    path.write_text("T_cam_imu: [[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n")
    data = load_dataset("boxes_like", duration=3.0, extrinsics=path)
    np.testing.assert_allclose(data.p_CinI, [-0.1, 0.0, 0.0])
    assert data.notes[0] == f"extrinsics: from {path}"


def test_euroc_folder_reads_extrinsics_and_noise(real_data_dir):
    data = load_dataset(real_data_dir / "euroc_V1_01_easy_micro")
    assert data.kind == "euroc"
    assert data.notes == ("extrinsics: from the recording (sensor.yaml)",)
    assert data.noise.gyro_noise_density == pytest.approx(1.6968e-4)
    np.testing.assert_allclose(data.R_CtoI @ data.R_CtoI.T, np.eye(3), atol=1e-6)


def test_a_recording_with_events_serves_a_frames_only_run(boxes_events):
    """The events cache is reused for an APS run (same seed: same frames and IMU), not simulated again."""
    frames_only = load_dataset("boxes_like", duration=1.5)
    assert not list(sequence_cache_dir().glob("boxes_like_d1.5_seed0_*frames.npz"))
    np.testing.assert_array_equal(frames_only.sequence.frames, boxes_events.sequence.frames)
    np.testing.assert_array_equal(frames_only.sequence.imu.gyro, boxes_events.sequence.imu.gyro)


def test_switching_events_off_keeps_frames_and_imu(pipeline_cache, boxes_events):
    """What the reuse relies on: the simulator's sensors draw from independent streams."""
    frames_only = simulate_preset("boxes_like", 1.5, 0, with_events=False, cache=False)
    np.testing.assert_array_equal(frames_only.frames, boxes_events.sequence.frames)
    np.testing.assert_array_equal(frames_only.imu.accel, boxes_events.sequence.imu.accel)


def test_ecd_folder_without_calibration_is_refused(boxes_aps, tmp_path):
    folder = _ecd_folder(boxes_aps.sequence.slice_time(0.0, 1.0), tmp_path / "rec")
    (folder / "calib.txt").unlink()
    with pytest.raises(ValueError, match="no camera calibration"):
        load_dataset(folder)


def test_a_euroc_recording_without_frames_is_told_about_its_camera_folder(real_data_dir, tmp_path):
    """No images.txt and no --frames events advice for EuRoC: its frames are mav0/cam0, and it holds no events."""
    import shutil

    folder = tmp_path / "euroc"
    shutil.copytree(real_data_dir / "euroc_V1_01_easy_micro", folder)
    index = folder / "mav0" / "cam0" / "data.csv"
    index.write_text("\n".join(index.read_text().splitlines()[:2]) + "\n")  # the header and one frame
    with pytest.raises(ValueError, match=r"fewer than 2 frames \(mav0/cam0/data.csv\): a EuRoC recording holds no "
                                         r"events") as error:
        load_dataset(folder)
    assert "images.txt" not in str(error.value) and "--frames events" not in str(error.value)
