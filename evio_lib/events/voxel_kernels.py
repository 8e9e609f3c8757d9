"""Numba kernels of the voxel grid's normalisation (:func:`evio_lib.events.representations.normalize_voxel_grid`).

E2VID's normalisation shifts and scales the non-zero voxels of a window's grid to zero mean and unit standard
deviation, v <- (v - mu) / sigma over the set {v != 0}, and leaves the zeros alone. In NumPy the two boolean-mask
passes (``grid[grid != 0]`` to gather the non-zero values, ``grid[mask] = ...`` to write them back) take most of the
time a 240 x 180 x 5 grid of 0.35 H W events takes (measured:
docs/results/speed.md#small-costs-behind-the-codes-choices): boolean indexing over a sparse random mask branches on
every element. Here each is one plain loop over the grid.

The numbers are the NumPy path's bit for bit: the non-zero values are gathered in the same (C) order, their mean and
standard deviation are still computed by NumPy (:func:`evio_lib.events.representations._normalize_in_place`), and the
kernel writes (v - mu) / sigma with float32 mu and sigma in float32, as NumPy's ``(values - mean) / std`` does (no
``fastmath``, so the subtraction and the division are not reassociated).

Numba compiles each kernel on first use and caches the machine code (``cache=True``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["nonzero_values", "write_normalized"]


@njit(cache=True)
def nonzero_values(flat, count):  # type: ignore[no-untyped-def]
    """Return the first ``count`` non-zero entries of the 1-D float32 array ``flat``, in order (``flat[flat != 0]``
    when ``count = np.count_nonzero(flat)``, which uses the same test: NaN counts, -0.0 does not)."""
    out = np.empty(count + 1, np.float32)   # one spare slot: every entry is written, only non-zero ones advance k
    k = 0
    for i in range(flat.size):
        v = flat[i]
        out[k] = v
        k = min(k + (v != 0), count)         # no branch (the mask is sparse and random); never past the spare slot
    return out[:count]


@njit(cache=True)
def write_normalized(flat, mean, std, scale):  # type: ignore[no-untyped-def]
    """In place: every non-zero v of the 1-D float32 ``flat`` becomes (v - mean) / std if ``scale``, else v - mean
    (``mean``, ``std``: float32)."""
    if scale:
        for i in range(flat.size):
            v = flat[i]
            flat[i] = (v - mean) / std if v != 0 else v   # a select, not a branch: the loop vectorises
    else:
        for i in range(flat.size):
            v = flat[i]
            flat[i] = v - mean if v != 0 else v
