"""Training of the SuperPoint-style network in stages: MagicPoint, detector rounds, detector + descriptor.

A training *variant* (thesis §3.2.5, Table 1) is one JSON file in ``evio_lib/features/configs/`` that fills a
:class:`TrainConfig`. Three stage types:

* ``"magicpoint"`` -- detector only, on Synthetic Shapes generated on the fly (thesis §3.2.5.1);
* ``"detector"`` -- detector only, on the real-image pool labelled by homographic adaptation with the model of
  ``labels_from`` (thesis §3.2.5.2-3.2.5.3, "Detector (Round k)");
* ``"detdesc"`` -- detector + descriptor on warped pairs of pool images with those labels, total loss
  ``L = L_p(X, Y) + L_p(X', Y') + lambda L_d(D, D', S)`` (Eq. 8; thesis §3.2.5.4-3.2.5.5);
* ``"distill"`` -- detector + descriptor of a (smaller) network trained to give the outputs of the trained network
  ``labels_from`` (the teacher) on augmented pool images: ``L = L_det + lambda L_desc``, the per-cell KL divergence
  of the 65-way softmaxes plus the descriptors' cosine distance (:mod:`evio_lib.features.training.distill`; not in
  the thesis). Its validation precision and recall compare the network's keypoints with the teacher's.

``init_from`` starts from the weights of an earlier stage (the thesis's "pre-trained" variants; a detector-only
checkpoint leaves the descriptor head at its seeded initialisation); without it the network starts from a seeded
random initialisation. Adam with the thesis's learning rates. Validation every ``val_every`` steps on held-out images
(the val split, not augmented, thesis §3.2.2) gives the detector loss and precision/recall (Eqs. 13-14, exact and
within 1 px); the best model is the one with the lowest validation loss (the detector loss; Eq. 8's total for
detdesc), ties broken by the higher precision + recall (thesis §3.2.5.1: "with an emphasis on the loss").

Reproducibility: the data order of epoch e is a permutation drawn from ``default_rng([seed, e])``, the datasets
draw their augmentation from (seed, index, epoch), and the random label choice of multi-label cells (Eq. 9) from a
torch generator seeded by (seed, step), so step s sees the same batch and the same labels whether or not the run was
interrupted. A checkpoint holds the model, the Adam state, the step, the losses so far and the torch RNG states:
``train(config, resume=True)`` continues bit-identically on the CPU.

Files of a run, under ``<checkpoint_dir>/<variant>/`` (default ``runs/features/``, git-ignored): ``last.pt``
(resume), ``best.pt`` (best validation, model only; load it with
``evio_lib.features.network.load_model`` / ``SuperPointDetector(weights=PATH)``), ``config.json`` and
``history.json``. :func:`run_chain` appends what it ran to ``<checkpoint_dir>/chain_log.json``.

Reference: thesis §3.2.1-3.2.5, Table 1; DeTone, Malisiewicz & Rabinovich, "SuperPoint", CVPRW 2018.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import shlex
import sys
import time
import tomllib
import warnings
from dataclasses import dataclass, field
from numbers import Integral, Real
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Subset

from evio_lib.features.network import (
    MODEL_CONFIGS,
    SuperPointNet,
    build_model,
    extract_keypoints,
    inference_model,
    load_checkpoint,
    logits_to_heatmap,
    pad_to_cells,
    resolve_weights,
    save_checkpoint,
    shipped_weights,
)
from evio_lib.features.training.augment import HOMOGRAPHIC_PAIR, HomographicConfig, PairSample
from evio_lib.features.training.losses import descriptor_cell_stats, detector_loss, superpoint_loss
from evio_lib.features.training.metrics import detection_counts, keypoints_to_map
from evio_lib.features.training.reprojection import reprojection_loss
from evio_lib.features.training.options import add_train_arguments  # the command's options (no torch)

__all__ = [
    "STAGES",
    "SELECTION_METRICS",
    "CONFIG_DIR",
    "DEFAULT_CHECKPOINT_DIR",
    "TrainConfig",
    "TrainResult",
    "available_configs",
    "load_config",
    "variant_dependencies",
    "checkpoint_path",
    "load_event_frames",
    "training_images",
    "export_labels",
    "benchmark_snapshots",
    "build_training_model",
    "train",
    "run_chain",
    "add_train_arguments",
    "main_train",
]

STAGES = ("magicpoint", "detector", "detdesc", "distill")
#: Validation quantities that ``TrainConfig.select_on`` may name, and whether larger is better.
SELECTION_METRICS = {"loss": False, "desc_nn_accuracy": True}
CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"  # evio_lib/features/configs
DEFAULT_CHECKPOINT_DIR = Path(__file__).resolve().parents[3] / "runs" / "features"  # git-ignored
_VAL_THRESHOLD = 1.0 / 65.0  # detection threshold of the validation metrics (thesis §3.2.4)
_VAL_NMS = 4  # NMS radius of the validation detections
_VAL_SEED = 9_999  # label-choice seed of the validation loss (the same draw at every validation)
_LAST, _BEST = "last.pt", "best.pt"


# ---------------------------------------------------------------------------------------------- the config
def _bad(name: str, value: Any, expected: str) -> ValueError:
    return ValueError(f"{name} must be {expected}; got {value!r}")


def _int(name: str, value: Any, minimum: int, allow_none: bool = False) -> int | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, Integral) or value < minimum:
        raise _bad(name, value, f"an int >= {minimum}" + (" or null" if allow_none else ""))
    return int(value)


def _real(name: str, value: Any, minimum: float, strict: bool = False) -> float:
    ok = not isinstance(value, bool) and isinstance(value, Real) and math.isfinite(value)
    if not ok or value < minimum or (strict and value == minimum):
        raise _bad(name, value, f"a finite number {'>' if strict else '>='} {minimum}")
    return float(value)


@dataclass(frozen=True)
class TrainConfig:
    """Everything one training variant needs; load it with :func:`load_config`.

    Args:
        name: variant name (thesis Table 1 row, e.g. ``"pretrained_detdesc_round2"``); the run folder's name.
        stage: ``"magicpoint"`` (synthetic shapes, detector only), ``"detector"`` (real images, detector only),
            ``"detdesc"`` (real warped pairs, detector + descriptor) or ``"distill"`` (real images, detector +
            descriptor learning the outputs of ``labels_from``).
        model: preset of ``superpoint.MODEL_CONFIGS`` ("full" = thesis architecture, "narrow") or a config dict.
        init_from: variant name or ``.pt`` path whose weights initialise the network ("pre-trained"), or None.
        labels_from: variant name or ``.pt`` path of the model whose homographic adaptation labels the real
            images (required for "detector" and "detdesc", unused for "magicpoint"); for "distill" the teacher
            whose outputs the network learns (a detector + descriptor checkpoint).
        n_homographies: homographies per image in the label export (thesis §3.2.5.2: 100).
        label_threshold: keypoint threshold of the exported heatmap (SuperPoint: 0.015).
        label_max_keypoints: keep only the strongest this many label points per image (None: all above the threshold).
        image_size: (H, W) training image size, multiples of 8 (thesis: 120 x 160 shapes, 240 x 320 real).
        batch_size: images (or pairs) per step.
        epochs: passes over the training set; used when ``max_steps`` is None.
        max_steps: total optimiser steps (overrides ``epochs``).
        lr: Adam learning rate (other Adam parameters at their defaults, as in the thesis).
        lambda_d: weight of the positive pairs in the descriptor hinge loss (Eq. 12).
        lambda_loss: weight lambda of the descriptor loss in Eq. 8 (of the descriptor term for "distill").
        lambda_reprojection: weight lambda_r of the reprojection loss added to Eq. 8 for DetDesc pairs
            (:func:`evio_lib.features.training.reprojection.reprojection_loss`: a cell's refined peak must land
            where the homography maps it, sub-pixel); 0 (default) keeps the thesis's loss. Validation reports the
            term (``reprojection``, pixels) for every DetDesc run.
        seed: seed of the initialisation, the data order, the augmentation and the label choice.
        pool_seed: seed of the real-image pool (crops, render poses) and of the label export's homographies.
        render_zoom: rendered pool scenes are drawn this many times larger before the random crop (``datasets.image_pool``),
            so training crops also show the content scale of the 480 x 640 benchmark views (1: off).
        pair_homography: overrides of ``augment.HOMOGRAPHIC_PAIR``'s fields (a dict, e.g. ``{"fill_view": true,
            "patch_ratio": 0.75}``) for the warped copy of DetDesc training pairs; None keeps its defaults.
        n_train_images: training set size (synthetic images, or real pool images).
        n_val_images: validation set size.
        augment: photometric + homographic augmentation of the training images (thesis: on).
        event_frames: None, a path to an ``.npy``/``.npz`` (N, H, W) stack of event frames, or a dict
            ``{"simulate": preset, "duration": s, "seed": k, "events_per_frame": n}`` -- the "Events" variants.
        event_fraction: share of the real pool taken by event frames (thesis: about 20 %).
        photos: None, or a folder of photographs whose train / val photographs join the real pools
            (``datasets.image_pool(photos=...)``: ``datasets.FOLDER_SHARE`` of each pool; the split of each
            photograph is ``evio_lib.sim.photos.photo_split``, so its test photographs are never trained on).
            ``"auto"`` is the shared folder (``evio_lib.sim.photos.default_photo_folder``), ``"none"`` None; a
            folder is stored as its absolute path, and the checkpoints record the folder's
            ``photo_fingerprint``, so a resumed run refuses other photographs. Stage "magicpoint" (synthetic
            shapes) keeps None.
        device: "cpu", "cuda" or "auto" (CUDA when available).
        num_workers: DataLoader worker processes (0: load in the main process); also the processes that render the
            real-image pool (at least one).
        num_threads: torch CPU threads during training (None: torch's default); 1 is several times faster than 2
            on a 2-core machine that other jobs keep busy. Restored when :func:`train` returns.
        checkpoint_dir: folder of the run folders (None: ``runs/features`` in the repository).
        checkpoint_every: write ``last.pt`` every this many steps (and at the end).
        val_every: validate every this many steps (and at the end).
        select_on: which validation quantity picks ``best.pt``: "loss" (lowest Eq. 8 loss, the thesis's) or
            "desc_nn_accuracy" (highest nearest-neighbour retrieval of corresponding cells; DetDesc stages).
        snapshot_every: also keep the weights of every this many steps as ``step_NNNNNNN.pt`` (None: none), e.g. to
            choose a checkpoint afterwards on the validation benchmark.
        max_minutes: wall-clock budget of one :func:`train` call (None: none). When it is spent the call stops
            after the current step, validates and writes ``last.pt``; the result equals a run with ``max_steps`` set
            to the steps done (the learning rate is constant), and ``--resume`` continues it. For lent machines
            whose commands have a time limit.
        description: one line for humans (the thesis's name of the variant).
    """

    name: str
    stage: str
    model: str | dict[str, Any] = "full"
    init_from: str | None = None
    labels_from: str | None = None
    n_homographies: int = 100
    label_threshold: float = 0.015
    label_max_keypoints: int | None = None
    image_size: tuple[int, int] = (120, 160)
    batch_size: int = 8
    epochs: int | None = None
    max_steps: int | None = 1000
    lr: float = 1e-3
    lambda_d: float = 250.0
    lambda_loss: float = 1.0
    lambda_reprojection: float = 0.0
    seed: int = 0
    pool_seed: int = 0
    render_zoom: float = 1.0
    pair_homography: dict[str, Any] | None = None
    n_train_images: int = 400
    n_val_images: int = 50
    augment: bool = True
    event_frames: str | dict[str, Any] | None = None
    event_fraction: float = 0.2
    photos: str | None = None
    device: str = "auto"
    num_workers: int = 0
    num_threads: int | None = None
    checkpoint_dir: str | None = None
    checkpoint_every: int = 100
    val_every: int = 250
    select_on: str = "loss"
    snapshot_every: int | None = None
    max_minutes: float | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or any(c in self.name for c in "/\\ "):
            raise _bad("name", self.name, "a non-empty string without '/', '\\' or spaces")
        if self.stage not in STAGES:
            raise _bad("stage", self.stage, f"one of {STAGES}")
        if isinstance(self.model, str):
            if self.model not in MODEL_CONFIGS:
                raise _bad("model", self.model, f"one of {sorted(MODEL_CONFIGS)} or a SuperPointNet config dict")
        elif isinstance(self.model, Mapping):
            object.__setattr__(self, "model", dict(self.model))
            SuperPointNet.from_config({k: v for k, v in self.model.items() if k != "detector_only"})  # validates
        else:
            raise _bad("model", self.model, f"one of {sorted(MODEL_CONFIGS)} or a SuperPointNet config dict")
        for key in ("init_from", "labels_from"):
            value = getattr(self, key)
            if value is not None and (not isinstance(value, str) or not value.strip()):
                raise _bad(key, value, "a variant name, a .pt path or null")
        if self.stage != "magicpoint" and self.labels_from is None:
            raise ValueError(f"labels_from must name the variant that labels the real images for stage {self.stage!r}; got None")
        _int("n_homographies", self.n_homographies, 1)
        _real("label_threshold", self.label_threshold, 0.0, strict=True)
        _int("label_max_keypoints", self.label_max_keypoints, 1, allow_none=True)
        try:
            size = tuple(int(v) for v in self.image_size)
        except (TypeError, ValueError):
            raise _bad("image_size", self.image_size, "(H, W), multiples of 8 and >= 16") from None
        if len(size) != 2 or size != tuple(self.image_size) or min(size) < 16 or size[0] % 8 or size[1] % 8:
            raise _bad("image_size", self.image_size, "(H, W), multiples of 8 and >= 16")
        object.__setattr__(self, "image_size", size)
        _int("batch_size", self.batch_size, 1)
        _int("epochs", self.epochs, 1, allow_none=True)
        _int("max_steps", self.max_steps, 1, allow_none=True)
        if self.epochs is None and self.max_steps is None:
            raise ValueError("epochs and max_steps must not both be null; set one of them")
        _real("lr", self.lr, 0.0, strict=True)
        _real("lambda_d", self.lambda_d, 0.0)
        _real("lambda_loss", self.lambda_loss, 0.0)
        _real("lambda_reprojection", self.lambda_reprojection, 0.0)
        _int("seed", self.seed, 0)
        _int("pool_seed", self.pool_seed, 0)
        _real("render_zoom", self.render_zoom, 1.0)
        if self.pair_homography is not None:
            if not isinstance(self.pair_homography, Mapping):
                raise _bad("pair_homography", self.pair_homography, "null or a dict of HomographicConfig fields")
            object.__setattr__(self, "pair_homography", dict(self.pair_homography))
            self.pair_homographic()  # validates the fields and their values
        if self.select_on not in SELECTION_METRICS:
            raise _bad("select_on", self.select_on, f"one of {sorted(SELECTION_METRICS)}")
        if self.stage == "distill" and self.select_on != "loss":
            raise _bad("select_on", self.select_on, "'loss' for stage 'distill' (it measures no descriptor retrieval)")
        if self.lambda_reprojection > 0 and self.stage != "detdesc":
            raise _bad("lambda_reprojection", self.lambda_reprojection,
                       f"0 for stage {self.stage!r} (the reprojection loss needs the warped pairs of stage 'detdesc')")
        _int("snapshot_every", self.snapshot_every, 1, allow_none=True)
        _int("n_train_images", self.n_train_images, 1)
        _int("n_val_images", self.n_val_images, 1)
        if self.n_train_images < self.batch_size:
            raise ValueError(f"n_train_images must be >= batch_size ({self.batch_size}); got {self.n_train_images}")
        if not isinstance(self.augment, bool):
            raise _bad("augment", self.augment, "true or false")
        if self.event_frames is not None:
            if self.stage == "magicpoint":
                raise ValueError("event_frames must be null for stage 'magicpoint' (synthetic shapes only)")
            if isinstance(self.event_frames, Mapping):
                spec = dict(self.event_frames)
                unknown = sorted(set(spec) - {"simulate", "duration", "seed", "events_per_frame", "reconstructor",
                                              "window_fraction"})
                if "simulate" not in spec or unknown:
                    raise _bad("event_frames", self.event_frames,
                               "a path or {'simulate': preset, 'duration', 'seed', 'events_per_frame' or "
                               "'window_fraction', 'reconstructor'}")
                if "window_fraction" in spec:
                    _real("event_frames window_fraction", spec["window_fraction"], 0.0, strict=True)
                if spec.get("reconstructor") is not None:
                    from evio_lib.events.reconstruct import available_reconstructors

                    if spec["reconstructor"] not in available_reconstructors():
                        raise _bad("event_frames reconstructor", spec["reconstructor"],
                                   f"one of {available_reconstructors()}")
                object.__setattr__(self, "event_frames", spec)
            elif not isinstance(self.event_frames, str) or not self.event_frames:
                raise _bad("event_frames", self.event_frames, "null, a path to an .npy/.npz stack or a simulate dict")
        frac = _real("event_fraction", self.event_fraction, 0.0)
        if frac > 1.0:
            raise _bad("event_fraction", self.event_fraction, "a number in [0, 1]")
        if self.photos is not None:
            if not isinstance(self.photos, (str, Path)) or not str(self.photos):
                raise _bad("photos", self.photos, "null, 'auto', 'none' or a folder of photographs")
            from evio_lib.sim.photos import resolve_photo_option

            folder = resolve_photo_option(self.photos)  # ValueError naming the folder when it holds no photograph
            if self.stage == "magicpoint":  # synthetic shapes only: a chain's --photos does not reach it
                folder = None
            if folder is None and str(self.photos) == "auto":
                raise ValueError("photos 'auto': no shared photo folder found (expected ../shared/data/photos beside "
                                 "the checkout or $EVIO_PHOTOS); name a folder of photographs")
            object.__setattr__(self, "photos", None if folder is None else str(Path(folder).resolve()))
        if self.device not in ("auto", "cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise _bad("device", self.device, "'auto', 'cpu' or 'cuda'")
        _int("num_workers", self.num_workers, 0)
        _int("num_threads", self.num_threads, 1, allow_none=True)
        if self.checkpoint_dir is not None and not isinstance(self.checkpoint_dir, (str, Path)):
            raise _bad("checkpoint_dir", self.checkpoint_dir, "a folder path or null")
        if self.checkpoint_dir is not None:
            object.__setattr__(self, "checkpoint_dir", str(self.checkpoint_dir))
        _int("checkpoint_every", self.checkpoint_every, 1)
        _int("val_every", self.val_every, 1)
        if self.max_minutes is not None:
            _real("max_minutes", self.max_minutes, 0.0, strict=True)
        if not isinstance(self.description, str):
            raise _bad("description", self.description, "a string")

    # -- derived values
    @property
    def detector_only(self) -> bool:
        """Return True for the detector-only stages (MagicPoint and the detector rounds)."""
        return self.stage not in ("detdesc", "distill")

    @property
    def steps_per_epoch(self) -> int:
        """Return the optimiser steps of one pass over the training set (last incomplete batch dropped)."""
        return self.n_train_images // self.batch_size

    @property
    def total_steps(self) -> int:
        """Return ``max_steps``, or ``epochs`` times :attr:`steps_per_epoch`."""
        return int(self.max_steps) if self.max_steps is not None else int(self.epochs) * self.steps_per_epoch

    @property
    def run_dir(self) -> Path:
        """Return the folder of this variant's checkpoints: ``<checkpoint_dir>/<name>``."""
        root = Path(self.checkpoint_dir) if self.checkpoint_dir is not None else DEFAULT_CHECKPOINT_DIR
        return root / self.name

    def pair_homographic(self) -> HomographicConfig:
        """Return the homographies of the warped copy of DetDesc pairs (``HOMOGRAPHIC_PAIR`` + ``pair_homography``)."""
        changes = self.pair_homography or {}
        unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(HomographicConfig)})
        if unknown:
            fields = [f.name for f in dataclasses.fields(HomographicConfig)]
            raise ValueError(f"pair_homography has unknown field(s) {unknown}; expected some of {fields}")
        try:
            config = HOMOGRAPHIC_PAIR.replace(**changes)
            config.sample(self.image_size, 0)  # sample_homography checks the values
        except (TypeError, ValueError) as error:
            raise ValueError(f"pair_homography {changes} is not a valid HomographicConfig: {error}") from None
        return config

    def to_dict(self) -> dict[str, Any]:
        """Return the config as JSON-ready plain values (tuples become lists)."""
        out = dataclasses.asdict(self)
        out["image_size"] = list(self.image_size)
        return out

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "TrainConfig":
        """Return a config from a dict, refusing unknown keys (a typo would otherwise be silently ignored)."""
        if not isinstance(values, Mapping):
            raise _bad("config", values, "a dict of TrainConfig fields")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known - {"thesis", "notes"})
        if unknown:
            raise ValueError(f"config has unknown keys {unknown}; expected some of {sorted(known)}")
        kwargs = {k: v for k, v in values.items() if k in known}
        if "image_size" in kwargs and isinstance(kwargs["image_size"], list):
            kwargs["image_size"] = tuple(kwargs["image_size"])
        missing = sorted({"name", "stage"} - set(kwargs))
        if missing:
            raise ValueError(f"config is missing the required keys {missing}")
        return cls(**kwargs)

    def replace(self, **changes: Any) -> "TrainConfig":
        """Return a copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


def available_configs(config_dir: str | Path = CONFIG_DIR) -> list[str]:
    """Return the names of the shipped variant configs (``configs/*.json`` and ``*.toml`` file stems), sorted.

    >>> {"magicpoint", "detdesc_round1", "pretrained_detdesc_round2"} <= set(available_configs())
    True
    """
    folder = Path(config_dir)
    return sorted(p.stem for p in folder.iterdir() if p.suffix in (".json", ".toml")) if folder.is_dir() else []


def _read_config_file(path: Path) -> dict[str, Any]:
    """Return the dict stored in a JSON or TOML config file."""
    try:
        if path.suffix == ".toml":
            return tomllib.loads(path.read_text())
        return json.loads(path.read_text())
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as error:
        raise ValueError(f"config file {path} is not valid {path.suffix[1:].upper()}: {error}") from None


def load_config(name_or_path: str | Path | Mapping[str, Any] | TrainConfig, **overrides: Any) -> TrainConfig:
    """Return the :class:`TrainConfig` of a shipped variant name, a ``.json``/``.toml`` file or a dict, with overrides.

    Args:
        name_or_path: variant name (see :func:`available_configs`), a config file path, a dict or a TrainConfig.
        overrides: fields to change, e.g. ``max_steps=20, device="cpu"`` (``None`` values are ignored, so
            unset command-line options can be passed through; ``epochs`` without ``max_steps`` clears
            ``max_steps`` so that the epoch count decides).

    >>> cfg = load_config("magicpoint", max_steps=5)
    >>> cfg.stage, cfg.total_steps, cfg.detector_only
    ('magicpoint', 5, True)
    """
    if isinstance(name_or_path, TrainConfig):
        values = name_or_path.to_dict()
    elif isinstance(name_or_path, Mapping):
        values = dict(name_or_path)
    elif isinstance(name_or_path, (str, Path)):
        path = Path(name_or_path)
        if path.suffix not in (".json", ".toml"):
            for suffix in (".json", ".toml"):
                candidate = CONFIG_DIR / f"{name_or_path}{suffix}"
                if candidate.is_file():
                    path = candidate
                    break
            else:
                raise ValueError(f"config {str(name_or_path)!r} is neither a config file nor a shipped variant; "
                                 f"expected one of {available_configs()} or a path to a .json/.toml file")
        if not path.is_file():
            raise ValueError(f"config file {path} does not exist")
        values = _read_config_file(path)
    else:
        raise _bad("name_or_path", name_or_path, "a variant name, a config path, a dict or a TrainConfig")
    given = {k: v for k, v in overrides.items() if v is not None}
    if "epochs" in given and "max_steps" not in given:
        given["max_steps"] = None  # an epoch count given alone replaces the config's step count
    values.update(given)
    return TrainConfig.from_dict(values)


def checkpoint_path(reference: str | Path, checkpoint_dir: str | Path | None = None, which: str = "best") -> Path:
    """Return the checkpoint file that a variant reference means: a ``.pt`` path as is, else ``<dir>/<name>/best.pt``.

    >>> checkpoint_path("magicpoint", "/tmp/runs").as_posix()
    '/tmp/runs/magicpoint/best.pt'
    """
    if which not in ("best", "last"):
        raise _bad("which", which, "'best' or 'last'")
    ref = Path(reference)
    if ref.suffix in (".pt", ".pth"):
        return ref
    root = Path(checkpoint_dir) if checkpoint_dir is not None else DEFAULT_CHECKPOINT_DIR
    return root / str(reference) / (_BEST if which == "best" else _LAST)


def _is_shipped_weights(reference: str) -> bool:
    """Return True when a reference names shipped weights (``evio_lib/weights/NAME.pt``) and no variant config.

    A variant config of the same name wins: ``init_from: "distilled_narrow"`` means that variant's own run
    (``runs/features/distilled_narrow/best.pt``), trained first by ``--chain``, not the shipped file.
    """
    return reference in shipped_weights() and reference not in available_configs()


def _existing_checkpoint(reference: str, checkpoint_dir: str | None, role: str) -> Path:
    """Return the checkpoint file of an ``init_from`` / ``labels_from`` reference, refusing a missing one.

    A ``.pt`` path is used as it is; a name is a variant's ``<checkpoint_dir>/<name>/best.pt``, or else shipped
    weights (:func:`_is_shipped_weights`). ``role`` names the field in the error.
    """
    path = checkpoint_path(reference, checkpoint_dir)
    if path.is_file():
        return path
    if Path(reference).suffix in (".pt", ".pth"):
        raise FileNotFoundError(f"{role} checkpoint {path} not found (expected a checkpoint file written by "
                                "features-train or save_checkpoint)")
    if _is_shipped_weights(reference):
        return resolve_weights(reference)
    raise FileNotFoundError(f"{role} checkpoint {path} not found: train variant {reference!r} first "
                            f"(python -m evio_lib features-train {reference}), or name shipped weights "
                            f"({', '.join(shipped_weights()) or 'none'}) or a .pt path")


def variant_dependencies(name: str, **overrides: Any) -> list[str]:
    """Return the variants that must be trained before ``name``, in training order, ending with ``name`` itself.

    Follows ``labels_from`` and ``init_from`` through the shipped configs (``.pt`` paths and the names of shipped
    weights end the chain).

    >>> variant_dependencies("pretrained_detdesc_round2")
    ['magicpoint', 'detdesc_round1', 'pretrained_detdesc_round2']
    """
    order: list[str] = []

    def visit(variant: str, stack: tuple[str, ...]) -> None:
        if variant in order:
            return
        if variant in stack:
            raise ValueError(f"config chain has a cycle: {' -> '.join(stack + (variant,))}")
        config = load_config(variant, **overrides)
        for ref in (config.labels_from, config.init_from):
            if ref is not None and Path(ref).suffix not in (".pt", ".pth") and not _is_shipped_weights(ref):
                visit(ref, stack + (variant,))
        order.append(variant)

    visit(name, ())
    return order


# ---------------------------------------------------------------------------------------------- data
_EVENT_CACHE: dict[str, Any] = {}
_POOL_CACHE: dict[tuple, list[np.ndarray]] = {}


def load_event_frames(spec: str | Path | Mapping[str, Any], name: str = "events") -> Any:
    """Return :class:`evio_lib.features.training.datasets.EventFrames` from a file or a simulated recording.

    ``spec`` is a path to an ``.npy`` (N, H, W) stack or an ``.npz`` (array ``frames``, else the first one), scaled
    to [0, 1] when it is not already; or ``{"simulate": "aerial_like", "duration": 4.0, "seed": 0,
    "events_per_frame": 15000}``: the project's simulator records the preset and every block of
    ``events_per_frame`` consecutive events becomes one frame, ``min(count / q99(count > 0), 1)`` per pixel
    (event-count frames). With ``"reconstructor": NAME`` (any name of
    :func:`evio_lib.events.create_reconstructor`, e.g. ``"firenet"``) each block is instead reconstructed into an
    intensity frame, the recurrent state carried from block to block (the thesis's event frames, §4.1); with
    ``"window_fraction": n`` the blocks hold N_e = n H W events (Eq. 87) instead of ``events_per_frame``.
    """
    from evio_lib.features.training.datasets import EventFrames

    key = json.dumps(spec if isinstance(spec, Mapping) else str(spec), sort_keys=True) + name
    if key in _EVENT_CACHE:
        return _EVENT_CACHE[key]
    if isinstance(spec, Mapping):
        from evio_lib.events.array import event_count_image
        from evio_lib.sim.presets import SimulationConfig, simulate_sequence

        spec = dict(spec)
        config = SimulationConfig(preset=str(spec["simulate"]), duration=float(spec.get("duration", 4.0)),
                                  seed=int(spec.get("seed", 0)), with_frames=False)
        sequence = simulate_sequence(config)
        width, height = sequence.sensor_size
        per_frame = int(spec.get("events_per_frame", 15000))
        if "window_fraction" in spec:
            from evio_lib.events.representations import window_size_from_fraction

            per_frame = window_size_from_fraction(float(spec["window_fraction"]), width, height)
        frames = []
        if spec.get("reconstructor"):
            from evio_lib.events.reconstruct import create_reconstructor, reconstruct_windows
            from evio_lib.events.representations import count_windows

            # float32 frames unless the spec says otherwise: the same training images on every machine ("auto"
            # would give int8 frames on an x86 CPU and float32 ones on a GPU)
            reconstructor = create_reconstructor(str(spec["reconstructor"]), width, height,
                                                 precision=str(spec.get("reconstructor_precision", "float32")))
            frames = list(reconstruct_windows(reconstructor, sequence.events,
                                              count_windows(sequence.events, per_frame))[0])
        else:
            for start in range(0, len(sequence.events) - per_frame + 1, per_frame):  # loop over frames, not events
                counts = event_count_image(sequence.events[start : start + per_frame], width, height).astype(np.float32)
                scale = float(np.quantile(counts[counts > 0], 0.99)) if (counts > 0).any() else 1.0
                frames.append(np.minimum(counts / max(scale, 1.0), 1.0).astype(np.float32))  # count / q99, clipped
        label = f"{spec['simulate']}-{config.seed}" + (f"-{spec['reconstructor']}" if spec.get("reconstructor") else "")
    else:
        path = Path(spec)
        if not path.is_file():
            raise ValueError(f"event_frames {str(spec)!r} is not a file (expected an .npy/.npz (N, H, W) stack)")
        data = np.load(path)
        if isinstance(data, np.lib.npyio.NpzFile):
            data = data["frames" if "frames" in data.files else data.files[0]]
        stack = np.asarray(data)
        if stack.ndim != 3:
            raise ValueError(f"event_frames file {path} must hold an (N, H, W) stack; got shape {stack.shape}")
        if stack.dtype == np.uint8:
            stack = stack.astype(np.float32) / 255.0
        else:
            stack = stack.astype(np.float32)
            lo, hi = float(stack.min()), float(stack.max())
            if lo < 0.0 or hi > 1.0:
                stack = (stack - lo) / max(hi - lo, 1e-12)
        frames = list(stack)
        label = path.stem
    safe = "".join(c if c.isalnum() or c in "_.-" else "_" for c in f"{name}-{label}")
    result = EventFrames(frames, name=safe)
    _EVENT_CACHE[key] = result
    return result


def training_images(config: TrainConfig, split: str, progress: bool = False) -> list[np.ndarray]:
    """Return the real-image pool of a split for a config (cached in memory for the life of the process).

    ``config.num_workers`` processes render it (the same pool as one process renders).
    """
    from evio_lib.features.training.datasets import image_pool

    if split not in ("train", "val"):
        raise _bad("split", split, "'train' or 'val' (the test split is held out for the benchmark)")
    n = config.n_train_images if split == "train" else config.n_val_images
    events_key = json.dumps(config.event_frames, sort_keys=True)
    photos_key = json.dumps(photos_fingerprint(config), sort_keys=True)
    key = (split, config.pool_seed, config.image_size, n, events_key, config.event_fraction, config.render_zoom,
           photos_key)
    if key not in _POOL_CACHE:
        events = None if config.event_frames is None else load_event_frames(config.event_frames)
        _POOL_CACHE[key] = image_pool(split, config.pool_seed, config.image_size, n, event_frames=events,
                                      event_fraction=config.event_fraction, progress=progress,
                                      render_zoom=config.render_zoom, workers=max(1, config.num_workers),
                                      photos=config.photos)
    return _POOL_CACHE[key]


def photos_fingerprint(config: TrainConfig) -> dict[str, Any] | None:
    """Return the photo folder's ``evio_lib.sim.photos.photo_fingerprint`` with its path, or None without photos."""
    if config.photos is None:
        return None
    from evio_lib.sim.photos import photo_fingerprint

    return {"folder": config.photos, **photo_fingerprint(config.photos)}


def _file_digest(path: Path) -> str:
    """Return the first 12 hex digits of the SHA-1 of a file (names the label cache after the exact model)."""
    return hashlib.sha1(path.read_bytes()).hexdigest()[:12]


def _heatmap_function(model: SuperPointNet, device: torch.device) -> Callable[[np.ndarray], np.ndarray]:
    """Return ``images (B, H, W) float32 -> heatmaps (B, H, W)`` of a model (BN folded, exact up to rounding)."""
    forward = inference_model(model.to(device).eval(), "fused")

    def heatmaps(batch: np.ndarray) -> np.ndarray:
        height, width = batch.shape[1:]
        x = pad_to_cells(torch.from_numpy(np.ascontiguousarray(batch, np.float32))[:, None]).to(device)
        with torch.inference_mode():
            return logits_to_heatmap(forward(x)["logits"])[:, :height, :width].cpu().numpy()

    return heatmaps


def export_labels(
    config: TrainConfig | str,
    splits: Sequence[str] = ("train", "val"),
    *,
    progress: bool = True,
    cache_dir: str | Path | None = None,
    recompute: bool = False,
) -> dict[str, list[np.ndarray]]:
    """Return {split: per-image (N_i, 2) keypoints} from homographic adaptation with the ``labels_from`` model.

    Runs :func:`evio_lib.features.training.datasets.adaptation_labels` (N = ``n_homographies`` warps, mean response,
    threshold ``label_threshold``, NMS 4) over the config's training and validation pools; the labels are cached
    under ``data/cache/`` in a file named after the label model and the SHA-1 of its checkpoint, so retraining that
    model never reuses stale labels. Thesis §3.2.5.2 ("Exporting Detections").
    """
    from evio_lib.features.training.datasets import adaptation_labels
    from evio_lib.features.network import load_model

    config = load_config(config) if not isinstance(config, TrainConfig) else config
    if config.labels_from is None:
        raise ValueError(f"labels_from must be set to export labels; variant {config.name!r} (stage {config.stage}) has none")
    path = _existing_checkpoint(config.labels_from, config.checkpoint_dir, "labels_from")
    device = _resolve_device(config.device)
    heatmaps = _heatmap_function(load_model(path), device)
    stem = Path(config.labels_from).stem if Path(config.labels_from).suffix else config.labels_from
    events = "" if config.event_frames is None else "_events"
    if config.photos is not None:  # another pool: its own file (the images' fingerprint also differs)
        events += f"_photos-{photos_fingerprint(config)['names_sha256'][:8]}"
    labels = {}
    for split in splits:
        images = training_images(config, split, progress=progress)
        name = f"{stem}-{_file_digest(path)}{events}_{split}_{config.image_size[0]}x{config.image_size[1]}"
        labels[split] = adaptation_labels(
            images, heatmaps, name, rng=config.pool_seed, cache_dir=cache_dir, recompute=recompute,
            progress=progress, n_homographies=config.n_homographies, threshold=config.label_threshold,
        )
        if config.label_max_keypoints is not None:  # labels are strongest first: the same as max_keypoints
            labels[split] = [k[: config.label_max_keypoints] for k in labels[split]]
        _check_label_density(labels[split], config, split, progress)
    return labels


#: Fewest label points per 1 000 pixels (median over a pool) before :func:`export_labels` warns: ~19 per 120 x 160
#: image. SuperPoint's COCO labels hold a few hundred points per 240 x 320 image.
MIN_LABEL_DENSITY = 1.0


def _check_label_density(labels: Sequence[np.ndarray], config: TrainConfig, split: str, verbose: bool) -> None:
    """Print the label count per image and warn when the median density is below :data:`MIN_LABEL_DENSITY`.

    A short-trained label model with the thesis's threshold 0.015 once left a median of 1 point per training image,
    and the network trained on those labels learned to detect almost nothing; this catches that early.
    """
    counts = np.array([len(k) for k in labels], dtype=np.float64)
    if counts.size == 0:
        return
    pixels = float(config.image_size[0] * config.image_size[1])
    median = float(np.median(counts))
    if verbose:
        print(f"labels ({split}, from {config.labels_from}): {counts.mean():.1f} points per image "
              f"(median {median:.0f}, min {counts.min():.0f}, max {counts.max():.0f})", file=sys.stderr)
    if median * 1000.0 / pixels < MIN_LABEL_DENSITY:
        warnings.warn(
            f"homographic-adaptation labels of {config.name!r} ({split}) are sparse: median {median:.0f} points per "
            f"{config.image_size[0]}x{config.image_size[1]} image (expected >= {MIN_LABEL_DENSITY * pixels / 1000:.0f});"
            f" lower label_threshold (now {config.label_threshold}) or train {config.labels_from!r} longer",
            RuntimeWarning, stacklevel=3)


def _datasets(config: TrainConfig, progress: bool) -> tuple[Dataset, Dataset]:
    """Return the training and validation datasets of a config."""
    if config.stage == "magicpoint":
        from evio_lib.features.training.shapes import SyntheticShapes

        train = SyntheticShapes(config.n_train_images, split="train", seed=config.seed, shape=config.image_size,
                                augment=config.augment)
        val = SyntheticShapes(config.n_val_images, split="val", seed=config.seed, shape=config.image_size,
                              augment=False)
        return train, val
    from evio_lib.features.training.datasets import RealImages

    if config.stage == "distill":  # no labels: the teacher's outputs on each (augmented) image are the targets
        train = RealImages(training_images(config, "train", progress=progress), split="train", seed=config.seed,
                           augment=config.augment)
        val = RealImages(training_images(config, "val"), split="val", seed=config.seed, augment=False)
        return train, val
    labels = export_labels(config, progress=progress)
    pairs = config.stage == "detdesc"
    warps = config.pair_homographic()
    train = RealImages(training_images(config, "train"), split="train", seed=config.seed, keypoints=labels["train"],
                       augment=config.augment, pairs=pairs, pair_homographic=warps)
    val = RealImages(training_images(config, "val"), split="val", seed=config.seed, keypoints=labels["val"],
                     augment=False, pairs=pairs, pair_homographic=warps)
    return train, val


# ---------------------------------------------------------------------------------------------- model
def _resolve_device(device: str) -> torch.device:
    """Return the torch device of a config's ``device`` ("auto": CUDA when available)."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but CUDA is not available on this machine")
    return dev


def build_training_model(config: TrainConfig) -> SuperPointNet:
    """Return the network a config starts from: seeded random, or ``init_from``'s weights ("pre-trained").

    A detector-only checkpoint initialises the encoder and detector head of a detector+descriptor network; the
    descriptor head keeps its seeded initialisation. Any other mismatch raises ValueError.
    """
    overrides = {"detector_only": config.detector_only}
    model = build_model(config.model, seed=config.seed, **overrides)
    if config.init_from is None:
        return model
    path = _existing_checkpoint(config.init_from, config.checkpoint_dir, "init_from")
    checkpoint = load_checkpoint(path)
    source = {k: v for k, v in checkpoint["model_config"].items() if k != "detector_only"}
    target = {k: v for k, v in model.config.items() if k != "detector_only"}
    if source != target:
        raise ValueError(f"init_from {path} has model config {source}, which does not match this variant's {target}")
    state = checkpoint["state_dict"]
    if config.detector_only:
        state = {k: v for k, v in state.items() if not k.startswith("descriptor_head.")}
    missing, unexpected = model.load_state_dict(state, strict=False)
    bad = [k for k in missing if not k.startswith("descriptor_head.")] + list(unexpected)
    if bad:
        raise ValueError(f"init_from {path}: state_dict does not fit the network (keys {bad[:5]} ...)")
    return model


# ---------------------------------------------------------------------------------------------- losses and validation
def _teacher_path(config: TrainConfig) -> Path:
    """Return the teacher checkpoint of a distill config (its ``labels_from``), refusing a missing file.

    Besides a variant name or a ``.pt`` path, the teacher may be the name of shipped weights (``evio_lib/weights/``).
    """
    return _existing_checkpoint(str(config.labels_from), config.checkpoint_dir, "labels_from (the teacher)")


def _check_teacher(config: TrainConfig, student: SuperPointNet) -> str:
    """Return the SHA-1 digest of a distill config's teacher after checking that it can teach ``student``.

    Refuses (one line, before any pool is rendered or folder written) a missing file, a detector-only teacher and a
    descriptor length that differs from the student's (``model``'s ``descriptor_dim``).
    """
    from evio_lib.features.training.distill import load_teacher

    path = _teacher_path(config)
    teacher = load_teacher(path)
    if student.descriptor_dim != teacher.descriptor_dim:
        raise ValueError(f"the teacher {path} has {teacher.descriptor_dim}-D descriptors and the student "
                         f"{student.descriptor_dim}-D; set the config's model descriptor_dim to "
                         f"{teacher.descriptor_dim}")
    return _file_digest(path)


def _batch_loss(model: SuperPointNet, batch: Sequence[torch.Tensor], config: TrainConfig, generator: torch.Generator,
                device: torch.device, descriptor_stats: bool = False
                ) -> tuple[torch.Tensor, dict[str, Any], dict[str, torch.Tensor]]:
    """Return (total loss, its terms, the network outputs of the first images) for one collated batch.

    With ``descriptor_stats`` (pairs with descriptors only) the terms also hold ``desc_positive_dot``,
    ``desc_negative_dot`` and ``desc_nn_accuracy`` (:func:`~evio_lib.features.training.losses.descriptor_cell_stats`).
    """
    tensors = [t.to(device) for t in batch]
    if config.stage == "distill":
        from evio_lib.features.training.distill import distillation_loss, teacher_forward

        image = tensors[0]
        teacher = teacher_forward(_teacher_path(config), device)(image)
        out = model(image)
        loss, parts = distillation_loss(out, teacher, config.lambda_loss)  # L = L_det + lambda L_desc
        return loss, dict(parts), {**out, "teacher_logits": teacher["logits"]}
    if isinstance(batch, PairSample):
        image, kmap, mask, wimage, wkmap, wmask, H = tensors
        b = image.shape[0]
        out = model(torch.cat([image, wimage]))  # one pass over both images of the pairs
        out1 = {k: v[:b] for k, v in out.items()}
        out2 = {k: v[b:] for k, v in out.items()}
        terms = superpoint_loss(out1, out2, kmap, wkmap, H, generator=generator, valid_mask=mask,
                                valid_mask_warped=wmask, lambda_loss=config.lambda_loss, lambda_d=config.lambda_d)
        parts: dict[str, Any] = {"detector": (terms.detector + terms.detector_warped) / 2,
                                 "descriptor": terms.descriptor}
        total = terms.total
        if config.lambda_reprojection > 0 or descriptor_stats:
            reprojection = reprojection_loss(out1["logits"], out2["logits"], H, valid_mask=mask, valid_mask_warped=wmask)
            parts["reprojection"] = reprojection
            if config.lambda_reprojection > 0:
                total = total + config.lambda_reprojection * reprojection  # L + lambda_r L_r
        if descriptor_stats and "descriptors" in out:
            stats = descriptor_cell_stats(out1["descriptors"], out2["descriptors"], H, valid_mask=mask,
                                          valid_mask_warped=wmask)
            parts.update({f"desc_{key}": value for key, value in stats._asdict().items()})
        return total, parts, out1  # L = L_p(X, Y) + L_p(X', Y') + lambda L_d (Eq. 8) [+ lambda_r L_r]
    image, kmap, mask = tensors
    out = model(image)
    loss = detector_loss(out["logits"], kmap, generator=generator, valid_mask=mask)  # L_p (Eq. 9)
    return loss, {"detector": loss}, out


@torch.no_grad()
def _validate(model: SuperPointNet, data: Dataset, config: TrainConfig, device: torch.device) -> dict[str, float]:
    """Return the validation loss terms and precision/recall (exact and within 1 px) on the val set.

    The "distill" stage has no labels: its precision and recall compare the network's keypoints with the teacher's
    (the same threshold and NMS).
    """
    was_training = model.training
    model.eval()
    generator = torch.Generator().manual_seed(_VAL_SEED)
    loader = DataLoader(data, batch_size=config.batch_size, shuffle=False, num_workers=0)
    sums: dict[str, float] = {}
    counted: dict[str, int] = {}  # batches per term (a descriptor statistic is NaN when a batch has no pair)
    counts = np.zeros((2, 4), np.int64)  # tolerance 0 / 1 x (correct pred, pred, found labels, labels)
    for batch in loader:  # loop over validation batches
        loss, parts, out = _batch_loss(model, batch, config, generator, device, descriptor_stats=True)
        for key, value in {"loss": loss, **parts}.items():
            if key.startswith("desc_") and not math.isfinite(float(value)):
                continue  # no valid corresponding cells in this batch
            sums[key] = sums.get(key, 0.0) + float(value)
            counted[key] = counted.get(key, 0) + 1
        heat = logits_to_heatmap(out["logits"]).cpu()
        teacher_heat = logits_to_heatmap(out["teacher_logits"]).cpu() if "teacher_logits" in out else None
        for i in range(heat.shape[0]):  # loop over images: NMS'd detections vs labels
            kp, _ = extract_keypoints(heat[i], _VAL_THRESHOLD, _VAL_NMS, border=0, max_keypoints=None)
            pred = keypoints_to_map(kp.numpy(), heat.shape[1:])
            if teacher_heat is None:
                labels = batch[1][i].numpy()
            else:  # distill: the teacher's detections are the labels
                teacher_kp, _ = extract_keypoints(teacher_heat[i], _VAL_THRESHOLD, _VAL_NMS, border=0,
                                                  max_keypoints=None)
                labels = keypoints_to_map(teacher_kp.numpy(), heat.shape[1:])
            for row, tol in enumerate((0.0, 1.0)):
                c = detection_counts(pred, labels, valid_mask=batch[2][i].numpy(), tolerance=tol)
                counts[row] += [int(c.correct_predictions[0]), int(c.predictions[0]), int(c.found_labels[0]), int(c.labels[0])]
    model.train(was_training)
    result = {k: v / counted[k] for k, v in sums.items()}
    for row, suffix in enumerate(("", "_1px")):
        correct, pred, found, labels = counts[row]
        result[f"precision{suffix}"] = float(correct / pred) if pred else 0.0  # Eq. 13
        result[f"recall{suffix}"] = float(found / labels) if labels else 0.0  # Eq. 14
    return result


def _is_better(metrics: Mapping[str, float], best: Mapping[str, float] | None, select_on: str = "loss") -> bool:
    """Return True when ``metrics`` beats ``best`` on ``select_on`` (lower loss, or higher descriptor retrieval);
    ties (and a quantity the stage lacks, e.g. descriptor retrieval of a detector-only stage) go to the loss, then
    to precision + recall."""
    if best is None:
        return True
    if select_on != "loss" and select_on in metrics and select_on in best:
        value, best_value = round(metrics[select_on], 6), round(best[select_on], 6)
        if value != best_value:
            return value > best_value if SELECTION_METRICS[select_on] else value < best_value
    loss, best_loss = round(metrics["loss"], 6), round(best["loss"], 6)
    if loss != best_loss:
        return loss < best_loss
    return metrics["precision"] + metrics["recall"] > best["precision"] + best["recall"]


# ---------------------------------------------------------------------------------------------- training
@dataclass
class TrainResult:
    """What :func:`train` did: where the checkpoints are, the losses and the validations."""

    name: str
    run_dir: Path
    last_path: Path
    best_path: Path | None
    steps: int  #: optimiser steps completed (the run's total)
    best_step: int | None
    best_metrics: dict[str, float] | None
    train_loss: list[float] = field(default_factory=list)  #: total loss of every step 1..steps
    validation: list[dict[str, float]] = field(default_factory=list)  #: {"step", "loss", "precision", ...}
    seconds: float = 0.0  #: wall time of this call
    resumed_from: int = 0  #: step the call started from (0 = fresh run)


def _step_generator(seed: int, step: int) -> torch.Generator:
    """Return the label-choice generator of one step, seeded by (seed, step) so that resuming changes nothing."""
    return torch.Generator().manual_seed(int(np.random.SeedSequence([seed, step, 7]).generate_state(1)[0]))


def _epoch_order(seed: int, epoch: int, n: int) -> np.ndarray:
    """Return the data order of one epoch: a permutation of range(n) from ``default_rng([seed, epoch])``."""
    return np.random.default_rng([seed, epoch]).permutation(n)


def _rng_state(device: torch.device) -> dict[str, Any]:
    state: dict[str, Any] = {"torch": torch.get_rng_state()}
    if device.type == "cuda":
        state["cuda"] = torch.cuda.get_rng_state(device)
    return state


def _restore_rng(state: Mapping[str, Any], device: torch.device) -> None:
    torch.set_rng_state(state["torch"])
    if device.type == "cuda" and "cuda" in state:
        torch.cuda.set_rng_state(state["cuda"], device)


_RESUME_FREE = {"max_steps", "epochs", "device", "num_workers", "num_threads", "checkpoint_every", "val_every",
                "checkpoint_dir", "snapshot_every", "description", "max_minutes"}


def train(config: TrainConfig | str, progress: bool = True, *, resume: bool = False) -> TrainResult:
    """Return the :class:`TrainResult` of training one variant (checkpoints in ``config.run_dir``).

    Args:
        config: a :class:`TrainConfig` or a variant name / config path (see :func:`load_config`).
        progress: tqdm progress bars (training, pool rendering, label export).
        resume: continue from ``run_dir/last.pt`` if it exists (model, Adam state, step, losses, RNG states);
            the resumed run equals an uninterrupted one bit for bit on the CPU. Only the schedule fields
            (max_steps/epochs, device, num_workers, checkpoint_every, val_every) may change between the runs.
            Without ``resume`` an existing run folder is trained again from scratch (its files are overwritten).

    Stages needing labels export them first (:func:`export_labels`, cached). Reference: thesis §3.2.5.
    """
    config = load_config(config) if not isinstance(config, TrainConfig) else config
    threads = torch.get_num_threads()
    if config.num_threads is not None:
        torch.set_num_threads(config.num_threads)
    try:
        return _train(config, progress, resume)
    finally:
        torch.set_num_threads(threads)


def _train(config: TrainConfig, progress: bool, resume: bool) -> TrainResult:
    """The body of :func:`train` (thread count already set)."""
    started = time.perf_counter()
    device = _resolve_device(config.device)
    run_dir = config.run_dir
    last_path, best_path = run_dir / _LAST, run_dir / _BEST
    model = build_training_model(config).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)  # thesis: Adam, default betas / eps
    step, train_loss, validation = 0, [], []
    best_step: int | None = None
    best_metrics: dict[str, float] | None = None
    # distill: the teacher checked (and fingerprinted) before anything is rendered or written
    teacher = _check_teacher(config, model) if config.stage == "distill" else None
    photos = photos_fingerprint(config)
    if resume and last_path.is_file():
        checkpoint = load_checkpoint(last_path, map_location="cpu")
        # a field added after the checkpoint was written counts as its default value
        defaults = {f.name: f.default for f in dataclasses.fields(TrainConfig) if f.default is not dataclasses.MISSING}
        saved = defaults | checkpoint["metadata"].get("config", {})
        current = config.to_dict()
        changed = sorted(k for k in set(saved) | set(current)
                         if k not in _RESUME_FREE and saved.get(k) != current.get(k))
        if changed:
            raise ValueError(f"cannot resume {last_path}: the config differs in {changed}; only "
                             f"{sorted(_RESUME_FREE)} may change (or train without resume to start over)")
        saved_photos = checkpoint["metadata"].get("photos_fingerprint")
        if saved_photos != photos:
            raise ValueError(f"cannot resume {last_path}: it trained with the photographs {saved_photos}, and the "
                             f"folder is now {photos}; train without resume to start over")
        saved_teacher = checkpoint["metadata"].get("teacher_sha1")
        if teacher is not None and saved_teacher is not None and saved_teacher != teacher:
            raise ValueError(f"cannot resume {last_path}: its teacher was the file with SHA-1 {saved_teacher}..., "
                             f"and {_teacher_path(config)} is now {teacher}... (a different teacher); train "
                             "without resume to start over")
        from evio_lib.io.checkpoint import load_state

        load_state(model, checkpoint["state_dict"], last_path,  # one line naming the file
                   "cannot resume: its state_dict does not fit this run's network")
        load_state(optimizer, checkpoint["optimizer"], last_path,
                   "cannot resume: its optimizer state does not fit this run's optimizer")
        step = int(checkpoint["step"])
        train_loss = [float(v) for v in checkpoint["train_loss"]]
        validation = [dict(v) for v in checkpoint["validation"]]
        best_step = checkpoint.get("best_step")
        best_metrics = checkpoint.get("best_metrics") or None
        _restore_rng(checkpoint["rng"], device)
    resumed_from = step
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2))
    train_data, val_data = _datasets(config, progress)
    total = config.total_steps

    def save_last() -> None:
        save_checkpoint(model, last_path, {"variant": config.name, "stage": config.stage, "config": config.to_dict(),
                                           **({"teacher_sha1": teacher} if teacher else {}),
                                           **({"photos_fingerprint": photos} if photos else {})},
                        optimizer=optimizer.state_dict(), step=step, train_loss=list(train_loss),
                        validation=[dict(v) for v in validation], best_step=best_step,
                        best_metrics=dict(best_metrics or {}), rng=_rng_state(device))
        (run_dir / "history.json").write_text(json.dumps(
            {"variant": config.name, "step": step, "train_loss": train_loss, "validation": validation,
             "best_step": best_step, "best_metrics": best_metrics}, indent=1))

    def validate() -> None:
        nonlocal best_step, best_metrics
        metrics = _validate(model, val_data, config, device)
        validation.append({"step": step, **metrics})
        if _is_better(metrics, best_metrics, config.select_on):
            best_step, best_metrics = step, metrics
            save_checkpoint(model, best_path, {"variant": config.name, "stage": config.stage, "step": step,
                                               "validation": metrics, "config": config.to_dict(),
                                               "description": config.description,
                                               **({"teacher_sha1": teacher} if teacher else {})})

    bar = None
    if progress and step < total:
        from tqdm import tqdm

        bar = tqdm(total=total, initial=step, desc=config.name, unit="step")
    model.train()
    per_epoch = config.steps_per_epoch
    stopped_early = False  # the max_minutes budget ran out before ``total``
    while step < total:  # one iteration per (remaining part of an) epoch
        epoch, offset = divmod(step, per_epoch)
        if hasattr(train_data, "set_epoch"):
            train_data.set_epoch(epoch)
        order = _epoch_order(config.seed, epoch, len(train_data))[: per_epoch * config.batch_size]
        remaining = order[offset * config.batch_size :][: (total - step) * config.batch_size]
        loader = DataLoader(Subset(train_data, remaining.tolist()), batch_size=config.batch_size, shuffle=False,
                            num_workers=config.num_workers, drop_last=True)
        for batch in loader:  # optimiser steps
            loss, _, _ = _batch_loss(model, batch, config, _step_generator(config.seed, step), device)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            step += 1
            train_loss.append(float(loss.detach()))
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{train_loss[-1]:.3f}")
            if step % config.val_every == 0 or step == total:
                validate()
            if step % config.checkpoint_every == 0 or step == total:
                save_last()
            if config.snapshot_every is not None and step % config.snapshot_every == 0:
                save_checkpoint(model, run_dir / f"step_{step:07d}.pt",
                                {"variant": config.name, "stage": config.stage, "step": step,
                                 "config": config.to_dict(), "description": config.description})
            if config.max_minutes is not None and time.perf_counter() - started >= 60.0 * config.max_minutes:
                stopped_early = step < total
                break
        if stopped_early:
            break
    if bar is not None:
        bar.close()
    if not last_path.is_file():  # nothing to train (total reached before this call) and no file yet
        save_last()
    if not validation or validation[-1]["step"] != step:
        validate()
        save_last()
    return TrainResult(config.name, run_dir, last_path, best_path if best_path.is_file() else None, step, best_step,
                       best_metrics, train_loss, validation, time.perf_counter() - started, resumed_from)


# ---------------------------------------------------------------------------------------------- checkpoint choice
def benchmark_snapshots(
    run: str | Path,
    *,
    n_images: int = 16,
    pairs_per_image: int = 2,
    seed: int = 0,
    eps: float = 3.0,
    progress: bool = True,
) -> dict[str, Any]:
    """Score every snapshot of a run on the validation benchmark and copy the best to ``best_benchmark.pt``.

    The training validation measures 120 x 160 crops; what the network is for is the 480 x 640 benchmark. This
    runs the benchmark's homography task (thesis settings: 480 x 640, best 1000 points, NMS 8, mutual nearest
    neighbours, RANSAC) on ``heldout_pairs(pool="val")``: viewpoint and illumination pairs of validation images,
    which training never fits and the test split never sees. Each ``step_*.pt`` (see
    ``TrainConfig.snapshot_every``) and ``best.pt`` gets a score, the mean homography correctness at ``eps`` over
    the two splits (ties: the mean matching score); the winner is copied to ``<run>/best_benchmark.pt`` and every
    row is written to ``<run>/snapshot_benchmark.json``. A file whose SHA-1 that report already scored with the same
    settings is not scored again, so the call can follow a run that is still writing snapshots.

    Args:
        run: a run folder, or a variant name (its folder under ``runs/features``).
        n_images: validation images (stripe textures left out, as in the test benchmark).
        pairs_per_image: pairs per image and split.
        seed: seed of the pool and of the pairs.
        eps: correctness threshold in pixels.
        progress: print one line per snapshot.

    Returns:
        ``{"rows": [{"file", "sha1", "step", "score", "homography", "matching_score"}, ...], "best": file name,
        "n_pairs": {split: n}}`` plus the settings (eps, pool, n_images, pairs_per_image, seed).
    """
    import shutil

    from evio_lib.features.evaluation.benchmark import BenchmarkSettings, heldout_pairs, run_benchmark

    run_dir = Path(run)
    if not run_dir.is_dir():
        run_dir = DEFAULT_CHECKPOINT_DIR / str(run)
    files = sorted(run_dir.glob("step_*.pt"))
    if not files:
        raise FileNotFoundError(f"no step_*.pt snapshots in {run_dir}: train with snapshot_every set first")
    files += [run_dir / _BEST] if (run_dir / _BEST).is_file() else []
    _int("n_images", n_images, 1)
    _int("pairs_per_image", pairs_per_image, 1)
    settings = BenchmarkSettings(eps=(float(eps),), tasks=("homography",))
    setup = {"eps": float(eps), "pool": "val", "n_images": n_images, "pairs_per_image": pairs_per_image, "seed": seed}
    report_path = run_dir / "snapshot_benchmark.json"
    known: dict[str, dict[str, Any]] = {}  # rows of an earlier call with the same setup, by file digest
    n_pairs: dict[str, int] = {}
    if report_path.is_file():
        earlier = json.loads(report_path.read_text())
        if all(earlier.get(k) == v for k, v in setup.items()):
            known = {row["sha1"]: row for row in earlier.get("rows", []) if "sha1" in row}
            n_pairs = dict(earlier.get("n_pairs", {}))
    pairs: list[Any] | None = None
    rows = []
    for path in files:  # loop over snapshots
        digest = _file_digest(path)
        if digest in known:  # scored before (a snapshot never changes; best.pt may)
            rows.append({**known[digest], "file": path.name})
            continue
        if pairs is None:
            pairs = heldout_pairs(seed, n_images=n_images, pairs_per_image=pairs_per_image, pool="val")
        # one level, as the snapshots were always ranked (and as the cached rows were scored)
        result = run_benchmark("superpoint", pairs, settings, name=path.name,
                               detector_options={"weights": path, "scales": (1.0,)})
        n_pairs = dict(result["n_pairs"])
        step = load_checkpoint(path)["metadata"].get("step")
        homography = {split: float(v[float(eps)]) for split, v in result["homography"].items()}
        matching = {split: float(v[float(eps)]) for split, v in result["matching_score"].items()}
        rows.append({"file": path.name, "sha1": digest, "step": step,
                     "score": float(np.mean(list(homography.values()))), "homography": homography,
                     "matching_score": matching})
        if progress:
            print(f"{path.name:20s} step {step}: homography {homography}, matching score {matching}", flush=True)
    best = max(rows, key=lambda r: (round(r["score"], 9), float(np.mean(list(r["matching_score"].values())))))
    shutil.copyfile(run_dir / best["file"], run_dir / "best_benchmark.pt")
    report = {"rows": rows, "best": best["file"], "n_pairs": n_pairs, **setup}
    report_path.write_text(json.dumps(report, indent=1))
    return report


# ---------------------------------------------------------------------------------------------- chains and CLI
def _command(name: str, overrides: Mapping[str, Any], resume: bool) -> str:
    """Return the command line that reproduces one training call."""
    flags = {"max_steps": "--steps", "epochs": "--epochs", "batch_size": "--batch-size", "device": "--device",
             "checkpoint_dir": "--out", "seed": "--seed", "num_workers": "--num-workers", "num_threads": "--threads",
             "max_minutes": "--max-minutes", "photos": "--photos"}
    parts = ["python", "-m", "evio_lib", "features-train", name]
    for key, value in overrides.items():
        if value is None:
            continue
        if key == "image_size":
            parts += ["--image-size", f"{value[0]}x{value[1]}"]
        elif key in flags:
            parts += [flags[key], str(value)]
        else:
            parts += ["--set", f"{key}={json.dumps(value)}"]
    if resume:
        parts.append("--resume")
    return shlex.join(parts)


def run_chain(
    names: Sequence[str],
    *,
    with_dependencies: bool = True,
    resume: bool = True,
    progress: bool = True,
    log_path: str | Path | None = None,
    **overrides: Any,
) -> list[TrainResult]:
    """Return the results of training variants in order (their prerequisites first), logging every command.

    ``run_chain(["pretrained_detdesc_round2"])`` trains magicpoint, exports its labels, trains detdesc_round1,
    exports its labels and trains pretrained_detdesc_round2 (label exports happen inside :func:`train`). With
    ``resume`` (default) a finished variant is not trained again and an interrupted one continues; prerequisites
    are always resumed (never retrained when finished), only the named variants obey ``resume=False``. Every call is
    appended to ``<checkpoint_dir>/chain_log.json`` (or ``log_path``): variant, command line, full config,
    start/end time, steps, best step and validation metrics. ``overrides`` (e.g. ``max_steps``, ``device``,
    ``checkpoint_dir``) apply to every variant of the chain.
    """
    if isinstance(names, str) or not isinstance(names, Sequence) or not names:
        raise _bad("names", names, "a non-empty list of variant names")
    order: list[str] = []
    for name in names:
        for item in (variant_dependencies(name, **overrides) if with_dependencies else [name]):
            if item not in order:
                order.append(item)
    root = Path(overrides.get("checkpoint_dir") or DEFAULT_CHECKPOINT_DIR)
    log_file = Path(log_path) if log_path is not None else root / "chain_log.json"
    results = []
    for name in order:  # loop over variants
        config = load_config(name, **overrides)
        entry: dict[str, Any] = {"variant": name, "command": _command(name, overrides, resume),
                                 "config": config.to_dict(), "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
                                 "torch": torch.__version__, "device": str(_resolve_device(config.device))}
        result = train(config, progress=progress, resume=resume or name not in names)  # prerequisites: resume
        entry.update({"finished": time.strftime("%Y-%m-%dT%H:%M:%S"), "seconds": round(result.seconds, 1),
                      "steps": result.steps, "resumed_from": result.resumed_from, "best_step": result.best_step,
                      "best_metrics": result.best_metrics, "best_path": str(result.best_path)})
        log = json.loads(log_file.read_text()) if log_file.is_file() else []
        log.append(entry)
        log_file.parent.mkdir(parents=True, exist_ok=True)
        log_file.write_text(json.dumps(log, indent=2, default=str))
        results.append(result)
    return results


def main_train(args: argparse.Namespace | Sequence[str] | None = None) -> int:
    """Run ``features-train`` from parsed arguments (or an argument list); return the exit code.

    A named variant whose run folder ``OUT/VARIANT`` already holds files is refused (exit 2, before any training)
    unless ``--resume`` (continue it) or ``--force`` (train it anew: the old folder is moved aside, deleted when the
    training returns, put back when it raises).
    """
    import os
    import secrets
    import shutil

    from evio_lib.io.output_dir import OutputExistsError, check_output_dir

    if args is None or not isinstance(args, argparse.Namespace):
        parser = add_train_arguments(argparse.ArgumentParser(prog="python -m evio_lib features-train"))
        args = parser.parse_args(None if args is None else list(args))
    if args.list or not args.variants:
        for name in available_configs():
            cfg = load_config(name)
            print(f"{name:36s} {cfg.stage:10s} {cfg.description}")
        if not args.list:
            print("error: name the VARIANT(s) to train, e.g. magicpoint (the shipped variants are listed above)",
                  file=sys.stderr)
        return 0 if args.list else 2
    if getattr(args, "select_snapshots", False):
        root = Path(args.checkpoint_dir) if args.checkpoint_dir else DEFAULT_CHECKPOINT_DIR
        try:
            for name in args.variants:
                report = benchmark_snapshots(root / name, progress=not args.quiet)
                print(f"{name}: best on the validation benchmark {report['best']} -> {root / name / 'best_benchmark.pt'}")
        except (ValueError, FileNotFoundError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        return 0
    overrides = {k: getattr(args, k) for k in ("max_steps", "epochs", "batch_size", "image_size", "device", "seed",
                                               "num_workers", "num_threads", "checkpoint_dir", "max_minutes",
                                               "photos")}
    overrides.update(dict(args.set))
    overrides = {k: v for k, v in overrides.items() if v is not None}
    force = bool(getattr(args, "force", False)) and not args.resume
    set_aside: list[tuple[Path, Path]] = []  # (run folder, where its old content waits) for --force
    try:
        for name in args.variants:  # before any training: the named variants' run folders
            config = load_config(name, **overrides)
            run_dir = config.run_dir
            inputs = [("the variant config", name if Path(name).is_file() else None)]
            for key in ("init_from", "labels_from", "event_frames", "photos"):  # paths (else variant names)
                value = getattr(config, key)
                if isinstance(value, str) and Path(value).exists():
                    inputs.append((f"the {key} file", value))
            try:
                check_output_dir(run_dir, force=force or args.resume, inputs=inputs)
            except OutputExistsError as error:
                raise OutputExistsError(f"{error}, or --resume to continue that run") from None
        for name in dict.fromkeys(args.variants):  # each run folder once, even when named twice
            run_dir = load_config(name, **overrides).run_dir
            if force and run_dir.is_dir() and any(run_dir.iterdir()):
                aside = run_dir.parent / f".{run_dir.name}.old-{secrets.token_hex(4)}"
                os.rename(run_dir, aside)
                set_aside.append((run_dir, aside))
        results = run_chain(list(args.variants), with_dependencies=args.chain, resume=args.resume,
                            progress=not args.quiet, **overrides)
    except BaseException as error:
        for run_dir, aside in reversed(set_aside):  # put the old runs back
            shutil.rmtree(run_dir, ignore_errors=True)
            os.rename(aside, run_dir)
        if isinstance(error, (ValueError, FileNotFoundError)):
            print(f"error: {error}", file=sys.stderr)
            return 2
        raise
    for _, aside in set_aside:
        shutil.rmtree(aside, ignore_errors=True)
    for result in results:
        metrics = result.best_metrics or {}
        print(f"{result.name}: {result.steps} steps in {result.seconds:.0f} s, best step {result.best_step} "
              f"(val loss {metrics.get('loss', float('nan')):.4f}, precision {metrics.get('precision', 0):.3f}, "
              f"recall {metrics.get('recall', 0):.3f}) -> {result.best_path}")
    return 0
