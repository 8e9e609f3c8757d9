"""Homographies: plane-induced homographies, warping points and images, and SuperPoint's random homographies.

A homography H (3, 3) maps pixels of image 1 to pixels of image 2: ``u2h ~ H u1h`` with ``uh = [x, y, 1]``.
Pixel centres lie at integer coordinates (OpenCV's convention), so an image of shape (H, W) spans pixel centres
``[0, W - 1] x [0, H - 1]``.

Reference: Hartley & Zisserman, "Multiple View Geometry", 2nd ed., §13.1 (Result 13.1, plane-induced homography);
thesis §3.2.5 (random homographies of homographic adaptation); DeTone, Malisiewicz & Rabinovich, "SuperPoint:
Self-Supervised Interest Point Detection and Description", CVPRW 2018.
"""
from __future__ import annotations

import math
from numbers import Integral, Real

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "homography_from_plane", "warp_points", "warp_image", "valid_mask", "sample_homography", "crop_to_full_homography",
]

_ROT_TOL = 1e-6  # tolerance on R R^T = I, det R = 1 and ||n|| = 1
_IMAGE_DTYPES = (np.dtype(np.uint8), np.dtype(np.float32), np.dtype(np.float64))


# ---------------------------------------------------------------------------------------------- input checks
def _as_matrix(value: ArrayLike, name: str, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Return ``value`` as a finite float64 array of the given shape, or raise ValueError naming ``name``."""
    array = np.asarray(value, dtype=np.float64)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}; got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite; got NaN or inf entries")
    return array


def _as_homography(value: ArrayLike, name: str = "H") -> NDArray[np.float64]:
    """Return a finite, invertible (3, 3) float64 homography."""
    H = _as_matrix(value, name, (3, 3))
    scale = np.abs(H).max()
    if scale == 0.0 or abs(np.linalg.det(H / scale)) < 1e-12:
        raise ValueError(f"{name} must be an invertible (3, 3) homography; got a singular matrix")
    return H


def as_image_shape(value: object, name: str) -> tuple[int, int]:
    """Return an image shape (height, width) of positive ints; (H, W, C) is cut to (H, W)."""
    try:
        dims = tuple(value)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"{name} must be an image shape (height, width); got {value!r}") from None
    if len(dims) not in (2, 3) or not all(
        isinstance(d, Integral) and not isinstance(d, bool) and d > 0 for d in dims
    ):
        raise ValueError(f"{name} must be an image shape (height, width) of positive integers; got {value!r}")
    return int(dims[0]), int(dims[1])


def _pixel_grid(shape: tuple[int, int]) -> NDArray[np.float64]:
    """Return homogeneous pixel centres (H, W, 3) [x, y, 1] of an image of the given shape."""
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return np.stack([xs, ys, np.ones_like(xs)], axis=-1)


# ---------------------------------------------------------------------------------------------- plane homography
def homography_from_plane(
    R_C1toC2: ArrayLike, p_C1inC2: ArrayLike, n_C1: ArrayLike, d: float, K1: ArrayLike, K2: ArrayLike
) -> NDArray[np.float64]:
    """Return the (3, 3) homography (H[2, 2] = 1) that the plane n_C1^T X_C1 = d induces between two views.

    For a point on the plane ``n^T X_C1 / d = 1``, so ``X_C2 = R X_C1 + t = (R + t n^T / d) X_C1`` and in pixels
    ``u2h ~ K2 (R + t n^T / d) K1^-1 u1h``.

    Args:
        R_C1toC2: (3, 3) rotation taking camera-1 coordinates into camera 2.
        p_C1inC2: (3,) position of camera 1's centre in frame C2 (metres), t above.
        n_C1: (3,) unit normal of the plane in frame C1.
        d: distance of the plane from camera 1's centre (metres, > 0).
        K1, K2: (3, 3) invertible intrinsic matrices of camera 1 and camera 2.

    Reference: Hartley & Zisserman §13.1, Result 13.1.

    >>> K = np.array([[200.0, 0, 120], [0, 200.0, 90], [0, 0, 1]])
    >>> H = homography_from_plane(np.eye(3), [-0.5, 0, 0], [0, 0, 1.0], 2.0, K, K)  # fronto-parallel wall 2 m away
    >>> H.round(3) + 0.0       # a pure shift of f * t_x / d = -50 px
    array([[  1.,   0., -50.],
           [  0.,   1.,   0.],
           [  0.,   0.,   1.]])
    """
    R = _as_matrix(R_C1toC2, "R_C1toC2", (3, 3))
    if np.abs(R @ R.T - np.eye(3)).max() > _ROT_TOL or abs(np.linalg.det(R) - 1.0) > _ROT_TOL:
        raise ValueError(f"R_C1toC2 must be a rotation matrix (R @ R.T == I, det R == 1 within {_ROT_TOL:g})")
    t = np.asarray(p_C1inC2, dtype=np.float64)
    t = _as_matrix(t.reshape(3) if t.shape == (3, 1) else t, "p_C1inC2", (3,))
    n = _as_matrix(n_C1, "n_C1", (3,))
    if abs(np.linalg.norm(n) - 1.0) > _ROT_TOL:
        raise ValueError(f"n_C1 must be a unit normal (norm 1 within {_ROT_TOL:g}); got norm {np.linalg.norm(n):.6g}")
    if isinstance(d, bool) or not isinstance(d, Real) or not (math.isfinite(d) and d > 0.0):
        raise ValueError(f"d must be a positive finite plane distance in metres; got {d!r}")
    K1 = _as_homography(K1, "K1")
    K2 = _as_homography(K2, "K2")
    H = K2 @ (R + np.outer(t, n) / d) @ np.linalg.inv(K1)  # H = K2 (R + t n^T / d) K1^-1
    if abs(H[2, 2]) < 1e-12 * np.abs(H).max():
        raise ValueError("the plane and pose give H[2, 2] == 0, which cannot be normalised to 1 (degenerate geometry)")
    return H / H[2, 2]


# ---------------------------------------------------------------------------------------------- warping
def warp_points(H: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Return the (N, 2) pixels (x, y) that the homography H maps ``points`` to.

    ``[x', y', w]^T = H [x, y, 1]^T``, result ``(x' / w, y' / w)``. Raises ValueError when a point maps to infinity
    (w == 0 up to rounding).

    Args:
        H: (3, 3) homography (image 1 pixels -> image 2 pixels).
        points: (N, 2) pixels (x, y) in image 1.

    Reference: Hartley & Zisserman §2.3.

    >>> warp_points([[2.0, 0, 1], [0, 2.0, 0], [0, 0, 1]], [[1.0, 1.0], [3.0, 0.5]])
    array([[3., 2.],
           [7., 1.]])
    """
    H = _as_matrix(H, "H", (3, 3))
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2) as (x, y) rows; got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("points must be finite; got NaN or inf entries")
    mapped = pts @ H[:, :2].T + H[:, 2]  # H [x, y, 1]^T
    w = mapped[:, 2]
    at_infinity = np.abs(w) <= 1e-12 * np.abs(mapped).max(axis=1, initial=0.0)
    if at_infinity.any():
        raise ValueError(
            f"points: {int(at_infinity.sum())} point(s) map to infinity under H (w == 0), "
            f"first at index {int(np.argmax(at_infinity))}: {pts[np.argmax(at_infinity)]}"
        )
    return mapped[:, :2] / w[:, None]  # (x' / w, y' / w)


def warp_image(
    image: np.ndarray,
    H: ArrayLike,
    out_shape: tuple[int, int] | None = None,
    interpolation: int = cv2.INTER_LINEAR,
    border_value: float = 0.0,
) -> np.ndarray:
    """Return image 1 warped into the frame of view 2 by H (same dtype: float32 in [0, 1], float64 or uint8).

    Output pixel u2 takes the value of image 1 at ``H^-1 u2`` (``cv2.warpPerspective``); pixels that come from
    outside image 1 get ``border_value`` (in the image's own units, e.g. 0..255 for uint8). Cubic and Lanczos
    interpolation can overshoot the input's range slightly on float images; linear and nearest cannot.

    Args:
        image: (H, W) or (H, W, C) image, C <= 4, dtype float32, float64 or uint8.
        H: (3, 3) homography mapping image-1 pixels to output pixels.
        out_shape: (height, width) of the output; default the input's.
        interpolation: an OpenCV interpolation flag (cv2.INTER_LINEAR, cv2.INTER_NEAREST, ...).
        border_value: value of output pixels that fall outside image 1.

    Reference: OpenCV ``warpPerspective``; Hartley & Zisserman §2.3.

    >>> img = np.zeros((4, 6), np.float32); img[1, 2] = 1.0
    >>> out = warp_image(img, [[1.0, 0, 2], [0, 1.0, 1], [0, 0, 1]])   # shift by (+2, +1) pixels
    >>> out.dtype, np.argwhere(out == 1.0).tolist()
    (dtype('float32'), [[2, 4]])
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or (img.ndim == 3 and not 1 <= img.shape[2] <= 4) or img.size == 0:
        raise ValueError(f"image must have shape (H, W) or (H, W, C) with 1 <= C <= 4; got {img.shape}")
    if img.dtype not in _IMAGE_DTYPES:
        raise ValueError(f"image must have dtype float32 (values in [0, 1]), float64 or uint8; got {img.dtype}")
    H = _as_homography(H)
    out_h, out_w = as_image_shape(img.shape if out_shape is None else out_shape, "out_shape")
    if isinstance(border_value, bool) or not isinstance(border_value, Real) or not math.isfinite(border_value):
        raise ValueError(f"border_value must be a finite number; got {border_value!r}")
    if not isinstance(interpolation, Integral) or isinstance(interpolation, bool):
        raise ValueError(f"interpolation must be an OpenCV interpolation flag (int); got {interpolation!r}")
    channels = 1 if img.ndim == 2 else img.shape[2]
    warped = cv2.warpPerspective(
        np.ascontiguousarray(img),
        H,
        (out_w, out_h),  # OpenCV wants dsize = (width, height)
        flags=int(interpolation),
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=(float(border_value),) * 4,
    )
    if img.ndim == 3 and warped.ndim == 2:  # OpenCV drops a single channel axis
        warped = warped[:, :, None]
    assert warped.shape[:2] == (out_h, out_w) and (img.ndim == 2 or warped.shape[2] == channels)
    return warped


def valid_mask(
    in_shape: tuple[int, int], H: ArrayLike, out_shape: tuple[int, int] | None = None, erode: int = 0
) -> NDArray[np.bool_]:
    """Return the bool (H_out, W_out) mask of warped-image pixels whose source lies inside image 1.

    Output pixel u2 is valid when ``u1 = H^-1 u2`` lies inside the pixel-centre rectangle ``[0, W - 1] x [0, H - 1]``
    of image 1 (so bilinear interpolation there uses no border value) and on the same side of H's vanishing line as
    image 1's centre (points beyond it would appear mirrored; the test does not depend on H's scale or sign). With
    ``erode > 0`` the valid region is eroded by a disc of that radius (pixels), to drop detections near the warped
    image border.

    Args:
        in_shape: (height, width) (or (H, W, C)) of image 1.
        H: (3, 3) homography mapping image-1 pixels to output pixels.
        out_shape: (height, width) of the warped image; default in_shape.
        erode: erosion radius in pixels (>= 0).

    Reference: SuperPoint (DeTone et al. 2018) homographic adaptation, valid-region masks.

    >>> valid_mask((4, 6), [[1.0, 0, 2], [0, 1.0, 1], [0, 0, 1]]).astype(int)
    array([[0, 0, 0, 0, 0, 0],
           [0, 0, 1, 1, 1, 1],
           [0, 0, 1, 1, 1, 1],
           [0, 0, 1, 1, 1, 1]])
    """
    in_h, in_w = as_image_shape(in_shape, "in_shape")
    H = _as_homography(H)
    out_h, out_w = (in_h, in_w) if out_shape is None else as_image_shape(out_shape, "out_shape")
    if isinstance(erode, bool) or not isinstance(erode, Integral) or erode < 0:
        raise ValueError(f"erode must be a non-negative integer radius in pixels; got {erode!r}")
    source = _pixel_grid((out_h, out_w)) @ np.linalg.inv(H).T  # v = H^-1 u2h = u1h / lambda, lambda = (H u1h)_3
    w = source[..., 2]
    centre_w = H[2] @ np.array([(in_w - 1) / 2.0, (in_h - 1) / 2.0, 1.0])  # lambda of image 1's centre
    in_front = w * (1.0 if centre_w == 0.0 else np.sign(centre_w)) > 0.0  # same side as the centre
    with np.errstate(divide="ignore", invalid="ignore"):
        x = source[..., 0] / w
        y = source[..., 1] / w
    # a little slack so that pixel centres exactly on the edge survive rounding
    tol = 1e-9 * max(in_h, in_w)
    mask = in_front & (x >= -tol) & (x <= in_w - 1 + tol) & (y >= -tol) & (y <= in_h - 1 + tol)
    if erode > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * erode + 1, 2 * erode + 1))
        # erosion only from the invalid region: outside the output image counts as valid (OpenCV's default border)
        mask = cv2.erode(mask.astype(np.uint8), kernel).astype(bool)
    return mask


# ---------------------------------------------------------------------------------------------- random homographies
def _truncated_normal(rng: np.random.Generator, size: int, mean: float, std: float) -> NDArray[np.float64]:
    """Return ``size`` normal samples redrawn until within 2 std of the mean (like tf.truncated_normal)."""
    out = rng.normal(mean, std, size)
    bad = np.abs(out - mean) > 2.0 * std
    while bad.any():
        out[bad] = rng.normal(mean, std, int(bad.sum()))
        bad = np.abs(out - mean) > 2.0 * std
    return out


def _inside(points: NDArray[np.float64], size: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Return whether every point of each candidate (..., 4, 2) lies in the rectangle [0, size] (up to rounding)."""
    tol = 1e-9 * float(size.max())
    return ((points >= -tol) & (points <= size + tol)).all(axis=(-2, -1))


def _four_point_homography(src: NDArray[np.float64], dst: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return H (3, 3), H[2, 2] = 1, with dst ~ H src for four (4, 2) point pairs (exact 8x8 linear solve)."""
    A = np.zeros((8, 8))
    b = dst.reshape(8)  # [x'_0, y'_0, x'_1, ...]
    x, y = src[:, 0], src[:, 1]
    # x' (h31 x + h32 y + 1) = h11 x + h12 y + h13, and the same for y'
    A[0::2, 0], A[0::2, 1], A[0::2, 2] = x, y, 1.0
    A[0::2, 6], A[0::2, 7] = -x * dst[:, 0], -y * dst[:, 0]
    A[1::2, 3], A[1::2, 4], A[1::2, 5] = x, y, 1.0
    A[1::2, 6], A[1::2, 7] = -x * dst[:, 1], -y * dst[:, 1]
    h = np.linalg.solve(A, b)
    return np.append(h, 1.0).reshape(3, 3)


def sample_homography(
    shape: tuple[int, int],
    rng: np.random.Generator | int,
    *,
    perspective: bool = True,
    scaling: bool = True,
    rotation: bool = True,
    translation: bool = True,
    n_scales: int = 5,
    n_angles: int = 25,
    scaling_amplitude: float = 0.1,
    perspective_amplitude_x: float = 0.1,
    perspective_amplitude_y: float = 0.1,
    patch_ratio: float = 0.5,
    max_angle: float = np.pi / 2,
    allow_artifacts: bool = False,
    translation_overflow: float = 0.0,
) -> NDArray[np.float64]:
    """Return a random homography H (3, 3), H[2, 2] = 1, as used by SuperPoint's homographic adaptation.

    DIRECTION: H maps pixel coordinates of the ORIGINAL image (shape (H, W)) to the WARPED image, so
    ``warp_image(img, H)`` produces the warped view, ``warp_points(H, kp)`` moves keypoints into it and
    ``valid_mask(img.shape, H)`` marks the warped pixels that saw the original image.

    Construction (thesis §3.2.5; SuperPoint): start from the central square crop (side ``patch_ratio`` of the image,
    in units of the image size) of the warped image; build a patch in the original image from it by
      1. perspective: move the left/right edges vertically by +/- a truncated normal (2 sigma = amplitude_y) and
         horizontally by truncated normals (amplitude_x);
      2. scaling: about the patch centre by one of 1 and ``n_scales`` truncated-normal scales in 1 +/- amplitude;
      3. translation: uniformly, within what keeps the patch inside the image (plus ``translation_overflow``
         times the image size when allow_artifacts);
      4. rotation: about the patch centre by one of 0 and ``n_angles`` angles evenly spaced in [-max_angle, max_angle].
    For 2 and 4 one candidate is picked at random among those whose patch stays inside the image (unless
    allow_artifacts, then among the random ones only); H maps the patch corners onto the crop corners.
    Coordinates are pixel centres (the image spans [0, W - 1] x [0, H - 1]); unlike SuperPoint's reference code, the
    rotation is applied in pixels, so it stays a rotation on non-square images.

    Args:
        shape: (height, width) of the original image (= the warped image).
        rng: seeded ``numpy.random.Generator`` (or an int seed).
        perspective, scaling, rotation, translation: switch each component on or off (all off gives the identity).
        n_scales, n_angles: number of scale / angle candidates (>= 1).
        scaling_amplitude: scales lie in (1 - a, 1 + a) (truncated normal, sigma a / 2).
        perspective_amplitude_x, perspective_amplitude_y: perspective corner shifts, fractions of the image size
            (capped at the crop margin unless allow_artifacts).
        patch_ratio: side of the central crop as a fraction of the image size, in (0, 1].
        max_angle: largest in-plane rotation in radians (>= 0).
        allow_artifacts: let the patch leave the image (the warped crop then shows the border value).
        translation_overflow: extra translation range (fraction of the image size) when allow_artifacts.

    Reference: thesis §3.2.5; DeTone et al., "SuperPoint", CVPRW 2018, §5 (homographic adaptation) and its
    reference implementation (sample_homography).

    >>> H = sample_homography((120, 160), np.random.default_rng(0))
    >>> H.shape, float(H[2, 2])
    ((3, 3), 1.0)
    >>> off = dict(perspective=False, scaling=False, rotation=False, translation=False)
    >>> sample_homography((120, 160), 0, **off).round(9) + 0.0     # every component off: the identity
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    """
    height, width = as_image_shape(shape, "shape")
    if isinstance(rng, (bool, np.bool_)) or not isinstance(rng, (np.random.Generator, Integral)):
        raise ValueError(f"rng must be a numpy.random.Generator or an int seed; got {type(rng).__name__}")
    rng = np.random.default_rng(rng) if isinstance(rng, Integral) else rng
    for name, value in (("n_scales", n_scales), ("n_angles", n_angles)):
        if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    for name, value in (
        ("scaling_amplitude", scaling_amplitude),
        ("perspective_amplitude_x", perspective_amplitude_x),
        ("perspective_amplitude_y", perspective_amplitude_y),
        ("max_angle", max_angle),
        ("translation_overflow", translation_overflow),
    ):
        if isinstance(value, bool) or not isinstance(value, Real) or not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name} must be a finite number >= 0; got {value!r}")
    if isinstance(patch_ratio, bool) or not isinstance(patch_ratio, Real) or not 0.0 < patch_ratio <= 1.0:
        raise ValueError(f"patch_ratio must be a fraction of the image size in (0, 1]; got {patch_ratio!r}")

    size = np.array([width - 1.0, height - 1.0])  # extent of the pixel-centre rectangle (x, y)
    margin = (1.0 - patch_ratio) / 2.0
    unit_square = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])
    crop = (margin + patch_ratio * unit_square) * size  # corners of the central crop of the warped image
    patch = crop.copy()  # its corners in the original image, perturbed below

    if perspective:
        amp_x, amp_y = perspective_amplitude_x, perspective_amplitude_y
        if not allow_artifacts:
            amp_x, amp_y = min(amp_x, margin), min(amp_y, margin)
        dy = _truncated_normal(rng, 1, 0.0, amp_y / 2.0)[0]
        dx_left, dx_right = _truncated_normal(rng, 2, 0.0, amp_x / 2.0)
        # left edge (corners 0, 1) and right edge (corners 2, 3) move apart/together vertically: a keystone
        patch += np.array([[dx_left, dy], [dx_left, -dy], [dx_right, dy], [dx_right, -dy]]) * size

    if scaling:
        scales = np.concatenate([[1.0], _truncated_normal(rng, n_scales, 1.0, scaling_amplitude / 2.0)])
        centre = patch.mean(axis=0)
        candidates = (patch - centre)[None] * scales[:, None, None] + centre  # (1 + n_scales, 4, 2)
        valid = np.arange(1, n_scales + 1) if allow_artifacts else np.flatnonzero(_inside(candidates, size))
        patch = candidates[valid[rng.integers(len(valid))]]

    if translation:
        t_min = patch.min(axis=0)  # room to move towards 0
        t_max = (size - patch).min(axis=0)  # room to move towards the far edge
        if allow_artifacts:
            t_min = t_min + translation_overflow * size
            t_max = t_max + translation_overflow * size
        # uniform between the two bounds; with artifacts allowed a patch larger than the image makes the interval
        # inverted (-t_min > t_max), and the shift is then drawn between the same two bounds, as SuperPoint does
        patch = patch + (-t_min + (t_max + t_min) * rng.random(2))

    if rotation:
        angles = np.concatenate([[0.0], np.linspace(-max_angle, max_angle, n_angles)])
        centre = patch.mean(axis=0)
        c, s = np.cos(angles), np.sin(angles)
        rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (1 + n_angles, 2, 2)
        candidates = (patch - centre)[None] @ np.swapaxes(rot, -1, -2) + centre  # p' = R (p - c) + c
        valid = np.arange(1, n_angles + 1) if allow_artifacts else np.flatnonzero(_inside(candidates, size))
        patch = candidates[valid[rng.integers(len(valid))]]

    return _four_point_homography(patch, crop)  # original-image patch -> warped-image crop


def crop_to_full_homography(shape: tuple[int, int], patch_ratio: float) -> NDArray[np.float64]:
    """Return the (3, 3) map A of the central crop (side ``patch_ratio``) of an image onto the whole image.

    The crop spans ``m + r [0, 1]`` times the pixel-centre extent ``(W - 1, H - 1)`` with ``m = (1 - r) / 2``, so
    ``x' = (x - m (W - 1)) / r`` (and the same for y): a zoom by ``1 / r`` about the image centre.
    ``A @ sample_homography(shape, rng, patch_ratio=r, ...)`` maps the random patch onto the whole view, which is
    SuperPoint's convention (its patch fills the warped image).

    >>> A = crop_to_full_homography((5, 9), 0.5)
    >>> warp_points(A, [[2.0, 1.0], [6.0, 3.0], [4.0, 2.0]]).tolist()   # crop corners -> image corners, centre fixed
    [[0.0, 0.0], [8.0, 4.0], [4.0, 2.0]]
    """
    height, width = int(shape[0]), int(shape[1])
    r = float(patch_ratio)
    if not 0.0 < r <= 1.0:
        raise ValueError(f"patch_ratio must be in (0, 1]; got {patch_ratio!r}")
    m = (1.0 - r) / 2.0
    return np.array([[1.0 / r, 0.0, -m * (width - 1) / r], [0.0, 1.0 / r, -m * (height - 1) / r], [0.0, 0.0, 1.0]])
