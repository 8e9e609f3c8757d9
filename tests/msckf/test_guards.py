"""Tests of the MSCKF's input guards and step checks: IMU range limits and unit mistakes, IMU gaps
(covariance inflation against a closed form, the stop beyond the bridged limit, consistency on the simulator's
ground truth), pixel coordinates given as observations, and the check after every propagation and update (the
returned states are always finite, P always a covariance). The simulated runs are vio-sim's (boxes_like, seeded).

``BAD_INPUTS`` is the table-driven part: each bad input is injected into one running filter; the state must stay
finite with a usable covariance after every one of them."""
import dataclasses
import warnings

import numpy as np
import pytest

from evio_lib.msckf import updater as updater_module
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.experiment import (
    VioSimConfig,
    _streams,
    experiment_msckf_config,
    initial_state,
    observation_covariance,
    simulate_data,
)
from evio_lib.msckf.filter import Msckf, MsckfWarning
from evio_lib.msckf.imu_buffer import StepRefusedError
from evio_lib.msckf.propagation import ImuGapError, imu_gaps, propagate
from evio_lib.msckf.state import FilterState, ImuState, covariance_problem, state_problem
from evio_lib.msckf.augmentation import augment_state


@pytest.fixture(scope="module")
def sim():
    """2.5 s of boxes_like (seed 0): 1 kHz noisy IMU, 49 images of ~60 exact-association tracks."""
    config = VioSimConfig(preset="boxes_like", duration=2.5, seed=0)
    data = simulate_data(config)
    msckf_config = experiment_msckf_config(config, data.noise, data.camera)
    return data, msckf_config, initial_state(data, msckf_config, _streams(config.seed)[2])


def run(sim, t=None, gyro=None, accel=None, frames=None, **overrides):
    """Return (outputs, filter, warnings) of a run on the simulation, with optional replaced inputs / config."""
    data, cfg, state = sim
    cfg = dataclasses.replace(cfg, **overrides) if overrides else cfg
    imu = data.imu
    f = Msckf(cfg, state)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        f.feed_imu(imu.t if t is None else t, imu.gyro if gyro is None else gyro, imu.accel if accel is None else accel)
        frames = [(fr.t, fr.ids, fr.xy) for fr in data.frames] if frames is None else frames
        outputs = [f.process_image(*frame) for frame in frames]
    return outputs, f, [w for w in caught if issubclass(w.category, MsckfWarning)]


def assert_usable(outputs, f):
    for o in outputs:
        for value in (o.q_GtoI, o.p_IinG, o.v_IinG, o.b_g, o.b_a, o.P_imu):
            assert np.all(np.isfinite(value))
        assert covariance_problem(o.P_imu) is None
    assert state_problem(f.state) is None


def assert_same_run(a, b):
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.p_IinG, y.p_IinG)
        np.testing.assert_array_equal(x.P_imu, y.P_imu)


def position_error(sim, outputs):
    data = sim[0]
    t = np.array([o.t for o in outputs])
    return np.array([o.p_IinG for o in outputs]) - data.trajectory.evaluate(t).p_IinG


# ---------------------------------------------------------------- IMU range


def test_default_range_is_a_typical_mems_imu_and_is_validated():
    cfg = MsckfConfig()
    assert cfg.accel_full_scale == pytest.approx(16 * 9.80665) and cfg.gyro_full_scale == pytest.approx(34.906585)
    assert (cfg.imu_max_gap, cfg.imu_max_bridged_gap, cfg.max_normalized_coordinate) == (0.05, 0.3, 10.0)
    assert MsckfConfig(accel_full_scale=np.inf).accel_full_scale == np.inf  # inf switches a guard off
    for changes, message in (({"gyro_full_scale": 0.0}, "gyro_full_scale must be a number > 0"),
                             ({"imu_max_gap": float("nan")}, "imu_max_gap must be a number > 0"),
                             ({"imu_gap_accel_sigma": -1.0}, "imu_gap_accel_sigma must be >= 0"),
                             ({"imu_max_bridged_gap": 0.01}, "imu_max_bridged_gap must be >= imu_max_gap")):
        with pytest.raises(ValueError, match=message):
            MsckfConfig(**changes)


@pytest.mark.parametrize(("value", "count"), [(1e200, 1), (1e6, 10)])
def test_out_of_range_accel_samples_are_dropped_counted_and_warned(sim, value, count):
    """Issue 17: one sample of 1e200 m/s^2 made the position 1e195 and P NaN; 1e6 m/s^2 for 10 ms gave 34 km.
    Now the samples are dropped: the run equals the one whose input never held them, and the user is told."""
    imu = sim[0].imu
    bad = np.arange(1200, 1200 + count)
    accel = imu.accel.copy()
    accel[bad, 0] = value
    outputs, f, caught = run(sim, accel=accel)
    keep = np.ones(len(imu.t), dtype=bool)
    keep[bad] = False
    reference, _, _ = run(sim, t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep])
    assert_same_run(outputs, reference)
    assert_usable(outputs, f)
    assert f.faults == {"imu_accel_out_of_range": count}
    assert len(caught) == 1 and "beyond the accelerometer's full scale ±156.9 m/s^2" in str(caught[0].message)
    assert np.linalg.norm(position_error(sim, outputs)[-1]) < 0.2


def test_wrong_units_are_refused_naming_the_units_expected(sim):
    imu = sim[0].imu
    f = Msckf(sim[1], sim[2])
    with pytest.raises(ValueError, match=r"gyro must be in rad/s: \d+ of the 2501 samples fed exceed the gyro's full "
                                         r"scale ±34.91 rad/s \(2000 deg/s.*look like deg/s \(np.radians"):
        f.feed_imu(imu.t, np.degrees(imu.gyro), imu.accel)
    with pytest.raises(ValueError, match=r"accel must be the specific force in m/s\^2: .*check the units"):
        f.feed_imu(imu.t, imu.gyro, imu.accel / 9.81 * 1000.0)  # mg
    assert not f.faults  # nothing of a refused batch is kept or counted
    with pytest.raises(ValueError, match="no IMU samples buffered"):
        f.process_image(0.05, [1], [[0.0, 0.0]])
    # the same stream fed one sample at a time: the first samples beyond the range are dropped and warned about,
    # then the share beyond it (> 10 % of >= 10 samples) stops the stream
    spin = np.tile([0.0, 0.0, np.degrees(3.0)], (len(imu.t), 1))  # 3 rad/s given in deg/s
    g = Msckf(sim[1], sim[2])
    with pytest.warns(MsckfWarning, match="deg/s"), pytest.raises(ValueError, match="gyro must be in rad/s"):
        for k in range(len(imu.t)):
            g.feed_imu(imu.t[k], spin[k], imu.accel[k])
    assert k == 9 and g.faults["imu_gyro_out_of_range"] == 9


def test_a_gyro_stream_within_range_that_looks_like_deg_s_is_reported_once(sim):
    imu = sim[0].imu
    slow_spin_deg = np.tile([0.0, 0.0, np.degrees(0.3)], (len(imu.t), 1))  # 17.2 "rad/s": in range, > 2π
    f = Msckf(sim[1], sim[2])
    with pytest.warns(MsckfWarning, match=r"gyro must be in rad/s: 200 of the 200 samples fed turn faster than one "
                                          r"revolution per second .* looks like deg/s"):
        f.feed_imu(imu.t[:200], slow_spin_deg[:200], imu.accel[:200])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f.feed_imu(imu.t[200:], slow_spin_deg[200:], imu.accel[200:])  # said once
        Msckf(sim[1], sim[2]).feed_imu(imu.t, imu.gyro, imu.accel)  # the real rad/s stream: no word
    assert f.faults == {"gyro_units_suspect": 1}


# ---------------------------------------------------------------- observations


def test_pixel_coordinates_are_refused_naming_normalised_coordinates(sim):
    data = sim[0]
    f = Msckf(sim[1], sim[2])
    f.feed_imu(data.imu.t, data.imu.gyro, data.imu.accel)
    frame = data.frames[0]
    with pytest.raises(ValueError, match=r"xy must be undistorted normalised image coordinates \(X/Z, Y/Z\), \|x\|, "
                                         r"\|y\| <= 10 .*got \d+ of \d+ observations beyond it.*pixel coordinates\? "
                                         r"Convert distorted pixels with camera.unproject\(uv\)"):
        f.process_image(frame.t, frame.ids, frame.uv)
    assert f.state is sim[2]  # nothing changed


def test_an_observation_outside_any_field_of_view_is_dropped(sim):
    frames = [(fr.t, fr.ids, fr.xy) for fr in sim[0].frames]
    t, ids, xy = frames[20]
    bad = xy.copy()
    bad[3] = [50.0, -1.0]
    outputs, f, caught = run(sim, frames=frames[:20] + [(t, ids, bad)] + frames[21:])
    reference, _, _ = run(sim, frames=frames[:20] + [(t, np.delete(ids, 3), np.delete(xy, 3, axis=0))] + frames[21:])
    assert_same_run(outputs, reference)
    assert f.faults == {"observation_out_of_view": 1} and "dropped 1 observation(s)" in str(caught[0].message)


# ---------------------------------------------------------------- the check after every step


def test_covariance_problem_names_what_is_wrong_and_is_scale_free(rng):
    A = rng.normal(size=(21, 21))
    P = A @ A.T * np.repeat([1e-12, 1e4, 1.0], 7)[:, None] ** 0.5 * np.repeat([1e-12, 1e4, 1.0], 7) ** 0.5
    assert covariance_problem(P) is None
    assert covariance_problem(np.zeros((15, 15))) is None  # zero variances (a noise-free start) are fine
    singular = augment_state(FilterState.initial(ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), 0.0),
                                                 np.eye(3), np.zeros(3), np.eye(15) * 1e-6), 0).P
    assert np.linalg.eigvalsh(singular).min() < 1e-12 and covariance_problem(singular) is None  # a fresh clone
    cases = [(np.where(np.eye(21) > 0, np.nan, P), "P holds 21 non-finite values"),
             (P - np.diag(np.diag(P)) * 2, "negative variances"),
             (P + np.triu(np.full((21, 21), 1e-3 * P.max()), 1), "P is not symmetric"),
             (np.array([[1.0, 2.0], [2.0, 1.0]]), "not positive semi-definite"),
             (np.array([[0.0, 1e-9], [1e-9, 1.0]]), r"variance 0 at index 0 with non-zero covariances")]
    for bad, message in cases:
        assert message in (covariance_problem(bad) or "") or pytest.fail(f"{message!r}: {covariance_problem(bad)}")
    assert covariance_problem(np.array([[1.0, 2.0], [2.0, 1.0]]), psd_size=1) is None


def test_a_propagation_that_would_leave_a_non_finite_state_is_refused(sim):
    """Guards off (range inf): a 1e200 sample reaches the propagation, whose result is refused: StepRefusedError,
    the state before the step is kept and counted. An image time of 1e200 s does the same."""
    data, cfg, state = sim
    imu = data.imu
    accel = imu.accel.copy()
    accel[1000, 2] = 1e200
    cfg = dataclasses.replace(cfg, accel_full_scale=np.inf, imu_max_bridged_gap=np.inf, imu_max_gap=np.inf)
    f = Msckf(cfg, state)
    f.feed_imu(imu.t, imu.gyro, accel)
    outputs = [f.process_image(fr.t, fr.ids, fr.xy) for fr in data.frames[:19]]
    before = f.state
    with pytest.raises(StepRefusedError, match=r"propagation from t = 0.950 s to t = 1.000 s refused: .*non-finite.*keeps "
                                               r"its state at t = 0.950 s"):
        f.process_image(data.frames[19].t, data.frames[19].ids, data.frames[19].xy)
    assert f.state is before and f.faults == {"propagation_refused": 1}
    assert_usable(outputs, f)
    g = Msckf(cfg, state)
    g.feed_imu(imu.t, imu.gyro, imu.accel)
    with pytest.raises(StepRefusedError, match="refused"):
        g.process_image(1e200, [1], [[0.0, 0.0]])
    assert g.state is state


@pytest.mark.parametrize("corruption", ["nan", "not_psd", "raises"])
def test_an_update_that_fails_the_check_is_rolled_back_and_the_filter_goes_on(sim, monkeypatch, corruption):
    real = updater_module.kalman_update
    calls = []

    def corrupted(P, H, r, sigma):
        dx, P_new = real(P, H, r, sigma)
        calls.append(1)
        if len(calls) != 3:
            return dx, P_new
        if corruption == "raises":
            raise ValueError("P must be positive semi-definite")
        P_new = P_new.copy()
        if corruption == "nan":
            P_new[0, 0] = np.nan
        else:
            P_new[12:15, 12:15] -= 10.0 * np.eye(3)
        return dx, P_new

    monkeypatch.setattr(updater_module, "kalman_update", corrupted)
    outputs, f, caught = run(sim)
    assert_usable(outputs, f)
    assert f.faults == {"update_refused": 1} and len(caught) == 1
    assert "refused and rolled back" in str(caught[0].message)


# ---------------------------------------------------------------- IMU gaps


def test_imu_gaps_lists_gaps_between_before_and_after_the_samples():
    t = np.array([0.0, 0.01, 0.5, 0.51, 0.52])
    np.testing.assert_allclose(imu_gaps(t, 0.0, 0.6, 0.05), [[0.01, 0.5], [0.52, 0.6]])
    np.testing.assert_allclose(imu_gaps(t, 0.2, 0.3, 0.05), [[0.01, 0.5]])  # inside one gap
    np.testing.assert_allclose(imu_gaps(t + 1.0, 0.0, 1.01, 0.05), [[0.0, 1.0]])  # the IMU starts late
    assert imu_gaps(t, 0.0, 0.01, 0.05).shape == (0, 2)


def test_gap_noise_inflation_matches_the_closed_form():
    """Free fall without rotation (a = 0, ω = 0), noise densities and P0 zero, samples at 0 and T only: the gap
    noise alone gives var δθ = σ_g² T², var δv = σ_a² T², cov δp δv = σ_a² T³ / 2, var δp = σ_a² T⁴ / 3; the
    nominal state is that of the uninflated run; with dense samples P stays 0."""
    T, sa, sg = 0.2, 3.0, 0.4
    cfg = MsckfConfig(gyro_noise_density=0.0, accel_noise_density=0.0, gyro_random_walk=0.0, accel_random_walk=0.0,
                      imu_gap_accel_sigma=sa, imu_gap_gyro_sigma=sg)
    state = FilterState.initial(ImuState.from_pose(np.eye(3), np.zeros(3), [1.0, 0.0, 0.0], 0.0), np.eye(3),
                                np.zeros(3), np.zeros((15, 15)))
    zeros = np.zeros((2, 3))
    out = propagate(state, [0.0, T], zeros, zeros, T, cfg)
    I3 = np.eye(3)
    np.testing.assert_allclose(out.P[0:3, 0:3], sg**2 * T**2 * I3, rtol=1e-12)
    np.testing.assert_allclose(out.P[6:9, 6:9], sa**2 * T**2 * I3, rtol=1e-12)
    np.testing.assert_allclose(out.P[12:15, 6:9], sa**2 * T**3 / 2 * I3, rtol=1e-12)
    np.testing.assert_allclose(out.P[12:15, 12:15], sa**2 * T**4 / 3 * I3, rtol=1e-12)
    blind = dataclasses.replace(cfg, imu_max_gap=np.inf, imu_max_bridged_gap=np.inf)
    plain = propagate(state, [0.0, T], zeros, zeros, T, blind)
    np.testing.assert_array_equal(plain.P, 0.0)
    np.testing.assert_array_equal(out.imu.p_IinG, plain.imu.p_IinG)
    dense = np.linspace(0.0, T, 41)
    np.testing.assert_array_equal(propagate(state, dense, np.zeros((41, 3)), np.zeros((41, 3)), T, cfg).P, 0.0)


def test_a_gap_beyond_the_bridged_limit_raises_naming_the_gap():
    cfg = MsckfConfig()
    state = FilterState.initial(ImuState.from_pose(np.eye(3), np.zeros(3), np.zeros(3), 0.0), np.eye(3),
                                np.zeros(3), cfg.initial_imu_covariance())
    t = np.concatenate([np.arange(0.0, 0.2, 0.001), np.arange(1.2, 2.0, 0.001)])
    w, a = np.zeros((len(t), 3)), np.tile([0.0, 0.0, 9.81], (len(t), 1))
    with pytest.raises(ImuGapError, match=r"IMU gap of 1 s > imu_max_bridged_gap = 0.3 s \(no IMU samples between "
                                          r"t = 0.199 s and t = 1.200 s\): .*state stays at t = 0.000 s") as info:
        propagate(state, t, w, a, 1.5, cfg)
    assert (info.value.start, info.value.end) == (pytest.approx(0.199), pytest.approx(1.2))
    with pytest.raises(ImuGapError, match=r"the IMU data end early: last sample at t = 0.199 s"):
        propagate(state, t[:200], w[:200], a[:200], 1.0, cfg)
    with pytest.raises(ImuGapError, match=r"the IMU data start late: first sample at t = 1.200 s"):
        propagate(state, t[200:], w[200:], a[200:], 1.3, cfg)
    propagate(state, t, w, a, 1.5, dataclasses.replace(cfg, imu_max_bridged_gap=1.5))  # a raised limit bridges it


def test_the_filter_counts_and_warns_about_a_gap_once_even_across_two_images(sim):
    imu = sim[0].imu
    keep = (imu.t <= 1.02) | (imu.t >= 1.18)  # images at 1.05, 1.1, 1.15 fall inside the gap
    outputs, f, caught = run(sim, t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep])
    assert f.faults == {"imu_gaps": 1} and len(caught) == 1
    assert "IMU gap of 0.16 s > imu_max_gap = 0.05 s (no samples from t = 1.020 s to t = 1.180 s)" in str(
        caught[0].message)
    assert outputs[20].counters["imu_gaps"] == 1 and "imu_gaps" not in outputs[22].counters
    assert_usable(outputs, f)


def test_across_a_bridged_gap_the_error_stays_within_three_sigma_and_without_inflation_it_does_not():
    """boxes_like, 5 s, seed 0 (per-observation noise as vio-sim), no IMU samples for 0.2 s from t = 3 s.
    Measured, max |e| / σ per axis: over the gap 2.93 with the inflation; afterwards 4.09 (at t = 3.5 s: the
    first updates after the gap are overconfident, the EKF linearised at a 0.2 rad attitude uncertainty) against
    10.2 without the inflation (the issue's case was 17σ)."""
    config = VioSimConfig(preset="boxes_like", duration=5.0, seed=0)
    data = simulate_data(config)
    cfg = experiment_msckf_config(config, data.noise, data.camera)
    imu = data.imu
    keep = (imu.t <= 3.0) | (imu.t >= 3.2)
    ratios = {}
    for name, c in (("inflated", cfg),
                    ("blind", dataclasses.replace(cfg, imu_max_gap=np.inf, imu_max_bridged_gap=np.inf))):
        f = Msckf(c, initial_state(data, c, _streams(config.seed)[2]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MsckfWarning)
            f.feed_imu(imu.t[keep], imu.gyro[keep], imu.accel[keep])
            out = [f.process_image(fr.t, fr.ids, fr.xy, observation_covariance(data.camera, fr.uv, c.pixel_noise_px))
                   for fr in data.frames]
        t = np.array([o.t for o in out])
        e = np.array([o.p_IinG for o in out]) - data.trajectory.evaluate(t).p_IinG
        ratio = np.abs(e) / np.array([o.sigma[12:15] for o in out])
        ratios[name] = (ratio[(t >= 3.0) & (t <= 3.2)].max(), ratio[t >= 3.0].max())
        assert_usable(out, f)
        assert f.faults == ({"imu_gaps": 1} if name == "inflated" else {})
    assert ratios["inflated"][0] < 3.0 and ratios["inflated"][1] < 4.5, ratios
    assert ratios["blind"][1] > 10.0 > 2.0 * ratios["inflated"][1], ratios


def test_a_gap_beyond_the_limit_stops_the_filter_with_a_message(sim):
    imu = sim[0].imu
    for keep, message in (((imu.t <= 1.0) | (imu.t >= 2.0), r"no IMU samples between t = 1.000 s and t = 2.000 s"),
                          (imu.t <= 1.0, r"the IMU data end early: last sample at t = 1.000 s")):
        with pytest.raises(ImuGapError, match=message):
            run(sim, t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep])


# ---------------------------------------------------------------- table-driven bad input


def _frame_edit(edit):
    return lambda f, frame, imu_next: f.process_image(*edit(frame))


BAD_INPUTS = [  # (name, action(filter, frame (t, ids, xy), next IMU chunk), exception expected or None)
    ("accel NaN", lambda f, fr, imu: f.feed_imu(imu[0][:3], imu[1][:3], np.full((3, 3), np.nan)), ValueError),
    ("gyro inf", lambda f, fr, imu: f.feed_imu(imu[0][:3], np.full((3, 3), np.inf), imu[2][:3]), ValueError),
    ("time NaN", lambda f, fr, imu: f.feed_imu([np.nan], imu[1][:1], imu[2][:1]), ValueError),
    ("time backwards", lambda f, fr, imu: f.feed_imu(imu[0][:3][::-1], imu[1][:3], imu[2][:3]), ValueError),
    ("shape (n, 2)", lambda f, fr, imu: f.feed_imu(imu[0][:3], imu[1][:3, :2], imu[2][:3]), ValueError),
    ("image xy NaN", _frame_edit(lambda fr: (fr[0], fr[1], np.where(fr[2] > 0, np.nan, fr[2]))), ValueError),
    ("image xy inf", _frame_edit(lambda fr: (fr[0], fr[1], np.full_like(fr[2], np.inf))), ValueError),
    ("image xy in pixels", _frame_edit(lambda fr: (fr[0], fr[1], fr[2] * 199.0 + 120.0)), ValueError),
    ("image ids repeated", _frame_edit(lambda fr: (fr[0], np.zeros_like(fr[1]), fr[2])), ValueError),
    ("image ids float", _frame_edit(lambda fr: (fr[0], fr[1] + 0.5, fr[2])), ValueError),
    ("image time NaN", _frame_edit(lambda fr: (np.nan, fr[1], fr[2])), ValueError),
    ("image time in the past", _frame_edit(lambda fr: (fr[0] - 1.0, fr[1], fr[2])), ValueError),
    ("image xy_cov not PD", lambda f, fr, imu: f.process_image(*fr, np.zeros((len(fr[1]), 2, 2))), ValueError),
    ("image xy_cov NaN", lambda f, fr, imu: f.process_image(*fr, np.full((len(fr[1]), 2, 2), np.nan)), ValueError),
]
BAD_BUT_USABLE = [  # IMU chunks accepted (samples dropped, gap bridged): the filter goes on
    ("accel 1e200", lambda imu: (imu[0], imu[1], np.where(np.arange(len(imu[0]))[:, None] == 5, 1e200, imu[2]))),
    ("gyro -1e200", lambda imu: (imu[0], np.where(np.arange(len(imu[0]))[:, None] == 7, -1e200, imu[1]), imu[2])),
    ("accel 1e6 for 10 ms", lambda imu: (imu[0], imu[1], np.where(np.arange(len(imu[0]))[:, None] < 10, 1e6,
                                                                   imu[2]))),
    ("IMU gap: three chunks missing", lambda imu: tuple(x[:0] for x in imu)),
]
BAD_OBSERVATIONS = [  # accepted observations that are wrong (dropped, gated or absorbed by the update)
    ("one observation at 1e200", lambda fr: (fr[0], fr[1], np.vstack([[1e200, 0.0], fr[2][1:]]), None)),
    ("all observations random in the image",
     lambda fr: (fr[0], fr[1], np.random.default_rng(5).uniform(-0.6, 0.6, fr[2].shape), None)),
    ("all observations at one pixel", lambda fr: (fr[0], fr[1], np.zeros_like(fr[2]), None)),
    ("observations swapped between tracks", lambda fr: (fr[0], fr[1], fr[2][::-1], None)),
    ("over-confident covariance 1e-30", lambda fr: (*fr, np.tile(np.eye(2) * 1e-30, (len(fr[1]), 1, 1)))),
    ("no observations", lambda fr: (fr[0], fr[1][:0], fr[2][:0], None)),
]


def test_bad_input_table_never_leaves_a_non_finite_state(sim):
    """Every bad input of the three tables is injected into one running filter (IMU fed in chunks, one per image):
    the refused ones raise ValueError and change nothing, the others are dropped, bridged or absorbed; after each
    image the state is finite and P a covariance, and the run still ends close to the truth."""
    data, cfg, state = sim
    imu = data.imu
    frames = [(fr.t, fr.ids, fr.xy) for fr in data.frames]
    refused = {2 + i: case for i, case in enumerate(BAD_INPUTS)}  # frames 2-15
    chunks = {16: BAD_BUT_USABLE[0], 18: BAD_BUT_USABLE[1], 20: BAD_BUT_USABLE[2]}
    chunks.update({k: BAD_BUT_USABLE[3] for k in (24, 25, 26)})
    observations = {28 + 3 * i: case for i, case in enumerate(BAD_OBSERVATIONS)}  # frames 28-43
    f = Msckf(cfg, state)
    outputs, fed = [], 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MsckfWarning)
        for k, frame in enumerate(frames):
            upto = int(np.searchsorted(imu.t, frame[0] + 0.01))
            chunk = (imu.t[fed:upto], imu.gyro[fed:upto], imu.accel[fed:upto])
            fed = upto
            if k in refused:  # refused input: nothing may change
                name, action, error = refused[k]
                before, faults = f.state, dict(f.faults)
                with pytest.raises(error):
                    action(f, frame, chunk)
                assert f.state is before and dict(f.faults) == faults, name
            if k in chunks:
                chunk = chunks[k][1](chunk)
            if len(chunk[0]):
                f.feed_imu(*chunk)
            outputs.append(f.process_image(*observations[k][1](frame)) if k in observations
                           else f.process_image(*frame))
            assert_usable(outputs[-1:], f)
    assert len(refused) + len(BAD_BUT_USABLE) + len(observations) == 24
    assert f.faults["imu_accel_out_of_range"] == 11 and f.faults["imu_gyro_out_of_range"] == 1
    assert f.faults["imu_gaps"] == 1 and f.faults["observation_out_of_view"] == 1
    assert np.linalg.norm(position_error(sim, outputs)[-1]) < 1.0


def test_gap_times_of_a_recording_on_a_unix_clock_keep_their_digits():
    from evio_lib.msckf.propagation import _gap_description

    text = _gap_description(1403715273.2, 1403715274.5, 1403715000.0, 1403716000.0)
    assert text == "no IMU samples between t = 1403715273.200 s and t = 1403715274.500 s"   # not 1.40372e+09 twice
