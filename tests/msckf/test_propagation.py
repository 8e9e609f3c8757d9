"""Tests for evio_lib.msckf.propagation: F and G by finite differences, Φ against scipy expm, Q_d against Van Loan,
nominal integration against simulated and closed-form truth, partitioned covariance, Monte-Carlo consistency."""
import numpy as np
import pytest
from scipy.linalg import block_diag, expm
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from evio_lib.geometry.rotation import (
    omega_matrix,
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_to_rot,
    quat_to_rotvec,
    rot_to_quat,
)
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.propagation import (
    PropagationSteps,
    discrete_noise_covariance,
    error_state_jacobians,
    integrate_imu,
    propagate,
    propagate_covariance,
    transition_matrix,
)
from evio_lib.msckf.state import FilterState, ImuState, state_difference
from evio_lib.sim.imu import synthesize_imu
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.trajectory import aerial_like, boxes_like

G_VEC = np.array([0.0, 0.0, -9.81])


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return Rotation.from_rotvec(rng.normal(size=3)).as_matrix()


def initial_state(R_ItoG, p, v, t0=0.0, cfg=None, b_g=(0.0, 0.0, 0.0), b_a=(0.0, 0.0, 0.0)) -> FilterState:
    cfg = cfg or MsckfConfig()
    ext = CameraImuExtrinsics.default()
    imu = ImuState.from_pose(R_ItoG, p, v, timestamp=t0, b_g=b_g, b_a=b_a)
    return FilterState.initial(imu, ext.R_CtoI, ext.p_CinI, cfg.initial_imu_covariance())


# ---------------------------------------------------------------- F and G against finite differences
# Independent model of the nominal dynamics (thesis Eq. 31) with the noise of Eq. 33:
#   ω = ω_m - b_g - n_g, a = a_m - b_a - n_a,
#   dq/dt = ½ Ω(ω) q, db_g/dt = n_wg, dv/dt = R_ItoG a + g, db_a/dt = n_wa, dp/dt = v.
# The error is x_true ⊟ x_est with q_true = δq(δθ) ⊗ q_est.


def _derivative(x, w_m, a_m, n):
    q, bg, v, ba, p = x
    w = w_m - bg - n[0:3]
    a = a_m - ba - n[6:9]
    return (0.5 * omega_matrix(w) @ q, n[3:6], quat_to_rot(q).T @ a + G_VEC, n[9:12], v)


def _error(xt, xe):
    dq = quat_multiply(xt[0], quat_inverse(xe[0]))
    return np.concatenate([quat_to_rotvec(dq)] + [xt[i] - xe[i] for i in range(1, 5)])


def _perturb(x, dx):
    q, bg, v, ba, p = x
    return (quat_multiply(quat_from_rotvec(dx[0:3]), q), bg + dx[3:6], v + dx[6:9], ba + dx[9:12], p + dx[12:15])


def _error_rate(xe, dx, n, w_m, a_m, eps=1e-4):
    """d/dt (x_true ⊟ x_est) at t = 0 by central differences along the exact derivatives."""
    xt = _perturb(xe, dx)
    ft, fe = _derivative(xt, w_m, a_m, n), _derivative(xe, w_m, a_m, np.zeros(12))
    step = lambda x, f, h: tuple(xi + h * fi for xi, fi in zip(x, f))  # noqa: E731
    return (_error(step(xt, ft, eps), step(xe, fe, eps)) - _error(step(xt, ft, -eps), step(xe, fe, -eps))) / (2 * eps)


def test_F_and_G_match_finite_differences_of_the_error_dynamics(rng):
    R_ItoG = random_rotation(rng)
    xe = (rot_to_quat(R_ItoG.T), 0.02 * rng.normal(size=3), rng.normal(size=3), 0.2 * rng.normal(size=3),
          rng.normal(size=3))
    w_m, a_m = rng.normal(size=3), np.array([0.5, -1.0, 9.5]) + rng.normal(size=3)
    F, G = error_state_jacobians(R_ItoG, w_m - xe[1], a_m - xe[3])
    eta = 1e-4
    F_num = np.zeros((15, 15))
    for j in range(15):
        d = np.zeros(15)
        d[j] = eta
        zero_noise = np.zeros(12)
        F_num[:, j] = (_error_rate(xe, d, zero_noise, w_m, a_m) - _error_rate(xe, -d, zero_noise, w_m, a_m)) / (2 * eta)
    G_num = np.zeros((15, 12))
    for j in range(12):
        n = np.zeros(12)
        n[j] = eta
        zero_dx = np.zeros(15)
        G_num[:, j] = (_error_rate(xe, zero_dx, n, w_m, a_m) - _error_rate(xe, zero_dx, -n, w_m, a_m)) / (2 * eta)
    np.testing.assert_allclose(F, F_num, atol=1e-6)
    np.testing.assert_allclose(G, G_num, atol=1e-6)
    # the check can fail: a sign error in the attitude-velocity coupling is seen
    assert np.abs(F[6:9, 0:3] + F_num[6:9, 0:3]).max() > 1.0


def test_error_state_jacobians_rejects_bad_shapes():
    with pytest.raises(ValueError, match=r"w_hat must have shape \(\.\.\., 3\); got \(2,\)"):
        error_state_jacobians(np.eye(3), np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match=r"R_ItoG, w_hat, a_hat must have shapes"):
        error_state_jacobians(np.eye(3)[None], np.zeros(3), np.zeros(3))


# ---------------------------------------------------------------- Φ against expm, Q_d against Van Loan


@pytest.mark.parametrize(
    ("w_scale", "dt"),
    [(0.0, 1e-3), (1e-9, 1e-3), (3.0, 1e-3), (3.0, 5e-3), (20.0, 0.05), (30.0, 0.1)],  # φ from 0 to 3 rad
)
def test_transition_matrix_is_the_matrix_exponential(rng, w_scale, dt):
    R = random_rotation(rng)
    w = w_scale * rng.normal(size=3) / np.sqrt(3)
    a = np.array([1.0, -2.0, 9.0]) + 5 * rng.normal(size=3)
    F, _ = error_state_jacobians(R, w, a)
    np.testing.assert_allclose(transition_matrix(R, w, a, dt), expm(F * dt), rtol=0, atol=1e-13 * max(1.0, dt * 100))


def test_transition_matrix_batches_over_leading_dimensions(rng):
    R = Rotation.from_rotvec(rng.normal(size=(2, 3, 3))).as_matrix().reshape(2, 3, 3, 3)
    w, a, dt = rng.normal(size=(2, 3, 3)), 9 * rng.normal(size=(2, 3, 3)), rng.uniform(1e-3, 1e-2, size=(2, 3))
    Phi = transition_matrix(R, w, a, dt)
    assert Phi.shape == (2, 3, 15, 15)
    F, _ = error_state_jacobians(R[1, 2], w[1, 2], a[1, 2])
    np.testing.assert_allclose(Phi[1, 2], expm(F * dt[1, 2]), atol=1e-13)
    with pytest.raises(ValueError, match="must share leading dimensions"):
        transition_matrix(R, w, a, dt[0])
    with pytest.raises(ValueError, match="dt must be finite and >= 0"):
        transition_matrix(np.eye(3), np.zeros(3), np.zeros(3), -1.0)


def van_loan(F: np.ndarray, G: np.ndarray, Qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Van Loan (1978): expm([[-F, G Qc G^T], [0, F^T]] dt) = [[., Φ^-1 Q_d], [0, Φ^T]]."""
    n = F.shape[0]
    A = np.zeros((2 * n, 2 * n))
    A[:n, :n], A[:n, n:], A[n:, n:] = -F, G @ Qc @ G.T, F.T
    B = expm(A * dt)
    Phi = B[n:, n:].T
    return Phi, Phi @ B[:n, n:]


@pytest.mark.parametrize(("dt", "tol"), [(1e-3, 1e-12), (5e-3, 1e-11), (2e-2, 1e-9)])
def test_discrete_noise_covariance_matches_van_loan(rng, dt, tol):
    R = random_rotation(rng)
    w, a = 4.0 * rng.normal(size=3), np.array([0.0, 0.0, 9.81]) + 20.0 * rng.normal(size=3)
    F, G = error_state_jacobians(R, w, a)
    default = MsckfConfig().continuous_noise_psd()
    for psd in (default, default * rng.uniform(0.1, 10.0, size=12)):  # per-axis densities too
        Q = discrete_noise_covariance(R, w, a, dt, psd)
        _, Q_vl = van_loan(F, G, np.diag(psd), dt)
        d = np.sqrt(np.diag(Q_vl))
        assert np.abs((Q - Q_vl) / np.outer(d, d)).max() < tol
        np.testing.assert_allclose(Q, Q.T, atol=0)
        assert np.linalg.eigvalsh(Q).min() > -1e-12 * np.abs(Q).max()


def test_discrete_noise_covariance_quadrature_error_stays_small_for_extreme_bias_walks(rng):
    """3-point Gauss-Legendre misses only a degree-6 term (gyro random walk -> position); bound it for σ_wg = 0.1."""
    R, w, a = random_rotation(rng), 4.0 * rng.normal(size=3), 20.0 * rng.normal(size=3)
    F, G = error_state_jacobians(R, w, a)
    psd = np.repeat([1e-4, 1e-2, 1e-2, 1e-2], 3)
    for dt, tol in ((1e-3, 1e-11), (2e-2, 1e-6)):
        _, Q_vl = van_loan(F, G, np.diag(psd), dt)
        d = np.sqrt(np.diag(Q_vl))
        assert np.abs((discrete_noise_covariance(R, w, a, dt, psd) - Q_vl) / np.outer(d, d)).max() < tol


def test_discrete_noise_covariance_rejects_bad_psd():
    with pytest.raises(ValueError, match=r"noise_psd must be diag\(Q_IMU\), 12 finite values >= 0"):
        discrete_noise_covariance(np.eye(3), np.zeros(3), np.zeros(3), 1e-3, np.ones(15))


def test_propagate_covariance_is_the_dense_block_update(rng):
    n = 15 + 12
    A = rng.normal(size=(n, n))
    P = A @ A.T
    Phi = expm(0.01 * rng.normal(size=(15, 15)))
    B = rng.normal(size=(15, 15))
    Q = B @ B.T
    big = block_diag(Phi, np.eye(12))
    expected = big @ P @ big.T + block_diag(Q, np.zeros((12, 12)))  # thesis Eqs. 38-40
    np.testing.assert_allclose(propagate_covariance(P, Phi, Q), expected, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match=r"P must have shape \(15 \+ 6N, 15 \+ 6N\); got \(16, 16\)"):
        propagate_covariance(np.eye(16), Phi, Q)


# ---------------------------------------------------------------- nominal integration against the truth


@pytest.mark.parametrize("make", [lambda: boxes_like(duration=10.0, seed=3), lambda: aerial_like(duration=10.0)])
def test_noise_free_propagation_follows_the_simulated_trajectory(make):
    traj = make()
    imu = synthesize_imu(traj, rate_hz=1000.0, noise=None)
    s0 = traj.evaluate(0.0)
    state = initial_state(s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0])
    image_times = np.r_[0.0123 + 0.05 * np.arange(199), 10.0]  # 20 Hz, off the IMU grid: partial steps every call
    for t in image_times:
        state = propagate(state, imu.t, imu.gyro, imu.accel, t, MsckfConfig())
    truth = traj.evaluate(10.0)
    assert state.timestamp == 10.0
    assert np.linalg.norm(state.imu.p_IinG - truth.p_IinG[0]) < 1e-3  # < 1 mm after 10 s
    assert np.linalg.norm(state.imu.v_IinG - truth.v_IinG[0]) < 1e-3
    dtheta = Rotation.from_matrix(state.imu.R_ItoG.T @ truth.R_ItoG[0]).as_rotvec()
    assert np.linalg.norm(dtheta) < 5e-5  # ~8e-6 rad on the vigorous boxes_like, 7e-8 on aerial_like
    # the covariance stays symmetric positive definite
    P = state.P
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > 0


def constant_rate_truth(t, q0, w, p0, v0, acc_G):
    """Closed form: constant body rate w (q(t) = exp(w t) ⊗ q0) and constant world acceleration."""
    t = np.atleast_1d(t)
    q = quat_multiply(quat_from_rotvec(w[None] * t[:, None]), q0)
    p = p0 + v0 * t[:, None] + 0.5 * acc_G * t[:, None] ** 2
    v = v0 + acc_G * t[:, None]
    return q, p, v


def test_partial_last_step_is_interpolated_against_closed_form_motion(rng):
    w = np.array([0.3, -0.5, 0.8])
    q0, p0, v0 = rot_to_quat(random_rotation(rng)), rng.normal(size=3), rng.normal(size=3)
    acc_G = np.array([0.4, -0.2, 0.1])
    b_g, b_a = np.array([0.01, -0.02, 0.005]), np.array([0.1, 0.05, -0.08])
    t = np.arange(0.0, 1.0 + 1e-9, 0.01)  # 100 Hz, coarse on purpose
    q_t, _, _ = constant_rate_truth(t, q0, w, p0, v0, acc_G)
    gyro = np.tile(w + b_g, (len(t), 1))
    accel = np.einsum("nij,j->ni", quat_to_rot(q_t), acc_G - G_VEC) + b_a  # R_GtoI (a - g) + b_a
    state = initial_state(quat_to_rot(q0).T, p0, v0, b_g=b_g, b_a=b_a)
    t_target = 0.537  # between samples
    out = propagate(state, t, gyro, accel, t_target, MsckfConfig())
    q_true, p_true, v_true = constant_rate_truth(t_target, q0, w, p0, v0, acc_G)
    assert np.linalg.norm(quat_to_rotvec(quat_multiply(out.imu.q_GtoI, quat_inverse(q_true[0])))) < 1e-12
    # linear interpolation of the rotating specific force at 100 Hz costs ~h² f''/12 ~ 1e-4 m/s^2 -> ~1e-5 m
    assert np.linalg.norm(out.imu.p_IinG - p_true[0]) < 5e-5
    assert np.linalg.norm(out.imu.v_IinG - v_true[0]) < 2e-4
    # stopping at the last sample before t_target would be ~v * 7 ms away: the check can fail
    early = propagate(state, t, gyro, accel, 0.53, MsckfConfig())
    assert np.linalg.norm(early.imu.p_IinG - p_true[0]) > 1e-3


def test_integrate_imu_matches_propagate_and_checks_inputs(rng):
    t = np.linspace(0.0, 0.2, 201)
    gyro, accel = rng.normal(size=(201, 3)), rng.normal(size=(201, 3)) + [0.0, 0.0, 9.81]
    state = initial_state(random_rotation(rng), rng.normal(size=3), rng.normal(size=3), b_g=[0.01, 0, 0])
    q, v, p = integrate_imu(state.imu, t, gyro, accel, G_VEC)
    out = propagate(state, t, gyro, accel, 0.2, MsckfConfig())
    np.testing.assert_allclose(q[-1], out.imu.q_GtoI, atol=1e-15)
    np.testing.assert_allclose(p[-1], out.imu.p_IinG, atol=1e-15)
    np.testing.assert_allclose(v[-1], out.imu.v_IinG, atol=1e-15)
    with pytest.raises(ValueError, match=r"t\[0\] must equal imu.timestamp"):
        integrate_imu(state.imu, t + 1.0, gyro, accel)
    with pytest.raises(ValueError, match=r"gyro and accel must have shape \(201, 3\)"):
        integrate_imu(state.imu, t, gyro[:-1], accel)


def test_splitting_a_propagation_into_calls_changes_nothing(rng):
    t = np.arange(0.0, 1.0 + 1e-9, 1e-3)
    gyro = np.cumsum(0.05 * rng.normal(size=(len(t), 3)), axis=0)
    accel = np.cumsum(0.2 * rng.normal(size=(len(t), 3)), axis=0) + [0.0, 0.0, 9.81]
    state = augment_state(initial_state(random_rotation(rng), np.zeros(3), np.ones(3)), 0)
    cfg = MsckfConfig()
    once = propagate(state, t, gyro, accel, 1.0, cfg)
    split = state
    for k in range(1, 21):  # image times on the IMU grid: the same intervals
        split = propagate(split, t, gyro, accel, t[50 * k], cfg)
    np.testing.assert_allclose(split.imu.q_GtoI, once.imu.q_GtoI, atol=1e-13)
    np.testing.assert_allclose(split.imu.p_IinG, once.imu.p_IinG, atol=1e-12)
    np.testing.assert_allclose(split.P, once.P, rtol=1e-9, atol=1e-15)


# ---------------------------------------------------------------- covariance: partition, hook, linearisation


def _state_with_cameras(rng) -> tuple[FilterState, np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(0.0, 0.3 + 1e-9, 1e-3)
    gyro = rng.normal(size=(len(t), 3))
    accel = 3 * rng.normal(size=(len(t), 3)) + [0.0, 0.0, 9.81]
    cfg = MsckfConfig()
    state = augment_state(initial_state(random_rotation(rng), np.zeros(3), np.ones(3)), 1)
    state = augment_state(propagate(state, t, gyro, accel, 0.05, cfg), 2)
    return state, t, gyro, accel


def test_covariance_partition_matches_the_step_by_step_recursion(rng):
    state, t, gyro, accel = _state_with_cameras(rng)
    seen: list[tuple[np.ndarray, PropagationSteps]] = []

    def record(Phi, steps):
        seen.append((Phi.copy(), steps))
        return Phi

    cfg = MsckfConfig()
    out = propagate(state, t, gyro, accel, 0.1234, cfg, transition_hook=record)
    (Phi, steps), = seen
    K = len(steps.dt)
    assert Phi.shape == (K, 15, 15) and steps.t[0] == 0.05 and steps.t[-1] == 0.1234
    # straightforward recursion with the public single-step functions (thesis Eqs. 36-40)
    Q = discrete_noise_covariance(steps.R_ItoG_mid, steps.w_hat, steps.a_hat, steps.dt, cfg.continuous_noise_psd())
    P = state.P.copy()
    for k in range(K):
        np.testing.assert_allclose(Phi[k], transition_matrix(steps.R_ItoG_mid[k], steps.w_hat[k], steps.a_hat[k],
                                                             steps.dt[k]), atol=1e-15)
        P = propagate_covariance(P, Phi[k], Q[k])
    np.testing.assert_allclose(out.P, P, rtol=1e-10, atol=1e-16)
    np.testing.assert_array_equal(out.P[15:, 15:], state.P[15:, 15:])  # camera block untouched


def test_transition_hook_gets_first_estimates_and_its_phi_is_used(rng):
    state, t, gyro, accel = _state_with_cameras(rng)
    null_q = rot_to_quat(random_rotation(rng))
    state = state.replace(imu=ImuState(state.imu.q_GtoI, state.imu.b_g, state.imu.v_IinG, state.imu.b_a,
                                       state.imu.p_IinG, state.timestamp, q_GtoI_null=null_q,
                                       v_IinG_null=[9.0, 9.0, 9.0], p_IinG_null=[7.0, 7.0, 7.0]))
    got = {}

    def identity_hook(Phi, steps):
        got["steps"] = steps
        return np.broadcast_to(np.eye(15), Phi.shape).copy()

    out = propagate(state, t, gyro, accel, 0.08, MsckfConfig(), transition_hook=identity_hook)
    steps = got["steps"]
    np.testing.assert_array_equal(steps.q_GtoI_prev[0], null_q)
    np.testing.assert_array_equal(steps.v_IinG_prev[0], [9.0, 9.0, 9.0])
    np.testing.assert_array_equal(steps.q_GtoI_prev[1:], steps.q_GtoI[1:-1])
    np.testing.assert_array_equal(steps.p_IinG_prev[1:], steps.p_IinG[1:-1])
    # with Φ = I the cross-covariance is unchanged and P_II only gains noise
    np.testing.assert_allclose(out.P[:15, 15:], state.P[:15, 15:], atol=1e-15)
    # after the call the first estimates are the predicted state (S-MSCKF)
    np.testing.assert_array_equal(out.imu.q_GtoI_null, out.imu.q_GtoI)
    np.testing.assert_array_equal(out.imu.p_IinG_null, out.imu.p_IinG)
    with pytest.raises(ValueError, match="transition_hook must return finite Phi of shape"):
        propagate(state, t, gyro, accel, 0.08, MsckfConfig(), transition_hook=lambda Phi, steps: Phi[:-1])


def test_phi_predicts_how_a_small_error_evolves_through_the_nominal_integrator(rng):
    """x_true ⊟ x_est after 50 ms of the same IMU data equals Φ_total (x_true ⊟ x_est) at the start."""
    t = np.arange(0.0, 0.05 + 1e-9, 1e-3)
    gyro = 2.0 * rng.normal(size=(len(t), 3))
    accel = 5.0 * rng.normal(size=(len(t), 3)) + [0.0, 0.0, 9.81]
    est = initial_state(random_rotation(rng), rng.normal(size=3), rng.normal(size=3), b_g=[0.02, -0.01, 0.0],
                        b_a=[0.1, 0.0, -0.1])
    dx = np.r_[1e-3 * rng.normal(size=3), 1e-3 * rng.normal(size=3), 1e-2 * rng.normal(size=3),
               1e-2 * rng.normal(size=3), 1e-2 * rng.normal(size=3)]
    true = est.inject_error(dx)
    Phis = []
    out_est = propagate(est, t, gyro, accel, 0.05, MsckfConfig(), transition_hook=lambda P, s: Phis.append(P) or P)
    out_true = propagate(true, t, gyro, accel, 0.05, MsckfConfig())
    Phi_total = np.eye(15)
    for Phi in Phis[0]:
        Phi_total = Phi @ Phi_total
    actual = state_difference(out_true, out_est)
    predicted = Phi_total @ dx
    assert np.linalg.norm(actual - predicted) < 2e-3 * np.linalg.norm(predicted)
    # without the coupling terms the prediction is far off: the check can fail
    assert np.linalg.norm(actual - dx) > 1e-2 * np.linalg.norm(predicted)


# ---------------------------------------------------------------- Monte-Carlo consistency of P


def test_monte_carlo_error_covariance_matches_the_propagated_covariance():
    """200 seeded noisy runs over 1 s at 500 Hz: the errors' NEES and sample variances agree with P."""
    rng = np.random.default_rng(7)
    cfg = MsckfConfig(gyro_noise_density=2e-3, accel_noise_density=3e-2, gyro_random_walk=2e-3, accel_random_walk=5e-2,
                      init_sigma_attitude=2e-3, init_sigma_gyro_bias=5e-3, init_sigma_velocity=2e-2,
                      init_sigma_accel_bias=3e-2, init_sigma_position=1e-2)
    traj = boxes_like(duration=10.0, seed=5)
    rate, T, runs = 500.0, 1.0, 200
    clean = synthesize_imu(traj, rate_hz=rate, noise=None, t_end=T)
    n = len(clean)
    dt = 1.0 / rate
    s0, s1 = traj.evaluate(0.0), traj.evaluate(T)
    truth0 = FilterState.initial(ImuState.from_pose(s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], 0.0),
                                 np.eye(3), np.zeros(3), cfg.initial_imu_covariance())
    P0 = cfg.initial_imu_covariance()
    errors, nees = [], []
    for _ in range(runs):
        dx0 = rng.multivariate_normal(np.zeros(15), P0)  # x_true ⊟ x_est at t = 0
        # true biases: start at the estimate's bias (0) + the sampled error, then random walks
        walk_g = cfg.gyro_random_walk * np.sqrt(dt) * rng.standard_normal((n - 1, 3))  # b_k+1 = b_k + σ_w sqrt(dt) ξ
        walk_a = cfg.accel_random_walk * np.sqrt(dt) * rng.standard_normal((n - 1, 3))
        bg = dx0[3:6] + np.vstack([np.zeros(3), np.cumsum(walk_g, axis=0)])
        ba = dx0[9:12] + np.vstack([np.zeros(3), np.cumsum(walk_a, axis=0)])
        gyro = clean.gyro + bg + cfg.gyro_noise_density / np.sqrt(dt) * rng.standard_normal((n, 3))
        accel = clean.accel + ba + cfg.accel_noise_density / np.sqrt(dt) * rng.standard_normal((n, 3))
        true0 = truth0.replace(imu=ImuState(truth0.imu.q_GtoI, dx0[3:6], truth0.imu.v_IinG, dx0[9:12],
                                            truth0.imu.p_IinG, 0.0))
        est0 = true0.inject_error(-dx0)  # so that true0 ⊟ est0 = dx0 (biases: est = 0)
        est = propagate(est0, clean.t, gyro, accel, T, cfg)
        true1 = FilterState.initial(ImuState.from_pose(s1.R_ItoG[0], s1.p_IinG[0], s1.v_IinG[0], T,
                                                       b_g=bg[-1], b_a=ba[-1]), np.eye(3), np.zeros(3), P0)
        e = state_difference(true1, est)
        errors.append(e)
        nees.append(e @ np.linalg.solve(est.P, e))
    errors = np.array(errors)
    mean_nees = float(np.mean(nees))
    lo, hi = chi2.ppf([0.0005, 0.9995], 15 * runs) / runs  # 99.9 % two-sided bounds on the mean NEES
    print(f"Monte Carlo: mean NEES {mean_nees:.2f} (99.9 % bounds {lo:.2f}-{hi:.2f})")
    assert lo < mean_nees < hi, (mean_nees, lo, hi)
    ratio = errors.var(axis=0) / np.diag(est.P)
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio
    # the noise matters in this scenario: the same errors against P propagated without Q_d are inconsistent
    quiet = propagate(est0, clean.t, gyro, accel, T, MsckfConfig(**{**cfg.to_dict(), "gyro_noise_density": 0.0,
                                                                    "accel_noise_density": 0.0, "gyro_random_walk": 0.0,
                                                                    "accel_random_walk": 0.0}))
    nees_quiet = np.mean([e @ np.linalg.solve(quiet.P, e) for e in errors])
    print(f"variance ratios {np.round(ratio, 2)}; NEES against P without process noise {nees_quiet:.1f}")
    assert nees_quiet > 1.5 * hi


# ------------------------------------------------- bookkeeping, inputs (speed: bench/bench_propagation.py)


def test_propagate_keeps_inputs_and_handles_zero_length(rng):
    state, t, gyro, accel = _state_with_cameras(rng)
    gyro_before = gyro.copy()
    P_before = state.P.copy()
    out = propagate(state, t, gyro, accel, 0.2, MsckfConfig())
    np.testing.assert_array_equal(gyro, gyro_before)
    np.testing.assert_array_equal(state.P, P_before)
    assert state.timestamp == 0.05 and out.timestamp == 0.2
    assert out.cameras[1] is state.cameras[1]
    np.testing.assert_array_equal(out.imu.b_g, state.imu.b_g)
    assert propagate(state, t, gyro, accel, state.timestamp, MsckfConfig()) is state


def test_propagate_holds_the_nearest_sample_outside_the_data(rng):
    state = initial_state(np.eye(3), np.zeros(3), np.zeros(3))
    t = np.array([0.5])  # a single sample after t0: held constant over [0, 1] (IMU gaps of 0.5 s: allowed here)
    out = propagate(state, t, np.zeros((1, 3)), np.array([[1.0, 0.0, 9.81]]), 1.0, MsckfConfig(imu_max_bridged_gap=1.0))
    np.testing.assert_allclose(out.imu.p_IinG, [0.5, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"t_target": -1.0}, r"t_target must be >= state.timestamp = 0.0 \(no backward propagation\); got -1.0"),
        ({"t_target": float("nan")}, "t_target must be a finite time"),
        ({"imu_t": np.zeros((5, 1))}, r"imu_t must have shape \(M,\) with M >= 1; got \(5, 1\)"),
        ({"imu_gyro": np.zeros((5, 2))}, r"imu_gyro and imu_accel must have shape \(M, 3\) = \(5, 3\)"),
        ({"imu_t": np.array([0.0, 0.1, 0.1, 0.3, 0.4])}, "imu_t must be strictly increasing"),
        ({"imu_accel": np.full((5, 3), np.nan)}, "must be finite around"),
        ({"config": {"gyro_noise_density": 1.0}}, "config must be an MsckfConfig"),
        ({"state": "state"}, "state must be a FilterState"),
    ],
)
def test_propagate_rejects_bad_inputs(kwargs, message):
    args = dict(state=initial_state(np.eye(3), np.zeros(3), np.zeros(3)), imu_t=np.linspace(0.0, 0.4, 5),
                imu_gyro=np.zeros((5, 3)), imu_accel=np.zeros((5, 3)), t_target=0.3, config=MsckfConfig())
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        propagate(**args)
