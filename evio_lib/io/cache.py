"""Binary cache of a :class:`Sequence`: one ``.npz`` file, reloaded exactly and fast (no text parsing).

Layout of the npz (``np.savez``/``np.savez_compressed``, loaded with ``allow_pickle=False``):

* ``events`` (N,) EVENT_DTYPE, ``frame_times`` (F,), ``frames`` (F, H, W) uint8 -- always present;
* ``imu_t``, ``imu_gyro``, ``imu_accel`` -- when the sequence has IMU samples;
* ``groundtruth_<field>`` / ``groundtruth_imu_<field>`` for t, p_BinG, q_GtoB and the optional v_BinG,
  bias_gyro, bias_accel -- when present;
* ``R_CtoI``, ``p_CinI`` -- when known;
* ``header``: a JSON string with the name, the camera parameters, the ground-truth bodies and the metadata.

Metadata must be JSON-like (dict with str keys, list, tuple, str, int, float, bool, None, NumPy arrays and
scalars): arrays and tuples are tagged so that they come back as arrays/tuples; float values are exact (JSON
stores Python's shortest round-trip repr).
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.io.errors import DataFileError
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence

__all__ = [
    "CacheError",
    "default_cache_dir",
    "load_npz_arrays",
    "discard_damaged_cache",
    "save_sequence_npz",
    "load_sequence_npz",
    "load_cached_sequence",
    "check_cache_file_writable",
    "store_sequence_npz",
    "to_json_value",
    "from_json_value",
    "camera_to_dict",
    "camera_from_dict",
]

class CacheError(DataFileError):
    """A cache file is damaged (empty, truncated, not an npz, missing entries, invalid content): the message names it.

    Its users delete it and make it again (:func:`discard_damaged_cache`); ``path`` and ``reason`` are attributes.
    """

    def __init__(self, path: str | Path, reason: str) -> None:
        self.path, self.reason = Path(path), reason
        super().__init__(f"{self.path.name}: {reason}")


def default_cache_dir() -> Path:
    """Return the project's one cache folder: ``$EVIO_CACHE_DIR`` if set; else, when ``evio_lib`` runs from a
    checkout of the repository (``pyproject.toml`` beside the package), ``<repository>/data/cache`` (git-ignored);
    else (an installed package) ``$XDG_CACHE_HOME/evio`` or ``~/.cache/evio``. Simulated recordings, evaluation
    stretches, training samples, feature labels and the event files of ROS bags and HDF5 recordings are cached under
    it, whatever the working folder."""
    env = os.environ.get("EVIO_CACHE_DIR")
    if env:
        return Path(env)
    repository = Path(__file__).resolve().parents[2]
    if (repository / "pyproject.toml").is_file() and (repository / "evio_lib").is_dir():
        return repository / "data" / "cache"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "evio"


def load_npz_arrays(path: str | Path, keys: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """Return every array of the npz cache ``path`` (or only ``keys``, which must all be there), read whole.

    Raises:
        DataFileError: the file does not exist.
        CacheError: it is empty, truncated, no npz, a member is damaged (zip CRC, zlib) or a key is missing.
    """
    import zipfile
    import zlib

    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path.name}: file not found at {path} (expected an evio cache .npz)")
    if path.stat().st_size == 0:
        raise CacheError(path, "the file is empty (0 bytes)")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in keys or () if k not in z.files]
            if missing:
                raise CacheError(path, f"missing entries {missing}; it has {sorted(z.files)}")
            return {key: z[key] for key in (keys or z.files)}
    except CacheError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError) as exc:
        detail = (str(exc).strip().splitlines() or [""])[0][:160]
        raise CacheError(path, f"not a readable npz file ({type(exc).__name__}: {detail}): truncated or damaged"
                         ) from None


def discard_damaged_cache(error: CacheError, action: str) -> str:
    """Delete the damaged cache file of ``error``, print the note "cache X was damaged (reason); ACTION" on stderr
    and return it (the caller then makes the cache again)."""
    import sys

    error.path.unlink(missing_ok=True)
    note = f"note: cache {error.path} was damaged ({error.reason}); {action}"
    print(note, file=sys.stderr, flush=True)
    return note


_FORMAT = "evio-sequence-npz"
_VERSION = 1
_CAMERA_FIELDS = ("fx", "fy", "cx", "cy", "width", "height", "k1", "k2", "p1", "p2", "k3")
_GT_FIELDS = ("t", "p_BinG", "q_GtoB", "v_BinG", "bias_gyro", "bias_accel")


def to_json_value(value: Any, where: str = "metadata") -> Any:
    """Return ``value`` converted to plain JSON types (arrays and tuples tagged); raise ValueError naming ``where``.

    >>> to_json_value({"R": np.eye(2), "size": (240, 180), "g": np.float64(9.81)})
    {'R': {'__ndarray__': [[1.0, 0.0], [0.0, 1.0]], 'dtype': 'float64', 'shape': [2, 2]}, 'size': {'__tuple__': [240, 180]}, 'g': 9.81}
    """
    if isinstance(value, np.generic):  # before float: np.float64 is a float subclass
        return value.item()
    if value is None or isinstance(value, (bool, str, int, float)):
        return value
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biuf":
            raise ValueError(f"{where} must hold numeric arrays only; got an array of dtype {value.dtype}")
        return {"__ndarray__": value.tolist(), "dtype": str(value.dtype), "shape": list(value.shape)}
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return {"__tuple__": [to_json_value(v, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, list):
        return [to_json_value(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict):
        out = {}
        for key, v in value.items():
            if not isinstance(key, str):
                raise ValueError(f"{where} must have str keys only (JSON); got key {key!r} of type {type(key).__name__}")
            out[key] = to_json_value(v, f"{where}[{key!r}]")
        return out
    raise ValueError(f"{where} must be JSON-like (dict, list, tuple, str, number, bool, None, ndarray); got {type(value).__name__}")


def from_json_value(value: Any) -> Any:
    """Return the value encoded by :func:`to_json_value` (tagged arrays and tuples restored)."""
    if isinstance(value, list):
        return [from_json_value(v) for v in value]
    if isinstance(value, dict):
        if "__ndarray__" in value:
            return np.array(value["__ndarray__"], dtype=np.dtype(value["dtype"])).reshape(value["shape"])
        if "__tuple__" in value and len(value) == 1:
            return tuple(from_json_value(v) for v in value["__tuple__"])
        return {k: from_json_value(v) for k, v in value.items()}
    return value


def camera_to_dict(camera: PinholeRadtan | None) -> dict | None:
    """Return the camera parameters as a dict (fx, fy, cx, cy, width, height, k1, k2, p1, p2, k3), or None."""
    if camera is None:
        return None
    return {name: getattr(camera, name) for name in _CAMERA_FIELDS}


def camera_from_dict(params: dict | None) -> PinholeRadtan | None:
    """Return the PinholeRadtan described by :func:`camera_to_dict`'s dict, or None."""
    if params is None:
        return None
    missing = [name for name in _CAMERA_FIELDS if name not in params]
    if missing:
        raise ValueError(f"camera parameters must include {list(_CAMERA_FIELDS)}; missing {missing}")
    return PinholeRadtan(**{name: params[name] for name in _CAMERA_FIELDS})


def save_sequence_npz(sequence: Sequence, path: str | Path, *, compress: bool = False) -> Path:
    """Write ``sequence`` to one npz file at exactly ``path`` and return that path.

    Args:
        sequence: the sequence to store (its metadata must be JSON-like, see the module docstring).
        path: output file (no ".npz" is appended).
        compress: zlib-compress the arrays (smaller, slower to write and to load).
    """
    if not isinstance(sequence, Sequence):
        raise ValueError(f"sequence must be a Sequence; got {type(sequence).__name__}")
    arrays: dict[str, np.ndarray] = {
        "events": np.asarray(sequence.events),
        "frame_times": np.asarray(sequence.frame_times),
        "frames": np.asarray(sequence.frames),
    }
    if sequence.imu is not None:
        arrays.update(imu_t=sequence.imu.t, imu_gyro=sequence.imu.gyro, imu_accel=sequence.imu.accel)
    bodies = {}
    for prefix in ("groundtruth", "groundtruth_imu"):
        gt = getattr(sequence, prefix)
        if gt is None:
            continue
        bodies[prefix] = gt.body
        for name in _GT_FIELDS:
            if getattr(gt, name) is not None:
                arrays[f"{prefix}_{name}"] = getattr(gt, name)
    for name in ("R_CtoI", "p_CinI"):
        if getattr(sequence, name) is not None:
            arrays[name] = np.asarray(getattr(sequence, name))
    header = {
        "format": _FORMAT,
        "version": _VERSION,
        "name": sequence.name,
        "camera": camera_to_dict(sequence.camera),
        "groundtruth_bodies": bodies,
        "metadata": to_json_value(sequence.metadata),
    }
    arrays["header"] = np.array(json.dumps(header))
    path = Path(path)
    with open(path, "wb") as f:
        (np.savez_compressed if compress else np.savez)(f, **arrays)
    return path


def load_cached_sequence(path: str | Path) -> Sequence | None:
    """Return the Sequence cached at ``path``, or None when there is none or it was damaged (then said and deleted,
    :func:`discard_damaged_cache`, so that the caller simulates it again)."""
    if not Path(path).is_file():
        return None
    try:
        return load_sequence_npz(path)
    except CacheError as error:  # empty, truncated, damaged
        discard_damaged_cache(error, "re-simulating")
        return None


def check_cache_file_writable(path: str | Path) -> None:
    """Raise ValueError unless the cache file ``path`` can be written: no folder in its place, its folder writable.

    Called before the work that makes the file (a simulation of seconds to minutes), so that the user learns now,
    with ``EVIO_CACHE_DIR`` named, and not after the work.
    """
    path = Path(path)
    if (path.exists() or path.is_symlink()) and not path.is_file():
        raise ValueError(f"the recording cache {path} is {'a folder' if path.is_dir() else 'no regular file'}, where "
                         f"the simulated recording is to be stored; remove it (the cache folder is set by "
                         f"EVIO_CACHE_DIR)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        os.rmdir(tempfile.mkdtemp(prefix=".evio-probe-", dir=path.parent))
    except OSError as error:
        origin = ("EVIO_CACHE_DIR=" + os.environ["EVIO_CACHE_DIR"] if os.environ.get("EVIO_CACHE_DIR")
                  else "the default cache folder")
        raise ValueError(f"cannot write the recording cache {path.parent} ({origin}): "
                         f"{error.strerror or type(error).__name__}; set EVIO_CACHE_DIR to a writable folder") from None


def store_sequence_npz(sequence: Sequence, path: str | Path) -> Path:
    """Write ``sequence`` to the cache file ``path`` whole or not at all (a temporary file renamed into place).

    The file gets the permissions of any file the user writes (``mkstemp`` alone would make it 0o600).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".npz", dir=path.parent)
    os.close(fd)
    try:
        save_sequence_npz(sequence, tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def load_sequence_npz(path: str | Path) -> Sequence:
    """Return the Sequence stored by :func:`save_sequence_npz` (arrays identical, metadata restored).

    Raises:
        DataFileError (a ValueError): the file is missing.
        CacheError (a DataFileError): the file is empty, truncated or damaged, is not an evio sequence cache, or holds
            a sequence that the Sequence checks refuse (e.g. unsorted events), with the problem in the message.

    >>> import tempfile, os
    >>> from evio_lib.events.array import make_events
    >>> f = os.path.join(tempfile.mkdtemp(), "seq.npz")
    >>> seq = Sequence("demo", events=make_events([0.0, 0.1], [1, 2], [3, 4], [1, -1]), metadata={"rate": 200.0})
    >>> back = load_sequence_npz(save_sequence_npz(seq, f))
    >>> back.name, back.events["x"].tolist(), back.metadata
    ('demo', [1, 2], {'rate': 200.0})
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path.name}: file not found at {path} (expected an evio sequence cache .npz)")
    arrays = load_npz_arrays(path)  # CacheError for an empty, truncated or damaged file
    if "header" not in arrays:
        raise CacheError(path, f"not an evio sequence cache (no 'header' entry); keys {sorted(arrays)}")
    try:
        header = json.loads(str(arrays.pop("header")[()]))
    except json.JSONDecodeError as exc:
        raise CacheError(path, f"the 'header' entry is not valid JSON ({exc.msg})") from None
    if not isinstance(header, dict) or header.get("format") != _FORMAT or header.get("version") != _VERSION:
        header = header if isinstance(header, dict) else {}
        raise CacheError(path, f"header format {header.get('format')!r} version {header.get('version')!r}; "
                               f"expected {_FORMAT!r} version {_VERSION}")
    try:
        return _sequence_from_arrays(arrays, header)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:  # a damaged or hand-made file: say which, why
        problem = f"missing entry {exc}" if isinstance(exc, KeyError) else str(exc)
        raise CacheError(path, f"the cached sequence is not valid ({problem})") from None


def _sequence_from_arrays(arrays: dict[str, np.ndarray], header: dict) -> Sequence:
    """Return the Sequence of the npz entries and header (the Sequence checks every field on construction)."""
    imu = None
    if "imu_t" in arrays:
        imu = ImuSamples(arrays["imu_t"], arrays["imu_gyro"], arrays["imu_accel"])
    gts: dict[str, GroundTruth | None] = {}
    for prefix in ("groundtruth", "groundtruth_imu"):
        if prefix not in header["groundtruth_bodies"]:
            gts[prefix] = None
            continue
        parts = {name: arrays.get(f"{prefix}_{name}") for name in _GT_FIELDS}
        gts[prefix] = GroundTruth(body=header["groundtruth_bodies"][prefix], **parts)
    return Sequence(
        name=header["name"],
        camera=camera_from_dict(header["camera"]),
        events=arrays["events"],
        frame_times=arrays["frame_times"],
        frames=arrays["frames"],
        imu=imu,
        groundtruth=gts["groundtruth"],
        groundtruth_imu=gts["groundtruth_imu"],
        R_CtoI=arrays.get("R_CtoI"),
        p_CinI=arrays.get("p_CinI"),
        metadata=from_json_value(header["metadata"]),
    )
