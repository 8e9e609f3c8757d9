"""Two-view epipolar geometry: essential matrix, eight-point algorithm, pose recovery, triangulation.

Conventions (camera 1 and camera 2, C = x right, y down, z forward):

* points are undistorted normalised image coordinates ``x = [X/Z, Y/Z]`` unless a function says pixels;
* the relative pose maps camera-1 coordinates into camera 2: ``X_C2 = R_C1toC2 @ X_C1 + p_C1inC2``, where
  ``p_C1inC2`` is the position of camera 1's centre in frame C2 (thesis Eq. 2 writes it t_{k-1}^k);
* the epipolar constraint is ``x2h^T E x1h = 0`` with ``E = [p_C1inC2 x] R_C1toC2`` (thesis Eqs. 2-3).

This is OpenCV's convention for ``findEssentialMat`` / ``recoverPose`` / ``triangulatePoints`` (points1 = view 1,
points2 = view 2, (R, t) map view 1 into view 2). The essential matrix is only defined up to scale and sign, so
monocular translation comes out as a unit direction.

Reference: thesis §2.1.2, Eqs. 2-3; Hartley & Zisserman, "Multiple View Geometry", 2nd ed., §9.6 (essential matrix,
Result 9.19), §11.2 (normalised eight-point algorithm), §11.4.3 (Sampson distance), §12.2 (linear triangulation);
Hartley, "In defense of the eight-point algorithm", PAMI 1997.
"""
from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scipy.optimize import least_squares

from evio_lib.geometry.rotation import skew, so3_exp

__all__ = [
    "essential_from_pose",
    "fundamental_from_essential",
    "eight_point",
    "decompose_essential",
    "triangulate_dlt",
    "recover_pose",
    "epipolar_residuals",
    "sampson_distance",
    "refine_essential",
    "estimate_essential_ransac",
]

_ROT_TOL = 1e-6  # tolerance on R R^T = I and det R = 1
_MIN_POINTS = 8  # the eight-point algorithm needs at least 8 correspondences
_RANSAC_CONFIDENCE = 0.999  # RANSAC stops once an all-inlier sample has been drawn with this probability
_RANSAC_BATCH = 64  # hypotheses evaluated together (vectorised) per RANSAC round


# ---------------------------------------------------------------------------------------------- input checks
def _as_matrix(value: ArrayLike, name: str, shape: tuple[int, int]) -> NDArray[np.float64]:
    """Return ``value`` as a finite float64 array of the given shape, or raise ValueError naming ``name``."""
    array = np.asarray(value, dtype=np.float64)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}; got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    return array


def _as_rotation(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return a checked (3, 3) rotation matrix (R R^T = I, det R = 1 within 1e-6)."""
    R = _as_matrix(value, name, (3, 3))
    deviation = float(np.abs(R @ R.T - np.eye(3)).max())
    if deviation > _ROT_TOL or abs(np.linalg.det(R) - 1.0) > _ROT_TOL:
        raise ValueError(
            f"{name} must be a rotation matrix (R @ R.T == I, det R == 1 within {_ROT_TOL:g}); "
            f"got max |R R^T - I| = {deviation:.3g}, det = {np.linalg.det(R):.6g}"
        )
    return R


def _as_vector3(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return a finite float64 (3,) vector (a (3, 1) column is accepted and flattened)."""
    array = np.asarray(value, dtype=np.float64)
    if array.shape not in ((3,), (3, 1)):
        raise ValueError(f"{name} must have shape (3,) or (3, 1); got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite; got {array.ravel()}")
    return array.reshape(3)


def _as_essential(value: ArrayLike, name: str = "E") -> NDArray[np.float64]:
    """Return a finite, non-zero (3, 3) float64 matrix."""
    E = _as_matrix(value, name, (3, 3))
    if not np.any(E):
        raise ValueError(f"{name} must be a non-zero (3, 3) matrix; got all zeros")
    return E


def _as_point_pair(
    xy1: ArrayLike, xy2: ArrayLike, min_points: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return two finite float64 (N, 2) arrays of corresponding points with the same N >= ``min_points``."""
    out = []
    for name, value in (("xy1", xy1), ("xy2", xy2)):
        array = np.asarray(value, dtype=np.float64)
        if array.ndim != 2 or array.shape[1] != 2:
            raise ValueError(f"{name} must have shape (N, 2) as (x, y) rows; got {array.shape}")
        if not np.isfinite(array).all():
            raise ValueError(f"{name} must be finite; got NaN or inf entries")
        out.append(array)
    if out[0].shape[0] != out[1].shape[0]:
        raise ValueError(
            f"xy1 and xy2 must hold the same number of correspondences; got {out[0].shape[0]} and {out[1].shape[0]}"
        )
    if out[0].shape[0] < min_points:
        raise ValueError(f"xy1 and xy2 must hold at least {min_points} correspondences (N >= {min_points}); "
                         f"got N = {out[0].shape[0]}")
    return out[0], out[1]


def _homogeneous(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return (..., 3) homogeneous points [x, y, 1] of (..., 2) points."""
    return np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)


# ---------------------------------------------------------------------------------------------- essential matrix
def essential_from_pose(R_C1toC2: ArrayLike, p_C1inC2: ArrayLike) -> NDArray[np.float64]:
    """Return the (3, 3) essential matrix E = [p_C1inC2 x] R_C1toC2 of a relative camera pose.

    Args:
        R_C1toC2: (3, 3) rotation taking camera-1 coordinates into camera 2.
        p_C1inC2: (3,) position of camera 1's centre in frame C2 (any scale; E scales with it).

    Reference: thesis §2.1.2, Eqs. 2-3.

    >>> E = essential_from_pose(np.eye(3), [1.0, 0.0, 0.0])   # sideways motion, no rotation
    >>> E
    array([[ 0.,  0.,  0.],
           [ 0.,  0., -1.],
           [ 0.,  1.,  0.]])
    >>> float(np.array([0.2, 0.1, 1.0]) @ E @ np.array([0.7, 0.1, 1.0]))   # same row y = 0.1 -> on the line
    0.0
    """
    R = _as_rotation(R_C1toC2, "R_C1toC2")
    t = _as_vector3(p_C1inC2, "p_C1inC2")
    return skew(t) @ R  # E = [t x] R


def fundamental_from_essential(E: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> NDArray[np.float64]:
    """Return the (3, 3) fundamental matrix F = K2^-T E K1^-1 (pixel constraint u2h^T F u1h = 0).

    Since ``x = K^-1 u``, the normalised constraint ``x2h^T E x1h = 0`` becomes ``u2h^T (K2^-T E K1^-1) u1h = 0``.
    F keeps E's scale (no renormalisation).

    Args:
        E: (3, 3) essential matrix (view 1 -> view 2).
        K1, K2: (3, 3) invertible intrinsic matrices of camera 1 and camera 2.

    Reference: Hartley & Zisserman §9.6, Eq. 9.12.

    >>> K = np.array([[200.0, 0, 120], [0, 200.0, 90], [0, 0, 1]])
    >>> F = fundamental_from_essential(essential_from_pose(np.eye(3), [1.0, 0, 0]), K, K)
    >>> float(np.array([10.0, 50.0, 1.0]) @ F @ np.array([150.0, 50.0, 1.0]))   # same pixel row
    0.0
    """
    E = _as_matrix(E, "E", (3, 3))
    inverses = []
    for name, K in (("K1", K1), ("K2", K2)):
        K = _as_matrix(K, name, (3, 3))
        if abs(np.linalg.det(K)) < 1e-12:
            raise ValueError(f"{name} must be an invertible (3, 3) intrinsic matrix; got det = {np.linalg.det(K):.3g}")
        inverses.append(np.linalg.inv(K))
    K1_inv, K2_inv = inverses
    return K2_inv.T @ E @ K1_inv  # F = K2^-T E K1^-1


def _normalising_transform(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return Hartley's similarity T (..., 3, 3): centroid to the origin, mean distance to it sqrt(2).

    Works on (..., N, 2) batches.
    """
    centroid = xy.mean(axis=-2)  # (..., 2)
    mean_dist = np.linalg.norm(xy - centroid[..., None, :], axis=-1).mean(axis=-1)  # (...)
    scale = math.sqrt(2.0) / np.maximum(mean_dist, 1e-300)  # s = sqrt(2) / mean ||x - c||
    T = np.zeros(xy.shape[:-2] + (3, 3))
    T[..., 0, 0] = scale
    T[..., 1, 1] = scale
    T[..., 0, 2] = -scale * centroid[..., 0]  # x' = s (x - cx)
    T[..., 1, 2] = -scale * centroid[..., 1]
    T[..., 2, 2] = 1.0
    return T


def _project_to_essential(E: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the closest essential matrices (..., 3, 3) in Frobenius norm: singular values set to (1, 1, 0)."""
    U, _, Vt = np.linalg.svd(E)
    return (U * np.array([1.0, 1.0, 0.0])) @ Vt  # E = U diag(1, 1, 0) V^T


def _fix_sign(E: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return E (..., 3, 3) with its largest-magnitude entry made positive (E is defined up to sign)."""
    flat = E.reshape(E.shape[:-2] + (9,))
    pivot = np.take_along_axis(flat, np.abs(flat).argmax(axis=-1)[..., None], axis=-1)  # (..., 1)
    return E * np.where(pivot < 0.0, -1.0, 1.0)[..., None]


def _eight_point_batch(xy1: NDArray[np.float64], xy2: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return essential matrices (M, 3, 3) from M batches of (M, n, 2) correspondences (n >= 8), vectorised."""
    T1 = _normalising_transform(xy1)
    T2 = _normalising_transform(xy2)
    x1 = np.einsum("mij,mnj->mni", T1, _homogeneous(xy1))  # x' = T x
    x2 = np.einsum("mij,mnj->mni", T2, _homogeneous(xy2))
    # x2^T E x1 = sum_ij x2_i E_ij x1_j = kron(x2, x1) . vec(E)  ->  A vec(E) = 0
    A = (x2[..., :, None] * x1[..., None, :]).reshape(xy1.shape[:-1] + (9,))
    if A.shape[-2] < 9:  # a zero row keeps the null space and lets the thin SVD return all 9 right vectors
        A = np.concatenate([A, np.zeros(A.shape[:-2] + (9 - A.shape[-2], 9))], axis=-2)
    _, _, Vt = np.linalg.svd(A, full_matrices=False)
    E_normalised = Vt[..., -1, :].reshape(-1, 3, 3)  # right singular vector of the smallest singular value
    E = np.swapaxes(T2, -1, -2) @ E_normalised @ T1  # undo the normalisation: E = T2^T E' T1
    E = _project_to_essential(E)
    return _fix_sign(E * (math.sqrt(2.0) / np.linalg.norm(E, axis=(-2, -1), keepdims=True)))


def eight_point(xy1: ArrayLike, xy2: ArrayLike) -> NDArray[np.float64]:
    """Return the essential matrix (3, 3) estimated from N >= 8 correspondences by the normalised eight-point algorithm.

    Steps: Hartley normalisation of each view (centroid to 0, mean distance sqrt(2)), linear least squares for
    ``x2h^T E x1h = 0`` by SVD, de-normalisation ``E = T2^T E' T1`` and projection onto the essential manifold
    (singular values (1, 1, 0)). The result has Frobenius norm sqrt(2) and its largest-magnitude entry positive
    (E is only defined up to scale and sign).

    Args:
        xy1: (N, 2) normalised image coordinates in view 1.
        xy2: (N, 2) corresponding normalised image coordinates in view 2.

    Reference: thesis §2.1.2; Hartley, "In defense of the eight-point algorithm", PAMI 1997;
    Hartley & Zisserman Algorithm 11.1.

    >>> rng = np.random.default_rng(0)
    >>> X_C1 = rng.uniform([-1, -1, 4], [1, 1, 8], size=(12, 3))
    >>> R, t = np.eye(3), np.array([-1.0, 0.0, 0.0])
    >>> X_C2 = X_C1 @ R.T + t
    >>> E = eight_point(X_C1[:, :2] / X_C1[:, 2:], X_C2[:, :2] / X_C2[:, 2:])
    >>> (E / E[1, 2]).round(6) + 0.0   # = [t x] R up to scale and sign
    array([[ 0.,  0.,  0.],
           [ 0.,  0.,  1.],
           [ 0., -1.,  0.]])
    >>> round(float(np.linalg.norm(E)), 6)
    1.414214
    """
    x1, x2 = _as_point_pair(xy1, xy2, _MIN_POINTS)
    return _eight_point_batch(x1[None], x2[None])[0]


def decompose_essential(E: ArrayLike) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Return the four candidate poses [(R_C1toC2, t_unit), ...] of an essential matrix.

    With ``E = U diag(1, 1, 0) V^T`` (U and V flipped to det +1), ``W = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]``:
    ``R in {U W V^T, U W^T V^T}`` and ``t = +/- u3`` (third column of U, unit length). Exactly one of the four puts
    the scene in front of both cameras (see :func:`recover_pose`). Order: (Ra, t), (Ra, -t), (Rb, t), (Rb, -t).

    Args:
        E: (3, 3) essential matrix (any scale or sign).

    Reference: Hartley & Zisserman §9.6.2, Result 9.19.

    >>> poses = decompose_essential(essential_from_pose(np.eye(3), [0.0, 0.0, 2.0]))
    >>> [np.allclose(R, np.eye(3)) for R, _ in poses].count(True)
    2
    >>> poses[0][1].round(3) + 0.0
    array([0., 0., 1.])
    """
    E = _as_essential(E)
    U, _, Vt = np.linalg.svd(E)
    # Flipping a singular vector basis changes only E's sign, which is free; this makes U W V^T a proper rotation.
    if np.linalg.det(U) < 0.0:
        U = -U
    if np.linalg.det(Vt) < 0.0:
        Vt = -Vt
    W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    Ra = U @ W @ Vt  # R = U W V^T
    Rb = U @ W.T @ Vt  # R = U W^T V^T
    t = U[:, 2].copy()  # t = u3 (unit), the left null vector of E: t^T E = 0
    return [(Ra, t), (Ra, -t), (Rb, t.copy()), (Rb, -t)]


# ---------------------------------------------------------------------------------------------- triangulation
def _triangulate_homogeneous(
    P1: NDArray[np.float64], P2: NDArray[np.float64], xy1: NDArray[np.float64], xy2: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Return homogeneous points (N, 4) (unit norm) minimising ||A X|| per correspondence (linear DLT)."""
    # x P[2] - P[0] = 0 and y P[2] - P[1] = 0 for each view (x ~ P X eliminates the unknown scale)
    A = np.stack(
        [
            xy1[:, 0:1] * P1[2] - P1[0],
            xy1[:, 1:2] * P1[2] - P1[1],
            xy2[:, 0:1] * P2[2] - P2[0],
            xy2[:, 1:2] * P2[2] - P2[1],
        ],
        axis=1,
    )  # (N, 4, 4)
    _, _, Vt = np.linalg.svd(A)
    return Vt[:, -1, :]  # null vector of A


def triangulate_dlt(P1: ArrayLike, P2: ArrayLike, xy1: ArrayLike, xy2: ArrayLike) -> NDArray[np.float64]:
    """Return Euclidean 3-D points (N, 3) triangulated linearly (DLT) from two views.

    Each view gives ``x P[2] - P[0]`` and ``y P[2] - P[1]`` as rows of A; X_h is the right singular vector of the
    smallest singular value of the 4x4 A, and ``X = X_h[:3] / X_h[3]`` (same rows as ``cv2.triangulatePoints``).
    Points at infinity (X_h[3] == 0, e.g. zero parallax) come out as inf/nan.

    Args:
        P1, P2: (3, 4) projection matrices, e.g. ``[I | 0]`` and ``[R_C1toC2 | p_C1inC2]`` with normalised
            coordinates, or ``K [R | t]`` with pixels. The points come out in the frame the P's map from
            (frame C1 for the example above).
        xy1, xy2: (N, 2) corresponding image points of view 1 and view 2 (in the units the P's produce).

    Reference: Hartley & Zisserman §12.2.

    >>> P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    >>> P2 = np.hstack([np.eye(3), [[-1.0], [0.0], [0.0]]])     # camera 2 one metre to the right
    >>> triangulate_dlt(P1, P2, [[0.25, 0.1]], [[0.0, 0.1]]).round(6)
    array([[1. , 0.4, 4. ]])
    """
    P1 = _as_matrix(P1, "P1", (3, 4))
    P2 = _as_matrix(P2, "P2", (3, 4))
    x1, x2 = _as_point_pair(xy1, xy2)
    if x1.shape[0] == 0:
        return np.zeros((0, 3))
    X_h = _triangulate_homogeneous(P1, P2, x1, x2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return X_h[:, :3] / X_h[:, 3:4]  # X = X_h[:3] / w


def _count_in_front(
    R: NDArray[np.float64], t: NDArray[np.float64], x1: NDArray[np.float64], x2: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Return the (N,) mask of correspondences triangulated in front of both cameras for the pose (R, t)."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, t[:, None]])
    X_h = _triangulate_homogeneous(P1, P2, x1, x2)
    w = X_h[:, 3]
    # Depths with the homogeneous scale kept: sign(Z1) = sign(X_h[2] w), sign(Z2) = sign((R X + t w)[2] w)
    depth1 = X_h[:, 2] * w
    depth2 = (X_h[:, :3] @ R[2] + t[2] * w) * w
    return (depth1 > 0.0) & (depth2 > 0.0)


def recover_pose(
    E: ArrayLike, xy1: ArrayLike, xy2: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Return (R_C1toC2 (3, 3), t_unit (3,), inlier_mask (N,)) of the decomposition that passes the cheirality test.

    Each of the four poses of :func:`decompose_essential` triangulates every correspondence; the one with the most
    points at positive depth in BOTH cameras wins, and ``inlier_mask`` marks those points. ``t_unit`` is the
    direction of p_C1inC2 (the scale is unobservable from two views).

    Args:
        E: (3, 3) essential matrix (view 1 -> view 2).
        xy1, xy2: (N, 2) corresponding normalised image coordinates (N >= 1).

    Reference: Hartley & Zisserman §9.6.3 (Fig. 9.12); thesis §2.1.2.

    >>> rng = np.random.default_rng(1)
    >>> X_C1 = rng.uniform([-1, -1, 4], [1, 1, 8], size=(20, 3))
    >>> R_true, t_true = np.eye(3), np.array([-0.6, 0.0, -0.8])
    >>> X_C2 = X_C1 @ R_true.T + t_true
    >>> xy1, xy2 = X_C1[:, :2] / X_C1[:, 2:], X_C2[:, :2] / X_C2[:, 2:]
    >>> R, t, mask = recover_pose(eight_point(xy1, xy2), xy1, xy2)
    >>> bool(np.allclose(R, R_true)), t.round(6) + 0.0, int(mask.sum())
    (True, array([-0.6,  0. , -0.8]), 20)
    """
    E = _as_essential(E)
    x1, x2 = _as_point_pair(xy1, xy2, 1)
    best = None
    for R, t in decompose_essential(E):
        mask = _count_in_front(R, t, x1, x2)
        if best is None or mask.sum() > best[2].sum():
            best = (R, t, mask)
    assert best is not None
    return best


# ---------------------------------------------------------------------------------------------- residuals
def epipolar_residuals(E: ArrayLike, xy1: ArrayLike, xy2: ArrayLike) -> NDArray[np.float64]:
    """Return the (N,) algebraic epipolar residuals r = x2h^T E x1h (zero for a perfect correspondence).

    Args:
        E: (3, 3) essential matrix (or a fundamental matrix with pixel inputs).
        xy1, xy2: (N, 2) corresponding points of view 1 and view 2.

    Reference: thesis §2.1.2 (epipolar constraint p_k^T E p_{k-1} = 0).

    >>> E = essential_from_pose(np.eye(3), [1.0, 0.0, 0.0])
    >>> epipolar_residuals(E, [[0.3, 0.1], [0.3, 0.1]], [[0.0, 0.1], [0.0, 0.2]]).round(6) + 0.0
    array([ 0. , -0.1])
    """
    E = _as_matrix(E, "E", (3, 3))
    x1, x2 = _as_point_pair(xy1, xy2)
    return np.einsum("ni,ij,nj->n", _homogeneous(x2), E, _homogeneous(x1))  # r = x2h^T E x1h


def _sampson_batch(E: NDArray[np.float64], x1h: NDArray[np.float64], x2h: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return Sampson distances (M, N) of M essential matrices (M, 3, 3) for (N, 3) homogeneous points."""
    Ex1 = x1h @ np.swapaxes(E, -1, -2)  # (m, n, 3) epipolar lines E x1h in view 2
    Etx2 = x2h @ E  # (m, n, 3) epipolar lines E^T x2h in view 1
    r = (Ex1 * x2h).sum(axis=-1)  # x2h^T E x1h
    # d = |r| / sqrt((E x1)_1^2 + (E x1)_2^2 + (E^T x2)_1^2 + (E^T x2)_2^2)
    denominator = Ex1[..., 0] ** 2 + Ex1[..., 1] ** 2 + Etx2[..., 0] ** 2 + Etx2[..., 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.abs(r) / np.sqrt(denominator)
    return np.where(denominator > 0.0, d, np.where(r == 0.0, 0.0, np.inf))


def sampson_distance(E: ArrayLike, xy1: ArrayLike, xy2: ArrayLike) -> NDArray[np.float64]:
    """Return the (N,) Sampson distances, the first-order geometric error of each correspondence.

    ``d = |x2h^T E x1h| / sqrt((E x1h)_1^2 + (E x1h)_2^2 + (E^T x2h)_1^2 + (E^T x2h)_2^2)``; d^2 approximates the
    smallest sum of squared point shifts (in both views) that makes the correspondence satisfy the constraint.
    Same units as the inputs (normalised coordinates for E; pixels for F), and independent of E's scale.
    ``cv2.findEssentialMat``'s RANSAC compares d^2 against threshold^2.

    Args:
        E: (3, 3) essential matrix (or a fundamental matrix with pixel inputs).
        xy1, xy2: (N, 2) corresponding points of view 1 and view 2.

    Reference: Hartley & Zisserman §11.4.3, Eq. 11.9.

    >>> E = essential_from_pose(np.eye(3), [1.0, 0.0, 0.0])
    >>> sampson_distance(E, [[0.3, 0.1]], [[0.0, 0.2]]).round(6)   # rows 0.1 apart: each point moves 0.05
    array([0.070711])
    """
    E = _as_essential(E)
    x1, x2 = _as_point_pair(xy1, xy2)
    return _sampson_batch(E[None], _homogeneous(x1), _homogeneous(x2))[0]


# ---------------------------------------------------------------------------------------------- refinement
def refine_essential(E: ArrayLike, xy1: ArrayLike, xy2: ArrayLike, max_iterations: int = 20) -> NDArray[np.float64]:
    """Return the essential matrix (3, 3) that minimises the sum of squared Sampson distances, starting from E.

    Linear estimates (:func:`eight_point`) minimise an algebraic error, and forcing their singular values to
    (1, 1, 0) can move the epipolar lines by several noise sigmas when the field of view is narrow. This
    Levenberg-Marquardt refinement stays on the essential manifold: ``E(θ, δ) = [t x] R`` with
    ``R = R0 exp([θ x])`` and ``t = (t0 + B δ) / ||t0 + B δ||`` (B spans the tangent plane of the unit sphere at t0),
    five parameters, residuals ``(x2h^T E x1h) / sqrt((E x1h)_1^2 + (E x1h)_2^2 + (E^T x2h)_1^2 + (E^T x2h)_2^2)``.
    The result has Frobenius norm sqrt(2) and its largest-magnitude entry positive. Use inliers only.

    Args:
        E: (3, 3) starting essential matrix (view 1 -> view 2), e.g. from :func:`eight_point`.
        xy1, xy2: (N, 2) corresponding normalised image coordinates, N >= 5.
        max_iterations: maximum Levenberg-Marquardt iterations (>= 1).

    Reference: Hartley & Zisserman §11.4.3 (Sampson error) and §11.5 (iterative minimisation on a minimal
    parametrisation).

    >>> rng = np.random.default_rng(3)
    >>> X_C1 = rng.uniform([-1, -1, 4], [1, 1, 8], size=(40, 3))
    >>> R, t = so3_exp([0.0, 0.1, 0.0]), np.array([-1.0, 0.0, 0.0])
    >>> X_C2 = X_C1 @ R.T + t
    >>> xy1 = X_C1[:, :2] / X_C1[:, 2:] + rng.normal(0, 0.003, (40, 2))
    >>> xy2 = X_C2[:, :2] / X_C2[:, 2:] + rng.normal(0, 0.003, (40, 2))
    >>> E0 = eight_point(xy1, xy2)
    >>> bool(sampson_distance(refine_essential(E0, xy1, xy2), xy1, xy2).mean() < sampson_distance(E0, xy1, xy2).mean())
    True
    """
    E = _as_essential(E)
    x1, x2 = _as_point_pair(xy1, xy2, 5)
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, Integral) or max_iterations < 1:
        raise ValueError(f"max_iterations must be a positive integer; got {max_iterations!r}")
    R0, t0 = decompose_essential(E)[0]  # any of the four gives +/-E, and the Sampson distance ignores the sign
    B = np.linalg.svd(t0[None, :])[2][1:].T  # (3, 2) orthonormal basis of the plane orthogonal to t0
    x1h, x2h = _homogeneous(x1), _homogeneous(x2)

    def essential(params: NDArray[np.float64]) -> NDArray[np.float64]:
        t = t0 + B @ params[3:]
        return skew(t / np.linalg.norm(t)) @ (R0 @ so3_exp(params[:3]))  # E = [t x] R0 exp([θ x])

    def residuals(params: NDArray[np.float64]) -> NDArray[np.float64]:
        E_p = essential(params)
        Ex1 = x1h @ E_p.T
        Etx2 = x2h @ E_p
        r = (Ex1 * x2h).sum(axis=1)  # x2h^T E x1h
        return r / np.sqrt(Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2 + 1e-300)

    # 'lm' evaluates the (5-column, finite-difference) Jacobian once per iteration plus one step: 6 calls each
    solution = least_squares(residuals, np.zeros(5), method="lm", max_nfev=6 * int(max_iterations) + 1)
    E_refined = essential(solution.x)
    return _fix_sign(E_refined * (math.sqrt(2.0) / np.linalg.norm(E_refined)))


def _local_optimisation(
    E: NDArray[np.float64],
    mask: NDArray[np.bool_],
    x1: NDArray[np.float64],
    x2: NDArray[np.float64],
    threshold: float,
    rounds: int = 10,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Return (E, mask) improved by refitting on the inliers (eight-point + Sampson refinement) until stable."""
    x1h, x2h = _homogeneous(x1), _homogeneous(x2)
    for _ in range(rounds):
        if mask.sum() < _MIN_POINTS:
            break
        E_new = _eight_point_batch(x1[mask][None], x2[mask][None])[0]
        E_new = refine_essential(E_new, x1[mask], x2[mask])
        mask_new = _sampson_batch(E_new[None], x1h, x2h)[0] <= threshold
        if mask_new.sum() < mask.sum():
            break
        converged = np.array_equal(mask_new, mask)
        E, mask = E_new, mask_new
        if converged:
            break
    return E, mask


# ---------------------------------------------------------------------------------------------- RANSAC
def estimate_essential_ransac(
    xy1: ArrayLike,
    xy2: ArrayLike,
    rng: np.random.Generator | int,
    threshold: float = 5e-3,
    max_iterations: int = 1000,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Return (E (3, 3), inlier_mask (N,)) estimated robustly by RANSAC around the eight-point algorithm.

    Each hypothesis is :func:`eight_point` on 8 random correspondences; its inliers are the correspondences with
    :func:`sampson_distance` <= ``threshold``. Whenever a hypothesis beats the best so far it is refitted on its
    inliers (eight-point, then :func:`refine_essential`; inliers re-selected, repeated until stable: "locally
    optimised" RANSAC), which matters because minimal 8-point fits to noisy data are poor. Sampling stops early
    once an all-inlier sample has been drawn with probability 0.999 (``k = log(0.001) / log(1 - w^8)``,
    w = inlier ratio); hypotheses are evaluated in vectorised batches of 64, so the iteration count is rounded up to
    a multiple of 64 (capped at max_iterations).

    Args:
        xy1, xy2: (N, 2) corresponding normalised image coordinates, N >= 8.
        rng: seeded ``numpy.random.Generator`` (or an int seed) drawing the samples.
        threshold: inlier threshold on the Sampson distance, in normalised coordinates
            (pixels / focal length: 5e-3 is 1 px for f = 200 px).
        max_iterations: maximum number of hypotheses (>= 1).

    Reference: Fischler & Bolles, "Random sample consensus", CACM 1981; Chum, Matas & Kittler, "Locally optimized
    RANSAC", DAGM 2003; Hartley & Zisserman §4.7.1 and §11.6.

    >>> rng = np.random.default_rng(2)
    >>> X_C1 = rng.uniform([-1, -1, 4], [1, 1, 8], size=(50, 3))
    >>> X_C2 = X_C1 + np.array([-1.0, 0.0, 0.0])
    >>> xy1, xy2 = X_C1[:, :2] / X_C1[:, 2:], X_C2[:, :2] / X_C2[:, 2:]
    >>> xy2[:10] += rng.uniform(-0.2, 0.2, size=(10, 2))          # 10 gross outliers
    >>> E, inliers = estimate_essential_ransac(xy1, xy2, rng)
    >>> int(inliers[10:].sum()), int(inliers[:10].sum())
    (40, 0)
    """
    x1, x2 = _as_point_pair(xy1, xy2, _MIN_POINTS)
    if isinstance(rng, (bool, np.bool_)) or not isinstance(rng, (np.random.Generator, Integral)):
        raise ValueError(f"rng must be a numpy.random.Generator or an int seed; got {type(rng).__name__}")
    rng = np.random.default_rng(rng) if isinstance(rng, Integral) else rng
    if isinstance(threshold, bool) or not isinstance(threshold, Real) or not (0 < threshold < math.inf):
        raise ValueError(f"threshold must be a positive finite Sampson distance; got {threshold!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, Integral) or max_iterations < 1:
        raise ValueError(f"max_iterations must be a positive integer; got {max_iterations!r}")

    n = x1.shape[0]
    x1h, x2h = _homogeneous(x1), _homogeneous(x2)
    best_E, best_mask = None, np.zeros(n, dtype=bool)
    needed = int(max_iterations)
    done = 0
    while done < min(needed, max_iterations):
        m = min(_RANSAC_BATCH, max_iterations - done)
        # m random 8-subsets without repetition: the 8 smallest of m x n uniform keys
        idx = np.argpartition(rng.random((m, n)), _MIN_POINTS - 1, axis=1)[:, :_MIN_POINTS]
        E_batch = _eight_point_batch(x1[idx], x2[idx])  # (m, 3, 3)
        masks = _sampson_batch(E_batch, x1h, x2h) <= threshold  # (m, n)
        counts = masks.sum(axis=1)
        k = int(counts.argmax())
        if counts[k] > best_mask.sum():
            best_E, best_mask = _local_optimisation(E_batch[k], masks[k], x1, x2, threshold)
            w = best_mask.mean()  # inlier ratio
            p_good = w**_MIN_POINTS  # probability that one sample is all inliers
            if p_good >= 1.0:
                needed = 0
            elif p_good > 0.0:
                needed = int(math.ceil(math.log(1.0 - _RANSAC_CONFIDENCE) / math.log1p(-p_good)))
        done += m

    assert best_E is not None
    return best_E, best_mask
