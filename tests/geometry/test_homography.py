"""Tests for evio_lib.geometry.homography against projections of 3-D planes, closed forms and OpenCV."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.homography import (
    crop_to_full_homography,
    homography_from_plane,
    sample_homography,
    valid_mask,
    warp_image,
    warp_points,
)

K1 = np.array([[200.0, 0.0, 120.0], [0.0, 200.0, 90.0], [0.0, 0.0, 1.0]])
K2 = np.array([[250.0, 0.0, 150.0], [0.0, 240.0, 100.0], [0.0, 0.0, 1.0]])


def project(K: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Return pixels (N, 2) of camera-frame points (N, 3)."""
    uvw = X @ K.T
    return uvw[:, :2] / uvw[:, 2:]


def plane_scene(rng: np.random.Generator, n: int = 50):
    """Return (R, t, n_C1, d, uv1, uv2) for random points of a random plane seen by two cameras."""
    R = Rotation.from_rotvec(rng.normal(0.0, 0.1, 3)).as_matrix()
    t = rng.normal(0.0, 0.3, 3)
    n_C1 = np.array([0.2, -0.3, -1.0]) + rng.normal(0.0, 0.1, 3)
    n_C1 /= np.linalg.norm(n_C1)
    # points on n^T X = d in front of camera 1: X = depth * ray with depth = d / (n^T ray)
    rays = np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)), np.ones(n)])
    d = -4.0 if (rays @ n_C1).mean() < 0 else 4.0
    n_C1 = n_C1 if d > 0 else -n_C1
    d = abs(d)
    X_C1 = rays * (d / (rays @ n_C1))[:, None]
    assert (X_C1[:, 2] > 0).all()
    np.testing.assert_allclose(X_C1 @ n_C1, d)
    X_C2 = X_C1 @ R.T + t
    assert (X_C2[:, 2] > 0).all()
    return R, t, n_C1, d, project(K1, X_C1), project(K2, X_C2)


# ------------------------------------------------------------------------------------------ plane homography
def test_homography_from_plane_maps_view1_to_view2(rng):
    for _ in range(5):
        R, t, n_C1, d, uv1, uv2 = plane_scene(rng)
        H = homography_from_plane(R, t, n_C1, d, K1, K2)
        assert H[2, 2] == 1.0
        np.testing.assert_allclose(warp_points(H, uv1), uv2, atol=1e-9)
        H_cv, _ = cv2.findHomography(uv1, uv2, 0)
        np.testing.assert_allclose(H, H_cv / H_cv[2, 2], rtol=1e-6, atol=1e-8)


def test_homography_from_plane_pure_rotation_is_infinite_homography(rng):
    R = Rotation.from_rotvec([0.1, -0.2, 0.05]).as_matrix()
    H = homography_from_plane(R, np.zeros(3), [0.0, 0.0, 1.0], 3.0, K1, K2)
    H_inf = K2 @ R @ np.linalg.inv(K1)
    np.testing.assert_allclose(H, H_inf / H_inf[2, 2], atol=1e-12)
    H_col = homography_from_plane(R, np.zeros((3, 1)), [0.0, 0.0, 1.0], 3.0, K1, K2)
    np.testing.assert_array_equal(H, H_col)


def test_homography_from_plane_bad_input():
    args = dict(R_C1toC2=np.eye(3), p_C1inC2=[0.1, 0.0, 0.0], n_C1=[0.0, 0.0, 1.0], d=2.0, K1=K1, K2=K2)
    with pytest.raises(ValueError, match="n_C1 must be a unit normal"):
        homography_from_plane(**{**args, "n_C1": [0.0, 0.0, 2.0]})
    with pytest.raises(ValueError, match="d must be a positive"):
        homography_from_plane(**{**args, "d": -1.0})
    with pytest.raises(ValueError, match=r"p_C1inC2 must have shape \(3,\)"):
        homography_from_plane(**{**args, "p_C1inC2": [0.1, 0.0]})
    with pytest.raises(ValueError, match="R_C1toC2 must be a rotation matrix"):
        homography_from_plane(**{**args, "R_C1toC2": np.diag([1.0, 1.0, -1.0])})
    with pytest.raises(ValueError, match="K2 must be an invertible"):
        homography_from_plane(**{**args, "K2": np.zeros((3, 3))})


# ------------------------------------------------------------------------------------------ warp_points
def test_warp_points_matches_opencv_and_does_not_modify_input(rng):
    H = np.array([[1.1, 0.05, 3.0], [-0.02, 0.95, -2.0], [1e-4, -2e-4, 1.0]])
    pts = rng.uniform(0, 200, (30, 2))
    copy = pts.copy()
    expected = cv2.perspectiveTransform(pts[None], H)[0]
    np.testing.assert_allclose(warp_points(H, pts), expected, atol=1e-9)
    np.testing.assert_array_equal(pts, copy)
    np.testing.assert_allclose(warp_points(np.linalg.inv(H), warp_points(H, pts)), pts, atol=1e-9)
    assert warp_points(H, np.zeros((0, 2))).shape == (0, 2)


def test_warp_points_bad_input():
    H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.01, 0.0, 1.0]])  # x = -100 maps to infinity
    with pytest.raises(ValueError, match="map to infinity"):
        warp_points(H, [[5.0, 5.0], [-100.0, 3.0]])
    with pytest.raises(ValueError, match=r"points must have shape \(N, 2\)"):
        warp_points(H, [1.0, 2.0])
    with pytest.raises(ValueError, match=r"H must have shape \(3, 3\)"):
        warp_points(np.eye(2), [[1.0, 2.0]])


# ------------------------------------------------------------------------------------------ warp_image, valid_mask
def ramp_image(shape: tuple[int, int]) -> np.ndarray:
    """Return the float32 image f(x, y) = 0.1 + 0.003 x + 0.002 y (bilinear interpolation reproduces it)."""
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]]
    return (0.1 + 0.003 * xs + 0.002 * ys).astype(np.float32)


def test_warp_image_samples_source_at_inverse_mapped_pixels(rng):
    shape = (90, 120)
    H = sample_homography(shape, rng, patch_ratio=0.8)
    out = warp_image(ramp_image(shape), H)
    assert out.dtype == np.float32 and out.shape == shape
    mask = valid_mask(shape, H, erode=1)
    ys, xs = np.nonzero(mask)
    src = warp_points(np.linalg.inv(H), np.column_stack([xs, ys]).astype(float))
    expected = 0.1 + 0.003 * src[:, 0] + 0.002 * src[:, 1]
    # OpenCV quantises sub-pixel positions to 1/32 px: error <= (0.003 + 0.002) / 32
    np.testing.assert_allclose(out[ys, xs], expected, atol=2e-4)
    assert mask.mean() > 0.3


def test_warp_image_integer_shift_dtypes_channels_and_out_shape(rng):
    img = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    H = np.array([[1.0, 0.0, 4.0], [0.0, 1.0, -3.0], [0.0, 0.0, 1.0]])  # x + 4, y - 3
    out = warp_image(img, H, out_shape=(25, 40), interpolation=cv2.INTER_NEAREST, border_value=7)
    assert out.dtype == np.uint8 and out.shape == (25, 40, 3)
    np.testing.assert_array_equal(out[0:17, 4:34], img[3:20, 0:30])
    assert (out[17:] == 7).all() and (out[:, :4] == 7).all()
    single = warp_image(img[:, :, :1], H)
    assert single.shape == (20, 30, 1)
    f32 = warp_image(img[:, :, 0].astype(np.float32) / 255.0, H)
    assert f32.dtype == np.float32 and 0.0 <= f32.min() and f32.max() <= 1.0


def test_valid_mask_consistent_with_opencv_warp(rng):
    shape = (60, 80)
    for _ in range(5):
        H = sample_homography(shape, rng, patch_ratio=0.7, allow_artifacts=True, translation_overflow=0.1)
        mask = valid_mask(shape, H)
        ones = np.ones(shape, np.float32)
        linear = cv2.warpPerspective(ones, H, shape[::-1], flags=cv2.INTER_LINEAR, borderValue=0.0)
        nearest = cv2.warpPerspective(ones, H, shape[::-1], flags=cv2.INTER_NEAREST, borderValue=0.0)
        np.testing.assert_allclose(linear[mask], 1.0, atol=1e-6)  # a valid pixel never blends in the border
        assert (nearest[mask] == 1.0).all()
        # invalid pixels are border, except a band under one pixel wide where nearest still hits the image
        band = mask ^ cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        assert (nearest[~mask & ~band] == 0.0).all()
        np.testing.assert_array_equal(warp_image(ones, H, interpolation=cv2.INTER_LINEAR)[mask], 1.0)


def test_valid_mask_shift_and_erode():
    H = np.array([[1.0, 0.0, 5.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # shift right by 5 px
    mask = valid_mask((10, 20), H)
    expected = np.zeros((10, 20), bool)
    expected[:, 5:] = True
    np.testing.assert_array_equal(mask, expected)
    np.testing.assert_array_equal(valid_mask((10, 20), -2.0 * H), mask)  # H's scale and sign do not matter
    eroded = valid_mask((10, 20), H, erode=2)
    expected[:, 5:7] = False  # only the side next to invalid pixels shrinks
    np.testing.assert_array_equal(eroded, expected)
    assert valid_mask((10, 20, 3), H, out_shape=(12, 30)).shape == (12, 30)


def test_warp_image_and_valid_mask_bad_input():
    H = np.eye(3)
    with pytest.raises(ValueError, match="image must have dtype float32"):
        warp_image(np.zeros((5, 5), np.int32), H)
    with pytest.raises(ValueError, match=r"image must have shape \(H, W\) or \(H, W, C\)"):
        warp_image(np.zeros((5, 5, 6), np.float32), H)
    with pytest.raises(ValueError, match="H must be an invertible"):
        warp_image(np.zeros((5, 5), np.float32), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="out_shape must be an image shape"):
        warp_image(np.zeros((5, 5), np.float32), H, out_shape=(0, 5))
    with pytest.raises(ValueError, match="erode must be a non-negative integer"):
        valid_mask((5, 5), H, erode=-1)
    with pytest.raises(ValueError, match="in_shape must be an image shape"):
        valid_mask(5, H)


# ------------------------------------------------------------------------------------------ sample_homography
OFF = dict(perspective=False, scaling=False, rotation=False, translation=False)
SHAPE = (120, 160)
SIZE = np.array([159.0, 119.0])  # pixel-centre extent (x, y)


def crop_corners(patch_ratio: float) -> np.ndarray:
    """Return the corners of the central crop of the warped image."""
    margin = (1.0 - patch_ratio) / 2.0
    return (margin + patch_ratio * np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])) * SIZE


def test_sample_homography_deterministic_and_identity():
    H1 = sample_homography(SHAPE, np.random.default_rng(3))
    np.testing.assert_array_equal(H1, sample_homography(SHAPE, np.random.default_rng(3)))
    np.testing.assert_array_equal(H1, sample_homography(SHAPE, 3))
    assert not np.allclose(H1, sample_homography(SHAPE, np.random.default_rng(4)))
    np.testing.assert_allclose(sample_homography(SHAPE, np.random.default_rng(0), **OFF), np.eye(3), atol=1e-12)


def test_sample_homography_patch_stays_inside_without_artifacts(rng):
    outside = 0
    for _ in range(100):
        H = sample_homography(SHAPE, rng, patch_ratio=0.6, perspective_amplitude_x=0.3, perspective_amplitude_y=0.3)
        patch = warp_points(np.linalg.inv(H), crop_corners(0.6))  # where the crop came from in the original
        assert (patch >= -1e-6).all() and (patch <= SIZE + 1e-6).all()
        assert valid_mask(SHAPE, H)[24:96, 32:128].all()  # the warped crop saw only the original image
        H_art = sample_homography(SHAPE, rng, patch_ratio=0.6, allow_artifacts=True, translation_overflow=0.2)
        patch = warp_points(np.linalg.inv(H_art), crop_corners(0.6))
        outside += not ((patch >= 0).all() and (patch <= SIZE).all())
    assert outside > 10  # with artifacts allowed the patch does leave the image


def test_sample_homography_rotation_and_scale_within_range(rng):
    angles = np.linspace(-np.pi / 4, np.pi / 4, 7)
    seen = set()
    centre = SIZE / 2.0
    for _ in range(40):
        H = sample_homography(SHAPE, rng, **{**OFF, "rotation": True}, n_angles=7, max_angle=np.pi / 4, patch_ratio=0.3)
        A = H[:2, :2]
        np.testing.assert_allclose(A @ A.T, np.eye(2), atol=1e-9)  # a pure rotation ...
        np.testing.assert_allclose(warp_points(H, centre[None])[0], centre, atol=1e-9)  # ... about the image centre
        angle = np.arctan2(A[1, 0], A[0, 0])
        assert np.min(np.abs(np.abs(angle) - np.abs(angles))) < 1e-9 and abs(angle) <= np.pi / 4 + 1e-12
        seen.add(round(abs(angle), 6))
    assert len(seen) >= 3
    for _ in range(40):
        H = sample_homography(SHAPE, rng, **{**OFF, "scaling": True}, scaling_amplitude=0.2, patch_ratio=0.5)
        np.testing.assert_allclose(H[:2, :2], H[0, 0] * np.eye(2), atol=1e-12)  # isotropic scaling
        patch_scale = 1.0 / H[0, 0]  # H maps the scaled patch back onto the crop
        assert 0.8 <= patch_scale <= 1.2
        np.testing.assert_allclose(warp_points(H, centre[None])[0], centre, atol=1e-9)
    H = sample_homography(SHAPE, rng, **{**OFF, "translation": True}, patch_ratio=0.5)
    np.testing.assert_allclose(H[:2, :2], np.eye(2), atol=1e-12)
    assert np.all(np.abs(H[:2, 2]) <= SIZE / 4 + 1e-9)
    H = sample_homography(SHAPE, rng, **{**OFF, "perspective": True})
    assert np.abs(H[2, :2]).max() > 0.0


def test_sample_homography_bad_input(rng):
    with pytest.raises(ValueError, match="shape must be an image shape"):
        sample_homography((0, 10), rng)
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        sample_homography(SHAPE, None)
    with pytest.raises(ValueError, match="patch_ratio must be a fraction"):
        sample_homography(SHAPE, rng, patch_ratio=1.5)
    with pytest.raises(ValueError, match="n_angles must be a positive integer"):
        sample_homography(SHAPE, rng, n_angles=0)
    with pytest.raises(ValueError, match="scaling_amplitude must be a finite number >= 0"):
        sample_homography(SHAPE, rng, scaling_amplitude=-0.1)


def test_sample_homography_with_artifacts_never_fails_on_large_patches():
    """With artifacts allowed, a perturbed patch wider than the image must still give a homography (not an error)."""
    rng = np.random.default_rng(11)
    for _ in range(500):
        H = sample_homography((240, 320), rng, allow_artifacts=True, scaling_amplitude=0.2, patch_ratio=0.85,
                              perspective_amplitude_x=0.2, perspective_amplitude_y=0.2, max_angle=np.pi / 2)
        assert H.shape == (3, 3) and np.all(np.isfinite(H))


def test_crop_to_full_homography_rejects_a_bad_ratio():
    for bad in (0.0, 1.5, -0.2):
        with pytest.raises(ValueError, match=r"patch_ratio must be in \(0, 1\]"):
            crop_to_full_homography((10, 10), bad)
    np.testing.assert_array_equal(crop_to_full_homography((10, 10), 1.0), np.eye(3))  # the whole image: identity
