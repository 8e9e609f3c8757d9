"""Tests of evio_lib.frontend.redetection against images with a known relation."""
import cv2
import numpy as np
import pytest

from evio_lib.features.base import create_detector
from evio_lib.frontend.redetection import redetection


def _texture(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    small = rng.random((24, 32)).astype(np.float32)
    image = cv2.GaussianBlur(cv2.resize(small, (320, 240), interpolation=cv2.INTER_CUBIC), (5, 5), 1.0)
    return np.clip(image, 0.0, 1.0)


@pytest.fixture(scope="module")
def sift():
    return create_detector("sift", max_keypoints=300)


def test_same_image_is_fully_redetected(sift):
    image = _texture(0)
    r = redetection(sift, image, image)
    assert r.transferred > 30 and r.rate == 1.0 and r.match_rate == 1.0


def test_shifted_image_is_mostly_redetected(sift):
    image = _texture(1)
    shifted = np.roll(image, (2, 3), axis=(0, 1))  # content moves by (dx, dy) = (3, 2) px
    r = redetection(sift, image, shifted)
    assert r.rate > 0.8 and r.match_rate > 0.9


def test_noise_lowers_the_rate(sift):
    image = _texture(2)
    noisy = np.clip(image + np.random.default_rng(3).normal(0, 0.08, image.shape), 0, 1).astype(np.float32)
    clean = redetection(sift, image, np.roll(image, 1, axis=1))
    assert redetection(sift, image, noisy).rate < clean.rate


def test_bad_input(sift):
    with pytest.raises(ValueError, match="same shape"):
        redetection(sift, _texture(0), _texture(0)[:100])
    with pytest.raises(ValueError, match="must be > 0"):
        redetection(sift, _texture(0), _texture(0), radius_px=0)
