"""Tests for evio_lib.events.array: construction, validation, windows, merging, count images."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from evio_lib.events.array import (
    EVENT_DTYPE,
    concatenate_events,
    empty_events,
    event_count_image,
    events_between,
    make_events,
    validate_events,
)


def random_events(rng: np.random.Generator, n: int, width: int = 20, height: int = 10, t_max: float = 1.0):
    t = np.sort(rng.uniform(0.0, t_max, n))
    return make_events(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice([-1, 1], n))


def raw_events(t, x, y, p) -> np.ndarray:
    """Build an event array without any validation (to feed broken arrays to validate_events)."""
    ev = np.empty(len(t), dtype=EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = t, x, y, p
    return ev


# --- make_events -----------------------------------------------------------------------------------------------


def test_event_dtype_is_exactly_the_project_layout():
    assert EVENT_DTYPE == np.dtype([("t", "<f8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])
    assert EVENT_DTYPE.itemsize == 13


def test_make_events_stores_fields_and_copies_inputs():
    t = np.array([0.0, 0.5, 0.5, 2.0])
    x = np.array([0, 65535, 3, 7])
    y = np.array([1.0, 2.0, 3.0, 4.0])  # integral floats are accepted
    p = np.array([1, -1, -1, 1])
    before = [a.copy() for a in (t, x, y, p)]
    ev = make_events(t, x, y, p)
    assert ev.dtype == EVENT_DTYPE and ev.shape == (4,)
    np.testing.assert_array_equal(ev["t"], t)
    np.testing.assert_array_equal(ev["x"], x)
    np.testing.assert_array_equal(ev["y"], [1, 2, 3, 4])
    np.testing.assert_array_equal(ev["p"], p)
    for a, b in zip((t, x, y, p), before):
        np.testing.assert_array_equal(a, b)
    ev["x"][0] = 99  # the result owns its memory
    assert x[0] == 0


def test_make_events_accepts_empty():
    ev = make_events([], [], [], [])
    assert ev.shape == (0,) and ev.dtype == EVENT_DTYPE


@pytest.mark.parametrize(
    "t, x, y, p, match",
    [
        ([0.0, 2.0, 1.0, 3.0, 2.5], [0] * 5, [0] * 5, [1] * 5, r"2 out-of-order timestamps starting at index 2"),
        ([0.0, np.nan], [0, 0], [0, 0], [1, 1], r"t must be finite.*index 1"),
        ([0.0, 1.0], [0, 0], [0, 0], [1, 0], r"p must be \+1 or -1.*index 1 \(p=0\)"),
        ([0.0, 1.0], [0, -1], [0, 0], [1, 1], r"x must be integers in \[0, 65535\].*index 1"),
        ([0.0, 1.0], [0, 0], [0, 70000], [1, 1], r"y must be integers in \[0, 65535\].*y=70000"),
        ([0.0, 1.0], [0, 1.5], [0, 0], [1, 1], r"x must hold integers.*1.5 at index 1"),
        ([0.0, 1.0], [0], [0, 0], [1, 1], r"x must have the same length as t \(2\); got length 1"),
        ([[0.0, 1.0]], [0], [0], [1], r"t must be a 1-D array of shape \(N,\); got shape \(1, 2\)"),
        (["a", "b"], [0, 0], [0, 0], [1, 1], r"t must hold real timestamps"),
    ],
)
def test_make_events_rejects_bad_input(t, x, y, p, match):
    with pytest.raises(ValueError, match=match):
        make_events(t, x, y, p)


# --- validate_events -------------------------------------------------------------------------------------------


def test_validate_events_accepts_valid_arrays(rng):
    validate_events(random_events(rng, 200), 20, 10)
    validate_events(empty_events(), 5, 5)


def test_validate_events_messages_name_the_problem():
    ev = raw_events([0.0, 1.0, 2.0, 1.5, 3.0, 2.9], [0] * 6, [0] * 6, [1] * 6)
    message = r"^events must be sorted by time; found 2 out-of-order timestamps starting at index 3$"
    with pytest.raises(ValueError, match=message):
        validate_events(ev)
    ev = raw_events([0.0, 1.0, 2.0, 3.0], [0, 240, 5, 241], [0, 0, 0, 0], [1, 1, 1, 1])
    with pytest.raises(ValueError, match=r"^event x out of range \[0, 240\): 2 events, first at index 1 \(x=240\)$"):
        validate_events(ev, width=240, height=180)
    validate_events(ev)  # no size given: no range check
    ev = raw_events([0.0, 1.0], [0, 0], [0, 180], [1, 1])
    with pytest.raises(ValueError, match=r"event y out of range \[0, 180\): 1 events, first at index 1 \(y=180\)"):
        validate_events(ev, width=240, height=180)
    ev = raw_events([0.0, 1.0], [0, 0], [0, 0], [1, 2])
    with pytest.raises(ValueError, match=r"polarity must be \+1 or -1; 1 events invalid, first at index 1 \(p=2\)"):
        validate_events(ev)
    ev = raw_events([0.0, np.inf], [0, 0], [0, 0], [1, 1])
    with pytest.raises(ValueError, match=r"timestamps must be finite.*index 1"):
        validate_events(ev)


def test_validate_events_rejects_wrong_type_dtype_and_shape():
    with pytest.raises(ValueError, match=r"events must have dtype"):
        validate_events(np.zeros(3))
    with pytest.raises(ValueError, match=r"events must be a NumPy array"):
        validate_events([(0.0, 1, 1, 1)])
    with pytest.raises(ValueError, match=r"events must be a 1-D array of shape \(N,\); got shape \(2, 2\)"):
        validate_events(np.zeros((2, 2), dtype=EVENT_DTYPE))
    other = np.zeros(2, dtype=[("t", "<f4"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])
    with pytest.raises(ValueError, match=r"events must have dtype"):
        validate_events(other)


# --- empty / window --------------------------------------------------------------------------------------------


def test_empty_events():
    ev = empty_events()
    assert ev.shape == (0,) and ev.dtype == EVENT_DTYPE


def test_events_between_matches_boolean_mask_and_is_half_open(rng):
    ev = random_events(rng, 500)
    ev = concatenate_events([ev, make_events([1.0, 1.0], [0, 1], [0, 0], [1, 1])])  # duplicates at a boundary
    before = ev.copy()
    for t0, t1 in [(0.2, 0.6), (0.0, 1.0), (-1.0, 5.0), (0.5, 0.5), (ev["t"][10], ev["t"][20]), (1.0, 2.0)]:
        got = events_between(ev, t0, t1)
        expected = ev[(ev["t"] >= t0) & (ev["t"] < t1)]  # independent truth: a linear scan
        np.testing.assert_array_equal(got, expected)
    assert events_between(ev, ev["t"][10], ev["t"][20]).shape[0] == 10
    assert events_between(ev, 1.0, 2.0).shape[0] == 2
    np.testing.assert_array_equal(ev, before)


def test_events_between_rejects_bad_input(rng):
    ev = random_events(rng, 10)
    with pytest.raises(ValueError, match=r"t1 must be >= t0; got t0=0.5, t1=0.1"):
        events_between(ev, 0.5, 0.1)
    with pytest.raises(ValueError, match=r"t0 and t1 must be finite"):
        events_between(ev, np.nan, 0.1)
    with pytest.raises(ValueError, match=r"events must be a 1-D array of dtype EVENT_DTYPE"):
        events_between(np.zeros(3), 0.0, 1.0)


# --- concatenate -----------------------------------------------------------------------------------------------


def _expected_merge(chunks):
    """Independent truth: tag each event with (chunk, position), then lexsort on (t, chunk, position)."""
    rows = [(e["t"], ci, i) for ci, c in enumerate(chunks) for i, e in enumerate(c)]
    rows.sort()
    return [chunks[ci][i] for _, ci, i in rows]


def test_concatenate_events_merges_stably(rng):
    # coarse timestamps force many ties across chunks
    chunks = []
    for k in range(4):
        n = int(rng.integers(0, 40))
        t = np.sort(rng.integers(0, 10, n) / 10.0)
        chunks.append(make_events(t, np.full(n, k), rng.integers(0, 5, n), rng.choice([-1, 1], n)))
    before = [c.copy() for c in chunks]
    merged = concatenate_events(chunks)
    validate_events(merged)
    expected = _expected_merge(chunks)
    assert merged.shape[0] == len(expected)
    for got, exp in zip(merged, expected):
        assert got == exp
    for c, b in zip(chunks, before):
        np.testing.assert_array_equal(c, b)


@settings(max_examples=30, deadline=None, derandomize=True, database=None)
@given(st.lists(st.lists(st.integers(0, 6), max_size=8), max_size=5))
def test_concatenate_events_property(chunk_times):
    chunks = [make_events(np.sort(np.array(ts, float)), np.full(len(ts), k), np.arange(len(ts)), np.ones(len(ts)))
              for k, ts in enumerate(chunk_times)]
    merged = concatenate_events(chunks)
    expected = _expected_merge(chunks)
    assert [tuple(e) for e in merged] == [tuple(e) for e in expected]


def test_concatenate_events_in_order_and_empty(rng):
    a, b = random_events(rng, 30, t_max=1.0), random_events(rng, 30, t_max=1.0)
    b["t"] += 1.0
    merged = concatenate_events([a, empty_events(), b])
    np.testing.assert_array_equal(merged, np.concatenate([a, b]))
    assert concatenate_events([]).shape == (0,)
    assert concatenate_events([empty_events()]).dtype == EVENT_DTYPE


def test_concatenate_events_rejects_bad_input(rng):
    with pytest.raises(ValueError, match=r"chunks\[1\] must be a 1-D array of dtype EVENT_DTYPE"):
        concatenate_events([empty_events(), np.zeros(3)])
    with pytest.raises(ValueError, match=r"chunks must be a sequence"):
        concatenate_events(random_events(rng, 3))
    bad = raw_events([1.0, 0.0], [0, 0], [0, 0], [1, 1])
    with pytest.raises(ValueError, match=r"chunks\[0\] must be sorted by time; found 1 out-of-order"):
        concatenate_events([bad])


# --- count image -----------------------------------------------------------------------------------------------


def test_event_count_image_matches_add_at(rng):
    ev = random_events(rng, 3000, width=20, height=10)
    expected = np.zeros((10, 20), np.int64)
    np.add.at(expected, (ev["y"].astype(int), ev["x"].astype(int)), 1)
    expected_signed = np.zeros((10, 20), np.int64)
    np.add.at(expected_signed, (ev["y"].astype(int), ev["x"].astype(int)), ev["p"].astype(int))
    counts = event_count_image(ev, 20, 10)
    assert counts.shape == (10, 20) and counts.dtype == np.int64
    np.testing.assert_array_equal(counts, expected)
    np.testing.assert_array_equal(event_count_image(ev, 20, 10, signed=True), expected_signed)
    assert counts.sum() == 3000


def test_event_count_image_small_case_by_hand():
    ev = make_events([0.0, 0.1, 0.2, 0.3], [2, 2, 0, 2], [1, 1, 0, 1], [1, -1, -1, 1])
    np.testing.assert_array_equal(event_count_image(ev, 3, 2), [[1, 0, 0], [0, 0, 3]])
    np.testing.assert_array_equal(event_count_image(ev, 3, 2, signed=True), [[-1, 0, 0], [0, 0, 1]])
    np.testing.assert_array_equal(event_count_image(empty_events(), 3, 2), np.zeros((2, 3)))


def test_event_count_image_rejects_out_of_range():
    ev = make_events([0.0, 0.1], [0, 5], [0, 0], [1, 1])
    with pytest.raises(ValueError, match=r"event x out of range \[0, 5\): 1 events, first at index 1 \(x=5\)"):
        event_count_image(ev, 5, 4)
    with pytest.raises(ValueError, match=r"width and height must be positive"):
        event_count_image(ev, 0, 4)
