"""Scoring event-to-image reconstructions: against the simulator's sharp truth, and against real APS frames.

Metrics (full-reference, as EVREAL reports them): MSE and SSIM (scikit-image, ``data_range=1``; Gaussian window,
sigma 1.5). Every image is compared in linear intensity: the reconstructors output it, the simulated APS frames are
decoded from their gamma encoding first. (Real APS frames are scored as recorded.) An event camera only sees changes, so a reconstruction's absolute brightness and contrast are arbitrary:
before scoring, both images are normalised the same way, each stretched linearly so that its 1st and 99th percentiles
map to 0 and 1 (clipped). EVREAL also normalises both images before its full-reference metrics; our percentile stretch
is robust to hot pixels, which a plain min-max is not.

Held-out simulated sequences: short stretches of the two presets with seeds that no training run uses, windows of
N_e = n H W events (thesis Eq. 87), each reconstruction scored against the sharp intensity rendered at its window's
last event. The blurred APS frames of the same stretch are scored against the sharp intensity at their mid-exposure
times, for reference.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Sequence
from pathlib import Path

import numpy as np
from skimage.metrics import structural_similarity

from evio_lib.events.reconstruct import (Reconstructor, reconstruct_at_times, reconstruct_windows,
                                        reconstructor_by_name_or_file)
from evio_lib.events.representations import count_windows, window_size_from_fraction

__all__ = ["normalize_for_metrics", "image_quality", "EvalSequence", "simulated_eval_sequence", "score_windows",
           "score_aps_frames", "score_at_frame_times", "load_slider_slice", "quality_table", "THESIS_FRACTION",
           "LINEAR_LIGHT_SEEDS", "linear_light_room_sequence", "window_scores"]

#: The held-out stretches: (preset, start [s], duration [s], length of the preset's motion [s]). ``boxes_like`` grows
#: violent towards the end of its motion: "fast" is its last stretch, "slow" its start.
EVAL_STRETCHES = {
    "boxes_like_slow": ("boxes_like", 1.0, 0.4, 10.0),
    "boxes_like_fast": ("boxes_like", 9.5, 0.4, 10.0),
    "aerial_like": ("aerial_like", 4.0, 0.4, 10.0),
}
#: Seed of the held-out simulated test stretches (the presets' default seed is 0; training sequences are planar scenes).
EVAL_SEED = 101
#: Seed of the validation stretches: the same stretches of other scenes and motions, where networks and settings are
#: chosen; the test stretches (EVAL_SEED) are only reported.
VALIDATION_SEED = 202


def normalize_for_metrics(image: np.ndarray) -> np.ndarray:
    """Return ``image`` stretched so its 1st/99th percentiles become 0/1 (clipped), as float64.

    >>> normalize_for_metrics(np.linspace(0.2, 0.4, 101)).round(2)[[0, 50, 100]].tolist()
    [0.0, 0.5, 1.0]
    """
    image = np.asarray(image, dtype=np.float64)
    lo, hi = np.percentile(image, [1, 99])
    if hi - lo < 1e-12:
        return np.zeros_like(image)
    return np.clip((image - lo) / (hi - lo), 0.0, 1.0)


def image_quality(reconstruction: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Return {"mse", "ssim"} of ``reconstruction`` against ``reference`` after :func:`normalize_for_metrics`.

    Args:
        reconstruction: (H, W) image.
        reference: (H, W) image of the same scene at the same time (sharp truth or an APS frame).
    """
    a, b = np.asarray(reconstruction), np.asarray(reference)
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"reconstruction and reference must be (H, W) images of one shape; got {a.shape} and {b.shape}")
    a, b = normalize_for_metrics(a), normalize_for_metrics(b)
    ssim = structural_similarity(a, b, data_range=1.0, gaussian_weights=True, sigma=1.5, use_sample_covariance=False)
    return {"mse": float(np.mean((a - b) ** 2)), "ssim": float(ssim)}


@dataclass
class EvalSequence:
    """A held-out simulated stretch: events, the sharp-intensity renderer, and the blurred APS frames."""

    name: str
    events: np.ndarray
    width: int
    height: int
    render: object                 # render(t) -> (H, W) sharp linear intensity
    frame_times: np.ndarray        # APS mid-exposure times [s]
    frames: np.ndarray             # (F, H, W) uint8 blurred APS frames


def simulated_eval_sequence(stretch: str, duration: float | None = None, seed: int = EVAL_SEED,
                            cache: bool = True) -> EvalSequence:
    """Return the held-out stretch ``stretch`` (a key of :data:`EVAL_STRETCHES`), simulated once and cached.

    Args:
        stretch: ``boxes_like_slow``, ``boxes_like_fast`` or ``aerial_like``.
        duration: seconds to simulate (default: the stretch's own, 0.4 s); shorter for quick lessons.
        seed: the simulation seed.
        cache: keep the events and frames in ``data/cache`` (git-ignored) for the next call.
    """
    from evio_lib.sim.presets import SimulationConfig, _pose_function, recording_settings_digest, simulate_sequence
    from evio_lib.sim.scene import scene_from_preset
    from evio_lib.sim.trajectory import trajectory_from_preset

    if stretch not in EVAL_STRETCHES:
        raise ValueError(f"stretch must be one of {sorted(EVAL_STRETCHES)}; got {stretch!r}")
    preset, start, default_duration, motion = EVAL_STRETCHES[stretch]
    duration = default_duration if duration is None else float(duration)
    config = SimulationConfig(preset=preset, duration=duration, start_time=start, trajectory_duration=motion, seed=seed)
    from evio_lib.io.cache import default_cache_dir  # the project's one cache folder ($EVIO_CACHE_DIR)

    name = f"reconstruction_eval_{stretch}_{duration:g}s_seed{seed}_m{recording_settings_digest(config)}.npz"
    path = default_cache_dir() / name
    from evio_lib.io.cache import CacheError, discard_damaged_cache, load_npz_arrays

    data = None
    if cache and path.is_file():
        try:
            data = load_npz_arrays(path, ("events", "frame_times", "frames"))
        except CacheError as error:  # empty, truncated, damaged: deleted, said, simulated again
            discard_damaged_cache(error, "re-simulating")
    if data is not None:
        events, frame_times, frames = data["events"], data["frame_times"], data["frames"]
    else:
        sequence = simulate_sequence(config)
        events, frame_times, frames = sequence.events, sequence.frame_times, sequence.frames
        if cache:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, events=events, frame_times=frame_times, frames=frames)
            os.replace(tmp, path)
    trajectory = trajectory_from_preset(preset, duration=motion, seed=seed)
    scene = scene_from_preset(preset, seed=seed)
    pose_at = _pose_function(trajectory, config.extrinsics)
    camera = config.camera

    def render(t: float) -> np.ndarray:
        R, p = pose_at(np.array([t]))
        return scene.render_intensity(camera, R[0], p[0])

    return EvalSequence(name=stretch, events=events, width=camera.width, height=camera.height, render=render,
                        frame_times=frame_times, frames=frames)


#: Seeds of the linear-light photo rooms (:func:`linear_light_room_sequence`): validation on the photo folder's val
#: photographs, test on its test photographs.
LINEAR_LIGHT_SEEDS = {"val": (303, 404, 505), "test": (606, 707, 808)}


def linear_light_room_sequence(seed: int, split: str = "val", photos: str | Path | None = None, gamma: float = 2.2,
                               contrast: float = 0.2, render_rate_hz: float = 1000.0, start: float = 1.0,
                               duration: float = 1.0) -> EvalSequence:
    """Return a held-out recording unlike the training sequences: a room of photographs in linear light.

    The scene is :func:`evio_lib.sim.scene.photo_room` of the photo folder's ``split`` photographs (never seen in
    training), its light I = V^``gamma`` (about 650 to 1 for gamma 2.2); the camera follows ``boxes_like``'s
    motion of the same seed from ``start`` for ``duration`` seconds (DAVIS240C, 240 x 180). The events come from
    renders at a fixed ``render_rate_hz`` with linear interpolation between them (the training sets and the presets
    sample adaptively), with one contrast threshold for every pixel, no mismatch, no refractory period and no noise.
    No APS frames. Simulated in a few seconds, so not cached.

    Raises ValueError when no photo folder is found (``photos=None`` looks where
    :func:`evio_lib.sim.photos.default_photo_folder` does) or the folder holds no photograph of ``split``.
    """
    from evio_lib.events.simulate import EventCameraParams, simulate_events
    from evio_lib.geometry.camera import PinholeRadtan
    from evio_lib.sim.photos import list_photos, resolve_photo_option
    from evio_lib.sim.presets import _pose_function
    from evio_lib.sim.rig import CameraImuExtrinsics
    from evio_lib.sim.scene import photo_room
    from evio_lib.sim.trajectory import trajectory_from_preset

    folder = resolve_photo_option(photos)
    if folder is None:
        raise ValueError("no photo folder: give photos=DIR (a folder of .jpg/.png photographs) or set $EVIO_PHOTOS")
    if not (np.isfinite(render_rate_hz) and render_rate_hz > 0):
        raise ValueError(f"render_rate_hz must be a positive number of renders per second; got {render_rate_hz!r}")
    scene = photo_room([str(p) for p in list_photos(folder, split)], seed=seed, gamma=gamma)
    pose_at = _pose_function(trajectory_from_preset("boxes_like", duration=10.0, seed=seed),
                             CameraImuExtrinsics.default())
    camera = PinholeRadtan.davis240c()

    def render(t: float) -> np.ndarray:
        R, p = pose_at(np.array([t]))
        return scene.render_intensity(camera, R[0], p[0])

    params = EventCameraParams(contrast_pos=contrast, contrast_neg=contrast, contrast_sigma=0.0, refractory_s=0.0)
    step = 1.0 / float(render_rate_hz)
    with warnings.catch_warnings():  # the fixed step is meant: no warning that a step exceeded the change bound
        warnings.filterwarnings("ignore", message="simulate_events: .* exceeded max_log_change",
                                category=RuntimeWarning)
        events, _ = simulate_events(render, start, start + duration, camera.width, camera.height, params=params,
                                    rng=np.random.default_rng(seed), dt_min=step, dt_max=step)
    return EvalSequence(name=f"linear-light room, {split} photographs, seed {seed}", events=events,
                        width=camera.width, height=camera.height, render=render, frame_times=np.zeros(0),
                        frames=np.zeros((0, camera.height, camera.width), np.uint8))


def window_scores(reconstructor: Reconstructor, sequence: EvalSequence, fraction: float | None,
                  warmup_s: float = 0.1, max_frames: int | None = None,
                  bounds: np.ndarray | None = None) -> dict[str, np.ndarray | int | float]:
    """Return the scores of each scored window of ``reconstructor`` against the sharp truth.

    Windows are N_e = ``fraction`` H W events, or the given ``bounds`` (K, 2) (e.g. from ``adaptive_windows``; then
    ``fraction`` is None). Every window is fed, from an empty state; windows ending in the first ``warmup_s`` seconds
    are not scored (every method starts from nothing). ``max_frames`` scores only that many windows, evenly spread
    (the renders of the truth cost time). Returns ``index`` (the scored windows' indices), ``mse`` and ``ssim`` (one
    per scored window), ``windows`` (K) and ``mean_fraction`` (the windows' mean size over H W).
    """
    if bounds is None:
        n_events = window_size_from_fraction(fraction, sequence.width, sequence.height)
        bounds = count_windows(sequence.events, n_events)
    if len(bounds) == 0:
        raise ValueError(f"{sequence.name} has {sequence.events.size} events: not one window to score")
    frames, times = reconstruct_windows(reconstructor, sequence.events, bounds)
    scored = np.flatnonzero(times >= sequence.events["t"][0] + warmup_s)
    if scored.size == 0:
        scored = np.array([len(times) - 1])
    if max_frames is not None and scored.size > max_frames:
        scored = scored[np.linspace(0, scored.size - 1, max_frames).round().astype(int)]
    scores = [image_quality(frames[k], sequence.render(float(times[k]))) for k in scored]
    return {"index": scored, "mse": np.array([x["mse"] for x in scores]),
            "ssim": np.array([x["ssim"] for x in scores]), "windows": len(bounds),
            "mean_fraction": float(np.diff(bounds, axis=1).mean() / (sequence.width * sequence.height))}


def score_windows(reconstructor: Reconstructor, sequence: EvalSequence, fraction: float | None, warmup_s: float = 0.1,
                  max_frames: int | None = None, bounds: np.ndarray | None = None) -> dict[str, float]:
    """Return mean {"mse", "ssim", "frames", "mean_fraction"} of :func:`window_scores` (the same arguments)."""
    each = window_scores(reconstructor, sequence, fraction, warmup_s, max_frames, bounds)
    return {"mse": float(each["mse"].mean()), "ssim": float(each["ssim"].mean()), "frames": int(each["index"].size),
            "mean_fraction": each["mean_fraction"]}


def score_aps_frames(sequence: EvalSequence, gamma: float | None = None) -> dict[str, float]:
    """Return mean {"mse", "ssim", "frames"} of the blurred APS frames against the sharp truth at mid-exposure.

    The simulated APS camera encodes its output as 255 V^gamma (gamma = 1/2.2 by default, :class:`ApsParams`); frames
    are decoded back to linear intensity V = (frame / 255)^(1 / gamma) before scoring, like every other image here.
    """
    from evio_lib.sim.aps import ApsParams

    gamma = ApsParams().gamma if gamma is None else float(gamma)
    if len(sequence.frame_times) == 0:
        raise ValueError(f"{sequence.name} has no APS frames")
    scores = [image_quality((frame.astype(np.float64) / 255.0) ** (1.0 / gamma), sequence.render(float(t)))
              for t, frame in zip(sequence.frame_times, sequence.frames)]
    return {"mse": float(np.mean([s["mse"] for s in scores])), "ssim": float(np.mean([s["ssim"] for s in scores])),
            "frames": len(scores)}


def score_at_frame_times(reconstructor: Reconstructor, events: np.ndarray, frame_times: np.ndarray,
                         frames: np.ndarray, max_window_events: int | None = None) -> dict[str, object]:
    """Return {"mse", "ssim", "per_frame", "reconstructions"} against real APS frames at their own timestamps.

    Frame k is reconstructed from all events up to ``frame_times[k]`` (the EVREAL protocol on ECD); only frames with
    events before them are scored.
    """
    frame_times = np.asarray(frame_times, dtype=np.float64)
    inside = frame_times > events["t"][0]
    if not inside.any():
        raise ValueError("no frame time follows the first event: nothing to reconstruct a frame from")
    recon = reconstruct_at_times(reconstructor, events, frame_times[inside], max_window_events=max_window_events)
    per_frame = [image_quality(r, f.astype(np.float64) / (255.0 if f.dtype == np.uint8 else 1.0))
                 for r, f in zip(recon, np.asarray(frames)[inside])]
    return {"mse": float(np.mean([s["mse"] for s in per_frame])), "ssim": float(np.mean([s["ssim"] for s in per_frame])),
            "per_frame": per_frame, "reconstructions": recon}


#: The thesis's window fraction per scene (§4.1): 0.7 on the textured boxes, 0.2 on the sparse aerial flight.
THESIS_FRACTION = {"boxes_like_slow": 0.7, "boxes_like_fast": 0.7, "aerial_like": 0.2}
#: The real slider_depth slice (read-only; never copied into the repository).
REAL_DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "real"   # beside the repository


def load_slider_slice(folder: str | Path | None = None) -> dict[str, np.ndarray] | None:
    """Return {"events", "frame_times", "frames"} of the real ECD slider_depth slice, or None when it is absent."""
    from evio_lib.io.ecd import read_ecd_events

    folder = Path(folder) if folder is not None else REAL_DATA / "ecd_slider_depth_slice"
    if not (folder / "slider_seg.txt").is_file() or not (folder / "images.txt").is_file():
        return None
    import cv2

    events = read_ecd_events(folder / "slider_seg.txt", sensor_size=(240, 180))
    lines = [line.split() for line in (folder / "images.txt").read_text().splitlines() if line.strip()]
    times = np.array([float(t) for t, _ in lines])
    inside = np.flatnonzero(times <= events["t"][-1])
    frames = np.stack([cv2.imread(str(folder / lines[i][1]), cv2.IMREAD_GRAYSCALE) for i in inside])
    return {"events": events, "frame_times": times[inside], "frames": frames}


def quality_table(methods: Sequence[str], stretches: Sequence[str] = tuple(EVAL_STRETCHES), duration: float | None = None,
                  max_frames: int | None = 12, with_aps: bool = True, with_slider: bool = True,
                  seed: int = EVAL_SEED, precision: str | None = None) -> list[dict]:
    """Return rows {method, sequence, mse, ssim, frames, precision}: every method (a reconstructor's name or a
    reconstruct-train checkpoint file) on every held-out stretch (at the thesis's n),
    the blurred APS frames for reference, and the real slider frames (EVREAL protocol) when the real data is present.
    ``precision``: the networks' arithmetic (one of ``PRECISIONS``; None: each reconstructor's default); each row's
    ``precision`` is the one its network computed in (what ``auto`` chose; None for the classical methods)."""
    rows = []
    for stretch in stretches:
        sequence = simulated_eval_sequence(stretch, duration=duration, seed=seed)
        for method in methods:
            rec = reconstructor_by_name_or_file(method, sequence.width, sequence.height, precision=precision)
            rows.append({"method": method, "sequence": stretch, "precision": getattr(rec, "precision", None),
                         **score_windows(rec, sequence, THESIS_FRACTION[stretch], max_frames=max_frames)})
        if with_aps and len(sequence.frame_times):
            rows.append({"method": "APS frames (blurred)", "sequence": stretch, **score_aps_frames(sequence)})
    slider = load_slider_slice() if with_slider else None
    if slider is not None:
        for method in methods:
            rec = reconstructor_by_name_or_file(method, 240, 180, precision=precision)
            score = score_at_frame_times(rec, slider["events"], slider["frame_times"], slider["frames"],
                                         max_window_events=window_size_from_fraction(0.35, 240, 180))
            rows.append({"method": method, "sequence": "real slider_depth (APS frames)", "mse": score["mse"],
                         "ssim": score["ssim"], "frames": len(score["per_frame"]),
                         "precision": getattr(rec, "precision", None)})
    return rows
