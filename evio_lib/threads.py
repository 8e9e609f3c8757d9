"""CPU threads: how many torch, OpenCV and BLAS may use, set at run time (after NumPy has been imported).

Why it matters here. The MSCKF multiplies small matrices (at most a few hundred rows) hundreds of times per frame.
OpenBLAS starts one thread per core for each of them, and the threads spin while they wait for each other: on the
2-core machine of this project, with one other busy process, the filter of the default ``run`` took several times the
CPU per frame with 2 BLAS threads as with one (measured in ``docs/results/speed.md#the-filter``, "One BLAS thread").

Environment variables such as ``OPENBLAS_NUM_THREADS`` only act if they are set before NumPy is first imported,
which a command or a notebook cannot promise. threadpoolctl (the library scikit-learn and joblib use) changes the
thread count of the BLAS libraries already loaded, at any time:

- :func:`set_threads` limits torch, OpenCV and every loaded BLAS for the rest of the process (``run --threads``,
  each job of ``table``);
- :func:`single_threaded_blas` is a context manager that runs its block with one BLAS thread and restores the
  previous counts (the filter's step uses it, so a notebook or a script gets the fast path without asking). Entering
  and leaving costs microseconds (``docs/results/speed.md#the-filter``).
"""
from __future__ import annotations

import os
import sys
from contextlib import AbstractContextManager
from numbers import Integral
from typing import Any

__all__ = ["THREAD_ENV_NAMES", "set_threads", "single_threaded_blas"]

#: The variables that NumPy's BLAS, OpenMP and MKL read when they are loaded (a child process sees them at its start).
THREAD_ENV_NAMES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_controller: Any = None
_modules_seen = 0  # len(sys.modules) when the controller was made: an import since may have loaded another BLAS


def _blas_controller() -> Any:
    """Return a threadpoolctl controller of the BLAS libraries loaded now.

    Made again only when modules were imported since the last one (making one costs far more than entering a block:
    ``docs/results/speed.md#small-costs-behind-the-codes-choices``): OpenCV or torch may bring their own OpenBLAS.
    NumPy and SciPy's linear algebra (with its own OpenBLAS) are loaded first.
    """
    global _controller, _modules_seen
    if _controller is None or len(sys.modules) != _modules_seen:
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
        _modules_seen = len(sys.modules)
    return _controller


def single_threaded_blas() -> AbstractContextManager:
    """Return a context manager under which every loaded BLAS library uses one thread (counts restored after).

    The thread counts are process-wide: two threads of one process that enter and leave such blocks out of order
    may leave BLAS at one thread.

    >>> import numpy as np
    >>> with single_threaded_blas():
    ...     float((np.eye(3) @ np.ones(3)).sum())
    3.0
    """
    return _blas_controller().limit(limits=1, user_api="blas")


def set_threads(threads: int) -> None:
    """Limit torch, OpenCV and BLAS (loaded now, and through the environment those loaded later) to ``threads``.

    On a small, busy CPU more threads oversubscribe it and run several times slower (module docstring).
    """
    if isinstance(threads, bool) or not isinstance(threads, Integral) or threads < 1:
        raise ValueError(f"threads must be an integer >= 1; got {threads!r}")
    threads = int(threads)
    import cv2
    import torch

    for name in THREAD_ENV_NAMES:
        os.environ[name] = str(threads)
    torch.set_num_threads(threads)
    cv2.setNumThreads(threads)
    _blas_controller().limit(limits=threads, user_api="blas")  # kept: the limiter is not used as a context
