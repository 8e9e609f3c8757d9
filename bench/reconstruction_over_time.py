"""Print SSIM against the window index over one held-out stretch: does a network keep its image over a long run?

The training sequences are 40 windows long, each started from an empty state; a 0.4 s stretch at n = 0.1 feeds the
network hundreds of windows in a row. This prints, per method, the SSIM of windows evenly spread over the whole
stretch (the first one included, so the warm-up shows), each against the sharp render at its last event, with the
stretch and SSIM of evio_lib.events.reconstruction.evaluation. A network whose SSIM falls late in the run and stays
down has a state that does not recover; the mean of `reconstruction_quality.py --fractions` cannot tell that from a
network that is worse at that window size throughout.

Usage:  python bench/reconstruction_over_time.py [--stretch boxes_like_fast] [--fraction 0.1] [--points 16] \\
            [--split val|test] [--methods firenet RUN/best.pt]

The first call simulates the stretch and caches it in data/cache (as reconstruction_quality.py does).
"""
from __future__ import annotations

import argparse

import numpy as np

from evio_lib.events.reconstruct import PRECISIONS, reconstruct_windows, reconstructor_by_name_or_file
from evio_lib.events.reconstruction.evaluation import (EVAL_SEED, EVAL_STRETCHES, VALIDATION_SEED, image_quality,
                                                       simulated_eval_sequence)
from evio_lib.events.representations import count_windows, window_size_from_fraction


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["high_pass", "firenet"],
                        help="reconstructor names or reconstruct-train checkpoint files (.pt)")
    parser.add_argument("--stretch", choices=sorted(EVAL_STRETCHES), default="boxes_like_fast")
    parser.add_argument("--fraction", type=float, default=0.1, help="window size n (N_e = n H W events)")
    parser.add_argument("--points", type=int, default=16, help="scored windows, evenly spread over the stretch")
    parser.add_argument("--split", choices=["test", "val"], default="val",
                        help="val: the stretch of seed 202 (choose here); test: seed 101 (reported)")
    parser.add_argument("--precision", choices=PRECISIONS, default=None, help="the networks' arithmetic")
    args = parser.parse_args()
    if not 0 < args.fraction <= 10:
        parser.error(f"--fraction must lie in (0, 10]; got {args.fraction}")
    if args.points < 2:
        parser.error(f"--points must be >= 2; got {args.points}")
    sequence = simulated_eval_sequence(args.stretch, seed=VALIDATION_SEED if args.split == "val" else EVAL_SEED)
    bounds = count_windows(sequence.events, window_size_from_fraction(args.fraction, sequence.width, sequence.height))
    scored = np.unique(np.linspace(0, len(bounds) - 1, args.points).round().astype(int))
    print(f"{args.stretch} ({args.split}), n = {args.fraction:g}: {len(bounds)} windows of "
          f"{sequence.events.size:,} events; SSIM at each window index")
    print("| method | " + " | ".join(str(k) for k in scored) + " |")
    print("|---|" + "---|" * len(scored))
    for method in args.methods:
        rec = reconstructor_by_name_or_file(method, sequence.width, sequence.height, precision=args.precision)
        frames, times = reconstruct_windows(rec, sequence.events, bounds)
        ssim = [image_quality(frames[k], sequence.render(float(times[k])))["ssim"] for k in scored]
        chosen = getattr(rec, "precision", None)
        label = method if chosen is None else f"{method} ({chosen})"
        print(f"| {label} | " + " | ".join(f"{v:.2f}" for v in ssim) + " |", flush=True)


if __name__ == "__main__":
    main()
