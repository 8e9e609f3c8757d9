"""Fixtures of the pipeline tests: small simulated recordings in a private cache (never the project's data/cache)."""
import os
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def _cache_env(folder: Path):
    """Set EVIO_CACHE_DIR to ``folder`` for the block, then put back what was there."""
    old = os.environ.get("EVIO_CACHE_DIR")
    os.environ["EVIO_CACHE_DIR"] = str(folder)
    try:
        yield folder
    finally:
        if old is None:
            os.environ.pop("EVIO_CACHE_DIR", None)
        else:
            os.environ["EVIO_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def pipeline_cache(tmp_path_factory):
    """A session folder for the recordings the pipeline tests simulate, made once and shared."""
    return tmp_path_factory.mktemp("evio_cache")


@pytest.fixture(autouse=True)
def _private_cache(pipeline_cache, monkeypatch):
    """Every pipeline test reads and writes recordings in the session folder. Set per test and undone after it,
    so that later tests and notebooks in the same worker process (pytest-xdist) use the project's cache."""
    monkeypatch.setenv("EVIO_CACHE_DIR", str(pipeline_cache))


@pytest.fixture(scope="session")
def boxes_aps(pipeline_cache):
    """3 s of boxes_like with APS frames (no events), seed 0."""
    from evio_lib.pipeline.dataset import load_dataset

    with _cache_env(pipeline_cache):
        return load_dataset("boxes_like", duration=3.0)


@pytest.fixture(scope="session")
def boxes_events(pipeline_cache):
    """1.5 s of boxes_like with events and APS frames, seed 0."""
    from evio_lib.pipeline.dataset import load_dataset

    with _cache_env(pipeline_cache):
        return load_dataset("boxes_like", duration=1.5, need_events=True)
