"""The filter and the pipeline stay readable: no function or method in ``evio_lib/pipeline`` or ``evio_lib/msckf``
is longer than 120 lines (a longer one is split into named steps, as ``run_pipeline`` and ``Msckf`` were)."""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "evio_lib"
MAX_LINES = 120


@pytest.mark.parametrize("folder", ["pipeline", "msckf"])
def test_no_function_is_longer_than_120_lines(folder):
    long = []
    for path in sorted((PACKAGE / folder).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_LINES:
                    long.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {node.name} ({length} lines)")
    assert not long, "split into named steps: " + "; ".join(long)
