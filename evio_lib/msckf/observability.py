"""Observability-constrained EKF (OC-EKF): keep the four unobservable directions of VIO unobservable (thesis §3.3.8).

Visual-inertial odometry cannot observe the global position (3 directions) nor the rotation about gravity (yaw, 1
direction). A plain EKF linearises propagation and update at different estimates and so "learns" yaw it cannot know,
becoming overconfident (Hesch et al., "Consistency analysis and improvement of vision-aided inertial navigation",
IEEE T-RO 2014; Huang et al. 2010). The OC-EKF, as in S-MSCKF (Sun et al., RA-L 2018), fixes this with the
first-estimate (``*_null``) states kept in ``evio_lib.msckf.state``.

Nullspace of the IMU error state [δθ, δb_g, δv, δb_a, δp] at step k (thesis Eq. 80; the first column block is
the global translation, the last column the yaw about gravity)::

    N_k = [[0_3,  R_GtoI,k g_G     ],
           [0_3,  0                ],
           [0_3,  -[v_IinG,k x] g_G],
           [0_3,  0                ],
           [I_3,  -[p_IinG,k x] g_G]]

and of a camera error [δθ_C, δp_C]: [[0_3, R_GtoC g_G], [I_3, -[p_CinG x] g_G]]; of a feature:
[I_3, -[p_FinG x] g_G].
(With q_true = δq ⊗ q_est a yaw ε of the world gives δθ = ε R_GtoI ĝ and δp = ε [ĝ x] p = -ε [p x] ĝ.)

1. Propagation (Eqs. 81-84): every interval's Φ is modified so that Φ_k N_k = N_k+1, with N_k built from the
   first estimates at the start of the interval (k|k-1) and N_k+1 from the prediction (k+1|k)::

       Φ_11 = R_GtoI,k+1|k R_GtoI,k|k-1^T                                         (Eq. 81)
       Φ_31 u = ([v_k|k-1 x] - [v_k+1|k x]) g_G                                     (Eq. 82)
       Φ_51 u = (δt [v_k|k-1 x] + [p_k|k-1 x] - [p_k+1|k x]) g_G                    (Eq. 83)

   with u = R_GtoI,k|k-1 g_G; each "A u = w" is met by the smallest change of A (Eq. 84)::

       A* = A - (A u - w) (u^T u)^-1 u^T

   The thesis prints Eq. 83 without the [p_k|k-1 x] g_G term; it is needed for Φ N_k = N_k+1 (the position row of
   Φ N_k is Φ_51 u - δt [v_k x] g - [p_k x] g, Φ_53 = δt I, Φ_55 = I), and msckf_vio has it too.

2. Update (Eqs. 85-86): each camera's 2x6 block H_C of a feature Jacobian must satisfy H_C u_C = 0 with
   u_C = [R_GtoC,null g_G; [(p_FinG - p_CinG,null) x] g_G] (the camera's and the feature's yaw directions combined,
   using H_f = -H_C[:, 3:6]); the minimal change is A* = A - A u (u^T u)^-1 u^T, and H_f is then recomputed as
   -A*[:, 3:6], so that H_C N_C + H_f N_f = 0 for all four directions.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import as_float_array, cross3, quat_to_rot
from evio_lib.msckf.propagation import PropagationSteps
from evio_lib.msckf.state import CAMERA_DIM, IMU_DIM, POS, THETA, VEL, FilterState

__all__ = [
    "least_squares_constraint",
    "imu_nullspace",
    "state_nullspace",
    "constrain_transition",
    "constrain_camera_blocks",
    "constrain_feature_jacobians",
    "camera_nullspace",
    "constrain_projected_jacobian",
]


def _matrices(x: ArrayLike, name: str, expected: str) -> NDArray[np.float64]:
    """Return x as a finite float64 array with ndim >= 2; raise ValueError naming ``name`` otherwise."""
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got {x!r}") from exc
    if arr.ndim < 2:
        raise ValueError(f"{name} must have shape {expected}; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values (no NaN/inf)")
    return arr


def _gravity(gravity_G: ArrayLike) -> NDArray[np.float64]:
    g = as_float_array(gravity_G, "gravity_G", (3,))
    if g.shape != (3,) or not np.any(g != 0.0):
        raise ValueError(f"gravity_G must be a non-zero vector of shape (3,), e.g. (0, 0, -9.81); got {g}")
    return g


def least_squares_constraint(A: ArrayLike, u: ArrayLike, w: ArrayLike | None = None) -> NDArray[np.float64]:
    """Return A* = A - (A u - w) (u^T u)^-1 u^T: the smallest (Frobenius) change of A with A* u = w (thesis Eq. 84).

    Args:
        A: (..., m, n) matrices (e.g. Φ_31, or a 2x6 measurement block).
        u: (..., n) non-zero vectors (a nullspace direction before the step).
        w: (..., m) targets (the direction after the step); None means w = 0 (Eq. 86).

    >>> A = np.eye(2)
    >>> least_squares_constraint(A, [1.0, 0.0], [2.0, 3.0])
    array([[2., 0.],
           [3., 1.]])
    """
    A = _matrices(A, "A", "(..., m, n)")
    m, n = A.shape[-2:]
    u = as_float_array(u, "u", (n,))
    uu = np.einsum("...i,...i->...", u, u)
    if np.any(uu <= 0.0):
        raise ValueError("u must be non-zero (u^T u > 0)")
    Au = np.einsum("...ij,...j->...i", A, u)
    if w is not None:
        Au = Au - as_float_array(w, "w", (m,))
    # A* = A - (A u - w) u^T / (u^T u)
    return A - (Au / uu[..., None])[..., :, None] * u[..., None, :]


def imu_nullspace(
    q_GtoI: ArrayLike, v_IinG: ArrayLike, p_IinG: ArrayLike, gravity_G: ArrayLike = (0.0, 0.0, -9.81)
) -> NDArray[np.float64]:
    """Return N (..., 15, 4): the unobservable directions of the IMU error state (thesis Eq. 80).

    Args:
        q_GtoI: (..., 4) JPL quaternion(s) of R_GtoI (first estimates for the OC-EKF).
        v_IinG, p_IinG: (..., 3) velocity and position of I in G.
        gravity_G: (3,) gravity in G, m/s^2.

    Columns 0-2: global translation; column 3: rotation about gravity (yaw), scaled by |g|.

    >>> N = imu_nullspace([0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    >>> (N[:, 3].round(2) + 0.0).tolist()
    [0.0, 0.0, -9.81, 0.0, 0.0, 0.0, 0.0, -9.81, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    """
    q = as_float_array(q_GtoI, "q_GtoI", (4,))
    v = as_float_array(v_IinG, "v_IinG", (3,))
    p = as_float_array(p_IinG, "p_IinG", (3,))
    g = _gravity(gravity_G)
    batch = np.broadcast_shapes(q.shape[:-1], v.shape[:-1], p.shape[:-1])
    N = np.zeros(batch + (IMU_DIM, 4))
    N[..., POS, 0:3] = np.eye(3)  # global translation: δp = I
    N[..., THETA, 3] = quat_to_rot(q) @ g  # δθ = R_GtoI g
    N[..., VEL, 3] = -cross3(v, g)  # δv = -[v x] g
    N[..., POS, 3] = -cross3(p, g)  # δp = -[p x] g
    return N


def state_nullspace(
    state: FilterState, gravity_G: ArrayLike = (0.0, 0.0, -9.81), first_estimates: bool = True
) -> NDArray[np.float64]:
    """Return N (15 + 6N, 4): the unobservable directions of the whole error state (IMU and every camera).

    Args:
        state: filter state.
        gravity_G: (3,) gravity in G.
        first_estimates: build N from the OC first estimates (*_null) instead of the current estimates.

    Camera i rows: [R_GtoC g_G; I_3 and -[p_CinG x] g_G] (thesis Eq. 80 applied to a camera pose).
    """
    if not isinstance(state, FilterState):
        raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
    g = _gravity(gravity_G)
    imu = state.imu
    if first_estimates:
        N_I = imu_nullspace(imu.q_GtoI_null, imu.v_IinG_null, imu.p_IinG_null, g)
    else:
        N_I = imu_nullspace(imu.q_GtoI, imu.v_IinG, imu.p_IinG, g)
    N = np.zeros((state.dim, 4))
    N[:IMU_DIM] = N_I
    for i, cam in enumerate(state.cameras.values()):
        q, p = (cam.q_GtoC_null, cam.p_CinG_null) if first_estimates else (cam.q_GtoC, cam.p_CinG)
        c = IMU_DIM + CAMERA_DIM * i
        N[c:c + 3, 3] = quat_to_rot(q) @ g  # δθ_C = R_GtoC g
        N[c + 3:c + 6, 0:3] = np.eye(3)
        N[c + 3:c + 6, 3] = -cross3(p, g)  # δp_C = -[p_C x] g
    return N


def constrain_transition(Phi: NDArray[np.float64], steps: PropagationSteps) -> NDArray[np.float64]:
    """Return the OC-modified transition matrices (K, 15, 15) of one propagation (thesis Eqs. 81-84).

    Args:
        Phi: (K, 15, 15) per-interval transition matrices from ``propagate`` (modified in place and returned).
        steps: what the propagation integrated: first estimates at each interval start (``*_prev``) and the
            predicted nodes (``q_GtoI``, ``v_IinG``, ``p_IinG``), interval lengths and gravity.

    Use as ``propagate(..., transition_hook=constrain_transition)``. Afterwards Φ_k N_k = N_k+1 (module docstring)
    for every interval, with N_k from the first estimates and N_k+1 from the prediction.
    """
    Phi = np.asarray(Phi, dtype=np.float64)
    K = steps.dt.shape[0]
    if Phi.shape != (K, IMU_DIM, IMU_DIM):
        raise ValueError(f"Phi must have shape (K, 15, 15) = ({K}, 15, 15); got {Phi.shape}")
    g = steps.gravity_G
    R_prev = quat_to_rot(steps.q_GtoI_prev)  # R_GtoI,k|k-1 (K, 3, 3)
    R_next = quat_to_rot(steps.q_GtoI[1:])  # R_GtoI,k+1|k
    v_prev, v_next = steps.v_IinG_prev, steps.v_IinG[1:]
    p_prev, p_next = steps.p_IinG_prev, steps.p_IinG[1:]
    Phi[:, THETA, THETA] = R_next @ np.swapaxes(R_prev, 1, 2)  # Φ_11 = R_k+1|k R_k|k-1^T        (Eq. 81)
    u = R_prev @ g  # u = R_GtoI,k|k-1 g_G
    uu = np.einsum("ki,ki->k", u, u)
    s = u / uu[:, None]  # (u^T u)^-1 u^T
    w1 = cross3(v_prev - v_next, g)  # ([v_k|k-1 x] - [v_k+1|k x]) g                             (Eq. 82)
    w2 = cross3(steps.dt[:, None] * v_prev + p_prev - p_next, g)  # (δt[v x] + [p x] - [p' x]) g  (Eq. 83)
    for rows, w in ((VEL, w1), (POS, w2)):
        A = Phi[:, rows, THETA]
        Au_w = np.einsum("kij,kj->ki", A, u) - w
        Phi[:, rows, THETA] = A - Au_w[:, :, None] * s[:, None, :]  # A* = A - (A u - w)(u^T u)^-1 u^T (Eq. 84)
    return Phi


def constrain_camera_blocks(
    H_C: ArrayLike, R_GtoC_null: ArrayLike, p_CinG_null: ArrayLike, p_FinG: ArrayLike,
    gravity_G: ArrayLike = (0.0, 0.0, -9.81),
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (H_C* (..., 2, 6), H_f* (..., 2, 3)): OC-modified per-camera measurement blocks (thesis Eqs. 85-86).

    Args:
        H_C: (..., 2, 6) Jacobians of one observation w.r.t. its camera's [δθ_C, δp_C].
        R_GtoC_null: (..., 3, 3) the observing cameras' first-estimate rotations (pose at augmentation).
        p_CinG_null: (..., 3) their first-estimate centres in G.
        p_FinG: (..., 3) the (triangulated) feature position in G.
        gravity_G: (3,) gravity in G.

    u = [R_GtoC,null g; [(p_FinG - p_CinG,null) x] g]; H_C* = H_C - H_C u (u^T u)^-1 u^T; H_f* = -H_C*[:, 3:6].
    """
    A = as_float_array(H_C, "H_C", (2, CAMERA_DIM))
    R = as_float_array(R_GtoC_null, "R_GtoC_null", (3, 3))
    p_C = as_float_array(p_CinG_null, "p_CinG_null", (3,))
    p_F = as_float_array(p_FinG, "p_FinG", (3,))
    g = _gravity(gravity_G)
    batch = A.shape[:-2]
    u = np.empty(batch + (CAMERA_DIM,))
    u[..., :3] = R @ g  # R_GtoC,null g_G
    u[..., 3:] = cross3(p_F - p_C, g)  # [(p_FinG - p_CinG,null) x] g_G
    uu = np.einsum("...i,...i->...", u, u)
    Au = np.einsum("...ij,...j->...i", A, u)
    A_star = A - (Au / uu[..., None])[..., :, None] * u[..., None, :]  # A* = A - A u (u^T u)^-1 u^T   (Eq. 86)
    return A_star, -A_star[..., 3:6]


def constrain_feature_jacobians(
    H_x: ArrayLike, H_f: ArrayLike, cam_columns: ArrayLike, R_GtoC_null: ArrayLike, p_CinG_null: ArrayLike,
    p_FinG: ArrayLike, gravity_G: ArrayLike = (0.0, 0.0, -9.81),
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (H_x* (2M, n), H_f* (2M, 3)): a feature's Jacobians (``update.feature_jacobians``) made OC (Eqs. 85-86).

    Args:
        H_x: (2M, n) Jacobian w.r.t. the error state; rows 2i, 2i+1 belong to camera i.
        H_f: (2M, 3) Jacobian w.r.t. the feature position (replaced).
        cam_columns: (M,) first error-state column of each observing camera (15 + 6 * window index).
        R_GtoC_null: (M, 3, 3) rotations or (M, 4) JPL quaternions: the cameras' first estimates.
        p_CinG_null: (M, 3) their first-estimate centres.
        p_FinG: (3,) the feature position in G.
        gravity_G: (3,) gravity in G.

    Afterwards H_x* N + H_f* N_f = 0 for the four unobservable directions (N from ``state_nullspace`` with first
    estimates, N_f = [I_3, -[p_FinG x] g]).
    """
    H_x = _matrices(H_x, "H_x", "(2M, n)")
    if H_x.ndim != 2 or H_x.shape[0] % 2:
        raise ValueError(f"H_x must have shape (2M, n); got {H_x.shape}")
    M, n = H_x.shape[0] // 2, H_x.shape[1]
    as_float_array(H_f, "H_f", (3,))
    if np.shape(H_f) != (2 * M, 3):
        raise ValueError(f"H_f must have shape ({2 * M}, 3); got {np.shape(H_f)}")
    cols = np.asarray(cam_columns)
    if cols.shape != (M,) or cols.dtype.kind not in "iu" or np.any(cols < 0) or np.any(cols + CAMERA_DIM > n):
        raise ValueError(f"cam_columns must be ({M},) integers with 0 <= column <= n - 6 = {n - 6}; got {cols!r}")
    R = np.asarray(R_GtoC_null, dtype=np.float64)
    if R.ndim == 2 and R.shape[-1] == 4:
        R = quat_to_rot(as_float_array(R, "R_GtoC_null", (4,)))
    if R.shape != (M, 3, 3):
        raise ValueError(f"R_GtoC_null must have shape ({M}, 3, 3) or ({M}, 4); got {np.shape(R_GtoC_null)}")
    p_C = as_float_array(p_CinG_null, "p_CinG_null", (3,))
    if p_C.shape != (M, 3):
        raise ValueError(f"p_CinG_null must have shape ({M}, 3); got {p_C.shape}")
    p_F = as_float_array(p_FinG, "p_FinG", (3,))
    if p_F.shape != (3,):
        raise ValueError(f"p_FinG must have shape (3,); got {p_F.shape}")
    idx = cols[:, None] + np.arange(CAMERA_DIM)  # (M, 6) column indices of each camera block
    rows = np.arange(2 * M).reshape(M, 2)
    blocks = H_x[rows[:, :, None], idx[:, None, :]]  # (M, 2, 6)
    blocks, H_f_blocks = constrain_camera_blocks(blocks, R, p_C, np.broadcast_to(p_F, (M, 3)), gravity_G)
    out = H_x.copy()
    out[rows[:, :, None], idx[:, None, :]] = blocks
    return out, H_f_blocks.reshape(2 * M, 3)


def camera_nullspace(
    R_GtoC_null: ArrayLike, p_CinG_null: ArrayLike, gravity_G: ArrayLike = (0.0, 0.0, -9.81)
) -> NDArray[np.float64]:
    """Return N_C (..., 6M, 4): the unobservable directions restricted to M cameras' [δθ_C, δp_C] blocks.

    Args:
        R_GtoC_null: (..., M, 3, 3) the cameras' first-estimate rotations G -> C.
        p_CinG_null: (..., M, 3) their first-estimate centres in G.
        gravity_G: (3,) gravity in G.

    Camera i rows 6i..6i+6: [[0_3, R_GtoC g_G], [I_3, -[p_CinG x] g_G]] (thesis Eq. 80 for a camera pose).

    >>> N = camera_nullspace(np.eye(3)[None], np.zeros((1, 3)))
    >>> N.shape, (N[:, 3].round(2) + 0.0).tolist()
    ((6, 4), [0.0, 0.0, -9.81, 0.0, 0.0, 0.0])
    """
    R = as_float_array(R_GtoC_null, "R_GtoC_null", (3, 3))
    p = as_float_array(p_CinG_null, "p_CinG_null", (3,))
    if R.ndim < 3 or R.shape[:-2] != p.shape[:-1]:
        raise ValueError(f"R_GtoC_null (..., M, 3, 3) and p_CinG_null (..., M, 3) must match; got {R.shape}, {p.shape}")
    g = _gravity(gravity_G)
    N = np.zeros(p.shape[:-1] + (CAMERA_DIM, 4))
    N[..., 3:, 0:3] = np.eye(3)  # global translation: δp_C = I
    N[..., :3, 3] = R @ g  # yaw: δθ_C = R_GtoC g
    N[..., 3:, 3] = -cross3(p, g)  # δp_C = -[p_C x] g
    return N.reshape(p.shape[:-2] + (CAMERA_DIM * p.shape[-2], 4))


def constrain_projected_jacobian(
    H_o: ArrayLike, N_C: ArrayLike, P_C: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Return H_o* (..., k, 6M): a feature's projected Jacobian changed as little as possible so that H_o* N_C = 0.

    Args:
        H_o: (..., k, 6M) Jacobian after the left-nullspace projection (Eq. 50) w.r.t. the M observing cameras.
        N_C: (..., 6M, 4) unobservable directions of those cameras (:func:`camera_nullspace`, first estimates).
        P_C: (..., 6M, 6M) their prior covariance, or None.

    An alternative to Eq. 86 that constrains the whole feature at once (4 conditions instead of 2 per camera;
    the feature's own yaw direction is already gone with A^T H_f = 0). With P_C it minimises ||ΔH L||_F,
    L L^T = P_C, i.e. the change of information relative to the prior (weak directions are changed least)::

        H_o* = H_o - H_o N (N^T W N)^-1 N^T W,   W = P_C^-1 (or I without P_C)

    >>> H = np.array([[1.0, 1.0]]); N = np.array([[1.0], [0.0]])
    >>> constrain_projected_jacobian(H, N).tolist()
    [[0.0, 1.0]]
    """
    H = _matrices(H_o, "H_o", "(..., k, 6M)")
    N = _matrices(N_C, "N_C", "(..., 6M, 4)")
    if N.shape[-2] != H.shape[-1]:
        raise ValueError(f"N_C must have shape (..., {H.shape[-1]}, r) to match H_o; got {N.shape}")
    if P_C is None:
        WN = N
    else:
        P = _matrices(P_C, "P_C", "(..., 6M, 6M)")
        if P.shape[-2:] != (H.shape[-1], H.shape[-1]):
            raise ValueError(f"P_C must have shape (..., {H.shape[-1]}, {H.shape[-1]}); got {P.shape}")
        WN = np.linalg.solve(P, N)  # W N = P^-1 N
    M = np.swapaxes(N, -1, -2) @ WN  # N^T W N (r, r)
    HN = H @ N
    # ΔH = H N (N^T W N)^-1 (W N)^T
    return H - np.linalg.solve(M, np.swapaxes(HN, -1, -2)).swapaxes(-1, -2) @ np.swapaxes(WN, -1, -2)
