"""Grayscale "active pixel sensor" (APS) frames of a DAVIS: motion blur, noise, limited dynamic range, 8 bits.

A DAVIS reads intensity frames from the same pixels that emit events. The frame model here is::

    E(u)  = 1/T  integral over [t_mid - T/2, t_mid + T/2] of I(u, t) dt     exposure (motion blur), midpoint rule
    S     = gain E                                                             signal, linear units
    S'    = S + sqrt(shot_noise_scale max(S, 0) + read_noise_sigma^2) N(0, 1) shot (Poisson-like) + read noise
    V     = clip(S', 0, clip) / clip                                           saturation (dynamic range)
    frame = round(255 V^gamma)                                                 output encoding, uint8

``shot_noise_scale`` is the inverse of the full-well capacity in electrons (5e-5 ~ 20 000 e-), so the shot-noise
variance of a pixel equals its signal divided by that capacity. The integral is approximated by the average of
``n`` renders at the midpoints of ``n`` equal sub-intervals of the exposure; ``n`` is chosen automatically so
that the image moves by at most ~0.5 pixel between sub-renders (measured from the scene's own 3-D points).

The default noise (read noise 0.001, shot-noise scale 5e-5) is matched to real DAVIS240C frames: Immerkaer's
estimator over the flattest half of each frame (``bench/aps_realism.py``) gives about the same noise on the simulated
boxes_like frames with these values as on the APS frames of ECD slider_depth (the numbers, and the estimator's floor
from texture: docs/results/pipeline.md, "The simulated APS frames against real ones"). The earlier values (read noise
0.01, shot-noise scale 0.003) gave several times the real frames' noise (CHANGELOG.md, where the change is dated).
The exposure (10 ms) could not be checked: the real slider moves too slowly for its blur to be measured.

Reference: thesis §2.2 (DAVIS: events and APS frames from the same pixel array); G. Gallego et al.,
"Event-based vision: a survey", TPAMI 2020 (APS frames, motion blur, dynamic range).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from evio_lib.sim.scene import Scene

__all__ = [
    "ApsParams",
    "PoseFunction",
    "exposure_sample_times",
    "choose_n_subframes",
    "aps_exposure",
    "aps_sensor_response",
    "render_aps_frame",
    "render_aps_frames",
]

PoseFunction = Callable[[np.ndarray], "tuple[np.ndarray, np.ndarray]"]
"""``pose_at(times (K,)) -> (R_CtoG (K, 3, 3), p_CinG (K, 3))``: the camera pose at the given times."""


@dataclass(frozen=True)
class ApsParams:
    """Settings of the simulated APS (grayscale) camera.

    Args:
        exposure_s: exposure time T in seconds (> 0).
        n_subframes: renders averaged over the exposure; 0 = automatic (image motion between renders below
            ``max_motion_px``, at most ``max_subframes``).
        gain: multiplies the linear exposure (> 0); larger gains saturate bright regions.
        read_noise_sigma: standard deviation of the additive read noise, in linear [0, 1] units (>= 0).
        shot_noise_scale: shot-noise variance per unit signal, i.e. 1 / full-well electrons (>= 0).
        gamma: output encoding exponent (> 0); 1/2.2 mimics a display-referred camera output.
        clip: linear signal that maps to 255 (> 0); brighter pixels saturate.
        max_subframes: cap of the automatic choice (>= 1).
        max_motion_px: target image motion between sub-renders of the automatic choice (> 0).

    >>> ApsParams(exposure_s=0.005).gamma == 1 / 2.2
    True
    """

    exposure_s: float = 0.01
    n_subframes: int = 0
    gain: float = 1.0
    read_noise_sigma: float = 0.001
    shot_noise_scale: float = 5e-5
    gamma: float = 1.0 / 2.2
    clip: float = 1.0
    max_subframes: int = 64
    max_motion_px: float = 0.5

    def __post_init__(self) -> None:
        positive = ("exposure_s", "gain", "gamma", "clip", "max_motion_px")
        non_negative = ("read_noise_sigma", "shot_noise_scale")
        for name in positive + non_negative:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not np.isfinite(value) or value < 0 or (name in positive and value == 0):
                kind = "positive" if name in positive else "non-negative"
                raise ValueError(f"{name} must be a finite {kind} number; got {value!r}")
            object.__setattr__(self, name, float(value))
        for name, low in (("n_subframes", 0), ("max_subframes", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f"{name} must be an int >= {low}; got {value!r}")
            object.__setattr__(self, name, int(value))

    @property
    def noiseless(self) -> bool:
        """Return True when both noise terms are zero."""
        return self.read_noise_sigma == 0.0 and self.shot_noise_scale == 0.0


def _as_rng(rng: np.random.Generator | int | None, params: ApsParams) -> np.random.Generator | None:
    """Return a Generator from ``rng`` (a Generator or an int seed); None is accepted only without noise."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None:
        if params.noiseless:
            return None
        raise ValueError("rng must be a numpy.random.Generator or an int seed when the noise is on; got None")
    if isinstance(rng, (bool, np.bool_)) or not isinstance(rng, (int, np.integer)) or rng < 0:
        raise ValueError(f"rng must be a numpy.random.Generator or a non-negative int seed; got {rng!r}")
    return np.random.default_rng(int(rng))


def _poses(pose_at: PoseFunction, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return validated (R_CtoG (K, 3, 3), p_CinG (K, 3)) from ``pose_at(times)``."""
    result = pose_at(times)
    try:
        R, p = result
    except (TypeError, ValueError):
        raise ValueError("pose_at must return a pair (R_CtoG (K, 3, 3), p_CinG (K, 3))") from None
    R = np.asarray(R, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    k = times.shape[0]
    if R.shape != (k, 3, 3) or p.shape != (k, 3):
        raise ValueError(f"pose_at(times) must return R_CtoG of shape ({k}, 3, 3) and p_CinG of shape ({k}, 3) for "
                         f"{k} times; got {R.shape} and {p.shape}")
    return R, p


def exposure_sample_times(t_mid: float, exposure_s: float, n: int) -> np.ndarray:
    """Return the (n,) midpoints of n equal sub-intervals of [t_mid - T/2, t_mid + T/2] (midpoint rule).

    ``t_k = t_mid - T/2 + (k + 1/2) T / n``, k = 0 .. n-1.

    >>> exposure_sample_times(1.0, 0.01, 2).round(4).tolist()
    [0.9975, 1.0025]
    """
    if not np.isfinite(t_mid):
        raise ValueError(f"t_mid must be a finite time in seconds; got {t_mid!r}")
    if not (np.isfinite(exposure_s) and exposure_s > 0):
        raise ValueError(f"exposure_s must be a positive finite number of seconds; got {exposure_s!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be an int >= 1; got {n!r}")
    return float(t_mid) - 0.5 * exposure_s + (np.arange(n) + 0.5) * (exposure_s / n)


def choose_n_subframes(scene: Scene, camera: Any, pose_at: PoseFunction, t_mid: float, params: ApsParams) -> int:
    """Return how many sub-renders keep the image motion between consecutive ones below ``params.max_motion_px``.

    The 3-D points seen at ``t_mid`` (every 4th pixel) are projected at 9 poses spread over the exposure; the
    longest pixel path length ``L`` gives ``n = ceil(L / max_motion_px)``, clipped to [1, max_subframes].
    ``params.n_subframes > 0`` is returned as is.

    Args:
        scene: the :class:`~evio_lib.sim.scene.Scene`.
        camera: e.g. ``PinholeRadtan`` (needs ``normalized_grid`` and ``project``).
        pose_at: ``times (K,) -> (R_CtoG (K, 3, 3), p_CinG (K, 3))``.
        t_mid: middle of the exposure, seconds.
        params: :class:`ApsParams`.
    """
    if params.n_subframes > 0:
        return params.n_subframes
    times = exposure_sample_times(t_mid, params.exposure_s, 1)
    R_mid, p_mid = _poses(pose_at, times)
    points = scene.hit_points(camera, R_mid[0], p_mid[0])[::4, ::4].reshape(-1, 3)  # geometry only, no texture
    points = points[np.isfinite(points).all(axis=1)]
    if points.shape[0] == 0:
        return 1
    probe_times = float(t_mid) + params.exposure_s * np.linspace(-0.5, 0.5, 9)
    R_all, p_all = _poses(pose_at, probe_times)
    visible = np.ones(points.shape[0], dtype=bool)
    pixels = []
    for R, p in zip(R_all, p_all):
        points_C = (points - p) @ R  # X_C = R_CtoG^T (X_G - p)
        in_front = points_C[:, 2] > 1e-6
        visible &= in_front
        safe = np.where(in_front[:, None], points_C, [0.0, 0.0, 1.0])
        pixels.append(camera.project(safe))
    path = np.zeros(points.shape[0])
    for a, b in zip(pixels[:-1], pixels[1:]):
        path += np.linalg.norm(b - a, axis=1)  # pixel path length over the exposure
    longest = float(path[visible].max()) if visible.any() else 0.0
    return int(np.clip(np.ceil(longest / params.max_motion_px), 1, params.max_subframes))


def aps_exposure(scene: Scene, camera: Any, pose_at: PoseFunction, t_mid: float, params: ApsParams,
                 n_subframes: int | None = None) -> np.ndarray:
    """Return the (H, W) float32 linear exposure: the mean of sub-renders over the exposure window (motion blur).

    ``E = 1/n sum_k I(t_k)`` with ``t_k`` from :func:`exposure_sample_times`.

    Args:
        scene, camera, pose_at, t_mid, params: as in :func:`render_aps_frame`.
        n_subframes: overrides the number of sub-renders (default: :func:`choose_n_subframes`).
    """
    n = choose_n_subframes(scene, camera, pose_at, t_mid, params) if n_subframes is None else n_subframes
    times = exposure_sample_times(t_mid, params.exposure_s, n)
    R_all, p_all = _poses(pose_at, times)
    total = None
    for R, p in zip(R_all, p_all):
        image = scene.render_intensity(camera, R, p).astype(np.float64)
        total = image if total is None else total + image
    return (total / n).astype(np.float32)


def aps_sensor_response(exposure: np.ndarray, params: ApsParams, rng: np.random.Generator | int | None
                        ) -> np.ndarray:
    """Return the uint8 frame of a linear exposure: gain, shot + read noise, saturation, gamma, 8-bit rounding.

    Args:
        exposure: (H, W) linear exposure (float, >= 0), e.g. from :func:`aps_exposure`.
        params: :class:`ApsParams`.
        rng: ``numpy.random.Generator`` or int seed (may be None when both noise terms are 0).

    >>> params = ApsParams(read_noise_sigma=0.0, shot_noise_scale=0.0, gamma=1.0)
    >>> aps_sensor_response(np.array([[0.0, 0.5, 2.0]]), params, None).tolist()
    [[0, 128, 255]]
    """
    image = np.asarray(exposure, dtype=np.float64)
    if image.ndim != 2:
        raise ValueError(f"exposure must have shape (H, W); got {image.shape}")
    if not np.isfinite(image).all():
        raise ValueError("exposure must be finite")
    generator = _as_rng(rng, params)
    signal = params.gain * image  # S = gain E
    if not params.noiseless:
        sigma = np.sqrt(params.shot_noise_scale * np.maximum(signal, 0.0) + params.read_noise_sigma**2)
        signal = signal + sigma * generator.standard_normal(signal.shape)  # S' = S + sigma N(0, 1)
    value = np.clip(signal, 0.0, params.clip) / params.clip  # saturation
    return np.round(255.0 * value**params.gamma).astype(np.uint8)  # frame = round(255 V^gamma)


def render_aps_frame(scene: Scene, camera: Any, pose_at: PoseFunction, t_mid: float, params: ApsParams,
                     rng: np.random.Generator | int | None) -> np.ndarray:
    """Return one (H, W) uint8 APS frame exposed over [t_mid - T/2, t_mid + T/2] (see the module docstring).

    Args:
        scene: the :class:`~evio_lib.sim.scene.Scene` to render.
        camera: e.g. ``PinholeRadtan.davis240c()``.
        pose_at: ``times (K,) -> (R_CtoG (K, 3, 3), p_CinG (K, 3))``, the camera pose in the world frame G.
        t_mid: middle of the exposure, seconds.
        params: :class:`ApsParams`.
        rng: ``numpy.random.Generator`` or int seed for the noise (None allowed when the noise is off).

    >>> from evio_lib.geometry.camera import PinholeRadtan
    >>> from evio_lib.sim.scene import Scene, TexturedPlane
    >>> wall = TexturedPlane([-5.0, -5.0, 2.0], [10.0, 0, 0], [0, 10.0, 0], np.full((4, 4), 0.25, np.float32))
    >>> camera = PinholeRadtan(fx=20.0, fy=20.0, cx=7.5, cy=5.5, width=16, height=12)
    >>> still = lambda times: (np.repeat(np.eye(3)[None], len(times), 0), np.zeros((len(times), 3)))
    >>> params = ApsParams(read_noise_sigma=0.0, shot_noise_scale=0.0, gamma=1.0)
    >>> frame = render_aps_frame(Scene([wall]), camera, still, 0.5, params, None)
    >>> frame.shape, frame.dtype, int(frame[6, 8])
    ((12, 16), dtype('uint8'), 64)
    """
    if not isinstance(params, ApsParams):
        raise ValueError(f"params must be an ApsParams; got {type(params).__name__}")
    generator = _as_rng(rng, params)
    exposure = aps_exposure(scene, camera, pose_at, t_mid, params)
    return aps_sensor_response(exposure, params, generator)


def render_aps_frames(scene: Scene, camera: Any, pose_at: PoseFunction, times: np.ndarray, params: ApsParams,
                      rng: np.random.Generator | int | None, progress: bool = False) -> np.ndarray:
    """Return (F, H, W) uint8 APS frames whose exposures are centred at ``times`` (F,).

    Args:
        scene, camera, pose_at, params: as in :func:`render_aps_frame`.
        times: (F,) exposure mid-times in seconds.
        rng: ``numpy.random.Generator`` or int seed (one stream for all frames, so results are reproducible).
        progress: show a tqdm progress bar.
    """
    times_arr = np.asarray(times, dtype=np.float64)
    if times_arr.ndim != 1 or not np.isfinite(times_arr).all():
        raise ValueError(f"times must be a finite (F,) array of seconds; got shape {times_arr.shape}")
    if not isinstance(params, ApsParams):
        raise ValueError(f"params must be an ApsParams; got {type(params).__name__}")
    generator = _as_rng(rng, params)
    height, width = camera.normalized_grid().shape[:2]
    frames = np.empty((times_arr.shape[0], height, width), dtype=np.uint8)
    iterator = range(times_arr.shape[0])
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="APS frames", unit="frame")
    for i in iterator:
        frames[i] = render_aps_frame(scene, camera, pose_at, float(times_arr[i]), params, generator)
    return frames
