"""Tests for evio_lib.features.base: the Features record, image conversion, box NMS (against a brute-force greedy
reference) and the detector registry."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from evio_lib.features import base
from evio_lib.features.base import (
    FeatureDetector,
    Features,
    available_detectors,
    create_detector,
    nms_keypoints,
    register_detector,
    to_float_image,
    to_uint8_image,
)

CLASSICAL = ["harris", "shi_tomasi", "fast", "sift", "orb", "fast_freak"]


# ---------------------------------------------------------------------------------------------- Features
def test_features_coerces_dtypes_and_counts():
    f = Features([[1, 2], [3, 4]], np.array([2.0, 1.0]), np.eye(2, dtype=np.float64))
    assert f.keypoints.dtype == np.float32 and f.keypoints.shape == (2, 2)
    assert f.scores.dtype == np.float32 and f.scores.shape == (2,)
    assert f.descriptors.dtype == np.float32 and not f.binary
    assert len(f) == 2
    b = Features(np.zeros((3, 2)), [3, 3, 1], np.zeros((3, 32), np.uint8), binary=True)
    assert b.binary and b.descriptors.dtype == np.uint8 and b.descriptors.shape == (3, 32)


def test_features_does_not_alias_inputs():
    kp = np.array([[1.0, 2.0]], np.float32)
    f = Features(kp, [1.0], [[1.0]])
    kp[0, 0] = 99.0
    assert f.keypoints[0, 0] == 1.0


def test_features_empty_has_right_shapes():
    e = Features.empty(128)
    assert len(e) == 0 and e.keypoints.shape == (0, 2) and e.scores.shape == (0,)
    assert e.descriptors.shape == (0, 128) and e.descriptors.dtype == np.float32
    eb = Features.empty(64, binary=True)
    assert eb.descriptors.shape == (0, 64) and eb.descriptors.dtype == np.uint8 and eb.binary


def test_features_is_frozen():
    f = Features.empty(8)
    with pytest.raises(AttributeError):
        f.binary = True  # type: ignore[misc]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(keypoints=np.zeros((2, 3)), scores=[1, 0], descriptors=np.zeros((2, 4))), r"keypoints must have shape"),
        (dict(keypoints=np.zeros((2, 2)), scores=[1, 0, 0], descriptors=np.zeros((2, 4))), r"scores must have shape"),
        (dict(keypoints=np.zeros((2, 2)), scores=[1, 0], descriptors=np.zeros((3, 4))), r"descriptors must have shape"),
        (dict(keypoints=np.zeros((2, 2)), scores=[1, 0], descriptors=np.zeros(2)), r"shape \(N, D\) with N = 2"),
        (dict(keypoints=np.zeros((2, 2)), scores=[0, 1], descriptors=np.zeros((2, 4))), r"sorted in descending order"),
        (dict(keypoints=[[np.nan, 0], [0, 0]], scores=[1, 0], descriptors=np.zeros((2, 4))), r"finite"),
        (dict(keypoints=np.zeros((1, 2)), scores=[1], descriptors=[[np.inf]]), r"descriptors must be finite"),
        (
            dict(keypoints=np.zeros((1, 2)), scores=[1], descriptors=np.zeros((1, 4), np.float32), binary=True),
            r"binary descriptors must be packed bits of dtype uint8",
        ),
        (dict(keypoints=np.zeros((1, 2)), scores=[1], descriptors=np.zeros((1, 4)), binary="yes"), r"binary must be"),
    ],
)
def test_features_rejects_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Features(**kwargs)


# ---------------------------------------------------------------------------------------------- images
def test_uint8_float_round_trip_is_exact_for_all_levels():
    u = np.arange(256, dtype=np.uint8).reshape(16, 16)
    f = to_float_image(u)
    assert f.dtype == np.float32 and f.shape == (16, 16)
    np.testing.assert_array_equal(f, u.astype(np.float32) / np.float32(255))
    np.testing.assert_array_equal(to_uint8_image(f), u)
    np.testing.assert_array_equal(to_uint8_image(f.astype(np.float64)), u)
    np.testing.assert_array_equal(to_uint8_image(u), u)


def test_image_conversion_returns_new_arrays(rng):
    f = rng.random((5, 7)).astype(np.float32)
    g = to_float_image(f)
    g[:] = 0
    assert f.any()
    u = (f * 255).astype(np.uint8)
    v = to_uint8_image(u)
    v[:] = 0
    assert u.any()


def test_to_uint8_rounds_to_nearest():
    np.testing.assert_array_equal(to_uint8_image(np.array([[0.0, 0.499 / 255, 0.501 / 255, 1.0]])), [[0, 0, 1, 255]])


@pytest.mark.parametrize("func", [to_float_image, to_uint8_image])
@pytest.mark.parametrize(
    "image, match",
    [
        (np.zeros((4, 4, 3), np.uint8), r"image must be a grayscale image of shape \(H, W\); got shape \(4, 4, 3\)"),
        (np.zeros(5, np.uint8), r"grayscale image of shape \(H, W\)"),
        (np.zeros((0, 5), np.uint8), r"non-empty"),
        (np.zeros((4, 4), np.int32), r"dtype uint8 .* or float32/float64 .*got int32"),
        (np.zeros((4, 4), bool), r"dtype uint8"),
        (np.full((4, 4), np.nan, np.float32), r"finite"),
        (np.full((4, 4), 2.0, np.float32), r"values in \[0, 1\]; got range \[2, 2\]"),
        (np.full((4, 4), -0.1), r"values in \[0, 1\]"),
    ],
)
def test_image_validation_errors(func, image, match):
    with pytest.raises(ValueError, match=match):
        func(image)


# ---------------------------------------------------------------------------------------------- NMS
def greedy_nms_reference(keypoints, scores, radius, shape):
    """Brute-force greedy box NMS: a plain loop, O(N^2), written independently from the library version."""
    h, w = shape
    cols = np.clip(np.rint(keypoints[:, 0]).astype(int), 0, w - 1)
    rows = np.clip(np.rint(keypoints[:, 1]).astype(int), 0, h - 1)
    order = sorted(range(len(scores)), key=lambda i: (-scores[i], i))
    kept = []
    for i in order:
        if all(max(abs(cols[i] - cols[j]), abs(rows[i] - rows[j])) > radius for j in kept):
            kept.append(i)
    return kept


@pytest.mark.parametrize("radius", [0, 1, 2, 4, 8])
def test_nms_matches_brute_force_greedy(rng, radius):
    shape = (40, 60)
    for trial in range(4):
        n = int(rng.integers(1, 400))
        kp = np.column_stack([rng.uniform(-0.5, shape[1] - 0.5, n), rng.uniform(-0.5, shape[0] - 0.5, n)])
        if trial % 2:  # integer positions with many duplicates and tied scores
            kp = np.rint(kp * 0.3)
            scores = rng.integers(0, 5, n).astype(float)
        else:
            scores = rng.random(n)
        got = nms_keypoints(kp, scores, radius, shape)
        assert got.dtype == np.intp
        assert got.tolist() == greedy_nms_reference(kp, scores, radius, shape)


def test_nms_result_properties(rng):
    shape, r = (120, 160), 4
    kp = np.column_stack([rng.uniform(0, 159, 3000), rng.uniform(0, 119, 3000)])
    scores = rng.random(3000)
    keep = nms_keypoints(kp, scores, r, shape)
    px = np.rint(kp).astype(int)
    # kept keypoints are pairwise more than r apart (Chebyshev), strongest first
    d = np.abs(px[keep][:, None] - px[keep][None]).max(-1)
    assert (d[~np.eye(keep.size, dtype=bool)] > r).all()
    assert (np.diff(scores[keep]) <= 0).all()
    # every dropped keypoint has a stronger kept one within r
    dropped = np.setdiff1d(np.arange(3000), keep)
    dd = np.abs(px[dropped][:, None] - px[keep][None]).max(-1)
    stronger = scores[keep][None] >= scores[dropped][:, None]
    assert ((dd <= r) & stronger).any(axis=1).all()


def test_nms_worst_case_chain_is_exact():
    # a monotone ramp of keypoints one pixel apart: greedy keeps every (r + 1)-th one
    kp = np.column_stack([np.arange(100.0), np.full(100, 5.0)])
    keep = nms_keypoints(kp, -np.arange(100.0), 3, (10, 100))
    assert keep.tolist() == list(range(0, 100, 4))


def test_nms_edge_cases():
    assert nms_keypoints(np.zeros((0, 2)), np.zeros(0), 4, (10, 10)).shape == (0,)
    assert nms_keypoints([[3.0, 3.0]], [1.0], 4, (10, 10)).tolist() == [0]
    # keypoints half a pixel outside are clipped onto the border, not rejected
    assert nms_keypoints([[-0.6, 9.7], [5.0, 5.0]], [1.0, 2.0], 1, (10, 10)).tolist() == [1, 0]
    # shape may carry a channel count
    assert nms_keypoints([[1.0, 1.0]], [1.0], 2, (10, 10, 3)).tolist() == [0]


@pytest.mark.parametrize(
    "args, match",
    [
        (([[1, 2, 3]], [1.0], 2, (10, 10)), r"keypoints must have shape \(N, 2\)"),
        (([[1, 2]], [1.0, 2.0], 2, (10, 10)), r"scores must have shape \(N,\) = \(1,\)"),
        (([[1, 2]], [np.nan], 2, (10, 10)), r"finite"),
        (([[1, 2]], [1.0], -1, (10, 10)), r"radius must be an integer >= 0"),
        (([[1, 2]], [1.0], 1.5, (10, 10)), r"radius must be an integer"),
        (([[1, 2]], [1.0], 2, (10,)), r"shape must be an image shape"),
        (([[1, 2]], [1.0], 2, (0, 10)), r"positive integers"),
        (([[30, 2]], [1.0], 2, (10, 10)), r"keypoints must lie inside the image of shape \(10, 10\); keypoint 0"),
    ],
)
def test_nms_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        nms_keypoints(*args)


# ---------------------------------------------------------------------------------------------- registry
class _Dummy(FeatureDetector):
    name = "dummy"

    def __init__(self, max_keypoints: int = 1000, nms_radius: int = 4, *, gain: float = 1.0, **options):
        super().__init__(max_keypoints, nms_radius, **options)
        self.gain = gain

    def detect_and_describe(self, image):
        to_float_image(image)
        return Features.empty(4)


@pytest.fixture
def clean_registry(monkeypatch):
    """Run the test with an empty registry of variants, restored afterwards."""
    monkeypatch.setattr(base, "_REGISTERED", {})


def test_available_detectors_lists_builtins_first():
    names = available_detectors()
    assert names[:7] == CLASSICAL + ["superpoint"]


@pytest.mark.parametrize("name", CLASSICAL)
def test_create_detector_builds_each_classical_detector(name):
    det = create_detector(name, max_keypoints=7, nms_radius=2)
    assert isinstance(det, FeatureDetector)
    assert det.name == name and det.max_keypoints == 7 and det.nms_radius == 2
    assert name in repr(det)
    pickle.loads(pickle.dumps(det))  # detectors can be sent to worker processes


def test_create_detector_normalises_names():
    assert create_detector("FAST-FREAK").name == "fast_freak"
    assert create_detector(" Shi-Tomasi ").name == "shi_tomasi"


def test_create_detector_unknown_name_lists_available():
    with pytest.raises(ValueError, match=r"unknown detector name 'surf'; available: harris, shi_tomasi, fast, sift"):
        create_detector("surf")
    with pytest.raises(ValueError, match=r"detector name must be a non-empty string"):
        create_detector("")
    with pytest.raises(ValueError, match=r"detector name must be a non-empty string"):
        create_detector(3)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "options, match",
    [
        (dict(max_keypoints=0), r"max_keypoints must be an integer >= 1; got 0"),
        (dict(max_keypoints=2.5), r"max_keypoints must be an integer"),
        (dict(max_keypoints=True), r"max_keypoints must be an integer"),
        (dict(nms_radius=-1), r"nms_radius must be an integer >= 0; got -1"),
        (dict(colour="red"), r"unknown option\(s\) \['colour'\] for detector 'harris'; accepted options: .*block_size"),
    ],
)
def test_create_detector_rejects_bad_options(options, match):
    with pytest.raises(ValueError, match=match):
        create_detector("harris", **options)


def test_register_detector_round_trip(clean_registry):
    register_detector("My-Variant", _Dummy)
    assert "my_variant" in available_detectors()
    det = create_detector("my_variant", max_keypoints=3, gain=2.0)
    assert isinstance(det, _Dummy) and det.gain == 2.0 and det.max_keypoints == 3
    register_detector("my_variant", _Dummy)  # the same factory again is a no-op
    with pytest.raises(ValueError, match=r"'my_variant' is already registered; pass overwrite=True"):
        register_detector("my_variant", lambda **kw: _Dummy(**kw))
    register_detector("my_variant", lambda **kw: _Dummy(gain=5.0, **kw), overwrite=True)
    assert create_detector("my_variant").gain == 5.0
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['bogus'\] for detector 'dummy'"):
        create_detector("my_variant", bogus=1)


def test_register_detector_rejects_bad_input(clean_registry):
    with pytest.raises(ValueError, match=r"'sift' is already registered"):
        register_detector("sift", _Dummy)
    with pytest.raises(ValueError, match=r"factory must be callable"):
        register_detector("thing", 42)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"non-empty string"):
        register_detector("  ", _Dummy)
    register_detector("not_a_detector", lambda **kw: "nope")
    with pytest.raises(TypeError, match=r"returned str, not a FeatureDetector"):
        create_detector("not_a_detector")


def test_feature_detector_is_abstract():
    with pytest.raises(TypeError):
        FeatureDetector()  # type: ignore[abstract]


# ---------------------------------------------------------------------------------------------- every listed name loads
def _textured_image() -> np.ndarray:
    """Return a 96x128 uint8 image with corners (squares on a ramp), the same on every run."""
    image = np.tile(np.linspace(40, 90, 128, dtype=np.float64), (96, 1))
    for y, x in ((10, 12), (40, 60), (60, 20), (20, 95), (65, 90)):
        image[y:y + 18, x:x + 22] = 230.0
    return image.astype(np.uint8)


@pytest.mark.parametrize("name", available_detectors())
def test_every_available_detector_constructs_and_detects(name):
    """available_detectors() promises create_detector(name) works with no options (issue 17: 'superpoint' did not)."""
    det = create_detector(name, max_keypoints=50)
    assert isinstance(det, FeatureDetector) and det.max_keypoints == 50
    features = det.detect_and_describe(_textured_image())
    assert isinstance(features, Features) and 0 < len(features) <= 50
    assert np.all((features.keypoints >= -0.5) & (features.keypoints <= [127.5, 95.5]))


def test_superpoint_is_the_best_shipped_network():
    from evio_lib.features.network import shipped_weights

    assert base.SUPERPOINT_DEFAULT_WEIGHTS in shipped_weights()
    default = create_detector("superpoint", max_keypoints=100, inference="fused")
    assert default.weights_path.name == base.SUPERPOINT_DEFAULT_WEIGHTS + ".pt"
    named = create_detector(base.SUPERPOINT_DEFAULT_WEIGHTS, max_keypoints=100, inference="fused")
    from evio_lib.features.network import SuperPointDetector

    assert SuperPointDetector().weights_path == default.weights_path   # the class's default names the same file
    image = _textured_image()
    a, b = default.detect_and_describe(image), named.detect_and_describe(image)  # the same network, the same output
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    np.testing.assert_array_equal(a.descriptors, b.descriptors)
    other = create_detector("superpoint", weights="pretrained_detdesc_round2_cpu")  # explicit weights still win
    assert other.weights_path.name == "pretrained_detdesc_round2_cpu.pt"
    untrained = create_detector("superpoint", weights=None, allow_random=True)
    assert untrained.weights_path is None
    with pytest.raises(FileNotFoundError, match=r"SuperPoint weights 'no_such_net' not found"):
        create_detector("superpoint", weights="no_such_net")
