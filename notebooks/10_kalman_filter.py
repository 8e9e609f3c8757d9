# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 10 — The Kalman filter: predict, update, and is it honest?
#
# Lesson 09 integrated the IMU and watched the errors grow. The back-end of the thesis this course follows
# (Friedel 2020, *Event-based visual-inertial odometry using smart features*, §3.3) stops that growth with a
# **Kalman filter**: it carries an estimate *and its uncertainty* forward in time, and corrects both whenever a
# measurement arrives. The next lesson builds the thesis's filter, the MSCKF (multi-state constraint Kalman filter),
# whose error state has 15 + 6N numbers for N camera poses. This one teaches the filter itself on problems small enough to see, in the style of R. Labbe's book *Kalman and
# Bayesian Filters in Python* and with its library, `filterpy`:
#
# 1. the **predict/update cycle**, drawn,
# 2. a **1-D constant-velocity filter** written by hand in NumPy, then with `filterpy.kalman.KalmanFilter`, and the
#    two compared,
# 3. the **process noise Q**: `filterpy`'s `Q_discrete_white_noise` against the **Van Loan** discretisation of the
#    continuous model, and why they differ,
# 4. **consistency**: NEES and NIS against their chi-square bands, what a wrong Q does to them, and the
#    **chi-square gate** that rejects an outlier,
# 5. a small **error-state filter**, attitude and gyroscope bias, corrected by gravity: the first two blocks of the
#    MSCKF, with the project's JPL quaternions, and the direction it cannot see.
#
# Library pieces used: `filterpy`, `scipy.linalg.expm`, `scipy.stats.chi2`,
# `evio_lib.evaluation.trajectory_metrics` (NEES and its χ² bounds), `evio_lib.msckf.update` (the MSCKF's gate and
# Joseph-form update) and `evio_lib.msckf.error_state_attitude` (the small filter of section 5).

# %% [markdown]
# First the idea as a picture. A Kalman filter describes what it knows about the state as a **Gaussian**
# $\mathcal N(\mathbf x, P)$: a mean $\mathbf x$ (the estimate) and a covariance $P$ (how unsure it is, and how the
# errors of the components go together). Left: each step has two halves. The **prediction** moves the estimate with
# a motion model $F$ and makes it less certain by the **process noise** $Q$ (what the model does not know). The
# **update** compares a measurement $\mathbf z$ with what the prediction expects, $H\mathbf x$; the difference is
# the **innovation** $\mathbf y$, and the **gain** $K$ says how much of it to believe. Right, for a position alone
# (the legend writes $\mathcal N(\text{mean}, \text{variance})$): the last estimate (grey) is moved by the velocity
# and widened into the **prior** (blue); the measurement (orange) has its own spread; the **posterior** (green) is
# their normalised product. It lies between the two, nearer the narrower one, and is narrower than either.

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: BLAS threads only slow them down
os.environ.setdefault("OMP_NUM_THREADS", "1")

import matplotlib.pyplot as plt  # noqa: E402

from evio_lib.evaluation.plots_kalman import plot_kalman_cycle_schematic  # noqa: E402

fig = plot_kalman_cycle_schematic()
plt.show()

# %%
import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402
from filterpy.common import Q_continuous_white_noise, Q_discrete_white_noise  # noqa: E402
from filterpy.kalman import KalmanFilter  # noqa: E402
from IPython.display import Markdown, display  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from evio_lib.course import fast_mode  # noqa: E402
from evio_lib.evaluation.plots_kalman import (  # noqa: E402
    plot_attitude_filter_run,
    plot_gate,
    plot_nees_nis,
    plot_track_1d,
)
from evio_lib.evaluation.trajectory_metrics import chi2_bounds, nees  # noqa: E402

FAST = fast_mode()
rng = np.random.default_rng(1001)
N_RUNS_1D = 60 if FAST else 300  # Monte-Carlo runs of the 1-D filter (section 4)
ATTITUDE_SECONDS = 20.0 if FAST else 60.0  # the error-state filter's demonstration run (section 5)
N_RUNS_ATT, ATT_RUN_SECONDS = (6, 10.0) if FAST else (30, 20.0)  # its Monte-Carlo runs and their length

# %% [markdown]
# ## 1. A 1-D constant-velocity target
#
# A target moves along a line. Its state is $\mathbf x = [p, v]^T$, position and velocity. Between two measurements,
# $\Delta t$ apart, it keeps its velocity except for a random **white acceleration** of spectral density $q$
# (a noise with no memory: its effect over a time $T$ has variance $q\,T$ on the velocity). So
#
# $$\mathbf x_{k+1} = F\mathbf x_k + \mathbf w_k,\qquad F = \begin{bmatrix}1 & \Delta t\\ 0 & 1\end{bmatrix},\qquad
# \mathbf w_k \sim \mathcal N(0, Q),$$
#
# and we measure the position with noise of standard deviation $\sigma_z$:
# $z_k = H\mathbf x_k + v_k$, $H = [1\ \ 0]$, $v_k\sim\mathcal N(0, R)$, $R = \sigma_z^2$.
# Section 3 derives $Q$; for now take its exact value
# $Q = q\begin{bmatrix}\Delta t^3/3 & \Delta t^2/2\\ \Delta t^2/2 & \Delta t\end{bmatrix}$.
# The simulation below draws the truth from exactly this model, for many runs at once (one column per run).

# %%
dt = 0.1  # s between measurements
q = 0.5  # m²/s³: spectral density of the white acceleration
sigma_z = 1.0  # m: standard deviation of one position measurement
n_steps = 100  # 10 s
F = np.array([[1.0, dt], [0.0, 1.0]])
H = np.array([[1.0, 0.0]])
R = np.array([[sigma_z**2]])
Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
x0 = np.array([[0.0], [0.0]])  # the filter's initial estimate: at the origin, at rest ...
P0 = np.diag([2.0**2, 1.0**2])  # ... give or take 2 m and 1 m/s


def simulate(n_runs, rng):
    """Truth (n_steps, 2, n_runs) and measurements (n_steps, 1, n_runs); each run starts from x0 + N(0, P0)."""
    x = x0 + np.linalg.cholesky(P0) @ rng.standard_normal((2, n_runs))
    L = np.linalg.cholesky(Q)
    truth, zs = [], []
    for _ in range(n_steps):
        x = F @ x + L @ rng.standard_normal((2, n_runs))  # x_k+1 = F x_k + w_k
        truth.append(x)
        zs.append(H @ x + sigma_z * rng.standard_normal((1, n_runs)))  # z = H x + v
    return np.array(truth), np.array(zs)


truth, zs = simulate(1, rng)
t = dt * np.arange(1, n_steps + 1)
print(f"{n_steps} measurements, {dt} s apart; the target ends at p = {truth[-1, 0, 0]:.1f} m, "
      f"v = {truth[-1, 1, 0]:.2f} m/s")

# %% [markdown]
# ## 2. Predict and update, by hand
#
# The two halves of the schematic, line by line (thesis Eq. 38 for the prediction, Eqs. 56-58 for the update):
#
# $$\text{predict:}\quad \bar{\mathbf x} = F\mathbf x,\qquad \bar P = F P F^T + Q$$
#
# $$\text{update:}\quad \mathbf y = \mathbf z - H\bar{\mathbf x},\quad S = H\bar P H^T + R,\quad K = \bar P H^T S^{-1},\quad
# \mathbf x = \bar{\mathbf x} + K\mathbf y,\quad P = (I - KH)\bar P(I - KH)^T + KRK^T.$$
#
# $S$ is the covariance the filter expects of the innovation $\mathbf y$. The last line is the **Joseph form** of the
# covariance update: algebraically equal to the shorter $(I - KH)\bar P$, but a sum of two symmetric positive
# semi-definite terms, so round-off cannot make $P$ lose its symmetry or become indefinite; the MSCKF uses it too.
# The functions work on a column per run, so the Monte-Carlo runs of section 4 use them unchanged.

# %%
def predict(x, P, F, Q):
    x = F @ x  # x = F x
    P = F @ P @ F.T + Q  # P = F P F^T + Q
    return x, P


def update(x, P, z, H, R):
    y = z - H @ x  # innovation
    S = H @ P @ H.T + R  # its covariance
    K = P @ H.T @ np.linalg.inv(S)  # gain (a division here: S is 1 x 1)
    x = x + K @ y  # x = x + K y
    I_KH = np.eye(len(P)) - K @ H
    P = I_KH @ P @ I_KH.T + K @ R @ K.T  # Joseph form
    return x, P, y, S


x, P = x0.copy(), P0.copy()
hand_x, hand_P = [], []
for z in zs:
    x, P = predict(x, P, F, Q)
    x, P, y, S = update(x, P, z, H, R)
    hand_x.append(x[:, 0])
    hand_P.append(P)
hand_x, hand_P = np.array(hand_x), np.array(hand_P)

# %% [markdown]
# The same filter with `filterpy`: a `KalmanFilter` object holds `x`, `P`, `F`, `H`, `R`, `Q`, and its `predict()`
# and `update(z)` do the two halves (filterpy's update uses the Joseph form as well).

# %%
kf = KalmanFilter(dim_x=2, dim_z=1)
kf.x, kf.P, kf.F, kf.H, kf.R, kf.Q = x0.copy(), P0.copy(), F, H, R, Q
fp_x, fp_P, fp_nis = [], [], []
for z in zs:
    kf.predict()
    kf.update(z)
    fp_x.append(kf.x[:, 0].copy())
    fp_P.append(kf.P.copy())
    fp_nis.append(kf.mahalanobis**2)  # y^T S^-1 y, used in section 4
fp_x, fp_P = np.array(fp_x), np.array(fp_P)
diff = max(np.abs(fp_x - hand_x).max(), np.abs(fp_P - hand_P).max())
print(f"largest difference, hand-written against filterpy (x and P over {n_steps} steps): {diff:.1e}")
assert diff < 1e-12

# %%
sigma = np.sqrt(np.diagonal(hand_P, axis1=1, axis2=2))
plot_track_1d(t, truth[:, :, 0], zs[:, 0, 0], hand_x, sigma,
              title="1-D constant-velocity filter: truth, measurements, estimate ±2σ")
plt.show()
rms_z = np.sqrt(np.mean((zs[:, 0, 0] - truth[:, 0, 0]) ** 2))
rms_p = np.sqrt(np.mean((hand_x[50:, 0] - truth[50:, 0, 0]) ** 2))
rms_v = np.sqrt(np.mean((hand_x[50:, 1] - truth[50:, 1, 0]) ** 2))
print(f"second half: measurement RMS error {rms_z:.2f} m; filter {rms_p:.2f} m (σ at the end {sigma[-1, 0]:.2f} m); "
      f"velocity {rms_v:.2f} m/s (σ {sigma[-1, 1]:.2f} m/s)")
assert rms_p < rms_z
settled = t[np.argmax(np.abs(sigma[:, 0] / sigma[-1, 0] - 1) < 0.01)]  # first time within 1 % of the final σ
assert np.allclose(sigma[t >= settled, 0], sigma[-1, 0], rtol=0.01)
display(Markdown(
    f"The line above compares the filter with the raw measurements over the second half of the run, where the start "
    f"no longer matters: {rms_p:.2f} m against {rms_z:.2f} m. The filter averages many measurements through the "
    f"motion model, so its position error is a fraction of one measurement's, and it estimates the velocity, which "
    f"nothing measures, from how the positions move ({rms_v:.2f} m/s RMS). The position σ falls from "
    f"{sigma[0, 0]:.2f} m after the first measurement to within 1 % of its final {sigma[-1, 0]:.2f} m by "
    f"t = {settled:.1f} s, and stays there: the prior $P_0$ has been replaced by what the measurements say, and "
    f"each prediction adds as much uncertainty ($Q$) as each update removes."))

# %% [markdown]
# ## 3. Where Q comes from: the piecewise and the continuous model
#
# $Q$ is the covariance of what the motion model leaves out over one step. There are two common models of it, and
# `filterpy` offers both.
#
# **Continuous white acceleration** (the model we simulated): $\dot{\mathbf x} = A\mathbf x + L\,w(t)$ with
# $A = \begin{bmatrix}0 & 1\\ 0 & 0\end{bmatrix}$, $L = [0, 1]^T$ and $w$ white with spectral density $q$. Over one
# step, $F = e^{A\Delta t}$ and $Q = \int_0^{\Delta t} e^{As} L q L^T e^{A^Ts}\,ds$. **Van Loan's method** (C. F. van Loan,
# 1978) evaluates both with a single matrix exponential, for any linear model (the next lesson checks the MSCKF's
# 15 × 15 discretisation the same way):
#
# $$\exp\!\left(\begin{bmatrix}-A & LqL^T\\ 0 & A^T\end{bmatrix}\Delta t\right) = \begin{bmatrix}\cdot & B_{12}\\ 0 & B_{22}\end{bmatrix},\qquad
# F = B_{22}^T,\quad Q = F\,B_{12}.$$
#
# For this $A$ the integral can be done by hand: $Q = q\begin{bmatrix}\Delta t^3/3 & \Delta t^2/2\\ \Delta t^2/2 &
# \Delta t\end{bmatrix}$, which is `filterpy`'s `Q_continuous_white_noise`.
#
# **Piecewise-constant (discrete) white acceleration**, `filterpy`'s `Q_discrete_white_noise` and Labbe's usual
# choice: the acceleration is a random *constant* $a_k$ over each step, of variance `var`, independent from step to
# step. It moves the state by $\Gamma a_k$ with $\Gamma = [\Delta t^2/2,\ \Delta t]^T$, so
# $Q = \Gamma\Gamma^T\,\mathrm{var} = \begin{bmatrix}\Delta t^4/4 & \Delta t^3/2\\ \Delta t^3/2 & \Delta t^2\end{bmatrix}\mathrm{var}$.
# Note the units: `var` is a variance of an acceleration (m²/s⁴), $q$ a spectral density (m²/s³). The two models give
# the same velocity variance when $\mathrm{var} = q/\Delta t$.

# %%
A = np.array([[0.0, 1.0], [0.0, 0.0]])
L = np.array([[0.0], [1.0]])
B = scipy.linalg.expm(np.block([[-A, L * q @ L.T], [np.zeros((2, 2)), A.T]]) * dt)
F_vl = B[2:, 2:].T  # F = B22^T
Q_vl = F_vl @ B[:2, 2:]  # Q = F B12
Q_closed = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
Q_dw = Q_discrete_white_noise(dim=2, dt=dt, var=q / dt)
np.set_printoptions(precision=6, suppress=False)
print("Van Loan (expm)                :\n", Q_vl)
print("closed form q[[Δt³/3, Δt²/2], [Δt²/2, Δt]]:\n", Q_closed)
print("Q_discrete_white_noise(var = q/Δt):\n", Q_dw)
print(f"determinants: continuous {np.linalg.det(Q_vl):.3e}, piecewise {np.linalg.det(Q_dw):.3e}")
np.set_printoptions()
assert np.allclose(F_vl, F, atol=1e-15)
assert np.allclose(Q_vl, Q_closed, rtol=1e-12, atol=0)
assert np.allclose(Q_continuous_white_noise(dim=2, dt=dt, spectral_density=q), Q_closed, rtol=1e-12, atol=0)
assert np.isclose(Q_dw[1, 1], Q_closed[1, 1]) and np.isclose(Q_dw[0, 1], Q_closed[0, 1])  # same velocity terms
assert np.isclose(Q_dw[0, 0], 0.75 * Q_closed[0, 0])  # Δt⁴/4 · q/Δt against q Δt³/3
assert abs(np.linalg.det(Q_dw)) < 1e-12 * np.linalg.det(Q_vl) and np.linalg.det(Q_vl) > 0  # rank 1 against 2
assert np.allclose(Q_discrete_white_noise(dim=2, dt=dt, var=q), dt * Q_dw)  # var = q: Δt times too small

# %% [markdown]
# What holds, and the asserts check: Van Loan's exponential reproduces the transition matrix $F$ and the closed form
# of $Q$ to round-off. With $\mathrm{var} = q/\Delta t$ the piecewise model agrees on the velocity variance and on
# the cross term, but gives the position only $3/4$ of the continuous variance ($\Delta t^4/4\cdot q/\Delta t$
# against $q\Delta t^3/3$), on every step size. And its $Q$ has rank one (the determinant printed above is zero up to
# round-off): a constant acceleration over the step moves position and velocity in a fixed ratio, while a white
# acceleration can also change the velocity and come back within the step, which moves the position alone.
# Which is right depends on the target: a vehicle whose acceleration changes at each control step is piecewise, a
# body shaken by a random force is continuous. The IMU noise of the MSCKF is given as a spectral density, so the
# next lesson uses the continuous model (and Van Loan to check it).
#
# The pitfall is the units: passing $q$ as `var`, as if it were the same number, makes $Q$ smaller by the factor
# $\Delta t$ (the last assert), ten times too small here. Section 4 shows what that does.
#
# ## 4. Is the filter honest? NEES, NIS and the chi-square gate
#
# A filter is **consistent** when its errors are as large as its covariance says, no more and no less. Two
# statistics test it. The **NEES** (normalised estimation error squared) $\epsilon_k = \mathbf e_k^T P_k^{-1}\mathbf e_k$,
# $\mathbf e_k = \mathbf x_k - \hat{\mathbf x}_k$, needs the truth, so it is a simulation tool; for a consistent filter
# it follows a **chi-square** law $\chi^2(n)$ with $n = 2$ degrees of freedom (the sum of $n$ squared standard normal
# variables), of mean $n$. The **NIS** (normalised innovation squared) $\nu_k = \mathbf y_k^T S_k^{-1}\mathbf y_k$ needs
# only the measurements, so it also works on real data; it follows $\chi^2(1)$ here. One run is too noisy to judge, so
# we average over $N$ seeded Monte-Carlo runs: $N\bar\epsilon_k \sim \chi^2(nN)$, which gives a 95 % interval for
# the average (`chi2_bounds`, from `scipy.stats.chi2`). Four filters, on the same data: the right $Q$ (Van Loan's),
# the piecewise model with $\mathrm{var} = q/\Delta t$, the piecewise model with $q$ passed as `var` (under-estimated
# $Q$), and ten times the right $Q$ (over-estimated).

# %%
truth_mc, zs_mc = simulate(N_RUNS_1D, rng)
filters = {
    "Q from Van Loan (the truth's model)": Q_vl,
    "Q_discrete_white_noise, var = q/Δt": Q_dw,
    "Q_discrete_white_noise, var = q (Q too small)": Q_discrete_white_noise(dim=2, dt=dt, var=q),
    "10 × Q (Q too large)": 10.0 * Q_vl,
}
nees_avg, nis_avg, rms_pos, P_end = {}, {}, {}, {}
for name, Q_f in filters.items():
    x, P = np.repeat(x0, N_RUNS_1D, axis=1), P0.copy()  # every run starts from the same estimate
    e_nees, e_nis, e_pos = [], [], []
    for k in range(n_steps):
        x, P = predict(x, P, F, Q_f)
        x, P, y, S = update(x, P, zs_mc[k], H, R)
        e_nees.append(nees((truth_mc[k] - x).T, np.broadcast_to(P, (N_RUNS_1D, 2, 2))))  # e^T P^-1 e per run
        e_nis.append(y[0] ** 2 / S[0, 0])  # y^T S^-1 y per run
        e_pos.append(truth_mc[k, 0] - x[0])
    nees_avg[name], nis_avg[name] = np.mean(e_nees, axis=1), np.mean(e_nis, axis=1)
    rms_pos[name] = np.sqrt(np.mean(np.square(e_pos)[n_steps // 2:]))  # second half: the start forgotten
    P_end[name] = P
nees_band, nis_band = chi2_bounds(2, N_RUNS_1D), chi2_bounds(1, N_RUNS_1D)
lo2, hi2 = chi2.ppf([0.025, 0.975], 2 * N_RUNS_1D) / N_RUNS_1D  # the same interval from scipy directly
assert np.allclose((lo2, hi2), nees_band)
plot_nees_nis(t, nees_avg, nis_avg, nees_band, nis_band, nees_dof=2, nis_dof=1, n_runs=N_RUNS_1D)
plt.show()

# %%
def inside(values, band):
    return 100.0 * np.mean((values >= band[0]) & (values <= band[1]))


rows = ["| filter | mean NEES (expected 2) | steps inside the NEES band | mean NIS (expected 1) | "
        "steps inside the NIS band | position RMS error, second half |", "|---|---|---|---|---|---|"]
for name in filters:
    rows.append(f"| {name} | {nees_avg[name].mean():.2f} | {inside(nees_avg[name], nees_band):.0f} % | "
                f"{nis_avg[name].mean():.2f} | {inside(nis_avg[name], nis_band):.0f} % | {rms_pos[name]:.3f} m |")
display(Markdown(f"Averages over {N_RUNS_1D} runs; the 95 % bands are [{nees_band[0]:.2f}, {nees_band[1]:.2f}] for "
                 f"the NEES and [{nis_band[0]:.2f}, {nis_band[1]:.2f}] for the NIS.\n\n" + "\n".join(rows)))
names = list(filters)
assert inside(nees_avg[names[0]], nees_band) >= 80 and inside(nis_avg[names[0]], nis_band) >= 80
assert nees_avg[names[2]].mean() > nees_band[1] and nees_avg[names[3]].mean() < nees_band[0]
assert min(rms_pos[names[2]], rms_pos[names[3]]) > rms_pos[names[0]]  # a wrong Q costs accuracy both ways

# %%
good, small, large = (nees_avg[n].mean() for n in (names[0], names[2], names[3]))
nis_small, nis_large = nis_avg[names[2]].mean(), nis_avg[names[3]].mean()
gap = abs(nees_avg[names[1]].mean() - good)
display(Markdown(
    f"The filter with the right $Q$ has a mean NEES of {good:.2f} and stays inside its band at "
    f"{inside(nees_avg[names[0]], nees_band):.0f} % of the steps: its covariance tells the truth. The piecewise "
    f"model with $\\mathrm{{var}} = q/\\Delta t$ differs from it by {gap:.3f} in the mean NEES (its curves lie on "
    f"the first filter's): the {Q_closed[0, 0] - Q_dw[0, 0]:.1e} m² of position noise per step it leaves out is "
    f"small beside the position variance of {P_end[names[0]][0, 0]:.2f} m² that the velocity noise and the "
    f"measurements leave. With $q$ passed as "
    f"`var` the filter is **over-confident**: its $P$ is too small, so it weighs the measurements too little, and "
    f"its squared errors are {small / 2:.1f} times what its covariance admits (mean NEES {small:.2f}), its errors "
    f"{np.sqrt(small / 2):.1f} times its σ. Ten times the right $Q$ makes it **pessimistic**: a mean NEES of "
    f"{large:.2f}, below the band; it follows the measurements too closely. Both are less accurate than the right "
    f"filter: position RMS errors of {rms_pos[names[2]]:.3f} m and {rms_pos[names[3]]:.3f} m against "
    f"{rms_pos[names[0]]:.3f} m."
    f"\n\nThe NIS, which a filter can compute on real data, moves the same way but much less: {nis_small:.2f} and "
    f"{nis_large:.2f} against the expected 1, and the over-confident filter still passes the NIS band at "
    f"{inside(nis_avg[names[2]], nis_band):.0f} % of the steps. The innovation is dominated by the measurement "
    f"noise $R$, which is right in all four filters, so a wrong $Q$ hides behind it. This is why the course checks "
    f"the MSCKF's consistency with NEES in simulation."))

# %% [markdown]
# **The chi-square gate.** A measurement whose NIS is far out in the tail of $\chi^2(1)$ is more likely a fault (a
# wrong match, a glitch) than noise. A gate rejects it before the update: skip the update when
# $\nu > \chi^2_{p}(m)$, the $p$-quantile for $m$ measurement rows. The MSCKF gates every feature track this way
# (`evio_lib.msckf.update.chi_square_gate`, with the same quantile function). Below, one measurement of the run of
# section 2 is moved by $12\sigma_z$, and the filter runs with and without a gate at $p = 0.99$.

# %%
from evio_lib.msckf.update import chi_square_threshold  # noqa: E402

gate = chi_square_threshold(1, 0.99)
assert np.isclose(gate, chi2.ppf(0.99, 1))
k_out = 60
zs_bad = zs.copy()
zs_bad[k_out] += 12.0 * sigma_z
errors, nis_seen, rejected = {}, None, []
for use_gate in (False, True):
    x, P = x0.copy(), P0.copy()
    err, nis_k = [], []
    for k, z in enumerate(zs_bad):
        x, P = predict(x, P, F, Q)
        y = z - H @ x
        nis_k.append((y.T @ np.linalg.inv(H @ P @ H.T + R) @ y).item())  # y^T S^-1 y
        if use_gate and nis_k[-1] > gate:
            rejected.append(k)  # skip the update: keep the prediction
        else:
            x, P, _, _ = update(x, P, z, H, R)
        err.append(abs(x[0, 0] - truth[k, 0, 0]))
    errors["with the gate" if use_gate else "no gate"] = np.array(err)
    nis_seen = np.array(nis_k)
plot_gate(t, nis_seen, gate, errors, outlier_time=t[k_out])
plt.show()
assert k_out in rejected and nis_seen[k_out] > 10 * gate
jump = errors["no gate"][k_out] - errors["no gate"][k_out - 1]
assert errors["no gate"][k_out] > 3 * errors["with the gate"][k_out]
display(Markdown(
    f"The outlier's NIS is {nis_seen[k_out]:.0f}, against a gate of {gate:.2f}. Without the gate the update believes "
    f"it and the position error jumps to {errors['no gate'][k_out]:.2f} m (from {errors['no gate'][k_out - 1]:.2f} m "
    f"one step before); the error then decays over the following steps as new measurements pull the estimate back. "
    f"With the gate the update is skipped: the filter keeps its prediction, {errors['with the gate'][k_out]:.2f} m "
    f"off at that step, and the next good measurements correct it as usual. The gate "
    f"has a price: at $p = 0.99$ it also rejects one good measurement in a hundred on average; in this run it "
    f"rejected {len(rejected) - 1 if len(rejected) > 1 else 'none'} of the {n_steps - 1} good ones."))

# %% [markdown]
# ## 5. A small error-state filter: attitude and gyroscope bias
#
# The MSCKF's state holds an attitude, a unit quaternion $\bar q_{GtoI}$ (the JPL convention of the IMU lesson, scalar last).
# Four numbers with one constraint: a covariance over all four would be singular. The remedy (thesis Eqs. 22-24) is
# the **error-state** filter. It keeps the **nominal** state (the quaternion and the bias $\mathbf b_g$) outside the
# Kalman filter and runs the filter on the small **error** between truth and estimate,
#
# $$\tilde{\mathbf x} = [\delta\boldsymbol\theta^T, \delta\mathbf b_g^T]^T,\qquad \bar q = \delta\bar q(\delta\boldsymbol\theta)\otimes\hat{\bar q},\qquad
# \mathbf b_g = \hat{\mathbf b}_g + \delta\mathbf b_g,$$
#
# with $\delta\boldsymbol\theta$ a small rotation vector in the body frame $I$ (3 numbers, a regular $6\times 6$
# covariance). Its $F$ and $H$ are linearisations around the current estimate, which makes it an **extended Kalman
# filter** (EKF). Its three ingredients:
#
# * **Prediction.** The nominal quaternion is integrated with the bias-corrected gyro rate
#   $\hat{\boldsymbol\omega} = \boldsymbol\omega_m - \hat{\mathbf b}_g$, held over the step:
#   $\hat{\bar q} \leftarrow \delta\bar q(\hat{\boldsymbol\omega}\Delta t)\otimes\hat{\bar q}$. The error obeys the top-left
#   blocks of thesis Eqs. 33-35,
#
#   $$\dot{\tilde{\mathbf x}} = F\tilde{\mathbf x} + G\mathbf n,\qquad F = \begin{bmatrix}-[\hat{\boldsymbol\omega}\times] & -I_3\\ 0 & 0\end{bmatrix},\qquad
#   G = \begin{bmatrix}-I_3 & 0\\ 0 & I_3\end{bmatrix},\qquad \mathbf n = [\mathbf n_g, \mathbf n_{wg}],$$
#
#   with the gyro's white noise $\mathbf n_g$ and the bias's random walk $\mathbf n_{wg}$, both given as spectral
#   densities; $\Phi$ and $Q_d$ come from Van Loan's exponential, as in section 3.
# * **Measurement.** The IMU only turns about its centre, so the accelerometer reads the specific force of the IMU lesson
#   at rest, "up" seen in $I$: $\mathbf z = C(\bar q)\,\mathbf f_G + \mathbf n_a$, $\mathbf f_G = [0, 0, 9.81]$ m/s².
#   To first order, $C(\delta\bar q)\approx I - [\delta\boldsymbol\theta\times]$ gives
#   $\mathbf z \approx \hat{\mathbf z} + [\hat{\mathbf z}\times]\delta\boldsymbol\theta$, so $H = \begin{bmatrix}[\hat{\mathbf z}\times] & 0\end{bmatrix}$.
# * **Correction.** The update's $\delta\hat{\mathbf x} = K\mathbf y$ is put back into the nominal state, the attitude
#   multiplicatively: $\hat{\bar q}\leftarrow\delta\bar q(\delta\hat{\boldsymbol\theta})\otimes\hat{\bar q}$,
#   $\hat{\mathbf b}_g \leftarrow \hat{\mathbf b}_g + \delta\hat{\mathbf b}_g$; the error state is then zero again.
#
# `evio_lib.msckf.error_state_attitude` implements this with the project's rotation functions and the MSCKF's
# Joseph-form update. Two quick checks first. With $\hat{\boldsymbol\omega} = 0$ each axis of $[\delta\theta,
# \delta b_g]$ *is* section 3's constant-velocity model (the attitude error integrates minus the bias error, as the
# position integrates the velocity), with the random walk's density in the place of $q$ and the gyro's white noise
# added to the angle. And $H$ against finite differences of the measurement function:

# %%
from evio_lib.geometry.rotation import (  # noqa: E402
    quat_from_rotvec,
    quat_inverse,
    quat_multiply,
    quat_to_rot,
)
from evio_lib.msckf.error_state_attitude import (  # noqa: E402
    AttitudeFilter,
    discretize,
    gravity_measurement,
    run_filter,
    simulate_rotating_imu,
)
from evio_lib.sim.imu import ImuNoiseParams  # noqa: E402

noise = ImuNoiseParams()  # the course's IMU (an MPU-6150 class MEMS, as in the IMU lesson)
imu_dt = 0.01  # a 100 Hz IMU
Phi0, Qd0 = discretize(np.zeros(3), imu_dt, noise.gyro_noise_density, noise.gyro_random_walk)
qw = noise.gyro_random_walk**2
cv_axis = qw * np.array([[imu_dt**3 / 3, -imu_dt**2 / 2], [-imu_dt**2 / 2, imu_dt]])  # [δθ, δb] of one axis
cv_axis[0, 0] += noise.gyro_noise_density**2 * imu_dt
assert np.allclose(Qd0[np.ix_([0, 3], [0, 3])], cv_axis, rtol=1e-10, atol=0)
assert np.allclose(Phi0[np.ix_([0, 3], [0, 3])], [[1.0, -imu_dt], [0.0, 1.0]])

q_hat = quat_from_rotvec([0.4, -0.3, 1.2])
z_hat, H_att = gravity_measurement(q_hat)
H_fd = np.zeros((3, 3))
for i in range(3):
    d = np.zeros(3)
    d[i] = 1e-6
    plus = quat_to_rot(quat_multiply(quat_from_rotvec(d), q_hat)) @ [0.0, 0.0, 9.81]  # q = δq ⊗ q̂
    minus = quat_to_rot(quat_multiply(quat_from_rotvec(-d), q_hat)) @ [0.0, 0.0, 9.81]
    H_fd[:, i] = (plus - minus) / 2e-6
print(f"max |H_fd - H| = {np.abs(H_fd - H_att[:, :3]).max():.1e} (entries up to {np.abs(H_att).max():.2f} m/s²)")
print(f"rank of H: {np.linalg.matrix_rank(H_att)};  H times the vertical seen in I: "
      f"{np.abs(H_att[:, :3] @ (z_hat / 9.81)).max():.1e}")
assert np.abs(H_fd - H_att[:, :3]).max() < 1e-6
assert np.linalg.matrix_rank(H_att) == 2

# %% [markdown]
# $H$ has rank 2, not 3: a rotation about the vertical (yaw) leaves the gravity reading unchanged, so $H$ maps that
# direction to zero (the last number above). One reference direction cannot tell the heading; keep this in mind for
# the results.
#
# **The run.** A simulated IMU turns about its own centre in a slow tumble about all three axes, with the course's
# gyroscope noise and a bias drawn with the spread of the IMU lesson's model
# (`gyro_bias_init_sigma`). The filter predicts at 100 Hz and is corrected by the accelerometer at 10 Hz. Its
# initial attitude error is drawn with σ = 0.02 rad (1.1°) per axis, and it starts from a zero bias with the bias
# spread as its σ. The loop is written out here;
# `run_filter` is the same loop in the library.

# %%
sigma_theta0 = 0.02  # rad, initial attitude uncertainty per axis
P0_att = np.diag([sigma_theta0**2] * 3 + [noise.gyro_bias_init_sigma**2] * 3)


def start_filter(data, rng):
    """An AttitudeFilter at data.t[0] whose error is drawn from P0_att (bias estimate 0, bias truth drawn)."""
    q0 = quat_multiply(quat_inverse(quat_from_rotvec(rng.normal(0.0, sigma_theta0, 3))), data.q_GtoI[0])
    return AttitudeFilter(q0, np.zeros(3), P0_att, noise.gyro_noise_density, noise.gyro_random_walk,
                          data.accel_sigma)


data = simulate_rotating_imu(ATTITUDE_SECONDS, 1.0 / imu_dt, noise, rng)
att = start_filter(data, np.random.default_rng(7))
att_check = start_filter(data, np.random.default_rng(7))  # the same start, for run_filter
rec = {"t": [], "q": [], "b": [], "P": [], "nis": []}
for k in range(len(data.t) - 1):
    att.predict(data.gyro[k], data.t[k + 1] - data.t[k])  # q ← δq(ω̂ Δt) ⊗ q,  P ← Φ P Φ^T + Q_d
    if (k + 1) % 10 == 0:  # the accelerometer at 10 Hz
        nis_k, _ = att.update(data.accel[k + 1])  # y = z − C(q) f_G,  K,  δx,  q ← δq(δθ) ⊗ q,  b_g += δb_g
        for key, value in zip(rec, (data.t[k + 1], att.q_GtoI, att.b_g, att.P, nis_k)):
            rec[key].append(value)
rec = {key: np.array(value) for key, value in rec.items()}
lib = run_filter(att_check, data, update_every=10)
assert np.array_equal(lib.q_GtoI, rec["q"]) and np.array_equal(lib.P, rec["P"])

# %%
idx = np.rint(rec["t"] / imu_dt).astype(int)
up_in_I = quat_to_rot(rec["q"]) @ np.array([0.0, 0.0, 1.0])  # the vertical, seen in I
P_theta = rec["P"][:, :3, :3]
var_yaw = np.einsum("ni,nij,nj->n", up_in_I, P_theta, up_in_I)  # σ² of a rotation about the vertical
var_tilt = (np.trace(P_theta, axis1=1, axis2=2) - var_yaw) / 2  # the other two directions, per axis
b_sigma = np.sqrt(np.diagonal(rec["P"][:, 3:, 3:], axis1=1, axis2=2))
yaw_deg, tilt_deg = np.degrees(np.sqrt(var_yaw)), np.degrees(np.sqrt(var_tilt))
plot_attitude_filter_run(rec["t"], rec["b"], data.b_g[idx], b_sigma, tilt_deg, yaw_deg,
                         title=f"error-state attitude filter, {ATTITUDE_SECONDS:g} s of a tumbling IMU")
plt.show()
b_err = np.abs(data.b_g[idx[-1]] - rec["b"][-1])
print(f"bias: true {np.round(1e3 * data.b_g[idx[-1]], 2)} mrad/s, estimated {np.round(1e3 * rec['b'][-1], 2)} "
      f"mrad/s, σ {np.round(1e3 * b_sigma[-1], 3)} mrad/s")
print(f"σ after the first update and at the end: tilt {tilt_deg[0]:.3f}° -> {tilt_deg[-1]:.4f}°, yaw {yaw_deg[0]:.3f}° "
      f"-> {yaw_deg[-1]:.3f}° (its smallest value {yaw_deg.min():.3f}°, the start {np.degrees(sigma_theta0):.3f}°)")
in_3sigma = 100 * np.mean(np.abs(data.b_g[idx] - rec["b"]) <= 3 * b_sigma)
print(f"the true bias lies within ±3σ of the estimate at {in_3sigma:.0f} % of the updates (per axis)")
closest = np.degrees(np.arccos(np.clip(np.abs(up_in_I).max(axis=0), 0.0, 1.0)))  # per body axis
print(f"the vertical comes within {closest.round(1)}° of the body's x, y, z axes during the run")
yaw_direction = np.concatenate([up_in_I, np.zeros_like(up_in_I)], axis=1)  # [u; 0]: a turn about the vertical
yaw_info = np.einsum("ni,ni->n", yaw_direction, np.linalg.solve(rec["P"], yaw_direction[:, :, None])[:, :, 0])
yaw_info_ratio = yaw_info * sigma_theta0**2  # u^T P^-1 u against the start's 1/σ²
print(f"information along the yaw direction, u^T P^-1 u, relative to the start: at most {yaw_info_ratio.max():.3f}, "
      f"at the end {yaw_info_ratio[-1]:.3f}")
assert np.all(b_err < 4 * b_sigma[-1]) and b_sigma[-1].max() < 0.05 * noise.gyro_bias_init_sigma
assert yaw_deg[-1] > 10 * tilt_deg[-1] and in_3sigma > 90

# %%
shrink = noise.gyro_bias_init_sigma / b_sigma[-1].max()
peak = int(np.argmax(yaw_deg))
gained = yaw_info_ratio.max() > 1.0
display(Markdown(
    f"The bias is found: its σ falls from {1e3 * noise.gyro_bias_init_sigma:.0f} mrad/s to at most "
    f"{1e3 * b_sigma[-1].max():.2f} mrad/s ({shrink:.0f} times smaller), and the true bias lies inside the ±3σ band "
    f"at {in_3sigma:.0f} % of the updates. Gravity alone measures only the tilt, but a bias error makes the "
    f"predicted tilt drift, and because the body keeps turning (the vertical comes within {closest.max():.0f}° of "
    f"every body axis), each bias component in turn tilts the estimate and is seen. The tilt σ settles at "
    f"{tilt_deg[-1]:.3f}° per axis."
    f"\n\nThe yaw σ behaves differently. While the bias is unknown it grows (to {yaw_deg[peak]:.2f}° at "
    f"t = {rec['t'][peak]:.1f} s): the unknown bias turns the estimate about the vertical too, unseen. Once the bias "
    f"is known, the filter can tell how far it turned, and the σ comes back to {yaw_deg[-1]:.2f}°, "
    f"{yaw_deg[-1] / tilt_deg[-1]:.0f} times the tilt's; it started at {np.degrees(sigma_theta0):.2f}°. Nothing "
    f"measures the heading, so an exact filter could never know it better than at the start: the information along "
    f"the yaw direction, $\\mathbf u^T P^{{-1}}\\mathbf u$ with $\\mathbf u = [\\text{{the vertical in }} I;\\ 0]$, "
    f"can never exceed its starting value."
    + (f" The EKF's rises, to {yaw_info_ratio.max():.3f} times its start: information that no measurement holds, "
       f"gained because the EKF evaluates its Jacobians at estimates that move. The observability lesson measures "
       f"the same effect in the MSCKF and what can be done about it." if gained else
       f" The EKF's stays at or below it in this run ({yaw_info_ratio.max():.3f} times).")))

# %% [markdown]
# **Is it consistent?** The same Monte-Carlo test as in section 4, now on the 6-D error state: seeded runs, each
# with its own bias, noise and initial error, the NEES averaged over the runs at every update and compared with
# the $\chi^2$ band for 6 degrees of freedom, and the NIS with 3.

# %%
nees_runs, nis_runs = [], []
for r in range(N_RUNS_ATT):
    data_r = simulate_rotating_imu(ATT_RUN_SECONDS, 1.0 / imu_dt, noise, rng)
    run_r = run_filter(start_filter(data_r, rng), data_r, update_every=10)
    nees_runs.append(nees(run_r.errors, run_r.P))  # errors: true minus estimated [δθ, δb_g]
    nis_runs.append(run_r.nis)
att_nees, att_nis = np.mean(nees_runs, axis=0), np.mean(nis_runs, axis=0)
band6, band3 = chi2_bounds(6, N_RUNS_ATT), chi2_bounds(3, N_RUNS_ATT)
fig = plot_nees_nis(run_r.t, {"error-state attitude filter": att_nees}, {"error-state attitude filter": att_nis},
                    band6, band3, nees_dof=6, nis_dof=3, n_runs=N_RUNS_ATT,
                    title="error-state attitude filter: NEES and NIS averaged over the runs")
plt.show()
in6, in3 = inside(att_nees, band6), inside(att_nis, band3)
assert in6 >= 80 and in3 >= 80
display(Markdown(
    f"Over {N_RUNS_ATT} runs of {ATT_RUN_SECONDS:g} s the average NEES is {att_nees.mean():.2f} (expected 6) and lies "
    f"inside its band [{band6[0]:.2f}, {band6[1]:.2f}] at {in6:.0f} % of the updates; the average NIS is "
    f"{att_nis.mean():.2f} (expected 3), inside [{band3[0]:.2f}, {band3[1]:.2f}] at {in3:.0f} %. The filter's "
    f"covariance describes its errors, the yaw it cannot observe included."))

# %% [markdown]
# The next lesson grows this filter into the MSCKF: velocity, position and the accelerometer bias join the state,
# and camera poses join it at every image.
#
# ## Summary
#
# * A Kalman filter carries a Gaussian $\mathcal N(\mathbf x, P)$: **predict** with $\mathbf x = F\mathbf x$,
#   $P = FPF^T + Q$; **update** with the innovation $\mathbf y = \mathbf z - H\mathbf x$, its covariance
#   $S = HPH^T + R$, the gain $K = PH^TS^{-1}$ and the Joseph-form $P$. A few lines of NumPy do it, and
#   `filterpy.kalman.KalmanFilter` gives the same numbers.
# * $Q$ is a model. The continuous white-acceleration model (spectral density $q$) discretises exactly by Van
#   Loan's matrix exponential, or in closed form $q[[\Delta t^3/3, \Delta t^2/2], [\Delta t^2/2, \Delta t]]$;
#   `Q_discrete_white_noise` is the piecewise-constant model, of rank one, whose `var` is a variance (m²/s⁴), not a
#   spectral density.
# * **NEES** (needs the truth) and **NIS** (needs only the data) are $\chi^2$-distributed for a consistent filter;
#   averaged over Monte-Carlo runs they must sit inside the $\chi^2$ band. An under-estimated $Q$ drives the NEES
#   above it (over-confident), an over-estimated one below (pessimistic); the NIS reacts much less.
# * A **chi-square gate** rejects a measurement whose NIS exceeds a $\chi^2$ quantile; it stops outliers, at the
#   price of rejecting a fraction $1 - p$ of the good measurements.
# * An **error-state EKF** keeps the quaternion outside the filter and estimates a 3-D attitude error
#   $\delta\boldsymbol\theta$ (with $\bar q = \delta\bar q\otimes\hat{\bar q}$) and the bias error; gravity corrects tilt and,
#   through the motion, the gyro bias, but never the yaw about gravity.
#
# ## Exercises
#
# 1. Drop the measurements between $t = 4$ s and $t = 6$ s of the 1-D run (call `kf.update(None)`, which keeps the
#    prior). How does the position σ grow in the gap, and how fast does it come back?
#
#    *Hint:* run `kf = KalmanFilter(dim_x=2, dim_z=1)` as in section 2 and, inside the loop,
#    `kf.update(None if 4.0 < t[k] <= 6.0 else zs[k])`; plot `np.sqrt(P[:, 0, 0])` against `t`.
# 2. The band of section 2 stops shrinking: $P$ converges to a steady state. Compute it directly from the discrete
#    algebraic Riccati equation and compare with the filter's $P$ and gain after 10 s.
#
#    *Hint:* `scipy.linalg.solve_discrete_are(F.T, H.T, Q, R)` returns the steady *prior* covariance $\bar P$; the
#    gain is `P_bar @ H.T @ np.linalg.inv(H @ P_bar @ H.T + R)` and the posterior `(np.eye(2) - K @ H) @ P_bar`.
# 3. With the right $Q$, how many good measurements does the gate reject at $p = 0.99$ and at $p = 0.95$ (the
#    MSCKF's default) over the Monte-Carlo runs of section 4? Is it the rate you expect?
#
#    *Hint:* collect `y[0] ** 2 / S[0, 0]` for every run and step with `Q_vl`, and count
#    `(nis > chi2.ppf(p, 1)).mean()`.
# 4. Let the IMU turn about the vertical only: `simulate_rotating_imu(30.0, 100.0, noise, rng,
#    rate_amplitude=(0.0, 0.0, 1.0))`. Which bias component does the filter fail to learn, and what happens to the
#    yaw σ?
#
#    *Hint:* run `run_filter(start_filter(data, rng), data)` and print `np.sqrt(np.diagonal(run.P[-1]))` and the
#    last `run.errors`; compare the bias σ of the three axes with `noise.gyro_bias_init_sigma`.
# 5. Add a second reference direction, a magnetometer that sees a known horizontal field
#    $\mathbf m_G = [1, 0, 0]$ with noise 0.01 per axis, at 10 Hz after each accelerometer update. Does the yaw σ
#    now converge?
#
#    *Hint:* the measurement is `z = quat_to_rot(q_true) @ m_G + noise`; its $H$ has the same form as gravity's:
#    `z_hat = quat_to_rot(kf.q_GtoI) @ m_G`, `H = np.zeros((3, 6)); H[:, :3] = skew(z_hat)` (`skew` from
#    `evio_lib.geometry.rotation`); update with
#    `dx, kf.P = kalman_update(kf.P, H, z - z_hat, 0.01**2)` (from `evio_lib.msckf.update`) and correct as
#    `AttitudeFilter.update` does.
#
# Worked solutions, with the code to run: [docs/solutions/10_kalman_filter.md](../docs/solutions/10_kalman_filter.md).
