"""Numba kernels of the scene renderer's float32 intensity path: the same numbers as the NumPy path, faster.

:meth:`evio_lib.sim.scene.Scene.render_intensity` is called hundreds of times per simulated second for the events and
several times per APS frame for the motion blur, so it is the simulator's hot loop. The NumPy path evaluates, per
plane and then per pixel, the steps of the module docstring of :mod:`evio_lib.sim.scene`, each step a pass over whole
arrays (most of its time in ``np.take`` gathers and temporaries; both paths' times per render:
docs/results/speed.md#the-simulator). These kernels do the same arithmetic one pixel at a time, in the same float32
operations and the same order, so the result is bit-identical (tested on random poses of both presets and on whole
simulated recordings):

1. :func:`visible_slots` -- the z-buffer. For each plane ``k`` and each pixel of its culling box, with
   ``(W, S, T) = (a x + b y) + c`` per form (float32), ``key = bits(copysign(W, min(S, T, W - S, W - T)))``,
   low bits replaced by ``k + 1``; the pixel keeps the largest key, then its low bits are the plane's slot.
2. :func:`shade_slots` -- ``lambda W``, ``lambda span_u S``, ``lambda span_v T`` from the slot's pre-scaled forms,
   misses (``W <= 0``) to the background, then ``col = clip(span_u S / W)``, ``row = clip(span_v T / W)``.
3. ``lod = max(footprint - 2 log2 W, 0)`` is computed by NumPy between the kernels: NumPy's float32 ``log2`` and
   LLVM's differ in the last bit for some inputs (docs/results/speed.md#the-compiled-renderer), and the level of
   detail must be NumPy's.
4. :func:`sample_atlas` -- the trilinear mip-map lookup of ``_TextureAtlas.sample``: wrap, clamp the level,
   bilinear in levels ``floor(lod)`` and ``floor(lod) + 1`` (texel coordinate ``(c + 1/2) 2^-L - 1/2``), blend.

Numba compiles the kernels on first use and caches the machine code (``cache=True``) beside this file, else in its
user cache folder or ``NUMBA_CACHE_DIR``; a later process's first render then loads that code instead of compiling
(both times: docs/results/speed.md#small-costs-behind-the-codes-choices). ``Scene`` falls back to the NumPy path when
Numba is missing or when ``EVIO_RENDERER=numpy`` is set (:func:`evio_lib.sim.scene.renderer_backend`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["visible_slots", "shade_slots", "sample_atlas"]


@njit(cache=True, nogil=True, inline="always")
def _minimum(a, b):  # type: ignore[no-untyped-def]
    """``np.minimum(a, b)`` for two scalars: NaN if either is NaN, else ``a`` if ``a < b``, else ``b`` (so a tie of
    +0 and -0 gives ``b``, as NumPy does; Python's ``min`` gives ``a``, which flips the z-buffer's sign test)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a < b else b


@njit(cache=True, nogil=True, inline="always")
def _maximum(a, b):  # type: ignore[no-untyped-def]
    """``np.maximum(a, b)`` for two scalars, with NumPy's rule for NaN and ties (see :func:`_minimum`)."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a > b else b


@njit(cache=True, nogil=True)
def visible_slots(x: np.ndarray, y: np.ndarray, boxes: np.ndarray, forms: np.ndarray, index_bits: int
                  ) -> np.ndarray:
    """Return the (H, W) int32 slot of the nearest plane per pixel (0 = nothing, k + 1 = plane k).

    Args:
        x, y: (H, W) float32 normalised ray coordinates.
        boxes: (B, 5) int64 rows ``(plane, r0, r1, c0, c1)``: the planes that may be seen and their pixel boxes.
        forms: (P, 9) float32 forms ``W, S, T`` of every plane, three coefficients each (``a x + b y + c``).
        index_bits: bits of the key that hold the slot.
    """
    height, width = x.shape
    keys = np.zeros((height, width), dtype=np.int32)
    mask = np.int32((1 << index_bits) - 1)
    clear = np.int32(~mask)
    bits = np.zeros(1, dtype=np.float32)
    bits_int = bits.view(np.int32)
    for b in range(boxes.shape[0]):
        k, r0, r1, c0, c1 = boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3], boxes[b, 4]
        wa, wb, wc = forms[k, 0], forms[k, 1], forms[k, 2]
        sa, sb, sc = forms[k, 3], forms[k, 4], forms[k, 5]
        ta, tb, tc = forms[k, 6], forms[k, 7], forms[k, 8]
        tag = np.int32(k + 1)
        for r in range(r0, r1):
            for c in range(c0, c1):
                xv, yv = x[r, c], y[r, c]
                w = xv * wa + yv * wb + wc
                s = xv * sa + yv * sb + sc
                t = xv * ta + yv * tb + tc
                edge = _minimum(s, t)
                edge = _minimum(edge, w - s)
                edge = _minimum(edge, w - t)
                bits[0] = math.copysign(w, edge)
                key = (bits_int[0] & clear) | tag
                if key > keys[r, c]:
                    keys[r, c] = key
    for r in range(height):
        for c in range(width):
            keys[r, c] &= mask
    return keys


@njit(cache=True, nogil=True)
def shade_slots(x: np.ndarray, y: np.ndarray, slot: np.ndarray, columns: np.ndarray, spans: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return (lambda W, col, row, slot) per pixel, misses (``lambda W <= 0``) turned into the background.

    Args:
        x, y: (H, W) float32 ray coordinates; slot: (H, W) int32 from :func:`visible_slots`.
        columns: (9, n_slots) float32 pre-scaled forms (``Scene._shade``); spans: (n_slots, 2) float32 texel spans.
    """
    height, width = x.shape
    w_out = np.empty((height, width), dtype=np.float32)
    col_out = np.empty((height, width), dtype=np.float32)
    row_out = np.empty((height, width), dtype=np.float32)
    slot_out = np.empty((height, width), dtype=np.int64)
    one, zero = np.float32(1.0), np.float32(0.0)
    for r in range(height):
        for c in range(width):
            k = slot[r, c]
            xv, yv = x[r, c], y[r, c]
            w = columns[0, k] * xv + columns[1, k] * yv + columns[2, k]
            col_w = columns[3, k] * xv + columns[4, k] * yv + columns[5, k]
            row_w = columns[6, k] * xv + columns[7, k] * yv + columns[8, k]
            if w <= zero:
                k, w, col_w, row_w = 0, one, zero, zero
            inv_w = one / w
            col = _minimum(_maximum(col_w * inv_w, zero), spans[k, 0])
            row = _minimum(_maximum(row_w * inv_w, zero), spans[k, 1])
            w_out[r, c], col_out[r, c], row_out[r, c], slot_out[r, c] = w, col, row, k
    return w_out, col_out, row_out, slot_out


@njit(cache=True, nogil=True)
def sample_atlas(slot: np.ndarray, col: np.ndarray, row: np.ndarray, lod: np.ndarray, data: np.ndarray,
                 base: np.ndarray, n_levels: int, stride: int, period_u: np.ndarray, period_v: np.ndarray,
                 max_level: np.ndarray, any_wrap: bool) -> np.ndarray:
    """Return the (H, W) float32 trilinear samples of ``_TextureAtlas.sample`` (same arguments, float32 arrays).

    ``period_u, period_v, max_level``: (n_slots,) float32; ``base``: (n_slots n_levels,) int64 flat offsets.
    """
    height, width = col.shape
    out = np.empty((height, width), dtype=np.float32)
    one, half = np.float32(1.0), np.float32(0.5)
    scales = np.empty(64, dtype=np.float32)  # 0.5^L, exact (np.exp2 of a whole number)
    for level in range(64):
        scales[level] = np.float32(math.ldexp(1.0, -level))
    for r in range(height):
        for c in range(width):
            k = slot[r, c]
            cv, rv = col[r, c], row[r, c]
            if any_wrap:  # c = c - floor(c / P) P  (P = 1e30 leaves a clamped axis unchanged)
                pu, pv = period_u[k], period_v[k]
                cv = cv - np.floor(cv / pu) * pu
                rv = rv - np.floor(rv / pv) * pv
            top_level = max_level[k]
            level_of_detail = _minimum(lod[r, c], top_level)
            level0 = np.floor(level_of_detail)
            blend = level_of_detail - level0  # trilinear weight of the coarser level
            level1 = _minimum(level0 + one, top_level)
            first_level = k * n_levels
            value0 = _bilinear(data, base[first_level + np.int64(level0)], stride, scales[np.int64(level0)], cv, rv)
            value1 = _bilinear(data, base[first_level + np.int64(level1)], stride, scales[np.int64(level1)], cv, rv)
            out[r, c] = value0 + blend * (value1 - value0)
    return out


@njit(cache=True, nogil=True, inline="always")
def _bilinear(data: np.ndarray, start: int, stride: int, scale: np.float32, col: np.float32, row: np.float32
              ) -> np.float32:
    """Return the bilinear sample of the level that starts at flat index ``start``; c_L = (c + 1/2) 0.5^L - 1/2."""
    half = np.float32(0.5)
    cl = (col + half) * scale - half
    rl = (row + half) * scale - half
    c0 = np.floor(cl)
    r0 = np.floor(rl)
    fc, fr = cl - c0, rl - r0
    index = start + (np.int64(r0) * stride + np.int64(c0))
    top_left, top_right = data[index], data[index + 1]
    bottom_left, bottom_right = data[index + stride], data[index + stride + 1]
    top = top_left + fc * (top_right - top_left)  # lerp along columns, then rows
    bottom = bottom_left + fc * (bottom_right - bottom_left)
    return top + fr * (bottom - top)
