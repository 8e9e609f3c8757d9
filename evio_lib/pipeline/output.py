"""The folder a pipeline run writes (atomically: a failed write leaves nothing behind).

    trajectory.txt      TUM (t x y z qx qy qz qw): the estimated pose of the same body as the recording's ground truth
                        (the camera for ECD folders and presets, whose groundtruth.txt is the camera's pose; the IMU
                        for EuRoC, whose ground truth is the IMU's), in the filter's world frame
    trajectory_imu.txt  TUM: the IMU's estimated pose (the filter's state)
    groundtruth.txt     TUM: the ground truth of the same body at the frame times (when the recording has one), so
                        ``evo_ape tum groundtruth.txt trajectory.txt`` works as is (add ``-a`` after a static start);
                        a ground truth that covers part of the run gives the frames it covers (the overlap the
                        metrics score), never values extrapolated past its ends
    states.csv          per frame: t, p_IinG, q_GtoI (JPL, x y z w), v_IinG, b_g, b_a, and the 15 standard deviations
                        of [δθ, δb_g, δv, δb_a, δp] (3-sigma bounds are 3x these)
    tracking.csv        per frame: the front-end's counts and timings (``frontend.stats_table``)
    metrics.json        the configuration, the dataset, notes, metrics, timings, the filter's faults and rejections
    figures/            position, orientation and velocity errors with 3-sigma bounds (thesis Figs. 23-32), over the
                        overlap with the ground truth, the bias estimates with 3-sigma bounds (Appendix C), the
                        top-down trajectory, the tracking statistics

A finished run is never thrown away for a part of its output: a figure that cannot be drawn is left out, the rest is
written, and metrics.json's ``output_problems`` names each part left out and why (``run`` prints each as a warning).
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from evio_lib.geometry.rotation import rot_to_quat
from evio_lib.io.output_dir import atomic_output_dir
from evio_lib.io.tum import write_tum
from evio_lib.pipeline.dataset import LoadedDataset
from evio_lib.pipeline.run import PipelineResult

__all__ = ["write_run", "write_json", "trajectory_body", "truth_rows", "STATE_COLUMNS"]

STATE_COLUMNS = (["t", "px", "py", "pz", "qx", "qy", "qz", "qw", "vx", "vy", "vz", "bgx", "bgy", "bgz", "bax", "bay",
                  "baz"] + [f"sigma_{n}" for n in ("thx", "thy", "thz", "bgx", "bgy", "bgz", "vx", "vy", "vz", "bax",
                                                     "bay", "baz", "px", "py", "pz")])


def trajectory_body(kind: str) -> str:
    """Return the body whose pose trajectory.txt holds: 'imu' for EuRoC, else 'camera' (like the ground truth)."""
    return "imu" if kind == "euroc" else "camera"


def _json(value: Any) -> Any:
    """Return value made JSON-able (NaN and inf as None, arrays as lists, tuples as lists)."""
    if isinstance(value, dict):
        return {str(k): _json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def write_json(path: Path, value: Any) -> None:
    """Write ``value`` as indented, strict JSON (NaN and inf as null, so that every JSON reader accepts the file)."""
    path.write_text(json.dumps(_json(value), indent=2, allow_nan=False) + "\n", encoding="utf-8")


def _write_csv(path: Path, columns: list[str], data: np.ndarray) -> None:
    np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.9g")


def truth_rows(truth: dict[str, np.ndarray]) -> np.ndarray:
    """Return the boolean mask of the frames a ground truth covers (finite position and orientation); the run holds
    NaN at the frames outside the ground truth's time span."""
    p, R = truth["p_IinG"], truth["R_ItoG"]
    return np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(R.reshape(len(R), -1)), axis=1)


def write_run(result: PipelineResult, data: LoadedDataset, out: str | Path, force: bool = False,
              figures: bool = True) -> Path:
    """Write the run's folder (module docstring) to ``out``; refuse a non-empty one unless ``force``. Return it.

    A part that cannot be written is left out and named in metrics.json's ``output_problems`` ("figures/NAME.png:
    why"; an empty list when everything was written). Raises (leaving no folder) only when the folder itself cannot
    be written.
    """
    body = trajectory_body(data.kind)
    problems: list[str] = []
    with atomic_output_dir(out, force) as tmp:
        result.write_tum(tmp / "trajectory_imu.txt", body="imu")
        result.write_tum(tmp / "trajectory.txt", body=body)
        if result.truth:
            R_ItoG, p_IinG = result.truth["R_ItoG"], result.truth["p_IinG"]
            inside = truth_rows(result.truth)
            R_ItoG, p_IinG = R_ItoG[inside], p_IinG[inside]
            if body == "camera":
                R_ItoG, p_IinG = R_ItoG @ result.R_CtoI, p_IinG + R_ItoG @ result.p_CinI
            write_tum(tmp / "groundtruth.txt", result.t[inside], p_IinG, rot_to_quat(np.swapaxes(R_ItoG, -1, -2)),
                      body=body)
        states = np.column_stack([result.t, result.p_IinG, result.q_GtoI, result.v_IinG, result.b_g, result.b_a,
                                  result.sigma])
        _write_csv(tmp / "states.csv", STATE_COLUMNS, states)
        if result.tracking:
            names = list(result.tracking)
            _write_csv(tmp / "tracking.csv", names, np.column_stack([result.tracking[n].astype(float) for n in names]))
        if figures:
            problems = save_figures(result, tmp / "figures")
        record = {
            "config": dataclasses.asdict(result.config), "label": result.config.label(), "dataset": result.dataset,
            "trajectory_body": body, "notes": result.notes, "metrics": result.metrics, "timings": result.timings,
            "faults": result.faults, "rejections": result.rejections,
            "tracking_mean": {k: float(np.mean(v)) for k, v in result.tracking.items() if k != "t"},
            "track_length_mean": float(np.mean(result.track_lengths)) if len(result.track_lengths) else None,
            "output_problems": problems,
        }
        write_json(tmp / "metrics.json", record)
        (tmp / "summary.txt").write_text(result.summary() + "\n" + "\n".join(result.notes) + "\n", encoding="utf-8")
    return Path(out)


def save_figures(result: PipelineResult, folder: Path) -> list[str]:
    """Save the run's figures as PNG files in ``folder``; return the figures left out, each "figures/NAME.png: why".

    The error figures cover the frames the ground truth covers. A figure that fails to draw or save is left out (and
    closed); the others are still saved."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from evio_lib.evaluation import plots_pipeline as pp
    from evio_lib.geometry.rotation import so3_log

    folder.mkdir(parents=True, exist_ok=True)
    t = result.t - result.t[0]
    truth = result.truth
    builders: dict[str, Any] = {}
    if truth:
        k = truth_rows(truth)                          # the frames the ground truth covers
        builders["position_errors"] = lambda: pp.plot_state_errors(
            t[k], truth["p_IinG"][k] - result.p_IinG[k], result.sigma[k, 12:15], quantity="position", unit="m")

        def orientation():
            # the filter's attitude error, in I: q_true = δq ⊗ q_est, C(δq) = I - [δθ]x, so δθ = log(R_est^T R_true)
            # with R = R_ItoG; its standard deviations are the filter's sigma[0:3] (same frame)
            dR = np.einsum("nji,njk->nik", result.R_ItoG[k], truth["R_ItoG"][k])
            err = np.degrees(np.array([so3_log(R) for R in dR])).reshape(-1, 3)
            return pp.plot_state_errors(t[k], err, np.degrees(result.sigma[k, 0:3]), quantity="orientation",
                                        unit="deg")

        builders["orientation_errors"] = orientation
        if "v_IinG" in truth:
            builders["velocity_errors"] = lambda: pp.plot_state_errors(
                t[k], truth["v_IinG"][k] - result.v_IinG[k], result.sigma[k, 6:9], quantity="velocity", unit="m/s")
    builders["gyro_bias"] = lambda: pp.plot_bias_estimates(t, result.b_g, result.sigma[:, 3:6], truth.get("b_g"),
                                                           kind="gyro")
    builders["accel_bias"] = lambda: pp.plot_bias_estimates(t, result.b_a, result.sigma[:, 9:12], truth.get("b_a"),
                                                            kind="accel")
    builders["trajectory_topdown"] = lambda: pp.plot_trajectory_topdown({result.config.label(): result.p_IinG},
                                                                        truth.get("p_IinG"))
    if result.tracking:
        builders["tracking"] = lambda: pp.plot_tracking_statistics(result.tracking, track_lengths=result.track_lengths)
    problems = []
    for name, build in builders.items():
        fig = None
        try:
            fig = build()
            fig.savefig(folder / f"{name}.png", dpi=110, bbox_inches="tight")
        except (ValueError, TypeError, IndexError, FloatingPointError, OverflowError, RuntimeError, OSError) as error:
            (folder / f"{name}.png").unlink(missing_ok=True)
            first = (str(error).strip().splitlines() or [type(error).__name__])[0]
            problems.append(f"figures/{name}.png: {first}")
        finally:
            if fig is not None:
                plt.close(fig)
    return problems
