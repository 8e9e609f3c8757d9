"""Features: one interface (``create_detector(name).detect_and_describe(image)``) for classical and learned detectors.

>>> from evio_lib.features import create_detector
>>> create_detector("fast").name
'fast'
"""
from evio_lib.features.base import Features, available_detectors, create_detector

__all__ = ["Features", "available_detectors", "create_detector"]
