"""Every parameter of the feature-tracking front-end in one frozen dataclass that validates and prints itself.

Defaults follow the thesis (§3.3.5: N = 60 features, a 4 x 5 grid with N / 20 per cell, two-point RANSAC) and, for
the KLT option, msckf_vio's image processor (15 px window, 3 pyramid levels, 30 iterations, epsilon 0.01).

``match_radius_px`` (15 px) bounds the flow left after the gyroscope's rotation is removed, i.e. the flow of the
translation, with a margin over the largest such flow between 24 Hz frames of the whole boxes_like preset (measured
with the simulator's depth: docs/results/pipeline.md#what-a-run-assumes).
Descriptor matching over a wider window lets repeated textures through (a copy 20-40 px away wins when the true
detection is missing), which two-point RANSAC cannot always reject while the translation is small. Without a
rotation prior the rotation's flow must fit in the radius too: widen it (e.g. 60 px) or set None.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from numbers import Integral, Real
from typing import Any

__all__ = ["FrontendConfig", "TRACKING_METHODS"]

TRACKING_METHODS = ("descriptor", "klt")


def _param(default: Any, unit: str, doc: str) -> Any:
    """Return a dataclass field carrying its unit and a one-line description (used by ``__str__``)."""
    return field(default=default, metadata={"unit": unit, "doc": doc})


@dataclass(frozen=True)
class FrontendConfig:
    """Every parameter of the front-end (frozen, validated); ``print(config)`` lists them one per line.

    >>> cfg = FrontendConfig(max_features=40)
    >>> cfg.per_cell, cfg.detector_name
    (2, 'sift')
    >>> FrontendConfig(method="klt").detector_name
    'fast'
    """

    method: str = _param("descriptor", "", "'descriptor' (detect + match + two-point RANSAC) or 'klt' (optical flow)")
    detector: str | None = _param(None, "", "evio_lib.features detector name; None: 'sift' (descriptor), 'fast' (klt)")
    detector_options: tuple[tuple[str, Any], ...] = _param((), "", "extra detector options as (name, value) pairs")
    max_features: int = _param(60, "", "N, the most features kept per frame (thesis §3.3.5)")
    grid_rows: int = _param(4, "", "rows of the feature grid")
    grid_cols: int = _param(5, "", "columns of the feature grid (cap per cell: max_features // (rows cols))")
    detector_max_keypoints: int = _param(1000, "", "candidates the detector returns per frame (before the grid; "
                                                   "enough that weakly textured cells get some)")
    nms_radius: int = _param(4, "px", "non-maximum suppression radius of the detector")
    min_distance_px: float = _param(5.0, "px", "a new feature is at least this far from every tracked one")
    match_radius_px: float | None = _param(15.0, "px", "guided matching: detections within this radius of the "
                                           "rotation-predicted position (None: anywhere)")
    ratio: float | None = _param(0.8, "", "Lowe's ratio test of descriptor matches (None: off)")
    max_descriptor_distance: float | None = _param(None, "", "absolute gate on the match distance (None: off)")
    ransac: bool = _param(True, "", "reject outliers with two-point RANSAC")
    ransac_threshold_px: float = _param(1.5, "px", "inlier threshold on the Sampson distance")
    ransac_iterations: int = _param(100, "", "two-match hypotheses per frame")
    klt_window: int = _param(15, "px", "KLT window side (odd)")
    klt_levels: int = _param(3, "", "KLT pyramid levels above the image")
    klt_max_iterations: int = _param(30, "", "KLT iterations per level")
    klt_epsilon: float = _param(0.01, "px", "KLT convergence threshold")
    klt_backward_check_px: float | None = _param(1.0, "px", "forward-backward KLT consistency (None: off)")
    max_track_gap: int = _param(0, "", "descriptor method: frames a lost track is kept and searched for (0: none)")
    border_px: float = _param(1.0, "px", "tracked points closer than this to the image edge are dropped")
    seed: int = _param(0, "", "seed of RANSAC's hypothesis sampling")

    def __post_init__(self) -> None:
        if self.method not in TRACKING_METHODS:
            raise ValueError(f"method must be one of {TRACKING_METHODS}; got {self.method!r}")
        if self.detector is not None and (not isinstance(self.detector, str) or not self.detector.strip()):
            raise ValueError(f"detector must be a detector name such as 'sift' or None; got {self.detector!r}")
        options = self.detector_options
        if isinstance(options, dict):
            options = tuple(sorted(options.items()))
            object.__setattr__(self, "detector_options", options)
        if not isinstance(options, tuple) or not all(
                isinstance(o, tuple) and len(o) == 2 and isinstance(o[0], str) for o in options):
            raise ValueError(f"detector_options must be a dict or (name, value) pairs; got {self.detector_options!r}")
        for name, minimum in (("max_features", 1), ("grid_rows", 1), ("grid_cols", 1), ("detector_max_keypoints", 1),
                              ("nms_radius", 0), ("ransac_iterations", 1), ("klt_window", 3), ("klt_levels", 0),
                              ("klt_max_iterations", 1), ("seed", 0),
                              ("max_track_gap", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral) or value < minimum:
                raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
        if self.max_track_gap and self.method != "descriptor":
            raise ValueError(f"max_track_gap applies to the descriptor method (KLT follows each patch and never "
                             f"searches for a lost one); got {self.max_track_gap} with method {self.method!r}")
        if self.klt_window % 2 == 0:
            raise ValueError(f"klt_window must be odd (a window centred on the point); got {self.klt_window}")
        if self.max_features < self.grid_rows * self.grid_cols:
            raise ValueError(f"max_features must be at least grid_rows * grid_cols = {self.grid_rows * self.grid_cols} "
                             f"(one feature per cell); got {self.max_features}")
        for name, positive in (("min_distance_px", False), ("ransac_threshold_px", True), ("klt_epsilon", True),
                               ("border_px", False)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) \
                    or value < 0 or (positive and value == 0):
                raise ValueError(f"{name} must be a finite number {'>' if positive else '>='} 0; got {value!r}")
        for name in ("match_radius_px", "max_descriptor_distance", "klt_backward_check_px"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, Real)
                                      or not math.isfinite(value) or value <= 0):
                raise ValueError(f"{name} must be a finite number > 0 or None; got {value!r}")
        if self.ratio is not None and (isinstance(self.ratio, bool) or not isinstance(self.ratio, Real)
                                       or not 0.0 < self.ratio <= 1.0):
            raise ValueError(f"ratio must be in (0, 1] or None; got {self.ratio!r}")
        if not isinstance(self.ransac, bool):
            raise ValueError(f"ransac must be True or False; got {self.ransac!r}")

    @property
    def per_cell(self) -> int:
        """Return the cap of each grid cell, max_features // (grid_rows grid_cols) (thesis: N / 20)."""
        return self.max_features // (self.grid_rows * self.grid_cols)

    @property
    def detector_name(self) -> str:
        """Return the detector used: ``detector``, or the method's default ('sift' or 'fast')."""
        if self.detector is not None:
            return self.detector
        return "sift" if self.method == "descriptor" else "fast"

    def __str__(self) -> str:
        lines = ["FrontendConfig"]
        for f in fields(self):
            value = getattr(self, f.name)
            text = f"{value:.6g}" if isinstance(value, float) else repr(value)
            if f.name == "detector" and value is None:
                text = f"None -> {self.detector_name!r}"
            lines.append(f"  {f.name:<24} = {text:<16} {f.metadata['unit']:<3} {f.metadata['doc']}".rstrip())
        return "\n".join(lines)
