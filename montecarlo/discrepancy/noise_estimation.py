"""Noise estimated from the data (``auto``): the variance factor, variance components, and
the diagnosis run at the estimate.

A system's residuals are whitened with stated noise values (``sigmas``: option name -> value);
``auto`` leaves some of them to the data. The covariance of the raw residuals is
``Sigma = sum_k theta_k Q_k`` with ``theta_k = sigma_k^2`` and known ``Q_k`` (ground: the pixel
noise ``I`` and the survey noise ``J J'``). In the whitened coordinates of the values used,
``Sigma_w = sum_k theta_k Qw_k`` and ``Sigma_w = I`` at the values used.

- **One unknown value** (the others known): the pivot ``chi2(sigma) = r(sigma)' r(sigma)`` of
  the final model's whitened residuals is chi2(n - p) at the true sigma (linear model,
  Gaussian noise) and decreases with sigma; the estimate solves ``chi2(sigma) = n - p`` and
  the ``level`` interval is the set of sigma whose chi2 lies within the central ``level``
  band of chi2(n - p) (test inversion). Where sigma scales every residual alike this is the
  a-posteriori variance factor of :func:`montecarlo.discrepancy.noise.noise_scale`.
- **Several unknown values**: variance-component estimation by restricted maximum likelihood
  (REML) on the final model, linearised, by Fisher scoring, the iteration of Förstner's and
  Koch's best invariant quadratic unbiased estimate (Koch 1999, *Parameter estimation and
  hypothesis testing in linear models*, sec. 3.6; Förstner 1979; Searle, Casella and McCulloch
  1992, *Variance components*, ch. 6): with ``P = S^-1 - S^-1 A (A' S^-1 A)^-1 A' S^-1``,
  ``H_kl = tr(P Q_k P Q_l)`` and ``u_k = r' P Q_k P r``, ``theta <- H^-1 u`` until it settles;
  ``cov(theta) = 2 H^-1``. Each component's interval is Satterthwaite's: ``theta_hat`` taken
  as ``theta chi2(nu) / nu`` with ``nu = 2 theta_hat^2 / var(theta_hat)`` (for one component
  this is the exact interval above).

The diagnosis under ``auto`` (:func:`diagnose_estimated`) starts from the values an initial fit
gives, diagnoses with the tests of an estimated noise (F, Pope's tau:
:mod:`montecarlo.discrepancy.estimated_sigma`), estimates the noise on its final model and
diagnoses again at the estimate until the values used are within ``tolerance`` of it, so the
MDBs and standard errors reported are those of the estimated noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, stats

from montecarlo.discrepancy.engine import Diagnosis, diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.problem import OUTLIER, Problem, is_outlier
from montecarlo.lsq import LeastSquaresFit

FloatArray = NDArray[np.float64]

LEVEL = 0.95
"""Confidence level of the intervals."""


@dataclass(frozen=True)
class NoiseEstimate:
    """One noise value estimated from the data: ``value`` and its ``level`` interval
    [``low``, ``high``] in the option's unit, the degrees of freedom behind it (``dof``:
    the model's n - p, or Satterthwaite's nu) and the ``method``."""

    option: str
    value: float
    low: float
    high: float
    dof: float
    method: str
    level: float = LEVEL

    def to_json(self) -> dict[str, Any]:
        return {"option": self.option, "value": self.value, "low": self.low,
                "high": self.high, "level": self.level, "dof": self.dof,
                "method": self.method}


def flagged_rows(problem: Problem, fit: LeastSquaresFit) -> list[int]:
    """Whitened-residual rows of the observations the fit gives shift parameters (flagged)."""
    flagged = {e[len(OUTLIER):] for e in fit.effects if is_outlier(e)}
    return [i for oid, _, rows in problem.observations if oid in flagged for i in rows]


def pivot_estimate(chi2_of: Callable[[float], float], dof: int, start: float,
                   level: float = LEVEL) -> tuple[float, float, float]:
    """The sigma with ``chi2_of(sigma) = dof`` and the ``level`` interval of the sigma whose
    ``chi2_of`` lies in the central band of chi2(dof); ``chi2_of`` decreases with sigma.
    """
    targets = (float(dof), *stats.chi2.ppf([(1 + level) / 2, (1 - level) / 2], dof))
    out = []
    for target in targets:
        def gap(log_s: float, t: float = target) -> float:
            return math.log(chi2_of(math.exp(log_s))) - math.log(t)

        lo = hi = math.log(start)
        while gap(lo) < 0:
            lo -= 1.0
        while gap(hi) > 0:
            hi += 1.0
        out.append(math.exp(optimize.brentq(gap, lo, hi, xtol=1e-12)) if lo < hi
                   else math.exp(lo))
    value, low, high = out
    return value, low, high


def reml(residual: FloatArray, A: FloatArray, Q: list[FloatArray], theta: FloatArray,
         free: list[bool], iterations: int = 100, tol: float = 1e-10
         ) -> tuple[FloatArray, FloatArray]:
    """Variance components ``theta`` of ``Sigma = sum theta_k Q[k]`` by REML Fisher scoring
    (module docstring) on the linear model ``residual = A x + e``; components not ``free``
    stay at their value. A free component is kept non-negative. Returns theta and the
    covariance of its free components (2 H^-1, in their order)."""
    theta = np.array(theta, float)
    idx = [k for k, f in enumerate(free) if f]
    fixed = [k for k, f in enumerate(free) if not f]
    H = np.zeros((len(idx), len(idx)))
    for _ in range(iterations):
        S = sum(t * q for t, q in zip(theta, Q, strict=True))
        Si = np.linalg.inv(S)
        SiA = Si @ A
        P = Si - SiA @ np.linalg.solve(A.T @ SiA, SiA.T)
        PQ = [P @ q for q in Q]
        Pr = P @ residual
        H = np.array([[np.sum(PQ[k] * PQ[m].T) for m in idx] for k in idx])
        u = np.array([Pr @ Q[k] @ Pr for k in idx])
        u -= np.array([sum(np.sum(PQ[k] * PQ[m].T) * theta[m] for m in fixed) for k in idx])
        new = np.linalg.solve(H, u)
        new = np.maximum(new, 1e-12 * max(float(np.max(new)), 1e-300))
        change = np.max(np.abs(new - theta[idx]) / np.maximum(np.abs(new), 1e-300))
        theta[idx] = new
        if change < tol:
            break
    return theta, np.asarray(2.0 * np.linalg.inv(H), dtype=np.float64)


def satterthwaite(theta: float, var: float, level: float = LEVEL
                  ) -> tuple[float, float, float]:
    """Interval of ``sigma = sqrt(theta)`` from ``theta_hat ~ theta chi2(nu) / nu``,
    ``nu = 2 theta_hat^2 / var``; returns (low, high, nu)."""
    nu = 2.0 * theta**2 / var if var > 0 else math.inf
    if not math.isfinite(nu) or nu <= 0:
        return math.nan, math.nan, nu
    hi_q, lo_q = (float(x) for x in stats.chi2.ppf([(1 + level) / 2, (1 - level) / 2], nu))
    # with nu near 0 the quantiles underflow: the data leave the component undetermined
    low = math.sqrt(nu * theta / hi_q) if hi_q > 0 else 0.0
    high = math.sqrt(nu * theta / lo_q) if lo_q > 0 else math.inf
    return low, high, nu


def scale_estimate(option: str, used: float, fit: LeastSquaresFit, level: float = LEVEL
                   ) -> NoiseEstimate:
    """One sigma that scales every whitened residual alike (``used`` the value the residuals
    were whitened with): the a-posteriori variance factor of the final model."""
    hi_q, lo_q = stats.chi2.ppf([(1 + level) / 2, (1 - level) / 2], fit.dof)
    return NoiseEstimate(option, used * math.sqrt(fit.chi2 / fit.dof),
                         used * math.sqrt(fit.chi2 / hi_q), used * math.sqrt(fit.chi2 / lo_q),
                         fit.dof, "a-posteriori variance factor of the final model", level)


def pivot_component(option: str, build: Callable[[Mapping[str, float]], Problem],
                    sigmas: Mapping[str, float], fit: LeastSquaresFit, level: float = LEVEL
                    ) -> NoiseEstimate:
    """One unknown sigma among known ones: the pivot of the module docstring on the final
    model (its parameters held, flagged observations' rows left out)."""
    params = {k: np.float64(v) for k, v in fit.params.items() if not is_outlier(k)}
    drop = flagged_rows(build(sigmas), fit)

    def chi2_of(s: float) -> float:
        r = np.asarray(build({**sigmas, option: s}).residuals(params),  # type: ignore[arg-type]
                       dtype=np.float64)
        return float(np.sum(np.delete(r, drop) ** 2))

    value, low, high = pivot_estimate(chi2_of, fit.dof, sigmas[option], level)
    return NoiseEstimate(option, value, low, high, fit.dof,
                         "chi-square pivot of the final model, the other noise known", level)


def reml_components(options: list[str], whitened_q: list[FloatArray],
                    sigmas: Mapping[str, float], free: list[bool], fit: LeastSquaresFit,
                    level: float = LEVEL) -> list[NoiseEstimate]:
    """Variance components of the final model by REML (module docstring); ``whitened_q``
    are the ``Qw_k`` in the coordinates whitened with ``sigmas``."""
    theta0 = np.array([sigmas[o] ** 2 for o in options])
    theta, cov = reml(fit.residual, fit.jacobian, whitened_q, theta0, free)
    out = []
    for j, k in enumerate([k for k, f in enumerate(free) if f]):
        low, high, nu = satterthwaite(float(theta[k]), float(cov[j, j]), level)
        out.append(NoiseEstimate(options[k], math.sqrt(theta[k]), low, high, nu,
                                 "REML variance components of the final model "
                                 "(Satterthwaite interval)", level))
    return out


Estimator = Callable[[Mapping[str, float], LeastSquaresFit], list[NoiseEstimate]]
"""The noise estimates of a fit whitened with the given values (only the unknown ones)."""


def diagnose_estimated(build: Callable[[Mapping[str, float]], Problem],
                       sigmas: Mapping[str, float], estimate: Estimator, alpha: float,
                       initial: Callable[[Problem], LeastSquaresFit] | None = None,
                       tolerance: float = 0.01, passes: int = 3
                       ) -> tuple[Diagnosis, dict[str, float], list[NoiseEstimate]]:
    """Diagnose with the unknown noise values estimated from the data (module docstring).

    ``sigmas`` holds a value for every option (starting values for the unknown ones);
    ``initial`` fits the model the first estimate comes from (default: the base model).
    Returns the diagnosis of the last pass, the values its tests used and the estimates of
    its final model.
    """
    used = dict(sigmas)
    problem = build(used)
    first = (initial or (lambda p: fit_model(p, ())))(problem)
    used.update({e.option: e.value for e in estimate(used, first)})
    for _ in range(passes):
        d = diagnose(build(used), alpha, noise_estimated=True)
        found = estimate(used, d.after)
        if all(abs(e.value / used[e.option] - 1.0) <= tolerance for e in found):
            break
        used.update({e.option: e.value for e in found})
    return d, used, found


def format_estimates(estimates: list[Mapping[str, Any]], used: Mapping[str, float]) -> str:
    """The estimates, their intervals and the values the tests used, one line each."""
    lines = []
    for e in estimates:
        lines.append(f"{e['option']} estimated from the data: {e['value']:.4g}, "
                     f"{100 * e['level']:g} % interval [{e['low']:.4g}, {e['high']:.4g}] "
                     f"({e['method']}, {e['dof']:.4g} dof); tests and MDBs at "
                     f"{used[e['option']]:.4g}")
    lines.append("tests with the noise estimated: F for each effect and for the global test "
                 "(against every effect at once), Pope's tau for each observation")
    return "\n".join(lines)


def check_components(options: list[str], whitened_q: list[FloatArray],
                     stated: Mapping[str, float], fit: LeastSquaresFit,
                     level: float = LEVEL) -> dict[str, Any]:
    """Each stated noise value against the variance components the final model gives (REML,
    every component free): the estimates and, per value, ``"consistent"``, ``"stated too
    small"`` (its interval lies above it) or ``"stated too large"``."""
    found = reml_components(options, whitened_q, stated, [True] * len(options), fit, level)
    verdict = {e.option: ("stated too small" if e.low > stated[e.option] else
                          "stated too large" if e.high < stated[e.option] else "consistent")
               for e in found}
    return {"estimates": [e.to_json() for e in found], "stated": dict(stated),
            "verdict": verdict}


def format_components(check: Mapping[str, Any]) -> str:
    """The lines of :func:`check_components`, a warning for each value the data reject."""
    lines = ["noise values the data give (final model, REML variance components): " + ", ".join(
        f"{e['option']} {e['value']:.4g} [{e['low']:.4g}, {e['high']:.4g}] (stated "
        f"{check['stated'][e['option']]:.4g})" for e in check["estimates"])]
    for option, verdict in check["verdict"].items():
        if verdict != "consistent":
            lines.append(f"warning: the stated {option} {check['stated'][option]:.4g} is "
                         f"rejected by the data ({verdict}); the tests and MDBs above assume it")
    return "\n".join(lines)
