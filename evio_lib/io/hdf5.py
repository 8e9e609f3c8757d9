"""HDF5 event recordings (DSEC, TUM-VIE, MVSEC) read with ``h5py``, the events streamed to an on-disk array.

Three layouts are recognised by the datasets they hold (``layout=`` forces one):

============  ==============================================================  =========================================
layout        what the file gives                                             what it lacks (where the dataset keeps it)
============  ==============================================================  =========================================
``dsec``      ``events/{x,y,t,p}`` (t in us from ``t_offset``, p 0/1),          frames (PNG folders), IMU (none
              ``ms_to_idx``, ``t_offset`` (us); sensor 640 x 480              published), ground truth, calibration
                                                                              (``cam_to_cam.yaml``)
``tumvie``    ``events/{x,y,t,p}`` (t in us, p 0/1), ``ms_to_idx``;           frames, IMU, mocap ground truth (text
              sensor 1280 x 720                                               files beside it), calibration (JSON)
``mvsec``     ``davis/<side>/events`` (N, 4) ``x y t p`` (t in s, p -1/+1),   calibration (YAML files); a pose file
              ``image_raw`` + ``image_raw_ts``, ``imu`` (N, 6)                 (``*_gt.hdf5``) beside the data file
              ``ax ay az gx gy gz`` + ``imu_ts``; ``pose`` (N, 4, 4)          gives the ground truth
              camera-to-world + ``pose_ts`` (in the file or its ``_gt``)
============  ==============================================================  =========================================

Units and clocks: integer microseconds become seconds with one rounding (:func:`evio_lib.io.aedat4.us_to_seconds`,
``t = s + rest / 1e6``); DSEC's ``t_offset`` is added to the integers first. A time column that is not integer
microseconds is refused: the span of ``events/t`` must match the length of ``ms_to_idx`` (one entry per
millisecond), so times in nanoseconds or seconds are caught. MVSEC's times are float64 seconds, used as stored.
The IMU goes through :func:`evio_lib.io.imu_checks.check_imu_units` (units, swapped columns, axes against the
ground truth), and a recording whose IMU, frames and events share no time is refused (another clock).

Streaming: the events are converted a block of :data:`~evio_lib.io.event_source.CHUNK_EVENTS` at a time into an
``.npy`` file of EVENT_DTYPE under the cache folder (``<cache>/recordings``, reused while the HDF5 file keeps its
size and modification time), each block checked (sorted, polarity, inside the sensor), and the Sequence holds a
read-only memory map of it (:mod:`evio_lib.io.event_source`).

Where a file holds two cameras (MVSEC's ``davis/left`` and ``davis/right``), the reader refuses in one line naming
both; ``group="davis/left"`` (``--topics davis/left`` on the command line) picks one.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np

from evio_lib.events.array import EVENT_DTYPE
from evio_lib.io.errors import DataFileError, require_file
from evio_lib.io.event_source import CHUNK_EVENTS, EventChunkChecker, open_events_npy, write_events_npy

__all__ = ["read_hdf5", "write_dsec_h5", "write_tumvie_h5", "write_mvsec_h5", "hdf5_layout", "LAYOUTS",
           "SENSOR_SIZES", "recording_cache_path", "pose_matrices_to_groundtruth", "require_package"]

LAYOUTS = ("dsec", "tumvie", "mvsec")
#: (width, height) of the event sensors of the datasets whose files do not say it.
SENSOR_SIZES = {"dsec": (640, 480), "tumvie": (1280, 720)}


def require_package(module: str, package: str, what: str) -> Any:
    """Return the imported ``module``, or raise DataFileError in one line naming the package to install."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise DataFileError(f"reading {what} needs the Python package {package}: pip install {package} (or pip "
                            f"install -e '.[recordings]')") from None


def recording_cache_path(source: Path, stream: str) -> Path:
    """Return the ``.npy`` event file that caches ``stream`` of the recording ``source`` (keyed by its resolved
    path, size and modification time)."""
    import hashlib

    stat = source.stat()
    key = f"{source.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{stream}|v1"
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    from evio_lib.io.cache import default_cache_dir

    return default_cache_dir() / "recordings" / f"{source.stem}_{digest}_events.npy"


def cached_events(source: Path, stream: str, chunks: Iterator[np.ndarray]) -> np.ndarray:
    """Return the memory map of ``stream``'s events, writing them from ``chunks`` first when not cached."""
    path = recording_cache_path(source, stream)
    if path.is_file():
        try:
            return open_events_npy(path)
        except DataFileError:
            path.unlink(missing_ok=True)  # damaged: written again below
    path.parent.mkdir(parents=True, exist_ok=True)
    write_events_npy(path, chunks)
    return open_events_npy(path)


def hdf5_layout(h5: Any) -> str:
    """Return the layout of an open h5py file ('dsec', 'tumvie' or 'mvsec'), or raise DataFileError listing what
    it holds."""
    if "events" in h5 and hasattr(h5["events"], "keys") and {"x", "y", "t", "p"} <= set(h5["events"].keys()):
        return "dsec" if "t_offset" in h5 else "tumvie"
    if "davis" in h5 and any("events" in h5["davis"][side] for side in h5["davis"]):
        return "mvsec"
    names: list[str] = []
    h5.visit(lambda name: names.append(name) if len(names) < 12 else None)
    raise DataFileError(f"{Path(h5.filename).name}: not a known event layout (DSEC/TUM-VIE: events/x, events/y, "
                        f"events/t, events/p and ms_to_idx; MVSEC: davis/left/events); the file holds "
                        f"{', '.join(names) or 'nothing'}")


def _us_chunks(h5: Any, name: str, offset: int, checker: EventChunkChecker) -> Iterator[np.ndarray]:
    """Yield EVENT_DTYPE blocks of a DSEC/TUM-VIE file (t in us + ``offset``, p 0/1 -> -1/+1), checked."""
    from evio_lib.io.aedat4 import us_to_seconds

    group = h5["events"]
    n = group["t"].shape[0]
    for a in range(0, n, CHUNK_EVENTS):
        b = min(n, a + CHUNK_EVENTS)
        p = group["p"][a:b]
        if p.size and (p.min() < 0 or p.max() > 1):
            bad = int(np.flatnonzero((p < 0) | (p > 1))[0])
            raise DataFileError(f"{name}: events/p[{a + bad}] = {p[bad]}; expected 0 (darker) or 1 (brighter)")
        chunk = np.empty(b - a, dtype=EVENT_DTYPE)
        chunk["t"] = us_to_seconds(group["t"][a:b].astype(np.int64) + offset)
        chunk["x"] = group["x"][a:b]
        chunk["y"] = group["y"][a:b]
        chunk["p"] = 2 * p.astype(np.int8) - 1
        yield checker(chunk)


def _check_us_clock(h5: Any, name: str) -> None:
    """Refuse an ``events/t`` that is not integer microseconds: its span must match ``ms_to_idx``'s length."""
    t = h5["events"]["t"]
    if not np.issubdtype(t.dtype, np.integer):
        raise DataFileError(f"{name}: events/t has dtype {t.dtype}; the DSEC/TUM-VIE layout stores integer "
                            f"microseconds")
    if "ms_to_idx" not in h5 or t.shape[0] < 2:
        return
    ms = h5["ms_to_idx"].shape[0]
    last, first = int(t[-1]), int(t[0])
    # one entry per millisecond, from the file's zero (DSEC) or from its first event
    if not any(0.5 * c - 2 <= ms <= 2.0 * c + 2 for c in (last / 1000.0, (last - first) / 1000.0)):
        raise DataFileError(f"{name}: events/t runs to {last} and ms_to_idx has {ms} entries (one per "
                            f"millisecond): events/t is not in microseconds")


def pose_matrices_to_groundtruth(t: np.ndarray, T_BtoG: np.ndarray, body: str = "camera") -> Any:
    """Return the GroundTruth of (K, 4, 4) body-to-world matrices at times ``t``: p_BinG = T[:3, 3], JPL
    q_GtoB = rot_to_quat(R_BtoG^T) (:func:`evio_lib.geometry.rotation.rot_to_quat`)."""
    from evio_lib.geometry.rotation import rot_to_quat
    from evio_lib.sequence import GroundTruth

    T = np.asarray(T_BtoG, dtype=np.float64)
    q = np.array([rot_to_quat(R.T) for R in T[:, :3, :3]]).reshape(-1, 4)
    return GroundTruth(t=np.asarray(t, np.float64), p_BinG=T[:, :3, 3].copy(), q_GtoB=q, body=body)


def _mvsec_group(h5: Any, group: str | None, name: str) -> str:
    sides = [f"davis/{side}" for side in h5["davis"] if "events" in h5["davis"][side]]
    if group is None:
        if len(sides) > 1:
            raise DataFileError(f"{name} holds {len(sides)} event cameras: {', '.join(sides)}; pick one with "
                                f"--topics {sides[0]}")
        return sides[0]
    group = group.strip("/")
    if group not in sides:
        raise DataFileError(f"{name}: no event camera {group!r}; the file holds {', '.join(sides)}")
    return group


def read_hdf5(path: str | Path, *, load_events: bool = True, load_frames: bool = True, layout: str | None = None,
              group: str | None = None) -> Any:
    """Return the Sequence of an HDF5 event recording (layouts in the module docstring).

    Args:
        path: the ``.h5`` / ``.hdf5`` file.
        load_events: convert the events (first read: a pass over the file; later reads reuse the ``.npy`` cache).
        load_frames: keep MVSEC's APS frames.
        layout: force a layout ('dsec', 'tumvie', 'mvsec'; None: found from the datasets).
        group: MVSEC's camera ('davis/left' or 'davis/right'), required when the file holds both.

    Returns:
        Sequence with camera None (no layout holds a calibration), events a memory map of the cached ``.npy``
        (:mod:`evio_lib.io.event_source`), frames, IMU and ground truth where the layout has them; metadata names
        the layout, the sensor size and where it came from.

    Raises:
        DataFileError naming the file and the dataset for a missing package, an unknown layout, times not in
        microseconds, unsorted events, pixels outside the sensor, polarities other than 0/1.
    """
    h5py = require_package("h5py", "h5py", "HDF5 recordings")
    require_package("hdf5plugin", "hdf5plugin", "compressed HDF5 recordings (DSEC's Blosc/zstd)")
    from evio_lib.io.imu_checks import check_imu_units
    from evio_lib.sequence import ImuSamples, Sequence

    path = require_file(path, "an HDF5 event recording (.h5, .hdf5)")
    name = path.name
    try:
        h5 = h5py.File(path, "r")
    except OSError as error:
        raise DataFileError(f"{name}: not a readable HDF5 file ({str(error).splitlines()[0]})") from None
    with h5:
        found = hdf5_layout(h5) if layout is None else layout
        if found not in LAYOUTS:
            raise DataFileError(f"layout must be one of {LAYOUTS}; got {layout!r}")
        metadata: dict = {"source": str(path), "format": f"HDF5 ({found})"}
        frames_t, frames, imu, truth = np.zeros(0), None, None, None
        if found in ("dsec", "tumvie"):
            if group is not None:
                raise DataFileError(f"{name}: the {found} layout holds one camera; --topics applies to MVSEC files "
                                    f"and ROS bags")
            _check_us_clock(h5, name)
            attrs = h5.attrs
            if "width" in attrs and "height" in attrs:
                width, height = int(attrs["width"]), int(attrs["height"])
                metadata["sensor_size_source"] = "the file's width and height attributes"
            else:
                width, height = SENSOR_SIZES[found]
                metadata["sensor_size_source"] = f"the {found} dataset's sensor"
            offset = int(np.asarray(h5["t_offset"])) if found == "dsec" else 0
            metadata["t_offset_us"] = offset
            stream = "events"
            where = f"{name} events/"
            chunks = lambda: _us_chunks(h5, name, offset, EventChunkChecker(where, (width, height)))  # noqa: E731
            n_events = h5["events"]["t"].shape[0]
        else:
            side = _mvsec_group(h5, group, name)
            g = h5[side]
            metadata["group"] = side
            raw = g["events"]
            if raw.ndim != 2 or raw.shape[1] != 4:
                raise DataFileError(f"{name}: {side}/events has shape {raw.shape}; MVSEC stores (N, 4) x y t p")
            if "image_raw" in g and g["image_raw"].ndim == 3:
                height, width = g["image_raw"].shape[1:]
                metadata["sensor_size_source"] = f"{side}/image_raw"
            else:
                width, height = 346, 260
                metadata["sensor_size_source"] = "the DAVIS346 of MVSEC"
            stream = f"{side}/events"
            where = f"{name} {side}/events"

            def chunks() -> Iterator[np.ndarray]:
                check = EventChunkChecker(where, (width, height))
                for a in range(0, raw.shape[0], CHUNK_EVENTS):
                    block = np.asarray(raw[a:a + CHUNK_EVENTS], dtype=np.float64)
                    x, y, p = block[:, 0], block[:, 1], block[:, 3]
                    if np.any(x != np.round(x)) or np.any(y != np.round(y)) or np.any(x < 0) or np.any(y < 0):
                        bad = int(np.flatnonzero((x != np.round(x)) | (y != np.round(y)) | (x < 0) | (y < 0))[0])
                        raise DataFileError(f"{where}: row {a + bad} has pixel ({x[bad]!r}, {y[bad]!r}); expected "
                                            f"integer columns x y t p")
                    chunk = np.empty(block.shape[0], dtype=EVENT_DTYPE)
                    chunk["t"] = block[:, 2]
                    chunk["x"] = np.minimum(x, 65535)
                    chunk["y"] = np.minimum(y, 65535)
                    chunk["p"] = np.where(p > 0, 1, np.where(p == 0, -1, np.where(p == -1, -1, 0)))  # 0 or -1: off
                    yield check(chunk)
            n_events = raw.shape[0]
            if load_frames and "image_raw" in g:
                frames = np.asarray(g["image_raw"], dtype=np.uint8)
                frames_t = np.asarray(g["image_raw_ts"], dtype=np.float64)
            if "imu" in g and "imu_ts" in g:
                values = np.asarray(g["imu"], dtype=np.float64)
                if values.ndim != 2 or values.shape[1] != 6:
                    raise DataFileError(f"{name}: {side}/imu has shape {values.shape}; expected (N, 6) ax ay az gx gy gz")
                imu = ImuSamples(t=np.asarray(g["imu_ts"], dtype=np.float64), gyro=values[:, 3:], accel=values[:, :3])
            truth = _mvsec_truth(h5, path, side, h5py)
        if load_events and n_events:
            events = cached_events(path, f"{found}:{stream}", chunks())
        else:
            events = np.empty(0, EVENT_DTYPE)
    metadata["sensor_size"] = (int(width), int(height))
    if frames is None:
        frames = np.zeros((0, height, width), dtype=np.uint8)
    if imu is not None:
        if len(imu) >= 2 and np.all(np.diff(imu.t) > 0):
            check_imu_units(imu.t, imu.gyro, imu.accel, truth, source=f"{name} {metadata.get('group', '')}/imu",
                            columns="ax ay az gx gy gz (m/s^2, then rad/s), as MVSEC stores them")
        _check_shared_clock(name, events, frames_t, imu)
    try:
        return Sequence(name=path.stem, camera=None, events=events, frame_times=frames_t, frames=frames, imu=imu,
                        groundtruth=truth, metadata=metadata)
    except ValueError as exc:
        raise DataFileError(f"{name}: the recording is not a valid sequence ({exc})") from None


def _mvsec_truth(h5: Any, path: Path, side: str, h5py: Any) -> Any:
    """Return MVSEC's camera poses (``pose`` + ``pose_ts`` in the file or in its ``*_gt.hdf5``), or None."""
    candidates = [h5]
    gt_name = path.name.replace("_data.", "_gt.")
    if gt_name != path.name and (path.parent / gt_name).is_file():
        candidates.append(h5py.File(path.parent / gt_name, "r"))
    try:
        for f in candidates:
            if side in f and "pose" in f[side] and "pose_ts" in f[side]:
                T = np.asarray(f[side]["pose"], dtype=np.float64)
                if T.ndim != 3 or T.shape[1:] != (4, 4):
                    raise DataFileError(f"{Path(f.filename).name}: {side}/pose has shape {T.shape}; expected "
                                        f"(N, 4, 4) camera-to-world matrices")
                return pose_matrices_to_groundtruth(np.asarray(f[side]["pose_ts"], np.float64), T)
    finally:
        for f in candidates[1:]:
            f.close()
    return None


def _check_shared_clock(name: str, events: np.ndarray, frame_times: np.ndarray, imu: Any) -> None:
    """Refuse events or frames that share no time with the IMU (another clock, or other units)."""
    i0, i1 = float(imu.t[0]), float(imu.t[-1])
    spans = []
    if events.size:
        spans.append(("the events", float(events["t"][0]), float(events["t"][-1])))
    if frame_times.size:
        spans.append(("the frames", float(frame_times[0]), float(frame_times[-1])))
    for what, a, b in spans:
        if b < i0 or a > i1:
            raise DataFileError(f"{name}: {what} cover [{a:.6g}, {b:.6g}] s and the IMU [{i0:.6g}, {i1:.6g}] s: they "
                                f"share no time (another clock, or other units)")


# ------------------------------------------------------------------------------------------------------ writers
def _seconds_to_us(t: np.ndarray, what: str) -> np.ndarray:
    """Return integer microseconds of seconds that lie on the microsecond grid (us_to_seconds gives them back)."""
    from evio_lib.io.aedat4 import us_to_seconds

    us = np.round(np.asarray(t, np.float64) * 1e6).astype(np.int64)
    back = us_to_seconds(us)
    if not np.array_equal(back, t):
        bad = int(np.flatnonzero(back != t)[0])
        raise ValueError(f"{what}[{bad}] = {float(t[bad])!r} s is not on the microsecond grid (us_to_seconds of an "
                         f"integer); put the recording on it first")
    return us


def _write_us_events(h5: Any, events: np.ndarray, offset_us: int) -> None:
    us = _seconds_to_us(events["t"], "events t") - offset_us
    group = h5.create_group("events")
    group.create_dataset("t", data=us.astype(np.int64 if us.size and us.max() >= 2 ** 32 else np.uint32))
    group.create_dataset("x", data=events["x"].astype(np.uint16))
    group.create_dataset("y", data=events["y"].astype(np.uint16))
    group.create_dataset("p", data=(events["p"] > 0).astype(np.uint8))
    # ms_to_idx[k] = index of the first event with t >= k ms (the DSEC definition)
    last_ms = int(us[-1] // 1000) + 1 if us.size else 0
    h5.create_dataset("ms_to_idx", data=np.searchsorted(us, np.arange(last_ms + 1) * 1000, side="left")
                      .astype(np.uint64))


def write_dsec_h5(events: np.ndarray, path: str | Path, t_offset_us: int | None = None,
                  sensor_size: tuple[int, int] | None = None) -> Path:
    """Write events (times on the microsecond grid) in the DSEC layout: events/{t,x,y,p}, ms_to_idx, t_offset
    (default: the first event's whole microseconds, so ``events/t`` starts near 0); ``sensor_size`` as attributes."""
    import h5py

    us0 = int(np.round(float(events["t"][0]) * 1e6)) if events.size else 0
    offset = us0 if t_offset_us is None else int(t_offset_us)
    with h5py.File(path, "w") as h5:
        _write_us_events(h5, events, offset)
        h5.create_dataset("t_offset", data=np.int64(offset))
        if sensor_size is not None:
            h5.attrs["width"], h5.attrs["height"] = int(sensor_size[0]), int(sensor_size[1])
    return Path(path)


def write_tumvie_h5(events: np.ndarray, path: str | Path, sensor_size: tuple[int, int] | None = None) -> Path:
    """Write events (times on the microsecond grid) in the TUM-VIE layout: events/{t,x,y,p} in us, ms_to_idx."""
    import h5py

    if events.size and float(events["t"][-1]) >= 2 ** 32 / 1e6:
        raise ValueError(f"TUM-VIE stores microseconds from the recording's start (uint32 ms_to_idx from 0); the last "
                         f"event is at {float(events['t'][-1])!r} s: subtract the start time first")
    with h5py.File(path, "w") as h5:
        _write_us_events(h5, events, 0)
        if sensor_size is not None:
            h5.attrs["width"], h5.attrs["height"] = int(sensor_size[0]), int(sensor_size[1])
    return Path(path)


def write_mvsec_h5(sequence: Any, path: str | Path, side: str = "left", pose_matrices: np.ndarray | None = None
                   ) -> Path:
    """Write a Sequence in MVSEC's layout under ``davis/<side>``: events (N, 4) x y t p, image_raw(+_ts), imu (N, 6)
    ax ay az gx gy gz (+ imu_ts), and the camera ground truth as pose (N, 4, 4) camera-to-world (+ pose_ts):
    ``pose_matrices`` when given (one per ground-truth time), else made from the quaternions."""
    import h5py

    from evio_lib.geometry.rotation import quat_to_rot

    ev = sequence.events
    with h5py.File(path, "w") as h5:
        g = h5.create_group(f"davis/{side}")
        g.create_dataset("events", data=np.stack([ev["x"], ev["y"], ev["t"], ev["p"]], axis=1).astype(np.float64))
        g.create_dataset("image_raw", data=sequence.frames)
        g.create_dataset("image_raw_ts", data=sequence.frame_times)
        if sequence.imu is not None:
            g.create_dataset("imu", data=np.concatenate([sequence.imu.accel, sequence.imu.gyro], axis=1))
            g.create_dataset("imu_ts", data=sequence.imu.t)
        if sequence.groundtruth is not None:
            gt = sequence.groundtruth
            if pose_matrices is not None:
                T = np.asarray(pose_matrices, dtype=np.float64)
            else:
                T = np.tile(np.eye(4), (len(gt), 1, 1))
                T[:, :3, :3] = np.swapaxes(quat_to_rot(gt.q_GtoB), -1, -2)  # R_CtoG = C(q_GtoC)^T
                T[:, :3, 3] = gt.p_BinG
            g.create_dataset("pose", data=T)
            g.create_dataset("pose_ts", data=gt.t)
    return Path(path)
