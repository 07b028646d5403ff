"""Seed 003's out-of-sample check (section 3.2: "one more set of data ... substituted into the
calculation"): saved offsets applied to a data set, and leave-one-out within one set."""

import math

import numpy as np
import pytest

from montecarlo.seed003 import procedure as pr
from montecarlo.seed003 import verification as vf
from montecarlo.seed003.model import Noise
from montecarlo.units import ARCSEC

A = ARCSEC
AZ, EL, _ = pr.procedure_layout()
OPTIONS = {"side": 1.0, "free_roll": False, "roll_sigma": math.radians(2.0),
           "sigma_ins": 2 * A, "sigma_theodolite": 2 * A}


def test_offsets_left_uncorrected_deviate_by_the_first_order_form():
    """Reference rows, level mount, no reading error, offsets gamma = 100", lambda = -80" not
    applied (0, 0): the corrected reading is the relative reading itself and the theodolite's
    relative angle is the mirror's (az, el), so the deviations are the first-order form of
    docs/reference/collimation.md with every roll 0 and s = +1:
    heading: ``gamma (1 - 1/cos el) + lambda tan el (sin az - cos az)``,
    pitch: ``-lambda (1 - cos az - sin az)``; its error is second order, below
    ``(|gamma| + |lambda|)^2`` = 0.16″ (the deviations reach 21″)."""
    g, lam = 100 * A, -80 * A
    data = pr.simulate_procedure(g, lam, AZ, EL, Noise(0, 0, 0, 0, 0), 1, frame_heading=0.4)
    check = vf.verify(data, 0.0, 0.0, **OPTIONS)
    d_az = g * (1 - 1 / np.cos(EL)) + lam * np.tan(EL) * (np.sin(AZ) - np.cos(AZ))
    d_el = -lam * (1 - np.cos(AZ) - np.sin(AZ))
    second = (abs(g) + abs(lam)) ** 2
    np.testing.assert_allclose(check.deviation_az, d_az, atol=second)
    np.testing.assert_allclose(check.deviation_el, d_el, atol=second)
    assert check.max_deviation == pytest.approx(max(np.abs(d_az).max(), np.abs(d_el).max()),
                                                abs=second)
    assert check.max_deviation > 20 * A and not check.holds
    # the residuals of that fit, reading minus model, are the same deviations per column
    f = vf.apply_offsets(data, 0.0, 0.0, **OPTIONS)
    np.testing.assert_allclose(f.residuals[:, 0], d_az, atol=second)
    np.testing.assert_allclose(f.residuals[:, 1], d_el, atol=second)
    np.testing.assert_array_equal(check.offsets, np.zeros((AZ.size, 2)))
    # the true offsets leave nothing
    check = vf.verify(data, g, lam, **OPTIONS)
    assert check.max_deviation < 1e-6 * A and check.holds
    np.testing.assert_array_equal(check.offsets, np.tile([g, lam], (AZ.size, 1)))


@pytest.mark.parametrize(("rows", "roll", "expected_dof"), [
    (True, "recorded", 20), (False, "level", 19), (True, "free", 20)])
def test_applied_offsets_fit_only_what_belongs_to_the_new_set(rows, roll, expected_dof):
    """10 measured mirrors, 20 readings. With reference rows and recorded rolls nothing is
    fitted (dof 20); relative readings fit the central azimuth (dof 19); free rolls fit one roll
    per pointing (12) against 12 prior pseudo-observations (dof 20 + 12 - 12 = 20). The offsets'
    rows and columns of the covariance are zero, residuals_before NaN; noise-free data at the
    true offsets leave no residual and give back the central mirror's azimuth (0.2 rad)."""
    g, lam = 150 * A, 120 * A
    data = pr.simulate_procedure(g, lam, AZ, EL, Noise(0, 0, 0, 0, 0), 4, az_center=0.2,
                                 reference_rows=rows, with_roll=roll == "recorded")
    f = vf.apply_offsets(data, g, lam, **{**OPTIONS, "free_roll": roll == "free"})
    assert f.dof == expected_dof and f.sigma_source == "given"
    assert (f.sigma_ins, f.sigma_theodolite) == (2 * A, 2 * A)
    assert f.residuals.shape == (AZ.size, 2)
    assert f.values[0] == g and f.values[1] == lam
    assert not f.covariance[:2].any() and not f.covariance[:, :2].any()
    assert np.isnan(f.residuals_before).all() and f.residuals_before.shape == (AZ.size, 2)
    assert np.abs(f.residuals).max() < 1e-6 * A and f.chi2 < 1e-6
    if not rows:
        assert f.params["reference_az"] == pytest.approx(0.2, abs=1e-9)
        assert f.covariance[2, 2] > 0
    assert f.roll_source == {"recorded": "recorded", "level": "assumed zero (level mount)",
                             "free": "fitted (one per pointing)"}[roll]


def test_holds_is_every_deviation_within_15_arcseconds_inclusive():
    """Seed 003's claim: |deviation| <= 15" in heading and pitch (either sign)."""
    claim = 15 * A
    assert abs(pr.CLAIM - claim) < 1e-15 * claim
    ok = vf.Verification(np.array([-claim, 3 * A]), np.array([0.0, claim]), np.zeros((2, 2)))
    assert ok.max_deviation == claim and ok.holds
    for az, el in (([-1.001 * claim, 0.0], [0.0, 0.0]), ([0.0, 0.0], [0.0, -1.001 * claim])):
        bad = vf.Verification(np.array(az), np.array(el), np.zeros((2, 2)))
        assert bad.max_deviation == pytest.approx(1.001 * claim) and not bad.holds


def test_without_row_keeps_the_reference_rows_and_their_roles():
    data = pr.simulate_procedure(0.0, 0.0, AZ[:4], EL[:4], Noise(), 0)  # rows: c, r, 4 mirrors
    out = vf.without_row(data, 3)
    assert out.ins_az.size == 5 and (out.center, out.roll_mirror) == (0, 1)
    for key in ("theodolite_az", "theodolite_el", "ins_az", "ins_el", "ins_roll"):
        np.testing.assert_array_equal(getattr(out, key), np.delete(getattr(data, key), 3))
    # the reference rows shift when a row before them is left out
    moved = pr.ProcedureData(data.theodolite_az, data.theodolite_el, data.ins_az, data.ins_el,
                             None, center=4, roll_mirror=5)
    out = vf.without_row(moved, 1)
    assert (out.center, out.roll_mirror, out.ins_roll) == (3, 4, None)
    apart = pr.ProcedureData(data.theodolite_az, data.theodolite_el, data.ins_az, data.ins_el,
                             None, center=0, roll_mirror=5)
    out = vf.without_row(apart, 3)
    assert (out.center, out.roll_mirror) == (0, 4)
    for row in (4, 5):
        with pytest.raises(ValueError, match=r"^a reference row cannot be left out$"):
            vf.without_row(moved, row)
    relative = pr.ProcedureData(data.theodolite_az, data.theodolite_el, data.ins_az, data.ins_el)
    assert vf.without_row(relative, 5).center is None


def test_leave_one_out_shows_a_blunder_at_its_own_mirror():
    """No reading error except 30" added to one pitch mirror's INS pitch reading, readings
    relative to a reference with the roll mirror on the left (the fits must be told the
    side), level mount: left out, the other nine give the
    true offsets exactly, so that mirror's corrected pitch deviates from
    the theodolite by the 30", its heading by a small fraction of it (the reference azimuth is
    fitted to all ten mirrors, the blunder among them, and the INS's errors at the reference
    pointings correlate the headings with the pitches: 0.07" here, bound 0.1"), and the offsets
    recorded for it are the true ones."""
    g, lam = 200 * A, -150 * A
    data = pr.simulate_procedure(g, lam, AZ, EL, Noise(0, 0, 0, 0, 0), 5, side=-1.0,
                                 reference_rows=False, with_roll=False)
    j = 7  # a pitch mirror (relative readings: no reference rows)
    ins_el = data.ins_el.copy()
    ins_el[j] += 30 * A
    bad = pr.ProcedureData(data.theodolite_az, data.theodolite_el, data.ins_az, ins_el,
                           data.ins_roll, data.center, data.roll_mirror)
    check = vf.leave_one_out(bad, **{**OPTIONS, "side": -1.0})
    assert check.deviation_el[j] == pytest.approx(30 * A, abs=1e-3 * A)
    assert abs(check.deviation_az[j]) < 0.1 * A
    np.testing.assert_allclose(check.offsets[j], [g, lam], atol=1e-4 * A)
    others = np.delete(np.arange(AZ.size), j)
    assert np.all(np.abs(check.offsets[others] - [g, lam]).max(axis=1) > 0.1 * A)
    assert not check.holds
