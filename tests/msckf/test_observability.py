"""Tests for evio_lib.msckf.observability: the nullspace of Eq. 80 against a finite rotation/translation of the world,
the least-squares constraint of Eq. 84, the OC transition hook (Φ_k N_k = N_k+1 per interval and over a whole
propagation; plain Φ fails once the first estimates differ from the estimates), the OC measurement Jacobian
(H N = 0 for all four directions; plain Jacobians fail) and bad input."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import quat_from_rotvec, quat_multiply, quat_to_rot, rot_to_quat
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.observability import (
    camera_nullspace,
    constrain_camera_blocks,
    constrain_projected_jacobian,
    constrain_feature_jacobians,
    constrain_transition,
    imu_nullspace,
    least_squares_constraint,
    state_nullspace,
)
from evio_lib.msckf.propagation import propagate
from evio_lib.msckf.state import CameraState, FilterState, ImuState, state_difference
from evio_lib.msckf.update import feature_jacobians, nullspace_project
from evio_lib.sim.rig import CameraImuExtrinsics

G = np.array([0.0, 0.0, -9.81])


def random_rotation(rng):
    return Rotation.from_rotvec(rng.normal(scale=1.0, size=3)).as_matrix()


def moving_state(rng, n_cameras=0, perturb_null=0.0):
    """A state with random pose / velocity / biases (and cameras); first estimates optionally perturbed."""
    cfg = MsckfConfig()
    ext = CameraImuExtrinsics.default()
    imu = ImuState.from_pose(random_rotation(rng), rng.normal(size=3) * 2, rng.normal(size=3),
                             timestamp=0.0, b_g=rng.normal(scale=0.01, size=3), b_a=rng.normal(scale=0.1, size=3))
    s = FilterState.initial(imu, ext.R_CtoI, ext.p_CinI, cfg.initial_imu_covariance())
    for i in range(n_cameras):
        s = augment_state(s.replace(imu=ImuState.from_pose(random_rotation(rng), rng.normal(size=3) * 2,
                                                           np.zeros(3), 0.0)), i)
    if perturb_null:
        imu = s.imu
        q_null = quat_multiply(quat_from_rotvec(rng.normal(scale=perturb_null, size=3)), imu.q_GtoI)
        imu = ImuState(imu.q_GtoI, imu.b_g, imu.v_IinG, imu.b_a, imu.p_IinG, imu.timestamp, q_GtoI_null=q_null,
                       v_IinG_null=imu.v_IinG + rng.normal(scale=perturb_null, size=3),
                       p_IinG_null=imu.p_IinG + rng.normal(scale=perturb_null, size=3))
        s = s.replace(imu=imu)
    return s, cfg


def imu_log(rng, duration=0.2, rate=200.0):
    t = np.arange(0.0, duration + 1e-9, 1.0 / rate)
    gyro = rng.normal(scale=0.5, size=(len(t), 3))
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(scale=2.0, size=(len(t), 3))
    return t, gyro, accel


# ---------------------------------------------------------------- nullspace


def test_imu_nullspace_matches_a_small_yaw_and_shift_of_the_world(rng):
    """Rotating the world by ε about gravity and shifting it by d changes the true state by ≈ N [d; ε / |g|]."""
    s, _ = moving_state(rng, n_cameras=2)
    eps, d = 1e-6, rng.normal(size=3) * 1e-6
    R_eps = Rotation.from_rotvec([0.0, 0.0, eps]).as_matrix()  # world yaw about z (gravity axis)

    def world_moved(state):
        imu = state.imu
        new_imu = ImuState.from_pose(R_eps @ imu.R_ItoG, R_eps @ imu.p_IinG + d, R_eps @ imu.v_IinG,
                                     imu.timestamp, imu.b_g, imu.b_a)
        cams = {cid: CameraState(cid, c.timestamp, rot_to_quat(c.R_GtoC @ R_eps.T), R_eps @ c.p_CinG + d)
                for cid, c in state.cameras.items()}
        return state.replace(imu=new_imu, cameras=cams)

    dx = state_difference(world_moved(s), s)
    N = state_nullspace(s, G, first_estimates=False)
    # yaw column scaled by |g|: a world rotation ε about +z is ε / |g| times -(the column for g = -|g| z) ...
    expected = N[:, :3] @ d + N[:, 3] * (-eps / 9.81)
    np.testing.assert_allclose(dx, expected, atol=1e-11)
    assert np.abs(dx).max() > 1e-7  # the test moves something
    np.testing.assert_allclose(N[:15], imu_nullspace(s.imu.q_GtoI, s.imu.v_IinG, s.imu.p_IinG, G))


def test_least_squares_constraint_meets_the_constraint_with_a_rank_one_change(rng):
    A = rng.normal(size=(4, 3, 6))
    u = rng.normal(size=(4, 6))
    w = rng.normal(size=(4, 3))
    A_star = least_squares_constraint(A, u, w)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", A_star, u), w, atol=1e-12)
    # KKT of min |A' - A|_F s.t. A' u = w: every row of A' - A is parallel to u
    for k in range(4):
        D = A_star[k] - A[k]
        assert np.linalg.matrix_rank(np.vstack([D, u[k]]), tol=1e-10) == 1
    # any other solution is farther from A
    other = A_star[0] + np.outer(rng.normal(size=3), np.linalg.svd(u[0][None])[2][1])
    assert np.linalg.norm(other - A[0]) > np.linalg.norm(A_star[0] - A[0])
    np.testing.assert_allclose(least_squares_constraint(A, u) @ u[..., None], 0.0, atol=1e-12)


# ---------------------------------------------------------------- propagation


def _run_hook(state, cfg, t, gyro, accel, t_target, modify):
    record = {}

    def hook(Phi, steps):
        record["raw"] = Phi.copy()
        out = constrain_transition(Phi, steps) if modify else Phi
        record["Phi"], record["steps"] = out.copy(), steps
        return out

    out = propagate(state, t, gyro, accel, t_target, cfg, transition_hook=hook)
    return out, record


def _interval_residuals(Phi, steps):
    N_prev = imu_nullspace(steps.q_GtoI_prev, steps.v_IinG_prev, steps.p_IinG_prev, steps.gravity_G)
    N_next = imu_nullspace(steps.q_GtoI[1:], steps.v_IinG[1:], steps.p_IinG[1:], steps.gravity_G)
    return np.abs(Phi @ N_prev - N_next).max(axis=(1, 2))


def test_modified_transition_keeps_the_nullspace_and_plain_phi_does_not(rng):
    s, cfg = moving_state(rng, n_cameras=1, perturb_null=0.02)  # first estimates differ, as after an update
    t, gyro, accel = imu_log(rng)
    _, rec = _run_hook(s, cfg, t, gyro, accel, 0.1234, modify=True)
    assert _interval_residuals(rec["Phi"], rec["steps"]).max() < 1e-9
    # the plain Φ breaks it on the first interval (first estimate != estimate) and, slightly, on every other one
    plain = _interval_residuals(rec["raw"], rec["steps"])
    assert plain[0] > 1e-3
    assert np.all(plain[1:] > 1e-12)
    # only Φ_11, Φ_31, Φ_51 change
    changed = np.abs(rec["Phi"] - rec["raw"]).max(axis=0) > 0
    allowed = np.zeros((15, 15), dtype=bool)
    allowed[0:3, 0:3] = allowed[6:9, 0:3] = allowed[12:15, 0:3] = True
    assert not np.any(changed & ~allowed)


def test_oc_propagation_chains_the_nullspace_across_calls(rng):
    """Φ_total N(first estimates at start) = N(prediction at end), over two propagate calls."""
    s0, cfg = moving_state(rng, perturb_null=0.01)
    t, gyro, accel = imu_log(rng, duration=0.3)
    s1, rec1 = _run_hook(s0, cfg, t, gyro, accel, 0.1, modify=True)
    s2, rec2 = _run_hook(s1, cfg, t, gyro, accel, 0.25, modify=True)
    Phi_total = np.eye(15)
    for Phi in list(rec1["Phi"]) + list(rec2["Phi"]):
        Phi_total = Phi @ Phi_total
    imu0, imu2 = s0.imu, s2.imu
    N0 = imu_nullspace(imu0.q_GtoI_null, imu0.v_IinG_null, imu0.p_IinG_null, G)
    N2 = imu_nullspace(imu2.q_GtoI_null, imu2.v_IinG_null, imu2.p_IinG_null, G)
    np.testing.assert_allclose(Phi_total @ N0, N2, atol=1e-8)


def test_modification_is_small_when_first_estimates_are_the_estimates(rng):
    s, cfg = moving_state(rng)
    t, gyro, accel = imu_log(rng)
    _, rec = _run_hook(s, cfg, t, gyro, accel, 0.2, modify=True)
    assert np.abs(rec["Phi"] - rec["raw"]).max() < 1e-3  # O(dt^2) changes of a 5 ms step


def test_constrain_transition_checks_shapes(rng):
    s, cfg = moving_state(rng)
    t, gyro, accel = imu_log(rng)
    _, rec = _run_hook(s, cfg, t, gyro, accel, 0.05, modify=False)
    with pytest.raises(ValueError, match=r"Phi must have shape \(K, 15, 15\)"):
        constrain_transition(rec["Phi"][:-1], rec["steps"])


# ---------------------------------------------------------------- measurement


def _window_and_feature(rng, null_error):
    s, _ = moving_state(rng, n_cameras=4)
    p_F = rng.normal(size=3)
    cams = {}
    for cid, c in s.cameras.items():  # turn every camera to look at the feature, 3-6 m away
        z = rng.normal(size=3)
        z /= np.linalg.norm(z)
        p_C = p_F - rng.uniform(3.0, 6.0) * z
        x = np.cross(z, rng.normal(size=3))
        x /= np.linalg.norm(x)
        R_CtoG = np.column_stack([x, np.cross(z, x), z])
        q = rot_to_quat(R_CtoG.T)
        q_null = quat_multiply(quat_from_rotvec(rng.normal(scale=null_error, size=3)), q)
        cams[cid] = CameraState(cid, 0.0, q, p_C, q_GtoC_null=q_null,
                                p_CinG_null=p_C + rng.normal(scale=null_error, size=3))
    s = s.replace(cameras=cams)
    q_C, p_C = s.camera_poses
    R = quat_to_rot(q_C)
    p_FinC = np.einsum("mij,mj->mi", R, p_F - p_C)
    obs = p_FinC[:, :2] / p_FinC[:, 2:] + rng.normal(scale=0.005, size=(4, 2))
    cols = np.array([s.camera_index(cid) for cid in s.camera_ids])
    return s, p_F, obs, cols


@pytest.mark.parametrize("null_error", [0.0, 0.05])
def test_oc_measurement_jacobian_annihilates_the_nullspace(rng, null_error):
    s, p_F, obs, cols = _window_and_feature(rng, null_error)
    q_C, p_C = s.camera_poses
    _, H_x, H_f = feature_jacobians(q_C, p_C, cols, p_F, obs, s.dim)
    nulls = [(c.q_GtoC_null, c.p_CinG_null) for c in s.cameras.values()]
    q_null, p_null = np.array([q for q, _ in nulls]), np.array([p for _, p in nulls])
    H_x2, H_f2 = constrain_feature_jacobians(H_x, H_f, cols, q_null, p_null, p_F, G)
    N = state_nullspace(s, G, first_estimates=True)
    N_f = np.column_stack([np.eye(3), -np.cross(p_F, G)])  # feature: [I, -[p_F x] g]
    scale = np.abs(H_x).max()
    assert np.abs(H_x2 @ N + H_f2 @ N_f).max() < 1e-12 * scale * 10
    plain = np.abs(H_x @ N + H_f @ N_f).max()
    if null_error:
        assert plain > 1e-3 * scale  # the plain Jacobian sees "yaw" once first estimates differ
        assert np.abs(H_x2 - H_x).max() > 1e-4 * scale
    else:  # first estimates = estimates: the plain Jacobian already satisfies it, OC changes nothing
        assert plain < 1e-12 * scale * 10
        np.testing.assert_allclose(H_x2, H_x, atol=1e-12 * scale)
        np.testing.assert_allclose(H_f2, H_f, atol=1e-12 * scale)


def test_constrain_camera_blocks_batches_like_the_full_matrix_version(rng):
    s, p_F, obs, cols = _window_and_feature(rng, 0.05)
    q_C, p_C = s.camera_poses
    _, H_x, H_f = feature_jacobians(q_C, p_C, cols, p_F, obs, s.dim)
    R_null = quat_to_rot(np.array([c.q_GtoC_null for c in s.cameras.values()]))
    p_null = np.array([c.p_CinG_null for c in s.cameras.values()])
    blocks = np.stack([H_x[2 * i:2 * i + 2, c:c + 6] for i, c in enumerate(cols)])
    b2, f2 = constrain_camera_blocks(blocks, R_null, p_null, np.tile(p_F, (4, 1)), G)
    H_x2, H_f2 = constrain_feature_jacobians(H_x, H_f, cols, R_null, p_null, p_F, G)
    for i, c in enumerate(cols):
        np.testing.assert_allclose(H_x2[2 * i:2 * i + 2, c:c + 6], b2[i])
    np.testing.assert_allclose(H_f2, f2.reshape(-1, 3))


def test_bad_inputs_raise_value_errors(rng):
    with pytest.raises(ValueError, match=r"u must be non-zero"):
        least_squares_constraint(np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"u must have shape \(\.\.\., 3\)"):
        least_squares_constraint(np.eye(3), np.ones(2))
    with pytest.raises(ValueError, match=r"A must have shape"):
        least_squares_constraint(np.ones(3), np.ones(3))
    with pytest.raises(ValueError, match=r"gravity_G must be a non-zero vector"):
        imu_nullspace([0, 0, 0, 1.0], np.zeros(3), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"q_GtoI must have shape"):
        imu_nullspace([0, 0, 1.0], np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"state must be a FilterState"):
        state_nullspace("state")
    with pytest.raises(ValueError, match=r"H_C must have shape \(\.\.\., 2, 6\)"):
        constrain_camera_blocks(np.zeros((2, 5)), np.eye(3), np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match=r"cam_columns must be"):
        constrain_feature_jacobians(np.zeros((4, 27)), np.zeros((4, 3)), [15, 25], np.stack([np.eye(3)] * 2),
                                    np.zeros((2, 3)), np.ones(3))
    with pytest.raises(ValueError, match=r"H_f must have shape \(4, 3\)"):
        constrain_feature_jacobians(np.zeros((4, 27)), np.zeros((2, 3)), [15, 21], np.stack([np.eye(3)] * 2),
                                    np.zeros((2, 3)), np.ones(3))


# ---------------------------------------------------------------- projected (whole-feature) constraint


def test_camera_nullspace_equals_the_camera_rows_of_the_state_nullspace(rng):
    s, _ = moving_state(rng, n_cameras=3)
    cams = list(s.cameras.values())
    N_C = camera_nullspace(quat_to_rot(np.array([c.q_GtoC_null for c in cams])),
                           np.array([c.p_CinG_null for c in cams]), G)
    np.testing.assert_allclose(N_C, state_nullspace(s, G)[15:], atol=1e-12)


@pytest.mark.parametrize("null_error", [0.0, 0.05])
def test_projected_constraint_annihilates_the_nullspace_with_a_minimal_change(rng, null_error):
    s, p_F, obs, cols = _window_and_feature(rng, null_error)
    q_C, p_C = s.camera_poses
    r, H_x, H_f = feature_jacobians(q_C, p_C, cols, p_F, obs, s.dim)
    H_o, _ = nullspace_project(H_x, H_f, r)
    cc = (cols[:, None] + np.arange(6)).reshape(-1)
    N = state_nullspace(s, G, first_estimates=True)
    cams = list(s.cameras.values())
    N_C = camera_nullspace(quat_to_rot(np.array([c.q_GtoC_null for c in cams])),
                           np.array([c.p_CinG_null for c in cams]), G)
    H2 = constrain_projected_jacobian(H_o[:, cc], N_C)
    scale = np.abs(H_o).max()
    assert np.abs(H2 @ N[cc]).max() < 1e-12 * scale * 10
    # minimal Frobenius change: the change lies in span(N) (rows of ΔH are combinations of N's columns)
    dH = H_o[:, cc] - H2
    coef = np.linalg.lstsq(N_C, dH.T, rcond=None)[0]
    np.testing.assert_allclose(N_C @ coef, dH.T, atol=1e-12 * scale * 10)
    plain = np.abs(H_o @ N).max()
    if null_error:
        assert plain > 1e-3 * scale  # plain projected Jacobian sees "yaw" once the first estimates differ
        # it changes less than Eq. 86 does (4 conditions per feature instead of 2 per camera)
        q_null, p_null = np.array([c.q_GtoC_null for c in cams]), np.array([c.p_CinG_null for c in cams])
        H_x86, H_f86 = constrain_feature_jacobians(H_x, H_f, cols, q_null, p_null, p_F, G)
        assert np.linalg.norm(H_x86 - H_x) > np.linalg.norm(dH)
    else:  # translation is annihilated exactly already; yaw too when first estimates = estimates
        assert plain < 1e-12 * scale * 10
        np.testing.assert_allclose(H2, H_o[:, cc], atol=1e-12 * scale)


def test_weighted_projected_constraint_changes_the_certain_columns(rng):
    H = np.array([[1.0, 1.0]])
    N = np.array([[1.0], [1.0]])
    P = np.diag([1.0, 1e-4])  # column 1 is well known: a change there adds little information relative to P
    H2 = constrain_projected_jacobian(H, N, P)
    assert abs((H2 @ N).item()) < 1e-12
    assert abs(H2[0, 0] - 1.0) < 1e-3 and abs(H2[0, 1] + 1.0) < 1e-3  # almost all change in column 1
    np.testing.assert_allclose(constrain_projected_jacobian(H, N), [[0.0, 0.0]], atol=1e-15)


def test_projected_constraint_bad_inputs(rng):
    with pytest.raises(ValueError, match=r"N_C must have shape \(\.\.\., 12, r\)"):
        constrain_projected_jacobian(np.zeros((3, 12)), np.zeros((6, 4)))
    with pytest.raises(ValueError, match=r"P_C must have shape \(\.\.\., 12, 12\)"):
        constrain_projected_jacobian(np.zeros((3, 12)), np.zeros((12, 4)), np.eye(6))
    with pytest.raises(ValueError, match=r"R_GtoC_null \(\.\.\., M, 3, 3\) and p_CinG_null"):
        camera_nullspace(np.stack([np.eye(3)] * 2), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"H_o must contain only finite"):
        constrain_projected_jacobian(np.full((3, 6), np.nan), np.zeros((6, 4)))
