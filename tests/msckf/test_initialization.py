"""Tests for evio_lib.msckf.initialization: the gravity-aligned rotation against scipy's Euler angles, static
initialisation on synthetic rest data (attitude up to yaw, gyro bias) and its rejection of moving windows (simulator
trajectories), initial states from truth (exact, and Monte-Carlo draws with the requested covariance), and on the real
EuRoC V1_01_easy slice: gyro bias and gravity direction against the ground truth, and IMU-only dead reckoning with the
ground-truth biases (figures in the assertions)."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import quat_to_rot
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.initialization import (
    gravity_aligned_rotation,
    initial_state_from_static,
    initial_state_from_truth,
    static_initialization,
)
from evio_lib.msckf.propagation import integrate_imu
from evio_lib.msckf.state import ImuState, state_difference
from evio_lib.sim.imu import ImuNoiseParams, synthesize_imu
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.trajectory import trajectory_from_preset

G = np.array([0.0, 0.0, -9.81])


def rest_imu(rng, R_ItoG, b_g, b_a, duration=1.0, rate=1000.0, noise=ImuNoiseParams()):
    """IMU samples of a rig at rest: ω_m = b_g + n_g, a_m = R_GtoI (0 - g) + b_a + n_a (no simulator involved)."""
    t = np.arange(0.0, duration, 1.0 / rate)
    n = len(t)
    gyro = b_g + noise.gyro_noise_density * np.sqrt(rate) * rng.standard_normal((n, 3))
    accel = R_ItoG.T @ -G + b_a + noise.accel_noise_density * np.sqrt(rate) * rng.standard_normal((n, 3))
    return t, gyro, accel


def tilt_deg(R_GtoI_a, R_GtoI_b):
    """Angle between the world up axis seen in I by two attitudes (yaw-free attitude error), degrees."""
    up_a, up_b = R_GtoI_a @ [0.0, 0.0, 1.0], R_GtoI_b @ [0.0, 0.0, 1.0]
    return float(np.degrees(np.arccos(np.clip(up_a @ up_b, -1.0, 1.0))))


# ---------------------------------------------------------------- gravity-aligned rotation


def test_gravity_aligned_rotation_matches_scipy_zyx_euler_angles(rng):
    for _ in range(20):
        yaw, pitch, roll = rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi)
        R_ItoG = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        up_I = R_ItoG.T @ [0.0, 0.0, 3.0]
        np.testing.assert_allclose(gravity_aligned_rotation(up_I, yaw), R_ItoG, atol=1e-12)
        R0 = gravity_aligned_rotation(up_I)
        np.testing.assert_allclose(Rotation.from_matrix(R0).as_euler("ZYX")[0], 0.0, atol=1e-12)
    # I's x axis vertical (pitch ±90 deg): still a rotation with the right up axis
    R = gravity_aligned_rotation([-2.0, 0.0, 0.0])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R.T @ [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], atol=1e-12)


# ---------------------------------------------------------------- static initialisation, synthetic


def test_static_initialization_recovers_attitude_and_gyro_bias_at_rest(rng):
    R_ItoG = Rotation.from_euler("ZYX", [0.7, 0.3, -0.4]).as_matrix()
    b_g, b_a = np.array([0.02, -0.03, 0.01]), np.zeros(3)
    t, gyro, accel = rest_imu(rng, R_ItoG, b_g, b_a, duration=1.0)
    q, bg_est, stats = static_initialization(t, gyro, accel, duration=1.0, yaw=0.7)
    # gyro bias: mean of 1000 samples of std 2.8e-3 rad/s -> ~1e-4
    np.testing.assert_allclose(bg_est, b_g, atol=4e-4)
    R_est = quat_to_rot(q)  # R_GtoI
    assert tilt_deg(R_est, R_ItoG.T) < 0.05
    angle = np.degrees(Rotation.from_matrix(R_est @ R_ItoG).magnitude())  # yaw given: whole rotation
    assert angle < 0.05
    assert stats.n_samples == 1000 and abs(stats.gravity_error) < 0.05
    np.testing.assert_allclose(stats.up_I, R_ItoG.T @ [0.0, 0.0, 1.0], atol=1e-3)


def test_accelerometer_bias_tilts_the_estimate_by_about_ba_over_g(rng):
    R_ItoG = np.eye(3)
    b_a = np.array([0.15, 0.0, 0.0])  # horizontal bias: tilt ≈ 0.15 / 9.81 rad
    t, gyro, accel = rest_imu(rng, R_ItoG, np.zeros(3), b_a, noise=ImuNoiseParams.noise_free())
    q, _, _ = static_initialization(t, gyro, accel, duration=1.0)
    assert tilt_deg(quat_to_rot(q), np.eye(3)) == pytest.approx(np.degrees(np.arctan(0.15 / 9.81)), rel=1e-6)


@pytest.mark.parametrize("preset", ["boxes_like", "aerial_like"])
def test_moving_windows_are_rejected(rng, preset):
    traj = trajectory_from_preset(preset, duration=10.0, seed=3)
    imu = synthesize_imu(traj, 500.0, ImuNoiseParams(), rng, t_start=4.0, t_end=6.0)
    with pytest.raises(ValueError, match=r"the IMU window is not static"):
        static_initialization(imu.t, imu.gyro, imu.accel, duration=1.5)


def test_static_initialization_rejects_bad_inputs(rng):
    t, gyro, accel = rest_imu(rng, np.eye(3), np.zeros(3), np.zeros(3), duration=0.5)
    with pytest.raises(ValueError, match=r"must hold >= 10 IMU samples; got 5"):
        static_initialization(t, gyro, accel, duration=0.004)
    with pytest.raises(ValueError, match=r"gyro and accel must have shape \(M, 3\)"):
        static_initialization(t, gyro[:, :2], accel)
    with pytest.raises(ValueError, match=r"imu_t must be strictly increasing"):
        static_initialization(t[::-1], gyro, accel)
    with pytest.raises(ValueError, match=r"duration must be a finite number > 0"):
        static_initialization(t, gyro, accel, duration=-1.0)
    with pytest.raises(ValueError, match=r"\|mean accel\| = 4.905"):
        static_initialization(t, gyro, accel * 0.5)  # a "static" window with the wrong gravity
    with pytest.raises(ValueError, match=r"up_I must be non-zero"):
        gravity_aligned_rotation(np.zeros(3))


# ---------------------------------------------------------------- initial states


def test_initial_state_from_truth_is_exact_or_drawn_with_the_given_covariance(rng):
    cfg = MsckfConfig()
    ext = CameraImuExtrinsics.default()
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    s = initial_state_from_truth(2.0, R, [1.0, 2.0, 3.0], [0.5, 0.0, 0.0], ext.R_CtoI, ext.p_CinI, cfg,
                                 b_g=[0.01, 0.0, 0.0])
    np.testing.assert_allclose(s.imu.R_ItoG, R, atol=1e-12)
    assert s.timestamp == 2.0 and s.num_cameras == 0
    np.testing.assert_array_equal(s.P, cfg.initial_imu_covariance())
    # Monte Carlo: the error truth - estimate has covariance P_imu (and zero mean)
    P = np.diag(np.linspace(0.01, 0.2, 15) ** 2)
    errors = np.array([
        state_difference(s, initial_state_from_truth(2.0, R, [1.0, 2.0, 3.0], [0.5, 0.0, 0.0], ext.R_CtoI,
                                                     ext.p_CinI, cfg, b_g=[0.01, 0.0, 0.0], P_imu=P, rng=rng))
        for _ in range(800)
    ])
    sd = np.sqrt(np.diag(P))
    np.testing.assert_allclose(errors.std(axis=0) / sd, 1.0, atol=0.12)
    assert np.all(np.abs(errors.mean(axis=0)) < 4 * sd / np.sqrt(800))
    drawn = initial_state_from_truth(2.0, R, np.zeros(3), np.zeros(3), ext.R_CtoI, ext.p_CinI, cfg, rng=1)
    np.testing.assert_array_equal(drawn.imu.p_IinG_null, drawn.imu.p_IinG)  # first estimates = the estimate
    with pytest.raises(ValueError, match=r"P_imu must have shape \(15, 15\)"):
        initial_state_from_truth(0.0, R, np.zeros(3), np.zeros(3), ext.R_CtoI, ext.p_CinI, cfg, P_imu=np.eye(3))
    with pytest.raises(ValueError, match=r"config must be an MsckfConfig"):
        initial_state_from_truth(0.0, R, np.zeros(3), np.zeros(3), ext.R_CtoI, ext.p_CinI, None)


def test_initial_state_from_static_starts_at_rest_at_the_window_end(rng):
    cfg = MsckfConfig(static_init_duration=0.5)
    ext = CameraImuExtrinsics.default()
    R_ItoG = Rotation.from_euler("ZYX", [0.0, 0.2, 0.1]).as_matrix()
    t, gyro, accel = rest_imu(rng, R_ItoG, np.array([0.01, 0.02, -0.01]), np.zeros(3), duration=2.0)
    s, stats = initial_state_from_static(t, gyro, accel, ext.R_CtoI, ext.p_CinI, cfg, p_IinG=[1.0, 0.0, 0.0])
    assert s.timestamp == stats.t_end == pytest.approx(0.5)
    np.testing.assert_array_equal(s.imu.v_IinG, np.zeros(3))
    np.testing.assert_array_equal(s.imu.p_IinG, [1.0, 0.0, 0.0])
    assert tilt_deg(s.imu.R_GtoI, R_ItoG.T) < 0.1
    np.testing.assert_allclose(s.imu.b_g, [0.01, 0.02, -0.01], atol=6e-4)


# ---------------------------------------------------------------- real data: EuRoC V1_01_easy (MAV on the ground)


@pytest.fixture
def euroc(real_data_dir):
    from evio_lib.io.euroc import read_euroc

    folder = real_data_dir / "euroc_V1_01_easy_micro"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    return read_euroc(folder, load_frames=False)


def test_static_initialization_on_euroc_matches_the_ground_truth(euroc):
    """First 1.5 s: the MAV stands with spinning rotors (raw accel std ~1 m/s^2). Measured: gyro bias error
    1.5e-3 rad/s (bias ~0.08 rad/s), gravity direction (roll/pitch) 0.56 deg from the ground-truth attitude (0.19
    deg when the ground-truth accelerometer bias is removed first: the rest is b_a / g)."""
    imu, gt = euroc.imu, euroc.groundtruth_imu
    q, b_g, stats = static_initialization(imu.t, imu.gyro, imu.accel, duration=1.5)
    i = int(np.searchsorted(gt.t, stats.t_start))
    assert np.linalg.norm(b_g - gt.bias_gyro[i]) < 3e-3
    assert np.linalg.norm(gt.bias_gyro[i]) > 0.05  # the bias is large, so the check means something
    R_gt = quat_to_rot(gt.interpolate([stats.t_start]).q_GtoB[0])  # R_GtoI of the ground truth
    assert tilt_deg(quat_to_rot(q), R_gt) < 1.0
    # the tilt is the roll/pitch error free of the (unobservable, arbitrary) yaw; ZYX Euler roll and pitch are not
    # compared one by one because the EuRoC IMU's x axis points almost up (pitch -68 deg), where they are
    # ill-conditioned. The gravity direction seen in I agrees component-wise too:
    up_gt_I = R_gt @ [0.0, 0.0, 1.0]
    np.testing.assert_allclose(stats.up_I, up_gt_I, atol=np.radians(1.0))
    # after take-off (t > 8 s) the window is rejected
    with pytest.raises(ValueError, match=r"not static"):
        static_initialization(imu.t, imu.gyro, imu.accel, duration=3.0, t_start=imu.t[0] + 8.0)


def test_imu_only_dead_reckoning_on_euroc_with_ground_truth_biases(euroc):
    """From the ground-truth state with ground-truth biases: position error 0.09 m after 2 s and 0.76 m after 5 s
    (without bias correction: 1.1 m and 16 m)."""
    imu, gt = euroc.imu, euroc.groundtruth_imu
    t0 = imu.t[0]
    g0 = gt.interpolate([t0])
    errors = {}
    for name, b_g, b_a in (("gt", gt.bias_gyro[0], gt.bias_accel[0]), ("none", np.zeros(3), np.zeros(3))):
        start = ImuState(g0.q_GtoB[0], b_g, g0.v_BinG[0], b_a, g0.p_BinG[0], t0)
        m = imu.t <= t0 + 5.0 + 1e-9
        _, _, p = integrate_imu(start, imu.t[m], imu.gyro[m], imu.accel[m], G)
        for T in (2.0, 5.0):
            k = int(np.searchsorted(imu.t[m], t0 + T - 1e-9))
            errors[name, T] = float(np.linalg.norm(p[k] - gt.interpolate([imu.t[m][k]]).p_BinG[0]))
    assert errors["gt", 2.0] < 0.2 and errors["gt", 5.0] < 1.5
    assert errors["none", 5.0] > 5 * errors["gt", 5.0]
