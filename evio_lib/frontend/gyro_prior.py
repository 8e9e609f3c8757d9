"""The gyroscope's prediction of the camera rotation between two frames (the prior of two-point RANSAC and KLT).

The body orientation obeys dR_ItoG/dt = R_ItoG [w_I x], so over [t0, t1] with piecewise-constant rates w_k held for
dt_k (the mean of the linearly interpolated gyro over each interval)::

    R_ItoG(t1) = R_ItoG(t0) prod_k exp([w_k dt_k x])  =>  R_I0toI1 = R_ItoG(t1)^T R_ItoG(t0) = (prod_k exp(w_k dt_k))^T

and in the camera frame (x_C = R_ItoC x_I with R_ItoC = R_CtoI^T): ``R_C0toC1 = R_ItoC R_I0toI1 R_CtoI``.

Reference: msckf_vio image_processor.cpp ``integrateImuData`` (mean rate over the interval); Forster et al.,
"On-Manifold Preintegration", T-RO 2017, Eq. 26.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import so3_exp

__all__ = ["integrate_gyro", "gyro_orientations", "camera_rotation_prior", "camera_rotation_priors"]


def integrate_gyro(t: ArrayLike, gyro: ArrayLike, t0: float, t1: float,
                   gyro_bias: ArrayLike | None = None) -> NDArray[np.float64]:
    """Return R_I0toI1 (3, 3), the rotation taking vectors in the IMU frame at t0 into the IMU frame at t1.

    The gyro is interpolated linearly between samples (held constant before the first and after the last) and each
    interval between consecutive breakpoints (t0, the samples inside (t0, t1), t1) is integrated with its mean rate.

    Args:
        t: (n,) strictly increasing sample times, s.
        gyro: (n, 3) angular rates w_I in the IMU frame, rad/s.
        t0, t1: the two frame times, t0 <= t1.
        gyro_bias: (3,) bias subtracted from every sample, rad/s (default zero).

    >>> t = np.linspace(0.0, 1.0, 101)
    >>> w = np.tile([0.0, 0.0, 0.5], (101, 1))                  # 0.5 rad/s about z
    >>> R = integrate_gyro(t, w, 0.2, 0.4)                      # 0.1 rad: x_I1 = Rz(-0.1) x_I0
    >>> bool(np.allclose(R, so3_exp([0.0, 0.0, -0.1])))
    True
    """
    times = np.asarray(t, dtype=np.float64)
    rates = np.asarray(gyro, dtype=np.float64)
    if times.ndim != 1 or times.shape[0] == 0 or rates.shape != (times.shape[0], 3):
        raise ValueError(f"t must have shape (n,) with n >= 1 and gyro shape (n, 3); got {times.shape} and "
                         f"{rates.shape}")
    if not (np.isfinite(times).all() and np.isfinite(rates).all()):
        raise ValueError("t and gyro must contain only finite values; got NaN or inf")
    if np.any(np.diff(times) <= 0):
        raise ValueError("t must be strictly increasing")
    for name, value in (("t0", t0), ("t1", t1)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not math.isfinite(value):
            raise ValueError(f"{name} must be a finite time in seconds; got {value!r}")
    if t1 < t0:
        raise ValueError(f"t1 must be >= t0; got t0 = {t0!r}, t1 = {t1!r}")
    bias = np.zeros(3) if gyro_bias is None else np.asarray(gyro_bias, dtype=np.float64)
    if bias.shape != (3,) or not np.isfinite(bias).all():
        raise ValueError(f"gyro_bias must be a finite (3,) vector in rad/s; got shape {bias.shape}")
    return gyro_orientations(times, rates, float(t0), float(t1), bias)[1][-1].T


def gyro_orientations(t: ArrayLike, gyro: ArrayLike, t0: float, t1: float, gyro_bias: ArrayLike | None = None
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Return (breaks (M + 1,), A (M + 1, 3, 3), w (M, 3)): the IMU's orientation over [t0, t1] at every breakpoint.

    breaks are t0, the sample times inside (t0, t1), and t1; A[k] = R_{I(breaks[k]) -> I(t0)} = prod_{j<k}
    exp([w_j dt_j]x); w[k] is the mean bias-corrected rate over [breaks[k], breaks[k + 1]] (the gyro interpolated
    linearly). :func:`integrate_gyro` is A[-1]^T; motion compensation (``events.motion_compensation``) reads every
    A[k]. The inputs are not checked here (``integrate_gyro`` checks them).

    >>> t = np.linspace(0.0, 1.0, 101); w = np.tile([0.0, 0.0, 0.5], (101, 1))
    >>> breaks, A, rates = gyro_orientations(t, w, 0.2, 0.4)
    >>> bool(np.allclose(A[-1], so3_exp([0.0, 0.0, 0.1])))   # R_{I(0.4) -> I(0.2)}: 0.1 rad about z
    True
    """
    times = np.asarray(t, dtype=np.float64)
    rates = np.asarray(gyro, dtype=np.float64)
    if not t1 >= t0:
        raise ValueError(f"the span must have t1 >= t0; got t0 = {t0!r}, t1 = {t1!r}")
    inside = times[(times > t0) & (times < t1)]
    breaks = np.concatenate([[float(t0)], inside, [float(t1)]])
    bias = np.zeros(3) if gyro_bias is None else np.asarray(gyro_bias, dtype=np.float64)
    w_at = np.stack([np.interp(breaks, times, rates[:, i]) for i in range(3)], axis=1) - bias
    w = 0.5 * (w_at[:-1] + w_at[1:])
    steps = so3_exp(w * np.diff(breaks)[:, None]).reshape(-1, 3, 3)  # exp(w_k dt_k), all k at once
    A = np.empty((breaks.size, 3, 3))
    A[0] = np.eye(3)
    for k, step in enumerate(steps):  # A(t_{k+1}) = A(t_k) exp(w_k dt_k), in order
        A[k + 1] = A[k] @ step
    return breaks, A, w


def camera_rotation_prior(t: ArrayLike, gyro: ArrayLike, t0: float, t1: float, R_CtoI: ArrayLike,
                          gyro_bias: ArrayLike | None = None) -> NDArray[np.float64]:
    """Return R_C0toC1 (3, 3) = R_ItoC R_I0toI1 R_CtoI, the camera rotation from frame time t0 to t1.

    X_C1 = R_C0toC1 X_C0 + p_C0inC1 for a point X fixed in the world.

    Args:
        t, gyro, t0, t1, gyro_bias: as :func:`integrate_gyro`.
        R_CtoI: (3, 3) camera-to-IMU rotation (x_I = R_CtoI x_C + p_CinI).

    >>> t = np.linspace(0.0, 1.0, 11); w = np.tile([0.0, 0.0, 1.0], (11, 1))
    >>> R_CtoI = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])   # camera looks along x_I
    >>> from evio_lib.geometry.rotation import so3_log
    >>> np.round(so3_log(camera_rotation_prior(t, w, 0.0, 0.1, R_CtoI)), 6) + 0.0  # body yaws 0.1 about z_I = -y_C
    array([0. , 0.1, 0. ])
    """
    R = np.asarray(R_CtoI, dtype=np.float64)
    if R.shape != (3, 3) or not np.isfinite(R).all() or np.abs(R @ R.T - np.eye(3)).max() > 1e-6:
        raise ValueError(f"R_CtoI must be a (3, 3) rotation matrix; got shape {R.shape}")
    return R.T @ integrate_gyro(t, gyro, t0, t1, gyro_bias) @ R  # R_C0toC1 = R_ItoC R_I0toI1 R_CtoI


def camera_rotation_priors(t: ArrayLike, gyro: ArrayLike, frame_times: ArrayLike, R_CtoI: ArrayLike,
                           gyro_bias: ArrayLike | None = None) -> NDArray[np.float64]:
    """Return (F, 3, 3) rotations R_C(k-1)toC(k) between consecutive frames (the identity for frame 0).

    The ``rotations`` argument of ``FeatureTracker.track``: entry k is :func:`camera_rotation_prior` from
    frame_times[k - 1] to frame_times[k].

    Args:
        t, gyro, R_CtoI, gyro_bias: as :func:`camera_rotation_prior`.
        frame_times: (F,) strictly increasing frame times, s.

    >>> t = np.linspace(0.0, 1.0, 101); w = np.tile([0.0, 0.0, 1.0], (101, 1))
    >>> R = camera_rotation_priors(t, w, [0.1, 0.2, 0.4], np.eye(3))
    >>> R.shape, bool(np.allclose(R[2], so3_exp([0.0, 0.0, -0.2])))
    ((3, 3, 3), True)
    """
    times = np.asarray(frame_times, dtype=np.float64)
    if times.ndim != 1 or not np.isfinite(times).all() or np.any(np.diff(times) <= 0):
        raise ValueError(f"frame_times must be a finite, strictly increasing (F,) array; got shape {times.shape}")
    out = np.repeat(np.eye(3)[None], times.shape[0], axis=0)
    for k in range(1, times.shape[0]):
        out[k] = camera_rotation_prior(t, gyro, times[k - 1], times[k], R_CtoI, gyro_bias)
    return out
