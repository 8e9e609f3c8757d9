"""Features: one interface (``create_detector(name).detect_and_describe(image)``) for classical and learned detectors.

>>> from evio_lib.features import create_detector
>>> create_detector("fast").name
'fast'

Every name of ``available_detectors()`` constructs with no options; "superpoint" is the best shipped network
(``SUPERPOINT_DEFAULT_WEIGHTS``).
"""
from evio_lib.features.base import SUPERPOINT_DEFAULT_WEIGHTS, Features, available_detectors, create_detector

__all__ = ["Features", "available_detectors", "create_detector", "SUPERPOINT_DEFAULT_WEIGHTS"]
