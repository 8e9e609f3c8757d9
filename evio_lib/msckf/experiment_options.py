"""Options of ``python -m evio_lib vio-sim``: the parser alone, without SciPy or the filter
(:func:`evio_lib.msckf.experiment.main_vio_sim` runs the command; a test checks the choices against
``sim.trajectory.PRESETS`` and ``experiment.NOISE_MODELS``)."""
from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_vio_sim_arguments"]


def add_vio_sim_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``python -m evio_lib vio-sim`` to ``parser``."""
    from evio_lib.cli_args import add_force_argument, integer, output_folder, real

    parser.add_argument("preset", choices=["boxes_like", "aerial_like"], help="simulated preset trajectory and scene")
    parser.add_argument("--duration", type=real(at_least=2.0), default=None,
                        help="seconds to simulate, >= 2 (default: the preset's, 60 s boxes_like, 40 s aerial_like)")
    parser.add_argument("--recording", type=Path, default=None, metavar="DIR",
                        help="a folder written by `simulate` of this preset: the perfect tracks and the filter run on "
                             "its own IMU samples, motion and frame times instead of a new simulation (its length "
                             "replaces --duration)")
    parser.add_argument("--seed", type=integer(minimum=0), default=0,
                        help="seed of every random stream, >= 0 (default 0)")
    parser.add_argument("--features", type=integer(minimum=1), default=60,
                        help="tracked features per image, >= 1 (default 60)")
    parser.add_argument("--pixel-noise", type=real(at_least=0.0), default=1.0,
                        help="pixel noise std of the tracks, >= 0 px (default 1)")
    parser.add_argument("--no-observability-constrained", action="store_true",
                        help="plain EKF instead of the observability-constrained one")
    parser.add_argument("--noise-model", choices=["per_observation", "global_factor", "nominal"], default="per_observation",
                        help="feature noise model of the filter (default per_observation: each observation's own "
                             "covariance from the undistortion Jacobian)")
    parser.add_argument("--gate", type=real(above=0.0, below=1.0), default=0.99,
                        help="chi-square gate probability of the filter, in (0, 1) (default 0.99: the simulated tracks "
                             "hold no outliers; the library default 0.95 is for real tracks)")
    parser.add_argument("--imu-only", action="store_true", help="propagate only (no visual updates)")
    parser.add_argument("--no-baselines", action="store_true", help="skip the IMU-only baseline rows")
    parser.add_argument("--out", type=output_folder(), default=None,
                        help="folder for trajectory.txt and groundtruth.txt (TUM, IMU body; created, must be new or "
                             "empty unless --force; written when the run is complete)")
    add_force_argument(parser)
