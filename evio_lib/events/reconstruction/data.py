"""Training data for learned event-to-image reconstruction, made by the project's own event simulator.

E2VID and E2VID+ were trained on ESIM sequences of natural images mapped onto planes and filmed by a camera under random
6-DoF motion, with the contrast thresholds drawn per sequence and noise added. This module does the same with
:func:`evio_lib.events.simulate.simulate_events`:

- scene: one textured plane (a random crop of a bundled photograph, or a procedural texture) at depth d in front of a
  pinhole camera, with a random tilt. A view at time t is the plane-induced homography of the reference view,
  H_t = K (R_C0toCt + p_C0inCt n^T / d) K^-1 (Hartley & Zisserman Result 13.1), so every render is one ``warpPerspective``;
- motion: smooth random 6-DoF motion, a drift plus a sinusoid per axis (rotation vector and translation), with its speed
  drawn per sequence;
- sensor: contrast thresholds C ~ U(c_min, c_max) per sequence (E2VID+ trained on a wide range), per-pixel mismatch,
  a refractory period, background noise, and a few hot pixels firing at a high rate;
- labels: the sharp intensity image at every window's end, and the homography that maps the current view's pixels into
  the previous window-end view (for the temporal-consistency loss, which needs the true motion).

Splits use disjoint textures (photographs by name, procedural textures by seed range) and disjoint motion seeds:
``train``, ``val`` and ``test`` never share a texture.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from evio_lib.events.array import EVENT_DTYPE, concatenate_events
from evio_lib.events.representations import count_windows, voxel_grid
from evio_lib.events.simulate import EventCameraParams, simulate_events
from evio_lib.sim.textures import PROCEDURAL_KINDS, load_texture, procedural_texture

__all__ = ["SPLIT_PHOTOS", "ReconstructionDataConfig", "PlanarSequence", "random_planar_sequence",
           "make_training_sample", "reconstruction_dataset", "hot_pixel_events", "SmoothCameraMotion",
           "random_crop", "random_contrast"]

#: Photographs (scikit-image's bundled images) per split: no texture is shared between splits.
SPLIT_PHOTOS = {
    "train": ("astronaut", "cell", "chelsea", "coffee", "grass", "ihc", "motorcycle", "page", "rocket", "text"),
    "val": ("moon", "gravel"),
    "test": ("camera", "brick", "coins"),
}
#: Seed offsets per split: procedural textures and motions of different splits come from disjoint seed ranges.
_SPLIT_SEED_OFFSET = {"train": 0, "val": 10_000_000, "test": 20_000_000}


@dataclass(frozen=True)
class ReconstructionDataConfig:
    """Every setting of the synthetic training sequences (``print(config)`` shows them)."""

    height: int = 64                       # training crops: the networks are fully convolutional
    width: int = 64
    focal_fraction: float = 0.85           # f = focal_fraction * width: about the DAVIS240C's 60 deg field of view
    duration: float = 1.0                  # seconds simulated per sequence
    windows: int = 8                       # windows per training sample (the truncated back-propagation length)
    num_bins: int = 5                      # voxel-grid bins B
    fraction_min: float = 0.1              # window fraction n ~ U(fraction_min, fraction_max) per sequence
    fraction_max: float = 0.8
    contrast_min: float = 0.1              # contrast threshold C ~ U(contrast_min, contrast_max) per sequence
    contrast_max: float = 0.6
    contrast_sigma: float = 0.03           # per-pixel threshold mismatch
    refractory_max_s: float = 1e-3         # refractory period ~ U(0, refractory_max_s)
    noise_rate_max_hz: float = 0.5         # background noise rate per pixel ~ U(0, max)
    hot_pixel_fraction_max: float = 0.001  # fraction of hot pixels ~ U(0, max), each firing at 100-1000 Hz
    photo_probability: float = 0.6         # else a procedural texture
    speed_min: float = 0.5                 # scale of the random motion (about view widths per second)
    speed_max: float = 3.0

    def __post_init__(self) -> None:
        for name in ("height", "width", "windows", "num_bins"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer; got {value!r}")
        if self.height < 16 or self.width < 16:
            raise ValueError(f"height and width must be >= 16 pixels; got {self.height}x{self.width}")
        for low, high in (("fraction_min", "fraction_max"), ("contrast_min", "contrast_max"), ("speed_min", "speed_max")):
            lo, hi = getattr(self, low), getattr(self, high)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
                raise ValueError(f"need 0 < {low} <= {high}; got {lo}, {hi}")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration must be > 0 seconds; got {self.duration!r}")


@dataclass
class PlanarSequence:
    """One simulated sequence: its events, and what is needed to render the truth at any time."""

    events: np.ndarray            # (N,) EVENT_DTYPE, on the width x height sensor
    render: object                # render(t) -> (H, W) float32 linear intensity at time t
    homography: object            # homography(t) -> (3, 3) map from reference-view pixels to the view at t
    contrast: float               # the sequence's nominal contrast threshold
    fraction: float               # the window fraction n drawn for it


@lru_cache(maxsize=16)
def _photo(name: str) -> np.ndarray:
    """Return the bundled photograph ``name`` (cached: decoding it again costs time, speed.md: small costs)."""
    return load_texture(name)


def random_crop(rng: np.random.Generator, image: np.ndarray, size: tuple[int, int], scale: float) -> np.ndarray:
    """Return a random crop of ``image`` resized to ``size`` (H, W) at zoom ``scale`` (< 1: a wider, detailed crop
    shrunk with INTER_AREA; >= 1: a smaller crop enlarged with INTER_CUBIC); the crop is at least 8 pixels a side."""
    ch = max(8, min(image.shape[0], int(round(size[0] / scale))))
    cw = max(8, min(image.shape[1], int(round(size[1] / scale))))
    r0 = int(rng.integers(0, image.shape[0] - ch + 1))
    c0 = int(rng.integers(0, image.shape[1] - cw + 1))
    return cv2.resize(image[r0:r0 + ch, c0:c0 + cw], (size[1], size[0]),
                      interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_CUBIC)


def random_contrast(rng: np.random.Generator, texture: np.ndarray, gamma: tuple[float, float] = (0.7, 1.5),
                    min_span: float = 0.3) -> np.ndarray:
    """Return ``texture`` stretched (1st/99th percentile to 0/1), raised to a gamma ~ U(gamma) and mapped onto a random
    brightness range [lo, hi] of at least ``min_span``: float32 in [0, 1]."""
    lo, hi = np.percentile(texture, [1, 99])                 # stretch: a flat crop (a page's margin) becomes visible
    texture = np.clip((texture - lo) / max(hi - lo, 1e-3), 0.0, 1.0) ** rng.uniform(*gamma)   # contrast variety
    lo, hi = sorted(rng.uniform(0.0, 1.0, 2))
    hi = max(hi, lo + min_span)
    return np.clip(lo + (hi - lo) * texture, 0.0, 1.0).astype(np.float32)


def _texture(rng: np.random.Generator, split: str, size: tuple[int, int], config: ReconstructionDataConfig) -> np.ndarray:
    """Return a float32 texture in [0, 1] of shape ``size`` from the split's photographs or procedural textures."""
    if rng.random() < config.photo_probability:
        name = SPLIT_PHOTOS[split][int(rng.integers(len(SPLIT_PHOTOS[split])))]
        tex = random_crop(rng, _photo(name), size, rng.uniform(0.35, 1.0))   # a random part at a random zoom
    else:
        kind = PROCEDURAL_KINDS[int(rng.integers(len(PROCEDURAL_KINDS)))]
        seed = _SPLIT_SEED_OFFSET[split] + int(rng.integers(0, 10_000_000))
        tex = procedural_texture(kind, size, seed=seed, scale_px=float(rng.uniform(4, min(size) / 4)))
    return random_contrast(rng, tex)


def fold_time(t: float, period: float) -> float:
    """Return t folded into [0, period] back and forth (a triangle wave): t for t <= period, then 2 period - t, ..."""
    if t <= period or period <= 0:
        return t
    phase = t % (2 * period)
    return phase if phase <= period else 2 * period - phase


class SmoothCameraMotion:
    """Random smooth 6-DoF camera motion: per axis a drift plus one sinusoid, for the rotation vector theta(t) and the
    camera centre c(t) in the reference frame C0, scaled by ``speed`` (about view widths per second).

    theta(t) = d t + a (sin(2 pi f t + phi) - sin(phi)), and likewise c(t) (translations scaled by ``depth``); drift and
    amplitude are shrunk so that, over ``duration``, each axis turns by at most 0.6 rad and moves by at most
    ``translation_limit``: the scene stays in front of the camera. :meth:`pose` returns (R_C0toCt, p_C0inCt).

    Beyond ``duration`` the drift runs back and forth (its time folded into [0, duration]: the camera retraces its
    path and turns round), so that a motion can be sampled for as long as wanted and stays within the same bounds;
    the sinusoids go on as they are.
    """

    def __init__(self, rng: np.random.Generator, speed: float, view_angle: float, depth: float, duration: float,
                 translation_limit: float) -> None:
        self.duration = float(duration)
        self.rot = [rng.normal(0.0, 0.4, 3) * speed * view_angle * np.array([1.0, 1.0, 0.5]),
                    rng.uniform(0.0, 0.25, 3) * speed * view_angle, rng.uniform(0.5, 3.0, 3), rng.uniform(0, 2 * np.pi, 3)]
        self.pos = [rng.normal(0.0, 0.3, 3) * speed * depth * view_angle * np.array([1.0, 1.0, 0.5]),
                    rng.uniform(0.0, 0.2, 3) * speed * depth * view_angle, rng.uniform(0.5, 3.0, 3),
                    rng.uniform(0, 2 * np.pi, 3)]
        for (drift, amp, _, _), limit in ((self.rot, 0.6), (self.pos, translation_limit)):
            worst = np.abs(drift) * duration + 2 * amp
            scale = np.minimum(1.0, limit / np.maximum(worst, 1e-12))
            drift *= scale
            amp *= scale

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return (R_C0toCt, p_C0inCt) at time t."""
        t_drift = fold_time(t, self.duration)

        def curve(params):
            drift, amp, freq, phase = params
            return drift * t_drift + amp * (np.sin(2 * np.pi * freq * t + phase) - np.sin(phase))

        R = cv2.Rodrigues(curve(self.rot))[0].T                  # exp(theta^) = R_CttoC0, transposed
        return R, -R @ curve(self.pos)


def random_planar_sequence(rng: np.random.Generator, split: str = "train",
                           config: ReconstructionDataConfig = ReconstructionDataConfig()) -> PlanarSequence:
    """Return one random planar sequence of ``split``: events over [0, duration] and its ground-truth renderer.

    Args:
        rng: the generator that draws everything (texture, motion, sensor).
        split: ``train``, ``val`` or ``test`` (disjoint textures).
        config: sizes and ranges.
    """
    if split not in SPLIT_PHOTOS:
        raise ValueError(f"split must be one of {tuple(SPLIT_PHOTOS)}; got {split!r}")
    h, w = config.height, config.width
    f = config.focal_fraction * w
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    K_inv = np.linalg.inv(K)
    margin = max(h, w)                                       # the texture extends a view size beyond every border
    canvas = _texture(rng, split, (h + 2 * margin, w + 2 * margin), config)
    to_canvas_inv = np.array([[1.0, 0.0, margin], [0.0, 1.0, margin], [0.0, 0.0, 1.0]])  # ref pixel -> canvas pixel

    depth = 1.0
    tilt = rng.normal(0.0, 0.25, 2)                          # plane normal tilted by ~15 deg
    n_C0 = np.array([tilt[0], tilt[1], 1.0])
    n_C0 /= np.linalg.norm(n_C0)
    speed = rng.uniform(config.speed_min, config.speed_max)
    view_angle = w / f                                       # radians per view width
    # keep the plane well in front of the camera: at most ~0.6 rad of rotation and 0.4 d of translation per axis
    motion = SmoothCameraMotion(rng, speed, view_angle, depth, config.duration, 0.4 * depth)

    def homography(t: float) -> np.ndarray:
        R, p = motion.pose(t)                                # R_C0toCt, p_C0inCt
        H = K @ (R + np.outer(p, n_C0) / depth) @ K_inv      # H_t = K (R + t n^T / d) K^-1
        return H / H[2, 2]

    def render(t: float) -> np.ndarray:
        H_canvas_to_view = homography(t) @ np.linalg.inv(to_canvas_inv)
        image = cv2.warpPerspective(canvas, H_canvas_to_view, (w, h), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REFLECT)
        return np.clip(image, 0.0, 1.0, out=image)

    contrast = float(rng.uniform(config.contrast_min, config.contrast_max))
    params = EventCameraParams(contrast_pos=contrast, contrast_neg=contrast * rng.uniform(0.8, 1.25),
                               contrast_sigma=config.contrast_sigma,
                               refractory_s=float(rng.uniform(0.0, config.refractory_max_s)),
                               background_rate_hz=float(rng.uniform(0.0, config.noise_rate_max_hz)))
    events, _ = simulate_events(render, 0.0, config.duration, w, h, params=params, rng=rng, change_quantile=0.99,
                                dt_min=1e-5)
    events = concatenate_events([events, hot_pixel_events(rng, w, h, config.duration, config.hot_pixel_fraction_max)])
    fraction = float(rng.uniform(config.fraction_min, config.fraction_max))
    return PlanarSequence(events=events, render=render, homography=homography, contrast=contrast, fraction=fraction)


def hot_pixel_events(rng: np.random.Generator, width: int, height: int, duration: float,
                     fraction_max: float) -> np.ndarray:
    """Return the events over [0, duration] of a few hot pixels, sorted by time.

    The share of hot pixels is drawn from U(0, fraction_max); each fires one polarity at a rate of U(100, 1000) Hz.
    """
    n_hot = rng.binomial(width * height, rng.uniform(0.0, fraction_max))
    if n_hot == 0:
        return np.zeros(0, EVENT_DTYPE)
    counts = rng.poisson(rng.uniform(100.0, 1000.0, n_hot) * duration)
    pixel = rng.integers(0, width * height, n_hot)
    polarity = rng.choice(np.array([-1, 1], np.int8), n_hot)
    idx = np.repeat(np.arange(n_hot), counts)
    events = np.zeros(idx.size, EVENT_DTYPE)
    events["t"] = rng.uniform(0.0, duration, idx.size)
    events["x"] = pixel[idx] % width
    events["y"] = pixel[idx] // width
    events["p"] = polarity[idx]
    return events[np.argsort(events["t"], kind="stable")]


def make_training_sample(rng: np.random.Generator, split: str = "train",
                         config: ReconstructionDataConfig = ReconstructionDataConfig(), max_tries: int = 8
                         ) -> dict[str, np.ndarray]:
    """Return one sample: ``voxels`` (L, B, H, W) float16, ``frames`` (L, H, W) float16, ``H_prev`` (L, 3, 3) float32.

    ``frames[k]`` is the sharp intensity at the end of window k; ``H_prev[k]`` maps pixels of view k into view k - 1
    (identity for k = 0). The window fraction n is drawn per sequence and lowered if the sequence has too few events
    for L windows; a sequence with fewer than L * 0.05 * H * W events (almost no motion) is drawn again.
    """
    h, w, L = config.height, config.width, config.windows
    for _ in range(max_tries):
        seq = random_planar_sequence(rng, split, config)
        n_events = min(int(round(seq.fraction * h * w)), seq.events.size // L)
        if n_events >= max(1, int(0.05 * h * w)):
            break
    else:
        raise RuntimeError(f"no sequence with enough events for {L} windows in {max_tries} tries; raise speed_min")
    bounds = count_windows(seq.events, n_events)[:L]
    t_end = seq.events["t"][bounds[:, 1] - 1]
    voxels = np.stack([voxel_grid(seq.events[a:b], w, h, config.num_bins) for a, b in bounds]).astype(np.float16)
    frames = np.stack([seq.render(float(t)) for t in t_end]).astype(np.float16)
    H_prev = np.stack([np.eye(3)] + [seq.homography(float(t_end[k - 1])) @ np.linalg.inv(seq.homography(float(t_end[k])))
                                     for k in range(1, L)]).astype(np.float32)
    return {"voxels": voxels, "frames": frames, "H_prev": H_prev}


def _sample_job(job: tuple[int, str, int, ReconstructionDataConfig]) -> dict[str, np.ndarray]:
    """Return sample i of a split, drawn with its own generator default_rng([seed, split offset, i])."""
    seed, split, i, config = job
    return make_training_sample(np.random.default_rng([seed, _SPLIT_SEED_OFFSET[split], i]), split, config)


def reconstruction_dataset(split: str, n_samples: int, seed: int = 0,
                           config: ReconstructionDataConfig = ReconstructionDataConfig(), cache: bool = True,
                           progress: bool = False, workers: int = 1) -> dict[str, np.ndarray]:
    """Return ``n_samples`` stacked samples of ``split`` (see :func:`make_training_sample`), cached as .npz.

    Sample i is drawn with its own generator ``default_rng([seed, split offset, i])``, so the first k samples of a
    larger set are the k samples of a smaller one, and the set is the same on every machine and for any ``workers``
    (processes that simulate in parallel).
    """
    if split not in SPLIT_PHOTOS:
        raise ValueError(f"split must be one of {tuple(SPLIT_PHOTOS)}; got {split!r}")
    if int(n_samples) != n_samples or n_samples < 1:
        raise ValueError(f"n_samples must be a positive integer; got {n_samples!r}")
    from evio_lib.io.cache import default_cache_dir  # the project's one cache folder ($EVIO_CACHE_DIR)

    key = json.dumps({"split": split, "n": int(n_samples), "seed": int(seed), "config": asdict(config), "v": 1},
                     sort_keys=True)
    path = default_cache_dir() / f"reconstruction_{split}_{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"
    if cache and path.is_file():
        from evio_lib.io.cache import CacheError, discard_damaged_cache, load_npz_arrays

        try:
            return load_npz_arrays(path, ("voxels", "frames", "H_prev"))
        except CacheError as error:  # empty, truncated, damaged: deleted, said, made again
            discard_damaged_cache(error, "simulating the samples again")
    jobs = [(int(seed), split, i, config) for i in range(int(n_samples))]
    if workers > 1:
        import multiprocessing

        with multiprocessing.get_context("fork").Pool(int(workers)) as pool:
            results = pool.imap(_sample_job, jobs, chunksize=4)
            if progress:
                from tqdm.auto import tqdm

                results = tqdm(results, total=len(jobs), desc=f"simulating {split} sequences")
            samples = list(results)
    else:
        if progress:
            from tqdm.auto import tqdm

            jobs = tqdm(jobs, desc=f"simulating {split} sequences")
        samples = [_sample_job(job) for job in jobs]
    data = {k: np.stack([s[k] for s in samples]) for k in ("voxels", "frames", "H_prev")}
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **data)
        os.replace(tmp, path)
    return data
