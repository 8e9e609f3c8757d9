"""Pixel noise seen through the camera model: the covariance of an undistorted, normalised observation.

A feature is measured in distorted pixels (u, v) with isotropic noise n ~ N(0, sigma_px^2 I); the filter uses the
undistorted normalised coordinates (x, y) = unproject(u, v). To first order

    delta(x, y) = J n,   J = d(x, y)/d(u, v) = D^-1,   D = d(u, v)/d(x, y),

so the observation's covariance is Sigma = sigma_px^2 J J^T (:func:`observation_covariance`); without distortion
Sigma = sigma_px^2 diag(1/fx^2, 1/fy^2). :func:`undistortion_noise_factor` is the RMS stretch of the noise over the
image, sqrt(mean tr(J J^T) / 2) f with f = sqrt(fx fy): one number for a filter that uses one isotropic noise.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.camera import PinholeRadtan

__all__ = ["observation_covariance", "undistortion_noise_factor"]


def undistortion_noise_factor(camera: PinholeRadtan, step_px: float = 4.0) -> float:
    """Return the RMS stretch of pixel noise by undistortion: sqrt(mean tr(J J^T) / 2) f over the image.

    J = d(x, y)/d(u, v) (2, 2) of ``camera.unproject`` by central differences on a grid of pixels ``step_px``
    apart (5 px inside the border), f = sqrt(fx fy). An undistorted camera gives 1.

    >>> round(undistortion_noise_factor(PinholeRadtan.davis240c()), 2)
    1.19
    """
    border = 5.0
    u = np.arange(border, camera.width - 1 - border + 1e-9, step_px)
    v = np.arange(border, camera.height - 1 - border + 1e-9, step_px)
    uv = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    h = 1e-3
    J_u = (camera.unproject(uv + [h, 0.0]) - camera.unproject(uv - [h, 0.0])) / (2 * h)  # d(x, y)/du
    J_v = (camera.unproject(uv + [0.0, h]) - camera.unproject(uv - [0.0, h])) / (2 * h)  # d(x, y)/dv
    trace = np.sum(J_u**2, axis=1) + np.sum(J_v**2, axis=1)  # tr(J J^T)
    return float(np.sqrt(trace.mean() / 2.0) * math.sqrt(camera.fx * camera.fy))


def observation_covariance(camera: PinholeRadtan, uv: ArrayLike, sigma_px: float) -> NDArray[np.float64]:
    """Return (N, 2, 2) covariances Σ = σ_px² J J^T of undistorted normalised coordinates of noisy pixels.

    Args:
        camera: the (distorting) camera model that maps normalised coordinates to pixels.
        uv: (N, 2) distorted pixel coordinates (x = column, y = row) at which the noise is linearised.
        sigma_px: std of the isotropic Gaussian pixel noise, pixels (> 0).

    J = d(x, y)/d(u, v) is the Jacobian of ``camera.unproject``; as unproject inverts the projection,
    J = D^-1 with D = d(u, v)/d(x, y) = diag(fx, fy) d(x_d, y_d)/d(x, y), the first two columns of
    ``camera.projection_jacobian`` at the point [x, y, 1] (Z = 1, so d/dX = d/dx). First order: a pixel error n
    ~ N(0, σ² I) gives δ(x, y) = J n ~ N(0, σ² J J^T). Without distortion Σ = σ² diag(1/fx², 1/fy²).

    >>> cam = PinholeRadtan.davis240c()
    >>> cov = observation_covariance(cam, np.array([[cam.cx, cam.cy], [5.0, 5.0]]), 1.0)  # principal point, corner
    >>> (np.sqrt(np.diagonal(cov, axis1=1, axis2=2)) * 199.0).round(2).tolist()  # std in pixels at f = 199 px
    [[1.0, 1.0], [1.34, 1.33]]
    """
    pixels = np.asarray(uv, dtype=np.float64)
    if pixels.ndim != 2 or pixels.shape[1] != 2:
        raise ValueError(f"uv must have shape (N, 2) distorted pixels (x, y); got {pixels.shape}")
    if not np.all(np.isfinite(pixels)):
        raise ValueError("uv must contain only finite values (no NaN/inf)")
    if isinstance(sigma_px, bool) or not isinstance(sigma_px, (int, float, np.integer, np.floating)) \
            or not math.isfinite(sigma_px) or sigma_px <= 0:
        raise ValueError(f"sigma_px must be a finite number > 0 (pixels); got {sigma_px!r}")
    if pixels.shape[0] == 0:
        return np.zeros((0, 2, 2))
    xy = camera.unproject(pixels)  # undistorted normalised (x, y)
    D = camera.projection_jacobian(np.column_stack([xy, np.ones(len(xy))]))[:, :, :2]  # d(u, v)/d(x, y) at Z = 1
    J = np.linalg.inv(D)  # d(x, y)/d(u, v)
    return float(sigma_px) ** 2 * (J @ np.swapaxes(J, 1, 2))  # Σ = σ² J J^T
