"""The seed 003 procedure fit on data of a second simulator written apart from this package.

``tests/independent/collimation_second.py`` was written by another author from the seed text and
the brief beside it (``collimation_second_brief.md``: the CSV format, no choice of ours), never
this package's code or docs; its header lists its conventions and scenario numbers, all its own.
Its files are read here exactly as the command line reads them
(:func:`montecarlo.io.collimation_csv.read_mirror_csv`), and fitted with the roll-mirror side the
data support (:func:`montecarlo.seed003.conventions.fit_with_conventions`).

Its default conventions are this package's physically (NED and forward-right-down body axes
against ENU and right-forward-up, the same heading -> pitch -> roll sequence, headings clockwise,
roll right side down, gamma to the right, lambda up, the theodolite's line of sight, a reference
frame built from the INS axes at the two reference mirrors). Its other conventions, and its
hidden errors, are in ``tests/test_collimation_conventions.py``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from montecarlo.discrepancy import procedure_effects as pe
from montecarlo.discrepancy.fit import fit_model
from montecarlo.io.collimation_csv import REFERENCE_SETS, SETS, procedure_data, read_mirror_csv
from montecarlo.seed003.conventions import fit_with_conventions
from montecarlo.seed003.procedure import fit_procedure
from montecarlo.units import ARCSEC
from tests.independent import collimation_second as cs

QUIET = {"theodolite_sigma_arcsec": 0.0, "ins_heading_sigma_arcsec": 0.0,
         "ins_pitch_sigma_arcsec": 0.0, "ins_roll_sigma_arcsec": 0.0}
"""No reading error (the simulator's hidden errors are kept unless a case says otherwise)."""

LEVEL = {"mount_roll_deg": 0.0, "mount_roll_jitter_arcsec": 0.0}
"""A level mount: the INS roll is zero at every pointing."""

EQUAL = {"theodolite_sigma_arcsec": 2.0, "ins_heading_sigma_arcsec": 2.0,
         "ins_pitch_sigma_arcsec": 2.0, "ins_roll_sigma_arcsec": 2.0}
"""2″ on every reading: the package's model has one sigma for every INS reading."""


def simulate(tmp_path, **kwargs):
    """One calibration of the second simulator, read as ``collimation fit`` reads it: the
    :class:`~montecarlo.io.collimation_csv.MirrorData` and the simulator's truth JSON."""
    csv_path, json_path = cs.generate(str(tmp_path), "cal", **kwargs)
    data = read_mirror_csv(csv_path, 2, "gamma and lambda", sets=SETS + REFERENCE_SETS)
    with open(json_path, encoding="utf-8") as f:
        return data, json.load(f)


def convention(truth, name: str) -> str:
    """The value of one of the simulator's conventions (its JSON adds a description)."""
    return str(truth["conventions"][name]).split()[0]


def true_offsets(truth):
    """(gamma, lambda) [arcsec] of the truth JSON: the simulator's gamma > 0 right of the roll
    axis, lambda > 0 above it, as this package's ``axis_az``, ``axis_el``."""
    o = truth["offsets_arcsec"]
    return o["azimuth_offset_gamma"], o["pitch_offset_lambda"]


# --------------------------------------------------------------------------- noise-free

EXACT_CASES = {  # name: (simulator arguments, fit arguments)
    "reference rows, roll recorded (0.4 deg + 20″ jitter), mirror errors 15″":
        ({"include_reference_rows": True, "include_roll": True}, {}),
    "reference rows, level mount, no roll column, mirror errors 15″":
        ({"include_reference_rows": True, "include_roll": False, **LEVEL}, {}),
    "relative, level mount, roll column":
        ({"include_reference_rows": False, "include_roll": True, "mirror_tolerance_arcsec": 0.0,
          **LEVEL}, {}),
    "relative, level mount, no roll column, left":
        ({"include_reference_rows": False, "include_roll": False, "roll_mirror_side": "left",
          "mirror_tolerance_arcsec": 0.0, **LEVEL}, {}),
}


@pytest.mark.parametrize("case", list(EXACT_CASES))
def test_noise_free_files_give_the_true_offsets(tmp_path, case):
    """Without reading errors the fit returns the simulator's offsets to 1e-3″ with a chi-square
    (at 1″ per reading) below 1e-6. The file holds degrees to 8 decimals (rounding up to
    1.8e-5″ per angle) and the fit turns a reading error into an offset error at most a few times
    larger on this layout, so 1e-3″ is loose for a correct reading model and 1000 times below
    what any convention or model difference does (tests/test_collimation_conventions.py: 0.1″
    and more). The mirrors' off-plane errors (15″) are measured by the theodolite, so they are
    no error for the fit with reference rows; relative files assume the roll mirror at exactly
    90° and level, so there the mirror errors are zero (their effect is measured in the
    conventions tests). The mount is level where a roll is not recorded at every pointing (an
    unrecorded roll turns the offsets: :func:`test_an_unrecorded_constant_roll_turns_the_offsets`).
    """
    sim, options = EXACT_CASES[case]
    data, truth = simulate(tmp_path, **QUIET, **sim)
    fit, _, choice = fit_with_conventions(procedure_data(data), sense="same", sigma_ins=ARCSEC,
                                          sigma_theodolite=ARCSEC, before=False, **options)
    gamma, lam = true_offsets(truth)
    assert fit.params["axis_az"] / ARCSEC == pytest.approx(gamma, abs=1e-3)
    assert fit.params["axis_el"] / ARCSEC == pytest.approx(lam, abs=1e-3)
    assert fit.chi2 < 1e-6
    if not sim["include_reference_rows"]:
        assert choice["roll_mirror"].chosen == convention(truth, "roll_mirror_side")


def test_an_unrecorded_constant_roll_turns_the_offsets(tmp_path):
    """A mount rolled by a constant phi (0.4°, the simulator's default) that the file does not
    record, fitted as a level mount: the roll turns the optical axis about the INS axis, and a
    common turn is not seen in the readings (it is what gamma and lambda already describe), so
    the fit returns the offsets turned by phi to first order, gamma cos phi + lambda sin phi and
    lambda cos phi - gamma sin phi (the simulator's own hand derivation, its test
    ``test_fd_absolute_reading_vs_offsets_with_roll``), with chi-square ~0. With reference rows,
    no reading error and no jitter: agreement within 0.05″ (second order: 210″ x 0.007 rad)."""
    data, truth = simulate(tmp_path, **QUIET, include_reference_rows=True, include_roll=False,
                           mount_roll_jitter_arcsec=0.0)
    fit = fit_procedure(procedure_data(data), sigma_ins=ARCSEC, sigma_theodolite=ARCSEC,
                        before=False)
    gamma, lam = true_offsets(truth)
    phi = math.radians(truth["scenario"]["mount_roll_deg"])
    assert fit.params["axis_az"] / ARCSEC == pytest.approx(
        gamma * math.cos(phi) + lam * math.sin(phi), abs=0.05)
    assert fit.params["axis_el"] / ARCSEC == pytest.approx(
        lam * math.cos(phi) - gamma * math.sin(phi), abs=0.05)
    assert abs(fit.params["axis_az"] / ARCSEC - gamma) > 0.5  # the turn is not hidden
    assert fit.chi2 < 1e-3


def test_the_fit_and_the_diagnosis_weigh_relative_readings_alike(tmp_path):
    """The procedure's fit and the diagnosis's base model propagate the reading errors apart
    (the diagnosis by moving the INS's absolute readings, those at the reference mirrors
    included). On the second simulator's relative files (level mount, 2″ on every reading,
    roll mirror on the left; 2.83″ per residual for the diagnosis) they give the same chi-square
    within 5e-3 relative and offsets within 0.01 sigma (the diagnosis evaluates the covariance
    once at its start, the fit at its solution: a second-order change, about 1e-3)."""
    for seed in range(3):
        data, _ = simulate(tmp_path, **EQUAL, **LEVEL, include_reference_rows=False,
                           include_roll=False, roll_mirror_side="left", seed=seed)
        fit = fit_procedure(procedure_data(data), side=-1.0, sigma_ins=2.0 * ARCSEC,
                            sigma_theodolite=2.0 * ARCSEC, before=False)
        base = fit_model(pe.procedure_problem(data, math.hypot(2.0, 2.0) * ARCSEC, -1.0), ())
        assert base.chi2 == pytest.approx(fit.chi2, rel=5e-3)
        for key in ("axis_az", "axis_el"):
            assert abs(base.params[key] - fit.params[key]) < 0.01 * fit.stderr[key]


# --------------------------------------------------------------------------- acceptance

EXACT_ROLL_MIRROR = {"mirror_tolerance_arcsec": 0.0}
"""The roll mirror exactly at 90° and level, as the package takes it in relative files (the
other mirrors' errors go too: the theodolite measures them, so they change nothing)."""

COVERAGE_CASES = {  # name: (simulator arguments, fit arguments)
    "reference rows, roll recorded, 2″":
        ({"include_reference_rows": True, "include_roll": True, **EQUAL}, {}),
    "reference rows, free roll, 2″":
        ({"include_reference_rows": True, "include_roll": False, **EQUAL},
         {"free_roll": True}),
    "relative, roll recorded, exact roll mirror, 2″":
        ({"include_reference_rows": False, "include_roll": True, **EXACT_ROLL_MIRROR, **EQUAL},
         {}),
    "relative, level mount, left, exact roll mirror, 2″":
        ({"include_reference_rows": False, "include_roll": False, "roll_mirror_side": "left",
          **LEVEL, **EXACT_ROLL_MIRROR, **EQUAL}, {}),
    "reference rows, roll recorded, simulator's noise, sigma a posteriori":
        ({"include_reference_rows": True, "include_roll": True}, {"known": False}),
    "relative, level mount, left, roll mirror within 15″, 2″":
        ({"include_reference_rows": False, "include_roll": False, "roll_mirror_side": "left",
          **LEVEL, **EQUAL}, {}),
}
"""Acceptance cases. All keep the simulator's hidden errors (mirror errors within 15″, its
mount roll 0.4° with 20″ jitter) unless an exact roll mirror or a level mount is named. "2″":
every reading errs by 2″, fitted with the known sigmas. The simulator's own reading errors
(INS 8″ heading, 3″ pitch and roll, theodolite 2″) cannot be represented by the package's single
INS sigma; that case is fitted as ``collimation fit`` does without sigma options (one scale, a
posteriori): it fails (:data:`KNOWN_FAILURES`), as does the last case, which keeps the roll
mirror's errors in a relative file (the package takes that mirror at 90° and level)."""

KNOWN_FAILURES = {
    "relative, level mount, left, roll mirror within 15″, 2″":
        "a relative file's roll mirror is taken at 90° and level; its elevation error e (within "
        "15″) moves lambda by about -0.8 e, unseen (tests/test_collimation_conventions.py), so "
        "lambda is within 2 sigma in about half the sets (23 of 50 measured)",
    "reference rows, roll recorded, simulator's noise, sigma a posteriori":
        "one a posteriori scale for INS headings that err by 8″ and pitches by 3″: gamma (read "
        "through the headings) gets too small a sigma, lambda too large a one; measured on 200 "
        "sets, gamma within 2 sigma in 182 (91 %), lambda in 197 (98.5 %)",
}

COVERAGE = 0.9545
"""P(|N(0, 1)| <= 2)."""


def coverage_counts(case: str, n: int, tmp_path, seed: int = 2026) -> tuple[np.ndarray, float]:
    """Of ``n`` calibrations of ``case`` (offsets uniform in 10-600″ with random signs), how many
    have gamma and lambda within 2 sigma of the truth; and the mean reduced chi-square."""
    sim, options = COVERAGE_CASES[case]
    options = dict(options)
    known = options.pop("known", True)
    sigmas = {"sigma_ins": 2.0 * ARCSEC, "sigma_theodolite": 2.0 * ARCSEC} if known else {}
    rng = np.random.default_rng(seed)
    inside = np.zeros(2, int)
    chi2 = []
    for i in range(n):
        gamma, lam = rng.uniform(10.0, 600.0, 2) * rng.choice([-1.0, 1.0], 2)
        data, _ = simulate(tmp_path, **sim, azimuth_offset_arcsec=gamma, pitch_offset_arcsec=lam,
                           seed=seed + i)
        fit, _, _ = fit_with_conventions(procedure_data(data), sense="same", before=False,
                                         **sigmas, **options)
        se = fit.stderr
        for j, (key, true) in enumerate((("axis_az", gamma), ("axis_el", lam))):
            inside[j] += abs(fit.params[key] / ARCSEC - true) <= 2.0 * se[key] / ARCSEC
        chi2.append(fit.chi2_red)
    return inside, float(np.mean(chi2))


def band(n: int, level: float = 0.99) -> tuple[float, float]:
    """Two-sided binomial band [count] around ``COVERAGE`` of ``n`` sets at ``level``."""
    lo, hi = stats.binom.interval(level, n, COVERAGE)
    return lo, hi


@pytest.mark.slow
@pytest.mark.parametrize("case", [
    pytest.param(c, marks=pytest.mark.xfail(strict=True, reason=KNOWN_FAILURES[c]))
    if c in KNOWN_FAILURES else c for c in COVERAGE_CASES])
def test_offsets_within_2_sigma_on_second_simulator_data(tmp_path, case):
    """400 calibrations per case: each offset within 2 sigma in a count inside the two-sided
    99 % binomial band around 95.45 % (370-392 of 400), so that an inflated sigma fails
    as an optimistic one does."""
    n = 400
    inside, chi2 = coverage_counts(case, n, tmp_path)
    lo, hi = band(n)
    print(f"{case}: gamma {inside[0]}/{n}, lambda {inside[1]}/{n} within 2 sigma "
          f"(band {lo:.0f}-{hi:.0f}); mean chi2_red {chi2:.3f}")
    assert lo <= inside.min() and inside.max() <= hi, inside
