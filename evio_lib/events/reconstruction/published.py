"""Published reconstructor weights in the project's FireNet: the layout of FireNet / FireNet+ checkpoints.

The published FireNet (Scheerlinck et al., WACV 2020) and FireNet+ (Stoffregen et al., ECCV 2020), as distributed by
their authors' code (``event_cnn_minimal``) and by the EVREAL benchmark, are the network of
:class:`~evio_lib.events.reconstruction.nets.FireNet` with other names and one difference at the end:

| published key | here |
|---|---|
| ``head.conv2d`` | ``head`` |
| ``G{k}.update_gate``, ``G{k}.reset_gate`` (separate convolutions over [x, h]) | ``gru{k}.gates`` (both, z first) |
| ``G{k}.out_gate`` | ``gru{k}.candidate`` |
| ``R{k}.conv1``, ``R{k}.conv2`` | ``res{k}.conv1``, ``res{k}.conv2`` |
| ``pred.conv2d`` | ``pred`` |

The published ConvGRU computes z = sigmoid(W_u [x, h]), r = sigmoid(W_r [x, h]), h~ = tanh(W_o [x, r h]),
h' = (1 - z) h + z h~, the equations of :class:`~evio_lib.events.reconstruction.nets.ConvGRUCell`, so stacking
W_u over W_r gives the same gate values. Its last layer is a plain 1 x 1 convolution (no sigmoid): the network is built
with ``output="clamp"`` (the image clipped to [0, 1]). The voxel grid is E2VID's (5 bins, normalised over its non-zero
cells), which :func:`evio_lib.events.representations.voxel_grid` computes.

A file is read with ``torch.load(weights_only=True)``: plain tensors and containers only, no code runs. A checkpoint
whose extra entries are Python objects (``event_cnn_minimal`` pickles its ``config`` object) is refused by torch's
loader; load it once in the code that wrote it and save ``checkpoint["state_dict"]`` alone. E2VID's recurrent UNet
(``unetrecurrent.*`` keys, BatchNorm and transposed-convolution decoders) is recognised and refused in one line: the
project's E2VID-style network is not the same layout.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["PUBLISHED_FIRENET_KEYS", "is_published_layout", "published_firenet_checkpoint"]

_PREFIXES = ("module.", "model.", "net.")
#: the keys of a published FireNet state dict (each with ``.weight`` and ``.bias``)
PUBLISHED_FIRENET_KEYS = ("head.conv2d", "G1.reset_gate", "G1.update_gate", "G1.out_gate", "R1.conv1", "R1.conv2",
                          "G2.reset_gate", "G2.update_gate", "G2.out_gate", "R2.conv1", "R2.conv2", "pred.conv2d")


def _state_dict_of(raw: dict) -> dict | None:
    """Return the tensors of a published checkpoint (the dict itself or its ``state_dict`` / ``model`` entry), with a
    common ``module.`` / ``model.`` prefix removed; None when nothing looks like a state dict."""
    import torch

    for candidate in (raw.get("state_dict"), raw.get("model"), raw):
        if isinstance(candidate, dict) and candidate and all(isinstance(v, torch.Tensor) for v in candidate.values()):
            state = dict(candidate)
            for prefix in _PREFIXES:
                if all(k.startswith(prefix) for k in state):
                    state = {k[len(prefix):]: v for k, v in state.items()}
            return state
    return None


def is_published_layout(raw: dict) -> str | None:
    """Return ``"firenet"`` or ``"e2vid"`` when ``raw`` (a loaded checkpoint) holds published weights of that network,
    else None."""
    if not isinstance(raw, dict) or "format" in raw:
        return None
    state = _state_dict_of(raw)
    if state is None:
        return None
    if any(k.startswith("unetrecurrent.") or k.startswith("unet.") for k in state):
        return "e2vid"
    if all(f"{key}.weight" in state for key in PUBLISHED_FIRENET_KEYS):
        return "firenet"
    return None


def published_firenet_checkpoint(raw: dict, path: str | Path) -> dict:
    """Return a checkpoint dict of the project's form (architecture, num_bins, network_options, state_dict) holding
    the published FireNet weights in ``raw``.

    Raises CheckpointError (one line, naming ``path``) for E2VID's layout, a tensor of an unexpected shape, a bias
    missing, or anything that is not the published FireNet.
    """
    import torch

    from evio_lib.io.checkpoint import CheckpointError

    kind = is_published_layout(raw)
    if kind == "e2vid":
        raise CheckpointError(f"{path}: holds published E2VID weights (unetrecurrent.* keys), whose recurrent UNet "
                              f"(BatchNorm, transposed-convolution decoders) is not the project's E2VID-style network; "
                              f"published FireNet / FireNet+ weights and reconstruct-train checkpoints load")
    if kind != "firenet":
        raise CheckpointError(f"{path}: not a published FireNet state dict (expected the keys "
                              f"{', '.join(k + '.weight' for k in PUBLISHED_FIRENET_KEYS[:3])}, ...)")
    state = _state_dict_of(raw)
    missing = [f"{key}.{part}" for key in PUBLISHED_FIRENET_KEYS for part in ("weight", "bias")
               if f"{key}.{part}" not in state]
    if missing:
        raise CheckpointError(f"{path}: a published FireNet state dict without {', '.join(missing[:4])} (the project's "
                              f"FireNet has a bias in every convolution)")
    head = state["head.conv2d.weight"]
    if head.ndim != 4 or head.shape[2:] != (3, 3):
        raise CheckpointError(f"{path}: head.conv2d.weight has shape {tuple(head.shape)}; expected (channels, bins, "
                              f"3, 3)")
    channels, num_bins = int(head.shape[0]), int(head.shape[1])

    def pair(name: str) -> tuple:
        return state[f"{name}.weight"].float(), state[f"{name}.bias"].float()

    converted = {}
    converted["head.weight"], converted["head.bias"] = pair("head.conv2d")
    for k in (1, 2):
        (wu, bu), (wr, br) = pair(f"G{k}.update_gate"), pair(f"G{k}.reset_gate")
        converted[f"gru{k}.gates.weight"] = torch.cat([wu, wr])            # z first, then r: ConvGRUCell's chunk order
        converted[f"gru{k}.gates.bias"] = torch.cat([bu, br])
        converted[f"gru{k}.candidate.weight"], converted[f"gru{k}.candidate.bias"] = pair(f"G{k}.out_gate")
        for conv in ("conv1", "conv2"):
            converted[f"res{k}.{conv}.weight"], converted[f"res{k}.{conv}.bias"] = pair(f"R{k}.{conv}")
    converted["pred.weight"], converted["pred.bias"] = pair("pred.conv2d")
    return {"architecture": "firenet", "num_bins": num_bins,
            "network_options": {"channels": channels, "output": "clamp"}, "state_dict": converted,
            "published": True}
