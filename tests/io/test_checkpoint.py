"""Tests of evio_lib.io.checkpoint: every checkpoint reader refuses a file it cannot use with one line naming it.

Bad files: corrupt bytes, an empty file, a truncated real checkpoint, a byte-flipped real checkpoint, a plain pickle,
a torch file holding a tensor, a dict of other keys, a FireNet checkpoint as SuperPoint weights and vice versa, a
state dict of another width (SuperPoint and FireNet), a missing file and a folder. Each goes through the library
(read_checkpoint, load_model / create_detector, create_reconstructor, reconstruct-train --init-from / --resume) and
the bad ones through the command lines of run, table, reconstruct and reconstruct-train.
"""
from __future__ import annotations

import pickle
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from evio_lib.features.network import WEIGHTS_DIR, build_model, load_model
from evio_lib.io.checkpoint import CheckpointError, CheckpointNotFoundError, read_checkpoint

SUPERPOINT = WEIGHTS_DIR / "pretrained_detdesc_round2_cpu.pt"
FIRENET = WEIGHTS_DIR / "reconstruction_firenet.pt"


def _make(folder: Path, name: str) -> Path:
    """Write the bad checkpoint ``name`` into ``folder`` and return its path."""
    path = folder / f"{name}.pt"
    if name == "corrupt":
        path.write_bytes(b"this is not a checkpoint at all\n" * 4)
    elif name == "empty":
        path.write_bytes(b"")
    elif name == "truncated":
        data = FIRENET.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif name == "flipped":  # a whole archive with damaged weights: only the zip's CRC check sees it
        data = bytearray(FIRENET.read_bytes())
        middle = len(data) // 2
        data[middle:middle + 64] = bytes(64)
        path.write_bytes(bytes(data))
    elif name == "pickle":
        path.write_bytes(pickle.dumps({"state_dict": {"w": [1.0, 2.0]}}))
    elif name == "code":  # a whole torch archive whose pickle would call a function: refused unread
        torch.save({"state_dict": _RunsCode()}, path)
    elif name == "tensor":
        torch.save(torch.zeros(3), path)
    elif name == "other_dict":
        torch.save({"weights": torch.zeros(3)}, path)
    elif name == "superpoint_wide":  # model_config says narrow, the tensors are of the full width
        torch.save({"format": "evio-superpoint-1", "model_config": build_model("narrow").config,
                    "state_dict": build_model("full").state_dict(), "metadata": {}}, path)
    elif name == "firenet_wide":  # the settings say the default FireNet, the tensors are 8 channels wide
        from evio_lib.events.reconstruction.nets import build_network

        ckpt = torch.load(FIRENET, weights_only=True)
        ckpt["state_dict"] = build_network("firenet", 5, channels=8).state_dict()
        torch.save(ckpt, path)
    elif name == "superpoint":  # a real SuperPoint checkpoint (for the reconstructor readers)
        shutil.copy(SUPERPOINT, path)
    elif name == "firenet":  # a real FireNet checkpoint (for the SuperPoint readers)
        shutil.copy(FIRENET, path)
    elif name == "folder":
        path.mkdir()
    elif name != "missing":
        raise AssertionError(name)
    return path


class _RunsCode:
    """Unpickled, calls print (a harmless stand-in for os.system): torch's weights_only loader must refuse it."""

    def __reduce__(self):
        return (print, ("this must never be printed",))


# (bad file, what the message must say) for the SuperPoint readers
SUPERPOINT_CASES = [
    ("corrupt", r"not a readable SuperPoint checkpoint: not a torch checkpoint file"),
    ("empty", r"the file is empty"),
    ("truncated", r"not a readable SuperPoint checkpoint: a truncated or damaged torch archive"),
    ("flipped", r"a damaged torch archive \(member .* fails its CRC check\)"),
    ("pickle", r"a plain Python pickle, not a file written by torch.save"),
    ("code", r"a torch archive holding Python objects other than tensors.*refused unread because loading them could "
             r"run code"),
    ("tensor", r"holds a Tensor, not a checkpoint dict"),
    ("other_dict", r"not a SuperPoint checkpoint: lacks \['model_config', 'state_dict'\]"),
    ("firenet", r"is a reconstructor checkpoint \(written by reconstruct-train\), not a SuperPoint checkpoint"),
    ("superpoint_wide", r"its state_dict does not match its model_config \(RuntimeError: size mismatch"),
    ("missing", r"file not found"),
    ("folder", r"not a file|file not found"),
]
# the same for the reconstructor readers
RECONSTRUCTOR_CASES = [
    ("corrupt", r"not a readable reconstructor checkpoint: not a torch checkpoint file"),
    ("empty", r"the file is empty"),
    ("truncated", r"not a readable reconstructor checkpoint: a truncated or damaged torch archive"),
    ("flipped", r"a damaged torch archive \(member .* fails its CRC check\)"),
    ("pickle", r"a plain Python pickle"),
    ("code", r"refused unread because loading them could run code"),
    ("tensor", r"holds a Tensor, not a checkpoint dict"),
    ("other_dict", r"has no 'format' entry"),
    ("superpoint", r"is a SuperPoint checkpoint \(written by features-train or save_checkpoint\), not a reconstructor"),
    ("firenet_wide", r"its state_dict does not fit the firenet network its settings describe \(RuntimeError: "),
    ("missing", r"file not found"),
    ("folder", r"not a file"),
]



@pytest.mark.parametrize("name, message", SUPERPOINT_CASES)
def test_superpoint_readers_refuse(tmp_path, name, message):
    path = _make(tmp_path, name)
    before = path.read_bytes() if path.is_file() else None
    for load in (load_model, lambda p: __import__("evio_lib.features", fromlist=["create_detector"])
                 .create_detector("superpoint", weights=p, inference="eager")):
        with pytest.raises(CheckpointError, match=message) as info:
            load(path)
        assert "\n" not in str(info.value) and str(path) in str(info.value)
    if name not in ("superpoint_wide",):  # read_checkpoint alone does not build the network
        with pytest.raises(CheckpointError, match=message):
            read_checkpoint(path, "superpoint")
    if name in ("missing", "folder"):
        with pytest.raises(FileNotFoundError):  # also a FileNotFoundError, as before
            read_checkpoint(path, "superpoint")
    assert (path.read_bytes() if path.is_file() else None) == before  # nothing was changed


@pytest.mark.parametrize("name, message", RECONSTRUCTOR_CASES)
def test_reconstructor_readers_refuse(tmp_path, name, message):
    from evio_lib.events.reconstruct import create_reconstructor

    path = _make(tmp_path, name)
    with pytest.raises(CheckpointError, match=message) as info:
        create_reconstructor("learned", 32, 24, checkpoint=path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_good_checkpoints_still_load(tmp_path):
    assert read_checkpoint(SUPERPOINT, "superpoint")["format"] == "evio-superpoint-1"
    assert read_checkpoint(FIRENET, "reconstructor")["architecture"] == "firenet"
    legacy = tmp_path / "legacy.pt"  # written before the format tag existed: still a SuperPoint checkpoint
    torch.save({"model_config": build_model("narrow").config, "state_dict": build_model("narrow").state_dict()},
               legacy)
    assert load_model(legacy).config == build_model("narrow").config
    with pytest.raises(ValueError, match="kind must be one of"):
        read_checkpoint(SUPERPOINT, "magic")
    assert issubclass(CheckpointNotFoundError, FileNotFoundError) and issubclass(CheckpointError, ValueError)


@pytest.fixture()
def tiny_train(tmp_path):
    """A reconstruct-train config small enough to fail or start in a second."""
    from evio_lib.events.reconstruction.data import ReconstructionDataConfig
    from evio_lib.events.reconstruction.training import ReconstructionTrainConfig

    data = ReconstructionDataConfig(height=32, width=32, duration=0.3, windows=3)
    return lambda **kw: ReconstructionTrainConfig(data=data, n_train=2, n_val=1, batch_size=1, crop=24, steps=1, **kw)


@pytest.mark.parametrize("name", ["corrupt", "empty", "truncated", "pickle", "superpoint", "firenet_wide"])
def test_reconstruct_train_init_from_and_resume_refuse(tmp_path, tiny_train, name):
    from evio_lib.events.reconstruction.training import train_reconstructor

    path = _make(tmp_path, name)
    with pytest.raises(ValueError, match=r"^init_from .*" + str(path.name)) as info:
        train_reconstructor(tiny_train(init_from=str(path)), tmp_path / "run", progress=False,
                            data={}, val_data={})
    assert "\n" not in str(info.value)
    run = tmp_path / "resumed"
    run.mkdir()
    shutil.copy(path, run / "last.pt")
    with pytest.raises(ValueError, match=r"^--resume: .*last.pt") as info:
        train_reconstructor(tiny_train(), run, resume=True, progress=False, data={}, val_data={})
    assert "\n" not in str(info.value)


def _cli(argv, capsys) -> str:
    from evio_lib.cli import main

    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    return lines[0]


@pytest.fixture()
def private_cache(tmp_path, monkeypatch):
    """No command line test may touch the project's cache."""
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))


@pytest.mark.parametrize("name, message", [c for c in SUPERPOINT_CASES if c[0] not in ("missing", "folder")])
def test_run_and_table_command_lines_refuse(tmp_path, capsys, private_cache, name, message):
    path = _make(tmp_path, name)
    line = _cli(["table", "--fast", "--presets", "boxes_like", "--rows", "cnn_events_trained", "--events-cnn", path],
                capsys)
    assert line.startswith(f"error: --events-cnn {path}: ") and re.search(message, line), line
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").rglob("*.npz"))  # no run started
    line = _cli(["run", "boxes_like", "--duration", "1", "--features", "superpoint", "--weights", path, "--quiet"],
                capsys)
    assert str(path) in line and re.search(message, line), line


@pytest.fixture()
def ecd_folder(tmp_path):
    from evio_lib.events.array import make_events

    rng = np.random.default_rng(0)
    n = 2000
    ev = make_events(np.sort(rng.uniform(0, 1, n)), rng.integers(0, 32, n), rng.integers(0, 24, n),
                     rng.choice([-1, 1], n))
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "events.txt").write_text("".join(f"{t:.9f} {x} {y} {1 if p > 0 else 0}\n"
                                               for t, x, y, p in zip(ev["t"], ev["x"], ev["y"], ev["p"])))
    return folder


@pytest.mark.parametrize("name, message", [c for c in RECONSTRUCTOR_CASES if c[0] not in ("missing", "folder")])
def test_reconstruct_command_lines_refuse(tmp_path, capsys, ecd_folder, name, message):
    path = _make(tmp_path, name)
    line = _cli(["reconstruct", ecd_folder, "--out", tmp_path / "frames", "--method", path, "--sensor-size", 32, 24,
                 "--quiet"], capsys)
    assert str(path) in line and re.search(message, line), line
    assert not (tmp_path / "frames").exists()
    line = _cli(["reconstruct-train", "--out", tmp_path / "run", "--init-from", path, "--steps", 1, "--quiet"], capsys)
    assert line.startswith("error: init_from ") and str(path) in line, line


def test_a_table_row_whose_worker_fails_is_that_rows_error(monkeypatch):
    """A failing (preset, row, seed) job records its one-line error; the table goes on."""
    import evio_lib.pipeline.dataset as dataset
    import evio_lib.pipeline.run as run
    from evio_lib.pipeline.table import TableRow, aggregate, table_job

    monkeypatch.setattr(dataset, "load_dataset", lambda *a, **k: None)
    bad = CheckpointError("/x/bad.pt: the file is empty; expected a SuperPoint checkpoint")
    for error, expected in ((bad, str(bad)), (RuntimeError("boom\nmore"), "RuntimeError: boom"),
                            (OSError("disk gone"), "disk gone")):
        def failing(*a, error=error, **k):
            raise error
        monkeypatch.setattr(run, "run_pipeline", failing)
        record = table_job("boxes_like", 1.0, 0, TableRow("sift_aps", "SIFT", (("features", "sift"),)))
        assert record["error"] == expected
        assert aggregate([record])[0]["failed"] == 1
