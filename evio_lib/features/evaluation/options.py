"""Options of ``python -m evio_lib features-benchmark``: the parser alone, without OpenCV, torch or the detectors
(:func:`evio_lib.features.evaluation.benchmark.main_benchmark` runs the command)."""
from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_benchmark_arguments"]


def scales_argument(text: str) -> str | tuple[float, ...]:
    """argparse type of --cnn-scales: ``pyramid.parse_scales`` with its error as an argparse error."""
    from evio_lib.features.network.pyramid import parse_scales  # imported only when the option is given

    try:
        return parse_scales(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_benchmark_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Return ``parser`` with the options of ``python -m evio_lib features-benchmark`` added."""
    from evio_lib.cli_args import add_force_argument, integer, output_folder

    parser.add_argument("--detectors", nargs="+", metavar="NAME",
                        help="detector names (create_detector); default: every available detector. A named detector "
                             "that fails ends the command with an error unless --keep-going")
    parser.add_argument("--keep-going", action="store_true",
                        help="skip a detector that fails (report it) instead of stopping with an error")
    parser.add_argument("--dataset", choices=["heldout", "events", "hpatches", "photos"], default="heldout",
                        help="heldout: HPatches-style pairs of the held-out test images (default); events: event "
                             "frames from --event-frames and warped copies; hpatches: the real HPatches folder; "
                             "photos: the same pairs of the held-out photographs of --photos, centre-cropped to 3:4 "
                             "and resized to 480 x 640")
    parser.add_argument("--photos", default="auto", metavar="DIR",
                        help="folder of photographs for --dataset photos, split by name hash into train/val/test "
                             "(default auto: ../shared/data/photos or $EVIO_PHOTOS where present)")
    parser.add_argument("--photo-split", choices=["test", "val"], default="test",
                        help="which held-out photographs --dataset photos uses: test (default) or val (to choose "
                             "networks without looking at the test photographs)")
    parser.add_argument("--hpatches-root", type=Path, help="HPatches folder with i_*/v_* scenes (--dataset hpatches)")
    parser.add_argument("--event-frames", type=Path,
                        help=".npy (N, H, W) or .npz (array 'frames') of event frames (--dataset events)")
    parser.add_argument("--seed", type=integer(minimum=0), default=0,
                        help="seed of the image pool and the random changes, >= 0 (default 0)")
    parser.add_argument("--n-images", type=integer(minimum=1), default=None,
                        help="use only the first N images / frames / scenes per split (default: all; 2 with --fast)")
    parser.add_argument("--pairs-per-image", type=integer(minimum=1), default=None,
                        help="pairs per image and split (default 5; 1 with --fast)")
    parser.add_argument("--settings", choices=["thesis-hpatches", "thesis-events"],
                        help="evaluation settings (default: thesis-events for --dataset events, else thesis-hpatches)")
    parser.add_argument("--speed-shapes", nargs="*", default=None, metavar="HxW",
                        help="also time detect_and_describe at these resolutions (default 180x240 240x320; give the "
                             "option with no value to skip the timing)")
    parser.add_argument("--speed-frames", type=integer(minimum=1), default=None,
                        help="timed frames per resolution (default 20; 5 with --fast)")
    parser.add_argument("--out", type=output_folder(),
                        help="folder to write results.json and tables.md into (new or empty unless --force; written "
                             "when the run is complete)")
    add_force_argument(parser)
    parser.add_argument("--fast", action="store_true",
                        help="tiny run: 2 images, 1 pair each, 5 timed frames (values given explicitly win)")
    parser.add_argument("--weights", default=None,
                        help="weights of the 'superpoint' detector: a shipped name (evio_lib/weights/NAME.pt) or a .pt "
                             "path (default: the shipped default weights); the row is named after them")
    parser.add_argument("--cnn-scales", type=scales_argument, default=None, metavar="auto|S,S,...",
                        help="image pyramid of the network detectors ('superpoint' and every shipped network): auto "
                             "(their default: levels 2^(-k/4) from 1.41 down to a 240-px shorter side; one level for "
                             "smaller images) or comma-separated scale factors, e.g. 1 for the thesis's single-scale "
                             "detector; the network rows are then named with it")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    return parser
