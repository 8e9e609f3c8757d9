"""Benchmark: the pipeline's real-time factor per configuration and where the time goes.

For each configuration the whole chain runs on the same stretch of a simulated preset (the simulation is done, or
read from the cache, first and not timed): frames (APS, FireNet reconstructions of event windows, or
motion-compensated event frames), the front-end
(detection with undistortion of the keypoints, matching or optical flow, two-point RANSAC) and the MSCKF (with the
per-observation covariances). Printed per configuration: milliseconds per frame in each stage, the frame rate, and
the real-time factor = seconds of recording processed per wall-clock second (> 1: faster than real time). One
thread for torch, OpenCV and BLAS (``--threads``), as a 2-core laptop running one job per core would.

Usage: python bench/bench_pipeline.py [--preset boxes_like] [--duration 10] [--process 5] [--configs ...]
Measured figures: docs/results/speed.md#the-pipeline.
"""
import argparse
import os
import sys

THREADS = "1"
if "--threads" in sys.argv:
    THREADS = sys.argv[sys.argv.index("--threads") + 1]
for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(name, THREADS)

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline  # noqa: E402

CONFIGS = {
    "imu_only": PipelineConfig(imu_only=True),
    "sift_aps": PipelineConfig(features="sift"),
    "klt_aps": PipelineConfig(tracker="klt", features="fast"),
    "cnn_aps": PipelineConfig(features="superpoint"),
    "cnn_narrow_aps": PipelineConfig(features="superpoint", detector_options=(("weights", "distilled_narrow"),)),
    # FireNet's frames in the default precision ("auto": int8 on x86 CPUs), then in float32
    "sift_events": PipelineConfig(frames="events", features="sift"),
    "klt_events": PipelineConfig(frames="events", tracker="klt", features="fast"),
    "cnn_events": PipelineConfig(frames="events", features="superpoint"),
    "sift_events_float32": PipelineConfig(frames="events", features="sift", reconstructor_precision="float32"),
    "klt_events_float32": PipelineConfig(frames="events", tracker="klt", features="fast",
                                         reconstructor_precision="float32"),
    "cnn_events_float32": PipelineConfig(frames="events", features="superpoint", reconstructor_precision="float32"),
    "sift_mc": PipelineConfig(frames="mc-events", features="sift"),
    "cnn_mc": PipelineConfig(frames="mc-events", features="superpoint"),
    "klt_mc": PipelineConfig(frames="mc-events", tracker="klt", features="fast"),
    "klt_aps_mc": PipelineConfig(frames="aps+mc-events", tracker="klt", features="fast"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="boxes_like", choices=["boxes_like", "aerial_like"])
    parser.add_argument("--duration", type=float, default=10.0, help="seconds simulated (cached) (default 10)")
    parser.add_argument("--process", type=float, default=5.0, help="seconds processed from the start (default 5)")
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)
    need_events = any(CONFIGS[c].frames != "aps" for c in args.configs)
    data = load_dataset(args.preset, duration=args.duration, seed=args.seed, need_events=need_events)
    print(f"{args.preset}, seed {args.seed}: {args.process:g} s processed of {args.duration:g} s simulated, "
          f"{args.threads} thread(s)")
    header = (f"{'config':<17} {'frames':>6} {'recon':>7} {'detect':>7} {'match':>7} {'ransac':>7} {'filter':>7} "
              f"{'total ms/frame':>15} {'fps':>6} {'x real time':>11} | {'RMSE [m]':>8}")
    print(header)
    print("-" * len(header))
    for name in args.configs:
        config = PipelineConfig(**{**CONFIGS[name].__dict__, "max_duration": args.process})
        result = run_pipeline(data, config)
        tm, k = result.timings, len(result.t)
        per = {s: 1e3 * tm[s] / k for s in ("reconstruction", "detection", "matching", "ransac", "filter", "total")}
        print(f"{name:<17} {k:>6} {per['reconstruction']:>7.1f} {per['detection']:>7.1f} {per['matching']:>7.1f} "
              f"{per['ransac']:>7.1f} {per['filter']:>7.1f} {per['total']:>15.1f} {1e3 / per['total']:>6.1f} "
              f"{tm['realtime_factor']:>11.2f} | {result.metrics.get('rmse_m', np.nan):>8.3f}", flush=True)


if __name__ == "__main__":
    main()
