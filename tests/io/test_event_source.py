"""Events on disk read a window at a time (evio_lib.io.event_source): the same events and the same windows."""
from __future__ import annotations

import numpy as np
import pytest

from evio_lib.events.array import EVENT_DTYPE, make_events
from evio_lib.events.representations import adaptive_windows, bounded_count_windows, count_windows
from evio_lib.io import event_source as es
from evio_lib.io.errors import DataFileError
from evio_lib.sequence import Sequence


def _events(n: int = 5000, seed: int = 0, width: int = 40, height: int = 30) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.sort(np.round(rng.uniform(0.0, 2.0, n), 4))  # rounded: many equal timestamps
    t[1000:1400] = np.linspace(0.5, 0.9, 400).round(4)  # and a stretch of its own density
    t.sort()
    return make_events(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice([-1, 1], n))


@pytest.fixture
def on_disk(tmp_path, monkeypatch):
    monkeypatch.setattr(es, "INDEX_STRIDE", 64)  # many index blocks on a small file
    events = _events()
    path = tmp_path / "events.npy"
    assert es.write_events_npy(path, (events[i:i + 777] for i in range(0, events.size, 777))) == events.size
    return events, es.open_events_npy(path)


def test_npy_file_reads_back_exactly(on_disk):
    events, mapped = on_disk
    assert isinstance(mapped, np.memmap) and mapped.dtype == EVENT_DTYPE
    assert np.array_equal(np.load(mapped.filename), events)  # a plain .npy numpy reads
    source = es.event_source(mapped)
    assert isinstance(source, es.NpyEventSource) and len(source) == events.size
    assert source.take(123, 4567).tobytes() == events[123:4567].tobytes()
    for t in (-1.0, 0.0, 0.5, 0.5001, 0.77, 1.99995, 3.0):
        for side in ("left", "right"):
            assert source.index_at(t, side) == np.searchsorted(events["t"], t, side=side)
    assert source.t_range == (float(events["t"][0]), float(events["t"][-1]))
    sliced = es.event_source(mapped[100:900])  # a slice of the map: the same records
    assert sliced.take(0, 800).tobytes() == events[100:900].tobytes()


@pytest.mark.parametrize("block", [1, 7, 1000, 10 ** 6])
def test_windows_on_a_source_equal_the_in_memory_ones(on_disk, block):
    events, mapped = on_disk
    source = es.event_source(mapped)
    source.chunk_events = block
    lo, hi = 37, events.size - 11
    part = events[lo:hi]
    assert np.array_equal(es.count_windows_source(source, lo, hi, 97) - lo, count_windows(part, 97))
    for n, low, high, t0, t1 in [(50, 0.0, 0.03, None, None), (50, 0.01, 0.1, 0.2, 1.9), (300, 0.05, None, 0.0, 2.0),
                                 (20, 0.0, 0.0005, 0.5, 0.9)]:
        b1, e1 = bounded_count_windows(part, n, low, high, t_start=t0, t_end=t1)
        b2, e2 = es.bounded_count_windows_source(source, lo, hi, n, low, high, t_start=t0, t_end=t1, block=block)
        assert np.array_equal(b2 - lo, b1) and e1.tobytes() == e2.tobytes()
    assert np.array_equal(es.adaptive_windows_source(source, lo, hi, 40, 30) - lo, adaptive_windows(part, 40, 30))


def test_sequence_holds_a_map_and_checks_it_by_blocks(on_disk, tmp_path):
    events, mapped = on_disk
    seq = Sequence("disk", events=mapped, frames=np.zeros((0, 30, 40), np.uint8))
    seq.validate()
    assert "events          5,000" in seq.summary()
    bad = events.copy()
    bad["t"][2500] = 0.0
    path = tmp_path / "bad.npy"
    es.write_events_npy(path, [bad])
    with pytest.raises(ValueError, match="event 2500 at t = 0.0 s comes before"):
        Sequence("bad", events=es.open_events_npy(path))


def test_chunk_checker_names_the_event():
    check = es.EventChunkChecker("rec.bag topic /dvs/events", sensor_size=(40, 30))
    check(make_events([0.0, 1.0], [0, 1], [0, 1], [1, -1]))
    with pytest.raises(DataFileError, match=r"/dvs/events: event 2 at t = 0.5 s comes before the previous event"):
        check(make_events([0.5], [0], [0], [1]))
    with pytest.raises(DataFileError, match=r"event 2 at pixel \(40, 0\) lies outside the 40 x 30 sensor"):
        es.EventChunkChecker("x", (40, 30))(make_events([0.0, 0.1, 0.2], [0, 0, 40], [0, 0, 0], [1, 1, 1]))
