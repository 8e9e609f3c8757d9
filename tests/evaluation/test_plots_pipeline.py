"""Tests of evio_lib.evaluation.plots_pipeline: figures render to Agg, draw what they claim, reject bad input."""
import doctest

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.evaluation import plots_pipeline  # noqa: E402
from evio_lib.evaluation.plots_pipeline import (  # noqa: E402
    plot_bias_estimates,
    plot_error_comparison,
    plot_state_errors,
    plot_tracking_statistics,
    plot_blur_schematic,
    plot_error_ratio_vs_blur,
    plot_tracks,
    plot_trajectory_topdown,
    track_length_bins,
)



def _render(fig) -> np.ndarray:
    """Draw the figure on the Agg canvas and return its pixels (fails on any drawing error)."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())


def _legend_labels(ax) -> list[str]:
    legend = ax.get_legend()
    return [] if legend is None else [text.get_text() for text in legend.get_texts()]


def test_docstring_examples_run():
    result = doctest.testmod(plots_pipeline, optionflags=doctest.ELLIPSIS)
    assert result.attempted >= 5 and result.failed == 0


# ----------------------------------------------------------------------------------------------- plot_state_errors
def test_plot_state_errors_draws_error_and_three_sigma_band(rng):
    t = np.linspace(0.0, 5.0, 51)
    sigma = np.column_stack([0.1 + 0.02 * t, 0.2 + 0.01 * t, 0.05 * (1 + t)])
    errors = rng.standard_normal((51, 3)) * sigma
    errors_before, sigma_before = errors.copy(), sigma.copy()
    fig = plot_state_errors(t, errors, sigma, quantity="velocity", unit="m/s", axis_labels=("N", "E", "D"),
                            title="run")
    assert len(fig.axes) == 3
    for j, (ax, name) in enumerate(zip(fig.axes, "NED")):
        error_line, upper, lower = ax.lines[:3]
        np.testing.assert_allclose(error_line.get_xdata(), t)
        np.testing.assert_allclose(error_line.get_ydata(), errors[:, j])
        np.testing.assert_allclose(upper.get_ydata(), 3.0 * sigma[:, j])
        np.testing.assert_allclose(lower.get_ydata(), -3.0 * sigma[:, j])
        assert ax.get_ylabel() == f"{name} velocity error [m/s]"
    # the panels share the time axis and the legend appears once
    assert fig.axes[0].get_shared_x_axes().joined(fig.axes[0], fig.axes[2])
    assert _legend_labels(fig.axes[0]) == ["error (truth - estimate)", "±3σ"]
    assert fig.axes[1].get_legend() is None and fig.axes[2].get_legend() is None
    assert fig.axes[2].get_xlabel() == "time [s]"
    np.testing.assert_array_equal(errors, errors_before)  # inputs untouched
    np.testing.assert_array_equal(sigma, sigma_before)
    _render(fig)


def test_plot_state_errors_leaves_nan_sigma_undrawn_and_scales_with_n_sigma():
    t = np.linspace(0.0, 1.0, 6)
    sigma = np.ones((6, 3))
    sigma[:2, 1] = np.nan  # e.g. before the filter is initialised
    fig = plot_state_errors(t, np.zeros((6, 3)), sigma, quantity="orientation", unit="deg", n_sigma=2.0)
    upper = fig.axes[1].lines[1].get_ydata()
    assert np.isnan(upper[:2]).all() and upper[2:].tolist() == [2.0] * 4
    assert fig.axes[0].get_ylabel() == "x orientation error [deg]"
    assert _legend_labels(fig.axes[0])[1] == "±2σ"
    _render(fig)  # NaN segments are skipped, not an error


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"errors": np.zeros((4, 3))}, r"errors must have shape \(N, 3\) = \(5, 3\) like t; got \(4, 3\)"),
        ({"errors": np.zeros((5, 2))}, r"errors must have shape \(N, 3\) = \(5, 3\)"),
        ({"sigma": np.zeros(5)}, r"sigma must have shape \(N, 3\) = \(5, 3\) like t; got \(5,\)"),
        ({"sigma": -np.ones((5, 3))}, r"sigma must contain standard deviations >= 0"),
        ({"sigma": np.full((5, 3), np.inf)}, r"sigma must not contain inf"),
        ({"t": np.zeros((5, 1))}, r"t must have shape \(N,\)"),
        ({"t": [0.0, 1.0, np.nan, 3.0, 4.0]}, r"t must contain only finite times"),
        ({"errors": "abc"}, r"errors must be a numeric array of shape \(N, 3\)"),
        ({"axis_labels": ("x", "y")}, r"axis_labels must be three names"),
        ({"n_sigma": 0.0}, r"n_sigma must be a finite number > 0"),
    ],
)
def test_plot_state_errors_rejects_bad_input(kwargs, match):
    args = {"t": np.linspace(0.0, 1.0, 5), "errors": np.zeros((5, 3)), "sigma": np.ones((5, 3))}
    extra = {k: kwargs.pop(k) for k in list(kwargs) if k not in args}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        plot_state_errors(args["t"], args["errors"], args["sigma"], **extra)


# --------------------------------------------------------------------------------------------- plot_bias_estimates
def test_plot_bias_estimates_draws_band_around_estimate_and_truth(rng):
    t = np.linspace(0.0, 10.0, 101)
    truth = np.tile([0.01, -0.02, 0.005], (101, 1))
    sigma = np.column_stack([0.02 * np.exp(-t / 3)] * 3) + 1e-3
    estimate = truth + sigma * rng.standard_normal((101, 3))
    fig = plot_bias_estimates(t, estimate, sigma, truth, kind="gyro")
    assert len(fig.axes) == 3
    for j, ax in enumerate(fig.axes):
        est_line, upper, lower, truth_line = ax.lines
        np.testing.assert_allclose(est_line.get_ydata(), estimate[:, j])
        np.testing.assert_allclose(upper.get_ydata(), estimate[:, j] + 3.0 * sigma[:, j])
        np.testing.assert_allclose(lower.get_ydata(), estimate[:, j] - 3.0 * sigma[:, j])
        np.testing.assert_allclose(truth_line.get_ydata(), truth[:, j])
        assert truth_line.get_linestyle() == "--"
        assert ax.get_ylabel() == f"{'xyz'[j]} gyroscope bias [rad/s]"
    assert _legend_labels(fig.axes[0]) == ["estimate", "estimate ±3σ", "truth"]
    assert fig.axes[1].get_legend() is None
    _render(fig)


def test_plot_bias_estimates_without_truth_and_units():
    t = np.linspace(0.0, 1.0, 4)
    fig = plot_bias_estimates(t, np.zeros((4, 3)), np.full((4, 3), 0.1), kind="accel")
    assert all(len(ax.lines) == 3 for ax in fig.axes)  # no truth line
    assert fig.axes[2].get_ylabel() == "z accelerometer bias [m/s^2]"
    assert "no truth" in fig.get_suptitle()
    custom = plot_bias_estimates(t, np.zeros((4, 3)), np.full((4, 3), 0.1), kind="gyro", unit="deg/h")
    assert custom.axes[0].get_ylabel() == "x gyroscope bias [deg/h]"


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"kind": "magnetometer"}, r"kind must be one of \['accel', 'gyro'\]; got 'magnetometer'"),
        ({"estimate": np.zeros((3, 3))}, r"estimate must have shape \(N, 3\) = \(4, 3\) like t; got \(3, 3\)"),
        ({"sigma": np.ones((4, 4))}, r"sigma must have shape \(N, 3\) = \(4, 3\)"),
        ({"sigma": -np.ones((4, 3))}, r"sigma must contain standard deviations >= 0"),
        ({"truth": np.zeros((5, 3))}, r"truth must have shape \(N, 3\) = \(4, 3\) like t; got \(5, 3\)"),
        ({"t": []}, r"t must have shape \(N,\) with N >= 1"),
    ],
)
def test_plot_bias_estimates_rejects_bad_input(kwargs, match):
    args = {"t": np.linspace(0.0, 1.0, 4), "estimate": np.zeros((4, 3)), "sigma": np.ones((4, 3)), "truth": None}
    kind = kwargs.pop("kind", "gyro")
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        plot_bias_estimates(args["t"], args["estimate"], args["sigma"], args["truth"], kind=kind)


# ----------------------------------------------------------------------------------------- plot_trajectory_topdown
def test_plot_trajectory_topdown_draws_xy_with_equal_aspect_and_start(rng):
    s = np.linspace(0.0, 2 * np.pi, 60)
    gt = np.column_stack([10 * np.cos(s), 3 * np.sin(s), 0.1 * s])  # an ellipse, 10 m by 3 m
    msckf = gt + 0.2 * rng.standard_normal(gt.shape)
    imu_only = gt[:40] * 1.5  # a shorter, drifting estimate
    imu_only[0] = np.nan  # the first row unknown: start is the first finite row
    fig = plot_trajectory_topdown({"MSCKF": msckf, "IMU only": imu_only}, gt, title="demo")
    assert len(fig.axes) == 1
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0 and ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"
    curves = {line.get_label(): line for line in ax.lines if not line.get_label().startswith("_")}
    np.testing.assert_allclose(curves["ground truth"].get_xydata(), gt[:, :2])
    np.testing.assert_allclose(curves["MSCKF"].get_xydata(), msckf[:, :2])
    assert _legend_labels(ax) == ["ground truth", "start", "end", "MSCKF", "IMU only"]
    # start markers (circles) at each curve's first finite position
    starts = [line.get_xydata()[0] for line in ax.lines if line.get_marker() == "o"]
    np.testing.assert_allclose(starts, [gt[0, :2], msckf[0, :2], imu_only[1, :2]])
    ends = [line.get_xydata()[0] for line in ax.lines if line.get_marker() == "x"]
    np.testing.assert_allclose(ends[2], imu_only[-1, :2])
    assert ax.get_title() == "demo"
    _render(fig)


def test_plot_trajectory_topdown_without_groundtruth_or_estimates():
    p = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    fig = plot_trajectory_topdown({"only": p}, None)
    assert _legend_labels(fig.axes[0]) == ["only", "start", "end"]
    fig2 = plot_trajectory_topdown({}, p)
    assert _legend_labels(fig2.axes[0]) == ["ground truth", "start", "end"]


@pytest.mark.parametrize(
    "estimates, groundtruth, match",
    [
        ({"a": np.zeros((5, 2))}, None, r"estimates\['a'\] must have shape \(N, 3\) with N >= 1"),
        ({"a": np.zeros((0, 3))}, None, r"estimates\['a'\] must have shape \(N, 3\) with N >= 1"),
        ({"a": np.full((3, 3), np.nan)}, None, r"estimates\['a'\] has no finite position"),
        ({"a": np.zeros((3, 3))}, np.zeros(3), r"groundtruth must have shape \(N, 3\)"),
        ({}, None, r"nothing to draw"),
        ([np.zeros((3, 3))], None, r"estimates must be a mapping label -> \(N, 3\) positions; got list"),
    ],
)
def test_plot_trajectory_topdown_rejects_bad_input(estimates, groundtruth, match):
    with pytest.raises(ValueError, match=match):
        plot_trajectory_topdown(estimates, groundtruth)


# ---------------------------------------------------------------------------------------- plot_tracking_statistics
def _stats(rng: np.random.Generator, n: int = 30) -> dict[str, np.ndarray]:
    """Columns like evio_lib.frontend.stats_table: tracked + new = total, lost = previous total - tracked."""
    total = np.full(n, 100)
    tracked = np.r_[0, rng.integers(60, 95, n - 1)]
    rejected = np.r_[0, rng.integers(0, 8, n - 1)]
    return {
        "t": 0.05 * np.arange(n), "frame": np.arange(n), "tracked": tracked, "new": total - tracked, "total": total,
        "rejected_ransac": rejected, "lost": np.r_[0, total[:-1] - tracked[1:]],
        "ransac_degenerate": np.zeros(n, dtype=bool),
    }


def test_plot_tracking_statistics_draws_counts_and_rejections(rng):
    stats = _stats(rng)
    fig = plot_tracking_statistics(stats)
    assert len(fig.axes) == 2
    top, bottom = fig.axes
    by_label = {line.get_label().split(" (")[0]: line for line in top.lines}
    for key in ("tracked", "new", "total"):
        np.testing.assert_allclose(by_label[key].get_xdata(), stats["t"])
        np.testing.assert_allclose(by_label[key].get_ydata(), stats[key])
    assert f"tracked (mean {stats['tracked'].mean():.1f})" in _legend_labels(top)
    np.testing.assert_allclose(bottom.lines[0].get_ydata(), stats["rejected_ransac"])
    np.testing.assert_allclose(bottom.lines[1].get_ydata(), stats["lost"])
    assert _legend_labels(bottom)[0].startswith("rejected by RANSAC")
    assert top.get_shared_x_axes().joined(top, bottom)
    _render(fig)


def test_plot_tracking_statistics_histogram_of_track_lengths(rng):
    stats = _stats(rng)
    del stats["lost"]  # optional column
    lengths = rng.integers(1, 12, 200)
    fig = plot_tracking_statistics(stats, track_lengths=lengths)
    assert len(fig.axes) == 3
    assert len(fig.axes[1].lines) == 1  # no "lost" line without the column
    heights = [patch.get_height() for patch in fig.axes[2].patches]
    np.testing.assert_array_equal(heights, np.bincount(lengths)[1:])  # short lengths: one bar per whole length
    assert fig.axes[2].get_xlabel().startswith("track length [frames] (log")
    assert fig.axes[2].get_xscale() == "log" and fig.axes[2].get_yscale() == "log"
    _render(fig)


def test_track_lengths_up_to_hundreds_of_frames_share_log_spaced_bins(rng):
    lengths = np.r_[rng.integers(1, 4, 3000), [50, 120, 480]]  # thousands of short tracks and three long ones
    edges = track_length_bins(lengths)
    assert edges[0] == 0.5 and edges[-1] == 480.5 and len(edges) < 40
    assert np.all(np.diff(edges) >= 1) and np.all(edges == np.round(edges - 0.5) + 0.5)  # between whole lengths
    widths = np.diff(edges)
    assert widths[0] == 1 and widths[-1] > 50  # one frame wide at the short end, wide at the long end
    fig = plot_tracking_statistics(_stats(rng), track_lengths=lengths)
    heights = np.array([patch.get_height() for patch in fig.axes[2].patches])
    assert heights.sum() == len(lengths) and fig.axes[2].get_xlim()[1] > 480
    with pytest.raises(ValueError, match=r"track_lengths must be finite track lengths >= 1"):
        track_length_bins([0.0, 2.0])
    with pytest.raises(ValueError, match=r"per_decade must be an integer >= 1"):
        track_length_bins([1, 2], per_decade=0)
    _render(fig)


def test_plot_tracking_statistics_accepts_the_columns_of_stats_table():
    """The front-end's own table (not a hand-made dict) is valid input: the column names agree."""
    from evio_lib.frontend import FrameStats, TrackedFrame, stats_table

    frames = []
    for k, (tracked, new, rejected) in enumerate([(0, 50, 0), (40, 10, 3), (45, 5, 1)]):
        stats = FrameStats(frame=k, detected=60, candidates=tracked + rejected, rejected_ransac=rejected,
                           tracked=tracked, dropped=0, lost=50 - tracked if k else 0, new=new, total=tracked + new,
                           ransac_degenerate=False, time_detect_s=0.0, time_match_s=0.0, time_ransac_s=0.0)
        empty = np.zeros((0, 2))
        frames.append(TrackedFrame(t=0.1 * k, ids=np.zeros(0, np.int64), xy=empty, pixels=empty,
                                   ages=np.zeros(0, np.int64), stats=stats))
    fig = plot_tracking_statistics(stats_table(frames))
    np.testing.assert_allclose(fig.axes[1].lines[0].get_ydata(), [0, 3, 1])
    np.testing.assert_allclose(fig.axes[1].lines[1].get_ydata(), [0, 10, 5])  # lost
    _render(fig)


@pytest.mark.parametrize("missing", ["t", "tracked", "new", "total", "rejected_ransac"])
def test_plot_tracking_statistics_names_a_missing_column(rng, missing):
    stats = _stats(rng)
    del stats[missing]
    with pytest.raises(ValueError, match=rf"stats lacks the column '{missing}'"):
        plot_tracking_statistics(stats)


def test_plot_tracking_statistics_rejects_bad_input(rng):
    stats = _stats(rng)
    with pytest.raises(ValueError, match=r"stats\['new'\] must have shape \(F,\) = \(30,\) like stats\['t'\]"):
        plot_tracking_statistics({**stats, "new": stats["new"][:-1]})
    with pytest.raises(ValueError, match=r"stats\['rejected_ransac'\] must contain finite counts >= 0"):
        plot_tracking_statistics({**stats, "rejected_ransac": -stats["rejected_ransac"] - 1})
    with pytest.raises(ValueError, match=r"stats\['t'\] must be finite frame times of shape \(F,\), F >= 1"):
        plot_tracking_statistics({key: value[:0] for key, value in stats.items()})
    with pytest.raises(ValueError, match=r"track_lengths must contain finite track lengths >= 1"):
        plot_tracking_statistics(stats, track_lengths=[0, 3])
    with pytest.raises(ValueError, match=r"track_lengths must have shape \(K,\)"):
        plot_tracking_statistics(stats, track_lengths=[])
    with pytest.raises(ValueError, match=r"stats must be a mapping of columns"):
        plot_tracking_statistics([1, 2, 3])


# ------------------------------------------------------------------------------------------- plot_error_comparison
def test_plot_error_comparison_draws_each_configuration_and_split(rng):
    t_aps = np.linspace(0.0, 60.0, 301)
    t_events = np.linspace(0.0, 60.0, 601)  # a different frame rate: its own times
    errors = {"APS": 0.05 * t_aps + 0.01 * rng.random(301), "events": 0.02 * t_events,
              "IMU only": 1e-3 * t_aps**3}
    times = {"APS": t_aps, "events": t_events, "IMU only": t_aps}
    fig = plot_error_comparison(times, errors, split_time=30.0, title="boxes")
    ax = fig.axes[0]
    assert len(fig.axes) == 1 and ax.get_yscale() == "linear"
    assert _legend_labels(ax) == ["APS", "events", "IMU only", "split at t = 30 s"]
    for line, label in zip(ax.lines[:3], ("APS", "events", "IMU only")):
        np.testing.assert_allclose(line.get_xdata(), times[label])
        np.testing.assert_allclose(line.get_ydata(), errors[label])
    assert list(ax.lines[3].get_xdata()) == [30.0, 30.0]
    assert ax.get_ylabel() == "position error [m]" and ax.get_title() == "boxes"
    _render(fig)


def test_plot_error_comparison_log_axis_drops_zeros():
    t = np.linspace(0.0, 1.0, 5)
    fig = plot_error_comparison({"a": t}, {"a": t**2}, log=True)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log" and len(ax.lines) == 1  # no split line when split_time is None
    np.testing.assert_allclose(ax.lines[0].get_xdata(), t[1:])  # e = 0 at t = 0 cannot be shown on log axes
    _render(fig)


def test_plot_error_comparison_line_styles_reach_the_legend():
    t = np.linspace(0.0, 1.0, 5)
    fig = plot_error_comparison({"APS": t, "events": t}, {"APS": t, "events": 2 * t}, styles={"events": "--"})
    ax = fig.axes[0]
    assert [line.get_linestyle() for line in ax.lines] == ["-", "--"]
    assert [handle.get_linestyle() for handle in ax.get_legend().legend_handles] == ["-", "--"]
    with pytest.raises(ValueError, match=r"styles must map some of the labels \['APS', 'events'\]"):
        plot_error_comparison({"APS": t, "events": t}, {"APS": t, "events": t}, styles={"IMU": "--"})
    _render(fig)


def test_plot_error_comparison_with_the_camera_motion_below():
    t = np.linspace(0.0, 60.0, 61)
    fig = plot_error_comparison({"APS": t}, {"APS": 0.01 * t}, motion=(t, 0.05 * t, 0.1 * t))
    ax, ax_m, ax_w = fig.axes  # the rate on its own axis, at the right of the speed's
    assert ax.get_xlabel() == "" and ax_m.get_xlabel() == "time [s]"
    assert ax_m.get_ylabel() == "speed [m/s]" and ax_w.get_ylabel() == "angular rate [rad/s]"
    np.testing.assert_allclose(ax_m.lines[0].get_ydata(), 0.05 * t)
    np.testing.assert_allclose(ax_w.lines[0].get_ydata(), 0.1 * t)
    assert _legend_labels(ax_m) == ["speed [m/s]", "angular rate [rad/s]"]
    with pytest.raises(ValueError, match="motion's speed and angular rate must have the shape"):
        plot_error_comparison({"APS": t}, {"APS": t}, motion=(t, t[:-1], t))
    with pytest.raises(ValueError, match=r"motion must be \(t, speed, angular_rate\)"):
        plot_error_comparison({"APS": t}, {"APS": t}, motion=(t, t))
    _render(fig)


def test_plot_state_errors_without_a_quantity_names_the_axis_only():
    fig = plot_state_errors([0.0, 1.0], np.zeros((2, 3)), np.ones((2, 3)), quantity="", unit="deg",
                            axis_labels=("about x_I", "about y_I (yaw)", "about z_I"))
    assert [ax.get_ylabel() for ax in fig.axes] == ["about x_I error [deg]", "about y_I (yaw) error [deg]",
                                                    "about z_I error [deg]"]


@pytest.mark.parametrize(
    "times, errors, kwargs, match",
    [
        ({"a": [0.0, 1.0]}, {"a": [0.0, 1.0, 2.0]}, {},
         r"error_norm_by_name\['a'\] must have shape \(N,\) = \(2,\) like t_by_name\['a'\]; got \(3,\)"),
        ({"a": [0.0, 1.0]}, {"b": [0.0, 1.0]}, {}, r"t_by_name and error_norm_by_name must have the same labels"),
        ({}, {}, {}, r"t_by_name must be a non-empty mapping"),
        ({"a": [0.0, 1.0]}, [0.0, 1.0], {}, r"error_norm_by_name must be a non-empty mapping"),
        ({"a": [0.0, 1.0]}, {"a": [0.0, -1.0]}, {}, r"error_norm_by_name\['a'\] must contain error norms >= 0"),
        ({"a": [[0.0, 1.0]]}, {"a": [0.0, 1.0]}, {}, r"t_by_name\['a'\] must have shape \(N,\)"),
        ({"a": [0.0, 1.0]}, {"a": [0.0, 1.0]}, {"split_time": np.nan}, r"split_time must be a finite time"),
        ({"a": [0.0, 1.0]}, {"a": [0.0, 1.0]}, {"split_time": "half"}, r"split_time must be a finite time"),
    ],
)
def test_plot_error_comparison_rejects_bad_input(times, errors, kwargs, match):
    with pytest.raises(ValueError, match=match):
        plot_error_comparison(times, errors, **kwargs)


# ----------------------------------------------------------------------------------------------------- plot_tracks
def _tracked_frames():
    """Three TrackedFrames: track 0 lives in all three, track 1 in the last two, track 2 dies, track 3 is new."""
    from evio_lib.frontend import FrameStats, TrackedFrame

    layout = [  # (ids, pixels) per frame
        ([0, 1, 2], [[10.0, 10.0], [50.0, 20.0], [5.0, 5.0]]),
        ([0, 1], [[12.0, 11.0], [52.0, 21.0]]),
        ([0, 1, 3], [[14.0, 12.0], [54.0, 22.0], [30.0, 40.0]]),
    ]
    frames = []
    for k, (ids, pixels) in enumerate(layout):
        stats = FrameStats(frame=k, detected=3, candidates=0, rejected_ransac=0, tracked=0, dropped=0, lost=0,
                           new=0, total=len(ids), ransac_degenerate=False, time_detect_s=0.0, time_match_s=0.0,
                           time_ransac_s=0.0)
        ids_arr = np.array(ids, np.int64)
        frames.append(TrackedFrame(t=0.1 * k, ids=ids_arr, xy=np.zeros((len(ids), 2)), pixels=np.array(pixels),
                                   ages=np.ones(len(ids), np.int64), stats=stats))
    return frames


def _xy(line) -> np.ndarray:
    return np.column_stack([line.get_xdata(), line.get_ydata()]).astype(float)


def test_plot_tracks_from_tracked_frames_draws_alive_tracks_and_new_ones():
    frames = _tracked_frames()
    image = np.linspace(0.0, 1.0, 48 * 64, dtype=np.float32).reshape(48, 64)
    image_before = image.copy()
    fig = plot_tracks(image, frames)
    ax = fig.axes[0]
    polyline, ends, new = ax.lines
    expected = np.array([[10.0, 10.0], [12.0, 11.0], [14.0, 12.0], [np.nan, np.nan], [50.0, 20.0], [52.0, 21.0],
                         [54.0, 22.0]])
    np.testing.assert_array_equal(_xy(polyline), expected)  # track 2 ended before the last frame: not drawn
    np.testing.assert_array_equal(_xy(ends), [[14.0, 12.0], [54.0, 22.0]])
    np.testing.assert_array_equal(_xy(new), [[30.0, 40.0]])
    assert _legend_labels(ax) == ["tracked (2, mean 3.0 frames)", "new (1)"]
    assert ax.get_ylim() == (47.5, -0.5) and ax.get_xlim() == (-0.5, 63.5)  # image orientation, rows down
    np.testing.assert_array_equal(ax.images[0].get_array(), image)
    np.testing.assert_array_equal(image, image_before)
    _render(fig)


def test_plot_tracks_last_limits_the_history():
    frames = _tracked_frames()
    fig = plot_tracks(np.zeros((48, 64), np.uint8), frames, last=2)
    polyline = fig.axes[0].lines[0]
    np.testing.assert_array_equal(_xy(polyline), [[12.0, 11.0], [14.0, 12.0], [np.nan, np.nan], [52.0, 21.0],
                                                  [54.0, 22.0]])
    mapping = {"a": [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]}
    fig2 = plot_tracks(np.zeros((48, 64)), mapping, last=1)  # one position left: drawn as a new feature
    assert _legend_labels(fig2.axes[0]) == ["new (1)"]


def test_plot_tracks_marks_rejected_candidates_as_points_or_segments():
    tracks = {0: np.array([[10.0, 10.0], [11.0, 10.0]])}
    fig = plot_tracks(np.zeros((48, 64)), tracks, rejected=np.array([[20.0, 30.0], [40.0, 5.0]]))
    crosses = fig.axes[0].lines[-1]
    assert crosses.get_marker() == "x"
    np.testing.assert_array_equal(_xy(crosses), [[20.0, 30.0], [40.0, 5.0]])
    assert _legend_labels(fig.axes[0])[-1] == "rejected by RANSAC (2)"
    pairs = np.array([[[18.0, 30.0], [20.0, 30.0]], [[30.0, 5.0], [40.0, 5.0]]])  # [previous, candidate]
    pairs_before = pairs.copy()
    fig2 = plot_tracks(np.zeros((48, 64, 3)), tracks, rejected=pairs)
    segment, crosses = fig2.axes[0].lines[-2:]
    np.testing.assert_array_equal(_xy(segment), [[18.0, 30.0], [20.0, 30.0], [np.nan, np.nan], [30.0, 5.0],
                                                 [40.0, 5.0]])
    np.testing.assert_array_equal(_xy(crosses), pairs[:, 1])
    np.testing.assert_array_equal(pairs, pairs_before)
    fig3 = plot_tracks(np.zeros((48, 64)), tracks, rejected=np.zeros((0, 2)))  # none rejected: no entry
    assert _legend_labels(fig3.axes[0]) == ["tracked (1, mean 2.0 frames)"]
    fig4 = plot_tracks(np.zeros((48, 64)), tracks, track_label="kept by RANSAC")
    assert _legend_labels(fig4.axes[0]) == ["kept by RANSAC (1, mean 2.0 frames)"]
    _render(fig2)


def test_plot_tracks_on_the_real_tracker_output():
    """The front-end's own output is valid input: a textured image shifted by 2 px per frame gives tracks."""
    from evio_lib.frontend import FrontendConfig, create_tracker
    from evio_lib.geometry.camera import PinholeRadtan

    rng = np.random.default_rng(3)
    camera = PinholeRadtan(fx=150.0, fy=150.0, cx=79.5, cy=59.5, width=160, height=120)
    texture = rng.random((140, 200)).astype(np.float32)
    from scipy.ndimage import gaussian_filter

    texture = gaussian_filter(texture, 1.5)
    texture = (texture - texture.min()) / np.ptp(texture)
    images = [texture[10:130, 2 * k: 2 * k + 160] for k in range(4)]
    tracker = create_tracker(camera, FrontendConfig(method="klt", max_features=40))
    frames = tracker.track(images, [0.0, 0.05, 0.1, 0.15])
    fig = plot_tracks(images[-1], frames)
    polyline = fig.axes[0].lines[0]
    xy = _xy(polyline)
    steps = np.diff(xy, axis=0)
    steps = steps[np.all(np.isfinite(steps), axis=1)]
    assert steps.shape[0] >= 10
    np.testing.assert_allclose(np.median(steps, axis=0), [-2.0, 0.0], atol=0.3)  # the texture moves 2 px left
    _render(fig)


@pytest.mark.parametrize(
    "image, tracks, kwargs, match",
    [
        (np.zeros((4, 4, 2)), {0: [[1.0, 1.0]]}, {}, r"image must have shape \(H, W\) or \(H, W, 3\)"),
        (np.array([["a"]]), {0: [[1.0, 1.0]]}, {}, r"image must be a numeric \(H, W\) grayscale"),
        (np.zeros((4, 4)), {0: [1.0, 1.0]}, {}, r"frames_or_tracks\[0\] must be finite pixel positions of shape"),
        (np.zeros((4, 4)), {0: [[np.nan, 1.0]]}, {}, r"frames_or_tracks\[0\] must be finite pixel positions"),
        (np.zeros((4, 4)), [], {}, r"frames_or_tracks must hold at least one tracked frame"),
        (np.zeros((4, 4)), [np.zeros((3, 2))], {}, r"frames_or_tracks\[0\] must be a tracked frame with \.ids"),
        (np.zeros((4, 4)), 5, {}, r"frames_or_tracks must be a sequence of tracked frames or a mapping"),
        (np.zeros((4, 4)), {0: [[1.0, 1.0]]}, {"rejected": np.zeros((3, 3))},
         r"rejected must have shape \(M, 2\) candidate pixels or \(M, 2, 2\)"),
        (np.zeros((4, 4)), {0: [[1.0, 1.0]]}, {"rejected": [[np.inf, 0.0]]}, r"rejected must contain only finite"),
        (np.zeros((4, 4)), {0: [[1.0, 1.0]]}, {"last": 0}, r"last must be None or an integer >= 1"),
    ],
)
def test_plot_tracks_rejects_bad_input(image, tracks, kwargs, match):
    with pytest.raises(ValueError, match=match):
        plot_tracks(image, tracks, **kwargs)


def test_plot_tracks_names_a_frame_whose_pixels_do_not_match_its_ids():
    from dataclasses import replace

    frames = _tracked_frames()
    frames[1] = replace(frames[1], pixels=np.zeros((3, 2)))  # 2 ids, 3 pixels
    with pytest.raises(ValueError, match=r"frames\[1\]\.pixels must have shape \(K, 2\) = \(2, 2\) like its ids"):
        plot_tracks(np.zeros((48, 64)), frames)
    plot_tracks(np.zeros((48, 64)), iter(_tracked_frames()))  # any iterable of frames, e.g. a generator


# ---------------------------------------------------------------------------------------- plot_error_ratio_vs_blur
def test_plot_error_ratio_vs_blur_draws_runs_cell_means_and_the_line_of_equal_errors():
    blur = np.array([0.5, 0.6, 2.0, 2.2, 9.0, 10.0])
    ratio = np.array([2.0, 8.0, 1.5, 1.5, 0.5, 0.5])
    exposure = np.array([5.0, 5.0, 20.0, 20.0, 20.0, 20.0])
    speed = np.array([1.0, 1.0, 1.0, 1.0, 2.0, 2.0])
    fig = plot_error_ratio_vs_blur(blur, ratio, exposure_ms=exposure, speed=speed, title="when")
    ax, bar = fig.axes
    assert (ax.get_xscale(), ax.get_yscale()) == ("log", "log") and bar.get_ylabel() == "APS exposure T [ms]"
    runs, means = ax.collections[::2], ax.collections[1::2]  # per speed: every run, then the cells' means
    assert [len(c.get_offsets()) for c in runs] == [4, 2] and [len(c.get_offsets()) for c in means] == [2, 1]
    np.testing.assert_allclose(means[0].get_offsets(), [[np.sqrt(0.5 * 0.6), 4.0], [np.sqrt(2.0 * 2.2), 1.5]])
    assert [line.get_ydata()[0] for line in ax.lines] == [1.0]  # equal errors
    assert _legend_labels(ax)[:3] == ["ratio 1: equal errors (below: events win)", "speed 1", "speed 2"]
    assert ax.get_title() == "when"
    assert [float(t) for t in bar.get_yticks()] == [5.0, 20.0]
    _render(fig)


def test_plot_error_ratio_vs_blur_names_the_speeds_in_the_legend():
    fig = plot_error_ratio_vs_blur([1.0, 10.0], [2.0, 0.5], exposure_ms=[10.0, 10.0], speed=[1.0, 2.0],
                                   speed_labels={1.0: "gentle start", 2.0: "violent end, speed 2"})
    labels = _legend_labels(fig.axes[0])
    assert labels[1:3] == ["gentle start", "violent end, speed 2"] and "geometric mean" in labels[3]
    _render(fig)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(ratio=[1.0]), r"ratio must have shape \(K,\) with K >= 1 = 2 like blur_px; got \(1,\)"),
        (dict(ratio=[1.0, 0.0]), r"ratio must contain finite numbers > 0"),
        (dict(blur_px=[1.0, np.nan]), r"blur_px must contain finite numbers > 0"),
        (dict(exposure_ms=[10.0]), r"exposure_ms must have shape \(K,\)"),
        (dict(speed=[1.0, -2.0]), r"speed must contain finite numbers > 0"),
    ],
)
def test_plot_error_ratio_vs_blur_rejects_bad_input(kwargs, match):
    args = dict(blur_px=[1.0, 2.0], ratio=[1.0, 2.0], exposure_ms=[10.0, 20.0], speed=[1.0, 1.0]) | kwargs
    with pytest.raises(ValueError, match=match):
        plot_error_ratio_vs_blur(args.pop("blur_px"), args.pop("ratio"), **args)


def test_plot_blur_schematic_draws_the_smear_the_formula_gives():
    fig = plot_blur_schematic(rate_rad_s=5.0, exposure_s=0.02, focal_px=200.0, window_s=0.01)
    timeline, edge = fig.axes
    ramp, band, line = edge.lines
    x, y = ramp.get_xdata(), ramp.get_ydata()
    rising = x[(y > 0) & (y < 1)]
    assert rising.max() - rising.min() == pytest.approx(20.0, abs=0.3)  # b = 5 rad/s x 20 ms x 200 px
    wide = band.get_xdata()[band.get_ydata() > 0]
    assert wide.max() - wide.min() == pytest.approx(10.0, abs=0.3)  # a 10 ms window's sweep
    assert "b = |ω|Tf = 20 px" in _legend_labels(edge)[0]
    exposures = [p for p in timeline.patches if p.get_label() == "APS exposure T" or p.get_y() > 1]
    assert exposures and all(p.get_width() == pytest.approx(20.0) for p in exposures)  # 20 ms each
    with pytest.raises(ValueError, match=r"exposure_s \(0.05 s\) must be at most one frame interval"):
        plot_blur_schematic(exposure_s=0.05)
    with pytest.raises(ValueError, match=r"rate_rad_s must be a finite number > 0"):
        plot_blur_schematic(rate_rad_s=0.0)
    _render(fig)
