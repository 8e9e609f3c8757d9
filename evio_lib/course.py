"""The course's notebooks: find the jupytext sources, build ``.ipynb`` files from them, and execute them.

The notebooks live in ``notebooks/NN_name.py`` as jupytext percent-format text; ``.ipynb`` files are build output written to
``build/notebooks/``. The environment variable :data:`FAST_MODE_ENV` (``EVIO_FAST=1``) switches every notebook to tiny data
for CI; unset (or ``0``), a notebook runs the full lesson. ``python -m evio_lib course --fast`` sets it for the kernels.
"""
from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path

FAST_MODE_ENV = "EVIO_FAST"
PROJECT_ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = PROJECT_ROOT / "notebooks"
BUILD_DIR = PROJECT_ROOT / "build" / "notebooks"
_NOTEBOOK_NAME = re.compile(r"^\d{2}_[a-z0-9_]+\.py$")


def fast_mode(environ: Mapping[str, str] | None = None) -> bool:
    """Return True when the course runs in its fast CI mode (``EVIO_FAST=1``).

    Args:
        environ: the environment to read (default ``os.environ``).

    Raises:
        ValueError: EVIO_FAST holds anything but ``1``, ``0`` or nothing (the notebooks test ``== "1"``, so
            ``EVIO_FAST=true`` would silently run the full lessons).

    >>> fast_mode({"EVIO_FAST": "1"}), fast_mode({"EVIO_FAST": "0"}), fast_mode({})
    (True, False, False)
    """
    value = (os.environ if environ is None else environ).get(FAST_MODE_ENV, "").strip()
    if value not in ("", "0", "1"):
        raise ValueError(f"{FAST_MODE_ENV} must be 1 (fast mode) or 0 (full lessons); got {value!r}")
    return value == "1"


def notebook_sources(notebook_dir: Path = NOTEBOOK_DIR) -> list[Path]:
    """Return the numbered jupytext notebook sources (``NN_name.py``) in course order."""
    if not notebook_dir.is_dir():
        raise FileNotFoundError(f"notebook folder not found: {notebook_dir} (expected the repository's notebooks/ folder)")
    return sorted(p for p in notebook_dir.iterdir() if _NOTEBOOK_NAME.match(p.name) and p.is_file())


def build_notebooks(sources: list[Path] | None = None, out_dir: Path = BUILD_DIR) -> list[Path]:
    """Convert jupytext ``.py`` sources to ``.ipynb`` files in ``out_dir``; return the written paths."""
    import jupytext  # imported here: only the course and test runner need it

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for source in sources if sources is not None else notebook_sources():
        notebook = jupytext.read(source)
        target = out_dir / (source.stem + ".ipynb")
        jupytext.write(notebook, target)
        written.append(target)
    return written


def kernel_environment(fast: bool | None = None, environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """Return the environment of a notebook kernel: ``environ`` with this working tree first on PYTHONPATH.

    Args:
        fast: True / False set :data:`FAST_MODE_ENV` to 1 / 0; None keeps what ``environ`` says.
        environ: the base environment (default ``os.environ``; never modified).
    """
    env = dict(os.environ if environ is None else environ)
    # the kernel imports this working tree's evio_lib, whatever copy pip last installed in editable mode
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PROJECT_ROOT), env.get("PYTHONPATH", "")]))
    if fast is not None:
        env[FAST_MODE_ENV] = "1" if fast else "0"
    return env


def execute_notebook(path: Path, timeout_s: int = 1800, fast: bool | None = None) -> Path:
    """Execute one ``.ipynb`` in place (outputs stored in the file); raise on the first failing cell.

    Args:
        path: the notebook.
        timeout_s: limit per cell, seconds.
        fast: run the kernel in fast mode (True), full mode (False) or as :data:`FAST_MODE_ENV` says (None).
    """
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.read(path, as_version=4)
    # The kernel app's own log (not the cells' output or warnings) only says, once per notebook, that a local kernel
    # talks over TCP without encryption; keep it quiet so the course's output shows what the lessons print.
    client = NotebookClient(notebook, timeout=timeout_s, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}},
                            extra_arguments=["--IPKernelApp.log_level=ERROR"])
    notebook.cells.append(nbformat.v4.new_code_cell(_STOP_WORKERS))  # executed last, never stored
    try:
        client.execute(env=kernel_environment(fast))
    finally:
        notebook.cells.pop()
    nbformat.write(notebook, path)
    return path


#: Run after a notebook's last cell: stop joblib's idle worker processes (``run_pipelines``, ``run_table``, the
#: simulator's frame workers) before the kernel shuts down. Otherwise the kernel's shutdown interrupts them and each
#: prints a KeyboardInterrupt traceback into the course's output. Reads loky's executor without creating one.
_STOP_WORKERS = """import sys as _sys
_pool = getattr(_sys.modules.get("joblib.externals.loky.reusable_executor"), "_executor", None)
if _pool is not None:
    _pool.shutdown(wait=True)"""
