"""Print the reconstruction rate (frames/s) at 240x180, batch 1, state carried, for every method.

Usage:  python bench/bench_reconstruction.py [--frames N] [--threads T]

Each frame is one window of N_e = 0.35 * 240 * 180 events (uniform random events, seed 0); the rate includes building
the voxel grid. The large E2VID-style network runs with random weights (none are shipped): its speed does not depend on
them. Goal for the default network: at least 100 frames/s on a 2-core CPU. Measured figures: docs/reconstruction.md.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from evio_lib.events.array import make_events
from evio_lib.events.reconstruct import create_reconstructor
from evio_lib.events.reconstruction.nets import E2VIDRecurrent
from evio_lib.events.representations import voxel_grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    w, h = 240, 180
    n = int(0.35 * w * h)
    rng = np.random.default_rng(0)
    windows = [make_events(np.sort(rng.uniform(k, k + 1, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                           rng.choice([-1, 1], n)) for k in range(args.frames)]
    methods = {name: create_reconstructor(name, w, h) for name in ("direct", "high_pass", "firenet")}
    with tempfile.TemporaryDirectory() as folder:  # a random-weight E2VID-style UNet, loaded the way users load one
        path = Path(folder) / "e2vid_random.pt"
        torch.save({"format": "evio-reconstructor-v1", "architecture": "e2vid", "network_options": {}, "num_bins": 5,
                    "state_dict": E2VIDRecurrent().state_dict()}, path)
        methods["e2vid"] = create_reconstructor("learned", w, h, checkpoint=path, device="cpu")
    start = time.perf_counter()
    for window in windows:
        voxel_grid(window, w, h, 5)
    print(f"{'voxel grid alone':24s} {args.frames / (time.perf_counter() - start):8.1f} frames/s")
    for name, rec in methods.items():
        rec.reset()
        rec.reconstruct(windows[0])  # warm-up (allocations, kernels)
        count = args.frames if name != "e2vid" else max(3, args.frames // 10)
        start = time.perf_counter()
        for window in windows[:count]:
            rec.reconstruct(window)
        rate = count / (time.perf_counter() - start)
        print(f"{name:24s} {rate:8.1f} frames/s  ({1e3 / rate:.1f} ms per frame, {args.threads} threads)")


if __name__ == "__main__":
    main()
