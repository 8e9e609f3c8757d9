"""Benchmark: events per second of ``EventSimulator.step`` alone, on one core.

Pre-renders the log images of a 240x180 periodic texture translating diagonally (renders are excluded from the
timing), then times ``step`` over the whole sequence for three render steps: dt_b, the step at which the largest
per-sample log change is 0.5 C (ESIM's adaptive-sampling operating point, simulate_events' default bound),
dt_b / 4 (few events per step: the fixed full-image cost dominates) and 4 dt_b (several events per pixel and
step), with float32 log images (what simulate_events passes for float32 renders) and float64 ones. Prints
events/step, ms/step and events/s (best of --repeats passes).

Run:  python bench/bench_event_generator.py [--repeats 5] [--steps 200] [--speed 200]
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: set before NumPy loads its BLAS/OpenMP runtimes
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import itertools  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from evio_lib.events.simulate import EventCameraParams, EventSimulator, log_intensity  # noqa: E402

WIDTH, HEIGHT = 240, 180


def make_texture(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """Return a periodic (size, size) float32 texture in [0.05, 1]: noise low-passed at a few scales (via FFT)."""
    f = np.fft.fftfreq(size)
    f2 = f[:, None] ** 2 + f[None, :] ** 2
    tex = np.zeros((size, size))
    for sigma, weight in ((2.0, 0.3), (6.0, 0.5), (16.0, 1.0)):
        # Gaussian blur of std sigma [px] as a product in the frequency domain: exp(-2 pi^2 sigma^2 f^2)
        kernel = np.exp(-2 * np.pi**2 * sigma**2 * f2)
        layer = np.fft.ifft2(np.fft.fft2(rng.standard_normal((size, size))) * kernel).real
        tex += weight * layer / layer.std()
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    return (0.05 + 0.95 * tex).astype(np.float32)


def render_sequence(texture: np.ndarray, speed_px_s: float, dt: float, steps: int,
                    dtype: type = np.float32) -> tuple[np.ndarray, list]:
    """Return (times, log images of ``dtype``) of the (periodic) texture moving at speed*(cos30, sin30) px/s."""
    times = dt * np.arange(steps + 1)
    direction = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    logs = []
    for t in times:
        sx, sy = 50.0 + speed_px_s * t * direction
        warp = np.array([[1.0, 0.0, sx], [0.0, 1.0, sy]], np.float32)  # dst(x, y) = tex(x + sx, y + sy)
        img = cv2.warpAffine(texture, warp, (WIDTH, HEIGHT), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                             borderMode=cv2.BORDER_WRAP)
        logs.append(log_intensity(img.astype(dtype), 1e-3))
    return times, logs


def time_steps(times: np.ndarray, logs: list, params: EventCameraParams, repeats: int) -> tuple[int, float]:
    """Return (events per pass, best seconds per pass) of EventSimulator.step over the sequence."""
    best, n_events = np.inf, 0
    for r in range(repeats):
        sim = EventSimulator(WIDTH, HEIGHT, params, rng=np.random.default_rng(r))
        sim.reset(logs[0], times[0])
        n = 0
        start = time.perf_counter()
        for t, log_image in zip(times[1:], logs[1:]):
            n += sim.step(log_image, t).shape[0]
        best = min(best, time.perf_counter() - start)
        n_events = n
    return n_events, best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--speed", type=float, default=200.0, help="texture speed [px/s]")
    parser.add_argument("--steps", type=int, default=200, help="steps per scenario")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    texture = make_texture(rng)
    params = EventCameraParams()  # C = 0.2, sigma = 0.03, refractory 0.1 ms, no noise
    print(f"EventSimulator.step on {WIDTH}x{HEIGHT} log images of a texture moving at {args.speed:.0f} px/s "
          f"(C={params.contrast_pos}, sigma={params.contrast_sigma}, refractory={params.refractory_s} s); "
          f"OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}, best of {args.repeats}")
    # ESIM operating point: the render step at which the largest per-sample log change is 0.5 C (simulate_events'
    # default bound), estimated from the peak rate over a short probe sequence
    _, probe = render_sequence(texture, args.speed, 1e-3, 200, dtype=np.float64)
    peak_rate = max(float(np.abs(b - a).max()) for a, b in zip(probe[:-1], probe[1:])) / 1e-3
    dt_bound = 0.5 * params.contrast_pos / peak_rate
    for dtype, dt in itertools.product((np.float32, np.float64), (dt_bound / 4, dt_bound, 4 * dt_bound)):
        times, logs = render_sequence(texture, args.speed, dt, args.steps, dtype=dtype)
        max_change = max(float(np.abs(b - a).max()) for a, b in zip(logs[:-1], logs[1:]))
        n_events, seconds = time_steps(times, logs, params, args.repeats)
        steps = len(times) - 1
        print(f"  {np.dtype(dtype).name} logs, render dt={dt * 1e3:5.2f} ms: "
              f"max|dL|/C={max_change / params.contrast_pos:4.2f} {steps:4d} steps {n_events / steps:6.0f} events/step "
              f"{seconds * 1e3 / steps:6.3f} ms/step {n_events / seconds / 1e6:6.2f} M events/s")

if __name__ == "__main__":
    main()
