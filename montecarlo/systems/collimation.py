"""Seed 003 as a study system (``system = "collimation"``): simulate and fit calibrations.

Each trial simulates one calibration on a seed-003-like fixture
(:func:`montecarlo.seed003.model.simulate_readings`) and fits it
(:func:`montecarlo.seed003.fit.fit`). Study-file parameters are those of :data:`DEFAULT_PARAMS`,
each key with its unit suffix, in a ``[params]`` table.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from montecarlo.engine.system import Metric
from montecarlo.seed003.fit import NotSeparable, consistency_angles, fit
from montecarlo.seed003.model import (
    BASE_EFFECTS,
    EFFECTS,
    Noise,
    direction,
    paper_layout,
    parameter_names,
    simulate_readings,
    wrap,
)
from montecarlo.systems.params import ParamSystem, angle_metrics
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]

DEFAULT_PARAMS: dict[str, float | int] = {
    "axis_az": math.radians(0.05),
    "axis_el": math.radians(0.05),
    "frame_heading": math.radians(30.0),
    "frame_tilt_x": 0.0,
    "frame_tilt_y": 0.0,
    "n_azimuth": 5,
    "n_pitch": 5,
    "azimuth_span": math.radians(90.0),
    "pitch_span": math.radians(60.0),
    "theodolite_sigma": 2.0 * ARCSEC,
    "ins_heading_sigma": 2.0 * ARCSEC,
    "ins_pitch_sigma": 2.0 * ARCSEC,
    "ins_roll_sigma": 2.0 * ARCSEC,
    "mount_roll_sigma": 0.0,
    "use_roll": 1,
    "fit_frame_tilt": 0,
    "procedure": 0,
    "reference_rows": 1,
    "roll_mirror_left": 0,
    "free_roll": 0,
    "roll_prior_sigma": math.radians(2.0),
}
"""Defaults of :func:`run_trials` (SI units, radians)."""

METRICS = ("axis_az_error", "axis_el_error", "axis_az_sigma", "axis_el_sigma",
           "axis_az_within_2sigma", "axis_el_within_2sigma", "axis_error_angle",
           "frame_heading_error", "residual_rms_before", "residual_rms_after",
           "residual_rms_ratio", "chi2_red", "consistency_max_after")
"""Names of the per-trial metrics returned by :func:`run_trials`."""


def run_trials(params: Mapping[str, float | int | str], rng: np.random.Generator, n: int,
               reference: bool = False) -> dict[str, FloatArray]:
    """Monte Carlo trials of the seed 003 calibration for the study runner.

    Each trial simulates one calibration (:func:`simulate_readings`) on :func:`paper_layout`
    and fits it (:func:`fit`) with the known residual sigma (:meth:`Noise.residual_sigma`).

    Parameters
    ----------
    params : mapping; missing keys take :data:`DEFAULT_PARAMS`.
        ``axis_az``, ``axis_el`` [rad]: true offsets gamma, lambda (default 0.05 deg each).
        ``frame_heading`` [rad]: INS heading of the theodolite azimuth zero (30 deg).
        ``frame_tilt_x``, ``frame_tilt_y`` [rad]: true tilt of the theodolite frame (0).
        ``n_azimuth``, ``n_pitch`` [count]: mirrors per family (5, 5).
        ``azimuth_span``, ``pitch_span`` [rad]: spread of each family (90 deg, 60 deg).
        ``theodolite_sigma`` [rad]: error of each theodolite reading (2 arc-seconds).
        ``ins_heading_sigma``, ``ins_pitch_sigma``, ``ins_roll_sigma`` [rad]: INS reading
        errors (2 arc-seconds each).
        ``mount_roll_sigma`` [rad]: spread of the true INS roll at the mirrors (0, level mount).
        ``use_roll`` [0/1]: fit with the reported roll (1) or assume roll 0 (0).
        ``fit_frame_tilt`` [0/1]: also fit ``frame_tilt_x``, ``frame_tilt_y``.
        ``procedure`` [0/1]: simulate and fit the paper's procedure instead
        (:func:`_procedure_trials`); with it ``reference_rows``, ``roll_mirror_left``,
        ``free_roll`` [0/1] and ``roll_prior_sigma`` [rad].
    rng : numpy Generator, the only source of randomness.
    n : number of trials.
    reference : with ``procedure``, fit trial by trial (the literal path) instead of the whole
        block at once (:mod:`montecarlo.seed003.batch_fit`, equal to it within the tolerance
        tests/test_collimation_batch.py states).

    Returns
    -------
    dict of metric name -> ndarray, shape (n,), float64, NaN for a trial whose fit failed:
        ``axis_az_error``, ``axis_el_error`` [rad]: fitted minus true gamma, lambda.
        ``axis_az_sigma``, ``axis_el_sigma`` [rad]: their 1-sigma from the fit covariance.
        ``axis_az_within_2sigma``, ``axis_el_within_2sigma`` [0/1]: |error| <= 2 sigma.
        ``axis_error_angle`` [rad]: angle between the fitted and the true optical axis.
        ``frame_heading_error`` [rad]: fitted minus true frame heading.
        ``residual_rms_before``, ``residual_rms_after`` [rad]: RMS of the 2m heading and
        pitch residuals without the offsets (reference terms fitted) and after the full fit.
        ``residual_rms_ratio`` [1]: ``residual_rms_after`` / injected residual noise
        ``sqrt((sigma_h^2 + sigma_p^2) / 2)``; its expectation is about ``sqrt(dof / 2m)``.
        ``chi2_red`` [1]: chi-square per degree of freedom with the injected sigma.
        ``consistency_max_after`` [rad]: largest :func:`consistency_angles` over the mirrors.
    """
    unknown = set(params) - set(DEFAULT_PARAMS)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {sorted(DEFAULT_PARAMS)}")
    p = {**DEFAULT_PARAMS, **params}
    if int(p["procedure"]):
        return _procedure_trials(p, rng, n, reference)
    az, el, _ = paper_layout(int(p["n_azimuth"]), int(p["n_pitch"]), float(p["azimuth_span"]),
                             float(p["pitch_span"]))
    truth = {k: float(p[k]) for k in parameter_names(EFFECTS)}
    noise = Noise(float(p["theodolite_sigma"]), float(p["ins_heading_sigma"]),
                  float(p["ins_pitch_sigma"]), float(p["ins_roll_sigma"]),
                  float(p["mount_roll_sigma"]))
    sim = simulate_readings(truth, az, el, noise, rng, n)
    effects = BASE_EFFECTS + (("frame_misalignment",) if int(p["fit_frame_tilt"]) else ())
    sigma = noise.residual_sigma()
    known_sigma = sigma if min(sigma) > 0 else None
    injected = math.sqrt((sigma[0] ** 2 + sigma[1] ** 2) / 2)
    u_true = direction(truth["axis_az"], truth["axis_el"])

    out = {k: np.full(n, np.nan) for k in METRICS}
    for i in range(n):
        roll = sim["ins_roll"][i] if int(p["use_roll"]) else None
        try:
            f = fit(sim["theodolite_az"][i], sim["theodolite_el"][i], sim["ins_az"][i],
                    sim["ins_el"][i], roll, sigma=known_sigma, effects=effects)
        except NotSeparable:
            continue
        got, se = f.params, f.stderr
        for k in ("axis_az", "axis_el"):
            out[f"{k}_error"][i] = got[k] - truth[k]
            out[f"{k}_sigma"][i] = se[k]
            out[f"{k}_within_2sigma"][i] = float(abs(got[k] - truth[k]) <= 2 * se[k])
        u = direction(got["axis_az"], got["axis_el"])
        out["axis_error_angle"][i] = np.arctan2(np.linalg.norm(np.cross(u, u_true)), u @ u_true)
        out["frame_heading_error"][i] = wrap(got["frame_heading"] - truth["frame_heading"])
        out["residual_rms_before"][i] = np.sqrt(np.mean(f.residuals_before ** 2))
        out["residual_rms_after"][i] = np.sqrt(np.mean(f.residuals ** 2))
        if injected > 0:
            out["residual_rms_ratio"][i] = out["residual_rms_after"][i] / injected
        out["chi2_red"][i] = f.chi2_red
        out["consistency_max_after"][i] = np.max(consistency_angles(
            got, sim["theodolite_az"][i], sim["theodolite_el"][i], sim["ins_az"][i],
            sim["ins_el"][i], sim["ins_roll"][i] if int(p["use_roll"]) else 0.0))
    return out


def _procedure_trials(p: Mapping[str, float | int | str], rng: np.random.Generator, n: int,
                      reference: bool = False) -> dict[str, FloatArray]:
    """Trials of the paper's procedure (:mod:`montecarlo.seed003.procedure`).

    Mirrors: ``n_azimuth`` horizontal ones at ``linspace(-0.4, 0.6, n_azimuth) * azimuth_span``
    (the paper-like -30 ... 45 deg for a 75 deg span), ``n_pitch`` at azimuth 0 and elevations
    ``pitch_span * (1 ... n_pitch) / n_pitch``; central reference mirror at 0, roll mirror at
    +-90 deg. Rolls: ``free_roll`` fits them; else ``use_roll`` 1 records them (absolute with
    reference rows, relative without), 0 assumes a level mount (biased when
    ``mount_roll_sigma`` > 0: the cost of an unrecorded roll). ``frame_tilt_*`` and
    ``fit_frame_tilt`` are not used. Metrics as :func:`run_trials`; ``frame_heading_error`` and
    ``residual_rms_before`` are NaN; ``consistency_max_after`` is the largest angle between a
    corrected reading and the theodolite's relative direction. Without ``reference`` the block
    is simulated and fitted at once (:func:`_procedure_block`) when the reading errors are given.
    """
    from montecarlo.seed003 import procedure as pr
    from montecarlo.seed003 import reference as ref

    span = float(p["azimuth_span"])
    az, el, _ = pr.procedure_layout(np.linspace(-0.4 * span, 0.6 * span, int(p["n_azimuth"])),
                                    float(p["pitch_span"]) * np.arange(1, int(p["n_pitch"]) + 1)
                                    / max(int(p["n_pitch"]), 1))
    side = -1.0 if int(p["roll_mirror_left"]) else 1.0
    free = bool(int(p["free_roll"]))
    noise = Noise(float(p["theodolite_sigma"]), float(p["ins_heading_sigma"]),
                  float(p["ins_pitch_sigma"]), float(p["ins_roll_sigma"]),
                  float(p["mount_roll_sigma"]))
    s_ins = math.sqrt((noise.ins_heading ** 2 + noise.ins_pitch ** 2) / 2)
    given = s_ins > 0 or noise.theodolite > 0
    truth = (float(p["axis_az"]), float(p["axis_el"]))
    if given and not reference:
        return _procedure_block(p, rng, n, az, el, noise, side, free, truth)
    u_true = direction(*truth)
    out = {k: np.full(n, np.nan) for k in METRICS}
    for i in range(n):
        data = pr.simulate_procedure(*truth, az, el, noise, rng, side=side,
                                     frame_heading=float(p["frame_heading"]),
                                     reference_rows=bool(int(p["reference_rows"])),
                                     with_roll=bool(int(p["use_roll"])) and not free)
        try:
            f = pr.fit_procedure(data, side=side, free_roll=free,
                                 roll_sigma=float(p["roll_prior_sigma"]),
                                 sigma_ins=s_ins if given else None,
                                 sigma_theodolite=noise.theodolite if given else None,
                                 before=False)
        except pr.NotDetermined:
            continue
        got, se = f.params, f.stderr
        for j, k in enumerate(("axis_az", "axis_el")):
            out[f"{k}_error"][i] = got[k] - truth[j]
            out[f"{k}_sigma"][i] = se[k]
            out[f"{k}_within_2sigma"][i] = float(abs(got[k] - truth[j]) <= 2 * se[k])
        u = direction(got["axis_az"], got["axis_el"])
        out["axis_error_angle"][i] = np.arctan2(np.linalg.norm(np.cross(u, u_true)), u @ u_true)
        out["residual_rms_after"][i] = np.sqrt(np.mean(f.residuals ** 2))
        injected = math.sqrt(s_ins ** 2 + noise.theodolite ** 2)
        if injected > 0:
            out["residual_rms_ratio"][i] = out["residual_rms_after"][i] / injected
        out["chi2_red"][i] = f.chi2_red
        c_az, c_el, t_az, t_el, _ = pr.corrected_and_theodolite(data, f)
        a, b = ref.direction(c_az, c_el), ref.direction(t_az, t_el)
        out["consistency_max_after"][i] = np.max(np.arctan2(
            np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))
    return out


def _procedure_block(p: Mapping[str, float | int | str], rng: np.random.Generator, n: int,
                     az: FloatArray, el: FloatArray, noise: Noise, side: float, free: bool,
                     truth: tuple[float, float]) -> dict[str, FloatArray]:
    """:func:`_procedure_trials` for a whole block at once (:mod:`montecarlo.seed003.batch_fit`)."""
    from montecarlo.seed003 import batch_fit as bf
    from montecarlo.seed003.procedure import NotDetermined

    s_ins = math.sqrt((noise.ins_heading ** 2 + noise.ins_pitch ** 2) / 2)
    out = {k: np.full(n, np.nan) for k in METRICS}
    data = bf.simulate_block(*truth, az, el, noise, rng, n, side=side,
                             frame_heading=float(p["frame_heading"]),
                             reference_rows=bool(int(p["reference_rows"])),
                             with_roll=bool(int(p["use_roll"])) and not free)
    try:
        f = bf.fit_block(data, side=side, free_roll=free, roll_sigma=float(p["roll_prior_sigma"]),
                         sigma_ins=s_ins, sigma_theodolite=noise.theodolite)
    except NotDetermined:
        return out
    ok = f.ok
    se = np.sqrt(np.diagonal(f.covariance, axis1=1, axis2=2))
    for j, k in enumerate(("axis_az", "axis_el")):
        err = f.values[:, j] - truth[j]
        out[f"{k}_error"] = err
        out[f"{k}_sigma"] = se[:, j]
        out[f"{k}_within_2sigma"] = np.where(ok, (np.abs(err) <= 2 * se[:, j]).astype(float),
                                             np.nan)
    u, u_true = direction(f.values[:, 0], f.values[:, 1]), direction(*truth)
    out["axis_error_angle"] = np.arctan2(np.linalg.norm(np.cross(u, u_true), axis=-1),
                                         u @ u_true)
    out["residual_rms_after"] = np.sqrt(np.mean(f.residuals ** 2, axis=-1))
    injected = math.sqrt(s_ins ** 2 + noise.theodolite ** 2)
    if injected > 0:
        out["residual_rms_ratio"] = out["residual_rms_after"] / injected
    out["chi2_red"] = f.chi2 / f.dof
    out["consistency_max_after"] = np.where(
        ok, np.max(bf.consistency_angles(data, f, side), axis=-1, initial=-np.inf), np.nan)
    return out


COLLIMATION = ParamSystem(
    name="collimation",
    run_trials=run_trials,
    defaults=DEFAULT_PARAMS,
    units={"axis_az": "arcsec", "axis_el": "arcsec", "frame_heading": "deg",
           "frame_tilt_x": "arcsec", "frame_tilt_y": "arcsec", "azimuth_span": "deg",
           "pitch_span": "deg", "theodolite_sigma": "arcsec", "ins_heading_sigma": "arcsec",
           "ins_pitch_sigma": "arcsec", "ins_roll_sigma": "arcsec", "mount_roll_sigma": "deg",
           "roll_prior_sigma": "deg"},
    metrics_=(
        *angle_metrics(("axis_az_error", "axis_el_error", "frame_heading_error"),
                 "fit error", "arcsec", signed=True),
        Metric("axis_error_angle", "angle between fitted and true optical axis", "arcsec",
               1.0 / ARCSEC),
        *angle_metrics(("axis_az_sigma", "axis_el_sigma"), "predicted σ", "arcsec"),
        *angle_metrics(("residual_rms_before", "residual_rms_after", "consistency_max_after"),
                 "residual", "arcsec"),
        Metric("axis_az_within_2sigma", "γ within 2σ (mean = coverage over the fitted trials)",
               "1", 1.0),
        Metric("axis_el_within_2sigma", "λ within 2σ (mean = coverage over the fitted trials)",
               "1", 1.0),
        Metric("residual_rms_ratio", "after-fit residual RMS / injected noise", "1", 1.0),
        Metric("chi2_red", "reduced χ² of the fit", "1", 1.0),
    ),
    seconds_per_trial=0.003,  # the batched fit, studies/collimation_layout.toml: 2.6 ms
    reference_seconds_per_trial=0.1,  # trial by trial: 106 ms
    default_block_size=64,
    limits={"axis_az": (-18000.0, 18000.0), "axis_el": (-18000.0, 18000.0),
            "frame_heading": (-360.0, 360.0), "frame_tilt_x": (-3600.0, 3600.0),
            "frame_tilt_y": (-3600.0, 3600.0), "n_azimuth": (0, 1000), "n_pitch": (0, 1000),
            "azimuth_span": (0.0, 360.0), "pitch_span": (0.0, 89.0),
            **dict.fromkeys(("theodolite_sigma", "ins_heading_sigma", "ins_pitch_sigma",
                             "ins_roll_sigma"), (0.0, 3600.0)),
            "mount_roll_sigma": (0.0, 45.0), "use_roll": (0, 1), "fit_frame_tilt": (0, 1),
            "procedure": (0, 1), "reference_rows": (0, 1), "roll_mirror_left": (0, 1),
            "free_roll": (0, 1), "roll_prior_sigma": (0.01, 45.0)},
    has_reference_path=True,
)
"""Seed 003: autocollimator-INS axis calibration, as a study system."""
