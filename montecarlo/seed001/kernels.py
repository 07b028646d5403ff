"""Compiled building blocks of the seed 001 simulation and estimation (numba).

Each kernel computes what a literal numpy function of :mod:`montecarlo.seed001.simulate` or
:mod:`montecarlo.seed001.estimate` computes, in a loop over time instead of over whole arrays,
and is tested equal to it to about 1e-12 on the same inputs:

* :func:`magnus_attitude` - the carrier's attitude from its rate at the Gauss points
  (:func:`montecarlo.seed001.estimate.carrier_attitude` after its spline), built on
  :func:`rotation_prefix_product`;
* :func:`target_pixels` - the target's image for given attitudes and camera angles (the end of
  :func:`montecarlo.seed001.estimate.predict_los`);
* :func:`rls_pass` - one pass of :func:`montecarlo.seed001.estimate.recursive_least_squares`;
* :func:`rk4_gimbal` - :func:`montecarlo.seed001.simulate.integrate_gimbal`.

Arrays have one batch axis (trials) first; callers flatten theirs. No fastmath: the kernels keep
IEEE arithmetic, so they differ from the numpy path only in the order of operations.

References
----------
seed 001: patent CN102288133B, eqs. (1)-(4), claim 1 (third step).
"""

from __future__ import annotations

import numba as nb
import numpy as np

SERIES_ANGLE_SQ = 2.5e-3
"""Below this squared step angle [rad^2] (0.05 rad) the quaternion of a rotation vector comes
from its Taylor series (terms up to angle^8; the first omitted term is below 3e-23)."""


@nb.njit(cache=True, nogil=True)
def rotation_prefix_product(steps):  # pragma: no cover - compiled
    """Products ``steps_0 steps_1 ... steps_{k-1}`` for every ``k``, identity first.

    Parameters
    ----------
    steps : ndarray, shape (B, M, 3, 3)

    Returns
    -------
    ndarray, shape (B, M + 1, 3, 3)
    """
    n_b, m = steps.shape[0], steps.shape[1]
    out = np.empty((n_b, m + 1, 3, 3))
    for b in range(n_b):
        for i in range(3):
            for j in range(3):
                out[b, 0, i, j] = 1.0 if i == j else 0.0
        for k in range(m):
            for i in range(3):
                a0, a1, a2 = out[b, k, i, 0], out[b, k, i, 1], out[b, k, i, 2]
                for j in range(3):
                    out[b, k + 1, i, j] = (a0 * steps[b, k, 0, j] + a1 * steps[b, k, 1, j]
                                           + a2 * steps[b, k, 2, j])
    return out


@nb.njit(cache=True, nogil=True)
def magnus_attitude(h, w1, w2, transform, bias):  # pragma: no cover - compiled
    """Attitude ``C_{b_k}^{b_0}`` from the rate at the two Gauss points of each step.

    The rate is ``transform_b (w - bias_b)``; each step turns by the fourth-order Magnus vector
    ``h/2 (r1 + r2) + sqrt(3)/12 h^2 r1 x r2``, made a rotation matrix through its quaternion
    (active, as ``scipy.spatial.transform.Rotation.from_rotvec(...).as_matrix()``).

    Parameters
    ----------
    h : ndarray, shape (M,) [s]
        Step lengths.
    w1, w2 : ndarray, shape (B, M, 3) [rad/s]
        Rates at ``t_mid -/+ h sqrt(3)/6``.
    transform : ndarray, shape (B, 3, 3)
    bias : ndarray, shape (B, 3) [rad/s]

    Returns
    -------
    ndarray, shape (B, M + 1, 3, 3)
    """
    n_b, m = w1.shape[0], w1.shape[1]
    c3 = np.sqrt(3.0) / 12.0
    steps = np.empty((n_b, m, 3, 3))
    r1 = np.empty(3)
    r2 = np.empty(3)
    for b in range(n_b):
        T = transform[b]
        for k in range(m):
            for i in range(3):
                r1[i] = (T[i, 0] * (w1[b, k, 0] - bias[b, 0]) + T[i, 1] * (w1[b, k, 1] - bias[b, 1])
                         + T[i, 2] * (w1[b, k, 2] - bias[b, 2]))
                r2[i] = (T[i, 0] * (w2[b, k, 0] - bias[b, 0]) + T[i, 1] * (w2[b, k, 1] - bias[b, 1])
                         + T[i, 2] * (w2[b, k, 2] - bias[b, 2]))
            hh, cc = 0.5 * h[k], c3 * h[k] * h[k]
            vx = hh * (r1[0] + r2[0]) + cc * (r1[1] * r2[2] - r1[2] * r2[1])
            vy = hh * (r1[1] + r2[1]) + cc * (r1[2] * r2[0] - r1[0] * r2[2])
            vz = hh * (r1[2] + r2[2]) + cc * (r1[0] * r2[1] - r1[1] * r2[0])
            a2 = vx * vx + vy * vy + vz * vz
            if a2 < SERIES_ANGLE_SQ:
                scale = 0.5 + a2 * (-1.0 / 48.0 + a2 * (1.0 / 3840.0 + a2 * (
                    -1.0 / 645120.0 + a2 / 185794560.0)))
                qw = 1.0 + a2 * (-1.0 / 8.0 + a2 * (1.0 / 384.0 + a2 * (
                    -1.0 / 46080.0 + a2 / 10321920.0)))
            else:
                angle = np.sqrt(a2)
                scale = np.sin(0.5 * angle) / angle
                qw = np.cos(0.5 * angle)
            qx, qy, qz = scale * vx, scale * vy, scale * vz
            s = steps[b, k]
            s[0, 0] = qx * qx - qy * qy - qz * qz + qw * qw
            s[1, 1] = -qx * qx + qy * qy - qz * qz + qw * qw
            s[2, 2] = -qx * qx - qy * qy + qz * qz + qw * qw
            s[0, 1] = 2.0 * (qx * qy - qz * qw)
            s[1, 0] = 2.0 * (qx * qy + qz * qw)
            s[0, 2] = 2.0 * (qx * qz + qy * qw)
            s[2, 0] = 2.0 * (qx * qz - qy * qw)
            s[1, 2] = 2.0 * (qy * qz - qx * qw)
            s[2, 1] = 2.0 * (qy * qz + qx * qw)
    return rotation_prefix_product(steps)


@nb.njit(cache=True, nogil=True)
def target_pixels(R, target, ca, sa, ce, se, cr, sr, k_x, k_z):  # pragma: no cover - compiled
    """Image of a fixed target seen through a camera turned by ``R_y(r) R_x(e) R_z(a)``.

    ``u = C (R_k^T target)`` with ``C = mounting_matrix(a_k, e_k, r)`` (seed 001, eq. (2));
    pixels ``[k_x u_x / u_y, k_z u_z / u_y]``.

    Parameters
    ----------
    R : ndarray, shape (B, N, 3, 3)
        Carrier attitudes ``C_{b_k}^{b_0}``.
    target : ndarray, shape (B, 3)
        Target direction in the carrier frame at ``t_0``.
    ca, sa, ce, se : ndarray, shape (B, N)
        Cosine and sine of the azimuth ``a_k`` and pitch ``e_k`` of the camera.
    cr, sr : ndarray, shape (B,)
        Cosine and sine of the roll ``r``.
    k_x, k_z : float [px]

    Returns
    -------
    ndarray, shape (B, N, 2) [px]
    """
    n_b, n = R.shape[0], R.shape[1]
    out = np.empty((n_b, n, 2))
    for b in range(n_b):
        t0, t1, t2 = target[b, 0], target[b, 1], target[b, 2]
        cg, sg = cr[b], sr[b]
        for k in range(n):
            Rk = R[b, k]
            v0 = Rk[0, 0] * t0 + Rk[1, 0] * t1 + Rk[2, 0] * t2
            v1 = Rk[0, 1] * t0 + Rk[1, 1] * t1 + Rk[2, 1] * t2
            v2 = Rk[0, 2] * t0 + Rk[1, 2] * t1 + Rk[2, 2] * t2
            cp, sp, ct, st = ca[b, k], sa[b, k], ce[b, k], se[b, k]
            u0 = (cg * cp - sg * st * sp) * v0 + (cg * sp + sg * st * cp) * v1 - sg * ct * v2
            u1 = -ct * sp * v0 + ct * cp * v1 + st * v2
            u2 = (sg * cp + cg * st * sp) * v0 + (sg * sp - cg * st * cp) * v1 + cg * ct * v2
            out[b, k, 0] = k_x * u0 / u1
            out[b, k, 1] = k_z * u2 / u1
    return out


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
            for i in range(q):
                for j in range(i + 1):
                    a = P[i, j] - (K[i, 0] * pat[j, 0] + K[i, 1] * pat[j, 1])
                    c = P[j, i] - (K[j, 0] * pat[i, 0] + K[j, 1] * pat[i, 1])
                    P[i, j] = P[j, i] = 0.5 * (a + c)
    return X, Ps


@nb.njit(cache=True, nogil=True)
def _gimbal_rates(wx, wy, wz, eta, eps):  # pragma: no cover - compiled
    """(eta', eps') of seed 001, eq. (4); see :func:`montecarlo.seed001.kinematics.gimbal_rates`."""
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    return (-se * sa * wx + se * ca * wy - ce * wz) / ce, -ca * wx - sa * wy


@nb.njit(cache=True, nogil=True)
def rk4_gimbal(h, stages, eta0, eps0, offset_eta, offset_eps):  # pragma: no cover - compiled
    """Gimbal angles of eq. (4) integrated by the classical Runge-Kutta method.

    Parameters
    ----------
    h : ndarray, shape (N - 1,) [s]
    stages : ndarray, shape (B, N - 1, 3, 3) [rad/s]
        Loop rate at ``t_k``, ``t_k + h/2``, ``t_{k+1}`` of each step (axis 2).
    eta0, eps0, offset_eta, offset_eps : ndarray, shape (B,) [rad]

    Returns
    -------
    eta, eps : ndarray, shape (B, N) [rad]

    References
    ----------
    seed 001, eq. (4).
    """
    n_b, m = stages.shape[0], stages.shape[1]
    eta = np.empty((n_b, m + 1))
    eps = np.empty((n_b, m + 1))
    for b in range(n_b):
        e, p = eta0[b], eps0[b]
        oe, op = offset_eta[b], offset_eps[b]
        eta[b, 0], eps[b, 0] = e, p
        for k in range(m):
            w = stages[b, k]
            hk = h[k]
            a1, b1 = _gimbal_rates(w[0, 0], w[0, 1], w[0, 2], e + oe, p + op)
            a2, b2 = _gimbal_rates(w[1, 0], w[1, 1], w[1, 2], e + 0.5 * hk * a1 + oe,
                                   p + 0.5 * hk * b1 + op)
            a3, b3 = _gimbal_rates(w[1, 0], w[1, 1], w[1, 2], e + 0.5 * hk * a2 + oe,
                                   p + 0.5 * hk * b2 + op)
            a4, b4 = _gimbal_rates(w[2, 0], w[2, 1], w[2, 2], e + hk * a3 + oe, p + hk * b3 + op)
            e = e + hk / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
            p = p + hk / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
            eta[b, k + 1], eps[b, k + 1] = e, p
    return eta, eps
