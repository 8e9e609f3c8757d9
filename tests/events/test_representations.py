"""Tests of evio_lib.events.representations against brute-force loops over events and closed forms."""
from __future__ import annotations

import numpy as np
import pytest

from evio_lib.events.array import make_events
from evio_lib.events.representations import (adaptive_windows, count_windows, normalize_voxel_grid, polarity_frame,
                                             time_surface, time_windows, voxel_grid, window_size_from_fraction)


def random_events(n: int, width: int = 7, height: int = 5, seed: int = 0, t_span: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, t_span, n))
    return make_events(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice([-1, 1], n))


def voxel_grid_loop(events, width, height, bins):
    """The E2VID voxel grid written event by event (the definition)."""
    grid = np.zeros((bins, height, width))
    t = events["t"]
    t_star = (bins - 1) * (t - t[0]) / (t[-1] - t[0])
    for e, ts in zip(events, t_star):
        for b in range(bins):
            grid[b, e["y"], e["x"]] += e["p"] * max(0.0, 1.0 - abs(b - ts))
    return grid


def test_window_size_is_eq_87():
    assert window_size_from_fraction(0.2, 240, 180) == 8640
    assert window_size_from_fraction(0.7, 240, 180) == 30240
    with pytest.raises(ValueError, match="fraction n"):
        window_size_from_fraction(0.0, 240, 180)


@pytest.mark.parametrize("bins", [1, 2, 5])
def test_voxel_grid_matches_the_definition(bins):
    ev = random_events(300, seed=bins)
    grid = voxel_grid(ev, 7, 5, bins, normalize=False)
    if bins == 1:  # a single bin: every event's whole weight lands in it
        np.testing.assert_allclose(grid[0], polarity_frame(ev, 7, 5), atol=1e-5)
    else:
        np.testing.assert_allclose(grid, voxel_grid_loop(ev, 7, 5, bins), atol=1e-5)
    # the bilinear weights of each event sum to one: summing the bins gives the polarity frame
    np.testing.assert_allclose(grid.sum(axis=0), polarity_frame(ev, 7, 5), atol=1e-4)


def test_voxel_grid_normalisation_is_e2vids():
    grid = voxel_grid(random_events(500, seed=3), 7, 5, 5)
    nonzero = grid[grid != 0]
    assert abs(nonzero.mean()) < 1e-5 and abs(nonzero.std() - 1.0) < 1e-4
    assert voxel_grid(make_events([], [], [], []), 7, 5, 5).shape == (5, 5, 7)
    np.testing.assert_array_equal(normalize_voxel_grid(np.zeros((2, 2))), np.zeros((2, 2)))


@pytest.mark.parametrize("case", ["sparse", "dense", "one_event", "constant", "empty", "fortran"])
def test_the_normalisation_kernels_give_numpys_grids_bit_for_bit(monkeypatch, case):
    """The Numba normalisation (events.voxel_kernels) against the NumPy boolean-mask path: the same bytes, on windows
    from a few events to more events than voxels, a grid of one repeated value (no spread: only centred), an empty
    one, and a grid not in C order (the NumPy path then)."""
    pytest.importorskip("numba")
    from evio_lib.events.representations import voxel_backend

    rng = np.random.default_rng(11)
    grids = {"sparse": voxel_grid(random_events(3000, 240, 180, seed=1), 240, 180, 5, normalize=False),
             "dense": voxel_grid(random_events(20000, 17, 13, seed=2), 17, 13, 5, normalize=False),
             "one_event": voxel_grid(random_events(1, seed=3), 7, 5, 5, normalize=False),
             "constant": np.where(rng.uniform(size=(5, 9, 11)) < 0.3, 0.5, 0.0).astype(np.float32),
             "empty": np.zeros((5, 4, 3), np.float32),
             "fortran": np.asfortranarray(voxel_grid(random_events(400, seed=4), 7, 5, 5, normalize=False))}
    grid = grids[case]
    out = {}
    for backend in ("numpy", "numba"):
        monkeypatch.setenv("EVIO_VOXEL_BACKEND", backend)
        assert voxel_backend() == backend
        out[backend] = normalize_voxel_grid(grid)
    assert out["numba"].tobytes() == out["numpy"].tobytes()
    np.testing.assert_array_equal(out["numba"][grid == 0], 0.0)        # the zeros stay zero
    nonzero = out["numba"][grid != 0]
    if case in ("sparse", "dense"):
        assert abs(nonzero.mean()) < 1e-5 and abs(nonzero.std() - 1.0) < 1e-4
    if case in ("constant", "one_event"):
        np.testing.assert_array_equal(nonzero, 0.0)                    # centred only: no spread to divide by
    monkeypatch.setenv("EVIO_VOXEL_BACKEND", "numba")
    events = random_events(5000, 240, 180, seed=5)
    with_kernels = voxel_grid(events, 240, 180, 5)
    monkeypatch.setenv("EVIO_VOXEL_BACKEND", "numpy")
    assert voxel_grid(events, 240, 180, 5).tobytes() == with_kernels.tobytes()
    monkeypatch.setenv("EVIO_VOXEL_BACKEND", "gpu")
    with pytest.raises(ValueError, match="EVIO_VOXEL_BACKEND must be one of auto, numba, numpy"):
        voxel_backend()


def test_voxel_grid_does_not_modify_its_input_and_checks_bounds():
    ev = random_events(50)
    copy = ev.copy()
    voxel_grid(ev, 7, 5)
    np.testing.assert_array_equal(ev, copy)
    with pytest.raises(ValueError, match="outside"):
        voxel_grid(ev, 3, 5)
    with pytest.raises(ValueError, match="EVENT_DTYPE"):
        voxel_grid(np.zeros((4, 4)), 7, 5)
    with pytest.raises(ValueError, match="num_bins"):
        voxel_grid(ev, 7, 5, 0)


def test_time_surface_matches_a_loop():
    ev = random_events(200, seed=5)
    tau, t_ref = 0.2, 1.1
    surface = time_surface(ev, 7, 5, tau=tau, t_ref=t_ref)
    expected = np.zeros((2, 5, 7))
    for e in ev:  # the last event of each pixel and polarity wins
        expected[0 if e["p"] > 0 else 1, e["y"], e["x"]] = np.exp(-(t_ref - e["t"]) / tau)
    np.testing.assert_allclose(surface, expected, atol=1e-6)
    with pytest.raises(ValueError, match="t_ref"):
        time_surface(ev, 7, 5, t_ref=0.5)


def test_count_and_time_windows():
    ev = random_events(1000, seed=1)
    bounds = count_windows(ev, 300)
    assert bounds.tolist() == [[0, 300], [300, 600], [600, 900]]
    b, t_end = time_windows(ev, 0.25, t_start=0.0, t_end=1.0)
    assert len(b) == 4 and b[0, 0] == 0 and b[-1, 1] == 1000
    np.testing.assert_allclose(t_end, [0.25, 0.5, 0.75, 1.0])
    for (a, z), te in zip(b, t_end):
        assert np.all(ev["t"][a:z] < te) and np.all(ev["t"][a:z] >= te - 0.25)
    with pytest.raises(ValueError, match="positive integer"):
        count_windows(ev, 0)


def test_adaptive_windows_follow_the_texture():
    """A dense scene (events over all pixels) gets longer windows than a sparse one (a few pixels) at the same ratio."""
    rng = np.random.default_rng(0)
    n, width, height = 20000, 40, 30
    t = np.sort(rng.uniform(0, 1, n))
    dense = make_events(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.choice([-1, 1], n))
    sparse = make_events(t, rng.integers(0, 8, n), rng.integers(0, 6, n), rng.choice([-1, 1], n))
    b_dense = adaptive_windows(dense, width, height, events_per_active_pixel=2.0, min_fraction=0.01,
                               max_fraction=3.0)
    b_sparse = adaptive_windows(sparse, width, height, events_per_active_pixel=2.0, min_fraction=0.01,
                               max_fraction=3.0)
    size_dense = np.diff(b_dense, axis=1).mean()
    size_sparse = np.diff(b_sparse, axis=1).mean()
    assert size_dense > 5 * size_sparse
    # each window closes exactly when the ratio is first reached
    a, z = b_dense[0]
    pix = dense["y"][a:z].astype(int) * width + dense["x"][a:z]
    assert (z - a) >= 2.0 * np.unique(pix).size
    pix_short = pix[:-1]
    assert (z - a - 1) < 2.0 * np.unique(pix_short).size
    assert np.all(b_dense[1:, 0] == b_dense[:-1, 1])  # consecutive, no gaps
    with pytest.raises(ValueError, match="events_per_active_pixel"):
        adaptive_windows(dense, width, height, events_per_active_pixel=1.0)


# ---------------------------------------------------------------------------------------------- bounded windows
def _stream(seed: int = 0):
    """A stream with a fast burst, a still gap and a slow stretch (event times in s)."""
    from evio_lib.events.array import make_events

    rng = np.random.default_rng(seed)
    t = np.sort(np.concatenate([rng.uniform(0.0, 0.1, 5000), rng.uniform(0.5, 1.0, 300)]))
    return make_events(t, rng.integers(0, 20, t.size), rng.integers(0, 10, t.size), np.ones(t.size))


def test_bounded_count_windows_without_bounds_match_count_windows():
    from evio_lib.events.representations import bounded_count_windows, count_windows

    ev = _stream()
    bounds, ends = bounded_count_windows(ev, 700)
    np.testing.assert_array_equal(bounds, count_windows(ev, 700))
    np.testing.assert_array_equal(ends, ev["t"][bounds[:, 1] - 1])


@pytest.mark.parametrize("n_events, low, high", [(700, 0.0, 0.05), (200, 0.02, None), (100, 0.01, 0.03)])
def test_bounded_count_windows_keep_their_bounds(n_events, low, high):
    from evio_lib.events.representations import bounded_count_windows

    ev = _stream(1)
    t = ev["t"]
    bounds, ends = bounded_count_windows(ev, n_events, low, high, t_start=0.0, t_end=1.0)
    starts = np.concatenate([[0.0], ends[:-1]])
    assert np.all(bounds[1:, 0] == bounds[:-1, 1]) and bounds[0, 0] == 0  # consecutive, nothing skipped
    assert np.all(ends <= 1.0) and np.all(np.diff(ends) > 0)
    counts = bounds[:, 1] - bounds[:, 0]
    length = ends - starts
    assert np.all(length >= low - 1e-12)
    if high is not None:
        assert np.all(length <= high + 1e-12)
    capped = np.isclose(length, high) if high is not None else np.zeros(len(ends), bool)
    # a window that was not capped closed on its N_e-th event or at the least duration, whichever came later
    assert np.all(counts[~capped] >= n_events)
    for (a, b), t0, t1 in zip(bounds, starts, ends):  # every event of the window lies inside it
        assert np.all((t[a:b] >= t0 - 1e-12) & (t[a:b] <= t1 + 1e-12))
    if high is not None:  # the still gap [0.1, 0.5] s still gets frames
        assert np.count_nonzero((ends > 0.12) & (ends < 0.5)) >= int(0.35 / high)


def test_bounded_count_windows_refuse_bad_bounds():
    from evio_lib.events.representations import bounded_count_windows

    ev = _stream()
    with pytest.raises(ValueError, match="max_duration"):
        bounded_count_windows(ev, 100, 0.05, 0.05)
    with pytest.raises(ValueError, match="min_duration"):
        bounded_count_windows(ev, 100, -1.0)
    with pytest.raises(ValueError, match="n_events"):
        bounded_count_windows(ev, 0)
    with pytest.raises(ValueError, match="windows"):
        bounded_count_windows(ev, 1, 0.0, 1e-9)
