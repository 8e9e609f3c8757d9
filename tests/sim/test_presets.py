"""Tests of evio_lib.sim.presets: whole simulated recordings are mutually consistent across sensors."""
from dataclasses import replace

import numpy as np
import pytest

from evio_lib.events.array import validate_events
from evio_lib.events.simulate import EventCameraParams, log_intensity
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import quat_to_rot
from evio_lib.io.ecd import read_ecd, write_ecd
from evio_lib.sim.imu import ImuNoiseParams
from evio_lib.sim.presets import CameraPoseTable, SimulationConfig, _pose_function, simulate_sequence
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.scene import scene_from_preset
from evio_lib.sim.trajectory import boxes_like, trajectory_from_preset

SMALL_CAMERA = PinholeRadtan.davis240c().scaled(0.25)  # 60 x 45 pixels: the same lens, cheap to render


def _ideal_config(preset: str, duration: float = 0.3, **changes) -> SimulationConfig:
    """A short, noise-free recording with a small camera (fast to simulate)."""
    config = SimulationConfig(
        preset=preset, duration=duration, seed=3, camera=SMALL_CAMERA, imu_noise=ImuNoiseParams.noise_free(),
        events=EventCameraParams(contrast_sigma=0.0, refractory_s=0.0), trajectory_duration=10.0, start_time=4.0,
    )
    return replace(config, **changes)


def test_pose_table_matches_the_exact_trajectory():
    trajectory = boxes_like(10.0, seed=1)
    extrinsics = CameraImuExtrinsics.default()
    table = CameraPoseTable(trajectory, extrinsics, 7.0, 10.0)  # the violent end of the preset
    times = np.random.default_rng(0).uniform(7.0, 10.0, 3000)
    R_table, p_table = table(times)
    R_exact, p_exact = _pose_function(trajectory, extrinsics)(times)
    assert np.abs(p_table - p_exact).max() < 1e-9  # metres
    assert np.abs(R_table - R_exact).max() < 1e-6  # rad: far below a pixel (1/200 rad)
    R_grid, p_grid = table(table.t[:50])
    R_true, p_true = _pose_function(trajectory, extrinsics)(table.t[:50])
    np.testing.assert_allclose(p_grid, p_true, atol=1e-12)
    np.testing.assert_allclose(R_grid, R_true, atol=1e-12)
    with pytest.raises(ValueError, match="times must lie in"):
        table(np.array([6.0]))


def test_config_validation():
    with pytest.raises(ValueError, match="preset must be one of"):
        SimulationConfig(preset="moon_landing")
    with pytest.raises(ValueError, match="duration must be a positive"):
        SimulationConfig(duration=0.0)
    with pytest.raises(ValueError, match="must lie within the preset's motion"):
        SimulationConfig(duration=5.0, start_time=8.0, trajectory_duration=10.0)
    assert "imu_rate_hz" in str(SimulationConfig())


@pytest.mark.parametrize("preset", ["boxes_like", "aerial_like"])
def test_sensors_agree_with_the_ground_truth(preset):
    config = _ideal_config(preset)
    seq = simulate_sequence(config)
    seq.validate()
    camera = config.camera
    # ground truth: the camera pose is the IMU pose composed with the extrinsics
    gt, gt_imu = seq.groundtruth, seq.groundtruth_imu
    np.testing.assert_allclose(gt.t, gt_imu.t)
    R_CtoG, p_CinG = config.extrinsics.camera_pose(gt_imu.R_BtoG, gt_imu.p_BinG)
    np.testing.assert_allclose(gt.p_BinG, p_CinG, atol=1e-12)
    np.testing.assert_allclose(gt.R_BtoG, R_CtoG, atol=1e-12)
    # noise-free IMU: the gyro reads the body rate plus the (constant) bias; the accelerometer the specific force
    assert seq.imu.t[0] == pytest.approx(config.start_time) and seq.imu.t[-1] == pytest.approx(config.t_end)
    np.testing.assert_allclose(np.diff(seq.imu.t), 1.0 / config.imu_rate_hz, atol=1e-9)
    truth = trajectory_from_preset(preset, duration=config.motion_duration(), seed=config.seed).evaluate(seq.imu.t)
    np.testing.assert_allclose(seq.imu.gyro, truth.w_I, atol=1e-12)  # noise-free: no bias, no noise
    specific_force_I = np.einsum("nji,nj->ni", truth.R_ItoG, truth.a_IinG - np.array([0.0, 0.0, -9.81]))
    np.testing.assert_allclose(seq.imu.accel, specific_force_I, atol=1e-9)
    # frames: 24 Hz inside the recording, sensor-sized, 8 bit
    assert seq.frames.dtype == np.uint8 and seq.frames.shape[1:] == (camera.height, camera.width)
    assert len(seq.frames) == len(seq.frame_times) >= int(config.duration * config.frame_rate_hz) - 1
    # events: the layout of the project, inside the sensor and the recording
    validate_events(seq.events, camera.width, camera.height)
    assert len(seq.events) > 100
    assert seq.events["t"][0] >= config.start_time and seq.events["t"][-1] <= config.t_end


def test_a_faster_recording_is_the_preset_played_faster():
    """speed = 2: the IMU reads the time-scaled motion (rates x 2, accelerations x 4), the ground truth at time t is
    the preset's pose at 2 t, and the digests name the speed (while speed 1 keeps the names of the recordings
    simulated before the option existed)."""
    from evio_lib.sim.presets import recording_settings_digest

    slow = _ideal_config("boxes_like", duration=0.2, with_events=False)
    fast = replace(slow, speed=2.0, start_time=2.0, trajectory_duration=5.0)  # the preset's [4, 4.4] s of a 10 s motion
    seq = simulate_sequence(fast)
    base = boxes_like(10.0, seed=fast.seed).evaluate(2.0 * seq.imu.t)
    np.testing.assert_allclose(seq.imu.gyro, 2.0 * base.w_I, atol=1e-12)
    np.testing.assert_allclose(seq.imu.accel, np.einsum("nji,nj->ni", base.R_ItoG, 4.0 * base.a_IinG
                                                        - np.array([0.0, 0.0, -9.81])), atol=1e-9)
    truth = seq.groundtruth_imu
    np.testing.assert_allclose(truth.p_BinG, boxes_like(10.0, seed=fast.seed).evaluate(2.0 * truth.t).p_IinG, atol=1e-12)
    assert seq.metadata["config"]["speed"] == 2.0
    assert recording_settings_digest(fast) != recording_settings_digest(replace(fast, speed=1.0))
    assert recording_settings_digest(SimulationConfig(preset="boxes_like", duration=60.0, trajectory_duration=60.0,
                                                      seed=0, start_time=0.0)) == "7d0f172b"  # as before the option
    for bad in (0.0, 0.1, 5.0, np.nan, True):
        with pytest.raises(ValueError, match=r"speed must be a number in \[0.25, 4\]"):
            replace(slow, speed=bad)


def test_events_integrate_to_the_log_intensity_change():
    """Per pixel, sum(p) * C equals the change of log intensity between the first and last render (within C)."""
    config = _ideal_config("boxes_like", with_frames=False)
    seq = simulate_sequence(config)
    scene = scene_from_preset(config.preset, seed=config.seed)
    pose_at = _pose_function(boxes_like(10.0, seed=config.seed), config.extrinsics)
    R, p = pose_at(np.array([config.start_time, config.t_end]))
    log_start = log_intensity(scene.render_intensity(config.camera, R[0], p[0]), config.events.log_eps)
    log_end = log_intensity(scene.render_intensity(config.camera, R[1], p[1]), config.events.log_eps)
    polarity_sum = np.zeros((config.camera.height, config.camera.width))
    np.add.at(polarity_sum, (seq.events["y"], seq.events["x"]), seq.events["p"])
    C = config.events.contrast_pos
    error = polarity_sum * C - (log_end - log_start)
    assert np.abs(error).max() <= C + 1e-6
    assert np.abs(polarity_sum).max() >= 3  # the test is not vacuous: pixels crossed several thresholds


def test_ecd_round_trip_of_a_simulated_sequence(tmp_path):
    config = _ideal_config("aerial_like", duration=0.2)
    seq = simulate_sequence(config)
    write_ecd(seq, tmp_path / "sim")
    back = read_ecd(tmp_path / "sim")
    np.testing.assert_array_equal(back.events, seq.events)
    np.testing.assert_allclose(back.imu.accel, seq.imu.accel, atol=1e-9)
    np.testing.assert_array_equal(back.frames, seq.frames)
    np.testing.assert_allclose(back.groundtruth.p_BinG, seq.groundtruth.p_BinG, atol=1e-9)
    np.testing.assert_allclose(quat_to_rot(back.groundtruth.q_GtoB), quat_to_rot(seq.groundtruth.q_GtoB), atol=1e-9)
    np.testing.assert_allclose(back.R_CtoI, seq.R_CtoI, atol=1e-12)
    np.testing.assert_allclose(back.groundtruth_imu.bias_gyro, seq.groundtruth_imu.bias_gyro, atol=1e-9)


def test_same_seed_same_recording_and_streams_are_independent():
    config = _ideal_config("aerial_like", duration=0.15, imu_noise=ImuNoiseParams(),
                           events=EventCameraParams())
    timings: dict[str, float] = {}
    a, b = simulate_sequence(config, timings=timings), simulate_sequence(config)
    np.testing.assert_array_equal(a.events, b.events)
    np.testing.assert_array_equal(a.imu.gyro, b.imu.gyro)
    assert set(timings) == {"imu_s", "events_s", "frames_s"} and all(v >= 0 for v in timings.values())
    assert a.metadata == b.metadata  # wall-clock seconds stay out of the recording
    assert a.metadata["timings"] == {"event_renders": float(a.metadata["timings"]["event_renders"])} \
        and a.metadata["timings"]["event_renders"] > 0
    no_events = simulate_sequence(replace(config, with_events=False))
    np.testing.assert_array_equal(no_events.imu.gyro, a.imu.gyro)  # switching a sensor off changes no other sensor
    assert len(no_events.events) == 0


def test_cached_simulation_is_the_simulation_and_is_keyed_by_every_field(tmp_path, monkeypatch, capsys):
    """simulate_sequence_cached: the first call simulates and stores, the second reads the same arrays back; a config
    that differs in any field (here the camera, or the extrinsics' 9th digit) gets its own file; a damaged file is
    said and simulated again."""
    from evio_lib.sim.presets import simulate_sequence_cached, simulation_cache_path

    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))
    cfg = SimulationConfig(preset="boxes_like", duration=0.2, trajectory_duration=2.0,
                           camera=PinholeRadtan.davis240c().scaled(0.25), seed=3)
    first = simulate_sequence_cached(cfg)
    path = simulation_cache_path(cfg)
    assert path.is_file() and path.parent == tmp_path / "cache" / "sequences"
    direct = simulate_sequence(cfg)
    again = simulate_sequence_cached(cfg)
    for seq in (first, again):
        np.testing.assert_array_equal(seq.events, direct.events)
        np.testing.assert_array_equal(seq.frames, direct.frames)
        np.testing.assert_array_equal(seq.imu.accel, direct.imu.accel)
        assert seq.metadata["timings"] == direct.metadata["timings"]
    other_camera = replace(cfg, camera=PinholeRadtan.davis240c().scaled(0.5))
    R = cfg.extrinsics.R_CtoI.copy()
    nudged = replace(cfg, extrinsics=CameraImuExtrinsics(R_CtoI=R, p_CinI=cfg.extrinsics.p_CinI + 1e-9))
    assert len({simulation_cache_path(c) for c in (cfg, other_camera, nudged)}) == 3
    path.write_bytes(path.read_bytes()[:100])  # truncated
    healed = simulate_sequence_cached(cfg)
    assert "was damaged" in capsys.readouterr().err
    np.testing.assert_array_equal(healed.events, direct.events)


def test_frames_rendered_by_worker_processes_are_the_serial_frames(monkeypatch):
    """jobs > 1 renders the exposures in other processes and draws the noise here, in frame order: same bytes."""
    from evio_lib.sim import presets

    monkeypatch.setattr(presets, "MIN_FRAMES_PER_JOB", 4)  # a short recording takes the parallel path
    config = SimulationConfig(preset="boxes_like", duration=0.6, start_time=0.5, seed=4, with_events=False,
                              camera=PinholeRadtan(fx=40.0, fy=40.0, cx=23.5, cy=17.5, width=48, height=36))
    serial = simulate_sequence(config)
    parallel = simulate_sequence(config, jobs=np.int64(2))
    assert serial.frames.shape[0] >= 8  # enough frames for the parallel path (>= 4 per job)
    assert np.array_equal(serial.frames, parallel.frames)
    assert np.array_equal(serial.imu.gyro, parallel.imu.gyro)


def test_frames_rendered_while_the_events_are_simulated_are_the_serial_frames(monkeypatch):
    """With events, one worker renders the exposures while this process simulates the events: same bytes."""
    from evio_lib.sim import presets

    monkeypatch.setattr(presets, "MIN_FRAMES_PER_JOB", 4)
    config = SimulationConfig(preset="boxes_like", duration=0.5, seed=5, with_events=True,
                              camera=PinholeRadtan(fx=40.0, fy=40.0, cx=23.5, cy=17.5, width=48, height=36))
    serial = simulate_sequence(config)
    parallel = simulate_sequence(config, jobs=2)
    assert serial.frames.shape[0] >= 4 and len(serial.events) > 0
    assert np.array_equal(serial.frames, parallel.frames)
    assert np.array_equal(serial.events, parallel.events)


@pytest.mark.parametrize("jobs", [0, -1, 1.5, True])
def test_jobs_must_be_a_positive_count(jobs, tmp_path, monkeypatch):
    from evio_lib.pipeline.dataset import simulate_preset
    from evio_lib.sim.presets import simulate_sequence_cached

    with pytest.raises(ValueError, match="jobs must be an integer >= 1"):
        simulate_sequence(SimulationConfig(duration=0.1, with_events=False), jobs=jobs)
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path))
    for call in (lambda: simulate_preset("boxes_like", 0.1, jobs=jobs),
                 lambda: simulate_sequence_cached(SimulationConfig(duration=0.1, with_events=False), jobs=jobs)):
        with pytest.raises(ValueError, match="jobs must be an integer >= 1"):  # before the cache is looked at
            call()


def test_evio_jobs_sets_the_default_and_is_checked(monkeypatch):
    from evio_lib.sim.jobs import default_jobs

    monkeypatch.setenv("EVIO_JOBS", "3")
    assert default_jobs() == 3
    monkeypatch.setenv("EVIO_JOBS", "two")
    with pytest.raises(ValueError, match="EVIO_JOBS must be a whole number >= 1"):
        default_jobs()
    monkeypatch.delenv("EVIO_JOBS")
    assert 1 <= default_jobs() <= 4
