"""Tests of evio_lib.features.training.train: configs, the three stage types, determinism, resume, chain log and CLI."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from evio_lib.features.network import SuperPointDetector, load_checkpoint, load_model
from evio_lib.features.training import train as tr

TINY = {"encoder_channels": [8, 8, 8, 8, 16, 16, 16, 16], "head_channels": 16, "descriptor_dim": 16}
SMALL = dict(model=TINY, image_size=(32, 48), batch_size=2, n_train_images=4, n_val_images=2, device="cpu",
             val_every=1000, checkpoint_every=1000, n_homographies=2)

THESIS_VARIANTS = ["magicpoint", "detector_round1", "detector_round2", "detdesc", "detdesc_lite", "detdesc_round1",
                   "detdesc_round2", "pretrained_detdesc_round2", "detdesc_round2_events",
                   "pretrained_detdesc_round2_events", "detector_round1_events"]


def tiny_magicpoint(tmp_path: Path, **changes) -> tr.TrainConfig:
    values = {"name": "tiny_mp", "stage": "magicpoint", **SMALL, "checkpoint_dir": str(tmp_path), "max_steps": 2}
    values.update(changes)
    return tr.load_config(values)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tests/features/conftest.py


@pytest.fixture
def label_cache(tmp_path, monkeypatch):
    """Keep the label cache out of the repository's data/cache."""
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


# ---------------------------------------------------------------------------------------------- configs
def test_every_shipped_config_loads_validates_and_chains():
    names = tr.available_configs()
    assert set(THESIS_VARIANTS) <= set(names)
    # magicpoint + 6 real-image variants x {scratch, pre-trained} x {COCO-like, Events}, + the distilled network
    assert len(names) == 26
    for name in names:
        cfg = tr.load_config(name)
        assert cfg.name == name and cfg.description
        assert cfg.total_steps >= 1 and cfg.image_size[0] % 8 == 0
        assert cfg.detector_only == (cfg.stage not in ("detdesc", "distill"))
        if cfg.stage == "distill":  # its teacher is shipped weights: nothing to train first
            assert tr.variant_dependencies(name) == [name] and cfg.event_frames is None
            continue
        if name.startswith("pretrained_"):
            assert cfg.init_from == cfg.labels_from == tr.load_config(name.removeprefix("pretrained_")).labels_from
        if name.endswith("_events"):
            assert cfg.event_frames is not None and cfg.labels_from in ("magicpoint",) + tuple(
                n for n in names if n.endswith("_events"))
        else:
            assert cfg.event_frames is None
        chain = tr.variant_dependencies(name)
        assert chain[0] == "magicpoint" and chain[-1] == name
        assert TINY == dict(tr.load_config(name, model=TINY).model)
    assert tr.variant_dependencies("pretrained_detdesc_round2") == ["magicpoint", "detdesc_round1",
                                                                   "pretrained_detdesc_round2"]
    assert tr.variant_dependencies("detdesc") == ["magicpoint", "detector_round1", "detector_round2", "detdesc"]
    # the thesis's own names: DetDescLite = one detector round, DetDesc (Round 2) = labels of DetDesc (Round 1)
    assert tr.load_config("detdesc_lite").labels_from == "detector_round1"
    assert tr.load_config("detdesc_round2").labels_from == "detdesc_round1"


def test_load_config_files_overrides_and_round_trip(tmp_path):
    cfg = tr.load_config("detdesc_round1", max_steps=7, batch_size=None, image_size=(64, 80))
    assert (cfg.max_steps, cfg.batch_size, cfg.image_size) == (7, 2, (64, 80))  # None overrides are ignored
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(cfg.to_dict()))
    assert tr.load_config(path) == cfg
    toml = tmp_path / "mine.toml"
    toml.write_text('name = "t"\nstage = "magicpoint"\nimage_size = [16, 24]\nmax_steps = 3\n')
    assert tr.load_config(toml).image_size == (16, 24)
    epochs = tr.load_config("magicpoint", max_steps=None, epochs=2, n_train_images=20, batch_size=8)
    assert epochs.steps_per_epoch == 2 and epochs.total_steps == 4
    assert tr.checkpoint_path("x.pt") == Path("x.pt")
    assert tr.checkpoint_path("magicpoint", tmp_path, "last") == tmp_path / "magicpoint" / "last.pt"


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"stage": "coco"}, "stage must be one of"),
        ({"image_size": (30, 40)}, "image_size must be"),
        ({"image_size": (8, 16)}, "image_size must be"),
        ({"batch_size": 0}, "batch_size must be an int >= 1"),
        ({"lr": 0.0}, "lr must be a finite number > 0"),
        ({"lr": float("nan")}, "lr must be a finite number"),
        ({"max_steps": None, "epochs": None}, "epochs and max_steps must not both be null"),
        ({"model": "huge"}, "model must be one of"),
        ({"model": {"encoder_channels": [8, 8]}}, "encoder_channels must be 8 positive integers"),
        ({"device": "tpu"}, "device must be"),
        ({"n_train_images": 1, "batch_size": 2}, "n_train_images must be >= batch_size"),
        ({"event_frames": "frames.npy"}, "event_frames must be null for stage 'magicpoint'"),
        ({"stage": "detector"}, "labels_from must name the variant"),
        ({"stage": "detector", "labels_from": "magicpoint", "event_frames": {"duration": 2}}, "event_frames must be"),
        ({"stage": "detector", "labels_from": "magicpoint",
          "event_frames": {"simulate": "aerial_like", "reconstructor": "e2vid_pretrained"}}, "event_frames reconstructor"),
        ({"stage": "detector", "labels_from": "magicpoint",
          "event_frames": {"simulate": "aerial_like", "window_fraction": 0}}, "event_frames window_fraction must be"),
        ({"name": "a b"}, "name must be"),
        ({"augment": "yes"}, "augment must be true or false"),
        ({"pair_homography": {"fill_veiw": True}}, r"pair_homography has unknown field\(s\) \['fill_veiw'\]"),
        ({"pair_homography": {"patch_ratio": 2.0}}, "pair_homography .* patch_ratio must be"),
        ({"pair_homography": [0.5]}, "pair_homography must be null or a dict"),
        ({"select_on": "precision"}, "select_on must be one of"),
        ({"snapshot_every": 0}, "snapshot_every must be an int >= 1"),
        ({"max_minutes": 0}, "max_minutes must be a finite number > 0"),
        ({"lambda_reprojection": -1.0}, "lambda_reprojection must be a finite number >= 0"),
        ({"lambda_reprojection": 1.0}, "lambda_reprojection must be 0 for stage 'magicpoint'"),
        ({"event_fraction": 1.5, "stage": "detector", "labels_from": "magicpoint"}, "event_fraction must be"),
    ],
)
def test_bad_config_values_raise(changes, match):
    values = {"name": "bad", "stage": "magicpoint", **changes}
    with pytest.raises(ValueError, match=match):
        tr.load_config(values)


def test_bad_config_names_keys_and_files(tmp_path):
    with pytest.raises(ValueError, match="neither a config file nor a shipped variant"):
        tr.load_config("detdesc_round9")
    with pytest.raises(ValueError, match=r"unknown keys \['learning_rate'\]"):
        tr.load_config("magicpoint", learning_rate=0.1)
    with pytest.raises(ValueError, match="missing the required keys"):
        tr.load_config({"stage": "magicpoint"})
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        tr.load_config(broken)
    with pytest.raises(ValueError, match="does not exist"):
        tr.load_config(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="which must be"):
        tr.checkpoint_path("magicpoint", which="first")


# ---------------------------------------------------------------------------------------------- training
def test_loss_decreases_on_a_fixed_batch(tmp_path):
    # 4 un-augmented synthetic images = one fixed batch: 30 Adam steps must fit it (loss at least halves)
    cfg = tiny_magicpoint(tmp_path, batch_size=4, augment=False, max_steps=30, lr=1e-2, val_every=30)
    result = tr.train(cfg, progress=False)
    first, last = np.mean(result.train_loss[:3]), np.mean(result.train_loss[-3:])
    assert len(result.train_loss) == 30 and result.steps == 30
    assert last < 0.5 * first, (first, last)
    assert result.best_path is not None and result.best_step == 30
    assert result.validation[-1]["step"] == 30 and 0.0 <= result.validation[-1]["recall_1px"] <= 1.0
    assert result.validation[-1]["precision_1px"] >= result.validation[-1]["precision"]  # 1 px tolerance is looser
    history = json.loads((cfg.run_dir / "history.json").read_text())
    assert history["train_loss"] == pytest.approx(result.train_loss)



def test_snapshots_and_selection_on_descriptor_retrieval(tmp_path):
    result = tr.train(tiny_magicpoint(tmp_path, max_steps=4, snapshot_every=2, val_every=2), progress=False)
    snapshots = sorted(p.name for p in result.run_dir.glob("step_*.pt"))
    assert snapshots == ["step_0000002.pt", "step_0000004.pt"]
    last = load_checkpoint(result.run_dir / "step_0000004.pt")
    for key, value in load_checkpoint(result.last_path)["state_dict"].items():
        assert torch.equal(value, last["state_dict"][key]), key
    # the selection rule: higher retrieval wins under select_on="desc_nn_accuracy", lower loss under "loss"
    worse_loss_better_desc = {"loss": 2.0, "desc_nn_accuracy": 0.5, "precision": 0.1, "recall": 0.1}
    best = {"loss": 1.0, "desc_nn_accuracy": 0.3, "precision": 0.1, "recall": 0.1}
    assert tr._is_better(worse_loss_better_desc, best, "desc_nn_accuracy")
    assert not tr._is_better(worse_loss_better_desc, best, "loss")
    detector_only = {"loss": 0.5, "precision": 0.1, "recall": 0.1}  # no descriptor: falls back to the loss
    assert tr._is_better(detector_only, {"loss": 0.6, "precision": 0.1, "recall": 0.1}, "desc_nn_accuracy")

def test_training_is_deterministic_and_resume_is_bit_identical(tmp_path):
    # 3 steps per epoch with augmentation: the interrupted run crosses an epoch boundary after resuming
    common = dict(n_train_images=6, batch_size=2, augment=True, val_every=2, checkpoint_every=1)
    full = tr.train(tiny_magicpoint(tmp_path / "a", max_steps=5, **common), progress=False)
    again = tr.train(tiny_magicpoint(tmp_path / "b", max_steps=5, **common), progress=False)
    part = tr.train(tiny_magicpoint(tmp_path / "c", max_steps=2, **common), progress=False)
    assert part.steps == 2
    resumed = tr.train(tiny_magicpoint(tmp_path / "c", max_steps=5, **common), progress=False, resume=True)
    assert resumed.resumed_from == 2 and resumed.steps == 5
    assert full.train_loss == again.train_loss == resumed.train_loss  # exact floats
    a = load_checkpoint(full.last_path)
    for other in (load_checkpoint(again.last_path), load_checkpoint(resumed.last_path)):
        assert a["state_dict"].keys() == other["state_dict"].keys()
        for key, value in a["state_dict"].items():
            assert torch.equal(value, other["state_dict"][key]), key
        for pid, state in a["optimizer"]["state"].items():
            for name, value in state.items():
                assert torch.equal(value, other["optimizer"]["state"][pid][name]), (pid, name)
    # resuming a finished run trains nothing; a changed config refuses to resume
    done = tr.train(tiny_magicpoint(tmp_path / "c", max_steps=5, **common), progress=False, resume=True)
    assert done.resumed_from == 5 and done.train_loss == full.train_loss
    with pytest.raises(ValueError, match=r"cannot resume .* differs in \['lr'\]"):
        tr.train(tiny_magicpoint(tmp_path / "c", max_steps=6, lr=0.5, **common), progress=False, resume=True)


def test_each_stage_type_runs_two_steps(tmp_path, label_cache, capsys):
    mp = tr.train(tiny_magicpoint(tmp_path / "runs", name="mp"), progress=False)
    assert mp.best_path.is_file() and load_model(mp.best_path).descriptor_dim == 0
    real = dict(SMALL, checkpoint_dir=str(tmp_path / "runs"), max_steps=2, labels_from="mp")
    # detector round: labels from the tiny MagicPoint by homographic adaptation (cached under EVIO_CACHE_DIR)
    det_cfg = tr.load_config({"name": "det", "stage": "detector", **real})
    labels = tr.export_labels(det_cfg, progress=False)
    assert len(labels["train"]) == 4 and len(labels["val"]) == 2
    assert all(k.ndim == 2 and k.shape[1] == 2 for k in labels["train"])
    assert list(label_cache.glob("labels_mp-*_train_32x48.npz"))  # named after the model and its hash
    det = tr.train(det_cfg, progress=False)
    assert det.steps == 2 and np.isfinite(det.train_loss).all()
    # detector + descriptor on warped pairs, "pre-trained" from the detector-only MagicPoint
    dd_cfg = tr.load_config({"name": "dd", "stage": "detdesc", "init_from": "mp", "snapshot_every": 1,
                             "pair_homography": {"fill_view": True, "patch_ratio": 0.8}, **real})
    train_data, val_data = tr._datasets(dd_cfg, progress=False)
    assert train_data.pair_homographic == val_data.pair_homographic == dd_cfg.pair_homographic()
    assert train_data.pair_homographic.fill_view and train_data.pair_homographic.patch_ratio == 0.8
    model = tr.build_training_model(dd_cfg)
    mp_state = load_checkpoint(mp.best_path)["state_dict"]
    assert torch.equal(model.state_dict()["encoder.0.conv.weight"], mp_state["encoder.0.conv.weight"])
    dd = tr.train(dd_cfg, progress=False)
    assert dd.steps == 2 and set(dd.validation[-1]) >= {"loss", "detector", "descriptor", "precision", "recall",
                                                        "desc_positive_dot", "desc_negative_dot", "desc_nn_accuracy",
                                                        "reprojection"}
    assert 0.0 <= dd.validation[-1]["reprojection"] <= 3.0  # pixels, capped at d_max
    # the same pairs with the reprojection term in the loss: its weight changes the total, not the term
    rp_cfg = tr.load_config({"name": "rp", "stage": "detdesc", "init_from": "mp", "lambda_reprojection": 2.0, **real})
    batch = next(iter(torch.utils.data.DataLoader(train_data, batch_size=2)))
    model = tr.build_training_model(rp_cfg)
    with_term, parts, _ = tr._batch_loss(model, batch, rp_cfg, torch.Generator().manual_seed(0), torch.device("cpu"))
    without, plain_parts, _ = tr._batch_loss(model, batch, dd_cfg, torch.Generator().manual_seed(0),
                                             torch.device("cpu"))
    assert "reprojection" not in plain_parts  # lambda_r = 0: training computes no extra term
    assert float(parts["reprojection"].detach()) > 0.0  # an untrained network's points do not follow the warp
    assert torch.isclose(with_term, without + 2.0 * parts["reprojection"])
    with_term.backward()  # the term's gradient reaches the network
    assert all(torch.isfinite(p.grad).all() for p in model.parameters() if p.grad is not None)
    assert 0.0 <= dd.validation[-1]["desc_nn_accuracy"] <= 1.0
    # choosing among the snapshots on the validation benchmark (one val image, one pair per split)
    report = tr.benchmark_snapshots(dd.run_dir, n_images=1, pairs_per_image=1, progress=False)
    assert [r["file"] for r in report["rows"]] == ["step_0000001.pt", "step_0000002.pt", "best.pt"]
    assert report["n_pairs"] == {"viewpoint": 1, "illumination": 1}
    assert all(0.0 <= r["score"] <= 1.0 for r in report["rows"])
    assert (dd.run_dir / "best_benchmark.pt").read_bytes() == (dd.run_dir / report["best"]).read_bytes()
    assert json.loads((dd.run_dir / "snapshot_benchmark.json").read_text())["best"] == report["best"]
    again = tr.benchmark_snapshots(dd.run_dir, n_images=1, pairs_per_image=1, progress=True)  # all known: no scoring
    assert again["rows"] == report["rows"] and again["n_pairs"] == report["n_pairs"]
    assert capsys.readouterr().out == ""  # nothing was benchmarked again
    with pytest.raises(FileNotFoundError, match=r"no step_\*\.pt snapshots"):
        tr.benchmark_snapshots(tmp_path / "empty_run_folder_that_is_not_there")
    detector = SuperPointDetector(weights=dd.best_path, inference="fused", max_keypoints=20)
    features = detector.detect_and_describe(np.random.default_rng(0).random((40, 56)).astype(np.float32))
    assert features.descriptors.shape[1] == 16 and len(features) <= 20


def test_init_and_labels_errors(tmp_path, label_cache):
    with pytest.raises(FileNotFoundError, match="train variant 'nothing' first"):
        tr.build_training_model(tiny_magicpoint(tmp_path, init_from="nothing"))
    cfg = tr.load_config({"name": "d", "stage": "detector", "labels_from": "nothing", **SMALL,
                          "checkpoint_dir": str(tmp_path)})
    with pytest.raises(FileNotFoundError, match="labels_from checkpoint .* not found"):
        tr.export_labels(cfg, progress=False)
    with pytest.raises(ValueError, match="labels_from must be set"):
        tr.export_labels(tiny_magicpoint(tmp_path), progress=False)
    other = tr.train(tiny_magicpoint(tmp_path, name="narrowish", model=dict(TINY, head_channels=8), max_steps=1),
                     progress=False)
    with pytest.raises(ValueError, match="does not match this variant"):
        tr.build_training_model(tiny_magicpoint(tmp_path, init_from=str(other.best_path)))


def test_event_frames_from_a_file(tmp_path):
    stack = np.random.default_rng(3).integers(0, 40, (30, 24, 32)).astype(np.float32)  # event counts
    np.save(tmp_path / "frames.npy", stack)
    frames = tr.load_event_frames(str(tmp_path / "frames.npy"))
    assert len(frames.frames) == 30 and frames.frames[0].dtype == np.float32
    np.testing.assert_allclose(frames.frames[0], stack[0] / stack.max(), atol=1e-6)  # scaled to [0, 1]
    assert len(frames.frames_for("train")) > len(frames.frames_for("val"))
    bad = tmp_path / "flat.npy"
    np.save(bad, np.zeros((4, 5)))
    with pytest.raises(ValueError, match=r"must hold an \(N, H, W\) stack"):
        tr.load_event_frames(str(bad))
    with pytest.raises(ValueError, match="is not a file"):
        tr.load_event_frames(str(tmp_path / "none.npy"))


def test_cli_runs_a_variant_and_logs_the_command(tmp_path, capsys):
    out = tmp_path / "runs"
    argv = ["magicpoint", "--steps", "2", "--batch-size", "2", "--image-size", "32x48", "--device", "cpu",
            "--out", str(out), "--quiet", "--set", f"model={json.dumps(TINY)}", "--set", "n_val_images=2",
            "--set", "val_every=1000", "--threads", "2"]
    assert tr.main_train(argv) == 0
    assert torch.get_num_threads() == 1  # --threads applies during training only
    log = json.loads((out / "chain_log.json").read_text())
    assert [e["variant"] for e in log] == ["magicpoint"]
    assert log[0]["command"].startswith("python -m evio_lib features-train magicpoint --steps 2")
    assert log[0]["config"]["model"] == TINY and log[0]["steps"] == 2
    assert (out / "magicpoint" / "best.pt").is_file() and (out / "magicpoint" / "config.json").is_file()
    assert tr.main_train(argv + ["--resume"]) == 0  # finished: nothing more to train
    assert json.loads((out / "chain_log.json").read_text())[-1]["resumed_from"] == 2
    assert tr.main_train(["--list"]) == 0 and "pretrained_detdesc_round2" in capsys.readouterr().out
    assert tr.main_train(["nope", "--out", str(out), "--quiet"]) == 2
    assert "neither a config file" in capsys.readouterr().err
    assert tr.main_train(["magicpoint", "--out", str(out), "--select-snapshots", "--quiet"]) == 2  # none kept
    assert "no step_*.pt" in capsys.readouterr().err
    with pytest.raises(ValueError, match="names must be a non-empty list"):
        tr.run_chain([])


def test_sparse_labels_warn_and_dense_labels_do_not(capsys):
    config = tr.load_config({"name": "d", "stage": "detector", "labels_from": "mp", **SMALL})  # 32 x 48 images
    pixels = config.image_size[0] * config.image_size[1]
    few = [np.zeros((0, 2)), np.zeros((1, 2)), np.zeros((1, 2))]  # median 1 point: 0.65 per 1000 px
    with pytest.warns(RuntimeWarning, match=r"sparse: median 1 points per 32x48 image .* lower label_threshold"):
        tr._check_label_density(few, config, "train", verbose=True)
    assert "0.7 points per image (median 1, min 0, max 1)" in capsys.readouterr().err
    enough = [np.zeros((int(np.ceil(tr.MIN_LABEL_DENSITY * pixels / 1000)), 2))] * 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr._check_label_density(enough, config, "train", verbose=False)


def test_time_budget_stops_saves_and_resumes_to_the_same_run(tmp_path):
    common = dict(n_train_images=6, batch_size=2, augment=True, val_every=1000, checkpoint_every=1000)
    full = tr.train(tiny_magicpoint(tmp_path / "a", max_steps=4, **common), progress=False)
    # a budget spent by the first step: the call stops there, validates and writes last.pt
    cut = tr.train(tiny_magicpoint(tmp_path / "b", max_steps=4, max_minutes=1e-9, **common), progress=False)
    assert cut.steps == 1 and [v["step"] for v in cut.validation] == [1]
    assert load_checkpoint(cut.last_path)["step"] == 1
    resumed = tr.train(tiny_magicpoint(tmp_path / "b", max_steps=4, **common), progress=False, resume=True)
    assert resumed.resumed_from == 1 and resumed.steps == 4
    assert resumed.train_loss == full.train_loss  # the cut changes nothing but where the call stopped
    assert "--max-minutes 0.5" in tr._command("magicpoint", {"max_minutes": 0.5}, resume=True)


def test_resume_accepts_a_checkpoint_written_before_a_config_field_existed(tmp_path):
    config = tiny_magicpoint(tmp_path, max_steps=1, checkpoint_every=1)
    first = tr.train(config, progress=False)
    checkpoint = torch.load(first.last_path, map_location="cpu", weights_only=False)
    del checkpoint["metadata"]["config"]["render_zoom"]  # as written by an older evio_lib
    torch.save(checkpoint, first.last_path)
    resumed = tr.train(tiny_magicpoint(tmp_path, max_steps=2), progress=False, resume=True)
    assert resumed.resumed_from == 1 and resumed.steps == 2
    with pytest.raises(ValueError, match=r"differs in \['render_zoom'\]"):  # a real change still refuses
        tr.train(tiny_magicpoint(tmp_path, max_steps=3, render_zoom=2.0), progress=False, resume=True)


def test_label_max_keypoints_keeps_the_strongest_labels(tmp_path, label_cache, monkeypatch):
    import evio_lib.features.training.datasets as datasets

    tr.train(tiny_magicpoint(tmp_path, name="mp", max_steps=1), progress=False)
    strongest_first = [np.arange(20, dtype=np.float32).reshape(10, 2), np.zeros((3, 2), np.float32)]
    monkeypatch.setattr(datasets, "adaptation_labels", lambda images, *a, **k: strongest_first[: len(images)])
    monkeypatch.setattr(tr, "training_images", lambda config, split, progress=False: [None, None])
    common = {"name": "d", "stage": "detector", "labels_from": "mp", **SMALL, "checkpoint_dir": str(tmp_path)}
    capped = tr.export_labels(tr.load_config({**common, "label_max_keypoints": 4}), progress=False)
    assert [len(k) for k in capped["train"]] == [4, 3]
    assert np.array_equal(capped["train"][0], strongest_first[0][:4])
    full = tr.export_labels(tr.load_config(common), progress=False)
    assert [len(k) for k in full["train"]] == [10, 3]


def test_event_frames_from_a_named_reconstructor(monkeypatch):
    """{"simulate": ..., "reconstructor": NAME, "window_fraction": n}: one reconstructed frame per N_e = n H W events."""
    from evio_lib.events.array import make_events
    from evio_lib.events.reconstruct import create_reconstructor, reconstruct_windows
    from evio_lib.events.representations import count_windows
    from evio_lib.geometry.camera import PinholeRadtan
    from evio_lib.sequence import Sequence
    from evio_lib.sim import presets

    rng = np.random.default_rng(0)
    n = 3000
    events = make_events(np.sort(rng.uniform(0, 1, n)), rng.integers(0, 32, n), rng.integers(0, 24, n),
                         rng.choice([-1, 1], n))
    camera = PinholeRadtan(fx=30.0, fy=30.0, cx=16.0, cy=12.0, width=32, height=24)
    monkeypatch.setattr(presets, "simulate_sequence",
                        lambda config, **kw: Sequence(name="tiny", camera=camera, events=events))
    frames = tr.load_event_frames({"simulate": "aerial_like", "duration": 1.0, "seed": 7, "reconstructor": "high_pass",
                                   "window_fraction": 1.0})
    expected, _ = reconstruct_windows(create_reconstructor("high_pass", 32, 24), events, count_windows(events, 768))
    assert len(frames.frames) == len(expected) == n // 768
    np.testing.assert_allclose(np.stack(frames.frames), expected)
