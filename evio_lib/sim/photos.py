"""A folder of natural photographs for training the learned parts: found, split once, read as grayscale.

The networks' published counterparts trained on MS-COCO photographs (FireNet/E2VID through ESIM, SuperPoint through
homographic adaptation). The project reads any folder of photographs instead (``--photos DIR``): every ``.jpg``,
``.jpeg``, ``.png``, ``.bmp``, ``.tif`` or ``.tiff`` under it, at any depth. Without the option it looks for
``../shared/data/photos`` beside the checkout (or ``$EVIO_PHOTOS``); where none is found a command that needs photographs
says so in one line.

**Split.** Each photograph goes to ``train``, ``val`` or ``test`` by a hash of its path relative to the folder, so the
split does not depend on the listing order, the machine or the other files present, and a photograph added later does
not move the others:

    u = int(sha256(relative path).hexdigest()[:8], 16) / 2^32,   val if u < 0.2, test if u < 0.4, else train.

Sub-folders listed in :data:`TRAIN_ONLY_FOLDERS` stay in ``train`` whatever their hash: the 180 x 180 Berkeley crops of
the shared store may be cut from the same photographs as ``bsd100/``, so a held-out split must not hold any of them,
and whole ``bsd100/`` goes to training with them. So held-out photographs come from the other sub-folders only
(Urban100, Sun-Hays 80, Set14 in the shared store).
"""
from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["PHOTO_SPLITS", "PHOTO_SUFFIXES", "TRAIN_ONLY_FOLDERS", "default_photo_folder", "photo_split",
           "list_photos", "load_photo", "photo_fingerprint", "resolve_photo_option"]

PHOTO_SPLITS = ("train", "val", "test")
PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")
#: top-level sub-folders whose photographs only ever train (crops that may share photographs with one another)
TRAIN_ONLY_FOLDERS = ("bsd100", "bsd_train400")
_VAL_FRACTION, _TEST_FRACTION = 0.2, 0.2


def default_photo_folder() -> Path | None:
    """Return ``$EVIO_PHOTOS`` (refused in one line when it is no folder) or ``../shared/data/photos`` beside the
    checkout where it exists, else None."""
    env = os.environ.get("EVIO_PHOTOS")
    if env:
        if not Path(env).is_dir():
            raise ValueError(f"$EVIO_PHOTOS={env}: not a folder (expected a folder of .jpg/.png photographs)")
        return Path(env)
    candidate = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "photos"
    return candidate if candidate.is_dir() else None


def resolve_photo_option(value: str | Path | None) -> Path | None:
    """Return the folder a ``--photos`` value names: ``auto`` (or None) the default folder where one exists, ``none``
    no folder, anything else that folder (checked: it must hold photographs)."""
    if value is None or str(value) == "auto":
        return default_photo_folder()
    if str(value) == "none":
        return None
    list_photos(value)                                          # a clear error for a folder without photographs
    return Path(value)


def photo_split(relative_path: str) -> str:
    """Return the split (``train``, ``val`` or ``test``) of a photograph from its path relative to the folder."""
    parts = Path(relative_path).parts
    if len(parts) > 1 and parts[0] in TRAIN_ONLY_FOLDERS:
        return "train"
    u = int(hashlib.sha256(Path(relative_path).as_posix().encode()).hexdigest()[:8], 16) / 2 ** 32
    if u < _VAL_FRACTION:
        return "val"
    return "test" if u < _VAL_FRACTION + _TEST_FRACTION else "train"


def list_photos(folder: str | Path, split: str | None = None) -> list[Path]:
    """Return the photographs under ``folder`` (sorted by relative path), all or those of one split.

    Raises ValueError naming the folder when it is missing or holds no photograph (of that split).
    """
    folder = Path(folder)
    if split is not None and split not in PHOTO_SPLITS:
        raise ValueError(f"split must be one of {PHOTO_SPLITS}; got {split!r}")
    if not folder.is_dir():
        raise ValueError(f"--photos {folder}: not a folder (expected a folder of .jpg/.png photographs)")
    paths = sorted((p for p in folder.rglob("*") if p.suffix.lower() in PHOTO_SUFFIXES and p.is_file()),
                   key=lambda p: p.relative_to(folder).as_posix())
    if split is not None:
        paths = [p for p in paths if photo_split(p.relative_to(folder).as_posix()) == split]
    if not paths:
        which = "photographs" if split is None else f"photographs of the {split} split"
        raise ValueError(f"--photos {folder}: holds no {which} (expected files ending in "
                         f"{', '.join(PHOTO_SUFFIXES)})")
    return paths


def photo_fingerprint(folder: str | Path) -> dict:
    """Return what identifies a photo folder's content for a training set's manifest: the count per split and a
    digest of the relative paths (not of the bytes: reading 700 files to resume a set would cost seconds)."""
    folder = Path(folder)
    paths = list_photos(folder)
    names = [p.relative_to(folder).as_posix() for p in paths]
    counts = {split: sum(photo_split(n) == split for n in names) for split in PHOTO_SPLITS}
    digest = hashlib.sha256("\n".join(names).encode()).hexdigest()[:16]
    return {"count": len(names), "per_split": counts, "names_sha256": digest}


@lru_cache(maxsize=1024)
def load_photo(path: str | Path) -> np.ndarray:
    """Return the photograph at ``path`` as float32 grayscale in [0, 1] (cached per process).

    Raises ValueError naming the file when it cannot be decoded.
    """
    import cv2

    data = np.fromfile(str(path), dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH) if data.size else None
    if image is None or image.ndim != 2 or min(image.shape) < 8:
        raise ValueError(f"{path}: not a readable photograph of at least 8 x 8 pixels")
    scale = 65535.0 if image.dtype == np.uint16 else 255.0
    return (image.astype(np.float32) / scale)
