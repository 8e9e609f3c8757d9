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
