"""The "real" training images the project can have offline, split by source into train / val / test.

The thesis trains its detector rounds and the full network on MS-COCO (thesis §3.2.1) and, for the "Events"
variants, replaces about 20 % of it with event frames. Nothing can be downloaded here, so the pool is built from

* **photo** -- every image bundled inside the scikit-image wheel that loads offline and is at least half the
  default output size (read from its ``data`` folder with OpenCV, display-encoded gray); left out:
  ``microaneurysms.png`` (102 x 102 px), ``multipage.tif`` (15 x 10), ``no_time_for_that_tiny.gif`` (25 x 14),
  ``lfw_subset.npy`` (25 x 25 faces), ``multipage_rgb.tif`` (OpenCV cannot decode it), ``chessboard_RGB.png``
  (same picture as the gray one), and the images that scikit-image would download (brain, cells3d, eagle,
  kidney, lily, skin, ...). Both motorcycle stereo views form one source (same scene).
* **room** -- views of ``evio_lib.sim.scene.indoor_room(seed)`` (brick walls with framed photographs, tiled
  floor, textured boxes) from random seeded poses inside the room.
* **aerial** -- views of ``evio_lib.sim.scene.aerial_ground(seed)`` (procedural farmland, roads, villages) from
  120-300 m altitude, random heading, up to 15 degrees of tilt.
* **cards** -- views of a scene of 6-14 textured cards at 1.5-5.5 m in front of a textured wall (occlusions,
  perspective), textured only with the photographs and procedural textures *of the same split*.
* **texture** -- flat procedural textures of ``evio_lib.sim.textures`` (checkerboards, dead leaves, tiles, ...).
* **events** -- event frames handed in through :class:`EventFrames` (the thesis's "Events" variants).
* **folder** -- the photographs of a folder handed in as ``photos=`` (``--photos DIR`` of ``features-train``; see
  :mod:`evio_lib.sim.photos`), one source per photograph, named ``folder:<path relative to the folder>``. Each
  photograph belongs to the split that :func:`evio_lib.sim.photos.photo_split` gives it (a hash of its relative
  path), so the held-out test photographs of the folder (``features-benchmark --dataset photos``) are never
  sources of the train or val pools.

Rendered views (linear intensity) are display-encoded with the sRGB curve so that they look like photographs.
Every pool image is a random crop of a source view, rescaled to the output size (crop side = output side times a
log-uniform factor between 1/1.5 -- at most 1.5x upsampling -- and the largest crop that fits; views with
intensity std below 0.04 are redrawn).

Split (thesis §3.2.2: validation images are held out from the training distribution; the test images feed the
HPatches-style benchmark and must never be trained on). The split is by **source** and fixed (it does not depend
on the seed): see :data:`PHOTO_SPLITS`, :data:`ROOM_SEEDS`, :data:`AERIAL_SEEDS`, :data:`CARD_SEEDS`,
:data:`TEXTURE_SEEDS`. Each source also declares its *content* (the photographs / textures it shows): the test
split shares no content with train or val -- ``indoor_room`` pastes 13 of the bundled photographs on its walls and
boxes, so rooms exist only in train and val and those 13 photographs are never test sources. Val shares some
content with train by design (two of the room photographs are val photo sources), like a held-out part of one
dataset. Event frames split in time: the first 80 % train, the next 10 % val, the last 10 % test, with a gap of
a few frames between blocks.

Labels for the detector rounds come from homographic adaptation (:func:`adaptation_labels`) and are cached as
``.npz`` under ``data/cache/`` (git-ignored), keyed by a name and a fingerprint of the images and parameters.

Reference: thesis §3.2.1-3.2.2, §3.2.5; DeTone et al., "SuperPoint", CVPRW 2018 (training on unlabelled images).
"""
from __future__ import annotations

import hashlib
import json
import math
import multiprocessing
import re
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from numbers import Integral, Real
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset

from evio_lib.features.training.augment import (
    HOMOGRAPHIC_ADAPTATION,
    HOMOGRAPHIC_PAIR,
    HOMOGRAPHIC_REAL,
    PHOTOMETRIC_REAL,
    HomographicConfig,
    PairSample,
    PhotometricConfig,
    Sample,
    as_rng,
    check_image,
    check_keypoints,
    homographic_augment,
    keypoints_to_map,
    photometric_augment,
)
from evio_lib.io.cache import default_cache_dir

__all__ = [
    "SPLITS",
    "PHOTO_FILES",
    "ROOM_PHOTOS",
    "PHOTO_SPLITS",
    "ROOM_SEEDS",
    "AERIAL_SEEDS",
    "CARD_SEEDS",
    "TEXTURE_SEEDS",
    "POOL_MIX",
    "DEFAULT_POOL_SIZE",
    "FOLDER_SHARE",
    "ImageSource",
    "EventFrames",
    "list_sources",
    "load_photo",
    "render_view",
    "random_crop",
    "image_pool",
    "images_fingerprint",
    "save_labels",
    "load_labels",
    "adaptation_labels",
    "RealImages",
]

SPLITS = ("train", "val", "test")
_SPLIT_CODES = {"train": 0, "val": 1, "test": 2}

#: source name -> files in scikit-image's data folder (several files = several views of one scene).
PHOTO_FILES: dict[str, tuple[str, ...]] = {
    "astronaut": ("astronaut.png",), "brick": ("brick.png",), "camera": ("camera.png",), "cell": ("cell.png",),
    "chelsea": ("chelsea.png",), "chessboard": ("chessboard_GRAY.png",), "clock": ("clock_motion.png",),
    "coffee": ("coffee.png",), "coins": ("coins.png",), "colorwheel": ("color.png",), "grass": ("grass.png",),
    "gravel": ("gravel.png",), "horse": ("horse.png",), "hubble": ("hubble_deep_field.jpg",), "ihc": ("ihc.png",),
    "logo": ("logo.png",), "moon": ("moon.png",), "motorcycle": ("motorcycle_left.png", "motorcycle_right.png"),
    "page": ("page.png",), "phantom": ("phantom.png",), "retina": ("retina.jpg",), "rocket": ("rocket.jpg",),
    "text": ("text.png",),
}
#: photographs that ``indoor_room`` pastes into every room (evio_lib.sim.scene.indoor_room's ``photos``).
ROOM_PHOTOS = frozenset({"astronaut", "brick", "camera", "chelsea", "coffee", "coins", "gravel", "grass", "ihc",
                         "motorcycle", "page", "rocket", "text"})
#: photo sources of each split (test: none of the room photographs).
PHOTO_SPLITS: dict[str, tuple[str, ...]] = {
    "train": ("astronaut", "brick", "camera", "chelsea", "chessboard", "colorwheel", "grass", "gravel", "ihc",
              "motorcycle", "page", "phantom", "rocket", "text"),
    "val": ("coffee", "coins"),
    "test": ("cell", "clock", "horse", "hubble", "logo", "moon", "retina"),
}
#: scene seeds of each split; rooms are absent from test because they show train/val photographs.
ROOM_SEEDS: dict[str, tuple[int, ...]] = {"train": tuple(range(8)), "val": (100,), "test": ()}
AERIAL_SEEDS: dict[str, tuple[int, ...]] = {"train": tuple(range(4)), "val": (100,), "test": (200, 201)}
CARD_SEEDS: dict[str, tuple[int, ...]] = {"train": tuple(range(8)), "val": (100,), "test": (200, 201, 202, 203)}
TEXTURE_SEEDS: dict[str, tuple[int, ...]] = {"train": (0, 1, 2), "val": (100,), "test": (200,)}
#: share of each source kind in a pool (event frames, when given, replace ``event_fraction`` of the pool).
POOL_MIX: dict[str, dict[str, float]] = {
    "train": {"photo": 0.30, "room": 0.30, "aerial": 0.15, "cards": 0.15, "texture": 0.10},
    "val": {"photo": 0.30, "room": 0.30, "aerial": 0.15, "cards": 0.15, "texture": 0.10},
    "test": {"photo": 0.30, "aerial": 0.25, "cards": 0.30, "texture": 0.15},
}
DEFAULT_POOL_SIZE = {"train": 800, "val": 100, "test": 60}
#: share of a pool taken by the photographs of a ``photos=`` folder; the kinds of :data:`POOL_MIX` share the rest
#: in their usual proportions. The thesis trains on photographs only (MS-COCO), so the photographs get the larger
#: part; the rendered scenes and textures keep 40 % for the content the photographs lack (rooms, aerial views,
#: occluding cards, repetitive textures).
FOLDER_SHARE = 0.6
_CARD_TEXTURE_KINDS = ("rectangles", "checkerboard", "tiles", "blobs", "stripes", "fractal_noise")
_MAX_UPSCALE = 1.5
_MIN_STD = 0.04
_AERIAL_EXTENT_M = 1500.0


# ============================================================================================== validation
def _check_split(split: Any) -> str:
    if split not in _SPLIT_CODES:
        raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
    return split


def _check_size(size: Any, name: str = "size") -> tuple[int, int]:
    try:
        height, width = (int(v) for v in size)
        ok = (height, width) == tuple(size) and height >= 16 and width >= 16
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{name} must be (height, width) of ints >= 16; got {size!r}")
    return height, width


def _check_seed(seed: Any, name: str = "seed") -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, Integral) or seed < 0:
        raise ValueError(f"{name} must be a non-negative int; got {seed!r}")
    return int(seed)


# ============================================================================================== sources
@dataclass(frozen=True)
class ImageSource:
    """One source of pool images: a photograph, a scene, a texture or a block of event frames.

    Args:
        name: unique name, e.g. ``"photo:camera"``, ``"room:3"``, ``"aerial:200"``, ``"events:flight:test"``.
        split: "train", "val" or "test".
        kind: "photo", "room", "aerial", "cards", "texture", "events" or "folder" (a photograph of a folder).
        content: tags of the pictures/textures it shows (``"photo:camera"``, ``"terrain:200"``, ...); the test
            split's content is disjoint from train's and val's.
        params: what :func:`render_view` needs (files, seed, frames).
    """

    name: str
    split: str
    kind: str
    content: frozenset[str]
    params: dict[str, Any] = field(default_factory=dict, compare=False, hash=False, repr=False)


class EventFrames:
    """Event frames (reconstructed or accumulated, float32 (H, W) in [0, 1], time-ordered) to add to the pool.

    The frames are split in time: the first ``fractions[0]`` train, the next ``fractions[1]`` val, the rest test,
    dropping ``gap`` frames at each boundary so that neighbouring (nearly identical) frames never straddle
    two splits. Pass one or more instances to :func:`image_pool` / :class:`RealImages` (``event_frames=``).

    Args:
        frames: sequence of (H, W) float32 images in [0, 1] (or uint8), in time order, all the same size.
        name: name of the recording (source names are ``events:<name>:<split>``).
        fractions: (train, val, test) fractions, non-negative, summing to 1.
        gap: frames dropped at each split boundary (>= 0).

    >>> ev = EventFrames([np.full((30, 40), i / 100, np.float32) for i in range(100)], name="demo", gap=2)
    >>> len(ev.frames_for("train")), len(ev.frames_for("val")), len(ev.frames_for("test"))
    (80, 8, 8)
    """

    def __init__(self, frames: Sequence[np.ndarray], name: str = "events",
                 fractions: tuple[float, float, float] = (0.8, 0.1, 0.1), gap: int = 5) -> None:
        if isinstance(frames, np.ndarray) and frames.ndim == 3:
            frames = list(frames)
        if not isinstance(frames, Sequence) or len(frames) == 0:
            raise ValueError("frames must be a non-empty sequence of (H, W) float32 images in [0, 1]")
        checked = [check_image(f, f"frames[{i}]") for i, f in enumerate(frames)]
        if len({f.shape for f in checked}) != 1:
            raise ValueError(f"frames must all have the same shape; got {sorted({f.shape for f in checked})}")
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
            raise ValueError(f"name must be a non-empty string of letters, digits, '_', '.', '-'; got {name!r}")
        try:
            fr = tuple(float(f) for f in fractions)
        except (TypeError, ValueError):
            fr = ()
        if len(fr) != 3 or min(fr) < 0 or abs(sum(fr) - 1.0) > 1e-9:
            raise ValueError(f"fractions must be three non-negative numbers summing to 1; got {fractions!r}")
        self.gap = _check_seed(gap, "gap")
        self.frames = checked
        self.name = name
        self.fractions = fr
        n = len(checked)
        edges = np.rint(np.cumsum((0.0,) + fr) * n).astype(int)  # block boundaries in frame indices
        self._ranges = {}
        for i, split in enumerate(SPLITS):
            start = edges[i] + (self.gap if i > 0 else 0)
            self._ranges[split] = range(min(start, edges[i + 1]), edges[i + 1])

    def indices(self, split: str) -> range:
        """Return the frame indices of ``split``."""
        return self._ranges[_check_split(split)]

    def frames_for(self, split: str) -> list[np.ndarray]:
        """Return the frames of ``split`` (time order)."""
        return [self.frames[i] for i in self.indices(split)]

    def source(self, split: str) -> ImageSource:
        """Return the :class:`ImageSource` of this recording's ``split`` block."""
        tag = f"events:{self.name}:{_check_split(split)}"
        return ImageSource(tag, split, "events", frozenset({tag}), {"frames": self.frames_for(split)})


def list_sources(split: str, event_frames: EventFrames | Sequence[EventFrames] | None = None,
                 photos: str | Path | None = None) -> list[ImageSource]:
    """Return the image sources of ``split`` (fixed table, see the module docstring), folder photographs and event
    blocks last.

    Args:
        split: "train", "val" or "test".
        event_frames: optional :class:`EventFrames` (or several) whose block of this split is added.
        photos: optional folder of photographs: one source (kind ``"folder"``) per photograph of this split
            (:func:`evio_lib.sim.photos.list_photos`; ValueError naming the folder when it holds none of the split).

    >>> names = [s.name for s in list_sources("test")]
    >>> "photo:clock" in names, "photo:camera" in names, any(n.startswith("room:") for n in names)
    (True, False, False)
    """
    split = _check_split(split)
    sources: list[ImageSource] = []
    for photo in PHOTO_SPLITS[split]:
        sources.append(ImageSource(f"photo:{photo}", split, "photo", frozenset({f"photo:{photo}"}),
                                   {"files": PHOTO_FILES[photo]}))
    for seed in ROOM_SEEDS[split]:
        content = frozenset({f"room:{seed}"} | {f"photo:{p}" for p in ROOM_PHOTOS})
        sources.append(ImageSource(f"room:{seed}", split, "room", content, {"seed": seed}))
    for seed in AERIAL_SEEDS[split]:
        sources.append(ImageSource(f"aerial:{seed}", split, "aerial", frozenset({f"terrain:{seed}"}), {"seed": seed}))
    for seed in CARD_SEEDS[split]:
        content = frozenset({f"cards:{seed}"} | {f"photo:{p}" for p in PHOTO_SPLITS[split]})
        sources.append(ImageSource(f"cards:{seed}", split, "cards", content, {"seed": seed, "split": split}))
    from evio_lib.sim.textures import PROCEDURAL_KINDS

    for seed in TEXTURE_SEEDS[split]:
        for kind in PROCEDURAL_KINDS:
            tag = f"procedural:{kind}:{seed}"
            sources.append(ImageSource(f"texture:{kind}:{seed}", split, "texture", frozenset({tag}),
                                       {"kind": kind, "seed": seed}))
    if photos is not None:
        from evio_lib.sim.photos import list_photos

        folder = Path(photos)
        for path in list_photos(folder, split):
            tag = f"folder:{path.relative_to(folder).as_posix()}"
            sources.append(ImageSource(tag, split, "folder", frozenset({tag}), {"path": str(path)}))
    if event_frames is not None:
        for ev in _as_event_list(event_frames):
            sources.append(ev.source(split))
    return sources


def _as_event_list(event_frames: Any) -> list[EventFrames]:
    items = [event_frames] if isinstance(event_frames, EventFrames) else list(event_frames)
    for item in items:
        if not isinstance(item, EventFrames):
            raise ValueError(f"event_frames must be an EventFrames or a sequence of them; got {type(item).__name__}")
    if len({item.name for item in items}) != len(items):
        raise ValueError("event_frames must have distinct names")
    return items


# ============================================================================================== views
def _skimage_data_dir() -> Path:
    import skimage

    return Path(skimage.__file__).resolve().parent / "data"


@lru_cache(maxsize=32)
def _load_photo_cached(file: str) -> np.ndarray:
    from evio_lib.sim.textures import read_gray8

    path = _skimage_data_dir() / file
    try:  # read_gray8: cv2.imread's pixels without page.png's iCCP chunk, on which libpng prints a warning
        gray = read_gray8(path)
    except ValueError:
        raise ValueError(f"photo file {file!r} could not be read from {path} (is scikit-image installed?)") from None
    image = gray.astype(np.float32) / np.float32(255.0)
    image.setflags(write=False)
    return image


def load_photo(name: str, index: int = 0) -> np.ndarray:
    """Return a bundled scikit-image photograph as a float32 (H, W) gray image in [0, 1] (display-encoded).

    Read with OpenCV straight from scikit-image's installed ``data`` folder (never downloaded).

    Args:
        name: a key of :data:`PHOTO_FILES` (e.g. ``"camera"``).
        index: which file of a multi-view source (the motorcycle stereo pair has two).

    >>> load_photo("camera").shape
    (512, 512)
    """
    if name not in PHOTO_FILES:
        raise ValueError(f"name must be one of {sorted(PHOTO_FILES)}; got {name!r}")
    files = PHOTO_FILES[name]
    if isinstance(index, bool) or not isinstance(index, Integral) or not 0 <= index < len(files):
        raise ValueError(f"index must be an int in [0, {len(files)}) for photo {name!r}; got {index!r}")
    return _load_photo_cached(files[index]).copy()


def _srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Return display values of linear intensities: ``12.92 c`` below 0.0031308, else ``1.055 c^(1/2.4) - 0.055``."""
    c = np.clip(linear, 0.0, 1.0).astype(np.float32)
    low = c * np.float32(12.92)
    high = np.float32(1.055) * np.power(c, np.float32(1.0 / 2.4)) - np.float32(0.055)
    return np.clip(np.where(c <= 0.0031308, low, high), 0.0, 1.0).astype(np.float32)


def _look_at(forward: np.ndarray, roll: float) -> np.ndarray:
    """Return R_CtoG of a camera looking along ``forward`` (G, z up), x right, y down, rolled by ``roll`` rad."""
    z = forward / np.linalg.norm(forward)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-6 else np.array([1.0, 0.0, 0.0])
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    R = np.stack([x, y, z], axis=1)  # columns: camera axes in G
    return R @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _camera(rng: np.random.Generator, shape: tuple[int, int], fov_deg: tuple[float, float]) -> Any:
    from evio_lib.geometry.camera import PinholeRadtan

    height, width = shape
    fov = math.radians(rng.uniform(*fov_deg))
    f = (width / 2.0) / math.tan(fov / 2.0)  # f = (W / 2) / tan(hfov / 2)
    return PinholeRadtan(fx=f, fy=f, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0, width=width, height=height)


@lru_cache(maxsize=3)
def _room(seed: int) -> Any:
    from evio_lib.sim.scene import indoor_room

    return indoor_room(seed)


@lru_cache(maxsize=2)
def _aerial(seed: int) -> Any:
    from evio_lib.sim.scene import aerial_ground

    return aerial_ground(seed, extent_m=_AERIAL_EXTENT_M)


@lru_cache(maxsize=2)
def _cards(split: str, seed: int) -> Any:
    """Return the cards scene (split, seed): a textured back wall and 6-14 textured cards in front of it."""
    from evio_lib.sim.scene import Scene, TexturedPlane
    from evio_lib.sim.textures import procedural_texture, rescale_contrast, srgb_to_linear

    rng = np.random.default_rng([seed, 7])
    textures: list[np.ndarray] = []
    for photo in PHOTO_SPLITS[split]:  # only this split's photographs
        for index in range(len(PHOTO_FILES[photo])):
            image = load_photo(photo, index)
            scale = min(1.0, 512.0 / max(image.shape))
            image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else image
            textures.append(rescale_contrast(srgb_to_linear(np.clip(image, 0, 1)), 0.05, 0.95))
    for _ in range(8):
        kind = _CARD_TEXTURE_KINDS[int(rng.integers(len(_CARD_TEXTURE_KINDS)))]
        tex = procedural_texture(kind, (256, 256), rng, scale_px=float(rng.uniform(12, 48)))
        textures.append(rescale_contrast(tex, 0.05, 0.95))

    def pick() -> np.ndarray:
        return textures[int(rng.integers(len(textures)))]

    depth = rng.uniform(6.0, 10.0)
    planes = [TexturedPlane([-15.0, -10.0, depth], [30.0, 0.0, 0.0], [0.0, 20.0, 0.0], pick(), "wall",
                            texture_repeat=(3.0, 2.0))]
    for i in range(int(rng.integers(6, 15))):
        z = rng.uniform(1.5, 5.5)
        centre = np.array([rng.uniform(-0.6, 0.6) * z, rng.uniform(-0.45, 0.45) * z, z])
        tex = pick()
        width = rng.uniform(0.4, 1.6)
        height = width * tex.shape[0] / tex.shape[1] * rng.uniform(0.8, 1.25)
        tilt = rng.normal(0.0, 0.5, 3) * [1.0, 1.0, 0.5]  # rotation vector: tilts up to ~50 deg, some in-plane spin
        R, _ = cv2.Rodrigues(tilt)
        u, v = R[:, 0] * width, R[:, 1] * height  # card axes (right, down), facing the camera at the origin
        planes.append(TexturedPlane(centre - u / 2 - v / 2, u, v, tex, f"card {i}"))
    return Scene(planes, background=float(rng.uniform(0.1, 0.9)))


def render_view(source: ImageSource, rng: np.random.Generator | int, shape: tuple[int, int] = (300, 400)
                ) -> np.ndarray:
    """Return one view (float32 (H, W) in [0, 1]) of a source: the photo/texture/frame itself, or a seeded render.

    Scenes are rendered at ``shape`` from a random pose (room: inside the room, mostly toward the boxes; aerial:
    120-300 m altitude; cards: near the origin looking along +z) with a 50-80 degree horizontal field of view
    and display-encoded (sRGB). Photos (bundled or of a folder) and event frames ignore ``shape``.

    Args:
        source: an :class:`ImageSource` from :func:`list_sources`.
        rng: Generator or seed (pose, frame choice).
        shape: (height, width) of rendered views.
    """
    gen = as_rng(rng)
    if not isinstance(source, ImageSource):
        raise ValueError(f"source must be an ImageSource; got {type(source).__name__}")
    if source.kind == "photo":
        files = source.params["files"]
        return load_photo(source.name.split(":", 1)[1], int(gen.integers(len(files))))
    if source.kind == "folder":
        from evio_lib.sim.photos import load_photo as load_folder_photo

        return load_folder_photo(source.params["path"]).copy()  # the cached array stays untouched
    if source.kind == "events":
        frames = source.params["frames"]
        if not frames:
            raise ValueError(f"source {source.name!r} has no frames in its split")
        return frames[int(gen.integers(len(frames)))].copy()
    if source.kind == "texture":
        from evio_lib.sim.textures import procedural_texture

        size = _check_size(shape, "shape")
        seed = source.params["seed"]
        return procedural_texture(source.params["kind"], size, np.random.default_rng([seed, 11]),
                                  scale_px=float(np.random.default_rng([seed, 12]).uniform(12, 40)))
    size = _check_size(shape, "shape")
    if source.kind == "room":
        scene = _room(source.params["seed"])
        camera = _camera(gen, size, (50.0, 80.0))
        position = np.array([gen.uniform(-1.5, 1.5), gen.uniform(-2.5, 0.5), gen.uniform(0.9, 2.0)])
        if gen.random() < 0.6:  # toward the boxes
            target = np.array([gen.uniform(-1.5, 1.5), gen.uniform(1.5, 3.5), gen.uniform(0.0, 1.0)])
            forward = target - position
        else:
            yaw, pitch = gen.uniform(-np.pi, np.pi), gen.uniform(-0.3, 0.3)
            forward = np.array([math.cos(pitch) * math.sin(yaw), math.cos(pitch) * math.cos(yaw), math.sin(pitch)])
        R_CtoG = _look_at(forward, gen.uniform(-0.3, 0.3))
        return _srgb_encode(scene.render_intensity(camera, R_CtoG, position))
    if source.kind == "aerial":
        scene = _aerial(source.params["seed"])
        camera = _camera(gen, size, (50.0, 70.0))
        position = np.array([gen.uniform(-300.0, 300.0), gen.uniform(-300.0, 300.0), gen.uniform(120.0, 300.0)])
        heading = gen.uniform(-np.pi, np.pi)
        tilt = gen.uniform(0.0, math.radians(15.0))
        azimuth = gen.uniform(-np.pi, np.pi)
        forward = np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), -math.cos(tilt)])
        z = forward
        x = np.array([math.cos(heading), math.sin(heading), 0.0])
        x = x - z * (x @ z)
        x /= np.linalg.norm(x)
        R_CtoG = np.stack([x, np.cross(z, x), z], axis=1)  # looking down, image x along the heading
        return _srgb_encode(scene.render_intensity(camera, R_CtoG, position))
    if source.kind == "cards":
        scene = _cards(source.params["split"], source.params["seed"])
        camera = _camera(gen, size, (50.0, 80.0))
        R_CtoG, _ = cv2.Rodrigues(gen.normal(0.0, 0.12, 3))
        position = gen.uniform(-0.3, 0.3, 3)
        return _srgb_encode(scene.render_intensity(camera, R_CtoG, position))
    raise ValueError(f"source.kind must be photo, room, aerial, cards, texture, events or folder; "
                     f"got {source.kind!r}")


_RENDERED_KINDS = ("room", "aerial", "cards")  # sources drawn by the renderer (their size sets the scale)


def random_crop(image: np.ndarray, size: tuple[int, int], rng: np.random.Generator | int,
                max_upscale: float = _MAX_UPSCALE) -> np.ndarray:
    """Return a random crop of ``image`` rescaled to ``size`` (float32), same aspect ratio as the output.

    Crop side = output side times ``z``, with ``log z`` uniform between ``log(1 / max_upscale)`` and the largest
    crop that fits (an image smaller than ``size / max_upscale`` is used whole and upscaled further); area
    averaging when shrinking, bilinear when enlarging.

    Args:
        image: (H, W) float32 image in [0, 1].
        size: (height, width) of the output.
        rng: Generator or seed.
        max_upscale: largest enlargement factor (>= 1).

    >>> crop = random_crop(np.random.default_rng(0).random((100, 200), dtype=np.float32), (40, 60), 0)
    >>> crop.shape, crop.dtype
    ((40, 60), dtype('float32'))
    """
    img = check_image(image)
    height, width = _check_size(size)
    if isinstance(max_upscale, bool) or not isinstance(max_upscale, Real) or not max_upscale >= 1.0:
        raise ValueError(f"max_upscale must be a number >= 1; got {max_upscale!r}")
    gen = as_rng(rng)
    src_h, src_w = img.shape
    z_max = min(src_h / height, src_w / width)  # largest crop factor that fits
    z_min = min(1.0 / float(max_upscale), z_max)
    z = math.exp(gen.uniform(math.log(z_min), math.log(z_max))) if z_max > z_min else z_max
    crop_h = int(min(src_h, max(1, round(height * z))))
    crop_w = int(min(src_w, max(1, round(width * z))))
    y0 = int(gen.integers(0, src_h - crop_h + 1))
    x0 = int(gen.integers(0, src_w - crop_w + 1))
    crop = img[y0 : y0 + crop_h, x0 : x0 + crop_w]
    interpolation = cv2.INTER_AREA if crop_h >= height else cv2.INTER_LINEAR
    return np.clip(cv2.resize(crop, (width, height), interpolation=interpolation), 0.0, 1.0).astype(np.float32)


def _allocate(total: int, shares: dict[str, float]) -> dict[str, int]:
    """Return integer counts proportional to ``shares`` summing to ``total`` (largest remainder)."""
    keys = list(shares)
    raw = np.array([shares[k] for k in keys], float)
    raw = raw / raw.sum() * total
    counts = np.floor(raw).astype(int)
    for i in np.argsort(-(raw - counts), kind="stable")[: total - counts.sum()]:
        counts[i] += 1
    return dict(zip(keys, counts.tolist()))


_POOL_CHUNK = 8  # pool images per task of a worker process


def _check_workers(workers: object) -> int:
    if isinstance(workers, bool) or not isinstance(workers, Integral) or workers < 1:
        raise ValueError(f"workers must be an int >= 1 (processes that render the pool); got {workers!r}")
    return int(workers)


def _pool_image(j: int, source: ImageSource, seed: int, split: str, shape: tuple[int, int],
                size: tuple[int, int]) -> tuple[int, np.ndarray]:
    """Return (j, pool image j): a random crop of a view of ``source`` from ``default_rng([seed, split, j])``."""
    rng = np.random.default_rng([seed, _SPLIT_CODES[split], j])
    for _ in range(8):  # redraw low-contrast crops (black borders of retina/hubble, blank walls)
        crop = random_crop(render_view(source, rng, shape), size, rng)
        if float(crop.std()) >= _MIN_STD:
            break
    return j, crop


def _pool_chunk(tasks: Sequence[tuple]) -> list[tuple[int, np.ndarray]]:
    """Return the pool images of several tasks (one worker process's share)."""
    return [_pool_image(*task) for task in tasks]


def image_pool(split: str, seed: int = 0, size: tuple[int, int] = (240, 320), n_images: int | None = None,
               event_frames: EventFrames | Sequence[EventFrames] | None = None, event_fraction: float = 0.2,
               return_sources: bool = False, progress: bool = False, render_zoom: float = 1.0,
               workers: int = 1, photos: str | Path | None = None) -> list[np.ndarray] | tuple[list, list[str]]:
    """Return the pool of ``split``: a list of float32 (H, W) images in [0, 1] (random crops of the split's sources).

    Images are shared among source kinds by :data:`POOL_MIX` (largest remainder) and round-robin among the
    sources of a kind (the folder's photographs in a seeded random order); with ``event_frames`` a fraction ``event_fraction`` of the pool (thesis: about 20 %) comes
    from the event frames of this split instead. With ``photos`` (a folder) the folder's photographs of this split
    take :data:`FOLDER_SHARE` of the rest and the kinds of :data:`POOL_MIX` share what remains in their usual
    proportions; without it the pool is exactly the one without the option. Image j uses
    ``default_rng([seed, split, j])``: the pool is deterministic for a given seed, and which sources belong to a
    split never depends on the seed.

    Args:
        split: "train", "val" or "test".
        seed: seed of the crops and render poses.
        size: (height, width) of every image (thesis: 240 x 320).
        n_images: pool size (default :data:`DEFAULT_POOL_SIZE`).
        event_frames: optional :class:`EventFrames` (or several) -- the "Events" variants.
        event_fraction: share of event-frame images when ``event_frames`` is given, in [0, 1].
        return_sources: also return the source name of every image.
        progress: show a tqdm progress bar.
        render_zoom: rendered scenes (room, aerial, cards) are drawn at ``render_zoom`` times the usual render size
            before the random crop, so that crops show the scene at 1 to ``1.87 render_zoom`` times the pixels per
            radian of a whole view at ``size`` (log-uniform) instead of 1 to 1.87. Training at 120 x 160 with
            ``render_zoom=4`` covers the content scale of the benchmark's 480 x 640 test views. Photos, textures and
            event frames ignore it (photos already span native to 4x downsampled crops; textures keep their pixel
            scale). 1 (default) leaves the pool exactly as before.
        workers: processes that render the pool (1: this process). The result does not depend on it (image j
            has its own generator); it only changes the time (per image:
            docs/results/speed.md#small-costs-behind-the-codes-choices). Needs the ``fork`` start method (Linux);
            elsewhere the pool is rendered here.
        photos: optional folder of photographs (:func:`list_sources`); its views are random crops of the
            photographs, like the bundled photos'.

    Reference: thesis §3.2.1-3.2.2.

    >>> pool, names = image_pool("test", seed=0, size=(60, 80), n_images=4, return_sources=True)
    >>> len(pool), pool[0].shape, pool[0].dtype, sorted({n.split(":")[0] for n in names})
    (4, (60, 80), dtype('float32'), ['aerial', 'cards', 'photo', 'texture'])
    """
    split = _check_split(split)
    seed = _check_seed(seed)
    height, width = _check_size(size)
    n_total = DEFAULT_POOL_SIZE[split] if n_images is None else n_images
    if isinstance(n_total, bool) or not isinstance(n_total, Integral) or n_total < 0:
        raise ValueError(f"n_images must be a non-negative int; got {n_images!r}")
    if isinstance(event_fraction, bool) or not isinstance(event_fraction, Real) or not 0.0 <= event_fraction <= 1.0:
        raise ValueError(f"event_fraction must be a number in [0, 1]; got {event_fraction!r}")
    if isinstance(render_zoom, bool) or not isinstance(render_zoom, Real) or not 1.0 <= render_zoom <= 16.0:
        raise ValueError(f"render_zoom must be a number in [1, 16]; got {render_zoom!r}")
    n_workers = _check_workers(workers)
    sources = list_sources(split, event_frames, photos)
    by_kind: dict[str, list[ImageSource]] = {}
    for source in sources:
        if source.kind != "events" or source.params["frames"]:
            by_kind.setdefault(source.kind, []).append(source)
    shares = {k: v for k, v in POOL_MIX[split].items() if k in by_kind}
    if "folder" in by_kind:  # the folder takes FOLDER_SHARE, the usual kinds the rest in their proportions
        total_share = sum(shares.values())
        shares = {k: (1.0 - FOLDER_SHARE) * v / total_share for k, v in shares.items()} | {"folder": FOLDER_SHARE}
    n_events = int(round(event_fraction * n_total)) if "events" in by_kind else 0
    counts = _allocate(int(n_total) - n_events, shares)
    if n_events:
        counts["events"] = n_events
    # assignment: image j -> source (round-robin within a kind, start rotated by the seed)
    plan: list[ImageSource] = []
    for kind, count in counts.items():
        members = by_kind[kind]
        if kind == "folder":  # a seeded order: a pool smaller than the folder draws from all its sub-folders
            members = [members[i] for i in np.random.default_rng([seed, 6]).permutation(len(members))]
        offset = int(np.random.default_rng([seed, 5]).integers(len(members)))
        plan += [members[(t + offset) % len(members)] for t in range(count)]
    render_shape = (int(math.ceil(1.25 * height)), int(math.ceil(1.25 * width)))
    zoomed_shape = (int(math.ceil(1.25 * render_zoom * height)), int(math.ceil(1.25 * render_zoom * width)))
    images: list[np.ndarray | None] = [None] * len(plan)
    order = sorted(range(len(plan)), key=lambda j: plan[j].name)  # one source at a time: scenes built once
    tasks = [(j, plan[j], seed, split, zoomed_shape if plan[j].kind in _RENDERED_KINDS else render_shape,
              (height, width)) for j in order]
    bar: Any = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), desc=f"image pool ({split})", unit="img")
    if n_workers > 1 and len(tasks) > 1 and "fork" in multiprocessing.get_all_start_methods():
        # contiguous chunks of the source-sorted order, so that each process builds few scenes
        chunks = [tasks[k:k + _POOL_CHUNK] for k in range(0, len(tasks), _POOL_CHUNK)]
        context = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(min(n_workers, len(chunks)), mp_context=context) as executor:
            for done in executor.map(_pool_chunk, chunks):  # loop over finished chunks, in order
                for j, crop in done:
                    images[j] = crop
                if bar is not None:
                    bar.update(len(done))
    else:
        for task in tasks:  # loop over pool images
            j, crop = _pool_image(*task)
            images[j] = crop
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    result = [img for img in images if img is not None]
    if return_sources:
        return result, [s.name for s in plan]
    return result


# ============================================================================================== label cache
def images_fingerprint(images: Sequence[np.ndarray], extra: Any = None) -> str:
    """Return a SHA-1 hex digest of the images (shape, float32 bytes) and of ``extra`` (JSON-serialisable).

    >>> a = [np.zeros((2, 2), np.float32)]
    >>> same = images_fingerprint(a) == images_fingerprint([np.zeros((2, 2), np.float32)])
    >>> same, images_fingerprint(a, extra=1) == images_fingerprint(a)
    (True, False)
    """
    digest = hashlib.sha1()
    for i, image in enumerate(images):
        img = check_image(image, f"images[{i}]")
        digest.update(repr(img.shape).encode())
        digest.update(img.tobytes())
    digest.update(json.dumps(extra, sort_keys=True, default=str).encode())
    return digest.hexdigest()


def save_labels(path: str | Path, labels: Sequence[np.ndarray], fingerprint: str = "",
                meta: dict[str, Any] | None = None) -> Path:
    """Write per-image keypoints to an ``.npz`` (keypoints concatenated + offsets) and return the path.

    Args:
        path: file to write (parent folders are created).
        labels: one (N_i, 2) (x, y) array per image.
        fingerprint: string stored to validate the cache (see :func:`images_fingerprint`).
        meta: JSON-serialisable description (parameters, model name).
    """
    arrays = [check_keypoints(k, f"labels[{i}]").astype(np.float32) for i, k in enumerate(labels)]
    offsets = np.cumsum([0] + [len(a) for a in arrays]).astype(np.int64)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp.npz")
    np.savez_compressed(tmp, keypoints=np.concatenate(arrays) if arrays else np.zeros((0, 2), np.float32),
                        offsets=offsets, fingerprint=np.array(fingerprint),
                        meta=np.array(json.dumps(meta or {}, sort_keys=True, default=str)))
    tmp.replace(out)  # atomic: a crash never leaves a half-written cache
    return out


def load_labels(path: str | Path, fingerprint: str | None = None) -> list[np.ndarray] | None:
    """Return the per-image keypoints saved by :func:`save_labels`, or None if absent or the fingerprint differs.

    A damaged file (empty, truncated) is deleted with a note on stderr and counts as absent (None: labelled again).
    """
    from evio_lib.io.cache import CacheError, discard_damaged_cache, load_npz_arrays

    file = Path(path)
    if not file.is_file():
        return None
    try:
        data = load_npz_arrays(file, ("fingerprint", "keypoints", "offsets"))
        if fingerprint is not None and str(data["fingerprint"]) != fingerprint:
            return None
        keypoints, offsets = data["keypoints"], data["offsets"]
        if offsets.ndim != 1 or offsets.size < 1 or offsets[-1] != len(keypoints) or np.any(np.diff(offsets) < 0):
            raise CacheError(file, f"offsets do not index the {len(keypoints)} keypoints")
    except CacheError as error:
        discard_damaged_cache(error, "labelling the images again")
        return None
    return [keypoints[offsets[i] : offsets[i + 1]].copy() for i in range(len(offsets) - 1)]


def adaptation_labels(images: Sequence[np.ndarray], heatmap_fn: Callable[[np.ndarray], Any], cache_name: str | None,
                      *, rng: np.random.Generator | int = 0, cache_dir: str | Path | None = None,
                      recompute: bool = False, progress: bool = False, n_homographies: int = 100,
                      config: HomographicConfig = HOMOGRAPHIC_ADAPTATION, batch_size: int = 16,
                      threshold: float = 0.015, nms_radius: int = 4, border: int = 4,
                      max_keypoints: int | None = None) -> list[np.ndarray]:
    """Return homographic-adaptation keypoints for every image, from the ``.npz`` cache when it is valid.

    The cache file is ``<cache_dir>/labels_<cache_name>.npz``; it is reused only when its fingerprint (images,
    seed and adaptation parameters) matches -- name the detector in ``cache_name`` (e.g.
    ``"magicpoint_round1_train"``), since the detector itself cannot be fingerprinted. ``cache_name=None``
    disables caching.

    Args:
        images: sequence of (H, W) float32 images in [0, 1].
        heatmap_fn: detector, ``images (B, H, W) -> heatmaps (B, H, W)``.
        cache_name: file-name stem (letters, digits, '_', '.', '-') or None.
        rng: seed (int) or Generator (a Generator disables caching: its state cannot be fingerprinted).
        cache_dir: folder (default :func:`evio_lib.io.cache.default_cache_dir`).
        recompute: ignore an existing cache and overwrite it.
        progress: tqdm progress bar.
        n_homographies, config, batch_size, threshold, nms_radius, border, max_keypoints: see
            :func:`evio_lib.features.training.adaptation.label_images`.

    Reference: thesis §3.2.5.2 (exporting detections, N = 100).
    """
    from evio_lib.features.training.adaptation import label_images

    if cache_name is not None and (not isinstance(cache_name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", cache_name)):
        raise ValueError(f"cache_name must be letters, digits, '_', '.', '-' (or None); got {cache_name!r}")
    params = {"seed": rng if isinstance(rng, Integral) else None, "n_homographies": n_homographies,
              "config": config.homography_kwargs() | {"margin": config.valid_border_margin}, "threshold": threshold,
              "nms_radius": nms_radius, "border": border, "max_keypoints": max_keypoints}
    use_cache = cache_name is not None and not isinstance(rng, np.random.Generator)
    path = Path(cache_dir if cache_dir is not None else default_cache_dir()) / f"labels_{cache_name}.npz"
    fingerprint = images_fingerprint(images, params) if use_cache else ""
    if use_cache and not recompute:
        cached = load_labels(path, fingerprint)
        if cached is not None and len(cached) == len(images):
            return cached
    labels = label_images(images, heatmap_fn, rng, n_homographies=n_homographies, config=config,
                          batch_size=batch_size, threshold=threshold, nms_radius=nms_radius, border=border,
                          max_keypoints=max_keypoints, progress=progress)
    if use_cache:
        save_labels(path, labels, fingerprint, {"name": cache_name, **params, "n_images": len(images)})
    return labels


# ============================================================================================== dataset
class RealImages(Dataset):
    """Torch dataset of pool images with augmentation and (optional) homographic-adaptation labels.

    ``dataset[i]`` is a :class:`~evio_lib.features.training.augment.Sample` (image (1, H, W), keypoint_map (H, W),
    valid_mask (H, W), float32 tensors) or, with ``pairs=True``, a
    :class:`~evio_lib.features.training.augment.PairSample`
    (image and its warped copy, their keypoint maps and masks, and the homography) for detector+descriptor
    training (thesis Eq. 8). Augmentation (default on for train only; thesis §3.2.2 leaves validation images
    unmodified): single mode -- photometric then homographic (``HOMOGRAPHIC_REAL``); pair mode -- the image gets
    photometric augmentation only, the warped copy ``pair_homographic`` (always, also for val) plus its own
    photometric draw. Without labels ``has_labels`` is False and keypoint maps are all zero. Draws depend on
    (seed, index, epoch): call :meth:`set_epoch` every epoch.

    A detector round (thesis §3.2.5.3) in three lines::

        images = image_pool("train", seed=0)                                   # or with event_frames=...
        labels = adaptation_labels(images, magicpoint_heatmaps, "magicpoint_r1_train")   # cached .npz
        data = RealImages(images, split="train", keypoints=labels)            # pairs=True for DetDesc

    Args:
        images: the images (e.g. from :func:`image_pool`); default ``image_pool(split, seed, size, n_images,
            event_frames, event_fraction)``.
        split, seed, size, n_images, event_frames, event_fraction, photos: passed to :func:`image_pool` when
            ``images`` is None (``seed`` also seeds the augmentation).
        keypoints: optional labels, one (N_i, 2) (x, y) array per image (e.g. :func:`adaptation_labels`).
        augment: None -> only for split "train".
        photometric, homographic: augmentation configs (None disables that part).
        pairs: return warped pairs.
        pair_homographic: homographies of the warped copy.

    >>> data = RealImages([np.full((32, 48), 0.5, np.float32)], keypoints=[np.array([[10.0, 20.0]])], augment=False)
    >>> item = data[0]
    >>> tuple(item.image.shape), float(item.keypoint_map[20, 10]), data.has_labels
    ((1, 32, 48), 1.0, True)
    """

    def __init__(self, images: Sequence[np.ndarray] | None = None, *, split: str = "train", seed: int = 0,
                 size: tuple[int, int] = (240, 320), n_images: int | None = None,
                 event_frames: EventFrames | Sequence[EventFrames] | None = None, event_fraction: float = 0.2,
                 photos: str | Path | None = None,
                 keypoints: Sequence[np.ndarray] | None = None, augment: bool | None = None,
                 photometric: PhotometricConfig | None = PHOTOMETRIC_REAL,
                 homographic: HomographicConfig | None = HOMOGRAPHIC_REAL, pairs: bool = False,
                 pair_homographic: HomographicConfig = HOMOGRAPHIC_PAIR) -> None:
        self.split = _check_split(split)
        self.seed = _check_seed(seed)
        if images is None:
            images = image_pool(split, self.seed, size, n_images, event_frames, event_fraction, photos=photos)
        if len(images) == 0:
            raise ValueError("images must hold at least one image; got an empty pool")
        self.images = [check_image(img, f"images[{i}]") for i, img in enumerate(images)]
        if len({img.shape for img in self.images}) != 1:
            raise ValueError(f"images must all have the same shape; got {sorted({i.shape for i in self.images})}")
        if keypoints is not None:
            if len(keypoints) != len(self.images):
                raise ValueError(f"keypoints must hold one (N, 2) array per image ({len(self.images)}); "
                                 f"got {len(keypoints)}")
            keypoints = [check_keypoints(k, f"keypoints[{i}]") for i, k in enumerate(keypoints)]
        if photometric is not None and not isinstance(photometric, PhotometricConfig):
            raise ValueError(f"photometric must be a PhotometricConfig or None; got {type(photometric).__name__}")
        for name, cfg in (("homographic", homographic), ("pair_homographic", pair_homographic)):
            if cfg is not None and not isinstance(cfg, HomographicConfig):
                raise ValueError(f"{name} must be a HomographicConfig or None; got {type(cfg).__name__}")
        if pairs and pair_homographic is None:
            raise ValueError("pair_homographic must be a HomographicConfig when pairs=True; got None")
        self.keypoints = keypoints
        self.has_labels = keypoints is not None
        self.augment = (self.split == "train") if augment is None else bool(augment)
        self.photometric = photometric
        self.homographic = homographic
        self.pairs = bool(pairs)
        self.pair_homographic = pair_homographic
        self.shape = self.images[0].shape
        self.epoch = 0

    def __len__(self) -> int:
        return len(self.images)

    def set_epoch(self, epoch: int) -> None:
        """Change the augmentation draws for a new epoch."""
        self.epoch = _check_seed(epoch, "epoch")

    def _index(self, index: int) -> int:
        if isinstance(index, bool) or not isinstance(index, Integral):
            raise ValueError(f"index must be an int; got {index!r}")
        i = int(index) + (len(self) if index < 0 else 0)
        if not 0 <= i < len(self):
            raise IndexError(f"index {index} out of range for {len(self)} images")
        return i

    def sample(self, index: int) -> dict[str, Any]:
        """Return item ``index`` as NumPy arrays: image, keypoints, valid_mask (+ warped_* and homography for pairs)."""
        i = self._index(index)
        rng = np.random.default_rng([self.seed, _SPLIT_CODES[self.split], i, self.epoch, 2])
        image = self.images[i]
        keypoints = self.keypoints[i] if self.keypoints is not None else np.zeros((0, 2))
        mask = np.ones(self.shape, bool)
        if self.pairs:
            warped = homographic_augment(image, keypoints, rng, self.pair_homographic)
            warped_image = warped.image
            if self.augment and self.photometric is not None:
                image = photometric_augment(image, rng, self.photometric)
                warped_image = photometric_augment(warped_image, rng, self.photometric)
            return {"image": image, "keypoints": keypoints, "valid_mask": mask, "warped_image": warped_image,
                    "warped_keypoints": warped.keypoints, "warped_valid_mask": warped.valid_mask,
                    "homography": warped.homography}
        if self.augment:
            if self.photometric is not None:
                image = photometric_augment(image, rng, self.photometric)
            if self.homographic is not None:
                image, keypoints, mask, _ = homographic_augment(image, keypoints, rng, self.homographic)
        return {"image": image, "keypoints": keypoints, "valid_mask": mask}

    def __getitem__(self, index: int) -> Sample | PairSample:
        item = self.sample(index)

        def tensors(image: np.ndarray, keypoints: np.ndarray, mask: np.ndarray) -> tuple[Any, Any, Any]:
            label = keypoints_to_map(keypoints, self.shape, mask)
            return (torch.from_numpy(np.ascontiguousarray(image, np.float32)[None].copy()), torch.from_numpy(label),
                    torch.from_numpy(mask.astype(np.float32)))

        base = tensors(item["image"], item["keypoints"], item["valid_mask"])
        if not self.pairs:
            return Sample(*base)
        warped = tensors(item["warped_image"], item["warped_keypoints"], item["warped_valid_mask"])
        return PairSample(*base, *warped, torch.from_numpy(item["homography"].astype(np.float32)))
