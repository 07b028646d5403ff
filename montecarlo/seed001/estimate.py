"""Installation angles of seed 001 by recursive least squares on the image drift of the target.

Third step of the patent's claim: the measured LOS error is the measurement, the error model of
the first step the regressor, recursive least squares (RLS) the estimator. Here:

* the measurement is the target's image position ``[x_px, z_px]`` (the drift), not its rate:
  image noise is white on the position, differencing it would correlate it;
* the residual is always computed with the exact kinematics (:func:`predict_los`);
* the first RLS pass uses the first-order rows about zero,
  :func:`montecarlo.seed001.linear_model.drift_matrix` (the derived eq. (6) integrated over time,
  image roll included): alone, that is the patent's linear estimate, whose error is of the order of
  the angles squared. Further passes use the exact Jacobian (:func:`los_jacobian`) about the
  current estimate until the estimate no longer moves (Gauss-Newton in RLS form);
* the state carries, beside the parameters, the target's image offset as a random walk: its
  initial value is the unknown aim point, its increments the LOS walk that white gyro noise
  drives through the loop (isotropic, density = the gyro noise density; see
  :func:`montecarlo.seed001.linear_model.bias_rate_matrix`). Without gyro noise this is plain RLS.

Parameters (``PARAMETER_NAMES``): the four observable combinations
``[delta_px, delta_gx, delta_gy, delta_z]`` (``delta_z = dpz - dgz``), the camera roll about the
LOS ``delta_py`` (seen only through the turn it gives the image drift, so weakly), and the gyro
biases ``[bias_x, bias_y, bias_z]``.

References
----------
seed 001: patent CN102288133B, claim 1, third and fourth steps; eqs. (1)-(6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from montecarlo.geometry.camera import Camera, pixels_from_direction
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed001 import estimate_kernels
from montecarlo.seed001.kinematics import (
    camera_matrix,
    check_mount,
    flat_batch,
    installation_matrix,
)
from montecarlo.seed001.linear_model import drift_matrix
from montecarlo.seed001.simulate import (
    Compensation,
    Record,
    Setup,
    check_sampling,
    target_direction,
)

FloatArray = NDArray[np.float64]

PARAMETER_NAMES = ("delta_px", "delta_gx", "delta_gy", "delta_z", "delta_py",
                   "bias_x", "bias_y", "bias_z")
"""Estimated parameters, in state order; angles [rad], biases [rad/s]."""

ROLL = PARAMETER_NAMES.index("delta_py")

INNER_GIMBAL_PARAMETER_NAMES = (*PARAMETER_NAMES, "delta_gz")
"""With the inner-gimbal mount ``dgz`` is estimated too, after the biases; ``dpz = delta_z +
dgz``."""


def parameter_names(mount: str = "patent") -> tuple[str, ...]:
    """Estimated parameters of a camera mount, in state order."""
    return INNER_GIMBAL_PARAMETER_NAMES if check_mount(mount) == "inner-gimbal" \
        else PARAMETER_NAMES

PRIOR_SIGMA = {"angle": np.radians(5.0), "bias": np.radians(50.0) / 3600.0, "offset": 100.0}
"""Prior standard deviations: installation angles [rad], gyro biases [rad/s], the aim point's
correction in each pass [px]. Wide enough not to pull observable parameters; they keep the
unobservable ones (e.g. ``delta_py`` when the drift is small) finite."""


def rate_spline(t: ArrayLike, omega: ArrayLike, sampling: str = "point"):
    """Continuous rate through gyro samples: a callable ``omega(t)``, shape (..., 3) [rad/s].

    ``point``: the cubic spline through the samples. ``interval-mean`` (row k is the mean over
    ``(t_{k-1}, t_k]``, the first interval as long as the second): the derivative of the cubic
    spline through the accumulated delta-angles, so that its mean over each interval is the
    sample.
    """
    t = np.asarray(t, float)
    omega = np.asarray(omega, float)
    axis = omega.ndim - 2
    if check_sampling(sampling) == "point":
        return CubicSpline(t, omega, axis=axis)
    edges = np.concatenate([[2.0 * t[0] - t[1]], t])
    step = np.diff(edges)[:, None] * omega
    angle = np.concatenate([np.zeros_like(step[..., :1, :]), np.cumsum(step, axis=-2)], axis=-2)
    return CubicSpline(edges, angle, axis=axis).derivative()


def gauss_points(t: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The two Gauss points ``t_mid -/+ h sqrt(3)/6`` of each step of ``t`` [s]."""
    t = np.asarray(t, float)
    h = np.diff(t)
    mid, half = t[:-1] + 0.5 * h, h * np.sqrt(3.0) / 6.0
    return mid - half, mid + half


def carrier_attitude(t: ArrayLike, omega: ArrayLike, sampling: str = "point") -> FloatArray:
    """Attitude of the carrier relative to its attitude at ``t[0]``, from its sampled rate.

    The rate is interpolated by a cubic spline (:func:`rate_spline`) and each step integrated
    by the fourth-order Magnus formula with two Gauss points,
    ``Omega = h/2 (w1 + w2) + sqrt(3)/12 h^2 w1 x w2``.

    Parameters
    ----------
    t : array_like, shape (N,) [s]
    omega : array_like, shape (..., N, 3) [rad/s]
        Body rate in body axes.
    sampling : {"point", "interval-mean"}
        What a sample of ``omega`` is (:data:`montecarlo.seed001.simulate.GYRO_SAMPLINGS`).

    Returns
    -------
    ndarray, shape (..., N, 3, 3)
        ``C_{b_k}^{b_0}`` (maps carrier axes at ``t_k`` to carrier axes at ``t_0``).
    """
    t = np.asarray(t, float)
    omega = np.asarray(omega, float)
    spline = rate_spline(t, omega, sampling)
    h = np.diff(t)
    mid, half = t[:-1] + 0.5 * h, h * np.sqrt(3.0) / 6.0
    w1, w2 = spline(mid - half), spline(mid + half)
    rotvec = (0.5 * h[:, None]) * (w1 + w2) + (np.sqrt(3.0) / 12.0 * h[:, None] ** 2) * np.cross(
        w1, w2)
    step = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix().reshape(*rotvec.shape, 3)
    # prefix products step_0 step_1 ... step_k (Hillis-Steele scan)
    d = 1
    while d < step.shape[-3]:
        step = np.concatenate([step[..., :d, :, :], step[..., :-d, :, :] @ step[..., d:, :, :]],
                              axis=-3)
        d *= 2
    eye = np.broadcast_to(np.eye(3), (*step.shape[:-3], 1, 3, 3))
    return np.concatenate([eye, step], axis=-3)


def predict_los(
    t: ArrayLike,
    gyro: ArrayLike,
    eta: ArrayLike,
    eps: ArrayLike,
    params: ArrayLike,
    camera: Camera,
    aim_px: ArrayLike = 0.0,
    *,
    mount: str = "patent",
    gyro_sampling: str = "point",
) -> FloatArray:
    """Image position of the target predicted with the exact kinematics for given parameters.

    The carrier rate is rebuilt from the IMU output, ``w_b = (R_y(dgy) R_x(dgx))^T (w_m - bias)``
    (in the carrier frame turned by ``dgz``), integrated to the carrier's attitude; the camera
    is at the encoder angles: ``camera_matrix(eta, eps, [dpx, dpy, delta_z])`` with the patent
    mount (``dpz`` becomes ``delta_z`` in the turned frame), ``camera_matrix(eta - dgz, eps,
    [dpx, dpy, delta_z + dgz])`` with the inner-gimbal mount; the target is the fixed direction
    imaged at ``aim_px`` at ``t[0]``.

    Parameters
    ----------
    t : array_like, shape (N,) [s]
    gyro : array_like, shape (..., N, 3) [rad/s]
    eta, eps : array_like, shape (..., N) [rad]
    params : array_like, shape (..., 8) or (..., 9)
        In the order of :func:`parameter_names` of ``mount``.
    camera : Camera
    aim_px : array_like, shape (..., 2) [px]
        Image position of the target at ``t[0]`` (the aim point).
    mount : {"patent", "inner-gimbal"}
    gyro_sampling : {"point", "interval-mean"}

    Returns
    -------
    ndarray, shape (..., N, 2) [px]

    References
    ----------
    seed 001, eqs. (1)-(2).
    """
    p = np.asarray(params, float)
    C_bg = mounting_matrix(0.0, p[..., 1], p[..., 2])  # seed 001, eq. (1) with dgz = 0
    omega_b = np.matmul(np.swapaxes(C_bg, -1, -2)[..., None, :, :],
                        (np.asarray(gyro, float) - p[..., None, 5:8])[..., None])[..., 0]
    R = carrier_attitude(t, omega_b, gyro_sampling)
    if check_mount(mount) == "inner-gimbal":
        dgz = p[..., 8, None]
        delta_p = np.stack([p[..., 0], p[..., 4], p[..., 3] + p[..., 8]], axis=-1)
        C_bc = camera_matrix(np.asarray(eta) - dgz, eps, delta_p[..., None, :], mount)
    else:
        delta_p = np.stack([p[..., 0], p[..., 4], p[..., 3]], axis=-1)
        C_bc = camera_matrix(eta, eps, delta_p[..., None, :])  # seed 001, eq. (2)
    aim = np.asarray(aim_px, float)
    aim = np.broadcast_to(aim, (*np.broadcast_shapes(C_bc.shape[:-3], aim.shape[:-1]), 2))
    target = target_direction(C_bc[..., 0, :, :], aim, camera)
    target_k = np.matmul(np.swapaxes(R, -1, -2), target[..., None, :, None])
    u = np.matmul(C_bc, target_k)[..., 0]
    return np.stack(pixels_from_direction(u, camera), axis=-1)


JACOBIAN_STEP = np.array([1e-6] * 5 + [1e-9] * 3)
"""Forward-difference steps of :func:`los_jacobian`: angles [rad], biases [rad/s]; ``dgz``
(inner-gimbal mount) takes the angles' step, the aim point ``AIM_STEP``."""

AIM_STEP = 1e-3
"""Forward-difference step of the aim point [px]."""


def los_jacobian(
    t: ArrayLike,
    gyro: ArrayLike,
    eta: ArrayLike,
    eps: ArrayLike,
    params: ArrayLike,
    camera: Camera,
    predicted: ArrayLike | None = None,
    aim_px: ArrayLike = 0.0,
    *,
    mount: str = "patent",
    gyro_sampling: str = "point",
    columns: str = "all",
) -> FloatArray:
    """Jacobian of :func:`predict_los` with respect to the parameters, by forward differences.

    ``columns``: ``"all"`` (the parameters, then the aim point ``[x, z]``), ``"params"`` or
    ``"aim"``.

    Returns
    -------
    ndarray, shape (..., N, 2, n) [px per parameter unit]
    """
    params = np.asarray(params, float)
    aim = np.asarray(aim_px, float) + np.zeros(2)
    kw = {"mount": mount, "gyro_sampling": gyro_sampling}
    if predicted is None:
        predicted = predict_los(t, gyro, eta, eps, params, camera, aim, **kw)
    steps = np.append(JACOBIAN_STEP, [1e-6] * (params.shape[-1] - JACOBIAN_STEP.size))
    out = []
    if columns in ("all", "params"):
        for j, h in enumerate(steps):
            moved = params.copy()
            moved[..., j] += h
            out.append((predict_los(t, gyro, eta, eps, moved, camera, aim, **kw) - predicted) / h)
    if columns in ("all", "aim"):
        for j in range(2):
            moved = aim.copy()
            moved[..., j] += AIM_STEP
            out.append((predict_los(t, gyro, eta, eps, params, camera, moved, **kw)
                        - predicted) / AIM_STEP)
    return np.stack(out, axis=-1)


class LosModel:
    """:func:`predict_los` and :func:`los_jacobian` of one batch of runs, compiled.

    The gyro output is splined once (:func:`rate_spline` is linear, so the rate of any
    parameters is the same affine map of the splined gyro output, applied by
    :func:`estimate_kernels.predicted_pixels`; :func:`estimate_kernels.spline_at` for point
    samples, scipy for interval means) and the cosines and sines of the gimbal angles are taken
    once, both with the runs last (the kernel's layout). The prediction and the forward
    differences of the Jacobian are one kernel call; sets that share the base's attitude or
    camera share their computation.

    Parameters
    ----------
    t : array_like, shape (N,) [s]
    gyro : array_like, shape (B, N, 3) [rad/s]
    eta, eps : array_like, shape (B, N) [rad]
    camera : Camera
    mount : {"patent", "inner-gimbal"}
    gyro_sampling : {"point", "interval-mean"}
    """

    ATTITUDE = (1, 2, 5, 6, 7)
    """Parameters that turn the carrier's attitude rebuilt from the gyro output."""

    def __init__(self, t: ArrayLike, gyro: ArrayLike, eta: ArrayLike, eps: ArrayLike,
                 camera: Camera, mount: str = "patent", gyro_sampling: str = "point") -> None:
        t = np.asarray(t, float)
        gyro = np.ascontiguousarray(gyro, float)
        self.h = np.diff(t)
        if check_sampling(gyro_sampling) == "point" and t.size >= 4:
            self.w1, self.w2 = estimate_kernels.spline_at(t, gyro, *gauss_points(t))
        else:
            spline = rate_spline(t, gyro, gyro_sampling)
            self.w1, self.w2 = (np.ascontiguousarray(np.moveaxis(spline(g), 0, -1))
                                for g in gauss_points(t))
        self.trig = [f(np.ascontiguousarray(np.asarray(a, float).T))
                     for a in (eta, eps) for f in (np.cos, np.sin)]
        self.k_x, self.k_z = float(camera.k_x), float(camera.k_z)
        self.shape = np.shape(eta)
        self.inner = check_mount(mount) == "inner-gimbal"
        self.camera_columns = (0, 3, 4, 8) if self.inner else (0, 3, 4)

    def _pixels(self, sets: FloatArray, aims: FloatArray, steps: ArrayLike = (0.0,)
                ) -> tuple[FloatArray, FloatArray]:
        """Image of the target at parameters ``sets[0]`` (shape (S, B, n)) and aim point
        ``aims[0]`` (shape (S, B, 2)), shape (B, N, 2), and the difference quotients of the
        other sets, shape (B, N, 2, S - 1)."""
        C_bg = mounting_matrix(0.0, sets[..., 1], sets[..., 2])  # seed 001, eq. (1), dgz = 0
        zero = np.zeros(sets.shape[:-1])
        if self.inner:  # camera_matrix(eta - dgz, eps, [dpx, dpy, delta_z + dgz], inner)
            install = installation_matrix(np.stack(
                [sets[..., 0], sets[..., 4], sets[..., 3] + sets[..., 8]], axis=-1))
            offsets = np.stack([-sets[..., 8], zero], axis=-1)
        else:  # camera_matrix(eta, eps, [dpx, dpy, delta_z]), seed 001, eq. (2)
            install = mounting_matrix(0.0, 0.0, sets[..., 4])
            offsets = np.stack([sets[..., 3], sets[..., 0]], axis=-1)

        def first_equal(columns: tuple[int, ...]) -> NDArray[np.int64]:
            """For each set, 0 if its ``columns`` equal those of set 0, else its own index."""
            moved = np.any(sets[..., list(columns)] != sets[:1, ..., list(columns)], axis=(1, 2))
            return np.where(moved, np.arange(len(sets)), 0)

        out = np.empty((*self.shape, 2))
        diff = np.empty((*self.shape, 2, len(sets) - 1))
        estimate_kernels.predicted_pixels(self.h, self.w1, self.w2,
                                          np.ascontiguousarray(np.swapaxes(C_bg, -1, -2)),
                                          np.ascontiguousarray(sets[..., 5:8]),
                                          first_equal(self.ATTITUDE), *self.trig,
                                          np.ascontiguousarray(install),
                                          np.ascontiguousarray(offsets),
                                          first_equal(self.camera_columns),
                                          np.ascontiguousarray(aims),
                                          self.k_x, self.k_z, np.asarray(steps, float), out, diff)
        return out, diff

    def predict(self, params: ArrayLike, aim_px: ArrayLike) -> FloatArray:
        """:func:`predict_los` at ``params`` (shape (B, n)) and ``aim_px`` (shape (B, 2)),
        shape (B, N, 2) [px]."""
        return self._pixels(np.asarray(params, float)[None], np.asarray(aim_px, float)[None])[0]

    def predict_and_jacobian(self, params: ArrayLike, aim_px: ArrayLike, columns: str = "all"
                             ) -> tuple[FloatArray, FloatArray]:
        """:func:`predict_los` and :func:`los_jacobian` (its ``columns``) at ``params`` and
        ``aim_px``, shapes (B, N, 2) and (B, N, 2, n + 2), (B, N, 2, n) or (B, N, 2, 2)."""
        p = np.asarray(params, float)
        aim = np.asarray(aim_px, float)
        steps = [0.0]
        if columns in ("all", "params"):
            steps += list(JACOBIAN_STEP) + [1e-6] * (p.shape[-1] - JACOBIAN_STEP.size)
        n_moved = len(steps) - 1
        if columns in ("all", "aim"):
            steps += [AIM_STEP] * 2
        sets = np.repeat(p[None], len(steps), axis=0)
        aims = np.repeat(aim[None], len(steps), axis=0)
        for j in range(n_moved):
            sets[1 + j, :, j] += steps[1 + j]
        for j in range(len(steps) - 1 - n_moved):
            aims[1 + n_moved + j, :, j] += AIM_STEP
        return self._pixels(sets, aims, steps)


def recursive_least_squares(
    rows: ArrayLike,
    obs: ArrayLike,
    prior_mean: ArrayLike,
    prior_cov: ArrayLike,
    noise_var: float,
    *,
    forgetting: float = 1.0,
    walk_transition: ArrayLike | None = None,
    walk_var: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Recursive least squares with covariance for ``y_k = A_k x + w_k + v_k``.

    ``x`` (p parameters) is constant; ``w_k`` (2 values, the last two states) is an offset that
    is constant too, or a random walk ``w_k = F_k w_{k-1} + q_k``, ``q_k ~ N(0, Q_k)``;
    ``v_k ~ N(0, noise_var I)``. Each step is a Kalman update; with ``w`` constant and
    ``forgetting = 1`` it is ordinary RLS and ends at the batch least-squares solution with the
    prior. ``forgetting = lambda < 1`` divides the covariance by lambda before each update
    (exponential forgetting; the covariance is then no longer that of the final estimate).

    Parameters
    ----------
    rows : array_like, shape (..., N, 2, p)
    obs : array_like, shape (..., N, 2)
    prior_mean : array_like, shape (..., p + 2)
    prior_cov : array_like, shape (..., p + 2, p + 2)
    noise_var : float
        Variance of each measurement component.
    forgetting : float in (0, 1]
    walk_transition : array_like, shape (..., N, 2, 2), optional
        ``F_k`` (``F_0`` unused); identity if omitted.
    walk_var : array_like, shape (..., N, 2), optional
        ``Q_k = diag(walk_var_k)``; zero if omitted.

    Returns
    -------
    mean : ndarray, shape (..., p + 2)
    cov : ndarray, shape (..., p + 2, p + 2)

    References
    ----------
    seed 001, claim 1, third step (recursive least squares).
    """
    rows = np.asarray(rows, float)
    obs = np.asarray(obs, float)
    n_steps, p = rows.shape[-3], rows.shape[-1]
    batch = np.broadcast_shapes(rows.shape[:-3], obs.shape[:-2], np.shape(prior_mean)[:-1],
                                np.shape(prior_cov)[:-2], np.shape(walk_var)[:-2],
                                np.shape(walk_transition)[:-3])
    x = np.array(np.broadcast_to(prior_mean, (*batch, p + 2)), float)
    P = np.array(np.broadcast_to(prior_cov, (*batch, p + 2, p + 2)), float)
    eye2 = np.eye(2)
    rows = np.broadcast_to(rows, (*batch, *rows.shape[-3:]))
    obs = np.broadcast_to(obs, (*batch, *obs.shape[-2:]))
    for k in range(n_steps):
        if k > 0 and walk_transition is not None:
            F = np.asarray(walk_transition[..., k, :, :])
            x[..., p:] = (F @ x[..., p:, None])[..., 0]
            P[..., p:, :] = F @ P[..., p:, :]
            P[..., :, p:] = P[..., :, p:] @ np.swapaxes(F, -1, -2)
        if k > 0 and walk_var is not None:
            P[..., p:, p:] += np.asarray(walk_var)[..., k, :, None] * eye2
        if forgetting != 1.0:
            P /= forgetting
        A = np.concatenate([rows[..., k, :, :], np.broadcast_to(eye2, (*batch, 2, 2))], -1)
        PAt = P @ np.swapaxes(A, -1, -2)
        S = A @ PAt + noise_var * eye2
        K = PAt @ np.linalg.inv(S)
        x += (K @ (obs[..., k, :] - (A @ x[..., None])[..., 0])[..., None])[..., 0]
        P -= K @ np.swapaxes(PAt, -1, -2)
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
    return x, P


@dataclass(frozen=True)
class Estimate:
    """Estimated parameters and their covariance.

    Attributes
    ----------
    values : ndarray, shape (..., n)
        In the order of :func:`parameter_names` of ``mount`` (8 parameters, 9 with the
        inner-gimbal mount); angles [rad], biases [rad/s].
    covariance : ndarray, shape (..., n, n)
    passes : int
        RLS passes run.
    converged : ndarray of bool, shape (...)
        The last pass moved every parameter and the aim point by less than ``tol`` of their
        standard deviations.
    residual_rms : ndarray, shape (...) [px]
        RMS per image axis of the measured minus the predicted image position (with the
        estimated aim point); it includes the LOS walk of gyro noise.
    aim_px : ndarray, shape (..., 2) [px]
        Estimated image position of the target at the first sample.
    mount : str
    """

    values: FloatArray
    covariance: FloatArray
    passes: int
    converged: NDArray[np.bool_]
    residual_rms: FloatArray
    aim_px: FloatArray
    mount: str = "patent"

    @property
    def names(self) -> tuple[str, ...]:
        return parameter_names(self.mount)

    @property
    def sigma(self) -> FloatArray:
        """Standard deviations, shape (..., n)."""
        return np.sqrt(np.diagonal(self.covariance, axis1=-2, axis2=-1))

    @property
    def observable(self) -> FloatArray:
        """``[delta_px, delta_gx, delta_gy, delta_z]``, shape (..., 4) [rad]."""
        return self.values[..., :4]

    def compensation(self) -> Compensation:
        """The corrections a stabilisation loop applies (claim 1, fourth step)."""
        dgz = self.values[..., 8] if self.mount == "inner-gimbal" else 0.0
        return Compensation(angles=self.values[..., :4], gyro_bias=self.values[..., 5:8],
                            delta_gz=dgz, mount=self.mount)


def estimate(
    t: ArrayLike,
    gyro: ArrayLike,
    eta: ArrayLike,
    eps: ArrayLike,
    los_px: ArrayLike,
    camera: Camera,
    image_noise: float,
    gyro_noise: float = 0.0,
    *,
    mount: str = "patent",
    gyro_sampling: str = "point",
    forgetting: float = 1.0,
    max_passes: int = 10,
    tol: float = 1e-2,
    reference: bool = False,
) -> Estimate:
    """Estimate installation angles, gyro biases and the aim point from a run (or a batch).

    The state of each RLS pass holds the corrections to the parameters and to the aim point
    (the target's image at ``t[0]``, started at the first measured position, prior
    ``PRIOR_SIGMA["offset"]`` per pass) and the LOS walk of gyro noise: it starts at zero, its
    increments have variance ``gyro_noise**2 dt k**2`` per axis, and it turns as an error of the
    aim point does, ``F_k = J_k J_{k-1}^-1`` with ``J_k`` the aim point's Jacobian (the true
    image roll and the pinhole's scale at the current parameters).

    Parameters
    ----------
    t : array_like, shape (N,) [s]
    gyro : array_like, shape (..., N, 3) [rad/s]
    eta, eps : array_like, shape (..., N) [rad]
    los_px : array_like, shape (..., N, 2) [px]
        Measured image position of the target.
    camera : Camera
    image_noise : float [px]
        Standard deviation of each image coordinate.
    gyro_noise : float [rad/s/sqrt(Hz)]
        White-noise density of the gyros (0: no LOS walk is modelled).
    mount : {"patent", "inner-gimbal"}
        Camera mount of the model (:func:`montecarlo.seed001.kinematics.camera_matrix`).
    gyro_sampling : {"point", "interval-mean"}
        What a gyro row holds (:data:`montecarlo.seed001.simulate.GYRO_SAMPLINGS`).
    forgetting : float in (0, 1]
    max_passes : int
        RLS passes. The first uses the first-order rows about zero
        (:func:`montecarlo.seed001.linear_model.drift_matrix`; alone, it is the patent's linear
        estimate), the next ones the exact Jacobian at the current estimate
        (:func:`los_jacobian`).
    tol : float
        Convergence: every parameter moved by less than ``tol`` standard deviations.
    reference : bool
        Run the literal numpy functions (:func:`predict_los`, :func:`los_jacobian`,
        :func:`recursive_least_squares`) instead of :class:`LosModel` and
        :func:`estimate_kernels.rls_pass` (the same results to rounding, many times slower).

    Returns
    -------
    Estimate
    """
    t = np.asarray(t, float)
    gyro, eta, eps, los_px = (np.asarray(a, float) for a in (gyro, eta, eps, los_px))
    batch = np.broadcast_shapes(gyro.shape[:-2], eta.shape[:-1], eps.shape[:-1],
                                los_px.shape[:-2])
    names = parameter_names(mount)
    n_par = len(names)
    kw = {"mount": mount, "gyro_sampling": gyro_sampling}
    model = drift_matrix(t, gyro, eta, eps, camera, mount=mount,
                         reference=reference)  # first order about zero
    n_x = model.shape[-1] - 3
    first_rows = np.zeros((*model.shape[:-1], n_par))
    first_rows[..., :4] = model[..., :4]
    first_rows[..., 5:8] = model[..., n_x:]
    first_rows[..., 8:] = model[..., 4:n_x]
    walk_var = None
    if gyro_noise > 0.0:
        dt = np.diff(t, prepend=t[0])[:, None]
        k = np.array([float(camera.k_x), float(camera.k_z)])
        walk_var = np.broadcast_to(gyro_noise**2 * dt * k**2, (*batch, t.size, 2))

    sig = np.array([PRIOR_SIGMA["angle"]] * 5 + [PRIOR_SIGMA["bias"]] * 3
                   + [PRIOR_SIGMA["angle"]] * (n_par - 8) + [PRIOR_SIGMA["offset"]] * 2)
    prior_cov = np.diag(np.append(sig**2, [0.0, 0.0]))
    params = np.zeros((*batch, n_par))
    aim = np.array(np.broadcast_to(los_px[..., 0, :], (*batch, 2)))
    converged = np.zeros(batch, bool)
    cov = np.broadcast_to(prior_cov[:n_par, :n_par], (*batch, n_par, n_par))
    if reference:
        def predict(q, a):
            return predict_los(t, gyro, eta, eps, q, camera, a, **kw)

        def predict_and_jacobian(q, a, columns):
            predicted = predict(q, a)
            return predicted, los_jacobian(t, gyro, eta, eps, q, camera, predicted, a,
                                           columns=columns, **kw)

        def rls(rows, obs, prior_mean):
            J = rows[..., n_par:]
            transition = J @ np.linalg.inv(np.concatenate([J[..., :1, :, :], J[..., :-1, :, :]],
                                                          axis=-3))
            return recursive_least_squares(rows, obs, prior_mean, prior_cov, image_noise**2,
                                           forgetting=forgetting, walk_transition=transition,
                                           walk_var=walk_var)
    else:
        n_t = t.size
        model = LosModel(t, flat_batch(gyro, batch, (n_t, 3)), flat_batch(eta, batch, (n_t,)),
                         flat_batch(eps, batch, (n_t,)), camera, **kw)
        walk_flat = flat_batch(0.0 if walk_var is None else walk_var, batch, (n_t, 2))
        cov_flat = flat_batch(prior_cov, batch, prior_cov.shape)

        def predict(q, a):
            return model.predict(q.reshape(-1, n_par), a.reshape(-1, 2)).reshape(*batch, n_t, 2)

        def predict_and_jacobian(q, a, columns):
            predicted, rows = model.predict_and_jacobian(q.reshape(-1, n_par), a.reshape(-1, 2),
                                                         columns)
            return (predicted.reshape(*batch, n_t, 2),
                    rows.reshape(*batch, n_t, 2, rows.shape[-1]))

        def rls(rows, obs, prior_mean):
            p = rows.shape[-1]
            rows = flat_batch(rows, batch, (n_t, 2, p))
            transition = estimate_kernels.walk_transition(rows[..., n_par:])
            x, P = estimate_kernels.rls_pass(rows, flat_batch(obs, batch, (n_t, 2)),
                                             flat_batch(prior_mean, batch, (p + 2,)), cov_flat,
                                             image_noise**2, forgetting, transition, walk_flat)
            return x.reshape(*batch, p + 2), P.reshape(*batch, p + 2, p + 2)

    passes = 0
    for passes in range(1, max_passes + 1):
        if passes == 1:
            predicted, aim_rows = predict_and_jacobian(params, aim, "aim")
            rows = np.concatenate([np.broadcast_to(first_rows, (*batch, *first_rows.shape[-3:])),
                                   aim_rows], axis=-1)
        else:
            predicted, rows = predict_and_jacobian(params, aim, "all")
        x, P = rls(rows, los_px - predicted,
                   np.concatenate([-params, np.zeros((*batch, 4))], axis=-1))
        params = params + x[..., :n_par]
        aim = aim + x[..., n_par:n_par + 2]
        cov = P[..., :n_par, :n_par]
        step = np.abs(x[..., :n_par + 2]) / np.sqrt(
            np.diagonal(P, axis1=-2, axis2=-1)[..., :n_par + 2])
        converged = np.all(step < tol, axis=-1)
        if np.all(converged):
            break
    residual = los_px - predict(params, aim)
    rms = np.sqrt(np.mean(residual**2, axis=(-2, -1)))
    return Estimate(values=params, covariance=cov, passes=passes, converged=converged,
                    residual_rms=rms, aim_px=aim, mount=mount)


def estimate_record(record: Record, setup: Setup, **kwargs) -> Estimate:
    """:func:`estimate` on a simulated record with the setup's camera and noise levels."""
    kwargs = {"mount": setup.mount, "gyro_sampling": setup.gyro_sampling, **kwargs}
    return estimate(record.t, record.gyro, record.eta, record.eps, record.los_px, setup.camera,
                    setup.image_noise, setup.gyro_noise, **kwargs)
