"""Gyro indirect stabilisation of seed 001: exact-kinematics simulator and linearised model.

An IMU and a two-axis gimbal (azimuth ``eta`` outer, pitch ``eps`` inner) carrying a camera sit on
a rocking carrier. The gimbal is stabilised *indirectly*: it integrates the rates of eq. (4)
computed from the IMU's measured carrier rate. IMU and camera installation angles make the line
of sight (LOS) drift; the camera sees the drift as the motion of a fixed target in the image.
The estimator that turns the drift back into angles is in
:mod:`montecarlo.stabilization_estimation`.

Frames and sign conventions (all right-handed; every matrix is *passive*, ``C_a^b`` maps
coordinates in a to coordinates in b; ``R_x, R_y, R_z`` are the passive elementary rotations,
``R_z(a) = [[cos a, sin a, 0], [-sin a, cos a, 0], [0, 0, 1]]``, whose first-order forms are the
matrices printed under seed 001, eq. (1)):

``n``  inertial frame, x right, y forward, z up (seed 000's base frame at rest).
``b``  carrier. Rocking angles yaw ``psi`` about z, then pitch ``theta`` about x, then roll
       ``gamma`` about y (intrinsic Z-X-Y, as seed 000):
       ``C_n^b = R_y(gamma) R_x(theta) R_z(psi) = rotations.mounting_matrix(psi, theta, gamma)``.
``g``  IMU: ``C_b^g = R_y(dgy) R_x(dgx) R_z(dgz)`` (seed 001, eq. (1), here with exact rotations).
``p``  gimbal pitch frame: ``C_b^p = R_x(eps) R_z(eta)``; ``eta`` turns about the carrier's z
       (positive: LOS to the left), ``eps`` about the azimuth frame's x (positive: LOS up).
``c``  camera: ``C_b^c = R_y(dpy) R_x(eps + dpx) R_z(eta + dpz)``. This is seed 001, eq. (2):
       the camera's pitch and azimuth installation angles add to the gimbal angles. ``dpy``
       (roll about the LOS), which the patent drops, is applied last; it only turns the image.
LOS    the camera's y axis. Its direction in the carrier frame is
       ``[-sin(eta+dpz) cos(eps+dpx), cos(eta+dpz) cos(eps+dpx), sin(eps+dpx)]``.

Angular rates are body rates in the rotating frame's own axes (``dC_n^b/dt = -[w_b x] C_n^b``).
The IMU measures ``w_m = C_b^g w_b + bias + noise`` [rad/s].

Image: the target is the point the LOS aimed at at ``t = 0``; with ``u`` its direction in frame c,
its image is at ``x_px = k_x u_x / u_y`` (right), ``z_px = k_z u_z / u_y`` (up)
(:func:`montecarlo.camera.pixels_from_direction`). ``los_x_px, los_z_px`` are this image position:
a LOS turned by a small angle ``a`` to the left (about +z) moves the target to ``x_px = +k_x a``;
a LOS turned up by ``a`` (about +x) moves it to ``z_px = -k_z a``.

All functions broadcast: batch axes first, then time, then vector components ``(..., N, 3)``.

References
----------
seed 001: patent CN102288133B (2013), eqs. (1)-(6); NOTES.md, "Seed 001 - cautions".
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import cumulative_trapezoid

from montecarlo.geometry.camera import Camera, pixels_from_direction
from montecarlo.io.table import read_table
from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes
from montecarlo.geometry.rotations import mounting_matrix

FloatArray = NDArray[np.float64]

DEFAULT_CAMERA = Camera.from_degrees(5.0, 5.0, 1024, 1024)
"""A narrow-field camera: 5 x 5 deg, 1024 x 1024 pixels (about 85 urad per pixel)."""

OBSERVABLE_NAMES = ("delta_px", "delta_gx", "delta_gy", "delta_z")
"""The four estimable combinations ``X`` of seed 001, eq. (6); ``delta_z = dpz - dgz``."""


def _vec(*components: ArrayLike) -> FloatArray:
    return np.stack(np.broadcast_arrays(*(np.asarray(c, float) for c in components)), axis=-1)


def _components(x: ArrayLike) -> FloatArray:
    """``x`` as an array with a vector axis of 3 (a scalar is repeated)."""
    return np.asarray(x, float) + np.zeros(3)


def _batch_shape(*vectors: ArrayLike) -> tuple[int, ...]:
    """Broadcast of the leading shapes of arrays whose last axis holds components."""
    return np.broadcast_shapes(*(np.shape(v)[:-1] for v in vectors if np.ndim(v) > 0))


def _matvec(M: ArrayLike, v: ArrayLike) -> FloatArray:
    return np.matmul(M, np.asarray(v, float)[..., None])[..., 0]


# --------------------------------------------------------------------------------------------
# Carrier rocking
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Rocking:
    """Sinusoidal rocking of the carrier about its three axes.

    Each Euler angle is ``amplitude * sin(2 pi frequency t + phase)``.

    Parameters
    ----------
    amplitude : array_like, shape (..., 3) [rad]
        Amplitudes of yaw ``psi`` (about z), pitch ``theta`` (about x), roll ``gamma`` (about y).
    frequency : array_like, shape (..., 3) [Hz]
    phase : array_like, shape (..., 3) [rad]
    """

    amplitude: ArrayLike
    frequency: ArrayLike
    phase: ArrayLike = 0.0

    def _arg(self, t: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        t = np.asarray(t, float)[..., None]
        a = np.asarray(self.amplitude, float)[..., None, :]
        w = 2.0 * np.pi * np.asarray(self.frequency, float)[..., None, :]
        return a, w, w * t + np.asarray(self.phase, float)[..., None, :]

    def angles(self, t: ArrayLike) -> FloatArray:
        """``[psi, theta, gamma]`` at times ``t`` (shape (N,)), shape (..., N, 3) [rad]."""
        a, _, arg = self._arg(t)
        return a * np.sin(arg)

    def angle_rates(self, t: ArrayLike) -> FloatArray:
        """Time derivatives of :meth:`angles`, shape (..., N, 3) [rad/s]."""
        a, w, arg = self._arg(t)
        return a * w * np.cos(arg)

    def attitude(self, t: ArrayLike) -> FloatArray:
        """``C_n^b`` at times ``t``, shape (..., N, 3, 3)."""
        psi, theta, gamma = np.moveaxis(self.angles(t), -1, 0)
        return mounting_matrix(psi, theta, gamma)

    def body_rate(self, t: ArrayLike) -> FloatArray:
        """Carrier angular rate ``w_b`` in carrier axes, shape (..., N, 3) [rad/s].

        ``w_b = R_y(gamma) R_x(theta) [0, 0, psi'] + R_y(gamma) [theta', 0, 0] + [0, gamma', 0]``
        for the Z-X-Y angles of :meth:`attitude`.
        """
        _, theta, gamma = np.moveaxis(self.angles(t), -1, 0)
        dpsi, dtheta, dgamma = np.moveaxis(self.angle_rates(t), -1, 0)
        cg, sg, ct, st = np.cos(gamma), np.sin(gamma), np.cos(theta), np.sin(theta)
        return _vec(cg * dtheta - sg * ct * dpsi, dgamma + st * dpsi, sg * dtheta + cg * ct * dpsi)


# --------------------------------------------------------------------------------------------
# The patent's equations with exact rotations
# --------------------------------------------------------------------------------------------


def imu_matrix(delta_g: ArrayLike) -> FloatArray:
    """``C_b^g = R_y(dgy) R_x(dgx) R_z(dgz)``, shape (..., 3, 3).

    Parameters
    ----------
    delta_g : array_like, shape (..., 3) [rad]
        IMU installation angles ``[dgx, dgy, dgz]``.

    References
    ----------
    seed 001, eq. (1) (printed to first order in the angles).
    """
    d = _components(delta_g)
    return mounting_matrix(d[..., 2], d[..., 0], d[..., 1])  # seed 001, eq. (1)


def measured_rate(omega_b: ArrayLike, delta_g: ArrayLike, bias: ArrayLike = 0.0) -> FloatArray:
    """IMU output without noise, ``w_bm = C_b^g w_b + bias``, shape (..., 3) [rad/s].

    References
    ----------
    seed 001, eq. (1) (the patent has no bias term).
    """
    return _matvec(imu_matrix(delta_g), omega_b) + bias  # seed 001, eq. (1)


def camera_matrix(eta: ArrayLike, eps: ArrayLike, delta_p: ArrayLike = 0.0) -> FloatArray:
    """``C_b^c = R_y(dpy) R_x(eps + dpx) R_z(eta + dpz)``, shape (..., 3, 3).

    Parameters
    ----------
    eta, eps : array_like [rad]
        Gimbal azimuth and pitch angles.
    delta_p : array_like, shape (..., 3) [rad]
        Camera installation angles ``[dpx, dpy, dpz]``.

    References
    ----------
    seed 001, eq. (2) (the rotations it applies to the carrier rate).
    """
    d = _components(delta_p)
    return mounting_matrix(np.asarray(eta) + d[..., 2], np.asarray(eps) + d[..., 0], d[..., 1])


def gimbal_rates(omega: ArrayLike, eta: ArrayLike, eps: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Indirect-stabilisation gimbal rates computed from a carrier rate.

    Parameters
    ----------
    omega : array_like, shape (..., 3) [rad/s]
        Carrier rate in carrier axes (in use: the IMU's measured rate).
    eta, eps : array_like [rad]
        Gimbal azimuth and pitch angles.

    Returns
    -------
    eta_dot, eps_dot : ndarray [rad/s]
        ``eps' = -cos(eta) w_x - sin(eta) w_y`` and
        ``eta' = sec(eps) (-sin(eps) sin(eta) w_x + sin(eps) cos(eta) w_y - cos(eps) w_z)``;
        with them the x and z components of the gimbal frame's rate vanish (LOS fixed).

    References
    ----------
    seed 001, eq. (4).
    """
    omega = np.asarray(omega, float)
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    eps_dot = -ca * wx - sa * wy  # seed 001, eq. (4)
    eta_dot = (-se * sa * wx + se * ca * wy - ce * wz) / ce  # seed 001, eq. (4)
    return eta_dot, eps_dot


def camera_rate(
    omega_b: ArrayLike,
    eta: ArrayLike,
    eps: ArrayLike,
    eta_dot: ArrayLike,
    eps_dot: ArrayLike,
    delta_p: ArrayLike = 0.0,
) -> FloatArray:
    """Angular rate of the camera in camera axes, shape (..., 3) [rad/s].

    ``w_i = R_y(dpy) [R_x(eps + dpx) (R_z(eta + dpz) w_b + [0, 0, eta']) + [eps', 0, 0]]``.
    Components x and z turn the LOS (the stabilisation error rate); y rolls the image.

    The patent prints the pitch-rate vector as ``[0 0 eps']``; the pitch axis is x, so it is
    ``[eps' 0 0]`` (only then do the rates of eq. (4) stabilise the LOS).

    References
    ----------
    seed 001, eqs. (2)-(3).
    """
    d = _components(delta_p)
    zero = np.zeros_like(np.asarray(eta_dot, float))
    inner = _matvec(mounting_matrix(np.asarray(eta) + d[..., 2], 0.0, 0.0), omega_b)
    inner = inner + _vec(zero, zero, eta_dot)  # seed 001, eqs. (2)-(3)
    outer = _matvec(mounting_matrix(0.0, np.asarray(eps) + d[..., 0], 0.0), inner)
    outer = outer + _vec(eps_dot, zero, zero)  # seed 001, eqs. (2)-(3), pitch rate about x
    return _matvec(mounting_matrix(0.0, 0.0, d[..., 1]), outer)


def los_direction(eta: ArrayLike, eps: ArrayLike) -> FloatArray:
    """Unit LOS of a gimbal at (eta, eps) in carrier axes, shape (..., 3)."""
    ce = np.cos(eps)
    return _vec(-np.sin(eta) * ce, np.cos(eta) * ce, np.sin(eps))


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


def simulate(
    rocking: Rocking,
    setup: Setup,
    delta_g: ArrayLike,
    delta_p: ArrayLike,
    gyro_bias: ArrayLike = 0.0,
    rng: int | np.random.Generator | None = None,
    compensation: Compensation | None = None,
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
    delta_g, delta_p, bias = (_components(x) for x in (delta_g, delta_p, gyro_bias))
    batch = _batch_shape(delta_g, delta_p, bias, rocking.amplitude, rocking.frequency,
                         rocking.phase)

    # noise-free IMU output at the sample times and at the mid-points of the Runge-Kutta steps
    t_half = np.sort(np.concatenate([t, t[:-1] + 0.5 * h]))
    omega_b = rocking.body_rate(t_half)
    omega_m = measured_rate(omega_b, delta_g[..., None, :], bias[..., None, :])  # seed 001, (1)
    omega_m = np.broadcast_to(omega_m, (*batch, t_half.size, 3))
    noise = setup.gyro_noise * np.sqrt(setup.rate) * rng.standard_normal((*batch, t.size, 3))

    # the rate the loop integrates: measured, or corrected by the compensation
    offset_eta = offset_eps = 0.0
    loop_rate, loop_noise = omega_m, noise
    if compensation is not None:
        angles = np.asarray(compensation.angles, float)
        C_gb = np.swapaxes(mounting_matrix(0.0, angles[..., 1], angles[..., 2]), -1, -2)
        C_gb = C_gb[..., None, :, :]
        loop_bias = _components(compensation.gyro_bias)[..., None, :]
        loop_rate = _matvec(C_gb, omega_m - loop_bias)
        loop_noise = _matvec(C_gb, noise)
        offset_eta, offset_eps = angles[..., 3], angles[..., 0]
    stages = np.stack([loop_rate[..., 0:-1:2, :], loop_rate[..., 1::2, :],
                       loop_rate[..., 2::2, :]], axis=-2)
    stages = stages + loop_noise[..., :-1, None, :]  # white noise held over each interval
    eta, eps = integrate_gimbal(t, stages, setup.aim_azimuth, setup.aim_pitch,
                                offset_eta, offset_eps)

    # camera attitude, target and its image
    C_nb = rocking.attitude(t)
    C_nc = np.matmul(camera_matrix(eta, eps, delta_p[..., None, :]), C_nb)  # seed 001, eq. (2)
    target = C_nc[..., 0, 1, :]  # LOS at t = 0 in frame n: row y of C_n^c
    u = _matvec(C_nc, target[..., None, :])
    x_px, z_px = pixels_from_direction(u, setup.camera)
    los_true = np.stack([x_px, z_px], axis=-1)
    los = los_true + setup.image_noise * rng.standard_normal(los_true.shape)
    los_error = np.arctan2(np.hypot(u[..., 0], u[..., 2]), u[..., 1])
    gyro = omega_m[..., 0::2, :] + noise
    return Record(t=t, gyro=gyro, eta=eta, eps=eps, los_px=los,
                  los_px_true=los_true, los_error=los_error)


# --------------------------------------------------------------------------------------------
# Linearised measurement model
# --------------------------------------------------------------------------------------------


def los_rate_matrix(omega: ArrayLike, eta: ArrayLike, eps: ArrayLike) -> FloatArray:
    """First-order LOS error rate per unit installation angle, derived from the kinematics.

    ``[dw_x, dw_z] = H X`` with ``X = [delta_px, delta_gx, delta_gy, delta_z]`` and
    ``delta_z = dpz - dgz``; ``dw_x, dw_z`` are the x (pitch) and z (azimuth) components of the
    camera rate (:func:`camera_rate`), zero without installation angles::

        H = [[0, -s_eta w_z, c_eta w_z, c_eta w_y - s_eta w_x],
             [sec(eps) (s_eta w_x - c_eta w_y), c_eps w_y + s_eps c_eta w_z,
              -c_eps w_x + s_eps s_eta w_z, s_eps (c_eta w_x + s_eta w_y)]]

    Row 1 equals the patent's; row 2 differs in ``H_21`` (see :func:`patent_eq6_matrix`).

    Parameters
    ----------
    omega : array_like, shape (..., 3) [rad/s]
        Carrier rate (the measured rate may be used: the difference is of second order).
    eta, eps : array_like [rad]
        Gimbal angles.

    Returns
    -------
    ndarray, shape (..., 2, 4) [rad/s per rad]

    References
    ----------
    seed 001, eqs. (5)-(6) (re-derived from eqs. (1)-(4)).
    """
    omega = np.asarray(omega, float)
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    zero = np.zeros_like(wx * ce * ca)
    row_x = _vec(zero, -sa * wz, ca * wz, ca * wy - sa * wx)  # seed 001, eq. (6), row 1
    row_z = _vec((sa * wx - ca * wy) / ce, ce * wy + se * ca * wz,  # derived (cf. eq. (6), row 2)
                 -ce * wx + se * sa * wz, se * (ca * wx + sa * wy))
    return np.stack([row_x, row_z], axis=-2)


def bias_rate_matrix(eta: ArrayLike, eps: ArrayLike) -> FloatArray:
    """First-order LOS error rate per unit gyro bias: ``[dw_x, dw_z] = G bias``.

    ``G = [[-c_eta, -s_eta, 0], [-s_eps s_eta, s_eps c_eta, -c_eps]]`` is the derivative of the
    x and z camera rates with respect to the rate fed to eq. (4); its rows are orthonormal, so
    white gyro noise of density q moves the LOS as an isotropic random walk of density q.

    Returns
    -------
    ndarray, shape (..., 2, 3) [dimensionless]
    """
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    zero = np.zeros_like(ce * ca)
    return np.stack([_vec(-ca, -sa, zero), _vec(-se * sa, se * ca, -ce)], axis=-2)


def image_roll_rate(omega: ArrayLike, eta: ArrayLike, eps: ArrayLike) -> FloatArray:
    """Camera rate about the LOS of the ideal loop, ``sec(eps) (-s_eta w_x + c_eta w_y)`` [rad/s].

    A two-axis gimbal does not stabilise the image's roll: the image turns at this rate.
    """
    omega = np.asarray(omega, float)
    return (-np.sin(eta) * omega[..., 0] + np.cos(eta) * omega[..., 1]) / np.cos(eps)


def patent_eq6_matrix(
    omega: ArrayLike, eta: ArrayLike, eps: ArrayLike, *, as_printed: bool = True
) -> FloatArray:
    """The patent's H of eq. (6), for comparison with :func:`los_rate_matrix`.

    Printed, ``H_22 = sin(eps) cos(eta) eps w_z + cos(eps) w_y`` carries a stray factor
    ``eps`` (eq. (5) has none); ``as_printed=False`` drops it. ``H_21 = c_eps s_eta w_x -
    c_eps c_eta w_y - s_eps w_z`` is kept as printed either way: it omits the turn of the
    ``eta'`` term of eq. (2) by ``delta_px`` and differs from the derived
    ``sec(eps) (s_eta w_x - c_eta w_y)`` by ``s_eps eta'`` (zero only for a level LOS).

    Returns
    -------
    ndarray, shape (..., 2, 4)

    References
    ----------
    seed 001, eq. (6).
    """
    omega = np.asarray(omega, float)
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    stray = np.asarray(eps, float) if as_printed else 1.0
    zero = np.zeros_like(wx * ce * ca)
    row1 = _vec(zero, -sa * wz, ca * wz, ca * wy - sa * wx)  # seed 001, eq. (6)
    row2 = _vec(ce * sa * wx - ce * ca * wy - se * wz, se * ca * stray * wz + ce * wy,
                -ce * wx + se * sa * wz, se * ca * wx + se * sa * wy)  # seed 001, eq. (6)
    return np.stack([row1, row2], axis=-2)


def patent_eq5_matrix(
    eta: ArrayLike, eps: ArrayLike, delta_g: ArrayLike, delta_p: ArrayLike
) -> FloatArray:
    """The patent's A of eq. (5), ``w_i = A w_b``, as printed.

    Rows are the x, y, z components of the LOS disturbance rate. Rows 1 and 3 agree with the
    first-order expansion of :func:`camera_rate` except for the ``delta_px`` terms of row 3
    (the same omission as ``H_21``); row 2 (roll about the LOS) is not used by eq. (6).

    Returns
    -------
    ndarray, shape (..., 3, 3)

    References
    ----------
    seed 001, eq. (5).
    """
    gx, gy, gz = np.moveaxis(_components(delta_g), -1, 0)
    px, _, pz = np.moveaxis(_components(delta_p), -1, 0)
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    d = gz - pz
    rows = [  # seed 001, eq. (5)
        _vec(d * sa, -d * ca, gy * ca - gx * sa),
        _vec(d * ce * ca + px * se * sa - gy * se, d * ce * sa - px * se * ca + gx * se,
             px * ce - gy * ce * sa - gx * ce * ca),
        _vec(-d * se * ca + px * ce * sa - gy * ce, -d * se * sa - px * ce * ca + gx * ce,
             -px * se + gy * se * sa + gx * se * ca),
    ]
    return np.stack(rows, axis=-2)


def plane_rotation(angle: ArrayLike) -> FloatArray:
    """``[[cos a, -sin a], [sin a, cos a]]``, shape (..., 2, 2): a turn of the image plane."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def drift_matrix(
    t: ArrayLike,
    gyro: ArrayLike,
    eta: ArrayLike,
    eps: ArrayLike,
    camera: Camera,
    rate_matrix=None,
) -> FloatArray:
    """First-order image drift of the target per unit parameter, from the rate model.

    The small LOS error ``phi = [phi_x, phi_z]`` (camera axes) obeys
    ``phi' = [dw_x, dw_z] + w_roll J phi`` with ``J = [[0, -1], [1, 0]]`` and ``w_roll`` the
    image roll rate (:func:`image_roll_rate`): the error is carried round as the image rolls.
    Hence ``phi(t) = R(rho(t)) int_0^t R(-rho) [H X + G bias] dt``, ``rho = int w_roll``, and
    the target's image moves by ``[k_x phi_z, -k_z phi_x]``. Integrals are trapezoidal.

    Parameters
    ----------
    t : array_like, shape (N,) [s]
    gyro : array_like, shape (..., N, 3) [rad/s]
        Measured carrier rate (used for the true one).
    eta, eps : array_like, shape (..., N) [rad]
    camera : Camera
    rate_matrix : callable, optional
        ``H(omega, eta, eps)`` of the rate model; :func:`los_rate_matrix` if omitted
        (:func:`patent_eq6_matrix` to see what the printed model would give).

    Returns
    -------
    ndarray, shape (..., N, 2, 7) [px per rad, px per rad/s]
        Columns ``[delta_px, delta_gx, delta_gy, delta_z, bias_x, bias_y, bias_z]``;
        rows ``[x_px, z_px]``.
    """
    t = np.asarray(t, float)
    gyro = np.asarray(gyro, float)
    eta, eps = np.asarray(eta, float), np.asarray(eps, float)
    H = (rate_matrix or los_rate_matrix)(gyro, eta, eps)
    rate = np.concatenate([H, bias_rate_matrix(eta, eps)], -1)
    rho = cumulative_trapezoid(image_roll_rate(gyro, eta, eps), t, axis=-1, initial=0.0)
    integrand = np.matmul(plane_rotation(-rho), rate)
    phi = np.matmul(plane_rotation(rho), cumulative_trapezoid(integrand, t, axis=-3, initial=0.0))
    k_x, k_z = np.asarray(camera.k_x, float), np.asarray(camera.k_z, float)
    return np.stack([k_x * phi[..., 1, :], -k_z * phi[..., 0, :]], axis=-2)


RAW_TO_OBSERVABLE = np.array([
    [1.0, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 1.0, 0.0],
    [0.0, 1.0, 0.0, 0.0, -1.0],
])
"""``X = T [dpx, dpz, dgx, dgy, dgz]``: the patent's five angles to the four combinations."""


RANK_TOLERANCE = 1e-6
"""Singular values (and unexplained column norms) below this fraction of the largest column
norm count as zero: a standard deviation a million times the best one is no estimate."""


@dataclass(frozen=True)
class Observability:
    """Observability of the installation angles in one experiment.

    Attributes
    ----------
    singular_values : ndarray, shape (4,) [1/rad]
        Of the stacked drift model of ``X`` (divided by the image noise) once the nuisance
        parameters are projected out.
    rank : int
        Numerical rank for ``X`` (4 when every combination is seen).
    raw_rank : int
        Rank for the patent's five angles ``[dpx, dpz, dgx, dgy, dgz]``: at most 4, since
        ``dpz`` and ``dgz`` enter only as ``delta_z = dpz - dgz``.
    raw_null_space : ndarray, shape (5 - raw_rank, 5)
        Orthonormal directions of the five angles that the data cannot see (for rank 4 the
        single row ``[0, 1, 0, 0, 1] / sqrt(2)``: equal changes of ``dpz`` and ``dgz``).
    sigma : ndarray, shape (4,) [rad]
        Cramer-Rao standard deviation of each combination from image noise alone, the others
        and the nuisance parameters being estimated too; ``inf`` where a combination is not
        seen independently of the others.
    """

    singular_values: FloatArray
    rank: int
    raw_rank: int
    raw_null_space: FloatArray
    sigma: FloatArray


def observability(
    record: Record, camera: Camera, image_noise: float, *, nuisance: bool = True
) -> Observability:
    """Rank, singular values and Cramer-Rao bounds of the stacked first-order drift model.

    Parameters
    ----------
    record : Record
        One run (no batch axes); its ``t, gyro, eta, eps`` are used.
    camera : Camera
    image_noise : float [px]
    nuisance : bool
        Estimate the gyro biases and the image offset of the target beside ``X`` (as
        :func:`montecarlo.stabilization_estimation.estimate` does); False: known.
    """
    M = drift_matrix(record.t, record.gyro, record.eta, record.eps, camera) / image_noise
    X = M[..., :4].reshape(-1, 4)
    if nuisance:
        offset = np.broadcast_to(np.eye(2) / image_noise, (record.t.size, 2, 2))
        Q = np.linalg.qr(np.concatenate([M[..., 4:], offset], -1).reshape(-1, 5))[0]
        X = X - Q @ (Q.T @ X)
    s = np.linalg.svd(X, compute_uv=False)
    tol = RANK_TOLERANCE * np.linalg.norm(X, axis=0).max()
    _, raw_s, V = np.linalg.svd(X @ RAW_TO_OBSERVABLE, full_matrices=False)
    raw_rank = int(np.sum(raw_s > tol))
    null = V[raw_rank:]
    null = null * np.sign(null[np.arange(len(null)), np.argmax(np.abs(null), axis=1)])[:, None]
    sigma = np.empty(4)
    for j in range(4):
        others = np.delete(X, j, axis=1)
        residual = X[:, j] - others @ np.linalg.lstsq(others, X[:, j], rcond=None)[0]
        norm = np.linalg.norm(residual)
        sigma[j] = 1.0 / norm if norm > tol else np.inf
    return Observability(singular_values=s, rank=int(np.sum(s > tol)),
                         raw_rank=raw_rank, raw_null_space=null, sigma=sigma)


# --------------------------------------------------------------------------------------------
# Time-series files
# --------------------------------------------------------------------------------------------

CSV_COLUMNS = ("t_s", "gyro_x", "gyro_y", "gyro_z", "eta_rad", "eps_rad", "los_x_px", "los_z_px")
"""Columns of a run: time [s], IMU rate [rad/s] (IMU axes), gimbal azimuth and pitch [rad],
measured image position of the target [px] (x right, z up, from the image centre)."""

MAX_GIMBAL_PITCH = np.radians(89.0)
"""Eq. (4) divides by cos(eps): runs with |eps| beyond this are refused [rad]."""


def write_csv(path: str | Path, record: Record) -> None:
    """Write one run (no batch axes) as a CSV file, atomically (temporary file, then rename).

    Raises
    ------
    InputError
        The file cannot be written (the message names it); nothing is left behind.
    """
    path = Path(path)
    columns = np.column_stack([record.t, record.gyro, record.eta, record.eps, record.los_px])
    text = io.StringIO()
    text.write(",".join(CSV_COLUMNS) + "\n")
    np.savetxt(text, columns, fmt="%.12g", delimiter=",")
    try:
        atomic_write_bytes(path, text.getvalue().encode())
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None


def read_csv(path: str | Path) -> Record:
    """Read a run written by :func:`write_csv` or measured in the same format.

    Raises
    ------
    InputError
        Missing column, non-numeric value, fewer than 10 rows, times not strictly increasing,
        or a gimbal pitch beyond ``MAX_GIMBAL_PITCH``; one line naming file, row and column.
    """
    table = read_table(path, CSV_COLUMNS, min_rows=10)
    t = table["t_s"].to_numpy(float)
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(f"{path}: row {i + 2}, column 't_s': {t[i]!r} is not after the "
                         f"previous time {t[i - 1]!r}")
    eps = table["eps_rad"].to_numpy(float)
    bad = np.flatnonzero(np.abs(eps) > MAX_GIMBAL_PITCH)
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{path}: row {i + 2}, column 'eps_rad': {eps[i]!r} is beyond "
                         f"+-{MAX_GIMBAL_PITCH:.4f} rad (eq. (4) divides by cos(eps))")
    return Record(t=t, gyro=table[["gyro_x", "gyro_y", "gyro_z"]].to_numpy(float),
                  eta=table["eta_rad"].to_numpy(float), eps=eps,
                  los_px=table[["los_x_px", "los_z_px"]].to_numpy(float))
