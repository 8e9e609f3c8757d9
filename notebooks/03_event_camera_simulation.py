# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 03 — Event cameras and a simulated world with ground truth
#
# The pipeline this course builds needs event data **together with** an IMU (inertial measurement unit: a gyroscope
# and an accelerometer, lesson 02's source of metric scale) and a perfect ground truth: lesson 04
# turns events into image frames, lesson 08 tests detectors on event frames, and the IMU lesson, the MSCKF lessons
# and the pipeline lessons at the end of the course build and check the filter on the simulator's trajectories, IMU
# signals and ground truth. Real recordings with all three are rare (and
# none come with the course), so the course simulates them. This lesson opens the simulator up, following the thesis
# the course reproduces (Friedel 2020, *Event-based visual-inertial odometry using smart features*) where it
# describes event cameras (§2.2.1) and its two datasets (§3.4):
#
# 1. **the principle**: a pixel of an event camera reports a change of its *log* intensity by a fixed contrast
#    step, asynchronously (thesis §2.2.1, Fig. 4) — we reproduce Fig. 4 for a single pixel;
# 2. **the simulator step by step** on a tiny image: the per-pixel reference, thresholds with mismatch, event times
#    by linear interpolation between renders, the refractory period, noise;
# 3. **adaptive sampling**: how often the scene must be rendered so that the result does not depend on it;
# 4. **the two presets** of the course — a textured room with boxes and hand-held motion that grows violent
#    (like RPG `boxes_6dof`, thesis §3.4.1), and a downward camera on an aircraft over sparse terrain (like the Camp
#    Atterbury flight, thesis §3.4.2): blurred frames versus sharp event frames, events in space-time, the IMU
#    against ground truth, the event rate over time, and writing/reading a recording in the Event-Camera-Dataset
#    (ECD) layout.
#
# The code lives in `evio_lib.events.simulate` (event generation), `evio_lib.sim` (scenes, trajectories, IMU, APS
# frames, whole recordings) and `evio_lib.io.ecd` (files). APS frames are the ordinary grayscale images that a DAVIS
# ("dynamic and active-pixel vision sensor", such as lesson 01's DAVIS240C) records beside its events: the
# active-pixel sensor (APS) part of each pixel exposes frames like a normal camera; section 4 simulates them.

# %% [markdown]
# First the idea as a picture. Left: the pixel's three stages (thesis Fig. 3) and the reset that makes each event's
# level the new reference. Right: one log-intensity curve with the levels $r_0 + kC$: an ON event each time $L$
# climbs one level above the last event's, an OFF event each time it falls one below — the rule section 1 computes.

# %%
import matplotlib.pyplot as plt

from evio_lib.evaluation.plots_schematics import plot_event_pixel_schematic

fig = plot_event_pixel_schematic(contrast=0.2)
plt.show()

# %%
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display
from scipy.optimize import brentq

from evio_lib.course import fast_mode
from evio_lib.events.array import concatenate_events, event_count_image, events_between
from evio_lib.events.simulate import EventCameraParams, EventSimulator, log_intensity, simulate_events
from evio_lib.evaluation.plots_sim import (
    event_rate,
    plot_event_cloud,
    plot_event_rates,
    plot_image_row,
    plot_image_table,
    plot_imu_vs_truth,
    plot_pixel_events,
    plot_sample_intervals,
)
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.io.ecd import read_ecd, write_ecd
from evio_lib.sim.imu import GRAVITY_G
from evio_lib.sim.presets import SimulationConfig, simulate_sequence_cached
from evio_lib.sim.scene import Scene, TexturedPlane, scene_from_preset
from evio_lib.sim.textures import load_texture, rescale_contrast
from evio_lib.sim.trajectory import trajectory_from_preset

FAST = fast_mode()

# %% [markdown]
# ## 1. The principle: one pixel, log intensity, contrast threshold
#
# An event-camera pixel continuously compares its **log intensity** $L(t) = \log(I(t) + \varepsilon)$ (a small
# $\varepsilon = 10^{-3}$ keeps a black pixel's log finite) with a
# **reference** level $r$, the value of $L$ at its last event. When $L$ has moved by a contrast threshold $C$ away
# from the reference, the pixel emits an event $e = (t, x, y, p)$ and moves the reference by $C$:
#
# $$L(t) \ge r + C_{+} \;\Rightarrow\; \text{ON event } (p = +1),\; r \leftarrow r + C_{+},
# \qquad L(t) \le r - C_{-} \;\Rightarrow\; \text{OFF event } (p = -1),\; r \leftarrow r - C_{-}.$$
#
# Working in log space makes the pixel respond to *relative* changes ($\Delta L = \Delta I / I$ for small changes),
# the same in shade and in sunlight — one reason for the very high dynamic range. No change, no data.
#
# We feed a single pixel ($1 \times 1$ image) a brightness that oscillates, $L(t) = L_0 + A \sin(2\pi f t)$ with
# $A = 0.9$, and sample it every 0.5 ms.

# %%
C = 0.2  # contrast threshold (natural-log units: a 22 % brightness change)
A, f_hz, L_mid = 0.9, 1.0, np.log(0.2)


def L_pixel(t):
    """Log intensity of our single pixel."""
    return L_mid + A * np.sin(2 * np.pi * f_hz * t)


ideal = EventCameraParams(contrast_pos=C, contrast_neg=C, contrast_sigma=0.0, refractory_s=0.0)
t_grid = np.linspace(0.0, 2.2, 4401)
pixel = EventSimulator(1, 1, ideal)
pixel.reset(np.full((1, 1), L_pixel(0.0)), t=0.0)
pixel_events = concatenate_events([pixel.step(np.full((1, 1), L_pixel(t)), t) for t in t_grid[1:]])
print(f"{len(pixel_events)} events, polarities: {pixel_events['p'].tolist()}")
assert pixel_events["p"][:4].tolist() == [1] * 4 and pixel_events["p"][4:12].tolist() == [-1] * 8  # 4 ON, 8 OFF
fig = plot_pixel_events(t_grid, L_pixel(t_grid), pixel_events, C)
plt.show()

# %% [markdown]
# Note the **hysteresis** at each turning point: at the peak the reference sits on the last level crossed
# ($L_0 + 4C$); on the way down the first OFF event needs a full $C$ *below* it. The first rise spans $A = 0.9$ and
# gives four ON events ($0.9 / 0.2 = 4.5$); the fall spans $2A = 1.8$ but starts from $L_0 + 4C$ rather than from the
# peak, so it gives eight OFF events, not nine.
#
# **Check against the analytic crossing times.** Between two extrema $L$ is monotone, so the pixel fires at
# $r \pm C, r \pm 2C, \dots$ as long as those levels are reached, and each crossing time solves $L(t) = r \pm kC$
# exactly (a root finder on the smooth curve). The simulator only sees samples every 0.5 ms and interpolates
# linearly between them — its times must agree to far better than the sample interval.

# %%
extrema = np.concatenate([[0.0], (np.arange(4) + 0.5) / (2 * f_hz), [t_grid[-1]]])  # turning points of the sine
r, t_exact, p_exact = L_pixel(0.0), [], []
for ta, tb in zip(extrema[:-1], extrema[1:]):
    s = np.sign(L_pixel(tb) - L_pixel(ta))  # +1 rising, -1 falling
    while s * (L_pixel(tb) - (r + s * C)) >= 0:  # next level r + sC reached before the turning point?
        r += s * C
        t_exact.append(brentq(lambda t: L_pixel(t) - r, ta, tb, xtol=1e-13))
        p_exact.append(int(s))
t_exact = np.array(t_exact)
timing_error = np.abs(pixel_events["t"] - t_exact).max()
print(f"{len(t_exact)} analytic crossings; largest timing error of the simulator: {timing_error * 1e6:.2f} us")
assert len(pixel_events) == len(t_exact) and np.array_equal(pixel_events["p"], p_exact)
assert timing_error < 1e-5  # 10 us, 50x finer than the 0.5 ms sampling

# %% [markdown]
# ## 2. The simulator step by step, on a tiny image
#
# The event simulator (in the spirit of ESIM, Rebecq et al. 2018) needs a **renderer**: a function
# $t \mapsto I(t)$ giving the image a camera would see at time $t$. Ours ray-casts textured planes
# (`evio_lib.sim.scene`). For this section: a $32 \times 24$ pinhole camera, 1 m in front of a poster, sliding
# sideways faster and faster (world frame = the camera's initial frame here).

# %%
W, H = 32, 24
tiny_camera = PinholeRadtan(fx=30.0, fy=30.0, cx=15.5, cy=11.5, width=W, height=H)
poster = rescale_contrast(load_texture("camera", size=(128, 128)), 0.05, 0.95)
tiny_scene = Scene([TexturedPlane([-1.5, -1.5, 1.0], [3.0, 0, 0], [0, 3.0, 0], poster)])
T_TINY = 1.0


def tiny_pose(t):
    """Camera pose (R_CtoG, p_CinG): sliding along x with growing speed 0.6 t m/s (image speed 18 t px/s)."""
    return np.eye(3), np.array([0.3 * t**2, 0.05 * t, 0.0])


def tiny_render(t):
    return tiny_scene.render_intensity(tiny_camera, *tiny_pose(t))


fig = plot_image_row([tiny_render(0.0), tiny_render(T_TINY)], ["I(t = 0 s)", f"I(t = {T_TINY:g} s)"], width_in=3.5,
                     vrange=(0.0, 1.0), colorbar=True, colorbar_label="intensity I (0 black, 1 white)")
plt.show()

# %% [markdown]
# **(a) Reference and thresholds with mismatch.** At the start every pixel's reference is its log intensity.
# Real pixels are not identical: each has its own thresholds, here $C_\pm \sim \mathcal{N}(0.2, 0.03^2)$, drawn
# once when the sensor is "manufactured" (`EventSimulator` draws them from the seeded generator).

# %%
tiny_params = EventCameraParams(contrast_pos=0.2, contrast_neg=0.2, contrast_sigma=0.03, refractory_s=0.0)
sim = EventSimulator(W, H, tiny_params, rng=np.random.default_rng(3))
L_start = log_intensity(tiny_render(0.0))
sim.reset(L_start, t=0.0)
assert np.allclose(sim.reference, L_start)  # r = L(t0)
plt.figure(figsize=(6, 2.5))
plt.hist([sim.thresholds_pos.ravel(), sim.thresholds_neg.ravel()], bins=25, label=["C+", "C-"])
plt.xlabel("contrast threshold [log units]")
plt.ylabel("pixels")
plt.legend()
plt.title("per-pixel thresholds (mismatch)")
plt.show()
print(f"C+ mean {sim.thresholds_pos.mean():.3f}, std {sim.thresholds_pos.std():.3f}")
assert abs(sim.thresholds_pos.mean() - 0.2) < 0.01 and abs(sim.thresholds_pos.std() - 0.03) < 0.005

# %% [markdown]
# **(b) Event times by linear interpolation.** The renderer gives samples $(t_0, L_0)$, $(t_1, L_1)$; between
# them the simulator assumes $L$ changes linearly. A pixel whose $L_1$ lies $n = \lfloor (L_1 - r)/C_+ \rfloor$
# thresholds above its reference fires $n$ ON events (likewise OFF events below), the $k$-th at
#
# $$t_k = t_0 + \frac{r + k\,C_\pm - L_0}{L_1 - L_0}\,(t_1 - t_0), \qquad k = 1, \dots, n,$$
#
# and the reference moves to $r + n C$. We take one deliberately long step (0.3 s) so that some pixels fire
# several events, write the rule in a few vectorised lines, and compare with `EventSimulator.step`.

# %%
t0, t1 = 0.0, 0.3
L0, L1 = L_start.astype(np.float64), log_intensity(tiny_render(t1)).astype(np.float64)
ref = sim.reference
step_events = sim.step(L1, t1)

# the rule, by hand: n crossings per pixel, levels r + k C, times by linear interpolation
d = L1 - ref
step_C = np.where(d > 0, sim.thresholds_pos, -sim.thresholds_neg)  # signed threshold of each pixel
n = np.floor(d / step_C).astype(int)  # number of crossings (>= 0)
ys, xs = np.nonzero(n > 0)
reps = n[ys, xs]
k = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps) + 1  # k = 1..n within each firing pixel
ys, xs = np.repeat(ys, reps), np.repeat(xs, reps)
level = ref[ys, xs] + k * step_C[ys, xs]
t_hand = t0 + (level - L0[ys, xs]) / (L1[ys, xs] - L0[ys, xs]) * (t1 - t0)

order_hand = np.lexsort((t_hand, xs, ys))  # compare event sets sorted by pixel, then time
order_lib = np.lexsort((step_events["t"], step_events["x"], step_events["y"]))
print(f"{len(step_events)} events from one step; pixels firing more than once: {int((reps > 1).sum())}")
assert len(t_hand) == len(step_events)
assert np.array_equal(xs[order_hand], step_events["x"][order_lib])
assert np.array_equal(ys[order_hand], step_events["y"][order_lib])
assert np.array_equal(np.sign(step_C[ys, xs])[order_hand], step_events["p"][order_lib])
assert np.allclose(t_hand[order_hand], step_events["t"][order_lib], atol=1e-6)

# %% [markdown]
# **(c) The events add up to the brightness change.** Because each event moves the reference by exactly one
# threshold and the reference always stays within one threshold of $L$, for every pixel, with its own thresholds
# $C_+, C_-$ (drawn around 0.2 with the mismatch of (a), so some exceed 0.2),
#
# $$-C_- < \big(L(t_b) - L(t_a)\big) - \big(N_{\text{ON}}\,C_+ - N_{\text{OFF}}\,C_-\big) < C_+ .$$
#
# This is why events can be integrated back into images (and why event frames look like edge maps: only where
# the brightness changed). We simulate the whole second with 200 renders and check it per pixel.

# %%
render_times = np.linspace(0.0, T_TINY, 201)


def run_tiny(params, seed=3):
    """Return (events, simulator) after feeding the tiny scene's renders at render_times to a fresh simulator."""
    s = EventSimulator(W, H, params, rng=np.random.default_rng(seed))
    s.reset(tiny_render(render_times[0]), render_times[0], is_log=False)
    chunks = [s.step(log_intensity(tiny_render(t)), t) for t in render_times[1:]]
    return concatenate_events(chunks), s


tiny_events, tiny_sim = run_tiny(tiny_params)
n_on = event_count_image(tiny_events[tiny_events["p"] > 0], W, H)
n_off = event_count_image(tiny_events[tiny_events["p"] < 0], W, H)
dL = log_intensity(tiny_render(T_TINY)).astype(np.float64) - log_intensity(tiny_render(0.0))
residual = dL - (n_on * tiny_sim.thresholds_pos - n_off * tiny_sim.thresholds_neg)
print(f"{len(tiny_events)} events; residual per pixel in [{residual.min():.3f}, {residual.max():.3f}]; the pixels' "
      f"thresholds C+ up to {tiny_sim.thresholds_pos.max():.3f}, C- up to {tiny_sim.thresholds_neg.max():.3f}")
assert np.all(residual < tiny_sim.thresholds_pos) and np.all(residual > -tiny_sim.thresholds_neg)
fig = plot_image_row([dL, event_count_image(tiny_events, W, H, signed=True) * 0.2, residual],
                     ["L(1 s) - L(0)", "0.2 x (N_ON - N_OFF)", "residual"], cmaps="bwr", symmetric=True,
                     colorbar=True, width_in=3.5, vrange="shared", colorbar_label="log-intensity change [log units]")
plt.show()

# %% [markdown]
# **(d) Refractory period.** After firing, a real pixel needs a moment (its *refractory period*) before it can fire
# again. The simulator drops crossings that come less than `refractory_s` after the pixel's last event (the reference
# still moves, so the pixel stays locked to the signal). With a long period of 50 ms the fast pixels lose events —
# and the sum rule of (c) no longer holds for them.

# %%
slow_pixels = EventCameraParams(contrast_sigma=0.03, refractory_s=0.05)
refr_events, refr_sim = run_tiny(slow_pixels)
print(f"refractory 0 ms: {len(tiny_events)} events;  50 ms: {len(refr_events)} events "
      f"({refr_sim.dropped_refractory} crossings dropped)")
assert len(refr_events) + refr_sim.dropped_refractory == len(tiny_events)  # same thresholds (same seed)
refr_sum = (event_count_image(refr_events[refr_events["p"] > 0], W, H) * refr_sim.thresholds_pos
            - event_count_image(refr_events[refr_events["p"] < 0], W, H) * refr_sim.thresholds_neg)
broken = (dL - refr_sum >= refr_sim.thresholds_pos) | (dL - refr_sum <= -refr_sim.thresholds_neg)  # outside (c)'s band
print(f"the sum rule of (c) fails for {int(broken.sum())} of {W * H} pixels with the 50 ms refractory period")
assert broken.any()  # (c) held for every pixel without the refractory period

# %% [markdown]
# **(e) Noise.** Real sensors also fire without any brightness change: *background* (shot) noise with random
# polarity and *leak* events (positive: charge slowly leaking in the pixel's circuit makes it fire ON events with
# no change of light). The simulator draws them as Poisson processes per pixel. On a static
# scene all events are noise, so their number must be close to rate $\times$ pixels $\times$ time.

# %%
noisy = EventCameraParams(background_rate_hz=2.0, leak_rate_hz=0.5)
noise_sim = EventSimulator(W, H, noisy, rng=np.random.default_rng(4))
static = log_intensity(tiny_render(0.0))
noise_sim.reset(static, 0.0)
noise_events = concatenate_events([noise_sim.step(static, t) for t in np.linspace(0.01, 2.0, 200)])
expected = (2.0 + 0.5) * W * H * 2.0
print(f"noise events on a static scene in 2 s: {len(noise_events)} "
      f"(expected {expected:.0f} +- {np.sqrt(expected):.0f}); "
      f"ON fraction {np.mean(noise_events['p'] > 0):.2f} (expected {(1.0 + 0.5) / 2.5:.2f})")
assert abs(len(noise_events) - expected) < 5 * np.sqrt(expected)
assert abs(np.mean(noise_events["p"] > 0) - 0.6) < 0.03  # ON fraction: (background / 2 + leak) / total

# %% [markdown]
# ## 3. Adaptive sampling: how often to render?
#
# Linear interpolation is only right if $L$ barely bends between two renders. The simulator therefore picks the
# next render time adaptively (ESIM's criterion): no pixel's log intensity may change by more than a fraction
# $\lambda$ of the threshold between samples,
#
# $$\max_{\text{pixels}} |L_{k+1} - L_k| \le \lambda\, C, \qquad
# \Delta t_{k+1} \approx 0.8\,\frac{\lambda C}{\max |\dot L|},$$
#
# re-rendering with half the step when the prediction was too optimistic. Slow scenes get few renders, fast
# ones many. Once the sampling is fine enough, the number of events must stop depending on it.

# %%
lambdas = (2.0, 1.0, 0.5, 0.25) if FAST else (4.0, 2.0, 1.0, 0.5, 0.25, 0.1)
counts = {}
for lam in lambdas:
    ev, sample_times = simulate_events(tiny_render, 0.0, T_TINY, W, H, tiny_params, rng=3, max_log_change=lam,
                                       dt_max=0.05)
    counts[lam] = len(ev)
    print(f"lambda = {lam:4.2f}: {len(sample_times):5d} renders, {len(ev)} events")
ev, sample_times = simulate_events(tiny_render, 0.0, T_TINY, W, H, tiny_params, rng=3, max_log_change=0.5, dt_max=0.05)
image_speed = 30.0 * 0.6 * render_times  # fx |v| / z = 30 px * 0.6 t m/s / 1 m
fig = plot_sample_intervals(sample_times, render_times, image_speed)
plt.show()
intervals = np.diff(sample_times)
early, late = intervals[sample_times[1:] < 0.3].mean(), intervals[sample_times[1:] > 0.7].mean()
print(f"mean render interval: {early * 1e3:.1f} ms for t < 0.3 s, {late * 1e3:.1f} ms for t > 0.7 s")
assert late < 0.5 * early  # faster image motion, more renders
fine, finer = counts[lambdas[-2]], counts[lambdas[-1]]
assert abs(fine - finer) / finer < 0.02  # converged: halving lambda changes the count by < 2 %

# %% [markdown]
# The render interval falls as the image speed grows, and the event count converges (coarse sampling loses
# events: a pixel that goes up and down between two renders looks unchanged). The presets below use
# $\lambda = 0.5$ and apply the bound to the 99 % quantile of pixels, so that occlusion edges — which jump by a
# whole log unit however short the step — do not force a render every 10 µs.
#
# ## 4. The presets: a room with boxes, and a flight over fields
#
# `SimulationConfig` + `simulate_sequence` turn a preset name into a whole recording (`Sequence`): events, APS
# frames (the DAVIS's grayscale frames, 24 Hz, with motion blur from sub-renders over the exposure), IMU at 1 kHz
# (gyro $= \boldsymbol\omega_I + \mathbf b_g + \mathbf n_g$, accelerometer
# $= R_{G\to I}(\mathbf a_{I\,\mathrm{in}\,G} - \mathbf g_G) + \mathbf b_a + \mathbf n_a$: the measurement model behind
# thesis Eq. 31, which removes the biases as $\boldsymbol\omega = \boldsymbol\omega_m - \mathbf b_g$,
# $\mathbf a = \mathbf a_m - \mathbf b_a$; the noise terms are the simulator's) and ground
# truth — all from one trajectory, so the sensors agree exactly. The boxes motion grows from gentle to violent over
# the preset's length; here we squeeze the whole preset into the recording.

# %%
camera = PinholeRadtan.davis240c().scaled(0.5) if FAST else PinholeRadtan.davis240c()
boxes_cfg = SimulationConfig(preset="boxes_like", duration=2.0 if FAST else 10.0,
                             trajectory_duration=2.0 if FAST else 10.0, camera=camera, seed=0)
aerial_cfg = SimulationConfig(preset="aerial_like", start_time=14.5 if FAST else 12.0, duration=1.0 if FAST else 12.0,
                              trajectory_duration=40.0, camera=camera, seed=0)
ev_cfg, aps_cfg = boxes_cfg.events, boxes_cfg.aps
display(Markdown(
    f"The camera: {camera.width} x {camera.height} pixels, focal length {camera.fx:.0f} px. Its event pixels: "
    f"thresholds C = {ev_cfg.contrast_pos:g} with a mismatch of {ev_cfg.contrast_sigma:g} (standard deviation), "
    f"a refractory period of {ev_cfg.refractory_s * 1e3:g} ms. Its APS frames: {aps_cfg.exposure_s * 1e3:g} ms "
    f"exposure, read noise {aps_cfg.read_noise_sigma:g} (in units of full scale), stored as 8-bit values "
    f"255 V^{aps_cfg.gamma:.3f} of the linear intensity V (a gamma curve, 1/2.2). The recordings: "
    f"{boxes_cfg.duration:g} s of the room, {aerial_cfg.duration:g} s of the flight."))

# %% [markdown]
# First, what the two worlds look like: one render at the start of each recording, with its depth map (the
# renderer also returns the 3-D point behind every pixel, used later for tests where the true 3-D point behind each
# feature is known). Both depth maps share one logarithmic colour scale: the room's walls are metres away, the ground
# hundreds of metres below the aircraft.

# %%
scenes = {"boxes_like": scene_from_preset("boxes_like"), "aerial_like": scene_from_preset("aerial_like")}
views = []
for cfg in (boxes_cfg, aerial_cfg):
    start = trajectory_from_preset(cfg.preset, duration=cfg.motion_duration(), seed=cfg.seed).evaluate([cfg.start_time])
    R_CtoG, p_CinG = cfg.extrinsics.camera_pose(start.R_ItoG, start.p_IinG)
    view = scenes[cfg.preset].render(camera, R_CtoG[0], p_CinG[0])
    views.append([view.intensity, view.depth])
fig = plot_image_table(views, ["boxes_like", "aerial_like"], ["intensity", "depth"],
                       ["intensity I (0 black, 1 white)", "depth along the optical axis [m] (log scale)"],
                       cmaps=["gray", "viridis"], vranges=[(0.0, 1.0), None], log_scale=[False, True])
plt.show()
depth_range = {cfg.preset: (float(np.nanmin(v[1])), float(np.nanmax(v[1]))) for cfg, v in zip((boxes_cfg, aerial_cfg),
                                                                                               views)}
print("depth range: " + ", ".join(f"{name} {lo:.1f}-{hi:.1f} m" for name, (lo, hi) in depth_range.items()))
assert depth_range["boxes_like"][1] < 10 < 100 < depth_range["aerial_like"][0]  # metres against hundreds of metres

# %% [markdown]
# Now the two recordings; each summary lists what a recording holds.

# %%
boxes, aerial = (simulate_sequence_cached(cfg) for cfg in (boxes_cfg, aerial_cfg))
print(boxes.summary())
print(aerial.summary())

# %% [markdown]
# ### Frames versus events in fast motion
#
# An APS frame integrates light over its exposure $T$ (10 ms here), so everything that moves during it is smeared:
# a rotation at angular speed $|\boldsymbol\omega|$ sweeps the image by about $f\,|\boldsymbol\omega|\,T$ pixels
# during the exposure ($f$ the focal length in pixels; translation adds a little). Events carry microsecond
# timestamps, so an image made of events can cover as short a time as we like. We build an **event frame** from a
# fixed number of events, $N_e = n\,H\,W$ (here $n = 0.3$), the ones nearest to the frame's middle. The thesis sizes
# its windows by the same rule (§4.1, Eq. 87), but feeds them to a reconstruction network; here we only count the
# events per pixel (lesson 04 reconstructs). The faster the motion, the faster the events come, so the window
# $\Delta t$ of an event frame shrinks, and with it its sweep $f\,|\boldsymbol\omega|\,\Delta t$.
#
# To see how much detail a frame loses, we compare it with an instantaneous render of the same moment (what an ideal
# camera with zero exposure would see), with a sharpness measure, the normalised gradient energy
# $S(f) = \overline{|\nabla f|^2} / \operatorname{var}(f)$: roughly one over the squared width of the image's
# features, so blur lowers it, whatever the image's brightness scale. $S$ also depends on what the camera looks at,
# so only the ratio $S(\text{APS frame}) / S(\text{render})$ of one moment says what the exposure lost (the frame is
# first decoded back to linear intensity, $V = (\text{frame}/255)^{2.2}$). An event frame is a sparse edge map
# whose $S$ is high even when nothing moves fast, so for events we compare the sweep. We take two frames of the
# boxes recording: the one whose exposure saw the slowest rotation and the one that saw the fastest.

# %%
def sharpness(image):
    """Normalised gradient energy: mean |grad f|^2 / var(f) (1/px^2); blur lowers it."""
    f = np.asarray(image, dtype=np.float64)
    gy, gx = np.gradient(f)
    return float(np.mean(gx**2 + gy**2) / f.var())


N_E = int(0.3 * camera.width * camera.height)  # events per event frame, N_e = n H W


def event_frame_at(events, t):
    """Return (count image of the N_E events nearest to time t, time span of those events [s])."""
    j = int(np.searchsorted(events["t"], t))
    chosen = events[max(j - N_E // 2, 0): j + N_E // 2]
    return event_count_image(chosen, camera.width, camera.height), float(chosen["t"][-1] - chosen["t"][0])


boxes_traj = trajectory_from_preset("boxes_like", duration=boxes_cfg.motion_duration(), seed=boxes_cfg.seed)


def boxes_camera_poses(times):
    """Ground-truth camera poses (R_CtoG (K,3,3), p_CinG (K,3)) of the boxes recording at times (K,)."""
    s = boxes_traj.evaluate(np.atleast_1d(np.asarray(times, dtype=np.float64)))
    return boxes_cfg.extrinsics.camera_pose(s.R_ItoG, s.p_IinG)


w_frames = np.linalg.norm(boxes_traj.evaluate(boxes.frame_times).w_I, axis=1)
cases, images = {}, []
for label, i in (("calmest", int(np.argmin(w_frames))), ("fastest", int(np.argmax(w_frames)))):
    t_i = boxes.frame_times[i]
    R_i, p_i = boxes_camera_poses(t_i)
    render = scenes["boxes_like"].render_intensity(camera, R_i[0], p_i[0])
    aps = (boxes.frames[i] / 255.0) ** (1.0 / aps_cfg.gamma)  # decoded to linear intensity V
    frame_i, span_i = event_frame_at(boxes.events, t_i)
    cases[label] = dict(t=t_i, w=w_frames[i], blur_px=camera.fx * w_frames[i] * aps_cfg.exposure_s,
                        kept=sharpness(aps) / sharpness(render), span_ms=span_i * 1e3,
                        sweep_px=camera.fx * w_frames[i] * span_i, s_events=sharpness(frame_i))
    images.append([aps, render, frame_i])
calm, quick = cases["calmest"], cases["fastest"]
counts_lit = np.concatenate([row[2][row[2] > 0] for row in images])
events_max = float(np.percentile(counts_lit, 99))  # one range for both event frames; a few busy pixels would set it
fig = plot_image_table(images, [f"{k}: t = {c['t']:.2f} s, |w| = {c['w']:.2f} rad/s" for k, c in cases.items()],
                       [f"APS frame ({aps_cfg.exposure_s * 1e3:g} ms exposure)", "instantaneous render",
                        f"event frame ({N_E} events)"],
                       ["intensity V (0 black, 1 white)", "intensity I (0 black, 1 white)", "events per pixel"],
                       cmaps=["gray", "gray", "gray_r"], vranges=[(0.0, 1.0), (0.0, 1.0), (0.0, events_max)])
plt.show()
rows = [("angular speed \\|w\\| [rad/s]", "w", "{:.2f}"),
        ("APS: image sweep during the exposure, f \\|w\\| T [px]", "blur_px", "{:.1f}"),
        ("APS: S(frame) / S(render)", "kept", "{:.0%}"), ("events: window Δt [ms]", "span_ms", "{:.1f}"),
        ("events: image sweep during the window, f \\|w\\| Δt [px]", "sweep_px", "{:.1f}"),
        ("events: S(event frame) [1/px²]", "s_events", "{:.2f}")]
display(Markdown("| | calmest frame | fastest frame |\n|---|---|---|\n" + "\n".join(
    f"| {name} | {fmt.format(calm[key])} | {fmt.format(quick[key])} |" for name, key, fmt in rows)))
assert quick["kept"] < calm["kept"] - 0.1  # motion blur removes detail, more so in fast motion
assert quick["blur_px"] > 2 * quick["sweep_px"]  # in fast motion the exposure smears more than the event window
assert quick["span_ms"] < 5 and calm["span_ms"] > 50  # a few ms of events in fast motion, ~0.1 s in calm
assert 1 / 3 < quick["sweep_px"] / calm["sweep_px"] < 3  # ... over which the image moves comparably
assert quick["s_events"] > 0.7 * calm["s_events"]  # the event frame stays nearly as sharp

# %%
display(Markdown(
    f"In the calmest frame the image moves {calm['blur_px']:.1f} px during the exposure, and the APS frame has "
    f"{calm['kept']:.0%} of the render's sharpness $S$ (its noise adds a little gradient energy). In the fastest it "
    f"moves {quick['blur_px']:.1f} px, and the frame has {quick['kept']:.0%}: the blur is visible in the left column. "
    f"The {N_E} events nearest to that "
    f"frame span only {quick['span_ms']:.1f} ms, over which the image moves {quick['sweep_px']:.1f} px; in calm "
    f"motion they span {calm['span_ms']:.0f} ms and a sweep of {calm['sweep_px']:.1f} px. So the event frame loses "
    f"less with speed (its $S$ is {quick['s_events'] / calm['s_events']:.0%} of the calm one's) than the APS "
    f"frame, whose share of the render's $S$ falls from {calm['kept']:.0%} to {quick['kept']:.0%}."))

# %% [markdown]
# ### Events in space-time
#
# Plotted over $(x, y, t)$, events are not a sequence of images but surfaces: each moving edge sweeps a sheet
# through space-time. Its polarity says which way the brightness went where it passed: a dark line moving over a
# bright background gives OFF events where it arrives and ON events where it leaves. Here: 100 ms of the events in a
# square patch in the middle of the image, at 20 % of the boxes recording (calm motion; the sheets are the mortar
# lines of the brick wall sliding through the patch; the number of events is in the title).

# %%
t_cloud = boxes_cfg.start_time + 0.2 * boxes_cfg.duration
patch = camera.width // 4  # side of the square patch in pixels
x0, y0 = (camera.width - patch) // 2, (camera.height - patch) // 2
cloud = events_between(boxes.events, t_cloud, t_cloud + 0.1)
cloud = cloud[(cloud["x"] >= x0) & (cloud["x"] < x0 + patch) & (cloud["y"] >= y0) & (cloud["y"] < y0 + patch)]
fig = plot_event_cloud(cloud, max_points=15000)
plt.show()
assert len(cloud) < 1000 if FAST else len(cloud) > 3000

# %% [markdown]
# ### IMU signals against ground truth
#
# The IMU measures in its own frame: the angular rate $\boldsymbol\omega_I$ and the **specific force**
# $R_{G\to I}(\mathbf a - \mathbf g_G)$ — at rest the accelerometer reads $+9.81$ m/s² *upwards*. Both carry white
# noise and slowly wandering biases (an MPU-6150-class sensor, like the DAVIS's). After removing the true bias
# (kept in `groundtruth_imu`), what is left of the gyro error must be white noise with standard deviation
# $\sigma_g \sqrt{f_{\mathrm{IMU}}}$ (noise density times the square root of the rate; a noise density, in
# rad/s/$\sqrt{\text{Hz}}$, is the noise per square root of bandwidth, so sampling faster lets in more noise).

# %%
imu = boxes.imu
truth_imu = boxes_traj.evaluate(imu.t)
gyro_true = truth_imu.w_I
accel_true = np.einsum("nji,nj->ni", truth_imu.R_ItoG, truth_imu.a_IinG - GRAVITY_G)  # R_GtoI (a - g)
fig = plot_imu_vs_truth(imu.t, imu.gyro, gyro_true, imu.accel, accel_true)
plt.show()

gt_imu = boxes.groundtruth_imu
bias_g = np.column_stack([np.interp(imu.t, gt_imu.t, gt_imu.bias_gyro[:, k]) for k in range(3)])
gyro_noise = imu.gyro - gyro_true - bias_g
sigma_expected = boxes_cfg.imu_noise.gyro_noise_density * np.sqrt(boxes_cfg.imu_rate_hz)
print(f"gyro noise std {gyro_noise.std(axis=0).round(5)} rad/s, expected {sigma_expected:.5f}; "
      f"initial gyro bias {gt_imu.bias_gyro[0].round(3)} rad/s")
assert np.allclose(gyro_noise.std(axis=0), sigma_expected, rtol=0.15)

# %% [markdown]
# ### Event rate over time: the two regimes
#
# An event camera's data rate follows the motion and the texture. In the room, with textured surfaces a few metres
# away (the depth range printed under the depth maps), the rate climbs with the shaking. From 250 m up, 20 m/s of flight moves the image of a DAVIS240C (focal length about 200
# px) by only $f v / h \approx 200 \cdot 20 / 250 = 16$ px/s (plus the slow turbulence rotations), over fields with
# few strong edges: far fewer events. We count events in 20 ms bins and plot them with the camera's angular speed, and
# quote events per pixel and second to compare cameras of any resolution.

# %%
rates, motion = {}, {}
for seq, cfg in ((boxes, boxes_cfg), (aerial, aerial_cfg)):
    rates[cfg.preset] = event_rate(seq.events, cfg.start_time, cfg.t_end, bin_s=0.02)
    t_m = np.linspace(cfg.start_time, cfg.t_end, 400)
    motion[cfg.preset] = (t_m, np.linalg.norm(
        trajectory_from_preset(cfg.preset, duration=cfg.motion_duration(), seed=cfg.seed).evaluate(t_m).w_I, axis=1))
fig = plot_event_rates(rates, motion)
plt.show()

n_pixels = camera.width * camera.height
b_t, b_rate = rates["boxes_like"]
quarter = len(b_rate) // 4
first, last = b_rate[:quarter].mean(), b_rate[-quarter:].mean()
aerial_per_px = rates["aerial_like"][1].mean() / n_pixels
boxes_per_px = b_rate.mean() / n_pixels
w_at_bins = np.interp(b_t, *motion["boxes_like"])  # the camera's angular speed at the rate bins
rate_vs_motion = np.corrcoef(b_rate, w_at_bins)[0, 1]
t_a, w_a = motion["aerial_like"]
flight_px_s = camera.fx * 20 / 250  # image speed of 20 m/s of flight at 250 m
assert last > 3 * first  # more motion, more events
assert rate_vs_motion > 0.7  # the rate follows the angular speed
assert (5 < boxes_per_px / aerial_per_px < 15) if FAST else (2 < boxes_per_px / aerial_per_px < 5)
assert camera.fx * w_a.max() >= flight_px_s  # at times rotation moves the image as fast as the flight
display(Markdown(
    f"In the room the rate follows the angular speed closely (correlation {rate_vs_motion:.2f}) and grows from "
    f"{first / 1e6:.2f} million events per second in the gentle first quarter to {last / 1e6:.2f} million in the "
    f"violent last one ({last / first:.1f} times). The flight produces {aerial_per_px:.1f} events per pixel and second "
    f"against the room's {boxes_per_px:.1f}, {boxes_per_px / aerial_per_px:.1f} times fewer. There 20 m/s of "
    f"translation at 250 m moves the image by only {flight_px_s:.0f} px/s, while the aircraft's slow rotations "
    f"(turbulence and banking) move it by {camera.fx * w_a.min():.0f}-{camera.fx * w_a.max():.0f} px/s: at times "
    "the rotations move the image faster than the flight does."))

# %% [markdown]
# ## 5. Files: the Event-Camera-Dataset layout
#
# The course reads real recordings in the layout of the RPG Event-Camera Dataset (`events.txt` with `t x y p`,
# polarity written as 1/0, `imu.txt`, `images.txt` + `images/`, `groundtruth.txt` with the **camera** pose in the
# world, `calib.txt`);
# simulated recordings are written the same way, plus `groundtruth_imu.txt` (IMU pose, velocity and biases) and a
# sidecar `evio_sim.json` with the camera-IMU extrinsics and the IMU noise. From a shell,
# `python -m evio_lib simulate boxes_like --out DIR --duration 5` does the same. Here we write 0.2 s and read
# them back: nothing may change.

# %%
clip = boxes.slice_time(boxes_cfg.t_end - 0.2, boxes_cfg.t_end)
with tempfile.TemporaryDirectory() as tmp:
    folder = write_ecd(clip, Path(tmp) / "boxes_clip")
    print(sorted(p.name for p in folder.iterdir()))
    print("events.txt starts with:\n" + "".join((folder / "events.txt").open().readlines()[:3]))
    back = read_ecd(folder)
assert np.array_equal(back.events, clip.events)
assert np.array_equal(back.frames, clip.frames) and np.array_equal(back.frame_times, clip.frame_times)
assert np.array_equal(back.imu.accel, clip.imu.accel) and np.array_equal(back.imu.gyro, clip.imu.gyro)
assert np.array_equal(back.groundtruth.p_BinG, clip.groundtruth.p_BinG)
assert np.allclose(back.R_CtoI, clip.R_CtoI) and back.camera == clip.camera
print(f"read back {len(back.events)} events, {len(back.frames)} frames, {len(back.imu)} IMU samples: identical")

# %% [markdown]
# ## Summary
#
# * An event pixel fires when its **log** intensity has moved by a contrast threshold $C$ from its reference (the
#   level of its last event); ON/OFF gives the direction. Turning points cost a full threshold (hysteresis).
# * The simulator interpolates $L$ linearly between renders to timestamp crossings, with per-pixel threshold
#   mismatch, a refractory period and Poisson noise; per pixel, $N_{\text{ON}}C_+ - N_{\text{OFF}}C_-$ tracks the
#   log-intensity change to within one threshold.
# * Adaptive sampling renders as often as the fastest pixel needs; the event count converges as the bound tightens.
# * In fast motion the APS frame blurs: the image moves several pixels during its exposure and the frame keeps a
#   smaller share of the scene's detail, while an event frame of a fixed number of events spans a fraction of the
#   exposure and loses less of its sharpness (section 4). The event rate follows the motion (room) and is several
#   times lower per pixel over sparse, distant terrain, as in the thesis, where the sparse Camp Atterbury scene
#   "resulted in a much lower rate of events compared to that of the Boxes dataset" (§4.1).
# * IMU, frames, events and ground truth come from one trajectory; the recording round-trips through the ECD layout.
#
# ## What comes next
#
# Events are not yet something a feature detector or a filter can use: they are a stream of $(t, x, y, p)$ tuples,
# not images. The next lesson, `04_event_reconstruction`, turns them into image frames from recordings like these:
# polarity frames (ON minus OFF events per pixel), time surfaces and voxel grids, then intensity reconstructed by
# integrating the events' log-intensity steps (the sum rule of section 2(c)) and by a small recurrent network.
# Lesson 05 then finds features in such frames.
#
# ## Exercises
#
# 1. Raise the refractory period of section 2(d) from 0 to 100 ms in steps and plot the number of events. When do
#    the fastest pixels start to lose events? Relate it to the time between two threshold crossings,
#    $C / |\dot L|$.
#
#    *Hint:* reuse `run_tiny` with `EventCameraParams(refractory_s=...)` and read `dropped_refractory`; estimate
#    $|\dot L|$ from consecutive log renders.
# 2. Lower the contrast thresholds to 0.1 and 0.05. How do the event count and the residual of 2(c) scale?
#    What would this cost a real sensor (bandwidth, noise)?
#
#    *Hint:* set `contrast_pos = contrast_neg = C` (and scale `contrast_sigma` with it); the residual of 2(c) is
#    bounded by one threshold.
# 3. Build the event frame of the fast moment from 1, 3, 10 and 30 ms of events and compute its sharpness $S$.
#    Which window length gives the sharpest frame, and why does a too-long window blur like an APS frame?
#
#    *Hint:* with `t_fast = cases['fastest']['t']`, select the events with $|t - t_{fast}| <$ half the window and
#    reuse `sharpness`; beware that a very sparse frame scores a high $S$ too.
# 4. Simulate `aerial_like` with `background_rate_hz = 0.1` and compare signal and noise events per second. At what
#    noise rate is every second event noise? (Thesis §4.1 found the aerial event frames noisy.)
#
#    *Hint:* `dataclasses.replace(aerial_cfg, events=dataclasses.replace(aerial_cfg.events, background_rate_hz=0.1))`
#    makes the changed config; noise adds rate x pixels x seconds events, so
#    compare it with the signal's events per pixel and second.
# 5. Write a longer clip with `write_ecd` and read only its IMU and ground truth (`read_ecd(..., load_events=False)`).
#    Integrate the gyro (minus the true bias) and compare the orientation with the ground truth after 1 s.
#
#    *Hint:* `with_events=False, with_frames=False` simulates only the IMU and ground truth; integrate the rotation
#    step by step, $R_{k+1} = R_k \exp([\boldsymbol\omega_k \Delta t]_\times)$ with $\boldsymbol\omega_k$ the mid-point
#    rate (`so3_exp`; lesson 09 derives this rule), and compare with `groundtruth_imu`.
#
# Solutions, with the code to run (checked by `tests/test_solutions.py`):
# [docs/solutions/03_event_camera_simulation.md](../docs/solutions/03_event_camera_simulation.md).
