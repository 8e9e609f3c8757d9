"""Tests of evio_lib.pipeline.run: the chain on simulated recordings, its metrics and its robustness."""
import dataclasses

import numpy as np
import pytest

from evio_lib.frontend import create_tracker
from evio_lib.pipeline.dataset import LoadedDataset
from evio_lib.pipeline.run import PipelineConfig, msckf_config_for, run_pipeline
from evio_lib.sequence import ImuSamples


def _with_sequence(data: LoadedDataset, **changes) -> LoadedDataset:
    """Return data whose sequence is a copy with some fields replaced (the cached original is left alone)."""
    seq = data.sequence
    fields = {f: getattr(seq, f) for f in ("name", "camera", "events", "frame_times", "frames", "imu", "groundtruth",
                                            "groundtruth_imu", "R_CtoI", "p_CinI", "metadata")}
    fields.update(changes)
    return dataclasses.replace(data, sequence=type(seq)(**fields))


@pytest.fixture
def recorded_sigmas(monkeypatch) -> list[float]:
    """The feature noise σ (px) of every observation covariance the pipeline builds, in order (the covariances
    themselves are built as usual)."""
    import evio_lib.pipeline.run as run_module
    from evio_lib.geometry.pixel_noise import observation_covariance

    calls: list[float] = []

    def recording(camera, pixels, sigma_px):
        calls.append(sigma_px)
        return observation_covariance(camera, pixels, sigma_px)

    monkeypatch.setattr(run_module, "observation_covariance", recording)
    return calls


@pytest.fixture(scope="module")
def sift_run(boxes_aps):
    return run_pipeline(boxes_aps, PipelineConfig(features="sift"))


@pytest.fixture(scope="module")
def imu_runs(boxes_aps):
    return (run_pipeline(boxes_aps, PipelineConfig(imu_only=True)),
            run_pipeline(boxes_aps, PipelineConfig(imu_only=True, bias_init="groundtruth")))


def test_vision_beats_imu_only(sift_run, imu_runs):
    plain, corrected = imu_runs
    assert np.all(np.isfinite(sift_run.p_IinG))
    assert sift_run.metrics["rmse_m"] < 0.25 * plain.metrics["rmse_m"]
    # the true biases help dead reckoning (the thesis's bias-corrected IMU row)
    assert corrected.metrics["final_error_m"] < plain.metrics["final_error_m"]
    assert len(sift_run.t) == len(plain.t)
    assert sift_run.tracking["total"].mean() > 40  # about N = 60 features per frame


def test_metrics_match_an_independent_computation(sift_run, boxes_aps):
    """RMSE, final error and % of distance from the ground-truth camera poses, recomputed with np.interp."""
    gt = boxes_aps.sequence.groundtruth_imu
    p_gt = np.stack([np.interp(sift_run.t, gt.t, gt.p_BinG[:, k]) for k in range(3)], axis=1)
    err = np.linalg.norm(sift_run.p_IinG - p_gt, axis=1)
    m = sift_run.metrics
    assert m["rmse_m"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-6)
    assert m["final_error_m"] == pytest.approx(err[-1], rel=1e-6)
    dense = gt.p_BinG[(gt.t >= sift_run.t[0]) & (gt.t <= sift_run.t[-1])]
    distance = np.linalg.norm(np.diff(dense, axis=0), axis=1).sum()
    assert m["distance_m"] == pytest.approx(distance, rel=0.02)
    assert m["percent_of_distance"] == pytest.approx(100 * err.mean() / m["distance_m"], rel=1e-6)
    lengths = [r["length_m"] for r in m["relative_errors"]]  # rpg's sub-trajectories: 10 ... 50 % of the path
    np.testing.assert_allclose(lengths, np.array([0.1, 0.2, 0.3, 0.4, 0.5]) * m["distance_m"], rtol=0.02)
    assert 0 < m["relative_translation_percent"] < 100


def test_camera_pose_composes_the_extrinsics(sift_run):
    R_CtoG, p_CinG = sift_run.camera_pose()
    k = len(sift_run.t) // 2
    R_ItoG = sift_run.R_ItoG[k]
    np.testing.assert_allclose(R_CtoG[k], R_ItoG @ sift_run.R_CtoI, atol=1e-12)
    np.testing.assert_allclose(p_CinG[k], sift_run.p_IinG[k] + R_ItoG @ sift_run.p_CinI, atol=1e-12)


def test_frames_without_features_are_survived(boxes_aps):
    """Blank frames (nothing to detect) in the middle: the filter propagates across them, nothing is NaN."""
    frames = boxes_aps.sequence.frames.copy()
    blank = (boxes_aps.sequence.frame_times > 1.0) & (boxes_aps.sequence.frame_times < 1.5)
    frames[blank] = 128
    data = _with_sequence(boxes_aps, frames=frames)
    result = run_pipeline(data, PipelineConfig(max_duration=2.0))
    inside = (result.tracking["t"] > 1.0) & (result.tracking["t"] < 1.5)
    assert inside.sum() == blank.sum() and np.all(result.tracking["total"][inside] == 0)
    assert np.all(np.isfinite(result.p_IinG)) and np.all(np.isfinite(result.sigma))
    assert result.metrics["rmse_m"] < 1.0


def test_dropped_imu_samples_are_bridged_and_counted(boxes_aps):
    imu = boxes_aps.sequence.imu
    keep = ~((imu.t > 1.0) & (imu.t < 1.1))  # 100 ms without IMU: longer than imu_max_gap, short enough to bridge
    data = _with_sequence(boxes_aps, imu=ImuSamples(t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep]))
    result = run_pipeline(data, PipelineConfig(max_duration=2.0))
    assert sum(result.faults.values()) >= 1
    assert np.all(np.isfinite(result.p_IinG))


def test_a_long_imu_gap_stops_with_a_clear_error(boxes_aps):
    imu = boxes_aps.sequence.imu
    keep = ~((imu.t > 1.0) & (imu.t < 1.6))
    data = _with_sequence(boxes_aps, imu=ImuSamples(t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep]))
    with pytest.raises(ValueError, match="gap"):
        run_pipeline(data, PipelineConfig(max_duration=2.0))


def test_static_initialisation_refuses_a_moving_start(boxes_aps):
    with pytest.raises(ValueError, match="static initialisation failed: the IMU window is not static"):
        run_pipeline(boxes_aps, PipelineConfig(init="static", max_duration=2.0))


@pytest.mark.parametrize("changes, message", [
    (dict(frames="video"), "frames must be one of"),
    (dict(init="magic"), "init must be one of"),
    (dict(bias_init=(1.0, 2.0)), "six finite numbers"),
    (dict(max_duration=-1.0), "max_duration"),
    (dict(tracker="sift"), r"tracker must be one of \('descriptor', 'klt'\); got 'sift'"),
    (dict(match_ratio=2.0), "match_ratio must be in"),
    (dict(frames="events", reconstructor="learned"), r"reconstructor must be one of \['direct', 'high_pass'"),
    (dict(frames="events", reconstructor="no/such.pt"), "or a reconstruct-train checkpoint file; got 'no/such.pt'"),
    (dict(max_track_gap=-1), r"max_track_gap must be an integer >= 0 \(frames\); got -1"),
    (dict(max_track_gap=1.0), "max_track_gap must be an integer"),
    (dict(far_points=1), "far_points must be True or False; got 1"),
    (dict(far_points="always"), "far_points must be True or False; got 'always'"),
    (dict(tracker="klt", features="fast", max_track_gap=2), "max_track_gap applies to the descriptor tracker"),
    (dict(frames="aps+mc-events", tracker="klt", event_tracker="klt", max_track_gap=1),
     "max_track_gap applies to the descriptor tracker"),
    (dict(frames="aps+mc-events", event_tracker="flow"),
     "event_tracker must be None, 'descriptor' or 'klt'; got 'flow'"),
    (dict(event_tracker="klt"), "event_tracker applies to a run that fuses APS frames with an event stream"),
    (dict(frames="mc-events", event_tracker="klt"),
     r"frames 'mc-events' is one stream: set its tracker with tracker \(--tracker\)"),
])
def test_bad_configs_are_refused(changes, message):
    with pytest.raises(ValueError, match=message):
        PipelineConfig(**changes)


def test_event_frames_with_a_stretch_without_events(boxes_events):
    """No events over 0.3 s: no frame there, the IMU carries the filter across, and nothing is NaN."""
    ev = boxes_events.sequence.events
    gap = (ev["t"] > 0.6) & (ev["t"] < 0.9)
    data = _with_sequence(boxes_events, events=ev[~gap])
    result = run_pipeline(data, PipelineConfig(frames="events", tracker="klt", features="fast",
                                               reconstructor="high_pass"))
    assert not np.any((result.t > 0.61) & (result.t < 0.89))
    assert len(result.t) > 10 and np.all(np.isfinite(result.p_IinG))
    assert result.timings["reconstruction"] > 0


def test_a_reconstructor_checkpoint_file_is_a_reconstructor(boxes_events):
    """--reconstructor PATH runs the reconstruct-train checkpoint at PATH: the shipped FireNet's file gives the
    frames of the name 'firenet'."""
    from evio_lib.events.reconstruct import shipped_checkpoint
    from evio_lib.pipeline.run import _frames

    path = str(shipped_checkpoint("firenet"))
    by_name = list(_frames(boxes_events, PipelineConfig(frames="events"), 0.0, 0.6))
    by_file = list(_frames(boxes_events, PipelineConfig(frames="events", reconstructor=path), 0.0, 0.6))
    assert len(by_name) == len(by_file) >= 2
    for (t_a, image_a, _), (t_b, image_b, _) in zip(by_name, by_file):
        assert t_a == t_b and np.array_equal(image_a, image_b)


def test_event_frames_follow_the_window_size(boxes_events):
    """Frames come at the ends of windows of N_e = n H W events (thesis Eq. 87)."""
    from evio_lib.pipeline.frames import event_frames

    seq = boxes_events.sequence
    times = [t for t, _, _ in event_frames(seq, "direct", window_fraction=0.5)]
    n_e = round(0.5 * 240 * 180)
    expected = seq.events["t"][np.arange(n_e - 1, len(seq.events), n_e)]
    np.testing.assert_allclose(times, expected[: len(times)])
    assert len(times) == len(seq.events) // n_e


def test_event_frames_take_a_reconstructor_already_made(boxes_events):
    """A reconstructor made beforehand gives the frames the name gives, reset first (so it serves twice); it must
    fit the sensor and takes no options of its own here."""
    from evio_lib.events.reconstruct import create_reconstructor
    from evio_lib.pipeline.frames import event_frames

    seq = boxes_events.sequence
    by_name = list(event_frames(seq, "high_pass", window_fraction=0.5, t_end=1.0))
    made = create_reconstructor("high_pass", seq.camera.width, seq.camera.height)
    for _ in range(2):  # the second pass starts from an empty state again
        again = list(event_frames(seq, made, window_fraction=0.5, t_end=1.0))
        assert len(again) == len(by_name) >= 3
        assert all(ta == tb and np.array_equal(a, b) for (ta, a, _), (tb, b, _) in zip(by_name, again))
    with pytest.raises(ValueError, match="made for a 24x18 sensor; the sequence's camera is 240x180"):
        next(event_frames(seq, create_reconstructor("high_pass", 24, 18)))
    with pytest.raises(ValueError, match="takes no threads or reconstructor options .*; got cutoff_hz$"):
        next(event_frames(seq, made, cutoff_hz=1.0))
    with pytest.raises(ValueError, match="got threads=2$"):
        next(event_frames(seq, made, threads=2))


def test_euroc_runs_with_static_initialisation(real_data_dir):
    from evio_lib.pipeline.dataset import load_dataset

    data = load_dataset(real_data_dir / "euroc_V1_01_easy_micro")
    result = run_pipeline(data, PipelineConfig(init="static", tracker="klt", features="fast"))
    assert result.metrics["init"] == "static"
    # yaw and position come from the ground truth at the end of the still window, so the errors need no alignment
    assert np.isfinite(result.metrics["ate_se3_m"]) and np.isfinite(result.metrics["rmse_m"])
    assert result.metrics["ate_se3_m"] < 0.5  # the MAV barely moves in these 4.7 s


def test_mc_event_frames_follow_their_bounded_windows(boxes_events):
    """mc-events: one frame per bounded window of N_e events, at the window's middle time, the filter's gyro bias
    asked before each frame, and the frames sharper than the plain count of the same events."""
    from evio_lib.events.representations import bounded_count_windows, polarity_frame, window_size_from_fraction
    from evio_lib.pipeline.frames import mc_event_frames

    seq = boxes_events.sequence
    asked = []

    def bias():
        asked.append(1)
        return np.zeros(3)

    frames = list(mc_event_frames(seq, boxes_events.R_CtoI, window_fraction=0.3, t_start=0.0, t_end=1.5,
                                  min_window_s=0.01, max_window_s=0.05, gyro_bias=bias))
    bounds, ends = bounded_count_windows(seq.events, window_size_from_fraction(0.3, 240, 180), 0.01, 0.05,
                                         t_start=0.0, t_end=1.5)
    starts = np.concatenate([[0.0], ends[:-1]])
    keep = (bounds[:, 1] - bounds[:, 0]) >= 500
    np.testing.assert_allclose([t for t, _, _ in frames], (0.5 * (starts + ends))[keep])
    assert len(asked) == len(frames) >= 10
    for _, image, seconds in frames:
        assert image.shape == (180, 240) and image.dtype == np.float32 and 0.0 <= image.min() <= image.max() <= 1.0
        assert seconds > 0
    # sharper than the uncompensated count (contrast of the image of events)
    (a, b), image = bounds[keep][-1], frames[-1][1]
    plain = polarity_frame(seq.events[a:b], 240, 180, signed=False)
    plain = np.minimum(plain / np.quantile(plain[plain > 0], 0.98), 1.0)
    assert image.var() > plain.var()


def test_mc_events_run_and_window_options_are_checked(boxes_events):
    result = run_pipeline(boxes_events, PipelineConfig(frames="mc-events", tracker="klt", features="fast"))
    assert result.config.label() == "KLT + FAST on motion-compensated event frames"
    assert len(result.t) > 20 and np.all(np.isfinite(result.p_IinG))
    assert result.metrics["rmse_m"] < 0.2  # 1.5 s of the gentle start
    assert np.mean(result.track_lengths) > 3
    assert PipelineConfig(frames="mc-events").window_bounds() == (0.01, 0.1)
    assert PipelineConfig(frames="events").window_bounds() == (0.0, None)
    assert PipelineConfig(frames="events", max_window_s=0.2).window_bounds() == (0.0, 0.2)
    for changes, match in (({"max_window_s": 0.0}, "max_window_s"), ({"min_window_s": -1.0}, "min_window_s"),
                           ({"min_window_s": 0.2, "max_window_s": 0.1}, "greater than"),
                           ({"frames": "mc"}, "frames must be one of")):
        with pytest.raises(ValueError, match=match):
            PipelineConfig(**changes)


def test_event_frames_with_a_time_cap_give_frames_in_a_still_stretch(boxes_events):
    """A time cap (--max-window) makes the reconstructed source give a frame at least that often even where few
    events come; without one, the windows wait for N_e events."""
    from evio_lib.pipeline.frames import event_frames

    seq = boxes_events.sequence
    ev = seq.events
    sparse = ev[(ev["t"] < 0.6) | (ev["t"] > 0.9) | (np.arange(ev.size) % 50 == 0)]
    data = _with_sequence(boxes_events, events=sparse)
    capped = [t for t, _, _ in event_frames(data.sequence, "direct", window_fraction=0.5, t_start=0.0, t_end=1.5,
                                            max_window_s=0.05)]
    plain = [t for t, _, _ in event_frames(data.sequence, "direct", window_fraction=0.5, t_start=0.0, t_end=1.5)]
    inside = lambda times: np.count_nonzero((np.asarray(times) > 0.62) & (np.asarray(times) < 0.88))  # noqa: E731
    assert inside(capped) >= 4 and inside(plain) <= 1
    assert np.all(np.diff(capped) <= 0.05 + 1e-9)


def test_a_track_gap_reaches_the_tracker_and_the_filter(boxes_aps):
    """max_track_gap = 2: the descriptor tracker revives tracks and the filter keeps them whole, so tracks get longer;
    the label says so; KLT refuses it (it never searches for a lost patch: test_bad_configs_are_refused)."""
    plain = run_pipeline(boxes_aps, PipelineConfig(features="sift"))
    gap = run_pipeline(boxes_aps, PipelineConfig(features="sift", max_track_gap=2))
    assert plain.config.max_track_gap == 0  # the default
    assert plain.tracking["revived"].sum() == 0 and gap.tracking["revived"].mean() > 3
    assert np.mean(gap.track_lengths) > np.mean(plain.track_lengths)
    assert gap.metrics["rmse_m"] < 0.3 and np.isfinite(gap.p_IinG).all()
    assert msckf_config_for(gap.config, boxes_aps).max_track_gap == 2  # the filter keeps the tracks open
    assert gap.config.frontend_config().max_track_gap == 2
    assert gap.config.label() == "SIFT on APS frames, track gap 2" and plain.config.label() == "SIFT on APS frames"


def test_far_points_reach_the_filter_and_the_label(boxes_aps):
    """far_points: True sets the filter's far_point_fallback, False (the default) leaves it off; the label names it.
    A run with far points uses some and stays on course in the room (numbers over the whole presets:
    docs/archive.md, the far-point rows)."""
    assert PipelineConfig().far_points is False and not msckf_config_for(PipelineConfig(), boxes_aps).far_point_fallback
    assert msckf_config_for(PipelineConfig(features="sift", far_points=True), boxes_aps).far_point_fallback
    assert PipelineConfig(features="sift", far_points=True).label() == "SIFT on APS frames, far points always"
    assert PipelineConfig(features="sift").label() == "SIFT on APS frames"
    result = run_pipeline(boxes_aps, PipelineConfig(features="sift", far_points=True))
    assert result.rejections["far_point_fallback"] > 0
    assert result.metrics["rmse_m"] < 0.3 and np.isfinite(result.p_IinG).all()


def test_two_frame_streams_in_one_run(boxes_events):
    """aps+mc-events: the APS frames and the motion-compensated event frames, each through its own tracker, in
    time order into one filter; the second stream's ids are offset, and both streams' frames are processed."""
    from evio_lib.pipeline.frames import STREAM_ID_OFFSET, frame_streams

    assert frame_streams("aps+mc-events") == ("aps", "mc-events")
    config = PipelineConfig(frames="aps+mc-events", tracker="klt", features="fast")
    assert config.label() == "KLT + FAST on APS frames + motion-compensated event frames"
    both = run_pipeline(boxes_events, config)
    aps = run_pipeline(boxes_events, PipelineConfig(tracker="klt", features="fast"))
    mc = run_pipeline(boxes_events, PipelineConfig(frames="mc-events", tracker="klt", features="fast"))
    assert np.all(np.diff(both.t) > 0) and np.all(np.isfinite(both.p_IinG))
    # every frame of either stream inside the run's span is processed once
    assert set(np.round(aps.t, 9)) | set(np.round(mc.t, 9)) >= set(np.round(both.t, 9))
    assert len(both.t) >= len(aps.t) + len(mc.t) - 3
    assert both.metrics["rmse_m"] < 0.2
    assert np.mean(both.track_lengths) > 3  # the streams' tracks are not cut by each other's frames
    with pytest.raises(ValueError, match="frames must be one of"):
        PipelineConfig(frames="aps+aps")
    assert STREAM_ID_OFFSET > 2**31


def test_each_frame_stream_gets_its_own_front_end(boxes_events, monkeypatch):
    """event_tracker: the event stream of a fused run gets its own tracker (KLT + FAST beside SIFT on the APS
    frames), each stream's frames go to its own, the track gap reaches the descriptor stream only, and the label
    names both front-ends."""
    import evio_lib.pipeline.run as run_module

    made = []

    def recording(camera, config, detector=None):
        tracker = create_tracker(camera, config, detector=detector)
        calls = []
        process = tracker.process

        def counted(image, t, R_prior=None):
            calls.append(t)
            return process(image, t, R_prior)

        tracker.process = counted
        made.append((config, calls))
        return tracker

    monkeypatch.setattr(run_module, "create_tracker", recording)
    config = PipelineConfig(frames="aps+mc-events", event_tracker="klt", max_track_gap=2, max_duration=0.8)
    assert config.label() == "SIFT on APS frames and KLT + FAST on motion-compensated event frames, track gap 2"
    result = run_pipeline(boxes_events, config)
    (aps_config, aps_calls), (mc_config, mc_calls) = made
    assert (aps_config.method, aps_config.detector_name, aps_config.max_track_gap) == ("descriptor", "sift", 2)
    assert (mc_config.method, mc_config.detector_name, mc_config.max_track_gap) == ("klt", "fast", 0)
    frame_times = boxes_events.sequence.frame_times
    assert set(np.round(aps_calls, 9)) <= set(np.round(frame_times, 9)) and len(aps_calls) >= 15
    assert not set(np.round(mc_calls, 9)) & set(np.round(frame_times, 9)) and len(mc_calls) >= 5
    assert len(result.t) == len(aps_calls) + len(mc_calls) and np.all(np.isfinite(result.p_IinG))
    assert result.metrics["rmse_m"] < 0.2
    assert config.stream_tracker("aps") == "descriptor" and config.stream_tracker("mc-events") == "klt"
    assert msckf_config_for(config, boxes_events).max_track_gap == (2, 0)  # the filter uses KLT's ended tracks at once
    assert msckf_config_for(dataclasses.replace(config, event_tracker=None), boxes_events).max_track_gap == (2, 2)
    same = PipelineConfig(frames="aps+mc-events", tracker="klt")  # unset: one front-end for both
    assert same.frontend_config("mc-events") == same.frontend_config("aps") == same.frontend_config()


def test_each_frame_stream_gets_its_own_pixel_noise(boxes_events, recorded_sigmas):
    """event_pixel_noise_px: the event stream's observations get covariances with their own sigma, the APS stream's
    with pixel_noise_px; unset, an event stream fused with APS frames gets FUSED_EVENT_NOISE_FACTOR times it, a
    lone event stream pixel_noise_px. Two streams get a window of twice the camera states."""
    from evio_lib.msckf.config import MsckfConfig
    from evio_lib.pipeline.run import FUSED_EVENT_NOISE_FACTOR

    calls = recorded_sigmas
    config = PipelineConfig(frames="aps+mc-events", tracker="klt", features="fast", pixel_noise_px=0.5,
                            event_pixel_noise_px=2.5, max_duration=0.8)
    both = run_pipeline(boxes_events, config)
    counts = {sigma: calls.count(sigma) for sigma in set(calls)}
    n_aps = int(np.count_nonzero((boxes_events.sequence.frame_times > both.t[0] - 1e-9)
                                 & (boxes_events.sequence.frame_times <= both.t[-1] + 1e-9)))
    assert set(counts) == {0.5, 2.5} and abs(counts[0.5] - n_aps) <= 1 and counts[2.5] >= 5
    assert config.label().endswith(", event noise 2.5 px")
    assert config.stream_pixel_noise("aps") == 0.5 and config.stream_pixel_noise("mc-events") == 2.5
    calls.clear()
    default = run_pipeline(boxes_events, dataclasses.replace(config, event_pixel_noise_px=None))
    assert set(calls) == {0.5, 0.5 * FUSED_EVENT_NOISE_FACTOR} and FUSED_EVENT_NOISE_FACTOR > 1
    assert (f"2 frame streams: feature noise aps 0.5 px, mc-events {0.5 * FUSED_EVENT_NOISE_FACTOR:g} px; the "
            f"window holds {2 * MsckfConfig().max_camera_states} camera states") in default.notes
    alone = PipelineConfig(frames="mc-events", tracker="klt", features="fast", pixel_noise_px=0.5)
    assert alone.stream_pixel_noise("mc-events") == 0.5 and "noise" not in alone.label()
    assert PipelineConfig(frames="events").stream_pixel_noise("events") == 1.0  # a lone FireNet stream too
    assert PipelineConfig(frames="aps+events").stream_pixel_noise("events") == FUSED_EVENT_NOISE_FACTOR
    with pytest.raises(ValueError, match="stream must be 'aps', 'events' or 'mc-events'; got 'video'"):
        config.stream_pixel_noise("video")
    with pytest.raises(ValueError, match="event_pixel_noise_px applies to event frame streams; frames 'aps' has"):
        PipelineConfig(event_pixel_noise_px=2.0)
    window = MsckfConfig().max_camera_states
    assert msckf_config_for(config, boxes_events).max_camera_states == 2 * window
    assert msckf_config_for(alone, boxes_events).max_camera_states == window
    for bad in (0.0, -1.0, float("nan"), float("inf"), True, "2"):
        with pytest.raises(ValueError, match="event_pixel_noise_px must be a finite number of pixels > 0"):
            PipelineConfig(frames="mc-events", event_pixel_noise_px=bad)
    with pytest.raises(ValueError, match="pixel_noise_px must be a finite number of pixels > 0; got 0"):
        PipelineConfig(pixel_noise_px=0)


def test_table_rows_cover_every_frame_source_and_the_help_names_them():
    import argparse

    from evio_lib.pipeline.command import add_table_arguments
    from evio_lib.pipeline.table import TABLE_ROWS

    sources = {dict(row.options).get("frames", "aps") for row in TABLE_ROWS}
    assert sources == {"aps", "events", "mc-events", "aps+mc-events"}
    assert all(row.needs_events == (dict(row.options).get("frames", "aps") != "aps") for row in TABLE_ROWS)
    parser = argparse.ArgumentParser()
    add_table_arguments(parser)
    rows_help = next(a.help for a in parser._actions if a.dest == "rows")
    assert all(row.key in rows_help.split() for row in TABLE_ROWS)


def test_run_pipelines_in_workers_equals_runs_one_by_one(boxes_aps):
    from evio_lib.pipeline.run import run_pipelines

    configs = {"IMU only": PipelineConfig(imu_only=True, max_duration=1.5),
               "KLT": PipelineConfig(tracker="klt", features="fast", max_duration=1.5)}
    serial = run_pipelines(boxes_aps, configs, jobs=1)
    parallel = run_pipelines(boxes_aps, configs, jobs=2)
    assert list(parallel) == list(configs)
    for name in configs:
        np.testing.assert_array_equal(parallel[name].p_IinG, serial[name].p_IinG)
        assert parallel[name].metrics["rmse_m"] == serial[name].metrics["rmse_m"]
    assert serial["KLT"].metrics["rmse_m"] < serial["IMU only"].metrics["rmse_m"]
    with pytest.raises(ValueError, match="jobs must be an integer >= 1"):
        run_pipelines(boxes_aps, configs, jobs=0)
    with pytest.raises(ValueError, match="threads must be an integer >= 1"):
        run_pipelines(boxes_aps, configs, jobs=2, threads=0)


def test_reconstructor_precision_reaches_the_network(boxes_events):
    """bfloat16 and int8 FireNet frames: close to float32's but not the same numbers; a bad precision is one error."""
    from evio_lib.pipeline.frames import event_frames

    frames = {precision: [image for _, image, _ in event_frames(boxes_events.sequence, "firenet", t_end=0.3,
                                                                 precision=precision)]
              for precision in ("float32", "bfloat16", "int8")}
    assert len(frames["float32"]) == len(frames["bfloat16"]) == len(frames["int8"]) >= 3
    difference = max(float(np.abs(a - b).max()) for a, b in zip(frames["float32"], frames["bfloat16"]))
    assert 0 < difference < 0.05
    int8_difference = [float(np.abs(a - b).mean()) for a, b in zip(frames["float32"], frames["int8"])]
    assert 0 < max(int8_difference) < 0.02
    config = PipelineConfig(frames="events", tracker="klt", features="fast", reconstructor_precision="bfloat16",
                            max_duration=0.6)
    result = run_pipeline(boxes_events, config)
    assert len(result.t) > 5 and np.all(np.isfinite(result.p_IinG))
    assert "event frames: firenet computed in bfloat16 (reconstructor precision bfloat16)" in result.notes
    assert result.reconstructor_precision == "bfloat16"
    high_pass = PipelineConfig(frames="events", reconstructor="high_pass", reconstructor_precision="bfloat16",
                               max_duration=0.3)  # the classical methods ignore it
    high_pass_result = run_pipeline(boxes_events, high_pass)
    assert len(high_pass_result.t) > 0 and not any("computed in" in note for note in high_pass_result.notes)
    assert high_pass_result.reconstructor_precision is None
    # the network of a two-stream run is made once and names its precision; a run that makes no frame has none
    fused = run_pipeline(boxes_events, PipelineConfig(frames="aps+events", tracker="klt", features="fast",
                                                      reconstructor_precision="float32", max_duration=0.3))
    assert fused.reconstructor_precision == "float32" and len(fused.t) > 0
    imu_only = run_pipeline(boxes_events, PipelineConfig(frames="events", imu_only=True, max_duration=0.3))
    assert imu_only.reconstructor_precision is None and not any("computed in" in n for n in imu_only.notes)
    with pytest.raises(ValueError, match="reconstructor_precision must be one of auto, float32, bfloat16, int8; got 'int4'"):
        PipelineConfig(frames="events", reconstructor_precision="int4")


def test_a_sequence_in_memory_runs_as_its_loaded_recording(boxes_aps):
    config = PipelineConfig(tracker="klt", features="fast", max_duration=1.0)
    loaded = run_pipeline(boxes_aps, config)
    direct = run_pipeline(boxes_aps.sequence, config)      # the same recording, given as the Sequence itself
    np.testing.assert_array_equal(direct.p_IinG, loaded.p_IinG)
    np.testing.assert_array_equal(direct.t, loaded.t)
    assert any("extrinsics: from the recording (Sequence)" in note for note in direct.notes)
    for bad in (None, 3, b"boxes_like"):
        with pytest.raises(TypeError, match="data must be a LoadedDataset, a Sequence, a preset name"):
            run_pipeline(bad, config)
    with pytest.raises(ValueError, match="duration applies to presets and recordings on disk"):
        from evio_lib.pipeline.dataset import load_dataset

        load_dataset(boxes_aps.sequence, duration=2.0)
