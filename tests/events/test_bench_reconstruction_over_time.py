"""bench/reconstruction_over_time.py: SSIM against the window index over a held-out stretch, and its refusals."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from evio_lib.events.reconstruct import create_reconstructor, reconstruct_windows
from evio_lib.events.reconstruction.evaluation import image_quality, linear_light_room_sequence
from evio_lib.events.representations import count_windows, window_size_from_fraction

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "bench" / "reconstruction_over_time.py"


def _bench():
    spec = importlib.util.spec_from_file_location("reconstruction_over_time", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_it_prints_one_score_per_window_index_and_method(tmp_path, monkeypatch, capsys, make_photo_folder):
    sequence = linear_light_room_sequence(303, "val", photos=make_photo_folder(tmp_path / "photos"), duration=0.1,
                                          render_rate_hz=300)
    bench = _bench()
    asked = []
    monkeypatch.setattr(bench, "simulated_eval_sequence",
                        lambda stretch, seed: asked.append((stretch, seed)) or sequence)
    bounds = count_windows(sequence.events, window_size_from_fraction(0.02, sequence.width, sequence.height))
    assert len(bounds) == 17
    frames, times = reconstruct_windows(create_reconstructor("high_pass", sequence.width, sequence.height),
                                        sequence.events, bounds)
    expected = [f"{image_quality(frames[k], sequence.render(float(times[k])))['ssim']:.2f}" for k in (0, 5, 11, 16)]
    for split, seed, points, columns in (("val", 202, "4", "0 | 5 | 11 | 16"),
                                         ("test", 101, "40", " | ".join(str(k) for k in range(17)))):
        monkeypatch.setattr(sys, "argv", ["x", "--methods", "direct", "high_pass", "--points", points, "--stretch",
                                          "aerial_like", "--fraction", "0.02", "--split", split])
        bench.main()
        lines = capsys.readouterr().out.strip().splitlines()
        assert asked[-1] == ("aerial_like", seed)
        assert lines[0] == f"aerial_like ({split}), n = 0.02: 17 windows of {sequence.events.size:,} events; " \
                           f"SSIM at each window index"
        assert lines[1] == f"| method | {columns} |"                # at most every window, each once
        rows = [line.split("|")[1:-1] for line in lines[3:]]
        assert [row[0].strip() for row in rows] == ["direct", "high_pass"]
        assert all(0 < float(v) <= 1 for row in rows for v in row[1:])
    assert [rows[1][1 + k].strip() for k in (0, 5, 11, 16)] == expected       # the last run: every window


def test_it_refuses_bad_options_in_one_line():
    for argv, expected in ((["--points", "1"], "error: --points must be >= 2; got 1"),
                           (["--fraction", "0"], "error: --fraction must lie in (0, 10]; got 0.0")):
        result = subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, cwd=ROOT,
                                env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert result.returncode == 2 and result.stderr.strip().splitlines()[-1].endswith(expected)
        assert result.stdout == ""


def test_it_refuses_a_stretch_without_a_window_and_an_unknown_method(tmp_path, monkeypatch, capsys,
                                                                      make_photo_folder):
    sequence = linear_light_room_sequence(303, "val", photos=make_photo_folder(tmp_path / "photos"), duration=0.1,
                                          render_rate_hz=300)
    bench = _bench()
    monkeypatch.setattr(bench, "simulated_eval_sequence", lambda stretch, seed: sequence)
    for argv, expected in ((["--fraction", "10"], "not one window"), (["--methods", "nope"], "error: ")):
        monkeypatch.setattr(sys, "argv", ["x", *argv])
        with pytest.raises(SystemExit) as stop:
            bench.main()
        out, err = capsys.readouterr()
        assert stop.value.code == 2 and out == "" and expected in err.strip().splitlines()[-1]


def test_start_window_feeds_the_later_windows_from_an_empty_state(tmp_path, monkeypatch, capsys, make_photo_folder):
    sequence = linear_light_room_sequence(303, "val", photos=make_photo_folder(tmp_path / "photos"), duration=0.1,
                                          render_rate_hz=300)
    bench = _bench()
    monkeypatch.setattr(bench, "simulated_eval_sequence", lambda stretch, seed: sequence)
    bounds = count_windows(sequence.events, window_size_from_fraction(0.02, sequence.width, sequence.height))
    fresh, times = reconstruct_windows(create_reconstructor("high_pass", sequence.width, sequence.height),
                                       sequence.events, bounds[10:])
    expected = [f"{image_quality(frames, sequence.render(float(t)))['ssim']:.2f}" for frames, t in zip(fresh, times)]
    monkeypatch.setattr(sys, "argv", ["x", "--methods", "high_pass", "--points", "40", "--fraction", "0.02",
                                      "--start-window", "10"])
    bench.main()
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].endswith("17 windows of " f"{sequence.events.size:,} events, fed from window 10; SSIM at each "
                             "window index")
    assert lines[1] == "| method | " + " | ".join(str(k) for k in range(10, 17)) + " |"   # the whole stretch's indices
    assert [v.strip() for v in lines[3].split("|")[2:-1]] == expected
    for start, expected in (("17", "error: --start-window 17: the stretch has 17 windows at n = 0.02 (indices 0-16)"),
                            ("-1", "error: --start-window must be >= 0; got -1")):
        monkeypatch.setattr(sys, "argv", ["x", "--fraction", "0.02", "--start-window", start])
        with pytest.raises(SystemExit) as stop:
            bench.main()
        out, err = capsys.readouterr()
        assert stop.value.code == 2 and out == "" and err.strip().splitlines()[-1].endswith(expected)
