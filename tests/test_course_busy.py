"""A lesson passes on a busy machine: no assert of a notebook or a solution compares wall-clock (or CPU) times, and a
lesson that prints its timings runs beside processes that keep every core busy.

A timing is printed, never asserted: another job on a student's laptop slows one run more than the other, so a ratio
of two times can come out either way. A lesson that needs to guard a claim asserts a count (frames, events, features)
or another quantity that the machine's load cannot change.
"""
from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from evio_lib import course

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```python([^\n]*)\n(.*?)^```\s*$", re.S | re.M)  # as tests/test_solutions.py reads the blocks
#: Text that marks a timing: the clocks, the pipeline's ``timings`` and real-time factor, frame rates of a run, the
#: features lesson's speed helper.
TIMING = re.compile(r"perf_counter|process_time|\btime\.time\(|monotonic\(|\btimings\b|realtime|real_time|\bfps\b|"
                    r"elapsed|timeit|measure_speed")


def _free_names(node: ast.AST) -> set[str]:
    """Names an expression reads, less those its comprehensions bind (``{r["name"]: r for r in rows}`` reads rows)."""
    bound = {n.id for c in ast.walk(node) if isinstance(c, ast.comprehension) for n in ast.walk(c.target)
             if isinstance(n, ast.Name)}
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name)} - bound


def _bases(target: ast.AST) -> set[str]:
    """The variables an assignment target writes: ``ms[size, name] = ...`` writes ms."""
    while isinstance(target, (ast.Subscript, ast.Attribute, ast.Starred)):
        target = target.value
    if isinstance(target, (ast.Tuple, ast.List)):
        return set().union(*(_bases(t) for t in target.elts))
    return {target.id} if isinstance(target, ast.Name) else set()


def timing_asserts(source: str) -> list[tuple[int, str]]:
    """(line, source) of every assert of ``source`` that reads a timing.

    An assert reads a timing when its text matches :data:`TIMING` or it reads a variable whose value came from one,
    followed through the statements in order: ``start = time.perf_counter()``, ``seconds[k] = time.perf_counter() -
    start``, ``runs.append(ms)``, ``per_frame = {k: r.timings["reconstruction"] / len(r.t)}``; a plain reassignment
    from something else (or a loop over something else) clears the variable again.
    """
    tree = ast.parse(source)
    timed_names: set[str] = set()
    found: list[tuple[int, str]] = []

    def timed(node: ast.AST) -> bool:
        return bool(TIMING.search(ast.unparse(node)) or _free_names(node) & timed_names)

    def visit(statements: list[ast.stmt]) -> None:
        for st in statements:
            if isinstance(st, ast.Assert):
                if timed(st):
                    found.append((st.lineno, " ".join(ast.get_source_segment(source, st).split())))
            elif isinstance(st, (ast.Assign, ast.AugAssign, ast.AnnAssign)) and st.value is not None:
                targets = st.targets if isinstance(st, ast.Assign) else [st.target]
                if timed(st.value):
                    timed_names.update(*(_bases(t) for t in targets))
                elif isinstance(st, ast.Assign):
                    timed_names.difference_update(t.id for t in targets if isinstance(t, ast.Name))
            elif (isinstance(st, ast.Expr) and isinstance(st.value, ast.Call)
                  and isinstance(st.value.func, ast.Attribute) and any(timed(a) for a in st.value.args)):
                timed_names.update(_bases(st.value.func.value))  # runs.append(1e3 * (time.process_time() - start))
            elif isinstance(st, (ast.For, ast.AsyncFor)):
                (timed_names.update if timed(st.iter) else timed_names.difference_update)(_bases(st.target))
            for field in ("body", "orelse", "handlers", "finalbody"):
                visit(getattr(st, field, None) or [])

    visit(tree.body)
    return found


def lesson_sources() -> list[tuple[str, str]]:
    """(name, Python source) of every notebook and of every solution file (its python blocks, in order, as one)."""
    units = [(p.name, p.read_text(encoding="utf-8")) for p in course.notebook_sources()]
    for path in sorted((ROOT / "docs" / "solutions").glob("[0-9][0-9]_*.md")):
        blocks = [m.group(2) for m in FENCE.finditer(path.read_text(encoding="utf-8"))]
        units.append((path.name, "\n\n".join(blocks)))
    return units


def test_no_lesson_or_solution_asserts_a_timing():
    units = lesson_sources()
    assert len(units) >= 20 and any(name.endswith(".md") for name, _ in units)
    found = [f"{name}:{line}: {code}" for name, source in units for line, code in timing_asserts(source)]
    assert found == [], "timings are printed, not asserted (assert a count instead):\n" + "\n".join(found)


#: The forms of timing asserts that lessons held, and asserts on recording times (data, not the clock) that must pass:
#: a sample of lesson code, kept as data beside the tests (it is scanned, never run).
TIMED_FORMS = (Path(__file__).parent / "data" / "timing_asserts_sample.txt").read_text(encoding="utf-8")


def test_the_scan_finds_timing_asserts_and_leaves_recording_times_alone():
    lines = [line for line, _ in timing_asserts(TIMED_FORMS)]
    expected = [i + 1 for i, text in enumerate(TIMED_FORMS.splitlines()) if text.lstrip().startswith("assert ")][1:-2]
    assert lines == expected and len(lines) == 6  # not the RMSE, the recording times, nor a reassigned name


# ---------------------------------------------------------------------------------------------- beside a CPU hog
BUSY_LESSON = "11_msckf"  # the shortest lesson that times something (perf_counter), about 4 s in fast mode on an idle CPU


def test_a_lesson_that_prints_timings_passes_beside_busy_processes(tmp_path):
    """Lesson 11 in fast mode while two processes spin on the cores (about 8 s on a loaded 2-core CPU)."""
    source = next(p for p in course.notebook_sources() if p.name.startswith(BUSY_LESSON))
    assert "perf_counter" in source.read_text(encoding="utf-8")  # it prints wall-clock times
    notebook = course.build_notebooks([source], out_dir=tmp_path)[0]
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(min(2, os.cpu_count() or 1))]
    try:
        time.sleep(0.2)
        assert all(h.poll() is None for h in hogs)  # spinning while the lesson runs
        course.execute_notebook(notebook, timeout_s=300, fast=True)  # raises NotebookFailed on a failing cell
        assert all(h.poll() is None for h in hogs)
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    printed = "".join("".join(o.get("text", "")) for c in json.loads(notebook.read_text())["cells"]
                      for o in c.get("outputs", []))
    assert re.search(r"covariance propagation \d+\.\d+ s for", printed)  # the timing was printed
