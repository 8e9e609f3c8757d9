"""Trajectory accuracy and filter consistency metrics: RMSE, final error, % of distance, ATE/RPE, NEES.

Position metrics as in the thesis's MSCKF evaluation (§4.5, Table 6), with e_k = p_est(t_k) - p_gt(t_k):

    RMSE          = sqrt( (1/N) sum_k |e_k|^2 )
    final error   = |e_N|
    distance D    = sum_k |p_gt,k+1 - p_gt,k|            (length of the ground-truth path)
    % of distance = 100 (1/N) sum_k |e_k| / D            (absolute error at every time step divided by the total
                                                          distance travelled, averaged over all time steps)

VIO is unobservable in global position and yaw (4 DoF), so trajectories are also compared after an alignment:
Umeyama's closed form (SE(3) or Sim(3)) or a position + yaw alignment (4 DoF), then the absolute trajectory error
(ATE, RMSE of the aligned positions) and the relative pose error (RPE) over a distance or time step (Zhang &
Scaramuzza, "A Tutorial on Quantitative Trajectory Evaluation for Visual(-Inertial) Odometry", IROS 2018).
:func:`relative_errors_by_length` is the relative error of rpg_trajectory_evaluation: for sub-trajectory lengths
of 10 ... 50 % of the path, every pair of poses that far apart along the ground truth, with translation, yaw and
gravity-direction errors. The tests check the ATE and RPE against the ``evo`` package.

Consistency: the normalised estimation error squared NEES_k = e_k^T P_k^-1 e_k of a consistent filter is chi-square
with d degrees of freedom; averaged over n Monte-Carlo runs, n * mean NEES ~ chi2(n d), which gives the two-sided
bounds of :func:`chi2_bounds` (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, §5.4).

Rotations here are body-to-world matrices R_ItoG (v_G = R_ItoG v_I), as in
:class:`evio_lib.sim.trajectory.TrajectorySample`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

__all__ = [
    "Alignment",
    "RelativePoseErrors",
    "position_errors",
    "rmse",
    "final_error",
    "distance_travelled",
    "camera_motion",
    "percent_of_distance",
    "align_umeyama",
    "absolute_trajectory_error",
    "relative_pose_error",
    "SubTrajectoryErrors",
    "subtrajectory_lengths",
    "relative_errors_by_length",
    "nees",
    "chi2_bounds",
    "orientation_errors",
    "summarize",
    "format_table",
]


# ==================================================================================================== validation
def _array(value: Any, name: str, tail: tuple[int, ...], expected: str) -> NDArray[np.float64]:
    """Return ``value`` as finite float64 with shape (N, *tail), else raise ValueError naming ``name``."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != 1 + len(tail) or array.shape[1:] != tail:
        raise ValueError(f"{name} must have shape {expected}; got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must contain only finite values; got non-finite entries")
    return array


def _error_norms(errors: ArrayLike) -> NDArray[np.float64]:
    """Return |e_k| (N,) from error vectors (N, d) or norms (N,), N >= 1."""
    e = np.asarray(errors, dtype=np.float64)
    if e.ndim not in (1, 2) or e.shape[0] == 0:
        raise ValueError(f"errors must have shape (N,) or (N, d) with N >= 1; got {e.shape}")
    if not np.isfinite(e).all():
        raise ValueError("errors must contain only finite values; got non-finite entries")
    return np.abs(e) if e.ndim == 1 else np.linalg.norm(e, axis=1)


def _same_length(a: NDArray[Any], b: NDArray[Any], name_a: str, name_b: str) -> None:
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"{name_a} and {name_b} must have the same length N; got {a.shape[0]} and {b.shape[0]}")


# ==================================================================================================== positions
def position_errors(t_est: ArrayLike, p_est: ArrayLike, t_gt: ArrayLike, p_gt: ArrayLike) -> NDArray[np.float64]:
    """Return position errors e_k = p_est,k - p_gt(t_est,k) (N, 3), ground truth linearly interpolated at t_est.

    Args:
        t_est: (N,) estimate times, s, inside [t_gt[0], t_gt[-1]].
        p_est: (N, 3) estimated positions in G, metres.
        t_gt: (M,) strictly increasing ground-truth times, s (M >= 2, or M = 1 with t_est equal to it).
        p_gt: (M, 3) ground-truth positions in G, metres.

    >>> position_errors([0.5], [[1.0, 0.0, 0.0]], [0.0, 1.0], [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]).tolist()
    [[0.0, 0.0, 0.0]]
    """
    t_e = _array(t_est, "t_est", (), "(N,)")
    p_e = _array(p_est, "p_est", (3,), "(N, 3)")
    t_g = _array(t_gt, "t_gt", (), "(M,)")
    p_g = _array(p_gt, "p_gt", (3,), "(M, 3)")
    _same_length(t_e, p_e, "t_est", "p_est")
    _same_length(t_g, p_g, "t_gt", "p_gt")
    if t_g.shape[0] == 0 or np.any(np.diff(t_g) <= 0):
        raise ValueError("t_gt must be non-empty and strictly increasing; got an empty or unsorted array")
    if t_e.size and (t_e.min() < t_g[0] - 1e-9 or t_e.max() > t_g[-1] + 1e-9):
        raise ValueError(f"t_est must lie inside the ground truth [{t_g[0]:.6f}, {t_g[-1]:.6f}] s; got "
                         f"[{t_e.min():.6f}, {t_e.max():.6f}]")
    # p_gt(t) = p_i + (t - t_i) / (t_i+1 - t_i) (p_i+1 - p_i)
    p_interp = np.stack([np.interp(t_e, t_g, p_g[:, i]) for i in range(3)], axis=1)
    return p_e - p_interp


def rmse(errors: ArrayLike) -> float:
    """Return the root-mean-square error sqrt(mean_k |e_k|^2) of error vectors (N, d) or error norms (N,).

    >>> round(rmse([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]]), 4)   # sqrt(25 / 2)
    3.5355
    """
    norms = _error_norms(errors)
    return float(np.sqrt(np.mean(norms**2)))  # RMSE = sqrt((1/N) sum |e_k|^2)


def final_error(errors: ArrayLike) -> float:
    """Return |e_N|, the norm of the last error (errors (N, d) vectors or (N,) norms).

    >>> final_error([[1.0, 0.0, 0.0], [0.0, 3.0, 4.0]])
    5.0
    """
    return float(_error_norms(errors)[-1])


def distance_travelled(p_gt: ArrayLike) -> float:
    """Return the path length D = sum_k |p_k+1 - p_k| (metres) of positions p_gt (N, 3).

    >>> distance_travelled([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 4.0, 1.0]])
    6.0
    """
    p = _array(p_gt, "p_gt", (3,), "(N, 3)")
    if p.shape[0] < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def camera_motion(sequence: Any, t: ArrayLike, smoothing_s: float = 0.05) -> tuple[NDArray[np.float64],
                                                                                   NDArray[np.float64]]:
    """Return (speed [m/s], angular rate [rad/s]) of a recording's sensor at times t, to set errors beside motion.

    speed: |d p/dt| of the ground truth's position (the IMU's where the recording has it, else the camera's), by
    central differences on the times t; angular rate: |gyro| averaged over ``smoothing_s`` (so it includes the gyro's
    bias and noise, a few hundredths of a rad/s), interpolated at t.

    >>> from types import SimpleNamespace as NS
    >>> from evio_lib.sequence import GroundTruth, ImuSamples
    >>> tt = np.linspace(0.0, 2.0, 201)
    >>> gt = GroundTruth(t=tt, p_BinG=np.c_[0.5 * tt, 0 * tt, 0 * tt], q_GtoB=np.tile([0, 0, 0, 1.0], (201, 1)), body="imu")
    >>> imu = ImuSamples(t=tt, gyro=np.tile([0.0, 0.0, 2.0], (201, 1)), accel=np.tile([0, 0, 9.81], (201, 1)))
    >>> [v.round(3).tolist() for v in camera_motion(NS(groundtruth_imu=gt, groundtruth=None, imu=imu), [0.5, 1.5])]
    [[0.5, 0.5], [2.0, 2.0]]
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    truth = sequence.groundtruth_imu if sequence.groundtruth_imu is not None else sequence.groundtruth
    if truth is None or sequence.imu is None:
        raise ValueError("camera_motion needs the recording's ground truth and IMU")
    if t.size < 2 or not np.all(np.diff(t) > 0):
        raise ValueError(f"t must hold at least 2 increasing times; got {t.size}")
    speed = np.linalg.norm(np.gradient(truth.interpolate(t).p_BinG, t, axis=0), axis=1)
    imu = sequence.imu
    rate = np.linalg.norm(imu.gyro, axis=1)
    kernel = max(1, int(round(smoothing_s / float(np.median(np.diff(imu.t))))))
    smooth = np.convolve(rate, np.ones(kernel) / kernel, mode="same")
    return speed, np.interp(t, imu.t, smooth)


def percent_of_distance(errors: ArrayLike, distance: float) -> float:
    """Return the thesis's "% error": 100 mean_k(|e_k| / D), the mean absolute position error over the distance D.

    Thesis §4.5 (Table 6): the absolute error at each time step is divided by the total distance travelled and
    the result averaged over all time steps, i.e. 100 (1/N) sum_k |e_k| / D.

    Args:
        errors: (N, 3) error vectors or (N,) error norms, metres.
        distance: total ground-truth distance travelled D > 0, metres (see :func:`distance_travelled`).

    >>> percent_of_distance([1.0, 2.0, 3.0], 100.0)
    2.0
    """
    norms = _error_norms(errors)
    if isinstance(distance, bool) or not isinstance(distance, (int, float, np.integer, np.floating)) \
            or not math.isfinite(distance) or distance <= 0:
        raise ValueError(f"distance must be a finite distance > 0 in metres; got {distance!r}")
    return float(100.0 * np.mean(norms / distance))  # % = 100 (1/N) sum |e_k| / D


# ==================================================================================================== alignment
@dataclass(frozen=True)
class Alignment:
    """Similarity transform p_gt ≈ scale R p_est + t found by :func:`align_umeyama`.

    Attributes:
        scale: s (1 without scale).
        R: (3, 3) rotation (a rotation about z for the 4-DoF alignment).
        t: (3,) translation, metres.
    """

    scale: float
    R: NDArray[np.float64]
    t: NDArray[np.float64]

    def apply(self, p: ArrayLike) -> NDArray[np.float64]:
        """Return s R p + t for points p (N, 3)."""
        return self.scale * np.asarray(p, dtype=np.float64) @ self.R.T + self.t

    def apply_rotation(self, R_ItoG: ArrayLike) -> NDArray[np.float64]:
        """Return aligned orientations R @ R_ItoG for (N, 3, 3) body-to-world matrices."""
        return self.R @ np.asarray(R_ItoG, dtype=np.float64)


def align_umeyama(p_est: ArrayLike, p_gt: ArrayLike, with_scale: bool = False, yaw_only: bool = False) -> Alignment:
    """Return the least-squares alignment (s, R, t) minimising sum_k |p_gt,k - (s R p_est,k + t)|^2.

    Umeyama (1991): with centred points a_k = p_est,k - mean(p_est), b_k = p_gt,k - mean(p_gt),
    Sigma = (1/N) sum b_k a_k^T = U D V^T, S = diag(1, 1, det(U) det(V)):  R = U S V^T,
    s = trace(D S) / ((1/N) sum |a_k|^2) (or 1), t = mean(p_gt) - s R mean(p_est).
    4-DoF (``yaw_only``, for VIO whose roll and pitch are observable from gravity): R = Rz(psi) with
    psi = atan2(sum (a_x b_y - a_y b_x), sum (a_x b_x + a_y b_y)); s = sum b_k . R a_k / sum |a_k|^2 with scale.

    Args:
        p_est: (N, 3) estimated positions (N >= 3 for SE(3)/Sim(3), >= 2 for 4-DoF).
        p_gt: (N, 3) ground-truth positions at the same times.
        with_scale: also estimate a scale (Sim(3); monocular VO without IMU).
        yaw_only: rotate about the world z axis only (position + yaw).

    >>> rng = np.random.default_rng(0)
    >>> a = rng.normal(size=(10, 3))
    >>> Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    >>> fit = align_umeyama(a, a @ Rz.T + [1.0, 2.0, 3.0])
    >>> np.round(fit.R, 6) + 0.0, np.round(fit.t, 6) + 0.0
    (array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]]), array([1., 2., 3.]))
    """
    a_all = _array(p_est, "p_est", (3,), "(N, 3)")
    b_all = _array(p_gt, "p_gt", (3,), "(N, 3)")
    _same_length(a_all, b_all, "p_est", "p_gt")
    minimum = 2 if yaw_only else 3
    if a_all.shape[0] < minimum:
        raise ValueError(f"p_est must hold at least {minimum} points for this alignment; got {a_all.shape[0]}")
    mu_a, mu_b = a_all.mean(axis=0), b_all.mean(axis=0)
    a, b = a_all - mu_a, b_all - mu_b
    var_a = float(np.mean(np.sum(a**2, axis=1)))  # (1/N) sum |a_k|^2
    if yaw_only:
        psi = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
                         float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
        c, s_ = math.cos(psi), math.sin(psi)
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        scale = float(np.mean(np.sum(b * (a @ R.T), axis=1)) / var_a) if with_scale and var_a > 0 else 1.0
    else:
        sigma = b.T @ a / a.shape[0]  # Sigma = (1/N) sum b_k a_k^T
        U, D, Vt = np.linalg.svd(sigma)
        S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
        R = U @ S @ Vt  # R = U S V^T
        scale = float(np.trace(np.diag(D) @ S) / var_a) if with_scale and var_a > 0 else 1.0
    t = mu_b - scale * R @ mu_a  # t = mu_gt - s R mu_est
    return Alignment(scale=scale, R=R, t=t)


def absolute_trajectory_error(p_est: ArrayLike, p_gt: ArrayLike, with_scale: bool = False,
                              yaw_only: bool = True) -> float:
    """Return the ATE: RMSE of p_gt,k - (s R p_est,k + t) after :func:`align_umeyama` (metres).

    Args:
        p_est: (N, 3) estimated positions, associated with p_gt (same times; see :func:`position_errors`).
        p_gt: (N, 3) ground-truth positions.
        with_scale: align with a scale too.
        yaw_only: 4-DoF position + yaw alignment (default, the VIO convention) instead of SE(3).

    >>> round(absolute_trajectory_error([[0.0, 0, 0], [1.0, 0, 0]], [[5.0, 5, 0], [5.0, 6, 0]]), 9)
    0.0
    """
    fit = align_umeyama(p_est, p_gt, with_scale=with_scale, yaw_only=yaw_only)
    residual = np.asarray(p_gt, dtype=np.float64) - fit.apply(p_est)
    return rmse(residual)


@dataclass(frozen=True)
class RelativePoseErrors:
    """Errors of the relative poses between index pairs (i, j) a fixed distance or time apart.

    Attributes:
        i, j: (M,) int64 start and end indices of each pair.
        translation: (M,) |t_err| of the relative-pose error, metres.
        rotation: (M,) angle of the relative-rotation error, radians.
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]


def _rotations(value: ArrayLike, name: str) -> NDArray[np.float64]:
    R = np.asarray(value, dtype=np.float64)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"{name} must have shape (N, 3, 3); got {R.shape}")
    if not np.isfinite(R).all():
        raise ValueError(f"{name} must contain only finite values; got non-finite entries")
    return R


def _rotation_angle(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the rotation angles (N,) of matrices (N, 3, 3): atan2(|vee(R - R^T)| / 2, (trace R - 1) / 2)."""
    skew = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    return np.arctan2(0.5 * np.linalg.norm(skew, axis=1), 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0))


def relative_pose_error(t: ArrayLike, R_est: ArrayLike, p_est: ArrayLike, R_gt: ArrayLike, p_gt: ArrayLike,
                        delta: float, mode: str = "distance") -> RelativePoseErrors:
    """Return the relative pose errors over pairs (i, j) separated by ``delta`` metres of path (or seconds).

    For each i, j is the first index with (path length from i to j along the ground truth) >= delta (mode
    "distance") or t_j - t_i >= delta (mode "time"). With T = (R_ItoG, p_IinG):
    dT_gt = T_gt,i^-1 T_gt,j, dT_est = T_est,i^-1 T_est,j, E = dT_gt^-1 dT_est; translation = |t(E)|,
    rotation = angle(R(E)). Relative errors do not depend on a global alignment.

    Args:
        t: (N,) increasing times, s (common to estimate and ground truth).
        R_est, R_gt: (N, 3, 3) body-to-world orientations R_ItoG.
        p_est, p_gt: (N, 3) positions p_IinG, metres.
        delta: separation (> 0), metres or seconds.
        mode: "distance" or "time".

    >>> N = 5
    >>> R = np.repeat(np.eye(3)[None], N, axis=0)
    >>> p = np.stack([np.arange(N, dtype=float), np.zeros(N), np.zeros(N)], axis=1)
    >>> rpe = relative_pose_error(np.arange(N), R, p * 1.1, R, p, delta=2.0)
    >>> rpe.i.tolist(), np.round(rpe.translation, 3).tolist()
    ([0, 1, 2], [0.2, 0.2, 0.2])
    """
    times = _array(t, "t", (), "(N,)")
    Re, Rg = _rotations(R_est, "R_est"), _rotations(R_gt, "R_gt")
    pe = _array(p_est, "p_est", (3,), "(N, 3)")
    pg = _array(p_gt, "p_gt", (3,), "(N, 3)")
    for arr, name in ((Re, "R_est"), (pe, "p_est"), (Rg, "R_gt"), (pg, "p_gt")):
        _same_length(times, arr, "t", name)
    if np.any(np.diff(times) < 0):
        raise ValueError("t must be non-decreasing; got unsorted times")
    if isinstance(delta, bool) or not isinstance(delta, (int, float, np.integer, np.floating)) \
            or not math.isfinite(delta) or delta <= 0:
        raise ValueError(f"delta must be a finite number > 0 (metres or seconds); got {delta!r}")
    if mode not in ("distance", "time"):
        raise ValueError(f"mode must be 'distance' or 'time'; got {mode!r}")
    if mode == "distance":
        along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pg, axis=0), axis=1))])
    else:
        along = times
    # first j with along_j >= along_i + delta (a relative 1e-9 slack absorbs rounding of the cumulative sum)
    j_all = np.searchsorted(along, along + delta - 1e-9 * (delta + np.abs(along)), side="left")
    i = np.flatnonzero(j_all < times.shape[0]).astype(np.int64)
    j = j_all[i].astype(np.int64)
    # relative poses in frame i: dR = R_i^T R_j, dp = R_i^T (p_j - p_i)
    dR_gt = np.swapaxes(Rg[i], 1, 2) @ Rg[j]
    dp_gt = np.einsum("nji,nj->ni", Rg[i], pg[j] - pg[i])
    dR_est = np.swapaxes(Re[i], 1, 2) @ Re[j]
    dp_est = np.einsum("nji,nj->ni", Re[i], pe[j] - pe[i])
    # E = dT_gt^-1 dT_est: R_E = dR_gt^T dR_est, t_E = dR_gt^T (dp_est - dp_gt)
    R_E = np.swapaxes(dR_gt, 1, 2) @ dR_est
    t_E = np.einsum("nji,nj->ni", dR_gt, dp_est - dp_gt)
    return RelativePoseErrors(i=i, j=j, translation=np.linalg.norm(t_E, axis=1), rotation=_rotation_angle(R_E))


@dataclass(frozen=True)
class SubTrajectoryErrors:
    """Relative errors of every pose pair (i, j) one sub-trajectory length apart (rpg_trajectory_evaluation).

    Attributes:
        length_m: the sub-trajectory length L, metres of ground-truth path.
        i, j: (M,) int64 start and end indices of the pairs.
        translation_m: (M,) |t(E)|, metres.
        translation_percent: (M,) 100 |t(E)| / L.
        yaw_rad: (M,) |yaw| of the error rotation expressed in the world frame (ZYX Euler angles).
        tilt_rad: (M,) sqrt(pitch^2 + roll^2) of the same angles (rpg's "gravity" error).
        rotation_rad: (M,) angle of the error rotation.
    """

    length_m: float
    i: NDArray[np.int64]
    j: NDArray[np.int64]
    translation_m: NDArray[np.float64]
    translation_percent: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]
    tilt_rad: NDArray[np.float64]
    rotation_rad: NDArray[np.float64]

    def summary(self) -> dict[str, float]:
        """Return the length, the pair count and the mean, median and RMSE of translation (m, %) and yaw (deg)."""
        out: dict[str, float] = {"length_m": self.length_m, "pairs": float(self.i.shape[0])}
        for key, values in (("translation_m", self.translation_m), ("translation_percent", self.translation_percent),
                            ("yaw_deg", np.degrees(self.yaw_rad))):
            empty = values.size == 0
            out[f"{key}_mean"] = float("nan") if empty else float(np.mean(values))
            out[f"{key}_median"] = float("nan") if empty else float(np.median(values))
            out[f"{key}_rmse"] = float("nan") if empty else float(np.sqrt(np.mean(values ** 2)))
        return out


def subtrajectory_lengths(p_gt: ArrayLike, percentages: Sequence[float] = (10, 20, 30, 40, 50)) -> NDArray[np.float64]:
    """Return the sub-trajectory lengths (metres) that are ``percentages`` of the ground-truth path length.

    rpg_trajectory_evaluation's preset uses 10, 20, 30, 40 and 50 % (and floors them to whole metres, which
    leaves nothing for paths shorter than 10 m; these lengths are not rounded).

    >>> subtrajectory_lengths([[0.0, 0, 0], [3.0, 4, 0], [3.0, 4, 10]]).tolist()
    [1.5, 3.0, 4.5, 6.0, 7.5]
    """
    pct = np.asarray(percentages, dtype=np.float64)
    if pct.ndim != 1 or pct.size == 0 or not np.isfinite(pct).all() or (pct <= 0).any():
        raise ValueError(f"percentages must be a non-empty sequence of numbers > 0; got {percentages!r}")
    return pct / 100.0 * distance_travelled(p_gt)


def _zyx_yaw_tilt(R: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (|yaw|, sqrt(pitch^2 + roll^2)) of R = Rz(yaw) Ry(pitch) Rx(roll) for matrices (M, 3, 3)."""
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    pitch = np.arctan2(-R[:, 2, 0], np.hypot(R[:, 0, 0], R[:, 1, 0]))
    roll = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    return np.abs(yaw), np.hypot(pitch, roll)


def relative_errors_by_length(R_est: ArrayLike, p_est: ArrayLike, R_gt: ArrayLike, p_gt: ArrayLike,
                              lengths: Sequence[float] | None = None,
                              percentages: Sequence[float] = (10, 20, 30, 40, 50),
                              max_length_diff: float = 0.2) -> list[SubTrajectoryErrors]:
    """Return the relative errors over sub-trajectories of each length, as rpg_trajectory_evaluation computes them.

    With d_k the ground-truth distance travelled from pose 0 to pose k, each pose i is paired with the first j >= i
    whose d_j - d_i is closest to L, kept when |d_j - d_i - L| < max_length_diff L (rpg's
    ``compute_comparison_indices_length``; evo's ``filter_pairs_by_path`` with all pairs and tol = 0.2 L). With
    T = (R_ItoG, p_IinG), dT = T_i^-1 T_j and the error E = dT_gt^-1 dT_est (rpg's T_error_in_c2 with an identity
    hand-eye transform; evo's RPE), the translation error is |t(E)| and the yaw and tilt are the ZYX Euler angles of
    the error rotated into the world by the estimate's orientation at j, R_est,j R(E) R_est,j^T.

    Pass an aligned estimate (``align_umeyama``): the world-frame yaw/tilt split uses its orientation, while the
    translation error and the rotation angle do not depend on the alignment.

    Args:
        R_est, R_gt: (N, 3, 3) body-to-world orientations R_ItoG at the same times.
        p_est, p_gt: (N, 3) positions, metres.
        lengths: sub-trajectory lengths in metres; None: ``percentages`` of the ground-truth path length.
        percentages: used when ``lengths`` is None (rpg's preset 10 ... 50 %).
        max_length_diff: relative tolerance on the length of a pair (rpg and evo: 0.2).

    Reference: Zhang & Scaramuzza, IROS 2018, §V (relative error); rpg_trajectory_evaluation
    ``compute_relative_error``; Sturm et al., IROS 2012, Eq. 2.

    >>> N = 11
    >>> R = np.repeat(np.eye(3)[None], N, axis=0)
    >>> p = np.stack([np.arange(N, dtype=float), np.zeros(N), np.zeros(N)], axis=1)
    >>> out = relative_errors_by_length(R, p * 1.02, R, p, lengths=[5.0])[0]      # 2 % scale drift
    >>> out.i.tolist(), np.round(out.translation_percent, 6).tolist()
    ([0, 1, 2, 3, 4, 5], [2.0, 2.0, 2.0, 2.0, 2.0, 2.0])
    """
    Re, Rg = _rotations(R_est, "R_est"), _rotations(R_gt, "R_gt")
    pe = _array(p_est, "p_est", (3,), "(N, 3)")
    pg = _array(p_gt, "p_gt", (3,), "(N, 3)")
    for arr, name in ((Rg, "R_gt"), (pe, "p_est"), (pg, "p_gt")):
        _same_length(Re, arr, "R_est", name)
    if isinstance(max_length_diff, bool) or not isinstance(max_length_diff, (int, float, np.integer, np.floating)) \
            or not math.isfinite(max_length_diff) or max_length_diff <= 0:
        raise ValueError(f"max_length_diff must be a finite number > 0 (a fraction of the length); got "
                         f"{max_length_diff!r}")
    if lengths is None:
        lengths_m = subtrajectory_lengths(pg, percentages)
    else:
        lengths_m = np.asarray(lengths, dtype=np.float64)
        if lengths_m.ndim != 1 or not np.isfinite(lengths_m).all() or (lengths_m <= 0).any():
            raise ValueError(f"lengths must be a sequence of lengths > 0 in metres; got {lengths!r}")
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pg, axis=0), axis=1))])  # d_k
    n = along.shape[0]
    results = []
    for length in lengths_m.tolist():
        target = along + length
        # closest d_j to d_i + L among j >= i (d is non-decreasing): the first index at or above the target, or the
        # first index of the value just below it (ties go to the earlier index, as rpg's and evo's argmin)
        above = np.searchsorted(along, target, side="left")
        below_value = along[np.clip(above - 1, 0, n - 1)]
        below = np.maximum(np.searchsorted(along, below_value, side="left"), np.arange(n))
        err_above = np.where(above < n, np.abs(along[np.minimum(above, n - 1)] - target), np.inf)
        err_below = np.abs(along[below] - target)
        j_all = np.where(err_below <= err_above, below, above)
        err = np.minimum(err_below, err_above)
        i = np.flatnonzero((err < max_length_diff * length) & (j_all > np.arange(n))).astype(np.int64)
        j = j_all[i].astype(np.int64)
        # dT = T_i^-1 T_j: dR = R_i^T R_j, dp = R_i^T (p_j - p_i); E = dT_gt^-1 dT_est
        dR_gt = np.swapaxes(Rg[i], 1, 2) @ Rg[j]
        dp_gt = np.einsum("nji,nj->ni", Rg[i], pg[j] - pg[i])
        dR_est = np.swapaxes(Re[i], 1, 2) @ Re[j]
        dp_est = np.einsum("nji,nj->ni", Re[i], pe[j] - pe[i])
        R_E = np.swapaxes(dR_gt, 1, 2) @ dR_est  # R_E = dR_gt^T dR_est
        t_E = np.einsum("nji,nj->ni", dR_gt, dp_est - dp_gt)  # t_E = dR_gt^T (dp_est - dp_gt)
        R_E_world = Re[j] @ R_E @ np.swapaxes(Re[j], 1, 2)  # rpg's T_error_in_w (rotation part)
        yaw, tilt = _zyx_yaw_tilt(R_E_world)
        translation = np.linalg.norm(t_E, axis=1)
        results.append(SubTrajectoryErrors(
            length_m=float(length), i=i, j=j, translation_m=translation,
            translation_percent=100.0 * translation / length,
            yaw_rad=yaw, tilt_rad=tilt, rotation_rad=_rotation_angle(R_E)))
    return results


# ==================================================================================================== orientation
def orientation_errors(R_est: ArrayLike, R_gt: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                      NDArray[np.float64]]:
    """Return (angle, yaw, tilt) (N,) each, radians: total, yaw and roll/pitch parts of the orientation errors.

    With the world-frame error dR = R_est R_gt^T (R_est = dR R_gt, R = R_ItoG):
    angle = |log dR|; yaw = atan2(dR[1, 0], dR[0, 0]) in (-pi, pi] (the heading error, rotation about z_G,
    unobservable in VIO); tilt = arccos(z_G . dR z_G) (angle between the true and estimated gravity directions,
    the observable roll/pitch error).

    Args:
        R_est, R_gt: (N, 3, 3) body-to-world orientations R_ItoG.

    >>> c, s = np.cos(0.1), np.sin(0.1)
    >>> Rz = np.array([[[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]])
    >>> [np.round(x, 6).tolist() for x in orientation_errors(Rz, np.eye(3)[None])]
    [[0.1], [0.1], [0.0]]
    """
    Re, Rg = _rotations(R_est, "R_est"), _rotations(R_gt, "R_gt")
    _same_length(Re, Rg, "R_est", "R_gt")
    dR = Re @ np.swapaxes(Rg, 1, 2)  # dR = R_est R_gt^T
    angle = _rotation_angle(dR)
    yaw = np.arctan2(dR[:, 1, 0], dR[:, 0, 0])  # ZYX yaw of dR
    tilt = np.arccos(np.clip(dR[:, 2, 2], -1.0, 1.0))  # z_G . dR z_G = dR[2, 2]
    return angle, yaw, tilt


# ==================================================================================================== consistency
def nees(errors: ArrayLike, covariances: ArrayLike) -> NDArray[np.float64]:
    """Return NEES_k = e_k^T P_k^-1 e_k (...,) for errors (..., d) and covariances (..., d, d).

    Leading dimensions are free, e.g. (runs, N, d) gives (runs, N); average over runs for the Monte-Carlo test
    against :func:`chi2_bounds`.

    >>> nees([[1.0, 2.0]], [np.diag([1.0, 4.0])]).tolist()
    [2.0]
    """
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(covariances, dtype=np.float64)
    if e.ndim < 1 or P.shape != e.shape + e.shape[-1:]:
        raise ValueError(f"covariances must have shape errors.shape + (d,) = (..., d, d); got errors {e.shape} and "
                         f"covariances {P.shape}")
    if not (np.isfinite(e).all() and np.isfinite(P).all()):
        raise ValueError("errors and covariances must contain only finite values; got non-finite entries")
    try:
        x = np.linalg.solve(P, e[..., None])[..., 0]  # x = P^-1 e
    except np.linalg.LinAlgError:
        raise ValueError("covariances must be positive definite; got a singular matrix") from None
    return np.einsum("...i,...i->...", e, x)  # e^T P^-1 e


def chi2_bounds(dof: int, n_runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Return the two-sided ``probability`` interval (lo, hi) of the average NEES over ``n_runs`` runs.

    n_runs * mean NEES ~ chi2(n_runs * dof) for a consistent filter, so
    lo = chi2.ppf((1 - P) / 2, n d) / n and hi = chi2.ppf((1 + P) / 2, n d) / n (Bar-Shalom et al. 2001, §5.4).

    Args:
        dof: dimension d of the error (e.g. 3 for position, 6 for pose).
        n_runs: number of Monte-Carlo runs averaged (>= 1).
        probability: coverage of the interval, in (0, 1).

    >>> [round(x, 2) for x in chi2_bounds(2, 50)]   # Bar-Shalom's example: [1.5, 2.6]
    [1.48, 2.59]
    """
    for value, name in ((dof, "dof"), (n_runs, "n_runs")):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an int >= 1; got {value!r}")
    if not (isinstance(probability, (int, float, np.floating)) and 0.0 < probability < 1.0):
        raise ValueError(f"probability must be in (0, 1); got {probability!r}")
    k = int(dof) * int(n_runs)
    lo = chi2.ppf(0.5 * (1.0 - probability), k) / n_runs
    hi = chi2.ppf(0.5 * (1.0 + probability), k) / n_runs
    return float(lo), float(hi)


# ==================================================================================================== reporting
def summarize(t_est: ArrayLike, p_est: ArrayLike, t_gt: ArrayLike, p_gt: ArrayLike, name: str = "") -> dict[str, Any]:
    """Return a dict of the thesis's metrics for one run (positions in metres, % of distance in percent).

    Keys: name, n, distance_m (ground-truth path length over the estimate's time span), rmse_m, final_error_m,
    mean_error_m, max_error_m, percent_of_distance, ate_4dof_m (ATE after a position + yaw alignment), ate_se3_m
    (ATE after an SE(3) alignment; NaN below 3 estimates).

    Args:
        t_est, p_est: (N,) times and (N, 3) estimated positions.
        t_gt, p_gt: (M,) times and (M, 3) ground-truth positions (interpolated at t_est).
        name: label of the row (e.g. "MSCKF, OC on").

    >>> t = np.linspace(0.0, 10.0, 11)
    >>> p = np.stack([t, np.zeros(11), np.zeros(11)], axis=1)
    >>> row = summarize(t, p + [0.0, 0.1, 0.0], t, p, name="offset")
    >>> [round(row[k], 6) for k in ("rmse_m", "distance_m", "percent_of_distance")]
    [0.1, 10.0, 1.0]
    """
    errors = position_errors(t_est, p_est, t_gt, p_gt)
    t_e = np.asarray(t_est, dtype=np.float64)
    t_g = np.asarray(t_gt, dtype=np.float64)
    p_g = np.asarray(p_gt, dtype=np.float64)
    inside = (t_g > t_e.min()) & (t_g < t_e.max())
    p_gt_at = np.asarray(p_est, dtype=np.float64) - errors  # ground truth at t_est
    path = np.concatenate([p_gt_at[:1], p_g[inside], p_gt_at[-1:]])  # ground truth over the estimate's span
    distance = distance_travelled(path)
    norms = np.linalg.norm(errors, axis=1)
    row: dict[str, Any] = {
        "name": name,
        "n": int(norms.shape[0]),
        "distance_m": distance,
        "rmse_m": rmse(errors),
        "final_error_m": final_error(errors),
        "mean_error_m": float(norms.mean()),
        "max_error_m": float(norms.max()),
        "percent_of_distance": percent_of_distance(errors, distance) if distance > 0 else float("nan"),
        "ate_4dof_m": (absolute_trajectory_error(p_est, p_gt_at, yaw_only=True) if norms.shape[0] >= 2
                       else float("nan")),
        "ate_se3_m": (absolute_trajectory_error(p_est, p_gt_at, yaw_only=False) if norms.shape[0] >= 3
                      else float("nan")),
    }
    return row


_COLUMNS = (
    ("name", "Method"),
    ("rmse_m", "RMSE [m]"),
    ("final_error_m", "Final Error [m]"),
    ("percent_of_distance", "% Error"),
)


def _format_value(value: Any, key: str) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    v = float(value)
    if not math.isfinite(v):
        return "-"
    text = f"{v:.2f}" if abs(v) >= 1.0 else f"{v:.3g}"  # 2 decimals, or 3 significant digits below 1
    return text + " %" if key == "percent_of_distance" else text


def format_table(rows: Sequence[dict[str, Any]], columns: Sequence[tuple[str, str]] | None = None) -> str:
    """Return a Markdown table of result rows (dicts such as :func:`summarize` returns), like the thesis's Table 6.

    Args:
        rows: one dict per method/run.
        columns: (key, header) pairs; default name, RMSE, final error and % of distance. Missing keys print "-".

    >>> print(format_table([{"name": "IMU-only", "rmse_m": 29.19, "final_error_m": 88.71, "percent_of_distance": 26.34},
    ...                     {"name": "MSCKF", "rmse_m": 0.437, "final_error_m": 0.968, "percent_of_distance": 0.447}]))
    | Method | RMSE [m] | Final Error [m] | % Error |
    |---|---|---|---|
    | IMU-only | 29.19 | 88.71 | 26.34 % |
    | MSCKF | 0.437 | 0.968 | 0.447 % |
    """
    cols = tuple(_COLUMNS if columns is None else columns)
    if not cols or any(not (isinstance(c, tuple) and len(c) == 2) for c in cols):
        raise ValueError(f"columns must be a non-empty sequence of (key, header) pairs; got {columns!r}")
    for k, row in enumerate(rows):
        if not isinstance(row, dict):
            raise ValueError(f"rows[{k}] must be a dict of metric values; got {type(row).__name__}")
    lines = ["| " + " | ".join(header for _, header in cols) + " |", "|" + "---|" * len(cols)]
    for row in rows:
        lines.append("| " + " | ".join(_format_value(row[key], key) if key in row else "-" for key, _ in cols) + " |")
    return "\n".join(lines)
