"""The MSCKF measurement update as pure functions on arrays: feature Jacobians, nullspace projection, gating,
QR compression and the Joseph-form Kalman update (thesis §3.3.6.2-3.3.6.3, Eqs. 41-58).

Error state (fixed by the filter's state layout): the IMU block [δθ, δb_g, δv, δb_a, δp] (15 entries) followed,
for each camera state i in window order, by [δθ_Ci (3), δp_Ci (3)] at columns 15 + 6i. Attitude errors are
q_true = δq ⊗ q_est with δq ≈ [δθ/2, 1], hence R_GtoC_true ≈ (I - [δθ x]) R_GtoC_est, and
p_CinG_true = p_CinG + δp.

One feature j seen by M cameras gives z_i = [X/Z, Y/Z] of p_FinC_i = R_GtoC_i (p_FinG - p_CinG_i) (Eqs. 41-42) and::

    r_i = z_i,meas - z_i,hat ≈ H_Ci [δθ_Ci; δp_Ci] + H_fi δp_FinG + n_i                        (Eqs. 43-44)
    J_i = 1/Z [[1, 0, -X/Z], [0, 1, -Y/Z]]                                                       (Eq. 48)
    H_Ci = J_i [ [p_FinC_i x], -R_GtoC_i ],   H_fi = J_i R_GtoC_i                                (Eqs. 45-47)

(first order: p_FinC_true = (I - [δθ x]) R (p_F - p_C - δp) ≈ p_FinC + [p_FinC x] δθ - R δp). Projecting on the
left nullspace A of H_f removes the feature error (Eq. 50): r_o = A^T r = A^T H_x δx + A^T n, and A^T A = I keeps
the noise white with the same variance σ^2.
"""
from __future__ import annotations

from functools import lru_cache
from numbers import Integral, Real

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_factor, cho_solve
from scipy.stats import chi2

from evio_lib.msckf.triangulation import as_camera_poses

__all__ = [
    "IMU_ERROR_DIM",
    "CAMERA_ERROR_DIM",
    "camera_error_column",
    "feature_jacobians",
    "nullspace_project",
    "chi_square_threshold",
    "chi_square_gate",
    "gating_mean_shrink",
    "measurement_compress",
    "kalman_update",
]

IMU_ERROR_DIM = 15  # [δθ, δb_g, δv, δb_a, δp]
CAMERA_ERROR_DIM = 6  # [δθ_C, δp_C] per camera state
_SYM_TOL = 1e-6  # relative asymmetry of P tolerated (it is symmetrised anyway)


# ------------------------------------------------------------------------------------------------- input checks


def _matrix(value: ArrayLike, name: str, expected: str, ndim: int) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got {value!r}") from exc
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have shape {expected}; got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must contain only finite values (no NaN/inf); got non-finite entries")
    return arr


def _rows_match(arr: NDArray[np.float64], rows: int, name: str, expected: str) -> None:
    if arr.shape[0] != rows:
        raise ValueError(f"{name} must have shape {expected} with {rows} rows; got {arr.shape}")


def _noise_variance(noise_var: float) -> float:
    if isinstance(noise_var, bool) or not isinstance(noise_var, Real) or not (np.isfinite(noise_var) and noise_var > 0):
        raise ValueError(
            f"noise_var must be a positive finite number (σ^2 of one normalised coordinate); got {noise_var!r}"
        )
    return float(noise_var)


def _covariance(P: ArrayLike, n: int | None = None) -> NDArray[np.float64]:
    P = _matrix(P, "P", "(n, n)", 2)
    if P.shape[0] != P.shape[1] or (n is not None and P.shape[0] != n):
        want = f"({n}, {n})" if n is not None else "(n, n)"
        raise ValueError(f"P must be a square covariance of shape {want}; got {P.shape}")
    scale = max(float(np.abs(P).max()), 1e-300) if P.size else 1.0
    if P.size and float(np.abs(P - P.T).max()) > _SYM_TOL * scale:
        asym = float(np.abs(P - P.T).max())
        raise ValueError(f"P must be symmetric (|P - P^T| <= {_SYM_TOL:g} max|P|); got max |P - P^T| = {asym:.3g}")
    return P


# ----------------------------------------------------------------------------------------------- Jacobians


def camera_error_column(window_index: int | ArrayLike) -> int | NDArray[np.int64]:
    """Return the first error-state column of camera state(s) at ``window_index``: 15 + 6 i.

    Args:
        window_index: position(s) i of the camera state(s) in the sliding window (0 = oldest).

    >>> camera_error_column(0), camera_error_column([1, 2]).tolist()
    (15, [21, 27])
    """
    idx = np.asarray(window_index)
    if idx.dtype.kind not in "iu" or np.any(idx < 0):
        raise ValueError(f"window_index must be non-negative integer(s); got {window_index!r}")
    cols = IMU_ERROR_DIM + CAMERA_ERROR_DIM * idx.astype(np.int64)
    return int(cols) if cols.ndim == 0 else cols


def feature_jacobians(
    R_GtoC: ArrayLike,
    p_CinG: ArrayLike,
    cam_columns: ArrayLike,
    p_FinG: ArrayLike,
    obs_xy: ArrayLike,
    state_dim: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Return (r (2M,), H_x (2M, state_dim), H_f (2M, 3)): residual and Jacobians of one feature seen by M cameras.

    Args:
        R_GtoC: (M, 3, 3) rotations G -> C_i of the observing camera states, or (M, 4) JPL quaternions q_GtoC.
        p_CinG: (M, 3) their centres in G.
        cam_columns: (M,) first error-state column of each camera's [δθ_C, δp_C] block (15 + 6 * window index,
            see :func:`camera_error_column`); distinct, with column + 6 <= state_dim.
        p_FinG: (3,) the triangulated feature position in G; it must lie in front of every camera (Z > 0).
        obs_xy: (M, 2) measured undistorted normalised coordinates (x, y).
        state_dim: size of the error state, 15 + 6 N.

    Rows 2i and 2i+1 belong to camera i (x, y). r_i = z_meas - [X/Z, Y/Z] (Eq. 43); H_x holds J_i [[p_FinC_i x],
    -R_GtoC_i] at columns cam_columns[i]..+6 and zeros elsewhere (Eqs. 45, 47, 48); H_f = J_i R_GtoC_i (Eq. 46).
    Reference: thesis §3.3.6.2; Mourikis & Roumeliotis, ICRA 2007.

    >>> r, H_x, H_f = feature_jacobians(np.eye(3)[None], np.zeros((1, 3)), [15], [0.0, 0.0, 2.0], [[0.01, 0.0]], 21)
    >>> r.tolist(), H_x.shape, H_f.round(3).tolist()
    ([0.01, 0.0], (2, 21), [[0.5, 0.0, 0.0], [0.0, 0.5, 0.0]])
    """
    R, p = as_camera_poses(R_GtoC, p_CinG)
    M = R.shape[0]
    if M == 0:
        raise ValueError("R_GtoC must hold at least one observing camera; got 0")
    z = _matrix(obs_xy, "obs_xy", "(M, 2)", 2)
    if z.shape != (M, 2):
        raise ValueError(f"obs_xy must have shape ({M}, 2), one row per camera; got {z.shape}")
    p_F = _matrix(p_FinG, "p_FinG", "(3,)", 1)
    if p_F.shape != (3,):
        raise ValueError(f"p_FinG must have shape (3,); got {p_F.shape}")
    if isinstance(state_dim, bool) or not isinstance(state_dim, Integral) or state_dim < CAMERA_ERROR_DIM:
        raise ValueError(f"state_dim must be an integer >= {CAMERA_ERROR_DIM} (15 + 6 N); got {state_dim!r}")
    cols = np.asarray(cam_columns)
    if cols.shape != (M,) or cols.dtype.kind not in "iu":
        raise ValueError(
            f"cam_columns must be ({M},) integers, one per camera; got shape {cols.shape} dtype {cols.dtype}"
        )
    cols = cols.astype(np.int64)
    if np.any(cols < 0) or np.any(cols + CAMERA_ERROR_DIM > state_dim):
        raise ValueError(
            f"cam_columns must satisfy 0 <= column and column + 6 <= state_dim ({state_dim}); got {cols.tolist()}"
        )
    ordered = np.sort(cols)
    if np.any(ordered[1:] == ordered[:-1]):
        raise ValueError(f"cam_columns must be distinct (one observation per camera state); got {cols.tolist()}")

    p_FinC = np.einsum("mij,mj->mi", R, p_F - p)  # p_FinC_i = R_GtoC_i (p_FinG - p_CinG_i)    (Eq. 42)
    Z = p_FinC[:, 2]
    if np.any(Z <= 1e-9):
        k = int(np.argmin(Z))
        raise ValueError(f"p_FinG must lie in front of every camera (Z > 0); got Z = {Z[k]:.3g} in camera {k}")
    inv_Z = 1.0 / Z
    z_hat = p_FinC[:, :2] * inv_Z[:, None]  # z_hat = [X/Z, Y/Z]                               (Eq. 41)
    r = (z - z_hat).reshape(-1)  # r = z_meas - z_hat                                           (Eq. 43)

    # J_i = 1/Z [[1, 0, -x], [0, 1, -y]] (Eq. 48) with (x, y) = z_hat_i; then (Eqs. 46-47)
    #   H_fi = J_i R_GtoC_i = [R_row0 - x R_row2; R_row1 - y R_row2] / Z
    #   J_i [p_FinC_i x] = [[x y, -(1 + x^2), y], [1 + y^2, -x y, -x]]   (p_FinC = Z [x, y, 1]; Z cancels)
    x, y = z_hat[:, 0], z_hat[:, 1]
    H_f_blocks = (R[:, :2, :] - z_hat[:, :, None] * R[:, 2:3, :]) * inv_Z[:, None, None]
    blocks = np.empty((M, 2, CAMERA_ERROR_DIM))  # [∂z/∂δθ_Ci, ∂z/∂δp_Ci] per camera
    xy = x * y
    blocks[:, 0, 0] = xy
    blocks[:, 0, 1] = -1.0 - x * x
    blocks[:, 0, 2] = y
    blocks[:, 1, 0] = 1.0 + y * y
    blocks[:, 1, 1] = -xy
    blocks[:, 1, 2] = -x
    blocks[:, :, 3:] = -H_f_blocks  # ∂z/∂δp_Ci = -J_i R_GtoC_i
    H_x = np.zeros((2 * M, state_dim))
    # flat index of H_x[2 i + k, cols_i + j] for camera i, row k, block column j
    flat = (np.arange(2 * M).reshape(M, 2, 1) * state_dim + cols[:, None, None]) + np.arange(CAMERA_ERROR_DIM)
    H_x.reshape(-1)[flat] = blocks
    return r, H_x, H_f_blocks.reshape(2 * M, 3)


# ---------------------------------------------------------------------------------------- nullspace projection


def nullspace_project(
    H_x: ArrayLike, H_f: ArrayLike, r: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (H_o (2M - 3, n), r_o (2M - 3,)) = (A^T H_x, A^T r), A a basis of the left nullspace of H_f (Eq. 50).

    Args:
        H_x: (2M, n) Jacobian of the stacked measurements wrt the error state.
        H_f: (2M, 3) Jacobian wrt the feature position.
        r: (2M,) stacked residual.

    From the complete QR factorisation H_f = Q [T; 0] (Q orthogonal (2M, 2M)), A = Q[:, 3:] satisfies A^T H_f = 0 and
    A^T A = I exactly, for any rank of H_f (a rank-deficient H_f merely discards a little more information). When
    2M <= 3 nothing is left: (0, n) and (0,) arrays. Reference: thesis Eq. 50; Mourikis & Roumeliotis 2007.

    >>> H_o, r_o = nullspace_project(np.eye(4)[:, :2], np.eye(4)[:, :3], np.arange(4.0))
    >>> H_o.shape, np.abs(r_o).round(6).tolist()
    ((1, 2), [3.0])
    """
    H_x = _matrix(H_x, "H_x", "(2M, n)", 2)
    m = H_x.shape[0]
    H_f = _matrix(H_f, "H_f", "(2M, 3)", 2)
    if H_f.shape != (m, 3):
        raise ValueError(f"H_f must have shape ({m}, 3) to match H_x's {m} rows; got {H_f.shape}")
    r = _matrix(r, "r", "(2M,)", 1)
    _rows_match(r, m, "r", "(2M,)")
    if m <= 3:
        return np.zeros((0, H_x.shape[1])), np.zeros(0)
    Q, _ = np.linalg.qr(H_f, mode="complete")
    A = Q[:, 3:]  # columns of Q beyond rank 3 span the left nullspace: A^T H_f = 0, A^T A = I
    return A.T @ H_x, A.T @ r


# ------------------------------------------------------------------------------------------------- gating


@lru_cache(maxsize=1024)
def _chi2_quantile(dof: int, probability: float) -> float:
    return float(chi2.ppf(probability, dof))


def chi_square_threshold(dof: int, probability: float = 0.95) -> float:
    """Return the chi-square quantile chi2.ppf(probability, dof) (cached; scipy.stats is slow per call).

    Args:
        dof: degrees of freedom (rows of the projected residual), >= 1.
        probability: the quantile, in (0, 1); 0.95 accepts 95% of correct features.

    >>> round(chi_square_threshold(2), 4)
    5.9915
    """
    if isinstance(dof, bool) or not isinstance(dof, Integral) or dof < 1:
        raise ValueError(f"dof must be a positive integer; got {dof!r}")
    if isinstance(probability, bool) or not isinstance(probability, Real) or not 0.0 < probability < 1.0:
        raise ValueError(f"probability must be a number in (0, 1); got {probability!r}")
    return _chi2_quantile(int(dof), float(probability))


def gating_mean_shrink(dof: int, probability: float = 0.95) -> float:
    """Return the factor by which a chi-square gate shrinks the mean of the residuals it lets through.

    A correct feature's whitened residual is r = μ + n with n ~ N(0, I_k) and μ = H δx the part explained by the
    state error. Keeping r only when |r|^2 < c = chi2.ppf(probability, k) gives, to first order in μ,

        E[r | |r|^2 < c] = s μ,   s = F_{k+2}(c) / F_k(c) = F_{k+2}(c) / probability

    (differentiate E[r 1{|r|^2 < c}] at μ = 0: E[n n^T 1{|n|^2 < c}] = F_{k+2}(c) I, because
    E[χ²_k 1{χ²_k < c}] = k F_{k+2}(c)). The update then corrects only a fraction s of the error it sees while the
    covariance shrinks as if it had corrected all of it, so gating correct data makes the filter overconfident.
    S-MSCKF's pruning updates have k = 1 (two observations, 4 rows minus 3): at 95 % s = 0.76, a 24 % under-correction
    on every row; at 99.9 % s = 0.988. Gating on a whole track (more rows) shrinks less: 0.97 at 95 % for 20
    observations (dof 37). See ``MsckfConfig`` for what this does to the filter's consistency.

    >>> round(gating_mean_shrink(1, 0.95), 3), round(gating_mean_shrink(1, 0.999), 3)
    (0.759, 0.988)
    """
    c = chi_square_threshold(dof, probability)
    return float(chi2.cdf(c, int(dof) + 2) / chi2.cdf(c, int(dof)))


def chi_square_gate(
    H_o: ArrayLike, r_o: ArrayLike, P: ArrayLike, noise_var: float, probability: float = 0.95
) -> tuple[bool, float]:
    """Return (passed, gamma): the Mahalanobis test of one feature's projected residual.

    Args:
        H_o: (m, n) projected Jacobian of the feature (from :func:`nullspace_project`).
        r_o: (m,) projected residual.
        P: (n, n) error-state covariance.
        noise_var: σ^2 of one normalised image coordinate (pixel σ / focal length, squared).
        probability: chi-square quantile of the test (0.95; msckf_vio's own table takes the 5% quantile by mistake).

    gamma = r_o^T (H_o P H_o^T + σ^2 I)^-1 r_o (Cholesky solve), passed = gamma < chi2.ppf(probability, m)
    (S-MSCKF, Sun et al. 2018). With m = 0 there is nothing to test: returns (False, 0.0) so the feature is dropped.

    >>> chi_square_gate(np.eye(2), [0.1, 0.0], np.eye(2), 1.0)
    (True, 0.005)
    """
    H_o = _matrix(H_o, "H_o", "(m, n)", 2)
    r_o = _matrix(r_o, "r_o", "(m,)", 1)
    _rows_match(r_o, H_o.shape[0], "r_o", "(m,)")
    P = _covariance(P, H_o.shape[1])
    noise_var = _noise_variance(noise_var)
    threshold = chi_square_threshold(max(H_o.shape[0], 1), probability)
    if H_o.shape[0] == 0:
        return False, 0.0
    S = H_o @ P @ H_o.T
    S.flat[:: S.shape[0] + 1] += noise_var  # S = H P H^T + σ^2 I (on the diagonal)
    try:
        w = np.linalg.solve(np.linalg.cholesky(S), r_o)  # S = L L^T  ->  gamma = |L^-1 r_o|^2
    except np.linalg.LinAlgError as exc:
        raise ValueError("P must be positive semi-definite: H_o P H_o^T + σ^2 I is not positive definite") from exc
    gamma = float(w @ w)
    return bool(gamma < threshold), gamma


# ----------------------------------------------------------------------------------------- QR compression


def measurement_compress(H: ArrayLike, r: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (T_H, r_q): the stacked system compressed by QR when it has more rows than columns (Eqs. 51-55).

    Args:
        H: (m, n) stacked projected Jacobians H_o of all features of this update.
        r: (m,) stacked projected residuals r_o.

    With H = [Q1 Q2] [T_H; 0], r_q = Q1^T r and T_H (n, n) upper triangular; the discarded Q2^T r is pure noise and
    Q1^T n keeps covariance σ^2 I, so the update is unchanged (H^T H = T_H^T T_H, H^T r = T_H^T r_q). Computed as the
    R factor of [H | r] (Q is never formed). When m <= n the inputs are returned (as copies).

    >>> T_H, r_q = measurement_compress(np.ones((3, 1)), np.array([1.0, 2.0, 3.0]))
    >>> np.abs(T_H).round(6).tolist(), np.abs(r_q).round(6).tolist()
    ([[1.732051]], [3.464102])
    """
    H = _matrix(H, "H", "(m, n)", 2)
    r = _matrix(r, "r", "(m,)", 1)
    _rows_match(r, H.shape[0], "r", "(m,)")
    m, n = H.shape
    if m <= n:
        return H.copy(), r.copy()
    # [H | r] = Q [[T_H, r_q], [0, s]]  ->  H = Q1 T_H and Q1^T r = r_q         (Eqs. 52-55)
    R_aug = np.linalg.qr(np.column_stack([H, r]), mode="r")
    return np.triu(R_aug[:n, :n]), R_aug[:n, n].copy()


# ----------------------------------------------------------------------------------------------- Kalman update


def kalman_update(
    P: ArrayLike, H: ArrayLike, r: ArrayLike, noise_var: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (dx (n,), P_new (n, n)): the EKF correction and the Joseph-form updated covariance (Eqs. 56-58).

    Args:
        P: (n, n) symmetric positive-definite error-state covariance.
        H: (m, n) measurement Jacobian (e.g. T_H from :func:`measurement_compress`).
        r: (m,) residual.
        noise_var: σ^2 of each residual entry (R = σ^2 I).

    S = H P H^T + σ^2 I; K = P H^T S^-1 by a Cholesky solve (S K^T = H P, no inverse); dx = K r;
    P_new = (I - K H) P (I - K H)^T + σ^2 K K^T, symmetrised ((P + P^T) / 2). m = 0 returns (0, copy of P).

    >>> dx, P_new = kalman_update(np.eye(2), np.array([[1.0, 0.0]]), np.array([2.0]), 1.0)
    >>> dx.round(6).tolist(), P_new.round(6).tolist()
    ([1.0, 0.0], [[0.5, 0.0], [0.0, 1.0]])
    """
    P = _covariance(P)
    n = P.shape[0]
    H = _matrix(H, "H", f"(m, {n})", 2)
    if H.shape[1] != n:
        raise ValueError(f"H must have shape (m, {n}) to match P; got {H.shape}")
    r = _matrix(r, "r", "(m,)", 1)
    _rows_match(r, H.shape[0], "r", "(m,)")
    noise_var = _noise_variance(noise_var)
    if H.shape[0] == 0:
        return np.zeros(n), P.copy()
    HP = H @ P
    S = HP @ H.T
    S.flat[:: S.shape[0] + 1] += noise_var  # S = H P H^T + σ^2 I (on the diagonal)
    S = 0.5 * (S + S.T)
    try:
        # K = P H^T S^-1, i.e. S K^T = H P (S and P symmetric)                             (Eq. 56)
        K = cho_solve(cho_factor(S, lower=True, check_finite=False), HP, check_finite=False).T
    except np.linalg.LinAlgError as exc:
        raise ValueError("P must be positive semi-definite: the innovation covariance H P H^T + σ^2 I is not") from exc
    dx = K @ r  # Δx = K r                                                                  (Eq. 57)
    # Joseph form (Eq. 58) multiplied out, which holds for any gain K:
    #   (I - K H) P (I - K H)^T + σ^2 K K^T = P - K (H P) - (K (H P))^T + K S K^T,   S = H P H^T + σ^2 I
    # O(n^2 m) instead of the two n x n products' O(n^3) (the time per update: docs/results/speed.md, "The filter").
    KHP = K @ HP
    P_new = P - KHP - KHP.T + (K @ S) @ K.T
    return dx, 0.5 * (P_new + P_new.T)
