"""The MSCKF's IMU input: checked samples in a buffer, and the checked propagation of the state to an image time.

Feeding (:meth:`ImuBuffer.feed`): times must be finite, strictly increasing and later than every sample fed
before (s); gyro in rad/s and accel (specific force) in m/s^2, both in the IMU frame I.

* Range: samples with a component beyond the IMU's full scale (``config.gyro_full_scale``, ``accel_full_scale``;
  ±2000 deg/s and ±16 g by default) cannot come from the sensor: they are dropped and the hole is interpolated like
  any gap. A batch that would bring the share of such samples above 10 % (of >= 10 fed so far) is refused with
  ValueError, naming the likely unit mistake (deg/s, mg, ...), and nothing of it is buffered: a real sensor
  saturates at its full scale, beyond it are only glitches.
* Units: a gyro stream that turns faster than one revolution per second most of the time (after 200 samples) is
  reported once as probably deg/s.

Propagation (:meth:`ImuBuffer.propagate`): ``propagation.propagate`` with the buffered samples (the OC-EKF's
transition hook when ``config.observability_constrained``); the IMU gaps longer than ``config.imu_max_gap`` that
it crosses are reported once each (a gap crossed by two propagations counts once); a gap longer than
``imu_max_bridged_gap`` raises ``propagation.ImuGapError``. The result must be finite with a symmetric positive
semi-definite IMU covariance block (the rest of P changes only by Φ P_IC, whose finiteness is checked), else
:class:`StepRefusedError` is raised and the state before it stands.

Nothing here warns or counts by itself: what the filter should count and announce comes back as
:data:`Fault` tuples (``Msckf`` turns them into ``Msckf.faults`` and ``MsckfWarning``).
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.observability import constrain_transition
from evio_lib.msckf.propagation import ImuGapError, imu_gaps, propagate
from evio_lib.msckf.state import IMU_DIM, FilterState, state_problem

__all__ = ["Fault", "ImuBuffer", "StepRefusedError"]

#: What the filter counts and warns about: (key of ``Msckf.faults``, count, message).
Fault = tuple[str, int, str]

_DEG_S_SUSPECT_RATE = 2.0 * math.pi  # rad/s: a gyro stream mostly faster than one turn per second looks like deg/s
_DEG_S_MIN_SAMPLES = 200  # samples seen before that judgement is made
_UNITS_MIN_SAMPLES = 10  # once this many samples were fed, more than _UNITS_FRACTION of them beyond the full
_UNITS_FRACTION = 0.1  # scale means wrong units (or a broken sensor), not glitches: feed refuses the batch

Samples = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


class StepRefusedError(ValueError):
    """Raised when a propagation would leave a non-finite or non-PSD state; the filter keeps the state before it."""


class ImuBuffer:
    """Checked IMU samples, held until the filter's state has passed them (module docstring).

    Args:
        config: the IMU's full scale, the gap limits and noise (``MsckfConfig``); ``observability_constrained``
            selects the OC-EKF's transition hook.
    """

    def __init__(self, config: MsckfConfig) -> None:
        self.config = config
        self._hook = constrain_transition if config.observability_constrained else None
        self._t = np.zeros(0)
        self._w = np.zeros((0, 3))
        self._a = np.zeros((0, 3))
        self._pending: list[Samples] = []
        self.last_time = -math.inf  # the last sample fed, dropped ones included
        self._fed = 0  # samples accepted by feed so far, dropped ones included
        self._dropped = {"imu_gyro_out_of_range": 0, "imu_accel_out_of_range": 0}
        self._gyro_seen = 0  # in-range gyro samples fed, and those turning faster than _DEG_S_SUSPECT_RATE
        self._gyro_fast = 0
        self._units_reported = False
        self._last_gap_end = -math.inf  # end of the last IMU gap reported (a gap crossed in two calls counts once)

    # ------------------------------------------------------------------------------------------------ feeding
    def feed(self, t: float | ArrayLike, gyro: ArrayLike, accel: ArrayLike) -> list[Fault]:
        """Buffer IMU samples: one (t float, gyro (3,), accel (3,)) or a batch (t (n,), gyro (n, 3), accel (n, 3));
        return the faults to count (dropped samples, a gyro that looks like deg/s).

        Raises ValueError for malformed, non-finite or out-of-order input and for a batch that would make the
        samples beyond the full scale more than 10 % of those fed (from 10 samples on); nothing of it is buffered.
        """
        try:
            t_arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
            w = np.asarray(gyro, dtype=np.float64).reshape(-1, 3) if np.size(gyro) % 3 == 0 else None
            a = np.asarray(accel, dtype=np.float64).reshape(-1, 3) if np.size(accel) % 3 == 0 else None
        except (TypeError, ValueError) as exc:
            raise ValueError("t, gyro and accel must be numeric: t (n,), gyro (n, 3), accel (n, 3)") from exc
        if t_arr.ndim != 1:
            raise ValueError(f"t must be a time or shape (n,); got shape {np.shape(t)}")
        n = t_arr.shape[0]
        if w is None or a is None or w.shape != (n, 3) or a.shape != (n, 3):
            raise ValueError(
                f"gyro and accel must have shape (n, 3) = ({n}, 3) (or (3,) for one sample); "
                f"got {np.shape(gyro)} and {np.shape(accel)}"
            )
        if not (np.all(np.isfinite(t_arr)) and np.all(np.isfinite(w)) and np.all(np.isfinite(a))):
            raise ValueError("t, gyro and accel must contain only finite values (no NaN/inf)")
        if n == 0:
            return []
        if np.any(np.diff(t_arr) <= 0.0) or t_arr[0] <= self.last_time:
            raise ValueError(
                f"t must be strictly increasing and later than the last sample fed ({self.last_time!r}); "
                f"got times from {t_arr[0]!r}"
            )
        t_last = float(t_arr[-1])  # dropped samples count for the time order too
        keep, faults = self._check_range(t_arr, w, a)
        if keep is not None:
            t_arr, w, a = t_arr[keep], w[keep], a[keep]
        if t_arr.shape[0]:
            self._pending.append((t_arr.copy(), w.copy(), a.copy()))
        self.last_time = t_last
        faults += self._check_gyro_units(w)
        return faults

    def _check_range(self, t: NDArray[np.float64], w: NDArray[np.float64],
                     a: NDArray[np.float64]) -> tuple[NDArray[np.bool_] | None, list[Fault]]:
        """Return (the mask of samples within the IMU's full scale, None: all are; the faults of the dropped ones);
        raise on a wrong-units batch."""
        cfg = self.config
        bad_w = np.any(np.abs(w) > cfg.gyro_full_scale, axis=1)
        bad_a = np.any(np.abs(a) > cfg.accel_full_scale, axis=1)
        n_w, n_a, n = int(np.count_nonzero(bad_w)), int(np.count_nonzero(bad_a)), t.shape[0]
        seen = self._fed + n
        if n_w == 0 and n_a == 0:
            self._fed = seen
            return None, []
        gyro_range = (f"the gyro's full scale ±{cfg.gyro_full_scale:.4g} rad/s "
                      f"({math.degrees(cfg.gyro_full_scale):.0f} deg/s, gyro_full_scale)")
        accel_range = (f"the accelerometer's full scale ±{cfg.accel_full_scale:.4g} m/s^2 "
                       f"({cfg.accel_full_scale / 9.80665:.3g} g, accel_full_scale)")
        total_w = self._dropped["imu_gyro_out_of_range"] + n_w
        total_a = self._dropped["imu_accel_out_of_range"] + n_a
        if seen >= _UNITS_MIN_SAMPLES and total_w > _UNITS_FRACTION * seen:
            raise ValueError(
                f"gyro must be in rad/s: {total_w} of the {seen} samples fed exceed {gyro_range}, largest "
                f"|component| {np.abs(w).max():.4g}; these look like deg/s (np.radians converts them). "
                "Nothing of this batch was buffered"
            )
        if seen >= _UNITS_MIN_SAMPLES and total_a > _UNITS_FRACTION * seen:
            raise ValueError(
                f"accel must be the specific force in m/s^2: {total_a} of the {seen} samples fed exceed "
                f"{accel_range}, largest |component| {np.abs(a).max():.4g}; check the units (g, mg or mm/s^2 need "
                "converting). Nothing of this batch was buffered"
            )
        self._fed = seen
        faults = []
        for key, bad, values, what, hint in (
                ("imu_gyro_out_of_range", bad_w, w, gyro_range, "; gyro must be in rad/s (deg/s?)"),
                ("imu_accel_out_of_range", bad_a, a, accel_range, "")):
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                self._dropped[key] += int(np.count_nonzero(bad))
                faults.append((key, int(np.count_nonzero(bad)),
                               f"feed_imu dropped {int(np.count_nonzero(bad))} IMU sample(s) beyond {what}, the "
                               f"first at t = {t[k]:.3f} s ({values[k].tolist()}){hint}; the IMU signal is "
                               "interpolated across the hole"))
        return ~(bad_w | bad_a), faults

    def _check_gyro_units(self, w: NDArray[np.float64]) -> list[Fault]:
        """Return a fault, once, when most gyro samples fed so far turn faster than one revolution per second."""
        if self._units_reported or w.shape[0] == 0:
            return []
        self._gyro_seen += w.shape[0]
        self._gyro_fast += int(np.count_nonzero(np.einsum("ij,ij->i", w, w) > _DEG_S_SUSPECT_RATE**2))
        if self._gyro_seen >= _DEG_S_MIN_SAMPLES and 2 * self._gyro_fast > self._gyro_seen:
            self._units_reported = True
            return [("gyro_units_suspect", 1,
                     f"gyro must be in rad/s: {self._gyro_fast} of the {self._gyro_seen} samples fed turn faster "
                     f"than one revolution per second (|ω| > 2π rad/s), which looks like deg/s "
                     "(np.radians converts them)")]
        return []

    # ------------------------------------------------------------------------------------------------ reading
    def samples(self, t_state: float) -> Samples:
        """Return the buffered (t (M,), gyro (M, 3), accel (M, 3)), merged, without the samples older than the last
        one at or before ``t_state`` (the filter's time; those are never needed again)."""
        if self._pending:
            self._t = np.concatenate([self._t] + [p[0] for p in self._pending])
            self._w = np.concatenate([self._w] + [p[1] for p in self._pending])
            self._a = np.concatenate([self._a] + [p[2] for p in self._pending])
            self._pending = []
        j = max(int(np.searchsorted(self._t, t_state, side="right")) - 1, 0)
        if j > 0:  # views, no copies
            self._t, self._w, self._a = self._t[j:], self._w[j:], self._a[j:]
        return self._t, self._w, self._a

    # ------------------------------------------------------------------------------------------------ propagation
    def propagate(self, state: FilterState, t: float) -> tuple[FilterState, list[Fault]]:
        """Return (the state propagated to time t with the buffered samples, the new IMU gaps it crossed).

        Raises ValueError when nothing was fed, ``propagation.ImuGapError`` for a gap beyond
        ``imu_max_bridged_gap`` and :class:`StepRefusedError` for a result that is not finite or whose IMU
        covariance is not positive semi-definite (module docstring)."""
        t0 = state.timestamp
        if t == t0:
            return state, []
        imu_t, imu_w, imu_a = self.samples(t0)
        if imu_t.shape[0] == 0:
            raise ValueError("no IMU samples buffered: call feed_imu before process_image")
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # the result is checked below
                new_state = propagate(state, imu_t, imu_w, imu_a, t, self.config, transition_hook=self._hook)
        except ImuGapError:
            raise
        except ValueError as exc:  # the inputs were checked: a breakdown of the numbers (e.g. an absurd time span)
            new_state, problem = None, f"the integration failed ({exc})"
        else:
            problem = state_problem(new_state, psd_size=IMU_DIM)  # P_CC is unchanged, P_IC = Φ P_IC checked finite
        if problem is not None:
            raise StepRefusedError(
                f"propagation from t = {t0:.3f} s to t = {t:.3f} s refused: {problem}; the filter keeps its state at "
                f"t = {t0:.3f} s. Check the IMU samples and the image time in between"
            )
        assert new_state is not None
        return new_state, self._new_gaps(imu_t, t0, t)

    def _new_gaps(self, imu_t: NDArray[np.float64], t0: float, t: float) -> list[Fault]:
        """Return a fault for each IMU gap longer than ``imu_max_gap`` in (t0, t) not reported before."""
        cfg = self.config
        faults = []
        for start, end in imu_gaps(imu_t, t0, t, cfg.imu_max_gap):
            if start > self._last_gap_end:  # a new gap, not the rest of one counted by the previous call
                faults.append(("imu_gaps", 1,
                               f"IMU gap of {end - start:.3g} s > imu_max_gap = {cfg.imu_max_gap:g} s (no samples "
                               f"from t = {start:.3f} s to t = {end:.3f} s): bridged by interpolation, covariance "
                               f"inflated for the unseen motion (imu_gap_accel_sigma = {cfg.imu_gap_accel_sigma:g} "
                               f"m/s^2, imu_gap_gyro_sigma = {cfg.imu_gap_gyro_sigma:g} rad/s)"))
            self._last_gap_end = max(self._last_gap_end, float(end))
        return faults
