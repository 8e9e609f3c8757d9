"""Benchmark of the SuperPoint detector: frames per second of detection + description on one grayscale image.

Run from the repository root::

    python bench/bench_superpoint.py                    # eager, fused, bf16, int8 (+ narrow) at 180x240 and 240x320
    python bench/bench_superpoint.py --runs 30 --repeats 5
    python bench/bench_superpoint.py --compile          # also torch.compile of fused and bf16 (compiles ~1 min each)
    python bench/bench_superpoint.py --weights PATH     # a trained checkpoint instead of the shipped/random one
    python bench/bench_superpoint.py --threads 1 --clock cpu   # CPU time of one thread: robust on a busy machine

Each number is ``SuperPointDetector.detect_and_describe(image)`` end to end (uint8 image in, keypoints, scores and
unit descriptors out: conversion, padding to multiples of 8, network, softmax, NMS, top-k, bicubic descriptor
sampling) with ``torch.set_num_threads(2)``: warm-up calls, then the median over ``--runs`` calls; this is repeated
``--repeats`` times (the modes interleaved, so that load from other processes hits them alike) and the range of the
medians is printed. Targets: >= 15 frames/s at 180x240 and >= 8 frames/s at 240x320 on the 2-core CPU.
Also printed: the relative difference of each fast path's logits and descriptors from the fp32 eager model, and the
share of its keypoints within 1 px of the fp32 ones (top 300, NMS 4), so speed is never bought blindly.

Modes (see evio_lib.features.network.inference_model): eager = the trained model as is (fp32, BN layers),
fused = BN folded into the convolutions + channels-last (fp32), bf16 = fused + bfloat16 autocast (final 1x1 layers
fp32), int8 = static int8 quantisation (FX, oneDNN), narrow = the half-width network in the "auto" mode.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings

import cv2
import numpy as np
import torch

from evio_lib.features import network as sp
from evio_lib.features.network.inference import _auto_mode


def _test_image(height: int, width: int) -> np.ndarray:
    """Return a natural (H, W) uint8 image: scikit-image's camera man resized, or a synthetic one without it."""
    try:
        from skimage import data

        image = data.camera()
    except Exception:  # noqa: BLE001 - any failure: fall back to a synthetic image
        image = (sp.calibration_images((512, 512), 1, seed=99)[0] * 255).astype(np.uint8)
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)


def _median_fps(detector: sp.SuperPointDetector, image: np.ndarray, runs: int, clock=time.perf_counter) -> float:
    """Return frames per second from the median time (by ``clock``) of ``runs`` detect_and_describe calls."""
    times = []
    for _ in range(runs):
        start = clock()
        detector.detect_and_describe(image)
        times.append(clock() - start)
    return 1.0 / statistics.median(times)


def _agreement(reference: sp.SuperPointDetector, fast: sp.SuperPointDetector, image: np.ndarray) -> str:
    """Return 'rel. diff logits/descriptors, keypoints within 1 px' of a fast path against the fp32 eager model."""
    x = sp.pad_to_cells(torch.from_numpy(image.astype(np.float32) / 255.0)[None, None])
    with torch.inference_mode():
        ref, out = reference._forward(x), fast._forward(x)
    rel = [float((out[k] - ref[k]).norm() / ref[k].norm()) for k in ("logits", "descriptors") if k in ref]
    kw = dict(image_shape=image.shape, nms_radius=4, max_keypoints=300)
    a = sp.postprocess(ref["logits"], None, **kw)[0].keypoints
    b = sp.postprocess(out["logits"], None, **kw)[0].keypoints
    close = (np.linalg.norm(b[:, None] - a[None], axis=2).min(axis=1) <= 1.0).mean() if len(a) and len(b) else 1.0
    return f"rel. diff {'/'.join(f'{r:.3f}' for r in rel)}, keypoints within 1 px {100 * close:.0f}%"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", default=["180x240", "240x320"], help="HxW image sizes")
    parser.add_argument("--runs", type=int, default=20, help="timed calls per median (default 20)")
    parser.add_argument("--warmup", type=int, default=3, help="untimed calls first (default 3)")
    parser.add_argument("--repeats", type=int, default=3, help="medians per mode, interleaved (default 3)")
    parser.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                        help="wall time (default), or process CPU time (with --threads 1: unaffected by other load)")
    parser.add_argument("--modes", nargs="+", default=["eager", "fused", "bf16", "int8"],
                        choices=sp.INFERENCE_MODES[1:])
    parser.add_argument("--no-narrow", action="store_true", help="skip the narrow (half-width) network")
    parser.add_argument("--compile", action="store_true", help="also time torch.compile of the fused model")
    parser.add_argument("--weights", default=None,
                        help="checkpoint path or shipped name (default: the shipped weights, else an untrained net)")
    parser.add_argument("--max-keypoints", type=int, default=1000)
    args = parser.parse_args()

    torch.set_num_threads(args.threads)
    clock = time.perf_counter if args.clock == "wall" else time.process_time
    warnings.simplefilter("ignore")  # torch.ao deprecation notices of the int8 path
    weights = args.weights
    if weights is None and sp.DEFAULT_WEIGHTS in sp.shipped_weights():
        weights = sp.DEFAULT_WEIGHTS
    source = weights if weights is not None else "untrained (random init, seed 0; no shipped weights yet)"
    print(f"SuperPoint benchmark: weights = {source}; torch {torch.__version__}, {args.threads} threads, "
          f"{os.cpu_count()} CPUs, {args.clock} clock; auto mode here = {_auto_mode(torch.device('cpu'))}")

    def make(mode: str, config: str = "full") -> sp.SuperPointDetector:
        common = dict(max_keypoints=args.max_keypoints, nms_radius=4, inference=mode)
        if weights is not None and config == "full":
            return sp.SuperPointDetector(weights=weights, **common)
        return sp.SuperPointDetector(weights=None, allow_random=True, model_config=config, **common)

    for size in args.sizes:
        height, width = (int(v) for v in size.lower().split("x"))
        image = _test_image(height, width)
        detectors: dict[str, sp.SuperPointDetector] = {}
        for mode in args.modes:
            start = time.perf_counter()
            detectors[mode] = make(mode)
            if mode == "int8":
                print(f"  (int8 calibration and conversion took {time.perf_counter() - start:.1f} s)")
        if not args.no_narrow:
            detectors["narrow (auto)"] = make("auto", "narrow")
        if args.compile:
            for mode in ("fused", "bf16"):
                det = make(mode)
                start = time.perf_counter()
                det._forward = torch.compile(det._forward)
                det.detect_and_describe(image)
                print(f"  (torch.compile of the {mode} model took {time.perf_counter() - start:.0f} s)")
                detectors[f"{mode} + compile"] = det
        for det in detectors.values():
            for _ in range(args.warmup):
                det.detect_and_describe(image)
        fps: dict[str, list[float]] = {name: [] for name in detectors}
        for _ in range(args.repeats):
            for name, det in detectors.items():
                fps[name].append(_median_fps(det, image, args.runs, clock))
        n_kp = len(next(iter(detectors.values())).detect_and_describe(image))
        print(f"\n{height}x{width} ({n_kp} keypoints from the first mode):")
        reference = detectors.get("eager") or make("eager")
        for name, values in fps.items():
            note = "" if name in ("eager", "narrow (auto)") else "  " + _agreement(reference, detectors[name], image)
            spread = f"range {min(values):.1f}-{max(values):.1f}"
            print(f"  {name:16s} {statistics.median(values):6.1f} frames/s  ({spread}){note}")


if __name__ == "__main__":
    main()
