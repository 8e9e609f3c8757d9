"""examples/homework.py runs as a student runs it: a short recording, its TUM files, its figure and its table.

The RMSE each table row prints is recomputed here from the files alone (each trajectory against groundtruth.txt,
linearly interpolated at its times), so the table, the files and the body they hold are checked against each other.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from evio_lib.io.tum import read_tum

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SCRIPT = PROJECT_ROOT / "examples" / "homework.py"
RUNS = ("msckf_perfect_tracks", "imu_only", "sift_aps", "klt_mc_events", "sift_aps_gyro_noise_x10")


def _run(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, MPLBACKEND="Agg", EVIO_CACHE_DIR=str(tmp_path / "cache"),  # a cold cache: simulated here
               PYTHONPATH=os.pathsep.join(filter(None, [str(PROJECT_ROOT), os.environ.get("PYTHONPATH")])))
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600)


def _table(stdout: str) -> dict[str, tuple[float, str]]:
    """{run: (RMSE, % of distance as printed)} from the Markdown table's rows."""
    rows = [line.strip("|").split("|") for line in stdout.splitlines() if line.startswith("| ")]
    assert [cell.strip() for cell in rows[0]] == ["run", "RMSE [m]", "% of distance"], stdout
    return {name.strip(): (float(rmse), percent.strip()) for name, rmse, percent in rows[1:]}


def test_homework_writes_the_files_and_one_row_per_run(tmp_path):
    done = _run(tmp_path, "--duration", "2", "--out", "out")
    assert done.returncode == 0, done.stderr[-3000:]
    out = tmp_path / "out"
    table = _table(done.stdout)
    assert list(table) == list(RUNS)
    assert sorted(p.name for p in out.iterdir()) == sorted([*(f"{r}.txt" for r in RUNS), "groundtruth.txt",
                                                           "count_frame.png"])
    assert (out / "count_frame.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    t_gt, p_gt, q_gt = read_tum(out / "groundtruth.txt")
    assert np.all(np.isfinite(p_gt)) and np.all(np.isfinite(q_gt)) and t_gt[-1] >= 1.9
    for run in RUNS:
        t, p, q = read_tum(out / f"{run}.txt")
        assert len(t) > 20 and np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(q)), run
        assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6), run
        assert (out / f"{run}.txt").read_text().startswith("# timestamp tx ty tz qx qy qz qw: pose of the IMU frame I")
        truth = np.column_stack([np.interp(t, t_gt, p_gt[:, i]) for i in range(3)])
        rmse = float(np.sqrt(np.mean(np.sum((truth - p) ** 2, axis=1))))
        assert rmse == pytest.approx(table[run][0], rel=0.01, abs=1e-4), run  # printed to 3 significant digits
    assert table["msckf_perfect_tracks"][0] < table["imu_only"][0] / 2  # the tracks bound the IMU's drift


@pytest.mark.parametrize("args, message", [
    (("--duration", "1"), "duration must be"),            # the perfect-track experiment needs 2 s
    (("--duration", "61"), "duration of boxes_like must be in (0, 60]"),
    (("--duration", "two"), "invalid float value"),
    (("--out", "full"), "already exists and is not empty; use --force"),
])
def test_homework_refuses_bad_input_in_one_line(tmp_path, args, message):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("mine\n")
    done = _run(tmp_path, *args)
    assert done.returncode == 2 and done.stdout == ""
    assert re.fullmatch(r"error: [^\n]+\n", done.stderr) and message in done.stderr, done.stderr
    assert (tmp_path / "full" / "keep.txt").read_text() == "mine\n"
