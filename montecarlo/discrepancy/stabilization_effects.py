"""Gyro indirect stabilisation (seed 001) with candidate effects for the discrepancy workflow.

The base model is the estimator's (:func:`montecarlo.seed001.estimate.predict_los`): the four
combinations, the camera roll, the gyro biases, the aim point, and ``delta_gz`` with the
inner-gimbal mount. Every other effect is a candidate, absent when its parameters are zero:

* ``inner_gimbal_mount`` (``camera_yaw_on_pitch`` = c [rad]): the camera's yaw installation
  angle applied after the pitch gimbal's rotation instead of added to the azimuth,
  ``C_b'^c = R_y(dpy) R_x(dpx) R_z(c) R_x(eps) R_z(eta + delta_z - c)`` in the carrier frame
  turned by ``dgz``; ``c = 0`` is eq. (2), ``c = dpz`` a camera bolted to the pitch gimbal
  (tested only against the patent mount);
* ``gyro_scale_factor`` (``gyro_scale_x, _y, _z`` [1]): the IMU reads ``(1 + s) w``;
* ``gyro_time_delay`` (``gyro_delay`` [s]): a gyro row holds the rate ``gyro_delay`` before its
  time stamp;
* ``servo_lag`` (``servo_lag`` [s]): the LOS lags the image's time stamps: the frame stamped
  ``t`` shows the gimbal and the carrier at ``t - servo_lag`` (encoder angles and gyro rate
  both read that much earlier).

The last two are timing errors of different streams. A stabilised LOS holds the target while
gimbal and carrier move together, so shifting both in time (``servo_lag``) moves the image only
by the LOS's residual drift, while shifting one against the other moves it by the whole
stabilised motion: the two candidates are nearly independent. Gimbal angles read late against
the gyro are, to first order, a gyro delay of the same size and are named
``gyro_time_delay``. (A gimbal-only lag as a candidate would be confounded with the gyro delay:
canonical correlation above 0.9996 on a 20 s run at 50 Hz, where the linearised identification
step ranks the two by less than its own linearisation error.)

The residuals are whitened with the LOS walk of gyro noise: the innovations of the Kalman filter
of the walk (the estimator's, its transition fixed at the estimate), each divided by its
standard deviation. They are white with unit variance when the model and the stated noise
levels are right.

References
----------
seed 001: patent CN102288133B, eqs. (1)-(4); docs/validation/stabilization.md, "Diagnosis".
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.interpolate import CubicSpline

from montecarlo.discrepancy.fit import FitError, fit_model
from montecarlo.discrepancy.problem import Effect, Problem
from montecarlo.discrepancy.view import SystemView
from montecarlo.geometry.camera import Camera, pixels_from_direction
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.lsq import LeastSquaresFit
from montecarlo.seed001 import estimate as se
from montecarlo.seed001.kinematics import installation_matrix, matvec
from montecarlo.seed001.simulate import Record, target_direction
from montecarlo.units import ARCMIN, DEG_PER_HOUR

FloatArray = NDArray[np.float64]

ANGLE = np.radians(5.0)
"""Bound of the installation angles of candidates [rad]."""

CANDIDATES = (
    Effect("inner_gimbal_mount", ("camera_yaw_on_pitch",), ((-ANGLE, ANGLE),), (1e-6,),
           "camera yaw applied after the pitch gimbal [rad]"),
    Effect("gyro_scale_factor", ("gyro_scale_x", "gyro_scale_y", "gyro_scale_z"),
           ((-0.02, 0.02),) * 3, (1e-6,) * 3, "gyro scale factors [1]", (1.0, 1.0, 1.0)),
    Effect("gyro_time_delay", ("gyro_delay",), ((-0.1, 0.1),), (1e-5,),
           "gyro rows late by this time [s]"),
    Effect("servo_lag", ("servo_lag",), ((-0.1, 0.1),), (1e-5,),
           "line of sight (gimbal and carrier) behind the image's time stamps by this time [s]"),
)

DISPLAY_UNITS = {
    **dict.fromkeys(("delta_px", "delta_gx", "delta_gy", "delta_z", "delta_py", "delta_gz",
                     "camera_yaw_on_pitch"), ("arcmin", ARCMIN)),
    **dict.fromkeys(("bias_x", "bias_y", "bias_z"), ("deg/h", DEG_PER_HOUR)),
    **dict.fromkeys(("aim_x", "aim_z"), ("px", 1.0)),
    **dict.fromkeys(("gyro_scale_x", "gyro_scale_y", "gyro_scale_z"), ("ppm", 1e-6)),
    **dict.fromkeys(("gyro_delay", "servo_lag"), ("ms", 1e-3)),
}
"""Parameter -> (unit shown in reports and JSON, its size in SI/radians)."""


def display_unit(name: str) -> tuple[str, float]:
    return DISPLAY_UNITS[name]


def base_effect(mount: str) -> Effect:
    names = (*se.parameter_names(mount), "aim_x", "aim_z")
    steps = tuple(1e-6 if n.startswith("delta") else 1e-9 if n.startswith("bias") else 1e-3
                  for n in names)
    return Effect("installation", names, ((-np.inf, np.inf),) * len(names), steps,
                  f"the estimator's model, {mount} mount: angles [rad], gyro biases [rad/s], "
                  "aim point [px]")


def predict_image(values: Mapping[str, FloatArray], data: Record, camera: Camera,
                  mount: str = "patent", gyro_sampling: str = "point") -> FloatArray:
    """Image position of the target under the base model and the candidates, (..., N, 2) [px].

    ``values`` maps parameter names to floats or arrays of shape (k, 1); missing ones are zero.
    With every candidate zero this is :func:`montecarlo.seed001.estimate.predict_los`.

    References
    ----------
    seed 001, eqs. (1)-(2).
    """
    def p(name: str) -> FloatArray:  # shape () or (k,)
        v = np.asarray(values.get(name, 0.0), float)
        return v[..., 0] if v.ndim else v

    def vector(*names: str) -> FloatArray:
        return np.stack(np.broadcast_arrays(*(p(n) for n in names)), axis=-1)

    t = data.t
    gyro = data.gyro
    sampling = gyro_sampling
    if "gyro_delay" in values or "servo_lag" in values:
        # the rate at t is the row stamped t + delay; an image L late shows the rate at t - L
        shift = p("gyro_delay") - p("servo_lag")
        gyro = se.rate_spline(t, gyro, gyro_sampling)(t + shift[..., None])
        sampling = "point"
    gyro = gyro / (1.0 + vector("gyro_scale_x", "gyro_scale_y", "gyro_scale_z")[..., None, :])
    C_bg = mounting_matrix(0.0, p("delta_gx"), p("delta_gy"))  # seed 001, eq. (1), dgz = 0
    omega = matvec(np.swapaxes(C_bg, -1, -2)[..., None, :, :],
                   gyro - vector("bias_x", "bias_y", "bias_z")[..., None, :])
    R = se.carrier_attitude(t, omega, sampling)
    eta, eps = data.eta, data.eps
    if "servo_lag" in values:
        later = t - p("servo_lag")[..., None]
        eta, eps = CubicSpline(t, eta)(later), CubicSpline(t, eps)(later)
    yaw = p("delta_z") + p("delta_gz") if mount == "inner-gimbal" else p("camera_yaw_on_pitch")
    install = installation_matrix(np.stack(np.broadcast_arrays(p("delta_px"), p("delta_py"),
                                                               yaw), axis=-1))
    gimbal = mounting_matrix(eta + (p("delta_z") - yaw)[..., None], eps, 0.0)
    C_bc = np.matmul(install[..., None, :, :], gimbal)  # seed 001, eq. (2), generalised
    aim = np.stack(np.broadcast_arrays(p("aim_x"), p("aim_z")), axis=-1)
    target = target_direction(C_bc[..., 0, :, :], aim, camera)
    u = np.matmul(C_bc, np.matmul(np.swapaxes(R, -1, -2), target[..., None, :, None]))[..., 0]
    return np.stack(pixels_from_direction(u, camera), axis=-1)


def walk_whitening(transition: FloatArray, walk_var: FloatArray | None, image_noise: float
                   ) -> tuple[FloatArray, FloatArray]:
    """Gains and innovation whiteners of the Kalman filter of the LOS walk.

    The image residual is ``w_k + v_k``: ``w_k = F_k w_{k-1} + q_k`` (``w_0 = 0``,
    ``q_k ~ N(0, diag(walk_var_k))``) and white ``v_k ~ N(0, image_noise^2 I)``.

    Returns
    -------
    gain : ndarray, shape (N, 2, 2)
    whiten : ndarray, shape (N, 2, 2)
        ``S_k^{-1/2}`` (inverse Cholesky factor) of each innovation's covariance.
    """
    n = transition.shape[0]
    gain, whiten = np.empty((n, 2, 2)), np.empty((n, 2, 2))
    P = np.zeros((2, 2))
    for k in range(n):
        if k > 0:
            P = transition[k] @ P @ transition[k].T
            if walk_var is not None:
                P = P + np.diag(walk_var[k])
        S = P + image_noise**2 * np.eye(2)
        gain[k] = P @ np.linalg.inv(S)
        whiten[k] = np.linalg.inv(np.linalg.cholesky(S))
        P = P - gain[k] @ P
    return gain, whiten


def whitened_innovations(residual: FloatArray, transition: FloatArray, gain: FloatArray,
                         whiten: FloatArray) -> FloatArray:
    """Innovations of image residuals (..., N, 2) through the walk's filter, whitened."""
    out = np.empty_like(residual)
    w = np.zeros((*residual.shape[:-2], 2))
    for k in range(residual.shape[-2]):
        if k > 0:
            w = w @ transition[k].T
        e = residual[..., k, :] - w
        out[..., k, :] = e @ whiten[k].T
        w = w + e @ gain[k].T
    return out


def stabilization_problem(data: Record, camera: Camera, image_noise: float,
                          gyro_noise: float = 0.0, mount: str = "patent",
                          gyro_sampling: str = "point", est: se.Estimate | None = None
                          ) -> Problem:
    """The DIA problem of one recording: the base model started at the estimator's result
    (``est``, computed here if None)."""
    if est is None:
        est = se.estimate(data.t, data.gyro, data.eta, data.eps, data.los_px, camera,
                          image_noise, gyro_noise, mount=mount, gyro_sampling=gyro_sampling)
    base = base_effect(mount)
    start = dict(zip(base.parameters, [*est.values.tolist(), *est.aim_px.tolist()],
                     strict=True))
    J = se.los_jacobian(data.t, data.gyro, data.eta, data.eps, est.values, camera,
                        aim_px=est.aim_px, mount=mount, gyro_sampling=gyro_sampling,
                        columns="aim")
    transition = J @ np.linalg.inv(np.concatenate([J[:1], J[:-1]], axis=0))
    walk_var = None
    if gyro_noise > 0.0:
        k = np.array([float(camera.k_x), float(camera.k_z)])
        walk_var = gyro_noise**2 * np.diff(data.t, prepend=data.t[0])[:, None] * k**2
    gain, whiten = walk_whitening(transition, walk_var, image_noise)

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        r = data.los_px - predict_image(values, data, camera, mount, gyro_sampling)
        r = whitened_innovations(r, transition, gain, whiten)
        return r.reshape(*r.shape[:-2], -1)

    candidates = CANDIDATES if mount == "patent" else CANDIDATES[1:]
    unavailable = {} if mount == "patent" else {
        "inner_gimbal_mount": "the base model already has the inner-gimbal mount"}
    return Problem("stabilization", base, candidates, residuals, start, unavailable)


def raw_residuals(data: Record, camera: Camera, params: Mapping[str, float], mount: str,
                  gyro_sampling: str) -> FloatArray:
    """Measured minus predicted image position, shape (N, 2) [px] (the walk not removed)."""
    return data.los_px - predict_image(params, data, camera, mount, gyro_sampling)


def report_view(data: Record, camera: Camera, mount: str, gyro_sampling: str) -> SystemView:
    """How the JSON and text reports show a stabilisation diagnosis."""
    def study_params(fit: LeastSquaresFit) -> dict[str, object]:
        raise NotImplementedError("no Monte Carlo of stabilisation diagnoses")

    return SystemView("stabilization", display_unit, "px", 1.0, ("x", "z"),
                      lambda params: raw_residuals(data, camera, params, mount, gyro_sampling),
                      [("time [s]", data.t, None)], "stabilization", study_params)


# --------------------------------------------------------------------------------------------
# Conventions of the recording
# --------------------------------------------------------------------------------------------

CONVENTIONS = {
    "eta_rad": "eta counted the other way (the model's eta > 0 turns the LOS left, "
               "counter-clockwise seen from above)",
    "eps_rad": "eps counted the other way (the model's eps > 0 turns the LOS up)",
    "los_x_px": "image x pointing the other way (the model's x is to the right)",
    "los_z_px": "image z pointing the other way (the model's z is up)",
}
"""Columns whose sign another author may define the other way -> what the model assumes."""

SMALL_ANGLE = np.radians(30.0)
"""Installation angles beyond this (after wrapping into (-180°, 180°]) are not installation
errors: a frame or sign convention differs (an eta counted clockwise fits exactly with half
turns about x in delta_px and delta_gx) [rad]."""

ANGLES = ("delta_px", "delta_gx", "delta_gy", "delta_z", "delta_py", "delta_gz")


def large_angles(params: Mapping[str, float]) -> dict[str, float]:
    """The installation angles of a fit beyond :data:`SMALL_ANGLE`, wrapped into (-pi, pi]
    [rad]."""
    out = {}
    for name in ANGLES:
        if name in params:
            wrapped = float(np.angle(np.exp(1j * float(params[name]))))
            if abs(wrapped) > SMALL_ANGLE:
                out[name] = wrapped
    return out


def flipped(data: Record, column: str) -> Record:
    """The recording with the sign of one column of :data:`CONVENTIONS` changed."""
    if column == "eta_rad":
        return Record(data.t, data.gyro, -data.eta, data.eps, data.los_px)
    if column == "eps_rad":
        return Record(data.t, data.gyro, data.eta, -data.eps, data.los_px)
    sign = np.array([-1.0, 1.0]) if column == "los_x_px" else np.array([1.0, -1.0])
    return Record(data.t, data.gyro, data.eta, data.eps, data.los_px * sign)


def convention_check(data: Record, camera: Camera, image_noise: float, gyro_noise: float,
                     mount: str, gyro_sampling: str, base: LeastSquaresFit, alpha: float
                     ) -> dict[str, object]:
    """Whether the recording's conventions differ from the model's, and which.

    Run when the base model fails the global test at ``alpha`` or fits only with installation
    angles that are not small (:func:`large_angles`): the base model is fitted again to the
    recording with each column of :data:`CONVENTIONS` negated in turn (when the estimator
    converges on it), and a column is named when that fit passes the global test with small
    angles. A recording the model fits with small angles is not checked (``checked`` false).

    Both image axes may be named: negating both turns the image by a half turn about its
    centre, which (for a target near the centre) the model explains by negating the four
    combinations, so a recording with one image axis the other way fits with either negated.

    Returns
    -------
    dict
        ``checked`` (bool), ``large_angles`` ({name: angle [rad]} of the base fit), ``named``
        (columns whose negation makes the model fit), ``fits`` ({column: {"chi2_red",
        "p_value", "large_angles"}} of each refit).
    """
    large = large_angles(base.params)
    p_base = float(stats.chi2.sf(base.chi2, base.dof))
    out: dict[str, object] = {"checked": False, "large_angles": large, "named": [], "fits": {}}
    if p_base >= alpha and not large:
        return out
    out["checked"] = True
    fits: dict[str, dict[str, object]] = {}
    for column in CONVENTIONS:
        other = flipped(data, column)
        try:  # the estimator may break down on data the model cannot explain
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                est = se.estimate(other.t, other.gyro, other.eta, other.eps, other.los_px,
                                  camera, image_noise, gyro_noise, mount=mount,
                                  gyro_sampling=gyro_sampling)
                if not est.converged:
                    continue
                fit = fit_model(stabilization_problem(other, camera, image_noise, gyro_noise,
                                                      mount, gyro_sampling, est), ())
        except (FitError, np.linalg.LinAlgError, ValueError):
            continue
        fits[column] = {"chi2_red": fit.chi2_red,
                        "p_value": float(stats.chi2.sf(fit.chi2, fit.dof)),
                        "large_angles": large_angles(fit.params)}
    out["fits"] = fits
    out["named"] = [c for c, f in fits.items()
                    if f["p_value"] >= alpha and not f["large_angles"]]
    return out
