"""Benchmark: real-time factor of the MSCKF back end (target: >= 10x on one core).

The setting: 20 Hz images, 1 kHz IMU, 60 tracked features per image, N_max = 20, one BLAS thread. The
simulation of the IMU and of the feature tracks is done first and excluded from the timing; the timed part is
``Msckf.feed_imu`` + ``Msckf.process_image`` for every image (propagation, augmentation, triangulation, updates,
marginalisation). Prints wall and CPU time and the real-time factor = simulated duration / time.

Usage: python bench/bench_msckf.py [--preset boxes_like] [--duration 20] [--repeat 3] [--seed 0] [--window 20]
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core; small matrices are much slower when threaded
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from evio_lib.msckf.experiment import (  # noqa: E402
    VioSimConfig,
    experiment_msckf_config,
    initial_state,
    simulate_data,
)
from evio_lib.msckf.filter import Msckf  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="boxes_like", choices=["boxes_like", "aerial_like"])
    parser.add_argument("--duration", type=float, default=20.0, help="simulated seconds (default 20)")
    parser.add_argument("--repeat", type=int, default=3, help="timed repetitions; the best is reported (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--window", type=int, default=20,
                        help="N_max (default 20, S-MSCKF's window; the library's default is 40)")
    args = parser.parse_args()

    config = VioSimConfig(preset=args.preset, duration=args.duration, seed=args.seed, features=60,
                          imu_rate_hz=1000.0, frame_rate_hz=20.0, msckf_overrides={"max_camera_states": args.window})
    t0 = time.perf_counter()
    data = simulate_data(config)
    print(f"simulated {args.preset} {args.duration:g} s: {len(data.imu)} IMU samples, {len(data.frames)} images, "
          f"{np.mean([len(f) for f in data.frames]):.1f} features/image (simulation {time.perf_counter() - t0:.1f} s, "
          "not timed)")
    msckf_config = experiment_msckf_config(config, data.noise, data.camera)
    state = initial_state(data, msckf_config, 0)
    print(f"threads: OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}, N_max = "
          f"{msckf_config.max_camera_states} ({'oldest third' if msckf_config.marginalize_third else 'two-way'} pruning), "
          f"OC {'on' if msckf_config.observability_constrained else 'off'}")
    walls, cpus, per_image = [], [], []
    for _ in range(args.repeat):
        wall0, cpu0 = time.perf_counter(), time.process_time()
        f = Msckf(msckf_config, state)
        f.feed_imu(data.imu.t, data.imu.gyro, data.imu.accel)
        used = 0
        for frame in data.frames:
            used += f.process_image(frame.t, frame.ids, frame.xy).n_features_used
        cpus.append(time.process_time() - cpu0)
        walls.append(time.perf_counter() - wall0)
        per_image.append(walls[-1] / len(data.frames))
    duration = args.duration
    print(f"features used per image: {used / len(data.frames):.1f}")
    print(f"wall time: best {min(walls):.2f} s, median {np.median(walls):.2f} s -> real-time factor "
          f"{duration / min(walls):.1f}x (best), {duration / np.median(walls):.1f}x (median); "
          f"{1e3 * min(per_image):.1f} ms per image")
    print(f"CPU time:  best {min(cpus):.2f} s, median {np.median(cpus):.2f} s -> real-time factor "
          f"{duration / min(cpus):.1f}x (best), {duration / np.median(cpus):.1f}x (median)")
    print(f"target: 10x real time -> {'met' if duration / np.median(cpus) >= 10 else 'NOT met'} (median CPU)")


if __name__ == "__main__":
    main()
