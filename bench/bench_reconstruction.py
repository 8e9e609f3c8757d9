"""Print the reconstruction rate (frames/s) at 240x180, batch 1, state carried, for every method.

Usage:  python bench/bench_reconstruction.py [--frames N] [--threads T] [--variants]

Each frame is one window of N_e = 0.35 * 240 * 180 events (uniform random events, seed 0); the rate includes building
the voxel grid. The large E2VID-style network runs with random weights (none are shipped): its speed does not depend on
them. FireNet runs in each precision (float32; bfloat16; int8, what the default precision "auto" picks on an x86
CPU). Goal: at least 100 frames/s on a 2-core CPU; the measured rates are in docs/results/reconstruction.md#speed.

``--variants`` also times FireNet's forward pass alone (state carried, on the same voxel grids) in the variants tried
for that goal, with each one's largest difference from the eager float32 network's images:
``eager`` (FireNet as trained), ``channels_last`` (the same module in channels-last memory), ``fast`` (the
FireNetInference the reconstructor uses: channels-last, split GRU convolutions, tanh via sigmoid, in-place steps),
``bf16`` (autocast to bfloat16: about twice as fast on CPUs with AVX512-BF16, but 5e-3 off, over the 1e-3 allowed),
``jit`` (torch.jit.trace + freeze) and ``compile`` (torch.compile with inductor freezing; tens of seconds to compile).
Measured 2026-11-27 on the idle 2-core AMD EPYC (AVX-512), ms per frame with 1 / 2 threads: eager 51.0 / 32.6,
channels_last 45.5 / 26.4, fast 44.4 / 22.1, bf16 28.3 / 15.5 (max diff 3.1e-3), jit 49.9 / 27.3, compile 42.0 /
25.4; the convolutions alone take 32-33 ms on one thread (1.62 G multiply-adds per frame): 100 frames/s on two cores
is out of reach for this network in float32 (docs/results/reconstruction.md#speed, Speed).
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from evio_lib.events.array import make_events
from evio_lib.events.reconstruct import create_reconstructor
from evio_lib.events.reconstruction.nets import E2VIDRecurrent
from evio_lib.events.representations import voxel_grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--variants", action="store_true", help="also time the FireNet forward-pass variants")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    w, h = 240, 180
    n = int(0.35 * w * h)
    rng = np.random.default_rng(0)
    windows = [make_events(np.sort(rng.uniform(k, k + 1, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                           rng.choice([-1, 1], n)) for k in range(args.frames)]
    methods = {name: create_reconstructor(name, w, h) for name in ("direct", "high_pass")}
    for precision in ("float32", "bfloat16", "int8"):   # the default "auto" is int8 on x86 CPUs, else float32
        methods[f"firenet ({precision})"] = create_reconstructor("firenet", w, h, precision=precision)
    with tempfile.TemporaryDirectory() as folder:  # a random-weight E2VID-style UNet, loaded the way users load one
        path = Path(folder) / "e2vid_random.pt"
        torch.save({"format": "evio-reconstructor-v1", "architecture": "e2vid", "network_options": {}, "num_bins": 5,
                    "state_dict": E2VIDRecurrent().state_dict()}, path)
        methods["e2vid"] = create_reconstructor("learned", w, h, checkpoint=path, device="cpu")
    voxel_grid(windows[0], w, h, 5)  # warm-up: the normalisation's kernels compile (or load) on first use
    start = time.perf_counter()
    for window in windows:
        voxel_grid(window, w, h, 5)
    print(f"{'voxel grid alone':24s} {args.frames / (time.perf_counter() - start):8.1f} frames/s")
    for name, rec in methods.items():
        for window in windows[:2]:  # warm-up: allocations, and int8's kernels (the second window compiles the GRU's)
            rec.reconstruct(window)
        rec.reset()
        count = args.frames if name != "e2vid" else max(3, args.frames // 10)
        start = time.perf_counter()
        for window in windows[:count]:
            rec.reconstruct(window)
        rate = count / (time.perf_counter() - start)
        print(f"{name:24s} {rate:8.1f} frames/s  ({1e3 / rate:.1f} ms per frame, {args.threads} threads)")
    if args.variants:
        grids = [torch.from_numpy(voxel_grid(window, w, h, 5))[None] for window in windows]
        net = methods["firenet (float32)"].net
        reference = _forward_all(net, grids)
        for name, forward in _variants(net, grids[0]).items():
            images = _forward_all(forward, grids)
            diff = max(float((a.float() - b).abs().max()) for a, b in zip(images, reference))
            start = time.perf_counter()
            _forward_all(forward, grids)
            rate = len(grids) / (time.perf_counter() - start)
            print(f"firenet forward: {name:14s} {rate:8.1f} frames/s  ({1e3 / rate:.1f} ms per frame, "
                  f"{args.threads} threads)  max |diff| from eager {diff:.1e}")


def _forward_all(forward, grids: list) -> list:
    """Return the images of ``forward`` over ``grids``, state carried from the first."""
    images, state = [], None
    with torch.inference_mode():
        for grid in grids:
            image, state = forward(grid, state)
            images.append(image.float().clone())
    return images


def _variants(net, example) -> dict:
    """Return name -> forward(voxels, state) for each variant of FireNet's forward pass."""
    import copy

    from evio_lib.events.reconstruction.nets import FireNetInference

    last = torch.channels_last
    cl_net = copy.deepcopy(net).to(memory_format=last)

    from evio_lib.events.reconstruction.nets import AutocastForward

    bf16 = AutocastForward(net)  # precision="bfloat16" of the reconstructor

    class _Pair(torch.nn.Module):  # trace the two calls: the first frame (no state) and the later ones
        def __init__(self, inner):
            super().__init__()
            self.inner = inner

        def forward(self, voxels, h1, h2):
            image, (h1, h2) = self.inner(voxels, [h1, h2])
            return image, h1, h2

    with torch.inference_mode(False), torch.no_grad():
        _, first_state = net(example)
        traced = torch.jit.freeze(torch.jit.trace(_Pair(copy.deepcopy(net)).eval(), (example, *first_state)))

    def jit(voxels, state):
        if state is None:
            return net(voxels, None)
        image, h1, h2 = traced(voxels, *state)
        return image, [h1, h2]

    variants = {"eager": net, "channels_last": lambda v, s: cl_net(v.contiguous(memory_format=last), s),
                "fast": FireNetInference(net), "bf16": bf16, "jit": jit}
    try:
        import torch._inductor.config as inductor_config

        inductor_config.freezing = True
        compiled = torch.compile(copy.deepcopy(net), dynamic=False)
        with torch.inference_mode():
            _forward_all(compiled, [example, example])  # compile both calls before timing
        variants["compile"] = compiled
    except Exception as error:  # no C++ compiler, or an inductor failure: say so and go on
        print(f"torch.compile unavailable here ({type(error).__name__}: {error})")
    return variants


if __name__ == "__main__":
    main()
