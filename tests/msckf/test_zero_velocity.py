"""Standstill detection and the zero-velocity update (evio_lib.msckf.zero_velocity, Msckf.zero_velocity_update)."""
import numpy as np
import pytest

from evio_lib.geometry.rotation import quat_to_rot
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.filter import Msckf
from evio_lib.msckf.initialization import gravity_aligned_rotation, initial_state_from_truth
from evio_lib.msckf.state import BA, BG, THETA, VEL, FilterState, ImuState, inject_error
from evio_lib.msckf.zero_velocity import (
    StandstillDetector,
    ZeroVelocityConfig,
    imu_still_test,
    track_disparity,
    zero_velocity_measurement,
)

G = np.array([0.0, 0.0, -9.81])
RATE = 200.0


def _still_imu(seconds, R_ItoG, b_g, b_a, rng, accel_noise=0.02, gyro_noise=0.002, vibration=0.0):
    """Samples of a still IMU with attitude R_ItoG: a_m = -R_GtoI g + b_a + noise, ω_m = b_g + noise."""
    t = np.arange(0.0, seconds, 1.0 / RATE)
    n = len(t)
    a = np.tile(-R_ItoG.T @ G + b_a, (n, 1)) + accel_noise * rng.standard_normal((n, 3))
    a += vibration * np.sin(2 * np.pi * 80.0 * t)[:, None] * np.array([1.0, 0.7, 0.3])  # rotor shaking, mean 0
    w = np.tile(b_g, (n, 1)) + gyro_noise * rng.standard_normal((n, 3))
    return t, w, a


def test_accelerometer_rows_match_finite_differences():
    """H of the measurement equals the numerical derivative of h(x) = [v, b_g, -R_GtoI g + b_a] (whitened)."""
    rng = np.random.default_rng(3)
    R = gravity_aligned_rotation([0.3, -0.2, 9.7], yaw=0.4)
    imu = ImuState.from_pose(R, np.zeros(3), np.array([0.01, -0.02, 0.0]), 0.0, b_g=[0.01, 0.0, -0.01],
                             b_a=[0.05, -0.02, 0.1])
    state = FilterState.initial(imu, np.eye(3), np.zeros(3), np.eye(15))
    t, w, a = _still_imu(0.2, R, imu.b_g, imu.b_a, rng)
    cfg = ZeroVelocityConfig()
    H, r0 = zero_velocity_measurement(state, t, w, a, G, 1e-3, 1e-2, cfg)
    eps = 1e-6
    numeric = np.zeros_like(H)
    for k in range(15):
        dx = np.zeros(15)
        dx[k] = eps
        _, r1 = zero_velocity_measurement(inject_error(state, dx), t, w, a, G, 1e-3, 1e-2, cfg)
        numeric[:, k] = -(r1 - r0) / eps  # r = z - h(x): dr/dx = -dh/dx
    np.testing.assert_allclose(H, numeric, atol=1e-4 * np.abs(H).max())
    assert np.all(H[:, 12:15] == 0.0)  # position never enters


def test_yaw_stays_unobservable():
    """-[R g]x R g = 0: the update has no component along the yaw direction (rotation about gravity)."""
    R = gravity_aligned_rotation([0.5, 0.1, 9.7], yaw=1.0)
    imu = ImuState.from_pose(R, np.zeros(3), np.zeros(3), 0.0)
    state = FilterState.initial(imu, np.eye(3), np.zeros(3), np.eye(15))
    rng = np.random.default_rng(0)
    t, w, a = _still_imu(0.2, R, np.zeros(3), np.zeros(3), rng)
    H, _ = zero_velocity_measurement(state, t, w, a, G, 1e-3, 1e-2, ZeroVelocityConfig())
    yaw_direction = R.T @ np.array([0.0, 0.0, 1.0])  # δθ (in I) of a rotation about the world's z axis
    np.testing.assert_allclose(H[:, THETA] @ yaw_direction, 0.0, atol=1e-9)


def test_track_disparity_uses_shared_tracks_only():
    d, n = track_disparity([1, 2, 3, 4], [[0, 0]] * 4, [3, 4, 5], [[0, 3], [4, 0], [100, 100]])
    assert (d, n) == (3.5, 2)
    assert np.isnan(track_disparity([1], [[0, 0]], [2], [[0, 0]])[0])


@pytest.mark.parametrize("case, expected", [
    ("still", True),
    ("vibrating rotors", True),  # zero-mean shaking of 1 m/s^2 at 80 Hz averages out in 50 ms blocks
    ("turning", False),  # 0.05 rad/s about x
    ("accelerating", False),  # 1 m/s^2 along x
    ("wrong gravity", False),  # |a| = 9.81 * 1.1
])
def test_imu_still_test(case, expected):
    rng = np.random.default_rng(1)
    R = np.eye(3)
    t, w, a = _still_imu(0.25, R, np.zeros(3), np.zeros(3), rng, vibration=1.0 if case == "vibrating rotors" else 0.0)
    if case == "turning":
        w = w + np.array([0.05, 0.0, 0.0])
    if case == "accelerating":
        a = a + np.array([1.0, 0.0, 0.0])
    if case == "wrong gravity":
        a = a * 1.1
    assert imu_still_test(t, w, a, np.zeros(3), np.zeros(3), R.T, G, ZeroVelocityConfig())[0] is expected


def test_detector_needs_the_images_to_say_still():
    """A constant velocity looks still to the IMU; the tracks' motion, or the filter's speed, says otherwise."""
    rng = np.random.default_rng(2)
    t, w, a = _still_imu(1.0, np.eye(3), np.zeros(3), np.zeros(3), rng)
    ids = np.arange(30)
    px = rng.uniform(0, 200, (30, 2))
    det = StandstillDetector()
    still_imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), 0.0)
    moving_imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.array([0.5, 0.0, 0.0]), 0.0)
    assert not det.test(0.5, ids, px, t, w, a, still_imu, G).still  # no previous frame yet
    moving = det.test(0.55, ids, px + [2.0, 0.0], t, w, a, still_imu, G)
    assert not moving.still and moving.disparity_px == pytest.approx(2.0)
    still = det.test(0.6, ids, px + [2.1, 0.0], t, w, a, still_imu, G)
    assert still.still and still.shared_tracks == 30
    fast = det.test(0.65, ids, px + [2.1, 0.0], t, w, a, moving_imu, G)
    assert not fast.still  # the filter believes it moves at 0.5 m/s
    few = det.test(0.7, ids[:5], px[:5] + [2.1, 0.0], t, w, a, still_imu, G)
    assert not few.still and few.shared_tracks == 5  # too few tracks to judge
    off = StandstillDetector(ZeroVelocityConfig(enabled=False))
    off.test(0.5, ids, px, t, w, a, still_imu, G)
    assert not off.test(0.55, ids, px, t, w, a, still_imu, G).still


@pytest.mark.parametrize("bad", [dict(max_disparity_px=0.0), dict(min_tracks=0), dict(velocity_sigma=-1.0),
                                 dict(chi2_probability=1.0), dict(enabled="yes"), dict(imu_window=float("nan"))])
def test_bad_settings_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ZeroVelocityConfig(**bad)


def _filter(R, b_g, v0, P_scale=1.0):
    cfg = MsckfConfig(gyro_noise_density=2e-4, accel_noise_density=2e-3)
    state = initial_state_from_truth(0.0, R, np.zeros(3), v0, np.eye(3), np.zeros(3), cfg, b_g=b_g)
    return Msckf(cfg, state), cfg


def test_zero_velocity_updates_hold_a_still_platform():
    """Still IMU with a wrong velocity and gyro bias at the start: the updates pull both to the truth, the position
    stays within millimetres, yaw's variance does not shrink; without them the position drifts."""
    rng = np.random.default_rng(4)
    R = gravity_aligned_rotation([0.2, -0.1, 9.8], yaw=0.7)
    b_g_true, b_a_true = np.array([0.003, -0.002, 0.004]), np.zeros(3)
    t, w, a = _still_imu(3.0, R, b_g_true, b_a_true, rng, accel_noise=0.01, gyro_noise=0.001)
    zv = ZeroVelocityConfig()
    results = {}
    for use in (True, False):
        filt, cfg = _filter(R, np.zeros(3), np.array([0.03, -0.02, 0.0]))
        filt.feed_imu(t[1:], w[1:], a[1:])
        yaw_dir = R.T @ np.array([0.0, 0.0, 1.0])
        yaw_var0 = yaw_dir @ filt.state.P[THETA, THETA] @ yaw_dir
        for tf in np.arange(0.05, 2.95, 0.05):
            out = filt.zero_velocity_update(tf, zv) if use else None
            if out is None:
                filt._propagate_to(float(tf))
        results[use] = filt.state
        if use:
            yaw_var = yaw_dir @ filt.state.P[THETA, THETA] @ yaw_dir
            assert yaw_var >= 0.999 * yaw_var0  # unobservable: not reduced by the update (grows by propagation)
            assert filt.rejections.get("zupt_gate", 0) == 0
    held, free = results[True], results[False]
    assert np.linalg.norm(held.imu.v_IinG) < 0.005
    np.testing.assert_allclose(held.imu.b_g, b_g_true, atol=5e-4)
    assert np.linalg.norm(held.imu.p_IinG) < 0.01
    assert np.linalg.norm(free.imu.p_IinG) > 5 * np.linalg.norm(held.imu.p_IinG)


def test_a_moving_platform_fails_the_gate():
    """The gate (a safety net behind the detector): accelerating at 2 m/s^2 is not standing still."""
    rng = np.random.default_rng(5)
    R = np.eye(3)
    t, w, a = _still_imu(1.0, R, np.zeros(3), np.zeros(3), rng)
    a = a + np.array([2.0, 0.0, 0.0])
    filt, _ = _filter(R, np.zeros(3), np.zeros(3))
    filt.feed_imu(t[1:], w[1:], a[1:])
    before = filt.state.imu.v_IinG.copy()
    assert filt.zero_velocity_update(0.5, ZeroVelocityConfig()) is None
    assert filt.rejections["zupt_gate"] == 1
    assert filt.state.timestamp == 0.5 and not np.allclose(filt.state.imu.v_IinG, before)  # propagated only
    with pytest.raises(ValueError, match="images in order"):
        filt.zero_velocity_update(0.2, ZeroVelocityConfig())
