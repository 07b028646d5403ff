"""Tests of the detection family when the noise is estimated from the data (``auto``).

With the noise known, a candidate's likelihood-ratio statistic ``T = |P_Gbar r|^2`` of the
whitened residuals ``r`` is chi2(q). With the noise known only up to a factor, ``s^2`` is
estimated from the same residuals, and the statistics become ratios that do not depend on the
factor (Koch 1999, *Parameter estimation and hypothesis testing in linear models*, sec. 4.2;
Teunissen 2000, *Testing theory*, ch. 4):

- a candidate effect with ``q`` parameters, against a model with ``n - p`` degrees of freedom:
  ``F = (T / q) / ((chi2 - T) / (n - p - q)) ~ F(q, n - p - q)``, the noise estimated from the
  model extended by the candidate (its residuals are orthogonal to ``T``'s);
- an observation (Pope 1976, *The statistics of residuals and the detection of outliers*):
  Pope's ``tau = sqrt(T / s^2)``, ``s^2 = chi2 / (n - p)`` the model's own variance factor;
  ``tau^2 / (n - p) ~ Beta(q / 2, (n - p - q) / 2)``, and ``tau`` is a monotone function of
  the F statistic above, so the two tests reject together (same p-value);
- the global test: with the noise unknown a model cannot be tested against the data alone; it
  is tested against the model extended by every candidate effect at once (the union of their
  columns projected orthogonal to the model, rank ``q``), ``F(q, n - p - q)``;
- the minimal detectable bias of a test ``F(q, d)`` of size ``a`` and power ``b`` is at the
  noncentrality ``lambda0`` of the noncentral ``F(q, d, lambda0)`` that rejects with ``b``
  (which tends to Baarda's chi2 ``lambda0`` as ``d -> infinity``), in units of the
  estimated noise.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, special, stats

FloatArray = NDArray[np.float64]


def f_statistic(T: float, chi2: float, dof: int, q: int) -> float:
    """``F = (T / q) / ((chi2 - T) / (dof - q))`` of ``q`` columns with statistic ``T`` in a
    model whose residuals have ``chi2`` on ``dof`` degrees of freedom; inf if they leave
    nothing."""
    rest = chi2 - T
    return math.inf if rest <= 0.0 else (T / q) / (rest / (dof - q))


def log_f_sf(F: float, q: int, d: int) -> float:
    """``log P(F(q, d) > F)``, finite far into the tail (for ranking huge statistics).

    scipy's ``f.logsf`` underflows for very large F; there the tail is the regularised
    incomplete beta ``I_x(d/2, q/2)`` at ``x = d / (d + q F)``, whose leading term near 0 is
    ``x^a (1 - x)^b / (a B(a, b))`` (a = d/2, b = q/2).
    """
    if math.isinf(F):
        return -math.inf
    value = float(stats.f.logsf(F, q, d))
    if np.isfinite(value):
        return value
    a, b = d / 2.0, q / 2.0
    x = d / (d + q * F)
    return a * math.log(x) + b * math.log1p(-x) - math.log(a) - float(special.betaln(a, b))


def pope_tau(T: float, chi2: float, dof: int) -> float:
    """Pope's ``tau = sqrt(T / s^2)``, ``s^2 = chi2 / dof``: an observation's statistic in
    units of the model's own a-posteriori noise."""
    return math.sqrt(T * dof / chi2) if chi2 > 0 else math.inf


def tau_sf(tau: float, dof: int, q: int) -> float:
    """``P(tau' > tau)`` under the model: ``tau^2 / dof ~ Beta(q/2, (dof - q)/2)``."""
    return float(stats.beta.sf(min(tau * tau / dof, 1.0), q / 2.0, (dof - q) / 2.0))


@lru_cache(maxsize=4096)
def noncentrality_f(alpha: float, q: int, d: int, power: float) -> float:
    """Noncentrality at which an ``F(q, d)`` test of size ``alpha`` has ``power``.

    Solves ``P(F'(q, d, lambda) > F_{1-alpha}(q, d)) = power``.
    """
    crit = stats.f.isf(alpha, q, d)

    def gap(lam: float) -> float:
        return float(stats.ncf.sf(crit, q, d, lam)) - power

    hi = 1.0
    while gap(hi) < 0:
        hi *= 2.0
    return float(optimize.brentq(gap, 1e-12, hi, xtol=1e-10))


def global_f(residual: FloatArray, columns: list[FloatArray], dof: int
             ) -> tuple[float, int, int, float]:
    """The global test under an estimated noise: the current model (``residual``, ``dof``)
    against the model extended by all ``columns`` (each candidate's projected columns).

    Returns (F, q, d, p-value); (nan, 0, 0, nan) when the candidates leave no column or no
    degree of freedom.
    """
    if not columns:
        return math.nan, 0, 0, math.nan
    M = np.column_stack(columns)
    u, s, _ = np.linalg.svd(M, full_matrices=False)
    U = u[:, s > 1e-10 * max(s[0], 1e-300)] if s.size else u[:, :0]
    q = U.shape[1]
    d = dof - q
    if q == 0 or d <= 0:
        return math.nan, 0, 0, math.nan
    T = float(np.sum((U.T @ residual) ** 2))
    F = f_statistic(T, float(residual @ residual), dof, q)
    return F, q, d, math.exp(log_f_sf(F, q, d))
