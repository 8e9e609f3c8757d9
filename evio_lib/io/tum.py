"""TUM trajectory files (``timestamp tx ty tz qx qy qz qw``) and their link to :class:`GroundTruth`.

A TUM line gives the pose of a body B in the world G: the position p_BinG and the HAMILTON quaternion
[qx, qy, qz, qw] of the body orientation R_BtoG (scipy's ``Rotation.from_quat`` convention). The ECD
``groundtruth.txt`` and the EuRoC ground truth use the same quaternion meaning.

Conversion to the library's JPL q_GtoB (C(q_GtoB) = R_GtoB): a JPL quaternion has the same four numbers as the
Hamilton quaternion of the transposed matrix, and R_GtoB^T = R_BtoG, so::

    q_GtoB (JPL) = q_BtoG (Hamilton, xyzw)      -- the same four numbers, no arithmetic

This keeps file round trips exact. Quaternions must be unit: a row whose norm is within 1e-3 of 1 (few decimals in
the file) is normalised on reading, a row further off (norm 2, 0.5, 0) is refused with the file and line; the
writer refuses what the reader would refuse (see :func:`evio_lib.io.errors.unit_quaternions`). Reference: Sturm et al., "A benchmark for the evaluation of RGB-D SLAM
systems", IROS 2012 (file format); Trawny & Roumeliotis 2005 (JPL quaternions).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from evio_lib.io.errors import QUATERNION_NORM_TOL, quaternion_norm_problem, read_table, time_format, unit_quaternions, write_table
from evio_lib.sequence import GroundTruth

__all__ = [
    "TUM_BODIES",
    "read_tum",
    "write_tum",
    "groundtruth_to_tum",
    "groundtruth_from_tum",
    "jpl_q_GtoB_from_hamilton_BtoG",
    "hamilton_BtoG_from_jpl_q_GtoB",
    "normalise_quaternions",
    "QUATERNION_NORM_TOL",
]

TUM_COLUMNS = ("t", "px", "py", "pz", "qx", "qy", "qz", "qw")


def jpl_q_GtoB_from_hamilton_BtoG(q_BtoG_xyzw: Any) -> np.ndarray:
    """Return JPL q_GtoB (..., 4) from Hamilton quaternions [x, y, z, w] of R_BtoG (the numbers are identical).

    C_JPL(q) = R_Hamilton(q)^T, hence the Hamilton quaternion of R_BtoG is the JPL quaternion of R_BtoG^T = R_GtoB.

    >>> from scipy.spatial.transform import Rotation
    >>> from evio_lib.geometry.rotation import quat_to_rot
    >>> q = Rotation.from_euler("z", 30, degrees=True).as_quat()       # Hamilton q of R_BtoG
    >>> bool(np.allclose(quat_to_rot(jpl_q_GtoB_from_hamilton_BtoG(q)), Rotation.from_quat(q).as_matrix().T))
    True
    """
    return np.array(q_BtoG_xyzw, dtype=np.float64)


def hamilton_BtoG_from_jpl_q_GtoB(q_GtoB: Any) -> np.ndarray:
    """Return Hamilton quaternions [x, y, z, w] (..., 4) of R_BtoG from JPL q_GtoB (inverse of the above; identical numbers)."""
    return np.array(q_GtoB, dtype=np.float64)


def normalise_quaternions(q_xyzw: Any, name: str = "q_xyzw") -> np.ndarray:
    """Return a new (N, 4) array of unit quaternions: rows within 1e-3 of unit norm divided by their norm.

    Rows within 1e-6 of unit norm keep their numbers exactly; a row whose norm is further than
    ``QUATERNION_NORM_TOL`` = 1e-3 from 1 (or zero) raises ValueError naming ``name`` and the row.

    >>> normalise_quaternions([[0.0, 0.0, 0.0, 1.0004]]).tolist()
    [[0.0, 0.0, 0.0, 1.0]]
    """
    q, bad, norm = unit_quaternions(np.asarray(q_xyzw, dtype=np.float64))
    if bad >= 0:
        raise ValueError(f"{name}[{bad}]: " + quaternion_norm_problem(norm, "qx qy qz qw"))
    return q


def _check_pose_arrays(t: Any, p: Any, q_xyzw: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (t (N,), p (N, 3), q (N, 4)) as float64, or raise ValueError naming the argument."""
    t = np.asarray(t, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q_xyzw, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"t must have shape (N,); got {t.shape}")
    n = t.shape[0]
    if p.shape != (n, 3):
        raise ValueError(f"p must have shape ({n}, 3); got {p.shape}")
    if q.shape != (n, 4):
        raise ValueError(f"q_xyzw must have shape ({n}, 4); got {q.shape}")
    for name, values in (("t", t), ("p", p), ("q_xyzw", q)):
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{name} must be finite; got NaN or inf")
    if np.any(t[1:] <= t[:-1]):
        i = int(np.flatnonzero(t[1:] <= t[:-1])[0]) + 1
        raise ValueError(f"t must be strictly increasing; got t[{i}] = {float(t[i])!r} after t[{i - 1}] = {float(t[i - 1])!r}")
    return t, p, q


def read_tum(path: str | Path, *, name: str | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (t (N,) [s], p (N, 3) [m], q_xyzw (N, 4) Hamilton) read from a TUM trajectory file.

    Args:
        path: text file with lines ``timestamp tx ty tz qx qy qz qw``; ``#`` comments and blank lines allowed.
        name: how error messages name the file (default: its file name).

    Returns:
        q_xyzw has unit rows: rows within 1e-6 of unit norm as written, rows within 1e-3 divided by their norm.

    Raises:
        DataFileError (a ValueError): "NAME line L: problem" for a wrong column count, a non-number, NaN,
            a timestamp that does not increase strictly, or a quaternion whose norm is not within 1e-3 of 1.
    """
    table = read_table(path, TUM_COLUMNS, name=name)
    table.check_times("t", strict=True)
    q = table.unit_quaternions(("qx", "qy", "qz", "qw"))
    p = np.stack([table[c] for c in ("px", "py", "pz")], axis=1)
    return table["t"].copy(), p, q


#: The bodies a TUM file written by evio can hold, as its header names them.
TUM_BODIES = {"imu": "the IMU frame I", "camera": "the camera frame C"}


def write_tum(path: str | Path, t: Any, p: Any, q_xyzw: Any, *, header: bool = True, body: str | None = None) -> None:
    """Write a TUM trajectory file ``timestamp tx ty tz qx qy qz qw`` (values exact: shortest round-trip digits).

    Args:
        path: output file (overwritten).
        t: (N,) strictly increasing timestamps [s]; 9 decimals when they lie on the ns grid.
        p: (N, 3) positions [m].
        q_xyzw: (N, 4) Hamilton quaternions, scalar last, of norm within 1e-3 of 1 (written as given; anything
            :func:`read_tum` would refuse, e.g. a zero quaternion, raises ValueError and writes nothing).
        header: write a "# timestamp tx ty tz qx qy qz qw" comment line first.
        body: 'imu' or 'camera': the header also says whose pose the file holds
            ("# timestamp tx ty tz qx qy qz qw: pose of the IMU frame I in the world frame G"); None: it does not.

    >>> import tempfile, os
    >>> f = os.path.join(tempfile.mkdtemp(), "traj.txt")
    >>> write_tum(f, [0.0, 0.05], [[0, 0, 0], [0.1, 0, 0]], [[0, 0, 0, 1]] * 2)
    >>> print(open(f).read().splitlines()[2])
    0.050000000 0.1 0.0 0.0 0.0 0.0 0.0 1.0
    >>> read_tum(f)[1][1].tolist()
    [0.1, 0.0, 0.0]
    """
    if body is not None and body not in TUM_BODIES:
        raise ValueError(f"body must be one of {', '.join(TUM_BODIES)} or None; got {body!r}")
    t, p, q = _check_pose_arrays(t, p, q_xyzw)
    normalise_quaternions(q)  # raises for a quaternion that read_tum would refuse; the numbers are written as given
    columns = [t, *p.T, *q.T]
    text = "timestamp tx ty tz qx qy qz qw" + (f": pose of {TUM_BODIES[body]} in the world frame G" if body else "")
    write_table(path, columns, [time_format(t)] + ["%r"] * 7, header=text if header else None)


def groundtruth_to_tum(gt: GroundTruth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (t, p_BinG, q_xyzw) in TUM form (Hamilton quaternion of R_BtoG) from a GroundTruth (JPL q_GtoB)."""
    if not isinstance(gt, GroundTruth):
        raise ValueError(f"gt must be a GroundTruth; got {type(gt).__name__}")
    return gt.t.copy(), gt.p_BinG.copy(), hamilton_BtoG_from_jpl_q_GtoB(gt.q_GtoB)


def groundtruth_from_tum(t: Any, p: Any, q_xyzw: Any, body: str = "camera") -> GroundTruth:
    """Return a GroundTruth (JPL q_GtoB) from TUM arrays (positions p_BinG, Hamilton quaternions of R_BtoG).

    Args:
        t: (N,) timestamps [s].
        p: (N, 3) positions of the body in the world [m].
        q_xyzw: (N, 4) Hamilton quaternions of the body orientation R_BtoG; norms within 1e-3 of 1 are
            normalised (see :func:`normalise_quaternions`), others raise ValueError naming the row.
        body: "camera" or "imu".

    >>> gt = groundtruth_from_tum([0.0], [[1.0, 2.0, 3.0]], [[0.0, 0.0, np.sin(0.25), np.cos(0.25)]], body="imu")
    >>> gt.R_BtoG[0].round(3).tolist()[0]    # yaw +0.5 rad about z: first row [cos, -sin, 0]
    [0.878, -0.479, 0.0]
    """
    t, p, q = _check_pose_arrays(t, p, q_xyzw)
    return GroundTruth(t=t, p_BinG=p, q_GtoB=jpl_q_GtoB_from_hamilton_BtoG(normalise_quaternions(q)), body=body)
