"""The event array: one structured NumPy array per event stream, and small helpers around it.

An event camera pixel reports a change of its log intensity as a tuple (t, x, y, p) (thesis §2.2.1):
``t`` the timestamp in seconds (float64), ``x``/``y`` the pixel column/row, ``p`` the polarity
(+1 brighter, -1 darker). A stream of events is one array of dtype :data:`EVENT_DTYPE`, sorted by ``t``.

Every function here leaves its inputs untouched.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = [
    "EVENT_DTYPE",
    "make_events",
    "validate_events",
    "empty_events",
    "events_between",
    "concatenate_events",
    "event_count_image",
]

#: Layout of one event: time [s], pixel column, pixel row, polarity (+1/-1). Packed, 13 bytes.
EVENT_DTYPE = np.dtype([("t", "<f8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])

_UINT16_MAX = np.iinfo(np.uint16).max


def _as_1d(name: str, values: object) -> np.ndarray:
    """Return ``values`` as a 1-D array, or raise ValueError naming ``name``."""
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of shape (N,); got shape {arr.shape}")
    return arr


def _first_unsorted(t: np.ndarray) -> tuple[int, int]:
    """Return (how many timestamps are smaller than their predecessor, index of the first one)."""
    bad = np.flatnonzero(t[1:] < t[:-1]) + 1
    return bad.size, (int(bad[0]) if bad.size else -1)


def _check_pixel_coordinate(name: str, values: np.ndarray) -> np.ndarray:
    """Return integer-valued pixel coordinates as uint16, or raise ValueError naming ``name``."""
    if values.dtype == np.bool_ or not np.issubdtype(values.dtype, np.number):
        raise ValueError(f"{name} must hold non-negative integers; got dtype {values.dtype}")
    if np.issubdtype(values.dtype, np.floating):
        integral = np.isfinite(values) & (values == np.round(values))
        if not integral.all():
            i = int(np.flatnonzero(~integral)[0])
            raise ValueError(f"{name} must hold integers; got non-integer value {values[i].item()!r} at index {i}")
    out_of_range = (values < 0) | (values > _UINT16_MAX)
    if out_of_range.any():
        i = int(np.flatnonzero(out_of_range)[0])
        raise ValueError(
            f"{name} must be integers in [0, {_UINT16_MAX}] (uint16); "
            f"{int(out_of_range.sum())} values out of range, first at index {i} ({name}={values[i].item()!r})"
        )
    return values.astype(np.uint16)


def make_events(t: object, x: object, y: object, p: object) -> np.ndarray:
    """Return a new event array of dtype :data:`EVENT_DTYPE` built from four equally long 1-D sequences.

    Args:
        t: (N,) timestamps [s]; finite and sorted non-decreasingly.
        x: (N,) pixel columns, non-negative integers that fit in uint16.
        y: (N,) pixel rows, non-negative integers that fit in uint16.
        p: (N,) polarities, each +1 or -1.

    Raises:
        ValueError: naming the argument and what is wrong (shape, value, order).

    Reference: thesis §2.2.1 (an event is the tuple (t, x, y, p)).

    >>> ev = make_events([0.1, 0.2], [3, 4], [5, 6], [1, -1])
    >>> ev["x"].tolist(), ev["p"].tolist(), ev.dtype == EVENT_DTYPE
    ([3, 4], [1, -1], True)
    """
    t_arr = _as_1d("t", t)
    x_arr, y_arr, p_arr = _as_1d("x", x), _as_1d("y", y), _as_1d("p", p)
    n = t_arr.shape[0]
    for name, arr in (("x", x_arr), ("y", y_arr), ("p", p_arr)):
        if arr.shape[0] != n:
            raise ValueError(f"{name} must have the same length as t ({n}); got length {arr.shape[0]}")
    if not np.issubdtype(t_arr.dtype, np.number) or t_arr.dtype == np.bool_:
        raise ValueError(f"t must hold real timestamps in seconds; got dtype {t_arr.dtype}")
    t_f = t_arr.astype(np.float64)
    finite = np.isfinite(t_f)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"t must be finite; {int((~finite).sum())} non-finite timestamps, first at index {i} (t={t_f[i]})"
        )
    count, first = _first_unsorted(t_f)
    if count:
        raise ValueError(
            f"t must be sorted by time (non-decreasing); found {count} out-of-order timestamps "
            f"starting at index {first}"
        )
    x_u = _check_pixel_coordinate("x", x_arr)
    y_u = _check_pixel_coordinate("y", y_arr)
    if not np.issubdtype(p_arr.dtype, np.number):
        raise ValueError(f"p must hold polarities +1/-1; got dtype {p_arr.dtype}")
    bad_p = (p_arr != 1) & (p_arr != -1)
    if bad_p.any():
        i = int(np.flatnonzero(bad_p)[0])
        raise ValueError(
            f"p must be +1 or -1; {int(bad_p.sum())} invalid polarities, first at index {i} (p={p_arr[i].item()!r})"
        )
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"] = t_f
    events["x"] = x_u
    events["y"] = y_u
    events["p"] = p_arr.astype(np.int8)
    return events


def validate_events(events: np.ndarray, width: int | None = None, height: int | None = None) -> None:
    """Return None when ``events`` is a valid event array; otherwise raise ValueError naming the problem.

    Checks: dtype exactly :data:`EVENT_DTYPE`, 1-D, finite timestamps sorted non-decreasingly, polarities in
    {-1, +1}, and (when given) ``x`` in [0, width) and ``y`` in [0, height).

    Args:
        events: (N,) event array.
        width: sensor width in pixels, or None to skip the x range check.
        height: sensor height in pixels, or None to skip the y range check.

    >>> validate_events(make_events([0.0, 1.0], [0, 239], [0, 179], [1, -1]), 240, 180)
    >>> validate_events(make_events([0.0], [240], [0], [1]), 240, 180)
    Traceback (most recent call last):
    ...
    ValueError: event x out of range [0, 240): 1 events, first at index 0 (x=240)
    """
    if not isinstance(events, np.ndarray):
        raise ValueError(f"events must be a NumPy array of dtype EVENT_DTYPE; got {type(events).__name__}")
    if events.dtype != EVENT_DTYPE:
        raise ValueError(f"events must have dtype {EVENT_DTYPE}; got {events.dtype}")
    if events.ndim != 1:
        raise ValueError(f"events must be a 1-D array of shape (N,); got shape {events.shape}")
    t = events["t"]
    finite = np.isfinite(t)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"event timestamps must be finite; {int((~finite).sum())} non-finite, first at index {i} (t={t[i]})"
        )
    count, first = _first_unsorted(t)
    if count:
        raise ValueError(
            f"events must be sorted by time; found {count} out-of-order timestamps starting at index {first}"
        )
    p = events["p"]
    bad_p = (p != 1) & (p != -1)
    if bad_p.any():
        i = int(np.flatnonzero(bad_p)[0])
        raise ValueError(
            f"event polarity must be +1 or -1; {int(bad_p.sum())} events invalid, first at index {i} (p={int(p[i])})"
        )
    for axis, size, label in (("x", width, "width"), ("y", height, "height")):
        if size is None:
            continue
        if int(size) <= 0:
            raise ValueError(f"{label} must be a positive number of pixels; got {size}")
        bad = events[axis] >= int(size)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"event {axis} out of range [0, {int(size)}): {int(bad.sum())} events, first at index {i} "
                f"({axis}={int(events[axis][i])})"
            )


def empty_events() -> np.ndarray:
    """Return an event array with no events (shape (0,), dtype :data:`EVENT_DTYPE`).

    >>> empty_events().shape
    (0,)
    """
    return np.empty(0, dtype=EVENT_DTYPE)


def events_between(events: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """Return the events with t0 <= t < t1 (half-open window), found by binary search.

    The result is a view into ``events`` (no copy, O(log N)); copy it before writing to it.

    Args:
        events: (N,) event array sorted by time.
        t0: window start [s], included.
        t1: window end [s], excluded; t1 >= t0.

    >>> ev = make_events([0.0, 0.1, 0.2, 0.3], [0, 1, 2, 3], [0, 0, 0, 0], [1, 1, -1, 1])
    >>> events_between(ev, 0.1, 0.3)["x"].tolist()
    [1, 2]
    """
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE or events.ndim != 1:
        got = events.dtype if isinstance(events, np.ndarray) else type(events).__name__
        raise ValueError(f"events must be a 1-D array of dtype EVENT_DTYPE; got {got}")
    if not (np.isfinite(t0) and np.isfinite(t1)):
        raise ValueError(f"t0 and t1 must be finite; got t0={t0}, t1={t1}")
    if t1 < t0:
        raise ValueError(f"t1 must be >= t0; got t0={t0}, t1={t1}")
    i0, i1 = np.searchsorted(events["t"], [t0, t1], side="left")
    return events[i0:i1]


def concatenate_events(chunks: Sequence[np.ndarray]) -> np.ndarray:
    """Return one time-sorted event array merging all ``chunks`` (stable: ties keep chunk order, then array order).

    Each chunk must itself be sorted by time. When the chunks follow one another in time they are simply
    concatenated; otherwise they are merged with a stable sort on the timestamps.

    Args:
        chunks: sequence of (N_i,) event arrays of dtype :data:`EVENT_DTYPE`.

    >>> a = make_events([0.0, 0.2], [0, 0], [0, 0], [1, 1])
    >>> b = make_events([0.1, 0.2], [1, 1], [0, 0], [-1, -1])
    >>> m = concatenate_events([a, b])
    >>> m["t"].tolist(), m["x"].tolist()
    ([0.0, 0.1, 0.2, 0.2], [0, 1, 0, 1])
    """
    if isinstance(chunks, np.ndarray):
        raise ValueError("chunks must be a sequence (list/tuple) of event arrays; got a single array")
    chunks = list(chunks)
    for i, c in enumerate(chunks):
        if not isinstance(c, np.ndarray) or c.dtype != EVENT_DTYPE or c.ndim != 1:
            got = c.dtype if isinstance(c, np.ndarray) else type(c).__name__
            raise ValueError(f"chunks[{i}] must be a 1-D array of dtype EVENT_DTYPE; got {got}")
        count, first = _first_unsorted(c["t"])
        if count:
            raise ValueError(
                f"chunks[{i}] must be sorted by time; found {count} out-of-order timestamps starting at index {first}"
            )
    non_empty = [c for c in chunks if c.size]
    if not non_empty:
        return empty_events()
    merged = np.concatenate(non_empty)
    in_order = all(a["t"][-1] <= b["t"][0] for a, b in zip(non_empty[:-1], non_empty[1:]))
    if in_order:
        return merged
    return merged[np.argsort(merged["t"], kind="stable")]


def event_count_image(events: np.ndarray, width: int, height: int, signed: bool = False) -> np.ndarray:
    """Return an (H, W) int64 image counting events per pixel (or summing polarities when ``signed``).

    Args:
        events: (N,) event array with x in [0, width) and y in [0, height).
        width: image width W in pixels.
        height: image height H in pixels.
        signed: False counts all events; True sums their polarities (+1/-1).

    >>> ev = make_events([0.0, 0.1, 0.2], [1, 1, 0], [0, 0, 1], [1, 1, -1])
    >>> event_count_image(ev, 2, 2).tolist()
    [[0, 2], [1, 0]]
    >>> event_count_image(ev, 2, 2, signed=True).tolist()
    [[0, 2], [-1, 0]]
    """
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE or events.ndim != 1:
        got = events.dtype if isinstance(events, np.ndarray) else type(events).__name__
        raise ValueError(f"events must be a 1-D array of dtype EVENT_DTYPE; got {got}")
    width, height = int(width), int(height)
    if width <= 0 or height <= 0:
        raise ValueError(f"width and height must be positive; got width={width}, height={height}")
    x = events["x"].astype(np.int64)
    y = events["y"].astype(np.int64)
    for name, v, size in (("x", x, width), ("y", y, height)):
        bad = v >= size
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"event {name} out of range [0, {size}): {int(bad.sum())} events, first at index {i} ({name}={v[i]})"
            )
    flat = y * width + x  # row-major pixel index
    if signed:
        p = events["p"].astype(np.int64)
        counts = np.bincount(flat[p > 0], minlength=width * height) - np.bincount(flat[p < 0], minlength=width * height)
    else:
        counts = np.bincount(flat, minlength=width * height)
    return counts.astype(np.int64).reshape(height, width)
