"""Tests of evio_lib.frontend.gyro_prior against the simulator's exact orientations."""
import numpy as np
import pytest

from evio_lib.frontend.gyro_prior import camera_rotation_prior, camera_rotation_priors, integrate_gyro
from evio_lib.geometry.rotation import so3_exp, so3_log
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.trajectory import trajectory_from_preset


@pytest.fixture(scope="module")
def motion():
    """The violent end of boxes_like (up to ~200 deg/s), sampled at 1 kHz like the DAVIS IMU."""
    trajectory = trajectory_from_preset("boxes_like", seed=0)
    t = np.arange(55.0, 56.0, 0.001)
    return t, trajectory.evaluate(t)


@pytest.mark.parametrize("t0, t1", [(55.1003, 55.1420), (55.5, 55.5), (55.2, 55.7)])
def test_integrated_gyro_matches_the_true_relative_rotation(motion, t0, t1):
    t, sample = motion
    R_ItoG = sample.R_ItoG
    i0, i1 = np.searchsorted(t, [t0, t1])  # frame times between samples: interpolate the truth at the sample grid
    R_true = R_ItoG[i1].T @ R_ItoG[i0]  # R_I0toI1 = R_ItoG(t1)^T R_ItoG(t0) at the nearest later samples
    R = integrate_gyro(t, sample.w_I, t[i0], t[i1])
    angle_error = np.linalg.norm(so3_log(R.T @ R_true))
    assert angle_error < 2e-6  # 1 kHz, trapezoidal rates: O(dt^2) per step


def test_camera_rotation_prior_matches_the_camera_poses(motion):
    t, sample = motion
    extrinsics = CameraImuExtrinsics.default()
    R_CtoG, _ = extrinsics.camera_pose(sample.R_ItoG, sample.p_IinG)
    i0, i1 = 100, 142  # one frame interval at 24 Hz
    R_true = R_CtoG[i1].T @ R_CtoG[i0]  # R_C0toC1 = R_GtoC1 R_C0toG
    R = camera_rotation_prior(t, sample.w_I, t[i0], t[i1], extrinsics.R_CtoI)
    assert np.linalg.norm(so3_log(R_true)) > 0.05  # a real rotation (> 3 deg)
    assert np.linalg.norm(so3_log(R.T @ R_true)) < 2e-6


def test_priors_of_a_frame_sequence(motion):
    t, sample = motion
    extrinsics = CameraImuExtrinsics.default()
    R_CtoG, _ = extrinsics.camera_pose(sample.R_ItoG, sample.p_IinG)
    frames = np.arange(0, 1000, 42)  # 24 Hz frames on sample times
    priors = camera_rotation_priors(t, sample.w_I, t[frames], extrinsics.R_CtoI)
    assert priors.shape == (len(frames), 3, 3) and np.array_equal(priors[0], np.eye(3))
    for k in range(1, len(frames)):
        R_true = R_CtoG[frames[k]].T @ R_CtoG[frames[k - 1]]
        assert np.linalg.norm(so3_log(priors[k].T @ R_true)) < 1e-5  # 2e-3 px at f = 199 px
    with pytest.raises(ValueError, match="frame_times"):
        camera_rotation_priors(t, sample.w_I, [0.2, 0.1], extrinsics.R_CtoI)


def test_bias_is_subtracted_and_inputs_are_not_modified():
    t = np.linspace(0.0, 1.0, 201)
    w = np.tile([0.1, -0.2, 0.3], (201, 1))
    w_before = w.copy()
    R = integrate_gyro(t, w, 0.1, 0.6, gyro_bias=[0.1, -0.2, 0.3])
    np.testing.assert_allclose(R, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(integrate_gyro(t, w, 0.1, 0.6), so3_exp([0.05, -0.1, 0.15]).T, atol=1e-12)
    np.testing.assert_array_equal(w, w_before)


def test_frames_outside_the_samples_hold_the_end_rates():
    t = np.array([1.0, 2.0])
    w = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(integrate_gyro(t, w, 0.0, 3.0), so3_exp([0.0, 0.0, -3.0]), atol=1e-12)


@pytest.mark.parametrize(
    "args, message",
    [
        ((np.zeros(3), np.zeros((2, 3)), 0.0, 1.0), "shape"),
        ((np.array([0.0, 0.0]), np.zeros((2, 3)), 0.0, 1.0), "strictly increasing"),
        ((np.array([0.0, 1.0]), np.full((2, 3), np.nan), 0.0, 1.0), "finite"),
        ((np.array([0.0, 1.0]), np.zeros((2, 3)), 1.0, 0.5), "t1 must be >= t0"),
        ((np.array([0.0, 1.0]), np.zeros((2, 3)), float("nan"), 0.5), "t0"),
    ],
)
def test_bad_input(args, message):
    with pytest.raises(ValueError, match=message):
        integrate_gyro(*args)
    with pytest.raises(ValueError, match="gyro_bias"):
        integrate_gyro(np.array([0.0, 1.0]), np.zeros((2, 3)), 0.0, 1.0, gyro_bias=[1.0, 2.0])
    with pytest.raises(ValueError, match="R_CtoI"):
        camera_rotation_prior(np.array([0.0, 1.0]), np.zeros((2, 3)), 0.0, 1.0, np.ones((3, 3)))
