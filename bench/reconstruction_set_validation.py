"""Score reconstructor checkpoints on a training set's validation (or test) sequences, as reconstruct-train validates.

Usage:  python bench/reconstruction_set_validation.py --data data/reconstruction_set_v3 [--split val] [--threads 2] \\
            evio_lib/weights/reconstruction_firenet.pt runs/firenet_stage4/best.pt

Prints per checkpoint the SSIM after the benchmark's 1st/99th-percentile stretch (what ``select_by="ssim_stretched"``
chooses by), the raw SSIM and the L1 (``training.evaluate_on_samples``: every window of every sequence, whole 64 x 64
views, from an empty state). Sets made by other generator versions can be compared: a checkpoint's score on two sets
says how much harder one set's windows are.
"""
from __future__ import annotations

import argparse
import sys

import torch

from evio_lib.events.reconstruct import LearnedReconstructor
from evio_lib.events.reconstruction.training import ReconstructionTrainConfig, evaluate_on_samples, open_split


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoints", nargs="+", help="reconstruct-train checkpoints or the shipped weights (.pt)")
    parser.add_argument("--data", required=True, help="a training set made by reconstruct-data")
    parser.add_argument("--split", choices=["val", "test"], default="val")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    if args.threads < 1:
        parser.error(f"--threads must be >= 1; got {args.threads}")
    torch.set_num_threads(args.threads)
    try:
        data = open_split(args.data, args.split)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    config = ReconstructionTrainConfig.from_dict({"lambda_stretched": 1.0})
    print(f"| checkpoint | {args.split} sequences | stretched SSIM | raw SSIM | L1 |")
    print("|---|---|---|---|---|")
    for path in args.checkpoints:
        try:  # a missing, damaged or foreign file: one line naming it (the checks of LearnedReconstructor)
            net = LearnedReconstructor(64, 64, path, device="cpu", threads=args.threads, precision="float32").net
        except ValueError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        r = evaluate_on_samples(net, data, config)
        print(f"| {path} | {len(data)} | {r['ssim_stretched']:.4f} | {r['ssim']:.4f} | {r['l1']:.4f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
