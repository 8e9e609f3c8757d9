"""Tests for evio_lib.events.simulate: the ESIM-style event generator and its adaptive sampler."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from evio_lib.events.array import EVENT_DTYPE, validate_events
from evio_lib.events.simulate import EventCameraParams, EventSimulator, log_intensity, simulate_events

IDEAL = EventCameraParams(contrast_sigma=0.0, refractory_s=0.0)  # no mismatch, no refractory, no noise


# --- scenes ----------------------------------------------------------------------------------------------------


def moving_texture(width: int, height: int, speed_px_s: float, seed: int = 0):
    """Return render(t): a smooth texture (sum of random sinusoids) translating along x at speed_px_s."""
    r = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    waves = [(r.uniform(0.15, 0.6), r.uniform(-0.4, 0.4), r.uniform(0, 2 * np.pi), r.uniform(0.1, 0.2))
             for _ in range(4)]

    def render(t: float) -> np.ndarray:
        u = xx - speed_px_s * t
        img = 0.5 + sum(a * np.sin(kx * u + ky * yy + ph) for kx, ky, ph, a in waves)
        return np.clip(img, 0.02, 1.0).astype(np.float32)

    return render


def ramp_render(log0: float, slope: float, eps: float = 1e-3):
    """Return render(t) for one pixel whose log intensity is exactly L(t) = log0 + slope * t."""
    return lambda t: np.array([[np.exp(log0 + slope * t) - eps]])


def run_steps(sim: EventSimulator, render, times, eps: float = 1e-3) -> np.ndarray:
    """Reset sim at times[0] and step through the remaining times; return all events."""
    sim.reset(log_intensity(render(times[0]), eps), times[0])
    chunks = [sim.step(log_intensity(render(t), eps), t) for t in times[1:]]
    return np.concatenate(chunks)


def esim_reference(logs, times, c_pos, c_neg, refractory):
    """Independent truth: a plain per-pixel loop of the ESIM rules (one crossing at a time)."""
    h, w = logs[0].shape
    ref = logs[0].astype(np.float64).copy()
    last = np.full((h, w), -np.inf)
    out = []
    for s in range(1, len(times)):
        t0, t1, l0, l1 = times[s - 1], times[s], logs[s - 1], logs[s]
        for y in range(h):
            for x in range(w):
                while True:
                    r = ref[y, x]
                    if l1[y, x] >= r + c_pos[y, x]:
                        pol, level = 1, r + c_pos[y, x]
                    elif l1[y, x] <= r - c_neg[y, x]:
                        pol, level = -1, r - c_neg[y, x]
                    else:
                        break
                    te = t0 + (level - l0[y, x]) / (l1[y, x] - l0[y, x]) * (t1 - t0)
                    if te - last[y, x] >= refractory:
                        out.append((te, x, y, pol))
                        last[y, x] = te
                    ref[y, x] = level
    return out


# --- closed form -----------------------------------------------------------------------------------------------

SAMPLINGS = {
    "one step": [0.0, 1.0],
    "two steps": [0.0, 0.37, 1.0],
    "on the thresholds": [0.0, 0.2, 0.4, 0.6, 0.8, 1.0],
    "1 kHz": list(np.linspace(0.0, 1.0, 1001)),
    "random": [0.0] + sorted(np.random.default_rng(3).uniform(0.0, 1.0, 57)) + [1.0],
}


@pytest.mark.parametrize("sampling", SAMPLINGS.values(), ids=SAMPLINGS.keys())
def test_linear_ramp_gives_exact_events_for_any_render_rate(sampling):
    sim = EventSimulator(1, 1, EventCameraParams(contrast_pos=0.2, contrast_neg=0.25, contrast_sigma=0.0))
    ev = run_steps(sim, ramp_render(np.log(0.3), +1.0), sampling)  # L rises by 1.0 over 1 s, C+ = 0.2
    assert ev.shape == (5,)
    np.testing.assert_allclose(ev["t"], [0.2, 0.4, 0.6, 0.8, 1.0], atol=1e-9, rtol=0)
    assert (ev["p"] == 1).all() and (ev["x"] == 0).all() and (ev["y"] == 0).all()

    sim = EventSimulator(1, 1, EventCameraParams(contrast_pos=0.2, contrast_neg=0.25, contrast_sigma=0.0))
    ev = run_steps(sim, ramp_render(np.log(0.9), -1.0), sampling)  # L falls by 1.0, C- = 0.25
    np.testing.assert_allclose(ev["t"], [0.25, 0.5, 0.75, 1.0], atol=1e-9, rtol=0)
    assert (ev["p"] == -1).all()


def test_crossing_exactly_at_the_sample_is_not_lost_to_round_off():
    # 0.6 / 0.2 = 2.9999999999999996 in float64 and 0.062 + (0.783 - 0.062) = 0.7830000000000001 > 0.783:
    # the third crossing still fires, at (not after) the sample time
    sim = EventSimulator(1, 1, IDEAL)
    sim.reset(np.zeros((1, 1)), 0.062)
    ev = sim.step(np.full((1, 1), 0.6), 0.783)
    assert ev.shape == (3,)
    np.testing.assert_allclose(ev["t"], 0.062 + 0.721 * np.array([1, 2, 3]) / 3, atol=1e-12, rtol=0)
    assert ev["t"][-1] <= 0.783
    assert sim.step(np.full((1, 1), 0.6), 1.0).shape == (0,)  # and nothing is left over for the next step


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(
    log0=st.floats(-3.5, -0.5),  # L stays above log(eps) = -6.9 for |slope| <= 3
    slope=st.floats(-3.0, 3.0),
    contrast=st.floats(0.05, 0.5),
    n_steps=st.integers(1, 20),
    seed=st.integers(0, 2**16),
)
def test_linear_ramp_property(log0, slope, contrast, n_steps, seed):
    ratio = abs(slope) / contrast
    assume(abs(slope) > 0.01 and 0.01 < ratio - np.floor(ratio) < 0.99)  # stay clear of a threshold at t = 1
    times = np.concatenate([[0.0], np.sort(np.random.default_rng(seed).uniform(0, 1, n_steps - 1)), [1.0]])
    params = EventCameraParams(contrast_pos=contrast, contrast_neg=contrast, contrast_sigma=0.0, refractory_s=0.0)
    ev = run_steps(EventSimulator(1, 1, params), ramp_render(log0, slope), times)
    k = np.arange(1, int(np.floor(ratio)) + 1)
    np.testing.assert_allclose(ev["t"], k * contrast / abs(slope), atol=1e-9, rtol=0)  # t_k = k C / |slope|
    assert (ev["p"] == np.sign(slope)).all()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_matches_bruteforce_esim_loop_with_mismatch_and_refractory(dtype):
    w, h = 12, 10
    render = moving_texture(w, h, speed_px_s=60.0, seed=1)
    times = np.concatenate([[0.0], np.cumsum(np.random.default_rng(5).uniform(2e-3, 12e-3, 40))])  # coarse steps
    logs = [log_intensity(render(t).astype(dtype)) for t in times]
    assert logs[0].dtype == dtype
    params = EventCameraParams(contrast_sigma=0.05, refractory_s=4e-3)
    sim = EventSimulator(w, h, params, rng=np.random.default_rng(7))
    sim.reset(logs[0], times[0])
    ev = np.concatenate([sim.step(lg, t) for lg, t in zip(logs[1:], times[1:])])
    expected = esim_reference(logs, times, sim.thresholds_pos, sim.thresholds_neg, params.refractory_s)
    assert sim.dropped_refractory > 0  # the refractory rule was exercised
    assert len(expected) > 300 and ev.shape[0] == len(expected)
    exp = np.array(expected, dtype=[("t", "f8"), ("x", "i8"), ("y", "i8"), ("p", "i8")])
    exp = exp[np.lexsort((exp["x"], exp["y"], exp["t"]))]
    got = ev[np.lexsort((ev["x"], ev["y"], ev["t"]))]
    np.testing.assert_allclose(got["t"], exp["t"], atol=1e-12, rtol=0)
    for f in ("x", "y", "p"):
        np.testing.assert_array_equal(got[f], exp[f])


# --- conservation, convergence, refractory ---------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sum_of_polarities_times_threshold_tracks_log_change(dtype):
    w, h = 40, 30
    texture = moving_texture(w, h, speed_px_s=150.0, seed=2)
    render = lambda t: texture(t).astype(dtype)  # noqa: E731
    params = EventCameraParams(contrast_sigma=0.03, refractory_s=0.0)
    sim = EventSimulator(w, h, params, rng=np.random.default_rng(1))
    times = np.linspace(0.0, 0.3, 151)
    ev = run_steps(sim, render, times)
    c_pos, c_neg = sim.thresholds_pos, sim.thresholds_neg
    assert np.std(c_pos) > 0.02  # mismatch is on
    contrib = np.where(ev["p"] > 0, c_pos[ev["y"], ev["x"]], -c_neg[ev["y"], ev["x"]])
    s = np.zeros((h, w))
    np.add.at(s, (ev["y"].astype(int), ev["x"].astype(int)), contrib)  # sum_k p_k C_k per pixel
    change = log_intensity(render(times[-1])) - log_intensity(render(times[0]))
    residual = change - s
    assert np.abs(s).max() > 1.0  # pixels fired many events
    assert (residual < c_pos + 1e-9).all() and (residual > -c_neg - 1e-9).all()  # within one threshold


def test_log_intensity_stays_within_one_threshold_of_reference_with_refractory():
    w, h = 20, 15
    render = moving_texture(w, h, speed_px_s=400.0, seed=3)
    sim = EventSimulator(w, h, EventCameraParams(refractory_s=2e-3), rng=np.random.default_rng(2))
    times = np.linspace(0.0, 0.1, 26)
    run_steps(sim, render, times)
    assert sim.dropped_refractory > 0
    residual = log_intensity(render(times[-1])) - sim.reference
    assert (residual < sim.thresholds_pos).all() and (residual > -sim.thresholds_neg).all()


def test_event_count_is_independent_of_render_rate_once_fine():
    w, h = 48, 36
    render = moving_texture(w, h, speed_px_s=100.0, seed=4)
    counts = []
    for n_steps in (200, 400, 800):  # 1 ms, 0.5 ms, 0.25 ms
        sim = EventSimulator(w, h, EventCameraParams(), rng=np.random.default_rng(0))
        counts.append(run_steps(sim, render, np.linspace(0.0, 0.2, n_steps + 1)).shape[0])
    assert counts[0] > 5000
    assert abs(counts[1] - counts[0]) / counts[2] < 0.01
    assert abs(counts[2] - counts[0]) / counts[2] < 0.01


def test_refractory_period_is_respected():
    w, h = 20, 15
    render = moving_texture(w, h, speed_px_s=500.0, seed=5)
    refractory = 3e-3
    times = np.linspace(0.0, 0.1, 21)  # 5 ms steps: several crossings per pixel and step
    sim = EventSimulator(w, h, EventCameraParams(refractory_s=refractory), rng=np.random.default_rng(3))
    ev = run_steps(sim, render, times)
    free_sim = EventSimulator(w, h, EventCameraParams(refractory_s=0.0), rng=np.random.default_rng(3))
    free = run_steps(free_sim, render, times)
    assert sim.dropped_refractory > 0 and ev.shape[0] + sim.dropped_refractory == free.shape[0]
    pix = ev["y"].astype(int) * w + ev["x"]
    order = np.lexsort((ev["t"], pix))
    same_pixel = pix[order][1:] == pix[order][:-1]
    gaps = np.diff(ev["t"][order])[same_pixel]
    assert gaps.size > 100 and gaps.min() >= refractory - 1e-12


# --- output format, determinism, no side effects ---------------------------------------------------------------


def test_output_format_sorted_in_range_and_in_interval(rng):
    w, h = 30, 20
    render = moving_texture(w, h, speed_px_s=300.0, seed=6)
    params = EventCameraParams(background_rate_hz=2.0, leak_rate_hz=1.0)
    sim = EventSimulator(w, h, params, rng=rng)
    sim.reset(log_intensity(render(0.0)), 0.0)
    t_prev = 0.0
    for t in np.linspace(0.0, 0.05, 11)[1:]:
        ev = sim.step(log_intensity(render(t)), t)
        assert ev.dtype == EVENT_DTYPE
        validate_events(ev, w, h)
        assert ev.shape[0] > 0 and ev["t"].min() > t_prev and ev["t"].max() <= t
        assert sim.time == t
        t_prev = t


def test_deterministic_for_a_seed():
    w, h = 16, 12
    render = moving_texture(w, h, speed_px_s=200.0, seed=7)
    params = EventCameraParams(background_rate_hz=20.0, leak_rate_hz=5.0)
    times = np.linspace(0.0, 0.05, 26)
    a = run_steps(EventSimulator(w, h, params, rng=np.random.default_rng(11)), render, times)
    b = run_steps(EventSimulator(w, h, params, rng=11), render, times)  # an int seed means default_rng(seed)
    c = run_steps(EventSimulator(w, h, params, rng=np.random.default_rng(12)), render, times)
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)


def test_inputs_are_not_modified_and_state_is_copied():
    w, h = 16, 12
    render = moving_texture(w, h, speed_px_s=200.0, seed=8)
    l0 = log_intensity(render(0.0)).astype(np.float32)
    l1 = log_intensity(render(0.02)).astype(np.float32)
    l2 = log_intensity(render(0.04)).astype(np.float32)
    copies = [l0.copy(), l1.copy(), l2.copy()]
    sim = EventSimulator(w, h, EventCameraParams(), rng=np.random.default_rng(0))
    sim.reset(l0, 0.0)
    l0[:] = 99.0  # the caller reuses its buffers: the simulator must hold its own copies
    e1 = sim.step(l1, 0.02)
    l1[:] = -99.0
    e2 = sim.step(l2, 0.04)
    np.testing.assert_array_equal(l2, copies[2])
    ref = EventSimulator(w, h, EventCameraParams(), rng=np.random.default_rng(0))
    ref.reset(copies[0], 0.0)
    np.testing.assert_array_equal(e1, ref.step(copies[1], 0.02))
    np.testing.assert_array_equal(e2, ref.step(copies[2], 0.04))


# --- thresholds and noise --------------------------------------------------------------------------------------


def test_threshold_mismatch_statistics_and_floor():
    sim = EventSimulator(100, 80, EventCameraParams(contrast_pos=0.3, contrast_neg=0.2, contrast_sigma=0.03), rng=0)
    assert sim.thresholds_pos.shape == (80, 100)
    assert abs(sim.thresholds_pos.mean() - 0.3) < 0.002 and abs(sim.thresholds_pos.std() - 0.03) < 0.002
    assert abs(sim.thresholds_neg.mean() - 0.2) < 0.002 and abs(sim.thresholds_neg.std() - 0.03) < 0.002
    assert not np.array_equal(sim.thresholds_pos, sim.thresholds_neg + 0.1)  # independent draws
    with pytest.raises(ValueError, match="read-only"):
        sim.thresholds_pos[0, 0] = 1.0
    floored = EventSimulator(50, 50, EventCameraParams(contrast_sigma=0.3, min_contrast=0.05), rng=1)
    assert floored.thresholds_neg.min() == 0.05 and (floored.thresholds_neg == 0.05).sum() > 100
    exact = EventSimulator(5, 4, IDEAL)
    assert (exact.thresholds_pos == 0.2).all() and (exact.thresholds_neg == 0.2).all()


def test_background_and_leak_noise_are_poisson_with_the_given_rates():
    w, h, duration = 40, 30, 2.0
    static = np.full((h, w), np.log(0.5))
    params = EventCameraParams(contrast_sigma=0.0, background_rate_hz=3.0, leak_rate_hz=1.0)
    sim = EventSimulator(w, h, params, rng=np.random.default_rng(4))
    sim.reset(static, 0.0)
    times = np.linspace(0.0, duration, 41)
    ev = np.concatenate([sim.step(static, t) for t in times[1:]])
    validate_events(ev, w, h)
    n_pix = w * h
    expected_pos = (0.5 * 3.0 + 1.0) * n_pix * duration  # half the background plus all leak events
    expected_neg = 0.5 * 3.0 * n_pix * duration
    n_pos, n_neg = int((ev["p"] > 0).sum()), int((ev["p"] < 0).sum())
    assert abs(n_pos - expected_pos) < 5 * np.sqrt(expected_pos)
    assert abs(n_neg - expected_neg) < 5 * np.sqrt(expected_neg)
    # uniform over pixels and time: chi-square-like sanity on coarse bins
    assert abs(np.mean(ev["x"]) - (w - 1) / 2) < 0.5 and abs(np.mean(ev["t"]) - duration / 2) < 0.05


# --- adaptive sampling -----------------------------------------------------------------------------------------


def test_simulate_events_closed_form_ramp():
    ev, samples = simulate_events(ramp_render(np.log(0.2), 1.0), 0.0, 1.0, 1, 1, IDEAL, dt_max=0.05)
    np.testing.assert_allclose(ev["t"], [0.2, 0.4, 0.6, 0.8, 1.0], atol=1e-9, rtol=0)
    assert samples[0] == 0.0 and samples[-1] == 1.0 and (np.diff(samples) > 0).all()
    # bound: 0.5 * 0.2 = 0.1 per sample at slope 1/s, so at least 10 steps
    assert len(samples) >= 11


def _run_adaptive(render, w, h, max_log_change=0.5, t_end=0.1, **kw):
    grabbed, renders = [], []

    def counting_render(t):
        renders.append(t)
        return render(t)

    ev, samples = simulate_events(
        counting_render, 0.0, t_end, w, h, EventCameraParams(), rng=np.random.default_rng(0),
        max_log_change=max_log_change, on_sample=lambda t, img: grabbed.append((t, img.copy())), **kw,
    )
    return ev, samples, grabbed, renders


def test_adaptive_sampling_bound_holds_and_density_grows_with_speed():
    w, h = 24, 18
    bound = 0.5 * 0.2
    n_samples = []
    for speed in (100.0, 300.0):
        ev, samples, grabbed, renders = _run_adaptive(moving_texture(w, h, speed, seed=9), w, h)
        validate_events(ev, w, h)
        np.testing.assert_array_equal([t for t, _ in grabbed], samples)
        logs = [log_intensity(img) for _, img in grabbed]
        changes = [np.abs(b - a).max() for a, b in zip(logs[:-1], logs[1:])]
        assert max(changes) <= bound
        assert max(changes) > 0.5 * bound  # the sampler does not waste renders either
        assert (np.diff(samples) <= 5e-3 + 1e-15).all()
        assert len(renders) <= 1.2 * len(samples)  # the dt prediction is rarely rejected at constant speed
        n_samples.append(len(samples))
    assert n_samples[1] > 2.0 * n_samples[0]


def test_adaptive_sampling_rerenders_when_motion_starts_suddenly():
    w, h = 24, 18
    moving = moving_texture(w, h, 800.0, seed=10)
    render = lambda t: moving(max(t - 0.05, 0.0))  # static until 0.05 s, then fast  # noqa: E731
    ev, samples, grabbed, renders = _run_adaptive(render, w, h)
    logs = [log_intensity(img) for _, img in grabbed]
    assert max(np.abs(b - a).max() for a, b in zip(logs[:-1], logs[1:])) <= 0.1  # guaranteed, not just predicted
    assert len(renders) > len(samples)  # some predictions were rejected and re-rendered
    assert np.diff(samples)[: 5].min() > 4e-3 and np.diff(samples)[-5:].max() < 1e-3


def test_adaptive_sampling_warns_when_dt_min_cannot_meet_the_bound():
    render = lambda t: np.full((2, 2), 0.1 if t < 0.05 else 0.9)  # noqa: E731  (a step in intensity)
    with pytest.warns(RuntimeWarning, match="exceeded max_log_change even at dt_min"):
        ev, samples = simulate_events(render, 0.0, 0.1, 2, 2, IDEAL)
    assert ev.shape[0] == 4 * 10 and (ev["p"] == 1).all()  # log(0.901/0.101) = 2.19 -> 10 events per pixel


def test_simulate_events_progress_bar_runs(capsys):
    ev, samples = simulate_events(ramp_render(np.log(0.2), 1.0), 0.0, 0.1, 1, 1, IDEAL, progress=True)
    assert samples[-1] == 0.1


# --- bad input -------------------------------------------------------------------------------------------------


def test_step_rejects_bad_input():
    sim = EventSimulator(4, 3, IDEAL)
    with pytest.raises(RuntimeError, match=r"reset"):
        sim.step(np.zeros((3, 4)), 1.0)
    sim.reset(np.zeros((3, 4)), 0.0)
    with pytest.raises(ValueError, match=r"log_image must have shape \(H, W\) = \(3, 4\); got \(4, 3\)"):
        sim.step(np.zeros((4, 3)), 1.0)
    with pytest.raises(ValueError, match=r"t must be strictly increasing; got t=0.0 after previous sample t=0.0"):
        sim.step(np.zeros((3, 4)), 0.0)
    bad = np.zeros((3, 4))
    bad[2, 1] = np.nan
    message = r"log_image must be finite; 1 NaN/inf pixels, first at \(row, col\) = \(2, 1\)"
    with pytest.raises(ValueError, match=message):
        sim.step(bad, 1.0)
    with pytest.raises(ValueError, match=r"t must be a finite time"):
        sim.step(np.zeros((3, 4)), np.nan)
    with pytest.raises(ValueError, match=r"log_image must hold real numbers"):
        sim.step(np.full((3, 4), "a"), 1.0)
    sim.step(np.zeros((3, 4)), 0.5)  # the failed calls left the state untouched
    with pytest.raises(ValueError, match=r"t must be strictly increasing; got t=0.4"):
        sim.step(np.zeros((3, 4)), 0.4)


def test_constructor_and_params_reject_bad_input():
    with pytest.raises(ValueError, match=r"rng must be a numpy.random.Generator"):
        EventSimulator(4, 3, EventCameraParams(contrast_sigma=0.03))
    with pytest.raises(ValueError, match=r"rng must be a numpy.random.Generator"):
        EventSimulator(4, 3, EventCameraParams(contrast_sigma=0.0, background_rate_hz=1.0))
    with pytest.raises(ValueError, match=r"width must be an integer in \[1, 65536\]"):
        EventSimulator(0, 3, IDEAL)
    with pytest.raises(ValueError, match=r"contrast_pos must be > 0; got 0.0"):
        EventCameraParams(contrast_pos=0.0)
    with pytest.raises(ValueError, match=r"refractory_s must be >= 0"):
        EventCameraParams(refractory_s=-1e-3)
    with pytest.raises(ValueError, match=r"leak_rate_hz must be finite"):
        EventCameraParams(leak_rate_hz=np.nan)
    with pytest.raises(ValueError, match=r"params must be an EventCameraParams"):
        EventSimulator(4, 3, {"contrast_pos": 0.2})


def test_reset_accepts_linear_intensity():
    img = np.random.default_rng(0).uniform(0, 1, (3, 4)).astype(np.float32)
    sim = EventSimulator(4, 3, IDEAL)
    sim.reset(img, 0.0, is_log=False)
    np.testing.assert_allclose(sim.reference, np.log(img.astype(np.float64) + 1e-3), rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match=r"intensity must be finite and >= 0"):
        sim.reset(-img, 0.0, is_log=False)


def test_simulate_events_rejects_bad_input():
    ok = lambda t: np.full((3, 4), 0.5)  # noqa: E731
    with pytest.raises(ValueError, match=r"render\(t\) must return shape \(H, W\) = \(3, 4\); got \(4, 3\)"):
        simulate_events(lambda t: np.zeros((4, 3)), 0.0, 1.0, 4, 3, IDEAL)
    with pytest.raises(ValueError, match=r"intensity must be finite and >= 0"):
        simulate_events(lambda t: np.full((3, 4), np.nan), 0.0, 1.0, 4, 3, IDEAL)
    with pytest.raises(ValueError, match=r"t_end must be > t_start"):
        simulate_events(ok, 1.0, 1.0, 4, 3, IDEAL)
    with pytest.raises(ValueError, match=r"dt_min and dt_max must satisfy"):
        simulate_events(ok, 0.0, 1.0, 4, 3, IDEAL, dt_min=1e-2, dt_max=1e-3)
    with pytest.raises(ValueError, match=r"max_log_change must be > 0"):
        simulate_events(ok, 0.0, 1.0, 4, 3, IDEAL, max_log_change=0.0)
    with pytest.raises(ValueError, match=r"render must be a callable"):
        simulate_events(np.zeros((3, 4)), 0.0, 1.0, 4, 3, IDEAL)


def test_log_intensity():
    img = np.array([[0.0, 0.5], [1.0, 0.25]], np.float32)
    np.testing.assert_allclose(log_intensity(img, 1e-3), np.log(img.astype(np.float64) + 1e-3), rtol=0, atol=1e-6)
    np.testing.assert_allclose(log_intensity(img.astype(np.float64), 1e-3), np.log(img.astype(np.float64) + 1e-3),
                               rtol=1e-15)
    assert log_intensity(img).dtype == np.float32 and log_intensity(img.astype(np.float64)).dtype == np.float64
    assert log_intensity(np.array([0, 1])).dtype == np.float64  # integers too
    with pytest.raises(ValueError, match=r"log_eps must be > 0"):
        log_intensity(img, 0.0)


def test_change_quantile_lets_sampling_follow_smooth_motion_past_a_discontinuity():
    """A hard edge jumps by a whole log unit however short the step; a quantile bound ignores those few pixels."""
    width, height = 64, 48
    xx = np.arange(width)[None, :].repeat(height, axis=0)

    def render(t: float) -> np.ndarray:
        ramp = 0.3 + 0.2 * np.sin(0.2 * (xx - 300.0 * t))  # smooth texture moving at 300 px/s
        edge = np.where(xx < 10 + 30.0 * t, 0.05, 1.0)  # an occlusion-like step edge moving at 30 px/s
        return (ramp * edge).astype(np.float32)

    params = EventCameraParams(contrast_sigma=0.0, refractory_s=0.0)
    with pytest.warns(RuntimeWarning, match="exceeded max_log_change"):
        events_max, times_max = simulate_events(render, 0.0, 0.2, width, height, params, dt_min=1e-4)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no sample may need dt_min any more
        events_q, times_q = simulate_events(render, 0.0, 0.2, width, height, params, dt_min=1e-4,
                                            change_quantile=0.95)
    assert np.diff(times_q).max() < 5e-3  # the smooth motion still limits the step below dt_max ...
    assert len(times_q) < len(times_max)  # ... with fewer renders (none wasted at dt_min) ...
    assert abs(len(events_q) - len(events_max)) <= 0.01 * len(events_max)  # ... for the same events
    with pytest.raises(ValueError, match="change_quantile must be in"):
        simulate_events(render, 0.0, 0.1, width, height, params, change_quantile=0.0)
