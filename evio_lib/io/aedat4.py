"""AEDAT4 recordings (iniVation DV, e.g. a DAVIS346): events, APS frames and IMU via the ``aedat`` package.

The ``aedat`` decoder (PyPI ``aedat``, Rust) yields packets ``{"stream_id": k, <kind>: data}`` where
``id_to_stream()`` tells each stream's kind ("events" with width/height, "frame", "imus", "triggers"):

* events: structured array (t [us], x, y, on [bool]) -> EVENT_DTYPE, t in s, p = +1 for on, -1 for off;
* frame: dict with ``t`` [us] (the exposure midpoint), ``format`` ("L", "RGB", "RGBA") and ``pixels`` (H, W[, C]);
* imus: structured array (t [us], temperature [deg C], accelerometer_x/y/z, gyroscope_x/y/z, magnetometer_*).

Units: the DAVIS IMU (InvenSense MPU) stores the accelerometer in g and the gyroscope in deg/s. They are
converted here to the library's SI units::

    accel [m/s^2] = accel [g] * 9.80665        (standard gravity, the definition of the unit g)
    gyro [rad/s]  = gyro [deg/s] * pi / 180

Timestamps stay absolute (Unix time): microseconds are exact in float64 seconds at that magnitude
(float64 spacing ~2.4e-7 s). The IMU is expressed in the IMU chip frame; the file holds no calibration and no
camera-IMU extrinsics, so ``camera``, ``R_CtoI`` and ``p_CinI`` are None. The converted samples go through
:func:`evio_lib.io.imu_checks.check_imu_units` (a file whose IMU is not in g and deg/s is refused, not run).

To run the pipeline on a file (``python -m evio_lib run FILE.aedat4 --calib calib.txt``) the calibration comes from
an ECD-style ``calib.txt`` (``fx fy cx cy k1 k2 p1 p2 [k3]``, :func:`evio_lib.io.ecd.read_calib`); the extrinsics
are taken as camera = IMU frame, as for the ECD: on a DAVIS the IMU chip sits on the camera's board, a centimetre or
so from the sensor, its axes assumed aligned with the camera's (give ``--extrinsics`` when they are not).
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from evio_lib.events.array import EVENT_DTYPE
from evio_lib.io.errors import DataFileError, require_file
from evio_lib.io.imu_checks import check_imu_units
from evio_lib.sequence import ImuSamples, Sequence

__all__ = ["read_aedat4", "STANDARD_GRAVITY", "us_to_seconds"]

#: Standard gravity [m/s^2]: one "g" of the accelerometer.
STANDARD_GRAVITY = 9.80665


def us_to_seconds(t_us: np.ndarray) -> np.ndarray:
    """Return float64 seconds from integer microseconds (one rounding: t = s + us_rest / 1e6).

    >>> us_to_seconds(np.array([1589163147368868], dtype=np.uint64)).tolist()
    [1589163147.368868]
    """
    seconds, rest = np.divmod(np.asarray(t_us).astype(np.int64), 1_000_000)
    return seconds.astype(np.float64) + rest.astype(np.float64) / 1e6


def _frame_to_gray(frame: dict, where: str) -> np.ndarray:
    """Return an AEDAT4 frame's pixels as (H, W) uint8 grayscale."""
    pixels = np.asarray(frame["pixels"])
    fmt = frame.get("format", "L")
    if pixels.ndim == 3 and pixels.shape[2] == 1:
        pixels = pixels[:, :, 0]
    elif pixels.ndim == 3:
        code = cv2.COLOR_RGBA2GRAY if pixels.shape[2] == 4 else cv2.COLOR_RGB2GRAY
        pixels = cv2.cvtColor(np.ascontiguousarray(pixels), code)
    if pixels.ndim != 2 or pixels.dtype != np.uint8:
        raise DataFileError(f"{where}: frame format {fmt!r} with pixels {pixels.dtype} {pixels.shape} is not 8-bit grayscale/colour")
    return pixels


@contextlib.contextmanager
def _native_stderr_captured():
    """Send what native code writes to file descriptor 2 into a temporary file; yield a function returning it.

    The Rust decoder panics on some damaged files, and its panic hook prints "thread ... panicked at ..." (and a
    backtrace with RUST_BACKTRACE) on the process's stderr before Python sees the exception: the command line's
    one-line error would come with a screenful of Rust. What was captured is written back to stderr when decoding
    succeeds, and dropped when the damage is reported as one DataFileError.
    """
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr (e.g. some embedded interpreters): capture nothing
        yield lambda: b""
        return
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            yield lambda: (captured.seek(0), captured.read())[1]
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def read_aedat4(path: str | Path, *, load_frames: bool = True) -> Sequence:
    """Return the Sequence of an AEDAT4 file: events, APS frames and IMU samples in SI units.

    Args:
        path: the ``.aedat4`` file.
        load_frames: keep the APS frames (False: frames empty, their size still gives the sensor size).

    Returns:
        Sequence with camera None (no calibration in the file), frames (F, H, W) uint8, imu (gyro rad/s,
        accel m/s^2, see the module docstring for the conversion), metadata with the sensor size, the units
        conversion, the number of trigger events and the mean IMU temperature.

    Raises:
        DataFileError (a ValueError): missing file, a file the decoder cannot read, no event stream, or a frame
            whose size differs from the sensor's.
    """
    import aedat

    path = require_file(path, "an AEDAT4 recording")
    name = path.name
    failure = None
    with _native_stderr_captured() as native_output:
        try:
            decoder = aedat.Decoder(str(path))
            streams = decoder.id_to_stream()
            packets = list(decoder)
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as exc:  # noqa: B036 - the Rust decoder raises RuntimeErrors, and on a damaged header
            # panics with pyo3's PanicException, which derives from BaseException, not Exception
            failure = exc
        else:
            leftover = native_output()
    if failure is not None:
        detail = (str(failure).strip().splitlines() or [""])[0][:200]
        raise DataFileError(f"{name}: not a readable AEDAT4 file, damaged or truncated? ({type(failure).__name__}: "
                            f"{detail})") from None
    if leftover:  # the decoder's own messages of a successful read go where they would have gone
        sys.stderr.flush()
        os.write(2, leftover)
    event_ids = [k for k, s in streams.items() if s.get("type") == "events"]
    if not event_ids:
        raise DataFileError(f"{name}: no event stream in the file; streams: {streams}")
    event_id = min(event_ids)
    width, height = int(streams[event_id]["width"]), int(streams[event_id]["height"])

    event_chunks, frame_list, frame_t, imu_chunks, n_triggers = [], [], [], [], 0
    for packet in packets:
        if packet["stream_id"] == event_id and "events" in packet:
            event_chunks.append(packet["events"])
        elif "frame" in packet and load_frames:
            frame = packet["frame"]
            gray = _frame_to_gray(frame, f"{name} frame {len(frame_list)}")
            if gray.shape != (height, width):
                raise DataFileError(
                    f"{name} frame {len(frame_list)}: size {gray.shape[1]} x {gray.shape[0]} differs from the sensor "
                    f"{width} x {height} (region-of-interest frames are not supported)"
                )
            frame_list.append(gray)
            frame_t.append(int(frame["t"]))
        elif "imus" in packet:
            imu_chunks.append(packet["imus"])
        elif "triggers" in packet:
            n_triggers += len(packet["triggers"])

    raw = np.concatenate(event_chunks) if event_chunks else np.zeros(0, dtype=[("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")])
    events = np.empty(raw.shape[0], dtype=EVENT_DTYPE)
    events["t"] = us_to_seconds(raw["t"])
    events["x"] = raw["x"]
    events["y"] = raw["y"]
    events["p"] = np.where(raw["on"], 1, -1)  # on -> +1 (brighter), off -> -1
    resorted = bool(np.any(events["t"][1:] < events["t"][:-1]))
    if resorted:
        events = events[np.argsort(events["t"], kind="stable")]

    metadata: dict = {
        "source": str(path),
        "format": "AEDAT4",
        "sensor_size": (width, height),
        "streams": {str(k): v.get("type") for k, v in streams.items()},
        "n_triggers": n_triggers,
        "events_resorted": resorted,
    }
    imu = None
    if imu_chunks:
        samples = np.concatenate(imu_chunks)
        order = np.argsort(samples["t"], kind="stable")
        samples = samples[order]
        accel_g = np.stack([samples[f"accelerometer_{a}"] for a in "xyz"], axis=1).astype(np.float64)
        gyro_dps = np.stack([samples[f"gyroscope_{a}"] for a in "xyz"], axis=1).astype(np.float64)
        imu = ImuSamples(t=us_to_seconds(samples["t"]),
                         gyro=np.deg2rad(gyro_dps),  # deg/s -> rad/s
                         accel=accel_g * STANDARD_GRAVITY)  # g -> m/s^2
        metadata["imu_units"] = "file: accelerometer in g, gyroscope in deg/s; converted: accel * 9.80665 -> m/s^2, gyro * pi/180 -> rad/s"
        metadata["imu_temperature_mean_C"] = round(float(np.mean(samples["temperature"])), 3)
        if len(imu) >= 2 and np.all(np.diff(imu.t) > 0):  # (duplicate times: the Sequence below names them)
            check_imu_units(imu.t, imu.gyro, imu.accel, source=f"{name} IMU (converted from g and deg/s)",
                            columns="accelerometer in g and gyroscope in deg/s, as AEDAT4 (DV) stores them")

    if frame_list:
        order = np.argsort(frame_t, kind="stable")
        frames = np.stack(frame_list)[order]
        frame_times = us_to_seconds(np.array(frame_t, dtype=np.int64)[order])
    else:
        frames, frame_times = np.zeros((0, height, width), dtype=np.uint8), np.zeros(0)
    try:  # the Sequence checks every field (e.g. strictly increasing IMU and frame times): name the file
        return Sequence(name=path.stem, camera=None, events=events, frame_times=frame_times, frames=frames, imu=imu,
                        metadata=metadata)
    except ValueError as exc:
        raise DataFileError(f"{name}: the recording is not a valid sequence ({exc})") from None
