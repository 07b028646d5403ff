"""The error sources that limit a real transfer alignment, as the truth draws them.

The filter of :mod:`montecarlo.seed000.transfer_alignment` models a slave IMU with constant
biases and white noises aligned to a perfect master. A real alignment also has (each here an
error source of the truth, which the filter does not model unless its tuning is inflated for it,
:func:`inflated_tuning`):

* **time-tag offset and jitter** ``tau_k = offset + jitter * n_k``: the master's data used at
  the update at ``t_k`` are valid at ``t_k - tau_k``. A lag turns the slave's acceleration into
  a velocity residual ``tau * a``; in steady state the filter reads it as a tilt
  ``tau * |d a_h / dt| / g`` (:func:`lag_tilt`);
* **lever arm known to ±x**: the master predicts the slave's velocity with a lever arm off by
  ``dl`` (each component uniform in ±x, aircraft body axes); the residual is
  ``C_b^n (omega x dl)`` (:func:`lever_arm_velocity`);
* **wing flexure** as a second-order Gauss-Markov angle per axis (Kain & Cloutier 1989), with
  autocorrelation ``sigma^2 (1 + beta |tau|) exp(-beta |tau|)`` (:func:`flexure_paths`), and
  **vibration** as a sinusoidal angle of random phase; both turn the slave relative to where the
  master predicts it, and their rates move it by ``theta' x l`` at the lever arm ``l``;
* **the master INS's own errors**: a constant attitude error ``phi_m`` in Schuler balance at the
  start (the master's accelerometer bias cancels its tilt, so its velocity error grows only as
  the specific force turns, ``dv_m' = f^n x phi_m + C_b^n b_m``, :func:`master_velocity_error`),
  plus a constant velocity error;
* **IMU noise and scale factors by grade**: the slave's true bias, angle / velocity random walks
  and scale factors, given apart from the filter's tuning (a mismatched filter).

References
----------
seed 000, section 2 and Table 2. J. E. Kain and J. R. Cloutier, "Rapid transfer alignment for
tactical weapon applications", AIAA GNC conference, 1989 (flexure as a Markov process).
Qin Yongyuan, *Inertial navigation* (2006), the psi-angle error equations.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.units import G0

if TYPE_CHECKING:
    from montecarlo.seed000.ta_manoeuvres import Truth
    from montecarlo.seed000.transfer_alignment import AlignmentConfig

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TruthEffects:
    """Error sources of the truth beyond the filter's model (SI units, radians).

    Every default is the matched case (nothing beyond the filter's model). ``None`` for a sensor
    figure means "as the filter is tuned" (``AlignmentConfig``).

    Attributes
    ----------
    time_offset : float [s]
        Master data late by this (valid at ``t - time_offset``).
    time_jitter : float [s]
        1σ white jitter of the time tag, independent per update.
    lever_arm : tuple of 3 float [m]
        Slave relative to master, aircraft body axes (right, forward, up). Compensated by the
        master except for ``lever_arm_error``; flexure and vibration rates act through it.
    lever_arm_error : float [m]
        Bound of the lever arm's knowledge error per axis (uniform in ±bound).
    flexure_sigma : float [rad]
        1σ per axis of the second-order Gauss-Markov flexure angle.
    flexure_beta : float [1/s]
        Its bandwidth ``beta`` (correlation time about 2.1/beta).
    vibration_amplitude : float [rad]
        Amplitude per axis of a sinusoidal angular vibration (random phase per axis and run).
    vibration_frequency : float [Hz]
    master_heading, master_level : float [rad]
        1σ of the master's constant attitude error: heading (up axis) and each level axis.
    master_velocity : float [m/s]
        1σ per axis of the master's constant velocity error.
    gyro_drift, accel_bias, gyro_arw, accel_vrw : float or None
        The slave's true sensor figures (units as ``AlignmentConfig``); None: as tuned.
    gyro_scale, accel_scale : float [-]
        1σ per axis of the slave's constant scale-factor errors (not in the filter's model).
    velocity_noise, attitude_noise : float or None
        True white noise of the master's velocity [m/s] and attitude [rad] as the slave sees
        them; None: as tuned.
    """

    time_offset: float = 0.0
    time_jitter: float = 0.0
    lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lever_arm_error: float = 0.0
    flexure_sigma: float = 0.0
    flexure_beta: float = 2.0
    vibration_amplitude: float = 0.0
    vibration_frequency: float = 8.0
    master_heading: float = 0.0
    master_level: float = 0.0
    master_velocity: float = 0.0
    gyro_drift: float | None = None
    accel_bias: float | None = None
    gyro_arw: float | None = None
    accel_vrw: float | None = None
    gyro_scale: float = 0.0
    accel_scale: float = 0.0
    velocity_noise: float | None = None
    attitude_noise: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            if f.name == "lever_arm":
                ok = all(np.isfinite(v) for v in values)
            else:
                ok = all(v is None or (np.isfinite(v) and v >= 0) for v in values)
            if not ok:
                raise ValueError(f"{f.name}: {value!r} must be finite"
                                 + ("" if f.name == "lever_arm" else " and >= 0"))
        if self.flexure_beta <= 0 or self.vibration_frequency <= 0:
            raise ValueError(f"flexure_beta ({self.flexure_beta!r} 1/s) and vibration_frequency "
                             f"({self.vibration_frequency!r} Hz) must be > 0")

    def sensor(self, cfg: AlignmentConfig) -> dict[str, float]:
        """True gyro_drift, accel_bias, gyro_arw, accel_vrw, velocity_noise, attitude_noise
        (None -> as ``cfg`` is tuned)."""
        names = ("gyro_drift", "accel_bias", "gyro_arw", "accel_vrw", "velocity_noise",
                 "attitude_noise")
        return {n: float(getattr(cfg, n) if getattr(self, n) is None else getattr(self, n))
                for n in names}


@dataclass(frozen=True)
class EffectDraws:
    """One draw per run of every effect (arrays with the runs axis first).

    Attributes
    ----------
    time_tag : (runs, m) [s]
        Total time-tag error at each of the m updates.
    lever_arm_error : (runs, 3) [m]
        Knowledge error of the lever arm, slave body axes (frame a).
    lever_arm : (3,) [m]
        True lever arm, slave body axes.
    flexure, flexure_rate : (runs, m, 3) [rad], [rad/s]
        Flexure plus vibration angle of the slave relative to the master's prediction and its
        rate, slave body axes, at the updates.
    master_phi : (runs, 3) [rad]
        Master's attitude error (east, north, up).
    master_dv : (runs, m, 3) [m/s]
        Master's velocity error at the updates.
    gyro_scale, accel_scale : (runs, 3) [-]
    """

    time_tag: FloatArray
    lever_arm_error: FloatArray
    lever_arm: FloatArray
    flexure: FloatArray
    flexure_rate: FloatArray
    master_phi: FloatArray
    master_dv: FloatArray
    gyro_scale: FloatArray
    accel_scale: FloatArray

    @classmethod
    def zeros(cls, runs: int, m: int) -> EffectDraws:
        """No effect at all (the matched case)."""
        z3, zm3 = np.zeros((runs, 3)), np.zeros((runs, m, 3))
        return cls(np.zeros((runs, m)), z3, np.zeros(3), zm3, zm3.copy(), z3.copy(),
                   zm3.copy(), z3.copy(), z3.copy())

    def scaled(self, **factors: float) -> EffectDraws:
        """This draw with named fields multiplied by factors (effects are linear in them)."""
        return replace(self, **{k: getattr(self, k) * v for k, v in factors.items()})


def lag_tilt(lag: ArrayLike, fdot_horizontal: ArrayLike) -> FloatArray:
    """Steady-state tilt a velocity-matching filter reads from a master lag [rad].

    A lag ``tau`` leaves the velocity residual ``tau * a``; once the filter has settled, it
    explains a steadily changing residual as a tilt ``phi`` with ``g phi = tau * da_h/dt``.

    Parameters
    ----------
    lag : array_like [s]
    fdot_horizontal : array_like [m/s³]
        Rate of change of the horizontal specific force.
    """
    return np.asarray(lag, float) * np.asarray(fdot_horizontal, float) / G0


def lever_arm_velocity(C_bn: ArrayLike, omega_b: ArrayLike, dl_b: ArrayLike) -> FloatArray:
    """Velocity error ``C_b^n (omega x dl)`` of a lever arm off by ``dl`` [m/s], shape (..., 3).

    Parameters
    ----------
    C_bn : (..., 3, 3)
        Body-to-navigation attitude.
    omega_b : (..., 3) [rad/s]
        Body angular rate, body axes.
    dl_b : (..., 3) [m]
        Lever arm error, body axes.
    """
    w, dl = np.asarray(omega_b, float), np.asarray(dl_b, float)
    return np.einsum("...ij,...j->...i", np.asarray(C_bn, float), np.cross(w, dl))


def gauss_markov2_transition(beta: float, sigma: float, dt: float
                             ) -> tuple[FloatArray, FloatArray]:
    """Exact discrete transition and noise covariance of ``x'' + 2 beta x' + beta^2 x = w``.

    The white-noise density ``q = 4 beta^3 sigma^2`` gives the stationary variance sigma^2;
    ``Qd`` is computed with Van Loan's method.

    Returns
    -------
    Phi, Qd : (2, 2) each, for the state ``[x, x']``.
    """
    A = np.array([[0.0, 1.0], [-beta**2, -2.0 * beta]])
    G = np.array([[0.0], [1.0]])
    q = 4.0 * beta**3 * sigma**2
    M = np.zeros((4, 4))
    M[:2, :2], M[:2, 2:], M[2:, 2:] = -A, G @ G.T * q, A.T
    E = expm(M * dt)
    Phi = E[2:, 2:].T
    return Phi, Phi @ E[:2, 2:]


def flexure_paths(rng: np.random.Generator, runs: int, m: int, dt: float, beta: float,
                  sigma: float) -> tuple[FloatArray, FloatArray]:
    """Stationary second-order Gauss-Markov angle and rate per axis, sampled every ``dt``.

    Returns
    -------
    angle, rate : (runs, m, 3) [rad], [rad/s]
        Started from the stationary distribution (var x = sigma², var x' = beta² sigma²).
    """
    out = np.zeros((runs, m, 3, 2))
    if sigma == 0.0 or m == 0:
        return out[..., 0], out[..., 1]
    Phi, Qd = gauss_markov2_transition(beta, sigma, dt)
    Lq = np.linalg.cholesky(Qd)
    x = rng.standard_normal((runs, 3, 2)) * np.array([sigma, beta * sigma])
    for k in range(m):
        x = x @ Phi.T + rng.standard_normal((runs, 3, 2)) @ Lq.T
        out[:, k] = x
    return out[..., 0], out[..., 1]


def master_velocity_error(truth: Truth, dt: float, phi_m: FloatArray) -> FloatArray:
    """Velocity error of a master whose attitude error ``phi_m`` is in Schuler balance [m/s].

    ``dv_m' = f^n x phi_m + C_b^n b_m`` with the body-fixed bias ``b_m`` that makes the rate zero
    at the start; on a straight, level flight the error stays zero, in a turn it grows.

    Parameters
    ----------
    truth : Truth
    dt : float [s]
    phi_m : (runs, 3) [rad]

    Returns
    -------
    ndarray, shape (runs, n_steps + 1, 3)
    """
    b_m = -np.einsum("ji,rj->ri", truth.C_mid[0], np.cross(truth.f_n[0], phi_m))
    rate = (np.cross(truth.f_n[None], phi_m[:, None])
            + np.einsum("kij,rj->rki", truth.C_mid, b_m))
    dv = np.zeros((phi_m.shape[0], truth.t.size, 3))
    dv[:, 1:] = np.cumsum(rate, axis=1) * dt
    return dv


def draw_effects(effects: TruthEffects, cfg: AlignmentConfig, truth: Truth,
                 rng: np.random.Generator, runs: int) -> EffectDraws:
    """Draw every effect for ``runs`` runs (nothing is drawn for an effect that is zero)."""
    steps = np.arange(cfg.kf_interval, cfg.n_steps + 1, cfg.kf_interval)
    m, t_kf = steps.size, cfg.dt * cfg.kf_interval
    draws = EffectDraws.zeros(runs, m)
    C_a_bf = mounting_matrix(*cfg.mount)  # C_{b_f}^a, seed 000, eq. (5)
    kw: dict[str, FloatArray] = {"lever_arm": C_a_bf @ np.asarray(effects.lever_arm, float)}
    tag = np.full((runs, m), effects.time_offset)
    if effects.time_jitter:
        tag = tag + effects.time_jitter * rng.standard_normal((runs, m))
    kw["time_tag"] = tag
    if effects.lever_arm_error:
        dl = rng.uniform(-effects.lever_arm_error, effects.lever_arm_error, (runs, 3))
        kw["lever_arm_error"] = dl @ C_a_bf.T
    flex, rate = flexure_paths(rng, runs, m, t_kf, effects.flexure_beta, effects.flexure_sigma)
    if effects.vibration_amplitude:
        w = 2.0 * np.pi * effects.vibration_frequency
        phase = rng.uniform(0.0, 2.0 * np.pi, (runs, 1, 3)) + w * truth.t[steps][None, :, None]
        flex = flex + effects.vibration_amplitude * np.sin(phase)
        rate = rate + effects.vibration_amplitude * w * np.cos(phase)
    kw["flexure"], kw["flexure_rate"] = flex, rate
    if effects.master_heading or effects.master_level or effects.master_velocity:
        phi_m = rng.standard_normal((runs, 3)) * np.array(
            [effects.master_level, effects.master_level, effects.master_heading])
        dv0 = effects.master_velocity * rng.standard_normal((runs, 1, 3))
        kw["master_phi"] = phi_m
        kw["master_dv"] = master_velocity_error(truth, cfg.dt, phi_m)[:, steps] + dv0
    if effects.gyro_scale or effects.accel_scale:
        kw["gyro_scale"] = effects.gyro_scale * rng.standard_normal((runs, 3))
        kw["accel_scale"] = effects.accel_scale * rng.standard_normal((runs, 3))
    return replace(draws, **kw)


def inflated_tuning(cfg: AlignmentConfig, effects: TruthEffects, truth: Truth
                    ) -> tuple[AlignmentConfig, TruthEffects]:
    """``cfg`` with its measurement noises widened to cover the effects as white noise.

    The filter "models" an effect here the cheap way real filters often do: no extra states,
    its rms contribution added to the velocity (and attitude) measurement noise. Velocity:
    lag and jitter times the rms acceleration, lever-arm error (uniform, rms bound/√3 per axis)
    times the rms body rate, flexure and vibration rates times the lever arm, the master's
    velocity error. Attitude: flexure, vibration (amplitude/√2) and the master's attitude.
    These are rough sizes, not a derived optimum. The returned effects keep the true master
    noises at the tuned values of ``cfg``.
    """
    accel = np.sqrt(np.mean(np.sum((np.diff(truth.v_n, axis=0) / cfg.dt) ** 2, axis=1)))
    rate = np.sqrt(np.mean(np.sum(truth.dtheta**2, axis=1))) / cfg.dt
    arm = float(np.linalg.norm(effects.lever_arm))
    angle_rate = np.hypot(effects.flexure_beta * effects.flexure_sigma,
                          2 * np.pi * effects.vibration_frequency
                          * effects.vibration_amplitude / np.sqrt(2))
    v_var = (cfg.velocity_noise**2 + ((effects.time_offset**2 + effects.time_jitter**2)
                                      * accel**2) / 3.0
             + (effects.lever_arm_error / np.sqrt(3) * rate) ** 2
             + (angle_rate * arm) ** 2 + effects.master_velocity**2)
    a_var = (cfg.attitude_noise**2 + effects.flexure_sigma**2
             + effects.vibration_amplitude**2 / 2
             + max(effects.master_level, effects.master_heading) ** 2)
    true = effects.sensor(cfg)
    return (replace(cfg, velocity_noise=float(np.sqrt(v_var)),
                    attitude_noise=float(np.sqrt(a_var))),
            replace(effects, velocity_noise=true["velocity_noise"],
                    attitude_noise=true["attitude_noise"]))
