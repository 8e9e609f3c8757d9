"""Benchmark: the CNN's inference modes (fp32 fused, bfloat16, int8) on what they are for, at one thread.

For each mode of ``SuperPointDetector(inference=...)`` and each of ``--weights`` (default: the shipped network behind
``create_detector("superpoint")``; e.g. ``--weights pretrained_detdesc_round1_gpu distilled_narrow`` compares the
half-width distilled network with its teacher):

1. speed: CPU milliseconds of ``detect_and_describe`` per 240 x 180 APS frame of ``boxes_like`` (one thread;
   network and post-processing), and frames per second;
2. agreement with fp32: the share of keypoints within 0.1 px and 1 px of the fused fp32 ones, and the largest
   descriptor difference of the keypoints at the same place;
3. the held-out homography benchmark (thesis Tables 2-5, ``features-benchmark``'s metrics) on the VALIDATION image
   pool (a choice is made on validation; the test pool is ``--pool test``), with the thesis's event-frame settings
   (240 x 320, the pipeline's resolution): homography correctness at eps = 1 / 3 / 5 px, matching score and
   repeatability, per split;
4. the pipeline: CNN features on APS frames, each ``--stretches`` entry PRESET:SEED:SECONDS (the first seconds of the
   preset's whole motion; default boxes_like:0:20), RMSE, % of distance and the real-time factor.

Usage: python bench/cnn_inference_modes.py [--modes fused bf16 int8] [--weights NAME|PATH ...] [--n-images 20]
                                           [--pairs-per-image 2]
                                           [--pool val] [--stretches boxes_like:0:20 boxes_like:1:20 ...]
Measured figures: docs/results/speed.md#the-cnns-inference-modes.
"""
from __future__ import annotations

import argparse
import os
import time
import warnings

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from evio_lib.features.base import SUPERPOINT_DEFAULT_WEIGHTS  # noqa: E402
from evio_lib.features.evaluation.benchmark import BenchmarkSettings, heldout_pairs, run_benchmark  # noqa: E402
from evio_lib.features.network import SuperPointDetector  # noqa: E402


def _frames(count: int) -> list[np.ndarray]:
    from evio_lib.pipeline import load_dataset

    data = load_dataset("boxes_like", duration=10, seed=0)
    step = max(1, len(data.sequence.frames) // count)
    return [data.sequence.frames[i] for i in range(0, len(data.sequence.frames), step)][:count]


def _agreement(reference, other) -> tuple[float, float, float]:  # type: ignore[no-untyped-def]
    """Return (share within 0.1 px, share within 1 px, max descriptor difference at coinciding keypoints)."""
    shares01, shares1, desc = [], [], 0.0
    for a, b in zip(reference, other):
        if len(a) == 0 or len(b) == 0:
            continue
        d = np.linalg.norm(b.keypoints[:, None] - a.keypoints[None], axis=2)
        nearest = d.argmin(axis=1)
        dist = d[np.arange(len(b)), nearest]
        shares01.append(float(np.mean(dist <= 0.1)))
        shares1.append(float(np.mean(dist <= 1.0)))
        same = dist <= 0.1
        if same.any():
            desc = max(desc, float(np.abs(b.descriptors[same] - a.descriptors[nearest[same]]).max()))
    return float(np.mean(shares01)), float(np.mean(shares1)), desc


def _label(weights: str, mode: str, several: bool) -> str:
    """Return the row name of a (weights, mode) variant: "weights/mode" when several networks are compared."""
    return f"{weights}/{mode}" if several else mode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", nargs="+", default=["fused", "bf16", "int8"], choices=["eager", "fused", "bf16", "int8"])
    parser.add_argument("--weights", nargs="+", default=[SUPERPOINT_DEFAULT_WEIGHTS],
                        help="shipped weights names or checkpoint paths; agreement is measured against the first "
                             "one's fused fp32 outputs (default: the shipped default network)")
    parser.add_argument("--n-images", type=int, default=20)
    parser.add_argument("--pairs-per-image", type=int, default=2)
    parser.add_argument("--pool", default="val", choices=["val", "test"])
    parser.add_argument("--stretches", nargs="*", default=["boxes_like:0:20"],
                        help="pipeline runs as PRESET:SEED:SECONDS (none: skip the pipeline)")
    parser.add_argument("--speed-frames", type=int, default=30)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    warnings.simplefilter("ignore")  # torch.ao deprecation notices of the int8 path
    frames = _frames(args.speed_frames)
    several = len(args.weights) > 1
    width = max(len(_label(w, m, several)) for w in args.weights for m in args.modes + ["fused"])  # rows line up
    variants = [(w, mode) for w in args.weights for mode in args.modes]
    print(f"weights {', '.join(args.weights)}; torch {torch.__version__}, 1 thread; {len(frames)} boxes_like "
          f"frames {frames[0].shape[1]}x{frames[0].shape[0]} for speed and agreement")
    outputs = {}
    reference = (args.weights[0], "fused")
    for weights, mode in [reference] + variants if reference not in variants else variants:
        det = SuperPointDetector(weights=weights, inference=mode, max_keypoints=1000)
        for image in frames[:3]:
            det.detect_and_describe(image)
        start = time.process_time()
        outputs[weights, mode] = [det.detect_and_describe(image) for image in frames]
        ms = (time.process_time() - start) / len(frames) * 1e3
        print(f"  {_label(weights, mode, several):<{width}} {ms:6.1f} ms CPU per frame ({1e3 / ms:5.1f} frames/s)",
              flush=True)
    for weights, mode in variants:
        if (weights, mode) != reference:
            a01, a1, desc = _agreement(outputs[reference], outputs[weights, mode])
            print(f"  {_label(weights, mode, several):<{width}} against {_label(*reference, several)}: {100 * a01:.1f} % of "
                  f"keypoints within 0.1 px, {100 * a1:.1f} % within 1 px; descriptors at the same keypoints differ "
                  f"by at most {desc:.4f}")
    pairs = heldout_pairs(0, n_images=args.n_images, pairs_per_image=args.pairs_per_image, size=(240, 320),
                          pool=args.pool)
    settings = BenchmarkSettings.thesis_event_frames()
    print(f"\nheld-out homography benchmark, {args.pool} pool: {len(pairs)} pairs, event-frame settings (240x320)")
    for weights, mode in variants:
        label = _label(weights, mode, several)
        result = run_benchmark("superpoint", pairs, settings, name=label,
                               detector_options={"inference": mode, "weights": weights})
        for split in result["homography"]:
            h = result["homography"][split]
            print(f"  {label:<{width}} {split:12s} correctness eps 1/3/5: "
                  f"{' / '.join(f'{h[e]:.3f}' for e in sorted(h))}; matching score "
                  f"{result['matching_score'][split][3.0]:.3f}; repeatability {result['repeatability'][split][3.0]:.3f}",
                  flush=True)
    if args.stretches:
        from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline
        from evio_lib.pipeline.dataset import PRESET_DURATIONS

        print("\npipeline: CNN on APS frames")
    for stretch in args.stretches:
        preset, seed, seconds = stretch.split(":")
        data = load_dataset(preset, duration=min(PRESET_DURATIONS[preset], max(20.0, float(seconds))), seed=int(seed))
        for weights, mode in variants:
            config = PipelineConfig(features="superpoint", detector_options=(("inference", mode), ("weights", weights)),
                                    max_duration=float(seconds))
            result = run_pipeline(data, config)
            m = result.metrics
            print(f"  {preset} seed {seed}, {float(seconds):g} s, {_label(weights, mode, several)}: RMSE "
                  f"{m['rmse_m']:.3f} m, {m['percent_of_distance']:.2f} % of distance, "
                  f"{result.timings['realtime_factor']:.2f}x real time", flush=True)


if __name__ == "__main__":
    main()
