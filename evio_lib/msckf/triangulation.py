"""Triangulation of MSCKF features from their tracks: a two-view initial guess refined by inverse-depth least squares.

A feature seen by M cameras C_i (poses R_GtoC_i, p_CinG_i) at undistorted normalised coordinates z_i = (x_i, y_i)
is parametrised in its first (anchor) camera A by the inverse depth θ = (α, β, ρ) = (X/Z, Y/Z, 1/Z) of
p_FinA = (X, Y, Z) (Montiel et al. 2006, Civera et al. 2008; thesis §3.3.7, Eqs. 59-79). With the pose of A
relative to C_i::

    R_AtoC_i = R_GtoC_i R_GtoA^T,      p_AinC_i = R_GtoC_i (p_AinG - p_CinG_i)                (thesis R^Ci_Cn, p^Ci_Cn)
    p_FinC_i = R_AtoC_i p_FinA + p_AinC_i = Z [ R_AtoC_i [α, β, 1]^T + ρ p_AinC_i ] = Z h_i   (Eqs. 59-66)
    g_i(α, β, ρ) = [h_i1 / h_i3, h_i2 / h_i3]                                                  (Eq. 67)

h_i is *linear* in θ: h_i = D_i θ + r_i3 with D_i = [r_i1, r_i2, p_AinC_i] (columns 1 and 2 of R_AtoC_i and the
translation), so the Jacobian of Eqs. 72-78 is J_i = (D_i[0:2, :] - g_i D_i[2, :]) / h_i3. The residual is
e_i = g_i(θ) - z_i; Levenberg-Marquardt minimises Σ |e_i|^2 (the isotropic information matrix Ω = σ^-2 I of Eq. 71
scales H and b of Eqs. 68-70 alike, so it cancels in the step). The result in G is (Eq. 79)::

    p_FinG = R_GtoA^T [α, β, 1]^T / ρ + p_AinG

A feature is rejected (``success=False`` with a ``reason`` from :data:`TRIANGULATION_REASONS`) for: fewer than two
observations, too small a translation-to-depth ratio, no convergence, a point behind / too close to / too far from
any camera, or a large reprojection residual. Nothing returned is ever NaN.

:func:`triangulate_inverse_depth_batch` solves many features at once (their tracks padded to one length; every
Levenberg-Marquardt iteration is a handful of NumPy operations on all of them), which is what the filter should call
once per update; :func:`triangulate_inverse_depth` is the same computation for one feature.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Integral

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.geometry.rotation import quat_to_rot

__all__ = [
    "TRIANGULATION_REASONS",
    "TriangulationResult",
    "as_camera_poses",
    "relative_to_anchor",
    "triangulate_two_view_initial",
    "triangulation_residual",
    "triangulation_jacobian",
    "triangulate_inverse_depth",
    "triangulate_inverse_depth_batch",
]

#: Every value ``TriangulationResult.reason`` can take ("ok" on success), in the order the checks run.
TRIANGULATION_REASONS: tuple[str, ...] = (
    "ok",
    "too_few_observations",  # fewer than 2 observations
    "not_converged",  # no step below step_tol within max_iterations
    "behind_camera",  # Z <= 0 in some camera (or ρ <= 0)
    "too_close",  # Z < min_depth in some camera
    "too_far",  # Z > max_depth in some camera
    "insufficient_baseline",  # max_i |p_CinG_i - p_AinG| / Z_A < min_baseline_ratio (or all centres equal)
    "large_residual",  # RMS reprojection error sqrt(Σ_i |g_i - z_i|^2 / M) > max_rms_residual
)
_OK, _TOO_FEW, _NOT_CONVERGED, _BEHIND, _TOO_CLOSE, _TOO_FAR, _BASELINE, _RESIDUAL = range(len(TRIANGULATION_REASONS))

_ROT_TOL = 1e-6  # max |R R^T - I| and |det R - 1| accepted for a camera rotation
_MIN_H3 = 1e-6  # h_i3 = Z_i / Z_A at or below this: the point is (nearly) in camera i's plane Z = 0 or behind it
_MIN_BASELINE = 1e-12  # metres; below this every camera shares one centre and the depth is unobservable
_LAMBDA0, _LAMBDA_MIN, _LAMBDA_MAX = 1e-3, 1e-12, 1e12  # Levenberg-Marquardt damping (relative to diag H)


@dataclass(frozen=True)
class TriangulationResult:
    """Outcome of :func:`triangulate_inverse_depth`; every field is finite.

    Attributes:
        p_FinG: (3,) feature position in G (Eq. 79). On failure the last estimate when ρ > 0, else the anchor camera
            centre; do not use it when ``success`` is False.
        success: True when every check passed.
        reason: ``"ok"`` or the first failed check, one of :data:`TRIANGULATION_REASONS`.
        iterations: Levenberg-Marquardt iterations run (accepted and rejected steps).
        cost: Σ_i |g_i - z_i|^2 at the returned estimate (normalised image units squared).
        rms_residual: RMS reprojection error sqrt(cost / M) (normalised units; the quantity that is checked).
        max_residual: largest per-observation reprojection error |g_i - z_i| (normalised units).
        inverse_depth: (3,) (α, β, ρ) of the feature in the anchor camera.
        anchor: index of the anchor camera within the feature's track.
        baseline_ratio: max_i |p_CinG_i - p_AinG| / Z_A = max baseline * ρ, the translation-to-depth ratio
            (0 when ρ <= 0).
        inverse_depth_std: (3,) standard deviations of (α, β, ρ) per unit of measurement noise, sqrt(diag((J^T
            J)^-1)) with J the Jacobian (Eqs. 72-78) at the returned estimate; multiply by the noise σ of z in
            normalised units. Its ρ entry says whether the track measured a depth at all: |ρ| within a few of it
            means the point may as well lie at infinity. ``inf`` where J^T J is singular (no baseline).
    """

    p_FinG: NDArray[np.float64]
    success: bool
    reason: str
    iterations: int
    cost: float
    rms_residual: float
    max_residual: float
    inverse_depth: NDArray[np.float64]
    anchor: int
    baseline_ratio: float
    inverse_depth_std: NDArray[np.float64]


# ----------------------------------------------------------------------------------------------------- input checks


def _float_array(value: ArrayLike, name: str, expected: str) -> NDArray[np.float64]:
    """Return ``value`` as a float64 array, raising ValueError naming ``name`` if it is not numeric."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got {value!r}") from exc


def _require_finite(arr: NDArray[np.float64], name: str) -> None:
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must contain only finite values (no NaN/inf); got non-finite entries")


def _rotations(R_GtoC: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return (M, 3, 3) float64 from (M, 3, 3) matrices or (M, 4) JPL quaternions; shape and finiteness checked."""
    R = _float_array(R_GtoC, name, "(M, 3, 3) or (M, 4)")
    if R.ndim == 2 and R.shape[1] == 4:
        _require_finite(R, name)
        if R.shape[0] and np.any(np.einsum("ij,ij->i", R, R) < 1e-12):
            raise ValueError(f"{name} given as JPL quaternions (M, 4) must have non-zero norms; got a zero quaternion")
        return quat_to_rot(R)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"{name} must have shape (M, 3, 3) (or (M, 4) JPL quaternions); got {R.shape}")
    _require_finite(R, name)
    return R


def _check_rotations(R: NDArray[np.float64], name: str) -> None:
    """Raise ValueError unless every R[m] is a rotation (R R^T = I and det R = 1 within _ROT_TOL)."""
    if R.shape[0] == 0:
        return
    orth = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max()
    det = np.linalg.det(R)
    if orth > _ROT_TOL or np.abs(det - 1.0).max() > _ROT_TOL:
        raise ValueError(
            f"{name} must hold rotation matrices (R R^T = I, det R = 1 within {_ROT_TOL:g}); "
            f"got max |R R^T - I| = {orth:.3g}, det in [{det.min():.6g}, {det.max():.6g}]"
        )


def _positions(p_CinG: ArrayLike, n: int, name: str) -> NDArray[np.float64]:
    p = _float_array(p_CinG, name, "(M, 3)")
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{name} must have shape (M, 3); got {p.shape}")
    if p.shape[0] != n:
        raise ValueError(f"{name} must have one row per camera of the rotations ({n}); got {p.shape[0]} rows")
    _require_finite(p, name)
    return p


def _observations(obs_xy: ArrayLike, n: int, name: str = "obs_xy") -> NDArray[np.float64]:
    z = _float_array(obs_xy, name, "(M, 2)")
    if z.ndim != 2 or z.shape[1] != 2:
        raise ValueError(f"{name} must have shape (M, 2) (undistorted normalised x, y); got {z.shape}")
    if z.shape[0] != n:
        raise ValueError(f"{name} must have one row per camera ({n}); got {z.shape[0]} rows")
    _require_finite(z, name)
    return z


def as_camera_poses(R_GtoC: ArrayLike, p_CinG: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return validated float64 camera poses (R_GtoC (M, 3, 3), p_CinG (M, 3)).

    Args:
        R_GtoC: (M, 3, 3) rotations G -> C_i, or (M, 4) JPL quaternions q_GtoC (scalar last), converted with
            :func:`~evio_lib.geometry.rotation.quat_to_rot`.
        p_CinG: (M, 3) camera centres in G.

    Raises ValueError on wrong shapes, differing M, non-finite values or matrices that are not rotations (1e-6).

    >>> R, p = as_camera_poses([[0.0, 0.0, 0.0, 1.0]], [[1.0, 2.0, 3.0]])
    >>> R.shape, p.shape
    ((1, 3, 3), (1, 3))
    """
    R = _rotations(R_GtoC, "R_GtoC")
    _check_rotations(R, "R_GtoC")
    return R, _positions(p_CinG, R.shape[0], "p_CinG")


def _as_inverse_depth(inverse_depth: ArrayLike) -> NDArray[np.float64]:
    theta = _float_array(inverse_depth, "inverse_depth", "(3,)")
    if theta.shape != (3,):
        raise ValueError(f"inverse_depth must have shape (3,) = (alpha, beta, rho); got {theta.shape}")
    _require_finite(theta, "inverse_depth")
    return theta


def _as_relative_poses(R_AtoC: ArrayLike, p_AinC: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    R = _float_array(R_AtoC, "R_AtoC", "(M, 3, 3)")
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R_AtoC must have shape (M, 3, 3); got {R.shape}")
    _require_finite(R, "R_AtoC")
    p = _float_array(p_AinC, "p_AinC", "(M, 3)")
    if p.shape != (R.shape[0], 3):
        raise ValueError(f"p_AinC must have shape ({R.shape[0]}, 3) to match R_AtoC; got {p.shape}")
    _require_finite(p, "p_AinC")
    return R, p


def _index(value: int, n: int, name: str) -> int:
    """Return ``value`` as an index in [0, n) (negative values count from the end) or raise ValueError."""
    if isinstance(value, bool) or not isinstance(value, Integral) or not -n <= int(value) < n:
        raise ValueError(f"{name} must be an integer camera index with -{n} <= {name} < {n}; got {value!r}")
    return int(value) % n


def _number(value: float, name: str, minimum: float = 0.0, strict: bool = True) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a finite number; got {value!r}") from exc
    ok = np.isfinite(number) and (number > minimum if strict else number >= minimum)
    if isinstance(value, bool) or not ok:
        raise ValueError(f"{name} must be a finite number {'>' if strict else '>='} {minimum:g}; got {value!r}")
    return number


# ----------------------------------------------------------------------------------------------------- geometry


def relative_to_anchor(
    R_GtoC: ArrayLike, p_CinG: ArrayLike, anchor: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return the anchor camera's pose in every camera: (R_AtoC (M, 3, 3), p_AinC (M, 3)).

    Args:
        R_GtoC: (M, 3, 3) rotations G -> C_i or (M, 4) JPL quaternions q_GtoC.
        p_CinG: (M, 3) camera centres in G.
        anchor: index of the anchor camera A (the first observation by default).

    R_AtoC_i = R_GtoC_i R_GtoA^T and p_AinC_i = R_GtoC_i (p_AinG - p_CinG_i), so that
    p_FinC_i = R_AtoC_i p_FinA + p_AinC_i (thesis Eq. 59; the anchor's own row is (I, 0)).

    >>> R, p = relative_to_anchor(np.stack([np.eye(3)] * 2), [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    >>> p.tolist()
    [[0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]
    """
    R, p = as_camera_poses(R_GtoC, p_CinG)
    if R.shape[0] == 0:
        raise ValueError("R_GtoC must hold at least one camera to pick an anchor; got 0")
    a = _index(anchor, R.shape[0], "anchor")
    R_AtoC = R @ R[a].T  # R_AtoC_i = R_GtoC_i R_GtoA^T
    p_AinC = np.einsum("mij,mj->mi", R, p[a] - p)  # p_AinC_i = R_GtoC_i (p_AinG - p_CinG_i)
    return R_AtoC, p_AinC


def _midpoints(
    d_i: NDArray[np.float64], d_j: NDArray[np.float64], c_i: NDArray[np.float64], c_j: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Return (points (K, 3), ok (K,)) of the midpoint method for rays c + s d (K pairs); see the public function."""
    b = c_j - c_i
    a11 = np.einsum("ki,ki->k", d_i, d_i)
    a22 = np.einsum("ki,ki->k", d_j, d_j)
    a12 = -np.einsum("ki,ki->k", d_i, d_j)
    rhs_i = np.einsum("ki,ki->k", d_i, b)
    rhs_j = -np.einsum("ki,ki->k", d_j, b)
    det = a11 * a22 - a12 * a12  # = |d_i x d_j|^2
    ok = det > 1e-12 * a11 * a22  # rays not parallel to within ~1e-6 rad
    det = np.where(ok, det, 1.0)
    s_i = (a22 * rhs_i - a12 * rhs_j) / det  # Cramer's rule on the 2x2 normal equations
    s_j = (a11 * rhs_j - a12 * rhs_i) / det
    ok &= (s_i > 0.0) & (s_j > 0.0)
    mid = 0.5 * ((c_i + s_i[:, None] * d_i) + (c_j + s_j[:, None] * d_j))
    return np.where(ok[:, None], mid, c_i + d_i), ok


def triangulate_two_view_initial(
    R_GtoC: ArrayLike,
    p_CinG: ArrayLike,
    obs_xy: ArrayLike,
    pair: tuple[int, int] | None = None,
) -> tuple[NDArray[np.float64], bool]:
    """Return (p_FinG (3,), ok): the midpoint of the closest points of two viewing rays, an initial guess.

    Args:
        R_GtoC: (M, 3, 3) rotations G -> C_i or (M, 4) JPL quaternions q_GtoC, M >= 2.
        p_CinG: (M, 3) camera centres in G.
        obs_xy: (M, 2) undistorted normalised coordinates (x, y) of the feature in each camera.
        pair: the two camera indices (i, j) to use; default: the first camera and the one farthest from it
            (the widest baseline of the track).

    Ray k: c_k + s_k d_k with c_k = p_CinG_k and d_k = R_GtoC_k^T [x_k, y_k, 1]^T, so s_k is the depth Z in camera k.
    Minimising |c_i + s_i d_i - c_j - s_j d_j|^2 gives the 2x2 normal equations (b = c_j - c_i)::

        [ d_i.d_i  -d_i.d_j ] [s_i]   [  d_i.b ]
        [-d_i.d_j   d_j.d_j ] [s_j] = [ -d_j.b ]       (determinant |d_i x d_j|^2)

    and p_FinG = ((c_i + s_i d_i) + (c_j + s_j d_j)) / 2 (the midpoint method; Hartley & Sturm 1997). ``ok`` is False
    for (nearly) parallel rays or a negative depth; p_FinG is then the point at unit depth on ray i.

    >>> R = np.stack([np.eye(3)] * 2); p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    >>> point, ok = triangulate_two_view_initial(R, p, [[0.1, 0.2], [-0.1, 0.2]])
    >>> np.round(point, 6).tolist(), ok
    ([0.5, 1.0, 5.0], True)
    """
    R, p = as_camera_poses(R_GtoC, p_CinG)
    n = R.shape[0]
    z = _observations(obs_xy, n)
    if n < 2:
        raise ValueError(f"obs_xy must hold at least 2 observations for two-view triangulation; got {n}")
    if pair is None:
        i = 0
        j = int(np.argmax(np.linalg.norm(p - p[0], axis=1)))
        j = j if j != 0 else n - 1
    else:
        if not isinstance(pair, Sequence) or len(pair) != 2:
            raise ValueError(f"pair must be two distinct camera indices (i, j); got {pair!r}")
        i, j = _index(pair[0], n, "pair[0]"), _index(pair[1], n, "pair[1]")
        if i == j:
            raise ValueError(f"pair must name two distinct cameras; got {pair!r}")
    rays = np.einsum("kji,kj->ki", R[[i, j]], np.column_stack([z[[i, j]], np.ones(2)]))  # d = R_GtoC^T [x, y, 1]
    point, ok = _midpoints(rays[:1], rays[1:], p[[i]], p[[j]])
    return point[0], bool(ok[0])


# ------------------------------------------------------------------------------------------- inverse-depth model


def _evaluate(
    theta: NDArray[np.float64],
    D: NDArray[np.float64],
    c: NDArray[np.float64],
    z: NDArray[np.float64],
    jacobian: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64]]:
    """Return (e (..., M, 2), J (..., M, 2, 3) or None, h3 (..., M)) at θ (..., 3); e = g - z, J = ∂g/∂θ.

    Thesis Eqs. 67 and 72-78.

    D (..., M, 3, 3) and c (..., M, 3) give h_i = D_i θ + c_i (Eqs. 62-64). Padded rows (D = 0, c = [0, 0, 1],
    z = 0) give e = 0, J = 0 and h3 = 1, so they add nothing.
    """
    h = np.einsum("...mij,...j->...mi", D, theta) + c  # h_i = R_AtoC_i [α, β, 1] + ρ p_AinC_i
    h3 = h[..., 2]
    safe = np.where(np.abs(h3) > _MIN_H3, h3, _MIN_H3)
    g = h[..., :2] / safe[..., None]  # g_i = [h_i1 / h_i3, h_i2 / h_i3]   (Eq. 67)
    if not jacobian:
        return g - z, None, h3
    # ∂g_ik/∂θ = (D_i[k, :] - g_ik D_i[2, :]) / h_i3                        (quotient rule, Eqs. 73-78)
    J = (D[..., :2, :] - g[..., None] * D[..., 2:3, :]) / safe[..., None, None]
    return g - z, J, h3


def _model_terms(
    R_AtoC: NDArray[np.float64], p_AinC: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return (D, c) with D_i = [r_i1, r_i2, p_AinC_i] and c_i = r_i3, so h_i = D_i θ + c_i (Eqs. 62-64)."""
    return np.concatenate([R_AtoC[..., :2], p_AinC[..., None]], axis=-1), R_AtoC[..., 2]


def _check_h3(h3: NDArray[np.float64]) -> None:
    if np.any(np.abs(h3) <= _MIN_H3):
        k = int(np.argmin(np.abs(h3)))
        raise ValueError(
            f"inverse_depth must put the feature off every camera's plane Z = 0 (|h_3| > {_MIN_H3:g}); "
            f"got h_3 = {h3[k]:.3g} in camera {k}"
        )


def triangulation_residual(
    inverse_depth: ArrayLike, R_AtoC: ArrayLike, p_AinC: ArrayLike, obs_xy: ArrayLike
) -> NDArray[np.float64]:
    """Return the stacked reprojection residual e (2M,) = [g_1 - z_1, ..., g_M - z_M] (x then y per camera).

    Args:
        inverse_depth: (3,) (α, β, ρ) = (X/Z, Y/Z, 1/Z) of the feature in the anchor camera A.
        R_AtoC: (M, 3, 3) rotations A -> C_i (from :func:`relative_to_anchor`).
        p_AinC: (M, 3) anchor centre in each C_i.
        obs_xy: (M, 2) measured undistorted normalised coordinates z_i.

    g_i is thesis Eq. 67. Raises ValueError where the point lies (nearly) in some camera's plane Z = 0.

    >>> R, p = relative_to_anchor(np.stack([np.eye(3)] * 2), [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    >>> np.round(triangulation_residual([0.1, 0.2, 0.2], R, p, [[0.1, 0.2], [-0.1, 0.2]]), 12) + 0.0
    array([0., 0., 0., 0.])
    """
    theta = _as_inverse_depth(inverse_depth)
    R, p = _as_relative_poses(R_AtoC, p_AinC)
    z = _observations(obs_xy, R.shape[0])
    e, _, h3 = _evaluate(theta, *_model_terms(R, p), z)
    _check_h3(h3)
    return e.reshape(-1)


def triangulation_jacobian(inverse_depth: ArrayLike, R_AtoC: ArrayLike, p_AinC: ArrayLike) -> NDArray[np.float64]:
    """Return the analytic Jacobian (2M, 3) of the residual e = g - z with respect to (α, β, ρ) (thesis Eqs. 72-78).

    Args:
        inverse_depth: (3,) (α, β, ρ) of the feature in the anchor camera A.
        R_AtoC: (M, 3, 3) rotations A -> C_i.
        p_AinC: (M, 3) anchor centre in each C_i.

    With h_i = R_AtoC_i [α, β, 1]^T + ρ p_AinC_i = D_i θ + r_i3 and g_i = (h_i1, h_i2) / h_i3 (quotient rule)::

        ∂g_ik/∂θ = D_i[k, :] / h_i3 - h_ik D_i[2, :] / h_i3^2,    D_i = [r_i1, r_i2, p_AinC_i]

    Rows 2i and 2i+1 are camera i's x and y. The measurement z does not depend on θ, so this is also ∂g/∂θ.

    >>> R, p = relative_to_anchor(np.stack([np.eye(3)] * 2), [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    >>> triangulation_jacobian([0.0, 0.0, 0.5], R, p).round(6).tolist()
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    """
    theta = _as_inverse_depth(inverse_depth)
    R, p = _as_relative_poses(R_AtoC, p_AinC)
    _, J, h3 = _evaluate(theta, *_model_terms(R, p), np.zeros((R.shape[0], 2)))
    _check_h3(h3)
    return J.reshape(-1, 3)


# ------------------------------------------------------------------------------------------- Levenberg-Marquardt


def _sym3_adjugate(A: NDArray[np.float64]) -> tuple[tuple[NDArray[np.float64], ...], NDArray[np.float64]]:
    """Return ((c00, c01, c02, c11, c12, c22), det A) of symmetric 3x3 matrices A (K, 3, 3): the cofactors of
    [[a, b, c], [b, d, e], [c, e, f]], i.e. the upper triangle of the symmetric adj(A), with A^-1 = adj(A) / det A."""
    a, bb, c = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
    d, e, f = A[:, 1, 1], A[:, 1, 2], A[:, 2, 2]
    c00, c01, c02 = d * f - e * e, c * e - bb * f, bb * e - c * d
    c11, c12, c22 = a * f - c * c, bb * c - a * e, a * d - bb * bb
    return (c00, c01, c02, c11, c12, c22), a * c00 + bb * c01 + c * c02


def _solve_sym3(A: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Return (x (K, 3), ok (K,)) solving the symmetric 3x3 systems A x = b by the adjugate (no exceptions)."""
    (c00, c01, c02, c11, c12, c22), det = _sym3_adjugate(A)
    ok = det > 1e-300
    inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    x = np.stack(
        [
            c00 * b[:, 0] + c01 * b[:, 1] + c02 * b[:, 2],
            c01 * b[:, 0] + c11 * b[:, 1] + c12 * b[:, 2],
            c02 * b[:, 0] + c12 * b[:, 1] + c22 * b[:, 2],
        ],
        axis=1,
    ) * inv_det[:, None]
    return x, ok & np.isfinite(x).all(axis=1)


def _sym3_inverse_diagonal(A: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return diag(A^-1) (K, 3) of symmetric 3x3 matrices A (K, 3, 3) by cofactors; inf where A is singular."""
    (c00, _, _, c11, _, c22), det = _sym3_adjugate(A)
    cof = np.column_stack([c00, c11, c22])
    scale = np.abs(A).max(axis=(1, 2))
    ok = det > 1e-12 * np.maximum(scale, 1e-300) ** 3
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok[:, None], cof / np.where(ok, det, 1.0)[:, None], np.inf)


def _levenberg_marquardt(
    theta: NDArray[np.float64],
    D: NDArray[np.float64],
    c: NDArray[np.float64],
    z: NDArray[np.float64],
    max_iterations: int,
    step_tol: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:
    """Return (θ (K, 3), e (K, M, 2), h3 (K, M), iterations (K,), converged (K,)) minimising Σ_i |g_i(θ) - z_i|^2.

    Every feature k has its own damping λ_k: solve (H + λ diag H) Δ = -b (Eq. 68 with b = J^T e of Eq. 70), accept
    when the cost does not grow and no camera sees the point behind it (λ /= 10), else reject (λ *= 10).
    Converged when an accepted step (or a rejected, nearly undamped one) is shorter than step_tol.
    """
    K = theta.shape[0]
    e, J, h3 = _evaluate(theta, D, c, z)
    cost = np.where((h3 > _MIN_H3).all(axis=1), np.einsum("kmi,kmi->k", e, e), np.inf)
    lam = np.full(K, _LAMBDA0)
    iterations = np.zeros(K, dtype=np.int64)
    converged = np.zeros(K, dtype=bool)
    active = np.ones(K, dtype=bool)
    for it in range(max_iterations):
        if not active.any():
            break
        iterations += active
        if it:
            e, J, h3 = _evaluate(theta, D, c, z)
        Jf = J.reshape(K, -1, 3)
        JfT = np.swapaxes(Jf, 1, 2)
        H = JfT @ Jf  # H = Σ_i J_i^T Ω J_i   (Eq. 69; Ω = σ^-2 I cancels)
        b = (JfT @ e.reshape(K, -1, 1))[..., 0]  # b = Σ_i J_i^T Ω e_i     (Eq. 70)
        damped = H + (lam[:, None] * np.diagonal(H, axis1=1, axis2=2) + 1e-15)[:, :, None] * np.eye(3)
        neg_delta, solvable = _solve_sym3(damped, b)  # (H + λ diag H) Δθ = -b
        trial = theta - neg_delta
        e_new, _, h3_new = _evaluate(trial, D, c, z, jacobian=False)
        cost_new = np.where((h3_new > _MIN_H3).all(axis=1), np.einsum("kmi,kmi->k", e_new, e_new), np.inf)
        accept = active & solvable & np.isfinite(cost_new) & (cost_new <= cost)
        theta = np.where(accept[:, None], trial, theta)
        cost = np.where(accept, cost_new, cost)
        small = solvable & (np.sqrt(np.einsum("ki,ki->k", neg_delta, neg_delta)) < step_tol)
        # converged: a short accepted step, or a short rejected one that was nearly Gauss-Newton (λ <= 1), i.e.
        # at the minimum up to rounding (a step made short only by heavy damping does not count)
        done = active & small & np.isfinite(cost) & (accept | (lam <= 1.0))
        lam = np.where(accept, np.maximum(lam * 0.1, _LAMBDA_MIN), lam * 10.0)
        converged |= done
        active &= ~done & solvable & (lam <= _LAMBDA_MAX)
    e, _, h3 = _evaluate(theta, D, c, z, jacobian=False)
    return theta, e, h3, iterations, converged


# ------------------------------------------------------------------------------------------- public triangulation


def _track_arrays(
    tracks: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike]],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Return the concatenated (R (T, 3, 3), p (T, 3), z (T, 2)) of all tracks and their lengths (K,)."""
    Rs, ps, zs, lengths = [], [], [], []
    for k, track in enumerate(tracks):
        if not isinstance(track, Sequence) or len(track) != 3:
            raise ValueError(f"tracks[{k}] must be a tuple (R_GtoC, p_CinG, obs_xy); got {type(track).__name__}")
        R = _rotations(track[0], f"tracks[{k}][0] (R_GtoC)")
        Rs.append(R)
        ps.append(_positions(track[1], R.shape[0], f"tracks[{k}][1] (p_CinG)"))
        zs.append(_observations(track[2], R.shape[0], f"tracks[{k}][2] (obs_xy)"))
        lengths.append(R.shape[0])
    if not Rs:
        return np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    R_all = np.concatenate(Rs)
    try:
        _check_rotations(R_all, "R_GtoC")
    except ValueError:
        for k, R in enumerate(Rs):
            _check_rotations(R, f"tracks[{k}][0] (R_GtoC)")
        raise
    return R_all, np.concatenate(ps), np.concatenate(zs), np.asarray(lengths, dtype=np.int64)


def _triangulate(
    R: NDArray[np.float64],
    p: NDArray[np.float64],
    z: NDArray[np.float64],
    lengths: NDArray[np.int64],
    anchor: int,
    initial: NDArray[np.float64] | None,
    max_iterations: int,
    step_tol: float,
    min_baseline_ratio: float,
    min_depth: float,
    max_depth: float,
    max_rms_residual: float,
) -> list[TriangulationResult]:
    """Triangulate K features whose observations are stacked in R, p, z with the given track lengths: set up the
    padded problem, guess, solve (Levenberg-Marquardt), check, report."""
    K = lengths.shape[0]
    if K == 0:
        return []
    prob = _padded_problem(R, p, z, lengths, anchor)
    theta0 = _initial_guess(prob, R, p, initial, min_baseline_ratio)
    theta, e, h3, iterations, reason = _solve(prob, theta0, max_iterations, step_tol)
    rho, positive, ratio, per_obs, cost, rms, reason = _check(prob, theta, e, h3, reason, min_baseline_ratio,
                                                              min_depth, max_depth, max_rms_residual)
    return _results(prob, theta, positive, rho, ratio, per_obs, cost, rms, iterations, reason)


@dataclass(frozen=True, eq=False)
class _Problem:
    """K features' observations scattered into padded (K, M) arrays, relative to each feature's anchor camera A.

    Pads: D = 0, c = [0, 0, 1], z = 0, dist = -1."""

    lengths: NDArray[np.int64]  # (K,) observations per feature
    starts: NDArray[np.int64]  # (K,) first stacked row of each feature
    anchors: NDArray[np.int64]  # (K,) anchor index within each track
    R_GtoA: NDArray[np.float64]  # (K, 3, 3)
    p_AinG: NDArray[np.float64]  # (K, 3)
    D: NDArray[np.float64]  # (K, M, 3, 3) and c (K, M, 3): the measurement model's terms (Eq. 59)
    c: NDArray[np.float64]
    zp: NDArray[np.float64]  # (K, M, 2) observations
    partner: NDArray[np.int64]  # (K,) the observation farthest from the anchor
    max_baseline: NDArray[np.float64]  # (K,) |p_CinG_i - p_AinG| at most


def _padded_problem(R: NDArray[np.float64], p: NDArray[np.float64], z: NDArray[np.float64],
                    lengths: NDArray[np.int64], anchor: int) -> _Problem:
    """Return the relative poses of each track to its anchor (Eq. 59) and its observations as padded arrays."""
    K = lengths.shape[0]
    M = max(int(lengths.max()), 1)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    row_k = np.repeat(np.arange(K), lengths)  # feature of each stacked observation
    row_j = np.arange(row_k.shape[0]) - starts[row_k]  # position within its track
    anchors = np.where(lengths > 0, anchor % np.maximum(lengths, 1), 0)
    a_glob = np.minimum(starts + anchors, max(R.shape[0] - 1, 0))
    R_GtoA = R[a_glob] if R.shape[0] else np.broadcast_to(np.eye(3), (K, 3, 3))
    p_AinG = p[a_glob] if R.shape[0] else np.zeros((K, 3))

    # relative poses (Eq. 59), scattered into padded (K, M) arrays; pads: D = 0, c = [0, 0, 1], z = 0
    R_AtoC = R @ np.swapaxes(R_GtoA[row_k], 1, 2)  # R_AtoC_i = R_GtoC_i R_GtoA^T
    p_AinC = np.einsum("mij,mj->mi", R, p_AinG[row_k] - p)  # p_AinC_i = R_GtoC_i (p_AinG - p_CinG_i)
    D_flat, c_flat = _model_terms(R_AtoC, p_AinC)
    D = np.zeros((K, M, 3, 3))
    D[row_k, row_j] = D_flat
    c = np.zeros((K, M, 3))
    c[..., 2] = 1.0
    c[row_k, row_j] = c_flat
    zp = np.zeros((K, M, 2))
    zp[row_k, row_j] = z
    dist = np.full((K, M), -1.0)
    dist[row_k, row_j] = np.linalg.norm(p - p_AinG[row_k], axis=1)  # |p_CinG_i - p_AinG|
    partner = np.argmax(dist, axis=1)
    max_baseline = np.maximum(dist.max(axis=1), 0.0)
    return _Problem(lengths, starts, anchors, R_GtoA, p_AinG, D, c, zp, partner, max_baseline)


def _initial_guess(prob: _Problem, R: NDArray[np.float64], p: NDArray[np.float64],
                   initial: NDArray[np.float64] | None, min_baseline_ratio: float) -> NDArray[np.float64]:
    """Return θ0 (K, 3) = (X/Z, Y/Z, 1/Z) of p_FinA = R_GtoA (p_FinG - p_AinG): of ``initial`` (K, 3) points in G,
    else of the midpoint of the anchor's and the partner's rays; where that is unusable (behind the anchor), the
    anchor's own ray at the farthest depth the baseline check still accepts."""
    K = prob.lengths.shape[0]
    R_GtoA, p_AinG, zp, anchors = prob.R_GtoA, prob.p_AinG, prob.zp, prob.anchors
    if initial is None:
        j_glob = np.minimum(prob.starts + prob.partner, max(R.shape[0] - 1, 0))
        z_a = np.column_stack([zp[np.arange(K), anchors], np.ones(K)])
        z_b = np.column_stack([zp[np.arange(K), prob.partner], np.ones(K)])
        d_a = np.einsum("kji,kj->ki", R_GtoA, z_a)  # ray directions d = R_GtoC^T [x, y, 1]
        d_b = np.einsum("kji,kj->ki", R[j_glob], z_b) if R.shape[0] else d_a
        guess, ok = _midpoints(d_a, d_b, p_AinG, p[j_glob] if R.shape[0] else p_AinG)
    else:
        guess, ok = initial, np.ones(K, dtype=bool)
    p_FinA = np.einsum("kij,kj->ki", R_GtoA, guess - p_AinG)
    ok &= p_FinA[:, 2] > 0.0
    Z0 = np.where(ok, p_FinA[:, 2], 1.0)
    # no usable guess: the anchor's own ray at the farthest depth the baseline check still accepts
    fallback_depth = np.maximum(prob.max_baseline, _MIN_BASELINE) / max(min_baseline_ratio, 1e-3)
    z_anchor = zp[np.arange(K), anchors]
    return np.where(
        ok[:, None],
        np.column_stack([p_FinA[:, 0] / Z0, p_FinA[:, 1] / Z0, 1.0 / Z0]),
        np.column_stack([z_anchor, 1.0 / fallback_depth]),
    )


def _solve(
    prob: _Problem, theta0: NDArray[np.float64], max_iterations: int, step_tol: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Return (θ (K, 3), e (K, M, 2), h3 (K, M), iterations (K,), reason (K,)): Levenberg-Marquardt from θ0 for the
    features with >= 2 observations and a baseline; the others keep θ0 with ρ = 0 and their reason code."""
    lengths, D, c, zp = prob.lengths, prob.D, prob.c, prob.zp
    K, M = zp.shape[:2]
    reason = np.full(K, _OK)
    reason[prob.max_baseline < _MIN_BASELINE] = _BASELINE
    reason[lengths < 2] = _TOO_FEW
    solve = np.flatnonzero(reason == _OK)
    theta = theta0.copy()
    theta[reason != _OK, 2] = 0.0
    e = np.zeros((K, M, 2))
    h3 = np.ones((K, M))
    iterations = np.zeros(K, dtype=np.int64)
    if solve.size:
        t, ee, hh, it, conv = _levenberg_marquardt(
            theta0[solve], D[solve], c[solve], zp[solve], max_iterations, step_tol
        )
        theta[solve], e[solve], h3[solve], iterations[solve] = t, ee, hh, it
        reason[solve[~conv]] = _NOT_CONVERGED
    return theta, e, h3, iterations, reason


def _check(
    prob: _Problem, theta: NDArray[np.float64], e: NDArray[np.float64], h3: NDArray[np.float64],
    reason: NDArray[np.int64], min_baseline_ratio: float, min_depth: float, max_depth: float,
    max_rms_residual: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.float64], NDArray[np.int64]]:
    """Return (ρ, ρ > 0, max baseline / Z_A, |residual| per observation (K, M), cost, RMS, reason): the first
    failed check of each feature (behind a camera, too close, too far, too little baseline, too large a residual)
    becomes its reason."""
    lengths = prob.lengths
    rho = theta[:, 2]
    positive = rho > 0.0
    rho_safe = np.where(positive, rho, 1.0)
    depths = np.where(positive[:, None], h3 / rho_safe[:, None], -1.0)  # Z_i = Z_A h_i3 (pads: Z_A)
    ratio = np.where(positive, prob.max_baseline * rho, 0.0)  # max baseline / Z_A
    per_obs = np.sqrt(np.einsum("kmi,kmi->km", e, e))  # |g_i - z_i| (pads: 0)
    cost = np.einsum("km,km->k", per_obs, per_obs)
    rms = np.sqrt(cost / np.maximum(lengths, 1))
    checks = (
        (_BEHIND, ~positive | (depths <= 0.0).any(axis=1)),
        (_TOO_CLOSE, (depths < min_depth).any(axis=1)),
        (_TOO_FAR, (depths > max_depth).any(axis=1)),
        (_BASELINE, ratio < min_baseline_ratio),
        (_RESIDUAL, rms > max_rms_residual),
    )
    for code, failed in checks:
        reason = np.where((reason == _OK) & failed, code, reason)
    return rho, positive, ratio, per_obs, cost, rms, reason


def _results(
    prob: _Problem, theta: NDArray[np.float64], positive: NDArray[np.bool_], rho: NDArray[np.float64],
    ratio: NDArray[np.float64], per_obs: NDArray[np.float64], cost: NDArray[np.float64], rms: NDArray[np.float64],
    iterations: NDArray[np.int64], reason: NDArray[np.int64],
) -> list[TriangulationResult]:
    """Return one TriangulationResult per feature: the point in G (Eq. 79) and the standard deviations of θ."""
    K = theta.shape[0]
    R_GtoA, p_AinG = prob.R_GtoA, prob.p_AinG
    rho_safe = np.where(positive, rho, 1.0)
    # standard deviations of θ per unit noise: sqrt(diag((J^T J)^-1)) at the estimate (Ω = σ^-2 I, Eq. 71)
    _, J_end, _ = _evaluate(theta, prob.D, prob.c, prob.zp)
    J_end = J_end.reshape(K, -1, 3)
    theta_std = np.sqrt(np.maximum(_sym3_inverse_diagonal(np.swapaxes(J_end, 1, 2) @ J_end), 0.0))

    # p_FinG = R_GtoA^T [α, β, 1]^T / ρ + p_AinG      (Eq. 79); the anchor centre where ρ <= 0
    bearing = np.column_stack([theta[:, :2], np.ones(K)])
    p_FinG = np.einsum("kji,kj->ki", R_GtoA, bearing) / rho_safe[:, None] + p_AinG
    p_FinG = np.where(positive[:, None] & np.isfinite(p_FinG).all(axis=1)[:, None], p_FinG, p_AinG)
    p_FinG[prob.lengths == 0] = 0.0  # no camera at all: nothing better than the origin
    worst = per_obs.max(axis=1)
    return [
        TriangulationResult(
            p_FinG=p_FinG[k],
            success=bool(reason[k] == _OK),
            reason=TRIANGULATION_REASONS[reason[k]],
            iterations=int(iterations[k]),
            cost=float(cost[k]),
            rms_residual=float(rms[k]),
            max_residual=float(worst[k]),
            inverse_depth=theta[k],
            anchor=int(prob.anchors[k]),
            baseline_ratio=float(ratio[k]),
            inverse_depth_std=theta_std[k],
        )
        for k in range(K)
    ]


def _settings(
    anchor: int,
    max_iterations: int,
    step_tol: float,
    min_baseline_ratio: float,
    min_depth: float,
    max_depth: float,
    max_rms_residual: float,
) -> dict:
    if isinstance(anchor, bool) or not isinstance(anchor, Integral):
        raise ValueError(f"anchor must be an integer camera index (negative counts from the end); got {anchor!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, Integral) or max_iterations < 1:
        raise ValueError(f"max_iterations must be a positive integer; got {max_iterations!r}")
    settings = dict(
        max_iterations=int(max_iterations),
        step_tol=_number(step_tol, "step_tol"),
        min_baseline_ratio=_number(min_baseline_ratio, "min_baseline_ratio", strict=False),
        min_depth=_number(min_depth, "min_depth", strict=False),
        max_depth=_number(max_depth, "max_depth"),
        max_rms_residual=_number(max_rms_residual, "max_rms_residual"),
    )
    if not settings["max_depth"] > settings["min_depth"]:
        raise ValueError(f"max_depth must exceed min_depth ({settings['min_depth']:g}); got {settings['max_depth']:g}")
    return settings


def _check_anchor(anchor: int, lengths: NDArray[np.int64]) -> None:
    used = lengths[lengths > 0]
    if used.size and not -int(used.min()) <= int(anchor) < int(used.min()):
        shortest = int(used.min())
        raise ValueError(
            f"anchor must index every track (-{shortest} <= anchor < {shortest}, the shortest track); got {anchor}"
        )


def triangulate_inverse_depth(
    R_GtoC: ArrayLike,
    p_CinG: ArrayLike,
    obs_xy: ArrayLike,
    *,
    anchor: int = 0,
    initial_p_FinG: ArrayLike | None = None,
    max_iterations: int = 10,
    step_tol: float = 1e-7,
    min_baseline_ratio: float = 0.002,
    min_depth: float = 0.1,
    max_depth: float = 1000.0,
    max_rms_residual: float = 0.025,
) -> TriangulationResult:
    """Return a :class:`TriangulationResult`: the feature's position in G by inverse-depth least squares, or why not.

    Args:
        R_GtoC: (M, 3, 3) rotations G -> C_i of the observing cameras, or (M, 4) JPL quaternions q_GtoC.
        p_CinG: (M, 3) camera centres in G (metres).
        obs_xy: (M, 2) undistorted normalised coordinates (x, y) of the feature in each camera.
        anchor: index of the anchor camera A holding the inverse-depth parameters (thesis: the first observation).
        initial_p_FinG: (3,) starting point in G (e.g. a previous estimate); default: the two-view midpoint of the
            anchor and the camera farthest from it (:func:`triangulate_two_view_initial`).
        max_iterations: Levenberg-Marquardt iterations allowed (accepted or rejected steps).
        step_tol: converged when |Δ(α, β, ρ)| < step_tol (thesis: "once the increments fall below a threshold").
        min_baseline_ratio: reject when max_i |p_CinG_i - p_AinG| / Z_A is below this (too little parallax).
        min_depth, max_depth: accepted range (metres) of the feature's depth Z in every camera.
        max_rms_residual: reject when the RMS reprojection error sqrt(Σ_i |g_i - z_i|^2 / M) exceeds this
            (normalised units: pixels / focal length; 0.025 is 5 px at f = 200 px).

    The checks, in order (the first failure is the ``reason``): at least 2 observations and two distinct camera
    centres; convergence; depth Z > 0, >= min_depth and <= max_depth in every camera; baseline ratio; residuals.
    Reference: thesis §3.3.7, Eqs. 59-79; Civera, Davison & Montiel, "Inverse depth parametrization for monocular
    SLAM", IEEE T-RO 2008.

    >>> R = np.stack([np.eye(3)] * 3)
    >>> p = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.1, 0.0]])
    >>> point = np.array([0.3, -0.2, 4.0])
    >>> obs = (point - p)[:, :2] / (point - p)[:, 2:]
    >>> result = triangulate_inverse_depth(R, p, obs)
    >>> result.success, result.reason, np.round(result.p_FinG, 6).tolist()
    (True, 'ok', [0.3, -0.2, 4.0])
    """
    settings = _settings(anchor, max_iterations, step_tol, min_baseline_ratio, min_depth, max_depth, max_rms_residual)
    R, p = as_camera_poses(R_GtoC, p_CinG)
    z = _observations(obs_xy, R.shape[0])
    lengths = np.array([R.shape[0]], dtype=np.int64)
    _check_anchor(anchor, lengths)
    initial = None
    if initial_p_FinG is not None:
        initial = _float_array(initial_p_FinG, "initial_p_FinG", "(3,)")
        if initial.shape != (3,):
            raise ValueError(f"initial_p_FinG must have shape (3,); got {initial.shape}")
        _require_finite(initial, "initial_p_FinG")
        initial = initial[None, :]
    return _triangulate(R, p, z, lengths, int(anchor), initial, **settings)[0]


def triangulate_inverse_depth_batch(
    tracks: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike]],
    *,
    anchor: int = 0,
    initial_p_FinG: ArrayLike | None = None,
    max_iterations: int = 10,
    step_tol: float = 1e-7,
    min_baseline_ratio: float = 0.002,
    min_depth: float = 0.1,
    max_depth: float = 1000.0,
    max_rms_residual: float = 0.025,
) -> list[TriangulationResult]:
    """Return one :class:`TriangulationResult` per track, all solved together (vectorised over features).

    Args:
        tracks: K tuples (R_GtoC (M_k, 3, 3) or q_GtoC (M_k, 4), p_CinG (M_k, 3), obs_xy (M_k, 2)), one per
            feature, as for :func:`triangulate_inverse_depth`; the lengths M_k may differ.
        anchor: camera index within each track used as the anchor (must be valid for the shortest track).
        initial_p_FinG: (K, 3) starting points in G, or None for the two-view midpoints.
        max_iterations, step_tol, min_baseline_ratio, min_depth, max_depth, max_rms_residual: as for
            :func:`triangulate_inverse_depth`.

    Gives the same results as calling :func:`triangulate_inverse_depth` on each track (each feature keeps its own
    damping and stops on its own), in far less time for many features. Reference: thesis §3.3.7, Eqs. 59-79.

    >>> R = np.stack([np.eye(3)] * 2); p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    >>> results = triangulate_inverse_depth_batch([(R, p, [[0.1, 0.2], [-0.1, 0.2]]), (R[:1], p[:1], [[0.0, 0.0]])])
    >>> [(r.reason, np.round(r.p_FinG, 6).tolist()) for r in results]
    [('ok', [0.5, 1.0, 5.0]), ('too_few_observations', [0.0, 0.0, 0.0])]
    """
    settings = _settings(anchor, max_iterations, step_tol, min_baseline_ratio, min_depth, max_depth, max_rms_residual)
    if not isinstance(tracks, Sequence):
        raise ValueError(f"tracks must be a sequence of (R_GtoC, p_CinG, obs_xy) tuples; got {type(tracks).__name__}")
    R, p, z, lengths = _track_arrays(tracks)
    _check_anchor(anchor, lengths)
    initial = None
    if initial_p_FinG is not None:
        initial = _float_array(initial_p_FinG, "initial_p_FinG", "(K, 3)")
        if initial.shape != (lengths.shape[0], 3):
            raise ValueError(f"initial_p_FinG must have shape ({lengths.shape[0]}, 3), one row per track; "
                             f"got {initial.shape}")
        _require_finite(initial, "initial_p_FinG")
    return _triangulate(R, p, z, lengths, int(anchor), initial, **settings)
