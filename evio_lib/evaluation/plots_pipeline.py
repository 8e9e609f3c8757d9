"""Figures of a complete EVIO run (``python -m evio_lib run``): filter errors with 3-sigma bounds, IMU biases, the
trajectory seen from above, the front-end's tracking statistics and an error comparison of several configurations.

- :func:`plot_state_errors`: per-axis error (truth - estimate) of position, orientation or velocity against time, inside
  the filter's ±3σ band. Called three times per run, it gives the position / orientation / velocity panels of the
  thesis's MSCKF result figures (Figs. 23-32, Friedel 2020, §4.5).
- :func:`plot_bias_estimates`: estimated gyroscope or accelerometer bias with ±3σ around the estimate and, when known,
  the true bias; thesis Appendix C (Figs. 49-58, "Gyroscope and Accelerometer Bias Results").
- :func:`plot_trajectory_topdown`: the x-y plane of any number of estimated trajectories and the ground truth, equal
  aspect, start and end marked (the top-down view of a run; the thesis shows the same information per axis).
- :func:`plot_tracking_statistics`: features tracked / new / total per frame and RANSAC rejections per frame, from the
  columns of :func:`evio_lib.frontend.stats_table`, optionally with a histogram of track lengths (front-end health
  behind the thesis's §4.5 remarks on blur and sparse event frames).
- :func:`plot_error_comparison`: position-error norm against time for several configurations on one axis (e.g. APS
  frames vs event frames vs IMU only, the comparison of thesis Table 6), with an optional line at the start of the
  fast second half of a recording.
- :func:`plot_error_ratio_vs_blur`: when event frames beat APS frames: the ratio of their errors against the APS
  frames' rotation blur |ω| T f, over runs at several speeds and exposures (thesis §4.5.1's argument, measured).
- :func:`plot_blur_schematic`: the idea behind it drawn: APS exposures and event windows on a timeline, and one
  edge as the APS frame, a count of events and motion-compensated events show it.
- :func:`plot_tracks`: the front-end's feature tracks drawn over the frame they end in (polylines over the last frames,
  new features, and the candidates two-point RANSAC rejected), the tracking figure of thesis §3.3.5 / §4.5.

Plotting only, on plain arrays: nothing here depends on the pipeline's classes. Matplotlib is imported when a figure is
made; no function calls ``plt.show``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "plot_state_errors",
    "plot_bias_estimates",
    "plot_trajectory_topdown",
    "plot_tracking_statistics",
    "plot_error_comparison",
    "plot_tracks",
    "track_length_bins",
    "plot_error_ratio_vs_blur",
    "plot_blur_schematic",
]

_BIAS_KINDS = {  # kind -> (default unit, name used in labels)
    "gyro": ("rad/s", "gyroscope bias"),
    "accel": ("m/s^2", "accelerometer bias"),
}
_STATS_KEYS = ("t", "tracked", "new", "total", "rejected_ransac")  # columns plot_tracking_statistics needs


def _array(value: Any, name: str, expected: str) -> NDArray[np.float64]:
    """Return value as a float64 array; raise ValueError naming ``name`` and the ``expected`` form otherwise."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got {type(value).__name__}") from exc


def _times(t: ArrayLike, name: str = "t") -> NDArray[np.float64]:
    """Return t as a finite float64 (N,) array with N >= 1; raise ValueError naming ``name`` otherwise."""
    arr = _array(t, name, "(N,)")
    if arr.ndim != 1 or arr.shape[0] < 1:
        raise ValueError(f"{name} must have shape (N,) with N >= 1 times [s]; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite times [s]; found {int(np.sum(~np.isfinite(arr)))} "
                         f"NaN/inf values")
    return arr


def _xyz(value: ArrayLike, name: str, n: int, *, sigma: bool = False) -> NDArray[np.float64]:
    """Return value as a float64 (n, 3) array (NaN allowed: not drawn); raise ValueError naming ``name`` otherwise.

    With ``sigma`` the values must also be standard deviations: >= 0 where not NaN.
    """
    arr = _array(value, name, f"(N, 3) = ({n}, 3)")
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape (N, 3) = ({n}, 3) like t; got {arr.shape}")
    if np.any(np.isinf(arr)):
        raise ValueError(f"{name} must not contain inf (NaN marks samples that are not drawn)")
    if sigma and np.any(arr < 0):  # NaN < 0 is False, so NaN passes
        raise ValueError(f"{name} must contain standard deviations >= 0 (or NaN); got min {np.nanmin(arr):.3g}")
    return arr


def _n_sigma(n_sigma: float) -> float:
    """Return n_sigma as a float > 0; raise ValueError otherwise."""
    try:
        value = float(n_sigma)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"n_sigma must be a finite number > 0; got {n_sigma!r}") from exc
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"n_sigma must be a finite number > 0; got {n_sigma!r}")
    return value


def _axis_labels(axis_labels: Sequence[str]) -> tuple[str, str, str]:
    """Return three axis names as strings; raise ValueError otherwise."""
    if isinstance(axis_labels, str) or len(axis_labels) != 3:
        raise ValueError(f"axis_labels must be three names, e.g. ('x', 'y', 'z'); got {axis_labels!r}")
    return tuple(str(a) for a in axis_labels)  # type: ignore[return-value]


def plot_state_errors(t: ArrayLike, errors: ArrayLike, sigma: ArrayLike, *, quantity: str = "position",
                      unit: str = "m", axis_labels: Sequence[str] = ("x", "y", "z"), n_sigma: float = 3.0,
                      title: str = "") -> "Figure":
    """Return a figure of three stacked panels (one per axis): the error against time inside the ±nσ band.

    Args:
        t: (N,) times [s].
        errors: (N, 3) per-axis errors, truth - estimate, in ``unit`` (orientation: the caller converts the small-angle
            error δθ to degrees). NaN samples are not drawn.
        sigma: (N, 3) the filter's standard deviations of those errors, sqrt(diag P), in ``unit``; NaN where unknown
            (not drawn there).
        quantity, unit: y labels read "<axis> <quantity> error [<unit>]", e.g. "x position error [m]" ("" leaves the
            quantity out, for axis names that already say it, e.g. "about y_I (yaw)").
        axis_labels: names of the three axes (e.g. ("North", "East", "Down"); for an orientation error in the body
            frame, name the axis that is closest to the vertical as the yaw axis).
        n_sigma: width of the band (3: a consistent filter keeps ~99.7 % of the errors inside).
        title: figure title.

    Reference: thesis Figs. 23-32 (MSCKF position and velocity errors with 3σ bounds), Friedel 2020 §4.5.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_state_errors([0.0, 1.0], np.zeros((2, 3)), np.ones((2, 3)))
    >>> len(fig.axes), fig.axes[0].lines[1].get_ydata().tolist()      # +3 sigma
    (3, [3.0, 3.0])
    """
    import matplotlib.pyplot as plt

    t = _times(t)
    e = _xyz(errors, "errors", t.shape[0])
    s = _xyz(sigma, "sigma", t.shape[0], sigma=True)
    names = _axis_labels(axis_labels)
    k_sigma = _n_sigma(n_sigma)
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    for j, (ax, name) in enumerate(zip(axes, names)):
        ax.plot(t, e[:, j], "C0-", lw=1.2, label="error (truth - estimate)")
        ax.plot(t, k_sigma * s[:, j], "r--", lw=1.0, label=f"±{k_sigma:g}σ")  # +nσ; NaN breaks the line
        ax.plot(t, -k_sigma * s[:, j], "r--", lw=1.0)  # -nσ
        ax.axhline(0.0, color="k", lw=0.5, alpha=0.5)
        ax.set_ylabel(" ".join(part for part in (name, quantity, "error") if part) + f" [{unit}]", fontsize=9)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=3, frameon=False)  # above the data
    axes[-1].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.align_ylabels(axes)
    return fig


def plot_bias_estimates(t: ArrayLike, estimate: ArrayLike, sigma: ArrayLike, truth: ArrayLike | None = None, *,
                        kind: str = "gyro", unit: str | None = None, axis_labels: Sequence[str] = ("x", "y", "z"),
                        n_sigma: float = 3.0, title: str = "") -> "Figure":
    """Return a figure of three stacked panels: the estimated IMU bias per axis, ±nσ around it, the truth if given.

    Args:
        t: (N,) times [s].
        estimate: (N, 3) estimated bias b_g [rad/s] (kind "gyro") or b_a [m/s^2] (kind "accel"), in ``unit``.
        sigma: (N, 3) its standard deviations (NaN where unknown, not drawn).
        truth: (N, 3) true bias (simulations), drawn dashed; None for recordings without one.
        kind: "gyro" or "accel": chooses the labels and the default unit.
        unit: unit of the arrays for the y labels; None: "rad/s" for gyro, "m/s^2" for accel.
        axis_labels: names of the three axes; n_sigma: band width; title: figure title.

    Reference: thesis Appendix C, Figs. 49-58 (estimated gyroscope and accelerometer biases with 3σ bounds).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_bias_estimates([0.0, 1.0], np.zeros((2, 3)), np.ones((2, 3)), kind="accel")
    >>> fig.axes[0].get_ylabel()
    'x accelerometer bias [m/s^2]'
    """
    import matplotlib.pyplot as plt

    if kind not in _BIAS_KINDS:
        raise ValueError(f"kind must be one of {sorted(_BIAS_KINDS)}; got {kind!r}")
    default_unit, name = _BIAS_KINDS[kind]
    unit = default_unit if unit is None else unit
    t = _times(t)
    b = _xyz(estimate, "estimate", t.shape[0])
    s = _xyz(sigma, "sigma", t.shape[0], sigma=True)
    b_true = None if truth is None else _xyz(truth, "truth", t.shape[0])
    names = _axis_labels(axis_labels)
    k_sigma = _n_sigma(n_sigma)
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)  # tall enough for "x accelerometer bias [m/s^2]"
    for j, (ax, axis) in enumerate(zip(axes, names)):
        ax.plot(t, b[:, j], "C0-", lw=1.2, label="estimate")
        ax.plot(t, b[:, j] + k_sigma * s[:, j], "r--", lw=1.0, label=f"estimate ±{k_sigma:g}σ")  # b + nσ
        ax.plot(t, b[:, j] - k_sigma * s[:, j], "r--", lw=1.0)  # b - nσ
        if b_true is not None:
            ax.plot(t, b_true[:, j], "k--", lw=1.2, label="truth")
        ax.set_ylabel(f"{axis} {name} [{unit}]", fontsize=9)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=3, frameon=False)  # above the data
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title or f"estimated {name}" + ("" if b_true is not None else " (no truth available)"))
    fig.tight_layout()
    fig.align_ylabels(axes)
    return fig


def _trajectory(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return value as a float64 (N, 3) array with at least one finite row; raise ValueError naming ``name``."""
    arr = _array(value, name, "(N, 3)")
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 1:
        raise ValueError(f"{name} must have shape (N, 3) with N >= 1 positions [m]; got {arr.shape}")
    if not np.any(np.all(np.isfinite(arr), axis=1)):
        raise ValueError(f"{name} has no finite position (every row contains NaN/inf)")
    return arr


def plot_trajectory_topdown(estimates: Mapping[str, ArrayLike], groundtruth: ArrayLike | None = None, *,
                            title: str = "") -> "Figure":
    """Return a top-down (x-y plane) figure of estimated trajectories and the ground truth, equal aspect.

    Args:
        estimates: label -> (N, 3) estimated positions p_IinG [m] (any number, e.g. {"MSCKF": ..., "IMU only": ...});
            each may have its own N. Rows with NaN are not drawn.
        groundtruth: (M, 3) true positions [m], drawn in black; None when there is none.
        title: figure title.

    The start (circle) and end (cross) of each curve are marked.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_trajectory_topdown({"MSCKF": np.zeros((2, 3))}, np.ones((3, 3)))
    >>> fig.axes[0].get_aspect()
    1.0
    """
    import matplotlib.pyplot as plt

    if not isinstance(estimates, Mapping):
        raise ValueError(f"estimates must be a mapping label -> (N, 3) positions; got {type(estimates).__name__}")
    curves = {str(label): _trajectory(value, f"estimates[{label!r}]") for label, value in estimates.items()}
    gt = None if groundtruth is None else _trajectory(groundtruth, "groundtruth")
    if not curves and gt is None:
        raise ValueError("nothing to draw: estimates is empty and groundtruth is None")
    fig, ax = plt.subplots(figsize=(6.5, 6))
    styled = ([("ground truth", gt, "k")] if gt is not None else []) + \
        [(label, p, f"C{k}") for k, (label, p) in enumerate(curves.items())]
    for k, (label, p, colour) in enumerate(styled):
        ax.plot(p[:, 0], p[:, 1], "-", color=colour, lw=1.8 if colour == "k" else 1.2, label=label)
        finite = np.flatnonzero(np.all(np.isfinite(p), axis=1))
        first, last = p[finite[0]], p[finite[-1]]
        ax.plot(first[0], first[1], "o", color=colour, ms=7, mfc="none", mew=1.5, label="start" if k == 0 else None)
        ax.plot(last[0], last[1], "x", color=colour, ms=7, mew=1.5, label="end" if k == 0 else None)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or "trajectory, top view (x-y plane)")
    fig.tight_layout()
    return fig


def _plain_log_ticks(ax: Any) -> None:
    """Label both log axes of ``ax`` with plain numbers (0.5, 1, 2, 5, 10 rather than 5x10^-1, 10^0), the minor ticks
    only at the leading digits 2 and 5."""
    from matplotlib.ticker import FuncFormatter

    def plain(value: float, _: Any) -> str:
        digit = round(value / 10 ** np.floor(np.log10(value))) if value > 0 else 0
        return f"{value:g}" if digit in (1, 2, 5) else ""

    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(FuncFormatter(plain))
        axis.set_minor_formatter(FuncFormatter(plain))
    ax.tick_params(which="minor", labelsize=7)


def track_length_bins(lengths: ArrayLike, per_decade: int = 10) -> NDArray[np.float64]:
    """Return histogram bin edges for track lengths on a logarithmic axis.

    Lengths up to 10 frames get one bin each (1, 2, 3, ... frames); longer ones share bins whose width grows with the
    length, about ``per_decade`` per decade, so that a histogram from 1 to hundreds of frames keeps both ends
    readable. Each edge lies half a frame below a whole length, and the last one above the longest track.

    >>> track_length_bins([1, 2, 3]).tolist()
    [0.5, 1.5, 2.5, 3.5]
    >>> edges = track_length_bins([1, 480]); bool(edges[0] == 0.5 and edges[-1] > 480 and len(edges) < 40)
    True
    """
    arr = _array(lengths, "track_lengths", "(K,)")
    if arr.ndim != 1 or arr.shape[0] < 1 or not np.all(np.isfinite(arr)) or np.any(arr < 1):
        raise ValueError(f"track_lengths must be finite track lengths >= 1 [frames] of shape (K,) with K >= 1; got "
                         f"shape {arr.shape}")
    if isinstance(per_decade, bool) or not isinstance(per_decade, (int, np.integer)) or per_decade < 1:
        raise ValueError(f"per_decade must be an integer >= 1; got {per_decade!r}")
    longest = float(np.ceil(arr.max()))
    whole = np.arange(1.0, min(longest, 10.0) + 2.0)  # 1, 2, ..., 11 at most: one bin per length up to 10 frames
    if longest > 10:
        steps = max(1, int(np.ceil(np.log10((longest + 1.0) / 11.0) * per_decade)))
        whole = np.unique(np.r_[whole, np.round(np.geomspace(11.0, longest + 1.0, steps + 1))])
    return whole - 0.5  # the last start is longest + 1: the last edge lies above the longest track


def plot_tracking_statistics(stats: Mapping[str, ArrayLike], *, track_lengths: ArrayLike | None = None,
                             title: str = "") -> "Figure":
    """Return a figure of the front-end's per-frame statistics: features (top), RANSAC rejections (bottom).

    Args:
        stats: columns as :func:`evio_lib.frontend.stats_table` returns them; needs "t" (F,) frame times [s] and the
            (F,) counts "tracked", "new", "total" and "rejected_ransac"; "lost" (F,) is drawn beside the rejections
            when present. Other columns are ignored.
        track_lengths: optional (K,) lengths of finished tracks in frames (>= 1); adds a third panel, their histogram.
        title: figure title.

    The legend gives each count's mean per frame.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> s = {"t": [0.0, 0.1], "tracked": [0, 8], "new": [10, 2], "total": [10, 10], "rejected_ransac": [0, 1]}
    >>> len(plot_tracking_statistics(s, track_lengths=[1, 2, 2]).axes)
    3
    """
    import matplotlib.pyplot as plt

    if not isinstance(stats, Mapping):
        raise ValueError(f"stats must be a mapping of columns (evio_lib.frontend.stats_table); "
                         f"got {type(stats).__name__}")
    for key in _STATS_KEYS:
        if key not in stats:
            raise ValueError(f"stats lacks the column {key!r}; expected the columns {list(_STATS_KEYS)} "
                             f"(evio_lib.frontend.stats_table)")
    t = _array(stats["t"], "stats['t']", "(F,)")
    if t.ndim != 1 or t.shape[0] < 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"stats['t'] must be finite frame times of shape (F,), F >= 1; got shape {t.shape}")
    columns = {}
    for key in _STATS_KEYS[1:] + (("lost",) if "lost" in stats else ()):
        col = _array(stats[key], f"stats[{key!r}]", f"(F,) = {t.shape}")
        if col.shape != t.shape:
            raise ValueError(f"stats[{key!r}] must have shape (F,) = {t.shape} like stats['t']; got {col.shape}")
        if not np.all(np.isfinite(col)) or np.any(col < 0):
            raise ValueError(f"stats[{key!r}] must contain finite counts >= 0")
        columns[key] = col
    lengths = None
    if track_lengths is not None:
        lengths = _array(track_lengths, "track_lengths", "(K,)")
        if lengths.ndim != 1 or lengths.shape[0] < 1:
            raise ValueError(f"track_lengths must have shape (K,) with K >= 1; got {lengths.shape}")
        if not np.all(np.isfinite(lengths)) or np.any(lengths < 1):
            raise ValueError("track_lengths must contain finite track lengths >= 1 [frames]")
    n_panels = 2 if lengths is None else 3
    fig, axes = plt.subplots(n_panels, 1, figsize=(8, 2.6 * n_panels + 0.6))
    top, bottom = axes[0], axes[1]
    for key, style in (("total", "k-"), ("tracked", "C0-"), ("new", "C2-")):
        top.plot(t, columns[key], style, lw=1.2, label=f"{key} (mean {columns[key].mean():.1f})")
    top.set_ylabel("features per frame")
    bottom.sharex(top)
    bottom.plot(t, columns["rejected_ransac"], "C3-", lw=1.2,
                label=f"rejected by RANSAC (mean {columns['rejected_ransac'].mean():.1f})")
    if "lost" in columns:
        bottom.plot(t, columns["lost"], "C1:", lw=1.2, label=f"lost (mean {columns['lost'].mean():.1f})")
    bottom.set_ylabel("tracks per frame")
    bottom.set_xlabel("time [s]")
    for ax, curves in ((top, ("total", "tracked", "new")), (bottom, ("rejected_ransac", "lost"))):
        ax.grid(True, alpha=0.3)
        highest = max(float(columns[k].max()) for k in curves if k in columns)
        ax.set_ylim(0.0, 1.45 * max(highest, 1.0))            # headroom: the legend sits above the curves
        ax.legend(fontsize=8, loc="upper left", ncol=3, frameon=False)
    if lengths is not None:
        hist = axes[2]
        hist.hist(lengths, bins=track_length_bins(lengths), color="C0", alpha=0.8)
        hist.axvline(float(np.median(lengths)), color="k", ls="--", lw=1.0,
                     label=f"median {np.median(lengths):g} frames, mean {lengths.mean():.1f} "
                           f"({lengths.shape[0]} tracks)")
        hist.set_xscale("log")  # lengths from 1 frame to hundreds: a few long tracks would squeeze the rest
        hist.set_yscale("log")  # counts from thousands of short tracks to a handful of long ones
        hist.set_xlim(0.8, 1.3 * (lengths.max() + 0.5))
        _plain_log_ticks(hist)
        hist.set_xlabel("track length [frames] (log; one bin per length up to 10, wider bins above)")
        hist.set_ylabel("tracks per bin (log)")
        hist.grid(True, which="both", alpha=0.3)
        hist.legend(fontsize=8)
    fig.suptitle(title or f"front-end statistics over {t.shape[0]} frames")
    fig.tight_layout()
    return fig


def plot_error_comparison(t_by_name: Mapping[str, ArrayLike], error_norm_by_name: Mapping[str, ArrayLike], *,
                          split_time: float | None = None, log: bool = False, ylabel: str = "position error [m]",
                          styles: Mapping[str, str] | None = None, title: str = "",
                          motion: tuple[ArrayLike, ArrayLike, ArrayLike] | None = None) -> "Figure":
    """Return a figure of error norms against time, one line per configuration, on one axis.

    Args:
        t_by_name: label -> (N_k,) times [s] of that configuration (each may have its own N_k).
        error_norm_by_name: the same labels -> (N_k,) error norms |p_true - p_est| >= 0 (NaN not drawn).
        split_time: draws a vertical line there (e.g. the start of a recording's fast second half); None: no line.
        log: logarithmic y axis (then only errors > 0 are drawn); use it when the errors span decades, or the
            small ones lie on the axis.
        ylabel: y-axis label; title: figure title.
        styles: optional label -> matplotlib line style ("-", "--", ":", "-."), e.g. dashed for event frames; each
            line keeps its own colour and its legend entry shows the style. Default: solid.
        motion: optional (t, speed [m/s], angular rate [rad/s]) of the camera, drawn in a panel below on the same
            time axis (speed on its left axis, angular rate on a second axis at its right, each with its unit), so the
            reader sees where each configuration gains or loses against how fast the camera moves.

    Reference: the configurations of thesis Table 6 (IMU only, grayscale/APS frames, event frames).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_error_comparison({"a": [0.0, 1.0]}, {"a": [0.0, 0.5]}, split_time=0.5)
    >>> [line.get_label() for line in fig.axes[0].lines]
    ['a', 'split at t = 0.5 s']
    """
    import matplotlib.pyplot as plt

    for name, value in (("t_by_name", t_by_name), ("error_norm_by_name", error_norm_by_name)):
        if not isinstance(value, Mapping) or not value:
            raise ValueError(f"{name} must be a non-empty mapping label -> (N,) array; got {type(value).__name__}")
    if set(t_by_name) != set(error_norm_by_name):
        raise ValueError(f"t_by_name and error_norm_by_name must have the same labels; got "
                         f"{sorted(map(str, t_by_name))} and {sorted(map(str, error_norm_by_name))}")
    curves = {}
    for label in error_norm_by_name:
        t = _times(t_by_name[label], f"t_by_name[{label!r}]")
        e = _array(error_norm_by_name[label], f"error_norm_by_name[{label!r}]", f"(N,) = {t.shape}")
        if e.shape != t.shape:
            raise ValueError(f"error_norm_by_name[{label!r}] must have shape (N,) = {t.shape} like "
                             f"t_by_name[{label!r}]; got {e.shape}")
        if np.any(np.isinf(e)) or np.any(e < 0):
            raise ValueError(f"error_norm_by_name[{label!r}] must contain error norms >= 0 (NaN not drawn, no inf)")
        curves[label] = (t, e)
    split = None
    if split_time is not None:
        try:
            split = float(split_time)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"split_time must be a finite time [s] or None; got {split_time!r}") from exc
        if not np.isfinite(split):
            raise ValueError(f"split_time must be a finite time [s] or None; got {split_time!r}")
    styles = {} if styles is None else styles
    if not isinstance(styles, Mapping) or set(styles) - set(curves) or \
            any(style not in ("-", "--", ":", "-.") for style in styles.values()):
        raise ValueError(f"styles must map some of the labels {sorted(map(str, curves))} to one of '-', '--', ':', "
                         f"'-.'; got {styles!r}")
    if motion is not None:
        if not isinstance(motion, (tuple, list)) or len(motion) != 3:
            raise ValueError("motion must be (t, speed, angular_rate), three (N,) arrays; got "
                             f"{type(motion).__name__}")
        t_m = _times(motion[0], "motion[0] (t)")
        v_m = _array(motion[1], "motion[1] (speed)", f"(N,) = {t_m.shape}")
        w_m = _array(motion[2], "motion[2] (angular rate)", f"(N,) = {t_m.shape}")
        if v_m.shape != t_m.shape or w_m.shape != t_m.shape:
            raise ValueError(f"motion's speed and angular rate must have the shape of its times {t_m.shape}; got "
                             f"{v_m.shape} and {w_m.shape}")
        fig, (ax, ax_m) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, height_ratios=(2.2, 1))
    else:
        fig, ax = plt.subplots(figsize=(8, 4))
    for k, (label, (t, e)) in enumerate(curves.items()):
        keep = e > 0 if log else np.ones_like(e, dtype=bool)  # log axes cannot show 0
        ax.plot(t[keep], e[keep], color=f"C{k}", ls=styles.get(label, "-"), lw=1.4, label=str(label))
    if split is not None:
        ax.axvline(split, color="k", ls="--", lw=1.0, label=f"split at t = {split:g} s")
    if log:
        ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    if motion is not None:  # two quantities, two units: speed on the left axis, angular rate on the right
        ax_m.plot(t_m, v_m, color="k", lw=1.2, label="speed [m/s]")
        ax_m.set_ylabel("speed [m/s]")
        ax_m.set_ylim(bottom=0.0)
        ax_m.grid(True, alpha=0.3)
        ax_m.set_xlabel("time [s]")
        ax_w = ax_m.twinx()
        ax_w.plot(t_m, w_m, color="C3", lw=1.2, ls="--", label="angular rate [rad/s]")
        ax_w.set_ylabel("angular rate [rad/s]", color="C3")
        ax_w.tick_params(axis="y", colors="C3")
        ax_w.set_ylim(bottom=0.0)
        ax_m.legend(ax_m.lines + ax_w.lines, [line.get_label() for line in ax_m.lines + ax_w.lines], fontsize=8,
                    loc="upper left")
    else:
        ax.set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def _image(image: ArrayLike) -> NDArray[Any]:
    """Return image as an (H, W) or (H, W, 3) array for imshow; raise ValueError naming the expected form."""
    arr = np.asarray(image)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValueError(f"image must be a numeric (H, W) grayscale or (H, W, 3) image; got dtype {arr.dtype}")
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)) or min(arr.shape[:2]) < 1:
        raise ValueError(f"image must have shape (H, W) or (H, W, 3); got {arr.shape}")
    return arr


def _tracks_from_frames(frames: Sequence[Any], last: int | None) -> dict[int, NDArray[np.float64]]:
    """Return id -> (L, 2) pixels of the tracks alive in the last frame, over the last ``last`` frames."""
    frames = list(frames)
    if not frames:
        raise ValueError("frames_or_tracks must hold at least one tracked frame (or be a mapping id -> (L, 2) pixels)")
    for k, frame in enumerate(frames):
        if not (hasattr(frame, "ids") and hasattr(frame, "pixels")):
            raise ValueError(f"frames_or_tracks[{k}] must be a tracked frame with .ids (K,) and .pixels (K, 2) "
                             f"(evio_lib.frontend.TrackedFrame); got {type(frame).__name__}")
    if last is not None:
        frames = frames[-last:]
    history: dict[int, list[NDArray[np.float64]]] = {}
    for k, frame in enumerate(frames):
        ids = np.asarray(frame.ids).reshape(-1)
        pixels = _array(frame.pixels, f"frames[{k}].pixels", "(K, 2)")
        if pixels.shape != (ids.shape[0], 2):
            raise ValueError(f"frames[{k}].pixels must have shape (K, 2) = ({ids.shape[0]}, 2) like its ids; "
                             f"got {pixels.shape}")
        for track_id, xy in zip(ids.tolist(), pixels):
            history.setdefault(int(track_id), []).append(xy)
    alive = np.asarray(frames[-1].ids).reshape(-1).tolist()
    return {int(i): np.array(history[int(i)]) for i in alive}


def plot_tracks(image: ArrayLike, frames_or_tracks: Sequence[Any] | Mapping[Any, ArrayLike], *,
                rejected: ArrayLike | None = None, last: int | None = None, track_label: str = "tracked",
                title: str = "") -> "Figure":
    """Return a figure of feature tracks drawn over the image they end in, with RANSAC's rejections marked.

    Args:
        image: (H, W) grayscale (uint8, or float in [0, 1]) or (H, W, 3) image: the frame the tracks end in.
        frames_or_tracks: either consecutive tracked frames, oldest first, the last one being ``image``'s (objects
            with ``.ids`` (K,) and ``.pixels`` (K, 2) raw pixel (x, y), e.g. :class:`evio_lib.frontend.TrackedFrame`;
            the tracks alive in the last frame are drawn over the frames given), or a mapping track id -> (L, 2)
            pixel positions (x, y), oldest first.
        rejected: optional candidates two-point RANSAC rejected in this frame: (M, 2) pixel positions, or
            (M, 2, 2) pairs [previous pixel, candidate pixel] (drawn as a segment ending in a cross).
        last: draw only each track's last ``last`` positions (None: all given).
        track_label: legend name of the polylines (e.g. "kept by RANSAC" for one frame pair's matches).
        title: axes title (default: the counts).

    Tracks with two or more positions are green polylines ending in a dot (one Line2D, tracks separated by NaN);
    tracks seen once (new features) are cyan circles; rejected candidates are red crosses. The legend gives the
    counts and the mean length of the drawn tracks in frames.

    Reference: thesis §3.3.5 (feature tracking with two-point RANSAC) and §4.5.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_tracks(np.zeros((48, 64)), {7: [[10.0, 10.0], [12.0, 11.0]], 8: [[30.0, 20.0]]},
    ...                   rejected=[[40.0, 30.0]])
    >>> [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    ['tracked (1, mean 2.0 frames)', 'new (1)', 'rejected by RANSAC (1)']
    """
    import matplotlib.pyplot as plt

    img = _image(image)
    if last is not None and (isinstance(last, bool) or not isinstance(last, (int, np.integer)) or last < 1):
        raise ValueError(f"last must be None or an integer >= 1 (positions per track); got {last!r}")
    if isinstance(frames_or_tracks, Mapping):
        tracks = {}
        for track_id, value in frames_or_tracks.items():
            xy = _array(value, f"frames_or_tracks[{track_id!r}]", "(L, 2)")
            if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 1 or not np.all(np.isfinite(xy)):
                raise ValueError(f"frames_or_tracks[{track_id!r}] must be finite pixel positions of shape (L, 2) "
                                 f"with L >= 1; got shape {xy.shape}")
            tracks[track_id] = xy if last is None else xy[-last:]
    elif isinstance(frames_or_tracks, (str, bytes)) or not hasattr(frames_or_tracks, "__iter__"):
        raise ValueError(f"frames_or_tracks must be a sequence of tracked frames or a mapping id -> (L, 2) pixels; "
                         f"got {type(frames_or_tracks).__name__}")
    else:
        tracks = _tracks_from_frames(frames_or_tracks, last)
    segments = None
    if rejected is not None:
        rej = _array(rejected, "rejected", "(M, 2) or (M, 2, 2)")
        if rej.size == 0:
            rej = rej.reshape(0, 2)
        if not ((rej.ndim == 2 and rej.shape[1] == 2) or (rej.ndim == 3 and rej.shape[1:] == (2, 2))):
            raise ValueError(f"rejected must have shape (M, 2) candidate pixels or (M, 2, 2) [previous, candidate] "
                             f"pixel pairs; got {rej.shape}")
        if not np.all(np.isfinite(rej)):
            raise ValueError("rejected must contain only finite pixel positions")
        if rej.ndim == 3:
            segments, rej = rej, rej[:, 1]
    long_tracks = [xy for xy in tracks.values() if xy.shape[0] >= 2]
    new_points = np.array([xy[-1] for xy in tracks.values() if xy.shape[0] == 1]).reshape(-1, 2)

    fig, ax = plt.subplots(figsize=(7.5, 7.5 * img.shape[0] / img.shape[1] + 0.6))
    ax.imshow(img, cmap="gray", vmin=0, vmax=255 if img.dtype == np.uint8 else 1, interpolation="nearest")
    if long_tracks:
        mean_length = float(np.mean([xy.shape[0] for xy in long_tracks]))
        joined = np.concatenate([np.vstack([xy, [np.nan, np.nan]]) for xy in long_tracks])[:-1]
        ax.plot(joined[:, 0], joined[:, 1], "-", color="lime", lw=1.2,
                label=f"{track_label} ({len(long_tracks)}, mean {mean_length:.1f} frames)")
        ends = np.array([xy[-1] for xy in long_tracks])
        ax.plot(ends[:, 0], ends[:, 1], ".", color="lime", ms=5)
    if new_points.shape[0]:
        ax.plot(new_points[:, 0], new_points[:, 1], "o", color="cyan", ms=5, mfc="none", mew=1.2,
                label=f"new ({new_points.shape[0]})")
    if rejected is not None and rej.shape[0]:
        if segments is not None:
            joined = np.concatenate([np.vstack([pair, [np.nan, np.nan]]) for pair in segments])[:-1]
            ax.plot(joined[:, 0], joined[:, 1], "-", color="red", lw=1.0)
        ax.plot(rej[:, 0], rej[:, 1], "x", color="red", ms=7, mew=1.5, label=f"rejected by RANSAC ({rej.shape[0]})")
    ax.set_xlim(-0.5, img.shape[1] - 0.5)
    ax.set_ylim(img.shape[0] - 0.5, -0.5)  # image rows go down
    ax.set_xlabel("x [px]")
    ax.set_ylabel("y [px]")
    if ax.get_legend_handles_labels()[1]:
        ax.legend(fontsize=8, loc="lower right", framealpha=0.8)
    ax.set_title(title or f"{len(tracks)} features, {len(long_tracks)} tracked from earlier frames")
    fig.tight_layout()
    return fig


def _positive(value: ArrayLike, name: str, n: int | None = None) -> NDArray[np.float64]:
    """Return value as a finite float64 (K,) array of numbers > 0 (length n when given); raise ValueError otherwise."""
    arr = _array(value, name, "(K,)")
    if arr.ndim != 1 or arr.shape[0] < 1 or (n is not None and arr.shape[0] != n):
        raise ValueError(f"{name} must have shape (K,) with K >= 1" + ("" if n is None else f" = {n} like blur_px")
                         + f"; got {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must contain finite numbers > 0")
    return arr


def plot_error_ratio_vs_blur(blur_px: ArrayLike, ratio: ArrayLike, *, exposure_ms: ArrayLike, speed: ArrayLike,
                             speed_labels: Mapping[float, str] | None = None,
                             ylabel: str = "error ratio, event frames / APS frames", title: str = "") -> "Figure":
    """Return the "when do events win" figure: an error ratio against the APS frames' rotation blur, log-log.

    Args:
        blur_px: (K,) rotation blur b = |ω| T f of each run's APS frames, pixels (> 0): the mean angular rate over
            the stretch times the exposure T times the focal length f, how far the rotation moves a point near the
            image centre while the shutter is open.
        ratio: (K,) the error of the run on event frames divided by that of the run on APS frames over the same
            stretch (> 0): below 1 the events win.
        exposure_ms: (K,) each run's APS exposure T [ms]; the marker's colour, with a colourbar.
        speed: (K,) each run's playback speed of the motion (1: the preset's); the marker's shape, in the legend.
        speed_labels: optional legend text per speed (e.g. {1.0: "gentle start, speed 1"}); default "speed s".
        ylabel, title: labels.

    Every run is a small marker; each (speed, exposure) cell's geometric mean over its runs is a large one with a
    black edge (a ratio's natural mean). A horizontal line marks ratio 1, the region below it is shaded.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_error_ratio_vs_blur([1.0, 10.0], [2.0, 0.5], exposure_ms=[10, 20], speed=[1, 2])
    >>> fig.axes[0].get_xscale(), fig.axes[0].get_yscale(), fig.axes[1].get_ylabel()
    ('log', 'log', 'APS exposure T [ms]')
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.lines import Line2D

    b = _positive(blur_px, "blur_px")
    r = _positive(ratio, "ratio", b.shape[0])
    exposure = _positive(exposure_ms, "exposure_ms", b.shape[0])
    speeds = _positive(speed, "speed", b.shape[0])
    low, high = float(exposure.min()), float(exposure.max())
    norm = LogNorm(low, high) if high > low else Normalize(low - 1.0, high + 1.0)
    cmap = plt.get_cmap("viridis")
    markers = "osD^vP*X"
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    lo = min(float(r.min()), 0.5) / 1.3
    ax.axhspan(lo, 1.0, color="C2", alpha=0.08, lw=0)
    line = ax.axhline(1.0, color="k", lw=1.0, ls="--")
    handles, labels = [line], ["ratio 1: equal errors (below: events win)"]
    names = {} if speed_labels is None else {float(key): str(value) for key, value in speed_labels.items()}
    for k, s in enumerate(np.unique(speeds)):
        marker = markers[k % len(markers)]
        here = speeds == s
        ax.scatter(b[here], r[here], c=exposure[here], cmap=cmap, norm=norm, marker=marker, s=22, alpha=0.6,
                   edgecolors="none")
        cells = np.unique(exposure[here])
        mean_b = [float(np.exp(np.log(b[here & (exposure == e)]).mean())) for e in cells]
        mean_r = [float(np.exp(np.log(r[here & (exposure == e)]).mean())) for e in cells]
        ax.scatter(mean_b, mean_r, c=cells, cmap=cmap, norm=norm, marker=marker, s=90, edgecolors="k",
                   linewidths=1.0)
        handles.append(Line2D([], [], ls="", marker=marker, ms=8, mfc="0.7", mec="k"))  # the shape, no colour
        labels.append(names.get(float(s), f"speed {s:g}"))
    handles.append(Line2D([], [], ls="", marker="o", ms=4, mfc="0.6", mec="none", alpha=0.6))
    labels.append("one run (small) / geometric mean of a cell's runs (large)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylim(bottom=lo)
    ax.set_xlabel("rotation blur of the APS frames |ω| T f [px] (log)")
    ax.set_ylabel(ylabel + " (log)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(handles, labels, fontsize=8, loc="upper right")
    _plain_log_ticks(ax)
    colourbar = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax)
    colourbar.set_ticks(np.unique(exposure))
    colourbar.set_ticklabels([f"{value:g}" for value in np.unique(exposure)])
    colourbar.minorticks_off()
    colourbar.set_label("APS exposure T [ms]")
    ax.set_title(title or "when do event frames beat APS frames?")
    fig.tight_layout()
    return fig


def plot_blur_schematic(rate_rad_s: float = 4.5, exposure_s: float = 0.02, focal_px: float = 199.0,
                        window_s: float = 0.01, frame_rate_hz: float = 24.0) -> "Figure":
    """Return the idea behind event frames in fast motion, drawn in two panels.

    Left, a timeline of 0.1 s: the APS frames come every 1 / ``frame_rate_hz`` s, each integrating the light over
    its exposure T; the event windows follow each other back to back, each ``window_s`` long at this speed. Right,
    one vertical edge seen by each, as an intensity profile across it: the camera turning at ``rate_rad_s`` moves
    the edge at |ω| f px/s, so the APS frame spreads it into a ramp b = |ω| T f pixels wide, a count of a window's
    events into a band |ω| w f wide, and the same events warped with the gyroscope's rotation to one time
    (motion-compensated) back onto a line.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_blur_schematic()
    >>> len(fig.axes), fig.axes[1].get_xlabel()
    (2, 'x across the edge [px]')
    """
    import matplotlib.pyplot as plt

    values = {"rate_rad_s": rate_rad_s, "exposure_s": exposure_s, "focal_px": focal_px, "window_s": window_s,
              "frame_rate_hz": frame_rate_hz}
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
    if exposure_s > 1.0 / frame_rate_hz:
        raise ValueError(f"exposure_s ({exposure_s:g} s) must be at most one frame interval, 1/{frame_rate_hz:g} s")
    blur_aps = rate_rad_s * exposure_s * focal_px
    blur_window = rate_rad_s * window_s * focal_px
    fig, (ax_t, ax_x) = plt.subplots(1, 2, figsize=(11.5, 3.6), width_ratios=(1.15, 1))
    span = 0.1
    for k in range(int(np.ceil(span * frame_rate_hz)) + 1):
        t_mid = (k + 0.5) / frame_rate_hz
        if t_mid - exposure_s / 2 < span:
            ax_t.add_patch(plt.Rectangle((1e3 * (t_mid - exposure_s / 2), 1.15), 1e3 * exposure_s, 0.6, color="C0",
                                         alpha=0.7, label="APS exposure T" if k == 0 else None))
    for k in range(int(np.ceil(span / window_s))):
        ax_t.add_patch(plt.Rectangle((1e3 * k * window_s, 0.25), 1e3 * window_s, 0.6, facecolor="C1",
                                     edgecolor="w", alpha=0.8, label="event window w" if k == 0 else None))
    ax_t.set_xlim(0, 1e3 * span)
    ax_t.set_ylim(0, 2.1)
    ax_t.set_yticks([0.55, 1.45], ["events", "APS frames"])
    ax_t.set_xlabel("time [ms]")
    ax_t.legend(fontsize=8, loc="upper right", ncol=2)
    ax_t.set_title(f"APS: one frame every {1e3 / frame_rate_hz:.1f} ms, exposed {1e3 * exposure_s:g} ms; "
                   f"events: windows of {1e3 * window_s:g} ms", fontsize=9)
    x = np.linspace(-1.6 * blur_aps, 1.6 * blur_aps, 801)
    ramp = np.clip(0.5 + x / blur_aps, 0.0, 1.0)  # a step edge averaged over its sweep of b pixels
    band = np.where(np.abs(x) <= blur_window / 2, 1.0, 0.0)  # events fired along the window's sweep
    line = np.exp(-0.5 * (x / 0.7) ** 2)  # warped to one time: back on a line, about a pixel wide
    ax_x.plot(x, ramp, color="C0", lw=2.0, label=f"APS frame: a ramp b = |ω|Tf = {blur_aps:.0f} px wide")
    ax_x.plot(x, band, color="C1", lw=1.5, ls="--", label=f"events counted as they come: {blur_window:.0f} px band")
    ax_x.plot(x, line, color="C2", lw=2.0, label="events warped with the gyro (motion-compensated)")
    ax_x.set_xlabel("x across the edge [px]")
    ax_x.set_ylabel("intensity / event count (scaled to 1)")
    ax_x.set_ylim(-0.05, 1.45)
    ax_x.legend(fontsize=8, loc="upper left")
    ax_x.grid(True, alpha=0.3)
    ax_x.set_title(f"one edge, camera turning at |ω| = {rate_rad_s:g} rad/s, f = {focal_px:g} px", fontsize=9)
    fig.tight_layout()
    return fig
