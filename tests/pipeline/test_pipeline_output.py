"""Tests of the run's output folder and of the run / table commands."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.cli import main
from evio_lib.io.tum import read_tum
from evio_lib.pipeline.output import write_run
from evio_lib.pipeline.run import PipelineConfig, run_pipeline
from evio_lib.pipeline.table import TableRow, aggregate, format_table6, table_rows


@pytest.fixture(scope="module")
def short_run(boxes_aps):
    return run_pipeline(boxes_aps, PipelineConfig(tracker="klt", features="fast", max_duration=1.5))


def test_output_folder(short_run, boxes_aps, tmp_path):
    out = write_run(short_run, boxes_aps, tmp_path / "run", figures=True)
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.txt", "trajectory_imu.txt", "groundtruth.txt", "states.csv", "tracking.csv", "metrics.json",
            "summary.txt", "figures"} <= names
    assert len(list((out / "figures").glob("*.png"))) == 7
    t, p, q = read_tum(out / "trajectory.txt")
    R_CtoG, p_CinG = short_run.camera_pose()
    np.testing.assert_allclose(p, p_CinG, atol=1e-9)  # the camera pose: the same body as the ECD ground truth
    t_gt, p_gt, _ = read_tum(out / "groundtruth.txt")
    seq_gt = boxes_aps.sequence.groundtruth  # the recording's own camera ground truth
    expected = np.stack([np.interp(t_gt, seq_gt.t, seq_gt.p_BinG[:, k]) for k in range(3)], axis=1)
    np.testing.assert_allclose(p_gt, expected, atol=1e-3)
    record = json.loads((out / "metrics.json").read_text())  # strict JSON: NaN would be refused by other readers
    assert record["trajectory_body"] == "camera"
    for name, body in (("trajectory.txt", "camera frame C"), ("groundtruth.txt", "camera frame C"),
                       ("trajectory_imu.txt", "IMU frame I")):  # each file says whose pose it holds
        assert (out / name).read_text().splitlines()[0] == f"# timestamp tx ty tz qx qy qz qw: pose of the {body} in " \
                                                           f"the world frame G", name
    t_imu, p_imu, q_imu = read_tum(short_run.write_tum(tmp_path / "imu.txt"))  # the result writes itself: IMU by default
    np.testing.assert_array_equal(p_imu, short_run.p_IinG)
    np.testing.assert_allclose(Rotation.from_quat(q_imu).as_matrix(), short_run.R_ItoG, atol=1e-12)
    np.testing.assert_array_equal(read_tum(short_run.write_tum(tmp_path / "c.txt", body="camera"))[1], p)
    with pytest.raises(ValueError, match="body must be one of imu, camera; got 'world'"):
        short_run.write_tum(tmp_path / "w.txt", body="world")
    assert record["metrics"]["rmse_m"] == pytest.approx(short_run.metrics["rmse_m"])
    states = np.loadtxt(out / "states.csv", delimiter=",", skiprows=1)
    assert states.shape == (len(short_run.t), 32)


def test_output_refuses_a_used_folder(short_run, boxes_aps, tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "keep.txt").write_text("mine")
    with pytest.raises(ValueError, match="not empty"):
        write_run(short_run, boxes_aps, tmp_path / "run")
    assert (tmp_path / "run" / "keep.txt").read_text() == "mine"


def test_evo_reads_the_trajectory(short_run, boxes_aps, tmp_path):
    evo_file = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    out = write_run(short_run, boxes_aps, tmp_path / "run", figures=False)
    ref = evo_file.read_tum_trajectory_file(str(out / "groundtruth.txt"))
    est = evo_file.read_tum_trajectory_file(str(out / "trajectory.txt"))
    ref, est = sync.associate_trajectories(ref, est)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    R_CtoG, p_CinG = short_run.camera_pose()
    ours = np.sqrt(np.mean(np.sum((p_CinG - np.loadtxt(out / "groundtruth.txt")[:, 1:4]) ** 2, axis=1)))
    assert ape.get_statistic(metrics.StatisticsType.rmse) == pytest.approx(ours, rel=1e-6)


def test_run_command(pipeline_cache, boxes_aps, tmp_path, capsys):
    out = tmp_path / "run"
    args = ["run", "boxes_like", "--duration", "3", "--max-duration", "1", "--tracker", "klt", "--features", "fast",
            "--quiet", "--no-figures", "--out", str(out)]
    assert main(args) == 0
    assert "RMSE" in capsys.readouterr().out and (out / "trajectory.txt").is_file()
    assert main(args) == 2  # the folder is used now
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "--force" in err


def test_a_default_run_prints_plain_notes_and_verbose_adds_the_measurements(pipeline_cache, boxes_aps, capsys):
    """The default output says what was chosen and why in words; --verbose adds the numbers behind each note, the
    settings, the time per stage and what the filter dropped."""
    args = ["run", "boxes_like", "--duration", "3", "--max-duration", "1", "--tracker", "klt", "--quiet"]
    assert main(args) == 0
    plain = capsys.readouterr().out
    assert main([*args, "--verbose"]) == 0
    verbose = capsys.readouterr().out
    start_plain = next(line for line in plain.splitlines() if line.strip().startswith("start:"))
    start_full = next(line for line in verbose.splitlines() if line.strip().startswith("start:"))
    assert "rad/s" in start_full and "rad/s" not in start_plain and not any(c.isdigit() for c in start_plain
                                                                           .split(":", 1)[1].split("first")[0])
    assert "settings: PipelineConfig(" in verbose and "time per stage:" in verbose and "tracks dropped" in verbose
    assert "settings:" not in plain and "time per stage" not in plain
    assert [line for line in plain.splitlines() if "RMSE" in line] == [line for line in verbose.splitlines()
                                                                      if "RMSE" in line]


def test_cnn_inference_reaches_the_detector(pipeline_cache, boxes_aps, monkeypatch, capsys):
    from evio_lib.pipeline import run as run_module

    configs = []
    real = run_module.run_pipeline
    monkeypatch.setattr(run_module, "run_pipeline", lambda data, config, **kw: configs.append(config) or real(
        data, config, **kw))
    args = ["run", "boxes_like", "--duration", "3", "--max-duration", "0.5", "--features", "superpoint",
            "--cnn-inference", "fused", "--quiet", "--no-figures"]
    assert main(args) == 0
    assert dict(configs[0].detector_options)["inference"] == "fused"
    assert "RMSE" in capsys.readouterr().out


def test_pixel_noise_options_reach_the_config(pipeline_cache, boxes_aps, monkeypatch, capsys):
    """--pixel-noise and --event-pixel-noise set their own fields (a swap would pass every other test)."""
    from evio_lib.pipeline import run as run_module

    configs = []
    real = run_module.run_pipeline
    monkeypatch.setattr(run_module, "run_pipeline", lambda data, config, **kw: configs.append(config) or real(
        data, config, **kw))
    args = ["run", "boxes_like", "--duration", "3", "--max-duration", "0.5", "--pixel-noise", "0.7", "--quiet",
            "--no-figures"]
    assert main(args) == 0
    assert configs[-1].pixel_noise_px == 0.7 and configs[-1].event_pixel_noise_px is None
    capsys.readouterr()
    assert main(args + ["--event-pixel-noise", "2.5"]) == 2  # refused: no event stream
    assert "--event-pixel-noise applies to event frame streams" in capsys.readouterr().err
    fused = ["run", "boxes_like", "--duration", "3", "--max-duration", "0.3", "--frames", "aps+mc-events", "--quiet",
             "--no-figures"]
    assert main(fused + ["--event-tracker", "klt", "--max-track-gap", "2"]) == 0
    assert (configs[-1].tracker, configs[-1].event_tracker, configs[-1].max_track_gap) == ("descriptor", "klt", 2)
    assert main(fused) == 0 and configs[-1].event_tracker is None


def test_run_weights_takes_a_shipped_name(monkeypatch, capsys, pipeline_cache):
    """``run --weights NAME`` loads the shipped network NAME, as ``features-benchmark --weights`` does; an unknown
    bare name is refused in one line that names both forms."""
    from evio_lib.pipeline import run as run_module

    configs = []
    real = run_module.run_pipeline
    monkeypatch.setattr(run_module, "run_pipeline", lambda data, config, **kw: configs.append(config) or real(
        data, config, **kw))
    args = ["run", "boxes_like", "--duration", "3", "--max-duration", "0.2", "--features", "superpoint", "--quiet",
            "--no-figures", "--weights"]
    assert main(args + ["pretrained_detdesc_round1_gpu"]) == 0
    assert dict(configs[-1].detector_options)["weights"] == "pretrained_detdesc_round1_gpu"
    capsys.readouterr()
    assert main(args + ["no_such_network"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --weights no_such_network: no such checkpoint file or the name of a shipped network")
    assert err.count("\n") == 1


@pytest.mark.parametrize("args, message", [
    (["run", "nowhere_at_all"], "neither a preset"),
    (["run", "boxes_like", "--bias-init", "1,2"], "--bias-init must be"),
    (["run", "boxes_like", "--weights", "missing.pt", "--features", "superpoint"], "no such checkpoint"),
    (["run", "boxes_like", "--frames", "video"], "--frames"),
    (["run", "boxes_like", "--cnn-inference", "int8"], "--cnn-inference applies to a CNN detector"),
    (["run", "boxes_like", "--features", "superpoint", "--cnn-inference", "int4"], "--cnn-inference"),
    (["table", "--rows", "nonsense"], "unknown table row"),
    (["table", "--aps-exposure", "0.05"], "--aps-exposure must be a number of seconds > 0 and at most one frame "
                                          "interval, 1/24 s (0.04166); got 0.05"),
    (["run", "boxes_like", "--aps-exposure", "0.1"], "--aps-exposure must be a number of seconds > 0 and at most"),
    (["run", "nowhere_at_all", "--aps-exposure", "0.02"], "neither a preset"),
    (["run", "boxes_like", "--frames", "mc-events", "--aps-exposure", "0.02"],
     "--aps-exposure applies to runs that use APS frames"),
    (["run", "boxes_like", "--imu-only", "--aps-exposure", "0.02"], "--aps-exposure applies to runs that use APS"),
    (["table", "--rows", "imu", "--aps-exposure", "0.02"], "--aps-exposure applies to table rows that use APS frames"),
    (["run", "boxes_like", "--speed", "5"], "--speed must be a number in [0.25, 4]"),
    (["table", "--speed", "0.2"], "--speed must be a number in [0.25, 4]"),
    (["table", "--speed", "2", "--duration", "40"], "--duration: duration of boxes_like must be in (0, 30] s (the "
                                                   "preset's whole motion played at speed 2)"),
])
def test_command_errors_are_one_line(args, message, capsys, pipeline_cache):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and "Traceback" not in err


def test_corrupt_recording_file_is_one_line(boxes_aps, tmp_path, capsys):
    from evio_lib.io.ecd import write_ecd

    folder = tmp_path / "rec"
    write_ecd(boxes_aps.sequence.slice_time(0.0, 1.0), folder)
    lines = (folder / "imu.txt").read_text().splitlines()
    lines[5] = "0.005 1.0 nan-ish 2.0"
    (folder / "imu.txt").write_text("\n".join(lines) + "\n")
    assert main(["run", str(folder), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "imu.txt" in err and err.count("\n") == 1


def test_table_fast_command(pipeline_cache, tmp_path, capsys):
    out = tmp_path / "table"
    assert main(["table", "--fast", "--presets", "boxes_like", "--rows", "imu", "imu_bias", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "IMU only (no bias correction)" in text and "IMU only (bias correction)" in text
    rows = json.loads((out / "table.json").read_text())
    assert [r["row"] for r in rows] == ["imu", "imu_bias"] and all(r["failed"] == 0 for r in rows)
    records = json.loads((out / "runs.json").read_text())
    assert all("aps_exposure_s" not in r for r in records)
    assert all(r["rejections"] == {} for r in records)  # IMU only: the filter drops no track


def test_aps_exposure_reaches_the_recording(pipeline_cache, tmp_path, monkeypatch, capsys):
    """--aps-exposure: run and table simulate the preset with it (the frames' times say so: the middle of each
    exposure), the run's notes and each table record name it."""
    import evio_lib.pipeline.dataset as dataset

    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))  # its own recordings: other tests count theirs
    asked = []
    real = dataset.simulate_preset
    monkeypatch.setattr(dataset, "simulate_preset", lambda *a, **kw: asked.append(kw.get("aps_exposure_s")) or real(
        *a, **kw))
    args = ["run", "boxes_like", "--duration", "1", "--aps-exposure", "0.02", "--quiet", "--no-figures", "--out",
            str(tmp_path / "run")]
    assert main(args) == 0 and asked == [0.02]
    assert "  APS exposure 20 ms (the simulator's default: 10 ms)\n" in capsys.readouterr().out
    notes = json.loads((tmp_path / "run" / "metrics.json").read_text())["notes"]
    assert "APS exposure 20 ms (the simulator's default: 10 ms)" in notes
    assert main(["table", "--fast", "--presets", "boxes_like", "--rows", "klt_aps", "--aps-exposure", "0.02",
                 "--out", str(tmp_path / "table")]) == 0
    (record,) = json.loads((tmp_path / "table" / "runs.json").read_text())
    assert record["aps_exposure_s"] == 0.02 and "error" not in record
    assert record["rejections"] and all(isinstance(n, int) and n > 0 for n in record["rejections"].values())
    assert len(asked) >= 2 and set(asked[1:]) == {0.02}  # the table's simulation and its run


def test_speed_reaches_the_recording(tmp_path, monkeypatch, capsys):
    """--speed: run and table simulate the preset played faster; the run's notes and each table record say so."""
    import evio_lib.pipeline.dataset as dataset

    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))
    asked = []
    real = dataset.simulate_preset
    monkeypatch.setattr(dataset, "simulate_preset", lambda *a, **kw: asked.append(kw.get("speed")) or real(*a, **kw))
    args = ["run", "boxes_like", "--duration", "1", "--start", "10", "--speed", "2", "--imu-only", "--quiet",
            "--no-figures", "--out", str(tmp_path / "run")]
    assert main(args) == 0 and asked == [2.0]
    assert "played at speed 2" in capsys.readouterr().out
    assert main(["table", "--fast", "--presets", "boxes_like", "--rows", "imu", "--speed", "2", "--out",
                 str(tmp_path / "table")]) == 0
    (record,) = json.loads((tmp_path / "table" / "runs.json").read_text())
    assert record["speed"] == 2.0 and "error" not in record
    assert set(asked[1:]) == {2.0}


def test_aggregate_is_mean_and_sample_std():
    records = [{"preset": "boxes_like", "row": "x", "label": "X", "seed": s, "rmse_m": v, "final_error_m": 2 * v,
                "percent_of_distance": 1.0, "rmse_first_half_m": v, "rmse_second_half_m": v, "realtime_factor": 3.0}
               for s, v in enumerate([1.0, 2.0, 4.0])]
    records.append({"preset": "boxes_like", "row": "x", "label": "X", "seed": 3, "error": "diverged"})
    (row,) = aggregate(records)
    assert row["rmse_m"] == pytest.approx(7 / 3) and row["rmse_m_std"] == pytest.approx(np.std([1, 2, 4], ddof=1))
    assert row["failed"] == 1 and row["errors"] == ["diverged"]
    assert "2.333 ± 1.528" in format_table6([row]) and "3 (1 failed)" in format_table6([row])


def test_table_rows():
    assert "cnn_events_trained" not in [r.key for r in table_rows()]
    trained = table_rows(["cnn_events_trained"], events_cnn="net.pt")
    assert trained[0].options[-1] == ("detector_options", (("weights", "net.pt"),)) and trained[0].needs_events
    assert isinstance(trained[0], TableRow)
    with pytest.raises(ValueError, match="unknown table row"):
        table_rows(["nope"])


def test_table_rows_take_a_reconstructor_precision_and_the_table_names_it():
    """--reconstructor-precision lands on the rows that reconstruct event frames only; a run records the precision
    its reconstructor computed in (what "auto" chose), and the table names it beside the row."""
    rows = {r.key: r for r in table_rows(["sift_aps", "sift_events", "klt_mc_events", "klt_events"],
                                         reconstructor_precision="float32")}
    assert dict(rows["sift_events"].options)["reconstructor_precision"] == "float32"
    assert dict(rows["klt_events"].options)["reconstructor_precision"] == "float32"
    assert "reconstructor_precision" not in dict(rows["sift_aps"].options)
    assert "reconstructor_precision" not in dict(rows["klt_mc_events"].options)  # no reconstructor there
    assert {k: r.uses_reconstructed_frames for k, r in rows.items()} == {
        "sift_aps": False, "sift_events": True, "klt_mc_events": False, "klt_events": True}
    records = [{"preset": "boxes_like", "row": "sift_events", "label": "SIFT, event frames", "seed": s,
                "rmse_m": 1.0 + s, "reconstructor_precision": "int8"} for s in (0, 1)]
    row = aggregate(records)[0]
    assert row["reconstructor_precision"] == "int8"
    assert "| SIFT, event frames (int8) | 1.500 ± 0.707 |" in format_table6([row])
    plain = aggregate([{k: v for k, v in r.items() if k != "reconstructor_precision"} for r in records])[0]
    assert "reconstructor_precision" not in plain and "| SIFT, event frames | 1.500" in format_table6([plain])


def test_a_ground_truth_shorter_than_the_run_writes_everything_over_the_overlap(short_run, boxes_aps, tmp_path):
    import copy

    cut = copy.copy(short_run)
    n = len(cut.t)
    inside = np.arange(n) < int(0.6 * n)              # the ground truth ends at 60 % of the frames
    cut.truth = {k: np.where(inside.reshape(-1, *([1] * (v.ndim - 1))), v, np.nan) for k, v in short_run.truth.items()}
    out = write_run(cut, boxes_aps, tmp_path / "run", figures=True)
    t_gt, p_gt, q_gt = read_tum(out / "groundtruth.txt")
    assert len(t_gt) == inside.sum() and np.isfinite(p_gt).all() and np.isfinite(q_gt).all()
    np.testing.assert_array_equal(t_gt, cut.t[inside])
    assert len(read_tum(out / "trajectory.txt")[0]) == n   # the estimate keeps every frame
    assert len(list((out / "figures").glob("*.png"))) == 7
    assert json.loads((out / "metrics.json").read_text())["output_problems"] == []


def test_a_figure_that_fails_is_left_out_and_named(short_run, boxes_aps, tmp_path, monkeypatch):
    from evio_lib.evaluation import plots_pipeline

    def broken(*args, **kwargs):
        raise ValueError("cannot draw")

    monkeypatch.setattr(plots_pipeline, "plot_tracking_statistics", broken)
    out = write_run(short_run, boxes_aps, tmp_path / "run", figures=True)
    assert len(list((out / "figures").glob("*.png"))) == 6 and not (out / "figures" / "tracking.png").exists()
    record = json.loads((out / "metrics.json").read_text())
    assert record["output_problems"] == ["figures/tracking.png: cannot draw"]
    assert (out / "trajectory.txt").is_file() and (out / "summary.txt").is_file()
