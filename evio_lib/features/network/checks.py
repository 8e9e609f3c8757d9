"""Argument checks shared by the network's modules (counts, finite numbers, image shapes, devices)."""
from __future__ import annotations

import math
from numbers import Integral, Real

import torch


def _check_count(name: str, value: object, minimum: int = 0) -> int:
    """Return ``value`` as an int >= minimum or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def _check_real(name: str, value: object, minimum: float) -> float:
    """Return ``value`` as a finite float >= minimum or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) or value < minimum:
        raise ValueError(f"{name} must be a finite number >= {minimum}; got {value!r}")
    return float(value)


def _check_image_shape(shape: object) -> tuple[int, int]:
    """Return (H, W) of positive ints or raise ValueError."""
    try:
        dims = tuple(shape)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"image_shape must be (H, W); got {shape!r}") from None
    if len(dims) != 2 or not all(isinstance(d, Integral) and not isinstance(d, bool) and d > 0 for d in dims):
        raise ValueError(f"image_shape must be (H, W) of positive integers; got {shape!r}")
    return int(dims[0]), int(dims[1])


def _check_device(device: object) -> torch.device:
    """Return a torch.device for "cpu"/"cuda"(:N), raising ValueError when CUDA is asked for but unavailable."""
    try:
        dev = torch.device(device)  # type: ignore[arg-type]
    except (RuntimeError, TypeError):
        raise ValueError(f"device must be 'cpu' or 'cuda' (or a torch.device); got {device!r}") from None
    if dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device must be 'cpu' or 'cuda'; got {device!r}")
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but CUDA is not available on this machine")
    return dev

