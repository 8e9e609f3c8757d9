"""ROS bags and HDF5 files: written with rosbags' own writer and h5py in each layout, read back exactly."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("h5py")

from evio_lib.events.array import make_events  # noqa: E402
from evio_lib.geometry.camera import PinholeRadtan  # noqa: E402
from evio_lib.geometry.rotation import quat_from_rotvec  # noqa: E402
from evio_lib.io import hdf5, rosbag  # noqa: E402
from evio_lib.io.aedat4 import us_to_seconds  # noqa: E402
from evio_lib.io.errors import DataFileError  # noqa: E402
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence  # noqa: E402

T0_NS = 1_600_000_000_000_000_000  # a Unix time, as ROS stamps are


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))


def _sequence(grid: str = "ns", n: int = 4000, seed: int = 0, start_us: int = 1_600_000_000_000_000,
              region: tuple[int, int] = (240, 180)) -> Sequence:
    """A small recording on the ns (bags) or us (HDF5) grid: events (pixels in ``region``), frames, IMU, camera
    poses, camera (240 x 180)."""
    rng = np.random.default_rng(seed)
    if grid == "ns":
        to_s, t0, step = rosbag.ns_to_seconds, T0_NS, 1_000_000_000
    else:
        to_s, t0, step = us_to_seconds, start_us, 1_000_000
    t_events = to_s(np.sort(rng.integers(t0, t0 + 2 * step, n)))
    events = make_events(t_events, rng.integers(0, region[0], n), rng.integers(0, region[1], n), rng.choice([-1, 1], n))
    t_imu = to_s(np.arange(t0, t0 + 2 * step, step // 200))
    imu = ImuSamples(t=t_imu, gyro=rng.normal(0, 0.02, (t_imu.size, 3)),
                     accel=np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.02, (t_imu.size, 3)))
    t_frames = to_s(np.arange(t0, t0 + 2 * step, step // 25))
    frames = rng.integers(0, 256, (t_frames.size, 180, 240)).astype(np.uint8)
    t_gt = to_s(np.arange(t0, t0 + 2 * step, step // 100))
    gt = GroundTruth(t=t_gt, p_BinG=rng.normal(0, 1, (t_gt.size, 3)),
                     q_GtoB=quat_from_rotvec(np.tile([0.0, 0.0, 0.1], (t_gt.size, 1))), body="camera")
    camera = PinholeRadtan(fx=199.1, fy=198.7, cx=121.3, cy=88.9, width=240, height=180, k1=-0.33, k2=0.12,
                           p1=1e-4, p2=-2e-4, k3=0.0)
    return Sequence("demo", camera=camera, events=events, frame_times=t_frames, frames=frames, imu=imu,
                    groundtruth=gt)


def _same(a: Sequence, b: Sequence, parts=("events", "frames", "imu", "groundtruth", "camera")) -> None:
    if "events" in parts:
        assert np.asarray(b.events).tobytes() == np.asarray(a.events).tobytes()
    if "frames" in parts:
        assert np.array_equal(b.frames, a.frames) and b.frame_times.tobytes() == a.frame_times.tobytes()
    if "imu" in parts:
        for f in ("t", "gyro", "accel"):
            assert getattr(b.imu, f).tobytes() == getattr(a.imu, f).tobytes()
    if "groundtruth" in parts:
        for f in ("t", "p_BinG", "q_GtoB"):
            assert getattr(b.groundtruth, f).tobytes() == getattr(a.groundtruth, f).tobytes()
    if "camera" in parts:
        assert b.camera == a.camera


@pytest.mark.parametrize("ros2", [False, True], ids=["ros1", "ros2"])
def test_bag_reads_back_exactly(tmp_path, ros2):
    seq = _sequence("ns")
    bag = rosbag.write_rosbag(seq, tmp_path / ("rec" if ros2 else "rec.bag"), ros2=ros2, events_per_message=333)
    back = rosbag.read_rosbag(bag)
    _same(seq, back)
    assert isinstance(back.events, np.memmap)  # streamed: the events live on disk
    assert back.metadata["topics"]["events"] == "/dvs/events"
    again = rosbag.read_rosbag(bag)  # the second read reuses the cached .npy
    assert again.events.filename == back.events.filename


def test_fast_event_bytes_equal_the_rosbags_serializer():
    store = rosbag.rosbag_typestore()
    seq = _sequence("ns", n=50)
    chunk = seq.events
    ns = rosbag.seconds_to_ns(chunk["t"])
    T = store.types
    stamp = lambda n: T["builtin_interfaces/msg/Time"](sec=int(n // 10 ** 9), nanosec=int(n % 10 ** 9))  # noqa: E731
    msg = T["dvs_msgs/msg/EventArray"](
        header=T["std_msgs/msg/Header"](seq=3, stamp=stamp(int(ns[-1])), frame_id=""), height=180, width=240,
        events=[T["dvs_msgs/msg/Event"](x=int(x), y=int(y), ts=stamp(int(n)), polarity=bool(p > 0))
                for x, y, n, p in zip(chunk["x"], chunk["y"], ns, chunk["p"])])
    raw = store.serialize_ros1(msg, "dvs_msgs/msg/EventArray")
    assert bytes(raw) == rosbag._dvs_ros1_bytes(chunk, int(ns[-1]), 240, 180, 3)
    assert rosbag._dvs_events(raw, cdr=False).tobytes() == chunk.tobytes()
    cdr = rosbag_cdr = rosbag.rosbag_typestore(ros2=True)
    msg2 = cdr.types["dvs_msgs/msg/EventArray"](
        header=cdr.types["std_msgs/msg/Header"](stamp=stamp(int(ns[-1])), frame_id="davis"), height=180, width=240,
        events=[cdr.types["dvs_msgs/msg/Event"](x=int(x), y=int(y), ts=stamp(int(n)), polarity=bool(p > 0))
                for x, y, n, p in zip(chunk["x"], chunk["y"], ns, chunk["p"])])
    assert rosbag._dvs_events(rosbag_cdr.serialize_cdr(msg2, "dvs_msgs/msg/EventArray"), cdr=True).tobytes() \
        == chunk.tobytes()


def test_compressed_frames_and_event_array_msgs(tmp_path):
    seq = _sequence("ns", n=300)
    bag = rosbag.write_rosbag(seq, tmp_path / "c.bag", compressed_frames=True)
    assert np.array_equal(rosbag.read_rosbag(bag).frames, seq.frames)  # PNG: lossless
    store = rosbag.rosbag_typestore()
    T = store.types
    ns = rosbag.seconds_to_ns(seq.events["t"])
    base = int(ns[0])
    packed = ((seq.events["p"] > 0).astype(np.uint64) << np.uint64(63)) | (seq.events["y"].astype(np.uint64) << np.uint64(48)) \
        | (seq.events["x"].astype(np.uint64) << np.uint64(32)) | (ns - base).astype(np.uint64)
    msg = T["event_array_msgs/msg/EventArray"](
        header=T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=base // 10 ** 9,
                                                                                      nanosec=base % 10 ** 9),
                                        frame_id=""),
        height=180, width=240, seq=0, time_base=base, encoding="mono", is_bigendian=False,
        events=np.frombuffer(packed.astype("<u8").tobytes(), np.uint8))
    from rosbags.rosbag1 import Writer

    with Writer(tmp_path / "p.bag") as writer:
        conn = writer.add_connection("/event_camera/events", "event_array_msgs/msg/EventArray", typestore=store)
        writer.write(conn, base, store.serialize_ros1(msg, "event_array_msgs/msg/EventArray"))
    assert np.asarray(rosbag.read_rosbag(tmp_path / "p.bag").events).tobytes() == seq.events.tobytes()
    msg.encoding = "evt3"
    with Writer(tmp_path / "e.bag") as writer:
        conn = writer.add_connection("/event_camera/events", "event_array_msgs/msg/EventArray", typestore=store)
        writer.write(conn, base, store.serialize_ros1(msg, "event_array_msgs/msg/EventArray"))
    with pytest.raises(DataFileError, match=r"e.bag topic /event_camera/events: event_array_msgs encoding 'evt3'"):
        rosbag.read_rosbag(tmp_path / "e.bag")


def test_stereo_bag_is_refused_with_its_topics_and_topics_picks(tmp_path):
    seq = _sequence("ns", n=200)
    left = rosbag.write_rosbag(seq, tmp_path / "l.bag", topics="mvsec-left")
    both = tmp_path / "both.bag"
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer

    store = rosbag.rosbag_typestore()
    with AnyReader([left], default_typestore=store) as reader, Writer(both) as writer:
        conns = {}
        for c in reader.connections:
            for side in ("left", "right"):
                topic = c.topic.replace("left", side)
                conns[topic] = writer.add_connection(topic, c.msgtype, typestore=store)
        for c, stamp, raw in reader.messages():
            for side in ("left", "right"):
                writer.write(conns[c.topic.replace("left", side)], stamp, raw)
    with pytest.raises(DataFileError, match=r"both.bag holds 2 events topics: /davis/left/events, "
                                            r"/davis/right/events; pick one with --topics"):
        rosbag.read_rosbag(both)
    back = rosbag.read_rosbag(both, topics="mvsec-right")
    assert back.metadata["topics"]["events"] == "/davis/right/events"
    _same(seq, back)
    picked = rosbag.read_rosbag(both, topics="events=/davis/left/events,frames=/davis/left/image_raw,"
                                             "imu=/davis/left/imu,camera_info=/davis/left/camera_info,"
                                             "pose=/davis/left/pose")
    _same(seq, picked)
    with pytest.raises(ValueError, match="--topics must be a preset"):
        rosbag.parse_topics("evnts=/x")


def test_bag_with_imu_in_g_is_refused_naming_the_topic(tmp_path):
    seq = _sequence("ns", n=100)
    seq.imu = ImuSamples(t=seq.imu.t, gyro=seq.imu.gyro, accel=seq.imu.accel / 9.80665)
    with pytest.raises(DataFileError, match=r"g.bag topic /dvs/imu"):
        rosbag.read_rosbag(rosbag.write_rosbag(seq, tmp_path / "g.bag"))


@pytest.mark.parametrize("layout", ["dsec", "tumvie"])
def test_dsec_and_tumvie_files_read_back_exactly(tmp_path, layout):
    seq = _sequence("us", start_us=1_600_000_000_000_000 if layout == "dsec" else 1234)
    path = tmp_path / f"{layout}.h5"
    if layout == "dsec":
        hdf5.write_dsec_h5(seq.events, path, sensor_size=(240, 180))
    else:
        hdf5.write_tumvie_h5(seq.events, path, sensor_size=(240, 180))
    back = hdf5.read_hdf5(path)
    assert back.metadata["format"] == f"HDF5 ({layout})" and back.sensor_size == (240, 180)
    _same(seq, back, ("events",))
    assert back.imu is None and back.camera is None


def test_dsec_time_not_in_microseconds_is_refused(tmp_path):
    import h5py

    seq = _sequence("us", n=500)
    path = hdf5.write_dsec_h5(seq.events, tmp_path / "ns.h5")
    with h5py.File(path, "r+") as h5:
        t = h5["events/t"][:].astype(np.int64) * 1000
        del h5["events/t"]
        h5["events/t"] = t
    with pytest.raises(DataFileError, match=r"ns.h5: events/t runs to .* ms_to_idx has .* not in microseconds"):
        hdf5.read_hdf5(path)


def test_mvsec_file_reads_back_exactly(tmp_path):
    seq = _sequence("us")
    path = hdf5.write_mvsec_h5(seq, tmp_path / "indoor_flying1_data.hdf5")
    back = hdf5.read_hdf5(path)
    _same(seq, back, ("events", "frames", "imu"))
    # the poses go through 4 x 4 matrices: the quaternions come back as rot_to_quat of them
    expect = hdf5.pose_matrices_to_groundtruth(seq.groundtruth.t, _matrices(seq.groundtruth))
    assert back.groundtruth.q_GtoB.tobytes() == expect.q_GtoB.tobytes()
    assert np.allclose(back.groundtruth.q_GtoB, seq.groundtruth.q_GtoB, atol=1e-12)
    assert back.groundtruth.p_BinG.tobytes() == seq.groundtruth.p_BinG.tobytes()
    shutil.copy(path, tmp_path / "two.hdf5")
    import h5py

    with h5py.File(tmp_path / "two.hdf5", "r+") as h5:
        h5.copy("davis/left", "davis/right")
    with pytest.raises(DataFileError, match=r"two.hdf5 holds 2 event cameras: davis/left, davis/right; pick one"):
        hdf5.read_hdf5(tmp_path / "two.hdf5")
    assert hdf5.read_hdf5(tmp_path / "two.hdf5", group="davis/right").metadata["group"] == "davis/right"


def _matrices(gt: GroundTruth) -> np.ndarray:
    from evio_lib.geometry.rotation import quat_to_rot

    T = np.tile(np.eye(4), (len(gt), 1, 1))
    T[:, :3, :3] = np.swapaxes(quat_to_rot(gt.q_GtoB), -1, -2)
    T[:, :3, 3] = gt.p_BinG
    return T


def test_unknown_h5_layout_lists_what_it_holds(tmp_path):
    import h5py

    with h5py.File(tmp_path / "other.h5", "w") as h5:
        h5["data/values"] = np.zeros(3)
    with pytest.raises(DataFileError, match=r"other.h5: not a known event layout .* the file holds data, data/values"):
        hdf5.read_hdf5(tmp_path / "other.h5")


def test_missing_package_is_one_line(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "h5py", None)  # import h5py now raises ImportError
    with pytest.raises(DataFileError, match=r"^reading HDF5 recordings needs the Python package h5py: pip install "
                                            r"h5py"):
        hdf5.read_hdf5(Path(__file__))
