"""Gyro indirect stabilisation of seed 001: frames, the carrier's rocking, eqs. (1)-(4).

An IMU and a two-axis gimbal (azimuth ``eta`` outer, pitch ``eps`` inner) carrying a camera sit on
a rocking carrier. The gimbal is stabilised *indirectly*: it integrates the rates of eq. (4)
computed from the IMU's measured carrier rate. IMU and camera installation angles make the line
of sight (LOS) drift; the camera sees the drift as the motion of a fixed target in the image.
The simulator is :mod:`montecarlo.seed001.simulate`, the linearised model
:mod:`montecarlo.seed001.linear_model`, the estimator that turns the drift back into angles
:mod:`montecarlo.seed001.estimate`.

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
``c``  camera, two mounts. ``patent``: ``C_b^c = R_y(dpy) R_x(eps + dpx) R_z(eta + dpz)``, seed
       001, eq. (2): the camera's pitch and azimuth installation angles add to the gimbal angles.
       ``dpy`` (roll about the LOS), which the patent drops, is applied last; it only turns the
       image. ``inner-gimbal`` (camera bolted to the pitch gimbal):
       ``C_b^c = R_y(dpy) R_x(dpx) R_z(dpz) R_x(eps) R_z(eta)``.
LOS    the camera's y axis; with the patent mount its direction in the carrier frame is
       ``[-sin(eta+dpz) cos(eps+dpx), cos(eta+dpz) cos(eps+dpx), sin(eps+dpx)]``.

Angular rates are body rates in the rotating frame's own axes (``dC_n^b/dt = -[w_b x] C_n^b``).
The IMU measures ``w_m = C_b^g w_b + bias + noise`` [rad/s].

Image: the target is a fixed direction in n, by default the point the LOS aimed at at ``t = 0``;
with ``u`` its direction in frame c,
its image is at ``x_px = k_x u_x / u_y`` (right), ``z_px = k_z u_z / u_y`` (up)
(:func:`montecarlo.geometry.camera.pixels_from_direction`). ``los_x_px, los_z_px`` are this image
position: a LOS turned by a small angle ``a`` to the left (about +z) moves the target to
``x_px = +k_x a``; a LOS turned up by ``a`` (about +x) moves it to ``z_px = -k_z a``.

All functions broadcast: batch axes first, then time, then vector components ``(..., N, 3)``.

References
----------
seed 001: patent CN102288133B (2013), eqs. (1)-(6); docs/reference/conventions.md, "Seed 001:
cautions".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.geometry.rotations import mounting_matrix

FloatArray = NDArray[np.float64]


def stack_vector(*components: ArrayLike) -> FloatArray:
    return np.stack(np.broadcast_arrays(*(np.asarray(c, float) for c in components)), axis=-1)


def as_vector(x: ArrayLike) -> FloatArray:
    """``x`` as an array with a vector axis of 3 (a scalar is repeated)."""
    return np.asarray(x, float) + np.zeros(3)


def batch_shape(*vectors: ArrayLike) -> tuple[int, ...]:
    """Broadcast of the leading shapes of arrays whose last axis holds components."""
    return np.broadcast_shapes(*(np.shape(v)[:-1] for v in vectors if np.ndim(v) > 0))


def flat_batch(x: ArrayLike, batch: tuple[int, ...], tail: tuple[int, ...]) -> FloatArray:
    """``x`` broadcast to ``(*batch, *tail)`` as a C-contiguous array of shape ``(-1, *tail)``
    (one batch axis, as the compiled kernels take it)."""
    return np.ascontiguousarray(np.broadcast_to(np.asarray(x, float), (*batch, *tail))).reshape(
        -1, *tail)


def matvec(M: ArrayLike, v: ArrayLike) -> FloatArray:
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
        a = as_vector(self.amplitude)[..., None, :]
        w = 2.0 * np.pi * as_vector(self.frequency)[..., None, :]
        return a, w, w * t + as_vector(self.phase)[..., None, :]

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
        return stack_vector(cg * dtheta - sg * ct * dpsi, dgamma + st * dpsi,
                            sg * dtheta + cg * ct * dpsi)


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
    d = as_vector(delta_g)
    return mounting_matrix(d[..., 2], d[..., 0], d[..., 1])  # seed 001, eq. (1)


def measured_rate(omega_b: ArrayLike, delta_g: ArrayLike, bias: ArrayLike = 0.0) -> FloatArray:
    """IMU output without noise, ``w_bm = C_b^g w_b + bias``, shape (..., 3) [rad/s].

    References
    ----------
    seed 001, eq. (1) (the patent has no bias term).
    """
    return matvec(imu_matrix(delta_g), omega_b) + bias  # seed 001, eq. (1)


MOUNTS = ("patent", "inner-gimbal")
"""Camera mounts: ``patent`` (eq. (2), the installation angles add to the gimbal angles) and
``inner-gimbal`` (the camera bolted to the pitch gimbal, its installation rotation applied after
the gimbal's)."""


def check_mount(mount: str) -> str:
    if mount not in MOUNTS:
        raise ValueError(f"mount must be one of {', '.join(MOUNTS)}, not {mount!r}")
    return mount


def installation_matrix(delta_p: ArrayLike) -> FloatArray:
    """``R_y(dpy) R_x(dpx) R_z(dpz)``, the inner-gimbal camera's installation rotation.

    Parameters
    ----------
    delta_p : array_like, shape (..., 3) [rad]
        Camera installation angles ``[dpx, dpy, dpz]``.
    """
    d = as_vector(delta_p)
    return mounting_matrix(d[..., 2], d[..., 0], d[..., 1])


def camera_matrix(
    eta: ArrayLike, eps: ArrayLike, delta_p: ArrayLike = 0.0, mount: str = "patent"
) -> FloatArray:
    """Camera attitude ``C_b^c``, shape (..., 3, 3).

    ``patent``: ``R_y(dpy) R_x(eps + dpx) R_z(eta + dpz)`` (eq. (2));
    ``inner-gimbal``: ``R_y(dpy) R_x(dpx) R_z(dpz) R_x(eps) R_z(eta)``.

    Parameters
    ----------
    eta, eps : array_like [rad]
        Gimbal azimuth and pitch angles.
    delta_p : array_like, shape (..., 3) [rad]
        Camera installation angles ``[dpx, dpy, dpz]``.
    mount : {"patent", "inner-gimbal"}

    References
    ----------
    seed 001, eq. (2) (the rotations it applies to the carrier rate).
    """
    d = as_vector(delta_p)
    if check_mount(mount) == "inner-gimbal":
        return np.matmul(installation_matrix(d), mounting_matrix(eta, eps, 0.0))
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
    mount: str = "patent",
) -> FloatArray:
    """Angular rate of the camera in camera axes, shape (..., 3) [rad/s].

    ``patent``: ``w_i = R_y(dpy) [R_x(eps + dpx) (R_z(eta + dpz) w_b + [0, 0, eta']) +
    [eps', 0, 0]]``; ``inner-gimbal``: ``w_i = R_y(dpy) R_x(dpx) R_z(dpz) [R_x(eps) (R_z(eta)
    w_b + [0, 0, eta']) + [eps', 0, 0]]``. Components x and z turn the LOS (the stabilisation
    error rate); y rolls the image.

    The patent prints the pitch-rate vector as ``[0 0 eps']``; the pitch axis is x, so it is
    ``[eps' 0 0]`` (only then do the rates of eq. (4) stabilise the LOS).

    References
    ----------
    seed 001, eqs. (2)-(3).
    """
    d = as_vector(delta_p)
    inner_mount = check_mount(mount) == "inner-gimbal"
    turn_eta = 0.0 if inner_mount else d[..., 2]
    turn_eps = 0.0 if inner_mount else d[..., 0]
    zero = np.zeros_like(np.asarray(eta_dot, float))
    inner = matvec(mounting_matrix(np.asarray(eta) + turn_eta, 0.0, 0.0), omega_b)
    inner = inner + stack_vector(zero, zero, eta_dot)  # seed 001, eqs. (2)-(3)
    outer = matvec(mounting_matrix(0.0, np.asarray(eps) + turn_eps, 0.0), inner)
    outer = outer + stack_vector(eps_dot, zero, zero)  # seed 001, eqs. (2)-(3), pitch rate about x
    if inner_mount:
        return matvec(installation_matrix(d), outer)
    return matvec(mounting_matrix(0.0, 0.0, d[..., 1]), outer)


def los_direction(eta: ArrayLike, eps: ArrayLike) -> FloatArray:
    """Unit LOS of a gimbal at (eta, eps) in carrier axes, shape (..., 3)."""
    ce = np.cos(eps)
    return stack_vector(-np.sin(eta) * ce, np.cos(eta) * ce, np.sin(eps))
