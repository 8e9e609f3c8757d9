"""The course's notebooks: find the jupytext sources, build ``.ipynb`` files from them, and execute them.

The notebooks live in ``notebooks/NN_name.py`` as jupytext percent-format text; ``.ipynb`` files are build output written to
``build/notebooks/``. The environment variable :data:`FAST_MODE_ENV` (``EVIO_FAST=1``) switches every notebook to tiny data
for CI; unset, a notebook runs the full lesson.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

FAST_MODE_ENV = "EVIO_FAST"
PROJECT_ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = PROJECT_ROOT / "notebooks"
BUILD_DIR = PROJECT_ROOT / "build" / "notebooks"
_NOTEBOOK_NAME = re.compile(r"^\d{2}_[a-z0-9_]+\.py$")


def fast_mode() -> bool:
    """Return True when the course runs in its fast CI mode (``EVIO_FAST=1``)."""
    return os.environ.get(FAST_MODE_ENV, "0") == "1"


def notebook_sources(notebook_dir: Path = NOTEBOOK_DIR) -> list[Path]:
    """Return the numbered jupytext notebook sources (``NN_name.py``) in course order."""
    if not notebook_dir.is_dir():
        raise FileNotFoundError(f"notebook folder not found: {notebook_dir} (expected the repository's notebooks/ folder)")
    return sorted(p for p in notebook_dir.iterdir() if _NOTEBOOK_NAME.match(p.name))


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


def execute_notebook(path: Path, timeout_s: int = 1800) -> Path:
    """Execute one ``.ipynb`` in place (outputs stored in the file); raise on the first failing cell."""
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.read(path, as_version=4)
    # the kernel imports this working tree's evio_lib, whatever copy pip last installed in editable mode
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PROJECT_ROOT), os.environ.get("PYTHONPATH", "")]))
    client = NotebookClient(notebook, timeout=timeout_s, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    nbformat.write(notebook, path)
    return path
