"""Figure and table: the position error of several frame sources over a whole preset, beside how fast the camera moves.

Runs each configuration on one simulated preset (cached; with events), then prints, per stretch of the recording,
the RMSE of each configuration together with the camera's mean speed and angular rate there, and saves a figure of
error against time with the motion below it (``plot_error_comparison(..., motion=...)``), so the reader sees where
each source gains or loses. One thread, as ``run`` uses by default.

Usage: python bench/error_vs_speed.py [--preset boxes_like] [--seed 0] [--stretch 10] [--aps-exposure S]
       [--speed FACTOR] [--out docs/figures/x.png]
Measured figures: docs/results/pipeline.md#faster-motion, "Motion-compensated event frames", "A longer APS exposure" and "Faster motion".
"""
import argparse
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import numpy as np  # noqa: E402

from evio_lib.evaluation.plots_pipeline import plot_error_comparison  # noqa: E402
from evio_lib.evaluation.trajectory_metrics import camera_motion  # noqa: E402
from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline  # noqa: E402

CONFIGS = {
    "KLT, APS frames": PipelineConfig(tracker="klt", features="fast"),
    "KLT, mc-events": PipelineConfig(tracker="klt", features="fast", frames="mc-events"),
    "KLT, APS + mc-events": PipelineConfig(tracker="klt", features="fast", frames="aps+mc-events"),
    "SIFT, APS frames": PipelineConfig(features="sift"),
    "SIFT, mc-events": PipelineConfig(features="sift", frames="mc-events"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="boxes_like", choices=["boxes_like", "aerial_like"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--stretch", type=float, default=10.0, help="seconds per row of the table (default 10)")
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--aps-exposure", type=float, default=None, metavar="SECONDS",
                        help="the simulated APS frames' exposure time (default: the simulator's 0.01 s)")
    parser.add_argument("--speed", type=float, default=None, metavar="FACTOR",
                        help="the preset's motion played this many times faster (default 1; run --speed)")
    parser.add_argument("--out", default=None, help="save the figure here (PNG)")
    args = parser.parse_args()
    data = load_dataset(args.preset, seed=args.seed, need_events=True, aps_exposure_s=args.aps_exposure,
                        speed=args.speed)
    results = {}
    for name in args.configs:
        results[name] = run_pipeline(data, PipelineConfig(**{**CONFIGS[name].__dict__, "seed": args.seed}))
        m = results[name].metrics
        print(f"{name:<22} {m['percent_of_distance']:6.2f} % of distance, RMSE {m['rmse_m']:.3f} m "
              f"(halves {m['rmse_first_half_m']:.3f} / {m['rmse_second_half_m']:.3f}), "
              f"{results[name].timings['realtime_factor']:.2f}x real time", flush=True)
    t_all = next(iter(results.values())).t
    edges = np.arange(t_all[0], t_all[-1] + 1e-9, args.stretch)
    if edges[-1] < t_all[-1]:  # the last, shorter stretch too
        edges = np.append(edges, t_all[-1] + 1e-9)
    t_grid = np.linspace(t_all[0], t_all[-1], 600)
    speed, rate = camera_motion(data.sequence, t_grid)
    print(f"\n{'stretch [s]':<12} {'speed':>6} {'rad/s':>6} | " + " | ".join(f"{n:>22}" for n in results))
    for a, b in zip(edges[:-1], edges[1:]):
        inside = (t_grid >= a) & (t_grid < b)
        cells = []
        for r in results.values():
            k = (r.t >= a) & (r.t < b)
            err = np.linalg.norm(r.p_IinG[k] - r.truth["p_IinG"][k], axis=1)
            cells.append(f"{np.sqrt(np.mean(err ** 2)) if k.any() else np.nan:>22.3f}")
        print(f"{a:5.0f}-{b:<5.0f}  {speed[inside].mean():6.2f} {rate[inside].mean():6.2f} | " + " | ".join(cells))
    if args.out:
        errors = {n: np.linalg.norm(r.p_IinG - r.truth["p_IinG"], axis=1) for n, r in results.items()}
        exposure = f", APS exposure {1e3 * args.aps_exposure:g} ms" if args.aps_exposure is not None else ""
        exposure += f", played at speed {args.speed:g}" if args.speed not in (None, 1.0) else ""
        fig = plot_error_comparison({n: r.t for n, r in results.items()}, errors, log=True,
                                    styles={n: "--" for n in results if "mc-events" in n},
                                    title=f"{args.preset}, seed {args.seed}{exposure}: position error (dashed: event "
                                          f"frames)",
                                    motion=(t_grid, speed, rate))
        fig.savefig(args.out, dpi=110)
        print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
