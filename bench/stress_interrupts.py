"""Interrupt ``python -m evio_lib run --out`` at random moments and check each ending.

Usage:  python bench/stress_interrupts.py [--tries 100] [--signal INT|TERM] [--seed 0] [-- RUN ARGUMENTS]

The run (default: ``boxes_like --duration 2 --frames aps``, its simulation cached by a first, uninterrupted run) is
timed once; each try then sends the signal at a moment drawn uniformly over that time (half the tries over its last
third, where the output folder and its figures are written). A try passes when the process ends with 130 (SIGINT)
or 143 (SIGTERM) and the one line ``error: interrupted`` / ``error: terminated`` on stderr, or with 0 when it
finished first (or killed by the signal itself when it arrives during the interpreter's shutdown, after the output is
complete: Python restores the default handler there), and leaves either no output folder or a complete one (metrics.json and summary.txt), never a
temporary folder. Prints one line per failing try and the counts.
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _run(args: list[str], cwd: Path, after: float | None, signum: int) -> tuple[int, str, float]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    start = time.perf_counter()
    # SIGINT as at a terminal: a script started in the background (`cmd &` in a non-interactive shell) inherits
    # SIGINT ignored, and Python then installs no KeyboardInterrupt handler, so every try would "finish first"
    process = subprocess.Popen([sys.executable, "-m", "evio_lib", "run", *args, "--out", "out", "--quiet"],
                               cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    if after is not None:
        try:
            process.wait(timeout=after)
        except subprocess.TimeoutExpired:
            process.send_signal(signum)
    _, err = process.communicate(timeout=600)
    return process.returncode, err, time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=100)
    parser.add_argument("--signal", choices=["INT", "TERM"], default="INT")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("run_args", nargs="*", default=["boxes_like", "--duration", "2", "--frames", "aps"])
    args = parser.parse_args()
    signum = signal.SIGINT if args.signal == "INT" else signal.SIGTERM
    expected_code, expected_line = (130, "error: interrupted") if args.signal == "INT" else (143, "error: terminated")
    rng = np.random.default_rng(args.seed)
    work = Path(tempfile.mkdtemp(prefix="evio_interrupts_"))
    try:
        code, err, full = _run(args.run_args, work, None, signum)
        if code != 0:
            print(f"error: the uninterrupted run failed ({code}): {err.strip().splitlines()[-1:]}", file=sys.stderr)
            return 2
        print(f"uninterrupted run: {full:.1f} s; {args.tries} tries with SIG{args.signal}")
        counts = {"interrupted": 0, "finished first": 0, "failed": 0}
        for k in range(args.tries):
            shutil.rmtree(work / "out", ignore_errors=True)
            after = full * (rng.uniform(2 / 3, 1.0) if k % 2 else rng.uniform(0.05, 1.0))
            code, err, _ = _run(args.run_args, work, after, signum)
            lines = err.strip().splitlines()
            left = sorted(p.name for p in work.iterdir())
            complete = (work / "out" / "metrics.json").is_file() and (work / "out" / "summary.txt").is_file()
            if code == expected_code and lines == [expected_line] and left == []:
                counts["interrupted"] += 1
            elif code in (0, -signum) and left == ["out"] and complete:   # -signum: it came during the shutdown
                counts["finished first"] += 1
            else:
                counts["failed"] += 1
                print(f"try {k} (signal after {after:.2f} s): exit {code}, left {left}, stderr {lines[-3:]}")
        print(", ".join(f"{v} {k}" for k, v in counts.items()))
        if counts["interrupted"] == 0 and args.tries >= 10:
            print("error: no try was interrupted: the signal did not reach the runs", file=sys.stderr)
            return 1
        return 1 if counts["failed"] else 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
