"""Print the reconstruction quality table: MSE / SSIM of every method on the held-out simulated stretches and the real
slider_depth frames, which both splits report (see evio_lib.events.reconstruction.evaluation for the protocol and the
normalisation).

Usage:  python bench/reconstruction_quality.py [--methods direct high_pass firenet] [--max-frames 12]
                                              [--split test|val] [--precision auto|float32|bfloat16|int8]
        python bench/reconstruction_quality.py --fractions 0.05 0.1 0.2 0.35 0.7 1.0 --max-frames 8 --split val \
                                              --methods firenet RUN/best.pt     # SSIM against the window fraction n

With ``--fractions`` it prints, per method and simulated stretch, the SSIM for each n (windows of n H W events) and
the spread (max - min) over the n from 0.1 to 0.7, instead of the table at the thesis's n.

The first run simulates the three held-out stretches (0.4 s each, seed 101; several minutes) and caches them in data/cache.
"""
from __future__ import annotations

import argparse

from evio_lib.events.reconstruct import PRECISIONS, reconstructor_by_name_or_file
from evio_lib.events.reconstruction.evaluation import (EVAL_SEED, EVAL_STRETCHES, VALIDATION_SEED, quality_table,
                                                       score_windows, simulated_eval_sequence)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["direct", "high_pass", "firenet"],
                        help="reconstructor names or reconstruct-train checkpoint files (.pt)")
    parser.add_argument("--max-frames", type=int, default=12, help="scored windows per stretch (evenly spread)")
    parser.add_argument("--split", choices=["test", "val"], default="test",
                        help="test: the held-out stretches (seed 101) that are reported; val: the same stretches of "
                             "other scenes (seed 202) where networks and settings are chosen")
    parser.add_argument("--precision", choices=PRECISIONS, default=None,
                        help="the networks' arithmetic (default: each reconstructor's own, auto: int8 for FireNet on "
                             "an x86 CPU)")
    parser.add_argument("--fractions", type=float, nargs="+", metavar="N",
                        help="score windows of each n H W events instead of the thesis's n (an n sweep)")
    args = parser.parse_args()
    if args.max_frames < 1:
        parser.error(f"--max-frames must be >= 1; got {args.max_frames}")
    if args.fractions is not None and not all(0 < n <= 10 for n in args.fractions):
        parser.error(f"--fractions must lie in (0, 10]; got {args.fractions}")
    seed = VALIDATION_SEED if args.split == "val" else EVAL_SEED
    if args.fractions is not None:
        sweep(args.methods, args.fractions, args.max_frames, seed, args.precision)
        return
    rows = quality_table(args.methods, max_frames=args.max_frames, seed=seed, with_slider=True,
                         precision=args.precision)   # the real slider frames: validation and test alike
    print(f"| {'sequence':32s} | {'method':22s} | {'MSE':>6s} | {'SSIM':>6s} | frames |")
    print(f"|{'-' * 34}|{'-' * 24}|{'-' * 8}|{'-' * 8}|--------|")
    for r in rows:  # a network's row names the precision it computed in (the default "auto" picks int8 on x86 CPUs)
        method = r["method"] if r.get("precision") is None else f"{r['method']} ({r['precision']})"
        print(f"| {r['sequence']:32s} | {method:22s} | {r['mse']:6.3f} | {r['ssim']:6.3f} | {r['frames']:6d} |")


def sweep(methods: list[str], fractions: list[float], max_frames: int, seed: int, precision: str | None) -> None:
    """Print SSIM per n for every method and simulated stretch, and the spread over the n within [0.1, 0.7]."""
    print("| stretch | method | " + " | ".join(f"n = {n:g}" for n in fractions) + " | spread, n = 0.1-0.7 |")
    print("|---|---|" + "---|" * len(fractions) + "---|")
    for stretch in EVAL_STRETCHES:
        sequence = simulated_eval_sequence(stretch, seed=seed)
        for method in methods:
            recs = [reconstructor_by_name_or_file(method, sequence.width, sequence.height, precision=precision)
                    for _ in fractions]                               # a fresh state for each n
            ssim = [score_windows(rec, sequence, n, max_frames=max_frames)["ssim"] for rec, n in zip(recs, fractions)]
            inside = [v for n, v in zip(fractions, ssim) if 0.1 <= n <= 0.7]
            spread = f"{max(inside) - min(inside):.3f}" if inside else "-"
            chosen = getattr(recs[0], "precision", None)
            label = method if chosen is None else f"{method} ({chosen})"
            print(f"| {stretch} | {label} | " + " | ".join(f"{v:.3f}" for v in ssim) + f" | {spread} |", flush=True)


if __name__ == "__main__":
    main()
