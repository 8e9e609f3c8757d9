"""State augmentation: clone the current camera pose into the sliding window and grow the covariance (thesis §3.3.3).

At each image the camera pose is computed from the IMU pose and the fixed camera-IMU extrinsics (thesis Eqs. 27-28)::

    q_GtoC = q_ItoC ⊗ q_GtoI                      (R_GtoC = R_ItoC R_GtoI)
    p_CinG = p_IinG + R_ItoG p_CinI

and the covariance is augmented with its Jacobian J (thesis Eqs. 29-30)::

    P <- [I; J] P [I; J]^T,    J = [[R_ItoC,                0_3x9, 0_3,  0_3x6N],
                                    [-R_ItoG [p_CinI x],    0_3x9, I_3,  0_3x6N]]

Derivation with the error convention of ``evio_lib.msckf.state`` (q_true = δq ⊗ q_est, so
R_ItoG,true ≈ R_ItoG (I + [δθ x])): δθ_C = R_ItoC δθ (exact: δq is conjugated by q_ItoC) and
δp_C = δp + R_ItoG [δθ x] p_CinI = δp - R_ItoG [p_CinI x] δθ.
The position row is the one of Sun et al.'s S-MSCKF paper (appendix); the thesis prints [R_ItoG p_CinI x] there (the
form of Mourikis & Roumeliotis 2007 and of the msckf_vio code, msckf_vio issue #32), which differs for the error
convention used here. J is checked against finite differences in tests/msckf/test_augmentation.py.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import quat_multiply, quat_normalize, quat_to_rot, rot_to_quat, skew
from evio_lib.msckf.state import (
    CAMERA_DIM,
    IMU_DIM,
    POS,
    THETA,
    FilterState,
    _camera_unchecked,
    _filter_state_unchecked,
    _frozen,
)

__all__ = ["camera_pose_from_imu", "augmentation_jacobian", "augment_state"]


def camera_pose_from_imu(
    q_GtoI: ArrayLike, p_IinG: ArrayLike, R_CtoI: ArrayLike, p_CinI: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return the camera pose (q_GtoC (4,), p_CinG (3,)) of an IMU pose and the camera-IMU extrinsics.

    Args:
        q_GtoI: (4,) JPL quaternion of R_GtoI.
        p_IinG: (3,) IMU position in G, m.
        R_CtoI: (3, 3) camera-to-IMU rotation; p_CinI: (3,) camera centre in I, m.

    q_GtoC = q_ItoC ⊗ q_GtoI and p_CinG = p_IinG + R_ItoG p_CinI (thesis Eqs. 27-28).

    >>> q, p = camera_pose_from_imu([0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0], np.eye(3), [0.0, 0.1, 0.0])
    >>> q, p
    (array([0., 0., 0., 1.]), array([1. , 0.1, 0. ]))
    """
    q_GtoI = quat_normalize(q_GtoI)
    p_IinG = _vec3(p_IinG, "p_IinG")
    p_CinI = _vec3(p_CinI, "p_CinI")
    R_CtoI = np.asarray(R_CtoI, dtype=np.float64)
    if R_CtoI.shape != (3, 3):
        raise ValueError(f"R_CtoI must have shape (3, 3); got {R_CtoI.shape}")
    q_ItoC = rot_to_quat(R_CtoI.T)  # C(q_ItoC) = R_ItoC = R_CtoI^T
    q_GtoC = quat_normalize(quat_multiply(q_ItoC, q_GtoI))  # q_GtoC = q_ItoC ⊗ q_GtoI
    p_CinG = p_IinG + quat_to_rot(q_GtoI).T @ p_CinI  # p_CinG = p_IinG + R_ItoG p_CinI
    return q_GtoC, p_CinG


def _vec3(x: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite vector of shape (3,); got shape {arr.shape}")
    return arr


def _rot_ItoG(q_GtoI: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return R_ItoG = C(q_GtoI)^T = (2 qw² - 1) I + 2 qw [qv x] + 2 qv qv^T for a validated unit quaternion."""
    qv, qw = q_GtoI[:3], q_GtoI[3]
    R = (2.0 * qw * qw - 1.0) * np.eye(3) + 2.0 * np.outer(qv, qv)
    R[0, 1] -= 2.0 * qw * qv[2]
    R[0, 2] += 2.0 * qw * qv[1]
    R[1, 2] -= 2.0 * qw * qv[0]
    R[1, 0] += 2.0 * qw * qv[2]
    R[2, 0] -= 2.0 * qw * qv[1]
    R[2, 1] += 2.0 * qw * qv[0]
    return R


def _jacobian_imu_block(state: FilterState, R_ItoG: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """Return the non-zero part J_I (6, 15) of J: the derivative of [δθ_C, δp_C] w.r.t. the IMU error state."""
    if R_ItoG is None:
        R_ItoG = _rot_ItoG(state.imu.q_GtoI)
    J_I = np.zeros((CAMERA_DIM, IMU_DIM))
    J_I[0:3, THETA] = state.R_CtoI.T  # δθ_C = R_ItoC δθ
    J_I[3:6, THETA] = -R_ItoG @ skew(state.p_CinI)  # δp_C = -R_ItoG [p_CinI x] δθ + δp
    J_I[3:6, POS] = np.eye(3)
    return J_I


def augmentation_jacobian(state: FilterState) -> NDArray[np.float64]:
    """Return J (6, 15 + 6N): the Jacobian of the new camera's error [δθ_C, δp_C] w.r.t. the current error state.

    Args:
        state: filter state before augmentation (its IMU pose and extrinsics R_CtoI, p_CinI are used).

    Reference: thesis Eq. 30 (position row corrected for the error convention used here; see the module docstring).

    >>> from evio_lib.msckf.state import ImuState
    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), timestamp=0.0)
    >>> J = augmentation_jacobian(FilterState.initial(imu, np.eye(3), [0.0, 0.0, 0.1], np.eye(15)))
    >>> J.shape, J[3:6, 0:3] + 0.0           # -[p_CinI x] for R_ItoG = I
    ((6, 15), array([[ 0. ,  0.1,  0. ],
           [-0.1,  0. ,  0. ],
           [ 0. ,  0. ,  0. ]]))
    """
    if not isinstance(state, FilterState):
        raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
    J = np.zeros((CAMERA_DIM, state.dim))
    J[:, :IMU_DIM] = _jacobian_imu_block(state)
    return J


def augment_state(state: FilterState, camera_id: int) -> FilterState:
    """Return a new state with the current camera pose appended to the window and the covariance augmented.

    Args:
        state: filter state propagated to the image time (the new camera's timestamp is state.timestamp).
        camera_id: identifier of the image (must not already be in the window).

    P_new = [[P, P J^T], [J P, J P J^T]] (thesis Eq. 29); only the IMU columns of J are non-zero, so J P costs
    6 x 15 x (15 + 6N). The camera's OC first estimates (*_null) are set to its pose (S-MSCKF).

    >>> from evio_lib.msckf.state import ImuState
    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), timestamp=1.5)
    >>> s = augment_state(FilterState.initial(imu, np.eye(3), [0.0, 0.0, 0.1], np.eye(15)), camera_id=4)
    >>> s.camera_ids, s.dim, s.cameras[4].p_CinG, s.cameras[4].timestamp
    ((4,), 21, array([0. , 0. , 0.1]), 1.5)
    """
    if not isinstance(state, FilterState):
        raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
    if isinstance(camera_id, (bool, np.bool_)) or not isinstance(camera_id, (int, np.integer)):
        raise ValueError(f"camera_id must be an integer frame identifier; got {camera_id!r}")
    if camera_id in state.cameras:
        raise ValueError(f"camera_id must be new; got {camera_id} which is already in the window {state.camera_ids}")
    imu = state.imu
    R_ItoG = _rot_ItoG(imu.q_GtoI)
    q_GtoC = _frozen(quat_normalize(quat_multiply(state.q_ItoC, imu.q_GtoI)))  # q_GtoC = q_ItoC ⊗ q_GtoI (Eq. 27)
    p_CinG = _frozen(imu.p_IinG + R_ItoG @ state.p_CinI)  # p_CinG = p_IinG + R_ItoG p_CinI (Eq. 28)
    camera = _camera_unchecked(int(camera_id), state.timestamp, q_GtoC, p_CinG, q_GtoC, p_CinG)

    n = state.dim
    P = state.P
    J_I = _jacobian_imu_block(state, R_ItoG)
    JP = J_I @ P[:IMU_DIM, :]  # J P (6, n): only the IMU rows of P contribute
    P_new = np.empty((n + CAMERA_DIM, n + CAMERA_DIM))
    P_new[:n, :n] = P
    P_new[n:, :n] = JP
    P_new[:n, n:] = JP.T
    JPJ = JP[:, :IMU_DIM] @ J_I.T  # J P J^T (6, 6)
    P_new[n:, n:] = 0.5 * (JPJ + JPJ.T)
    cameras = dict(state.cameras)
    cameras[camera.id] = camera
    return _filter_state_unchecked(imu, cameras, P_new, state)
