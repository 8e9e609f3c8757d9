"""Fast inference of the network (:func:`inference_model`): BN folding, bfloat16, int8 quantisation, "auto" choice.

Modes: "eager" (the model as trained, fp32), "fused" (BN folded, channels-last, fp32), "bf16" (fused, bfloat16
autocast, final 1x1 layers in fp32) and "int8" (fused, static int8 quantisation with PyTorch's FX graph mode on the
oneDNN backend (:func:`quantize_int8`), activation ranges calibrated on fixed synthetic images
(:func:`calibration_images`), final 1x1 layers kept in fp32 so that logits and descriptors are not rounded to 8 bits).
"auto" (the detector's default) is "bf16" on CPUs with native bfloat16 (AVX512-BF16/AMX), else "int8", and "fused"
on CUDA: each mode's speed and agreement with fp32 are measured in docs/results/speed.md#the-cnns-inference-modes (and,
against the eager model, in docs/results/speed.md#small-costs-behind-the-codes-choices). Everything runs under
``torch.inference_mode``. ``torch.compile`` was measured (a long compilation, no gain over the fused channels-last
model: docs/archive.md) and is not used; see bench/bench_superpoint.py.
"""
from __future__ import annotations

import functools
import warnings
from typing import Sequence

import cv2
import numpy as np
import torch
from torch import nn

from evio_lib.features.base import to_float_image
from evio_lib.features.network.checks import _check_count, _check_image_shape
from evio_lib.features.network.model import SuperPointNet, _check_input
from evio_lib.features.network.postprocessing import pad_to_cells

__all__ = ["INFERENCE_MODES", "calibration_images", "quantize_int8", "inference_model"]

INFERENCE_MODES = ("auto", "eager", "fused", "bf16", "int8")


def calibration_images(shape: tuple[int, int] = (240, 320), count: int = 8, seed: int = 0) -> list[np.ndarray]:
    """Return ``count`` deterministic synthetic float32 (H, W) images in [0, 1] for int8 calibration.

    Smooth random textures (low-pass filtered noise at several scales) with filled polygons, lines, an ellipse and
    a checkerboard patch of random contrast, blurred slightly and with mild noise: the edges, corners and flat
    regions that set the activation ranges. Generated here so calibration needs no data set (and never sees test
    images).

    >>> imgs = calibration_images((32, 48), count=2)
    >>> len(imgs), imgs[0].shape, imgs[0].dtype, bool(0.0 <= imgs[0].min() and imgs[0].max() <= 1.0)
    (2, (32, 48), dtype('float32'), True)
    """
    height, width = _check_image_shape(shape)
    count = _check_count("count", count, minimum=1)
    rng = np.random.default_rng(seed)
    images = []
    for _ in range(count):
        img = np.zeros((height, width), np.float32)
        for scale in (4, 16, 64):  # smooth texture: noise blurred at several scales
            noise = rng.standard_normal((height, width)).astype(np.float32)
            img += cv2.GaussianBlur(noise, (0, 0), scale / 2.0) * (scale / 16.0)
        img = (img - img.min()) / max(float(np.ptp(img)), 1e-6) * rng.uniform(0.2, 0.6) + rng.uniform(0.0, 0.3)
        for _ in range(int(rng.integers(3, 7))):  # filled polygons of random grey levels
            n = int(rng.integers(3, 6))
            centre = rng.uniform([0, 0], [width, height])
            radius = rng.uniform(0.05, 0.3) * min(height, width)
            angles = np.sort(rng.uniform(0, 2 * np.pi, n))
            pts = centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])
            cv2.fillPoly(img, [np.round(pts).astype(np.int32)], float(rng.uniform(0, 1)))
        for _ in range(int(rng.integers(2, 5))):  # lines
            p, q = rng.uniform([0, 0], [width, height], size=(2, 2)).round().astype(int)
            grey, thickness = float(rng.uniform(0, 1)), int(rng.integers(1, 4))
            cv2.line(img, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), grey, thickness)
        axes = (int(rng.integers(3, max(4, width // 6))), int(rng.integers(3, max(4, height // 6))))
        centre = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        cv2.ellipse(img, centre, axes, float(rng.uniform(0, 180)), 0, 360, float(rng.uniform(0, 1)), -1)
        cell = int(rng.integers(4, 12))
        y0, x0 = int(rng.integers(0, max(1, height - 4 * cell))), int(rng.integers(0, max(1, width - 4 * cell)))
        yy, xx = np.mgrid[: min(4 * cell, height - y0), : min(4 * cell, width - x0)]
        img[y0 : y0 + yy.shape[0], x0 : x0 + yy.shape[1]] = ((yy // cell + xx // cell) % 2) * rng.uniform(0.5, 1.0)
        img = cv2.GaussianBlur(img, (0, 0), 0.7) + rng.normal(0.0, 0.01, (height, width)).astype(np.float32)
        images.append(np.clip(img, 0.0, 1.0).astype(np.float32))
    return images


def _quantization_modules():  # pragma: no cover - trivial import helper
    """Return (get_default_qconfig_mapping, prepare_fx, convert_fx), silencing torch.ao's deprecation warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from torch.ao.quantization import get_default_qconfig_mapping
        from torch.ao.quantization.quantize_fx import convert_fx, prepare_fx
    return get_default_qconfig_mapping, prepare_fx, convert_fx


def quantize_int8(
    model: SuperPointNet,
    calibration: Sequence[np.ndarray] | None = None,
    *,
    float_heads: bool = True,
) -> nn.Module:
    """Return an int8 (static, FX graph mode, oneDNN or x86 backend) copy of an fp32 model, for CPU inference.

    BN is folded first; activations are quantised per tensor (ranges from a histogram observer over the
    calibration images), weights per output channel. With ``float_heads`` the two final 1x1 convolutions stay in
    fp32 (they are ~2 % of the multiply-adds), so logits and descriptors are not rounded to 8 bits. The result maps
    a (B, 1, H, W) float tensor (H, W multiples of 8) to the same dict as :class:`SuperPointNet`, in float32.
    PyTorch's dynamic quantisation covers only Linear/LSTM layers, hence static quantisation of the convolutions.

    Args:
        model: a SuperPointNet (BN or not); it is not modified.
        calibration: float32 (H, W) images in [0, 1] (any size); default :func:`calibration_images` (4 at
            120x160; activation ranges hardly depend on the image size, calibration time does:
            docs/results/speed.md#small-costs-behind-the-codes-choices).
        float_heads: keep the final 1x1 layers in fp32.
    """
    if not isinstance(model, SuperPointNet):
        raise ValueError(f"model must be a SuperPointNet; got {type(model).__name__}")
    get_default_qconfig_mapping, prepare_fx, convert_fx = _quantization_modules()
    if calibration is None:
        images = calibration_images((120, 160), 4)
    else:
        images = [to_float_image(image, "calibration image") for image in calibration]
    if not images:
        raise ValueError("calibration must hold at least one (H, W) image; got an empty sequence")
    fused = model.fuse_for_inference().cpu()
    engine = _int8_engine()
    torch.backends.quantized.engine = engine
    qconfig = get_default_qconfig_mapping(engine)
    if float_heads:
        qconfig = qconfig.set_module_name("detector_head.1", None)
        if fused.descriptor_head is not None:
            qconfig = qconfig.set_module_name("descriptor_head.1", None)
    example = pad_to_cells(torch.from_numpy(images[0])[None, None])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch.ao deprecation notices
        prepared = prepare_fx(fused, qconfig, (example,))
        with torch.inference_mode():
            for image in images:
                prepared(pad_to_cells(torch.from_numpy(image)[None, None]))
        quantized = convert_fx(prepared)
    return _Int8SuperPoint(quantized.eval(), engine)


@functools.lru_cache(maxsize=1)
def _cpu_flags() -> frozenset[str]:
    """Return the CPU feature flags of /proc/cpuinfo (empty where it cannot be read, e.g. not Linux)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="ignore") as f:
            return frozenset(next((line.split(":", 1)[1].split() for line in f if line.startswith("flags")), []))
    except OSError:
        return frozenset()


def _int8_engine() -> str:
    """Return the quantised-kernel engine: "onednn" with full 8-bit activations where the CPU has 8-bit dot
    products (AVX512-VNNI, AVX-VNNI, AMX: no int16 saturation), else "x86" (FBGEMM, 7-bit activations, safe)."""
    vnni = bool({"avx512_vnni", "avx_vnni", "amx_int8"} & _cpu_flags())
    return "onednn" if "onednn" in torch.backends.quantized.supported_engines and vnni else "x86"


def _bf16_native() -> bool:
    """Return whether this CPU runs bfloat16 convolutions natively (oneDNN with AVX512-BF16 or AMX-BF16)."""
    try:
        onednn_bf16 = bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):  # private API: absent in some builds
        onednn_bf16 = False
    return onednn_bf16 and bool({"avx512_bf16", "amx_bf16"} & _cpu_flags())


def _auto_mode(device: torch.device) -> str:
    """Return the inference mode "auto" stands for on ``device`` (see :func:`inference_model`)."""
    if device.type != "cpu":
        return "fused"
    return "bf16" if _bf16_native() else "int8"


class _Int8SuperPoint(nn.Module):
    """Runs an FX-quantised SuperPointNet with the quantised engine it was converted for (a global torch setting)."""

    def __init__(self, quantized: nn.Module, engine: str) -> None:
        super().__init__()
        self.quantized = quantized
        self.engine = engine

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        if torch.backends.quantized.engine != self.engine:
            torch.backends.quantized.engine = self.engine
        return self.quantized(x)


class _FastSuperPoint(nn.Module):
    """Inference wrapper: fused fp32 or bf16 (channels-last) forward of a SuperPointNet; outputs float32."""

    def __init__(self, fused: SuperPointNet, bf16: bool) -> None:
        super().__init__()
        self.net = fused.to(memory_format=torch.channels_last)
        self.bf16 = bf16

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        net = self.net
        x = _check_input(x).contiguous(memory_format=torch.channels_last)
        if not self.bf16:
            return {k: v.contiguous() for k, v in net(x).items()}
        with torch.autocast(x.device.type, dtype=torch.bfloat16):
            features = net.encoder(x)
            det = net.detector_head[0](features)
            desc = None if net.descriptor_head is None else net.descriptor_head[0](features)
        out = {"logits": net.detector_head[1](det.float()).contiguous()}  # final 1x1 layers in fp32
        if desc is not None:
            out["descriptors"] = net.descriptor_head[1](desc.float()).contiguous()
        return out


def inference_model(
    model: SuperPointNet, mode: str = "auto", *, calibration: Sequence[np.ndarray] | None = None
) -> nn.Module:
    """Return a module for fast inference: (B, 1, H, W) float -> {"logits", "descriptors"} float32 (eval only).

    Modes: "eager" (the model itself in eval mode), "fused" (BN folded, channels-last fp32), "bf16" (fused,
    bfloat16 autocast, final 1x1 layers fp32), "int8" (:func:`quantize_int8`, CPU only), "auto" (bf16 on a CPU
    with native bfloat16, else int8; fused on CUDA). Call it under ``torch.inference_mode()``. The returned module
    lives on the model's device.
    """
    if not isinstance(model, SuperPointNet):
        raise ValueError(f"model must be a SuperPointNet; got {type(model).__name__}")
    if mode not in INFERENCE_MODES:
        raise ValueError(f"mode must be one of {INFERENCE_MODES}; got {mode!r}")
    device = next(model.parameters()).device
    if mode == "auto":
        mode = _auto_mode(device)
    if mode == "eager":
        return model.eval()
    if mode == "int8":
        if device.type != "cpu":
            raise ValueError(f"mode 'int8' runs on the CPU only; the model is on {device}")
        return quantize_int8(model, calibration)
    return _FastSuperPoint(model.fuse_for_inference(), bf16=(mode == "bf16"))
