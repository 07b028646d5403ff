"""Least-squares fit of the autocollimator's axis offsets to one calibration (seed 003, 3.2).

Nonlinear least squares of the INS heading and pitch readings against the forward model of
:mod:`montecarlo.seed003.model`, iterated as the paper describes (fit, correct, refit).

References
----------
seed 003, section 3.2 (least squares, iterated); docs/reference/collimation.md;
docs/reference/references.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from montecarlo.lsq import ParameterSummary
from montecarlo.seed003.model import (
    BASE_EFFECTS,
    EFFECTS,
    attitude_matrix,
    azimuth_elevation,
    correct_readings,
    direction,
    mirror_normal_in_nav,
    parameter_names,
    predict_readings,
    wrap,
)
from montecarlo.seed003.model import getter as _getter
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------- fit


_JAC_STEP = 1e-6
"""Central-difference step for the Jacobian [rad]; truncation error ~1e-12 relative."""


_SEPARABLE = 1e-4
"""Smallest accepted ratio of singular values of the column-normalised Jacobian: below it the
weakest parameter combination has a sigma above 1e4 times the reading noise (about 8 deg for
2.8 arc-seconds), far outside the linear regime of the fit."""


class NotSeparable(ValueError):
    """The mirrors do not determine all parameters (the Jacobian is rank deficient)."""


@dataclass(frozen=True)
class Fit(ParameterSummary):
    """Least-squares solution of one calibration.

    Attributes
    ----------
    names : parameter names; ``values`` [rad] in that order.
    covariance : (p, p) [rad^2], from the Jacobian at the solution, scaled by ``sigma`` given or
        estimated (``sigma_source`` ``"given"`` or ``"a posteriori"``).
    sigma : standard deviations of heading and pitch residuals used [rad].
    residuals : (m, 2) reading minus model, heading and pitch [rad], after the fit.
    residuals_before : (m, 2) the same with the axis offsets held at zero (reference terms fitted).
    chi2, dof : sum of squared normalised residuals and its degrees of freedom.
    passes : offset increment fitted in each pass of fit -> correct -> refit [rad].
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    sigma: tuple[float, float]
    sigma_source: str
    residuals: FloatArray
    residuals_before: FloatArray
    chi2: float
    dof: int
    passes: list[float] = field(default_factory=list)



def min_mirrors(n_parameters: int) -> int:
    """Fewest mirrors for ``n_parameters``: two readings each, at least one degree of freedom."""
    return (n_parameters + 2) // 2


def _solve_once(names: tuple[str, ...], theodolite_az: FloatArray, theodolite_el: FloatArray,
                ins_az: FloatArray, ins_el: FloatArray, roll: FloatArray,
                sigma: tuple[float, float] | None) -> tuple[FloatArray, FloatArray, FloatArray,
                                                            tuple[float, float], int]:
    """One nonlinear least-squares fit; returns values, covariance, residuals, sigma, dof."""
    m = ins_az.size
    dof = 2 * m - len(names)
    if dof < 1:
        raise NotSeparable(f"{m} mirrors give {2 * m} readings; {len(names)} parameters need "
                           f"at least {min_mirrors(len(names))} mirrors")
    start = dict.fromkeys(names, 0.0)
    if "frame_heading" in start:
        start["frame_heading"] = float(np.angle(np.mean(np.exp(1j * (ins_az - theodolite_az)))))
    if "axis_el" in start:
        start["axis_el"] = float(np.mean(theodolite_el - ins_el))
    x_ref = np.array([start[k] for k in names])
    scale = (1.0, 1.0) if sigma is None else sigma

    def residuals(x: FloatArray) -> FloatArray:
        """Normalised residuals; x of shape (p,) or (k, p) gives (2m,) or (k, 2m)."""
        values = x_ref + x
        heading, pitch = predict_readings(
            {k: values[..., j, None] for j, k in enumerate(names)},
            theodolite_az, theodolite_el, roll)
        return np.concatenate([wrap(ins_az - heading) / scale[0], (ins_el - pitch) / scale[1]],
                              axis=-1)

    def jacobian(x: FloatArray) -> FloatArray:
        """Central differences, all 2p perturbed parameter vectors in one vectorised call."""
        steps = _JAC_STEP * np.eye(len(names))
        r = residuals(np.concatenate([x + steps, x - steps]))
        return (r[: len(names)] - r[len(names):]).T / (2 * _JAC_STEP)

    sol = least_squares(residuals, np.zeros(len(names)), jac=jacobian, method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    J = sol.jac
    norms = np.linalg.norm(J, axis=0)
    _, s, vt = np.linalg.svd(J / np.where(norms > 0, norms, 1.0), full_matrices=False)
    if norms.min() == 0.0 or s[-1] < _SEPARABLE * s[0]:
        weak = [names[i] for i in np.argsort(-np.abs(vt[-1]))[:2]]
        raise NotSeparable(f"parameters {' and '.join(weak)} are not separable with these "
                           "mirrors (axis_az needs mirrors at different elevations)")
    cov = np.linalg.inv(J.T @ J)
    r = residuals(sol.x)
    if sigma is None:
        s2 = float(r @ r) / dof
        sigma = (math.sqrt(s2), math.sqrt(s2))
        cov = cov * s2
    raw = np.stack([r[:m] * scale[0], r[m:] * scale[1]], axis=-1)
    return x_ref + sol.x, cov, raw, sigma, dof


def fit(theodolite_az: ArrayLike, theodolite_el: ArrayLike, ins_az: ArrayLike, ins_el: ArrayLike,
        ins_roll: ArrayLike | None = None, *, sigma: float | tuple[float, float] | None = None,
        effects: Sequence[str] = BASE_EFFECTS, tol: float = 0.01 * ARCSEC, max_passes: int = 5
        ) -> Fit:
    """Fit the axis offsets and reference terms to one calibration's readings.

    Nonlinear least squares (``scipy.optimize.least_squares``) of heading and pitch residuals
    ``reading - predict_readings(params, theodolite angles, roll)``, iterated as seed 003
    describes: fit, correct the readings with the fitted offsets (:func:`correct_readings`), fit
    the corrected readings again, until the offset fitted to corrected readings is below ``tol``.
    The paper fits approximate relations and needs the loop; our model is exact, so the second
    pass changes the offsets only by about 1e-3 arc-seconds (corrected readings weight the
    residuals very slightly differently from raw ones). ``Fit.passes`` records each increment.

    Parameters
    ----------
    theodolite_az, theodolite_el, ins_az, ins_el : array_like, shape (m,) [rad]
    ins_roll : array_like, shape (m,) [rad], or None to assume a level mount (roll 0).
    sigma : standard deviation of each heading and pitch residual (theodolite and INS
        combined) [rad], one value or (heading, pitch); None to estimate one value from the
        residuals.
    effects : effects fitted; must contain ``axis_misalignment``.

    Returns
    -------
    Fit

    Raises
    ------
    NotSeparable
        Too few mirrors, or parameters the mirror layout cannot separate.
    """
    if "axis_misalignment" not in effects:
        raise ValueError("effects must include 'axis_misalignment'")
    names = parameter_names(effects)
    theodolite_az, theodolite_el, ins_az, ins_el = (
        np.asarray(v, float) for v in (theodolite_az, theodolite_el, ins_az, ins_el))
    roll = np.zeros_like(ins_az) if ins_roll is None else np.asarray(ins_roll, float)
    if sigma is not None:
        sigma = (float(sigma), float(sigma)) if np.ndim(sigma) == 0 else tuple(map(float, sigma))
    reference = tuple(k for k in names if k not in EFFECTS["axis_misalignment"])
    i_az, i_el = names.index("axis_az"), names.index("axis_el")

    offset = np.eye(3)  # R_z(-gamma) R_x(lambda) accumulated over the passes
    az, el, rl = ins_az, ins_el, roll
    passes: list[float] = []
    for _ in range(max_passes):
        values, cov, _, used_sigma, dof = _solve_once(names, theodolite_az, theodolite_el,
                                                      az, el, rl, sigma)
        passes.append(math.hypot(values[i_az], values[i_el]))
        offset = offset @ attitude_matrix(values[i_az], values[i_el], 0.0)
        az, el, rl = correct_readings(az, el, rl, values[i_az], values[i_el])
        if passes[-1] < tol:
            break
    values[i_az], values[i_el] = azimuth_elevation(offset[:, 1])

    params = dict(zip(names, values, strict=True))
    heading, pitch = predict_readings(params, theodolite_az, theodolite_el, roll)
    res = np.stack([wrap(ins_az - heading), ins_el - pitch], axis=-1)
    scale = np.array(used_sigma)
    before = _solve_once(reference, theodolite_az, theodolite_el, ins_az, ins_el, roll, sigma)
    return Fit(names=names, values=values, covariance=cov, sigma=used_sigma,
               sigma_source="a posteriori" if sigma is None else "given", residuals=res,
               residuals_before=before[2], chi2=float(np.sum((res / scale) ** 2)), dof=dof,
               passes=passes)


def consistency_angles(params: Mapping[str, float], theodolite_az: ArrayLike,
                       theodolite_el: ArrayLike, ins_az: ArrayLike, ins_el: ArrayLike,
                       ins_roll: ArrayLike = 0.0) -> FloatArray:
    """Angle between the (corrected) optical axis and each mirror normal, shape (m,) [rad].

    ``angle(C_b^n u, C_t^n d)`` with the INS attitude as read and ``u`` from the fitted offsets:
    the per-mirror axis consistency that seed 003's 15 arc-second claim is about.
    """
    p = _getter(params)
    w = mirror_normal_in_nav(params, theodolite_az, theodolite_el)
    u = direction(p("axis_az"), p("axis_el"))
    axis = np.matmul(attitude_matrix(ins_az, ins_el, ins_roll), u[..., None])[..., 0]
    return np.arctan2(np.linalg.norm(np.cross(axis, w), axis=-1), np.sum(axis * w, axis=-1))
