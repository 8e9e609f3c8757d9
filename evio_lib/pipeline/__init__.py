"""The complete EVIO pipeline: a recording -> frames (APS or reconstructed from events) -> feature tracks -> MSCKF.

    from evio_lib.pipeline import load_dataset, PipelineConfig, run_pipeline, write_run
    data = load_dataset("boxes_like")                       # a preset (simulated, cached), an ECD or a EuRoC folder
    result = run_pipeline(data, PipelineConfig(frames="aps", features="sift"))
    print(result.summary()); write_run(result, data, "runs/boxes")   # TUM trajectory, metrics.json, figures

Modules: ``dataset`` (what DATASET means, extrinsics, IMU noise), ``frames`` (the frame source), ``run`` (the chain
and its metrics), ``output`` (the run's folder), ``table`` (thesis Table 6 over configurations and seeds), ``command``
(``python -m evio_lib run`` and ``table``). Reference: thesis §4.5.
"""
from evio_lib.pipeline.dataset import PRESETS, LoadedDataset, load_dataset, read_kalibr_extrinsics, simulate_preset
from evio_lib.pipeline.run import INIT_MODES, PipelineConfig, PipelineResult, run_pipeline

__all__ = ["PRESETS", "LoadedDataset", "load_dataset", "read_kalibr_extrinsics", "simulate_preset", "INIT_MODES",
           "PipelineConfig", "PipelineResult", "run_pipeline"]
