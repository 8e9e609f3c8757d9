"""Tests of the reconstructor training: SSIM against scikit-image, the homography warp, learning, resume."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from skimage.metrics import structural_similarity

from evio_lib.events.reconstruct import create_reconstructor
from evio_lib.events.reconstruction.data import ReconstructionDataConfig, reconstruction_dataset
from evio_lib.events.reconstruction.evaluation import normalize_for_metrics
from evio_lib.events.reconstruction.training import (ReconstructionTrainConfig, _gaussian_blur_torch, learning_rate,
                                                  main_reconstruct_train, sequence_loss, ssim_torch, stretch_torch,
                                                  temporal_consistency_loss, train_reconstructor, warm_state,
                                                  warp_with_flow, warp_with_homography)

DATA = ReconstructionDataConfig(height=32, width=32, duration=0.3, windows=3)


def test_ssim_matches_scikit_image():
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 1, (40, 50)).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1).astype(np.float32)
    ours = float(ssim_torch(torch.from_numpy(a)[None, None], torch.from_numpy(b)[None, None]))
    ref = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0)
    assert abs(ours - ref) < 1e-4


def test_warp_with_a_translation_shifts_the_image():
    image = torch.arange(48, dtype=torch.float32).reshape(1, 1, 6, 8)
    H = torch.tensor([[[1.0, 0.0, 2.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]]])  # current (x, y) -> previous (x+2, y+1)
    out = warp_with_homography(image, H)
    torch.testing.assert_close(out[0, 0, :5, :6], image[0, 0, 1:, 2:])
    assert float(out[0, 0, -1, -1]) == 0.0  # from outside the previous view


@pytest.fixture(scope="module")
def tiny_data():
    return (reconstruction_dataset("train", 6, seed=0, config=DATA, cache=False),
            reconstruction_dataset("val", 2, seed=0, config=DATA, cache=False))


def test_training_lowers_the_loss_and_resume_is_exact(tmp_path, tiny_data):
    data, val = tiny_data
    config = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=30,
                                       validate_every=30, lr=3e-3)
    first = train_reconstructor(config, tmp_path / "a", data=data, val_data=val, progress=False)
    history = first["last"]
    assert first["steps"] == 30
    untrained = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=1,
                                          validate_every=1, lr=1e-9)
    baseline = train_reconstructor(untrained, tmp_path / "u", data=data, val_data=val, progress=False)
    assert history["val_loss"] < baseline["last"]["val_loss"]
    # 12 steps in one go == 6 steps, then --resume to 12
    whole = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=12, validate_every=6)
    train_reconstructor(whole, tmp_path / "w", data=data, val_data=val, progress=False)
    half = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=6, validate_every=6)
    train_reconstructor(half, tmp_path / "r", data=data, val_data=val, progress=False)
    train_reconstructor(whole, tmp_path / "r", resume=True, data=data, val_data=val, progress=False)
    a = torch.load(tmp_path / "w" / "last.pt", weights_only=True)["state_dict"]
    b = torch.load(tmp_path / "r" / "last.pt", weights_only=True)["state_dict"]
    for key in a:
        torch.testing.assert_close(a[key], b[key])
    # the checkpoint loads through the one-call API
    rec = create_reconstructor("learned", 32, 32, checkpoint=tmp_path / "w" / "best.pt", precision="float32")
    assert rec.training_steps in (6, 12)


def test_command_line_refuses_a_used_folder_and_bad_settings(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "keep.txt").write_text("mine")
    with pytest.raises(ValueError, match="not empty"):
        main_reconstruct_train(["--out", str(tmp_path / "run")])
    with pytest.raises(ValueError, match="unknown reconstruction training settings"):
        main_reconstruct_train(["--out", str(tmp_path / "new"), "--set", "learning_rate=0.1"])
    with pytest.raises(ValueError, match="--seed"):
        main_reconstruct_train(["--out", str(tmp_path / "new"), "--seed", "-5"])
    assert (tmp_path / "run" / "keep.txt").read_text() == "mine"


def test_init_from_starts_from_the_checkpoint_and_refuses_another_network(tmp_path, tiny_data):
    data, val = tiny_data
    base = dict(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, validate_every=1)
    train_reconstructor(ReconstructionTrainConfig(steps=3, **base), tmp_path / "a", data=data, val_data=val,
                        progress=False)
    start = torch.load(tmp_path / "a" / "last.pt", weights_only=True)["state_dict"]
    # a run of one step at a vanishing learning rate from those weights ends where it started
    tuned = ReconstructionTrainConfig(steps=1, lr=1e-12, init_from=str(tmp_path / "a" / "last.pt"), **base)
    train_reconstructor(tuned, tmp_path / "b", data=data, val_data=val, progress=False)
    after = torch.load(tmp_path / "b" / "last.pt", weights_only=True)["state_dict"]
    for key in start:
        torch.testing.assert_close(after[key], start[key], atol=1e-6, rtol=0)
    scored = torch.load(tmp_path / "a" / "last.pt", weights_only=True)["history"][-1]["val_loss"]
    assert abs(torch.load(tmp_path / "b" / "last.pt", weights_only=True)["history"][0]["val_loss"] - scored) < 1e-5
    with pytest.raises(ValueError, match="does not exist"):
        ReconstructionTrainConfig(init_from=str(tmp_path / "missing.pt"), **base)
    wider = ReconstructionTrainConfig(steps=1, network_options={"channels": 8}, init_from=str(tmp_path / "a" / "last.pt"),
                                      **base)
    with pytest.raises(ValueError, match="holds a firenet network"):
        train_reconstructor(wider, tmp_path / "c", data=data, val_data=val, progress=False)


def test_stretch_matches_the_metrics_normalisation():
    rng = np.random.default_rng(1)
    images = rng.gamma(2.0, 0.1, (3, 1, 20, 30)).astype(np.float64)   # skewed, spread well above the floor
    ours = stretch_torch(torch.from_numpy(images)).numpy()
    for k in range(3):
        np.testing.assert_allclose(ours[k, 0], normalize_for_metrics(images[k, 0]), atol=1e-9)
    flat = torch.full((1, 1, 8, 8), 0.3) + 0.001 * torch.arange(64.0).reshape(1, 1, 8, 8) / 64
    assert float(stretch_torch(flat).max()) < 0.03          # a nearly flat image is not blown up to [0, 1]


def test_gaussian_blur_matches_scipy():
    from scipy.ndimage import gaussian_filter

    image = np.random.default_rng(5).uniform(0, 1, (2, 1, 30, 26))
    for sigma in (0.8, 1.5, 3.0):
        ours = _gaussian_blur_torch(torch.from_numpy(image), sigma).numpy()
        for k in range(2):   # torch's "reflect" padding is scipy's "mirror"; both cut the kernel at 3 sigma
            np.testing.assert_allclose(ours[k, 0], gaussian_filter(image[k, 0], sigma, mode="mirror", truncate=3.0),
                                       atol=1e-6)


def test_detail_consistency_forgives_a_brightness_change_and_not_a_flicker():
    rng = np.random.default_rng(6)
    frame = torch.from_numpy(rng.uniform(0.2, 0.8, (1, 1, 40, 40)))
    still = torch.zeros(1, 2, 40, 40)                                   # no motion: every pixel its own source
    brighter = frame + 0.1 * torch.exp(-((torch.arange(40.0) - 20) / 12) ** 2)[None, None, None]   # a smooth bump
    flicker = frame + 0.1 * torch.from_numpy(rng.choice([-1.0, 1.0], (1, 1, 40, 40)))
    loss = {(name, s): temporal_consistency_loss(pred, frame, frame, frame, still, detail_sigma=s).item()
            for name, pred in (("brighter", brighter), ("flicker", flicker)) for s in (0.0, 3.0)}
    assert loss["brighter", 0.0] > 0.03 and loss["brighter", 3.0] < 0.1 * loss["brighter", 0.0]
    assert loss["flicker", 3.0] > 0.8 * loss["flicker", 0.0] > 0.07
    moved = torch.zeros(1, 2, 40, 40)
    moved[:, 0] = 5.0                                   # sources 5 px to the right: the last 5 columns see outside
    brighter_moved = warp_with_flow(frame, moved) + 0.1  # consistent with the motion, 0.1 brighter everywhere
    plain = temporal_consistency_loss(brighter_moved, frame, frame, frame, moved).item()
    detail = temporal_consistency_loss(brighter_moved, frame, frame, frame, moved, detail_sigma=2.0).item()
    assert plain > 0.09 and detail < 1e-6             # the view's border, where the blur meets outside, adds nothing
    truth_prev = frame.clone()
    truth = frame.clone()
    truth[..., 15:20] += 0.6                            # a strip the warp does not explain (an occlusion): M ~ 0 there
    perfect = temporal_consistency_loss(truth, truth_prev, truth, truth_prev, still, detail_sigma=3.0).item()
    assert perfect < 1e-6                               # perfect predictions: the masked strip leaks into no blur


def test_sequence_loss_passes_the_detail_setting_on():
    rng = np.random.default_rng(7)
    frames = torch.from_numpy(rng.uniform(0.1, 0.7, (1, 1, 24, 24)).astype(np.float32)).repeat(1, 3, 1, 1)  # still
    flickering = frames + torch.from_numpy(rng.normal(0, 0.05, (1, 3, 24, 24)).astype(np.float32))
    brighter = frames + torch.linspace(0.0, 0.2, 3).view(1, 3, 1, 1)   # each window brighter than the last
    voxels, flow = torch.zeros(1, 3, 5, 24, 24), torch.zeros(1, 3, 2, 24, 24)
    parts = {}
    for s in (0.0, 3.0):
        config = ReconstructionTrainConfig(data=DATA, crop=24, tc_detail_sigma=s)
        for name, outputs in (("flicker", flickering), ("brighter", brighter)):
            parts[name, s] = sequence_loss(_AffineOfTruth(outputs, 1.0, 0.0), voxels, frames, flow, config)[1]["tc"]
    assert parts["brighter", 0.0] > 0.05 and parts["brighter", 3.0] < 1e-4
    assert parts["flicker", 3.0] > 0.5 * parts["flicker", 0.0] > 0.01
    with pytest.raises(ValueError, match="tc_detail_sigma"):
        ReconstructionTrainConfig(data=DATA, tc_detail_sigma=-1.0)
    with pytest.raises(ValueError, match="radius 24 px"):
        ReconstructionTrainConfig(data=DATA, crop=16, tc_detail_sigma=8.0)


class _AffineOfTruth(torch.nn.Module):
    """A stand-in network whose k-th output is gain * frame_k + offset (the truth up to an affine map)."""

    def __init__(self, frames: torch.Tensor, gain: float, offset: float) -> None:
        super().__init__()
        self.frames, self.gain, self.offset, self.k = frames, gain, offset, 0
        self.weight = torch.nn.Parameter(torch.ones(()))

    def forward(self, voxels, state):
        out = self.weight * (self.gain * self.frames[:, self.k:self.k + 1] + self.offset)
        self.k += 1
        return out, state


def test_the_stretched_terms_ignore_gain_and_offset_and_reach_the_loss():
    rng = np.random.default_rng(2)
    frames = torch.from_numpy(rng.uniform(0.1, 0.9, (2, 3, 24, 24)).astype(np.float32))
    voxels = torch.zeros(2, 3, 5, 24, 24)
    plain = ReconstructionTrainConfig(data=DATA, lambda_tc=0.0)
    stretched = ReconstructionTrainConfig(data=DATA, lambda_tc=0.0, lambda_stretched=0.5)
    loss_plain, parts_plain = sequence_loss(_AffineOfTruth(frames, 0.4, 0.3), voxels, frames, None, plain)
    loss_s, parts_s = sequence_loss(_AffineOfTruth(frames, 0.4, 0.3), voxels, frames, None, stretched)
    assert parts_plain["ssim"] < 0.9 and parts_s["ssim_stretched"] > 0.999       # raw terms see the affine map
    assert parts_plain["ssim_stretched"] == 0.0                                  # not computed in training without it
    assert abs(loss_s.item() - loss_plain.item()) < 0.5 * 2e-3                   # the stretched terms are ~0 here
    loss_w, parts_w = sequence_loss(_AffineOfTruth(torch.flip(frames, dims=[2]), 1.0, 0.0), voxels, frames, None,
                                    stretched)                                   # wrong structure: the terms count
    loss_w_plain, _ = sequence_loss(_AffineOfTruth(torch.flip(frames, dims=[2]), 1.0, 0.0), voxels, frames, None,
                                    plain)
    assert loss_w.item() - loss_w_plain.item() > 0.5 * (1 - parts_w["ssim_stretched"])
    with torch.no_grad():                                                        # validation always measures it
        _, parts_val = sequence_loss(_AffineOfTruth(frames, 0.4, 0.3), voxels, frames, None, plain)
    assert parts_val["ssim_stretched"] > 0.999


def test_cosine_schedule_and_selection_by_the_stretched_ssim(tmp_path, tiny_data):
    data, val = tiny_data
    config = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=4, validate_every=2,
                                       lr=2e-3, lr_schedule="cosine", lr_final_fraction=0.1, lambda_stretched=1.0,
                                       select_by="ssim_stretched")
    rates = [learning_rate(config, k) for k in range(5)]
    assert rates[0] == pytest.approx(2e-3) and rates[-1] == pytest.approx(2e-4) and np.all(np.diff(rates) < 0)
    summary = train_reconstructor(config, tmp_path / "c", data=data, val_data=val, progress=False)
    ckpt = torch.load(tmp_path / "c" / "last.pt", weights_only=True)
    assert ckpt["optimizer"]["param_groups"][0]["lr"] == pytest.approx(learning_rate(config, 3))
    scores = [entry["val_ssim_stretched"] for entry in ckpt["history"]]
    assert summary["best_val_ssim"] == pytest.approx(max(scores))
    with pytest.raises(ValueError, match="lr_schedule"):
        ReconstructionTrainConfig(data=DATA, lr_schedule="linear")
    with pytest.raises(ValueError, match="select_by"):
        ReconstructionTrainConfig(data=DATA, select_by="mse")
    with pytest.raises(ValueError, match="lambda_stretched"):
        ReconstructionTrainConfig(data=DATA, lambda_stretched=-1.0)


def test_ship_tool_appends_a_stage_to_the_shipped_file(tmp_path, tiny_data):
    import subprocess
    import sys
    from pathlib import Path

    from evio_lib.events.reconstruct import shipped_checkpoint

    data, val = tiny_data
    config = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=2, validate_every=1)
    train_reconstructor(config, tmp_path / "run", data=data, val_data=val, progress=False)
    tool = Path(__file__).resolve().parents[2] / "tools" / "ship_reconstructor.py"
    out = tmp_path / "shipped.pt"
    subprocess.run([sys.executable, str(tool), "--base", str(shipped_checkpoint("firenet")), "--stage",
                    str(tmp_path / "run" / "last.pt"), "the third stage's command", "--out", str(out)], check=True,
                   capture_output=True)
    base = torch.load(shipped_checkpoint("firenet"), map_location="cpu", weights_only=True)
    new = torch.load(out, map_location="cpu", weights_only=True)
    trained = torch.load(tmp_path / "run" / "last.pt", map_location="cpu", weights_only=True)
    assert [s["command"] for s in new["stages"]] == [s["command"] for s in base["stages"]] + ["the third stage's command"]
    assert new["step"] == base["step"] + trained["step"] and new["command"] == "the third stage's command"
    assert new["history"][:len(base["history"])] == base["history"]
    added = new["history"][len(base["history"]):]
    assert [h["stage"] for h in added] == [len(base["stages"]) + 1] * 2
    assert [h["step"] for h in added] == [base["step"] + 1, base["step"] + 2]
    for key, value in trained["state_dict"].items():
        torch.testing.assert_close(new["state_dict"][key], value)
    assert new["int8_ranges"]["weights_sha1"] != base["int8_ranges"]["weights_sha1"]
    failed = subprocess.run([sys.executable, str(tool), "--base", str(tmp_path / "run" / "best.pt"), "--stage",
                             str(tmp_path / "run" / "best.pt"), "x", "--out", str(tmp_path / "x.pt")],
                            capture_output=True, text=True)
    assert failed.returncode == 2 and "holds no stages" in failed.stderr and not (tmp_path / "x.pt").exists()
    wider = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=1, validate_every=1,
                                      network_options={"channels": 8})
    train_reconstructor(wider, tmp_path / "wide", data=data, val_data=val, progress=False)
    failed = subprocess.run([sys.executable, str(tool), "--base", str(shipped_checkpoint("firenet")), "--stage",
                             str(tmp_path / "wide" / "last.pt"), "x", "--out", str(tmp_path / "x.pt")],
                            capture_output=True, text=True)
    assert failed.returncode == 2 and "another network" in failed.stderr and not (tmp_path / "x.pt").exists()


def test_resume_keeps_a_cosine_schedule_and_accepts_runs_saved_before_the_new_settings(tmp_path, tiny_data):
    data, val = tiny_data
    base = dict(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, validate_every=2)
    cosine = ReconstructionTrainConfig(steps=4, lr_schedule="cosine", **base)
    train_reconstructor(ReconstructionTrainConfig(steps=4, lr_schedule="cosine", max_minutes=1e-9, **base),
                        tmp_path / "c", data=data, val_data=val, progress=False)         # stops after one step
    longer = ReconstructionTrainConfig(steps=8, lr_schedule="cosine", **base)
    with pytest.raises(ValueError, match="cosine schedule over steps = 4"):
        train_reconstructor(longer, tmp_path / "c", resume=True, data=data, val_data=val, progress=False)
    assert train_reconstructor(cosine, tmp_path / "c", resume=True, data=data, val_data=val,
                               progress=False)["steps"] == 4
    # a last.pt written before lambda_stretched, lr_schedule, lr_final_fraction and select_by existed
    plain = ReconstructionTrainConfig(steps=2, **base)
    train_reconstructor(plain, tmp_path / "old", data=data, val_data=val, progress=False)
    ckpt = torch.load(tmp_path / "old" / "last.pt", weights_only=True)
    for key in ("lambda_stretched", "lr_schedule", "lr_final_fraction", "select_by"):
        del ckpt["config"][key]
    torch.save(ckpt, tmp_path / "old" / "last.pt")
    more = ReconstructionTrainConfig(steps=4, **base)
    assert train_reconstructor(more, tmp_path / "old", resume=True, data=data, val_data=val,
                               progress=False)["steps"] == 4


def test_several_training_sets_train_together_and_validate_on_the_first(tmp_path):
    """--data A B: the train splits of both sets are drawn from, A's val split validates, both manifests are recorded;
    sets whose sequences differ in windows or bins are refused before training."""
    from evio_lib.events.reconstruction.training import open_split
    from evio_lib.events.reconstruction.training_set import TrainingSetConfig, make_training_set

    small = TrainingSetConfig(height=32, width=32, windows=4, duration_min=0.3, duration_max=0.4)
    make_training_set(tmp_path / "a", sequences=2, val=1, test=1, seed=4, config=small, workers=1, progress=False)
    make_training_set(tmp_path / "b", sequences=3, val=1, test=1, seed=5, config=small, workers=1, progress=False)
    joined = open_split([tmp_path / "a", tmp_path / "b"], "train")
    assert len(joined) == 5
    assert [p.parent.parent.name for p in joined.paths] == ["a", "a", "b", "b", "b"]
    np.testing.assert_array_equal(joined.take([2])[0], open_split(tmp_path / "b", "train").take([0])[0])
    main_reconstruct_train(["--out", str(tmp_path / "run"), "--data", str(tmp_path / "a"), str(tmp_path / "b"),
                            "--steps", "1", "--quiet", "--set", "crop=16", "--set", "validate_every=1"])
    ckpt = torch.load(tmp_path / "run" / "last.pt", weights_only=True)
    assert ckpt["config"]["training_set"] == str(tmp_path / "a")
    assert ckpt["config"]["extra_training_sets"] == [str(tmp_path / "b")]
    assert ckpt["training_set_manifest"]["seed"] == 4
    assert [m["seed"] for m in ckpt["training_set_manifest"]["extra_training_sets"]] == [5]
    longer = TrainingSetConfig(height=32, width=32, windows=5, duration_min=0.3, duration_max=0.4)
    make_training_set(tmp_path / "d", sequences=1, val=1, test=1, seed=7, config=longer, workers=1, progress=False)
    with pytest.raises(ValueError, match="must agree on both"):
        main_reconstruct_train(["--out", str(tmp_path / "run2"), "--data", str(tmp_path / "a"), str(tmp_path / "d")])
    assert not (tmp_path / "run2").exists()


def test_sets_of_different_image_sizes_train_together_on_crops_that_fit_the_smallest(tmp_path):
    """--data A C with C's images larger: allowed when the crop fits A's (every sample cropped inside its own image,
    preloaded or read per step); a crop larger than the smallest set is refused before anything is written."""
    from evio_lib.events.reconstruction.training import _augment_batch, open_split
    from evio_lib.events.reconstruction.training_set import TrainingSetConfig, make_training_set

    small = TrainingSetConfig(height=32, width=32, windows=4, duration_min=0.3, duration_max=0.4)
    wider = TrainingSetConfig(height=40, width=48, windows=4, duration_min=0.3, duration_max=0.4)
    make_training_set(tmp_path / "a", sequences=2, val=1, test=1, seed=4, config=small, workers=1, progress=False)
    make_training_set(tmp_path / "c", sequences=2, val=1, test=1, seed=6, config=wider, workers=1, progress=False)
    with pytest.raises(ValueError, match="crop = 48 is larger than the smallest sequences"):
        main_reconstruct_train(["--out", str(tmp_path / "run"), "--data", str(tmp_path / "a"), str(tmp_path / "c")])
    assert not (tmp_path / "run").exists()
    for preload in (False, True):
        joined = open_split([tmp_path / "a", tmp_path / "c"], "train", preload=preload)
        assert len(joined) == 4
        same = joined.take([2, 3])                          # one size: stacked as before
        assert same[1].shape == (2, 4, 40, 48)
        voxels, frames, flow = joined.take([0, 3, 1])       # sizes mixed: per-sample lists
        assert [f.shape for f in frames] == [(4, 32, 32), (4, 40, 48), (4, 32, 32)]
        v, f, w = _augment_batch(np.random.default_rng(0), voxels, frames, flow, crop=24)
        assert v.shape == (3, 4, 5, 24, 24) and f.shape == (3, 4, 24, 24) and w.shape == (3, 4, 2, 24, 24)
        # each crop is a window of its own sample's image, up to the flips
        for crop, full in zip(f, frames):
            hits = [(oy, ox) for oy in range(full.shape[1] - 23) for ox in range(full.shape[2] - 23)
                    if any(np.array_equal(crop[0], c) for c in
                           (full[0, oy:oy + 24, ox:ox + 24], full[0, oy:oy + 24, ox:ox + 24][:, ::-1],
                            full[0, oy:oy + 24, ox:ox + 24][::-1], full[0, oy:oy + 24, ox:ox + 24][::-1, ::-1]))]
            assert hits
    summary = main_reconstruct_train(["--out", str(tmp_path / "run"), "--data", str(tmp_path / "a"),
                                      str(tmp_path / "c"), "--steps", "2", "--quiet", "--set", "crop=24",
                                      "--set", "batch_size=4", "--set", "validate_every=2", "--set", "preload=true"])
    assert summary == 0 and (tmp_path / "run" / "best.pt").is_file()
    with pytest.raises(ValueError, match="extra_training_sets needs training_set"):
        ReconstructionTrainConfig(extra_training_sets=[str(tmp_path / "b")])


def _tensors(state) -> list:
    """Return the tensors of a recurrent state (a tensor or nested lists/tuples of them)."""
    if isinstance(state, torch.Tensor):
        return [state]
    return [t for part in (state or []) for t in _tensors(part)]


def test_a_warm_start_begins_a_batch_from_the_state_another_batch_left(tmp_path, tiny_data, monkeypatch):
    from evio_lib.events.reconstruction.nets import build_network

    torch.manual_seed(0)
    net = build_network("firenet")
    rng = np.random.default_rng(3)
    other = torch.from_numpy(rng.normal(0, 1, (2, 3, 5, 24, 24)).astype(np.float32))
    voxels = torch.from_numpy(rng.normal(0, 1, (2, 3, 5, 24, 24)).astype(np.float32))
    frames = torch.from_numpy(rng.uniform(0.1, 0.9, (2, 3, 24, 24)).astype(np.float32))
    state = warm_state(net, other)
    by_hand = None
    for k in range(3):
        _, by_hand = net(other[:, k], by_hand)
    leaves = _tensors(state)
    assert leaves and all(torch.equal(a, b) for a, b in zip(leaves, _tensors(by_hand)))
    assert not any(t.requires_grad for t in leaves)                    # no gradient through it
    config = ReconstructionTrainConfig(data=DATA)
    cold, _ = sequence_loss(net, voxels, frames, None, config)
    warm, _ = sequence_loss(net, voxels, frames, None, config, state=state)
    again, _ = sequence_loss(net, voxels, frames, None, config, state=None)
    assert warm.item() != cold.item() and again.item() == cold.item()
    data, val = tiny_data
    config = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=3, validate_every=3,
                                       warm_start=1.0, time_reversal=0.5)
    warm_run = train_reconstructor(config, tmp_path / "warm", data=data, val_data=val, progress=False)["last"]
    import evio_lib.events.reconstruction.training as training

    monkeypatch.setattr(training, "warm_state", lambda net, voxels: None)  # the same draws, every batch started empty
    cold_run = train_reconstructor(config, tmp_path / "cold", data=data, val_data=val, progress=False)["last"]
    assert warm_run["val_l1"] != cold_run["val_l1"]                    # the states reached the training
    with pytest.raises(ValueError, match=r"warm_start must be a probability in \[0, 1\]"):
        ReconstructionTrainConfig(data=DATA, warm_start=1.5)


def test_warm_starts_from_the_previous_batch_chain_the_states_each_batch_ended_in(tmp_path, tiny_data, monkeypatch):
    import evio_lib.events.reconstruction.training as training

    seen = []                                            # (state passed in, state handed back) at each step
    real = training.sequence_loss

    def recording(net, voxels, frames, flow, config, state=None, final_state=None):
        out = real(net, voxels, frames, flow, config, state=state, final_state=final_state)
        if torch.is_grad_enabled():                      # training steps, not validation
            by_hand = state                              # the state after the batch's last window, run again
            with torch.no_grad():
                for k in range(voxels.shape[1]):
                    _, by_hand = net(voxels[:, k], by_hand)
            seen.append((state, None if final_state is None else final_state[0], by_hand, voxels.shape[1]))
        return out

    monkeypatch.setattr(training, "sequence_loss", recording)
    data, val = tiny_data
    config = ReconstructionTrainConfig(data=DATA, n_train=6, n_val=2, batch_size=2, crop=24, steps=4, validate_every=2,
                                       warm_start=1.0, warm_start_from="previous", time_reversal=0.5)
    train_reconstructor(config, tmp_path / "chain", data=data, val_data=val, progress=False)
    assert len(seen) == 4 and seen[0][0] is None                     # nothing before the first batch
    assert len({n for *_, n in seen}) == 2                           # batches played forwards and backwards
    for (_, ended, by_hand, _), (started, *_) in zip(seen, seen[1:]):  # a validation between steps 2 and 3
        assert ended is not None and started is ended                # each batch starts where the last one ended
        for a, b in zip(_tensors(ended), _tensors(by_hand), strict=True):
            torch.testing.assert_close(a, b)                          # the state after the last window
        assert not any(t.requires_grad for t in _tensors(started))   # cut from the last batch's graph
    with pytest.raises(ValueError, match="warm_start_from must be one of"):
        ReconstructionTrainConfig(data=DATA, warm_start_from="random")
