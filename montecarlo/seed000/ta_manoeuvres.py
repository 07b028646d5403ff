"""Flight profiles of the transfer alignment (seed 000, Table 2) and the slave's sampled truth.

The aircraft flies one of :data:`MANOEUVRES` in a flat, non-rotating east-north-up frame g; the
slave IMU is fixed to it with the mounting angles of seed 000, section 1.4. :func:`make_truth`
samples the slave's attitude and velocity and its error-free IMU outputs, which
:mod:`montecarlo.seed000.transfer_alignment` corrupts and aligns.

References
----------
seed 000, section 1.4 (mounting angles, eq. (5)) and section 2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.units import G0

if TYPE_CHECKING:
    from montecarlo.seed000.transfer_alignment import AlignmentConfig

FloatArray = NDArray[np.float64]

GRAVITY_N = np.array([0.0, 0.0, -G0])
"""Gravity in the east-north-up navigation frame [m/s²]."""

MANOEUVRES = ("level", "s_turn", "wing_rock", "surge")
"""Flight profiles: straight and level; S-turn (coordinated turns, turn rate sinusoidal in time,
bank up to ``bank``); wing rock (roll oscillation of amplitude ``bank``, constant heading); surge
(straight and level, speed ``speed + surge sin(2 pi t / T)``)."""

def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix ``[v x]``, shape (..., 3, 3)."""
    x, y, z = np.moveaxis(np.asarray(v, float), -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1),
                     np.stack([-y, x, o], -1)], -2)


def exp_so3(rotvec: FloatArray) -> FloatArray:
    """Rotation matrix ``exp([v x])`` of rotation vectors, shape (..., 3, 3)."""
    v = np.asarray(rotvec, float)
    return Rotation.from_rotvec(v.reshape(-1, 3)).as_matrix().reshape(*v.shape[:-1], 3, 3)


def log_so3(C: FloatArray) -> FloatArray:
    """Rotation vector ``v`` with ``exp([v x]) = C``, shape (..., 3)."""
    C = np.asarray(C, float)
    return Rotation.from_matrix(C.reshape(-1, 3, 3)).as_rotvec().reshape(*C.shape[:-2], 3)


def aircraft_motion(cfg: AlignmentConfig, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Aircraft attitude and velocity along the manoeuvre.

    Heading psi is measured about up, positive to the left, so the nose points along
    ``[-sin psi, cos psi, 0]`` (east, north, up), the seed 000 Z-X-Y convention with b_f
    right-forward-up. In the S-turn the turn rate is ``w(t) = w0 sin(2 pi t / T)`` with
    ``w0 = g tan(bank) / V``, and the bank is coordinated, ``gamma = -atan(V w / g)``, so the
    specific force stays along the body z axis. In the surge the attitude stays level and the
    speed is ``V + surge sin(2 pi t / T)``.

    Parameters
    ----------
    cfg : AlignmentConfig
    t : ndarray, shape (n,) [s]

    Returns
    -------
    C_bn : ndarray, shape (n, 3, 3)
        ``C_{b_f}^g``, aircraft body to navigation frame.
    v_n : ndarray, shape (n, 3) [m/s]
    """
    t = np.asarray(t, float)
    zero = np.zeros_like(t)
    phase = 2.0 * np.pi * t / cfg.period
    if cfg.manoeuvre == "s_turn":
        w0 = G0 * np.tan(cfg.bank) / cfg.speed
        rate = w0 * np.sin(phase)
        psi = w0 * cfg.period / (2.0 * np.pi) * (1.0 - np.cos(phase))
        gamma = -np.arctan(cfg.speed * rate / G0)
    elif cfg.manoeuvre == "wing_rock":
        psi, gamma = zero, cfg.bank * np.sin(phase)
    else:
        psi, gamma = zero, zero
    speed = cfg.speed + (cfg.surge * np.sin(phase) if cfg.manoeuvre == "surge" else zero)
    C_bn = np.swapaxes(mounting_matrix(psi, zero, gamma), -1, -2)
    v_n = speed[..., None] * np.stack([-np.sin(psi), np.cos(psi), zero], axis=-1)
    return C_bn, v_n


@dataclass(frozen=True)
class Truth:
    """Sampled truth of the slave IMU along the manoeuvre (k = 0 .. n_steps).

    Attributes
    ----------
    t : (n+1,) [s]
    C_bn : (n+1, 3, 3)
        Slave body (product frame a) to navigation frame.
    v_n : (n+1, 3) [m/s]
    dtheta : (n, 3) [rad]
        Error-free gyro angle increments in body axes, ``exp([dtheta x]) = C_k^T C_{k+1}``.
    f_b : (n, 3) [m/s²]
        Error-free specific force in body axes over each step, defined so that the midpoint
        mechanisation of :func:`simulate` reproduces ``v_n`` exactly.
    C_mid, f_n : (n, 3, 3), (n, 3)
        Mid-step attitude and navigation-frame specific force (for the filter's F matrix).
    """

    t: FloatArray
    C_bn: FloatArray
    v_n: FloatArray
    dtheta: FloatArray
    f_b: FloatArray
    C_mid: FloatArray
    f_n: FloatArray


def make_truth(cfg: AlignmentConfig) -> Truth:
    """Truth trajectory and error-free IMU outputs of the slave for ``cfg``."""
    t = np.arange(cfg.n_steps + 1, dtype=np.float64) * cfg.dt
    C_af, v_n = aircraft_motion(cfg, t)
    C_a_bf = np.swapaxes(mounting_matrix(*cfg.mount), -1, -2)  # C_a^{b_f}, seed 000, eq. (5)
    C_bn = C_af @ C_a_bf
    dtheta = log_so3(np.swapaxes(C_bn[:-1], -1, -2) @ C_bn[1:])
    C_mid = C_bn[:-1] @ exp_so3(dtheta / 2.0)
    f_n = np.diff(v_n, axis=0) / cfg.dt - GRAVITY_N
    f_b = np.einsum("kji,kj->ki", C_mid, f_n)
    return Truth(t, C_bn, v_n, dtheta, f_b, C_mid, f_n)
