"""Linear light: training sequences whose textures are display values decoded to linear intensity, and the held-out
rooms of photographs in linear light (the scene, the recording, the bench's refusals)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from evio_lib.events.reconstruction.evaluation import linear_light_room_sequence, score_windows
from evio_lib.events.reconstruction.training_set import TrainingSetConfig, make_sequence, make_training_set
from evio_lib.events.reconstruct import create_reconstructor
from evio_lib.sim.photos import list_photos
from evio_lib.sim.scene import photo_room

SMALL = TrainingSetConfig(height=32, width=32, windows=4, duration_min=0.3, duration_max=0.4)


def test_a_set_without_linear_light_keeps_its_sequences_and_manifest(tmp_path):
    _, meta = make_sequence(np.random.default_rng(3), "train", SMALL)
    # the random draws of generator version 3 before this option (sensor and motion come after the scene's draws):
    # an extra draw at the default would move them
    assert meta["contrast_pos"] == pytest.approx(1.0876385802184554, abs=1e-12)
    assert meta["contrast_neg"] == pytest.approx(1.271486575238944, abs=1e-12)
    assert meta["speed"] == pytest.approx(0.7320506605441232, abs=1e-12)
    assert (meta["rule"], meta["layers"]) == ("time", 1) and "linear_gamma" not in meta
    make_training_set(tmp_path / "plain", sequences=1, val=1, test=0, seed=0, config=SMALL, workers=1, progress=False)
    assert "linear_light_fraction" not in json.loads((tmp_path / "plain" / "training_set.json").read_text())["config"]


def test_linear_light_widens_the_range_of_the_light():
    linear = TrainingSetConfig(**{**SMALL.__dict__, "linear_light_fraction": 1.0})
    ratios = {"display": [], "linear": []}
    for seed in range(6):
        for kind, config in (("display", SMALL), ("linear", linear)):
            arrays, meta = make_sequence(np.random.default_rng(seed), "train", config)
            frames = arrays["frames"].astype(np.float64)
            assert np.isfinite(frames).all() and frames.min() >= 0
            lo, hi = np.percentile(frames, [1, 99])
            ratios[kind].append(hi / max(lo, 1e-4))
            if kind == "linear":
                assert 1.8 <= meta["linear_gamma"] <= 2.6
    # decoding display values with gamma ~2.2 raises the contrast ratio of the light several times (median)
    assert np.median(ratios["linear"]) > 3 * np.median(ratios["display"]), ratios


def test_the_fraction_is_recorded_refused_out_of_range_and_part_of_the_settings(tmp_path):
    half = TrainingSetConfig(**{**SMALL.__dict__, "linear_light_fraction": 0.5})
    make_training_set(tmp_path / "s", sequences=2, val=1, test=0, seed=0, config=half, workers=1, progress=False)
    manifest = json.loads((tmp_path / "s" / "training_set.json").read_text())
    assert manifest["config"]["linear_light_fraction"] == 0.5
    assert TrainingSetConfig.from_dict(manifest["config"]) == half
    with pytest.raises(ValueError, match="other settings"):
        make_training_set(tmp_path / "s", sequences=2, val=1, test=0, seed=0, config=SMALL, workers=1, progress=False)
    with pytest.raises(ValueError, match=r"linear_light_fraction must lie in \[0, 1\]"):
        TrainingSetConfig(linear_light_fraction=1.5)


def test_the_photo_room_is_made_of_the_photographs_in_linear_light(tmp_path, make_photo_folder):
    photos = [str(p) for p in list_photos(make_photo_folder(tmp_path / "photos"))]
    display, linear = photo_room(photos, seed=1, gamma=1.0), photo_room(photos, seed=1, gamma=2.2)
    assert len(linear.planes) == len(display.planes) >= 6 + 5 * 5
    for a, b in zip(display.planes, linear.planes):  # the same photograph on each face, only decoded
        np.testing.assert_allclose(np.asarray(b.texture, np.float64), np.asarray(a.texture, np.float64) ** 2.2,
                                   rtol=1e-5, atol=1e-7)
        assert 0.05 - 1e-6 <= np.min(a.texture) and np.max(a.texture) <= 0.95 + 1e-6
    with pytest.raises(ValueError, match="at least one photograph"):
        photo_room([], seed=0)
    with pytest.raises(ValueError, match="gamma must be a positive number"):
        photo_room(photos, gamma=0.0)


def test_the_linear_light_recording_has_events_and_a_truth_to_score_against(tmp_path, make_photo_folder):
    folder = make_photo_folder(tmp_path / "photos")
    sequence = linear_light_room_sequence(303, "val", photos=folder, duration=0.1, render_rate_hz=300)
    events = sequence.events
    assert events.size > 500 and np.all(np.diff(events["t"]) >= 0)
    assert events["x"].max() < 240 and events["y"].max() < 180 and set(np.unique(events["p"])) <= {-1, 1}
    again = linear_light_room_sequence(303, "val", photos=folder, duration=0.1, render_rate_hz=300)
    np.testing.assert_array_equal(events, again.events)                     # deterministic from the seed
    coarser = linear_light_room_sequence(303, "val", photos=folder, duration=0.1, render_rate_hz=300, contrast=0.4)
    assert 0 < coarser.events.size < 0.75 * events.size                     # twice the threshold: about half the events
    truth = sequence.render(1.1)
    assert truth.shape == (180, 240) and truth.min() >= 0
    score = score_windows(create_reconstructor("high_pass", 240, 180), sequence, 0.1, warmup_s=0.05, max_frames=2)
    assert 0 < score["ssim"] <= 1 and score["frames"] >= 1
    with pytest.raises(ValueError, match="no photo folder"):
        linear_light_room_sequence(303, "val", photos="none")
    with pytest.raises(ValueError, match="render_rate_hz must be a positive number"):
        linear_light_room_sequence(303, "val", photos=folder, render_rate_hz=0.0)


def test_the_bench_says_a_missing_photo_folder_in_one_line(tmp_path):
    root = Path(__file__).resolve().parents[2]
    result = subprocess.run([sys.executable, str(root / "bench" / "reconstruction_linear_light.py"), "--photos",
                             str(tmp_path / "nowhere")], capture_output=True, text=True, cwd=root,
                            env={**os.environ, "PYTHONPATH": str(root)})
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.strip().splitlines() == [f"error: --photos {tmp_path / 'nowhere'}: not a folder (expected a "
                                                  f"folder of .jpg/.png photographs)"]
    result = subprocess.run([sys.executable, str(root / "bench" / "reconstruction_linear_light.py"), "--contrast", "0"],
                            capture_output=True, text=True, cwd=root, env={**os.environ, "PYTHONPATH": str(root)})
    assert result.returncode == 2 and "--contrast must lie in (0, 2]; got 0.0" in result.stderr
