"""Multi-scale inference (features.network.pyramid and SuperPointDetector(scales=...)), against closed forms, the
single-scale detector run by hand on each level, and a known zoom."""
import cv2
import numpy as np
import pytest

from evio_lib.features.base import Features
from evio_lib.features.network import SuperPointDetector
from evio_lib.features.network.postprocessing import postprocess
from evio_lib.features.network.pyramid import (PYRAMID_LEVELS_ABOVE, PYRAMID_MIN_SIDE, PYRAMID_STEP, check_scales,
                                               merge_levels, parse_scales, pyramid_scales, resize_level)


def test_the_automatic_levels_follow_the_shorter_side():
    step = PYRAMID_STEP
    assert step == pytest.approx(2.0 ** -0.25) and PYRAMID_MIN_SIDE == 240 and PYRAMID_LEVELS_ABOVE == 2
    assert pyramid_scales((480, 640)) == pytest.approx([2.0 ** (-k / 4) for k in range(-2, 5)])  # 1.41 ... 0.5
    assert pyramid_scales((640, 480)) == pyramid_scales((480, 640))  # portrait: the same shorter side
    assert pyramid_scales((480, 752)) == pyramid_scales((480, 640))  # EuRoC frames
    for shape in [(180, 240), (260, 346), (240, 320), (100, 100)]:
        assert pyramid_scales(shape) == (1.0,)  # event frames keep the single-scale network, no enlarged level
    assert pyramid_scales((285, 400)) == (1.0,)  # 285 * 2^(-1/4) = 239.7 < 240
    assert pyramid_scales((286, 400)) == pytest.approx([step**-2, 1 / step, 1.0, step])  # 240.5
    assert len(pyramid_scales((960, 1280), levels_above=0)) == 9  # two octaves
    assert pyramid_scales((480, 640), min_side=400, levels_above=2) == pytest.approx([step**-2, 1 / step, 1.0, step])
    for bad in [dict(step=1.0), dict(step=0.0), dict(min_side=0), dict(levels_above=-1), dict(levels_above=True)]:
        with pytest.raises(ValueError):
            pyramid_scales((480, 640), **bad)


@pytest.mark.parametrize("bad", ["big", [], [0.0], [1e-300], [0.05], [1.0, 1.0], [float("nan")], [5.0], [True],
                                 [np.True_], None, [[1.0]]])
def test_bad_scales_are_refused_with_the_expected_form(bad):
    with pytest.raises(ValueError, match="scales"):
        check_scales(bad)
    with pytest.raises(ValueError, match="scales"):
        SuperPointDetector(weights=None, allow_random=True, inference="fused", scales=bad)


@pytest.mark.parametrize("bad", ["", "x", "1,x", "0", "1,1", "auto,1", "5"])
def test_a_command_line_pyramid_is_parsed_or_refused_in_words(bad):
    assert parse_scales(" auto ") == "auto" and parse_scales("1") == (1.0,)
    assert parse_scales("1.41,1,0.5") == (1.41, 1.0, 0.5)
    with pytest.raises(ValueError, match="comma-separated"):
        parse_scales(bad)


def test_a_level_is_the_area_average_of_the_image():
    image = np.random.default_rng(0).random((48, 64)).astype(np.float32)
    half = resize_level(image, 0.5)
    assert half.shape == (24, 32) and half.dtype == np.float32
    np.testing.assert_allclose(half, image.reshape(24, 2, 32, 2).mean(axis=(1, 3)), atol=1e-6)
    assert resize_level(image, 1.0) is image
    enlarged = resize_level(image, 1.5)
    assert enlarged.shape == (72, 96) and enlarged.min() >= 0.0 and enlarged.max() <= 1.0  # bicubic, clipped
    white = np.ones((720, 1280), np.float32)  # area sums of ones can exceed 1 by rounding: clipped too
    assert all(resize_level(white, s).max() <= 1.0 for s in pyramid_scales(white.shape))


def test_merged_levels_map_back_to_image_pixels_best_first():
    def feats(points, scores, fill):
        n = len(points)
        return Features(np.array(points, np.float64).reshape(n, 2), np.array(scores), np.full((n, 3), fill, np.float32))

    full = feats([[10.0, 20.0], [3.0, 4.0]], [0.6, 0.2], 1.0)
    half = feats([[4.5, 9.5], [0.0, 0.0], [49.6, 49.6]], [0.9, 0.6, 0.1], 2.0)
    merged = merge_levels([full, half], [(100, 100), (50, 50)], (100, 100), max_keypoints=4)
    # x = (x_s + 1/2) W / W_s - 1/2: (4.5, 9.5) -> (9.5, 19.5), (0, 0) -> (0.5, 0.5); the tie at 0.6 keeps level order
    np.testing.assert_allclose(merged.keypoints, [[9.5, 19.5], [10.0, 20.0], [0.5, 0.5], [3.0, 4.0]])
    np.testing.assert_allclose(merged.scores, [0.9, 0.6, 0.6, 0.2])
    np.testing.assert_allclose(merged.descriptors[:, 0], [2.0, 1.0, 2.0, 1.0])
    enlarged = feats([[0.0, 0.0], [140.0, 70.0]], [0.5, 0.4], 3.0)  # a level of 141 x 141 for a 100 x 100 image
    clipped = merge_levels([enlarged], [(141, 141)], (100, 100), max_keypoints=10)
    np.testing.assert_allclose(clipped.keypoints, [[0.0, 0.0], [99.0, 49.5]], atol=1e-4)  # -0.145 clipped to 0
    kept = merge_levels([enlarged, full], [(141, 141), (100, 100)], (100, 100), max_keypoints=10, border=4)
    np.testing.assert_allclose(kept.keypoints, [[10.0, 20.0]])  # (0, 0), (99, 49.5) and (3, 4) lie within 4 px
    assert len(merge_levels([full], [(100, 100)], (100, 100), 10, border=3)) == 2
    with pytest.raises(ValueError, match="one shape per level"):
        merge_levels([full, half], [(100, 100)], (100, 100), 4)


@pytest.fixture(scope="module")
def textured():
    """A 480 x 640 photograph of the validation pool (scikit-image's coins), never trained on."""
    from evio_lib.features.training.datasets import image_pool

    pool, names = image_pool("val", seed=0, size=(480, 640), n_images=1, return_sources=True)
    assert names == ["photo:coins"]
    return pool[0]


def test_single_scale_is_the_thesis_detector_and_small_images_stay_single_scale(textured):
    auto = SuperPointDetector(max_keypoints=300, nms_radius=4, inference="fused")
    small = textured[:180, :240]
    for image in (small, np.round(small * 255).astype(np.uint8)):
        out, shape = auto._run(image)  # the network's outputs, then the thesis's post-processing by hand
        by_hand = postprocess(out["logits"], out["descriptors"], image_shape=shape, threshold=auto.threshold,
                              nms_radius=4, border=auto.border, max_keypoints=300,
                              subpixel_radius=auto.subpixel_radius)[0]
        found = auto.detect_and_describe(image)
        np.testing.assert_array_equal(found.keypoints, by_hand.keypoints)
        np.testing.assert_array_equal(found.descriptors, by_hand.descriptors)
    assert auto.scales_for(small.shape) == (1.0,) and len(auto.scales_for(textured.shape)) == 7
    assert "scales='auto'" in repr(auto)


def test_each_level_is_the_single_scale_detector_on_the_resized_image(textured):
    two = SuperPointDetector(max_keypoints=400, nms_radius=4, inference="fused", scales=(1.0, 0.5))
    single = SuperPointDetector(max_keypoints=400, nms_radius=4, inference="fused", scales=(1.0,))
    merged = two.detect_and_describe(textured)
    full = single.detect_and_describe(textured)
    half = single.detect_and_describe(cv2.resize(textured, (320, 240), interpolation=cv2.INTER_AREA))
    points = np.concatenate([full.keypoints, (half.keypoints + 0.5) * 2.0 - 0.5])
    scores = np.concatenate([full.scores, half.scores])
    order = np.argsort(-scores, kind="stable")[:400]
    np.testing.assert_allclose(merged.keypoints, points[order], atol=1e-4)
    np.testing.assert_allclose(merged.scores, scores[order])
    np.testing.assert_allclose(merged.descriptors, np.concatenate([full.descriptors, half.descriptors])[order],
                               atol=1e-6)
    assert len(merged) == 400


def _correct_mutual_matches(detector, image1, image2, H, tol=3.0):
    """Return the number of mutual nearest-neighbour matches whose point in image 2 lies within tol of H x1."""
    f1, f2 = detector.detect_and_describe(image1), detector.detect_and_describe(image2)
    similarity = f1.descriptors @ f2.descriptors.T
    forward, backward = similarity.argmax(1), similarity.argmax(0)
    mutual = np.flatnonzero(backward[forward] == np.arange(len(f1)))
    mapped = cv2.perspectiveTransform(f1.keypoints[mutual].reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
    return int((np.linalg.norm(mapped - f2.keypoints[forward[mutual]], axis=1) <= tol).sum())


def test_the_pyramid_matches_across_a_zoom_that_the_single_scale_network_misses(textured):
    # image 2 is the centre of image 1 enlarged 1.5 times: x2 = 1.5 (x1 - c) + c', a known homography
    zoom = 1.5
    H = np.array([[zoom, 0.0, 319.5 - zoom * 319.5], [0.0, zoom, 239.5 - zoom * 239.5], [0.0, 0.0, 1.0]])
    zoomed = np.clip(cv2.warpPerspective(textured, H, (640, 480), flags=cv2.INTER_CUBIC), 0.0, 1.0)
    auto = SuperPointDetector(max_keypoints=1000, nms_radius=8, inference="fused")
    single = SuperPointDetector(max_keypoints=1000, nms_radius=8, inference="fused", scales=(1.0,))
    n_auto = _correct_mutual_matches(auto, textured, zoomed, H)
    n_single = _correct_mutual_matches(single, textured, zoomed, H)
    assert n_auto > 2 * n_single + 50, (n_auto, n_single)  # measured: 148 against 35
