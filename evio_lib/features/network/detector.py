"""The network as a feature detector: :class:`SuperPointDetector`, and every shipped checkpoint registered by name.

``create_detector("superpoint")`` is this detector with the default weights; importing this module registers every
other checkpoint ``evio_lib/weights/NAME.pt`` as detector NAME (:mod:`evio_lib.features.base` imports it on a
registry miss).
"""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch

from evio_lib.features.base import FeatureDetector, Features, register_detector, to_float_image
from evio_lib.features.network.checks import _check_count, _check_device, _check_real
from evio_lib.features.network.inference import INFERENCE_MODES, _auto_mode, inference_model
from evio_lib.features.network.model import DEFAULT_WEIGHTS, build_model, load_model, resolve_weights, shipped_weights
from evio_lib.features.network.postprocessing import logits_to_heatmap, pad_to_cells, postprocess
from evio_lib.features.network.pyramid import check_scales, merge_levels, pyramid_scales, resize_level

__all__ = ["SuperPointDetector"]


class SuperPointDetector(FeatureDetector):
    """The CNN as a FeatureDetector: ``detect_and_describe(image)`` -> keypoints, probabilities, unit descriptors.

    Args:
        max_keypoints: keep the best this many keypoints after NMS.
        nms_radius: greedy box NMS radius in pixels (thesis: 4, or 8 for 480x640 homography estimation).
        weights: a checkpoint path or the name of shipped weights in ``evio_lib/weights/`` (default
            ``DEFAULT_WEIGHTS``); None builds an untrained network, allowed only with ``allow_random=True``.
        device: "cpu" or "cuda".
        threshold: minimum keypoint probability (default 1/65).
        border: pixels at the image edge without keypoints (default 4).
        inference: "auto" (bf16 on CPUs with native bfloat16, else int8; fused fp32 on CUDA), "eager",
            "fused", "bf16" or "int8" (see :func:`inference_model`).
        model_config: preset name or config dict of the untrained network (weights=None only).
        allow_random: permit weights=None.
        seed: initialisation seed of the untrained network.
        calibration: images for int8 calibration (default :func:`calibration_images`).
        descriptor_interpolation: "bicubic" (default, thesis) or "bilinear".
        subpixel_radius: half-size of the heat-centroid window that moves each peak off the pixel grid
            (:func:`refine_keypoints`; default 2, i.e. 5 x 5); 0 keeps the thesis's integer peaks.
        num_threads: if given, ``torch.set_num_threads(num_threads)`` (process-wide).
        scales: the image pyramid the network runs on (:mod:`evio_lib.features.network.pyramid`): "auto" (default)
            takes levels 2^(-k/4) down to a shorter side of 240 pixels and two enlarged levels (2^(1/4), 2^(1/2)) on
            top, so a 480 x 640 image gets seven levels and a 180 x 240 event frame one; a sequence such as
            ``(1.0,)`` fixes the levels (``(1.0,)`` is the thesis's single-scale detector). Every level has its own
            NMS; the best ``max_keypoints`` of all levels are kept, none within ``border`` pixels of the image's
            edge.

    Any image size works: the image is padded to multiples of 8 (edge replication) and the heatmap cropped back.
    Scores are keypoint probabilities; descriptors are float32 with unit L2 norm (D = 256), (N, 0) for a
    detector-only (MagicPoint) checkpoint.

    >>> det = SuperPointDetector(weights=None, allow_random=True, inference="fused", max_keypoints=50)
    >>> f = det.detect_and_describe(np.random.default_rng(0).random((60, 90)).astype(np.float32))
    >>> f.keypoints.shape[1], f.descriptors.shape[1], len(f) <= 50
    (2, 256, True)
    """

    name = "superpoint"

    def __init__(
        self,
        max_keypoints: int = 1000,
        nms_radius: int = 4,
        *,
        weights: str | Path | None = DEFAULT_WEIGHTS,
        device: str | torch.device = "cpu",
        threshold: float = 1.0 / 65.0,
        border: int = 4,
        inference: str = "auto",
        model_config: Mapping[str, Any] | str = "full",
        allow_random: bool = False,
        seed: int = 0,
        calibration: Sequence[np.ndarray] | None = None,
        descriptor_interpolation: str = "bicubic",
        subpixel_radius: int = 2,
        num_threads: int | None = None,
        scales: str | Sequence[float] = "auto",
        **options: Any,
    ) -> None:
        super().__init__(max_keypoints=max_keypoints, nms_radius=nms_radius, **options)
        self.threshold = _check_real("threshold", threshold, minimum=0.0)
        self.border = _check_count("border", border)
        if descriptor_interpolation not in ("bicubic", "bilinear"):
            raise ValueError(
                f"descriptor_interpolation must be 'bicubic' or 'bilinear'; got {descriptor_interpolation!r}"
            )
        self.descriptor_interpolation = descriptor_interpolation
        self.subpixel_radius = _check_count("subpixel_radius", subpixel_radius)
        self.scales = check_scales(scales)
        if inference not in INFERENCE_MODES:
            raise ValueError(f"inference must be one of {INFERENCE_MODES}; got {inference!r}")
        if num_threads is not None:
            torch.set_num_threads(_check_count("num_threads", num_threads, minimum=1))
        self.device = _check_device(device)
        if weights is None:
            if not allow_random:
                raise ValueError(
                    "weights=None builds an UNTRAINED network; pass allow_random=True to confirm (tests, lessons), "
                    f"or give weights (shipped: {shipped_weights() or 'none yet'})"
                )
            model = build_model(model_config, seed=seed).eval()
            self.weights_path: Path | None = None
        else:
            self.weights_path = resolve_weights(weights)
            model = load_model(self.weights_path)
        self.model = model.to(self.device).eval()
        if inference == "auto":
            inference = _auto_mode(self.device)
        self.inference = inference
        self._forward = inference_model(self.model, inference, calibration=calibration)

    @property
    def descriptor_dim(self) -> int:
        """Return D (0 for a detector-only checkpoint)."""
        return self.model.descriptor_dim

    def scales_for(self, shape: tuple[int, int]) -> tuple[float, ...]:
        """Return the pyramid levels used for an image of ``shape`` (H, W)."""
        return pyramid_scales(shape) if self.scales == "auto" else self.scales  # type: ignore[return-value]

    def _run(self, image: np.ndarray) -> tuple[dict[str, torch.Tensor], tuple[int, int]]:
        """Return the network outputs for one image and its (H, W)."""
        img = to_float_image(image)
        x = pad_to_cells(torch.from_numpy(img)[None, None]).to(self.device)
        with torch.inference_mode():
            out = self._forward(x)
        return out, img.shape

    def heatmap(self, image: np.ndarray) -> np.ndarray:
        """Return the (H, W) float32 keypoint probability map of a grayscale image (before threshold and NMS).

        Always the network's map of the image itself (scale 1), whatever ``scales`` is; it is the map behind
        :meth:`detect_and_describe` only when ``scales_for(image.shape) == (1.0,)``.
        """
        out, (height, width) = self._run(image)
        return logits_to_heatmap(out["logits"])[0, :height, :width].cpu().numpy()

    def detect_and_describe(self, image: np.ndarray) -> Features:
        """Return keypoints (N, 2) (x, y), probabilities (N,) and unit descriptors (N, D) of a grayscale image."""
        img = to_float_image(image)
        scales = self.scales_for(img.shape)
        if scales == (1.0,):
            return self._detect_level(img)
        levels = [resize_level(img, s) for s in scales]
        found = [self._detect_level(level) for level in levels]
        return merge_levels(found, [level.shape for level in levels], img.shape, self.max_keypoints, self.border)

    def _detect_level(self, image: np.ndarray) -> Features:
        """Return the detections of one level (the thesis's single-scale post-processing)."""
        out, shape = self._run(image)
        with torch.inference_mode():
            return postprocess(
                out["logits"],
                out.get("descriptors"),
                image_shape=shape,
                threshold=self.threshold,
                nms_radius=self.nms_radius,
                border=self.border,
                max_keypoints=self.max_keypoints,
                descriptor_interpolation=self.descriptor_interpolation,
                subpixel_radius=self.subpixel_radius,
            )[0]

    def __repr__(self) -> str:
        source = self.weights_path.name if self.weights_path is not None else "untrained"
        return (
            f"SuperPointDetector(weights={source!r}, inference={self.inference!r}, device={str(self.device)!r}, "
            f"max_keypoints={self.max_keypoints}, nms_radius={self.nms_radius}, threshold={self.threshold:.4g}, "
            f"subpixel_radius={self.subpixel_radius}, scales={self.scales!r})"
        )


def _register_shipped_variants() -> None:
    """Register every shipped checkpoint ``evio_lib/weights/NAME.pt`` as detector NAME (create_detector(NAME))."""
    for name in shipped_weights():
        key = name.strip().lower().replace("-", "_").replace(" ", "_")
        if key == SuperPointDetector.name:
            continue  # "superpoint" is the built-in name (its default weights)
        factory = functools.partial(SuperPointDetector, weights=name)
        try:
            register_detector(key, factory)
        except ValueError:  # already registered (module re-import) or a built-in name: leave it
            pass


_register_shipped_variants()
