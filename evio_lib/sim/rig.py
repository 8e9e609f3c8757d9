"""Camera-IMU extrinsics of the simulated rig: the fixed transform between the IMU frame I and the camera frame C.

Frames (project conventions): I = IMU/body, C = camera (x right, y down, z forward along the optical axis),
G = world. ``R_CtoI`` rotates camera vectors into the IMU frame (v_I = R_CtoI @ v_C) and ``p_CinI`` is the camera
centre expressed in I, so a point maps as ``x_I = R_CtoI @ x_C + p_CinI``. Reference: thesis §3.3.2, Eq. 27-28
(camera pose from the IMU pose and the camera-IMU transform).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import so3_exp

__all__ = ["CameraImuExtrinsics"]

_ROT_TOL = 1e-6  # tolerance on R R^T = I and det R = 1


def _as_rotation(R: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return R as a read-only float64 (3, 3) rotation matrix; raise ValueError naming ``name`` otherwise."""
    arr = np.array(R, dtype=np.float64)
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must have shape (3, 3); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values; got non-finite entries")
    orth = float(np.abs(arr @ arr.T - np.eye(3)).max())
    det = float(np.linalg.det(arr))
    if orth > _ROT_TOL or abs(det - 1.0) > _ROT_TOL:
        raise ValueError(
            f"{name} must be a rotation matrix (R @ R.T == I, det 1, tol {_ROT_TOL:g}); "
            f"got max |R R^T - I| = {orth:.3g}, det = {det:.6g}"
        )
    arr.setflags(write=False)
    return arr


def _as_vector3(p: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return p as a read-only float64 (3,) vector; raise ValueError naming ``name`` otherwise."""
    arr = np.array(p, dtype=np.float64)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have shape (3,); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values; got {arr}")
    arr.setflags(write=False)
    return arr


def _as_poses(R: ArrayLike, p: ArrayLike, name_R: str, name_p: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (R (N,3,3), p (N,3)) float64 from one pose or a batch; raise ValueError on bad shapes."""
    R_arr = np.asarray(R, dtype=np.float64)
    p_arr = np.asarray(p, dtype=np.float64)
    if R_arr.ndim < 2 or R_arr.shape[-2:] != (3, 3):
        raise ValueError(f"{name_R} must have shape (3, 3) or (N, 3, 3); got {R_arr.shape}")
    if p_arr.ndim < 1 or p_arr.shape[-1] != 3:
        raise ValueError(f"{name_p} must have shape (3,) or (N, 3); got {p_arr.shape}")
    if R_arr.shape[:-2] != p_arr.shape[:-1]:
        raise ValueError(
            f"{name_R} and {name_p} must have matching leading dimensions; got {R_arr.shape} and {p_arr.shape}"
        )
    return R_arr, p_arr


@dataclass(frozen=True, eq=False)
class CameraImuExtrinsics:
    """Rigid camera-to-IMU transform: ``x_I = R_CtoI @ x_C + p_CinI``.

    Attributes:
        R_CtoI: (3, 3) rotation from the camera frame C into the IMU frame I.
        p_CinI: (3,) camera optical centre expressed in I, metres.

    Reference: thesis §3.3.2 (camera-IMU transform in the MSCKF state augmentation, Eq. 27-28).

    >>> ext = CameraImuExtrinsics(np.eye(3), [0.1, 0.0, 0.0])
    >>> R_CtoG, p_CinG = ext.camera_pose(np.eye(3), [1.0, 2.0, 3.0])
    >>> p_CinG
    array([1.1, 2. , 3. ])
    """

    R_CtoI: NDArray[np.float64]
    p_CinI: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, "R_CtoI", _as_rotation(self.R_CtoI, "R_CtoI"))
        object.__setattr__(self, "p_CinI", _as_vector3(self.p_CinI, "p_CinI"))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraImuExtrinsics):
            return NotImplemented
        return bool(np.array_equal(self.R_CtoI, other.R_CtoI) and np.array_equal(self.p_CinI, other.p_CinI))

    @property
    def R_ItoC(self) -> NDArray[np.float64]:
        """Return R_ItoC (3, 3) = R_CtoI^T, rotating IMU vectors into the camera frame."""
        return self.R_CtoI.T.copy()

    @property
    def p_IinC(self) -> NDArray[np.float64]:
        """Return p_IinC (3,) = -R_ItoC @ p_CinI, the IMU origin expressed in the camera frame."""
        return -self.R_CtoI.T @ self.p_CinI

    def camera_pose(self, R_ItoG: ArrayLike, p_IinG: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Return the camera pose (R_CtoG, p_CinG) for IMU pose(s) (R_ItoG, p_IinG).

        Args:
            R_ItoG: (3, 3) or (N, 3, 3) IMU orientation in the world.
            p_IinG: (3,) or (N, 3) IMU position in the world, metres.

        Returns:
            R_CtoG (..., 3, 3) = R_ItoG @ R_CtoI and p_CinG (..., 3) = p_IinG + R_ItoG @ p_CinI (thesis Eq. 27-28).
        """
        R, p = _as_poses(R_ItoG, p_IinG, "R_ItoG", "p_IinG")
        R_CtoG = R @ self.R_CtoI  # R_CtoG = R_ItoG R_CtoI
        p_CinG = p + R @ self.p_CinI  # p_CinG = p_IinG + R_ItoG p_CinI
        return R_CtoG, p_CinG

    def imu_pose(self, R_CtoG: ArrayLike, p_CinG: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Return the IMU pose (R_ItoG, p_IinG) for camera pose(s) (R_CtoG, p_CinG); inverse of ``camera_pose``.

        Args:
            R_CtoG: (3, 3) or (N, 3, 3) camera orientation in the world.
            p_CinG: (3,) or (N, 3) camera centre in the world, metres.

        Returns:
            R_ItoG (..., 3, 3) = R_CtoG @ R_ItoC and p_IinG (..., 3) = p_CinG - R_ItoG @ p_CinI.
        """
        R, p = _as_poses(R_CtoG, p_CinG, "R_CtoG", "p_CinG")
        R_ItoG = R @ self.R_CtoI.T  # R_ItoG = R_CtoG R_ItoC
        p_IinG = p - R_ItoG @ self.p_CinI  # p_IinG = p_CinG - R_ItoG p_CinI
        return R_ItoG, p_IinG

    @classmethod
    def default(cls) -> "CameraImuExtrinsics":
        """Return DAVIS-like extrinsics: camera and IMU nearly aligned (a rotation of ~2.5 deg) and ~3.3 cm apart.

        R_CtoI = exp([0.02, -0.035, 0.015] x) and p_CinI = [0.03, -0.012, 0.008] m: a deliberately non-identity
        calibration, like the small mounting offsets of a real DAVIS240C's IMU, so that code which ignores the
        extrinsics fails the tests.

        >>> ext = CameraImuExtrinsics.default()
        >>> round(float(np.degrees(np.arccos((np.trace(ext.R_CtoI) - 1) / 2))), 2)
        2.46
        """
        return cls(R_CtoI=so3_exp(np.array([0.02, -0.035, 0.015])), p_CinI=np.array([0.03, -0.012, 0.008]))

    @classmethod
    def identity(cls) -> "CameraImuExtrinsics":
        """Return the identity extrinsics (camera frame = IMU frame), handy for lessons and unit tests."""
        return cls(R_CtoI=np.eye(3), p_CinI=np.zeros(3))

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-able dict {"R_CtoI": 3x3 nested list, "p_CinI": list of 3 floats}."""
        return {"R_CtoI": self.R_CtoI.tolist(), "p_CinI": self.p_CinI.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "CameraImuExtrinsics":
        """Return extrinsics from a dict made by ``to_dict`` (keys "R_CtoI" and "p_CinI")."""
        if not isinstance(data, dict) or "R_CtoI" not in data or "p_CinI" not in data:
            keys = sorted(data) if isinstance(data, dict) else type(data).__name__
            raise ValueError(f"data must be a dict with keys 'R_CtoI' and 'p_CinI'; got {keys}")
        return cls(R_CtoI=np.asarray(data["R_CtoI"], dtype=float), p_CinI=np.asarray(data["p_CinI"], dtype=float))
