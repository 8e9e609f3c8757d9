"""Tests of evio_lib.msckf.error_state_attitude: Jacobians against finite differences, the discretisation against
quadrature and the constant-velocity closed form, the update and its gate, the simulation, and the NEES."""
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from evio_lib.evaluation.trajectory_metrics import chi2_bounds, nees
from evio_lib.geometry.rotation import quat_from_rotvec, quat_inverse, quat_multiply, quat_to_rot
from evio_lib.msckf.error_state_attitude import (
    SPECIFIC_FORCE_AT_REST_G,
    AttitudeFilter,
    attitude_error,
    discretize,
    error_state_jacobians,
    gravity_measurement,
    run_filter,
    simulate_rotating_imu,
)
from evio_lib.msckf.propagation import error_state_jacobians as msckf_jacobians
from evio_lib.sim.imu import ImuNoiseParams

W_HAT = np.array([0.4, -0.7, 1.1])
Q_HAT = quat_from_rotvec([0.3, -0.2, 0.9])


def make_filter(q=Q_HAT, b=(0.01, -0.02, 0.005), P=None, gate=None):
    P = np.diag([1e-4] * 3 + [1e-4] * 3) if P is None else P
    return AttitudeFilter(q, np.array(b), P, 1e-3, 1e-4, 0.05, gate_probability=gate)


def test_jacobians_are_the_msckf_top_left_blocks():
    F, G = error_state_jacobians(W_HAT)
    F15, G15 = msckf_jacobians(np.eye(3), W_HAT, [0.0, 0.0, 9.81])
    np.testing.assert_array_equal(F, F15[:6, :6])
    np.testing.assert_array_equal(G, G15[:6, :6])


def test_transition_matrix_matches_finite_differences_of_the_nonlinear_step():
    """Φ maps an initial error [δθ, δb_g] to the error after one step of the true and the estimated kinematics."""
    dt, eps = 0.02, 1e-6
    b_hat = np.array([0.01, -0.02, 0.005])
    gyro = W_HAT + b_hat  # the reading; the estimate's rate is W_HAT

    def error_after(dx):
        q_true = quat_multiply(quat_from_rotvec(dx[:3]), Q_HAT)  # q = δq ⊗ q̂
        b_true = b_hat + dx[3:]
        q_true_next = quat_multiply(quat_from_rotvec((gyro - b_true) * dt), q_true)
        q_est_next = quat_multiply(quat_from_rotvec((gyro - b_hat) * dt), Q_HAT)
        return np.r_[attitude_error(q_true_next, q_est_next), dx[3:]]

    Phi_fd = np.column_stack([(error_after(e) - error_after(-e)) / (2 * eps) for e in np.eye(6) * eps])
    Phi, _ = discretize(W_HAT, dt, 1e-3, 1e-4)
    np.testing.assert_allclose(Phi, Phi_fd, atol=1e-8)
    np.testing.assert_allclose(Phi, scipy.linalg.expm(error_state_jacobians(W_HAT)[0] * dt), atol=1e-14)


def test_noise_jacobian_matches_finite_differences():
    """G: a constant gyro noise n_g over τ moves δθ by -n_g τ (to first order), a bias noise n_wg moves δb by n_wg τ."""
    tau, eps = 1e-4, 1e-6
    b_hat = np.zeros(3)

    def error_after(n):
        q_true = quat_multiply(quat_from_rotvec((W_HAT - n[:3]) * tau), Q_HAT)  # ω = ω_m - b - n_g
        q_est = quat_multiply(quat_from_rotvec(W_HAT * tau), Q_HAT)
        return np.r_[attitude_error(q_true, q_est), b_hat + n[3:] * tau]

    G_fd = np.column_stack([(error_after(e) - error_after(-e)) / (2 * eps * tau) for e in np.eye(6) * eps])
    _, G = error_state_jacobians(W_HAT)
    np.testing.assert_allclose(G_fd, G, atol=1e-3)  # O(|ω| τ) from the rotation within τ


def test_measurement_jacobian_matches_finite_differences_and_misses_yaw():
    z_hat, H = gravity_measurement(Q_HAT)
    np.testing.assert_allclose(z_hat, quat_to_rot(Q_HAT) @ SPECIFIC_FORCE_AT_REST_G)
    eps = 1e-6
    H_fd = np.zeros((3, 6))
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        plus = quat_to_rot(quat_multiply(quat_from_rotvec(d), Q_HAT)) @ SPECIFIC_FORCE_AT_REST_G
        minus = quat_to_rot(quat_multiply(quat_from_rotvec(-d), Q_HAT)) @ SPECIFIC_FORCE_AT_REST_G
        H_fd[:, i] = (plus - minus) / (2 * eps)
    np.testing.assert_allclose(H, H_fd, atol=1e-7)
    assert np.linalg.matrix_rank(H) == 2
    np.testing.assert_allclose(H[:, :3] @ z_hat, 0.0, atol=1e-12)  # a turn about the vertical is not seen


def test_discrete_noise_matches_quadrature_and_the_constant_velocity_form():
    dt, sigma_g, sigma_wg = 0.05, 2e-3, 3e-4
    Phi, Q_d = discretize(W_HAT, dt, sigma_g, sigma_wg)
    F, G = error_state_jacobians(W_HAT)
    GQG = G @ np.diag([sigma_g**2] * 3 + [sigma_wg**2] * 3) @ G.T

    def integrand(s):
        Phi_s = scipy.linalg.expm(F * (dt - s))
        return Phi_s @ GQG @ Phi_s.T

    Q_quad, _ = scipy.integrate.quad_vec(integrand, 0.0, dt, epsabs=1e-16, epsrel=1e-12)
    np.testing.assert_allclose(Q_d, Q_quad, rtol=1e-9, atol=1e-18)
    assert np.allclose(Q_d, Q_d.T) and np.linalg.eigvalsh(Q_d).min() > 0
    # ω = 0: each axis is the constant-velocity model with -b_g as the velocity
    _, Q0 = discretize(np.zeros(3), dt, sigma_g, sigma_wg)
    axis = sigma_wg**2 * np.array([[dt**3 / 3, -dt**2 / 2], [-dt**2 / 2, dt]]) + np.diag([sigma_g**2 * dt, 0.0])
    for i in range(3):
        np.testing.assert_allclose(Q0[np.ix_([i, i + 3], [i, i + 3])], axis, rtol=1e-10)


def test_predict_integrates_the_quaternion_and_grows_p():
    kf = make_filter(b=(0.0, 0.0, 0.0))
    P_before = kf.P.copy()
    kf.predict(W_HAT, 0.01)
    expected = quat_multiply(quat_from_rotvec(W_HAT * 0.01), Q_HAT)
    np.testing.assert_allclose(kf.q_GtoI, expected / np.linalg.norm(expected), atol=1e-15)
    assert np.trace(kf.P) > np.trace(P_before)


def test_update_corrects_a_known_error_multiplicatively():
    d_theta = np.array([0.01, -0.008, 0.0])  # a tilt error (no yaw: the vertical of Q_HAT is not along z)
    q_true = quat_multiply(quat_from_rotvec(d_theta), Q_HAT)
    kf = AttitudeFilter(Q_HAT, np.zeros(3), np.diag([1e-4] * 3 + [1e-8] * 3), 1e-3, 1e-4, 1e-4)  # R << H P H^T
    z = quat_to_rot(q_true) @ SPECIFIC_FORCE_AT_REST_G  # a noise-free reading
    before = attitude_error(q_true, kf.q_GtoI)
    P_before = kf.P.copy()
    nis, accepted = kf.update(z)
    after = attitude_error(q_true, kf.q_GtoI)
    up = quat_to_rot(kf.q_GtoI) @ [0.0, 0.0, 1.0]
    tilt = lambda e: e - (e @ up) * up  # the part gravity can see
    assert accepted and nis > 0
    assert np.linalg.norm(tilt(after)) < 0.02 * np.linalg.norm(tilt(before))  # left: second order and R
    assert np.all(np.linalg.eigvalsh(P_before - kf.P) > -1e-15)  # the update never adds uncertainty
    np.testing.assert_allclose(np.linalg.norm(kf.q_GtoI), 1.0)


def test_gate_rejects_an_outlier_and_leaves_the_state_alone():
    kf = make_filter(gate=0.99)
    q_before, P_before = kf.q_GtoI.copy(), kf.P.copy()
    z = quat_to_rot(Q_HAT) @ SPECIFIC_FORCE_AT_REST_G + np.array([3.0, 0.0, 0.0])  # 60 σ off
    nis, accepted = kf.update(z)
    assert not accepted and nis > 100
    np.testing.assert_array_equal(kf.q_GtoI, q_before)
    np.testing.assert_array_equal(kf.P, P_before)
    _, accepted = kf.update(quat_to_rot(Q_HAT) @ SPECIFIC_FORCE_AT_REST_G)
    assert accepted


def test_simulation_is_seeded_and_self_consistent():
    noise = ImuNoiseParams()
    a = simulate_rotating_imu(2.0, 100.0, noise, np.random.default_rng(3))
    b = simulate_rotating_imu(2.0, 100.0, noise, np.random.default_rng(3))
    np.testing.assert_array_equal(a.gyro, b.gyro)
    assert a.t.shape == (201,) and a.q_GtoI.shape == (201, 4) and a.accel.shape == (201, 3)
    np.testing.assert_allclose(np.linalg.norm(a.q_GtoI, axis=1), 1.0)
    k = 57
    step = quat_multiply(quat_from_rotvec(a.w_I[k] * 0.01), a.q_GtoI[k])
    np.testing.assert_allclose(a.q_GtoI[k + 1], step / np.linalg.norm(step), atol=1e-12)
    clean = simulate_rotating_imu(2.0, 100.0, ImuNoiseParams.noise_free(), np.random.default_rng(0))
    np.testing.assert_allclose(clean.gyro, clean.w_I)
    np.testing.assert_allclose(np.linalg.norm(clean.accel, axis=1), 9.81)
    yaw_only = simulate_rotating_imu(2.0, 100.0, ImuNoiseParams.noise_free(), np.random.default_rng(0),
                                     rate_amplitude=(0.0, 0.0, 1.0))
    np.testing.assert_allclose(yaw_only.accel, np.tile([0.0, 0.0, 9.81], (201, 1)), atol=1e-9)  # stays level


def test_run_filter_learns_the_bias_and_its_nees_is_in_the_band():
    noise = ImuNoiseParams()
    rng = np.random.default_rng(11)
    sigma0 = 0.02
    P0 = np.diag([sigma0**2] * 3 + [noise.gyro_bias_init_sigma**2] * 3)
    n_runs, nees_runs = 12, []
    for _ in range(n_runs):
        data = simulate_rotating_imu(6.0, 100.0, noise, rng)
        q0 = quat_multiply(quat_inverse(quat_from_rotvec(rng.normal(0.0, sigma0, 3))), data.q_GtoI[0])
        kf = AttitudeFilter(q0, np.zeros(3), P0, noise.gyro_noise_density, noise.gyro_random_walk,
                            data.accel_sigma)
        run = run_filter(kf, data, update_every=10)
        nees_runs.append(nees(run.errors, run.P))
    assert run.t.shape == (60,) and run.accepted.all()
    assert np.sqrt(run.P[-1, 3:, 3:].diagonal()).max() < 0.05 * noise.gyro_bias_init_sigma  # the bias is learned
    average = np.mean(nees_runs, axis=0)
    lo, hi = chi2_bounds(6, n_runs)
    # one run's NEES is correlated in time, so the band is judged on the average over time and most updates
    assert np.mean((average >= lo) & (average <= hi)) >= 0.8
    assert lo < average.mean() < hi


def test_run_filter_equals_the_loop_written_out():
    data = simulate_rotating_imu(1.0, 100.0, ImuNoiseParams(), np.random.default_rng(5))
    a, b = make_filter(q=data.q_GtoI[0]), make_filter(q=data.q_GtoI[0])
    run = run_filter(a, data, update_every=5)
    nis = []
    for k in range(len(data.t) - 1):
        b.predict(data.gyro[k], data.t[k + 1] - data.t[k])
        if (k + 1) % 5 == 0:
            nis.append(b.update(data.accel[k + 1])[0])
    np.testing.assert_array_equal(run.nis, nis)
    np.testing.assert_array_equal(run.q_GtoI[-1], b.q_GtoI)
    np.testing.assert_allclose(run.errors[-1, 3:], data.b_g[-1] - b.b_g)


def test_bad_input_is_rejected_with_a_clear_message():
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        discretize(W_HAT, 0.0, 1e-3, 1e-4)
    with pytest.raises(ValueError, match="gyro_noise_density must be a finite number >= 0"):
        discretize(W_HAT, 0.01, -1.0, 1e-4)
    with pytest.raises(ValueError, match=r"w_hat must have shape \(\.\.\., 3\)"):
        error_state_jacobians([1.0, 2.0])
    with pytest.raises(ValueError, match="P must be a symmetric positive semi-definite"):
        make_filter(P=-np.eye(6))
    with pytest.raises(ValueError, match="gate_probability must be None"):
        make_filter(gate=1.5)
    with pytest.raises(ValueError, match="accel_sigma must be a finite number > 0"):
        AttitudeFilter(Q_HAT, np.zeros(3), np.eye(6), 1e-3, 1e-4, 0.0)
    with pytest.raises(ValueError, match=r"accel must have shape \(3,\)"):
        make_filter().update(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="rng must be a numpy Generator"):
        simulate_rotating_imu(1.0, 100.0, ImuNoiseParams(), 3)
    data = simulate_rotating_imu(0.05, 100.0, ImuNoiseParams(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="too few for one update every 10"):
        run_filter(make_filter(), data, update_every=10)
    with pytest.raises(ValueError, match="update_every must be an int >= 1"):
        run_filter(make_filter(), data, update_every=0)
