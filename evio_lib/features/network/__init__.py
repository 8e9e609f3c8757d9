"""SuperPoint-style CNN: network, post-processing, checkpoints, fast CPU inference and the detector wrapper.

- :mod:`~evio_lib.features.network.model`: :class:`SuperPointNet` (thesis §3.2.4, Fig. 12), its width presets and
  checkpoints (save, load, shipped weights in ``evio_lib/weights/``);
- :mod:`~evio_lib.features.network.postprocessing`: logits and descriptor maps -> keypoints, scores and unit
  descriptors (heatmap, threshold, box NMS, sub-pixel refinement, descriptor interpolation);
- :mod:`~evio_lib.features.network.inference`: the fast inference modes (BN folded, bfloat16, int8) and "auto";
- :mod:`~evio_lib.features.network.detector`: :class:`SuperPointDetector`, the network behind
  ``create_detector("superpoint")``, and the registration of every shipped checkpoint by name;
- :mod:`~evio_lib.features.network.checks`: the argument checks they share.

Every public name of these modules is importable from this package. The former module
``evio_lib.features.superpoint`` is an alias of this package, which also keeps that module's private helpers below
(the tests and benches use a few).

Reference: DeTone, Malisiewicz & Rabinovich, "SuperPoint: Self-Supervised Interest Point Detection and Description",
CVPRW 2018; thesis §3.2.4 (architecture, post-processing), §3.2.6 (NMS, best-N points).
"""
from evio_lib.features.network import detector, inference, model, postprocessing
from evio_lib.features.network.detector import *  # noqa: F401,F403
from evio_lib.features.network.inference import *  # noqa: F401,F403
from evio_lib.features.network.model import *  # noqa: F401,F403
from evio_lib.features.network.postprocessing import *  # noqa: F401,F403

# The private helpers of the former single module evio_lib.features.superpoint (an alias of this package), kept
# reachable under their old names; new code imports them from the module that defines them.
from evio_lib.features.network.checks import _check_count, _check_device, _check_image_shape, _check_real  # noqa: F401
from evio_lib.features.network.detector import _register_shipped_variants  # noqa: F401
from evio_lib.features.network.inference import (  # noqa: F401
    _auto_mode,
    _bf16_native,
    _cpu_flags,
    _FastSuperPoint,
    _int8_engine,
    _Int8SuperPoint,
    _quantization_modules,
)
from evio_lib.features.network.model import (  # noqa: F401
    _CHECKPOINT_FORMAT,
    _POOL_AFTER,
    _check_config,
    _check_input,
    _conv_block,
)
from evio_lib.features.network.postprocessing import _check_logits, _check_tensor, _nms_numpy, _nms_torch  # noqa: F401

__all__ = [*model.__all__, *postprocessing.__all__, *inference.__all__, *detector.__all__]
