"""Run reconstructors' frames through the whole pipeline on validation seeds: RMSE and mean track length per run.

Usage:  python bench/reconstruction_in_pipeline.py --methods firenet RUN/best.pt [--jobs 2] [--quick]
        python bench/reconstruction_in_pipeline.py --methods firenet RUN/best.pt --extra-seeds 5 6 7 8 --jobs 2
        python bench/reconstruction_in_pipeline.py --methods firenet --precisions float32 int8 --jobs 2

SSIM scores frames one at a time; a tracker needs a corner to look the same from one window to the next. A
candidate network that scores higher SSIM can still give shorter tracks: stage 9 did (docs/archive.md,
"Stage 9"), so a reconstructor is shipped only if it also keeps the pipeline's track lengths here. For each
validation stretch (simulation seeds 3 and 4 and any ``--extra-seeds``, never the test seeds 0-2 of Table 6) and
each method, SIFT and KLT + FAST run on the method's event frames (`PipelineConfig(frames="events",
reconstructor=METHOD, reconstructor_precision=P)` for each P of ``--precisions``, float32 by default; the preset's
window fraction n). It prints one row per run, then each (method, precision) against the first, per front-end: the
geometric mean of its RMSE ratios with their standard error (as a factor) and their smallest and largest, in how
many runs its tracks were shorter, and the geometric mean of its track-length ratios. ``--extra-seeds S ...`` adds
the boxes_like and aerial_like stretches 0-8 s of more validation seeds (four runs per seed and network), for
when four stretches cannot tell two networks apart.

Single runs are chaotic (a diverging run moves the RMSE by 10x); the track lengths move far less, which is why both
are printed. The first call simulates the stretches with events and caches them; with them cached, two methods
took 2.8 min wall and 5.2 min CPU at ``--jobs 2`` on the 2-core machine (2026-12-04); with ``--extra-seeds 5 6``
(32 runs) 9.8 min wall, 17.6 min CPU, the four new stretches simulated in the same call; with ``--extra-seeds 5 6 7
8`` (48 runs, the reconstructor shipping rule's check) 3.9 min wall, 7.5 min CPU with every stretch cached (a 2-core
AMD EPYC with AVX-512, 2026-12-06). ``--quick`` runs the first stretch only, for 3 s (28 s wall).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

#: (preset, seed, start [s], duration [s]): validation stretches, the gentle start and a later, faster part
STRETCHES = (("boxes_like", 3, 0.0, 8.0), ("boxes_like", 4, 0.0, 8.0), ("aerial_like", 3, 0.0, 8.0),
             ("boxes_like", 3, 20.0, 6.0))
#: the seeds of Table 6's test runs (`evio_lib.pipeline.table`): never used to choose a reconstructor
TEST_SEEDS = (0, 1, 2)
FRONT_ENDS = {"SIFT": dict(features="sift"), "KLT + FAST": dict(tracker="klt", features="fast")}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["firenet"],
                        help="reconstructor names or reconstruct-train checkpoint files (.pt); the first is the "
                             "reference of the comparison")
    parser.add_argument("--precisions", nargs="+", default=["float32"], metavar="P",
                        help="the networks' arithmetic, each run for every method: float32, bfloat16, int8")
    parser.add_argument("--jobs", type=int, default=1, help="runs in parallel (one process each)")
    parser.add_argument("--extra-seeds", nargs="+", type=int, default=[], metavar="S",
                        help="more validation seeds, 5 or above: each adds boxes_like and aerial_like 0-8 s")
    parser.add_argument("--quick", action="store_true", help="the first stretch only, its first 3 s")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1; got {args.jobs}")
    problem = extra_seeds_problem(args.extra_seeds)
    if problem:
        parser.error(f"--extra-seeds {' '.join(map(str, args.extra_seeds))}: {problem}")
    if args.quick and args.extra_seeds:
        parser.error("--quick runs one short stretch; give it without --extra-seeds")
    from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipelines

    repeated = sorted({m for m in args.methods if args.methods.count(m) > 1})
    if repeated:
        parser.error(f"--methods lists {', '.join(repeated)} more than once; give each method once")
    names = _names(args.methods)
    def _label(method: str, precision: str) -> str:   # a method's name in the table, its precision unless float32
        return names[method] if precision == "float32" else f"{names[method]} ({precision})"
    variants = [_label(m, p) for m in args.methods for p in args.precisions]
    configs = {}  # "front-end | method" -> its configuration
    for method in args.methods:
        for precision in args.precisions:
            for front_end, options in FRONT_ENDS.items():
                try:
                    configs[f"{front_end} | {_label(method, precision)}"] = PipelineConfig(
                        frames="events", reconstructor=method, reconstructor_precision=precision, **options)
                except ValueError as error:
                    parser.error(f"--methods {method} --precisions {precision}: {error}")
    stretches = [(*STRETCHES[0][:3], 3.0)] if args.quick else stretches_for(args.extra_seeds)
    measured = {}  # (stretch, front-end, method) -> (RMSE, mean track length)
    print("| stretch | front-end | method | RMSE [m] | mean track length [frames] |")
    print("|---|---|---|---|---|")
    for preset, seed, start, duration in stretches:
        data = load_dataset(preset, seed=seed, start=start, duration=duration, need_events=True)
        results = run_pipelines(data, configs, jobs=args.jobs)
        stretch = f"{preset} seed {seed}, {start:g}-{start + duration:g} s"
        for name, r in results.items():
            front_end, method = name.split(" | ")
            rmse, tracks = float(r.metrics["rmse_m"]), float(np.mean(r.track_lengths))
            measured[stretch, front_end, method] = rmse, tracks
            print(f"| {stretch} | {front_end} | {method} | {rmse:.3f} | {tracks:.2f} |", flush=True)
    reference = variants[0]
    for method in variants[1:]:
        for front_end in FRONT_ENDS:
            pairs = [(measured[key], measured[key[0], front_end, method]) for key in measured
                     if key[1:] == (front_end, reference)]
            mean, error, low, high = ratio_summary([other[0] / ref[0] for ref, other in pairs])
            shorter = sum(other[1] < ref[1] for ref, other in pairs)
            tracks = ratio_summary([other[1] / ref[1] for ref, other in pairs])[0]
            print(f"{method} against {reference}, {front_end}: RMSE x{mean:.2f} (geometric mean over {len(pairs)} "
                  f"runs, standard error x{error:.2f}; runs x{low:.2f} to x{high:.2f}); tracks shorter in "
                  f"{shorter} of {len(pairs)}, their lengths x{tracks:.3f} (geometric mean)")
    return 0


def extra_seeds_problem(extra_seeds: list[int]) -> str | None:
    """What is wrong with ``--extra-seeds`` (None if nothing): each must be a distinct non-negative seed that is
    neither one of Table 6's test seeds nor one of the seeds ``STRETCHES`` already runs."""
    base_seeds = sorted({seed for _, seed, _, _ in STRETCHES})
    repeated = sorted({s for s in extra_seeds if extra_seeds.count(s) > 1})
    for bad, why in (([s for s in extra_seeds if s < 0], "seeds must be >= 0"),
                     ([s for s in extra_seeds if s in TEST_SEEDS],
                      f"the test seeds {', '.join(map(str, TEST_SEEDS))} never choose a reconstructor"),
                     ([s for s in extra_seeds if s in base_seeds],
                      f"the seeds {', '.join(map(str, base_seeds))} are run already"),
                     (repeated, "each seed may be given once")):
        if bad:
            return f"{', '.join(map(str, sorted(set(bad))))}: {why}; give validation seeds of 5 or above"
    return None


def stretches_for(extra_seeds: list[int]) -> list[tuple[str, int, float, float]]:
    """The four stretches of ``STRETCHES``, then boxes_like and aerial_like 0-8 s of each extra seed in turn."""
    return list(STRETCHES) + [(preset, seed, 0.0, 8.0) for seed in extra_seeds
                              for preset in ("boxes_like", "aerial_like")]


def ratio_summary(ratios: list[float]) -> tuple[float, float, float, float]:
    """Geometric mean of per-run ratios (RMSE, track length), its standard error as a factor, and the smallest and
    largest ratio.

    With r_i the ratios and l_i = ln r_i over n runs: mean = exp(mean(l)), error = exp(std(l, ddof=1) / sqrt(n))
    (1.0 for a single run). A mean of x1.3 with an error of x1.3 is one standard error from "no change"."""
    logs = np.log(np.asarray(ratios, dtype=float))
    error = math.exp(float(np.std(logs, ddof=1)) / math.sqrt(len(logs))) if len(logs) > 1 else 1.0
    return math.exp(float(np.mean(logs))), error, float(np.exp(logs.min())), float(np.exp(logs.max()))


def _names(methods: list[str]) -> dict[str, str]:
    """Each method's name in the table: a checkpoint by its file name, or by its path as given where two checkpoints
    share a file name (runs/a/best.pt and runs/b/best.pt); a reconstructor by its name."""
    short = {m: Path(m).name if Path(m).is_file() else m for m in methods}
    return {m: m if list(short.values()).count(short[m]) > 1 else short[m] for m in methods}


if __name__ == "__main__":
    sys.exit(main())
