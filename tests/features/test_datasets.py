"""Tests for evio_lib.features.training.datasets: the split by source (no source or test content in two splits), offline
loading, the pool's determinism and composition, event frames, the label cache and the RealImages dataset."""
from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

import evio_lib.sim.scene as scene_module
import evio_lib.features.training.datasets as datasets
from evio_lib.features.training.augment import PairSample, Sample, keypoints_to_map
from evio_lib.io.cache import default_cache_dir
from evio_lib.features.training.datasets import (
    DEFAULT_POOL_SIZE,
    PHOTO_FILES,
    PHOTO_SPLITS,
    POOL_MIX,
    ROOM_PHOTOS,
    SPLITS,
    EventFrames,
    RealImages,
    adaptation_labels,
    image_pool,
    images_fingerprint,
    list_sources,
    load_labels,
    load_photo,
    random_crop,
    save_labels,
)
from evio_lib.geometry.homography import warp_image, warp_points


def ramp(shape=(48, 64), offset=0.0) -> np.ndarray:
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]]
    return np.clip(offset + 0.5 * xs / shape[1] + 0.3 * ys / shape[0], 0, 1).astype(np.float32)


# ------------------------------------------------------------------------------------------------ the split
def test_no_source_is_in_two_splits():
    sources = {split: list_sources(split) for split in SPLITS}
    names = [s.name for split in SPLITS for s in sources[split]]
    assert len(names) == len(set(names))
    assert all(s.split == split for split in SPLITS for s in sources[split])
    content = {split: set().union(*(s.content for s in sources[split])) for split in SPLITS}
    assert not content["test"] & (content["train"] | content["val"])  # test content never trained on
    # every bundled photo source belongs to exactly one split
    photo_splits = [p for split in SPLITS for p in PHOTO_SPLITS[split]]
    assert sorted(photo_splits) == sorted(PHOTO_FILES)
    assert not ROOM_PHOTOS & set(PHOTO_SPLITS["test"])
    assert all(kind in {s.kind for s in sources[split]} for split in SPLITS for kind in POOL_MIX[split])


def test_rooms_show_only_the_declared_photographs(monkeypatch):
    # indoor_room pastes photographs on walls and boxes: they must be the ones declared as room content
    loaded = []
    original = scene_module.load_texture

    def recorder(name, size=None):
        loaded.append(name)
        return original(name, size)

    monkeypatch.setattr(scene_module, "load_texture", recorder)
    scene_module.indoor_room(0)
    assert loaded and set(loaded) <= ROOM_PHOTOS


def test_photos_load_offline(monkeypatch):
    def no_network(*args, **kwargs):
        raise OSError("network access attempted")

    monkeypatch.setattr(socket.socket, "connect", no_network)
    for name, files in PHOTO_FILES.items():
        for index in range(len(files)):
            photo = load_photo(name, index)
            assert photo.ndim == 2 and photo.dtype == np.float32 and 0.0 <= photo.min() and photo.max() <= 1.0
            assert min(photo.shape) >= 120 and photo.std() > 0.03, name
    with pytest.raises(ValueError, match="name must be one of"):
        load_photo("lena")


# ------------------------------------------------------------------------------------------------ crops and pools
def test_random_crop_respects_the_scale_limits(rng):
    image = ramp((200, 300))  # intensity slope 0.5 / 300 per pixel along x
    slopes = []
    for seed in range(20):
        crop = random_crop(image, (40, 60), seed)
        assert crop.shape == (40, 60) and crop.dtype == np.float32
        slopes.append(float(np.median(np.diff(crop[20], axis=0))) / (0.5 / 300))
    # the crop side is between 1/1.5 and 5 times the output side, so the slope scales by 1/1.5 .. 5
    assert 1.0 / 1.5 - 1e-3 <= min(slopes) < 1.0 and max(slopes) <= 5.0 + 1e-3 and max(slopes) > 2.5
    small = random_crop(ramp((20, 30)), (40, 60), 0)  # smaller than size / 1.5: used whole, upscaled
    assert small.shape == (40, 60)
    with pytest.raises(ValueError, match="max_upscale must be a number >= 1"):
        random_crop(image, (40, 60), 0, max_upscale=0.5)


def test_pool_is_deterministic_and_from_its_split():
    pool, names = image_pool("test", seed=1, size=(48, 64), n_images=10, return_sources=True)
    again = image_pool("test", seed=1, size=(48, 64), n_images=10)
    other = image_pool("test", seed=2, size=(48, 64), n_images=10)
    assert len(pool) == 10 and all(p.shape == (48, 64) and p.dtype == np.float32 for p in pool)
    assert all(np.array_equal(a, b) for a, b in zip(pool, again))
    assert not all(np.array_equal(a, b) for a, b in zip(pool, other))
    test_names = {s.name for s in list_sources("test")}
    assert set(names) <= test_names
    kinds = [n.split(":")[0] for n in names]
    # POOL_MIX["test"] = 0.3 / 0.25 / 0.3 / 0.15 of 10: 3, 2.5, 3, 1.5 -> the tied remainder goes to the first kind
    assert {k: kinds.count(k) for k in set(kinds)} == {"photo": 3, "aerial": 3, "cards": 3, "texture": 1}
    assert np.mean([p.std() > 0.04 for p in pool]) >= 0.9


def test_pool_rendered_by_worker_processes_is_the_same_pool():
    serial, names = image_pool("train", seed=3, size=(48, 64), n_images=20, return_sources=True, render_zoom=2.0)
    parallel, names_parallel = image_pool("train", seed=3, size=(48, 64), n_images=20, return_sources=True,
                                          render_zoom=2.0, workers=3)
    assert names == names_parallel and len(parallel) == 20
    assert all(np.array_equal(a, b) for a, b in zip(serial, parallel))
    for bad in (0, -2, 1.5, True):
        with pytest.raises(ValueError, match="workers must be an int >= 1"):
            image_pool("test", n_images=1, workers=bad)


def test_render_zoom_magnifies_rendered_views_only(monkeypatch):
    size = (48, 64)
    plain, names = image_pool("test", seed=1, size=size, n_images=10, return_sources=True)
    zoomed = image_pool("test", seed=1, size=size, n_images=10, render_zoom=4.0)
    rendered = [n.split(":")[0] in ("aerial", "cards") for n in names]
    for a, b, r in zip(plain, zoomed, rendered):
        assert b.shape == size and b.dtype == np.float32
        assert np.array_equal(a, b) != r  # photos and textures untouched, renders redrawn
    # renders are drawn at render_zoom x 1.25 x size, the others at 1.25 x size
    shapes = []
    original = datasets.render_view

    def spy(source, rng, shape=(300, 400)):
        shapes.append((source.kind, tuple(shape)))
        return original(source, rng, shape)

    monkeypatch.setattr(datasets, "render_view", spy)
    image_pool("test", seed=1, size=size, n_images=10, render_zoom=4.0)
    assert {s for k, s in shapes if k in ("aerial", "cards")} == {(240, 320)}
    assert {s for k, s in shapes if k not in ("aerial", "cards")} == {(60, 80)}
    for bad in (0.5, True, float("nan"), 20):
        with pytest.raises(ValueError, match=r"render_zoom must be a number in \[1, 16\]"):
            image_pool("test", n_images=1, render_zoom=bad)


def test_pool_arguments_are_checked():
    with pytest.raises(ValueError, match="split must be one of"):
        image_pool("holdout")
    with pytest.raises(ValueError, match=r"size must be \(height, width\) of ints >= 16"):
        image_pool("test", size=(8, 8))
    with pytest.raises(ValueError, match="event_fraction must be a number in"):
        image_pool("test", n_images=1, event_fraction=1.5)
    assert DEFAULT_POOL_SIZE["train"] > DEFAULT_POOL_SIZE["val"]


# ------------------------------------------------------------------------------------------------ event frames
def test_event_frames_split_in_time_with_gaps():
    # frame i: a fine checkerboard (mean 0.05, so crops keep the frame's mean) on top of the level i / 250
    checker = (np.indices((48, 64)).sum(0) % 2).astype(np.float32) * 0.1
    frames = [checker + i / 250.0 for i in range(200)]
    events = EventFrames(frames, name="flight", gap=3)
    blocks = [list(events.indices(s)) for s in SPLITS]
    assert blocks[0] == list(range(160)) and blocks[1] == list(range(163, 180)) and blocks[2] == list(range(183, 200))
    assert events.source("test").name == "events:flight:test"
    pool, names = image_pool("val", seed=0, size=(48, 64), n_images=10, event_frames=events, event_fraction=0.3,
                             return_sources=True)
    assert names.count("events:flight:val") == 3 and "events:flight:train" not in names
    # the event images come from val frames 163..179 only: their mean is 0.05 + i / 250 for such an i
    for image, name in zip(pool, names):
        if name.startswith("events"):
            level = float(image.mean()) - 0.05
            assert 163 / 250 - 0.01 < level < 179 / 250 + 0.01, level
    with pytest.raises(ValueError, match="fractions must be three non-negative numbers summing to 1"):
        EventFrames(frames, fractions=(0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="frames must all have the same shape"):
        EventFrames([ramp(), ramp((30, 40))])
    with pytest.raises(ValueError, match="event_frames must have distinct names"):
        list_sources("train", [events, events])


# ------------------------------------------------------------------------------------------------ label cache
def test_labels_roundtrip(tmp_path: Path, rng, monkeypatch):
    monkeypatch.delenv("EVIO_CACHE_DIR", raising=False)  # the project's folder, whatever the environment says
    labels = [rng.uniform(0, 50, (n, 2)).astype(np.float32) for n in (3, 0, 7)]
    path = save_labels(tmp_path / "sub" / "labels.npz", labels, "abc", {"model": "x"})
    back = load_labels(path, "abc")
    assert len(back) == 3 and all(np.array_equal(a, b) for a, b in zip(labels, back))
    assert load_labels(path, "other") is None and load_labels(tmp_path / "missing.npz") is None
    assert default_cache_dir().parts[-2:] == ("data", "cache")


def test_adaptation_labels_are_cached(tmp_path: Path):
    images = [np.zeros((40, 56), np.float32) for _ in range(2)]
    images[0][20, 28] = 1.0
    calls = []

    def detector(batch):
        calls.append(len(batch))
        return batch

    kwargs = dict(rng=0, cache_dir=tmp_path, n_homographies=4, threshold=0.1)
    first = adaptation_labels(images, detector, "toy", **kwargs)
    n_calls = len(calls)
    assert n_calls > 0 and (tmp_path / "labels_toy.npz").is_file()
    second = adaptation_labels(images, detector, "toy", **kwargs)
    assert len(calls) == n_calls  # served from the cache
    assert all(np.array_equal(a, b) for a, b in zip(first, second))
    assert [len(k) for k in first] == [1, 0] and first[0].tolist() == [[28.0, 20.0]]
    adaptation_labels(images, detector, "toy", **{**kwargs, "threshold": 0.2})  # other parameters: recomputed
    assert len(calls) > n_calls
    n_calls = len(calls)
    adaptation_labels(images, detector, "toy", recompute=True, **{**kwargs, "threshold": 0.2})
    assert len(calls) > n_calls
    assert images_fingerprint(images) != images_fingerprint(images[:1])
    with pytest.raises(ValueError, match="cache_name must be letters, digits"):
        adaptation_labels(images, detector, "../evil", **kwargs)


# ------------------------------------------------------------------------------------------------ RealImages
def test_real_images_without_augmentation_returns_the_labels():
    images = [ramp(), ramp(offset=0.2)]
    labels = [np.array([[10.0, 12.0], [40.0, 30.0]]), np.zeros((0, 2))]
    data = RealImages(images, split="val", keypoints=labels)
    assert len(data) == 2 and data.has_labels and not data.augment
    item = data[0]
    assert isinstance(item, Sample)
    np.testing.assert_array_equal(item.image[0].numpy(), images[0])
    np.testing.assert_array_equal(item.keypoint_map.numpy(), keypoints_to_map(labels[0], (48, 64)))
    assert float(item.valid_mask.min()) == 1.0
    unlabelled = RealImages(images, split="val")
    assert not unlabelled.has_labels and float(unlabelled[0].keypoint_map.sum()) == 0.0


def test_real_images_training_augmentation_moves_labels():
    images = [ramp()]
    labels = [np.array([[20.0, 20.0], [30.0, 25.0], [45.0, 15.0]])]
    data = RealImages(images, split="train", keypoints=labels, seed=3)
    assert data.augment
    item = data.sample(0)
    assert not np.array_equal(item["image"], images[0])
    again = RealImages(images, split="train", keypoints=labels, seed=3).sample(0)
    np.testing.assert_array_equal(item["image"], again["image"])
    data.set_epoch(1)
    assert not np.array_equal(data.sample(0)["image"], item["image"])


def test_real_image_pairs_are_related_by_the_homography():
    image = ramp((48, 64))
    labels = [np.array([[20.0, 20.0], [30.0, 25.0], [40.0, 30.0]])]
    data = RealImages([image], split="val", keypoints=labels, pairs=True, seed=1)
    raw = data.sample(0)
    H = raw["homography"]
    np.testing.assert_allclose(raw["warped_image"], warp_image(image, H), atol=1e-6)  # no photometric on val
    moved = warp_points(H, labels[0])
    for kp in raw["warped_keypoints"]:
        assert np.linalg.norm(moved - kp, axis=1).min() < 1e-3
    batch = next(iter(DataLoader(RealImages([image, image], split="train", keypoints=labels * 2, pairs=True),
                                 batch_size=2)))
    assert isinstance(batch, PairSample)
    assert tuple(batch.warped_image.shape) == (2, 1, 48, 64) and tuple(batch.homography.shape) == (2, 3, 3)
    assert batch.homography.dtype == torch.float32


def test_real_images_bad_input():
    with pytest.raises(ValueError, match=r"keypoints must hold one \(N, 2\) array per image \(1\); got 2"):
        RealImages([ramp()], keypoints=[np.zeros((0, 2))] * 2)
    with pytest.raises(ValueError, match="images must all have the same shape"):
        RealImages([ramp(), ramp((30, 40))])
    with pytest.raises(ValueError, match="images must hold at least one image"):
        RealImages([])
    with pytest.raises(ValueError, match="split must be one of"):
        RealImages([ramp()], split="holdout")
