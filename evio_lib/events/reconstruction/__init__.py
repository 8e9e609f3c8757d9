"""Learned event-to-image reconstruction: networks, training data, training, evaluation and the ``reconstruct`` command.

- :mod:`~evio_lib.events.reconstruction.nets`: FireNet and the E2VID-style recurrent UNet;
- :mod:`~evio_lib.events.reconstruction.quantized`: FireNet with int8 convolutions (``precision="int8"``), its
  calibration, and its compiled pointwise kernels (:mod:`~evio_lib.events.reconstruction.quantized_kernels`);
- :mod:`~evio_lib.events.reconstruction.data`: short simulated planar samples (quick tests and the lesson);
- :mod:`~evio_lib.events.reconstruction.training_set`: the training-set generator (many independent sequences, one
  file each, made in parallel and resumable);
- :mod:`~evio_lib.events.reconstruction.training`: losses and the training loop (``reconstruct-train``);
- :mod:`~evio_lib.events.reconstruction.evaluation`: the held-out stretches and their scores;
- :mod:`~evio_lib.events.reconstruction.command`: the ``reconstruct`` command.

The reconstructors themselves (``create_reconstructor``) live in :mod:`evio_lib.events.reconstruct`.
"""
