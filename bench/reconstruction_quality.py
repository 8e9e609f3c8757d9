"""Print the reconstruction quality table: MSE / SSIM of every method on the held-out simulated stretches and the real
slider_depth frames (see evio_lib.events.reconstruction.evaluation for the protocol and the normalisation).

Usage:  python bench/reconstruction_quality.py [--methods direct high_pass firenet] [--max-frames 12]
                                              [--split test|val] [--precision float32|bfloat16|int8]

The first run simulates the three held-out stretches (0.4 s each, seed 101; several minutes) and caches them in data/cache.
"""
from __future__ import annotations

import argparse

from evio_lib.events.reconstruct import PRECISIONS
from evio_lib.events.reconstruction.evaluation import EVAL_SEED, VALIDATION_SEED, quality_table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["direct", "high_pass", "firenet"],
                        help="reconstructor names or reconstruct-train checkpoint files (.pt)")
    parser.add_argument("--max-frames", type=int, default=12, help="scored windows per stretch (evenly spread)")
    parser.add_argument("--split", choices=["test", "val"], default="test",
                        help="test: the held-out stretches (seed 101) that are reported; val: the same stretches of "
                             "other scenes (seed 202) where networks and settings are chosen")
    parser.add_argument("--precision", choices=PRECISIONS, default=None,
                        help="the networks' arithmetic (default: each reconstructor's own, float32)")
    args = parser.parse_args()
    seed = VALIDATION_SEED if args.split == "val" else EVAL_SEED
    rows = quality_table(args.methods, max_frames=args.max_frames, seed=seed, with_slider=args.split == "test",
                         precision=args.precision)
    print(f"| {'sequence':32s} | {'method':22s} | {'MSE':>6s} | {'SSIM':>6s} | frames |")
    print(f"|{'-' * 34}|{'-' * 24}|{'-' * 8}|{'-' * 8}|--------|")
    for r in rows:
        print(f"| {r['sequence']:32s} | {r['method']:22s} | {r['mse']:6.3f} | {r['ssim']:6.3f} | {r['frames']:6d} |")


if __name__ == "__main__":
    main()
