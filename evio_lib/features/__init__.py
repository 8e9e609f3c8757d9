"""Features: one interface (``create_detector(name).detect_and_describe(image)``) for classical and learned detectors.

>>> from evio_lib.features import create_detector
>>> create_detector("fast").name
'fast'

Every name of ``available_detectors()`` constructs with no options; "superpoint" is the best shipped network
(``SUPERPOINT_DEFAULT_WEIGHTS``).

Layout:

- :mod:`~evio_lib.features.base`: the ``Features`` record, ``FeatureDetector``, the name registry, box NMS;
- :mod:`~evio_lib.features.classical`: the OpenCV detectors (Harris, Shi-Tomasi, FAST, SIFT, ORB, FAST + FREAK);
- :mod:`evio_lib.features.network`: the SuperPoint-style CNN (model and checkpoints, post-processing, fast
  inference, the detector);
- :mod:`evio_lib.features.training`: its training data, augmentation, losses and staged training
  (``features-train``; configs in ``evio_lib/features/configs/``);
- :mod:`evio_lib.features.evaluation`: detector and descriptor metrics and the benchmark (``features-benchmark``).
"""
from evio_lib.lazy_exports import lazy_exports

__all__ = ["Features", "available_detectors", "create_detector", "SUPERPOINT_DEFAULT_WEIGHTS"]
# imported on first use: the command-line options modules of this package must not pull in OpenCV
__getattr__, __dir__ = lazy_exports(__name__, {name: "base" for name in __all__}, globals())
