"""Exact-kinematics simulator of a gyro indirect-stabilisation run (seed 001, eqs. (1)-(4)).

The carrier rocks, the IMU measures its rate through its installation angles, the gimbal
integrates eq. (4) from the measured rate, and the camera, turned by its own installation
angles, images the target the line of sight aimed at at ``t = 0``. Frames and signs are those of
:mod:`montecarlo.seed001.kinematics`.

References
----------
seed 001: patent CN102288133B, eqs. (1)-(4), claim 1 (second step); docs/references.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.geometry.camera import Camera, pixels_from_direction
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed001 import kernels
from montecarlo.seed001.kinematics import (
    Rocking,
    as_vector,
    batch_shape,
    camera_matrix,
    flat_batch,
    gimbal_rates,
    imu_matrix,
    matvec,
    measured_rate,
)

FloatArray = NDArray[np.float64]


DEFAULT_CAMERA = Camera.from_degrees(5.0, 5.0, 1024, 1024)
"""A narrow-field camera: 5 x 5 deg, 1024 x 1024 pixels (about 85 urad per pixel)."""
# --------------------------------------------------------------------------------------------
# Simulation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Setup:
    """Experiment settings shared by all trials of a batch.

    Parameters
    ----------
    duration : float [s]
    rate : float [Hz]
        Sample rate of the gyro, of the gimbal control and of the camera (one row per sample).
    aim_azimuth, aim_pitch : float [rad]
        Gimbal angles at ``t = 0`` (where the target is).
    camera : Camera
        Pinhole camera of seed 000 (field of view and pixel counts).
    image_noise : float [px]
        Standard deviation of the target's image position, per axis and frame.
    gyro_noise : float [rad/s/sqrt(Hz)]
        White-noise density of each gyro axis; per-sample std ``gyro_noise * sqrt(rate)``.
    """

    duration: float = 60.0
    rate: float = 100.0
    aim_azimuth: float = 0.0
    aim_pitch: float = 0.0
    camera: Camera = DEFAULT_CAMERA
    image_noise: float = 0.1
    gyro_noise: float = 0.0

    @property
    def times(self) -> FloatArray:
        """Sample times ``0, 1/rate, ...`` up to ``duration``, shape (N,) [s]."""
        n = round(self.duration * self.rate) + 1
        return np.arange(n) / self.rate


@dataclass(frozen=True)
class Compensation:
    """Installation angles and gyro bias the stabilisation loop corrects for.

    The loop uses ``w_c = (R_y(dgy) R_x(dgx))^T (w_m - bias)`` as the carrier rate and evaluates
    eq. (4) at ``(eta + delta_z, eps + delta_px)``. Only ``delta_z = dpz - dgz`` is needed: the
    carrier frame turned by ``dgz`` about z makes the compensated loop exact.

    Parameters
    ----------
    angles : array_like, shape (..., 4) [rad]
        ``[delta_px, delta_gx, delta_gy, delta_z]``.
    gyro_bias : array_like, shape (..., 3) [rad/s]
    """

    angles: ArrayLike
    gyro_bias: ArrayLike = 0.0


@dataclass(frozen=True)
class Record:
    """A simulated (or measured) run: the CSV columns, plus the truth when simulated.

    Attributes
    ----------
    t : ndarray, shape (N,) [s]
    gyro : ndarray, shape (..., N, 3) [rad/s]
        IMU output ``w_m`` (IMU axes).
    eta, eps : ndarray, shape (..., N) [rad]
        Gimbal azimuth and pitch angles.
    los_px : ndarray, shape (..., N, 2) [px]
        Measured image position ``[x, z]`` of the target (with image noise).
    los_px_true : ndarray, shape (..., N, 2) [px], or None for measured data
        The same without image noise.
    los_error : ndarray, shape (..., N) [rad], or None for measured data
        True angle between the LOS and the target direction (the stabilisation error).
    """

    t: FloatArray
    gyro: FloatArray
    eta: FloatArray
    eps: FloatArray
    los_px: FloatArray
    los_px_true: FloatArray | None = None
    los_error: FloatArray | None = None


def integrate_gimbal(
    t: ArrayLike,
    omega_stages: ArrayLike,
    eta0: ArrayLike,
    eps0: ArrayLike,
    offset_eta: ArrayLike = 0.0,
    offset_eps: ArrayLike = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Integrate the gimbal angles of eq. (4) with the classical Runge-Kutta method.

    Parameters
    ----------
    t : array_like, shape (N,) [s]
    omega_stages : array_like, shape (..., N - 1, 3, 3) [rad/s]
        Rate used by the loop at ``t_k``, ``t_k + h/2`` and ``t_{k+1}`` of each step (axis -2).
    eta0, eps0 : array_like, shape (...) [rad]
        Initial gimbal angles.
    offset_eta, offset_eps : array_like, shape (...) [rad]
        Added to the angles where eq. (4) is evaluated (compensation of ``delta_z, delta_px``).

    Returns
    -------
    eta, eps : ndarray, shape (..., N) [rad]

    References
    ----------
    seed 001, eq. (4).
    """
    t = np.asarray(t, float)
    w = np.asarray(omega_stages, float)
    h = np.diff(t)
    shape = w.shape[:-3]
    eta = np.empty((*shape, t.size))
    eps = np.empty((*shape, t.size))
    eta[..., 0] = eta0
    eps[..., 0] = eps0

    def f(e, p, omega):
        return gimbal_rates(omega, e + offset_eta, p + offset_eps)  # seed 001, eq. (4)

    for k in range(t.size - 1):
        e, p = eta[..., k], eps[..., k]
        wk = w[..., k, :, :]
        a1, b1 = f(e, p, wk[..., 0, :])
        a2, b2 = f(e + 0.5 * h[k] * a1, p + 0.5 * h[k] * b1, wk[..., 1, :])
        a3, b3 = f(e + 0.5 * h[k] * a2, p + 0.5 * h[k] * b2, wk[..., 1, :])
        a4, b4 = f(e + h[k] * a3, p + h[k] * b3, wk[..., 2, :])
        eta[..., k + 1] = e + h[k] / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        eps[..., k + 1] = p + h[k] / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    return eta, eps


def target_view_compiled(
    rocking_angles: ArrayLike, eta: ArrayLike, eps: ArrayLike, delta_p: ArrayLike
) -> FloatArray:
    """Direction in the camera of the target the LOS aimed at at ``t[0]``, compiled.

    ``u_k = C_b^c(k) C_n^b(k) target`` with ``target`` row y of ``C_n^c(0)``, as in
    :func:`simulate`.

    Parameters
    ----------
    rocking_angles : array_like, shape (..., N, 3) [rad]
        Carrier angles ``[psi, theta, gamma]`` (:meth:`Rocking.angles`).
    eta, eps : array_like, shape (..., N) [rad]
    delta_p : array_like, shape (..., 3) [rad]

    Returns
    -------
    ndarray, shape (..., N, 3)

    References
    ----------
    seed 001, eq. (2).
    """
    rocking_angles, eta, eps = (np.asarray(a, float) for a in (rocking_angles, eta, eps))
    delta_p = as_vector(delta_p)
    shape = np.broadcast_shapes(rocking_angles.shape[:-1], eta.shape, eps.shape,
                                (*delta_p.shape[:-1], 1))
    angles = [rocking_angles[..., i] for i in range(3)] + [
        eta + delta_p[..., 2, None], eps + delta_p[..., 0, None], delta_p[..., 1, None]]
    trig = np.empty((12, *shape))
    for i, a in enumerate(angles):  # numpy's cosines and sines are vectorised
        trig[2 * i], trig[2 * i + 1] = np.cos(a), np.sin(a)
    trig = trig.reshape(12, -1, shape[-1])
    u = np.empty((*trig.shape[1:], 3))
    kernels.target_directions(trig[:6], trig[6:], u)  # seed 001, eq. (2)
    return u.reshape(*shape, 3)


def simulate(
    rocking: Rocking,
    setup: Setup,
    delta_g: ArrayLike,
    delta_p: ArrayLike,
    gyro_bias: ArrayLike = 0.0,
    rng: int | np.random.Generator | None = None,
    compensation: Compensation | None = None,
    reference: bool = False,
) -> Record:
    """Simulate one run (or a batch of runs) with the exact kinematics.

    The carrier rocks (:class:`Rocking`); the IMU, turned by ``delta_g``, measures
    ``w_m = C_b^g w_b + bias + n`` (eq. (1)); ``n`` is white, held constant over each sample
    interval. The gimbal integrates eq. (4) from ``w_m`` (or from the compensated rate) by
    Runge-Kutta at the sample rate, starting at ``(aim_azimuth, aim_pitch)``. The camera, turned
    by ``delta_p`` (eq. (2)), images the target it aimed at at ``t = 0``.

    Parameters
    ----------
    rocking : Rocking
    setup : Setup
    delta_g : array_like, shape (..., 3) [rad]
        IMU installation angles ``[dgx, dgy, dgz]``.
    delta_p : array_like, shape (..., 3) [rad]
        Camera installation angles ``[dpx, dpy, dpz]``.
    gyro_bias : array_like, shape (..., 3) [rad/s]
    rng : int, Generator or None
        Source of gyro and image noise.
    compensation : Compensation or None
        Corrections applied by the stabilisation loop (None: none).
    reference : bool
        Integrate the gimbal by the literal :func:`integrate_gimbal` and turn the target into
        the camera with numpy instead of :func:`kernels.rk4_gimbal` and
        :func:`target_view_compiled` (same results to about 1e-13).

    Returns
    -------
    Record
        Batch shape: the broadcast of the leading shapes of all inputs.

    References
    ----------
    seed 001, eqs. (1)-(4) and the second step of claim 1 (LOS error relative to the aim point).
    """
    rng = np.random.default_rng(rng)
    t = setup.times
    h = 1.0 / setup.rate
    delta_g, delta_p, bias = (as_vector(x) for x in (delta_g, delta_p, gyro_bias))
    batch = batch_shape(delta_g, delta_p, bias, rocking.amplitude, rocking.frequency,
                         rocking.phase)

    # noise-free IMU output at the sample times and at the mid-points of the Runge-Kutta steps
    t_half = np.sort(np.concatenate([t, t[:-1] + 0.5 * h]))
    if reference:
        omega_b = rocking.body_rate(t_half)
        omega_m = measured_rate(omega_b, delta_g[..., None, :], bias[..., None, :])  # eq. (1)
        omega_m = np.broadcast_to(omega_m, (*batch, t_half.size, 3))
    else:
        flat = [flat_batch(a, batch, tail)
                for a, tail in ((rocking.amplitude, (3,)), (rocking.frequency, (3,)),
                                (rocking.phase, (3,)), (imu_matrix(delta_g), (3, 3)),
                                (bias, (3,)))]
        rock_angles, omega_m = (a.reshape(*batch, t_half.size, 3)
                                for a in kernels.rocking_gyro(t_half, *flat))  # eq. (1)
    noise = setup.gyro_noise * np.sqrt(setup.rate) * rng.standard_normal((*batch, t.size, 3))

    # the rate the loop integrates: measured, or corrected by the compensation
    offset_eta = offset_eps = 0.0
    C_gb, loop_bias = np.eye(3), np.zeros(3)
    if compensation is not None:
        angles = np.asarray(compensation.angles, float)
        C_gb = np.swapaxes(mounting_matrix(0.0, angles[..., 1], angles[..., 2]), -1, -2)
        loop_bias = as_vector(compensation.gyro_bias)
        offset_eta, offset_eps = angles[..., 3], angles[..., 0]
    if reference:
        loop_rate, loop_noise = omega_m, noise
        if compensation is not None:
            loop_rate = matvec(C_gb[..., None, :, :], omega_m - loop_bias[..., None, :])
            loop_noise = matvec(C_gb[..., None, :, :], noise)
        stages = np.stack([loop_rate[..., 0:-1:2, :], loop_rate[..., 1::2, :],
                           loop_rate[..., 2::2, :]], axis=-2)
        stages = stages + loop_noise[..., :-1, None, :]  # white noise held over each interval
        eta, eps = integrate_gimbal(t, stages, setup.aim_azimuth, setup.aim_pitch, offset_eta,
                                    offset_eps)
    else:
        flat = [flat_batch(a, batch, tail)
                for a, tail in ((omega_m, (t_half.size, 3)), (noise, (t.size, 3)),
                                (C_gb, (3, 3)), (loop_bias, (3,)), (setup.aim_azimuth, ()),
                                (setup.aim_pitch, ()), (offset_eta, ()), (offset_eps, ()))]
        eta, eps = (a.reshape(*batch, t.size)
                    for a in kernels.rk4_gimbal(np.diff(t), *flat))  # seed 001, eq. (4)

    # camera attitude, target and its image
    if reference:
        C_nb = rocking.attitude(t)
        C_nc = np.matmul(camera_matrix(eta, eps, delta_p[..., None, :]), C_nb)  # seed 001, (2)
        target = C_nc[..., 0, 1, :]  # LOS at t = 0 in frame n: row y of C_n^c
        u = matvec(C_nc, target[..., None, :])
    else:
        u = target_view_compiled(rock_angles[..., 0::2, :], eta, eps, delta_p)
    x_px, z_px = pixels_from_direction(u, setup.camera)
    los_true = np.stack([x_px, z_px], axis=-1)
    los = los_true + setup.image_noise * rng.standard_normal(los_true.shape)
    los_error = np.arctan2(np.hypot(u[..., 0], u[..., 2]), u[..., 1])
    gyro = omega_m[..., 0::2, :] + noise
    return Record(t=t, gyro=gyro, eta=eta, eps=eps, los_px=los,
                  los_px_true=los_true, los_error=los_error)
