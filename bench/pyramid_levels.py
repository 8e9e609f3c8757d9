"""Which image pyramid should the network run on? Viewpoint homography correctness of pyramid settings.

Run from the repository root::

    python bench/pyramid_levels.py                                  # validation photographs, the settings below
    python bench/pyramid_levels.py --split val --n-images 12 --weights runs/features/x/best.pt

For the viewpoint pairs of the photo benchmark's ``--split`` photographs (``features-benchmark --dataset photos``:
3 pairs per photograph, seed 0, 480 x 640; the ``val`` split chooses settings without looking at the test
photographs) it runs SIFT and the network with each pyramid of :data:`SETTINGS` (``SuperPointDetector(scales=...)``)
at the homography task's settings (best 1000 points, NMS 8, mutual nearest neighbours, ``cv2.findHomography`` with
RANSAC) and prints, per setting, the homography correctness at eps = 1 / 3 / 5 px (thesis Eq. 17), the mean number
of mutual matches and the detection time per image. Only the homography task runs (no repeatability, no
illumination pairs), so it is several times faster than the benchmark itself.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from evio_lib.features.base import create_detector
from evio_lib.features.evaluation.benchmark import photo_pairs
from evio_lib.features.evaluation.evaluate import corner_error, estimate_homography, match_descriptors
from evio_lib.features.network.pyramid import pyramid_scales
from evio_lib.sim.photos import resolve_photo_option

#: row name -> scales option of the network (None: SIFT)
SETTINGS = {
    "SIFT": None,
    "network, one level": (1.0,),
    "network, levels 1 to 0.5": pyramid_scales((480, 640), levels_above=0),
    "network, levels 1.19 to 0.5": pyramid_scales((480, 640), levels_above=1),
    "network, levels 1.41 to 0.5": pyramid_scales((480, 640), levels_above=2),
    "network, levels 2 to 0.5": pyramid_scales((480, 640), levels_above=4),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--split", choices=("val", "test"), default="val")
    parser.add_argument("--n-images", type=int, default=None, help="first N photographs (default all)")
    parser.add_argument("--weights", default=None, help="network checkpoint (default: the shipped default)")
    parser.add_argument("--photos", default="auto")
    parser.add_argument("--only", nargs="*", default=None, help="row names to run (default all)")
    args = parser.parse_args()
    folder = resolve_photo_option(args.photos)
    if folder is None:
        raise SystemExit("error: no photo folder (give --photos DIR)")
    pairs = [p for p in photo_pairs(folder, args.split, 0, n_images=args.n_images, pairs_per_image=3)
             if p.split == "viewpoint"]
    print(f"{len(pairs)} viewpoint pairs of the {args.split} photographs; weights: {args.weights or 'shipped default'}; "
          f"scales='auto' at 480 x 640: {tuple(round(s, 2) for s in pyramid_scales((480, 640)))}")
    print("| setting | eps = 1 | eps = 3 | eps = 5 | mutual matches | ms per image |")
    print("|---|---|---|---|---|---|")
    for row, scales in SETTINGS.items():
        if args.only and row not in args.only:
            continue
        if scales is None:
            detector = create_detector("sift", max_keypoints=1000, nms_radius=8)
        else:
            options = {"scales": scales} | ({"weights": args.weights} if args.weights else {})
            detector = create_detector("superpoint", max_keypoints=1000, nms_radius=8, **options)
        errors, matches, seconds = [], [], 0.0
        for pair in pairs:
            start = time.perf_counter()
            f1, f2 = detector.detect_and_describe(pair.image1), detector.detect_and_describe(pair.image2)
            seconds += time.perf_counter() - start
            m = match_descriptors(f1.descriptors, f2.descriptors, binary=f1.binary)
            H, _ = estimate_homography(f1.keypoints, f2.keypoints, m)
            errors.append(corner_error(H, pair.H, pair.image1.shape))
            matches.append(len(m))
        e = np.array(errors)
        print(f"| {row} | {np.mean(e <= 1):.3f} | {np.mean(e <= 3):.3f} | {np.mean(e <= 5):.3f} | "
              f"{np.mean(matches):.0f} | {1000 * seconds / (2 * len(pairs)):.0f} |", flush=True)


if __name__ == "__main__":
    main()
