"""Figures for the event-camera simulation lesson (notebook 03): one pixel's events, event clouds, rates, IMU.

Plotting only (plus :func:`event_rate`, the histogram the rate plots show); the simulator lives in
:mod:`evio_lib.events.simulate` and :mod:`evio_lib.sim`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.events.array import EVENT_DTYPE

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "event_rate",
    "plot_pixel_events",
    "plot_image_row",
    "plot_image_table",
    "plot_sample_intervals",
    "plot_event_cloud",
    "plot_imu_vs_truth",
    "plot_event_rates",
]

_ON_COLOUR, _OFF_COLOUR = "tab:red", "tab:blue"


def _check_events(events: np.ndarray, name: str = "events") -> None:
    """Raise ValueError unless ``events`` is a 1-D array of dtype EVENT_DTYPE."""
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE or events.ndim != 1:
        got = events.dtype if isinstance(events, np.ndarray) else type(events).__name__
        raise ValueError(f"{name} must be a 1-D array of dtype EVENT_DTYPE; got {got}")


def event_rate(events: np.ndarray, t_start: float, t_end: float, bin_s: float = 0.01
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (bin centres [s], events per second) of the events in [t_start, t_end) counted in bins of ``bin_s``.

    rate_k = (number of events with t in [t_start + k bin_s, t_start + (k + 1) bin_s)) / bin_s; a last partial bin
    is dropped.

    Args:
        events: (N,) event array (EVENT_DTYPE), sorted by time.
        t_start: start of the first bin [s].
        t_end: end of the window [s], > t_start.
        bin_s: bin width [s], > 0 and <= t_end - t_start.

    >>> from evio_lib.events.array import make_events
    >>> ev = make_events([0.01, 0.02, 0.15], [0, 1, 2], [0, 0, 0], [1, -1, 1])
    >>> centres, rate = event_rate(ev, 0.0, 0.2, bin_s=0.1)
    >>> centres.round(2).tolist(), rate.round(1).tolist()
    ([0.05, 0.15], [20.0, 10.0])
    """
    _check_events(events)
    if not (np.isfinite(t_start) and np.isfinite(t_end) and t_end > t_start):
        raise ValueError(f"t_start and t_end must be finite with t_end > t_start; got t_start={t_start}, t_end={t_end}")
    if not (np.isfinite(bin_s) and 0 < bin_s <= t_end - t_start):
        raise ValueError(f"bin_s must be in (0, t_end - t_start] = (0, {t_end - t_start:g}] s; got {bin_s!r}")
    n_bins = int(np.floor((t_end - t_start) / bin_s + 1e-9))
    edges = t_start + bin_s * np.arange(n_bins + 1)
    counts = np.diff(np.searchsorted(events["t"], edges, side="left"))  # events per half-open bin
    return 0.5 * (edges[:-1] + edges[1:]), counts / bin_s


def plot_pixel_events(t: ArrayLike, log_intensity: ArrayLike, events: np.ndarray, contrast: float,
                      reference0: float | None = None) -> "Figure":
    """Return a two-panel figure of one pixel (like thesis Fig. 4): its log intensity with the threshold levels
    and the events it fired (top), and the event stream as +1/-1 spikes (bottom).

    Args:
        t: (K,) times [s] of the log-intensity curve.
        log_intensity: (K,) L(t) = log(I + eps) of the pixel.
        events: (N,) events of that pixel (EVENT_DTYPE).
        contrast: the threshold C (the levels drawn are reference0 + k C).
        reference0: the initial reference level (default: L at the first time).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> from evio_lib.events.array import make_events
    >>> fig = plot_pixel_events([0.0, 1.0], [0.0, 0.5], make_events([0.4, 0.8], [0, 0], [0, 0], [1, 1]), 0.2)
    >>> len(fig.axes)
    2
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    log_i = np.asarray(log_intensity, dtype=np.float64)
    if t.ndim != 1 or log_i.shape != t.shape or t.size < 2:
        raise ValueError(f"t and log_intensity must have the same shape (K,), K >= 2; got {t.shape} and {log_i.shape}")
    _check_events(events)
    if not (np.isfinite(contrast) and contrast > 0):
        raise ValueError(f"contrast must be a positive threshold; got {contrast!r}")
    r0 = float(log_i[0]) if reference0 is None else float(reference0)
    fig, (ax, ax_ev) = plt.subplots(2, 1, figsize=(9, 5), sharex=True, height_ratios=(3, 1))
    k = np.arange(np.floor((log_i.min() - r0) / contrast), np.ceil((log_i.max() - r0) / contrast) + 1)
    for j, level in enumerate(r0 + k * contrast):
        ax.axhline(level, color="0.85", lw=0.8, zorder=0, label="levels r0 + k C" if j == 0 else None)
    ax.plot(t, log_i, color="k", lw=1.5, label="log intensity L(t)")
    level_at_event = np.interp(events["t"], t, log_i)
    for p, colour, marker, label in ((1, _ON_COLOUR, "^", "ON event"), (-1, _OFF_COLOUR, "v", "OFF event")):
        sel = events["p"] == p
        ax.scatter(events["t"][sel], level_at_event[sel], color=colour, marker=marker, s=40, zorder=3, label=label)
        ax_ev.vlines(events["t"][sel], 0, p, color=colour, lw=1.5)
    ax.set_ylabel("L = log(I + eps) [log units]")
    ax.set_title(f"one pixel: an event each time L moves by C = {contrast:g} from its last event level")
    ax.legend(loc="upper right", fontsize=8)
    ax_ev.axhline(0, color="k", lw=0.5)
    ax_ev.set_ylim(-1.3, 1.3)
    ax_ev.set_yticks([-1, 1])
    ax_ev.set_ylabel("polarity p")
    ax_ev.set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def _value_range(images: Sequence[np.ndarray], symmetric: bool = False) -> tuple[float, float]:
    """Return (vmin, vmax) over the finite values of all ``images`` (centred on 0 when ``symmetric``)."""
    finite = [im[np.isfinite(im)] if np.issubdtype(im.dtype, np.floating) else im.ravel() for im in images]
    finite = [f for f in finite if f.size]
    vmin, vmax = (min(float(f.min()) for f in finite), max(float(f.max()) for f in finite)) if finite else (0.0, 1.0)
    if symmetric:
        vmax = max(abs(vmin), abs(vmax), 1e-12)
        vmin = -vmax
    return vmin, vmax


def _per_image(value, n: int, name: str, is_single) -> list:
    """Return ``value`` repeated n times when ``is_single(value)``, else as a list of length n (ValueError if not)."""
    values = [value] * n if is_single(value) else list(value)
    if len(values) != n:
        raise ValueError(f"{name} must be one value or one per image ({n}); got {len(values)}")
    return values


def _is_range(value) -> bool:
    return value is None or (len(value) == 2 and all(np.isscalar(v) for v in value))


def plot_image_row(images: Sequence[ArrayLike], titles: Sequence[str], cmaps: Sequence[str] | str = "gray",
                   symmetric: Sequence[bool] | bool = False, colorbar: bool = False, width_in: float = 4.0,
                   vrange: tuple[float, float] | str | Sequence[tuple[float, float] | None] | None = None,
                   colorbar_label: str | Sequence[str] = "") -> "Figure":
    """Return a figure showing ``images`` side by side, each with its title.

    Args:
        images: list of (H, W) arrays (grayscale frames, renders, depth maps, event-count images).
        titles: one title per image.
        cmaps: one colour map for all or one per image.
        symmetric: per image (or for all): centre the colour range on 0 (signed event images).
        colorbar: add a colour bar to every panel.
        width_in: width of each panel in inches.
        vrange: the colour range: None (each image its own min..max), ``"shared"`` (one min..max over all images,
            for images of one quantity), one (vmin, vmax) for all, or one (vmin, vmax) or None per image.
        colorbar_label: the colour bars' label (the quantity and its unit), one for all or one per image.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_image_row([np.zeros((4, 5)), np.eye(4)], ["a", "b"], cmaps=["gray", "bwr"], symmetric=[False, True])
    >>> len(fig.axes)
    2
    >>> fig = plot_image_row([np.zeros((4, 4)), 2 * np.eye(4)], ["a", "b"], vrange="shared", colorbar=True)
    >>> [ax.images[0].get_clim() for ax in fig.axes[:2]]
    [(0.0, 2.0), (0.0, 2.0)]
    """
    import matplotlib.pyplot as plt

    images = [np.asarray(im) for im in images]
    n = len(images)
    if n == 0 or len(titles) != n:
        raise ValueError(f"images and titles must be non-empty and equally long; got {n} images and "
                         f"{len(titles)} titles")
    for i, im in enumerate(images):
        if im.ndim != 2:
            raise ValueError(f"images[{i}] must have shape (H, W); got {im.shape}")
    cmaps = _per_image(cmaps, n, "cmaps", lambda v: isinstance(v, str))
    symmetric = _per_image(symmetric, n, "symmetric", lambda v: isinstance(v, (bool, np.bool_)))
    labels = _per_image(colorbar_label, n, "colorbar_label", lambda v: isinstance(v, str))
    if isinstance(vrange, str):
        if vrange != "shared":
            raise ValueError(f"vrange must be None, 'shared', (vmin, vmax) or one per image; got {vrange!r}")
        ranges = [_value_range(images, symmetric=any(symmetric))] * n
    else:
        ranges = _per_image(vrange, n, "vrange", _is_range)
    aspect = images[0].shape[0] / images[0].shape[1]
    fig, axes = plt.subplots(1, n, figsize=(width_in * n, width_in * aspect + 0.6), squeeze=False)
    for ax, im, title, cmap, sym, value_range, label in zip(axes[0], images, titles, cmaps, symmetric, ranges,
                                                             labels):
        vmin, vmax = _value_range([im], sym) if value_range is None else value_range
        handle = ax.imshow(im, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        if colorbar:
            fig.colorbar(handle, ax=ax, fraction=0.035, pad=0.02).set_label(label, fontsize=8)
    fig.tight_layout()
    return fig


def plot_image_table(rows: Sequence[Sequence[ArrayLike]], row_labels: Sequence[str], column_titles: Sequence[str],
                     colorbar_labels: Sequence[str], cmaps: Sequence[str] | str = "gray",
                     vranges: Sequence[tuple[float, float] | None] | None = None,
                     log_scale: Sequence[bool] | bool = False, width_in: float = 3.4) -> "Figure":
    """Return a grid of images, one row per case and one column per quantity, each column on one colour range.

    Every column shows one quantity (e.g. an APS frame, a render, an event-count image) for every row, with one
    colour bar under the column, so that the rows can be compared by eye.

    Args:
        rows: R rows of C (H, W) arrays each.
        row_labels: R labels, written left of each row.
        column_titles: C titles, above the top row.
        colorbar_labels: C colour-bar labels (the quantity and its unit).
        cmaps: one colour map for all columns or one per column.
        vranges: per column (vmin, vmax), or None for the min..max over the column (positive values only when the
            column is on a log scale); None for all columns.
        log_scale: per column (or for all): a logarithmic colour scale (for values spanning decades, e.g. depth).
        width_in: width of each panel in inches.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_image_table([[np.zeros((4, 5)), np.ones((4, 5))], [np.eye(4, 5), 3 * np.ones((4, 5))]],
    ...                        ["calm", "fast"], ["a", "b"], ["a [1]", "b [1]"])
    >>> fig.axes[1].images[0].get_clim(), fig.axes[3].images[0].get_clim()
    ((1.0, 3.0), (1.0, 3.0))
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize

    grid = [[np.asarray(im) for im in row] for row in rows]
    n_rows = len(grid)
    n_cols = len(grid[0]) if n_rows else 0
    if n_rows == 0 or n_cols == 0 or any(len(row) != n_cols for row in grid):
        raise ValueError(f"rows must be a non-empty list of equally long, non-empty lists of images; got row lengths "
                         f"{[len(row) for row in grid]}")
    for r, row in enumerate(grid):
        for c, im in enumerate(row):
            if im.ndim != 2:
                raise ValueError(f"rows[{r}][{c}] must have shape (H, W); got {im.shape}")
    if len(row_labels) != n_rows or len(column_titles) != n_cols or len(colorbar_labels) != n_cols:
        raise ValueError(f"need {n_rows} row_labels and {n_cols} column_titles and colorbar_labels; got "
                         f"{len(row_labels)}, {len(column_titles)} and {len(colorbar_labels)}")
    cmaps = _per_image(cmaps, n_cols, "cmaps", lambda v: isinstance(v, str))
    logs = _per_image(log_scale, n_cols, "log_scale", lambda v: isinstance(v, (bool, np.bool_)))
    ranges = [None] * n_cols if vranges is None else _per_image(vranges, n_cols, "vranges", lambda v: False)
    aspect = grid[0][0].shape[0] / grid[0][0].shape[1]
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(width_in * n_cols, (width_in * aspect + 0.3) * n_rows + 0.9),
                             squeeze=False)
    for c in range(n_cols):
        column = [grid[r][c] for r in range(n_rows)]
        if ranges[c] is not None:
            vmin, vmax = ranges[c]
        elif logs[c]:
            positive = [im[im > 0] for im in column]
            vmin, vmax = _value_range([p for p in positive if p.size] or [np.ones(1)])
        else:
            vmin, vmax = _value_range(column)
        norm = LogNorm(vmin, vmax) if logs[c] else Normalize(vmin, vmax)
        for r in range(n_rows):
            handle = axes[r, c].imshow(grid[r][c], cmap=cmaps[c], norm=norm, interpolation="nearest")
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
        axes[0, c].set_title(column_titles[c], fontsize=9)
        fig.colorbar(handle, ax=list(axes[:, c]), orientation="horizontal", fraction=0.05, pad=0.03,
                     aspect=25).set_label(colorbar_labels[c], fontsize=8)
    for r in range(n_rows):
        axes[r, 0].set_ylabel(row_labels[r], fontsize=9)
    return fig


def plot_sample_intervals(sample_times: ArrayLike, speed_t: ArrayLike | None = None, speed: ArrayLike | None = None,
                          speed_label: str = "image speed [px/s]") -> "Figure":
    """Return a figure of adaptive sampling: the interval between consecutive renders against time (log scale),
    optionally with a motion measure (e.g. image speed) on a second axis.

    Args:
        sample_times: (S,) increasing render times [s] (e.g. the second output of ``simulate_events``).
        speed_t: optional (K,) times of the motion measure.
        speed: optional (K,) motion measure.
        speed_label: axis label of the motion measure.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> len(plot_sample_intervals([0.0, 0.1, 0.15, 0.17]).axes)
    1
    """
    import matplotlib.pyplot as plt

    ts = np.asarray(sample_times, dtype=np.float64)
    if ts.ndim != 1 or ts.size < 2 or np.any(np.diff(ts) <= 0):
        raise ValueError(f"sample_times must be a strictly increasing (S,) array with S >= 2; got shape {ts.shape}")
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ax.semilogy(ts[1:], np.diff(ts) * 1e3, ".", ms=3, color="k", label="render interval")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("interval between renders [ms]")
    if speed is not None:
        if speed_t is None:
            raise ValueError("speed_t must be given with speed")
        ax2 = ax.twinx()
        ax2.plot(np.asarray(speed_t), np.asarray(speed), color="tab:orange", lw=1.5, label="image speed (right axis)")
        ax2.set_ylabel(speed_label, color="tab:orange")
        handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
        ax.legend(handles=handles, loc="upper right", fontsize=8)
    ax.set_title(f"adaptive sampling: {ts.size} renders")
    fig.tight_layout()
    return fig


def plot_event_cloud(events: np.ndarray, max_points: int = 20000, title: str = "events in space-time") -> "Figure":
    """Return a 3-D scatter plot of events (x, t, y), ON red and OFF blue (with a legend), thinned to at most
    ``max_points``.

    Thinning keeps every k-th event (deterministic). Time runs along the depth axis, in milliseconds from the first
    event; image rows grow downwards as in an image.

    Args:
        events: (N,) event array (EVENT_DTYPE), N >= 1.
        max_points: upper bound of the points drawn (>= 1).
        title: figure title.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> from evio_lib.events.array import make_events
    >>> len(plot_event_cloud(make_events([0.0, 0.001], [3, 4], [5, 6], [1, -1])).axes)
    1
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    _check_events(events)
    if events.size == 0:
        raise ValueError("events must hold at least one event; got an empty array")
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)) or max_points < 1:
        raise ValueError(f"max_points must be an int >= 1; got {max_points!r}")
    stride = int(np.ceil(events.size / max_points))
    ev = events[::stride]
    t_ms = (ev["t"] - events["t"][0]) * 1e3
    fig = plt.figure(figsize=(8, 6))
    ax = fig.add_subplot(projection="3d")
    colours = np.where(ev["p"] > 0, _ON_COLOUR, _OFF_COLOUR)
    ax.scatter(ev["x"], t_ms, ev["y"], c=colours, s=2.0, alpha=0.6, depthshade=False, linewidths=0)
    ax.set_xlabel("x [px]")
    ax.set_ylabel("t [ms]")
    ax.set_zlabel("y [px]")
    ax.invert_zaxis()
    ax.view_init(elev=15, azim=-60)
    handles = [Line2D([], [], ls="", marker="o", ms=4, color=colour, label=label)
               for colour, label in ((_ON_COLOUR, "ON event (p = +1)"), (_OFF_COLOUR, "OFF event (p = -1)"))]
    ax.legend(handles=handles, loc="upper left", fontsize=8)
    shown = "all shown" if stride == 1 else f"every {stride}th shown"
    ax.set_title(f"{title} ({events.size} events, {shown})", fontsize=10)
    return fig


def plot_imu_vs_truth(t: ArrayLike, gyro: ArrayLike, gyro_true: ArrayLike, accel: ArrayLike, accel_true: ArrayLike
                      ) -> "Figure":
    """Return a 2 x 3 figure: measured gyro / accelerometer axes (thin) over their noise-free truths (thick, grey).

    Args:
        t: (N,) sample times [s].
        gyro: (N, 3) measured angular rate [rad/s]; gyro_true: (N, 3) true w_I.
        accel: (N, 3) measured specific force [m/s^2]; accel_true: (N, 3) true R_GtoI (a_IinG - g_G).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> z = np.zeros((3, 3))
    >>> len(plot_imu_vs_truth([0.0, 0.1, 0.2], z, z, z, z).axes)
    6
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    arrays = {"gyro": gyro, "gyro_true": gyro_true, "accel": accel, "accel_true": accel_true}
    arrays = {k: np.asarray(v, dtype=np.float64) for k, v in arrays.items()}
    for name, value in arrays.items():
        if value.shape != (t.shape[0], 3):
            raise ValueError(f"{name} must have shape (N, 3) = ({t.shape[0]}, 3) like t; got {value.shape}")
    fig, axes = plt.subplots(2, 3, figsize=(12, 5), sharex=True)
    rows = (("gyro", "gyro_true", "gyro {} [rad/s]"), ("accel", "accel_true", "accel {} [m/s²]"))
    for row, (meas, true, label) in enumerate(rows):
        for k, axis in enumerate("xyz"):
            ax = axes[row, k]
            ax.plot(t, arrays[true][:, k], color="0.6", lw=3.0, label="ground truth")
            ax.plot(t, arrays[meas][:, k], color="tab:orange", lw=0.6, label="measured")
            ax.set_ylabel(label.format(axis))
            if row == 1:
                ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_event_rates(rates: Mapping[str, tuple[ArrayLike, ArrayLike]],
                     motion: Mapping[str, tuple[ArrayLike, ArrayLike]] | None = None,
                     motion_label: str = "angular speed |w| [rad/s]", shared_axes: bool = True) -> "Figure":
    """Return a figure with one panel per sequence: its event rate over time, and optionally a motion measure.

    Args:
        rates: name -> (bin centres [s], events per second), e.g. from :func:`event_rate`.
        motion: optional name -> (times [s], values) drawn on a second axis of the same panel.
        motion_label: label of that second axis.
        shared_axes: every panel on the same rate axis (and the same motion axis), so that the sequences can be
            compared by eye.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_event_rates({"a": ([0.0, 1.0], [10.0, 20.0]), "b": ([0.0, 1.0], [1e6, 2e6])},
    ...                        {"a": ([0.0, 1.0], [0.1, 0.2]), "b": ([0.0, 1.0], [1.0, 2.0])})
    >>> len(fig.axes), fig.axes[0].get_ylim() == fig.axes[1].get_ylim()
    (4, True)
    """
    import matplotlib.pyplot as plt

    if not rates:
        raise ValueError("rates must hold at least one (name -> (times, rate)) entry; got none")
    fig, axes = plt.subplots(len(rates), 1, figsize=(9, 2.8 * len(rates)), squeeze=False, sharey=shared_axes)
    motion_axes = []
    for ax, (name, (t, rate)) in zip(axes[:, 0], rates.items()):
        ax.plot(np.asarray(t), np.asarray(rate) / 1e6, color="k", lw=1.2, label="event rate (left axis)")
        ax.set_ylabel("events [Mev/s]")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("time [s]")
        handles = ax.get_legend_handles_labels()[0]
        if motion is not None and name in motion:
            tm, value = motion[name]
            ax2 = ax.twinx()
            if shared_axes and motion_axes:
                ax2.sharey(motion_axes[0])
            motion_axes.append(ax2)
            ax2.plot(np.asarray(tm), np.asarray(value), color="tab:orange", lw=1.0,
                     label=f"{motion_label.split(' [')[0]} (right axis)")
            ax2.set_ylabel(motion_label, color="tab:orange")
            handles += ax2.get_legend_handles_labels()[0]
        ax.legend(handles=handles, loc="upper left", fontsize=8)
    fig.tight_layout()
    return fig
