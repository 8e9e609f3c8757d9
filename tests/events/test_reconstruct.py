"""Tests of evio_lib.events.reconstruct: the closed-form integrators against the per-event filter, the learned API."""
from __future__ import annotations

import numpy as np
import pytest

from evio_lib.events.array import EVENT_DTYPE, make_events
from evio_lib.events.reconstruct import (LogIntegrator, available_reconstructors, create_reconstructor,
                                         reconstruct_at_times, reconstruct_windows)


def random_events(n, width=6, height=4, seed=0, t0=0.0, t1=1.0):
    rng = np.random.default_rng(seed)
    return make_events(np.sort(rng.uniform(t0, t1, n)), rng.integers(0, width, n), rng.integers(0, height, n),
                       rng.choice([-1, 1], n))


def per_event_filter(events, width, height, contrast, alpha, beta, t_end, state=None, t_state=None):
    """Scheerlinck's filter written event by event: L = exp(-alpha dt - beta) L + C p, then decay to t_end."""
    L = np.zeros(height * width) if state is None else state.copy()
    t_last = np.full(height * width, events["t"][0] if t_state is None else t_state)
    for e in events:
        i = int(e["y"]) * width + int(e["x"])
        L[i] = np.exp(-alpha * (e["t"] - t_last[i]) - beta) * L[i] + contrast * e["p"]
        t_last[i] = e["t"]
    return L * np.exp(-alpha * (t_end - t_last))


@pytest.mark.parametrize("cutoff_hz, beta", [(0.0, 0.0), (0.06, 0.06), (3.0, 0.3)])
def test_closed_form_equals_the_per_event_filter(cutoff_hz, beta):
    ev = random_events(400, seed=int(10 * cutoff_hz))
    rec = LogIntegrator(6, 4, contrast=0.25, cutoff_hz=cutoff_hz, per_event_decay=beta)
    first, second = ev[:250], ev[250:]
    rec.reconstruct(first, t_end=float(first["t"][-1]))
    rec.reconstruct(second, t_end=1.2)
    expected = per_event_filter(ev, 6, 4, 0.25, 2 * np.pi * cutoff_hz, beta, 1.2)
    np.testing.assert_allclose(rec.log_state, expected, atol=1e-10)


def test_direct_integration_sums_contrast_times_polarity():
    ev = random_events(300, seed=4)
    rec = create_reconstructor("direct", 6, 4, contrast=0.2)
    image = rec.reconstruct(ev)
    signed = np.bincount(ev["y"].astype(int) * 6 + ev["x"], weights=ev["p"].astype(float), minlength=24)
    np.testing.assert_allclose(rec.log_state, 0.2 * signed)
    assert image.dtype == np.float32 and image.shape == (4, 6) and 0 <= image.min() and image.max() <= 1
    rec.reset()
    assert not rec.log_state.any()


def test_high_pass_forgets_old_events():
    ev = random_events(200, seed=2, t0=0.0, t1=0.1)
    rec = create_reconstructor("high_pass", 6, 4, cutoff_hz=5.0)
    rec.reconstruct(ev)
    before = np.abs(rec.log_state).max()
    rec.reconstruct(make_events([], [], [], []), t_end=2.0)  # 2 s later with no events: exp(-2 pi 5 * 1.9)
    assert np.abs(rec.log_state).max() < 1e-10 * before


def test_inputs_are_checked_and_untouched():
    ev = random_events(100, seed=1)
    copy = ev.copy()
    rec = create_reconstructor("direct", 6, 4)
    rec.reconstruct(ev)
    np.testing.assert_array_equal(ev, copy)
    with pytest.raises(ValueError, match="outside the 3x4 sensor"):
        create_reconstructor("direct", 3, 4).reconstruct(ev)
    with pytest.raises(ValueError, match="EVENT_DTYPE"):
        rec.reconstruct(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="t_end"):
        rec.reconstruct(ev, t_end=0.0)
    with pytest.raises(ValueError, match="unknown reconstructor"):
        create_reconstructor("nope")
    with pytest.raises(ValueError, match="checkpoint"):
        create_reconstructor("learned")
    with pytest.raises(ValueError, match="e2vid"):
        create_reconstructor("e2vid")
    with pytest.raises(ValueError, match="positive integers"):
        create_reconstructor("direct", 0, 4)


def test_every_available_reconstructor_constructs_and_gives_unit_range_frames():
    ev = random_events(500, width=24, height=16, seed=7)
    for name in available_reconstructors():
        rec = create_reconstructor(name, 24, 16)
        frames, times = reconstruct_windows(rec, ev, [[0, 250], [250, 500]])
        assert frames.shape == (2, 16, 24) and frames.dtype == np.float32, name
        assert np.isfinite(frames).all() and frames.min() >= 0 and frames.max() <= 1, name
        np.testing.assert_allclose(times, ev["t"][[249, 499]])
        empty = rec.reconstruct(np.zeros(0, EVENT_DTYPE), t_end=2.0)  # a stretch with no events
        assert empty.shape == (16, 24) and np.isfinite(empty).all(), name
    assert "firenet" in available_reconstructors()


def test_reconstruct_at_times_feeds_all_events_up_to_each_time():
    ev = random_events(600, seed=9)
    times = np.array([0.2, 0.5, 1.0])
    frames = reconstruct_at_times(create_reconstructor("direct", 6, 4), ev, times, max_window_events=100)
    rec = create_reconstructor("direct", 6, 4)
    expected = rec.reconstruct(ev[ev["t"] <= 0.5], t_end=0.5)
    np.testing.assert_allclose(frames[1], expected)
    with pytest.raises(ValueError, match="sorted"):
        reconstruct_at_times(rec, ev, [0.5, 0.2])


def test_a_bad_checkpoint_is_a_clear_error(tmp_path):
    bad = tmp_path / "garbage.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not a readable reconstructor checkpoint"):
        create_reconstructor("learned", 8, 8, checkpoint=bad)
    with pytest.raises(FileNotFoundError):
        create_reconstructor("learned", 8, 8, checkpoint=tmp_path / "missing.pt")


def test_bfloat16_network_is_close_to_float32_and_other_precisions_are_refused():
    rng = np.random.default_rng(5)
    n = 40_000
    windows = [make_events(np.sort(rng.uniform(k, k + 1, n)), rng.integers(0, 64, n), rng.integers(0, 48, n),
                           rng.choice([-1, 1], n)) for k in range(6)]
    images = {}
    for precision in ("float32", "bfloat16"):
        rec = create_reconstructor("firenet", 64, 48, precision=precision)
        images[precision] = np.stack([rec.reconstruct(w) for w in windows])  # state carried over six windows
        assert images[precision].dtype == np.float32
    difference = np.abs(images["float32"] - images["bfloat16"])
    assert 0 < difference.max() < 0.03 and difference.mean() < 3e-3
    with pytest.raises(ValueError, match="precision must be one of auto, float32, bfloat16, int8; got 'float16'"):
        create_reconstructor("firenet", 64, 48, precision="float16")


def test_classical_reconstructors_check_a_precision_and_compute_as_always():
    window = make_events(np.linspace(0.0, 0.1, 50), np.arange(50) % 8, np.arange(50) % 6, np.ones(50))
    for name in ("direct", "high_pass"):
        plain = create_reconstructor(name, 8, 6).reconstruct(window, t_end=0.1)
        given = create_reconstructor(name, 8, 6, precision="bfloat16").reconstruct(window, t_end=0.1)
        np.testing.assert_array_equal(given, plain)
        with pytest.raises(ValueError, match="precision must be one of auto, float32, bfloat16, int8; got 'half'"):
            create_reconstructor(name, 8, 6, precision="half")
