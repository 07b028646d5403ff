"""Transfer alignment of a slave IMU to a master INS (the simulation behind seed 000, Table 2).

Seed 000 obtains the product's attitude in the air from an IMU fixed to it, aligned in flight to
the aircraft's master INS ("transfer alignment", its ref. [5]); Table 2 gives the slave's heading
and level accuracy (1σ) from a semi-physical simulation for five IMU grades. The paper does not say
how that simulation worked. This module is our own, compact but real, version of it:

* **Truth.** A flat, non-rotating navigation frame g (east, north, up) with constant gravity; the
  aircraft flies one of :data:`MANOEUVRES`; the slave IMU is fixed to the aircraft with the
  mounting angles of seed 000, section 1.4 (its body frame is the product frame a). The slave
  runs its own strapdown mechanisation (attitude by rotation vectors, velocity by the midpoint
  rule) on gyro and accelerometer outputs corrupted by a random-constant gyro drift and
  accelerometer bias, angle and velocity random walks.
* **Filter.** A closed-loop error-state Kalman filter with the 12 states
  ``x = [phi (3), dv (3), gyro bias (3), accel bias (3)]`` (15 with attitude matching, which adds
  the master-to-slave mounting error ``mu``), measurement the slave-minus-master velocity (and,
  as an option, the attitude difference). Error model, with ``phi`` the misalignment of the
  slave's computed navigation frame (``C_n^{n'} = I - [phi x]``) [Qin 2006, ch. 9]::

      phi' = -C_b^n b_g - C_b^n w_g
      dv'  = f^n x phi + C_b^n b_a + C_b^n w_a
      b_g' = 0,  b_a' = 0,  mu' = 0
      z_v  = dv + n_v,      z_att = phi - C_b^n mu + n_att

  Earth rate, transport rate, Coriolis and Schuler terms are left out of both the truth and the
  filter. For alignments of one or two minutes at aircraft speeds they are small against the
  terms kept (earth rate times a milliradian misalignment is 7e-8 rad/s, below the smallest
  drift of Table 2; the Schuler period is 84 min) and, being in the same frame for truth and
  filter, leaving them out does not make the filter inconsistent. Lever arm and wing flexure are
  taken as compensated (flexure enters only as the attitude-matching noise).
* **Outputs.** The slave's heading error (``phi_U``) and level errors (``phi_E``, ``phi_N``) at
  the end of the alignment, 1σ from the filter covariance and from a Monte Carlo of the filter's
  actual error against the truth.

References
----------
seed 000, section 2 and Table 2; its ref. [5]. Qin Yongyuan, *Inertial navigation* (2006):
the psi-angle error equations (the same book is seed 000's ref. [3]).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from montecarlo.seed000.ta_effects import (
    EffectDraws,
    TruthEffects,
    draw_effects,
    lever_arm_velocity,
)
from montecarlo.seed000.ta_manoeuvres import (
    GRAVITY_N,
    MANOEUVRES,
    Truth,
    aircraft_motion,
    make_truth,
)
from montecarlo.seed000.ta_manoeuvres import exp_so3 as _exp
from montecarlo.seed000.ta_manoeuvres import log_so3 as _log
from montecarlo.seed000.ta_manoeuvres import skew as _skew
from montecarlo.units import DEG_PER_HOUR, G0

FloatArray = NDArray[np.float64]

__all__ = ["MANOEUVRES", "AlignmentConfig", "CovarianceHistory", "MonteCarloResult", "Truth",
           "aircraft_motion", "covariance_analysis", "make_truth", "simulate"]

PAPER_MOUNT = tuple(np.radians([30.0, 20.0, 10.0]))
"""Seed 000, section 1.4: mounting angles (psi, theta, gamma) of the product [rad]."""


@dataclass(frozen=True)
class AlignmentConfig:
    """Everything that defines one transfer-alignment simulation (SI units, radians).

    Attributes
    ----------
    gyro_drift : float [rad/s]
        1σ per axis of the slave's gyro drift (random constant).
    accel_bias : float [m/s²]
        1σ per axis of the slave's accelerometer bias (random constant).
    gyro_arw : float [rad/√s]
        Angle random walk (default 0.005 °/√h).
    accel_vrw : float [m/s/√s]
        Velocity random walk (default 20 µg/√Hz).
    manoeuvre : str
        One of :data:`MANOEUVRES`.
    speed : float [m/s]
        True airspeed (= ground speed, no wind).
    bank : float [rad]
        Peak bank angle of the S-turn, roll amplitude of the wing rock.
    period : float [s]
        Period of the S-turn (one left and one right turn), of the wing rock or of the surge.
    surge : float [m/s]
        Speed amplitude of the surge manoeuvre (``|surge| < speed``; unused otherwise).
    duration : float [s]
        Length of the alignment; results are the errors at its end.
    dt : float [s]
        IMU sampling interval (mechanisation step).
    kf_interval : int
        Mechanisation steps per Kalman update.
    velocity_noise : float [m/s]
        1σ white noise of the master's velocity as seen by the filter.
    attitude_matching : bool
        Add the attitude-difference measurement and the 3 mounting-error states ``mu``.
    attitude_noise : float [rad]
        1σ per axis of the attitude-matching noise (master attitude noise, flexure).
    initial_level, initial_heading : float [rad]
        1σ of the slave's initial misalignment (coarse alignment from the nominal mounting).
    initial_velocity : float [m/s]
        1σ per axis of the slave's initial velocity error.
    mount : tuple of 3 float [rad]
        Z-X-Y angles (psi, theta, gamma) of the slave body (product frame a) relative to the
        aircraft body b_f, as in seed 000, eq. (5).
    mount_sigma : float [rad]
        1σ per axis of the mounting error ``mu`` (used only with attitude matching).
    """

    gyro_drift: float = 0.05 * DEG_PER_HOUR
    accel_bias: float = 5e-5 * G0
    gyro_arw: float = 0.005 * np.pi / 180.0 / 60.0
    accel_vrw: float = 20e-6 * G0
    manoeuvre: str = "s_turn"
    speed: float = 200.0
    bank: float = float(np.radians(30.0))
    period: float = 60.0
    surge: float = 20.0
    duration: float = 120.0
    dt: float = 0.02
    kf_interval: int = 10
    velocity_noise: float = 0.05
    attitude_matching: bool = False
    attitude_noise: float = 0.5e-3
    initial_level: float = float(np.radians(0.5))
    initial_heading: float = float(np.radians(1.0))
    initial_velocity: float = 0.1
    mount: tuple[float, float, float] = PAPER_MOUNT
    mount_sigma: float = float(np.radians(1.0))

    def __post_init__(self) -> None:
        if self.manoeuvre not in MANOEUVRES:
            raise ValueError(f"manoeuvre {self.manoeuvre!r} not in {MANOEUVRES}")
        if not (self.period > 0 and self.speed > 0 and abs(self.bank) < np.pi / 2):
            raise ValueError(f"need period > 0 (got {self.period!r} s), speed > 0 (got "
                             f"{self.speed!r} m/s) and |bank| < 90° (got {self.bank!r} rad)")
        if self.manoeuvre == "surge" and not abs(self.surge) < self.speed:
            raise ValueError(f"need |surge| < speed (got {self.surge!r} m/s, speed "
                             f"{self.speed!r} m/s)")
        if self.kf_interval < 1 or self.dt <= 0 or self.duration < self.dt * self.kf_interval:
            raise ValueError(f"duration {self.duration!r} s: need dt > 0, kf_interval >= 1 "
                             "and at least one Kalman update")

    @property
    def n_states(self) -> int:
        return 15 if self.attitude_matching else 12

    @property
    def n_steps(self) -> int:
        """Mechanisation steps, a whole number of Kalman intervals."""
        n_updates = round(self.duration / (self.dt * self.kf_interval))
        return n_updates * self.kf_interval


def _system_matrices(cfg: AlignmentConfig, C: FloatArray, f_n: FloatArray) -> FloatArray:
    """Continuous error-state matrix F (n_states x n_states) at one instant."""
    F = np.zeros((cfg.n_states, cfg.n_states))
    F[0:3, 6:9] = -C  # phi' = -C_b^n b_g
    F[3:6, 0:3] = _skew(f_n)  # dv' = f^n x phi
    F[3:6, 9:12] = C  # dv' += C_b^n b_a
    return F


def _process_noise(cfg: AlignmentConfig) -> FloatArray:
    """Continuous process-noise density (diagonal, since C C^T = I) per unit time."""
    q = np.zeros(cfg.n_states)
    q[0:3] = cfg.gyro_arw**2
    q[3:6] = cfg.accel_vrw**2
    return np.diag(q)


def measurement_matrix(cfg: AlignmentConfig, C: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Measurement matrix H and noise covariance R at an update with slave attitude ``C``."""
    n = cfg.n_states
    H_v = np.zeros((3, n))
    H_v[:, 3:6] = np.eye(3)
    R_v = cfg.velocity_noise**2 * np.eye(3)
    if not cfg.attitude_matching:
        return H_v, R_v
    H_a = np.zeros((3, n))
    H_a[:, 0:3] = np.eye(3)
    H_a[:, 12:15] = -C  # z_att = phi - C_b^n mu
    R = np.zeros((6, 6))
    R[:3, :3] = R_v
    R[3:, 3:] = cfg.attitude_noise**2 * np.eye(3)
    return np.vstack([H_v, H_a]), R


def initial_covariance(cfg: AlignmentConfig) -> FloatArray:
    """Diagonal P0 from the configured initial uncertainties and IMU grade."""
    d = [cfg.initial_level**2] * 2 + [cfg.initial_heading**2]
    d += [cfg.initial_velocity**2] * 3 + [cfg.gyro_drift**2] * 3 + [cfg.accel_bias**2] * 3
    if cfg.attitude_matching:
        d += [cfg.mount_sigma**2] * 3
    return np.diag(d)


@dataclass(frozen=True)
class CovarianceHistory:
    """Filter covariance after each Kalman update, and the gains used.

    Attributes
    ----------
    t : (m,) [s]
        Update times.
    P : (m, n_states, n_states)
        Posterior covariance after each update.
    K : (m, n_states, n_meas)
        Kalman gain of each update (the same for every Monte Carlo run: the filter is linearised
        about the master's trajectory, so P does not depend on the measurements).
    """

    t: FloatArray
    P: FloatArray
    K: FloatArray

    def attitude_sigma(self) -> FloatArray:
        """1σ of (phi_E, phi_N, phi_U) after each update, shape (m, 3) [rad]."""
        return np.sqrt(np.diagonal(self.P[:, :3, :3], axis1=-2, axis2=-1))


def covariance_analysis(cfg: AlignmentConfig, truth: Truth | None = None) -> CovarianceHistory:
    """Run the filter's covariance (no measurements needed).

    ``P`` is propagated every IMU step with ``Phi = I + F dt + (F dt)^2 / 2`` and
    ``Q = G Q_c G^T dt``, and updated (Joseph form) every ``kf_interval`` steps.
    """
    truth = make_truth(cfg) if truth is None else truth
    n = cfg.n_states
    P = initial_covariance(cfg)
    Qd = _process_noise(cfg) * cfg.dt
    eye = np.eye(n)
    times, Ps, Ks = [], [], []
    for k in range(cfg.n_steps):
        Fdt = _system_matrices(cfg, truth.C_mid[k], truth.f_n[k]) * cfg.dt
        Phi = eye + Fdt + 0.5 * Fdt @ Fdt
        P = Phi @ P @ Phi.T + Qd
        if (k + 1) % cfg.kf_interval == 0:
            H, R = measurement_matrix(cfg, truth.C_bn[k + 1])
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            IKH = eye - K @ H
            P = IKH @ P @ IKH.T + K @ R @ K.T
            times.append(truth.t[k + 1])
            Ps.append(P)
            Ks.append(K)
    return CovarianceHistory(np.array(times), np.array(Ps), np.array(Ks))


@functools.lru_cache(maxsize=64)
def final_attitude_covariance(cfg: AlignmentConfig) -> FloatArray:
    """Covariance of (phi_E, phi_N, phi_U) at the end of the alignment, (3, 3) [rad²]."""
    return covariance_analysis(cfg).P[-1, :3, :3].copy()


@dataclass(frozen=True)
class MonteCarloResult:
    """Filter covariance and actual errors of a batch of simulated alignments.

    Attributes
    ----------
    cov : CovarianceHistory
    phi : (m, runs, 3) [rad]
        Actual misalignment (phi_E, phi_N, phi_U) of each run after each update.
    x_true : (runs, n_states)
        True error state at the end (phi, dv, remaining gyro bias, remaining accel bias, mu).
    master_phi : (runs, 3) [rad]
        The master's own attitude error (zero unless drawn).
    """

    cov: CovarianceHistory
    phi: FloatArray
    x_true: FloatArray
    master_phi: FloatArray

    def final_error(self, reference: str = "master") -> FloatArray:
        """Each run's final (phi_E, phi_N, phi_U), shape (runs, 3) [rad].

        ``reference = "master"``: relative to the master INS (what seed 000, Table 2 gives:
        "IMU传递对准后对主惯导的相对精度"), ``phi - phi_master``; ``"true"``: against the true
        navigation frame.
        """
        if reference not in ("master", "true"):
            raise ValueError(f"reference {reference!r} not in ('master', 'true')")
        return self.phi[-1] - (self.master_phi if reference == "master" else 0.0)

    def nees(self) -> FloatArray:
        """Normalised estimation error squared of each run's final state, shape (runs,)."""
        P = self.cov.P[-1]
        return np.einsum("ri,ij,rj->r", self.x_true, np.linalg.inv(P), self.x_true)


def mechanisation_step(C_bn: FloatArray, v_n: FloatArray, dtheta: FloatArray, f_b: FloatArray,
                       dt: float) -> tuple[FloatArray, FloatArray]:
    """One step of the slave's strapdown mechanisation (flat, non-rotating navigation frame).

    ``C <- C exp([dtheta x])`` and ``v <- v + (C exp([dtheta/2 x]) f_b + g^n) dt``.

    Parameters
    ----------
    C_bn : (..., 3, 3)
        Body-to-navigation attitude at the start of the step.
    v_n : (..., 3) [m/s]
    dtheta : (..., 3) [rad]
        Gyro angle increment over the step, body axes.
    f_b : (..., 3) [m/s²]
        Accelerometer specific force over the step, body axes.
    dt : float [s]

    Returns
    -------
    C_bn, v_n after the step.
    """
    C_half = C_bn @ _exp(dtheta / 2.0)
    v_next = v_n + (np.einsum("...ij,...j->...i", C_half, f_b) + GRAVITY_N) * dt
    return C_bn @ _exp(dtheta), v_next


def _misalignment(C_hat: FloatArray, C_true: FloatArray) -> FloatArray:
    """phi with ``C_hat = exp(-[phi x]) C_true`` (to first order ``(I - [phi x]) C_true``)."""
    return -_log(C_hat @ np.swapaxes(C_true, -1, -2))


def simulate(cfg: AlignmentConfig, rng: np.random.Generator, runs: int,
             effects: TruthEffects | None = None) -> MonteCarloResult:
    """Monte Carlo of the closed-loop transfer alignment against the simulated truth.

    Each run draws its initial misalignment, velocity error (and mounting error) from the
    filter's P0, its gyro drift and accelerometer bias and its white noises from the true sensor
    figures (``effects``, by default as the filter is tuned), and every further effect of
    ``effects``; the slave mechanises its corrupted IMU outputs, the filter estimates the error
    state from the measurement residuals and the slave is corrected (and the error state reset)
    after each update.

    Parameters
    ----------
    cfg : AlignmentConfig
        The filter's model and tuning (and the flight).
    rng : numpy.random.Generator
        The only source of randomness.
    runs : int
    effects : TruthEffects, optional
        The truth beyond the filter's model (default: none, a matched filter).

    Returns
    -------
    MonteCarloResult
    """
    effects = TruthEffects() if effects is None else effects
    truth = make_truth(cfg)
    cov = covariance_analysis(cfg, truth)
    true = effects.sensor(cfg)
    sd = np.sqrt(np.diag(initial_covariance(cfg)))
    sd[6:9], sd[9:12] = true["gyro_drift"], true["accel_bias"]
    x0 = rng.standard_normal((runs, cfg.n_states)) * sd
    draws = draw_effects(effects, cfg, truth, rng, runs)
    return _closed_loop(cfg, truth, cov, x0, draws, rng, true)


def response(cfg: AlignmentConfig, draws: EffectDraws, truth: Truth | None = None
             ) -> MonteCarloResult:
    """The alignment's error caused by ``draws`` alone (no initial error, bias or noise).

    To first order the closed-loop error is linear in its sources, so the error of a
    configuration is the filter's own (matched) error plus the responses to its effects.
    """
    truth = make_truth(cfg) if truth is None else truth
    x0 = np.zeros((draws.time_tag.shape[0], cfg.n_states))
    return _closed_loop(cfg, truth, covariance_analysis(cfg, truth), x0, draws, None, {})


def _reference(truth: Truth, k: int, tag: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Slave's true velocity and attitude at ``t_k - tag`` (linear / geodesic interpolation)."""
    if not np.any(tag):
        return truth.v_n[k], truth.C_bn[k]
    pos = np.clip(k - tag / (truth.t[1] - truth.t[0]), 0.0, truth.t.size - 1.000001)
    i0 = pos.astype(int)
    frac = (pos - i0)[:, None]
    v = truth.v_n[i0] + frac * (truth.v_n[i0 + 1] - truth.v_n[i0])
    return v, truth.C_bn[i0] @ _exp(frac * truth.dtheta[i0])


def _closed_loop(cfg: AlignmentConfig, truth: Truth, cov: CovarianceHistory, x0: FloatArray,
                 draws: EffectDraws, rng: np.random.Generator | None, true: dict[str, float]
                 ) -> MonteCarloResult:
    """The closed loop of :func:`simulate`; ``rng = None``: no white noise (:func:`response`)."""
    runs = x0.shape[0]
    phi0, dv0, b_g, b_a = x0[:, 0:3], x0[:, 3:6], x0[:, 6:9], x0[:, 9:12]
    C_hat = _exp(-phi0) @ truth.C_bn[0]
    v_hat = truth.v_n[0] + dv0
    b_g_hat = np.zeros((runs, 3))
    b_a_hat = np.zeros((runs, 3))
    if cfg.attitude_matching:
        # the true slave body is the nominal one turned by mu: C_b^n = C_nom^n exp([mu x])
        mu = x0[:, 12:15]
        nominal_from_true = _exp(-mu)
        M_hat = np.broadcast_to(np.eye(3), (runs, 3, 3)).copy()
    sqdt = np.sqrt(cfg.dt)
    gyro_gain, accel_gain = 1.0 + draws.gyro_scale, 1.0 + draws.accel_scale
    phis, update = [], 0
    for k in range(cfg.n_steps):
        dth = truth.dtheta[k] * gyro_gain + (b_g - b_g_hat) * cfg.dt
        f_b = truth.f_b[k] * accel_gain + b_a - b_a_hat
        if rng is not None:
            dth = dth + true["gyro_arw"] * sqdt * rng.standard_normal((runs, 3))
            f_b = f_b + true["accel_vrw"] / sqdt * rng.standard_normal((runs, 3))
        C_hat, v_hat = mechanisation_step(C_hat, v_hat, dth, f_b, cfg.dt)
        if (k + 1) % cfg.kf_interval:
            continue
        C_now = truth.C_bn[k + 1]
        v_ref, C_ref = _reference(truth, k + 1, draws.time_tag[:, update])
        v_master = (v_ref + draws.master_dv[:, update]
                    + lever_arm_velocity(C_now, truth.dtheta[k] / cfg.dt, draws.lever_arm_error)
                    - lever_arm_velocity(C_now, draws.flexure_rate[:, update], draws.lever_arm))
        z = v_hat - v_master
        if rng is not None:
            z = z - true["velocity_noise"] * rng.standard_normal((runs, 3))
        if cfg.attitude_matching:
            # the master's view of the slave: its own attitude error, no flexure, nominal mount
            C_ref = (_exp(-draws.master_phi) @ C_ref @ _exp(-draws.flexure[:, update])
                     @ nominal_from_true @ M_hat)
            z_att = -_log(C_hat @ np.swapaxes(C_ref, -1, -2))
            if rng is not None:
                z_att = z_att + true["attitude_noise"] * rng.standard_normal((runs, 3))
            z = np.concatenate([z, z_att], axis=1)
        x_hat = z @ cov.K[update].T
        update += 1
        C_hat = _exp(x_hat[:, 0:3]) @ C_hat
        v_hat = v_hat - x_hat[:, 3:6]
        b_g_hat = b_g_hat + x_hat[:, 6:9]
        b_a_hat = b_a_hat + x_hat[:, 9:12]
        if cfg.attitude_matching:
            M_hat = M_hat @ _exp(x_hat[:, 12:15])
        phis.append(_misalignment(C_hat, C_now))
    parts = [phis[-1], v_hat - truth.v_n[-1], b_g - b_g_hat, b_a - b_a_hat]
    if cfg.attitude_matching:
        # remaining mounting error: true C_b^{b_nom} = exp([mu x]) against the estimate M_hat
        parts.append(_log(np.swapaxes(M_hat, -1, -2) @ _exp(mu)))
    return MonteCarloResult(cov, np.array(phis), np.concatenate(parts, axis=1),
                            draws.master_phi)


def observability_matrix(cfg: AlignmentConfig, segments: list[tuple[FloatArray, FloatArray]]
                         ) -> FloatArray:
    """Total observability matrix of a piecewise-constant system.

    Parameters
    ----------
    cfg : AlignmentConfig
        Selects the state and measurement set.
    segments : list of (C_bn (3, 3), f_n (3,))
        Attitude and specific force held constant on each segment; segment j contributes
        ``O_j Phi_{j-1} ... Phi_1`` with ``O_j = [H; H F_j; ...; H F_j^(n-1)]`` and
        ``Phi_j = expm(F_j)`` (a unit-length segment; the rank does not depend on it).

    Returns
    -------
    ndarray, shape (len(segments) * n * n_meas, n)
    """
    from scipy.linalg import expm

    n = cfg.n_states
    blocks, transition = [], np.eye(n)
    for C, f_n in segments:
        F = _system_matrices(cfg, np.asarray(C, float), np.asarray(f_n, float))
        H, _ = measurement_matrix(cfg, np.asarray(C, float))
        rows, HF = [], H
        for _ in range(n):
            rows.append(HF)
            HF = HF @ F
        blocks.append(np.vstack(rows) @ transition)
        transition = expm(F) @ transition
    return np.vstack(blocks)
