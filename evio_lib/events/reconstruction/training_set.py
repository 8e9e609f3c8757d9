"""The reconstruction training set: many short, independent simulated sequences, one file per sequence.

E2VID and FireNet were trained on about 1 000 ESIM sequences of 2 s, each with its own images, camera motion, contrast
thresholds and noise; E2VID+/FireNet+ (Stoffregen et al., ECCV 2020, "Reducing the sim-to-real gap") widened the
thresholds to 0.2-1.5, added more noise and trained on longer sequences. This module makes such a set with the project's
ESIM-style simulator (:func:`evio_lib.events.simulate.simulate_events`).

Every sequence is drawn by its own generator ``default_rng([seed, split offset, i])``, so sequence i is the same on
every machine, for any number of worker processes, and in a set of any size.

- **Scene: layered planes.** A background plane at depth d_0 ~ U(2, 6) and K ~ U{0..4} foreground planes, each a
  textured shape (ellipse, rectangle or random polygon, 15-60 % of the view wide) at depth d_k ~ U(0.5, 0.8) d_0, each
  tilted by ~15 degrees and drifting with its own velocity (independently moving objects). Plane k seen from the
  reference view C0 is mapped into the view at time t by the plane-induced homography (Hartley & Zisserman
  Result 13.1)

      H_k(t) = K (R(t) + p_k(t) n_k^T / d_k) K^-1,   p_k(t) = p_C0inCt(t) + R(t) v_k t,

  with R(t) = R_C0toCt, n_k the plane's unit normal and v_k its own velocity in C0. Layers are drawn far to near with
  their warped masks (occlusions and disocclusions).
- **Textures** from every source the project has: crops of the bundled scikit-image photographs at a zoom
  log-uniform over 0.3-3 (wide detailed crops to smooth close-ups), the procedural kinds (dead leaves of rectangles or
  ellipses, value and fractal (Perlin-style) noise, checkerboards, stripes, tiles) at feature sizes log-uniform over
  3 px to a third of the canvas, and the aerial farmland texture; 30 % of them blurred (sigma 0.5-3 px: surfaces out
  of focus or with little texture, which the held-out scenes have and a network must not fill with invented detail);
  each stretched, with random contrast, gamma and brightness. With ``linear_light_fraction`` F > 0, a share F of
  the sequences takes those values as display values and renders their decoding, I = V^g with g ~ U(1.8, 2.6)
  (light of a wide range, as a renderer in linear intensity gives; :func:`_texture`).
  Photographs and procedural seed ranges are disjoint between the ``train``, ``val`` and ``test`` splits.
- **Motion**, slow to violent: per axis a drift plus a sinusoid for rotation and translation; the speed is
  log-uniform over 0.2-4 view widths per second; bounded so every plane stays in front of the camera.
- **Sensor**: with probability 1/2 E2VID's thresholds C ~ N(0.18, 0.03), else E2VID+'s wide C ~ U(0.2, 1.5);
  C- = C U(0.8, 1.25); per-pixel mismatch sigma = C U(0, 0.15); refractory period U(0, 1 ms); background activity
  U(0, 1) Hz per pixel; leak events U(0, 0.2) Hz per pixel; hot pixels (up to 0.1 % of the pixels, 100-1000 Hz).
- **Windows**, so that one network serves every window rule: with probability 0.7 windows of N_e = n H W events with
  n log-uniform over [0.05, 1.0], else windows of a fixed duration (the sequence's length / L). The rule and n are
  drawn first; a sequence with fewer than L N_e events is simulated again, the same scene, sensor and motion over a
  longer time (up to ``duration_extend_max``; the motion's drift then runs back and forth), so that the windows
  have the n drawn (generator version 2 cut n to the events there were, so its count windows were smaller than drawn:
  docs/archive.md, "training-set generator version 2"). L windows per sequence (40 by default), each stored as a
  normalised voxel grid with
  B bins, the sharp intensity at its end, and the true flow of every pixel into the previous window's end view (for the
  temporal-consistency loss): flow_k(u) = pi(H_j(t_k-1) H_j(t_k)^-1 u) - u with j the plane visible at u.

A set is a folder: ``training_set.json`` (the config, the seed, the counts) and ``train/``, ``val/``, ``test/``, each
with ``seq_00000.npz``... written atomically (a temporary file, then a rename). Making a set again into the same folder
with the same settings resumes it (the files already there are kept); another setting is refused.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, fields
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from evio_lib.events.array import concatenate_events
from evio_lib.events.reconstruction.data import (_SPLIT_SEED_OFFSET, SPLIT_PHOTOS, SmoothCameraMotion, _photo,
                                                 fold_time,
                                                 hot_pixel_events, random_contrast, random_crop)
from evio_lib.events.representations import count_windows, time_windows, voxel_grid
from evio_lib.events.simulate import EventCameraParams, simulate_events
from evio_lib.sim.photos import list_photos, load_photo, photo_fingerprint, resolve_photo_option
from evio_lib.sim.textures import PROCEDURAL_KINDS, aerial_terrain_texture, procedural_texture

__all__ = ["TrainingSetConfig", "SPLITS", "make_sequence", "make_training_set", "read_training_set",
           "load_sequence", "MANIFEST_NAME", "main_reconstruct_data"]

SPLITS = ("train", "val", "test")
MANIFEST_NAME = "training_set.json"
_FORMAT = "evio-reconstruction-set-v1"
#: Raised whenever the generator draws differently for the same settings (2: zoomed and blurred textures; 3: the
#: window rule drawn first and the sequence lengthened to hold it), so that a set is never resumed or extended with
#: sequences of another generator.
GENERATOR_VERSION = 3
#: share of textures taken from the photo folder when a set is made with one (the rest as without it: bundled
#: photographs, farmland, procedural kinds); E2VID's scenes were all MS-COCO photographs, the rest keeps the flat
#: regions, blur and regular patterns that held-out scenes have
PHOTO_FOLDER_FRACTION = 0.7
_ARRAYS = ("voxels", "frames", "flow")


@dataclass(frozen=True)
class TrainingSetConfig:
    """Every setting of a training set (stored in its ``training_set.json``)."""

    height: int = 64                      # sensor size: the networks are fully convolutional
    width: int = 64
    windows: int = 40                     # L windows per sequence (the recurrence's training length)
    num_bins: int = 5                     # voxel-grid bins B
    duration_min: float = 1.0             # seconds simulated per sequence ~ U(duration_min, duration_max)
    duration_max: float = 2.0
    duration_extend_max: float = 30.0     # a sequence too short for its windows is simulated again up to this long
    fraction_min: float = 0.05            # count windows: n log-uniform over [fraction_min, fraction_max]
    fraction_max: float = 1.0
    time_window_probability: float = 0.3  # else count windows
    max_foreground: int = 4               # foreground planes K ~ U{0..max_foreground}
    speed_min: float = 0.2                # view widths per second, log-uniform
    speed_max: float = 4.0
    noise_rate_max_hz: float = 1.0        # background activity per pixel ~ U(0, max)
    leak_rate_max_hz: float = 0.2         # leak events per pixel ~ U(0, max)
    hot_pixel_fraction_max: float = 0.001
    refractory_max_s: float = 1e-3
    linear_light_fraction: float = 0.0    # sequences whose textures are display values decoded to linear light

    def __post_init__(self) -> None:
        for field in fields(self):                                  # every setting is a number (from JSON or --set)
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ValueError(f"{field.name} must be a number; got {value!r}")
        for name in ("height", "width", "windows", "num_bins"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer; got {value!r}")
        if self.height < 16 or self.width < 16:
            raise ValueError(f"height and width must be >= 16 pixels; got {self.height}x{self.width}")
        if int(self.max_foreground) != self.max_foreground or not 0 <= self.max_foreground <= 16:
            raise ValueError(f"max_foreground must be an integer in 0..16; got {self.max_foreground!r}")
        for low, high in (("duration_min", "duration_max"), ("fraction_min", "fraction_max"),
                          ("speed_min", "speed_max")):
            lo, hi = getattr(self, low), getattr(self, high)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
                raise ValueError(f"need 0 < {low} <= {high}; got {lo}, {hi}")
        if self.duration_max > 30:
            raise ValueError(f"duration_max must be <= 30 s per sequence; got {self.duration_max}")
        if not (np.isfinite(self.duration_extend_max) and self.duration_max <= self.duration_extend_max <= 30):
            raise ValueError(f"need duration_max <= duration_extend_max <= 30 s; got {self.duration_max}, "
                             f"{self.duration_extend_max}")
        if self.fraction_max > 10:
            raise ValueError(f"fraction_max must be <= 10; got {self.fraction_max}")
        if not 0 <= self.time_window_probability <= 1:
            raise ValueError(f"time_window_probability must lie in [0, 1]; got {self.time_window_probability}")
        for name in ("noise_rate_max_hz", "leak_rate_max_hz", "hot_pixel_fraction_max", "refractory_max_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be >= 0; got {value!r}")
        if not (np.isfinite(self.linear_light_fraction) and 0 <= self.linear_light_fraction <= 1):
            raise ValueError(f"linear_light_fraction must lie in [0, 1]; got {self.linear_light_fraction!r}")

    @classmethod
    def from_dict(cls, values: dict) -> "TrainingSetConfig":
        """Return a config from :func:`dataclasses.asdict`'s output, refusing unknown keys."""
        from evio_lib.cli_args import settings_from_dict

        return settings_from_dict(cls, values, "training-set settings")


# ------------------------------------------------------------------------------------------------------- textures
@lru_cache(maxsize=1)
def _farmland() -> np.ndarray:
    return aerial_terrain_texture(1024, seed=12345)


def _texture(rng: np.random.Generator, split: str, size: tuple[int, int], photos: tuple[str, ...] = (),
             linear_gamma: float | None = None) -> np.ndarray:
    """Return a float32 texture in [0, 1] of ``size`` from one of the split's sources, with random contrast and gamma.

    ``photos``: the split's photographs of a photo folder (:mod:`evio_lib.sim.photos`); when given, a texture is one of
    them with probability :data:`PHOTO_FOLDER_FRACTION`, else drawn as without them.

    ``linear_gamma``: the texture's values V are display values and the scene's light is I = V^gamma (a
    display-encoded photograph decoded to linear intensity, as a simulator that renders in linear light sees it).
    Half of such textures first span nearly the whole display range, V in [U(0, 0.05), U(0.85, 1)], so that the
    scene's contrast reaches several hundred to one, where a display-encoded texture spans a few to one.
    """
    image, source = None, None
    if photos and rng.random() < PHOTO_FOLDER_FRACTION:         # a natural photograph of the folder
        image = load_photo(photos[int(rng.integers(len(photos)))])
    else:
        source = rng.random()
        if source < 0.45:                                       # a bundled photograph
            names = SPLIT_PHOTOS[split]
            image = _photo(names[int(rng.integers(len(names)))])
    if image is not None:                                       # either photograph, cropped at a random zoom
        scale = float(np.exp(rng.uniform(np.log(0.3), np.log(3.0))))   # < 1: a wide, detailed crop; > 1: zoomed in
        tex = random_crop(rng, image, size, scale)
        if rng.random() < 0.5:
            tex = tex[:, ::-1]
    elif source < 0.55:                                         # the farmland, a quarter per split
        farm = _farmland()
        quarter = farm.shape[0] // 2
        base_r, base_c = divmod(SPLITS.index(split), 2)
        own = farm[base_r * quarter:(base_r + 1) * quarter, base_c * quarter:(base_c + 1) * quarter]
        tex = random_crop(rng, own, size, rng.uniform(0.3, 1.0))
    else:                                                       # procedural: dead leaves, noise, patterns
        kind = PROCEDURAL_KINDS[int(rng.integers(len(PROCEDURAL_KINDS)))]
        seed = _SPLIT_SEED_OFFSET[split] + int(rng.integers(0, 10_000_000))
        largest = max(4.0, min(size) / 3)
        tex = procedural_texture(kind, size, seed=seed, scale_px=float(np.exp(rng.uniform(np.log(3.0), np.log(largest)))))
    if rng.random() < 0.3:                                      # smooth content: out-of-focus or low-texture surfaces
        tex = cv2.GaussianBlur(tex.astype(np.float32), (0, 0), float(rng.uniform(0.5, 3.0)))
    tex = random_contrast(rng, tex, gamma=(0.5, 2.0), min_span=0.25)
    if linear_gamma is None:
        return tex
    if rng.random() < 0.5:                                      # nearly the whole display range
        lo, hi = np.percentile(tex, [1, 99])
        black, white = float(rng.uniform(0.0, 0.05)), float(rng.uniform(0.85, 1.0))
        tex = black + (white - black) * np.clip((tex - lo) / max(hi - lo, 1e-3), 0.0, 1.0)
    return (tex ** linear_gamma).astype(np.float32)              # I = V^gamma: linear light


def _shape_mask(rng: np.random.Generator, size: tuple[int, int], centre: tuple[float, float],
                extent: float) -> np.ndarray:
    """Return a float32 (H, W) mask in [0, 1] of one random shape (ellipse, rotated rectangle or polygon)."""
    mask = np.zeros(size, np.float32)
    cx, cy = centre
    kind = int(rng.integers(3))
    if kind == 0:
        axes = (float(extent * rng.uniform(0.3, 0.5)), float(extent * rng.uniform(0.3, 0.5)))
        cv2.ellipse(mask, ((float(cx), float(cy)), (2 * axes[0], 2 * axes[1]), float(rng.uniform(0, 180))), 1.0, -1)
    elif kind == 1:
        box = cv2.boxPoints(((float(cx), float(cy)), (float(extent * rng.uniform(0.5, 1.0)),
                                                      float(extent * rng.uniform(0.5, 1.0))), float(rng.uniform(0, 90))))
        cv2.fillPoly(mask, [np.round(box).astype(np.int32)], 1.0)
    else:
        n = int(rng.integers(3, 9))
        angles = np.sort(rng.uniform(0, 2 * np.pi, n))
        radii = extent * rng.uniform(0.25, 0.55, n)
        pts = np.stack([cx + radii * np.cos(angles), cy + radii * np.sin(angles)], axis=1)
        cv2.fillPoly(mask, [np.round(pts).astype(np.int32)], 1.0)
    return mask


# ------------------------------------------------------------------------------------------------------- the scene
class _LayeredScene:
    """Planes seen from a moving pinhole camera: ``render(t)``, ``visible_layer(t)``, ``homographies(t)``."""

    def __init__(self, rng: np.random.Generator, split: str, config: TrainingSetConfig, duration: float,
                 photos: tuple[str, ...] = ()) -> None:
        h, w = config.height, config.width
        f = 0.85 * w                                             # about a 60 degree field of view (DAVIS240C)
        self.size = (h, w)
        self.K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
        self.K_inv = np.linalg.inv(self.K)
        margin = max(h, w)                                       # textures extend a view size beyond every border
        self.canvas_from_ref = np.array([[1.0, 0.0, margin], [0.0, 1.0, margin], [0.0, 0.0, 1.0]])
        canvas = (h + 2 * margin, w + 2 * margin)
        linear_gamma = None                                      # drawn only where asked: other sets stay as made
        if config.linear_light_fraction > 0 and rng.random() < config.linear_light_fraction:
            linear_gamma = float(rng.uniform(1.8, 2.6))
        self.linear_gamma = linear_gamma
        d0 = rng.uniform(2.0, 6.0)
        n_fg = int(rng.integers(0, config.max_foreground + 1))
        depths = np.concatenate([[d0], np.sort(rng.uniform(0.5, 0.8, n_fg) * d0)[::-1]])   # far to near
        view_angle = w / f
        speed = float(np.exp(rng.uniform(np.log(config.speed_min), np.log(config.speed_max))))
        self.speed = speed
        near = float(depths.min())                               # the camera stays in front of the nearest plane
        self.motion = SmoothCameraMotion(rng, speed, view_angle, near, duration, 0.35 * near)
        self.layers = []                                         # (texture, mask or None, normal, depth, velocity)
        for k, depth in enumerate(depths):
            tilt = rng.normal(0.0, 0.25, 2)
            normal = np.array([tilt[0], tilt[1], 1.0])
            normal /= np.linalg.norm(normal)
            texture = _texture(rng, split, canvas, photos, linear_gamma)
            if k == 0:
                self.layers.append((texture, None, normal, depth, np.zeros(3)))
                continue
            centre = (margin + rng.uniform(0.1, 0.9) * w, margin + rng.uniform(0.1, 0.9) * h)
            mask = _shape_mask(rng, canvas, centre, rng.uniform(0.15, 0.6) * max(h, w))
            mask = cv2.GaussianBlur(mask, (3, 3), 0.6)           # anti-aliased edges
            velocity = rng.normal(0.0, 0.3, 3) * speed * depth * view_angle * np.array([1.0, 1.0, 0.3])
            velocity *= min(1.0, 0.3 * depth / max(float(np.abs(velocity).max()) * duration, 1e-12))
            self.layers.append((texture, mask, normal, depth, velocity))

    def homographies(self, t: float) -> list[np.ndarray]:
        """Return H_k(t) for every layer: reference-view pixels of plane k -> pixels of the view at t."""
        R, p = self.motion.pose(t)
        t_drift = fold_time(t, self.motion.duration)             # beyond the drawn time the planes move back too
        out = []
        for _, _, normal, depth, velocity in self.layers:
            p_k = p + R @ velocity * t_drift                     # the plane's own motion, seen from Ct
            H = self.K @ (R + np.outer(p_k, normal) / depth) @ self.K_inv
            out.append(H / H[2, 2])
        return out

    def _warp(self, image: np.ndarray, H: np.ndarray, border: int) -> np.ndarray:
        h, w = self.size
        return cv2.warpPerspective(image, H @ np.linalg.inv(self.canvas_from_ref), (w, h), flags=cv2.INTER_LINEAR,
                                   borderMode=border)

    def render(self, t: float, with_layer: bool = False):
        """Return the (H, W) float32 linear intensity at t (and the index of the visible layer per pixel)."""
        image = None
        layer = np.zeros(self.size, np.int16)
        for k, ((texture, mask, _, _, _), H) in enumerate(zip(self.layers, self.homographies(t))):
            tex = self._warp(texture, H, cv2.BORDER_REFLECT)
            if mask is None:
                image = tex
                continue
            alpha = self._warp(mask, H, cv2.BORDER_CONSTANT)
            image = image + alpha * (tex - image)
            if with_layer:
                layer[alpha > 0.5] = k
        np.clip(image, 0.0, 1.0, out=image)
        return (image, layer) if with_layer else image

    def flow_to(self, t: float, t_prev: float) -> np.ndarray:
        """Return (2, H, W) float32: where each pixel of the view at t lies in the view at ``t_prev`` minus itself."""
        h, w = self.size
        _, layer = self.render(t, with_layer=True)
        u = np.stack([*np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), np.ones((h, w))])
        flow = np.zeros((2, h, w), np.float32)
        for k, (H_now, H_prev) in enumerate(zip(self.homographies(t), self.homographies(t_prev))):
            where = layer == k
            if not where.any():
                continue
            q = (H_prev @ np.linalg.inv(H_now)) @ u[:, where]
            flow[:, where] = (q[:2] / q[2] - u[:2, where]).astype(np.float32)
        return flow


# ------------------------------------------------------------------------------------------------------- sequences
def _sensor(rng: np.random.Generator, config: TrainingSetConfig) -> EventCameraParams:
    """Draw the sequence's event-camera parameters (E2VID's or E2VID+'s thresholds, noise, refractory period)."""
    if rng.random() < 0.5:
        contrast = float(max(0.05, rng.normal(0.18, 0.03)))     # E2VID
    else:
        contrast = float(rng.uniform(0.2, 1.5))                  # E2VID+ / FireNet+
    return EventCameraParams(contrast_pos=contrast, contrast_neg=contrast * float(rng.uniform(0.8, 1.25)),
                             contrast_sigma=contrast * float(rng.uniform(0.0, 0.15)),
                             refractory_s=float(rng.uniform(0.0, config.refractory_max_s)),
                             background_rate_hz=float(rng.uniform(0.0, config.noise_rate_max_hz)),
                             leak_rate_hz=float(rng.uniform(0.0, config.leak_rate_max_hz)))


def make_sequence(rng: np.random.Generator, split: str = "train", config: TrainingSetConfig = TrainingSetConfig(),
                  max_tries: int = 8, photos: tuple[str, ...] = ()) -> tuple[dict[str, np.ndarray], dict]:
    """Return (arrays, metadata) of one random sequence of ``split``.

    arrays: ``voxels`` (L, B, H, W) float16 (normalised voxel grids), ``frames`` (L, H, W) float16 (sharp linear
    intensity at each window's end), ``flow`` (L, 2, H, W) float16 (pixel k -> its place in view k - 1, minus itself;
    zero for k = 0). metadata: the drawn contrast, window rule, speed, events and duration, and ``linear_gamma``
    for a sequence in linear light. ``photos``: paths of the
    split's photographs of a photo folder (see :func:`_texture`); empty: the textures of generator version 3 alone.

    The window rule (and for count windows n) is drawn first. A sequence with fewer than L n H W events is simulated
    again (at most twice) with the same scene, sensor and motion (the generator's state restored) over a longer time,
    at most ``config.duration_extend_max`` (beyond the drawn time the motion's drift runs back and forth:
    :class:`~evio_lib.events.reconstruction.data.SmoothCameraMotion`); only then is n lowered to the events there
    are. A sequence with too few events even for L windows of 0.05 H W events (almost no motion, or very high
    thresholds) is drawn again, up to ``max_tries`` times.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
    h, w, L = config.height, config.width, config.windows
    for _ in range(max_tries):
        rule = "time" if rng.random() < config.time_window_probability else "count"
        fraction = float(np.exp(rng.uniform(np.log(config.fraction_min), np.log(config.fraction_max))))
        needed = L * fraction * h * w if rule == "count" else L * 0.05 * h * w
        duration = float(rng.uniform(config.duration_min, config.duration_max))
        state, drawn_duration = rng.bit_generator.state, duration
        for attempt in range(3):
            scene = _LayeredScene(rng, split, config, drawn_duration, photos)
            params = _sensor(rng, config)
            events, _ = simulate_events(scene.render, 0.0, duration, w, h, params=params, rng=rng,
                                        change_quantile=0.99, dt_min=1e-5)
            events = concatenate_events([events, hot_pixel_events(rng, w, h, duration,
                                                                  config.hot_pixel_fraction_max)])
            if events.size >= needed or duration >= config.duration_extend_max or attempt == 2:
                break                                   # (after the last try ``duration`` stays the one simulated)
            # the same scene and motion sampled for longer (beyond the drawn time the drift runs back and forth):
            # the events grow about in proportion to the time; aim 20 % above the need
            duration = min(config.duration_extend_max, 1.2 * duration * needed / max(events.size, 1))
            rng.bit_generator.state = state
        if events.size >= L * 0.05 * h * w:
            break
    else:
        raise RuntimeError(f"no sequence with {L} windows of >= 0.05 H W events in {max_tries} tries; "
                           f"lower the thresholds' range or raise speed_min")
    fraction_drawn = fraction if rule == "count" else None
    if rule == "time":
        bounds, t_end = time_windows(events, duration / L, t_start=0.0, t_end=duration)
        bounds, t_end = bounds[:L], t_end[:L]
        fraction = float(np.mean(np.diff(bounds, axis=1))) / (h * w)
    else:
        n_events = min(int(round(fraction * h * w)), events.size // L)
        fraction = n_events / (h * w)
        bounds = count_windows(events, n_events)[:L]
        t_end = events["t"][bounds[:, 1] - 1].astype(np.float64)
    voxels = np.stack([voxel_grid(events[a:b], w, h, config.num_bins) for a, b in bounds]).astype(np.float16)
    frames = np.stack([scene.render(float(t)) for t in t_end]).astype(np.float16)
    flow = np.stack([np.zeros((2, h, w), np.float32)] +
                    [scene.flow_to(float(t_end[k]), float(t_end[k - 1])) for k in range(1, L)]).astype(np.float16)
    meta = {"contrast_pos": params.contrast_pos, "contrast_neg": params.contrast_neg, "rule": rule,
            "fraction": fraction, "fraction_drawn": fraction_drawn, "speed": scene.speed, "layers": len(scene.layers),
            "events": int(events.size), "duration": duration, "noise_hz": params.background_rate_hz}
    if scene.linear_gamma is not None:
        meta["linear_gamma"] = scene.linear_gamma
    return {"voxels": voxels, "frames": frames, "flow": flow}, meta


# ------------------------------------------------------------------------------------------------------- the folder
def _sequence_path(folder: Path, split: str, i: int) -> Path:
    return folder / split / f"seq_{i:05d}.npz"


def load_sequence(path: str | Path) -> dict[str, np.ndarray]:
    """Return the arrays of one sequence file (``voxels``, ``frames``, ``flow``), refusing a damaged file by name."""
    from evio_lib.io.cache import load_npz_arrays

    return load_npz_arrays(Path(path), _ARRAYS)


def _write_sequence(folder: Path, split: str, i: int, seed: int, config: TrainingSetConfig,
                    photos: tuple[str, ...] = ()) -> dict:
    """Make sequence i of ``split`` (unless its file is there and readable) and return its metadata."""
    path = _sequence_path(folder, split, i)
    meta_path = path.with_suffix(".json")
    if path.is_file() and meta_path.is_file():
        try:
            return json.loads(meta_path.read_text())
        except (OSError, ValueError):
            pass                                                # a damaged metadata file: make the sequence again
    cv2.setNumThreads(1)                                        # the worker processes are the parallelism
    start = time.process_time()
    arrays, meta = make_sequence(np.random.default_rng([seed, _SPLIT_SEED_OFFSET[split], i]), split, config,
                                 photos=photos)
    meta["cpu_s"] = time.process_time() - start
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, **arrays)                         # voxel grids are mostly zeros: 2.6 -> 1.1 MB
    os.replace(tmp, path)
    tmp_meta = meta_path.with_name(f".{meta_path.name}.{os.getpid()}.tmp")
    tmp_meta.write_text(json.dumps(meta) + "\n")
    os.replace(tmp_meta, meta_path)                             # the .json last: it marks the sequence complete
    return meta


def _manifest(config: TrainingSetConfig, seed: int, counts: dict[str, int], photos: dict | None = None) -> dict:
    settings = asdict(config)
    if not settings["linear_light_fraction"]:                   # a set without linear light keeps v3's manifest
        del settings["linear_light_fraction"]
    manifest = {"format": _FORMAT, "generator": GENERATOR_VERSION, "seed": int(seed), "config": settings,
                "sequences": dict(counts)}
    if photos is not None:                                      # a set made without photographs keeps v3's manifest
        manifest["photos"] = photos
    return manifest


def make_training_set(out: str | Path, sequences: int = 600, val: int = 32, test: int = 32, seed: int = 0,
                      config: TrainingSetConfig = TrainingSetConfig(), workers: int = 2,
                      progress: bool = True, photos: str | Path | None = None) -> dict:
    """Make (or resume) a training set in ``out``; return its summary (sequences, simulated seconds, events, time).

    Args:
        out: the set's folder. A folder holding a set made with other settings (or anything else) is refused.
        sequences: training sequences; val, test: held-out sequences (their own textures and motions).
        seed: the set's seed (sequence i of a split is drawn by ``default_rng([seed, split offset, i])``).
        config: sizes and ranges.
        workers: processes simulating in parallel (joblib); the result does not depend on it.
        progress: a progress bar on stderr.
        photos: a folder of photographs (:mod:`evio_lib.sim.photos`: split by name, so the train, val and test
            sequences see disjoint photographs); None: the bundled textures alone. The manifest records the folder's
            fingerprint (counts and a digest of the names), so a set is never resumed with other photographs.
    """
    for name, value, low in (("sequences", sequences, 1), ("val", val, 1), ("test", test, 0), ("workers", workers, 1),
                             ("seed", seed, 0)):
        if isinstance(value, bool) or int(value) != value or value < low:
            raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    out = Path(out)
    counts = {"train": int(sequences), "val": int(val), "test": int(test)}
    manifest_path = out / MANIFEST_NAME
    fingerprint = photo_fingerprint(photos) if photos is not None else None
    split_photos = {split: tuple(str(p) for p in list_photos(photos, split))
                    if photos is not None and counts[split] else () for split in SPLITS}
    wanted = _manifest(config, seed, counts, fingerprint)
    if manifest_path.is_file():
        try:
            have = json.loads(manifest_path.read_text())
        except (OSError, ValueError) as error:
            raise ValueError(f"{manifest_path} is not a readable training-set manifest ({error}); use another folder")
        keys = ("format", "generator", "seed", "config", "photos")
        if "photos" not in have and wanted.get("photos") is not None and \
                {k: have.get(k) for k in keys[:4]} == {k: wanted.get(k) for k in keys[:4]}:
            raise ValueError(f"{out} holds a training set made without photographs; to resume or extend it, give "
                             f"--photos none (photos=None), or use another folder for a set with photographs")
        if {k: have.get(k) for k in keys} != {k: wanted.get(k) for k in keys}:
            raise ValueError(f"{out} holds a training set made with other settings (seed {have.get('seed')}, "
                             f"generator version {have.get('generator')}, photos {have.get('photos')}, config "
                             f"{have.get('config')}); use another folder to make this one")
    elif out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} is not empty and holds no {MANIFEST_NAME}: not a training set; use an empty folder")
    for split in SPLITS:
        (out / split).mkdir(parents=True, exist_ok=True)
    # the manifest lists what this call asks for: a set made bigger keeps its first sequences; made smaller, the
    # sequences beyond the new counts stay on disk unused
    wanted["complete"] = False
    _write_json(manifest_path, wanted)
    jobs = [(split, i) for split in ("val", "test", "train") for i in range(counts[split])]
    start, cpu_start = time.perf_counter(), time.process_time()
    from joblib import Parallel, delayed

    runner = Parallel(n_jobs=int(workers), return_as="generator", batch_size=1)
    results = runner(delayed(_write_sequence)(out, split, i, int(seed), config, split_photos[split])
                     for split, i in jobs)
    if progress:
        from tqdm.auto import tqdm

        results = tqdm(results, total=len(jobs), desc="simulating sequences", unit="seq")
    metas = list(results)
    wanted["complete"] = True
    _write_json(manifest_path, wanted)
    return {"folder": str(out), "sequences": counts, "simulated_s": float(sum(m["duration"] for m in metas)),
            "events": int(sum(m["events"] for m in metas)), "wall_s": time.perf_counter() - start,
            "cpu_s_workers": float(sum(m.get("cpu_s", 0.0) for m in metas)),
            "cpu_s_main": time.process_time() - cpu_start}


def _write_json(path: Path, value: dict) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(value, indent=1) + "\n")
    os.replace(tmp, path)


def read_training_set(folder: str | Path, split: str) -> tuple[list[Path], TrainingSetConfig]:
    """Return (the sequence files of ``split``, the set's config) of a complete training set.

    Raises ValueError naming the folder when it is not a training set, is incomplete (make it again with the same
    options to finish it) or lacks a sequence its manifest lists.
    """
    folder = Path(folder)
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
    manifest_path = folder / MANIFEST_NAME
    if not manifest_path.is_file():
        raise ValueError(f"{folder} is not a training set: it has no {MANIFEST_NAME} (make one with "
                         f"`python -m evio_lib reconstruct-data --out {folder}`)")
    try:
        manifest = json.loads(manifest_path.read_text())
        config = TrainingSetConfig.from_dict(manifest["config"])
        count = int(manifest["sequences"][split])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{manifest_path} is not a readable training-set manifest ({error})") from None
    if manifest.get("format") != _FORMAT:
        raise ValueError(f"{manifest_path} has format {manifest.get('format')!r}; expected {_FORMAT!r}")
    if not manifest.get("complete"):
        raise ValueError(f"the training set in {folder} is incomplete (interrupted); run reconstruct-data again with "
                         f"the same options to finish it")
    paths = [_sequence_path(folder, split, i) for i in range(count)]
    missing = [p for p in paths if not (p.is_file() and p.with_suffix(".json").is_file())]
    if missing:
        raise ValueError(f"the training set in {folder} lacks {len(missing)} of its {count} {split} sequences "
                         f"(first: {missing[0]}); run reconstruct-data again with the same options to remake them")
    return paths, config


def main_reconstruct_data(args) -> int:
    """Run ``reconstruct-data`` (options: :func:`~evio_lib.events.reconstruction.training_options.
    add_reconstruct_data_arguments`); return the exit code."""
    import argparse

    from evio_lib.io.output_dir import check_output_dir

    if not isinstance(args, argparse.Namespace):
        from evio_lib.events.reconstruction.training_options import add_reconstruct_data_arguments

        args = add_reconstruct_data_arguments(argparse.ArgumentParser()).parse_args(args)
    from evio_lib.cli_args import parse_set_options

    config = TrainingSetConfig.from_dict(parse_set_options(args.set))
    for option, value, low in (("--sequences", args.sequences, 1), ("--val", args.val, 1), ("--test", args.test, 0),
                               ("--jobs", args.jobs, 1), ("--seed", args.seed, 0)):
        if value < low:
            raise ValueError(f"{option} must be >= {low}; got {value}")
    if args.sequences > 1_000_000:
        raise ValueError(f"--sequences must be <= 1000000; got {args.sequences}")
    # not the working folder nor the package; a set folder is resumed, so a non-empty one is checked by its manifest
    check_output_dir(args.out, force=True, name="--out")
    photos = resolve_photo_option(args.photos)
    if photos is None and args.photos == "auto":
        print("note: no photo folder found (../shared/data/photos or $EVIO_PHOTOS); the set uses the bundled "
              "textures alone (give --photos DIR to use yours)")
    summary = make_training_set(args.out, args.sequences, args.val, args.test, args.seed, config, workers=args.jobs,
                                progress=not args.quiet, photos=photos)
    counts = summary["sequences"]
    print(f"made {counts['train']} training, {counts['val']} validation and {counts['test']} test sequences in "
          f"{summary['folder']}: {summary['simulated_s']:.0f} s simulated, {summary['events'] / 1e6:.1f} M events, "
          f"{summary['wall_s']:.0f} s wall ({summary['cpu_s_workers']:.0f} s CPU in the workers)")
    return 0
