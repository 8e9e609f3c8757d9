"""Write the shipped reconstructor checkpoint from the runs that made it (the optimiser state and RNG left out).

Usage:
    python tools/ship_reconstructor.py --stage RUN1/best.pt "COMMAND 1" [--stage RUN2/best.pt "COMMAND 2" ...] \\
        --out evio_lib/weights/reconstruction_firenet.pt
    python tools/ship_reconstructor.py --base evio_lib/weights/reconstruction_firenet.pt \\
        --stage RUN3/best.pt "COMMAND 3" --out evio_lib/weights/reconstruction_firenet.pt   # one stage more
    python tools/ship_reconstructor.py --int8-ranges evio_lib/weights/reconstruction_firenet.pt   # only add those

The last stage's weights are shipped; every stage's command, config, training-set manifest and validation history
(each entry labelled with its stage, steps counted on from the stage before) are kept, so ``checkpoint["stages"]``
says how to make the weights again. A FireNet's int8 calibration (``int8_ranges``, the ranges of
``evio_lib.events.reconstruction.quantized.stored_ranges``, tied to the weights by their SHA-1) is stored too, so
that ``precision="int8"`` loads without calibrating; ``--int8-ranges FILE`` adds it to a shipped file in place.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stage", nargs=2, action="append", metavar=("CHECKPOINT", "COMMAND"))
    parser.add_argument("--out", type=Path)
    parser.add_argument("--base", type=Path, metavar="SHIPPED",
                        help="a shipped checkpoint whose stages come first (the new stages fine-tune its weights)")
    parser.add_argument("--int8-ranges", type=Path, metavar="FILE", help="only add the int8 calibration to FILE")
    args = parser.parse_args()
    if args.int8_ranges is not None:
        shipped = torch.load(args.int8_ranges, map_location="cpu", weights_only=True)
        _add_int8_ranges(shipped)
        _save(shipped, args.int8_ranges)
        print(f"added int8_ranges to {args.int8_ranges}")
        return
    if not args.stage or args.out is None:
        parser.error("--stage and --out are needed (or --int8-ranges FILE)")
    history, stages, offset, last, network = [], [], 0, None, None
    if args.base is not None:
        base = torch.load(args.base, map_location="cpu", weights_only=True)
        if "stages" not in base:
            parser.error(f"--base {args.base} holds no stages: not a file written by this tool")
        history, stages, offset = list(base["history"]), list(base["stages"]), int(base["step"])
        network = (base["architecture"], base["num_bins"], dict(base.get("network_options") or {}))
    for number, (path, command) in enumerate(args.stage, start=len(stages) + 1):
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        if network is not None and (ckpt["architecture"], ckpt["num_bins"],
                                    dict(ckpt.get("network_options") or {})) != network:
            parser.error(f"{path} holds another network than --base {args.base} ({network[0]}, {network[1]} bins, "
                         f"options {network[2]})")
        for entry in ckpt["history"]:
            history.append({**entry, "step": entry["step"] + offset, "stage": number})
        manifest = ckpt.get("training_set_manifest")
        beside = Path(path).parent / "training_set.json"     # runs made before checkpoints recorded it
        if manifest is None and beside.is_file():
            manifest = json.loads(beside.read_text())
        stages.append({"command": command, "config": ckpt["config"], "steps": ckpt["step"],
                       "training_set_manifest": manifest})
        offset += ckpt["step"]
        last = ckpt
    shipped = {key: last[key] for key in ("format", "config", "architecture", "network_options", "num_bins",
                                          "state_dict", "best_val_ssim")}
    shipped["training_set_manifest"] = stages[-1]["training_set_manifest"]
    shipped.update(step=offset, history=history, stages=stages, command=stages[-1]["command"])
    _add_int8_ranges(shipped)
    _save(shipped, args.out)
    metric = (last["config"] or {}).get("select_by", "ssim")
    print(f"wrote {args.out}: {len(stages)} stages, {offset} steps, best validation {metric} "
          f"{shipped['best_val_ssim']:.3f}")


def _add_int8_ranges(shipped: dict) -> None:
    """Store a FireNet's int8 calibration in the checkpoint (other architectures have no int8 path)."""
    if shipped["architecture"] != "firenet":
        return
    from evio_lib.events.reconstruction.nets import build_network
    from evio_lib.events.reconstruction.quantized import stored_ranges

    net = build_network("firenet", shipped["num_bins"], **dict(shipped.get("network_options") or {}))
    net.load_state_dict(shipped["state_dict"])
    shipped["int8_ranges"] = stored_ranges(net.eval())


def _save(checkpoint: dict, path: Path) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(checkpoint, tmp)
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
