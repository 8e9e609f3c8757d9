"""The MSCKF: one filter composed of its parts, driven by IMU samples and per-image feature tracks.

The parts, one idea each (as OpenVINS divides its filter):

* :class:`~evio_lib.msckf.imu_buffer.ImuBuffer`: the checked IMU samples and the checked propagation of the state to
  an image time (thesis §3.3.4; the OC-EKF's transition matrices when ``observability_constrained``).
* :class:`~evio_lib.msckf.feature_database.FeatureDatabase`: the tracks seen in the window, per frame stream; which
  tracks have ended and which lose observations when camera states leave the window.
* :class:`~evio_lib.msckf.updater.MsckfUpdater`: the batched, gated, QR-compressed update of those features
  (thesis §3.3.7, Eqs. 41-58; the OC-EKF's update-side constraint).
* this module: the window of camera states (augmentation, Eqs. 27-30; which states leave it; marginalisation), the
  zero-velocity update, the guards, and the loop that runs the parts in order.

One image (``Msckf.process_image``) runs these named steps, in the order of S-MSCKF (Sun et al., RA-L 2018; msckf_vio)
and thesis §3.3.6.1:

1. ``_propagate_to(t)``: IMU propagation to the image time (``ImuBuffer.propagate``).
2. ``_augment()``: clone the camera pose into the window (Eqs. 27-30).
3. ``FeatureDatabase.add_observations``: append (camera id, xy, W) to each feature's track; W (2, 2) is the
   whitening matrix L^-1 of the observation's noise covariance Σ = L L^T (``xy_cov``; default σ² I).
4. ``FeatureDatabase.collect_lost``: tracks not observed in this image have ended; those with >= ``min_track_length``
   observations are used with all their observations, shorter ones are dropped. With several frame streams (e.g.
   APS frames and event frames of one camera, as Ultimate SLAM fuses them; ``process_image(..., stream=k)``) each
   track belongs to the stream that started it, and an image ends only the tracks of its own stream: every image
   still adds a clone to the one window, so the tracks of both streams constrain the same trajectory.
5. ``_select_cameras_to_remove`` / ``FeatureDatabase.collect_pruned``: when the window exceeds N_max, the oldest
   third goes (``marginalize_third``, the default, as in Mourikis & Roumeliotis 2007) or two states chosen by
   S-MSCKF's two-way keyframe rule; the features observed at >= 2 of them are used with those observations, which
   are then deleted from the tracks.
6. ``_update``: the features of 4 and 5 enter ONE stacked, compressed update (``MsckfUpdater.update``, which returns
   an ``UpdateResult``; ``_take_update`` applies it). (msckf_vio applies two updates in a row; the two sets use
   disjoint observations, so stacking them changes only the linearisation point of the second set and halves the
   cost.) Every dropped feature is counted in ``rejections`` with its reason (``far_point_fallback`` counts the
   low-parallax tracks kept as far points, before the gate).
7. ``_marginalize``: the chosen camera states leave the window (their rows and columns of P are dropped).

Guards, all counted in ``Msckf.faults`` and announced by a ``MsckfWarning`` (the first time, then at 10, 100, ...
occurrences) or an exception:

* IMU range and units (``feed_imu``, module ``imu_buffer``): samples beyond ``config.accel_full_scale`` /
  ``gyro_full_scale`` are dropped and interpolated over; a batch that makes them more than 10 % of the samples fed
  is refused with ValueError (wrong units); a gyro stream that turns faster than one revolution per second most of
  the time is reported as probably deg/s.
* IMU gaps (``propagation.propagate``): longer than ``imu_max_gap`` -> counted, warned, covariance inflated for the
  unseen motion; longer than ``imu_max_bridged_gap`` -> ``ImuGapError``, the state stays before the gap.
* Observations: a frame mostly beyond ``max_normalized_coordinate`` (pixels instead of normalised coordinates) is
  refused with ValueError; single observations beyond it are dropped.
* Every step is checked: after each propagation the state must be finite and the IMU covariance block symmetric
  positive semi-definite, after each update the whole state and P (``state.state_problem``). A propagation that
  fails the check raises ``StepRefusedError`` (a propagation cannot be skipped: the image time would be wrong) and
  the filter keeps the state before it; an update that fails it is rolled back (the state after propagation and
  augmentation is kept), its features are dropped, the filter goes on. So the state never holds NaN or inf, and P
  stays a covariance.
"""
from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import quat_to_rot
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.feature_database import FeatureDatabase, FeatureUse, whitening_matrices
from evio_lib.msckf.imu_buffer import ImuBuffer, StepRefusedError
from evio_lib.msckf.propagation import ImuGapError
from evio_lib.msckf.state import IMU_DIM, FilterState, remove_camera_states, state_problem
from evio_lib.msckf.update import chi_square_threshold, kalman_update
from evio_lib.msckf.updater import MsckfUpdater, UpdateResult, apply_correction
from evio_lib.msckf.zero_velocity import ZeroVelocityConfig, zero_velocity_measurement
from evio_lib.threads import single_threaded_blas

__all__ = ["FilterOutput", "Msckf", "MsckfWarning"]


class MsckfWarning(UserWarning):
    """Warning of the MSCKF about its input (dropped IMU samples, IMU gaps, dropped observations, refused updates)."""


@dataclass(frozen=True, eq=False)
class FilterOutput:
    """The filter's estimate after one image.

    Attributes:
        t: image time, s.
        q_GtoI: (4,) JPL quaternion of R_GtoI; p_IinG, v_IinG: (3,) position and velocity of I in G.
        b_g, b_a: (3,) gyro and accelerometer bias estimates.
        P_imu: (15, 15) covariance of the IMU error [δθ, δb_g, δv, δb_a, δp].
        n_features_used: features that entered this image's updates (after gating).
        counters: per-image figures: window size, tracks, features tried / used per update kind, rows, updates.
    """

    t: float
    q_GtoI: NDArray[np.float64]
    p_IinG: NDArray[np.float64]
    v_IinG: NDArray[np.float64]
    b_g: NDArray[np.float64]
    b_a: NDArray[np.float64]
    P_imu: NDArray[np.float64]
    n_features_used: int
    counters: Mapping[str, int] = field(default_factory=dict)

    @property
    def sigma(self) -> NDArray[np.float64]:
        """Return the (15,) standard deviations sqrt(diag(P_imu)) (3-sigma bounds are 3 * sigma)."""
        return np.sqrt(np.clip(np.diag(self.P_imu), 0.0, None))

    @property
    def R_ItoG(self) -> NDArray[np.float64]:
        """Return R_ItoG = C(q_GtoI)^T (3, 3)."""
        return quat_to_rot(self.q_GtoI).T


class Msckf:
    """Multi-state constraint Kalman filter (S-MSCKF flavour) driven by IMU samples and per-image feature tracks.

    Args:
        config: every parameter (``MsckfConfig``).
        state: the initial state (e.g. ``initialization.initial_state_from_truth`` or ``initial_state_from_static``);
            it usually holds no camera poses.

    Attributes:
        config: the configuration.
        rejections: Counter of dropped features by reason (too_few_observations, the triangulation reasons of
            ``TRIANGULATION_REASONS``, chi2) and of the far-point candidates (far_point_fallback, counted before
            the gate).
        faults: Counter of bad input and refused steps (module docstring): imu_accel_out_of_range and
            imu_gyro_out_of_range (samples dropped; a sample beyond both counts in both), gyro_units_suspect (1
            once a gyro stream looked like deg/s), imu_gaps (gaps longer than imu_max_gap bridged), imu_gap_refused
            (ImuGapError raised), observation_out_of_view (observations dropped), propagation_refused
            (StepRefusedError raised), update_refused (updates rolled back). Empty for a clean run.
        tracks: dict feature id -> list of (camera id, xy (2,), W (2, 2)) observations held in the window; W is
            the whitening matrix L^-1 of the observation's noise covariance Σ = L L^T (:func:`whitening_matrices`).

    Feed IMU samples with ``feed_imu`` (any chunking, in time order) and images with ``process_image``; or call
    ``run``. Reference: thesis §3.3 (Eqs. 18-86); Mourikis & Roumeliotis, ICRA 2007; Sun et al., RA-L 2018.

    >>> from evio_lib.msckf.initialization import initial_state_from_truth
    >>> cfg = MsckfConfig()
    >>> s0 = initial_state_from_truth(0.0, np.eye(3), np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3), cfg)
    >>> f = Msckf(cfg, s0)
    >>> t = np.arange(0.0, 1.0005, 0.001)
    >>> f.feed_imu(t, np.zeros((len(t), 3)), np.tile([0.0, 0.0, 9.81], (len(t), 1)))
    >>> out = f.process_image(0.05, np.array([1, 2]), np.array([[0.1, 0.0], [0.0, 0.1]]))
    >>> out.t, out.p_IinG + 0.0, out.counters["window"], len(f.tracks)
    (0.05, array([0., 0., 0.]), 1, 2)
    """

    def __init__(self, config: MsckfConfig, state: FilterState) -> None:
        if not isinstance(config, MsckfConfig):
            raise ValueError(f"config must be an MsckfConfig; got {type(config).__name__}")
        if not isinstance(state, FilterState):
            raise ValueError(f"state must be a FilterState; got {type(state).__name__}")
        self.config = config
        self._state = state
        self._imu = ImuBuffer(config)
        self._features = FeatureDatabase(config)
        self._updater = MsckfUpdater(config)
        self.rejections: Counter[str] = Counter()
        self.faults: Counter[str] = Counter()
        self._frame_counters: Counter[str] = Counter()
        self._next_camera_id = max(state.camera_ids, default=-1) + 1

    # ------------------------------------------------------------------------------------------------ properties
    @property
    def state(self) -> FilterState:
        """Return the current filter state (immutable)."""
        return self._state

    @property
    def tracks(self) -> dict[int, list[tuple[int, NDArray[np.float64], NDArray[np.float64]]]]:
        """Return the tracks held in the window: feature id -> list of (camera id, xy (2,), W (2, 2))
        (``FeatureDatabase.tracks``, the live dict)."""
        return self._features.tracks

    # ------------------------------------------------------------------------------------------------ input
    def feed_imu(self, t: float | ArrayLike, gyro: ArrayLike, accel: ArrayLike) -> None:
        """Buffer IMU samples: one (t float, gyro (3,), accel (3,)) or a batch (t (n,), gyro (n, 3), accel (n, 3)).

        Times must be finite, strictly increasing and later than every sample fed before (s); gyro in rad/s and
        accel (specific force) in m/s^2, both in I. Samples with a component beyond the IMU's full scale
        (``config.gyro_full_scale``, ``accel_full_scale``) are dropped (counted in ``faults``, warned); a batch that
        would make them more than 10 % of the samples fed (from 10 samples on) raises ValueError, naming the
        likely unit mistake, and nothing of it is buffered (``imu_buffer.ImuBuffer.feed``).
        """
        for key, count, message in self._imu.feed(t, gyro, accel):
            self._warn(key, count, message, stacklevel=3)

    def _warn(self, key: str, count: int, message: str, stacklevel: int = 4) -> None:
        """Add count to faults[key]; warn with message the first time and when the total reaches 10, 100, ...

        ``stacklevel`` 4 names the caller of a public method that called ``_warn`` through one helper."""
        old = self.faults[key]
        new = old + count
        self.faults[key] = new
        self._frame_counters[key] += count
        if old == 0 or int(math.log10(new)) > int(math.log10(old)):
            warnings.warn(f"{message} [{new} so far: Msckf.faults[{key!r}]]", MsckfWarning, stacklevel=stacklevel)

    def _check_image(
        self, t: float, ids: ArrayLike, xy: ArrayLike
    ) -> tuple[float, NDArray[np.int64], NDArray[np.float64]]:
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
            raise ValueError(f"t must be a finite image time in seconds; got {t!r}")
        t = float(t)
        if t < self._state.timestamp:
            raise ValueError(f"t must be >= the filter time {self._state.timestamp!r} (images in order); got {t!r}")
        ids_arr = np.asarray(ids)
        if ids_arr.size == 0:
            ids_arr = ids_arr.astype(np.int64).reshape(0)
        if ids_arr.ndim != 1 or ids_arr.dtype.kind not in "iu":
            raise ValueError(f"ids must be a 1-D integer array of feature ids (K,); got dtype {ids_arr.dtype}, "
                             f"shape {ids_arr.shape}")
        K = ids_arr.shape[0]
        try:
            xy_arr = np.asarray(xy, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"xy must be a numeric array of shape (K, 2) = ({K}, 2); got {xy!r}") from exc
        if K == 0 and xy_arr.size == 0:
            xy_arr = xy_arr.reshape(0, 2)
        if xy_arr.shape != (K, 2):
            raise ValueError(f"xy must have shape (K, 2) = ({K}, 2), undistorted normalised (x, y); got {xy_arr.shape}")
        if not np.all(np.isfinite(xy_arr)):
            raise ValueError("xy must contain only finite values (no NaN/inf)")
        if np.unique(ids_arr).shape[0] != K:
            raise ValueError("ids must be unique within one image (one observation per feature)")
        limit = self.config.max_normalized_coordinate
        n_far = int(np.count_nonzero(np.any(np.abs(xy_arr) > limit, axis=1)))
        if 2 * n_far > K:
            raise ValueError(
                f"xy must be undistorted normalised image coordinates (X/Z, Y/Z), |x|, |y| <= {limit:g} "
                f"(max_normalized_coordinate); got {n_far} of {K} observations beyond it, largest "
                f"{np.abs(xy_arr).max():.4g}: pixel coordinates? Convert distorted pixels with camera.unproject(uv) "
                "(evio_lib.geometry.camera.PinholeRadtan), undistorted pixels with ((u - cx) / fx, (v - cy) / fy)"
            )
        return t, ids_arr.astype(np.int64), xy_arr

    # ------------------------------------------------------------------------------------------------ main steps
    def process_image(self, t: float, ids: ArrayLike, xy: ArrayLike, xy_cov: ArrayLike | None = None,
                      stream: int = 0) -> FilterOutput:
        """Return the estimate after processing one image's feature observations (steps in the module docstring).

        Args:
            t: image time, s (>= the filter time); IMU samples up to t should have been fed (beyond the last
                sample the last measurement is held).
            ids: (K,) unique integer feature (track) ids.
            xy: (K, 2) undistorted normalised image coordinates (x, y) of the features.
            xy_cov: (K, 2, 2) noise covariance of each observation in normalised coordinates (e.g. σ_px² J J^T with
                J = d(xy)/d(pixel), ``geometry.pixel_noise.observation_covariance``), or None for the isotropic
                ``config.feature_noise_sigma``² I. The update whitens each observation by its own covariance.
            stream: which frame stream the image comes from (0 when there is one). An image ends only the tracks
                of its stream; the ids of different streams must differ (an id seen in another stream is refused).

        The step runs with one BLAS thread (:func:`evio_lib.threads.single_threaded_blas`): its matrices are small,
        and threaded BLAS spends more CPU time waiting than computing (measured: docs/results/speed.md, "The
        filter").
        """
        if isinstance(stream, bool) or not isinstance(stream, (int, np.integer)) or stream < 0:
            raise ValueError(f"stream must be an integer >= 0; got {stream!r}")
        with single_threaded_blas():
            return self._process_image(t, ids, xy, xy_cov, int(stream))

    def _process_image(self, t: float, ids: ArrayLike, xy: ArrayLike, xy_cov: ArrayLike | None,
                       stream: int = 0) -> FilterOutput:
        """The body of :meth:`process_image`."""
        t, ids, xy = self._check_image(t, ids, xy)
        self._features.check_stream(ids, stream)
        if xy_cov is None:
            whiten = None
        else:
            cov = np.asarray(xy_cov, dtype=np.float64)
            if cov.shape != (ids.shape[0], 2, 2):
                raise ValueError(f"xy_cov must have shape (K, 2, 2) = ({ids.shape[0]}, 2, 2), one covariance per "
                                 f"observation; got {cov.shape}")
            whiten = whitening_matrices(cov)
        self._frame_counters = Counter()
        far = np.any(np.abs(xy) > self.config.max_normalized_coordinate, axis=1)
        if far.any():  # outside any plausible field of view: drop these observations
            k = int(np.flatnonzero(far)[0])
            self._warn("observation_out_of_view", int(np.count_nonzero(far)),
                       f"process_image(t = {t:.3f} s) dropped {int(np.count_nonzero(far))} observation(s) beyond "
                       f"max_normalized_coordinate = {self.config.max_normalized_coordinate:g}, e.g. feature "
                       f"{int(ids[k])} at {xy[k].tolist()}; xy must be undistorted normalised coordinates")
            ids, xy = ids[~far], xy[~far]
            whiten = None if whiten is None else whiten[~far]
        self._propagate_to(t)
        camera_id = self._augment()
        remove: list[int] = []
        if self._state.num_cameras > self.config.max_camera_states:
            remove = self._select_cameras_to_remove()
        used = 0
        if self.config.imu_only:
            self._features.clear()
        else:
            features = self._features
            features.add_observations(camera_id, ids, xy, whiten, stream)
            lost, too_short = features.collect_lost(ids, stream, self._state.camera_ids)
            if too_short:
                self.rejections["too_few_observations"] += too_short
            pruned = features.collect_pruned(remove, self._state.camera_ids)
            self._frame_counters["lost_tried"] += len(lost)
            self._frame_counters["prune_tried"] += len(pruned)
            used_mask = self._take_update(self._update(lost + pruned, far=self._far_points_now()))
            used = int(np.count_nonzero(used_mask))
            self._frame_counters["lost_used"] += int(np.count_nonzero(used_mask[:len(lost)]))
            self._frame_counters["prune_used"] += int(np.count_nonzero(used_mask[len(lost):]))
        self._marginalize(remove)
        self._features.remove_unused()
        return self._output(used)

    def run(
        self, imu_t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, frames: Iterable[tuple[Any, ...]]
    ) -> list[FilterOutput]:
        """Return one FilterOutput per frame: feeds all IMU samples, then processes the frames in order.

        Each frame is (t, ids, xy) or (t, ids, xy, xy_cov), the arguments of :meth:`process_image`."""
        self.feed_imu(imu_t, gyro, accel)
        return [self.process_image(*frame) for frame in frames]

    def zero_velocity_update(self, t: float, zv: ZeroVelocityConfig, window: float | None = None
                             ) -> FilterOutput | None:
        """Return the estimate after a zero-velocity update at image time t, or None when its gate refuses it.

        The platform was declared still at t (:class:`evio_lib.msckf.zero_velocity.StandstillDetector`): the
        state is propagated to t and corrected by the 9-row measurement v = 0, mean(ω_m) = b_g,
        mean(a_m) = -R_GtoI g + b_a over the IMU samples since the previous image (at least ``window`` s, default
        ``zv.imu_window``), see :func:`evio_lib.msckf.zero_velocity.zero_velocity_measurement`. No camera pose is
        cloned and no feature is used. A measurement that fails the chi-square gate (``zv.chi2_probability``) is
        not applied (counted in ``rejections['zupt_gate']``); the state is then propagated to t and the caller
        processes the image as usual. One BLAS thread, as :meth:`process_image`.
        """
        with single_threaded_blas():
            return self._zero_velocity_update(t, zv, window)

    def _zero_velocity_update(self, t: float, zv: ZeroVelocityConfig, window: float | None) -> FilterOutput | None:
        """The body of :meth:`zero_velocity_update`."""
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
            raise ValueError(f"t must be a finite image time in seconds; got {t!r}")
        t = float(t)
        if t < self._state.timestamp:
            raise ValueError(f"t must be >= the filter time {self._state.timestamp!r} (images in order); got {t!r}")
        imu_t, imu_w, imu_a = self._imu.samples(self._state.timestamp)
        span = zv.imu_window if window is None else float(window)
        lo = int(np.searchsorted(imu_t, min(self._state.timestamp, t - span), side="right"))
        hi = int(np.searchsorted(imu_t, t, side="right"))
        t_win, w_win, a_win = imu_t[lo:hi].copy(), imu_w[lo:hi].copy(), imu_a[lo:hi].copy()
        self._frame_counters = Counter()
        self._propagate_to(t)
        if t_win.shape[0] < 2:
            self.rejections["zupt_no_imu"] += 1
            return None
        cfg = self.config
        state = self._state
        H, r = zero_velocity_measurement(state, t_win, w_win, a_win, cfg.gravity, cfg.gyro_noise_density,
                                         cfg.accel_noise_density, zv)
        S = H @ state.P @ H.T + np.eye(H.shape[0])
        try:
            chi2 = float(r @ np.linalg.solve(S, r))
        except np.linalg.LinAlgError:
            chi2 = math.inf
        if not chi2 <= chi_square_threshold(H.shape[0], zv.chi2_probability):
            self.rejections["zupt_gate"] += 1
            return None
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                dx, P_new = kalman_update(state.P, H, r, 1.0)
        except ValueError as exc:
            self._refuse_update(f"the zero-velocity update failed ({exc})")
            return None
        new_state = apply_correction(state, dx, P_new) if np.all(np.isfinite(dx)) else None
        problem = "its correction holds non-finite values" if new_state is None else state_problem(new_state)
        if problem is not None:
            self._refuse_update(problem)
            return None
        self._state = new_state
        self._frame_counters["zupt"] += 1
        return self._output(0)

    def _propagate_to(self, t: float) -> None:
        """Propagate the state to time t with the buffered IMU samples (``ImuBuffer.propagate``: the OC hook when
        configured, the result checked), count and warn about the IMU gaps crossed, count the refusals."""
        try:
            state, gaps = self._imu.propagate(self._state, t)
        except ImuGapError:
            self.faults["imu_gap_refused"] += 1
            raise
        except StepRefusedError:
            self.faults["propagation_refused"] += 1
            raise
        self._state = state
        for key, count, message in gaps:
            self._warn(key, count, message)

    def _augment(self) -> int:
        """Clone the current camera pose into the window; return its camera id."""
        camera_id = self._next_camera_id
        self._next_camera_id += 1
        self._state = augment_state(self._state, camera_id)
        return camera_id

    def _select_cameras_to_remove(self) -> list[int]:
        """Return the camera ids to marginalise from a full window (never the newest), oldest first.

        S-MSCKF's two-way rule (msckf_vio ``findRedundantCamStates``): with key = the 4th-newest state, the
        3rd-newest and then the 2nd-newest are compared with the key; if the relative rotation angle, the distance
        and the tracking rate say the motion is small (angle < ``keyframe_rotation_threshold``, distance <
        ``keyframe_translation_threshold`` and tracking rate > ``keyframe_tracking_rate_threshold``), that state
        is redundant and removed, otherwise the oldest remaining state is removed. With ``marginalize_third`` the
        oldest third of the window (at least 2) is removed instead. Windows of fewer than 5 lose their oldest 2.
        """
        ids = list(self._state.camera_ids)
        n = len(ids)
        excess = max(n - self.config.max_camera_states, 1)
        if self.config.marginalize_third:
            return ids[: min(max(n // 3, 2, excess), n - 1)]
        if n < 5:
            return ids[: min(max(2, excess), n - 1)]
        cams = self._state.cameras
        key = cams[ids[-4]]
        R_key = key.R_GtoC
        removed: list[int] = []
        cand, oldest = n - 3, 0
        for _ in range(2):
            c = cams[ids[cand]]
            # relative rotation angle: |rotvec(R_c R_key^T)|, from the trace
            cos_angle = (np.trace(c.R_GtoC @ R_key.T) - 1.0) / 2.0
            angle = math.acos(min(1.0, max(-1.0, cos_angle)))
            distance = float(np.linalg.norm(c.p_CinG - key.p_CinG))
            if (angle < self.config.keyframe_rotation_threshold
                    and distance < self.config.keyframe_translation_threshold
                    and self._features.tracking_rate > self.config.keyframe_tracking_rate_threshold):
                removed.append(ids[cand])
                cand += 1
            else:
                removed.append(ids[oldest])
                oldest += 1
        extra = [i for i in ids[:-1] if i not in removed][: max(excess - 2, 0)]  # window far too large: oldest
        return sorted(set(removed + extra), key=ids.index)

    def _marginalize(self, remove: list[int]) -> None:
        """Remove the camera states ``remove`` from the window (drop their rows and columns of P)."""
        if remove:
            self._state = remove_camera_states(self._state, remove)
            self._frame_counters["cameras_removed"] += len(remove)

    # ------------------------------------------------------------------------------------------------ the update
    def _far_points_now(self) -> bool:
        """Return whether this image's update may use far points: ``far_point_fallback`` on, and the gate (never
        ungated: no residual check)."""
        return self.config.far_point_fallback and self.config.chi2_gating

    def _update(self, uses: list[FeatureUse], far: bool = False) -> UpdateResult:
        """Return the result of ONE compressed EKF update of the current state with ``uses`` (``MsckfUpdater``);
        the filter is not changed (``_take_update`` applies the result)."""
        return self._updater.update(self._state, uses, far)

    def _take_update(self, result: UpdateResult) -> NDArray[np.bool_]:
        """Apply an update's result (its state, its rejections and counters; a refused update is counted and
        warned about, and the state before it stays); return which features were used."""
        self.rejections.update(result.rejections)
        if result.rows:
            self._frame_counters["rows"] += result.rows
            if result.refused is not None:
                self._refuse_update(result.refused)
            else:
                self._state = result.state
                self._frame_counters["updates"] += 1
        return result.used

    def _refuse_update(self, reason: str) -> bool:
        """Count and warn about a refused update (the state stays as before it); return False."""
        self._warn("update_refused", 1, f"update at t = {self._state.timestamp:.3f} s refused and rolled back: "
                                        f"{reason}; its features are dropped")
        return False

    # ------------------------------------------------------------------------------------------------ output
    def _output(self, used: int) -> FilterOutput:
        imu = self._state.imu
        counters = dict(self._frame_counters)
        counters.update(window=self._state.num_cameras, tracks=len(self.tracks))
        return FilterOutput(
            t=imu.timestamp, q_GtoI=imu.q_GtoI.copy(), p_IinG=imu.p_IinG.copy(), v_IinG=imu.v_IinG.copy(),
            b_g=imu.b_g.copy(), b_a=imu.b_a.copy(), P_imu=self._state.P[:IMU_DIM, :IMU_DIM].copy(),
            n_features_used=used, counters=MappingProxyType(counters),
        )
