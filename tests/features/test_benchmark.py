"""Tests for evio_lib.features.evaluation.benchmark: data sets with known geometry, the run on easy cases, tables and
the CLI."""
from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from skimage import data as skdata

from evio_lib.features.base import Features, FeatureDetector, create_detector
from evio_lib.features.evaluation.benchmark import (
    BenchmarkSettings,
    diagnose_pairs,
    event_frame_pairs,
    format_table,
    heldout_pairs,
    illumination_change,
    illumination_pairs,
    main_benchmark,
    measure_speed,
    run_benchmark,
    viewpoint_pairs,
)
from evio_lib.features.evaluation.evaluate import diagnose_matches
from evio_lib.features.evaluation.hpatches import ImagePair, resize_pair


@pytest.fixture(scope="module")
def camera() -> np.ndarray:
    """A real photograph shipped with scikit-image, downsized to 240 x 320 (float32 in [0, 1])."""
    return cv2.resize(skdata.camera(), (320, 240), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


def corners(shape) -> np.ndarray:
    h, w = shape
    return np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], np.float64)


def cv_warp(H, pts) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(pts, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)


class PatchDetector(FeatureDetector):
    """A small deterministic detector for the tests: Shi-Tomasi corners, 9x9 patch descriptors (L2-normalised)."""

    name = "patch"

    def detect_and_describe(self, image):
        img = np.asarray(image, np.float32)
        pts = cv2.goodFeaturesToTrack(img, self.max_keypoints, 0.01, max(self.nms_radius, 1), blockSize=3)
        pts = np.zeros((0, 2), np.float32) if pts is None else pts.reshape(-1, 2)
        pts = pts[(pts[:, 0] >= 4) & (pts[:, 0] < img.shape[1] - 5) & (pts[:, 1] >= 4) & (pts[:, 1] < img.shape[0] - 5)]
        xi, yi = np.rint(pts[:, 0]).astype(int), np.rint(pts[:, 1]).astype(int)
        offsets = np.arange(-4, 5)
        patches = img[yi[:, None, None] + offsets[None, :, None], xi[:, None, None] + offsets[None, None, :]]
        desc = patches.reshape(len(pts), -1) - patches.reshape(len(pts), -1).mean(1, keepdims=True)
        desc /= np.linalg.norm(desc, axis=1, keepdims=True) + 1e-12
        scores = np.linspace(1.0, 0.5, len(pts), dtype=np.float32)  # goodFeaturesToTrack returns strongest first
        return Features(pts, scores, desc.astype(np.float32))


# ---------------------------------------------------------------------------------------------- settings
def test_settings_follow_the_thesis():
    s = BenchmarkSettings.thesis_hpatches()
    assert (s.repeatability_size, s.repeatability_keypoints, s.repeatability_nms) == ((240, 320), 300, 4)
    assert (s.homography_size, s.homography_keypoints, s.homography_nms) == ((480, 640), 1000, 8)
    assert s.eps == (1.0, 3.0, 5.0)
    e = BenchmarkSettings.thesis_event_frames()
    assert (e.repeatability_keypoints, e.homography_size, e.homography_nms) == (100, (240, 320), 4)
    with pytest.raises(ValueError, match="repeatability_keypoints must be a positive integer"):
        BenchmarkSettings(repeatability_keypoints=0)
    with pytest.raises(ValueError, match="homography_size must be"):
        BenchmarkSettings(homography_size=(480,))
    with pytest.raises(ValueError, match="tasks must name"):
        BenchmarkSettings(tasks=("speed",))
    with pytest.raises(ValueError, match="eps must be a non-empty sequence"):
        BenchmarkSettings(eps=(1.0, -3.0))


# ---------------------------------------------------------------------------------------------- data sets
def test_viewpoint_pairs_are_warps_that_fill_the_view(camera):
    pairs = viewpoint_pairs([camera], seed=3, pairs_per_image=3, noise_std=0.0)
    assert [p.name for p in pairs] == ["viewpoint/0000/1-2", "viewpoint/0000/1-3", "viewpoint/0000/1-4"]
    for pair in pairs:
        assert pair.split == "viewpoint" and pair.image2.shape == camera.shape and pair.image2.dtype == np.float32
        # image 2 is image 1 warped by H (checked with OpenCV directly) ...
        expected = cv2.warpPerspective(camera, pair.H, camera.shape[::-1], flags=cv2.INTER_LINEAR)
        np.testing.assert_allclose(pair.image2, expected, atol=1e-6)
        # ... and every corner of image 2 comes from inside image 1: no empty border
        back = cv_warp(np.linalg.inv(pair.H), corners(camera.shape))
        assert (back >= -1e-6).all() and (back[:, 0] <= camera.shape[1] - 1 + 1e-6).all()
        assert (back[:, 1] <= camera.shape[0] - 1 + 1e-6).all()
        assert not np.allclose(pair.H, np.eye(3), atol=0.05)  # a real viewpoint change


def test_pairs_are_fixed_by_the_seed_and_independent_of_the_image_count(camera):
    other = np.ascontiguousarray(camera[::-1])
    one = viewpoint_pairs([camera], seed=5, pairs_per_image=2)
    two = viewpoint_pairs([camera, other], seed=5, pairs_per_image=2)
    again = viewpoint_pairs([camera], seed=5, pairs_per_image=2)
    for a, b, c in zip(one, two[:2], again):
        np.testing.assert_array_equal(a.H, b.H)
        np.testing.assert_array_equal(a.image2, c.image2)
    assert not np.allclose(one[0].H, viewpoint_pairs([camera], seed=6, pairs_per_image=1)[0].H)


def test_illumination_pairs_change_only_intensities(camera):
    pairs = illumination_pairs([camera], seed=0, pairs_per_image=4)
    assert len(pairs) == 4 and all(p.split == "illumination" for p in pairs)
    for pair in pairs:
        np.testing.assert_array_equal(pair.H, np.eye(3))
        assert pair.image2.dtype == np.float32 and 0.0 <= pair.image2.min() and pair.image2.max() <= 1.0
        assert np.abs(pair.image2 - camera).mean() > 0.01  # visibly changed ...
        # ... but the structure is still there: strong correlation of the gradients
        gx1 = cv2.Sobel(camera, cv2.CV_32F, 1, 0)
        gx2 = cv2.Sobel(pair.image2, cv2.CV_32F, 1, 0)
        assert np.corrcoef(gx1.ravel(), gx2.ravel())[0, 1] > 0.5
    # strength 0 keeps the image (up to 8-bit quantisation)
    same = illumination_change(camera, np.random.default_rng(0), strength=0.0)
    np.testing.assert_allclose(same, camera, atol=0.5 / 255 + 1e-6)
    with pytest.raises(ValueError, match="strength must be a number in"):
        illumination_change(camera, np.random.default_rng(0), strength=5.0)
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        illumination_change(camera, 0)


def test_event_frame_pairs_are_small_rotations_and_translations(rng):
    frames = (rng.random((3, 90, 120)) < 0.1).astype(np.float32)  # sparse event-like frames
    pairs = event_frame_pairs(frames, seed=1, pairs_per_frame=2)
    assert len(pairs) == 6 and all(p.split == "event_frames" for p in pairs)
    for pair in pairs:
        H = pair.H / pair.H[2, 2]
        np.testing.assert_allclose(H[2, :2], 0.0, atol=1e-12)  # affine: no perspective
        scale = math.sqrt(abs(np.linalg.det(H[:2, :2])))
        angle = math.atan2(H[1, 0], H[0, 0])
        assert scale == pytest.approx(1 / 0.9, rel=1e-6)  # the 0.9 crop stretched to the frame
        assert abs(angle) <= np.pi / 18 + 1e-9
    with pytest.raises(ValueError, match=r"frames\[0\] must be a grayscale"):
        event_frame_pairs(np.zeros((2, 4, 4)), seed=0)


def test_heldout_pairs_with_given_images(camera):
    pairs = heldout_pairs(7, images=[camera, camera.T.copy()], pairs_per_image=2)
    assert [p.split for p in pairs] == ["viewpoint"] * 4 + ["illumination"] * 4
    assert len(heldout_pairs(7, images=[camera, camera.T.copy()], n_images=1, pairs_per_image=1,
                             splits=["illumination"])) == 1
    with pytest.raises(ValueError, match="splits must name 'viewpoint' and/or 'illumination'"):
        heldout_pairs(0, images=[camera], splits=["night"])
    with pytest.raises(ValueError, match="images must hold at least one image"):
        heldout_pairs(0, images=[])


# ---------------------------------------------------------------------------------------------- the run
def test_identical_images_score_one_everywhere(camera):
    pairs = [ImagePair(camera, camera.copy(), np.eye(3), "illumination", "same")]
    settings = BenchmarkSettings(repeatability_size=(120, 160), homography_size=(240, 320))
    result = run_benchmark(lambda **k: PatchDetector(**k), pairs, settings, name="patch")
    for metric in ("repeatability", "homography", "matching_score", "mAP"):
        assert result[metric]["illumination"] == {1.0: 1.0, 3.0: 1.0, 5.0: 1.0}, metric
    assert result["n_pairs"] == {"illumination": 1}
    assert result["per_pair"][0]["corner_error"] < 0.05
    assert set(result["speed"]) == {"120x160", "240x320"}


def test_detector_instance_is_cut_to_the_point_budget(camera):
    pairs = viewpoint_pairs([camera], seed=0, pairs_per_image=1)
    settings = BenchmarkSettings(repeatability_size=None, repeatability_keypoints=40, tasks=("repeatability",))
    result = run_benchmark(PatchDetector(max_keypoints=500, nms_radius=2), pairs, settings)
    assert result["detector"] == "patch"
    assert result["keypoints"]["repeatability"] <= 40
    assert "homography" not in result and 0.0 < result["repeatability"]["viewpoint"][3.0] <= 1.0


def test_end_to_end_with_sift_on_two_pairs(camera):
    """Thesis settings (240x320 / 300 points / NMS 4, 480x640 / 1000 points / NMS 8) on one pair of each split."""
    pairs = viewpoint_pairs([camera], seed=0, pairs_per_image=1) + illumination_pairs([camera], seed=0,
                                                                                        pairs_per_image=1)
    result = run_benchmark("sift", pairs)
    assert result["n_pairs"] == {"viewpoint": 1, "illumination": 1}
    for metric in ("repeatability", "homography", "matching_score", "mAP"):
        for split in ("viewpoint", "illumination"):
            values = list(result[metric][split].values())
            assert len(values) == 3 and all(0.0 <= v <= 1.0 for v in values), (metric, split, values)
    # SIFT on a clean photograph: repeatable, and the homography within 5 px on both pairs
    assert result["repeatability"]["viewpoint"][3.0] > 0.3
    assert result["homography"]["viewpoint"][5.0] == 1.0 and result["homography"]["illumination"][5.0] == 1.0
    assert 0 < result["keypoints"]["repeatability"] <= 300 and result["keypoints"]["homography"] <= 1000
    assert set(result["speed"]) == {"240x320", "480x640"}
    table = format_table([result], "homography")
    assert table.splitlines()[0].startswith("| Model | Viewpoint ε = 1 |") and "| SIFT |" in table
    json.dumps({k: v for k, v in result.items() if k != "per_pair"})  # the summary is JSON-serialisable


def test_diagnose_pairs_sees_the_homography_task_of_run_benchmark(camera):
    pairs = viewpoint_pairs([camera], seed=0, pairs_per_image=1) + illumination_pairs([camera], seed=0,
                                                                                        pairs_per_image=1)
    rows = diagnose_pairs("sift", pairs)
    assert rows.shape == (2, 5)
    settings = BenchmarkSettings()
    sift = create_detector("sift", max_keypoints=settings.homography_keypoints, nms_radius=settings.homography_nms)
    for row, pair in zip(rows, pairs):  # the same detections as written out by hand, at 480 x 640
        large = resize_pair(pair, settings.homography_size, settings.resize_mode)
        f1, f2 = sift.detect_and_describe(large.image1), sift.detect_and_describe(large.image2)
        expected = diagnose_matches(f1.keypoints, f2.keypoints, f1.descriptors, f2.descriptors, large.H,
                                    large.image1.shape)
        np.testing.assert_allclose(row[:3], expected[:3])
        assert row[4] == pytest.approx(expected.corner_error_oracle)
    benchmark = run_benchmark("sift", pairs, BenchmarkSettings(tasks=("homography",)))
    np.testing.assert_array_equal(rows[:, 0], [r["n_matches"] for r in benchmark["per_pair"]])
    assert (rows[:, 1] <= rows[:, 0]).all() and (rows[:, 4] <= 3.0).all()  # SIFT on a clean photograph
    with pytest.raises(ValueError, match="pairs must hold ImagePair objects"):
        diagnose_pairs("sift", [camera])


def test_measure_speed(camera):
    speed = measure_speed(create_detector("fast"), [camera], (60, 80), n_frames=3)
    assert speed["images"] == 3 and speed["ms"] > 0 and speed["fps"] == pytest.approx(1000 / speed["ms"])


def test_run_benchmark_bad_input(camera):
    with pytest.raises(ValueError, match="settings must be a BenchmarkSettings"):
        run_benchmark("fast", [], settings={"eps": 3})
    with pytest.raises(ValueError, match="pairs must hold ImagePair objects"):
        run_benchmark("fast", [(camera, camera, np.eye(3))])
    with pytest.raises(ValueError, match="detector must be a name"):
        run_benchmark(42, [])


# ---------------------------------------------------------------------------------------------- tables
ROWS = [
    {"detector": "sift",
     "repeatability": {"viewpoint": {1.0: 0.26, 3.0: 0.486}, "illumination": {1.0: 0.278, 3.0: 0.434}},
     "speed": {"240x320": {"ms": 20.0, "fps": 50.0}}},
    {"detector": "my_net", "repeatability": {"viewpoint": {1.0: 0.377, 3.0: float("nan")},
                                              "illumination": {1.0: 0.438, 3.0: 0.665}},
     "speed": {"240x320": {"ms": 100.0, "fps": 10.0}, "180x240": {"ms": 50.0, "fps": 20.0}}},
]


def test_format_table_in_the_form_of_table_2():
    expected = "\n".join([
        "| Model | Viewpoint ε = 1 | Viewpoint ε = 3 | Illumination ε = 1 | Illumination ε = 3 |",
        "|---|---|---|---|---|",
        "| SIFT | 0.260 | **0.486** | 0.278 | 0.434 |",
        "| my_net | **0.377** | - | **0.438** | **0.665** |",
    ])
    assert format_table(ROWS, "repeatability") == expected
    # after a JSON round trip (string keys) the table is the same
    assert format_table(json.loads(json.dumps(ROWS)), "repeatability") == expected


def test_format_table_speed_and_errors():
    lines = format_table(ROWS, "speed").splitlines()
    assert lines[0] == "| Model | 180x240 ms | 180x240 frames/s | 240x320 ms | 240x320 frames/s |"
    assert lines[2] == "| SIFT | - | - | **20.0** | **50.0** |"
    with pytest.raises(ValueError, match="kind must be one of"):
        format_table(ROWS, "precision")
    with pytest.raises(ValueError, match="rows hold no 'homography' results"):
        format_table(ROWS, "homography")
    with pytest.raises(ValueError, match="rows must hold at least one benchmark result"):
        format_table([], "repeatability")


# ---------------------------------------------------------------------------------------------- command line
def _save_event_frames(tmp_path, camera):
    """Write two 120 x 160 crops of the camera image as tmp_path/frames.npy (an --event-frames stack)."""
    np.save(tmp_path / "frames.npy", np.stack([camera[:120, :160], camera[120:, 160:]]))


def test_main_benchmark_on_event_frames(tmp_path, camera, capsys):
    _save_event_frames(tmp_path, camera)
    out = tmp_path / "out"
    code = main_benchmark(["--dataset", "events", "--event-frames", str(tmp_path / "frames.npy"), "--detectors",
                           "fast", "--fast", "--quiet", "--speed-shapes", "60x80", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "Repeatability (events)" in printed and "| FAST |" in printed
    summary = json.loads((out / "results.json").read_text())
    assert summary[0]["detector"] == "fast" and summary[0]["n_pairs"] == {"event_frames": 2}
    assert set(summary[0]["speed"]) >= {"60x80", "240x320"}
    assert (out / "tables.md").read_text().count("| FAST |") == 5


def test_main_benchmark_passes_weights_to_the_superpoint_detector(tmp_path, camera, capsys):
    sp = pytest.importorskip("evio_lib.features.network")
    weights = sp.save_checkpoint(sp.build_model("narrow", seed=3), tmp_path / "tiny_net.pt")
    _save_event_frames(tmp_path, camera)
    out = tmp_path / "out"
    code = main_benchmark(["--dataset", "events", "--event-frames", str(tmp_path / "frames.npy"), "--detectors",
                           "superpoint", "--weights", str(weights), "--fast", "--quiet", "--speed-shapes", "64x80",
                           "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "results.json").read_text())
    assert summary[0]["detector"] == "tiny_net" and "64x80" in summary[0]["speed"]
    assert "| tiny_net |" in capsys.readouterr().out


def test_main_benchmark_gives_the_networks_the_pyramid_asked_for(tmp_path, camera, capsys):
    sp = pytest.importorskip("evio_lib.features.network")
    weights = sp.save_checkpoint(sp.build_model("narrow", seed=3), tmp_path / "tiny_net.pt")
    _save_event_frames(tmp_path, camera)
    out = tmp_path / "out"
    code = main_benchmark(["--dataset", "events", "--event-frames", str(tmp_path / "frames.npy"), "--detectors",
                           "superpoint", "fast", "--weights", str(weights), "--cnn-scales", "1,0.5", "--fast",
                           "--quiet", "--speed-shapes", "64x80", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "results.json").read_text())
    assert [row["detector"] for row in summary] == ["tiny_net (scales 1,0.5)", "fast"]  # FAST has no pyramid


def test_the_pyramid_reaches_every_network_however_spelt(tmp_path, camera, monkeypatch):
    from evio_lib.features import base

    made = []
    real = base.create_detector

    def spy(name, **options):
        made.append((name, options.get("scales")))
        return real(name, **options)

    monkeypatch.setattr(base, "create_detector", spy)
    _save_event_frames(tmp_path, camera)
    code = main_benchmark(["--dataset", "events", "--event-frames", str(tmp_path / "frames.npy"), "--detectors",
                           "SuperPoint", "distilled-narrow", "fast", "--cnn-scales", "1,0.5", "--fast", "--quiet",
                           "--speed-shapes", "64x80"])
    assert code == 0
    assert {scales for name, scales in made if name != "fast"} == {(1.0, 0.5)}
    assert {scales for name, scales in made if name == "fast"} == {None}


@pytest.mark.parametrize("bad", ["0", "1,1", "1,x", "5", ""])
def test_the_command_refuses_a_bad_pyramid(bad, capsys):
    from evio_lib.cli import main

    assert main(["features-benchmark", "--cnn-scales", bad, "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --cnn-scales") and "1,0.71,0.5" in err[0]


def test_main_benchmark_reports_bad_arguments(capsys):
    assert main_benchmark(["--dataset", "hpatches", "--quiet"]) == 2
    assert "--hpatches-root" in capsys.readouterr().err


def test_main_benchmark_on_a_fake_hpatches_folder(tmp_path, camera, capsys):
    scene = tmp_path / "hpatches" / "v_camera"
    scene.mkdir(parents=True)
    image = np.round(camera * 255).astype(np.uint8)
    cv2.imwrite(str(scene / "1.ppm"), cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
    for k in range(2, 7):
        H = np.array([[1.0, 0.0, 2.0 * k], [0.0, 1.0, -1.0 * k], [0.0, 0.0, 1.0]])
        warped = cv2.warpPerspective(image, H, image.shape[::-1])
        cv2.imwrite(str(scene / f"{k}.ppm"), cv2.cvtColor(warped, cv2.COLOR_GRAY2BGR))
        np.savetxt(scene / f"H_1_{k}", H)
    out = tmp_path / "out"
    code = main_benchmark(["--dataset", "hpatches", "--hpatches-root", str(tmp_path / "hpatches"), "--detectors",
                           "orb", "--quiet", "--speed-shapes", "--out", str(out)])
    assert code == 0
    assert "5 pairs {'viewpoint': 5}" in capsys.readouterr().out
    summary = json.loads((out / "results.json").read_text())
    assert summary[0]["n_pairs"] == {"viewpoint": 5}
    # pure translations of a clean photograph: ORB gets every homography within 5 px
    assert summary[0]["homography"]["viewpoint"]["5.0"] == 1.0


def test_heldout_pairs_from_the_test_pool():
    datasets = pytest.importorskip("evio_lib.features.training.datasets")
    pairs = heldout_pairs(0, n_images=2, pairs_per_image=1, size=(60, 80))
    pool = datasets.image_pool("test", 0, size=(60, 80), n_images=2)
    assert [p.split for p in pairs] == ["viewpoint", "viewpoint", "illumination", "illumination"]
    np.testing.assert_array_equal(pairs[0].image1, pool[0])
    np.testing.assert_array_equal(pairs[3].image1, pool[1])


def test_heldout_pairs_pool_choice_is_checked():
    with pytest.raises(ValueError, match="pool must be 'test' or 'val'"):
        heldout_pairs(0, n_images=1, pool="train")  # the training split is never a benchmark
