"""Tests of evio_lib.io.output_dir: refused non-empty folders, atomic replacement, nothing left behind on failure."""
import os
import re
from pathlib import Path

import pytest

from evio_lib.io.output_dir import OutputExistsError, atomic_output_dir, check_output_dir


def _tree(folder):
    """Return {relative path: bytes} of every file under ``folder`` (the folder's complete content)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _siblings(folder):
    return sorted(p.name for p in folder.parent.iterdir())


def test_check_accepts_new_and_empty_folders(tmp_path):
    assert check_output_dir(tmp_path / "new") == tmp_path / "new"
    assert check_output_dir(str(tmp_path / "a" / "b" / "c")) == tmp_path / "a" / "b" / "c"  # missing parents are fine
    (tmp_path / "empty").mkdir()
    assert check_output_dir(tmp_path / "empty") == tmp_path / "empty"
    assert not (tmp_path / "new").exists() and not (tmp_path / "a").exists()  # checking creates nothing


def test_check_refuses_non_empty_folder_unless_forced(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / ".hidden").write_text("x")  # a hidden file counts: the folder is not empty
    with pytest.raises(OutputExistsError, match=r"output folder .*out already exists and is not empty; use --force to replace it"):
        check_output_dir(tmp_path / "out")
    assert issubclass(OutputExistsError, ValueError)
    assert check_output_dir(tmp_path / "out", force=True) == tmp_path / "out"
    assert (tmp_path / "out" / ".hidden").read_text() == "x"


def test_check_refuses_a_file_and_a_file_as_parent(tmp_path):
    (tmp_path / "file.txt").write_text("data")
    with pytest.raises(ValueError, match=r"output path .*file.txt exists and is not a folder"):
        check_output_dir(tmp_path / "file.txt", force=True)
    with pytest.raises(ValueError, match=r"cannot create output folder .*: .*file.txt is a file, not a folder"):
        check_output_dir(tmp_path / "file.txt" / "sub" / "out")
    with pytest.raises(ValueError, match="output folder must be a path; got ''"):
        check_output_dir("")


def test_check_refuses_unwritable_parent(tmp_path, monkeypatch):
    parent = tmp_path / "locked"
    parent.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if os.path.abspath(p) == str(parent) else real_access(p, mode))
    with pytest.raises(ValueError, match=r"cannot create output folder .*: the folder .*locked is not writable"):
        check_output_dir(parent / "deeper" / "out")  # the nearest EXISTING parent is the one checked


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root may write into a read-only folder")
def test_check_refuses_really_unwritable_parent(tmp_path):
    parent = tmp_path / "ro"
    parent.mkdir()
    parent.chmod(0o500)
    try:
        with pytest.raises(ValueError, match="is not writable"):
            check_output_dir(parent / "out")
    finally:
        parent.chmod(0o700)


def test_atomic_writes_appear_only_at_the_end(tmp_path):
    target = tmp_path / "sub" / "out"
    with atomic_output_dir(target) as tmp:
        assert tmp.parent == target.parent and tmp.name.startswith(".out.tmp-") and not any(tmp.iterdir())
        (tmp / "a.txt").write_text("A")
        (tmp / "nested").mkdir()
        (tmp / "nested" / "b.txt").write_text("B")
        assert not target.exists()  # nothing at the target while the command runs
    assert _tree(target) == {"a.txt": b"A", "nested/b.txt": b"B"}
    assert _siblings(target) == ["out"]  # no temporary folder left
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o777 & ~umask  # permissions of a plain mkdir, not mkdtemp's 0o700


def test_atomic_into_existing_empty_folder(tmp_path):
    (tmp_path / "out").mkdir()
    with atomic_output_dir(tmp_path / "out") as tmp:
        (tmp / "x").write_text("1")
    assert _tree(tmp_path / "out") == {"x": b"1"}


def test_atomic_refuses_non_empty_before_the_block_runs(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "keep.txt").write_text("user data")
    ran = []
    with pytest.raises(OutputExistsError, match="use --force"):
        with atomic_output_dir(tmp_path / "out"):
            ran.append(True)
    assert not ran and _tree(tmp_path / "out") == {"keep.txt": b"user data"} and _siblings(tmp_path / "out") == ["out"]


def test_force_replaces_the_folder_whole(tmp_path):
    target = tmp_path / "out"
    (target / "images").mkdir(parents=True)
    (target / "images" / "old.png").write_bytes(b"old")
    (target / "events.txt").write_text("old events")
    with atomic_output_dir(target, force=True) as tmp:
        (tmp / "events.txt").write_text("new events")
        assert (target / "images" / "old.png").read_bytes() == b"old"  # the old folder stays until the new one is done
    assert _tree(target) == {"events.txt": b"new events"}  # replaced, not merged
    assert _siblings(target) == ["out"]  # neither the temporary nor the old folder is left


@pytest.mark.parametrize("error", [RuntimeError("boom"), KeyboardInterrupt()])
@pytest.mark.parametrize("force", [False, True])
def test_exception_leaves_target_untouched_and_no_temporary_folder(tmp_path, error, force):
    target = tmp_path / "out"
    if force:
        target.mkdir()
        (target / "keep.txt").write_text("user data")
    before = _tree(target) if target.exists() else None
    with pytest.raises(type(error)):
        with atomic_output_dir(target, force=force) as tmp:
            (tmp / "half.txt").write_text("half")
            raise error
    after = _tree(target) if target.exists() else None
    assert after == before
    assert _siblings(target) == (["out"] if force else [])


def test_exception_removes_the_parents_it_created(tmp_path):
    with pytest.raises(ValueError):
        with atomic_output_dir(tmp_path / "new" / "deeper" / "out"):
            raise ValueError("failed")
    assert list(tmp_path.iterdir()) == []


def test_target_filled_meanwhile_is_not_overwritten(tmp_path):
    target = tmp_path / "out"
    with pytest.raises(OutputExistsError, match="filled by something else"):
        with atomic_output_dir(target) as tmp:
            (tmp / "new.txt").write_text("new")
            target.mkdir()
            (target / "other.txt").write_text("someone else's")
    assert _tree(target) == {"other.txt": b"someone else's"} and _siblings(target) == ["out"]


# ---------------------------------------------------------------------------------------------- inputs (issue 25)
@pytest.fixture
def recording(tmp_path, monkeypatch):
    """A user's recording REC (and a sibling REC2) below the working folder tmp_path/work."""
    work = tmp_path / "work"
    (work / "REC" / "images").mkdir(parents=True)
    (work / "REC" / "events.txt").write_text("0.1 1 2 1\n")
    (work / "REC" / "images" / "frame_00000000.png").write_bytes(b"user's image")
    (work / "REC2").mkdir()
    monkeypatch.chdir(work)
    return work


INPUT_CASES = [  # (output folder, force, message); the input is ("the input recording", "REC")
    ("REC", False, "--out REC is the input recording REC; choose a folder outside every input"),
    ("REC", True, "--out REC is the input recording REC; choose a folder outside every input"),
    ("REC/images", True, "--out REC/images lies inside the input recording REC; choose a folder outside every input"),
    ("REC/new/deeper", False, "--out REC/new/deeper lies inside the input recording REC"),
    ("REC/../REC", True, "--out REC/../REC is the input recording REC"),
    ("link", True, "--out link is the input recording REC"),  # a symbolic link to the recording is the recording
    ("link/images", True, "--out link/images lies inside the input recording REC"),
    ("{work}/..", True, "--out {work}/.. contains the working folder {work}"),  # also an ancestor of the input
    (".", True, "--out . is the working folder {work}; choose a new folder for the output"),
    ("..", False, "--out .. contains the working folder {work}"),
]


@pytest.mark.parametrize("out, force, message", INPUT_CASES, ids=[f"{o}-force" if f else o for o, f, _ in INPUT_CASES])
def test_check_refuses_inputs_and_the_working_folder_even_with_force(recording, out, force, message):
    (recording / "link").symlink_to(recording / "REC")
    before = _tree(recording)
    out = out.replace("{work}", str(recording))
    with pytest.raises(ValueError, match=re.escape(message.replace("{work}", str(recording)))):
        check_output_dir(out, force, inputs=[("the input recording", "REC")], name="--out")
    assert _tree(recording) == before


@pytest.mark.parametrize("out", [".", "..", "REC/.."])
def test_atomic_refuses_the_working_folder_before_the_block_runs(recording, out):
    before, ran = _tree(recording.parent), []
    with pytest.raises(ValueError, match="the working folder"):
        with atomic_output_dir(out, force=True):
            ran.append(True)
    assert not ran and _tree(recording.parent) == before


def test_check_refuses_a_folder_that_contains_an_input(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "data" / "rec").mkdir(parents=True)
    (tmp_path / "data" / "w.pt").write_bytes(b"weights")
    with pytest.raises(ValueError, match=r"^--out data contains the input recording data/rec; choose a folder outside"):
        check_output_dir("data", True, inputs=[("the input recording", "data/rec")], name="--out")
    with pytest.raises(ValueError, match=r"^--out data/w.pt is the --weights checkpoint data/w.pt"):
        check_output_dir("data/w.pt", True, inputs=[("the --weights checkpoint", "data/w.pt")], name="--out")
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == ["rec", "w.pt"]


def test_check_accepts_siblings_and_skips_missing_inputs(recording):
    inputs = [("the input recording", "REC"), ("the --weights checkpoint", None), ("the --times file", "")]
    assert check_output_dir("REC2", inputs=inputs, name="--out") == Path("REC2")  # REC2 starts with REC, is not in it
    assert check_output_dir("out/run", inputs=inputs, name="--out") == Path("out/run")
    assert check_output_dir("RE", inputs=inputs, name="--out") == Path("RE")


def test_check_protects_the_library(tmp_path, monkeypatch):
    import evio_lib

    monkeypatch.chdir(tmp_path)  # elsewhere than the checkout, so the working folder is not what is refused

    package = Path(evio_lib.__file__).resolve().parent
    with pytest.raises(ValueError, match="is the evio_lib package"):
        check_output_dir(package, force=True)
    with pytest.raises(ValueError, match="lies inside the evio_lib package"):
        check_output_dir(package / "weights", force=True)  # the shipped weights
    with pytest.raises(ValueError, match="contains the evio_lib package"):
        check_output_dir(package.parent, force=True)  # the checkout (or site-packages) that holds it
    assert check_output_dir(package / "weights" / "not_yet_there") == package / "weights" / "not_yet_there"


def test_check_refuses_to_replace_an_unwritable_folder(tmp_path, monkeypatch):
    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "old.txt").write_text("old")
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if os.path.abspath(p) == str(folder) else real_access(p, mode))
    with pytest.raises(ValueError, match=r"cannot replace output folder .*ro: the folder is not writable"):
        check_output_dir(folder, force=True)
    assert _tree(folder) == {"old.txt": b"old"}


def test_links_inside_an_input_and_their_targets_are_inputs(tmp_path, monkeypatch):
    """A recording whose frames folder is a link (frames kept elsewhere), or whose files are links into another
    folder: --out on the link, or on the folder the links point to, would break the recording (found by the
    campaign of issue 25: both replaced with --force, exit 0)."""
    monkeypatch.chdir(tmp_path)
    store = tmp_path / "store"
    (store / "images").mkdir(parents=True)
    (store / "images" / "frame_0.png").write_bytes(b"png")
    (store / "imu.txt").write_text("0 0 0 9.81 0 0 0\n")
    rec = tmp_path / "rec"
    rec.mkdir()
    (rec / "images").symlink_to(store / "images")
    (rec / "imu.txt").symlink_to(store / "imu.txt")
    inputs = [("the input recording", "rec")]
    with pytest.raises(ValueError, match=r"--out rec/images lies inside the input recording rec; choose a folder"):
        check_output_dir("rec/images", True, inputs=inputs, name="--out")
    with pytest.raises(ValueError, match=r"--out store contains the target of the input recording.s link .*rec/images"):
        check_output_dir("store", True, inputs=inputs, name="--out")
    with pytest.raises(ValueError, match=r"--out store/images is the target of the input recording's link"):
        check_output_dir("store/images", True, inputs=inputs, name="--out")
    assert check_output_dir("elsewhere", True, inputs=inputs, name="--out") == Path("elsewhere")
