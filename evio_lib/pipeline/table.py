"""The thesis's Table 6 on the simulated presets: every configuration, several seeds, mean and spread.

Rows (thesis Table 6, plus the KLT front-end of msckf_vio / OpenVINS as a baseline):

- IMU only, without bias correction (biases start at zero) and with it (biases start at the ground truth's at the
  first frame; the thesis estimated them by hand from a still stretch, the simulator knows them exactly);
- SIFT on APS frames, the CNN (the shipped SuperPoint-style network) on APS frames, KLT + FAST on APS frames; when
  named, the half-width network distilled from the CNN (``distilled_narrow``, not in the thesis) on APS frames;
- SIFT on event frames and the CNN on event frames (FireNet reconstructions of windows of n H W events, the
  thesis's n per preset);
- the CNN trained with event frames, when a checkpoint is given (``events_cnn``); none is shipped yet, and the
  row then says so instead of a number;
- KLT + FAST on the FireNet event frames, and SIFT, the CNN and KLT + FAST on motion-compensated event frames
  (``mc-events``: each window's events warped with the gyroscope's rotation and counted, Rebecq et al. 2017);
- KLT + FAST on both the APS frames and the motion-compensated event frames, fused by the filter (Ultimate SLAM's
  frames + events + IMU).

Each (preset, row, seed) job is a pure function of its arguments (:func:`table_job`: it loads the simulated
recording from the cache, or simulates it, runs the pipeline and returns a dict of numbers), run through joblib
(``jobs``), so joblib's Dask or Ray backend can spread a large sweep over a cluster unchanged
(``with joblib.parallel_config(backend="dask"): run_table(...)``). The recordings are simulated first, one job per
(preset, seed), so two jobs never simulate the same one.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from evio_lib.pipeline.dataset import PRESETS, check_preset_duration, check_speed, preset_length
from evio_lib.pipeline.frames import frame_streams

__all__ = ["TABLE_ROWS", "OPTIONAL_ROWS", "TableRow", "table_rows", "table_job", "run_table", "aggregate",
           "format_table6"]


@dataclass(frozen=True)
class TableRow:
    """One row of Table 6: a label and the PipelineConfig fields that make it."""

    key: str
    label: str
    options: tuple[tuple[str, Any], ...]

    @property
    def needs_events(self) -> bool:
        return dict(self.options).get("frames", "aps") != "aps"

    @property
    def uses_reconstructed_frames(self) -> bool:
        """Return True when the row's runs reconstruct event frames with a reconstructor (frames "events")."""
        return "events" in frame_streams(dict(self.options).get("frames", "aps"))

    @property
    def uses_aps_frames(self) -> bool:
        """Return True when the row's runs read the APS frames (IMU-only rows and event-only sources do not)."""
        options = dict(self.options)
        return "aps" in frame_streams(options.get("frames", "aps")) and not options.get("imu_only", False)


TABLE_ROWS = (
    TableRow("imu", "IMU only (no bias correction)", (("imu_only", True),)),
    TableRow("imu_bias", "IMU only (bias correction)", (("imu_only", True), ("bias_init", "groundtruth"))),
    TableRow("sift_aps", "SIFT, APS frames", (("features", "sift"),)),
    TableRow("sift_aps_gap2", "SIFT, APS frames, tracks surviving 2 missed frames",
             (("features", "sift"), ("max_track_gap", 2))),
    TableRow("cnn_aps", "CNN, APS frames", (("features", "superpoint"),)),
    TableRow("cnn_aps_far", "CNN, APS frames, far points always",
             (("features", "superpoint"), ("far_points", True))),
    TableRow("cnn_narrow_aps", "CNN (distilled, half width), APS frames",
             (("features", "superpoint"), ("detector_options", (("weights", "distilled_narrow"),)))),
    TableRow("sift_events", "SIFT, event frames", (("features", "sift"), ("frames", "events"))),
    TableRow("cnn_events", "CNN, event frames", (("features", "superpoint"), ("frames", "events"))),
    TableRow("cnn_events_trained", "CNN trained with event frames, event frames",
             (("features", "superpoint"), ("frames", "events"))),
    TableRow("klt_aps", "KLT + FAST, APS frames (baseline)", (("tracker", "klt"), ("features", "fast"))),
    TableRow("klt_events", "KLT + FAST, event frames",
             (("tracker", "klt"), ("features", "fast"), ("frames", "events"))),
    TableRow("sift_mc_events", "SIFT, motion-compensated event frames",
             (("features", "sift"), ("frames", "mc-events"))),
    TableRow("sift_mc_events_gap2", "SIFT, motion-compensated event frames, tracks surviving 2 missed frames",
             (("features", "sift"), ("frames", "mc-events"), ("max_track_gap", 2))),
    TableRow("cnn_mc_events", "CNN, motion-compensated event frames",
             (("features", "superpoint"), ("frames", "mc-events"))),
    TableRow("cnn_mc_events_far", "CNN, motion-compensated event frames, far points always",
             (("features", "superpoint"), ("frames", "mc-events"), ("far_points", True))),
    TableRow("klt_mc_events", "KLT + FAST, motion-compensated event frames",
             (("tracker", "klt"), ("features", "fast"), ("frames", "mc-events"))),
    TableRow("klt_aps_mc_events", "KLT + FAST, APS + motion-compensated event frames",
             (("tracker", "klt"), ("features", "fast"), ("frames", "aps+mc-events"))),
)


#: Rows run only when named (``keys``): beside the thesis's configurations, not part of the default table.
OPTIONAL_ROWS = ("cnn_narrow_aps", "sift_aps_gap2", "sift_mc_events_gap2", "cnn_aps_far", "cnn_mc_events_far")


def table_rows(keys: Sequence[str] | None = None, events_cnn: str | None = None,
               reconstructor_precision: str | None = None) -> list[TableRow]:
    """Return the rows to run: ``keys`` (default all but :data:`OPTIONAL_ROWS`) in table order; the events-trained
    CNN row only with a checkpoint; ``reconstructor_precision`` (one of ``PRECISIONS``; None: the runs' default,
    "auto") set on every row that reconstructs event frames."""
    known = [r.key for r in TABLE_ROWS]
    if keys is not None:
        unknown = [k for k in keys if k not in known]
        if unknown:
            raise ValueError(f"unknown table row(s) {unknown}; choose from {known}")
    rows = []
    for row in TABLE_ROWS:
        if keys is not None and row.key not in keys:
            continue
        if keys is None and row.key in OPTIONAL_ROWS:
            continue
        if row.key == "cnn_events_trained":
            if events_cnn is None:
                continue
            row = TableRow(row.key, row.label, row.options + (("detector_options", (("weights", str(events_cnn)),)),))
        if reconstructor_precision is not None and row.uses_reconstructed_frames:
            row = TableRow(row.key, row.label, row.options + (("reconstructor_precision", reconstructor_precision),))
        rows.append(row)
    return rows



def _simulate(preset: str, duration: float, seed: int, with_events: bool, aps_exposure_s: float | None = None,
              speed: float = 1.0) -> None:
    from evio_lib.pipeline.dataset import simulate_preset

    simulate_preset(preset, duration, seed, with_events=with_events, jobs=1,  # the jobs of the table run in parallel
                    aps_exposure_s=aps_exposure_s, speed=speed)


def table_job(preset: str, duration: float, seed: int, row: TableRow, threads: int = 1,
              aps_exposure_s: float | None = None, speed: float = 1.0) -> dict[str, Any]:
    """Return the numbers of one (preset, row, seed) run: metrics, timings and tracking means (a pure function).

    ``aps_exposure_s``: the simulated APS frames' exposure time (None: the simulator's 10 ms; recorded when set).
    ``speed``: the preset's motion played this many times faster (recorded when not 1).

    A run that fails (e.g. the filter diverges to a refused state) returns its error message under "error"
    instead of numbers, so one bad seed does not lose the rest of the table.
    """
    from evio_lib.pipeline.dataset import load_dataset
    from evio_lib.pipeline.run import PipelineConfig, run_pipeline, set_threads

    set_threads(threads)
    config = PipelineConfig(seed=seed, **dict(row.options))
    record: dict[str, Any] = {"preset": preset, "row": row.key, "label": row.label, "seed": seed,
                              "duration_s": duration}
    if aps_exposure_s is not None:
        record["aps_exposure_s"] = aps_exposure_s
    if speed != 1.0:
        record["speed"] = speed
    start = time.perf_counter()
    try:
        data = load_dataset(preset, duration=duration, seed=seed, need_events=row.needs_events,
                            need_frames=True, aps_exposure_s=aps_exposure_s, speed=speed)
        result = run_pipeline(data, config)
    except (ValueError, OSError) as error:  # a bad input of this row (e.g. its checkpoint): the row's error
        record["error"] = (str(error).splitlines() or [type(error).__name__])[0]
        return record
    except Exception as error:  # anything else fails this row only, named by its type so that a bug stays visible
        record["error"] = f"{type(error).__name__}: {(str(error).splitlines() or [''])[0]}"
        return record
    if result.reconstructor_precision is not None:
        record["reconstructor_precision"] = result.reconstructor_precision  # e.g. int8, where "auto" chose it
    record.update({k: v for k, v in result.metrics.items() if isinstance(v, (int, float))})
    record["realtime_factor"] = result.timings["realtime_factor"]
    record["wall_s"] = time.perf_counter() - start
    record.update({f"time_{k}_s": v for k, v in result.timings.items() if k not in ("realtime_factor",)})
    if result.tracking:
        record["tracked_per_frame"] = float(np.mean(result.tracking["tracked"]))
        record["mean_track_length"] = float(np.mean(result.track_lengths)) if len(result.track_lengths) else 0.0
    record["faults"] = int(sum(result.faults.values()))
    record["rejections"] = {k: int(v) for k, v in sorted(result.rejections.items())}  # the filter's, by reason
    return record


def run_table(presets: Sequence[str] = PRESETS, seeds: Sequence[int] = (0, 1, 2), rows: Sequence[TableRow] | None = None,
              durations: dict[str, float] | None = None, jobs: int = 1, progress: bool = True,
              aps_exposure_s: float | None = None, speed: float = 1.0) -> list[dict[str, Any]]:
    """Return one record per (preset, row, seed) (:func:`table_job`), run with ``jobs`` joblib workers.

    Args:
        presets: preset names; seeds: simulation (and front-end) seeds; rows: default :func:`table_rows`.
        durations: seconds per preset (default the whole presets, 60 s and 40 s, divided by ``speed``).
        jobs: joblib workers (processes); each uses one thread.
        aps_exposure_s: the simulated APS frames' exposure time, s (None: the simulator's 10 ms).
        speed: every preset's motion played this many times faster (:func:`evio_lib.pipeline.dataset.simulate_preset`).
    """
    from joblib import Parallel, delayed

    rows = table_rows() if rows is None else list(rows)
    for preset in presets:
        if preset not in PRESETS:
            raise ValueError(f"preset must be one of {PRESETS}; got {preset!r}")
    speed = check_speed(speed)
    durations = {p: preset_length(p, speed) for p in presets} | (durations or {})
    for preset in presets:  # before any worker starts: a bad duration is one error, not one per job
        check_preset_duration(preset, durations[preset], speed)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be an integer >= 1; got {jobs!r}")
    if aps_exposure_s is not None:
        from evio_lib.pipeline.dataset import check_aps_exposure

        aps_exposure_s = check_aps_exposure(aps_exposure_s)
    events = any(r.needs_events for r in rows)
    sims = [(p, durations[p], s, events, aps_exposure_s, speed) for p in presets for s in seeds]
    runs = [(p, durations[p], s, r, 1, aps_exposure_s, speed) for p in presets for r in rows for s in seeds]
    verbose = 5 if progress else 0
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        Parallel(n_jobs=jobs, verbose=verbose)(delayed(_simulate)(*args) for args in sims)
        return Parallel(n_jobs=jobs, verbose=verbose)(delayed(table_job)(*args) for args in runs)
    except Exception as error:
        _raise_interruption_behind(error)
        raise


def _raise_interruption_behind(error: BaseException) -> None:
    """Re-raise the Ctrl-C or SIGTERM behind ``error``, if any.

    joblib, interrupted while it dispatches, can fail in its own clean-up (an AttributeError raised while handling
    the KeyboardInterrupt); the user pressed Ctrl-C, so the command must say "interrupted", not show joblib's bug.
    """
    seen = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, KeyboardInterrupt):
            raise cause from None
        cause = cause.__cause__ or cause.__context__


def aggregate(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Return one row per (preset, row) with mean and standard deviation over seeds of each metric."""
    keys = ("rmse_m", "final_error_m", "percent_of_distance", "rmse_first_half_m", "rmse_second_half_m",
            "ate_se3_m", "orientation_rmse_deg", "relative_translation_percent", "realtime_factor",
            "tracked_per_frame", "mean_track_length")
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault((r["preset"], r["row"]), []).append(r)
    out = []
    for (preset, row), runs in groups.items():
        ok = [r for r in runs if "error" not in r]
        agg: dict[str, Any] = {"preset": preset, "row": row, "label": runs[0]["label"], "seeds": len(runs),
                               "failed": len(runs) - len(ok),
                               "errors": sorted({r["error"] for r in runs if "error" in r})}
        precisions = sorted({r["reconstructor_precision"] for r in ok if "reconstructor_precision" in r})
        if precisions:
            agg["reconstructor_precision"] = "/".join(precisions)
        for k in keys:
            values = np.array([r[k] for r in ok if k in r and r[k] is not None], dtype=float)
            values = values[np.isfinite(values)]
            agg[k] = float(values.mean()) if values.size else float("nan")
            agg[k + "_std"] = float(values.std(ddof=1)) if values.size > 1 else float("nan")
        out.append(agg)
    return out


def _cell(mean: float, std: float, digits: int) -> str:
    if not math.isfinite(mean):
        return "-"
    return f"{mean:.{digits}f}" + (f" ± {std:.{digits}f}" if math.isfinite(std) else "")


def format_table6(rows: Sequence[dict[str, Any]]) -> str:
    """Return the aggregated rows as a Markdown table, one block per preset (mean ± std over seeds)."""
    lines = []
    for preset in dict.fromkeys(r["preset"] for r in rows):
        lines += [f"**{preset}**", "",
                  "| configuration | RMSE [m] | final error [m] | % of distance | RMSE 1st / 2nd half [m] | real-time factor "
                  "| seeds |", "|---|---|---|---|---|---|---|"]
        for r in (r for r in rows if r["preset"] == preset):
            halves = f"{_cell(r['rmse_first_half_m'], float('nan'), 3)} / {_cell(r['rmse_second_half_m'], float('nan'), 3)}"
            seeds = f"{r['seeds'] - r['failed']}" + (f" ({r['failed']} failed)" if r["failed"] else "")
            label = r["label"] + (f" ({r['reconstructor_precision']})" if r.get("reconstructor_precision") else "")
            lines.append(f"| {label} | {_cell(r['rmse_m'], r['rmse_m_std'], 3)} | "
                         f"{_cell(r['final_error_m'], r['final_error_m_std'], 3)} | "
                         f"{_cell(r['percent_of_distance'], r['percent_of_distance_std'], 2)} | {halves} | "
                         f"{_cell(r['realtime_factor'], float('nan'), 2)}x | {seeds} |")
        lines.append("")
    return "\n".join(lines)
