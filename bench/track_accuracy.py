"""How far do the front-end's tracks drift from the point they started on? Checked against the simulator's world.

For a stretch of a simulated preset, every track's first observation is cast as a ray from the TRUE camera pose
through its undistorted normalised coordinate into the simulator's scene (``Scene.intersect``): that is the world
point the track started on. Each later observation of the track is compared with the projection of that point into
the true camera at that frame (the same distortion model). A correct track stays within the detector's noise (about a
pixel); a track that slides along similar-looking texture grows its error with its age, and two-point RANSAC cannot
see a slide that is smaller than its threshold per frame.

Printed per configuration: tracks, observations, the median and 95th percentile reprojection error of the
observations, the share of observations off by more than 3 px, and the median error by track age.

With ``--frames mc-events`` the tracks run on motion-compensated event frames instead of the APS frames (each frame is
compared with the true camera at its own time, the middle of its event window): the accuracy that the filter's pixel
noise should describe for that stream.

With ``--speed`` and ``--aps-exposure`` the preset is played faster and its APS frames exposed longer (as ``run``
does); ``--simulate-from`` simulates only from that time on, so a stretch of a long recording costs only itself (the
4 s stretch of ``run --start 24 --duration 4`` is the same cached recording).

Usage: python bench/track_accuracy.py [--preset aerial_like] [--duration 15] [--start 5] [--seconds 3]
       [--configs sift cnn klt sift_gap2 cnn_gap2] [--frames aps|mc-events] [--speed 2] [--aps-exposure 0.02]
       [--simulate-from 24]
Measured figures: docs/explanations/short-tracks.md.
"""
import argparse
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from evio_lib.frontend import camera_rotation_priors, create_tracker  # noqa: E402
from evio_lib.pipeline import PipelineConfig, load_dataset  # noqa: E402
from evio_lib.pipeline.frames import mc_event_frames  # noqa: E402
from evio_lib.sim.scene import scene_from_preset  # noqa: E402

CONFIGS = {
    "sift": PipelineConfig(features="sift"),
    "cnn": PipelineConfig(features="superpoint"),
    "klt": PipelineConfig(tracker="klt", features="fast"),
    "sift_gap2": PipelineConfig(features="sift", max_track_gap=2),
    "cnn_gap2": PipelineConfig(features="superpoint", max_track_gap=2),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="aerial_like", choices=["boxes_like", "aerial_like"])
    parser.add_argument("--duration", type=float, default=15.0, help="seconds simulated (cached) (default 15)")
    parser.add_argument("--start", type=float, default=5.0, help="first frame time (default 5 s)")
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds tracked (default 3)")
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", default="aps", choices=["aps", "mc-events"],
                        help="frame source: the APS frames or motion-compensated event frames (default aps)")
    parser.add_argument("--speed", type=float, default=None, help="play the preset's motion this many times faster")
    parser.add_argument("--aps-exposure", type=float, default=None, help="APS exposure time, s (default 0.01)")
    parser.add_argument("--simulate-from", type=float, default=0.0,
                        help="simulate [S, S + duration] s instead of [0, duration] (default 0)")
    args = parser.parse_args()
    end = args.simulate_from + args.duration
    if not args.simulate_from <= args.start < args.start + args.seconds <= end:
        parser.error(f"--start {args.start:g} and --seconds {args.seconds:g} must lie in the simulated "
                     f"[{args.simulate_from:g}, {end:g}] s (--simulate-from, --duration)")
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    try:
        data = load_dataset(args.preset, duration=args.duration, seed=args.seed, need_events=args.frames != "aps",
                            start=args.simulate_from, speed=args.speed, aps_exposure_s=args.aps_exposure)
    except ValueError as error:  # e.g. a stretch past the end of the (faster) motion
        parser.error(str(error))
    seq, cam = data.sequence, data.sequence.camera
    scene = scene_from_preset(args.preset, seed=args.seed)
    if args.frames == "aps":
        pick = (seq.frame_times >= args.start) & (seq.frame_times <= args.start + args.seconds)
        times, images = seq.frame_times[pick], seq.frames[pick]
    else:  # the pipeline's defaults; the true gyro bias is removed (the filter's estimate in a run)
        gt_imu = seq.groundtruth_imu
        known = gt_imu is not None and gt_imu.bias_gyro is not None
        b_g = gt_imu.interpolate([args.start]).bias_gyro[0] if known else None
        made = list(mc_event_frames(seq, data.R_CtoI, t_start=args.start, t_end=args.start + args.seconds,
                                    gyro_bias=None if b_g is None else (lambda: b_g)))
        if len(made) < 2:
            raise SystemExit(f"error: {len(made)} motion-compensated frame(s) in [{args.start:g}, "
                             f"{args.start + args.seconds:g}] s (too few events there); choose another --start")
        times = np.array([t for t, _, _ in made])
        images = np.stack([im for _, im, _ in made])  # float32 in [0, 1], as the pipeline passes them
    truth = seq.groundtruth.interpolate(times)  # camera poses: R_CtoG, p_CinG
    R_CtoG, p_CinG = truth.R_BtoG, truth.p_BinG
    rotations = camera_rotation_priors(seq.imu.t, seq.imu.gyro, times, data.R_CtoI)
    print(f"{args.preset}, seed {args.seed}" + (f", speed {args.speed:g}" if args.speed else "")
          + (f", APS exposure {1e3 * args.aps_exposure:g} ms" if args.aps_exposure else "")
          + f": {len(times)} {args.frames} frames from t = {args.start:g} s")
    print(f"{'config':<6} {'tracks':>6} {'obs':>6} {'median px':>9} {'p95 px':>7} {'> 3 px':>7} | median px by age "
          f"1-2, 3-5, 6-10, 11+")
    for name in args.configs:
        frames = create_tracker(cam, CONFIGS[name].frontend_config()).track(images, times, rotations)
        start: dict[int, np.ndarray] = {}  # track id -> world point it started on
        errors, ages = [], []
        for k, frame in enumerate(frames):
            new = [i for i, tid in enumerate(frame.ids) if tid not in start]
            if new:
                rays_C = np.c_[frame.xy[new], np.ones(len(new))]
                dist, hit, _, _ = scene.intersect(np.repeat(p_CinG[k][None], len(new), axis=0),
                                                  rays_C @ R_CtoG[k].T)
                for i, d, r in zip(new, dist, rays_C):
                    if np.isfinite(d):
                        start[int(frame.ids[i])] = p_CinG[k] + d * (R_CtoG[k] @ (r / np.linalg.norm(r)))
            old = [i for i, tid in enumerate(frame.ids) if int(tid) in start and frame.ages[i] > 1]
            if not old:
                continue
            X = np.array([start[int(frame.ids[i])] for i in old])
            X_C = (X - p_CinG[k]) @ R_CtoG[k]  # R_GtoC (X - p_CinG)
            front = X_C[:, 2] > 0
            uv = cam.project(X_C[front])
            errors.append(np.linalg.norm(uv - frame.pixels[np.array(old)[front]], axis=1))
            ages.append(frame.ages[np.array(old)[front]])
        err, age = np.concatenate(errors), np.concatenate(ages)
        by_age = []
        for lo, hi in ((2, 2), (3, 5), (6, 10), (11, 10 ** 6)):
            sel = (age >= lo) & (age <= hi)
            by_age.append(f"{np.median(err[sel]):.2f}" if sel.any() else "-")
        print(f"{name:<6} {len(start):>6} {len(err):>6} {np.median(err):>9.2f} {np.percentile(err, 95):>7.2f} "
              f"{np.mean(err > 3):>7.2f} | {', '.join(by_age)}", flush=True)


if __name__ == "__main__":
    main()
