"""Event frames against APS frames over short stretches of a simulated preset: speeds, exposures and seeds.

The thesis argues that event frames pay off where the APS frames blur (Friedel 2020, §4.5.1). How much a frame blurs
is, for a rotation, the distance a point near the image centre moves while the shutter is open:

    b = |ω| T f   [px]

with |ω| the angular rate, T the exposure and f the focal length in pixels. This module runs the pipeline over a
grid of short stretches (a :class:`Stretch` of a preset's motion, played at some speed) and APS exposures, and
returns one record per run with that blur beside the run's error, so that the error of event frames over the error
of APS frames can be set against b.

- :class:`Stretch`: where in a preset's motion, for how long and how fast; :meth:`Stretch.load` simulates it once
  (the recordings are cached by :func:`evio_lib.pipeline.load_dataset`; another exposure reuses the events).
- :func:`rotation_blur_px`: b of a recording's APS frames, from the bias-corrected gyroscope.
- :func:`stretch_record`: a run's flat record (stretch, seed, exposure, blur, errors); :func:`stretch_run`: one run
  of one configuration on one stretch, seed and exposure, as such a record.
- :func:`simulate_stretches`: simulate many recordings (stretches, seeds, exposures) side by side in worker
  processes, so that the runs read them from disk.
- :func:`run_stretches`: many runs spread over worker processes (joblib).
- :func:`error_ratios`: each (stretch, seed, exposure)'s error on event frames over its error on APS frames.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

import numpy as np

from evio_lib.pipeline.dataset import PRESETS, LoadedDataset, check_speed, load_dataset
from evio_lib.pipeline.run import PipelineConfig, run_pipeline

__all__ = ["Stretch", "rotation_blur_px", "stretch_record", "stretch_run", "simulate_stretches", "run_stretches",
           "error_ratios"]


@dataclasses.dataclass(frozen=True)
class Stretch:
    """A stretch of a simulated preset's motion: ``duration`` s from ``start`` s, played ``speed`` times faster.

    ``start`` and ``duration`` count seconds of the played motion (at speed 2 the whole 60 s room lasts 30 s), as
    :func:`evio_lib.pipeline.load_dataset` counts them. ``label`` names the stretch in records and tables.

    >>> Stretch("fast", start=24.0, duration=1.5, speed=2.0).preset
    'boxes_like'
    """

    label: str
    start: float
    duration: float
    speed: float = 1.0
    preset: str = "boxes_like"

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or not self.label:
            raise ValueError(f"label must be a non-empty name; got {self.label!r}")
        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {PRESETS}; got {self.preset!r}")
        for name in ("start", "duration"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < 0 or (name == "duration" and value == 0):
                raise ValueError(f"{name} must be a number of seconds {'>' if name == 'duration' else '>='} 0; "
                                 f"got {value!r}")
        object.__setattr__(self, "speed", check_speed(self.speed))

    def load(self, seed: int = 0, aps_exposure_s: float | None = None, need_events: bool = True) -> LoadedDataset:
        """Return the stretch simulated with ``seed`` (cached; ``aps_exposure_s`` None: the simulator's 10 ms)."""
        return load_dataset(self.preset, seed=seed, start=self.start, duration=self.duration,
                            speed=None if self.speed == 1.0 else self.speed, aps_exposure_s=aps_exposure_s,
                            need_events=need_events)


def rotation_blur_px(data: LoadedDataset, exposure_s: float) -> float:
    """Return the APS frames' mean rotation blur b = |ω| T f over a recording, pixels.

    |ω| is the gyroscope's rate with the true bias removed where the recording has a ground truth of the IMU (the
    simulated presets), averaged over every IMU sample; T is ``exposure_s``; f the camera's focal length in pixels
    (fx). It leaves out the translation's blur (f |v| / Z) and a roll's larger smear away from the image centre.

    >>> from types import SimpleNamespace as NS
    >>> imu = NS(t=np.array([0.0, 1.0]), gyro=np.array([[3.0, 0.0, 4.0], [3.0, 0.0, 4.0]]))
    >>> seq = NS(imu=imu, groundtruth_imu=None, camera=NS(fx=200.0))
    >>> rotation_blur_px(NS(sequence=seq), 0.01)    # 5 rad/s x 10 ms x 200 px
    10.0
    """
    if isinstance(exposure_s, bool) or not isinstance(exposure_s, (int, float, np.floating)) \
            or not (math.isfinite(exposure_s) and exposure_s > 0):
        raise ValueError(f"exposure_s must be a number of seconds > 0; got {exposure_s!r}")
    sequence = data.sequence
    imu = sequence.imu
    if imu is None or len(imu.t) == 0:
        raise ValueError("rotation_blur_px needs the recording's gyroscope; it has no IMU samples")
    gyro = np.asarray(imu.gyro, dtype=np.float64)
    truth = getattr(sequence, "groundtruth_imu", None)
    if truth is not None and getattr(truth, "bias_gyro", None) is not None:
        gyro = gyro - truth.interpolate(imu.t).bias_gyro
    return float(np.linalg.norm(gyro, axis=1).mean() * exposure_s * sequence.camera.fx)


def _exposure(data: LoadedDataset) -> float:
    """Return the APS exposure recorded in a simulated recording's metadata, s."""
    config = data.sequence.metadata.get("config", {}) if isinstance(data.sequence.metadata, dict) else {}
    return float(config.get("aps", {}).get("exposure_s"))


def stretch_record(stretch: Stretch, seed: int, data: LoadedDataset, result: Any) -> dict:
    """Return the flat record of a run (a :class:`~evio_lib.pipeline.run.PipelineResult`) on ``stretch``.

    The record: ``stretch``, ``speed``, ``seed``, ``frames`` (the run's frame source), ``exposure_ms`` (the
    recording's APS exposure), ``blur_px`` (:func:`rotation_blur_px` at that exposure), ``rate_rad_s`` (the mean
    bias-corrected angular rate), the run's ``rmse_m``, ``mean_error_m``, ``percent_of_distance`` and
    ``distance_m``, ``frames_per_second`` (frames the filter used per second of the stretch) and ``track_length``
    (mean, frames). A run made in a lesson with :func:`~evio_lib.pipeline.run_pipeline` and one made by
    :func:`stretch_run` give the same record.
    """
    exposure = _exposure(data)
    blur = rotation_blur_px(data, exposure)
    metrics = result.metrics
    lengths = np.asarray(result.track_lengths)
    return {"stretch": stretch.label, "speed": stretch.speed, "seed": int(seed), "frames": result.config.frames,
            "exposure_ms": round(1e3 * exposure, 6), "blur_px": blur,
            "rate_rad_s": blur / exposure / data.sequence.camera.fx,
            "rmse_m": float(metrics["rmse_m"]), "mean_error_m": float(metrics["mean_error_m"]),
            "percent_of_distance": float(metrics["percent_of_distance"]), "distance_m": float(metrics["distance_m"]),
            "frames_per_second": len(result.t) / stretch.duration,
            "track_length": float(lengths.mean()) if lengths.size else float("nan")}


def stretch_run(stretch: Stretch, seed: int, config: PipelineConfig, aps_exposure_s: float | None = None) -> dict:
    """Return one run of ``config`` (its RANSAC seeded with ``seed``) on ``stretch`` simulated with ``seed`` and
    that APS exposure, as :func:`stretch_record` makes it.

    The recording is read from the cache when :meth:`Stretch.load` has simulated it before.
    """
    if not isinstance(stretch, Stretch):
        raise ValueError(f"stretch must be a Stretch; got {type(stretch).__name__}")
    if not isinstance(config, PipelineConfig):
        raise ValueError(f"config must be a PipelineConfig; got {type(config).__name__}")
    data = stretch.load(seed, aps_exposure_s, need_events="events" in config.frames)
    return stretch_record(stretch, seed, data, run_pipeline(data, dataclasses.replace(config, seed=seed)))


def _simulate_one(stretch: Stretch, seed: int, aps_exposure_s: float | None) -> None:
    """Simulate one recording into the cache, in this process only (a worker of :func:`simulate_stretches`)."""
    import os

    os.environ["EVIO_JOBS"] = "1"  # the worker's own APS rendering stays in the worker: the workers share the cores
    stretch.load(seed, aps_exposure_s)


def simulate_stretches(recordings: Sequence[tuple[Stretch, int, float | None]], jobs: int | None = None) -> None:
    """Simulate every (stretch, seed, APS exposure) of ``recordings`` (with events) into the cache, side by side.

    First each stretch and seed with the simulator's own exposure (None), events included; then the other exposures,
    whose recordings reuse those events and simulate only their frames (:func:`evio_lib.pipeline.load_dataset`).
    The two rounds keep two workers from simulating the same events at once. A recording already in the cache is
    read, not simulated again; the recordings do not depend on ``jobs`` (as :func:`run_stretches`).
    """
    from evio_lib.sim.jobs import map_in_workers

    wanted = []
    for k, item in enumerate(recordings):
        if not (isinstance(item, tuple) and len(item) == 3 and isinstance(item[0], Stretch)):
            raise ValueError(f"recordings[{k}] must be (Stretch, seed, aps_exposure_s or None); got {item!r}")
        wanted.append(item)
    first = list(dict.fromkeys((stretch, seed, None) for stretch, seed, _ in wanted))
    second = list(dict.fromkeys(item for item in wanted if item[2] is not None))
    for round_ in (first, second):
        map_in_workers(_simulate_one, [dict(stretch=s, seed=seed, aps_exposure_s=e) for s, seed, e in round_], jobs)


def run_stretches(calls: Sequence[Mapping[str, Any]], jobs: int | None = None) -> list[dict]:
    """Return ``[stretch_run(**call) for call in calls]``, the runs spread over ``jobs`` worker processes.

    Simulate each recording first (:meth:`Stretch.load`, in this process): the workers then read it from the cache
    instead of simulating it twice. ``jobs``: as :func:`evio_lib.sim.jobs.map_in_workers` (None: one per core, at
    most 4). Every run is deterministic, so the records do not depend on ``jobs``.
    """
    from evio_lib.sim.jobs import map_in_workers

    calls = [dict(call) for call in calls]
    for k, call in enumerate(calls):
        missing = {"stretch", "seed", "config"} - set(call)
        if missing:
            raise ValueError(f"calls[{k}] lacks {sorted(missing)}; each call holds stretch, seed, config and "
                             f"optionally aps_exposure_s")
    return map_in_workers(stretch_run, calls, jobs)


def error_ratios(records: Sequence[Mapping[str, Any]], events: str = "mc-events", aps: str = "aps",
                 key: str = "mean_error_m") -> list[dict]:
    """Return, for every (stretch, seed, exposure) with a run on ``aps`` frames, its ``events`` run's error over it.

    The run on event frames does not depend on the APS exposure: one per (stretch, seed) serves every exposure.
    ``key``: the error compared (the mean position error by default, whose ratio is that of the % of distance on
    the same stretch). Each ratio record holds stretch, speed, seed, exposure_ms, blur_px (the APS frames'), the two
    errors and ``ratio``.

    >>> runs = [dict(stretch="s", speed=1.0, seed=0, frames="aps", exposure_ms=10.0, blur_px=2.0, mean_error_m=0.1),
    ...         dict(stretch="s", speed=1.0, seed=0, frames="mc-events", exposure_ms=10.0, blur_px=2.0,
    ...              mean_error_m=0.05)]
    >>> error_ratios(runs)[0]["ratio"]
    0.5
    """
    event_error = {(r["stretch"], r["seed"]): r[key] for r in records if r["frames"] == events}
    out = []
    for r in records:
        if r["frames"] != aps:
            continue
        if (r["stretch"], r["seed"]) not in event_error:
            raise ValueError(f"no run on {events!r} frames for stretch {r['stretch']!r}, seed {r['seed']}")
        ev = event_error[(r["stretch"], r["seed"])]
        out.append({"stretch": r["stretch"], "speed": r["speed"], "seed": r["seed"], "exposure_ms": r["exposure_ms"],
                    "blur_px": r["blur_px"], f"aps_{key}": r[key], f"events_{key}": ev, "ratio": ev / r[key]})
    return out
