"""Tests for evio_lib.msckf.config: defaults, validation, derived matrices, printing and round trips."""
import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from evio_lib.msckf.config import MsckfConfig


def test_defaults_are_valid_and_the_measured_choices():
    """Window of 40 with the oldest third marginalised (Mourikis & Roumeliotis 2007): the settings the Monte-Carlo
    runs found consistent (config docstring); S-MSCKF's 20 / two-way remain one replace() away. Gate 95 %."""
    cfg = MsckfConfig()
    assert cfg.max_camera_states == 40
    assert cfg.min_track_length == 3
    assert cfg.chi2_probability == 0.95 and cfg.chi2_gating is True
    assert cfg.observability_constrained is True and cfg.marginalize_third is True
    s_msckf = dataclasses.replace(cfg, max_camera_states=20, marginalize_third=False, chi2_probability=0.95)
    assert s_msckf.chi2_threshold(1) == pytest.approx(3.841, abs=1e-3)
    assert cfg.gravity_G == (0.0, 0.0, -9.81)
    np.testing.assert_array_equal(cfg.gravity, [0.0, 0.0, -9.81])


def test_str_prints_every_parameter_one_per_line_with_its_value():
    cfg = MsckfConfig(max_camera_states=11, pixel_noise_px=0.7)
    lines = str(cfg).splitlines()
    names = [f.name for f in dataclasses.fields(MsckfConfig)]
    assert lines[0] == "MsckfConfig"
    assert len(lines) == 1 + len(names)
    for line, name in zip(lines[1:], names):
        assert line.split()[0] == name and " = " in line
    assert any(line.split()[:3] == ["max_camera_states", "=", "11"] for line in lines)
    assert any(line.split()[:3] == ["pixel_noise_px", "=", "0.7"] for line in lines)


def test_continuous_noise_psd_follows_the_noise_vector_order():
    cfg = MsckfConfig(gyro_noise_density=1.0, gyro_random_walk=2.0, accel_noise_density=3.0, accel_random_walk=4.0)
    # n_IMU = [n_g, n_wg, n_a, n_wa] (thesis Eq. 33)
    np.testing.assert_array_equal(cfg.continuous_noise_psd(), np.repeat([1.0, 4.0, 9.0, 16.0], 3))


def test_initial_imu_covariance_follows_the_error_state_order():
    cfg = MsckfConfig(init_sigma_attitude=1.0, init_sigma_gyro_bias=2.0, init_sigma_velocity=3.0,
                      init_sigma_accel_bias=4.0, init_sigma_position=5.0)
    P0 = cfg.initial_imu_covariance()
    assert P0.shape == (15, 15)
    # [δθ, δb_g, δv, δb_a, δp] (thesis Eq. 22)
    np.testing.assert_array_equal(P0, np.diag(np.repeat([1.0, 4.0, 9.0, 16.0, 25.0], 3)))


def test_feature_noise_sigma_is_pixels_over_focal_length():
    assert MsckfConfig(pixel_noise_px=2.0, focal_length_px=400.0).feature_noise_sigma == pytest.approx(0.005)


def test_chi2_threshold_is_the_upper_quantile_from_scipy():
    cfg = MsckfConfig()
    for dof in (1, 2, 7, 30):
        assert cfg.chi2_threshold(dof) == pytest.approx(chi2.ppf(0.95, dof), rel=1e-12)
    assert cfg.chi2_threshold(2) > 5.9  # not msckf_vio's 5 % quantile (0.103 for 2 DoF)
    with pytest.raises(ValueError, match="dof must be a positive integer"):
        cfg.chi2_threshold(0)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"gyro_noise_density": -1e-3}, "gyro_noise_density must be >= 0"),
        ({"accel_random_walk": float("nan")}, "accel_random_walk must be finite"),
        ({"pixel_noise_px": 0.0}, "pixel_noise_px must be > 0"),
        ({"chi2_probability": 1.0}, r"chi2_probability must lie in \(0, 1\)"),
        ({"keyframe_tracking_rate_threshold": 1.5}, r"keyframe_tracking_rate_threshold must lie in \[0, 1\]"),
        ({"max_camera_states": 1}, "max_camera_states must be an integer >= 2"),
        ({"max_camera_states": 20.0}, "max_camera_states must be an integer"),
        ({"min_track_length": 45}, "min_track_length must be <= max_camera_states"),
        ({"triangulation_max_iterations": 0}, "triangulation_max_iterations must be an integer >= 1"),
        ({"triangulation_min_depth": 5.0, "triangulation_max_depth": 1.0}, "triangulation_min_depth must be <"),
        ({"chi2_gating": "yes"}, "chi2_gating must be True or False"),
        ({"gravity_G": (0.0, -9.81)}, r"gravity_G must be 3 finite numbers .* shape \(3,\); got shape \(2,\)"),
        ({"focal_length_px": "200"}, "focal_length_px must be a real number"),
    ],
)
def test_bad_values_raise_value_error_naming_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        MsckfConfig(**changes)


def test_config_is_frozen_and_replace_revalidates():
    cfg = MsckfConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.max_camera_states = 5  # type: ignore[misc]
    assert dataclasses.replace(cfg, max_camera_states=5).max_camera_states == 5
    with pytest.raises(ValueError, match="max_camera_states"):
        dataclasses.replace(cfg, max_camera_states=-5)


def test_dict_round_trip_and_unknown_keys():
    cfg = MsckfConfig(max_camera_states=12, gravity_G=(0.0, 0.0, -9.80665), observability_constrained=False)
    back = MsckfConfig.from_dict(cfg.to_dict())
    assert back == cfg
    with pytest.raises(ValueError, match="unexpected"):
        MsckfConfig.from_dict({"n_max": 3})


def test_with_imu_noise_copies_the_simulator_densities():
    from evio_lib.sim.imu import ImuNoiseParams

    noise = ImuNoiseParams(gyro_noise_density=1e-3, accel_noise_density=2e-2, gyro_random_walk=3e-4,
                           accel_random_walk=4e-3, gyro_bias_init_sigma=0.01, accel_bias_init_sigma=0.05)
    cfg = MsckfConfig().with_imu_noise(noise)
    assert (cfg.gyro_noise_density, cfg.accel_noise_density, cfg.gyro_random_walk, cfg.accel_random_walk) == (
        1e-3, 2e-2, 3e-4, 4e-3)
    assert (cfg.init_sigma_gyro_bias, cfg.init_sigma_accel_bias) == (0.01, 0.05)
    assert MsckfConfig().with_imu_noise(noise, include_bias_sigmas=False).init_sigma_gyro_bias == 0.03
    with pytest.raises(ValueError, match="noise must have attributes"):
        MsckfConfig().with_imu_noise(object())


def test_retired_options_are_gone_and_refused_by_name():
    """The update-side OC has one form (the projected one) and far points no starvation or scene-depth test: their
    fields are gone, and a dict that still names one is refused with its name (docs/archive.md has their numbers)."""
    from dataclasses import fields

    names = {f.name for f in fields(MsckfConfig)}
    for retired, value in (("oc_update", "eq86"), ("far_point_starvation", 2.0), ("far_point_scene_depth", 50.0)):
        assert retired not in names
        with pytest.raises(ValueError, match=retired):
            MsckfConfig.from_dict({retired: value})
    assert "far_point_fallback" in names and "observability_constrained" in names


def test_triangulation_settings_are_the_filters_and_drive_triangulate_inverse_depth():
    """The keyword arguments Msckf passes to the triangulation; an RMS residual above the configured pixels fails."""
    from evio_lib.msckf.filter import Msckf
    from evio_lib.msckf.initialization import initial_state_from_truth
    from evio_lib.msckf.triangulation import triangulate_inverse_depth

    cfg = MsckfConfig(triangulation_max_reprojection_px=2.0, focal_length_px=200.0, triangulation_max_iterations=7)
    settings = cfg.triangulation_settings()
    assert settings == dict(max_iterations=7, step_tol=cfg.triangulation_tolerance,
                            min_baseline_ratio=cfg.triangulation_min_baseline_ratio,
                            min_depth=cfg.triangulation_min_depth, max_depth=cfg.triangulation_max_depth,
                            max_rms_residual=0.01)
    s0 = initial_state_from_truth(0.0, np.eye(3), np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), cfg)
    assert Msckf(cfg, s0)._updater.triangulation_settings == settings  # the filter's own settings
    R = np.stack([np.eye(3)] * 3)
    p = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.1, 0.0]])
    point = np.array([0.3, -0.2, 4.0])
    obs = (point - p)[:, :2] / (point - p)[:, 2:]
    assert triangulate_inverse_depth(R, p, obs, **settings).success
    noisy = obs + np.array([[0.0, 0.0], [0.03, 0.0], [-0.03, 0.02]])  # a few pixels at f = 200 px: RMS > 2 px
    assert triangulate_inverse_depth(R, p, noisy, **settings).reason == "large_residual"
