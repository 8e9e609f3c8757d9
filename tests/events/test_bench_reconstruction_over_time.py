"""bench/reconstruction_over_time.py: SSIM against the window index over a held-out stretch, and its refusals."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

from evio_lib.events.reconstruction.evaluation import linear_light_room_sequence

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
    monkeypatch.setattr(sys, "argv", ["x", "--methods", "direct", "high_pass", "--points", "4", "--stretch",
                                      "aerial_like", "--fraction", "0.02"])
    bench.main()
    lines = capsys.readouterr().out.strip().splitlines()
    assert asked == [("aerial_like", 202)]                            # the validation stretch by default
    assert lines[0].startswith("aerial_like (val), n = 0.02:") and lines[1].startswith("| method | 0 | ")
    rows = [line.split("|")[1:-1] for line in lines[3:]]
    assert [row[0].strip() for row in rows] == ["direct", "high_pass"]
    assert all(len(row) == 5 and all(0 < float(v) <= 1 for v in row[1:]) for row in rows)


def test_it_refuses_bad_options_in_one_line():
    for argv, expected in ((["--points", "1"], "--points must be >= 2; got 1"),
                           (["--fraction", "0"], "--fraction must lie in (0, 10]; got 0.0")):
        result = subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, cwd=ROOT,
                                env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert result.returncode == 2 and expected in result.stderr and result.stdout == ""
