"""Tests for evio_lib.features.classical: the interface contract of every classical detector, corners of synthetic
images with known positions, shift self-consistency, and the responses against independent formulas and OpenCV."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage
from skimage import data

from evio_lib.features.base import Features, create_detector, nms_keypoints
from evio_lib.features.classical import (
    FastDetector,
    HarrisDetector,
    ShiTomasiDetector,
    fast_score,
    harris_response,
    upright_sift_descriptors,
)
from evio_lib.geometry.homography import warp_image

CLASSICAL = ["harris", "shi_tomasi", "fast", "sift", "orb", "fast_freak"]
DESCRIPTOR = {  # (D, binary) of each detector's descriptors
    "harris": (128, False),
    "shi_tomasi": (128, False),
    "fast": (128, False),
    "sift": (128, False),
    "orb": (32, True),
    "fast_freak": (64, True),
}


@pytest.fixture(scope="module")
def textured() -> np.ndarray:
    """A real photograph (skimage's camera man), 160 x 200, uint8."""
    return cv2.resize(data.camera(), (200, 160), interpolation=cv2.INTER_AREA)


@pytest.fixture(scope="module")
def detections(textured) -> dict[str, Features]:
    """Features of the textured image per detector (max_keypoints 60 so that the cap binds, NMS radius 3)."""
    return {n: create_detector(n, max_keypoints=60, nms_radius=3).detect_and_describe(textured) for n in CLASSICAL}


def checkerboard(square: int = 12, n: int = 6, margin: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Return a float32 checkerboard on grey and its (n + 1)^2 corners (x, y), with pixel centres at integers."""
    size = 2 * margin + n * square
    img = np.full((size, size), 0.5, np.float32)
    yy, xx = np.mgrid[0 : n * square, 0 : n * square]
    img[margin : margin + n * square, margin : margin + n * square] = ((yy // square + xx // square) % 2) * 0.8 + 0.1
    lines = margin - 0.5 + square * np.arange(n + 1)  # square edges lie between pixel centres
    gx, gy = np.meshgrid(lines, lines)
    return img, np.column_stack([gx.ravel(), gy.ravel()])


def polygons() -> tuple[np.ndarray, np.ndarray]:
    """Return a uint8 image with two rectangles and an anti-aliased square turned by 30 degrees, and its 12 corners."""
    img = np.full((120, 160), 50, np.uint8)
    img[20:50, 15:60] = 230
    img[70:100, 30:55] = 150
    corners = [(14.5, 19.5), (59.5, 19.5), (14.5, 49.5), (59.5, 49.5)]  # rectangle edges lie between pixel centres
    corners += [(29.5, 69.5), (54.5, 69.5), (29.5, 99.5), (54.5, 99.5)]
    a = np.radians(30.0)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    square = np.array([115.0, 75.0]) + np.array([[-18, -18], [18, -18], [18, 18], [-18, 18]]) @ rot.T
    cv2.fillPoly(img, [np.round(square * 16).astype(np.int32)], 200, cv2.LINE_AA, shift=4)
    return img, np.vstack([corners, square])


def structure_tensor_responses(img01: np.ndarray, k: float = 0.04) -> tuple[np.ndarray, np.ndarray]:
    """Independent Harris R and Shi-Tomasi lambda_min: 3x3 Sobel, 3x3 window sums, reflect-101 borders.

    OpenCV scales the Sobel derivatives by 1 / (2^(ksize - 1) * block_size) = 1 / 12 for ksize = block_size = 3.
    """
    sobel_x = np.array([[-1, 0, 1], [-2, 0, 2], [-1, 0, 1]], float)
    ix = ndimage.correlate(img01.astype(float), sobel_x, mode="mirror") / 12.0
    iy = ndimage.correlate(img01.astype(float), sobel_x.T, mode="mirror") / 12.0
    box = np.ones((3, 3))
    a = ndimage.correlate(ix * ix, box, mode="mirror")
    b = ndimage.correlate(ix * iy, box, mode="mirror")
    c = ndimage.correlate(iy * iy, box, mode="mirror")
    harris = a * c - b * b - k * (a + c) ** 2  # R = det M - k tr(M)^2
    lam_min = (a + c) / 2 - np.sqrt(((a - c) / 2) ** 2 + b * b)  # smaller eigenvalue of [[a, b], [b, c]]
    return harris, lam_min


def chebyshev_pixel_distances(points: np.ndarray) -> np.ndarray:
    """Pairwise max(|dx|, |dy|) of rounded points, with +inf on the diagonal."""
    px = np.rint(points).astype(int)
    d = np.abs(px[:, None] - px[None]).max(-1).astype(float)
    np.fill_diagonal(d, np.inf)
    return d


# ---------------------------------------------------------------------------------------------- interface contract
@pytest.mark.parametrize("name", CLASSICAL)
def test_contract_shapes_dtypes_order(name, detections, textured):
    f = detections[name]
    dim, binary = DESCRIPTOR[name]
    assert isinstance(f, Features)
    assert 20 <= len(f) <= 60, "the cap binds on a textured image"
    assert f.keypoints.shape == (len(f), 2) and f.keypoints.dtype == np.float32
    assert f.scores.shape == (len(f),) and f.scores.dtype == np.float32
    assert (np.diff(f.scores) <= 0).all(), "scores sorted in descending order"
    assert f.descriptors.shape == (len(f), dim) and f.binary is binary
    if binary:
        assert f.descriptors.dtype == np.uint8
    else:
        assert f.descriptors.dtype == np.float32
        np.testing.assert_allclose(np.linalg.norm(f.descriptors, axis=1), 1.0, atol=1e-5)
    h, w = textured.shape
    assert (f.keypoints[:, 0] >= -0.5).all() and (f.keypoints[:, 0] <= w - 0.5).all()
    assert (f.keypoints[:, 1] >= -0.5).all() and (f.keypoints[:, 1] <= h - 0.5).all()


@pytest.mark.parametrize("name", CLASSICAL)
def test_contract_nms_radius_and_max_keypoints(name, textured):
    for radius, k in ((0, 500), (5, 500), (9, 25)):
        f = create_detector(name, max_keypoints=k, nms_radius=radius).detect_and_describe(textured)
        assert 0 < len(f) <= k
        assert (chebyshev_pixel_distances(f.keypoints) > radius).all(), f"NMS radius {radius} violated"
    # the best k are a prefix of the best 2k (same candidates, same order)
    few = create_detector(name, max_keypoints=20, nms_radius=4).detect_and_describe(textured)
    many = create_detector(name, max_keypoints=40, nms_radius=4).detect_and_describe(textured)
    np.testing.assert_array_equal(few.keypoints, many.keypoints[:20])
    np.testing.assert_array_equal(few.descriptors, many.descriptors[:20])


@pytest.mark.parametrize("name", CLASSICAL)
def test_contract_uint8_and_float_inputs_agree(name, detections, textured):
    before = textured.copy()
    det = create_detector(name, max_keypoints=60, nms_radius=3)
    for image in (textured.astype(np.float32) / np.float32(255), textured.astype(np.float64) / 255):
        g = det.detect_and_describe(image)
        np.testing.assert_array_equal(g.keypoints, detections[name].keypoints)
        np.testing.assert_array_equal(g.scores, detections[name].scores)
        np.testing.assert_array_equal(g.descriptors, detections[name].descriptors)
    np.testing.assert_array_equal(textured, before)  # the input is left untouched


@pytest.mark.parametrize("name", CLASSICAL)
def test_contract_any_size_and_flat_images(name, rng):
    det = create_detector(name, max_keypoints=50, nms_radius=2)
    dim, binary = DESCRIPTOR[name]
    for shape in [(1, 1), (2, 3), (7, 7), (9, 30), (31, 17), (64, 65), (70, 130)]:
        image = (rng.random(shape) * 255).astype(np.uint8)
        f = det.detect_and_describe(image)
        assert f.descriptors.shape == (len(f), dim) and f.binary is binary and len(f) <= 50
        if len(f):
            assert (f.keypoints[:, 0] <= shape[1]).all() and (f.keypoints[:, 1] <= shape[0]).all()
    for flat in (np.zeros((60, 80), np.uint8), np.full((60, 80), 0.5, np.float32), np.ones((60, 80), np.float32)):
        f = det.detect_and_describe(flat)
        assert len(f) == 0 and f.keypoints.shape == (0, 2) and f.descriptors.shape == (0, dim)


@pytest.mark.parametrize("name", CLASSICAL)
def test_contract_bad_images_raise(name):
    det = create_detector(name)
    with pytest.raises(ValueError, match=r"image must be a grayscale image of shape \(H, W\)"):
        det.detect_and_describe(np.zeros((20, 20, 3), np.uint8))
    with pytest.raises(ValueError, match=r"image must have dtype uint8"):
        det.detect_and_describe(np.zeros((20, 20), np.int16))
    with pytest.raises(ValueError, match=r"image must be finite"):
        det.detect_and_describe(np.full((20, 20), np.nan, np.float32))
    with pytest.raises(ValueError, match=r"values in \[0, 1\]"):
        det.detect_and_describe(np.full((20, 20), 255.0, np.float32))


@pytest.mark.parametrize(
    "name, options, match",
    [
        ("harris", dict(k=0.0), r"k must be a finite number in \(0, 0.25\]"),
        ("harris", dict(quality_level=1.5), r"quality_level must be a finite number in \[0, 1\]"),
        ("shi_tomasi", dict(aperture=4), r"aperture must be a Sobel kernel size 3, 5 or 7; got 4"),
        ("shi_tomasi", dict(block_size=1), r"block_size must be an integer >= 2"),
        ("fast", dict(threshold=0), r"threshold must be an integer intensity step in \[1, 255\]"),
        ("fast", dict(descriptor_size=-2.0), r"descriptor_size must be a finite number in \(0, inf\]"),
        ("sift", dict(sigma=0.0), r"sigma must be a finite number"),
        ("sift", dict(n_octave_layers=0), r"n_octave_layers must be an integer >= 1"),
        ("orb", dict(scale_factor=1.0), r"scale_factor must be a finite number in \(1, 4\]"),
        ("orb", dict(fast_threshold=300), r"fast_threshold must be an integer intensity step"),
        ("fast_freak", dict(scale_normalized="yes"), r"scale_normalized must be a bool"),
        ("fast_freak", dict(nonmax=True), r"unknown option\(s\) \['nonmax'\] for detector 'fast_freak'"),
    ],
)
def test_detector_options_are_validated(name, options, match):
    with pytest.raises(ValueError, match=match):
        create_detector(name, **options)


# ---------------------------------------------------------------------------------------------- known corners
@pytest.mark.parametrize("name, tol", [("harris", 1.0), ("shi_tomasi", 2.0)])
def test_checkerboard_corners_found(name, tol):
    img, truth = checkerboard()
    f = create_detector(name, max_keypoints=200, nms_radius=3).detect_and_describe(img)
    dist = np.linalg.norm(truth[:, None] - f.keypoints[None], axis=-1)
    assert dist.min(axis=1).max() <= tol, "every corner and junction is found"
    strongest = f.keypoints[: len(truth)]
    assert np.linalg.norm(strongest[:, None] - truth[None], axis=-1).min(axis=1).max() <= tol, "no spurious points"


@pytest.mark.parametrize("name", ["harris", "shi_tomasi", "fast"])
def test_polygon_corners_found(name):
    img, truth = polygons()
    f = create_detector(name, max_keypoints=100, nms_radius=3).detect_and_describe(img)
    assert np.linalg.norm(truth[:, None] - f.keypoints[None], axis=-1).min(axis=1).max() <= 1.5
    strongest = f.keypoints[: len(truth)]
    assert np.linalg.norm(strongest[:, None] - truth[None], axis=-1).min(axis=1).max() <= 1.5


def test_fast_ignores_checkerboard_x_junctions():
    img, truth = checkerboard()
    f = FastDetector(nms_radius=3).detect_and_describe(img)
    interior = truth[(truth.min(axis=1) > 20) & (truth.max(axis=1) < 20 + 72 - 1)]
    assert np.linalg.norm(interior[:, None] - f.keypoints[None], axis=-1).min(axis=1).min() > 2.0


# ---------------------------------------------------------------------------------------------- self-consistency
@pytest.mark.parametrize(
    "name, min_repeat, min_correct",
    [
        ("harris", 0.9, 0.9),
        ("shi_tomasi", 0.9, 0.9),
        ("fast", 0.9, 0.9),
        ("sift", 0.8, 0.9),
        ("orb", 0.5, 0.8),
        ("fast_freak", 0.8, 0.9),
    ],
)
def test_shift_repeatability_and_matching(name, min_repeat, min_correct, textured):
    """Under a pure shift the keypoints move with the image and descriptors match their shifted selves."""
    shift = np.array([16.0, 8.0])  # multiples of 8 keep SIFT's pyramid levels aligned
    shifted = warp_image(textured, [[1, 0, shift[0]], [0, 1, shift[1]], [0, 0, 1]])
    det = create_detector(name, max_keypoints=200, nms_radius=3)
    f1, f2 = det.detect_and_describe(textured), det.detect_and_describe(shifted)
    p1 = f1.keypoints + shift
    h, w = textured.shape
    margin = 10
    inside = (p1[:, 0] > shift[0] + margin) & (p1[:, 1] > shift[1] + margin)
    inside &= (p1[:, 0] < w - margin) & (p1[:, 1] < h - margin)  # seen by both images, away from the borders
    assert inside.sum() >= 30
    nearest = np.abs(p1[inside][:, None] - f2.keypoints[None]).max(-1).min(axis=1)
    assert (nearest <= 1.0).mean() >= min_repeat
    norm = cv2.NORM_HAMMING if f1.binary else cv2.NORM_L2
    matches = cv2.BFMatcher(norm, crossCheck=True).match(f1.descriptors, f2.descriptors)
    q = np.array([m.queryIdx for m in matches])
    t = np.array([m.trainIdx for m in matches])
    assert len(matches) >= 30
    assert (np.abs(p1[q] - f2.keypoints[t]).max(axis=1) <= 2.0).mean() >= min_correct


def test_detection_is_deterministic(textured):
    for name in CLASSICAL:
        det = create_detector(name, max_keypoints=80)
        a, b = det.detect_and_describe(textured), det.detect_and_describe(textured)
        np.testing.assert_array_equal(a.keypoints, b.keypoints)
        np.testing.assert_array_equal(a.descriptors, b.descriptors)


# ---------------------------------------------------------------------------------------------- responses vs truth
def test_harris_and_shi_tomasi_scores_match_structure_tensor(textured):
    img01 = textured.astype(np.float32) / np.float32(255)
    harris, lam_min = structure_tensor_responses(img01)
    np.testing.assert_allclose(harris_response(textured), harris, atol=1e-6 * np.abs(harris).max())
    for det, truth in ((HarrisDetector(max_keypoints=100), harris), (ShiTomasiDetector(max_keypoints=100), lam_min)):
        f = det.detect_and_describe(textured)
        cols, rows = f.keypoints[:, 0].astype(int), f.keypoints[:, 1].astype(int)
        np.testing.assert_allclose(f.scores, truth[rows, cols], rtol=1e-3, atol=1e-5 * truth.max())
        # each keypoint is a 3x3 local maximum of its response
        assert (truth[rows, cols] >= ndimage.maximum_filter(truth, 3)[rows, cols] - 1e-5 * truth.max()).all()


def test_harris_keeps_the_best_local_maxima(textured):
    """The returned Harris keypoints are exactly: 3x3 maxima above the quality threshold -> NMS -> top k."""
    det = HarrisDetector(max_keypoints=50, nms_radius=4, quality_level=0.01)
    f = det.detect_and_describe(textured)
    r = harris_response(textured)
    is_peak = (r == ndimage.maximum_filter(r, 3, mode="nearest")) & (r > 0.01 * r.max())
    rows, cols = np.nonzero(is_peak)
    pts = np.column_stack([cols, rows]).astype(float)
    keep = nms_keypoints(pts, r[rows, cols], 4, r.shape)[:50]
    np.testing.assert_array_equal(f.keypoints, pts[keep])


def test_fast_score_matches_opencv(textured):
    for threshold in (10, 30):
        kps = cv2.FastFeatureDetector_create(threshold, True).detect(textured)
        pts = np.array(cv2.KeyPoint.convert(kps))
        np.testing.assert_array_equal(fast_score(textured, pts), [k.response for k in kps])
    # the detector's score is the FAST score plus a tie-break below 1
    f = FastDetector(threshold=20, max_keypoints=100).detect_and_describe(textured)
    assert (fast_score(textured, f.keypoints) == np.floor(f.scores)).all()
    assert (fast_score(textured, f.keypoints) > 20 - 1).all()
    with pytest.raises(ValueError, match=r"at least 3 pixels inside the image"):
        fast_score(textured, np.array([[1, 50]]))
    with pytest.raises(ValueError, match=r"points must have shape \(N, 2\)"):
        fast_score(textured, np.zeros((3, 3)))


def test_sift_keeps_opencvs_strongest_keypoint(textured):
    kps = cv2.SIFT_create().detect(textured, None)
    best = max(kps, key=lambda k: k.response)
    f = create_detector("sift", max_keypoints=10).detect_and_describe(textured)
    np.testing.assert_allclose(f.keypoints[0], best.pt, atol=1e-4)
    assert f.scores[0] == pytest.approx(best.response, rel=1e-6)


def test_upright_sift_descriptors_equal_opencv_at_angle_zero(textured):
    pts = np.array([[50.0, 60.0], [120.0, 80.0], [30.0, 140.0]])
    ok, desc = upright_sift_descriptors(textured, pts, 4.0)
    assert ok.all() and desc.shape == (3, 128)
    _, ref = cv2.SIFT_create().compute(textured, [cv2.KeyPoint(x, y, 4.0, 0.0) for x, y in pts])
    np.testing.assert_allclose(desc, ref / np.linalg.norm(ref, axis=1, keepdims=True), rtol=1e-6)
