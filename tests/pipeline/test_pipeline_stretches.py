"""Tests of evio_lib.pipeline.stretches: stretches of a preset run on APS and event frames, the blur, the ratios."""
import json
from types import SimpleNamespace as NS

import numpy as np
import pytest

from evio_lib.pipeline import PipelineConfig, run_pipeline
from evio_lib.pipeline.stretches import (
    Stretch,
    error_ratios,
    rotation_blur_px,
    run_stretches,
    simulate_stretches,
    stretch_record,
    stretch_run,
)

KLT = dict(tracker="klt", features="fast")


def same(a, b) -> bool:
    """Records equal, NaN equal to NaN (a path under 0.5 m has no % of distance)."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(label="", start=0.0, duration=1.0), r"label must be a non-empty name"),
        (dict(label="a", start=-1.0, duration=1.0), r"start must be a number of seconds >= 0; got -1.0"),
        (dict(label="a", start=0.0, duration=0.0), r"duration must be a number of seconds > 0; got 0.0"),
        (dict(label="a", start=0.0, duration=1.0, preset="room"), r"preset must be one of"),
        (dict(label="a", start=0.0, duration=1.0, speed=0.0), r"speed must be a number in"),
    ],
)
def test_stretch_refuses_bad_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Stretch(**kwargs)


def test_rotation_blur_is_rate_times_exposure_times_focal_length():
    t = np.linspace(0.0, 1.0, 201)
    gyro = np.c_[2.0 * np.ones_like(t), np.zeros_like(t), np.zeros_like(t)]  # 2 rad/s about x
    bias = NS(bias_gyro=np.zeros((2, 3)), interpolate=lambda tt: NS(bias_gyro=np.tile([0.5, 0.0, 0.0], (len(tt), 1))))
    data = NS(sequence=NS(imu=NS(t=t, gyro=gyro), groundtruth_imu=bias, camera=NS(fx=200.0)))
    # the true bias (0.5 rad/s) is removed: 1.5 rad/s x 20 ms x 200 px = 6 px
    assert rotation_blur_px(data, 0.02) == pytest.approx(6.0)
    assert rotation_blur_px(data, 0.04) == pytest.approx(2 * rotation_blur_px(data, 0.02))
    with pytest.raises(ValueError, match=r"exposure_s must be a number of seconds > 0; got 0"):
        rotation_blur_px(data, 0)
    with pytest.raises(ValueError, match=r"has no IMU samples"):
        rotation_blur_px(NS(sequence=NS(imu=None, groundtruth_imu=None, camera=NS(fx=1.0))), 0.01)


def test_error_ratios_pair_each_aps_run_with_the_event_run_of_its_stretch_and_seed():
    runs = [dict(stretch="s", speed=1.0, seed=0, frames="mc-events", exposure_ms=10.0, blur_px=1.0, mean_error_m=0.2)]
    runs += [dict(stretch="s", speed=1.0, seed=0, frames="aps", exposure_ms=e, blur_px=0.1 * e, mean_error_m=m)
             for e, m in ((5.0, 0.1), (40.0, 0.4))]
    runs += [dict(stretch="s", speed=1.0, seed=0, frames="aps+mc-events", exposure_ms=10.0, blur_px=1.0,
                  mean_error_m=9.0)]  # neither side of the ratio
    ratios = error_ratios(runs)
    assert [(r["exposure_ms"], r["blur_px"], r["ratio"]) for r in ratios] == [(5.0, 0.5, 2.0), (40.0, 4.0, 0.5)]
    with pytest.raises(ValueError, match=r"no run on 'mc-events' frames for stretch 's', seed 1"):
        error_ratios(runs + [dict(runs[1], seed=1)])


def test_stretch_run_on_a_simulated_stretch_gives_the_record_of_the_same_run(boxes_events):
    gentle = Stretch("gentle", start=0.0, duration=1.5)  # the fixture's recording, from the same cache
    record = stretch_run(gentle, 0, PipelineConfig(frames="mc-events", **KLT))
    reference = stretch_record(gentle, 0, boxes_events, run_pipeline(boxes_events, PipelineConfig(frames="mc-events",
                                                                                                  **KLT)))
    assert same(record, reference)
    assert (record["stretch"], record["seed"], record["frames"], record["exposure_ms"]) == ("gentle", 0, "mc-events",
                                                                                           10.0)
    assert record["frames_per_second"] > 10 and record["track_length"] >= 1
    assert 0.1 < record["rate_rad_s"] < 1.0  # the gentle start turns at a few tenths of a rad/s
    assert record["blur_px"] == pytest.approx(record["rate_rad_s"] * 0.01 * boxes_events.sequence.camera.fx)


def test_a_longer_exposure_blurs_more_and_the_runs_do_not_depend_on_the_workers(boxes_events):
    gentle = Stretch("gentle", start=0.0, duration=1.5)
    calls = [dict(stretch=gentle, seed=0, config=PipelineConfig(**KLT), aps_exposure_s=exposure)
             for exposure in (None, 0.03)]
    here = run_stretches(calls, jobs=1)
    assert [r["exposure_ms"] for r in here] == [10.0, 30.0]
    assert here[1]["blur_px"] == pytest.approx(3 * here[0]["blur_px"])  # the same motion, 3 x the exposure
    assert here[1]["rate_rad_s"] == pytest.approx(here[0]["rate_rad_s"])
    assert same(run_stretches(calls, jobs=2), here)
    with pytest.raises(ValueError, match=r"calls\[0\] lacks \['config'\]"):
        run_stretches([dict(stretch=gentle, seed=0)])


def test_simulate_stretches_puts_every_recording_in_the_cache(boxes_events):
    gentle = Stretch("gentle", start=0.0, duration=1.5)
    simulate_stretches([(gentle, 0, 0.02), (gentle, 0, None), (gentle, 0, 0.02)], jobs=2)  # repeats are simulated once
    data = gentle.load(0, 0.02)
    assert data.sequence.metadata["config"]["aps"]["exposure_s"] == 0.02
    np.testing.assert_array_equal(data.sequence.events["t"], boxes_events.sequence.events["t"])  # the same events
    with pytest.raises(ValueError, match=r"recordings\[0\] must be \(Stretch, seed, aps_exposure_s or None\)"):
        simulate_stretches([("gentle", 0, None)])
