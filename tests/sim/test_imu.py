"""Tests of evio_lib.sim.imu: IMU synthesis (measurement model, noise statistics) and the RK4 strapdown integrator."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import so3_exp, so3_log
from evio_lib.sim.imu import (
    GRAVITY_G,
    MEMS_ACCEL_FULL_SCALE,
    MEMS_GYRO_FULL_SCALE,
    ImuData,
    ImuNoiseParams,
    integrate_imu_rk4,
    synthesize_imu,
)
from evio_lib.sim.trajectory import Trajectory, TrajectorySample, aerial_like, boxes_like

BOXES = boxes_like(duration=60.0, seed=0)
AERIAL = aerial_like(duration=40.0, seed=0)


class _SpinAndAccelerate(Trajectory):
    """Closed-form test trajectory: constant spin w about a fixed axis, constant acceleration a0 from rest at p0.

    R_ItoG(t) = R0 exp([w t x]) (so w_I = w, dw_I = 0), p_IinG = p0 + a0 t^2 / 2.
    """

    def __init__(self, R0, w, a0, p0=(0.0, 0.0, 0.0), duration=10.0):
        self.R0, self.w, self.a0, self.p0 = np.asarray(R0), np.asarray(w), np.asarray(a0), np.asarray(p0)
        self.t_start, self.t_end = 0.0, duration

    def evaluate(self, t):
        t = self._check_times(t)
        n = t.shape[0]
        return TrajectorySample(
            t=t,
            p_IinG=self.p0 + 0.5 * t[:, None] ** 2 * self.a0,
            v_IinG=t[:, None] * self.a0,
            a_IinG=np.broadcast_to(self.a0, (n, 3)).copy(),
            R_ItoG=self.R0 @ so3_exp(t[:, None] * self.w),
            w_I=np.broadcast_to(self.w, (n, 3)).copy(),
            dw_I=np.zeros((n, 3)),
        )


STATIC = _SpinAndAccelerate(np.eye(3), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], duration=400.0)


def _integration_errors(traj, t_start, t_end, rate_hz, midpoint="linear"):
    """Return (max position error m, max velocity error m/s, max attitude error rad) of noise-free RK4 vs truth."""
    imu = synthesize_imu(traj, rate_hz=rate_hz, noise=None, t_start=t_start, t_end=t_end)
    s0 = traj.evaluate(t_start)
    R, p, v = integrate_imu_rk4(imu, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], midpoint=midpoint)
    truth = traj.evaluate(imu.t)
    e_p = np.linalg.norm(p - truth.p_IinG, axis=1).max()
    e_v = np.linalg.norm(v - truth.v_IinG, axis=1).max()
    e_R = np.linalg.norm(so3_log(np.swapaxes(R, 1, 2) @ truth.R_ItoG), axis=1).max()
    return e_p, e_v, e_R


# ------------------------------------------------------------------------------------------------ measurement model
def test_noise_free_measurements_match_closed_form():
    """Spin + acceleration: gyro = w exactly, accel = R_GtoI (a0 - g) with R from scipy."""
    R0 = Rotation.from_rotvec([0.3, -0.5, 1.0]).as_matrix()
    w, a0 = np.array([0.2, -1.0, 0.5]), np.array([1.0, -2.0, 0.5])
    traj = _SpinAndAccelerate(R0, w, a0, duration=2.0)
    imu = synthesize_imu(traj, rate_hz=100.0, noise=None)
    assert len(imu) == 201 and imu.t[0] == 0.0 and imu.t[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(imu.gyro, np.broadcast_to(w, (201, 3)), atol=1e-15)
    R_ItoG = R0 @ Rotation.from_rotvec(imu.t[:, None] * w).as_matrix()
    expected = np.einsum("nji,j->ni", R_ItoG, a0 - np.array([0.0, 0.0, -9.81]))
    np.testing.assert_allclose(imu.accel, expected, atol=1e-12)
    assert np.all(imu.bias_gyro == 0) and np.all(imu.bias_accel == 0)


def test_readings_saturate_at_the_full_scale_per_axis():
    """A spin of 3000 deg/s about z and 20 g along x: the readings clip at ±2000 deg/s and ±16 g, per axis; the
    axes within range and the run without limits are untouched (noise and bias included before the clip)."""
    w, a0 = np.array([0.0, 0.1, np.radians(3000.0)]), np.array([20.0 * 9.80665, 0.0, 0.0])
    traj = _SpinAndAccelerate(np.eye(3), w, a0, duration=0.1)
    free = synthesize_imu(traj, rate_hz=1000.0, noise=ImuNoiseParams(), rng=3)
    clipped = synthesize_imu(traj, rate_hz=1000.0, noise=ImuNoiseParams(), rng=3, gyro_full_scale=MEMS_GYRO_FULL_SCALE,
                             accel_full_scale=MEMS_ACCEL_FULL_SCALE)
    assert MEMS_GYRO_FULL_SCALE == pytest.approx(34.906585) and MEMS_ACCEL_FULL_SCALE == pytest.approx(156.9064)
    np.testing.assert_array_equal(clipped.gyro[:, 2], MEMS_GYRO_FULL_SCALE)  # 52.4 rad/s > 34.9 rad/s
    np.testing.assert_array_equal(clipped.gyro[:, :2], free.gyro[:, :2])
    assert np.abs(free.accel).max() > MEMS_ACCEL_FULL_SCALE  # the spin turns the 20 g through x and y
    np.testing.assert_array_equal(clipped.accel, np.clip(free.accel, -MEMS_ACCEL_FULL_SCALE, MEMS_ACCEL_FULL_SCALE))
    np.testing.assert_array_equal(clipped.bias_gyro, free.bias_gyro)
    for bad in (0.0, -1.0, float("nan"), True):
        with pytest.raises(ValueError, match="gyro_full_scale must be None or a number > 0"):
            synthesize_imu(traj, rate_hz=100.0, noise=None, gyro_full_scale=bad)


def test_level_imu_at_rest_reads_plus_g_up():
    imu = synthesize_imu(STATIC, rate_hz=10.0, noise=ImuNoiseParams.noise_free(), t_end=1.0)
    np.testing.assert_allclose(imu.accel, np.broadcast_to([0.0, 0.0, 9.81], (11, 3)), atol=1e-15)
    np.testing.assert_allclose(imu.gyro, 0.0, atol=0)


def test_window_and_rate_define_the_sample_times():
    imu = synthesize_imu(AERIAL, rate_hz=200.0, noise=None, t_start=12.5, t_end=13.0)
    np.testing.assert_allclose(imu.t, 12.5 + np.arange(101) / 200.0, atol=1e-12)
    truth = AERIAL.evaluate(imu.t)
    np.testing.assert_allclose(imu.gyro, truth.w_I, atol=0)


# ------------------------------------------------------------------------------------------------ RK4 truth test
@pytest.mark.parametrize(
    "traj,t_start",
    [(BOXES, 0.0), (BOXES, 25.0), (AERIAL, 15.0)],  # aerial window covers the banked turn
    ids=["boxes_first_10s", "boxes_25_35s", "aerial_turn_15_25s"],
)
def test_noise_free_imu_integrates_back_to_the_trajectory(traj, t_start):
    """10 s at 1 kHz, linear-midpoint RK4 from the true initial state: position error < 1 mm."""
    e_p, e_v, e_R = _integration_errors(traj, t_start, t_start + 10.0, 1000.0)
    assert e_p < 1e-3
    assert e_v < 1e-3
    assert e_R < 1e-5


def test_integration_error_converges_at_the_expected_order():
    """Exact consistency of the ground truth: the error falls as h^2 (linear midpoint) and h^4 (cubic midpoint)
    even in the violent last 10 s of boxes_like (peak 4 m/s, 5 rad/s); an inconsistent truth would plateau."""
    lin_1k = _integration_errors(BOXES, 50.0, 60.0, 1000.0)[0]
    lin_500 = _integration_errors(BOXES, 50.0, 60.0, 500.0)[0]
    assert lin_500 / lin_1k == pytest.approx(4.0, rel=0.1)
    cub_1k = _integration_errors(BOXES, 50.0, 60.0, 1000.0, midpoint="cubic")[0]
    cub_500 = _integration_errors(BOXES, 50.0, 60.0, 500.0, midpoint="cubic")[0]
    assert cub_500 / cub_1k == pytest.approx(16.0, rel=0.2)
    assert cub_1k < 1e-6
    e_p, e_v, e_R = _integration_errors(AERIAL, 15.0, 25.0, 1000.0, midpoint="cubic")
    assert e_p < 1e-8 and e_v < 1e-8 and e_R < 1e-10


def test_biases_are_removed_only_when_asked():
    noise = ImuNoiseParams(0.0, 0.0, 1e-3, 1e-2, 0.02, 0.1)  # biases only, no white noise
    imu = synthesize_imu(AERIAL, rate_hz=500.0, noise=noise, rng=3, t_start=15.0, t_end=20.0)
    s0 = AERIAL.evaluate(15.0)
    truth = AERIAL.evaluate(imu.t)
    _, p_true_bias, _ = integrate_imu_rk4(imu, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], use_true_bias=True)
    _, p_raw, _ = integrate_imu_rk4(imu, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], use_true_bias=False)
    assert np.abs(p_true_bias - truth.p_IinG).max() < 1e-4
    assert np.abs(p_raw - truth.p_IinG).max() > 0.1


# ------------------------------------------------------------------------------------------------ noise statistics
def test_white_noise_std_is_density_times_sqrt_rate():
    noise = ImuNoiseParams()
    rate = 1000.0
    imu = synthesize_imu(STATIC, rate_hz=rate, noise=noise, rng=np.random.default_rng(11), t_end=300.0)
    truth_accel = np.array([0.0, 0.0, 9.81])
    n_g = imu.gyro - imu.bias_gyro  # truth w_I = 0
    n_a = imu.accel - truth_accel - imu.bias_accel
    np.testing.assert_allclose(n_g.std(axis=0), noise.gyro_noise_density * np.sqrt(rate), rtol=0.02)
    np.testing.assert_allclose(n_a.std(axis=0), noise.accel_noise_density * np.sqrt(rate), rtol=0.02)
    sigma_mean = noise.gyro_noise_density * np.sqrt(rate) / np.sqrt(len(imu))
    np.testing.assert_allclose(n_g.mean(axis=0), 0.0, atol=5 * sigma_mean)
    # white: lag-1 autocorrelation ~ 0
    rho = np.mean(n_g[1:, 0] * n_g[:-1, 0]) / np.var(n_g[:, 0])
    assert abs(rho) < 0.01
    # bias increments: std = random_walk * sqrt(dt), uncorrelated
    d_bg = np.diff(imu.bias_gyro, axis=0)
    np.testing.assert_allclose(d_bg.std(axis=0), noise.gyro_random_walk * np.sqrt(1.0 / rate), rtol=0.02)
    d_ba = np.diff(imu.bias_accel, axis=0)
    np.testing.assert_allclose(d_ba.std(axis=0), noise.accel_random_walk * np.sqrt(1.0 / rate), rtol=0.02)


def test_bias_random_walk_variance_grows_linearly_and_starts_at_init_sigma():
    noise = ImuNoiseParams(
        gyro_random_walk=2e-3, accel_random_walk=3e-2, gyro_bias_init_sigma=0.05, accel_bias_init_sigma=0.2
    )
    gen = np.random.default_rng(5)
    runs = [synthesize_imu(STATIC, rate_hz=50.0, noise=noise, rng=gen, t_end=4.0) for _ in range(600)]
    bg = np.stack([r.bias_gyro for r in runs])  # (600, N, 3)
    ba = np.stack([r.bias_accel for r in runs])
    t = runs[0].t
    np.testing.assert_allclose(bg[:, 0].std(), 0.05, rtol=0.08)
    np.testing.assert_allclose(ba[:, 0].std(), 0.2, rtol=0.08)
    for k in (25, 50, 100, 200):  # t = 0.5, 1, 2, 4 s
        var_g = np.var(bg[:, k] - bg[:, 0])
        var_a = np.var(ba[:, k] - ba[:, 0])
        assert var_g == pytest.approx(noise.gyro_random_walk**2 * t[k], rel=0.12)
        assert var_a == pytest.approx(noise.accel_random_walk**2 * t[k], rel=0.12)


def test_seeded_determinism():
    noise = ImuNoiseParams()
    a = synthesize_imu(AERIAL, rate_hz=100.0, noise=noise, rng=42, t_end=2.0)
    b = synthesize_imu(AERIAL, rate_hz=100.0, noise=noise, rng=np.random.default_rng(42), t_end=2.0)
    c = synthesize_imu(AERIAL, rate_hz=100.0, noise=noise, rng=43, t_end=2.0)
    np.testing.assert_array_equal(a.gyro, b.gyro)
    np.testing.assert_array_equal(a.bias_accel, b.bias_accel)
    assert np.abs(a.gyro - c.gyro).max() > 1e-4


def test_noise_params_dict_round_trip_and_noise_free():
    p = ImuNoiseParams(gyro_noise_density=1e-4, accel_random_walk=2e-3)
    back = ImuNoiseParams.from_dict(json.loads(json.dumps(p.to_dict())))
    assert back == p
    assert ImuNoiseParams.noise_free().is_noise_free and not ImuNoiseParams().is_noise_free
    d = ImuNoiseParams().to_dict()
    assert set(d) == {
        "gyro_noise_density", "accel_noise_density", "gyro_random_walk", "accel_random_walk",
        "gyro_bias_init_sigma", "accel_bias_init_sigma",
    }


# ------------------------------------------------------------------------------------------------ bad inputs
def test_bad_inputs_raise_value_errors():
    with pytest.raises(ValueError, match="rng must be a numpy Generator or an int seed"):
        synthesize_imu(AERIAL, noise=ImuNoiseParams(), t_end=1.0)
    with pytest.raises(ValueError, match="rate_hz must be a finite rate > 0"):
        synthesize_imu(AERIAL, rate_hz=0.0, noise=None)
    with pytest.raises(ValueError, match="t_start, t_end must satisfy"):
        synthesize_imu(AERIAL, noise=None, t_start=5.0, t_end=50.0)
    with pytest.raises(ValueError, match="must hold >= 2 samples"):
        synthesize_imu(AERIAL, rate_hz=1.0, noise=None, t_start=1.0, t_end=1.5)
    with pytest.raises(ValueError, match=r"gravity_G must be a finite vector of shape \(3,\)"):
        synthesize_imu(AERIAL, noise=None, t_end=1.0, gravity_G=[0.0, -9.81])
    with pytest.raises(ValueError, match="trajectory must be a Trajectory"):
        synthesize_imu("boxes", noise=None)
    with pytest.raises(ValueError, match="noise must be an ImuNoiseParams"):
        synthesize_imu(AERIAL, noise={"gyro_noise_density": 0.0}, t_end=1.0)
    with pytest.raises(ValueError, match="gyro_noise_density must be a finite number >= 0"):
        ImuNoiseParams(gyro_noise_density=-1.0)
    with pytest.raises(ValueError, match="data must be a dict with keys among"):
        ImuNoiseParams.from_dict({"gyro_noise": 1.0})

    imu = synthesize_imu(STATIC, rate_hz=10.0, noise=None, t_end=1.0)
    with pytest.raises(ValueError, match=r"R_ItoG0 must have shape \(3, 3\)"):
        integrate_imu_rk4(imu, np.eye(4), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="must be a rotation matrix"):
        integrate_imu_rk4(imu, 2.0 * np.eye(3), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"v_IinG0 must be a finite vector of shape \(3,\)"):
        integrate_imu_rk4(imu, np.eye(3), np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="midpoint must be 'linear' or 'cubic'"):
        integrate_imu_rk4(imu, np.eye(3), np.zeros(3), np.zeros(3), midpoint="quadratic")
    with pytest.raises(ValueError, match="imu must be an ImuData"):
        integrate_imu_rk4(None, np.eye(3), np.zeros(3), np.zeros(3))

    t = np.arange(5.0)
    with pytest.raises(ValueError, match=r"gyro must have shape \(N, 3\) with N = 5"):
        ImuData(t, np.zeros((4, 3)), np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="t must be finite and strictly increasing"):
        ImuData(t[::-1], *(np.zeros((5, 3)),) * 4)
    uneven = ImuData(np.array([0.0, 0.1, 0.3, 0.4]), *(np.zeros((4, 3)),) * 4)
    with pytest.raises(ValueError, match="midpoint='cubic' needs >= 4 uniformly spaced samples"):
        integrate_imu_rk4(uneven, np.eye(3), np.zeros(3), np.zeros(3), midpoint="cubic")


def test_inputs_are_not_modified():
    imu = synthesize_imu(STATIC, rate_hz=10.0, noise=ImuNoiseParams(), rng=1, t_end=1.0)
    gyro_before = imu.gyro.copy()
    R0, p0, v0 = np.eye(3), np.zeros(3), np.zeros(3)
    integrate_imu_rk4(imu, R0, p0, v0)
    np.testing.assert_array_equal(imu.gyro, gyro_before)
    np.testing.assert_array_equal(R0, np.eye(3))
    assert not imu.gyro.flags.writeable
    np.testing.assert_array_equal(GRAVITY_G, [0.0, 0.0, -9.81])
