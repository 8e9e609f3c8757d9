"""Numba kernel of the motion-compensated event frame: warp, distort and count each event in one pass.

:func:`evio_lib.events.motion_compensation.warp_events` and
:func:`~evio_lib.events.motion_compensation.accumulate_bilinear` do the work of a frame as NumPy passes over all of a
window's events: about twenty gathers and temporaries of N elements (most of the time in the warp; a measured window:
docs/results/speed.md#small-costs-behind-the-codes-choices). :func:`warp_and_count` does the same arithmetic one event
at a time, in float64, without temporaries. For event e in the gyro interval k (t_k <= t_e < t_k+1, rate w_k in the
camera frame) with the undistorted ray b = (x, y, 1)::

    phi = w_k (t_e - t_k)
    b'  = b + phi x b + 1/2 phi x (phi x b)          exp([phi]x) b to second order
    c   = M_k b'                                      M_k = R_{C(t_k) -> C(t_ref)}
    (x', y') = (c_x / c_z, c_y / c_z), distorted (radial-tangential), u = fx x_d + cx, v = fy y_d + cy

and the point (u, v) adds the bilinear weights (1 - du)(1 - dv), du (1 - dv), (1 - du) dv, du dv to its four
neighbouring pixels (dropped unless -1 < u < W and -1 < v < H, shares off the edge lost). The sums differ from the
NumPy path's only by rounding (the order of the additions), which the tests bound. A warp that is not finite (a NaN
rate) drops the event here; :func:`evio_lib.events.motion_compensation.motion_compensated_frame` refuses such rates
before either path runs.

Numba compiles the kernel on first use (about a second) and caches the machine code (``cache=True``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["warp_and_count"]


@njit(cache=True, nogil=True, error_model="numpy")  # a ray at z = 0 gives inf, dropped as off the sensor
def warp_and_count(x_pix: np.ndarray, y_pix: np.ndarray, t: np.ndarray, grid: np.ndarray, breaks: np.ndarray,
                   w_C: np.ndarray, M: np.ndarray, intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """Return the (height, width) float64 bilinear count of the events warped to the reference time.

    Args:
        x_pix, y_pix: (N,) integer pixel of each event, on the sensor; t: (N,) its time [s], non-decreasing (the
            caller checks both: the kernel reads the grid at the pixel and walks the intervals forward only).
        grid: (H W, 2) undistorted normalised coordinates of every pixel (``camera.normalized_grid()``).
        breaks: (K + 1,) the gyro intervals' bounds [s]; w_C: (K, 3) each interval's rate in the camera frame.
        M: (K, 9) row-major R_{C(t_k) -> C(t_ref)} of each interval's start.
        intrinsics: (9,) fx, fy, cx, cy, k1, k2, p1, p2, k3.
        width, height: the sensor's size.
    """
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    k1, k2, p1, p2, k3 = intrinsics[4], intrinsics[5], intrinsics[6], intrinsics[7], intrinsics[8]
    wp = width + 2
    out = np.zeros((height + 2) * wp)  # padded by one pixel on each side: every point has its four neighbours
    intervals = w_C.shape[0]
    k = 0
    for e in range(t.shape[0]):
        te = t[e]
        while k + 1 < intervals and breaks[k + 1] <= te:  # the events are sorted: the interval only moves on
            k += 1
        dt = te - breaks[k]
        px, py, pz = dt * w_C[k, 0], dt * w_C[k, 1], dt * w_C[k, 2]
        g = y_pix[e] * width + x_pix[e]
        x, y = grid[g, 0], grid[g, 1]
        cx_, cy_, cz_ = py - pz * y, pz * x - px, px * y - py * x  # phi x b
        bx = x + cx_ + 0.5 * (py * cz_ - pz * cy_)
        by = y + cy_ + 0.5 * (pz * cx_ - px * cz_)
        bz = 1.0 + cz_ + 0.5 * (px * cy_ - py * cx_)
        zr = M[k, 6] * bx + M[k, 7] * by + M[k, 8] * bz
        xn = (M[k, 0] * bx + M[k, 1] * by + M[k, 2] * bz) / zr
        yn = (M[k, 3] * bx + M[k, 4] * by + M[k, 5] * bz) / zr
        r2 = xn * xn + yn * yn
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = xn * radial + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
        u = fx * xd + cx
        v = fy * yd + cy
        if not (u > -1.0 and u < width and v > -1.0 and v < height):  # NaN fails too
            continue
        u0, v0 = math.floor(u), math.floor(v)
        du, dv = u - u0, v - v0
        i00 = (int(v0) + 1) * wp + int(u0) + 1
        out[i00] += (1.0 - du) * (1.0 - dv)
        out[i00 + 1] += du * (1.0 - dv)
        out[i00 + wp] += (1.0 - du) * dv
        out[i00 + wp + 1] += du * dv
    return out.reshape(height + 2, wp)[1:-1, 1:-1]
