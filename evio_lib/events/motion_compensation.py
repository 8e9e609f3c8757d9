"""Motion-compensated event frames: each event warped to one reference time with the gyroscope's rotation.

An event frame that simply counts a window's events is sharp only while the image barely moves during the window;
in fast motion every edge smears over the pixels it swept. Most of that motion, for a hand-held or flying camera,
is rotation, and the gyroscope measures it. Rebecq et al. (BMVC 2017, "Real-time visual-inertial odometry for
event cameras using keyframe-based nonlinear optimization") therefore warp each event to the window's reference
time t_ref with the IMU's rotation before counting: the frame is then as sharp as the rotation is known, whatever
the speed, and it costs a few milliseconds (no network).

The warp of an event at pixel u_e and time t_e (a point far away, or any point under pure rotation)::

    b_e   = [x, y, 1],  (x, y) = undistort(u_e)                  the event's ray in the camera frame C(t_e)
    b_ref = R_{C(t_e) -> C(t_ref)} b_e                            the same ray seen from C(t_ref)
    u_ref = distort(b_ref[:2] / b_ref[2])                         its pixel in the frame at t_ref

and the frame is the count of warped events per pixel, each event spread over its four neighbouring pixels with
bilinear weights (so sub-pixel warps keep their precision), lightly blurred and scaled to [0, 1].

The rotation comes from the gyro integrator of the tracker's rotation prior
(:func:`evio_lib.frontend.gyro_prior.gyro_orientations`). Over the window the IMU orientation
relative to its start, A(t) = R_{I(t) -> I(t_a)}, is the ordered product of exp([w_k dt_k]x) over the intervals
between the breakpoints (t_a, the IMU samples inside, t_b), each with its mean rate w_k. An event inside interval k
adds the partial step exp([w_k (t_e - t_k)]x) (expanded to second order: at most 0.05 rad per 5 ms interval even at
10 rad/s, an error of about 2e-5 rad), and in the camera frame (R_ItoC = R_CtoI^T)::

    R_{C(t_e) -> C(t_ref)} = R_ItoC A(t_ref)^T A(t_k) exp([w_k (t_e - t_k)]x) R_CtoI

Translation is not compensated: its flow f |v| / Z over the window is what blurs these frames (at 2 m/s and 2 m with
f = 200 px, 4 px over a 20 ms window), so the windows stay short (see :func:`evio_lib.pipeline.frames.mc_event_frames`).
"""
from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.frontend.gyro_prior import gyro_orientations
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import so3_exp

__all__ = ["warp_events", "accumulate_bilinear", "motion_compensated_frame", "mc_backend", "MC_BACKEND_ENV"]

#: Environment variable that picks the backend of :func:`motion_compensated_frame`: auto (default), numba or numpy.
MC_BACKEND_ENV = "EVIO_MC_BACKEND"
_KERNEL_PROBLEM: list[str] = []  # "" once the kernel loaded, else why it did not (said once)


def mc_backend() -> str:
    """Return the backend of :func:`motion_compensated_frame`: ``"numba"`` or ``"numpy"`` (the same frame up to
    rounding).

    ``EVIO_MC_BACKEND`` = ``numba`` | ``numpy`` | ``auto`` (default: the compiled kernel
    :func:`evio_lib.events.warp_kernels.warp_and_count` when it loads, else NumPy with one warning saying why). The
    kernel makes a frame faster than the NumPy passes of :func:`warp_events` and :func:`accumulate_bilinear`
    (measured: docs/results/speed.md#small-costs-behind-the-codes-choices), which stay the reference it is tested
    against.
    """
    from evio_lib.compiled import compiled_backend

    return compiled_backend(MC_BACKEND_ENV, "evio_lib.events.warp_kernels", _KERNEL_PROBLEM,
                            "motion-compensated frames with NumPy (slower, the same frames)")


def _interval_rotations(t: np.ndarray, t_ref: float, imu_t: ArrayLike, gyro: ArrayLike, R_CtoI: ArrayLike,
                        gyro_bias: ArrayLike | None) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                              NDArray[np.float64]]:
    """Return (breaks (K + 1,), w_C (K, 3), M (K, 3, 3)) of the window: the gyro intervals, their rates in the camera
    frame and the rotations R_{C(t_k) -> C(t_ref)} of their starts (module docstring)."""
    t_a, t_b = min(float(t[0]), float(t_ref)), max(float(t[-1]), float(t_ref))
    breaks, A, w = gyro_orientations(imu_t, gyro, t_a, t_b, gyro_bias)
    R_CtoI = np.asarray(R_CtoI, dtype=np.float64)
    k_ref = int(np.clip(np.searchsorted(breaks, t_ref, side="right") - 1, 0, w.shape[0] - 1))
    A_ref = A[k_ref] @ so3_exp(w[k_ref] * (t_ref - breaks[k_ref]))
    M = R_CtoI.T @ A_ref.T @ A[:-1] @ R_CtoI                                 # (K, 3, 3) C(t_k) -> C(t_ref)
    return breaks, w @ R_CtoI, M                                             # rates in the camera frame (rows)


def warp_events(events: np.ndarray, camera: PinholeRadtan, t_ref: float, imu_t: ArrayLike, gyro: ArrayLike,
                R_CtoI: ArrayLike, gyro_bias: ArrayLike | None = None) -> NDArray[np.float64]:
    """Return (N, 2) pixels: where each event's ray lies in the (distorted) image at ``t_ref`` (module docstring).

    Args:
        events: (N,) event array sorted by time, on the camera's sensor.
        camera: the event camera (its undistortion is looked up per pixel: ``camera.normalized_grid()``).
        t_ref: the reference time [s]; events before and after it are warped forward and backward.
        imu_t, gyro: (n,) IMU times [s] and (n, 3) rates [rad/s] covering the window.
        R_CtoI: (3, 3) camera-to-IMU rotation.
        gyro_bias: (3,) rad/s subtracted from the gyro (e.g. the filter's estimate).
    """
    if events.size == 0:
        return np.zeros((0, 2))
    t = events["t"]
    breaks, w_C, M = _interval_rotations(t, t_ref, imu_t, gyro, R_CtoI, gyro_bias)
    grid = camera.normalized_grid().reshape(-1, 2)
    xy = grid[events["y"].astype(np.intp) * camera.width + events["x"]]      # undistorted rays, looked up
    # per event: its interval k, the rate and the rotation of that interval (gathered column by column: contiguous)
    k = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, w_C.shape[0] - 1)
    dt = t - breaks[k]
    px, py, pz = (dt * w_C[:, i][k] for i in range(3))                          # phi = w_k (t_e - t_k), frame C
    x, y = xy[:, 0], xy[:, 1]                                                 # b_e = (x, y, 1)
    cx, cy, cz = py - pz * y, pz * x - px, px * y - py * x                   # phi x b_e
    bx = x + cx + 0.5 * (py * cz - pz * cy)                                  # exp([phi]x) b_e to second order
    by = y + cy + 0.5 * (pz * cx - px * cz)
    bz = 1.0 + cz + 0.5 * (px * cy - py * cx)
    m = M.reshape(-1, 9).T                                                   # (9, intervals)
    zr = m[6][k] * bx + m[7][k] * by + m[8][k] * bz
    out = np.empty((events.size, 2))
    out[:, 0] = (m[0][k] * bx + m[1][k] * by + m[2][k] * bz) / zr
    out[:, 1] = (m[3][k] * bx + m[4][k] * by + m[5][k] * bz) / zr
    return camera.normalized_to_pixels(out)


def accumulate_bilinear(pixels: ArrayLike, width: int, height: int) -> NDArray[np.float32]:
    """Return the (height, width) float32 count of sub-pixel points, each split over its 4 nearest pixels.

    A point at (u, v) adds (1 - du)(1 - dv) to pixel (floor u, floor v), du (1 - dv) to its right neighbour, and so
    on (du, dv the fractional parts); points off the sensor are dropped, shares off the edge are lost.

    >>> accumulate_bilinear([[1.25, 0.0]], 4, 2)
    array([[0.  , 0.75, 0.25, 0.  ],
           [0.  , 0.  , 0.  , 0.  ]], dtype=float32)
    """
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    p = p[np.isfinite(p).all(axis=1) & (p[:, 0] > -1) & (p[:, 0] < width) & (p[:, 1] > -1) & (p[:, 1] < height)]
    # on a grid padded by one pixel on each side every point has its 4 neighbours: one bincount, cropped after
    x0 = np.floor(p[:, 0])
    y0 = np.floor(p[:, 1])
    dx, dy = p[:, 0] - x0, p[:, 1] - y0
    wp = width + 2
    i00 = (y0.astype(np.int64) + 1) * wp + (x0.astype(np.int64) + 1)
    index = np.concatenate([i00, i00 + 1, i00 + wp, i00 + wp + 1])
    weight = np.concatenate([(1 - dx) * (1 - dy), dx * (1 - dy), (1 - dx) * dy, dx * dy])
    out = np.bincount(index, weights=weight, minlength=wp * (height + 2)).reshape(height + 2, wp)
    return out[1:-1, 1:-1].astype(np.float32)


def motion_compensated_frame(events: np.ndarray, camera: PinholeRadtan, t_ref: float, imu_t: ArrayLike,
                             gyro: ArrayLike, R_CtoI: ArrayLike, gyro_bias: ArrayLike | None = None,
                             blur_sigma_px: float = 0.75, saturation_quantile: float = 0.98) -> NDArray[np.float32]:
    """Return the (H, W) float32 motion-compensated event frame in [0, 1] (module docstring).

    The warped events are counted with bilinear weights (:func:`warp_events`, :func:`accumulate_bilinear`), blurred
    with a Gaussian of ``blur_sigma_px`` (0: none) and divided by the ``saturation_quantile`` of the non-zero
    pixels, so that a frame's brightness does not depend on how many events its window held; above it, pixels are 1.
    Polarity is ignored: an edge gives events of one sign or the other depending on the direction it moves, and a
    tracker wants the edge.
    """
    if not 0 < saturation_quantile <= 1:
        raise ValueError(f"saturation_quantile must be in (0, 1]; got {saturation_quantile!r}")
    if not (np.isfinite(blur_sigma_px) and blur_sigma_px >= 0):
        raise ValueError(f"blur_sigma_px must be a number >= 0; got {blur_sigma_px!r}")
    width, height = camera.width, camera.height
    if events.size and mc_backend() == "numba":
        from evio_lib.events.warp_kernels import warp_and_count

        t = np.ascontiguousarray(events["t"], dtype=np.float64)
        x, y = events["x"], events["y"]
        if np.any(np.diff(t) < 0) or x.min() < 0 or y.min() < 0 or x.max() >= width or y.max() >= height:
            raise ValueError(f"events must be sorted by time and lie on the {width} x {height} sensor")
        breaks, w_C, M = _interval_rotations(t, t_ref, imu_t, gyro, R_CtoI, gyro_bias)
        if not (np.isfinite(w_C).all() and np.isfinite(M).all()):
            raise ValueError("the gyro rates (or the bias) over the window must be finite numbers")
        intrinsics = np.array([camera.fx, camera.fy, camera.cx, camera.cy, camera.k1, camera.k2, camera.p1, camera.p2,
                               camera.k3], dtype=np.float64)
        image = warp_and_count(x, y, t,
                               camera.normalized_grid().reshape(-1, 2), breaks, np.ascontiguousarray(w_C),
                               np.ascontiguousarray(M.reshape(-1, 9)), intrinsics, width, height).astype(np.float32)
    else:
        image = accumulate_bilinear(warp_events(events, camera, t_ref, imu_t, gyro, R_CtoI, gyro_bias), width, height)
    if blur_sigma_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma_px)
    values = image[image > 1e-6]
    if values.size:
        scale = float(np.quantile(values, saturation_quantile))
        if scale > 0:
            image = np.minimum(image / scale, 1.0, out=image)
    return image.astype(np.float32, copy=False)
