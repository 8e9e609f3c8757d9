"""The exercise solutions in docs/solutions/*.md run and their asserts hold (issue 27).

Each notebook's exercises must all carry a hint and be answered, in order, by a "## Exercise N:" section of
docs/solutions/NN_name.md (an exercise added to a notebook without a solution fails here). Every fenced ```python
block of a solution file is executed, in order, in one namespace per file (a later block may
use an earlier block's names). Blocks fenced ```python no-test are too expensive for CI (trainings, full-length
runs, command-line benchmarks): they are counted, not run, and the test checks that they stay few. The blocks run
with EVIO_FAST=1 and the Agg backend, on tiny data, so that the whole file stays around a minute on a 2-core CPU.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

SOLUTIONS = Path(__file__).resolve().parents[1] / "docs" / "solutions"
FENCE = re.compile(r"^```python([^\n]*)\n(.*?)^```\s*$", re.S | re.M)
MAX_NO_TEST = 16  # expensive blocks (trainings, full runs); most solutions must be checked


def solution_files() -> list[Path]:
    return sorted(SOLUTIONS.glob("[0-9][0-9]_*.md"))


def blocks(path: Path) -> list[tuple[str, str]]:
    """(fence info after 'python', code) of every ```python block of a markdown file."""
    return [(m.group(1).strip(), m.group(2)) for m in FENCE.finditer(path.read_text(encoding="utf-8"))]


def test_one_solution_file_per_notebook():
    notebooks = sorted(p.stem for p in (SOLUTIONS.parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))
    assert [p.stem for p in solution_files()] == notebooks


def exercises(notebook: Path) -> dict[int, str]:
    """{number: text} of the items of a notebook's "## Exercises" section (up to the next heading or cell)."""
    lines = notebook.read_text(encoding="utf-8").split("\n")
    start = lines.index("# ## Exercises")
    items: dict[int, str] = {}
    for line in lines[start + 1:]:
        if line.startswith("# %%") or line.startswith("# ## "):
            break
        match = re.match(r"^# (\d+)\. ", line)
        if match:
            number = int(match.group(1))
            items[number] = ""
        if items:
            items[number] += line + "\n"
    return items


@pytest.mark.parametrize("path", solution_files(), ids=lambda p: p.stem)
def test_every_exercise_has_a_hint_and_a_solution(path):
    items = exercises(SOLUTIONS.parents[1] / "notebooks" / f"{path.stem}.py")
    assert list(items) == list(range(1, len(items) + 1)) and items, path.stem
    assert all("*Hint:*" in text for text in items.values()), [n for n, t in items.items() if "*Hint:*" not in t]
    solved = [int(n) for n in re.findall(r"^## Exercise (\d+):", path.read_text(encoding="utf-8"), re.M)]
    assert solved == list(items), f"{path.name} answers exercises {solved}, the notebook has {list(items)}"


def test_few_blocks_are_untested():
    infos = [info for path in solution_files() for info, _ in blocks(path)]
    assert set(infos) <= {"", "no-test"}, set(infos)
    untested, tested = infos.count("no-test"), infos.count("")
    print(f"{tested} solution blocks run, {untested} marked no-test")
    assert tested >= 40 and untested <= MAX_NO_TEST


@pytest.mark.parametrize("path", solution_files(), ids=lambda p: p.stem)
def test_solution_blocks_run(path, monkeypatch, tmp_path):
    monkeypatch.setenv("EVIO_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    import cv2
    import matplotlib
    import torch

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # one thread, as the notebooks run: on a busy 2-core CPU more threads only contend (torch would take both cores)
    threads = torch.get_num_threads(), cv2.getNumThreads()
    torch.set_num_threads(1)
    cv2.setNumThreads(1)

    namespace: dict = {"__name__": f"solution_{path.stem}"}
    try:
        for number, (info, code) in enumerate(blocks(path), 1):
            if info == "no-test":
                continue
            try:
                exec(compile(code, f"{path.name}[block {number}]", "exec"), namespace)
            finally:
                plt.close("all")
    finally:
        torch.set_num_threads(threads[0])
        cv2.setNumThreads(threads[1])
