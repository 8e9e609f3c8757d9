"""How often a detector finds a point again in the next frame: the bound on a descriptor tracker's track survival.

Every keypoint of frame a is carried into frame b by pyramidal Lucas-Kanade flow (15 px window, 3 levels; accurate to
a fraction of a pixel between frames tens of milliseconds apart), and is *re-detected* when the detector's keypoints
in b include one within ``radius_px`` of it. For the re-detected ones, the guided match (the nearest descriptor among
b's keypoints within ``window_px`` of the transferred point, as the descriptor tracker matches without a ratio test)
is *correct* when it is that same keypoint. A descriptor tracker cannot continue a feature the detector did not find
again, so the re-detection rate bounds the fraction of tracks that survive a frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from evio_lib.features.base import FeatureDetector, to_uint8_image
from evio_lib.features.evaluation.evaluate import descriptor_distances

__all__ = ["Redetection", "redetection"]


@dataclass(frozen=True)
class Redetection:
    """Result of :func:`redetection` on one frame pair.

    Attributes:
        keypoints_a, keypoints_b: keypoints detected in each frame.
        transferred: keypoints of a that the flow followed into b.
        redetected: of those, the ones with a keypoint of b within radius_px.
        matched_correctly: of those, the ones whose guided nearest descriptor is that keypoint.
    """

    keypoints_a: int
    keypoints_b: int
    transferred: int
    redetected: int
    matched_correctly: int

    @property
    def rate(self) -> float:
        """Return redetected / transferred (NaN when nothing was transferred)."""
        return self.redetected / self.transferred if self.transferred else float("nan")

    @property
    def match_rate(self) -> float:
        """Return matched_correctly / redetected (NaN when nothing was re-detected)."""
        return self.matched_correctly / self.redetected if self.redetected else float("nan")


def redetection(detector: FeatureDetector, image_a: np.ndarray, image_b: np.ndarray, radius_px: float = 2.0,
                window_px: float = 15.0) -> Redetection:
    """Return how many of ``detector``'s keypoints in ``image_a`` it finds again in ``image_b`` (module docstring).

    Args:
        detector: any detector of ``evio_lib.features`` (with descriptors).
        image_a, image_b: (H, W) consecutive frames, float32 in [0, 1] or uint8.
        radius_px: a keypoint of b this close to the transferred point counts as the same point.
        window_px: the guided matching window around the transferred point.
    """
    if radius_px <= 0 or window_px <= 0:
        raise ValueError(f"radius_px and window_px must be > 0; got {radius_px!r} and {window_px!r}")
    a, b = to_uint8_image(image_a, "image_a"), to_uint8_image(image_b, "image_b")
    if a.shape != b.shape:
        raise ValueError(f"image_a and image_b must have the same shape; got {a.shape} and {b.shape}")
    fa = detector.detect_and_describe(a.astype(np.float32) / 255.0)
    fb = detector.detect_and_describe(b.astype(np.float32) / 255.0)
    if len(fa) == 0 or len(fb) == 0:
        return Redetection(len(fa), len(fb), 0, 0, 0)
    moved, status, _ = cv2.calcOpticalFlowPyrLK(a, b, fa.keypoints.astype(np.float32).reshape(-1, 1, 2), None,
                                                winSize=(15, 15), maxLevel=3)
    moved, ok = moved.reshape(-1, 2).astype(np.float64), status.ravel() == 1
    dist = np.linalg.norm(moved[:, None, :] - fb.keypoints[None, :, :].astype(np.float64), axis=2)
    near = ok & (dist.min(axis=1) < radius_px)
    desc = descriptor_distances(fa.descriptors, fb.descriptors, fa.binary)
    nearest = np.argmin(np.where(dist < window_px, desc, np.inf), axis=1)
    right = near & (dist[np.arange(len(nearest)), nearest] < radius_px)
    return Redetection(len(fa), len(fb), int(ok.sum()), int(near.sum()), int(right.sum()))
