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
