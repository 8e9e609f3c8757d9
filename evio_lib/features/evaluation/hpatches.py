"""Image pairs related by a known homography, and a loader for the real HPatches folder layout.

HPatches (Balntas et al., CVPR 2017) has one folder per scene: ``i_<name>`` (illumination changes, identity-like
geometry) or ``v_<name>`` (viewpoint changes), each with a reference image ``1.ppm``, five more images ``2.ppm`` ..
``6.ppm`` and the ground-truth homographies ``H_1_2`` .. ``H_1_6`` (3 x 3 text, mapping pixels of image 1 to pixels of
image k). The data set cannot be downloaded here; anyone who has it passes its root folder, and
``evio_lib.features.evaluation.benchmark`` runs the official benchmark from the same command as the built-in one.

Resizing (the thesis evaluates at 240 x 320 for repeatability and 480 x 640 for homography estimation) changes the
pixel coordinates of both images, so the homography is updated: if ``S1`` and ``S2`` map original to resized pixels,
``H' = S2 H S1^-1``. Pixel centres sit at integer coordinates (OpenCV's convention), so scaling by s about the image
corner maps ``x -> s (x + 0.5) - 0.5``.

Reference: thesis §3.2.3 and §3.2.6; Balntas, Lenc, Vedaldi & Mikolajczyk, "HPatches: A benchmark and evaluation of
handcrafted and learned local descriptors", CVPR 2017; SuperPoint's HPatches loader (resize, then centre crop).
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from numbers import Integral
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ImagePair",
    "SPLIT_PREFIXES",
    "read_gray_image",
    "resize_image",
    "resize_pair",
    "hpatches_scenes",
    "iter_hpatches_pairs",
]

SPLIT_PREFIXES = {"illumination": "i_", "viewpoint": "v_"}  # scene folder prefix of each HPatches split
N_IMAGES_PER_SCENE = 6  # 1.ppm (reference) .. 6.ppm
RESIZE_MODES = ("crop", "stretch")


@dataclass(frozen=True, eq=False)
class ImagePair:
    """Two grayscale images and the homography between them: one benchmark sample.

    Attributes:
        image1: (H1, W1) float32 in [0, 1], the reference image.
        image2: (H2, W2) float32 in [0, 1].
        H: (3, 3) float64 homography mapping image-1 pixels (x, y) to image-2 pixels.
        split: the data set split, e.g. "viewpoint", "illumination" or "event_frames".
        name: an identifier of the pair, e.g. "v_graffiti/1-3".
    """

    image1: np.ndarray
    image2: np.ndarray
    H: np.ndarray
    split: str
    name: str = ""


# ---------------------------------------------------------------------------------------------- images
def _as_size(value: object, name: str) -> tuple[int, int]:
    """Return a (height, width) of positive ints, or raise ValueError naming ``name``."""
    try:
        dims = tuple(value)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"{name} must be (height, width) in pixels; got {value!r}") from None
    if len(dims) != 2 or not all(isinstance(d, Integral) and not isinstance(d, bool) and d > 0 for d in dims):
        raise ValueError(f"{name} must be (height, width) of two positive integers; got {value!r}")
    return int(dims[0]), int(dims[1])


def _as_gray(image: np.ndarray, name: str) -> NDArray[np.float32]:
    """Return a grayscale (H, W) float32 image in [0, 1] from uint8 or float input, or raise ValueError."""
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"{name} must be a grayscale image of shape (H, W); got {img.shape}")
    if img.dtype == np.uint8:
        return img.astype(np.float32) / np.float32(255.0)
    if not np.issubdtype(img.dtype, np.floating):
        raise ValueError(f"{name} must be uint8 or float in [0, 1]; got dtype {img.dtype}")
    if not np.isfinite(img).all() or img.min() < 0.0 or img.max() > 1.0:
        raise ValueError(
            f"{name} must hold finite values in [0, 1] (float images); got range [{img.min()}, {img.max()}]"
        )
    return img.astype(np.float32)


def read_gray_image(path: str | Path) -> NDArray[np.float32]:
    """Return the image file at ``path`` as a grayscale (H, W) float32 image in [0, 1] (OpenCV reads and converts).

    Args:
        path: an image file OpenCV reads (.ppm, .png, .jpg, ...).
    """
    path = Path(path)
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if path.is_file() else None
    if image is None:
        raise ValueError(f"path {path} is not a readable image file (OpenCV could not read it)")
    return image.astype(np.float32) / np.float32(255.0)


def resize_image(
    image: np.ndarray, size: tuple[int, int], mode: str = "crop"
) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """Return (resized image, S): the image resized to ``size`` and the (3, 3) map S of its pixels to the new ones.

    ``mode="crop"`` keeps the aspect ratio: scale so that the image covers ``size``, then cut the centre (as
    SuperPoint's HPatches loader); ``mode="stretch"`` scales each axis on its own. With per-axis scales
    ``s = new / old`` and crop offset o, pixel centres map as ``x' = s (x + 0.5) - 0.5 - o``, i.e.
    ``S = [[sx, 0, sx/2 - 1/2 - ox], [0, sy, sy/2 - 1/2 - oy], [0, 0, 1]]``. Shrinking uses area averaging, enlarging
    bilinear interpolation.

    Args:
        image: (H, W) grayscale image, uint8 or float32 in [0, 1].
        size: (height, width) of the output.
        mode: "crop" or "stretch".

    >>> img, S = resize_image(np.zeros((60, 100), np.float32), (30, 40))   # scale 1/2 to 30 x 50, crop 5 columns
    >>> img.shape, S.round(3).tolist()
    ((30, 40), [[0.5, 0.0, -5.25], [0.0, 0.5, -0.25], [0.0, 0.0, 1.0]])
    """
    img = _as_gray(image, "image")
    out_h, out_w = _as_size(size, "size")
    if mode not in RESIZE_MODES:
        raise ValueError(f"mode must be one of {RESIZE_MODES}; got {mode!r}")
    in_h, in_w = img.shape
    if mode == "stretch":
        scaled_h, scaled_w = out_h, out_w
    else:
        scale = max(out_h / in_h, out_w / in_w)  # cover the output, then crop the centre
        scaled_h, scaled_w = max(out_h, round(in_h * scale)), max(out_w, round(in_w * scale))
    sx, sy = scaled_w / in_w, scaled_h / in_h
    if (scaled_h, scaled_w) == (in_h, in_w):
        scaled = img.copy()
    else:
        shrink = scaled_h * scaled_w < in_h * in_w
        scaled = cv2.resize(img, (scaled_w, scaled_h), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    off_y, off_x = (scaled_h - out_h) // 2, (scaled_w - out_w) // 2
    resized = np.ascontiguousarray(scaled[off_y : off_y + out_h, off_x : off_x + out_w])
    # x' = s (x + 0.5) - 0.5 - o
    S = np.array([[sx, 0.0, 0.5 * sx - 0.5 - off_x], [0.0, sy, 0.5 * sy - 0.5 - off_y], [0.0, 0.0, 1.0]])
    return np.clip(resized, 0.0, 1.0).astype(np.float32), S


def resize_pair(pair: ImagePair, size: tuple[int, int] | None, mode: str = "crop") -> ImagePair:
    """Return the pair with both images resized to ``size`` and H updated: ``H' = S2 H S1^-1`` (H'[2, 2] = 1).

    Args:
        pair: the image pair (image 1 -> image 2 homography H).
        size: (height, width) of both outputs; None returns the pair unchanged.
        mode: "crop" (keep the aspect ratio, cut the centre) or "stretch" (see ``resize_image``).

    >>> pair = ImagePair(np.zeros((60, 80), np.float32), np.zeros((60, 80), np.float32), np.eye(3), "viewpoint")
    >>> small = resize_pair(pair, (30, 40))
    >>> small.image1.shape, np.allclose(small.H, np.eye(3))
    ((30, 40), True)
    """
    if not isinstance(pair, ImagePair):
        raise ValueError(f"pair must be an ImagePair; got {type(pair).__name__}")
    if size is None:
        return pair
    image1, S1 = resize_image(pair.image1, size, mode)
    image2, S2 = resize_image(pair.image2, size, mode)
    H = S2 @ np.asarray(pair.H, dtype=np.float64) @ np.linalg.inv(S1)  # H' = S2 H S1^-1
    return ImagePair(image1, image2, H / H[2, 2], pair.split, pair.name)


# ---------------------------------------------------------------------------------------------- HPatches
def _as_splits(split: str | Sequence[str]) -> tuple[str, ...]:
    """Return the requested HPatches splits as a tuple of names."""
    names = tuple(SPLIT_PREFIXES) if split == "all" else ((split,) if isinstance(split, str) else tuple(split))
    bad = [s for s in names if s not in SPLIT_PREFIXES]
    if bad or not names:
        raise ValueError(f"split must be 'all', 'illumination', 'viewpoint' or a list of those; got {split!r}")
    return names


def hpatches_scenes(root: str | Path, split: str | Sequence[str] = "all") -> list[Path]:
    """Return the scene folders (sorted by name) of an HPatches root folder for the requested split(s).

    Args:
        root: the folder holding the ``i_*`` and ``v_*`` scene folders (e.g. ``hpatches-sequences-release``).
        split: "all", "illumination" (``i_*``), "viewpoint" (``v_*``), or a list of those.
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"root must be an HPatches folder with i_*/v_* scene folders; {root} is not a directory")
    prefixes = tuple(SPLIT_PREFIXES[s] for s in _as_splits(split))
    scenes = sorted(p for p in root.iterdir() if p.is_dir() and p.name.startswith(prefixes))
    if not scenes:
        raise ValueError(f"root {root} holds no HPatches scene folder starting with {prefixes}")
    return scenes


def _read_homography(path: Path) -> NDArray[np.float64]:
    """Return the (3, 3) homography in an HPatches ``H_1_k`` text file."""
    if not path.is_file():
        raise ValueError(f"HPatches homography file {path} is missing")
    try:
        H = np.loadtxt(path, dtype=np.float64)
    except ValueError as error:
        raise ValueError(f"HPatches homography file {path} must hold 3 x 3 numbers: {error}") from None
    if H.shape != (3, 3) or not np.isfinite(H).all() or abs(np.linalg.det(H)) < 1e-12:
        raise ValueError(f"HPatches homography file {path} must hold an invertible 3 x 3 matrix; got shape {H.shape}")
    return H / H[2, 2]


def iter_hpatches_pairs(
    root: str | Path,
    split: str | Sequence[str] = "all",
    size: tuple[int, int] | None = None,
    *,
    resize_mode: str = "crop",
    max_scenes: int | None = None,
) -> Iterator[ImagePair]:
    """Return an iterator over the HPatches pairs (image 1 with image k = 2..6) of every scene, optionally resized.

    The arguments and the folder list are checked at the call; the images are read as the iterator advances. Each
    ``ImagePair`` holds image 1 and image k as grayscale float32 in [0, 1], ``H_1_k`` (updated for the resize),
    the split ("illumination" for ``i_*`` scenes, "viewpoint" for ``v_*``) and the name ``"<scene>/1-<k>"``.

    Args:
        root: the folder holding the ``i_*`` and ``v_*`` scene folders.
        split: "all", "illumination", "viewpoint", or a list of those.
        size: (height, width) to resize both images to (thesis: (240, 320) for repeatability, (480, 640) for
            homography estimation); None keeps the original size.
        resize_mode: "crop" (keep the aspect ratio, cut the centre; SuperPoint's choice) or "stretch".
        max_scenes: only the first this many scenes (sorted by name) of each split.

    Reference: Balntas et al., CVPR 2017; thesis §3.2.3.
    """
    if size is not None:
        size = _as_size(size, "size")
    if resize_mode not in RESIZE_MODES:
        raise ValueError(f"resize_mode must be one of {RESIZE_MODES}; got {resize_mode!r}")
    if max_scenes is not None and (
        isinstance(max_scenes, bool) or not isinstance(max_scenes, Integral) or max_scenes < 1
    ):
        raise ValueError(f"max_scenes must be a positive integer or None; got {max_scenes!r}")
    available = hpatches_scenes(root, split)  # raises when the root holds none of the requested scenes
    scenes: list[tuple[str, Path]] = []
    for name in _as_splits(split):
        found = [p for p in available if p.name.startswith(SPLIT_PREFIXES[name])]
        scenes.extend((name, p) for p in found[:max_scenes])
    return _generate_pairs(scenes, size, resize_mode)  # validated now, images read lazily


def _generate_pairs(
    scenes: list[tuple[str, Path]], size: tuple[int, int] | None, resize_mode: str
) -> Iterator[ImagePair]:
    """Yield the pairs of the given (split, scene folder) list."""
    for split_name, scene in scenes:
        reference = scene / "1.ppm"
        if not reference.is_file():
            raise ValueError(f"HPatches scene {scene} has no reference image 1.ppm")
        image1 = read_gray_image(reference)
        for k in range(2, N_IMAGES_PER_SCENE + 1):
            image_path = scene / f"{k}.ppm"
            if not image_path.is_file():
                raise ValueError(f"HPatches scene {scene} is missing image {k}.ppm")
            pair = ImagePair(image1, read_gray_image(image_path), _read_homography(scene / f"H_1_{k}"),
                             split_name, f"{scene.name}/1-{k}")
            yield resize_pair(pair, size, resize_mode)
