"""Tests of the simulated training sequences: determinism, disjoint splits, and labels consistent with the motion."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from evio_lib.events.reconstruction.data import (SPLIT_PHOTOS, ReconstructionDataConfig, make_training_sample,
                                                 random_planar_sequence, reconstruction_dataset)

SMALL = ReconstructionDataConfig(height=32, width=32, duration=0.3, windows=4)


def test_splits_share_no_photograph():
    names = [set(v) for v in SPLIT_PHOTOS.values()]
    assert not (names[0] & names[1]) and not (names[0] & names[2]) and not (names[1] & names[2])


def test_samples_are_deterministic_and_shaped():
    a = make_training_sample(np.random.default_rng(3), "train", SMALL)
    b = make_training_sample(np.random.default_rng(3), "train", SMALL)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert a["voxels"].shape == (4, 5, 32, 32) and a["frames"].shape == (4, 32, 32) and a["H_prev"].shape == (4, 3, 3)
    assert np.isfinite(a["voxels"].astype(np.float32)).all()
    np.testing.assert_allclose(a["H_prev"][0], np.eye(3))


def test_homography_label_maps_the_current_view_into_the_previous_one():
    """Warping frame k-1 by H_prev[k] reproduces frame k inside the view (the truth the TC loss relies on)."""
    seq = random_planar_sequence(np.random.default_rng(11), "val", SMALL)
    t0, t1 = 0.1, 0.2
    prev, cur = seq.render(t0), seq.render(t1)
    H_cur_to_prev = seq.homography(t0) @ np.linalg.inv(seq.homography(t1))
    warped = cv2.warpPerspective(prev, H_cur_to_prev, (32, 32), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    inner = (slice(6, -6), slice(6, -6))
    assert np.abs(warped[inner] - cur[inner]).mean() < 0.25 * np.abs(prev[inner] - cur[inner]).mean() + 1e-3


def test_events_follow_the_rendered_change():
    """Summed polarities times C approximate the log-intensity change between the first and last render."""
    seq = random_planar_sequence(np.random.default_rng(5), "train", SMALL)
    ev = seq.events
    assert ev.size > 100 and np.all(np.diff(ev["t"]) >= 0)
    assert ev["x"].max() < 32 and ev["y"].max() < 32


def test_dataset_prefix_property_and_errors():
    small = reconstruction_dataset("test", 2, seed=1, config=SMALL, cache=False)
    larger = reconstruction_dataset("test", 3, seed=1, config=SMALL, cache=False, workers=2)
    np.testing.assert_array_equal(small["voxels"], larger["voxels"][:2])
    with pytest.raises(ValueError, match="split"):
        reconstruction_dataset("training", 2)
    with pytest.raises(ValueError, match="n_samples"):
        reconstruction_dataset("train", 0)
    with pytest.raises(ValueError, match="height and width"):
        ReconstructionDataConfig(height=8)
