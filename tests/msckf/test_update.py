"""Tests for evio_lib.msckf.update: measurement Jacobians against finite differences of the measurement function
(camera poses perturbed with the filter's error-state convention), nullspace projection against an explicit Schur
complement, QR compression invariants, a seeded Monte-Carlo of the chi-square gate, the Joseph-form update against the
information-form solution, and bad input."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from evio_lib.msckf.update import (
    camera_error_column,
    chi_square_gate,
    chi_square_threshold,
    feature_jacobians,
    gating_mean_shrink,
    kalman_update,
    measurement_compress,
    nullspace_project,
)
from evio_lib.msckf.triangulation import triangulate_inverse_depth_batch

SIGMA = 1.0 / 200.0  # 1 px at f = 200 px, in normalised units


# ---------------------------------------------------------------- helpers (independent of the library)


def random_spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.1 * np.eye(n))


def window_and_feature(rng: np.random.Generator, n_cams: int = 5, observers=(0, 2, 3, 4)):
    """A window of n_cams camera states looking along +z_G and a feature ~5 m ahead seen by ``observers``."""
    p_CinG = rng.normal(scale=0.5, size=(n_cams, 3))
    R_GtoC = np.swapaxes(Rotation.from_rotvec(rng.normal(scale=0.2, size=(n_cams, 3))).as_matrix(), 1, 2)
    p_FinG = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), 5.0])
    idx = np.asarray(observers)
    return R_GtoC, p_CinG, p_FinG, idx


def measure(R_GtoC, p_CinG, p_FinG):
    """z = [X/Z, Y/Z] of p_FinC = R_GtoC (p_FinG - p_CinG), stacked (2M,)."""
    p_C = np.einsum("mij,mj->mi", R_GtoC, p_FinG - p_CinG)
    return (p_C[:, :2] / p_C[:, 2:]).ravel()


def perturbed_measurement(R_GtoC, p_CinG, cols, p_FinG, dx, dp_F):
    """The measurement after applying the error state dx and the feature error dp_F.

    q_true = δq ⊗ q_est, i.e. R_true = exp(-[δθ x]) R_est (the exact rotation of the JPL error quaternion; scipy
    builds it), and p_true = p + δp."""
    R_true, p_true = R_GtoC.copy(), p_CinG.copy()
    for i, c in enumerate(cols):
        R_true[i] = Rotation.from_rotvec(-dx[c:c + 3]).as_matrix() @ R_GtoC[i]
        p_true[i] = p_CinG[i] + dx[c + 3:c + 6]
    return measure(R_true, p_true, p_FinG + dp_F)


# ---------------------------------------------------------------- feature_jacobians


def test_feature_jacobians_match_finite_differences(rng):
    n_cams = 5
    state_dim = 15 + 6 * n_cams
    R_all, p_all, p_F, idx = window_and_feature(rng, n_cams)
    R, p = R_all[idx], p_all[idx]
    cols = camera_error_column(idx)
    z_meas = measure(R, p, p_F).reshape(-1, 2) + rng.normal(scale=SIGMA, size=(len(idx), 2))
    r, H_x, H_f = feature_jacobians(R, p, cols, p_F, z_meas, state_dim)
    M = len(idx)
    assert r.shape == (2 * M,) and H_x.shape == (2 * M, state_dim) and H_f.shape == (2 * M, 3)
    np.testing.assert_allclose(r, z_meas.ravel() - measure(R, p, p_F), atol=1e-15)

    step = 1e-6
    numeric_x = np.zeros_like(H_x)
    for k in range(state_dim):
        d = np.zeros(state_dim)
        d[k] = step
        numeric_x[:, k] = (perturbed_measurement(R, p, cols, p_F, d, 0.0)
                           - perturbed_measurement(R, p, cols, p_F, -d, 0.0)) / (2 * step)
    numeric_f = np.zeros_like(H_f)
    for k in range(3):
        d = np.zeros(3)
        d[k] = step
        numeric_f[:, k] = (perturbed_measurement(R, p, cols, p_F, np.zeros(state_dim), d)
                           - perturbed_measurement(R, p, cols, p_F, np.zeros(state_dim), -d)) / (2 * step)
    np.testing.assert_allclose(H_x, numeric_x, atol=1e-8)
    np.testing.assert_allclose(H_f, numeric_f, atol=1e-8)
    # only the observing cameras' 6 columns are non-zero; the IMU block and camera 1 are untouched
    assert np.all(H_x[:, :15] == 0) and np.all(H_x[:, 21:27] == 0)
    for i, c in enumerate(cols):
        rows = slice(2 * i, 2 * i + 2)
        assert np.count_nonzero(np.delete(H_x[rows], np.arange(c, c + 6), axis=1)) == 0


def test_feature_jacobians_accept_quaternions_and_do_not_modify_inputs(rng):
    R_all, p_all, p_F, idx = window_and_feature(rng, 4, observers=(1, 3))
    R, p = R_all[idx], p_all[idx]
    obs = measure(R, p, p_F).reshape(-1, 2)
    q = Rotation.from_matrix(np.swapaxes(R, 1, 2)).as_quat()  # JPL q_GtoC = Hamilton quaternion of R^T
    copies = [R.copy(), p.copy(), obs.copy(), p_F.copy()]
    a = feature_jacobians(R, p, [21, 33], p_F, obs, 39)
    b = feature_jacobians(q, p, np.array([21, 33]), p_F, obs, 39)
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, atol=1e-12)
    np.testing.assert_allclose(a[0], 0.0, atol=1e-15)  # noise-free residual
    for before, after in zip(copies, (R, p, obs, p_F)):
        np.testing.assert_array_equal(before, after)


def test_camera_error_column():
    assert camera_error_column(0) == 15
    assert camera_error_column(np.arange(3)).tolist() == [15, 21, 27]
    with pytest.raises(ValueError, match="window_index must be non-negative integer"):
        camera_error_column(-1)
    with pytest.raises(ValueError, match="window_index must be non-negative integer"):
        camera_error_column(1.5)


# ---------------------------------------------------------------- nullspace projection


def test_nullspace_basis_properties(rng):
    for M in (2, 3, 8):
        H_f = rng.normal(size=(2 * M, 3))
        r = rng.normal(size=2 * M)
        A_T, r_o = nullspace_project(np.eye(2 * M), H_f, r)  # with H_x = I the projected Jacobian is A^T itself
        assert A_T.shape == (2 * M - 3, 2 * M) and r_o.shape == (2 * M - 3,)
        np.testing.assert_allclose(A_T @ H_f, 0.0, atol=1e-12)  # A^T H_f = 0
        np.testing.assert_allclose(A_T @ A_T.T, np.eye(2 * M - 3), atol=1e-12)  # A^T A = I
        np.testing.assert_allclose(r_o, A_T @ r, atol=1e-12)
        # A spans the whole left nullspace: A A^T is the projector I - H_f (H_f^T H_f)^-1 H_f^T
        proj = np.eye(2 * M) - H_f @ np.linalg.solve(H_f.T @ H_f, H_f.T)
        np.testing.assert_allclose(A_T.T @ A_T, proj, atol=1e-12)


def test_nullspace_projection_equals_marginalising_the_feature(rng):
    # information on x after marginalising f (flat prior) from r = H_x x + H_f f + n, n ~ N(0, σ² I):
    # Λ = (H_x^T H_x - H_x^T H_f (H_f^T H_f)^-1 H_f^T H_x) / σ² (Schur complement), η likewise with r
    R_all, p_all, p_F, idx = window_and_feature(rng, 6, observers=(0, 1, 3, 4, 5))
    cols = camera_error_column(idx)
    obs = measure(R_all[idx], p_all[idx], p_F).reshape(-1, 2) + rng.normal(scale=SIGMA, size=(len(idx), 2))
    r, H_x, H_f = feature_jacobians(R_all[idx], p_all[idx], cols, p_F, obs, 51)
    H_o, r_o = nullspace_project(H_x, H_f, r)
    assert H_o.shape == (2 * len(idx) - 3, 51)
    var = SIGMA**2
    info = np.block([[H_x.T @ H_x, H_x.T @ H_f], [H_f.T @ H_x, H_f.T @ H_f]]) / var
    vec = np.concatenate([H_x.T @ r, H_f.T @ r]) / var
    n = 51
    schur = info[:n, :n] - info[:n, n:] @ np.linalg.solve(info[n:, n:], info[n:, :n])
    eta = vec[:n] - info[:n, n:] @ np.linalg.solve(info[n:, n:], vec[n:])
    np.testing.assert_allclose(H_o.T @ H_o / var, schur, rtol=1e-9, atol=1e-9 * np.abs(schur).max())
    np.testing.assert_allclose(H_o.T @ r_o / var, eta, rtol=1e-9, atol=1e-9 * np.abs(eta).max())


def test_nullspace_of_a_single_observation_is_empty(rng):
    H_o, r_o = nullspace_project(rng.normal(size=(2, 21)), rng.normal(size=(2, 3)), rng.normal(size=2))
    assert H_o.shape == (0, 21) and r_o.shape == (0,)


# ---------------------------------------------------------------- chi-square gate


def test_chi_square_threshold_is_scipys_quantile():
    for dof in (1, 5, 37):
        assert chi_square_threshold(dof) == pytest.approx(chi2.ppf(0.95, dof), rel=1e-12)
    assert chi_square_threshold(4, 0.99) == pytest.approx(chi2.ppf(0.99, 4), rel=1e-12)
    assert chi_square_threshold(4, 0.95) > chi2.ppf(0.05, 4)  # not msckf_vio's 5% table


def test_chi_square_gate_passes_95_percent_of_correct_features_and_rejects_outliers(rng):
    n, m = 12, 7
    P = random_spd(rng, n, scale=1e-4)
    H = rng.normal(size=(m, n))
    var = SIGMA**2
    trials = 2000
    L = np.linalg.cholesky(P)
    dx = rng.normal(size=(trials, n)) @ L.T  # δx ~ N(0, P)
    residuals = dx @ H.T + rng.normal(scale=SIGMA, size=(trials, m))  # r = H δx + n
    S_inv = np.linalg.inv(H @ P @ H.T + var * np.eye(m))
    passed = 0
    for k in range(trials):
        ok, gamma = chi_square_gate(H, residuals[k], P, var)
        if k < 20:
            assert gamma == pytest.approx(residuals[k] @ S_inv @ residuals[k], rel=1e-9)
        passed += ok
    assert abs(passed / trials - 0.95) < 0.02
    outlier = residuals[0] + 20 * np.sqrt(np.diag(H @ P @ H.T) + var)
    ok, gamma = chi_square_gate(H, outlier, P, var)
    assert not ok and gamma > chi2.ppf(0.95, m)
    # a looser probability lets more through
    ok99 = sum(chi_square_gate(H, residuals[k], P, var, probability=0.99)[0] for k in range(300))
    ok95 = sum(chi_square_gate(H, residuals[k], P, var)[0] for k in range(300))
    assert ok99 >= ok95


def test_chi_square_gate_with_no_rows():
    assert chi_square_gate(np.zeros((0, 3)), np.zeros(0), np.eye(3), 1.0) == (False, 0.0)


@pytest.mark.parametrize("dof, probability", [(1, 0.95), (1, 0.999), (3, 0.95), (10, 0.99)])
def test_gating_mean_shrink_matches_monte_carlo(dof, probability):
    """Residuals N(mu, I) kept by the gate have mean s mu (first order in mu); sampled with a fixed seed."""
    gen = np.random.default_rng(7)
    mu = np.zeros(dof)
    mu[0] = 0.05
    n = 1_000_000
    r = gen.standard_normal((n, dof)) + mu
    keep = np.einsum("ij,ij->i", r, r) < chi2.ppf(probability, dof)
    # mean of the kept first component over mu, against the closed form; the antithetic copy -r cancels the
    # O(1) sampling noise of the mean (E[n 1{.}] = 0 by symmetry)
    m_plus = r[keep, 0].sum() / n
    r2 = -(r - mu) + mu  # the mirrored noise, same mu
    keep2 = np.einsum("ij,ij->i", r2, r2) < chi2.ppf(probability, dof)
    m_minus = r2[keep2, 0].sum() / n
    estimate = 0.5 * (m_plus + m_minus) / mu[0] / probability
    assert estimate == pytest.approx(gating_mean_shrink(dof, probability), abs=0.02)


def test_gating_mean_shrink_values():
    assert gating_mean_shrink(1, 0.95) == pytest.approx(chi2.cdf(chi2.ppf(0.95, 1), 3) / 0.95)
    assert gating_mean_shrink(1, 0.95) < 0.77 < 0.98 < gating_mean_shrink(1, 0.999) < 1.0
    with pytest.raises(ValueError, match="dof"):
        gating_mean_shrink(0)


# ---------------------------------------------------------------- QR compression


def test_measurement_compress_keeps_the_normal_equations(rng):
    H = rng.normal(size=(120, 27))
    r = rng.normal(size=120)
    T_H, r_q = measurement_compress(H, r)
    assert T_H.shape == (27, 27) and r_q.shape == (27,)
    np.testing.assert_array_equal(T_H, np.triu(T_H))
    np.testing.assert_allclose(T_H.T @ T_H, H.T @ H, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(T_H.T @ r_q, H.T @ r, rtol=1e-10, atol=1e-10)
    # and so the Kalman update is unchanged
    P = random_spd(rng, 27)
    dx_full, P_full = kalman_update(P, H, r, 0.3)
    dx_q, P_q = kalman_update(P, T_H, r_q, 0.3)
    np.testing.assert_allclose(dx_q, dx_full, atol=1e-10)
    np.testing.assert_allclose(P_q, P_full, atol=1e-10)


def test_measurement_compress_leaves_wide_systems_alone(rng):
    H = rng.normal(size=(4, 9))
    r = rng.normal(size=4)
    T_H, r_q = measurement_compress(H, r)
    np.testing.assert_array_equal(T_H, H)
    np.testing.assert_array_equal(r_q, r)
    assert T_H is not H and r_q is not r


# ---------------------------------------------------------------- Kalman update


def test_kalman_update_equals_information_form(rng):
    n, m = 10, 6
    P = random_spd(rng, n)
    H = rng.normal(size=(m, n))
    var = 0.05
    x_true = np.linalg.cholesky(P) @ rng.normal(size=n)
    y = H @ x_true + rng.normal(scale=np.sqrt(var), size=m)  # prior mean 0: residual = y
    dx, P_new = kalman_update(P, H, y, var)
    P_info = np.linalg.inv(np.linalg.inv(P) + H.T @ H / var)  # (P^-1 + H^T R^-1 H)^-1
    x_info = P_info @ (H.T @ y / var)
    np.testing.assert_allclose(P_new, P_info, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(dx, x_info, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(P_new, P_new.T)
    assert np.linalg.eigvalsh(P_new).min() > 0
    assert np.all(np.diag(P_new) <= np.diag(P) + 1e-12)  # information never increases uncertainty


def test_sequential_updates_equal_one_batch_update_and_stay_spd(rng):
    n = 21
    P = random_spd(rng, n, scale=1e-2)
    H = rng.normal(size=(30, n))
    r = rng.normal(size=30)
    dx_batch, P_batch = kalman_update(P, H, r, 1e-3)
    dx_seq, P_seq = np.zeros(n), P
    for rows in np.split(np.arange(30), 5):
        # a later update linearises about the corrected state: its residual is r - H dx (a linear model)
        d, P_seq = kalman_update(P_seq, H[rows], r[rows] - H[rows] @ dx_seq, 1e-3)
        dx_seq = dx_seq + d
        assert np.linalg.eigvalsh(P_seq).min() > 0
    np.testing.assert_allclose(P_seq, P_batch, atol=1e-10)
    np.testing.assert_allclose(dx_seq, dx_batch, atol=1e-8)


def test_kalman_update_with_no_rows(rng):
    P = random_spd(rng, 4)
    dx, P_new = kalman_update(P, np.zeros((0, 4)), np.zeros(0), 1.0)
    np.testing.assert_array_equal(dx, 0.0)
    np.testing.assert_array_equal(P_new, P)


# ---------------------------------------------------------------- the pieces together


def test_update_pipeline_reduces_camera_pose_error(rng):
    # one feature seen by 6 cameras whose pose errors are drawn from P: the update must shrink them on average
    n_cams, state_dim, var = 6, 51, SIGMA**2
    P = np.eye(state_dim) * 1e-6
    P[15:, 15:] = np.kron(np.eye(n_cams), np.diag([1e-4] * 3 + [1e-2] * 3))
    before, after = [], []
    for _ in range(30):
        R_true, p_true, p_F, idx = window_and_feature(rng, n_cams, observers=range(n_cams))
        err = rng.normal(size=state_dim) * np.sqrt(np.diag(P))  # P is diagonal
        cols = camera_error_column(idx)
        # estimate = truth minus the error (δx = x_true - x_est)
        R_est = np.stack([Rotation.from_rotvec(err[c:c + 3]).as_matrix() @ R_true[i] for i, c in enumerate(cols)])
        p_est = p_true - np.stack([err[c + 3:c + 6] for c in cols])
        obs = measure(R_true, p_true, p_F).reshape(-1, 2) + rng.normal(scale=SIGMA, size=(n_cams, 2))
        r, H_x, H_f = feature_jacobians(R_est, p_est, cols, p_F, obs, state_dim)
        H_o, r_o = nullspace_project(H_x, H_f, r)
        T_H, r_q = measurement_compress(H_o, r_o)
        dx, P_new = kalman_update(P, T_H, r_q, var)
        before.append(err @ np.linalg.solve(P, err))
        after.append((err - dx) @ np.linalg.solve(P, err - dx))
        assert np.trace(P_new) < np.trace(P)
    assert np.mean(after) < np.mean(before)


def test_triangulated_features_with_exact_poses_pass_the_gate_95_percent(rng):
    # with exact camera poses (P = 0) and the feature triangulated from the same noisy measurements, the projected
    # residual is white noise with 2M - 3 degrees of freedom: the gate must pass ~95% of these correct features
    trials, n_cams = 2000, 6
    state_dim = 15 + 6 * n_cams
    cases, tracks = [], []
    for _ in range(trials):
        M = int(rng.integers(3, n_cams + 1))
        R_all, p_all, p_F, _ = window_and_feature(rng, n_cams)
        idx = np.sort(rng.choice(n_cams, size=M, replace=False))
        obs = measure(R_all[idx], p_all[idx], p_F).reshape(-1, 2) + rng.normal(scale=SIGMA, size=(M, 2))
        cases.append((R_all[idx], p_all[idx], camera_error_column(idx), obs))
        tracks.append((R_all[idx], p_all[idx], obs))
    results = triangulate_inverse_depth_batch(tracks)
    P = np.zeros((state_dim, state_dim))
    passed = used = 0
    for (R, p, cols, obs), result in zip(cases, results):
        if not result.success:
            continue
        used += 1
        r, H_x, H_f = feature_jacobians(R, p, cols, result.p_FinG, obs, state_dim)
        H_o, r_o = nullspace_project(H_x, H_f, r)
        passed += chi_square_gate(H_o, r_o, P, SIGMA**2)[0]
    assert used > 0.98 * trials
    print(f"gate pass rate of correct triangulated features: {passed / used:.3f} ({used} features)")
    assert abs(passed / used - 0.95) < 0.02


# ---------------------------------------------------------------- bad input


def test_bad_input_raises(rng):
    R_all, p_all, p_F, idx = window_and_feature(rng, 4, observers=(0, 1))
    R, p = R_all[idx], p_all[idx]
    obs = measure(R, p, p_F).reshape(-1, 2)
    with pytest.raises(ValueError, match=r"obs_xy must have shape \(2, 2\)"):
        feature_jacobians(R, p, [15, 21], p_F, obs[:1], 39)
    with pytest.raises(ValueError, match=r"p_FinG must have shape \(3,\)"):
        feature_jacobians(R, p, [15, 21], p_F[:2], obs, 39)
    with pytest.raises(ValueError, match="p_FinG must contain only finite"):
        feature_jacobians(R, p, [15, 21], [np.nan, 0, 5], obs, 39)
    with pytest.raises(ValueError, match="cam_columns must be distinct"):
        feature_jacobians(R, p, [15, 15], p_F, obs, 39)
    with pytest.raises(ValueError, match=r"column \+ 6 <= state_dim"):
        feature_jacobians(R, p, [15, 36], p_F, obs, 39)
    with pytest.raises(ValueError, match=r"cam_columns must be \(2,\) integers"):
        feature_jacobians(R, p, [15.0, 21.0], p_F, obs, 39)
    with pytest.raises(ValueError, match="state_dim must be an integer"):
        feature_jacobians(R, p, [15, 21], p_F, obs, 3)
    with pytest.raises(ValueError, match="in front of every camera"):
        feature_jacobians(R, p, [15, 21], p_F * [1, 1, -1], obs, 39)
    with pytest.raises(ValueError, match="R_GtoC must hold rotation matrices"):
        feature_jacobians(R + 0.1, p, [15, 21], p_F, obs, 39)
    with pytest.raises(ValueError, match=r"H_f must have shape \(6, 3\)"):
        nullspace_project(np.zeros((6, 9)), np.zeros((5, 3)), np.zeros(6))
    with pytest.raises(ValueError, match=r"r must have shape \(2M,\) with 6 rows"):
        nullspace_project(np.zeros((6, 9)), np.zeros((6, 3)), np.zeros(5))
    with pytest.raises(ValueError, match="H_x must contain only finite"):
        nullspace_project(np.full((6, 9), np.nan), np.zeros((6, 3)), np.zeros(6))
    P = np.eye(9)
    with pytest.raises(ValueError, match=r"P must be a square covariance of shape \(9, 9\)"):
        chi_square_gate(np.zeros((3, 9)), np.zeros(3), np.eye(8), 1.0)
    with pytest.raises(ValueError, match="noise_var must be a positive finite number"):
        chi_square_gate(np.zeros((3, 9)), np.zeros(3), P, 0.0)
    with pytest.raises(ValueError, match=r"probability must be a number in \(0, 1\)"):
        chi_square_gate(np.zeros((3, 9)), np.zeros(3), P, 1.0, probability=1.5)
    with pytest.raises(ValueError, match="dof must be a positive integer"):
        chi_square_threshold(0)
    with pytest.raises(ValueError, match=r"r must have shape \(m,\) with 4 rows"):
        measurement_compress(np.zeros((4, 2)), np.zeros(3))
    with pytest.raises(ValueError, match=r"H must have shape \(m, 9\)"):
        kalman_update(P, np.zeros((2, 8)), np.zeros(2), 1.0)
    asym = np.eye(9)
    asym[0, 1] = 0.5
    with pytest.raises(ValueError, match="P must be symmetric"):
        kalman_update(asym, np.zeros((2, 9)), np.zeros(2), 1.0)
    with pytest.raises(ValueError, match="P must be positive semi-definite"):
        kalman_update(-np.eye(9), np.eye(9)[:2], np.zeros(2), 1e-3)
