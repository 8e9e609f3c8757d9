"""Why SIFT's tracks are short: how often a detector finds the same point again in the next frame.

For pairs of consecutive simulated APS frames of boxes_like (or event frames), every keypoint of the first frame is
carried into the second by pyramidal Lucas-Kanade flow (a forward-backward-free, 15 px window: accurate to a fraction
of a pixel between frames 40 ms apart), and counted as *re-detected* when the detector's keypoints in the second frame
include one within 2 px of it. For those re-detected, the nearest descriptor among the second frame's keypoints within
15 px is checked to be that same keypoint (the guided matching of the front-end, without ratio test). A descriptor
tracker cannot continue a feature that is not re-detected, so the re-detection rate bounds its tracks' survival.

Usage: python bench/frontend_repeatability.py [--detectors sift superpoint orb] [--frames aps|events]
Measured figures: docs/pipeline.md.
"""
import argparse
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from evio_lib.features.base import create_detector, to_uint8_image  # noqa: E402
from evio_lib.features.evaluate import descriptor_distances  # noqa: E402
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
        counts, redetected, correct = [], [], []
        for k in picks:
            a, b = images[k], images[k + 1]
            fa = detector.detect_and_describe(a.astype(np.float32) / 255.0)
            fb = detector.detect_and_describe(b.astype(np.float32) / 255.0)
            if len(fa) == 0 or len(fb) == 0:
                continue
            moved, status, _ = cv2.calcOpticalFlowPyrLK(a, b, fa.keypoints.astype(np.float32).reshape(-1, 1, 2), None,
                                                        winSize=(15, 15), maxLevel=3)
            moved, ok = moved.reshape(-1, 2), status.ravel() == 1
            dist = np.linalg.norm(moved[:, None, :] - fb.keypoints[None, :, :], axis=2)
            near = dist.min(axis=1) < 2.0
            desc = descriptor_distances(fa.descriptors, fb.descriptors, fa.binary)
            nearest = np.argmin(np.where(dist < 15.0, desc, np.inf), axis=1)
            right = dist[np.arange(len(nearest)), nearest] < 2.0
            counts.append(len(fb))
            redetected.append(np.mean(near[ok]))
            correct.append(np.mean(right[ok & near]) if np.any(ok & near) else np.nan)
        print(f"{name:<12} {np.mean(counts):>9.0f} {np.mean(redetected):>19.2f} {np.nanmean(correct):>18.2f}",
              flush=True)


if __name__ == "__main__":
    main()
