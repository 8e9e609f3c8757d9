"""SuperPoint-style CNN: network, post-processing, checkpoints, fast CPU inference and the detector wrapper.

The network (thesis §3.2.4, Fig. 12) is fully convolutional: a VGG-style shared encoder of eight 3x3 convolutions
(depths 64-64-64-64-128-128-128-128, a 2x2 max-pool after every two of the first six) reduces an (H, W) image to an
(H/8, W/8) grid of cells; a detector head (3x3x256 then 1x1x65) gives 65 logits per 8x8 cell (64 pixel positions and
a "no point" dustbin) and a descriptor head (3x3x256 then 1x1x256) a raw descriptor per cell.

Layer order (a choice; the thesis only says "ReLU and batch norm after every convolution"): every 3x3 convolution is
followed by BatchNorm then ReLU (conv -> BN -> ReLU; the convolution has no bias because BN adds one). This order lets
inference fold each BN exactly into its convolution (:meth:`SuperPointNet.fuse_for_inference`); BN placed after the
ReLU could not be folded (it would have to pass through the ReLU, the max-pools and the zero padding of the next
convolution). The two final 1x1 convolutions have a bias and neither BN nor ReLU: they output the detector logits and
the raw (unnormalised) descriptors, since a ReLU would clip negative logits and descriptor signs and a BN would only
add a batch-dependent affine map to them.

Post-processing (:func:`postprocess`): softmax over the 65 channels, drop the dustbin, depth-to-space (pixel
shuffle) to an (H, W) heatmap, keep pixels with probability >= ``threshold`` (1/65 by default: a pixel more likely
than a uniform guess over the 65 classes, thesis §3.2.4), zero an image border of ``border`` pixels, greedy box NMS
(:func:`nms_heatmap`, the same result as :func:`evio_lib.features.base.nms_keypoints`), best ``max_keypoints`` by
score. Descriptors: the coarse descriptor map is L2-normalised per cell, interpolated at the keypoints with
**bicubic** interpolation (as in the thesis; ``descriptor_interpolation="bilinear"`` is the cheaper option) and
L2-normalised again. Cell (h, w) covers pixels x in [8w, 8w + 7], so its descriptor sits at the cell centre
(8w + 3.5, 8h + 3.5) (pixel centres at integer coordinates), the same centre the descriptor loss uses.

Fast inference (:func:`inference_model`): modes "eager" (the model as trained, fp32), "fused" (BN folded, channels-
last, fp32), "bf16" (fused, bfloat16 autocast, final 1x1 layers in fp32) and "int8" (fused, static int8 quantisation
with PyTorch's FX graph mode on the oneDNN backend, activation ranges calibrated on fixed synthetic images, final 1x1
layers kept in fp32 so that logits and descriptors are not rounded to 8 bits). "auto" (the detector's default) is
"bf16" on CPUs with native bfloat16 (AVX512-BF16/AMX; ~2.9x eager, logits within ~0.2 % of fp32), else "int8"
(~5x eager, ~97 % of keypoints within 1 px of fp32), and "fused" on CUDA. Everything runs under
``torch.inference_mode``. ``torch.compile`` was measured (a minute of compilation, no gain over the fused
channels-last model on this CPU) and is not used; see bench/bench_superpoint.py.

Reference: DeTone, Malisiewicz & Rabinovich, "SuperPoint: Self-Supervised Interest Point Detection and Description",
CVPRW 2018; thesis §3.2.4 (architecture, post-processing), §3.2.6 (NMS, best-N points).
"""
from __future__ import annotations

import copy
import functools
import math
import warnings
from collections import OrderedDict
from numbers import Integral, Real
from pathlib import Path
from typing import Any, Mapping, Sequence

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from evio_lib.features.base import FeatureDetector, Features, register_detector, to_float_image

__all__ = [
    "CELL",
    "MODEL_CONFIGS",
    "DEFAULT_WEIGHTS",
    "WEIGHTS_DIR",
    "TRAINING_COMMAND",
    "INFERENCE_MODES",
    "SuperPointNet",
    "build_model",
    "count_parameters",
    "pad_to_cells",
    "logits_to_heatmap",
    "nms_heatmap",
    "extract_keypoints",
    "refine_keypoints",
    "sample_descriptors",
    "postprocess",
    "calibration_images",
    "quantize_int8",
    "inference_model",
    "save_checkpoint",
    "load_checkpoint",
    "load_model",
    "resolve_weights",
    "shipped_weights",
    "SuperPointDetector",
]

CELL = 8  # pixels per cell side: three 2x2 max-pools, 2^3
# Width presets. "full" is the thesis architecture (§3.2.4). "narrow" is the lighter option with half the channels
# everywhere (about 1/4 of the multiply-adds); it is unrelated to the thesis's "DetDescLite", which is a training
# chain (one detector round), not a narrower network.
MODEL_CONFIGS: dict[str, dict[str, Any]] = {
    "full": {"encoder_channels": [64, 64, 64, 64, 128, 128, 128, 128], "head_channels": 256, "descriptor_dim": 256},
    "narrow": {"encoder_channels": [32, 32, 32, 32, 64, 64, 64, 64], "head_channels": 128, "descriptor_dim": 256},
}
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"  # package data: evio_lib/weights/*.pt
DEFAULT_WEIGHTS = "superpoint"  # evio_lib/weights/superpoint.pt: the shipped best model (pre-trained DetDesc Round 2)
# How the shipped weights are made (issue 4 training chain); quoted by the missing-weights error.
TRAINING_COMMAND = (
    "python -m evio_lib features-train pretrained_detdesc_round2 --chain  (writes "
    "runs/features/pretrained_detdesc_round2/best.pt; copy it to evio_lib/weights/ under the weights name)"
)
INFERENCE_MODES = ("auto", "eager", "fused", "bf16", "int8")
_POOL_AFTER = (1, 3, 5)  # 2x2 max-pool after encoder convolutions 2, 4 and 6 (0-based 1, 3, 5)
_CHECKPOINT_FORMAT = "evio-superpoint-1"


# ---------------------------------------------------------------------------------------------- the network
@torch.fx.wrap
def _check_input(x: torch.Tensor) -> torch.Tensor:
    """Return x after checking it is a (B, 1, H, W) floating tensor with H and W multiples of 8 (FX: a leaf call)."""
    if not isinstance(x, torch.Tensor) or x.ndim != 4 or x.shape[1] != 1:
        shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"x must be a (B, 1, H, W) image tensor; got {shape}")
    if x.shape[2] % CELL or x.shape[3] % CELL or x.shape[2] == 0 or x.shape[3] == 0:
        raise ValueError(
            f"x must have H and W that are positive multiples of {CELL}; got {tuple(x.shape[2:])} "
            "(pad with pad_to_cells)"
        )
    if not x.is_floating_point():
        raise ValueError(f"x must be a floating tensor with values in [0, 1]; got dtype {x.dtype}")
    return x


def _conv_block(c_in: int, c_out: int, batch_norm: bool) -> nn.Sequential:
    """Return conv3x3 -> BN -> ReLU (conv3x3 with bias -> ReLU without batch norm)."""
    layers: OrderedDict[str, nn.Module] = OrderedDict()
    layers["conv"] = nn.Conv2d(c_in, c_out, kernel_size=3, padding=1, bias=not batch_norm)
    if batch_norm:
        layers["bn"] = nn.BatchNorm2d(c_out)
    layers["relu"] = nn.ReLU(inplace=True)
    return nn.Sequential(layers)


def _check_config(
    encoder_channels: Sequence[int], head_channels: int, descriptor_dim: int, detector_only: bool, batch_norm: bool
) -> dict[str, Any]:
    """Return the validated model configuration as a plain dict (lists and ints: safe for weights_only loading)."""
    channels = list(encoder_channels) if isinstance(encoder_channels, (list, tuple)) else None
    if channels is None or len(channels) != 8 or not all(
        isinstance(c, Integral) and not isinstance(c, bool) and c >= 1 for c in channels
    ):
        raise ValueError(
            f"encoder_channels must be 8 positive integers (e.g. 64,64,64,64,128,128,128,128); got {encoder_channels!r}"
        )
    for name, value in (("head_channels", head_channels), ("descriptor_dim", descriptor_dim)):
        if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    for name, value in (("detector_only", detector_only), ("batch_norm", batch_norm)):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} must be a bool; got {value!r}")
    return {
        "encoder_channels": [int(c) for c in channels],
        "head_channels": int(head_channels),
        "descriptor_dim": int(descriptor_dim),
        "detector_only": bool(detector_only),
        "batch_norm": bool(batch_norm),
    }


class SuperPointNet(nn.Module):
    """SuperPoint-style detector/descriptor CNN (MagicPoint with ``detector_only=True``).

    ``forward(x)`` takes a (B, 1, H, W) float tensor in [0, 1], H and W multiples of 8, and returns a dict:
    ``"logits"`` (B, 65, H/8, W/8) detector logits (channel k < 64 is pixel (row k // 8, col k % 8) of the cell,
    channel 64 the dustbin) and, unless ``detector_only``, ``"descriptors"`` (B, D, H/8, W/8) raw cell descriptors
    (normalise them; :func:`postprocess` and the losses do).

    Args:
        encoder_channels: output depths of the eight 3x3 encoder convolutions (thesis: 64,64,64,64,128,128,128,128).
        head_channels: depth of the 3x3 convolution of each head (thesis: 256).
        descriptor_dim: descriptor length D (thesis: 256).
        detector_only: drop the descriptor head (MagicPoint / the "Detector" rounds).
        batch_norm: BN after every 3x3 convolution (conv -> BN -> ReLU); False gives conv(+bias) -> ReLU, which is
            also what :meth:`fuse_for_inference` returns.
        seed: if given, initialise the weights from this seed without touching torch's global random state.

    Reference: thesis §3.2.4, Fig. 12; DeTone et al. 2018, §3.

    >>> net = SuperPointNet()
    >>> out = net.eval()(torch.zeros(1, 1, 24, 32))
    >>> tuple(out["logits"].shape), tuple(out["descriptors"].shape), count_parameters(net)
    ((1, 65, 3, 4), (1, 256, 3, 4), 1302145)
    """

    def __init__(
        self,
        encoder_channels: Sequence[int] = (64, 64, 64, 64, 128, 128, 128, 128),
        head_channels: int = 256,
        descriptor_dim: int = 256,
        detector_only: bool = False,
        batch_norm: bool = True,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        self._config = _check_config(encoder_channels, head_channels, descriptor_dim, detector_only, batch_norm)
        self.inference_only = False  # True for the BN-folded copies of fuse_for_inference
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, Integral):
                raise ValueError(f"seed must be an int or None; got {seed!r}")
            with torch.random.fork_rng(devices=[]):  # seeded init, global RNG state restored afterwards
                torch.manual_seed(int(seed))
                self._build()
        else:
            self._build()

    def _build(self) -> None:
        """Create the layers (called once by __init__)."""
        cfg = self._config
        bn = cfg["batch_norm"]
        layers: list[nn.Module] = []
        c_in = 1
        for i, c_out in enumerate(cfg["encoder_channels"]):
            layers.append(_conv_block(c_in, c_out, bn))
            if i in _POOL_AFTER:
                layers.append(nn.MaxPool2d(kernel_size=2, stride=2))
            c_in = c_out
        self.encoder = nn.Sequential(*layers)
        head = cfg["head_channels"]
        self.detector_head = nn.Sequential(_conv_block(c_in, head, bn), nn.Conv2d(head, CELL * CELL + 1, kernel_size=1))
        self.descriptor_head = (
            None
            if cfg["detector_only"]
            else nn.Sequential(_conv_block(c_in, head, bn), nn.Conv2d(head, cfg["descriptor_dim"], kernel_size=1))
        )

    @property
    def config(self) -> dict[str, Any]:
        """Return a copy of the model configuration (the keyword arguments that rebuild this architecture)."""
        return copy.deepcopy(self._config)

    @property
    def descriptor_dim(self) -> int:
        """Return D, the descriptor length (0 for a detector-only model)."""
        return 0 if self._config["detector_only"] else self._config["descriptor_dim"]

    @classmethod
    def from_config(cls, config: Mapping[str, Any] | str, **overrides: Any) -> "SuperPointNet":
        """Return a new model from a config dict or a preset name ("full", "narrow"), with keyword overrides.

        >>> SuperPointNet.from_config("narrow", detector_only=True).config["encoder_channels"]
        [32, 32, 32, 32, 64, 64, 64, 64]
        """
        if isinstance(config, str):
            if config not in MODEL_CONFIGS:
                raise ValueError(f"config must be a dict or one of {sorted(MODEL_CONFIGS)}; got {config!r}")
            config = MODEL_CONFIGS[config]
        if not isinstance(config, Mapping):
            raise ValueError(f"config must be a dict of SuperPointNet arguments or a preset name; got {config!r}")
        known = {"encoder_channels", "head_channels", "descriptor_dim", "detector_only", "batch_norm", "seed"}
        merged = {**dict(config), **overrides}
        unknown = sorted(set(merged) - known)
        if unknown:
            raise ValueError(f"config has unknown keys {unknown}; expected some of {sorted(known)}")
        return cls(**merged)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """Return {"logits": (B, 65, H/8, W/8), "descriptors": (B, D, H/8, W/8)} for x (B, 1, H, W) in [0, 1]."""
        features = self.encoder(_check_input(x))
        out = {"logits": self.detector_head(features)}
        if self.descriptor_head is not None:
            out["descriptors"] = self.descriptor_head(features)
        return out

    def train(self, mode: bool = True) -> "SuperPointNet":
        """Set training mode; a fused inference copy refuses training mode (its batch norms are folded away)."""
        if mode and getattr(self, "inference_only", False):
            raise RuntimeError(
                "this SuperPointNet is a BN-folded inference copy (fuse_for_inference); train the original"
            )
        return super().train(mode)

    def fuse_for_inference(self) -> "SuperPointNet":
        """Return an eval-only copy with every BatchNorm folded into the convolution before it.

        Per output channel, with s = gamma / sqrt(running_var + eps): ``W' = s W`` and ``b' = s (b - mean) + beta``,
        so conv'(x) = BN(conv(x)) exactly (up to float rounding) for the running statistics of eval mode. The copy
        is a ``SuperPointNet(batch_norm=False)`` in eval mode without gradients; its ``train()`` raises. A model
        without BN is copied unchanged.

        >>> net = SuperPointNet(seed=0).eval()
        >>> fused = net.fuse_for_inference()
        >>> x = torch.rand(1, 1, 16, 16, generator=torch.Generator().manual_seed(0))
        >>> bool(torch.allclose(fused(x)["logits"], net(x)["logits"], atol=1e-4)), fused.config["batch_norm"]
        (True, False)
        """
        fused = SuperPointNet(**{**self._config, "batch_norm": False})
        state: dict[str, torch.Tensor] = {}
        with torch.no_grad():
            for name, module in self.named_modules():
                if isinstance(module, nn.Sequential) and hasattr(module, "conv"):  # a conv block
                    conv = module.conv
                    weight = conv.weight.detach().float()
                    bias = conv.bias.detach().float() if conv.bias is not None else weight.new_zeros(weight.shape[0])
                    if hasattr(module, "bn"):
                        bn = module.bn
                        scale = bn.weight.detach().float() / torch.sqrt(bn.running_var.float() + bn.eps)  # s
                        weight = weight * scale[:, None, None, None]  # W' = s W
                        # b' = s (b - mu) + beta
                        bias = (bias - bn.running_mean.float()) * scale + bn.bias.detach().float()
                    state[f"{name}.conv.weight"] = weight
                    state[f"{name}.conv.bias"] = bias
            for head in ("detector_head", "descriptor_head"):
                module = getattr(self, head)
                if module is not None:  # the final 1x1 convolution
                    state[f"{head}.1.weight"] = module[1].weight.detach().float().clone()
                    state[f"{head}.1.bias"] = module[1].bias.detach().float().clone()
        fused.load_state_dict(state)
        fused = fused.to(next(self.parameters()).device).eval()
        fused.requires_grad_(False)
        fused.inference_only = True
        return fused


def build_model(config: Mapping[str, Any] | str = "full", seed: int | None = 0, **overrides: Any) -> SuperPointNet:
    """Return a freshly initialised SuperPointNet from a preset name or config dict (seeded; global RNG untouched).

    >>> build_model("full", detector_only=True).descriptor_dim
    0
    """
    return SuperPointNet.from_config(config, seed=seed, **overrides)


def count_parameters(model: nn.Module, trainable_only: bool = False) -> int:
    """Return the number of parameters (BN running statistics are buffers and not counted).

    >>> count_parameters(nn.Conv2d(1, 2, 3))   # 2 * 1 * 3 * 3 weights + 2 biases
    20
    """
    return int(sum(p.numel() for p in model.parameters() if p.requires_grad or not trainable_only))


# ---------------------------------------------------------------------------------------------- post-processing
def pad_to_cells(x: torch.Tensor) -> torch.Tensor:
    """Return (B, C, H', W') with H', W' the next multiples of 8, padding bottom and right by edge replication.

    Replication (not zeros) so that the padding adds no artificial step edge, whose corners would be detected.

    >>> tuple(pad_to_cells(torch.zeros(1, 1, 180, 240)).shape)
    (1, 1, 184, 240)
    """
    if not isinstance(x, torch.Tensor) or x.ndim != 4:
        raise ValueError(f"x must be a (B, C, H, W) tensor; got {tuple(getattr(x, 'shape', ())) or type(x).__name__}")
    pad_h = -x.shape[2] % CELL
    pad_w = -x.shape[3] % CELL
    if pad_h == 0 and pad_w == 0:
        return x
    return F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")


def _check_logits(logits: torch.Tensor) -> torch.Tensor:
    """Return logits as (B, 65, Hc, Wc), adding a batch axis to (65, Hc, Wc)."""
    if not isinstance(logits, torch.Tensor):
        raise ValueError(f"logits must be a torch tensor (B, 65, Hc, Wc); got {type(logits).__name__}")
    if logits.ndim == 3:
        logits = logits[None]
    if logits.ndim != 4 or logits.shape[1] != CELL * CELL + 1:
        raise ValueError(f"logits must have shape (B, 65, Hc, Wc) or (65, Hc, Wc); got {tuple(logits.shape)}")
    return logits


def logits_to_heatmap(logits: torch.Tensor) -> torch.Tensor:
    """Return the (B, H, W) keypoint probability map ("pointness") of detector logits (B, 65, H/8, W/8).

    Softmax over the 65 channels, drop the dustbin (channel 64), depth-to-space: channel k of cell (h, w) becomes
    pixel (row 8h + k // 8, col 8w + k % 8) (``F.pixel_shuffle``). A (65, Hc, Wc) input gives (1, H, W).

    Reference: thesis §3.2.4; DeTone et al. 2018, §3.1.

    >>> logits = torch.zeros(1, 65, 1, 1); logits[0, 8 * 2 + 5] = 10.0   # cell pixel row 2, col 5
    >>> heat = logits_to_heatmap(logits)
    >>> tuple(heat.shape), [int(i) for i in divmod(int(heat.argmax()), 8)], round(float(heat.max()), 3)
    ((1, 8, 8), [2, 5], 0.997)
    """
    logits = _check_logits(logits)
    prob = torch.softmax(logits.float(), dim=1)  # p_k = exp(x_k) / sum_j exp(x_j), j = 0..64
    return F.pixel_shuffle(prob[:, : CELL * CELL], CELL)[:, 0]  # drop dustbin, (B, 64, Hc, Wc) -> (B, H, W)


def nms_heatmap(scores: torch.Tensor, radius: int) -> torch.Tensor:
    """Return the scores with every pixel zeroed that greedy box NMS suppresses (positive pixels are candidates).

    Greedy definition (SuperPoint's grid NMS, as :func:`evio_lib.features.base.nms_keypoints`): visit positive
    pixels by descending score; keep one unless a kept pixel lies within Chebyshev distance ``radius``
    (``max(|dx|, |dy|) <= r``). Computed with max-pooling in rounds, no loop over pixels: a pixel that is the largest
    remaining score in its (2r + 1)^2 box is kept, pixels in the boxes of kept ones are removed, repeat until nothing
    changes (usually 2-4 rounds). Equal scores inside one box are all kept (the greedy order would keep one).
    On the CPU the box maxima come from ``cv2.dilate`` (much faster than torch's CPU max-pool), on a GPU from
    ``F.max_pool2d``.

    Args:
        scores: (H, W), (B, H, W) or (B, 1, H, W) non-negative scores; zero = no candidate.
        radius: NMS radius r >= 0 in pixels (0 returns the scores unchanged).

    Reference: DeTone et al. 2018 (NMS of the detector output); thesis §3.2.6 (NMS 4 and 8).

    >>> s = torch.zeros(1, 7); s[0, 1], s[0, 2], s[0, 3], s[0, 5] = 0.5, 0.9, 0.8, 0.7
    >>> nms_heatmap(s, 1).double().numpy().round(2).tolist()   # 0.9 suppresses 0.5 and 0.8; 0.7 survives
    [[0.0, 0.0, 0.9, 0.0, 0.0, 0.7, 0.0]]
    """
    ndim = scores.ndim if isinstance(scores, torch.Tensor) else -1
    if ndim not in (2, 3, 4) or (ndim == 4 and scores.shape[1] != 1):
        raise ValueError(
            "scores must be a torch tensor of shape (H, W), (B, H, W) or (B, 1, H, W); "
            f"got {tuple(getattr(scores, 'shape', ())) or type(scores).__name__}"
        )
    if isinstance(radius, bool) or not isinstance(radius, Integral) or radius < 0:
        raise ValueError(f"radius must be an integer >= 0 (pixels); got {radius!r}")
    if radius == 0:
        return scores
    shape = scores.shape
    s = scores.reshape(-1, shape[-2], shape[-1])
    if s.device.type == "cpu":  # OpenCV's dilation is ~100x faster than torch's CPU max-pool
        arr = s.detach().float().numpy()
        kept = np.stack([_nms_numpy(arr[i], int(radius)) for i in range(arr.shape[0])])
        return torch.from_numpy(kept).to(scores.dtype).reshape(shape)
    return _nms_torch(s[:, None], int(radius)).reshape(shape)


def _nms_numpy(s: np.ndarray, radius: int) -> np.ndarray:
    """Greedy box NMS of one (H, W) float32 map by rounds of box maxima (cv2.dilate); see :func:`nms_heatmap`."""
    box = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    candidate = s > 0
    keep = (s == cv2.dilate(s, box)) & candidate  # round 1: box maxima are kept by greedy NMS
    while True:
        suppressed = cv2.dilate(keep.view(np.uint8), box) > 0  # within r of a kept pixel (kept ones included)
        remaining = np.where(suppressed, np.float32(0.0), s)
        new = (remaining == cv2.dilate(remaining, box)) & candidate & ~suppressed  # largest undecided in its box
        if not new.any():
            break
        keep |= new
    return np.where(keep, s, np.float32(0.0))


def _nms_torch(s: torch.Tensor, radius: int) -> torch.Tensor:
    """The same rounds with max-pooling, for (B, 1, H, W) tensors on a GPU."""
    k = 2 * radius + 1

    def box_max(t: torch.Tensor) -> torch.Tensor:
        return F.max_pool2d(t, kernel_size=k, stride=1, padding=radius)  # max over the (2r+1)^2 box

    candidate = s > 0
    keep = (s == box_max(s)) & candidate
    while True:
        suppressed = box_max(keep.to(s.dtype)) > 0
        remaining = torch.where(suppressed, torch.zeros_like(s), s)
        new = (remaining == box_max(remaining)) & candidate & ~suppressed
        if not bool(new.any()):
            break
        keep |= new
    return torch.where(keep, s, torch.zeros_like(s))


def _check_tensor(value: Any, name: str, form: str, ndim: int, *, last: int | None = None, what: str = "") -> None:
    """Raise ValueError naming ``name`` and its expected ``form`` unless ``value`` is a torch tensor of that rank."""
    if not isinstance(value, torch.Tensor) or value.ndim != ndim or (last is not None and value.shape[-1] != last):
        got = tuple(getattr(value, "shape", ())) or type(value).__name__
        raise ValueError(f"{name} must be a {form} torch tensor{what}; got {got}")


def extract_keypoints(
    heatmap: torch.Tensor,
    threshold: float = 1.0 / 65.0,
    nms_radius: int = 4,
    border: int = 4,
    max_keypoints: int | None = 1000,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Return keypoints (N, 2) float32 (x, y) and scores (N,) of one (H, W) heatmap, strongest first.

    Steps: keep pixels with ``heatmap >= threshold``; drop a band of ``border`` pixels at the image edge (before
    NMS, so that a dropped border pixel suppresses nothing); greedy box NMS of ``nms_radius``; sort by score
    (ties in raster order); keep the best ``max_keypoints`` (None: all).

    >>> heat = torch.zeros(16, 16); heat[5, 7], heat[6, 8], heat[10, 3], heat[1, 1] = 0.9, 0.5, 0.3, 1.0
    >>> kp, sc = extract_keypoints(heat, threshold=0.2, nms_radius=2, border=2)
    >>> kp.tolist(), sc.double().numpy().round(2).tolist()   # (1, 1) is in the border, (8, 6) is suppressed by (7, 5)
    ([[7.0, 5.0], [3.0, 10.0]], [0.9, 0.3])
    """
    _check_tensor(heatmap, "heatmap", "(H, W)", 2)
    threshold = _check_real("threshold", threshold, minimum=0.0)
    border = _check_count("border", border)
    nms_radius = _check_count("nms_radius", nms_radius)
    if max_keypoints is not None:
        max_keypoints = _check_count("max_keypoints", max_keypoints, minimum=1)
    heat = heatmap.float()
    scores = torch.where(heat >= threshold, heat, torch.zeros_like(heat))  # threshold: p >= 1/65
    if threshold == 0.0:
        scores = scores.clamp_min(torch.finfo(torch.float32).tiny)  # every pixel is a candidate
    if border > 0:
        inner = torch.zeros_like(scores)
        inner[border:-border, border:-border] = 1.0  # keep border <= x <= W - 1 - border (same for y)
        scores = scores * inner
    scores = nms_heatmap(scores, nms_radius)
    ys, xs = torch.nonzero(scores > 0, as_tuple=True)  # raster order
    values = scores[ys, xs]
    order = torch.sort(values, descending=True, stable=True).indices
    if max_keypoints is not None:
        order = order[:max_keypoints]
    keypoints = torch.stack([xs[order], ys[order]], dim=1).to(torch.float32)
    return keypoints, values[order]


def refine_keypoints(heatmap: torch.Tensor, keypoints: torch.Tensor, radius: int = 2) -> torch.Tensor:
    """Return keypoints (N, 2) float32 moved to the centroid of the heatmap around each integer peak (sub-pixel).

    For a peak at integer pixel (x, y) and the (2r + 1) x (2r + 1) window of probabilities p(u, v) around it
    (u, v in -r..r; pixels outside the image count as 0), the refined point is::

        x* = x + sum p(u, v) u / sum p(u, v),   y* = y + sum p(u, v) v / sum p(u, v)

    (a weighted mean of pixels of the image, so it stays inside it). The network's cell head can only place a
    point on a pixel; the mass it spreads over the neighbours says on which side of that pixel the corner lies, so
    the centroid recovers part of the lost half pixel (SuperPoint's own post-processing stops at integer peaks, as
    the thesis does). ``radius = 0`` returns the points unchanged.

    Args:
        heatmap: (H, W) keypoint probabilities (:func:`logits_to_heatmap`).
        keypoints: (N, 2) integer-valued (x, y) peaks inside the heatmap (:func:`extract_keypoints`).
        radius: half-size r of the window (pixels, >= 0).

    >>> heat = torch.zeros(8, 8); heat[3, 4], heat[3, 5] = 0.6, 0.2   # mass right of the peak at (4, 3)
    >>> refine_keypoints(heat, torch.tensor([[4.0, 3.0]]), radius=1).tolist()
    [[4.25, 3.0]]
    """
    _check_tensor(heatmap, "heatmap", "(H, W)", 2)
    _check_tensor(keypoints, "keypoints", "(N, 2)", 2, last=2, what=" of (x, y) pixels")
    radius = _check_count("radius", radius)
    if radius == 0 or keypoints.shape[0] == 0:
        return keypoints.to(torch.float32)
    height, width = heatmap.shape
    cols = keypoints[:, 0].round().long()
    rows = keypoints[:, 1].round().long()
    if (cols < 0).any() or (cols >= width).any() or (rows < 0).any() or (rows >= height).any():
        raise ValueError(f"keypoints must lie inside the ({height}, {width}) heatmap")
    heat = heatmap.float().clamp_min(0.0)
    padded = F.pad(heat, (radius,) * 4)  # zeros outside the image
    offsets = torch.arange(-radius, radius + 1, device=heat.device)
    du, dv = offsets[None, :], offsets[:, None]  # (1, k) column offsets, (k, 1) row offsets
    window = padded[rows[:, None, None] + radius + dv, cols[:, None, None] + radius + du]  # (N, k, k)
    mass = window.sum(dim=(1, 2)).clamp_min(torch.finfo(torch.float32).tiny)
    x = cols.float() + (window * du).sum(dim=(1, 2)) / mass
    y = rows.float() + (window * dv).sum(dim=(1, 2)) / mass
    return torch.stack([x, y], dim=1)


def sample_descriptors(
    descriptor_map: torch.Tensor, keypoints: torch.Tensor, interpolation: str = "bicubic"
) -> torch.Tensor:
    """Return (N, D) unit descriptors interpolated from a coarse (D, Hc, Wc) map at (N, 2) pixel keypoints (x, y).

    Cell (h, w) holds the descriptor of pixel (8w + 3.5, 8h + 3.5); the map is L2-normalised per cell, interpolated
    (``F.grid_sample``, ``align_corners=False`` so that normalised coordinate ``(x + 0.5) / (8 Wc) * 2 - 1`` is
    exactly pixel x; border cells are extended outwards) and each result L2-normalised.

    Args:
        descriptor_map: (D, Hc, Wc) raw descriptors of one image.
        keypoints: (N, 2) pixels (x, y) in the (8 Hc, 8 Wc) image.
        interpolation: "bicubic" (thesis §3.2.4) or "bilinear".

    >>> dmap = torch.zeros(2, 1, 2); dmap[0, 0, 0] = 1.0; dmap[1, 0, 1] = 1.0   # left cell e_x, right cell e_y
    >>> sample_descriptors(dmap, torch.tensor([[3.5, 3.5], [7.5, 3.5]]), "bilinear").numpy().round(3)
    array([[1.   , 0.   ],
           [0.707, 0.707]], dtype=float32)
    """
    _check_tensor(descriptor_map, "descriptor_map", "(D, Hc, Wc)", 3)
    _check_tensor(keypoints, "keypoints", "(N, 2)", 2, last=2, what=" of (x, y) pixels")
    if interpolation not in ("bicubic", "bilinear"):
        raise ValueError(f"interpolation must be 'bicubic' or 'bilinear'; got {interpolation!r}")
    d, hc, wc = descriptor_map.shape
    if keypoints.shape[0] == 0:
        return torch.zeros((0, d), dtype=torch.float32, device=descriptor_map.device)
    dmap = F.normalize(descriptor_map.float(), p=2, dim=0)  # unit descriptor per cell
    kp = keypoints.to(device=dmap.device, dtype=torch.float32)
    size = torch.tensor([CELL * wc, CELL * hc], dtype=torch.float32, device=dmap.device)
    grid = (kp + 0.5) / size * 2.0 - 1.0  # pixel x -> [-1, 1] with align_corners=False (pixel edges at -1, 1)
    sampled = F.grid_sample(
        dmap[None], grid[None, None], mode=interpolation, padding_mode="border", align_corners=False
    )  # (1, D, 1, N)
    return F.normalize(sampled[0, :, 0].T, p=2, dim=1)  # (N, D), ||d|| = 1


def postprocess(
    logits: torch.Tensor,
    descriptors: torch.Tensor | None = None,
    *,
    image_shape: tuple[int, int] | None = None,
    threshold: float = 1.0 / 65.0,
    nms_radius: int = 4,
    border: int = 4,
    max_keypoints: int | None = 1000,
    descriptor_interpolation: str = "bicubic",
    subpixel_radius: int = 0,
) -> list[Features]:
    """Return one Features record per image from network outputs (the detector's whole post-processing).

    Args:
        logits: (B, 65, Hc, Wc) (or (65, Hc, Wc)) detector logits.
        descriptors: (B, D, Hc, Wc) raw descriptor map, or None (detector-only: (N, 0) descriptors).
        image_shape: (H, W) of the unpadded input; the heatmap is cropped to it before thresholding (default
            (8 Hc, 8 Wc)).
        threshold, nms_radius, border, max_keypoints: see :func:`extract_keypoints`.
        descriptor_interpolation: "bicubic" or "bilinear", see :func:`sample_descriptors`.
        subpixel_radius: window half-size of :func:`refine_keypoints` (0, the default: integer peaks as in the
            thesis); descriptors are sampled at the refined points.

    Reference: thesis §3.2.4 (softmax, dustbin, reshape, threshold 1/65, NMS, bicubic descriptors, L2 norm).

    >>> logits = torch.full((1, 65, 4, 4), -5.0); logits[:, 64] = 5.0; logits[0, 8 * 3 + 4, 1, 2] = 12.0
    >>> f = postprocess(logits, torch.randn(1, 16, 4, 4, generator=torch.Generator().manual_seed(0)))[0]
    >>> f.keypoints.tolist(), f.descriptors.shape, round(float(np.linalg.norm(f.descriptors[0])), 4)
    ([[20.0, 11.0]], (1, 16), 1.0)
    """
    logits = _check_logits(logits)
    b, _, hc, wc = logits.shape
    if descriptors is not None:
        if not isinstance(descriptors, torch.Tensor) or descriptors.ndim != 4 or descriptors.shape[0] != b or tuple(
            descriptors.shape[2:]
        ) != (hc, wc):
            raise ValueError(
                f"descriptors must have shape (B, D, Hc, Wc) = ({b}, D, {hc}, {wc}) to match logits; "
                f"got {tuple(getattr(descriptors, 'shape', ()))}"
            )
    if image_shape is None:
        height, width = CELL * hc, CELL * wc
    else:
        height, width = _check_image_shape(image_shape)
        if height > CELL * hc or width > CELL * wc:
            raise ValueError(
                f"image_shape {(height, width)} exceeds the {(CELL * hc, CELL * wc)} pixels that the logits cover"
            )
    heat = logits_to_heatmap(logits)[:, :height, :width]
    records = []
    for i in range(b):  # loop over images only
        keypoints, scores = extract_keypoints(heat[i], threshold, nms_radius, border, max_keypoints)
        keypoints = refine_keypoints(heat[i], keypoints, subpixel_radius)
        if descriptors is None:
            desc = np.zeros((keypoints.shape[0], 0), np.float32)
        else:
            desc = sample_descriptors(descriptors[i], keypoints, descriptor_interpolation).cpu().numpy()
        records.append(Features(keypoints.cpu().numpy(), scores.cpu().numpy(), desc))
    return records


# ---------------------------------------------------------------------------------------------- fast inference
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
            120x160; activation ranges hardly depend on the image size, calibration time does: ~0.5 s per image).
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


# ---------------------------------------------------------------------------------------------- checkpoints
def save_checkpoint(
    model: SuperPointNet, path: str | Path, metadata: Mapping[str, Any] | None = None, **extra: Any
) -> Path:
    """Write ``{"format", "model_config", "state_dict", "metadata", **extra}`` with ``torch.save``; return the path.

    The file loads with ``torch.load(path, weights_only=True)``, so metadata and extra entries must be plain
    Python values (dict, list, str, int, float, bool, None) or tensors (e.g. ``optimizer=opt.state_dict()``,
    ``epoch=3`` for resuming). Tensors are stored on the CPU.
    """
    if not isinstance(model, SuperPointNet):
        raise ValueError(f"model must be a SuperPointNet; got {type(model).__name__}")
    reserved = {"format", "model_config", "state_dict", "metadata"} & set(extra)
    if reserved:
        raise ValueError(f"extra entries must not use the reserved keys {sorted(reserved)}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    checkpoint = {
        "format": _CHECKPOINT_FORMAT,
        "model_config": model.config,
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "metadata": dict(metadata or {}),
        **extra,
    }
    torch.save(checkpoint, path)
    return path


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Return the checkpoint dict of a file written by :func:`save_checkpoint` (``torch.load(weights_only=True)``)."""
    from evio_lib.io.checkpoint import read_checkpoint

    # refuses a missing, empty, truncated, foreign or other-kind file with a CheckpointError (a ValueError; a missing
    # file is also a FileNotFoundError) naming the file
    return read_checkpoint(path, "superpoint", map_location=map_location, weights_only=True)


def shipped_weights() -> list[str]:
    """Return the names of the SuperPoint-style weights shipped in ``evio_lib/weights/`` (file stems), sorted.

    The folder also holds other networks' weights (``reconstruction_*.pt``, the event-to-image reconstructors of
    :mod:`evio_lib.events.reconstruct`); they are not detectors and are left out.
    """
    if not WEIGHTS_DIR.is_dir():
        return []
    return sorted(p.stem for p in WEIGHTS_DIR.glob("*.pt") if not p.stem.startswith("reconstruction_"))


def resolve_weights(weights: str | Path) -> Path:
    """Return the checkpoint path of ``weights``: an existing file path, or the name of shipped weights.

    A name ``NAME`` (no folder, no suffix) means ``evio_lib/weights/NAME.pt``. Raises FileNotFoundError naming the
    file that is missing and the training command that writes it.
    """
    if not isinstance(weights, (str, Path)) or str(weights).strip() == "":
        raise ValueError(f"weights must be a checkpoint path or the name of shipped weights; got {weights!r}")
    path = Path(weights)
    looks_like_path = isinstance(weights, Path) or path.suffix in (".pt", ".pth") or len(path.parts) > 1
    if looks_like_path:
        if path.is_file():
            return path
        from evio_lib.io.checkpoint import CheckpointNotFoundError  # a FileNotFoundError and a ValueError

        raise CheckpointNotFoundError(f"SuperPoint weights file not found: {path}")
    shipped = WEIGHTS_DIR / f"{weights}.pt"
    if shipped.is_file():
        return shipped
    raise FileNotFoundError(
        f"SuperPoint weights {str(weights)!r} not found: expected the file {shipped} "
        f"(shipped weights: {shipped_weights() or 'none yet'}). It is produced by the training chain: "
        f"{TRAINING_COMMAND}. Or pass weights=PATH to a checkpoint written by save_checkpoint, or weights=None "
        "with allow_random=True for an untrained network (tests, lessons)."
    )


def load_model(weights: str | Path, device: str | torch.device = "cpu") -> SuperPointNet:
    """Return the SuperPointNet stored in a checkpoint (path or shipped name), in eval mode on ``device``."""
    from evio_lib.io.checkpoint import CheckpointError, load_state

    path = resolve_weights(weights)
    checkpoint = load_checkpoint(path, map_location="cpu")
    try:
        model = SuperPointNet.from_config(checkpoint["model_config"])
    except (ValueError, TypeError) as err:
        raise CheckpointError(f"{path}: its model_config is not a SuperPointNet configuration ({err})") from None
    load_state(model, checkpoint["state_dict"], path, "its state_dict does not match its model_config")
    return model.to(_check_device(device)).eval()


# ---------------------------------------------------------------------------------------------- the detector
class SuperPointDetector(FeatureDetector):
    """The CNN as a FeatureDetector: ``detect_and_describe(image)`` -> keypoints, probabilities, unit descriptors.

    Args:
        max_keypoints: keep the best this many keypoints after NMS.
        nms_radius: greedy box NMS radius in pixels (thesis: 4, or 8 for 480x640 homography estimation).
        weights: a checkpoint path or the name of shipped weights in ``evio_lib/weights/`` (default
            ``DEFAULT_WEIGHTS``); None builds an untrained network, allowed only with ``allow_random=True``.
        device: "cpu" or "cuda".
        threshold: minimum keypoint probability (default 1/65).
        border: pixels at the image edge without keypoints (default 4).
        inference: "auto" (bf16 on CPUs with native bfloat16, else int8; fused fp32 on CUDA), "eager",
            "fused", "bf16" or "int8" (see :func:`inference_model`).
        model_config: preset name or config dict of the untrained network (weights=None only).
        allow_random: permit weights=None.
        seed: initialisation seed of the untrained network.
        calibration: images for int8 calibration (default :func:`calibration_images`).
        descriptor_interpolation: "bicubic" (default, thesis) or "bilinear".
        subpixel_radius: half-size of the heat-centroid window that moves each peak off the pixel grid
            (:func:`refine_keypoints`; default 2, i.e. 5 x 5); 0 keeps the thesis's integer peaks.
        num_threads: if given, ``torch.set_num_threads(num_threads)`` (process-wide).

    Any image size works: the image is padded to multiples of 8 (edge replication) and the heatmap cropped back.
    Scores are keypoint probabilities; descriptors are float32 with unit L2 norm (D = 256), (N, 0) for a
    detector-only (MagicPoint) checkpoint.

    >>> det = SuperPointDetector(weights=None, allow_random=True, inference="fused", max_keypoints=50)
    >>> f = det.detect_and_describe(np.random.default_rng(0).random((60, 90)).astype(np.float32))
    >>> f.keypoints.shape[1], f.descriptors.shape[1], len(f) <= 50
    (2, 256, True)
    """

    name = "superpoint"

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        weights: str | Path | None = DEFAULT_WEIGHTS,
        device: str | torch.device = "cpu",
        threshold: float = 1.0 / 65.0,
        border: int = 4,
        inference: str = "auto",
        model_config: Mapping[str, Any] | str = "full",
        allow_random: bool = False,
        seed: int = 0,
        calibration: Sequence[np.ndarray] | None = None,
        descriptor_interpolation: str = "bicubic",
        subpixel_radius: int = 2,
        num_threads: int | None = None,
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints=max_keypoints, nms_radius=nms_radius, **options)
        self.threshold = _check_real("threshold", threshold, minimum=0.0)
        self.border = _check_count("border", border)
        if descriptor_interpolation not in ("bicubic", "bilinear"):
            raise ValueError(
                f"descriptor_interpolation must be 'bicubic' or 'bilinear'; got {descriptor_interpolation!r}"
            )
        self.descriptor_interpolation = descriptor_interpolation
        self.subpixel_radius = _check_count("subpixel_radius", subpixel_radius)
        if inference not in INFERENCE_MODES:
            raise ValueError(f"inference must be one of {INFERENCE_MODES}; got {inference!r}")
        if num_threads is not None:
            torch.set_num_threads(_check_count("num_threads", num_threads, minimum=1))
        self.device = _check_device(device)
        if weights is None:
            if not allow_random:
                raise ValueError(
                    "weights=None builds an UNTRAINED network; pass allow_random=True to confirm (tests, lessons), "
                    f"or give weights (shipped: {shipped_weights() or 'none yet'})"
                )
            model = build_model(model_config, seed=seed).eval()
            self.weights_path: Path | None = None
        else:
            self.weights_path = resolve_weights(weights)
            model = load_model(self.weights_path)
        self.model = model.to(self.device).eval()
        if inference == "auto":
            inference = _auto_mode(self.device)
        self.inference = inference
        self._forward = inference_model(self.model, inference, calibration=calibration)

    @property
    def descriptor_dim(self) -> int:
        """Return D (0 for a detector-only checkpoint)."""
        return self.model.descriptor_dim

    def _run(self, image: np.ndarray) -> tuple[dict[str, torch.Tensor], tuple[int, int]]:
        """Return the network outputs for one image and its (H, W)."""
        img = to_float_image(image)
        x = pad_to_cells(torch.from_numpy(img)[None, None]).to(self.device)
        with torch.inference_mode():
            out = self._forward(x)
        return out, img.shape

    def heatmap(self, image: np.ndarray) -> np.ndarray:
        """Return the (H, W) float32 keypoint probability map of a grayscale image (before threshold and NMS)."""
        out, (height, width) = self._run(image)
        return logits_to_heatmap(out["logits"])[0, :height, :width].cpu().numpy()

    def detect_and_describe(self, image: np.ndarray) -> Features:
        """Return keypoints (N, 2) (x, y), probabilities (N,) and unit descriptors (N, D) of a grayscale image."""
        out, shape = self._run(image)
        with torch.inference_mode():
            return postprocess(
                out["logits"],
                out.get("descriptors"),
                image_shape=shape,
                threshold=self.threshold,
                nms_radius=self.nms_radius,
                border=self.border,
                max_keypoints=self.max_keypoints,
                descriptor_interpolation=self.descriptor_interpolation,
                subpixel_radius=self.subpixel_radius,
            )[0]

    def __repr__(self) -> str:
        source = self.weights_path.name if self.weights_path is not None else "untrained"
        return (
            f"SuperPointDetector(weights={source!r}, inference={self.inference!r}, device={str(self.device)!r}, "
            f"max_keypoints={self.max_keypoints}, nms_radius={self.nms_radius}, threshold={self.threshold:.4g}, "
            f"subpixel_radius={self.subpixel_radius})"
        )


def _register_shipped_variants() -> None:
    """Register every shipped checkpoint ``evio_lib/weights/NAME.pt`` as detector NAME (create_detector(NAME))."""
    for name in shipped_weights():
        key = name.strip().lower().replace("-", "_").replace(" ", "_")
        if key == SuperPointDetector.name:
            continue  # "superpoint" is the built-in name (its default weights)
        factory = functools.partial(SuperPointDetector, weights=name)
        try:
            register_detector(key, factory)
        except ValueError:  # already registered (module re-import) or a built-in name: leave it
            pass


_register_shipped_variants()


# ---------------------------------------------------------------------------------------------- small checks
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

