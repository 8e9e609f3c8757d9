"""Synthetic IMU measurements from a ground-truth trajectory, and a reference RK4 strapdown integrator.

Measurement model (thesis §3.3.4, Eq. 31; Kalibr/EuRoC noise conventions)::

    gyro_k  = w_I(t_k) + b_g(t_k) + n_g,k                      n_g,k ~ N(0, (σ_g sqrt(rate))^2)
    accel_k = R_GtoI(t_k) (a_IinG(t_k) - g_G) + b_a(t_k) + n_a,k   n_a,k ~ N(0, (σ_a sqrt(rate))^2)
    b(t_k+1) = b(t_k) + σ_b sqrt(Δt) ξ,  ξ ~ N(0, I)           (bias random walk)

where σ_g, σ_a are the continuous white-noise densities and σ_b the bias random-walk densities. Optionally the
readings saturate at the sensor's full scale, per axis, like a real MEMS IMU's ADC (``gyro_full_scale``,
``accel_full_scale`` of :func:`synthesize_imu`; typical ranges ``MEMS_GYRO_FULL_SCALE`` ±2000 deg/s and
``MEMS_ACCEL_FULL_SCALE`` ±16 g, the defaults of ``MsckfConfig``).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import omega_matrix, quat_to_rot, rot_to_quat
from evio_lib.sim.trajectory import Trajectory

__all__ = [
    "GRAVITY_G", "MEMS_ACCEL_FULL_SCALE", "MEMS_GYRO_FULL_SCALE", "ImuNoiseParams", "ImuData", "synthesize_imu",
    "integrate_imu_rk4",
]

GRAVITY_G = np.array([0.0, 0.0, -9.81])  # m/s^2, gravity in the world frame G (z up)
GRAVITY_G.setflags(write=False)
MEMS_ACCEL_FULL_SCALE = 16.0 * 9.80665  # m/s^2: ±16 g, the largest range of a typical MEMS accelerometer
MEMS_GYRO_FULL_SCALE = math.radians(2000.0)  # rad/s: ±2000 deg/s, the largest range of a typical MEMS gyroscope


@dataclass(frozen=True)
class ImuNoiseParams:
    """Continuous-time IMU noise densities (Kalibr / EuRoC convention) and the spread of the initial biases.

    Defaults are for an InvenSense MPU-6150 class MEMS IMU (the IMU inside the DAVIS240C):
    gyro noise density 0.005 deg/s/sqrt(Hz) = 8.73e-5 rad/s/sqrt(Hz) and accelerometer noise density
    400 ug/sqrt(Hz) = 3.92e-3 m/s^2/sqrt(Hz) (MPU-6150 product specification, rate noise spectral density and
    noise power spectral density). The datasheet gives no bias random walk; the defaults assume twice the
    Kalibr values of the EuRoC ADIS16448 (1.9393e-5 rad/s^2/sqrt(Hz), 3.0e-3 m/s^3/sqrt(Hz)). Initial bias
    spreads match the magnitude of the biases estimated in thesis §4.4 (gyro ~0.05 rad/s, accel ~0.1-0.3 m/s^2).

    Attributes:
        gyro_noise_density: rad/s/sqrt(Hz).
        accel_noise_density: m/s^2/sqrt(Hz).
        gyro_random_walk: rad/s^2/sqrt(Hz).
        accel_random_walk: m/s^3/sqrt(Hz).
        gyro_bias_init_sigma: rad/s, std of each component of the initial gyro bias.
        accel_bias_init_sigma: m/s^2, std of each component of the initial accelerometer bias.

    >>> p = ImuNoiseParams()
    >>> round(float(p.gyro_noise_density * np.sqrt(1000.0)), 5)   # per-sample gyro noise std at 1 kHz, rad/s
    0.00276
    """

    gyro_noise_density: float = 8.73e-5
    accel_noise_density: float = 3.92e-3
    gyro_random_walk: float = 3.9e-5
    accel_random_walk: float = 6.0e-3
    gyro_bias_init_sigma: float = 0.03
    accel_bias_init_sigma: float = 0.15

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or not np.isfinite(value) or value < 0:
                raise ValueError(f"{f.name} must be a finite number >= 0; got {value!r}")
            object.__setattr__(self, f.name, float(value))

    @classmethod
    def noise_free(cls) -> "ImuNoiseParams":
        """Return parameters with every density and bias spread zero (perfect IMU)."""
        return cls(**{f.name: 0.0 for f in fields(cls)})

    @property
    def is_noise_free(self) -> bool:
        """Return True when every parameter is zero (no random draw is needed)."""
        return all(getattr(self, f.name) == 0.0 for f in fields(self))

    def to_dict(self) -> dict[str, float]:
        """Return a JSON-able dict of the six parameters."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "ImuNoiseParams":
        """Return parameters from a dict made by ``to_dict`` (missing keys keep their defaults)."""
        names = {f.name for f in fields(cls)}
        if not isinstance(data, dict) or not set(data) <= names:
            extra = sorted(set(data) - names) if isinstance(data, dict) else type(data).__name__
            raise ValueError(f"data must be a dict with keys among {sorted(names)}; got unexpected {extra}")
        return cls(**data)


def _as_n3(x: ArrayLike, name: str, n: int) -> NDArray[np.float64]:
    arr = np.array(x, dtype=np.float64)
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape (N, 3) with N = {n}; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ImuData:
    """IMU samples with the true biases used to make them.

    Attributes:
        t: (N,) strictly increasing sample times, s.
        gyro: (N, 3) measured angular velocity of I in I, rad/s.
        accel: (N, 3) measured specific force R_GtoI (a_IinG - g_G) in I, m/s^2.
        bias_gyro: (N, 3) true gyro bias at each sample, rad/s.
        bias_accel: (N, 3) true accelerometer bias at each sample, m/s^2.
    """

    t: NDArray[np.float64]
    gyro: NDArray[np.float64]
    accel: NDArray[np.float64]
    bias_gyro: NDArray[np.float64]
    bias_accel: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.array(self.t, dtype=np.float64)
        if t.ndim != 1 or t.shape[0] < 2:
            raise ValueError(f"t must have shape (N,) with N >= 2; got {t.shape}")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise ValueError("t must be finite and strictly increasing")
        t.setflags(write=False)
        object.__setattr__(self, "t", t)
        for name in ("gyro", "accel", "bias_gyro", "bias_accel"):
            object.__setattr__(self, name, _as_n3(getattr(self, name), name, t.shape[0]))

    def __len__(self) -> int:
        return int(self.t.shape[0])


def _check_gravity(gravity_G: ArrayLike) -> NDArray[np.float64]:
    g = np.asarray(gravity_G, dtype=np.float64)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ValueError(f"gravity_G must be a finite vector of shape (3,); got shape {g.shape}")
    return g


def synthesize_imu(
    trajectory: Trajectory,
    rate_hz: float = 1000.0,
    noise: ImuNoiseParams | None = ImuNoiseParams(),
    rng: np.random.Generator | int | None = None,
    t_start: float | None = None,
    t_end: float | None = None,
    gravity_G: ArrayLike = GRAVITY_G,
    gyro_full_scale: float | None = None,
    accel_full_scale: float | None = None,
) -> ImuData:
    """Return IMU samples (ImuData) at ``rate_hz`` measured along ``trajectory``, with optional noise and biases.

    Args:
        trajectory: ground truth (evaluated at t_k = t_start + k / rate_hz, t_k <= t_end).
        rate_hz: sample rate, Hz (> 0).
        noise: noise parameters; None or ``ImuNoiseParams.noise_free()`` gives perfect measurements (zero biases).
        rng: numpy Generator or integer seed; required unless the noise is zero.
        t_start, t_end: sample window, s (default: the trajectory's whole span).
        gravity_G: (3,) gravity in G, m/s^2.
        gyro_full_scale, accel_full_scale: measurement range per axis (rad/s, m/s^2; > 0), e.g.
            ``MEMS_GYRO_FULL_SCALE``; readings (noise and bias included) are clipped to ±full scale, as a saturating
            sensor does. None (default): unlimited.

    Model (thesis Eq. 31): gyro = w_I + b_g + n_g; accel = R_GtoI (a_IinG - g_G) + b_a + n_a, white noise with
    std density * sqrt(rate_hz), biases drawn N(0, init_sigma^2) then random walks with per-sample increment std
    random_walk * sqrt(Δt). Random draws, in order: initial b_g, b_a, then b_g and b_a increments, then n_g, n_a.

    >>> from evio_lib.sim.trajectory import aerial_like
    >>> imu = synthesize_imu(aerial_like(turbulence=0.0), rate_hz=200.0, noise=None, t_end=1.0)
    >>> print(len(imu), round(float(np.linalg.norm(imu.accel[0])), 2))    # level flight: |specific force| = g
    201 9.81
    """
    if not isinstance(trajectory, Trajectory):
        raise ValueError(f"trajectory must be a Trajectory; got {type(trajectory).__name__}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a finite rate > 0 Hz; got {rate_hz!r}")
    t0 = trajectory.t_start if t_start is None else float(t_start)
    t1 = trajectory.t_end if t_end is None else float(t_end)
    if not (trajectory.t_start <= t0 < t1 <= trajectory.t_end):
        raise ValueError(
            f"t_start, t_end must satisfy {trajectory.t_start:g} <= t_start < t_end <= {trajectory.t_end:g}; "
            f"got t_start={t0:g}, t_end={t1:g}"
        )
    n = int(math.floor((t1 - t0) * rate_hz + 1e-9)) + 1
    if n < 2:
        raise ValueError(f"the window [t_start, t_end] = [{t0:g}, {t1:g}] s must hold >= 2 samples at {rate_hz:g} Hz")
    g_G = _check_gravity(gravity_G)
    for name, value in (("gyro_full_scale", gyro_full_scale), ("accel_full_scale", accel_full_scale)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float, np.integer,
                                                                                    np.floating))
                                  or math.isnan(value) or value <= 0):
            raise ValueError(f"{name} must be None or a number > 0 (the range per axis); got {value!r}")
    noise = ImuNoiseParams.noise_free() if noise is None else noise
    if not isinstance(noise, ImuNoiseParams):
        raise ValueError(f"noise must be an ImuNoiseParams or None; got {type(noise).__name__}")

    t = t0 + np.arange(n) / rate_hz  # t_k = t_start + k / rate
    truth = trajectory.evaluate(t)
    gyro = truth.w_I.copy()  # w_I
    # accel = R_GtoI (a_IinG - g_G) = R_ItoG^T (a - g); row-wise: sum_j R[n, j, i] f[n, j]
    accel = np.einsum("nji,nj->ni", truth.R_ItoG, truth.a_IinG - g_G)
    bias_g = np.zeros((n, 3))
    bias_a = np.zeros((n, 3))
    if not noise.is_noise_free:
        if rng is None:
            raise ValueError("rng must be a numpy Generator or an int seed when noise is not noise-free; got None")
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        dt = np.diff(t)[:, None]
        bg0 = gen.normal(0.0, noise.gyro_bias_init_sigma, 3)
        ba0 = gen.normal(0.0, noise.accel_bias_init_sigma, 3)
        # b_{k+1} = b_k + random_walk sqrt(Δt_k) ξ_k
        dbg = noise.gyro_random_walk * np.sqrt(dt) * gen.standard_normal((n - 1, 3))
        dba = noise.accel_random_walk * np.sqrt(dt) * gen.standard_normal((n - 1, 3))
        bias_g = bg0 + np.concatenate([np.zeros((1, 3)), np.cumsum(dbg, axis=0)])
        bias_a = ba0 + np.concatenate([np.zeros((1, 3)), np.cumsum(dba, axis=0)])
        # discrete white noise std = density sqrt(rate)
        gyro += bias_g + noise.gyro_noise_density * math.sqrt(rate_hz) * gen.standard_normal((n, 3))
        accel += bias_a + noise.accel_noise_density * math.sqrt(rate_hz) * gen.standard_normal((n, 3))
    if gyro_full_scale is not None:  # the sensor saturates: reading = clip(signal, -range, +range) per axis
        np.clip(gyro, -gyro_full_scale, gyro_full_scale, out=gyro)
    if accel_full_scale is not None:
        np.clip(accel, -accel_full_scale, accel_full_scale, out=accel)
    return ImuData(t=t, gyro=gyro, accel=accel, bias_gyro=bias_g, bias_accel=bias_a)


def _rot_GtoI_homogeneous(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return C(q) (..., 3, 3) = (qw^2 - qv.qv) I - 2 qw [qv x] + 2 qv qv^T, without normalising q.

    Equal to the JPL matrix (2 qw^2 - 1) I - ... for unit q, and a smooth (quadratic) function of q elsewhere, so
    RK4 stage quaternions (off the unit sphere by O(h^2)) can be used without breaking 4th-order accuracy.
    """
    qv, qw = q[..., :3], q[..., 3]
    out = (qw**2 - np.sum(qv * qv, axis=-1))[..., None, None] * np.eye(3)
    out = out + 2.0 * qv[..., :, None] * qv[..., None, :]
    cross = np.zeros(q.shape[:-1] + (3, 3))
    # [qv x] = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
    cross[..., 0, 1], cross[..., 0, 2], cross[..., 1, 2] = -qv[..., 2], qv[..., 1], -qv[..., 0]
    cross = cross - np.swapaxes(cross, -1, -2)
    return out - 2.0 * qw[..., None, None] * cross


def _cubic_midpoints(s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return (N-1, 3): uniformly sampled signal s (N, 3) at the interval midpoints, by 4-point cubic interpolation.

    Interior: s_k+½ = (-s_k-1 + 9 s_k + 9 s_k+1 - s_k+2) / 16; first / last interval use the one-sided stencils
    (5 s_0 + 15 s_1 - 5 s_2 + s_3) / 16 and its mirror image (Lagrange weights at x = 1/2 and 5/2).
    """
    mid = np.empty((s.shape[0] - 1, s.shape[1]))
    mid[1:-1] = (-s[:-3] + 9.0 * s[1:-2] + 9.0 * s[2:-1] - s[3:]) / 16.0
    mid[0] = (5.0 * s[0] + 15.0 * s[1] - 5.0 * s[2] + s[3]) / 16.0
    mid[-1] = (s[-4] - 5.0 * s[-3] + 15.0 * s[-2] + 5.0 * s[-1]) / 16.0
    return mid


def integrate_imu_rk4(
    imu: ImuData,
    R_ItoG0: ArrayLike,
    p_IinG0: ArrayLike,
    v_IinG0: ArrayLike,
    gravity_G: ArrayLike = GRAVITY_G,
    use_true_bias: bool = True,
    midpoint: str = "linear",
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Return (R_ItoG (N,3,3), p_IinG (N,3), v_IinG (N,3)) at imu.t: RK4 strapdown integration from imu.t[0].

    Args:
        imu: IMU samples (gyro in rad/s, accel = specific force in m/s^2, both in I).
        R_ItoG0: (3, 3) initial orientation; p_IinG0, v_IinG0: (3,) initial position (m) and velocity (m/s) in G.
        gravity_G: (3,) gravity in G.
        use_true_bias: subtract imu.bias_gyro / imu.bias_accel (the true biases) before integrating.
        midpoint: how stages 2-3 get the signal at t_k + h/2: "linear" (mean of samples k and k+1; the filter's
            choice, global error O(h^2)) or "cubic" (4-sample cubic through k-1..k+2, uniform sampling and N >= 4
            required, global error O(h^4); isolates the RK4 error).

    Continuous dynamics (thesis Eq. 31-32), JPL q = q_GtoI::

        dq/dt = ½ Ω(ω) q,   dv_IinG/dt = R_ItoG(q) a + g_G,   dp_IinG/dt = v_IinG,   ω = gyro - b_g, a = accel - b_a

    Classic RK4 over each interval [t_k, t_k+1] (h = t_k+1 - t_k) with the signal linearly interpolated: stage 1 uses
    sample k, stages 2 and 3 the midpoint (mean of samples k and k+1), stage 4 sample k+1. The quaternion ODE is
    linear, so its RK4 step is q_k+1 = Φ_k q_k with
    M1 = A_k, M2 = A_m (I + h/2 M1), M3 = A_m (I + h/2 M2), M4 = A_k+1 (I + h M3),
    Φ_k = I + h/6 (M1 + 2 M2 + 2 M3 + M4) (A = ½ Ω), renormalised every step. The stage quaternions S1 = q_k,
    S2 = (I + h/2 M1) q_k, S3 = (I + h/2 M2) q_k, S4 = (I + h M3) q_k give the stage accelerations
    f_j = C(S_j)^T a_j + g_G (a_j: sample k, midpoint, midpoint, sample k+1), and then
    v_k+1 = v_k + h/6 (f1 + 2 f2 + 2 f3 + f4) and p_k+1 = p_k + h v_k + h²/6 (f1 + f2 + f3).
    Only the q recursion is a loop (one 4x4 product per sample); the rest is vectorised.

    >>> from evio_lib.sim.trajectory import aerial_like
    >>> traj = aerial_like()
    >>> imu = synthesize_imu(traj, rate_hz=200.0, noise=None, t_end=2.0)
    >>> s0 = traj.evaluate(0.0)
    >>> R, p, v = integrate_imu_rk4(imu, s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0])
    >>> bool(np.abs(p[-1] - traj.evaluate(2.0).p_IinG[0]).max() < 1e-4)
    True
    """
    if not isinstance(imu, ImuData):
        raise ValueError(f"imu must be an ImuData; got {type(imu).__name__}")
    R0 = np.asarray(R_ItoG0, dtype=np.float64)
    if R0.shape != (3, 3):
        raise ValueError(f"R_ItoG0 must have shape (3, 3); got {R0.shape}")
    p0 = np.asarray(p_IinG0, dtype=np.float64)
    v0 = np.asarray(v_IinG0, dtype=np.float64)
    for name, arr in (("p_IinG0", p0), ("v_IinG0", v0)):
        if arr.shape != (3,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be a finite vector of shape (3,); got shape {arr.shape}")
    g_G = _check_gravity(gravity_G)
    q0 = rot_to_quat(R0.T)  # q_GtoI (raises ValueError if R_ItoG0 is not a rotation)

    w = imu.gyro - imu.bias_gyro if use_true_bias else imu.gyro  # ω = gyro - b_g
    a = imu.accel - imu.bias_accel if use_true_bias else imu.accel  # a = accel - b_a
    h = np.diff(imu.t)[:, None, None]  # (N-1, 1, 1)
    if midpoint == "linear":
        w_mid, a_mid = 0.5 * (w[:-1] + w[1:]), 0.5 * (a[:-1] + a[1:])  # s_mid = (s_k + s_k+1) / 2
    elif midpoint == "cubic":
        if len(imu) < 4 or not np.allclose(h, h[0], rtol=1e-6, atol=0.0):
            raise ValueError(f"midpoint='cubic' needs >= 4 uniformly spaced samples; got {len(imu)} samples")
        w_mid, a_mid = _cubic_midpoints(w), _cubic_midpoints(a)
    else:
        raise ValueError(f"midpoint must be 'linear' or 'cubic'; got {midpoint!r}")
    eye = np.eye(4)
    A = 0.5 * omega_matrix(w)  # (N, 4, 4): ½ Ω(ω_k)
    A_k, A_k1 = A[:-1], A[1:]
    A_m = 0.5 * omega_matrix(w_mid)  # ½ Ω(ω_mid)
    M1 = A_k
    M2 = A_m @ (eye + 0.5 * h * M1)
    M3 = A_m @ (eye + 0.5 * h * M2)
    M4 = A_k1 @ (eye + h * M3)
    Phi = eye + h / 6.0 * (M1 + 2.0 * M2 + 2.0 * M3 + M4)  # q_k+1 = Φ_k q_k

    n = len(imu)
    q = np.empty((n, 4))
    q[0] = q0
    qk = q0.copy()
    for k in range(n - 1):  # sequential by nature: one 4x4 mat-vec and a renormalisation per sample
        qk = Phi[k] @ qk
        qk /= math.sqrt(qk @ qk)
        q[k + 1] = qk

    # stage quaternions and stage accelerations f_j = C(S_j)^T a_j + g
    qs = q[:-1, :, None]
    stages = [q[:-1]] + [((eye + c * h * M) @ qs)[..., 0] for c, M in ((0.5, M1), (0.5, M2), (1.0, M3))]
    acc = [a[:-1], a_mid, a_mid, a[1:]]
    f = [np.einsum("nji,nj->ni", _rot_GtoI_homogeneous(S), a_j) + g_G for S, a_j in zip(stages, acc)]
    h2 = h[:, :, 0]
    dv = h2 / 6.0 * (f[0] + 2.0 * f[1] + 2.0 * f[2] + f[3])  # v_k+1 - v_k
    v = v0 + np.concatenate([np.zeros((1, 3)), np.cumsum(dv, axis=0)])
    dp = h2 * v[:-1] + h2**2 / 6.0 * (f[0] + f[1] + f[2])  # p_k+1 - p_k
    p = p0 + np.concatenate([np.zeros((1, 3)), np.cumsum(dp, axis=0)])
    R_ItoG = np.swapaxes(quat_to_rot(q), -1, -2)  # R_ItoG = C(q_GtoI)^T
    return R_ItoG, p, v
