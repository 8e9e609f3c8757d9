"""The feature tracks of the MSCKF's sliding window: which feature was seen by which camera state, and when a track
is handed to an update (thesis §3.3.6.1; OpenVINS calls this the feature database).

A track is a list of observations (camera id, xy (2,), W (2, 2)) of one feature id: xy are undistorted normalised
image coordinates (X/Z, Y/Z) and W = L^-1 is the whitening matrix of the observation's noise covariance Σ = L L^T
(:func:`whitening_matrices`; without a covariance the isotropic I / σ with σ = ``config.feature_noise_sigma``).

A track is used once, in one of two ways (:class:`FeatureUse`):

* **lost** (:meth:`FeatureDatabase.collect_lost`): it was not observed for more than ``config.track_gap_of(stream)``
  images of its stream; with >= ``min_track_length`` observations all of them give residuals, shorter tracks are
  dropped.
* **pruned** (:meth:`FeatureDatabase.collect_pruned`): camera states are about to leave the window; a track seen at
  >= 2 of them gives residuals from those observations (the gate still sees the whole track), and the observations
  at the leaving states are deleted from every track.

Several frame streams (e.g. APS frames and event frames of one camera; ``Msckf.process_image(..., stream=k)``): each
track belongs to the stream that started it, and an image of one stream ends only that stream's tracks.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.msckf.config import MsckfConfig

__all__ = ["FeatureDatabase", "FeatureUse", "isotropic_whitening", "whitening_matrices"]

#: One observation in a track: (camera id, xy (2,), W (2, 2)).
Observation = tuple[int, NDArray[np.float64], NDArray[np.float64]]


def whitening_matrices(xy_cov: ArrayLike) -> NDArray[np.float64]:
    """Return (K, 2, 2) whitening matrices W = L^-1 of observation covariances Σ = L L^T (L lower Cholesky).

    Args:
        xy_cov: (K, 2, 2) symmetric positive-definite covariances of undistorted normalised coordinates.

    W Σ W^T = I, so W r has unit covariance. Closed form for 2 x 2: L = [[a, 0], [b, c]] with a = sqrt(Σ00),
    b = Σ10 / a, c = sqrt(Σ11 - b²), and L^-1 = [[1/a, 0], [-b/(a c), 1/c]].

    >>> whitening_matrices(np.array([[[4.0, 2.0], [2.0, 5.0]]])).round(3).tolist()
    [[[0.5, 0.0], [-0.25, 0.5]]]
    """
    cov = np.asarray(xy_cov, dtype=np.float64)
    if cov.ndim != 3 or cov.shape[1:] != (2, 2):
        raise ValueError(f"xy_cov must have shape (K, 2, 2), one covariance per observation; got {cov.shape}")
    if not np.all(np.isfinite(cov)):
        raise ValueError("xy_cov must contain only finite values (no NaN/inf)")
    scale = np.maximum(np.abs(cov).max(axis=(1, 2)), 1e-300)
    if np.any(np.abs(cov[:, 0, 1] - cov[:, 1, 0]) > 1e-9 * scale):
        raise ValueError("xy_cov must hold symmetric 2 x 2 matrices (Σ01 = Σ10)")
    a2 = cov[:, 0, 0]
    safe_a = np.sqrt(np.where(a2 > 0.0, a2, 1.0))
    b = cov[:, 1, 0] / safe_a  # b = Σ10 / a
    c2 = cov[:, 1, 1] - b * b  # c² = Σ11 - b²  (the Schur complement, > 0 iff Σ is positive definite)
    if np.any(a2 <= 0.0) or np.any(c2 <= 1e-12 * scale):
        raise ValueError("xy_cov must hold positive-definite covariances (Σ00 > 0 and det Σ > 0)")
    c = np.sqrt(c2)
    W = np.zeros(cov.shape)
    W[:, 0, 0] = 1.0 / safe_a  # W = L^-1 = [[1/a, 0], [-b/(a c), 1/c]]
    W[:, 1, 0] = -b / (safe_a * c)
    W[:, 1, 1] = 1.0 / c
    return W


def isotropic_whitening(sigma: float) -> NDArray[np.float64]:
    """Return the read-only (2, 2) whitening matrix W = I / σ of the isotropic noise Σ = σ² I (σ in normalised
    image units, e.g. ``MsckfConfig.feature_noise_sigma``); one array shared by every observation that has no
    covariance of its own."""
    W = np.eye(2) / sigma
    W.flags.writeable = False
    return W


@dataclass
class FeatureUse:
    """One feature entering an update: its observations (window indices, xy) and which of them give residuals.

    Attributes:
        window_idx: (M,) positions of the observing cameras in the window (``FilterState.camera_ids`` order).
        xy: (M, 2) undistorted normalised observations.
        involved: (M,) observations used in the Jacobian (all for a lost track, those at the leaving states for a
            pruned one); the chi-square gate always sees all M.
        whiten: (M, 2, 2) W_i = L_i^-1 of each Σ_i; None: I / ``feature_noise_sigma`` for all.
    """

    window_idx: NDArray[np.int64]
    xy: NDArray[np.float64]
    involved: NDArray[np.bool_]
    whiten: NDArray[np.float64] | None = None


def _use(track: list[Observation], positions: dict[int, int], involved: NDArray[np.bool_]) -> FeatureUse:
    """Return the FeatureUse of a track's observations (window positions from ``positions``: camera id -> index)."""
    idx = np.fromiter((positions[c] for c, _, _ in track), dtype=np.int64, count=len(track))
    return FeatureUse(idx, np.array([z for _, z, _ in track]), involved, np.array([W for _, _, W in track]))


class FeatureDatabase:
    """The tracks held in the sliding window, per frame stream (module docstring).

    Args:
        config: reads ``track_gap_of(stream)`` (the images a track may miss and continue), ``min_track_length``
            (observations a lost track needs to be used) and ``feature_noise_sigma`` (the noise of observations
            given without a covariance).

    Attributes:
        tracks: dict feature id -> list of (camera id, xy (2,), W (2, 2)) observations held in the window.
        tracking_rate: share of the last image's ids that continued a track (S-MSCKF's keyframe rule reads it).

    >>> db = FeatureDatabase(MsckfConfig())
    >>> db.add_observations(0, np.array([7, 8]), np.zeros((2, 2)), None)   # camera state 0 sees features 7 and 8
    >>> db.add_observations(1, np.array([7]), np.zeros((1, 2)), None)      # state 1 sees 7 only: 8 has ended
    >>> uses, too_short = db.collect_lost(np.array([7]), 0, camera_ids=[0, 1])
    >>> len(uses), too_short, sorted(db.tracks), db.tracking_rate        # 8 had 1 observation of the 3 needed
    (0, 1, [7], 1.0)
    """

    def __init__(self, config: MsckfConfig) -> None:
        self._track_gap_of = config.track_gap_of
        self._min_track_length = config.min_track_length
        self._iso_whiten = isotropic_whitening(config.feature_noise_sigma)  # shared, never written
        self.tracks: dict[int, list[Observation]] = {}
        self._track_stream: dict[int, int] = {}  # the frame stream of each track (one stream: all 0)
        self._track_last_image: dict[int, int] = {}  # the stream's image count when each track was last observed
        self._stream_images: Counter[int] = Counter()  # images processed per stream
        self.tracking_rate = 1.0

    def check_stream(self, ids: NDArray[np.int64], stream: int) -> None:
        """Raise ValueError when an id of ``ids`` is a track of another frame stream (each stream needs its own)."""
        other = [fid for fid in ids.tolist() if self._track_stream.get(fid, stream) != stream]
        if other:
            raise ValueError(f"process_image(stream={stream}) got feature id {other[0]}, a track of stream "
                             f"{self._track_stream[other[0]]}; each stream needs its own ids")

    def clear(self) -> None:
        """Forget every track (the IMU-only mode keeps none)."""
        self.tracks.clear()
        self._track_stream.clear()
        self._track_last_image.clear()

    def add_observations(self, camera_id: int, ids: NDArray[np.int64], xy: NDArray[np.float64],
                         whiten: NDArray[np.float64] | None, stream: int = 0) -> None:
        """Count an image of ``stream`` and append its observations, taken at camera state ``camera_id``, to the
        tracks; record the tracking rate (share of known ids).

        Args:
            ids: (K,) feature ids; xy: (K, 2) undistorted normalised coordinates; whiten: (K, 2, 2) W = L^-1 of
                each observation's covariance, or None for the isotropic noise.
        """
        self._stream_images[stream] += 1  # the clock of max_track_gap: images of this stream so far
        tracked = 0
        tracks = self.tracks
        image = self._stream_images[stream]  # this image's number in its stream
        last_image = self._track_last_image
        W_all = [self._iso_whiten] * ids.shape[0] if whiten is None else whiten
        for fid, z, W in zip(ids.tolist(), xy, W_all):
            track = tracks.get(fid)
            if track is None:
                tracks[fid] = [(camera_id, z, W)]
                self._track_stream[fid] = stream
            else:
                track.append((camera_id, z, W))
                tracked += 1
            last_image[fid] = image
        self.tracking_rate = tracked / ids.shape[0] if ids.shape[0] else 0.0

    def collect_lost(self, ids: NDArray[np.int64], stream: int,
                     camera_ids: Sequence[int]) -> tuple[list[FeatureUse], int]:
        """Remove the tracks of ``stream`` that ended (missing from more than ``track_gap_of(stream)`` of its images
        in a row: with 0, not in ``ids``); return (those long enough to be used, with all their observations; the
        number dropped as too short).

        Args:
            ids: (K,) the feature ids of this image; camera_ids: the window's camera ids, oldest first.
        """
        current = set(ids.tolist())
        streams = self._track_stream
        last_image = self._track_last_image
        oldest = self._stream_images[stream] - self._track_gap_of(stream)  # last seen before this image: ended
        lost = [fid for fid in self.tracks
                if fid not in current and streams[fid] == stream and last_image[fid] < oldest]
        if not lost:
            return [], 0
        pos = {cid: i for i, cid in enumerate(camera_ids)}
        uses = []
        too_short = 0
        for fid in lost:
            track = self.tracks.pop(fid)
            del streams[fid]
            del last_image[fid]
            if len(track) < self._min_track_length:
                too_short += 1
                continue
            uses.append(_use(track, pos, np.ones(len(track), dtype=bool)))
        return uses, too_short

    def collect_pruned(self, remove: list[int], camera_ids: Sequence[int]) -> list[FeatureUse]:
        """Return the features seen at >= 2 of the camera states ``remove`` (those observations give the residuals).

        The observations made at those states are deleted from every track (they are used now or never).
        camera_ids: the window's camera ids, oldest first (``remove`` still among them).
        """
        if not remove or not self.tracks:
            return []
        gone = set(remove)
        pos = {cid: i for i, cid in enumerate(camera_ids)}
        uses = []
        for fid, track in self.tracks.items():
            involved = [obs[0] in gone for obs in track]
            n_involved = sum(involved)
            if n_involved == 0:
                continue
            if n_involved >= 2:
                uses.append(_use(track, pos, np.array(involved)))
            self.tracks[fid] = [obs for obs in track if obs[0] not in gone]
        return uses

    def remove_unused(self) -> None:
        """Drop tracks left without observations in the window."""
        for fid in [fid for fid, track in self.tracks.items() if not track]:
            del self.tracks[fid]
            del self._track_stream[fid]
            del self._track_last_image[fid]
