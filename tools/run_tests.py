"""Run every test of evio in one pytest session: unit tests, doctests of evio_lib, and all notebooks under nbval.

Usage:  python tools/run_tests.py [--full] [extra pytest arguments]

The notebooks are jupytext .py files; nbval only collects .ipynb, so they are first converted into build/notebooks/.
Notebooks run in fast mode (EVIO_FAST=1) unless --full is given. Exits with pytest's code, except that "no tests collected"
(pytest's 5) is turned into a failure: a test command that ran nothing must not pass.

The tests run in one worker process per core (pytest-xdist, at most 4; ``-n 0`` among the extra arguments runs them
in this process). ``--dist loadscope`` keeps each test module, and each notebook, in one worker, so the cells of a
notebook run in order in one kernel. Each worker, and each notebook kernel, uses one thread for torch, OpenCV and
BLAS, and the simulator renders frames in the worker itself (EVIO_JOBS=1): two workers with two threads or
processes each would oversubscribe two cores.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from evio_lib import course  # noqa: E402
from evio_lib.sim.jobs import JOBS_ENV  # noqa: E402
from evio_lib.threads import THREAD_ENV_NAMES  # noqa: E402


def main(argv: list[str]) -> int:
    """Convert the notebooks, run pytest over tests/, evio_lib/ doctests and the notebooks; return the exit code."""
    full = "--full" in argv
    extra = [a for a in argv if a != "--full"]
    notebooks = course.build_notebooks()
    env = dict(os.environ)
    env[course.FAST_MODE_ENV] = "0" if full else "1"
    env.setdefault("MPLBACKEND", "Agg")
    for name in (*THREAD_ENV_NAMES, "OPENCV_FOR_THREADS_NUM"):
        env.setdefault(name, "1")  # read by NumPy, torch and OpenCV at import, in every worker and kernel
    env.setdefault(JOBS_ENV, "1")  # the simulator's frame workers: the test workers already use every core
    # the notebook kernels import this working tree, whatever copy of evio_lib pip last installed in editable mode
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH", "")]))
    # one worker per core, at most 4 (as sim.jobs.default_jobs, without its EVIO_JOBS)
    workers = ["--numprocesses", str(min(os.cpu_count() or 1, 4)), "--dist", "loadscope"]
    command = [sys.executable, "-m", "pytest", "tests", "evio_lib", "--doctest-modules",
               *[str(p.relative_to(ROOT)) for p in notebooks], "--nbval-lax", "-p", "no:cacheprovider", *workers,
               *extra]
    print(f"notebooks: {len(notebooks)} ({'full' if full else 'fast'} mode)\n$ {' '.join(command)}", flush=True)
    code = subprocess.call(command, cwd=ROOT, env=env)
    if code == 5:
        print("pytest collected no tests: failing, because a test run that runs nothing proves nothing", file=sys.stderr)
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
