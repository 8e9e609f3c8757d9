"""Choose between a Numba-compiled kernel and its NumPy reference, by an environment variable.

The simulator's renderer (:func:`evio_lib.sim.scene.renderer_backend`), the motion-compensated event frames
(:func:`evio_lib.events.motion_compensation.mc_backend`) and the voxel grid's normalisation
(:func:`evio_lib.events.representations.voxel_backend`) each have compiled kernels that give the NumPy path's
numbers faster. All choose the same way: ``<ENV>`` = ``numba`` | ``numpy`` | ``auto`` (default: the kernels when
their module loads, else NumPy with one warning saying why; ``numba`` where they cannot load is an error).
"""
from __future__ import annotations

import importlib
import os
import warnings

__all__ = ["compiled_backend"]


def compiled_backend(env: str, module: str, memo: list[str], fallback_note: str) -> str:
    """Return ``"numba"`` or ``"numpy"`` for the kernels of ``module``, as the variable ``env`` asks.

    Args:
        env: the environment variable's name, e.g. ``EVIO_RENDERER``.
        module: the kernels' module, imported once to see whether they load (Numba compiles them lazily).
        memo: the caller's module-level list: empty until the first call, then ``[""]`` when the kernels load, else
            ``[why not]``, so the import is tried and the warning given once per process.
        fallback_note: what the NumPy path means for the user, for the warning (e.g. "rendering with NumPy (about
            2x slower, same images)").
    """
    choice = os.environ.get(env, "auto").strip().lower() or "auto"
    if choice not in ("auto", "numba", "numpy"):
        raise ValueError(f"{env} must be one of auto, numba, numpy; got {choice!r}")
    if choice == "numpy":
        return "numpy"
    if not memo:
        try:
            importlib.import_module(module)  # fails here without numba or a cache folder for the machine code
        except ImportError as error:
            memo.append(f"the numba package does not import ({error}); pip install numba")
        except Exception as error:  # e.g. RuntimeError: cannot cache function ...: no locator available
            memo.append(f"Numba cannot load the kernels ({type(error).__name__}: {error}); set NUMBA_CACHE_DIR to a "
                        f"writable folder")
        else:
            memo.append("")
        if memo[0] and choice == "auto":
            warnings.warn(f"{fallback_note}: {memo[0]}; {env}=numpy silences this", RuntimeWarning, stacklevel=3)
    if memo[0]:
        if choice == "numba":
            raise ValueError(f"{env}=numba cannot be used here: {memo[0]}; or set {env}=numpy")
        return "numpy"
    return "numba"
