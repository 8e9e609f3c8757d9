"""Print SSIM of reconstructors on rooms of held-out photographs in linear light: data unlike the training sequences.

Each recording (:func:`evio_lib.events.reconstruction.evaluation.linear_light_room_sequence`) is a room whose every
surface is a photograph of the photo folder's validation (or test) split, its light the photographs' display values
decoded with gamma 2.2 (about 650 to 1), its events from renders at a fixed 1 kHz with one threshold C = 0.2
(`--contrast`) and no mismatch or noise: photographs (held out from training, though checkpoints are kept on the
sets' validation sequences of the same photographs), light, renderer and sensor all differ from what the networks
trained on. Each
recording is 1 s of the boxes_like motion; windows of n H W events, 8 scored per recording (evenly spread, after the
first 0.1 s), each against the sharp render at its last event, with the 1st/99th-percentile stretch of
evio_lib.events.reconstruction.evaluation.

Usage:  python bench/reconstruction_linear_light.py [--methods high_pass firenet RUN/best.pt] [--split val|test]
                                                    [--fractions 0.1 0.35] [--photos DIR] [--gamma 2.2]
                                                    [--contrast 0.2]

Choose on --split val (seeds 303, 404, 505); score --split test (seeds 606, 707, 808) once, for the network kept.
About 4 s of simulation per recording and 10-30 s per method and n (one thread).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from evio_lib.events.reconstruct import PRECISIONS, reconstructor_by_name_or_file
from evio_lib.events.reconstruction.evaluation import LINEAR_LIGHT_SEEDS, linear_light_room_sequence, score_windows
from evio_lib.sim.photos import list_photos, resolve_photo_option


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["direct", "high_pass", "firenet"],
                        help="reconstructor names or reconstruct-train checkpoint files (.pt)")
    parser.add_argument("--split", choices=["val", "test"], default="val",
                        help="val: validation photographs, seeds 303 404 505 (choose here); test: test photographs, "
                             "seeds 606 707 808 (score once)")
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.1, 0.35], metavar="N",
                        help="window sizes n (N_e = n H W events)")
    parser.add_argument("--max-frames", type=int, default=8, help="scored windows per recording (evenly spread)")
    parser.add_argument("--photos", default=None, help="the photo folder (default: ../shared/data/photos or "
                                                       "$EVIO_PHOTOS)")
    parser.add_argument("--gamma", type=float, default=2.2, help="the display encoding undone, I = V^gamma (1: "
                                                                 "display values as light)")
    parser.add_argument("--contrast", type=float, default=0.2,
                        help="the rooms' contrast threshold C (direct and high_pass assume 0.2 whatever it is)")
    parser.add_argument("--precision", choices=PRECISIONS, default=None, help="the networks' arithmetic")
    args = parser.parse_args()
    if args.max_frames < 1:
        parser.error(f"--max-frames must be >= 1; got {args.max_frames}")
    if not all(0 < n <= 10 for n in args.fractions):
        parser.error(f"--fractions must lie in (0, 10]; got {args.fractions}")
    if not (np.isfinite(args.gamma) and args.gamma > 0):
        parser.error(f"--gamma must be a positive number; got {args.gamma}")
    if not (np.isfinite(args.contrast) and 0 < args.contrast <= 2):
        parser.error(f"--contrast must lie in (0, 2]; got {args.contrast}")
    try:  # the photo folder first: a missing one is said in one line before anything is simulated
        folder = resolve_photo_option(args.photos)
        if folder is None:
            raise ValueError("no photo folder found: give --photos DIR (a folder of .jpg/.png photographs)")
        list_photos(folder, args.split)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        raise SystemExit(2)
    seeds = LINEAR_LIGHT_SEEDS[args.split]
    scores = {(m, n): [] for m in args.methods for n in args.fractions}
    labels = dict.fromkeys(args.methods, "")
    print("| recording | events | method | " + " | ".join(f"n = {n:g}" for n in args.fractions) + " |")
    print("|---|---|---|" + "---|" * len(args.fractions))
    for seed in seeds:
        sequence = linear_light_room_sequence(seed, args.split, photos=folder, gamma=args.gamma,
                                              contrast=args.contrast)
        for method in args.methods:
            row = []
            for n in args.fractions:  # a fresh state for each n
                rec = reconstructor_by_name_or_file(method, sequence.width, sequence.height, precision=args.precision)
                ssim = score_windows(rec, sequence, n, max_frames=args.max_frames)["ssim"]
                scores[(method, n)].append(ssim)
                row.append(ssim)
            chosen = getattr(rec, "precision", None)   # what auto picked (int8 for FireNet on an x86 CPU)
            labels[method] = method if chosen is None else f"{method} ({chosen})"
            print(f"| seed {seed} | {sequence.events.size:,} | {labels[method]} | "
                  + " | ".join(f"{v:.3f}" for v in row) + " |", flush=True)
    for method in args.methods:
        print(f"| mean of {len(seeds)} | | {labels[method]} | "
              + " | ".join(f"{np.mean(scores[(method, n)]):.3f}" for n in args.fractions) + " |")


if __name__ == "__main__":
    main()
