"""The in-memory recording: events, frames, IMU samples, ground truth and calibration of one sequence.

Every reader of :mod:`evio_lib.io` (ECD, EuRoC, AEDAT4, npz cache) and the simulator produce a
:class:`Sequence`; every estimator consumes one. Frames and conventions (project-wide):

* G world (z up, gravity [0, 0, -9.81] m/s^2), I IMU/body, C camera (x right, y down, z forward);
* ``q_GtoB`` are JPL quaternions, scalar last: C(q_GtoB) = R_GtoB (see :mod:`evio_lib.geometry.rotation`);
* timestamps are float64 seconds, events use :data:`evio_lib.events.array.EVENT_DTYPE`;
* frames are the raw uint8 images of the sensor (convert to float32 [0, 1] where they are used).

Reference: thesis §3.3 (state of the IMU and camera poses), §2.2.1 (events).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from evio_lib.events.array import EVENT_DTYPE, empty_events, events_between, validate_events
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import quat_to_rot

__all__ = ["ImuSamples", "GroundTruth", "Sequence"]

_UNIT_TOL = 1e-6  # tolerance on |q| - 1 and on R R^T - I, det R - 1
_BODIES = ("camera", "imu")


def _float_array(value: Any, name: str, tail: tuple[int, ...]) -> np.ndarray:
    """Return ``value`` as a float64 array of shape (N, *tail); raise ValueError naming ``name`` otherwise."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape (N{''.join(f', {d}' for d in tail)}); got {value!r}") from exc
    if arr.ndim != 1 + len(tail) or arr.shape[1:] != tail:
        raise ValueError(f"{name} must have shape (N{''.join(f', {d}' for d in tail)}); got {arr.shape}")
    return arr


def _check_times(t: np.ndarray, name: str) -> None:
    """Raise ValueError unless ``t`` is finite and strictly increasing."""
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name} must be finite; got non-finite values at indices {np.flatnonzero(~np.isfinite(t))[:5].tolist()}")
    bad = np.flatnonzero(t[1:] <= t[:-1])
    if bad.size:
        i = int(bad[0]) + 1
        raise ValueError(f"{name} must be strictly increasing; got {name}[{i}] = {float(t[i])!r} after {name}[{i - 1}] = {float(t[i - 1])!r}")


def _float_array_any(value: Any, name: str, expected: str) -> np.ndarray:
    """Return ``value`` as a float64 array (any shape); raise ValueError naming ``name`` and ``expected`` otherwise."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {expected}; got {value!r}") from None


def _check_finite(values: np.ndarray, name: str) -> None:
    """Raise ValueError naming ``name`` if ``values`` holds NaN or inf."""
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad.reshape(len(values), -1).any(axis=1))[0])
        raise ValueError(f"{name} must be finite; got a non-finite value in row {row}")


def _time_mask(t: np.ndarray, t0: float, t1: float, name: str = "t") -> slice:
    """Return the slice of sorted times ``t`` with t0 <= t < t1; raise ValueError if ``t`` is not sorted.

    The binary search is only right on sorted times, so the order is checked first (O(N), cheap next to a copy).
    """
    bad = np.flatnonzero(t[1:] < t[:-1])
    if bad.size:
        raise ValueError(f"{name} must be sorted by time to slice it; {name}[{int(bad[0]) + 1}] < {name}[{int(bad[0])}] "
                         f"({bad.size} out-of-order values)")
    i0, i1 = np.searchsorted(t, [t0, t1], side="left")
    return slice(int(i0), int(i1))


_EVENTS_EXPECTED = ("a 1-D NumPy array of dtype EVENT_DTYPE (t float64 [s], x and y uint16, p int8 +1/-1) sorted by t; "
                    "build one with evio_lib.events.array.make_events(t, x, y, p)")


def _check_event_array(events: Any) -> None:
    """Raise ValueError unless ``events`` is a 1-D EVENT_DTYPE array, finite, sorted by t, polarities +1/-1.

    The message says what was given and how to convert it (make_events, or a stable sort by t).
    """
    if not isinstance(events, np.ndarray):
        raise ValueError(f"events must be {_EVENTS_EXPECTED}; got {type(events).__name__}")
    if events.dtype != EVENT_DTYPE or events.ndim != 1:
        if events.dtype.names is None and events.ndim == 2 and events.shape[1] == 4:
            hint = "; for columns (t, x, y, p) use make_events(a[:, 0], a[:, 1], a[:, 2], a[:, 3])"
        elif events.dtype.names is not None and {"t", "x", "y", "p"} <= set(events.dtype.names):
            hint = "; convert with make_events(ev['t'], ev['x'], ev['y'], ev['p'])"
        else:
            hint = ""
        raise ValueError(f"events must be {_EVENTS_EXPECTED}; got an array of dtype {events.dtype} and shape "
                         f"{events.shape}{hint}")
    t = events["t"]
    bad = np.flatnonzero(t[1:] < t[:-1])
    if bad.size:
        raise ValueError(
            f"events must be sorted by time; found {bad.size} out-of-order timestamps starting at index {int(bad[0]) + 1}; "
            f"sort them with events[np.argsort(events['t'], kind='stable')]"
        )
    try:
        validate_events(events)
    except ValueError as exc:
        raise ValueError(f"events: {exc}") from None


def _check_rotation(R: np.ndarray, name: str) -> None:
    """Raise ValueError unless ``R`` is a finite (3, 3) rotation matrix (R R^T = I, det R = 1, tolerance 1e-6)."""
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"{name} must be a finite (3, 3) rotation matrix; got shape {R.shape}")
    if np.abs(R @ R.T - np.eye(3)).max() > _UNIT_TOL or abs(np.linalg.det(R) - 1.0) > _UNIT_TOL:
        raise ValueError(f"{name} must be a rotation matrix (R R^T = I, det 1, tol {_UNIT_TOL:g}); got det {np.linalg.det(R):.6g}")


@dataclass
class ImuSamples:
    """IMU measurements in the IMU frame I.

    Attributes:
        t: (N,) timestamps [s], strictly increasing.
        gyro: (N, 3) angular velocity w_I [rad/s].
        accel: (N, 3) specific force a_I [m/s^2] (reads +9.81 upwards when still).

    Reference: thesis §3.3.3 (IMU measurement model).

    >>> imu = ImuSamples(t=[0.0, 0.005], gyro=np.zeros((2, 3)), accel=[[0, 0, 9.81]] * 2)
    >>> len(imu), imu.accel.shape
    (2, (2, 3))
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray

    def __post_init__(self) -> None:
        self.t = _float_array(self.t, "imu.t", ())
        self.gyro = _float_array(self.gyro, "imu.gyro", (3,))
        self.accel = _float_array(self.accel, "imu.accel", (3,))
        n = self.t.shape[0]
        for name in ("gyro", "accel"):
            if getattr(self, name).shape[0] != n:
                raise ValueError(f"imu.{name} must have shape ({n}, 3) like imu.t; got {getattr(self, name).shape}")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def validate(self, prefix: str = "imu") -> None:
        """Return None if times are strictly increasing and all values finite; else raise ValueError naming the field."""
        _check_times(self.t, f"{prefix}.t")
        _check_finite(self.gyro, f"{prefix}.gyro")
        _check_finite(self.accel, f"{prefix}.accel")

    def slice_time(self, t0: float, t1: float) -> "ImuSamples":
        """Return a copy of the samples with t0 <= t < t1 (ValueError if the times are not sorted)."""
        s = _time_mask(self.t, t0, t1, "imu.t")
        return ImuSamples(self.t[s].copy(), self.gyro[s].copy(), self.accel[s].copy())


_GT_OPTIONAL = ("v_BinG", "bias_gyro", "bias_accel")


@dataclass
class GroundTruth:
    """Poses (and optionally velocity and IMU biases) of a body frame B in the world G.

    Attributes:
        t: (K,) timestamps [s], strictly increasing.
        p_BinG: (K, 3) position of B's origin in G [m].
        q_GtoB: (K, 4) JPL quaternions (scalar last) with C(q_GtoB) = R_GtoB.
        body: "camera" (B = C) or "imu" (B = I).
        v_BinG: optional (K, 3) velocity of B in G [m/s].
        bias_gyro: optional (K, 3) gyroscope bias [rad/s].
        bias_accel: optional (K, 3) accelerometer bias [m/s^2].

    Reference: thesis §3.3.1-3.3.2 (JPL attitude, IMU state).

    >>> gt = GroundTruth(t=[0.0, 1.0], p_BinG=[[0, 0, 0], [1, 0, 0]], q_GtoB=[[0, 0, 0, 1]] * 2, body="imu")
    >>> gt.interpolate([0.25]).p_BinG.round(3).tolist()
    [[0.25, 0.0, 0.0]]
    """

    t: np.ndarray
    p_BinG: np.ndarray
    q_GtoB: np.ndarray
    body: str = "camera"
    v_BinG: np.ndarray | None = None
    bias_gyro: np.ndarray | None = None
    bias_accel: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.body not in _BODIES:
            raise ValueError(f"body must be one of {_BODIES}; got {self.body!r}")
        self.t = _float_array(self.t, "groundtruth.t", ())
        self.p_BinG = _float_array(self.p_BinG, "groundtruth.p_BinG", (3,))
        self.q_GtoB = _float_array(self.q_GtoB, "groundtruth.q_GtoB", (4,))
        for name in _GT_OPTIONAL:
            if getattr(self, name) is not None:
                setattr(self, name, _float_array(getattr(self, name), f"groundtruth.{name}", (3,)))
        k = self.t.shape[0]
        for name in ("p_BinG", "q_GtoB", *_GT_OPTIONAL):
            value = getattr(self, name)
            if value is not None and value.shape[0] != k:
                raise ValueError(f"groundtruth.{name} must have {k} rows like groundtruth.t; got shape {value.shape}")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def R_BtoG(self) -> np.ndarray:
        """Return the (K, 3, 3) rotations R_BtoG = C(q_GtoB)^T (body orientation in the world)."""
        return np.swapaxes(quat_to_rot(self.q_GtoB), -1, -2)

    def validate(self, prefix: str = "groundtruth", *, unit_quaternions: bool = True) -> None:
        """Return None if times increase strictly, values are finite and quaternions unit; else raise ValueError.

        Args:
            prefix: how messages name this ground truth.
            unit_quaternions: also check |q| = 1 within 1e-6 (Sequence construction checks the rest only).
        """
        _check_times(self.t, f"{prefix}.t")
        for name in ("p_BinG", "q_GtoB", *_GT_OPTIONAL):
            if getattr(self, name) is not None:
                _check_finite(getattr(self, name), f"{prefix}.{name}")
        if not unit_quaternions:
            return
        norm_err = np.abs(np.linalg.norm(self.q_GtoB, axis=1) - 1.0)
        if np.any(norm_err > _UNIT_TOL):
            row = int(np.argmax(norm_err))
            raise ValueError(f"{prefix}.q_GtoB must hold unit quaternions (tol {_UNIT_TOL:g}); row {row} has norm error {norm_err[row]:.3g}")

    def slice_time(self, t0: float, t1: float) -> "GroundTruth":
        """Return a copy of the samples with t0 <= t < t1 (ValueError if the times are not sorted)."""
        s = _time_mask(self.t, t0, t1, "groundtruth.t")
        parts = {name: (None if getattr(self, name) is None else getattr(self, name)[s].copy())
                 for name in ("t", "p_BinG", "q_GtoB", *_GT_OPTIONAL)}
        return GroundTruth(body=self.body, **parts)

    def interpolate(self, t: Any) -> "GroundTruth":
        """Return the ground truth at times ``t``: linear in position/velocity/biases, slerp in rotation.

        Args:
            t: scalar or (M,) query times [s] within [self.t[0], self.t[-1]] (no extrapolation).

        Slerp between neighbours q0, q1 (sign of q1 flipped so that q0 . q1 >= 0, angle cos(th) = q0 . q1)::

            q(a) = sin((1 - a) th) / sin(th) q0 + sin(a th) / sin(th) q1,   a = (t - t0) / (t1 - t0)

        It follows the shortest rotation between the two samples at constant angular rate (Shoemake 1985);
        on the unit sphere the formula is the same for JPL and Hamilton quaternions.
        """
        tq = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if tq.ndim != 1:
            raise ValueError(f"t must be a scalar or have shape (M,); got {np.shape(t)}")
        if len(self) == 0:
            raise ValueError("groundtruth is empty; nothing to interpolate")
        if not np.all(np.isfinite(tq)) or np.any(tq < self.t[0]) or np.any(tq > self.t[-1]):
            raise ValueError(
                f"t must lie within the ground-truth time range [{float(self.t[0])!r}, {float(self.t[-1])!r}]; "
                f"got values in [{float(tq.min())!r}, {float(tq.max())!r}]"
            )
        if len(self) == 1:
            i = np.zeros(tq.shape, dtype=np.int64)
            j, a = i, np.zeros(tq.shape)
        else:
            i = np.clip(np.searchsorted(self.t, tq, side="right") - 1, 0, len(self) - 2)
            j = i + 1
            a = (tq - self.t[i]) / (self.t[j] - self.t[i])  # a = (t - t_i) / (t_{i+1} - t_i)

        def lerp(values: np.ndarray | None) -> np.ndarray | None:
            return None if values is None else (1.0 - a)[:, None] * values[i] + a[:, None] * values[j]

        q0, q1 = self.q_GtoB[i], self.q_GtoB[j]
        dot = np.sum(q0 * q1, axis=1)
        q1 = np.where(dot[:, None] < 0.0, -q1, q1)  # q and -q are the same rotation: take the short way
        theta = np.arccos(np.clip(np.abs(dot), -1.0, 1.0))
        small = theta < 1e-9
        sin_theta = np.where(small, 1.0, np.sin(theta))
        w0 = np.where(small, 1.0 - a, np.sin((1.0 - a) * theta) / sin_theta)
        w1 = np.where(small, a, np.sin(a * theta) / sin_theta)
        q = w0[:, None] * q0 + w1[:, None] * q1
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        return GroundTruth(t=tq, p_BinG=lerp(self.p_BinG), q_GtoB=q, body=self.body, v_BinG=lerp(self.v_BinG),
                           bias_gyro=lerp(self.bias_gyro), bias_accel=lerp(self.bias_accel))


@dataclass
class Sequence:
    """One recording (real or simulated): events, frames, IMU, ground truth, calibration and metadata.

    Attributes:
        name: short name, e.g. "slider_depth".
        camera: intrinsics (and sensor size), or None when the recording has no calibration.
        events: (N,) events of dtype EVENT_DTYPE sorted by t (possibly empty; None gives an empty array).
        frame_times: (F,) frame timestamps [s], strictly increasing.
        frames: (F, H, W) uint8 intensity frames; (0, H, W) when there are none (H, W still give the sensor size
            when known, else (0, 0, 0)).
        imu: IMU samples in I, or None.
        groundtruth: camera poses (body "camera"), or None.
        groundtruth_imu: IMU states (body "imu", possibly with velocity and biases), or None.
        R_CtoI: (3, 3) camera-to-IMU rotation (x_I = R_CtoI x_C + p_CinI), or None when unknown.
        p_CinI: (3,) camera centre in I [m], or None when unknown.
        metadata: free-form JSON-like dict (IMU noise densities under "imu_noise", source files, units notes...).

    Construction and every later assignment check each field (ValueError naming it and the expected form): events
    must already be an EVENT_DTYPE array sorted by t (a list, an (N, 4) float array, another dtype or unsorted
    events are refused; build them with :func:`evio_lib.events.array.make_events`), times strictly increasing,
    R_CtoI a (3, 3) rotation, p_CinI of shape (3,); frames must match frame_times and the camera. So slicing by
    time (binary search) is right; only an in-place edit of an array can break the order, which :meth:`validate`
    (and slice_time, for IMU and ground-truth times) re-checks. :meth:`validate` also checks events inside the
    sensor and unit quaternions. Arrays are stored as given (no copy) and never modified. The events may be a
    read-only memory map of an ``.npy`` file (the ROS bag and HDF5 readers write one,
    :mod:`evio_lib.io.event_source`): they are then checked a block at a time through the file, and the consumers
    that walk them (event frames, ``reconstruct``) read one window at a time.

    >>> from evio_lib.events.array import make_events
    >>> Sequence("bad", events=[(0.0, 1, 2, 1)])
    Traceback (most recent call last):
    ...
    ValueError: events must be a 1-D NumPy array of dtype EVENT_DTYPE (t float64 [s], x and y uint16, p int8 +1/-1) sorted by t; build one with evio_lib.events.array.make_events(t, x, y, p); got list
    >>> seq = Sequence("demo", events=make_events([0.0, 0.5, 1.0], [1, 2, 3], [0, 0, 0], [1, -1, 1]),
    ...                frames=np.zeros((0, 4, 5), np.uint8))
    >>> seq.validate(); seq.sensor_size, len(seq.slice_time(0.0, 0.6).events)
    ((5, 4), 2)
    """

    name: str
    camera: PinholeRadtan | None = None
    events: np.ndarray = field(default_factory=empty_events)
    frame_times: np.ndarray | None = None
    frames: np.ndarray | None = None
    imu: ImuSamples | None = None
    groundtruth: GroundTruth | None = None
    groundtruth_imu: GroundTruth | None = None
    R_CtoI: np.ndarray | None = None
    p_CinI: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    def __setattr__(self, name: str, value: Any) -> None:
        """Set a field after checking it on its own (type, dtype, shape, order, finiteness); see :meth:`validate`.

        This runs for every field the constructor sets and for every later assignment (``seq.events = ...``), so
        the events stay sorted and :meth:`slice_time` / ``events_between`` stay right. Checks that relate two
        fields (frames against frame_times and the camera) run at the end of construction and in :meth:`validate`.
        """
        super().__setattr__(name, self._checked_field(name, value))

    def _checked_field(self, name: str, value: Any) -> Any:
        """Return ``value`` converted for field ``name`` (None -> empty where the field has an empty form), or raise."""
        if name == "events":
            if value is None:
                return empty_events()
            if isinstance(value, np.memmap) and value.dtype == EVENT_DTYPE and value.ndim == 1:
                # events on disk (a ROS bag or an HDF5 file read through evio_lib.io.event_source): checked a block
                # at a time through the file, so that the check leaves no page of the map resident
                from evio_lib.io.event_source import check_events_streamed

                check_events_streamed(value, "events")
            else:
                _check_event_array(value)
        elif name == "frame_times":
            if value is None:
                return np.zeros(0, dtype=np.float64)
            try:
                value = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"frame_times must be a numeric array of shape (F,) [s]; got {value!r}") from None
            if value.ndim != 1:
                raise ValueError(f"frame_times must have shape (F,); got {value.shape}")
            _check_times(value, "frame_times")
        elif name == "frames":
            if value is None:
                camera = self.__dict__.get("camera")
                h, w = (camera.height, camera.width) if isinstance(camera, PinholeRadtan) else (0, 0)
                return np.zeros((0, h, w), dtype=np.uint8)
            if not isinstance(value, np.ndarray) or value.dtype != np.uint8 or value.ndim != 3:
                got = (f"dtype {value.dtype} and shape {value.shape}" if isinstance(value, np.ndarray)
                       else type(value).__name__)
                raise ValueError(f"frames must be a uint8 array of shape (F, H, W) (convert float images in [0, 1] with "
                                 f"evio_lib.features.base.to_uint8_image); got {got}")
        elif name == "camera":
            if value is not None and not isinstance(value, PinholeRadtan):
                raise ValueError(f"camera must be a PinholeRadtan or None; got {type(value).__name__}")
        elif name == "name":
            if not isinstance(value, str):
                raise ValueError(f"name must be a str; got {type(value).__name__}")
        elif name == "metadata":
            if value is None:
                return {}
            if not isinstance(value, dict):
                raise ValueError(f"metadata must be a dict; got {type(value).__name__}")
        elif name == "imu":
            if value is not None:
                if not isinstance(value, ImuSamples):
                    raise ValueError(f"imu must be an ImuSamples or None; got {type(value).__name__}")
                value.validate("imu")
        elif name in ("groundtruth", "groundtruth_imu"):
            if value is not None:
                if not isinstance(value, GroundTruth):
                    raise ValueError(f"{name} must be a GroundTruth or None; got {type(value).__name__}")
                body = "camera" if name == "groundtruth" else "imu"
                if value.body != body:
                    raise ValueError(f"{name}.body must be {body!r}; got {value.body!r}")
                value.validate(name, unit_quaternions=False)
        elif name == "R_CtoI":
            if value is not None:
                value = _float_array_any(value, "R_CtoI", "a (3, 3) rotation matrix")
                _check_rotation(value, "R_CtoI")
        elif name == "p_CinI":
            if value is not None:
                value = _float_array_any(value, "p_CinI", "a vector of shape (3,) [m]")
                if value.shape != (3,) or not np.all(np.isfinite(value)):
                    raise ValueError(f"p_CinI must be a finite vector of shape (3,); got shape {value.shape}")
        return value

    def __post_init__(self) -> None:
        self._check_frames()

    def _check_frames(self) -> None:
        """Raise ValueError unless frames match frame_times in number and the camera in size."""
        f = self.frame_times.shape[0]
        if self.frames.shape[0] != f:
            raise ValueError(f"frames must have shape ({f}, H, W) matching frame_times ({f},); got {self.frames.shape}")
        if self.camera is not None and self.frames.shape[1] * self.frames.shape[2] > 0:
            expected = (self.camera.height, self.camera.width)
            if self.frames.shape[1:] != expected:
                raise ValueError(f"frames must have shape (F, {expected[0]}, {expected[1]}) like the camera; got {self.frames.shape}")

    @property
    def sensor_size(self) -> tuple[int, int] | None:
        """Return (width, height) in pixels from the camera, else from the frame array, else None."""
        if self.camera is not None:
            return (self.camera.width, self.camera.height)
        if self.frames.ndim == 3 and self.frames.shape[1] > 0 and self.frames.shape[2] > 0:
            return (int(self.frames.shape[2]), int(self.frames.shape[1]))
        return None

    def validate(self) -> None:
        """Return None if every part is consistent; else raise ValueError naming the field and the problem.

        Construction and every assignment already check each field on its own (events: EVENT_DTYPE, 1-D, sorted,
        finite, polarity +1/-1; frames (F, H, W) uint8; strictly increasing finite times everywhere; IMU and
        ground-truth types, shapes, bodies and finiteness; R_CtoI a rotation, p_CinI (3,)) and, at construction,
        frames against frame_times and the camera. ``validate`` re-checks all of it (arrays may have been edited
        in place) and adds: events inside the sensor, unit ground-truth quaternions (tolerance 1e-6).
        """
        for name in ("name", "camera", "metadata", "events", "frame_times", "frames", "imu", "groundtruth",
                     "groundtruth_imu", "R_CtoI", "p_CinI"):
            self._checked_field(name, getattr(self, name))
        size = self.sensor_size
        if size is not None and isinstance(self.events, np.memmap):
            from evio_lib.io.event_source import check_events_streamed

            check_events_streamed(self.events, "events", size)
        elif size is not None:
            try:
                validate_events(self.events, *size)
            except ValueError as exc:
                raise ValueError(f"events: {exc}") from None
        self._check_frames()
        for name in ("groundtruth", "groundtruth_imu"):
            if getattr(self, name) is not None:
                getattr(self, name).validate(name)

    def slice_time(self, t0: float, t1: float) -> "Sequence":
        """Return a new Sequence holding copies of everything with t0 <= t < t1 (half-open window).

        Camera, extrinsics and (a deep copy of) metadata are kept; events are found by binary search.
        """
        if not (np.isfinite(t0) and np.isfinite(t1)) or t1 < t0:
            raise ValueError(f"t0 and t1 must be finite with t0 <= t1; got t0={float(t0)!r}, t1={float(t1)!r}")
        s = _time_mask(self.frame_times, t0, t1)
        return replace(
            self,
            events=events_between(self.events, t0, t1).copy(),
            frame_times=self.frame_times[s].copy(),
            frames=self.frames[s].copy(),
            imu=None if self.imu is None else self.imu.slice_time(t0, t1),
            groundtruth=None if self.groundtruth is None else self.groundtruth.slice_time(t0, t1),
            groundtruth_imu=None if self.groundtruth_imu is None else self.groundtruth_imu.slice_time(t0, t1),
            R_CtoI=None if self.R_CtoI is None else self.R_CtoI.copy(),
            p_CinI=None if self.p_CinI is None else self.p_CinI.copy(),
            metadata=copy.deepcopy(self.metadata),
        )

    def summary(self) -> str:
        """Return a short multi-line text describing what the sequence holds (counts, time ranges, rates)."""

        def span(t: np.ndarray) -> str:
            if t.size == 0:
                return "none"
            dur = float(t[-1] - t[0])
            rate = f", {(t.size - 1) / dur:.1f} Hz" if dur > 0 and t.size > 1 else ""
            return f"{t.size:,} over {t[0]:.6f} .. {t[-1]:.6f} s ({dur:.3f} s{rate})"

        size = self.sensor_size
        lines = [f"Sequence {self.name!r}"]
        lines.append(f"  sensor          {'unknown' if size is None else f'{size[0]} x {size[1]} px'}")
        if self.camera is not None:
            c = self.camera
            lines.append(f"  camera          fx={c.fx:.2f} fy={c.fy:.2f} cx={c.cx:.2f} cy={c.cy:.2f} "
                         f"k=({c.k1:.4g}, {c.k2:.4g}, {c.p1:.4g}, {c.p2:.4g}, {c.k3:.4g})")
        else:
            lines.append("  camera          none")
        n = self.events.shape[0]
        if n:
            t = self.events["t"]
            dur = float(t[-1] - t[0])
            rate = f", {n / dur / 1e3:.1f} kev/s" if dur > 0 else ""
            if isinstance(self.events, np.memmap):  # events on disk: counted a block at a time
                from evio_lib.io.event_source import event_source

                chunks = event_source(self.events).chunks()
                pos = 100.0 * sum(int(np.count_nonzero(chunk["p"] > 0)) for _, chunk in chunks) / n
            else:
                pos = 100.0 * float(np.mean(self.events["p"] > 0))
            lines.append(f"  events          {n:,} over {t[0]:.6f} .. {t[-1]:.6f} s ({dur:.3f} s{rate}), {pos:.1f} % positive")
        else:
            lines.append("  events          none")
        lines.append(f"  frames          {span(self.frame_times)}")
        lines.append(f"  imu             {'none' if self.imu is None else span(self.imu.t)}")
        for name in ("groundtruth", "groundtruth_imu"):
            gt = getattr(self, name)
            extra = ""
            if gt is not None:
                have = [n for n in _GT_OPTIONAL if getattr(gt, n) is not None]
                extra = f" [{gt.body}{', ' + ', '.join(have) if have else ''}]"
            lines.append(f"  {name:<15} {'none' if gt is None else span(gt.t)}{extra}")
        known = self.R_CtoI is not None or self.p_CinI is not None
        lines.append(f"  extrinsics      {'R_CtoI/p_CinI known' if known else 'unknown'}")
        if self.metadata:
            lines.append(f"  metadata        {', '.join(sorted(map(str, self.metadata)))}")
        return "\n".join(lines)
