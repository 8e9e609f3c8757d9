"""RPG Event-Camera Dataset (ECD) text layout: read and write a folder of ``*.txt`` files.

Layout (Mueggler et al., "The Event-Camera Dataset and Simulator", IJRR 2017), one record per line::

    events.txt        t x y p                  p in {0, 1} (0 = darker -> -1, 1 = brighter -> +1)
    imu.txt           t ax ay az gx gy gz      accelerometer [m/s^2] THEN gyroscope [rad/s], IMU frame
    images.txt        t images/frame_00000000.png
    images/           the 8-bit grayscale frames
    groundtruth.txt   t px py pz qx qy qz qw   CAMERA pose: p_CinG, Hamilton quaternion of R_CtoG
    calib.txt         fx fy cx cy k1 k2 p1 p2 k3

evio extensions (written by :func:`write_ecd`, read back when present):

    groundtruth_imu.txt  t px py pz qx qy qz qw [vx vy vz] [bgx bgy bgz bax bay baz]
                         IMU state: p_IinG, Hamilton quaternion of R_ItoG, v_IinG, gyro and accel biases
                         (8, 11, 14 or 17 columns: pose, + velocity, + biases, + both)
    evio_sim.json        name, sensor size (width, height), R_CtoI, p_CinI and the metadata (IMU noise
                         parameters, gravity, simulator settings ...)

Quaternions: the Hamilton quaternion of R_BtoG has the same four numbers as the JPL q_GtoB used inside the
library (see :mod:`evio_lib.io.tum`). Times are written with 9 decimals when they lie on the nanosecond grid
(the ECD style), else with the shortest exact representation; all other numbers with the shortest exact
representation, so a write -> read round trip reproduces the arrays exactly.

Sensor size (needed to check pixel coordinates and to build the camera): the ``sensor_size`` argument, else
the sidecar, else the first frame, else the DAVIS240C of the ECD (240 x 180).

A half-written folder is never read as a recording: :func:`write_ecd` creates the marker file
:data:`INCOMPLETE_MARKER` before it writes anything and removes it after the last file, and :func:`read_ecd`
refuses a folder that holds the marker (a write that failed or was killed). A folder that write_ecd created itself
is removed again when the write fails.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from evio_lib.events.array import EVENT_DTYPE
from evio_lib.geometry.camera import PinholeRadtan, intrinsics_problem
from evio_lib.geometry.rotation import as_float_array, check_rotation
from evio_lib.io.cache import from_json_value, to_json_value
from evio_lib.io.errors import DataFileError, read_table, read_text, require_file, time_format, write_table
from evio_lib.io.image_files import decoder_note, read_image
from evio_lib.io.imu_checks import check_imu_units
from evio_lib.io.tum import read_tum, write_tum
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence

__all__ = ["read_ecd", "read_calib", "read_ecd_events", "read_ecd_frames", "write_ecd", "DAVIS240C_SIZE", "SIDECAR_NAME", "INCOMPLETE_MARKER"]

#: (width, height) of the DAVIS240C that recorded the ECD, assumed when nothing else gives the size.
DAVIS240C_SIZE = (240, 180)
#: File name of the evio sidecar (extrinsics, sensor size, metadata).
SIDECAR_NAME = "evio_sim.json"
#: File that :func:`write_ecd` writes first and removes last; :func:`read_ecd` refuses a folder that holds it.
INCOMPLETE_MARKER = ".evio_incomplete"

_EVENT_COLUMNS = ("t", "x", "y", "p")
_IMU_COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")
_CALIB_COLUMNS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
_POSE = ("t", "px", "py", "pz", "qx", "qy", "qz", "qw")
_VEL = ("vx", "vy", "vz")
_BIAS = ("bgx", "bgy", "bgz", "bax", "bay", "baz")
_GT_IMU_LAYOUTS = {8: _POSE, 11: _POSE + _VEL, 14: _POSE + _BIAS, 17: _POSE + _VEL + _BIAS}
_LAYOUT_FILES = ("events.txt", "imu.txt", "images.txt", "groundtruth.txt", "calib.txt", "groundtruth_imu.txt", SIDECAR_NAME)


def read_ecd_events(path: str | Path, *, sensor_size: tuple[int, int] | None = None, name: str | None = None) -> np.ndarray:
    """Return the events of an ECD event file (``t x y p`` per line, p in {0, 1}) as an EVENT_DTYPE array.

    Args:
        path: the text file (e.g. ``events.txt`` or the ``slider_seg.txt`` slice).
        sensor_size: (width, height); when given, x must lie in [0, width) and y in [0, height).
        name: how error messages name the file (default: its file name).

    Raises:
        DataFileError (a ValueError): "NAME line L: problem" for a wrong column count, a non-number, NaN,
            non-integer or out-of-sensor pixel coordinates, polarity other than 0/1, or a timestamp smaller than
            the previous one (equal timestamps are allowed); "NAME: file not found ..." when missing.

    Parsing uses ``np.loadtxt`` with integer pixel columns (its rate:
    docs/results/speed.md#small-costs-behind-the-codes-choices).

    >>> import tempfile, os
    >>> f = os.path.join(tempfile.mkdtemp(), "events.txt")
    >>> _ = open(f, "w").write("0.003811000 96 133 0\\n0.003820001 127 171 1\\n")
    >>> ev = read_ecd_events(f, sensor_size=(240, 180))
    >>> ev["t"].tolist(), ev["p"].tolist()
    ([0.003811, 0.003820001], [-1, 1])
    """
    table = read_table(path, _EVENT_COLUMNS, name=name, int_columns=("x", "y", "p"))
    table.check_times("t", strict=False)
    width, height = sensor_size if sensor_size is not None else (65536, 65536)
    where = f"for a {width} x {height} sensor" if sensor_size is not None else "(uint16)"
    table.check_range("x", 0, width - 1, f"x must be an integer in [0, {width}) {where}")
    table.check_range("y", 0, height - 1, f"y must be an integer in [0, {height}) {where}")
    table.check_range("p", 0, 1, "polarity must be 0 (darker) or 1 (brighter)")
    events = np.empty(len(table), dtype=EVENT_DTYPE)
    events["t"] = table["t"]
    events["x"] = table["x"]
    events["y"] = table["y"]
    events["p"] = 2 * table["p"] - 1  # p_file in {0, 1} -> p in {-1, +1}
    return events


def _read_sidecar(folder: Path) -> dict | None:
    """Return the decoded evio_sim.json of ``folder``, or None when absent."""
    path = folder / SIDECAR_NAME
    if not path.is_file():
        return None
    try:
        raw = json.loads(read_text(path))
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{SIDECAR_NAME} line {exc.lineno}: invalid JSON ({exc.msg})") from None
    if not isinstance(raw, dict):
        raise DataFileError(f"{SIDECAR_NAME}: expected a JSON object at the top level; got {type(raw).__name__}")
    sidecar = from_json_value(raw)
    meta = sidecar.get("metadata")
    if meta is not None and not isinstance(meta, dict):
        raise DataFileError(f"{SIDECAR_NAME}: metadata must be a JSON object; got {type(meta).__name__}")
    if isinstance(meta, dict) and meta.get("gravity_G") is not None:
        _check_gravity(meta["gravity_G"])
    if isinstance(meta, dict) and meta.get("imu_noise") is not None and not isinstance(meta["imu_noise"], dict):
        raise DataFileError(f"{SIDECAR_NAME}: metadata.imu_noise must be an object of noise densities (e.g. "
                            f'{{"gyro_noise_density": 8.73e-05, "accel_noise_density": 0.00392}}); got '
                            f"{meta['imu_noise']!r}")
    _check_extrinsics(sidecar)
    return sidecar


def _check_extrinsics(sidecar: dict) -> None:
    """Refuse a sidecar's R_CtoI that is no 3 x 3 rotation or p_CinI that is no 3 numbers, naming the file (the
    library's own checks: ``geometry.rotation.check_rotation`` and ``as_float_array``)."""
    for key, what, check, ndim in (
            ("R_CtoI", "a 3 x 3 rotation matrix (rows of 3 numbers), the camera's orientation in the IMU frame",
             lambda value: check_rotation(value, "R_CtoI"), 2),
            ("p_CinI", "3 numbers [m], the camera's position in the IMU frame",
             lambda value: as_float_array(value, "p_CinI", (3,)), 1)):
        value = sidecar.get(key)
        if value is None:
            continue
        try:
            problem = None if check(value).ndim == ndim else "one, not a stack of them"
        except ValueError as error:
            problem = str(error)
        if problem:
            raise DataFileError(f"{SIDECAR_NAME}: {key} must be {what}; got {value!r} ({problem})")


def _check_gravity(value) -> None:
    """Refuse a sidecar's gravity_G that is not a 3-vector of about 9.81 m/s^2 (9-10.5), naming the file."""
    try:
        g = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise DataFileError(f"{SIDECAR_NAME}: metadata.gravity_G must be 3 numbers (m/s^2 in the ground truth's "
                            f"world frame, e.g. [0, 0, -9.81]); got {value!r}") from None
    norm = float(np.linalg.norm(g))
    if not (np.isfinite(norm) and 9.0 <= norm <= 10.5):
        raise DataFileError(f"{SIDECAR_NAME}: metadata.gravity_G = {g.tolist()} has norm {norm:.4g} m/s^2; gravity is "
                            f"about 9.81 m/s^2 (e.g. [0, 0, -9.81] for a z-up world)")


def _read_image_list(folder: Path) -> tuple[np.ndarray, list[Path]]:
    """Return (times (F,), image paths) listed in images.txt, checking order and that each image exists."""
    path = folder / "images.txt"
    times, files = [], []
    for number, line in enumerate(read_text(path).splitlines(keepends=True), start=1):
        stripped = line.split("#", 1)[0].strip()
        if not stripped:
            continue
        tokens = stripped.split(maxsplit=1)                 # the path is the rest of the line: it may hold spaces
        if len(tokens) != 2:
            raise DataFileError(f"images.txt line {number}: expected 2 columns (t image_path), got {len(tokens)}")
        try:
            t = float(tokens[0])
        except ValueError:
            raise DataFileError(f"images.txt line {number}: column 't' must be a number; got {tokens[0]!r}") from None
        if not np.isfinite(t):
            raise DataFileError(f"images.txt line {number}: column 't' must be a finite number; got {tokens[0]!r}")
        if times and t <= times[-1]:
            raise DataFileError(
                f"images.txt line {number}: timestamp {t!r} follows {times[-1]!r}; t must be strictly increasing (no duplicates)"
            )
        image = folder / tokens[1]
        if not image.is_file():
            raise DataFileError(f"images.txt line {number}: image file {tokens[1]} not found in {folder}")
        times.append(t)
        files.append(image)
    return np.array(times, dtype=np.float64), files


def _load_gray(path: Path, where: str) -> np.ndarray:
    """Return the image at ``path`` as an (H, W) uint8 grayscale array."""
    image, said = read_image(path, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DataFileError(f"{where}: could not decode image {path.name}{decoder_note(said)}")
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if image.dtype != np.uint8:
        raise DataFileError(f"{where}: image {path.name} must be 8-bit; got dtype {image.dtype}")
    return image


def _read_single_row(path: Path, columns: tuple[str, ...]) -> np.ndarray:
    """Return the one data row of a one-line file (calib.txt) as float64 (len(columns),)."""
    table = read_table(path, columns)
    if len(table) != 1:
        if len(table) == 0:
            raise DataFileError(f"{path.name}: expected one line ({' '.join(columns)}); the file holds no data")
        raise table.error(1, f"expected a single line ({' '.join(columns)}); found {len(table)} data lines")
    return np.array([table[c][0] for c in columns], dtype=np.float64)


def _read_camera(folder: Path, width: int, height: int) -> PinholeRadtan | None:
    """Return the camera of calib.txt (fx fy cx cy k1 k2 p1 p2 k3) for a width x height sensor, or None without it."""
    if not (folder / "calib.txt").is_file():
        return None
    c = _read_single_row(folder / "calib.txt", _CALIB_COLUMNS)
    try:
        camera = PinholeRadtan(fx=c[0], fy=c[1], cx=c[2], cy=c[3], width=width, height=height,
                               k1=c[4], k2=c[5], p1=c[6], p2=c[7], k3=c[8])
    except ValueError as error:
        raise DataFileError(f"calib.txt: {error}") from None
    problem = intrinsics_problem(camera)
    if problem is not None:
        raise DataFileError(f"calib.txt (fx fy cx cy k1 k2 p1 p2 k3): {problem}")
    return camera


def read_calib(path: str | Path, width: int, height: int) -> PinholeRadtan:
    """Return the camera of a calibration file in the ECD ``calib.txt`` format for a width x height sensor.

    One line ``fx fy cx cy k1 k2 p1 p2 [k3]`` (pixels; radial-tangential distortion, k3 optional, 0 when absent), as
    ``run FILE.aedat4 --calib FILE`` takes it. Raises DataFileError naming the file for a missing file, a line with
    another number of values, or intrinsics that do not fit the image (:func:`intrinsics_problem`).
    """
    path = require_file(path, "a calibration `fx fy cx cy k1 k2 p1 p2 [k3]` (the ECD calib.txt format)")
    rows = [line.split("#", 1)[0].split() for line in path.read_text(encoding="utf-8", errors="replace").splitlines()]
    rows = [(number, tokens) for number, tokens in enumerate(rows, start=1) if tokens]
    layout = "fx fy cx cy k1 k2 p1 p2 [k3]"
    if len(rows) != 1:
        raise DataFileError(f"{path.name}: expected one line ({layout}); found {len(rows)} lines with values")
    number, tokens = rows[0]
    if len(tokens) not in (8, 9):
        raise DataFileError(f"{path.name} line {number}: expected 8 or 9 numbers ({layout}), got {len(tokens)}")
    try:
        c = [float(v) for v in tokens] + ([0.0] if len(tokens) == 8 else [])
        camera = PinholeRadtan(fx=c[0], fy=c[1], cx=c[2], cy=c[3], width=width, height=height,
                               k1=c[4], k2=c[5], p1=c[6], p2=c[7], k3=c[8])
    except ValueError as error:
        raise DataFileError(f"{path.name} line {number}: {error} ({layout})") from None
    problem = intrinsics_problem(camera)
    if problem is not None:
        raise DataFileError(f"{path.name} ({layout}): {problem}")
    return camera


def _read_camera_groundtruth(folder: Path) -> GroundTruth | None:
    """Return the camera poses of groundtruth.txt, or None without it."""
    if not (folder / "groundtruth.txt").is_file():
        return None
    t, p, q = read_tum(folder / "groundtruth.txt")
    return GroundTruth(t=t, p_BinG=p, q_GtoB=q, body="camera")  # Hamilton q of R_CtoG == JPL q_GtoC


def _read_groundtruth_imu(path: Path) -> GroundTruth:
    """Return the IMU-state ground truth of groundtruth_imu.txt (8, 11, 14 or 17 columns)."""
    first_line, n_columns = 0, 0
    try:  # the first data line only: the file may be large, and the table reader parses it whole next
        with open(path, "r", encoding="utf-8") as f:
            for number, line in enumerate(f, start=1):
                tokens = line.split("#", 1)[0].split()
                if tokens:
                    first_line, n_columns = number, len(tokens)
                    break
    except UnicodeDecodeError:
        read_text(path)  # raises the error that names the line and the byte
    if first_line == 0:
        raise DataFileError(f"{path.name}: the file holds no data (expected {' '.join(_POSE)} ...)")
    columns = _GT_IMU_LAYOUTS.get(n_columns)
    if columns is None:
        raise DataFileError(
            f"{path.name} line {first_line}: expected 8, 11, 14 or 17 columns "
            f"({' '.join(_POSE + _VEL + _BIAS)}, velocity and biases optional), got {n_columns}"
        )
    table = read_table(path, columns)
    table.check_times("t", strict=True)

    def stack(names: tuple[str, ...]) -> np.ndarray:
        return np.stack([table[c] for c in names], axis=1)

    has_v, has_b = "vx" in columns, "bgx" in columns
    return GroundTruth(
        t=table["t"].copy(),
        p_BinG=stack(("px", "py", "pz")),
        q_GtoB=table.unit_quaternions(("qx", "qy", "qz", "qw")),  # Hamilton q of R_ItoG == JPL q_GtoI (same numbers)
        body="imu",
        v_BinG=stack(_VEL) if has_v else None,
        bias_gyro=stack(_BIAS[:3]) if has_b else None,
        bias_accel=stack(_BIAS[3:]) if has_b else None,
    )


def read_ecd(folder: str | Path, *, load_events: bool = True, load_frames: bool = True,
             sensor_size: tuple[int, int] | None = None) -> Sequence:
    """Return the Sequence stored in an ECD folder (plus the evio extensions when present).

    Args:
        folder: the sequence folder; ``events.txt`` is required, every other file is optional (the matching
            part is then None or empty).
        load_events: parse events.txt (False: leave the events empty, e.g. to read only IMU and poses).
        load_frames: load the images of images.txt (False: no frames and no frame_times).
        sensor_size: (width, height) in pixels, overriding the sidecar / first frame / DAVIS240C default.

    Returns:
        Sequence with camera (from calib.txt), events, frames, imu, groundtruth (camera), groundtruth_imu,
        R_CtoI/p_CinI and metadata (from evio_sim.json); ``metadata["sensor_size_source"]`` says where the sensor
        size came from when there is no sidecar.

    Raises:
        DataFileError (a ValueError): missing events.txt or folder; any malformed file ("FILE line L: problem");
            a folder that :func:`write_ecd` did not finish (it holds :data:`INCOMPLETE_MARKER`).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DataFileError(f"ECD folder not found: {folder}")
    if (folder / INCOMPLETE_MARKER).exists():
        raise DataFileError(f"ECD folder {folder} is incomplete: a write_ecd into it failed or was interrupted "
                            f"({INCOMPLETE_MARKER} is still there); write the recording again")
    events_path = require_file(folder / "events.txt", "the ECD event list `t x y p`")
    sidecar = _read_sidecar(folder)
    has_images = (folder / "images.txt").is_file()
    frame_times, image_files = _read_image_list(folder) if has_images else (np.zeros(0), [])

    # sensor size: argument > sidecar (may say "unknown": None) > first frame > DAVIS240C
    size_source = "argument"
    size_unknown = False
    if sensor_size is None and sidecar is not None and "sensor_size" in sidecar:
        sensor_size, size_source = sidecar["sensor_size"], SIDECAR_NAME
        size_unknown = sensor_size is None
    if sensor_size is None and image_files:
        h, w = _load_gray(image_files[0], "images.txt first image").shape
        sensor_size, size_source, size_unknown = (w, h), "first frame", False
    if sensor_size is None:
        sensor_size, size_source = DAVIS240C_SIZE, "assumed DAVIS240C (240 x 180)"
    if len(sensor_size) != 2 or any(int(v) != v or v <= 0 for v in sensor_size):
        raise ValueError(f"sensor_size must be (width, height) in positive whole pixels; got {sensor_size!r} ({size_source})")
    width, height = int(sensor_size[0]), int(sensor_size[1])
    size_unknown = size_unknown and not (folder / "calib.txt").is_file()

    camera = _read_camera(folder, width, height)

    if load_frames and image_files:
        frames = np.empty((len(image_files), height, width), dtype=np.uint8)
        for i, path in enumerate(image_files):
            image = _load_gray(path, f"images.txt frame {i}")
            if image.shape != (height, width):
                raise DataFileError(
                    f"images.txt frame {i} ({path.name}): image size {image.shape[1]} x {image.shape[0]} differs from "
                    f"the sensor size {width} x {height}"
                )
            frames[i] = image
    else:
        shape = (0, 0, 0) if size_unknown else (0, height, width)
        frame_times, frames = np.zeros(0), np.zeros(shape, dtype=np.uint8)

    imu = None
    if (folder / "imu.txt").is_file():
        table = read_table(folder / "imu.txt", _IMU_COLUMNS)
        table.check_times("t", strict=True)
        imu = ImuSamples(t=table["t"].copy(),
                         gyro=np.stack([table[c] for c in ("gx", "gy", "gz")], axis=1),
                         accel=np.stack([table[c] for c in ("ax", "ay", "az")], axis=1))

    groundtruth = _read_camera_groundtruth(folder)
    groundtruth_imu = None
    if (folder / "groundtruth_imu.txt").is_file():
        groundtruth_imu = _read_groundtruth_imu(folder / "groundtruth_imu.txt")
    if imu is not None:  # units and axes, before the events are parsed (see evio_lib.io.imu_checks)
        side_meta = sidecar.get("metadata", {}) if sidecar is not None else {}
        check_imu_units(imu.t, imu.gyro, imu.accel, groundtruth_imu if groundtruth_imu is not None else groundtruth,
                        source="imu.txt", columns="t ax ay az gx gy gz (accelerometer m/s^2, then gyro rad/s)",
                        R_CtoI=sidecar.get("R_CtoI") if sidecar is not None else None,
                        gravity_G=side_meta.get("gravity_G") if isinstance(side_meta, dict) else None,
                        truth_source="groundtruth_imu.txt" if groundtruth_imu is not None else "groundtruth.txt")

    event_size = None if size_unknown else (width, height)
    events = read_ecd_events(events_path, sensor_size=event_size) if load_events else np.empty(0, EVENT_DTYPE)

    if sidecar is not None:
        metadata = sidecar.get("metadata", {})
        name = sidecar.get("name", folder.name)
        R_CtoI, p_CinI = sidecar.get("R_CtoI"), sidecar.get("p_CinI")
    else:
        metadata = {"source": str(folder), "format": "ECD text", "sensor_size_source": size_source}
        name, R_CtoI, p_CinI = folder.name, None, None
    return Sequence(name=name, camera=camera, events=events, frame_times=frame_times, frames=frames, imu=imu,
                    groundtruth=groundtruth, groundtruth_imu=groundtruth_imu, R_CtoI=R_CtoI, p_CinI=p_CinI,
                    metadata=metadata)


def read_ecd_frames(folder: str | Path) -> Sequence:
    """Return the frames (images.txt + images/) and calibration (calib.txt) of an ECD-style folder, without events.

    For folders whose event file is missing, named otherwise or too large to parse when only the frames are wanted
    (e.g. a slice whose events are in ``slider_seg.txt``). The sensor size is the first frame's; ground truth
    (``groundtruth.txt``) is read when present. Raises DataFileError when images.txt is missing or malformed.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DataFileError(f"ECD folder not found: {folder}")
    require_file(folder / "images.txt", "the ECD image list `t images/frame_XXXXXXXX.png`")
    frame_times, image_files = _read_image_list(folder)
    if not image_files:
        raise DataFileError(f"{folder / 'images.txt'}: lists no image")
    frames = np.stack([_load_gray(path, f"images.txt frame {i}") for i, path in enumerate(image_files)])
    height, width = frames.shape[1:]
    camera = _read_camera(folder, width, height)
    groundtruth = _read_camera_groundtruth(folder)
    return Sequence(name=folder.name, camera=camera, frame_times=frame_times, frames=frames, groundtruth=groundtruth,
                    metadata={"source": str(folder), "format": "ECD text (frames only)"})


def _write_groundtruth_imu(path: Path, gt: GroundTruth) -> None:
    """Write groundtruth_imu.txt with the columns the GroundTruth has (8, 11, 14 or 17)."""
    columns = [gt.t, *gt.p_BinG.T, *gt.q_GtoB.T]  # JPL q_GtoI == Hamilton q of R_ItoG (same numbers)
    names = list(_POSE)
    if gt.v_BinG is not None:
        columns += list(gt.v_BinG.T)
        names += _VEL
    if gt.bias_gyro is not None and gt.bias_accel is not None:
        columns += [*gt.bias_gyro.T, *gt.bias_accel.T]
        names += _BIAS
    write_table(path, columns, [time_format(gt.t)] + ["%r"] * (len(columns) - 1), header=" ".join(names))


def write_ecd(sequence: Sequence, folder: str | Path, progress: bool = False) -> Path:
    """Write ``sequence`` as an ECD folder (plus groundtruth_imu.txt and evio_sim.json) and return the folder.

    Args:
        sequence: a valid Sequence (checked with ``sequence.validate()`` first).
        folder: output folder, created if needed. Layout files from an earlier write that the new sequence does
            not produce (e.g. imu.txt) are removed, as are old ``images/frame_*.png``; nothing else is touched.
            (The command line never writes into a non-empty folder: see :mod:`evio_lib.io.output_dir`.)
        progress: show progress bars (events and frames).

    If writing fails (a full disk, Ctrl-C), a folder this call created is removed again; an existing folder keeps
    :data:`INCOMPLETE_MARKER`, so that :func:`read_ecd` refuses it instead of loading part of a recording.

    The round trip ``read_ecd(write_ecd(seq, f))`` gives the same events, frames, IMU, poses, extrinsics, sensor
    size and metadata (tuples and arrays in metadata included), bit for bit; only groundtruth.txt's velocity and
    biases are not stored (the ECD camera pose has none).

    >>> import tempfile
    >>> from evio_lib.events.array import make_events
    >>> seq = Sequence("demo", events=make_events([0.0, 0.25], [1, 2], [3, 4], [1, -1]), frames=np.zeros((0, 8, 9), np.uint8))
    >>> back = read_ecd(write_ecd(seq, tempfile.mkdtemp()))
    >>> back.name, back.sensor_size, back.events["p"].tolist()
    ('demo', (9, 8), [1, -1])
    """
    if not isinstance(sequence, Sequence):
        raise ValueError(f"sequence must be a Sequence; got {type(sequence).__name__}")
    sequence.validate()
    sidecar: dict[str, Any] = {
        "format": "evio_sim",
        "version": 1,
        "name": sequence.name,
        "sensor_size": list(sequence.sensor_size) if sequence.sensor_size is not None else None,
        "R_CtoI": sequence.R_CtoI,
        "p_CinI": sequence.p_CinI,
        "metadata": sequence.metadata,
    }
    sidecar_text = json.dumps(to_json_value(sidecar, "sequence"), indent=1) + "\n"  # before any file: bad metadata fails here
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"folder must be a folder path; {folder} is a file")
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    marker = folder / INCOMPLETE_MARKER
    marker.write_text("write_ecd has not finished writing this folder; read_ecd refuses it while this file exists\n",
                      encoding="utf-8")
    try:
        _write_layout(sequence, folder, sidecar_text, progress)
    except BaseException:
        if created:  # a folder this call made holds nothing else: remove it whole
            shutil.rmtree(folder, ignore_errors=True)
        raise
    marker.unlink()  # last: the folder is complete
    return folder


def _write_layout(sequence: Sequence, folder: Path, sidecar_text: str, progress: bool) -> None:
    """Write every file of the ECD layout of ``sequence``, and the sidecar text, into the existing ``folder``."""
    for stale in _LAYOUT_FILES:
        (folder / stale).unlink(missing_ok=True)
    if (folder / "images").is_dir():
        for old in (folder / "images").glob("frame_*.png"):
            old.unlink()

    ev = sequence.events
    write_table(folder / "events.txt", [ev["t"], ev["x"], ev["y"], (ev["p"] > 0).astype(np.int8)],
                [time_format(ev["t"]), "%d", "%d", "%d"], progress=progress)  # p: -1/+1 -> 0/1
    if sequence.imu is not None:
        imu = sequence.imu
        write_table(folder / "imu.txt", [imu.t, *imu.accel.T, *imu.gyro.T], [time_format(imu.t)] + ["%r"] * 6)
    if sequence.frames.shape[0] > 0:
        (folder / "images").mkdir(exist_ok=True)
        names = [f"images/frame_{i:08d}.png" for i in range(sequence.frames.shape[0])]
        indices = range(len(names))
        if progress:
            from tqdm.auto import tqdm

            indices = tqdm(indices, desc="images", unit="frame")
        for i in indices:
            if not cv2.imwrite(str(folder / names[i]), sequence.frames[i]):
                raise OSError(f"could not write {folder / names[i]}")
        with open(folder / "images.txt", "w", encoding="utf-8", newline="\n") as f:
            fmt = time_format(sequence.frame_times)
            f.write("".join(f"{fmt % t} {n}\n" for t, n in zip(sequence.frame_times.tolist(), names)))
    if sequence.groundtruth is not None:
        gt = sequence.groundtruth
        write_tum(folder / "groundtruth.txt", gt.t, gt.p_BinG, gt.q_GtoB, header=False)  # JPL q_GtoC == Hamilton q of R_CtoG
    if sequence.camera is not None:
        c = sequence.camera
        write_table(folder / "calib.txt", [np.array([getattr(c, n)]) for n in _CALIB_COLUMNS], ["%r"] * 9)
    if sequence.groundtruth_imu is not None:
        _write_groundtruth_imu(folder / "groundtruth_imu.txt", sequence.groundtruth_imu)
    (folder / SIDECAR_NAME).write_text(sidecar_text, encoding="utf-8")
