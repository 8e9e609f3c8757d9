"""Events read a window at a time: an in-memory array or an on-disk ``.npy`` file behind one small interface.

A recording of 100 M events is 1.3 GB as one :data:`~evio_lib.events.array.EVENT_DTYPE` array (13 bytes an event);
a billion do not fit. The readers of ROS bags and HDF5 files (:mod:`evio_lib.io.rosbag`, :mod:`evio_lib.io.hdf5`)
therefore write the events once, in chunks, to an ``.npy`` file of EVENT_DTYPE (:func:`write_events_npy`) and give
the :class:`~evio_lib.sequence.Sequence` a read-only memory map of it. Every array operation on ``sequence.events``
keeps working (``events["t"][0]``, ``len``), but a pass over the whole map would make every page of the file
resident. The consumers that walk the events (the pipeline's event frames, ``reconstruct``, ``convert``) go through
:func:`event_source` instead:

* :class:`ArrayEventSource` wraps an array in memory; ``take(i0, i1)`` is the view ``events[i0:i1]``, so the
  in-memory path gives the same bytes as before;
* :class:`NpyEventSource` reads the records it is asked for from the file with ``np.fromfile`` at an offset (no
  mapping, so nothing stays resident after a window is done) and finds times with a coarse index of every
  :data:`INDEX_STRIDE`-th timestamp (a binary search over the index, then over one block).

The window cuts of :mod:`evio_lib.events.representations` (count, time-bounded count and adaptive windows) are
repeated here on a source (:func:`count_windows_source`, :func:`bounded_count_windows_source`,
:func:`adaptive_windows_source`): the same arithmetic on the same numbers, reading the times a block at a time, so
the bounds equal the in-memory functions' (tests compare them on blocks of a few events).
"""
from __future__ import annotations

import mmap
import os
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from evio_lib.events.array import EVENT_DTYPE
from evio_lib.io.errors import DataFileError

__all__ = ["EventSource", "ArrayEventSource", "NpyEventSource", "event_source", "write_events_npy",
           "open_events_npy", "check_event_chunk", "EventChunkChecker", "count_windows_source",
           "bounded_count_windows_source", "adaptive_windows_source", "INDEX_STRIDE", "CHUNK_EVENTS",
           "check_events_streamed"]

#: Every INDEX_STRIDE-th timestamp of an on-disk source is kept in memory to find times (100 M events: 1526 floats).
INDEX_STRIDE = 65536
#: Events read at once by passes over an on-disk source (4 M events: 52 MB).
CHUNK_EVENTS = 1 << 22
_HEADER_BYTES = 256  # fixed .npy header length, so the count can be written after the events


class EventSource:
    """Events sorted by time, read by index range. Subclasses implement ``__len__``, :meth:`take`, :meth:`times`."""

    #: how many events a pass should read at once (the whole array for an in-memory source)
    chunk_events: int = CHUNK_EVENTS

    def __len__(self) -> int:
        raise NotImplementedError

    def take(self, i0: int, i1: int) -> np.ndarray:
        """Return the events with indices [i0, i1) as an EVENT_DTYPE array (a view for an in-memory source)."""
        raise NotImplementedError

    def times(self, i0: int, i1: int) -> np.ndarray:
        """Return the (i1 - i0,) float64 timestamps [s] of the events [i0, i1)."""
        return np.ascontiguousarray(self.take(i0, i1)["t"])

    def time_at(self, index: int) -> float:
        """Return the timestamp of event ``index`` [s] (negative: from the end)."""
        n = len(self)
        index = index + n if index < 0 else index
        if not 0 <= index < n:
            raise IndexError(f"event index {index} outside [0, {n})")
        return float(self.times(index, index + 1)[0])

    @property
    def t_range(self) -> tuple[float, float]:
        """Return (first, last) timestamp [s]; ValueError when there are no events."""
        if len(self) == 0:
            raise ValueError("the recording holds no events")
        return self.time_at(0), self.time_at(-1)

    def index_at(self, t: float, side: str = "left") -> int:
        """Return where ``t`` would go in the sorted timestamps (``np.searchsorted`` semantics)."""
        raise NotImplementedError

    def slice(self, t0: float, t1: float) -> np.ndarray:
        """Return the events with t0 <= t < t1."""
        return self.take(self.index_at(t0), self.index_at(t1))

    def chunks(self, i0: int = 0, i1: int | None = None, size: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """Yield (first index, events) over [i0, i1) in blocks of ``size`` events (default :attr:`chunk_events`)."""
        i1 = len(self) if i1 is None else i1
        size = self.chunk_events if size is None else max(1, int(size))
        for a in range(i0, i1, size):
            yield a, self.take(a, min(i1, a + size))


class ArrayEventSource(EventSource):
    """An EVENT_DTYPE array in memory as an :class:`EventSource` (``take`` returns views, nothing is copied)."""

    def __init__(self, events: np.ndarray) -> None:
        self.events = events
        self.chunk_events = max(1, len(events))

    def __len__(self) -> int:
        return int(self.events.shape[0])

    def take(self, i0: int, i1: int) -> np.ndarray:
        return self.events[i0:i1]

    def index_at(self, t: float, side: str = "left") -> int:
        return int(np.searchsorted(self.events["t"], t, side=side))


class NpyEventSource(EventSource):
    """Events of an ``.npy`` file (or part of one) of EVENT_DTYPE, read with ``np.fromfile`` at offsets.

    Args:
        path: the file.
        data_offset: byte offset of the first event of the file's array (its header length).
        start, count: the events [start, start + count) of that array (default: all of them).
    """

    def __init__(self, path: str | Path, data_offset: int | None = None, start: int = 0,
                 count: int | None = None) -> None:
        self.path = Path(path)
        if data_offset is None:
            data_offset, total = _npy_layout(self.path)
        else:
            total = (self.path.stat().st_size - data_offset) // EVENT_DTYPE.itemsize
        self.offset = int(data_offset) + int(start) * EVENT_DTYPE.itemsize
        self.count = int(total - start if count is None else count)
        strided = np.arange(0, self.count, INDEX_STRIDE, dtype=np.int64)
        self._index_t = np.array([self._read(int(i), int(i) + 1)["t"][0] for i in strided], dtype=np.float64)

    def __len__(self) -> int:
        return self.count

    def _read(self, i0: int, i1: int) -> np.ndarray:
        n = max(0, i1 - i0)
        if n == 0:
            return np.empty(0, EVENT_DTYPE)
        with open(self.path, "rb") as f:
            f.seek(self.offset + i0 * EVENT_DTYPE.itemsize)
            out = np.fromfile(f, dtype=EVENT_DTYPE, count=n)
        if out.shape[0] != n:
            raise DataFileError(f"{self.path.name}: the event file ends after {i0 + out.shape[0]} of {self.count} "
                                f"events (truncated?)")
        return out

    def take(self, i0: int, i1: int) -> np.ndarray:
        i0, i1 = max(0, int(i0)), min(self.count, int(i1))
        return self._read(i0, i1)

    def index_at(self, t: float, side: str = "left") -> int:
        if self.count == 0:
            return 0
        # block k holds indices [k S, (k + 1) S); the answer lies in the block after the last index time before t
        k = int(np.searchsorted(self._index_t, t, side=side)) - 1
        if k < 0:
            return 0
        a = k * INDEX_STRIDE
        b = min(self.count, a + INDEX_STRIDE)
        return a + int(np.searchsorted(self.times(a, b), t, side=side))


def event_source(events: np.ndarray | EventSource) -> EventSource:
    """Return an :class:`EventSource` over ``events``: a source as it is, a memory map of an ``.npy`` file as an
    :class:`NpyEventSource` (read by offsets, nothing kept resident), any other array as an
    :class:`ArrayEventSource`."""
    if isinstance(events, EventSource):
        return events
    if isinstance(events, np.memmap) and getattr(events, "filename", None) and events.ndim == 1 \
            and events.dtype == EVENT_DTYPE and events.strides in ((EVENT_DTYPE.itemsize,), (0,)) \
            and isinstance(getattr(events, "_mmap", None), mmap.mmap):
        # the map starts at the offset rounded down to the allocation granularity (np.memmap's own rule)
        map_start = events.offset - events.offset % mmap.ALLOCATIONGRANULARITY
        base = np.frombuffer(events._mmap, dtype=np.uint8)  # a view of the map (touches no page)
        byte = events.__array_interface__["data"][0] - base.__array_interface__["data"][0] if events.size else 0
        return NpyEventSource(events.filename, data_offset=map_start + byte, start=0, count=int(events.shape[0]))
    return ArrayEventSource(events)


def _npy_header(count: int) -> bytes:
    """Return the fixed-length (:data:`_HEADER_BYTES`) .npy version-1.0 header of ``count`` EVENT_DTYPE records."""
    text = "{'descr': %r, 'fortran_order': False, 'shape': (%d,), }" % (np.lib.format.dtype_to_descr(EVENT_DTYPE),
                                                                      count)
    text = text.ljust(_HEADER_BYTES - 10 - 1) + "\n"
    return b"\x93NUMPY\x01\x00" + np.uint16(len(text)).tobytes() + text.encode("latin1")


def _npy_layout(path: Path) -> tuple[int, int]:
    """Return (header length, number of events) of an ``.npy`` file of EVENT_DTYPE, or raise DataFileError."""
    try:
        with open(path, "rb") as f:
            version = np.lib.format.read_magic(f)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, fortran, dtype = read_header(f)
            offset = f.tell()
    except (OSError, ValueError, TypeError) as error:
        raise DataFileError(f"{path.name}: not an event file (.npy of EVENT_DTYPE): {error}") from None
    if dtype != EVENT_DTYPE or len(shape) != 1 or fortran:
        raise DataFileError(f"{path.name}: expected a 1-D .npy array of EVENT_DTYPE; got {dtype} {shape}")
    if path.stat().st_size < offset + shape[0] * EVENT_DTYPE.itemsize:
        raise DataFileError(f"{path.name}: the file is shorter than its {shape[0]} events (truncated?)")
    return offset, int(shape[0])


def write_events_npy(path: str | Path, chunks: Iterable[np.ndarray]) -> int:
    """Write the EVENT_DTYPE ``chunks`` one after the other to the ``.npy`` file ``path``; return the event count.

    The header is written first with room for any count and rewritten at the end, so the events are never held
    together in memory. The file is written under a temporary name and renamed when complete.
    """
    path = Path(path)
    tmp = path.with_name(path.name + f".part{os.getpid()}")
    count = 0
    try:
        with open(tmp, "wb") as f:
            f.write(_npy_header(0))
            for chunk in chunks:
                if chunk.dtype != EVENT_DTYPE:
                    raise ValueError(f"write_events_npy: chunks must be EVENT_DTYPE arrays; got {chunk.dtype}")
                f.write(np.ascontiguousarray(chunk).tobytes())
                count += int(chunk.shape[0])
            f.seek(0)
            f.write(_npy_header(count))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return count


def open_events_npy(path: str | Path) -> np.ndarray:
    """Return a read-only memory map of an ``.npy`` event file (checked: EVENT_DTYPE, 1-D, complete)."""
    path = Path(path)
    offset, count = _npy_layout(path)
    if count == 0:
        return np.empty(0, EVENT_DTYPE)
    return np.memmap(path, dtype=EVENT_DTYPE, mode="r", offset=offset, shape=(count,))


def check_event_chunk(chunk: np.ndarray, first_index: int, previous_t: float, where: str,
                      sensor_size: tuple[int, int] | None = None) -> None:
    """Raise DataFileError naming ``where`` unless the chunk's times are finite and sorted (continuing from
    ``previous_t``), its polarities +1/-1 and (when ``sensor_size`` is given) its pixels inside the sensor."""
    if chunk.size == 0:
        return
    t = chunk["t"]
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataFileError(f"{where}: event {first_index + int(bad[0])} has a non-finite timestamp")
    if t[0] < previous_t:
        raise DataFileError(f"{where}: event {first_index} at t = {float(t[0])!r} s comes before the previous event "
                            f"({previous_t!r} s); events must be sorted by time")
    bad = np.flatnonzero(t[1:] < t[:-1])
    if bad.size:
        i = int(bad[0]) + 1
        raise DataFileError(f"{where}: event {first_index + i} at t = {float(t[i])!r} s comes before the previous "
                            f"event ({float(t[i - 1])!r} s); events must be sorted by time")
    bad = np.flatnonzero((chunk["p"] != 1) & (chunk["p"] != -1))
    if bad.size:
        raise DataFileError(f"{where}: event {first_index + int(bad[0])} has polarity {int(chunk['p'][bad[0]])}; "
                            f"expected +1/-1")
    if sensor_size is not None:
        width, height = sensor_size
        bad = np.flatnonzero((chunk["x"] >= width) | (chunk["y"] >= height))
        if bad.size:
            i = int(bad[0])
            raise DataFileError(f"{where}: event {first_index + i} at pixel ({int(chunk['x'][i])}, "
                                f"{int(chunk['y'][i])}) lies outside the {width} x {height} sensor")


class EventChunkChecker:
    """Check chunks of one event stream as they are read (:func:`check_event_chunk`), carrying the last time.

    >>> from evio_lib.events.array import make_events
    >>> check = EventChunkChecker("demo")
    >>> check(make_events([0.0, 1.0], [0, 0], [0, 0], [1, -1])).size
    2
    """

    def __init__(self, where: str, sensor_size: tuple[int, int] | None = None) -> None:
        self.where, self.sensor_size = where, sensor_size
        self.count, self.last_t = 0, -np.inf

    def __call__(self, chunk: np.ndarray) -> np.ndarray:
        check_event_chunk(chunk, self.count, self.last_t, self.where, self.sensor_size)
        if chunk.size:
            self.last_t = float(chunk["t"][-1])
        self.count += int(chunk.size)
        return chunk


def check_events_streamed(events: np.ndarray, where: str = "events",
                          sensor_size: tuple[int, int] | None = None) -> None:
    """Check a memory-mapped event array a chunk at a time through its file (no page stays resident); ValueError."""
    source = event_source(events)
    checker = EventChunkChecker(where, sensor_size)
    for _, chunk in source.chunks():
        try:
            checker(chunk)
        except DataFileError as error:
            raise ValueError(str(error)) from None


# ------------------------------------------------------------------------------------------- windows on a source
class _Times:
    """The timestamps of a source's events [lo, hi), read a block at a time; blocks behind are dropped."""

    def __init__(self, source: EventSource, lo: int, hi: int, block: int) -> None:
        self.source, self.lo, self.hi, self.block = source, lo, hi, max(1, block)
        self.start, self.t = lo, np.zeros(0)

    def _cover(self, i: int) -> None:
        """Make the buffer hold index ``i`` (< hi)."""
        if not self.lo <= i < self.hi:
            raise IndexError(f"event index {i} outside [{self.lo}, {self.hi})")
        if i < self.start:
            self.start, self.t = i, self.source.times(i, min(self.hi, i + self.block))
        while i >= self.start + self.t.size:
            stop = min(self.hi, self.start + self.t.size + self.block)
            self.t = np.concatenate([self.t, self.source.times(self.start + self.t.size, stop)])

    def forget_before(self, i: int) -> None:
        """Drop the times before index ``i``."""
        if i > self.start:
            cut = min(self.t.size, i - self.start)
            self.t, self.start = self.t[cut:], self.start + cut

    def __getitem__(self, i: int) -> float:
        self._cover(i)
        return float(self.t[i - self.start])

    def search_right(self, value: float, begin: int) -> int:
        """Return the first index >= ``begin`` whose time is > ``value`` (hi when none)."""
        i = begin
        while i < self.hi:
            self._cover(i)
            stop = self.start + self.t.size
            found = int(np.searchsorted(self.t[i - self.start:], value, side="right")) + i
            if found < stop:
                return found
            i = stop
        return self.hi

    def search_left(self, value: float, begin: int) -> int:
        """Return the first index >= ``begin`` whose time is >= ``value`` (hi when none)."""
        i = begin
        while i < self.hi:
            self._cover(i)
            stop = self.start + self.t.size
            found = int(np.searchsorted(self.t[i - self.start:], value, side="left")) + i
            if found < stop:
                return found
            i = stop
        return self.hi


def count_windows_source(source: EventSource, lo: int, hi: int, n_events: int) -> np.ndarray:
    """Return (K, 2) global index bounds of the count windows of the events [lo, hi) (as
    :func:`evio_lib.events.representations.count_windows` on ``events[lo:hi]``, plus ``lo``)."""
    from evio_lib.events.representations import MAX_WINDOWS, _check_bounded_window_args, _too_many_windows

    n = hi - lo
    if int(n_events) != n_events or n_events < 1:
        raise ValueError(f"n_events must be a positive integer; got {n_events!r}")
    if n // int(n_events) > MAX_WINDOWS:
        raise _too_many_windows(n // int(n_events), f"n_events={int(n_events)} for {n} events",
                                f" (use n_events >= {-(-n // MAX_WINDOWS)})")
    starts = np.arange(0, n - int(n_events) + 1, int(n_events), dtype=np.int64)
    bounds = np.stack([starts, starts + int(n_events)], axis=1) if starts.size else np.zeros((0, 2), np.int64)
    return bounds + lo


def bounded_count_windows_source(source: EventSource, lo: int, hi: int, n_events: int, min_duration: float = 0.0,
                                 max_duration: float | None = None, t_start: float | None = None,
                                 t_end: float | None = None, block: int | None = None
                                 ) -> tuple[np.ndarray, np.ndarray]:
    """Return (bounds (K, 2) global indices, end times (K,)): the windows of
    :func:`evio_lib.events.representations.bounded_count_windows` on the events [lo, hi), reading their times a
    ``block`` at a time (default: the source's chunk size)."""
    from evio_lib.events.representations import MAX_WINDOWS, _check_bounded_window_args, _too_many_windows

    n_events = _check_bounded_window_args(n_events, min_duration, max_duration)
    size = hi - lo
    t = _Times(source, lo, hi, source.chunk_events if block is None else block)
    if size == 0 and (t_start is None or t_end is None):
        return np.zeros((0, 2), np.int64), np.zeros(0)
    t0 = t[lo] if t_start is None else float(t_start)
    t1 = t[hi - 1] if t_end is None else float(t_end)
    span = max(0.0, t1 - t0)
    most = size / n_events + (span / max_duration if max_duration else 0.0)
    if min_duration > 0:
        most = min(most, span / min_duration + 1)
    if most > MAX_WINDOWS:
        raise _too_many_windows(most, f"n_events={n_events} with windows of {min_duration:g}-{max_duration} s over "
                                      f"{size} events and {span:g} s", " (use more events or longer windows)")
    a = t.search_left(t0, lo)
    start = t0
    bounds, ends = [], []
    while True:
        t.forget_before(a)
        b = a + n_events
        close = t[b - 1] if b <= hi else np.inf
        if close < start + min_duration:
            close = start + min_duration
            b = t.search_right(close, a)
        if max_duration is not None and close > start + max_duration:
            close = start + max_duration
            b = t.search_right(close, a)
        if not close <= t1:
            break
        bounds.append((a, b))
        ends.append(close)
        a, start = b, close
    return np.asarray(bounds, dtype=np.int64).reshape(-1, 2), np.asarray(ends, dtype=np.float64)


def adaptive_windows_source(source: EventSource, lo: int, hi: int, width: int, height: int,
                            events_per_active_pixel: float = 2.0, min_fraction: float = 0.02,
                            max_fraction: float = 1.5) -> np.ndarray:
    """Return (K, 2) global index bounds of :func:`evio_lib.events.representations.adaptive_windows` on the events
    [lo, hi), reading at most one window's largest size (``max_fraction`` H W events) at a time."""
    from evio_lib.events.representations import _adaptive_window_bounds, _check_adaptive_args, _pixel_index

    w, h, n_min, n_max = _check_adaptive_args(width, height, events_per_active_pixel, min_fraction, max_fraction)
    return _adaptive_window_bounds(lambda a, b: _pixel_index(source.take(a, b), w, h), lo, hi, n_min, n_max,
                                   events_per_active_pixel)
