"""Tests of issue 25 on the command line: an output folder never touches what the command reads, errors that can be
known early come before the work, and SIGTERM (what CI, ``timeout`` and schedulers send) is handled like Ctrl-C.

Every bad command line runs in a working folder that holds a user's recording and files; each must end with exit
status 2 and exactly one ``error:`` line before any real work, and leave the folder's complete content (names,
bytes, links) as it was.
"""
import os
import shlex
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from evio_lib import cli

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def _content(folder: Path) -> dict[str, object]:
    """Return {relative path: bytes, 'dir' or 'link -> target'} of everything under ``folder`` (links not followed)."""
    found: dict[str, object] = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root) / name
            key = str(path.relative_to(folder))
            if path.is_symlink():
                found[key] = f"link -> {os.readlink(path)}"
            elif path.is_dir():
                found[key] = "dir"
            else:
                found[key] = path.read_bytes()
    return found


@pytest.fixture
def work(tmp_path: Path, monkeypatch) -> Path:
    """The working folder: a recording REC (ECD layout, not loadable: a refusal must come before loading), a link
    to it, checkpoints, a Kalibr file, event files, a reconstruct-train run and a features-train config."""
    work = tmp_path / "work"
    rec = work / "REC"
    (rec / "images").mkdir(parents=True)
    (rec / "events.txt").write_text("0.1 1 2 1\n")
    (rec / "images.txt").write_text("0.0 images/frame_00000000.png\n")
    (rec / "images" / "frame_00000000.png").write_bytes(b"user's image")
    (rec / "imu.txt").write_text("0.0 0 0 9.81 0 0 0\n")
    (work / "link").symlink_to(rec)
    (work / "w.pt").write_bytes(b"a user's checkpoint")
    (work / "cam").mkdir()
    (work / "cam" / "kalibr.yaml").write_text("cam0:\n  T_cam_imu: []\n")
    (work / "cnn").mkdir()
    (work / "cnn" / "events.pt").write_bytes(b"an events-trained CNN")
    (work / "ev").mkdir()
    (work / "ev" / "events.txt").write_text("0.1 1 2 1\n")
    (work / "ev" / "frames.npy").write_bytes(b"not even numpy")
    (work / "ck").mkdir()
    (work / "ck" / "best.pt").write_bytes(b"a reconstructor")
    (work / "runs" / "magicpoint").mkdir(parents=True)
    shutil.copy(PROJECT_ROOT / "evio_lib" / "features" / "configs" / "magicpoint.json",
                work / "runs" / "magicpoint" / "my.json")
    (work / "cache" / "sequences").mkdir(parents=True)
    (work / "cache" / "sequences" / "boxes_like_d3_seed0.npz").write_bytes(b"a cached recording")
    (work / "ro").mkdir()
    (work / "ro" / "old.txt").write_text("an old run")
    monkeypatch.setenv("EVIO_CACHE_DIR", str(work / "cache"))
    monkeypatch.chdir(work)
    return work


FORCED = "choose a folder outside every input"
# (command line, {w} the working folder; text the one error line must hold)
BAD_OUTPUTS = [
    # run: the recording, inside it, an ancestor of it, the working folder, a link, --weights, --extrinsics, the cache
    ("run REC --out REC", f"--out REC is the input recording REC; {FORCED}"),
    ("run REC --out REC --force", f"--out REC is the input recording REC; {FORCED}"),
    ("run REC --out REC/images --force", f"--out REC/images lies inside the input recording REC; {FORCED}"),
    ("run REC --out REC/results", f"--out REC/results lies inside the input recording REC; {FORCED}"),
    ("run {w}/REC --out {w}/.. --force", "--out {w}/.. contains the working folder {w}"),
    ("run REC --out {w}/REC/.. --force", "--out {w}/REC/.. is the working folder {w}"),
    ("run link --out REC --force", f"--out REC is the input recording link; {FORCED}"),
    ("run REC --out link/images --force", f"--out link/images lies inside the input recording REC; {FORCED}"),
    ("run REC --out . --force", "--out . is the working folder {w}; choose a new folder for the output"),
    ("run REC --out ..", "--out .. contains the working folder {w}"),
    ("run REC --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("run REC --out ' '", "--out must be a folder path such as runs/out; got ' '"),
    ("run REC --features superpoint --weights w.pt --out w.pt --force", f"--out w.pt is the --weights checkpoint w.pt"),
    ("run REC --extrinsics cam/kalibr.yaml --out cam --force",
     f"--out cam contains the --extrinsics file cam/kalibr.yaml; {FORCED}"),
    ("run boxes_like --duration 3 --out cache --force", f"--out cache contains the recording cache {{w}}/cache/sequences"),
    ("run boxes_like --duration 3 --out cache/sequences/x", "--out cache/sequences/x lies inside the recording cache"),
    # run: errors known before the recording is loaded
    ("run REC --features nope", "--features nope: unknown detector name 'nope'; available: harris"),
    ("run REC --features nope --out new", "--features nope: unknown detector name 'nope'; available: harris"),
    ("run REC --features superpoint --weights cnn", "--weights cnn: a folder; expected a checkpoint file (.pt)"),
    ("run REC --features sift --weights w.pt", "--features sift with --weights w.pt: unknown option(s) ['weights']"),
    # table
    ("table --rows nope", "--rows: unknown table row(s) ['nope']; choose from ['imu'"),
    ("table --rows imu nope --out new", "--rows: unknown table row(s) ['nope']"),
    ("table --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("table --out . --force", "--out . is the working folder {w}"),
    ("table --events-cnn cnn/events.pt --out cnn --force", f"--out cnn contains the --events-cnn checkpoint cnn/events.pt"),
    ("table --out cache --force", "--out cache contains the recording cache"),
    ("table --out /proc/evio_out --rows imu", "cannot create output folder /proc/evio_out: "),
    ("run boxes_like --duration 3 --out /sys/kernel/evio_out",
     "cannot create output folder /sys/kernel/evio_out: "),
    ("table --duration 1e9 --rows imu", "--duration: duration of boxes_like must be in (0, 60] s (the preset's whole"),
    ("table --presets aerial_like --duration 50", "--duration: duration of aerial_like must be in (0, 40] s"),
    # reconstruct
    ("reconstruct REC --out REC --force", f"--out REC is the input recording REC; {FORCED}"),
    ("reconstruct REC --out REC/frames", f"--out REC/frames lies inside the input recording REC; {FORCED}"),
    ("reconstruct {w}/REC --out {w}/.. --force", "--out {w}/.. contains the working folder {w}"),
    ("reconstruct boxes_like --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("reconstruct boxes_like --out . --force", "--out . is the working folder {w}"),
    ("reconstruct REC --events ev/events.txt --out ev --force", f"--out ev contains the --events file ev/events.txt"),
    ("reconstruct REC --method ck/best.pt --out ck --force", "--out ck contains the --method checkpoint ck/best.pt"),
    # simulate and vio-sim (no input paths: the working folder and an empty path)
    ("simulate boxes_like --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("simulate boxes_like --out . --force", "--out . is the working folder {w}"),
    ("simulate boxes_like --out .. --force", "--out .. contains the working folder {w}"),
    ("vio-sim boxes_like --out . --force", "--out . is the working folder {w}"),
    ("vio-sim boxes_like --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("vio-sim boxes_like --features 10000000", "--features must be <= 2000 per image (MAX_SIM_FEATURES"),
    ("vio-sim boxes_like --pixel-noise 1e9", "--pixel-noise must be <= 50 px (MAX_SIM_PIXEL_NOISE_PX"),
    ("features-benchmark --detectors fast --speed-shapes 100000x100000",
     "--speed-shapes 100000x100000 is 1e+10 pixels; the most is 16,777,216"),
    # features-benchmark
    ("features-benchmark --detectors fast --fast --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("features-benchmark --detectors fast --fast --out . --force", "--out . is the working folder {w}"),
    ("features-benchmark --detectors fast --dataset events --event-frames ev/frames.npy --out ev --force",
     "--out ev contains the --event-frames file ev/frames.npy"),
    ("features-benchmark --detectors superpoint --weights w.pt --fast --out w.pt --force",
     "--out w.pt is the --weights checkpoint w.pt"),
    # features-train
    ("features-train magicpoint --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("features-train runs/magicpoint/my.json --out runs --force",
     "output folder runs/magicpoint contains the variant config runs/magicpoint/my.json"),
    # reconstruct-train
    ("reconstruct-train --out ''", "--out must be a folder path such as runs/out; got ''"),
    ("reconstruct-train --out . --force", "--out . is the working folder {w}"),
    ("reconstruct-train --out ck --init-from ck/best.pt --force", "--out ck contains the --init-from checkpoint ck/best.pt"),
]


@pytest.mark.parametrize("command, message", BAD_OUTPUTS, ids=[c for c, _ in BAD_OUTPUTS])
def test_bad_output_is_one_error_line_and_nothing_changes(work, capsys, command, message):
    before = _content(work.parent)
    code = cli.main(shlex.split(command.replace("{w}", str(work))))
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("error: "), captured.err
    assert message.replace("{w}", str(work)) in lines[0]
    assert _content(work.parent) == before  # nothing the user gave is modified, nothing is left behind


def test_run_refuses_an_unwritable_folder_to_replace(work, capsys, monkeypatch):
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if os.path.abspath(p) == str(work / "ro")
                        else real_access(p, mode))  # root may write anywhere: the check itself is what is tested
    before = _content(work.parent)
    assert cli.main(["run", "REC", "--out", "ro", "--force"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: cannot replace output folder ro: the folder is not writable")
    assert _content(work.parent) == before


def test_run_checks_come_before_loading(work, capsys, monkeypatch):
    from evio_lib.pipeline import dataset

    def never(*args, **kwargs):
        raise AssertionError("the recording was loaded before the arguments were checked")

    monkeypatch.setattr(dataset, "load_dataset", never)
    for argv in (["run", "REC", "--out", "REC/x"], ["run", "REC", "--features", "nope"],
                 ["run", "boxes_like", "--features", "nope", "--out", "new"]):
        assert cli.main(argv) == 2
        assert capsys.readouterr().err.count("error: ") == 1


# ------------------------------------------------------------------------------------------------------ signals
# First line of every child: Python's own SIGINT handler. A pytest-xdist worker ignores SIGINT, a child inherits an
# ignored signal, and Python then never raises KeyboardInterrupt: the test would wait in vain.
_SIGINT_AS_AT_A_SHELL = "import signal; signal.signal(signal.SIGINT, signal.default_int_handler)\n"


def _start(code: str, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(PROJECT_ROOT)}
    return subprocess.Popen([sys.executable, "-c", _SIGINT_AS_AT_A_SHELL + textwrap.dedent(code)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(predicate, process: subprocess.Popen, seconds: float = 240.0) -> None:  # generous: a busy 2-core CPU
    deadline = time.monotonic() + seconds
    while not predicate():
        if process.poll() is not None:
            raise AssertionError(f"the command ended early ({process.returncode}): {process.stderr.read()}")
        if time.monotonic() > deadline:
            process.kill()
            raise AssertionError("timed out waiting for the command")
        time.sleep(0.05)


@pytest.mark.parametrize("signum, code, line", [(signal.SIGTERM, 143, "error: terminated"),
                                                (signal.SIGINT, 130, "error: interrupted")])
def test_a_signal_while_writing_leaves_no_temporary_folder(tmp_path, signum, code, line):
    """python -m evio_lib simulate, its write slowed down: the signal arrives while .out.tmp-* is being filled."""
    process = _start("""
        import runpy, sys, time
        import evio_lib.io.ecd as ecd

        def slow_write(sequence, folder, progress=False):
            (folder / "half.txt").write_text("half")
            time.sleep(120)

        ecd.write_ecd = slow_write
        sys.argv = ["evio_lib", "simulate", "boxes_like", "--out", "out", "--duration", "0.2", "--no-events", "--quiet"]
        runpy.run_module("evio_lib", run_name="__main__", alter_sys=True)
        """, tmp_path)
    _wait_for(lambda: any(tmp_path.glob(".out.tmp-*/half.txt")), process)
    process.send_signal(signum)
    _, err = process.communicate(timeout=60)
    assert process.returncode == code, err
    assert err.strip().splitlines() == [line]
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # neither out nor .out.tmp-* is left


SLOW_IMPORT = """
    import importlib.abc, runpy, sys, time

    class SlowImport(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "evio_lib.cli":
                open("starting", "w").close()
                time.sleep(120)
            return None  # the normal finders import it

    sys.meta_path.insert(0, SlowImport())
    """
SLOW_PARSER = """
    import runpy, sys, time
    import evio_lib.cli

    def slow_parser(*args, build=evio_lib.cli.build_parser, **kwargs):
        open("starting", "w").close()
        time.sleep(120)
        return build(*args, **kwargs)

    evio_lib.cli.build_parser = slow_parser
    """


@pytest.mark.parametrize("stage", ["import", "parser"])
@pytest.mark.parametrize("signum, code, line", [(signal.SIGTERM, 143, "error: terminated"),
                                                (signal.SIGINT, 130, "error: interrupted")])
def test_a_signal_while_starting_is_one_line(tmp_path, stage, signum, code, line):
    """The signal arrives while `python -m evio_lib` still imports evio_lib.cli (before main() runs), or while
    main() builds the parser (which imports every command's module)."""
    process = _start((SLOW_IMPORT if stage == "import" else SLOW_PARSER) + """
    sys.argv = ["evio_lib", "simulate", "boxes_like", "--out", "out", "--quiet"]
    runpy.run_module("evio_lib", run_name="__main__", alter_sys=True)
    """, tmp_path)
    _wait_for(lambda: (tmp_path / "starting").exists(), process)
    process.send_signal(signum)
    _, err = process.communicate(timeout=60)
    assert process.returncode == code, err
    assert err.strip().splitlines() == [line]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["starting"]


def test_sigterm_from_the_shell(tmp_path):
    """A real `python -m evio_lib simulate` process, terminated while it imports or simulates: 143, one line."""
    env = {**os.environ, "PYTHONPATH": str(PROJECT_ROOT)}
    process = subprocess.Popen([sys.executable, "-m", "evio_lib", "simulate", "boxes_like", "--out", "out",
                                "--duration", "60", "--quiet"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    time.sleep(1.5)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 143, err
    assert err.strip().splitlines() == ["error: terminated"]
    assert list(tmp_path.iterdir()) == []


def test_sigterm_handler_is_restored(work, capsys):
    before = signal.getsignal(signal.SIGTERM)
    assert cli.main(["run", "REC", "--out", "REC"]) == 2
    assert signal.getsignal(signal.SIGTERM) is before
    capsys.readouterr()


def test_ctrl_c_inside_joblib_is_one_line(work, monkeypatch, capsys):
    """joblib, interrupted while it dispatches, may fail in its own clean-up (an AttributeError raised while the
    KeyboardInterrupt is handled): `table` still ends with 130 and one line, not joblib's traceback."""
    import joblib

    class Broken:
        def __init__(self, *args, **kwargs):
            pass

        def __call__(self, jobs):
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                raise AttributeError("'Parallel' object has no attribute '_pre_dispatch_amount'")

    monkeypatch.setattr(joblib, "Parallel", Broken)
    assert cli.main(["table", "--fast", "--rows", "imu"]) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["error: interrupted"]
    assert not (work / "out").exists()
