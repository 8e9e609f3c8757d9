"""Print the seconds per `reconstruct-train` optimisation step of FireNet on the CPU, as trained, and in two older forms.

Usage:  python bench/bench_reconstruction_training.py [--threads T] [--steps S] [--batch N] [--crop C] [--windows L]

One step is what `train_reconstructor` does per batch: N sequences of L windows (random voxel grids and images,
seed 0; the time does not depend on the values), the loss of `sequence_loss` with the stretched terms and the
temporal-consistency term (stage 3's recipe, `lambda_stretched=1`), backward, gradient clipping and Adam. Variants:

- ``shipped``: the library as it trains now: SSIM's Gaussian window as two separable passes of one grouped
  convolution over the five local-mean maps, the network in channels-last memory;
- ``nchw``: the same SSIM, the network in the default (NCHW) memory layout;
- ``ssim_2d``: NCHW and SSIM as five 2-D 11 x 11 convolutions (how `ssim_torch` was written until 2026-12-03).

Measured 2026-12-03 on this 2-core CPU (one thread, while a two-job pipeline table shared the machine, so these are
upper bounds): ssim_2d 6.75 s, nchw 4.91 s, shipped 4.20 s per step (batch 4, 48 x 48 crops, 40 windows). Run it on
an idle machine for your own figures (docs/howto/train-reconstructor.md#how-long-each-step-takes, "Training speed").
"""
from __future__ import annotations

import argparse
import time

import torch
from torch.nn import functional as F

import evio_lib.events.reconstruction.training as training
from evio_lib.events.reconstruction.nets import build_network


def ssim_2d(a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """SSIM with the 2-D Gaussian window as five separate convolutions: the form replaced on 2026-12-03."""
    g = training._gaussian_kernel_1d().to(a.device, a.dtype)
    window = (g[:, None] * g[None, :])[None, None]
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_a, mu_b = F.conv2d(a, window), F.conv2d(b, window)
    var_a = F.conv2d(a * a, window) - mu_a ** 2
    var_b = F.conv2d(b * b, window) - mu_b ** 2
    cov = F.conv2d(a * b, window) - mu_a * mu_b
    ssim_map = (2 * mu_a * mu_b + c1) * (2 * cov + c2) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))
    return ssim_map.mean()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--steps", type=int, default=3, help="timed steps per variant (after one untimed step)")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--crop", type=int, default=48)
    parser.add_argument("--windows", type=int, default=40)
    parser.add_argument("--variants", nargs="+", default=["shipped", "nchw", "ssim_2d"],
                        choices=["shipped", "nchw", "ssim_2d"])
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = training.ReconstructionTrainConfig(lambda_stretched=1.0)
    generator = torch.Generator().manual_seed(0)
    shape = (args.batch, args.windows)
    voxels = torch.randn(*shape, config.data.num_bins, args.crop, args.crop, generator=generator)
    frames = torch.rand(*shape, args.crop, args.crop, generator=generator)
    flow = torch.randn(*shape, 2, args.crop, args.crop, generator=generator)
    library_ssim = training.ssim_torch
    print(f"one step: batch {args.batch}, {args.crop} x {args.crop} crops, {args.windows} windows, "
          f"{args.threads} thread(s)")
    for variant in args.variants:
        training.ssim_torch = ssim_2d if variant == "ssim_2d" else library_ssim
        torch.manual_seed(0)
        net = build_network("firenet", config.data.num_bins)
        if variant == "shipped":
            net = net.to(memory_format=torch.channels_last)
        optimizer = torch.optim.Adam(net.parameters(), lr=1e-4)

        def step() -> None:
            loss, _ = training.sequence_loss(net, voxels, frames, flow, config)
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
            optimizer.step()

        try:
            step()
            cpu, wall = time.process_time(), time.perf_counter()
            for _ in range(args.steps):
                step()
            wall, cpu = (time.perf_counter() - wall) / args.steps, (time.process_time() - cpu) / args.steps
        finally:
            training.ssim_torch = library_ssim
        print(f"{variant:>8}: {wall:.2f} s per step ({cpu:.2f} s of CPU)")


if __name__ == "__main__":
    main()
