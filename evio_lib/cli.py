"""Command line of evio: ``python -m evio_lib COMMAND ...`` (see ``python -m evio_lib --help``)."""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path


def _cmd_course(args: argparse.Namespace) -> int:
    """Build the notebooks from their jupytext sources, execute them in order, optionally open JupyterLab."""
    from evio_lib import course

    sources = course.notebook_sources()
    if args.only:
        sources = [s for s in sources if any(s.name.startswith(prefix) for prefix in args.only)]
        if not sources:
            print(f"no notebook matches {args.only}; available: {[s.name for s in course.notebook_sources()]}", file=sys.stderr)
            return 2
    built = course.build_notebooks(sources)
    print(f"built {len(built)} notebooks into {course.BUILD_DIR}")
    if not args.no_execute:
        mode = "fast" if course.fast_mode() else "full"
        for path in built:
            start = time.perf_counter()
            print(f"executing {path.name} ({mode} mode) ...", flush=True)
            course.execute_notebook(path)
            print(f"  done in {time.perf_counter() - start:.1f} s")
    if args.open:
        return subprocess.call([sys.executable, "-m", "jupyter", "lab", str(course.BUILD_DIR)])
    print(f"open them with:  jupyter lab {course.BUILD_DIR}")
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    """Simulate a preset recording and write it in the ECD text layout (plus the simulator's sidecar files)."""
    from evio_lib.io.ecd import write_ecd
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence

    config = SimulationConfig(preset=args.preset, duration=args.duration, seed=args.seed,
                              with_events=not args.no_events, with_frames=not args.no_frames)
    print(config)
    start = time.perf_counter()
    sequence = simulate_sequence(config, progress=not args.quiet)
    print(f"simulated in {time.perf_counter() - start:.1f} s: {sequence.summary()}")
    write_ecd(sequence, args.out, progress=not args.quiet)
    if args.cache:
        from evio_lib.io.cache import save_sequence_npz

        save_sequence_npz(sequence, args.out / "sequence.npz")
    print(f"wrote {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of the evio command line."""
    parser = argparse.ArgumentParser(prog="python -m evio_lib", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("course", help="build and execute the course notebooks (build/notebooks/*.ipynb)")
    p.add_argument("--only", nargs="+", metavar="NN", help="only notebooks whose names start with these prefixes, e.g. 01 02")
    p.add_argument("--no-execute", action="store_true", help="only convert the jupytext sources to .ipynb")
    p.add_argument("--open", action="store_true", help="start JupyterLab on the built notebooks afterwards")
    p.set_defaults(func=_cmd_course)

    p = sub.add_parser("simulate", help="simulate a preset recording and write it in the ECD text layout")
    p.add_argument("preset", choices=["boxes_like", "aerial_like"])
    p.add_argument("--out", type=Path, required=True, help="output folder (created)")
    p.add_argument("--duration", type=float, default=10.0, help="seconds to simulate (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random stream (default 0)")
    p.add_argument("--no-events", action="store_true", help="skip the event camera (IMU, frames and ground truth only)")
    p.add_argument("--no-frames", action="store_true", help="skip the grayscale frames")
    p.add_argument("--cache", action="store_true", help="also write sequence.npz, the fast binary cache")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_simulate)

    from evio_lib.features.benchmark import add_benchmark_arguments, main_benchmark

    p = sub.add_parser("features-benchmark", help="detector/descriptor benchmark (repeatability, homography; thesis Tables 2-5)")
    add_benchmark_arguments(p)
    p.set_defaults(func=main_benchmark)

    from evio_lib.features.train import add_train_arguments, main_train

    p = sub.add_parser("features-train", help="train a SuperPoint-style variant (or a chain of them) from its config")
    add_train_arguments(p)
    p.set_defaults(func=main_train)

    from evio_lib.msckf.experiment import add_vio_sim_arguments, main_vio_sim

    p = sub.add_parser("vio-sim", help="MSCKF on simulated perfect-data-association tracks; TUM files and error metrics")
    add_vio_sim_arguments(p)
    p.set_defaults(func=main_vio_sim)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the process exit code."""
    args = build_parser().parse_args(argv)
    return args.func(args)
