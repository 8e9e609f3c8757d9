"""The MSCKF filter state: IMU state, sliding window of camera poses, error-state covariance, error injection.

Nominal IMU state (thesis Eq. 21), JPL quaternion scalar last (see ``evio_lib.geometry.rotation``)::

    X_IMU = [q_GtoI, b_g, v_IinG, b_a, p_IinG]

Error state (thesis Eqs. 22, 26), 15 + 6N entries, in EXACTLY this order::

    x~ = [δθ (0:3), δb_g (3:6), δv (6:9), δb_a (9:12), δp (12:15),  δθ_C1, δp_C1,  ...,  δθ_CN, δp_CN]

Camera i occupies 15 + 6 i + (0:3) (attitude) and 15 + 6 i + (3:6) (position), i in insertion order.
Attitude errors follow thesis Eqs. 23-24: q_true = δq ⊗ q_est with δq ≈ [δθ/2, 1]; in this module the exact
δq = quat_from_rotvec(δθ) is used, so ``state_difference`` and ``inject_error`` are exact inverses. All other
errors are additive (x_true = x_est + δx). The same holds for camera attitudes: q_GtoC,true = δq(δθ_C) ⊗ q_GtoC,est.

States are immutable values (frozen dataclasses with read-only arrays): every operation returns a new state and never
modifies its inputs. ``*_null`` fields are the first-estimate copies used by the observability-constrained EKF of
S-MSCKF (Sun et al. 2018; thesis §3.3.8): the IMU's are the values predicted by the last propagation step, a camera's
are its pose at augmentation; error injection leaves them untouched.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from types import MappingProxyType
from typing import Iterable, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import (
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_to_rot,
    quat_to_rotvec,
    rot_to_quat,
)

__all__ = [
    "IMU_DIM",
    "CAMERA_DIM",
    "THETA",
    "BG",
    "VEL",
    "BA",
    "POS",
    "ImuState",
    "CameraState",
    "FilterState",
    "inject_error",
    "state_difference",
    "remove_camera_states",
    "symmetrize",
    "covariance_problem",
    "state_problem",
    "PSD_TOLERANCE",
    "SYMMETRY_TOLERANCE",
]

IMU_DIM = 15  # size of the IMU error state
CAMERA_DIM = 6  # size of one camera's error state [δθ_C, δp_C]
THETA, BG, VEL, BA, POS = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)  # IMU error blocks

_UNIT_TOL = 1e-6  # | |q| - 1 | allowed for a stored quaternion (then renormalised)
_SYM_RTOL = 1e-6  # relative asymmetry of P tolerated at construction
PSD_TOLERANCE = 1e-8  # smallest eigenvalue allowed for the correlation matrix of P is -PSD_TOLERANCE
SYMMETRY_TOLERANCE = 1e-6  # largest |C - C^T| allowed for the correlation matrix C of P


# ---------------------------------------------------------------------------------------------------------- checks
def _vec(x: ArrayLike, name: str, n: int = 3) -> NDArray[np.float64]:
    """Return a read-only float64 copy of x with shape (n,), finite; raise ValueError naming ``name`` otherwise."""
    try:
        arr = np.array(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape ({n},); got {x!r}") from exc
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values; got {arr}")
    arr.setflags(write=False)
    return arr


def _unit_quat(q: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return a read-only unit JPL quaternion (qw >= 0); raise ValueError if |q| is not 1 within 1e-6."""
    arr = _vec(q, name, 4)
    norm = float(np.linalg.norm(arr))
    if abs(norm - 1.0) > _UNIT_TOL:
        raise ValueError(
            f"{name} must be a unit quaternion [qx, qy, qz, qw] (|q| = 1 within 1e-6); got |q| = {norm:.9g}"
        )
    if abs(norm - 1.0) <= 1e-15 and arr[3] >= 0.0:
        return arr  # already unit with qw >= 0: keep the exact numbers (renormalising is not idempotent)
    out = quat_normalize(arr)
    out.setflags(write=False)
    return out


def _time(t: float, name: str) -> float:
    """Return t as a finite float; raise ValueError otherwise."""
    if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
        raise ValueError(f"{name} must be a finite time in seconds (float); got {t!r}")
    return float(t)


def _frozen(arr: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mark arr read-only and return it (arrays owned by a state)."""
    arr.setflags(write=False)
    return arr


def symmetrize(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the symmetric part (P + P^T) / 2 as a new array (removes round-off asymmetry of covariances).

    Args:
        P: (n, n) matrix.

    >>> symmetrize(np.array([[1.0, 2.0], [0.0, 1.0]]))
    array([[1., 1.],
           [1., 1.]])
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"P must be a square matrix of shape (n, n); got {P.shape}")
    return 0.5 * (P + P.T)


def covariance_problem(P: ArrayLike, psd_size: int | None = None) -> str | None:
    """Return None when P is a usable covariance, else one line saying what is wrong with it.

    Args:
        P: (n, n) covariance.
        psd_size: test positive semi-definiteness on the leading (psd_size, psd_size) block only (None: all of P).
            Finiteness, variances and symmetry are always tested on all of P.

    Usable means: finite; variances >= 0 (a zero variance with zero covariances); symmetric and positive
    semi-definite within tolerance, both judged on the correlation matrix C = D^-1/2 P D^-1/2 (D = diag P), so
    that variances of 1e-12 rad² and 1e4 m² weigh the same: max |C - C^T| <= SYMMETRY_TOLERANCE and
    λ_min(C) >= -PSD_TOLERANCE (tested by a Cholesky factorisation of C + PSD_TOLERANCE I, O(n³ / 3)).

    >>> covariance_problem(np.diag([1e-12, 1e4])) is None
    True
    >>> covariance_problem(np.array([[1.0, 2.0], [2.0, 1.0]]))   # |correlation| 2 > 1
    'P is not positive semi-definite (smallest eigenvalue of its correlation matrix -1 < -1e-08)'
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        return f"P must be a square matrix; got shape {P.shape}"
    finite = np.isfinite(P)
    if not finite.all():
        return f"P holds {int(P.size - np.count_nonzero(finite))} non-finite values (NaN/inf)"
    d = np.diagonal(P)
    if np.any(d < 0.0):
        i = int(np.argmin(d))
        return f"P has {int(np.count_nonzero(d < 0.0))} negative variances (smallest {d[i]:.3g} at index {i})"
    zero = d == 0.0
    if zero.any() and np.any(P[zero] != 0.0):
        i = int(np.flatnonzero(zero & np.any(P != 0.0, axis=1))[0])
        return f"P is not positive semi-definite (variance 0 at index {i} with non-zero covariances)"
    inv_sd = np.where(zero, 0.0, 1.0 / np.sqrt(np.where(zero, 1.0, d)))
    C = P * inv_sd[:, None] * inv_sd[None, :]  # correlation matrix (0 rows where the variance is 0)
    asym = float(np.abs(C - C.T).max()) if C.size else 0.0
    if asym > SYMMETRY_TOLERANCE:
        return f"P is not symmetric (max |C - C^T| of its correlation matrix {asym:.3g} > {SYMMETRY_TOLERANCE:g})"
    m = C.shape[0] if psd_size is None else min(int(psd_size), C.shape[0])
    block = 0.5 * (C[:m, :m] + C[:m, :m].T) + PSD_TOLERANCE * np.eye(m)
    try:
        np.linalg.cholesky(block)
    except np.linalg.LinAlgError:
        lam = float(np.linalg.eigvalsh(block).min()) - PSD_TOLERANCE
        return (f"P is not positive semi-definite (smallest eigenvalue of its correlation matrix {lam:.3g} < "
                f"-{PSD_TOLERANCE:g})")
    return None


# ---------------------------------------------------------------------------------------------------------- IMU
@dataclass(frozen=True, eq=False)
class ImuState:
    """Nominal IMU state X_IMU = [q_GtoI, b_g, v_IinG, b_a, p_IinG] at ``timestamp`` (thesis Eq. 21).

    Attributes:
        q_GtoI: (4,) unit JPL quaternion [qx, qy, qz, qw]; C(q_GtoI) = R_GtoI (v_I = R_GtoI v_G).
        b_g: (3,) gyroscope bias in I, rad/s.
        v_IinG: (3,) velocity of I in G, m/s.
        b_a: (3,) accelerometer bias in I, m/s^2.
        p_IinG: (3,) position of I's origin in G, m.
        timestamp: time of the state, s.
        q_GtoI_null, v_IinG_null, p_IinG_null: first estimates for the OC-EKF (S-MSCKF's *_null); default to the
            nominal values. Propagation sets them to the predicted state; updates leave them alone.

    >>> s = ImuState.from_pose(np.eye(3), [1.0, 2.0, 3.0], [0.0, 0.0, 0.0], timestamp=0.5)
    >>> s.q_GtoI, s.p_IinG_null
    (array([0., 0., 0., 1.]), array([1., 2., 3.]))
    """

    q_GtoI: NDArray[np.float64]
    b_g: NDArray[np.float64]
    v_IinG: NDArray[np.float64]
    b_a: NDArray[np.float64]
    p_IinG: NDArray[np.float64]
    timestamp: float
    q_GtoI_null: NDArray[np.float64] | None = None
    v_IinG_null: NDArray[np.float64] | None = None
    p_IinG_null: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        setattr_ = object.__setattr__
        setattr_(self, "q_GtoI", _unit_quat(self.q_GtoI, "q_GtoI"))
        for name in ("b_g", "v_IinG", "b_a", "p_IinG"):
            setattr_(self, name, _vec(getattr(self, name), name))
        setattr_(self, "timestamp", _time(self.timestamp, "timestamp"))
        setattr_(self, "q_GtoI_null",
                 self.q_GtoI if self.q_GtoI_null is None else _unit_quat(self.q_GtoI_null, "q_GtoI_null"))
        for name, nominal in (("v_IinG_null", self.v_IinG), ("p_IinG_null", self.p_IinG)):
            value = getattr(self, name)
            setattr_(self, name, nominal if value is None else _vec(value, name))

    @classmethod
    def from_pose(
        cls,
        R_ItoG: ArrayLike,
        p_IinG: ArrayLike,
        v_IinG: ArrayLike,
        timestamp: float,
        b_g: ArrayLike = (0.0, 0.0, 0.0),
        b_a: ArrayLike = (0.0, 0.0, 0.0),
    ) -> "ImuState":
        """Return an ImuState from an orientation matrix R_ItoG (3, 3), p_IinG, v_IinG (3,) and optional biases.

        q_GtoI = rot_to_quat(R_ItoG^T) (the JPL quaternion of R_GtoI). Raises ValueError if R_ItoG is not a rotation.
        """
        R = np.asarray(R_ItoG, dtype=np.float64)
        if R.shape != (3, 3):
            raise ValueError(f"R_ItoG must have shape (3, 3); got {R.shape}")
        return cls(rot_to_quat(R.T), b_g, v_IinG, b_a, p_IinG, timestamp)

    @property
    def R_GtoI(self) -> NDArray[np.float64]:
        """Return R_GtoI = C(q_GtoI) (3, 3)."""
        return quat_to_rot(self.q_GtoI)

    @property
    def R_ItoG(self) -> NDArray[np.float64]:
        """Return R_ItoG = C(q_GtoI)^T (3, 3)."""
        return quat_to_rot(self.q_GtoI).T


# ---------------------------------------------------------------------------------------------------------- camera
@dataclass(frozen=True, eq=False)
class CameraState:
    """One camera pose of the sliding window (thesis Eq. 25): q_GtoC, p_CinG, cloned at image ``timestamp``.

    Attributes:
        id: image / frame identifier (unique in a FilterState; the key feature observations refer to).
        timestamp: image time, s.
        q_GtoC: (4,) unit JPL quaternion with C(q_GtoC) = R_GtoC.
        p_CinG: (3,) camera optical centre in G, m.
        q_GtoC_null, p_CinG_null: first estimates for the OC-EKF (S-MSCKF): the pose at augmentation (default).
    """

    id: int
    timestamp: float
    q_GtoC: NDArray[np.float64]
    p_CinG: NDArray[np.float64]
    q_GtoC_null: NDArray[np.float64] | None = None
    p_CinG_null: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if isinstance(self.id, (bool, np.bool_)) or not isinstance(self.id, (int, np.integer)):
            raise ValueError(f"id must be an integer frame identifier; got {self.id!r}")
        setattr_ = object.__setattr__
        setattr_(self, "id", int(self.id))
        setattr_(self, "timestamp", _time(self.timestamp, "timestamp"))
        setattr_(self, "q_GtoC", _unit_quat(self.q_GtoC, "q_GtoC"))
        setattr_(self, "p_CinG", _vec(self.p_CinG, "p_CinG"))
        setattr_(self, "q_GtoC_null",
                 self.q_GtoC if self.q_GtoC_null is None else _unit_quat(self.q_GtoC_null, "q_GtoC_null"))
        setattr_(self, "p_CinG_null",
                 self.p_CinG if self.p_CinG_null is None else _vec(self.p_CinG_null, "p_CinG_null"))

    @property
    def R_GtoC(self) -> NDArray[np.float64]:
        """Return R_GtoC = C(q_GtoC) (3, 3)."""
        return quat_to_rot(self.q_GtoC)

    @property
    def R_CtoG(self) -> NDArray[np.float64]:
        """Return R_CtoG = C(q_GtoC)^T (3, 3)."""
        return quat_to_rot(self.q_GtoC).T


def _unchecked(cls: type, **values: object) -> object:
    """Return an instance of the frozen dataclass ``cls`` with ``values`` set, skipping __post_init__ (fast path).

    For this package's own hot paths only: every value must already be valid, arrays float64, owned and read-only.
    """
    obj = object.__new__(cls)
    for name, value in values.items():
        object.__setattr__(obj, name, value)
    return obj


def _camera_unchecked(
    id: int, timestamp: float, q_GtoC: NDArray[np.float64], p_CinG: NDArray[np.float64],
    q_null: NDArray[np.float64], p_null: NDArray[np.float64],
) -> CameraState:
    """Return a CameraState from already validated read-only arrays, skipping the checks (internal fast path)."""
    return _unchecked(CameraState, id=id, timestamp=timestamp, q_GtoC=q_GtoC, p_CinG=p_CinG, q_GtoC_null=q_null,
                      p_CinG_null=p_null)


# ---------------------------------------------------------------------------------------------------------- filter
@dataclass(frozen=True, eq=False)
class FilterState:
    """The whole filter state: IMU state, ordered camera window, covariance P (15 + 6N) and camera-IMU extrinsics.

    Attributes:
        imu: the nominal IMU state.
        cameras: read-only mapping camera id -> CameraState, in window order (oldest first); the i-th camera's
            error state is P[15 + 6 i : 21 + 6 i] (see ``camera_slice``).
        P: (15 + 6N, 15 + 6N) read-only error-state covariance in the order of thesis Eq. 26 (module docstring).
        R_CtoI: (3, 3) fixed rotation camera -> IMU (v_I = R_CtoI v_C).
        p_CinI: (3,) fixed camera centre in I, m.

    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), timestamp=0.0)
    >>> s = FilterState.initial(imu, np.eye(3), [0.1, 0.0, 0.0], np.eye(15))
    >>> s.dim, s.num_cameras, s.timestamp
    (15, 0, 0.0)
    """

    imu: ImuState
    cameras: Mapping[int, CameraState]
    P: NDArray[np.float64]
    R_CtoI: NDArray[np.float64]
    p_CinI: NDArray[np.float64]

    def __post_init__(self) -> None:
        if not isinstance(self.imu, ImuState):
            raise ValueError(f"imu must be an ImuState; got {type(self.imu).__name__}")
        if not isinstance(self.cameras, Mapping):
            raise ValueError(f"cameras must be a mapping id -> CameraState; got {type(self.cameras).__name__}")
        cams = dict(self.cameras)
        for key, cam in cams.items():
            if not isinstance(cam, CameraState) or cam.id != key:
                raise ValueError(
                    f"cameras must map each id to a CameraState with that id; got key {key!r} -> "
                    f"{getattr(cam, 'id', type(cam).__name__)!r}"
                )
        object.__setattr__(self, "cameras", MappingProxyType(cams))
        n = IMU_DIM + CAMERA_DIM * len(cams)
        try:
            P = np.array(self.P, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"P must be a numeric ({n}, {n}) covariance; got {type(self.P).__name__}") from exc
        if P.shape != (n, n):
            raise ValueError(f"P must have shape (15 + 6N, 15 + 6N) = ({n}, {n}) for N = {len(cams)}; got {P.shape}")
        if not np.all(np.isfinite(P)):
            raise ValueError("P must contain only finite values (no NaN/inf)")
        asym = float(np.abs(P - P.T).max())
        if asym > _SYM_RTOL * (1e-12 + float(np.abs(P).max())):
            raise ValueError(f"P must be symmetric (relative tol {_SYM_RTOL:g}); got max |P - P^T| = {asym:.3g}")
        object.__setattr__(self, "P", _frozen(P))
        R = np.array(self.R_CtoI, dtype=np.float64)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(f"R_CtoI must be a finite (3, 3) rotation matrix; got shape {R.shape}")
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or abs(np.linalg.det(R) - 1.0) > 1e-6:
            raise ValueError("R_CtoI must be a rotation matrix (R R^T = I, det R = 1 within 1e-6)")
        object.__setattr__(self, "R_CtoI", _frozen(R))
        object.__setattr__(self, "p_CinI", _vec(self.p_CinI, "p_CinI"))

    @classmethod
    def initial(
        cls, imu: ImuState, R_CtoI: ArrayLike, p_CinI: ArrayLike, P_imu: ArrayLike
    ) -> "FilterState":
        """Return a state with no camera poses and IMU covariance P_imu (15, 15) (config.initial_imu_covariance())."""
        return cls(imu, {}, P_imu, R_CtoI, p_CinI)

    # ---------------------------------------------------------------- sizes and indices
    @property
    def timestamp(self) -> float:
        """Return the time of the state (the IMU state's timestamp), s."""
        return self.imu.timestamp

    @property
    def num_cameras(self) -> int:
        """Return N, the number of camera poses in the window."""
        return len(self.cameras)

    @property
    def dim(self) -> int:
        """Return the error-state dimension 15 + 6N."""
        return IMU_DIM + CAMERA_DIM * len(self.cameras)

    @cached_property
    def camera_ids(self) -> tuple[int, ...]:
        """Return the camera ids in window (= covariance) order."""
        return tuple(self.cameras)

    @cached_property
    def _positions(self) -> dict[int, int]:
        return {cid: i for i, cid in enumerate(self.cameras)}

    def camera_index(self, camera_id: int) -> int:
        """Return the first error-state index 15 + 6 i of camera ``camera_id`` (its δθ_C; δp_C starts 3 later)."""
        try:
            return IMU_DIM + CAMERA_DIM * self._positions[camera_id]
        except (KeyError, TypeError):
            raise ValueError(
                f"camera_id must be one of the window's ids {self.camera_ids}; got {camera_id!r}"
            ) from None

    def camera_slice(self, camera_id: int) -> slice:
        """Return the slice of camera ``camera_id``'s 6 error states [δθ_C, δp_C] in P and dx."""
        start = self.camera_index(camera_id)
        return slice(start, start + CAMERA_DIM)

    @cached_property
    def camera_poses(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Return (q_GtoC (N, 4), p_CinG (N, 3)) of the window in order, stacked (read-only), for vectorised use."""
        q = np.array([c.q_GtoC for c in self.cameras.values()]).reshape(-1, 4)
        p = np.array([c.p_CinG for c in self.cameras.values()]).reshape(-1, 3)
        return _frozen(q), _frozen(p)

    @property
    def R_ItoC(self) -> NDArray[np.float64]:
        """Return R_ItoC = R_CtoI^T (3, 3)."""
        return self.R_CtoI.T.copy()

    @cached_property
    def q_ItoC(self) -> NDArray[np.float64]:
        """Return the JPL quaternion q_ItoC (4,) of R_ItoC (read-only; used by augmentation, Eq. 27)."""
        return _frozen(rot_to_quat(self.R_CtoI.T))

    # ---------------------------------------------------------------- convenience
    def replace(self, **changes: object) -> "FilterState":
        """Return a copy with some fields replaced (imu, cameras, P, R_CtoI, p_CinI), validated again."""
        return replace(self, **changes)

    def inject_error(self, dx: ArrayLike) -> "FilterState":
        """Return the state corrected by the error-state estimate dx (15 + 6N,); see the function ``inject_error``."""
        return inject_error(self, dx)

    def remove_camera_states(self, ids: Iterable[int]) -> "FilterState":
        """Return the state without cameras ``ids``; see the function ``remove_camera_states``."""
        return remove_camera_states(self, ids)


def _filter_state_unchecked(
    imu: ImuState, cameras: Mapping[int, CameraState], P: NDArray[np.float64], like: FilterState
) -> FilterState:
    """Return a FilterState with like's extrinsics, skipping the checks (internal fast path; P owned, symmetric).

    ``cameras`` must be a read-only mapping (e.g. ``like.cameras``) or a fresh dict, which is wrapped here.
    """
    if not isinstance(cameras, MappingProxyType):
        cameras = MappingProxyType(dict(cameras))
    out = _unchecked(FilterState, imu=imu, cameras=cameras, P=_frozen(P), R_CtoI=like.R_CtoI, p_CinI=like.p_CinI)
    if "q_ItoC" in like.__dict__:  # carry the cached extrinsic quaternion over (same extrinsics)
        out.__dict__["q_ItoC"] = like.__dict__["q_ItoC"]
    return out


def state_problem(state: "FilterState", psd_size: int | None = None) -> str | None:
    """Return None when the state is usable (finite nominal values, unit quaternions, usable P), else what is wrong.

    Args:
        state: the state to test.
        psd_size: as in :func:`covariance_problem` (None: the whole P is tested for positive semi-definiteness).

    The filter calls this after every propagation and update and refuses a step that fails it (``Msckf``).
    """
    imu = state.imu
    values = [imu.q_GtoI, imu.b_g, imu.v_IinG, imu.b_a, imu.p_IinG]
    if state.num_cameras:
        values.extend(state.camera_poses)
    for name, v in zip(("q_GtoI", "b_g", "v_IinG", "b_a", "p_IinG", "q_GtoC", "p_CinG"), values):
        if not np.all(np.isfinite(v)):
            return f"the state holds non-finite values in {name}"
    if not math.isfinite(state.timestamp):
        return "the state's timestamp is not finite"
    return covariance_problem(state.P, psd_size)


# ---------------------------------------------------------------------------------------------------------- operations
def _check_dx(state: FilterState, dx: ArrayLike, name: str) -> NDArray[np.float64]:
    if not isinstance(state, FilterState):
        raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
    try:
        arr = np.asarray(dx, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric vector of shape ({state.dim},); got {dx!r}") from exc
    if arr.shape != (state.dim,):
        raise ValueError(
            f"{name} must have shape (15 + 6N,) = ({state.dim},) for N = {state.num_cameras}; got {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values")
    return arr


def inject_error(state: FilterState, dx: ArrayLike) -> FilterState:
    """Return a new state with the error-state correction dx applied (the estimate moves toward x_est ⊞ dx).

    Args:
        state: current estimate.
        dx: (15 + 6N,) error-state estimate [δθ, δb_g, δv, δb_a, δp, (δθ_Ci, δp_Ci) for each camera in window
            order], radians / SI units, e.g. the Kalman update K r.

    Attitudes: q <- quat_from_rotvec(δθ) ⊗ q (thesis Eq. 23 with the exact δq whose first-order form is Eq. 24
    [δθ/2, 1]), renormalised; everything else additive. Timestamps, the OC first estimates (*_null), the
    covariance and the extrinsics are unchanged. Inverse of ``state_difference``.

    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), timestamp=0.0)
    >>> s = FilterState.initial(imu, np.eye(3), np.zeros(3), np.eye(15))
    >>> dx = np.zeros(15); dx[2] = 0.1; dx[12] = 1.0            # 0.1 rad about z, 1 m along x
    >>> s2 = inject_error(s, dx)
    >>> np.round(s2.imu.q_GtoI, 4), s2.imu.p_IinG
    (array([0.    , 0.    , 0.05  , 0.9988]), array([1., 0., 0.]))
    """
    dx = _check_dx(state, dx, "dx")
    imu = state.imu
    q_I = quat_normalize(quat_multiply(quat_from_rotvec(dx[THETA]), imu.q_GtoI))  # q <- δq(δθ) ⊗ q
    new_imu = replace(
        imu,
        q_GtoI=q_I,
        b_g=imu.b_g + dx[BG],
        v_IinG=imu.v_IinG + dx[VEL],
        b_a=imu.b_a + dx[BA],
        p_IinG=imu.p_IinG + dx[POS],
    )
    cameras: dict[int, CameraState] = {}
    if state.num_cameras:
        dcam = dx[IMU_DIM:].reshape(-1, CAMERA_DIM)
        q_C, p_C = state.camera_poses
        q_new = quat_normalize(quat_multiply(quat_from_rotvec(dcam[:, :3]), q_C))  # q_GtoC <- δq(δθ_C) ⊗ q_GtoC
        p_new = p_C + dcam[:, 3:]  # p_CinG <- p_CinG + δp_C
        for i, cam in enumerate(state.cameras.values()):
            cameras[cam.id] = _camera_unchecked(
                cam.id, cam.timestamp, _frozen(q_new[i].copy()), _frozen(p_new[i].copy()), cam.q_GtoC_null,
                cam.p_CinG_null,
            )
    return _filter_state_unchecked(new_imu, cameras, state.P, state)


def state_difference(state_true: FilterState, state_est: FilterState) -> NDArray[np.float64]:
    """Return the error state dx = x_true ⊟ x_est (15 + 6N,) in the order of thesis Eq. 26.

    Args:
        state_true: e.g. the ground truth (same camera ids, in the same order, as state_est).
        state_est: the estimate.

    δθ = rotvec(q_true ⊗ q_est^-1) (so q_true = quat_from_rotvec(δθ) ⊗ q_est, thesis Eq. 23), other blocks
    x_true - x_est. ``inject_error(state_est, state_difference(state_true, state_est))`` reproduces state_true's
    nominal values (for |δθ| < π). Useful for NEES and Monte-Carlo checks.
    """
    for name, s in (("state_true", state_true), ("state_est", state_est)):
        if not isinstance(s, FilterState):
            raise ValueError(f"{name} must be a FilterState; got {type(s).__name__}")
    if state_true.camera_ids != state_est.camera_ids:
        raise ValueError(
            "state_true and state_est must hold the same camera ids in the same order; "
            f"got {state_true.camera_ids} and {state_est.camera_ids}"
        )
    a, b = state_true.imu, state_est.imu
    dx = np.empty(state_est.dim)
    dx[THETA] = quat_to_rotvec(quat_multiply(a.q_GtoI, quat_inverse(b.q_GtoI)))
    dx[BG] = a.b_g - b.b_g
    dx[VEL] = a.v_IinG - b.v_IinG
    dx[BA] = a.b_a - b.b_a
    dx[POS] = a.p_IinG - b.p_IinG
    if state_est.num_cameras:
        qa, pa = state_true.camera_poses
        qb, pb = state_est.camera_poses
        dcam = dx[IMU_DIM:].reshape(-1, CAMERA_DIM)
        dcam[:, :3] = quat_to_rotvec(quat_multiply(qa, quat_inverse(qb)))
        dcam[:, 3:] = pa - pb
    return dx


def remove_camera_states(state: FilterState, ids: Iterable[int]) -> FilterState:
    """Return a new state without the camera poses ``ids``: their 6 rows and columns are deleted from P.

    Args:
        state: current state.
        ids: camera ids to remove (each must be in the window; repeats are ignored; may be empty).

    Marginalising a Gaussian = dropping its rows/columns; the remaining cameras keep their order.

    >>> from evio_lib.msckf.augmentation import augment_state
    >>> imu = ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), timestamp=0.0)
    >>> s = augment_state(augment_state(FilterState.initial(imu, np.eye(3), np.zeros(3), np.eye(15)), 7), 8)
    >>> r = remove_camera_states(s, [7])
    >>> r.camera_ids, r.P.shape
    ((8,), (21, 21))
    """
    if not isinstance(state, FilterState):
        raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
    if isinstance(ids, (int, np.integer)):
        raise ValueError(f"ids must be an iterable of camera ids, e.g. [3, 4]; got the single value {ids!r}")
    drop = set()
    for cid in ids:
        if cid not in state.cameras:
            raise ValueError(f"ids must be camera ids in the window {state.camera_ids}; got {cid!r}")
        drop.add(int(cid))
    if not drop:
        return state
    keep = np.ones(state.dim, dtype=bool)
    for cid in drop:
        keep[state.camera_slice(cid)] = False
    idx = np.flatnonzero(keep)
    cameras = {cid: cam for cid, cam in state.cameras.items() if cid not in drop}
    return _filter_state_unchecked(state.imu, cameras, state.P[np.ix_(idx, idx)], state)
