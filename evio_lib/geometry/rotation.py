"""Rotations for the whole project: JPL quaternions, rotation matrices, rotation vectors and SO(3) exp/log.

Convention (JPL, Trawny & Roumeliotis, "Indirect Kalman Filter for 3D Attitude Estimation", 2005; thesis
§3.3.1-3.3.2, Eqs. 18-24). The thesis prints Eq. 18 with the scalar first, [qw qx qy qz], but Eq. 24 with the
scalar last; this library stores the scalar LAST everywhere::

    q = [qx, qy, qz, qw] = [qv, qw],   |q| = 1,   qw >= 0 after normalisation

Rotation matrix of a JPL quaternion (a *passive* matrix: q_GtoI gives R_GtoI, v_I = R_GtoI @ v_G)::

    C(q) = (2 qw^2 - 1) I - 2 qw [qv x] + 2 qv qv^T

JPL product (q ⊗ p = L(q) p, compatible with matrix products: C(q ⊗ p) = C(q) C(p))::

    q ⊗ p = [ qw pv + pw qv - qv x pv ,  qw pw - qv . pv ]

Skew matrix (thesis Eq. 20): [v x] b = v x b. Error quaternion (thesis Eqs. 23-24): q_true = δq ⊗ q_est with
δq ≈ [δθ/2, 1] for a small attitude error δθ. Kinematics: dq_GtoI/dt = ½ Ω(w_I) q_GtoI.

Relation to Hamilton quaternions (scipy, TUM/ECD/EuRoC files): for the SAME rotation matrix R, the JPL quaternion
is the conjugate of the Hamilton one. Equivalently, the four numbers of a JPL quaternion are the Hamilton
quaternion of R^T, so ``quat_to_rot(q) == Rotation.from_quat(q).as_matrix().T`` (scipy, xyzw order).

Rotation vectors: ``quat_from_rotvec(theta)`` is the JPL quaternion [sin(|θ|/2) θ/|θ|, cos(|θ|/2)]; because JPL
matrices are passive its matrix is C = exp(-[θ x]) = so3_exp(theta).T, whereas ``so3_exp(phi)`` is the active
exp([φ x]) (Rodrigues), i.e. scipy's ``Rotation.from_rotvec(phi).as_matrix()``.
``quat_to_rotvec`` (an extra helper) inverts ``quat_from_rotvec`` and ``so3_log`` inverts ``so3_exp``.

Every function accepts one item or a batch (leading dimensions ``...``), returns float64 and never modifies its
inputs. Bad shapes or non-finite values raise ``ValueError`` naming the argument.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "as_float_array",
    "check_rotation",
    "skew",
    "cross3",
    "quat_normalize",
    "quat_multiply",
    "quat_inverse",
    "quat_to_rot",
    "rot_to_quat",
    "quat_from_rotvec",
    "quat_to_rotvec",
    "small_angle_quat",
    "so3_exp",
    "so3_log",
    "omega_matrix",
    "hamilton_to_jpl",
    "jpl_to_hamilton",
]

_ROT_TOL = 1e-6  # tolerance on det(R) - 1 and R R^T - I for rot_to_quat / so3_log
_SMALL_ANGLE = 1e-6  # below this |qv| the rotation-vector formulas switch to their Taylor series


def as_float_array(x: ArrayLike, name: str, tail: tuple[int, ...]) -> NDArray[np.float64]:
    """Return ``x`` as a float64 array whose trailing shape is ``tail``; raise ValueError otherwise or if not finite.

    The shared input check of the rotation and filter code: the message names ``name`` and the expected (..., tail).
    """
    expected = "(..., " + ", ".join(map(str, tail)) + ")"
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got {x!r}") from exc
    if arr.ndim < len(tail) or arr.shape[arr.ndim - len(tail):] != tail:
        raise ValueError(f"{name} must have shape {expected}; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values (no NaN/inf)")
    return arr


def skew(v: ArrayLike) -> NDArray[np.float64]:
    """Return the skew-symmetric cross-product matrix [v x] (..., 3, 3), so that skew(a) @ b == cross(a, b).

    Args:
        v: (..., 3) vectors (any frame; the matrix acts in the same frame).

    Reference: thesis Eq. 20.

    >>> skew([1.0, 2.0, 3.0])
    array([[ 0., -3.,  2.],
           [ 3.,  0., -1.],
           [-2.,  1.,  0.]])
    """
    return skew_unchecked(as_float_array(v, "v", (3,)))


def cross3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return a x b (..., 3) for (..., 3) arrays that broadcast: ``np.cross``'s numbers, bit for bit, in a third of
    its time on small arrays (the filter's and RANSAC's inner loops call it tens of thousands of times per run).

    ``(a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0)``, each product rounded before the difference, as ``np.cross``.

    >>> cross3(np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    array([0., 0., 1.])
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def skew_unchecked(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return [v x] (..., 3, 3) for an already validated float64 (..., 3) array: the fast path of :func:`skew`.

    For inner loops (filter propagation and updates) whose inputs were checked once upstream.
    """
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out = np.zeros(v.shape[:-1] + (3, 3), dtype=np.float64)
    # [v x] = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
    out[..., 0, 1] = -z
    out[..., 0, 2] = y
    out[..., 1, 0] = z
    out[..., 1, 2] = -x
    out[..., 2, 0] = -y
    out[..., 2, 1] = x
    return out


def quat_normalize(q: ArrayLike) -> NDArray[np.float64]:
    """Return the unit JPL quaternion(s) (..., 4) [qx, qy, qz, qw] with qw >= 0 (q and -q are the same rotation).

    Args:
        q: (..., 4) quaternions, scalar last, non-zero and finite.

    Raises:
        ValueError: wrong shape, non-finite entries or a (near) zero norm.

    >>> quat_normalize([1.0, 1.0, 1.0, -1.0])
    array([-0.5, -0.5, -0.5,  0.5])
    """
    q = as_float_array(q, "q", (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError(f"q must have a non-zero norm; got norm {float(norm.min()):.3g}")
    # q_unit = sign(qw) q / |q|  (sign(0) taken as +1)
    sign = np.where(q[..., 3:4] < 0.0, -1.0, 1.0)
    return q * (sign / norm)


def quat_multiply(q: ArrayLike, p: ArrayLike) -> NDArray[np.float64]:
    """Return the JPL product q ⊗ p (..., 4), for which C(q ⊗ p) = C(q) @ C(p).

    Args:
        q: (..., 4) JPL quaternion(s), scalar last (e.g. q_ItoC).
        p: (..., 4) JPL quaternion(s), scalar last (e.g. q_GtoI); leading dimensions broadcast.

    The product is bilinear and is not renormalised. Reference: Trawny & Roumeliotis 2005 (quaternion
    multiplication); thesis Eqs. 23, 27.

    >>> q_z90 = quat_from_rotvec([0.0, 0.0, np.pi / 2])
    >>> np.round(quat_multiply(q_z90, q_z90), 3)      # 90 deg twice = 180 deg about z
    array([0., 0., 1., 0.])
    """
    q = as_float_array(q, "q", (4,))
    p = as_float_array(p, "p", (4,))
    qv, qw = q[..., :3], q[..., 3:4]
    pv, pw = p[..., :3], p[..., 3:4]
    # vector = qw pv + pw qv - qv x pv ;  scalar = qw pw - qv . pv
    vec = qw * pv + pw * qv - cross3(qv, pv)
    scal = qw * pw - np.sum(qv * pv, axis=-1, keepdims=True)
    return np.concatenate([vec, scal], axis=-1)


def quat_inverse(q: ArrayLike) -> NDArray[np.float64]:
    """Return the inverse quaternion q^-1 = [-qv, qw] / |q|^2 (..., 4) (the conjugate for unit q).

    Args:
        q: (..., 4) JPL quaternion(s), scalar last, non-zero. If q is q_GtoI the result is q_ItoG.

    >>> quat_inverse([0.48, 0.0, 0.36, 0.8]) + 0.0
    array([-0.48,  0.  , -0.36,  0.8 ])
    """
    q = as_float_array(q, "q", (4,))
    norm2 = np.sum(q * q, axis=-1, keepdims=True)
    if np.any(norm2 < 1e-24):
        raise ValueError(f"q must have a non-zero norm; got norm {float(np.sqrt(norm2.min())):.3g}")
    conj = np.concatenate([-q[..., :3], q[..., 3:4]], axis=-1)
    return conj / norm2


def quat_to_rot(q: ArrayLike) -> NDArray[np.float64]:
    """Return the rotation matrix C(q) (..., 3, 3) of JPL quaternion(s); for q_GtoI this is R_GtoI.

    Args:
        q: (..., 4) JPL quaternion(s), scalar last; normalised first (raises on zero norm).

    C(q) = (2 qw^2 - 1) I - 2 qw [qv x] + 2 qv qv^T  (Trawny & Roumeliotis 2005).
    Equals ``scipy.spatial.transform.Rotation.from_quat(q).as_matrix().T``.

    >>> np.round(quat_to_rot(quat_from_rotvec([0.0, 0.0, np.pi / 2])), 3) + 0.0
    array([[ 0.,  1.,  0.],
           [-1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    q = quat_normalize(q)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    # C = (2 qw^2 - 1) I - 2 qw [qv x] + 2 qv qv^T, written out entry by entry
    out = np.empty(q.shape[:-1] + (3, 3), dtype=np.float64)
    d = 2.0 * w * w - 1.0
    out[..., 0, 0] = d + 2.0 * x * x
    out[..., 1, 1] = d + 2.0 * y * y
    out[..., 2, 2] = d + 2.0 * z * z
    out[..., 0, 1] = 2.0 * (x * y + w * z)
    out[..., 1, 0] = 2.0 * (x * y - w * z)
    out[..., 0, 2] = 2.0 * (x * z - w * y)
    out[..., 2, 0] = 2.0 * (x * z + w * y)
    out[..., 1, 2] = 2.0 * (y * z + w * x)
    out[..., 2, 1] = 2.0 * (y * z - w * x)
    return out


def check_rotation(R: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return R as float64 (..., 3, 3) after checking it is a rotation (det = 1, R R^T = I within 1e-6)."""
    R = as_float_array(R, name, (3, 3))
    orth_err = np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max(axis=(-2, -1)) if R.size else np.zeros(0)
    if np.any(orth_err > _ROT_TOL):
        raise ValueError(
            f"{name} must be a rotation matrix with {name} @ {name}.T == I (tol {_ROT_TOL:g}); "
            f"got max deviation {float(np.max(orth_err)):.3g}"
        )
    det = np.sum(R[..., 0, :] * cross3(R[..., 1, :], R[..., 2, :]), axis=-1)  # det R = r0 . (r1 x r2)
    if np.any(np.abs(det - 1.0) > _ROT_TOL):
        bad = det.flat[int(np.argmax(np.abs(det - 1.0)))]
        raise ValueError(
            f"{name} must be a rotation matrix with det({name}) == 1 (tol {_ROT_TOL:g}); got det {bad:.6g}"
        )
    return R


def rot_to_quat(R: ArrayLike) -> NDArray[np.float64]:
    """Return the unit JPL quaternion(s) (..., 4), qw >= 0, whose matrix C(q) is R; R_GtoI gives q_GtoI.

    Args:
        R: (..., 3, 3) rotation matrices (det 1, R R^T = I within 1e-6).

    Shepperd's method: of the four squares 4qw^2 = 1 + tr R, 4qx^2 = 1 + R00 - R11 - R22, ... the largest is
    taken as pivot so the division is always well conditioned (robust at 180 degrees). From C(q):
    R12 - R21 = 4 qw qx, R20 - R02 = 4 qw qy, R01 - R10 = 4 qw qz, R01 + R10 = 4 qx qy, R02 + R20 = 4 qx qz,
    R12 + R21 = 4 qy qz.

    >>> rot_to_quat(np.diag([1.0, -1.0, -1.0]))      # 180 deg about x
    array([1., 0., 0., 0.])
    """
    return _rot_to_quat_unchecked(check_rotation(R, "R"))


def _rot_to_quat_unchecked(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Shepperd's method on an already validated (..., 3, 3) float64 rotation; see rot_to_quat."""
    r00, r01, r02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r10, r11, r12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r20, r21, r22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    trace = r00 + r11 + r22
    # each row is (4 q_pivot) * [qx, qy, qz, qw] for pivot x, y, z, w
    cand = np.stack(
        [
            np.stack([1.0 + r00 - r11 - r22, r01 + r10, r02 + r20, r12 - r21], axis=-1),  # pivot qx
            np.stack([r01 + r10, 1.0 - r00 + r11 - r22, r12 + r21, r20 - r02], axis=-1),  # pivot qy
            np.stack([r02 + r20, r12 + r21, 1.0 - r00 - r11 + r22, r01 - r10], axis=-1),  # pivot qz
            np.stack([r12 - r21, r20 - r02, r01 - r10, 1.0 + trace], axis=-1),  # pivot qw
        ],
        axis=-2,
    )
    pivot = np.argmax(np.stack([r00, r11, r22, trace], axis=-1), axis=-1)
    q = np.take_along_axis(cand, pivot[..., None, None], axis=-2)[..., 0, :]
    return quat_normalize(q)


def quat_from_rotvec(theta: ArrayLike) -> NDArray[np.float64]:
    """Return the exact JPL quaternion(s) (..., 4) [sin(|θ|/2) θ/|θ|, cos(|θ|/2)] of rotation vector(s) θ.

    Args:
        theta: (..., 3) rotation vectors in radians (safe at θ = 0).

    JPL matrices are passive, so the matrix of the result is C = exp(-[θ x]) = so3_exp(theta).T: a frame turned by
    +θ (right-hand rule) maps vectors with exp(-[θ x]). Reference: Trawny & Roumeliotis 2005 (axis-angle quaternion).

    >>> np.round(quat_from_rotvec([0.0, 0.0, np.pi]), 3)
    array([0., 0., 1., 0.])
    """
    theta = as_float_array(theta, "theta", (3,))
    angle = np.linalg.norm(theta, axis=-1, keepdims=True)
    # sin(|θ|/2) / |θ| = 0.5 * sinc(|θ| / (2π)) with numpy's normalised sinc (exact at 0)
    half_sinc = 0.5 * np.sinc(angle / (2.0 * np.pi))
    return np.concatenate([half_sinc * theta, np.cos(0.5 * angle)], axis=-1)


def quat_to_rotvec(q: ArrayLike) -> NDArray[np.float64]:
    """Return the rotation vector(s) θ (..., 3), |θ| <= π, with quat_from_rotvec(θ) equal to q up to sign.

    Args:
        q: (..., 4) JPL quaternion(s), scalar last; normalised first (qw >= 0).

    θ = 2 atan2(|qv|, qw) qv / |qv|, with the Taylor series 2/qw (1 - |qv|^2 / (3 qw^2)) for tiny |qv|.

    >>> np.round(quat_to_rotvec(quat_from_rotvec([0.1, -0.2, 0.3])), 6)
    array([ 0.1, -0.2,  0.3])
    """
    q = quat_normalize(q)
    qv, qw = q[..., :3], q[..., 3:4]
    n = np.linalg.norm(qv, axis=-1, keepdims=True)
    small = n < _SMALL_ANGLE
    n_safe = np.where(small, 1.0, n)
    qw_safe = np.where(small, qw, 1.0)  # qw ~ 1 where small
    # scale = |θ| / |qv| = 2 atan2(|qv|, qw) / |qv|
    scale = np.where(small, 2.0 / qw_safe * (1.0 - n**2 / (3.0 * qw_safe**2)), 2.0 * np.arctan2(n, qw) / n_safe)
    return scale * qv


def small_angle_quat(dtheta: ArrayLike) -> NDArray[np.float64]:
    """Return the first-order error quaternion(s) (..., 4) δq = [δθ/2, 1] / |[δθ/2, 1]|.

    Args:
        dtheta: (..., 3) small attitude errors in radians (e.g. δθ of q_GtoI in q_true = δq ⊗ q_est).

    Reference: thesis Eq. 24; Trawny & Roumeliotis 2005 (small-angle error quaternion). Agrees with
    quat_from_rotvec(dtheta) up to O(|δθ|^3).

    >>> small_angle_quat([0.0, 0.0, 0.0])
    array([0., 0., 0., 1.])
    """
    dtheta = as_float_array(dtheta, "dtheta", (3,))
    dq = np.concatenate([0.5 * dtheta, np.ones(dtheta.shape[:-1] + (1,))], axis=-1)  # [δθ/2, 1]
    return dq / np.linalg.norm(dq, axis=-1, keepdims=True)


def so3_exp(phi: ArrayLike) -> NDArray[np.float64]:
    """Return the rotation matrix exp([φ x]) (..., 3, 3) (Rodrigues' formula; accurate near φ = 0).

    Args:
        phi: (..., 3) rotation vectors in radians.

    exp([φ x]) = I + sin|φ|/|φ| [φ x] + (1 - cos|φ|)/|φ|^2 [φ x]^2, evaluated through sinc so it is exact at 0.
    This is the active matrix: so3_exp(phi) == Rotation.from_rotvec(phi).as_matrix() == quat_to_rot(
    quat_from_rotvec(phi)).T.

    >>> np.round(so3_exp([0.0, 0.0, np.pi / 2]), 3) + 0.0
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    phi = as_float_array(phi, "phi", (3,))
    angle = np.linalg.norm(phi, axis=-1)
    a = np.sinc(angle / np.pi)  # sin(θ)/θ
    b = 0.5 * np.sinc(angle / (2.0 * np.pi)) ** 2  # (1 - cos θ)/θ^2 = ½ (sin(θ/2)/(θ/2))^2
    K = skew(phi)
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def so3_log(R: ArrayLike) -> NDArray[np.float64]:
    """Return the rotation vector(s) φ (..., 3), |φ| <= π, with so3_exp(φ) == R (inverse of so3_exp).

    Args:
        R: (..., 3, 3) rotation matrices (det 1, R R^T = I within 1e-6).

    Computed through the quaternion (Shepperd + atan2), so it stays accurate near 0 and near π: the JPL quaternion
    of R is that of exp(-[φ x]) reversed, hence φ = -quat_to_rotvec(rot_to_quat(R)). At exactly π, φ and -φ are
    both valid; one is returned.

    >>> np.round(so3_log(so3_exp([0.3, -0.2, 0.1])), 6)
    array([ 0.3, -0.2,  0.1])
    """
    R = check_rotation(R, "R")
    # C(quat_from_rotvec(θ)) = exp(-[θ x])  =>  log(R) = -rotvec(q(R))
    return -quat_to_rotvec(_rot_to_quat_unchecked(R))


def omega_matrix(w: ArrayLike) -> NDArray[np.float64]:
    """Return Ω(ω) (..., 4, 4) of the JPL kinematics dq_GtoI/dt = ½ Ω(w_I) q_GtoI.

    Args:
        w: (..., 3) angular velocity of I expressed in I (w_I), rad/s.

    Ω(ω) = [[-[ω x], ω], [-ω^T, 0]] (Trawny & Roumeliotis 2005, quaternion kinematics); it is the left-product
    matrix of the pure quaternion [ω, 0], i.e. Ω(ω) q = [ω, 0] ⊗ q. Integrating over dt with constant ω gives
    q(t + dt) = quat_from_rotvec(ω dt) ⊗ q(t).

    >>> omega_matrix([1.0, 2.0, 3.0])
    array([[ 0.,  3., -2.,  1.],
           [-3.,  0.,  1.,  2.],
           [ 2., -1.,  0.,  3.],
           [-1., -2., -3.,  0.]])
    """
    w = as_float_array(w, "w", (3,))
    out = np.zeros(w.shape[:-1] + (4, 4), dtype=np.float64)
    out[..., :3, :3] = skew(-w)  # -[ω x] = [(-ω) x]
    out[..., :3, 3] = w
    out[..., 3, :3] = -w
    return out


def hamilton_to_jpl(q_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Return the JPL quaternion(s) (..., 4) with the same rotation matrix as Hamilton quaternion(s) [x, y, z, w].

    Args:
        q_xyzw: (..., 4) Hamilton quaternions, scalar last (TUM/ECD/EuRoC files, scipy ``Rotation.from_quat``).

    The two are conjugates: [x, y, z, w] -> [-x, -y, -z, w] (no normalisation; use quat_normalize if needed).
    Example: a TUM line "t px py pz qx qy qz qw" stores the Hamilton quaternion of R_CtoG (camera orientation in the
    world). hamilton_to_jpl of it is the JPL q_CtoG (quat_to_rot gives the same R_CtoG), and
    quat_inverse(q_CtoG) is q_GtoC.

    >>> q_CtoG = hamilton_to_jpl([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # camera yawed +90 deg
    >>> np.round(quat_to_rot(q_CtoG), 3) + 0.0                                        # R_CtoG
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    q = as_float_array(q_xyzw, "q_xyzw", (4,))
    return np.concatenate([-q[..., :3], q[..., 3:4]], axis=-1)


def jpl_to_hamilton(q: ArrayLike) -> NDArray[np.float64]:
    """Return the Hamilton quaternion(s) [x, y, z, w] (..., 4) with the same rotation matrix as JPL quaternion(s) q.

    Args:
        q: (..., 4) JPL quaternion(s), scalar last. Inverse of hamilton_to_jpl (conjugation, no normalisation);
            the result can be passed to ``scipy.spatial.transform.Rotation.from_quat`` or written to a TUM file.

    >>> jpl_to_hamilton([0.48, 0.0, -0.36, 0.8]) + 0.0
    array([-0.48,  0.  ,  0.36,  0.8 ])
    """
    q = as_float_array(q, "q", (4,))
    return np.concatenate([-q[..., :3], q[..., 3:4]], axis=-1)
