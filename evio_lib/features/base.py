"""The common feature interface: the ``Features`` record, the ``FeatureDetector`` base class, the name registry,
image validation and the radius non-maximum suppression shared by every detector.

Every detector, classical or learned, is created by name and used the same way::

    detector = create_detector("sift", max_keypoints=300, nms_radius=4)
    features = detector.detect_and_describe(image)     # (H, W) uint8 or float32 in [0, 1]
    features.keypoints, features.scores, features.descriptors

Keypoints are (x, y) pixels with pixel centres at integer coordinates (OpenCV's convention, as in
``evio_lib.geometry.homography``).

Reference: thesis §3.2.6 (detectors compared on repeatability and homography estimation with the best N points
after non-maximum suppression); DeTone et al., "SuperPoint", CVPRW 2018 (grid NMS).
"""
from __future__ import annotations

import importlib
import inspect
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass
from numbers import Integral
from typing import Any, Callable

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Features",
    "FeatureDetector",
    "to_float_image",
    "to_uint8_image",
    "create_detector",
    "register_detector",
    "available_detectors",
    "nms_keypoints",
    "SUPERPOINT_DEFAULT_WEIGHTS",
]

# Built-in names -> (module, class), imported only when asked for (the CNN pulls in torch).
_BUILTIN_DETECTORS: dict[str, tuple[str, str]] = {
    "harris": ("evio_lib.features.classical", "HarrisDetector"),
    "shi_tomasi": ("evio_lib.features.classical", "ShiTomasiDetector"),
    "fast": ("evio_lib.features.classical", "FastDetector"),
    "sift": ("evio_lib.features.classical", "SiftDetector"),
    "orb": ("evio_lib.features.classical", "OrbDetector"),
    "fast_freak": ("evio_lib.features.classical", "FastFreakDetector"),
    "superpoint": ("evio_lib.features.network.detector", "SuperPointDetector"),   # default weights: below
}
#: Shipped weights behind the name "superpoint" (and SuperPointDetector()'s default): the best shipped network on the
#: held-out benchmark (docs/results/features.md): pre-trained DetDesc Round 1 fine-tuned on natural photographs with
#: the reprojection loss (training/superpoint_photos); ``weights=`` picks another.
SUPERPOINT_DEFAULT_WEIGHTS = "photos_detdesc"
# Modules that register trained variants (register_detector) when imported; loaded on a registry miss.
_PLUGIN_MODULES: tuple[str, ...] = ("evio_lib.features.network.detector",)
_REGISTERED: dict[str, Callable[..., "FeatureDetector"]] = {}


# ---------------------------------------------------------------------------------------------- the record
@dataclass(frozen=True)
class Features:
    """Keypoints, scores and descriptors that a detector found in one image.

    Attributes:
        keypoints: (N, 2) float32 pixels (x, y) in the input image.
        scores: (N,) float32 detector responses, higher = stronger, sorted in descending order.
        descriptors: (N, D) float32 rows of unit L2 norm for float descriptors, or (N, D) uint8 packed bits
            (D bytes = 8 D bits, compared with the Hamming distance) when ``binary`` is True.
        binary: True for binary descriptors (ORB, FREAK).

    The constructor converts array-likes to these dtypes and raises ValueError on inconsistent shapes, non-finite
    values or unsorted scores.

    >>> f = Features([[3.0, 4.0], [1.0, 2.0]], [0.9, 0.5], [[1.0, 0.0], [0.0, 1.0]])
    >>> len(f), f.keypoints.dtype, f.descriptors.shape, f.binary
    (2, dtype('float32'), (2, 2), False)
    """

    keypoints: np.ndarray
    scores: np.ndarray
    descriptors: np.ndarray
    binary: bool = False

    def __post_init__(self) -> None:
        binary = self.binary
        if not isinstance(binary, (bool, np.bool_)):
            raise ValueError(f"binary must be a bool (True for packed-bit descriptors); got {binary!r}")
        keypoints = np.array(self.keypoints, dtype=np.float32)
        if keypoints.size == 0:
            keypoints = keypoints.reshape(0, 2)
        if keypoints.ndim != 2 or keypoints.shape[1] != 2:
            raise ValueError(f"keypoints must have shape (N, 2) as (x, y) pixels; got {keypoints.shape}")
        n = keypoints.shape[0]
        scores = np.array(self.scores, dtype=np.float32)
        if scores.size == 0:
            scores = scores.reshape(0)
        if scores.shape != (n,):
            raise ValueError(f"scores must have shape (N,) = ({n},) to match keypoints; got {scores.shape}")
        descriptors = np.asarray(self.descriptors)
        if descriptors.ndim != 2 or descriptors.shape[0] != n:
            raise ValueError(
                f"descriptors must have shape (N, D) with N = {n} rows to match keypoints; got {descriptors.shape}"
            )
        if binary:
            if descriptors.dtype != np.uint8:
                raise ValueError(f"binary descriptors must be packed bits of dtype uint8; got {descriptors.dtype}")
            descriptors = np.array(descriptors, dtype=np.uint8)
        else:
            descriptors = np.array(descriptors, dtype=np.float32)
            if not np.isfinite(descriptors).all():
                raise ValueError("descriptors must be finite; got NaN or inf entries")
        if not (np.isfinite(keypoints).all() and np.isfinite(scores).all()):
            raise ValueError("keypoints and scores must be finite; got NaN or inf entries")
        if n > 1 and (np.diff(scores) > 0).any():
            first = int(np.flatnonzero(np.diff(scores) > 0)[0]) + 1
            raise ValueError(
                f"scores must be sorted in descending order; score {first} is larger than score {first - 1}"
            )
        object.__setattr__(self, "keypoints", keypoints)
        object.__setattr__(self, "scores", scores)
        object.__setattr__(self, "descriptors", descriptors)
        object.__setattr__(self, "binary", bool(binary))

    def __len__(self) -> int:
        """Return the number of keypoints N."""
        return int(self.keypoints.shape[0])

    @classmethod
    def empty(cls, descriptor_dim: int, binary: bool = False) -> "Features":
        """Return a Features record with no keypoints and (0, descriptor_dim) descriptors of the right dtype.

        >>> Features.empty(32, binary=True).descriptors.shape
        (0, 32)
        """
        dim = _check_int("descriptor_dim", descriptor_dim, minimum=0)
        dtype = np.uint8 if binary else np.float32
        return cls(np.zeros((0, 2), np.float32), np.zeros(0, np.float32), np.zeros((0, dim), dtype), binary)


# ---------------------------------------------------------------------------------------------- the detector base
class FeatureDetector(ABC):
    """Base class of every detector: ``detect_and_describe(image) -> Features``.

    Args:
        max_keypoints: keep at most this many keypoints (the strongest after NMS), >= 1.
        nms_radius: radius r in pixels of the non-maximum suppression; no two returned keypoints lie within a
            (2r + 1) x (2r + 1) box of each other (see :func:`nms_keypoints`); 0 only merges keypoints that round
            to the same pixel.
        **options: detector-specific options. Subclasses take their own options as keyword arguments and pass on
            only the rest; whatever reaches this base class is unknown and raises ValueError.
    """

    name: str = "base"

    def __init__(self, max_keypoints: int = 1000, nms_radius: int = 4, **options: Any) -> None:
        self.max_keypoints = _check_int("max_keypoints", max_keypoints, minimum=1)
        self.nms_radius = _check_int("nms_radius", nms_radius, minimum=0)
        if options:
            accepted: list[str] = []  # every named parameter of the constructors along the class hierarchy
            for cls in type(self).__mro__:
                if "__init__" in vars(cls) and cls is not object:
                    accepted += [
                        p.name
                        for p in inspect.signature(vars(cls)["__init__"]).parameters.values()
                        if p.name != "self" and p.name not in accepted
                        and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)
                    ]
            raise ValueError(
                f"unknown option(s) {sorted(options)} for detector {self.name!r}; accepted options: {accepted}"
            )

    @abstractmethod
    def detect_and_describe(self, image: np.ndarray) -> Features:
        """Return the keypoints, scores and descriptors of a grayscale (H, W) uint8 or float32 [0, 1] image."""

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, max_keypoints={self.max_keypoints}, "
            f"nms_radius={self.nms_radius})"
        )


# ---------------------------------------------------------------------------------------------- images
def _check_image(image: object, name: str) -> np.ndarray:
    """Return ``image`` as an array after checking it is a non-empty 2-D uint8/float32/float64 image."""
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a grayscale image of shape (H, W); got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} must be a non-empty (H, W) image; got shape {arr.shape}")
    if arr.dtype == np.uint8:
        return arr
    if arr.dtype not in (np.float32, np.float64):
        raise ValueError(
            f"{name} must have dtype uint8 (0..255) or float32/float64 (values in [0, 1]); got {arr.dtype}"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite; got NaN or inf pixels")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"{name} of dtype {arr.dtype} must have values in [0, 1]; got range [{lo:.4g}, {hi:.4g}]")
    return arr


def to_float_image(image: ArrayLike, name: str = "image") -> NDArray[np.float32]:
    """Return a grayscale image as a new (H, W) float32 array in [0, 1] (uint8 is divided by 255).

    Args:
        image: (H, W) uint8 in 0..255, or float32/float64 in [0, 1].
        name: how error messages call the argument.

    >>> to_float_image(np.array([[0, 51, 255]], np.uint8))
    array([[0. , 0.2, 1. ]], dtype=float32)
    """
    arr = _check_image(image, name)
    if arr.dtype == np.uint8:
        return arr.astype(np.float32) / np.float32(255.0)  # f = u / 255
    return np.array(arr, dtype=np.float32, order="C")


def to_uint8_image(image: ArrayLike, name: str = "image") -> NDArray[np.uint8]:
    """Return a grayscale image as a new (H, W) uint8 array (float values are scaled by 255 and rounded).

    ``to_uint8_image(to_float_image(u)) == u`` for every uint8 image u, so detectors that work on uint8 give the
    same result for an image and its float version.

    Args:
        image: (H, W) uint8 in 0..255, or float32/float64 in [0, 1].
        name: how error messages call the argument.

    >>> to_uint8_image(np.array([[0.0, 0.2, 1.0]], np.float32))
    array([[  0,  51, 255]], dtype=uint8)
    """
    arr = _check_image(image, name)
    if arr.dtype == np.uint8:
        return np.array(arr, dtype=np.uint8, order="C")
    return np.clip(np.rint(arr * 255.0), 0, 255).astype(np.uint8)  # u = round(255 f)


# ---------------------------------------------------------------------------------------------- NMS
def nms_keypoints(
    keypoints: ArrayLike, scores: ArrayLike, radius: int, shape: tuple[int, int]
) -> NDArray[np.intp]:
    """Return the indices of the keypoints that survive greedy box NMS, strongest first.

    Greedy definition (the grid NMS of SuperPoint): visit keypoints by descending score (ties: lower index first);
    keep a keypoint unless an already kept one lies within Chebyshev distance ``radius`` of it, measured on the
    keypoints rounded to the nearest pixel, i.e. ``max(|dx|, |dy|) <= radius``. Radius 0 merges keypoints that
    round to the same pixel. Taking the first k indices gives the best k keypoints after NMS.

    The greedy result is computed exactly without a loop over points: in each round every undecided keypoint that
    is the strongest undecided one in its (2r + 1)^2 box is kept (no stronger keypoint can still suppress it), and
    the undecided keypoints in the boxes of the newly kept ones are suppressed; box maxima come from
    ``cv2.dilate`` of a priority raster. Rounds repeat until every keypoint is decided (a few on real images).

    Args:
        keypoints: (N, 2) pixels (x, y); rounded coordinates must lie in the image up to one pixel (those just
            outside are clipped onto the border).
        scores: (N,) finite scores, higher = stronger.
        radius: NMS radius r >= 0 in pixels.
        shape: image shape (H, W) (a third entry is ignored).

    Reference: DeTone et al., "SuperPoint", CVPRW 2018, §3 (NMS on the detector output); thesis §3.2.6 (NMS 4/8).

    >>> kp = [[10, 10], [12, 11], [30, 5], [10.4, 9.6]]
    >>> nms_keypoints(kp, [0.5, 0.9, 0.3, 0.8], radius=2, shape=(20, 40)).tolist()
    [1, 2]
    >>> nms_keypoints(kp, [0.5, 0.9, 0.3, 0.8], radius=0, shape=(20, 40)).tolist()   # 0 and 3 share pixel (10, 10)
    [1, 3, 2]
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.size == 0:
        kp = kp.reshape(0, 2)
    if kp.ndim != 2 or kp.shape[1] != 2:
        raise ValueError(f"keypoints must have shape (N, 2) as (x, y) pixels; got {kp.shape}")
    sc = np.asarray(scores, dtype=np.float64)
    if sc.size == 0:
        sc = sc.reshape(0)
    if sc.shape != (kp.shape[0],):
        raise ValueError(f"scores must have shape (N,) = ({kp.shape[0]},) to match keypoints; got {sc.shape}")
    if not (np.isfinite(kp).all() and np.isfinite(sc).all()):
        raise ValueError("keypoints and scores must be finite; got NaN or inf entries")
    r = _check_int("radius", radius, minimum=0)
    height, width = _check_shape(shape)
    n = kp.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.intp)

    cols = np.rint(kp[:, 0]).astype(np.int64)  # nearest pixel centre
    rows = np.rint(kp[:, 1]).astype(np.int64)
    outside = (cols < -1) | (cols > width) | (rows < -1) | (rows > height)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise ValueError(
            f"keypoints must lie inside the image of shape {(height, width)}; keypoint {i} is at {kp[i].tolist()}"
        )
    cols = np.clip(cols, 0, width - 1)
    rows = np.clip(rows, 0, height - 1)

    order = np.argsort(-sc, kind="stable")  # strongest first, ties by index
    dtype = np.float32 if n < 2**24 else np.float64  # priorities are exact integers in the rasters
    priority = np.empty(n, dtype)
    priority[order] = np.arange(n, 0, -1, dtype=dtype)  # n for the strongest ... 1 for the weakest
    pixel = rows * width + cols
    best = np.zeros(height * width, dtype)
    np.maximum.at(best, pixel, priority)  # strongest keypoint of each pixel (distance 0 <= r)
    candidate = best[pixel] == priority
    if r == 0:
        return order[candidate[order]].astype(np.intp)

    index = np.flatnonzero(candidate)  # one keypoint per pixel from here on
    c_rows, c_cols = rows[index], cols[index]
    raster = best.reshape(height, width)  # priority of the undecided keypoint at each pixel, 0 = none
    box = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
    kept = np.zeros(index.size, bool)
    undecided = np.arange(index.size)
    while undecided.size:
        box_max = cv2.dilate(raster, box)  # strongest undecided priority within the box around each pixel
        rr, cc = c_rows[undecided], c_cols[undecided]
        is_max = box_max[rr, cc] == raster[rr, cc]  # strongest undecided in its box -> kept by greedy NMS
        new = undecided[is_max]
        kept[new] = True
        covered = np.zeros((height, width), np.uint8)
        covered[c_rows[new], c_cols[new]] = 1
        covered = cv2.dilate(covered, box).view(bool)  # within r of a newly kept keypoint
        raster[covered] = 0  # the new keypoints and those they suppress are decided
        rest = undecided[~is_max]
        undecided = rest[~covered[c_rows[rest], c_cols[rest]]]
    survives = np.zeros(n, bool)
    survives[index[kept]] = True
    return order[survives[order]].astype(np.intp)


# ---------------------------------------------------------------------------------------------- registry
def _normalise_name(name: object) -> str:
    """Return the registry key of a detector name: lower case, '-' and ' ' as '_'."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"detector name must be a non-empty string such as 'sift'; got {name!r}")
    return name.strip().lower().replace("-", "_").replace(" ", "_")


def _load_plugins() -> None:
    """Import the modules that register trained variants; a module that fails to import is skipped with a warning."""
    for module in _PLUGIN_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name != module:  # the module exists but one of its imports does not
                warnings.warn(f"{module} could not be imported ({err}); its detectors are unavailable", stacklevel=3)
        except Exception as err:  # noqa: BLE001 - a broken plugin must not hide the classical detectors
            warnings.warn(f"{module} could not be imported ({err!r}); its detectors are unavailable", stacklevel=3)


def _lookup(key: str) -> Callable[..., FeatureDetector] | None:
    """Return the factory registered under ``key``, importing a built-in class on demand, or None."""
    if key in _REGISTERED:
        return _REGISTERED[key]
    if key in _BUILTIN_DETECTORS:
        module, cls = _BUILTIN_DETECTORS[key]
        try:
            return getattr(importlib.import_module(module), cls)
        except ImportError as err:
            raise ImportError(f"detector {key!r} needs {module}.{cls}, which could not be imported: {err}") from err
    return None


def register_detector(name: str, factory: Callable[..., FeatureDetector], *, overwrite: bool = False) -> None:
    """Register ``factory(**options) -> FeatureDetector`` under ``name`` so that ``create_detector(name)`` finds it.

    Names are case-insensitive and '-' equals '_'. Registering the same factory twice is a no-op; a different
    factory under a taken name (or a built-in name) raises ValueError unless ``overwrite`` is True. Modules that
    register variants on import should be listed in ``_PLUGIN_MODULES`` so a registry miss imports them.

    Args:
        name: the new detector name, e.g. "detdesc_round2".
        factory: a FeatureDetector subclass or any callable taking keyword options and returning a detector
            (e.g. ``functools.partial(SuperPointDetector, weights="detdesc_round2")``).
        overwrite: allow replacing an existing name.

    >>> class Nothing(FeatureDetector):
    ...     name = "nothing"
    ...     def detect_and_describe(self, image):
    ...         return Features.empty(8)
    >>> register_detector("nothing", Nothing, overwrite=True)
    >>> len(create_detector("Nothing", max_keypoints=5).detect_and_describe(np.zeros((4, 4), np.uint8)))
    0
    >>> _ = _REGISTERED.pop("nothing")  # (tidy up: this example is not a real detector)
    """
    key = _normalise_name(name)
    if not callable(factory):
        raise ValueError(f"factory must be callable (a FeatureDetector class or function); got {factory!r}")
    if _REGISTERED.get(key) is factory:
        return
    if not overwrite and (key in _REGISTERED or key in _BUILTIN_DETECTORS):
        raise ValueError(f"detector name {key!r} is already registered; pass overwrite=True to replace it")
    _REGISTERED[key] = factory


def available_detectors() -> list[str]:
    """Return the names that :func:`create_detector` accepts: the built-ins, then registered variants.

    >>> available_detectors()[:6]
    ['harris', 'shi_tomasi', 'fast', 'sift', 'orb', 'fast_freak']
    """
    _load_plugins()
    return list(_BUILTIN_DETECTORS) + [k for k in _REGISTERED if k not in _BUILTIN_DETECTORS]


def create_detector(name: str, **options: Any) -> FeatureDetector:
    """Return a new detector of the given name, configured by keyword options.

    Args:
        name: one of :func:`available_detectors` (case-insensitive, '-' equals '_': "FAST-FREAK" works).
        **options: ``max_keypoints``, ``nms_radius`` and the detector's own options (see its class).

    Raises ValueError for an unknown name (the message lists the available ones) or an unknown option.
    "superpoint" is the best shipped network (``SUPERPOINT_DEFAULT_WEIGHTS``, ``photos_detdesc``).

    >>> det = create_detector("fast", max_keypoints=300, nms_radius=4)
    >>> det.name, det.max_keypoints, det.nms_radius
    ('fast', 300, 4)
    """
    key = _normalise_name(name)
    factory = _lookup(key)
    if factory is None:
        _load_plugins()  # trained variants register themselves when their module is imported
        factory = _lookup(key)
    if factory is None:
        raise ValueError(f"unknown detector name {name!r}; available: {', '.join(available_detectors())}")
    detector = factory(**options)
    if not isinstance(detector, FeatureDetector):
        raise TypeError(f"the factory registered as {key!r} returned {type(detector).__name__}, not a FeatureDetector")
    return detector


# ---------------------------------------------------------------------------------------------- small checks
def _check_int(name: str, value: object, minimum: int) -> int:
    """Return ``value`` as an int >= minimum, or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def _check_shape(shape: object) -> tuple[int, int]:
    """Return (H, W) of an image shape, or raise ValueError."""
    try:
        dims = tuple(shape)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"shape must be an image shape (H, W); got {shape!r}") from None
    if len(dims) not in (2, 3) or not all(isinstance(d, Integral) and not isinstance(d, bool) and d > 0 for d in dims):
        raise ValueError(f"shape must be an image shape (H, W) of positive integers; got {shape!r}")
    return int(dims[0]), int(dims[1])
