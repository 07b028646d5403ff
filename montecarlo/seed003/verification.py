"""Out-of-sample check of a seed 003 calibration, as the paper prescribes.

Section 3.2: "to make sure the result is right, one more set of data can be measured and the
iterated result substituted into the calculation, to check whether the error meets the
requirement". :func:`apply_offsets` does that for a new data set: the offsets gamma, lambda of a
saved fit are held, only what belongs to the new set is fitted (the theodolite azimuth of the
central mirror when the file has no reference rows, the rolls when they are free), and the
corrected readings are compared with the theodolite. :func:`leave_one_out` does the same within
one data set: each measured mirror is left out in turn, the offsets are fitted to the others and
applied to it.

References
----------
seed 003, section 3.2 (verification by one more measured set; the 15 arc-second claim).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from montecarlo.seed003.procedure import (
    CLAIM,
    ProcedureData,
    ProcedureFit,
    _Model,
    _rolls,
    _solve,
    _start,
    corrected_and_theodolite,
    fit_procedure,
)

FloatArray = NDArray[np.float64]


def apply_offsets(data: ProcedureData, axis_az: float, axis_el: float, *, side: float,
                  free_roll: bool, roll_sigma: float, sigma_ins: float,
                  sigma_theodolite: float) -> ProcedureFit:
    """The procedure's fit with the offsets held at ``axis_az``, ``axis_el`` [rad].

    The other parameters (``reference_az``, the rolls) are fitted as in
    :func:`~montecarlo.seed003.procedure.fit_procedure`; their covariance is that of the
    reduced problem, the offsets' rows and columns are zero. ``residuals_before`` is NaN.
    """
    model = _Model(data, side, free_roll, roll_sigma)
    x0 = _start(model)
    x0[:2] = axis_az, axis_el
    p = len(model.names)
    free = np.arange(2, p)
    cov = np.zeros((p, p))
    if free.size:
        x, sub, w = _solve(model, x0, free, sigma_ins, sigma_theodolite)
        cov[np.ix_(free, free)] = sub
    else:
        x = x0
        L = np.linalg.cholesky(model.residual_covariance(x, sigma_ins, sigma_theodolite))
        w = np.linalg.solve(L, model.residuals(x, model.z0))
    res = model.residuals(x, model.z0)
    m = model.m
    rolls, source = _rolls(model, data, x, free_roll)
    dof = 2 * m + model.n_prior - free.size
    return ProcedureFit(names=model.names, values=x, covariance=cov, sigma_ins=sigma_ins,
                        sigma_theodolite=sigma_theodolite, sigma_source="given",
                        residuals=np.stack([res[:m], res[m:]], axis=-1),
                        residuals_before=np.full((m, 2), np.nan), chi2=float(w @ w), dof=dof,
                        roll_source=source, rolls=rolls, side=side)


@dataclass(frozen=True)
class Verification:
    """Deviations of corrected readings from the theodolite at mirrors not used by the fit.

    ``deviation_az``, ``deviation_el`` (m,) [rad], in the order of ``data.measured``;
    ``offsets`` (m, 2): the gamma, lambda applied to each mirror [rad].
    """

    deviation_az: FloatArray
    deviation_el: FloatArray
    offsets: FloatArray

    @property
    def max_deviation(self) -> float:
        """Largest |deviation| of any mirror in heading or pitch [rad]."""
        return float(max(np.max(np.abs(self.deviation_az)), np.max(np.abs(self.deviation_el))))

    @property
    def holds(self) -> bool:
        """Seed 003's claim: every corrected reading within 15″ of the theodolite."""
        return self.max_deviation <= CLAIM


def deviations(data: ProcedureData, fit: ProcedureFit) -> tuple[FloatArray, FloatArray]:
    """Corrected reading minus theodolite at the measured mirrors, heading and pitch [rad]."""
    c_az, c_el, t_az, t_el, _ = corrected_and_theodolite(data, fit)
    return np.angle(np.exp(1j * (c_az - t_az))), c_el - t_el


def verify(data: ProcedureData, axis_az: float, axis_el: float, **options) -> Verification:
    """Apply saved offsets to a new data set (:func:`apply_offsets`) and compare."""
    fit = apply_offsets(data, axis_az, axis_el, **options)
    d_az, d_el = deviations(data, fit)
    return Verification(d_az, d_el, np.tile([axis_az, axis_el], (d_az.size, 1)))


def without_row(data: ProcedureData, row: int) -> ProcedureData:
    """The data set without one measured row (reference rows keep their roles)."""
    if row in (data.center, data.roll_mirror):
        raise ValueError("a reference row cannot be left out")
    keep = np.array([i for i in range(data.ins_az.size) if i != row])

    def shift(i: int | None) -> int | None:
        return None if i is None else i - (i > row)

    return dataclasses.replace(
        data, theodolite_az=data.theodolite_az[keep], theodolite_el=data.theodolite_el[keep],
        ins_az=data.ins_az[keep], ins_el=data.ins_el[keep],
        ins_roll=None if data.ins_roll is None else data.ins_roll[keep],
        center=shift(data.center), roll_mirror=shift(data.roll_mirror))


def leave_one_out(data: ProcedureData, *, side: float, free_roll: bool, roll_sigma: float,
                  sigma_ins: float, sigma_theodolite: float) -> Verification:
    """Each measured mirror in turn: fit the offsets without it, apply them to it.

    The offsets come from :func:`~montecarlo.seed003.procedure.fit_procedure` on the other
    mirrors; applied to the whole set (:func:`apply_offsets`), the left-out mirror's corrected
    reading is compared with the theodolite. With free rolls the left-out pointing's own roll
    is fitted to its readings when the offsets are applied, as it would be for a new set.
    """
    k = data.measured
    d_az, d_el, offsets = np.empty(k.size), np.empty(k.size), np.empty((k.size, 2))
    options = {"side": side, "free_roll": free_roll, "roll_sigma": roll_sigma,
               "sigma_ins": sigma_ins, "sigma_theodolite": sigma_theodolite}
    for j, row in enumerate(k):
        f = fit_procedure(without_row(data, int(row)), before=False, **options)
        g, lam = f.params["axis_az"], f.params["axis_el"]
        applied = apply_offsets(data, g, lam, **options)
        az, el = deviations(data, applied)
        d_az[j], d_el[j], offsets[j] = az[j], el[j], (g, lam)
    return Verification(d_az, d_el, offsets)


