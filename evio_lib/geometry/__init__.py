"""Geometry: rotations (JPL quaternions), the pinhole-radtan camera, epipolar geometry and homographies.

The names a student uses are listed by ``dir(evio_lib.geometry)`` and imported on first use; the rest live in the
submodules, e.g. ``from evio_lib.geometry.homography import ...``.
"""
from __future__ import annotations

from evio_lib.lazy_exports import lazy_exports

#: name -> submodule of the names this package offers, imported on first use (PEP 562)
_EXPORTS = {
    "PinholeRadtan": "camera", "quat_to_rot": "rotation", "rot_to_quat": "rotation", "quat_multiply": "rotation",
    "so3_exp": "rotation", "so3_log": "rotation", "skew": "rotation", "observation_covariance": "pixel_noise",
    "undistortion_noise_factor": "pixel_noise", "essential_from_pose": "epipolar",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
