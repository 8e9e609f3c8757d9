"""Filter initialisation: from a given (e.g. ground-truth) state, or statically from the first stationary IMU samples.

Static initialisation (as in S-MSCKF / OpenVINS, thesis §4.4 for why biases matter). While the IMU rests, the
accelerometer measures the specific force a_m = R_GtoI (0 - g_G) + b_a + n_a, i.e. "up" in I, and the gyroscope
measures ω_m = b_g + n_g. Over a window of M samples::

    b_g = mean(ω_m)                                   (gyro bias; the Earth rate, 7e-5 rad/s, is ignored)
    z_I = mean(a_m) / |mean(a_m)|                     (world z axis = up, expressed in I: z_I = R_GtoI e_z)

The accelerometer bias is not separable from the tilt (it shifts z_I by about |b_a| / g rad), so it is left at 0.
Yaw is unobservable; it is set by choice: R_ItoG = Rz(yaw) Ry(θ) Rx(φ) (ZYX Euler angles) with pitch and roll
from the third row of R_ItoG, which must equal z_I^T::

    [-sin θ, cos θ sin φ, cos θ cos φ] = z_I^T   ->   θ = atan2(-z_x, sqrt(z_y² + z_z²)),  φ = atan2(z_y, z_z)

A window that is not static is rejected (ValueError): the IMU samples are averaged over short blocks (50 ms, which
removes motor vibration such as a MAV's spinning rotors) and the spread of those block means must stay below a
threshold for the gyroscope and the accelerometer, and |mean(a_m)| must be close to |g|.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import rot_to_quat
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.state import FilterState, ImuState, inject_error

__all__ = [
    "StaticInitStats",
    "StaticInitialization",
    "gravity_aligned_rotation",
    "static_initialization",
    "initial_state_from_truth",
    "initial_state_from_static",
]


@dataclass(frozen=True)
class StaticInitStats:
    """Residual statistics of a static initialisation window (for reports and for judging the result).

    Attributes:
        t_start, t_end: first and last sample time used, s.
        n_samples: samples in the window.
        gyro_std, accel_std: (3,) per-axis standard deviation of the raw samples (noise + vibration), rad/s, m/s^2.
        gyro_block_std, accel_block_std: spread (norm of the per-axis std) of the block means; the static test.
        accel_norm: |mean(a_m)|, m/s^2 (should be close to |g|).
        gravity_error: accel_norm - gravity_magnitude, m/s^2 (accelerometer bias / scale along gravity).
        up_I: (3,) unit vector of the world's up axis in I (mean specific force direction).
    """

    t_start: float
    t_end: float
    n_samples: int
    gyro_std: NDArray[np.float64]
    accel_std: NDArray[np.float64]
    gyro_block_std: float
    accel_block_std: float
    accel_norm: float
    gravity_error: float
    up_I: NDArray[np.float64]


class StaticInitialization(NamedTuple):
    """Result of :func:`static_initialization`: unpacks as ``q_GtoI, b_g, stats``."""

    q_GtoI: NDArray[np.float64]
    b_g: NDArray[np.float64]
    stats: StaticInitStats


def _samples(imu_t: ArrayLike, gyro: ArrayLike, accel: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """Return validated (t (M,), gyro (M, 3), accel (M, 3))."""
    try:
        t = np.asarray(imu_t, dtype=np.float64)
        w = np.asarray(gyro, dtype=np.float64)
        a = np.asarray(accel, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError("imu_t (M,), gyro (M, 3) and accel (M, 3) must be numeric arrays") from exc
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"imu_t must have shape (M,) with M >= 2; got {t.shape}")
    M = t.shape[0]
    if w.shape != (M, 3) or a.shape != (M, 3):
        raise ValueError(f"gyro and accel must have shape (M, 3) = ({M}, 3); got {w.shape} and {a.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(w)) and np.all(np.isfinite(a))):
        raise ValueError("imu_t, gyro and accel must contain only finite values (no NaN/inf)")
    if np.any(np.diff(t) <= 0.0):
        raise ValueError("imu_t must be strictly increasing")
    return t, w, a


def _positive(value: float, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
    return float(value)


def gravity_aligned_rotation(up_I: ArrayLike, yaw: float = 0.0) -> NDArray[np.float64]:
    """Return R_ItoG (3, 3) whose world z axis points along ``up_I`` (in I), with the ZYX yaw angle ``yaw``.

    Args:
        up_I: (3,) non-zero vector: the world's up direction expressed in I (e.g. the mean specific force at rest).
        yaw: heading ψ of R_ItoG = Rz(ψ) Ry(θ) Rx(φ), radians (unobservable from the IMU; 0 by convention).

    θ = atan2(-z_x, sqrt(z_y² + z_z²)), φ = atan2(z_y, z_z) with z = up_I / |up_I| (module docstring).

    >>> np.round(gravity_aligned_rotation([0.0, 0.0, 9.81]), 6) + 0.0     # level: identity
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    >>> R = gravity_aligned_rotation([1.0, 0.0, 0.0])                     # I's x axis points up
    >>> np.round(R.T @ [0.0, 0.0, 1.0], 6) + 0.0                          # R_GtoI e_z = up_I
    array([1., 0., 0.])
    """
    try:
        z = np.asarray(up_I, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"up_I must be a numeric vector of shape (3,); got {up_I!r}") from exc
    if z.shape != (3,) or not np.all(np.isfinite(z)):
        raise ValueError(f"up_I must be a finite vector of shape (3,); got shape {z.shape}")
    norm = float(np.linalg.norm(z))
    if norm < 1e-9:
        raise ValueError(f"up_I must be non-zero (the mean specific force at rest); got norm {norm:.3g}")
    if isinstance(yaw, bool) or not isinstance(yaw, (int, float, np.integer, np.floating)) or not math.isfinite(yaw):
        raise ValueError(f"yaw must be a finite angle in radians; got {yaw!r}")
    z = z / norm
    pitch = math.atan2(-z[0], math.hypot(z[1], z[2]))  # θ = atan2(-z_x, sqrt(z_y² + z_z²))
    roll = math.atan2(z[1], z[2])  # φ = atan2(z_y, z_z)
    cy, sy, cp, sp, cr, sr = (math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll),
                              math.sin(roll))
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return Rz @ Ry @ Rx  # R_ItoG = Rz(ψ) Ry(θ) Rx(φ)


def _block_spread(t: NDArray[np.float64], x: NDArray[np.float64], block: float) -> float:
    """Return |std over blocks of the block means| (norm over axes) of x (M, 3) cut into blocks of ``block`` s."""
    b = np.floor((t - t[0]) / block).astype(np.int64)
    counts = np.bincount(b)
    used = counts > 0
    means = np.stack([np.bincount(b, weights=x[:, i])[used] / counts[used] for i in range(3)], axis=1)
    if means.shape[0] < 2:
        return 0.0
    return float(np.linalg.norm(means.std(axis=0)))


def static_initialization(
    imu_t: ArrayLike,
    gyro: ArrayLike,
    accel: ArrayLike,
    duration: float = 1.0,
    gravity_magnitude: float = 9.81,
    *,
    t_start: float | None = None,
    yaw: float = 0.0,
    max_gyro_std: float = 0.03,
    max_accel_std: float = 0.25,
    max_gravity_error: float = 0.5,
    block: float = 0.05,
) -> StaticInitialization:
    """Return (q_GtoI (4,), b_g (3,), stats): attitude and gyro bias from a stationary IMU window.

    Args:
        imu_t: (M,) strictly increasing sample times, s.
        gyro: (M, 3) angular rate in I, rad/s; accel: (M, 3) specific force in I, m/s^2.
        duration: window length, s (e.g. ``MsckfConfig.static_init_duration``); the window is
            [t_start, t_start + duration].
        gravity_magnitude: |g|, m/s^2 (world z is up, g_G = [0, 0, -gravity_magnitude]).
        t_start: window start, s (default: the first sample).
        yaw: the heading to assign (ZYX yaw of R_ItoG), radians; yaw is not observable from the IMU.
        max_gyro_std, max_accel_std: static test: largest allowed spread (norm over axes of the std) of the
            ``block``-second means of the gyro (rad/s) and of the accelerometer (m/s^2).
        max_gravity_error: largest allowed | |mean(a_m)| - gravity_magnitude |, m/s^2.
        block: averaging block, s (suppresses vibration, e.g. a MAV's rotors, that is not motion).

    Returns a :class:`StaticInitialization` (a NamedTuple ``q_GtoI, b_g, stats``): q_GtoI is the JPL quaternion of
    R_GtoI = gravity_aligned_rotation(mean(a_m), yaw)^T; b_g = mean(ω_m) (module docstring).
    Raises ValueError when the window holds fewer than 10 samples or is not static (the message gives the figures).

    >>> t = np.arange(0.0, 1.0, 0.005)
    >>> w = np.tile([0.01, -0.02, 0.005], (len(t), 1)); a = np.tile([0.0, 0.0, 9.81], (len(t), 1))
    >>> q, b_g, stats = static_initialization(t, w, a, duration=1.0)
    >>> np.round(q, 6) + 0.0, np.round(b_g, 6), stats.n_samples
    (array([0., 0., 0., 1.]), array([ 0.01 , -0.02 ,  0.005]), 200)
    """
    t, w, a = _samples(imu_t, gyro, accel)
    duration = _positive(duration, "duration")
    g_mag = _positive(gravity_magnitude, "gravity_magnitude")
    max_gyro_std = _positive(max_gyro_std, "max_gyro_std")
    max_accel_std = _positive(max_accel_std, "max_accel_std")
    max_gravity_error = _positive(max_gravity_error, "max_gravity_error")
    block = _positive(block, "block")
    t0 = float(t[0]) if t_start is None else float(t_start)
    if not math.isfinite(t0):
        raise ValueError(f"t_start must be a finite time in seconds; got {t_start!r}")
    sel = (t >= t0) & (t <= t0 + duration)
    n = int(np.count_nonzero(sel))
    if n < 10:
        raise ValueError(
            f"the window [t_start, t_start + duration] = [{t0:.6f}, {t0 + duration:.6f}] s must hold >= 10 IMU "
            f"samples; got {n} (samples span [{t[0]:.6f}, {t[-1]:.6f}] s)"
        )
    t, w, a = t[sel], w[sel], a[sel]
    gyro_spread = _block_spread(t, w, block)
    accel_spread = _block_spread(t, a, block)
    a_mean = a.mean(axis=0)
    a_norm = float(np.linalg.norm(a_mean))
    if gyro_spread > max_gyro_std or accel_spread > max_accel_std or abs(a_norm - g_mag) > max_gravity_error:
        raise ValueError(
            "the IMU window is not static: spread of the "
            f"{block * 1e3:g} ms means of gyro = {gyro_spread:.4f} rad/s (max_gyro_std {max_gyro_std:g}), of accel "
            f"= {accel_spread:.4f} m/s^2 (max_accel_std {max_accel_std:g}), |mean accel| = {a_norm:.3f} m/s^2 "
            f"(expected {g_mag:g} +- {max_gravity_error:g}); choose a stationary window (t_start, duration)"
        )
    b_g = w.mean(axis=0)  # b_g = mean(ω_m)
    R_ItoG = gravity_aligned_rotation(a_mean, yaw)
    q_GtoI = rot_to_quat(R_ItoG.T)  # JPL quaternion of R_GtoI
    stats = StaticInitStats(
        t_start=float(t[0]), t_end=float(t[-1]), n_samples=n, gyro_std=w.std(axis=0), accel_std=a.std(axis=0),
        gyro_block_std=gyro_spread, accel_block_std=accel_spread, accel_norm=a_norm, gravity_error=a_norm - g_mag,
        up_I=a_mean / a_norm,
    )
    return StaticInitialization(q_GtoI, b_g, stats)


def _extrinsics(R_CtoI: ArrayLike, p_CinI: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    R = np.asarray(R_CtoI, dtype=np.float64)
    p = np.asarray(p_CinI, dtype=np.float64)
    if R.shape != (3, 3) or p.shape != (3,):
        raise ValueError(f"R_CtoI must have shape (3, 3) and p_CinI shape (3,); got {R.shape} and {p.shape}")
    return R, p


def initial_state_from_truth(
    timestamp: float,
    R_ItoG: ArrayLike,
    p_IinG: ArrayLike,
    v_IinG: ArrayLike,
    R_CtoI: ArrayLike,
    p_CinI: ArrayLike,
    config: MsckfConfig,
    b_g: ArrayLike = (0.0, 0.0, 0.0),
    b_a: ArrayLike = (0.0, 0.0, 0.0),
    P_imu: ArrayLike | None = None,
    rng: np.random.Generator | int | None = None,
) -> FilterState:
    """Return an initial FilterState (no camera poses) at a given state and covariance.

    Args:
        timestamp: time of the state, s.
        R_ItoG: (3, 3) orientation; p_IinG, v_IinG: (3,) position and velocity of I in G.
        R_CtoI: (3, 3), p_CinI: (3,) camera-IMU extrinsics (x_I = R_CtoI x_C + p_CinI).
        config: filter configuration (``initial_imu_covariance`` when P_imu is None).
        b_g, b_a: (3,) initial bias estimates (e.g. the true ones, or zeros for an uncorrected IMU).
        P_imu: (15, 15) covariance of the initial error [δθ, δb_g, δv, δb_a, δp]; default from the config.
        rng: when given (Generator or seed), the returned estimate is the given state corrected by one draw
            δx ~ N(0, P_imu) (x_est = x ⊞ δx), so that x - x_est really has covariance P_imu: the start of a
            Monte-Carlo consistency run. None returns the given state exactly.

    >>> cfg = MsckfConfig()
    >>> s = initial_state_from_truth(0.0, np.eye(3), [1.0, 2.0, 3.0], np.zeros(3), np.eye(3), np.zeros(3), cfg)
    >>> s.imu.p_IinG, s.dim, s.num_cameras
    (array([1., 2., 3.]), 15, 0)
    """
    if not isinstance(config, MsckfConfig):
        raise ValueError(f"config must be an MsckfConfig; got {type(config).__name__}")
    R_CtoI, p_CinI = _extrinsics(R_CtoI, p_CinI)
    P = config.initial_imu_covariance() if P_imu is None else np.asarray(P_imu, dtype=np.float64)
    if P.shape != (15, 15):
        raise ValueError(f"P_imu must have shape (15, 15); got {P.shape}")
    imu = ImuState.from_pose(R_ItoG, p_IinG, v_IinG, timestamp, b_g=b_g, b_a=b_a)
    state = FilterState.initial(imu, R_CtoI, p_CinI, P)
    if rng is None:
        return state
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    try:
        L = np.linalg.cholesky(state.P)
    except np.linalg.LinAlgError:
        evals, evecs = np.linalg.eigh(state.P)
        L = evecs * np.sqrt(np.clip(evals, 0.0, None))
    dx = L @ gen.standard_normal(15)  # δx ~ N(0, P)
    est = inject_error(state, dx)
    # the first estimates (*_null) must be the estimate itself, not the truth
    imu_est = ImuState(est.imu.q_GtoI, est.imu.b_g, est.imu.v_IinG, est.imu.b_a, est.imu.p_IinG, timestamp)
    return FilterState.initial(imu_est, R_CtoI, p_CinI, P)


def initial_state_from_static(
    imu_t: ArrayLike,
    gyro: ArrayLike,
    accel: ArrayLike,
    R_CtoI: ArrayLike,
    p_CinI: ArrayLike,
    config: MsckfConfig,
    *,
    t_start: float | None = None,
    p_IinG: ArrayLike = (0.0, 0.0, 0.0),
    yaw: float = 0.0,
    **static_options: float,
) -> tuple[FilterState, StaticInitStats]:
    """Return (state, stats): a FilterState at the end of a static window (v = 0, b_a = 0) and the window statistics.

    Args:
        imu_t, gyro, accel: IMU samples (see :func:`static_initialization`).
        R_CtoI, p_CinI: camera-IMU extrinsics.
        config: configuration: window length ``static_init_duration``, |g| from ``gravity_G``, initial covariance.
        t_start: window start (default: first sample); p_IinG: (3,) position to assign; yaw: heading to assign.
        static_options: passed to :func:`static_initialization` (max_gyro_std, max_accel_std, ...).

    The state's time is the last sample of the window; the filter then starts from there.
    """
    if not isinstance(config, MsckfConfig):
        raise ValueError(f"config must be an MsckfConfig; got {type(config).__name__}")
    g_mag = float(np.linalg.norm(config.gravity))
    q_GtoI, b_g, stats = static_initialization(
        imu_t, gyro, accel, config.static_init_duration, g_mag, t_start=t_start, yaw=yaw, **static_options
    )
    R_CtoI, p_CinI = _extrinsics(R_CtoI, p_CinI)
    imu = ImuState(q_GtoI, b_g, np.zeros(3), np.zeros(3), p_IinG, stats.t_end)
    return FilterState.initial(imu, R_CtoI, p_CinI, config.initial_imu_covariance()), stats
