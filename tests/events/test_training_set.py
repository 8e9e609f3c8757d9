"""Tests of the reconstruction training set: the layered scene's flow against its renders, determinism across workers and
set sizes, resuming, refusals, the command line, and the augmentations (time reversal against reversed events)."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

from evio_lib.events.array import make_events
from evio_lib.events.reconstruction.data import SmoothCameraMotion, fold_time
from evio_lib.events.reconstruction.training import SequenceSource, _augment_batch, warp_with_flow
from evio_lib.events.reconstruction.training_set import (_LayeredScene, TrainingSetConfig, load_sequence,
                                                         make_sequence, make_training_set, read_training_set)
from evio_lib.events.representations import voxel_grid
from evio_lib.events.simulate import simulate_events

SMALL = TrainingSetConfig(height=32, width=32, windows=4, duration_min=0.3, duration_max=0.4)


def test_sequences_are_deterministic_and_shaped():
    a, meta_a = make_sequence(np.random.default_rng(3), "train", SMALL)
    b, meta_b = make_sequence(np.random.default_rng(3), "train", SMALL)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert meta_a == meta_b
    assert a["voxels"].shape == (4, 5, 32, 32) and a["frames"].shape == (4, 32, 32) and a["flow"].shape == (4, 2, 32, 32)
    assert a["voxels"].dtype == a["frames"].dtype == a["flow"].dtype == np.float16
    assert np.all(a["flow"][0] == 0) and np.isfinite(a["flow"].astype(np.float32)).all()
    assert meta_a["rule"] in ("count", "time") and 0 < meta_a["fraction"]
    assert meta_a["contrast_pos"] > 0 and meta_a["events"] >= 4 * 0.05 * 32 * 32


def test_fold_time_is_a_triangle_wave():
    period = 1.5
    t = np.array([0.0, 0.7, 1.5, 2.0, 3.0, 3.4, 4.5, 6.0])
    want = np.array([0.0, 0.7, 1.5, 1.0, 0.0, 0.4, 1.5, 0.0])      # up to 1.5, down to 0 at 3, up again
    np.testing.assert_allclose([fold_time(float(x), period) for x in t], want, atol=1e-12)
    dense = np.linspace(0.0, 10.0, 20001)
    folded = np.array([fold_time(float(x), period) for x in dense])
    assert folded.min() >= 0.0 and folded.max() <= period
    assert np.abs(np.diff(folded)).max() <= (dense[1] - dense[0]) + 1e-12     # continuous, slope +-1


def test_motion_stays_within_its_bounds_beyond_its_duration():
    """The rotation and translation bounds drawn for 1 s hold over 10 s: the drift turns round, the sinusoids go on."""
    for seed in range(5):
        motion = SmoothCameraMotion(np.random.default_rng(seed), 3.0, 1.2, 2.0, 1.0, 0.5)
        for t in np.linspace(0.0, 10.0, 401):
            R, p = motion.pose(float(t))
            theta = np.linalg.norm(cv2.Rodrigues(R)[0])
            assert theta <= 0.6 * np.sqrt(3) + 1e-9
            assert np.abs(-R.T @ p).max() <= 0.5 + 1e-9             # the centre in C0


def test_a_slow_sequence_is_lengthened_to_hold_the_windows_drawn():
    """Count windows of n = 0.8 H W events on a slow camera: generator version 2 cut n to the events of 1 s; now the
    same scene is simulated for longer, and n is what was drawn."""
    config = TrainingSetConfig(height=32, width=32, windows=8, duration_min=1.0, duration_max=1.0,
                               fraction_min=0.8, fraction_max=0.8, time_window_probability=0.0, speed_min=0.2,
                               speed_max=0.2, max_foreground=0)
    lengthened = 0
    for seed in range(3):
        arrays, meta = make_sequence(np.random.default_rng(seed), "train", config)
        assert meta["rule"] == "count" and meta["fraction_drawn"] == pytest.approx(0.8)
        assert meta["duration"] <= config.duration_extend_max
        if meta["duration"] < config.duration_extend_max:           # not at the limit: the events were enough
            assert meta["fraction"] == pytest.approx(0.8, abs=1 / (32 * 32))
        lengthened += meta["duration"] > 1.0
        assert np.isfinite(arrays["flow"].astype(np.float32)).all()
    assert lengthened >= 2                                           # 1 s of this motion is too short for most


def test_a_sequence_still_short_after_its_last_try_reports_the_time_it_simulated(monkeypatch):
    """When three tries are not enough (here a camera whose events stop after 1.5 s), n is lowered and the metadata
    keep the duration of the last simulation, not the longer one a fourth try would have asked for."""
    import evio_lib.events.reconstruction.training_set as training_set

    simulated = []

    def runs_dry(render, t_start, t_end, *args, **kwargs):
        simulated.append(t_end)
        return simulate_events(render, t_start, min(t_end, 1.5), *args, **kwargs)

    monkeypatch.setattr(training_set, "simulate_events", runs_dry)
    config = TrainingSetConfig(height=32, width=32, windows=8, duration_min=1.0, duration_max=1.0,
                               fraction_min=0.5, fraction_max=0.5, time_window_probability=0.0, speed_min=0.2,
                               speed_max=0.2, max_foreground=0)
    for seed in (0, 1):
        simulated.clear()
        _, meta = make_sequence(np.random.default_rng(seed), "train", config)
        assert len(simulated) == 3 and simulated[-1] < config.duration_extend_max    # every try fell short
        assert meta["duration"] == simulated[-1] and meta["fraction"] < 0.5


@pytest.mark.parametrize("seed, t0", [(0, 0.30), (1, 0.30), (2, 0.30), (0, 1.62), (1, 2.45)])
def test_flow_maps_each_pixel_to_where_it_was(seed, t0):
    """Warping the earlier render by the stored flow reproduces the later render (the TC loss's truth), far better than
    no warp, on a scene with several independently moving planes; also beyond the drawn time, where the drift runs
    back (1.62 s: after the first turn at 1 s; 2.45 s: after the second)."""
    config = TrainingSetConfig(height=48, width=48, max_foreground=3, speed_min=1.0, speed_max=2.0)
    scene = _LayeredScene(np.random.default_rng(seed), "val", config, 1.0)
    t1 = t0 + 0.04
    prev, cur = scene.render(t0), scene.render(t1)
    flow = scene.flow_to(t1, t0)
    warped = warp_with_flow(torch.from_numpy(prev)[None, None], torch.from_numpy(flow)[None])[0, 0].numpy()
    inner = (slice(8, -8), slice(8, -8))
    error_warped = np.median(np.abs(warped[inner] - cur[inner]))
    error_still = np.median(np.abs(prev[inner] - cur[inner]))
    assert np.abs(flow).max() > 0.5                      # the camera moved
    assert error_warped < 0.3 * error_still + 1e-3


def test_set_is_the_same_for_any_workers_and_size_and_resumes(tmp_path):
    make_training_set(tmp_path / "a", sequences=3, val=1, test=1, seed=4, config=SMALL, workers=1, progress=False)
    summary = make_training_set(tmp_path / "b", sequences=2, val=1, test=1, seed=4, config=SMALL, workers=2,
                                progress=False)
    assert summary["sequences"] == {"train": 2, "val": 1, "test": 1} and summary["events"] > 0
    for i in range(2):
        a = load_sequence(tmp_path / "a" / "train" / f"seq_{i:05d}.npz")
        b = load_sequence(tmp_path / "b" / "train" / f"seq_{i:05d}.npz")
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    # resume: a lost file is made again, identical; the set grows to 3 keeping its first sequences
    lost = tmp_path / "b" / "train" / "seq_00001.npz"
    before = load_sequence(lost)
    lost.unlink()
    make_training_set(tmp_path / "b", sequences=3, val=1, test=1, seed=4, config=SMALL, workers=1, progress=False)
    np.testing.assert_array_equal(load_sequence(lost)["voxels"], before["voxels"])
    paths, config = read_training_set(tmp_path / "b", "train")
    assert len(paths) == 3 and config == SMALL
    assert not list((tmp_path / "b").rglob("*.tmp*"))   # no temporary file left behind


def test_refusals_name_the_problem(tmp_path):
    make_training_set(tmp_path / "s", sequences=1, val=1, test=0, seed=0, config=SMALL, workers=1, progress=False)
    with pytest.raises(ValueError, match="other settings"):
        make_training_set(tmp_path / "s", sequences=1, val=1, test=0, seed=1, config=SMALL, progress=False)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(ValueError, match="not a training set"):
        make_training_set(tmp_path / "mine", sequences=1, config=SMALL, progress=False)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"
    with pytest.raises(ValueError, match="no training_set.json"):
        read_training_set(tmp_path / "mine", "train")
    manifest = tmp_path / "s" / "training_set.json"
    values = json.loads(manifest.read_text())
    manifest.write_text(json.dumps({**values, "complete": False}))
    with pytest.raises(ValueError, match="incomplete"):
        read_training_set(tmp_path / "s", "train")
    manifest.write_text(json.dumps(values))
    (tmp_path / "s" / "val" / "seq_00000.json").unlink()
    with pytest.raises(ValueError, match="lacks 1 of its 1 val sequences"):
        read_training_set(tmp_path / "s", "val")
    with pytest.raises(ValueError, match="unknown training-set settings"):
        TrainingSetConfig.from_dict({"hieght": 32})
    with pytest.raises(ValueError, match="duration_min"):
        TrainingSetConfig(duration_min=2.0, duration_max=1.0)
    with pytest.raises(ValueError, match="max_foreground must be a number; got True"):
        TrainingSetConfig(max_foreground=True)
    numpy_numbers = TrainingSetConfig(height=np.int64(32), duration_min=np.float32(0.5), duration_max=1)
    assert numpy_numbers.height == 32                               # numpy scalars and ints for floats are numbers


def test_command_line_errors_are_one_line(tmp_path, capsys):
    from evio_lib.cli import main

    for argv, expected in ((["--sequences", "0"], "--sequences must be >= 1"),
                           (["--set", "windows=0"], "windows must be a positive integer"),
                           (["--set", "speed"], "--set expects KEY=JSON"),
                           (["--set", 'noise_rate_max_hz="high"'],
                            "noise_rate_max_hz must be a number; got 'high'"),
                           (["--set", "linear_light_fraction=true"],
                            "linear_light_fraction must be a number; got True")):
        code = main(["reconstruct-data", "--out", str(tmp_path / "x"), "--sequences", "1", "--val", "1", "--test", "0",
                     "--photos", "none", *argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and err[0].startswith("error:") and expected in err[0], err
    assert not (tmp_path / "x").exists()


def test_time_reversal_equals_the_voxels_of_the_reversed_events():
    """Played backwards, a window's voxel grid is the grid of the events at T - t with negated polarity."""
    rng = np.random.default_rng(0)
    n = 400
    t = np.sort(rng.uniform(0.0, 1.0, n))
    x, y, p = rng.integers(0, 16, n), rng.integers(0, 12, n), rng.choice([-1, 1], n)
    forward = voxel_grid(make_events(t, x, y, p), 16, 12, 5)
    order = np.argsort(1.0 - t, kind="stable")
    backward = voxel_grid(make_events((1.0 - t)[order], x[order], y[order], -p[order]), 16, 12, 5)
    voxels = np.stack([forward, forward])[None]                         # (1, L=2, B, H, W)
    frames = np.zeros((1, 2, 12, 16), np.float32)
    frames[0, 0] = 0.25
    flow = np.zeros((1, 2, 2, 12, 16), np.float32)
    always = np.random.default_rng(1)
    v, f, w = _augment_batch(always, voxels, frames, flow, crop=64, time_reversal=1.0)
    assert w is None and v.shape[1] == 1 and f.shape[1] == 1
    # the flips are random: undo them by comparing against every flip of the truth
    candidates = [backward, backward[..., ::-1], backward[..., ::-1, :], backward[..., ::-1, ::-1]]
    assert any(np.allclose(v[0, 0], c, atol=1e-5) for c in candidates)
    assert np.all(f[0, 0] == 0.25)                                       # the label is the earlier window's end


def test_tensor_batches_augment_exactly_as_numpy_batches():
    """A set held on a GPU is cropped, flipped and reversed in torch: the same random draws, the same values, and
    the numpy arrays passed in are left unchanged."""
    rng = np.random.default_rng(3)
    voxels = rng.normal(size=(6, 5, 3, 12, 16)).astype(np.float16)
    frames = rng.uniform(0, 1, (6, 5, 12, 16)).astype(np.float16)
    flow = rng.normal(size=(6, 5, 2, 12, 16)).astype(np.float16)
    copies = [a.copy() for a in (voxels, frames, flow)]
    for seed in range(12):                                # some of these play the batch backwards
        expected = _augment_batch(np.random.default_rng(seed), voxels, frames, flow, crop=10, time_reversal=0.5)
        tensors = [torch.from_numpy(a.copy()) for a in (voxels, frames, flow)]
        got = _augment_batch(np.random.default_rng(seed), *tensors, crop=10, time_reversal=0.5)
        assert (expected[2] is None) == (got[2] is None)
        for e, g in zip(expected, got):
            if e is not None:
                assert isinstance(g, torch.Tensor) and g.is_contiguous() and e.shape == tuple(g.shape)
                np.testing.assert_array_equal(e, g.numpy())
    for a, c in zip((voxels, frames, flow), copies):
        np.testing.assert_array_equal(a, c)
    source = SequenceSource(arrays={"voxels": voxels, "frames": frames, "flow": flow}, device="meta")
    taken = source.take([4, 1, 4])                        # held as tensors on the device, indexed there
    assert all(isinstance(t, torch.Tensor) and t.device.type == "meta" and t.shape[0] == 3 for t in taken)


def test_flips_keep_flow_and_images_consistent():
    """Flipping images and flow then warping equals warping then flipping."""
    rng = np.random.default_rng(2)
    frames = rng.uniform(0, 1, (1, 2, 10, 14)).astype(np.float32)
    flow = np.zeros((1, 2, 2, 10, 14), np.float32)
    flow[0, 1, 0], flow[0, 1, 1] = 1.0, -1.0                              # x + 1, y - 1
    voxels = np.zeros((1, 2, 5, 10, 14), np.float32)
    for seed in range(4):
        _, f, w = _augment_batch(np.random.default_rng(seed), voxels.copy(), frames.copy(), flow.copy(), crop=64)
        warped = warp_with_flow(torch.from_numpy(np.ascontiguousarray(f[:, 0:1])),
                                torch.from_numpy(np.ascontiguousarray(w[:, 1])))[0, 0].numpy()
        plain = warp_with_flow(torch.from_numpy(frames[:, 0:1]), torch.from_numpy(flow[:, 1]))[0, 0].numpy()
        flipped_plain = [plain, plain[:, ::-1], plain[::-1, :], plain[::-1, ::-1]]
        flipped_frame = [frames[0, 1], frames[0, 1, :, ::-1], frames[0, 1, ::-1], frames[0, 1, ::-1, ::-1]]
        k = next(i for i, c in enumerate(flipped_frame) if np.array_equal(c, f[0, 1]))
        np.testing.assert_allclose(warped, flipped_plain[k], atol=1e-5)


def test_training_on_a_set_raises_validation_ssim_and_keeps_the_best(tmp_path):
    from evio_lib.events.reconstruction.training import (ReconstructionTrainConfig, evaluate_on_samples, open_split,
                                                         train_reconstructor)
    from evio_lib.events.reconstruction.nets import FireNet

    make_training_set(tmp_path / "set", sequences=6, val=2, test=0, seed=0, config=SMALL, workers=1, progress=False)
    config = ReconstructionTrainConfig(training_set=str(tmp_path / "set"), batch_size=2, crop=32, steps=40,
                                       validate_every=10, lr=3e-3, time_reversal=0.3)
    torch.manual_seed(config.seed)
    untrained = evaluate_on_samples(FireNet(), open_split(tmp_path / "set", "val"), config)
    summary = train_reconstructor(config, tmp_path / "run", progress=False)
    history = json.loads((tmp_path / "run" / "history.json").read_text())
    assert summary["best_val_ssim"] == max(h["val_ssim"] for h in history) > untrained["ssim"]
    best = torch.load(tmp_path / "run" / "best.pt", weights_only=True)
    assert best["history"][-1]["val_ssim"] == summary["best_val_ssim"]
    assert TrainingSetConfig.from_dict(best["training_set_manifest"]["config"]) == SMALL   # the data's recipe
    with pytest.raises(ValueError, match="voxel bins"):
        ReconstructionTrainConfig(training_set=str(tmp_path / "set"), data={"num_bins": 3})
    with pytest.raises(ValueError, match="not a training set"):
        ReconstructionTrainConfig(training_set=str(tmp_path / "run"))
