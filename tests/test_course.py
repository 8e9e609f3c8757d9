"""Tests of evio_lib.course: fast-mode parsing, the notebooks' order, the .ipynb build and the kernels' environment."""
import json
import os

import pytest

from evio_lib import course


@pytest.mark.parametrize("value, fast", [("1", True), ("0", False), ("", False), (None, False), (" 1 ", True)])
def test_fast_mode_values(value, fast):
    environ = {} if value is None else {"EVIO_FAST": value}
    assert course.fast_mode(environ) is fast


@pytest.mark.parametrize("value", ["true", "yes", "2", "fast", "1.0"])
def test_fast_mode_refuses_what_the_notebooks_would_read_as_full(value):
    with pytest.raises(ValueError, match=rf"EVIO_FAST must be 1 \(fast mode\) or 0 \(full lessons\); got '{value}'"):
        course.fast_mode({"EVIO_FAST": value})


def test_fast_mode_reads_the_process_environment(monkeypatch):
    monkeypatch.setenv("EVIO_FAST", "1")
    assert course.fast_mode()
    monkeypatch.delenv("EVIO_FAST")
    assert not course.fast_mode()


def test_notebook_sources_in_course_order(tmp_path):
    for name in ["10_msckf.py", "02_epipolar.py", "01_pinhole.py", "1_short.py", "03_Upper.py", "04_notes.md",
                 "05_helper.py.bak", "helpers.py", "11_b.py"]:
        (tmp_path / name).write_text("# %%\n")
    (tmp_path / "06_folder.py").mkdir()  # a folder is not a notebook, whatever its name
    names = [p.name for p in course.notebook_sources(tmp_path)]
    assert names == ["01_pinhole.py", "02_epipolar.py", "10_msckf.py", "11_b.py"]


def test_notebook_sources_of_the_repository():
    names = [p.name for p in course.notebook_sources()]
    assert names[0].startswith("01_") and names == sorted(names) and len(names) >= 10
    assert all(name[:2].isdigit() and name.endswith(".py") for name in names)


def test_notebook_sources_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"notebook folder not found: .*nowhere \(expected the repository's "):
        course.notebook_sources(tmp_path / "nowhere")


def test_build_writes_ipynb_files_with_the_cells(tmp_path):
    source = tmp_path / "01_demo.py"
    source.write_text('# %% [markdown]\n# # Title\n\n# %%\nx = 1 + 1\nassert x == 2\n')
    out = tmp_path / "build" / "nb"
    written = course.build_notebooks([source], out_dir=out)
    assert written == [out / "01_demo.ipynb"]
    notebook = json.loads(written[0].read_text())
    assert [c["cell_type"] for c in notebook["cells"]] == ["markdown", "code"]
    assert "".join(notebook["cells"][1]["source"]) == "x = 1 + 1\nassert x == 2"
    assert all(c.get("outputs", []) == [] for c in notebook["cells"])  # built, not executed
    assert source.read_text().startswith("# %% [markdown]")  # the source is not touched


def test_build_defaults_to_build_notebooks():
    assert course.BUILD_DIR == course.PROJECT_ROOT / "build" / "notebooks"
    assert course.build_notebooks([]) == []


def test_kernel_environment_sets_mode_and_path_without_touching_os_environ():
    base = {"EVIO_FAST": "1", "PYTHONPATH": "/elsewhere", "HOME": "/home/student"}
    env = course.kernel_environment(fast=False, environ=base)
    assert env["EVIO_FAST"] == "0" and env["HOME"] == "/home/student"
    assert env["PYTHONPATH"].split(os.pathsep) == [str(course.PROJECT_ROOT), "/elsewhere"]  # this tree first
    assert base["EVIO_FAST"] == "1"  # the caller's mapping is not modified
    assert course.kernel_environment(fast=True, environ={})["EVIO_FAST"] == "1"
    assert "EVIO_FAST" not in course.kernel_environment(environ={})  # None keeps what the environment says
    before = dict(os.environ)
    course.kernel_environment(fast=True)
    assert dict(os.environ) == before


def test_execute_passes_the_mode_to_the_kernel(tmp_path, monkeypatch):
    monkeypatch.setenv("EVIO_FAST", "0")
    source = tmp_path / "01_mode.py"
    source.write_text('# %%\nimport os, evio_lib\nprint(os.environ["EVIO_FAST"], evio_lib.__file__)\n')
    notebook_path = course.build_notebooks([source], out_dir=tmp_path / "nb")[0]
    course.execute_notebook(notebook_path, timeout_s=120, fast=True)
    outputs = json.loads(notebook_path.read_text())["cells"][0]["outputs"]
    mode, module = "".join(outputs[0]["text"]).split()
    assert mode == "1"  # --fast reached the kernel, though this process says 0
    assert module.startswith(str(course.PROJECT_ROOT))  # and the kernel imports this working tree
    assert os.environ["EVIO_FAST"] == "0"


def test_executing_prints_no_kernel_transport_warning(tmp_path, capfd):
    """The kernel's own 'running over TCP without encryption' log line stays out of the course's output."""
    source = tmp_path / "01_quiet.py"
    source.write_text('# %%\nprint("hello")\n')
    notebook_path = course.build_notebooks([source], out_dir=tmp_path / "nb")[0]
    course.execute_notebook(notebook_path, timeout_s=120, fast=True)
    captured = capfd.readouterr()
    assert "without encryption" not in captured.err + captured.out
    assert "hello" in "".join(json.loads(notebook_path.read_text())["cells"][0]["outputs"][0]["text"])


def test_joblib_workers_are_stopped_before_the_kernel_and_the_cleanup_is_not_stored(tmp_path, capfd):
    source = tmp_path / "01_workers.py"
    source.write_text("# %%\nimport math\nfrom joblib import Parallel, delayed\n"
                      "print(sum(Parallel(n_jobs=2)(delayed(math.sqrt)(i) for i in range(4))))\n")
    notebook_path = course.build_notebooks([source], out_dir=tmp_path / "nb")[0]
    course.execute_notebook(notebook_path, timeout_s=120, fast=True)
    cells = json.loads(notebook_path.read_text())["cells"]
    assert len(cells) == 1 and "_pool" not in "".join(cells[0]["source"])
    assert "KeyboardInterrupt" not in capfd.readouterr().err


def test_stop_workers_ends_the_reusable_pool_without_making_one():
    import joblib.externals.loky.reusable_executor as loky_pool
    from joblib import Parallel, delayed

    assert Parallel(n_jobs=2)(delayed(abs)(-i) for i in range(4)) == [0, 1, 2, 3]
    pool = loky_pool._executor
    processes = list(pool._processes.values())
    assert processes and all(p.is_alive() for p in processes)
    exec(course._STOP_WORKERS, {})
    assert not any(p.is_alive() for p in processes)
    exec(course._STOP_WORKERS, {})  # a stopped pool again: nothing to do, no error
    assert Parallel(n_jobs=2)(delayed(abs)(-i) for i in range(3)) == [0, 1, 2]  # joblib starts a new pool


# ---------------------------------------------------------------------------------------------- a failing lesson
FAILING_LESSON = '''# %% [markdown]
# # A lesson whose second cell fails

# %%
counts = [1, 2, 3]
print("three counts")

# %%
total = sum(counts)
assert (len(counts)
        == 4)
print("never printed")

# %%
print("never run")
'''


def test_a_failing_cell_is_one_line_naming_the_lesson_and_the_cell(tmp_path, monkeypatch, capsys):
    """The course command prints one line, not nbclient's traceback, and leaves the executed part for the student."""
    from evio_lib import cli

    (tmp_path / "lessons").mkdir()
    (tmp_path / "lessons" / "01_demo.py").write_text(FAILING_LESSON)
    build = tmp_path / "build" / "notebooks"
    notebook_sources, build_notebooks = course.notebook_sources, course.build_notebooks
    monkeypatch.setattr(course, "notebook_sources", lambda: notebook_sources(tmp_path / "lessons"))
    monkeypatch.setattr(course, "build_notebooks", lambda sources: build_notebooks(sources, out_dir=build))
    monkeypatch.setattr(course, "_STOP_WORKERS", "open('workers_stopped', 'w').close()")
    monkeypatch.chdir(tmp_path)
    assert cli.main(["course", "--fast"]) == 1
    assert (build / "workers_stopped").exists()  # the clean-up of a last cell also ran after the failing one
    err = capsys.readouterr().err
    assert err == ("error: notebook 01_demo, cell 2: AssertionError (line 2: assert (len(counts) == 4)); "
                   "the partial notebook is at build/notebooks/01_demo.ipynb\n")
    cells = json.loads((build / "01_demo.ipynb").read_text())["cells"]
    assert [c.get("execution_count") for c in cells] == [None, 1, 2, None]
    assert "three counts" in "".join(cells[1]["outputs"][0]["text"])
    assert [o["output_type"] for o in cells[2]["outputs"]] == ["error"] and cells[3]["outputs"] == []


class _Cell(dict):
    """The part of an nbformat cell that the failure message reads."""

    def __init__(self, source):
        super().__init__(source=source, cell_type="code")
        self.source = source


@pytest.mark.parametrize("ename, evalue, traceback, expected", [
    ("AssertionError", "", "Cell \x1b[0;32mIn[7], line 2\x1b[0m\n----> 2 assert x == 3",
     "AssertionError (line 2: assert x == 3)"),
    ("AssertionError", "the counts differ", "Cell In[7], line 2", "AssertionError: the counts differ (line 2: assert x == 3)"),
    ("ValueError", "\nbad shape (3,)\nexpected (2,)", "Cell In[4], line 1\n...\nFile lib.py:9, in f\n",
     "ValueError: bad shape (3,) ... (line 1: x = 2)"),
    ("ZeroDivisionError", "division by zero", "Input In [4], in <cell line: 2>()",  # IPython 8.0-8.5
     "ZeroDivisionError: division by zero (line 2: assert x == 3)"),
    ("SyntaxError", "invalid syntax (2977855035.py, line 1)", "  Cell In[3], line 9", "SyntaxError: invalid syntax "
     "(2977855035.py, line 1)"),  # no such line in the cell: no code shown
])
def test_failure_message_is_the_exception_and_the_cells_line(ename, evalue, traceback, expected):
    from nbclient.exceptions import CellExecutionError

    cell = _Cell("x = 2\nassert x == 3")
    assert course._failure_message(CellExecutionError(traceback, ename, evalue), cell, 60) == expected


def test_failure_message_of_a_timeout_and_a_dead_kernel():
    from nbclient.exceptions import CellTimeoutError, DeadKernelError

    assert course._failure_message(CellTimeoutError("x"), _Cell("x"), 1800) == "still running after 1800 s, the limit per cell"
    assert course._failure_message(DeadKernelError("Kernel died"), _Cell("x"), 60) == "the kernel stopped (Kernel died)"


def test_notebook_failed_names_the_lesson_the_cell_and_the_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    failed = course.NotebookFailed("14_evio_pipeline", 41, "AssertionError (line 3: assert a < b)",
                                   tmp_path / "build" / "notebooks" / "14_evio_pipeline.ipynb")
    assert str(failed) == ("notebook 14_evio_pipeline, cell 41: AssertionError (line 3: assert a < b); the partial "
                           "notebook is at build/notebooks/14_evio_pipeline.ipynb")
    elsewhere = course.NotebookFailed("01_x", None, "the kernel stopped (Kernel died)", "/elsewhere/01_x.ipynb")
    assert str(elsewhere).startswith("notebook 01_x, after its last cell: ") and str(elsewhere).endswith("/elsewhere/01_x.ipynb")


def test_statement_at_shows_a_split_statement_whole():
    source = 'x = 1\nfor i in range(3):\n    assert (i\n            < 2), "big"\nif x: assert x\n'
    assert course._statement_at(source, 4) == 'assert (i\n            < 2), "big"'
    assert course._statement_at(source, 2) == "for i in range(3):"  # a loop's header, not its body
    assert course._statement_at(source, 5) == "assert x"
    assert course._statement_at(source, 9) == ""
    assert course._statement_at("%time " + source, 4) == '            < 2), "big"'  # IPython, not Python: the line
