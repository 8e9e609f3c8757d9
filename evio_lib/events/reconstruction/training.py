"""Training the recurrent reconstructors on simulated sequences (a training set, or quick planar samples).

Loss over a sample of L consecutive windows, with the network's state carried from window to window (truncated
back-propagation through time over L windows, from a zero state):

    loss = 1/L sum_k [ |I^_k - I_k|_1  +  lambda_ssim (1 - SSIM(I^_k, I_k))  +  lambda_tc TC_k ]

- L1 and SSIM (Wang et al. 2004; Gaussian window sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, data range 1) against the sharp
  intensity I_k at the end of window k;
- optionally (``lambda_stretched`` > 0) the same L1 and SSIM terms between the 1st/99th-percentile stretches of
  prediction and truth, S(x) = clip((x - q01(x)) / max(q99(x) - q01(x), 0.05), 0, 1), the normalisation under which the
  reconstructions are scored (:func:`evio_lib.events.reconstruction.evaluation.normalize_for_metrics`): events fix
  intensity only up to an offset and a gain, so this term asks for the structure the metric rewards and leaves the
  unobservable global brightness and contrast to the raw terms (gradients flow through the prediction's quantiles);
- temporal consistency (Lai et al., ECCV 2018, as E2VID+ uses it): TC_k = mean( M_k . |I^_k - W_k(I^_k-1)| ), where W_k
  warps the previous prediction into view k with the true motion (the simulator's homography) and
  M_k = exp(-alpha |I_k - W_k(I_k-1)|^2), alpha = 50, masks pixels where the warp does not explain the true images
  (occlusions, borders). With ``tc_detail_sigma`` s > 0 the term sees only the detail of the difference d,
  TC_k = mean( M_k . |d - G_s * (M_k d) / G_s * M_k| ), d = I^_k - W_k(I^_k-1), G_s a Gaussian of s pixels:
  texture that flickers from window to window is penalised, while a region's overall brightness, which events do
  not fix, may still be corrected from one window to the next. The true motion is a flow field per window,
  W_k(I)(u) = I(u + flow_k(u)): a training set (:mod:`evio_lib.events.reconstruction.training_set`) stores it, and a
  planar sample's homography gives it as
  flow_k(u) = pi(H u) - u.

Data come from a training set folder (``training_set``: every sequence of its ``train`` split, validation on its ``val``
split), joined by the ``train`` splits of ``extra_training_sets`` if given (each step draws uniformly over all their
sequences; the sets may differ in image size, each sample then cropped inside its own image), or, without one, from
:func:`~evio_lib.events.reconstruction.data.reconstruction_dataset`'s planar samples.
Augmentation per step: a random crop, horizontal and vertical flips (the flow's components negated to match), and with
probability ``time_reversal`` the batch played backwards: window order and voxel bins reversed and the polarity negated
(events at T - t with -p are the events of the reversed video), each window's label the image at its new end (the
previous window's end: one window fewer), and no temporal-consistency term (the stored flow points the other way).
A polarity swap alone is not used: it stands for the negated log image, whose linear intensity 1/I is not an image in
[0, 1] the network can output.
With probability ``warm_start`` (default 0) a batch starts from a recurrent state another batch left, not from an
empty one, so that it learns to overwrite a stale image. ``warm_start_from`` says which: ``"other"`` (default) runs
the network without gradients over another random batch (:func:`warm_state`); ``"previous"`` takes the state the
previous training step's batch ended in (detached, no extra pass), so runs of warm draws chain batches and the state
a batch starts from can be many sequences old (a chain is on average 1 / (1 - warm_start) batches long), as on a long
recording. A resumed run starts its chain afresh.

The learning rate is constant or (``lr_schedule="cosine"``) follows lr_k = lr_min + (lr - lr_min)(1 + cos(pi k / steps)) / 2
with lr_min = ``lr_final_fraction`` lr, a function of the step alone (so ``--resume`` continues the same schedule).

The checkpoint kept as ``best.pt`` is the one with the highest validation SSIM: raw (``select_by="ssim"``, the
default) or after the stretch S above (``select_by="ssim_stretched"``, the form of the benchmark's metric).

E2VID's perceptual LPIPS term needs an ImageNet-pretrained VGG/AlexNet, whose weights cannot be downloaded here; it is
left out rather than imitated.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from torch.nn import functional as F

from evio_lib.events.reconstruction.data import ReconstructionDataConfig, reconstruction_dataset
from evio_lib.events.reconstruction.training_set import MANIFEST_NAME, load_sequence, read_training_set
from evio_lib.events.reconstruction.nets import build_network, count_parameters
from evio_lib.cli_args import parse_set_options, settings_from_dict
from evio_lib.io.checkpoint import load_state, read_checkpoint
from evio_lib.events.reconstruction.training_options import add_reconstruct_train_arguments  # no torch

__all__ = ["ReconstructionTrainConfig", "LR_SCHEDULES", "SELECTION_METRICS", "WARM_START_SOURCES", "ssim_torch",
           "stretch_torch", "learning_rate", "warp_with_homography", "warp_with_flow", "flow_from_homographies",
           "temporal_consistency_loss", "SequenceSource", "open_split", "sequence_loss", "train_reconstructor",
           "evaluate_on_samples", "add_reconstruct_train_arguments", "main_reconstruct_train"]


LR_SCHEDULES = ("constant", "cosine")
SELECTION_METRICS = ("ssim", "ssim_stretched")
WARM_START_SOURCES = ("other", "previous")
#: Smallest percentile spread the stretch divides by: a nearly flat crop is not blown up into amplified noise.
STRETCH_MIN_SPREAD = 0.05


@dataclass(frozen=True)
class ReconstructionTrainConfig:
    """Every setting of a reconstructor training run (saved in each checkpoint)."""

    architecture: str = "firenet"
    network_options: dict = field(default_factory=dict)
    data: ReconstructionDataConfig = field(default_factory=ReconstructionDataConfig)
    n_train: int = 400                 # training samples of L windows (each its own simulated sequence)
    n_val: int = 32
    batch_size: int = 4
    crop: int = 48                     # random square crops of the samples (and flips) per step
    lr: float = 1e-3
    steps: int = 3000                  # the default schedule (time per step: docs/howto/train-reconstructor.md)
    max_minutes: float | None = None   # wall-clock budget of one call; --resume continues
    lambda_ssim: float = 1.0
    lambda_tc: float = 1.0
    tc_alpha: float = 50.0
    tc_detail_sigma: float = 0.0       # > 0: the consistency term sees only detail finer than a Gaussian of this (px)
    validate_every: int = 250
    seed: int = 0
    threads: int = 1                   # torch threads: 1 is fastest on a loaded 2-core machine (OpenMP spin-waits)
    device: str = "cpu"
    init_from: str | None = None       # a reconstruct-train checkpoint whose weights start the run (fine-tuning)
    training_set: str | None = None    # a reconstruct-data folder; None: planar samples drawn by `data`, n_train, n_val
    extra_training_sets: list = field(default_factory=list)  # more folders whose train splits join training_set's
    time_reversal: float = 0.2         # probability of playing a batch backwards
    preload: bool = False              # read the whole training set into memory first (fast steps on a GPU)
    lambda_stretched: float = 0.0      # weight of L1 + (1 - SSIM) between the percentile-stretched images
    lr_schedule: str = "constant"      # or "cosine": lr decays to lr_final_fraction * lr over `steps`
    lr_final_fraction: float = 0.05
    select_by: str = "ssim"            # validation metric of best.pt: "ssim" (raw) or "ssim_stretched"
    warm_start: float = 0.0            # probability that a batch starts from the state another batch left behind
    warm_start_from: str = "other"     # that batch: "other" (a random one, run without gradients) or "previous"

    def __post_init__(self) -> None:
        if isinstance(self.data, dict):
            object.__setattr__(self, "data", ReconstructionDataConfig(**self.data))
        for name in ("n_train", "n_val", "batch_size", "steps", "validate_every", "threads", "crop"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer; got {value!r}")
        if not (np.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"lr must be > 0; got {self.lr!r}")
        if self.max_minutes is not None and not (np.isfinite(self.max_minutes) and self.max_minutes > 0):
            raise ValueError(f"max_minutes must be > 0 when given; got {self.max_minutes!r}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0; got {self.seed}")
        build_network(self.architecture, self.data.num_bins, **self.network_options)  # fails early on a bad name
        if self.init_from is not None and not Path(self.init_from).is_file():
            raise ValueError(f"init_from must be a reconstruct-train checkpoint file; {self.init_from!r} does not exist")
        if isinstance(self.tc_detail_sigma, bool) or not (np.isfinite(self.tc_detail_sigma)
                                                          and 0 <= self.tc_detail_sigma <= 8):
            raise ValueError(f"tc_detail_sigma must lie in [0, 8] pixels (0: the whole difference); got "
                             f"{self.tc_detail_sigma!r}")
        if _blur_radius(self.tc_detail_sigma) >= self.crop:
            raise ValueError(f"tc_detail_sigma = {self.tc_detail_sigma:g} needs a blur of radius "
                             f"{_blur_radius(self.tc_detail_sigma)} px, which a crop of {self.crop} px cannot "
                             f"hold: a smaller tc_detail_sigma or a larger crop")
        if not (np.isfinite(self.lambda_stretched) and self.lambda_stretched >= 0):
            raise ValueError(f"lambda_stretched must be >= 0; got {self.lambda_stretched!r}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"lr_schedule must be one of {LR_SCHEDULES}; got {self.lr_schedule!r}")
        if not (np.isfinite(self.lr_final_fraction) and 0 <= self.lr_final_fraction <= 1):
            raise ValueError(f"lr_final_fraction must lie in [0, 1]; got {self.lr_final_fraction!r}")
        if self.select_by not in SELECTION_METRICS:
            raise ValueError(f"select_by must be one of {SELECTION_METRICS}; got {self.select_by!r}")
        if not (np.isfinite(self.time_reversal) and 0 <= self.time_reversal <= 1):
            raise ValueError(f"time_reversal must be a probability in [0, 1]; got {self.time_reversal!r}")
        if isinstance(self.warm_start, bool) or not (np.isfinite(self.warm_start) and 0 <= self.warm_start <= 1):
            raise ValueError(f"warm_start must be a probability in [0, 1]; got {self.warm_start!r}")
        if self.warm_start_from not in WARM_START_SOURCES:
            raise ValueError(f"warm_start_from must be one of {WARM_START_SOURCES}; got {self.warm_start_from!r}")
        if self.extra_training_sets and self.training_set is None:
            raise ValueError("extra_training_sets needs training_set (the folder whose val split validates the run)")
        if self.training_set is not None:
            _, data = read_training_set(self.training_set, "train")   # refuses a folder that is no complete set
            if data.num_bins != self.data.num_bins:
                raise ValueError(f"the training set {self.training_set} has {data.num_bins} voxel bins; this run's "
                                 f"network takes data.num_bins = {self.data.num_bins}")
            sizes = {(data.height, data.width)}
            for folder in self.extra_training_sets:
                _, extra = read_training_set(folder, "train")
                if (extra.windows, extra.num_bins) != (data.windows, data.num_bins):
                    raise ValueError(f"the training set {folder} has {extra.windows} windows of {extra.num_bins} "
                                     f"bins per sequence; {self.training_set} has {data.windows} of {data.num_bins}: "
                                     f"sets trained on together must agree on both")
                sizes.add((extra.height, extra.width))
            smallest = min(min(size) for size in sizes)
            if len(sizes) > 1 and self.crop > smallest:
                raise ValueError(f"crop = {self.crop} is larger than the smallest sequences ({smallest} pixels on a "
                                 f"side) of sets of different sizes ({sorted(sizes)}); their crops must be equal to "
                                 f"be batched: --set crop=N with N <= {smallest}")

    def to_dict(self) -> dict:
        """Return the config as plain JSON-able values."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> "ReconstructionTrainConfig":
        """Return a config from :meth:`to_dict`'s output, refusing unknown keys."""
        return settings_from_dict(cls, values, "reconstruction training settings")


def _gaussian_kernel_1d(size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Return the normalised 1-D Gaussian g of SSIM's window (the 2-D window is the outer product g g^T)."""
    x = torch.arange(size, dtype=torch.float32) - (size - 1) / 2
    g = torch.exp(-x ** 2 / (2 * sigma ** 2))
    return g / g.sum()


def ssim_torch(a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Return the mean SSIM of two (N, 1, H, W) image batches (differentiable; 'valid' windows only).

    SSIM = (2 mu_a mu_b + C1)(2 sigma_ab + C2) / ((mu_a^2 + mu_b^2 + C1)(sigma_a^2 + sigma_b^2 + C2)), Gaussian
    sigma = 1.5, C1 = (0.01 L)^2, C2 = (0.03 L)^2: scikit-image's ``structural_similarity(gaussian_weights=True,
    use_sample_covariance=False)`` on the same 'valid' region.

    The five local means (of a, b, a^2, b^2, a b) are one grouped convolution with the separable 11 x 11 Gaussian,
    as an 11 x 1 and a 1 x 11 pass: the same sums as the 2-D window, and with its backward pass much faster on the
    CPU than five 2-D 11 x 11 convolutions (measured: docs/results/speed.md#small-costs-behind-the-codes-choices).
    """
    g = _gaussian_kernel_1d().to(a.device, a.dtype)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    maps = torch.cat([a, b, a * a, b * b, a * b], dim=1)                             # (N, 5, H, W)
    means = F.conv2d(F.conv2d(maps, g.view(1, 1, -1, 1).expand(5, 1, -1, 1), groups=5),
                     g.view(1, 1, 1, -1).expand(5, 1, 1, -1), groups=5)
    mu_a, mu_b, aa, bb, ab = means.unbind(dim=1)
    var_a, var_b, cov = aa - mu_a ** 2, bb - mu_b ** 2, ab - mu_a * mu_b
    ssim_map = (2 * mu_a * mu_b + c1) * (2 * cov + c2) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))
    return ssim_map.mean()


def stretch_torch(image: torch.Tensor, min_spread: float = STRETCH_MIN_SPREAD) -> torch.Tensor:
    """Return each (H, W) image of an (N, 1, H, W) batch stretched so its 1st/99th percentiles become 0/1 (clipped).

    The differentiable form of :func:`~evio_lib.events.reconstruction.evaluation.normalize_for_metrics` (the same
    linearly interpolated percentiles), except that the spread is at least ``min_spread``.
    """
    flat = image.flatten(1)
    q = torch.quantile(flat, torch.tensor([0.01, 0.99], dtype=image.dtype, device=image.device), dim=1)
    lo, hi = q[0].view(-1, 1, 1, 1), q[1].view(-1, 1, 1, 1)
    return ((image - lo) / (hi - lo).clamp(min=min_spread)).clamp(0.0, 1.0)


def learning_rate(config: "ReconstructionTrainConfig", step: int) -> float:
    """Return the learning rate of optimisation step ``step`` (0-based) under the config's schedule.

    >>> cfg = ReconstructionTrainConfig(lr=1e-3, steps=100, lr_schedule="cosine", lr_final_fraction=0.1)
    >>> [round(learning_rate(cfg, k), 6) for k in (0, 50, 100)]
    [0.001, 0.00055, 0.0001]
    """
    if config.lr_schedule == "constant":
        return config.lr
    low = config.lr_final_fraction * config.lr
    progress = min(max(step / config.steps, 0.0), 1.0)
    return low + (config.lr - low) * 0.5 * (1.0 + math.cos(math.pi * progress))


def warp_with_homography(image: torch.Tensor, H_cur_to_prev: torch.Tensor) -> torch.Tensor:
    """Return ``image`` (the previous view, (N, C, H, W)) resampled into the current view: out(u) = image(H u).

    ``H_cur_to_prev`` (N, 3, 3) maps current-view pixels (x, y, 1) into the previous view. Outside samples are zero.
    """
    n, _, h, w = image.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=image.dtype, device=image.device),
                            torch.arange(w, dtype=image.dtype, device=image.device), indexing="ij")
    pts = torch.stack([xs, ys, torch.ones_like(xs)], dim=-1).reshape(1, -1, 3)           # (1, HW, 3)
    mapped = pts @ H_cur_to_prev.to(image.dtype).transpose(1, 2)                           # (N, HW, 3)
    xy = mapped[..., :2] / mapped[..., 2:3].clamp(min=1e-6)
    grid = torch.stack([2 * xy[..., 0] / (w - 1) - 1, 2 * xy[..., 1] / (h - 1) - 1], dim=-1).reshape(n, h, w, 2)
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros", align_corners=True)


def warp_with_flow(image: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """Return ``image`` (the previous view, (N, C, H, W)) resampled into the current view: out(u) = image(u + flow(u)).

    ``flow`` (N, 2, H, W) holds (dx, dy) in pixels from each current-view pixel to its place in the previous view.
    Outside samples are zero.
    """
    n, _, h, w = image.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=image.dtype, device=image.device),
                            torch.arange(w, dtype=image.dtype, device=image.device), indexing="ij")
    x = xs + flow[:, 0].to(image.dtype)
    y = ys + flow[:, 1].to(image.dtype)
    grid = torch.stack([2 * x / (w - 1) - 1, 2 * y / (h - 1) - 1], dim=-1)
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros", align_corners=True)


def flow_from_homographies(H_cur_to_prev: np.ndarray, height: int, width: int) -> np.ndarray:
    """Return (..., 2, H, W) float16 flows pi(H u) - u of (..., 3, 3) homographies mapping current into previous pixels."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    pts = np.stack([xs, ys, np.ones_like(xs)]).reshape(3, -1)
    mapped = np.asarray(H_cur_to_prev, np.float64) @ pts                         # (..., 3, HW)
    xy = mapped[..., :2, :] / np.maximum(mapped[..., 2:3, :], 1e-6)
    return (xy - pts[:2]).reshape(*np.shape(H_cur_to_prev)[:-2], 2, height, width).astype(np.float16)


def temporal_consistency_loss(pred: torch.Tensor, pred_prev: torch.Tensor, frame: torch.Tensor, frame_prev: torch.Tensor,
                              flow: torch.Tensor, alpha: float = 50.0, detail_sigma: float = 0.0) -> torch.Tensor:
    """Return mean(M . |pred - W(pred_prev)|) with M = exp(-alpha |frame - W(frame_prev)|^2) (Lai et al. 2018).

    W warps the previous view into the current one with the true ``flow`` (N, 2, H, W) (:func:`warp_with_flow`); M is
    zero where a pixel's source lies outside the previous view. ``detail_sigma`` s > 0: mean(M . |d - L(d)|) for the
    difference d = pred - W(pred_prev), with L(d) = G_s * (M d) / G_s * M its local mean under a Gaussian of s pixels
    weighted by M (a normalised convolution, reflected at the image's border): the difference's detail, to which
    pixels the mask leaves out (occluded, outside the previous view) contribute nothing.
    """
    warped_pred = warp_with_flow(pred_prev, flow)
    with torch.no_grad():
        mask = torch.exp(-alpha * (frame - warp_with_flow(frame_prev, flow)) ** 2)
        mask = mask * (warp_with_flow(torch.ones_like(frame_prev), flow) > 0.999)
    difference = pred - warped_pred
    if detail_sigma > 0:
        with torch.no_grad():
            weight = _gaussian_blur_torch(mask, detail_sigma).clamp(min=1e-6)
        difference = difference - _gaussian_blur_torch(mask * difference, detail_sigma) / weight
    return (mask * difference.abs()).sum() / mask.sum().clamp(min=1.0)


def _blur_radius(sigma: float) -> int:
    """Return the radius in pixels of :func:`_gaussian_blur_torch`'s kernel: 3 sigma, rounded as scipy's truncate=3."""
    return int(3 * sigma + 0.5)


def _gaussian_blur_torch(image: torch.Tensor, sigma: float) -> torch.Tensor:
    """Return (N, 1, H, W) ``image`` blurred by a Gaussian of ``sigma`` pixels (3 sigma radius, reflected border)."""
    radius = _blur_radius(sigma)
    g = _gaussian_kernel_1d(2 * radius + 1, sigma).to(image.device, image.dtype)
    padded = F.pad(image, (radius, radius, radius, radius), mode="reflect")
    return F.conv2d(F.conv2d(padded, g.view(1, 1, -1, 1)), g.view(1, 1, 1, -1))


def sequence_loss(net: torch.nn.Module, voxels: torch.Tensor, frames: torch.Tensor, flow: torch.Tensor | None,
                  config: ReconstructionTrainConfig, state=None, final_state: list | None = None
                  ) -> tuple[torch.Tensor, dict[str, float]]:
    """Return (loss, parts) of one batch: voxels (N, L, B, H, W), frames (N, L, H, W), flow (N, L, 2, H, W) or None.

    ``flow=None`` leaves out the temporal-consistency term (a batch played backwards). ``state``: the network's
    recurrent state to start from (None: empty), e.g. the one another batch left behind (:func:`warm_state`).
    ``final_state``: a list that receives the state after the last window, detached (``warm_start_from="previous"``).
    """
    # the parts are summed on the device and read once at the end: a read per window would wait for a GPU each time
    prev, sums = None, {key: voxels.new_zeros(()) for key in ("l1", "ssim", "tc", "ssim_stretched")}
    total = voxels.new_zeros(())
    n_windows = voxels.shape[1]
    for k in range(n_windows):
        pred, state = net(voxels[:, k], state)
        target = frames[:, k:k + 1]
        l1 = (pred - target).abs().mean()
        ssim = ssim_torch(pred, target)
        loss = l1 + config.lambda_ssim * (1 - ssim)
        sums["l1"] = sums["l1"] + l1.detach()
        sums["ssim"] = sums["ssim"] + ssim.detach()
        if config.lambda_stretched > 0 or not torch.is_grad_enabled():   # always measured in validation
            pred_s = stretch_torch(pred)
            with torch.no_grad():
                target_s = stretch_torch(target)
            ssim_s = ssim_torch(pred_s, target_s)
            sums["ssim_stretched"] = sums["ssim_stretched"] + ssim_s.detach()
            if config.lambda_stretched > 0:
                loss = loss + config.lambda_stretched * ((pred_s - target_s).abs().mean() + 1 - ssim_s)
        if prev is not None and config.lambda_tc > 0 and flow is not None:
            tc = temporal_consistency_loss(pred, prev, target, frames[:, k - 1:k], flow[:, k], config.tc_alpha,
                                           config.tc_detail_sigma)
            loss = loss + config.lambda_tc * tc
            sums["tc"] = sums["tc"] + tc.detach()
        total = total + loss / n_windows
        prev = pred
    if final_state is not None:
        final_state.append(_detached(state))
    values = torch.stack(list(sums.values())).double().cpu().numpy() / n_windows
    return total, {key: float(value) for key, value in zip(sums, values)}


def _augment_batch(rng: np.random.Generator, voxels, frames, flow, crop: int, time_reversal: float = 0.0):
    """Return random crop x crop windows of the batch, flipped at random, and played backwards with ``time_reversal``.

    A crop keeps the flow (a displacement); a flip u' = (size - 1) - u negates its component along that axis. Played
    backwards (see the module docstring) the batch has one window fewer and no flow (None). The arrays are numpy
    arrays or torch tensors (a set held on the GPU); both draw the same random numbers and give the same values.
    Samples of different image sizes (sets trained on together) come as lists of per-sample arrays, each cropped
    inside its own image before the batch is stacked (``crop`` no larger than the smallest).
    """
    is_tensor = isinstance(voxels[0], torch.Tensor)
    stack = torch.stack if is_tensor else np.stack
    def flip(x, axes):
        return torch.flip(x, dims=axes) if is_tensor else np.flip(x, axis=axes)
    # one corner per sample, inside that sample's own image (a batch of sets of several sizes comes as lists)
    windows = []
    for i in range(len(voxels)):
        height, width = frames[i].shape[-2:]
        crop_h, crop_w = min(crop, height), min(crop, width)
        oy, ox = int(rng.integers(0, height - crop_h + 1)), int(rng.integers(0, width - crop_w + 1))
        windows.append((slice(oy, oy + crop_h), slice(ox, ox + crop_w)))
    voxels = stack([voxels[i][..., rows, cols] for i, (rows, cols) in enumerate(windows)])
    frames = stack([frames[i][..., rows, cols] for i, (rows, cols) in enumerate(windows)])
    flow = stack([flow[i][..., rows, cols] for i, (rows, cols) in enumerate(windows)])
    for i in range(voxels.shape[0]):
        for axis, component in ((-1, 0), (-2, 1)):
            if rng.random() < 0.5:
                voxels[i] = flip(voxels[i], (axis,))
                frames[i] = flip(frames[i], (axis,))
                flow[i] = flip(flow[i], (axis,))
                flow[i, :, component] *= -1
    if time_reversal > 0 and voxels.shape[1] > 1 and rng.random() < time_reversal:
        reversed_voxels = -flip(voxels[:, 1:], (1, 2))            # windows L-1..1, bins reversed, polarity negated
        reversed_frames = flip(frames[:, :-1], (1,))               # labels: the images at windows L-2..0
        if is_tensor:
            return reversed_voxels.contiguous(), reversed_frames.contiguous(), None
        return np.ascontiguousarray(reversed_voxels), np.ascontiguousarray(reversed_frames), None
    return voxels, frames, flow


def warm_state(net: torch.nn.Module, voxels: torch.Tensor):
    """Return the recurrent state ``net`` holds after the windows of ``voxels`` (N, L, B, H, W), without gradients.

    A batch started from it (``warm_start`` > 0) begins with another scene's image in the state: the network has to
    overwrite it, as on a long recording it has to recover from whatever its state holds. Training sequences
    otherwise always start empty, and a network never taught to recover may not (docs/results/reconstruction.md,
    "Over a long run").
    """
    state = None
    with torch.no_grad():
        for k in range(voxels.shape[1]):
            _, state = net(voxels[:, k], state)
    return state


def _detached(state):
    """A recurrent state (tensors nested in lists and tuples) cut from the graph that made it."""
    if isinstance(state, torch.Tensor):
        return state.detach()
    if isinstance(state, (list, tuple)):
        return type(state)(_detached(x) for x in state)
    return state


def _as_float_tensor(x, device: str) -> torch.Tensor | None:
    """A batch array (numpy, or a tensor already on its device) as float32 on ``device``."""
    if x is None:
        return None
    if isinstance(x, torch.Tensor):
        return x.to(device=device, dtype=torch.float32)
    return torch.from_numpy(x.astype(np.float32)).to(device)


_KEYS = ("voxels", "frames", "flow")


class SequenceSource:
    """Training or validation sequences, from a training-set folder or an in-memory stack of planar samples.

    ``len(source)`` sequences; ``source.take(indices)`` returns stacked (voxels, frames, flow) numpy arrays, or torch
    tensors on ``device`` when a preloaded set is held there (``device`` other than ``"cpu"``: a GPU's steps then
    crop and flip on the GPU instead of copying every batch from the host). Sequences of several image sizes (sets
    joined for training) cannot be stacked: they are held one by one, and a draw that mixes sizes is returned as
    three lists of per-sample arrays (:func:`_augment_batch` crops them to one size).
    """

    def __init__(self, paths: list[Path] | None = None, arrays: dict[str, np.ndarray] | None = None,
                 preload: bool = False, device: str = "cpu") -> None:
        self.paths = paths
        self.arrays = arrays
        self.sequences: list[dict] | None = None                # a preloaded set of several image sizes
        if arrays is not None and "flow" not in arrays:            # planar samples: homographies -> flows
            h, w = arrays["frames"].shape[-2:]
            self.arrays = {"voxels": arrays["voxels"], "frames": arrays["frames"],
                           "flow": flow_from_homographies(arrays["H_prev"], h, w)}
        if paths is not None and preload:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(8) as pool:                   # zlib decompression releases the GIL
                loaded = list(pool.map(load_sequence, paths))
            if len({x["frames"].shape for x in loaded}) == 1:
                self.arrays = {k: np.stack([x[k] for x in loaded]) for k in _KEYS}
            else:                                                  # several sizes: held one sequence at a time
                self.sequences = loaded
        self.device = device
        if self.arrays is not None and device != "cpu":
            self.arrays = {k: torch.from_numpy(np.ascontiguousarray(v)).to(device) for k, v in self.arrays.items()}
        if self.sequences is not None and device != "cpu":
            self.sequences = [{k: torch.from_numpy(np.ascontiguousarray(x[k])).to(device) for k in _KEYS}
                              for x in self.sequences]

    def __len__(self) -> int:
        if self.arrays is not None:
            return self.arrays["voxels"].shape[0]
        return len(self.sequences) if self.sequences is not None else len(self.paths)

    def take(self, indices) -> tuple:
        if self.arrays is not None:
            if self.device != "cpu":
                indices = torch.as_tensor(np.asarray(indices), device=self.device)
            return tuple(self.arrays[k][indices] for k in _KEYS)
        if self.sequences is not None:
            picked = [self.sequences[int(i)] for i in indices]
        else:
            picked = [load_sequence(self.paths[int(i)]) for i in indices]
        if len({tuple(x["frames"].shape) for x in picked}) > 1:      # sizes mixed: cropped before stacking
            return tuple([x[k] for x in picked] for k in _KEYS)
        stack = torch.stack if isinstance(picked[0]["frames"], torch.Tensor) else np.stack
        return tuple(stack([x[k] for x in picked]) for k in _KEYS)


def open_split(folder: str | Path | Sequence[str | Path], split: str, preload: bool = False,
               device: str = "cpu") -> SequenceSource:
    """Return the sequences of one split (``train``, ``val`` or ``test``) of a reconstruct-data training set, or of
    several sets together (a list of folders: their sequences one after the other); preloaded ones held on
    ``device``."""
    folders = [folder] if isinstance(folder, (str, Path)) else list(folder)
    return SequenceSource([path for f in folders for path in read_training_set(f, split)[0]], preload=preload,
                          device=device)


def _as_source(data) -> SequenceSource:
    return data if isinstance(data, SequenceSource) else SequenceSource(arrays=data)


def evaluate_on_samples(net: torch.nn.Module, data, config: ReconstructionTrainConfig,
                        batch_size: int = 8) -> dict[str, float]:
    """Return the mean loss parts (l1, ssim, tc) and loss of ``net`` on sequences, without gradients.

    ``data``: a stack of planar samples (:func:`reconstruction_dataset`) or a sequence source of a training set.
    """
    data = _as_source(data)
    sums, count = {"l1": 0.0, "ssim": 0.0, "tc": 0.0, "ssim_stretched": 0.0, "loss": 0.0}, 0
    was_training = net.training
    net.eval()
    with torch.no_grad():
        for i in range(0, len(data), batch_size):
            voxels, frames, flow = data.take(np.arange(i, min(i + batch_size, len(data))))
            v, f, w = (_as_float_tensor(x, config.device) for x in (voxels, frames, flow))
            loss, parts = sequence_loss(net, v, f, w, config)
            n = v.shape[0]
            for k in parts:
                sums[k] += parts[k] * n
            sums["loss"] += loss.item() * n
            count += n
    net.train(was_training)
    return {k: v / count for k, v in sums.items()}


#: Settings that may change between a run and its --resume (the budget, the hardware); all others must match.
_RESUMABLE_KEYS = ("steps", "max_minutes", "threads", "device", "validate_every")


def _run_defining(values: dict) -> dict:
    """Return the settings that define a run (everything but :data:`_RESUMABLE_KEYS`)."""
    return {k: v for k, v in values.items() if k not in _RESUMABLE_KEYS}


def _save(path: Path, net, optimizer, config: ReconstructionTrainConfig, step: int, history: list,
          rng: np.random.Generator, best: float, manifest: dict | None) -> None:
    """Write a checkpoint atomically (a temporary file, then rename); it records the training set's ``manifest`` (its
    settings, seed, counts and generator version), so the data can be made again."""
    tmp = path.with_suffix(".tmp")
    torch.save({"format": "evio-reconstructor-v1", "config": config.to_dict(), "architecture": config.architecture,
                "network_options": config.network_options, "num_bins": config.data.num_bins,
                "state_dict": net.state_dict(), "optimizer": optimizer.state_dict(), "step": step,
                "history": history, "rng": rng.bit_generator.state, "best_val_ssim": best,
                "training_set_manifest": manifest}, tmp)
    tmp.replace(path)


def _load_initial_weights(net: torch.nn.Module, config: ReconstructionTrainConfig) -> None:
    """Copy the weights of ``config.init_from`` into ``net``, refusing a checkpoint of another network."""
    try:  # a missing, empty, truncated, foreign or SuperPoint file: one line naming it
        ckpt = read_checkpoint(config.init_from, "reconstructor", map_location=config.device, weights_only=True)
    except ValueError as error:
        raise ValueError(f"init_from {error}") from None
    theirs = (ckpt.get("architecture"), ckpt.get("num_bins"), ckpt.get("network_options", {}))
    ours = (config.architecture, config.data.num_bins, config.network_options)
    if theirs != ours:
        raise ValueError(f"init_from {config.init_from} holds a {theirs[0]} network with {theirs[1]} bins and options "
                         f"{theirs[2]}; this run trains a {ours[0]} with {ours[1]} bins and options {ours[2]}")
    try:
        load_state(net, ckpt["state_dict"], config.init_from,
                   f"its state_dict does not fit this run's {config.architecture} network")
    except ValueError as error:
        raise ValueError(f"init_from {error}") from None


def train_reconstructor(config: ReconstructionTrainConfig, out: str | Path, resume: bool = False,
                        progress: bool = True, data: dict | None = None, val_data: dict | None = None) -> dict:
    """Train a reconstructor; write ``last.pt``, ``best.pt`` (highest validation SSIM) and ``history.json`` in ``out``.

    Returns a summary: steps done, minutes, final and best validation metrics. With ``resume`` the run continues from
    ``out/last.pt`` (same config required) and gives the same result as an uninterrupted run of the same total steps.

    Args:
        config: the run's settings.
        out: the run folder (created).
        resume: continue from ``out/last.pt``.
        progress: show a tqdm progress bar.
        data, val_data: pre-made sample stacks (tests); default: the training set's train and val splits, or without
            one :func:`reconstruction_dataset`'s planar samples.
    """
    out = Path(out)
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    net = build_network(config.architecture, config.data.num_bins, **config.network_options).to(config.device)
    if config.device == "cpu":   # oneDNN's convolutions without reorders: a faster training step (speed.md: small costs)
        net = net.to(memory_format=torch.channels_last)
    optimizer = torch.optim.Adam(net.parameters(), lr=config.lr)
    rng = np.random.default_rng(config.seed)
    step, history, best = 0, [], -math.inf
    last = out / "last.pt"
    if config.init_from is not None and not resume:
        _load_initial_weights(net, config)
    if resume:
        if not last.is_file():
            raise FileNotFoundError(f"--resume: no checkpoint {last} to continue from")
        try:  # a damaged last.pt (e.g. a full disk) is one line naming it
            ckpt = read_checkpoint(last, "reconstructor", map_location=config.device, weights_only=True)
        except ValueError as error:
            raise ValueError(f"--resume: {error}") from None
        missing = [key for key in ("config", "optimizer", "step", "history", "best_val_ssim", "rng") if key not in ckpt]
        if missing:
            raise ValueError(f"--resume: {last} lacks {missing}: not the last.pt of a reconstruct-train run "
                             f"(start a new --out folder)")
        if not isinstance(ckpt["config"], dict):
            raise ValueError(f"--resume: {last} holds no config; start a new --out folder")
        # a setting added after the run was saved had its default in effect (each default keeps the old behaviour)
        theirs = {**ReconstructionTrainConfig().to_dict(), **ckpt["config"]}
        if _run_defining(theirs) != _run_defining(config.to_dict()):
            raise ValueError(f"--resume: {last} was trained with a different config; start a new --out folder")
        if config.lr_schedule == "cosine" and theirs.get("steps") != config.steps:
            raise ValueError(f"--resume: {last} follows a cosine schedule over steps = {theirs.get('steps')}; resume "
                             f"with that --steps (another would move the schedule) or start a new --out folder")
        try:
            load_state(net, ckpt["state_dict"], last, f"its state_dict does not fit this run's {config.architecture} "
                       f"network")
            load_state(optimizer, ckpt["optimizer"], last, "its optimizer state does not fit this run's optimizer")
        except ValueError as error:
            raise ValueError(f"--resume: {error}") from None
        step, history, best = ckpt["step"], ckpt["history"], ckpt["best_val_ssim"]
        rng.bit_generator.state = ckpt["rng"]
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")
    if data is None and config.training_set is not None:
        data = open_split([config.training_set, *config.extra_training_sets], "train", preload=config.preload,
                          device=config.device)
    if val_data is None and config.training_set is not None:
        val_data = open_split(config.training_set, "val", preload=config.preload, device=config.device)
    if data is None:
        data = reconstruction_dataset("train", config.n_train, config.seed, config.data, progress=progress,
                                      workers=max(2, config.threads))
    if val_data is None:
        val_data = reconstruction_dataset("val", config.n_val, config.seed, config.data, progress=progress,
                                          workers=max(2, config.threads))
    data, val_data = _as_source(data), _as_source(val_data)
    manifest = None                                          # read once: every checkpoint records it
    if config.training_set is not None:
        manifest = json.loads((Path(config.training_set) / MANIFEST_NAME).read_text())
        if config.extra_training_sets:                       # the joined sets' manifests, in order
            manifest["extra_training_sets"] = [json.loads((Path(f) / MANIFEST_NAME).read_text())
                                               for f in config.extra_training_sets]
    n_train = len(data)
    start = time.perf_counter()
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=config.steps, initial=step, desc=f"training {config.architecture}", unit="step")
    running = None
    previous_state = None                                    # the state the last batch ended in (warm_start_from)
    try:
        while step < config.steps:
            idx = rng.integers(0, n_train, config.batch_size)
            v, f, w = _augment_batch(rng, *data.take(idx), config.crop, config.time_reversal)
            state = None                                     # no draw at warm_start = 0: older runs resume the same
            if config.warm_start > 0 and rng.random() < config.warm_start:
                if config.warm_start_from == "previous":
                    state = previous_state                   # None on a run's (or a resumed run's) first step
                else:
                    other = _augment_batch(rng, *data.take(rng.integers(0, n_train, config.batch_size)), config.crop,
                                           config.time_reversal)[0]
                    state = warm_state(net, _as_float_tensor(other, config.device))
            ended_in = [] if config.warm_start_from == "previous" else None
            loss, parts = sequence_loss(net, *(_as_float_tensor(x, config.device) for x in (v, f, w)), config,
                                        state=state, final_state=ended_in)
            previous_state = ended_in[0] if ended_in else None
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(config, step)
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
            optimizer.step()
            step += 1
            running = loss.item() if running is None else 0.98 * running + 0.02 * loss.item()
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{running:.3f}", ssim=f"{parts['ssim']:.3f}")
            out_of_time = config.max_minutes is not None and time.perf_counter() - start > 60 * config.max_minutes
            if step % config.validate_every == 0 or step == config.steps or out_of_time:
                val = evaluate_on_samples(net, val_data, config)
                history.append({"step": step, "train_loss": running, **{f"val_{k}": x for k, x in val.items()}})
                if val[config.select_by] > best:
                    best = val[config.select_by]
                    _save(out / "best.pt", net, optimizer, config, step, history, rng, best, manifest)
                _save(last, net, optimizer, config, step, history, rng, best, manifest)
                (out / "history.json").write_text(json.dumps(history, indent=1) + "\n")
            if out_of_time:
                break
    finally:
        if bar is not None:
            bar.close()
    return {"steps": step, "minutes": (time.perf_counter() - start) / 60, "best_val_ssim": best,
            "last": history[-1] if history else None, "parameters": count_parameters(net)}


def main_reconstruct_train(args: argparse.Namespace | Sequence[str] | None = None) -> int:
    """Run ``reconstruct-train`` (see :func:`add_reconstruct_train_arguments`); return the exit code."""
    if not isinstance(args, argparse.Namespace):
        args = add_reconstruct_train_arguments(argparse.ArgumentParser()).parse_args(args)
    values: dict = {"architecture": args.architecture, "seed": args.seed}
    if args.threads is not None:
        values["threads"] = args.threads
    if args.steps is not None:
        values["steps"] = args.steps
    if args.max_minutes is not None:
        values["max_minutes"] = args.max_minutes
    if args.device is not None:
        values["device"] = args.device
    if args.init_from is not None:
        values["init_from"] = str(args.init_from)
    if args.data:
        values["training_set"] = str(args.data[0])
        if len(args.data) > 1:
            values["extra_training_sets"] = [str(folder) for folder in args.data[1:]]
    values.update(parse_set_options(args.set))
    if values.get("seed", 0) < 0:
        raise ValueError(f"--seed must be >= 0; got {values['seed']}")
    config = ReconstructionTrainConfig.from_dict(values)
    out = Path(args.out)
    from evio_lib.io.output_dir import check_output_dir

    # not the working folder, no input nor inside one, a folder that can be created (OUT itself is --resume's input)
    inputs = [("the --init-from checkpoint", args.init_from)]
    inputs += [("the --data training set", folder) for folder in args.data or []]
    check_output_dir(out, force=True, name="--out", inputs=inputs)
    if not args.resume and out.exists() and any(out.iterdir()) and not args.force:
        raise ValueError(f"--out {out} is not empty; use --resume to continue the run there or --force to start afresh")
    print(f"training {config.architecture} ({count_parameters(build_network(config.architecture, config.data.num_bins))} "
          f"parameters) into {out}")
    summary = train_reconstructor(config, out, resume=args.resume, progress=not args.quiet)
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main_reconstruct_train(sys.argv[1:]))
