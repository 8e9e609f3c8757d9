"""Smooth 6-DoF ground-truth trajectories of the IMU frame I in the world G, with exactly consistent derivatives.

A trajectory is built from scalar *signals*: each signal returns its value and its first derivatives, all in closed
form (polynomials, amplitude- and frequency-modulated sinusoids, clipped smoothsteps, B-splines evaluated with
their own derivative splines). Nothing is differentiated numerically, so velocity, acceleration, angular velocity
and angular acceleration are the exact derivatives of the positions and orientations.

Orientation is parametrised by ZYX Euler angles (yaw ψ, pitch θ, roll φ) of an intermediate "body" frame B,
followed by a constant mounting rotation::

    R_ItoG(t) = Rz(ψ) Ry(θ) Rx(φ) R_ItoB                                     (R_BtoG = Rz Ry Rx)
    w_B = [φ' - sinθ ψ', cosφ θ' + sinφ cosθ ψ', -sinφ θ' + cosφ cosθ ψ']   (R_BtoG^T dR_BtoG/dt = [w_B x])
    w_I = R_ItoB^T w_B                                                       (dR_ItoG/dt = R_ItoG [w_I x])

Presets (thesis §3.4): ``boxes_like`` (hand-held DAVIS shaken in front of textured boxes, RPG ``boxes_6dof``) and
``aerial_like`` (fixed-wing flight at 250 m altitude, camera looking down, one coordinated 90-degree turn, Camp
Atterbury flight test).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.polynomial import Polynomial
from numpy.polynomial.polynomial import polyval
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline, make_interp_spline

__all__ = [
    "TrajectorySample",
    "Trajectory",
    "EulerTrajectory",
    "TimeScaledTrajectory",
    "boxes_like",
    "aerial_like",
    "trajectory_from_preset",
    "PRESETS",
    "GRAVITY_MAGNITUDE",
]

GRAVITY_MAGNITUDE = 9.81  # m/s^2, |g_G| (project convention g_G = [0, 0, -9.81])
_T_TOL = 1e-9  # s, tolerance on query times outside [t_start, t_end]
_MAX_ORDER = 3  # highest derivative a public signal provides (angles need 3 for dw_I)


# --------------------------------------------------------------------------------------------------------------------
# Scalar signals: __call__(t (N,), order) -> (order + 1, N) array [f, f', f'', ...]
# --------------------------------------------------------------------------------------------------------------------
class _Signal(ABC):
    """A scalar function of time with closed-form derivatives."""

    @abstractmethod
    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        """Return (order + 1, N): the value and derivatives 1..order at times t (N,)."""


def _product(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the derivative stack of a*b from those of a and b (Leibniz: (ab)^(n) = sum C(n,k) a^(k) b^(n-k))."""
    out = np.zeros_like(a)
    for n in range(a.shape[0]):
        for k in range(n + 1):
            out[n] += math.comb(n, k) * a[k] * b[n - k]
    return out


def _compose(f: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return the derivative stack of f(u(t)), given f^(k)(u(t)) (k = 0..n) and u's stack (Faa di Bruno, n <= 3)."""
    n = u.shape[0] - 1
    if n > 3:
        raise ValueError(f"order must be <= 3 for a composition; got {n}")
    out = np.empty_like(u)
    out[0] = f[0]
    if n >= 1:
        out[1] = f[1] * u[1]  # (f∘u)' = f' u'
    if n >= 2:
        out[2] = f[2] * u[1] ** 2 + f[1] * u[2]  # (f∘u)'' = f'' u'^2 + f' u''
    if n >= 3:
        out[3] = f[3] * u[1] ** 3 + 3.0 * f[2] * u[1] * u[2] + f[1] * u[3]  # f''' u'^3 + 3 f'' u' u'' + f' u'''
    return out


class _PolyDerivatives:
    """A polynomial with its derivative coefficients computed once (evaluating is then a few Horner passes).

    Building ``Polynomial.deriv`` objects on every call dominated the cost of evaluating a trajectory at one time, which the
    event simulator does for every render.
    """

    def __init__(self, p: Polynomial) -> None:
        p = p.convert(kind=Polynomial, domain=[-1, 1], window=[-1, 1])  # plain power series in t
        self.coefs = [p.coef] + [p.deriv(k).coef for k in range(1, _MAX_ORDER + 2)]

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        """Return (order + 1, N): the polynomial and its derivatives 1..order at t."""
        return np.stack([polyval(t, self.coefs[k]) for k in range(order + 1)])


class _Poly(_Signal):
    """f(t) = polynomial in t."""

    def __init__(self, coef: Sequence[float]) -> None:
        self.p = _PolyDerivatives(Polynomial(np.asarray(coef, dtype=np.float64)))

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        return self.p(t, order)


class _Chirp(_Signal):
    """f(t) = A(t) sin(Φ(t)) with polynomial amplitude A and polynomial phase Φ (instantaneous freq. Φ'/(2π))."""

    def __init__(self, amplitude: Polynomial, phase: Polynomial) -> None:
        self.amplitude = _PolyDerivatives(amplitude)
        self.phase = _PolyDerivatives(phase)

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        phi = self.phase(t, order)
        s, c = np.sin(phi[0]), np.cos(phi[0])
        sin_derivs = np.stack([s, c, -s, -c, s][: order + 1])  # d^k sin(x)/dx^k
        g = _compose(sin_derivs, phi)  # sin(Φ(t)) and its time derivatives
        return _product(self.amplitude(t, order), g)  # A(t) sin(Φ(t))


class _Spline(_Signal):
    """f(t) = B-spline; derivatives are the spline's own derivative splines (exactly consistent)."""

    def __init__(self, spline: BSpline) -> None:
        self.splines = [spline] + [spline.derivative(k) for k in range(1, min(spline.k, _MAX_ORDER + 1) + 1)]

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        out = np.zeros((order + 1, t.shape[0]))
        for k in range(min(order, len(self.splines) - 1) + 1):
            out[k] = self.splines[k](t)
        return out


def _smoothstep_poly() -> tuple[Polynomial, Polynomial]:
    """Return (S, IS): the C4 smoothstep S(x) = 630 ∫_0^x s^4 (1-s)^4 ds on [0, 1] and its integral IS = ∫_0^x S."""
    bump = Polynomial([0.0, 1.0]) ** 4 * Polynomial([1.0, -1.0]) ** 4  # s^4 (1 - s)^4
    S = bump.integ()
    S = S / S(1.0)  # S(0) = 0, S(1) = 1, S^(k)(0) = S^(k)(1) = 0 for k = 1..4
    return S, S.integ()


_S, _IS = _smoothstep_poly()
_S_DERIVS = [_S.deriv(k) for k in range(1, _MAX_ORDER + 2)]  # S', S'', ... computed once, not per evaluation


class _RampIntegral(_Signal):
    """J(t) = ∫_{-inf}^t S((τ - t0) / T) dτ: 0 before t0, smooth C5 onset over [t0, t0 + T], then slope 1.

    J = T IS(x) for x = (t - t0)/T in [0, 1];  J = T IS(1) + (t - t0 - T) after;  J^(k) = S^(k-1)(x) / T^(k-1).
    Provides derivatives up to order 4 (the coordinated-turn bank needs the 4th derivative of the heading).
    """

    def __init__(self, t0: float, duration: float) -> None:
        self.t0 = float(t0)
        self.T = float(duration)

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        x = (t - self.t0) / self.T
        xc = np.clip(x, 0.0, 1.0)
        inside = (x > 0.0) & (x < 1.0)
        out = np.zeros((order + 1, t.shape[0]))
        # J = T IS(x) inside, T IS(1) + T (x - 1) after, 0 before
        out[0] = np.where(x >= 1.0, self.T * (_IS(1.0) + (x - 1.0)), self.T * _IS(xc))
        if order >= 1:
            out[1] = _S(xc)  # J' = S(x)  (0 before, 1 after)
        for k in range(2, order + 1):
            out[k] = np.where(inside, _S_DERIVS[k - 2](xc) / self.T ** (k - 1), 0.0)  # J^(k) = S^(k-1)(x) / T^(k-1)
        return out


class _Heading(_Signal):
    """ψ(t) = ψ0 + r [J_a(t) - J_b(t)]: constant, smooth roll into a turn at rate r, plateau, smooth roll out.

    ψ' = r [S(x_a) - S(x_b)] rises from 0 to r over [t_a, t_a + T] and falls back over [t_b, t_b + T];
    the total heading change is r (t_b - t_a).
    """

    def __init__(self, psi0: float, rate: float, t_a: float, t_b: float, ramp: float) -> None:
        self.psi0, self.rate = float(psi0), float(rate)
        self.ja, self.jb = _RampIntegral(t_a, ramp), _RampIntegral(t_b, ramp)

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        out = self.rate * (self.ja(t, order) - self.jb(t, order))
        out[0] += self.psi0
        return out


class _CoordinatedBank(_Signal):
    """φ(t) = -atan(V ψ'(t) / g): bank of a coordinated (no side-slip) level turn, body frame x fwd, y left, z up.

    The lift along body z must supply the centripetal acceleration V ψ' (to the left for ψ' > 0) and balance
    gravity: tan(bank) = V ψ' / g; with a right-handed roll about x (forward) a left bank is φ < 0.
    """

    def __init__(self, heading: _Heading, speed: float, gravity: float = GRAVITY_MAGNITUDE) -> None:
        self.heading, self.scale = heading, float(speed) / float(gravity)

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        if order > 3:
            raise ValueError(f"order must be <= 3; got {order}")
        u = self.scale * self.heading(t, order + 1)[1:]  # u = V ψ' / g and its derivatives
        h = 1.0 / (1.0 + u[0] ** 2)
        # d^k atan(u)/du^k: h, -2 u h^2, (6 u^2 - 2) h^3
        atan_derivs = np.stack([np.arctan(u[0]), h, -2.0 * u[0] * h**2, (6.0 * u[0] ** 2 - 2.0) * h**3][: order + 1])
        return -_compose(atan_derivs, u)


class _Sum(_Signal):
    """f(t) = sum of signals."""

    def __init__(self, *signals: _Signal) -> None:
        self.signals = signals

    def __call__(self, t: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        return sum(s(t, order) for s in self.signals)


# --------------------------------------------------------------------------------------------------------------------
# Trajectories
# --------------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrajectorySample:
    """Ground-truth IMU states at N query times (all arrays have leading dimension N).

    Attributes:
        t: (N,) times, s.
        p_IinG: (N, 3) IMU position in G, m.
        v_IinG: (N, 3) velocity d p_IinG/dt in G, m/s.
        a_IinG: (N, 3) acceleration d v_IinG/dt in G (kinematic, gravity not included), m/s^2.
        R_ItoG: (N, 3, 3) IMU orientation (v_G = R_ItoG @ v_I).
        w_I: (N, 3) angular velocity of I in I, rad/s (dR_ItoG/dt = R_ItoG [w_I x]).
        dw_I: (N, 3) angular acceleration d w_I/dt in I, rad/s^2.
    """

    t: NDArray[np.float64]
    p_IinG: NDArray[np.float64]
    v_IinG: NDArray[np.float64]
    a_IinG: NDArray[np.float64]
    R_ItoG: NDArray[np.float64]
    w_I: NDArray[np.float64]
    dw_I: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.t.shape[0])


class Trajectory(ABC):
    """A smooth (C2 or better) trajectory of the IMU frame I in G on [t_start, t_end]."""

    t_start: float
    t_end: float
    name: str = "trajectory"

    @property
    def duration(self) -> float:
        """Return t_end - t_start, seconds."""
        return self.t_end - self.t_start

    def _check_times(self, t: float | ArrayLike) -> NDArray[np.float64]:
        """Return t as a float64 (N,) array inside [t_start, t_end]; raise ValueError otherwise."""
        arr = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if arr.ndim != 1:
            raise ValueError(f"t must be a float or an array of shape (N,); got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("t must contain only finite times (no NaN/inf)")
        if arr.size and (arr.min() < self.t_start - _T_TOL or arr.max() > self.t_end + _T_TOL):
            raise ValueError(
                f"t must lie in [t_start, t_end] = [{self.t_start:g}, {self.t_end:g}] s; "
                f"got values in [{arr.min():g}, {arr.max():g}]"
            )
        return arr

    @abstractmethod
    def evaluate(self, t: float | ArrayLike) -> TrajectorySample:
        """Return the exact states at time(s) t (float or (N,) array, seconds, inside [t_start, t_end])."""


def _rot_x(a: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _rot_y(a: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _rot_z(a: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


class EulerTrajectory(Trajectory):
    """Trajectory from three position signals and ZYX Euler-angle signals of a body frame B, plus a fixed mount.

    p_IinG(t) = [x(t), y(t), z(t)];  R_ItoG(t) = Rz(ψ) Ry(θ) Rx(φ) @ R_ItoB  (see the module docstring for w_I).
    Built by the presets; signals are private closed-form functions of time.
    """

    def __init__(
        self,
        position: Sequence[_Signal],
        yaw: _Signal,
        pitch: _Signal,
        roll: _Signal,
        R_ItoB: ArrayLike,
        t_start: float,
        t_end: float,
        name: str = "trajectory",
    ) -> None:
        if len(position) != 3:
            raise ValueError(f"position must hold 3 signals (x, y, z); got {len(position)}")
        if not (np.isfinite(t_start) and np.isfinite(t_end) and t_end > t_start):
            raise ValueError(f"t_end must be > t_start (finite); got t_start={t_start}, t_end={t_end}")
        self.position = tuple(position)
        self.yaw, self.pitch, self.roll = yaw, pitch, roll
        self.R_ItoB = np.array(R_ItoB, dtype=np.float64)
        self.t_start, self.t_end, self.name = float(t_start), float(t_end), name

    def evaluate(self, t: float | ArrayLike) -> TrajectorySample:
        """Return the exact states (TrajectorySample, leading dimension N) at time(s) t (float or (N,), s)."""
        t = self._check_times(t)
        pos = np.stack([s(t, 2) for s in self.position], axis=-1)  # (3, N, 3): p, v, a
        psi, th, ph = self.yaw(t, 3), self.pitch(t, 3), self.roll(t, 3)  # (4, N) each: angle, rate, acc, jerk
        R_BtoG = _rot_z(psi[0]) @ _rot_y(th[0]) @ _rot_x(ph[0])  # R_BtoG = Rz(ψ) Ry(θ) Rx(φ)
        sps, cps = np.sin(ph[0]), np.cos(ph[0])  # sin φ, cos φ
        sth, cth = np.sin(th[0]), np.cos(th[0])  # sin θ, cos θ
        # w_B = [φ' - sθ ψ',  cφ θ' + sφ cθ ψ',  -sφ θ' + cφ cθ ψ']
        w_B = np.stack(
            [
                ph[1] - sth * psi[1],
                cps * th[1] + sps * cth * psi[1],
                -sps * th[1] + cps * cth * psi[1],
            ],
            axis=-1,
        )
        # dw_B/dt, differentiating each line above by the product rule
        dw_B = np.stack(
            [
                ph[2] - cth * th[1] * psi[1] - sth * psi[2],
                -sps * ph[1] * th[1] + cps * th[2]
                + cps * ph[1] * cth * psi[1] - sps * sth * th[1] * psi[1] + sps * cth * psi[2],
                -cps * ph[1] * th[1] - sps * th[2]
                - sps * ph[1] * cth * psi[1] - cps * sth * th[1] * psi[1] + cps * cth * psi[2],
            ],
            axis=-1,
        )
        # R_ItoG = R_BtoG R_ItoB ;  w_I = R_ItoB^T w_B  (row vectors: w_B @ R_ItoB)
        return TrajectorySample(
            t=t,
            p_IinG=pos[0],
            v_IinG=pos[1],
            a_IinG=pos[2],
            R_ItoG=R_BtoG @ self.R_ItoB,
            w_I=w_B @ self.R_ItoB,
            dw_I=dw_B @ self.R_ItoB,
        )


class TimeScaledTrajectory(Trajectory):
    """Another trajectory played ``speed`` times faster: the same path and attitudes, in 1/speed of the time.

    With the base trajectory b on [t0, t1] and s = ``speed``, this one is defined on [t0/s, t1/s] by

        p(t) = p_b(s t),  R(t) = R_b(s t),  v(t) = s v_b(s t),  a(t) = s^2 a_b(s t),
        w_I(t) = s w_b(s t),  dw_I(t) = s^2 dw_b(s t)                          (chain rule, d/dt = s d/d(st))

    so speeds and angular rates grow by s and accelerations by s^2 (s = 2 turns the violent end of ``boxes_like``,
    about 1.6-1.8 m/s and 2.4-2.6 rad/s on average over its last 10 s, into 3.1-3.6 m/s and 4.7-5.2 rad/s over
    5 s). The specific force an accelerometer reads, a - g, grows less than s^2 where gravity dominates it.

    >>> fast = TimeScaledTrajectory(boxes_like(duration=60.0, seed=0), 2.0)
    >>> fast.t_end, bool(np.allclose(fast.evaluate(10.0).v_IinG, 2 * boxes_like(seed=0).evaluate(20.0).v_IinG))
    (30.0, True)
    """

    def __init__(self, base: Trajectory, speed: float) -> None:
        if isinstance(speed, bool) or not isinstance(speed, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a finite number > 0 (how many times faster the motion is played); "
                             f"got {speed!r}")
        self.base, self.speed = base, float(speed)
        self.t_start, self.t_end = base.t_start / self.speed, base.t_end / self.speed
        self.name = base.name

    def evaluate(self, t: float | ArrayLike) -> TrajectorySample:
        """Return the states at time(s) t of this clock: the base's at speed * t, with the derivatives scaled."""
        t = self._check_times(t)
        s = self.speed
        b = self.base.evaluate(np.clip(s * t, self.base.t_start, self.base.t_end))  # clip: the tolerance at the ends
        return TrajectorySample(t=t, p_IinG=b.p_IinG, v_IinG=s * b.v_IinG, a_IinG=s * s * b.a_IinG, R_ItoG=b.R_ItoG,
                                w_I=s * b.w_I, dw_I=s * s * b.dw_I)


# --------------------------------------------------------------------------------------------------------------------
# Presets
# --------------------------------------------------------------------------------------------------------------------
def _check_duration(duration: float, minimum: float) -> float:
    if not isinstance(duration, (int, float, np.floating, np.integer)) or not np.isfinite(duration):
        raise ValueError(f"duration must be a finite number of seconds >= {minimum:g}; got {duration!r}")
    if duration < minimum:
        raise ValueError(f"duration must be >= {minimum:g} s; got {duration:g}")
    return float(duration)


def _ramped_chirp(
    rng: np.random.Generator, duration: float, amp0: float, amp1: float, f0: float, f1: float
) -> _Chirp:
    """Return A(t) sin(Φ(t)) whose amplitude and frequency grow quadratically in s = t / duration.

    A(t) = amp0 + (amp1 - amp0) s^2;  f(t) = f0 + (f1 - f0) s^2;
    Φ(t) = φ0 + 2π ∫_0^t f = φ0 + 2π (f0 t + (f1 - f0) t^3 / (3 D^2)).
    """
    D2 = duration**2
    phase0 = rng.uniform(0.0, 2.0 * np.pi)
    amplitude = Polynomial([amp0, 0.0, (amp1 - amp0) / D2])
    phase = Polynomial([phase0, 2.0 * np.pi * f0, 0.0, 2.0 * np.pi * (f1 - f0) / (3.0 * D2)])
    return _Chirp(amplitude, phase)


def _shaking_axis(rng: np.random.Generator, duration: float, amp0: float, amp1: float, f0: float, f1: float) -> _Sum:
    """Return the sum of two ramped chirps with seeded frequency ratios: a main one and a faster, weaker one."""
    m1 = rng.uniform(0.8, 1.2)  # main component frequency factor
    m2 = rng.uniform(1.6, 2.2)  # second component frequency factor
    return _Sum(
        _ramped_chirp(rng, duration, 0.75 * amp0, 0.75 * amp1, m1 * f0, m1 * f1),
        _ramped_chirp(rng, duration, 0.25 * amp0, 0.25 * amp1, m2 * f0, m2 * f1),
    )


# B = G axes at zero angles; the IMU (≈ camera) looks along +y_G with its x along +x_G and its y (image down)
# along -z_G: columns of R_ItoB are x_I, y_I, z_I in B.  (= Rx(-90 deg))
_R_ItoB_BOXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

# B = aircraft body (x forward, y left wing, z up). The IMU (≈ camera) looks down (z_I = -z_B), image x along the
# right wing (x_I = -y_B), image down = backwards (y_I = -x_B).
_R_ItoB_AERIAL = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def boxes_like(duration: float = 60.0, seed: int = 0) -> Trajectory:
    """Return a hand-held 6-DoF trajectory like RPG ``boxes_6dof``: gentle at first, vigorous shaking at the end.

    Args:
        duration: length in seconds (>= 2); the motion envelope (amplitudes and frequencies growing as (t/D)^2)
            is stretched over the whole duration.
        seed: seeds the random phases and frequency ratios.

    The rig stays near (0, 0, 1.4) m (within ~0.3 m); the IMU/camera looks along +y_G (x_C ≈ +x_G, y_C ≈ -z_G)
    toward boxes at y in [1.5, 3.5] m. Per axis, the position is a sum of two chirps whose amplitudes grow from
    ~0.1 m to ~0.15-0.2 m and frequencies from ~0.35 Hz to ~1.8 Hz (and ~2x that for the weaker component); the
    yaw/pitch/roll amplitudes likewise grow from ~8 to ~16 degrees. Speed rises from ~0.3 m/s (mean, first
    quarter) to a peak of ~3-4 m/s, angular rate from ~0.35 rad/s (peak ~0.7) to a peak of ~5 rad/s; peak
    acceleration ~40-60 m/s^2 (thesis §3.4.1; Mueggler et al., "The event-camera dataset and simulator", IJRR 2017).

    >>> traj = boxes_like(duration=60.0, seed=0)
    >>> s = traj.evaluate([0.0, 60.0])
    >>> np.round(s.R_ItoG[0] @ [0.0, 0.0, 1.0], 1) + 0.0   # IMU z axis (≈ optical axis) in G at t = 0
    array([ 0.1,  1. , -0.1])
    """
    D = _check_duration(duration, 2.0)
    rng = np.random.default_rng(seed)
    f0, f1 = 0.35, 1.8  # Hz, start and end frequency of the main components
    centre = (0.0, 0.0, 1.4)
    position = [
        _Sum(_Poly([c]), _shaking_axis(rng, D, amp0, amp1, f0, f1))
        for c, amp0, amp1 in zip(centre, (0.12, 0.10, 0.10), (0.21, 0.15, 0.16))
    ]
    # yaw = pan about z_G, pitch = about y_G (camera roll about the optical axis), roll = about x_G (camera tilt)
    yaw, pitch, roll = (_shaking_axis(rng, D, a0, a1, f0, f1) for a0, a1 in ((0.16, 0.30), (0.13, 0.23), (0.13, 0.25)))
    return EulerTrajectory(position, yaw, pitch, roll, _R_ItoB_BOXES, 0.0, D, name="boxes_like")


def aerial_like(duration: float = 40.0, seed: int = 0, turbulence: float = 1.0) -> Trajectory:
    """Return a fixed-wing flight like the Camp Atterbury test: 250 m altitude, 20 m/s, one coordinated 90° turn.

    Args:
        duration: length in seconds (>= 2). From ~20 s on, the turn (3 s roll-in, ~6.9 s at 25 degrees of bank,
            3 s roll-out; heading +90 degrees, a left turn from +x_G to +y_G) is centred in the flight with straight
            level flight before and after. Shorter flights squeeze the turn into the middle half of the flight
            (roll-in/out 30 % of it) with a steeper bank, capped at 30 degrees; below ~16 s the cap makes the
            heading change smaller than 90 degrees (~57 degrees for 10 s).
        seed: seeds the turbulence (small attitude and position oscillations).
        turbulence: scale of the turbulence (0 gives the ideal manoeuvre).

    The camera (≈ IMU axes) looks down (optical axis ≈ -z_G), image top = direction of flight. Heading ψ(t) is a
    C4 smooth step; bank φ = -atan(V ψ'/g) (coordinated turn, tan(bank) = V ψ'/g). The horizontal position is
    the antiderivative of a quintic spline fitted to V [cos ψ, sin ψ] on a 20 ms grid, so p, v and a are the spline
    and its exact derivatives. The ground track is centred on x = y = 0 (spans ~ ±(V D / 4) m). Thesis §3.4.2.

    >>> s = aerial_like(duration=40.0, seed=0).evaluate([0.0, 40.0])
    >>> np.round(np.linalg.norm(s.v_IinG, axis=1), 0), np.round(s.p_IinG[:, 2], -1)
    (array([20., 20.]), array([250., 250.]))
    """
    D = _check_duration(duration, 2.0)
    if not (np.isfinite(turbulence) and turbulence >= 0.0):
        raise ValueError(f"turbulence must be a finite scale >= 0; got {turbulence!r}")
    rng = np.random.default_rng(seed)
    speed, altitude = 20.0, 250.0  # m/s, m
    turn_angle = np.pi / 2
    rate = GRAVITY_MAGNITUDE * np.tan(np.radians(25.0)) / speed  # ψ' on the plateau: tan(bank) = V ψ'/g
    ramp = 3.0  # s, roll-in / roll-out time
    plateau = turn_angle / rate  # r (t_b - t_a) = 90 deg
    if plateau + ramp > 0.5 * D:  # short flight: squeeze the turn into the middle half, bank <= 30 deg
        ramp, plateau = 0.3 * 0.5 * D, 0.7 * 0.5 * D
        rate = min(turn_angle / plateau, GRAVITY_MAGNITUDE * np.tan(np.radians(30.0)) / speed)
    t_a = 0.5 * D - 0.5 * (plateau + ramp)
    heading = _Heading(0.0, rate, t_a, t_a + plateau, ramp)

    # horizontal velocity V [cos ψ, sin ψ] fitted by a quintic spline; position = its antiderivative
    grid = np.linspace(0.0, D, int(round(D / 0.02)) + 1)
    psi_grid = heading(grid, 0)[0]
    vel_xy = make_interp_spline(grid, speed * np.stack([np.cos(psi_grid), np.sin(psi_grid)], -1), k=5)
    pos_xy = vel_xy.antiderivative()  # exact integral, zero at t = 0
    track = pos_xy(grid)
    offset = -0.5 * (track.min(axis=0) + track.max(axis=0))  # centre the ground track on the origin
    xy = [_Spline(BSpline(pos_xy.t, pos_xy.c[:, i] + offset[i], pos_xy.k)) for i in range(2)]

    def gust(amp: float, fmin: float, fmax: float) -> _Sum:
        """Turbulence: two constant-amplitude sinusoids with seeded frequency and phase."""
        parts = []
        for weight in (0.7, 0.3):
            f, ph = rng.uniform(fmin, fmax), rng.uniform(0.0, 2.0 * np.pi)
            parts.append(_Chirp(Polynomial([turbulence * weight * amp]), Polynomial([ph, 2.0 * np.pi * f])))
        return _Sum(*parts)

    position = [
        _Sum(xy[0], gust(0.3, 0.05, 0.2)),
        _Sum(xy[1], gust(0.3, 0.05, 0.2)),
        _Sum(_Poly([altitude]), gust(1.0, 0.03, 0.15)),
    ]
    yaw = _Sum(heading, gust(np.radians(1.0), 0.1, 0.6))
    pitch = _Sum(_Poly([np.radians(-2.0)]), gust(np.radians(1.0), 0.1, 0.8))  # ~2 deg nose up (θ < 0 in FLU)
    roll = _Sum(_CoordinatedBank(heading, speed), gust(np.radians(1.5), 0.2, 1.0))
    return EulerTrajectory(position, yaw, pitch, roll, _R_ItoB_AERIAL, 0.0, D, name="aerial_like")


PRESETS = ("boxes_like", "aerial_like")
#: Longest preset trajectory, seconds (one hour). A trajectory is sampled at the IMU rate (1 kHz): one hour is 3.6 M
#: samples, about 1 GB of poses, velocities and IMU readings; a mistyped --duration 1e9 would ask for 7 TiB.
MAX_TRAJECTORY_DURATION_S = 3600.0


def trajectory_from_preset(name: str, duration: float | None = None, seed: int = 0, speed: float = 1.0) -> Trajectory:
    """Return the preset trajectory ``name`` ('boxes_like' | 'aerial_like') with its default or given duration.

    Args:
        name: preset name.
        duration: seconds; None keeps the preset's default (60 s boxes, 40 s aerial).
        seed: seeds the preset's random phases / turbulence.
        speed: play the motion this many times faster (:class:`TimeScaledTrajectory`): the preset's motion of
            ``duration * speed`` seconds (None: its default length) played in ``duration`` (default / speed)
            seconds. 1 is the preset itself.

    >>> trajectory_from_preset("aerial_like").duration
    40.0
    >>> trajectory_from_preset("boxes_like", speed=2.0).duration   # the 60 s room, twice as fast
    30.0
    """
    if name not in PRESETS:
        raise ValueError(f"name must be one of {PRESETS}; got {name!r}")
    if isinstance(speed, bool) or not isinstance(speed, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a finite number > 0 (how many times faster the motion is played); "
                         f"got {speed!r}")
    base_duration = None if duration is None else duration * speed
    if base_duration is not None and not (base_duration <= MAX_TRAJECTORY_DURATION_S):  # NaN too
        raise ValueError(f"duration {duration:g} s is longer than the longest trajectory, "
                         f"{MAX_TRAJECTORY_DURATION_S / speed:g} s" + (f" at speed {speed:g}" if speed != 1 else "")
                         + " (MAX_TRAJECTORY_DURATION_S: "
                         f"sampled at 1 kHz, an hour is about 1 GB)")
    factory = boxes_like if name == "boxes_like" else aerial_like
    base = factory(seed=seed) if base_duration is None else factory(duration=base_duration, seed=seed)
    return base if speed == 1.0 else TimeScaledTrajectory(base, speed)
