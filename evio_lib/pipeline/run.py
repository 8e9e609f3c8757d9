"""One recording -> frames -> feature tracks -> MSCKF -> trajectory and metrics (thesis §4.5).

:func:`run_pipeline` runs the whole chain on a :class:`~evio_lib.pipeline.dataset.LoadedDataset`:

1. frames: the APS frames, or frames reconstructed from event windows (:mod:`evio_lib.pipeline.frames`);
2. front-end (:func:`evio_lib.frontend.create_tracker`): detection (SIFT, the CNN, ... by name), matching within the
   gyroscope-predicted position, two-point RANSAC, a 4 x 5 grid of at most N / 20 features per cell (N = 60);
3. the MSCKF (:class:`evio_lib.msckf.filter.Msckf`) with every IMU sample, each frame's undistorted tracks and their
   own 2 x 2 covariances (the pixel noise pushed through the undistortion, Σ_i = σ² J_i J_iᵀ);
4. metrics against the ground truth when the recording has one: RMSE, final error and % of distance (mean |e_k|
   over the distance travelled, the thesis's definition), ATE after an SE(3) and a position + yaw alignment, the
   orientation error and, for the "fast second half" comparison, the RMSE over each half of the run.

Initialisation (``PipelineConfig.init``): 'groundtruth' starts from the ground truth's pose at the first frame and
its velocity (the recording's own, else a central difference of its positions over ±25 ms) as the thesis did;
'static' estimates roll, pitch and the gyro bias from the first ``static_init_duration`` (1 s; shorter recordings use
half their length, at least 0.1 s) of a still IMU, velocity 0, as OpenVINS and S-MSCKF do; the window being still,
the filter starts at its first sample. Yaw and position are not
observable from a still IMU: with a ground truth they are taken from it (so the errors need no alignment), without
one they are 0. 'auto' (the default) uses 'static' whenever the IMU is still over that window (and the ground truth,
where there is one, says it is not moving faster than 5 cm/s), else the ground truth. Biases start at zero
(``bias_init='zero'``; after a static start the gyro bias is the still IMU's mean), at the ground truth's
(``'groundtruth'``, the thesis's hand-tuned "bias correction" row) or at given values.

Standstill (``PipelineConfig.zupt``, on by default): every frame is tested for standstill (the tracks moved less
than half a pixel, the IMU is still, the filter's speed is below 0.1 m/s; :mod:`evio_lib.msckf.zero_velocity`) and a
still frame gets a zero-velocity update instead of a visual one (OpenVINS's ZUPT): no camera clone piles up at one
place and the IMU's drift is stopped.

Scoring: a ground truth that ends before (or starts after) the run is scored over the overlap, and the notes say so.
The % of distance (thesis) is reported only for paths of at least :data:`MIN_PERCENT_DISTANCE_M` (0.5 m): over a
shorter path it divides by almost nothing (a still platform's millimetres of error would read as thousands of %).

Every per-frame figure is kept (:class:`PipelineResult`); nothing is written here (see :mod:`.output`).
"""
from __future__ import annotations

import dataclasses
import heapq
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from evio_lib.cli_args import as_option_error
from evio_lib.events.reconstruct import Reconstructor, available_reconstructors, reconstructor_by_name_or_file
from evio_lib.evaluation.trajectory_metrics import orientation_errors, relative_errors_by_length, summarize
from evio_lib.frontend import FrontendConfig, camera_rotation_prior, create_tracker, stats_table
from evio_lib.geometry.pixel_noise import observation_covariance
from evio_lib.geometry.rotation import quat_to_rot, rot_to_quat
from evio_lib.io.tum import TUM_BODIES, write_tum
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.filter import Msckf, MsckfWarning
from evio_lib.msckf.initialization import initial_state_from_static, initial_state_from_truth
from evio_lib.msckf.zero_velocity import StandstillDetector, ZeroVelocityConfig
from evio_lib.pipeline.dataset import LoadedDataset
from evio_lib.pipeline.frames import (FRAME_SOURCES, STREAM_ID_OFFSET, aps_frames, event_frames, frame_streams,
                                      mc_event_frames)
from evio_lib.threads import set_threads, single_threaded_blas  # re-exported: `from evio_lib.pipeline.run import set_threads` keeps working

__all__ = ["FUSED_EVENT_NOISE_FACTOR", "INIT_MODES", "MIN_PERCENT_DISTANCE_M", "PipelineConfig", "PipelineResult",
           "run_pipeline", "run_pipelines", "set_threads"]

INIT_MODES = ("auto", "groundtruth", "static")
#: Shortest ground-truth path for which the % of distance is reported, m. Over a shorter path the mean error divided
#: by the length measures the noise of standing still, not drift per metre travelled.
MIN_PERCENT_DISTANCE_M = 0.5
#: An event stream fused with the APS frames ('aps+mc-events', 'aps+events') gets this multiple of pixel_noise_px as
#: its feature noise when event_pixel_noise_px is not given. Its tracks lie farther from their points than the APS
#: tracks' (bench/track_accuracy.py) and come several times as often with errors that persist from frame to frame,
#: so at equal sigma they outvote the APS tracks. Chosen on validation seeds of boxes_like with motion-compensated
#: event frames (the measurements: docs/results/pipeline.md, "Weighting the two streams"); 'aps+events' (FireNet
#: frames) gets the same factor, unmeasured.
FUSED_EVENT_NOISE_FACTOR = 3.0
#: 'auto' initialisation: fastest ground-truth speed (m/s) over the still window for which the start counts as still.
_STILL_TRUTH_SPEED = 0.05


def _check_stream(stream: str) -> None:
    """Raise ValueError unless ``stream`` names one frame stream ('aps', 'events' or 'mc-events')."""
    if stream not in ("aps", "events", "mc-events"):
        raise ValueError(f"stream must be 'aps', 'events' or 'mc-events'; got {stream!r}")


@dataclass(frozen=True)
class PipelineConfig:
    """Every choice of one pipeline run (frozen, validated).

    Attributes:
        frames: 'aps' (the recorded frames; the default), 'events' (reconstructed from event windows) or
            'mc-events' (event windows warped with the gyroscope's rotation and counted:
            :func:`~evio_lib.pipeline.frames.mc_event_frames`),
            or two of them joined by '+' ('aps+mc-events', 'aps+events'): two frame streams, each with its own
            tracker, whose tracks the filter fuses (Ultimate SLAM's standard frames + events).
        features: detector name of ``evio_lib.features`` ('sift', 'superpoint' = the shipped CNN, 'orb', 'fast',
            ...); None (the default): each tracker's own, SIFT for 'descriptor' and FAST corners for 'klt'. A name
            given is used by every stream's tracker, KLT included (``features='sift'`` with ``tracker='klt'`` tracks
            SIFT keypoints).
        detector_options: extra options of the detector as (name, value) pairs (e.g. ('weights', PATH)); default
            none.
        tracker: 'descriptor' (the thesis's front-end; the default) or 'klt' (optical flow; ``features`` then
            detects new ones).
        event_tracker: a run that fuses APS frames with an event stream ('aps+mc-events', 'aps+events'): the event
            stream's tracker, 'descriptor' or 'klt' (None: ``tracker``, one front-end for both streams). With
            ``features`` None each stream's tracker detects its own (SIFT, FAST corners); ``max_track_gap`` applies
            to the descriptor stream only.
        max_features: N, features kept per frame (default 60, the thesis's).
        match_ratio: Lowe's ratio test of the descriptor matches (None: off, the pipeline's default: the guided
            window, the mutual check and two-point RANSAC select the matches). With the front-end's stand-alone
            default 0.8 fewer tracks continue, since the second-best match anywhere in the repetitive room is often
            close, and the error grows (docs/archive.md, the ratio-test rows).
        reconstructor: event frames only: a reconstructor name ('firenet', the default; 'high_pass', 'direct') or a
            reconstruct-train checkpoint file.
        reconstructor_precision: event frames only: a network's arithmetic, 'auto' (default: int8 for FireNet on
            an x86 CPU where Numba's kernels load, else float32), 'float32', 'bfloat16' (on a CPU with native
            bfloat16) or 'int8' (FireNet only: int8 convolutions); direct and high_pass ignore it. Their speed and
            their quality against float32: docs/results/reconstruction.md, "Speed" and "int8 and float32".
        window_fraction: event frames only: n of N_e = n H W; None: the thesis's n for the preset (0.7 / 0.2) for
            reconstructed frames, 1.0 for every recording for motion-compensated ones (``MC_WINDOW_FRACTION``).
        adaptive_windows: event frames only: adaptive windows instead of fixed N_e (default False).
        min_window_s, max_window_s: event frames only: the least and the greatest window duration, s (None: the
            source's default; 'events': none, 'mc-events': 0.01 s and 0.1 s).
        init: one of :data:`INIT_MODES` (default 'auto'; module docstring).
        bias_init: 'zero' (the default), 'groundtruth', or six numbers (b_g [rad/s], b_a [m/s^2]).
        imu_only: propagate the IMU only (no frames are processed: the IMU-only rows of Table 6; default False).
        observability_constrained: the observability-constrained EKF (thesis §3.3.8;
            ``MsckfConfig.observability_constrained``; True, the default); False: the plain EKF.
        pixel_noise_px: feature noise σ of the APS frames' tracks, pixels (default 1.0; and of a lone event
            stream's tracks when ``event_pixel_noise_px`` is None).
        event_pixel_noise_px: feature noise σ of the event streams' tracks ('events', 'mc-events'), pixels; None:
            :data:`FUSED_EVENT_NOISE_FACTOR` x ``pixel_noise_px`` when the run fuses them with the APS frames,
            else ``pixel_noise_px``; refused for a run without an event stream (it would change nothing). Each
            observation's covariance is σ² pushed through the undistortion, so with two streams ('aps+mc-events')
            each stream is weighted by its own accuracy. How far each stream's observations lie from their points
            (``bench/track_accuracy.py``): docs/results/pipeline.md, "Weighting the two streams".
        max_duration: seconds of the recording processed from the start (None: all).
        seed: seed of the front-end's RANSAC (default 0).
        zupt: detect standstill and apply zero-velocity updates there (default True; module docstring).
        observation_outlier_px: the filter drops a track's observations that reproject farther than this after
            triangulation and keeps the rest (``MsckfConfig.observation_outlier_px``; None: off).
        far_points: use a track whose triangulation lands behind a camera, beyond 1 000 m or without baseline with
            its point placed far on its bearing instead of dropping it (``MsckfConfig.far_point_fallback``; such
            tracks still tell the rotation between the cameras). False (default): dropped; True costs SIFT and KLT
            accuracy in the room and is an option for the CNN over distant terrain (docs/archive.md, the far-point
            rows; Table 6's optional rows ``cnn_aps_far``, ``cnn_mc_events_far``).
        max_track_gap: frames a descriptor track may miss and still continue with its id
            (``FrontendConfig.max_track_gap`` and ``MsckfConfig.max_track_gap``; 0: a missed detection ends the
            track, the thesis's tracker and the default). KLT never searches for a lost patch: with KLT on every
            stream the gap must be 0, and with ``event_tracker`` 'klt' it applies to the APS stream only (front-end
            and filter). A gap of 2 lengthens SIFT's tracks on APS frames and lowers their second-half error, but
            it is not the default: the CNN diverged with it and the gentle start of a recording gets worse
            (docs/archive.md, the track-gap rows).
    """

    frames: str = "aps"
    features: str | None = None
    detector_options: tuple[tuple[str, Any], ...] = ()
    tracker: str = "descriptor"
    event_tracker: str | None = None
    max_features: int = 60
    match_ratio: float | None = None
    reconstructor: str = "firenet"
    reconstructor_precision: str = "auto"
    window_fraction: float | None = None
    adaptive_windows: bool = False
    min_window_s: float | None = None
    max_window_s: float | None = None
    init: str = "auto"
    bias_init: Any = "zero"
    imu_only: bool = False
    observability_constrained: bool = True
    pixel_noise_px: float = 1.0
    event_pixel_noise_px: float | None = None
    max_duration: float | None = None
    seed: int = 0
    zupt: bool = True
    observation_outlier_px: float | None = None
    max_track_gap: int = 0
    far_points: bool = False

    def __post_init__(self) -> None:
        if self.frames not in FRAME_SOURCES:
            raise ValueError(f"frames must be one of {FRAME_SOURCES}; got {self.frames!r}")
        if self.init not in INIT_MODES:
            raise ValueError(f"init must be one of {INIT_MODES}; got {self.init!r}")
        if isinstance(self.bias_init, str):
            if self.bias_init not in ("zero", "groundtruth"):
                raise ValueError(f"bias_init must be 'zero', 'groundtruth' or six numbers; got {self.bias_init!r}")
        else:
            values = np.asarray(self.bias_init, dtype=np.float64).reshape(-1)
            if values.shape != (6,) or not np.all(np.isfinite(values)):
                raise ValueError(f"bias_init must be 'zero', 'groundtruth' or six finite numbers (b_g, b_a); got "
                                 f"{self.bias_init!r}")
            from evio_lib.io.imu_checks import check_bias_values  # |b_g| <= 0.5 rad/s, |b_a| <= 3 m/s^2 per axis

            object.__setattr__(self, "bias_init", check_bias_values(values, "bias_init"))
        for name in ("min_window_s", "max_window_s"):
            value = getattr(self, name)
            strict = name == "max_window_s"
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                      or not math.isfinite(value) or value < 0 or (strict and value == 0)):
                raise ValueError(f"{name} must be None or a number of seconds {'>' if strict else '>='} 0; got "
                                 f"{value!r}")
        low, high = self.window_bounds()
        if high is not None and high <= low:
            raise ValueError(f"max_window_s ({high:g}) must be greater than min_window_s ({low:g})")
        if "events" in frame_streams(self.frames):  # before the recording loads: a name or a checkpoint file
            names = available_reconstructors()
            if not isinstance(self.reconstructor, str) or (self.reconstructor not in names
                                                           and not Path(self.reconstructor).is_file()):
                raise ValueError(f"reconstructor must be one of {names} or a reconstruct-train checkpoint file; got "
                                 f"{self.reconstructor!r}")
        from evio_lib.events.reconstruct import PRECISIONS

        if self.reconstructor_precision not in PRECISIONS:
            raise ValueError(f"reconstructor_precision must be one of {', '.join(PRECISIONS)}; got "
                             f"{self.reconstructor_precision!r}")
        if self.max_duration is not None and not (math.isfinite(self.max_duration) and self.max_duration > 0):
            raise ValueError(f"max_duration must be None or a number of seconds > 0; got {self.max_duration!r}")
        if isinstance(self.detector_options, dict):
            object.__setattr__(self, "detector_options", tuple(sorted(self.detector_options.items())))
        if not isinstance(self.zupt, bool):
            raise ValueError(f"zupt must be True or False; got {self.zupt!r}")
        if not isinstance(self.far_points, bool):
            raise ValueError(f"far_points must be True or False; got {self.far_points!r}")
        if self.observation_outlier_px is not None:  # checked as the filter will check it, before any loading
            MsckfConfig(observation_outlier_px=self.observation_outlier_px)
        for name, expected in (("pixel_noise_px", "a finite number of pixels > 0"),
                               ("event_pixel_noise_px", "a finite number of pixels > 0")):
            value = getattr(self, name)
            if value is None and name != "pixel_noise_px":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be {expected}; got {value!r}")
        if self.event_pixel_noise_px is not None and frame_streams(self.frames) == ("aps",):
            raise ValueError(f"event_pixel_noise_px applies to event frame streams; frames {self.frames!r} has none "
                             f"(use 'mc-events', 'events' or 'aps+mc-events')")
        try:  # validates those
            FrontendConfig(method=self.tracker, max_features=self.max_features, ratio=self.match_ratio, seed=self.seed)
        except ValueError as error:  # FrontendConfig names its own fields; say which of ours was wrong
            raise as_option_error(error, {"method": "tracker", "ratio": "match_ratio"}) from None
        if isinstance(self.max_track_gap, bool) or not isinstance(self.max_track_gap, (int, np.integer)) or self.max_track_gap < 0:
            raise ValueError(f"max_track_gap must be an integer >= 0 (frames); got {self.max_track_gap!r}")
        object.__setattr__(self, "max_track_gap", int(self.max_track_gap))
        streams = frame_streams(self.frames)
        if self.event_tracker is not None:
            if self.event_tracker not in ("descriptor", "klt"):
                raise ValueError(f"event_tracker must be None, 'descriptor' or 'klt'; got {self.event_tracker!r}")
            if not self.fuses_aps_and_events:
                raise ValueError(f"event_tracker applies to a run that fuses APS frames with an event stream "
                                 f"('aps+mc-events', 'aps+events'); frames {self.frames!r} is one stream: set its "
                                 f"tracker with tracker (--tracker)")
        trackers = {self.stream_tracker(name) for name in streams}
        if self.max_track_gap and "descriptor" not in trackers:
            raise ValueError(f"max_track_gap applies to the descriptor tracker (KLT follows each patch and never "
                             f"searches for a lost one); got {self.max_track_gap} with tracker {self.tracker!r}")

    def window_bounds(self) -> tuple[float, float | None]:
        """Return (least, greatest) window duration in s of the event source (the source's defaults for None)."""
        from evio_lib.pipeline.frames import MC_MAX_WINDOW_S, MC_MIN_WINDOW_S

        mc = "mc-events" in frame_streams(self.frames)
        low = self.min_window_s if self.min_window_s is not None else (MC_MIN_WINDOW_S if mc else 0.0)
        high = self.max_window_s if self.max_window_s is not None else (MC_MAX_WINDOW_S if mc else None)
        return float(low), (None if high is None else float(high))

    def stream_pixel_noise(self, stream: str) -> float:
        """Return the feature noise σ (pixels) of the frame stream ``stream`` ('aps', 'events' or 'mc-events')."""
        _check_stream(stream)
        if stream == "aps":
            return float(self.pixel_noise_px)
        if self.event_pixel_noise_px is not None:
            return float(self.event_pixel_noise_px)
        return float(self.pixel_noise_px) * (FUSED_EVENT_NOISE_FACTOR if self.fuses_aps_and_events else 1.0)

    @property
    def fuses_aps_and_events(self) -> bool:
        """Return True when the run fuses the APS frames with an event stream ('aps+mc-events', 'aps+events')."""
        streams = frame_streams(self.frames)
        return "aps" in streams and len(streams) > 1

    def stream_tracker(self, stream: str) -> str:
        """Return the tracker ('descriptor' or 'klt') of the frame stream ``stream``."""
        _check_stream(stream)
        return self.event_tracker if stream != "aps" and self.event_tracker is not None else self.tracker

    def frontend_config(self, stream: str | None = None) -> FrontendConfig:
        """Return the front-end's configuration (of the frame stream ``stream``; None: the first stream's)."""
        tracker = self.stream_tracker(frame_streams(self.frames)[0] if stream is None else stream)
        return FrontendConfig(method=tracker, detector=self.features, detector_options=self.detector_options,
                              max_features=self.max_features, ratio=self.match_ratio, seed=self.seed,
                              max_track_gap=self.max_track_gap if tracker == "descriptor" else 0)

    def label(self) -> str:
        """Return a short name, e.g. 'SIFT on APS frames' or 'IMU only'."""
        if self.imu_only:
            return "IMU only" + (" (bias correction)" if self.bias_init != "zero" else "")
        names = {"aps": "APS frames", "mc-events": "motion-compensated event frames",
                 "events": f"event frames ({self.reconstructor})"}

        def frontend(stream: str) -> str:
            detector = self.frontend_config(stream).detector_name
            name = {"sift": "SIFT", "superpoint": "CNN", "fast": "FAST"}.get(detector, detector)
            return f"KLT + {name}" if self.stream_tracker(stream) == "klt" else name

        streams = frame_streams(self.frames)
        if len({frontend(s) for s in streams}) == 1:  # one front-end: 'KLT + FAST on APS frames + ...'
            label = f"{frontend(streams[0])} on " + " + ".join(names[s] for s in streams)
        else:  # 'SIFT on APS frames and KLT + FAST on motion-compensated event frames'
            label = " and ".join(f"{frontend(s)} on {names[s]}" for s in streams)
        noise = ""
        if self.event_pixel_noise_px is not None and streams != ("aps",):
            noise = f", event noise {self.event_pixel_noise_px:g} px"  # only when set: the default is in the docs
        return (label + (f", track gap {self.max_track_gap}" if self.max_track_gap else "") + noise
                + (", far points always" if self.far_points else ""))


@dataclass(eq=False)
class PipelineResult:
    """Everything one run produced (per-frame arrays have one row per processed frame).

    Attributes:
        config: the run's settings; dataset: the recording's name, kind and source; notes: assumptions made.
        t: (K,) frame times; q_GtoI (K, 4) JPL; p_IinG, v_IinG, b_g, b_a (K, 3); sigma (K, 15) standard deviations of
            [δθ, δb_g, δv, δb_a, δp]; features_used (K,) features in the updates at each frame.
        R_CtoI, p_CinI: the extrinsics used.
        tracking: the front-end's statistics as columns (``frontend.stats_table``), empty for IMU only.
        track_lengths: frames each track was observed in (tracks still alive at the end included).
        truth: ground truth of the IMU at t (keys p_IinG, R_ItoG, v_IinG, b_g, b_a; absent ones missing), or {}.
        metrics: the error metrics (empty without ground truth) and the counts.
        timings: seconds per stage (reconstruction, detection, matching, ransac, filter, total) and the real-time
            factor (recording seconds processed per wall-clock second).
        faults, rejections: the filter's counters.
        reconstructor_precision: the precision the event-frame network computed in (what "auto" chose), or None
            when the run reconstructed no frames with a network.
    """

    config: PipelineConfig
    dataset: dict[str, str]
    notes: list[str]
    t: np.ndarray
    q_GtoI: np.ndarray
    p_IinG: np.ndarray
    v_IinG: np.ndarray
    b_g: np.ndarray
    b_a: np.ndarray
    sigma: np.ndarray
    features_used: np.ndarray
    R_CtoI: np.ndarray
    p_CinI: np.ndarray
    tracking: dict[str, np.ndarray]
    track_lengths: np.ndarray
    truth: dict[str, np.ndarray]
    metrics: dict[str, Any]
    timings: dict[str, float]
    faults: dict[str, int] = field(default_factory=dict)
    rejections: dict[str, int] = field(default_factory=dict)
    reconstructor_precision: str | None = None

    @property
    def R_ItoG(self) -> np.ndarray:
        """Return (K, 3, 3) estimated orientations R_ItoG = C(q_GtoI)^T."""
        return np.swapaxes(quat_to_rot(self.q_GtoI), -1, -2)

    def camera_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Return (R_CtoG (K, 3, 3), p_CinG (K, 3)): the camera's estimated pose, R_CtoG = R_ItoG R_CtoI."""
        R_ItoG = self.R_ItoG
        return R_ItoG @ self.R_CtoI, self.p_IinG + R_ItoG @ self.p_CinI

    def write_tum(self, path: str | Path, body: str = "imu") -> Path:
        """Write the estimated trajectory to ``path`` in TUM format (``t x y z qx qy qz qw``, Hamilton quaternion of
        R_BtoG) and return the path; ``body`` 'imu' (default, p_IinG and R_ItoG) or 'camera' (p_CinG and R_CtoG =
        R_ItoG R_CtoI). The file's header names the body."""
        if body not in TUM_BODIES:
            raise ValueError(f"body must be one of {', '.join(TUM_BODIES)}; got {body!r}")
        R_BtoG, p_BinG = (self.R_ItoG, self.p_IinG) if body == "imu" else self.camera_pose()
        write_tum(path, self.t, p_BinG, rot_to_quat(np.swapaxes(R_BtoG, -1, -2)), body=body)  # JPL q_GtoB = Hamilton q of R_BtoG
        return Path(path)

    def summary(self) -> str:
        """Return a few lines: the run, its speed and its errors."""
        m, tm = self.metrics, self.timings
        lines = [f"{self.config.label()} on {self.dataset['name']}: {len(self.t)} frames over "
                 f"{m.get('duration_s', 0.0):.1f} s, {tm.get('realtime_factor', float('nan')):.2f}x real time"]
        if "rmse_m" in m and not math.isfinite(m["rmse_m"]):  # static start: another world frame, aligned only
            lines.append(f"  ATE after alignment: {m['ate_se3_m']:.3f} m (SE(3)), {m['ate_4dof_m']:.3f} m (position + "
                         f"yaw); ground-truth path {m['distance_m']:.2f} m")
        elif "rmse_m" in m:
            percent = (f"{m['percent_of_distance']:.2f} % of {m['distance_m']:.1f} m" if
                       math.isfinite(m["percent_of_distance"]) else
                       f"path {m['distance_m']:.3f} m (too short for a % of distance)")
            lines.append(f"  RMSE {m['rmse_m']:.3f} m, final error {m['final_error_m']:.3f} m, {percent}, "
                         f"ATE (SE(3)) {m['ate_se3_m']:.3f} m, orientation RMSE {m['orientation_rmse_deg']:.2f} deg")
        if m.get("zupt_frames"):
            lines.append(f"  standing still: {m['zupt_frames']} of {len(self.t)} frames got a zero-velocity update")
        if len(self.tracking.get("t", ())):
            lines.append(f"  tracking: {np.mean(self.tracking['total']):.1f} features/frame, "
                         f"{np.mean(self.tracking['tracked']):.1f} tracked, mean track length "
                         f"{np.mean(self.track_lengths) if len(self.track_lengths) else 0:.1f} frames")
        if self.faults:
            lines.append("  faults: " + ", ".join(f"{k}={v}" for k, v in sorted(self.faults.items())))
        return "\n".join(lines)

    def details(self) -> list[str]:
        """Return the lines ``run --verbose`` adds: the time per stage and what the filter dropped, by reason."""
        stages = ", ".join(f"{name} {seconds:.2f} s" for name, seconds in self.timings.items()
                           if name != "realtime_factor" and isinstance(seconds, (int, float)))
        dropped = ", ".join(f"{reason.replace('_', ' ')} {count}" for reason, count in sorted(self.rejections.items())
                            if count)
        used = float(np.mean(self.features_used)) if len(self.features_used) else 0.0
        return [f"time per stage: {stages}",
                f"filter: {used:.1f} features used per frame; tracks dropped by reason: {dropped or 'none'}"]


# ==================================================================================================== set-up
def _groundtruth(data: LoadedDataset):
    """Return the recording's ground truth: the IMU's when it has one, else the camera's, else None."""
    seq = data.sequence
    return seq.groundtruth_imu if seq.groundtruth_imu is not None else seq.groundtruth


def _truth_imu(data: LoadedDataset, t: np.ndarray) -> dict[str, np.ndarray]:
    """Return the IMU's ground truth interpolated at times t (positions, orientations, velocity, biases) or {}.

    ``GroundTruth.interpolate`` refuses times outside the ground truth's span (no extrapolation).
    """
    gt = _groundtruth(data)
    if gt is None:
        return {}
    g = gt.interpolate(t)
    if gt.body == "camera":  # camera poses: I = C composed with the extrinsics
        R_ItoG = g.R_BtoG @ data.R_CtoI.T  # R_ItoG = R_CtoG R_ItoC
        p_IinG = g.p_BinG - R_ItoG @ data.p_CinI  # p_CinG = p_IinG + R_ItoG p_CinI
        return {"p_IinG": p_IinG, "R_ItoG": R_ItoG}
    out = {"p_IinG": g.p_BinG, "R_ItoG": g.R_BtoG}
    if g.v_BinG is not None:
        out["v_IinG"] = g.v_BinG
    if g.bias_gyro is not None:
        out["b_g"], out["b_a"] = g.bias_gyro, g.bias_accel
    return out


def _truth_at(data: LoadedDataset, t: float) -> dict[str, np.ndarray]:
    """Return the IMU's ground truth at one time (arrays of one row), or {} when t lies outside its span."""
    gt = _groundtruth(data)
    if gt is None or not (gt.t[0] <= t <= gt.t[-1]):
        return {}
    return _truth_imu(data, np.array([t]))


def _still_window(cfg: MsckfConfig, t_first: float, t_last: float) -> float:
    """Return the length of the static-initialisation window: ``cfg.static_init_duration`` (1 s), or half the
    run for a shorter recording, at least 0.1 s (a 0.17 s AEDAT4 clip still gets a static start)."""
    return float(min(cfg.static_init_duration, max(0.1, 0.5 * (t_last - t_first))))


def _plain_motion(imu: Any, t0: float, window: float, error: Exception) -> str:
    """Return in words what moved in the IMU window [t0, t0 + window] (the largest spread of the gyro and the
    accelerometer), or the static test's own reason where the window is too short to say."""
    sel = (imu.t >= t0) & (imu.t <= t0 + window)
    if np.count_nonzero(sel) < 10:
        return str(error)
    gyro = float(np.max(np.ptp(imu.gyro[sel], axis=0)))
    accel = float(np.max(np.ptp(imu.accel[sel], axis=0)))
    return f"the gyro ranges over {gyro:.2f} rad/s and the accelerometer over {accel:.2f} m/s^2"


def _still_start(data: LoadedDataset, cfg: MsckfConfig, t_first: float) -> tuple[bool, str]:
    """Return (still, why): whether the recording starts still over the static-initialisation window.

    Still means: the IMU passes :func:`~evio_lib.msckf.initialization.static_initialization`'s test and, where there
    is a ground truth, its speed stays below 5 cm/s over the window (the IMU cannot tell rest from a constant
    velocity; the ground truth can)."""
    from evio_lib.msckf.initialization import static_initialization

    imu = data.sequence.imu
    window = cfg.static_init_duration
    try:
        static_initialization(imu.t, imu.gyro, imu.accel, window, float(np.linalg.norm(cfg.gravity)),
                              t_start=t_first)
    except ValueError as error:
        return False, f"the recording moves in its first {window:g} s ({_plain_motion(imu, t_first, window, error)})"
    gt = _groundtruth(data)
    if gt is not None:
        a, b = max(t_first, float(gt.t[0])), min(t_first + window, float(gt.t[-1]))
        if b > a:
            tt = np.linspace(a, b, 11)
            p = _truth_imu(data, tt)["p_IinG"]
            speed = float(np.max(np.linalg.norm(np.diff(p, axis=0), axis=1)) / (tt[1] - tt[0]))
            if speed > _STILL_TRUTH_SPEED:
                return False, (f"the IMU looks still over the first {window:g} s but the ground truth moves at up to "
                               f"{speed:.2f} m/s (a constant velocity)")
    return True, f"the IMU rests over the first {window:g} s"


def _anchor_to_truth(state: Any, truth: dict[str, np.ndarray], t: float) -> Any:
    """Return the static-start ``state`` at time ``t``, turned to the ground truth's yaw and moved to its position
    when ``truth`` (the truth at t) is given.

    The static start fixes roll and pitch (from gravity) with yaw ψ = 0; here R_ItoG <- Rz(ψ_true) R_ItoG with
    ψ_true = atan2(R_true[1, 0], R_true[0, 0]) (ZYX yaw), and p_IinG <- p_true. Velocity (0), biases and P stay."""
    from evio_lib.msckf.state import FilterState, ImuState

    imu = state.imu
    R_ItoG, p_IinG = imu.R_ItoG, imu.p_IinG
    if truth:
        R_true = truth["R_ItoG"][0]
        yaw = math.atan2(R_true[1, 0], R_true[0, 0])
        c, s_ = math.cos(yaw), math.sin(yaw)
        R_ItoG, p_IinG = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]) @ R_ItoG, truth["p_IinG"][0]
    new = ImuState.from_pose(R_ItoG, p_IinG, imu.v_IinG, t, b_g=imu.b_g, b_a=imu.b_a)
    return FilterState.initial(new, state.R_CtoI, state.p_CinI, state.P)


def _truth_velocity(data: LoadedDataset, t0: float, truth0: dict[str, np.ndarray]) -> np.ndarray:
    """Return v_IinG at t0: the recording's own velocity (in ``truth0``, the truth at t0), else a central difference
    of positions over ±25 ms."""
    if "v_IinG" in truth0:
        return truth0["v_IinG"][0]
    gt = _groundtruth(data)
    h = 0.025
    a, b = max(t0 - h, gt.t[0]), min(t0 + h, gt.t[-1])
    if b <= a:
        raise ValueError("the ground truth is too short to difference a velocity at the first frame")
    p = _truth_imu(data, np.array([a, b]))["p_IinG"]
    return (p[1] - p[0]) / (b - a)


def _bias_estimates(config: PipelineConfig, truth0: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """Return the initial (b_g, b_a) the config asks for, or None for 'zero' (``truth0``: the truth at the start)."""
    if config.bias_init == "zero":
        return None
    if config.bias_init == "groundtruth":
        if "b_g" not in truth0:
            raise ValueError("bias_init 'groundtruth' needs a ground truth with biases (groundtruth_imu.txt with 14 or "
                             "17 columns, or EuRoC's state_groundtruth_estimate0)")
        return truth0["b_g"][0], truth0["b_a"][0]
    values = np.asarray(config.bias_init, dtype=np.float64)
    return values[:3], values[3:]


def msckf_config_for(config: PipelineConfig, data: LoadedDataset) -> MsckfConfig:
    """Return the filter's configuration: library defaults with the recording's IMU noise, the pixel noise and OC.

    With several frame streams every frame of each is a camera clone, so the one sliding window holds
    ``max_camera_states`` x the number of streams (80 for two). The streams fill it in proportion to their frame
    rates, so with one stream's share the window would span a fraction of the APS-only run's time and the APS tracks
    would lose their parallax (the spans measured: docs/results/pipeline.md, "Weighting the two streams")."""
    cam = data.sequence.camera
    gravity = data.sequence.metadata.get("gravity_G")  # Sequence.metadata is always a dict
    cfg = MsckfConfig().with_imu_noise(data.noise)
    changes: dict[str, Any] = dict(pixel_noise_px=config.pixel_noise_px, focal_length_px=math.sqrt(cam.fx * cam.fy),
                                   observability_constrained=config.observability_constrained, imu_only=config.imu_only,
                                   observation_outlier_px=config.observation_outlier_px,
                                   far_point_fallback=config.far_points,
                                   max_track_gap=_filter_track_gaps(config),
                                   max_camera_states=cfg.max_camera_states * len(frame_streams(config.frames)))
    if gravity is not None:
        changes["gravity_G"] = tuple(float(g) for g in gravity)
    return dataclasses.replace(cfg, **changes)


def _filter_track_gaps(config: PipelineConfig) -> int | tuple[int, ...]:
    """Return the filter's ``max_track_gap``: ``max_track_gap``, or with several frame streams one gap per stream (a KLT
    stream's tracks never come back, so its gap is 0 and its ended tracks are used at once)."""
    streams = frame_streams(config.frames)
    if len(streams) == 1:
        return config.max_track_gap
    return tuple(config.frontend_config(name).max_track_gap for name in streams)


def _event_reconstructor(data: LoadedDataset, config: PipelineConfig) -> Reconstructor | None:
    """Return the reconstructor of a run's event frames (made once, so that the run can say what precision "auto"
    chose before any frame is made), or None when ``config.frames`` reconstructs no frames from events."""
    if "events" not in frame_streams(config.frames):
        return None
    camera = data.sequence.camera  # a network takes one torch thread, as event_frames' default
    return reconstructor_by_name_or_file(config.reconstructor, camera.width, camera.height, what="reconstructor",
                                         precision=config.reconstructor_precision, threads=1)


def _frames(data: LoadedDataset, config: PipelineConfig, t_start: float, t_end: float,
            gyro_bias: Any = None, stream: str | None = None, reconstructor: Reconstructor | None = None
            ) -> Iterator[tuple[float, np.ndarray, float]]:
    """Return the frame source of ``stream`` (one of ``frame_streams(config.frames)``; None: ``config.frames``, a
    single stream); ``gyro_bias`` (a callable) gives mc-events the filter's current gyro bias; ``reconstructor``
    (:func:`_event_reconstructor`) makes the events stream's frames."""
    stream = config.frames if stream is None else stream
    if len(frame_streams(stream)) > 1:
        raise ValueError(f"_frames makes one stream; split {stream!r} with frame_streams")
    if stream == "aps":
        return aps_frames(data.sequence, t_start, t_end)
    low, high = config.window_bounds()
    if stream == "mc-events":
        return mc_event_frames(data.sequence, data.R_CtoI, config.window_fraction, config.adaptive_windows, t_start,
                               t_end, min_window_s=low, max_window_s=high, gyro_bias=gyro_bias)
    if reconstructor is None:
        reconstructor = _event_reconstructor(data, config)
    return event_frames(data.sequence, reconstructor, config.window_fraction, config.adaptive_windows, t_start, t_end,
                        min_window_s=low, max_window_s=high)


def _tagged(frames: Iterator[tuple[float, np.ndarray, float]], stream: int
            ) -> Iterator[tuple[float, np.ndarray, float, int]]:
    """Yield each (t, image, seconds) of ``frames`` with its stream's index appended."""
    for t, image, seconds in frames:
        yield t, image, seconds, stream


def _span(data: LoadedDataset, config: PipelineConfig) -> tuple[float, float]:
    """Return (t_first, t_last): the time span the run may process (inside the IMU's, cut by max_duration)."""
    seq = data.sequence
    streams = frame_streams(config.frames)
    t0, t1 = -math.inf, math.inf
    if "aps" in streams or config.imu_only:
        if len(seq.frame_times) < 2:
            raise ValueError("the recording has fewer than 2 frames")
        t0, t1 = float(seq.frame_times[0]), float(seq.frame_times[-1])
    if not config.imu_only and streams != ("aps",):  # events too: the span both cover
        t0, t1 = max(t0, float(seq.events["t"][0])), min(t1, float(seq.events["t"][-1]))
    t0, t1 = max(t0, float(seq.imu.t[0])), min(t1, float(seq.imu.t[-1]))
    if config.max_duration is not None:
        t1 = min(t1, t0 + config.max_duration)
    if t1 <= t0:
        raise ValueError(f"the frames (or events) and the IMU do not overlap in time (frames [{t0:.3f}, ...], IMU "
                         f"[{seq.imu.t[0]:.3f}, {seq.imu.t[-1]:.3f}] s)")
    return t0, t1


# ==================================================================================================== the run
def run_pipeline(data: "LoadedDataset | Sequence | str | Path", config: PipelineConfig | None = None, progress: bool = False,
                 detector: Any = None) -> PipelineResult:
    """Return the result of running frames -> front-end -> MSCKF on a recording (module docstring).

    Args:
        data: the recording: a :class:`~evio_lib.pipeline.dataset.LoadedDataset`, or what
            :func:`~evio_lib.pipeline.dataset.load_dataset` takes (a Sequence in memory, a preset name, a path),
            loaded with its checks and the preset's defaults.
        config: the run's choices (default ``PipelineConfig()``: SIFT on APS frames).
        progress: show a progress bar over the processed seconds.
        detector: an already created feature detector to use instead of ``config.features`` (e.g. a loaded CNN), by
            every stream's tracker (with ``config.event_tracker`` 'klt' too, which otherwise detects FAST corners).

    Raises ValueError for a recording the run cannot use (no overlap of frames and IMU, a still start required by
    static initialisation that is not still, an IMU gap too long to bridge) with the reason in the message.

    The run in three parts: :func:`_initial_state` (the filter's first state and the time it starts at),
    :class:`_PipelineRun` (the filter and the front-ends, fed frame by frame in time order) and
    :meth:`_PipelineRun.result` (the arrays, the timings and the metrics).
    """
    config, data = _checked_inputs(data, config)
    notes = list(data.notes)
    has_truth = _groundtruth(data) is not None
    if config.init == "groundtruth" and not has_truth:
        raise ValueError("init 'groundtruth' needs a ground truth (groundtruth.txt); use init 'static'")
    t_first, t_last = _span(data, config)
    msckf_cfg = msckf_config_for(config, data)
    still_window = _still_window(msckf_cfg, t_first, t_last)
    msckf_cfg = dataclasses.replace(msckf_cfg, static_init_duration=still_window)
    state, t_first, init, unanchored = _initial_state(data, config, msckf_cfg, t_first, has_truth, notes)
    if t_last <= t_first:
        raise ValueError(f"nothing left to process after the initialisation at t = {t_first:.3f} s")

    run = _PipelineRun(data, config, msckf_cfg, state, t_first, notes, detector)
    run.process(t_last, progress)
    return run.result(t_last, init, unanchored=unanchored, has_truth=has_truth)


def _checked_inputs(data: Any, config: PipelineConfig | None) -> tuple[PipelineConfig, LoadedDataset]:
    """Return (config, data) for :func:`run_pipeline`: the default config for None, and ``data`` loaded by
    :func:`~evio_lib.pipeline.dataset.load_dataset` unless it is a LoadedDataset already (what the run reads only)."""
    config = PipelineConfig() if config is None else config
    if not isinstance(config, PipelineConfig):
        raise ValueError(f"config must be a PipelineConfig; got {type(config).__name__}")
    if data is None or isinstance(data, (bytes, int, float, dict, list, tuple)):
        raise TypeError(f"data must be a LoadedDataset, a Sequence, a preset name or a recording's path; got "
                        f"{type(data).__name__}")
    if not isinstance(data, LoadedDataset):          # a Sequence, a preset name or a path: the checks of load_dataset
        from evio_lib.pipeline.dataset import load_dataset

        uses = config.frames.split("+")
        data = load_dataset(data, need_events=not config.imu_only and any(s != "aps" for s in uses),
                            need_frames=config.imu_only or "aps" in uses,
                            seed=config.seed if isinstance(data, (str, Path)) else 0)   # as `run --seed` does
    return config, data


def _initial_state(data: LoadedDataset, config: PipelineConfig, msckf_cfg: MsckfConfig, t_first: float,
                   has_truth: bool, notes: list[str]) -> tuple[Any, float, str, bool]:
    """Return (state, t_first, init, unanchored): the filter's first state, the time it starts at, the
    initialisation used ('groundtruth' or 'static', 'auto' resolved; module docstring) and whether the start has no
    ground truth to take yaw and position from (another world frame: aligned errors only). Appends to ``notes``."""
    seq = data.sequence
    init = config.init
    unanchored = False  # a static start without ground truth at its end: another world frame, aligned errors only
    if init == "auto":
        still, why = _still_start(data, msckf_cfg, t_first)
        init = "static" if still or not has_truth else "groundtruth"
        start = ("the filter starts from gravity and the resting gyro" if still else
                 "no ground truth to start from, so the filter starts from gravity and the gyro's mean anyway"
                 if init == "static" else "the filter starts from the ground truth's pose and velocity")
        notes.append(f"start: {why}: {start}")

    if init == "groundtruth":
        t_first = max(t_first, float(_groundtruth(data).t[0]) + 0.025)
        truth0 = _truth_imu(data, np.array([t_first]))
        biases = _bias_estimates(config, truth0)
        b_g, b_a = biases if biases is not None else (np.zeros(3), np.zeros(3))
        state = initial_state_from_truth(t_first, truth0["R_ItoG"][0], truth0["p_IinG"][0],
                                         _truth_velocity(data, t_first, truth0), data.R_CtoI, data.p_CinI, msckf_cfg,
                                         b_g=b_g, b_a=b_a)
        notes.append(f"initialisation: ground-truth pose and velocity at t = {t_first:.3f} s, biases "
                     f"{'zero' if biases is None else 'from ' + str(config.bias_init)}")
    else:
        imu = seq.imu
        try:
            state, stats = initial_state_from_static(imu.t, imu.gyro, imu.accel, data.R_CtoI, data.p_CinI, msckf_cfg,
                                                     t_start=t_first)
        except ValueError as error:
            raise ValueError(f"static initialisation failed: {error}. Start the run where the sensor is still, or "
                             f"give a ground truth (init 'groundtruth')") from None
        # The window is still, so the attitude, the gyro bias and v = 0 hold over all of it: the filter starts at
        # its first sample and the frames inside it are processed too (a 0.17 s clip keeps its frames).
        t_first = stats.t_start
        truth_start = _truth_at(data, t_first) if has_truth else {}
        biases = _bias_estimates(config, truth_start if config.bias_init == "groundtruth" else {})
        if biases is not None:
            state = dataclasses.replace(state, imu=dataclasses.replace(state.imu, b_g=np.asarray(biases[0]),
                                                                        b_a=np.asarray(biases[1])))
        # the unobservable yaw and position from the ground truth where there is one: the errors need no alignment
        state = _anchor_to_truth(state, truth_start, t_first)
        unanchored = not truth_start
        notes.append(f"initialisation: static, IMU still over [{stats.t_start:.3f}, {stats.t_end:.3f}] s (gravity "
                     f"error {stats.gravity_error:+.3f} m/s^2), velocity 0, gyro bias "
                     f"{'from the still IMU' if biases is None else 'from ' + str(config.bias_init)}; "
                     + ("yaw and position from the ground truth" if truth_start else
                        "yaw 0 and position 0, so compare with a ground truth after alignment (ATE)"))
    return state, t_first, init, unanchored


class _PipelineRun:
    """One run of :func:`run_pipeline` after its initialisation: the filter, one tracker and one standstill test per
    frame stream, and what each frame left (the filter's outputs, the tracked frames, the timings).

    ``__init__`` starts the filter at ``t_first`` and feeds it the whole IMU; :meth:`process` takes the frames in
    time order through :meth:`step`; :meth:`result` turns the records into a :class:`PipelineResult`."""

    def __init__(self, data: LoadedDataset, config: PipelineConfig, msckf_cfg: MsckfConfig, state: Any,
                 t_first: float, notes: list[str], detector: Any = None) -> None:
        seq = data.sequence
        self.data, self.config, self.msckf_cfg, self.t_first, self.notes = data, config, msckf_cfg, t_first, notes
        self.filt = filt = Msckf(msckf_cfg, state)
        self.imu = imu = seq.imu
        self.zv = ZeroVelocityConfig(enabled=config.zupt and not config.imu_only)
        self.zupt_frames = 0
        k0 = int(np.searchsorted(imu.t, t_first, side="right"))
        self.wall0 = time.perf_counter()
        filt.feed_imu(imu.t[k0:], imu.gyro[k0:], imu.accel[k0:])
        self.streams = streams = frame_streams(config.frames)
        # one tracker (and standstill test) per frame stream; the second stream's track ids are offset so that the
        # filter's tracks of the two never share an id (STREAM_ID_OFFSET)
        self.trackers = [create_tracker(seq.camera, config.frontend_config(name), detector=detector)
                         for name in streams]
        self.standstills = [StandstillDetector(self.zv) for _ in streams]
        self.sigmas_px = sigmas_px = [config.stream_pixel_noise(name) for name in streams]  # each stream's noise
        self.reconstructor = None if config.imu_only else _event_reconstructor(data, config)
        self.precision = precision = getattr(self.reconstructor, "precision", None)  # networks only
        if precision is not None:  # what "auto" chose: int8 on an x86 CPU, else float32
            notes.append(f"event frames: {config.reconstructor} computed in {precision} (reconstructor precision "
                         f"{config.reconstructor_precision})")
        if len(streams) > 1:
            notes.append(f"{len(streams)} frame streams: feature noise "
                         + ", ".join(f"{name} {sigma:g} px" for name, sigma in zip(streams, sigmas_px))
                         + f"; the window holds {msckf_cfg.max_camera_states} camera states")
        self.outputs: list = []
        self.tracked: list = []
        self.timings = dict(reconstruction=0.0, detection=0.0, matching=0.0, ransac=0.0, filter=0.0)
        self.t_prev_stream: list[float | None] = [None] * len(streams)
        self.wall = 0.0

    def _gyro_bias(self) -> np.ndarray:
        """Return the filter's current gyro bias (mc-events warp each window with the gyro less this)."""
        return self.filt.state.imu.b_g

    def _source(self, t_last: float) -> Iterator[tuple[float, np.ndarray | None, float, int]]:
        """Return the frames of (t_first, t_last] as (t, image, reconstruction seconds, stream index), every stream
        merged in time order; IMU only: the frame times with no image."""
        config, seq, t_first = self.config, self.data.sequence, self.t_first
        if config.imu_only:
            times = seq.frame_times[(seq.frame_times > t_first) & (seq.frame_times <= t_last)]
            return ((float(t), None, 0.0, 0) for t in times)
        parts = [_tagged(_frames(self.data, config, t_first, t_last, gyro_bias=self._gyro_bias, stream=name,
                                 reconstructor=self.reconstructor), k)
                 for k, name in enumerate(self.streams)]
        return parts[0] if len(parts) == 1 else heapq.merge(*parts, key=lambda item: item[0])

    def process(self, t_last: float, progress: bool = False) -> None:
        """Feed the filter every frame of (t_first, t_last] in time order (a frame not after the last one is
        skipped), with a progress bar over the processed seconds when ``progress``."""
        t_first = self.t_first
        bar = None
        if progress:
            from tqdm import tqdm

            total = round(t_last - t_first, 1)
            bar = tqdm(total=total, unit="s", desc=self.config.label(), leave=False, bar_format="{l_bar}{bar}| {n:.1f}/"
                       "{total:.1f} s [{elapsed}<{remaining}]")
        t_prev = None
        source = self._source(t_last)
        # one BLAS thread: the front-end's and the filter's matrices are small, and threaded BLAS spins
        # (evio_lib.threads)
        with warnings.catch_warnings(), single_threaded_blas():
            warnings.simplefilter("ignore", MsckfWarning)  # counted in filt.faults and reported in the summary
            for t, image, t_rec, k in source:
                if t <= t_first or (t_prev is not None and t <= t_prev):
                    continue
                self.step(t, image, t_rec, k)
                if bar is not None:  # whole tenths of a second, never past the total
                    bar.update(max(0.0, min(bar.total, round(t - t_first, 1)) - bar.n))
                t_prev = t
        if bar is not None:
            bar.update(max(0.0, bar.total - bar.n))  # ends at its total
            bar.refresh()
            bar.close()
        self.wall = time.perf_counter() - self.wall0

    def step(self, t: float, image: np.ndarray | None, t_rec: float, k: int) -> None:
        """Process one frame of stream ``k`` at time ``t`` (``image`` None: an IMU-only step to t): track it, then a
        zero-velocity update where it stands still, else the visual update with its stream's pixel noise."""
        filt, imu, timings, outputs = self.filt, self.imu, self.timings, self.outputs
        timings["reconstruction"] += t_rec
        if image is None:
            start = time.perf_counter()
            outputs.append(filt.process_image(t, np.zeros(0, np.int64), np.zeros((0, 2))))
            timings["filter"] += time.perf_counter() - start
        else:
            R_prior = None
            if self.t_prev_stream[k] is not None:
                b_g = filt.state.imu.b_g
                R_prior = camera_rotation_prior(imu.t, imu.gyro, self.t_prev_stream[k], t, self.data.R_CtoI,
                                                gyro_bias=b_g)
            frame = self.trackers[k].process(image, t, R_prior)
            self.t_prev_stream[k] = t
            if k:
                frame = dataclasses.replace(frame, ids=frame.ids + k * STREAM_ID_OFFSET)
            timings["detection"] += frame.stats.time_detect_s
            timings["matching"] += frame.stats.time_match_s
            timings["ransac"] += frame.stats.time_ransac_s
            self.tracked.append(frame)
            start = time.perf_counter()
            out = None
            if self.zv.enabled and self.standstills[k].test(t, frame.ids, frame.pixels, imu.t, imu.gyro, imu.accel,
                                                            filt.state.imu, self.msckf_cfg.gravity).still:
                out = filt.zero_velocity_update(t, self.zv)  # None: its gate refused; a visual update then
                self.zupt_frames += out is not None
            if out is None:
                sigma = self.sigmas_px[k]
                cov = observation_covariance(self.data.sequence.camera, frame.pixels, sigma) if len(frame) else None
                out = filt.process_image(t, frame.ids, frame.xy, cov, stream=k)
            outputs.append(out)
            timings["filter"] += time.perf_counter() - start
        if not (np.all(np.isfinite(outputs[-1].p_IinG)) and np.all(np.isfinite(outputs[-1].P_imu))):
            raise ValueError(f"the filter's state became non-finite at t = {t:.3f} s (faults: {dict(filt.faults)})")

    def result(self, t_last: float, init: str, unanchored: bool, has_truth: bool) -> PipelineResult:
        """Return the run's :class:`PipelineResult`: the filter's outputs as arrays, the tracking statistics, the
        timings and, with a ground truth, the metrics (``unanchored``: aligned errors only)."""
        config, data, outputs, t_first, timings = self.config, self.data, self.outputs, self.t_first, self.timings
        seq, tracked = data.sequence, self.tracked
        if not outputs:
            raise ValueError(f"no frame to process in [{t_first:.3f}, {t_last:.3f}] s (no events or frames there)")
        lengths = _track_lengths(tracked)

        t = np.array([o.t for o in outputs])
        P = np.array([o.P_imu for o in outputs])
        duration = float(t[-1] - t_first)
        wall = self.wall
        timings["total"] = wall  # reconstruction happens inside the loop, so it is part of the wall time
        timings["realtime_factor"] = duration / wall if wall > 0 else float("inf")
        result = PipelineResult(
            config=config, dataset={"name": seq.name, "kind": data.kind, "source": data.source}, notes=self.notes,
            t=t, q_GtoI=np.array([o.q_GtoI for o in outputs]), p_IinG=np.array([o.p_IinG for o in outputs]),
            v_IinG=np.array([o.v_IinG for o in outputs]), b_g=np.array([o.b_g for o in outputs]),
            b_a=np.array([o.b_a for o in outputs]), sigma=np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None)),
            features_used=np.array([o.n_features_used for o in outputs]), R_CtoI=data.R_CtoI, p_CinI=data.p_CinI,
            tracking=stats_table(tracked) if tracked else {}, track_lengths=lengths, truth={}, metrics={},
            timings=timings, faults=dict(self.filt.faults), rejections=dict(self.filt.rejections),
            reconstructor_precision=self.precision,
        )
        result.metrics = {"frames": int(len(t)), "duration_s": duration, "t_start": t_first, "t_end": float(t[-1]),
                          "init": init, "zupt_frames": int(self.zupt_frames)}
        if has_truth:
            _score(result, data, aligned_only=unanchored)
        return result


def _score(result: PipelineResult, data: LoadedDataset, aligned_only: bool) -> None:
    """Fill ``result.truth`` and ``result.metrics`` against the ground truth, over the frames it covers.

    A ground truth that ends before the run (common with motion capture) or starts after it is scored over the
    overlap; the truth arrays hold NaN at the other frames and a note says which part was scored."""
    gt = _groundtruth(data)
    t = result.t
    inside = (t >= gt.t[0]) & (t <= gt.t[-1])
    n_in = int(np.count_nonzero(inside))
    if n_in < 2:
        result.notes.append(f"no metrics: the ground truth [{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s covers {n_in} of the "
                            f"{len(t)} frames [{t[0]:.3f}, {t[-1]:.3f}] s")
        return
    if n_in == len(t):
        result.truth = _truth_imu(data, t)
        result.metrics.update(trajectory_metrics(result, aligned_only=aligned_only))
    else:
        part = _truth_imu(data, t[inside])
        result.truth = {}
        for key, value in part.items():
            full = np.full((len(t),) + value.shape[1:], np.nan)
            full[inside] = value
            result.truth[key] = full
        sub = dataclasses.replace(result, t=t[inside], q_GtoI=result.q_GtoI[inside], p_IinG=result.p_IinG[inside],
                                  truth=part, metrics={})
        result.metrics.update(trajectory_metrics(sub, aligned_only=aligned_only))
        result.metrics["scored_frames"] = n_in
        result.notes.append(f"scored over the overlap with the ground truth: {n_in} of {len(t)} frames, "
                            f"[{t[inside][0]:.3f}, {t[inside][-1]:.3f}] s (the ground truth spans "
                            f"[{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s)")
    if result.metrics.get("distance_m", 0.0) < MIN_PERCENT_DISTANCE_M:
        result.metrics["percent_of_distance"] = float("nan")
        result.notes.append(f"no % of distance: the ground-truth path is {result.metrics.get('distance_m', 0.0):.3f} m, "
                            f"shorter than {MIN_PERCENT_DISTANCE_M} m")


def _track_lengths(frames: list) -> np.ndarray:
    """Return the number of frames each track was observed in: its largest age (ages count the frames a track has
    been seen in, this one included), one entry per track id, in id order."""
    if not frames:
        return np.zeros(0, np.int64)
    ids = np.concatenate([f.ids for f in frames])
    ages = np.concatenate([f.ages for f in frames])
    unique, index = np.unique(ids, return_inverse=True)
    lengths = np.zeros(unique.shape[0], np.int64)
    np.maximum.at(lengths, index, ages)
    return lengths


def trajectory_metrics(result: PipelineResult, aligned_only: bool = False) -> dict[str, Any]:
    """Return the error metrics of a result against its ``truth`` (IMU positions and orientations at ``t``).

    Keys: those of :func:`evio_lib.evaluation.trajectory_metrics.summarize` (rmse_m, final_error_m,
    percent_of_distance, distance_m, ate_4dof_m, ate_se3_m, ...), orientation_rmse_deg, rmse_first_half_m /
    rmse_second_half_m (the run split at its middle time), relative_errors (one summary per sub-trajectory length,
    10-50 % of the path, :func:`~evio_lib.evaluation.trajectory_metrics.relative_errors_by_length`) and
    relative_translation_percent (their mean translation error in % of the length, averaged over the lengths).
    With ``aligned_only`` (static initialisation: another world frame) the unaligned figures are NaN; the ATEs and
    the relative errors (which need no alignment) remain.
    """
    t, truth = result.t, result.truth
    row = summarize(t, result.p_IinG, t, truth["p_IinG"])
    row.pop("name", None)
    angle, _, _ = orientation_errors(result.R_ItoG, truth["R_ItoG"])
    row["orientation_rmse_deg"] = float(np.degrees(np.sqrt(np.mean(angle ** 2))))
    err = np.linalg.norm(result.p_IinG - truth["p_IinG"], axis=1)
    mid = 0.5 * (t[0] + t[-1])
    first, second = t <= mid, t > mid
    row["rmse_first_half_m"] = float(np.sqrt(np.mean(err[first] ** 2))) if first.any() else float("nan")
    row["rmse_second_half_m"] = float(np.sqrt(np.mean(err[second] ** 2))) if second.any() else float("nan")
    # relative errors over sub-trajectories of 10-50 % of the path (rpg_trajectory_evaluation): they need no
    # alignment, so they also hold after a static start
    if row["distance_m"] > 0 and len(t) >= 3:
        try:
            relative = relative_errors_by_length(result.R_ItoG, result.p_IinG, truth["R_ItoG"], truth["p_IinG"])
        except ValueError:
            relative = []
        row["relative_errors"] = [r.summary() for r in relative]
        means = [summary["translation_percent_mean"] for summary in row["relative_errors"] if summary["pairs"] > 0]
        row["relative_translation_percent"] = float(np.mean(means)) if means else float("nan")
    if aligned_only:
        for key in ("rmse_m", "final_error_m", "mean_error_m", "max_error_m", "percent_of_distance",
                    "orientation_rmse_deg", "rmse_first_half_m", "rmse_second_half_m"):
            row[key] = float("nan")
    return row


def run_pipelines(data: LoadedDataset, configs: Mapping[str, PipelineConfig], jobs: int | None = None,
                  threads: int = 1) -> dict[str, PipelineResult]:
    """Return ``{name: run_pipeline(data, config)}`` for every configuration, the runs spread over worker processes.

    Every run is deterministic, so its trajectory, tracks and metrics are the same in a worker as here (tested).
    Its timings are those of its own process, set to ``threads`` threads (:func:`set_threads`): on a CPU with fewer
    free cores than workers, or whose cores are hyper-threads, they are slower than a run alone. ``jobs``: worker
    processes (default :func:`evio_lib.sim.jobs.default_jobs`: ``EVIO_JOBS``, else one per logical CPU, at most 4 and
    at most one per configuration); 1 runs them here, one after the other, with this process's thread settings.

    >>> from evio_lib.pipeline import load_dataset
    >>> data = load_dataset("boxes_like", duration=2.0)  # doctest: +SKIP
    >>> results = run_pipelines(data, {"SIFT": PipelineConfig(), "KLT": PipelineConfig(tracker="klt", features="fast")})  # doctest: +SKIP
    """
    from evio_lib.sim.jobs import check_jobs, default_jobs, map_in_workers

    names = list(configs)
    jobs = min(check_jobs(default_jobs() if jobs is None else jobs), max(len(names), 1))
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be an integer >= 1 (threads per worker); got {threads!r}")
    if jobs == 1:  # here, with this process's thread settings
        return {name: run_pipeline(data, configs[name]) for name in names}
    calls = [dict(data=data, config=configs[name], threads=threads) for name in names]
    return dict(zip(names, map_in_workers(_run_in_worker, calls, jobs)))


def _run_in_worker(data: LoadedDataset, config: PipelineConfig, threads: int) -> PipelineResult:
    """One run of :func:`run_pipelines` in a worker process, limited to ``threads`` threads."""
    set_threads(threads)
    return run_pipeline(data, config)
