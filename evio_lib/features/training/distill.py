"""Knowledge distillation: a smaller SuperPoint-style network trained to give a trained network's outputs.

The ``"distill"`` stage of :mod:`evio_lib.features.training.train`. The *teacher* (the config's ``labels_from``, e.g.
the shipped full-width network) and the *student* (the config's ``model``, e.g. the half-width ``"narrow"`` preset,
about a quarter of the multiply-adds) see the same augmented pool image; the student learns the teacher's soft
outputs cell by cell (Hinton, Vinyals & Dean, "Distilling the knowledge in a neural network", 2015):

* detector: per 8 x 8 cell c the teacher's 65-way softmax p_T(c) (64 pixel positions + the "no point" dustbin) is the
  target of the student's, ``L_det = mean_c KL(p_T(c) || p_S(c)) = mean_c sum_k p_T,k (log p_T,k - log p_S,k)``;
* descriptor: per cell the direction of the teacher's raw descriptor, ``L_desc = mean_c (1 - <d_S, d_T> /
  (|d_S| |d_T|))``, since only the normalised descriptor is used (the post-processing samples it bilinearly at each
  keypoint and normalises again);
* ``L = L_det + lambda_loss L_desc``.

Matching the whole output distribution, not only the teacher's final keypoints, passes on how confident the teacher
is everywhere (where its second-best position is, how close a cell came to holding a point), which is what the
keypoint threshold and the NMS later act on. Why distil rather than run the thesis's chain (synthetic shapes, two
rounds of homographic adaptation, the DetDesc stage) for the smaller network: the chain takes hours on a 2-core CPU
(docs/howto/train-features.md) and its result is a different detector; distillation reuses what the shipped network
learned and aims at its outputs, so the pipeline's behaviour (thresholds, keypoint counts, descriptor distances)
carries over.

The loss covers the whole image, the black borders of a warped image included: the teacher's responses there are as
much a part of its behaviour as anywhere else. The teacher runs BN-folded in float32
(:func:`~evio_lib.features.network.inference.inference_model` "fused"; no bfloat16 rounding, whatever the CPU), without
gradients; it is loaded once per process and version of its checkpoint file.
"""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Callable

import torch
import torch.nn.functional as F

from evio_lib.features.network import SuperPointNet, inference_model, load_model

__all__ = ["distillation_loss", "load_teacher", "teacher_forward"]


def distillation_loss(student: dict[str, torch.Tensor], teacher: dict[str, torch.Tensor],
                      lambda_loss: float = 1.0) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Return (L, {"detector": L_det, "descriptor": L_desc}) of a student's outputs against a teacher's.

    Both are :class:`~evio_lib.features.network.model.SuperPointNet` outputs of the same images:
    ``"logits"`` (B, 65, Hc, Wc) and ``"descriptors"`` (B, D, Hc, Wc). See the module docstring for the terms.
    A zero loss means the student's softmax and descriptor directions equal the teacher's in every cell.

    >>> g = torch.Generator().manual_seed(0)
    >>> out = {"logits": torch.randn(2, 65, 3, 4, generator=g), "descriptors": torch.randn(2, 8, 3, 4, generator=g)}
    >>> same, parts = distillation_loss(out, out)
    >>> round(float(same), 6), sorted(parts)
    (0.0, ['descriptor', 'detector'])
    >>> other = {"logits": out["logits"].flip(1), "descriptors": -out["descriptors"]}
    >>> round(float(distillation_loss(other, out)[1]["descriptor"]), 6)  # opposite directions: 1 - (-1)
    2.0
    """
    for name, out in (("student", student), ("teacher", teacher)):
        if not isinstance(out, dict) or "logits" not in out or "descriptors" not in out:
            raise ValueError(f"{name} must be a SuperPointNet output dict with 'logits' and 'descriptors'")
    if student["logits"].shape != teacher["logits"].shape:
        raise ValueError(f"student and teacher logits differ in shape: {tuple(student['logits'].shape)} against "
                         f"{tuple(teacher['logits'].shape)}")
    if student["descriptors"].shape != teacher["descriptors"].shape:
        raise ValueError(f"student and teacher descriptors differ in shape: {tuple(student['descriptors'].shape)} "
                         f"against {tuple(teacher['descriptors'].shape)}")
    log_p_student = F.log_softmax(student["logits"].float(), dim=1)
    log_p_teacher = F.log_softmax(teacher["logits"].float(), dim=1)
    # KL(p_T || p_S) per cell, summed over the 65 channels, averaged over cells and images
    detector = (log_p_teacher.exp() * (log_p_teacher - log_p_student)).sum(dim=1).mean()
    cosine = F.cosine_similarity(student["descriptors"].float(), teacher["descriptors"].float(), dim=1, eps=1e-8)
    descriptor = (1.0 - cosine).mean()
    return detector + lambda_loss * descriptor, {"detector": detector, "descriptor": descriptor}


def load_teacher(path: str | Path, device: torch.device | str = "cpu") -> SuperPointNet:
    """Return the network stored at ``path``, refusing a detector-only one (a teacher needs both heads)."""
    model = load_model(path, device=device)
    if model.descriptor_dim == 0:
        raise ValueError(f"the teacher {path} is a detector-only network; distillation needs a detector + descriptor "
                         "checkpoint")
    return model


@functools.lru_cache(maxsize=2)
def _teacher(path: str, version: tuple[int, int, int], device: str
             ) -> Callable[[torch.Tensor], dict[str, torch.Tensor]]:
    """Return the fused fp32 forward of the checkpoint at ``path`` (cached per file version and device)."""
    return inference_model(load_teacher(path, device), "fused")


def teacher_forward(path: str | Path, device: torch.device | str = "cpu"
                    ) -> Callable[[torch.Tensor], dict[str, torch.Tensor]]:
    """Return the teacher's forward pass: (B, 1, H, W) in [0, 1] -> {"logits", "descriptors"} without gradients.

    ``path`` is a SuperPoint checkpoint (the distill config's ``labels_from``). The BN-folded float32 network is built
    once per file version (inode, size, modification time) and device and kept for the life of the process.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"teacher checkpoint {path} not found (the distill stage's labels_from)")
    stat = path.stat()  # a rewritten file (new inode, size or time) is loaded again
    forward = _teacher(str(path.resolve()), (stat.st_ino, stat.st_size, stat.st_mtime_ns), str(torch.device(device)))

    def run(images: torch.Tensor) -> dict[str, torch.Tensor]:
        with torch.no_grad():
            return {k: v.float() for k, v in forward(images).items()}

    return run

