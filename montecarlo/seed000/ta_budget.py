"""Actual error of a transfer alignment whose filter leaves out a time-tag offset and a lever-arm
error: the moments the air calibration (seed 000, eq. (19)) draws its slave attitude error from.

The filter's covariance P is its error only when it is matched. A master time-tag offset
``tau`` (deterministic for a given flight) and a lever arm known to ±x (each axis uniform) add,
to first order, a mean ``tau * r_lag`` and a covariance ``x² L`` computed once per flight from
the closed loop's unit responses (:func:`transfer_alignment.response`)::

    E[phi] = tau r_lag,     Cov[phi] = P + x² L,   L = sum_i r_i r_i^T / 3

with ``r_lag`` the response to a 1 s offset scaled from 10 ms, ``r_i`` the response to a 1 m
error along aircraft axis i.

References
----------
seed 000, section 2, eq. (19) and Table 2.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed000 import ta_effects as te
from montecarlo.seed000 import transfer_alignment as ta

FloatArray = NDArray[np.float64]

_UNIT_LAG = 0.01
"""Offset of the unit response [s]: small enough to stay linear, large against round-off."""


@functools.lru_cache(maxsize=32)
def unit_responses(cfg: ta.AlignmentConfig) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(P, r_lag, L) of the slave's (E, N, U) error for the flight and filter ``cfg``.

    Returns
    -------
    P : (3, 3) [rad²]
        The filter's final attitude covariance (its matched error).
    r_lag : (3,) [rad/s]
        Final error per second of master time-tag offset.
    L : (3, 3) [rad²/m²]
        Covariance per m² of lever-arm bound (uniform per aircraft axis).
    """
    m = cfg.n_steps // cfg.kf_interval
    dl = np.eye(3) @ mounting_matrix(*cfg.mount).T  # aircraft axes i, in slave axes
    draws = replace(te.EffectDraws.zeros(4, m),
                    time_tag=np.vstack([np.full((1, m), _UNIT_LAG), np.zeros((3, m))]),
                    lever_arm_error=np.vstack([np.zeros((1, 3)), dl]))
    res = ta.response(cfg, draws)
    err = res.final_error("true")
    r = err[1:]
    return res.cov.P[-1, :3, :3].copy(), err[0] / _UNIT_LAG, r.T @ r / 3.0


def error_moments(cfg: ta.AlignmentConfig, time_offset: float, lever_arm_error: float
                  ) -> tuple[FloatArray, FloatArray]:
    """Mean (3,) [rad] and covariance (3, 3) [rad²] of the slave's actual (E, N, U) error.

    Parameters
    ----------
    cfg : AlignmentConfig
        Flight and filter (which models neither effect).
    time_offset : float [s]
        Master data late by this.
    lever_arm_error : float [m]
        Bound of the lever arm's knowledge error per aircraft axis.
    """
    P, r_lag, L = unit_responses(cfg)
    return time_offset * r_lag, P + lever_arm_error**2 * L
