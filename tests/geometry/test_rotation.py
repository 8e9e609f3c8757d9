"""Tests for evio_lib.geometry.rotation: JPL quaternions pinned against scipy (Hamilton, active matrices),
scipy.linalg.expm and finite differences."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import (
    cross3,
    hamilton_to_jpl,
    jpl_to_hamilton,
    omega_matrix,
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_to_rot,
    quat_to_rotvec,
    rot_to_quat,
    skew,
    small_angle_quat,
    so3_exp,
    so3_log,
)

IDENTITY_Q = np.array([0.0, 0.0, 0.0, 1.0])

# ---------------------------------------------------------------- helpers / strategies

finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False, allow_infinity=False)
quat_strategy = st.tuples(finite, finite, finite, finite).map(np.array).filter(lambda q: np.linalg.norm(q) > 0.1)
vec_strategy = st.tuples(finite, finite, finite).map(lambda v: 3.0 * np.array(v))  # |v| up to ~5.2 rad
PROPERTY = settings(derandomize=True, max_examples=60, deadline=None)


def same_rotation_quat(a: np.ndarray, b: np.ndarray, atol: float = 1e-12) -> bool:
    """True where unit quaternions a and b are equal up to the q/-q sign ambiguity."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return bool(np.all(np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1)) < atol))


def random_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def scipy_jpl_matrix(q: np.ndarray) -> np.ndarray:
    """Independent truth: the JPL matrix of q is the transposed scipy (Hamilton, active) matrix of the same numbers."""
    return np.swapaxes(Rotation.from_quat(q).as_matrix(), -1, -2)


# ---------------------------------------------------------------- skew


def test_skew_is_cross_product_and_antisymmetric(rng):
    a, b = rng.normal(size=(2, 7, 3))
    S = skew(a)
    assert S.shape == (7, 3, 3) and S.dtype == np.float64
    np.testing.assert_allclose(S @ b[..., None], np.cross(a, b)[..., None], atol=1e-14)
    np.testing.assert_array_equal(S, -np.swapaxes(S, -1, -2))


@pytest.mark.parametrize("shape_a, shape_b", [((3,), (3,)), ((50, 3), (50, 3)), ((7, 1, 3), (40, 3)), ((3,), (9, 3))])
def test_cross3_is_np_cross_bit_for_bit(rng, shape_a, shape_b):
    a = rng.normal(size=shape_a) * 10.0 ** rng.uniform(-6, 6, size=shape_a)
    b = rng.normal(size=shape_b) * 10.0 ** rng.uniform(-6, 6, size=shape_b)
    expected = np.cross(a, b)
    got = cross3(a, b)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got, expected)


def test_skew_thesis_layout():
    # thesis Eq. 20: [p x] = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
    np.testing.assert_array_equal(skew([1, 2, 3]), [[0, -3, 2], [3, 0, -1], [-2, 1, 0]])


# ---------------------------------------------------------------- quaternion <-> matrix against scipy


def test_quat_to_rot_matches_scipy_transposed(rng):
    q = random_quats(rng, 200)
    np.testing.assert_allclose(quat_to_rot(q), scipy_jpl_matrix(q), atol=1e-14)


def test_quat_to_rot_formula_and_normalises(rng):
    q = random_quats(rng, 5)
    qv, qw = q[:, :3], q[:, 3]
    expected = np.array(
        [(2 * w**2 - 1) * np.eye(3) - 2 * w * skew(v) + 2 * np.outer(v, v) for v, w in zip(qv, qw)]
    )
    np.testing.assert_allclose(quat_to_rot(q), expected, atol=1e-14)
    np.testing.assert_allclose(quat_to_rot(3.7 * q), expected, atol=1e-14)  # non-unit input is normalised
    np.testing.assert_allclose(quat_to_rot(-q), expected, atol=1e-14)  # q and -q: same rotation


def test_quat_to_rot_passive_meaning():
    # q_GtoI of a body yawed +90 deg about z: world x-axis seen in I is -y_I
    q_GtoI = quat_from_rotvec([0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(quat_to_rot(q_GtoI) @ [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], atol=1e-15)


@PROPERTY
@given(q=quat_strategy)
def test_quat_to_rot_property_scipy(q):
    np.testing.assert_allclose(quat_to_rot(q), scipy_jpl_matrix(q), atol=1e-13)


def test_rot_to_quat_matches_scipy(rng):
    r = Rotation.random(300, rng=rng)
    q_expected = r.as_quat(canonical=False)  # Hamilton of the active matrix == JPL of its transpose
    q = rot_to_quat(np.swapaxes(r.as_matrix(), -1, -2))
    assert q.shape == (300, 4)
    assert np.all(q[:, 3] >= 0.0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    assert same_rotation_quat(q, q_expected)


@PROPERTY
@given(q=quat_strategy)
def test_rot_quat_round_trip_property(q):
    R = quat_to_rot(q)
    q_back = rot_to_quat(R)
    assert q_back[3] >= 0.0
    assert same_rotation_quat(q_back, q)
    np.testing.assert_allclose(quat_to_rot(q_back), R, atol=1e-14)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-6, 0.5, np.pi / 2, np.pi - 1e-4, np.pi - 1e-9, np.pi])
def test_rot_to_quat_robust_all_angles(rng, angle):
    axes = rng.normal(size=(50, 3))
    axes = np.concatenate([np.eye(3), -np.eye(3), axes / np.linalg.norm(axes, axis=-1, keepdims=True)])
    R = Rotation.from_rotvec(angle * axes).as_matrix()  # active exp([θ x])
    q = rot_to_quat(R)
    np.testing.assert_allclose(quat_to_rot(q), R, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    # R is active exp(θ) = passive C(quat_from_rotvec(-θ))
    assert same_rotation_quat(q, quat_from_rotvec(-angle * axes), atol=1e-12)


# ---------------------------------------------------------------- product, inverse, normalise


def test_quat_multiply_matches_matrix_product_and_scipy(rng):
    q, p = random_quats(rng, 100), random_quats(rng, 100)
    qp = quat_multiply(q, p)
    np.testing.assert_allclose(quat_to_rot(qp), quat_to_rot(q) @ quat_to_rot(p), atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(qp, axis=-1), 1.0, atol=1e-14)
    # JPL q ⊗ p has the numbers of the Hamilton product p * q (scipy composes Hamilton products)
    ham = (Rotation.from_quat(p) * Rotation.from_quat(q)).as_quat(canonical=False)
    assert same_rotation_quat(qp, ham)


def test_quat_multiply_explicit_formula():
    q = np.array([0.1, -0.2, 0.3, 0.9])
    p = np.array([-0.4, 0.5, 0.2, 0.7])
    qv, qw, pv, pw = q[:3], q[3], p[:3], p[3]
    expected = np.concatenate([qw * pv + pw * qv - np.cross(qv, pv), [qw * pw - qv @ pv]])
    np.testing.assert_allclose(quat_multiply(q, p), expected, atol=1e-15)


@PROPERTY
@given(q=quat_strategy, p=quat_strategy, r=quat_strategy)
def test_quat_multiply_associative_and_compatible(q, p, r):
    np.testing.assert_allclose(
        quat_multiply(quat_multiply(q, p), r), quat_multiply(q, quat_multiply(p, r)), atol=1e-13
    )
    np.testing.assert_allclose(
        quat_to_rot(quat_multiply(q, p)), quat_to_rot(q) @ quat_to_rot(p), atol=1e-13
    )


def test_quat_multiply_identity_and_broadcast(rng):
    q = random_quats(rng, 6).reshape(2, 3, 4)
    np.testing.assert_allclose(quat_multiply(q, IDENTITY_Q), q, atol=0)
    np.testing.assert_allclose(quat_multiply(IDENTITY_Q, q), q, atol=0)
    assert quat_multiply(q, q[0, 0]).shape == (2, 3, 4)


def test_quat_inverse(rng):
    q = random_quats(rng, 50)
    q_inv = quat_inverse(q)
    np.testing.assert_allclose(quat_multiply(q, q_inv), np.tile(IDENTITY_Q, (50, 1)), atol=1e-15)
    np.testing.assert_allclose(quat_multiply(q_inv, q), np.tile(IDENTITY_Q, (50, 1)), atol=1e-15)
    np.testing.assert_allclose(quat_to_rot(q_inv), np.swapaxes(quat_to_rot(q), -1, -2), atol=1e-14)
    np.testing.assert_allclose(q_inv, (Rotation.from_quat(q).inv()).as_quat(canonical=False), atol=1e-15)
    # non-unit: a true inverse, not just the conjugate
    np.testing.assert_allclose(quat_multiply(2.5 * q, quat_inverse(2.5 * q)), np.tile(IDENTITY_Q, (50, 1)), atol=1e-14)


def test_quat_normalize(rng):
    q = rng.normal(size=(40, 4)) * 3.0
    qn = quat_normalize(q)
    np.testing.assert_allclose(np.linalg.norm(qn, axis=-1), 1.0, atol=1e-15)
    assert np.all(qn[:, 3] >= 0.0)
    assert same_rotation_quat(qn, q)
    np.testing.assert_allclose(quat_normalize([0, 0, 0, -5]), IDENTITY_Q)


# ---------------------------------------------------------------- rotation vectors, small angles


def test_quat_from_rotvec_matches_scipy_and_is_passive(rng):
    theta = rng.normal(size=(100, 3)) * 1.5
    q = quat_from_rotvec(theta)
    # same numbers as scipy's Hamilton quaternion of the active exp([θ x]) (no sign ambiguity: qw = cos(|θ|/2))
    np.testing.assert_allclose(q, Rotation.from_rotvec(theta).as_quat(canonical=False), atol=1e-15)
    # its JPL (passive) matrix is exp(-[θ x])
    np.testing.assert_allclose(quat_to_rot(q), np.array([expm(-skew(t)) for t in theta]), atol=1e-13)


def test_quat_from_rotvec_at_and_near_zero():
    np.testing.assert_array_equal(quat_from_rotvec(np.zeros(3)), IDENTITY_Q)
    tiny = np.array([1e-12, -2e-12, 3e-12])
    np.testing.assert_allclose(quat_from_rotvec(tiny), np.concatenate([tiny / 2, [1.0]]), rtol=1e-15, atol=0)


@PROPERTY
@given(theta=vec_strategy)
def test_rotvec_quat_round_trip_property(theta):
    angle = np.linalg.norm(theta)
    q = quat_from_rotvec(theta)
    back = quat_to_rotvec(q)
    # the inverse returns the equivalent vector with |θ| <= π
    wrapped = theta * (1.0 - 2.0 * np.pi / angle) if angle > np.pi else theta
    np.testing.assert_allclose(back, wrapped, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-14, 1e-9, 1e-7, 1e-5, 1.0, np.pi - 1e-7])
def test_quat_to_rotvec_accuracy_small_and_large(rng, angle):
    axis = rng.normal(size=3)
    theta = angle * axis / np.linalg.norm(axis)
    np.testing.assert_allclose(quat_to_rotvec(quat_from_rotvec(theta)), theta, rtol=1e-9, atol=1e-15)
    back = quat_to_rotvec(quat_from_rotvec(theta))
    np.testing.assert_allclose(back, Rotation.from_rotvec(theta).as_rotvec(), atol=1e-12)


def test_quat_to_rotvec_taylor_branch_is_exact_to_rounding(rng):
    # just below and above the series switch (|qv| = 1e-6): full double precision on both sides
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    for angle in [1.9e-6, 2.1e-6]:
        theta = angle * axis
        np.testing.assert_allclose(quat_to_rotvec(quat_from_rotvec(theta)), theta, rtol=1e-14, atol=0)


def test_small_angle_quat_is_third_order_accurate(rng):
    axis = rng.normal(size=(20, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    errors = []
    for scale in [1e-1, 1e-2, 1e-3]:
        dtheta = scale * axis
        dq = small_angle_quat(dtheta)
        np.testing.assert_allclose(np.linalg.norm(dq, axis=-1), 1.0, atol=1e-15)
        errors.append(np.abs(dq - quat_from_rotvec(dtheta)).max())
    # agreement to second order: error ~ c |δθ|^3 (c = 1/12), so 10x smaller angles -> ~1000x smaller error
    assert errors[0] < 0.1**3 / 10
    assert errors[0] / errors[1] > 500 and errors[1] / errors[2] > 500
    np.testing.assert_array_equal(small_angle_quat(np.zeros(3)), IDENTITY_Q)


def test_small_angle_quat_error_state_convention(rng):
    # q_true = δq ⊗ q_est  =>  R_true ≈ (I - [δθ x]) R_est  (passive JPL error)
    q_est = random_quats(rng, 1)[0]
    dtheta = np.array([1e-4, -2e-4, 3e-4])
    R_true = quat_to_rot(quat_multiply(small_angle_quat(dtheta), q_est))
    np.testing.assert_allclose(R_true, (np.eye(3) - skew(dtheta)) @ quat_to_rot(q_est), atol=1e-7)


# ---------------------------------------------------------------- SO(3) exp / log


def test_so3_exp_matches_scipy_and_expm(rng):
    phi = rng.normal(size=(100, 3)) * 2.0
    R = so3_exp(phi)
    np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(R[:5], np.array([expm(skew(p)) for p in phi[:5]]), atol=1e-13)
    np.testing.assert_allclose(R, np.swapaxes(quat_to_rot(quat_from_rotvec(phi)), -1, -2), atol=1e-14)


@pytest.mark.parametrize("angle", [0.0, 1e-15, 1e-10, 1e-7, 1e-4])
def test_so3_exp_near_zero(angle):
    phi = angle * np.array([0.6, -0.8, 0.0])
    # relative accuracy of the rotation part against expm of the tiny skew matrix
    np.testing.assert_allclose(so3_exp(phi) - np.eye(3), expm(skew(phi)) - np.eye(3), rtol=1e-12, atol=1e-30)


def test_so3_log_matches_scipy(rng):
    r = Rotation.random(300, rng=rng)
    np.testing.assert_allclose(so3_log(r.as_matrix()), r.as_rotvec(), atol=1e-13)


@pytest.mark.parametrize(
    "angle", [0.0, 1e-15, 1e-12, 1e-8, 1e-4, 1.0, 3.0, np.pi - 1e-4, np.pi - 1e-8, np.pi - 1e-12, np.pi]
)
def test_so3_exp_log_round_trip_near_zero_and_pi(rng, angle):
    axis = rng.normal(size=(30, 3))
    axis = np.concatenate([np.eye(3), axis / np.linalg.norm(axis, axis=-1, keepdims=True)])
    phi = angle * axis
    R = so3_exp(phi)
    phi_back = so3_log(R)
    np.testing.assert_allclose(so3_exp(phi_back), R, atol=1e-14)
    assert np.all(np.linalg.norm(phi_back, axis=-1) <= np.pi + 1e-12)
    if angle < np.pi - 1e-6:  # unique logarithm away from π
        np.testing.assert_allclose(phi_back, phi, rtol=1e-8, atol=1e-15)
    else:  # at/near π, ±φ are (almost) both valid; the angle is still exact
        np.testing.assert_allclose(np.linalg.norm(phi_back, axis=-1), angle, atol=1e-7)


@PROPERTY
@given(phi=vec_strategy)
def test_so3_log_exp_property(phi):
    R = so3_exp(phi)
    np.testing.assert_allclose(so3_exp(so3_log(R)), R, atol=1e-13)
    np.testing.assert_allclose(so3_log(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-10)


# ---------------------------------------------------------------- kinematics


def test_omega_matrix_structure(rng):
    w = rng.normal(size=(5, 3))
    Om = omega_matrix(w)
    assert Om.shape == (5, 4, 4)
    np.testing.assert_array_equal(Om, -np.swapaxes(Om, -1, -2))
    q = random_quats(rng, 5)
    pure = np.concatenate([w, np.zeros((5, 1))], axis=-1)
    np.testing.assert_allclose((Om @ q[..., None])[..., 0], quat_multiply(pure, q), atol=1e-15)


def test_omega_matrix_finite_differences(rng):
    """dq_GtoI/dt = ½ Ω(w_I) q_GtoI, with the truth built by scipy: R_ItoG(t) = R_ItoG(0) exp([w t x])."""
    w_I = np.array([0.7, -1.3, 2.1])
    R0_ItoG = Rotation.random(rng=rng).as_matrix()
    h, t = 1e-5, 0.37

    def q_GtoI(tt: float) -> np.ndarray:
        R_ItoG = R0_ItoG @ expm(skew(w_I * tt))
        # the JPL quaternion of R_GtoI has the numbers of scipy's Hamilton quaternion of R_GtoI^T = R_ItoG
        return Rotation.from_matrix(R_ItoG).as_quat(canonical=False)

    q_m, q_0, q_p = q_GtoI(t - h), q_GtoI(t), q_GtoI(t + h)
    q_m = q_m * np.sign(q_m @ q_0)  # keep one sign along the path
    q_p = q_p * np.sign(q_p @ q_0)
    dq_dt = (q_p - q_m) / (2.0 * h)
    np.testing.assert_allclose(dq_dt, 0.5 * omega_matrix(w_I) @ q_0, atol=1e-8)
    # a flipped convention (Ω(-w)) must not match
    assert np.abs(dq_dt - 0.5 * omega_matrix(-w_I) @ q_0).max() > 0.1
    # constant-rate closed form: q(t + dt) = quat_from_rotvec(w dt) ⊗ q(t), also for a large step
    dt = 0.3
    assert same_rotation_quat(quat_multiply(quat_from_rotvec(w_I * dt), q_0), q_GtoI(t + dt), atol=1e-12)
    np.testing.assert_allclose(expm(0.5 * omega_matrix(w_I) * dt) @ q_0, quat_multiply(quat_from_rotvec(w_I * dt), q_0),
                               atol=1e-12)


# ---------------------------------------------------------------- Hamilton <-> JPL


def test_hamilton_jpl_same_matrix(rng):
    r = Rotation.random(100, rng=rng)
    q_ham = r.as_quat()
    q_jpl = hamilton_to_jpl(q_ham)
    np.testing.assert_allclose(quat_to_rot(q_jpl), r.as_matrix(), atol=1e-14)
    np.testing.assert_array_equal(jpl_to_hamilton(q_jpl), q_ham)
    np.testing.assert_allclose(Rotation.from_quat(jpl_to_hamilton(q_jpl)).as_matrix(), quat_to_rot(q_jpl), atol=1e-14)


def test_tum_pose_example(rng):
    # a TUM line stores p_CinG and the Hamilton quaternion of R_CtoG
    R_CtoG = Rotation.random(rng=rng).as_matrix()
    p_CinG = rng.normal(size=3)
    tum_q = Rotation.from_matrix(R_CtoG).as_quat()
    q_CtoG = hamilton_to_jpl(tum_q)
    q_GtoC = quat_inverse(q_CtoG)
    point_C = np.array([0.1, -0.2, 3.0])
    point_G = quat_to_rot(q_CtoG) @ point_C + p_CinG
    np.testing.assert_allclose(point_G, R_CtoG @ point_C + p_CinG, atol=1e-14)
    np.testing.assert_allclose(quat_to_rot(q_GtoC) @ (point_G - p_CinG), point_C, atol=1e-14)


# ---------------------------------------------------------------- shapes, dtypes, no mutation


BATCH = (2, 3)


@pytest.mark.parametrize(
    "func, tail_in, tail_out",
    [
        (skew, (3,), (3, 3)),
        (quat_normalize, (4,), (4,)),
        (quat_inverse, (4,), (4,)),
        (quat_to_rot, (4,), (3, 3)),
        (quat_from_rotvec, (3,), (4,)),
        (quat_to_rotvec, (4,), (3,)),
        (small_angle_quat, (3,), (4,)),
        (so3_exp, (3,), (3, 3)),
        (omega_matrix, (3,), (4, 4)),
        (hamilton_to_jpl, (4,), (4,)),
        (jpl_to_hamilton, (4,), (4,)),
    ],
)
def test_batch_shapes_dtype_and_no_mutation(rng, func, tail_in, tail_out):
    x = (rng.normal(size=BATCH + tail_in)).astype(np.float32)
    x_copy = x.copy()
    out = func(x)
    assert out.shape == BATCH + tail_out and out.dtype == np.float64
    np.testing.assert_array_equal(x, x_copy)
    single = func(x[1, 2])
    assert single.shape == tail_out
    np.testing.assert_allclose(out[1, 2], single, atol=1e-12)


def test_batch_shapes_matrix_inputs(rng):
    R = so3_exp(rng.normal(size=BATCH + (3,)))
    R_copy = R.copy()
    assert rot_to_quat(R).shape == BATCH + (4,)
    assert so3_log(R).shape == BATCH + (3,)
    assert rot_to_quat(R[0, 0]).shape == (4,)
    assert rot_to_quat(np.eye(3, dtype=int)).dtype == np.float64
    assert rot_to_quat(np.empty((0, 3, 3))).shape == (0, 4)
    np.testing.assert_array_equal(R, R_copy)
    q = random_quats(rng, 6).reshape(BATCH + (4,))
    assert quat_multiply(q, q).shape == BATCH + (4,)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "func, arg, bad_shape, pattern",
    [
        (skew, "v", (4,), r"v must have shape \(\.\.\., 3\); got \(4,\)"),
        (quat_normalize, "q", (3,), r"q must have shape \(\.\.\., 4\); got \(3,\)"),
        (quat_inverse, "q", (5, 3), r"q must have shape \(\.\.\., 4\); got \(5, 3\)"),
        (quat_to_rot, "q", (3, 3), r"q must have shape \(\.\.\., 4\)"),
        (quat_from_rotvec, "theta", (4,), r"theta must have shape \(\.\.\., 3\)"),
        (quat_to_rotvec, "q", (3,), r"q must have shape \(\.\.\., 4\)"),
        (small_angle_quat, "dtheta", (2,), r"dtheta must have shape \(\.\.\., 3\)"),
        (so3_exp, "phi", (3, 2), r"phi must have shape \(\.\.\., 3\); got \(3, 2\)"),
        (omega_matrix, "w", (), r"w must have shape \(\.\.\., 3\); got \(\)"),
        (rot_to_quat, "R", (3,), r"R must have shape \(\.\.\., 3, 3\); got \(3,\)"),
        (so3_log, "R", (4, 4), r"R must have shape \(\.\.\., 3, 3\); got \(4, 4\)"),
        (hamilton_to_jpl, "q_xyzw", (3,), r"q_xyzw must have shape \(\.\.\., 4\)"),
        (jpl_to_hamilton, "q", (4, 3), r"q must have shape \(\.\.\., 4\)"),
    ],
)
def test_bad_shapes_raise(func, arg, bad_shape, pattern):
    with pytest.raises(ValueError, match=pattern):
        func(np.ones(bad_shape))


@pytest.mark.parametrize(
    "func, x, name",
    [
        (skew, [0.0, np.nan, 1.0], "v"),
        (quat_normalize, [0.0, 0.0, np.inf, 1.0], "q"),
        (quat_to_rot, [np.nan, 0.0, 0.0, 1.0], "q"),
        (quat_from_rotvec, [np.inf, 0.0, 0.0], "theta"),
        (so3_exp, [0.0, 0.0, np.nan], "phi"),
        (omega_matrix, [0.0, -np.inf, 0.0], "w"),
        (rot_to_quat, np.full((3, 3), np.nan), "R"),
        (hamilton_to_jpl, [0.0, 0.0, 0.0, np.nan], "q_xyzw"),
    ],
)
def test_non_finite_raises(func, x, name):
    with pytest.raises(ValueError, match=rf"{name} must contain only finite values"):
        func(x)


def test_quat_multiply_bad_inputs():
    with pytest.raises(ValueError, match=r"p must have shape \(\.\.\., 4\); got \(3,\)"):
        quat_multiply(IDENTITY_Q, np.ones(3))
    with pytest.raises(ValueError, match=r"q must contain only finite values"):
        quat_multiply([np.nan, 0, 0, 1], IDENTITY_Q)


@pytest.mark.parametrize("func", [quat_normalize, quat_inverse, quat_to_rot, quat_to_rotvec])
def test_zero_quaternion_raises(func):
    with pytest.raises(ValueError, match=r"q must have a non-zero norm"):
        func(np.zeros((2, 4)))


@pytest.mark.parametrize("func", [rot_to_quat, so3_log])
def test_non_rotation_matrix_raises(func):
    with pytest.raises(ValueError, match=r"R must be a rotation matrix with R @ R.T == I"):
        func(1.01 * np.eye(3))
    with pytest.raises(ValueError, match=r"R must be a rotation matrix with R @ R.T == I"):
        func(np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(ValueError, match=r"det\(R\) == 1 .*got det -1"):
        func(np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])]))  # a reflection in the batch
    func(so3_exp([0.1, 0.2, 0.3]) + 1e-9)  # within tolerance: accepted


def test_non_numeric_input_raises():
    with pytest.raises(ValueError, match=r"v must be a numeric array"):
        skew(["a", "b", "c"])
