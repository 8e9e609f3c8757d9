"""Pinhole camera with radial-tangential (plumb-bob / OpenCV) lens distortion.

Model (thesis §2.1.1, Eq. 1, extended with the Brown-Conrady distortion used by OpenCV):

1. a point ``P_C = (X, Y, Z)`` in the camera frame C (x right, y down, z forward) maps to normalised
   coordinates ``x = X / Z``, ``y = Y / Z``;
2. the lens moves them to distorted normalised coordinates, with ``r^2 = x^2 + y^2``::

       x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
       y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y

3. the intrinsic matrix K gives pixels: ``u = fx x_d + cx``, ``v = fy y_d + cy``.

Pixel centres lie at integer coordinates (OpenCV's convention): pixel (column 0, row 0) covers
``[-0.5, 0.5] x [-0.5, 0.5]``.

Reference: OpenCV "Camera Calibration and 3D Reconstruction" (calib3d) documentation; D. C. Brown,
"Decentering distortion of lenses", 1966.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from numbers import Integral, Real

import cv2
import numpy as np

__all__ = ["PinholeRadtan", "intrinsics_problem", "PLAUSIBLE_FOV_DEG"]

# Image dtypes that cv2.remap handles directly.
_REMAP_DTYPES = tuple(np.dtype(name) for name in ("float32", "float64", "uint8", "uint16", "int16"))


def _as_points(values: np.ndarray, dim: int, name: str) -> tuple[np.ndarray, bool]:
    """Return ``values`` as a finite float64 (N, dim) array and whether a single (dim,) point was given."""
    array = np.asarray(values, dtype=np.float64)
    single = array.shape == (dim,)
    if single:
        array = array[None, :]
    if array.ndim != 2 or array.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}) or ({dim},); got {np.shape(values)}")
    bad = ~np.isfinite(array).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{name} must be finite; found {int(bad.sum())} row(s) with NaN or inf, "
            f"first at index {int(np.argmax(bad))}"
        )
    return array, single


def _restore(points: np.ndarray, single: bool) -> np.ndarray:
    """Return ``points`` as (dim,) when the caller passed one point, else unchanged."""
    return points[0] if single else points


@dataclass(frozen=True)
class PinholeRadtan:
    """Pinhole camera with radial-tangential distortion (OpenCV's plumb-bob model).

    Args:
        fx, fy: focal lengths in pixels (> 0).
        cx, cy: principal point in pixels (pixel centres at integer coordinates).
        width, height: image size in pixels (> 0).
        k1, k2, k3: radial distortion coefficients.
        p1, p2: tangential distortion coefficients.

    Reference: thesis §2.1.1 Eq. 1 (pinhole projection); OpenCV calib3d (distortion).

    >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80)
    >>> cam.project(np.array([0.1, -0.2, 1.0])).round(3)
    array([60., 20.])
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite real number; got {value!r}")
            object.__setattr__(self, name, float(value))
        for name in ("fx", "fy"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be a positive focal length in pixels; got {getattr(self, name)!r}")
        for name in ("width", "height"):
            value = getattr(self, name)
            # whole-number floats (e.g. 240.0 read back from a file) are accepted; 180.5 is not
            whole = isinstance(value, Integral) or (
                isinstance(value, Real) and math.isfinite(value) and value == int(value)
            )
            if isinstance(value, bool) or not whole or value <= 0:
                raise ValueError(f"{name} must be a positive integer number of pixels; got {value!r}")
            object.__setattr__(self, name, int(value))

    # ------------------------------------------------------------------ constructors and properties
    @classmethod
    def davis240c(cls) -> "PinholeRadtan":
        """Return the DAVIS240C calibration of the RPG Event-Camera Dataset (240 x 180 pixels).

        Reference: Mueggler et al., "The Event-Camera Dataset and Simulator", IJRR 2017 (calib.txt).

        >>> PinholeRadtan.davis240c().K.round(1)
        array([[199.1,   0. , 132.2],
               [  0. , 198.8, 110.7],
               [  0. ,   0. ,   1. ]])
        """
        return cls(
            fx=199.092366542,
            fy=198.82882047,
            cx=132.192071378,
            cy=110.712660011,
            width=240,
            height=180,
            k1=-0.368436311798,
            k2=0.150947243557,
            p1=-0.000296130534385,
            p2=-0.000759431726241,
            k3=0.0,
        )

    @property
    def K(self) -> np.ndarray:
        """Return the (3, 3) intrinsic matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (a fresh array)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Return the (5,) distortion coefficients in OpenCV order (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    @property
    def _has_distortion(self) -> bool:
        """Return True when any distortion coefficient is non-zero."""
        return bool(np.any(self.dist_coeffs != 0.0))

    def scaled(self, factor: float) -> "PinholeRadtan":
        """Return the same lens seen by a sensor resampled by ``factor`` (e.g. 2.0 doubles the resolution).

        With pixel centres at integer coordinates a continuous pixel coordinate maps as
        ``u' = factor (u + 0.5) - 0.5``, hence ``fx' = factor fx`` and ``cx' = factor (cx + 0.5) - 0.5``.
        Distortion acts on normalised coordinates, so its coefficients are unchanged.

        Args:
            factor: positive scale; ``width * factor`` and ``height * factor`` must be whole numbers.

        >>> PinholeRadtan.davis240c().scaled(0.5).width
        120
        """
        if isinstance(factor, bool) or not isinstance(factor, Real) or not math.isfinite(factor) or factor <= 0:
            raise ValueError(f"factor must be a positive finite number; got {factor!r}")
        new_size = []
        for name in ("width", "height"):
            exact = getattr(self, name) * float(factor)
            rounded = int(round(exact))
            if rounded < 1 or abs(exact - rounded) > 1e-9 * max(1.0, exact):
                raise ValueError(
                    f"factor must turn {name}={getattr(self, name)} into a whole number of pixels; "
                    f"got factor={factor!r} giving {exact!r}"
                )
            new_size.append(rounded)
        s = float(factor)
        return PinholeRadtan(
            fx=s * self.fx,  # fx' = s fx
            fy=s * self.fy,
            cx=s * (self.cx + 0.5) - 0.5,  # cx' = s (cx + 1/2) - 1/2
            cy=s * (self.cy + 0.5) - 0.5,
            width=new_size[0],
            height=new_size[1],
            k1=self.k1,
            k2=self.k2,
            p1=self.p1,
            p2=self.p2,
            k3=self.k3,
        )

    # ------------------------------------------------------------------ distortion on normalised coordinates
    def _distort(self, xy: np.ndarray) -> np.ndarray:
        """Return distorted normalised coordinates for validated (N, 2) undistorted ones."""
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))  # 1 + k1 r^2 + k2 r^4 + k3 r^6
        x_d = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
        y_d = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
        return np.stack([x_d, y_d], axis=1)

    def _distortion_jacobian(self, xy: np.ndarray) -> np.ndarray:
        """Return the (N, 2, 2) Jacobian d(x_d, y_d)/d(x, y) of the distortion at validated (N, 2) points."""
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        dradial_dr2 = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2)  # d(radial)/d(r^2)
        jac = np.empty((xy.shape[0], 2, 2))
        # dx_d/dx = radial + 2 x^2 radial' + 2 p1 y + 6 p2 x ;  dx_d/dy = 2 x y radial' + 2 p1 x + 2 p2 y
        jac[:, 0, 0] = radial + 2.0 * x * x * dradial_dr2 + 2.0 * self.p1 * y + 6.0 * self.p2 * x
        jac[:, 0, 1] = 2.0 * x * y * dradial_dr2 + 2.0 * self.p1 * x + 2.0 * self.p2 * y
        # dy_d/dx = 2 x y radial' + 2 p1 x + 2 p2 y ;  dy_d/dy = radial + 2 y^2 radial' + 6 p1 y + 2 p2 x
        jac[:, 1, 0] = jac[:, 0, 1]
        jac[:, 1, 1] = radial + 2.0 * y * y * dradial_dr2 + 6.0 * self.p1 * y + 2.0 * self.p2 * x
        return jac

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Return distorted normalised coordinates (N, 2) for undistorted normalised ones.

        Args:
            xy: (N, 2) or (2,) undistorted normalised coordinates ``(X/Z, Y/Z)`` in the camera frame C.

        Reference: OpenCV calib3d, radial-tangential (plumb-bob) model.

        >>> cam = PinholeRadtan(fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=1, height=1, k1=0.1)
        >>> cam.distort_normalized([1.0, 0.0]).round(3)
        array([1.1, 0. ])
        """
        points, single = _as_points(xy, 2, "xy")
        return _restore(self._distort(points), single)

    def undistort_normalized(self, xy_d: np.ndarray, iterations: int = 20, tol: float = 1e-12) -> np.ndarray:
        """Return undistorted normalised coordinates (N, 2) for distorted normalised ones.

        Inverts the distortion with Newton's method on ``f(x) = distort(x) - x_d`` (2 x 2 system per point,
        all points at once), starting from ``x = x_d``; a point stops once its step is below ``tol``.
        Newton converges quadratically, so a handful of steps reach machine precision even in the DAVIS240C
        corners, where OpenCV's default 5 fixed-point iterations leave errors of about 2e-4.

        Args:
            xy_d: (N, 2) or (2,) distorted normalised coordinates.
            iterations: maximum number of Newton steps (>= 1).
            tol: stop when every step (in normalised units) is below this.

        >>> cam = PinholeRadtan.davis240c()
        >>> xy = np.array([[0.3, -0.2], [-0.6, 0.5]])
        >>> bool(np.allclose(cam.undistort_normalized(cam.distort_normalized(xy)), xy, atol=1e-12))
        True
        """
        points_d, single = _as_points(xy_d, 2, "xy_d")
        if isinstance(iterations, bool) or not isinstance(iterations, Integral) or iterations < 1:
            raise ValueError(f"iterations must be a positive integer; got {iterations!r}")
        if not (isinstance(tol, Real) and math.isfinite(tol) and tol >= 0):
            raise ValueError(f"tol must be a finite non-negative number; got {tol!r}")
        xy = points_d.copy()
        if not self._has_distortion:
            return _restore(xy, single)
        active = np.arange(xy.shape[0])
        for _ in range(int(iterations)):
            if active.size == 0:
                break
            current = xy[active]
            residual = self._distort(current) - points_d[active]  # f(x) = distort(x) - x_d
            jac = self._distortion_jacobian(current)
            # Newton step: solve J dx = -f with the closed-form 2 x 2 inverse.
            det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
            det = np.where(det == 0.0, np.finfo(float).tiny, det)
            step_x = -(jac[:, 1, 1] * residual[:, 0] - jac[:, 0, 1] * residual[:, 1]) / det
            step_y = -(-jac[:, 1, 0] * residual[:, 0] + jac[:, 0, 0] * residual[:, 1]) / det
            xy[active, 0] += step_x
            xy[active, 1] += step_y
            still_moving = np.hypot(step_x, step_y) > tol
            active = active[still_moving]
        return _restore(xy, single)

    # ------------------------------------------------------------------ projection and back-projection
    def project(self, points_C: np.ndarray) -> np.ndarray:
        """Return distorted pixel coordinates (N, 2) of 3-D points in the camera frame.

        ``u = fx x_d + cx``, ``v = fy y_d + cy`` with ``(x_d, y_d) = distort(X/Z, Y/Z)`` (thesis Eq. 1 plus distortion).

        Args:
            points_C: (N, 3) or (3,) points in the camera frame C, metres, all with Z > 0.

        >>> cam = PinholeRadtan(fx=200.0, fy=200.0, cx=120.0, cy=90.0, width=240, height=180)
        >>> cam.project(np.array([[0.5, 0.25, 2.0]])).round(2)
        array([[170., 115.]])
        """
        points, single = _as_points(points_C, 3, "points_C")
        behind = points[:, 2] <= 0.0
        if behind.any():
            raise ValueError(
                f"points_C must lie in front of the camera (Z > 0); {int(behind.sum())} of {points.shape[0]} "
                f"point(s) have Z <= 0, first at index {int(np.argmax(behind))}"
            )
        xy = points[:, :2] / points[:, 2:3]  # x = X / Z, y = Y / Z
        return _restore(self._normalized_to_pixels(xy), single)

    def _normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Return distorted pixels for validated (N, 2) undistorted normalised coordinates."""
        xy_d = self._distort(xy)
        u = self.fx * xy_d[:, 0] + self.cx  # u = fx x_d + cx
        v = self.fy * xy_d[:, 1] + self.cy  # v = fy y_d + cy
        return np.stack([u, v], axis=1)

    def normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Return distorted pixel coordinates (N, 2) of undistorted normalised coordinates.

        Args:
            xy: (N, 2) or (2,) undistorted normalised coordinates ``(X/Z, Y/Z)`` in the camera frame C.
        """
        points, single = _as_points(xy, 2, "xy")
        return _restore(self._normalized_to_pixels(points), single)

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Return undistorted normalised coordinates (N, 2) ``(X/Z, Y/Z)`` of distorted pixels.

        ``x_d = (u - cx) / fx``, ``y_d = (v - cy) / fy``, then the distortion is inverted iteratively
        (see :meth:`undistort_normalized`).

        Args:
            uv: (N, 2) or (2,) distorted pixel coordinates (x = column, y = row).

        >>> cam = PinholeRadtan.davis240c()
        >>> uv = cam.project(np.array([0.2, -0.1, 1.0]))
        >>> cam.unproject(uv).round(6)
        array([ 0.2, -0.1])
        """
        pixels, single = _as_points(uv, 2, "uv")
        x_d = (pixels[:, 0] - self.cx) / self.fx  # x_d = (u - cx) / fx
        y_d = (pixels[:, 1] - self.cy) / self.fy  # y_d = (v - cy) / fy
        return _restore(self.undistort_normalized(np.stack([x_d, y_d], axis=1), iterations=50), single)

    def pixel_rays(self, uv: np.ndarray) -> np.ndarray:
        """Return unit bearing vectors (N, 3) in the camera frame C through distorted pixels.

        ``ray = [x, y, 1] / ||[x, y, 1]||`` with ``(x, y) = unproject(uv)``.

        Args:
            uv: (N, 2) or (2,) distorted pixel coordinates.

        >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80)
        >>> cam.pixel_rays([150.0, 40.0]).round(4)
        array([0.7071, 0.    , 0.7071])
        """
        pixels, single = _as_points(uv, 2, "uv")
        xy = self.unproject(pixels)
        rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        return _restore(rays, single)

    def undistort_points(self, uv: np.ndarray) -> np.ndarray:
        """Return undistorted pixel coordinates (N, 2) (same K) of distorted pixels, like ``cv2.undistortPoints(P=K)``.

        Args:
            uv: (N, 2) or (2,) distorted pixel coordinates.
        """
        pixels, single = _as_points(uv, 2, "uv")
        xy = self.unproject(pixels)
        out = np.stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy], axis=1)  # u' = fx x + cx
        return _restore(out, single)

    def in_image(self, uv: np.ndarray, border: float = 0.0) -> np.ndarray:
        """Return a (N,) bool mask of pixels inside the image, at least ``border`` pixels from the edge pixel centres.

        Inside means ``border <= u <= width - 1 - border`` and ``border <= v <= height - 1 - border``
        (between the outermost pixel centres, so bilinear interpolation has all four neighbours).

        Args:
            uv: (N, 2) or (2,) pixel coordinates; a single point gives a 0-d bool array.
            border: margin in pixels (may be negative to allow points slightly outside).

        >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80)
        >>> cam.in_image(np.array([[0.0, 0.0], [98.0, 78.0], [98.5, 10.0], [5.0, 5.0]]), border=1.0)
        array([False,  True, False,  True])
        """
        pixels, single = _as_points(uv, 2, "uv")
        if isinstance(border, bool) or not isinstance(border, Real) or not math.isfinite(border):
            raise ValueError(f"border must be a finite number of pixels; got {border!r}")
        border = float(border)
        inside = (
            (pixels[:, 0] >= border)
            & (pixels[:, 0] <= self.width - 1 - border)
            & (pixels[:, 1] >= border)
            & (pixels[:, 1] <= self.height - 1 - border)
        )
        return inside[0] if single else inside

    def projection_jacobian(self, points_C: np.ndarray) -> np.ndarray:
        """Return the (N, 2, 3) Jacobian d(u, v)/d(X, Y, Z) of :meth:`project`, distortion included.

        Chain rule: ``J = diag(fx, fy) @ d(x_d, y_d)/d(x, y) @ [[1/Z, 0, -X/Z^2], [0, 1/Z, -Y/Z^2]]``.

        Args:
            points_C: (N, 3) or (3,) points in the camera frame C with Z > 0; a single point gives (2, 3).

        >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80)
        >>> cam.projection_jacobian(np.array([0.2, -0.4, 2.0])).round(3)
        array([[50.,  0., -5.],
               [ 0., 50., 10.]])
        """
        points, single = _as_points(points_C, 3, "points_C")
        behind = points[:, 2] <= 0.0
        if behind.any():
            raise ValueError(
                f"points_C must lie in front of the camera (Z > 0); {int(behind.sum())} of {points.shape[0]} "
                f"point(s) have Z <= 0, first at index {int(np.argmax(behind))}"
            )
        inv_z = 1.0 / points[:, 2]
        xy = points[:, :2] * inv_z[:, None]
        d_xy_d_point = np.zeros((points.shape[0], 2, 3))
        d_xy_d_point[:, 0, 0] = inv_z  # dx/dX = 1/Z
        d_xy_d_point[:, 1, 1] = inv_z  # dy/dY = 1/Z
        d_xy_d_point[:, 0, 2] = -xy[:, 0] * inv_z  # dx/dZ = -X/Z^2
        d_xy_d_point[:, 1, 2] = -xy[:, 1] * inv_z  # dy/dZ = -Y/Z^2
        jac = self._distortion_jacobian(xy) @ d_xy_d_point
        jac[:, 0, :] *= self.fx
        jac[:, 1, :] *= self.fy
        return _restore(jac, single)

    # ------------------------------------------------------------------ whole-image helpers (cached)
    @cached_property
    def _pixel_centres(self) -> np.ndarray:
        """Return (height * width, 2) pixel-centre coordinates (u, v), row-major."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        return np.stack([u.ravel(), v.ravel()], axis=1)

    @cached_property
    def _normalized_grid(self) -> np.ndarray:
        grid = self.unproject(self._pixel_centres).reshape(self.height, self.width, 2)
        grid.setflags(write=False)
        return grid

    def normalized_grid(self) -> np.ndarray:
        """Return the (height, width, 2) undistorted normalised coordinates (x, y) of every pixel centre.

        Entry ``[v, u]`` holds ``unproject([u, v])``; the ray through that pixel is ``[x, y, 1]`` in frame C.
        The array is computed once per camera and returned read-only.

        >>> grid = PinholeRadtan(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80).normalized_grid()
        >>> grid.shape, grid[40, 50].tolist()
        ((80, 100, 2), [0.0, 0.0])
        """
        return self._normalized_grid

    @cached_property
    def _undistort_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """Return float32 (map_u, map_v): where in the distorted image each undistorted pixel samples."""
        # undistorted pixel (u, v) -> x = (u - cx) / fx -> distort -> pixel in the raw image
        centres = self._pixel_centres
        xy = np.stack([(centres[:, 0] - self.cx) / self.fx, (centres[:, 1] - self.cy) / self.fy], axis=1)
        uv_distorted = self._normalized_to_pixels(xy)
        map_u = uv_distorted[:, 0].reshape(self.height, self.width).astype(np.float32)
        map_v = uv_distorted[:, 1].reshape(self.height, self.width).astype(np.float32)
        map_u.setflags(write=False)
        map_v.setflags(write=False)
        return map_u, map_v

    def undistort_image(self, image: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """Return the undistorted image (same K, same size, same dtype); pixels that see outside the sensor are 0.

        Each output pixel ``(u, v)`` samples the input at ``normalized_to_pixels((u - cx) / fx, (v - cy) / fy)``
        (the same tables as ``cv2.initUndistortRectifyMap(K, D, None, K)``), computed once per camera.

        Args:
            image: (height, width) or (height, width, channels) image, e.g. float32 in [0, 1] or uint8.
            interpolation: an OpenCV interpolation flag (``cv2.INTER_LINEAR``, ``cv2.INTER_NEAREST``, ...).

        >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=49.5, cy=39.5, width=100, height=80)
        >>> image = np.full((80, 100), 0.5, dtype=np.float32)
        >>> float(cam.undistort_image(image)[40, 50])
        0.5
        """
        array = np.asarray(image)
        if array.ndim not in (2, 3) or array.shape[:2] != (self.height, self.width):
            raise ValueError(
                f"image must have shape ({self.height}, {self.width}) or ({self.height}, {self.width}, C); "
                f"got {array.shape}"
            )
        if array.dtype not in _REMAP_DTYPES:
            raise ValueError(
                f"image must have dtype float32, float64, uint8, uint16 or int16 (float32 in [0, 1] in the library); "
                f"got dtype {array.dtype}"
            )
        map_u, map_v = self._undistort_maps
        # out[v, u] = image(map_u[v, u], map_v[v, u]), bilinear (or the chosen interpolation), 0 outside
        out = cv2.remap(
            np.ascontiguousarray(array), map_u, map_v, interpolation=interpolation,
            borderMode=cv2.BORDER_CONSTANT, borderValue=0,
        )
        if out.ndim == 2 and array.ndim == 3:  # OpenCV drops a trailing channel axis of length 1
            out = out[:, :, None]
        return out


#: Field of view (degrees, horizontal and vertical) that a pinhole calibration may give: narrower is no lens a
#: feature tracker can use (f > 28.6 x the image size), wider no pinhole model can describe (f < 0.088 x the size).
PLAUSIBLE_FOV_DEG = (2.0, 160.0)


def intrinsics_problem(camera: PinholeRadtan) -> str | None:
    """Return what is implausible about a calibration read from a file, or None.

    Checked against the image size: the principal point inside the image (``-0.5 <= cx <= width - 0.5``, the same for
    cy: a point outside is a calibration for another resolution, or fx fy cx cy in another order); focal lengths that
    give a field of view within :data:`PLAUSIBLE_FOV_DEG` (``fov = 2 atan(size / (2 f))``); ``fy / fx`` within
    [0.5, 2] (pixels are close to square). Readers call it on every calibration file; constructing a camera does
    not (tests and simulations may build any camera).

    >>> intrinsics_problem(PinholeRadtan(fx=199.1, fy=198.8, cx=132.2, cy=110.7, width=240, height=180)) is None
    True
    >>> intrinsics_problem(PinholeRadtan(fx=199.1, fy=198.8, cx=367.2, cy=248.4, width=240, height=180))
    'principal point (cx, cy) = (367.2, 248.4) lies outside the 240 x 180 image (expected -0.5 <= cx <= 239.5, -0.5 <= cy <= 179.5): a calibration for another resolution, or the values in another order (fx fy cx cy)?'
    """
    w, h = camera.width, camera.height
    if not (-0.5 <= camera.cx <= w - 0.5 and -0.5 <= camera.cy <= h - 0.5):
        return (f"principal point (cx, cy) = ({camera.cx:g}, {camera.cy:g}) lies outside the {w} x {h} image (expected "
                f"-0.5 <= cx <= {w - 0.5:g}, -0.5 <= cy <= {h - 0.5:g}): a calibration for another resolution, or the "
                f"values in another order (fx fy cx cy)?")
    low, high = PLAUSIBLE_FOV_DEG
    for name, f, size in (("fx", camera.fx, w), ("fy", camera.fy, h)):
        fov = math.degrees(2.0 * math.atan(size / (2.0 * f)))
        if not low <= fov <= high:
            return (f"{name} = {f:g} px gives a field of view of {fov:.3g} degrees over {size} px; a pinhole calibration "
                    f"gives {low:g} to {high:g} degrees ({size / (2 * math.tan(math.radians(high / 2))):.3g} <= {name} <= "
                    f"{size / (2 * math.tan(math.radians(low / 2))):.4g} px): a calibration for another resolution or "
                    f"another unit?")
    if not 0.5 <= camera.fy / camera.fx <= 2.0:
        return f"fy / fx = {camera.fy / camera.fx:.3g} (fx {camera.fx:g}, fy {camera.fy:g}); pixels are close to square (0.5 .. 2)"
    return _distortion_problem(camera)


#: at the image's border the radial distortion factor r_d / r_u of a lens a radtan model describes lies within this
#: range (strong wide-angle lenses reach about 0.6; a fisheye needs another model)
PLAUSIBLE_DISTORTION_SCALE = (1.0 / 3.0, 3.0)


def _distortion_problem(camera: PinholeRadtan) -> str | None:
    """Return what is implausible about the distortion coefficients, or None.

    Along the border of the image (distorted pixels) the model is inverted (``undistort_normalized``) and applied
    again: the round trip must come back within 0.1 px (where it does not, the model folds: two rays land on one
    pixel), the distortion r_d(r) = r (1 + k1 r^2 + k2 r^4 + k3 r^6) must grow along every ray up to the border
    (d r_d / d r > 0; a fold otherwise), and the factor r_d / r_u at the border must lie within
    :data:`PLAUSIBLE_DISTORTION_SCALE`. ``k1 = 1e6`` fails the last (the image would span 0.9 degrees); coefficients
    in another order or unit, or of another model, fail one of them.
    """
    if not camera._has_distortion:
        return None
    w, h = camera.width, camera.height
    u = np.concatenate([np.linspace(-0.5, w - 0.5, 33), np.full(25, -0.5), np.full(25, w - 0.5)])
    v = np.concatenate([np.full(33, -0.5), np.linspace(-0.5, h - 0.5, 25), np.linspace(-0.5, h - 0.5, 25)])
    u, v = np.concatenate([u, u[:33]]), np.concatenate([v, np.full(33, h - 0.5)])
    xy_d = np.column_stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy])
    coefficients = (f"k1 {camera.k1:g}, k2 {camera.k2:g}, k3 {camera.k3:g}, p1 {camera.p1:g}, p2 {camera.p2:g}")
    with np.errstate(all="ignore"):
        xy_u = camera.undistort_normalized(xy_d)
        back = camera.distort_normalized(xy_u)
        error_px = np.hypot((back[:, 0] - xy_d[:, 0]) * camera.fx, (back[:, 1] - xy_d[:, 1]) * camera.fy)
        r_d, r_u = np.hypot(*xy_d.T), np.hypot(*xy_u.T)
    if not (np.all(np.isfinite(error_px)) and error_px.max() <= 0.1):
        return (f"the distortion ({coefficients}) cannot be inverted at the image border (round trip off by "
                f"{np.nanmax(error_px):.3g} px): it folds the image; coefficients in another order (k1 k2 p1 p2 k3) "
                f"or of another lens model?")
    r = np.linspace(0.0, float(r_u.max()), 200)
    grows = np.diff(r * (1 + camera.k1 * r ** 2 + camera.k2 * r ** 4 + camera.k3 * r ** 6))
    if np.any(grows <= 0):
        return (f"the radial distortion ({coefficients}) turns back before the image border (r_d stops growing at "
                f"r = {r[int(np.argmax(grows <= 0))]:.3g}): it folds the image; coefficients in another order "
                f"(k1 k2 p1 p2 k3) or of another lens model?")
    scale = r_d[r_u > 0] / r_u[r_u > 0]
    low, high = PLAUSIBLE_DISTORTION_SCALE
    if scale.size and not (low <= scale.min() and scale.max() <= high):
        worst = scale.min() if scale.min() < low else scale.max()
        return (f"the distortion ({coefficients}) scales the image border by {worst:.3g} (r_d / r_u; a lens the radtan "
                f"model describes stays within {low:.2g} to {high:g}): coefficients in another order or unit, or of "
                f"another lens model?")
    return None
