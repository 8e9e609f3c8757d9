"""Realism of the simulated APS frames: their noise against the real DAVIS240C frames, and what it does to the pipeline.

1. Noise. Immerkaer's estimator (1996: sigma = sqrt(pi / 2) / 6 * mean |I * N| with the 3 x 3 Laplacian-difference
   kernel N = [[1, -2, 1], [-2, 4, -2], [1, -2, 1]]), averaged over the flattest half of each image (the pixels with
   the smallest gradient, so that edges do not count as noise), median over frames, in grey levels (DN, 0-255). It is
   run on the real frames of ECD slider_depth (``../shared/data/real/ecd_slider_depth_slice/images``), on the
   simulated frames of both presets as shipped (the noise matched to the real frames), on frames
   simulated with another noise (``--read-noise``, ``--shot-noise``; default: the model used before, read noise 0.01
   and shot-noise scale 0.003) and without noise (the estimator's floor: what texture alone gives).
2. With ``--pipeline``: the whole preset is simulated again (frames only, same seed, so the same motion, scene and
   IMU) with that other noise, and SIFT and KLT on APS frames run on both.

Usage: python bench/aps_realism.py [--pipeline --preset boxes_like --seed 3]
Measured figures: docs/results/pipeline.md#the-simulated-aps-frames-against-real-ones, "APS realism".
"""
import argparse
import dataclasses
import os
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline  # noqa: E402
from evio_lib.pipeline.dataset import PRESET_DURATIONS  # noqa: E402
from evio_lib.sim.aps import ApsParams  # noqa: E402
from evio_lib.sim.presets import SimulationConfig, simulate_sequence  # noqa: E402

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "ecd_slider_depth_slice" / "images"
KERNEL = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)


def noise_dn(image: np.ndarray) -> float:
    """Return Immerkaer's noise estimate of a uint8 image over its flattest half, in grey levels."""
    f = image.astype(np.float32)
    lap = np.abs(cv2.filter2D(f, -1, KERNEL))[1:-1, 1:-1]
    grad = (np.abs(cv2.Sobel(f, cv2.CV_32F, 1, 0)) + np.abs(cv2.Sobel(f, cv2.CV_32F, 0, 1)))[1:-1, 1:-1]
    flat = grad <= np.quantile(grad, 0.5)
    return float(np.sqrt(np.pi / 2) / 6 * lap[flat].mean())


def describe(name: str, frames) -> None:
    frames = list(frames)
    print(f"{name:<34} noise {np.median([noise_dn(f) for f in frames]):5.2f} DN, mean {np.mean(frames):6.1f}, "
          f"std {np.mean([f.std() for f in frames]):5.1f} ({len(frames)} frames)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pipeline", action="store_true", help="also run SIFT and KLT on the other noise's frames")
    parser.add_argument("--preset", default="boxes_like", choices=["boxes_like", "aerial_like"])
    parser.add_argument("--seed", type=int, default=3, help="the pipeline comparison's seed (default 3: validation)")
    parser.add_argument("--read-noise", type=float, default=0.01,
                        help="read noise of the other frames (default 0.01: the earlier, noisier model)")
    parser.add_argument("--shot-noise", type=float, default=0.003,
                        help="shot-noise scale of the other frames (default 0.003: the earlier, noisier model)")
    args = parser.parse_args()
    if REAL.is_dir():
        describe("real DAVIS240C, ECD slider_depth", (cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
                                                      for f in sorted(REAL.glob("*.png"))))
    for preset in ("boxes_like", "aerial_like"):
        describe(f"simulated {preset}, as shipped", load_dataset(preset, duration=5.0).sequence.frames[::4])
    for label, aps in (("no noise", ApsParams(read_noise_sigma=0.0, shot_noise_scale=0.0)),
                       ("other noise", ApsParams(read_noise_sigma=args.read_noise, shot_noise_scale=args.shot_noise))):
        config = SimulationConfig(preset="boxes_like", duration=2.0, trajectory_duration=60.0, seed=0, aps=aps)
        describe(f"simulated boxes_like, {label}", simulate_sequence(config, jobs=1).frames[::4])
    if not args.pipeline:
        return
    full = PRESET_DURATIONS[args.preset]
    shipped = load_dataset(args.preset, seed=args.seed)
    config = SimulationConfig(preset=args.preset, duration=full, trajectory_duration=full, seed=args.seed,
                              aps=ApsParams(read_noise_sigma=args.read_noise, shot_noise_scale=args.shot_noise))
    other = dataclasses.replace(shipped, sequence=simulate_sequence(config))
    if not np.array_equal(other.sequence.imu.gyro, shipped.sequence.imu.gyro):
        raise SystemExit("the re-simulated recording has another IMU: the comparison would not be like for like")
    for name, pipeline in (("KLT + FAST", PipelineConfig(tracker="klt", features="fast", seed=args.seed)),
                           ("SIFT", PipelineConfig(features="sift", seed=args.seed))):
        for label, data in (("as shipped", shipped), ("other noise", other)):
            r = run_pipeline(data, pipeline)
            m = r.metrics
            print(f"{name:<11} {label:<12} {m['percent_of_distance']:6.3f} % of distance, RMSE {m['rmse_m']:.3f} m "
                  f"(second half {m['rmse_second_half_m']:.3f}), mean track {np.mean(r.track_lengths):.1f} frames",
                  flush=True)


if __name__ == "__main__":
    main()
