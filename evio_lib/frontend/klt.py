"""KLT tracking baseline: pyramidal Lucas-Kanade optical flow with FAST corners (the front-end of msckf_vio, OpenVINS).

Per frame:

1. predict where each tracked feature moves under the gyroscope's rotation alone (undistort, rotate, distort:
   ``FeatureTracker._predict``);
2. refine the prediction with pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK`` with the prediction as the initial
   flow): minimise sum_window (I1(x + d) - I0(x))^2 over the displacement d, coarse to fine (Bouguet 2000);
3. optionally track back from the new position and drop features that do not return within
   ``klt_backward_check_px`` of where they started (forward-backward check, Kalal et al. 2010);
4. reject outliers with two-point RANSAC, cap the grid and add FAST detections in cells with room, as
   :class:`~evio_lib.frontend.tracker.DescriptorTracker` does.

Reference: Lucas & Kanade, IJCAI 1981; Bouguet, "Pyramidal Implementation of the Lucas Kanade Feature Tracker", 2000;
Kalal, Mikolajczyk & Matas, "Forward-Backward Error", ICPR 2010; Sun et al., RA-L 2018 (msckf_vio); Geneva et al.,
ICRA 2020 (OpenVINS).
"""
from __future__ import annotations

import time

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.features.base import nms_keypoints, to_uint8_image
from evio_lib.features.classical import FastDetector
from evio_lib.frontend.tracker import FeatureTracker, TrackedFrame

__all__ = ["KltTracker"]


class KltTracker(FeatureTracker):
    """Optical-flow tracker with the same interface and output as :class:`~evio_lib.frontend.tracker.DescriptorTracker`.

    Args: see :class:`~evio_lib.frontend.tracker.FeatureTracker` (``config.klt_*`` set the flow; the detector,
    FAST by default, only supplies new features). With the FAST detector the corners come straight from OpenCV
    (``cv2.FastFeatureDetector`` with its 3 x 3 suppression, then the detector's radius NMS and keypoint budget), as
    msckf_vio does, without the descriptors that ``detect_and_describe`` would compute and KLT does not use; any
    other detector runs through ``detect_and_describe``.

    >>> from evio_lib.geometry.camera import PinholeRadtan
    >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=31.5, cy=23.5, width=64, height=48)
    >>> from evio_lib.frontend.config import FrontendConfig
    >>> tracker = KltTracker(cam, FrontendConfig(method="klt"))
    >>> out = tracker.process(np.zeros((48, 64), np.float32), 0.0)   # a blank frame: nothing to track
    >>> len(out), out.stats.total
    (0, 0)
    """

    def reset(self) -> None:
        super().reset()
        self._image_prev: NDArray[np.uint8] | None = None

    def _detect(self, img8: NDArray[np.uint8]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Return (keypoints (K, 2) pixels, scores (K,)) of new-feature candidates, strongest first."""
        det = self.detector
        if isinstance(det, FastDetector):
            fast = cv2.FastFeatureDetector_create(det.threshold, True, cv2.FAST_FEATURE_DETECTOR_TYPE_9_16)
            corners = fast.detect(img8)
            if not corners:
                return np.zeros((0, 2)), np.zeros(0)
            points = np.array([c.pt for c in corners], dtype=np.float64)
            scores = np.array([c.response for c in corners], dtype=np.float64)
            keep = nms_keypoints(points, scores, det.nms_radius, img8.shape)[:det.max_keypoints]
            return points[keep], scores[keep]
        features = det.detect_and_describe(img8)
        return features.keypoints.astype(np.float64), features.scores.astype(np.float64)

    def _flow(self, image_prev: NDArray[np.uint8], image: NDArray[np.uint8], points: NDArray[np.float64],
              guess: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Return (new pixels (K, 2), success (K,)) of pyramidal Lucas-Kanade from image_prev to image."""
        cfg = self.config
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, cfg.klt_max_iterations, cfg.klt_epsilon)
        nxt, status, _ = cv2.calcOpticalFlowPyrLK(
            image_prev, image, points.astype(np.float32).reshape(-1, 1, 2),
            guess.astype(np.float32).reshape(-1, 1, 2).copy(), winSize=(cfg.klt_window, cfg.klt_window),
            maxLevel=cfg.klt_levels, criteria=criteria, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        nxt = nxt.reshape(-1, 2).astype(np.float64)
        ok = status.reshape(-1).astype(bool) & np.isfinite(nxt).all(axis=1)
        return nxt, ok

    def process(self, image: ArrayLike, t: float, R_prev_to_curr: ArrayLike | None = None) -> TrackedFrame:
        img, t, R = self._check_input(image, t, R_prev_to_curr)
        img8 = to_uint8_image(img)
        n_prev = self.num_tracks

        start = time.perf_counter()
        if self._image_prev is not None and n_prev:
            nxt, ok = self._flow(self._image_prev, img8, self._pixels, self._predict(R))
            ok &= self._inside(np.where(ok[:, None], nxt, 0.0))
            if self.config.klt_backward_check_px is not None and ok.any():
                back, ok_back = self._flow(img8, self._image_prev, nxt[ok], self._pixels[ok])
                error = np.linalg.norm(back - self._pixels[ok], axis=1)
                ok[np.flatnonzero(ok)] = ok_back & (error <= self.config.klt_backward_check_px)
            prev_index = np.flatnonzero(ok)
            pixels = nxt[prev_index]
            xy = self.camera.unproject(pixels) if prev_index.size else np.zeros((0, 2))
        else:
            prev_index, pixels, xy = np.zeros(0, np.intp), np.zeros((0, 2)), np.zeros((0, 2))
        t_match = time.perf_counter() - start

        start = time.perf_counter()
        inliers, degenerate = self._ransac(self._xy[prev_index], xy, R)
        t_ransac = time.perf_counter() - start
        prev_index, pixels, xy = prev_index[inliers], pixels[inliers], xy[inliers]
        keep = self._cap_tracked(pixels, self._ages[prev_index] + 1)
        prev_index, pixels, xy = prev_index[keep], pixels[keep], xy[keep]

        start = time.perf_counter()
        detected = 0
        new_pixels, new_xy = np.zeros((0, 2)), np.zeros((0, 2))
        if (self.grid.counts(pixels) < self.grid.per_cell).any():  # detect only when some cell has room
            kp, scores = self._detect(img8)
            detected = kp.shape[0]
            chosen = self._select_new(kp, scores, pixels)
            new_pixels = kp[chosen]
            new_xy = self.camera.unproject(new_pixels) if chosen.size else np.zeros((0, 2))
        t_detect = time.perf_counter() - start

        n_new = new_pixels.shape[0]
        ids = np.concatenate([self._ids[prev_index], self._new_ids(n_new)])
        ages = np.concatenate([self._ages[prev_index] + 1, np.ones(n_new, np.int64)])
        self._image_prev = img8
        n_candidates = int(inliers.shape[0])
        return self._finish(
            t, ids, np.concatenate([pixels, new_pixels]), np.concatenate([xy, new_xy]), ages,
            detected=detected, candidates=n_candidates, rejected_ransac=int(np.count_nonzero(~inliers)),
            tracked=int(prev_index.shape[0]), dropped=int(np.count_nonzero(inliers)) - int(prev_index.shape[0]),
            lost=n_prev - int(prev_index.shape[0]), new=n_new, ransac_degenerate=bool(degenerate),
            time_detect_s=t_detect, time_match_s=t_match, time_ransac_s=t_ransac,
        )
