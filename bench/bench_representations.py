"""Print events/s of every event representation on one core (goal: >= 10 M events/s for the voxel grid at 240x180).

Usage:  python bench/bench_representations.py [--events N] [--repeats R]

Events are uniform over a 240x180 sensor and 0.1 s, seed 0. The figure is the best of R runs (the least disturbed by
other processes). Measured on this 2-core CPU (2026-11-25, load 10 from other jobs), 1 M events: polarity frame
88.2 M events/s, time surface 3.5, voxel grid 16.9, adaptive windows 2.7 (docs/results/reconstruction.md).
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from evio_lib.events.array import make_events  # noqa: E402
from evio_lib.events.motion_compensation import motion_compensated_frame  # noqa: E402
from evio_lib.events.representations import (adaptive_windows, polarity_frame, time_surface,  # noqa: E402
                                             voxel_grid)
from evio_lib.geometry.camera import PinholeRadtan  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    n, w, h = args.events, 240, 180
    events = make_events(np.sort(rng.uniform(0, 0.1, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                         rng.choice([-1, 1], n))
    camera = PinholeRadtan.davis240c()
    imu_t = np.arange(-0.01, 0.11, 0.001)  # a 1 kHz gyro turning at 2 rad/s
    gyro = np.tile([1.2, -1.5, 0.4], (imu_t.size, 1))
    cases = {
        "polarity frame": lambda: polarity_frame(events, w, h),
        "time surface (2 channels)": lambda: time_surface(events, w, h),
        "voxel grid B=5 (normalised)": lambda: voxel_grid(events, w, h, 5),
        "adaptive windows": lambda: adaptive_windows(events, w, h),
        "motion-compensated frame (gyro)": lambda: motion_compensated_frame(events, camera, 0.05, imu_t, gyro,
                                                                            np.eye(3)),
    }
    for name, run in cases.items():
        best = min(_timed(run) for _ in range(args.repeats))
        print(f"{name:30s} {n / best / 1e6:8.1f} M events/s  ({best * 1e3:.1f} ms for {n} events)")


def _timed(run) -> float:
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
