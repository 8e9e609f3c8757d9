"""Options of ``python -m evio_lib reconstruct-data`` and ``reconstruct-train``: the parsers alone, without torch
(:func:`evio_lib.events.reconstruction.training_set.main_reconstruct_data` and
:func:`evio_lib.events.reconstruction.training.main_reconstruct_train` run the commands)."""
from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_reconstruct_train_arguments", "add_reconstruct_data_arguments"]


def add_reconstruct_data_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``python -m evio_lib reconstruct-data`` to ``parser``."""
    from evio_lib.cli_args import output_folder

    parser.add_argument("--out", type=output_folder(), required=True,
                        help="the set's folder: training_set.json, train/, val/, test/ (run again to resume or extend)")
    parser.add_argument("--sequences", type=int, default=2000,
                        help="training sequences (default 2000, 1.9 GB; the time it takes: "
                             "docs/howto/train-reconstructor.md)")
    parser.add_argument("--val", type=int, default=64, help="validation sequences (default 64)")
    parser.add_argument("--test", type=int, default=64, help="test sequences (default 64)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the set (default 0)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2); the set does not depend on it")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=JSON",
                        help="override a setting of the set, e.g. --set height=96 --set width=96")
    parser.add_argument("--photos", default="auto", metavar="DIR",
                        help="a folder of photographs for 70 %% of the textures, split by name into train/val/test "
                             "(default auto: ../shared/data/photos or $EVIO_PHOTOS where present; none: the bundled "
                             "textures alone)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def add_reconstruct_train_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``python -m evio_lib reconstruct-train`` to ``parser``."""
    from evio_lib.cli_args import output_folder

    parser.add_argument("--out", type=output_folder(), required=True,
                        help="run folder: last.pt, best.pt, history.json, config.json")
    parser.add_argument("--data", type=Path, nargs="+", default=None, metavar="SET",
                        help="train on reconstruct-data folders (their train splits together, drawn uniformly over "
                             "all their sequences; validation on the first one's val split); default: short planar "
                             "samples simulated on the fly")
    parser.add_argument("--architecture", choices=["firenet", "e2vid"], default="firenet",
                        help="firenet (38k parameters, the default) or e2vid (10.7 M parameters; needs a GPU to train)")
    parser.add_argument("--steps", type=int, default=None, help="total optimisation steps (default 3000; the time per "
                        "step: docs/howto/train-reconstructor.md)")
    parser.add_argument("--max-minutes", type=float, default=None,
                        help="stop after this many minutes (checkpoint written); --resume continues")
    parser.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    parser.add_argument("--init-from", type=Path, default=None, metavar="CHECKPOINT",
                        help="start from these weights (a reconstruct-train checkpoint of the same network): fine-tuning")
    parser.add_argument("--force", action="store_true", help="start afresh even if OUT holds files")
    parser.add_argument("--seed", type=int, default=0, help="seed of the data and of the training (default 0)")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch CPU threads and data-simulation processes (default 1; 2 on an idle 2-core machine)")
    parser.add_argument("--device", default=None, help="cpu (default) or cuda when a GPU is present")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=JSON",
                        help="override a setting, e.g. --set n_train=200 --set 'data={\"height\": 48}'")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    return parser
