"""Training of the SuperPoint-style network: data, augmentation, labels, losses, metrics and the staged training.

- :mod:`~evio_lib.features.training.train`: training configs (``evio_lib/features/configs/``), the three stage types
  (MagicPoint, detector rounds, detector + descriptor), chains and the ``features-train`` command;
- :mod:`~evio_lib.features.training.options`: the options of ``features-train`` alone (no torch: fast ``--help``);
- :mod:`~evio_lib.features.training.losses`: detector cross-entropy, descriptor hinge loss, total loss;
- :mod:`~evio_lib.features.training.reprojection`: the optional reprojection loss that trains sub-pixel keypoints
  to follow the pair's homography;
- :mod:`~evio_lib.features.training.metrics`: precision and recall of detections against labels (validation);
- :mod:`~evio_lib.features.training.shapes`: Synthetic Shapes, the labelled images that bootstrap MagicPoint;
- :mod:`~evio_lib.features.training.adaptation`: homographic adaptation, which labels real images;
- :mod:`~evio_lib.features.training.datasets`: the real training images (split by source), event frames, label caches;
- :mod:`~evio_lib.features.training.augment`: photometric and homographic augmentation, keypoint <-> label maps.

Nothing is imported here (the options module must stay free of torch); import the modules.
"""
