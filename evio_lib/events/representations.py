"""Event representations: cutting the stream into windows, and turning a window into an image-like tensor.

Windows (thesis §4.1, Eq. 87). A reconstruction step consumes one window of events. Three ways to cut the stream:

- by count: N_e = n * H * W events per window, with the fraction n in (0, 1] (the thesis's choice: n = 0.7 for the textured
  boxes, n = 0.2 for the sparse aerial flight),
- by time: a fixed duration per window,
- by count within time bounds (:func:`bounded_count_windows`): N_e events, but never shorter than a least duration
  (at most so many frames per second in fast motion) nor longer than a greatest one (at least so many frames per
  second when the scene is nearly still),
- adaptive (the thesis's future-work item): a window closes once its events reach ``events_per_active_pixel`` per pixel
  that fired in it. A textured scene lights up many pixels for a given motion, a sparse one few, so the same rule gives a
  large N_e on the boxes and a small one over the airfield, i.e. n follows the scene's texture instead of being tuned by
  hand per dataset. (Events per active pixel is about |displacement . grad L| / C per pixel: it measures how far edges
  moved, in units of the contrast threshold C, whatever the texture density.)

Representations of one window (all vectorised with ``np.bincount``; no Python loop over events):

- count frames (events per pixel: ``polarity_frame(..., signed=False)``, float32, or
  :func:`evio_lib.events.array.event_count_image`, int64) and polarity frames (sum of polarities),
- time surfaces: exp(-(t_ref - t_last(x, y)) / tau), per polarity or merged,
- voxel grids (E2VID's input): B temporal bins, each event spread over the two nearest bins with bilinear weights
  t* = (B - 1)(t - t_0)/(t_N - t_0), V[b, y, x] += p * max(0, 1 - |b - t*|), then the non-zero voxels are normalised to zero
  mean and unit standard deviation (E2VID's normalisation; its gather and write-back run in the Numba kernels of
  :mod:`evio_lib.events.voxel_kernels` where they load: the same numbers as NumPy's boolean masks, faster).

Every function leaves its inputs untouched.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from evio_lib.events.array import EVENT_DTYPE

__all__ = [
    "MAX_SENSOR_PIXELS",
    "MAX_EVENT_FRAME_RATE_HZ",
    "MAX_WINDOWS",
    "check_sensor_pixels",
    "window_size_from_fraction",
    "count_windows",
    "time_windows",
    "bounded_count_windows",
    "adaptive_windows",
    "polarity_frame",
    "time_surface",
    "voxel_grid",
    "normalize_voxel_grid",
    "voxel_backend",
    "VOXEL_BACKEND_ENV",
]


#: Environment variable that picks the backend of the voxel grid's normalisation: auto (default), numba or numpy.
VOXEL_BACKEND_ENV = "EVIO_VOXEL_BACKEND"
_VOXEL_KERNEL_PROBLEM: list[str] = []  # "" once the kernels loaded, else why they did not (said once)

#: Largest sensor accepted, in pixels (4096 x 4096 = 16.8 Mpx). The largest event cameras have about 1 Mpx (1280 x 720,
#: 1280 x 960); every representation and reconstructor holds a few float arrays of H x W (64 MiB each at this size), so
#: a mistyped size such as 100000 x 100000 (1e10 px: 40 GB per float32 frame) is refused before any allocation.
MAX_SENSOR_PIXELS = 4096 * 4096

#: Most event frames per second of recording. Each frame goes through the reconstructor (and in ``run`` the
#: front-end: milliseconds per frame on a 2-core CPU, docs/results/speed.md#the-pipeline), so 1000 frames per recorded
#: second already run many times slower than real time, far more frames than the thesis's windows give. A window per
#: event (--window-fraction 1e-9) is refused instead of running for hours.
MAX_EVENT_FRAME_RATE_HZ = 1000.0

#: Most windows one cut of the stream may give. Each window is one reconstruction step (milliseconds with the shipped
#: FireNet at 240 x 180, docs/results/reconstruction.md#speed, so 10^6 windows take hours) and one frame of H x W
#: floats kept or written (173 KB at 240 x 180: 10^6 frames are 173 GB); a window per event (--window-fraction 1e-9,
#: --window-time 1e-9) would never end.
MAX_WINDOWS = 1_000_000


def _too_many_windows(windows: float, what: str, advice: str) -> ValueError:
    """Return the ValueError for a cut into ``windows`` windows (> MAX_WINDOWS), ``what`` saying how it came about."""
    return ValueError(f"{what} gives about {windows:.3g} windows; the most is {MAX_WINDOWS:,} (MAX_WINDOWS){advice}")


def _check_events(events: np.ndarray) -> None:
    """Raise ValueError unless ``events`` is a 1-D array of dtype EVENT_DTYPE."""
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE or events.ndim != 1:
        got = f"dtype {events.dtype}, shape {events.shape}" if isinstance(events, np.ndarray) else type(events).__name__
        raise ValueError(f"events must be a 1-D array of dtype EVENT_DTYPE (see evio_lib.events.array.make_events); got {got}")


def _check_size(width: int, height: int) -> tuple[int, int]:
    """Return (width, height) as positive ints, or raise ValueError."""
    w, h = int(width), int(height)
    if w <= 0 or h <= 0 or w != width or h != height:
        raise ValueError(f"width and height must be positive integers; got width={width}, height={height}")
    check_sensor_pixels(w, h)
    return w, h


def check_sensor_pixels(width: int, height: int, what: str = "the sensor") -> None:
    """Raise ValueError when width x height exceeds :data:`MAX_SENSOR_PIXELS` (``what`` names it in the message).

    >>> check_sensor_pixels(100000, 100000, "--sensor-size 100000 100000")
    Traceback (most recent call last):
    ...
    ValueError: --sensor-size 100000 100000 is 1e+10 pixels; the most is 16,777,216 (4096 x 4096, MAX_SENSOR_PIXELS; event cameras have about 1 Mpx)
    """
    pixels = int(width) * int(height)
    if pixels > MAX_SENSOR_PIXELS:
        raise ValueError(f"{what} is {pixels:.3g} pixels; the most is {MAX_SENSOR_PIXELS:,} (4096 x 4096, "
                         f"MAX_SENSOR_PIXELS; event cameras have about 1 Mpx)")


def _pixel_index(events: np.ndarray, width: int, height: int) -> np.ndarray:
    """Return the row-major pixel index y * W + x of every event (int64), checking the sensor bounds."""
    x = events["x"].astype(np.int64)
    y = events["y"].astype(np.int64)
    if events.size and (x.max() >= width or y.max() >= height):
        bad = np.flatnonzero((x >= width) | (y >= height))
        i = int(bad[0])
        raise ValueError(f"events must lie on the {width}x{height} sensor; {bad.size} events outside, first at index {i} "
                         f"(x={x[i]}, y={y[i]})")
    return y * width + x


def window_size_from_fraction(n: float, width: int, height: int) -> int:
    """Return N_e = round(n * H * W), the events per window for the fraction n (thesis Eq. 87).

    >>> window_size_from_fraction(0.7, 240, 180)
    30240
    """
    w, h = _check_size(width, height)
    if not (np.isfinite(n) and 0 < n <= 10):
        raise ValueError(f"the window fraction n must be in (0, 10] (the thesis uses 0.05-0.7); got {n!r}")
    return max(1, int(round(n * w * h)))


def count_windows(events: np.ndarray, n_events: int) -> np.ndarray:
    """Return (K, 2) index bounds [start, stop) of consecutive windows of ``n_events`` events (last partial one dropped).

    Args:
        events: (N,) event array sorted by time.
        n_events: events per window, N_e >= 1 (see :func:`window_size_from_fraction`).

    >>> from evio_lib.events.array import make_events
    >>> ev = make_events(range(7), [0] * 7, [0] * 7, [1] * 7)
    >>> count_windows(ev, 3).tolist()
    [[0, 3], [3, 6]]
    """
    _check_events(events)
    if int(n_events) != n_events or n_events < 1:
        raise ValueError(f"n_events must be a positive integer; got {n_events!r}")
    if events.size // int(n_events) > MAX_WINDOWS:
        raise _too_many_windows(events.size // int(n_events), f"n_events={int(n_events)} for {events.size} events",
                                f" (use n_events >= {-(-events.size // MAX_WINDOWS)})")
    starts = np.arange(0, events.size - int(n_events) + 1, int(n_events), dtype=np.int64)
    return np.stack([starts, starts + int(n_events)], axis=1) if starts.size else np.zeros((0, 2), np.int64)


def time_windows(events: np.ndarray, duration: float, t_start: float | None = None,
                 t_end: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return (bounds (K, 2) index [start, stop), end_times (K,)) of windows of fixed ``duration`` seconds.

    Window k covers [t_start + k * duration, t_start + (k + 1) * duration); windows may be empty (a still scene).

    Args:
        events: (N,) event array sorted by time.
        duration: window length [s], > 0.
        t_start: start of the first window [s] (default: the first event's time).
        t_end: no window ends after this time [s] (default: the last event's time).

    >>> from evio_lib.events.array import make_events
    >>> ev = make_events([0.0, 0.05, 0.12, 0.31], [0] * 4, [0] * 4, [1] * 4)
    >>> b, t = time_windows(ev, 0.1, t_start=0.0, t_end=0.3)
    >>> b.tolist(), t.round(2).tolist()
    ([[0, 2], [2, 3], [3, 3]], [0.1, 0.2, 0.3])
    """
    _check_events(events)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"the window duration must be a positive number of seconds; got {duration!r}")
    if events.size == 0 and (t_start is None or t_end is None):
        return np.zeros((0, 2), np.int64), np.zeros(0)
    t0 = float(events["t"][0]) if t_start is None else float(t_start)
    t1 = float(events["t"][-1]) if t_end is None else float(t_end)
    windows = (t1 - t0) / duration
    if windows > MAX_WINDOWS:  # before np.arange(n + 1): 1e-9 s over a minute would be 6e10 edges
        raise _too_many_windows(windows, f"a window duration of {duration:g} s over {t1 - t0:g} s",
                                f" (use a duration >= {(t1 - t0) / MAX_WINDOWS:.3g} s)")
    n = int(np.floor(windows + 1e-9))
    if n <= 0:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    edges = t0 + duration * np.arange(n + 1)
    idx = np.searchsorted(events["t"], edges, side="left").astype(np.int64)
    return np.stack([idx[:-1], idx[1:]], axis=1), edges[1:]


def _check_bounded_window_args(n_events: Any, min_duration: float, max_duration: float | None) -> int:
    """Return ``n_events`` as an int, or raise ValueError naming the argument of a bounded count window that is wrong."""
    if isinstance(n_events, bool) or int(n_events) != n_events or n_events < 1:
        raise ValueError(f"n_events must be a positive integer; got {n_events!r}")
    n_events = int(n_events)
    if not (np.isfinite(min_duration) and min_duration >= 0):
        raise ValueError(f"min_duration must be a number of seconds >= 0; got {min_duration!r}")
    if max_duration is not None and not (np.isfinite(max_duration) and max_duration > min_duration):
        raise ValueError(f"max_duration must be None or a number of seconds > min_duration ({min_duration:g}); got "
                         f"{max_duration!r}")
    return n_events


def bounded_count_windows(events: np.ndarray, n_events: int, min_duration: float = 0.0,
                          max_duration: float | None = None, t_start: float | None = None,
                          t_end: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return (bounds (K, 2) index [start, stop), end_times (K,)) of count windows held within time bounds.

    Window k starts where window k - 1 ended (the first at ``t_start``) and closes at the earliest time T with

    - at least ``n_events`` events in it and T - start >= ``min_duration`` (T is then the later of the N_e-th
      event's time and start + ``min_duration``), or
    - T - start = ``max_duration`` (a time cap: the window may hold fewer events, even none, in a still stretch).

    So fast motion gives at most 1 / ``min_duration`` frames per second, slow motion at least 1 / ``max_duration``,
    and in between the windows hold N_e events as :func:`count_windows` cuts them. A window never ends after
    ``t_end``: the last, unfinished one is dropped.

    Args:
        events: (N,) event array sorted by time.
        n_events: N_e >= 1.
        min_duration: least window length [s] (0: none).
        max_duration: greatest window length [s] (None: none), > ``min_duration``.
        t_start, t_end: the span cut into windows [s] (default: the first and the last event's time).

    >>> from evio_lib.events.array import make_events
    >>> ev = make_events([0.0, 0.01, 0.02, 0.03, 0.5, 0.51], [0] * 6, [0] * 6, [1] * 6)
    >>> b, t = bounded_count_windows(ev, 2, max_duration=0.2)
    >>> b.tolist(), t.round(2).tolist()     # two windows of 2 events, two empty ones closed by the cap, 2 events
    ([[0, 2], [2, 4], [4, 4], [4, 4], [4, 6]], [0.01, 0.03, 0.23, 0.43, 0.51])
    >>> bounded_count_windows(ev, 2, min_duration=0.025)[0].tolist()   # the first window must last 25 ms: 3 events
    [[0, 3], [3, 5]]
    """
    _check_events(events)
    n_events = _check_bounded_window_args(n_events, min_duration, max_duration)
    t = np.ascontiguousarray(events["t"])  # searchsorted would copy the strided field at every call
    if events.size == 0 and (t_start is None or t_end is None):
        return np.zeros((0, 2), np.int64), np.zeros(0)
    t0 = float(t[0]) if t_start is None else float(t_start)
    t1 = float(t[-1]) if t_end is None else float(t_end)
    span = max(0.0, t1 - t0)
    most = events.size / n_events + (span / max_duration if max_duration else 0.0)
    if min_duration > 0:
        most = min(most, span / min_duration + 1)
    if most > MAX_WINDOWS:
        raise _too_many_windows(most, f"n_events={n_events} with windows of {min_duration:g}-{max_duration} s over "
                                      f"{events.size} events and {span:g} s", " (use more events or longer windows)")
    a = int(np.searchsorted(t, t0, side="left"))
    start = t0
    bounds, ends = [], []
    while True:
        b = a + n_events
        close = float(t[b - 1]) if b <= events.size else np.inf     # when the N_e-th event arrives
        if close < start + min_duration:                            # too soon: wait for the least duration
            close = start + min_duration
            b = int(np.searchsorted(t, close, side="right"))
        if max_duration is not None and close > start + max_duration:
            close = start + max_duration                            # the time cap
            b = int(np.searchsorted(t, close, side="right"))
        if not close <= t1:
            break
        bounds.append((a, b))
        ends.append(close)
        a, start = b, close
    return np.asarray(bounds, dtype=np.int64).reshape(-1, 2), np.asarray(ends, dtype=np.float64)


def _check_adaptive_args(width: int, height: int, events_per_active_pixel: float, min_fraction: float,
                         max_fraction: float) -> tuple[int, int, int, int]:
    """Return (W, H, n_min, n_max events) of adaptive windows, or raise ValueError naming the argument that is wrong."""
    w, h = _check_size(width, height)
    if not (np.isfinite(events_per_active_pixel) and events_per_active_pixel > 1.0):
        raise ValueError(f"events_per_active_pixel must be > 1 (every active pixel has at least one event); "
                         f"got {events_per_active_pixel!r}")
    if not 0 < min_fraction <= max_fraction:
        raise ValueError(f"need 0 < min_fraction <= max_fraction; got {min_fraction}, {max_fraction}")
    return w, h, window_size_from_fraction(min_fraction, w, h), window_size_from_fraction(max_fraction, w, h)


def _adaptive_window_bounds(pixels: Callable[[int, int], np.ndarray], lo: int, hi: int, n_min: int, n_max: int,
                            events_per_active_pixel: float) -> np.ndarray:
    """Return (K, 2) bounds of the adaptive windows over events [lo, hi); ``pixels(a, b)`` gives the pixel index of
    events [a, b) (from memory or read from disk; at most ``n_max`` events are asked for at a time)."""
    bounds = []
    start = lo
    while hi - start >= n_min:
        chunk = pixels(start, min(hi, start + n_max))
        first = np.zeros(chunk.size, dtype=bool)
        first[np.unique(chunk, return_index=True)[1]] = True     # first event of each pixel in the window
        count = np.arange(1, chunk.size + 1)
        active = np.cumsum(first)
        ratio_reached = np.flatnonzero((count >= n_min) & (count >= events_per_active_pixel * active))
        if ratio_reached.size:
            stop = start + int(ratio_reached[0]) + 1
        elif chunk.size == n_max:
            stop = start + n_max
        else:
            break                                                # the stream ended before the window closed
        bounds.append((start, stop))
        start = stop
    return np.asarray(bounds, dtype=np.int64).reshape(-1, 2)


def adaptive_windows(events: np.ndarray, width: int, height: int, events_per_active_pixel: float = 2.0,
                     min_fraction: float = 0.02, max_fraction: float = 1.5) -> np.ndarray:
    """Return (K, 2) index bounds of windows that close when events / active pixels reaches ``events_per_active_pixel``.

    The number of events a motion produces grows with the scene's texture, and so does the number of pixels that fire:
    their ratio measures how far the edges moved (in contrast thresholds), whatever the texture density. Closing each
    window at a fixed ratio makes N_e large in a textured scene and small in a sparse one (see the module docstring).
    N_e is clipped to [min_fraction, max_fraction] * H * W so that noise alone cannot make windows tiny or endless.
    The loop runs over windows, never over events (each window is found with cumulative sums).

    Args:
        events: (N,) event array sorted by time, on the width x height sensor.
        width: sensor width W [px].
        height: sensor height H [px].
        events_per_active_pixel: the ratio that closes a window (> 1). The default 2.0 was chosen on the course's
            simulated evaluation stretches with an earlier network (bench/adaptive_windows.py), where it matched the
            best fixed n of every stretch (docs/archive.md); with the network the library now uses it trails the best
            fixed n (docs/results/reconstruction.md#adaptive-windows).
        min_fraction: smallest window, as a fraction n of H * W.
        max_fraction: largest window, as a fraction n of H * W.
    """
    _check_events(events)
    w, h, n_min, n_max = _check_adaptive_args(width, height, events_per_active_pixel, min_fraction, max_fraction)
    pix = _pixel_index(events, w, h)
    return _adaptive_window_bounds(lambda a, b: pix[a:b], 0, events.size, n_min, n_max, events_per_active_pixel)


def polarity_frame(events: np.ndarray, width: int, height: int, signed: bool = True) -> np.ndarray:
    """Return an (H, W) float32 frame: the sum of polarities per pixel (``signed``) or the event count.

    >>> from evio_lib.events.array import make_events
    >>> polarity_frame(make_events([0, 1, 2], [1, 1, 0], [0, 0, 1], [1, 1, -1]), 2, 2).tolist()
    [[0.0, 2.0], [-1.0, 0.0]]
    """
    _check_events(events)
    w, h = _check_size(width, height)
    pix = _pixel_index(events, w, h)
    weights = events["p"].astype(np.float64) if signed else None
    return np.bincount(pix, weights=weights, minlength=w * h).astype(np.float32).reshape(h, w)


def time_surface(events: np.ndarray, width: int, height: int, tau: float = 0.03, t_ref: float | None = None,
                 split_polarity: bool = True) -> np.ndarray:
    """Return the exponential time surface exp(-(t_ref - t_last) / tau): (2, H, W) per polarity [ON, OFF], or (H, W).

    Pixels without an event are 0; the most recent event at t_ref gives 1.

    Args:
        events: (N,) event array sorted by time.
        width: sensor width W [px].
        height: sensor height H [px].
        tau: decay time constant [s], > 0.
        t_ref: time the surface is read at [s] (default: the last event's time); must be >= every event's time.
        split_polarity: one channel per polarity (True) or one for all events.

    Reference: Lagorce et al., HOTS (TPAMI 2017), the exponential time surface.

    >>> from evio_lib.events.array import make_events
    >>> ts = time_surface(make_events([0.0, 0.1], [0, 1], [0, 0], [1, -1]), 2, 1, tau=0.1, split_polarity=False)
    >>> [round(float(v), 3) for v in ts[0]]
    [0.368, 1.0]
    """
    _check_events(events)
    w, h = _check_size(width, height)
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"tau must be a positive time constant in seconds; got {tau!r}")
    pix = _pixel_index(events, w, h)
    t = events["t"]
    if t_ref is None:
        t_ref = float(t[-1]) if t.size else 0.0
    if t.size and t_ref < t[-1]:
        raise ValueError(f"t_ref must be >= the last event's time {t[-1]!r}; got {t_ref!r}")
    channels = [events["p"] > 0, events["p"] < 0] if split_polarity else [np.ones(t.size, bool)]
    out = np.zeros((len(channels), h * w), dtype=np.float32)
    for c, mask in enumerate(channels):
        p_idx, t_sel = pix[mask], t[mask]
        # the last event of each pixel: first occurrence in the reversed (time-descending) stream
        uniq, first_rev = np.unique(p_idx[::-1], return_index=True)
        t_last = t_sel[::-1][first_rev]
        out[c, uniq] = np.exp(-(t_ref - t_last) / tau)
    out = out.reshape(len(channels), h, w)
    return out if split_polarity else out[0]


def voxel_grid(events: np.ndarray, width: int, height: int, num_bins: int = 5, normalize: bool = True,
               t_start: float | None = None, t_end: float | None = None) -> np.ndarray:
    """Return the (B, H, W) float32 voxel grid of one window, with bilinear weights in time (E2VID's input).

    t* = (B - 1)(t - t_0) / (t_1 - t_0);  V[b, y, x] += p * max(0, 1 - |b - t*|)  for b in {floor(t*), floor(t*) + 1}.
    With ``normalize`` the non-zero voxels are shifted and scaled to zero mean and unit standard deviation
    (:func:`normalize_voxel_grid`).

    Args:
        events: (N,) event array sorted by time (one window).
        width: sensor width W [px].
        height: sensor height H [px].
        num_bins: B >= 1 temporal bins (E2VID uses 5).
        normalize: apply E2VID's normalisation of the non-zero voxels.
        t_start: time of bin 0 [s] (default: the first event's time).
        t_end: time of bin B - 1 [s] (default: the last event's time).

    Reference: Zhu et al., unsupervised event-based optical flow (CVPR 2019), the voxel grid; Rebecq et al., E2VID
    (TPAMI 2019), its use for reconstruction.

    >>> from evio_lib.events.array import make_events
    >>> v = voxel_grid(make_events([0.0, 0.5, 1.0], [0, 0, 1], [0, 0, 0], [1, 1, -1]), 2, 1, 3, normalize=False)
    >>> v[:, 0, :].tolist()
    [[1.0, 0.0], [1.0, 0.0], [0.0, -1.0]]
    """
    _check_events(events)
    w, h = _check_size(width, height)
    if int(num_bins) != num_bins or num_bins < 1:
        raise ValueError(f"num_bins must be a positive integer; got {num_bins!r}")
    num_bins = int(num_bins)
    pix = _pixel_index(events, w, h)
    hw = h * w
    if events.size == 0:
        return np.zeros((num_bins, h, w), np.float32)
    t = events["t"]
    t0 = float(t[0]) if t_start is None else float(t_start)
    t1 = float(t[-1]) if t_end is None else float(t_end)
    span = t1 - t0
    if span < 0:
        raise ValueError(f"t_end must be >= t_start; got t_start={t0}, t_end={t1}")
    t_star = (t - t0) * ((num_bins - 1) / span) if span > 0 else np.zeros(t.size)
    np.clip(t_star, 0.0, num_bins - 1, out=t_star)
    lower = t_star.astype(np.int64)                    # floor, as t* >= 0
    p = events["p"].astype(np.float64)
    w_upper = p * (t_star - lower)                     # p (t* - b), the share of bin b + 1
    idx = lower * hw + pix
    # both shares in one bincount (each large temporary costs more than the sums: fresh pages); bin B - 1 has no
    # upper neighbour: its share (zero, since t* = B - 1 exactly there) lands in a spare bin
    grid = np.bincount(np.concatenate([idx, idx + hw]), weights=np.concatenate([p - w_upper, w_upper]),
                       minlength=(num_bins + 1) * hw)
    grid = grid[:num_bins * hw].astype(np.float32).reshape(num_bins, h, w)
    return _normalize_in_place(grid) if normalize else grid


def normalize_voxel_grid(grid: np.ndarray) -> np.ndarray:
    """Return a copy of ``grid`` whose non-zero entries have zero mean and unit standard deviation (E2VID).

    Zero voxels (no event) stay zero; a grid with fewer than two non-zero voxels, or with zero spread, is only centred.

    >>> normalize_voxel_grid(np.array([[0.0, 1.0, 3.0]], np.float32)).tolist()
    [[0.0, -1.0, 1.0]]
    """
    return _normalize_in_place(np.array(grid, dtype=np.float32, order="C"))  # C order: the kernels' layout


def _normalize_in_place(grid: np.ndarray) -> np.ndarray:
    """:func:`normalize_voxel_grid` on a float32 ``grid`` it may overwrite; returns it.

    The non-zero values are gathered and written back by the Numba kernels of :mod:`evio_lib.events.voxel_kernels`
    where they load (faster than NumPy's boolean masks, docs/results/speed.md#small-costs-behind-the-codes-choices,
    the same numbers bit for bit), else by NumPy: :func:`voxel_backend`."""
    kernels = voxel_backend() == "numba" and grid.flags.c_contiguous
    if kernels:
        from evio_lib.events import voxel_kernels

        flat = grid.reshape(-1)
        values = voxel_kernels.nonzero_values(flat, np.count_nonzero(flat))
    else:
        nonzero = grid != 0
        values = grid[nonzero]
    if values.size == 0:
        return grid
    mean = float(values.mean())
    std = float(values.std())
    scale = values.size > 1 and std > 0
    if kernels:
        voxel_kernels.write_normalized(flat, np.float32(mean), np.float32(std), scale)
    else:
        grid[nonzero] = (values - mean) / std if scale else values - mean
    return grid


def voxel_backend() -> str:
    """Return the backend of the voxel grid's normalisation: ``"numba"`` or ``"numpy"`` (the same numbers).

    ``EVIO_VOXEL_BACKEND`` = ``numba`` | ``numpy`` | ``auto`` (default: the kernels of
    :mod:`evio_lib.events.voxel_kernels` when they load, else NumPy with one warning saying why)."""
    from evio_lib.compiled import compiled_backend

    return compiled_backend(VOXEL_BACKEND_ENV, "evio_lib.events.voxel_kernels", _VOXEL_KERNEL_PROBLEM,
                            "voxel grids normalised with NumPy (about 1 ms slower per 240 x 180 window, the same grids)")
