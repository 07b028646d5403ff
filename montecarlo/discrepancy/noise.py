"""The noise scale the data give: the a-posteriori variance factor of a fitted model.

The residuals are whitened by the stated noise, so under a right model with the stated noise
``chi2 = r'r ~ chi2(dof)``. With a true noise ``s`` times the stated one,
``chi2 ~ s^2 chi2(dof)``: the a-posteriori variance factor ``s^2 = chi2 / dof`` estimates it
(Koch 1999, *Parameter estimation and hypothesis testing in linear models*, sec. 3.2.2), and
``[chi2 / chi2_{(1+level)/2}(dof), chi2 / chi2_{(1-level)/2}(dof)]`` is its exact ``level``
interval for a linear model with Gaussian noise. The stated noise is rejected by the data
when ``s = 1`` lies outside the interval: too small (the data scatter more) or too large.
"""

from __future__ import annotations

import math
from typing import Any

from scipy import stats

from montecarlo.lsq import LeastSquaresFit

LEVEL = 0.95
"""Confidence level of the noise-scale interval."""


def noise_scale(fit: LeastSquaresFit, level: float = LEVEL) -> dict[str, Any]:
    """Ratio of the noise the data give to the stated one, from ``fit`` (the final model).

    Returns ``factor`` (``sqrt(chi2 / dof)``), ``low`` and ``high`` (its ``level``
    interval), ``level``, ``dof`` and ``verdict``: ``"consistent"``, ``"stated too small"``
    (the interval lies above 1) or ``"stated too large"`` (below 1). None without a degree
    of freedom.
    """
    if fit.dof <= 0:
        return {"factor": math.nan, "low": math.nan, "high": math.nan, "level": level,
                "dof": fit.dof, "verdict": "no degree of freedom"}
    hi_q, lo_q = stats.chi2.ppf([(1 + level) / 2, (1 - level) / 2], fit.dof)
    low, high = math.sqrt(fit.chi2 / hi_q), math.sqrt(fit.chi2 / lo_q)
    verdict = ("stated too small" if low > 1.0 else "stated too large" if high < 1.0
               else "consistent")
    return {"factor": math.sqrt(fit.chi2 / fit.dof), "low": low, "high": high,
            "level": level, "dof": fit.dof, "verdict": verdict}


def format_noise(scale: dict[str, Any], stated: dict[str, float] | None = None) -> str:
    """One line: the factor, its interval and, for each stated noise (name -> value with its
    unit in the name), the value the data give."""
    if not math.isfinite(scale["factor"]):
        return "noise scale: no degree of freedom left to estimate it"
    line = (f"noise scale the data give (final model): {scale['factor']:.3f} x the stated "
            f"noise, {100 * scale['level']:g} % interval [{scale['low']:.3f}, "
            f"{scale['high']:.3f}] ({scale['dof']} dof)")
    if stated:
        line += "; i.e. " + ", ".join(
            f"{k} {v * scale['factor']:.4g} [{v * scale['low']:.4g}, {v * scale['high']:.4g}]"
            for k, v in stated.items())
    if scale["verdict"] != "consistent":
        line += (f"\nwarning: the stated noise is rejected by the data ({scale['verdict']}); "
                 "the tests and MDBs above assume it")
    return line
