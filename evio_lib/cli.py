"""The evio command line: build and run the course, simulate recordings, benchmark and train feature detectors, and
run the MSCKF on simulated tracks. Run a command with --help for its options. A mistake in the input ends the command
with one line "error: ..." and exit status 2 (add --debug for the full traceback); a command that writes a folder
refuses a non-empty one unless given --force, and never leaves a half-written one behind."""
from __future__ import annotations

import argparse
import errno
import importlib
import pickle
import re
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Container, Iterator, Sequence

from evio_lib.cli_args import add_force_argument, integer, output_folder, real

#: Exceptions that mean "the input was wrong" (bad values, missing or unreadable files, a bad checkpoint): printed as
#: one line "error: ..." with exit status 2. Anything else is a bug and keeps its traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, pickle.UnpicklingError, EOFError)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line ``error: --option message`` (exit status 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        match = re.match(r"argument (\S+): (.*)", message, flags=re.DOTALL)
        if match:  # "argument --seed: must be >= 0; got -5" -> "--seed must be >= 0; got -5"
            option, problem = match.groups()
            if problem.startswith(option):
                message = problem
            elif problem.startswith("must "):
                message = f"{option} {problem}"
            else:
                message = f"{option}: {problem}"
        self.exit(2, f"error: {message} (see: {self.prog} --help)\n")


def _cmd_course(args: argparse.Namespace) -> int:
    """Build the notebooks from their jupytext sources, execute them in order, optionally open JupyterLab.

    A failing cell stops the course with one line ``error: notebook NN_name, cell K: ...; the partial notebook is at
    PATH`` on stderr and exit status 1; the notebook is written with the outputs up to that cell.
    """
    from evio_lib import course

    fast = True if args.fast else course.fast_mode()  # checks EVIO_FAST's value before any work
    sources = course.notebook_sources()
    if args.only:
        sources = [s for s in sources if any(s.name.startswith(prefix) for prefix in args.only)]
        if not sources:
            raise ValueError(f"--only {' '.join(args.only)} matches no notebook; available: "
                             f"{', '.join(s.name for s in course.notebook_sources())}")
    built = course.build_notebooks(sources)
    print(f"built {len(built)} notebooks into {course.BUILD_DIR}")
    if not args.no_execute:
        mode = "fast" if fast else "full"
        for path in built:
            start = time.perf_counter()
            print(f"executing {path.name} ({mode} mode) ...", flush=True)
            try:
                course.execute_notebook(path, fast=fast)
            except course.NotebookFailed as failure:  # one line naming the lesson and the cell, not nbclient's traceback
                if args.debug:
                    raise
                print(f"error: {failure}", file=sys.stderr)
                return 1  # the command ran, a lesson failed (2 is for a mistake in the input)
            print(f"  done in {time.perf_counter() - start:.1f} s")
    if args.open:
        return subprocess.call([sys.executable, "-m", "jupyter", "lab", str(course.BUILD_DIR)])
    print(f"open them with:  jupyter lab {course.BUILD_DIR}")
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    """Simulate a preset recording and write it in the ECD text layout (plus the simulator's sidecar files)."""
    from evio_lib.io.ecd import write_ecd
    from evio_lib.io.output_dir import atomic_output_dir, check_output_dir
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence

    out = check_output_dir(args.out, args.force, name="--out")  # before the simulation: a refused folder costs nothing
    config = SimulationConfig(preset=args.preset, duration=args.duration, seed=args.seed,
                              with_events=not args.no_events, with_frames=not args.no_frames)
    if not args.quiet:
        print(config)
    timings: dict[str, float] = {}  # wall-clock seconds: printed, never written (equal seeds give equal folders)
    start = time.perf_counter()
    # the APS frames rendered by one process per core or EVIO_JOBS (the frames do not depend on it)
    sequence = simulate_sequence(config, progress=not args.quiet, timings=timings, jobs=None)
    seconds = time.perf_counter() - start
    if args.quiet:
        print(f"simulated {sequence.name} in {seconds:.1f} s: {len(sequence.events)} events, {len(sequence.frames)} "
              f"frames, {len(sequence.imu.t)} IMU samples")
    else:
        print(f"simulated in {seconds:.1f} s: {sequence.summary()}")
    with atomic_output_dir(out, args.force) as tmp:
        write_ecd(sequence, tmp, progress=not args.quiet)
        if args.cache:
            from evio_lib.io.cache import save_sequence_npz

            save_sequence_npz(sequence, tmp / "sequence.npz")
    print(f"wrote {out}")
    return 0


#: Commands whose options and main function live in their own modules: name -> (module of the options,
#: add-options function, module of the main function, main function). The main modules import torch, SciPy or
#: OpenCV (seconds); the options modules import none of them, so ``--help`` and a usage error start in well under a
#: second, and :func:`main` imports the main module of the one command that runs.
_COMMAND_MODULES = {
    "convert": ("evio_lib.io.convert", "add_convert_arguments", "evio_lib.io.convert", "main_convert"),
    "features-benchmark": ("evio_lib.features.evaluation.options", "add_benchmark_arguments",
                           "evio_lib.features.evaluation.benchmark", "main_benchmark"),
    "features-train": ("evio_lib.features.training.options", "add_train_arguments", "evio_lib.features.training.train",
                       "main_train"),
    "vio-sim": ("evio_lib.msckf.experiment_options", "add_vio_sim_arguments", "evio_lib.msckf.experiment",
                "main_vio_sim"),
    "reconstruct": ("evio_lib.events.reconstruction.command", "add_reconstruct_arguments",
                    "evio_lib.events.reconstruction.command", "main_reconstruct"),
    "reconstruct-data": ("evio_lib.events.reconstruction.training_options", "add_reconstruct_data_arguments",
                         "evio_lib.events.reconstruction.training_set", "main_reconstruct_data"),
    "reconstruct-train": ("evio_lib.events.reconstruction.training_options", "add_reconstruct_train_arguments",
                          "evio_lib.events.reconstruction.training", "main_reconstruct_train"),
    "run": ("evio_lib.pipeline.command", "add_run_arguments", "evio_lib.pipeline.command", "main_run"),
    "table": ("evio_lib.pipeline.command", "add_table_arguments", "evio_lib.pipeline.command", "main_table"),
}


def _lazy_main(module: str, function: str) -> Callable[[argparse.Namespace], int]:
    """Return a main function that imports ``module`` when it is called (after the arguments parsed)."""

    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(module), function)(args)

    run.__qualname__ = run.__name__ = function
    return run


def _add_options(p: argparse.ArgumentParser, name: str, full: Container[str] | None) -> None:
    """Give the sub-parser of command ``name`` its options and main function, importing the command's options
    module, when ``full`` is None (every command) or holds ``name``; otherwise leave it a stub with its help text
    only."""
    if full is not None and name not in full:
        return
    options, add, module, main_function = _COMMAND_MODULES[name]
    getattr(importlib.import_module(options), add)(p)
    p.set_defaults(func=_lazy_main(module, main_function))


def _requested_command(argv: Sequence[str]) -> str | None:
    """Return the command named in ``argv`` (its first positional word), or None (``--help`` alone, a typo)."""
    for word in argv:
        if not word.startswith("-"):
            return word
    return None


def build_parser(full: Container[str] | None = None) -> argparse.ArgumentParser:
    """Return the argument parser of the evio command line (one ``add_parser`` block per command).

    Args:
        full: the commands that get their options (importing their modules); None: all of them. The others keep
            their name and help text, which is all ``python -m evio_lib --help`` shows, so it starts in well under a
            second instead of importing torch and SciPy for every command.
    """
    parser = _Parser(prog="python -m evio_lib", description=__doc__)
    parser.add_argument("--debug", action="store_true",
                        help="show the full Python traceback of an error instead of the one-line message")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("course", help="build and execute the course notebooks (build/notebooks/*.ipynb)",
                       description="Convert the notebooks/NN_*.py lessons (jupytext) into build/notebooks/*.ipynb "
                                   "and execute them in order, storing the outputs in the .ipynb files. On a 2-core "
                                   "CPU the whole course takes about 10 min in full mode and about 3 min with --fast.")
    p.add_argument("--only", nargs="+", metavar="NN",
                   help="only notebooks whose names start with these prefixes, e.g. 01 02")
    p.add_argument("--fast", action="store_true",
                   help="fast mode: tiny data and few iterations, the same lessons (about 3 min for the whole course "
                        "instead of about 10; the same as EVIO_FAST=1)")
    p.add_argument("--no-execute", action="store_true", help="only convert the jupytext sources to .ipynb")
    p.add_argument("--open", action="store_true", help="start JupyterLab on the built notebooks afterwards")
    p.set_defaults(func=_cmd_course)

    p = sub.add_parser("simulate", help="simulate a preset recording and write it in the ECD text layout",
                       description="Simulate a recording (events, APS frames, IMU, ground truth) of a preset scene and "
                                   "trajectory and write it as an ECD folder. The same seed gives the same folder, "
                                   "byte for byte.")
    p.add_argument("preset", choices=["boxes_like", "aerial_like"],
                   help="boxes_like: a textured room, hand-held motion; aerial_like: a downward camera over terrain")
    p.add_argument("--out", type=output_folder(), required=True,
                   help="output folder (created; must be new or empty unless --force)")
    add_force_argument(p)
    p.add_argument("--duration", type=real(above=0.0), default=10.0, help="seconds to simulate, > 0 (default 10)")
    p.add_argument("--seed", type=integer(minimum=0), default=0, help="seed of every random stream, >= 0 (default 0)")
    p.add_argument("--no-events", action="store_true", help="skip the event camera (IMU, frames and ground truth only)")
    p.add_argument("--no-frames", action="store_true", help="skip the grayscale frames")
    p.add_argument("--cache", action="store_true", help="also write sequence.npz, the fast binary cache")
    p.add_argument("--quiet", action="store_true", help="no progress bars and no print-out of the configuration")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("features-benchmark",
                       help="detector/descriptor benchmark (repeatability, homography; thesis Tables 2-5)",
                       description="Benchmark feature detectors and descriptors on image pairs with known homographies "
                                   "(thesis Tables 2-5). The default run (every detector on the 580 held-out pairs) "
                                   "takes one to two hours on a 2-core CPU (extrapolated from a 40-pair run: about 4 s "
                                   "of CPU per pair for SIFT and one network together); --fast (4 pairs) takes under a "
                                   "minute; --detectors and --n-images choose a smaller run.")
    _add_options(p, "features-benchmark", full)

    p = sub.add_parser("features-train", help="train a SuperPoint-style variant (or a chain of them) from its config",
                       description="Train a SuperPoint-style network variant from its config (thesis Table 1); "
                                   "checkpoints go to OUT/VARIANT/.")
    _add_options(p, "features-train", full)

    p = sub.add_parser("vio-sim",
                       help="MSCKF on simulated perfect-data-association tracks; TUM files and error metrics",
                       description="Run the MSCKF on simulated tracks with perfect data association and print its "
                                   "error metrics (and those of IMU-only baselines).")
    _add_options(p, "vio-sim", full)

    p = sub.add_parser("reconstruct", help="events of a recording -> image frames (images.txt + PNGs, ECD layout)",
                       description="Reconstruct image frames from the events of an ECD folder, a ROS bag, an HDF5 "
                                   "file (read a window at a time) or a simulated preset "
                                   "with the shipped network (default), direct integration or the high-pass filter; "
                                   "writes images.txt and images/frame_XXXXXXXX.png.")
    _add_options(p, "reconstruct", full)

    p = sub.add_parser("convert", help="a recording (ROS bag, HDF5, AEDAT4, ECD, EuRoC, preset) -> an ECD folder or "
                                       "the binary cache",
                       description="Read any recording the library reads, with the same checks as run (units, axes, "
                                   "clocks, calibration), and write it as an ECD folder (events.txt written a block at "
                                   "a time) or as DIR/sequence.npz.")
    _add_options(p, "convert", full)

    p = sub.add_parser("reconstruct-data", help="simulate a training set for the event-to-image networks",
                       description="Simulate many short, independent sequences (layered textured planes, random "
                                   "6-DoF motion, thresholds and noise drawn per sequence) into one file each, in "
                                   "parallel; running it again on the same folder resumes or extends the set.")
    _add_options(p, "reconstruct-data", full)

    p = sub.add_parser("reconstruct-train", help="train a recurrent event-to-image network on simulated sequences",
                       description="Train FireNet (default) or the E2VID-style UNet on a reconstruct-data training set "
                                   "(--data) or on short planar samples simulated on the fly. Writes last.pt, best.pt "
                                   "(highest validation SSIM) and history.json; --resume continues a run.")
    _add_options(p, "reconstruct-train", full)

    p = sub.add_parser("run", help="the whole EVIO pipeline on a recording: frames -> features -> MSCKF -> trajectory",
                       description="Run frames (APS or reconstructed from events) -> feature tracking -> MSCKF on a "
                                   "simulated preset, an ECD or EuRoC folder, an AEDAT4 file, a ROS bag or an HDF5 "
                                   "file; print the errors against the "
                                   "ground truth and write a TUM trajectory, metrics and figures with --out. With no "
                                   "argument: SIFT on the APS frames of the 60 s boxes_like preset (simulated on first "
                                   "use, about 1 min, then cached).")
    _add_options(p, "run", full)

    p = sub.add_parser("table", help="the thesis's Table 6 on both presets: every configuration over several seeds",
                       description="Run IMU-only, SIFT and CNN on APS and on event frames (and the KLT baseline) on "
                                   "both presets over several seeds through joblib, and print RMSE, final error, "
                                   "%% of distance and the real-time factor (mean +- std). --fast is the CI size.")
    _add_options(p, "table", full)

    for command in sub.choices.values():  # --debug is also accepted after the command name
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help="show the full Python traceback of an error instead of the one-line message")
    return parser


#: Errors of a write that the system refused, in words that say what to do (by errno).
_WRITE_ERRORS = {
    errno.EFBIG: "a file grew beyond the largest file allowed (the shell's file-size limit, see ulimit -f, or the file "
                 "system's)",
    errno.ENOSPC: "no space left on the device (free some, or write elsewhere)",
    errno.EDQUOT: "the disk quota is used up (free some, or write elsewhere)",
}
#: The temporary folder an output folder is written into (``io.output_dir``: ``.NAME.tmp-XXXX`` beside NAME).
_TEMPORARY_FOLDER = re.compile(r"(^|/)\.([^/]+)\.tmp-[A-Za-z0-9_]+(?![A-Za-z0-9_])")


def _one_line(error: BaseException, output: object = None) -> str:
    """Return the first line of an exception's message (its type when the message is empty).

    A file is named as the user knows it (an output folder's temporary name, ``.NAME.tmp-XXXX``, as NAME); a write
    the system refused (file too large, disk full, quota) says so in words and, when the error names no
    file, where the command writes (``output``, its output folder, and the cache).
    """
    text = str(error).strip()
    if isinstance(error, OSError) and error.strerror:
        reason = _WRITE_ERRORS.get(error.errno, error.strerror)
        if error.filename is not None:
            text = f"{error.filename}: {reason}"
        elif error.errno in _WRITE_ERRORS:  # the system names no file: say where the command writes
            from evio_lib.io.cache import default_cache_dir

            places = ([f"--out {output}"] if output is not None else []) + [f"the cache {default_cache_dir()}"]
            text = f"a file could not be written: {reason}; this command writes into {' and '.join(places)}"
        else:
            text = reason
    text = _TEMPORARY_FOLDER.sub(r"\1\2", text)
    if isinstance(error, pickle.UnpicklingError) or not text:
        text = f"{type(error).__name__}: {text.splitlines()[0] if text else 'no message'}"
    first = text.splitlines()[0]
    return first if first == text else f"{first} ... (--debug shows the rest)"


class Terminated(KeyboardInterrupt):
    """SIGTERM (what CI, ``timeout`` and schedulers send), raised like Ctrl-C so that every cleanup runs: an output
    folder being written (:func:`evio_lib.io.output_dir.atomic_output_dir`) removes its temporary folder."""


@contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (once: a second one does not cut the cleanup short).

    Only the main thread can install a signal handler; elsewhere the block runs with the handler as it was. The old
    handler is restored at the end.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def handler(signum: int, frame: object) -> None:
        if not received:
            received.append(signum)
            raise Terminated()

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if old is None else old)


def _stopped(stop: KeyboardInterrupt) -> int:
    """Print the one line of an interruption and return its exit status: 143 SIGTERM, 130 Ctrl-C."""
    if isinstance(stop, Terminated):
        print("error: terminated", file=sys.stderr)
        return 143
    print("error: interrupted", file=sys.stderr)
    return 130


def main(argv: list[str] | None = None) -> int:
    """Run the command line on ``argv`` (default ``sys.argv[1:]``); return the process exit code.

    Exit codes: 0 success; 2 a mistake in the input (one line ``error: ...`` on stderr; ``--debug`` re-raises it
    with its traceback); 130 interrupted (Ctrl-C, ``error: interrupted``); 143 terminated (SIGTERM, as sent by CI,
    ``timeout`` and schedulers: ``error: terminated``; handled like Ctrl-C, so no half-written output folder is
    left); 1 a command that ran but failed (e.g. a benchmarked detector).
    """
    with _sigterm_as_interrupt():
        try:
            argv = sys.argv[1:] if argv is None else list(argv)
            # imports the module of the command that runs, and no other: Ctrl-C here is still one line
            parser = build_parser(full={_requested_command(argv)})
            try:
                args = parser.parse_args(argv)
            except SystemExit as stop:  # --help (0) or a usage error (2, already printed)
                return stop.code if isinstance(stop.code, int) else 2
        except KeyboardInterrupt as stop:
            return _stopped(stop)
        try:
            return int(args.func(args) or 0)
        except KeyboardInterrupt as stop:
            if args.debug:
                raise
            return _stopped(stop)
        except USER_ERRORS as error:
            if args.debug:
                raise
            print(f"error: {_one_line(error, getattr(args, 'out', None))}", file=sys.stderr)
            return 2
