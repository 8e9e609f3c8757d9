"""Fixtures of the pipeline tests: small simulated recordings in a private cache (never the project's data/cache)."""
import os

import pytest


@pytest.fixture(scope="session")
def pipeline_cache(tmp_path_factory):
    """Point EVIO_CACHE_DIR at a session folder, so the tests simulate their own recordings once and share them."""
    folder = tmp_path_factory.mktemp("evio_cache")
    old = os.environ.get("EVIO_CACHE_DIR")
    os.environ["EVIO_CACHE_DIR"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("EVIO_CACHE_DIR", None)
    else:
        os.environ["EVIO_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def boxes_aps(pipeline_cache):
    """3 s of boxes_like with APS frames (no events), seed 0."""
    from evio_lib.pipeline.dataset import load_dataset

    return load_dataset("boxes_like", duration=3.0)


@pytest.fixture(scope="session")
def boxes_events(pipeline_cache):
    """1.5 s of boxes_like with events and APS frames, seed 0."""
    from evio_lib.pipeline.dataset import load_dataset

    return load_dataset("boxes_like", duration=1.5, need_events=True)
