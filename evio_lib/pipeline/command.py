"""Command line of the pipeline: ``python -m evio_lib run [DATASET] ...`` and ``python -m evio_lib table ...``."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from evio_lib.cli_args import add_force_argument, as_option_error, integer, output_folder, real

__all__ = ["add_run_arguments", "main_run", "add_table_arguments", "main_table"]


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of ``run``."""
    from evio_lib.events.reconstruct import PRECISIONS  # no torch: --help stays light

    p.add_argument("dataset", nargs="?", default="boxes_like", metavar="DATASET",
                   help="a preset (boxes_like [default], aerial_like; simulated on first use and cached), an ECD folder "
                        "(events.txt, images.txt + images/, imu.txt, calib.txt, optional groundtruth.txt), a EuRoC "
                        "ASL folder (mav0/), an AEDAT4 file (.aedat4, with --calib), a ROS bag (.bag file or ROS2 "
                        "folder) or an HDF5 file (.h5/.hdf5: DSEC, TUM-VIE, MVSEC; with --calib)")
    p.add_argument("--frames", choices=["aps", "events", "mc-events", "aps+events", "aps+mc-events"], default="aps",
                   help="aps: the recorded frames (default); events: frames reconstructed from event windows; "
                        "mc-events: event windows warped with the gyroscope's rotation and counted (no network); "
                        "aps+events, aps+mc-events: both streams, each with its own tracker, fused by the filter")
    p.add_argument("--features", default=None,
                   help="feature detector: sift, superpoint (the shipped CNN, photos_detdesc), distilled_narrow (a "
                        "half-width CNN, faster: docs/results/speed.md), orb, fast, ... (default: the tracker's "
                        "own, sift for the descriptor tracker and fast for klt)")
    p.add_argument("--weights", type=Path, default=None,
                   help="the CNN's weights for --features superpoint: a checkpoint file (.pt) or the name of a "
                        "shipped network, e.g. pretrained_detdesc_round1_gpu (default: the shipped default, "
                        "photos_detdesc)")
    p.add_argument("--cnn-inference", choices=["auto", "fused", "bf16", "int8"], default=None,
                   help="the CNN's arithmetic (--features superpoint): auto (default: bf16 where the CPU has it, else "
                        "int8), fused (fp32), bf16, or int8 (faster than bf16, less accurate in the pipeline; "
                        "docs/results/speed.md)")
    p.add_argument("--tracker", choices=["descriptor", "klt"], default="descriptor",
                   help="descriptor: detect + match + two-point RANSAC (thesis); klt: optical flow (msckf_vio)")
    p.add_argument("--event-tracker", choices=["descriptor", "klt"], default=None,
                   help="--frames aps+mc-events or aps+events: the event stream's own tracker (default: --tracker "
                        "for both streams; without --features each stream's tracker detects its own, sift or fast; "
                        "--max-track-gap applies to the descriptor stream)")
    p.add_argument("--max-features", type=integer(minimum=20), default=60, help="N, features per frame (default 60)")
    p.add_argument("--reconstructor", default="firenet",
                   help="event frames: firenet (default, shipped), high_pass, direct, a reconstruct-train "
                        "checkpoint file, or published FireNet / FireNet+ weights (.pth)")
    p.add_argument("--reconstructor-precision", choices=PRECISIONS, default=PRECISIONS[0],
                   help="event frames: a network's arithmetic (default auto: int8 for FireNet on an x86 CPU, "
                        "else float32; speed and quality of each: docs/results/reconstruction.md)")
    p.add_argument("--window-fraction", type=real(above=0.0), default=None,
                   help="event frames: n of N_e = n H W events per window (default: 0.7 boxes_like, 0.2 aerial_like, "
                        "0.5 otherwise; mc-events: 1.0 for every recording)")
    p.add_argument("--adaptive", action="store_true", help="event frames: adaptive windows instead of a fixed n")
    p.add_argument("--min-window", type=real(at_least=0.0), default=None, metavar="SECONDS",
                   help="event frames: the shortest window, s (default: none for events, 0.01 s for mc-events)")
    p.add_argument("--max-window", type=real(above=0.0), default=None, metavar="SECONDS",
                   help="event frames: the longest window, s; a slow stretch still gives a frame this often "
                        "(default: none for events, 0.1 s for mc-events)")
    p.add_argument("--duration", type=real(above=0.0), default=None,
                   help="presets: seconds to simulate (default: the whole preset, 60 s boxes_like, 40 s aerial_like)")
    p.add_argument("--start", type=real(at_least=0.0), default=0.0, metavar="SECONDS",
                   help="presets: where in the preset's motion the simulated stretch begins (default 0; e.g. --start "
                        "50 --duration 10 for the violent end of boxes_like)")
    add_aps_exposure_argument(p)
    add_speed_argument(p)
    p.add_argument("--max-duration", type=real(above=0.0), default=None,
                   help="seconds of the recording to process from its start (default: all)")
    p.add_argument("--seed", type=integer(minimum=0), default=0, help="presets: simulation seed; RANSAC seed (default 0)")
    p.add_argument("--init", choices=["auto", "groundtruth", "static"], default="auto",
                   help="auto (default): static (attitude and gyro bias from the still IMU, velocity 0; yaw and "
                        "position from the ground truth when there is one) whenever the IMU is still over the first "
                        "second, else from the ground truth; groundtruth: the ground truth's pose and velocity at the "
                        "first frame (the thesis's set-up); static: require a still start")
    p.add_argument("--bias-init", default="zero",
                   help="initial biases: zero (default), groundtruth, or six numbers 'bgx,bgy,bgz,bax,bay,baz' "
                        "(rad/s, m/s^2)")
    p.add_argument("--imu-only", action="store_true", help="propagate the IMU only (no visual updates)")
    p.add_argument("--no-observability-constrained", action="store_true",
                   help="plain EKF instead of the observability-constrained one")
    p.add_argument("--no-zupt", action="store_true",
                   help="no zero-velocity updates where the platform stands still (default: detected from the "
                        "feature tracks and the IMU, and applied as in OpenVINS)")
    p.add_argument("--observation-outlier", type=real(above=0.0), default=None, metavar="PX",
                   help="drop a track's observations that reproject farther than PX pixels from its triangulated "
                        "point, and keep the rest of the track (default: off)")
    p.add_argument("--far-points", action="store_true",
                   help="use a track whose triangulation fails for lack of parallax (behind a camera, beyond 1 000 m, "
                        "no baseline) with its point placed far on its bearing, where it still constrains the "
                        "rotation (default: off, such tracks are dropped)")
    p.add_argument("--pixel-noise", type=real(above=0.0), default=1.0, metavar="PX",
                   help="the filter's feature noise sigma in pixels of the APS frames' tracks, and of a lone event "
                        "stream's; the base of the --event-pixel-noise default (default 1.0)")
    p.add_argument("--event-pixel-noise", type=real(above=0.0), default=None, metavar="PX",
                   help="the feature noise sigma of the event frame streams' tracks, so that --frames aps+mc-events "
                        "weights each stream by its own accuracy (default: 3 x --pixel-noise when fused with the "
                        "APS frames, else --pixel-noise; refused with --frames aps)")
    p.add_argument("--max-track-gap", type=integer(minimum=0), default=0, metavar="FRAMES",
                   help="descriptor tracker: keep a lost track for FRAMES frames and continue it, with its id, when "
                        "the feature is matched again (default 0: a missed detection ends the track, as in the "
                        "thesis; 2 measured best for SIFT, docs/archive.md; not with --tracker klt)")
    p.add_argument("--extrinsics", type=Path, default=None,
                   help="a Kalibr YAML with T_cam_imu, overriding the recording's extrinsics")
    p.add_argument("--calib", type=Path, default=None,
                   help="camera calibration, one line 'fx fy cx cy k1 k2 p1 p2 [k3]' (the ECD calib.txt format): "
                        "required for an AEDAT4 or HDF5 file and a bag without CameraInfo, overrides a folder's or "
                        "a bag's calibration")
    p.add_argument("--topics", default=None, metavar="TOPICS",
                   help="ROS bags: which topics to read, a dataset preset (ecd, mvsec-left, mvsec-right, uzh-fpv, "
                        "vector-left) or role=/topic pairs, e.g. events=/davis/left/events,imu=/davis/left/imu "
                        "(default: found by message type; several of one type are refused with their list); MVSEC "
                        "HDF5 files: the camera group, e.g. davis/left")
    p.add_argument("--out", type=output_folder(), default=None,
                   help="write trajectory.txt (TUM), states.csv, tracking.csv, metrics.json and figures/ here "
                        "(must be new or empty unless --force)")
    add_force_argument(p)
    p.add_argument("--no-figures", action="store_true", help="do not draw the figures (faster)")
    p.add_argument("--threads", type=integer(minimum=1), default=1,
                   help="threads of torch, OpenCV and BLAS (default 1: on a small, busy CPU more threads oversubscribe "
                        "it and run several times slower)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true",
                   help="also the measurements behind each note (what the start and the initialisation measured), "
                        "the settings of the run, the time per stage and what the filter dropped, and why")


def _bias(text: str):
    if text in ("zero", "groundtruth"):
        return text
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 6:
        raise ValueError(f"--bias-init must be zero, groundtruth or six comma-separated numbers "
                         f"'bgx,bgy,bgz,bax,bay,baz'; got {text!r}")
    from evio_lib.io.imu_checks import check_bias_values

    return check_bias_values(values, "--bias-init")  # finite, |b_g| <= 0.5 rad/s, |b_a| <= 3 m/s^2 per axis


def _check_detector(name: str, options: tuple) -> object:
    """Return the detector ``name`` made with ``options``, or raise ValueError naming ``--features`` when it cannot be
    created."""
    import pickle

    from evio_lib.features.base import create_detector

    try:
        return create_detector(name, **dict(options))
    except (ValueError, OSError, RuntimeError, EOFError, pickle.UnpicklingError) as error:  # torch.load's too
        detail = (str(error).strip().splitlines() or [type(error).__name__])[0]
        weights = dict(options).get("weights")
        if weights is not None and detail.startswith(f"{weights}: "):  # the checkpoint reader names the file first
            detail = detail[len(f"{weights}: "):]
        given = f" with --weights {weights}" if weights is not None else ""
        raise ValueError(f"--features {name}{given}: {detail}") from None


def main_run(args: argparse.Namespace) -> int:
    """Run the pipeline on one recording; print the summary; write the output folder when --out is given."""
    from evio_lib.io.output_dir import check_output_dir
    from evio_lib.pipeline.dataset import PRESETS, load_dataset, sequence_cache_dir
    from evio_lib.pipeline.frames import frame_streams
    from evio_lib.pipeline.output import write_run
    from evio_lib.pipeline.run import PipelineConfig, run_pipeline, set_threads

    shipped_weights_name = _shipped_name(args.weights)
    if args.out is not None:  # before any work: a refused folder costs nothing
        preset = str(args.dataset) in PRESETS  # a preset name is no path; its recording lives in the cache
        check_output_dir(args.out, args.force, name="--out", inputs=[
            ("the input recording", None if preset else args.dataset),
            ("the --weights checkpoint", None if shipped_weights_name else args.weights),
            ("the --extrinsics file", args.extrinsics), ("the --calib file", getattr(args, "calib", None)),
            ("the recording cache", sequence_cache_dir() if preset else None)])
    set_threads(args.threads)
    options = (("weights", str(args.weights)),) if args.weights is not None else ()
    if not shipped_weights_name:
        _require_checkpoint_file("--weights", args.weights, "or the name of a shipped network")
    if args.features is None and args.weights is not None:
        raise ValueError(f"--weights {args.weights} is a CNN checkpoint: name the network it is for, --features "
                         f"superpoint (or distilled_narrow)")
    # an unknown name fails now, not after loading the recording (None: each tracker's own, SIFT or FAST)
    detector = _check_detector(args.features, options) if args.features is not None else None
    cnn_inference = getattr(args, "cnn_inference", None)
    if cnn_inference is not None:
        if not hasattr(detector, "inference"):  # the SuperPoint-style CNN's mode; classical detectors have none
            raise ValueError(f"--cnn-inference applies to a CNN detector (--features superpoint or a shipped network); "
                             + (f"--features {args.features} has no inference modes" if args.features is not None
                                else "add --features superpoint"))
        options = options + (("inference", cnn_inference),)
    try:
        config = PipelineConfig(frames=args.frames, features=args.features, detector_options=options,
                                tracker=args.tracker, event_tracker=args.event_tracker, max_features=args.max_features,
                                reconstructor=args.reconstructor,
                                reconstructor_precision=args.reconstructor_precision,
                                window_fraction=args.window_fraction, adaptive_windows=args.adaptive,
                                min_window_s=args.min_window, max_window_s=args.max_window, init=args.init,
                                bias_init=_bias(args.bias_init), imu_only=args.imu_only,
                                observability_constrained=not args.no_observability_constrained,
                                zupt=not args.no_zupt, max_duration=args.max_duration, seed=args.seed,
                                observation_outlier_px=args.observation_outlier, max_track_gap=args.max_track_gap,
                                far_points=args.far_points,
                                pixel_noise_px=args.pixel_noise, event_pixel_noise_px=args.event_pixel_noise)
    except ValueError as error:  # the message names the config field; the user typed the option
        raise as_option_error(error, _OPTIONS) from None
    _check_aps_exposure(args.aps_exposure, uses_aps="aps" in frame_streams(args.frames) and not args.imu_only)
    _check_speed(args.speed)
    start = time.perf_counter()
    data = load_dataset(args.dataset, duration=args.duration, seed=args.seed, start=args.start,
                        need_events=args.frames != "aps" and not args.imu_only,
                        need_frames="aps" in args.frames.split("+") or args.imu_only, extrinsics=args.extrinsics,
                        progress=not args.quiet, calib=args.calib, aps_exposure_s=args.aps_exposure,
                        speed=args.speed, topics=getattr(args, "topics", None))
    print(f"loaded {data.sequence.name} ({data.kind}) in {time.perf_counter() - start:.1f} s")
    for note in data.notes:
        print(f"  {note if args.verbose else plain_note(note)}")
    if args.verbose:
        print(f"  settings: {config}")
    result = run_pipeline(data, config, progress=not args.quiet)
    print(result.summary())
    for note in result.notes[len(data.notes):]:
        print(f"  {note if args.verbose else plain_note(note)}")
    if args.verbose:
        for line in result.details():
            print(f"  {line}")
    if args.out is not None:
        out = write_run(result, data, args.out, force=args.force, figures=not args.no_figures)
        problems = json.loads((out / "metrics.json").read_text(encoding="utf-8"))["output_problems"]
        print(f"wrote {args.out} (trajectory.txt is the {'IMU' if data.kind == 'euroc' else 'camera'} pose in TUM "
              f"format)")
        for problem in problems:
            print(f"warning: left out {problem}", file=sys.stderr)
    return 0


#: The notes whose measured details a default run leaves out (the filter's start, what it measured to choose it).
PLAIN_NOTES = ("start:", "initialisation:")


def plain_note(note: str) -> str:
    """Return a run's note as a default run prints it: the notes of :data:`PLAIN_NOTES` without their measured
    details (each parenthesised part, after a space, that holds a number), every other note whole ("start: the
    recording moves in its first 1 s (the gyro ranges over 0.41 rad/s ...): the filter starts from the ground truth's
    pose" -> "start: the recording moves in its first 1 s: the filter starts ..."). ``run --verbose`` prints every
    note whole, as ``metrics.json`` keeps them.

    >>> plain_note("initialisation: static, IMU still over [0.000, 1.000] s (gravity error +0.012 m/s^2), velocity 0")
    'initialisation: static, IMU still over [0.000, 1.000] s, velocity 0'
    >>> plain_note("extrinsics: from runs/camchain (1).yaml")
    'extrinsics: from runs/camchain (1).yaml'
    """
    if not note.startswith(PLAIN_NOTES):
        return note
    out, depth, start = [], 0, 0
    for i, ch in enumerate(note):  # outermost parenthesised parts, nested ones included in them
        if ch == "(":
            if depth == 0:
                out.append(note[start:i])
                start = i
            depth += 1
        elif ch == ")" and depth > 0:
            depth -= 1
            if depth == 0:
                part = note[start:i + 1]
                detail = start > 0 and note[start - 1] == " " and any(c.isdigit() for c in part)
                out.append("" if detail else part)
                start = i + 1
    out.append(note[start:])
    text = "".join(out)
    while "  " in text or " :" in text or " ," in text or " ;" in text:
        text = text.replace("  ", " ").replace(" :", ":").replace(" ,", ",").replace(" ;", ";")
    return text.strip()


def _check_aps_exposure(seconds: float | None, uses_aps: bool = True,
                        users: str = "runs that use APS frames (--frames aps, aps+mc-events or aps+events, without "
                                     "--imu-only)") -> None:
    """Raise ValueError naming --aps-exposure unless it is None or an exposure the run uses (``uses_aps``: it reads
    APS frames). A recording folder refuses it in ``load_dataset``, before anything is read."""
    from evio_lib.pipeline.dataset import check_aps_exposure

    if seconds is None:
        return
    if not uses_aps:  # it would change nothing but cost a new simulation
        raise ValueError(f"--aps-exposure applies to {users}")
    try:
        check_aps_exposure(seconds)
    except ValueError as error:
        raise as_option_error(error, _OPTIONS) from None


def _check_speed(speed: float | None) -> None:
    """Raise ValueError naming --speed unless it is None or a playback speed of a preset's motion."""
    from evio_lib.pipeline.dataset import check_speed

    if speed is not None:
        try:
            check_speed(speed)
        except ValueError as error:
            raise ValueError(f"--{error}") from None


def _require_checkpoint_file(option: str, path: Path | None, alternative: str = "") -> None:
    """Raise ValueError unless ``path`` (the value of ``option``) is None or an existing file; ``alternative`` (e.g.
    "or the name of a shipped network") is added to what the message says is expected."""
    if path is not None and not path.is_file():
        also = f" {alternative}" if alternative else ""
        problem = (f"a folder; expected a checkpoint file (.pt){also}" if path.is_dir()
                   else f"no such checkpoint file{also}")
        raise ValueError(f"{option} {path}: {problem}")


def _shipped_name(weights: Path | None) -> bool:
    """True when the detector will read ``weights`` (``run --weights``) as the name of shipped CNN weights
    (``evio_lib/weights/NAME.pt``), by :func:`~evio_lib.features.network.resolve_weights`'s own rule."""
    if weights is None:
        return False
    from evio_lib.features.network import resolve_weights

    try:
        return resolve_weights(str(weights)) != Path(str(weights))  # a name resolves into the weights folder
    except (FileNotFoundError, ValueError):
        return False


#: PipelineConfig fields and the ``run`` options that set them (for messages).
_OPTIONS = {"reconstructor": "--reconstructor", "reconstructor_precision": "--reconstructor-precision",
            "bias_init": "--bias-init", "max_duration": "--max-duration", "window_fraction": "--window-fraction",
            "min_window_s": "--min-window", "max_window_s": "--max-window",
            "max_features": "--max-features", "init": "--init", "frames": "--frames", "seed": "--seed",
            "tracker": "--tracker", "observation_outlier_px": "--observation-outlier",
            "max_track_gap": "--max-track-gap", "pixel_noise_px": "--pixel-noise",
            "event_pixel_noise_px": "--event-pixel-noise", "event_tracker": "--event-tracker",
            "aps_exposure_s": "--aps-exposure", "far_points": "--far-points"}


def add_aps_exposure_argument(p: argparse.ArgumentParser) -> None:
    """Add ``--aps-exposure`` (presets: the simulated APS frames' exposure time) to ``run`` or ``table``."""
    p.add_argument("--aps-exposure", type=real(above=0.0), default=None, metavar="SECONDS",
                   help="presets: the APS frames' exposure time (default: the simulator's 0.01 s; at most one frame "
                        "interval, 1/24 s): longer exposures blur the frames more where the camera moves fast; the "
                        "frames are simulated for it and cached, the events and the IMU are the default recording's")


def add_speed_argument(p: argparse.ArgumentParser) -> None:
    """Add ``--speed`` (presets: the motion played faster) to ``run`` or ``table``."""
    p.add_argument("--speed", type=real(above=0.0), default=None, metavar="FACTOR",
                   help="presets: play the preset's motion FACTOR times faster, in [0.25, 4] (default 1): the same "
                        "path in 1/FACTOR of the time, rates x FACTOR, accelerations x FACTOR^2; --duration and "
                        "--start are seconds of the faster motion (boxes_like at 2: 30 s, its violent end from "
                        "about 24 s)")


def add_table_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of ``table``."""
    from evio_lib.events.reconstruct import PRECISIONS  # no torch: --help stays light

    p.add_argument("--presets", nargs="+", choices=["boxes_like", "aerial_like"], default=["boxes_like", "aerial_like"],
                   help="which presets (default both)")
    p.add_argument("--seeds", type=integer(minimum=1), default=3, help="seeds 0 .. S-1 per configuration (default 3)")
    p.add_argument("--duration", type=real(above=0.0), default=None,
                   help="seconds of each preset (default: the whole preset, 60 s boxes_like, 40 s aerial_like)")
    p.add_argument("--rows", nargs="+", default=None,
                   help="only these rows: imu imu_bias sift_aps sift_aps_gap2 cnn_aps cnn_aps_far cnn_narrow_aps "
                        "sift_events cnn_events klt_aps klt_events sift_mc_events sift_mc_events_gap2 cnn_mc_events "
                        "cnn_mc_events_far klt_mc_events klt_aps_mc_events cnn_events_trained (default: all but the "
                        "rows ending in _gap2, SIFT whose tracks survive two missed frames, in _far, the CNN with "
                        "--far-points, and cnn_narrow_aps, the distilled CNN, run only when named)")
    p.add_argument("--events-cnn", type=Path, default=None,
                   help="checkpoint of a CNN trained with event frames (the 'CNN trained with event frames' row)")
    p.add_argument("--reconstructor-precision", choices=PRECISIONS, default=None,
                   help="rows on event frames: FireNet's arithmetic (default auto: int8 on an x86 CPU, else float32; "
                        "the table names the one each row used)")
    add_aps_exposure_argument(p)
    add_speed_argument(p)
    p.add_argument("--jobs", type=integer(minimum=1), default=1, help="parallel joblib workers (default 1)")
    p.add_argument("--fast", action="store_true", help="CI size: 3 s of each preset, one seed")
    p.add_argument("--out", type=output_folder(), default=None, help="write table.md, table.json and runs.json here")
    add_force_argument(p)


def main_table(args: argparse.Namespace) -> int:
    """Run the Table 6 sweep and print it (and write it with --out)."""
    from evio_lib.io.output_dir import atomic_output_dir, check_output_dir
    from evio_lib.pipeline.dataset import sequence_cache_dir
    from evio_lib.pipeline.output import write_json
    from evio_lib.pipeline.table import aggregate, format_table6, run_table, table_rows

    if args.out is not None:
        check_output_dir(args.out, args.force, name="--out", inputs=[
            ("the --events-cnn checkpoint", args.events_cnn), ("the recording cache", sequence_cache_dir())])
    _require_checkpoint_file("--events-cnn", args.events_cnn)
    if args.events_cnn is not None:  # a damaged or foreign checkpoint fails now, not in every run of its row
        from evio_lib.features.network import load_model

        try:
            load_model(args.events_cnn)
        except (ValueError, OSError) as error:  # evio_lib.io.checkpoint's one line "FILE: problem; expected ..."
            raise ValueError(f"--events-cnn {error}") from None
    try:  # a bad row name fails before any run
        rows = table_rows(args.rows, None if args.events_cnn is None else str(args.events_cnn),
                          args.reconstructor_precision)
    except ValueError as error:
        raise ValueError(f"--rows: {error}") from None
    if args.reconstructor_precision is not None and not any(row.uses_reconstructed_frames for row in rows):
        raise ValueError("--reconstructor-precision applies to table rows on event frames (sift_events, cnn_events, "
                         "klt_events, cnn_events_trained); none of the rows chosen is one")
    _check_aps_exposure(args.aps_exposure, uses_aps=any(row.uses_aps_frames for row in rows),
                        users="table rows that use APS frames; none of the rows chosen does")
    seeds = 1 if args.fast else args.seeds
    duration = 3.0 if args.fast and args.duration is None else args.duration
    durations = {p: duration for p in args.presets} if duration is not None else None
    from evio_lib.pipeline.dataset import check_preset_duration

    _check_speed(args.speed)
    speed = 1.0 if args.speed is None else args.speed
    if durations is not None:
        for preset, seconds in durations.items():
            try:
                check_preset_duration(preset, seconds, speed)
            except ValueError as error:
                raise ValueError(f"--duration: {error}") from None
    start = time.perf_counter()
    records = run_table(args.presets, list(range(seeds)), rows, durations, jobs=args.jobs,
                        aps_exposure_s=args.aps_exposure, speed=speed)
    table = aggregate(records)
    text = format_table6(table)
    print(text)
    if args.events_cnn is None:
        print("(no row 'CNN trained with event frames': none is shipped; train one with `python -m evio_lib "
              "features-train pretrained_detdesc_round2_events` and give --events-cnn CHECKPOINT)")
    for r in table:
        for error in r["errors"]:
            print(f"{r['preset']} / {r['label']}: failed: {error}")
    print(f"{len(records)} runs in {time.perf_counter() - start:.0f} s with {args.jobs} job(s)")
    if args.out is not None:
        with atomic_output_dir(args.out, args.force) as tmp:
            (tmp / "table.md").write_text(text + "\n", encoding="utf-8")
            write_json(tmp / "table.json", table)
            write_json(tmp / "runs.json", records)
        print(f"wrote {args.out}")
    return 0
