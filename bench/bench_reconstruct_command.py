"""Print how long ``python -m evio_lib reconstruct`` takes on a 4 s, 21 M-event ECD folder (target: under 60 s).

Usage:  python bench/bench_reconstruct_command.py [--repeats 420] [--precisions auto float32] [--threads 2]

The folder is made in a temporary directory from the real ECD ``slider_depth`` slice (``../shared/data/real/``,
50 000 events of 0.17 s): the slice repeated ``--repeats`` times back to back, then squeezed in time so that the
whole lasts 4 s (420 repeats: 21 M events, about 5 M events per second, a fast scene for a DAVIS240C), written as
``events.txt`` (``t x y p``, p in {0, 1}, about 0.5 GB) beside the slice's ``calib.txt``. Then, for each precision,
``reconstruct FOLDER --out OUT --precision P`` runs in a child process (FireNet, the default windows of 0.35 H W
events), and the script prints its frames, wall time and CPU time (user + system of the child). Reading the text
file is part of the time, as it is for a user. Nothing is kept: the folder is deleted at the end.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from evio_lib.events.reconstruct import PRECISIONS

ROOT = Path(__file__).resolve().parents[1]
SLIDER = ROOT.parent / "shared" / "data" / "real" / "ecd_slider_depth_slice"


def write_ecd_events(path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, p01: np.ndarray) -> None:
    """Write ``t x y p`` lines (t with 9 decimals, below 10 s; x, y right-aligned in 3 columns) without a Python
    loop: every line has the same width, so the text is one (N, width) byte array filled column by column."""
    if t.size and not (0 <= t.min() and t.max() < 10):
        raise ValueError("write_ecd_events writes times in [0, 10) s")
    ns = np.round(t * 1e9).astype(np.int64)
    line = np.full((t.size, 22), ord(" "), np.uint8)    # "S.NNNNNNNNN XXX YYY P\n": 22 bytes
    line[:, 0] = ord("0") + ns // 1_000_000_000
    line[:, 1] = ord(".")
    for k in range(9):                                      # nine decimals, the last first
        line[:, 10 - k] = ord("0") + (ns // 10 ** k) % 10
    for start, values in ((12, x.astype(np.int64)), (16, y.astype(np.int64))):
        for k, power in enumerate((100, 10, 1)):
            digit = (values // power) % 10
            shown = (values >= power) | (power == 1)        # no leading zeros: spaces instead
            line[:, start + k] = np.where(shown, ord("0") + digit, ord(" "))
    line[:, 20] = ord("0") + p01
    line[:, 21] = ord("\n")
    line.tofile(path)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=420, help="copies of the 50 000-event slice (default 420)")
    parser.add_argument("--precisions", nargs="+", default=["auto", "float32"], choices=PRECISIONS)
    parser.add_argument("--threads", type=int, default=2, help="torch threads of the child (default 2)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1; got {args.repeats}")
    if not (SLIDER / "slider_seg.txt").is_file():
        print(f"error: the real slider slice is not at {SLIDER} (see ../shared/data/real/README.md)", file=sys.stderr)
        return 2
    from evio_lib.io.ecd import read_ecd_events

    slice_ = read_ecd_events(SLIDER / "slider_seg.txt", sensor_size=(240, 180))
    t0, span = float(slice_["t"][0]), float(slice_["t"][-1] - slice_["t"][0]) + 1e-4
    reps = args.repeats
    t = ((slice_["t"] - t0)[None, :] + span * np.arange(reps)[:, None]).reshape(-1) * (4.0 / (span * reps))
    x, y = np.tile(slice_["x"], reps), np.tile(slice_["y"], reps)
    p01 = np.tile((slice_["p"] > 0).astype(np.int64), reps)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / f"slider_x{reps}"
        folder.mkdir()
        start = time.perf_counter()
        write_ecd_events(folder / "events.txt", t, x, y, p01)
        (folder / "calib.txt").write_text((SLIDER / "calib.txt").read_text())
        size_gb = (folder / "events.txt").stat().st_size / 1e9
        print(f"{t.size / 1e6:.1f} M events over {t[-1]:.2f} s ({size_gb:.2f} GB of text) written in "
              f"{time.perf_counter() - start:.1f} s")
        env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
        for precision in args.precisions:
            out = Path(tmp) / f"frames_{precision}"
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "evio_lib", "reconstruct", str(folder), "--out", str(out),
                                   "--precision", precision], env=env, capture_output=True, text=True)
            wall = time.perf_counter() - start
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if done.returncode != 0:
                print(f"error: reconstruct --precision {precision} failed: {done.stderr.strip()[-500:]}",
                      file=sys.stderr)
                return 1
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            print(f"--precision {precision:8s} {wall:6.1f} s wall, {cpu:6.1f} s CPU ({args.threads} threads): "
                  f"{done.stdout.strip().splitlines()[-1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
