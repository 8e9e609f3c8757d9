"""Tests for evio_lib.msckf.experiment: the perfect-data-association run against ground truth and IMU-only dead
reckoning, the TUM files (same body, same timestamps, checked with scipy), determinism, the NEES of the pose against
closed-form cases, the undistortion noise factor against a Monte-Carlo estimate, the command line and bad input."""
import argparse
import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import rot_to_quat
from evio_lib.io.tum import read_tum
from evio_lib.msckf.experiment import (
    VioSimConfig,
    add_vio_sim_arguments,
    experiment_msckf_config,
    initial_state,
    main_vio_sim,
    pose_nees,
    run_vio_sim,
    run_vio_sim_config,
    simulate_data,
)
from evio_lib.geometry.pixel_noise import observation_covariance, undistortion_noise_factor
from evio_lib.msckf.state import state_difference
from evio_lib.sim.trajectory import trajectory_from_preset


@pytest.fixture(scope="module")
def boxes_5s(tmp_path_factory):
    out = tmp_path_factory.mktemp("vio_sim")
    return run_vio_sim("boxes_like", duration=5.0, seed=1, out_dir=out), out


def test_short_boxes_run_beats_imu_only_by_a_large_factor(boxes_5s):
    """5 s boxes_like, 60 tracks, 1 px noise, unknown biases. Rows: the MSCKF, IMU-only without and with bias
    correction (the true initial biases), and the MSCKF started from those same biases (like for like)."""
    r, _ = boxes_5s
    msckf, no_bias, with_bias, msckf_bias = r.rows
    assert msckf["name"].startswith("MSCKF, OC on") and "no bias" in no_bias["name"] and "bias correction" in \
        with_bias["name"] and msckf_bias["name"] == "MSCKF, OC on (bias correction)"
    assert msckf["rmse_m"] < 0.15 and msckf["final_error_m"] < 0.25
    assert no_bias["rmse_m"] > 10 * msckf["rmse_m"] and no_bias["final_error_m"] > 20 * msckf["final_error_m"]
    assert with_bias["rmse_m"] > 2 * msckf["rmse_m"]
    assert with_bias["rmse_m"] > 2 * msckf_bias["rmse_m"]
    assert msckf["percent_of_distance"] < 5.0 and msckf["distance_m"] > 1.0
    for series in (r.nees_pose, r.nees_position, r.nees_attitude, r.nees_yaw, r.sigma, r.sigma_yaw):
        assert np.all(np.isfinite(series)) and np.all(series >= 0)
    assert np.mean(r.nees_pose) < 5 * 6  # not wildly overconfident
    assert r.features_used.sum() > 200 and r.cpu_s > 0 and r.realtime_factor > 0
    assert r.msckf_config.chi2_probability == 0.99  # the experiment's gate (exact tracks, no outliers)
    # the gyro bias is learnt from zero: its error is well below the prior spread (0.03 rad/s)
    assert np.linalg.norm(r.b_g_est[-1] - r.b_g_gt[-1]) < 0.01
    text = r.report()
    assert "RMSE" in text and "% Error" in text and "real-time factor" in text


def test_tum_files_hold_the_imu_pose_at_the_same_timestamps(boxes_5s):
    r, out = boxes_5s
    t_est, p_est, q_est = read_tum(out / "trajectory.txt")
    t_gt, p_gt, q_gt = read_tum(out / "groundtruth.txt")
    np.testing.assert_array_equal(t_est, t_gt)
    np.testing.assert_allclose(t_est, r.t, atol=1e-9)
    np.testing.assert_allclose(np.diff(t_est), 0.05, atol=1e-9)  # 20 Hz images
    # ground truth: the IMU body (not the camera) of the trajectory, Hamilton quaternions of R_ItoG (scipy)
    truth = trajectory_from_preset("boxes_like", 5.0, seed=0).evaluate(t_gt)
    np.testing.assert_allclose(p_gt, truth.p_IinG, atol=1e-12)
    np.testing.assert_allclose(Rotation.from_quat(q_gt).as_matrix(), truth.R_ItoG, atol=1e-9)
    # the estimate is in the same frame: close to the truth in position and orientation
    assert np.max(np.linalg.norm(p_est - p_gt, axis=1)) < 0.3
    dR = Rotation.from_quat(q_est) * Rotation.from_quat(q_gt).inv()
    assert np.max(dR.magnitude()) < 0.05
    np.testing.assert_allclose(p_est, r.p_est, atol=1e-12)


def test_runs_are_deterministic_for_a_seed_and_differ_between_seeds():
    a = run_vio_sim("boxes_like", duration=2.0, seed=3, features=30, baselines=False)
    b = run_vio_sim("boxes_like", duration=2.0, seed=3, features=30, baselines=False)
    c = run_vio_sim("boxes_like", duration=2.0, seed=4, features=30, baselines=False)
    np.testing.assert_array_equal(a.p_est, b.p_est)
    np.testing.assert_array_equal(a.q_est, b.q_est)
    np.testing.assert_array_equal(a.nees_pose, b.nees_pose)
    assert a.rejections == b.rejections
    assert not np.allclose(a.p_est, c.p_est)
    np.testing.assert_array_equal(a.p_gt, c.p_gt)  # same trajectory (trajectory_seed), other noise


def test_imu_only_mode_and_observability_constrained_switch():
    r = run_vio_sim("boxes_like", duration=2.0, seed=2, features=30, imu_only=True, baselines=False)
    assert r.features_used.sum() == 0 and r.msckf_config.imu_only
    assert r.rows[0]["name"].startswith("IMU-only")
    off = run_vio_sim("boxes_like", duration=2.0, seed=2, features=30, observability_constrained=False,
                      baselines=False)
    assert not off.msckf_config.observability_constrained and off.rows[0]["name"] == "MSCKF, OC off"
    assert off.metrics["rmse_m"] < 0.5 * r.metrics["rmse_m"]


def test_initial_state_draws_the_error_from_the_prior_and_zero_biases():
    cfg = VioSimConfig(preset="boxes_like", duration=2.0, seed=0, features=10)
    data = simulate_data(cfg)
    mcfg = experiment_msckf_config(cfg, data.noise, data.camera)
    s0 = data.trajectory.evaluate(0.0)
    truth = initial_state(data, dataclasses.replace(mcfg, init_sigma_attitude=0.0, init_sigma_velocity=0.0,
                                                    init_sigma_position=0.0), 0)
    np.testing.assert_allclose(truth.imu.p_IinG, s0.p_IinG[0], atol=1e-12)
    rng = np.random.default_rng(7)
    draws = np.array([state_difference(truth, initial_state(data, mcfg, rng)) for _ in range(400)])
    assert np.all(draws[:, 3:6] == 0.0) and np.all(draws[:, 9:12] == 0.0)  # bias estimates stay 0
    sig = np.sqrt(np.diag(mcfg.initial_imu_covariance()))
    for block in (slice(0, 3), slice(6, 9), slice(12, 15)):
        np.testing.assert_allclose(draws[:, block].std(axis=0), sig[block], rtol=0.15)
        assert np.all(np.abs(draws[:, block].mean(axis=0)) < 0.2 * sig[block])


def test_pose_nees_against_closed_form_cases():
    rng = np.random.default_rng(0)
    R_true = Rotation.from_rotvec(rng.normal(size=(5, 3)))  # R_ItoG
    alpha = np.array([0.01, -0.02, 0.005, 0.0, 0.03])
    R_est = Rotation.from_rotvec(np.outer(alpha, [0.0, 0.0, 1.0])).inv() * R_true  # a pure yaw error about z_G
    q_true = rot_to_quat(R_true.inv().as_matrix())  # JPL q_GtoI
    q_est = rot_to_quat(R_est.inv().as_matrix())
    sigma_theta, sigma_p = 0.01, 0.05
    P = np.tile(np.eye(15), (5, 1, 1))
    P[:, 0:3, 0:3] *= sigma_theta**2
    P[:, 12:15, 12:15] *= sigma_p**2
    dp = rng.normal(scale=0.05, size=(5, 3))
    p_true = rng.normal(size=(5, 3))
    out = pose_nees(q_est, p_true - dp, q_true, p_true, P)
    np.testing.assert_allclose(out["yaw"], alpha**2 / sigma_theta**2, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(out["attitude"], alpha**2 / sigma_theta**2, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(out["position"], np.sum(dp**2, axis=1) / sigma_p**2, rtol=1e-9)
    np.testing.assert_allclose(out["pose"], out["attitude"] + out["position"], rtol=1e-9)
    # a pure tilt error (about x_G) has no yaw component
    R_tilt = Rotation.from_rotvec([[0.02, 0.0, 0.0]]).inv() * R_true[:1]
    tilt = pose_nees(rot_to_quat(R_tilt.inv().as_matrix()), p_true[:1], q_true[:1], p_true[:1], P[:1])
    assert tilt["yaw"][0] < 1e-12 and tilt["attitude"][0] == pytest.approx(4.0, rel=1e-6)
    with pytest.raises(ValueError, match=r"P_imu must have shape \(K, 15, 15\) = \(5, 15, 15\)"):
        pose_nees(q_est, p_true, q_true, p_true, P[:, :6, :6])
    with pytest.raises(ValueError, match=r"q_est, q_gt must have shape \(K, 4\)"):
        pose_nees(q_est[:, :3], p_true, q_true, p_true, P)


def test_undistortion_noise_factor_matches_a_monte_carlo_estimate():
    cam = PinholeRadtan.davis240c()
    rng = np.random.default_rng(1)
    uv = np.column_stack([rng.uniform(5, cam.width - 6, 4000), rng.uniform(5, cam.height - 6, 4000)])
    noise = rng.normal(scale=0.05, size=uv.shape)  # small: the linearisation holds
    dxy = cam.unproject(uv + noise) - cam.unproject(uv)
    mc = np.sqrt(np.mean(np.sum(dxy**2, axis=1)) / 2) / 0.05 * np.sqrt(cam.fx * cam.fy)
    assert undistortion_noise_factor(cam) == pytest.approx(mc, rel=0.03)
    flat = dataclasses.replace(cam, k1=0.0, k2=0.0, p1=0.0, p2=0.0, k3=0.0, fy=cam.fx)
    assert undistortion_noise_factor(flat) == pytest.approx(1.0, abs=1e-6)
    cfg = experiment_msckf_config(VioSimConfig(pixel_noise_px=2.0, noise_model="global_factor"), camera=cam)
    assert cfg.pixel_noise_px == pytest.approx(2.0 * undistortion_noise_factor(cam))
    for model in ("per_observation", "nominal"):  # the default passes per-observation covariances instead
        assert experiment_msckf_config(VioSimConfig(pixel_noise_px=2.0, noise_model=model)).pixel_noise_px == 2.0
    cfg0 = experiment_msckf_config(VioSimConfig(pixel_noise_px=0.0, msckf_overrides={"max_camera_states": 10}))
    assert cfg0.pixel_noise_px == 0.1 and cfg0.max_camera_states == 10


def test_observation_covariance_against_finite_differences_and_the_simulator_noise_monte_carlo():
    cam = PinholeRadtan.davis240c()
    uv = np.array([[120.0, 90.0], [5.0, 5.0], [234.0, 174.0], [30.0, 150.0], [200.0, 20.0]])
    cov = observation_covariance(cam, uv, 1.5)
    h = 1e-3  # J = d(x, y)/d(u, v) of unproject by central differences
    J = np.stack([(cam.unproject(uv + d) - cam.unproject(uv - d)) / (2 * h) for d in ([h, 0.0], [0.0, h])], axis=2)
    np.testing.assert_allclose(cov, 1.5**2 * J @ np.swapaxes(J, 1, 2), rtol=1e-6)
    # the simulator's noise model: isotropic Gaussian pixel noise on the distorted pixels, then unproject
    rng = np.random.default_rng(7)
    n = 20000
    for k in range(len(uv)):
        xy = cam.unproject(uv[k] + 1.5 * rng.standard_normal((n, 2)))
        mc = np.cov(xy.T)
        np.testing.assert_allclose(mc, cov[k], atol=0.04 * np.abs(cov[k]).max())
    ratio = np.sqrt(cov[:, 0, 0] / cov[0, 0, 0])
    assert ratio[1] > 1.3 and ratio[2] > 1.3  # noise stretched at the corners by the undistortion
    flat = dataclasses.replace(cam, k1=0.0, k2=0.0, p1=0.0, p2=0.0, k3=0.0)
    np.testing.assert_allclose(observation_covariance(flat, uv, 2.0),
                               np.broadcast_to(np.diag([4.0 / cam.fx**2, 4.0 / cam.fy**2]), (5, 2, 2)), rtol=1e-9)
    assert observation_covariance(cam, np.zeros((0, 2)), 1.0).shape == (0, 2, 2)
    with pytest.raises(ValueError, match=r"uv must have shape \(N, 2\).*got \(2,\)"):
        observation_covariance(cam, np.zeros(2), 1.0)
    with pytest.raises(ValueError, match=r"sigma_px must be a finite number > 0"):
        observation_covariance(cam, uv, 0.0)


def test_per_observation_noise_passes_the_gate_at_the_nominal_rate_and_beats_the_nominal_model():
    """Same simulated data: with the per-observation covariances the chi-square gate rejects ~5 % of the features
    tried (its false-alarm rate), with the nominal isotropic σ far more, and the error is smaller."""
    results = {}
    for model in ("per_observation", "nominal"):
        config = VioSimConfig(duration=4.0, seed=2, features=40, noise_model=model)
        results[model] = run_vio_sim_config(config, baselines=False, data=simulate_data(config))
    per, nom = results["per_observation"], results["nominal"]
    assert per.rejections["chi2"] < 0.7 * nom.rejections["chi2"]
    assert per.metrics["rmse_m"] < nom.metrics["rmse_m"]


def test_command_line_parses_and_runs(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    add_vio_sim_arguments(parser)
    args = parser.parse_args(["aerial_like", "--duration", "3", "--seed", "4", "--features", "25",
                              "--no-observability-constrained", "--out", str(tmp_path / "run")])
    assert (args.preset, args.duration, args.seed, args.features, args.no_observability_constrained,
            args.imu_only) == \
        ("aerial_like", 3.0, 4, 25, True, False)
    defaults = parser.parse_args(["boxes_like"])
    assert defaults.duration is None and defaults.seed == 0 and defaults.features == 60
    assert not defaults.no_observability_constrained
    with pytest.raises(SystemExit):
        parser.parse_args(["mars_like"])
    args = parser.parse_args(["boxes_like", "--duration", "2", "--features", "20", "--no-baselines",
                              "--out", str(tmp_path / "run")])
    assert main_vio_sim(args) == 0
    printed = capsys.readouterr().out
    assert "MSCKF, OC on" in printed and "RMSE [m]" in printed and "% Error" in printed
    assert (tmp_path / "run" / "trajectory.txt").is_file() and (tmp_path / "run" / "groundtruth.txt").is_file()


def test_bad_input_raises_value_errors():
    with pytest.raises(ValueError, match=r"preset must be one of"):
        VioSimConfig(preset="mars_like")
    with pytest.raises(ValueError, match=r"duration must be None or a number of seconds >= 2; got 1.0"):
        VioSimConfig(duration=1.0)
    with pytest.raises(ValueError, match=r"features must be an integer >= 1; got 0"):
        VioSimConfig(features=0)
    with pytest.raises(ValueError, match=r"seed must be an integer >= 0"):
        VioSimConfig(seed=-1)
    with pytest.raises(ValueError, match=r"pixel_noise_px must be a finite number >= 0; got -1.0"):
        VioSimConfig(pixel_noise_px=-1.0)
    with pytest.raises(ValueError, match=r"observability_constrained must be True or False"):
        VioSimConfig(observability_constrained="yes")
    with pytest.raises(ValueError, match=r"frame_rate_hz must be <= imu_rate_hz"):
        VioSimConfig(frame_rate_hz=2000.0)
    with pytest.raises(ValueError, match=r"msckf_overrides must name MsckfConfig fields; got unknown \['n_max'\]"):
        VioSimConfig(msckf_overrides={"n_max": 5})
    with pytest.raises(ValueError, match=r"noise_model must be one of"):
        VioSimConfig(noise_model="exact")
    with pytest.raises(ValueError, match=r"max_track_length must be None or an integer >= 2"):
        VioSimConfig(max_track_length=1)
    with pytest.raises(ValueError, match=r"config must be a VioSimConfig"):
        run_vio_sim_config({"preset": "boxes_like"})
    with pytest.raises(ValueError, match=r"max_camera_states must be an integer >= 2"):  # MsckfConfig checks
        experiment_msckf_config(VioSimConfig(msckf_overrides={"max_camera_states": 0}))


def test_run_vio_sim_seeds_gives_the_same_runs_in_worker_processes():
    from evio_lib.msckf.experiment import run_vio_sim_seeds

    options = dict(preset="boxes_like", duration=2.0, features=30, baselines=False,
                   msckf_overrides={"init_sigma_velocity": 0.03})
    serial = run_vio_sim_seeds([3, 4, 5], jobs=1, **options)
    parallel = run_vio_sim_seeds([3, 4, 5], jobs=2, **options)
    assert [r.config.seed for r in parallel] == [3, 4, 5]
    for a, b in zip(serial, parallel):
        np.testing.assert_array_equal(a.p_est, b.p_est)
        np.testing.assert_array_equal(a.nees_pose, b.nees_pose)
    assert not np.array_equal(serial[0].p_est, serial[1].p_est)  # different seeds, different runs
    with pytest.raises(ValueError, match="jobs must be an integer >= 1"):
        run_vio_sim_seeds([1], jobs=0)
    with pytest.raises(ValueError, match="writes no files"):
        run_vio_sim_seeds([1, 2], out_dir="somewhere")
    with pytest.raises(ValueError, match="seeds must be non-negative integers; got \\[1.5\\]"):
        run_vio_sim_seeds([1.5])


def test_perfect_tracks_on_a_simulated_recording_use_its_own_imu_motion_and_frame_times():
    """simulated_data_from_recording: the recording's IMU samples and true biases, the simulator's trajectory made
    again from the recording's settings (its ground truth agrees), perfect tracks at its APS frame times; the filter
    on them stays close to the truth. A recording without simulator settings is refused, naming what is needed."""
    from evio_lib.msckf.experiment import run_vio_sim_config, simulated_data_from_recording
    from evio_lib.sequence import Sequence
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence

    seq = simulate_sequence(SimulationConfig(duration=2.0, seed=3, with_events=False, trajectory_duration=60.0))
    config = VioSimConfig("boxes_like", 2.0, seed=3)
    data = simulated_data_from_recording(seq, config)
    np.testing.assert_array_equal(data.imu.t, seq.imu.t)
    np.testing.assert_array_equal(data.imu.gyro, seq.imu.gyro)
    truth = data.trajectory.evaluate(seq.groundtruth_imu.t)
    assert np.max(np.abs(truth.p_IinG - seq.groundtruth_imu.p_BinG)) < 1e-9
    assert [f.t for f in data.frames] == list(seq.frame_times)
    tracked = run_vio_sim_config(config, baselines=False, data=data)
    imu_only = run_vio_sim_config(dataclasses.replace(config, imu_only=True), baselines=False, data=data)
    print(f"RMSE over 2 s: perfect tracks {tracked.metrics['rmse_m']:.3f} m, IMU only {imu_only.metrics['rmse_m']:.3f} m")
    assert tracked.metrics["rmse_m"] < 0.75 * imu_only.metrics["rmse_m"]
    with pytest.raises(ValueError, match="holds no simulator settings"):
        simulated_data_from_recording(Sequence(name="mine", imu=seq.imu, groundtruth_imu=seq.groundtruth_imu,
                                               frame_times=seq.frame_times, frames=seq.frames, camera=seq.camera))
    with pytest.raises(ValueError, match="differs from the recording's preset"):
        simulated_data_from_recording(seq, VioSimConfig("aerial_like", 2.0))


def test_vio_sim_runs_on_a_recording_folder_and_refuses_what_is_not_one(tmp_path, capsys):
    """vio-sim --recording DIR: the perfect tracks on a folder written by `simulate` (its length, its IMU); the
    preset must be the recording's, --duration is refused beside it, a folder of another kind names what it lacks."""
    from evio_lib.cli import main
    from evio_lib.io.ecd import write_ecd
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence

    folder = write_ecd(simulate_sequence(SimulationConfig(duration=2.0, with_events=False)), tmp_path / "rec")
    assert main(["vio-sim", "boxes_like", "--recording", str(folder), "--no-baselines", "--out",
                 str(tmp_path / "out")]) == 0
    assert "MSCKF, OC on" in capsys.readouterr().out
    t, _, _ = read_tum(tmp_path / "out" / "trajectory.txt")
    assert 1.9 < t[-1] <= 2.0  # the recording's length, not the preset's 60 s
    for argv, message in (
            (["aerial_like", "--recording", str(folder)], "is a boxes_like recording; run `vio-sim boxes_like"),
            (["boxes_like", "--recording", str(folder), "--duration", "3"], "the recording's own length is used"),
            (["boxes_like", "--recording", str(tmp_path / "none")], "no such folder"),
            (["boxes_like", "--recording", str(tmp_path / "out")], "is no folder written by `python -m evio_lib "
                                                                    "simulate boxes_like --out DIR`: events.txt")):
        assert main(["vio-sim", *argv]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: --") and message in err and err.count("\n") == 1, err
