"""Benchmark of the Synthetic Shapes generator: milliseconds per 120 x 160 image of ``generate_shape_image``.

Run from the repository root::

    python bench/bench_shapes.py               # 90 images (every kind in turn), best of 3 passes
    python bench/bench_shapes.py --images 300 --repeats 5

Target: >= 1 000 images per minute on one core, i.e. < 60 ms per image, so that MagicPoint's training
data can be drawn on the fly. A script, not a test: a wall-clock assertion fails on a loaded machine,
so the figure is printed. Reported: wall and CPU time (``time.process_time``, what one core
spends; less sensitive to other processes) per image, overall and per shape kind, best of the passes.

Measured (2-core machine shared with ~7 other jobs, 2026-11-25): 10.6 ms per image wall, 3.6 ms CPU (90 images,
best of 3; multiple_polygons the slowest kind at 11.3 ms CPU) -- about 5 700 images per minute by wall time, inside
the target. The verdict uses the CPU time.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: no BLAS / OpenMP threads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from evio_lib.features.training.shapes import SHAPE_KINDS, generate_shape_image  # noqa: E402

TARGET_MS = 60.0  # 1 000 images per minute


def time_images(n_images: int, shape: tuple[int, int], repeats: int) -> tuple[float, float, dict[str, float]]:
    """Return (wall ms per image, CPU ms per image, CPU ms per image of each kind), best of ``repeats`` passes."""
    best_wall = best_cpu = float("inf")
    best_kind: dict[str, float] = {}
    for _ in range(repeats):
        per_kind: dict[str, list[float]] = {kind: [] for kind in SHAPE_KINDS}
        wall0, cpu0 = time.perf_counter(), time.process_time()
        for i in range(n_images):
            kind = SHAPE_KINDS[i % len(SHAPE_KINDS)]
            c0 = time.process_time()
            generate_shape_image(kind, shape, i)  # seed i: the same images every run
            per_kind[kind].append(time.process_time() - c0)
        wall = (time.perf_counter() - wall0) / n_images * 1e3
        cpu = (time.process_time() - cpu0) / n_images * 1e3
        if cpu < best_cpu:
            best_wall, best_cpu = wall, cpu
            best_kind = {k: 1e3 * float(np.mean(v)) for k, v in per_kind.items() if v}
    return best_wall, best_cpu, best_kind


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=90, help="images per pass (kinds in turn)")
    parser.add_argument("--repeats", type=int, default=3, help="passes; the fastest (by CPU time) is reported")
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--width", type=int, default=160)
    args = parser.parse_args()
    if args.images < 1 or args.repeats < 1:
        parser.error("--images and --repeats must be >= 1")
    cv2.setNumThreads(1)
    wall, cpu, per_kind = time_images(args.images, (args.height, args.width), args.repeats)
    print(f"generate_shape_image {args.height}x{args.width}: {wall:.1f} ms per image wall, {cpu:.1f} ms CPU "
          f"({60e3 / wall:,.0f} images per minute by wall time; {args.images} images, best of {args.repeats})")
    for kind, ms in sorted(per_kind.items(), key=lambda kv: -kv[1]):
        print(f"  {kind:<22} {ms:6.1f} ms CPU")
    verdict = "within" if cpu < TARGET_MS else "OUTSIDE"
    print(f"target < {TARGET_MS:.0f} ms per image (1 000 images per minute): {verdict} the target")


if __name__ == "__main__":
    main()
