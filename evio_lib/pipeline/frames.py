"""The pipeline's frame source: APS frames as recorded, or frames reconstructed from events (thesis §4.1).

Event frames follow the thesis: the stream is cut into windows of N_e = n H W events (Eq. 87; n = 0.7 for the
textured boxes, 0.2 for the sparse aerial scene) or into adaptive windows (a window closes when it holds
``events_per_active_pixel`` events per pixel that fired), each window is fed to a reconstructor
(:func:`evio_lib.events.create_reconstructor`: the shipped FireNet by default) with its recurrent state carried, and
the frame's time is the window's last event. The frames come one at a time (a generator), so a long recording
never holds all its frames in memory. A stretch without events yields no frame: the filter then propagates the IMU
alone across it.
"""
from __future__ import annotations

import time
from typing import Iterator

import numpy as np

from evio_lib.events.representations import MAX_EVENT_FRAME_RATE_HZ  # re-exported here
from evio_lib.sequence import Sequence

__all__ = ["FRAME_SOURCES", "MAX_EVENT_FRAME_RATE_HZ", "THESIS_WINDOW_FRACTION", "aps_frames", "event_frames", "default_window_fraction"]

FRAME_SOURCES = ("aps", "events")
#: The thesis's n (§4.1, Figs. 16/18): 0.7 for boxes_like, 0.2 for aerial_like.
THESIS_WINDOW_FRACTION = {"boxes_like": 0.7, "aerial_like": 0.2}


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


def event_frames(sequence: Sequence, reconstructor: str = "firenet", window_fraction: float | None = None,
                 adaptive: bool = False, t_start: float = -np.inf, t_end: float = np.inf, threads: int | None = 1,
                 **reconstructor_options) -> Iterator[tuple[float, np.ndarray, float]]:
    """Yield (t, float32 image in [0, 1], seconds spent reconstructing it) for each event window in [t_start, t_end].

    Args:
        sequence: a recording with events and a camera (its width x height).
        reconstructor: a name of :func:`evio_lib.events.reconstruct.create_reconstructor` ('firenet', 'high_pass',
            'direct', or 'learned' with ``checkpoint=PATH`` in ``reconstructor_options``).
        window_fraction: n of N_e = n H W (default: the thesis's n for the preset, :func:`default_window_fraction`).
        adaptive: adaptive windows (2 events per active pixel) instead of fixed N_e.
        t_start, t_end: only events in this span are used; the recurrent state starts empty at t_start.
        threads: torch threads of a learned reconstructor (None: torch's default).
    """
    from evio_lib.events.reconstruct import create_reconstructor
    from evio_lib.events.representations import adaptive_windows, count_windows, window_size_from_fraction

    if sequence.camera is None:
        raise ValueError("event frames need the camera's size: the recording has no calibration")
    width, height = sequence.camera.width, sequence.camera.height
    events = sequence.events
    lo, hi = np.searchsorted(events["t"], [t_start, t_end], side="left")
    events = events[lo:hi]
    n = default_window_fraction(sequence.name) if window_fraction is None else float(window_fraction)
    if not np.isfinite(n) or n <= 0:
        raise ValueError(f"window_fraction must be a number > 0 (thesis: 0.2-0.7); got {window_fraction!r}")
    if not adaptive:  # estimated before the reconstructor loads: a window per event would never end
        from evio_lib.events.representations import MAX_WINDOWS

        per_window = window_size_from_fraction(n, width, height)
        if 0 < events.size < per_window:  # not one frame: say why, not "no events"
            raise ValueError(f"the {events.size:,} events in [{events['t'][0]:.3f}, {events['t'][-1]:.3f}] s are fewer "
                             f"than one window of N_e = n H W = {per_window:,} events (window_fraction "
                             f"(--window-fraction) n = {n:g}, {width} x {height} px); use n <= "
                             f"{events.size / (width * height):.3g}, adaptive windows (--adaptive) or APS frames")
        span = float(events["t"][-1] - events["t"][0]) if events.size > 1 else 0.0
        most = min(MAX_WINDOWS, max(1.0, MAX_EVENT_FRAME_RATE_HZ * span))
        if events.size / per_window > most:
            raise ValueError(f"window_fraction (--window-fraction) {n:g} gives about {events.size / per_window:.3g} "
                             f"windows of {per_window:,} event(s) (n H W = {n * width * height:.3g}) for "
                             f"{events.size:,} events over {span:.3g} s; the most is {most:,.0f} (MAX_WINDOWS "
                             f"{MAX_WINDOWS:,}, MAX_EVENT_FRAME_RATE_HZ {MAX_EVENT_FRAME_RATE_HZ:g} per second; use n >= "
                             f"{events.size / (most * width * height):.3g})")
    options = dict(reconstructor_options)
    if reconstructor not in ("direct", "high_pass") and threads is not None:
        options.setdefault("threads", threads)
    rec = create_reconstructor(reconstructor, width, height, **options)
    rec.reset()
    if adaptive:
        bounds = adaptive_windows(events, width, height)
    else:
        bounds = count_windows(events, window_size_from_fraction(n, width, height))
    for a, b in np.asarray(bounds, dtype=np.int64).reshape(-1, 2):
        if b <= a:
            continue
        start = time.perf_counter()
        image = rec.reconstruct(events[a:b])
        yield float(events["t"][b - 1]), image, time.perf_counter() - start
