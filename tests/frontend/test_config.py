"""Tests of evio_lib.frontend.config."""
from dataclasses import fields

import pytest

from evio_lib.frontend.config import FrontendConfig


def test_defaults_follow_the_thesis_and_print_every_field():
    cfg = FrontendConfig()
    assert (cfg.max_features, cfg.grid_rows, cfg.grid_cols, cfg.per_cell) == (60, 4, 5, 3)  # N / 20 per cell
    text = str(cfg)
    assert text.splitlines()[0] == "FrontendConfig"
    assert len(text.splitlines()) == 1 + len(fields(cfg))
    for f in fields(cfg):
        assert f"  {f.name} " in text
    assert "None -> 'sift'" in text


def test_detector_defaults_and_options():
    assert FrontendConfig().detector_name == "sift"
    assert FrontendConfig(method="klt").detector_name == "fast"
    assert FrontendConfig(method="klt", detector="harris").detector_name == "harris"
    assert FrontendConfig(detector_options={"threshold": 10}).detector_options == (("threshold", 10),)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(method="orb"), "method"),
        (dict(detector=""), "detector"),
        (dict(detector_options=[1, 2]), "detector_options"),
        (dict(max_features=0), "max_features"),
        (dict(max_features=10), "at least grid_rows"),
        (dict(grid_rows=2.5), "grid_rows"),
        (dict(klt_window=16), "odd"),
        (dict(ransac_threshold_px=0.0), "ransac_threshold_px"),
        (dict(min_distance_px=-1.0), "min_distance_px"),
        (dict(match_radius_px=0.0), "match_radius_px"),
        (dict(ratio=1.2), "ratio"),
        (dict(ransac="yes"), "ransac"),
        (dict(seed=-1), "seed"),
    ],
)
def test_bad_values_raise_a_clear_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FrontendConfig(**kwargs)
