"""The course's homework in one script: events, APS frames, perfect tracks and the whole pipeline on boxes_like.

1. simulate the first ``--duration`` s of the ``boxes_like`` preset (events, APS frames, IMU, ground truth);
2. an event count frame beside each APS frame (the events of the frame interval ending at the APS frame's time),
   one pair saved as ``count_frame.png``;
3. the MSCKF on perfect feature tracks (the ground truth's landmarks projected with 1 px noise at the APS frame
   times) against IMU-only propagation, both on this recording's IMU;
4. the whole pipeline: SIFT on the APS frames, KLT + FAST on motion-compensated event frames (``mc-events``);
5. SIFT again with the filter's gyro noise density ten times the recording's;
6. every trajectory in TUM format (the IMU's pose, ``t x y z qx qy qz qw``), beside ``groundtruth.txt``;
7. one table: RMSE and % of distance of every run.

    python examples/homework.py [--duration 8] [--out runs/homework] [--force]

Every random source is seeded (``SEED``): two runs print the same table.
"""
import argparse
import dataclasses
from pathlib import Path

from evio_lib.evaluation import format_table, plot_image_grid
from evio_lib.events import event_count_image, events_between
from evio_lib.io import atomic_output_dir, check_output_dir, groundtruth_to_tum, write_tum
from evio_lib.msckf import VioSimConfig, run_vio_sim_config, simulated_data_from_recording
from evio_lib.pipeline import PipelineConfig, load_dataset, run_pipeline

PRESET, SEED = "boxes_like", 0

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.error = lambda message: parser.exit(2, f"error: {message}\n")  # one line, exit status 2
parser.add_argument("--duration", type=float, default=8.0, help="seconds of the preset, from its start (default 8)")
parser.add_argument("--out", type=Path, default=Path("runs/homework"), help="output folder (default runs/homework)")
parser.add_argument("--force", action="store_true", help="replace a non-empty output folder")
args = parser.parse_args()
try:  # every check before the minutes of work: the folder, the duration (vio-sim needs >= 2 s), then the recording
    check_output_dir(args.out, args.force, name="--out")
    perfect = {"msckf_perfect_tracks": VioSimConfig(PRESET, args.duration, SEED),
               "imu_only": VioSimConfig(PRESET, args.duration, SEED, imu_only=True)}
    data = load_dataset(PRESET, duration=args.duration, seed=SEED, need_events=True)  # 1. the recording
except ValueError as error:
    parser.error(str(error))
seq = data.sequence

# 2. event count frames: the events of each APS frame interval, counted per pixel, ending at that frame's time
counts = [event_count_image(events_between(seq.events, t0, t1), seq.camera.width, seq.camera.height)
          for t0, t1 in zip(seq.frame_times[:-1], seq.frame_times[1:])]
k = len(counts) // 2  # counts[k] ends at APS frame k + 1; shown from 0 (black) to 4 or more events (white)
figure = plot_image_grid({f"APS frame, t = {seq.frame_times[k + 1]:.3f} s": seq.frames[k + 1],
                          f"event count, {counts[k].sum()} events": counts[k].clip(max=4) / 4}, columns=2)

# 3. perfect tracks on this recording (its motion, its IMU samples with their true biases, its extrinsics and camera):
# the filter with the tracks and without them (IMU only)
results = {name: run_vio_sim_config(config, baselines=False, data=simulated_data_from_recording(data, config))
           for name, config in perfect.items()}

# 4. and 5. the pipeline: SIFT on APS frames, KLT on motion-compensated event frames, and SIFT with the filter's
# gyro noise density ten times the recording's (the noise the filter assumes; the recording stays the same)
sift = PipelineConfig(features="sift", seed=SEED)
klt = PipelineConfig(frames="mc-events", tracker="klt", features="fast", seed=SEED)
noisier = dataclasses.replace(data, noise=dataclasses.replace(data.noise,
                                                              gyro_noise_density=10 * data.noise.gyro_noise_density))
for name, recording, config in (("sift_aps", data, sift), ("klt_mc_events", data, klt),
                                ("sift_aps_gyro_noise_x10", noisier, sift)):
    results[name] = run_pipeline(recording, config)

# 6. the TUM files and the figure, written together (a failed run leaves no half-written folder)
with atomic_output_dir(args.out, args.force) as folder:
    write_tum(folder / "groundtruth.txt", *groundtruth_to_tum(seq.groundtruth_imu), body="imu")
    for name, result in results.items():
        result.write_tum(folder / f"{name}.txt")  # the IMU's pose, like groundtruth.txt
    figure.savefig(folder / "count_frame.png", dpi=100)

# 7. the table
print(f"{PRESET}, first {args.duration:g} s, seed {SEED}; TUM files and count_frame.png in {args.out}")
print(format_table([{**r.metrics, "name": name} for name, r in results.items()],
                   (("name", "run"), ("rmse_m", "RMSE [m]"), ("percent_of_distance", "% of distance"))))
