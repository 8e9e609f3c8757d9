"""The MSCKF orchestrator: IMU buffering, propagation, augmentation, feature bookkeeping, updates and pruning.

One image (``Msckf.process_image``) runs these named steps, in the order of S-MSCKF (Sun et al., RA-L 2018; msckf_vio)
and thesis §3.3.6.1:

1. ``_propagate_to(t)``: IMU propagation to the image time (OC-modified Φ when ``observability_constrained``).
2. ``_augment()``: clone the camera pose into the window (Eqs. 27-30).
3. ``_add_observations``: append (camera id, xy, W) to each feature's track (a dict id -> observations); W (2, 2)
   is the whitening matrix L^-1 of the observation's noise covariance Σ = L L^T (``xy_cov``; default σ² I).
4. ``_collect_lost_features``: tracks not observed in this image have ended; those with >= ``min_track_length``
   observations are used with all their observations, shorter ones are dropped. With several frame streams (e.g.
   APS frames and event frames of one camera, as Ultimate SLAM fuses them; ``process_image(..., stream=k)``) each
   track belongs to the stream that started it, and an image ends only the tracks of its own stream: every image
   still adds a clone to the one window, so the tracks of both streams constrain the same trajectory.
5. ``_select_cameras_to_remove`` / ``_collect_pruned_features``: when the window exceeds N_max, the oldest third
   goes (``marginalize_third``, the default, as in Mourikis & Roumeliotis 2007) or two states chosen by S-MSCKF's
   two-way keyframe rule; the features
   observed at >= 2 of them are used with those observations, which are then deleted from the tracks.
6. ``_update``: the features of 4 and 5 enter ONE stacked, compressed update. (msckf_vio applies two updates in a
   row; the two sets use disjoint observations, so stacking them changes only the linearisation point of the
   second set and halves the cost.)
7. ``_marginalize``: the chosen camera states leave the window (their rows and columns of P are dropped).

An update (``_update``): all features are triangulated at once (inverse depth, ``triangulate_inverse_depth_batch``);
for each, the residual and Jacobians of the observations used (Eqs. 41-48) are whitened per observation (rows 2i, 2i+1 of r, H_x and H_f multiplied by W_i = L_i^-1, so the noise becomes N(0, I)),
projected on the left nullspace of H_f (Eq. 50), OC-constrained as a whole (with ``observability_constrained``:
H_o* = H_o (I - N (N^T N)^-1 N^T) with the observing cameras' first-estimate nullspace N, so H_o* N = 0; see
``observability.constrain_projected_jacobian``) and chi-square gated (``chi2_probability``, 95 %) with unit noise on
ALL the feature's observations in the window (a pruned feature's update rows come from the removed states only, but
the gate sees the whole track: more degrees of freedom, more power against moving points, less bias on the kept
residuals, ``update.gating_mean_shrink``); the survivors are stacked, QR-compressed
(Eqs. 51-55) and applied in one Joseph-form Kalman update (Eqs. 56-58). Features are processed in batches of equal
observation count, so the per-feature work is vectorised. Every dropped feature is counted in ``rejections`` with
its reason (``far_point_fallback`` counts the low-parallax tracks kept as far points, before the gate).

Guards (issue 17), all counted in ``Msckf.faults`` and announced by a ``MsckfWarning`` (the first time, then at
10, 100, ... occurrences) or an exception:

* IMU range (``feed_imu``): samples beyond ``config.accel_full_scale`` / ``gyro_full_scale`` (±16 g, ±2000 deg/s by
  default) cannot come from the sensor: they are dropped and the hole is interpolated like any gap. A batch of >= 10
  A batch that would bring the share of such samples above 10 % (of >= 10 fed so far) is refused with ValueError
  (wrong units: deg/s, mg, ...; a real sensor saturates at its full scale, beyond it are only glitches), and a
  gyro stream that turns faster than one revolution per second most of the time is reported as probably deg/s
  (warning).
* IMU gaps (``propagation.propagate``): longer than ``imu_max_gap`` -> counted, warned, covariance inflated for the
  unseen motion; longer than ``imu_max_bridged_gap`` -> ``ImuGapError``, the state stays before the gap.
* Observations: a frame mostly beyond ``max_normalized_coordinate`` (pixels instead of normalised coordinates) is
  refused with ValueError; single observations beyond it are dropped.
* Every step is checked: after each propagation the state must be finite and the IMU covariance block symmetric
  positive semi-definite (the rest of P changes only by Φ P_IC, whose finiteness is checked), after each update
  the whole state and P (``state.state_problem``). A propagation that fails the check raises
  ``StepRefusedError`` (a propagation cannot be skipped: the image time would be wrong) and the filter keeps the
  state before it; an update that fails it is rolled back (the state after propagation and augmentation is kept),
  its features are dropped, the filter goes on. So the state never holds NaN or inf, and P stays a covariance.
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

from evio_lib.geometry.rotation import quat_from_rotvec, quat_multiply, quat_normalize, quat_to_rot
from evio_lib.msckf.augmentation import augment_state
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.observability import (
    camera_nullspace,
    constrain_projected_jacobian,
    constrain_transition,
)
from evio_lib.msckf.propagation import ImuGapError, imu_gaps, propagate
from evio_lib.msckf.state import (
    BA,
    BG,
    CAMERA_DIM,
    IMU_DIM,
    POS,
    THETA,
    VEL,
    FilterState,
    ImuState,
    _camera_unchecked,
    _filter_state_unchecked,
    _frozen,
    _unchecked,
    remove_camera_states,
    state_problem,
)
from evio_lib.msckf.triangulation import triangulate_inverse_depth_batch
from evio_lib.msckf.update import chi_square_threshold, kalman_update, measurement_compress
from evio_lib.msckf.zero_velocity import ZeroVelocityConfig, zero_velocity_measurement
from evio_lib.threads import single_threaded_blas

__all__ = [
    "FilterOutput", "Msckf", "MsckfWarning", "StepRefusedError", "apply_correction",
    "whitening_matrices",
]

_DEG_S_SUSPECT_RATE = 2.0 * math.pi  # rad/s: a gyro stream mostly faster than one turn per second looks like deg/s
_DEG_S_MIN_SAMPLES = 200  # samples seen before that judgement is made
_UNITS_MIN_SAMPLES = 10  # once this many samples were fed, more than _UNITS_FRACTION of them beyond the full
_UNITS_FRACTION = 0.1  # scale means wrong units (or a broken sensor), not glitches: feed_imu refuses the batch


class MsckfWarning(UserWarning):
    """Warning of the MSCKF about its input (dropped IMU samples, IMU gaps, dropped observations, refused updates)."""


class StepRefusedError(ValueError):
    """Raised when a propagation would leave a non-finite or non-PSD state; the filter keeps the state before it."""

# triangulation failures that mean "too little parallax for a depth" rather than "inconsistent observations"
_FAR_POINT_REASONS = ("behind_camera", "too_far", "insufficient_baseline")


def whitening_matrices(xy_cov: ArrayLike) -> NDArray[np.float64]:
    """Return (K, 2, 2) whitening matrices W = L^-1 of observation covariances Σ = L L^T (L lower Cholesky).

    Args:
        xy_cov: (K, 2, 2) symmetric positive-definite covariances of undistorted normalised coordinates.

    W Σ W^T = I, so W r has unit covariance. Closed form for 2 x 2: L = [[a, 0], [b, c]] with a = sqrt(Σ00),
    b = Σ10 / a, c = sqrt(Σ11 - b²), and L^-1 = [[1/a, 0], [-b/(a c), 1/c]].

    >>> whitening_matrices(np.array([[[4.0, 2.0], [2.0, 5.0]]])).round(3).tolist()
    [[[0.5, 0.0], [-0.25, 0.5]]]
    """
    cov = np.asarray(xy_cov, dtype=np.float64)
    if cov.ndim != 3 or cov.shape[1:] != (2, 2):
        raise ValueError(f"xy_cov must have shape (K, 2, 2), one covariance per observation; got {cov.shape}")
    if not np.all(np.isfinite(cov)):
        raise ValueError("xy_cov must contain only finite values (no NaN/inf)")
    scale = np.maximum(np.abs(cov).max(axis=(1, 2)), 1e-300)
    if np.any(np.abs(cov[:, 0, 1] - cov[:, 1, 0]) > 1e-9 * scale):
        raise ValueError("xy_cov must hold symmetric 2 x 2 matrices (Σ01 = Σ10)")
    a2 = cov[:, 0, 0]
    safe_a = np.sqrt(np.where(a2 > 0.0, a2, 1.0))
    b = cov[:, 1, 0] / safe_a  # b = Σ10 / a
    c2 = cov[:, 1, 1] - b * b  # c² = Σ11 - b²  (the Schur complement, > 0 iff Σ is positive definite)
    if np.any(a2 <= 0.0) or np.any(c2 <= 1e-12 * scale):
        raise ValueError("xy_cov must hold positive-definite covariances (Σ00 > 0 and det Σ > 0)")
    c = np.sqrt(c2)
    W = np.zeros(cov.shape)
    W[:, 0, 0] = 1.0 / safe_a  # W = L^-1 = [[1/a, 0], [-b/(a c), 1/c]]
    W[:, 1, 0] = -b / (safe_a * c)
    W[:, 1, 1] = 1.0 / c
    return W


def apply_correction(state: FilterState, dx: NDArray[np.float64], P_new: NDArray[np.float64]) -> FilterState:
    """Return the state corrected by dx (15 + 6N,) with covariance P_new: ``state.inject_error(dx)`` with P replaced.

    Same result as ``evio_lib.msckf.state.inject_error`` (q <- quat_from_rotvec(δθ) ⊗ q for the IMU and every
    camera, renormalised; everything else additive; first estimates kept), computed for all attitudes in one
    batch: the filter calls it after every update. dx and P_new must be finite (the filter checks).
    """
    dx = np.asarray(dx, dtype=np.float64)
    if dx.shape != (state.dim,) or np.shape(P_new) != (state.dim, state.dim):
        raise ValueError(f"dx must have shape ({state.dim},) and P_new ({state.dim}, {state.dim}); got "
                         f"{dx.shape} and {np.shape(P_new)}")
    imu = state.imu
    n_cam = state.num_cameras
    dcam = dx[IMU_DIM:].reshape(n_cam, CAMERA_DIM)
    q_C, p_C = state.camera_poses
    # q <- δq(δθ) ⊗ q, for the IMU (row 0) and the cameras (rows 1..N) at once
    q_all = quat_normalize(quat_multiply(
        quat_from_rotvec(np.vstack((dx[THETA], dcam[:, :3]))), np.vstack((imu.q_GtoI, q_C))
    ))
    new_imu = _unchecked(
        ImuState, q_GtoI=_frozen(q_all[0].copy()), b_g=_frozen(imu.b_g + dx[BG]),
        v_IinG=_frozen(imu.v_IinG + dx[VEL]), b_a=_frozen(imu.b_a + dx[BA]), p_IinG=_frozen(imu.p_IinG + dx[POS]),
        timestamp=imu.timestamp, q_GtoI_null=imu.q_GtoI_null, v_IinG_null=imu.v_IinG_null,
        p_IinG_null=imu.p_IinG_null,
    )
    p_new = p_C + dcam[:, 3:]  # p_CinG <- p_CinG + δp_C
    cameras = {
        cam.id: _camera_unchecked(cam.id, cam.timestamp, _frozen(q_all[i + 1].copy()), _frozen(p_new[i].copy()),
                                  cam.q_GtoC_null, cam.p_CinG_null)
        for i, cam in enumerate(state.cameras.values())
    }
    return _filter_state_unchecked(new_imu, cameras, np.array(P_new, dtype=np.float64), state)


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


@dataclass
class _FeatureUse:
    """One feature entering an update: its observations (window indices, xy) and which of them give residuals."""

    window_idx: NDArray[np.int64]  # (M,) positions of the observing cameras in the window
    xy: NDArray[np.float64]  # (M, 2) undistorted normalised observations
    involved: NDArray[np.bool_]  # (M,) observations used in the Jacobian (all, or those in removed states)
    whiten: NDArray[np.float64] | None = None  # (M, 2, 2) W_i = L_i^-1 of Σ_i; None: I / feature_noise_sigma


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
        self.rejections: Counter[str] = Counter()
        self.tracks: dict[int, list[tuple[int, NDArray[np.float64], NDArray[np.float64]]]] = {}
        self._track_stream: dict[int, int] = {}  # the frame stream of each track (one stream: all 0)
        self._track_last_image: dict[int, int] = {}  # the stream's image count when each track was last observed
        self._stream_images: Counter[int] = Counter()  # images processed per stream
        self._next_camera_id = max(state.camera_ids, default=-1) + 1
        self._tracking_rate = 1.0
        self._imu_t = np.zeros(0)
        self._imu_w = np.zeros((0, 3))
        self._imu_a = np.zeros((0, 3))
        self._pending: list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]] = []
        self._last_imu_t = -math.inf
        self._hook = constrain_transition if config.observability_constrained else None
        self._iso_whiten = np.eye(2) / config.feature_noise_sigma  # W = I / σ (Σ = σ² I); shared, never written
        self._iso_whiten.flags.writeable = False
        self._gravity = config.gravity
        self._tri_settings = dict(
            max_iterations=config.triangulation_max_iterations,
            step_tol=config.triangulation_tolerance,
            min_baseline_ratio=config.triangulation_min_baseline_ratio,
            min_depth=config.triangulation_min_depth,
            max_depth=config.triangulation_max_depth,
            max_rms_residual=config.triangulation_max_reprojection_px / config.focal_length_px,
        )
        self._frame_counters: Counter[str] = Counter()
        self.faults: Counter[str] = Counter()
        self._imu_fed = 0  # IMU samples accepted by feed_imu so far, dropped ones included
        self._gyro_seen = 0  # in-range gyro samples fed, and those turning faster than _DEG_S_SUSPECT_RATE
        self._gyro_fast = 0
        self._last_gap_end = -math.inf  # end of the last IMU gap counted (a gap crossed in two calls counts once)

    # ------------------------------------------------------------------------------------------------ properties
    @property
    def state(self) -> FilterState:
        """Return the current filter state (immutable)."""
        return self._state

    # ------------------------------------------------------------------------------------------------ input
    def feed_imu(self, t: float | ArrayLike, gyro: ArrayLike, accel: ArrayLike) -> None:
        """Buffer IMU samples: one (t float, gyro (3,), accel (3,)) or a batch (t (n,), gyro (n, 3), accel (n, 3)).

        Times must be finite, strictly increasing and later than every sample fed before (s); gyro in rad/s and
        accel (specific force) in m/s^2, both in I. Samples with a component beyond the IMU's full scale
        (``config.gyro_full_scale``, ``accel_full_scale``) are dropped (counted in ``faults``, warned); a batch that
        would make them more than 10 % of the samples fed (from 10 samples on) raises ValueError, naming the
        likely unit mistake, and nothing of it is buffered.
        """
        try:
            t_arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
            w = np.asarray(gyro, dtype=np.float64).reshape(-1, 3) if np.size(gyro) % 3 == 0 else None
            a = np.asarray(accel, dtype=np.float64).reshape(-1, 3) if np.size(accel) % 3 == 0 else None
        except (TypeError, ValueError) as exc:
            raise ValueError("t, gyro and accel must be numeric: t (n,), gyro (n, 3), accel (n, 3)") from exc
        if t_arr.ndim != 1:
            raise ValueError(f"t must be a time or shape (n,); got shape {np.shape(t)}")
        n = t_arr.shape[0]
        if w is None or a is None or w.shape != (n, 3) or a.shape != (n, 3):
            raise ValueError(
                f"gyro and accel must have shape (n, 3) = ({n}, 3) (or (3,) for one sample); "
                f"got {np.shape(gyro)} and {np.shape(accel)}"
            )
        if not (np.all(np.isfinite(t_arr)) and np.all(np.isfinite(w)) and np.all(np.isfinite(a))):
            raise ValueError("t, gyro and accel must contain only finite values (no NaN/inf)")
        if n == 0:
            return
        if np.any(np.diff(t_arr) <= 0.0) or t_arr[0] <= self._last_imu_t:
            raise ValueError(
                f"t must be strictly increasing and later than the last sample fed ({self._last_imu_t!r}); "
                f"got times from {t_arr[0]!r}"
            )
        t_last = float(t_arr[-1])  # dropped samples count for the time order too
        keep = self._check_imu_range(t_arr, w, a)
        if keep is not None:
            t_arr, w, a = t_arr[keep], w[keep], a[keep]
        if t_arr.shape[0]:
            self._pending.append((t_arr.copy(), w.copy(), a.copy()))
        self._last_imu_t = t_last
        self._check_gyro_units(w)

    def _warn(self, key: str, count: int, message: str) -> None:
        """Add count to faults[key]; warn with message the first time and when the total reaches 10, 100, ..."""
        old = self.faults[key]
        new = old + count
        self.faults[key] = new
        self._frame_counters[key] += count
        if old == 0 or int(math.log10(new)) > int(math.log10(old)):
            warnings.warn(f"{message} [{new} so far: Msckf.faults[{key!r}]]", MsckfWarning, stacklevel=4)

    def _check_imu_range(self, t: NDArray[np.float64], w: NDArray[np.float64],
                         a: NDArray[np.float64]) -> NDArray[np.bool_] | None:
        """Return the mask of samples within the IMU's full scale (None: all are); raise on a wrong-units batch."""
        cfg = self.config
        bad_w = np.any(np.abs(w) > cfg.gyro_full_scale, axis=1)
        bad_a = np.any(np.abs(a) > cfg.accel_full_scale, axis=1)
        n_w, n_a, n = int(np.count_nonzero(bad_w)), int(np.count_nonzero(bad_a)), t.shape[0]
        seen = self._imu_fed + n
        if n_w == 0 and n_a == 0:
            self._imu_fed = seen
            return None
        gyro_range = (f"the gyro's full scale ±{cfg.gyro_full_scale:.4g} rad/s "
                      f"({math.degrees(cfg.gyro_full_scale):.0f} deg/s, gyro_full_scale)")
        accel_range = (f"the accelerometer's full scale ±{cfg.accel_full_scale:.4g} m/s^2 "
                       f"({cfg.accel_full_scale / 9.80665:.3g} g, accel_full_scale)")
        total_w = self.faults["imu_gyro_out_of_range"] + n_w
        total_a = self.faults["imu_accel_out_of_range"] + n_a
        if seen >= _UNITS_MIN_SAMPLES and total_w > _UNITS_FRACTION * seen:
            raise ValueError(
                f"gyro must be in rad/s: {total_w} of the {seen} samples fed exceed {gyro_range}, largest "
                f"|component| {np.abs(w).max():.4g}; these look like deg/s (np.radians converts them). "
                "Nothing of this batch was buffered"
            )
        if seen >= _UNITS_MIN_SAMPLES and total_a > _UNITS_FRACTION * seen:
            raise ValueError(
                f"accel must be the specific force in m/s^2: {total_a} of the {seen} samples fed exceed "
                f"{accel_range}, largest |component| {np.abs(a).max():.4g}; check the units (g, mg or mm/s^2 need "
                "converting). Nothing of this batch was buffered"
            )
        self._imu_fed = seen
        for key, bad, values, what, hint in (
                ("imu_gyro_out_of_range", bad_w, w, gyro_range, "; gyro must be in rad/s (deg/s?)"),
                ("imu_accel_out_of_range", bad_a, a, accel_range, "")):
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                self._warn(key, int(np.count_nonzero(bad)),
                           f"feed_imu dropped {int(np.count_nonzero(bad))} IMU sample(s) beyond {what}, the first "
                           f"at t = {t[k]:.3f} s ({values[k].tolist()}){hint}; the IMU signal is interpolated "
                           "across the hole")
        return ~(bad_w | bad_a)

    def _check_gyro_units(self, w: NDArray[np.float64]) -> None:
        """Warn once when most gyro samples fed so far turn faster than one revolution per second (deg/s?)."""
        if self.faults["gyro_units_suspect"] or w.shape[0] == 0:
            return
        self._gyro_seen += w.shape[0]
        self._gyro_fast += int(np.count_nonzero(np.einsum("ij,ij->i", w, w) > _DEG_S_SUSPECT_RATE**2))
        if self._gyro_seen >= _DEG_S_MIN_SAMPLES and 2 * self._gyro_fast > self._gyro_seen:
            self._warn("gyro_units_suspect", 1,
                       f"gyro must be in rad/s: {self._gyro_fast} of the {self._gyro_seen} samples fed turn faster "
                       f"than one revolution per second (|ω| > 2π rad/s), which looks like deg/s "
                       "(np.radians converts them)")

    def _imu_buffer(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Return the buffered IMU arrays, merged, without samples older than the last one at or before the state."""
        if self._pending:
            self._imu_t = np.concatenate([self._imu_t] + [p[0] for p in self._pending])
            self._imu_w = np.concatenate([self._imu_w] + [p[1] for p in self._pending])
            self._imu_a = np.concatenate([self._imu_a] + [p[2] for p in self._pending])
            self._pending = []
        j = max(int(np.searchsorted(self._imu_t, self._state.timestamp, side="right")) - 1, 0)
        if j > 0:  # views, no copies
            self._imu_t, self._imu_w, self._imu_a = self._imu_t[j:], self._imu_w[j:], self._imu_a[j:]
        return self._imu_t, self._imu_w, self._imu_a

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
        and threaded BLAS made it 6x slower in CPU time on a 2-core machine.
        """
        if isinstance(stream, bool) or not isinstance(stream, (int, np.integer)) or stream < 0:
            raise ValueError(f"stream must be an integer >= 0; got {stream!r}")
        with single_threaded_blas():
            return self._process_image(t, ids, xy, xy_cov, int(stream))

    def _process_image(self, t: float, ids: ArrayLike, xy: ArrayLike, xy_cov: ArrayLike | None,
                       stream: int = 0) -> FilterOutput:
        """The body of :meth:`process_image`."""
        t, ids, xy = self._check_image(t, ids, xy)
        other = [fid for fid in ids.tolist() if self._track_stream.get(fid, stream) != stream]
        if other:
            raise ValueError(f"process_image(stream={stream}) got feature id {other[0]}, a track of stream "
                             f"{self._track_stream[other[0]]}; each stream needs its own ids")
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
            self.tracks.clear()
            self._track_stream.clear()
            self._track_last_image.clear()
        else:
            self._stream_images[stream] += 1  # the clock of max_track_gap: images of this stream so far
            self._add_observations(camera_id, ids, xy, whiten, stream)
            lost = self._collect_lost_features(ids, stream)
            pruned = self._collect_pruned_features(remove)
            self._frame_counters["lost_tried"] += len(lost)
            self._frame_counters["prune_tried"] += len(pruned)
            used_mask = self._update(lost + pruned, far=self._far_points_now())
            used = int(np.count_nonzero(used_mask))
            self._frame_counters["lost_used"] += int(np.count_nonzero(used_mask[:len(lost)]))
            self._frame_counters["prune_used"] += int(np.count_nonzero(used_mask[len(lost):]))
        self._marginalize(remove)
        self._remove_unused_tracks()
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
        imu_t, imu_w, imu_a = self._imu_buffer()
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
        """Propagate the state to time t with the buffered IMU samples (OC hook when configured), count and warn
        about the IMU gaps crossed, and refuse a result that is not finite or whose IMU covariance is not PSD."""
        t0 = self._state.timestamp
        if t == t0:
            return
        imu_t, imu_w, imu_a = self._imu_buffer()
        if imu_t.shape[0] == 0:
            raise ValueError("no IMU samples buffered: call feed_imu before process_image")
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # the result is checked below
                state = propagate(self._state, imu_t, imu_w, imu_a, t, self.config, transition_hook=self._hook)
        except ImuGapError:
            self.faults["imu_gap_refused"] += 1
            raise
        except ValueError as exc:  # the inputs were checked: a breakdown of the numbers (e.g. an absurd time span)
            state, problem = None, f"the integration failed ({exc})"
        else:
            problem = state_problem(state, psd_size=IMU_DIM)  # P_CC is unchanged, P_IC = Φ P_IC checked finite
        if problem is not None:
            self.faults["propagation_refused"] += 1
            raise StepRefusedError(
                f"propagation from t = {t0:.3f} s to t = {t:.3f} s refused: {problem}; the filter keeps its state at "
                f"t = {t0:.3f} s. Check the IMU samples and the image time in between"
            )
        assert state is not None
        self._state = state
        cfg = self.config
        for start, end in imu_gaps(imu_t, t0, t, cfg.imu_max_gap):
            if start > self._last_gap_end:  # a new gap, not the rest of one counted by the previous call
                self._warn("imu_gaps", 1,
                           f"IMU gap of {end - start:.3g} s > imu_max_gap = {cfg.imu_max_gap:g} s (no samples from "
                           f"t = {start:.3f} s to t = {end:.3f} s): bridged by interpolation, covariance inflated "
                           f"for the unseen motion (imu_gap_accel_sigma = {cfg.imu_gap_accel_sigma:g} m/s^2, "
                           f"imu_gap_gyro_sigma = {cfg.imu_gap_gyro_sigma:g} rad/s)")
            self._last_gap_end = max(self._last_gap_end, float(end))

    def _augment(self) -> int:
        """Clone the current camera pose into the window; return its camera id."""
        camera_id = self._next_camera_id
        self._next_camera_id += 1
        self._state = augment_state(self._state, camera_id)
        return camera_id

    def _add_observations(self, camera_id: int, ids: NDArray[np.int64], xy: NDArray[np.float64],
                          whiten: NDArray[np.float64] | None, stream: int = 0) -> None:
        """Append this image's observations (with their whitening matrices) to the tracks; record the tracking
        rate (share of known ids)."""
        tracked = 0
        tracks = self.tracks
        image = self._stream_images[stream]  # this image's number in its stream (counted in _process_image)
        last_image = self._track_last_image
        W_all = [self._iso_whiten] * ids.shape[0] if whiten is None else whiten
        for fid, z, W in zip(ids.tolist(), xy, W_all):
            track = tracks.get(fid)
            if track is None:
                tracks[fid] = [(camera_id, z, W)]
                self._track_stream[fid] = stream
            else:
                track.append((camera_id, z, W))
                tracked += 1
            last_image[fid] = image
        self._tracking_rate = tracked / ids.shape[0] if ids.shape[0] else 0.0

    def _collect_lost_features(self, ids: NDArray[np.int64], stream: int = 0) -> list[_FeatureUse]:
        """Remove the tracks of ``stream`` that ended (missing from more than ``config.track_gap_of(stream)`` of its
        images in a row: with 0, not in ``ids``); return those long enough to be used (all their observations)."""
        current = set(ids.tolist())
        streams = self._track_stream
        last_image = self._track_last_image
        oldest = self._stream_images[stream] - self.config.track_gap_of(stream)  # last seen before this image: ended
        lost = [fid for fid in self.tracks
                if fid not in current and streams[fid] == stream and last_image[fid] < oldest]
        if not lost:
            return []
        pos = self._window_positions()
        uses = []
        for fid in lost:
            track = self.tracks.pop(fid)
            del streams[fid]
            del last_image[fid]
            if len(track) < self.config.min_track_length:
                self.rejections["too_few_observations"] += 1
                continue
            idx = np.fromiter((pos[c] for c, _, _ in track), dtype=np.int64, count=len(track))
            uses.append(_FeatureUse(idx, np.array([z for _, z, _ in track]), np.ones(len(track), dtype=bool),
                                    np.array([W for _, _, W in track])))
        return uses

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
                    and self._tracking_rate > self.config.keyframe_tracking_rate_threshold):
                removed.append(ids[cand])
                cand += 1
            else:
                removed.append(ids[oldest])
                oldest += 1
        extra = [i for i in ids[:-1] if i not in removed][: max(excess - 2, 0)]  # window far too large: oldest
        return sorted(set(removed + extra), key=ids.index)

    def _collect_pruned_features(self, remove: list[int]) -> list[_FeatureUse]:
        """Return the features seen at >= 2 of the states to ``remove`` (those observations give the residuals).

        The observations made at those states are deleted from every track (they are used now or never).
        """
        if not remove or not self.tracks:
            return []
        gone = set(remove)
        pos = self._window_positions()
        uses = []
        for fid, track in self.tracks.items():
            involved = [obs[0] in gone for obs in track]
            n_involved = sum(involved)
            if n_involved == 0:
                continue
            if n_involved >= 2:
                idx = np.fromiter((pos[c] for c, _, _ in track), dtype=np.int64, count=len(track))
                uses.append(_FeatureUse(idx, np.array([z for _, z, _ in track]), np.array(involved),
                                        np.array([W for _, _, W in track])))
            self.tracks[fid] = [obs for obs in track if obs[0] not in gone]
        return uses

    def _marginalize(self, remove: list[int]) -> None:
        """Remove the camera states ``remove`` from the window (drop their rows and columns of P)."""
        if remove:
            self._state = remove_camera_states(self._state, remove)
            self._frame_counters["cameras_removed"] += len(remove)

    def _remove_unused_tracks(self) -> None:
        """Drop tracks left without observations in the window."""
        for fid in [fid for fid, track in self.tracks.items() if not track]:
            del self.tracks[fid]
            del self._track_stream[fid]
            del self._track_last_image[fid]

    # ------------------------------------------------------------------------------------------------ the update
    def _window_positions(self) -> dict[int, int]:
        return {cid: i for i, cid in enumerate(self._state.camera_ids)}

    def _far_points_now(self) -> bool:
        """Return whether this image's update may use far points: ``far_point_fallback`` on, and the gate (never
        ungated: no residual check)."""
        return self.config.far_point_fallback and self.config.chi2_gating

    def _update(self, uses: list[_FeatureUse], far: bool = False) -> NDArray[np.bool_]:
        """Triangulate, gate, build, stack and apply ONE compressed EKF update; return which of ``uses`` were used.

        Gating tests each feature on ALL its observations in the window (dof 2M - 3), also when only some of them
        (a prune's) give the update's rows: a moving point shows over its whole track, and a gate with more
        degrees of freedom biases the kept residuals less (``update.gating_mean_shrink``).
        """
        used = np.zeros(len(uses), dtype=bool)
        if not uses:
            return used
        state = self._state
        q_C, p_C = state.camera_poses
        R_C = quat_to_rot(q_C)  # (N, 3, 3) R_GtoC of the window
        results = triangulate_inverse_depth_batch(
            [(R_C[u.window_idx], p_C[u.window_idx], u.xy) for u in uses], **self._tri_settings
        )
        if self.config.observation_outlier_px is not None:
            uses, results = self._drop_outlier_observations(uses, results, R_C, p_C)
        ok: list[tuple[int, _FeatureUse, NDArray[np.float64]]] = []
        for k, (u, res) in enumerate(zip(uses, results)):
            if far and res.reason in _FAR_POINT_REASONS and np.count_nonzero(u.involved) >= 2:
                # low parallax: the depth is not observable from this track, its bearing is. A point far along
                # the anchor's bearing; the nullspace projection removes its position error to first order, so
                # the rows constrain the rotation between the cameras; the chi-square gate below judges them.
                # Counted here as a candidate (the gate may still refuse it, then counted there too). The bearing
                # is the fitted (α, β) of the anchor (finite on every failure path; with no baseline at all, the
                # starting guess, i.e. about the anchor's own observation).
                self.rejections["far_point_fallback"] += 1
                a = u.window_idx[res.anchor]
                alpha, beta, _ = res.inverse_depth
                p_FinA = np.array([alpha, beta, 1.0]) * self.config.triangulation_max_depth
                ok.append((k, u, p_C[a] + R_C[a].T @ p_FinA))
            elif not res.success:
                self.rejections[res.reason] += 1
            elif np.count_nonzero(u.involved) < 2:  # 2 rows cannot survive the 3-column nullspace projection
                self.rejections["too_few_observations"] += 1
            else:
                ok.append((k, u, res.p_FinG))
        if self.config.observability_constrained:
            cams = state.cameras.values()
            R_null = quat_to_rot(np.array([c.q_GtoC_null for c in cams]))
            p_null = np.array([c.p_CinG_null for c in state.cameras.values()])
        else:
            R_null = p_null = None

        # gate on whole tracks, grouped by their length M; the projections of fully used tracks (ended tracks)
        # are the update's rows as they are
        gating = self.config.chi2_gating
        by_length: dict[int, list[tuple[int, _FeatureUse, NDArray[np.float64]]]] = {}
        for item in ok:
            if gating or item[1].involved.all():
                by_length.setdefault(item[1].xy.shape[0], []).append(item)
        passed = dict.fromkeys((k for k, _, _ in ok), True)
        H_parts, r_parts, col_parts = [], [], []
        for M, items in by_length.items():
            keep, H_o, r_o, cols = self._project(M, [(np.ones(M, dtype=bool), u, p) for _, u, p in items],
                                                 R_C, p_C, R_null, p_null)
            if gating:
                gamma = self._mahalanobis(H_o, r_o, cols, state.P)
                good = gamma < chi_square_threshold(2 * M - 3, self.config.chi2_probability)
                self.rejections["chi2"] += int(np.count_nonzero(keep & ~good))
                keep &= good
            ks = np.array([k for k, _, _ in items])
            passed.update(zip(ks.tolist(), keep.tolist()))
            take = keep & np.array([u.involved.all() for _, u, _ in items])
            if np.any(take):
                used[ks[take]] = True
                H_parts.append(H_o[take])
                r_parts.append(r_o[take])
                col_parts.append(cols[take])
        groups: dict[int, list[tuple[int, _FeatureUse, NDArray[np.float64]]]] = {}
        for k, u, p in ok:
            if passed[k] and not u.involved.all():  # whole tracks were used (or dropped) above
                groups.setdefault(int(np.count_nonzero(u.involved)), []).append((k, u, p))
        for m, items in groups.items():  # pruned tracks: rows from the observations at the removed states only
            keep, H_o, r_o, cols = self._project(m, [(u.involved, u, p) for _, u, p in items], R_C, p_C, R_null,
                                                 p_null)
            used[np.array([k for k, _, _ in items])[keep]] = True
            H_parts.append(H_o[keep])
            r_parts.append(r_o[keep])
            col_parts.append(cols[keep])
        if not np.any(used) or not self._apply_update(H_parts, r_parts, col_parts):
            used[:] = False
        return used

    def _drop_outlier_observations(self, uses: list[_FeatureUse], results: list[Any], R_C: NDArray[np.float64],
                                   p_C: NDArray[np.float64]) -> tuple[list[_FeatureUse], list[Any]]:
        """Return (uses, results) with each track's outlying observations dropped and the track triangulated again.

        An observation is an outlier when it reprojects farther than ``config.observation_outlier_px`` from the
        triangulated point (the last estimate also when the triangulation failed for its RMS residual, which one
        jump can cause). The worst go first, while at least ``min_track_length`` observations and two thirds of
        the track remain; a pruned feature keeps at least two involved observations. Counted in
        ``rejections["outlier_observations"]``."""
        limit = self.config.observation_outlier_px / self.config.focal_length_px  # normalised units
        changed: list[int] = []
        uses = list(uses)
        for k, (u, res) in enumerate(zip(uses, results)):
            M = u.xy.shape[0]
            if M <= self.config.min_track_length or not (res.success or res.reason == "large_residual"):
                continue
            p_FinC = np.einsum("mij,mj->mi", R_C[u.window_idx], res.p_FinG - p_C[u.window_idx])
            if np.any(p_FinC[:, 2] <= 1e-9):
                continue
            err = np.linalg.norm(u.xy - p_FinC[:, :2] / p_FinC[:, 2:3], axis=1)
            order = np.argsort(err)[::-1]
            most = min(M - self.config.min_track_length, M // 3)
            drop = [i for i in order[:most] if err[i] > limit]
            keep = np.ones(M, dtype=bool)
            keep[drop] = False
            if not drop or np.count_nonzero(u.involved & keep) < min(2, np.count_nonzero(u.involved)):
                continue
            self.rejections["outlier_observations"] += len(drop)
            uses[k] = _FeatureUse(u.window_idx[keep], u.xy[keep], u.involved[keep],
                                  None if u.whiten is None else u.whiten[keep])
            changed.append(k)
        if changed:
            again = triangulate_inverse_depth_batch(
                [(R_C[uses[k].window_idx], p_C[uses[k].window_idx], uses[k].xy) for k in changed],
                **self._tri_settings)
            results = list(results)
            for k, res in zip(changed, again):
                results[k] = res
        return uses, results

    def _project(
        self,
        m: int,
        items: list[tuple[NDArray[np.bool_], _FeatureUse, NDArray[np.float64]]],
        R_C: NDArray[np.float64],
        p_C: NDArray[np.float64],
        R_null: NDArray[np.float64] | None,
        p_null: NDArray[np.float64] | None,
    ) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
        """Return (keep (F,), H_o, r_o, cols) for F features with m observations selected by each item's mask:
        the projected Jacobians H_o (F, 2m-3, 6m), residuals r_o (F, 2m-3) and camera columns cols (F, 6m);
        keep is False where a depth or a value is not usable.

        Vectorised over the F features: residuals and Jacobians (Eqs. 41-48), whitening, nullspace projection
        (Eq. 50) and, with the first-estimate poses R_null, p_null, the OC constraint H_o N_C = 0. H_o holds only the observing cameras' columns ``cols``.
        """
        widx = np.array([u.window_idx[sel] for sel, u, _ in items])  # (F, m)
        z = np.array([u.xy[sel] for sel, u, _ in items])  # (F, m, 2)
        W = np.array([np.broadcast_to(self._iso_whiten, (m, 2, 2)) if u.whiten is None else u.whiten[sel]
                      for sel, u, _ in items])  # (F, m, 2, 2) W_i = L_i^-1, Σ_i = L_i L_i^T
        p_F = np.array([p for _, _, p in items])  # (F, 3)
        F = widx.shape[0]
        R = R_C[widx]  # (F, m, 3, 3)
        p_FinC = np.einsum("fmij,fmj->fmi", R, p_F[:, None, :] - p_C[widx])  # R_GtoC (p_F - p_C)       (Eq. 42)
        Z = p_FinC[..., 2]
        front = np.all(Z > 1e-9, axis=1)
        if not np.all(front):  # a far point (far_point_fallback) of an inconsistent track; else guarded anyway
            self.rejections["behind_camera"] += int(np.count_nonzero(~front))
            Z = np.where(front[:, None], Z, 1.0)
        inv_Z = 1.0 / Z
        z_hat = p_FinC[..., :2] * inv_Z[..., None]  # [X/Z, Y/Z]                                          (Eq. 41)
        r = (z - z_hat).reshape(F, 2 * m)  # r = z_meas - z_hat                                           (Eq. 43)
        x, y = z_hat[..., 0], z_hat[..., 1]
        # H_f,i = J_i R_GtoC_i with J_i = 1/Z [[1, 0, -x], [0, 1, -y]]                                  (Eqs. 46, 48)
        H_f = (R[..., :2, :] - z_hat[..., :, None] * R[..., 2:3, :]) * inv_Z[..., None, None]  # (F, m, 2, 3)
        blocks = np.empty((F, m, 2, CAMERA_DIM))  # J_i [[p_FinC x], -R_GtoC]                            (Eq. 47)
        xy_ = x * y
        blocks[..., 0, 0], blocks[..., 0, 1], blocks[..., 0, 2] = xy_, -1.0 - x * x, y
        blocks[..., 1, 0], blocks[..., 1, 1], blocks[..., 1, 2] = 1.0 + y * y, -xy_, -x
        blocks[..., 3:] = -H_f
        # whitening: W_i r_i = W_i H_Ci δx_Ci + W_i H_fi δp_F + W_i n_i with W_i n_i ~ N(0, I), done
        # BEFORE the nullspace so that A^T (W n) stays white (A^T A = I).
        r = np.einsum("fmij,fmj->fmi", W, r.reshape(F, m, 2)).reshape(F, 2 * m)  # r_w = W r
        H_f = W @ H_f  # (F, m, 2, 3)
        blocks = W @ blocks  # (F, m, 2, 6)
        # left nullspace of H_f (2m, 3): the last 2m - 3 columns of its complete QR                       (Eq. 50)
        Q = np.linalg.qr(H_f.reshape(F, 2 * m, 3), mode="complete")[0]
        A_T = np.swapaxes(Q[:, :, 3:], 1, 2)  # (F, 2m - 3, 2m)
        # H_o = A^T blockdiag(H_C1 .. H_Cm): camera j's 6 columns get A^T's two columns 2j, 2j+1 times H_Cj
        A_cam = np.swapaxes(A_T.reshape(F, 2 * m - 3, m, 2), 1, 2)  # (F, m, 2m - 3, 2)
        H_o = np.swapaxes(A_cam @ blocks, 1, 2).reshape(F, 2 * m - 3, m * CAMERA_DIM)
        r_o = np.einsum("fkr,fr->fk", A_T, r)
        cols = ((IMU_DIM + CAMERA_DIM * widx)[:, :, None] + np.arange(CAMERA_DIM)).reshape(F, m * CAMERA_DIM)
        if R_null is not None:
            N_C = camera_nullspace(R_null[widx], p_null[widx], self._gravity)  # (F, 6m, 4) first estimates
            H_o = constrain_projected_jacobian(H_o, N_C)  # H_o* = H_o (I - N (N^T N)^-1 N^T): H_o* N_C = 0
        keep = front & np.all(np.isfinite(H_o), axis=(1, 2)) & np.all(np.isfinite(r_o), axis=1)
        return keep, H_o, r_o, cols

    @staticmethod
    def _mahalanobis(H_o: NDArray[np.float64], r_o: NDArray[np.float64], cols: NDArray[np.int64],
                     P: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return γ_f = r_o^T (H_o P H_o^T + I)^-1 r_o for each feature (whitened rows: unit noise; inf if singular).

        H_o only touches the columns ``cols``, so only that block of P is read."""
        k = H_o.shape[1]
        P_sub = P[cols[:, :, None], cols[:, None, :]]
        S = H_o @ P_sub @ np.swapaxes(H_o, 1, 2)
        S[:, np.arange(k), np.arange(k)] += 1.0
        try:
            return np.einsum("fk,fk->f", r_o, np.linalg.solve(S, r_o[:, :, None])[..., 0])
        except np.linalg.LinAlgError:
            return np.full(H_o.shape[0], np.inf)

    def _apply_update(
        self, H_parts: list[NDArray[np.float64]], r_parts: list[NDArray[np.float64]],
        col_parts: list[NDArray[np.int64]],
    ) -> bool:
        """Stack the projected rows into one (rows, 15 + 6N) system, QR-compress it and apply the Kalman update.

        Returns False (state unchanged, counted in ``rejections``) when the update fails or is not finite."""
        state = self._state
        n = state.dim
        rows = sum(h.shape[0] * h.shape[1] for h in H_parts)
        H = np.zeros((rows, n))
        r = np.empty(rows)
        start = 0
        for H_o, r_o, cols in zip(H_parts, r_parts, col_parts):
            F, k, _ = H_o.shape
            row_idx = start + np.arange(F * k).reshape(F, k)
            H[row_idx[:, :, None], cols[:, None, :]] = H_o
            r[start:start + F * k] = r_o.reshape(-1)
            start += F * k
        H_c, r_c = measurement_compress(H, r)  # (Eqs. 51-55) when rows > n
        self._frame_counters["rows"] += rows
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # the result is checked below
                dx, P_new = kalman_update(state.P, H_c, r_c, 1.0)  # (Eqs. 56-58), whitened rows: R = I
        except ValueError as exc:
            return self._refuse_update(f"the Kalman update failed ({exc})")
        if not np.all(np.isfinite(dx)):
            return self._refuse_update("its correction holds non-finite values")
        new_state = apply_correction(state, dx, P_new)
        problem = state_problem(new_state)  # finite, P symmetric positive semi-definite (Cholesky, O(n³ / 3))
        if problem is not None:
            return self._refuse_update(problem)
        self._state = new_state
        self._frame_counters["updates"] += 1
        return True

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
