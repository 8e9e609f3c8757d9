"""Tests for evio_lib.features.training.augment: photometric operations against closed forms, homographic warps against
the geometry module, label maps."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from torch.utils.data import default_collate

from evio_lib.features.training.augment import (
    HOMOGRAPHIC_ADAPTATION,
    HOMOGRAPHIC_REAL,
    HOMOGRAPHIC_SYNTHETIC,
    PHOTOMETRIC_OPS,
    PHOTOMETRIC_REAL,
    PHOTOMETRIC_SYNTHETIC,
    HomographicConfig,
    PhotometricConfig,
    Sample,
    additive_gaussian_noise,
    additive_shade,
    additive_speckle_noise,
    check_image,
    filter_keypoints,
    homographic_augment,
    keypoints_to_map,
    map_to_keypoints,
    motion_blur,
    photometric_augment,
    random_brightness,
    random_contrast,
    to_torch_sample,
)
from evio_lib.geometry.homography import crop_to_full_homography, valid_mask, warp_image, warp_points


def smooth_image(rng: np.random.Generator, shape=(120, 160)) -> np.ndarray:
    """A smooth random image in [0.2, 0.8] (no clipping by small photometric changes)."""
    noise = rng.random((shape[0] // 8, shape[1] // 8)).astype(np.float32)
    img = cv2.resize(noise, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)
    img = cv2.GaussianBlur(img, (0, 0), 3.0)
    img = (img - img.min()) / (img.max() - img.min())
    return (0.2 + 0.6 * img).astype(np.float32)


# ------------------------------------------------------------------------------------------------ input checks
def test_check_image_converts_and_rejects():
    assert check_image(np.array([[0, 255]], np.uint8)).dtype == np.float32
    with pytest.raises(ValueError, match=r"image must be a grayscale image of shape \(H, W\); got shape \(2, 2, 3\)"):
        check_image(np.zeros((2, 2, 3), np.float32))
    with pytest.raises(ValueError, match="image must have dtype float32"):
        check_image(np.zeros((2, 2), np.int16))
    with pytest.raises(ValueError, match=r"image must hold finite values in \[0, 1\]"):
        check_image(np.full((2, 2), 1.5, np.float32))
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator or a non-negative int seed"):
        random_brightness(np.zeros((2, 2), np.float32), rng=-1)


def test_operations_do_not_modify_their_input(rng):
    img = smooth_image(rng)
    before = img.copy()
    for op in (additive_gaussian_noise, additive_speckle_noise, random_brightness, random_contrast, additive_shade,
               motion_blur):
        out = op(img, 3)
        assert out.dtype == np.float32 and out.shape == img.shape
        assert 0.0 <= out.min() and out.max() <= 1.0
    photometric_augment(img, 3, PHOTOMETRIC_SYNTHETIC)
    np.testing.assert_array_equal(img, before)


# ------------------------------------------------------------------------------------------------ photometric ops
def test_gaussian_noise_has_the_requested_std():
    img = np.full((300, 300), 0.5, np.float32)
    out = additive_gaussian_noise(img, 1, std_range=(0.05, 0.05))
    assert abs(float((out - img).std()) - 0.05) < 0.002  # 90,000 samples: std error ~ 0.0001
    assert abs(float((out - img).mean())) < 0.001
    stds = [float((additive_gaussian_noise(img, s, std_range=(0.02, 0.08)) - img).std()) for s in range(20)]
    assert 0.02 - 0.002 <= min(stds) and max(stds) <= 0.08 + 0.002 and max(stds) - min(stds) > 0.02


def test_speckle_noise_replaces_about_p_pixels_each_side():
    img = np.full((200, 200), 0.5, np.float32)
    out = additive_speckle_noise(img, 2, prob_range=(0.02, 0.02))
    n = img.size
    for value in (0.0, 1.0):
        frac = float((out == value).mean())
        assert abs(frac - 0.02) < 4 * np.sqrt(0.02 * 0.98 / n)
    untouched = (out != 0.0) & (out != 1.0)
    np.testing.assert_array_equal(out[untouched], 0.5)
    with pytest.raises(ValueError, match=r"prob_range must satisfy 0 <= low <= high <= 0.5"):
        additive_speckle_noise(img, 0, prob_range=(0.2, 0.7))


def test_brightness_is_one_constant_shift_within_range(rng):
    img = smooth_image(rng)
    shifts = []
    for seed in range(40):
        out = random_brightness(img, seed, max_abs_change=0.15)
        diff = out - img
        assert float(diff.max() - diff.min()) < 1e-6  # one constant for the whole image (no clipping here)
        shifts.append(float(diff.mean()))
    assert -0.15 <= min(shifts) < -0.1 and 0.1 < max(shifts) <= 0.15


def test_contrast_scales_deviations_about_the_mean(rng):
    img = smooth_image(rng)
    out = random_contrast(img, 4, strength_range=(1.3, 1.3))
    np.testing.assert_allclose(out, (img - img.mean()) * 1.3 + img.mean(), atol=1e-6)
    factors = []
    for seed in range(30):
        o = random_contrast(img, seed, strength_range=(0.5, 1.5))
        factors.append(float(np.std(o) / np.std(img)))
    assert 0.5 - 1e-4 <= min(factors) < 0.65 and 1.35 < max(factors) <= 1.5 + 1e-4


def test_shade_is_a_smooth_multiplicative_mask():
    img = np.full((120, 160), 0.6, np.float32)
    out = additive_shade(img, 5, transparency_range=(0.5, 0.5), kernel_size_range=(101, 101))
    ratio = out / img  # = 1 - t M with M in [0, 1]
    assert 0.5 - 1e-5 <= ratio.min() < 0.95 and ratio.max() <= 1.0 + 1e-6
    gy, gx = np.gradient(ratio)
    assert float(np.hypot(gx, gy).max()) < 0.05  # blurred: no sharp ellipse edges
    brighter = additive_shade(img * 0.5, 5, transparency_range=(-0.5, -0.5))
    assert (brighter >= img * 0.5 - 1e-6).all() and brighter.max() > 0.31


def test_motion_blur_kernel_is_normalised_and_linear():
    img = np.zeros((41, 41), np.float32)
    img[20, 20] = 1.0
    for seed in range(10):
        out = motion_blur(img, seed, max_kernel_size=9)
        assert abs(float(out.sum()) - 1.0) < 1e-5  # kernel sums to 1
        np.testing.assert_allclose(out, out[::-1, ::-1], atol=1e-6)  # a line through the centre: point-symmetric
        rows, cols = np.nonzero(out > 1e-6)
        assert max(np.abs(rows - 20).max(), np.abs(cols - 20).max()) <= 4  # extent <= (k - 1) / 2
        if (out > 1e-6).sum() > 1:  # a line: second moments of the kernel are rank one (elongated)
            w = out[rows, cols]
            cov = np.cov(np.stack([cols, rows]), aweights=w)
            eig = np.linalg.eigvalsh(cov)
            assert eig[0] < 0.25 * eig[1]
    const = np.full((30, 30), 0.3, np.float32)
    np.testing.assert_allclose(motion_blur(const, 3, max_kernel_size=9), 0.3, atol=1e-6)
    np.testing.assert_array_equal(motion_blur(img, 3, max_kernel_size=1), img)


def test_photometric_augment_is_seeded_and_honours_the_config(rng):
    img = smooth_image(rng)
    a = photometric_augment(img, 11, PHOTOMETRIC_REAL)
    b = photometric_augment(img, 11, PHOTOMETRIC_REAL)
    c = photometric_augment(img, 12, PHOTOMETRIC_REAL)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    only_brightness = PHOTOMETRIC_REAL.replace(ops=("brightness",))
    out = photometric_augment(img, 5, only_brightness)
    diff = out - img
    assert float(diff.max() - diff.min()) < 1e-6
    nothing = PHOTOMETRIC_REAL.replace(probability=0.0)
    np.testing.assert_array_equal(photometric_augment(img, 5, nothing), img)
    # the synthetic preset is much noisier than the real-image one (Gaussian noise up to 95/255)
    rough = np.mean([np.abs(np.diff(photometric_augment(img, s, PHOTOMETRIC_SYNTHETIC), axis=1)).mean()
                     for s in range(5)])
    mild = np.mean([np.abs(np.diff(photometric_augment(img, s, PHOTOMETRIC_REAL), axis=1)).mean() for s in range(5)])
    assert rough > 2 * mild
    assert set(PHOTOMETRIC_REAL.ops) == set(PHOTOMETRIC_OPS)


def test_photometric_config_rejects_bad_values():
    with pytest.raises(ValueError, match=r"ops must be names from"):
        PhotometricConfig(ops=("blur",))
    with pytest.raises(ValueError, match=r"contrast_range must satisfy"):
        PhotometricConfig(contrast_range=(1.5, 0.5))
    with pytest.raises(ValueError, match=r"probability must be a number in \[0, 1\]"):
        PhotometricConfig(probability=2.0)
    with pytest.raises(ValueError, match="config must be a PhotometricConfig"):
        photometric_augment(np.zeros((4, 4), np.float32), 0, config={"ops": ()})


# ------------------------------------------------------------------------------------------------ homographic
@pytest.mark.parametrize("config", [HOMOGRAPHIC_SYNTHETIC, HOMOGRAPHIC_REAL, HOMOGRAPHIC_ADAPTATION])
def test_homography_presets_always_sample(config):
    # sample_homography alone raises on ~15-50 % of these draws (empty translation range with allow_artifacts)
    gen = np.random.default_rng(0)
    Hs = [config.sample((120, 160), gen) for _ in range(100)]
    assert all(H.shape == (3, 3) and H[2, 2] == 1.0 and np.isfinite(H).all() for H in Hs)
    np.testing.assert_array_equal(config.sample((120, 160), 7), config.sample((120, 160), 7))


def test_homographic_augment_moves_keypoints_with_the_image(rng):
    shape = (120, 160)
    keypoints = rng.uniform([20, 20], [140, 100], (15, 2))
    # image: a Gaussian blob (sigma 1.5 px) on every keypoint
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]]
    img = np.zeros(shape, np.float32)
    for x, y in keypoints:
        img = np.maximum(img, np.exp(-((xs - x) ** 2 + (ys - y) ** 2) / (2 * 1.5**2)).astype(np.float32))
    out = homographic_augment(img, keypoints, 3, HOMOGRAPHIC_REAL)
    np.testing.assert_allclose(out.image, warp_image(img, out.homography), atol=1e-6)
    np.testing.assert_array_equal(out.valid_mask, valid_mask(shape, out.homography, erode=3))
    moved = warp_points(out.homography, keypoints)
    keep = filter_keypoints(moved, shape, out.valid_mask)
    np.testing.assert_allclose(out.keypoints, moved[keep], atol=1e-4)
    assert 0 < len(out.keypoints) <= len(keypoints)
    # every kept keypoint sits on a bright blob of the warped image
    values = out.image[np.rint(out.keypoints[:, 1]).astype(int), np.rint(out.keypoints[:, 0]).astype(int)]
    assert values.min() > 0.5
    again = homographic_augment(img, keypoints, 3, HOMOGRAPHIC_REAL)
    np.testing.assert_array_equal(again.image, out.image)


def test_homographic_augment_with_fixed_homography_and_bad_input():
    img = np.zeros((40, 60), np.float32)
    shift = np.array([[1.0, 0, 10], [0, 1.0, 0], [0, 0, 1]])
    out = homographic_augment(img, [[5.0, 5.0], [55.0, 5.0]], 0, HOMOGRAPHIC_REAL.replace(valid_border_margin=0),
                              homography=shift)
    assert out.keypoints.tolist() == [[15.0, 5.0]]  # the second point leaves the image
    assert not out.valid_mask[:, :10].any() and out.valid_mask[:, 10:].all()
    with pytest.raises(ValueError, match=r"keypoints must have shape \(N, 2\)"):
        homographic_augment(img, np.zeros((3, 3)), 0)
    with pytest.raises(ValueError, match="valid_border_margin must be a non-negative int"):
        HomographicConfig(valid_border_margin=-1)



def test_fill_view_stretches_the_patch_onto_the_whole_view():
    shape = (120, 160)
    plain = HOMOGRAPHIC_REAL.replace(allow_artifacts=False, patch_ratio=0.6)
    filled = plain.replace(fill_view=True)
    for seed in range(5):  # same generator draws: the filled homography is the crop-to-full map times the plain one
        A = crop_to_full_homography(shape, 0.6)
        expected = A @ plain.sample(shape, seed)
        np.testing.assert_allclose(filled.sample(shape, seed), expected / expected[2, 2], atol=1e-12)
        # without artifacts the patch lies inside image 1, so the whole warped view saw image 1
        assert valid_mask(shape, filled.sample(shape, seed)).all()
    # the zoom: the patch (about 0.6 of the image) fills the view, so areas grow by about 1 / 0.6 ** 2
    zooms = [abs(np.linalg.det(filled.sample(shape, s)[:2, :2])) ** 0.5 for s in range(50)]
    assert 1.35 < np.median(zooms) < 2.0
    with pytest.raises(ValueError, match="fill_view must be true or false"):
        HomographicConfig(fill_view=1)


# ------------------------------------------------------------------------------------------------ label maps
def test_keypoint_maps_round_to_the_nearest_pixel():
    kp = np.array([[1.4, 2.6], [1.6, 0.0], [-0.6, 1.0], [4.49, 3.0], [4.51, 3.0]])
    label = keypoints_to_map(kp, (4, 5))
    assert label.dtype == np.float32 and label.shape == (4, 5)
    assert sorted(map(tuple, np.argwhere(label == 1).tolist())) == [(0, 2), (3, 1), (3, 4)]
    assert map_to_keypoints(label).tolist() == [[2.0, 0.0], [1.0, 3.0], [4.0, 3.0]]
    mask = np.ones((4, 5), bool)
    mask[3] = False
    assert keypoints_to_map(kp, (4, 5), mask).sum() == 1
    with pytest.raises(ValueError, match=r"mask must have shape \(4, 5\)"):
        keypoints_to_map(kp, (4, 5), np.ones((2, 2), bool))


def test_map_keypoint_roundtrip(rng):
    label = (rng.random((30, 40)) < 0.05).astype(np.float32)
    np.testing.assert_array_equal(keypoints_to_map(map_to_keypoints(label), label.shape), label)


def test_torch_samples_collate(rng):
    img = smooth_image(rng, (32, 48))
    samples = [to_torch_sample(img, [[3.0, 4.0], [10.0, 20.0]]) for _ in range(3)]
    batch = default_collate(samples)
    assert isinstance(batch, Sample)
    assert tuple(batch.image.shape) == (3, 1, 32, 48) and batch.image.dtype == torch.float32
    assert tuple(batch.keypoint_map.shape) == (3, 32, 48) and float(batch.keypoint_map[0, 4, 3]) == 1.0
    assert float(batch.valid_mask.min()) == 1.0
