"""Evaluation of detectors and descriptors: the metrics, image pairs with known homographies and the benchmark.

- :mod:`~evio_lib.features.evaluation.evaluate`: repeatability, localisation error, homography correctness,
  matching score, mean average precision, descriptor matching;
- :mod:`~evio_lib.features.evaluation.hpatches`: image pairs related by a known homography and the HPatches loader;
- :mod:`~evio_lib.features.evaluation.benchmark`: the benchmark of thesis §3.2.6 (Tables 2-5): data sets, the run,
  the tables and the ``features-benchmark`` command;
- :mod:`~evio_lib.features.evaluation.photos`: the benchmark's pairs of held-out natural photographs
  (``--dataset photos``);
- :mod:`~evio_lib.features.evaluation.options`: the options of ``features-benchmark`` alone (fast ``--help``).

Nothing is imported here (the options module must stay free of OpenCV and torch); import the modules.
"""
