"""Does a detector's output move with the image? Repeatability and localisation error under shifts and small warps.

Run from the repository root::

    python bench/detector_localisation.py                               # shipped CNN, Harris and SIFT, 480x640
    python bench/detector_localisation.py --weights runs/features/magicpoint/best.pt --detectors fast

A fully convolutional detector with 8x8 cells must be *covariant*: shift the image by 1 px and every keypoint
shifts by 1 px. A badly trained cell head instead keeps favourite positions inside its cells, so keypoints stay put
(error 1 px for a 1 px shift) or jump to another position of the cell (half-cell shifts). This probe finds that
before the benchmark does: for ``--images`` validation-pool images (never trained on; ``datasets.image_pool("val")``)
it warps each image by pure shifts of 0.5, 1, 2.5, (4, 4) and 8 px, a 1.1x / 1.5x zoom about the centre and a 5
degree rotation (no noise), detects in both images (best ``--keypoints`` points, NMS ``--nms``) and prints the
symmetric repeatability (``evaluate.repeatability``, thesis Eqs. 15-16) at eps = 1 and 3 px and the mean error (px) of
the points found again within 3 px (``evaluate.localisation_error``), averaged over the images. Harris, whose corners
are covariant by construction, keeps ~0.9 at 1 px and an error near 0 under integer shifts. A network with 8x8 cells
that is not covariant inside its cells is still exact under the 8 px shift (a whole cell), not under the others.
"""
from __future__ import annotations

import numpy as np
from _val_probe import probe_parser, probe_setup, similarity

from evio_lib.features.evaluation.evaluate import localisation_error, repeatability
from evio_lib.geometry.homography import warp_image


def warps(shape: tuple[int, int]) -> list[tuple[str, np.ndarray]]:
    """Return the probe's (name, 3x3 homography) pairs for images of ``shape``: shifts, zooms, a rotation."""

    def shift(dx: float, dy: float) -> np.ndarray:
        H = np.eye(3)
        H[:2, 2] = dx, dy
        return H

    return [("shift 0.5 px", shift(0.5, 0)), ("shift 1 px", shift(1, 0)), ("shift 2.5 px", shift(2.5, 0)),
            ("shift (4, 4) px", shift(4, 4)), ("shift 8 px", shift(8, 0)),
            ("zoom 1.1", similarity(shape, 1.1, 0)), ("zoom 1.5", similarity(shape, 1.5, 0)),
            ("rotate 5 deg", similarity(shape, 1, 5))]


def main() -> None:
    parser = probe_parser(__doc__.split("\n")[0], detectors=["harris", "sift"], size="480x640", images=4,
                          keypoints=1000, nms=8)
    args = parser.parse_args()
    shape, images, detectors = probe_setup(args)
    print(f"{len(images)} val images at {shape[0]}x{shape[1]}, best {args.keypoints} points, NMS {args.nms}: "
          "repeatability at 1 / 3 px / mean error (px) of the points found again within 3 px")
    print(f"{'warp':>16s} " + " ".join(f"{n[-24:]:>24s}" for n in detectors))
    first = {name: [det.detect_and_describe(img) for img in images] for name, det in detectors.items()}
    for label, H in warps(shape):  # loop over warps
        row = []
        for name, det in detectors.items():  # loop over detectors
            values = []
            for img, f1 in zip(images, first[name]):
                f2 = det.detect_and_describe(warp_image(img, H))
                r1, r3 = repeatability(f1.keypoints, f2.keypoints, H, shape, shape, eps=(1.0, 3.0))
                values.append((r1, r3, localisation_error(f1.keypoints, f2.keypoints, H, shape, shape, eps=3.0)))
            r1, r3, error = np.nanmean(values, axis=0)
            row.append(f"{r1:.3f} / {r3:.3f} / {error:.2f}")
        print(f"{label:>16s} " + " ".join(f"{v:>24s}" for v in row), flush=True)


if __name__ == "__main__":
    main()
