"""Write the shipped reconstructor checkpoint from the runs that made it (the optimiser state and RNG left out).

Usage:
    python tools/ship_reconstructor.py --stage RUN1/best.pt "COMMAND 1" [--stage RUN2/best.pt "COMMAND 2" ...] \\
        --out evio_lib/weights/reconstruction_firenet.pt

The last stage's weights are shipped; every stage's command, config, training-set manifest and validation history
(each entry labelled with its stage, steps counted on from the stage before) are kept, so ``checkpoint["stages"]``
says how to make the weights again.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stage", nargs=2, action="append", required=True, metavar=("CHECKPOINT", "COMMAND"))
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    history, stages, offset, last = [], [], 0, None
    for number, (path, command) in enumerate(args.stage, start=1):
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
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
    tmp = args.out.with_suffix(".tmp")
    torch.save(shipped, tmp)
    os.replace(tmp, args.out)
    print(f"wrote {args.out}: {len(stages)} stages, {offset} steps, validation SSIM {shipped['best_val_ssim']:.3f}")


if __name__ == "__main__":
    main()
