"""SuperPoint-style CNN: network, post-processing, checkpoints, fast CPU inference and the detector wrapper.

- :mod:`~evio_lib.features.network.model`: :class:`SuperPointNet` (thesis §3.2.4, Fig. 12), its width presets and
  checkpoints (save, load, shipped weights in ``evio_lib/weights/``);
- :mod:`~evio_lib.features.network.postprocessing`: logits and descriptor maps -> keypoints, scores and unit
  descriptors (heatmap, threshold, box NMS, sub-pixel refinement, descriptor interpolation);
- :mod:`~evio_lib.features.network.inference`: the fast inference modes (BN folded, bfloat16, int8) and "auto";
- :mod:`~evio_lib.features.network.pyramid`: multi-scale inference (the levels of an image pyramid, merged);
- :mod:`~evio_lib.features.network.detector`: :class:`SuperPointDetector`, the network behind
  ``create_detector("superpoint")``, and the registration of every shipped checkpoint by name;
- :mod:`~evio_lib.features.network.checks`: the argument checks they share.

Every public name of these modules is importable from this package; private helpers are imported from the module
that defines them.

Reference: DeTone, Malisiewicz & Rabinovich, "SuperPoint: Self-Supervised Interest Point Detection and Description",
CVPRW 2018; thesis §3.2.4 (architecture, post-processing), §3.2.6 (NMS, best-N points).
"""
from evio_lib.features.network import detector, inference, model, postprocessing, pyramid
from evio_lib.features.network.detector import *  # noqa: F401,F403
from evio_lib.features.network.inference import *  # noqa: F401,F403
from evio_lib.features.network.model import *  # noqa: F401,F403
from evio_lib.features.network.postprocessing import *  # noqa: F401,F403
from evio_lib.features.network.pyramid import *  # noqa: F401,F403

__all__ = [*model.__all__, *postprocessing.__all__, *inference.__all__, *pyramid.__all__, *detector.__all__]
