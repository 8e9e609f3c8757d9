"""The SuperPoint-style network: :class:`SuperPointNet`, its width presets, and checkpoints (shipped weights too).

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

Checkpoints (:func:`save_checkpoint`, :func:`load_model`) hold the model configuration and the state dict as plain
values (``torch.load(weights_only=True)``); a name without folder or suffix means shipped weights
``evio_lib/weights/NAME.pt`` (:func:`resolve_weights`, :func:`shipped_weights`).

Reference: DeTone, Malisiewicz & Rabinovich, "SuperPoint: Self-Supervised Interest Point Detection and Description",
CVPRW 2018; thesis §3.2.4 (architecture).
"""
from __future__ import annotations

import copy
from collections import OrderedDict
from numbers import Integral
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch
from torch import nn

from evio_lib.features.base import SUPERPOINT_DEFAULT_WEIGHTS
from evio_lib.features.network.checks import _check_device

__all__ = [
    "CELL",
    "MODEL_CONFIGS",
    "DEFAULT_WEIGHTS",
    "WEIGHTS_DIR",
    "TRAINING_COMMAND",
    "SuperPointNet",
    "build_model",
    "count_parameters",
    "save_checkpoint",
    "load_checkpoint",
    "load_model",
    "resolve_weights",
    "shipped_weights",
]

CELL = 8  # pixels per cell side: three 2x2 max-pools, 2^3
# Width presets. "full" is the thesis architecture (§3.2.4). "narrow" is the lighter option with half the channels
# everywhere (about 1/4 of the multiply-adds); it is unrelated to the thesis's "DetDescLite", which is a training
# chain (one detector round), not a narrower network.
MODEL_CONFIGS: dict[str, dict[str, Any]] = {
    "full": {"encoder_channels": [64, 64, 64, 64, 128, 128, 128, 128], "head_channels": 256, "descriptor_dim": 256},
    "narrow": {"encoder_channels": [32, 32, 32, 32, 64, 64, 64, 64], "head_channels": 128, "descriptor_dim": 256},
}
WEIGHTS_DIR = Path(__file__).resolve().parents[2] / "weights"  # package data: evio_lib/weights/*.pt
#: the shipped weights SuperPointDetector() loads: the same as create_detector("superpoint") (features.base)
DEFAULT_WEIGHTS = SUPERPOINT_DEFAULT_WEIGHTS
# How shipped weights are made (the training chain); quoted by the missing-weights error.
TRAINING_COMMAND = (
    "python -m evio_lib features-train pretrained_detdesc_round1 --chain  (writes "
    "runs/features/pretrained_detdesc_round1/best.pt, the network the default weights are fine-tuned from; copy it "
    "to evio_lib/weights/ under the weights name; docs/howto/train-features.md gives every shipped file's commands, "
    "the fine-tuning on photographs among them)"
)
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
