"""Two-point RANSAC: outlier rejection of feature matches between consecutive frames with a known rotation.

Two views of a point, undistorted normalised bearings ``f1 = [x1, y1, 1]`` (previous camera C1) and ``f2``
(current camera C2), with ``X_C2 = R X_C1 + t`` (``R = R_C1toC2`` from the gyroscope, ``t = p_C1inC2`` unknown),
satisfy the epipolar constraint (thesis §2.1.2, Eq. 3)::

    f2^T [t x] R f1 = 0.

With R known, the rotation-compensated bearing ``g1 = R f1`` (scaled so that its z is 1) leaves a pure translation
between (g1, f2), and the constraint is linear in t::

    f2^T (t x g1) = t . (g1 x f2) = 0,   i.e.   c^T t = 0  with  c = g1 x f2
                                                  = (y_g - y2,  x2 - x_g,  x_g y2 - y_g x2).

t has two degrees of freedom (its scale is unobservable), so two matches determine it:
``t = c_i x c_j / |c_i x c_j|``. Each hypothesis is scored by the Sampson distance of every match to the essential
matrix ``E = [t x]`` of the compensated pair (Hartley & Zisserman §11.4.3)::

    d = |f2^T E g1| / sqrt((E g1)_1^2 + (E g1)_2^2 + (E^T f2)_1^2 + (E^T f2)_2^2),

converted to pixels by the focal length; matches with ``d < threshold`` are inliers. The best hypothesis is refitted
by least squares on its inliers (t = the right singular vector of the stacked c_k with the smallest singular value)
and the inliers recomputed.

Hypotheses are ranked by the MSAC cost sum_k min(d_k, threshold)^2 (Torr & Zisserman 2000), which prefers the
hypothesis whose inliers fit best among those with equal support. The best one is refitted on its inliers by weighted
least squares, min sum_k (c_k^T t / s_k)^2 with |t| = 1 and s_k the Sampson denominator at the current t (so that
the algebraic residual approximates the Sampson distance), and kept when it lowers the cost.

A match whose compensated displacement D = |g1 - f2| is below the threshold fits every t (its Sampson distance is at
most D), and one that moves a little more constrains the direction of its epipolar line only to within about
threshold / D radians. Only "moving" matches, D >= 3 threshold, tell hypotheses apart; each hypothesis pairs a moving
match with any other. Two moving matches always fit some t, and a few random outliers can line up with one, so the
translation counts as observed only when at least three moving matches, and at least half of them, agree with it.
Otherwise (pure rotation, a translation too small for the depth of the scene, or a few matches that moved far: on a
repeated texture, say) t is unobservable and the matches are classified by their displacement alone: inliers move
less than 3 threshold (msckf_vio does the same when the mean displacement is below one pixel).

With ``n`` hypotheses, an all-inlier pair is drawn with probability ``1 - (1 - w^2)^n`` for an inlier ratio w; the
default n = 100 gives 99 % down to w = 0.21.

Reference: Troiani, Martinelli, Laugier and Scaramuzza, "2-Point-based Outlier Rejection for Camera-IMU Systems with
applications to Micro Aerial Vehicles", ICRA 2014; msckf_vio (Sun et al., RA-L 2018), image_processor.cpp
``twoPointRansac``; thesis §3.3.5.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import cross3

_MIN_MOVING = 3  # moving matches that must agree on a translation before it counts as observed
_MOVING_FACTOR = 3.0  # a match is "moving" when its compensated displacement is at least this many thresholds

__all__ = ["TwoPointRansacResult", "two_point_ransac", "compensate_rotation", "translation_constraints"]


@dataclass(frozen=True)
class TwoPointRansacResult:
    """What :func:`two_point_ransac` found.

    Attributes:
        inliers: (K,) bool, True for the matches consistent with the rotation and the translation direction.
        t_dir: (3,) unit translation direction p_C1inC2 (sign arbitrary), or zeros when none was estimated
            (fewer than 3 matches, or the degenerate case).
        residuals_px: (K,) Sampson distance of each match to the final model in pixels (the compensated
            displacement |g1 - f2| in pixels in the degenerate case).
        degenerate: True when the translation was unobservable (fewer than three, or fewer than half, of the moving
            matches agree with one t) and the matches were classified by their displacement.
    """

    inliers: NDArray[np.bool_]
    t_dir: NDArray[np.float64]
    residuals_px: NDArray[np.float64]
    degenerate: bool

    @property
    def num_rejected(self) -> int:
        """Return the number of matches RANSAC rejected."""
        return int(np.count_nonzero(~self.inliers))


def _as_xy(value: ArrayLike, name: str) -> NDArray[np.float64]:
    array = np.asarray(value, dtype=np.float64)
    if array.size == 0:
        array = array.reshape(0, 2)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must have shape (K, 2), undistorted normalised (x, y); got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must contain only finite values; got NaN or inf")
    return array


def _as_rotation(value: ArrayLike | None) -> NDArray[np.float64]:
    if value is None:
        return np.eye(3)
    R = np.asarray(value, dtype=np.float64)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise ValueError(f"R_prev_to_curr must be a finite (3, 3) rotation matrix; got shape {R.shape}")
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or abs(np.linalg.det(R) - 1.0) > 1e-6:
        raise ValueError("R_prev_to_curr must be a rotation (R R^T = I, det R = 1 within 1e-6)")
    return R


def compensate_rotation(xy_prev: ArrayLike, R_prev_to_curr: ArrayLike | None) -> NDArray[np.float64]:
    """Return the (K, 2) normalised coordinates of g1 = R f1 / (R f1)_z, the previous bearings rotated into C2.

    Points that the rotation turns behind the camera ((R f1)_z <= 0) come back as NaN.

    Args:
        xy_prev: (K, 2) undistorted normalised coordinates in the previous camera C1.
        R_prev_to_curr: (3, 3) rotation R_C1toC2 (X_C2 = R X_C1 + t), or None for the identity.

    >>> c, s = np.cos(0.1), np.sin(0.1)
    >>> R_y = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])   # 0.1 rad about y: x moves right
    >>> compensate_rotation([[0.0, 0.0]], R_y).round(4).tolist()      # tan(0.1) = 0.1003
    [[0.1003, 0.0]]
    """
    xy = _as_xy(xy_prev, "xy_prev")
    R = _as_rotation(R_prev_to_curr)
    g = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1) @ R.T  # g1 = R f1
    with np.errstate(divide="ignore", invalid="ignore"):
        out = g[:, :2] / g[:, 2:3]
    out[g[:, 2] <= 1e-9] = np.nan
    return out


def translation_constraints(g1: ArrayLike, xy_curr: ArrayLike) -> NDArray[np.float64]:
    """Return the (K, 3) rows c_k = g1_k x f2_k of the linear constraints c_k^T t = 0 on the translation.

    Args:
        g1: (K, 2) rotation-compensated previous points (:func:`compensate_rotation`).
        xy_curr: (K, 2) current undistorted normalised points.

    >>> translation_constraints([[0.1, 0.2]], [[0.3, 0.2]]).round(3).tolist()   # (y_g - y2, x2 - x_g, x_g y2 - y_g x2)
    [[0.0, 0.2, -0.04]]
    """
    a = _as_xy(g1, "g1")
    b = _as_xy(xy_curr, "xy_curr")
    # c = [x_g, y_g, 1] x [x2, y2, 1] = (y_g - y2, x2 - x_g, x_g y2 - y_g x2)
    return np.stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0], a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _sampson_parts(t: NDArray[np.float64], g1: NDArray[np.float64], f2: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (r, s) (..., K): the algebraic residual r = f2^T [t x] g1 = c^T t and the Sampson denominator s,
    for translations t (..., 3) and K compensated matches; the Sampson distance is |r| / s."""
    g1h = np.concatenate([g1, np.ones((g1.shape[0], 1))], axis=1)
    f2h = np.concatenate([f2, np.ones((f2.shape[0], 1))], axis=1)
    tt = t[..., None, :]
    Eg = cross3(tt, g1h)  # E g1 = t x g1 (epipolar lines in view 2)
    Etf = -cross3(tt, f2h)  # E^T f2 = [t x]^T f2 = -(t x f2) (epipolar lines in view 1)
    r = np.einsum("...ki,ki->...k", Eg, f2h)  # f2^T E g1
    # s = sqrt((E g1)_1^2 + (E g1)_2^2 + (E^T f2)_1^2 + (E^T f2)_2^2)
    return r, np.sqrt(Eg[..., 0] ** 2 + Eg[..., 1] ** 2 + Etf[..., 0] ** 2 + Etf[..., 1] ** 2)


def _sampson(t: NDArray[np.float64], g1: NDArray[np.float64], f2: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return Sampson distances (M, K) of K compensated matches to M translation hypotheses t (M, 3)."""
    r, s = _sampson_parts(t, g1, f2)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.abs(r) / s
    return np.where(s > 0.0, d, np.where(r == 0.0, 0.0, np.inf))


def _generator(rng: np.random.Generator | int | None) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or (isinstance(rng, Integral) and not isinstance(rng, bool) and rng >= 0):
        return np.random.default_rng(rng if rng is not None else 0)
    raise ValueError(f"rng must be a numpy.random.Generator or a non-negative int seed; got {rng!r}")


def two_point_ransac(
    xy_prev: ArrayLike,
    xy_curr: ArrayLike,
    R_prev_to_curr: ArrayLike | None,
    *,
    focal_px: float,
    threshold_px: float = 1.5,
    iterations: int = 100,
    max_displacement_px: float | None = None,
    rng: np.random.Generator | int | None = 0,
) -> TwoPointRansacResult:
    """Return the inliers of matches (xy_prev[k], xy_curr[k]) under a known rotation and an unknown translation.

    See the module docstring for the equations. Fewer than 3 matches cannot be checked (two always fit a
    translation exactly): they are all kept, unless the rotation turns one behind the camera or it moves more
    than ``max_displacement_px``.

    Args:
        xy_prev: (K, 2) undistorted normalised coordinates in the previous camera C1.
        xy_curr: (K, 2) undistorted normalised coordinates of the same features in the current camera C2.
        R_prev_to_curr: (3, 3) rotation R_C1toC2 (X_C2 = R X_C1 + t), e.g. integrated from the gyroscope;
            None for the identity (valid only when the camera barely rotates between the frames).
        focal_px: focal length in pixels that converts normalised distances to pixels (e.g. (fx + fy) / 2).
        threshold_px: inlier threshold on the Sampson distance, pixels (> 0).
        iterations: number of random two-match hypotheses (>= 1).
        max_displacement_px: matches whose rotation-compensated displacement exceeds this are rejected outright
            (msckf_vio: 50 px); None: no limit.
        rng: numpy Generator or int seed of the hypothesis sampling.

    Reference: Troiani et al., ICRA 2014; msckf_vio image_processor.cpp ``twoPointRansac``.

    >>> rng = np.random.default_rng(1)
    >>> X = rng.uniform([-1, -1, 2], [1, 1, 4], size=(30, 3))         # points in C1
    >>> x1 = X[:, :2] / X[:, 2:]
    >>> X2 = X + [0.1, 0.0, 0.05]                                     # R = I, t = (0.1, 0, 0.05)
    >>> x2 = X2[:, :2] / X2[:, 2:]
    >>> x2[:3] += 0.05                                                # three outliers (10 px at f = 200)
    >>> res = two_point_ransac(x1, x2, np.eye(3), focal_px=200.0)
    >>> res.inliers[:3].tolist(), int(res.inliers.sum()), np.round(np.abs(res.t_dir), 3).tolist()
    ([False, False, False], 27, [0.894, 0.0, 0.447])
    """
    x1 = _as_xy(xy_prev, "xy_prev")
    x2 = _as_xy(xy_curr, "xy_curr")
    if x1.shape != x2.shape:
        raise ValueError(f"xy_prev and xy_curr must have the same shape (K, 2); got {x1.shape} and {x2.shape}")
    for name, value in (("focal_px", focal_px), ("threshold_px", threshold_px)):
        if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) or value <= 0:
            raise ValueError(f"{name} must be a finite number > 0 (pixels); got {value!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, Integral) or iterations < 1:
        raise ValueError(f"iterations must be an integer >= 1; got {iterations!r}")
    if max_displacement_px is not None and (isinstance(max_displacement_px, bool) or not isinstance(
            max_displacement_px, Real) or not math.isfinite(max_displacement_px) or max_displacement_px <= 0):
        raise ValueError(f"max_displacement_px must be a finite number > 0 or None; got {max_displacement_px!r}")
    generator = _generator(rng)
    g1 = compensate_rotation(x1, R_prev_to_curr)
    valid = np.isfinite(g1).all(axis=1)  # not turned behind the camera
    g1 = np.where(valid[:, None], g1, 0.0)
    threshold = float(threshold_px) / float(focal_px)  # pixels -> normalised units
    displacement = np.linalg.norm(g1 - x2, axis=1)  # |g1 - f2|, normalised
    if max_displacement_px is not None:
        valid &= displacement * focal_px <= max_displacement_px
    zeros = np.zeros(3)
    if x1.shape[0] < 3:
        return TwoPointRansacResult(valid.copy(), zeros, displacement * focal_px, False)
    moving = np.flatnonzero(valid & (displacement >= _MOVING_FACTOR * threshold))
    unobservable = TwoPointRansacResult(valid & (displacement < _MOVING_FACTOR * threshold), zeros,
                                        displacement * focal_px, True)
    if moving.shape[0] < _MIN_MOVING:
        return unobservable

    c = translation_constraints(g1, x2)  # (K, 3): c_k^T t = 0
    candidates = np.flatnonzero(valid)
    n = candidates.shape[0]
    i = moving[generator.integers(0, moving.shape[0], size=iterations)]  # one moving match per hypothesis
    j = candidates[(np.searchsorted(candidates, i) + 1 + generator.integers(0, n - 1, size=iterations)) % n]
    t = cross3(c[i], c[j])  # t = c_i x c_j, the null vector of both constraints
    norm = np.linalg.norm(t, axis=1)
    if not (norm > 1e-12).any():
        return unobservable
    t = t[norm > 1e-12] / norm[norm > 1e-12, None]
    d = np.where(valid[None, :], _sampson(t, g1, x2), np.inf)  # (M, K)
    cost = (np.minimum(d, threshold) ** 2).sum(axis=1)  # MSAC: sum_k min(d_k, threshold)^2
    best = int(np.argmin(cost))
    t_best, d_best, cost_best = t[best], d[best], cost[best]
    for _ in range(2):  # refit on the inliers: min sum_k (c_k^T t / s_k)^2, |t| = 1, s_k the Sampson denominator
        inliers = d_best < threshold
        _, scale = _sampson_parts(t_best, g1[inliers], x2[inliers])
        _, _, Vt = np.linalg.svd(c[inliers] / np.maximum(scale, 1e-12)[:, None], full_matrices=False)
        d_refit = np.where(valid, _sampson(Vt[-1][None], g1, x2)[0], np.inf)
        cost_refit = float((np.minimum(d_refit, threshold) ** 2).sum())
        if cost_refit > cost_best:
            break
        t_best, d_best, cost_best = Vt[-1], d_refit, cost_refit
    inliers = d_best < threshold
    moving_inliers = np.count_nonzero(inliers[moving])
    if moving_inliers < max(_MIN_MOVING, 0.5 * moving.shape[0]):  # confirmed by a third, and most, moving matches
        return unobservable
    return TwoPointRansacResult(inliers, t_best / np.linalg.norm(t_best), d_best * focal_px, False)
