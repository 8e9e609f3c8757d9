"""Every parameter of the MSCKF back-end in one frozen dataclass that validates and prints itself.

The filter follows thesis §3.3 (Mourikis & Roumeliotis 2007 with the changes of Sun et al. 2018, S-MSCKF). Noise
densities use the continuous-time (Kalibr / EuRoC) convention, the same as ``evio_lib.sim.imu.ImuNoiseParams``:
a white-noise density σ (unit/sqrt(Hz)) gives per-sample noise of std σ sqrt(rate) and contributes σ² to the
continuous noise covariance Q_IMU of thesis Eq. 33. Some fields are only read by later stages of the back-end
(triangulation, measurement update, keyframe selection, initialisation); they live here so one object describes a run.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from evio_lib.msckf.update import chi_square_threshold

__all__ = ["MsckfConfig"]


def _param(default: Any, unit: str, doc: str) -> Any:
    """Return a dataclass field carrying its unit and a one-line description (used by ``__str__``)."""
    return field(default=default, metadata={"unit": unit, "doc": doc})


# kinds of validation, by field name
_NON_NEGATIVE = (
    "imu_gap_accel_sigma", "imu_gap_gyro_sigma",
    "gyro_noise_density", "accel_noise_density", "gyro_random_walk", "accel_random_walk",
    "init_sigma_attitude", "init_sigma_gyro_bias", "init_sigma_velocity", "init_sigma_accel_bias",
    "init_sigma_position", "keyframe_rotation_threshold", "keyframe_translation_threshold",
    "triangulation_min_baseline_ratio", "static_init_duration",
)
_POSITIVE = (
    "pixel_noise_px", "focal_length_px", "triangulation_tolerance", "triangulation_min_depth",
    "triangulation_max_depth", "triangulation_max_reprojection_px",
)
# > 0, and math.inf allowed (switches the guard off)
_POSITIVE_OR_INF = (
    "accel_full_scale", "gyro_full_scale", "imu_max_gap", "imu_max_bridged_gap", "max_normalized_coordinate",
)
_INTEGER_MIN = {"max_camera_states": 2, "min_track_length": 2, "triangulation_max_iterations": 1}
_BOOLEAN = ("marginalize_third", "chi2_gating", "observability_constrained", "imu_only", "far_point_fallback")


@dataclass(frozen=True)
class MsckfConfig:
    """Every parameter of the MSCKF back-end (frozen, validated); ``print(config)`` lists them one per line with units.

    Attributes (defaults in brackets; units in ``fields(MsckfConfig)[i].metadata``):
        gyro_noise_density, accel_noise_density: white-noise densities σ_g [8.73e-5 rad/s/√Hz], σ_a
            [3.92e-3 m/s²/√Hz] (MPU-6150 class IMU of the DAVIS240C, as in the simulator).
        gyro_random_walk, accel_random_walk: bias random-walk densities σ_wg [3.9e-5 rad/s²/√Hz], σ_wa
            [6.0e-3 m/s³/√Hz].
        gravity_G: gravity in the world frame G [(0, 0, -9.81) m/s²].
        init_sigma_*: standard deviations of the initial error state (attitude, gyro bias, velocity, accel bias,
            position), used by ``initial_imu_covariance``.
        max_camera_states: N_max, the sliding-window size [40] (thesis §3.3.6.1; S-MSCKF uses 20).
        min_track_length: minimum number of observations for a finished track to be used in an update [3].
        marginalize_third: when the window is full, marginalise the oldest third of it at once (Mourikis &
            Roumeliotis 2007; the thesis's future-work item) instead of S-MSCKF's two keyframe-selected states
            [True]. Both rules stay: lessons 12 and 13 compare them in exercises; the measured NEES and drift of
            each are in docs/explanations/consistency.md ("Reaching the band").
        keyframe_*: S-MSCKF's two-way keyframe selection thresholds (rotation, translation, tracking rate), read
            when ``marginalize_third`` is False.
        pixel_noise_px, focal_length_px: feature measurement noise in pixels and the focal length that converts
            it to normalised image coordinates (``feature_noise_sigma``).
        observation_outlier_px: per-observation outlier test [None: off]. After a track is triangulated, its
            observations reprojecting farther than this many pixels from the point are dropped (the worst first,
            while at least ``min_track_length`` remain and at most a third go) and the point is triangulated again
            without them, so that one jumped observation (a descriptor match to a similar-looking place) costs one
            observation instead of poisoning, or losing, the whole track. The chi-square gate then tests what is
            left.
        far_point_fallback: keep tracks without parallax [False]. A track whose triangulation fails as behind a
            camera, beyond ``triangulation_max_depth`` or without baseline (the inverse depth ρ ~ 1/Z is then
            smaller than its noise σ_ρ ≈ σ_px / (f b)) is given the point p_A + R_AtoG [α, β, 1] Z_max on its
            anchor camera's fitted bearing (α, β) and goes through the chi-square gate like any track (with
            ``chi2_gating`` off there is no gate, and the option does nothing). The nullspace projection
            (Eq. 50) removes the point's error to first order, so what remains constrains the rotation between
            the cameras. Off by default (the thesis's filter), here and in the pipeline
            (``PipelineConfig.far_points``): it kept the CNN on course over the aerial terrain but cost SIFT and KLT
            accuracy (measured: docs/archive.md, the row "tracks without parallax placed far on their bearing").
        max_track_gap: images of its stream a track may miss and still continue [0]. With 0 a track ends at the first
            image without it and is used then; with g > 0 it is kept (its observations need not come from
            consecutive clones) until more than g images in a row lack it, so a front-end that finds a feature
            again after a missed detection (``FrontendConfig.max_track_gap``) continues one track instead of two
            short ones. The update of such a track comes g images later. A tuple gives each frame stream its own g
            (index = the ``stream`` of ``Msckf.process_image``; e.g. ``(2, 0)``: descriptor tracks with gaps on
            stream 0, KLT tracks, which never come back, on stream 1); :meth:`track_gap_of` reads it.
        chi2_gating, chi2_probability: per-feature chi-square (Mahalanobis) gating and its probability [0.95],
            applied to ALL of a feature's observations in the window (dof 2M - 3) even when a prune uses only
            some. A gate also throws away correct data, and which data depends on the residual: the kept
            residuals' mean shrinks by ``update.gating_mean_shrink`` (0.76 for the 1-row features of a
            two-state prune gated alone at 95 %), so every update under-corrects while P shrinks in full. With
            outliers the gate earns its keep, so real tracks keep 0.95 and the perfect-data-association
            experiments use 0.99 (``experiment.VioSimConfig.gate_probability``); the pose NEES at each gate and
            the error with moving-point tracks: docs/explanations/consistency.md.
        triangulation_*: inverse-depth Gauss-Newton settings and the checks that reject bad features.
        observability_constrained: OC-EKF on/off (thesis §3.3.8) [True]: first-estimate transition matrices
            (Eqs. 81-84) and, on the update side, each feature's nullspace-projected Jacobian changed minimally so
            that H_o N = 0 for the observing cameras' first-estimate nullspace N
            (``observability.constrain_projected_jacobian``).
        imu_only: propagate only, never update (thesis Table 6 baseline) [False].
        static_init_duration: length of the stationary IMU window used by the static initialisation [1.0 s].
        accel_full_scale, gyro_full_scale: measurement range of the IMU, per axis [±16 g = 156.9 m/s², ±2000 deg/s
            = 34.9 rad/s, a typical MEMS IMU's largest range]. ``Msckf.feed_imu`` drops samples beyond it (counted
            in ``Msckf.faults``, with a warning), and refuses a batch that is mostly beyond it (wrong units, e.g.
            deg/s). ``math.inf`` switches the check off.
        imu_max_gap: longest interval without IMU samples that is bridged by interpolation alone [0.05 s].
        imu_gap_accel_sigma, imu_gap_gyro_sigma: std of the specific force [10 m/s²] and angular rate [1 rad/s]
            that the IMU did not see over a longer gap; the covariance grows as for a constant unknown deviation
            of that size (white noise of density σ² T over a gap of length T: var δv = σ_a² T², var δθ = σ_g² T²).
            How far the true signal strays from the interpolation over a gap, measured on the simulator's
            presets: docs/results/msckf.md ("IMU gaps").
        imu_max_bridged_gap: a longer gap stops the propagation with ``propagation.ImuGapError`` [0.3 s]: the
            attitude error over it (σ_g T > 0.3 rad) is too large for the linearised updates that follow (the first
            updates after a gap are overconfident, linearised at a large attitude uncertainty). The position errors
            in σ after bridged gaps, which set the limit: docs/results/msckf.md ("IMU gaps").
        max_normalized_coordinate: |x| or |y| of an observation beyond this is outside any plausible field of
            view (10: 84° off axis) [10]; a frame mostly beyond it is refused as pixel coordinates, single ones are
            dropped (``rejections['outside_field_of_view']``).

    Reference: thesis §3.3 (Eqs. 18-86); Sun et al., "Robust stereo visual inertial odometry for fast autonomous
    flight", RA-L 2018 (S-MSCKF).

    >>> cfg = MsckfConfig(max_camera_states=10)
    >>> cfg.max_camera_states, round(cfg.feature_noise_sigma, 5)
    (10, 0.00503)
    >>> print(str(cfg).splitlines()[1])
      gyro_noise_density                 = 8.73e-05      rad/s/sqrt(Hz)    gyroscope white-noise density sigma_g
    """

    # IMU noise (thesis Eq. 33: n_IMU = [n_g, n_wg, n_a, n_wa])
    gyro_noise_density: float = _param(8.73e-5, "rad/s/sqrt(Hz)", "gyroscope white-noise density sigma_g")
    accel_noise_density: float = _param(3.92e-3, "m/s^2/sqrt(Hz)", "accelerometer white-noise density sigma_a")
    gyro_random_walk: float = _param(3.9e-5, "rad/s^2/sqrt(Hz)", "gyro bias random-walk density sigma_wg")
    accel_random_walk: float = _param(6.0e-3, "m/s^3/sqrt(Hz)", "accel bias random-walk density sigma_wa")
    gravity_G: tuple[float, float, float] = _param((0.0, 0.0, -9.81), "m/s^2", "gravity in the world frame G")
    # initial covariance of the IMU error state [dtheta, db_g, dv, db_a, dp]
    init_sigma_attitude: float = _param(1e-3, "rad", "initial std of each attitude error component")
    init_sigma_gyro_bias: float = _param(0.03, "rad/s", "initial std of each gyro bias component")
    init_sigma_velocity: float = _param(0.1, "m/s", "initial std of each velocity component")
    init_sigma_accel_bias: float = _param(0.15, "m/s^2", "initial std of each accel bias component")
    init_sigma_position: float = _param(1e-3, "m", "initial std of each position component")
    # sliding window and update triggers (thesis §3.3.6.1)
    max_camera_states: int = _param(40, "", "N_max: camera poses kept in the sliding window")
    min_track_length: int = _param(3, "", "observations a finished track needs to be used")
    marginalize_third: bool = _param(True, "", "prune a third of a full window at once (else 2 states)")
    keyframe_rotation_threshold: float = _param(0.2618, "rad", "keyframe selection: relative rotation")
    keyframe_translation_threshold: float = _param(0.4, "m", "keyframe selection: relative translation")
    keyframe_tracking_rate_threshold: float = _param(0.5, "", "keyframe selection: fraction of tracks kept")
    # measurement model and gating
    pixel_noise_px: float = _param(1.0, "px", "feature measurement noise std")
    focal_length_px: float = _param(199.0, "px", "focal length converting pixel noise to normalised units")
    chi2_gating: bool = _param(True, "", "reject features failing the chi-square test")
    chi2_probability: float = _param(0.95, "", "chi-square gating probability (quantile)")
    observation_outlier_px: float | None = _param(None, "px", "drop a track's observations reprojecting farther "
                                                              "than this after triangulation (None: off)")
    max_track_gap: int | tuple[int, ...] = _param(0, "", "images of its stream a track may miss and continue (0: "
                                                          "ends at the first; a tuple: one per frame stream)")
    # triangulation (inverse-depth Gauss-Newton, thesis §3.3.7)
    triangulation_max_iterations: int = _param(10, "", "Gauss-Newton iterations at most")
    triangulation_tolerance: float = _param(1e-7, "", "stop when the update norm falls below this")
    triangulation_min_depth: float = _param(0.1, "m", "reject features closer than this to any camera")
    triangulation_max_depth: float = _param(1000.0, "m", "reject features farther than this")
    triangulation_min_baseline_ratio: float = _param(0.002, "", "reject if max baseline / depth is below this")
    triangulation_max_reprojection_px: float = _param(5.0, "px", "reject if the RMS reprojection error exceeds")
    far_point_fallback: bool = _param(False, "", "a track whose triangulation lands behind a camera, beyond the max "
                                                 "depth or without baseline: placed at the max depth on its anchor "
                                                 "bearing, gated")
    # filter variants and modes
    observability_constrained: bool = _param(True, "", "observability-constrained EKF (thesis §3.3.8)")
    imu_only: bool = _param(False, "", "propagate only, no visual updates")
    static_init_duration: float = _param(1.0, "s", "stationary IMU window of the static initialisation")
    # input guards: IMU range, IMU gaps, plausible observations
    accel_full_scale: float = _param(16.0 * 9.80665, "m/s^2", "accelerometer range per axis (16 g)")
    gyro_full_scale: float = _param(math.radians(2000.0), "rad/s", "gyroscope range per axis (2000 deg/s)")
    imu_max_gap: float = _param(0.05, "s", "longer IMU gaps inflate the covariance (and are counted)")
    imu_gap_accel_sigma: float = _param(10.0, "m/s^2", "std of the unseen specific force over an IMU gap")
    imu_gap_gyro_sigma: float = _param(1.0, "rad/s", "std of the unseen angular rate over an IMU gap")
    imu_max_bridged_gap: float = _param(0.3, "s", "longer IMU gaps stop the filter (ImuGapError)")
    max_normalized_coordinate: float = _param(10.0, "", "|x|, |y| of an observation beyond this: not normalised")

    def __post_init__(self) -> None:
        for name in _NON_NEGATIVE + _POSITIVE + ("chi2_probability", "keyframe_tracking_rate_threshold"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ValueError(f"{name} must be a real number; got {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite; got {value!r}")
            object.__setattr__(self, name, value)
        for name in _POSITIVE_OR_INF:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or math.isnan(value) or value <= 0.0:
                raise ValueError(f"{name} must be a number > 0 (math.inf switches the check off); got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.imu_max_bridged_gap < self.imu_max_gap:
            raise ValueError(f"imu_max_bridged_gap must be >= imu_max_gap ({self.imu_max_gap:g} s); "
                             f"got {self.imu_max_bridged_gap:g} s")
        for name in _NON_NEGATIVE:
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must be >= 0; got {getattr(self, name)!r}")
        for name in _POSITIVE:
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0; got {getattr(self, name)!r}")
        if self.observation_outlier_px is not None:
            value = self.observation_outlier_px
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"observation_outlier_px must be None or a number of pixels > 0; got {value!r}")
            object.__setattr__(self, "observation_outlier_px", float(value))
        if not 0.0 < self.chi2_probability < 1.0:
            raise ValueError(f"chi2_probability must lie in (0, 1), e.g. 0.95; got {self.chi2_probability!r}")
        if not 0.0 <= self.keyframe_tracking_rate_threshold <= 1.0:
            raise ValueError(
                f"keyframe_tracking_rate_threshold must lie in [0, 1]; got {self.keyframe_tracking_rate_threshold!r}"
            )
        gaps = self.max_track_gap if isinstance(self.max_track_gap, tuple) else (self.max_track_gap,)
        if not gaps or any(isinstance(g, bool) or not isinstance(g, (int, np.integer)) or g < 0 for g in gaps):
            raise ValueError(f"max_track_gap must be an integer >= 0, or a tuple of them (one per frame stream); got "
                             f"{self.max_track_gap!r}")
        object.__setattr__(self, "max_track_gap", tuple(int(g) for g in gaps)
                           if isinstance(self.max_track_gap, tuple) else int(self.max_track_gap))
        for name, minimum in _INTEGER_MIN.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
                raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.min_track_length > self.max_camera_states:
            raise ValueError(
                f"min_track_length must be <= max_camera_states ({self.max_camera_states}); "
                f"got {self.min_track_length}"
            )
        if self.triangulation_min_depth >= self.triangulation_max_depth:
            raise ValueError(
                "triangulation_min_depth must be < triangulation_max_depth; "
                f"got {self.triangulation_min_depth} >= {self.triangulation_max_depth}"
            )
        for name in _BOOLEAN:
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name} must be True or False; got {getattr(self, name)!r}")
            object.__setattr__(self, name, bool(getattr(self, name)))
        try:
            g = np.asarray(self.gravity_G, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"gravity_G must be 3 finite numbers (m/s^2); got {self.gravity_G!r}") from exc
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"gravity_G must be 3 finite numbers (m/s^2), shape (3,); got shape {g.shape}")
        object.__setattr__(self, "gravity_G", tuple(float(x) for x in g))

    # ------------------------------------------------------------------ derived quantities
    @property
    def gravity(self) -> NDArray[np.float64]:
        """Return g_G (3,) as a new float64 array, m/s^2."""
        return np.array(self.gravity_G, dtype=np.float64)

    def track_gap_of(self, stream: int = 0) -> int:
        """Return the images a track of frame stream ``stream`` may miss and continue (``max_track_gap``).

        >>> MsckfConfig(max_track_gap=(2, 0)).track_gap_of(1), MsckfConfig(max_track_gap=2).track_gap_of(1)
        (0, 2)
        """
        if not isinstance(self.max_track_gap, tuple):
            return self.max_track_gap
        if not 0 <= stream < len(self.max_track_gap):
            raise ValueError(f"max_track_gap {self.max_track_gap} has no entry for frame stream {stream}")
        return self.max_track_gap[stream]

    @property
    def feature_noise_sigma(self) -> float:
        """Return the feature noise std in normalised image coordinates: pixel_noise_px / focal_length_px."""
        return self.pixel_noise_px / self.focal_length_px

    def triangulation_settings(self) -> dict[str, Any]:
        """Return the keyword arguments of ``triangulation.triangulate_inverse_depth`` that this config sets.

        The checks ``Msckf`` runs on every track: iterations and step tolerance, the baseline ratio, the depth range
        and the RMS reprojection residual (``triangulation_max_reprojection_px`` / ``focal_length_px``, normalised).

        >>> settings = MsckfConfig().triangulation_settings()
        >>> settings["max_iterations"], round(settings["max_rms_residual"], 4)
        (10, 0.0251)
        """
        return dict(
            max_iterations=self.triangulation_max_iterations,
            step_tol=self.triangulation_tolerance,
            min_baseline_ratio=self.triangulation_min_baseline_ratio,
            min_depth=self.triangulation_min_depth,
            max_depth=self.triangulation_max_depth,
            max_rms_residual=self.triangulation_max_reprojection_px / self.focal_length_px,
        )

    def continuous_noise_psd(self) -> NDArray[np.float64]:
        """Return diag(Q_IMU) (12,): [σ_g² x3, σ_wg² x3, σ_a² x3, σ_wa² x3] for n_IMU = [n_g, n_wg, n_a, n_wa].

        Reference: thesis Eq. 33 (the continuous noise of the error-state dynamics).

        >>> MsckfConfig(gyro_noise_density=0.1).continuous_noise_psd()[:3]
        array([0.01, 0.01, 0.01])
        """
        sig = (self.gyro_noise_density, self.gyro_random_walk, self.accel_noise_density, self.accel_random_walk)
        return np.repeat(np.square(sig), 3)

    def initial_imu_covariance(self) -> NDArray[np.float64]:
        """Return the initial 15x15 covariance of [δθ, δb_g, δv, δb_a, δp] (diagonal, from the init_sigma_* fields).

        >>> np.diag(MsckfConfig(init_sigma_velocity=0.5).initial_imu_covariance())[6:9]
        array([0.25, 0.25, 0.25])
        """
        sig = (
            self.init_sigma_attitude, self.init_sigma_gyro_bias, self.init_sigma_velocity,
            self.init_sigma_accel_bias, self.init_sigma_position,
        )
        return np.diag(np.repeat(np.square(sig), 3))

    def chi2_threshold(self, dof: int) -> float:
        """Return the chi-square gating threshold: the chi2_probability quantile with ``dof`` degrees of freedom.

        Args:
            dof: degrees of freedom (>= 1), e.g. the length of a feature's projected residual.

        >>> round(MsckfConfig().chi2_threshold(2), 3)   # 95 % quantile, 2 DoF
        5.991
        """
        return chi_square_threshold(dof, self.chi2_probability)

    # ------------------------------------------------------------------ conversions
    def with_imu_noise(self, noise: Any, include_bias_sigmas: bool = True) -> "MsckfConfig":
        """Return a copy whose IMU noise densities come from ``noise`` (e.g. ``evio_lib.sim.imu.ImuNoiseParams``).

        Args:
            noise: any object with gyro_noise_density, accel_noise_density, gyro_random_walk and accel_random_walk
                attributes (same units as here).
            include_bias_sigmas: also copy its gyro_bias_init_sigma / accel_bias_init_sigma into init_sigma_gyro_bias
                / init_sigma_accel_bias where present (the filter then starts consistent with the simulated biases).
        """
        names = ("gyro_noise_density", "accel_noise_density", "gyro_random_walk", "accel_random_walk")
        missing = [n for n in names if not hasattr(noise, n)]
        if missing:
            raise ValueError(f"noise must have attributes {names}; got {type(noise).__name__} lacking {missing}")
        changes = {n: getattr(noise, n) for n in names}
        if include_bias_sigmas:
            for src, dst in (("gyro_bias_init_sigma", "init_sigma_gyro_bias"),
                             ("accel_bias_init_sigma", "init_sigma_accel_bias")):
                if hasattr(noise, src):
                    changes[dst] = getattr(noise, src)
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-able dict of every field (gravity_G as a list)."""
        out = asdict(self)
        out["gravity_G"] = list(self.gravity_G)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "MsckfConfig":
        """Return a config from a dict made by ``to_dict`` (missing keys keep their defaults)."""
        names = {f.name for f in fields(cls)}
        if not isinstance(data, dict) or not set(data) <= names:
            extra = sorted(set(data) - names) if isinstance(data, dict) else type(data).__name__
            raise ValueError(f"data must be a dict with keys among the MsckfConfig fields; got unexpected {extra}")
        return cls(**data)

    def __str__(self) -> str:
        lines = ["MsckfConfig"]
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float):
                text = f"{value:.6g}"
            elif isinstance(value, tuple):
                text = "(" + ", ".join(f"{x:g}" for x in value) + ")"
            else:
                text = repr(value)
            lines.append(f"  {f.name:<34} = {text:<13} {f.metadata['unit']:<17} {f.metadata['doc']}".rstrip())
        return "\n".join(lines)
