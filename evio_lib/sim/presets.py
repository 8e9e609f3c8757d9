"""Whole simulated recordings: one call turns a preset name into a :class:`~evio_lib.sequence.Sequence`.

A preset couples a scene (:mod:`evio_lib.sim.scene`) with a trajectory of the IMU (:mod:`evio_lib.sim.trajectory`); the rig's
camera-IMU extrinsics (:mod:`evio_lib.sim.rig`) give the camera's pose. From that one ground truth the simulator derives every
sensor, so they are mutually consistent by construction:

- IMU samples (gyro = w_I + b_g + n_g, accel = R_GtoI (a_IinG - g_G) + b_a + n_a) at ``imu_rate_hz``,
- events of an ESIM-style event camera, rendered with adaptive sampling,
- grayscale (APS) frames at ``frame_rate_hz`` with real motion blur over the exposure,
- ground truth: the camera pose in the world (``groundtruth``, like the ECD's ``groundtruth.txt``) and the IMU state with
  velocity and true biases (``groundtruth_imu``).

The two presets reproduce the regimes of the thesis (§3.4, §4.1): ``boxes_like`` (a textured room with boxes, hand-held motion
growing violent) and ``aerial_like`` (a downward camera over sparse terrain at ~250 m and ~20 m/s with a banked turn).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from evio_lib.events.simulate import EventCameraParams, simulate_events
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import rot_to_quat, so3_exp, so3_log
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence
from evio_lib.sim.aps import ApsParams, aps_exposure, aps_sensor_response, render_aps_frames
from evio_lib.sim.imu import GRAVITY_G, ImuNoiseParams, synthesize_imu
from evio_lib.sim.jobs import check_jobs, default_jobs  # default_jobs: re-exported
from evio_lib.sim.rig import CameraImuExtrinsics
from evio_lib.sim.scene import scene_from_preset
from evio_lib.sim.trajectory import trajectory_from_preset

PRESETS = ("boxes_like", "aerial_like")

__all__ = ["PRESETS", "MAX_RECORDING_DURATION_S", "MIN_SPEED", "MAX_SPEED", "CameraPoseTable", "SimulationConfig", "simulate_sequence",
           "simulation_cache_path", "simulate_sequence_cached",
           "recording_settings_digest"]

#: Longest recording with events or frames that one simulation makes, seconds (ten minutes). The events (13 B each)
#: and 24 frames/s of W x H bytes are all held in memory: at the presets' event rates ten minutes take gigabytes and
#: many minutes of simulation on a 2-core CPU (measured: docs/results/speed.md#small-costs-behind-the-codes-choices).
#: An IMU-only simulation may run for MAX_TRAJECTORY_DURATION_S (an hour).
MAX_RECORDING_DURATION_S = 600.0

#: Bounds of ``SimulationConfig.speed``. At speed 2 the violent end of boxes_like (3.1-3.6 m/s and about 5 rad/s
#: over its last 5 s) makes many times the preset's event rate, and before the end, on some seeds, one axis of its
#: specific force exceeds the 16 g full scale that the filter accepts (``MsckfConfig.accel_full_scale``), which drops
#: such samples (both measured in docs/results/pipeline.md#faster-motion); the gentler stretches of a preset stay
#: within it at higher speeds, so the bound is four times the preset's speed.
MIN_SPEED, MAX_SPEED = 0.25, 4.0


@dataclass(frozen=True)
class SimulationConfig:
    """Every setting of a simulated recording (frozen, validated); ``print(config)`` shows them all.

    Attributes (defaults in brackets; every time is in seconds of the recording's clock, which starts at 0):
        preset: the scene and motion, one of :data:`PRESETS` ['boxes_like'].
        duration: length of the recording, s [10].
        start_time: where in the preset's motion the recording starts, s [0].
        trajectory_duration: length of the preset's whole motion, s. None [default]: ``max(start_time + duration,
            2 s)``, so the whole motion (gentle start, violent end) is played within the recording: **duration here
            compresses the preset**. ``evio_lib.pipeline.load_dataset(preset, duration=D)`` means something else,
            the first D s of the preset's full-length motion (60 s boxes_like, 40 s aerial_like); to simulate that
            here, pass ``trajectory_duration=preset_length(preset)`` (``evio_lib.pipeline.dataset.preset_length``).
        speed: the preset's motion played this many times faster [1], in [MIN_SPEED, MAX_SPEED]
            (``TimeScaledTrajectory``); duration, start_time and trajectory_duration are times of the faster motion.
        seed: one seed for everything random: the trajectory's phases, the scene, the IMU noise and biases, the
            events and the frames [0]. (``msckf.experiment.VioSimConfig`` splits it into ``seed``, the noise, and
            ``trajectory_seed``, the motion.)
        imu_rate_hz, frame_rate_hz, groundtruth_rate_hz: sample rates, Hz [1000, 24 (the DAVIS240C's APS), 200].
        camera: intrinsics and radial-tangential distortion of the camera, pixels [the DAVIS240C's, 240 x 180].
        extrinsics: the camera's pose in the IMU frame, R_CtoI and p_CinI [m] [``CameraImuExtrinsics.default()``].
        imu_noise: noise densities and bias random walks of the IMU (continuous-time, per sqrt(Hz)).
        events: the event camera: contrast thresholds, their per-pixel spread, refractory period, noise.
        aps: the APS frames: exposure, blur, sensor response and noise.
        event_change_quantile: the adaptive event sampling bounds this quantile of the per-pixel log-intensity change
            between renders [0.99] (occlusion edges jump by a whole log unit however short the step).
        with_events, with_frames: simulate the events and the APS frames [True, True]; without both, an IMU-only
            recording may last up to ``MAX_TRAJECTORY_DURATION_S``.
    """

    preset: str = "boxes_like"
    duration: float = 10.0
    start_time: float = 0.0
    trajectory_duration: float | None = None
    speed: float = 1.0
    seed: int = 0
    imu_rate_hz: float = 1000.0
    frame_rate_hz: float = 24.0
    groundtruth_rate_hz: float = 200.0
    camera: PinholeRadtan = field(default_factory=PinholeRadtan.davis240c)
    extrinsics: CameraImuExtrinsics = field(default_factory=CameraImuExtrinsics.default)
    imu_noise: ImuNoiseParams = field(default_factory=ImuNoiseParams)
    events: EventCameraParams = field(default_factory=EventCameraParams)
    aps: ApsParams = field(default_factory=ApsParams)
    event_change_quantile: float = 0.99
    with_events: bool = True
    with_frames: bool = True

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {PRESETS}; got {self.preset!r}")
        for name in ("duration", "imu_rate_hz", "frame_rate_hz", "groundtruth_rate_hz"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number; got {value!r}")
        if isinstance(self.speed, bool) or not isinstance(self.speed, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(self.speed) and MIN_SPEED <= self.speed <= MAX_SPEED):
            raise ValueError(f"speed must be a number in [{MIN_SPEED:g}, {MAX_SPEED:g}] (how many times faster than the "
                             f"preset the motion is played; events per second grow with it); got {self.speed!r}")
        object.__setattr__(self, "speed", float(self.speed))  # 2 and 2.0 name the same recording
        from evio_lib.sim.trajectory import MAX_TRAJECTORY_DURATION_S

        longest = MAX_RECORDING_DURATION_S if self.with_events or self.with_frames else MAX_TRAJECTORY_DURATION_S
        if self.duration > longest:  # before any array is made: --duration 1e9 would ask for terabytes
            rate = 0.35e6 * max(float(self.speed), 1.0)  # events/s of the presets, more when played faster
            gib = self.duration * (rate * 13 + 24 * self.camera.width * self.camera.height) / 2**30
            raise ValueError(f"duration {self.duration:g} s is longer than the longest simulation, {longest:g} s "
                             f"({'MAX_RECORDING_DURATION_S' if longest == MAX_RECORDING_DURATION_S else 'MAX_TRAJECTORY_DURATION_S'}"
                             f"; {self.duration:g} s of events and frames would take about {gib:.3g} GiB of memory)")
        if not (np.isfinite(self.start_time) and self.start_time >= 0):
            raise ValueError(f"start_time must be a finite number >= 0; got {self.start_time!r}")
        if self.trajectory_duration is not None and self.start_time + self.duration > self.trajectory_duration + 1e-9:
            raise ValueError(f"the recording [{self.start_time}, {self.start_time + self.duration}] s must lie within the "
                             f"preset's motion of trajectory_duration={self.trajectory_duration} s")

    @property
    def t_end(self) -> float:
        """End time of the recording (s)."""
        return self.start_time + self.duration

    def motion_duration(self) -> float:
        """Length of the preset's trajectory that the recording is cut from (s)."""
        if self.trajectory_duration is not None:
            return self.trajectory_duration
        return max(self.t_end, 2.0 / min(self.speed, 1.0))  # the presets' motions last at least 2 s (of their own clock)


def _pose_function(trajectory, extrinsics: CameraImuExtrinsics):
    """Return pose_at(times) -> (R_CtoG (K,3,3), p_CinG (K,3)) of the camera along the IMU trajectory."""

    def pose_at(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sample = trajectory.evaluate(np.atleast_1d(np.asarray(times, dtype=np.float64)))
        return extrinsics.camera_pose(sample.R_ItoG, sample.p_IinG)

    return pose_at


class CameraPoseTable:
    """Camera poses on a dense time grid, interpolated for the event renderer's one-at-a-time queries.

    Evaluating the closed-form trajectory costs about a millisecond per call for a single time (hundreds of tiny NumPy
    operations), while the event simulator asks for one pose per render, thousands of times per simulated second. The table
    evaluates the trajectory once, vectorised, at ``rate_hz`` and interpolates between grid points:

    - position: cubic Hermite with the exact velocities at both ends,
      p(u) = h00 p_i + h10 dt v_i + h01 p_i+1 + h11 dt v_i+1, whose error is of order |d4p/dt4| dt^4 / 384,
    - rotation: geodesic interpolation R(u) = R_i exp(u log(R_i^T R_i+1)), whose error from the angular acceleration is
      of order |dw/dt| dt^2 / 8 (about 1e-8 rad at 10 kHz, i.e. 2e-6 px for the DAVIS240C).

    At the grid times the poses are the trajectory's own; tests/sim/test_presets.py measures the error.
    """

    def __init__(self, trajectory, extrinsics: CameraImuExtrinsics, t_start: float, t_end: float,
                 rate_hz: float = 10000.0, chunk: int = 20000) -> None:
        n = int(np.ceil((t_end - t_start) * rate_hz)) + 1
        self.t = np.linspace(t_start, t_end, n)
        self.dt = (t_end - t_start) / (n - 1)
        R_CtoG, p_CinG, v_CinG = [], [], []
        for i in range(0, n, chunk):
            sample = trajectory.evaluate(self.t[i:i + chunk])
            R, p = extrinsics.camera_pose(sample.R_ItoG, sample.p_IinG)
            # v_C = v_I + R_ItoG (w_I x p_CinI): the camera centre moves with the rigid body
            lever_G = np.einsum("nij,nj->ni", sample.R_ItoG, np.cross(sample.w_I, extrinsics.p_CinI))
            R_CtoG.append(R)
            p_CinG.append(p)
            v_CinG.append(sample.v_IinG + lever_G)
        self.R_CtoG = np.concatenate(R_CtoG)
        self.p_CinG = np.concatenate(p_CinG)
        self.v_CinG = np.concatenate(v_CinG)
        # rotation increment between grid points, in the earlier pose's frame: phi_i = log(R_i^T R_i+1)
        self.phi = so3_log(np.einsum("nji,njk->nik", self.R_CtoG[:-1], self.R_CtoG[1:]))

    def __call__(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (R_CtoG (K,3,3), p_CinG (K,3)) at times (K,) within the table's span."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if np.any(times < self.t[0] - 1e-9) or np.any(times > self.t[-1] + 1e-9):
            raise ValueError(f"times must lie in [{self.t[0]}, {self.t[-1]}] s; got [{times.min()}, {times.max()}]")
        i = np.clip(((times - self.t[0]) / self.dt).astype(np.int64), 0, len(self.t) - 2)
        u = np.clip((times - self.t[i]) / self.dt, 0.0, 1.0)[:, None]
        u2, u3 = u * u, u * u * u
        h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2  # cubic Hermite basis
        p = (h00 * self.p_CinG[i] + h10 * self.dt * self.v_CinG[i]
             + h01 * self.p_CinG[i + 1] + h11 * self.dt * self.v_CinG[i + 1])
        R = self.R_CtoG[i] @ so3_exp(u * self.phi[i])
        return R, p


#: Fewer frames per process than this are rendered in this process: starting the workers (and making the scene in
#: each) would cost more than it saves (measured in docs/results/speed.md#the-simulator, "Frames in worker processes").
MIN_FRAMES_PER_JOB = 100


def simulate_sequence(config: SimulationConfig, progress: bool = False,
                      timings: dict[str, float] | None = None, jobs: int | None = 1) -> Sequence:
    """Return a simulated recording (events, APS frames, IMU, ground truth, calibration) for ``config``.

    Args:
        config: the preset, duration, seed and sensor settings.
        progress: show progress bars (on stderr).
        timings: when given, filled with the wall-clock seconds of each sensor (``imu_s``, ``events_s``,
            ``frames_s``). They are kept out of the recording's metadata, so that equal configs (seeds) give equal
            recordings, byte for byte once written.
        jobs: worker processes that render the APS exposures (the sensor noise is then drawn here, frame after
            frame, so the frames do not depend on ``jobs``); 1 renders them in this process, None asks
            :func:`evio_lib.sim.jobs.default_jobs`. Under ``MIN_FRAMES_PER_JOB`` frames per process they are
            rendered here.

    The random streams of the IMU, the event camera and the APS frames are independent children of ``config.seed``
    (``numpy.random.SeedSequence.spawn``), so switching one sensor off does not change the others.
    ``metadata["timings"]`` holds only what does not depend on the machine: ``event_renders``, the number of scene
    renders of the adaptive event sampling.
    """
    jobs = default_jobs() if jobs is None else check_jobs(jobs)
    seed_imu, seed_events, seed_aps = np.random.SeedSequence(config.seed).spawn(3)  # the scene and trajectory use the seed too
    trajectory, scene, pose_at = _world(config)
    camera = config.camera
    timings = {} if timings is None else timings
    counts: dict[str, float] = {}

    start = time.perf_counter()
    imu = synthesize_imu(trajectory, rate_hz=config.imu_rate_hz, noise=config.imu_noise,
                         rng=np.random.default_rng(seed_imu), t_start=config.start_time, t_end=config.t_end)
    timings["imu_s"] = time.perf_counter() - start

    # Ground truth on a regular grid: the camera pose (like the ECD) and the IMU state with its true biases.
    n_gt = int(np.floor(config.duration * config.groundtruth_rate_hz + 1e-9)) + 1
    t_gt = config.start_time + np.arange(n_gt) / config.groundtruth_rate_hz
    truth = trajectory.evaluate(t_gt)
    R_CtoG, p_CinG = config.extrinsics.camera_pose(truth.R_ItoG, truth.p_IinG)
    groundtruth = GroundTruth(t=t_gt, p_BinG=p_CinG, q_GtoB=rot_to_quat(np.swapaxes(R_CtoG, -1, -2)), body="camera")
    bias_gyro = np.stack([np.interp(t_gt, imu.t, imu.bias_gyro[:, k]) for k in range(3)], axis=1)
    bias_accel = np.stack([np.interp(t_gt, imu.t, imu.bias_accel[:, k]) for k in range(3)], axis=1)
    groundtruth_imu = GroundTruth(t=t_gt, p_BinG=truth.p_IinG, q_GtoB=rot_to_quat(np.swapaxes(truth.R_ItoG, -1, -2)),
                                  body="imu", v_BinG=truth.v_IinG, bias_gyro=bias_gyro, bias_accel=bias_accel)

    frame_times = np.zeros(0)
    if config.with_frames:
        half_exposure = 0.5 * config.aps.exposure_s
        frame_times = np.arange(config.start_time + half_exposure, config.t_end - half_exposure + 1e-12,
                                1.0 / config.frame_rate_hz)
    # The APS exposures go to worker processes when there are enough of them; while events are simulated here, one
    # core is left to this process and the workers render meanwhile.
    workers = max(jobs - 1, 1) if config.with_events else jobs
    pending = None
    if config.with_frames and jobs > 1 and frame_times.shape[0] >= MIN_FRAMES_PER_JOB * workers:
        pending = _submit_exposures(config, frame_times, workers)
    try:
        events = None
        if config.with_events:
            start_events = time.perf_counter()
            pose_table = CameraPoseTable(trajectory, config.extrinsics, config.start_time, config.t_end)

            def render(t: float) -> np.ndarray:
                R, p = pose_table(np.array([t]))
                return scene.render_intensity(camera, R[0], p[0])

            events, sample_times = simulate_events(render, config.start_time, config.t_end, camera.width,
                                                   camera.height, params=config.events,
                                                   rng=np.random.default_rng(seed_events), progress=progress,
                                                   change_quantile=config.event_change_quantile)
            timings["events_s"] = time.perf_counter() - start_events
            counts["event_renders"] = float(len(sample_times))

        frames = np.zeros((0, camera.height, camera.width), dtype=np.uint8)
        if config.with_frames:
            rng_aps = np.random.default_rng(seed_aps)
            start = time.perf_counter()
            if pending is not None:
                frames = _collect_frames(pending, config, frame_times, rng_aps, progress)
            else:
                frames = render_aps_frames(scene, camera, pose_at, frame_times, config.aps, rng_aps, progress=progress)
            timings["frames_s"] = time.perf_counter() - start  # with workers: what is left after the events
    finally:
        if pending is not None:  # after an error: the chunks not rendered yet are dropped (no-op once consumed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # joblib's note that it cancelled tasks
                pending.close()

    metadata = {
        "source": "evio simulator",
        "config": {"preset": config.preset, "duration": config.duration, "seed": config.seed,
                   "start_time": config.start_time, "trajectory_duration": config.motion_duration(),
                   "speed": config.speed,
                   "imu_rate_hz": config.imu_rate_hz, "frame_rate_hz": config.frame_rate_hz,
                   "groundtruth_rate_hz": config.groundtruth_rate_hz, "events": asdict(config.events),
                   "aps": asdict(config.aps)},
        "imu_noise": config.imu_noise.to_dict(),
        "gravity_G": GRAVITY_G.tolist(),
        "timings": counts,  # deterministic counts only; wall-clock seconds go to the `timings` argument
    }
    return Sequence(
        name=f"{config.preset}_seed{config.seed}",
        camera=camera,
        events=events,
        frame_times=frame_times,
        frames=frames,
        imu=ImuSamples(t=imu.t, gyro=imu.gyro, accel=imu.accel),
        groundtruth=groundtruth,
        groundtruth_imu=groundtruth_imu,
        R_CtoI=np.array(config.extrinsics.R_CtoI),
        p_CinI=np.array(config.extrinsics.p_CinI),
        metadata=metadata,
    )


def _exposure_chunk(config: SimulationConfig, times: np.ndarray) -> np.ndarray:
    """Return (K, H, W) float32 APS exposures at ``times``: the task of the workers of :func:`_submit_exposures`.

    The scene and the motion are made again from the config (0.3 s; the scene pickles to 80 MB, too much to send),
    once per recording in each worker.
    """
    key = json.dumps([config.preset, config.seed, config.motion_duration(), config.speed, asdict(config.extrinsics)],
                     default=lambda value: np.asarray(value).tolist())
    if key not in _WORKER_WORLD:  # a worker renders several chunks of one recording: the world is made once
        _WORKER_WORLD.clear()
        _WORKER_WORLD[key] = _world(config)
    _, scene, pose_at = _WORKER_WORLD[key]
    return np.stack([aps_exposure(scene, config.camera, pose_at, float(t), config.aps) for t in times])


_WORKER_WORLD: dict[str, tuple] = {}  # in a frame worker: the (trajectory, scene, pose_at) of the last recording


def _world(config: SimulationConfig):  # type: ignore[no-untyped-def]
    """Return (trajectory, scene, pose_at) of ``config``: made the same way here and in the frame workers."""
    trajectory = trajectory_from_preset(config.preset, duration=config.motion_duration(), seed=config.seed,
                                        speed=config.speed)
    scene = scene_from_preset(config.preset, seed=config.seed)
    return trajectory, scene, _pose_function(trajectory, config.extrinsics)


def _submit_exposures(config: SimulationConfig, times: np.ndarray, workers: int):  # type: ignore[no-untyped-def]
    """Start rendering the APS exposures at ``times`` in ``workers`` processes; return joblib's generator of them.

    joblib dispatches the chunks at once and goes on in the background, so the workers render while this process
    simulates the events; the generator gives the chunks in time order. Chunks of at most 240 frames (40 MB of
    exposures), at least two per worker, one BLAS thread per worker (threaded BLAS on the renderer's small matrices
    spins); each worker makes the scene and the motion once per recording (:func:`_exposure_chunk`).
    """
    from joblib import Parallel, delayed, parallel_config

    n_chunks = min(times.shape[0], max(2 * workers, -(-times.shape[0] // 240)))
    with parallel_config(backend="loky", inner_max_num_threads=1):
        return Parallel(n_jobs=workers, return_as="generator")(
            delayed(_exposure_chunk)(config, chunk) for chunk in np.array_split(times, n_chunks))


def _collect_frames(pending: Iterator[np.ndarray], config: SimulationConfig, times: np.ndarray, rng: np.random.Generator,
                    progress: bool) -> np.ndarray:
    """Return the (F, H, W) uint8 APS frames of :func:`render_aps_frames` from the workers' exposures.

    The exposures (the costly, noise-free part: one scene render per sub-frame of the motion blur) are taken in
    order, and the sensor noise is drawn here from ``rng`` frame after frame, as :func:`render_aps_frames` draws
    it: the frames are bit-identical to the serial ones.
    """
    frames = np.empty((times.shape[0], config.camera.height, config.camera.width), dtype=np.uint8)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=times.shape[0], desc="APS frames (worker processes)", unit="frame")
    i = 0
    for exposures in pending:
        for exposure in exposures:
            frames[i] = aps_sensor_response(exposure, config.aps, rng)
            i += 1
        if bar is not None:
            bar.update(exposures.shape[0])
    if bar is not None:
        bar.close()
    return frames


def _settings(config: SimulationConfig) -> dict:
    """Return the config's fields as a dict, without ``speed`` when it is 1 (the preset's own motion): the digests of
    the recordings simulated before the field existed stay what they were."""
    settings = asdict(config)
    if settings["speed"] == 1.0:
        del settings["speed"]
    return settings


def _settings_digest(settings: dict, length: int) -> str:
    """Return the first ``length`` hex digits of the SHA-1 of the settings as sorted JSON (arrays as lists)."""
    text = json.dumps(settings, sort_keys=True, default=lambda value: np.asarray(value).tolist())
    return hashlib.sha1(text.encode("utf-8")).hexdigest()[:length]


def recording_settings_digest(config: SimulationConfig) -> str:
    """Return 8 hex digits that name every setting of a simulated recording but which sensors were simulated.

    Cached preset recordings carry it in their file names, so that a recording made with other settings (e.g. the
    APS noise of the simulator before it was matched to the real camera, CHANGELOG.md) is never read back as if it
    were current; the events and the
    frames-only recordings of one setting share it (a recording with events also serves a run that needs only the
    frames).
    """
    return _settings_digest(_settings(dataclasses.replace(config, with_events=True, with_frames=True)), 8)


def simulation_cache_path(config: SimulationConfig) -> Path:
    """Return the cache file of ``config``'s recording: ``<cache>/sequences/<preset>_<sha1 of the config>.npz``.

    The cache folder is the project's one (``$EVIO_CACHE_DIR``, else ``data/cache``, git-ignored). The name hashes
    every field of the config (the camera, extrinsics and sensor settings included, arrays at full precision), so
    two configs share a file only when they are equal, and equal configs give equal recordings (every random
    stream is seeded by the config).
    """
    from evio_lib.io.cache import default_cache_dir  # the project's one cache folder

    return default_cache_dir() / "sequences" / f"{config.preset}_{_settings_digest(_settings(config), 16)}.npz"


def simulate_sequence_cached(config: SimulationConfig, progress: bool = False, jobs: int | None = None) -> Sequence:
    """Return :func:`simulate_sequence` of ``config``, read from :func:`simulation_cache_path` when it was made before.

    The first call simulates and stores the recording whole (a temporary file renamed into place); a damaged cache
    file is said, deleted and simulated again. ``metadata["timings"]`` (deterministic counts) comes back as stored.
    ``jobs``: as in :func:`simulate_sequence` (None: :func:`default_jobs`; the recording does not depend on it).
    """
    from evio_lib.io.cache import check_cache_file_writable, load_cached_sequence, store_sequence_npz

    jobs = None if jobs is None else check_jobs(jobs)  # refused even when the recording is in the cache

    path = simulation_cache_path(config)
    cached = load_cached_sequence(path)  # None: not there, or damaged (said, deleted, simulated again)
    if cached is not None:
        return cached
    check_cache_file_writable(path)
    sequence = simulate_sequence(config, progress=progress, jobs=jobs)
    store_sequence_npz(sequence, path)
    return sequence
