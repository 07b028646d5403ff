"""First-order model of the line-of-sight drift per installation angle (seed 001, eqs. (5)-(6)).

The LOS error rates are expanded to first order in the installation angles and the gyro bias
(re-derived from the exact kinematics, and compared with the patent's printed eqs. (5)-(6)),
integrated into the image drift the camera sees, and stacked over a run for the observability
analysis (rank and Cramer-Rao bounds).

References
----------
seed 001: patent CN102288133B, eqs. (5)-(6); docs/reference/stabilization.md;
docs/reference/references.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import cumulative_trapezoid

from montecarlo.geometry.camera import Camera
from montecarlo.seed001 import estimate_kernels
from montecarlo.seed001.kinematics import as_vector, check_mount, flat_batch, stack_vector
from montecarlo.seed001.simulate import Record

FloatArray = NDArray[np.float64]


OBSERVABLE_NAMES = ("delta_px", "delta_gx", "delta_gy", "delta_z")
"""The four estimable combinations ``X`` of seed 001, eq. (6); ``delta_z = dpz - dgz``."""

INNER_GIMBAL_NAMES = (*OBSERVABLE_NAMES, "delta_gz")
"""``X`` of the inner-gimbal mount: ``dpz`` and ``dgz`` enter separately
(``dpz = delta_z + dgz``)."""


def model_names(mount: str = "patent") -> tuple[str, ...]:
    """The installation-angle columns of the first-order model of a camera mount."""
    return INNER_GIMBAL_NAMES if check_mount(mount) == "inner-gimbal" else OBSERVABLE_NAMES
# --------------------------------------------------------------------------------------------
# Linearised measurement model
# --------------------------------------------------------------------------------------------


def los_rate_matrix(
    omega: ArrayLike, eta: ArrayLike, eps: ArrayLike, mount: str = "patent"
) -> FloatArray:
    """First-order LOS error rate per unit installation angle, derived from the kinematics.

    ``[dw_x, dw_z] = H X``; ``dw_x, dw_z`` are the x (pitch) and z (azimuth) components of the
    camera rate (:func:`camera_rate`), zero without installation angles. Patent mount (eq. (2)):
    ``X = [delta_px, delta_gx, delta_gy, delta_z]`` with ``delta_z = dpz - dgz``::

        H = [[0, -s_eta w_z, c_eta w_z, c_eta w_y - s_eta w_x],
             [sec(eps) (s_eta w_x - c_eta w_y), c_eps w_y + s_eps c_eta w_z,
              -c_eps w_x + s_eps s_eta w_z, s_eps (c_eta w_x + s_eta w_y)]]

    Row 1 equals the patent's; row 2 differs in ``H_21`` (see :func:`patent_eq6_matrix`).

    Inner-gimbal mount: the pitch frame's error rate is ``C_b^p (dg x w)`` (the loop's rate
    error ``w_b - w_m = dg x w_b``), and the installation rotation adds ``-dp x [0, w_r, 0]``
    with ``w_r`` the roll rate (:func:`image_roll_rate`): ``dpz`` enters as ``[w_r, 0]``, not as
    an azimuth offset. With ``X = [delta_px, delta_gx, delta_gy, delta_z, dgz]`` (``dpz =
    delta_z + dgz``) the first four columns hold ``dgz`` fixed::

        H = [[0, -s_eta w_z, c_eta w_z, w_r, (1 - c_eps) w_r],
             [-w_r, c_eps w_y + s_eps c_eta w_z, -c_eps w_x + s_eps s_eta w_z, 0,
              -s_eps (c_eta w_x + s_eta w_y)]]

    Parameters
    ----------
    omega : array_like, shape (..., 3) [rad/s]
        Carrier rate (the measured rate may be used: the difference is of second order).
    eta, eps : array_like [rad]
        Gimbal angles.
    mount : {"patent", "inner-gimbal"}

    Returns
    -------
    ndarray, shape (..., 2, 4) (patent) or (..., 2, 5) (inner-gimbal) [rad/s per rad]

    References
    ----------
    seed 001, eqs. (5)-(6) (re-derived from eqs. (1)-(4)).
    """
    omega = np.asarray(omega, float)
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    zero = np.zeros_like(wx * ce * ca)
    if check_mount(mount) == "inner-gimbal":
        roll = (ca * wy - sa * wx) / ce
        row_x = stack_vector(zero, -sa * wz, ca * wz, roll, (1.0 - ce) * roll)
        row_z = stack_vector(-roll, ce * wy + se * ca * wz, -ce * wx + se * sa * wz, zero,
                             -se * (ca * wx + sa * wy))
        return np.stack([row_x, row_z], axis=-2)
    row_x = stack_vector(zero, -sa * wz, ca * wz, ca * wy - sa * wx)  # seed 001, eq. (6), row 1
    row_z = stack_vector((sa * wx - ca * wy) / ce, ce * wy + se * ca * wz,  # derived, cf. eq. (6)
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
    return np.stack([stack_vector(-ca, -sa, zero), stack_vector(-se * sa, se * ca, -ce)], axis=-2)


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
    row1 = stack_vector(zero, -sa * wz, ca * wz, ca * wy - sa * wx)  # seed 001, eq. (6)
    row2 = stack_vector(ce * sa * wx - ce * ca * wy - se * wz, se * ca * stray * wz + ce * wy,
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
    gx, gy, gz = np.moveaxis(as_vector(delta_g), -1, 0)
    px, _, pz = np.moveaxis(as_vector(delta_p), -1, 0)
    ce, se, ca, sa = np.cos(eps), np.sin(eps), np.cos(eta), np.sin(eta)
    d = gz - pz
    rows = [  # seed 001, eq. (5)
        stack_vector(d * sa, -d * ca, gy * ca - gx * sa),
        stack_vector(d * ce * ca + px * se * sa - gy * se, d * ce * sa - px * se * ca + gx * se,
             px * ce - gy * ce * sa - gx * ce * ca),
        stack_vector(-d * se * ca + px * ce * sa - gy * ce, -d * se * sa - px * ce * ca + gx * ce,
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
    mount: str = "patent",
    reference: bool = False,
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
        ``H(omega, eta, eps)`` of the rate model; :func:`los_rate_matrix` of ``mount`` if
        omitted (:func:`patent_eq6_matrix` to see what the printed model would give).
    mount : {"patent", "inner-gimbal"}
    reference : bool
        Compute with numpy and scipy instead of :func:`estimate_kernels.drift_rows` (same
        result to rounding; always so with a ``rate_matrix`` or the inner-gimbal mount).

    Returns
    -------
    ndarray, shape (..., N, 2, 7 or 8) [px per rad, px per rad/s]
        Columns ``[*model_names(mount), bias_x, bias_y, bias_z]``; rows ``[x_px, z_px]``.
    """
    t = np.asarray(t, float)
    gyro = np.asarray(gyro, float)
    eta, eps = np.asarray(eta, float), np.asarray(eps, float)
    k_x, k_z = np.asarray(camera.k_x, float), np.asarray(camera.k_z, float)
    if not reference and rate_matrix is None and check_mount(mount) == "patent":
        batch = np.broadcast_shapes(gyro.shape[:-2], eta.shape[:-1], eps.shape[:-1])
        return estimate_kernels.drift_rows(t, flat_batch(gyro, batch, (t.size, 3)),
                                           flat_batch(eta, batch, (t.size,)),
                                           flat_batch(eps, batch, (t.size,)), float(k_x),
                                           float(k_z)).reshape(*batch, t.size, 2, 7)
    H = rate_matrix(gyro, eta, eps) if rate_matrix else los_rate_matrix(gyro, eta, eps, mount)
    G = bias_rate_matrix(eta, eps)  # without the gyro's batch axes: broadcast to H's
    rate = np.concatenate([H, np.broadcast_to(G, (*H.shape[:-1], G.shape[-1]))], -1)
    rho = cumulative_trapezoid(image_roll_rate(gyro, eta, eps), t, axis=-1, initial=0.0)
    integrand = np.matmul(plane_rotation(-rho), rate)
    phi = np.matmul(plane_rotation(rho), cumulative_trapezoid(integrand, t, axis=-3, initial=0.0))
    return np.stack([k_x * phi[..., 1, :], -k_z * phi[..., 0, :]], axis=-2)


RAW_TO_OBSERVABLE = np.array([
    [1.0, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 1.0, 0.0],
    [0.0, 1.0, 0.0, 0.0, -1.0],
])
"""``X = T [dpx, dpz, dgx, dgy, dgz]``: the patent's five angles to the four combinations."""

RAW_TO_INNER_GIMBAL = np.array([*RAW_TO_OBSERVABLE, [0.0, 0.0, 0.0, 0.0, 1.0]])
"""The same for the inner-gimbal mount's ``X = [delta_px, delta_gx, delta_gy, delta_z, dgz]``."""


RANK_TOLERANCE = 1e-6
"""Singular values (and unexplained column norms) below this fraction of the largest column
norm count as zero: a standard deviation a million times the best one is no estimate."""


@dataclass(frozen=True)
class Observability:
    """Observability of the installation angles in one experiment.

    Attributes
    ----------
    rank : int
        Numerical rank for ``X`` (4, or 5 for the inner-gimbal mount, when every column is
        seen).
    raw_rank : int
        Rank for the patent's five angles ``[dpx, dpz, dgx, dgy, dgz]``: at most 4, since
        ``dpz`` and ``dgz`` enter only as ``delta_z = dpz - dgz``.
    raw_null_space : ndarray, shape (5 - raw_rank, 5)
        Orthonormal directions of the five angles that the data cannot see (for rank 4 the
        single row ``[0, 1, 0, 0, 1] / sqrt(2)``: equal changes of ``dpz`` and ``dgz``).
    sigma : ndarray, shape (4,) or (5,) [rad]
        Cramer-Rao standard deviation of each column of ``X`` from image noise alone, the others
        and the nuisance parameters being estimated too; ``inf`` where a combination is not
        seen independently of the others.
    """

    rank: int
    raw_rank: int
    raw_null_space: FloatArray
    sigma: FloatArray


def observability(
    record: Record, camera: Camera, image_noise: float, *, nuisance: bool = True,
    mount: str = "patent",
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
        :func:`montecarlo.seed001.estimate.estimate` does); False: known.
    mount : {"patent", "inner-gimbal"}
        ``X`` has the columns of :func:`model_names`.
    """
    n_x = len(model_names(mount))
    M = drift_matrix(record.t, record.gyro, record.eta, record.eps, camera,
                     mount=mount) / image_noise
    X = M[..., :n_x].reshape(-1, n_x)
    if nuisance:
        offset = np.broadcast_to(np.eye(2) / image_noise, (record.t.size, 2, 2))
        Q = np.linalg.qr(np.concatenate([M[..., n_x:], offset], -1).reshape(-1, 5))[0]
        X = X - Q @ (Q.T @ X)
    s = np.linalg.svd(X, compute_uv=False)
    tol = RANK_TOLERANCE * np.linalg.norm(X, axis=0).max()
    raw = RAW_TO_INNER_GIMBAL if n_x == 5 else RAW_TO_OBSERVABLE
    _, raw_s, V = np.linalg.svd(X @ raw, full_matrices=False)
    raw_rank = int(np.sum(raw_s > tol))
    null = V[raw_rank:]
    null = null * np.sign(null[np.arange(len(null)), np.argmax(np.abs(null), axis=1)])[:, None]
    sigma = np.empty(n_x)
    for j in range(n_x):
        others = np.delete(X, j, axis=1)
        residual = X[:, j] - others @ np.linalg.lstsq(others, X[:, j], rcond=None)[0]
        norm = np.linalg.norm(residual)
        sigma[j] = 1.0 / norm if norm > tol else np.inf
    return Observability(rank=int(np.sum(s > tol)),
                         raw_rank=raw_rank, raw_null_space=null, sigma=sigma)
