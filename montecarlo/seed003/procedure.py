"""Fit and simulation of seed 003's measuring procedure (readings relative to the INS's reference).

The readings are modelled by :mod:`montecarlo.seed003.reference`. Two kinds of data:

* **with reference rows**: every INS reading (the two reference mirrors included) is the INS's
  absolute attitude; the relative heading and pitch at the measured mirrors are computed from the
  rows (:func:`~montecarlo.seed003.reference.relative_from_absolute`). Parameters: gamma, lambda.
* **without reference rows**: the readings are already relative (the paper's Table 1); the
  reference mirrors are at theodolite ``(az_c, 0)`` and ``(az_c + s 90 deg, 0)``, ``az_c`` fitted
  (``reference_az``). Parameters: gamma, lambda, ``reference_az``.

Rolls: recorded (absolute with reference rows, relative without; the INS's absolute roll at the
reference pointings is then fitted with the prior ``N(0, roll_sigma)``), assumed zero (level
mount), or fitted (``free_roll``: one absolute roll per pointing, reference pointings included,
each with the prior ``N(0, roll_sigma)``). With free rolls only the INS axis directions are
observed, and these depend on the offsets only through their size ``angle(u, e_y)``: the
direction of the offset in the (gamma, lambda) plane is fixed by the prior on the rolls alone
(docs/reference/collimation.md).

The fit is generalised least squares: the residual covariance is propagated from the reading
errors (INS ``sigma_ins`` per heading, pitch and roll read; theodolite ``sigma_theodolite`` per
angle), which correlates residuals through the reference rows. Relative readings carry, unseen,
the errors of the INS's heading and pitch at the two reference pointings, from which it built
its reference: they are propagated too, and correlate every residual of the calibration.

References
----------
seed 003, section 3.2 (procedure, least squares iterated; the 15 arc-second claim).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import LinAlgError, cho_factor, cho_solve, solve_triangular
from scipy.optimize import least_squares

from montecarlo.lsq import ParameterSummary
from montecarlo.seed003 import reference as ref
from montecarlo.seed003.model import (
    Noise,
    attitude_angles,
    azimuth_elevation,
    direction,
    wrap,
)
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]

CLAIM = 15.0 * ARCSEC
"""Seed 003's consistency claim: optical axis and INS axis agree within 15 arc-seconds [rad]."""

_STEP = 1e-6
"""Central-difference step [rad] for the Jacobians."""

_SEPARABLE = 1e-4
"""Smallest accepted ratio of singular values of the column-normalised whitened Jacobian (as in
:mod:`montecarlo.seed003.fit`): below it a parameter combination is not determined at all."""


class NotDetermined(ValueError):
    """Too few readings for the parameters."""


@dataclass(frozen=True)
class ProcedureData:
    """One calibration by seed 003's procedure, angles [rad], one entry per row.

    ``center``/``roll_mirror`` are the row indices of the reference mirrors, or None (then the
    INS readings are relative to the reference; otherwise absolute). ``ins_roll`` is None when
    the roll was not recorded.
    """

    theodolite_az: FloatArray
    theodolite_el: FloatArray
    ins_az: FloatArray
    ins_el: FloatArray
    ins_roll: FloatArray | None = None
    center: int | None = None
    roll_mirror: int | None = None

    @property
    def has_reference(self) -> bool:
        return self.center is not None

    @property
    def measured(self) -> NDArray[np.intp]:
        """Row indices of the measured (non-reference) mirrors."""
        skip = {self.center, self.roll_mirror}
        return np.array([i for i in range(self.ins_az.size) if i not in skip], dtype=np.intp)


@dataclass(frozen=True)
class ProcedureFit(ParameterSummary):
    """Result of :func:`fit_procedure`; angles [rad].

    ``residuals``/``residuals_before`` (m, 2): relative heading and pitch, reading minus model,
    with all parameters fitted / with the offsets held at zero. ``rolls``: absolute roll at each
    row used by the model (recorded, assumed 0 or fitted). ``chi2`` includes the roll prior.
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    sigma_ins: float
    sigma_theodolite: float
    sigma_source: str
    residuals: FloatArray
    residuals_before: FloatArray
    chi2: float
    dof: int
    roll_source: str
    rolls: FloatArray
    side: float



class _Model:
    """Residuals ``r(x, z)`` of one data set: x the parameters, z the noisy readings.

    Both may carry a leading batch axis (not both at once).
    """

    def __init__(self, data: ProcedureData, side: float, free_roll: bool, roll_sigma: float):
        self.data, self.side, self.free_roll, self.roll_sigma = data, side, free_roll, roll_sigma
        n = data.ins_az.size
        self.k = data.measured
        self.m = self.k.size
        self.rows = np.arange(n) if data.has_reference else self.k
        self.recorded_roll = data.ins_roll is not None and not free_roll
        groups = ["ins_az", "ins_el"] + (["ins_roll"] if self.recorded_roll else []) + [
            "theodolite_az", "theodolite_el"]
        self.groups = groups
        self.z0 = np.concatenate([getattr(data, g)[self.rows] for g in groups])
        self.is_ins = np.concatenate([np.full(self.rows.size, g.startswith("ins"))
                                      for g in groups])
        n_pointings = n if data.has_reference else self.m + 2
        self.names = ("axis_az", "axis_el") + (() if data.has_reference else ("reference_az",))
        self.n_core = len(self.names)
        if free_roll:
            self.names += tuple(f"roll_{i}" for i in range(n_pointings))
        elif self.recorded_roll and not data.has_reference:
            self.names += ("roll_center", "roll_mirror")
        self.n_prior = len(self.names) - self.n_core

    def _split(self, z):
        q = self.rows.size
        return {g: z[..., j * q:(j + 1) * q] for j, g in enumerate(self.groups)}

    def observed(self, z):
        """Relative heading and pitch read at the measured mirrors, (..., m) each."""
        g = self._split(z)
        if not self.data.has_reference:
            return g["ins_az"], g["ins_el"]
        c, r = self.data.center, self.data.roll_mirror
        axis = direction(g["ins_az"], g["ins_el"])
        frame = ref.frame_from_axes(axis[..., c, :], axis[..., r, :], self.side)
        return azimuth_elevation(np.matmul(axis[..., self.k, :], frame))

    def predicted(self, x, z, reference_error=None):
        g = self._split(z)
        x = np.asarray(x, float)
        gamma, lam = x[..., 0, None], x[..., 1, None]
        roll_rel = False
        if self.free_roll:
            rolls = x[..., self.n_core:]
        elif self.recorded_roll:
            rolls = g["ins_roll"]
            roll_rel = not self.data.has_reference
        else:
            n_rolls = self.rows.size + (0 if self.data.has_reference else 2)
            rolls = np.zeros((*np.shape(g["ins_az"])[:-1], n_rolls))
        if self.data.has_reference:
            c, r = self.data.center, self.data.roll_mirror
            az, el = g["theodolite_az"], g["theodolite_el"]
            center = (az[..., c, None], el[..., c, None], rolls[..., c, None])
            mirror = (az[..., r, None], el[..., r, None], rolls[..., r, None])
            az_k, el_k, roll_k = az[..., self.k], el[..., self.k], rolls[..., self.k]
        else:
            az_c = x[..., 2, None]
            if roll_rel:
                roll_k = rolls
                roll_c, roll_r = x[..., self.n_core, None], x[..., self.n_core + 1, None]
            else:
                roll_k, roll_c, roll_r = rolls[..., :self.m], rolls[..., self.m, None], \
                    rolls[..., self.m + 1, None]
            center = (az_c, 0.0, roll_c)
            mirror = (ref.roll_mirror_azimuth(az_c, self.side), 0.0, roll_r)
            az_k, el_k = g["theodolite_az"], g["theodolite_el"]
        heading, pitch, _ = ref.relative_readings(gamma, lam, az_k, el_k, roll_k, center, mirror,
                                                  self.side, roll_rel, reference_error)
        return heading, pitch

    def residuals(self, x, z, reference_error=None):
        """Reading minus model, (..., 2m) [rad]: headings then pitches. ``reference_error``
        (..., 4): the INS's heading and pitch errors at the reference pointings (relative data;
        see :func:`montecarlo.seed003.reference.relative_readings`)."""
        h_obs, p_obs = self.observed(z)
        h, p = self.predicted(x, z, reference_error)
        return np.concatenate([wrap(h_obs - h), p_obs - p], axis=-1)

    def reference_error_columns(self, x, z):
        """(..., 2m, 4) central differences of the residuals over the errors of the INS's
        heading and pitch at the two reference pointings, which relative readings carry unseen
        (:func:`montecarlo.seed003.reference.relative_readings`); x, z as for the residuals."""
        E = _STEP * np.eye(4)
        steps = np.concatenate([E, -E])[:, None, :]
        x, z = np.asarray(x, float), np.asarray(z, float)
        r = self.residuals(x[..., None, :], z[..., None, :], steps)
        return np.swapaxes(r[..., :4, :] - r[..., 4:, :], -1, -2) / (2 * _STEP)

    def prior(self, x):
        return np.asarray(x)[..., self.n_core:] / self.roll_sigma

    def jacobian_x(self, x, z, free):
        p = len(free)
        steps = np.zeros((2 * p, x.size))
        steps[np.arange(p), free] = _STEP
        steps[p + np.arange(p), free] = -_STEP
        r = self.residuals(x + steps, z)
        return (r[:p] - r[p:]).T / (2 * _STEP)

    def residual_covariance(self, x, sigma_ins, sigma_theodolite):
        """Covariance of the 2m residuals propagated from the reading errors [rad^2]: those in
        the data and, for relative readings, the INS's at the two reference pointings."""
        q = self.z0.size
        steps = _STEP * np.eye(q)
        r = self.residuals(x, np.concatenate([self.z0 + steps, self.z0 - steps]))
        G = (r[:q] - r[q:]).T / (2 * _STEP)
        s = np.where(self.is_ins, sigma_ins, sigma_theodolite)
        cov = (G * s**2) @ G.T
        if not self.data.has_reference:
            H = self.reference_error_columns(x, self.z0)
            cov = cov + sigma_ins**2 * (H @ H.T)
        return cov


def _start(model: _Model) -> FloatArray:
    x = np.zeros(len(model.names))
    if not model.data.has_reference:
        d, k = model.data, model.k
        x[2] = float(np.angle(np.mean(np.exp(1j * (d.theodolite_az[k] - d.ins_az[k])))))
    return x


def _solve(model: _Model, x0: FloatArray, free: NDArray[np.intp], sigma_ins: float,
           sigma_theodolite: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """GLS solve over the parameters ``free`` (others held at x0); returns x, cov, chi2 terms."""
    x = x0.copy()
    for _ in range(2):  # the residual covariance at the start, then at the first solution
        L = np.linalg.cholesky(model.residual_covariance(x, sigma_ins, sigma_theodolite))
        W = solve_triangular(L, np.eye(L.shape[0]), lower=True)  # whitening, L^-1

        def whitened(xf, W=W):
            xx = x0.copy()
            xx[free] = xf
            return np.concatenate([W @ model.residuals(xx, model.z0), model.prior(xx)])

        def jac(xf, W=W):
            xx = x0.copy()
            xx[free] = xf
            J = model.jacobian_x(xx, model.z0, free)
            Jp = np.zeros((model.n_prior, free.size))
            for j, i in enumerate(free):
                if i >= model.n_core:
                    Jp[i - model.n_core, j] = 1.0 / model.roll_sigma
            return np.vstack([W @ J, Jp])

        sol = least_squares(whitened, x[free], jac=jac, method="lm", xtol=1e-15, ftol=1e-15,
                            gtol=1e-15)
        x[free] = sol.x
    J = jac(x[free])
    norms = np.linalg.norm(J, axis=0)
    singular = np.linalg.svd(J / np.where(norms > 0, norms, 1.0), compute_uv=False)
    try:
        if norms.min() == 0.0 or singular[-1] < _SEPARABLE * singular[0]:
            raise LinAlgError
        cov = cho_solve(cho_factor(J.T @ J), np.eye(free.size))
    except LinAlgError:
        raise NotDetermined("the mirrors do not determine all parameters: not separable "
                            "(gamma needs pitch mirrors, lambda azimuth mirrors)") from None
    return x, cov, whitened(x[free])


def _fit_from_starts(model: _Model, free: NDArray[np.intp], sigma_ins: float,
                     sigma_theodolite: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Solve; with fitted rolls start from the fit with rolls at 0 and from its mirror images
    (gamma or lambda negated), and keep the smallest chi-square: the rolls turn the offset about
    the INS axis, so the cost has local minima in the offset's direction."""
    x0 = _start(model)
    if not model.n_prior:
        return _solve(model, x0, free, sigma_ins, sigma_theodolite)
    level, _, _ = _solve(model, x0, np.arange(model.n_core), sigma_ins, sigma_theodolite)
    best = None
    for flip in ((1.0, 1.0), (-1.0, 1.0), (1.0, -1.0)):
        start = level.copy()
        start[:2] *= flip
        got = _solve(model, start, free, sigma_ins, sigma_theodolite)
        if best is None or got[2] @ got[2] < best[2] @ best[2]:
            best = got
    return best


def _rolls(model: _Model, data: ProcedureData, x: FloatArray, free_roll: bool
           ) -> tuple[FloatArray, str]:
    """The absolute roll at every pointing of a solution ``x`` [rad] and where it came from:
    fitted, recorded, recorded with the reference pointings fitted, or assumed zero."""
    if free_roll:
        return x[model.n_core:], "fitted (one per pointing)"
    if model.recorded_roll and data.has_reference:
        return data.ins_roll[model.rows], "recorded"
    if model.recorded_roll:
        return (np.concatenate([data.ins_roll[model.rows], x[model.n_core:]]),
                "recorded (relative); at the reference mirrors fitted")
    return np.zeros(model.rows.size + (0 if data.has_reference else 2)), \
        "assumed zero (level mount)"


def fit_procedure(data: ProcedureData, *, side: float = 1.0, free_roll: bool = False,
                  roll_sigma: float = math.radians(2.0), sigma_ins: float | None = None,
                  sigma_theodolite: float | None = None, before: bool = True) -> ProcedureFit:
    """Fit gamma, lambda (and ``reference_az``, free rolls) to one calibration by the procedure.

    Generalised nonlinear least squares of the relative heading and pitch at the measured mirrors
    against :func:`montecarlo.seed003.reference.relative_readings`; the residual covariance is
    propagated from the reading errors (central differences), recomputed once at the solution.
    Free rolls carry the prior ``N(0, roll_sigma)`` as pseudo-observations.

    Parameters
    ----------
    data : ProcedureData
    side : +1 (roll mirror on the right) or -1 (left).
    free_roll : fit one absolute roll per pointing (ignores a recorded roll).
    roll_sigma : prior 1-sigma of each free roll [rad].
    sigma_ins, sigma_theodolite : errors of each INS and theodolite reading [rad]; when both are
        None they are taken equal and estimated from the residuals (a posteriori).
    before : also fit with the offsets held at zero (``residuals_before``; NaN when False).

    Returns
    -------
    ProcedureFit

    Raises
    ------
    NotDetermined
        Fewer readings than parameters.

    References
    ----------
    seed 003, section 3.2 (least squares of the readings of 10 mirrors).
    """
    model = _Model(data, side, free_roll, roll_sigma)
    p = len(model.names)
    dof = 2 * model.m + model.n_prior - p
    if dof < 1:
        raise NotDetermined(f"{model.m} measured mirrors give {2 * model.m} readings; "
                            f"{model.n_core} parameters need at least "
                            f"{model.n_core // 2 + 1} measured mirrors")
    given = sigma_ins is not None or sigma_theodolite is not None
    s_ins = ARCSEC if not given else float(sigma_ins or 0.0)
    s_theo = ARCSEC if not given else float(sigma_theodolite or 0.0)
    free = np.arange(p)
    x, cov, w = _fit_from_starts(model, free, s_ins, s_theo)
    if not given:  # a posteriori: one scale for both; the prior is not scaled
        scale = math.sqrt(float(np.sum(w[:2 * model.m] ** 2)) / max(dof, 1))
        s_ins, s_theo = s_ins * scale, s_theo * scale
        x, cov, w = _solve(model, x, free, s_ins, s_theo)
    before_free = np.arange(2, p)
    x_before = _start(model)
    if before and before_free.size:
        x_before, _, _ = _solve(model, x_before, before_free, s_ins, s_theo)
    res = model.residuals(x, model.z0)
    res_before = model.residuals(x_before, model.z0) if before else np.full_like(res, np.nan)
    m = model.m
    rolls, source = _rolls(model, data, x, free_roll)
    return ProcedureFit(names=model.names, values=x, covariance=cov, sigma_ins=s_ins,
                        sigma_theodolite=s_theo,
                        sigma_source="given" if given else "a posteriori",
                        residuals=np.stack([res[:m], res[m:]], axis=-1),
                        residuals_before=np.stack([res_before[:m], res_before[m:]], axis=-1),
                        chi2=float(w @ w), dof=dof, roll_source=source, rolls=rolls, side=side)


# --------------------------------------------------------------------------- simulation

PAPER_AZIMUTHS = tuple(math.radians(a) for a in (-30.0, -15.0, 15.0, 30.0, 45.0))
"""Azimuth mirrors of the paper-like layout (horizontal), theodolite azimuth [rad]."""

PAPER_PITCHES = tuple(math.radians(e) for e in (4.0, 7.5, 11.0, 14.5, 18.0))
"""Pitch mirrors of the paper-like layout (azimuth 0), elevation [rad]."""

HIGH_PITCHES = tuple(math.radians(e) for e in (12.0, 24.0, 36.0, 48.0, 60.0))
"""Pitch mirrors of the "pitch to 60 deg" layout [rad]."""


def procedure_layout(azimuths: ArrayLike = PAPER_AZIMUTHS, pitches: ArrayLike = PAPER_PITCHES
                     ) -> tuple[FloatArray, FloatArray, tuple[str, ...]]:
    """Measured mirrors: horizontal ones at ``azimuths``, pitch ones at azimuth 0 and ``pitches``.

    The central reference mirror is at theodolite (0, 0), the roll mirror at (s 90 deg, 0)
    (seed 003, section 3.1). Returns theodolite azimuth, elevation [rad] and the set names.
    """
    a, p = np.atleast_1d(np.asarray(azimuths, float)), np.atleast_1d(np.asarray(pitches, float))
    return (np.concatenate([a, np.zeros(p.size)]), np.concatenate([np.zeros(a.size), p]),
            ("azimuth",) * a.size + ("pitch",) * p.size)


def simulate_procedure(axis_az: float, axis_el: float, az: ArrayLike, el: ArrayLike,
                       noise: Noise, rng: int | np.random.Generator | None = None, *,
                       side: float = 1.0, frame_heading: float = 0.0, az_center: float = 0.0,
                       reference_rows: bool = True, with_roll: bool = True) -> ProcedureData:
    """One calibration by the procedure: theodolite and INS readings with errors.

    True mirror normals: the measured ``az, el``, the central reference at ``(az_center, 0)`` and
    the roll mirror at ``(az_center + s 90 deg, 0)``. The INS's absolute roll at every pointing is
    ``N(0, noise.mount_roll)``; its attitude is :func:`montecarlo.seed003.reference.attitude_at`
    turned to navigation heading by ``frame_heading``. With ``reference_rows`` the rows are the
    two reference mirrors (first) and the measured ones, with absolute readings; without, only the
    measured mirrors, read relative to the reference (exact :func:`relative_readings`). Each
    reading gets its error: theodolite ``noise.theodolite``, INS heading/pitch/roll
    ``noise.ins_heading``/``ins_pitch``/``ins_roll``; relative readings also those of the INS's
    heading and pitch at the two reference pointings, from which it built its reference (drawn
    last).
    """
    rng = np.random.default_rng(rng)
    az, el = np.asarray(az, float), np.asarray(el, float)
    m = az.size
    ref_az = np.array([az_center, float(ref.roll_mirror_azimuth(az_center, side))])
    all_az, all_el = np.concatenate([ref_az, az]), np.concatenate([np.zeros(2), el])
    rolls = noise.mount_roll * rng.standard_normal(m + 2)
    k = m + 2 if reference_rows else m
    e = rng.standard_normal((5 if with_roll else 4, k))
    if reference_rows:
        heading, pitch, roll = attitude_angles(
            ref.attitude_at(axis_az, axis_el, all_az, all_el, rolls))
        heading = wrap(heading + frame_heading)
        t_az, t_el = all_az, all_el
    else:
        scale = np.array([noise.ins_heading, noise.ins_pitch] * 2)
        heading, pitch, roll = ref.relative_readings(
            axis_az, axis_el, az, el, rolls[2:], (az_center, 0.0, rolls[0]),
            (ref_az[1], 0.0, rolls[1]), side, reference_error=scale * rng.standard_normal(4))
        t_az, t_el = az, el
    return ProcedureData(
        theodolite_az=wrap(t_az + noise.theodolite * e[0]),
        theodolite_el=t_el + noise.theodolite * e[1],
        ins_az=wrap(heading + noise.ins_heading * e[2]),
        ins_el=pitch + noise.ins_pitch * e[3],
        ins_roll=roll + noise.ins_roll * e[4] if with_roll else None,
        center=0 if reference_rows else None, roll_mirror=1 if reference_rows else None)


# --------------------------------------------------------------------------- report quantities


def _reference_pointings(data: ProcedureData, fit: ProcedureFit):
    """Theodolite (az, el) and absolute roll of the central and the roll reference pointing."""
    p = fit.params
    if data.has_reference:
        c, r = data.center, data.roll_mirror
        return ((data.theodolite_az[c], data.theodolite_el[c], fit.rolls[c]),
                (data.theodolite_az[r], data.theodolite_el[r], fit.rolls[r]))
    m = data.measured.size
    az_c = p["reference_az"]
    return ((az_c, 0.0, fit.rolls[m]),
            (float(ref.roll_mirror_azimuth(az_c, fit.side)), 0.0, fit.rolls[m + 1]))


def central_azimuth(data: ProcedureData, fit: ProcedureFit) -> float:
    """Theodolite azimuth of the central reference mirror [rad]: its row's reading, or the
    fitted ``reference_az`` when the file has no reference rows. Adding it to an azimuth
    relative to the central mirror gives the azimuth in the frame of the file's theodolite
    readings (the frame of the paper's table, whose theodolite column is relative to the
    central reference mirror)."""
    return float(_reference_pointings(data, fit)[0][0])


def corrected_and_theodolite(data: ProcedureData, fit: ProcedureFit
                             ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Corrected INS readings and the theodolite's relative angles at the measured mirrors [rad].

    The relative attitude at each measured mirror comes from the readings (relative heading and
    pitch; the roll recorded, or, when assumed or fitted, the model's relative roll at the fitted
    parameters); at the reference mirrors from the readings (reference rows) or the model. The
    corrected reading is :func:`montecarlo.seed003.reference.corrected_readings`; the theodolite
    value :func:`montecarlo.seed003.reference.theodolite_relative`.

    Returns
    -------
    corrected_az, corrected_el, theodolite_az, theodolite_el, relative_roll : ndarray (m,)
    """
    k, side = data.measured, fit.side
    gamma, lam = fit.params["axis_az"], fit.params["axis_el"]
    center, mirror = _reference_pointings(data, fit)
    if data.has_reference:
        c, r = data.center, data.roll_mirror
        h, p, roll = ref.relative_from_absolute(
            data.ins_az, data.ins_el, fit.rolls,
            (data.ins_az[c], data.ins_el[c], fit.rolls[c]),
            (data.ins_az[r], data.ins_el[r], fit.rolls[r]), side)
        rel_c, rel_r = (h[c], p[c], roll[c]), (h[r], p[r], roll[r])
        h, p, roll = h[k], p[k], roll[k]
    else:
        C_c = ref.attitude_at(gamma, lam, *center)
        C_r = ref.attitude_at(gamma, lam, *mirror)
        C_R = ref.reference_frame(C_c, C_r, side)
        rel_c, rel_r = attitude_angles(C_R.T @ C_c), attitude_angles(C_R.T @ C_r)
        h, p = data.ins_az, data.ins_el
        if fit.roll_source.startswith("recorded"):
            roll = data.ins_roll
        else:
            m = k.size
            C_k = ref.attitude_at(gamma, lam, data.theodolite_az, data.theodolite_el,
                                  fit.rolls[:m])
            roll = attitude_angles(C_R.T @ C_k)[2]
    az, el = ref.corrected_readings(h, p, roll, gamma, lam, rel_c, rel_r, side)
    t_az, t_el = ref.theodolite_relative(data.theodolite_az[k], data.theodolite_el[k],
                                         center[:2], mirror[:2], side)
    return az, el, t_az, t_el, roll


def heading_floor(data: ProcedureData, fit: ProcedureFit) -> float:
    """RMS shift of the relative headings per radian of unrecorded roll at every pointing [rad/rad].

    ``sqrt(mean_k sum_j (d heading_k / d phi_j)^2)`` at the fitted offsets, all pointings'
    absolute rolls independent: the scatter a level-mount assumption leaves when the mount rolls
    by 1 rad (1 sigma); it scales with lambda (and gamma).
    """
    model = _Model(data, fit.side, True, 1.0)
    x = np.zeros(len(model.names))
    x[:model.n_core] = fit.values[:model.n_core]
    J = model.jacobian_x(x, model.z0, np.arange(model.n_core, x.size))[:model.m]
    return float(np.sqrt(np.mean(np.sum(J**2, axis=1))))


def predicted_stderr(data: ProcedureData, fit: ProcedureFit, free_roll: bool,
                     roll_sigma: float) -> dict[str, float]:
    """1-sigma of the parameters for ``data``'s layout at the fitted values [rad], noise-free.

    The same generalised least-squares covariance as :func:`fit_procedure`, evaluated on
    readings simulated without error (:func:`simulate_procedure`) with ``fit``'s sigmas.
    """
    model = _Model(data, fit.side, free_roll, roll_sigma)
    x = np.zeros(len(model.names))
    x[:model.n_core] = fit.values[:model.n_core]
    L = np.linalg.cholesky(model.residual_covariance(x, fit.sigma_ins, fit.sigma_theodolite))
    J = solve_triangular(L, model.jacobian_x(x, model.z0, np.arange(x.size)), lower=True)
    J = np.vstack([J, np.hstack([np.zeros((model.n_prior, model.n_core)),
                                 np.eye(model.n_prior) / roll_sigma])])
    cov = np.linalg.pinv(J.T @ J)
    return dict(zip(model.names, np.sqrt(np.diag(cov)).tolist(), strict=True))


def pitch_reach(data: ProcedureData, fit: ProcedureFit, pitch: ArrayLike, free_roll: bool,
                roll_sigma: float, target: float = CLAIM / 2,
                highest: float = math.radians(85.0)) -> float | None:
    """Smallest top elevation of the pitch mirrors for which sigma_gamma <= ``target`` [rad].

    The pitch mirrors (``pitch``: mask over the measured mirrors) keep their azimuths and their
    elevations scaled to reach the candidate top elevation (1 deg steps up to ``highest``); the
    readings are simulated without error at the fitted offsets (:func:`predicted_stderr`).
    None when no pitch mirror or no elevation up to ``highest`` suffices.
    """
    pitch = np.asarray(pitch, bool)
    k = data.measured
    el = data.theodolite_el[k]
    if not pitch.any() or np.max(np.abs(el[pitch])) <= 0:
        return None
    top = float(np.max(np.abs(el[pitch])))
    center, _ = _reference_pointings(data, fit)
    for reach in np.arange(math.ceil(math.degrees(top)), math.degrees(highest) + 0.5):
        new_el = np.where(pitch, el * math.radians(reach) / top, el)
        sim = simulate_procedure(fit.params["axis_az"], fit.params["axis_el"],
                                 data.theodolite_az[k], new_el, Noise(0, 0, 0, 0, 0), 0,
                                 side=fit.side, az_center=float(center[0]),
                                 reference_rows=data.has_reference,
                                 with_roll=data.ins_roll is not None)
        se = predicted_stderr(sim, fit, free_roll, roll_sigma)
        if se["axis_az"] <= target:
            return math.radians(reach)
    return None


# --------------------------------------------------------------------------- acceptance


def acceptance_trials(n: int, rng: np.random.Generator, az: ArrayLike, el: ArrayLike, *,
                      side: float = 1.0, reference_rows: bool = True, roll: str = "recorded",
                      mount_roll: float = math.radians(1.0), noise_sigma: float = 2.0 * ARCSEC,
                      offsets: tuple[float, float] = (10.0 * ARCSEC, 600.0 * ARCSEC),
                      roll_sigma: float = math.radians(2.0)) -> dict[str, FloatArray]:
    """Monte Carlo of simulate -> fit by the procedure: how often the offsets lie within 2 sigma.

    Each trial draws gamma and lambda uniformly in ``offsets`` with random signs, a frame heading
    in [-pi, pi), simulates (:func:`simulate_procedure`, theodolite and INS errors
    ``noise_sigma``) and fits with the known sigmas (:func:`fit_procedure`). ``roll``:
    ``"recorded"`` (mount rolls ``N(0, mount_roll)``, roll column written), ``"level"`` (level
    mount, no roll column) or ``"free"`` (mount rolls, no roll column, ``free_roll``).

    Returns
    -------
    dict of ndarray (n,): ``axis_az_error``, ``axis_el_error`` [rad], ``axis_az_sigma``,
    ``axis_el_sigma`` [rad], ``chi2_red`` [1].
    """
    noise = Noise(noise_sigma, noise_sigma, noise_sigma, noise_sigma,
                  0.0 if roll == "level" else mount_roll)
    out = {k: np.empty(n) for k in ("axis_az_error", "axis_el_error", "axis_az_sigma",
                                    "axis_el_sigma", "chi2_red")}
    for i in range(n):
        truth = rng.uniform(*offsets, 2) * rng.choice([-1.0, 1.0], 2)
        data = simulate_procedure(truth[0], truth[1], az, el, noise, rng, side=side,
                                  frame_heading=rng.uniform(-math.pi, math.pi),
                                  reference_rows=reference_rows, with_roll=roll == "recorded")
        f = fit_procedure(data, side=side, free_roll=roll == "free", roll_sigma=roll_sigma,
                          sigma_ins=noise_sigma, sigma_theodolite=noise_sigma, before=False)
        se = f.stderr
        for j, k in enumerate(("axis_az", "axis_el")):
            out[f"{k}_error"][i] = f.params[k] - truth[j]
            out[f"{k}_sigma"][i] = se[k]
        out["chi2_red"][i] = f.chi2_red
    return out


ACCEPTANCE_CASES = {
    f"{layout}, {rows}, {roll}, {side}": (layout, rows == "reference rows", roll,
                                          1.0 if side == "right" else -1.0)
    for layout in ("paper-like", "pitch to 60°")
    for rows, roll, side in (("reference rows", "recorded", "right"),
                             ("reference rows", "recorded", "left"),
                             ("reference rows", "level", "right"),
                             ("reference rows", "free", "right"),
                             ("relative", "recorded", "right"),
                             ("relative", "recorded", "left"),
                             ("relative", "level", "right"),
                             ("relative", "free", "left"))
}
"""Acceptance cases: name -> (layout, reference rows?, roll, side) (reference/collimation.md)."""


def acceptance_case(name: str, n: int, seed: int) -> dict[str, FloatArray]:
    """:func:`acceptance_trials` for one of :data:`ACCEPTANCE_CASES`."""
    layout, rows, roll, side = ACCEPTANCE_CASES[name]
    az, el, _ = procedure_layout(pitches=PAPER_PITCHES if layout == "paper-like"
                                 else HIGH_PITCHES)
    return acceptance_trials(n, np.random.default_rng(seed), az, el, side=side,
                             reference_rows=rows, roll=roll)
