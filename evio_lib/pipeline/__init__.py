"""The complete EVIO pipeline: a recording -> frames (APS or reconstructed from events) -> feature tracks -> MSCKF.

    from evio_lib.pipeline import load_dataset, PipelineConfig, run_pipeline, write_run
    data = load_dataset("boxes_like")                       # a preset (simulated, cached), an ECD or a EuRoC folder
    result = run_pipeline(data, PipelineConfig(frames="aps", features="sift"))
    print(result.summary()); write_run(result, data, "runs/boxes")   # TUM trajectory, metrics.json, figures

Modules: ``dataset`` (what DATASET means, extrinsics, IMU noise), ``frames`` (the frame source), ``run`` (the chain
and its metrics), ``output`` (the run's folder), ``table`` (thesis Table 6 over configurations and seeds), ``command``
(``python -m evio_lib run`` and ``table``). Reference: thesis §4.5.
"""
from __future__ import annotations

from evio_lib.lazy_exports import lazy_exports

#: name -> module of the names this package offers; imported on first use (PEP 562), so that ``python -m evio_lib run
#: --help`` and the command's argument checks do not import OpenCV, torch and SciPy first.
_EXPORTS = {
    "PRESETS": "dataset", "LoadedDataset": "dataset", "load_dataset": "dataset",
    "read_kalibr_extrinsics": "dataset", "simulate_preset": "dataset",
    "INIT_MODES": "run", "PipelineConfig": "run", "PipelineResult": "run", "run_pipeline": "run",
    "run_pipelines": "run",
}

__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
