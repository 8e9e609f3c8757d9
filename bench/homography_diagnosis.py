"""Why is a homography wrong? Matches, their localisation error, and the oracle fit, per detector and split.

Run from the repository root::

    python bench/homography_diagnosis.py                         # every shipped CNN, SIFT and Harris, val pairs
    python bench/homography_diagnosis.py --pool test --images 58 --pairs 5 --detectors sift

The homography benchmark (thesis Eq. 17) needs two things: enough correct matches, and keypoints placed precisely
enough that a homography fitted to them lands within eps of the true corners. The corners of image 1 usually lie
outside the region that the matches cover, so the fit is extrapolated and a keypoint error of 1 px can become
several px at the corners. For each detector this prints, over the benchmark's pairs (thesis homography settings:
480x640, best 1000 points, NMS 8, mutual nearest neighbours, RANSAC; ``benchmark.diagnose_pairs``, which runs
``evaluate.diagnose_matches`` on every pair):

* ``matches`` / ``correct``: mutual matches and those within eps (px) of the truth;
* ``loc. err``: mean error of the correct matches (px), averaged over the pairs -- the keypoints' localisation
  under the warp;
* ``RANSAC``: the benchmark's correctness at eps;
* ``oracle``: the correctness of a least-squares homography fitted to the correct matches only (perfect outlier
  rejection). When the oracle fails too, only more or better-localised correct matches can help.

Pairs come from ``benchmark.heldout_pairs`` (``--pool val``: validation images, never trained on and not the test
split, so that a decision made from this script does not tune on the test set).
"""
from __future__ import annotations

import argparse

import numpy as np

from evio_lib.features import create_detector
from evio_lib.features.evaluation.options import scales_argument
from evio_lib.features.evaluation.benchmark import BenchmarkSettings, diagnose_pairs, heldout_pairs
from evio_lib.features.network import shipped_weights


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--weights", nargs="*", default=shipped_weights(),
                        help="SuperPoint weights: shipped names or .pt paths (default: every shipped file)")
    parser.add_argument("--detectors", nargs="*", default=["sift", "harris"], help="other detectors by name")
    parser.add_argument("--pool", default="val", choices=["val", "test"], help="images of this split")
    parser.add_argument("--images", type=int, default=16)
    parser.add_argument("--pairs", type=int, default=2, help="pairs per image and split")
    parser.add_argument("--splits", nargs="*", default=["viewpoint", "illumination"])
    parser.add_argument("--eps", type=float, default=3.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cnn-scales", type=scales_argument, default="auto",
                        help="the networks' pyramid: auto (their default) or comma-separated scales, e.g. 1 (one level)")
    args = parser.parse_args()

    settings = BenchmarkSettings()  # the thesis's homography task: size, point budget, NMS radius
    height, width = settings.homography_size
    options = dict(max_keypoints=settings.homography_keypoints, nms_radius=settings.homography_nms)
    detectors = {w: create_detector("superpoint", weights=w, scales=args.cnn_scales, **options) for w in args.weights}
    detectors |= {n: create_detector(n, **options) for n in args.detectors}
    pairs = heldout_pairs(args.seed, n_images=args.images, pairs_per_image=args.pairs, pool=args.pool,
                          splits=args.splits, size=(height, width))
    print(f"{len(pairs)} {args.pool} pairs at {height}x{width}, best {settings.homography_keypoints} points, "
          f"NMS {settings.homography_nms}, eps = {args.eps:g} px")
    print(f"{'split':>12s} {'detector':>30s} {'matches':>8s} {'correct':>8s} {'loc. err':>9s} {'RANSAC':>7s} "
          f"{'oracle':>7s}")
    for split in args.splits:  # loop over splits and detectors; the pairs' work is in diagnose_pairs
        chosen = [p for p in pairs if p.split == split]
        for name, detector in detectors.items():
            d = diagnose_pairs(detector, chosen, settings, eps=args.eps)  # columns: the MatchDiagnosis fields
            loc = np.nanmean(d[:, 2]) if np.isfinite(d[:, 2]).any() else np.nan
            print(f"{split:>12s} {name[-30:]:>30s} {d[:, 0].mean():8.1f} {d[:, 1].mean():8.1f} {loc:9.2f} "
                  f"{(d[:, 3] <= args.eps).mean():7.3f} {(d[:, 4] <= args.eps).mean():7.3f}", flush=True)


if __name__ == "__main__":
    main()
