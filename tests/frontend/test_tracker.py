"""Tests of the trackers (evio_lib.frontend.tracker, evio_lib.frontend.klt) on simulated APS frames with known poses.

Truth: the simulator's camera poses (epipolar error of every continued track against the true relative pose) and its
depth maps (reprojection of the previous observation into the next frame).
"""
from pathlib import Path

import numpy as np
import pytest

from evio_lib.frontend import (
    DescriptorTracker,
    FrontendConfig,
    KltTracker,
    camera_rotation_prior,
    camera_rotation_priors,
    create_tracker,
    stats_table,
)
from evio_lib.features.base import FeatureDetector, Features
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.epipolar import sampson_distance
from evio_lib.geometry.rotation import skew
from evio_lib.sim.presets import SimulationConfig, simulate_sequence
from evio_lib.sim.scene import scene_from_preset

METHODS = ("descriptor", "klt")


def _recording(start: float, duration: float) -> dict:
    """Simulated boxes_like APS frames (noise, motion blur), gyro priors, true poses and depth at the frame times."""
    seq = simulate_sequence(SimulationConfig(preset="boxes_like", duration=duration, start_time=start,
                                             trajectory_duration=60.0, with_events=False))
    times = seq.frame_times
    truth = seq.groundtruth.interpolate(times)
    scene = scene_from_preset("boxes_like", seed=0)
    R_CtoG, p_CinG = truth.R_BtoG, truth.p_BinG
    priors = [None] + [camera_rotation_prior(seq.imu.t, seq.imu.gyro, times[k - 1], times[k], seq.R_CtoI)
                       for k in range(1, len(times))]
    return dict(camera=seq.camera, frames=seq.frames.astype(np.float32) / 255.0, times=times, priors=priors,
                R_CtoG=R_CtoG, p_CinG=p_CinG,
                depth=[scene.render(seq.camera, R_CtoG[k], p_CinG[k]).depth for k in range(len(times))])


@pytest.fixture(scope="module")
def gentle():
    """Half a second in the gentle part of boxes_like (~0.3 m/s, ~30 deg/s), 12 frames at 24 Hz."""
    return _recording(20.0, 0.5)


@pytest.fixture(scope="module")
def tracked(gentle):
    return {m: create_tracker(gentle["camera"], FrontendConfig(method=m)).track(
        gentle["frames"], gentle["times"], gentle["priors"]) for m in METHODS}


def _continued_errors(rec, frames):
    """Return (Sampson px, reprojection px) of every track continued from frame k-1 to k."""
    cam = rec["camera"]
    sampson, reprojection = [], []
    for k in range(1, len(frames)):
        a, b = frames[k - 1], frames[k]
        _, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
        R01 = rec["R_CtoG"][k].T @ rec["R_CtoG"][k - 1]  # R_C0toC1
        t01 = rec["R_CtoG"][k].T @ (rec["p_CinG"][k - 1] - rec["p_CinG"][k])  # p_C0inC1
        sampson.append(sampson_distance(skew(t01) @ R01, a.xy[ia], b.xy[ib]) * cam.fx)
        px = a.pixels[ia]
        rows = np.clip(np.rint(px[:, 1]).astype(int), 0, cam.height - 1)
        cols = np.clip(np.rint(px[:, 0]).astype(int), 0, cam.width - 1)
        X0 = np.c_[a.xy[ia], np.ones(len(ia))] * rec["depth"][k - 1][rows, cols][:, None]  # X = z [x, y, 1]
        reprojection.append(np.linalg.norm(cam.project(X0 @ R01.T + t01) - b.pixels[ib], axis=1))
    return np.concatenate(sampson), np.concatenate(reprojection)


# measured (seed 0, the APS noise matched to real DAVIS240C frames): descriptor median/95th Sampson 0.04/0.56 px,
# none reprojected > 3 px, 31 tracked per frame; KLT 0.02/0.16 px, none, 49 tracked
@pytest.mark.parametrize("method, sampson_p95, far_fraction, min_tracked",
                         [("descriptor", 2.0, 0.05, 10), ("klt", 1.0, 0.02, 40)])
def test_tracks_follow_the_true_motion(gentle, tracked, method, sampson_p95, far_fraction, min_tracked):
    sampson, reprojection = _continued_errors(gentle, tracked[method])
    assert np.median(sampson) < 0.5 and np.percentile(sampson, 95) < sampson_p95
    assert np.median(reprojection) < 1.0 and np.mean(reprojection > 3.0) < far_fraction
    assert stats_table(tracked[method])["tracked"][1:].mean() >= min_tracked


@pytest.mark.parametrize("method", METHODS)
def test_ids_are_unique_stable_and_never_reused(tracked, method):
    frames = tracked[method]
    seen_before: set[int] = set()
    previous: dict[int, int] = {}
    for frame in frames:
        assert frame.ids.dtype == np.int64 and len(np.unique(frame.ids)) == len(frame)
        ages = dict(zip(frame.ids.tolist(), frame.ages.tolist()))
        for i, age in ages.items():
            if i in previous:
                assert age == previous[i] + 1  # continued: one frame older
            else:
                assert i not in seen_before and age == 1  # new: a fresh id, never one that was lost
        seen_before |= set(ages)
        previous = ages
    all_new = np.concatenate([f.ids[f.ages == 1] for f in frames])
    assert np.all(np.diff(all_new) > 0)  # ids count up


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("max_features", [60, 40])
def test_grid_caps_are_respected(gentle, method, max_features):
    tracker = create_tracker(gentle["camera"], FrontendConfig(method=method, max_features=max_features))
    frames = tracker.track(gentle["frames"][:5], gentle["times"][:5], gentle["priors"][:5])
    for frame in frames:
        assert len(frame) <= max_features
        assert tracker.grid.counts(frame.pixels).max() <= max_features // 20
    assert len(frames[0]) >= 0.8 * max_features  # a textured frame fills most cells


@pytest.mark.parametrize("method", METHODS)
def test_statistics_add_up(tracked, method):
    frames = tracked[method]
    table = stats_table(frames)
    np.testing.assert_array_equal(table["tracked"] + table["new"], table["total"])
    np.testing.assert_array_equal(table["total"], [len(f) for f in frames])
    np.testing.assert_array_equal(table["candidates"], table["rejected_ransac"] + table["tracked"] + table["dropped"])
    np.testing.assert_array_equal(table["lost"][1:], table["total"][:-1] - table["tracked"][1:])
    np.testing.assert_array_equal(table["frame"], np.arange(len(frames)))
    assert table["t"].tolist() == [f.t for f in frames]
    assert table["new"][0] == table["total"][0] > 0 and table["tracked"][0] == 0
    assert all(f.stats.time_detect_s >= 0 and f.stats.time_match_s >= 0 for f in frames)


@pytest.mark.parametrize("method", METHODS)
def test_xy_are_the_undistorted_pixels(tracked, gentle, method):
    for frame in tracked[method]:
        np.testing.assert_allclose(gentle["camera"].normalized_to_pixels(frame.xy), frame.pixels, atol=1e-6)


@pytest.mark.parametrize("method", METHODS)
def test_blank_frame_gives_no_features_and_tracking_resumes(gentle, method):
    tracker = create_tracker(gentle["camera"], FrontendConfig(method=method))
    first = tracker.process(gentle["frames"][0], 0.0)
    blank = tracker.process(np.zeros_like(gentle["frames"][0]), 0.1)
    assert len(blank) == 0 and blank.stats.lost == len(first) and blank.stats.tracked == 0
    assert blank.xy.shape == (0, 2) and blank.ids.dtype == np.int64
    again = tracker.process(gentle["frames"][1], 0.2)
    assert again.stats.new == len(again) > 0 and again.ids.min() > first.ids.max()


def _blanked(rec, blank):
    """The gentle frames with the frames at the indices ``blank`` replaced by black ones (missed detections)."""
    frames = rec["frames"].copy()
    frames[list(blank)] = 0.0
    return frames


def test_a_track_gap_revives_tracks_after_a_missed_frame_with_their_ids(gentle):
    """One black frame (every detection missed): with max_track_gap = 2 the next frame continues the tracks of the
    frame before it with their ids and ages, at the true positions (the earlier points, placed with the simulator's
    depth and moved with the true pose, reproject onto them); without a gap every track after the blank is new."""
    cam = gentle["camera"]
    errors = []
    for blank in (3, 5, 7, 9):
        frames = _blanked(gentle, [blank])
        runs = {gap: DescriptorTracker(cam, FrontendConfig(max_track_gap=gap)).track(
            frames, gentle["times"], gentle["priors"]) for gap in (0, 2)}
        assert runs[0][blank + 1].stats.tracked == 0 and runs[0][blank + 1].stats.revived == 0
        before, after = runs[2][blank - 1], runs[2][blank + 1]
        assert len(runs[2][blank]) == 0 and after.stats.revived == after.stats.tracked >= 20  # measured: 29-36
        # every revived track was last seen in the frame before the blank, or one earlier (two missed frames)
        assert set(after.ids[after.ages > 1]) <= set(before.ids) | set(runs[2][blank - 2].ids)
        _, i0, i1 = np.intersect1d(before.ids, after.ids, return_indices=True)
        assert len(i1) >= 15  # measured: 24-31
        np.testing.assert_array_equal(after.ages[i1], before.ages[i0] + 1)  # ages count observations
        k0, k1 = blank - 1, blank + 1
        R01 = gentle["R_CtoG"][k1].T @ gentle["R_CtoG"][k0]
        t01 = gentle["R_CtoG"][k1].T @ (gentle["p_CinG"][k0] - gentle["p_CinG"][k1])
        px = before.pixels[i0]
        rows, cols = np.rint(px[:, 1]).astype(int), np.rint(px[:, 0]).astype(int)
        X0 = np.c_[before.xy[i0], np.ones(len(i0))] * gentle["depth"][k0][rows, cols][:, None]
        errors.append(np.linalg.norm(cam.project(X0 @ R01.T + t01) - after.pixels[i1], axis=1))
        for k in (0, 1):  # nothing can be revived before a track has missed a frame
            np.testing.assert_array_equal(runs[0][k].ids, runs[2][k].ids)
    errors = np.concatenate(errors)
    # measured: 110 revived, median 0.08 px, none over 3 px (consecutive matches: 0.09 px, none)
    assert np.median(errors) < 0.3 and np.mean(errors > 3.0) < 0.05


def test_a_dormant_track_is_forgotten_after_max_track_gap(gentle):
    """Frames 5 and 6 black: with max_track_gap = 1 no track of frame 4 comes back in frame 7; with 2 some do."""
    frames = _blanked(gentle, [5, 6])
    ids4 = {}
    for gap in (1, 2):
        out = DescriptorTracker(gentle["camera"], FrontendConfig(max_track_gap=gap)).track(
            frames, gentle["times"], gentle["priors"])
        ids4[gap] = len(np.intersect1d(out[4].ids, out[7].ids))
        table = stats_table(out)  # the statistics still add up with revived tracks
        np.testing.assert_array_equal(table["candidates"], table["rejected_ransac"] + table["tracked"]
                                      + table["dropped"])
        np.testing.assert_array_equal(table["lost"][1:], table["total"][:-1] - table["tracked"][1:]
                                      + table["revived"][1:])
        for k in range(1, len(out)):  # revived: continued tracks that were not in the previous frame
            older = set(out[k].ids[out[k].ages > 1].tolist())
            assert table["revived"][k] == len(older - set(out[k - 1].ids.tolist()))
    assert ids4[1] == 0 and ids4[2] >= 5


class _ScriptedDetector(FeatureDetector):
    """Returns the features scripted for each call, whatever the image (a controlled test of the bookkeeping)."""

    name = "scripted"

    def __init__(self, script):
        super().__init__()
        self.script = list(script)

    def detect_and_describe(self, image):
        keypoints, descriptors = self.script.pop(0)
        n = len(keypoints)
        return Features(np.reshape(keypoints, (n, 2)), np.linspace(1.0, 0.5, n), np.reshape(descriptors, (n, 2)))


def test_a_rotation_that_turns_tracks_behind_the_camera_ends_them_also_with_dormant_ones():
    """A point is missed in frame 1 (dormant); in frame 2 a 150 deg turn puts it and the continued point behind the
    camera: their predictions keep the old pixels, the detections there match, and both are rejected as RANSAC
    rejects a bearing turned behind the camera, without an error; the statistics still add up."""
    cam = PinholeRadtan(fx=100.0, fy=100.0, cx=31.5, cy=23.5, width=64, height=48)
    a, b = ([30.0, 20.0], [1.0, 0.0]), ([10.0, 10.0], [0.0, 1.0])
    script = [([a[0], b[0]], [a[1], b[1]]), ([a[0]], [a[1]]), ([a[0], b[0]], [a[1], b[1]])]
    tracker = DescriptorTracker(cam, FrontendConfig(max_track_gap=2, max_features=20),
                                detector=_ScriptedDetector(script))
    turn = np.array([[np.cos(2.6), 0.0, np.sin(2.6)], [0.0, 1.0, 0.0], [-np.sin(2.6), 0.0, np.cos(2.6)]])
    frames = [tracker.process(np.zeros((48, 64), np.float32), 0.1 * k, R)
              for k, R in enumerate([None, np.eye(3), turn])]
    assert frames[1].stats.tracked == 1 and frames[1].stats.lost == 1  # b went dormant
    last = frames[2].stats
    assert last.candidates == 2 and last.rejected_ransac == 2 and last.tracked == last.revived == 0
    assert last.new == 2 and not set(frames[2].ids) & set(frames[0].ids)


def test_the_gyro_prior_keeps_klt_tracks_under_fast_rotation():
    rec = _recording(56.0, 0.3)  # the violent end: ~170 deg/s
    cam = rec["camera"]
    with_prior = KltTracker(cam).track(rec["frames"], rec["times"], rec["priors"])
    without = KltTracker(cam).track(rec["frames"], rec["times"])
    tracked_with = stats_table(with_prior)["tracked"][1:].mean()
    tracked_without = stats_table(without)["tracked"][1:].mean()
    assert tracked_with > 2.0 * tracked_without  # measured: 29 vs 6 over 0.3 s
    _, reprojection = _continued_errors(rec, with_prior)
    assert np.mean(reprojection > 3.0) < 0.02


def test_other_detectors_plug_in(gentle):
    for name in ("orb", "harris"):  # binary (Hamming) and float descriptors
        tracker = DescriptorTracker(gentle["camera"], FrontendConfig(detector=name))
        frames = tracker.track(gentle["frames"][:4], gentle["times"][:4], gentle["priors"][:4])
        assert stats_table(frames)["tracked"][1:].min() > 0, name
        sampson, _ = _continued_errors(gentle, frames)
        assert np.median(sampson) < 0.5, name


def test_output_feeds_the_msckf(gentle, tracked):
    from evio_lib.msckf.config import MsckfConfig
    from evio_lib.msckf.filter import Msckf
    from evio_lib.msckf.initialization import initial_state_from_truth

    cfg = MsckfConfig()
    state = initial_state_from_truth(gentle["times"][0] - 0.01, np.eye(3), np.zeros(3), np.zeros(3), np.eye(3),
                                     np.zeros(3), cfg)
    msckf = Msckf(cfg, state)
    t_imu = np.arange(gentle["times"][0] - 0.01, gentle["times"][-1] + 0.01, 0.001)
    msckf.feed_imu(t_imu, np.zeros((len(t_imu), 3)), np.tile([0.0, 0.0, 9.81], (len(t_imu), 1)))
    for frame in tracked["descriptor"]:
        out = msckf.process_image(frame.t, frame.ids, frame.xy)
        assert np.isfinite(out.p_IinG).all()
    assert len(msckf.tracks) > 0


def test_inputs_are_not_modified(gentle):
    image = gentle["frames"][0].copy()
    R = gentle["priors"][1].copy()
    for method in METHODS:
        tracker = create_tracker(gentle["camera"], FrontendConfig(method=method))
        tracker.process(image, 0.0)
        tracker.process(image, 0.1, R)
        np.testing.assert_array_equal(image, gentle["frames"][0])
        np.testing.assert_array_equal(R, gentle["priors"][1])


def test_reset_forgets_tracks_but_not_ids(gentle):
    tracker = DescriptorTracker(gentle["camera"])
    first = tracker.process(gentle["frames"][0], 1.0)
    tracker.reset()
    assert tracker.num_tracks == 0
    again = tracker.process(gentle["frames"][0], 0.5)  # time may restart after a reset
    assert again.stats.new == len(again) and again.ids.min() > first.ids.max()


@pytest.mark.parametrize("method", METHODS)
def test_bad_input_raises_a_clear_error(gentle, method):
    tracker = create_tracker(gentle["camera"], FrontendConfig(method=method))
    image = gentle["frames"][0]
    with pytest.raises(ValueError, match=r"shape \(H, W\) = \(180, 240\)"):
        tracker.process(image[:100], 0.0)
    with pytest.raises(ValueError, match="grayscale"):
        tracker.process(np.stack([image] * 3, axis=-1), 0.0)
    with pytest.raises(ValueError, match=r"values in \[0, 1\]"):
        tracker.process(image * 255.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        tracker.process(np.full_like(image, np.nan), 0.0)
    with pytest.raises(ValueError, match="finite frame time"):
        tracker.process(image, float("nan"))
    with pytest.raises(ValueError, match="rotation"):
        tracker.process(image, 0.0, np.ones((3, 3)))
    tracker.process(image, 1.0)
    with pytest.raises(ValueError, match="must increase"):
        tracker.process(image, 1.0)
    with pytest.raises(ValueError, match="one per image"):
        tracker.track([image, image], [2.0])
    with pytest.raises(ValueError, match="PinholeRadtan"):
        create_tracker("davis")
    with pytest.raises(ValueError, match="FrontendConfig"):
        DescriptorTracker(gentle["camera"], {"max_features": 60})
    with pytest.raises(ValueError, match="unknown detector"):
        DescriptorTracker(gentle["camera"], FrontendConfig(detector="nope"))
    with pytest.raises(ValueError, match="max_track_gap must be an integer >= 0"):
        FrontendConfig(max_track_gap=-1)
    with pytest.raises(ValueError, match="max_track_gap applies to the descriptor method"):
        FrontendConfig(method="klt", max_track_gap=2)


def test_uint8_images_are_accepted(gentle):
    image8 = np.rint(gentle["frames"][0] * 255).astype(np.uint8)
    a = DescriptorTracker(gentle["camera"]).process(image8, 0.0)
    b = DescriptorTracker(gentle["camera"]).process(gentle["frames"][0], 0.0)
    np.testing.assert_array_equal(a.pixels, b.pixels)


# ---------------------------------------------------------------------------------------------- real EuRoC images
@pytest.mark.parametrize("method", METHODS)
def test_tracks_on_real_euroc_images(real_data_dir: Path, method):
    from evio_lib.io.euroc import read_euroc

    seq = read_euroc(real_data_dir / "euroc_V1_01_easy_micro")
    n = 30
    times = seq.frame_times[:n]
    priors = camera_rotation_priors(seq.imu.t, seq.imu.gyro, times, seq.R_CtoI)
    assert isinstance(seq.camera, PinholeRadtan)
    frames = create_tracker(seq.camera, FrontendConfig(method=method)).track(seq.frames[:n], times, priors)
    table = stats_table(frames)
    # the MAV barely moves in these 1.5 s: most features continue from frame to frame and RANSAC rejects few.
    # Measured over all 95 frames: descriptor (SIFT) 56 features, 49 continued, 9 of 4613 candidates rejected;
    # KLT 56 features, 56 continued, none rejected
    assert table["total"][1:].min() >= 45
    assert table["tracked"][1:].mean() >= (0.75 if method == "descriptor" else 0.9) * table["total"][:-1].mean()
    assert table["rejected_ransac"].sum() <= 0.05 * table["candidates"].sum()
    assert np.concatenate([f.ages for f in frames[-5:]]).mean() > 5
