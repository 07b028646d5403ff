"""Seed 003's measuring procedure with candidate effects for the discrepancy workflow.

The base model is the procedure's reading model (:mod:`montecarlo.seed003.reference`): the INS
reads its attitude relative to the frame ``R`` it set up at the central and the roll reference
mirror. Base parameters: the offsets gamma, lambda (``axis_az``, ``axis_el`` [rad]) and, for files
without reference rows (relative readings), the theodolite azimuth of the central reference
mirror (``reference_az`` [rad]). Rolls: recorded (absolute with reference rows; relative without,
the rolls at the reference pointings then taken as 0) or a level mount (no roll column).

Candidates, absent when zero (the parametrisations of
:mod:`montecarlo.discrepancy.collimation_effects` where they carry over):

* ``frame_misalignment`` (``frame_tilt_x``, ``frame_tilt_y`` [rad]): the theodolite/mirror frame
  tilted against the INS level;
* ``ins_scale_factor`` (``ins_heading_scale``, ``ins_pitch_scale`` [1]): every absolute reading
  of the INS (reference pointings included) is ``h + s_h wrap(h - h_c)``, ``p (1 + s_p)``
  (``h_c`` the heading at the central mirror; a constant cancels in the relative readings);
* ``ins_bias`` (``ins_heading_bias``, ``ins_pitch_bias`` [rad]): ``h + b_h``, ``p + b_p``;
* ``theodolite_collimation`` (``theodolite_c`` [rad]): azimuths read ``az + c / cos(el)``;
* ``reading_model`` (``reading_tilt_x``, ``reading_tilt_y`` [rad], files without reference
  rows): the readings refer to the procedure's frame ``R`` tilted about its x and y axes. Data
  read without the reference (absolute readings, a level frame up to a heading) are this with
  the tilt :func:`reference_tilt` (of the order of the offsets); a bilinear switch between the
  two models would not be, and the engine adapts along linearised candidates.

A bad mirror is found by the engine's data snooping (one observation per measured mirror). The
residuals are whitened with the covariance propagated from the reading errors (theodolite and
INS ``angle_sigma / sqrt 2`` each), which correlates them through the reference rows.

References
----------
seed 003, section 3.2 (procedure); docs/reference/discrepancy.md ("Collimation: the procedure's
readings").
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy.fit import FitError, fit_model
from montecarlo.discrepancy.problem import Effect, Problem, is_outlier
from montecarlo.discrepancy.view import SystemView
from montecarlo.io.collimation_csv import MirrorData, procedure_data
from montecarlo.lsq import LeastSquaresFit
from montecarlo.seed003 import conventions as cv
from montecarlo.seed003 import reference as ref
from montecarlo.seed003.conventions import Choice
from montecarlo.seed003.model import (
    Noise,
    attitude_angles,
    attitude_matrix,
    autocollimate,
    azimuth_elevation,
    direction,
    mirror_normal_in_nav,
    wrap,
)
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]

_OFFSETS = ((-math.radians(5.0), math.radians(5.0)),) * 2


def base_effect(reference_rows: bool) -> Effect:
    """The always-fitted parameters: gamma, lambda [rad] (and ``reference_az`` [rad])."""
    if reference_rows:
        return Effect("offsets", ("axis_az", "axis_el"), _OFFSETS, (1e-7,) * 2,
                      "optical axis vs INS axis: azimuth gamma, elevation lambda [rad]")
    return Effect("offsets", ("axis_az", "axis_el", "reference_az"),
                  (*_OFFSETS, (-np.inf, np.inf)), (1e-7,) * 3,
                  "gamma, lambda and the theodolite azimuth of the central mirror [rad]")


READING_MODEL = Effect("reading_model", ("reading_tilt_x", "reading_tilt_y"),
                       ((-math.radians(1.0), math.radians(1.0)),) * 2, (1e-7,) * 2,
                       "tilt of the frame the readings refer to, about its x and y [rad]",
                       (1.0, 1.0))

CANDIDATES = (*(c for c in ce.CANDIDATES if c.name not in ("axis_misalignment",)),
              READING_MODEL)

TRUTH_KEYS = tuple(p for c in CANDIDATES for p in c.parameters)
"""Parameters of every candidate effect that does not depend on the data (all but ``ins_roll``)."""

ROLL = "ins_roll"
"""The unrecorded (or misrecorded) INS roll: one roll per pointing but the central one."""

ROLL_PRIOR = math.radians(2.0)
"""Default size (1 sigma) of an unrecorded roll [rad]; the candidate's physical bound is 3 sigma."""


def roll_parameters(data: MirrorData) -> tuple[str, ...]:
    """Parameters of ``ins_roll``: the roll at the roll reference pointing and at each measured
    mirror [rad], added to the recorded (or assumed zero) roll. The central pointing's roll is
    not one of them: a roll common to all pointings turns the offset about the INS axis, which
    gamma and lambda already describe (docs/reference/collimation.md, "Free rolls")."""
    pd = procedure_data(data)
    return ("ins_roll_reference_roll",
            *(f"ins_roll_{data.mirror[i]}" for i in pd.measured))


def roll_effect(data: MirrorData, prior: float = ROLL_PRIOR,
                only: Sequence[str] | None = None) -> Effect:
    """The ``ins_roll`` candidate of these data, each roll within +-3 ``prior`` [rad]; ``only``
    keeps those of its parameters (the others stay zero), as a diagnosis adapts it."""
    every = roll_parameters(data)
    names = every if only is None else tuple(n for n in every if n in set(only))
    return Effect(ROLL, names, ((-3.0 * prior, 3.0 * prior),) * len(names), (1e-6,) * len(names),
                  "INS roll not recorded: one roll per pointing (the central one the reference) "
                  f"within +-{3 * math.degrees(prior):.3g} deg [rad]",
                  tuple((-1.0) ** every.index(n) for n in names))


def _roll_offsets(params: Mapping[str, ArrayLike], data: MirrorData) -> FloatArray | float:
    """The ``ins_roll`` values at the pointings [centre (0), roll mirror, measured...] [rad],
    shape (..., n); 0.0 when none is given."""
    values = [params.get(n) for n in roll_parameters(data)]
    if all(v is None for v in values):
        return 0.0
    values = [np.asarray(0.0 if v is None else v, float) for v in values]
    batch = next((v.shape[:-1] for v in values if v.ndim), ())
    return np.concatenate([np.zeros((*batch, 1)),
                           *(np.broadcast_to(v, (*batch, 1)) for v in values)], axis=-1)


def display_unit(name: str) -> tuple[str, float]:
    if name == "reference_az" or name.startswith("ins_roll_"):
        return "deg", math.pi / 180.0
    if name in READING_MODEL.parameters:
        return "arcsec", ARCSEC
    return ce.display_unit(name)


def _tilt(tilt_x: ArrayLike, tilt_y: ArrayLike) -> FloatArray:
    """Rotation by small angles about x and y: ``expm(skew([tx, ty, 0]))`` (Rodrigues)."""
    tx, ty = np.broadcast_arrays(np.asarray(tilt_x, float), np.asarray(tilt_y, float))
    a = np.hypot(tx, ty)[..., None, None]
    K = np.zeros((*tx.shape, 3, 3))
    K[..., 0, 2], K[..., 2, 0] = ty, -ty
    K[..., 1, 2], K[..., 2, 1] = -tx, tx
    small = a < 1e-8
    s = np.where(small, 1.0 - a**2 / 6.0, np.sin(a) / np.where(small, 1.0, a))
    c = np.where(small, 0.5 - a**2 / 24.0, (1.0 - np.cos(a)) / np.where(small, 1.0, a) ** 2)
    return np.eye(3) + s * K + c * (K @ K)


def relative_to_reference(heading: ArrayLike, pitch: ArrayLike, side: float,
                          tilt: tuple[ArrayLike, ArrayLike] = (0.0, 0.0)
                          ) -> tuple[FloatArray, FloatArray]:
    """Relative heading and pitch of pointings 2.. from absolute readings (..., n) [rad].

    Pointing 0 is the central, 1 the roll reference mirror; the frame is
    :func:`montecarlo.seed003.reference.frame_from_axes` of the INS axes there, turned by the
    reading-frame ``tilt`` (about its x and y axes [rad]; the ``reading_model`` candidate).

    References
    ----------
    seed 003, section 3.2 (the reference axis from the central and the roll mirror).
    """
    axes = direction(heading, pitch)
    frame = ref.frame_from_axes(axes[..., 0, :], axes[..., 1, :], side)
    if np.any(np.asarray(tilt[0]) != 0.0) or np.any(np.asarray(tilt[1]) != 0.0):
        # parameters come as (k, 1) per model, the frame is (k, 3, 3)
        frame = frame @ _tilt(*(np.asarray(t, float)[..., 0] if np.ndim(t) else t
                                for t in tilt))
    return azimuth_elevation(np.matmul(axes[..., 2:, :], frame))


def reference_tilt(heading: ArrayLike, pitch: ArrayLike, side: float
                   ) -> tuple[FloatArray, FloatArray]:
    """The reading-frame tilt that turns the procedure's readings into absolute ones [rad].

    The x and y components of the rotation vector of ``R^T L``, ``L`` the level frame with the
    INS's heading at the central mirror (pointing 0): absolute readings are relative readings in
    the frame ``R`` tilted by this (up to a heading, and to second order).
    """
    axes = direction(heading, pitch)
    frame = ref.frame_from_axes(axes[..., 0, :], axes[..., 1, :], side)
    h0 = np.asarray(heading, float)[..., 0]
    level = ref.frame_from_axes(direction(h0, 0.0),
                                direction(ref.roll_mirror_azimuth(h0, side), 0.0), side)
    M = np.swapaxes(frame, -1, -2) @ level
    return 0.5 * (M[..., 2, 1] - M[..., 1, 2]), 0.5 * (M[..., 0, 2] - M[..., 2, 0])


def _pointings(params: Mapping[str, ArrayLike], data: MirrorData, side: float
               ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
    """True theodolite (az, el) of the pointings [centre, roll mirror, measured...] [rad]."""
    p = _getter(params)
    pd = procedure_data(data)
    k = pd.measured
    if pd.has_reference:
        rows = np.array([pd.center, pd.roll_mirror, *k], dtype=np.intp)
        az, el = data.theodolite_az[rows], data.theodolite_el[rows]
    else:
        rows = k
        az_c = p("reference_az")
        shape = np.broadcast_shapes(np.shape(az_c), (1,))
        az_c = np.broadcast_to(az_c, shape)
        batch = shape[:-1]
        az = np.concatenate([az_c, ref.roll_mirror_azimuth(az_c, side),
                             np.broadcast_to(data.theodolite_az[k], (*batch, k.size))], axis=-1)
        el = np.concatenate([np.zeros(2), data.theodolite_el[k]])
    return az, el, rows


def _getter(params: Mapping[str, ArrayLike]):
    return lambda name: np.asarray(params.get(name, 0.0), float)


def reported_attitudes(params: Mapping[str, ArrayLike], data: MirrorData, side: float = 1.0,
                       rolls: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
    """Absolute heading and pitch the INS reports at [centre, roll mirror, measured...] [rad].

    Headings in the theodolite frame (its azimuth zero). The theodolite azimuths are corrected
    for the collimation, the directions tilted by the frame tilt, the INS autocollimated at its
    absolute roll (``rolls`` at every pointing if given; else recorded or 0, a relative roll
    turned absolute in the true reference frame), and the INS scale factors and biases applied.

    References
    ----------
    seed 003, sections 2 and 3.2; the effects as in the module docstring.
    """
    p = _getter(params)
    az, el, rows = _pointings(params, data, side)
    az = az - p("theodolite_c") / np.cos(el)
    w = mirror_normal_in_nav({"frame_tilt_x": p("frame_tilt_x"),
                              "frame_tilt_y": p("frame_tilt_y")}, az, el)
    az, el = azimuth_elevation(w)
    gamma, lam = p("axis_az"), p("axis_el")
    relative_roll = False
    if rolls is None:
        has_ref = procedure_data(data).has_reference
        if data.ins_roll is None:
            rolls = np.zeros(az.shape[-1])
        elif has_ref:
            rolls = data.ins_roll[rows]
        else:
            rolls = np.concatenate([np.zeros(2), data.ins_roll[rows]])
            relative_roll = True
    rolls = np.asarray(rolls, float) + _roll_offsets(params, data)
    if relative_roll:
        C_ref = ref.attitude_at(gamma, lam, az[..., :2], el[..., :2], rolls[..., :2])
        C_R = ref.reference_frame(C_ref[..., 0, :, :], C_ref[..., 1, :, :], side)
        w_k = np.einsum("...ij,...mi->...mj", C_R, direction(az[..., 2:], el[..., 2:]))
        h_k, p_k = autocollimate(direction(gamma, lam), w_k, rolls[..., 2:])
        C_k = C_R[..., None, :, :] @ attitude_matrix(h_k, p_k, rolls[..., 2:])
        C = np.concatenate([C_ref, C_k], axis=-3)
    else:
        C = ref.attitude_at(gamma, lam, az, el, rolls)
    heading, pitch, _ = attitude_angles(C)
    heading = heading + p("ins_heading_scale") * wrap(heading - heading[..., :1]) \
        + p("ins_heading_bias")
    pitch = pitch * (1.0 + p("ins_pitch_scale")) + p("ins_pitch_bias")
    return heading, pitch


def predict_relative(params: Mapping[str, ArrayLike], data: MirrorData, side: float = 1.0
                     ) -> tuple[FloatArray, FloatArray]:
    """Relative heading and pitch at the measured mirrors, shapes (..., m) [rad]."""
    heading, pitch = reported_attitudes(params, data, side)
    p = _getter(params)
    return relative_to_reference(heading, pitch, side,
                                 (p("reading_tilt_x"), p("reading_tilt_y")))


def observed_relative(data: MirrorData, side: float = 1.0) -> tuple[FloatArray, FloatArray]:
    """Relative heading and pitch read at the measured mirrors [rad] (computed from the
    reference rows' absolute readings when present)."""
    pd = procedure_data(data)
    if not pd.has_reference:
        return data.ins_az, data.ins_el
    rows = np.array([pd.center, pd.roll_mirror, *pd.measured], dtype=np.intp)
    return relative_to_reference(data.ins_az[rows], data.ins_el[rows], side)


def raw_residuals(data: MirrorData, params: Mapping[str, ArrayLike], side: float = 1.0
                  ) -> FloatArray:
    """Reading minus model, relative heading and pitch, shape (..., m, 2) [rad]."""
    h_obs, p_obs = observed_relative(data, side)
    h, p = predict_relative(params, data, side)
    return np.stack([wrap(h_obs - h), p_obs - p], axis=-1)


def residual_covariance(data: MirrorData, params: Mapping[str, float], sigma: float,
                        side: float = 1.0) -> FloatArray:
    """Covariance of the 2m residuals (headings, then pitches) [rad^2], propagated by central
    differences from independent errors ``sigma`` of every INS heading and pitch and theodolite
    azimuth and elevation in the file, and, without reference rows, of the INS's heading and
    pitch at the two reference mirrors (common to all relative readings)."""
    fields = ("ins_az", "ins_el", "theodolite_az", "theodolite_el")
    step = 1e-6
    columns = []
    for f in fields:
        for i in range(len(data.mirror)):
            pair = []
            for sgn in (1.0, -1.0):
                v = getattr(data, f).copy()
                v[i] += sgn * step
                r = raw_residuals(dataclasses.replace(data, **{f: v}), params, side)
                pair.append(np.concatenate([r[:, 0], r[:, 1]]))
            columns.append((pair[0] - pair[1]) / (2.0 * step))
    if not procedure_data(data).has_reference:  # the INS's readings at the reference mirrors
        heading, pitch = reported_attitudes(params, data, side)
        for values, other, j in [(heading, pitch, 0), (heading, pitch, 1),
                                 (pitch, heading, 0), (pitch, heading, 1)]:
            pair = []
            for sgn in (1.0, -1.0):
                v = values.copy()
                v[j] += sgn * step
                h, p = relative_to_reference(*((v, other) if values is heading else (other, v)),
                                             side)
                pair.append(np.concatenate([h, p]))
            columns.append((pair[0] - pair[1]) / (2.0 * step))
    G = np.array(columns).T
    return sigma**2 * (G @ G.T)


def start_values(data: MirrorData) -> dict[str, float]:
    pd = procedure_data(data)
    if pd.has_reference:
        return {}
    k = pd.measured
    return {"reference_az": float(np.angle(np.mean(np.exp(
        1j * (data.theodolite_az[k] - data.ins_az[k])))))}


def procedure_problem(data: MirrorData, angle_sigma: float, side: float = 1.0,
                      roll_prior: float = ROLL_PRIOR, rolls: Sequence[str] | None = None
                      ) -> Problem:
    """The DIA problem of one calibration by the procedure; ``angle_sigma`` is the error of a
    heading or pitch residual of a mirror without reference rows, ``hypot`` of the theodolite's
    and the INS's (each taken as ``angle_sigma / sqrt 2``). ``roll_prior`` [rad] sizes the
    ``ins_roll`` candidate and ``rolls`` keeps some of its parameters (:func:`roll_effect`)."""
    pd = procedure_data(data)
    k = pd.measured
    start = start_values(data)
    cov = residual_covariance(data, start, angle_sigma / math.sqrt(2.0), side)
    vals, vecs = np.linalg.eigh(cov)
    W = (vecs / np.sqrt(np.maximum(vals, 1e-30 * vals.max()))) @ vecs.T

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        r = raw_residuals(data, values, side)
        return np.concatenate([r[..., 0], r[..., 1]], axis=-1) @ W.T

    m = k.size
    # observation number: position among the measured mirrors (the report's residual axes)
    observations = tuple((data.mirror[i], j + 1, (j, m + j)) for j, i in enumerate(k))
    unavailable = {"reading_model": "with reference rows the readings are absolute by "
                   "definition"} if pd.has_reference else {}
    return Problem("collimation", base_effect(pd.has_reference),
                   (*CANDIDATES, roll_effect(data, roll_prior, rolls)), residuals, start,
                   unavailable, observations)


def choose_conventions(data: MirrorData, angle_sigma: float, side: str = "auto",
                       sense: str = "auto", roll_prior: float = ROLL_PRIOR
                       ) -> tuple[MirrorData, float, dict[str, Choice]]:
    """The roll-mirror side and azimuth sense the data support (:mod:`montecarlo.seed003.
    conventions`): the base model fitted under each, the smallest chi-square taken under
    ``"auto"``. Returns the data (theodolite azimuths turned for an ``opposite`` sense), the
    side's sign and the two :class:`~montecarlo.seed003.conventions.Choice`."""
    senses = list(cv.SENSES) if sense == "auto" else [sense]
    chi2: dict[tuple[str, str], float] = {}
    for sn in senses:
        turned = dataclasses.replace(data, theodolite_az=cv.SENSES[sn] * data.theodolite_az)
        for sd, sign in ref.SIDES.items():
            try:
                f = fit_model(procedure_problem(turned, angle_sigma, sign, roll_prior), ())
            except (FitError, ValueError, np.linalg.LinAlgError):
                chi2[sd, sn] = math.inf
                continue
            chi2[sd, sn] = f.chi2
    if not any(math.isfinite(v) for v in chi2.values()):
        raise FitError("the base model cannot be fitted under any convention")
    by_sense = {sn: min(chi2[sd, sn] for sd in ref.SIDES) for sn in senses}
    if len(senses) == 1:
        sense_choice = cv.Choice("azimuth_sense", sense, sense, by_sense, False,
                                 "stated, not compared")
    else:
        sense_choice = cv.decide("azimuth_sense", by_sense, cv.STATED_SENSE, None, 1.0,
                                 "the azimuth mirrors cannot tell the senses apart")
    sn = sense_choice.chosen
    side_choice = cv.decide("roll_mirror", {sd: chi2[sd, sn] for sd in ref.SIDES},
                            cv.STATED_SIDE if side == "auto" else side,
                            None if side == "auto" else side, 1.0,
                            "with reference rows the side does not change the fit"
                            if procedure_data(data).has_reference else
                            "the readings do not depend on the side")
    turned = dataclasses.replace(data, theodolite_az=cv.SENSES[sn] * data.theodolite_az)
    return turned, ref.SIDES[side_choice.chosen], {"roll_mirror": side_choice,
                                                   "azimuth_sense": sense_choice}


def min_mirrors() -> int:
    """Fewest rows: 3 base parameters + the largest candidate (2) + 1 dof, 2 readings each."""
    return 3


def simulate(layout: MirrorData, truth: Mapping[str, float], noise: Noise,
             rng: int | np.random.Generator | None = None, side: float = 1.0,
             frame_heading: float = 0.0) -> MirrorData:
    """Readings of the layout's mirrors (true theodolite angles) by the procedure under ``truth``.

    Absolute INS rolls ``N(0, noise.mount_roll)`` at every pointing; the INS reports
    :func:`reported_attitudes` plus its errors (heading also turned by ``frame_heading``). With
    reference rows in ``layout`` the file holds these absolute readings (roll column if the
    layout has one); without, the relative readings the INS computes from its erroneous reports
    (:func:`relative_to_reference`, the reading-frame tilt from ``truth``), no roll column; the
    reference pointings at ``truth["reference_az"]``. Theodolite azimuths read
    ``+ c / cos(el)``; every theodolite reading gets ``noise.theodolite``.
    """
    rng = np.random.default_rng(rng)
    pd = procedure_data(layout)
    n_point = pd.measured.size + 2
    rolls = noise.mount_roll * rng.standard_normal(n_point)
    plain = dataclasses.replace(layout, ins_roll=None)
    # the INS autocollimates on the true normals: the collimation changes only what the
    # theodolite reads (below), not where the mirrors are
    seen = {k: v for k, v in truth.items() if k != "theodolite_c"}
    heading, pitch = reported_attitudes(seen, plain, side, rolls)
    heading = heading + noise.ins_heading * rng.standard_normal(n_point)
    pitch = pitch + noise.ins_pitch * rng.standard_normal(n_point)
    _, _, rows = _pointings(truth, plain, side)
    m_rows = len(layout.mirror)
    c = float(truth.get("theodolite_c", 0.0))
    theo_az = layout.theodolite_az + c / np.cos(layout.theodolite_el) \
        + noise.theodolite * rng.standard_normal(m_rows)
    theo_el = layout.theodolite_el + noise.theodolite * rng.standard_normal(m_rows)
    if pd.has_reference:
        ins_az, ins_el = np.zeros(m_rows), np.zeros(m_rows)
        ins_az[rows], ins_el[rows] = wrap(heading + frame_heading), pitch
        roll = None
        if layout.ins_roll is not None:
            roll = np.zeros(m_rows)
            roll[rows] = rolls + noise.ins_roll * rng.standard_normal(n_point)
        return dataclasses.replace(layout, theodolite_az=wrap(theo_az), theodolite_el=theo_el,
                                   ins_az=ins_az, ins_el=ins_el, ins_roll=roll)
    rel_h, rel_p = relative_to_reference(heading, pitch, side,
                                         (truth.get("reading_tilt_x", 0.0),
                                          truth.get("reading_tilt_y", 0.0)))
    return dataclasses.replace(layout, theodolite_az=wrap(theo_az), theodolite_el=theo_el,
                               ins_az=wrap(rel_h), ins_el=rel_p, ins_roll=None)


def exact_problem(layout: MirrorData, truth: Mapping[str, float], angle_sigma: float,
                  side: float = 1.0, roll_prior: float = ROLL_PRIOR) -> Problem:
    """The problem of error-free readings generated by ``truth`` (for design MDBs)."""
    return procedure_problem(simulate(layout, truth, Noise(0.0, 0.0, 0.0, 0.0, 0.0), 0, side),
                             angle_sigma, side, roll_prior)


def paper_layout(reference_rows: bool = True, azimuths: ArrayLike | None = None,
                 pitches: ArrayLike | None = None, side: float = 1.0) -> MirrorData:
    """The paper-like layout of the procedure, no readings: reference mirrors C (0, 0) and R
    (s 90 deg, 0) when ``reference_rows``, 5 azimuth and 5 pitch mirrors
    (:func:`montecarlo.seed003.procedure.procedure_layout`)."""
    from montecarlo.seed003.procedure import PAPER_AZIMUTHS, PAPER_PITCHES, procedure_layout

    az, el, sets = procedure_layout(PAPER_AZIMUTHS if azimuths is None else azimuths,
                                    PAPER_PITCHES if pitches is None else pitches)
    names = [f"A{i + 1}" for i in range(sets.count("azimuth"))] + \
        [f"P{i + 1}" for i in range(sets.count("pitch"))]
    kinds = list(sets)
    if reference_rows:
        az = np.concatenate([[0.0, side * math.pi / 2], az])
        el = np.concatenate([[0.0, 0.0], el])
        names, kinds = ["C", "R", *names], ["reference_center", "reference_roll", *kinds]
    zero = np.zeros_like(az)
    return MirrorData(tuple(names), tuple(kinds), az, el, zero, zero.copy())


def report_view(data: MirrorData, angle_sigma: float, side: float = 1.0,
                roll_prior: float = ROLL_PRIOR) -> SystemView:
    """How reports show a diagnosis by the procedure: units, residual axes, Monte Carlo params.

    The Monte Carlo simulates a model's fitted values, the fitted ``ins_roll`` included (as
    unrecorded rolls), and refits that model, ``ins_roll`` with the same ``roll_prior``."""
    k = procedure_data(data).measured
    axes = [("theodolite elevation [deg]", np.degrees(data.theodolite_el[k]), None),
            ("theodolite azimuth [deg]", np.degrees(data.theodolite_az[k]), None),
            ("mirror (file order)", k.astype(float), None)]
    layout = json.dumps(data.layout())

    def study_params(fit: LeastSquaresFit) -> dict[str, object]:
        values = fit.params
        return {"layout": layout, "readings": "reference",
                "roll_mirror": side, "theodolite_sigma": angle_sigma / math.sqrt(2.0),
                "ins_sigma": angle_sigma / math.sqrt(2.0), "mount_roll_sigma": 0.0,
                **{q: float(values.get(q, 0.0)) for q in ("axis_az", "axis_el",
                                                          "reference_az", *TRUTH_KEYS)},
                "ins_roll": json.dumps({q: float(values[q]) for q in roll_parameters(data)
                                        if q in values}) if ROLL in fit.effects else "",
                "roll_prior": roll_prior,
                "fit_effects": ",".join(e for e in fit.effects[1:] if not is_outlier(e)),
                "diagnose": 0}

    return SystemView("collimation", display_unit, "arcsec", ARCSEC,
                      ("relative heading", "relative pitch"),
                      lambda params: raw_residuals(data, params, side), axes,
                      "discrepancy_collimation", study_params,
                      lambda name: ("arcsec", ARCSEC) if name == "reference_az"
                      else display_unit(name))
