"""How far do a detector's descriptors survive zoom and rotation? Precision of mutual nearest-neighbour matches.

Run from the repository root::

    python bench/descriptor_invariance.py                                  # shipped CNN and SIFT, 120x160
    python bench/descriptor_invariance.py --size 480x640 --keypoints 1000 --nms 8
    python bench/descriptor_invariance.py --weights runs/features/pretrained_detdesc_round2/best.pt --detectors orb

For ``--images`` validation-pool images (never trained on; ``datasets.image_pool("val")``), each warp is a pure
similarity about the image centre, ``H = [[z R, c - z R c], [0, 1]]`` with zoom z and rotation R, plus Gaussian
sensor noise (std 0.01) on the warped image. Both images are detected and described; descriptors are matched by
mutual nearest neighbours (L2 for float descriptors, Hamming for binary ones)
and a match is correct when ``||H x1 - x2|| <= 3`` px. The printed number is the share of correct matches,
averaged over the images. A scale- and rotation-invariant detector (SIFT) keeps most of its matches; a network
that never saw a zoom in training loses them (the issue-4 notes have the figures that motivated ``fill_view``).
"""
from __future__ import annotations

import numpy as np
from _val_probe import probe_parser, probe_setup, similarity

from evio_lib.features.evaluation.evaluate import match_descriptors
from evio_lib.geometry.homography import warp_image, warp_points

WARPS = ((1.0, 0.0), (1.25, 0.0), (1.5, 0.0), (1.0, 15.0), (1.0, 30.0), (1.0, 45.0), (1.5, 30.0))  # (zoom, degrees)


def match_precision(detector, image: np.ndarray, H: np.ndarray, rng: np.random.Generator) -> float:  # type: ignore[no-untyped-def]
    """Return the share of mutual nearest-neighbour matches within 3 px of H (0 without matches)."""
    warped = warp_image(image, H)
    warped = np.clip(warped + rng.normal(0.0, 0.01, warped.shape), 0.0, 1.0).astype(np.float32)
    f1, f2 = detector.detect_and_describe(image), detector.detect_and_describe(warped)
    if len(f1.keypoints) == 0 or len(f2.keypoints) == 0:
        return 0.0
    binary = f1.descriptors.dtype == np.uint8  # packed bits (ORB, FREAK)
    matches = match_descriptors(f1.descriptors, f2.descriptors, binary=binary, mutual=True)
    if len(matches) == 0:
        return 0.0
    error = np.linalg.norm(warp_points(H, f1.keypoints[matches[:, 0]]) - f2.keypoints[matches[:, 1]], axis=1)
    return float(np.mean(error <= 3.0))


def main() -> None:
    parser = probe_parser(__doc__.split("\n")[0], detectors=["sift"], size="120x160", images=8, keypoints=150, nms=4)
    args = parser.parse_args()
    shape, images, detectors = probe_setup(args)
    names = list(detectors)
    print(f"{len(images)} val images at {shape[0]}x{shape[1]}, best {args.keypoints} points, NMS {args.nms}: "
          "precision of mutual nearest-neighbour matches at 3 px")
    print(f"{'zoom':>5s} {'rot':>5s} " + " ".join(f"{n[-28:]:>28s}" for n in names))
    for zoom, degrees in WARPS:  # loop over warps
        H = similarity(shape, zoom, degrees)
        row = []
        for name in names:  # loop over detectors; the same noise for each
            rng = np.random.default_rng(args.seed)
            row.append(np.mean([match_precision(detectors[name], img, H, rng) for img in images]))
        print(f"{zoom:5.2f} {degrees:5.0f} " + " ".join(f"{v:28.3f}" for v in row), flush=True)


if __name__ == "__main__":
    main()
