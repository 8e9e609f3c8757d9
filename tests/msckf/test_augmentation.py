"""Tests for evio_lib.msckf.augmentation: camera pose from the IMU pose, Jacobian J by finite differences, P growth."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import (
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_to_rot,
    quat_to_rotvec,
    rot_to_quat,
    skew,
)
from evio_lib.msckf.augmentation import augment_state, augmentation_jacobian, camera_pose_from_imu
from evio_lib.msckf.state import CameraState, FilterState, ImuState, inject_error
from evio_lib.sim.rig import CameraImuExtrinsics


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return Rotation.from_rotvec(rng.normal(size=3)).as_matrix()


def make_state(rng: np.random.Generator, n_cameras: int = 2, extrinsics: CameraImuExtrinsics | None = None):
    ext = extrinsics or CameraImuExtrinsics.default()
    imu = ImuState.from_pose(random_rotation(rng), rng.normal(size=3), rng.normal(size=3), timestamp=3.5,
                             b_g=0.01 * rng.normal(size=3), b_a=0.1 * rng.normal(size=3))
    cams = {i: CameraState(i, 0.1 * i, rot_to_quat(random_rotation(rng)), rng.normal(size=3)) for i in range(n_cameras)}
    n = 15 + 6 * n_cameras
    A = rng.normal(size=(n, n))
    return FilterState(imu, cams, A @ A.T + np.eye(n), ext.R_CtoI, ext.p_CinI)


def test_camera_pose_matches_the_simulator_rig(rng):
    ext = CameraImuExtrinsics.default()
    R_ItoG, p_IinG = random_rotation(rng), rng.normal(size=3)
    q_GtoC, p_CinG = camera_pose_from_imu(rot_to_quat(R_ItoG.T), p_IinG, ext.R_CtoI, ext.p_CinI)
    R_CtoG_rig, p_CinG_rig = ext.camera_pose(R_ItoG, p_IinG)  # independent implementation (matrices)
    np.testing.assert_allclose(quat_to_rot(q_GtoC).T, R_CtoG_rig, atol=1e-12)
    np.testing.assert_allclose(p_CinG, p_CinG_rig, atol=1e-12)


def test_camera_pose_rejects_bad_inputs():
    with pytest.raises(ValueError, match=r"p_IinG must be a finite vector of shape \(3,\)"):
        camera_pose_from_imu([0, 0, 0, 1.0], np.zeros(2), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"R_CtoI must have shape \(3, 3\)"):
        camera_pose_from_imu([0, 0, 0, 1.0], np.zeros(3), np.eye(2), np.zeros(3))


def numerical_augmentation_jacobian(state: FilterState, eps: float = 1e-6) -> np.ndarray:
    """Central differences of the new camera's pose error w.r.t. every error-state component."""
    q0, p0 = camera_pose_from_imu(state.imu.q_GtoI, state.imu.p_IinG, state.R_CtoI, state.p_CinI)
    J = np.zeros((6, state.dim))
    for j in range(state.dim):
        cols = []
        for sign in (1.0, -1.0):
            dx = np.zeros(state.dim)
            dx[j] = sign * eps
            s = inject_error(state, dx)
            q, p = camera_pose_from_imu(s.imu.q_GtoI, s.imu.p_IinG, s.R_CtoI, s.p_CinI)
            # camera error: q_GtoC,true = δq(δθ_C) ⊗ q_GtoC,est, p additive
            cols.append(np.r_[quat_to_rotvec(quat_multiply(q, quat_inverse(q0))), p - p0])
        J[:, j] = (cols[0] - cols[1]) / (2.0 * eps)
    return J


def test_augmentation_jacobian_matches_finite_differences(rng):
    state = make_state(rng, n_cameras=2)
    J = augmentation_jacobian(state)
    assert J.shape == (6, 27)
    J_num = numerical_augmentation_jacobian(state)
    np.testing.assert_allclose(J, J_num, atol=1e-8)
    # only δθ and δp of the IMU enter
    assert np.all(J[:, 3:12] == 0) and np.all(J[:, 15:] == 0)


def test_printed_position_block_would_fail_the_same_check(rng):
    """The [R_ItoG p_CinI x] block printed in thesis Eq. 30 does not match this error convention (tests can fail)."""
    ext = CameraImuExtrinsics(np.eye(3), [0.1, -0.05, 0.08])  # a lever arm large enough to see it
    state = make_state(rng, n_cameras=0, extrinsics=ext)
    J_num = numerical_augmentation_jacobian(state)
    printed = skew(state.imu.R_ItoG @ state.p_CinI)
    assert np.abs(printed - J_num[3:6, 0:3]).max() > 1e-2
    np.testing.assert_allclose(-state.imu.R_ItoG @ skew(state.p_CinI), J_num[3:6, 0:3], atol=1e-8)


def test_augment_state_grows_the_covariance_as_I_J_P_I_J(rng):
    state = make_state(rng, n_cameras=2)
    new = augment_state(state, camera_id=42)
    assert new.camera_ids == (0, 1, 42)
    assert new.dim == state.dim + 6
    J = augmentation_jacobian(state)
    T = np.vstack([np.eye(state.dim), J])  # [I; J]
    np.testing.assert_allclose(new.P, T @ state.P @ T.T, rtol=1e-12, atol=1e-12)  # thesis Eq. 29
    np.testing.assert_array_equal(new.P, new.P.T)
    # the new block is the IMU pose's uncertainty moved to the camera: PSD with rank 6 deficiency
    eig = np.linalg.eigvalsh(new.P)
    assert eig.min() > -1e-9 * eig.max()


def test_augment_state_stores_the_camera_pose_and_keeps_the_input(rng):
    state = make_state(rng, n_cameras=1)
    P_before = state.P.copy()
    new = augment_state(state, 7)
    cam = new.cameras[7]
    q, p = camera_pose_from_imu(state.imu.q_GtoI, state.imu.p_IinG, state.R_CtoI, state.p_CinI)
    np.testing.assert_allclose(cam.q_GtoC, q, atol=1e-15)
    np.testing.assert_allclose(cam.p_CinG, p, atol=1e-15)
    assert cam.timestamp == state.timestamp == 3.5
    np.testing.assert_array_equal(cam.q_GtoC_null, cam.q_GtoC)
    np.testing.assert_array_equal(cam.p_CinG_null, cam.p_CinG)
    assert new.imu is state.imu
    assert state.camera_ids == (0,)
    np.testing.assert_array_equal(state.P, P_before)


def test_augmented_covariance_matches_monte_carlo_of_the_nonlinear_map(rng):
    """Sampled IMU errors pushed through the exact camera-pose formula have covariance J P J^T."""
    state = make_state(rng, n_cameras=0)
    P = np.diag(np.repeat([1e-4, 1e-6, 1e-2, 1e-4, 1e-2], 3))  # attitude 0.01 rad, position 0.1 m
    state = state.replace(P=P)
    new = augment_state(state, 0)
    q0, p0 = new.cameras[0].q_GtoC, new.cameras[0].p_CinG
    dx = rng.multivariate_normal(np.zeros(15), P, size=4000)
    # exact nonlinear map, batched: q_true = δq ⊗ q, p_true = p + δp, then q_GtoC = q_ItoC ⊗ q_true and
    # p_CinG = p_true + R_ItoG,true p_CinI
    q_true = quat_multiply(quat_from_rotvec(dx[:, 0:3]), state.imu.q_GtoI)
    p_true = state.imu.p_IinG + dx[:, 12:15]
    q_cam = quat_multiply(rot_to_quat(state.R_CtoI.T), q_true)
    p_cam = p_true + np.einsum("nji,j->ni", quat_to_rot(q_true), state.p_CinI)
    errs = np.hstack([quat_to_rotvec(quat_multiply(q_cam, quat_inverse(q0))), p_cam - p0])
    C = np.cov(errs.T)
    expected = new.P[15:, 15:]
    # sample covariance of 4000 draws: ~2.2 % relative std on the diagonal
    np.testing.assert_allclose(np.diag(C), np.diag(expected), rtol=0.1)


def test_augment_state_rejects_bad_inputs(rng):
    state = make_state(rng, n_cameras=1)
    with pytest.raises(ValueError, match=r"camera_id must be new; got 0 which is already in the window \(0,\)"):
        augment_state(state, 0)
    with pytest.raises(ValueError, match="camera_id must be an integer"):
        augment_state(state, 1.5)
    with pytest.raises(ValueError, match="state must be a FilterState"):
        augment_state({"imu": None}, 1)
    with pytest.raises(ValueError, match="state must be a FilterState"):
        augmentation_jacobian(None)
