"""ROS bags (ROS1 ``.bag`` files, ROS2 bag folders) read without ROS, through the ``rosbags`` package.

Topics are found by message type (one role each):

==============  ==========================================================  =============================================
role            message types                                               becomes
==============  ==========================================================  =============================================
``events``      ``dvs_msgs/EventArray`` (rpg_dvs_ros, dv-ros),              events, t = each event's ``ts``
                ``event_array_msgs/EventArray`` (encoding ``mono``)         t = ``time_base`` + dt [ns] (the message's
                                                                            definition); other encodings are refused
``frames``      ``sensor_msgs/Image`` (mono8, mono16, bgr8, rgb8, bgra8,    uint8 grayscale frames at ``header.stamp``
                rgba8), ``sensor_msgs/CompressedImage``                     (mono16: the high byte)
``imu``         ``sensor_msgs/Imu``                                         IMU samples (m/s^2, rad/s) at ``header.stamp``
``pose``        ``geometry_msgs/PoseStamped``, ``TransformStamped``,        the camera's ground truth (the pose is taken
                ``nav_msgs/Odometry``                                       as the camera's in the world, as the ECD's)
``camera_info`` ``sensor_msgs/CameraInfo`` (``plumb_bob`` or                the camera (K, D); ``equidistant`` and other
                ``rational_polynomial``'s first five)                       models are refused: give ``--calib``
==============  ==========================================================  =============================================

Several topics of one role (a stereo rig: ``/davis/left/events`` and ``/davis/right/events``) are refused in one
line listing them; ``topics=`` picks (``--topics`` on the command line): a preset name of :data:`TOPIC_PRESETS`
or ``role=/topic`` pairs separated by commas (``events=/davis/left/events,imu=/davis/left/imu``).

Times: ROS stores seconds and nanoseconds. They become float64 seconds with :func:`ns_to_seconds`
(``t = s + rest / 1e9``: the sub-second part rounded once, then the sum), the same function whatever the field.
A bag's messages are ordered by receive time; the events must also be ordered by their own timestamps across
messages (refused otherwise, naming the topic and the event). The IMU goes through
:func:`evio_lib.io.imu_checks.check_imu_units`; events, frames and IMU that share no time are refused.

Streaming: events are converted message by message into an ``.npy`` file of EVENT_DTYPE under the cache folder
(``<cache>/recordings``, reused while the bag keeps its size and modification time), and the Sequence holds a
read-only memory map of it (:mod:`evio_lib.io.event_source`). ``dvs_msgs/EventArray`` payloads are decoded with
NumPy views of the raw bytes (ROS1 and ROS2's CDR), not one Python object per event.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np

from evio_lib.events.array import EVENT_DTYPE
from evio_lib.io.errors import DataFileError
from evio_lib.io.event_source import EventChunkChecker

__all__ = ["read_rosbag", "is_rosbag", "parse_topics", "ns_to_seconds", "seconds_to_ns", "TOPIC_PRESETS", "ROLE_TYPES",
           "DVS_MSGS", "EVENT_ARRAY_MSGS", "rosbag_typestore"]

#: Message types of each role (rosbags' names: package/msg/Type).
ROLE_TYPES = {
    "events": ("dvs_msgs/msg/EventArray", "event_array_msgs/msg/EventArray"),
    "frames": ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"),
    "imu": ("sensor_msgs/msg/Imu",),
    "pose": ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/TransformStamped", "nav_msgs/msg/Odometry"),
    "camera_info": ("sensor_msgs/msg/CameraInfo",),
}
#: Topic names of the datasets' bags, per role (first name present in the bag wins). The ECD and MVSEC names are
#: from their data-format pages; the UZH-FPV and VECtor names are the ones their drivers publish (check a bag's
#: own list: a refusal prints it).
TOPIC_PRESETS: dict[str, dict[str, tuple[str, ...]]] = {
    "ecd": {"events": ("/dvs/events",), "frames": ("/dvs/image_raw",), "imu": ("/dvs/imu",),
            "camera_info": ("/dvs/camera_info",), "pose": ("/optitrack/davis",)},
    "mvsec-left": {"events": ("/davis/left/events",), "frames": ("/davis/left/image_raw",),
                   "imu": ("/davis/left/imu",), "camera_info": ("/davis/left/camera_info",),
                   "pose": ("/davis/left/pose", "/davis/left/odometry")},
    "mvsec-right": {"events": ("/davis/right/events",), "frames": ("/davis/right/image_raw",),
                    "imu": ("/davis/right/imu",), "camera_info": ("/davis/right/camera_info",),
                    "pose": ("/davis/right/pose", "/davis/right/odometry")},
    "uzh-fpv": {"events": ("/dvs/events",), "frames": ("/dvs/image_raw",), "imu": ("/dvs/imu",),
                "camera_info": ("/dvs/camera_info",), "pose": ("/groundtruth/pose", "/groundtruth/odometry")},
    "vector-left": {"events": ("/dvs/left/events", "/left/events"), "frames": ("/camera/left/image_mono",),
                    "imu": ("/imu/data",), "camera_info": ("/dvs/left/camera_info",),
                    "pose": ("/gt/pose",)},
}

#: The ``.msg`` texts of rpg_dvs_ros's dvs_msgs (registered with rosbags' type store).
DVS_MSGS = {
    "dvs_msgs/msg/Event": "uint16 x\nuint16 y\ntime ts\nbool polarity\n",
    "dvs_msgs/msg/EventArray": "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n",
}
#: The ``.msg`` text of event_array_msgs/EventArray (ros-event-camera).
EVENT_ARRAY_MSGS = {
    "event_array_msgs/msg/EventArray": ("std_msgs/Header header\nuint32 height\nuint32 width\nuint64 seq\n"
                                        "uint64 time_base\nstring encoding\nbool is_bigendian\nuint8[] events\n"),
}
_ROS1_EVENT = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])  # 13 bytes
# CDR: each field aligned to its size from the payload's start; after the first event (at a 4-aligned offset) every
# event starts 2 bytes past a multiple of 4 and takes 16 bytes: x, y, 2 bytes of padding, sec, nanosec, polarity
_CDR_FIRST = np.dtype({"names": ["x", "y", "sec", "nsec", "p"], "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                       "offsets": [0, 2, 4, 8, 12], "itemsize": 13})
_CDR_NEXT = np.dtype({"names": ["x", "y", "sec", "nsec", "p"], "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                      "offsets": [0, 2, 6, 10, 14], "itemsize": 15})


def ns_to_seconds(ns: Any) -> np.ndarray:
    """Return float64 seconds of integer nanoseconds: ``s + rest / 1e9`` (the sub-second part rounded once).

    >>> ns_to_seconds(np.array([1_500_000_000_123_456_789])).tolist()
    [1500000000.1234567]
    """
    seconds, rest = np.divmod(np.asarray(ns).astype(np.int64), 1_000_000_000)
    return seconds.astype(np.float64) + rest.astype(np.float64) / 1e9


def seconds_to_ns(t: Any) -> np.ndarray:
    """Return the integer nanoseconds whose :func:`ns_to_seconds` is nearest to ``t`` (the inverse on the grid)."""
    t = np.asarray(t, dtype=np.float64)
    seconds = np.floor(t)
    return seconds.astype(np.int64) * 1_000_000_000 + np.round((t - seconds) * 1e9).astype(np.int64)


def _stamp_ns(stamp: Any) -> int:
    """Return a ROS time (``sec``/``nanosec`` or ROS1's ``sec``/``nsec``) as integer nanoseconds."""
    nanos = getattr(stamp, "nanosec", None)
    if nanos is None:
        nanos = stamp.nsec
    return int(stamp.sec) * 1_000_000_000 + int(nanos)


def rosbag_typestore(ros2: bool = False) -> Any:
    """Return a rosbags type store (ROS1 Noetic or ROS2 Humble) with dvs_msgs and event_array_msgs registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
    types: dict = {}
    for name, text in {**DVS_MSGS, **EVENT_ARRAY_MSGS}.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def is_rosbag(path: str | Path) -> bool:
    """Return True for a ROS1 ``.bag`` file or a ROS2 bag folder (``metadata.yaml`` beside ``.db3``/``.mcap``)."""
    path = Path(path)
    if path.is_file():
        return path.suffix.lower() == ".bag"
    return path.is_dir() and (path / "metadata.yaml").is_file() and any(
        p.suffix in (".db3", ".mcap") for p in path.iterdir())


def parse_topics(text: str | None) -> dict[str, tuple[str, ...]]:
    """Return role -> candidate topics from ``--topics`` (a preset name or ``role=/topic`` pairs), or {}.

    >>> parse_topics("events=/davis/left/events,imu=/davis/left/imu")
    {'events': ('/davis/left/events',), 'imu': ('/davis/left/imu',)}
    """
    if text is None or not str(text).strip():
        return {}
    text = str(text).strip()
    if text in TOPIC_PRESETS:
        return dict(TOPIC_PRESETS[text])
    chosen: dict[str, tuple[str, ...]] = {}
    for part in text.split(","):
        role, sep, topic = part.partition("=")
        role, topic = role.strip(), topic.strip()
        if not sep or role not in ROLE_TYPES or not topic:
            raise ValueError(f"--topics must be a preset ({', '.join(TOPIC_PRESETS)}) or role=/topic pairs "
                             f"separated by commas, roles {', '.join(ROLE_TYPES)}; got {text!r}")
        chosen[role] = (topic,)
    return chosen


def _choose(role: str, connections: dict[str, str], wanted: dict[str, tuple[str, ...]], name: str) -> str | None:
    """Return the topic of ``role``: the one asked for, the only one of its types, or None; refuse ambiguity."""
    of_type = sorted(t for t, msgtype in connections.items() if msgtype in ROLE_TYPES[role])
    if role in wanted:
        for topic in wanted[role]:
            if topic in connections:
                if connections[topic] not in ROLE_TYPES[role]:
                    raise DataFileError(f"{name}: topic {topic} is {connections[topic]}, not {role} "
                                        f"({' or '.join(ROLE_TYPES[role])})")
                return topic
        if len(wanted[role]) == 1 and wanted[role][0] not in connections and not of_type:
            return None
        if len(of_type) == 1:
            return of_type[0]
        if of_type:
            raise DataFileError(f"{name}: no topic {' or '.join(wanted[role])} for {role}; the bag's {role} topics: "
                                f"{', '.join(of_type)} (pick with --topics {role}=TOPIC)")
        return None
    if len(of_type) > 1:
        raise DataFileError(f"{name} holds {len(of_type)} {role} topics: {', '.join(of_type)}; pick one with "
                            f"--topics {role}={of_type[0]} (or a preset: {', '.join(TOPIC_PRESETS)})")
    return of_type[0] if of_type else None


def _dvs_events(raw: bytes, cdr: bool) -> np.ndarray:
    """Return the events of one serialized dvs_msgs/EventArray (ROS1 or CDR) as EVENT_DTYPE, by NumPy views."""
    data = memoryview(raw)
    if cdr:
        if bytes(data[0:2]) not in (b"\x00\x01", b"\x00\x03"):
            raise ValueError("not little-endian CDR")
        origin = 4
        n_id = int.from_bytes(data[origin + 8:origin + 12], "little")
        pos = 12 + n_id
        pos += -pos % 4
        height, width, count = np.frombuffer(data, "<u4", 3, origin + pos)
        start = origin + pos + 12
        records = np.empty(int(count), dtype=[("x", "<u2"), ("y", "<u2"), ("sec", "<i8"), ("nsec", "<i8"),
                                               ("p", "u1")])
        if count:
            first = np.frombuffer(data, _CDR_FIRST, 1, start)
            rest = np.ndarray((int(count) - 1,), dtype=_CDR_NEXT, buffer=data, offset=start + 14, strides=(16,))
            for field in ("x", "y", "sec", "nsec", "p"):
                records[field][:1] = first[field]
                records[field][1:] = rest[field]
    else:
        n_id = int.from_bytes(data[12:16], "little")
        pos = 16 + n_id
        height, width, count = np.frombuffer(data, "<u4", 3, pos)
        records = np.frombuffer(data, _ROS1_EVENT, int(count), pos + 12)
    events = np.empty(records.shape[0], dtype=EVENT_DTYPE)
    events["t"] = ns_to_seconds(records["sec"].astype(np.int64) * 1_000_000_000 + records["nsec"].astype(np.int64))
    events["x"] = records["x"]
    events["y"] = records["y"]
    events["p"] = np.where(records["p"] != 0, 1, -1)
    return events


def _event_array_msgs_events(msg: Any, where: str) -> np.ndarray:
    """Return the events of one event_array_msgs/EventArray in the ``mono`` encoding as EVENT_DTYPE."""
    if msg.encoding != "mono":
        raise DataFileError(f"{where}: event_array_msgs encoding {msg.encoding!r} is not read (only 'mono', whose "
                            f"layout the message package documents; convert evt3 with event_array_tools first)")
    if msg.is_bigendian:
        raise DataFileError(f"{where}: big-endian event_array_msgs payloads are not read")
    packed = np.frombuffer(np.asarray(msg.events, dtype=np.uint8).tobytes(), "<u8")
    events = np.empty(packed.shape[0], dtype=EVENT_DTYPE)
    events["t"] = ns_to_seconds(np.int64(msg.time_base) + (packed & 0xFFFFFFFF).astype(np.int64))
    events["x"] = (packed >> np.uint64(32)) & np.uint64(0xFFFF)
    events["y"] = (packed >> np.uint64(48)) & np.uint64(0x7FFF)
    events["p"] = np.where((packed >> np.uint64(63)) != 0, 1, -1)
    return events


def _gray(msg: Any, where: str) -> np.ndarray:
    """Return a sensor_msgs/Image or CompressedImage as (H, W) uint8 grayscale."""
    import cv2

    if hasattr(msg, "encoding"):
        enc, h, w = msg.encoding.lower(), int(msg.height), int(msg.width)
        data = np.asarray(msg.data, dtype=np.uint8)
        step = int(msg.step)
        if enc in ("mono8", "8uc1"):
            return data.reshape(h, step)[:, :w].copy()
        if enc in ("mono16", "16uc1"):
            dtype = ">u2" if msg.is_bigendian else "<u2"
            return (data.reshape(h, step).view(dtype)[:, :w] >> 8).astype(np.uint8)
        channels = {"bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4}.get(enc)
        if channels is None:
            raise DataFileError(f"{where}: image encoding {msg.encoding!r} is not read (mono8, mono16, bgr8, rgb8, "
                                f"bgra8, rgba8)")
        pixels = data.reshape(h, step)[:, :w * channels].reshape(h, w, channels)
        code = {"bgr8": cv2.COLOR_BGR2GRAY, "rgb8": cv2.COLOR_RGB2GRAY, "bgra8": cv2.COLOR_BGRA2GRAY,
                "rgba8": cv2.COLOR_RGBA2GRAY}[enc]
        return cv2.cvtColor(np.ascontiguousarray(pixels), code)
    image = cv2.imdecode(np.asarray(msg.data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DataFileError(f"{where}: a compressed image ({msg.format!r}) could not be decoded")
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    return image


def _camera(msg: Any, where: str) -> Any:
    """Return the PinholeRadtan of a sensor_msgs/CameraInfo (plumb_bob, or rational_polynomial's first five)."""
    from evio_lib.geometry.camera import PinholeRadtan, intrinsics_problem

    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=np.float64)
    D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64)
    model = str(msg.distortion_model)
    if model not in ("plumb_bob", "rational_polynomial", "") or (model == "" and D.size):
        raise DataFileError(f"{where}: distortion model {model!r} is not read (plumb_bob: k1 k2 p1 p2 k3); give the "
                            f"calibration with --calib FILE")
    if K.size != 9 or not np.any(K):
        raise DataFileError(f"{where}: the camera matrix K is empty; give the calibration with --calib FILE")
    d = np.zeros(5)
    d[:min(5, D.size)] = D[:5]
    try:
        camera = PinholeRadtan(fx=K[0], fy=K[4], cx=K[2], cy=K[5], width=int(msg.width), height=int(msg.height),
                               k1=d[0], k2=d[1], p1=d[2], p2=d[3], k3=d[4])
    except ValueError as error:
        raise DataFileError(f"{where}: {error}") from None
    problem = intrinsics_problem(camera)
    if problem is not None:
        raise DataFileError(f"{where}: {problem}")
    return camera


def _pose(msg: Any, msgtype: str) -> tuple[int, np.ndarray, np.ndarray]:
    """Return (t [ns], p (3,), Hamilton q of the rotation (x, y, z, w)) of a pose message."""
    if msgtype.endswith("PoseStamped"):
        pose = msg.pose
        p, q = pose.position, pose.orientation
    elif msgtype.endswith("Odometry"):
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
    else:
        p, q = msg.transform.translation, msg.transform.rotation
    return (_stamp_ns(msg.header.stamp), np.array([p.x, p.y, p.z], dtype=np.float64),
            np.array([q.x, q.y, q.z, q.w], dtype=np.float64))


def read_rosbag(path: str | Path, *, load_events: bool = True, load_frames: bool = True,
                topics: str | dict | None = None) -> Any:
    """Return the Sequence of a ROS bag (ROS1 ``.bag`` file or ROS2 folder); roles and topics in the module docstring.

    Args:
        path: the bag.
        load_events: convert the events (first read: a pass over the bag; later reads reuse the ``.npy`` cache).
        load_frames: decode the frames.
        topics: ``--topics``: a preset name, ``role=/topic`` pairs, or a dict role -> topics; None: by type.

    Returns:
        Sequence with the camera of the CameraInfo topic (None without one: ``--calib``), events a memory map of the
        cached ``.npy`` (:mod:`evio_lib.io.event_source`), frames, IMU and the pose topic as the camera's ground
        truth; metadata names the topics read.

    Raises:
        DataFileError naming the bag and the topic: rosbags missing, several topics of a role, unsorted events,
        pixels outside the sensor, unknown encodings, IMU units, clocks that share no time.
    """
    from evio_lib.io.hdf5 import cached_events, require_package

    require_package("rosbags", "rosbags", "ROS bags")
    from rosbags.highlevel import AnyReader

    from evio_lib.io.errors import unit_quaternions
    from evio_lib.io.imu_checks import check_imu_units
    from evio_lib.sequence import GroundTruth, ImuSamples, Sequence

    path = Path(path)
    if not path.exists():
        raise DataFileError(f"{path.name}: not found at {path} (expected a ROS1 .bag file or a ROS2 bag folder)")
    name = path.name
    wanted = parse_topics(topics) if not isinstance(topics, dict) else {k: tuple(v) if not isinstance(v, str)
                                                                        else (v,) for k, v in topics.items()}
    ros2 = path.is_dir()
    try:
        reader = AnyReader([path], default_typestore=rosbag_typestore(ros2=ros2))
        reader.open()
    except Exception as error:  # noqa: BLE001 - rosbags raises its own error classes per storage format
        raise DataFileError(f"{name}: not a readable ROS bag ({type(error).__name__}: "
                            f"{str(error).splitlines()[0] if str(error) else ''})") from None
    try:
        connections = {c.topic: c.msgtype for c in reader.connections}
        chosen = {role: _choose(role, connections, wanted, name) for role in ROLE_TYPES}
        by_topic = {topic: [c for c in reader.connections if c.topic == topic] for topic in chosen.values() if topic}
        metadata: dict = {"source": str(path), "format": "ROS2 bag" if ros2 else "ROS1 bag",
                          "topics": {role: topic for role, topic in chosen.items() if topic}}

        camera = None
        if chosen["camera_info"]:
            for connection, _, raw in reader.messages(connections=by_topic[chosen["camera_info"]]):
                camera = _camera(reader.deserialize(raw, connection.msgtype), f"{name} topic {chosen['camera_info']}")
                break

        imu = None
        if chosen["imu"]:
            rows = []
            for connection, _, raw in reader.messages(connections=by_topic[chosen["imu"]]):
                m = reader.deserialize(raw, connection.msgtype)
                a, w = m.linear_acceleration, m.angular_velocity
                rows.append((_stamp_ns(m.header.stamp), a.x, a.y, a.z, w.x, w.y, w.z))
            if rows:
                table = np.array(rows, dtype=np.float64)
                t_ns = np.array([r[0] for r in rows], dtype=np.int64)
                imu = ImuSamples(t=ns_to_seconds(t_ns), gyro=table[:, 4:7], accel=table[:, 1:4])

        truth = None
        if chosen["pose"]:
            t_list, p_list, q_list = [], [], []
            for connection, _, raw in reader.messages(connections=by_topic[chosen["pose"]]):
                t_ns, p, q = _pose(reader.deserialize(raw, connection.msgtype), connection.msgtype)
                t_list.append(t_ns)
                p_list.append(p)
                q_list.append(q)
            if t_list:
                where = f"{name} topic {chosen['pose']}"
                q, bad, norm = unit_quaternions(np.array(q_list))
                if bad >= 0:
                    raise DataFileError(f"{where} message {bad}: the orientation has norm {norm:.6g}; expected a "
                                        f"unit quaternion")
                t_pose = ns_to_seconds(np.array(t_list, dtype=np.int64))
                if np.any(np.diff(t_pose) <= 0):
                    i = int(np.flatnonzero(np.diff(t_pose) <= 0)[0]) + 1
                    raise DataFileError(f"{where} message {i}: header stamp {t_pose[i]!r} s does not follow "
                                        f"{t_pose[i - 1]!r} s; poses must be strictly increasing in time")
                # Hamilton q of R_CtoG (x y z w) has the numbers of the JPL q_GtoC (evio_lib.io.tum)
                truth = GroundTruth(t=t_pose, p_BinG=np.array(p_list), q_GtoB=q, body="camera")
                metadata["groundtruth_body"] = "camera (the pose topic taken as the camera's pose in the world)"

        frames_t, frames = np.zeros(0), None
        if chosen["frames"] and load_frames:
            images, stamps = [], []
            where = f"{name} topic {chosen['frames']}"
            for connection, _, raw in reader.messages(connections=by_topic[chosen["frames"]]):
                m = reader.deserialize(raw, connection.msgtype)
                images.append(_gray(m, where))
                stamps.append(_stamp_ns(m.header.stamp))
                if images[-1].shape != images[0].shape:
                    raise DataFileError(f"{where} message {len(images) - 1}: image size {images[-1].shape[::-1]} "
                                        f"differs from the first image's {images[0].shape[::-1]}")
            if images:
                order = np.argsort(np.array(stamps, dtype=np.int64), kind="stable")
                frames = np.stack(images)[order]
                frames_t = ns_to_seconds(np.array(stamps, dtype=np.int64)[order])

        size = None
        if camera is not None:
            size = (camera.width, camera.height)
            metadata["sensor_size_source"] = f"topic {chosen['camera_info']}"
        elif frames is not None:
            size = (frames.shape[2], frames.shape[1])
            metadata["sensor_size_source"] = f"topic {chosen['frames']}"
        events = np.empty(0, EVENT_DTYPE)
        if chosen["events"]:
            topic = chosen["events"]
            if size is None:  # the EventArray's own width and height
                for connection, _, raw in reader.messages(connections=by_topic[topic]):
                    m = reader.deserialize(raw, connection.msgtype)
                    if int(m.width) > 0 and int(m.height) > 0:
                        size = (int(m.width), int(m.height))
                        metadata["sensor_size_source"] = f"topic {topic} (width, height)"
                    break
            if load_events:
                events = cached_events(path, f"rosbag:{topic}", _bag_event_chunks(reader, by_topic[topic], cdr=ros2,
                                                                                 where=f"{name} topic {topic}",
                                                                                 sensor_size=size))
        if size is None:
            raise DataFileError(f"{name}: the sensor size is unknown (no camera_info, frames or event width/height); "
                                f"topics: {', '.join(sorted(connections))}")
        metadata["sensor_size"] = size
    finally:
        reader.close()
    if frames is None:
        frames = np.zeros((0, size[1], size[0]), dtype=np.uint8)
    if imu is not None:
        if len(imu) >= 2 and np.all(np.diff(imu.t) > 0):
            check_imu_units(imu.t, imu.gyro, imu.accel, truth, source=f"{name} topic {chosen['imu']}",
                            columns="sensor_msgs/Imu linear_acceleration (m/s^2) and angular_velocity (rad/s)")
        from evio_lib.io.hdf5 import _check_shared_clock

        _check_shared_clock(name, events, frames_t, imu)
    try:
        return Sequence(name=path.stem, camera=camera, events=events, frame_times=frames_t, frames=frames, imu=imu,
                        groundtruth=truth, metadata=metadata)
    except ValueError as exc:
        raise DataFileError(f"{name}: the recording is not a valid sequence ({exc})") from None


def _bag_event_chunks(reader: Any, connections: list, cdr: bool, where: str,
                      sensor_size: tuple[int, int] | None) -> Iterator[np.ndarray]:
    """Yield checked EVENT_DTYPE blocks of about a million events from the event topic's messages, in bag order."""
    check = EventChunkChecker(where, sensor_size)
    pending, held = [], 0
    for connection, _, raw in reader.messages(connections=connections):
        if connection.msgtype == "dvs_msgs/msg/EventArray":
            try:
                block = _dvs_events(raw, cdr)
            except (ValueError, TypeError):  # an unusual serialization: the reference decoder
                m = reader.deserialize(raw, connection.msgtype)
                block = np.empty(len(m.events), dtype=EVENT_DTYPE)
                block["t"] = ns_to_seconds(np.array([_stamp_ns(e.ts) for e in m.events], dtype=np.int64))
                block["x"] = [e.x for e in m.events]
                block["y"] = [e.y for e in m.events]
                block["p"] = [1 if e.polarity else -1 for e in m.events]
        else:
            block = _event_array_msgs_events(reader.deserialize(raw, connection.msgtype), where)
        pending.append(block)
        held += block.size
        if held >= 1 << 20:
            yield check(np.concatenate(pending))
            pending, held = [], 0
    if pending:
        yield check(np.concatenate(pending))


# ------------------------------------------------------------------------------------------------------- writer
def _dvs_ros1_bytes(events: np.ndarray, stamp_ns: int, width: int, height: int, seq: int = 0) -> bytes:
    """Return the ROS1 serialization of a dvs_msgs/EventArray holding ``events`` (times on the ns grid)."""
    ns = seconds_to_ns(events["t"])
    records = np.empty(events.size, dtype=_ROS1_EVENT)
    records["x"], records["y"] = events["x"], events["y"]
    records["sec"], records["nsec"] = ns // 1_000_000_000, ns % 1_000_000_000
    records["p"] = events["p"] > 0
    head = np.array([seq, stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000, 0, height, width, events.size],
                    dtype="<u4")
    return head.tobytes() + records.tobytes()


def write_rosbag(sequence: Any, path: str | Path, *, ros2: bool = False, events_per_message: int = 20000,
                 topics: str = "ecd", compressed_frames: bool = False, fast_events: bool = False) -> Path:
    """Write a Sequence as a ROS bag with the topics of a preset (events, frames, IMU, pose, camera_info).

    Times must lie on the nanosecond grid of :func:`ns_to_seconds` (they come back exactly). Messages are
    serialized by rosbags' own serializer from the registered ``.msg`` texts; ``fast_events`` (ROS1 only) writes
    the EventArray bytes with NumPy instead (the same bytes; for benchmarks of many events).
    """
    store = rosbag_typestore(ros2=ros2)
    T = store.types
    names = {role: candidates[0] for role, candidates in TOPIC_PRESETS[topics].items()}
    path = Path(path)
    if ros2:
        from rosbags.rosbag2 import Writer

        writer = Writer(path, version=8)
        serialize = store.serialize_cdr
    else:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
        serialize = store.serialize_ros1

    def stamp(ns: int) -> Any:
        return T["builtin_interfaces/msg/Time"](sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))

    def header(ns: int, seq: int = 0) -> Any:
        if ros2:
            return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id="")
        return T["std_msgs/msg/Header"](seq=seq, stamp=stamp(ns), frame_id="")

    width, height = sequence.sensor_size
    messages: list[tuple[int, str, Any]] = []  # (bag time ns, role, message or bytes)
    ev = sequence.events
    for k, a in enumerate(range(0, ev.size, events_per_message)):
        chunk = np.asarray(ev[a:a + events_per_message])
        ns = int(seconds_to_ns(chunk["t"][-1:])[0])
        if fast_events and not ros2:
            messages.append((ns, "events", _dvs_ros1_bytes(chunk, ns, width, height, k)))
            continue
        e_ns = seconds_to_ns(chunk["t"])
        events = [T["dvs_msgs/msg/Event"](x=int(x), y=int(y), ts=stamp(int(n)), polarity=bool(p > 0))
                  for x, y, n, p in zip(chunk["x"], chunk["y"], e_ns, chunk["p"])]
        messages.append((ns, "events", T["dvs_msgs/msg/EventArray"](header=header(ns, k), height=height, width=width,
                                                                   events=events)))
    for k, (t, image) in enumerate(zip(sequence.frame_times, sequence.frames)):
        ns = int(seconds_to_ns([t])[0])
        if compressed_frames:
            import cv2

            ok, png = cv2.imencode(".png", image)
            msg = T["sensor_msgs/msg/CompressedImage"](header=header(ns, k), format="mono8; png compressed",
                                                      data=np.frombuffer(png.tobytes(), np.uint8))
        else:
            msg = T["sensor_msgs/msg/Image"](header=header(ns, k), height=image.shape[0], width=image.shape[1],
                                            encoding="mono8", is_bigendian=0, step=image.shape[1],
                                            data=np.ascontiguousarray(image).reshape(-1))
        messages.append((ns, "frames", msg))
    vec = T["geometry_msgs/msg/Vector3"]
    quat = T["geometry_msgs/msg/Quaternion"]
    if sequence.imu is not None:
        imu = sequence.imu
        cov = np.zeros(9)
        for k, n in enumerate(seconds_to_ns(imu.t)):
            msg = T["sensor_msgs/msg/Imu"](header=header(int(n), k), orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
                                          orientation_covariance=cov, angular_velocity=vec(*imu.gyro[k]),
                                          angular_velocity_covariance=cov,
                                          linear_acceleration=vec(*imu.accel[k]), linear_acceleration_covariance=cov)
            messages.append((int(n), "imu", msg))
    if sequence.groundtruth is not None:
        gt = sequence.groundtruth
        for k, n in enumerate(seconds_to_ns(gt.t)):
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](*gt.p_BinG[k]),
                                               orientation=quat(*gt.q_GtoB[k]))
            messages.append((int(n), "pose", T["geometry_msgs/msg/PoseStamped"](header=header(int(n), k), pose=pose)))
    if sequence.camera is not None:
        c = sequence.camera
        K = np.array([c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0])
        fields = dict(header=header(0), height=c.height, width=c.width, distortion_model="plumb_bob",
                      binning_x=0, binning_y=0,
                      roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                               do_rectify=False))
        D = np.array([c.k1, c.k2, c.p1, c.p2, c.k3])
        R, P = np.eye(3).reshape(-1), np.zeros(12)
        fields.update(dict(d=D, k=K, r=R, p=P) if ros2 else dict(D=D, K=K, R=R, P=P))
        first = int(min(m[0] for m in messages)) if messages else 0
        messages.append((first, "camera_info", T["sensor_msgs/msg/CameraInfo"](**fields)))
    types = {"events": "dvs_msgs/msg/EventArray",
             "frames": "sensor_msgs/msg/CompressedImage" if compressed_frames else "sensor_msgs/msg/Image",
             "imu": "sensor_msgs/msg/Imu", "pose": "geometry_msgs/msg/PoseStamped",
             "camera_info": "sensor_msgs/msg/CameraInfo"}
    messages.sort(key=lambda m: m[0])
    with writer:
        conns = {role: writer.add_connection(names[role] if role != "frames" or not compressed_frames
                                             else names[role] + "/compressed", types[role], typestore=store)
                 for role in {m[1] for m in messages}}
        for ns, role, msg in messages:
            data = msg if isinstance(msg, bytes) else serialize(msg, types[role])
            writer.write(conns[role], max(ns, 1), data)
    return path
