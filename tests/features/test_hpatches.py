"""Tests for evio_lib.features.evaluation.hpatches on a tiny fake HPatches folder written with OpenCV."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from evio_lib.features.evaluation.hpatches import (
    ImagePair,
    hpatches_scenes,
    iter_hpatches_pairs,
    read_gray_image,
    resize_image,
    resize_pair,
)

SCENE_SHAPE = (90, 120)  # (height, width) of the fake scenes' images


def texture(rng: np.random.Generator, shape=SCENE_SHAPE) -> np.ndarray:
    """Return a smooth random uint8 texture (blurred noise), so warps and resizes can be compared pixel-wise."""
    noise = rng.random(shape).astype(np.float32)
    smooth = cv2.GaussianBlur(noise, (0, 0), 3.0)
    smooth = (smooth - smooth.min()) / (smooth.max() - smooth.min())
    return np.round(smooth * 255).astype(np.uint8)


def scene_homography(k: int, viewpoint: bool) -> np.ndarray:
    """Return the ground truth H_1_k of the fake scenes: mild perspective for v_*, identity for i_*."""
    if not viewpoint:
        return np.eye(3)
    return np.array([[1.0 + 0.02 * k, 0.03, -2.0 * k], [-0.02, 1.0 - 0.01 * k, 1.5 * k], [1e-4 * k, -5e-5 * k, 1.0]])


@pytest.fixture
def fake_hpatches(tmp_path: Path, rng: np.random.Generator) -> Path:
    """Write a tiny HPatches tree: i_lights and v_wall (colour .ppm images 1..6 and H_1_2..H_1_6), plus clutter."""
    root = tmp_path / "hpatches-sequences-release"
    for name, viewpoint in (("i_lights", False), ("v_wall", True), ("v_zebra", True)):
        scene = root / name
        scene.mkdir(parents=True)
        base = texture(rng)
        cv2.imwrite(str(scene / "1.ppm"), cv2.cvtColor(base, cv2.COLOR_GRAY2BGR))
        for k in range(2, 7):
            H = scene_homography(k, viewpoint)
            image = cv2.warpPerspective(base, H, SCENE_SHAPE[::-1], flags=cv2.INTER_LINEAR)
            if not viewpoint:
                image = np.clip(image.astype(np.float32) * (0.5 + 0.1 * k), 0, 255).astype(np.uint8)
            cv2.imwrite(str(scene / f"{k}.ppm"), cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
            np.savetxt(scene / f"H_1_{k}", H)
    (root / "README.txt").write_text("not a scene")
    (root / "x_other").mkdir()
    return root


def test_scenes_and_pairs_of_the_fake_tree(fake_hpatches):
    assert [p.name for p in hpatches_scenes(fake_hpatches)] == ["i_lights", "v_wall", "v_zebra"]
    assert [p.name for p in hpatches_scenes(fake_hpatches, "viewpoint")] == ["v_wall", "v_zebra"]
    pairs = list(iter_hpatches_pairs(fake_hpatches))
    assert len(pairs) == 15
    assert [p.split for p in pairs] == ["illumination"] * 5 + ["viewpoint"] * 10
    assert pairs[0].name == "i_lights/1-2" and pairs[-1].name == "v_zebra/1-6"
    for pair in pairs:
        assert isinstance(pair, ImagePair)
        assert pair.image1.dtype == np.float32 and pair.image1.shape == SCENE_SHAPE
        assert 0.0 <= pair.image2.min() and pair.image2.max() <= 1.0
    k = 4
    np.testing.assert_allclose(pairs[5 + k - 2].H, scene_homography(k, True), rtol=1e-12)
    assert len(list(iter_hpatches_pairs(fake_hpatches, "viewpoint", max_scenes=1))) == 5


def test_pairs_agree_with_their_homography_after_resizing(fake_hpatches):
    """Image 2 must equal image 1 warped by the (updated) H wherever image 1 covers it, at every size and mode."""
    for size, mode in ((None, "crop"), ((60, 80), "crop"), ((48, 96), "crop"), ((70, 70), "stretch")):
        for pair in iter_hpatches_pairs(fake_hpatches, "viewpoint", size, resize_mode=mode, max_scenes=1):
            if size is not None:
                assert pair.image1.shape == size and pair.image2.shape == size
            predicted = cv2.warpPerspective(pair.image1, pair.H, pair.image1.shape[::-1], flags=cv2.INTER_LINEAR)
            inside = cv2.warpPerspective(np.ones_like(pair.image1), pair.H, pair.image1.shape[::-1]) > 0.999
            inside = cv2.erode(inside.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
            assert inside.mean() > 0.5
            error = np.abs(predicted - pair.image2)[inside]
            assert error.mean() < 0.01, (size, mode, pair.name, error.mean())


@pytest.mark.parametrize("mode", ["crop", "stretch"])
def test_resize_image_maps_pixel_centres(mode):
    """A small bright blob must land where S sends its centre (blob centroid, independent of the formula)."""
    in_shape, size = (90, 160), (45, 60)
    ys, xs = np.mgrid[0 : in_shape[0], 0 : in_shape[1]]
    centre = np.array([97.3, 41.8])
    image = np.exp(-((xs - centre[0]) ** 2 + (ys - centre[1]) ** 2) / (2 * 4.0**2)).astype(np.float32)
    resized, S = resize_image(image, size, mode)
    assert resized.shape == size and resized.dtype == np.float32
    ys2, xs2 = np.mgrid[0 : size[0], 0 : size[1]]
    weight = resized / resized.sum()
    centroid = np.array([(weight * xs2).sum(), (weight * ys2).sum()])
    mapped = S @ np.append(centre, 1.0)
    np.testing.assert_allclose(centroid, mapped[:2], atol=0.05)


def test_resize_pair_updates_h_and_keeps_the_split():
    image = np.zeros((60, 80), np.float32)
    H = np.array([[1.0, 0.0, 4.0], [0.0, 1.0, -2.0], [0.0, 0.0, 1.0]])
    pair = ImagePair(image, image, H, "viewpoint", "a/1-2")
    half = resize_pair(pair, (30, 40))
    assert (half.split, half.name) == ("viewpoint", "a/1-2")
    np.testing.assert_allclose(half.H, [[1.0, 0.0, 2.0], [0.0, 1.0, -1.0], [0.0, 0.0, 1.0]], atol=1e-12)
    assert resize_pair(pair, None) is pair


def test_read_gray_image_and_uint8_input(tmp_path, rng):
    image = texture(rng, (20, 30))
    assert cv2.imwrite(str(tmp_path / "a.ppm"), cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
    read = read_gray_image(tmp_path / "a.ppm")
    np.testing.assert_allclose(read, image / 255.0, atol=1e-7)
    resized, _ = resize_image(image, (10, 15))
    assert resized.dtype == np.float32 and resized.max() <= 1.0


def test_bad_input(tmp_path, fake_hpatches):
    with pytest.raises(ValueError, match="root must be an HPatches folder"):
        hpatches_scenes(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="holds no HPatches scene folder"):
        iter_hpatches_pairs(tmp_path / "empty")
    with pytest.raises(ValueError, match="split must be 'all', 'illumination', 'viewpoint'"):
        hpatches_scenes(fake_hpatches, "rotation")
    with pytest.raises(ValueError, match=r"size must be \(height, width\)"):
        iter_hpatches_pairs(fake_hpatches, size=(240,))
    with pytest.raises(ValueError, match="resize_mode must be one of"):
        iter_hpatches_pairs(fake_hpatches, resize_mode="pad")
    with pytest.raises(ValueError, match="is not a readable image file"):
        read_gray_image(tmp_path / "missing.ppm")
    with pytest.raises(ValueError, match=r"image must be a grayscale image of shape \(H, W\)"):
        resize_image(np.zeros((10, 10, 3), np.float32), (5, 5))
    (fake_hpatches / "v_wall" / "H_1_3").unlink()
    with pytest.raises(ValueError, match="H_1_3 is missing"):
        list(iter_hpatches_pairs(fake_hpatches, "viewpoint"))
    np.savetxt(fake_hpatches / "v_wall" / "H_1_3", np.eye(3))
    (fake_hpatches / "v_zebra" / "H_1_2").write_text("1 0 0\n0 1 0\n")
    with pytest.raises(ValueError, match="must hold an invertible 3 x 3 matrix"):
        list(iter_hpatches_pairs(fake_hpatches, "viewpoint", max_scenes=2))
