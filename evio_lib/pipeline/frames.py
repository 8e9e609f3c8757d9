"""The pipeline's frame sources: APS frames as recorded, frames reconstructed from events (thesis §4.1), or
motion-compensated event frames (Rebecq et al. 2017).

Event frames follow the thesis: the stream is cut into windows of N_e = n H W events (Eq. 87; n = 0.7 for the
textured boxes, 0.2 for the sparse aerial scene) or into adaptive windows (a window closes when it holds
``events_per_active_pixel`` events per pixel that fired), each window is fed to a reconstructor
(:func:`evio_lib.events.create_reconstructor`: the shipped FireNet by default) with its recurrent state carried, and
the frame's time is the window's last event (for time-bounded windows, the window's end). The frames come one at
a time (a generator), so a long recording never holds all its frames in memory. A stretch without events yields
no frame: the filter then propagates the IMU alone across it. Windows may also be held between a least and a
greatest duration (``min_window_s``, ``max_window_s``), so that fast motion does not flood the front-end and a slow
stretch still gives frames.

Motion-compensated event frames (``mc-events``, :func:`mc_event_frames`) need no network: each window's events are
warped to its middle time with the gyroscope's rotation and counted (:mod:`evio_lib.events.motion_compensation`),
which keeps edges sharp at any rotation speed for a few milliseconds per frame.
"""
from __future__ import annotations

import time
from typing import Callable, Iterator

import numpy as np

from evio_lib.events.reconstruct import Reconstructor, create_reconstructor
from evio_lib.io.event_source import EventSource
from evio_lib.events.representations import MAX_EVENT_FRAME_RATE_HZ  # re-exported here
from evio_lib.sequence import Sequence

__all__ = ["FRAME_SOURCES", "MAX_EVENT_FRAME_RATE_HZ", "MC_MAX_WINDOW_S", "MC_MIN_EVENTS", "MC_MIN_WINDOW_S",
           "MC_WINDOW_FRACTION", "STREAM_ID_OFFSET", "THESIS_WINDOW_FRACTION", "aps_frames", "default_window_fraction",
           "event_frames", "frame_streams", "mc_event_frames"]

FRAME_SOURCES = ("aps", "events", "mc-events", "aps+events", "aps+mc-events")
#: A source "a+b" feeds two frame streams into one run (:func:`frame_streams` splits it): each has its own tracker,
#: and the filter fuses their tracks, as Ultimate SLAM fuses standard frames and event frames.
STREAM_ID_OFFSET = 1 << 40
#: mc-events: the shortest and the longest window, s (at most 1 / MC_MIN_WINDOW_S frames per second in fast motion,
#: at least 1 / MC_MAX_WINDOW_S while the camera moves slowly), and the fewest events that make a frame. A longer
#: shortest window cost accuracy (the translation, which the gyroscope cannot undo, blurs a long window;
#: docs/archive.md, the motion-compensated frame settings row).
MC_MIN_WINDOW_S = 0.01
MC_MAX_WINDOW_S = 0.1
#: mc-events: n of the windows' N_e = n H W, one value for every recording (the thesis's n per scene serves the
#: reconstructed frames). Chosen on a validation seed of both whole presets with KLT, against the thesis's 0.7 and
#: 0.2 and other window bounds (docs/archive.md, the motion-compensated frame settings row, has the whole search).
MC_WINDOW_FRACTION = 1.0
MC_MIN_EVENTS = 500
#: The thesis's n (§4.1, Figs. 16/18): 0.7 for boxes_like, 0.2 for aerial_like.
THESIS_WINDOW_FRACTION = {"boxes_like": 0.7, "aerial_like": 0.2}


def frame_streams(frames: str) -> tuple[str, ...]:
    """Return the single sources of a frame source: ('aps',) for 'aps', ('aps', 'mc-events') for 'aps+mc-events'.

    >>> frame_streams("aps+mc-events")
    ('aps', 'mc-events')
    """
    if frames not in FRAME_SOURCES:
        raise ValueError(f"frames must be one of {FRAME_SOURCES}; got {frames!r}")
    return tuple(frames.split("+"))


def default_window_fraction(sequence_name: str) -> float:
    """Return the thesis's n for a preset recording (by name prefix), else 0.5 (between the two)."""
    for preset, n in THESIS_WINDOW_FRACTION.items():
        if sequence_name.startswith(preset):
            return n
    return 0.5


def aps_frames(sequence: Sequence, t_start: float = -np.inf, t_end: float = np.inf
               ) -> Iterator[tuple[float, np.ndarray, float]]:
    """Yield (t, uint8 image, 0.0 s of reconstruction) for each APS frame with t_start <= t <= t_end."""
    for t, image in zip(sequence.frame_times, sequence.frames):
        if t_start <= t <= t_end:
            yield float(t), image, 0.0


def _event_windows(sequence: Sequence, window_fraction: float | None, adaptive: bool, min_window_s: float,
                   max_window_s: float | None, t_start: float, t_end: float
                   ) -> tuple[EventSource, np.ndarray, np.ndarray, np.ndarray]:
    """Return (the events as a source, bounds (K, 2) into it, start_times (K,), end_times (K,)): an event stream's
    windows over [t_start, t_end).

    Fixed windows hold N_e = n H W events (held between ``min_window_s`` and ``max_window_s`` when given:
    :func:`~evio_lib.events.representations.bounded_count_windows`); adaptive ones follow the texture. A count window
    starts at its first event and ends at its last; bounded windows start where the previous one ended. Events in
    memory are cut by the functions of :mod:`evio_lib.events.representations`; events on disk (a recording read from
    a ROS bag or an HDF5 file, :mod:`evio_lib.io.event_source`) by their block-at-a-time twins, which give the same
    bounds while holding one block of timestamps."""
    from evio_lib.events.representations import (MAX_WINDOWS, adaptive_windows, bounded_count_windows,
                                                 count_windows, window_size_from_fraction)
    from evio_lib.io.event_source import (ArrayEventSource, adaptive_windows_source, bounded_count_windows_source,
                                          count_windows_source, event_source)

    if sequence.camera is None:
        raise ValueError("event frames need the camera's size: the recording has no calibration")
    width, height = sequence.camera.width, sequence.camera.height
    source = event_source(sequence.events)
    in_memory = isinstance(source, ArrayEventSource)
    lo, hi = source.index_at(t_start), source.index_at(t_end)
    events = source.events[lo:hi] if in_memory else None  # the in-memory path: the arrays as before
    size = hi - lo

    def time_of(index: int) -> float:  # time of the index-th event of [lo, hi)
        return float(events["t"][index]) if in_memory else source.time_at(lo + index)

    def times_of(indices: np.ndarray) -> np.ndarray:
        if in_memory:
            return events["t"][indices]
        return np.array([source.time_at(lo + int(i)) for i in indices], dtype=np.float64)

    n = default_window_fraction(sequence.name) if window_fraction is None else float(window_fraction)
    if not np.isfinite(n) or n <= 0:
        raise ValueError(f"window_fraction must be a number > 0 (thesis: 0.2-0.7); got {window_fraction!r}")
    if adaptive:
        bounds = (adaptive_windows(events, width, height) if in_memory
                  else adaptive_windows_source(source, lo, hi, width, height) - lo)
        bounds = np.asarray(bounds, dtype=np.int64).reshape(-1, 2)
        return source, bounds + lo, times_of(bounds[:, 0]), times_of(bounds[:, 1] - 1)
    per_window = window_size_from_fraction(n, width, height)
    span = time_of(size - 1) - time_of(0) if size > 1 else 0.0
    if min_window_s > 0 or max_window_s is not None:
        first = float(t_start) if np.isfinite(t_start) else (time_of(0) if size else 0.0)
        last = float(t_end) if np.isfinite(t_end) else (time_of(size - 1) if size else first)
        if in_memory:
            bounds, ends = bounded_count_windows(events, per_window, min_window_s, max_window_s, t_start=first,
                                                 t_end=last)
        else:
            bounds, ends = bounded_count_windows_source(source, lo, hi, per_window, min_window_s, max_window_s,
                                                        t_start=first, t_end=last)
            bounds = bounds - lo
        return source, bounds + lo, np.concatenate([[first], ends[:-1]]), ends
    # estimated before the reconstructor loads: a window per event would never end
    if 0 < size < per_window:  # not one frame: say why, not "no events"
        raise ValueError(f"the {size:,} events in [{time_of(0):.3f}, {time_of(size - 1):.3f}] s are fewer "
                         f"than one window of N_e = n H W = {per_window:,} events (window_fraction "
                         f"(--window-fraction) n = {n:g}, {width} x {height} px); use n <= "
                         f"{size / (width * height):.3g}, adaptive windows (--adaptive), a time cap "
                         f"(--max-window) or APS frames")
    most = min(MAX_WINDOWS, max(1.0, MAX_EVENT_FRAME_RATE_HZ * span))
    if size / per_window > most:
        raise ValueError(f"window_fraction (--window-fraction) {n:g} gives about {size / per_window:.3g} "
                         f"windows of {per_window:,} event(s) (n H W = {n * width * height:.3g}) for "
                         f"{size:,} events over {span:.3g} s; the most is {most:,.0f} (MAX_WINDOWS "
                         f"{MAX_WINDOWS:,}, MAX_EVENT_FRAME_RATE_HZ {MAX_EVENT_FRAME_RATE_HZ:g} per second; use n >= "
                         f"{size / (most * width * height):.3g})")
    bounds = count_windows(events, per_window) if in_memory else count_windows_source(source, lo, hi, per_window) - lo
    return source, bounds + lo, times_of(bounds[:, 0]), times_of(bounds[:, 1] - 1)


def event_frames(sequence: Sequence, reconstructor: str | Reconstructor = "firenet",
                 window_fraction: float | None = None,
                 adaptive: bool = False, t_start: float = -np.inf, t_end: float = np.inf, threads: int | None = 1,
                 min_window_s: float = 0.0, max_window_s: float | None = None,
                 **reconstructor_options) -> Iterator[tuple[float, np.ndarray, float]]:
    """Yield (t, float32 image in [0, 1], seconds spent reconstructing it) for each event window in [t_start, t_end].

    Args:
        sequence: a recording with events and a camera (its width x height).
        reconstructor: a name of :func:`evio_lib.events.reconstruct.create_reconstructor` ('firenet', 'high_pass',
            'direct', or 'learned' with ``checkpoint=PATH`` in ``reconstructor_options``), or a reconstructor already
            made for the sequence's sensor (then ``threads`` and ``reconstructor_options`` must be left out: it
            was made with its own). It is reset when the first frame is asked for, and it carries one stream's
            state: two generators must not share one while both are read.
        window_fraction: n of N_e = n H W (default: the thesis's n for the preset, :func:`default_window_fraction`).
        adaptive: adaptive windows (2 events per active pixel) instead of fixed N_e.
        t_start, t_end: only events in this span are used; the recurrent state starts empty at t_start.
        threads: torch threads of a learned reconstructor (None: torch's default).
        min_window_s, max_window_s: time bounds of the fixed windows (0 and None: none); a window capped at
            ``max_window_s`` may hold few events (a frame at least every ``max_window_s`` in a still stretch).
    """
    width, height = sequence.camera.width, sequence.camera.height
    if isinstance(reconstructor, Reconstructor):
        given = ([f"threads={threads!r}"] if threads != 1 else []) + sorted(reconstructor_options)
        if given:
            raise ValueError("event_frames: a reconstructor already made takes no threads or reconstructor options "
                             f"(make it with them instead); got {', '.join(given)}")
        if (reconstructor.width, reconstructor.height) != (width, height):
            raise ValueError(f"event_frames: the reconstructor was made for a {reconstructor.width}x"
                             f"{reconstructor.height} sensor; the sequence's camera is {width}x{height}")
    source, bounds, _, ends = _event_windows(sequence, window_fraction, adaptive, min_window_s, max_window_s, t_start,
                                             t_end)
    if isinstance(reconstructor, Reconstructor):
        rec = reconstructor
    else:
        options = dict(reconstructor_options)
        if reconstructor not in ("direct", "high_pass") and threads is not None:
            options.setdefault("threads", threads)
        rec = create_reconstructor(reconstructor, width, height, **options)
    rec.reset()
    for (a, b), t in zip(bounds, ends):
        if b <= a:
            continue
        start = time.perf_counter()
        image = rec.reconstruct(source.take(a, b))
        yield float(t), image, time.perf_counter() - start


def mc_event_frames(sequence: Sequence, R_CtoI: np.ndarray, window_fraction: float | None = None,
                    adaptive: bool = False, t_start: float = -np.inf, t_end: float = np.inf,
                    min_window_s: float = MC_MIN_WINDOW_S, max_window_s: float | None = MC_MAX_WINDOW_S,
                    gyro_bias: Callable[[], np.ndarray] | None = None, blur_sigma_px: float = 0.75
                    ) -> Iterator[tuple[float, np.ndarray, float]]:
    """Yield (t, float32 image in [0, 1], seconds spent making it): motion-compensated event frames.

    Each window's events are warped to the window's middle time with the gyroscope's rotation and counted
    (:func:`evio_lib.events.motion_compensation.motion_compensated_frame`); that middle time is the frame's time.
    The windows hold N_e = n H W events (n = :data:`MC_WINDOW_FRACTION` by default, for every recording), held
    between ``min_window_s`` and ``max_window_s`` (defaults :data:`MC_MIN_WINDOW_S`, :data:`MC_MAX_WINDOW_S`).
    A window with fewer than :data:`MC_MIN_EVENTS` events (a still stretch) gives no frame.

    Args:
        sequence: a recording with events, an IMU and a camera.
        R_CtoI: (3, 3) camera-to-IMU rotation.
        gyro_bias: called before each frame for the gyro bias to remove (the filter's current estimate); None: 0.
        window_fraction, adaptive, t_start, t_end, min_window_s, max_window_s: as :func:`event_frames`.
        blur_sigma_px: the Gaussian blur of the counted frame.
    """
    from evio_lib.events.motion_compensation import motion_compensated_frame

    n = MC_WINDOW_FRACTION if window_fraction is None else window_fraction
    source, bounds, starts, ends = _event_windows(sequence, n, adaptive, min_window_s, max_window_s, t_start, t_end)
    imu = sequence.imu
    for (a, b), t0, t1 in zip(bounds, starts, ends):
        if b - a < MC_MIN_EVENTS:
            continue
        start = time.perf_counter()
        t_ref = 0.5 * (float(t0) + float(t1))
        bias = None if gyro_bias is None else gyro_bias()
        image = motion_compensated_frame(source.take(a, b), sequence.camera, t_ref, imu.t, imu.gyro, R_CtoI, bias,
                                         blur_sigma_px=blur_sigma_px)
        yield t_ref, image, time.perf_counter() - start
