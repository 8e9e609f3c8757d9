"""Shared pytest fixtures for the evio test suite."""
import importlib
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
REAL_DATA_DIR = PROJECT_ROOT.parent / "shared" / "data" / "real"


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, so every test run draws the same numbers."""
    return np.random.default_rng(20201)


@pytest.fixture
def real_data_dir() -> Path:
    """Folder of real recordings (../shared/data/real); skips the test where it is absent."""
    if not REAL_DATA_DIR.is_dir():
        pytest.skip(f"real recordings not found at {REAL_DATA_DIR} (only present beside a CI checkout)")
    return REAL_DATA_DIR


@pytest.fixture
def make_photo_folder() -> Callable[..., Path]:
    """Return a function that writes ``count`` smooth random grayscale photographs into a folder (about a fifth of
    them fall in each held-out split by name) and returns the folder."""
    import cv2

    def make(folder: Path, count: int = 30, seed: int = 0) -> Path:
        rng = np.random.default_rng(seed)
        for i in range(count):
            path = folder / "urban100" / f"img_{i:03d}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            image = cv2.GaussianBlur(rng.uniform(0, 255, (60, 80)).astype(np.float32), (0, 0), 3.0)
            image = (image - image.min()) / (image.max() - image.min()) * 255  # each spans the whole display range
            assert cv2.imwrite(str(path), image.astype(np.uint8))
        return folder

    return make
