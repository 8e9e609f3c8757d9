"""Benchmark: wall time to simulate whole recordings of each preset (events, APS frames, IMU, ground truth).

Usage:  python bench/bench_simulation.py [--duration 10] [--presets boxes_like aerial_like] [--no-frames] [--no-events]
                                        [--jobs 2]

Prints, per preset, the wall time of each sensor, the number of renders the adaptive event sampler needed, the event count and
the event rate. Target: the full 10 s ``boxes_like`` simulation in under two minutes on the 2-core development machine.
Targets: the 60 s ``boxes_like`` without events in <= 30 s (``--duration 60 --no-events --jobs 2``) and 5 s
with events in <= 10 s (``--duration 5``). ``--jobs``: processes that render the APS frames (default 2; the frames do
not depend on it). This is a script that prints figures, not a timed test.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from evio_lib.pipeline.dataset import PRESET_DURATIONS  # noqa: E402
from evio_lib.sim.presets import PRESETS, SimulationConfig, simulate_sequence  # noqa: E402


def main() -> None:
    """Simulate each preset and print its timings."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--presets", nargs="+", default=list(PRESETS), choices=PRESETS)
    parser.add_argument("--no-frames", action="store_true")
    parser.add_argument("--no-events", action="store_true")
    parser.add_argument("--jobs", type=int, default=2, help="processes that render the APS frames (default 2)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for preset in args.presets:
        config = SimulationConfig(preset=preset, duration=args.duration, seed=args.seed, with_frames=not args.no_frames,
                                  with_events=not args.no_events,
                                  trajectory_duration=PRESET_DURATIONS.get(preset))  # the preset's whole motion
        cpu = time.process_time()
        start = time.perf_counter()
        timings: dict[str, float] = {}  # seconds per sensor (kept out of the recording's metadata)
        sequence = simulate_sequence(config, timings=timings, jobs=args.jobs)
        wall = time.perf_counter() - start
        cpu = time.process_time() - cpu  # this process only (the frame workers are not counted)
        timings.update(sequence.metadata["timings"])  # the deterministic counts (event_renders)
        n_events = 0 if sequence.events is None else len(sequence.events)
        print(f"{preset}: {args.duration:g} s simulated in {wall:.1f} s wall, {cpu:.1f} s CPU in this process "
              f"(events {timings.get('events_s', 0):.1f} s with {int(timings.get('event_renders', 0))} renders, "
              f"frames {timings.get('frames_s', 0):.1f} s, IMU {timings['imu_s']:.2f} s); "
              f"{n_events} events ({n_events / args.duration / 1e6:.2f} M events per simulated second), "
              f"{len(sequence.frames)} frames", flush=True)


if __name__ == "__main__":
    main()
