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


class NotebookFailed(RuntimeError):
    """A cell of a lesson failed: the notebook's name, the cell, why, and where the partially executed notebook is.

    ``str()`` is the one line the course command prints after ``error:``, e.g. ``notebook 14_evio_pipeline, cell 41:
    AssertionError (line 28: assert contrast > 2); the partial notebook is at build/notebooks/14_evio_pipeline.ipynb``.

    Attributes:
        notebook: the notebook's name without suffix (``14_evio_pipeline``).
        cell: the failing cell's number as the notebook shows it beside the cell (``[41]``: code cells counted from 1
            in a fresh kernel); None when the failure came after the last cell.
        message: the exception's type and first line, and the line of the cell that raised it where known.
        path: the written notebook, holding the outputs of every cell up to the failing one.
    """

    def __init__(self, notebook: str, cell: int | None, message: str, path: Path):
        self.notebook, self.cell, self.message, self.path = notebook, cell, message, Path(path)
        super().__init__(str(self))

    def __str__(self) -> str:
        where = f"cell {self.cell}" if self.cell is not None else "after its last cell"
        return f"notebook {self.notebook}, {where}: {self.message}; the partial notebook is at {_shown(self.path)}"


def execute_notebook(path: Path, timeout_s: int = 1800, fast: bool | None = None) -> Path:
    """Execute one ``.ipynb`` in place (outputs stored in the file); stop at the first failing cell.

    Args:
        path: the notebook.
        timeout_s: limit per cell, seconds.
        fast: run the kernel in fast mode (True), full mode (False) or as :data:`FAST_MODE_ENV` says (None).

    Raises:
        NotebookFailed: a cell raised an exception, ran past ``timeout_s`` or lost its kernel. The notebook is written
            anyway, with the outputs of the cells run so far and the failing cell's error, for the student to open.
    """
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellControlSignal, DeadKernelError

    notebook = nbformat.read(path, as_version=4)
    started: list[int] = []  # index of each cell as its execution starts: the last one is the failing one

    def on_cell_start(cell: object, cell_index: int) -> None:
        started.append(cell_index)

    async def on_cell_error(cell: object, cell_index: int, execute_reply: object) -> None:
        # the notebook stops at this cell: stop the joblib workers as after the last one, before the kernel shuts down
        try:
            await client.async_wait_for_reply(client.kc.execute(_STOP_WORKERS, store_history=False))
        except Exception:  # noqa: BLE001 -- a clean-up that fails must not hide the lesson's own error
            pass

    # The kernel app's own log (not the cells' output or warnings) only says, once per notebook, that a local kernel
    # talks over TCP without encryption; keep it quiet so the course's output shows what the lessons print.
    client = NotebookClient(notebook, timeout=timeout_s, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}},
                            extra_arguments=["--IPKernelApp.log_level=ERROR"], on_cell_start=on_cell_start,
                            on_cell_error=on_cell_error)
    notebook.cells.append(nbformat.v4.new_code_cell(_STOP_WORKERS))  # executed last, never stored
    failure: BaseException | None = None
    try:
        client.execute(env=kernel_environment(fast))
    except (CellControlSignal, DeadKernelError) as error:  # a cell's exception, a cell's timeout, a dead kernel
        failure = error
    finally:
        notebook.cells.pop()
    nbformat.write(notebook, path)
    if failure is not None:
        index = started[-1] if started else None
        cell = notebook.cells[index] if index is not None and index < len(notebook.cells) else None
        raise NotebookFailed(path.stem, _cell_number(notebook.cells, index) if cell is not None else None,
                             _failure_message(failure, cell, timeout_s), path) from failure
    return path


def _shown(path: Path) -> str:
    """The path relative to the working folder where it lies below it (``build/notebooks/x.ipynb``), else as given."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _cell_number(cells: list, index: int) -> int:
    """The number shown beside a code cell, ``[K]``: its execution count, else its rank among the code cells."""
    count = cells[index].get("execution_count")
    return int(count) if count else sum(c.cell_type == "code" for c in cells[:index + 1])


_ANSI = re.compile(r"\x1b\[[0-9;]*m")
#: The cell's own frame in an IPython traceback: "Cell In[3], line 2" (IPython >= 8.6) or "<cell line: 2>" (8.0-8.5)
_CELL_FRAME = re.compile(r"Cell In\s*\[\d*\], line (\d+)|<cell line: (\d+)>")


def _failure_message(error: BaseException, cell, timeout_s: int) -> str:
    """One line saying why a cell failed: ``Type: first line of the message (line L: the cell's line that raised)``."""
    from nbclient.exceptions import CellExecutionError, CellTimeoutError

    if isinstance(error, CellTimeoutError):
        return f"still running after {timeout_s} s, the limit per cell"
    if not isinstance(error, CellExecutionError):
        return f"the kernel stopped ({_first_line(str(error)) or type(error).__name__})"
    evalue = _first_line(error.evalue)
    text = f"{error.ename}: {evalue}" if evalue else error.ename
    frame = _CELL_FRAME.search(_ANSI.sub("", error.traceback))
    if frame and cell is not None:
        number = int(frame.group(1) or frame.group(2))
        code = " ".join(_statement_at(cell.source, number).split())
        if code:
            text += f" (line {number}: {code if len(code) <= 160 else code[:157] + '...'})"
    return text


def _statement_at(source: str, number: int) -> str:
    """The source of the innermost simple statement on line ``number`` of ``source`` (all its lines: an assert split
    over three lines is shown whole); the line alone for a compound statement's header or a cell Python cannot parse
    (an IPython magic)."""
    import ast

    lines = source.splitlines()
    if not 1 <= number <= len(lines):
        return ""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return lines[number - 1]
    around = [node for node in ast.walk(tree) if isinstance(node, ast.stmt)
              and node.lineno <= number <= (node.end_lineno or node.lineno)]
    if not around:
        return lines[number - 1]
    node = min(around, key=lambda n: ((n.end_lineno or n.lineno) - n.lineno, hasattr(n, "body")))  # the innermost
    if hasattr(node, "body"):  # if / for / with / def ...: its header line, not its whole body
        return lines[number - 1]
    return ast.get_source_segment(source, node) or lines[number - 1]


def _first_line(text: str) -> str:
    """The first non-blank line of ``text``, with `` ...`` where more lines follow."""
    lines = [line.strip() for line in str(text).splitlines() if line.strip()]
    return "" if not lines else lines[0] + (" ..." if len(lines) > 1 else "")


#: Run after a notebook's last cell: stop joblib's idle worker processes (``run_pipelines``, ``run_table``, the
#: simulator's frame workers) before the kernel shuts down. Otherwise the kernel's shutdown interrupts them and each
#: prints a KeyboardInterrupt traceback into the course's output. Reads loky's executor without creating one.
_STOP_WORKERS = """import sys as _sys
_pool = getattr(_sys.modules.get("joblib.externals.loky.reusable_executor"), "_executor", None)
if _pool is not None:
    _pool.shutdown(wait=True)"""
