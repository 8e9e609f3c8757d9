"""``python -m evio_lib reconstruct``: events of a recording -> image frames in the ECD layout (images.txt + images/).

SEQUENCE is a folder the library reads (the ECD layout: ``events.txt``, optional ``calib.txt`` for the sensor size) or a
simulated preset name (``boxes_like``, ``aerial_like``: simulated first, ``--duration`` seconds). Frames are written as
``images.txt`` (``t images/frame_XXXXXXXX.png``) and 8-bit PNGs into ``--out``, atomically: a failure or Ctrl-C leaves
no half-written folder, and a non-empty ``--out`` is refused unless ``--force``.

Windows: ``--window-fraction n`` (N_e = n H W events, thesis Eq. 87), ``--window-time S`` or ``--adaptive``
(:func:`evio_lib.events.representations.adaptive_windows`). With ``--times FILE`` (first column: timestamps in
seconds, e.g. a sequence's own images.txt) exactly one frame is written per listed time, reconstructed from all events
up to it (the EVREAL protocol for comparing with APS frames); windows then split the events between two listed times.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Sequence

import numpy as np

from evio_lib.io.errors import read_text

__all__ = ["add_reconstruct_arguments", "main_reconstruct", "read_times_file"]

DEFAULT_FRACTION = 0.35
#: Most memory the frames of one run may take, GiB: they are all reconstructed before the folder is written, as H x W
#: float32 (173 KB each at 240 x 180: 8 GiB are about 49 000 frames, half an hour of fast motion at n = 0.35).
MAX_FRAME_MEMORY_GIB = 8.0


def _check_frame_count(args: argparse.Namespace, events: np.ndarray, width: int, height: int,
                       times: np.ndarray | None) -> None:
    """Refuse, with the numbers, windows that would give more frames than MAX_WINDOWS or MAX_FRAME_MEMORY_GIB allow.

    The count is estimated from the inputs before any reconstruction: events / (n H W) for --window-fraction,
    (last - first event time) / S for --window-time, the listed times for --times.
    """
    from evio_lib.events.representations import MAX_EVENT_FRAME_RATE_HZ, MAX_WINDOWS, window_size_from_fraction

    frame_bytes = 4.0 * width * height
    most = int(min(MAX_WINDOWS, MAX_FRAME_MEMORY_GIB * 2**30 // frame_bytes))
    limit = (f"the most is {most:,} (MAX_WINDOWS {MAX_WINDOWS:,}; frames of {width}x{height} within "
             f"MAX_FRAME_MEMORY_GIB = {MAX_FRAME_MEMORY_GIB:g} GiB)")
    span = float(events["t"][-1] - events["t"][0]) if events.size > 1 else 0.0
    if times is None and not args.adaptive:  # cut windows: also at most MAX_EVENT_FRAME_RATE_HZ per recorded second
        by_rate = int(max(1.0, MAX_EVENT_FRAME_RATE_HZ * span))
        if by_rate < most:
            most = by_rate
            limit = (f"the most is {most:,} ({MAX_EVENT_FRAME_RATE_HZ:g} frames per recorded second, "
                     f"MAX_EVENT_FRAME_RATE_HZ, over {span:.3g} s)")
    if times is not None:
        if times.size > most:
            raise ValueError(f"--times {args.times} lists {times.size:,} times, about "
                             f"{times.size * frame_bytes / 2**30:.3g} GiB of frames; {limit}")
        return
    if args.adaptive:  # windows of at least 0.02 H W events: bounded like --window-fraction 0.02
        return
    if args.window_time is not None:
        count = span / args.window_time
        if count > most:
            raise ValueError(f"--window-time {args.window_time:g} gives about {count:.3g} windows over the {span:.3g} s "
                             f"of events; {limit} (use --window-time >= {span / most:.3g})")
        return
    fraction = DEFAULT_FRACTION if args.window_fraction is None else args.window_fraction
    per_window = window_size_from_fraction(fraction, width, height)
    count = events.size / per_window
    if count > most:
        raise ValueError(f"--window-fraction {fraction:g} gives about {count:.3g} windows of {per_window:,} event(s) "
                         f"(n H W = {fraction * width * height:.3g}) for {events.size:,} events; {limit} (use "
                         f"--window-fraction >= {events.size / (most * width * height):.3g})")


def read_times_file(path: str | Path) -> np.ndarray:
    """Return the timestamps [s] in the first column of ``path`` (lines starting with '#' are skipped).

    Raises ValueError naming the line when a timestamp is not a finite number or the times are not increasing.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--times file {path} does not exist")
    times = []
    for number, line in enumerate(read_text(path, str(path)).splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        token = text.split()[0]
        try:
            t = float(token)
        except ValueError:
            raise ValueError(f"{path} line {number}: the first column must be a timestamp in seconds; "
                             f"got {token!r}") from None
        if not np.isfinite(t):
            raise ValueError(f"{path} line {number}: timestamp must be finite; got {token!r}")
        if times and t <= times[-1]:
            raise ValueError(f"{path} line {number}: timestamps must increase; {t!r} follows {times[-1]!r}")
        times.append(t)
    if not times:
        raise ValueError(f"{path} holds no timestamps (expected one per line, in seconds, in the first column)")
    return np.asarray(times)


def add_reconstruct_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``python -m evio_lib reconstruct`` to ``parser``."""
    from evio_lib.cli_args import output_folder
    from evio_lib.events.reconstruct import PRECISIONS, available_reconstructors

    parser.add_argument("sequence", metavar="SEQUENCE",
                        help="an ECD-layout folder (events.txt, optional calib.txt), a ROS bag (.bag or a ROS2 folder), "
                             "an HDF5 file (.h5/.hdf5: DSEC, TUM-VIE, MVSEC) or a preset: boxes_like, aerial_like")
    parser.add_argument("--out", type=output_folder(), required=True,
                        help="output folder for images.txt and images/ (created; never an input or inside one)")
    parser.add_argument("--method", default="firenet",
                        help=f"reconstructor: {', '.join(available_reconstructors())} (default firenet, the shipped "
                             f"network), a checkpoint file written by reconstruct-train, or published FireNet / FireNet+ "
                             f"weights (.pth: the event_cnn_minimal / EVREAL layout)")
    parser.add_argument("--precision", choices=PRECISIONS, default=PRECISIONS[0],
                        help="a network's arithmetic (default auto: int8 for FireNet on an x86 CPU, faster than "
                             "float32 at nearly the same SSIM, else float32; bfloat16 is faster than float32 on a CPU "
                             "with native bfloat16 (AVX512-BF16); measured in docs/results/reconstruction.md; ignored "
                             "by direct and high_pass)")
    window = parser.add_mutually_exclusive_group()
    window.add_argument("--window-fraction", type=float, default=None, metavar="N",
                        help=f"N_e = N * H * W events per frame (default {DEFAULT_FRACTION}; the thesis used 0.7 on "
                             f"boxes, 0.2 on its aerial flight)")
    window.add_argument("--window-time", type=float, default=None, metavar="S", help="one frame every S seconds")
    window.add_argument("--adaptive", action="store_true",
                        help="windows close at a fixed number of events per active pixel (n follows the texture)")
    parser.add_argument("--times", type=Path, default=None, metavar="FILE",
                        help="one frame per timestamp in FILE's first column (e.g. the sequence's images.txt)")
    parser.add_argument("--events", type=Path, default=None, metavar="FILE",
                        help="read the events from FILE (ECD text `t x y p`) instead of SEQUENCE/events.txt")
    parser.add_argument("--sensor-size", type=int, nargs=2, default=None, metavar=("W", "H"),
                        help="sensor size in pixels (default: from the folder's frames, else the DAVIS240C's 240 180)")
    parser.add_argument("--duration", type=float, default=2.0,
                        help="seconds to simulate when SEQUENCE is a preset (default 2)")
    parser.add_argument("--seed", type=int, default=0, help="simulation seed when SEQUENCE is a preset (default 0)")
    parser.add_argument("--topics", default=None, metavar="TOPICS",
                        help="a ROS bag's event topic (a preset such as mvsec-left, or events=/topic) or an MVSEC "
                             "file's camera (davis/left), where the recording holds several")
    parser.add_argument("--force", action="store_true", help="replace a non-empty --out folder")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def _load_events(args: argparse.Namespace) -> tuple[np.ndarray, int, int]:
    """Return (events, width, height) of SEQUENCE (a folder or a preset name)."""
    from evio_lib.sim.presets import PRESETS

    folder = Path(args.sequence)
    size = tuple(args.sensor_size) if args.sensor_size else None
    if size is not None and min(size) <= 0:
        raise ValueError(f"--sensor-size must be two positive integers W H; got {args.sensor_size}")
    if args.events is not None:
        from evio_lib.io.ecd import read_ecd_events

        if not args.events.is_file():
            raise FileNotFoundError(f"--events file {args.events} does not exist")
        width, height = size or _frame_size(folder) or (240, 180)
        return read_ecd_events(args.events, sensor_size=(width, height)), width, height
    from evio_lib.pipeline.dataset import _is_bag_or_h5

    topics = getattr(args, "topics", None)
    if _is_bag_or_h5(args.sequence):
        # events stay on disk (a memory-mapped .npy in the cache), read a window at a time below
        if folder.suffix.lower() in (".h5", ".hdf5"):
            from evio_lib.io.hdf5 import read_hdf5

            sequence = read_hdf5(folder, load_frames=False, group=topics)
        else:
            from evio_lib.io.rosbag import read_rosbag

            sequence = read_rosbag(folder, load_frames=False, topics=topics)
        width, height = size or sequence.sensor_size
        return sequence.events, int(width), int(height)
    if topics is not None:
        raise ValueError("--topics applies to ROS bags and MVSEC HDF5 files")
    if folder.is_dir():
        from evio_lib.io.ecd import read_ecd

        sequence = read_ecd(folder, load_frames=False, sensor_size=size)
        width, height = sequence.sensor_size or (sequence.camera.width, sequence.camera.height)
        return sequence.events, int(width), int(height)
    if args.sequence in PRESETS:
        from evio_lib.sim.presets import SimulationConfig, simulate_sequence

        if not (np.isfinite(args.duration) and args.duration > 0):
            raise ValueError(f"--duration must be > 0 seconds; got {args.duration}")
        if args.seed < 0:
            raise ValueError(f"--seed must be >= 0; got {args.seed}")
        sequence = simulate_sequence(SimulationConfig(preset=args.sequence, duration=args.duration, seed=args.seed,
                                                      with_frames=False), progress=not args.quiet)
        return sequence.events, sequence.camera.width, sequence.camera.height
    raise ValueError(f"SEQUENCE must be an existing folder in the ECD layout or a preset {list(PRESETS)}; "
                     f"got {args.sequence!r}")


def _frame_size(folder: Path) -> tuple[int, int] | None:
    """Return (W, H) of the first frame listed in ``folder/images.txt``, or None."""
    import cv2

    listing = folder / "images.txt"
    if not listing.is_file():
        return None
    for line in listing.read_text().splitlines():
        parts = line.split()
        if len(parts) >= 2 and not line.startswith("#"):
            image = cv2.imread(str(folder / parts[1]), cv2.IMREAD_GRAYSCALE)
            return (image.shape[1], image.shape[0]) if image is not None else None
    return None


def main_reconstruct(args: argparse.Namespace | Sequence[str] | None = None) -> int:
    """Run ``reconstruct`` (see :func:`add_reconstruct_arguments`); return the exit code."""
    import cv2

    from evio_lib.events.reconstruct import available_reconstructors, reconstruct_at_times
    from evio_lib.events.representations import adaptive_windows, count_windows, time_windows, window_size_from_fraction
    from evio_lib.io.output_dir import atomic_output_dir, check_output_dir

    if not isinstance(args, argparse.Namespace):
        args = add_reconstruct_arguments(argparse.ArgumentParser()).parse_args(args)
    if args.window_fraction is not None and not (np.isfinite(args.window_fraction) and 0 < args.window_fraction <= 10):
        raise ValueError(f"--window-fraction must be in (0, 10]; got {args.window_fraction}")
    if args.window_time is not None and not (np.isfinite(args.window_time) and args.window_time > 0):
        raise ValueError(f"--window-time must be > 0 seconds; got {args.window_time}")
    if args.times is not None and (args.window_time is not None or args.adaptive):
        raise ValueError("--times takes its frame times from FILE; combine it only with --window-fraction")
    if args.sensor_size is not None and min(args.sensor_size) > 0:  # before any array of that size is made
        from evio_lib.events.representations import check_sensor_pixels

        check_sensor_pixels(*args.sensor_size, f"--sensor-size {args.sensor_size[0]} {args.sensor_size[1]}")
    method_file = None if args.method in available_reconstructors() else args.method
    check_output_dir(args.out, args.force, name="--out", inputs=[  # a preset name is no path: only a folder counts
        ("the input recording", args.sequence if Path(args.sequence).exists() else None),
        ("the --events file", args.events), ("the --times file", args.times), ("the --method checkpoint", method_file)])
    if method_file is not None and not Path(method_file).is_file():  # before the events load (seconds to minutes)
        raise ValueError(f"--method must be one of {available_reconstructors()} or a checkpoint file; got "
                         f"{args.method!r}" + (" (a folder)" if Path(method_file).is_dir() else ""))
    times = read_times_file(args.times) if args.times is not None else None
    events, width, height = _load_events(args)
    if events is None or events.size == 0:
        raise ValueError(f"{args.sequence} holds no events to reconstruct from")
    _check_frame_count(args, events, width, height, times)  # a window per event would never end
    from evio_lib.events.reconstruct import reconstructor_by_name_or_file

    reconstructor = reconstructor_by_name_or_file(args.method, width, height, what="--method",
                                                  precision=args.precision)
    fraction = DEFAULT_FRACTION if args.window_fraction is None else args.window_fraction
    if times is not None:
        frames = reconstruct_at_times(reconstructor, events, times,
                                      max_window_events=window_size_from_fraction(fraction, width, height))
        frame_times = times
    else:
        from evio_lib.io.event_source import (ArrayEventSource, adaptive_windows_source, count_windows_source,
                                              event_source)

        source = event_source(events)  # events on disk (a bag, an HDF5 file): windows read one at a time
        if args.adaptive:
            bounds = (adaptive_windows(events, width, height) if isinstance(source, ArrayEventSource)
                      else adaptive_windows_source(source, 0, len(source), width, height))
        elif args.window_time is not None:
            if isinstance(source, ArrayEventSource):
                bounds, _ = time_windows(events, args.window_time)
            else:  # time_windows' edges, found by binary search in the file
                bounds, ends = time_windows(np.asarray(events[[0, -1]]), args.window_time)
                if len(bounds):
                    edges = np.concatenate([[float(events["t"][0])], ends])
                    index = np.array([source.index_at(float(t)) for t in edges], dtype=np.int64)
                    bounds = np.stack([index[:-1], index[1:]], axis=1)
        else:
            bounds = count_windows_source(source, 0, len(source), window_size_from_fraction(fraction, width, height)) \
                if not isinstance(source, ArrayEventSource) else \
                count_windows(events, window_size_from_fraction(fraction, width, height))
        if len(bounds) == 0:
            raise ValueError(f"{args.sequence}: {events.size} events make no complete window; use a smaller "
                             f"--window-fraction or --window-time")

        def reconstructed():  # frames one at a time: a long recording never holds them all
            iterator = bounds
            if not args.quiet:
                from tqdm.auto import tqdm

                iterator = tqdm(bounds, desc=f"reconstructing ({reconstructor.name})", unit="frame")
            reconstructor.reset()
            last = 0.0
            for a, b in iterator:
                window = source.take(a, b)
                last = float(window["t"][-1]) if b > a else last
                yield last, reconstructor.reconstruct(window)

        frames = None
    with atomic_output_dir(args.out, args.force) as tmp:
        (tmp / "images").mkdir()
        lines = []
        for i, (t, frame) in enumerate(zip(frame_times, frames) if frames is not None else reconstructed()):
            name = f"images/frame_{i:08d}.png"
            if not cv2.imwrite(str(tmp / name), np.round(np.clip(frame, 0, 1) * 255).astype(np.uint8)):
                raise OSError(f"could not write {tmp / name}")
            lines.append(f"{t:.9f} {name}\n")
        (tmp / "images.txt").write_text("".join(lines))
        written = len(lines)
    chosen = getattr(reconstructor, "precision", None)  # a network's arithmetic (what --precision auto chose)
    what = reconstructor.name if chosen is None else f"{reconstructor.name}, {chosen}"
    print(f"wrote {written} frames ({what}, {width}x{height}) to {args.out}")
    return 0
