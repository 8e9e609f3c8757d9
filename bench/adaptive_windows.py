"""Print SSIM of the shipped network with adaptive windows against fixed window fractions n on the held-out stretches.

Usage:  python bench/adaptive_windows.py [--ratios 1.5 2.0] [--fractions 0.2 0.35 0.7] [--max-frames 12]

Adaptive windows close at a fixed number of events per active pixel (evio_lib.events.representations.adaptive_windows);
the mean window size they choose is printed as a fraction n of H W, next to the fixed-n scores.
"""
from __future__ import annotations

import argparse

from evio_lib.events.reconstruct import create_reconstructor
from evio_lib.events.reconstruction.evaluation import EVAL_STRETCHES, score_windows, simulated_eval_sequence
from evio_lib.events.representations import adaptive_windows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ratios", type=float, nargs="+", default=[1.5, 2.0])
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.2, 0.35, 0.7])
    parser.add_argument("--method", default="firenet")
    parser.add_argument("--max-frames", type=int, default=12)
    args = parser.parse_args()
    for name in EVAL_STRETCHES:
        seq = simulated_eval_sequence(name)
        cells = []
        for n in args.fractions:
            r = score_windows(create_reconstructor(args.method, seq.width, seq.height), seq, n, max_frames=args.max_frames)
            cells.append(f"n={n}: {r['ssim']:.3f}")
        for ratio in args.ratios:
            bounds = adaptive_windows(seq.events, seq.width, seq.height, events_per_active_pixel=ratio)
            r = score_windows(create_reconstructor(args.method, seq.width, seq.height), seq, None,
                              max_frames=args.max_frames, bounds=bounds)
            cells.append(f"adaptive {ratio} (mean n {r['mean_fraction']:.2f}): {r['ssim']:.3f}")
        print(f"{name:16s} " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
