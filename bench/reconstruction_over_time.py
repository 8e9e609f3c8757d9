"""Print SSIM against the window index over one held-out stretch: does a network keep its image over a long run?

The training sequences are 40 windows long, each started from an empty state; the violent boxes stretch (0.4 s)
feeds a network 658 windows in a row at n = 0.1 (the gentle boxes and the terrain 60-72). This prints, per method,
the SSIM of windows evenly spread over the whole stretch (the first one included, so the warm-up shows), each
against the sharp render at its last event, with the stretch and SSIM of evio_lib.events.reconstruction.evaluation.
A network whose SSIM falls late in the run and stays down, where another recovers, may have a state that does not
recover (or may fail on the stretch's later content); the mean of `reconstruction_quality.py --fractions` tells
neither from a network that is worse at that window size throughout. `--start-window K` feeds the windows from K on,
from an empty state (indices stay those of the whole stretch): a network that is also low there when started fresh
fails on the content, not on a state carried from earlier windows.

Usage:  python bench/reconstruction_over_time.py [--stretch boxes_like_fast] [--fraction 0.1] [--points 16] \\
            [--start-window 0] [--split val|test] [--precision auto|float32|bfloat16|int8] \\
            [--methods firenet RUN/best.pt]

The first call simulates the stretch and caches it in data/cache (as reconstruction_quality.py does).
"""
from __future__ import annotations

import argparse
import sys

from evio_lib.events.reconstruct import PRECISIONS, reconstructor_by_name_or_file
from evio_lib.events.representations import count_windows, window_size_from_fraction
from evio_lib.events.reconstruction.evaluation import (EVAL_SEED, EVAL_STRETCHES, VALIDATION_SEED,
                                                       simulated_eval_sequence, window_scores)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["high_pass", "firenet"],
                        help="reconstructor names or reconstruct-train checkpoint files (.pt)")
    parser.add_argument("--stretch", choices=sorted(EVAL_STRETCHES), default="boxes_like_fast")
    parser.add_argument("--fraction", type=float, default=0.1, help="window size n (N_e = n H W events)")
    parser.add_argument("--points", type=int, default=16,
                        help="scored windows, evenly spread over the windows fed (at most every one)")
    parser.add_argument("--start-window", type=int, default=0,
                        help="feed the windows from this index on, from an empty state")
    parser.add_argument("--split", choices=["test", "val"], default="val",
                        help="val: the stretch of seed 202 (choose here); test: seed 101 (reported)")
    parser.add_argument("--precision", choices=PRECISIONS, default=None, help="the networks' arithmetic")
    args = parser.parse_args()
    if not 0 < args.fraction <= 10:
        parser.error(f"--fraction must lie in (0, 10]; got {args.fraction}")
    if args.points < 2:
        parser.error(f"--points must be >= 2; got {args.points}")
    if args.start_window < 0:
        parser.error(f"--start-window must be >= 0; got {args.start_window}")
    sequence = simulated_eval_sequence(args.stretch, seed=VALIDATION_SEED if args.split == "val" else EVAL_SEED)
    bounds = count_windows(sequence.events, window_size_from_fraction(args.fraction, sequence.width, sequence.height))
    if len(bounds) == 0:
        parser.error(f"--fraction {args.fraction:g}: the {args.stretch} stretch has {sequence.events.size:,} "
                     f"events, not one window")
    if args.start_window >= len(bounds):
        parser.error(f"--start-window {args.start_window}: the stretch has {len(bounds)} windows at n = "
                     f"{args.fraction:g} (indices 0-{len(bounds) - 1})")
    try:                                                            # every name and file checked before the runs
        recs = {m: reconstructor_by_name_or_file(m, sequence.width, sequence.height, precision=args.precision)
                for m in args.methods}
    except ValueError as error:                                     # an unknown name, a missing or foreign file
        print(f"error: {error}", file=sys.stderr)
        raise SystemExit(2)
    for i, (method, rec) in enumerate(recs.items()):             # windows from start_window fed, any may be scored
        each = window_scores(rec, sequence, None, warmup_s=0.0, max_frames=args.points,
                             bounds=bounds[args.start_window:])
        if i == 0:
            start = f", fed from window {args.start_window}" if args.start_window else ""
            print(f"{args.stretch} ({args.split}), n = {args.fraction:g}: {len(bounds)} windows of "
                  f"{sequence.events.size:,} events{start}; SSIM at each window index")
            print("| method | " + " | ".join(str(k + args.start_window) for k in each["index"]) + " |")
            print("|---|" + "---|" * len(each["index"]))
        chosen = getattr(rec, "precision", None)
        label = method if chosen is None else f"{method} ({chosen})"
        print(f"| {label} | " + " | ".join(f"{v:.2f}" for v in each["ssim"]) + " |", flush=True)

if __name__ == "__main__":
    main()
