"""Tests for evio_lib.msckf.state: IMU / camera / filter states, error injection and removal of camera states."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import rot_to_quat, skew
from evio_lib.msckf.state import (
    BA,
    BG,
    POS,
    THETA,
    VEL,
    CameraState,
    FilterState,
    ImuState,
    inject_error,
    remove_camera_states,
    state_difference,
    symmetrize,
)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return Rotation.from_rotvec(rng.normal(size=3)).as_matrix()


def random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def make_state(rng: np.random.Generator, n_cameras: int = 3) -> FilterState:
    """A random filter state with n_cameras camera poses (ids 10, 11, ...) and a random SPD covariance."""
    imu = ImuState.from_pose(random_rotation(rng), rng.normal(size=3), rng.normal(size=3), timestamp=1.25,
                             b_g=0.01 * rng.normal(size=3), b_a=0.1 * rng.normal(size=3))
    cams = {
        10 + i: CameraState(10 + i, 0.1 * i, rot_to_quat(random_rotation(rng)), rng.normal(size=3))
        for i in range(n_cameras)
    }
    n = 15 + 6 * n_cameras
    return FilterState(imu, cams, random_spd(rng, n), random_rotation(rng), rng.normal(size=3) * 0.05)


# ---------------------------------------------------------------- ImuState / CameraState


def test_imu_state_from_pose_stores_the_jpl_quaternion_and_first_estimates(rng):
    R_ItoG = random_rotation(rng)
    p, v = rng.normal(size=3), rng.normal(size=3)
    s = ImuState.from_pose(R_ItoG, p, v, timestamp=2.0)
    # JPL numbers of R_GtoI = Hamilton quaternion (scipy, xyzw) of the transposed matrix R_GtoI^T = R_ItoG
    q_expected = Rotation.from_matrix(R_ItoG).as_quat()
    q_expected *= np.sign(q_expected[3])
    np.testing.assert_allclose(s.q_GtoI, q_expected, atol=1e-12)
    np.testing.assert_allclose(s.R_ItoG, R_ItoG, atol=1e-12)
    np.testing.assert_allclose(s.R_GtoI, R_ItoG.T, atol=1e-12)
    np.testing.assert_array_equal(s.b_g, np.zeros(3))
    assert s.q_GtoI_null is s.q_GtoI and s.v_IinG_null is s.v_IinG and s.p_IinG_null is s.p_IinG
    assert s.timestamp == 2.0


def test_imu_state_copies_its_inputs_and_is_read_only(rng):
    p = rng.normal(size=3)
    s = ImuState(np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), np.zeros(3), np.zeros(3), p, 0.0)
    p[0] = 1e9
    assert s.p_IinG[0] != 1e9
    with pytest.raises(ValueError):
        s.p_IinG[0] = 1.0
    with pytest.raises(AttributeError):
        s.timestamp = 3.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("q_GtoI", [0.0, 0.0, 0.0, 2.0], r"q_GtoI must be a unit quaternion .* got \|q\| = 2"),
        ("q_GtoI", [0.0, 0.0, 1.0], r"q_GtoI must have shape \(4,\); got \(3,\)"),
        ("v_IinG", [0.0, np.nan, 0.0], "v_IinG must contain only finite values"),
        ("b_a", np.zeros((3, 1)), r"b_a must have shape \(3,\); got \(3, 1\)"),
        ("timestamp", float("inf"), "timestamp must be a finite time"),
    ],
)
def test_imu_state_rejects_bad_inputs(field, value, message):
    kwargs = dict(q_GtoI=[0.0, 0.0, 0.0, 1.0], b_g=np.zeros(3), v_IinG=np.zeros(3), b_a=np.zeros(3),
                  p_IinG=np.zeros(3), timestamp=0.0)
    kwargs[field] = value
    with pytest.raises(ValueError, match=message):
        ImuState(**kwargs)


def test_camera_state_validation_and_rotation(rng):
    R_CtoG = random_rotation(rng)
    cam = CameraState(3, 0.5, rot_to_quat(R_CtoG.T), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(cam.R_CtoG, R_CtoG, atol=1e-12)
    np.testing.assert_array_equal(cam.p_CinG_null, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="id must be an integer"):
        CameraState(True, 0.5, [0.0, 0.0, 0.0, 1.0], np.zeros(3))
    with pytest.raises(ValueError, match=r"p_CinG must have shape \(3,\)"):
        CameraState(1, 0.5, [0.0, 0.0, 0.0, 1.0], np.zeros(4))


# ---------------------------------------------------------------- FilterState


def test_filter_state_sizes_indices_and_camera_arrays(rng):
    s = make_state(rng, n_cameras=3)
    assert s.dim == 33 and s.num_cameras == 3 and s.camera_ids == (10, 11, 12)
    assert s.camera_index(10) == 15 and s.camera_index(12) == 27
    assert s.camera_slice(11) == slice(21, 27)
    q, p = s.camera_poses
    assert q.shape == (3, 4) and p.shape == (3, 3)
    np.testing.assert_array_equal(p[1], s.cameras[11].p_CinG)
    np.testing.assert_allclose(s.R_ItoC, s.R_CtoI.T)
    assert s.timestamp == 1.25
    with pytest.raises(ValueError, match=r"camera_id must be one of the window's ids \(10, 11, 12\); got 99"):
        s.camera_index(99)
    with pytest.raises(TypeError):
        s.cameras[99] = s.cameras[10]  # type: ignore[index]


def test_filter_state_rejects_bad_covariance_and_cameras(rng):
    s = make_state(rng, n_cameras=1)
    with pytest.raises(ValueError, match=r"P must have shape .* = \(21, 21\) for N = 1; got \(15, 15\)"):
        s.replace(P=np.eye(15))
    bad = s.P.copy()
    bad[0, 1] += 1.0
    with pytest.raises(ValueError, match="P must be symmetric"):
        s.replace(P=bad)
    bad = s.P.copy()
    bad[3, 3] = np.nan
    with pytest.raises(ValueError, match="P must contain only finite values"):
        s.replace(P=bad)
    with pytest.raises(ValueError, match="cameras must map each id to a CameraState with that id"):
        s.replace(cameras={5: s.cameras[10]})
    with pytest.raises(ValueError, match="R_CtoI must be a rotation matrix"):
        s.replace(R_CtoI=2.0 * np.eye(3))
    with pytest.raises(ValueError, match="imu must be an ImuState"):
        s.replace(imu="imu")


def test_symmetrize():
    P = np.array([[2.0, 1.0], [3.0, 4.0]])
    np.testing.assert_array_equal(symmetrize(P), [[2.0, 2.0], [2.0, 4.0]])
    with pytest.raises(ValueError, match=r"P must be a square matrix"):
        symmetrize(np.ones((2, 3)))


# ---------------------------------------------------------------- error injection


def test_inject_error_and_state_difference_are_inverse(rng):
    est = make_state(rng, n_cameras=3)
    dx = 0.3 * rng.normal(size=est.dim)
    true = inject_error(est, dx)
    np.testing.assert_allclose(state_difference(true, est), dx, atol=1e-12)
    np.testing.assert_allclose(state_difference(est, est), np.zeros(est.dim), atol=1e-15)
    # and back: applying -dx undoes the additive parts exactly and the rotations to round-off
    back = inject_error(true, -dx)
    np.testing.assert_allclose(state_difference(back, est), np.zeros(est.dim), atol=1e-12)


def test_inject_error_follows_the_jpl_error_quaternion_convention(rng):
    est = make_state(rng, n_cameras=2)
    dx = np.zeros(est.dim)
    dx[THETA] = [0.2, -0.1, 0.3]
    dx[est.camera_index(11):est.camera_index(11) + 3] = [-0.05, 0.1, 0.02]
    new = inject_error(est, dx)
    # q_true = δq ⊗ q_est  <=>  R_GtoI,true = exp(-[δθ x]) R_GtoI,est (JPL, passive);
    # scipy's from_rotvec gives the active exp([δθ x])
    dR = Rotation.from_rotvec(dx[THETA]).as_matrix().T
    np.testing.assert_allclose(new.imu.R_GtoI, dR @ est.imu.R_GtoI, atol=1e-12)
    dRc = Rotation.from_rotvec([-0.05, 0.1, 0.02]).as_matrix().T
    np.testing.assert_allclose(new.cameras[11].R_GtoC, dRc @ est.cameras[11].R_GtoC, atol=1e-12)
    np.testing.assert_allclose(new.cameras[10].R_GtoC, est.cameras[10].R_GtoC, atol=1e-15)
    # small angle: δq ≈ [δθ/2, 1] (thesis Eq. 24), R_true ≈ (I - [δθ x]) R_est
    small = np.zeros(est.dim)
    small[THETA] = [1e-7, -2e-7, 3e-7]
    tiny = inject_error(est, small)
    np.testing.assert_allclose(tiny.imu.R_GtoI, (np.eye(3) - skew(small[THETA])) @ est.imu.R_GtoI, atol=1e-13)


def test_inject_error_is_additive_elsewhere_and_keeps_the_rest(rng):
    est = make_state(rng, n_cameras=2)
    dx = rng.normal(size=est.dim)
    new = inject_error(est, dx)
    np.testing.assert_allclose(new.imu.b_g, est.imu.b_g + dx[BG])
    np.testing.assert_allclose(new.imu.v_IinG, est.imu.v_IinG + dx[VEL])
    np.testing.assert_allclose(new.imu.b_a, est.imu.b_a + dx[BA])
    np.testing.assert_allclose(new.imu.p_IinG, est.imu.p_IinG + dx[POS])
    np.testing.assert_allclose(new.cameras[11].p_CinG, est.cameras[11].p_CinG + dx[est.camera_slice(11)][3:])
    # first estimates, timestamps, covariance and extrinsics are untouched
    np.testing.assert_array_equal(new.imu.q_GtoI_null, est.imu.q_GtoI_null)
    np.testing.assert_array_equal(new.imu.p_IinG_null, est.imu.p_IinG_null)
    np.testing.assert_array_equal(new.cameras[10].q_GtoC_null, est.cameras[10].q_GtoC_null)
    assert new.timestamp == est.timestamp and new.cameras[11].timestamp == est.cameras[11].timestamp
    np.testing.assert_array_equal(new.P, est.P)
    np.testing.assert_array_equal(new.p_CinI, est.p_CinI)
    assert abs(np.linalg.norm(new.imu.q_GtoI) - 1.0) < 1e-15


def test_inject_error_does_not_modify_its_inputs(rng):
    est = make_state(rng, n_cameras=2)
    q_before, p_before, P_before = est.imu.q_GtoI.copy(), est.cameras[10].p_CinG.copy(), est.P.copy()
    dx = rng.normal(size=est.dim)
    dx_before = dx.copy()
    inject_error(est, dx)
    np.testing.assert_array_equal(est.imu.q_GtoI, q_before)
    np.testing.assert_array_equal(est.cameras[10].p_CinG, p_before)
    np.testing.assert_array_equal(est.P, P_before)
    np.testing.assert_array_equal(dx, dx_before)


def test_inject_error_rejects_bad_dx(rng):
    est = make_state(rng, n_cameras=1)
    with pytest.raises(ValueError, match=r"dx must have shape \(15 \+ 6N,\) = \(21,\) for N = 1; got \(15,\)"):
        inject_error(est, np.zeros(15))
    with pytest.raises(ValueError, match="dx must contain only finite values"):
        inject_error(est, np.full(21, np.nan))
    with pytest.raises(ValueError, match="state must be a FilterState"):
        inject_error("state", np.zeros(21))


def test_state_difference_needs_the_same_cameras(rng):
    a = make_state(rng, n_cameras=2)
    b = remove_camera_states(a, [10])
    with pytest.raises(ValueError, match="same camera ids in the same order"):
        state_difference(a, b)


# ---------------------------------------------------------------- removing camera states


def test_remove_camera_states_deletes_their_rows_and_columns(rng):
    s = make_state(rng, n_cameras=4)  # ids 10..13
    r = remove_camera_states(s, [11, 13])
    assert r.camera_ids == (10, 12)
    keep = np.r_[0:15, 15:21, 27:33]  # IMU, camera 10, camera 12
    np.testing.assert_array_equal(r.P, s.P[np.ix_(keep, keep)])
    assert r.cameras[12] is s.cameras[12]
    assert r.imu is s.imu
    assert s.camera_ids == (10, 11, 12, 13)  # input untouched
    assert s.remove_camera_states([]) is s
    keep = np.r_[0:15, 21:39]
    np.testing.assert_array_equal(s.remove_camera_states([10, 10]).P, s.P[np.ix_(keep, keep)])


def test_remove_camera_states_rejects_unknown_ids(rng):
    s = make_state(rng, n_cameras=2)
    with pytest.raises(ValueError, match=r"ids must be camera ids in the window \(10, 11\); got 7"):
        remove_camera_states(s, [7])
    with pytest.raises(ValueError, match="ids must be an iterable of camera ids"):
        remove_camera_states(s, 10)
