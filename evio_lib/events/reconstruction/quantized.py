"""FireNet's forward pass with 8-bit integer convolutions (CPU inference only): ``precision="int8"``.

Every convolution but the last 1x1 runs in int8 (PyTorch's x86 quantised kernels, which use AVX-512 VNNI where the
CPU has it); the pointwise steps between them run in float32 in compiled kernels
(:mod:`evio_lib.events.reconstruction.quantized_kernels`). Affine quantisation of a tensor x with scale s and zero
point z:

    q = clamp(round(x / s) + z, 0, 255),   x^ = s (q - z),

activations per tensor in unsigned 8 bits, weights per output channel in 7 bits (q in [-63, 63], z = 0,
s_k = max |w_k| / 63) and the bias in float (PyTorch's int8 convolution folds it in). Seven-bit weights keep every pair of
products u8 x s7 below 2^15, so CPUs whose kernels add such pairs in 16 bits (AVX2 without VNNI) cannot overflow.
A convolution's int32 accumulator is requantised to its output's own scale, so every quantised activation needs a
range [lo, hi] (s = (hi - lo) / 255, z = round(-lo / s)):

- the ConvGRU states h and r . h lie in (-1, 1) by construction (h' = (1 - z) h + z tanh(.)): the fixed range
  [-1, 1]; the residual blocks read h;
- every other range is **calibrated**: the float forward pass is run over :data:`CALIBRATION_SEQUENCES` = 16
  voxel-grid sequences of the training-set generator's validation split (:func:`calibration_voxels`, fixed seed),
  and each range is the widest per-window 0.01 / 99.99 % quantile (a few hot pixels must not stretch a whole scale).
  Four sequences were used before: their ranges were narrower than those a network reaches on a long held-out
  stretch, and clipping there moved a network trained on photographs by up to 0.03 SSIM from its float32 frames
  (docs/results/reconstruction.md, "Four or 16 calibration sequences");
- the six gate inputs (``gru{1,2}_x``, ``_h``, ``_rh``: the convolutions summed inside sigmoid(.) and tanh(.)) are
  then capped at +-:data:`GATE_INPUT_CAP` = 6. Past 6 the nonlinearities are flat (1 - sigmoid(6) = 0.0025, under
  one 8-bit grey level; 1 - tanh(6) = 1e-5), so clipping there costs almost nothing, while a calibrated range of
  (-35, 30) (``gru1_x`` of one network) spends 8 bits on values that all read as 0 or 1 and rounds the informative
  ones near 0 to steps of 0.25. On validation sequences the calibration never saw, the cap brought int8 several
  times closer to float32 (docs/archive.md, "int8 FireNet without the gate-input cap"); 6 is the saturation
  argument's value, not the best of the caps tried there.

Measured on the validation stretches (``bench/reconstruction_quality.py --split val --precision int8``) and for speed
(``bench/bench_reconstruction.py``): docs/results/reconstruction.md. PyTorch marks its quantised tensors as deprecated (a
``UserWarning``); the project pins torch, and the warning is silenced inside this module only.
"""
from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch
from torch.ao.nn.intrinsic.quantized import ConvReLU2d as _QConvReLU2d
from torch.ao.nn.quantized import Conv2d as _QConv2d
from torch.nn import functional as F

from evio_lib.events.reconstruction.nets import FireNet

__all__ = ["CALIBRATION_SEQUENCES", "INT8_ENGINE", "Int8Ranges", "FireNetInt8", "calibrate_firenet",
           "calibration_voxels", "int8_forward",
           "int8_unavailable", "stored_ranges", "weights_digest"]

#: Gate inputs (summed inside sigmoid/tanh) are clipped to [-GATE_INPUT_CAP, GATE_INPUT_CAP]: see the module docstring.
GATE_INPUT_CAP = 6.0
#: How many generator sequences (40 windows of 64 x 64 each) :func:`calibration_voxels` gives a calibration.
CALIBRATION_SEQUENCES = 16

#: The calibrated tensors of :class:`FireNetInt8` (each a range [lo, hi] of float values).
RANGE_NAMES = ("voxels", "head", "gru1_x", "gru1_h", "gru1_rh", "res1_a", "res1_b", "res1_out",
               "gru2_x", "gru2_h", "gru2_rh", "res2_a", "res2_b")
_GATE_INPUTS = frozenset(name for name in RANGE_NAMES if name.startswith("gru"))  # the ranges GATE_INPUT_CAP clips
_LEVELS = 255          # activations: q in [0, 255]
_STATE_RANGE = (-1.0, 1.0)
_WEIGHT_LEVELS = 63    # weights in [-63, 63]


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """A context that hides PyTorch's deprecation warning for quantised tensors (and nothing else)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*quantize_per_tensor.*deprecated", category=UserWarning)
        yield


def _supported_engines() -> tuple[str, ...]:
    """The quantised engines of this PyTorch build (a function, so that tests can stand in another build's)."""
    return tuple(torch.backends.quantized.supported_engines)


@contextlib.contextmanager
def _engine(name: str) -> Iterator[None]:
    """A context in which PyTorch's quantised engine (a process-wide setting) is ``name``; the previous one after.
    Not thread-safe (no setting of the process is): build int8 networks from one thread at a time."""
    before = torch.backends.quantized.engine
    torch.backends.quantized.engine = name
    try:
        yield
    finally:
        torch.backends.quantized.engine = before


def _scale_zero_point(lo: float, hi: float) -> tuple[float, int]:
    """Return (s, z) of the affine 8-bit quantisation of [lo, hi] (the range is widened to hold 0 exactly)."""
    lo, hi = min(float(lo), 0.0), max(float(hi), 0.0)
    scale = max(hi - lo, 1e-8) / _LEVELS
    return scale, int(np.clip(round(-lo / scale), 0, _LEVELS))


@dataclass(frozen=True)
class Int8Ranges:
    """The calibrated float ranges, name -> (lo, hi), one per entry of :data:`RANGE_NAMES`."""

    ranges: dict

    def __post_init__(self) -> None:
        missing = [name for name in RANGE_NAMES if name not in self.ranges]
        if missing:
            raise ValueError(f"int8 ranges must give [lo, hi] for each of {RANGE_NAMES}; missing {missing}")
        for name, (lo, hi) in self.ranges.items():
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                raise ValueError(f"int8 range {name!r} must be finite with lo <= hi; got {(lo, hi)!r}")

    def scale_zero_point(self, name: str) -> tuple[float, int]:
        return _scale_zero_point(*self.ranges[name])


def _quantised_conv(conv: torch.nn.Conv2d, out_range: tuple[float, int], relu: bool = False,
                    in_columns: slice = slice(None), extra: torch.nn.Conv2d | None = None,
                    with_bias: bool = True) -> torch.nn.Module:
    """Return an int8 copy of ``conv`` (its input columns ``in_columns``; rows of ``extra`` appended; its bias only
    ``with_bias``: the GRU's h-part convolutions leave it to the x part), requantising its output to ``out_range``
    = (scale, zero point)."""
    weight = conv.weight.detach()[:, in_columns]
    bias = conv.bias.detach() if conv.bias is not None and with_bias else torch.zeros(conv.out_channels)
    if extra is not None:
        weight = torch.cat([weight, extra.weight.detach()[:, in_columns]])
        bias = torch.cat([bias, extra.bias.detach()])
    out_channels, in_channels, k = weight.shape[0], weight.shape[1], weight.shape[-1]
    module = (_QConvReLU2d if relu else _QConv2d)(in_channels, out_channels, k, padding=k // 2)
    scales = weight.abs().amax(dim=(1, 2, 3)).clamp_min(1e-12) / _WEIGHT_LEVELS
    qweight = torch.quantize_per_channel(weight.float(), scales.double(), torch.zeros(out_channels, dtype=torch.long),
                                         0, torch.qint8)
    module.set_weight_bias(qweight, bias.float())
    module.scale, module.zero_point = float(out_range[0]), int(out_range[1])
    return module


class FireNetInt8(torch.nn.Module):
    """A :class:`FireNet`'s forward pass with int8 convolutions: ``forward(voxels, state) -> (image, state)``.

    Built from a float FireNet and its calibrated :class:`Int8Ranges` (:func:`calibrate_firenet`); the FireNet is left
    untouched. The state is two float32 tensors (N, C, H, W), exchangeable with FireNet's. CPU inference only (no
    gradients); one instance per thread (it reuses internal buffers from window to window).

    Per window: the voxel grid is quantised, the head, the GRUs' and the residual blocks' convolutions run in int8,
    and the pointwise steps between them (dequantise, gates, state update, residual sum, requantise, the 1x1
    prediction and its sigmoid) are fused into six compiled kernels (:mod:`evio_lib.events.reconstruction.
    quantized_kernels`) that read and write the quantised tensors' bytes in place.
    """

    def __init__(self, net: FireNet, ranges: Int8Ranges) -> None:
        super().__init__()
        if type(net) is not FireNet:
            raise TypeError(f"FireNetInt8 needs a FireNet; got {type(net).__name__}")
        if any(p.device.type != "cpu" for p in net.parameters()):
            raise ValueError("FireNetInt8 runs on the CPU only: move the FireNet to the CPU first")
        problem = int8_unavailable()
        if problem:
            raise ValueError(f"FireNetInt8 cannot run here: {problem}")
        from evio_lib.events.reconstruction import quantized_kernels  # numba: compiled on first use, then cached

        self.kernels = quantized_kernels
        self.ranges = ranges
        sz = ranges.scale_zero_point
        self.voxel_q = sz("voxels")
        self.state_q = _scale_zero_point(*_STATE_RANGE)
        self.res1_out_q = sz("res1_out")
        with _quiet(), _engine(INT8_ENGINE):  # the packed weights keep the engine they were packed for
            self.head = _quantised_conv(net.head, sz("head"), relu=True)
            self.grus = []
            for i, cell in enumerate((net.gru1, net.gru2), start=1):
                c = cell.hidden_channels
                x_cols, h_cols = slice(0, cell.gates.in_channels - c), slice(cell.gates.in_channels - c, None)
                conv_x = _quantised_conv(cell.gates, sz(f"gru{i}_x"), in_columns=x_cols, extra=cell.candidate)
                conv_h = _quantised_conv(cell.gates, sz(f"gru{i}_h"), in_columns=h_cols, with_bias=False)
                conv_rh = _quantised_conv(cell.candidate, sz(f"gru{i}_rh"), in_columns=h_cols, with_bias=False)
                self.grus.append((c, conv_x, conv_h, conv_rh))
            self.res = [(_quantised_conv(block.conv1, sz(f"res{i}_a"), relu=True),
                         _quantised_conv(block.conv2, sz(f"res{i}_b")))
                        for i, block in enumerate((net.res1, net.res2), start=1)]
        self.pred_w = net.pred.weight.detach().reshape(-1).float().numpy().copy()
        self.pred_b = np.float32(net.pred.bias.detach()[0])
        self.num_bins = net.num_bins
        self._scratch: dict[tuple, torch.Tensor] = {}   # internal buffers, reused from window to window

    def _buffer(self, name: str, shape: tuple, scale_zero_point: tuple[float, int] | None = None) -> torch.Tensor:
        """A channels-last buffer that never leaves the module (quantised when ``scale_zero_point`` is given),
        allocated once per name and shape: fresh large arrays cost page faults on every window."""
        key = (name, tuple(shape))
        if key not in self._scratch:
            self._scratch[key] = (_empty_quantised(shape, scale_zero_point) if scale_zero_point is not None else
                                  torch.empty(tuple(shape), memory_format=torch.channels_last))
        return self._scratch[key]

    def _gru(self, i: int, xq: torch.Tensor, h: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """Return (h' float, h' quantised to the state range) of ConvGRU cell ``i``."""
        c, conv_x, conv_h, conv_rh = self.grus[i]
        k = self.kernels
        from_x = conv_x(xq)                                               # [z, r, h~] parts from x (+ biases)
        n, _, height, width = from_x.shape
        h_new = torch.empty((n, c, height, width), memory_format=torch.channels_last)
        h_new_q = self._buffer(f"h_new_q{i}", (n, c, height, width), self.state_q)
        fx = (_bytes(from_x), *_qparams(from_x))
        if h is None:                                                     # h = 0: h' = z h~
            k.gru_first(*fx, _hwc(h_new), _bytes(h_new_q), *_writes(self.state_q))
            return h_new, h_new_q
        h_q = self._buffer(f"h_q{i}", h.shape, self.state_q)
        k.quantise(_hwc(h), _bytes(h_q), *_writes(self.state_q))
        from_h = conv_h(h_q)
        z = self._buffer(f"z{i}", h.shape)
        rh_q = self._buffer(f"rh_q{i}", h.shape, self.state_q)
        k.gru_gates(*fx, _bytes(from_h), *_qparams(from_h), _hwc(h), _hwc(z), _bytes(rh_q), *_writes(self.state_q))
        from_rh = conv_rh(rh_q)
        k.gru_update(*fx, _bytes(from_rh), *_qparams(from_rh), _hwc(h), _hwc(z), _hwc(h_new), _bytes(h_new_q),
                     *_writes(self.state_q))
        return h_new, h_new_q

    def forward(self, voxels: torch.Tensor, state: list | None = None) -> tuple[torch.Tensor, list]:
        h1, h2 = state if state is not None else (None, None)
        last = torch.channels_last
        h1 = h1.detach().float().contiguous(memory_format=last) if h1 is not None else None
        h2 = h2.detach().float().contiguous(memory_format=last) if h2 is not None else None
        voxels = voxels.detach()
        k = self.kernels
        threads = torch.get_num_threads()
        k.set_threads(threads)
        torch.set_num_threads(threads)  # Numba's OpenMP start-up resets the pool size that PyTorch's kernels use
        try:
            return self._forward(voxels, h1, h2)
        finally:
            torch.set_num_threads(threads)

    def _forward(self, voxels: torch.Tensor, h1: torch.Tensor | None, h2: torch.Tensor | None
                 ) -> tuple[torch.Tensor, list]:
        last = torch.channels_last
        k = self.kernels
        with _quiet():
            v = voxels.float().contiguous(memory_format=last)
            xq = self.head(torch.quantize_per_tensor(v, *self.voxel_q, torch.quint8))
            h1, h1_q = self._gru(0, xq, h1)
            b = self.res[0][1](self.res[0][0](h1_q))                     # x = relu(h1 + conv(relu(conv(h1))))
            xq = self._buffer("res1_out", h1.shape, self.res1_out_q)
            k.residual_quantise(_bytes(b), *_qparams(b), _hwc(h1), _bytes(xq), *_writes(self.res1_out_q))
            h2, h2_q = self._gru(1, xq, h2)
            b = self.res[1][1](self.res[1][0](h2_q))
            n, _, height, width = h2.shape
            image = torch.empty((n, 1, height, width))
            k.residual_predict(_bytes(b), *_qparams(b), _hwc(h2), self.pred_w, self.pred_b,
                               image.numpy().reshape(n * height, width))
        return image, [h1, h2]


def _empty_quantised(shape: tuple, scale_zero_point: tuple[float, int]) -> torch.Tensor:
    return torch._empty_affine_quantized(tuple(shape), scale=scale_zero_point[0], zero_point=scale_zero_point[1],
                                         dtype=torch.quint8, memory_format=torch.channels_last)


def _qparams(q: torch.Tensor) -> tuple[np.float32, np.float32]:
    """(s, z) of a quantised tensor, as the kernels read them (float32)."""
    return np.float32(q.q_scale()), np.float32(q.q_zero_point())


def _writes(scale_zero_point: tuple[float, int]) -> tuple[np.float32, np.float32]:
    """(1 / s, z + 1/2), as the kernels write a quantised tensor (float32)."""
    return np.float32(1.0 / scale_zero_point[0]), np.float32(scale_zero_point[1] + 0.5)


def _bytes(q: torch.Tensor) -> np.ndarray:
    """The (N H, W, C) uint8 bytes of a channels-last quantised tensor, without a copy (writes go to the tensor)."""
    if not q.is_contiguous(memory_format=torch.channels_last):
        raise ValueError("expected a channels-last quantised tensor")
    raw = torch.empty(0, dtype=torch.uint8)
    raw.set_(q.untyped_storage(), q.storage_offset(), q.size(), q.stride())
    n, c, h, w = q.shape
    return raw.permute(0, 2, 3, 1).numpy().reshape(n * h, w, c)


def _hwc(x: torch.Tensor) -> np.ndarray:
    """The (N H, W, C) float32 view of a channels-last tensor (no copy)."""
    n, c, h, w = x.shape
    return x.permute(0, 2, 3, 1).numpy().reshape(n * h, w, c)


# --------------------------------------------------------------------------------------------------- calibration
class _RangeRecorder:
    """Keeps, per name, the widest per-window 0.01 / 99.99 % quantiles seen."""

    def __init__(self) -> None:
        self.ranges: dict[str, tuple[float, float]] = {}

    def __call__(self, name: str, x: torch.Tensor) -> torch.Tensor:
        values = x.detach().float().reshape(-1).numpy()
        values = values[:: values.size // 50_000 + 1]     # a strided sample: the quantiles agree within ~1e-3 of range
        k = max(int(1e-4 * values.size), 0)
        part = np.partition(values, (k, values.size - 1 - k))
        lo, hi = float(part[k]), float(part[values.size - 1 - k])
        old = self.ranges.get(name, (lo, hi))
        self.ranges[name] = (min(lo, old[0]), max(hi, old[1]))
        return x


def _float_forward_recording(net: FireNet, voxels: torch.Tensor, state: list | None, record: _RangeRecorder
                             ) -> tuple[torch.Tensor, list]:
    """FireNet's float forward pass, recording every tensor that :class:`FireNetInt8` quantises."""
    h1, h2 = state if state is not None else (None, None)
    record("voxels", voxels)
    x = record("head", F.relu(net.head(voxels)))
    hs = []
    for i, (cell, res, h) in enumerate(((net.gru1, net.res1, h1), (net.gru2, net.res2, h2)), start=1):
        c = cell.hidden_channels
        x_cols = slice(0, cell.gates.in_channels - c)
        from_x = record(f"gru{i}_x", F.conv2d(x, torch.cat([cell.gates.weight[:, x_cols], cell.candidate.weight[:, x_cols]]),
                                              torch.cat([cell.gates.bias, cell.candidate.bias]), padding=1))
        if h is None:
            h = torch.zeros_like(from_x[:, :c])
        h_cols = slice(cell.gates.in_channels - c, None)
        zr = torch.sigmoid(from_x[:, :2 * c] + record(f"gru{i}_h", F.conv2d(h, cell.gates.weight[:, h_cols], padding=1)))
        z, r = zr[:, :c], zr[:, c:]
        h_tilde = torch.tanh(from_x[:, 2 * c:] + record(f"gru{i}_rh", F.conv2d(r * h, cell.candidate.weight[:, h_cols],
                                                                                padding=1)))
        h = (1 - z) * h + z * h_tilde
        hs.append(h)
        a = record(f"res{i}_a", F.relu(res.conv1(h)))
        x = F.relu(h + record(f"res{i}_b", res.conv2(a)))
        if i == 1:
            record("res1_out", x)
    return torch.sigmoid(net.pred(x)), hs


def calibration_voxels(sequences: int = CALIBRATION_SEQUENCES, seed: int = 0) -> list[np.ndarray]:
    """Return ``sequences`` voxel-grid sequences (each (40, 5, 64, 64) float32) of the training-set generator's
    validation split, seed ``seed``: the calibration data of :func:`calibrate_firenet` (0.5-2 s of CPU each; since
    generator version 3 they hold windows of the n drawn, and the ranges they give differ from version 2's)."""
    from evio_lib.events.reconstruction.training_set import TrainingSetConfig, make_sequence

    rng = np.random.default_rng(seed)
    return [make_sequence(rng, "val", TrainingSetConfig())[0]["voxels"].astype(np.float32) for _ in range(sequences)]


def calibrate_firenet(net: FireNet, voxel_sequences: list[np.ndarray]) -> Int8Ranges:
    """Return the :class:`Int8Ranges` of ``net`` over ``voxel_sequences`` (each (L, B, H, W), the state carried
    through each sequence from zero, as in use)."""
    if not voxel_sequences:
        raise ValueError("calibrate_firenet needs at least one voxel-grid sequence")
    record = _RangeRecorder()
    with torch.inference_mode():
        for sequence in voxel_sequences:
            sequence = np.asarray(sequence, np.float32)
            if sequence.ndim != 4 or sequence.shape[1] != net.num_bins:
                raise ValueError(f"each calibration sequence must be (L, {net.num_bins}, H, W); got {sequence.shape}")
            state = None
            for window in torch.from_numpy(sequence):
                _, state = _float_forward_recording(net, window[None], state, record)
    return _with_gate_inputs_capped(record.ranges)


def _with_gate_inputs_capped(ranges: dict) -> Int8Ranges:
    """Return ``ranges`` (name -> (lo, hi)) as :class:`Int8Ranges`, the gate inputs clipped to +-GATE_INPUT_CAP: for a
    calibration, and for ranges stored in a checkpoint before the cap existed. Both ends are clipped into
    [-cap, cap], so a range lying wholly beyond the cap, e.g. (7, 9), becomes (cap, cap), which the quantiser widens
    to [0, cap] (every range holds 0), instead of an inverted (7, cap)."""
    def capped(lo: float, hi: float) -> tuple[float, float]:
        return min(max(lo, -GATE_INPUT_CAP), GATE_INPUT_CAP), max(min(hi, GATE_INPUT_CAP), -GATE_INPUT_CAP)

    return Int8Ranges({name: capped(lo, hi) if name in _GATE_INPUTS else (lo, hi) for name, (lo, hi) in ranges.items()})


_CALIBRATED: dict[str, Int8Ranges] = {}  # weights' digest -> ranges: one calibration per network and process


def weights_digest(net: torch.nn.Module) -> str:
    """SHA-1 of a network's parameters and buffers (what int8 ranges are calibrated for)."""
    import hashlib

    return hashlib.sha1(b"".join(t.detach().cpu().numpy().tobytes() for t in net.state_dict().values())).hexdigest()


def stored_ranges(net: FireNet) -> dict:
    """Return ``{"weights_sha1", "ranges"}`` of ``net``, calibrated on :func:`calibration_voxels`: what a shipped
    checkpoint stores under ``int8_ranges`` (tools/ship_reconstructor.py) so that loading skips the calibration."""
    ranges = calibrate_firenet(net, calibration_voxels())
    return {"weights_sha1": weights_digest(net), "ranges": {k: [float(lo), float(hi)] for k, (lo, hi) in
                                                              ranges.ranges.items()}}


#: PyTorch's quantised engine :class:`FireNetInt8` packs its convolutions for (x86 CPUs: FBGEMM, VNNI where present).
INT8_ENGINE = "x86"


def int8_unavailable() -> str:
    """Return why this machine cannot run :class:`FireNetInt8`, or "" when it can: this PyTorch build must offer the
    x86 quantised engine (not e.g. an ARM build with qnnpack only, which the int8 path was never measured on) and the
    compiled kernels must load (numba installed, a writable cache for their machine code). The engine selected at the
    moment does not matter (the SuperPoint int8 path selects onednn): FireNetInt8 packs its weights for x86."""
    engines = _supported_engines()
    if INT8_ENGINE not in engines:
        return f"this PyTorch build has no {INT8_ENGINE!r} quantised engine (it has {engines})"
    try:
        from evio_lib.events.reconstruction import quantized_kernels  # noqa: F401
    except ImportError as error:
        return f"the numba package does not import ({error})"
    except Exception as error:  # e.g. numba's RuntimeError "cannot cache function ...: no locator available"
        return (f"the compiled kernels cannot load ({type(error).__name__}: {error}); set NUMBA_CACHE_DIR to a "
                f"writable folder")
    return ""


def int8_forward(net: FireNet, stored: dict | None = None) -> FireNetInt8:
    """Return the int8 forward pass of ``net``.

    Its ranges come from ``stored`` (a checkpoint's ``int8_ranges``, :func:`stored_ranges`) when they were calibrated
    for exactly these weights (same SHA-1), else from a calibration on :func:`calibration_voxels`
    (:data:`CALIBRATION_SEQUENCES` sequences simulated, then their float windows at 64 x 64; its time:
    docs/results/reconstruction.md#int8-and-float32), done once per set of weights and process. Raises ValueError
    for anything but a FireNet on the CPU, and where the compiled kernels cannot load (no numba, or no writable cache
    for its machine code)."""
    if type(net) is not FireNet or any(p.device.type != "cpu" for p in net.parameters()):
        where = next(net.parameters()).device.type
        raise ValueError(f"precision int8 runs a FireNet on the CPU only; got a {type(net).__name__} on {where}")
    if net.output != "sigmoid":
        raise ValueError(f"precision int8 runs a FireNet that ends in a sigmoid; this one's output is {net.output!r} "
                         f"(published weights): use float32")
    problem = int8_unavailable()
    if problem:
        raise ValueError(f"precision int8 cannot run here: {problem}; use float32")
    digest = weights_digest(net)
    if stored is not None and stored.get("weights_sha1") == digest:
        ranges = _with_gate_inputs_capped({k: tuple(v) for k, v in stored["ranges"].items()})
    else:
        if digest not in _CALIBRATED:
            _CALIBRATED[digest] = calibrate_firenet(net, calibration_voxels())
        ranges = _CALIBRATED[digest]
    return FireNetInt8(net, ranges).eval()
