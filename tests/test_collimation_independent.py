"""The seed 003 procedure fit on data of a simulator written blind to it.

``tests/independent/collimation_blind.py`` was written by another author from the seed text and
the CSV format only, never this package's modules, docs or tests; it writes the calibration CSV,
which is read here exactly as the command line reads it. Agreement therefore checks the reading
model itself, not only the fit. Its conventions are its own (NED frame, Z-Y-X attitude, the
roll mirror's side and the azimuth sense as options); the fit runs with the side and sense the
data support (:func:`montecarlo.seed003.conventions.fit_with_conventions`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from montecarlo.discrepancy import procedure_effects as pe
from montecarlo.discrepancy.fit import fit_model
from montecarlo.io.collimation_csv import REFERENCE_SETS, SETS, procedure_data, read_mirror_csv
from montecarlo.seed003.conventions import fit_with_conventions
from montecarlo.seed003.procedure import fit_procedure
from montecarlo.units import ARCSEC
from tests.acceptance import check_coverage, check_not_inflated, slug
from tests.independent import collimation_blind as cb

LAYOUTS = {"paper-like": (4.0, 7.5, 11.0, 14.5, 18.0),
           "pitch to 60": (12.0, 24.0, 36.0, 48.0, 60.0)}

CASES = [  # layout, reference rows, roll ("recorded", "level", "free"), roll mirror side
    ("paper-like", True, "recorded", "right"),
    ("paper-like", False, "level", "right"),
    ("paper-like", True, "free", "right"),
    ("paper-like", False, "recorded", "left"),
    ("pitch to 60", True, "recorded", "left"),
    ("pitch to 60", False, "level", "left"),
    ("pitch to 60", False, "free", "right"),
    ("pitch to 60", True, "level", "right"),
]


def _fit(tmp_path, case, gamma, lam, rng, noise=2.0, mount_roll=1.0):
    """Simulate one calibration blind, read its CSV and fit it [arcsec in, rad out]."""
    layout, rows, roll, side = case
    out, _ = cb.simulate(gamma, lam, roll_mirror_side=side, azimuth_sense="cw",
                         mount_roll_sigma_deg=0.0 if roll == "level" else mount_roll,
                         write_roll=roll == "recorded", reference_rows=rows,
                         theodolite_sigma_arcsec=noise, ins_sigma_arcsec=noise,
                         pitch_elevations_deg=LAYOUTS[layout], rng=rng)
    path = tmp_path / "cal.csv"
    cb.write_csv(path, out)
    data = procedure_data(read_mirror_csv(path, sets=SETS + REFERENCE_SETS))
    sigma = 2.0 * ARCSEC  # the weights; a posteriori sigmas of noise-free data would be zero
    # the prior of the unrecorded rolls states the simulated roll (the default 2 deg prior on a
    # 1 deg roll makes the offsets' sigma conservative, and a two-sided check then fails)
    prior = math.radians(mount_roll if mount_roll > 0.0 else 2.0)
    fit, _, choice = fit_with_conventions(data, sense="same", free_roll=roll == "free",
                                          sigma_ins=sigma, sigma_theodolite=sigma, before=False,
                                          roll_sigma=prior)
    if not rows and noise == 0.0:  # noise-free: the side is decided
        assert choice["roll_mirror"].chosen == side
    return fit


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-{c[1]}-{c[2]}-{c[3]}")
def test_noise_free_independent_data_give_the_offsets(tmp_path, case):
    """Without noise the fit returns the simulator's offsets. The mount rolls 1 deg where every
    roll is recorded (absolute form); elsewhere it is level, because an unrecorded roll (at the
    reference pointings of the relative form, or every roll under ``free_roll``) is fitted under
    a zero-mean prior that pulls it, and the offsets with it, by up to several arc-seconds on the
    paper-like layout. The CSV holds degrees to 17 digits, so the tolerance is far below an
    arc-second; a reading model that differs from the specification (where lambda enters through
    the reference) misses by tens of arc-seconds."""
    rng = np.random.default_rng(11)
    for gamma, lam in ((300.0, -200.0), (-45.0, 580.0)):
        fit = _fit(tmp_path, case, gamma, lam, rng, noise=0.0,
                   mount_roll=1.0 if case[2] == "recorded" and case[1] else 0.0)
        assert fit.params["axis_az"] / ARCSEC == pytest.approx(gamma, abs=0.01)
        assert fit.params["axis_el"] / ARCSEC == pytest.approx(lam, abs=0.01)


def _relative_left(tmp_path, rng):
    """One blind relative file (pitch to 60, level mount, roll mirror on the left, 2″ on every
    reading; offsets uniform in 10-600″ with random signs), read as the command line reads it."""
    gamma, lam = rng.uniform(10.0, 600.0, 2) * rng.choice([-1.0, 1.0], 2)
    out, _ = cb.simulate(gamma, lam, roll_mirror_side="left", azimuth_sense="cw",
                         mount_roll_sigma_deg=0.0, write_roll=False, reference_rows=False,
                         theodolite_sigma_arcsec=2.0, ins_sigma_arcsec=2.0,
                         pitch_elevations_deg=LAYOUTS["pitch to 60"], rng=rng)
    cb.write_csv(tmp_path / "cal.csv", out)
    return read_mirror_csv(tmp_path / "cal.csv", sets=SETS + REFERENCE_SETS)


def _fit_left(mirrors):
    """The procedure's fit on the left side with the known 2″ sigmas."""
    return fit_procedure(procedure_data(mirrors), side=-1.0, sigma_ins=2.0 * ARCSEC,
                         sigma_theodolite=2.0 * ARCSEC, before=False)


def test_relative_readings_fit_with_chi2_near_one_on_independent_data(tmp_path):
    """Relative readings carry the errors of the INS's readings at the two reference mirrors,
    common to the set; the fit must weigh them. 80 sets of the blind simulator (pitch to 60,
    level mount, roll mirror on the left), fitted on that side with the known 2″ sigmas: the
    mean reduced chi-square is 1 within 4 standard errors, sqrt(2 / 17 / 80) each (0.15).
    Leaving those errors out of the fit gave 1.26 on these sets."""
    rng = np.random.default_rng(7)
    chi2 = []
    for _ in range(80):
        chi2.append(_fit_left(_relative_left(tmp_path, rng)).chi2_red)
    assert abs(np.mean(chi2) - 1.0) < 4 * np.sqrt(2 / 17 / 80), np.mean(chi2)


def test_the_fit_and_the_diagnosis_weigh_relative_readings_alike(tmp_path):
    """The procedure's fit and the diagnosis's base model were written apart, each propagating
    the reading errors its own way (the diagnosis by moving the INS's absolute readings, those
    at the reference mirrors included). On the blind simulator's relative files (pitch to 60,
    level mount, left; 2″ each, so 2.83″ per residual for the diagnosis) they give the same
    chi-square and offsets: within 5e-3 relative and 0.01 sigma (the diagnosis evaluates the
    covariance once, at its start, the fit at its solution: a change of second order in the
    offsets, about 1e-3)."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        mirrors = _relative_left(tmp_path, rng)
        fit = _fit_left(mirrors)
        base = fit_model(pe.procedure_problem(mirrors, math.hypot(2.0, 2.0) * ARCSEC, -1.0), ())
        assert base.chi2 == pytest.approx(fit.chi2, rel=5e-3)
        for key in ("axis_az", "axis_el"):
            assert abs(base.params[key] - fit.params[key]) < 0.01 * fit.stderr[key]


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-{c[1]}-{c[2]}-{c[3]}")
def test_offsets_within_2_sigma_on_independent_data(tmp_path, case, figures):
    """200 calibrations per case, 2 arc-second theodolite and INS noise, mount rolling 1 deg
    (1 sigma) unless level; offsets uniform in 10-600 arc-seconds with random signs. The fit's
    sigma is honest if each offset's error is within 2 sigma as often as a normal error's (the
    binomial band of 95.45 % at 200 trials, 90.0-99.5 % at alpha 0.001) and its mean
    (error/sigma)^2 is not below chi-square's 0.001 quantile (sigma not inflated)."""
    rng = np.random.default_rng(2026)
    n = 200
    inside = np.zeros((n, 2), bool)
    z2 = np.zeros(2)
    for i in range(n):
        truth = rng.uniform(10.0, 600.0, 2) * rng.choice([-1.0, 1.0], 2)
        fit = _fit(tmp_path, case, truth[0], truth[1], rng)
        se = fit.stderr
        for j, key in enumerate(("axis_az", "axis_el")):
            z = (fit.params[key] / ARCSEC - truth[j]) / (se[key] / ARCSEC)
            inside[i, j] = abs(z) <= 2.0
            z2[j] += z**2
    coverage = inside.mean(axis=0)
    print(f"{case}: gamma within 2 sigma {coverage[0]:.3f}, lambda {coverage[1]:.3f}")
    for j, key in enumerate(("axis_az", "axis_el")):
        check_coverage(figures, slug(*case, f"{key}_within_2sigma"), int(inside[:, j].sum()), n)
        check_not_inflated(figures, slug(*case, f"{key}_mean_z2"), float(z2[j]), n)
