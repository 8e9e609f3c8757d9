"""A small error-state Kalman filter of attitude and gyroscope bias: the first two blocks of the MSCKF on their own.

The IMU turns about its own centre (no linear acceleration), so its accelerometer sees only gravity: one known
direction, measured in the body frame. The gyroscope drives the prediction; the accelerometer corrects it.

Nominal state: the JPL quaternion ``q_GtoI`` (scalar last, C(q_GtoI) = R_GtoI, :mod:`evio_lib.geometry.rotation`)
and the gyroscope bias ``b_g`` (rad/s, in I). Error state (thesis Eqs. 22-24)::

    x~ = [δθ (3), δb_g (3)],   q_true = δq(δθ) ⊗ q_est,   b_true = b_est + δb_g

δθ is a small rotation vector in I. Its dynamics are the top-left 6 x 6 block of thesis Eqs. 33-35, with
ω = ω_m - b_g the bias-corrected rate and the noise n = [n_g, n_wg] of densities σ_g (rad/s/√Hz) and σ_wg
(rad/s²/√Hz)::

    dδθ/dt = -[ω x] δθ - δb_g - n_g,   dδb_g/dt = n_wg
    F = [[-[ω x], -I], [0, 0]],   G = [[-I, 0], [0, I]],   Q_c = diag(σ_g² I, σ_wg² I)

With ω held over a step Δt, Φ = exp(F Δt) and Q_d = ∫ Φ(s) G Q_c G^T Φ(s)^T ds both come from one matrix exponential
(Van Loan's method, thesis Eqs. 36-37). The measurement is the specific force at rest, f_G = -g_G (up, 9.81 m/s²),
seen in I with white noise of std σ_a per axis::

    z = C(q_true) f_G + n_a ≈ ẑ + [ẑ x] δθ + n_a,   ẑ = C(q_est) f_G,   H = [[ẑ x], 0]

(first order: C(δq) ≈ I - [δθ x], and -[δθ x] ẑ = [ẑ x] δθ). H has rank 2: a rotation about ẑ, the vertical, leaves
z unchanged, so the yaw about gravity is unobservable from this measurement. The update is the MSCKF's own
(:func:`evio_lib.msckf.update.kalman_update`, Joseph form, thesis Eqs. 56-58) and the correction is multiplicative,
q ← quat_from_rotvec(δθ) ⊗ q, b_g ← b_g + δb_g.

:func:`simulate_rotating_imu` draws a matching data set: the true rate is held constant over each IMU interval, so
the filter's model is exact and its NEES follows the chi-square law.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import (
    as_float_array,
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_to_rot,
    quat_to_rotvec,
    skew,
    skew_unchecked,
)
from evio_lib.msckf.update import chi_square_threshold, kalman_update
from evio_lib.sim.imu import GRAVITY_G, ImuNoiseParams

__all__ = [
    "ERROR_DIM",
    "SPECIFIC_FORCE_AT_REST_G",
    "error_state_jacobians",
    "discretize",
    "gravity_measurement",
    "attitude_error",
    "AttitudeFilter",
    "RotatingImuData",
    "simulate_rotating_imu",
    "FilterRun",
    "run_filter",
]

ERROR_DIM = 6  # [δθ, δb_g]
SPECIFIC_FORCE_AT_REST_G = -GRAVITY_G  # f_G = a - g_G with a = 0: [0, 0, 9.81] m/s², "up"
SPECIFIC_FORCE_AT_REST_G.setflags(write=False)
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)
_DIAG = np.arange(ERROR_DIM)


def _positive(value: float, name: str, unit: str, allow_zero: bool = True) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound} ({unit}); got {value!r}")
    return float(value)


def error_state_jacobians(w_hat: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (F (6, 6), G (6, 6)) of dx~/dt = F x~ + G n for x~ = [δθ, δb_g] and n = [n_g, n_wg].

    Args:
        w_hat: (3,) bias-corrected angular rate ω = ω_m - b_g of I, in I, rad/s.

    The top-left blocks of the MSCKF's F and G (thesis Eqs. 34-35).

    >>> F, G = error_state_jacobians([0.0, 0.0, 1.0])
    >>> F[:3] + 0.0
    array([[ 0.,  1.,  0., -1.,  0.,  0.],
           [-1.,  0.,  0.,  0., -1.,  0.],
           [ 0.,  0.,  0.,  0.,  0., -1.]])
    """
    w = as_float_array(w_hat, "w_hat", (3,))
    if w.shape != (3,):
        raise ValueError(f"w_hat must have shape (3,); got {w.shape}")
    F = np.zeros((ERROR_DIM, ERROR_DIM))
    F[:3, :3] = -skew(w)  # dδθ/dt = -[ω x] δθ - δb_g - n_g
    F[:3, 3:] = -np.eye(3)
    G = np.zeros((ERROR_DIM, ERROR_DIM))
    G[:3, :3] = -np.eye(3)
    G[3:, 3:] = np.eye(3)  # dδb_g/dt = n_wg
    return F, G


def discretize(w_hat: ArrayLike, dt: float, gyro_noise_density: float,
               gyro_random_walk: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (Φ (6, 6), Q_d (6, 6)) over one step of ``dt`` seconds with ω held constant (Van Loan's method).

    Args:
        w_hat: (3,) bias-corrected angular rate in I, rad/s.
        dt: step length, s (> 0).
        gyro_noise_density: σ_g, rad/s/√Hz.
        gyro_random_walk: σ_wg, rad/s²/√Hz.

    exp([[-F, G Q_c G^T], [0, F^T]] Δt) = [[., B12], [0, B22]] gives Φ = B22^T and Q_d = Φ B12 (Van Loan 1978;
    the block form the MSCKF's discretisation is checked with). For ω = 0 each axis is the constant-velocity
    model: Q_d per axis is [[σ_g² Δt + σ_wg² Δt³/3, -σ_wg² Δt²/2], [-σ_wg² Δt²/2, σ_wg² Δt]].

    >>> Phi, Q_d = discretize([0.0, 0.0, 0.0], 0.1, 0.0, 1.0)
    >>> [round(float(v), 6) for v in (Phi[0, 3], Q_d[0, 0], Q_d[0, 3], Q_d[3, 3])]
    [-0.1, 0.000333, -0.005, 0.1]
    """
    dt = _positive(dt, "dt", "s", allow_zero=False)
    sigma_g = _positive(gyro_noise_density, "gyro_noise_density", "rad/s/√Hz")
    sigma_wg = _positive(gyro_random_walk, "gyro_random_walk", "rad/s²/√Hz")
    w = as_float_array(w_hat, "w_hat", (3,))
    if w.shape != (3,):
        raise ValueError(f"w_hat must have shape (3,); got {w.shape}")
    return _discretize_unchecked(w, dt, sigma_g, sigma_wg)


def _discretize_unchecked(w: NDArray[np.float64], dt: float, sigma_g: float,
                          sigma_wg: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`discretize` on validated inputs (the filter's inner loop)."""
    n = ERROR_DIM
    # block = [[-F, G Q_c G^T], [0, F^T]] with F = [[-[ω x], -I], [0, 0]] and G Q_c G^T = diag(σ_g² I, σ_wg² I)
    block = np.zeros((2 * n, 2 * n))
    block[:3, 3:6] = _EYE3  # -F: [[[ω x], I], [0, 0]]
    block[_DIAG, _DIAG + n] = (sigma_g**2, sigma_g**2, sigma_g**2, sigma_wg**2, sigma_wg**2, sigma_wg**2)
    block[9:12, 6:9] = -_EYE3  # F^T: [[-[ω x]^T, 0], [-I, 0]] = [[[ω x], 0], [-I, 0]]
    w_skew = skew_unchecked(w)
    block[:3, :3] = w_skew
    block[6:9, 6:9] = w_skew
    B = scipy.linalg.expm(block * dt)
    Phi = B[n:, n:].T  # Φ = B22^T
    Q_d = Phi @ B[:n, n:]  # Q_d = Φ B12
    return Phi, 0.5 * (Q_d + Q_d.T)


def gravity_measurement(q_GtoI: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (ẑ (3,), H (3, 6)): the predicted accelerometer reading at rest and its Jacobian in [δθ, δb_g].

    Args:
        q_GtoI: (4,) JPL quaternion of the estimate.

    ẑ = C(q) f_G with f_G = [0, 0, 9.81] m/s² (the specific force at rest), H = [[ẑ x], 0]: r = z - ẑ ≈ H x~ + n_a.

    >>> z_hat, H = gravity_measurement([0.0, 0.0, 0.0, 1.0])
    >>> z_hat.tolist(), (H[:, :3] + 0.0).round(2).tolist()
    ([0.0, 0.0, 9.81], [[0.0, -9.81, 0.0], [9.81, 0.0, 0.0], [0.0, 0.0, 0.0]])
    """
    q = as_float_array(q_GtoI, "q_GtoI", (4,))
    if q.shape != (4,):
        raise ValueError(f"q_GtoI must have shape (4,); got {q.shape}")
    z_hat = quat_to_rot(q) @ SPECIFIC_FORCE_AT_REST_G
    H = np.zeros((3, ERROR_DIM))
    H[:, :3] = skew(z_hat)  # -[δθ x] ẑ = [ẑ x] δθ
    return z_hat, H


def attitude_error(q_true: ArrayLike, q_est: ArrayLike) -> NDArray[np.float64]:
    """Return δθ (..., 3), the rotation vector of δq = q_true ⊗ q_est^-1 (so that q_true = δq ⊗ q_est), rad.

    Args:
        q_true, q_est: (..., 4) JPL quaternions (q_GtoI); leading dimensions broadcast.

    >>> attitude_error(quat_from_rotvec([0.0, 0.0, 0.1]), [0.0, 0.0, 0.0, 1.0]).round(6).tolist()
    [0.0, 0.0, 0.1]
    """
    return quat_to_rotvec(quat_multiply(q_true, quat_inverse(q_est)))


@dataclass
class AttitudeFilter:
    """The error-state filter: nominal ``q_GtoI`` and ``b_g``, error covariance ``P`` (6, 6), and its noise model.

    Attributes:
        q_GtoI: (4,) JPL quaternion of the estimate.
        b_g: (3,) gyroscope bias estimate, rad/s.
        P: (6, 6) covariance of [δθ, δb_g] (rad², rad²/s, rad²/s²).
        gyro_noise_density: σ_g, rad/s/√Hz.
        gyro_random_walk: σ_wg, rad/s²/√Hz.
        accel_sigma: σ_a, the accelerometer's noise std per axis and per sample, m/s².
        gate_probability: None (every reading is used) or the chi-square gate's probability, e.g. 0.99.

    ``predict(gyro, dt)`` and ``update(accel)`` follow filterpy's ``KalmanFilter`` (predict, then update), on the
    error state. Not thread-safe; each call replaces the attributes by new arrays (the caller's arrays are never
    modified).

    >>> kf = AttitudeFilter([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0], np.eye(6) * 1e-4, 1e-3, 1e-4, 0.05)
    >>> kf.predict([0.0, 0.0, 0.1], 0.01)
    >>> nis, accepted = kf.update([0.0, 0.0, 9.81])
    >>> accepted, bool(kf.P[0, 0] < 1e-4)
    (True, True)
    """

    q_GtoI: NDArray[np.float64]
    b_g: NDArray[np.float64]
    P: NDArray[np.float64]
    gyro_noise_density: float
    gyro_random_walk: float
    accel_sigma: float
    gate_probability: float | None = field(default=None)

    def __post_init__(self) -> None:
        q = as_float_array(self.q_GtoI, "q_GtoI", (4,))
        b = as_float_array(self.b_g, "b_g", (3,))
        P = as_float_array(self.P, "P", (ERROR_DIM, ERROR_DIM))
        if q.shape != (4,) or b.shape != (3,) or P.shape != (ERROR_DIM, ERROR_DIM):
            raise ValueError(f"q_GtoI, b_g, P must have shapes (4,), (3,), (6, 6); got {q.shape}, {b.shape}, "
                             f"{P.shape}")
        scale = max(1.0, float(np.abs(P).max()))
        if np.abs(P - P.T).max() > 1e-9 * scale or np.linalg.eigvalsh(0.5 * (P + P.T)).min() < -1e-12 * scale:
            raise ValueError("P must be a symmetric positive semi-definite (6, 6) covariance of [δθ, δb_g]")
        self.q_GtoI, self.b_g, self.P = quat_normalize(q), b.copy(), P.copy()
        self.gyro_noise_density = _positive(self.gyro_noise_density, "gyro_noise_density", "rad/s/√Hz")
        self.gyro_random_walk = _positive(self.gyro_random_walk, "gyro_random_walk", "rad/s²/√Hz")
        self.accel_sigma = _positive(self.accel_sigma, "accel_sigma", "m/s²", allow_zero=False)
        p = self.gate_probability
        if p is not None and not (isinstance(p, float) and 0.0 < p < 1.0):
            raise ValueError(f"gate_probability must be None (no gate) or a float in (0, 1); got {p!r}")

    def predict(self, gyro: ArrayLike, dt: float) -> None:
        """Propagate over ``dt`` seconds with the gyroscope reading ``gyro`` (3,) rad/s held over the step.

        q ← quat_from_rotvec(ω Δt) ⊗ q with ω = gyro - b_g (exact for a constant rate); b_g unchanged;
        P ← Φ P Φ^T + Q_d (thesis Eq. 38).
        """
        gyro = as_float_array(gyro, "gyro", (3,))
        if gyro.shape != (3,):
            raise ValueError(f"gyro must have shape (3,); got {gyro.shape}")
        dt = _positive(dt, "dt", "s", allow_zero=False)
        w_hat = gyro - self.b_g  # ω = ω_m - b_g
        Phi, Q_d = _discretize_unchecked(w_hat, dt, self.gyro_noise_density, self.gyro_random_walk)
        q = quat_multiply(quat_from_rotvec(w_hat * dt), self.q_GtoI)  # q ← δq(ω Δt) ⊗ q
        self.q_GtoI = q / np.linalg.norm(q)
        P = Phi @ self.P @ Phi.T + Q_d  # P = Φ P Φ^T + Q_d
        self.P = 0.5 * (P + P.T)

    def update(self, accel: ArrayLike) -> tuple[float, bool]:
        """Correct the state with an accelerometer reading ``accel`` (3,) m/s²; return (NIS, accepted).

        r = z - ẑ, S = H P H^T + σ_a² I, NIS = r^T S^-1 r (chi-square with 3 degrees of freedom when the filter is
        consistent). With a ``gate_probability`` a reading whose NIS exceeds chi2.ppf(gate_probability, 3) is
        rejected and the state left as it was; otherwise δx = K r with the Joseph-form P (thesis Eqs. 56-58), then
        q ← quat_from_rotvec(δθ) ⊗ q and b_g ← b_g + δb_g.
        """
        z = as_float_array(accel, "accel", (3,))
        if z.shape != (3,):
            raise ValueError(f"accel must have shape (3,); got {z.shape}")
        z_hat, H = gravity_measurement(self.q_GtoI)
        r = z - z_hat  # innovation y = z - h(x)
        noise_var = self.accel_sigma**2
        S = H @ self.P @ H.T + noise_var * np.eye(3)  # S = H P H^T + R
        nis = float(r @ np.linalg.solve(S, r))  # NIS = y^T S^-1 y
        if self.gate_probability is not None and nis > chi_square_threshold(3, self.gate_probability):
            return nis, False
        dx, self.P = kalman_update(self.P, H, r, noise_var)  # K = P H^T S^-1, δx = K r, Joseph-form P
        self.q_GtoI = quat_normalize(quat_multiply(quat_from_rotvec(dx[:3]), self.q_GtoI))  # q ← δq ⊗ q
        self.b_g = self.b_g + dx[3:]
        return nis, True


@dataclass(frozen=True)
class RotatingImuData:
    """A simulated IMU turning about its centre: truth and readings at the sample times.

    Attributes:
        t: (N,) sample times, s.
        q_GtoI: (N, 4) true attitude (JPL).
        b_g: (N, 3) true gyroscope bias, rad/s.
        w_I: (N, 3) true rate over [t_k, t_k+1), rad/s (the last one unused).
        gyro: (N, 3) readings w_I + b_g + n_g, rad/s.
        accel: (N, 3) readings C(q_GtoI) f_G + n_a, m/s² (no accelerometer bias).
        accel_sigma: per-sample accelerometer noise std, m/s².
    """

    t: NDArray[np.float64]
    q_GtoI: NDArray[np.float64]
    b_g: NDArray[np.float64]
    w_I: NDArray[np.float64]
    gyro: NDArray[np.float64]
    accel: NDArray[np.float64]
    accel_sigma: float


def simulate_rotating_imu(duration: float, rate_hz: float, noise: ImuNoiseParams, rng: np.random.Generator,
                          rate_amplitude: ArrayLike = (0.8, 0.6, 1.0),
                          rate_frequency: ArrayLike = (0.13, 0.21, 0.17)) -> RotatingImuData:
    """Return a seeded simulation of an IMU that turns about its own centre, starting level (q = identity).

    Args:
        duration: length, s (> 0).
        rate_hz: sample rate, Hz (> 0).
        noise: gyroscope densities (``gyro_noise_density``, ``gyro_random_walk``), initial bias spread
            (``gyro_bias_init_sigma``) and ``accel_noise_density``; the accelerometer bias is not simulated.
        rng: numpy Generator (draws, in order: initial bias, bias increments, gyro noise, accel noise).
        rate_amplitude: (3,) amplitude of each body-rate component, rad/s; (0, 0, w) turns about the vertical only.
        rate_frequency: (3,) frequency of each component, Hz: w_k = amplitude sin(2π f t_k + phase), phases
            (0.3, 1.1, 2.0) rad.

    The rate is held over each sample interval, q_k+1 = quat_from_rotvec(w_k Δt) ⊗ q_k, exactly as
    :meth:`AttitudeFilter.predict` integrates; the bias is a random walk of std σ_wg √Δt per step; the gyro noise
    has std σ_g √rate and the accelerometer's σ_a √rate per sample (as :func:`evio_lib.sim.imu.synthesize_imu`).

    >>> data = simulate_rotating_imu(1.0, 100.0, ImuNoiseParams(), np.random.default_rng(0))
    >>> data.t.shape, round(float(np.linalg.norm(data.accel[0])), 1)
    ((101,), 9.8)
    """
    duration = _positive(duration, "duration", "s", allow_zero=False)
    rate_hz = _positive(rate_hz, "rate_hz", "Hz", allow_zero=False)
    if not isinstance(noise, ImuNoiseParams):
        raise ValueError(f"noise must be an ImuNoiseParams; got {type(noise).__name__}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator (np.random.default_rng(seed)); got {type(rng).__name__}")
    amplitude = as_float_array(rate_amplitude, "rate_amplitude", (3,))
    frequency = as_float_array(rate_frequency, "rate_frequency", (3,))
    n = int(math.floor(duration * rate_hz + 1e-9)) + 1
    if n < 2:
        raise ValueError(f"duration * rate_hz must give >= 2 samples; got {duration:g} s at {rate_hz:g} Hz")
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    w = amplitude * np.sin(2.0 * np.pi * frequency * t[:, None] + np.array([0.3, 1.1, 2.0]))
    steps = quat_from_rotvec(w[:-1] * dt)  # δq of each interval
    q = np.empty((n, 4))
    q[0] = (0.0, 0.0, 0.0, 1.0)
    for k in range(n - 1):
        q[k + 1] = quat_multiply(steps[k], q[k])
    q = quat_normalize(q)
    b0 = rng.normal(0.0, noise.gyro_bias_init_sigma, 3)
    increments = noise.gyro_random_walk * math.sqrt(dt) * rng.standard_normal((n - 1, 3))
    b_g = b0 + np.concatenate([np.zeros((1, 3)), np.cumsum(increments, axis=0)])
    gyro = w + b_g + noise.gyro_noise_density * math.sqrt(rate_hz) * rng.standard_normal((n, 3))
    accel_sigma = noise.accel_noise_density * math.sqrt(rate_hz)
    accel = quat_to_rot(q) @ SPECIFIC_FORCE_AT_REST_G + accel_sigma * rng.standard_normal((n, 3))
    return RotatingImuData(t=t, q_GtoI=q, b_g=b_g, w_I=w, gyro=gyro, accel=accel, accel_sigma=accel_sigma)


@dataclass(frozen=True)
class FilterRun:
    """What :func:`run_filter` recorded after each update.

    Attributes:
        t: (M,) update times, s.
        q_GtoI: (M, 4) attitude estimates; b_g: (M, 3) bias estimates, rad/s; P: (M, 6, 6) covariances.
        errors: (M, 6) true minus estimated error state [δθ, δb_g] (rad, rad/s).
        nis: (M,) normalised innovation squared of each update (before it).
        accepted: (M,) whether the gate let the reading through (all True without a gate).
    """

    t: NDArray[np.float64]
    q_GtoI: NDArray[np.float64]
    b_g: NDArray[np.float64]
    P: NDArray[np.float64]
    errors: NDArray[np.float64]
    nis: NDArray[np.float64]
    accepted: NDArray[np.bool_]


def run_filter(kf: AttitudeFilter, data: RotatingImuData, update_every: int = 10) -> FilterRun:
    """Return the record of ``kf`` run over ``data``: a prediction per IMU interval, an update every few samples.

    Args:
        kf: the filter at ``data.t[0]`` (it is advanced in place).
        data: readings and truth (:func:`simulate_rotating_imu`).
        update_every: accelerometer updates at samples update_every, 2 update_every, ... (>= 1).

    The loop: ``kf.predict(gyro[k], Δt)`` for each interval, then ``kf.update(accel[k + 1])`` when k + 1 is a
    multiple of ``update_every``.
    """
    if isinstance(update_every, bool) or not isinstance(update_every, (int, np.integer)) or update_every < 1:
        raise ValueError(f"update_every must be an int >= 1; got {update_every!r}")
    rows: dict[str, list] = {name: [] for name in ("t", "q", "b", "P", "nis", "accepted")}
    for k in range(len(data.t) - 1):
        kf.predict(data.gyro[k], data.t[k + 1] - data.t[k])
        if (k + 1) % update_every == 0:
            nis, accepted = kf.update(data.accel[k + 1])
            for name, value in zip(rows, (data.t[k + 1], kf.q_GtoI, kf.b_g, kf.P, nis, accepted)):
                rows[name].append(value)
    if not rows["t"]:
        raise ValueError(f"data holds {len(data.t)} samples: too few for one update every {update_every}")
    t = np.array(rows["t"])
    q, b = np.array(rows["q"]), np.array(rows["b"])
    idx = np.rint((t - data.t[0]) / (data.t[1] - data.t[0])).astype(int)
    errors = np.concatenate([attitude_error(data.q_GtoI[idx], q), data.b_g[idx] - b], axis=1)
    return FilterRun(t=t, q_GtoI=q, b_g=b, P=np.array(rows["P"]), errors=errors, nis=np.array(rows["nis"]),
                     accepted=np.array(rows["accepted"], dtype=bool))
