"""Studies of the discrepancy workflow: simulated data sets, fitted or diagnosed, per trial.

Two study systems (``discrepancy_ground``, ``discrepancy_collimation``) simulate measured-like
data sets on a layout from a truth, fit a model or run the whole diagnosis, and score it
(:func:`montecarlo.discrepancy.design.score_trials`). They serve the acceptance studies and the
Monte Carlo gap of a diagnosis report (:func:`monte_carlo_gap`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy import procedure_effects as pe
from montecarlo.discrepancy.candidate_tests import ALPHA
from montecarlo.discrepancy.design import TRIAL_METRICS, inject_at_mdb, score_trials
from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.problem import Problem
from montecarlo.discrepancy.view import SystemView
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.engine.system import Metric
from montecarlo.geometry.camera import Camera
from montecarlo.io.collimation_csv import MirrorData, procedure_data
from montecarlo.io.ground_csv import GroundData
from montecarlo.seed003.model import Noise
from montecarlo.systems.params import ParamSystem, study_params
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]

# --------------------------------------------------------------------------- ground

GROUND_DEFAULTS: dict[str, float | int | str] = {
    "fov_yaw": math.radians(90.0), "fov_pitch": math.radians(90.0), "n_x": 512, "n_z": 512,
    "pixel_sigma": 0.3, "survey_sigma": 0.01, "layout": "",
    **ge.DEFAULT_MOUNTING,
    **dict.fromkeys(ge.TRUTH_KEYS, 0.0),
    "refraction_k": ge.STANDARD_REFRACTION,
    "extra_truth": "",
    "fit_effects": "", "diagnose": 0, "expected": "", "inject_mdb": 0.0, "alpha": ALPHA,
    "n_outliers": 0, "outlier_size": 0.0,
}
"""Defaults of :func:`run_ground_trials` (SI units, radians); see its docstring."""


def default_layout(camera: Camera, mounting: Mapping[str, float]) -> GroundData:
    """The acceptance layout: 6 x 6 targets over 80 % of the field at 50 and 100 m, one hour."""
    return ge.field_layout(camera, mounting, (50.0, 100.0), (6, 6), 0.8, 3600.0, 1, rng=2024)


def run_ground_trials(params: Mapping[str, float | int | str], rng: np.random.Generator,
                      n: int) -> dict[str, FloatArray]:
    """Monte Carlo of the ground diagnosis: simulate data sets, fit or diagnose each.

    Parameters
    ----------
    params : mapping; missing keys take :data:`GROUND_DEFAULTS`.
        ``fov_yaw``, ``fov_pitch`` [rad], ``n_x``, ``n_z`` [px]: camera (seed 000's 90 deg,
        512 px). ``pixel_sigma`` [px] (0.3), ``survey_sigma`` [m] (0.01): noise.
        ``layout`` [JSON text]: targets as :meth:`GroundData.layout`; "" for
        :func:`default_layout` at the true mounting. ``psi``, ``theta``, ``gamma`` [rad]: true
        mounting (30, 20, 10 deg). Every candidate parameter (``k1``, ``p1``, ``p2``, ``c_x``
        [px], ``c_z`` [px], ``s``, ``a``, ``rho`` [rad], ``s_h``, ``b_x``, ``b_y``, ``b_z``,
        ``l_x``, ``l_y``, ``l_z`` [m], ``dk``, ``w_psi``, ``w_theta``, ``w_gamma``
        [rad/s]): its true value (0; ``dk`` [1] is the true refraction coefficient's
        difference from ``refraction_k``). ``refraction_k`` [1] (0.13): the standard
        coefficient of refraction, in the base model of the fit and in the simulated data
        with earth curvature (:func:`montecarlo.discrepancy.ground_effects.apparent_height_shift`).
        ``extra_truth`` [JSON text]: further true parameters, e.g. session shifts [rad].
        ``fit_effects`` [text]: comma-separated effects fitted for ``chi2`` .. ``rms`` ("":
        the base model). ``diagnose`` [0/1]: also run the whole DIA diagnosis. ``expected``
        [text]: the effect injected, for scoring. ``inject_mdb`` [1]: if > 0, ``expected`` is
        injected at this multiple of its design MDB along its default direction (replacing its
        values above); ``expected`` may list several effects, separated by commas (each
        injected in turn, given the ones before). ``alpha`` [1]: significance (0.01).
        ``n_outliers`` [count] (0): targets whose image point is moved by ``outlier_size``
        [multiples of ``pixel_sigma``] in a random direction (scored by ``outliers_found``
        and ``clean_flagged``).
    rng : numpy Generator, the only source of randomness.
    n : number of simulated data sets.

    Returns
    -------
    dict of metric -> ndarray (n,), float64 (NaN where not applicable):
        ``chi2``, ``chi2_red``, ``p_value`` [1], ``rms`` [px]: residual statistic of the
        ``fit_effects`` model (rms over both coordinates of all observations).
        With ``diagnose``: ``detected``, ``named_any`` [0/1]; ``n_named`` [count];
        ``named_expected`` [0/1] (the expected effect named), ``named_expected_or_group``
        [0/1] (named or in a named effect's confounded group); ``named_watched`` [0/1]
        (refraction named: k differs from the standard); ``expected_within_2sigma`` [1] (fraction of
        its parameters within 2 sigma of the truth, when it is named);
        ``expected_all_within_2sigma`` [0/1]; ``chi2_red_after`` [1] and
        ``chi2_red_after_in_band`` [0/1] (inside the central 99 % band of chi2(dof)/dof).
    """
    unknown = set(params) - set(GROUND_DEFAULTS)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}")
    p = {**GROUND_DEFAULTS, **params}
    camera, layout, truth = _ground_design(p)
    sigma, survey = float(p["pixel_sigma"]), float(p["survey_sigma"])
    k_std = float(p["refraction_k"])
    alpha = float(p["alpha"])
    expected = str(p["expected"])
    effects = tuple(e for e in str(p["fit_effects"]).split(",") if e.strip())
    effects = tuple(e.strip() for e in effects)
    truth = _inject(lambda tr: ge.exact_problem(layout, camera, tr, sigma, survey, k_std),
                    truth, p)
    count, size = int(p["n_outliers"]), float(p["outlier_size"]) * sigma

    def spoil(data: GroundData, g: np.random.Generator) -> tuple[GroundData, set[str]]:
        rows = g.choice(data.n, count, replace=False)
        pixels = data.pixels.copy()
        pixels[rows] += size * _directions(g, count)
        ids = {ge.observations(data)[r][0] for r in rows}
        return dataclasses.replace(data, pixels=pixels), ids

    return score_trials(
        lambda g: ge.simulate(layout, camera, truth, sigma, survey, g, k_std),
        lambda data: ge.ground_problem(data, camera, sigma, survey, k_std),
        lambda data, fit: float(np.sqrt(np.mean(
            ge.raw_residuals(data, camera, fit.params, k_std) ** 2))),
        truth, effects, int(p["diagnose"]), expected, alpha, rng, n,
        watched=("refraction",), spoil=spoil if count else None)


def _ground_design(p: Mapping[str, Any]) -> tuple[Camera, GroundData, dict[str, float]]:
    """Camera, target layout and truth (before any injection) of ground parameters ``p``."""
    camera = Camera(float(p["fov_yaw"]), float(p["fov_pitch"]), float(p["n_x"]),
                    float(p["n_z"]))
    truth = {k: float(p[k]) for k in ("psi", "theta", "gamma", *ge.TRUTH_KEYS)}
    if p["extra_truth"]:
        truth.update({k: float(v) for k, v in json.loads(str(p["extra_truth"])).items()})
    layout = (default_layout(camera, truth) if not p["layout"]
              else GroundData.from_layout(str(p["layout"])))
    return camera, layout, truth


def _inject(exact: Any, truth: dict[str, float], p: Mapping[str, Any]) -> dict[str, float]:
    """Each ``expected`` effect whose parameters are all zero in ``truth``, injected at
    ``inject_mdb`` times its design MDB (given the effects injected before it)."""
    multiple = float(p["inject_mdb"])
    wanted = [e.strip() for e in str(p["expected"]).split(",") if e.strip()]
    if multiple > 0 and not wanted:
        raise ValueError("inject_mdb needs an expected effect")
    for e in wanted if multiple > 0 else ():
        if all(truth.get(q, 0.0) == 0.0 for q in exact(truth).effect(e).parameters):
            truth = inject_at_mdb(exact, truth, e, multiple, float(p["alpha"]))
    return truth


def _directions(g: np.random.Generator, count: int) -> FloatArray:
    """``count`` random unit vectors in the plane of an observation's two components."""
    phi = g.uniform(0.0, 2.0 * np.pi, count)
    return np.column_stack([np.cos(phi), np.sin(phi)])


GROUND = ParamSystem(
    name="discrepancy_ground",
    run_trials=run_ground_trials,
    defaults=GROUND_DEFAULTS,
    units={"fov_yaw": "deg", "fov_pitch": "deg", "pixel_sigma": "px", "survey_sigma": "m",
           "psi": "deg", "theta": "deg", "gamma": "deg", "c_x": "px", "c_z": "px",
           "rho": "mrad", "b_x": "m", "b_y": "m", "b_z": "m", "l_x": "m", "l_y": "m",
           "l_z": "m"},
    metrics_=(
        Metric("chi2", "χ² of the fitted model", "1", 1.0),
        Metric("chi2_red", "reduced χ² of the fitted model", "1", 1.0),
        Metric("p_value", "global test p-value", "1", 1.0),
        Metric("rms", "residual RMS", "px", 1.0),
        *(Metric(m, m.replace("_", " "), "1", 1.0) for m in TRIAL_METRICS[4:]),
    ),
    seconds_per_trial=0.05,
    default_block_size=32,
)
"""Study system ``discrepancy_ground``: residual statistics and DIA rates."""


# --------------------------------------------------------------------------- collimation

COLLIMATION_DEFAULTS: dict[str, float | int | str] = {
    "n_azimuth": 7, "n_pitch": 7, "azimuth_span": math.radians(90.0),
    "pitch_span": math.radians(60.0), "layout": "",
    "theodolite_sigma": 2.0 * ARCSEC, "ins_sigma": 2.0 * ARCSEC, "mount_roll_sigma": 0.0,
    "frame_heading": math.radians(30.0),
    **dict.fromkeys(ce.TRUTH_KEYS, 0.0),
    "fit_effects": "", "diagnose": 0, "expected": "", "inject_mdb": 0.0, "alpha": ALPHA,
    "n_outliers": 0, "outlier_size": 0.0,
    "readings": "absolute", "reference_az": 0.0, "reading_tilt_x": 0.0, "reading_tilt_y": 0.0,
    "roll_mirror": 1.0, "ins_roll": "", "roll_prior": pe.ROLL_PRIOR,
}
"""Defaults of :func:`run_collimation_trials` (SI units, radians); see its docstring."""



def run_collimation_trials(params: Mapping[str, float | int | str],
                           rng: np.random.Generator, n: int) -> dict[str, FloatArray]:
    """Monte Carlo of the collimation diagnosis: simulate calibrations, fit or diagnose each.

    Parameters
    ----------
    params : mapping; missing keys take :data:`COLLIMATION_DEFAULTS`.
        ``n_azimuth``, ``n_pitch`` [count] (7, 7), ``azimuth_span``, ``pitch_span`` [rad]
        (90, 60 deg): seed 003's fixture, or ``layout`` [JSON text] as
        :meth:`MirrorData.layout` ("" for the fixture). ``theodolite_sigma`` [rad] (2
        arc-seconds): each theodolite reading; ``ins_sigma`` [rad] (2 arc-seconds): each INS
        heading, pitch and roll reading; ``mount_roll_sigma`` [rad] (0): true roll spread
        (reported when > 0). The diagnosis is told ``hypot(theodolite_sigma, ins_sigma)`` per
        heading and pitch residual. ``frame_heading`` [rad] (30 deg) and every candidate
        parameter (``axis_az``, ``axis_el``, ``frame_tilt_x``, ``frame_tilt_y``,
        ``ins_heading_bias``, ``ins_pitch_bias``, ``theodolite_c`` [rad];
        ``ins_heading_scale``, ``ins_pitch_scale`` [1]): true values (0).
        ``fit_effects``, ``diagnose``, ``expected``, ``inject_mdb``, ``alpha``: as in
        :func:`run_ground_trials`. ``n_outliers`` [count] (0): mirrors whose theodolite
        reading is off by ``outlier_size`` [multiples of the per-component noise] in a random
        direction.
        ``readings`` [text] ("absolute"): "reference" simulates and diagnoses by seed 003's
        procedure (:mod:`montecarlo.discrepancy.procedure_effects`; ``layout`` "" for its
        paper-like layout with reference rows; ``axis_az``, ``axis_el`` are then base
        parameters, ``reference_az`` [rad] (0) the central mirror's theodolite azimuth of
        relative-reading layouts, ``reading_tilt_x``, ``reading_tilt_y`` [rad] (0) the
        ``reading_model`` candidate, ``roll_mirror`` +1
        right or -1 left; ``frame_heading`` turns the absolute readings; ``ins_roll`` [JSON
        text] ("") the unrecorded rolls, ``{"ins_roll_<pointing>": roll [rad], ...}`` as the
        ``ins_roll`` candidate names them for ``layout``, added to the simulated readings
        (with ``ins_roll`` in ``fit_effects``, the fit refits these rolls only, the others
        held at 0 as a diagnosis holds the ones it found absorbed); ``roll_prior`` [rad] (2
        deg) that candidate's prior, as ``diagnose collimation --roll-sigma-deg``).
    rng : numpy Generator, the only source of randomness.
    n : number of simulated calibrations.

    Returns
    -------
    dict of metric -> ndarray (n,), float64: :data:`montecarlo.discrepancy.design.TRIAL_METRICS`
    (``rms`` [rad] of heading and pitch residuals; ``named_watched`` counts
    ``theodolite_collimation`` named).
    """
    unknown = set(params) - set(COLLIMATION_DEFAULTS)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}")
    p = {**COLLIMATION_DEFAULTS, **params}
    if p["readings"] == "reference":
        return _procedure_trials(p, rng, n)
    if p["readings"] != "absolute":
        raise ValueError(f"readings must be 'reference' or 'absolute', not {p['readings']!r}")
    layout, noise, sigma, truth = _collimation_design(p)
    alpha = float(p["alpha"])
    expected = str(p["expected"])
    effects = tuple(e.strip() for e in str(p["fit_effects"]).split(",") if e.strip())
    truth = _inject(lambda tr: ce.exact_problem(layout, tr, sigma), truth, p)
    count, size = int(p["n_outliers"]), float(p["outlier_size"]) * sigma

    def spoil(data: MirrorData, g: np.random.Generator) -> tuple[MirrorData, set[str]]:
        rows = g.choice(len(data.mirror), count, replace=False)
        shift = size * _directions(g, count)
        az, el = data.theodolite_az.copy(), data.theodolite_el.copy()
        az[rows] += shift[:, 0] / np.cos(el[rows])  # a misreading of the theodolite
        el[rows] += shift[:, 1]
        observations = ce.collimation_problem(data, sigma).observations
        ids = {observations[r][0] for r in rows}
        return dataclasses.replace(data, theodolite_az=az, theodolite_el=el), ids

    return score_trials(
        lambda g: ce.simulate(layout, truth, noise, g),
        lambda data: ce.collimation_problem(data, sigma),
        lambda data, fit: float(np.sqrt(np.mean(ce.raw_residuals(data, fit.params) ** 2))),
        truth, effects, int(p["diagnose"]), expected, alpha, rng, n,
        watched=("theodolite_collimation",), spoil=spoil if count else None)


def _collimation_design(p: Mapping[str, Any]) -> tuple[MirrorData, Noise, float, dict[str, float]]:
    """Mirror layout, noise, the sigma the diagnosis is told [rad] and truth (before any
    injection) of collimation parameters ``p`` under absolute readings."""
    layout = (ce.paper_mirrors(int(p["n_azimuth"]), int(p["n_pitch"]), float(p["azimuth_span"]),
                            float(p["pitch_span"]))
              if not p["layout"] else MirrorData.from_layout(str(p["layout"])))
    ins = float(p["ins_sigma"])
    noise = Noise(float(p["theodolite_sigma"]), ins, ins, ins, float(p["mount_roll_sigma"]))
    truth = {k: float(p[k]) for k in ("frame_heading", *ce.TRUTH_KEYS)}
    return layout, noise, math.hypot(noise.theodolite, ins), truth


def _procedure_design(p: Mapping[str, Any]
                      ) -> tuple[MirrorData, Noise, float, dict[str, float], dict[str, float]]:
    """Layout, noise, told sigma [rad], truth (before any injection) and the unrecorded rolls
    of collimation parameters ``p`` under reference readings (seed 003's procedure)."""
    side = float(p["roll_mirror"])
    layout = (pe.paper_layout(side=side) if not p["layout"]
              else MirrorData.from_layout(str(p["layout"])))
    ins = float(p["ins_sigma"])
    noise = Noise(float(p["theodolite_sigma"]), ins, ins, ins, float(p["mount_roll_sigma"]))
    truth = {k: float(p[k]) for k in ("axis_az", "axis_el", "reference_az", *pe.TRUTH_KEYS)}
    rolls = _rolls(str(p["ins_roll"]), layout)
    return layout, noise, math.hypot(noise.theodolite, ins), {**truth, **rolls}, rolls


def exact_design(system: str, params: Mapping[str, Any]
                 ) -> tuple[Callable[[Mapping[str, float]], Problem], dict[str, float]]:
    """The design of a study system's ``run_trials`` parameters, as the MDB injection sees it.

    Returns ``exact(truth)``, the problem of noise-free data of the design generated by a
    truth, and the parameters' truth before any injection (SI): the linearisation point of
    :mod:`montecarlo.discrepancy.identification_rates`.
    """
    if system == GROUND.name:
        p = {**GROUND_DEFAULTS, **params}
        camera, layout, truth = _ground_design(p)
        sigma, survey = float(p["pixel_sigma"]), float(p["survey_sigma"])
        k_std = float(p["refraction_k"])
        return (lambda tr: ge.exact_problem(layout, camera, tr, sigma, survey, k_std)), truth
    p = {**COLLIMATION_DEFAULTS, **params}
    if p["readings"] == "reference":
        layout, _, sigma, truth, _ = _procedure_design(p)
        side, prior = float(p["roll_mirror"]), float(p["roll_prior"])
        return (lambda tr: pe.exact_problem(layout, tr, sigma, side, prior)), truth
    layout, _, sigma, truth = _collimation_design(p)
    return (lambda tr: ce.exact_problem(layout, tr, sigma)), truth


def _procedure_trials(p: Mapping[str, Any], rng: np.random.Generator, n: int
                      ) -> dict[str, FloatArray]:
    """:func:`run_collimation_trials` under ``readings = "reference"``."""
    side = float(p["roll_mirror"])
    layout, noise, sigma, truth, rolls = _procedure_design(p)
    prior = float(p["roll_prior"])
    effects = tuple(e.strip() for e in str(p["fit_effects"]).split(",") if e.strip())
    # a model with ins_roll refits the rolls it was given (a diagnosis fixes the others at 0)
    kept = tuple(rolls) if rolls and pe.ROLL in effects else None
    truth = _inject(lambda tr: pe.exact_problem(layout, tr, sigma, side, prior), truth, p)
    count, size = int(p["n_outliers"]), float(p["outlier_size"]) * sigma
    heading = float(p["frame_heading"])

    def spoil(data: MirrorData, g: np.random.Generator) -> tuple[MirrorData, set[str]]:
        measured = procedure_data(data).measured
        rows = g.choice(measured, count, replace=False)
        shift = size * _directions(g, count)
        az, el = data.theodolite_az.copy(), data.theodolite_el.copy()
        az[rows] += shift[:, 0] / np.cos(el[rows])  # a misreading of the theodolite
        el[rows] += shift[:, 1]
        return (dataclasses.replace(data, theodolite_az=az, theodolite_el=el),
                {data.mirror[r] for r in rows})

    return score_trials(
        lambda g: pe.simulate(layout, truth, noise, g, side, heading),
        lambda data: pe.procedure_problem(data, sigma, side, prior, kept),
        lambda data, fit: float(np.sqrt(np.mean(pe.raw_residuals(data, fit.params, side)
                                                ** 2))),
        truth, effects, int(p["diagnose"]), str(p["expected"]), float(p["alpha"]), rng, n,
        watched=("reading_model",), spoil=spoil if count else None)


def _rolls(text: str, layout: MirrorData) -> dict[str, float]:
    """The ``ins_roll`` parameter of :func:`run_collimation_trials`: roll name -> value [rad]."""
    if not text:
        return {}
    rolls = json.loads(text)
    if not isinstance(rolls, dict):
        raise ValueError(f"ins_roll: a JSON object of roll name -> value, not {text!r}")
    unknown = set(rolls) - set(pe.roll_parameters(layout))
    if unknown:
        raise ValueError(f"ins_roll: not rolls of this layout's pointings: {sorted(unknown)}")
    return {k: float(v) for k, v in rolls.items()}


COLLIMATION = ParamSystem(
    name="discrepancy_collimation",
    run_trials=run_collimation_trials,
    defaults=COLLIMATION_DEFAULTS,
    units={"azimuth_span": "deg", "pitch_span": "deg", "theodolite_sigma": "arcsec",
           "ins_sigma": "arcsec", "mount_roll_sigma": "deg", "frame_heading": "deg",
           "axis_az": "arcsec", "axis_el": "arcsec", "frame_tilt_x": "arcsec",
           "frame_tilt_y": "arcsec", "ins_heading_bias": "arcsec", "ins_pitch_bias": "arcsec",
           "theodolite_c": "arcsec", "reference_az": "deg", "reading_tilt_x": "arcsec",
           "reading_tilt_y": "arcsec", "roll_prior": "deg"},
    metrics_=(
        Metric("chi2", "χ² of the fitted model", "1", 1.0),
        Metric("chi2_red", "reduced χ² of the fitted model", "1", 1.0),
        Metric("p_value", "global test p-value", "1", 1.0),
        Metric("rms", "residual RMS", "arcsec", 1.0 / ARCSEC),
        *(Metric(m, m.replace("_", " "), "1", 1.0) for m in TRIAL_METRICS[4:]),
    ),
    seconds_per_trial=0.05,
    default_block_size=32,
    limits={"roll_prior": (1e-6, None)},  # positive [deg]: the candidate's range is +-3 times it
)
"""Study system ``discrepancy_collimation``: residual statistics and DIA rates."""


# --------------------------------------------------------------------------- Monte Carlo gap


def monte_carlo_gap(d: Diagnosis, view: SystemView, trials: int = 200, seed: int = 0,
                    n_jobs: int | None = 1) -> dict[str, FloatArray]:
    """Simulated chi2_red of the model before and after, through the study runner.

    Returns ``{"before": (trials,), "after": (trials,)}``: each data set is simulated on the
    measured layout from that model's fitted values and refitted with the same model.
    """
    from montecarlo.systems import study_from_dict

    system = {s.name: s for s in (GROUND, COLLIMATION)}[view.study_system]
    before = study_params(system, view.study_params(d.before))
    after = study_params(system, view.study_params(d.after))
    keys = sorted(set(before) | set(after))
    common = {k: before[k] for k in keys if before.get(k) == after.get(k)}
    sweep = {f"params.{k}": [before[k], after[k]] for k in keys if k not in common}
    raw: dict[str, Any] = {
        "study": {"name": f"diagnose_{view.system}", "system": system.name,
                  "trials": trials, "seed": seed, "per_trial": True},
        "params": common,
    }
    if sweep:
        raw["sweep"] = {"mode": "zip", **sweep}
    study = study_from_dict(raw, f"<diagnose {view.system}>")
    result = run_study(study, RunOptions(n_jobs=n_jobs, progress=False))
    column = "default/chi2_red"
    values = [result.trials[p.index][column].to_numpy(float) for p in study.points]
    return {"before": values[0], "after": values[-1]}
