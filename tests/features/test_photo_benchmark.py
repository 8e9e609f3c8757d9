"""Tests for evio_lib.features.evaluation.photos and ``features-benchmark --dataset photos``: photographs fitted to
480 x 640 without distortion, the split's photographs and nothing else, fixed pairs, and the command line on a small
folder of generated photographs (nothing here needs the shared photo folder)."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from evio_lib import cli
from evio_lib.features.evaluation.benchmark import heldout_pairs
from evio_lib.features.evaluation.benchmark import photo_pairs
from evio_lib.features.evaluation.photos import fit_photo, photo_images
from evio_lib.sim import photos as sim_photos
from evio_lib.sim.photos import photo_split

# shapes (height, width) of the generated photographs: smaller and larger than 480 x 640, landscape and portrait
SHAPES = [(340, 512), (600, 900), (512, 340), (480, 640), (425, 640), (700, 700)]


def _texture(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """A uint8 photograph-like texture: blurred noise at two scales plus a few filled rectangles (corners)."""
    h, w = shape
    coarse = rng.random((h // 16 + 2, w // 16 + 2)).astype(np.float32)
    coarse = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    fine = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 1.5)
    image = 0.6 * coarse + 0.4 * fine
    for _ in range(12):
        x0, y0 = int(rng.integers(0, w - 40)), int(rng.integers(0, h - 40))
        cv2.rectangle(image, (x0, y0), (x0 + int(rng.integers(15, 40)), y0 + int(rng.integers(15, 40))),
                      float(rng.random()), -1)
    return np.clip(image * 255, 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def photo_folder(tmp_path_factory) -> tuple[Path, dict[str, list[str]]]:
    """A folder of generated PNGs (one sub-folder too) and the relative names of each split, from photo_split."""
    folder = tmp_path_factory.mktemp("photos")
    rng = np.random.default_rng(7)
    names: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    index = 0
    while len(names["test"]) < 3 or len(names["val"]) < 2:  # enough of each held-out split, whatever the hash says
        name = f"scene_{index:03d}.png" if index % 3 else f"sub/scene_{index:03d}.png"
        split = photo_split(name)
        if split != "train" or len(names["train"]) < 2:
            path = folder / name
            path.parent.mkdir(exist_ok=True)
            cv2.imwrite(str(path), _texture(SHAPES[index % len(SHAPES)], rng))
            names[split].append(name)
        index += 1
    return folder, {split: sorted(n) for split, n in names.items()}


# ---------------------------------------------------------------------------------------------- fit_photo
def test_fit_photo_keeps_the_centre_at_the_aspect_ratio_without_distortion():
    # a filled disc at the centre of a wide, small photograph: enlarged, it must stay a disc (equal extents)
    image = np.zeros((300, 500), np.float32)
    cv2.circle(image, (250, 150), 90, 1.0, -1)
    out = fit_photo(image)
    assert out.shape == (480, 640) and out.dtype == np.float32 and 0 <= out.min() and out.max() <= 1
    ys, xs = np.nonzero(out > 0.5)
    scale = 480 / 300  # the crop 300 x 400 (columns 50..449) enlarged to 480 x 640
    assert abs((xs.max() - xs.min()) - (ys.max() - ys.min())) <= 2
    assert abs((xs.max() - xs.min() + 1) - 181 * scale) <= 3
    # pixel centres map as x' = s (x - left + 0.5) - 0.5: the disc's centre (250, 150) goes to (320.3, 240.3)
    assert abs(xs.mean() - (scale * (250 - 50 + 0.5) - 0.5)) < 0.2
    assert abs(ys.mean() - (scale * (150 + 0.5) - 0.5)) < 0.2


def test_fit_photo_crops_the_exact_centre_and_averages_when_shrinking():
    rng = np.random.default_rng(0)
    wide = rng.random((480, 800)).astype(np.float32)
    np.testing.assert_array_equal(fit_photo(wide), wide[:, 80:720])  # already 480 high: only the centre columns
    tall = rng.random((1200, 1280)).astype(np.float32)  # keep the width, rows 120..1079; halve by 2 x 2 means
    expected = tall[120:1080].reshape(480, 2, 640, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(fit_photo(tall), expected, atol=1e-5)
    portrait = rng.random((512, 340)).astype(np.float32)  # a central landscape band 255 x 340, enlarged (bicubic)
    band = portrait[128:383]
    np.testing.assert_allclose(fit_photo(portrait), np.clip(cv2.resize(band, (640, 480),
                                                                       interpolation=cv2.INTER_CUBIC), 0, 1))
    assert fit_photo((portrait * 255).astype(np.uint8)).dtype == np.float32
    with pytest.raises(ValueError, match="grayscale"):
        fit_photo(np.zeros((4, 4)))


# ---------------------------------------------------------------------------------------------- the data set
def test_photo_images_are_the_split_photographs_at_480_by_640(photo_folder):
    folder, names = photo_folder
    for split in ("test", "val"):
        images = photo_images(folder, split)
        assert len(images) == len(names[split])
        for image, name in zip(images, names[split]):  # in the order of their relative paths
            raw = cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255
            assert image.shape == (480, 640) and image.dtype == np.float32
            np.testing.assert_array_equal(image, fit_photo(raw))
    assert len(photo_images(folder, "test", n_images=2)) == 2
    with pytest.raises(ValueError, match="train is never a benchmark"):
        photo_images(folder, "train")


def test_photo_pairs_are_fixed_by_the_seed_and_are_heldout_pairs_of_the_photographs(photo_folder):
    folder, names = photo_folder
    first = photo_pairs(folder, "test", seed=3, n_images=2, pairs_per_image=2)
    again = photo_pairs(folder, "test", seed=3, n_images=2, pairs_per_image=2)
    assert [p.split for p in first] == ["viewpoint"] * 4 + ["illumination"] * 4
    for a, b in zip(first, again):
        assert a.name == b.name
        np.testing.assert_array_equal(a.image1, b.image1)
        np.testing.assert_array_equal(a.image2, b.image2)
        np.testing.assert_array_equal(a.H, b.H)
        assert a.image1.shape == a.image2.shape == (480, 640)
    reference = heldout_pairs(3, images=photo_images(folder, "test", n_images=2), pairs_per_image=2)
    for a, b in zip(first, reference):
        np.testing.assert_array_equal(a.image2, b.image2)
        np.testing.assert_array_equal(a.H, b.H)
    other = photo_pairs(folder, "test", seed=4, n_images=2, pairs_per_image=2)
    assert not np.array_equal(first[0].H, other[0].H)
    val = photo_pairs(folder, "val", seed=3, n_images=1, pairs_per_image=1)
    raw = cv2.imread(str(folder / names["val"][0]), cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255
    np.testing.assert_array_equal(val[0].image1, fit_photo(raw))


# ---------------------------------------------------------------------------------------------- command line
@pytest.mark.parametrize("photos_option, message", [
    ("none", "--photos none names no folder"),
    ("auto", "no photo folder found"),
    ("{d}/missing", "--photos {d}/missing: not a folder"),
])
def test_missing_photo_folder_is_one_error_line(tmp_path, monkeypatch, capsys, photos_option, message):
    monkeypatch.delenv("EVIO_PHOTOS", raising=False)
    monkeypatch.setattr(sim_photos, "default_photo_folder", lambda: None)  # as on a machine without the shared store
    photos = photos_option.replace("{d}", str(tmp_path))
    code = cli.main(["features-benchmark", "--dataset", "photos", "--photos", photos, "--detectors", "sift", "--quiet"])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ")
    assert "--photos" in lines[0] and message.replace("{d}", str(tmp_path)) in lines[0]


def test_features_benchmark_on_a_photo_folder(photo_folder, tmp_path, capsys):
    folder, names = photo_folder
    out = tmp_path / "out"
    code = cli.main(["features-benchmark", "--dataset", "photos", "--photos", str(folder), "--detectors", "sift",
                     "--n-images", "2", "--pairs-per-image", "1", "--quiet", "--speed-shapes", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    assert "photos benchmark: 4 pairs {'viewpoint': 2, 'illumination': 2}" in printed
    summary = json.loads((out / "results.json").read_text())
    assert summary[0]["detector"] == "sift" and summary[0]["n_pairs"] == {"viewpoint": 2, "illumination": 2}
    tables = (out / "tables.md").read_text()
    assert "### Homography estimation correctness (photos)" in tables and "| SIFT |" in tables
    # illumination pairs share the geometry (H = I): SIFT on textured 480 x 640 photographs gets them within 5 px
    assert summary[0]["homography"]["illumination"]["5.0"] == 1.0
