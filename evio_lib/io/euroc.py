"""EuRoC MAV dataset, ASL folder layout: camera images, IMU, calibration and ground truth.

Layout (Burri et al., "The EuRoC micro aerial vehicle datasets", IJRR 2016)::

    mav0/imu0/data.csv       timestamp [ns], w_x w_y w_z [rad/s], a_x a_y a_z [m/s^2]   (IMU frame S = I)
    mav0/imu0/sensor.yaml    T_BS (IMU -> body), noise densities and random walks
    mav0/cam0/data.csv       timestamp [ns], file name of mav0/cam0/data/<file>
    mav0/cam0/sensor.yaml    T_BS (camera -> body), intrinsics [fu, fv, cu, cv], radtan distortion, resolution
    mav0/state_groundtruth_estimate0/data.csv
                             timestamp [ns], p_RS_R [m], q_RS (w x y z, Hamilton, body -> world R), v_RS_R [m/s],
                             b_w_RS_S [rad/s], b_a_RS_S [m/s^2]

Ground truth is looked for in that order: the ``groundtruth`` argument, the standard
``mav0/state_groundtruth_estimate0/data.csv``, then ``<folder>/groundtruth_openvins/*.csv`` (open_vins' recomputed
ground truth in the same 17-column layout). A ``.txt`` argument is read as a TUM file (pose only).

Times: nanosecond integers are parsed exactly (int64) and converted once to float64 seconds
(t = s + ns_rest / 1e9). Timestamps that are obviously not nanoseconds are refused: an IMU whose median step is
outside 0.1 ms .. 100 ms (10 Hz .. 10 kHz) once read as ns, or image / ground-truth times on a time base about 1000x
(or 10^6x) off the IMU's (e.g. microseconds), with the expected unit in the message. Quaternions: the Hamilton q of R_ItoG has the same four numbers as the JPL q_GtoI.
The camera ground truth is derived from the IMU one with the extrinsics (thesis §3.3.2, Eq. 27-28)::

    R_CtoG = R_ItoG R_CtoI,     p_CinG = p_IinG + R_ItoG p_CinI
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from evio_lib.geometry.camera import PinholeRadtan, intrinsics_problem
from evio_lib.geometry.rotation import rot_to_quat
from evio_lib.io.errors import DataFileError, read_table, read_text, require_file
from evio_lib.io.image_files import decoder_note, read_image
from evio_lib.io.imu_checks import check_imu_units, check_noise_values
from evio_lib.io.tum import read_tum
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence

__all__ = ["read_euroc", "read_asl_yaml", "ns_to_seconds", "camera_groundtruth"]

_IMU_COLUMNS = ("t_ns", "wx", "wy", "wz", "ax", "ay", "az")
_GT_COLUMNS = ("t_ns", "px", "py", "pz", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "bwx", "bwy", "bwz", "bax", "bay", "baz")
_IMU_STEP_RANGE_S = (1e-4, 0.1)  # plausible IMU sample interval [s]: 10 kHz .. 10 Hz
_NOISE_KEYS = ("gyroscope_noise_density", "gyroscope_random_walk", "accelerometer_noise_density", "accelerometer_random_walk")


def ns_to_seconds(t_ns: Any) -> np.ndarray:
    """Return float64 seconds from integer nanoseconds, rounding once (no precision lost before the last step).

    >>> ns_to_seconds(np.array([1403715273262142976])).tolist()
    [1403715273.262143]
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    seconds, rest = np.divmod(t_ns, 1_000_000_000)
    return seconds.astype(np.float64) + rest.astype(np.float64) / 1e9  # t = s + ns / 1e9


def _yaml_scalar(text: str) -> Any:
    """Return a YAML flow scalar or flow list ("[1, 2]") as int / float / str / list."""
    text = text.strip()
    if text.startswith("[") and text.endswith("]"):
        inner = text[1:-1].strip()
        return [_yaml_scalar(item) for item in inner.split(",")] if inner else []
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return {"true": True, "false": False, "null": None, "~": None}.get(text.lower(), text)


def read_asl_yaml(path: str | Path, *, name: str | None = None) -> dict:
    """Return the content of an ASL/Kalibr ``sensor.yaml`` as a nested dict (a tiny, tolerant YAML subset parser).

    Supported: ``%YAML`` directives, ``#`` comments, ``key: value`` mappings nested by indentation, scalars and
    flow lists ``[a, b, ...]`` that may span several lines. Not supported (raises): block lists ``- item``.

    >>> import tempfile, os
    >>> f = os.path.join(tempfile.mkdtemp(), "sensor.yaml")
    >>> _ = open(f, "w").write("%YAML:1.0\\nT_BS:\\n  rows: 2\\n  data: [1.0, 0.0,\\n         0.0, 1.0]\\nrate_hz: 200 # Hz\\n")
    >>> read_asl_yaml(f)
    {'T_BS': {'rows': 2, 'data': [1.0, 0.0, 0.0, 1.0]}, 'rate_hz': 200}
    """
    path = require_file(path, "an ASL sensor.yaml")
    name = path.name if name is None else name
    root: dict = {}
    stack: list[tuple[int, dict]] = [(-1, root)]
    pending: tuple[int, int, str, str] | None = None  # (line, indent, key, text so far) of an open flow list
    for number, raw in enumerate(read_text(path, name).splitlines(), start=1):
        line = raw.split("#", 1)[0].rstrip()
        if pending is not None:
            start, indent, key, text = pending
            if ":" in line:  # a new "key: value" while the list is open: the ']' is missing
                break
            text += " " + line.strip()
            if "]" not in line:
                pending = (start, indent, key, text)
                continue
            pending = None
            stack[-1][1][key] = _yaml_scalar(text)
            continue
        if not line.strip() or line.lstrip().startswith("%") or line.strip() == "---":
            continue
        indent = len(line) - len(line.lstrip())
        content = line.strip()
        if content.startswith("- "):
            raise DataFileError(f"{name} line {number}: block lists ('- item') are not supported; use [a, b, ...]")
        key, sep, value = content.partition(":")
        if not sep or not key.strip():
            raise DataFileError(f"{name} line {number}: expected 'key: value'; got {content!r}")
        while stack[-1][0] >= indent:
            stack.pop()
        parent, key, value = stack[-1][1], key.strip(), value.strip()
        if not value:
            child: dict = {}
            parent[key] = child
            stack.append((indent, child))
        elif value.startswith("[") and "]" not in value:
            pending = (number, indent, key, value)
        else:
            parent[key] = _yaml_scalar(value)
    if pending is not None:
        raise DataFileError(f"{name} line {pending[0]}: flow list of '{pending[2]}' is not closed with ']'")
    return root


def _matrix_4x4(node: Any, where: str) -> np.ndarray:
    """Return the 4x4 matrix of a yaml node {rows: 4, cols: 4, data: [16 numbers]}."""
    data = node.get("data") if isinstance(node, dict) else None
    if not isinstance(data, list) or len(data) != 16:
        raise DataFileError(f"{where}: T_BS must have 'data' with 16 numbers (4 x 4, row major); got {data!r}")
    T = np.array(data, dtype=np.float64).reshape(4, 4)
    if not np.allclose(T[3], [0, 0, 0, 1]) or np.abs(T[:3, :3] @ T[:3, :3].T - np.eye(3)).max() > 1e-6:
        raise DataFileError(f"{where}: T_BS must be a rigid transform (rotation block, last row 0 0 0 1); got {T.tolist()}")
    return T


def _read_camera(yaml: dict, where: str) -> PinholeRadtan:
    """Return the PinholeRadtan of a cam sensor.yaml dict."""
    model = yaml.get("camera_model", "pinhole")
    distortion = yaml.get("distortion_model", "radial-tangential")
    if model != "pinhole" or distortion not in ("radial-tangential", "radtan", "plumb_bob"):
        raise DataFileError(
            f"{where}: only camera_model 'pinhole' with distortion_model 'radial-tangential' is supported; "
            f"got {model!r} / {distortion!r}"
        )
    intr, dist, res = yaml.get("intrinsics"), yaml.get("distortion_coefficients", [0.0] * 4), yaml.get("resolution")
    if not (isinstance(intr, list) and len(intr) == 4):
        raise DataFileError(f"{where}: intrinsics must be [fu, fv, cu, cv]; got {intr!r}")
    if not (isinstance(dist, list) and len(dist) in (4, 5)):
        raise DataFileError(f"{where}: distortion_coefficients must be [k1, k2, p1, p2(, k3)]; got {dist!r}")
    if not (isinstance(res, list) and len(res) == 2):
        raise DataFileError(f"{where}: resolution must be [width, height]; got {res!r}")
    k3 = dist[4] if len(dist) == 5 else 0.0
    for key, values, kind in (("intrinsics", intr, "numbers [fu, fv, cu, cv] in pixels"),
                              ("distortion_coefficients", dist, "numbers [k1, k2, p1, p2(, k3)]"),
                              ("resolution", res, "whole numbers of pixels [width, height]")):
        for value in values:
            number = value if isinstance(value, (int, float)) and not isinstance(value, bool) else None
            if number is None or not math.isfinite(number) or (key == "resolution" and not float(number).is_integer()):
                raise DataFileError(f"{where}: {key} must be {kind}; got {values!r} ({value!r} is not)")
    try:
        camera = PinholeRadtan(fx=float(intr[0]), fy=float(intr[1]), cx=float(intr[2]), cy=float(intr[3]),
                               width=int(res[0]), height=int(res[1]),
                               k1=float(dist[0]), k2=float(dist[1]), p1=float(dist[2]), p2=float(dist[3]), k3=float(k3))
    except (TypeError, ValueError) as error:
        raise DataFileError(f"{where}: {error}") from None
    problem = intrinsics_problem(camera)
    if problem is not None:
        raise DataFileError(f"{where}: intrinsics [fu, fv, cu, cv] against resolution [width, height]: {problem}")
    return camera


def _read_image_index(path: Path, name: str) -> tuple[np.ndarray, list[Path]]:
    """Return (t (F,) [s], image paths) of a cam data.csv (``timestamp [ns],filename``)."""
    stamps, files = [], []
    for number, line in enumerate(read_text(path, name).splitlines(keepends=True), start=1):
        stripped = line.split("#", 1)[0].strip()
        if not stripped:
            continue
        tokens = [tok.strip() for tok in stripped.split(",")]
        if len(tokens) != 2:
            raise DataFileError(f"{name} line {number}: expected 2 columns (timestamp [ns], filename), got {len(tokens)}")
        try:
            t_ns = int(tokens[0])
        except ValueError:
            raise DataFileError(f"{name} line {number}: timestamp must be an integer number of ns; got {tokens[0]!r}") from None
        if stamps and t_ns <= stamps[-1]:
            raise DataFileError(
                f"{name} line {number}: timestamp {t_ns} follows {stamps[-1]}; timestamps must be strictly increasing"
            )
        image = path.parent / "data" / tokens[1]
        if not image.is_file():
            raise DataFileError(f"{name} line {number}: image file data/{tokens[1]} not found in {path.parent}")
        stamps.append(t_ns)
        files.append(image)
    return ns_to_seconds(np.array(stamps, dtype=np.int64)), files


def _find_groundtruth(folder: Path, mav0: Path, groundtruth: str | Path | None) -> Path | None:
    """Return the ground-truth file to read (see the module docstring for the search order), or None."""
    if groundtruth is not None:
        return require_file(groundtruth, "a EuRoC ground-truth csv or a TUM trajectory")
    standard = mav0 / "state_groundtruth_estimate0" / "data.csv"
    if standard.is_file():
        return standard
    candidates = sorted((folder / "groundtruth_openvins").glob("*.csv"))
    return candidates[0] if candidates else None


def _read_groundtruth(path: Path, name: str) -> GroundTruth:
    """Return the IMU ground truth of a EuRoC state csv (17 columns) or of a TUM .txt (pose only)."""
    if path.suffix == ".txt":
        t, p, q = read_tum(path, name=name)
        return GroundTruth(t=t, p_BinG=p, q_GtoB=q, body="imu")  # Hamilton q of R_ItoG == JPL q_GtoI
    table = read_table(path, _GT_COLUMNS, name=name, int_columns=("t_ns",), delimiter=",")
    table.check_times("t_ns", strict=True)

    def stack(names: tuple[str, ...]) -> np.ndarray:
        return np.stack([table[c] for c in names], axis=1)

    # Hamilton (w x y z in the file) of R_ItoG -> JPL q_GtoI, same numbers; norms within 1e-3 of 1 normalised
    q = table.unit_quaternions(("qx", "qy", "qz", "qw"), layout="qw qx qy qz")
    return GroundTruth(t=ns_to_seconds(table["t_ns"]), p_BinG=stack(("px", "py", "pz")), q_GtoB=q, body="imu",
                       v_BinG=stack(("vx", "vy", "vz")), bias_gyro=stack(("bwx", "bwy", "bwz")),
                       bias_accel=stack(("bax", "bay", "baz")))


def _unit_hint(step_ns: float) -> str:
    """Return which unit a median timestamp step (read as ns) suggests, for a plausible IMU rate, or ""."""
    for unit, factor in (("microseconds", 1e3), ("milliseconds", 1e6), ("seconds", 1e9)):
        if _IMU_STEP_RANGE_S[0] <= step_ns * factor * 1e-9 <= _IMU_STEP_RANGE_S[1]:
            return f"; they look like {unit} (multiply by {factor:.0e} to get nanoseconds)"
    return ""


def _check_imu_rate(t_ns: np.ndarray, name: str) -> None:
    """Raise DataFileError unless the median IMU step, read as nanoseconds, is a plausible 10 Hz .. 10 kHz rate."""
    step_ns = float(np.median(np.diff(t_ns)))
    step_s = step_ns * 1e-9
    low, high = _IMU_STEP_RANGE_S
    if not low <= step_s <= high:
        raise DataFileError(
            f"{name}: the median step between timestamps is {step_ns:.6g}, i.e. {step_s:.3g} s ({1.0 / step_s:.4g} Hz) "
            f"read as nanoseconds, outside a plausible IMU rate of {1 / high:g} Hz .. {1 / low:g} Hz; EuRoC timestamps "
            f"must be integer nanoseconds (200 Hz is a step of 5000000){_unit_hint(step_ns)}"
        )


def _check_time_base(t: np.ndarray, t_imu: np.ndarray, name: str, imu_name: str) -> None:
    """Raise DataFileError when times ``t`` [s] lie on another time base than the IMU's (a ratio near 10^3 or 10^6).

    Two recordings of the same run overlap in time; when they do not and their mid times differ by a factor within
    [300, 3000] or [3e5, 3e6], one file has microseconds or milliseconds where nanoseconds are expected.
    """
    if t.size == 0 or t_imu.size == 0 or (t[0] <= t_imu[-1] and t_imu[0] <= t[-1]):
        return
    mid, mid_imu = 0.5 * (t[0] + t[-1]), 0.5 * (t_imu[0] + t_imu[-1])
    if mid <= 0 or mid_imu <= 0:
        return
    ratio = mid / mid_imu
    for factor, unit in ((1e3, "microseconds"), (1e6, "milliseconds")):
        for r, who, other in ((ratio, imu_name, name), (1.0 / ratio, name, imu_name)):
            if 0.3 * factor <= r <= 3.0 * factor:
                raise DataFileError(
                    f"{name}: its times ({t[0]:.6g} .. {t[-1]:.6g} s) and those of {imu_name} "
                    f"({t_imu[0]:.6g} .. {t_imu[-1]:.6g} s) differ by a factor of {r if r > 1 else 1 / r:.4g}: "
                    f"{who} looks like {unit} where {other} has the expected nanoseconds; every EuRoC timestamp "
                    f"must be integer nanoseconds"
                )


def _camera_folders(mav0: Path) -> list[str]:
    """Return the names of the camera folders ``mav0/cam*`` (sorted)."""
    return sorted(p.name for p in mav0.glob("cam*") if p.is_dir())


def camera_groundtruth(gt_imu: GroundTruth, R_CtoI: np.ndarray, p_CinI: np.ndarray) -> GroundTruth:
    """Return the camera poses implied by IMU poses and the camera-IMU extrinsics.

    R_CtoG = R_ItoG R_CtoI,  p_CinG = p_IinG + R_ItoG p_CinI  (thesis §3.3.2, Eq. 27-28).
    """
    R_ItoG = gt_imu.R_BtoG
    R_CtoG = R_ItoG @ R_CtoI
    p_CinG = gt_imu.p_BinG + R_ItoG @ p_CinI
    q_GtoC = rot_to_quat(np.swapaxes(R_CtoG, -1, -2))  # JPL q_GtoC has C(q) = R_GtoC = R_CtoG^T
    return GroundTruth(t=gt_imu.t.copy(), p_BinG=p_CinG, q_GtoB=q_GtoC, body="camera")


def read_euroc(folder: str | Path, *, load_frames: bool = True, camera: str | None = None,
               groundtruth: str | Path | None = None) -> Sequence:
    """Return the Sequence of a EuRoC ASL folder: frames of one camera, IMU, calibration, extrinsics, ground truth.

    Args:
        folder: the dataset folder holding ``mav0/`` (or the ``mav0`` folder itself).
        load_frames: load the PNG images (False: no frames and no frame_times; the camera is still read).
        camera: which camera folder, e.g. "cam0" or "cam1"; it must exist. None (default) takes "cam0"; a recording
            without any ``mav0/cam*`` folder then loads without camera, with a warning and
            ``metadata["camera_name"] = None``.
        groundtruth: optional explicit ground-truth file (EuRoC csv, or TUM .txt for pose only).

    Returns:
        Sequence with events empty; imu (gyro w then accel a, rad/s and m/s^2); camera from sensor.yaml;
        R_CtoI/p_CinI from the two T_BS (T_CtoI = T_ItoB^-1 T_CtoB); groundtruth_imu (with velocity and
        biases from a csv); groundtruth = the derived camera poses; metadata["imu_noise"] with the four
        continuous-time noise parameters (Kalibr names), rates and the files read.

    Raises:
        DataFileError (a ValueError): missing files or malformed lines ("mav0/imu0/data.csv line L: ..."); an IMU
            file without samples (or with one); timestamps that are not nanoseconds; a named camera folder that is
            absent; a camera folder without its data.csv (when frames are loaded).
    """
    folder = Path(folder)
    if camera is not None and (not isinstance(camera, str) or not camera.strip() or "/" in camera):
        raise ValueError(f"camera must be the name of a camera folder such as 'cam0' or 'cam1', or None; got {camera!r}")
    mav0 = folder / "mav0" if (folder / "mav0").is_dir() else folder
    cameras = _camera_folders(mav0) if mav0.is_dir() else []
    if not (mav0 / "imu0").is_dir() and not cameras:
        raise DataFileError(f"EuRoC folder not found: {folder} has no mav0/imu0 or mav0/cam0")
    if camera is not None and camera not in cameras:
        raise DataFileError(
            f"camera {camera!r} not found: {mav0} has no folder {camera}/ "
            f"(camera folders: {', '.join(cameras) if cameras else 'none'})"
        )
    camera_name = camera if camera is not None else ("cam0" if "cam0" in cameras else None)
    if camera_name is None:
        warnings.warn(
            f"{folder}: no camera folder mav0/cam0 (camera folders: {', '.join(cameras) if cameras else 'none'}); "
            f"loading IMU and ground truth only (camera=None, no frames)",
            stacklevel=2,
        )

    def rel(path: Path) -> str:  # how messages name a file: relative to the dataset folder
        return str(path.relative_to(folder)) if path.is_relative_to(folder) else str(path)

    imu_csv = require_file(mav0 / "imu0" / "data.csv", "the IMU samples `timestamp [ns], w xyz, a xyz`")
    imu_yaml_path = mav0 / "imu0" / "sensor.yaml"
    imu_yaml = read_asl_yaml(imu_yaml_path, name=rel(imu_yaml_path)) if imu_yaml_path.is_file() else {}
    table = read_table(imu_csv, _IMU_COLUMNS, name=rel(imu_csv), int_columns=("t_ns",), delimiter=",")
    if len(table) < 2:
        raise DataFileError(
            f"{rel(imu_csv)}: {'no IMU samples (only comments or a header)' if len(table) == 0 else 'a single IMU sample'}; "
            f"expected at least 2 lines `timestamp [ns],w_x,w_y,w_z [rad/s],a_x,a_y,a_z [m/s^2]`"
        )
    table.check_times("t_ns", strict=True)
    _check_imu_rate(table["t_ns"], rel(imu_csv))
    imu = ImuSamples(t=ns_to_seconds(table["t_ns"]),
                     gyro=np.stack([table[c] for c in ("wx", "wy", "wz")], axis=1),
                     accel=np.stack([table[c] for c in ("ax", "ay", "az")], axis=1))

    cam_dir = mav0 / camera_name if camera_name is not None else None
    cam_yaml_path = cam_dir / "sensor.yaml" if cam_dir is not None else None
    cam = None
    R_CtoI = p_CinI = None
    if cam_dir is not None and not cam_yaml_path.is_file():
        warnings.warn(f"{rel(cam_yaml_path)} not found: {camera_name} has no calibration (camera=None, no extrinsics)",
                      stacklevel=2)
    elif cam_yaml_path is not None:
        cam_yaml = read_asl_yaml(cam_yaml_path, name=rel(cam_yaml_path))
        cam = _read_camera(cam_yaml, rel(cam_yaml_path))
        if "T_BS" in cam_yaml:
            T_CtoB = _matrix_4x4(cam_yaml["T_BS"], rel(cam_yaml_path))
            T_ItoB = _matrix_4x4(imu_yaml["T_BS"], rel(imu_yaml_path)) if "T_BS" in imu_yaml else np.eye(4)
            T_CtoI = np.linalg.inv(T_ItoB) @ T_CtoB  # x_I = T_ItoB^-1 T_CtoB x_C
            R_CtoI, p_CinI = T_CtoI[:3, :3].copy(), T_CtoI[:3, 3].copy()

    frame_times, frames = np.zeros(0), None
    if cam_dir is not None and load_frames:
        cam_csv = cam_dir / "data.csv"
        if not cam_csv.is_file():
            raise DataFileError(
                f"{rel(cam_csv)}: file not found, although the camera folder {rel(cam_dir)}/ exists (expected the image "
                f"list `timestamp [ns],filename`: the frames are what features are tracked on, and a EuRoC "
                f"recording holds no events to replace them; read_euroc(..., load_frames=False) reads the rest)"
            )
        frame_times, files = _read_image_index(cam_csv, rel(cam_csv))
        _check_time_base(frame_times, imu.t, rel(cam_csv), rel(imu_csv))
        images = []
        for path in files:
            image, said = read_image(path, cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise DataFileError(f"{rel(path)}: could not decode the image{decoder_note(said)}")
            if images and image.shape != images[0].shape:
                raise DataFileError(f"{rel(path)}: image size {image.shape[::-1]} differs from the first image {images[0].shape[::-1]}")
            images.append(image)
        if images:
            if cam is not None and images[0].shape != (cam.height, cam.width):
                raise DataFileError(
                    f"{rel(files[0])}: image size {images[0].shape[1]} x {images[0].shape[0]} differs from the "
                    f"resolution {cam.width} x {cam.height} in {rel(cam_yaml_path)}"
                )
            frames = np.stack(images)

    metadata: dict[str, Any] = {"source": str(folder), "format": "EuRoC ASL", "camera_name": camera_name,
                                "imu_file": rel(imu_csv)}
    # negative, NaN or non-numbers are refused here, never replaced by defaults downstream
    noise = check_noise_values({key: imu_yaml[key] for key in _NOISE_KEYS if key in imu_yaml}, rel(imu_yaml_path))
    if noise:
        metadata["imu_noise"] = noise
    if "rate_hz" in imu_yaml:
        metadata["imu_rate_hz"] = float(imu_yaml["rate_hz"])

    gt_imu = gt_cam = None
    gt_path = _find_groundtruth(folder, mav0, groundtruth)
    if gt_path is not None:
        gt_imu = _read_groundtruth(gt_path, rel(gt_path))
        _check_time_base(gt_imu.t, imu.t, rel(gt_path), rel(imu_csv))
        metadata["groundtruth_file"] = rel(gt_path)
        if R_CtoI is not None:
            gt_cam = camera_groundtruth(gt_imu, R_CtoI, p_CinI)
            metadata["groundtruth_camera"] = "derived from groundtruth_imu and R_CtoI/p_CinI"
    check_imu_units(imu.t, imu.gyro, imu.accel, gt_imu, source=rel(imu_csv),
                    columns="timestamp [ns], w_x w_y w_z [rad/s], a_x a_y a_z [m/s^2]",
                    truth_source=rel(gt_path) if gt_path is not None else "the ground truth")
    return Sequence(name=folder.name, camera=cam, frame_times=frame_times, frames=frames, imu=imu,
                    groundtruth=gt_cam, groundtruth_imu=gt_imu, R_CtoI=R_CtoI, p_CinI=p_CinI, metadata=metadata)
