"""``python -m evio_lib convert SOURCE --out DIR``: any recording the library reads, written as an ECD folder or as
the project's binary cache (``DIR/sequence.npz``).

SOURCE is what ``run`` takes (a preset, an ECD or EuRoC folder, an AEDAT4 file) or a ROS bag or HDF5 file
(:mod:`evio_lib.io.rosbag`, :mod:`evio_lib.io.hdf5`); it goes through the same reader and so the same checks at
the door (units, axes, clocks, calibration). ``--calib FILE`` gives or replaces the camera; ``--topics`` picks a
bag's topics or an MVSEC camera. The folder is refused when it holds files (``--force`` replaces it) and is written
beside its place and renamed when complete (:mod:`evio_lib.io.output_dir`): no half-written folder is ever left.

The ECD folder's ``events.txt`` is written a block of events at a time from the recording's events (on disk for a
bag or an HDF5 file), so converting a recording of any length holds one block in memory; the cache's
``sequence.npz`` is written by :func:`evio_lib.io.cache.save_sequence_npz`, whose events NumPy copies into the
archive in buffered blocks.
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["add_convert_arguments", "main_convert", "read_recording", "write_ecd_streamed"]


def add_convert_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``python -m evio_lib convert``."""
    from evio_lib.cli_args import add_force_argument, output_folder

    parser.add_argument("source", metavar="SOURCE",
                        help="a recording: a ROS bag (.bag or a ROS2 folder), an HDF5 file (.h5/.hdf5: DSEC, TUM-VIE, "
                             "MVSEC), an AEDAT4 file, an ECD or EuRoC folder, or a preset (boxes_like, aerial_like)")
    parser.add_argument("--out", type=output_folder(), required=True,
                        help="the folder to write (new or empty unless --force)")
    parser.add_argument("--format", choices=("ecd", "cache"), default="ecd",
                        help="ecd: the ECD text layout (events.txt, images/, imu.txt, calib.txt, groundtruth.txt); "
                             "cache: the project's binary cache DIR/sequence.npz (default ecd)")
    parser.add_argument("--topics", default=None, metavar="TOPICS",
                        help="a ROS bag's topics (a preset: ecd, mvsec-left, mvsec-right, uzh-fpv, vector-left; or "
                             "role=/topic pairs) or an MVSEC file's camera (davis/left)")
    parser.add_argument("--calib", type=Path, default=None,
                        help="camera calibration 'fx fy cx cy k1 k2 p1 p2 [k3]' (the ECD calib.txt format), for "
                             "recordings that hold none or to replace theirs")
    parser.add_argument("--duration", type=float, default=None, help="presets only: seconds simulated")
    add_force_argument(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    return parser


def read_recording(source: str | Path, *, topics: str | None = None, calib: str | Path | None = None,
                   duration: float | None = None, progress: bool = False) -> Any:
    """Return the Sequence of any recording the library reads, with its reader's checks (no IMU or camera
    required, unlike ``run``); ``calib`` sets the camera."""
    from evio_lib.pipeline.dataset import PRESETS, _is_bag_or_h5, _is_euroc, simulate_preset

    text = str(source)
    path = Path(text)
    if topics is not None and not _is_bag_or_h5(text):
        raise ValueError("--topics applies to ROS bags and MVSEC HDF5 files")
    if duration is not None and text not in PRESETS:
        raise ValueError("--duration applies to simulated presets; a recording is converted whole")
    if text in PRESETS:
        if calib is not None:
            raise ValueError(f"--calib applies to recordings; the preset {text} knows its camera")
        seq = simulate_preset(text, duration, with_events=True, progress=progress)
    elif _is_bag_or_h5(text):
        if path.suffix.lower() in (".h5", ".hdf5"):
            from evio_lib.io.hdf5 import read_hdf5

            seq = read_hdf5(path, group=topics)
        else:
            from evio_lib.io.rosbag import read_rosbag

            seq = read_rosbag(path, topics=topics)
    elif path.is_file() and path.suffix.lower() == ".aedat4":
        from evio_lib.io.aedat4 import read_aedat4

        seq = read_aedat4(path)
    elif path.is_dir() and _is_euroc(path):
        from evio_lib.io.euroc import read_euroc

        seq = read_euroc(path)
    elif path.is_dir() and (path / "events.txt").is_file():
        from evio_lib.io.ecd import read_ecd

        seq = read_ecd(path)
    else:
        raise ValueError(f"SOURCE {text!r} is not a recording the library reads: expected a preset "
                         f"({', '.join(PRESETS)}), a ROS bag (.bag or a ROS2 folder), an HDF5 file (.h5, .hdf5), an "
                         f"AEDAT4 file, an ECD folder (events.txt) or a EuRoC folder (mav0/)")
    if calib is not None:
        from evio_lib.io.ecd import read_calib

        if seq.sensor_size is None:
            raise ValueError(f"{text}: the sensor size is unknown, so --calib cannot be checked against it")
        seq.camera = read_calib(calib, *seq.sensor_size)
    return seq


def write_ecd_streamed(sequence: Any, folder: Path, progress: bool = False) -> Path:
    """Write ``sequence`` as an ECD folder (:func:`evio_lib.io.ecd.write_ecd`) with its events written a block at a
    time: the same text ``write_ecd`` writes (nine decimals when every time lies on the nanosecond grid, else the
    shortest exact form), read back exactly."""
    from evio_lib.io.ecd import write_ecd
    from evio_lib.io.errors import time_format
    from evio_lib.io.event_source import event_source

    events = sequence.events
    head = dataclasses.replace(sequence, events=None)  # everything but the events, checked and written by write_ecd
    write_ecd(head, folder, progress=progress)
    source = event_source(events)
    fmt = "%.9f"
    for _, chunk in source.chunks():  # the format holds for the whole column, as write_ecd decides it
        if time_format(chunk["t"]) != "%.9f":
            fmt = "%r"
            break
    row = f"{fmt} %d %d %d\n"
    with open(folder / "events.txt", "w", encoding="utf-8", newline="\n") as f:
        for _, chunk in source.chunks():
            for a in range(0, chunk.size, 200_000):
                block = chunk[a:a + 200_000]
                columns = [block["t"].tolist(), block["x"].tolist(), block["y"].tolist(),
                           (block["p"] > 0).astype(np.int8).tolist()]
                f.write("".join([row % r for r in zip(*columns)]))
    return folder


def main_convert(args: argparse.Namespace) -> int:
    """Run ``convert`` (see :func:`add_convert_arguments`); return the exit code."""
    from evio_lib.io.output_dir import atomic_output_dir, check_output_dir
    from evio_lib.pipeline.dataset import PRESETS

    check_output_dir(args.out, args.force, name="--out", inputs=[
        ("the input recording", None if str(args.source) in PRESETS else args.source),
        ("the --calib file", args.calib)])
    seq = read_recording(args.source, topics=args.topics, calib=args.calib, duration=args.duration,
                         progress=not args.quiet)
    with atomic_output_dir(args.out, args.force) as tmp:
        if args.format == "ecd":
            write_ecd_streamed(seq, tmp, progress=not args.quiet)
        else:
            from evio_lib.io.cache import save_sequence_npz

            save_sequence_npz(seq, tmp / "sequence.npz")
    print(f"wrote {len(seq.events):,} events, {len(seq.frames)} frames, "
          f"{0 if seq.imu is None else len(seq.imu)} IMU samples of {seq.name} to {args.out} ({args.format})")
    return 0
