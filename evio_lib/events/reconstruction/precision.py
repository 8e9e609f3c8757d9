"""The arithmetic a reconstruction network computes in, and the forward pass that gives it (torch-free to import).

``PRECISIONS`` names the choices: ``auto`` (int8 for a FireNet on an x86 CPU where the int8 path runs, else float32),
``float32``, ``bfloat16`` (autocast) and ``int8`` (:mod:`evio_lib.events.reconstruction.quantized`). The command
lines import this module for their ``--precision`` choices without loading torch; :func:`resolve_precision` and
:func:`inference_network` import the networks when called. It sits above :mod:`~evio_lib.events.reconstruction.nets`
and :mod:`~evio_lib.events.reconstruction.quantized`, which import neither it nor each other's callers.
"""
from __future__ import annotations

from typing import Any

__all__ = ["PRECISIONS", "resolve_precision", "inference_network"]

#: the arithmetic a network may compute in (``auto`` chooses)
PRECISIONS = ("auto", "float32", "bfloat16", "int8")


def resolve_precision(net: Any, precision: str = "auto") -> str:
    """Return the precision ``net`` will compute in: ``precision`` itself, or for ``"auto"`` ``"int8"`` when ``net``
    is a FireNet on the CPU and this machine runs the int8 path (PyTorch's x86 int8 convolutions, Numba's kernels:
    :func:`evio_lib.events.reconstruction.quantized.int8_unavailable`), else ``"float32"`` (a GPU, an ARM CPU, the
    E2VID-style network, no numba).

    Why int8 is the default, with its measured speed and accuracy: docs/results/reconstruction.md ("int8 and
    float32")."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if precision != "auto":
        return precision
    from evio_lib.events.reconstruction.nets import FireNet

    if type(net) is not FireNet or net.output != "sigmoid" or any(p.device.type != "cpu" for p in net.parameters()):
        return "float32"                                # (the int8 kernels fuse the sigmoid into the last layer)
    from evio_lib.events.reconstruction.quantized import int8_unavailable

    return "float32" if int8_unavailable() else "int8"


def inference_network(net: Any, precision: str = "float32", int8_ranges: dict | None = None) -> Any:
    """Return the fastest forward pass for ``net`` in ``precision`` (one of :data:`PRECISIONS`; ``auto``:
    :func:`resolve_precision`).

    float32: a :class:`FireNetInference` for a FireNet on the CPU (outputs within ~1e-6), else ``net`` itself.
    bfloat16: :class:`AutocastForward` around ``net`` (the eager network: oneDNN's bfloat16 convolutions are fastest
    in its default memory layout).
    int8: a FireNet on the CPU only, :func:`evio_lib.events.reconstruction.quantized.int8_forward` (int8
    convolutions; compiled pointwise kernels), with ``int8_ranges`` (a checkpoint's stored calibration, used when it
    matches the weights) or a calibration once per process.
    The network's own parameters and state_dict are not changed.
    """
    from evio_lib.events.reconstruction.nets import AutocastForward, FireNet, FireNetInference

    precision = resolve_precision(net, precision)
    if precision == "int8":
        from evio_lib.events.reconstruction.quantized import int8_forward

        return int8_forward(net, int8_ranges)
    if precision == "bfloat16":
        return AutocastForward(net).eval()
    if type(net) is FireNet and all(p.device.type == "cpu" for p in net.parameters()):
        return FireNetInference(net).eval()
    return net
