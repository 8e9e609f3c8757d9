"""Shared set-up of the validation-image probes (``descriptor_invariance.py``, ``detector_localisation.py``).

Both scripts warp ``datasets.image_pool("val")`` images (never trained on) by known homographies and run the shipped
CNN next to classical detectors; this module holds their common options, detector set-up and the similarity warp.
Run the scripts from the repository root (``python bench/NAME.py``), which puts this folder on the import path.
"""
from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from evio_lib.features import create_detector
from evio_lib.features.evaluation.options import scales_argument
from evio_lib.features.network import shipped_weights
from evio_lib.features.training.datasets import image_pool


def similarity(shape: tuple[int, int], zoom: float, degrees: float) -> np.ndarray:
    """Return the (3, 3) zoom-and-rotation homography about the pixel centre of an image of ``shape``.

    ``H = [[z R, c - z R c], [0, 1]]`` with zoom z, rotation R by ``degrees`` and c the centre ((W-1)/2, (H-1)/2).
    """
    height, width = shape
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    a = np.deg2rad(degrees)
    A = zoom * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    H = np.eye(3)
    H[:2, :2], H[:2, 2] = A, centre - A @ centre
    return H


def probe_parser(description: str, *, detectors: list[str], size: str, images: int, keypoints: int, nms: int
                 ) -> argparse.ArgumentParser:
    """Return the probes' parser (--weights, --detectors, --size, --images, --keypoints, --nms, --seed, --cnn-scales) with these
    defaults."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--weights", nargs="*", default=shipped_weights(),
                        help="SuperPoint weights: shipped names or .pt paths (default: every shipped file)")
    parser.add_argument("--detectors", nargs="*", default=detectors, help="other detectors by name")
    parser.add_argument("--size", default=size, help="HxW of the images")
    parser.add_argument("--images", type=int, default=images)
    parser.add_argument("--keypoints", type=int, default=keypoints)
    parser.add_argument("--nms", type=int, default=nms)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cnn-scales", type=scales_argument, default=(1.0,),
                        help="the networks' pyramid: comma-separated scales (default 1: one level, the 8 x 8 cells this "
                             "probe is about) or auto (the detector's default pyramid)")
    return parser


def probe_setup(args: argparse.Namespace) -> tuple[tuple[int, int], list[np.ndarray], dict[str, Any]]:
    """Return (shape, validation images, {name: detector}) for parsed probe options (CNN weights first)."""
    shape = tuple(int(v) for v in args.size.lower().split("x"))
    images = image_pool("val", seed=args.seed, size=shape, n_images=args.images)
    detectors = {w: create_detector("superpoint", weights=w, max_keypoints=args.keypoints, nms_radius=args.nms,
                                    scales=args.cnn_scales) for w in args.weights}
    detectors |= {n: create_detector(n, max_keypoints=args.keypoints, nms_radius=args.nms) for n in args.detectors}
    return shape, images, detectors
