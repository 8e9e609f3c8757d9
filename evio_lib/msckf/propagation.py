"""IMU propagation of the MSCKF: nominal state integration and error-state covariance propagation (thesis §3.3.4).

Nominal dynamics (thesis Eq. 31), with bias-corrected measurements ω = ω_m - b_g and a = a_m - b_a::

    dq_GtoI/dt = ½ Ω(ω) q_GtoI,   db_g/dt = 0,   dv_IinG/dt = R_ItoG a + g_G,   db_a/dt = 0,   dp_IinG/dt = v_IinG

Integration, per IMU interval [t_k, t_k+1] of length h, with the measurements interpolated linearly in between:
the quaternion does not depend on v or p, so the RK4 stages of Eq. 31 only need q at t_k, t_k + h/2 and t_k+1. These
come from the closed-form zeroth-order integrator q(t + τ) = quat_from_rotvec(ω̄ τ) ⊗ q(t) on each half interval,
ω̄ being the mean of the linear rate there ((3ω_k + ω_k+1)/4, then (ω_k + 3ω_k+1)/4); v and p then follow RK4,
which for dv/dt = f(t) reduces to Simpson's rule::

    f = R_ItoG a + g_G at t_k, t_k + h/2, t_k+1
    v_k+1 = v_k + h/6 (f_k + 4 f_mid + f_k+1),     p_k+1 = p_k + h v_k + h²/6 (f_k + 2 f_mid)

Quaternions are renormalised after the chain (the map is linear in q, so this equals renormalising every step).

Error-state model (thesis Eqs. 33-35), x~ = [δθ, δb_g, δv, δb_a, δp], noise n = [n_g, n_wg, n_a, n_wa]::

    F = [[-[ω x], -I, 0, 0, 0], [0]*5, [-R_ItoG [a x], 0, 0, -R_ItoG, 0], [0]*5, [0, 0, I, 0, 0]]
    G = [[-I, 0, 0, 0], [0, I, 0, 0], [0, 0, -R_ItoG, 0], [0, 0, 0, I], [0]*4]

Discretisation over each interval, with F and G frozen at its midpoint (ω, a, R_ItoG at t_k + h/2):

* Φ = exp(F h) (Eq. 36) in closed form. With Θ = [ω x] h, φ = |ω| h and c_j(φ) = Σ_m (-φ²)^m / (2m + j)!
  (c_1 = sin φ / φ, c_2 = (1 - cos φ) / φ², ...), the repeated integrals Γ_n = ∫…∫ exp(-[ω x] s) of the attitude
  block are Γ_n = h^n (I / n! - c_n+1 Θ + c_n+2 Θ²) and, with A = -R_ItoG [a x],
  Φ_θθ = Γ0, Φ_θbg = -Γ1, Φ_vθ = A Γ1, Φ_vbg = -A Γ2, Φ_vba = -R_ItoG h, Φ_pθ = A Γ2, Φ_pbg = -A Γ3,
  Φ_pv = I h, Φ_pba = -R_ItoG h²/2, identity on the diagonal. Exact for constant F (tested against scipy expm).
* Q_d = ∫_0^h Φ(s) G Q_IMU G^T Φ(s)^T ds (Eq. 37) by 3-point Gauss-Legendre quadrature with the closed-form Φ(s),
  kept as a square-root factor X (Q_d = X X^T). Exact for polynomial integrands up to degree 5, i.e. for ω = 0 in
  every term but the negligible gyro-random-walk-to-position one (degree 6); against Van Loan's matrix-exponential
  method the error, normalised by sqrt(Q_ii Q_jj), is < 1e-12 for dt <= 5 ms and ~5e-11 at 20 ms.
* Covariance (Eqs. 38-40): the recursion P_II <- Φ_k P_II Φ_k^T + Q_d,k over the K intervals of one call is
  evaluated unrolled, P_II <- Φ_tot P_II Φ_tot^T + Σ_k S_k Q_d,k S_k^T with S_k = Φ_K-1 ... Φ_k+1 and
  Φ_tot = Φ_K-1 ... Φ_0 (the same in exact arithmetic; the sum is Y Y^T with Y = [S_k X_k], so it stays positive
  semi-definite); P_IC <- Φ_tot P_IC; P_CC is unchanged; P is symmetrised.

IMU gaps: the measurements are interpolated across any interval without samples, but what the platform
did there is unknown. An integration interval that lies in a data gap of length T > ``config.imu_max_gap`` (between
two samples, before the first sample or after the last one) gets extra white noise of density σ_g² T on the gyro
and σ_a² T on the accelerometer (``imu_gap_gyro_sigma``, ``imu_gap_accel_sigma``), so that over the whole gap
var δθ = σ_g² T² and var δv = σ_a² T², as for a constant unseen deviation of std σ (and var δp = σ_a² T⁴ / 3);
the couplings (attitude into velocity through the specific force, velocity into position) follow from Φ as for any
noise. A gap longer than ``config.imu_max_bridged_gap`` raises ``ImuGapError``: beyond it the attitude error would
be too large for the linearised model. Samples beyond the IMU's full scale (``accel_full_scale``,
``gyro_full_scale``) are refused (``Msckf.feed_imu`` drops them before they get here).

Speed: everything is vectorised over the samples of one call except a short loop of one 15x15 product per sample
(the suffix products of the Φs); the quaternion chain uses recursive doubling.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import as_float_array, skew, skew_unchecked
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.state import (
    BA,
    BG,
    IMU_DIM,
    POS,
    THETA,
    VEL,
    FilterState,
    ImuState,
    _filter_state_unchecked,
    _frozen,
    _unchecked,
)

__all__ = [
    "ImuGapError",
    "imu_gaps",
    "PropagationSteps",
    "TransitionHook",
    "error_state_jacobians",
    "transition_matrix",
    "discrete_noise_covariance",
    "propagate_covariance",
    "integrate_imu",
    "propagate",
]

_GL_NODES = 3  # exact for polynomial integrands of degree <= 5
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_GL_NODES)  # Gauss-Legendre nodes / weights on [-1, 1]
_SERIES_MAX_PHI = 1.0  # below this rotation angle the c_j(φ) come from their power series
_SERIES_TERMS = 10  # φ^20 / 20! < 5e-19 for φ < 1
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)
_INV_FACT = np.array([1.0, 1.0, 0.5, 1.0 / 6.0])  # 1 / k!, k = 0..3
_EYE15 = np.eye(IMU_DIM)
_EYE15.setflags(write=False)


@dataclass(frozen=True, eq=False)
class PropagationSteps:
    """What one ``propagate`` call integrated, for a ``transition_hook`` (e.g. the OC-EKF's Φ modification).

    K intervals between K + 1 nodes (node 0 = the state before the call, node K = t_target).

    Attributes:
        t: (K + 1,) node times, s.
        dt: (K,) interval lengths, s.
        w_hat: (K, 3) bias-corrected angular rate at each interval's midpoint (the ω of F), rad/s, in I.
        a_hat: (K, 3) bias-corrected specific force at each midpoint (the a of F), m/s^2, in I.
        R_ItoG_mid: (K, 3, 3) orientation at each midpoint (the R_ItoG of F and G).
        q_GtoI, v_IinG, p_IinG: (K + 1, 4 / 3 / 3) nominal IMU states at the nodes.
        q_GtoI_prev, v_IinG_prev, p_IinG_prev: (K, 4 / 3 / 3) first estimates at the start of each interval:
            the incoming state's *_null values for the first, the predicted nodes 1..K-1 after that (S-MSCKF).
        gravity_G: (3,) gravity used, m/s^2.
    """

    t: NDArray[np.float64]
    dt: NDArray[np.float64]
    w_hat: NDArray[np.float64]
    a_hat: NDArray[np.float64]
    R_ItoG_mid: NDArray[np.float64]
    q_GtoI: NDArray[np.float64]
    v_IinG: NDArray[np.float64]
    p_IinG: NDArray[np.float64]
    q_GtoI_prev: NDArray[np.float64]
    v_IinG_prev: NDArray[np.float64]
    p_IinG_prev: NDArray[np.float64]
    gravity_G: NDArray[np.float64]


TransitionHook = Callable[[NDArray[np.float64], PropagationSteps], NDArray[np.float64]]


class ImuGapError(ValueError):
    """Raised when a propagation would cross an IMU gap longer than ``MsckfConfig.imu_max_bridged_gap``.

    Attributes:
        start, end: the gap, s (the last sample before it, or the state time when the IMU starts late; the first
            sample after it, or the target time when the IMU ends early).
    """

    def __init__(self, message: str, start: float, end: float) -> None:
        super().__init__(message)
        self.start = start
        self.end = end


# ------------------------------------------------------------------------------------------------------ input checks
def _check_noise_psd(noise_psd: ArrayLike) -> NDArray[np.float64]:
    q = np.asarray(noise_psd, dtype=np.float64)
    if q.shape != (12,) or not np.all(np.isfinite(q)) or np.any(q < 0):
        raise ValueError(
            "noise_psd must be diag(Q_IMU), 12 finite values >= 0 for [n_g, n_wg, n_a, n_wa] "
            f"(e.g. MsckfConfig.continuous_noise_psd()); got shape {q.shape}"
        )
    return q


# ------------------------------------------------------------------------------------------------------ F, G, Φ, Q_d
def error_state_jacobians(
    R_ItoG: ArrayLike, w_hat: ArrayLike, a_hat: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (F (15, 15), G (15, 12)) of the continuous error-state dynamics dx~/dt = F x~ + G n (Eqs. 33-35).

    Args:
        R_ItoG: (3, 3) orientation of I in G.
        w_hat: (3,) bias-corrected angular rate ω = ω_m - b_g of I in I, rad/s.
        a_hat: (3,) bias-corrected specific force a = a_m - b_a in I, m/s^2.

    Error state [δθ, δb_g, δv, δb_a, δp] (attitude error in I: q_true = δq ⊗ q_est); noise
    [n_g, n_wg, n_a, n_wa].

    >>> F, G = error_state_jacobians(np.eye(3), [0.0, 0.0, 1.0], [0.0, 0.0, 9.81])
    >>> F[0:3, 0:3] + 0.0, F[12:15, 6:9], G.shape
    (array([[ 0.,  1.,  0.],
           [-1.,  0.,  0.],
           [ 0.,  0.,  0.]]), array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]]), (15, 12))
    """
    R = as_float_array(R_ItoG, "R_ItoG", (3, 3))
    w = as_float_array(w_hat, "w_hat", (3,))
    a = as_float_array(a_hat, "a_hat", (3,))
    if R.shape != (3, 3) or w.shape != (3,) or a.shape != (3,):
        raise ValueError(
            f"R_ItoG, w_hat, a_hat must have shapes (3, 3), (3,), (3,); got {R.shape}, {w.shape}, {a.shape}"
        )
    F = np.zeros((IMU_DIM, IMU_DIM))
    F[THETA, THETA] = -skew(w)  # dδθ/dt = -[ω x] δθ - δb_g - n_g
    F[THETA, BG] = -_EYE3
    F[VEL, THETA] = -R @ skew(a)  # dδv/dt = -R_ItoG [a x] δθ - R_ItoG δb_a - R_ItoG n_a
    F[VEL, BA] = -R
    F[POS, VEL] = _EYE3  # dδp/dt = δv
    G = np.zeros((IMU_DIM, 12))
    G[THETA, 0:3] = -_EYE3
    G[BG, 3:6] = _EYE3  # dδb_g/dt = n_wg
    G[VEL, 6:9] = -R
    G[BA, 9:12] = _EYE3  # dδb_a/dt = n_wa
    return F, G


# c_j(φ) = Σ_m (-1)^m φ^2m / (2m + j)!, j = 1..5: coefficient table (5, terms) for the power series
_SERIES_COEF = np.array(
    [[(-1.0) ** m / math.factorial(2 * m + j) for m in range(_SERIES_TERMS)] for j in range(1, 6)]
)


def _c_coefficients(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return c_j(φ) = Σ_m (-φ²)^m / (2m + j)!, j = 1..5, shape (5, n); series below φ = 1, closed form above."""
    powers = np.power((phi * phi)[None, :], np.arange(_SERIES_TERMS)[:, None])  # φ^2m, (terms, n)
    c = _SERIES_COEF @ powers  # no cancellation for small φ
    big = np.flatnonzero(phi >= _SERIES_MAX_PHI)
    if big.size:  # closed form: c_1 = sin φ / φ, c_2 = (1 - cos φ) / φ², c_j+2 = (1 / j! - c_j) / φ²
        x = phi[big]
        x2 = x * x
        c[0, big] = np.sin(x) / x
        c[1, big] = (1.0 - np.cos(x)) / x2
        for j in (1, 2, 3):
            c[j + 1, big] = (1.0 / math.factorial(j) - c[j - 1, big]) / x2
    return c


def _gammas(w: NDArray[np.float64], tau: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return Γ (4, n, 3, 3) = [Γ0, Γ1, Γ2, Γ3] for rates w (n, 3) and times τ (n,).

    Γ_k(τ) = ∫_0^τ Γ_k-1(s) ds, Γ_0(τ) = exp(-[ω x] τ); in closed form
    Γ_k = τ^k (I / k! - c_k+1 Θ + c_k+2 Θ²) with Θ = [ω x] τ, φ = |ω| τ.
    """
    theta = skew_unchecked(w * tau[:, None])  # Θ = [ω x] τ
    theta2 = theta @ theta
    c = _c_coefficients(np.sqrt(np.einsum("ij,ij->i", w, w)) * np.abs(tau))[:, :, None, None]
    tau_k = np.power(tau[None, :], np.arange(4)[:, None])[:, :, None, None]  # τ^k, (4, n, 1, 1)
    # Γ_k = τ^k (I / k! - c_k+1 Θ + c_k+2 Θ²)
    return tau_k * (_INV_FACT[:, None, None, None] * _EYE3 - c[0:4] * theta + c[1:5] * theta2)


def _discretize(
    R_ItoG: NDArray[np.float64], w: NDArray[np.float64], a: NDArray[np.float64], dt: NDArray[np.float64],
    noise_psd: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """Return (Φ (K, 15, 15), X (K, 15, 12 n)) for K frozen (R_ItoG, ω, a) over dt (K,); no input checks.

    Φ = exp(F h) in closed form (Eq. 36). X is a square-root factor of Q_d (Eq. 37): Q_d,k = X_k X_k^T, from
    n-point Gauss-Legendre quadrature Q_d ≈ Σ_i (h w_i / 2) Φ(s_i) G Q G^T Φ(s_i)^T, with Φ(s) G read off the
    closed form (columns n_g, n_wg, n_a, n_wa; rows θ, b_g, v, b_a, p)::

        [[-Γ0,    -Γ1,    0,      0        ],
         [ 0,      I,     0,      0        ],
         [-A Γ1,  -A Γ2,  -R,     -R s     ],
         [ 0,      0,     0,      I        ],
         [-A Γ2,  -A Γ3,  -R s,   -R s²/2  ]]

    noise_psd: (12,) for all intervals or (K, 12) one per interval (e.g. inflated over IMU gaps); X is None when
    noise_psd is None.
    """
    K = dt.shape[0]
    m = 1 if noise_psd is None else 1 + _GL_NODES
    tau = np.empty((K, m))
    tau[:, 0] = dt  # Φ(h)
    if m > 1:
        tau[:, 1:] = 0.5 * dt[:, None] * (1.0 + _GL_X[None, :])  # quadrature nodes s_i on [0, h]
    gam = _gammas(np.repeat(w, m, axis=0), tau.reshape(-1)).reshape(4, K, m, 3, 3)
    A = (-R_ItoG @ skew_unchecked(a))[:, None]  # A = -R_ItoG [a x], (K, 1, 3, 3)
    AG1, AG2, AG3 = A @ gam[1], A @ gam[2], A @ gam[3]  # (K, m, 3, 3)

    Phi = np.zeros((K, IMU_DIM, IMU_DIM))
    diag = np.arange(IMU_DIM)
    Phi[:, diag, diag] = 1.0
    t1 = dt[:, None, None]
    Phi[:, THETA, THETA] = gam[0, :, 0]  # Φ_θθ = Γ0 = exp(-[ω x] h)
    Phi[:, THETA, BG] = -gam[1, :, 0]  # Φ_θbg = -Γ1
    Phi[:, VEL, THETA] = AG1[:, 0]  # Φ_vθ = A Γ1
    Phi[:, VEL, BG] = -AG2[:, 0]  # Φ_vbg = -A Γ2
    Phi[:, VEL, BA] = -R_ItoG * t1  # Φ_vba = -R_ItoG h
    Phi[:, POS, THETA] = AG2[:, 0]  # Φ_pθ = A Γ2
    Phi[:, POS, BG] = -AG3[:, 0]  # Φ_pbg = -A Γ3
    Phi[:, POS, VEL] = _EYE3 * t1  # Φ_pv = I h
    Phi[:, POS, BA] = -0.5 * R_ItoG * (t1 * t1)  # Φ_pba = -R_ItoG h² / 2
    if noise_psd is None:
        return Phi, None

    # X laid out (K, 15, n, 12) so that the reshape to (K, 15, 12 n) needs no copy; blocks per node are (K, n, 3, 3)
    n = _GL_NODES
    s1 = tau[:, 1:, None, None]  # (K, n, 1, 1) quadrature nodes
    R = np.broadcast_to(R_ItoG[:, None], (K, n, 3, 3))
    blocks = [  # (row block, noise column block, value of Φ(s_i) G per interval and node)
        (THETA, 0, -gam[0, :, 1:]), (THETA, 1, -gam[1, :, 1:]),
        (BG, 1, np.broadcast_to(_EYE3, (K, n, 3, 3))),
        (VEL, 0, -AG1[:, 1:]), (VEL, 1, -AG2[:, 1:]), (VEL, 2, -R), (VEL, 3, -R * s1),
        (BA, 3, np.broadcast_to(_EYE3, (K, n, 3, 3))),
        (POS, 0, -AG2[:, 1:]), (POS, 1, -AG3[:, 1:]), (POS, 2, -R * s1), (POS, 3, -0.5 * R * (s1 * s1)),
    ]
    # sqrt of the quadrature weight times the noise density: Q_d = Σ_i (h w_i / 2) Φ(s_i) G Q G^T Φ(s_i)^T = X X^T
    psd = noise_psd.reshape(-1, 1, 4, 3)  # (1 or K, 1, 4, 3)
    scale = np.sqrt((0.5 * dt[:, None] * _GL_W[None, :])[:, :, None, None] * psd)  # (K, n, 4, 3)
    X = np.zeros((K, IMU_DIM, n, 12))
    for rows, col, value in blocks:
        # X[k, r, i, 3 col + c] = value[k, i, r, c] * scale[k, i, col, c]
        X[:, rows, :, 3 * col:3 * col + 3] = (value * scale[:, :, col, None, :]).transpose(0, 2, 1, 3)
    return Phi, X.reshape(K, IMU_DIM, 12 * n)


def _frozen_inputs(
    R_ItoG: ArrayLike, w_hat: ArrayLike, a_hat: ArrayLike, dt: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], tuple[int, ...]]:
    """Validate and flatten the inputs of transition_matrix / discrete_noise_covariance to (n, ...) batches."""
    R = as_float_array(R_ItoG, "R_ItoG", (3, 3))
    w = as_float_array(w_hat, "w_hat", (3,))
    a = as_float_array(a_hat, "a_hat", (3,))
    h = np.asarray(dt, dtype=np.float64)
    batch = R.shape[:-2]
    if w.shape[:-1] != batch or a.shape[:-1] != batch or h.shape != batch:
        raise ValueError(
            "R_ItoG (..., 3, 3), w_hat (..., 3), a_hat (..., 3) and dt (...) must share leading dimensions; "
            f"got {R.shape}, {w.shape}, {a.shape}, {h.shape}"
        )
    if not np.all(np.isfinite(h)) or np.any(h < 0):
        raise ValueError(f"dt must be finite and >= 0 seconds; got {h}")
    return R.reshape(-1, 3, 3), w.reshape(-1, 3), a.reshape(-1, 3), h.reshape(-1), batch


def transition_matrix(R_ItoG: ArrayLike, w_hat: ArrayLike, a_hat: ArrayLike, dt: ArrayLike) -> NDArray[np.float64]:
    """Return Φ = exp(F dt) (..., 15, 15), the error-state transition for F frozen at (R_ItoG, ω, a) (Eq. 36).

    Args:
        R_ItoG: (..., 3, 3) orientation; w_hat: (..., 3) bias-corrected rate (rad/s, in I); a_hat: (..., 3)
            bias-corrected specific force (m/s^2, in I); dt: (...) interval, s (>= 0).

    Closed form of the module docstring (exact matrix exponential of the constant F of error_state_jacobians).

    >>> Phi = transition_matrix(np.eye(3), [0.0, 0.0, 0.0], [0.0, 0.0, 9.81], 0.1)
    >>> np.round(Phi[12:15, 3:6], 6) + 0.0       # Φ_pbg = -A Γ3 = R [a x] dt³/6
    array([[ 0.      , -0.001635,  0.      ],
           [ 0.001635,  0.      ,  0.      ],
           [ 0.      ,  0.      ,  0.      ]])
    """
    R, w, a, h, batch = _frozen_inputs(R_ItoG, w_hat, a_hat, dt)
    return _discretize(R, w, a, h, None)[0].reshape(batch + (IMU_DIM, IMU_DIM))


def discrete_noise_covariance(
    R_ItoG: ArrayLike, w_hat: ArrayLike, a_hat: ArrayLike, dt: ArrayLike, noise_psd: ArrayLike
) -> NDArray[np.float64]:
    """Return Q_d = ∫_0^dt Φ(s) G Q_IMU G^T Φ(s)^T ds (..., 15, 15) for F, G frozen at (R_ItoG, ω, a) (Eq. 37).

    Args:
        R_ItoG, w_hat, a_hat, dt: as in ``transition_matrix``.
        noise_psd: (12,) diag(Q_IMU) for [n_g, n_wg, n_a, n_wa] (``MsckfConfig.continuous_noise_psd()``).

    3-point Gauss-Legendre quadrature of the closed-form Φ(s) (module docstring).

    >>> Q = discrete_noise_covariance(np.eye(3), np.zeros(3), np.zeros(3), 2.0, np.r_[np.zeros(6), np.ones(6)])
    >>> round(float(Q[12, 12]), 6), round(float(Q[6, 12]), 6)  # ∫ s² + s⁴/4 ds = 8/3 + 8/5; ∫ s + s³/2 ds = 2 + 2
    (4.266667, 4.0)
    """
    q = _check_noise_psd(noise_psd)
    R, w, a, h, batch = _frozen_inputs(R_ItoG, w_hat, a_hat, dt)
    X = _discretize(R, w, a, h, q)[1]
    return (X @ X.transpose(0, 2, 1)).reshape(batch + (IMU_DIM, IMU_DIM))


def propagate_covariance(P: ArrayLike, Phi: ArrayLike, Q_d: ArrayLike) -> NDArray[np.float64]:
    """Return the propagated covariance (15 + 6N, 15 + 6N) of one step, partitioned as in thesis Eqs. 38-40.

    Args:
        P: (15 + 6N, 15 + 6N) covariance [[P_II, P_IC], [P_IC^T, P_CC]].
        Phi: (15, 15) IMU error-state transition; Q_d: (15, 15) its discrete noise covariance.

    P_II <- Φ P_II Φ^T + Q_d, P_IC <- Φ P_IC, P_CC unchanged, result symmetrised. (``propagate`` applies the
    same equations to a whole batch of steps at once.)
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1] or P.shape[0] < IMU_DIM or (P.shape[0] - IMU_DIM) % 6:
        raise ValueError(f"P must have shape (15 + 6N, 15 + 6N); got {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError("P must contain only finite values (no NaN/inf)")
    Phi = as_float_array(Phi, "Phi", (IMU_DIM, IMU_DIM))
    Q_d = as_float_array(Q_d, "Q_d", (IMU_DIM, IMU_DIM))
    if Phi.shape != (IMU_DIM, IMU_DIM) or Q_d.shape != (IMU_DIM, IMU_DIM):
        raise ValueError(f"Phi and Q_d must have shape (15, 15); got {Phi.shape} and {Q_d.shape}")
    out = P.copy()
    out[:IMU_DIM, :IMU_DIM] = Phi @ P[:IMU_DIM, :IMU_DIM] @ Phi.T + Q_d  # Eq. 38
    out[:IMU_DIM, IMU_DIM:] = Phi @ P[:IMU_DIM, IMU_DIM:]  # Eq. 40, P_IC
    out[IMU_DIM:, :IMU_DIM] = out[:IMU_DIM, IMU_DIM:].T
    return 0.5 * (out + out.T)


# ------------------------------------------------------------------------------------------------------ nominal state
def _left_matrix(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return L(q) (..., 4, 4) with q ⊗ p = L(q) p (JPL): [[qw I - [qv x], qv], [-qv^T, qw]]."""
    L = np.empty(q.shape[:-1] + (4, 4))
    L[..., :3, :3] = q[..., 3, None, None] * _EYE3 - skew_unchecked(q[..., :3])
    L[..., :3, 3] = q[..., :3]
    L[..., 3, :3] = -q[..., :3]
    L[..., 3, 3] = q[..., 3]
    return L


def _rot_ItoG(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return R_ItoG = C(q_GtoI)^T = (2 qw² - 1) I + 2 qw [qv x] + 2 qv qv^T (n, 3, 3) of unit quaternions (n, 4)."""
    qv, qw = q[:, :3], q[:, 3]
    R = 2.0 * qv[:, :, None] * qv[:, None, :] + (2.0 * qw)[:, None, None] * skew_unchecked(qv)
    R += (2.0 * qw * qw - 1.0)[:, None, None] * _EYE3
    return R


def _integrate(
    q0: NDArray[np.float64], v0: NDArray[np.float64], p0: NDArray[np.float64], t: NDArray[np.float64],
    w: NDArray[np.float64], a: NDArray[np.float64], g: NDArray[np.float64],
) -> tuple[NDArray[np.float64], ...]:
    """Integrate Eq. 31 over the nodes t (K + 1,) with bias-corrected w, a (K + 1, 3); see the module docstring.

    Returns q (K + 1, 4), v (K + 1, 3), p (K + 1, 3), R_ItoG_mid (K, 3, 3), w_mid (K, 3), a_mid (K, 3) (the
    last three at the interval midpoints).
    """
    h = np.diff(t)
    K = h.shape[0]
    half = 0.5 * h[:, None]
    w_mid = 0.5 * (w[:-1] + w[1:])
    a_mid = 0.5 * (a[:-1] + a[1:])
    # half-step rotation vectors with the mean rate of each half of the linear ω(t): first halves, then second halves
    rotvec = np.concatenate(((0.5 * (w[:-1] + w_mid)) * half, (0.5 * (w_mid + w[1:])) * half))
    angle = np.sqrt(np.einsum("ij,ij->i", rotvec, rotvec))
    # δq = [sin(|θ|/2) θ/|θ|, cos(|θ|/2)] (quat_from_rotvec), sin(x/2)/x = ½ sinc(x / 2π) with numpy's sinc
    dq = np.concatenate(((0.5 * np.sinc(angle / (2.0 * np.pi)))[:, None] * rotvec, np.cos(0.5 * angle)[:, None]), 1)
    Ls = _left_matrix(dq)
    L1 = Ls[:K]  # q(t_k + h/2) = δq1 ⊗ q(t_k)
    C = Ls[K:] @ L1  # q(t_k+1) = L_k q(t_k), L_k = L(δq2) L(δq1)
    # prefix products C_k = L_k ... L_0 by recursive doubling (log2 K batched 4x4 products instead of a K-loop)
    shift = 1
    while shift < K:
        C[shift:] = C[shift:] @ C[:-shift]
        shift *= 2
    q = np.empty((K + 1, 4))
    q[0] = q0
    q[1:] = C @ q0  # q_k+1 = C_k q_0
    q_all = np.concatenate((q, (L1 @ q[:-1, :, None])[..., 0]))  # nodes (K + 1) then midpoints (K)
    q_all /= np.linalg.norm(q_all, axis=1, keepdims=True)
    R_all = _rot_ItoG(q_all)
    f_all = np.einsum("nij,nj->ni", R_all, np.concatenate((a, a_mid))) + g  # f = R_ItoG a + g_G
    f, f_mid = f_all[: K + 1], f_all[K + 1:]
    hv = h[:, None]
    dv = hv / 6.0 * (f[:-1] + 4.0 * f_mid + f[1:])  # Simpson (RK4 with stages 2 = 3)
    v = np.empty((K + 1, 3))
    v[0] = v0
    np.cumsum(dv, axis=0, out=v[1:])
    v[1:] += v0
    dp = hv * v[:-1] + hv * hv / 6.0 * (f[:-1] + 2.0 * f_mid)  # p_k+1 - p_k
    p = np.empty((K + 1, 3))
    p[0] = p0
    np.cumsum(dp, axis=0, out=p[1:])
    p[1:] += p0
    return q_all[: K + 1], v, p, R_all[K + 1:], w_mid, a_mid


def integrate_imu(
    imu: ImuState, t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, gravity_G: ArrayLike = (0.0, 0.0, -9.81)
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Return the nominal (q_GtoI (K+1, 4), v_IinG (K+1, 3), p_IinG (K+1, 3)) at the sample times t (Eq. 31).

    Args:
        imu: initial state; it must be at t[0] (imu.timestamp == t[0]); its biases are held constant.
        t: (K + 1,) strictly increasing sample times, s.
        gyro, accel: (K + 1, 3) raw measurements (rad/s, m/s^2, in I), linearly interpolated between samples.
        gravity_G: (3,) gravity in G.

    Nominal part of ``propagate`` (no covariance), handy for IMU-only dead reckoning and lessons.

    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), [1.0, 0.0, 0.0], timestamp=0.0)
    >>> t = np.linspace(0.0, 1.0, 101)
    >>> q, v, p = integrate_imu(imu, t, np.zeros((101, 3)), np.tile([0.0, 0.0, 9.81], (101, 1)))
    >>> p[-1] + 0.0                                  # at rest in the air: uniform motion at 1 m/s
    array([1., 0., 0.])
    """
    if not isinstance(imu, ImuState):
        raise ValueError(f"imu must be an ImuState; got {type(imu).__name__}")
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError(f"t must have shape (K + 1,), K + 1 >= 2, finite and strictly increasing; got shape {t.shape}")
    if abs(t[0] - imu.timestamp) > 1e-12:
        raise ValueError(f"t[0] must equal imu.timestamp = {imu.timestamp!r}; got {t[0]!r}")
    gyro = as_float_array(gyro, "gyro", (3,))
    accel = as_float_array(accel, "accel", (3,))
    if gyro.shape != (t.shape[0], 3) or accel.shape != (t.shape[0], 3):
        raise ValueError(f"gyro and accel must have shape ({t.shape[0]}, 3); got {gyro.shape} and {accel.shape}")
    g = as_float_array(gravity_G, "gravity_G", (3,))
    q, v, p, *_ = _integrate(imu.q_GtoI, imu.v_IinG, imu.p_IinG, t, gyro - imu.b_g, accel - imu.b_a, g)
    return q, v, p


# ------------------------------------------------------------------------------------------------------ gaps
def _window(t_imu: NDArray[np.float64], t0: float, t_target: float) -> tuple[int, int, int, int]:
    """Return (lo, hi, j0, j1): samples j0..j1-1 lie strictly inside (t0, t_target); lo..hi-1 add one each side."""
    M = t_imu.shape[0]
    j0 = int(np.searchsorted(t_imu, t0, side="right"))
    j1 = int(np.searchsorted(t_imu, t_target, side="left"))
    return max(j0 - 1, 0), min(j1 + 1, M), j0, j1


def _gap_bounds(
    t_nodes: NDArray[np.float64], win_t: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (start (K,), end (K,)): the data gap each integration interval [t_k, t_k+1] lies in.

    start is the last sample at or before t_k (t_k itself when there is none), end the first sample at or after
    t_k+1 (t_k+1 when there is none); no sample lies strictly inside an interval.
    """
    mid = 0.5 * (t_nodes[:-1] + t_nodes[1:])
    i = np.searchsorted(win_t, mid)  # first sample > mid
    n = win_t.shape[0]
    start = np.where(i > 0, win_t[np.maximum(i - 1, 0)], t_nodes[:-1])
    end = np.where(i < n, win_t[np.minimum(i, n - 1)], t_nodes[1:])
    return start, end


def imu_gaps(imu_t: ArrayLike, t0: float, t_target: float, max_gap: float) -> NDArray[np.float64]:
    """Return (G, 2) [start, end] of the IMU gaps longer than max_gap that a propagation t0 -> t_target crosses.

    Args:
        imu_t: (M,) strictly increasing sample times, s.
        t0, t_target: the propagation's start and end, s (t0 <= t_target).
        max_gap: gaps longer than this are listed, s.

    A gap runs from the last sample before a stretch without samples to the first sample after it; with no sample
    before t0 (IMU starts late) it starts at t0, with none after t_target (IMU ends early) it ends at t_target.

    >>> imu_gaps([0.0, 0.01, 0.5, 0.51], 0.0, 0.6, 0.05)
    array([[0.01, 0.5 ],
           [0.51, 0.6 ]])
    """
    t_imu = np.asarray(imu_t, dtype=np.float64)
    if t_imu.ndim != 1 or t_imu.shape[0] < 1:
        raise ValueError(f"imu_t must have shape (M,) with M >= 1; got {t_imu.shape}")
    if not t0 <= t_target:
        raise ValueError(f"t0 must be <= t_target; got {t0!r} and {t_target!r}")
    if t_target == t0:
        return np.zeros((0, 2))
    lo, hi, j0, j1 = _window(t_imu, t0, t_target)
    t_nodes = np.concatenate(([t0], t_imu[j0:j1], [t_target]))
    start, end = _gap_bounds(t_nodes, t_imu[lo:hi])
    long = end - start > max_gap
    bounds = np.unique(np.column_stack((start[long], end[long])), axis=0)
    return bounds.reshape(-1, 2)


def _gap_description(start: float, end: float, first_sample: float, last_sample: float) -> str:
    """Return where a gap lies, in words (for messages)."""
    if start < first_sample:
        return f"the IMU data start late: first sample at t = {first_sample:.3f} s, state at t = {start:.3f} s"
    if end > last_sample:
        return f"the IMU data end early: last sample at t = {last_sample:.3f} s, propagating to t = {end:.3f} s"
    return f"no IMU samples between t = {start:.3f} s and t = {end:.3f} s"


# ------------------------------------------------------------------------------------------------------ propagate
def _signal_at(t: float, imu_t: NDArray[np.float64], values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return values linearly interpolated at time t (3,), holding the first / last sample outside imu_t."""
    i = int(np.searchsorted(imu_t, t, side="right"))
    if i == 0:
        return values[0]
    if i == imu_t.shape[0]:
        return values[-1]
    u = (t - imu_t[i - 1]) / (imu_t[i] - imu_t[i - 1])
    return (1.0 - u) * values[i - 1] + u * values[i]  # s(t) = (1 - u) s_i-1 + u s_i


def propagate(
    state: FilterState,
    imu_t: ArrayLike,
    imu_gyro: ArrayLike,
    imu_accel: ArrayLike,
    t_target: float,
    config: MsckfConfig,
    transition_hook: TransitionHook | None = None,
) -> FilterState:
    """Return the state propagated from state.timestamp to t_target with the IMU samples (thesis §3.3.4).

    Args:
        state: filter state at time t0 = state.timestamp.
        imu_t: (M,) strictly increasing IMU sample times, s. Only the samples around [t0, t_target] are read, so
            a whole log may be passed; include the last sample at or before t0 and the first at or after t_target,
            otherwise the nearest sample is held constant beyond the ends.
        imu_gyro: (M, 3) measured angular rate ω_m of I in I, rad/s.
        imu_accel: (M, 3) measured specific force a_m in I, m/s^2.
        t_target: time to propagate to, s (>= t0; typically the next image time).
        config: noise densities (``continuous_noise_psd``) and gravity.
        transition_hook: optional ``f(Phi (K, 15, 15), steps: PropagationSteps) -> Phi`` applied to the per-interval
            transition matrices before the covariance propagation (the OC-EKF modifies Φ there; Q_d is unchanged).

    The measurement signal is the piecewise-linear interpolation of the samples; the intervals are [t0, first
    sample > t0], sample to sample, and [last sample < t_target, t_target] (the partial last step is interpolated).
    The nominal state follows Eq. 31 (RK4, module docstring); the covariance follows Eqs. 36-40. The returned
    IMU state has timestamp t_target and its OC first estimates (*_null) set to the predicted values (S-MSCKF);
    camera poses are unchanged. Inputs are not modified.

    Guards (module docstring): samples beyond ``config.accel_full_scale`` / ``gyro_full_scale`` in the window raise
    ValueError; intervals in an IMU gap longer than ``config.imu_max_gap`` get inflated noise; a gap longer than
    ``config.imu_max_bridged_gap`` raises :class:`ImuGapError`. The result is not checked for finiteness and
    positive semi-definiteness here: ``Msckf`` does that after every step (``state.state_problem``).

    >>> from evio_lib.msckf.state import ImuState
    >>> cfg = MsckfConfig()
    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), timestamp=0.0)
    >>> s = FilterState.initial(imu, np.eye(3), np.zeros(3), cfg.initial_imu_covariance())
    >>> t = np.arange(0.0, 1.001, 0.005)                                   # 200 Hz, hovering (specific force = -g)
    >>> s1 = propagate(s, t, np.zeros((len(t), 3)), np.tile([0.0, 0.0, 9.81], (len(t), 1)), 0.5, cfg)
    >>> s1.timestamp, s1.imu.p_IinG + 0.0, round(float(np.sqrt(s1.P[12, 12])), 4)  # σ_x grows with δv, δb_a
    (0.5, array([0., 0., 0.]), 0.0538)
    """
    t_imu, gyro, accel, t_target = _checked_inputs(state, imu_t, imu_gyro, imu_accel, t_target, config)
    t0 = state.timestamp
    if t_target == t0:
        return state
    t_nodes, w_nodes, a_nodes, gap = _nodes(t_imu, gyro, accel, t0, t_target, config)
    imu = state.imu
    g = config.gravity
    q, v, p, R_mid, w_mid, a_mid = _integrate(
        imu.q_GtoI, imu.v_IinG, imu.p_IinG, t_nodes, w_nodes - imu.b_g, a_nodes - imu.b_a, g
    )
    dt = np.diff(t_nodes)
    Phi, X = _discretize(R_mid, w_mid, a_mid, dt, _gap_noise_psd(config, gap))  # Eq. 36; Q_d,k = X_k X_k^T (37)
    if transition_hook is not None:
        for arr in (t_nodes, dt, w_mid, a_mid, R_mid, q, v, p):
            _frozen(arr)  # the hook may read, not write, what the state is built from
        steps = PropagationSteps(
            t=t_nodes, dt=dt, w_hat=w_mid, a_hat=a_mid, R_ItoG_mid=R_mid, q_GtoI=q, v_IinG=v, p_IinG=p,
            q_GtoI_prev=np.vstack((imu.q_GtoI_null, q[1:-1])), v_IinG_prev=np.vstack((imu.v_IinG_null, v[1:-1])),
            p_IinG_prev=np.vstack((imu.p_IinG_null, p[1:-1])), gravity_G=g,
        )
        Phi = _hooked_transition(transition_hook, Phi, steps)
    P_new = _propagated_covariance(state, Phi, X)

    # predicted IMU state; its OC first estimates are the predicted values (S-MSCKF)
    q_new, v_new, p_new = (_frozen(x[-1].copy()) for x in (q, v, p))
    new_imu = _unchecked(
        ImuState, q_GtoI=q_new, b_g=imu.b_g, v_IinG=v_new, b_a=imu.b_a, p_IinG=p_new, timestamp=t_target,
        q_GtoI_null=q_new, v_IinG_null=v_new, p_IinG_null=p_new,
    )
    return _filter_state_unchecked(new_imu, state.cameras, P_new, state)


def _checked_inputs(
    state: FilterState, imu_t: ArrayLike, imu_gyro: ArrayLike, imu_accel: ArrayLike, t_target: float,
    config: MsckfConfig,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]:
    """Return (imu_t (M,), imu_gyro (M, 3), imu_accel (M, 3), t_target) of :func:`propagate` as arrays and a float,
    after its type, shape and time checks (ValueError)."""
    if not isinstance(state, FilterState):
        raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
    if not isinstance(config, MsckfConfig):
        raise ValueError(f"config must be an MsckfConfig; got {type(config).__name__}")
    t_imu = np.asarray(imu_t, dtype=np.float64)
    gyro = np.asarray(imu_gyro, dtype=np.float64)
    accel = np.asarray(imu_accel, dtype=np.float64)
    if t_imu.ndim != 1 or t_imu.shape[0] < 1:
        raise ValueError(f"imu_t must have shape (M,) with M >= 1; got {t_imu.shape}")
    M = t_imu.shape[0]
    if gyro.shape != (M, 3) or accel.shape != (M, 3):
        raise ValueError(
            f"imu_gyro and imu_accel must have shape (M, 3) = ({M}, 3); got {gyro.shape} and {accel.shape}"
        )
    t0 = state.timestamp
    if isinstance(t_target, bool) or not isinstance(t_target, (int, float, np.integer, np.floating)) \
            or not math.isfinite(t_target):
        raise ValueError(f"t_target must be a finite time in seconds; got {t_target!r}")
    t_target = float(t_target)
    if t_target < t0:
        raise ValueError(f"t_target must be >= state.timestamp = {t0!r} (no backward propagation); got {t_target!r}")
    return t_imu, gyro, accel, t_target


def _nodes(
    t_imu: NDArray[np.float64], gyro: NDArray[np.float64], accel: NDArray[np.float64], t0: float, t_target: float,
    config: MsckfConfig,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Return (t_nodes (K + 1,), w_nodes (K + 1, 3), a_nodes (K + 1, 3), gap (K,)): the integration nodes t0, the
    samples strictly inside (t0, t_target), t_target, the measurements there (interpolated at the ends) and the
    length of the data gap each interval lies in.

    Raises ValueError for non-finite or unordered samples in the window or samples beyond the IMU's full scale, and
    :class:`ImuGapError` for a gap longer than ``config.imu_max_bridged_gap``."""
    # samples strictly inside (t0, t_target), plus one on each side for the interpolated end points
    lo, hi, j0, j1 = _window(t_imu, t0, t_target)
    win_t, win_g, win_a = t_imu[lo:hi], gyro[lo:hi], accel[lo:hi]
    if not (np.all(np.isfinite(win_t)) and np.all(np.isfinite(win_g)) and np.all(np.isfinite(win_a))):
        raise ValueError("imu_t, imu_gyro and imu_accel must be finite around [state.timestamp, t_target]")
    if np.any(np.diff(win_t) <= 0.0):
        raise ValueError("imu_t must be strictly increasing")
    for name, values, limit, field in (("imu_accel", win_a, config.accel_full_scale, "accel_full_scale"),
                                       ("imu_gyro", win_g, config.gyro_full_scale, "gyro_full_scale")):
        beyond = np.abs(values) > limit
        if beyond.any():
            k = int(np.flatnonzero(beyond.any(axis=1))[0])
            raise ValueError(
                f"{name} holds {int(np.count_nonzero(beyond.any(axis=1)))} samples beyond the IMU's full scale "
                f"±{limit:.4g} ({field}) around [state.timestamp, t_target], the first at t = {win_t[k]:.3f} s "
                f"({values[k].tolist()}); drop them (Msckf.feed_imu does) or check the units (m/s^2, rad/s)"
            )
    t_nodes = np.concatenate(([t0], t_imu[j0:j1], [t_target]))
    gap_start, gap_end = _gap_bounds(t_nodes, win_t)
    gap = gap_end - gap_start  # length of the data gap each interval lies in
    k_long = int(np.argmax(gap))
    if gap[k_long] > config.imu_max_bridged_gap:
        where = _gap_description(float(gap_start[k_long]), float(gap_end[k_long]), float(t_imu[0]),
                                 float(t_imu[-1]))
        raise ImuGapError(
            f"IMU gap of {gap[k_long]:.3g} s > imu_max_bridged_gap = {config.imu_max_bridged_gap:g} s ({where}): "
            f"the motion over it is unknown, so the state stays at t = {t0:.3f} s. Feed IMU samples covering the "
            "gap, restart the filter after it, or raise imu_max_bridged_gap",
            float(gap_start[k_long]), float(gap_end[k_long]),
        )
    w_nodes = np.vstack((_signal_at(t0, win_t, win_g), gyro[j0:j1], _signal_at(t_target, win_t, win_g)))
    a_nodes = np.vstack((_signal_at(t0, win_t, win_a), accel[j0:j1], _signal_at(t_target, win_t, win_a)))
    return t_nodes, w_nodes, a_nodes, gap


def _gap_noise_psd(config: MsckfConfig, gap: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return diag(Q_IMU), (12,), or (K, 12) when an interval lies in a gap longer than ``imu_max_gap``: the unseen
    motion over a gap of length T adds σ_g² T (gyro) and σ_a² T (accel) to the white-noise densities."""
    noise_psd = config.continuous_noise_psd()
    in_gap = gap > config.imu_max_gap
    if in_gap.any():  # unseen motion over a gap of length T: + σ_g² T (gyro), + σ_a² T (accel) white-noise density
        extra = np.zeros(12)
        extra[0:3] = config.imu_gap_gyro_sigma ** 2
        extra[6:9] = config.imu_gap_accel_sigma ** 2
        noise_psd = noise_psd + np.where(in_gap, gap, 0.0)[:, None] * extra
    return noise_psd


def _hooked_transition(hook: TransitionHook, Phi: NDArray[np.float64], steps: PropagationSteps) -> NDArray[np.float64]:
    """Return the hook's transition matrices (K, 15, 15) for a copy of Phi, checked for shape and finiteness."""
    K = Phi.shape[0]
    Phi = np.asarray(hook(Phi.copy(), steps), dtype=np.float64)
    if Phi.shape != (K, IMU_DIM, IMU_DIM) or not np.all(np.isfinite(Phi)):
        raise ValueError(f"transition_hook must return finite Phi of shape ({K}, 15, 15); got {Phi.shape}")
    return Phi


def _propagated_covariance(state: FilterState, Phi: NDArray[np.float64], X: NDArray[np.float64]
                           ) -> NDArray[np.float64]:
    """Return P after the K intervals with transitions Phi (K, 15, 15) and noise factors X (Q_d,k = X_k X_k^T).

    Eqs. 38-40 over all K intervals at once. Unrolling P_k+1 = Φ_k P_k Φ_k^T + Q_d,k gives
    P_II,K = Φ_tot P_II,0 Φ_tot^T + Σ_k S_k Q_d,k S_k^T with S_k = Φ_K-1 ... Φ_k+1 (S_K-1 = I), Φ_tot = S_-1;
    P_IC,K = Φ_tot P_IC,0; P_CC unchanged. With Q_d,k = X_k X_k^T the sum is Y Y^T,
    Y = [S_0 X_0, ..., S_K-1 X_K-1] (15 x 36K)."""
    K = Phi.shape[0]
    S = np.empty((K, IMU_DIM, IMU_DIM))
    acc = _EYE15
    for k in range(K - 1, -1, -1):  # suffix products: one 15x15 product per interval
        S[k] = acc
        acc = acc @ Phi[k]
    Phi_total = acc
    Y = np.empty((IMU_DIM, K, X.shape[2]))
    np.matmul(S, X, out=Y.transpose(1, 0, 2))  # S_k X_k written straight into the (15, K, 36) layout of Y
    Y = Y.reshape(IMU_DIM, -1)
    P = state.P
    P_II = Phi_total @ P[:IMU_DIM, :IMU_DIM] @ Phi_total.T + Y @ Y.T
    P_new = np.empty_like(P)
    P_new[:IMU_DIM, :IMU_DIM] = 0.5 * (P_II + P_II.T)
    if state.num_cameras:
        P_IC = Phi_total @ P[:IMU_DIM, IMU_DIM:]
        P_new[:IMU_DIM, IMU_DIM:] = P_IC
        P_new[IMU_DIM:, :IMU_DIM] = P_IC.T
        P_new[IMU_DIM:, IMU_DIM:] = P[IMU_DIM:, IMU_DIM:]
    return P_new
