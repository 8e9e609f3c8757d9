"""Feature-tracking front-end: frames in, feature tracks (ids + undistorted normalised coordinates) out.

    from evio_lib.frontend import FrontendConfig, create_tracker, camera_rotation_priors
    tracker = create_tracker(seq.camera, FrontendConfig(detector="sift", max_features=60))   # or method="klt"
    priors = camera_rotation_priors(seq.imu.t, seq.imu.gyro, seq.frame_times, seq.R_CtoI)   # gyro prior (optional)
    for image, t, R in zip(seq.frames, seq.frame_times, priors):
        frame = tracker.process(image, t, R)          # or tracker.track(seq.frames, seq.frame_times, priors)
        msckf.process_image(frame.t, frame.ids, frame.xy)

Two-point RANSAC is ``evio_lib.frontend.two_point_ransac.two_point_ransac`` (the module keeps the name, so the package
does not re-export the function). Modules: ``config`` (every parameter), ``tracker`` (the thesis's descriptor tracker
and the shared output), ``klt`` (the optical-flow baseline), ``matching``, ``two_point_ransac``, ``grid``,
``gyro_prior``. Reference: thesis §3.3.5.
"""
from __future__ import annotations

from evio_lib.features.base import FeatureDetector
from evio_lib.frontend.config import TRACKING_METHODS, FrontendConfig
from evio_lib.frontend.grid import FeatureGrid
from evio_lib.frontend.gyro_prior import camera_rotation_prior, camera_rotation_priors, integrate_gyro
from evio_lib.frontend.klt import KltTracker
from evio_lib.frontend.matching import match_mutual_ratio
from evio_lib.frontend.tracker import DescriptorTracker, FeatureTracker, FrameStats, TrackedFrame, stats_table
from evio_lib.geometry.camera import PinholeRadtan

__all__ = [
    "TRACKING_METHODS", "FrontendConfig", "FeatureGrid", "camera_rotation_prior", "camera_rotation_priors",
    "integrate_gyro", "KltTracker",
    "match_mutual_ratio", "DescriptorTracker", "FeatureTracker", "FrameStats", "TrackedFrame", "stats_table",
    "create_tracker",
]


def create_tracker(camera: PinholeRadtan, config: FrontendConfig | None = None,
                   detector: FeatureDetector | None = None) -> FeatureTracker:
    """Return the tracker that ``config.method`` names ("descriptor" or "klt"), for images of ``camera``.

    Args:
        camera: calibration of the images.
        config: front-end parameters (default ``FrontendConfig()``: SIFT, N = 60, 4 x 5 grid, two-point RANSAC).
        detector: an already created detector (e.g. a trained CNN) instead of ``config.detector_name``.

    >>> cam = PinholeRadtan.davis240c()
    >>> type(create_tracker(cam)).__name__, type(create_tracker(cam, FrontendConfig(method="klt"))).__name__
    ('DescriptorTracker', 'KltTracker')
    """
    config = FrontendConfig() if config is None else config
    if not isinstance(config, FrontendConfig):
        raise ValueError(f"config must be a FrontendConfig; got {type(config).__name__}")
    cls = DescriptorTracker if config.method == "descriptor" else KltTracker
    return cls(camera, config, detector)
