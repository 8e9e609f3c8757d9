"""Peak memory of run and reconstruct on a ROS bag and a DSEC-layout HDF5 file of 100 M events.

Writes a synthetic recording in chunks (never all in memory) into a temporary folder: a ROS1 bag with
dvs_msgs/EventArray messages (events uniform over a 240 x 180 sensor, --rate events per second, default 20 M/s), a resting IMU at
200 Hz and a CameraInfo, and the same events as a DSEC-layout HDF5 file. Then, each in its own process, measured
with ``os.wait4`` (the child's own peak resident memory, ru_maxrss, and its wall time):

1. the bag's first read: its events decoded and checked into the cached ``.npy`` (the read speed in events/s);
2. ``run BAG --frames mc-events --tracker klt --features fast`` (motion-compensated event frames, read a window at
   a time; the IMU at rest, so the filter starts static);
3. ``reconstruct BAG --window-fraction 1`` with --method (default direct: the window handling alone; firenet adds
   the network);
4. the HDF5 file's first read and ``reconstruct`` on it.

Usage: python bench/bench_recording_memory.py [--events 100000000] [--method direct] [--keep DIR]
Disk: about 4 GB per 100 M events (bag, HDF5, two cached .npy); ``df -h /tmp`` first. Not a test: minutes.
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

WIDTH, HEIGHT = 240, 180
T0_NS = 1_600_000_000_000_000_000
CHUNK = 4_000_000        # events generated at once
PER_MESSAGE = 20_000     # events per EventArray message


def _chunks(n_events: int, rate: float, seed: int = 0):
    """Yield (events EVENT_DTYPE on the ns grid) blocks of a uniform random stream of ``rate`` events/s."""
    import numpy as np

    from evio_lib.events.array import EVENT_DTYPE
    from evio_lib.io.rosbag import ns_to_seconds

    rng = np.random.default_rng(seed)
    start_ns = T0_NS
    for a in range(0, n_events, CHUNK):
        n = min(CHUNK, n_events - a)
        span_ns = int(n / rate * 1e9)
        ns = start_ns + np.sort(rng.integers(0, span_ns, n))
        start_ns += span_ns
        block = np.empty(n, EVENT_DTYPE)
        block["t"] = ns_to_seconds(ns)
        block["x"] = rng.integers(0, WIDTH, n)
        block["y"] = rng.integers(0, HEIGHT, n)
        block["p"] = rng.choice(np.array([-1, 1], np.int8), n)
        yield block


def write_bag(path: Path, n_events: int, rate: float) -> float:
    """Write the synthetic bag; return its duration in seconds."""
    import numpy as np

    from rosbags.rosbag1 import Writer

    from evio_lib.io.rosbag import _dvs_ros1_bytes, rosbag_typestore, seconds_to_ns

    store = rosbag_typestore()
    T = store.types
    duration = n_events / rate
    with Writer(path) as writer:
        ev = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        imu = writer.add_connection("/dvs/imu", "sensor_msgs/msg/Imu", typestore=store)
        info = writer.add_connection("/dvs/camera_info", "sensor_msgs/msg/CameraInfo", typestore=store)
        stamp = lambda n: T["builtin_interfaces/msg/Time"](sec=int(n // 10 ** 9), nanosec=int(n % 10 ** 9))  # noqa
        header = lambda n: T["std_msgs/msg/Header"](seq=0, stamp=stamp(n), frame_id="")  # noqa
        K = np.array([200.0, 0, 120, 0, 200.0, 90, 0, 0, 1])
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        msg = T["sensor_msgs/msg/CameraInfo"](header=header(T0_NS), height=HEIGHT, width=WIDTH,
                                              distortion_model="plumb_bob", D=np.zeros(5), K=K, R=np.eye(3).ravel(),
                                              P=np.zeros(12), binning_x=0, binning_y=0, roi=roi)
        writer.write(info, T0_NS, store.serialize_ros1(msg, "sensor_msgs/msg/CameraInfo"))
        rng = np.random.default_rng(1)
        imu_ns = T0_NS + np.arange(0, int(duration * 1e9), 5_000_000)
        vec, quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
        imu_messages = []
        for n in imu_ns:
            g = rng.normal(0, 0.002, 3)
            a = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.02, 3)
            m = T["sensor_msgs/msg/Imu"](header=header(int(n)), orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
                                         orientation_covariance=np.zeros(9), angular_velocity=vec(*g),
                                         angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(*a),
                                         linear_acceleration_covariance=np.zeros(9))
            imu_messages.append((int(n), store.serialize_ros1(m, "sensor_msgs/msg/Imu")))
        k = 0
        for block in _chunks(n_events, rate):
            for a in range(0, block.size, PER_MESSAGE):
                part = block[a:a + PER_MESSAGE]
                ns = int(seconds_to_ns(part["t"][-1:])[0])
                while k < len(imu_messages) and imu_messages[k][0] <= ns:  # bag order: by time
                    writer.write(imu, imu_messages[k][0], imu_messages[k][1])
                    k += 1
                writer.write(ev, ns, _dvs_ros1_bytes(part, ns, WIDTH, HEIGHT))
        for n, raw in imu_messages[k:]:
            writer.write(imu, n, raw)
    return duration


def write_h5(path: Path, n_events: int, rate: float) -> None:
    """Write the same events in the DSEC layout, a chunk at a time (resizable datasets)."""
    import numpy as np

    import h5py

    offset_us = T0_NS // 1000
    with h5py.File(path, "w") as h5:
        g = h5.create_group("events")
        sets = {name: g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(1 << 18,))
                for name, dtype in (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.uint8))}
        n = 0
        ms_to_idx = []  # ms_to_idx[k]: the first event with t >= k ms, found block by block
        for block in _chunks(n_events, rate):
            us = np.round(block["t"] * 1e6).astype(np.int64) - offset_us  # (the bag's times, to the microsecond)
            values = {"t": us, "x": block["x"], "y": block["y"], "p": (block["p"] > 0).astype(np.uint8)}
            for name, data in values.items():
                sets[name].resize((n + block.size,))
                sets[name][n:] = data
            edges = np.arange(len(ms_to_idx), us[-1] // 1000 + 1) * 1000
            ms_to_idx.extend((n + np.searchsorted(us, edges, side="left")).tolist())
            n += block.size
        h5.create_dataset("ms_to_idx", data=np.array(ms_to_idx + [n], dtype=np.uint64))
        h5.create_dataset("t_offset", data=np.int64(offset_us))
        h5.attrs["width"], h5.attrs["height"] = WIDTH, HEIGHT


def measure(label: str, argv: list[str], env: dict) -> tuple[float, float, int]:
    """Run ``argv`` in a child process; print and return (wall s, peak RSS MB, exit code)."""
    start = time.perf_counter()
    child = subprocess.Popen(argv, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    output = child.stdout.read()
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    peak_mb = usage.ru_maxrss / 1024.0  # Linux: kilobytes
    tail = [line for line in output.strip().splitlines() if line.strip()][-3:]
    print(f"{label:<44} {wall:8.1f} s  peak RSS {peak_mb:8.0f} MB  exit {child.returncode}")
    for line in tail:
        print(f"    | {line[:150]}")
    return wall, peak_mb, child.returncode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=100_000_000)
    parser.add_argument("--rate", type=float, default=2e7,
                        help="events per second of the synthetic stream (default 2e7: 100 M events over 5 s)")
    parser.add_argument("--method", default="direct", help="reconstruct's --method (default direct)")
    parser.add_argument("--keep", type=Path, default=None, help="write into this folder and keep it")
    parser.add_argument("--skip", nargs="*", default=[], choices=["run", "reconstruct", "h5"])
    parser.add_argument("--write", choices=["bag", "h5"], default=None, help=argparse.SUPPRESS)  # (child process)
    parser.add_argument("--path", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.write is not None:
        start = time.perf_counter()
        if args.write == "bag":
            write_bag(args.path, args.events, args.rate)
        else:
            write_h5(args.path, args.events, args.rate)
        print(f"wrote {args.path.name}: {args.events:,} events over {args.events / args.rate:.1f} s, "
              f"{args.path.stat().st_size / 1e9:.2f} GB in {time.perf_counter() - start:.1f} s")
        return
    # This process stays small (no NumPy arrays): a child's ru_maxrss starts from its parent's resident memory at
    # the fork, so the files are written by a child too.
    folder = args.keep or Path(tempfile.mkdtemp(prefix="evio_rec_mem_"))
    folder.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "EVIO_CACHE_DIR": str(folder / "cache"), "OMP_NUM_THREADS": "1"}
    py = [sys.executable]
    try:
        bag = folder / "synthetic.bag"
        write = py + [__file__, "--events", str(args.events), "--rate", str(args.rate), "--path"]
        subprocess.run(write + [str(bag), "--write", "bag"], check=True, env=env)
        read = ("from evio_lib.io.rosbag import read_rosbag; import sys; s = read_rosbag(sys.argv[1]); "
                "print(len(s.events), 'events')")
        wall, _, _ = measure("read bag (decode, check, cache .npy)", py + ["-c", read, str(bag)], env)
        print(f"    read speed: {args.events / wall / 1e6:.2f} M events/s (including interpreter start)")
        if "run" not in args.skip:
            measure("run --frames mc-events (KLT, fast)", py + ["-m", "evio_lib", "run", str(bag), "--frames",
                                                                "mc-events", "--tracker", "klt", "--features", "fast",
                                                                "--quiet"], env)
        if "reconstruct" not in args.skip:
            measure(f"reconstruct --method {args.method} (bag)",
                    py + ["-m", "evio_lib", "reconstruct", str(bag), "--out", str(folder / "rec_bag"), "--method",
                          args.method, "--window-fraction", "1.0", "--quiet"], env)
        if "h5" not in args.skip:
            h5 = folder / "synthetic.h5"
            subprocess.run(write + [str(h5), "--write", "h5"], check=True, env=env)
            read = ("from evio_lib.io.hdf5 import read_hdf5; import sys; s = read_hdf5(sys.argv[1]); "
                    "print(len(s.events), 'events')")
            wall, _, _ = measure("read h5 (decode, check, cache .npy)", py + ["-c", read, str(h5)], env)
            print(f"    read speed: {args.events / wall / 1e6:.2f} M events/s (including interpreter start)")
            if "reconstruct" not in args.skip:
                measure(f"reconstruct --method {args.method} (h5)",
                        py + ["-m", "evio_lib", "reconstruct", str(h5), "--out", str(folder / "rec_h5"), "--method",
                              args.method, "--window-fraction", "1.0", "--quiet"], env)
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
