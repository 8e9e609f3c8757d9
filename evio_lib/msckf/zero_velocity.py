"""Standing still: detect it from the IMU and the feature tracks, and tell the filter (zero-velocity update, ZUPT).

Why. While the platform stands still (a MAV on the ground before take-off, a hand-held camera put down) the MSCKF
learns nothing from its features: every camera clone sits at the same place, triangulation has no baseline
(``insufficient_baseline``, ``behind_camera``) and the update rejects them, while the IMU's noise and bias keep
integrating into velocity and position. OpenVINS (Geneva et al., ICRA 2020, "UpdaterZeroVelocity") and Ultimate SLAM
replace the visual update by a zero-velocity update there. This module does the same in three parts:

1. **Detection** (:class:`StandstillDetector`), per frame, all of:

   - *images*: the median displacement of the tracks seen in this frame and the previous one is below
     ``max_disparity_px`` (0.5 px, OpenVINS's EuRoC setting), with at least ``min_tracks`` shared tracks. This is
     what tells standing still from moving at a constant velocity, which the IMU cannot tell apart;
   - *IMU* over the last ``imu_window`` seconds (0.25 s): the gyro's mean minus the current gyro-bias estimate below
     ``max_gyro_rate`` (0.02 rad/s), the accelerometer's mean minus what a still IMU at the estimated attitude
     measures, |mean(a_m) - (-R̂_GtoI g_G + b̂_a)|, below ``max_accel_residual`` (0.3 m/s^2, about 1.7 degrees of
     tilt; a constant horizontal acceleration keeps |a_m| near |g| but not its direction), and the spread of
     the 50 ms block means below ``max_gyro_spread`` / ``max_accel_spread`` (the same vibration-robust test as the
     static initialisation, :func:`evio_lib.msckf.initialization.static_initialization`: a MAV's rotors shake its
     accelerometer by 1 m/s^2 per sample while it does not move). OpenVINS tests a chi-square of the raw IMU
     residuals with the noise inflated 10x instead; on the real EuRoC V1_01 start (rotors spinning) the raw
     per-sample spread is 0.1-1.3 m/s^2 against a white-noise floor of 0.002 m/s^2/sqrt(Hz), so a fixed inflation
     is a guess, while block means measure the motion content directly;
   - *estimate*: |v| of the filter below ``max_velocity`` (0.1 m/s, OpenVINS's ``zupt_max_velocity``), so a
     platform the filter believes to be moving needs the evidence of several frames first; this also keeps a
     far-away scene (aerial: features at 250 m move less than a pixel per frame at 20 m/s) from passing as still.

   With fewer than ``min_tracks`` shared tracks the image test cannot be made and the frame is not declared still.

2. **Measurement** (:func:`zero_velocity_measurement`), from the IMU samples since the last frame. At rest the true
   velocity is 0, the gyroscope measures only its bias and the accelerometer only gravity plus its bias::

       v_IinG            = 0                                   H_v = I                 (σ_v = velocity_sigma)
       mean(ω_m)         = b_g + n                             H_bg = I
       mean(a_m)         = -R_GtoI g_G + b_a + n               H_θ = -[R̂_GtoI g_G]x,  H_ba = I

   The accelerometer row follows from the JPL error R_GtoI = (I - [δθ]x) R̂_GtoI:
   -R_GtoI g_G = -R̂ g_G + [δθ]x R̂ g_G = -R̂ g_G - [R̂ g_G]x δθ. Residuals r = z - h(x̂); the noise of a window mean
   is the larger of the white-noise floor σ²/T (continuous density σ, window T) and the samples' own variance / N,
   times ``noise_multiplier``² (vibration is correlated over samples, so var/N is optimistic). Yaw and position do
   not enter (H has no position column and -[R̂ g]x R̂ g = 0): the update keeps the unobservable directions.

3. **Filter** (:meth:`evio_lib.msckf.filter.Msckf.zero_velocity_update`): propagate to the frame time, apply the
   9-row update without cloning the camera pose (no clone piles up at one place), chi-square gated at
   ``chi2_probability`` as a safety net; the frame's feature observations are not used.

>>> cfg = ZeroVelocityConfig()
>>> cfg.max_disparity_px, cfg.max_velocity
(0.5, 0.1)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import skew
from evio_lib.msckf.state import BA, BG, THETA, VEL, FilterState

__all__ = ["ZeroVelocityConfig", "StandstillDetector", "StillTest", "track_disparity", "imu_still_test",
           "zero_velocity_measurement"]


@dataclass(frozen=True)
class ZeroVelocityConfig:
    """Settings of the standstill detection and the zero-velocity update (module docstring; SI units).

    Attributes:
        enabled: detect standstill and apply zero-velocity updates (``run --no-zupt`` turns it off).
        max_disparity_px: largest median displacement of the shared tracks between two frames, pixels.
        min_tracks: fewest tracks shared by the two frames for the image test.
        imu_window: seconds of IMU tested before the frame.
        block: averaging block of the IMU spread test, s.
        max_gyro_rate: largest |mean(ω_m) - b̂_g|, rad/s.
        max_gyro_spread, max_accel_spread: largest spread of the block means, rad/s and m/s^2.
        max_accel_residual: largest |mean(a_m) - (-R̂_GtoI g_G + b̂_a)|, m/s^2.
        max_velocity: largest |v̂| of the filter, m/s.
        velocity_sigma: noise of the v = 0 measurement, m/s.
        noise_multiplier: inflation of the noise of the IMU means.
        chi2_probability: gate of the update (a failed gate means: not still after all).
    """

    enabled: bool = True
    max_disparity_px: float = 0.5
    min_tracks: int = 10
    imu_window: float = 0.25
    block: float = 0.05
    max_gyro_rate: float = 0.02
    max_gyro_spread: float = 0.03
    max_accel_spread: float = 0.25
    max_accel_residual: float = 0.3
    max_velocity: float = 0.1
    velocity_sigma: float = 0.01
    noise_multiplier: float = 3.0
    chi2_probability: float = 0.999

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ValueError(f"enabled must be True or False; got {self.enabled!r}")
        if isinstance(self.min_tracks, bool) or not isinstance(self.min_tracks, (int, np.integer)) \
                or self.min_tracks < 1:
            raise ValueError(f"min_tracks must be an integer >= 1; got {self.min_tracks!r}")
        for f in fields(self):
            if f.name in ("enabled", "min_tracks"):
                continue
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{f.name} must be a finite number > 0; got {value!r}")
        if not self.chi2_probability < 1.0:
            raise ValueError(f"chi2_probability must be in (0, 1); got {self.chi2_probability!r}")


class StillTest(NamedTuple):
    """One frame's standstill verdict and the figures behind it (NaN where a test could not be made)."""

    still: bool
    disparity_px: float
    shared_tracks: int
    gyro_rate: float
    gyro_spread: float
    accel_spread: float
    accel_residual: float
    speed: float


def track_disparity(ids_prev: ArrayLike, px_prev: ArrayLike, ids: ArrayLike, px: ArrayLike) -> tuple[float, int]:
    """Return (median displacement in pixels, number of shared tracks) between two frames' tracks.

    Args:
        ids_prev, ids: (K0,), (K,) integer track ids of the previous and the current frame.
        px_prev, px: (K0, 2), (K, 2) their pixel positions.

    NaN when no track is shared.

    >>> track_disparity([1, 2, 3], [[0, 0], [10, 10], [5, 5]], [2, 3, 4], [[10, 13], [5, 5], [0, 0]])
    (1.5, 2)
    """
    ids_prev, ids = np.asarray(ids_prev).reshape(-1), np.asarray(ids).reshape(-1)
    px_prev = np.asarray(px_prev, dtype=np.float64).reshape(-1, 2)
    px = np.asarray(px, dtype=np.float64).reshape(-1, 2)
    if px_prev.shape[0] != ids_prev.shape[0] or px.shape[0] != ids.shape[0]:
        raise ValueError(f"ids and pixels must match: ({ids_prev.shape[0]},) with ({px_prev.shape[0]}, 2) and "
                         f"({ids.shape[0]},) with ({px.shape[0]}, 2)")
    _, i0, i1 = np.intersect1d(ids_prev, ids, assume_unique=True, return_indices=True)
    if i0.shape[0] == 0:
        return float("nan"), 0
    return float(np.median(np.linalg.norm(px[i1] - px_prev[i0], axis=1))), int(i0.shape[0])


def _block_spread(t: NDArray[np.float64], x: NDArray[np.float64], block: float) -> float:
    """Return the norm over axes of the std of the ``block``-second means of x (M, 3)."""
    b = np.floor((t - t[0]) / block).astype(np.int64)
    counts = np.bincount(b)
    used = counts > 0
    means = np.stack([np.bincount(b, weights=x[:, i])[used] / counts[used] for i in range(3)], axis=1)
    return float(np.linalg.norm(means.std(axis=0))) if means.shape[0] >= 2 else 0.0


def imu_still_test(imu_t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, b_g: ArrayLike, b_a: ArrayLike,
                   R_GtoI: ArrayLike, gravity_G: ArrayLike, config: ZeroVelocityConfig
                   ) -> tuple[bool, float, float, float, float]:
    """Return (passed, gyro_rate, gyro_spread, accel_spread, accel_residual) of the IMU part of the test.

    Args:
        imu_t, gyro, accel: the IMU samples of the tested window (M,), (M, 3), (M, 3); fewer than 3 fail.
        b_g, b_a: (3,) current bias estimates; R_GtoI: (3, 3) current attitude; gravity_G: (3,) gravity in G.

    >>> t = np.arange(0.0, 0.25, 0.005)
    >>> ok, rate, *_ = imu_still_test(t, np.full((50, 3), 0.01), np.tile([0, 0, 9.81], (50, 1)), [0.01] * 3,
    ...                               np.zeros(3), np.eye(3), [0, 0, -9.81], ZeroVelocityConfig())
    >>> ok, round(rate, 6)
    (True, 0.0)
    """
    t = np.asarray(imu_t, dtype=np.float64)
    w = np.asarray(gyro, dtype=np.float64).reshape(-1, 3)
    a = np.asarray(accel, dtype=np.float64).reshape(-1, 3)
    if t.shape[0] < 3:
        return False, math.nan, math.nan, math.nan, math.nan
    rate = float(np.linalg.norm(w.mean(axis=0) - np.asarray(b_g, dtype=np.float64)))
    gyro_spread = _block_spread(t, w, config.block)
    accel_spread = _block_spread(t, a, config.block)
    expected = -np.asarray(R_GtoI, dtype=np.float64) @ np.asarray(gravity_G, dtype=np.float64) \
        + np.asarray(b_a, dtype=np.float64)  # a_m of a still IMU: -R_GtoI g_G + b_a
    accel_residual = float(np.linalg.norm(a.mean(axis=0) - expected))
    passed = (rate < config.max_gyro_rate and gyro_spread < config.max_gyro_spread
              and accel_spread < config.max_accel_spread and accel_residual < config.max_accel_residual)
    return passed, rate, gyro_spread, accel_spread, accel_residual


class StandstillDetector:
    """Per-frame standstill test (module docstring, part 1); remembers the previous frame's tracks.

    >>> det = StandstillDetector(ZeroVelocityConfig(min_tracks=2))
    >>> t = np.arange(0.0, 0.3, 0.005); w = np.zeros((60, 3)); a = np.tile([0.0, 0.0, 9.81], (60, 1))
    >>> from evio_lib.msckf.state import ImuState
    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), 0.0)
    >>> det.test(0.25, [1, 2], [[0, 0], [5, 5]], t, w, a, imu, [0, 0, -9.81]).still  # no previous frame
    False
    >>> det.test(0.30, [1, 2], [[0.1, 0], [5, 5.1]], t, w, a, imu, [0, 0, -9.81]).still
    True
    """

    def __init__(self, config: ZeroVelocityConfig | None = None) -> None:
        self.config = ZeroVelocityConfig() if config is None else config
        self._prev: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None

    def test(self, t: float, ids: ArrayLike, pixels: ArrayLike, imu_t: ArrayLike, gyro: ArrayLike, accel: ArrayLike,
             imu: Any, gravity_G: ArrayLike) -> StillTest:
        """Return the verdict for the frame at time ``t`` with tracks (ids, pixels) and remember them.

        Args:
            t: frame time, s; ids (K,), pixels (K, 2): the frame's tracks.
            imu_t, gyro, accel: IMU samples (any span covering [t - imu_window, t]).
            imu: the filter's current IMU estimate (an :class:`~evio_lib.msckf.state.ImuState`: attitude, biases,
                velocity); gravity_G: (3,) gravity in G.
        """
        cfg = self.config
        ids = np.asarray(ids).reshape(-1)
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        if self._prev is None:
            disparity, shared = math.nan, 0
        else:
            disparity, shared = track_disparity(self._prev[0], self._prev[1], ids, pixels)
        self._prev = (ids.copy(), pixels.copy())
        imu_t = np.asarray(imu_t, dtype=np.float64)
        lo, hi = np.searchsorted(imu_t, [t - cfg.imu_window, t], side="right")
        imu_ok, rate, gyro_spread, accel_spread, accel_residual = imu_still_test(
            imu_t[lo:hi], np.asarray(gyro)[lo:hi], np.asarray(accel)[lo:hi], imu.b_g, imu.b_a, imu.R_GtoI, gravity_G,
            cfg)
        speed = float(np.linalg.norm(imu.v_IinG))
        still = bool(cfg.enabled and imu_ok and shared >= cfg.min_tracks and disparity < cfg.max_disparity_px
                     and speed < cfg.max_velocity)
        return StillTest(still, disparity, shared, rate, gyro_spread, accel_spread, accel_residual, speed)

    def reset(self) -> None:
        """Forget the previous frame (e.g. after a frame without tracks)."""
        self._prev = None


def zero_velocity_measurement(state: FilterState, imu_t: ArrayLike, gyro: ArrayLike, accel: ArrayLike,
                              gravity_G: ArrayLike, gyro_noise_density: float, accel_noise_density: float,
                              config: ZeroVelocityConfig) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (H (9, n), r (9,)) of the zero-velocity measurement, whitened (unit noise), n = ``state.dim``.

    Rows: velocity, gyro mean, accelerometer mean (module docstring, part 2); each row divided by its noise σ.

    Args:
        state: the filter state at the frame time.
        imu_t, gyro, accel: the IMU samples of the still window (M >= 1).
        gravity_G: (3,) gravity in G; gyro_noise_density, accel_noise_density: continuous white-noise densities.

    >>> from evio_lib.msckf.state import ImuState
    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.array([0.02, 0.0, 0.0]), timestamp=0.0)
    >>> s = FilterState.initial(imu, np.eye(3), np.zeros(3), np.eye(15))
    >>> t = np.arange(0.0, 0.05, 0.005)
    >>> H, r = zero_velocity_measurement(s, t, np.zeros((10, 3)), np.tile([0, 0, 9.81], (10, 1)), [0, 0, -9.81],
    ...                                  1e-4, 2e-3, ZeroVelocityConfig())
    >>> H.shape, round(float(r[0]) * 0.01, 6), bool(np.abs(r[3:]).max() < 1e-9)     # r_v = -v / σ_v
    ((9, 15), -0.02, True)
    """
    t = np.asarray(imu_t, dtype=np.float64).reshape(-1)
    w = np.asarray(gyro, dtype=np.float64).reshape(-1, 3)
    a = np.asarray(accel, dtype=np.float64).reshape(-1, 3)
    if t.shape[0] < 1 or w.shape[0] != t.shape[0] or a.shape[0] != t.shape[0]:
        raise ValueError(f"imu_t (M,), gyro (M, 3) and accel (M, 3) with M >= 1 are needed; got {t.shape}, "
                         f"{w.shape}, {a.shape}")
    imu = state.imu
    g = np.asarray(gravity_G, dtype=np.float64)
    M = t.shape[0]
    span = max(float(t[-1] - t[0]), 1e-3) * (M / max(M - 1, 1))  # T of M samples
    k = config.noise_multiplier

    def mean_sigma(x: NDArray[np.float64], density: float) -> NDArray[np.float64]:
        sample_var = x.var(axis=0) / M if M > 1 else np.zeros(3)
        return k * np.sqrt(np.maximum(sample_var, density ** 2 / span))  # σ of a window mean, per axis

    R_GtoI = imu.R_GtoI
    Rg = R_GtoI @ g
    H = np.zeros((9, state.dim))
    r = np.empty(9)
    H[0:3, VEL] = np.eye(3)
    r[0:3] = -imu.v_IinG  # z = 0
    sig = np.full(3, config.velocity_sigma)
    H[3:6, BG] = np.eye(3)
    r[3:6] = w.mean(axis=0) - imu.b_g
    sig_w = mean_sigma(w, gyro_noise_density)
    H[6:9, THETA] = -skew(Rg)
    H[6:9, BA] = np.eye(3)
    r[6:9] = a.mean(axis=0) - (-Rg + imu.b_a)
    sig_a = mean_sigma(a, accel_noise_density)
    sigma = np.concatenate([sig, sig_w, sig_a])
    return H / sigma[:, None], r / sigma
