"""Why SIFT's tracks are short: how often a detector finds the same point again in the next frame.

Pairs of consecutive simulated APS frames of boxes_like (or FireNet event frames) through
:func:`evio_lib.frontend.redetection.redetection`: each keypoint is carried into the next frame by Lucas-Kanade flow
and counts as re-detected when the detector fires again within 2 px; then whether the guided nearest descriptor is
that point. Averages over the pairs are printed.

Usage: python bench/frontend_repeatability.py [--detectors sift superpoint orb] [--frames aps|events]
Measured figures: docs/explanations/short-tracks.md.
"""
import argparse
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from evio_lib.features.base import create_detector, to_uint8_image  # noqa: E402
from evio_lib.frontend.redetection import redetection  # noqa: E402
from evio_lib.pipeline import load_dataset  # noqa: E402
from evio_lib.pipeline.frames import event_frames  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--detectors", nargs="+", default=["sift", "superpoint", "orb", "fast_freak"])
    parser.add_argument("--frames", choices=["aps", "events"], default="aps")
    parser.add_argument("--duration", type=float, default=10.0, help="seconds of boxes_like simulated (cached)")
    parser.add_argument("--start", type=int, default=100, help="first frame index of the pairs (default 100)")
    parser.add_argument("--pairs", type=int, default=20)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    data = load_dataset("boxes_like", duration=args.duration, need_events=args.frames == "events")
    if args.frames == "aps":
        images = [to_uint8_image(f) for f in data.sequence.frames]
    else:
        images = [to_uint8_image(img) for _, img, _ in event_frames(data.sequence, "firenet")]
    picks = range(args.start, min(args.start + 3 * args.pairs, len(images) - 1), 3)
    print(f"boxes_like {args.frames} frames, {len(picks)} consecutive pairs from frame {args.start}")
    print(f"{'detector':<12} {'keypoints':>9} {'re-detected (2 px)':>19} {'guided NN correct':>18}")
    for name in args.detectors:
        detector = create_detector(name, max_keypoints=1000, nms_radius=4)
        results = [redetection(detector, images[k], images[k + 1]) for k in picks]
        print(f"{name:<12} {np.mean([r.keypoints_b for r in results]):>9.0f} "
              f"{np.nanmean([r.rate for r in results]):>19.2f} {np.nanmean([r.match_rate for r in results]):>18.2f}",
              flush=True)

if __name__ == "__main__":
    main()
