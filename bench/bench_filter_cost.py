"""Benchmark: the MSCKF's cost per frame over a whole run, in stretches of a few seconds (is it flat?).

Runs the default pipeline (SIFT on the APS frames of ``boxes_like``, seed 0) and times every ``Msckf.process_image``
call with the process CPU clock (one thread for torch, OpenCV and BLAS, so the clock is the filter's own time). Prints
the run's summary and stage timings, then the mean filter milliseconds per frame in each stretch.

Usage: python bench/bench_filter_cost.py [--seconds 60] [--stretch 5] [--features sift]
Measured figures: docs/results/speed.md#the-filter.
"""
import argparse
import time

import numpy as np  # noqa: E402

from evio_lib.msckf.filter import Msckf  # noqa: E402
from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline  # noqa: E402
from evio_lib.threads import set_threads  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="seconds processed (default 60, the whole run)")
    parser.add_argument("--stretch", type=float, default=5.0, help="seconds per printed stretch (default 5)")
    parser.add_argument("--features", default="sift")
    args = parser.parse_args()
    set_threads(1)  # torch, OpenCV and BLAS (the filter's step limits BLAS to one thread anyway)
    calls: list[tuple[float, float]] = []
    timed = Msckf.process_image

    def process_image(self, t, *rest, **options):  # type: ignore[no-untyped-def]
        start = time.process_time()
        out = timed(self, t, *rest, **options)
        calls.append((t, time.process_time() - start))
        return out

    Msckf.process_image = process_image
    data = load_dataset("boxes_like", duration=60, seed=0)
    result = run_pipeline(data, PipelineConfig(features=args.features, max_duration=args.seconds))
    print(result.summary())
    print("stage seconds:", {k: round(v, 2) for k, v in result.timings.items()})
    t, cost = np.array(calls).T
    t0 = float(t.min())
    print(f"filter CPU ms per frame, stretches of {args.stretch:g} s:")
    for a in np.arange(0.0, args.seconds, args.stretch):
        inside = (t - t0 >= a) & (t - t0 < a + args.stretch)
        if inside.any():
            print(f"  {a:5.1f}-{a + args.stretch:5.1f} s: {1e3 * cost[inside].mean():5.1f} ms ({int(inside.sum())} frames)")


if __name__ == "__main__":
    main()
