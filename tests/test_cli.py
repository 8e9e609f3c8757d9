"""Tests of evio_lib.cli: users' mistakes end in one line "error: ..." and exit 2, output folders are never lost or
left half-written, equal seeds give equal folders, and every option explains itself.

The table BAD_INPUTS holds the bad command lines; each must fail before any real work, so the table runs in seconds.
"""
import argparse
import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from evio_lib import cli, course
from evio_lib.features.evaluation import benchmark
from evio_lib.io.cache import default_cache_dir

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def _tree(folder: Path) -> dict[str, bytes]:
    """Return {relative path: bytes} of every file under ``folder``."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def inputs(tmp_path: Path) -> Path:
    """A folder of a user's files: a non-empty output folder, a plain file, bad checkpoints, event frames."""
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "events.txt").write_text("0.1 1 2 1\n")
    (tmp_path / "full" / "images").mkdir()
    (tmp_path / "full" / "images" / "frame_00000000.png").write_bytes(b"user's image")
    (tmp_path / "file.txt").write_text("a file, not a folder")
    (tmp_path / "garbage.pt").write_text("garbage\n")
    (tmp_path / "empty.pt").write_bytes(b"")
    (tmp_path / "runs" / "magicpoint").mkdir(parents=True)
    (tmp_path / "runs" / "magicpoint" / "last.pt").write_bytes(b"an earlier run")
    np.save(tmp_path / "frames.npy", np.random.default_rng(0).random((2, 60, 80), dtype=np.float32))
    return tmp_path


# (command line with {d} for the inputs folder, text the one error line must hold)
BAD_INPUTS = [
    # simulate
    ("simulate boxes_like --out {d}/o --duration -1", "--duration must be > 0; got -1"),
    ("simulate boxes_like --out {d}/o --duration 0", "--duration must be > 0; got 0"),
    ("simulate boxes_like --out {d}/o --duration nan", "--duration must be a finite number > 0; got nan"),
    ("simulate boxes_like --out {d}/o --duration inf", "--duration must be a finite number > 0; got inf"),
    ("simulate boxes_like --out {d}/o --duration ten", "--duration must be a number > 0; got 'ten'"),
    ("simulate boxes_like --out {d}/o --seed -5", "--seed must be >= 0; got -5"),
    ("simulate boxes_like --out {d}/o --seed 1.5", "--seed must be an integer >= 0; got '1.5'"),
    ("simulate mars_like --out {d}/o", "preset: invalid choice: 'mars_like'"),
    ("simulate boxes_like", "the following arguments are required: --out"),
    ("simulate boxes_like --out {d}/o --bogus", "unrecognized arguments: --bogus"),
    ("simulate boxes_like --out {d}/full --duration 0.01", "output folder {d}/full already exists and is not empty; use --force"),
    ("simulate boxes_like --out {d}/file.txt --force", "output path {d}/file.txt exists and is not a folder"),
    ("simulate boxes_like --out {d}/file.txt/sub", "cannot create output folder {d}/file.txt/sub: {d}/file.txt is a file"),
    # vio-sim
    ("vio-sim boxes_like --duration 1", "--duration must be >= 2; got 1"),
    ("vio-sim boxes_like --features 0", "--features must be >= 1; got 0"),
    ("vio-sim boxes_like --pixel-noise -1", "--pixel-noise must be >= 0; got -1"),
    ("vio-sim boxes_like --gate 1", "--gate must be > 0 and < 1; got 1"),
    ("vio-sim boxes_like --seed -2", "--seed must be >= 0; got -2"),
    ("vio-sim boxes_like --noise-model exact", "--noise-model: invalid choice: 'exact'"),
    ("vio-sim boxes_like --out {d}/full", "output folder {d}/full already exists and is not empty; use --force"),
    # features-benchmark
    ("features-benchmark --detectors superpoint --weights {d}/garbage.pt --fast",
     "--weights {d}/garbage.pt: not a readable SuperPoint checkpoint: not a torch checkpoint file"),
    ("features-benchmark --detectors superpoint --weights {d}/empty.pt --fast",
     "--weights {d}/empty.pt: the file is empty; expected a SuperPoint checkpoint"),
    ("features-benchmark --detectors superpoint --weights {d}/missing.pt --fast", "--weights {d}/missing.pt: "),
    ("features-benchmark --detectors superpoint --weights no_such_network --fast",
     "--weights no_such_network: SuperPoint weights 'no_such_network' not found"),
    ("features-benchmark --detectors nope --fast", "unknown detector name 'nope'; available: harris"),
    ("features-benchmark --pairs-per-image 0 --fast", "--pairs-per-image must be >= 1; got 0"),
    ("features-benchmark --n-images 0", "--n-images must be >= 1; got 0"),
    ("features-benchmark --speed-frames 0", "--speed-frames must be >= 1; got 0"),
    ("features-benchmark --seed -1", "--seed must be >= 0; got -1"),
    ("features-benchmark --detectors fast --speed-shapes 10x", "--speed-shapes entries must look like 180x240"),
    ("features-benchmark --detectors fast --speed-shapes 4x4", "--speed-shapes entries must be at least 8x8"),
    ("features-benchmark --detectors fast --dataset hpatches", "--dataset hpatches needs --hpatches-root"),
    ("features-benchmark --detectors fast --dataset events", "--dataset events needs --event-frames"),
    ("features-benchmark --detectors fast --dataset events --event-frames {d}/none.npy", "--event-frames {d}/none.npy is not a file"),
    ("features-benchmark --detectors fast --dataset events --event-frames {d}/file.txt", "--event-frames"),
    ("features-benchmark --detectors fast --fast --out {d}/full", "output folder {d}/full already exists and is not empty"),
    # features-train
    ("features-train nope --out {d}/runs", "config 'nope' is neither a config file nor a shipped variant"),
    ("features-train magicpoint --steps 0", "--steps must be >= 1; got 0"),
    ("features-train magicpoint --batch-size 0", "--batch-size must be >= 1; got 0"),
    ("features-train magicpoint --threads 0", "--threads must be >= 1; got 0"),
    ("features-train magicpoint --num-workers -1", "--num-workers must be >= 0; got -1"),
    ("features-train magicpoint --max-minutes 0", "--max-minutes must be > 0; got 0"),
    ("features-train magicpoint --image-size 120", "--image-size must look like 120x160"),
    ("features-train magicpoint --set steps", "--set must look like KEY=VALUE"),
    ("features-train magicpoint --device tpu", "--device: invalid choice: 'tpu'"),
    ("features-train", "name the VARIANT(s) to train"),
    ("features-train magicpoint --out {d}/runs --steps 1",
     "output folder {d}/runs/magicpoint already exists and is not empty; use --force to replace it, or --resume"),
    # run: stretches and event windows
    ("run {d}/full --start 1", "--start applies to simulated presets"),
    ("run boxes_like --start 70", "start of boxes_like must be in [0, 60) s"),
    ("run boxes_like --start -1", "--start must be >= 0; got -1"),
    ("run boxes_like --max-window 0", "--max-window must be > 0; got 0"),
    ("run boxes_like --frames mc-events --min-window 0.2 --max-window 0.1", "(0.1) must be greater than"),
    ("run boxes_like --frames mc", "--frames: invalid choice: 'mc'"),
    ("run boxes_like --max-track-gap -1", "--max-track-gap must be >= 0; got -1"),
    ("run boxes_like --max-track-gap 1.5", "--max-track-gap"),
    ("run boxes_like --frames aps+mc-events --event-pixel-noise 0", "--event-pixel-noise must be > 0; got 0"),
    ("run {d}/full --aps-exposure 0.02", "--aps-exposure applies to simulated presets; a recording's frames"),
    ("run {d}/full --speed 2", "--speed applies to simulated presets; a recording's motion is the one"),
    ("run boxes_like --speed 0", "--speed must be > 0; got 0"),
    ("run boxes_like --event-tracker klt", "--event-tracker applies to a run that fuses APS frames with an event"),
    ("run boxes_like --frames aps+mc-events --event-tracker sift", "--event-tracker: invalid choice: 'sift'"),
    ("run boxes_like --pixel-noise inf", "--pixel-noise must be a finite number > 0; got inf"),
    ("run boxes_like --frames events --reconstructor-precision float16",
     "--reconstructor-precision: invalid choice: 'float16'"),
    ("reconstruct boxes_like --out {d}/rec --precision int4", "--precision: invalid choice: 'int4'"),
    # course and the command itself
    ("course --only 99 --no-execute", "--only 99 matches no notebook; available: 01_"),
    ("", "the following arguments are required: COMMAND"),
    ("fly", "COMMAND: invalid choice: 'fly'"),
]


@pytest.mark.parametrize("command, message", BAD_INPUTS, ids=[c for c, _ in BAD_INPUTS])
def test_bad_input_is_one_error_line_and_exit_2(inputs, capsys, command, message):
    before = _tree(inputs)
    code = cli.main(command.replace("{d}", str(inputs)).split())
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("error: "), captured.err
    assert message.replace("{d}", str(inputs)) in lines[0]
    assert _tree(inputs) == before  # nothing the user gave is modified, nothing is left behind
    assert sorted(p.name for p in inputs.iterdir()) == sorted(["full", "file.txt", "garbage.pt", "empty.pt", "runs",
                                                               "frames.npy"])


def test_bad_fast_mode_variable(monkeypatch, capsys):
    monkeypatch.setenv("EVIO_FAST", "yes")
    assert cli.main(["course", "--no-execute"]) == 2
    assert capsys.readouterr().err.strip() == "error: EVIO_FAST must be 1 (fast mode) or 0 (full lessons); got 'yes'"


def test_debug_shows_the_traceback(inputs):
    argv = ["simulate", "boxes_like", "--out", str(inputs / "full"), "--duration", "0.01"]
    with pytest.raises(ValueError, match="already exists and is not empty"):
        cli.main(["--debug", *argv])
    with pytest.raises(ValueError, match="already exists and is not empty"):
        cli.main([*argv, "--debug"])  # also after the command


def test_help_exits_0(capsys):
    assert cli.main(["--help"]) == 0
    assert "simulate" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------- simulate
def _simulate(out: Path, *extra: str) -> int:
    return cli.main(["simulate", "boxes_like", "--out", str(out), "--duration", "0.04", "--quiet", *extra])


def test_simulate_twice_gives_byte_identical_folders(tmp_path, capsys):
    assert _simulate(tmp_path / "a", "--cache", "--seed", "3") == 0
    assert _simulate(tmp_path / "b", "--cache", "--seed", "3") == 0
    a, b = _tree(tmp_path / "a"), _tree(tmp_path / "b")
    assert set(a) >= {"events.txt", "imu.txt", "images.txt", "groundtruth.txt", "calib.txt", "evio_sim.json",
                      "sequence.npz", "images/frame_00000000.png"}
    assert a == b
    assert _simulate(tmp_path / "c", "--seed", "4") == 0
    assert _tree(tmp_path / "c")["events.txt"] != a["events.txt"]  # the seed matters: the comparison is not vacuous
    sidecar = json.loads(a["evio_sim.json"])
    assert set(sidecar["metadata"]["timings"]) == {"event_renders"}  # counts only, no wall-clock seconds
    printed = capsys.readouterr().out
    assert "SimulationConfig(" not in printed and "simulated boxes_like_seed3 in" in printed  # --quiet: no config


def test_simulate_prints_config_without_quiet(tmp_path, capsys):
    assert cli.main(["simulate", "boxes_like", "--out", str(tmp_path / "o"), "--duration", "0.02", "--no-events",
                     "--no-frames"]) == 0
    assert "SimulationConfig(preset='boxes_like'" in capsys.readouterr().out


def test_simulate_force_replaces_the_folder(inputs, capsys):
    assert _simulate(inputs / "full", "--force", "--no-frames") == 0
    files = _tree(inputs / "full")
    assert "images/frame_00000000.png" not in files  # the old folder is replaced, not merged into
    assert files["events.txt"] != b"0.1 1 2 1\n" and "imu.txt" in files
    assert [p.name for p in inputs.iterdir() if p.name.startswith(".")] == []  # no temporary folder left


@pytest.mark.parametrize("error", [OSError("No space left on device"), KeyboardInterrupt()])
@pytest.mark.parametrize("existing", [False, True])
def test_simulate_failure_leaves_no_partial_output(inputs, monkeypatch, capsys, error, existing):
    from evio_lib.io import ecd

    real_write = ecd.write_ecd

    def write_then_fail(sequence, folder, progress=False):
        real_write(sequence, folder, progress)  # a complete ECD folder in the temporary place ...
        raise error  # ... and then the failure (disk full, Ctrl-C) before the command finished

    monkeypatch.setattr(ecd, "write_ecd", write_then_fail)
    out = inputs / ("full" if existing else "new")
    before = _tree(inputs)
    code = _simulate(out, "--force", "--no-frames")
    assert code == (130 if isinstance(error, KeyboardInterrupt) else 2)
    assert capsys.readouterr().err.strip().startswith("error: ")
    assert _tree(inputs) == before and out.exists() == existing
    assert [p.name for p in inputs.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("error, words", [
    (OSError(errno.EFBIG, "File too large"), "a file grew beyond the largest file allowed (the shell's file-size limit"),
    (OSError(errno.ENOSPC, "No space left on device"), "no space left on the device (free some, or write elsewhere)"),
])
def test_a_refused_write_says_the_cause_in_words_and_where_the_command_writes(inputs, monkeypatch, capsys, error, words):
    """A write the system refuses without naming a file ('[Errno 27] File too large') says what happened in words and
    where the command writes (its --out and the cache: the failing file may be either); a temporary folder's name
    never reaches the message."""
    from evio_lib.io import ecd

    def fail(sequence, folder, progress=False):
        raise error

    monkeypatch.setattr(ecd, "write_ecd", fail)
    assert _simulate(inputs / "new", "--no-frames") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: a file could not be written: {words}") and "Errno" not in err
    assert err.rstrip().endswith(f"; this command writes into --out {inputs / 'new'} and the cache "
                                 f"{default_cache_dir()}")  # the system named no file: where the command writes
    named = OSError(errno.ENOSPC, "No space left on device", str(inputs / ".new.tmp-ab_9x" / "events.txt"))
    monkeypatch.setattr(ecd, "write_ecd", lambda *a, **k: (_ for _ in ()).throw(named))
    assert _simulate(inputs / "new", "--no-frames") == 2
    assert capsys.readouterr().err == f"error: {inputs / 'new' / 'events.txt'}: no space left on the device (free " \
                                      "some, or write elsewhere)\n"
    assert cli._one_line(PermissionError(errno.EACCES, "Permission denied", "/o/.run.tmp-ab_12cd")) == \
        "/o/run: Permission denied"  # the temporary folder itself, as the last part of the name


# ---------------------------------------------------------------------------------------------- features-benchmark
def _event_frames_args(inputs: Path) -> list[str]:
    return ["features-benchmark", "--dataset", "events", "--event-frames", str(inputs / "frames.npy"), "--quiet",
            "--speed-shapes"]


@pytest.mark.parametrize("extra, n_images, per_image, speed_frames", [
    (["--fast"], 2, 1, 5),
    (["--fast", "--pairs-per-image", "3", "--n-images", "1", "--speed-frames", "7"], 1, 3, 7),  # explicit values win
    ([], None, 5, 20),
    (["--pairs-per-image", "2"], None, 2, 20),
])
def test_fast_never_overrides_explicit_values(inputs, monkeypatch, capsys, extra, n_images, per_image, speed_frames):
    seen = {}

    def capture(args):
        seen.update(vars(args))
        raise ValueError("stop here")

    monkeypatch.setattr(benchmark, "_benchmark_pairs", capture)
    assert cli.main([*_event_frames_args(inputs), "--detectors", "fast", *extra]) == 2
    assert (seen["n_images"], seen["pairs_per_image"], seen["speed_frames"]) == (n_images, per_image, speed_frames)


@pytest.mark.parametrize("keep_going", [False, True])
def test_a_failing_named_detector_fails_the_command(inputs, monkeypatch, capsys, keep_going):
    real_run = benchmark.run_benchmark

    def run(detector, *args, **kwargs):
        if detector == "orb":
            raise RuntimeError("orb broke")
        return real_run(detector, *args, **kwargs)

    monkeypatch.setattr(benchmark, "run_benchmark", run)
    out = inputs / "bench"
    argv = [*_event_frames_args(inputs), "--detectors", "fast", "orb", "--fast", "--out", str(out)]
    code = cli.main(argv + (["--keep-going"] if keep_going else []))
    captured = capsys.readouterr()
    if keep_going:
        assert code == 0 and "skipping orb (--keep-going): orb broke" in captured.err
        assert [row["detector"] for row in json.loads((out / "results.json").read_text())] == ["fast"]
    else:
        assert code == 1 and "error: detector orb failed: orb broke" in captured.err
        assert not out.exists()  # no results of a failed run


def test_benchmark_weights_named_by_the_option(inputs, capsys):
    # the issue's case, also as a direct call of the library's entry point
    assert benchmark.main_benchmark(["--detectors", "superpoint", "--weights", str(inputs / "garbage.pt")]) == 2
    assert "--weights" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------- course
def test_course_fast_flag_reaches_the_kernels(monkeypatch, tmp_path, capsys):
    calls = []
    monkeypatch.delenv("EVIO_FAST", raising=False)
    monkeypatch.setattr(course, "build_notebooks", lambda sources: [tmp_path / (s.stem + ".ipynb") for s in sources])
    monkeypatch.setattr(course, "execute_notebook", lambda path, fast=None: calls.append((path.name, fast)))
    assert cli.main(["course", "--only", "01", "--fast"]) == 0
    assert calls == [("01_pinhole_camera.ipynb", True)] and "fast mode" in capsys.readouterr().out
    assert "EVIO_FAST" not in os.environ  # the flag goes to the kernels, not into this process
    calls.clear()
    assert cli.main(["course", "--only", "01"]) == 0
    assert calls == [("01_pinhole_camera.ipynb", False)]
    monkeypatch.setenv("EVIO_FAST", "1")
    calls.clear()
    assert cli.main(["course", "--only", "01", "02"]) == 0
    assert calls == [("01_pinhole_camera.ipynb", True), ("02_epipolar_geometry.ipynb", True)]


# ---------------------------------------------------------------------------------------------- help texts
def _all_parsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _all_parsers(sub)


def test_every_option_has_help_text():
    parsers = list(_all_parsers(cli.build_parser()))
    assert len(parsers) == 12  # the top level and eleven commands
    missing = [f"{p.prog} {a.dest}" for p in parsers for a in p._actions
               if not isinstance(a, argparse._SubParsersAction) and not (a.help and a.help.strip())]
    assert missing == []


def test_help_texts_say_what_a_user_needs(capsys):
    parser = cli.build_parser()
    assert "`" not in parser.description and ":func:" not in parser.description  # prose, no reStructuredText markup
    assert "python -m evio_lib" not in parser.description.splitlines()[0]  # says what evio does, not how to type it
    assert cli.main(["course", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "build/notebooks" in text and "about 3 min" in text and "about 10 min" in text and "--fast" in text
    assert cli.main(["features-benchmark", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "default run" in text and "two hours on a 2-core CPU" in text and "--keep-going" in text and "--force" in text


# ---------------------------------------------------------------------------------------------- as a real process
def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(PROJECT_ROOT), os.environ.get("PYTHONPATH")])))
    return subprocess.run([sys.executable, "-m", "evio_lib", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.parametrize("args, message", [
    (["simulate", "boxes_like", "--out", "o", "--duration", "-1"], "error: --duration must be > 0; got -1"),
    (["features-benchmark", "--weights", "garbage.pt", "--detectors", "superpoint"],
     "error: --weights garbage.pt: not a readable SuperPoint checkpoint"),
])
def test_the_issue_cases_from_the_shell(tmp_path, args, message):
    (tmp_path / "garbage.pt").write_text("garbage\n")
    done = _run(*args, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.startswith(message) and len(done.stderr.strip().splitlines()) == 1
    assert "Traceback" not in done.stderr and "libpng" not in done.stderr


def test_simulate_from_the_shell_is_quiet_and_clean(tmp_path):
    done = _run("simulate", "boxes_like", "--out", "o", "--duration", "0.03", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # no libpng warning, no progress bar
    assert done.stdout.splitlines()[-1] == "wrote o" and len(done.stdout.splitlines()) == 2


# ---------------------------------------------------------------------------------------------- features-train
@pytest.mark.parametrize("fails", [False, True])
def test_train_force_replaces_a_run_only_when_training_returns(inputs, monkeypatch, capsys, fails):
    from evio_lib.features.training import train

    def run_chain(names, **kwargs):
        run_dir = inputs / "runs" / "magicpoint"
        assert not run_dir.exists()  # the old run is out of the way while the new one trains
        run_dir.mkdir()
        (run_dir / "last.pt").write_bytes(b"the new run")
        if fails:
            raise ValueError("bad config value")
        return []

    monkeypatch.setattr(train, "run_chain", run_chain)
    code = cli.main(["features-train", "magicpoint", "--out", str(inputs / "runs"), "--force", "--quiet"])
    expected = b"an earlier run" if fails else b"the new run"
    assert code == (2 if fails else 0)
    assert (inputs / "runs" / "magicpoint" / "last.pt").read_bytes() == expected
    assert sorted(p.name for p in (inputs / "runs").iterdir()) == ["magicpoint"]  # nothing set aside is left


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["table", "--help"], ["simulate", "--help"],
                                  ["course", "--help"], ["run", "--seed", "-1"], ["vio-sim", "--help"],
                                  ["vio-sim", "nowhere_like"], ["features-train", "--help"],
                                  ["features-train", "--steps", "0"], ["reconstruct-train", "--help"],
                                  ["features-benchmark", "--help"], ["features-benchmark", "--seed", "-2"],
                                  ["reconstruct", "--help"]])
def test_help_and_usage_errors_import_no_heavy_library(argv):
    """`--help` and a usage error build only the parser of the command named (issue 26: start-up under a second):
    torch, SciPy and OpenCV (seconds to import) stay unloaded. Counts modules, not seconds."""
    code = ("import contextlib, io, sys\n"
            "from evio_lib.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
            f"    status = main({argv!r})\n"
            "heavy = sorted(m for m in ('torch', 'scipy', 'cv2', 'matplotlib', 'skimage') if m in sys.modules)\n"
            "print(status, ','.join(heavy) or '-', len(sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=PROJECT_ROOT)
    status, heavy, count = done.stdout.split()
    assert int(status) in (0, 2) and heavy == "-", done.stdout + done.stderr
    assert int(count) < 250  # the standard library's argparse, pathlib, ..., NumPy (0.1 s) and evio_lib's CLI modules


def test_vio_sim_choices_are_the_librarys():
    """The vio-sim options module lists the presets and noise models without importing them: they must agree."""
    import argparse

    from evio_lib.msckf.experiment import NOISE_MODELS
    from evio_lib.msckf.experiment_options import add_vio_sim_arguments
    from evio_lib.sim.trajectory import PRESETS

    parser = argparse.ArgumentParser()
    add_vio_sim_arguments(parser)
    choices = {a.dest: tuple(a.choices) for a in parser._actions if a.choices}
    assert choices["preset"] == tuple(PRESETS) and choices["noise_model"] == tuple(NOISE_MODELS)
