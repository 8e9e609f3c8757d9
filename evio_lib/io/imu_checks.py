"""Units and frames of an IMU recording, checked at the door: a wrong unit is refused with the fix, never run.

Every reader and loader (:func:`evio_lib.io.ecd.read_ecd`, :func:`evio_lib.io.euroc.read_euroc`,
:func:`evio_lib.io.aedat4.read_aedat4`, :func:`evio_lib.pipeline.dataset.load_dataset`) calls
:func:`check_imu_units` on the samples it returns. Without it a recording with the accelerometer in g runs to
the end and prints a confident, wrong trajectory (one such run: docs/results/pipeline.md#what-a-run-assumes).

The physics the checks rely on (specific force ``a_m = R_GtoI (a - g_G)`` in m/s^2, gyro ``w_m = w + b_g`` in
rad/s):

* **Accelerometer units.** At rest, and on average during any motion a person or a vehicle makes, the
  accelerometer reads gravity: ``|a_m| ≈ 9.81 m/s^2``. A median ``|a_m|`` near 1 is the unit g (multiply by
  9.80665), near 1000 milli-g (multiply by 0.00980665). Only free fall reads less than half of g for long.
* **Columns swapped.** A gyro column whose median norm is near 9.81 while the "accelerometer" is small holds the
  accelerometer: the file's column order differs from the reader's.
* **Gyro units.** Still, the gyro reads its bias, a few mrad/s (MEMS: below about 0.1 rad/s, 5 deg/s, even
  uncalibrated); in deg/s the same bias reads 57.3 times more (1 deg/s reads as "1 rad/s"). In motion a gyro in
  deg/s reads 57.3x the true angular rate. With a ground truth the check compares the gyro with the truth's
  angular rate (the ratio of norms is about 1 in rad/s, 57.3 in deg/s; norms do not depend on the frame, so no
  extrinsics are needed). Without one: a still stretch (the accelerometer steady: gravity does not turn, so the
  sensor turns slower than about 0.35 rad/s about any horizontal axis) whose gyro reads more than
  :data:`STILL_GYRO_BOUND` = 0.5 rad/s everywhere, or a gyro beyond ±2000 deg/s = 34.9 rad/s (the largest range of
  a MEMS gyroscope, so no real sample reads more) for :data:`SUSTAINED_FRACTION` = 5 % of the samples.
* **Gravity axis.** With a ground truth of the IMU orientation ``R_ItoG`` (world z up, or the recording's own
  ``gravity_G``), integrating the specific force in the world gives the change of velocity::

      mean over [t0, t1] of R_ItoG a_m = (v(t1) - v(t0)) / (t1 - t0) - g_G

  so the mean specific force in the world must lie within :data:`GRAVITY_ANGLE_TOL_DEG` = 30 degrees of the
  truth's prediction (the truth's change of velocity is part of it, so any speed passes), over at least
  :data:`MIN_GRAVITY_SPAN_S` = 0.5 s of overlap. An accelerometer whose axes the truth contradicts (columns in
  another order, a sign flipped, another sensor frame) is refused, naming the IMU axis on which the truth expects
  the specific force and the one on which the file has it.
* **Axes off gravity.** A swap of the two axes gravity does not lie on passes that test (a mirror image keeps
  gravity in place). The motion does not: per window of 0.05-0.2 s, every signed order of the file's columns (48)
  is fitted to the truth's rotation (gyro) and acceleration (accelerometer), see :func:`_axes_problem`.

Bounds for user-given values (``--bias-init``): :data:`GYRO_BIAS_BOUND` 0.5 rad/s and :data:`ACCEL_BIAS_BOUND`
3 m/s^2 per axis, see :func:`check_bias_values`.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from evio_lib.io.errors import DataFileError

__all__ = ["ImuUnitsError", "check_imu_units", "check_bias_values", "check_noise_values", "STANDARD_GRAVITY",
           "DEG_PER_RAD", "GYRO_FULL_SCALE_BOUND", "STILL_GYRO_BOUND", "SUSTAINED_FRACTION", "GRAVITY_ANGLE_TOL_DEG",
           "GYRO_BIAS_BOUND", "ACCEL_BIAS_BOUND", "MIN_GRAVITY_SPAN_S", "MAX_IMU_STEP_S", "ACCEL_AXES_FLOOR", "GYRO_AXES_FLOOR",
           "AXES_RATIO", "MAX_TRUTH_SPEED", "truth_speed_problem"]

#: Standard gravity [m/s^2]: one g.
STANDARD_GRAVITY = 9.80665
#: Degrees per radian: a gyro in deg/s reads this many times its rate in rad/s.
DEG_PER_RAD = 180.0 / math.pi
#: rad/s: ±2000 deg/s, the largest measurement range of a MEMS gyroscope (InvenSense, Bosch, ADI data sheets).
GYRO_FULL_SCALE_BOUND = math.radians(2000.0)
#: rad/s: a still gyro reads its bias, below about 0.1 rad/s for a MEMS part; above this it is not rad/s.
STILL_GYRO_BOUND = 0.5
#: Fraction of the samples beyond GYRO_FULL_SCALE_BOUND that counts as "sustained".
SUSTAINED_FRACTION = 0.05
#: Largest angle between the measured and the predicted mean specific force in the world [deg].
GRAVITY_ANGLE_TOL_DEG = 30.0
#: Longest median step between IMU samples [s]: an IMU samples at 100 Hz or more (the DAVIS 1 kHz, EuRoC 200 Hz), so
#: a median step above 0.1 s is a time unit other than seconds (ms, us, ns), said with the factor.
MAX_IMU_STEP_S = 0.1
#: Shortest overlap of IMU and ground truth over which gravity and the axes are checked [s].
MIN_GRAVITY_SPAN_S = 0.5
#: m/s^2: median residual of the per-window specific force above which wrong accelerometer axes are refused
#: (when another signed order of the axes explains the truth at least AXES_RATIO times better).
ACCEL_AXES_FLOOR = 0.4
#: rad/s: the same for the gyro's per-step angular rate (a MEMS gyro bias is below 0.1 rad/s).
GYRO_AXES_FLOOR = 0.15
#: How many times better another signed order of the axes must explain the truth before the file's is refused.
AXES_RATIO = 3.0
#: rad/s per axis: the largest plausible gyro bias. Consumer MEMS data sheets give a zero-rate offset of ±5 deg/s
#: (0.09 rad/s) at most, tactical parts far less; 0.5 rad/s (29 deg/s) is five times that, so a larger value is a
#: unit mistake (deg/s) or a typo.
GYRO_BIAS_BOUND = 0.5
#: m/s^2 per axis: the largest plausible accelerometer bias. Consumer MEMS data sheets give a zero-g offset of
#: ±150 mg (1.5 m/s^2) at most; 3 m/s^2 is twice that.
ACCEL_BIAS_BOUND = 3.0

#: m/s: a ground truth moving faster (95th percentile) holds its positions in another unit than metres
MAX_TRUTH_SPEED = 100.0
#: a sample with |a| or |w| beyond this many times the median, and beyond the floors below, is a glitch (a bit error,
#: a parser fault) that the unit, axis and gravity checks leave out, when at most GLITCH_MAX_FRACTION of the samples
#: are such (more are not glitches: the checks see them and say what is wrong)
GLITCH_FACTOR = 100.0
GLITCH_ACCEL_FLOOR = 1e3   # m/s^2: ~100 g, beyond any MEMS accelerometer, and beyond 100 g-unit readings
GLITCH_GYRO_FLOOR = 1e4    # beyond 2000 deg/s read as rad/s, so a gyro in deg/s is still diagnosed
GLITCH_MAX_FRACTION = 0.01
_STILL_WINDOW_S = 0.1  # length of the windows tested for stillness [s]
_STILL_BIN_S = 0.01  # samples are averaged into bins of this length before the steadiness test (noise / sqrt(n))
_STILL_ACCEL_STD = 0.1  # m/s^2: per-axis std of the binned accelerometer in a still window
_STILL_GRAVITY_TOL = 1.0  # m/s^2: a still window reads |a| within this of g
_TRUTH_STEP_S = 0.05  # the truth's angular rate is taken over steps of at least this length (its noise averages)
_TRUTH_MOVING_RATE = 0.2  # rad/s: truth steps faster than this compare the gyro with the truth (bias < 0.1 rad/s)
_TRUTH_MOVING_MIN_S = 0.5  # s of such steps needed for the ratio
_GYRO_RATIO_BOUND = 10.0  # gyro / truth rate ratio beyond which the gyro is not rad/s (1 in rad/s, 57.3 in deg/s)


class ImuUnitsError(DataFileError):
    """The IMU samples are not in the library's units or frame (accel m/s^2, gyro rad/s, axes of the truth)."""


def _glitched_samples(gyro: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """Return the mask of samples whose |a| or |w| lies beyond GLITCH_FACTOR times its median (and beyond a floor no
    unit mistake reaches: GLITCH_ACCEL_FLOOR, GLITCH_GYRO_FLOOR), computed without overflow."""
    with np.errstate(over="ignore", invalid="ignore"):
        a = np.abs(accel).max(axis=1)                   # the largest component: no squares of 1e200
        w = np.abs(gyro).max(axis=1)
    return ((a > max(GLITCH_FACTOR * float(np.median(a)), GLITCH_ACCEL_FLOOR))
            | (w > max(GLITCH_FACTOR * float(np.median(w)), GLITCH_GYRO_FLOOR)))


def _norms(x: np.ndarray) -> np.ndarray:
    return np.linalg.norm(x, axis=1)


def _accel_problem(accel_median: float, gyro_median: float, columns: str, speed: float = 1.0) -> str | None:
    """Return what is wrong with the magnitudes of accelerometer and gyro, or None (``speed``: see check_imu_units)."""
    if 0.5 * STANDARD_GRAVITY <= accel_median <= 4.0 * STANDARD_GRAVITY * max(speed, 1.0) ** 2:
        return None
    if accel_median < 0.5 * STANDARD_GRAVITY and 0.5 * STANDARD_GRAVITY <= gyro_median <= 4.0 * STANDARD_GRAVITY:
        return (f"the gyro and accelerometer columns look swapped: the gyro's median |w| is {gyro_median:.3g} (gravity "
                f"reads 9.81 m/s^2) and the accelerometer's median |a| is {accel_median:.3g}; put the columns in the "
                f"order {columns}")
    if 0.5 <= accel_median <= 2.0:
        return (f"the accelerometer looks like it is in g: median |a| = {accel_median:.3g} instead of about 9.81 "
                f"m/s^2; multiply the accelerometer by 9.80665 to get m/s^2")
    if 500.0 <= accel_median <= 2000.0:
        return (f"the accelerometer looks like it is in milli-g: median |a| = {accel_median:.4g} instead of about "
                f"9.81 m/s^2; multiply the accelerometer by 0.00980665 to get m/s^2")
    return (f"the accelerometer's median |a| = {accel_median:.4g} is no specific force in m/s^2 (about 9.81 when "
            f"still or moving as people and vehicles do); convert it to m/s^2 (raw counts: divide by the LSB per g "
            f"and multiply by 9.80665)")


def _window_ids(t: np.ndarray, length: float) -> np.ndarray:
    return np.floor((t - t[0]) / length).astype(np.int64)


def _still_gyro_norms(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """Return |mean gyro| of every still window (accelerometer steady and reading about g)."""
    bins = _window_ids(t, _STILL_BIN_S)
    windows = _window_ids(t, _STILL_WINDOW_S)
    out = []
    for w in np.unique(windows):
        sel = windows == w
        if sel.sum() < 5:
            continue
        b = bins[sel]
        _, inverse, counts = np.unique(b, return_inverse=True, return_counts=True)
        if counts.size < 3:
            continue
        binned = np.zeros((counts.size, 3))
        np.add.at(binned, inverse, accel[sel])
        binned /= counts[:, None]
        if binned.std(axis=0).max() > _STILL_ACCEL_STD:
            continue
        if abs(np.linalg.norm(accel[sel].mean(axis=0)) - STANDARD_GRAVITY) > _STILL_GRAVITY_TOL:
            continue
        out.append(np.linalg.norm(gyro[sel].mean(axis=0)))
    return np.asarray(out)


def _truth_rates(truth: Any, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (start, end, |angular rate|) of the truth's steps of at least _TRUTH_STEP_S within [t0, t1]."""
    inside = np.flatnonzero((truth.t >= t0) & (truth.t <= t1))
    if inside.size < 2:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    keep = [inside[0]]
    for i in inside[1:]:
        if truth.t[i] - truth.t[keep[-1]] >= _TRUTH_STEP_S:
            keep.append(i)
    keep = np.asarray(keep)
    if keep.size < 2:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    R = truth.R_BtoG[keep]
    dR = np.einsum("nji,njk->nik", R[:-1], R[1:])  # R_k^T R_k+1: the rotation of the body between the samples
    cos = np.clip((np.trace(dR, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    dt = np.diff(truth.t[keep])
    return truth.t[keep][:-1], truth.t[keep][1:], np.arccos(cos) / dt


def _gyro_truth_ratio(t: np.ndarray, gyro: np.ndarray, truth: Any) -> float | None:
    """Return the median ratio |mean gyro| / |truth rate| over the truth's fast steps, or None without enough motion."""
    start, end, rate = _truth_rates(truth, t[0], t[-1])
    moving = rate > _TRUTH_MOVING_RATE
    if np.sum(end[moving] - start[moving]) < _TRUTH_MOVING_MIN_S:
        return None
    cumulative = np.concatenate([np.zeros((1, 3)), np.cumsum(gyro, axis=0)])
    i0 = np.searchsorted(t, start[moving])
    i1 = np.searchsorted(t, end[moving])
    ok = i1 > i0
    if ok.sum() < 3:
        return None
    mean_gyro = (cumulative[i1[ok]] - cumulative[i0[ok]]) / (i1[ok] - i0[ok])[:, None]
    return float(np.median(np.linalg.norm(mean_gyro, axis=1) / rate[moving][ok]))


def _checkable_overlap(t: np.ndarray, truth: Any, R_CtoI: Any) -> tuple[float, float, np.ndarray | None] | None:
    """Return (t0, t1, R_CtoI as an array or None) of the IMU's overlap with the truth, or None when the truth cannot
    check the axes: a camera truth without the camera-IMU rotation, or less than MIN_GRAVITY_SPAN_S of overlap."""
    if truth.body == "camera" and R_CtoI is None:
        return None
    t0, t1 = max(t[0], truth.t[0]), min(t[-1], truth.t[-1])
    if t1 - t0 < MIN_GRAVITY_SPAN_S:
        return None
    return t0, t1, None if R_CtoI is None else np.asarray(R_CtoI, dtype=np.float64)


def _imu_to_world(R_BtoG: np.ndarray, body: str, R_CtoI: np.ndarray | None) -> np.ndarray:
    """Return R_ItoG from the truth's body rotations: the body itself, or the camera (R_CtoG R_CtoI^T)."""
    return R_BtoG if body == "imu" else np.einsum("nij,kj->nik", R_BtoG, R_CtoI)


def _gravity_problem(t: np.ndarray, accel: np.ndarray, truth: Any, R_CtoI: Any, gravity_G: Any) -> str | None:
    """Return what the truth contradicts about the accelerometer's axes, or None (also when it cannot tell)."""
    overlap = _checkable_overlap(t, truth, R_CtoI)
    if overlap is None:
        return None
    t0, t1, R_CtoI = overlap
    sel = (t >= t0) & (t <= t1)
    at = truth.interpolate(t[sel])
    R_ItoG = _imu_to_world(at.R_BtoG, truth.body, R_CtoI)
    g = np.array([0.0, 0.0, -9.81]) if gravity_G is None else np.asarray(gravity_G, dtype=np.float64).reshape(3)
    span = t[sel][-1] - t[sel][0]
    if at.v_BinG is not None and truth.body == "imu":
        dv = at.v_BinG[-1] - at.v_BinG[0]
    else:  # velocities at both ends from positions 0.2 s apart (the camera's velocity: rotation adds little)
        h = min(0.2, span / 4)
        ends = truth.interpolate(np.array([t[sel][0], t[sel][0] + h, t[sel][-1] - h, t[sel][-1]]))
        dv = (ends.p_BinG[3] - ends.p_BinG[2]) / h - (ends.p_BinG[1] - ends.p_BinG[0]) / h
    expected = dv / span - g  # mean of R_ItoG a_m

    def angle(P: np.ndarray) -> float:
        measured = np.einsum("nij,nj->i", R_ItoG, accel[sel] @ P.T) / sel.sum()
        c = measured @ expected / (np.linalg.norm(measured) * np.linalg.norm(expected) + 1e-300)
        return math.degrees(math.acos(max(-1.0, min(1.0, c))))

    found = angle(np.eye(3))
    if found <= GRAVITY_ANGLE_TOL_DEG:
        return None
    # where the truth expects the specific force in the IMU frame, against where the file has it
    expected_I = np.einsum("nji,j->ni", R_ItoG, expected).mean(axis=0)
    measured_I = accel[sel].mean(axis=0)

    def axis(v: np.ndarray) -> str:
        k = int(np.argmax(np.abs(v)))
        return f"{'-' if v[k] < 0 else '+'}{'xyz'[k]} ({', '.join(f'{c:.2f}' for c in v / np.linalg.norm(v))})"

    return (f"gravity lies on an axis the ground truth contradicts: over {span:.1f} s the mean specific force in the "
            f"world points {found:.0f} deg away from up (tolerance {GRAVITY_ANGLE_TOL_DEG:.0f} deg); the truth puts "
            f"it on the IMU's {axis(expected_I)}, the accelerometer on {axis(measured_I)}: reorder or flip the "
            f"accelerometer columns to the IMU axes of the truth (the specific force reads +9.81 up when still), or "
            f"check the ground truth's frame and the camera-IMU extrinsics")


def _signed_permutations() -> np.ndarray:
    """Return the (48, 3, 3) signed permutation matrices, the identity first."""
    import itertools

    out = [np.eye(3)]
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            P = np.zeros((3, 3))
            P[range(3), order] = signs
            if not np.array_equal(P, np.eye(3)):
                out.append(P)
    return np.asarray(out)


def _axes_text(P: np.ndarray, name: str) -> str:
    """Return 'x <- +z, y <- -y, ...': which column of the file each of the truth's axes reads."""
    return ", ".join(f"{'xyz'[i]} = {'-' if P[i].sum() < 0 else ''}{name}{'xyz'[int(np.argmax(np.abs(P[i])))]}"
                     for i in range(3))


def _best_order(residuals: np.ndarray) -> tuple[float, int, float]:
    """Return (residual of the file's order, index of the best signed order, its residual)."""
    best = int(np.argmin(residuals))
    return float(residuals[0]), best, float(residuals[best])


def _gyro_windows(t: np.ndarray, gyro: np.ndarray, truth: Any, R_CtoI: Any) -> tuple | None:
    """Return the windows over the IMU's overlap with the truth (span / 10, 0.05-0.2 s long) and per window the mean
    gyro and the truth's angular rate in the IMU frame, Log(R_ItoG(t_k)^T R_ItoG(t_k+1)) / length, or None (no
    checkable overlap, fewer than 3 windows): (t0, length, edges, i_edges, ok, truth at the edges, R_CtoI, mean gyro
    (M, 3), truth rate (M, 3), moving (M,))."""
    from scipy.spatial.transform import Rotation

    overlap = _checkable_overlap(t, truth, R_CtoI)
    if overlap is None:
        return None
    t0, t1, R_CtoI = overlap
    span = t1 - t0
    length = float(np.clip(span / 10.0, 0.05, 0.2))
    edges = t0 + length * np.arange(int(span // length) + 1)
    i_edges = np.searchsorted(t, edges)
    ok = np.diff(i_edges) >= 3
    if ok.sum() < 3:
        return None
    at = truth.interpolate(edges)
    R_ItoG = _imu_to_world(at.R_BtoG, truth.body, R_CtoI)
    cumulative_gyro = np.concatenate([np.zeros((1, 3)), np.cumsum(gyro, axis=0)])
    counts = np.diff(i_edges)[ok]
    mean_gyro = (cumulative_gyro[i_edges[1:]] - cumulative_gyro[i_edges[:-1]])[ok] / counts[:, None]
    dR = np.einsum("nji,njk->nik", R_ItoG[:-1], R_ItoG[1:])[ok]  # R_k^T R_k+1 in the IMU frame
    truth_rate = Rotation.from_matrix(dR).as_rotvec() / length
    moving = np.linalg.norm(truth_rate, axis=1) > _TRUTH_MOVING_RATE
    return t0, length, edges, i_edges, ok, at, R_CtoI, mean_gyro, truth_rate, moving


def _gyro_residual(t: np.ndarray, gyro: np.ndarray, truth: Any, R_CtoI: Any) -> float | None:
    """Return the median |mean gyro - truth angular rate| (rad/s) over the moving windows, or None (too little
    motion to tell)."""
    windows = _gyro_windows(t, gyro, truth, R_CtoI)
    if windows is None or windows[-1].sum() < 3:
        return None
    mean_gyro, truth_rate, moving = windows[-3:]
    return float(np.median(np.linalg.norm(mean_gyro[moving] - truth_rate[moving], axis=1)))


def _axes_problem(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, truth: Any, R_CtoI: Any,
                  gravity_G: Any) -> str | None:
    """Return which sensor's axes the truth contradicts (columns swapped or a sign flipped), or None.

    The whole-span gravity test cannot see a swap of the two axes gravity does not lie on (EuRoC's y and z while
    the drone keeps x up): their mirror image explains gravity as well. The motion can. Over windows k of the
    overlap the truth predicts, for every signed order P of the file's columns (48 of them, 24 proper rotations
    and 24 mirror images)::

        accelerometer:  mean_k R_ItoG P a_m  =  (v(t_k+1) - v(t_k)) / (t_k+1 - t_k) - g_G
        gyro:           mean_k P w_m         =  Log(R_ItoG(t_k)^T R_ItoG(t_k+1)) / (t_k+1 - t_k)   (+ b_g)

    The file's order (P = I) is refused when its median residual exceeds a floor (ACCEL_AXES_FLOOR,
    GYRO_AXES_FLOOR: noise, bias and vibration stay below) and another order explains the truth AXES_RATIO times
    better; the message names that order. Without motion every order explains the truth equally and nothing is
    refused.
    """
    windows = _gyro_windows(t, gyro, truth, R_CtoI)
    if windows is None:
        return None
    t0, length, edges, i_edges, ok, at, R_CtoI, mean_gyro, truth_rate, moving = windows
    orders = _signed_permutations()
    counts = np.diff(i_edges)[ok]
    problems = []
    if moving.sum() >= 3:
        residual = np.median(np.linalg.norm(np.einsum("pij,nj->pni", orders, mean_gyro[moving])
                                            - truth_rate[moving][None], axis=2), axis=1)
        own, best, other = _best_order(residual)
        if own > GYRO_AXES_FLOOR and own > AXES_RATIO * other:
            problems.append(f"the gyro's axes: the truth's rotation needs {_axes_text(orders[best], 'w')} of the file "
                            f"(median error {other:.2f} rad/s against {own:.2f} rad/s as written)")
    # accelerometer: the world specific force per window from the truth's change of velocity
    g = np.array([0.0, 0.0, -9.81]) if gravity_G is None else np.asarray(gravity_G, dtype=np.float64).reshape(3)
    if truth.body == "imu" and at.v_BinG is not None:
        v = at.v_BinG
    else:
        h = min(0.05, length / 2)
        lo = np.clip(edges - h, truth.t[0], truth.t[-1])
        hi = np.clip(edges + h, truth.t[0], truth.t[-1])
        v = (truth.interpolate(hi).p_BinG - truth.interpolate(lo).p_BinG) / (hi - lo)[:, None]
    expected_G = (np.diff(v, axis=0) / length - g)[ok]
    rows = np.repeat(np.arange(len(i_edges) - 1), np.diff(i_edges))
    inside = slice(i_edges[0], i_edges[-1])
    R_samples = _imu_to_world(truth.interpolate(t[inside]).R_BtoG, truth.body, R_CtoI)
    # M[k, :, i, j] = mean over window k of R_ItoG[:, i] a_m[j]: then mean_k R_ItoG P a_m = sum_ij P_ij M[k, :, i, j]
    outer = np.einsum("nai,nj->naij", R_samples, accel[inside])
    M = np.zeros((len(i_edges) - 1, 3, 3, 3))
    np.add.at(M, rows, outer)
    M = M[ok] / counts[:, None, None, None]
    measured = np.einsum("pij,kaij->pka", orders, M)
    residual = np.median(np.linalg.norm(measured - expected_G[None], axis=2), axis=1)
    own, best, other = _best_order(residual)
    if own > ACCEL_AXES_FLOOR and own > AXES_RATIO * other:
        problems.append(f"the accelerometer's axes: the truth's accelerations need {_axes_text(orders[best], 'a')} "
                        f"of the file (median error {other:.2f} m/s^2 against {own:.2f} m/s^2 as written)")
    if not problems:
        return None
    return ("the ground truth contradicts " + "; and ".join(problems) + ": reorder or flip those columns to the IMU "
            "axes of the truth, or check the ground truth's frame and the camera-IMU extrinsics")


def truth_speed_problem(truth: Any, max_speed: float = None) -> str | None:
    """Return what is implausible about a ground truth's positions, or None: a body whose positions move faster than
    ``max_speed`` (default MAX_TRUTH_SPEED; 95th percentile over steps of at least 0.05 s) holds them in another unit (millimetres read as
    metres move a walking camera at ~1000 m/s)."""
    if truth is None or len(truth) < 2:
        return None
    t, p = np.asarray(truth.t, dtype=np.float64), np.asarray(truth.p_BinG, dtype=np.float64)
    keep = [0]
    for i in range(1, len(t)):
        if t[i] - t[keep[-1]] >= _TRUTH_STEP_S:
            keep.append(i)
    if len(keep) < 3:
        return None
    k = np.asarray(keep)
    speed = np.linalg.norm(np.diff(p[k], axis=0), axis=1) / np.diff(t[k])
    fast = float(np.percentile(speed, 95))
    max_speed = MAX_TRUTH_SPEED if max_speed is None else float(max_speed)
    if fast <= max_speed:
        return None
    fits = [(unit, factor) for unit, factor in (("millimetres", 1e3), ("centimetres", 1e2)) if fast / factor <= 30.0]
    guess = (": positions in another unit than metres?" if not fits else
             "".join([": positions in ", " or ".join(u for u, _ in fits), "? divide them by ",
                      " or ".join(f"{f:g}" for _, f in fits), " to get metres"]))
    return (f"the positions move at {fast:.4g} m/s (95th percentile over {len(k) - 1} steps), faster than any "
            f"camera a person, vehicle or drone carries ({max_speed:g} m/s){guess}")


def _with_wxyz_read_as_xyzw(truth: Any) -> Any:
    """Return the truth with its quaternions reordered as if the file held w x y z where x y z w was expected."""
    import dataclasses

    q = np.asarray(truth.q_GtoB)[:, [1, 2, 3, 0]]
    return dataclasses.replace(truth, q_GtoB=q / np.linalg.norm(q, axis=1, keepdims=True))


def check_imu_units(t: Any, gyro: Any, accel: Any, truth: Any = None, *, source: str = "the IMU",
                    columns: str = "gyro (rad/s) then accelerometer (m/s^2)", R_CtoI: Any = None,
                    gravity_G: Any = None, speed: float = 1.0, truth_source: str = "the ground truth") -> str:
    """Refuse IMU samples that are not gyro [rad/s] and specific force [m/s^2] in the frame the truth says.

    Args:
        t: (N,) sample times [s], increasing.
        gyro, accel: (N, 3) samples as the reader will return them (after any unit conversion).
        truth: optional :class:`~evio_lib.sequence.GroundTruth` (body 'imu', or 'camera' with ``R_CtoI``) for the
            angular-rate and gravity-axis checks.
        source: how the message names the samples, e.g. "mav0/imu0/data.csv".
        columns: the column order the reader expects, for the swapped-columns message.
        R_CtoI: the recording's own camera-IMU rotation, needed with a camera ground truth.
        gravity_G: gravity in the truth's world frame (default (0, 0, -9.81): z up).
        speed: a simulated motion played this many times faster than people and vehicles move (a preset's
            ``speed``): its accelerations, and so the plausible median |a| (4 g at speed 1), grow with speed^2.
        truth_source: how a message about the ground truth names it (its file), e.g. "groundtruth.txt". The truth's
            positions are checked for their unit (:func:`truth_speed_problem`, times ``speed``), and a gravity or
            axes contradiction that vanishes when the truth's quaternions are read as w x y z is blamed on the truth.

    Returns:
        One line saying what was checked (for the dataset notes).

    Raises:
        ImuUnitsError (a ValueError): one line "SOURCE: what is wrong; the fix".

    >>> t = np.arange(400) * 0.005
    >>> accel = np.tile([0.0, 0.0, 9.81], (400, 1)); gyro = np.tile([0.002, -0.001, 0.003], (400, 1))
    >>> check_imu_units(t, gyro, accel)[:33]
    'IMU units: median |a| 9.81 m/s^2,'
    >>> check_imu_units(t, gyro, accel / 9.81, source="imu.txt")
    Traceback (most recent call last):
    ...
    evio_lib.io.imu_checks.ImuUnitsError: imu.txt: the accelerometer looks like it is in g: median |a| = 1 instead of about 9.81 m/s^2; multiply the accelerometer by 9.80665 to get m/s^2
    >>> check_imu_units(t, np.degrees(gyro) * 100, accel, source="imu.txt")
    Traceback (most recent call last):
    ...
    evio_lib.io.imu_checks.ImuUnitsError: imu.txt: the gyro looks like it is in deg/s: where the accelerometer is still it reads |w| = 21.4 (a MEMS gyro's bias is below 0.1 rad/s; this bound is 0.5 rad/s); multiply the gyro by pi/180 = 0.0174533 to get rad/s
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    gyro = np.asarray(gyro, dtype=np.float64).reshape(-1, 3)
    accel = np.asarray(accel, dtype=np.float64).reshape(-1, 3)
    if t.size < 2 or gyro.shape[0] != t.size or accel.shape[0] != t.size:
        return "IMU units: not checked (fewer than 2 samples)"
    finite = np.isfinite(t) & np.isfinite(gyro).all(axis=1) & np.isfinite(accel).all(axis=1)
    t, gyro, accel = t[finite], gyro[finite], accel[finite]
    if t.size < 2:
        return "IMU units: not checked (fewer than 2 finite samples)"
    glitch = _glitched_samples(gyro, accel)                # a few absurd samples never steer the diagnosis
    if 0 < glitch.sum() <= max(1, GLITCH_MAX_FRACTION * t.size):
        t, gyro, accel = t[~glitch], gyro[~glitch], accel[~glitch]
    else:
        glitch = np.zeros(t.size, bool)

    step = float(np.median(np.diff(t)))
    if step > MAX_IMU_STEP_S:
        guess = next((f"; they look like {unit}: divide them by {factor:g} to get seconds"
                      for unit, factor in (("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9))
                      if 0.5e-3 <= step / factor <= 0.05), "; convert them to seconds")
        raise ImuUnitsError(f"{source}: the IMU times are not seconds: the samples lie {step:.4g} apart (median "
                            f"step), where an IMU samples at 100 Hz or more (steps of 0.01 s or less){guess}")
    accel_median = float(np.median(_norms(accel)))
    gyro_median = float(np.median(_norms(gyro)))
    problem = _accel_problem(accel_median, gyro_median, columns, speed)
    if problem is not None:
        raise ImuUnitsError(f"{source}: {problem}")

    degs = ("; multiply the gyro by pi/180 = 0.0174533 to get rad/s")
    done = [f"median |a| {accel_median:.3g} m/s^2"]
    beyond = float(np.mean(np.abs(gyro).max(axis=1) > GYRO_FULL_SCALE_BOUND))
    if beyond >= SUSTAINED_FRACTION:
        raise ImuUnitsError(f"{source}: the gyro looks like it is in deg/s: {100 * beyond:.0f} % of the samples read "
                            f"more than 34.9 rad/s, beyond the ±2000 deg/s range of any MEMS gyroscope{degs}")
    ratio = None
    if truth is not None and len(truth) >= 2:
        problem = truth_speed_problem(truth, MAX_TRUTH_SPEED * max(1.0, float(speed)))
        if problem is not None:
            raise ImuUnitsError(f"{truth_source}: {problem}")
        ratio = _gyro_truth_ratio(t, gyro, truth)
    if ratio is not None:
        if ratio > _GYRO_RATIO_BOUND:
            unit = "deg/s" if 20.0 <= ratio <= 200.0 else "another unit than rad/s"
            raise ImuUnitsError(f"{source}: the gyro looks like it is in {unit}: it reads {ratio:.1f} times the "
                                f"ground truth's angular rate (1 in rad/s, 57.3 in deg/s)"
                                + (degs if unit == "deg/s" else "; convert it to rad/s"))
        done.append(f"gyro / truth angular rate {ratio:.2f}")
    else:
        still = _still_gyro_norms(t, gyro, accel)
        if still.size and still.min() > STILL_GYRO_BOUND:
            raise ImuUnitsError(f"{source}: the gyro looks like it is in deg/s: where the accelerometer is still it "
                                f"reads |w| = {still.min():.3g} (a MEMS gyro's bias is below 0.1 rad/s; this bound is "
                                f"{STILL_GYRO_BOUND:g} rad/s){degs}")
        done.append(f"still gyro {still.min():.3g} rad/s" if still.size else "no still stretch for the gyro check")
    if truth is not None and len(truth) >= 2:
        problem = _gravity_problem(t, accel, truth, R_CtoI, gravity_G)
        if problem is None:
            problem = _axes_problem(t, gyro, accel, truth, R_CtoI, gravity_G)
        if problem is not None:
            # the truth's quaternions written w x y z: the truth then contradicts the gyro's rotation axes too (the
            # rates' magnitudes do not tell: a reordering keeps every dot product), and read as w x y z it agrees
            reordered = _with_wxyz_read_as_xyzw(truth)
            as_read, as_wxyz = _gyro_residual(t, gyro, truth, R_CtoI), _gyro_residual(t, gyro, reordered, R_CtoI)
            if (as_read is not None and as_wxyz is not None and as_read > GYRO_AXES_FLOOR
                    and as_read > AXES_RATIO * as_wxyz
                    and _gravity_problem(t, accel, reordered, R_CtoI, gravity_G) is None
                    and _axes_problem(t, gyro, accel, reordered, R_CtoI, gravity_G) is None):
                raise ImuUnitsError(f"{truth_source}: the orientations contradict the IMU as written and agree with "
                                    f"it when each quaternion is read as w x y z: write them as qx qy qz qw (scalar "
                                    f"last)")
            raise ImuUnitsError(f"{source}: {problem}")
        if _checkable_overlap(t, truth, R_CtoI) is not None:
            done.append("gravity and axes checked against the ground truth")
        else:
            shared = max(min(t[-1], truth.t[-1]) - max(t[0], truth.t[0]), 0.0)
            done.append(f"axes not checked (the ground truth shares {shared:.2f} s with the IMU; "
                        f"{MIN_GRAVITY_SPAN_S:g} s needed" + (", and camera-IMU extrinsics"
                                                             if truth.body == "camera" and R_CtoI is None else "") + ")")
    if glitch.any():
        done.append(f"{int(glitch.sum())} glitched sample{'s' if glitch.sum() > 1 else ''} left out of these checks "
                    f"(|a| or |w| beyond {GLITCH_FACTOR:g}x the median)")
    return "IMU units: " + ", ".join(done)


def check_bias_values(values: Any, what: str = "--bias-init") -> tuple[float, ...]:
    """Return six biases (b_g [rad/s], b_a [m/s^2]) as floats, or raise ValueError naming the implausible one.

    Bounds per axis: |b_g| <= GYRO_BIAS_BOUND (0.5 rad/s) and |b_a| <= ACCEL_BIAS_BOUND (3 m/s^2), five and two
    times the worst zero-rate / zero-g offsets of consumer MEMS data sheets (±5 deg/s, ±150 mg).

    >>> check_bias_values([0.01, 0, 0, 0.1, 0, 0])
    (0.01, 0.0, 0.0, 0.1, 0.0, 0.0)
    >>> check_bias_values([1e6, 0, 0, 0, 0, 0])
    Traceback (most recent call last):
    ...
    ValueError: --bias-init: gyro bias bgx = 1e+06 rad/s is implausible: |b_g| must be <= 0.5 rad/s per axis (consumer MEMS gyros are within ±5 deg/s = 0.09 rad/s; a larger value is a deg/s or typing mistake)
    """
    try:
        numbers = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be six numbers 'bgx,bgy,bgz,bax,bay,baz' (rad/s, m/s^2); got {values!r}") from None
    if len(numbers) != 6 or not all(math.isfinite(v) for v in numbers):
        raise ValueError(f"{what} must be six finite numbers 'bgx,bgy,bgz,bax,bay,baz' (rad/s, m/s^2); got {values!r}")
    for name, value in zip(("bgx", "bgy", "bgz"), numbers[:3]):
        if abs(value) > GYRO_BIAS_BOUND:
            raise ValueError(f"{what}: gyro bias {name} = {value:g} rad/s is implausible: |b_g| must be <= "
                             f"{GYRO_BIAS_BOUND:g} rad/s per axis (consumer MEMS gyros are within ±5 deg/s = 0.09 "
                             f"rad/s; a larger value is a deg/s or typing mistake)")
    for name, value in zip(("bax", "bay", "baz"), numbers[3:]):
        if abs(value) > ACCEL_BIAS_BOUND:
            raise ValueError(f"{what}: accelerometer bias {name} = {value:g} m/s^2 is implausible: |b_a| must be <= "
                             f"{ACCEL_BIAS_BOUND:g} m/s^2 per axis (consumer MEMS accelerometers are within ±150 mg = "
                             f"1.5 m/s^2; a larger value is a g or typing mistake)")
    return numbers


def check_noise_values(noise: dict, where: str) -> dict[str, float]:
    """Return the IMU noise parameters of ``noise`` as floats; raise DataFileError for a negative, NaN or non-number.

    >>> check_noise_values({"gyroscope_noise_density": -1e-4}, "imu0/sensor.yaml")
    Traceback (most recent call last):
    ...
    evio_lib.io.errors.DataFileError: imu0/sensor.yaml: gyroscope_noise_density must be a finite number >= 0; got -0.0001 (a noise density or random walk is a standard deviation)
    """
    out = {}
    for key, value in noise.items():
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = math.nan
        if isinstance(value, bool) or not math.isfinite(number) or number < 0:
            raise DataFileError(f"{where}: {key} must be a finite number >= 0; got {value!r} (a noise density or "
                                f"random walk is a standard deviation)")
        out[key] = number
    return out
