"""Compiled pointwise kernels of :class:`evio_lib.events.reconstruction.quantized.FireNetInt8` (Numba).

Between its int8 convolutions, FireNet's forward pass is pointwise: dequantise, add, sigmoid/tanh, the ConvGRU's
state update, the residual sum and its ReLU, requantise, and the final 1x1 prediction. As separate PyTorch calls these
took longer than the int8 convolutions themselves (docs/archive.md, "int8 pointwise steps"; mostly passes over channel
slices of channels-last tensors); here each step is one pass over the pixels, in parallel over image rows.

Every array is (R, W, C): the rows of all images, the columns, the channels (a channels-last tensor's memory).
Quantised inputs arrive as their uint8 bytes with their (scale s, zero point z): x = s (q - z). Quantised outputs are
written as q = clamp(floor(x / s + z + 1/2), 0, 255), given (1 / s, z + 1/2). Every scalar is float32 (a float64 one
would make LLVM compute the whole loop in float64, at half the vector width).

ConvGRU, with a_* the convolutions' outputs (x part: [z, r, h~] with the biases; h part: [z, r]; the r . h part):
    z = sigmoid(a_x,z + a_h,z),  r = sigmoid(a_x,r + a_h,r),  h~ = tanh(a_x,h~ + a_rh),  h' = h + z (h~ - h)
and with h = 0 (a sequence's first window): h' = sigmoid(a_x,z) tanh(a_x,h~).
"""
from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

__all__ = ["set_threads", "quantise", "gru_first", "gru_gates", "gru_update", "residual_quantise",
           "residual_predict"]


def set_threads(threads: int) -> None:
    """Run the kernels on ``threads`` threads (at most Numba's pool size)."""
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))


# tanh(x) ~ x P(x^2) / Q(x^2) for |x| <= 7.9053 (clamped beyond, where tanh is 1 to float32 precision): the
# rational minimax approximation Eigen uses for float32 (its published coefficients), within about 2 float32 ulps.
# Unlike math.tanh and math.exp, it is only multiply-adds and one division, so LLVM vectorises the loops.
_F = np.float32
_TANH_CLAMP = _F(7.90531110763549805)
_A1, _A3, _A5 = _F(4.89352455891786e-03), _F(6.37261928875436e-04), _F(1.48572235717979e-05)
_A7, _A9 = _F(5.12229709037114e-08), _F(-8.60467152213735e-11)
_A11, _A13 = _F(2.00018790482477e-13), _F(-2.76076847742355e-16)
_B0, _B2 = _F(4.89352518554385e-03), _F(2.26843463243900e-03)
_B4, _B6 = _F(1.18534705686654e-04), _F(1.19825839466702e-06)
_HALF, _ZERO, _TOP = _F(0.5), _F(0.0), _F(255.0)


@njit(cache=True, inline="always", fastmath=True)
def _tanh(x):  # type: ignore[no-untyped-def]
    x = min(max(x, -_TANH_CLAMP), _TANH_CLAMP)
    x2 = x * x
    p = x * (_A1 + x2 * (_A3 + x2 * (_A5 + x2 * (_A7 + x2 * (_A9 + x2 * (_A11 + x2 * _A13))))))
    return p / (_B0 + x2 * (_B2 + x2 * (_B4 + x2 * _B6)))


@njit(cache=True, inline="always", fastmath=True)
def _sigmoid(x):  # type: ignore[no-untyped-def]
    return _HALF + _HALF * _tanh(_HALF * x)                 # sigmoid(x) = (1 + tanh(x / 2)) / 2


@njit(cache=True, inline="always", fastmath=True)
def _q(x, inv_scale, zero_half):  # type: ignore[no-untyped-def]
    """q(x) with inv_scale = 1 / s and zero_half = z + 1/2 (float32; truncation of a value >= 0 is its floor)."""
    return np.uint8(min(max(x * inv_scale + zero_half, _ZERO), _TOP))


@njit(cache=True, parallel=True, fastmath=True)
def quantise(x, out, inv_scale, zero_half):  # type: ignore[no-untyped-def]
    """out = q(x)."""
    rows, cols, chans = x.shape
    for i in prange(rows):
        for j in range(cols):
            for c in range(chans):
                out[i, j, c] = _q(x[i, j, c], inv_scale, zero_half)


@njit(cache=True, parallel=True, fastmath=True)
def gru_first(ax, sx, zx, h_out, hq_out, inv_state, zh_state):  # type: ignore[no-untyped-def]
    """h' = sigmoid(a_x,z) tanh(a_x,h~) (h = 0); h' and q(h') written."""
    rows, cols, chans = h_out.shape
    for i in prange(rows):
        for j in range(cols):
            for c in range(chans):
                z = _sigmoid(sx * (_F(ax[i, j, c]) - zx))
                h = z * _tanh(sx * (_F(ax[i, j, 2 * chans + c]) - zx))
                h_out[i, j, c] = h
                hq_out[i, j, c] = _q(h, inv_state, zh_state)


@njit(cache=True, parallel=True, fastmath=True)
def gru_gates(ax, sx, zx, ah, sh, zh, h, z_out, rhq_out, inv_state, zh_state):  # type: ignore[no-untyped-def]
    """z and q(r . h) written."""
    rows, cols, chans = h.shape
    for i in prange(rows):
        for j in range(cols):
            for c in range(chans):
                z = _sigmoid(sx * (_F(ax[i, j, c]) - zx) + sh * (_F(ah[i, j, c]) - zh))
                r = _sigmoid(sx * (_F(ax[i, j, chans + c]) - zx) + sh * (_F(ah[i, j, chans + c]) - zh))
                z_out[i, j, c] = z
                rhq_out[i, j, c] = _q(r * h[i, j, c], inv_state, zh_state)


@njit(cache=True, parallel=True, fastmath=True)
def gru_update(ax, sx, zx, arh, srh, zrh, h, z, h_out, hq_out, inv_state, zh_state):  # type: ignore[no-untyped-def]
    """h' = h + z (tanh(a_x,h~ + a_rh) - h); h' and q(h') written."""
    rows, cols, chans = h.shape
    for i in prange(rows):
        for j in range(cols):
            for c in range(chans):
                h_tilde = _tanh(sx * (_F(ax[i, j, 2 * chans + c]) - zx) + srh * (_F(arh[i, j, c]) - zrh))
                hn = h[i, j, c] + z[i, j, c] * (h_tilde - h[i, j, c])
                h_out[i, j, c] = hn
                hq_out[i, j, c] = _q(hn, inv_state, zh_state)


@njit(cache=True, parallel=True, fastmath=True)
def residual_quantise(ab, sb, zb, h, xq_out, inv_out, zh_out):  # type: ignore[no-untyped-def]
    """q(relu(h + a_b)) written (the first residual block's output, the second GRU's input)."""
    rows, cols, chans = h.shape
    for i in prange(rows):
        for j in range(cols):
            for c in range(chans):
                x = max(h[i, j, c] + sb * (_F(ab[i, j, c]) - zb), _ZERO)
                xq_out[i, j, c] = _q(x, inv_out, zh_out)


@njit(cache=True, parallel=True, fastmath=True)
def residual_predict(ab, sb, zb, h, weight, bias, image_out):  # type: ignore[no-untyped-def]
    """image = sigmoid(bias + sum_c weight_c relu(h + a_b)_c): the second residual block and the 1x1 prediction."""
    rows, cols, chans = h.shape
    for i in prange(rows):
        for j in range(cols):
            acc = bias
            for c in range(chans):
                acc += weight[c] * max(h[i, j, c] + sb * (_F(ab[i, j, c]) - zb), _ZERO)
            image_out[i, j] = _sigmoid(acc)
