"""Feature tracking between consecutive frames (thesis §3.3.5): detect, match, reject outliers, keep a spread grid.

Per frame, :class:`DescriptorTracker` (the thesis's front-end)

1. detects keypoints and descriptors in the raw (distorted) image with any detector of ``evio_lib.features``
   (SIFT by default, or the CNN) and undistorts the keypoints to normalised coordinates with the camera model;
2. matches the descriptors of the features tracked in the previous frame to the new detections within
   ``match_radius_px`` of where the gyroscope's rotation predicts them (mutual nearest neighbours with Lowe's ratio
   test, :mod:`evio_lib.frontend.matching`);
3. rejects outlier matches with two-point RANSAC, the gyroscope's rotation removed
   (:mod:`evio_lib.frontend.two_point_ransac`);
4. caps the tracked features per cell of a 4 x 5 grid at N / 20, older tracks first (:mod:`evio_lib.frontend.grid`);
5. starts new tracks from the strongest unmatched detections, only in cells with room and at least
   ``min_distance_px`` from every tracked feature.

Track ids are int64, start at 0 and are never reused. By default a feature that is lost and detected again becomes a
new track (the MSCKF uses a lost track's observations once and forgets it). With ``max_track_gap = g > 0`` the
descriptor tracker keeps a lost track for g frames ("dormant": its last descriptor, its last position and the
gyroscope's rotation since then) and matches it like the others: predicted by that rotation, within the same
``match_radius_px`` (a radius that grew with the gap, as the translation's flow adds up, let more wrong matches
through on noisy frames: docs/archive.md, "a match radius that grows with the track gap"), and checked by
the same two-point RANSAC with its own rotation removed (for a translation direction that changes little over a
few frames, the epipolar constraint t . (g1 x f2) = 0 holds for the longer baseline too). A revived track keeps its
id, so the MSCKF (``MsckfConfig.max_track_gap`` = g) continues one track instead of starting a second one. The
output of every frame (:class:`TrackedFrame`) holds ids and undistorted normalised coordinates, the input of
``evio_lib.msckf.filter.Msckf.process_image``, and per-frame statistics for plots.

:class:`evio_lib.frontend.klt.KltTracker` (pyramidal Lucas-Kanade optical flow with FAST detections, the front-end of
msckf_vio and OpenVINS) shares steps 3-5 and the output.

Reference: thesis §3.3.5; Sun et al., "Robust Stereo Visual Inertial Odometry for Fast Autonomous Flight", RA-L 2018
(msckf_vio's image processor); Geneva et al., "OpenVINS", ICRA 2020.
"""
from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, fields
from typing import Any, Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.features.base import FeatureDetector, Features, create_detector, to_float_image
from evio_lib.frontend.config import FrontendConfig
from evio_lib.frontend.grid import FeatureGrid
from evio_lib.frontend.matching import match_mutual_ratio
from evio_lib.frontend.two_point_ransac import _as_rotation, compensate_rotation, two_point_ransac
from evio_lib.geometry.camera import PinholeRadtan

__all__ = ["FrameStats", "TrackedFrame", "FeatureTracker", "DescriptorTracker", "stats_table"]


@dataclass(frozen=True)
class FrameStats:
    """Counts and timings of one tracked frame.

    Attributes:
        frame: index of the frame (0 for the first one processed since the last reset).
        detected: keypoints the detector returned in the whole frame (0 when the KLT tracker did not detect).
        candidates: previous tracks that found a candidate in this frame (descriptor match, or KLT success).
        rejected_ransac: candidates that two-point RANSAC rejected.
        tracked: tracks continued into this frame (after RANSAC and the grid cap).
        dropped: RANSAC inliers not continued: their cell was over its cap, or they reached the image border.
        lost: tracks of the previous frame not continued (no candidate, rejected or dropped).
        new: tracks started in this frame.
        total: features output, tracked + new.
        ransac_degenerate: RANSAC found the translation unobservable (pure rotation) and classified by displacement.
        revived: tracks continued after they were missing from 1 to ``max_track_gap`` frames (counted in tracked).
        time_detect_s, time_match_s, time_ransac_s: wall-clock seconds of detection (with undistortion of the
            keypoints), matching (descriptor matching or optical flow) and RANSAC.
    """

    frame: int
    detected: int
    candidates: int
    rejected_ransac: int
    tracked: int
    dropped: int
    lost: int
    new: int
    total: int
    ransac_degenerate: bool
    time_detect_s: float
    time_match_s: float
    time_ransac_s: float
    revived: int = 0


@dataclass(frozen=True)
class TrackedFrame:
    """The front-end's output for one frame.

    Attributes:
        t: frame time, s.
        ids: (K,) int64 unique track ids.
        xy: (K, 2) float64 undistorted normalised coordinates (X/Z, Y/Z) in the camera frame, the input of
            ``Msckf.process_image(t, ids, xy)``.
        pixels: (K, 2) float64 raw (distorted) pixel coordinates (x, y), for drawing.
        ages: (K,) int64 number of frames each track has been observed in, this one included (1 = new).
        stats: counts and timings.
    """

    t: float
    ids: NDArray[np.int64]
    xy: NDArray[np.float64]
    pixels: NDArray[np.float64]
    ages: NDArray[np.int64]
    stats: FrameStats

    def __len__(self) -> int:
        """Return the number of features K."""
        return int(self.ids.shape[0])


def stats_table(frames: Iterable[TrackedFrame]) -> dict[str, NDArray[Any]]:
    """Return the statistics of frames as columns: {"t": (F,), "tracked": (F,), "new": (F,), ...} for plots.

    >>> stats_table([])["tracked"].shape
    (0,)
    """
    frames = list(frames)
    table: dict[str, NDArray[Any]] = {"t": np.array([f.t for f in frames], dtype=np.float64)}
    for f in fields(FrameStats):
        table[f.name] = np.array([getattr(fr.stats, f.name) for fr in frames])
    return table


class FeatureTracker(ABC):
    """Shared state and steps of the trackers: input checks, RANSAC, the grid, new tracks, ids and output.

    Args:
        camera: calibration of the images (intrinsics and radial-tangential distortion); images must be
            (camera.height, camera.width).
        config: front-end parameters (:class:`~evio_lib.frontend.config.FrontendConfig`).
        detector: an already created detector to use instead of ``config.detector_name`` (e.g. a trained CNN).
    """

    def __init__(self, camera: PinholeRadtan, config: FrontendConfig | None = None,
                 detector: FeatureDetector | None = None) -> None:
        if not isinstance(camera, PinholeRadtan):
            raise ValueError(f"camera must be a PinholeRadtan calibration; got {type(camera).__name__}")
        config = FrontendConfig() if config is None else config
        if not isinstance(config, FrontendConfig):
            raise ValueError(f"config must be a FrontendConfig; got {type(config).__name__}")
        if detector is None:
            detector = create_detector(config.detector_name, max_keypoints=config.detector_max_keypoints,
                                       nms_radius=config.nms_radius, **dict(config.detector_options))
        elif not isinstance(detector, FeatureDetector):
            raise ValueError(f"detector must be a FeatureDetector (evio_lib.features.create_detector); "
                             f"got {type(detector).__name__}")
        self.camera = camera
        self.config = config
        self.detector = detector
        self.grid = FeatureGrid(camera.width, camera.height, config.grid_rows, config.grid_cols, config.per_cell)
        self._focal_px = 0.5 * (camera.fx + camera.fy)
        self.reset()

    def reset(self) -> None:
        """Forget every track (the next frame starts afresh); ids keep counting up, so they are never reused."""
        if not hasattr(self, "_next_id"):
            self._next_id = 0
        self._rng = np.random.default_rng(self.config.seed)
        self._frame_index = 0
        self._t_prev: float | None = None
        self._ids = np.zeros(0, np.int64)
        self._pixels = np.zeros((0, 2))
        self._xy = np.zeros((0, 2))
        self._ages = np.zeros(0, np.int64)

    @property
    def num_tracks(self) -> int:
        """Return the number of features tracked in the last frame."""
        return int(self._ids.shape[0])

    # ------------------------------------------------------------------------------------------------ checks
    def _check_input(self, image: ArrayLike, t: float, R_prev_to_curr: ArrayLike | None
                     ) -> tuple[NDArray[np.float32], float, NDArray[np.float64] | None]:
        img = to_float_image(image, "image")  # a new float32 array: the caller's image is never modified
        if img.shape != (self.camera.height, self.camera.width):
            raise ValueError(f"image must have shape (H, W) = ({self.camera.height}, {self.camera.width}) to match "
                             f"the camera; got {img.shape}")
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
            raise ValueError(f"t must be a finite frame time in seconds; got {t!r}")
        if self._t_prev is not None and not t > self._t_prev:
            raise ValueError(f"t must increase from frame to frame; got {t!r} after {self._t_prev!r}")
        R = None if R_prev_to_curr is None else _as_rotation(R_prev_to_curr)
        return img, float(t), R

    # ------------------------------------------------------------------------------------------------ shared steps
    def _predict(self, R: NDArray[np.float64] | None) -> NDArray[np.float64]:
        """Return the (K, 2) pixels where the tracked features move under the rotation R alone.

        Undistort to f = [x, y, 1], rotate g = R f, project g with the lens model (exact for a pure rotation;
        msckf_vio's ``predictFeatureTracking`` uses the homography K R K^-1 and ignores distortion). Features that
        the rotation turns behind the camera keep their previous pixel."""
        if R is None or self.num_tracks == 0:
            return self._pixels.copy()
        return self._project_or_keep(compensate_rotation(self._xy, R), self._pixels)  # g = R f / (R f)_z

    def _project_or_keep(self, g: NDArray[np.float64], pixels: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return the pixels of the rotated bearings g, keeping ``pixels`` where g is behind the camera (NaN) or
        projects absurdly far."""
        ahead = np.isfinite(g).all(axis=1)
        predicted = pixels.copy()
        if ahead.any():
            predicted[ahead] = self.camera.normalized_to_pixels(g[ahead])
        far = ~np.isfinite(predicted).all(axis=1) | (np.abs(predicted) > 1e6).any(axis=1)
        predicted[far] = pixels[far]
        return predicted

    def _ransac(self, xy_prev: NDArray[np.float64], xy_curr: NDArray[np.float64],
                R: NDArray[np.float64] | None) -> tuple[NDArray[np.bool_], bool]:
        """Return the inlier mask of candidate pairs and whether RANSAC found the translation unobservable."""
        if not self.config.ransac or xy_prev.shape[0] == 0:
            return np.ones(xy_prev.shape[0], bool), False
        result = two_point_ransac(xy_prev, xy_curr, R, focal_px=self._focal_px,
                                  threshold_px=self.config.ransac_threshold_px,
                                  iterations=self.config.ransac_iterations, rng=self._rng)
        return result.inliers, result.degenerate

    def _inside(self, pixels: NDArray[np.float64]) -> NDArray[np.bool_]:
        b = self.config.border_px
        return ((pixels[:, 0] >= b) & (pixels[:, 0] <= self.camera.width - 1 - b)
                & (pixels[:, 1] >= b) & (pixels[:, 1] <= self.camera.height - 1 - b))

    def _cap_tracked(self, pixels: NDArray[np.float64], ages: NDArray[np.int64]) -> NDArray[np.intp]:
        """Return the indices of continued tracks kept by the grid: per cell the oldest first (then lower index)."""
        keep = self.grid.keep_best(pixels, ages.astype(np.float64))
        return np.sort(keep)

    def _select_new(self, candidates: NDArray[np.float64], scores: NDArray[np.float64],
                    tracked_pixels: NDArray[np.float64]) -> NDArray[np.intp]:
        """Return indices of candidate pixels that start new tracks: strongest first, in cells with room, far from
        tracked features."""
        if candidates.shape[0] == 0:
            return np.zeros(0, np.intp)
        ok = self._inside(candidates)
        if tracked_pixels.shape[0] and self.config.min_distance_px > 0:
            d2 = ((candidates[:, None, :] - tracked_pixels[None, :, :]) ** 2).sum(axis=2)
            ok &= d2.min(axis=1) >= self.config.min_distance_px ** 2
        index = np.flatnonzero(ok)
        occupied = self.grid.counts(tracked_pixels)
        chosen = self.grid.keep_best(candidates[index], scores[index], occupied=occupied)
        return index[chosen]

    def _new_ids(self, n: int) -> NDArray[np.int64]:
        ids = np.arange(self._next_id, self._next_id + n, dtype=np.int64)
        self._next_id += n
        return ids

    def _finish(self, t: float, ids: NDArray[np.int64], pixels: NDArray[np.float64], xy: NDArray[np.float64],
                ages: NDArray[np.int64], **counts: Any) -> TrackedFrame:
        """Store the new state and return the frame's output (arrays are copies the caller may keep)."""
        self._ids, self._pixels, self._xy, self._ages = ids, pixels, xy, ages
        self._t_prev = t
        stats = FrameStats(frame=self._frame_index, total=int(ids.shape[0]), **counts)
        self._frame_index += 1
        return TrackedFrame(t=t, ids=ids.copy(), xy=xy.copy(), pixels=pixels.copy(), ages=ages.copy(), stats=stats)

    # ------------------------------------------------------------------------------------------------ interface
    @abstractmethod
    def process(self, image: ArrayLike, t: float, R_prev_to_curr: ArrayLike | None = None) -> TrackedFrame:
        """Return the tracked features of the next frame.

        Args:
            image: (H, W) float32 image in [0, 1] (an APS frame or a frame reconstructed from events), or uint8.
            t: frame time, s, later than the previous frame's.
            R_prev_to_curr: (3, 3) rotation of the camera from the previous frame to this one, R_C0toC1
                (X_C1 = R X_C0 + t), e.g. :func:`~evio_lib.frontend.gyro_prior.camera_rotation_prior`; None: the
                identity (RANSAC then assumes the camera barely rotated).
        """

    def track(self, images: Iterable[ArrayLike], times: ArrayLike,
              rotations: Iterable[ArrayLike | None] | None = None) -> list[TrackedFrame]:
        """Return the tracked frames of a whole sequence: ``process`` on each (image, t, rotation) in order.

        Args:
            images: F images (an (F, H, W) array or any iterable of (H, W) images).
            times: (F,) frame times, s.
            rotations: F rotations R_prev_to_curr (the first one is ignored), or None for no prior.
        """
        times = np.asarray(times, dtype=np.float64)
        images = list(images)
        if times.shape != (len(images),):
            raise ValueError(f"times must have shape (F,) = ({len(images)},), one per image; got {times.shape}")
        rotation_list = [None] * len(images) if rotations is None else list(rotations)
        if len(rotation_list) != len(images):
            raise ValueError(f"rotations must hold one rotation per image ({len(images)}); got {len(rotation_list)}")
        return [self.process(img, float(t), R) for img, t, R in zip(images, times, rotation_list)]


class DescriptorTracker(FeatureTracker):
    """The thesis's front-end: detections matched frame to frame by descriptor, two-point RANSAC, a 4 x 5 grid.

    Args: see :class:`FeatureTracker`; ``config.method`` is ignored (this class is the "descriptor" method).

    >>> from evio_lib.geometry.camera import PinholeRadtan
    >>> cam = PinholeRadtan(fx=100.0, fy=100.0, cx=31.5, cy=23.5, width=64, height=48)
    >>> tracker = DescriptorTracker(cam)
    >>> out = tracker.process(np.zeros((48, 64), np.float32), 0.0)   # a blank frame: nothing to track
    >>> len(out), out.stats.detected, out.ids.dtype
    (0, 0, dtype('int64'))
    """

    def reset(self) -> None:
        super().reset()
        self._descriptors: NDArray[Any] | None = None
        # dormant tracks (max_track_gap > 0): lost, still searched for; _dormant_R maps their last frame's camera
        # to the last processed frame's (R_C_last_seen_to_C_prev)
        self._dormant_ids = np.zeros(0, np.int64)
        self._dormant_descriptors: NDArray[Any] | None = None
        self._dormant_xy = np.zeros((0, 2))
        self._dormant_pixels = np.zeros((0, 2))
        self._dormant_ages = np.zeros(0, np.int64)
        self._dormant_missed = np.zeros(0, np.int64)
        self._dormant_R = np.zeros((0, 3, 3))

    def _dormant_rotations(self, R: NDArray[np.float64] | None) -> NDArray[np.float64]:
        """Return (D, 3, 3) rotations from each dormant track's last frame to the current one, R R_dormant."""
        return self._dormant_R if R is None else np.einsum("ij,djk->dik", R, self._dormant_R)

    @staticmethod
    def _rotate_bearings(xy: NDArray[np.float64], rotations: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return g_k = R_k f_k / (R_k f_k)_z for f_k = [x_k, y_k, 1], each point with its own rotation (NaN when
        the rotation turns it behind the camera), as :func:`compensate_rotation` does with one rotation."""
        g = np.einsum("kij,kj->ki", rotations, np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(g[:, 2:3] > 1e-9, g[:, :2] / g[:, 2:3], np.nan)

    def _predict_dormant(self, rotations: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return the (D, 2) pixels where the dormant tracks move under their own rotations (as :meth:`_predict`)."""
        return self._project_or_keep(self._rotate_bearings(self._dormant_xy, rotations), self._dormant_pixels)

    def process(self, image: ArrayLike, t: float, R_prev_to_curr: ArrayLike | None = None) -> TrackedFrame:
        img, t, R = self._check_input(image, t, R_prev_to_curr)
        start = time.perf_counter()
        features: Features = self.detector.detect_and_describe(img)
        kp = features.keypoints.astype(np.float64)
        xy_all = self.camera.unproject(kp) if len(features) else np.zeros((0, 2))
        t_detect = time.perf_counter() - start

        # the pool of tracks searched for: the previous frame's, then the dormant ones
        n_active, n_dormant = self.num_tracks, int(self._dormant_ids.shape[0])
        dormant_R = self._dormant_rotations(R)
        pool_descriptors = self._descriptors
        if n_dormant:
            pool_descriptors = (self._dormant_descriptors if self._descriptors is None or n_active == 0
                                else np.concatenate([self._descriptors, self._dormant_descriptors]))
        start = time.perf_counter()
        if pool_descriptors is not None and n_active + n_dormant and len(features):
            allowed = None
            if self.config.match_radius_px is not None:  # guided: near the rotation-predicted position
                predicted = self._predict(R)
                if n_dormant:
                    predicted = np.concatenate([predicted, self._predict_dormant(dormant_R)])
                d2 = ((predicted[:, None, :] - kp[None, :, :]) ** 2).sum(axis=2)
                allowed = d2 <= self.config.match_radius_px ** 2
            pairs = match_mutual_ratio(pool_descriptors, features.descriptors, binary=features.binary,
                                       ratio=self.config.ratio, max_distance=self.config.max_descriptor_distance,
                                       allowed=allowed)
        else:
            pairs = np.zeros((0, 2), np.int64)
        t_match = time.perf_counter() - start

        start = time.perf_counter()
        revived_pairs = pairs[:, 0] >= n_active
        if revived_pairs.any():  # each previous bearing rotated into this frame by its own rotation, then R = I
            g_prev = np.empty((pairs.shape[0], 2))
            active = ~revived_pairs
            g_prev[active] = compensate_rotation(self._xy[pairs[active, 0]], R)
            k = pairs[revived_pairs, 0] - n_active
            g_prev[revived_pairs] = self._rotate_bearings(self._dormant_xy[k], dormant_R[k])
            ahead = np.isfinite(g_prev).all(axis=1)  # a bearing turned behind the camera is no match (as in RANSAC)
            inliers = np.zeros(pairs.shape[0], bool)
            inliers[ahead], degenerate = self._ransac(g_prev[ahead], xy_all[pairs[ahead, 1]], None)
        else:
            inliers, degenerate = self._ransac(self._xy[pairs[:, 0]], xy_all[pairs[:, 1]], R)
        t_ransac = time.perf_counter() - start
        pool_ids = np.concatenate([self._ids, self._dormant_ids])
        pool_ages = np.concatenate([self._ages, self._dormant_ages])
        good = pairs[inliers]
        good = good[self._inside(kp[good[:, 1]])]
        keep = self._cap_tracked(kp[good[:, 1]], pool_ages[good[:, 0]] + 1)
        good = good[keep]

        prev_index, det_index = good[:, 0], good[:, 1]
        if self.config.max_track_gap:
            self._update_dormant(prev_index, n_active, R, dormant_R)
        unused = np.ones(len(features), bool)
        unused[det_index] = False
        candidates = np.flatnonzero(unused)
        new = candidates[self._select_new(kp[candidates], features.scores[candidates].astype(np.float64),
                                          kp[det_index])]
        det = np.concatenate([det_index, new])
        ids = np.concatenate([pool_ids[prev_index], self._new_ids(new.shape[0])])
        ages = np.concatenate([pool_ages[prev_index] + 1, np.ones(new.shape[0], np.int64)])
        self._descriptors = features.descriptors[det]
        continued = int(np.count_nonzero(prev_index < n_active))
        return self._finish(
            t, ids, kp[det], xy_all[det], ages,
            detected=len(features), candidates=int(pairs.shape[0]), rejected_ransac=int(np.count_nonzero(~inliers)),
            tracked=int(prev_index.shape[0]), dropped=int(np.count_nonzero(inliers)) - int(prev_index.shape[0]),
            lost=n_active - continued, new=int(new.shape[0]), ransac_degenerate=bool(degenerate),
            time_detect_s=t_detect, time_match_s=t_match, time_ransac_s=t_ransac,
            revived=int(prev_index.shape[0]) - continued,
        )

    def _update_dormant(self, prev_index: NDArray[np.int64], n_active: int, R: NDArray[np.float64] | None,
                        dormant_R: NDArray[np.float64]) -> None:
        """Make the previous frame's tracks that were not continued dormant, age the dormant ones that were not
        revived, and forget those missing for more than ``max_track_gap`` frames."""
        continued = np.zeros(n_active + self._dormant_ids.shape[0], bool)
        continued[prev_index] = True
        lost = np.flatnonzero(~continued[:n_active])
        still = np.flatnonzero(~continued[n_active:] & (self._dormant_missed + 1 <= self.config.max_track_gap))
        step = np.eye(3) if R is None else R
        descriptors = [] if self._descriptors is None else [self._descriptors[lost]]
        if self._dormant_descriptors is not None:
            descriptors.append(self._dormant_descriptors[still])
        self._dormant_ids = np.concatenate([self._ids[lost], self._dormant_ids[still]])
        self._dormant_descriptors = np.concatenate(descriptors) if descriptors else None
        self._dormant_xy = np.concatenate([self._xy[lost], self._dormant_xy[still]])
        self._dormant_pixels = np.concatenate([self._pixels[lost], self._dormant_pixels[still]])
        self._dormant_ages = np.concatenate([self._ages[lost], self._dormant_ages[still]])
        self._dormant_missed = np.concatenate([np.ones(lost.shape[0], np.int64), self._dormant_missed[still] + 1])
        self._dormant_R = np.concatenate([np.broadcast_to(step, (lost.shape[0], 3, 3)), dormant_R[still]])
