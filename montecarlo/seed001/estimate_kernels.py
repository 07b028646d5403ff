"""Compiled building blocks of the seed 001 estimation (numba).

Each kernel computes what a literal numpy function of :mod:`montecarlo.seed001.estimate` or
:mod:`montecarlo.seed001.linear_model` computes, in a loop over time instead of over whole
arrays, and is tested equal to it to about 1e-12 on the same inputs:

* :func:`spline_at` - the cubic spline of the gyro output at the Gauss points
  (``scipy.interpolate.CubicSpline``);
* :func:`predicted_pixels` - the image of the target predicted from the gyro output, the
  carrier's attitude a prefix product of Magnus steps, for either camera mount and any aim
  point (:func:`montecarlo.seed001.estimate.predict_los` after its spline);
* :func:`drift_rows` - the first-order drift model integrated over time
  (:func:`montecarlo.seed001.linear_model.drift_matrix`);
* :func:`rls_pass` - one pass of :func:`montecarlo.seed001.estimate.recursive_least_squares`,
  and :func:`walk_transition` - the turn of its random walk.

The simulator's kernels are in :mod:`montecarlo.seed001.simulate_kernels`.

Arrays have one batch axis (trials), first unless a kernel says otherwise; callers flatten
theirs. Per-step matrices are never stored for the whole run: arrays of them for a batch of runs
take tens of MB, and touching fresh memory costs more than the arithmetic (the current step's,
for all runs of a batch, fit in the processor's cache). No fastmath: the kernels keep IEEE
arithmetic and differ from the numpy path only in the order of operations.

References
----------
seed 001: patent CN102288133B, eqs. (1)-(6), claim 1 (third step).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from montecarlo.jit import one_layout

SERIES_ANGLE_SQ = 2.5e-3
"""Below this squared step angle [rad^2] (0.05 rad) the quaternion of a rotation vector comes
from its Taylor series (terms up to angle^8; the first omitted term is below 3e-23)."""


@one_layout
@nb.njit(cache=True, nogil=True)
def spline_at(t, y, g1, g2):  # pragma: no cover - compiled
    """Not-a-knot cubic spline of ``y(t)`` at two points inside each interval.

    ``scipy.interpolate.CubicSpline(t, y, axis=1)`` evaluated at ``g1`` and ``g2``: the slopes
    solve scipy's tridiagonal system (here by elimination without pivoting, for ``N >= 4``),
    the piecewise polynomials are scipy's.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Increasing.
    y : ndarray, shape (B, N, c)
    g1, g2 : ndarray, shape (N - 1,)
        Points of interval ``[t_k, t_{k+1}]``.

    Returns
    -------
    ndarray, shape (N - 1, c, B), twice
        Trials last, as :func:`predicted_pixels` takes them.
    """
    n_b, n, n_c = y.shape[0], y.shape[1], y.shape[2]
    dx = np.diff(t)
    lower, diag, upper = np.empty(n), np.empty(n), np.empty(n)
    diag[0], upper[0] = dx[1], t[2] - t[0]
    for i in range(1, n - 1):
        lower[i], diag[i], upper[i] = dx[i], 2 * (dx[i - 1] + dx[i]), dx[i - 1]
    lower[n - 1], diag[n - 1] = t[n - 1] - t[n - 3], dx[n - 3]
    d0, d1 = t[2] - t[0], t[n - 1] - t[n - 3]
    slope, rhs, c_up, s = np.empty(n - 1), np.empty(n), np.empty(n), np.empty(n)
    out1, out2 = np.empty((n - 1, n_c, n_b)), np.empty((n - 1, n_c, n_b))
    for b in range(n_b):
        for c in range(n_c):
            for i in range(n - 1):
                slope[i] = (y[b, i + 1, c] - y[b, i, c]) / dx[i]
            rhs[0] = ((dx[0] + 2 * d0) * dx[1] * slope[0] + dx[0] ** 2 * slope[1]) / d0
            for i in range(1, n - 1):
                rhs[i] = 3 * (dx[i] * slope[i - 1] + dx[i - 1] * slope[i])
            rhs[n - 1] = (dx[n - 2] ** 2 * slope[n - 3]
                          + (2 * d1 + dx[n - 2]) * dx[n - 3] * slope[n - 2]) / d1
            c_up[0] = upper[0] / diag[0]  # forward elimination
            s[0] = rhs[0] / diag[0]
            for i in range(1, n):
                m = diag[i] - lower[i] * c_up[i - 1]
                c_up[i] = upper[i] / m
                s[i] = (rhs[i] - lower[i] * s[i - 1]) / m
            for i in range(n - 2, -1, -1):  # back substitution
                s[i] -= c_up[i] * s[i + 1]
            for i in range(n - 1):
                tt = (s[i] + s[i + 1] - 2 * slope[i]) / dx[i]
                p0, p1, p2, p3 = tt / dx[i], (slope[i] - s[i]) / dx[i] - tt, s[i], y[b, i, c]
                for g, out in ((g1[i], out1), (g2[i], out2)):
                    z = g - t[i]
                    out[i, c, b] = p3 + p2 * z + p1 * (z * z) + p0 * (z * z * z)
    return out1, out2


@nb.njit(cache=True, nogil=True, inline="always")
def _magnus_vector(hh, cc, wa, wb, T, bias, b):  # pragma: no cover - compiled
    """Rotation vector of one step of run ``b`` in :func:`predicted_pixels`: ``hh (r1 + r2)
    + cc r1 x r2`` with ``r = T (w - bias)`` (all arrays with the runs last)."""
    u0, u1, u2 = wa[0, b] - bias[0, b], wa[1, b] - bias[1, b], wa[2, b] - bias[2, b]
    x0 = T[0, b] * u0 + T[1, b] * u1 + T[2, b] * u2
    x1 = T[3, b] * u0 + T[4, b] * u1 + T[5, b] * u2
    x2 = T[6, b] * u0 + T[7, b] * u1 + T[8, b] * u2
    u0, u1, u2 = wb[0, b] - bias[0, b], wb[1, b] - bias[1, b], wb[2, b] - bias[2, b]
    y0 = T[0, b] * u0 + T[1, b] * u1 + T[2, b] * u2
    y1 = T[3, b] * u0 + T[4, b] * u1 + T[5, b] * u2
    y2 = T[6, b] * u0 + T[7, b] * u1 + T[8, b] * u2
    return (hh * (x0 + y0) + cc * (x1 * y2 - x2 * y1),
            hh * (x1 + y1) + cc * (x2 * y0 - x0 * y2),
            hh * (x2 + y2) + cc * (x0 * y1 - x1 * y0))


@one_layout
@nb.njit(cache=True, nogil=True)
def predicted_pixels(h, w1, w2, transform, bias, attitude_of, c_eta, s_eta, c_eps, s_eps,
                     installation, offsets, camera_of, aim, k_x, k_z, steps, out,
                     diff):  # pragma: no cover - compiled
    """Image of a fixed target imaged at ``aim`` at ``t_0``, for several sets of parameters.

    The carrier's attitude ``R_k = C_{b_k}^{b_0}`` is the prefix product of the steps'
    rotations; each step turns by the fourth-order Magnus vector ``h/2 (r1 + r2) +
    sqrt(3)/12 h^2 r1 x r2`` of the rate ``r = transform (w - bias)`` at its two Gauss points,
    made a matrix through its quaternion (as ``scipy.spatial.transform.Rotation``). The camera
    is ``C_k = M R_x(eps_k + o_eps) R_z(eta_k + o_eta)`` with ``M`` the set's installation
    matrix and ``[o_eta, o_eps]`` its offsets (patent mount, eq. (2): ``M = R_y(dpy)``, offsets
    ``[dz, dpx]``; inner-gimbal mount: ``M = R_y(dpy) R_x(dpx) R_z(dpz)``, offsets
    ``[-dgz, 0]``). The target is ``C_0^T d`` with ``d`` the pinhole's direction of ``aim``,
    its direction ``u_k = C_k R_k^T target`` and its image ``x = [k_x u_x / u_y,
    k_z u_z / u_y]``.

    All runs of the batch advance together, one step for all: the innermost loops run over the
    runs (trials last in the time series and in the kernel's own state), so the processor
    computes several runs with one vector instruction. A step angle above
    ``sqrt(SERIES_ANGLE_SQ)`` takes sine and cosine in a second, scalar loop.

    Parameters
    ----------
    h : ndarray, shape (N - 1,) [s]
        Step lengths.
    w1, w2 : ndarray, shape (N - 1, 3, B) [rad/s]
        Rate at ``t_mid -/+ h sqrt(3)/6`` of each step (:func:`spline_at`).
    transform : ndarray, shape (S, B, 3, 3)
    bias : ndarray, shape (S, B, 3) [rad/s]
    attitude_of : ndarray of int, shape (S,)
        Set whose attitude set ``s`` uses (``s`` itself, or an earlier set with the same
        transform and bias).
    c_eta, s_eta, c_eps, s_eps : ndarray, shape (N, B)
        Cosines and sines of the gimbal angles (the camera's angles follow by the sum formulas).
    installation : ndarray, shape (S, B, 3, 3)
        ``M`` of each set.
    offsets : ndarray, shape (S, B, 2) [rad]
        ``[o_eta, o_eps]`` of each set.
    camera_of : ndarray of int, shape (S,)
        Set whose camera set ``s`` uses (``s`` itself, or an earlier set with the same
        installation and offsets).
    aim : ndarray, shape (S, B, 2) [px]
        Image of the target at ``t_0``.
    k_x, k_z : float [px]
    steps : ndarray, shape (S,)
        0 for set 0; else set ``s`` gives the forward difference ``(x_s - x_0) / step_s``.
    out : ndarray, shape (B, N, 2)
        Filled with the image of set 0 [px].
    diff : ndarray, shape (B, N, 2, S - 1)
        Filled with the forward differences of the other sets (contiguous, as
        :func:`rls_pass` reads its rows fastest that way).

    References
    ----------
    seed 001, eqs. (1)-(2).
    """
    n_s, n_b, n = offsets.shape[0], out.shape[0], out.shape[1]
    T = np.empty((n_s, 9, n_b))
    bs = np.empty((n_s, 3, n_b))
    M = np.empty((n_s, 9, n_b))
    tr = np.empty((n_s, 4, n_b))
    target = np.empty((n_s, 3, n_b))
    R = np.empty((n_s, 9, n_b))
    C = np.empty((n_s, 9, n_b))
    q = np.empty((4, n_b))  # quaternion of each run's step
    x0 = np.empty(n_b)
    z0 = np.empty(n_b)
    c0 = np.sqrt(3.0) / 12.0
    for i in range(n_s):
        for b in range(n_b):
            for r in range(3):
                bs[i, r, b] = bias[i, b, r]
                for c in range(3):
                    T[i, 3 * r + c, b] = transform[i, b, r, c]
                    M[i, 3 * r + c, b] = installation[i, b, r, c]
            for j in range(2):
                tr[i, 2 * j, b] = np.cos(offsets[i, b, j])
                tr[i, 2 * j + 1, b] = np.sin(offsets[i, b, j])
            for j in range(9):
                R[i, j, b] = 1.0 if j % 4 == 0 else 0.0
    for k in range(n):
        if k > 0:
            hk = h[k - 1]
            hh, cc = 0.5 * hk, c0 * (hk * hk)
            wa, wb = w1[k - 1], w2[k - 1]
            for i in range(n_s):
                if attitude_of[i] != i:
                    continue
                Ti, bi, Ri = T[i], bs[i], R[i]
                big = False
                for b in range(n_b):
                    vx, vy, vz = _magnus_vector(hh, cc, wa, wb, Ti, bi, b)
                    a2 = vx * vx + vy * vy + vz * vz
                    scale = 0.5 + a2 * (-1.0 / 48.0 + a2 * (1.0 / 3840.0 + a2 * (
                        -1.0 / 645120.0 + a2 / 185794560.0)))
                    q[3, b] = 1.0 + a2 * (-1.0 / 8.0 + a2 * (1.0 / 384.0 + a2 * (
                        -1.0 / 46080.0 + a2 / 10321920.0)))
                    q[0, b], q[1, b], q[2, b] = scale * vx, scale * vy, scale * vz
                    big |= a2 >= SERIES_ANGLE_SQ
                if big:  # sine and cosine where the series is not exact
                    for b in range(n_b):
                        vx, vy, vz = _magnus_vector(hh, cc, wa, wb, Ti, bi, b)
                        a2 = vx * vx + vy * vy + vz * vz
                        if a2 >= SERIES_ANGLE_SQ:
                            angle = np.sqrt(a2)
                            scale = np.sin(0.5 * angle) / angle
                            q[3, b] = np.cos(0.5 * angle)
                            q[0, b], q[1, b], q[2, b] = scale * vx, scale * vy, scale * vz
                for b in range(n_b):
                    qx, qy, qz, qw = q[0, b], q[1, b], q[2, b], q[3, b]
                    s00 = qx * qx - qy * qy - qz * qz + qw * qw
                    s01 = 2.0 * (qx * qy - qz * qw)
                    s02 = 2.0 * (qx * qz + qy * qw)
                    s10 = 2.0 * (qx * qy + qz * qw)
                    s11 = -qx * qx + qy * qy - qz * qz + qw * qw
                    s12 = 2.0 * (qy * qz - qx * qw)
                    s20 = 2.0 * (qx * qz - qy * qw)
                    s21 = 2.0 * (qy * qz + qx * qw)
                    s22 = -qx * qx - qy * qy + qz * qz + qw * qw
                    for r in range(3):
                        a0, a1, a2 = Ri[3 * r, b], Ri[3 * r + 1, b], Ri[3 * r + 2, b]
                        Ri[3 * r, b] = a0 * s00 + a1 * s10 + a2 * s20
                        Ri[3 * r + 1, b] = a0 * s01 + a1 * s11 + a2 * s21
                        Ri[3 * r + 2, b] = a0 * s02 + a1 * s12 + a2 * s22
        ce_, se_, ca_, sa_ = c_eta[k], s_eta[k], c_eps[k], s_eps[k]
        for i in range(n_s):
            if camera_of[i] != i:
                continue
            tri, Mi, Ci = tr[i], M[i], C[i]
            for b in range(n_b):
                ca_o, sa_o, ce_o, se_o = tri[0, b], tri[1, b], tri[2, b], tri[3, b]
                cp = ce_[b] * ca_o - se_[b] * sa_o
                sp = se_[b] * ca_o + ce_[b] * sa_o
                ct = ca_[b] * ce_o - sa_[b] * se_o
                st = sa_[b] * ce_o + ca_[b] * se_o
                g0, g1, g2 = cp, sp, 0.0
                g3, g4, g5 = -ct * sp, ct * cp, st
                g6, g7, g8 = st * sp, -st * cp, ct
                for r in range(3):
                    m0, m1, m2 = Mi[3 * r, b], Mi[3 * r + 1, b], Mi[3 * r + 2, b]
                    Ci[3 * r, b] = m0 * g0 + m1 * g3 + m2 * g6
                    Ci[3 * r + 1, b] = m0 * g1 + m1 * g4 + m2 * g7
                    Ci[3 * r + 2, b] = m0 * g2 + m1 * g5 + m2 * g8
        if k == 0:
            for i in range(n_s):
                Ci = C[camera_of[i]]
                for b in range(n_b):
                    d0, d2 = aim[i, b, 0] / k_x, aim[i, b, 1] / k_z
                    norm = np.sqrt(d0 * d0 + 1.0 + d2 * d2)
                    d0, d1, d2 = d0 / norm, 1.0 / norm, d2 / norm
                    target[i, 0, b] = Ci[0, b] * d0 + Ci[3, b] * d1 + Ci[6, b] * d2
                    target[i, 1, b] = Ci[1, b] * d0 + Ci[4, b] * d1 + Ci[7, b] * d2
                    target[i, 2, b] = Ci[2, b] * d0 + Ci[5, b] * d1 + Ci[8, b] * d2
        for i in range(n_s):
            Ci, Ri, ti = C[camera_of[i]], R[attitude_of[i]], target[i]
            st_i = steps[i]
            for b in range(n_b):
                t0, t1, t2 = ti[0, b], ti[1, b], ti[2, b]
                v0 = Ri[0, b] * t0 + Ri[3, b] * t1 + Ri[6, b] * t2
                v1 = Ri[1, b] * t0 + Ri[4, b] * t1 + Ri[7, b] * t2
                v2 = Ri[2, b] * t0 + Ri[5, b] * t1 + Ri[8, b] * t2
                u0 = Ci[0, b] * v0 + Ci[1, b] * v1 + Ci[2, b] * v2
                u1 = Ci[3, b] * v0 + Ci[4, b] * v1 + Ci[5, b] * v2
                u2 = Ci[6, b] * v0 + Ci[7, b] * v1 + Ci[8, b] * v2
                x, z = k_x * u0 / u1, k_z * u2 / u1
                if i == 0:
                    x0[b], z0[b] = x, z
                    out[b, k, 0], out[b, k, 1] = x, z
                else:
                    diff[b, k, 0, i - 1] = (x - x0[b]) / st_i
                    diff[b, k, 1, i - 1] = (z - z0[b]) / st_i


@one_layout
@nb.njit(cache=True, nogil=True)
def rls_pass(rows, obs, prior_mean, prior_cov, noise_var, forgetting, walk_transition,
             walk_var):  # pragma: no cover - compiled
    """One recursive-least-squares pass over time, a Kalman update per step.

    The model of :func:`montecarlo.seed001.estimate.recursive_least_squares`:
    ``y_k = A_k x + w_k + v_k`` with ``A_k = [rows_k, I_2]``, the offset ``w`` (the last two
    states) a random walk ``w_k = F_k w_{k-1} + q_k``, ``q_k ~ N(0, diag(walk_var_k))``.

    Parameters
    ----------
    rows : ndarray, shape (B, N, 2, p)
    obs : ndarray, shape (B, N, 2)
    prior_mean : ndarray, shape (B, p + 2)
    prior_cov : ndarray, shape (B, p + 2, p + 2)
    noise_var : float
    forgetting : float in (0, 1]
    walk_transition : ndarray, shape (B, N, 2, 2)
    walk_var : ndarray, shape (B, N, 2)

    Returns
    -------
    mean : ndarray, shape (B, p + 2)
    cov : ndarray, shape (B, p + 2, p + 2)

    References
    ----------
    seed 001, claim 1, third step (recursive least squares).
    """
    n_b, n, p = rows.shape[0], rows.shape[1], rows.shape[3]
    q = p + 2
    X = prior_mean.copy()
    Ps = prior_cov.copy()
    pat = np.empty((q, 2))
    K = np.empty((q, 2))
    for b in range(n_b):
        x = X[b]
        P = Ps[b]
        for k in range(n):
            if k > 0:
                F = walk_transition[b, k]
                w0, w1 = x[p], x[p + 1]
                x[p] = F[0, 0] * w0 + F[0, 1] * w1
                x[p + 1] = F[1, 0] * w0 + F[1, 1] * w1
                for j in range(q):
                    a, c = P[p, j], P[p + 1, j]
                    P[p, j] = F[0, 0] * a + F[0, 1] * c
                    P[p + 1, j] = F[1, 0] * a + F[1, 1] * c
                for i in range(q):
                    a, c = P[i, p], P[i, p + 1]
                    P[i, p] = a * F[0, 0] + c * F[0, 1]
                    P[i, p + 1] = a * F[1, 0] + c * F[1, 1]
                P[p, p] += walk_var[b, k, 0]
                P[p + 1, p + 1] += walk_var[b, k, 1]
            if forgetting != 1.0:
                for i in range(q):
                    for j in range(q):
                        P[i, j] /= forgetting
            A = rows[b, k]
            for i in range(q):
                s0 = P[i, p]
                s1 = P[i, p + 1]
                for j in range(p):
                    s0 += P[i, j] * A[0, j]
                    s1 += P[i, j] * A[1, j]
                pat[i, 0] = s0
                pat[i, 1] = s1
            S00 = pat[p, 0] + noise_var
            S01 = pat[p, 1]
            S10 = pat[p + 1, 0]
            S11 = pat[p + 1, 1] + noise_var
            r0 = obs[b, k, 0] - x[p]
            r1 = obs[b, k, 1] - x[p + 1]
            for j in range(p):
                S00 += A[0, j] * pat[j, 0]
                S01 += A[0, j] * pat[j, 1]
                S10 += A[1, j] * pat[j, 0]
                S11 += A[1, j] * pat[j, 1]
                r0 -= A[0, j] * x[j]
                r1 -= A[1, j] * x[j]
            det = S00 * S11 - S01 * S10
            i00, i01, i10, i11 = S11 / det, -S01 / det, -S10 / det, S00 / det
            for i in range(q):
                K[i, 0] = pat[i, 0] * i00 + pat[i, 1] * i10
                K[i, 1] = pat[i, 0] * i01 + pat[i, 1] * i11
            for i in range(q):
                x[i] += K[i, 0] * r0 + K[i, 1] * r1
            for i in range(q):  # P - K PAt^T, kept exactly symmetric
                k0, k1 = K[i, 0], K[i, 1]
                for j in range(i + 1):
                    v = P[i, j] - (k0 * pat[j, 0] + k1 * pat[j, 1])
                    P[i, j] = v
                    P[j, i] = v
    return X, Ps


@one_layout
@nb.njit(cache=True, nogil=True)
def walk_transition(J):  # pragma: no cover - compiled
    """``F_k = J_k J_{k-1}^-1`` (``F_0 = I``), the turn of the LOS walk in
    :func:`montecarlo.seed001.estimate.estimate`; the 2 x 2 inverse by formula.

    Parameters
    ----------
    J : ndarray, shape (B, N, 2, 2) [px per px]
        The aim point's Jacobian at each sample.

    Returns
    -------
    ndarray, shape (B, N, 2, 2)

    References
    ----------
    seed 001, claim 1, third step (the state's random walk).
    """
    n_b, n = J.shape[0], J.shape[1]
    F = np.empty((n_b, n, 2, 2))
    for b in range(n_b):
        for k in range(n):
            j = k - 1 if k > 0 else 0
            a, c, d, e = J[b, j, 0, 0], J[b, j, 0, 1], J[b, j, 1, 0], J[b, j, 1, 1]
            det = a * e - c * d
            i00, i01, i10, i11 = e / det, -c / det, -d / det, a / det
            for r in range(2):
                x, y = J[b, k, r, 0], J[b, k, r, 1]
                F[b, k, r, 0] = x * i00 + y * i10
                F[b, k, r, 1] = x * i01 + y * i11
    return F


@one_layout
@nb.njit(cache=True, nogil=True)
def drift_rows(t, gyro, eta, eps, k_x, k_z):  # pragma: no cover - compiled
    """First-order image drift of the target per unit parameter (seed 001, eqs. (5)-(6)).

    :func:`montecarlo.seed001.linear_model.drift_matrix` with its default rate model: the rate
    rows ``[H, G]`` (:func:`~montecarlo.seed001.linear_model.los_rate_matrix`,
    :func:`~montecarlo.seed001.linear_model.bias_rate_matrix`), turned back by the image roll
    ``rho`` (:func:`~montecarlo.seed001.linear_model.image_roll_rate` integrated), integrated,
    turned forward, and scaled to pixels ``[k_x phi_z, -k_z phi_x]``. Trapezoidal sums run in
    the order of ``scipy.integrate.cumulative_trapezoid``.

    Parameters
    ----------
    t : ndarray, shape (N,) [s]
    gyro : ndarray, shape (B, N, 3) [rad/s]
    eta, eps : ndarray, shape (B, N) [rad]
    k_x, k_z : float [px]

    Returns
    -------
    ndarray, shape (B, N, 2, 7) [px per rad, px per rad/s]

    References
    ----------
    seed 001, eqs. (5)-(6), re-derived and integrated over time.
    """
    n_b, n = gyro.shape[0], gyro.shape[1]
    out = np.empty((n_b, n, 2, 7))
    rate = np.empty((2, 7))
    acc = np.empty((2, 7))
    prev = np.empty((2, 7))
    for b in range(n_b):
        acc[:] = 0.0
        rho = roll_prev = 0.0
        for k in range(n):
            wx, wy, wz = gyro[b, k, 0], gyro[b, k, 1], gyro[b, k, 2]
            ce, se = np.cos(eps[b, k]), np.sin(eps[b, k])
            ca, sa = np.cos(eta[b, k]), np.sin(eta[b, k])
            rate[0, 0], rate[0, 1], rate[0, 2] = 0.0, -sa * wz, ca * wz  # seed 001, eq. (6)
            rate[0, 3] = ca * wy - sa * wx
            rate[1, 0] = (sa * wx - ca * wy) / ce  # derived, cf. eq. (6)
            rate[1, 1] = ce * wy + se * ca * wz
            rate[1, 2] = -ce * wx + se * sa * wz
            rate[1, 3] = se * (ca * wx + sa * wy)
            rate[0, 4], rate[0, 5], rate[0, 6] = -ca, -sa, 0.0  # gyro bias
            rate[1, 4], rate[1, 5], rate[1, 6] = -se * sa, se * ca, -ce
            roll = (-sa * wx + ca * wy) / ce
            if k > 0:
                rho += (t[k] - t[k - 1]) * (roll_prev + roll) / 2.0
            roll_prev = roll
            c, s = np.cos(rho), np.sin(rho)
            for j in range(7):
                y0 = c * rate[0, j] + s * rate[1, j]  # R(-rho) rate
                y1 = -s * rate[0, j] + c * rate[1, j]
                if k > 0:
                    d = t[k] - t[k - 1]
                    acc[0, j] += d * (prev[0, j] + y0) / 2.0
                    acc[1, j] += d * (prev[1, j] + y1) / 2.0
                prev[0, j], prev[1, j] = y0, y1
                out[b, k, 0, j] = k_x * (s * acc[0, j] + c * acc[1, j])  # k_x phi_z
                out[b, k, 1, j] = -k_z * (c * acc[0, j] - s * acc[1, j])  # -k_z phi_x
    return out
