"""Classical detectors behind the common interface: Harris, Shi-Tomasi, FAST, SIFT, ORB and FAST + FREAK.

Each detector follows the same pipeline: candidates with scores -> :func:`~evio_lib.features.base.nms_keypoints`
(box NMS of radius ``nms_radius``, strongest first) -> descriptors for the strongest survivors -> the best
``max_keypoints`` keypoints that have a descriptor. Every detector converts its input with
:func:`~evio_lib.features.base.to_uint8_image` first, so a uint8 image and its float version ``u / 255`` give
identical results.

Descriptors:

- SIFT: its own 128-D descriptor, L2-normalised float32.
- ORB: its own rotated BRIEF, 32 bytes (256 bits) uint8, ``binary=True``.
- FAST + FREAK: FAST keypoints described by FREAK, 64 bytes (512 bits) uint8, ``binary=True``; FREAK drops
  keypoints whose sampling pattern leaves the image (about 20 px from the border), which are then not returned.
- Harris, Shi-Tomasi and FAST have no descriptor of their own. They are described by **upright SIFT descriptors**
  computed at the keypoint (``cv2.SIFT.compute`` with orientation 0 and a fixed patch size ``descriptor_size``
  pixels, i.e. 4 x 4 histogram cells of ``1.5 * descriptor_size`` pixels each), L2-normalised float32. Upright
  descriptors suit the small in-plane rotations of the benchmark's homographies (thesis §3.2.6) and keep the
  comparison about the detectors. Keypoints whose descriptor is all zeros (a flat patch) are dropped.

OpenCV hands keypoints over as Python ``cv2.KeyPoint`` objects; building and reading those is the only step done
per keypoint, everything numerical is vectorised.

References: Harris & Stephens 1988 (corner response); Shi & Tomasi 1994 ("Good features to track");
Rosten & Drummond 2006 (FAST); Lowe 2004 (SIFT); Rublee et al. 2011 (ORB); Alahi et al. 2012 (FREAK);
thesis §2.1.3 and §3.2.6 (the classical detectors the CNN is compared with, Tables 2-5).
"""
from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from evio_lib.features.base import FeatureDetector, Features, _check_int, nms_keypoints, to_uint8_image

__all__ = [
    "HarrisDetector",
    "ShiTomasiDetector",
    "FastDetector",
    "SiftDetector",
    "OrbDetector",
    "FastFreakDetector",
    "harris_response",
    "upright_sift_descriptors",
    "fast_score",
]

_SIFT_DIM = 128  # floats
_ORB_BYTES = 32  # 256 bits
_FREAK_BYTES = 64  # 512 bits


# ---------------------------------------------------------------------------------------------- small helpers
def _check_real(name: str, value: object, low: float, high: float = np.inf, low_open: bool = False) -> float:
    """Return ``value`` as a float in [low, high] ((low, high] if low_open), or raise ValueError naming ``name``."""
    ok = isinstance(value, Real) and not isinstance(value, bool) and np.isfinite(value)
    ok = ok and (value > low if low_open else value >= low) and value <= high
    if not ok:
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}]"
        raise ValueError(f"{name} must be a finite number in {interval}; got {value!r}")
    return float(value)


def _points_of(keypoints: list[cv2.KeyPoint] | tuple[cv2.KeyPoint, ...]) -> NDArray[np.float64]:
    """Return the (N, 2) pixel positions (x, y) of OpenCV keypoints."""
    if len(keypoints) == 0:
        return np.zeros((0, 2), np.float64)
    return np.asarray(cv2.KeyPoint.convert(list(keypoints)), dtype=np.float64).reshape(-1, 2)


def _responses_of(keypoints: list[cv2.KeyPoint] | tuple[cv2.KeyPoint, ...]) -> NDArray[np.float64]:
    """Return the (N,) detector responses of OpenCV keypoints."""
    return np.fromiter((k.response for k in keypoints), dtype=np.float64, count=len(keypoints))


def _surviving(requested: list[cv2.KeyPoint], returned: list[cv2.KeyPoint] | tuple) -> NDArray[np.bool_]:
    """Return which of the requested keypoints an OpenCV ``compute`` kept (it only drops, never reorders or moves).

    The positions of the requested keypoints are unique (they passed NMS), so survivors are found by position.
    """
    if len(returned) == len(requested):
        return np.ones(len(requested), bool)
    req = _points_of(requested).astype(np.float32)
    ret = _points_of(returned).astype(np.float32)
    key_req = (req[:, 0].view(np.uint32).astype(np.uint64) << np.uint64(32)) | req[:, 1].view(np.uint32)
    key_ret = (ret[:, 0].view(np.uint32).astype(np.uint64) << np.uint64(32)) | ret[:, 1].view(np.uint32)
    return np.isin(key_req, key_ret)


def _unit_rows(descriptors: NDArray[np.float32]) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
    """Return (rows with non-zero norm, those rows divided by their L2 norm) of a float descriptor matrix."""
    norms = np.linalg.norm(descriptors, axis=1)
    ok = norms > 0.0
    return ok, (descriptors[ok] / norms[ok, None]).astype(np.float32)  # d / ||d||_2


def upright_sift_descriptors(
    image: NDArray[np.uint8], points: NDArray[np.float64], size: float
) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
    """Return (which points got a descriptor, (M, 128) L2-normalised upright SIFT descriptors of those points).

    Args:
        image: (H, W) uint8 image.
        points: (N, 2) pixels (x, y).
        size: keypoint diameter in pixels given to SIFT (histogram cells are 1.5 * size pixels wide).
    """
    if points.shape[0] == 0:
        return np.zeros(0, bool), np.zeros((0, _SIFT_DIM), np.float32)
    # angle 0: upright (not rotation invariant); octave 0: described on the un-doubled first pyramid level
    kps = [cv2.KeyPoint(float(x), float(y), size, 0.0, 0.0, 0) for x, y in points]
    returned, desc = cv2.SIFT_create().compute(image, kps)
    alive = _surviving(kps, returned)
    if desc is None or not alive.any():
        return np.zeros(points.shape[0], bool), np.zeros((0, _SIFT_DIM), np.float32)
    nonzero, unit = _unit_rows(np.asarray(desc, np.float32))
    ok = alive.copy()
    ok[alive] = nonzero
    return ok, unit


# ---------------------------------------------------------------------------------------------- shared pipeline
class _ClassicalDetector(FeatureDetector):
    """Candidates -> NMS -> descriptors of the strongest survivors -> at most ``max_keypoints`` Features."""

    descriptor_dim: int = _SIFT_DIM
    binary: bool = False
    min_size: int = 1  # images with a side shorter than this give no keypoints

    def detect_and_describe(self, image: np.ndarray) -> Features:
        """Return the keypoints (strongest first), scores and descriptors of a grayscale image.

        Args:
            image: (H, W) uint8 in 0..255 or float32/float64 in [0, 1].
        """
        img = to_uint8_image(image)
        if min(img.shape) < self.min_size:
            return Features.empty(self.descriptor_dim, self.binary)
        points, scores, state = self._candidates(img)
        if points.shape[0] == 0:
            return Features.empty(self.descriptor_dim, self.binary)
        order = nms_keypoints(points, scores, self.nms_radius, img.shape)
        kept, descriptors = self._describe_best(img, order, points, state)
        return Features(points[kept], scores[kept], descriptors, self.binary)

    def _describe_best(
        self, img: NDArray[np.uint8], order: NDArray[np.intp], points: NDArray[np.float64], state: Any
    ) -> tuple[NDArray[np.intp], np.ndarray]:
        """Describe the NMS survivors in batches, strongest first, until ``max_keypoints`` have a descriptor."""
        want = self.max_keypoints
        kept: list[NDArray[np.intp]] = []
        descs: list[np.ndarray] = []
        n_kept, start = 0, 0
        while n_kept < want and start < order.size:
            missing = want - n_kept
            stop = min(order.size, start + missing + missing // 4 + 8)  # a margin for keypoints without descriptor
            batch = order[start:stop]
            ok, desc = self._describe(img, batch, points, state)
            kept.append(batch[ok])
            descs.append(desc)
            n_kept += int(ok.sum())
            start = stop
        dtype = np.uint8 if self.binary else np.float32
        if not kept:
            return np.zeros(0, np.intp), np.zeros((0, self.descriptor_dim), dtype)
        return np.concatenate(kept)[:want], np.concatenate(descs).astype(dtype, copy=False)[:want]

    def _candidates(self, img: NDArray[np.uint8]) -> tuple[NDArray[np.float64], NDArray[np.float64], Any]:
        """Return candidate keypoints (M, 2), their scores (M,) and any state ``_describe`` needs."""
        raise NotImplementedError

    def _describe(
        self, img: NDArray[np.uint8], batch: NDArray[np.intp], points: NDArray[np.float64], state: Any
    ) -> tuple[NDArray[np.bool_], np.ndarray]:
        """Return (which of ``batch`` got a descriptor, their descriptors in batch order)."""
        raise NotImplementedError


class _UprightSiftDescribed(_ClassicalDetector):
    """Detectors without a descriptor of their own: upright SIFT descriptors at the keypoints."""

    def _describe(self, img, batch, points, state):  # type: ignore[no-untyped-def]
        return upright_sift_descriptors(img, points[batch], self.descriptor_size)


# ---------------------------------------------------------------------------------------------- Harris / Shi-Tomasi
def harris_response(image: np.ndarray, block_size: int = 3, aperture: int = 3, k: float = 0.04) -> NDArray[np.float32]:
    """Return the (H, W) float32 Harris corner response R = det(M) - k tr(M)^2 of a grayscale image.

    M is the structure tensor: Sobel derivatives (``aperture`` x ``aperture``, scaled by 1 / (2^(aperture - 1)
    block_size) as OpenCV does) of the image in [0, 1], their products summed over a ``block_size`` x
    ``block_size`` window. Computed by ``cv2.cornerHarris`` (reflect-101 border).

    Args:
        image: (H, W) uint8 or float32/float64 in [0, 1].
        block_size: side of the summation window (pixels).
        aperture: Sobel kernel size (3, 5 or 7).
        k: Harris sensitivity, typically 0.04-0.06.

    Reference: Harris & Stephens, "A combined corner and edge detector", 1988.

    >>> img = np.zeros((20, 20), np.uint8); img[5:15, 5:15] = 255     # a white square
    >>> R = harris_response(img)
    >>> sorted(divmod(int(i), 20) for i in np.argsort(R, axis=None)[-4:])     # its four corners (row, col)
    [(5, 5), (5, 14), (14, 5), (14, 14)]
    """
    img = to_uint8_image(image).astype(np.float32) / np.float32(255.0)
    return cv2.cornerHarris(img, int(block_size), int(aperture), float(k))


class _CornerResponseDetector(_UprightSiftDescribed):
    """Corners from a dense response map: 3x3 local maxima above ``quality_level * max`` -> NMS -> top-k."""

    _floor: float = 0.0  # absolute minimum response, rejects rounding noise on (nearly) flat images
    _default_quality_level: float = 0.001  # each response's own default (it scales differently with contrast)

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        block_size: int = 3,
        aperture: int = 3,
        quality_level: float | None = None,
        descriptor_size: float = 4.0,
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints, nms_radius, **options)
        self.block_size = _check_int("block_size", block_size, minimum=2)
        if aperture not in (3, 5, 7) or isinstance(aperture, bool):
            raise ValueError(f"aperture must be a Sobel kernel size 3, 5 or 7; got {aperture!r}")
        self.aperture = int(aperture)
        level = self._default_quality_level if quality_level is None else quality_level
        self.quality_level = _check_real("quality_level", level, 0.0, 1.0)
        self.descriptor_size = _check_real("descriptor_size", descriptor_size, 0.0, low_open=True)

    def _response(self, img01: NDArray[np.float32]) -> NDArray[np.float32]:
        raise NotImplementedError

    def _candidates(self, img):  # type: ignore[no-untyped-def]
        response = self._response(img.astype(np.float32) / np.float32(255.0))
        peak = float(response.max())
        threshold = max(self.quality_level * peak, self._floor)
        local_max = response == cv2.dilate(response, np.ones((3, 3), np.uint8))  # 3x3 local maxima
        rows, cols = np.nonzero(local_max & (response > threshold))
        points = np.column_stack([cols, rows]).astype(np.float64)  # (x, y) = (col, row)
        return points, response[rows, cols].astype(np.float64), None


class HarrisDetector(_CornerResponseDetector):
    """Harris corners: local maxima of R = det(M) - k tr(M)^2 (see :func:`harris_response`), upright SIFT descriptors.

    Args:
        max_keypoints, nms_radius: see :class:`~evio_lib.features.base.FeatureDetector`.
        block_size: structure-tensor window (pixels), default 3.
        aperture: Sobel kernel size, default 3.
        k: Harris sensitivity, default 0.04.
        quality_level: keep candidates with R > quality_level * max(R), default 1e-5 (R grows with the fourth
            power of the contrast, so this keeps corners down to ~6 % of the strongest corner's contrast).
        descriptor_size: SIFT keypoint diameter for the descriptor (pixels), default 4.

    Keypoints lie on integer pixels; scores are R.

    Reference: Harris & Stephens 1988; thesis §2.1.3, Tables 2-3 (Harris row).

    >>> img = np.zeros((40, 40), np.uint8); img[10:30, 10:30] = 255
    >>> f = HarrisDetector(max_keypoints=10).detect_and_describe(img)
    >>> sorted(f.keypoints.astype(int).tolist()), f.descriptors.shape
    ([[10, 10], [10, 29], [29, 10], [29, 29]], (4, 128))
    """

    name = "harris"
    _floor = 1e-10  # R scales with contrast^4: a corner of contrast 1 gives R ~ 0.1
    _default_quality_level = 1e-5

    def __init__(self, max_keypoints: int = 1000, nms_radius: int = 4, *, k: float = 0.04, **options: Any) -> None:
        super().__init__(max_keypoints, nms_radius, **options)  # block_size, aperture, quality_level, ...
        self.k = _check_real("k", k, 0.0, 0.25, low_open=True)

    def _response(self, img01):  # type: ignore[no-untyped-def]
        return cv2.cornerHarris(img01, self.block_size, self.aperture, self.k)  # R = det M - k (tr M)^2


class ShiTomasiDetector(_CornerResponseDetector):
    """Shi-Tomasi corners: local maxima of the smaller eigenvalue of the structure tensor, upright SIFT descriptors.

    Args:
        max_keypoints, nms_radius: see :class:`~evio_lib.features.base.FeatureDetector`.
        block_size: structure-tensor window (pixels), default 3.
        aperture: Sobel kernel size, default 3.
        quality_level: keep candidates with lambda_min > quality_level * max(lambda_min), default 1e-4
            (lambda_min grows with the square of the contrast: down to ~1 % of the strongest corner's contrast).
        descriptor_size: SIFT keypoint diameter for the descriptor (pixels), default 4.

    Score: lambda_min(M) = (a + c) / 2 - sqrt(((a - c) / 2)^2 + b^2) for M = [[a, b], [b, c]]
    (``cv2.cornerMinEigenVal``); keypoints on integer pixels.

    Reference: Shi & Tomasi, "Good features to track", CVPR 1994.

    >>> img = np.zeros((40, 40), np.uint8); img[10:30, 10:30] = 255
    >>> sorted(ShiTomasiDetector().detect_and_describe(img).keypoints.astype(int).tolist())
    [[10, 10], [10, 29], [29, 10], [29, 29]]
    """

    name = "shi_tomasi"
    _floor = 1e-7  # lambda_min scales with contrast^2: a corner of contrast 1 gives ~0.25
    _default_quality_level = 1e-4

    def _response(self, img01):  # type: ignore[no-untyped-def]
        return cv2.cornerMinEigenVal(img01, self.block_size, ksize=self.aperture)  # lambda_min(M)


# ---------------------------------------------------------------------------------------------- FAST
# The 16-pixel Bresenham circle of radius 3 used by FAST-9/16, as (dx, dy), clockwise from the top (OpenCV's order).
_FAST_CIRCLE = np.array(
    [(0, 3), (1, 3), (2, 2), (3, 1), (3, 0), (3, -1), (2, -2), (1, -3),
     (0, -3), (-1, -3), (-2, -2), (-3, -1), (-3, 0), (-3, 1), (-2, 2), (-1, 3)]
)  # fmt: skip
_FAST_ARC = 9


def fast_score(image: np.ndarray, points: np.ndarray) -> NDArray[np.float64]:
    """Return the FAST-9 score of integer pixels: the largest threshold t for which each is still a FAST corner.

    With d_k = I(circle_k) - I(centre) on the 16-pixel circle of radius 3, a pixel is a corner at threshold t when
    9 contiguous d_k are all > t (brighter arc) or all < -t (darker arc), so
    ``score = max(max_arcs min_arc d_k, max_arcs min_arc (-d_k)) - 1`` (OpenCV's ``KeyPoint.response``).

    Args:
        image: (H, W) uint8 or float32/float64 in [0, 1] (scores are in uint8 levels).
        points: (N, 2) integer pixels (x, y) at least 3 pixels from the border.

    Reference: Rosten & Drummond, ECCV 2006, §2 (segment test) and OpenCV's ``cornerScore``.

    >>> img = np.zeros((9, 9), np.uint8); img[4:, 4:] = 100                    # a bright quadrant
    >>> fast_score(img, np.array([[4, 4]])).tolist()                          # 3/4 of the circle is darker by 100
    [99.0]
    """
    return _fast_scores(to_uint8_image(image), points)[0]


def _fast_scores(img: NDArray[np.uint8], points: np.ndarray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (FAST score t, tie-break sum) of integer pixels; see :func:`fast_score`.

    The tie-break is the summed contrast of the circle pixels on the winning side (sum of max(0, +-d_k)), which
    is largest at the tip of a corner, where the most circle pixels differ from the centre.
    """
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2) as (x, y) pixels; got {pts.shape}")
    cols, rows = np.rint(pts[:, 0]).astype(np.intp), np.rint(pts[:, 1]).astype(np.intp)
    h, w = img.shape
    if pts.shape[0] and (cols.min() < 3 or rows.min() < 3 or cols.max() > w - 4 or rows.max() > h - 4):
        raise ValueError(f"points must lie at least 3 pixels inside the image of shape {(h, w)} (the FAST circle)")
    centre = img[rows, cols].astype(np.int16)
    ring = img[rows[:, None] + _FAST_CIRCLE[:, 1], cols[:, None] + _FAST_CIRCLE[:, 0]].astype(np.int16)
    d = ring - centre[:, None]  # d_k = I_k - I_p, (N, 16)
    arcs = d[:, (np.arange(16)[:, None] + np.arange(_FAST_ARC)[None, :]) % 16]  # (N, 16 start points, 9)
    brighter = arcs.min(axis=2).max(axis=1)  # best arc whose pixels are all brighter by > t
    darker = (-arcs).min(axis=2).max(axis=1)  # best arc whose pixels are all darker by > t
    side = np.where(brighter >= darker, 1, -1)[:, None]
    tie_break = np.maximum(side * d, 0).sum(axis=1)  # sum of max(0, +-d_k) on the winning side
    return np.maximum(brighter, darker).astype(np.float64) - 1.0, tie_break.astype(np.float64)


def _fast_detector_scores(img: NDArray[np.uint8], points: np.ndarray) -> NDArray[np.float64]:
    """Return t + s / 4081 (t: FAST score, s <= 16 * 255: tie-break), ordering corners by t, then by s."""
    t, tie_break = _fast_scores(img, points)
    return t + tie_break / (16 * 255 + 1)


def _fast_corners(img: NDArray[np.uint8], threshold: int) -> tuple[list[cv2.KeyPoint], NDArray[np.float64]]:
    """Return every FAST-9 corner pixel (OpenCV, no suppression) as keypoints and their (x, y) positions."""
    kps = cv2.FastFeatureDetector_create(threshold, False, cv2.FAST_FEATURE_DETECTOR_TYPE_9_16).detect(img)
    return list(kps), _points_of(kps)


def _check_fast_threshold(name: str, value: object) -> int:
    """Return a FAST intensity threshold in [1, 255] (uint8 levels), or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Integral) or not 1 <= value <= 255:
        raise ValueError(f"{name} must be an integer intensity step in [1, 255] (uint8 levels); got {value!r}")
    return int(value)


class FastDetector(_UprightSiftDescribed):
    """FAST-9 corners (a contiguous arc of 9 of 16 circle pixels brighter/darker than the centre), upright SIFT
    descriptors.

    Args:
        max_keypoints, nms_radius: see :class:`~evio_lib.features.base.FeatureDetector`.
        threshold: intensity step t in uint8 levels (0..255) that the arc must exceed, default 20.
        descriptor_size: SIFT keypoint diameter for the descriptor (pixels), default 4.

    Candidates are all FAST corner pixels (``cv2.FastFeatureDetector`` without its own suppression). The score is
    ``t + s / 4081``: t is :func:`fast_score` (the largest threshold at which the pixel is still a corner, equal to
    OpenCV's response, so ``floor(score) == t``) and s <= 16 * 255 the summed contrast of the circle pixels on
    the corner's side, which breaks the many ties of t in favour of the corner's tip. The radius NMS replaces
    FAST's 3x3 suppression (which in OpenCV drops tied corners entirely, e.g. all four corners of a clean
    synthetic square). Keypoints lie on integer pixels, at least 3 px from the border. FAST fires on L-shaped
    corners, not on the X-junctions of a checkerboard (the circle then has four short arcs).

    Reference: Rosten & Drummond, "Machine learning for high-speed corner detection", ECCV 2006.

    >>> img = np.zeros((40, 40), np.uint8); img[10:30, 10:30] = 255
    >>> sorted(FastDetector().detect_and_describe(img).keypoints.astype(int).tolist())
    [[10, 10], [10, 29], [29, 10], [29, 29]]
    """

    name = "fast"

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        threshold: int = 20,
        descriptor_size: float = 4.0,
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints, nms_radius, **options)
        self.threshold = _check_fast_threshold("threshold", threshold)
        self.descriptor_size = _check_real("descriptor_size", descriptor_size, 0.0, low_open=True)

    def _candidates(self, img):  # type: ignore[no-untyped-def]
        _, points = _fast_corners(img, self.threshold)
        return points, _fast_detector_scores(img, points), None


# ---------------------------------------------------------------------------------------------- SIFT
class SiftDetector(_ClassicalDetector):
    """SIFT: difference-of-Gaussian extrema with their own 128-D descriptors (L2-normalised float32).

    Args:
        max_keypoints, nms_radius: see :class:`~evio_lib.features.base.FeatureDetector`.
        n_octave_layers: DoG layers per octave, default 3.
        contrast_threshold: minimum |DoG| contrast (OpenCV units), default 0.04.
        edge_threshold: maximum principal-curvature ratio, default 10.
        sigma: blur of the first octave, default 1.6.

    Scores are |DoG| responses; keypoints are sub-pixel. A point with two dominant orientations is reported by
    OpenCV twice at the same place; the NMS keeps one of them. Detection runs on all candidates, description only
    on the kept ones.

    Reference: Lowe, "Distinctive image features from scale-invariant keypoints", IJCV 2004; thesis Tables 2-5.
    """

    name = "sift"
    min_size = 16

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        n_octave_layers: int = 3,
        contrast_threshold: float = 0.04,
        edge_threshold: float = 10.0,
        sigma: float = 1.6,
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints, nms_radius, **options)
        self.n_octave_layers = _check_int("n_octave_layers", n_octave_layers, minimum=1)
        self.contrast_threshold = _check_real("contrast_threshold", contrast_threshold, 0.0)
        self.edge_threshold = _check_real("edge_threshold", edge_threshold, 0.0, low_open=True)
        self.sigma = _check_real("sigma", sigma, 0.0, low_open=True)

    def _sift(self) -> cv2.SIFT:
        return cv2.SIFT_create(0, self.n_octave_layers, self.contrast_threshold, self.edge_threshold, self.sigma)

    def _candidates(self, img):  # type: ignore[no-untyped-def]
        kps = self._sift().detect(img, None)
        return _points_of(kps), _responses_of(kps), kps

    def _describe(self, img, batch, points, state):  # type: ignore[no-untyped-def]
        kps = [state[i] for i in batch]
        returned, desc = self._sift().compute(img, kps)
        alive = _surviving(kps, returned)
        if desc is None or not alive.any():
            return np.zeros(batch.size, bool), np.zeros((0, _SIFT_DIM), np.float32)
        nonzero, unit = _unit_rows(np.asarray(desc, np.float32))
        alive[alive] = nonzero
        return alive, unit


# ---------------------------------------------------------------------------------------------- ORB
class OrbDetector(_ClassicalDetector):
    """ORB: oriented FAST on an image pyramid, Harris-ranked, with rotated BRIEF descriptors (32 bytes, binary).

    Args:
        max_keypoints, nms_radius: see :class:`~evio_lib.features.base.FeatureDetector`.
        scale_factor: pyramid decimation ratio, default 1.2.
        n_levels: pyramid levels, default 8.
        edge_threshold: border (pixels) where no keypoint is detected, default 31 (= patch_size).
        patch_size: BRIEF patch size (pixels), default 31.
        fast_threshold: FAST intensity threshold (uint8 levels), default 20.
        n_candidates: how many keypoints ORB itself keeps (its ``nfeatures``, spread over the pyramid levels)
            before the radius NMS and the top-k, default 5000; independent of ``max_keypoints`` so that the best k
            keypoints are a prefix of the best 2k.

    Scores are ORB's Harris responses; positions in the full-resolution image. Descriptors are packed bits
    (uint8, ``binary=True``), matched with the Hamming distance.

    Reference: Rublee et al., "ORB: an efficient alternative to SIFT or SURF", ICCV 2011; thesis Tables 4-5.
    """

    name = "orb"
    descriptor_dim = _ORB_BYTES
    binary = True

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        scale_factor: float = 1.2,
        n_levels: int = 8,
        edge_threshold: int = 31,
        patch_size: int = 31,
        fast_threshold: int = 20,
        n_candidates: int = 5000,
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints, nms_radius, **options)
        self.scale_factor = _check_real("scale_factor", scale_factor, 1.0, 4.0, low_open=True)
        self.n_levels = _check_int("n_levels", n_levels, minimum=1)
        self.edge_threshold = _check_int("edge_threshold", edge_threshold, minimum=0)
        self.patch_size = _check_int("patch_size", patch_size, minimum=2)
        self.fast_threshold = _check_fast_threshold("fast_threshold", fast_threshold)
        self.n_candidates = _check_int("n_candidates", n_candidates, minimum=1)
        self.min_size = 2 * max(self.edge_threshold, self.patch_size) + 2  # ORB finds nothing (or fails) below

    def _candidates(self, img):  # type: ignore[no-untyped-def]
        orb = cv2.ORB_create(
            nfeatures=self.n_candidates,
            scaleFactor=self.scale_factor,
            nlevels=self.n_levels,
            edgeThreshold=self.edge_threshold,
            patchSize=self.patch_size,
            fastThreshold=self.fast_threshold,
        )
        kps, desc = orb.detectAndCompute(img, None)
        if desc is None or len(kps) == 0:
            return np.zeros((0, 2)), np.zeros(0), None
        return _points_of(kps), _responses_of(kps), np.asarray(desc, np.uint8)

    def _describe(self, img, batch, points, state):  # type: ignore[no-untyped-def]
        return np.ones(batch.size, bool), state[batch]


# ---------------------------------------------------------------------------------------------- FAST + FREAK
class FastFreakDetector(_ClassicalDetector):
    """FAST-9 keypoints described by FREAK (retina-like binary descriptor, 64 bytes = 512 bits).

    Args:
        max_keypoints, nms_radius: see :class:`~evio_lib.features.base.FeatureDetector`.
        threshold: FAST intensity threshold (uint8 levels), default 20.
        orientation_normalized: rotate the FREAK pattern to the keypoint orientation, default True.
        scale_normalized: scale the pattern with the keypoint size, default True.
        pattern_scale: FREAK pattern scale, default 22.
        n_octaves: octaves the pattern covers, default 4.

    Keypoints and scores as in :class:`FastDetector`. Keypoints too close to the border for the FREAK pattern get
    no descriptor and are dropped (the next strongest take their place). Needs OpenCV's contrib build
    (``cv2.xfeatures2d``).

    Reference: Alahi, Ortiz & Vandergheynst, "FREAK: Fast retina keypoint", CVPR 2012; thesis Tables 4-5.
    """

    name = "fast_freak"
    descriptor_dim = _FREAK_BYTES
    binary = True

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        threshold: int = 20,
        orientation_normalized: bool = True,
        scale_normalized: bool = True,
        pattern_scale: float = 22.0,
        n_octaves: int = 4,
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints, nms_radius, **options)
        self.threshold = _check_fast_threshold("threshold", threshold)
        for flag_name, flag in (
            ("orientation_normalized", orientation_normalized),
            ("scale_normalized", scale_normalized),
        ):
            if not isinstance(flag, (bool, np.bool_)):
                raise ValueError(f"{flag_name} must be a bool; got {flag!r}")
        self.orientation_normalized = bool(orientation_normalized)
        self.scale_normalized = bool(scale_normalized)
        self.pattern_scale = _check_real("pattern_scale", pattern_scale, 0.0, low_open=True)
        self.n_octaves = _check_int("n_octaves", n_octaves, minimum=1)
        if not hasattr(cv2, "xfeatures2d"):
            raise ImportError("FAST+FREAK needs OpenCV's contrib build: pip install opencv-contrib-python-headless")

    def _candidates(self, img):  # type: ignore[no-untyped-def]
        kps, points = _fast_corners(img, self.threshold)
        return points, _fast_detector_scores(img, points), kps

    def _freak(self) -> Any:
        """Return this detector's FREAK extractor; made once, since its first use builds the pattern (its
        cost: docs/results/speed.md#small-costs-behind-the-codes-choices)."""
        if getattr(self, "_freak_extractor", None) is None:
            self._freak_extractor = cv2.xfeatures2d.FREAK_create(
                self.orientation_normalized, self.scale_normalized, self.pattern_scale, self.n_octaves
            )
        return self._freak_extractor

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_freak_extractor"] = None  # OpenCV objects do not pickle; rebuilt on first use
        return state

    def _describe(self, img, batch, points, state):  # type: ignore[no-untyped-def]
        freak = self._freak()
        kps = [state[i] for i in batch]
        returned, desc = freak.compute(img, kps)
        alive = _surviving(kps, returned)
        if desc is None or not alive.any():
            return np.zeros(batch.size, bool), np.zeros((0, _FREAK_BYTES), np.uint8)
        return alive, np.asarray(desc, np.uint8)
