"""Options of ``python -m evio_lib features-train``: the parser alone, so that ``--help`` and a usage error need
neither torch nor the training code (:func:`evio_lib.features.training.train.main_train` runs the command)."""
from __future__ import annotations

import argparse
import json
from typing import Any

__all__ = ["add_train_arguments"]


def _parse_size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--image-size must look like 120x160 (height x width); got {text!r}") from None
    return h, w


def _parse_set(text: str) -> tuple[str, Any]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"--set must look like KEY=VALUE (VALUE in JSON); got {text!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value  # a bare string


def add_train_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``features-train`` options to a parser and return it (the lead wires it into the CLI)."""
    from evio_lib.cli_args import integer, output_folder, real

    parser.add_argument("variants", nargs="*", metavar="VARIANT",
                        help="variant names (configs in evio_lib/features/configs) or config file paths")
    parser.add_argument("--list", action="store_true", help="list the shipped variants and exit")
    parser.add_argument("--chain", action="store_true",
                        help="also train the variants each one depends on, in order (finished ones are reused)")
    parser.add_argument("--steps", type=integer(minimum=1), dest="max_steps",
                        help="total optimiser steps, >= 1 (overrides the config)")
    parser.add_argument("--epochs", type=integer(minimum=1), help="epochs, >= 1 (used when the config has no max_steps)")
    parser.add_argument("--batch-size", type=integer(minimum=1), dest="batch_size",
                        help="images per optimiser step, >= 1 (default: the config's)")
    parser.add_argument("--image-size", type=_parse_size, dest="image_size",
                        help="training image size HxW, multiples of 8 (default: the config's)")
    parser.add_argument("--device", choices=["auto", "cpu", "cuda"],
                        help="where to train: auto takes CUDA when available (default: the config's)")
    parser.add_argument("--seed", type=integer(minimum=0),
                        help="seed of the initialisation, the data and the augmentation, >= 0 (default: the config's)")
    parser.add_argument("--num-workers", type=integer(minimum=0), dest="num_workers",
                        help="data-loading worker processes, >= 0 (0: load in the training process)")
    parser.add_argument("--threads", type=integer(minimum=1), dest="num_threads",
                        help="torch CPU threads, >= 1 (default: torch's)")
    parser.add_argument("--max-minutes", type=real(above=0.0), dest="max_minutes",
                        help="stop each training call after this many minutes (validate and save first); "
                             "--resume continues")
    parser.add_argument("--out", type=output_folder(), dest="checkpoint_dir",
                        help="checkpoint folder (default runs/features); each variant trains into OUT/VARIANT, "
                             "which must be new or empty unless --resume or --force")
    parser.add_argument("--photos", metavar="DIR",
                        help="folder of photographs (.jpg/.png/...) whose train and val photographs join the "
                             "real-image pools (60 %% of each; its test photographs are never trained on); 'auto' the "
                             "shared folder, 'none' no folder (default: the config's, none in the shipped configs)")
    parser.add_argument("--set", type=_parse_set, action="append", default=[], metavar="KEY=VALUE",
                        help="any other config field, VALUE in JSON (repeatable), e.g. --set n_homographies=20")
    parser.add_argument("--resume", action="store_true", help="continue from <out>/<variant>/last.pt")
    parser.add_argument("--force", action="store_true",
                        help="train the named variants from scratch even if OUT/VARIANT holds a run; the old run is "
                             "deleted once the new training returns (restored if it fails)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--select-snapshots", action="store_true", dest="select_snapshots",
                        help="train nothing: score the variant's step_*.pt snapshots on the validation benchmark and "
                             "copy the best to best_benchmark.pt")
    return parser
