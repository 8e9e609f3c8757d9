"""The perfect-data-association experiment: the MSCKF on simulated IMU data and simulated feature tracks.

The end-to-end check of the back end, without a front end: the simulator's scene points are projected into
the moving camera of a preset trajectory (``boxes_like`` or ``aerial_like``) with Gaussian pixel noise
(:func:`evio_lib.sim.tracks.simulate_feature_tracks`, exact track ids), a noisy 1 kHz IMU with random-walk biases
is synthesised along the same trajectory (:func:`evio_lib.sim.imu.synthesize_imu`), and the filter
(:class:`evio_lib.msckf.filter.Msckf`) runs on both. Its IMU pose at every image time is compared with the ground
truth (thesis §4.5, Table 6 metrics: RMSE, final error, % of distance = mean |e_k| / D, plus the 4-DoF ATE).

Initial state (a Monte-Carlo-ready start): attitude, velocity and position are the truth corrected by one draw
δx ~ N(0, P0) of the initial covariance P0 (``MsckfConfig.initial_imu_covariance``); the bias estimates start
at zero while the true initial biases are drawn by the IMU noise model (``ImuNoiseParams.*_bias_init_sigma``,
the same spreads as P0's bias blocks), so x_true - x_est ~ N(0, P0) holds for every block.

Consistency: the pose error of the IMU at image k (thesis Eqs. 23-26; q_true = δq(δθ) ⊗ q_est)::

    δθ_I = rotvec(q_true ⊗ q_est^-1)           (attitude error in I)
    δp   = p_true - p_est
    NEES_pose = [δθ_I; δp]^T P_pose^-1 [δθ_I; δp]        (P_pose = rows/cols [0:3, 12:15] of P_imu, 6 DoF)
    δθ_G = R_ItoG,est δθ_I                      (the same error in G: R_ItoG,true ≈ exp([δθ_G x]) R_ItoG,est)
    NEES_yaw = (e_z^T δθ_G)^2 / (e_z^T R_ItoG P_θθ R_ItoG^T e_z)   (1 DoF, the unobservable heading)

Baselines (thesis Table 6): IMU-only propagation from the same initial state, without bias correction (bias
estimates 0) and with it (bias estimates = the true initial biases).

Command line: ``python -m evio_lib vio-sim PRESET [--duration S] [--seed N] [--features N]
[--no-observability-constrained] [--imu-only] [--out DIR]`` (:func:`add_vio_sim_arguments`, :func:`main_vio_sim`).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from numbers import Integral
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.evaluation.trajectory_metrics import chi2_bounds, format_table, orientation_errors, summarize
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.pixel_noise import observation_covariance, undistortion_noise_factor
from evio_lib.geometry.rotation import quat_inverse, quat_multiply, quat_to_rot, quat_to_rotvec, rot_to_quat
from evio_lib.io.tum import hamilton_BtoG_from_jpl_q_GtoB, write_tum
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.filter import FilterOutput, Msckf
from evio_lib.msckf.state import BA, BG, POS, THETA, FilterState, ImuState, inject_error
from evio_lib.sim.imu import ImuData, ImuNoiseParams, synthesize_imu
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.tracks import FeatureFrame, simple_geometry, simulate_feature_tracks, track_lengths
from evio_lib.sim.trajectory import PRESETS, Trajectory, trajectory_from_preset
from evio_lib.msckf.experiment_options import add_vio_sim_arguments  # the options alone

__all__ = [
    "VioSimConfig",
    "VioSimResult",
    "SimulatedData",
    "experiment_msckf_config",
    "NOISE_MODELS",
    "MAX_SIM_FEATURES",
    "MAX_SIM_PIXEL_NOISE_PX",
    "simulate_data",
    "simulated_data_from_recording",
    "initial_state",
    "pose_nees",
    "run_vio_sim",
    "run_vio_sim_config",
    "run_vio_sim_seeds",
    "add_vio_sim_arguments",
    "main_vio_sim",
]

_POSE_IDX = np.r_[0:3, 12:15]  # [δθ, δp] rows of the IMU error state

#: How the filter models the feature noise (``VioSimConfig.noise_model``):
#: 'per_observation': Σ_i = σ_px² J_i J_i^T at each observation's pixel (:func:`observation_covariance`);
#: 'global_factor': isotropic σ_px · :func:`undistortion_noise_factor` / f for every observation;
#: 'nominal': isotropic σ_px / f (ignores the undistortion's stretch of the noise).
NOISE_MODELS = ("per_observation", "global_factor", "nominal")
#: Most simulated tracks per image (the thesis keeps about 60, OpenVINS 200-400; each costs memory and time).
MAX_SIM_FEATURES = 2000
#: Largest simulated track noise std [px]: a fifth of the 240 px image; real trackers are within 1-2 px.
MAX_SIM_PIXEL_NOISE_PX = 50.0


@dataclass(frozen=True)
class VioSimConfig:
    """Settings of one perfect-data-association run (frozen, validated).

    Attributes:
        preset: 'boxes_like' or 'aerial_like'.
        duration: seconds simulated; None = the preset's default (60 s boxes, 40 s aerial).
        seed: seed of every random stream of the run (IMU noise and biases, track noise and spawning, the initial
            error draw). The trajectory's shape is set by ``trajectory_seed`` so Monte-Carlo runs share it.
        features: tracks maintained per image (~60 as in thesis §4.5).
        observability_constrained: observability-constrained EKF on/off (thesis §3.3.8; the filter's
            ``MsckfConfig.observability_constrained``).
        imu_only: run the filter in IMU-only mode (no updates).
        pixel_noise_px: std of the Gaussian pixel noise added to the tracks, pixels (also the filter's
            ``pixel_noise_px``, floored at 0.1 px).
        imu_rate_hz, frame_rate_hz: IMU and image rates, Hz.
        trajectory_seed: seed of the preset trajectory's random phases / turbulence.
        max_track_length: end simulated tracks after this many images (None: only when they leave the view).
        msckf_overrides: (name, value) pairs replacing fields of :func:`experiment_msckf_config`'s config.
        gate_probability: chi-square gate of the filter in this experiment [0.99]. The tracks are exact
            (perfect data association): the gate has no outlier to catch and only biases the kept residuals
            (``update.gating_mean_shrink``); the library default (``MsckfConfig.chi2_probability`` 0.95) is for
            real tracks. The pose NEES at both gates: docs/explanations/consistency.md.
        noise_model: one of :data:`NOISE_MODELS`: how the filter models the feature noise (default
            'per_observation': each observation's own covariance, from its noisy pixel).
    """

    preset: str = "boxes_like"
    duration: float | None = None
    seed: int = 0
    features: int = 60
    observability_constrained: bool = True
    imu_only: bool = False
    pixel_noise_px: float = 1.0
    imu_rate_hz: float = 1000.0
    frame_rate_hz: float = 20.0
    trajectory_seed: int = 0
    max_track_length: int | None = None
    msckf_overrides: tuple[tuple[str, Any], ...] = ()
    noise_model: str = "per_observation"
    gate_probability: float = 0.99

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {PRESETS}; got {self.preset!r}")
        if self.noise_model not in NOISE_MODELS:
            raise ValueError(f"noise_model must be one of {NOISE_MODELS}; got {self.noise_model!r}")
        if self.duration is not None:
            if isinstance(self.duration, bool) or not isinstance(self.duration, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(self.duration) or self.duration < 2.0:
                raise ValueError(f"duration must be None or a number of seconds >= 2; got {self.duration!r}")
            object.__setattr__(self, "duration", float(self.duration))
        for name, minimum in (("seed", 0), ("features", 1), ("trajectory_seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
                raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.max_track_length is not None and (isinstance(self.max_track_length, bool) or not isinstance(
                self.max_track_length, (int, np.integer)) or self.max_track_length < 2):
            raise ValueError(f"max_track_length must be None or an integer >= 2; got {self.max_track_length!r}")
        for name in ("observability_constrained", "imu_only"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name} must be True or False; got {getattr(self, name)!r}")
        for name, positive in (("pixel_noise_px", False), ("imu_rate_hz", True), ("frame_rate_hz", True)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value) or value < 0 or (positive and value == 0):
                raise ValueError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}; got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.features > MAX_SIM_FEATURES:  # before any track is made: 10 M features per image would hang the run
            raise ValueError(f"features must be <= {MAX_SIM_FEATURES} per image (MAX_SIM_FEATURES; the thesis tracks "
                             f"about 60, OpenVINS a few hundred); got {self.features}")
        if self.pixel_noise_px > MAX_SIM_PIXEL_NOISE_PX:
            raise ValueError(f"pixel_noise_px must be <= {MAX_SIM_PIXEL_NOISE_PX:g} px (MAX_SIM_PIXEL_NOISE_PX: a "
                             f"tracker this far off tracks nothing; real tracks are within 1-2 px); got "
                             f"{self.pixel_noise_px:g}")
        if isinstance(self.gate_probability, bool) or not isinstance(self.gate_probability, (float, int, np.floating)) \
                or not 0.0 < self.gate_probability < 1.0:
            raise ValueError(f"gate_probability must be a number in (0, 1), e.g. 0.99; got {self.gate_probability!r}")
        object.__setattr__(self, "gate_probability", float(self.gate_probability))
        if self.frame_rate_hz > self.imu_rate_hz:
            raise ValueError(f"frame_rate_hz must be <= imu_rate_hz ({self.imu_rate_hz:g}); got {self.frame_rate_hz:g}")
        overrides = dict(self.msckf_overrides) if not isinstance(self.msckf_overrides, dict) else self.msckf_overrides
        names = {f.name for f in dataclasses.fields(MsckfConfig)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise ValueError(f"msckf_overrides must name MsckfConfig fields; got unknown {unknown}")
        object.__setattr__(self, "msckf_overrides", tuple(sorted(overrides.items())))

    @property
    def resolved_duration(self) -> float:
        """Return the simulated duration, s (the preset's default when ``duration`` is None)."""
        if self.duration is not None:
            return self.duration
        return trajectory_from_preset(self.preset, None, self.trajectory_seed).duration


@dataclass(frozen=True, eq=False)
class SimulatedData:
    """Everything the filter and the evaluation need from the simulator (one seeded draw).

    Attributes:
        trajectory: ground truth; imu: noisy IMU samples and their true biases; frames: feature tracks per image;
        extrinsics: camera-IMU calibration; camera: the camera model; noise: the IMU noise model used.
    """

    trajectory: Trajectory
    imu: ImuData
    frames: list[FeatureFrame]
    extrinsics: CameraImuExtrinsics
    camera: PinholeRadtan
    noise: ImuNoiseParams


@dataclass(frozen=True, eq=False)
class VioSimResult:
    """Result of :func:`run_vio_sim`.

    Attributes:
        config: the run's VioSimConfig; msckf_config: the filter configuration used.
        t: (K,) image times, s.
        p_est, q_est (JPL q_GtoI), v_est: (K, 3), (K, 4), (K, 3) filter estimates of the IMU pose and velocity.
        p_gt, q_gt, v_gt: the same, ground truth at the same times (body = IMU).
        b_g_est, b_a_est, b_g_gt, b_a_gt: (K, 3) bias estimates and true biases.
        sigma: (K, 15) standard deviations of the IMU error state.
        sigma_yaw: (K,) standard deviation of the IMU's heading (rotation about gravity), rad: sqrt(u^T P_θθ u)
            with u = R_GtoI e_z (from :func:`pose_nees`).
        nees_pose (6 DoF), nees_position (3), nees_attitude (3), nees_yaw (1): (K,) NEES series.
        rows: metric rows (trajectory_metrics.summarize, plus ate) of the filter and, with baselines, the IMU-only
            rows (no bias correction; bias correction = the true initial biases) and "MSCKF (bias correction)",
            the filter started from those same bias estimates with a tight bias prior (``KNOWN_BIAS_SIGMA``), the
            like-for-like comparison with the corrected IMU-only row.
        rejections: dropped features by reason; features_used: (K,) features used per image.
        track_lengths: (T,) observations per simulated track.
        cpu_s, wall_s: filter time (IMU feeding + images; the simulation excluded); realtime_factor: duration/cpu.
    """

    config: VioSimConfig
    msckf_config: MsckfConfig
    t: NDArray[np.float64]
    p_est: NDArray[np.float64]
    q_est: NDArray[np.float64]
    v_est: NDArray[np.float64]
    p_gt: NDArray[np.float64]
    q_gt: NDArray[np.float64]
    v_gt: NDArray[np.float64]
    b_g_est: NDArray[np.float64]
    b_a_est: NDArray[np.float64]
    b_g_gt: NDArray[np.float64]
    b_a_gt: NDArray[np.float64]
    sigma: NDArray[np.float64]
    nees_pose: NDArray[np.float64]
    nees_position: NDArray[np.float64]
    nees_attitude: NDArray[np.float64]
    nees_yaw: NDArray[np.float64]
    rows: list[dict[str, Any]]
    rejections: dict[str, int]
    features_used: NDArray[np.int64]
    track_lengths: NDArray[np.int64]
    cpu_s: float
    wall_s: float
    realtime_factor: float
    yaw_error: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    sigma_yaw: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    @property
    def metrics(self) -> dict[str, Any]:
        """Return the filter's metric row (the first of ``rows``)."""
        return self.rows[0]

    def write_tum(self, path: str | Path, truth: bool = False) -> Path:
        """Write the estimated trajectory (``truth``: the ground truth at the same times) to ``path`` in TUM format
        and return the path: the pose of the IMU frame I in G (Hamilton quaternions of R_ItoG, the numbers of the JPL
        q_GtoI); the file's header names the body. A folder is refused (:meth:`write_folder` writes both files)."""
        if Path(path).is_dir():
            raise ValueError(f"{path} is a folder: write_tum writes one file (e.g. {Path(path) / 'trajectory.txt'}); "
                             f"write_folder({str(path)!r}) writes trajectory.txt and groundtruth.txt into it")
        p, q = (self.p_gt, self.q_gt) if truth else (self.p_est, self.q_est)
        write_tum(path, self.t, p, hamilton_BtoG_from_jpl_q_GtoB(q), body="imu")
        return Path(path)

    def write_folder(self, out_dir: str | Path) -> tuple[Path, Path]:
        """Write ``trajectory.txt`` (estimate) and ``groundtruth.txt`` (truth) into ``out_dir`` (made if absent) with
        :meth:`write_tum`; return their paths."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        return self.write_tum(out / "trajectory.txt"), self.write_tum(out / "groundtruth.txt", truth=True)

    def report(self) -> str:
        """Return a printable summary: the metric table, NEES averages, rejections and timing."""
        cfg = self.config
        columns = (("name", "Method"), ("rmse_m", "RMSE [m]"), ("final_error_m", "Final Error [m]"),
                   ("percent_of_distance", "% Error"), ("ate_4dof_m", "ATE 4-DoF [m]"))
        lines = [
            f"vio-sim {cfg.preset}: {self.t[-1] - self.t[0] + 1.0 / cfg.frame_rate_hz:.1f} s, seed {cfg.seed}, "
            f"{cfg.features} features/image, {cfg.pixel_noise_px:g} px noise ({cfg.noise_model}), "
            f"OC {'on' if cfg.observability_constrained else 'off'}"
            f"{', IMU-only' if cfg.imu_only else ''}; distance travelled {self.metrics['distance_m']:.2f} m",
            format_table(self.rows, columns),
        ]
        lo6, hi6 = chi2_bounds(6, len(self.t))
        lines.append(f"mean NEES over the run: pose {np.mean(self.nees_pose):.2f} (6 DoF; 95% band of a consistent "
                     f"time average [{lo6:.2f}, {hi6:.2f}]), position {np.mean(self.nees_position):.2f} (3), attitude "
                     f"{np.mean(self.nees_attitude):.2f} (3), yaw {np.mean(self.nees_yaw):.2f} (1)")
        lens = self.track_lengths
        lines.append(f"features used per image: mean {np.mean(self.features_used):.1f}; simulated tracks: "
                     f"{lens.size}, mean length {lens.mean() if lens.size else 0.0:.1f} images")
        lines.append("rejections: " + (", ".join(f"{k} {v}" for k, v in sorted(self.rejections.items())) or "none"))
        lines.append(f"filter time: {self.cpu_s:.2f} s CPU, {self.wall_s:.2f} s wall; real-time factor "
                     f"{self.realtime_factor:.1f}x (CPU)")
        return "\n".join(lines)


# ==================================================================================================== setup
def experiment_msckf_config(config: VioSimConfig, noise: ImuNoiseParams | None = None,
                            camera: PinholeRadtan | None = None) -> MsckfConfig:
    """Return the MsckfConfig of a run: the library defaults, the simulated IMU noise model, the run's pixel noise.

    Args:
        config: the run (observability_constrained, imu_only, pixel_noise_px, noise_model, msckf_overrides).
        noise: the simulated IMU noise model (default ``ImuNoiseParams()``): densities and initial bias spreads.
        camera: gives the focal length that converts pixel noise to normalised units (default DAVIS240C).

    The simulated noise is added to the DISTORTED pixels; the filter sees undistorted normalised coordinates, where
    undistortion (DAVIS240C, k1 = -0.37) stretches it by 1.03x at the centre and up to 1.49x at the border.
    With ``noise_model`` 'per_observation' (default) the filter receives each observation's own covariance
    (:func:`observation_covariance`, passed by :func:`run_vio_sim_config`) and pixel_noise_px is the simulated
    one; 'global_factor' scales the isotropic pixel noise by the RMS stretch over the image
    (:func:`undistortion_noise_factor`, 1.19 for the DAVIS240C); 'nominal' uses the simulated pixel noise as is.
    pixel_noise_px is floored at 0.1 px so that noise-free runs keep a proper measurement covariance.
    ``msckf_overrides`` are applied last. Measured figures: see :func:`run_vio_sim_config`.
    """
    noise = ImuNoiseParams() if noise is None else noise
    camera = PinholeRadtan.davis240c() if camera is None else camera
    focal = math.sqrt(camera.fx * camera.fy)  # σ_xy = σ_px / f
    cfg = MsckfConfig().with_imu_noise(noise)
    factor = undistortion_noise_factor(camera) if config.noise_model == "global_factor" else 1.0
    sigma_px = max(config.pixel_noise_px * factor, 0.1)
    cfg = dataclasses.replace(cfg, pixel_noise_px=sigma_px, focal_length_px=focal,
                              observability_constrained=config.observability_constrained, imu_only=config.imu_only,
                              chi2_probability=config.gate_probability)
    return dataclasses.replace(cfg, **dict(config.msckf_overrides)) if config.msckf_overrides else cfg


def _streams(seed: int) -> list[np.random.Generator]:
    """Return independent generators (IMU, tracks, initial error) derived from one seed."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)]


def simulate_data(config: VioSimConfig, noise: ImuNoiseParams | None = None) -> SimulatedData:
    """Return the simulated trajectory, IMU and feature tracks of a run (deterministic for ``config.seed``).

    Images at t_k = k / frame_rate_hz, k >= 1, strictly before the end; the IMU covers [0, duration].
    """
    noise = ImuNoiseParams() if noise is None else noise
    rng_imu, rng_tracks, _ = _streams(config.seed)
    duration = config.resolved_duration
    trajectory = trajectory_from_preset(config.preset, duration, config.trajectory_seed)
    imu = synthesize_imu(trajectory, config.imu_rate_hz, noise, rng_imu)
    dt = 1.0 / config.frame_rate_hz
    times = dt * np.arange(1, int(math.floor(duration / dt - 1e-9)) + 1)  # t_k = k / rate < duration
    times = times[times < trajectory.t_end - 1e-9]
    extrinsics = CameraImuExtrinsics.default()
    camera = PinholeRadtan.davis240c()
    frames = simulate_feature_tracks(trajectory, extrinsics, camera, simple_geometry(config.preset), times,
                                     rng_tracks, pixel_noise_px=config.pixel_noise_px,
                                     features_per_frame=config.features, max_track_length=config.max_track_length)
    return SimulatedData(trajectory, imu, frames, extrinsics, camera, noise)


def simulated_data_from_recording(recording: Any, config: VioSimConfig | None = None) -> SimulatedData:
    """Return the perfect-track experiment's data on a recording the simulator made (a preset), instead of a new one.

    The recording's own IMU samples (with the true biases of its ground truth), extrinsics, camera and IMU noise
    model, its motion (the simulator's trajectory, made again from the settings in its metadata), and perfect feature
    tracks of the preset's landmarks at its APS frame times, with the pixel noise, features per image and track length
    of ``config`` (default ``VioSimConfig(preset, seed=the recording's seed)``) and the track stream of
    ``config.seed``. ``run_vio_sim_config(config, data=...)`` then runs the filter on it, so the MSCKF on perfect
    tracks and the whole pipeline (``run_pipeline``) see the same IMU.

    Args:
        recording: a :class:`~evio_lib.sequence.Sequence` made by ``evio_lib.sim.simulate_sequence``, or a
            ``LoadedDataset`` of a preset (``evio_lib.pipeline.load_dataset("boxes_like", ...)``; its ``noise`` is used).
        config: the experiment's settings (its preset must be the recording's).
    """
    from evio_lib.sequence import Sequence
    from evio_lib.sim.presets import SimulationConfig

    seq = getattr(recording, "sequence", recording)
    if not isinstance(seq, Sequence):
        raise ValueError(f"recording must be a Sequence or a LoadedDataset; got {type(recording).__name__}")
    settings = (seq.metadata or {}).get("config")
    if not isinstance(settings, dict) or settings.get("preset") not in PRESETS:
        raise ValueError(f"recording {seq.name!r} holds no simulator settings (metadata['config']): perfect tracks "
                         f"need the landmarks and motion of a simulated preset ({', '.join(PRESETS)})")
    if seq.groundtruth_imu is None or seq.frame_times is None or len(seq.frame_times) == 0:
        raise ValueError(f"recording {seq.name!r} needs its IMU ground truth and frame times for perfect tracks")
    sim = SimulationConfig(**{k: settings[k] for k in ("preset", "duration", "seed", "start_time",
                                                      "trajectory_duration", "speed") if k in settings},
                           with_events=False, with_frames=False)
    config = VioSimConfig(sim.preset, seed=sim.seed) if config is None else config
    if config.preset != sim.preset:
        raise ValueError(f"config.preset {config.preset!r} differs from the recording's preset {sim.preset!r}")
    trajectory = trajectory_from_preset(sim.preset, duration=sim.motion_duration(), seed=sim.seed, speed=sim.speed)
    truth = seq.groundtruth_imu.interpolate(seq.imu.t)
    imu = ImuData(seq.imu.t, seq.imu.gyro, seq.imu.accel, truth.bias_gyro, truth.bias_accel)
    noise = getattr(recording, "noise", None)
    if not isinstance(noise, ImuNoiseParams):
        try:
            noise = ImuNoiseParams.from_dict(seq.metadata.get("imu_noise") or {})
        except (TypeError, ValueError) as error:
            raise ValueError(f"recording {seq.name!r}: its metadata's imu_noise is not the simulator's: {error}") from None
    extrinsics = CameraImuExtrinsics(seq.R_CtoI, seq.p_CinI)
    _, rng_tracks, _ = _streams(config.seed)
    frames = simulate_feature_tracks(trajectory, extrinsics, seq.camera, simple_geometry(sim.preset), seq.frame_times,
                                     rng_tracks, pixel_noise_px=config.pixel_noise_px,
                                     features_per_frame=config.features, max_track_length=config.max_track_length)
    return SimulatedData(trajectory, imu, frames, extrinsics, seq.camera, noise)


def initial_state(data: SimulatedData, msckf_config: MsckfConfig, rng: np.random.Generator | int,
                  bias_estimates: tuple[Any, Any] | None = None) -> FilterState:
    """Return the filter's initial state: truth ⊞ δx, δx ~ N(0, P0) on attitude, velocity and position.

    Args:
        data: the simulation (truth at its first IMU time).
        msckf_config: gives P0 (``initial_imu_covariance``).
        rng: Generator or seed of the draw.
        bias_estimates: (b_g, b_a) initial bias estimates; None = zeros (biases unknown: their error is the true
            initial bias, itself drawn from the same prior by the IMU model).
    """
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    t0 = float(data.imu.t[0])
    s0 = data.trajectory.evaluate(t0)
    b_g, b_a = (np.zeros(3), np.zeros(3)) if bias_estimates is None else bias_estimates
    P0 = msckf_config.initial_imu_covariance()
    imu = ImuState.from_pose(s0.R_ItoG[0], s0.p_IinG[0], s0.v_IinG[0], t0, b_g=b_g, b_a=b_a)
    truth = FilterState.initial(imu, data.extrinsics.R_CtoI, data.extrinsics.p_CinI, P0)
    evals, evecs = np.linalg.eigh(P0)  # P0 = V diag(λ) V^T; L = V sqrt(λ) (also for zero variances)
    dx = (evecs * np.sqrt(np.clip(evals, 0.0, None))) @ gen.standard_normal(P0.shape[0])  # δx ~ N(0, P0)
    dx[BG] = 0.0  # the bias errors are the true biases themselves
    dx[BA] = 0.0
    # x_true = x_est ⊞ δx  <=>  x_est = x_true ⊞ (-δx) to first order; the sign does not change the distribution
    est = inject_error(truth, dx)
    e = est.imu
    imu_est = ImuState(e.q_GtoI, e.b_g, e.v_IinG, e.b_a, e.p_IinG, t0)  # first estimates = the estimate
    return FilterState.initial(imu_est, data.extrinsics.R_CtoI, data.extrinsics.p_CinI, P0)


KNOWN_BIAS_SIGMA = (0.002, 0.01)  # rad/s, m/s^2: prior std of "known" initial biases (a few % of the unknown ones)


def pose_nees(q_est: NDArray[np.float64], p_est: NDArray[np.float64], q_gt: NDArray[np.float64],
              p_gt: NDArray[np.float64], P_imu: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    """Return NEES series (K,) of the IMU pose: 'pose' (6 DoF), 'position', 'attitude' (3) and 'yaw' (1), and
    'yaw_sigma' (K,), the std of the heading error δθ_G,z, rad.

    Args:
        q_est, q_gt: (K, 4) JPL q_GtoI estimate and truth; p_est, p_gt: (K, 3) positions in G, m.
        P_imu: (K, 15, 15) covariance of the IMU error [δθ, δb_g, δv, δb_a, δp].

    δθ_I = rotvec(q_gt ⊗ q_est^-1), δp = p_gt - p_est; yaw: δθ_G = R_ItoG δθ_I, z component (module docstring).

    >>> q = np.array([[0.0, 0.0, 0.0, 1.0]]); P = np.eye(15)[None] * 0.01
    >>> out = pose_nees(q, np.zeros((1, 3)), q, np.array([[0.1, 0.0, 0.0]]), P)
    >>> [round(float(out[k][0]), 3) for k in ("pose", "position", "attitude", "yaw")]
    [1.0, 1.0, 0.0, 0.0]
    """
    q_est, q_gt = np.asarray(q_est, dtype=np.float64), np.asarray(q_gt, dtype=np.float64)
    p_est, p_gt = np.asarray(p_est, dtype=np.float64), np.asarray(p_gt, dtype=np.float64)
    P = np.asarray(P_imu, dtype=np.float64)
    K = q_est.shape[0] if q_est.ndim == 2 else -1
    if q_est.shape != (K, 4) or q_gt.shape != (K, 4) or p_est.shape != (K, 3) or p_gt.shape != (K, 3):
        raise ValueError(f"q_est, q_gt must have shape (K, 4) and p_est, p_gt (K, 3); got {q_est.shape}, "
                         f"{q_gt.shape}, {p_est.shape}, {p_gt.shape}")
    if P.shape != (K, 15, 15):
        raise ValueError(f"P_imu must have shape (K, 15, 15) = ({K}, 15, 15); got {P.shape}")
    dtheta = quat_to_rotvec(quat_multiply(q_gt, quat_inverse(q_est)))  # δθ_I = rotvec(q_true ⊗ q_est^-1)
    dp = p_gt - p_est
    e = np.concatenate([dtheta, dp], axis=1)
    P_pose = P[:, _POSE_IDX[:, None], _POSE_IDX[None, :]]
    nees_pose = np.einsum("ki,ki->k", e, np.linalg.solve(P_pose, e[..., None])[..., 0])
    nees_pos = np.einsum("ki,ki->k", dp, np.linalg.solve(P[:, POS, POS], dp[..., None])[..., 0])
    nees_att = np.einsum("ki,ki->k", dtheta, np.linalg.solve(P[:, THETA, THETA], dtheta[..., None])[..., 0])
    R_GtoI = quat_to_rot(q_est)  # rows of R_GtoI = columns of R_ItoG; R_ItoG^T e_z = R_GtoI[:, :, 2]
    u = R_GtoI[:, :, 2]  # δθ_G,z = e_z^T R_ItoG δθ_I = (R_ItoG^T e_z) . δθ_I
    yaw_err = np.einsum("ki,ki->k", u, dtheta)
    yaw_var = np.einsum("ki,kij,kj->k", u, P[:, THETA, THETA], u)
    return {"pose": nees_pose, "position": nees_pos, "attitude": nees_att, "yaw": yaw_err**2 / yaw_var,
            "yaw_sigma": np.sqrt(yaw_var)}


def _run_filter(msckf_config: MsckfConfig, state: FilterState, data: SimulatedData, per_observation: bool = False
                ) -> tuple[list[FilterOutput], Msckf, float, float]:
    """Return (outputs, filter, cpu_s, wall_s): the filter fed with all IMU samples and all frames.

    With ``per_observation`` each frame's observations carry their own covariance (:func:`observation_covariance`
    at the noisy pixels, σ = msckf_config.pixel_noise_px); its cost is included in the timing."""
    imu = data.imu
    wall0, cpu0 = time.perf_counter(), time.process_time()
    f = Msckf(msckf_config, state)
    f.feed_imu(imu.t, imu.gyro, imu.accel)
    if per_observation and not msckf_config.imu_only:
        sigma_px = msckf_config.pixel_noise_px
        outputs = [f.process_image(fr.t, fr.ids, fr.xy, observation_covariance(data.camera, fr.uv, sigma_px))
                   for fr in data.frames]
    else:
        outputs = [f.process_image(fr.t, fr.ids, fr.xy) for fr in data.frames]
    return outputs, f, time.process_time() - cpu0, time.perf_counter() - wall0


def _stack(outputs: list[FilterOutput], name: str) -> NDArray[np.float64]:
    return np.array([getattr(o, name) for o in outputs])


# ==================================================================================================== the run
def run_vio_sim_config(config: VioSimConfig, baselines: bool = True, out_dir: str | Path | None = None,
                       data: SimulatedData | None = None) -> VioSimResult:
    """Return the VioSimResult of one run described by ``config`` (see :func:`run_vio_sim`).

    Args:
        config: the run settings.
        baselines: also run the two IMU-only baselines (rows 2 and 3 of ``rows``).
        out_dir: when given, write trajectory.txt and groundtruth.txt there (TUM, IMU body, same timestamps).
        data: a simulation made by :func:`simulate_data` for this config (re-used to save time), else simulated.
    """
    if not isinstance(config, VioSimConfig):
        raise ValueError(f"config must be a VioSimConfig; got {type(config).__name__}")
    data = simulate_data(config) if data is None else data
    msckf_config = experiment_msckf_config(config, data.noise, data.camera)
    _, _, rng_init = _streams(config.seed)
    state = initial_state(data, msckf_config, rng_init)
    outputs, f, cpu_s, wall_s = _run_filter(msckf_config, state, data, config.noise_model == "per_observation")

    t = _stack(outputs, "t")
    truth = data.trajectory.evaluate(t)
    q_gt = rot_to_quat(np.swapaxes(truth.R_ItoG, 1, 2))  # JPL q_GtoI of R_GtoI = R_ItoG^T
    q_est, p_est, P_imu = _stack(outputs, "q_GtoI"), _stack(outputs, "p_IinG"), _stack(outputs, "P_imu")
    nees = pose_nees(q_est, p_est, q_gt, truth.p_IinG, P_imu)
    k_imu = np.clip(np.searchsorted(data.imu.t, t - 1e-9), 0, len(data.imu.t) - 1)  # IMU sample at each image
    imu_t, dense = data.imu.t, data.trajectory.evaluate(data.imu.t)

    label = ("IMU-only (filter mode)" if config.imu_only
             else f"MSCKF, OC {'on' if config.observability_constrained else 'off'}")
    row = summarize(t, p_est, imu_t, dense.p_IinG, name=label)
    rows = [row]
    if baselines:
        b_true = (data.imu.bias_gyro[0], data.imu.bias_accel[0])
        for name, biases in (("IMU-only (no bias correction)", None), ("IMU-only (bias correction)", b_true)):
            base_cfg = dataclasses.replace(msckf_config, imu_only=True)
            s0 = initial_state(data, base_cfg, _streams(config.seed)[2], bias_estimates=biases)
            out_b, _, _, _ = _run_filter(base_cfg, s0, data)
            rows.append(summarize(t, _stack(out_b, "p_IinG"), imu_t, dense.p_IinG, name=name))
        if not config.imu_only:
            g_sigma, a_sigma = KNOWN_BIAS_SIGMA
            known_cfg = dataclasses.replace(msckf_config, init_sigma_gyro_bias=g_sigma, init_sigma_accel_bias=a_sigma)
            s0 = initial_state(data, known_cfg, _streams(config.seed)[2], bias_estimates=b_true)
            out_k, _, _, _ = _run_filter(known_cfg, s0, data, config.noise_model == "per_observation")
            rows.append(summarize(t, _stack(out_k, "p_IinG"), imu_t, dense.p_IinG,
                                  name=f"{label} (bias correction)"))
    _, yaw_err, _ = orientation_errors(quat_to_rot(q_est).transpose(0, 2, 1), truth.R_ItoG)
    duration = config.resolved_duration
    result = VioSimResult(
        config=config, msckf_config=msckf_config, t=t, p_est=p_est, q_est=q_est, v_est=_stack(outputs, "v_IinG"),
        p_gt=truth.p_IinG, q_gt=q_gt, v_gt=truth.v_IinG, b_g_est=_stack(outputs, "b_g"),
        b_a_est=_stack(outputs, "b_a"), b_g_gt=data.imu.bias_gyro[k_imu], b_a_gt=data.imu.bias_accel[k_imu],
        sigma=np.sqrt(np.clip(np.diagonal(P_imu, axis1=1, axis2=2), 0.0, None)),
        nees_pose=nees["pose"], nees_position=nees["position"], nees_attitude=nees["attitude"], nees_yaw=nees["yaw"],
        rows=rows, rejections=dict(f.rejections), features_used=np.array([o.n_features_used for o in outputs]),
        track_lengths=track_lengths(data.frames), cpu_s=cpu_s, wall_s=wall_s,
        realtime_factor=duration / cpu_s if cpu_s > 0 else float("inf"), yaw_error=yaw_err,
        sigma_yaw=nees["yaw_sigma"],
    )
    if out_dir is not None:
        result.write_folder(out_dir)
    return result


def run_vio_sim(
    preset: str = "boxes_like",
    duration: float | None = None,
    seed: int = 0,
    features: int = 60,
    observability_constrained: bool = True,
    imu_only: bool = False,
    pixel_noise_px: float = 1.0,
    *,
    baselines: bool = True,
    out_dir: str | Path | None = None,
    **options: Any,
) -> VioSimResult:
    """Return the result of a perfect-data-association MSCKF run on a simulated preset (thesis §4.5 metrics).

    Args:
        preset: 'boxes_like' | 'aerial_like'.
        duration: seconds (None = preset default: 60 s boxes, 40 s aerial).
        seed: seed of every random stream (IMU noise/biases, tracks, initial error).
        features: tracks per image.
        observability_constrained: observability-constrained EKF on/off.
        imu_only: filter in IMU-only mode.
        pixel_noise_px: track noise std, pixels.
        baselines: also run the IMU-only baselines (without and with bias correction).
        out_dir: write trajectory.txt / groundtruth.txt (TUM, IMU body, the image timestamps) there.
        options: other :class:`VioSimConfig` fields (imu_rate_hz, frame_rate_hz, trajectory_seed,
            max_track_length, msckf_overrides).

    >>> r = run_vio_sim("boxes_like", duration=2.0, seed=0, features=30, baselines=False)
    >>> len(r.t), r.p_est.shape, bool(r.metrics["rmse_m"] < 0.1)
    (39, (39, 3), True)
    """
    config = VioSimConfig(preset=preset, duration=duration, seed=seed, features=features,
                          observability_constrained=observability_constrained, imu_only=imu_only,
                          pixel_noise_px=pixel_noise_px, **options)
    return run_vio_sim_config(config, baselines=baselines, out_dir=out_dir)


def run_vio_sim_seeds(seeds: Sequence[int], jobs: int | None = None, **kwargs: Any) -> list[VioSimResult]:
    """Return ``[run_vio_sim(seed=s, **kwargs) for s in seeds]``, the runs spread over ``jobs`` worker processes.

    Monte Carlo runs are independent and each seeds all of its own random streams, so the results are the same
    numbers in any number of processes (tested). ``jobs``: worker processes (default
    :func:`evio_lib.sim.jobs.default_jobs`: ``EVIO_JOBS``, else one per logical CPU, at most 4 and at most one per
    seed); 1 runs them here, in order. The filter's steps run on one BLAS thread in any process
    (:func:`evio_lib.threads.single_threaded_blas`). ``out_dir`` is refused: the runs would write the same files.

    >>> runs = run_vio_sim_seeds([0, 1], jobs=1, duration=2.0, features=30, baselines=False)
    >>> [r.config.seed for r in runs], bool(runs[0].metrics["rmse_m"] != runs[1].metrics["rmse_m"])
    ([0, 1], True)
    """
    from evio_lib.sim.jobs import map_in_workers

    if kwargs.get("out_dir") is not None:
        raise ValueError("run_vio_sim_seeds writes no files: every seed would write out_dir's trajectory.txt; call "
                         "run_vio_sim(seed=..., out_dir=...) for the run to keep")
    seeds = list(seeds)
    bad = [s for s in seeds if isinstance(s, bool) or not isinstance(s, Integral) or s < 0]
    if bad:
        raise ValueError(f"seeds must be non-negative integers; got {bad[:3]}")
    return map_in_workers(run_vio_sim, [dict(kwargs, seed=int(seed)) for seed in seeds], jobs)


# ==================================================================================================== command line
def main_vio_sim(args: argparse.Namespace) -> int:
    """Run the experiment for parsed ``vio-sim`` arguments, print the report; return the exit code (0).

    ``--out`` is checked before the run (a non-empty folder is refused unless ``--force``) and written atomically
    at the end (:func:`evio_lib.io.output_dir.atomic_output_dir`).
    """
    from evio_lib.io.output_dir import atomic_output_dir, check_output_dir

    force = getattr(args, "force", False)
    recording = getattr(args, "recording", None)
    if args.out is not None:
        check_output_dir(args.out, force, name="--out",
                         inputs=[("the --recording folder", recording)] if recording is not None else ())
    sequence = None
    if recording is not None:
        if args.duration is not None:
            raise ValueError(f"--duration {args.duration:g} and --recording: the recording's own length is used; "
                             f"leave --duration out")
        from evio_lib.io.ecd import read_ecd

        if not Path(recording).is_dir():
            raise ValueError(f"--recording {recording}: no such folder (expected a folder written by `python -m "
                             f"evio_lib simulate {args.preset} --out DIR`)")
        try:
            sequence = read_ecd(recording, load_events=False)
        except ValueError as error:
            raise ValueError(f"--recording {recording} is no folder written by `python -m evio_lib simulate "
                             f"{args.preset} --out DIR`: {error}") from None
        made = (sequence.metadata.get("config") or {}).get("preset") if isinstance(sequence.metadata, dict) else None
        if made is not None and made != args.preset:
            raise ValueError(f"--recording {recording} is a {made} recording; run `vio-sim {made} --recording "
                             f"{recording}`")
        length = float(sequence.imu.t[-1] - sequence.imu.t[0]) if sequence.imu is not None and len(sequence.imu.t) else 0.0
        if length < 2.0:
            raise ValueError(f"--recording {recording} lasts {length:.3g} s; the experiment needs at least 2 s (simulate "
                             f"it with --duration 2 or more)")
        args.duration = length
    try:
        config = VioSimConfig(preset=args.preset, duration=args.duration, seed=args.seed, features=args.features,
                              observability_constrained=not args.no_observability_constrained,
                              imu_only=args.imu_only, pixel_noise_px=args.pixel_noise,
                              noise_model=getattr(args, "noise_model", "per_observation"),
                              gate_probability=getattr(args, "gate", 0.99))
    except ValueError as error:  # the message names the config field; the user typed the option
        from evio_lib.cli_args import as_option_error

        raise as_option_error(error, {"features": "--features", "pixel_noise_px": "--pixel-noise",
                                      "duration": "--duration", "seed": "--seed",
                                      "gate_probability": "--gate"}) from None
    try:
        data = None if sequence is None else simulated_data_from_recording(sequence, config)
    except ValueError as error:
        raise ValueError(f"--recording {recording}: {error}") from None
    result = run_vio_sim_config(config, baselines=not args.no_baselines, data=data)
    print(result.report())
    if args.out is not None:
        with atomic_output_dir(args.out, force) as tmp:
            result.write_folder(tmp)
        print(f"wrote {Path(args.out) / 'trajectory.txt'} and {Path(args.out) / 'groundtruth.txt'}")
    return 0
