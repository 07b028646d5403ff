"""Compiled building blocks of the seed 001 simulation (numba).

Each kernel computes what a literal numpy function of :mod:`montecarlo.seed001.simulate`
computes, in a loop over time instead of over whole arrays, and is tested equal to it to about
1e-12 on the same inputs:

* :func:`rocking_gyro` - the carrier's rocking and the IMU output of the simulator;
* :func:`target_directions` - the target's direction in the camera (the end of
  :func:`montecarlo.seed001.simulate.simulate`);
* :func:`rk4_gimbal` - :func:`montecarlo.seed001.simulate.integrate_gimbal`.

The estimator's kernels are in :mod:`montecarlo.seed001.estimate_kernels`.

Arrays have one batch axis (trials), first unless a kernel says otherwise; callers flatten
theirs. No fastmath: the kernels keep IEEE arithmetic and differ from the numpy path only in
the order of operations and, in :func:`rk4_gimbal`, in cosines and sines of small turns by
their series.

References
----------
seed 001: patent CN102288133B, eqs. (1)-(4).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from montecarlo.jit import one_layout


@one_layout
@nb.njit(cache=True, nogil=True)
def rocking_gyro(t, amplitude, frequency, phase, imu, bias):  # pragma: no cover - compiled
    """Sinusoidal rocking and the noise-free output of an IMU on the carrier.

    Angles ``a sin(2 pi f t + phase)`` (yaw, pitch, roll; Z-X-Y), the body rate
    ``w_b = [c_g th' - s_g c_th psi', ga' + s_th psi', s_g th' + c_g c_th psi']`` and the IMU
    output ``imu_b w_b + bias_b`` (:class:`montecarlo.seed001.kinematics.Rocking`,
    :func:`montecarlo.seed001.kinematics.measured_rate`).

    Parameters
    ----------
    t : ndarray, shape (M,) [s]
    amplitude, frequency, phase : ndarray, shape (B, 3) [rad], [Hz], [rad]
    imu : ndarray, shape (B, 3, 3)
        ``C_b^g``.
    bias : ndarray, shape (B, 3) [rad/s]

    Returns
    -------
    angles : ndarray, shape (B, M, 3) [rad]
    output : ndarray, shape (B, M, 3) [rad/s]

    References
    ----------
    seed 001, eq. (1).
    """
    n_b, m = amplitude.shape[0], t.size
    angles = np.empty((n_b, m, 3))
    output = np.empty((n_b, m, 3))
    a = np.empty(3)
    w = np.empty(3)
    for b in range(n_b):
        for i in range(3):
            w[i] = 2.0 * np.pi * frequency[b, i]
        M = imu[b]
        for k in range(m):
            for i in range(3):
                arg = w[i] * t[k] + phase[b, i]
                angles[b, k, i] = amplitude[b, i] * np.sin(arg)
                a[i] = amplitude[b, i] * w[i] * np.cos(arg)
            theta, gamma = angles[b, k, 1], angles[b, k, 2]
            cg, sg, ct, st = np.cos(gamma), np.sin(gamma), np.cos(theta), np.sin(theta)
            w0 = cg * a[1] - sg * ct * a[0]
            w1 = a[2] + st * a[0]
            w2 = sg * a[1] + cg * ct * a[0]
            for i in range(3):
                output[b, k, i] = (M[i, 0] * w0 + M[i, 1] * w1 + M[i, 2] * w2) + bias[b, i]
    return angles, output


@nb.njit(cache=True, nogil=True, inline="always")
def _zxy(cp, sp, ct, st, cg, sg):  # pragma: no cover - compiled
    """``R_y(gamma) R_x(theta) R_z(psi)`` from cosines and sines, seed 000, eq. (5)
    (:func:`montecarlo.geometry.rotations.mounting_matrix`); 9 entries, row by row."""
    return (cg * cp - sg * st * sp, cg * sp + sg * st * cp, -sg * ct,
            -ct * sp, ct * cp, st,
            sg * cp + cg * st * sp, sg * sp - cg * st * cp, cg * ct)


@one_layout
@nb.njit(cache=True, nogil=True)
def target_directions(carrier, camera, out):  # pragma: no cover - compiled
    """Direction in the camera of the target its LOS aimed at at ``t_0``.

    ``u_k = C_b^c(k) C_n^b(k) target``, both matrices Z-X-Y (seed 000, eq. (5)), ``target`` row
    y of ``C_b^c(0) C_n^b(0)`` (in frame n).

    Parameters
    ----------
    carrier, camera : ndarray, shape (6, B, N)
        Cosines and sines ``[c_psi, s_psi, c_theta, s_theta, c_gamma, s_gamma]`` of the
        carrier's angles and of the camera's (seed 001, eq. (2)).
    out : ndarray, shape (B, N, 3)
        Filled with the directions.

    References
    ----------
    seed 001, eq. (2).
    """
    for b in range(out.shape[0]):
        n = _zxy(carrier[0, b, 0], carrier[1, b, 0], carrier[2, b, 0], carrier[3, b, 0],
                 carrier[4, b, 0], carrier[5, b, 0])
        c = _zxy(camera[0, b, 0], camera[1, b, 0], camera[2, b, 0], camera[3, b, 0],
                 camera[4, b, 0], camera[5, b, 0])
        t0 = n[0] * c[3] + n[3] * c[4] + n[6] * c[5]  # C_n^b(0)^T (row y of C_b^c(0))
        t1 = n[1] * c[3] + n[4] * c[4] + n[7] * c[5]
        t2 = n[2] * c[3] + n[5] * c[4] + n[8] * c[5]
        for k in range(out.shape[1]):
            n = _zxy(carrier[0, b, k], carrier[1, b, k], carrier[2, b, k], carrier[3, b, k],
                     carrier[4, b, k], carrier[5, b, k])
            c = _zxy(camera[0, b, k], camera[1, b, k], camera[2, b, k], camera[3, b, k],
                     camera[4, b, k], camera[5, b, k])
            v0 = n[0] * t0 + n[1] * t1 + n[2] * t2
            v1 = n[3] * t0 + n[4] * t1 + n[5] * t2
            v2 = n[6] * t0 + n[7] * t1 + n[8] * t2
            out[b, k, 0] = c[0] * v0 + c[1] * v1 + c[2] * v2
            out[b, k, 1] = c[3] * v0 + c[4] * v1 + c[5] * v2
            out[b, k, 2] = c[6] * v0 + c[7] * v1 + c[8] * v2


@nb.njit(cache=True, nogil=True, inline="always")
def _gimbal_rates(wx, wy, wz, ca, sa, ce, se):  # pragma: no cover - compiled
    """(eta', eps') of seed 001, eq. (4), from the cosines and sines of eta and eps; see
    :func:`montecarlo.seed001.kinematics.gimbal_rates`."""
    return (-se * sa * wx + se * ca * wy - ce * wz) / ce, -ca * wx - sa * wy


SMALL_TURN = 0.01
"""Below this turn [rad] :func:`_turned` takes its cosine and sine from their Taylor series
(terms up to the 8th power; the first omitted term is below 3e-24)."""


@nb.njit(cache=True, nogil=True, inline="always")
def _turned(c, s, d, angle):  # pragma: no cover - compiled
    """Cosine and sine of ``angle = a + d`` from those of ``a`` (``c``, ``s``) by the sum
    formulas, or directly when the turn ``d`` [rad] is not small."""
    if abs(d) < SMALL_TURN:
        d2 = d * d
        sd = d * (1.0 + d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0 + d2 * (-1.0 / 5040.0))))
        cd = 1.0 + d2 * (-0.5 + d2 * (1.0 / 24.0 + d2 * (-1.0 / 720.0 + d2 / 40320.0)))
        return c * cd - s * sd, s * cd + c * sd
    return np.cos(angle), np.sin(angle)


@one_layout
@nb.njit(cache=True, nogil=True)
def rk4_gimbal(h, rate, noise, transform, bias, eta0, eps0, offset_eta, offset_eps
               ):  # pragma: no cover - compiled
    """Gimbal angles of eq. (4) integrated by the classical Runge-Kutta method.

    The loop's rate is ``transform_b (rate - bias_b) + transform_b noise_k``: the rate sampled at
    the steps and their mid-points, white noise held over each step. Each step takes the cosines
    and sines of its first stage's angles; its later stages turn them (:func:`_turned`).

    Parameters
    ----------
    h : ndarray, shape (N - 1,) [s]
    rate : ndarray, shape (B, 2 N - 1, 3) [rad/s]
        At ``t_0, t_0 + h_0/2, t_1, ...``.
    noise : ndarray, shape (B, N, 3) [rad/s]
    transform : ndarray, shape (B, 3, 3)
    bias : ndarray, shape (B, 3) [rad/s]
    eta0, eps0, offset_eta, offset_eps : ndarray, shape (B,) [rad]
        Initial angles; offsets added where eq. (4) is evaluated.

    Returns
    -------
    eta, eps : ndarray, shape (B, N) [rad]

    References
    ----------
    seed 001, eq. (4).
    """
    n_b, m = rate.shape[0], (rate.shape[1] - 1) // 2
    eta = np.empty((n_b, m + 1))
    eps = np.empty((n_b, m + 1))
    w = np.empty((3, 3))
    for b in range(n_b):
        T = transform[b]
        e, p = eta0[b], eps0[b]
        oe, op = offset_eta[b], offset_eps[b]
        eta[b, 0], eps[b, 0] = e, p
        for k in range(m):
            n0, n1, n2 = noise[b, k, 0], noise[b, k, 1], noise[b, k, 2]
            for s in range(3):
                r0 = rate[b, 2 * k + s, 0] - bias[b, 0]
                r1 = rate[b, 2 * k + s, 1] - bias[b, 1]
                r2 = rate[b, 2 * k + s, 2] - bias[b, 2]
                for i in range(3):
                    w[s, i] = ((T[i, 0] * r0 + T[i, 1] * r1 + T[i, 2] * r2)
                               + (T[i, 0] * n0 + T[i, 1] * n1 + T[i, 2] * n2))
            hk = h[k]
            ea, pa = e + oe, p + op  # eq. (4) at the stages' angles; the three later stages
            ca, sa, ce, se = np.cos(ea), np.sin(ea), np.cos(pa), np.sin(pa)  # turn the first
            a1, b1 = _gimbal_rates(w[0, 0], w[0, 1], w[0, 2], ca, sa, ce, se)
            ca2, sa2 = _turned(ca, sa, 0.5 * hk * a1, e + 0.5 * hk * a1 + oe)
            ce2, se2 = _turned(ce, se, 0.5 * hk * b1, p + 0.5 * hk * b1 + op)
            a2, b2 = _gimbal_rates(w[1, 0], w[1, 1], w[1, 2], ca2, sa2, ce2, se2)
            ca3, sa3 = _turned(ca, sa, 0.5 * hk * a2, e + 0.5 * hk * a2 + oe)
            ce3, se3 = _turned(ce, se, 0.5 * hk * b2, p + 0.5 * hk * b2 + op)
            a3, b3 = _gimbal_rates(w[1, 0], w[1, 1], w[1, 2], ca3, sa3, ce3, se3)
            ca4, sa4 = _turned(ca, sa, hk * a3, e + hk * a3 + oe)
            ce4, se4 = _turned(ce, se, hk * b3, p + hk * b3 + op)
            a4, b4 = _gimbal_rates(w[2, 0], w[2, 1], w[2, 2], ca4, sa4, ce4, se4)
            e = e + hk / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
            p = p + hk / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
            eta[b, k + 1], eps[b, k + 1] = e, p
    return eta, eps
