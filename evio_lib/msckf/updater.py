"""The MSCKF's batched feature update (thesis §3.3.7): from the tracks an image hands over to one EKF update.

:meth:`MsckfUpdater.update` takes the features of one image (lost and pruned tracks,
``feature_database.FeatureUse``) and runs these named steps:

1. ``_triangulate``: all features at once, in inverse depth (``triangulate_inverse_depth_batch``); with
   ``observation_outlier_px`` each track's outlying observations are dropped and the track triangulated again
   (``_drop_outlier_observations``).
2. ``_usable``: a feature whose triangulation failed is dropped (counted by reason); with ``far_point_fallback`` and
   the gate on, a track that failed for lack of parallax (behind a camera, beyond ``triangulation_max_depth``, no
   baseline) is kept with a point far along its anchor's bearing (counted as ``far_point_fallback``).
3. ``_gated_rows``: for each feature the residual and Jacobians of its observations (Eqs. 41-48), whitened per
   observation (rows 2i, 2i+1 of r, H_x and H_f multiplied by W_i = L_i^-1, so the noise becomes N(0, I)), projected
   on the left nullspace of H_f (Eq. 50) and, with ``observability_constrained``, constrained as a whole,
   H_o* = H_o (I - N (N^T N)^-1 N^T) with the observing cameras' first-estimate nullspace N, so H_o* N = 0
   (``observability.constrain_projected_jacobian``); features with equal observation counts are processed together
   (``_project``). The chi-square gate (``chi2_probability``, with unit noise) tests ALL the feature's observations
   in the window, dof 2M - 3 (``_mahalanobis``): a pruned feature's update rows come from the leaving states only,
   but the gate sees the whole track: more degrees of freedom, more power against moving points, less bias on the
   kept residuals (``update.gating_mean_shrink``).
4. ``_apply``: the surviving rows are stacked, QR-compressed (Eqs. 51-55) and applied in one Joseph-form Kalman
   update (Eqs. 56-58, R = I for whitened rows); the corrected state must be finite with a covariance P (else the
   update is refused and the state before it stands).

The updater changes nothing it is given: the new state, the features used, the rows and every dropped feature by
reason come back in an :class:`UpdateResult`, which ``Msckf`` applies.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from evio_lib.geometry.rotation import quat_from_rotvec, quat_multiply, quat_normalize, quat_to_rot
from evio_lib.msckf.config import MsckfConfig
from evio_lib.msckf.feature_database import FeatureUse, isotropic_whitening
from evio_lib.msckf.observability import camera_nullspace, constrain_projected_jacobian
from evio_lib.msckf.state import (
    BA,
    BG,
    CAMERA_DIM,
    IMU_DIM,
    POS,
    THETA,
    VEL,
    FilterState,
    ImuState,
    _camera_unchecked,
    _filter_state_unchecked,
    _frozen,
    _unchecked,
    state_problem,
)
from evio_lib.msckf.triangulation import triangulate_inverse_depth_batch
from evio_lib.msckf.update import chi_square_threshold, kalman_update, measurement_compress

__all__ = ["FAR_POINT_REASONS", "MsckfUpdater", "UpdateResult", "apply_correction"]

#: Triangulation failures that mean "too little parallax for a depth" rather than "inconsistent observations".
FAR_POINT_REASONS = ("behind_camera", "too_far", "insufficient_baseline")

_Item = tuple[int, FeatureUse, NDArray[np.float64]]  # (index in uses, feature, point p_FinG (3,))


def apply_correction(state: FilterState, dx: NDArray[np.float64], P_new: NDArray[np.float64]) -> FilterState:
    """Return the state corrected by dx (15 + 6N,) with covariance P_new: ``state.inject_error(dx)`` with P replaced.

    Same result as ``evio_lib.msckf.state.inject_error`` (q <- quat_from_rotvec(δθ) ⊗ q for the IMU and every
    camera, renormalised; everything else additive; first estimates kept), computed for all attitudes in one
    batch: the filter calls it after every update. dx and P_new must be finite (the filter checks).
    """
    dx = np.asarray(dx, dtype=np.float64)
    if dx.shape != (state.dim,) or np.shape(P_new) != (state.dim, state.dim):
        raise ValueError(f"dx must have shape ({state.dim},) and P_new ({state.dim}, {state.dim}); got "
                         f"{dx.shape} and {np.shape(P_new)}")
    imu = state.imu
    n_cam = state.num_cameras
    dcam = dx[IMU_DIM:].reshape(n_cam, CAMERA_DIM)
    q_C, p_C = state.camera_poses
    # q <- δq(δθ) ⊗ q, for the IMU (row 0) and the cameras (rows 1..N) at once
    q_all = quat_normalize(quat_multiply(
        quat_from_rotvec(np.vstack((dx[THETA], dcam[:, :3]))), np.vstack((imu.q_GtoI, q_C))
    ))
    new_imu = _unchecked(
        ImuState, q_GtoI=_frozen(q_all[0].copy()), b_g=_frozen(imu.b_g + dx[BG]),
        v_IinG=_frozen(imu.v_IinG + dx[VEL]), b_a=_frozen(imu.b_a + dx[BA]), p_IinG=_frozen(imu.p_IinG + dx[POS]),
        timestamp=imu.timestamp, q_GtoI_null=imu.q_GtoI_null, v_IinG_null=imu.v_IinG_null,
        p_IinG_null=imu.p_IinG_null,
    )
    p_new = p_C + dcam[:, 3:]  # p_CinG <- p_CinG + δp_C
    cameras = {
        cam.id: _camera_unchecked(cam.id, cam.timestamp, _frozen(q_all[i + 1].copy()), _frozen(p_new[i].copy()),
                                  cam.q_GtoC_null, cam.p_CinG_null)
        for i, cam in enumerate(state.cameras.values())
    }
    return _filter_state_unchecked(new_imu, cameras, np.array(P_new, dtype=np.float64), state)


@dataclass(frozen=True, eq=False)
class UpdateResult:
    """What one :meth:`MsckfUpdater.update` did.

    Attributes:
        used: (F,) which of the features entered the update that was applied (all False when none was).
        state: the state after the update; the state it was given when no update was applied.
        rejections: the features dropped, by reason (the triangulation's reasons, too_few_observations,
            behind_camera, chi2), the observations dropped (outlier_observations) and the far-point candidates
            (far_point_fallback, counted before the gate).
        rows: projected rows stacked for the Kalman update (0: no feature passed, no update was tried).
        refused: why a tried update was refused (the Kalman update failed, or its result was not finite or not a
            covariance); None when it was applied or not tried.
    """

    used: NDArray[np.bool_]
    state: FilterState
    rejections: Counter[str] = field(default_factory=Counter)
    rows: int = 0
    refused: str | None = None

    @property
    def applied(self) -> bool:
        """Return whether an update changed the state."""
        return self.rows > 0 and self.refused is None


class MsckfUpdater:
    """The batched, gated, compressed MSCKF update of a window's features (module docstring).

    Args:
        config: the triangulation settings and checks, the gate (``chi2_gating``, ``chi2_probability``), the OC
            switch, ``observation_outlier_px``, the isotropic feature noise, ``triangulation_max_depth`` (the far
            points' depth) and gravity (the OC nullspace).

    Attributes:
        config: the configuration.
        triangulation_settings: the keyword arguments of the triangulation (``MsckfConfig.triangulation_settings``).
    """

    def __init__(self, config: MsckfConfig) -> None:
        self.config = config
        self.triangulation_settings = config.triangulation_settings()
        self._iso_whiten = isotropic_whitening(config.feature_noise_sigma)  # W = I / σ (Σ = σ² I); never written
        self._gravity = config.gravity

    def update(self, state: FilterState, uses: list[FeatureUse], far: bool = False) -> UpdateResult:
        """Return the result of ONE compressed EKF update of ``state`` with the features ``uses`` (steps in the
        module docstring); ``far``: tracks without parallax may enter as far points (``far_point_fallback``)."""
        used = np.zeros(len(uses), dtype=bool)
        rejections: Counter[str] = Counter()
        if not uses:
            return UpdateResult(used, state, rejections)
        q_C, p_C = state.camera_poses
        R_C = quat_to_rot(q_C)  # (N, 3, 3) R_GtoC of the window
        uses, results = self._triangulate(uses, R_C, p_C, rejections)
        ok = self._usable(uses, results, R_C, p_C, far, rejections)
        if self.config.observability_constrained:
            cams = state.cameras.values()
            R_null = quat_to_rot(np.array([c.q_GtoC_null for c in cams]))
            p_null = np.array([c.p_CinG_null for c in state.cameras.values()])
        else:
            R_null = p_null = None
        H_parts, r_parts, col_parts = self._gated_rows(ok, used, state.P, R_C, p_C, R_null, p_null, rejections)
        if not np.any(used):
            return UpdateResult(used, state, rejections)
        new_state, rows, refused = self._apply(state, H_parts, r_parts, col_parts)
        if refused is not None:
            used[:] = False
        return UpdateResult(used, new_state, rejections, rows, refused)

    # ------------------------------------------------------------------------------------------------ 1. points
    def _triangulate(self, uses: list[FeatureUse], R_C: NDArray[np.float64], p_C: NDArray[np.float64],
                     rejections: Counter[str]) -> tuple[list[FeatureUse], list[Any]]:
        """Return (uses, the triangulation result of each), outlying observations dropped when configured."""
        results = triangulate_inverse_depth_batch(
            [(R_C[u.window_idx], p_C[u.window_idx], u.xy) for u in uses], **self.triangulation_settings
        )
        if self.config.observation_outlier_px is not None:
            uses, results, dropped = self._drop_outlier_observations(uses, results, R_C, p_C)
            if dropped:
                rejections["outlier_observations"] += dropped
        return uses, results

    def _drop_outlier_observations(
        self, uses: list[FeatureUse], results: list[Any], R_C: NDArray[np.float64], p_C: NDArray[np.float64]
    ) -> tuple[list[FeatureUse], list[Any], int]:
        """Return (uses, results, observations dropped) with each track's outlying observations dropped and the
        track triangulated again.

        An observation is an outlier when it reprojects farther than ``config.observation_outlier_px`` from the
        triangulated point (the last estimate also when the triangulation failed for its RMS residual, which one
        jump can cause). The worst go first, while at least ``min_track_length`` observations and two thirds of
        the track remain; a pruned feature keeps at least two involved observations."""
        limit = self.config.observation_outlier_px / self.config.focal_length_px  # normalised units
        changed: list[int] = []
        dropped = 0
        uses = list(uses)
        for k, (u, res) in enumerate(zip(uses, results)):
            M = u.xy.shape[0]
            if M <= self.config.min_track_length or not (res.success or res.reason == "large_residual"):
                continue
            p_FinC = np.einsum("mij,mj->mi", R_C[u.window_idx], res.p_FinG - p_C[u.window_idx])
            if np.any(p_FinC[:, 2] <= 1e-9):
                continue
            err = np.linalg.norm(u.xy - p_FinC[:, :2] / p_FinC[:, 2:3], axis=1)
            order = np.argsort(err)[::-1]
            most = min(M - self.config.min_track_length, M // 3)
            drop = [i for i in order[:most] if err[i] > limit]
            keep = np.ones(M, dtype=bool)
            keep[drop] = False
            if not drop or np.count_nonzero(u.involved & keep) < min(2, np.count_nonzero(u.involved)):
                continue
            dropped += len(drop)
            uses[k] = FeatureUse(u.window_idx[keep], u.xy[keep], u.involved[keep],
                                 None if u.whiten is None else u.whiten[keep])
            changed.append(k)
        if changed:
            again = triangulate_inverse_depth_batch(
                [(R_C[uses[k].window_idx], p_C[uses[k].window_idx], uses[k].xy) for k in changed],
                **self.triangulation_settings)
            results = list(results)
            for k, res in zip(changed, again):
                results[k] = res
        return uses, results, dropped

    def _usable(self, uses: list[FeatureUse], results: list[Any], R_C: NDArray[np.float64],
                p_C: NDArray[np.float64], far: bool, rejections: Counter[str]) -> list[_Item]:
        """Return (k, feature, point) of the features that go on to the gate: triangulated, or far points."""
        ok: list[_Item] = []
        for k, (u, res) in enumerate(zip(uses, results)):
            if far and res.reason in FAR_POINT_REASONS and np.count_nonzero(u.involved) >= 2:
                # low parallax: the depth is not observable from this track, its bearing is. A point far along
                # the anchor's bearing; the nullspace projection removes its position error to first order, so
                # the rows constrain the rotation between the cameras; the chi-square gate below judges them.
                # Counted here as a candidate (the gate may still refuse it, then counted there too). The bearing
                # is the fitted (α, β) of the anchor (finite on every failure path; with no baseline at all, the
                # starting guess, i.e. about the anchor's own observation).
                rejections["far_point_fallback"] += 1
                a = u.window_idx[res.anchor]
                alpha, beta, _ = res.inverse_depth
                p_FinA = np.array([alpha, beta, 1.0]) * self.config.triangulation_max_depth
                ok.append((k, u, p_C[a] + R_C[a].T @ p_FinA))
            elif not res.success:
                rejections[res.reason] += 1
            elif np.count_nonzero(u.involved) < 2:  # 2 rows cannot survive the 3-column nullspace projection
                rejections["too_few_observations"] += 1
            else:
                ok.append((k, u, res.p_FinG))
        return ok

    # ------------------------------------------------------------------------------------------------ 2. rows
    def _gated_rows(
        self, ok: list[_Item], used: NDArray[np.bool_], P: NDArray[np.float64], R_C: NDArray[np.float64],
        p_C: NDArray[np.float64], R_null: NDArray[np.float64] | None, p_null: NDArray[np.float64] | None,
        rejections: Counter[str],
    ) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]], list[NDArray[np.int64]]]:
        """Return the update's (H_o, r_o, cols) parts of the features that pass the gate; mark them in ``used``.

        Gating tests each feature on ALL its observations in the window (dof 2M - 3), also when only some of them
        (a prune's) give the update's rows: a moving point shows over its whole track, and a gate with more
        degrees of freedom biases the kept residuals less (``update.gating_mean_shrink``)."""
        # gate on whole tracks, grouped by their length M; the projections of fully used tracks (ended tracks)
        # are the update's rows as they are
        gating = self.config.chi2_gating
        by_length: dict[int, list[_Item]] = {}
        for item in ok:
            if gating or item[1].involved.all():
                by_length.setdefault(item[1].xy.shape[0], []).append(item)
        passed = dict.fromkeys((k for k, _, _ in ok), True)
        H_parts, r_parts, col_parts = [], [], []
        for M, items in by_length.items():
            keep, H_o, r_o, cols = self._project(M, [(np.ones(M, dtype=bool), u, p) for _, u, p in items],
                                                 R_C, p_C, R_null, p_null, rejections)
            if gating:
                gamma = self._mahalanobis(H_o, r_o, cols, P)
                good = gamma < chi_square_threshold(2 * M - 3, self.config.chi2_probability)
                rejections["chi2"] += int(np.count_nonzero(keep & ~good))
                keep &= good
            ks = np.array([k for k, _, _ in items])
            passed.update(zip(ks.tolist(), keep.tolist()))
            take = keep & np.array([u.involved.all() for _, u, _ in items])
            if np.any(take):
                used[ks[take]] = True
                H_parts.append(H_o[take])
                r_parts.append(r_o[take])
                col_parts.append(cols[take])
        groups: dict[int, list[_Item]] = {}
        for k, u, p in ok:
            if passed[k] and not u.involved.all():  # whole tracks were used (or dropped) above
                groups.setdefault(int(np.count_nonzero(u.involved)), []).append((k, u, p))
        for m, items in groups.items():  # pruned tracks: rows from the observations at the removed states only
            keep, H_o, r_o, cols = self._project(m, [(u.involved, u, p) for _, u, p in items], R_C, p_C, R_null,
                                                 p_null, rejections)
            used[np.array([k for k, _, _ in items])[keep]] = True
            H_parts.append(H_o[keep])
            r_parts.append(r_o[keep])
            col_parts.append(cols[keep])
        return H_parts, r_parts, col_parts

    def _project(
        self,
        m: int,
        items: list[tuple[NDArray[np.bool_], FeatureUse, NDArray[np.float64]]],
        R_C: NDArray[np.float64],
        p_C: NDArray[np.float64],
        R_null: NDArray[np.float64] | None,
        p_null: NDArray[np.float64] | None,
        rejections: Counter[str],
    ) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
        """Return (keep (F,), H_o, r_o, cols) for F features with m observations selected by each item's mask:
        the projected Jacobians H_o (F, 2m-3, 6m), residuals r_o (F, 2m-3) and camera columns cols (F, 6m);
        keep is False where a depth or a value is not usable.

        Vectorised over the F features: residuals and Jacobians (Eqs. 41-48), whitening, nullspace projection
        (Eq. 50) and, with the first-estimate poses R_null, p_null, the OC constraint H_o N_C = 0. H_o holds only
        the observing cameras' columns ``cols``.
        """
        widx = np.array([u.window_idx[sel] for sel, u, _ in items])  # (F, m)
        z = np.array([u.xy[sel] for sel, u, _ in items])  # (F, m, 2)
        W = np.array([np.broadcast_to(self._iso_whiten, (m, 2, 2)) if u.whiten is None else u.whiten[sel]
                      for sel, u, _ in items])  # (F, m, 2, 2) W_i = L_i^-1, Σ_i = L_i L_i^T
        p_F = np.array([p for _, _, p in items])  # (F, 3)
        F = widx.shape[0]
        R = R_C[widx]  # (F, m, 3, 3)
        p_FinC = np.einsum("fmij,fmj->fmi", R, p_F[:, None, :] - p_C[widx])  # R_GtoC (p_F - p_C)       (Eq. 42)
        Z = p_FinC[..., 2]
        front = np.all(Z > 1e-9, axis=1)
        if not np.all(front):  # a far point (far_point_fallback) of an inconsistent track; else guarded anyway
            rejections["behind_camera"] += int(np.count_nonzero(~front))
            Z = np.where(front[:, None], Z, 1.0)
        inv_Z = 1.0 / Z
        z_hat = p_FinC[..., :2] * inv_Z[..., None]  # [X/Z, Y/Z]                                          (Eq. 41)
        r = (z - z_hat).reshape(F, 2 * m)  # r = z_meas - z_hat                                           (Eq. 43)
        x, y = z_hat[..., 0], z_hat[..., 1]
        # H_f,i = J_i R_GtoC_i with J_i = 1/Z [[1, 0, -x], [0, 1, -y]]                                  (Eqs. 46, 48)
        H_f = (R[..., :2, :] - z_hat[..., :, None] * R[..., 2:3, :]) * inv_Z[..., None, None]  # (F, m, 2, 3)
        blocks = np.empty((F, m, 2, CAMERA_DIM))  # J_i [[p_FinC x], -R_GtoC]                            (Eq. 47)
        xy_ = x * y
        blocks[..., 0, 0], blocks[..., 0, 1], blocks[..., 0, 2] = xy_, -1.0 - x * x, y
        blocks[..., 1, 0], blocks[..., 1, 1], blocks[..., 1, 2] = 1.0 + y * y, -xy_, -x
        blocks[..., 3:] = -H_f
        # whitening: W_i r_i = W_i H_Ci δx_Ci + W_i H_fi δp_F + W_i n_i with W_i n_i ~ N(0, I), done
        # BEFORE the nullspace so that A^T (W n) stays white (A^T A = I).
        r = np.einsum("fmij,fmj->fmi", W, r.reshape(F, m, 2)).reshape(F, 2 * m)  # r_w = W r
        H_f = W @ H_f  # (F, m, 2, 3)
        blocks = W @ blocks  # (F, m, 2, 6)
        # left nullspace of H_f (2m, 3): the last 2m - 3 columns of its complete QR                       (Eq. 50)
        Q = np.linalg.qr(H_f.reshape(F, 2 * m, 3), mode="complete")[0]
        A_T = np.swapaxes(Q[:, :, 3:], 1, 2)  # (F, 2m - 3, 2m)
        # H_o = A^T blockdiag(H_C1 .. H_Cm): camera j's 6 columns get A^T's two columns 2j, 2j+1 times H_Cj
        A_cam = np.swapaxes(A_T.reshape(F, 2 * m - 3, m, 2), 1, 2)  # (F, m, 2m - 3, 2)
        H_o = np.swapaxes(A_cam @ blocks, 1, 2).reshape(F, 2 * m - 3, m * CAMERA_DIM)
        r_o = np.einsum("fkr,fr->fk", A_T, r)
        cols = ((IMU_DIM + CAMERA_DIM * widx)[:, :, None] + np.arange(CAMERA_DIM)).reshape(F, m * CAMERA_DIM)
        if R_null is not None:
            N_C = camera_nullspace(R_null[widx], p_null[widx], self._gravity)  # (F, 6m, 4) first estimates
            H_o = constrain_projected_jacobian(H_o, N_C)  # H_o* = H_o (I - N (N^T N)^-1 N^T): H_o* N_C = 0
        keep = front & np.all(np.isfinite(H_o), axis=(1, 2)) & np.all(np.isfinite(r_o), axis=1)
        return keep, H_o, r_o, cols

    @staticmethod
    def _mahalanobis(H_o: NDArray[np.float64], r_o: NDArray[np.float64], cols: NDArray[np.int64],
                     P: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return γ_f = r_o^T (H_o P H_o^T + I)^-1 r_o for each feature (whitened rows: unit noise; inf if singular).

        H_o only touches the columns ``cols``, so only that block of P is read."""
        k = H_o.shape[1]
        P_sub = P[cols[:, :, None], cols[:, None, :]]
        S = H_o @ P_sub @ np.swapaxes(H_o, 1, 2)
        S[:, np.arange(k), np.arange(k)] += 1.0
        try:
            return np.einsum("fk,fk->f", r_o, np.linalg.solve(S, r_o[:, :, None])[..., 0])
        except np.linalg.LinAlgError:
            return np.full(H_o.shape[0], np.inf)

    # ------------------------------------------------------------------------------------------------ 3. the update
    @staticmethod
    def _apply(
        state: FilterState, H_parts: list[NDArray[np.float64]], r_parts: list[NDArray[np.float64]],
        col_parts: list[NDArray[np.int64]],
    ) -> tuple[FilterState, int, str | None]:
        """Return (the updated state, rows, None), or (``state``, rows, why) when the update is refused: the
        projected rows stacked into one (rows, 15 + 6N) system, QR-compressed, applied in a Kalman update and
        checked (finite, P a covariance)."""
        n = state.dim
        rows = sum(h.shape[0] * h.shape[1] for h in H_parts)
        H = np.zeros((rows, n))
        r = np.empty(rows)
        start = 0
        for H_o, r_o, cols in zip(H_parts, r_parts, col_parts):
            F, k, _ = H_o.shape
            row_idx = start + np.arange(F * k).reshape(F, k)
            H[row_idx[:, :, None], cols[:, None, :]] = H_o
            r[start:start + F * k] = r_o.reshape(-1)
            start += F * k
        H_c, r_c = measurement_compress(H, r)  # (Eqs. 51-55) when rows > n
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # the result is checked below
                dx, P_new = kalman_update(state.P, H_c, r_c, 1.0)  # (Eqs. 56-58), whitened rows: R = I
        except ValueError as exc:
            return state, rows, f"the Kalman update failed ({exc})"
        if not np.all(np.isfinite(dx)):
            return state, rows, "its correction holds non-finite values"
        new_state = apply_correction(state, dx, P_new)
        problem = state_problem(new_state)  # finite, P symmetric positive semi-definite (Cholesky, O(n³ / 3))
        if problem is not None:
            return state, rows, problem
        return new_state, rows, None
