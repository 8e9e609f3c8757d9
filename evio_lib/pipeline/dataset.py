"""What ``python -m evio_lib run DATASET`` reads: a simulated preset, an ECD or EuRoC ASL folder, an AEDAT4 file.

:func:`load_dataset` turns the DATASET argument into a :class:`LoadedDataset`: the :class:`~evio_lib.sequence.Sequence`
plus the camera-IMU extrinsics and IMU noise model the filter needs, and notes saying where each came from.

- A preset name (``boxes_like``, ``aerial_like``) is simulated on first use and cached as ``.npz`` under the project's
  cache folder (``io.cache.default_cache_dir() / "sequences"``), keyed by preset, duration, seed,
  start, a digest of every other setting (:func:`evio_lib.sim.presets.recording_settings_digest`: the sensor models)
  and whether events were simulated; the sidecar knows the extrinsics and the IMU noise exactly.
- An ECD folder (``events.txt`` [+ ``images.txt``, ``imu.txt``, ``calib.txt``, ``groundtruth.txt``]): extrinsics from
  the evio sidecar when present, else camera = IMU frame (the DAVIS chip's own IMU; about a centimetre off in reality),
  said in the notes. IMU noise from the sidecar, else the DAVIS's MPU-6150 model of :class:`ImuNoiseParams`.
- A EuRoC ASL folder (``mav0/`` or the ``mav0`` folder itself): extrinsics and noise from the ``sensor.yaml`` files.
- An AEDAT4 file (``.aedat4``, e.g. a DAVIS346): events, APS frames and IMU (g and deg/s converted to m/s^2 and
  rad/s). It holds no calibration: ``calib=`` (``--calib FILE``, the ECD ``calib.txt`` format) is required, and
  refused when missing, never guessed. Extrinsics camera = IMU frame (the DAVIS's own IMU, as for the ECD), noise the
  MPU-6150 model, no ground truth (the run starts static and reports no error metrics); all said in the notes.

Every recording's IMU is checked by :func:`evio_lib.io.imu_checks.check_imu_units` (accelerometer in g, gyro in deg/s,
swapped columns, gravity on an axis the ground truth contradicts), and stored noise densities that are negative or
NaN are refused, never replaced by defaults (defaults for missing ones are named in the notes).

- A ROS bag (a ROS1 ``.bag`` file or a ROS2 bag folder, :mod:`evio_lib.io.rosbag`): topics found by message type,
  ``topics=`` (``--topics``) picks among several (a stereo rig) or names a dataset's preset; the camera from its
  CameraInfo topic, else ``calib=`` (required then, as for AEDAT4).
- An HDF5 file (``.h5``, ``.hdf5``: DSEC, TUM-VIE, MVSEC layouts, :mod:`evio_lib.io.hdf5`): no layout holds a
  calibration, so ``calib=`` is required for a run; DSEC and TUM-VIE files hold no IMU (refused by ``run``).
  Bags and HDF5 files keep their events on disk (a memory-mapped ``.npy`` in the cache), read a window at a time.

``extrinsics=PATH`` (a Kalibr camchain YAML with ``T_cam_imu``) overrides every source of extrinsics.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from evio_lib.io.errors import DataFileError
from evio_lib.io.imu_checks import ImuUnitsError, check_imu_units
from evio_lib.sequence import Sequence
from evio_lib.sim.imu import ImuNoiseParams

__all__ = ["PRESETS", "PRESET_DURATIONS", "preset_length", "check_speed", "LoadedDataset", "load_dataset", "simulate_preset", "read_kalibr_extrinsics",
           "sequence_cache_dir"]

PRESETS = ("boxes_like", "aerial_like")
#: Default length of each preset's motion and recording, seconds (the thesis's sequences: 60 s boxes, 40 s aerial).
PRESET_DURATIONS = {"boxes_like": 60.0, "aerial_like": 40.0}


@dataclass(frozen=True)
class LoadedDataset:
    """A recording ready for the pipeline.

    Attributes:
        sequence: the recording (frames, events, IMU, ground truth, camera).
        kind: 'preset', 'ecd', 'euroc', 'aedat4', 'rosbag', 'hdf5' or 'cache' (a folder with sequence.npz).
        source: the preset name or the folder read.
        R_CtoI, p_CinI: camera-IMU extrinsics used (x_I = R_CtoI x_C + p_CinI).
        noise: IMU noise densities for the filter.
        notes: one line per assumption made (e.g. "extrinsics: camera = IMU frame").
    """

    sequence: Sequence
    kind: str
    source: str
    R_CtoI: np.ndarray
    p_CinI: np.ndarray
    noise: ImuNoiseParams
    notes: tuple[str, ...]


def sequence_cache_dir() -> Path:
    """Return the folder of cached simulated recordings (``default_cache_dir() / "sequences"``)."""
    from evio_lib.io.cache import default_cache_dir

    return default_cache_dir() / "sequences"


def preset_length(preset: str, speed: float = 1.0) -> float:
    """Return the length of a preset's whole motion played ``speed`` times faster, seconds (60 s boxes_like and 40 s
    aerial_like at speed 1)."""
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {PRESETS}; got {preset!r}")
    return PRESET_DURATIONS[preset] / check_speed(speed)


def check_speed(value: Any) -> float:
    """Return ``value`` as a playback speed of a preset's motion, or raise ValueError: a number in
    [``MIN_SPEED``, ``MAX_SPEED``] (:class:`evio_lib.sim.presets.SimulationConfig`)."""
    from evio_lib.sim.presets import MAX_SPEED, MIN_SPEED

    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(value) and MIN_SPEED <= value <= MAX_SPEED):
        raise ValueError(f"speed must be a number in [{MIN_SPEED:g}, {MAX_SPEED:g}] (how many times faster than the "
                         f"preset its motion is played); got {value!r}")
    return float(value)


def _speed_words(speed: float) -> str:
    return "" if speed == 1.0 else f" played at speed {speed:g}"


def check_preset_duration(preset: str, duration: Any, speed: float = 1.0) -> float:
    """Return ``duration`` as a float, or raise ValueError unless it lies in (0, the preset's length] seconds (at
    ``speed``: the preset's length / speed)."""
    full = preset_length(preset, speed)
    try:
        value = float(duration)
    except (TypeError, ValueError):
        raise ValueError(f"duration of {preset} must be a number of seconds in (0, {full:g}]; got {duration!r}") from None
    if not np.isfinite(value) or value <= 0 or value > full:
        raise ValueError(f"duration of {preset} must be in (0, {full:g}] s (the preset's whole motion"
                         f"{_speed_words(speed)}); got {duration!r}")
    return value


def check_preset_start(preset: str, start: float, speed: float = 1.0) -> float:
    """Return ``start`` as a float in [0, the preset's length at ``speed``), or raise ValueError naming the span."""
    full = preset_length(preset, speed)
    try:
        value = float(start)
    except (TypeError, ValueError):
        raise ValueError(f"start of {preset} must be a number of seconds in [0, {full:g}); got {start!r}") from None
    if not np.isfinite(value) or value < 0 or value >= full:
        raise ValueError(f"start of {preset} must be in [0, {full:g}) s (where in the preset's motion"
                         f"{_speed_words(speed)} the stretch begins); got {start!r}")
    return value


def simulate_preset(preset: str, duration: float | None = None, seed: int = 0, with_events: bool = False,
                    cache: bool = True, progress: bool = False, jobs: int | None = None, start: float = 0.0,
                    aps_exposure_s: float | None = None, speed: float = 1.0) -> Sequence:
    """Return the simulated recording of a preset: ``duration`` s of its full motion from ``start`` (cached as .npz).

    The motion is always the preset's whole trajectory (60 s boxes_like: gentle start, violent end; 40 s
    aerial_like), so a shorter duration is the start of the same recording, not a faster one; ``start`` > 0 takes a
    later stretch of the same motion (e.g. the violent end of boxes_like: ``start=50, duration=10``). ``jobs``:
    processes that render the APS frames (``simulate_sequence``; the result does not depend on it); None:
    ``evio_lib.sim.jobs.default_jobs()``, ``EVIO_JOBS`` or one per core, at most 4. ``aps_exposure_s``: the APS
    frames' exposure time T (:class:`evio_lib.sim.aps.ApsParams`; None: the simulator's 10 ms), at most one frame
    interval. It changes the frames' blur and their times (the middle of each exposure, T/2 + k/24 s), and the
    recording's cache name (another T is another recording); the events, the IMU and the ground truth stay the same,
    so a recording with events and another T is the default recording's events with frames simulated for T (cached
    frames-only), unless a whole recording for T is in the cache already. ``speed``: the preset's motion played this
    many times faster (:class:`evio_lib.sim.trajectory.TimeScaledTrajectory`; rates x speed, accelerations x
    speed^2); ``start`` and ``duration`` are then seconds of the faster motion, whose whole lasts the preset's length
    / speed (boxes_like at speed 2: 30 s, its violent end from about 24 s).
    """
    from evio_lib.sim.jobs import check_jobs

    jobs = None if jobs is None else check_jobs(jobs)  # refused even when the recording is in the cache
    from evio_lib.io.cache import check_cache_file_writable, load_cached_sequence, store_sequence_npz
    from evio_lib.sim.presets import SimulationConfig, recording_settings_digest, simulate_sequence

    speed = check_speed(speed)
    full = preset_length(preset, speed)
    start = check_preset_start(preset, start, speed)
    duration = check_preset_duration(preset, (full - start) if duration is None else duration, speed)
    if start + duration > full + 1e-9:
        raise ValueError(f"the stretch [{start:g}, {start + duration:g}] s of {preset} ends after its motion"
                         f"{_speed_words(speed)} (0-{full:g} s); use a duration of at most {full - start:g} s from "
                         f"{start:g} s")
    config = SimulationConfig(preset=preset, duration=duration, trajectory_duration=full, seed=seed,
                              with_events=with_events, start_time=start, speed=speed)
    if aps_exposure_s is not None:
        config = dataclasses.replace(config, aps=dataclasses.replace(
            config.aps, exposure_s=check_aps_exposure(aps_exposure_s, config.frame_rate_hz)))
    stem = sequence_cache_dir() / (f"{preset}_d{duration:g}_seed{seed}" + (f"_start{start:g}" if start else "")
                                   + (f"_speed{speed:g}" if speed != 1.0 else "")
                                   + f"_m{recording_settings_digest(config)}")
    path = stem.with_name(stem.name + ("_events.npz" if with_events else "_frames.npz"))
    # a recording simulated with events also serves a run that needs only the frames (the same seed gives the same
    # frames, IMU and ground truth with or without events)
    candidates = [path] if with_events else [path, stem.with_name(stem.name + "_events.npz")]
    for found in candidates if cache else ():
        sequence = load_cached_sequence(found)  # None: not there, or damaged (said, deleted, simulated again)
        if sequence is not None:
            return sequence
    if cache and with_events and config.aps != SimulationConfig().aps:
        # The events, the IMU and the ground truth do not depend on the APS settings (their own random streams):
        # the default recording's (cached, or simulated once for every exposure) with this exposure's frames, cached
        # frames-only, instead of a second events file of about 2 GB for the whole room.
        events = simulate_preset(preset, duration, seed, with_events=True, progress=progress, jobs=jobs, start=start,
                                 speed=speed)
        frames = simulate_preset(preset, duration, seed, with_events=False, progress=progress, jobs=jobs, start=start,
                                 aps_exposure_s=config.aps.exposure_s, speed=speed)
        return dataclasses.replace(events, frames=frames.frames, frame_times=frames.frame_times,
                                   metadata={**events.metadata, "config": frames.metadata["config"]})
    if cache:  # before the simulation (seconds to minutes): a cache that cannot be written is said now
        check_cache_file_writable(path)
    sequence = simulate_sequence(config, progress=progress, jobs=jobs)
    if cache:
        store_sequence_npz(sequence, path)
    return sequence


def check_aps_exposure(value: Any, frame_rate_hz: float = 24.0) -> float:
    """Return ``value`` as an APS exposure time in seconds, or raise ValueError: a number in (0, 1 / frame_rate_hz]
    (a frame cannot be exposed for longer than the interval between frames)."""
    longest = 1.0 / frame_rate_hz
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(value) and 0 < value <= longest):
        shown = math.floor(longest * 1e5) / 1e5  # rounded down, so that the bound shown is itself accepted
        raise ValueError(f"aps_exposure_s must be a number of seconds > 0 and at most one frame interval, "
                         f"1/{frame_rate_hz:g} s ({shown:.5f}); got {value!r}")
    return float(value)


def read_kalibr_extrinsics(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Return (R_CtoI, p_CinI) from a Kalibr-style YAML holding ``T_cam_imu`` (4 x 4, x_C = T_cam_imu x_I).

    Accepted: a camchain file (``cam0: T_cam_imu: [[...], ...]``) or a file with a top-level ``T_cam_imu``.
    T_CtoI = T_cam_imu^-1: R_CtoI = R^T, p_CinI = -R^T t.
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"extrinsics file not found: {path} (expected a Kalibr YAML with T_cam_imu)")
    try:
        content: Any = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as error:
        raise DataFileError(f"{path}: not a readable YAML file ({str(error).splitlines()[0]})") from None
    node = None
    if isinstance(content, dict):
        node = content.get("T_cam_imu")
        if node is None:
            cams = [v for k, v in sorted(content.items()) if isinstance(v, dict) and "T_cam_imu" in v]
            node = cams[0]["T_cam_imu"] if cams else None
    if node is None:
        raise DataFileError(f"{path}: no T_cam_imu found (expected 'T_cam_imu:' or 'cam0: T_cam_imu:' with a 4 x 4 "
                            f"matrix, Kalibr's camchain format)")
    try:
        T = np.asarray(node, dtype=np.float64)
    except (TypeError, ValueError):
        T = np.zeros(0)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise DataFileError(f"{path}: T_cam_imu must be a 4 x 4 matrix of numbers; got {node!r}"[:300])
    R, t = T[:3, :3], T[:3, 3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise DataFileError(f"{path}: the rotation block of T_cam_imu is not a rotation (R R^T != I or det < 0)")
    return R.T.copy(), -R.T @ t


def _noise_from_metadata(metadata: dict, source: str) -> tuple[ImuNoiseParams | None, list[str]]:
    """Return (the IMU noise stored in a recording's metadata, or None; the names that took their defaults).

    Simulator names or Kalibr names. A stored value that is negative, NaN or no number is refused (ValueError
    naming it), never replaced by the default: the filter would otherwise run with another noise model than the
    recording states. Values the metadata lacks take the defaults of :class:`ImuNoiseParams`, and the caller says so.
    """
    from evio_lib.io.imu_checks import check_noise_values

    noise = metadata.get("imu_noise") if isinstance(metadata, dict) else None
    if not isinstance(noise, dict):
        return None, []
    kalibr = {"gyroscope_noise_density": "gyro_noise_density", "accelerometer_noise_density": "accel_noise_density",
              "gyroscope_random_walk": "gyro_random_walk", "accelerometer_random_walk": "accel_random_walk"}
    fields = ImuNoiseParams.__dataclass_fields__
    stored = {k: v for k, v in noise.items() if kalibr.get(k, k) in fields}
    values = {kalibr.get(k, k): v for k, v in check_noise_values(stored, f"{source}: IMU noise").items()}
    missing = [name for name in ("gyro_noise_density", "accel_noise_density", "gyro_random_walk", "accel_random_walk")
               if name not in values]
    return ImuNoiseParams.from_dict(values), missing


#: How the messages name a recording's two ground truths (camera poses, IMU states), by kind.
_TRUTH_FILES = {"preset": ("the simulated camera ground truth", "the simulated IMU ground truth"),
                "ecd": ("groundtruth.txt", "groundtruth_imu.txt"),
                "euroc": ("the ground truth", "the ground truth (state_groundtruth_estimate0/data.csv)"),
                "aedat4": ("the ground truth", "the ground truth"),
                "rosbag": ("the pose topic", "the pose topic"),
                "cache": ("the ground truth of sequence.npz", "the IMU ground truth of sequence.npz"),
                "hdf5": ("the ground truth (pose, pose_ts)", "the ground truth (pose, pose_ts)"),
                "sequence": ("the Sequence's groundtruth", "the Sequence's groundtruth_imu")}
#: File suffixes of HDF5 recordings.
HDF5_SUFFIXES = (".h5", ".hdf5")


def _check_truth_times(gt: Any, imu_t: np.ndarray, name: str) -> None:
    """Refuse a ground truth that cannot score or initialise a run: under 2 poses, or no time shared with the IMU.

    Raises ValueError naming the file, what it holds and what is expected (its times against the IMU's, which
    catches a truth on another clock or in other units: ns against s).
    """
    if gt is None:
        return
    n = len(gt.t)
    if n < 2:
        raise ValueError(f"{name} holds {n} pose{'' if n == 1 else 's'}; a ground truth needs at least 2 (lines "
                         f"t px py pz qx qy qz qw over the recording): complete it, or remove it to run without "
                         f"ground truth (static start, no error metrics)")
    t0, t1 = float(gt.t[0]), float(gt.t[-1])
    i0, i1 = float(imu_t[0]), float(imu_t[-1])
    if t1 < i0 or t0 > i1:
        raise ValueError(f"{name} covers [{t0:.6g}, {t1:.6g}] s and the IMU [{i0:.6g}, {i1:.6g}] s: they share no "
                         f"time, so the ground truth is on another clock or in other units (both must be seconds on "
                         f"the sensor's clock)")
    # Both starting near 0 they overlap whatever the unit. A ground truth spanning hundreds of times the IMU's time
    # with under one pose per second inside it is in ms, us or ns (a 200 Hz truth in ns: poses 5e6 "s" apart); the
    # unit is the one that gives its poses a rate of 1 Hz - 2 kHz
    step, span, imu_span = float(np.median(np.diff(gt.t))), t1 - t0, i1 - i0
    inside = int(np.count_nonzero((gt.t >= i0) & (gt.t <= i1)))
    if imu_span > 0 and span >= 300.0 * imu_span and inside < imu_span and step > 0:
        units = [unit for scale, unit in ((1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds"))
                 if 1.0 <= scale / step <= 2000.0]
        guess = f"its times look like {units[0]}" if units else "its times are not seconds on the IMU's clock"
        raise ValueError(f"{name} covers [{t0:.6g}, {t1:.6g}] s with poses {step:.6g} s apart ({inside} within the "
                         f"IMU's [{i0:.6g}, {i1:.6g}] s): {guess}; write them in seconds on the sensor's clock")


def _is_bag_or_h5(text: str) -> bool:
    """Return True for a ROS bag (``.bag`` file, ROS2 folder) or an HDF5 file (``.h5``, ``.hdf5``)."""
    from evio_lib.io.rosbag import is_rosbag

    path = Path(text)
    return (path.is_file() and path.suffix.lower() in HDF5_SUFFIXES) or is_rosbag(path)


def _is_euroc(folder: Path) -> bool:
    return (folder / "mav0").is_dir() or (folder.name == "mav0" and (folder / "imu0").is_dir())


def _motion_speed(seq: Any, kind: str, speed: float | None) -> float:
    """Return how many times faster than people and vehicles the recording's motion plays: a preset's ``speed``, a
    simulated Sequence's ``metadata["speed"]``, else 1 (the IMU checks scale their bounds with it)."""
    if kind == "preset":
        return 1.0 if speed is None else float(speed)
    if kind == "sequence" and isinstance(seq.metadata, dict):
        return float(seq.metadata.get("speed") or 1.0)
    return 1.0


def load_dataset(dataset: "str | Path | Sequence | None" = None, *, duration: float | None = None, seed: int = 0,
                 need_events: bool = False, need_frames: bool = True, extrinsics: str | Path | None = None,
                 progress: bool = False, calib: str | Path | None = None, start: float = 0.0,
                 aps_exposure_s: float | None = None, speed: float | None = None,
                 topics: str | None = None) -> LoadedDataset:
    """Return the recording named by ``dataset`` (a preset name, a folder or a file; None: ``boxes_like``).

    Args:
        dataset: a :class:`~evio_lib.sequence.Sequence` in memory (e.g. from
            :func:`evio_lib.sim.presets.simulate_sequence`; checked like a recording read from disk), or
            'boxes_like', 'aerial_like', an ECD folder, a EuRoC ASL folder or an AEDAT4 file (``.aedat4``:
            events, APS frames and IMU, converted from g and deg/s; no ground truth, so the run starts static).
        duration: presets only: seconds simulated (default: the preset's whole 60 / 40 s, or what is left after
            ``start``).
        start: presets only: where in the preset's motion the simulated stretch begins, s (default 0).
        aps_exposure_s: presets only: the APS frames' exposure time, s (None: the simulator's 10 ms;
            :func:`simulate_preset`).
        speed: presets only: the preset's motion played this many times faster (None: 1, the preset itself);
            ``duration`` and ``start`` are seconds of the faster motion (:func:`simulate_preset`).
        seed: presets only: the simulation seed.
        need_events, need_frames: what the run uses (a preset is simulated with events only when needed; a folder
            without them is refused with a message saying what is missing).
        extrinsics: a Kalibr YAML with T_cam_imu overriding the recording's extrinsics.
        progress: show the simulator's progress bars.
        calib: a calibration file in the ECD ``calib.txt`` format (``fx fy cx cy k1 k2 p1 p2 [k3]``): required for
            an AEDAT4 file, an HDF5 file and a bag without a CameraInfo topic (they hold none), overrides the
            calibration of a folder or a bag; refused for a preset.
        topics: ROS bags: a preset of :data:`evio_lib.io.rosbag.TOPIC_PRESETS` or ``role=/topic`` pairs; MVSEC HDF5
            files: the camera group (``davis/left``); refused for other recordings.

    The IMU of every recording goes through :func:`evio_lib.io.imu_checks.check_imu_units` (units, swapped columns,
    gravity against the ground truth).

    Raises ValueError (DataFileError) naming what is missing or malformed.

    The steps, in order: the options against the kind of ``dataset`` (:func:`_check_dataset_options`); the reading
    (:func:`_load_preset`, :func:`_read_bag_or_hdf5`, :func:`_read_aedat4_file`, :func:`_read_folder`); ``calib``;
    the checks of the IMU, the ground truth's times and the camera; the extrinsics (:func:`_extrinsics`); the IMU's
    units against them (:func:`_check_imu_against_truth`); the frames and events the run needs; the IMU noise.
    """
    notes: list[str] = []
    dataset = "boxes_like" if dataset is None else dataset
    given, text = _check_dataset_options(dataset, duration=duration, start=start, aps_exposure_s=aps_exposure_s,
                                         speed=speed, topics=topics)
    if given:                                         # a shallow copy: --calib below never changes the caller's
        seq, kind, source = dataclasses.replace(dataset), "sequence", dataset.name
    elif text in PRESETS:
        seq, kind, source = _load_preset(text, duration=duration, seed=seed, need_events=need_events,
                                         progress=progress, calib=calib, start=start, aps_exposure_s=aps_exposure_s,
                                         speed=speed, notes=notes)
    elif _is_bag_or_h5(text):
        seq, kind, source = _read_bag_or_hdf5(text, duration=duration, need_events=need_events,
                                              need_frames=need_frames, calib=calib, topics=topics, notes=notes)
    elif Path(text).is_file() and Path(text).suffix.lower() == ".aedat4":
        seq, kind, source = _read_aedat4_file(text, duration=duration, need_frames=need_frames, calib=calib,
                                              notes=notes)
    else:
        seq, kind, source = _read_folder(text, duration=duration, need_events=need_events, need_frames=need_frames)
    if calib is not None:
        _replace_camera(seq, calib, kind, source, notes)
    _check_imu_truth_and_camera(seq, kind, source)
    R_CtoI, p_CinI = _extrinsics(seq, kind, extrinsics, notes)
    _check_imu_against_truth(seq, kind, source, R_CtoI, assumed=extrinsics is None and seq.R_CtoI is None,
                             speed=speed)
    if need_frames and len(seq.frame_times) < 2:
        where = {"euroc": " (mav0/cam0/data.csv)", "ecd": " (images.txt)"}.get(kind, "")
        advice = {"euroc": "a EuRoC recording holds no events to make frames from; it needs the images of mav0/cam0",
                  "preset": "a longer --duration gives it more (24 a second)"}.get(
            kind, "use --frames events or mc-events, or a recording with frames")
        raise ValueError(f"{source} has fewer than 2 frames{where}: {advice}")
    if need_events and len(seq.events) == 0:
        raise ValueError(f"{source} has no events (events.txt is empty): use --frames aps")
    noise = _imu_noise(seq.metadata, source, notes)
    return LoadedDataset(sequence=seq, kind=kind, source=source, R_CtoI=R_CtoI, p_CinI=p_CinI, noise=noise,
                         notes=tuple(notes))


# ---------------------------------------------------------------------------------------------- load_dataset's steps
def _check_dataset_options(dataset: Any, *, duration: float | None, start: float, aps_exposure_s: float | None,
                           speed: float | None, topics: str | None) -> tuple[bool, str]:
    """Return (given, text): whether ``dataset`` is a Sequence in memory, and the name the checks read ("" for a
    Sequence). Refuse the options that do not apply to it (presets-only options for a recording, ``topics`` for
    anything but a bag or an MVSEC file) and a preset name that is also a path, before anything is read."""
    given = isinstance(dataset, Sequence)
    if given:                                        # a recording in memory (simulate_sequence, a reader, a slice)
        for option, value in (("duration", duration), ("start", start), ("aps_exposure_s", aps_exposure_s),
                              ("speed", speed), ("topics", topics)):
            if value:
                raise ValueError(f"{option} applies to presets and recordings on disk; a Sequence is used as it is "
                                 f"(cut it with sequence.slice_time(t0, t1))")
    elif not isinstance(dataset, (str, Path)):
        raise TypeError(f"dataset must be a preset name, a recording's path or a Sequence; got "
                        f"{type(dataset).__name__}")
    text = dataset.name if given else str(dataset)
    if given:
        text = ""                                     # none of the name checks below applies
    if start and text not in PRESETS:
        raise ValueError("--start applies to simulated presets; a recording is processed from its beginning")
    if aps_exposure_s is not None and text not in PRESETS and Path(text).exists():  # else: 'neither a preset ...'
        raise ValueError("--aps-exposure applies to simulated presets; a recording's frames were exposed when it "
                         "was recorded")
    if speed is not None and text not in PRESETS and Path(text).exists():
        raise ValueError("--speed applies to simulated presets; a recording's motion is the one it was recorded with")
    if topics is not None and not _is_bag_or_h5(text):
        raise ValueError("--topics applies to ROS bags and MVSEC HDF5 files (which hold several cameras); "
                         f"{text} is neither")
    if text in PRESETS and Path(text).exists() and not given:
        raise ValueError(f"DATASET {text!r} names both the simulated preset and the {'folder' if Path(text).is_dir() else 'file'} "
                         f"{Path(text).resolve()}; write ./{text} for the recording, or run from another folder for "
                         f"the preset")
    return given, text


def _load_preset(text: str, *, duration: float | None, seed: int, need_events: bool, progress: bool,
                 calib: Any, start: float, aps_exposure_s: float | None, speed: float | None,
                 notes: list[str]) -> tuple[Sequence, str, str]:
    """Return (sequence, 'preset', name) of the preset ``text``, simulated or from the cache (:func:`simulate_preset`);
    ``notes`` get a non-default exposure and speed."""
    if calib is not None:
        raise ValueError(f"--calib applies to recordings; the preset {text} knows its camera")
    seq = simulate_preset(text, duration, seed, with_events=need_events, progress=progress, start=start,
                          aps_exposure_s=aps_exposure_s, speed=1.0 if speed is None else speed)
    if aps_exposure_s is not None:
        notes.append(f"APS exposure {1e3 * aps_exposure_s:g} ms (the simulator's default: 10 ms)")
    if speed is not None and speed != 1.0:
        notes.append(f"motion: the preset's played at speed {speed:g} (rates x {speed:g}, accelerations x "
                     f"{speed * speed:g}; its whole motion lasts {preset_length(text, speed):g} s)")
    return seq, "preset", text


def _read_bag_or_hdf5(text: str, *, duration: float | None, need_events: bool, need_frames: bool, calib: Any,
                      topics: str | None, notes: list[str]) -> tuple[Sequence, str, str]:
    """Return (sequence, 'hdf5' or 'rosbag', path) of an HDF5 file or a ROS bag; refuse one without a camera when
    no ``calib`` is given. ``notes`` get the topics read and where the ground truth comes from."""
    if duration is not None:
        raise ValueError("--duration applies to simulated presets; for a recording use --max-duration")
    if Path(text).suffix.lower() in HDF5_SUFFIXES:
        from evio_lib.io.hdf5 import read_hdf5

        seq, kind = read_hdf5(text, load_events=need_events, load_frames=need_frames, group=topics), "hdf5"
        missing = "no calibration in the file"
    else:
        from evio_lib.io.rosbag import read_rosbag

        seq, kind = read_rosbag(text, load_events=need_events, load_frames=need_frames, topics=topics), "rosbag"
        missing = "no sensor_msgs/CameraInfo topic in the bag"
        notes.append("topics: " + ", ".join(f"{role} {topic}" for role, topic in seq.metadata["topics"].items()))
    source = text
    if seq.camera is None and calib is None:
        raise ValueError(f"{text}: {missing}; give one with --calib FILE (one line fx fy cx cy k1 k2 p1 p2 [k3] "
                         f"in pixels, the ECD calib.txt format)")
    if seq.groundtruth is None:
        notes.append(f"ground truth: none in the {'bag' if kind == 'rosbag' else 'file'}: static "
                     f"initialisation (the sensor must start still), no error metrics")
    else:
        notes.append("ground truth: " + ("the pose topic, taken as the camera's pose in the world"
                                         if kind == "rosbag" else "pose (camera-to-world matrices)"))
    return seq, kind, source


def _read_aedat4_file(text: str, *, duration: float | None, need_frames: bool, calib: Any,
                      notes: list[str]) -> tuple[Sequence, str, str]:
    """Return (sequence, 'aedat4', path) of an AEDAT4 file, which holds no calibration: ``calib`` is required."""
    from evio_lib.io.aedat4 import read_aedat4

    if duration is not None:
        raise ValueError("--duration applies to simulated presets; for a recording use --max-duration")
    if calib is None:
        raise ValueError(f"{text}: an AEDAT4 recording holds no camera calibration; give one with --calib FILE "
                         f"(one line fx fy cx cy k1 k2 p1 p2 [k3] in pixels, the ECD calib.txt format, e.g. from "
                         f"a Kalibr or OpenCV calibration of this camera)")
    seq, kind, source = read_aedat4(text, load_frames=need_frames), "aedat4", text
    notes.append("IMU units: " + str(seq.metadata.get("imu_units", "none in the file")))
    notes.append("ground truth: none in an AEDAT4 file: static initialisation (the sensor must start still), "
                 "no error metrics")
    return seq, kind, source


def _read_folder(text: str, *, duration: float | None, need_events: bool,
                 need_frames: bool) -> tuple[Sequence, str, str]:
    """Return (sequence, 'euroc', 'ecd' or 'cache', path) of a recording folder, by its layout; refuse a path that
    is no folder or a folder of no known layout."""
    if duration is not None:
        raise ValueError("--duration applies to simulated presets; for a recording folder use --max-duration")
    folder = Path(text)
    if not folder.exists():
        raise ValueError(f"DATASET {text!r} is neither a preset ({', '.join(PRESETS)}) nor an existing folder")
    if not folder.is_dir():
        raise ValueError(f"DATASET {text!r} is a file; expected a preset name, an ECD folder (events.txt, imu.txt, "
                         f"...), a EuRoC ASL folder (mav0/), an AEDAT4 file (.aedat4), a ROS bag (.bag, or a ROS2 "
                         f"bag folder) or an HDF5 file (.h5, .hdf5)")
    if _is_euroc(folder):
        from evio_lib.io.euroc import read_euroc

        if need_events:
            raise ValueError(f"{folder} is a EuRoC folder: it has no events; use --frames aps")
        seq, kind = read_euroc(folder, load_frames=need_frames), "euroc"
    elif (folder / "events.txt").is_file():
        from evio_lib.io.ecd import read_ecd

        seq, kind = read_ecd(folder, load_events=need_events, load_frames=need_frames), "ecd"
    elif (folder / "sequence.npz").is_file():  # the binary cache (convert --format cache, simulate --cache)
        from evio_lib.io.cache import load_sequence_npz

        seq, kind = load_sequence_npz(folder / "sequence.npz"), "cache"
    else:
        raise ValueError(f"{folder} is not a recording folder: expected events.txt (ECD layout), mav0/ "
                         f"(EuRoC ASL layout) or sequence.npz (the binary cache)")
    return seq, kind, str(folder)


def _replace_camera(seq: Sequence, calib: Any, kind: str, source: str, notes: list[str]) -> None:
    """Set ``seq.camera`` from the calibration file ``calib`` (the ECD ``calib.txt`` format), checked against the
    sensor size."""
    from evio_lib.io.ecd import read_calib

    if seq.sensor_size is None:
        raise ValueError(f"{source}: the sensor size is unknown (no frames, no sidecar), so --calib cannot be "
                         f"checked against it")
    seq.camera = read_calib(calib, *seq.sensor_size)
    notes.append(f"camera: from --calib {calib}" + ("" if kind == "aedat4" else " (replaces the recording's)"))


def _check_imu_truth_and_camera(seq: Sequence, kind: str, source: str) -> None:
    """Refuse a recording without an IMU (two samples at least), with a ground truth that shares no time with the
    IMU, or without a camera calibration; each message names what is missing and where it would be."""
    if seq.imu is None or len(seq.imu.t) < 2:
        if kind == "hdf5":
            raise ValueError(f"{source}: the {seq.metadata['format']} layout holds no IMU, and the MSCKF needs one; "
                             f"its events still make frames (python -m evio_lib reconstruct {source} --out DIR) and "
                             f"an ECD folder (python -m evio_lib convert {source} --out DIR)")
        if kind == "rosbag":
            raise ValueError(f"{source} has no sensor_msgs/Imu topic (topics read: {seq.metadata['topics']}): the "
                             f"MSCKF needs the IMU")
        if seq.imu is not None and len(seq.imu.t) == 1:
            raise ValueError(f"{source} holds one IMU sample (imu.txt / mav0/imu0/data.csv): the MSCKF needs the IMU "
                             f"over the whole recording (at 100 Hz or more)")
        raise ValueError(f"{source} has no IMU samples (imu.txt / mav0/imu0/data.csv): the MSCKF needs the IMU")
    for gt, name in ((seq.groundtruth, _TRUTH_FILES[kind][0]), (seq.groundtruth_imu, _TRUTH_FILES[kind][1])):
        _check_truth_times(gt, seq.imu.t, f"{source}: {name}")
    if seq.camera is None:
        raise ValueError(f"{source} has no camera calibration (calib.txt / mav0/cam0/sensor.yaml): the front-end needs "
                         f"it to undistort the features")


def _extrinsics(seq: Sequence, kind: str, extrinsics: str | Path | None,
                notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Return (R_CtoI, p_CinI): from the ``extrinsics`` file, else from the recording, else camera = IMU frame;
    ``notes`` say which."""
    if extrinsics is not None:
        R_CtoI, p_CinI = read_kalibr_extrinsics(extrinsics)
        notes.append(f"extrinsics: from {extrinsics}")
    elif seq.R_CtoI is not None and seq.p_CinI is not None:
        R_CtoI, p_CinI = np.asarray(seq.R_CtoI, float), np.asarray(seq.p_CinI, float)
        notes.append("extrinsics: from the recording (" + {"preset": "simulator", "ecd": "evio_sim.json",
                                                           "euroc": "sensor.yaml", "aedat4": "file", "rosbag": "bag",
                                                           "hdf5": "file", "cache": "sequence.npz",
                                                           "sequence": "Sequence"}[kind] + ")")
    else:
        R_CtoI, p_CinI = np.eye(3), np.zeros(3)
        notes.append("extrinsics: none in the recording; assumed camera = IMU frame (the DAVIS's own IMU); "
                     "give --extrinsics FILE if it differs")
    return R_CtoI, p_CinI


def _check_imu_against_truth(seq: Sequence, kind: str, source: str, R_CtoI: np.ndarray, assumed: bool,
                             speed: float | None) -> None:
    """Check the IMU's units and axes (:func:`~evio_lib.io.imu_checks.check_imu_units`) with the extrinsics the run
    will use (``assumed``: camera = IMU frame, for lack of any)."""
    truth = seq.groundtruth_imu if seq.groundtruth_imu is not None else seq.groundtruth
    gravity_G = seq.metadata.get("gravity_G") if isinstance(seq.metadata, dict) else None
    try:  # the readers checked already; presets, --extrinsics and the assumed extrinsics are checked here
        check_imu_units(seq.imu.t, seq.imu.gyro, seq.imu.accel, truth, source=f"{source} IMU", R_CtoI=R_CtoI,
                        gravity_G=gravity_G, speed=_motion_speed(seq, kind, speed))
    except ImuUnitsError as error:
        if not (assumed and truth is not None and truth.body == "camera"):
            raise
        # with a camera ground truth the check needs the rotation the run will use: a recording without extrinsics
        # whose IMU axes contradict its camera truth would run to a confident, wrong trajectory
        raise ImuUnitsError(f"{error} (the recording holds no camera-IMU extrinsics, so the check, like the run, "
                            f"took the camera frame as the IMU frame; if they differ, give the camera-IMU "
                            f"transformation with --extrinsics FILE, a Kalibr camchain with T_cam_imu)") from None


def _imu_noise(metadata: Any, source: str, notes: list[str]) -> ImuNoiseParams:
    """Return the IMU noise for the filter: the recording's (:func:`_noise_from_metadata`), else the DAVIS's
    MPU-6150 model; ``notes`` say which values were assumed."""
    noise, defaulted = _noise_from_metadata(metadata, source)
    if noise is None:
        noise = ImuNoiseParams()
        notes.append("IMU noise: not in the recording; assumed the DAVIS's MPU-6150 model (ImuNoiseParams defaults)")
    elif defaulted:
        notes.append(f"IMU noise: from the recording, except {', '.join(defaulted)}: not in it, assumed the DAVIS's "
                     f"MPU-6150 model (ImuNoiseParams defaults)")
    return noise
