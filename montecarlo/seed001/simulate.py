"""Exact-kinematics simulator of a gyro indirect-stabilisation run (seed 001, eqs. (1)-(4)).

The carrier rocks, the IMU measures its rate through its installation angles, the gimbal
integrates eq. (4) from the measured rate, and the camera, turned by its own installation
angles, images the target the line of sight aimed at at ``t = 0``. Frames and signs are those of
:mod:`montecarlo.seed001.kinematics`.

References
----------
seed 001: patent CN102288133B, eqs. (1)-(4), claim 1 (second step); docs/reference/references.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.geometry.camera import Camera, pixels_from_direction
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed001 import simulate_kernels
from montecarlo.seed001.kinematics import (
    Rocking,
    as_vector,
    batch_shape,
    camera_matrix,
    check_mount,
    flat_batch,
    gimbal_rates,
    imu_matrix,
    matvec,
    measured_rate,
)

FloatArray = NDArray[np.float64]


DEFAULT_CAMERA = Camera.from_degrees(5.0, 5.0, 1024, 1024)
"""A narrow-field camera: 5 x 5 deg, 1024 x 1024 pixels (about 85 urad per pixel)."""

GYRO_SAMPLINGS = ("point", "interval-mean")
"""What a gyro row holds: the rate at its time stamp (``point``), or the mean rate over the
sample interval ending at its time stamp (``interval-mean``: the IMU's delta-angle divided by
the interval)."""

QUADRATURE = np.polynomial.legendre.leggauss(5)
"""Gauss-Legendre nodes and weights on [-1, 1] for the interval means of the simulated rate."""


def check_sampling(sampling: str) -> str:
    if sampling not in GYRO_SAMPLINGS:
        raise ValueError(f"gyro sampling must be one of {', '.join(GYRO_SAMPLINGS)}, "
                         f"not {sampling!r}")
    return sampling
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
    target_px : (float, float) [px]
        Image position ``(x, z)`` of the target at ``t = 0`` (``(0, 0)``: the target is where
        the LOS aims at the start).
    mount : {"patent", "inner-gimbal"}
        Camera mount (:func:`montecarlo.seed001.kinematics.camera_matrix`).
    gyro_sampling : {"point", "interval-mean"}
        What a gyro row holds (:data:`GYRO_SAMPLINGS`).
    """

    duration: float = 60.0
    rate: float = 100.0
    aim_azimuth: float = 0.0
    aim_pitch: float = 0.0
    camera: Camera = DEFAULT_CAMERA
    image_noise: float = 0.1
    gyro_noise: float = 0.0
    target_px: tuple[float, float] = (0.0, 0.0)
    mount: str = "patent"
    gyro_sampling: str = "point"

    def __post_init__(self) -> None:
        check_mount(self.mount)
        check_sampling(self.gyro_sampling)

    @property
    def times(self) -> FloatArray:
        """Sample times ``0, 1/rate, ...`` up to ``duration``, shape (N,) [s]."""
        n = round(self.duration * self.rate) + 1
        return np.arange(n) / self.rate


@dataclass(frozen=True)
class Compensation:
    """Installation angles and gyro bias the stabilisation loop corrects for.

    The loop uses ``w_c = (R_y(dgy) R_x(dgx))^T (w_m - bias)`` as the carrier rate, the rate of
    the carrier frame turned by ``dgz`` about z. Patent mount: it evaluates eq. (4) at
    ``(eta + delta_z, eps + delta_px)``; only ``delta_z = dpz - dgz`` is needed. Inner-gimbal
    mount: it integrates eq. (4) for the camera's LOS (:func:`pointing_angles`) and sets the
    encoder angles that put the camera's LOS there (:func:`encoder_angles`).

    Parameters
    ----------
    angles : array_like, shape (..., 4) [rad]
        ``[delta_px, delta_gx, delta_gy, delta_z]``.
    gyro_bias : array_like, shape (..., 3) [rad/s]
    delta_gz : array_like, shape (...) [rad]
        Used by the inner-gimbal mount only (``dpz = delta_z + dgz``).
    mount : {"patent", "inner-gimbal"}
    """

    angles: ArrayLike
    gyro_bias: ArrayLike = 0.0
    delta_gz: ArrayLike = 0.0
    mount: str = "patent"


def _inner_gimbal_los(angles: ArrayLike, delta_gz: ArrayLike) -> FloatArray:
    """LOS of an inner-gimbal camera in its pitch frame, ``(R_x(dpx) R_z(dpz))^T e_y``."""
    a = np.asarray(angles, float)
    M = mounting_matrix(a[..., 3] + np.asarray(delta_gz, float), a[..., 0], 0.0)
    return M[..., 1, :]


def pointing_angles(
    eta: ArrayLike, eps: ArrayLike, angles: ArrayLike, delta_gz: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Azimuth and pitch of an inner-gimbal camera's LOS in the carrier frame turned by ``dgz``.

    Parameters
    ----------
    eta, eps : array_like [rad]
        Encoder angles.
    angles : array_like, shape (..., 4) [rad]
        ``[delta_px, delta_gx, delta_gy, delta_z]``.
    delta_gz : array_like [rad]

    Returns
    -------
    eta_los, eps_los : ndarray [rad]
        ``los_direction(eta_los, eps_los)`` is the camera's LOS.
    """
    m = _inner_gimbal_los(angles, delta_gz)
    pitch = np.swapaxes(mounting_matrix(np.asarray(eta) - np.asarray(delta_gz), eps, 0.0),
                        -1, -2)
    los = matvec(pitch, m)
    return np.arctan2(-los[..., 0], los[..., 1]), np.arcsin(np.clip(los[..., 2], -1.0, 1.0))


def encoder_angles(
    eta_los: ArrayLike, eps_los: ArrayLike, angles: ArrayLike, delta_gz: ArrayLike,
    eta_near: ArrayLike = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Encoder angles that put an inner-gimbal camera's LOS at ``(eta_los, eps_los)``.

    The inverse of :func:`pointing_angles`: with ``m`` the LOS in the pitch frame,
    ``m_y sin(eps) + m_z cos(eps)`` is the LOS's z component, which gives ``eps``; the azimuth
    then turns ``[m_x, m_y cos(eps) - m_z sin(eps)]`` onto the LOS's horizontal part. ``eta`` is
    taken within pi of ``eta_near``.
    """
    m = np.moveaxis(_inner_gimbal_los(angles, delta_gz), -1, 0)[..., None]
    eps = np.arcsin(np.sin(eps_los) / np.hypot(m[1], m[2])) - np.arctan2(m[2], m[1])
    q = m[1] * np.cos(eps) - m[2] * np.sin(eps)
    eta = (np.arctan2(np.cos(eps_los) * np.cos(eta_los), -np.cos(eps_los) * np.sin(eta_los))
           - np.arctan2(q, m[0]) + np.asarray(delta_gz, float)[..., None])
    eta = eta_near + np.angle(np.exp(1j * (eta - eta_near)))
    return eta, eps


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
        True angle between the LOS and its direction at ``t = 0`` (the stabilisation error).
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


def carrier_trig(rocking_angles: ArrayLike) -> FloatArray:
    """Cosines and sines ``[c_psi, s_psi, c_theta, s_theta, c_gamma, s_gamma]`` of the carrier's
    angles ``[psi, theta, gamma]`` (shape (..., N, 3) [rad]), shape (6, ..., N)."""
    a = np.moveaxis(np.asarray(rocking_angles, float), -1, 0)
    trig = np.empty((6, *a.shape[1:]))
    trig[0::2], trig[1::2] = np.cos(a), np.sin(a)  # numpy's cosines and sines are vectorised
    return trig


def target_view_compiled(
    carrier: ArrayLike, eta: ArrayLike, eps: ArrayLike, delta_p: ArrayLike
) -> FloatArray:
    """Direction in the camera of the target the LOS aimed at at ``t[0]``, compiled.

    ``u_k = C_b^c(k) C_n^b(k) target`` with ``target`` row y of ``C_n^c(0)``, as in
    :func:`simulate`.

    Parameters
    ----------
    carrier : array_like, shape (6, ..., N)
        :func:`carrier_trig` of the carrier's angles (:meth:`Rocking.angles`).
    eta, eps : array_like, shape (..., N) [rad]
    delta_p : array_like, shape (..., 3) [rad]

    Returns
    -------
    ndarray, shape (..., N, 3)

    References
    ----------
    seed 001, eq. (2).
    """
    carrier, eta, eps = (np.asarray(a, float) for a in (carrier, eta, eps))
    delta_p = as_vector(delta_p)
    shape = np.broadcast_shapes(carrier.shape[1:], eta.shape, eps.shape,
                                (*delta_p.shape[:-1], 1))
    angles = [eta + delta_p[..., 2, None], eps + delta_p[..., 0, None], delta_p[..., 1, None]]
    camera = np.empty((6, *shape))
    for i, a in enumerate(angles):
        camera[2 * i], camera[2 * i + 1] = np.cos(a), np.sin(a)
    carrier = carrier.reshape(6, *(1,) * (len(shape) + 1 - carrier.ndim), *carrier.shape[1:])
    carrier = np.broadcast_to(carrier, (6, *shape)).reshape(6, -1, shape[-1])
    u = np.empty((*carrier.shape[1:], 3))
    simulate_kernels.target_directions(np.ascontiguousarray(carrier),
                                       camera.reshape(6, -1, shape[-1]), u)  # seed 001, eq. (2)
    return u.reshape(*shape, 3)


@dataclass(frozen=True)
class Motion:
    """The carrier's noise-free motion and IMU output in a batch of runs (:func:`imu_motion`).

    Runs with the same rocking, IMU installation angles and gyro bias share it, e.g. a
    calibration run and its compensated rerun.

    Attributes
    ----------
    omega_m : ndarray, shape (..., 2 N - 1, 3) [rad/s]
        IMU output (eq. (1), without noise) at ``t_0, t_0 + h/2, t_1, ...``.
    carrier : ndarray, shape (6, ..., N), or None
        :func:`carrier_trig` of the carrier's angles at the sample times, where
        :func:`target_view_compiled` uses it (the compiled path, patent mount, target at the
        centre at ``t = 0``); else None.
    gyro : ndarray, shape (..., N, 3) [rad/s]
        The gyro rows without noise: ``omega_m`` at the sample times, or its interval means.
    """

    omega_m: FloatArray
    carrier: FloatArray | None
    gyro: FloatArray


def imu_motion(rocking: Rocking, setup: Setup, delta_g: ArrayLike, gyro_bias: ArrayLike = 0.0,
               reference: bool = False) -> Motion:
    """The noise-free part of :func:`simulate`: the carrier's rocking and the IMU output.

    ``reference``: the literal numpy functions instead of
    :func:`simulate_kernels.rocking_gyro` (the same results to rounding).

    References
    ----------
    seed 001, eq. (1).
    """
    t = setup.times
    h = 1.0 / setup.rate
    delta_g, bias = as_vector(delta_g), as_vector(gyro_bias)
    batch = batch_shape(delta_g, bias, rocking.amplitude, rocking.frequency, rocking.phase)
    t_half = np.sort(np.concatenate([t, t[:-1] + 0.5 * h]))
    carrier = None
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
                                for a in simulate_kernels.rocking_gyro(t_half, *flat))  # eq. (1)
        if setup.mount == "patent" and not np.any(setup.target_px):  # as simulate's image
            carrier = carrier_trig(rock_angles[..., 0::2, :])
    if setup.gyro_sampling == "point":
        gyro = omega_m[..., 0::2, :]
    else:
        gyro = interval_mean_rate(rocking, t, h, delta_g, bias)
    return Motion(omega_m=omega_m, carrier=carrier, gyro=gyro)


def simulate(
    rocking: Rocking,
    setup: Setup,
    delta_g: ArrayLike,
    delta_p: ArrayLike,
    gyro_bias: ArrayLike = 0.0,
    rng: int | np.random.Generator | None = None,
    compensation: Compensation | None = None,
    reference: bool = False,
    motion: Motion | None = None,
) -> Record:
    """Simulate one run (or a batch of runs) with the exact kinematics.

    The carrier rocks (:class:`Rocking`); the IMU, turned by ``delta_g``, measures
    ``w_m = C_b^g w_b + bias + n`` (eq. (1)); ``n`` is white, held constant over each sample
    interval. The gimbal integrates eq. (4) from ``w_m`` (or from the compensated rate) by
    Runge-Kutta at the sample rate, starting at ``(aim_azimuth, aim_pitch)``. The camera, turned
    by ``delta_p`` (eq. (2), or the inner-gimbal mount of ``setup.mount``), images a fixed
    target whose image at ``t = 0`` is at ``setup.target_px``. The gyro rows hold the rate at
    their time stamps or its means over the intervals ending there (``setup.gyro_sampling``).

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
        Compute the IMU output, integrate the gimbal and turn the target into the camera with
        the literal numpy functions instead of :func:`simulate_kernels.rocking_gyro`,
        :func:`simulate_kernels.rk4_gimbal` and :func:`target_view_compiled` (the same results
        to rounding). The compiled image covers the patent mount with the target at the centre at
        ``t = 0``; other set-ups use the numpy camera chain either way.
    motion : Motion or None
        :func:`imu_motion` of the same rocking, ``delta_g``, ``gyro_bias``, setup and
        ``reference``, if already computed (e.g. for the calibration run before its
        compensated rerun); computed here if None.

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
    delta_g, delta_p, bias = (as_vector(x) for x in (delta_g, delta_p, gyro_bias))
    batch = batch_shape(delta_g, delta_p, bias, rocking.amplitude, rocking.frequency,
                         rocking.phase)
    if compensation is not None:  # its batch too (each run draws its own noise)
        batch = np.broadcast_shapes(batch, np.shape(compensation.delta_gz),
                                    batch_shape(compensation.angles, compensation.gyro_bias))

    # noise-free IMU output at the sample times and at the mid-points of the Runge-Kutta steps
    if motion is None:
        motion = imu_motion(rocking, setup, delta_g, bias, reference)
    omega_m = np.broadcast_to(motion.omega_m, (*batch, 2 * t.size - 1, 3))
    noise = setup.gyro_noise * np.sqrt(setup.rate) * rng.standard_normal((*batch, t.size, 3))

    # the rate the loop integrates: measured, or corrected by the compensation
    offset_eta = offset_eps = 0.0
    C_gb, loop_bias = np.eye(3), np.zeros(3)
    if compensation is not None:
        angles = np.asarray(compensation.angles, float)
        C_gb = np.swapaxes(mounting_matrix(0.0, angles[..., 1], angles[..., 2]), -1, -2)
        loop_bias = as_vector(compensation.gyro_bias)
        offset_eta, offset_eps = angles[..., 3], angles[..., 0]
    inner = compensation is not None and compensation.mount == "inner-gimbal"
    if inner:
        dgz = np.asarray(compensation.delta_gz, float)
        start = pointing_angles(setup.aim_azimuth, setup.aim_pitch, angles, dgz)
    else:
        start = (setup.aim_azimuth, setup.aim_pitch, offset_eta, offset_eps)
    if reference:
        loop_rate, loop_noise = omega_m, noise
        if compensation is not None:
            loop_rate = matvec(C_gb[..., None, :, :], omega_m - loop_bias[..., None, :])
            loop_noise = matvec(C_gb[..., None, :, :], noise)
        stages = np.stack([loop_rate[..., 0:-1:2, :], loop_rate[..., 1::2, :],
                           loop_rate[..., 2::2, :]], axis=-2)
        stages = stages + loop_noise[..., :-1, None, :]  # white noise held over each interval
        eta, eps = integrate_gimbal(t, stages, *start)
    else:
        start = (*start, 0.0, 0.0)[:4]
        flat = [flat_batch(a, batch, tail)
                for a, tail in ((omega_m, (2 * t.size - 1, 3)), (noise, (t.size, 3)),
                                (C_gb, (3, 3)), (loop_bias, (3,)), (start[0], ()),
                                (start[1], ()), (start[2], ()), (start[3], ()))]
        eta, eps = (a.reshape(*batch, t.size)
                    for a in simulate_kernels.rk4_gimbal(np.diff(t), *flat))  # seed 001, eq. (4)
    if inner:
        eta, eps = encoder_angles(eta, eps, angles, dgz, setup.aim_azimuth)

    # camera attitude, target and its image
    if reference or setup.mount != "patent" or np.any(setup.target_px):
        C_nb = rocking.attitude(t)
        C_nc = np.matmul(camera_matrix(eta, eps, delta_p[..., None, :], setup.mount),
                         C_nb)  # seed 001, eq. (2)
        target = target_direction(C_nc[..., 0, :, :], setup.target_px, setup.camera)
        u = matvec(C_nc, target[..., None, :])
        v = matvec(C_nc, C_nc[..., 0:1, 1, :])  # the LOS at t = 0 (row y of C_n^c) in frame c
    else:  # patent mount, target at the centre at t = 0: the target is the LOS at t = 0
        u = v = target_view_compiled(motion.carrier, eta, eps, delta_p)
    x_px, z_px = pixels_from_direction(u, setup.camera)
    los_true = np.stack([x_px, z_px], axis=-1)
    los = los_true + setup.image_noise * rng.standard_normal(los_true.shape)
    los_error = np.arctan2(np.hypot(v[..., 0], v[..., 2]), v[..., 1])
    if setup.gyro_sampling == "point":
        gyro = motion.gyro + noise
    else:  # the mean over (t_k - h, t_k], with the noise the loop used over that interval
        first = setup.gyro_noise * np.sqrt(setup.rate) * rng.standard_normal((*batch, 1, 3))
        gyro = motion.gyro + np.concatenate([first, noise[..., :-1, :]], axis=-2)
    return Record(t=t, gyro=gyro, eta=eta, eps=eps, los_px=los,
                  los_px_true=los_true, los_error=los_error)


def target_direction(C_nc0: ArrayLike, target_px: ArrayLike, camera: Camera) -> FloatArray:
    """Direction in frame n of a target imaged at ``target_px = (x, z)`` by a camera at ``C_nc0``.

    Parameters
    ----------
    C_nc0 : array_like, shape (..., 3, 3)
        Camera attitude ``C_n^c`` when the target is at ``target_px``.
    target_px : array_like, shape (..., 2) [px]
    camera : Camera

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vector; the inverse of the pinhole ``x = k_x u_x / u_y``, ``z = k_z u_z / u_y``.
    """
    px = np.asarray(target_px, float)
    u = np.stack(np.broadcast_arrays(px[..., 0] / float(camera.k_x), np.ones(px.shape[:-1]),
                                     px[..., 1] / float(camera.k_z)), axis=-1)
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    return matvec(np.swapaxes(np.asarray(C_nc0, float), -1, -2), u)


def interval_mean_rate(
    rocking: Rocking, t: ArrayLike, h: float, delta_g: ArrayLike, bias: ArrayLike = 0.0
) -> FloatArray:
    """Noise-free IMU output averaged over ``(t_k - h, t_k]``, shape (..., N, 3) [rad/s].

    The delta-angle of eq. (1)'s rate over the interval divided by ``h`` (Gauss-Legendre,
    :data:`QUADRATURE`).

    References
    ----------
    seed 001, eq. (1).
    """
    t = np.asarray(t, float)
    x, w = QUADRATURE
    nodes = t[:, None] - 0.5 * h + 0.5 * h * x
    omega_b = rocking.body_rate(nodes.ravel())
    omega_m = measured_rate(omega_b, as_vector(delta_g)[..., None, :],
                            as_vector(bias)[..., None, :])  # seed 001, eq. (1)
    omega_m = omega_m.reshape(*omega_m.shape[:-2], t.size, x.size, 3)
    return np.einsum("...gj,g->...j", omega_m, 0.5 * w)
