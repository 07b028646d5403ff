"""Seed 003's procedure (section 3.2) against hand values: the layout, the simulator's reading
errors, the fit's sigmas, degrees of freedom, roll sources and residuals without the offsets."""

import math

import numpy as np
import pytest

from montecarlo.seed003 import procedure as pr
from montecarlo.seed003.model import Noise, wrap
from montecarlo.units import ARCSEC

A = ARCSEC
AZ, EL, SETS = pr.procedure_layout()


def test_paper_like_layout_by_hand():
    """Azimuth mirrors at -30, -15, 15, 30, 45 deg (horizontal), pitch mirrors at azimuth 0 and
    4, 7.5, 11, 14.5, 18 deg; the high layout's pitch mirrors at 12 ... 60 deg."""
    np.testing.assert_allclose(np.degrees(AZ), [-30, -15, 15, 30, 45, 0, 0, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.degrees(EL), [0, 0, 0, 0, 0, 4, 7.5, 11, 14.5, 18], atol=1e-12)
    assert SETS == ("azimuth",) * 5 + ("pitch",) * 5
    _, el, _ = pr.procedure_layout(pitches=pr.HIGH_PITCHES)
    np.testing.assert_allclose(np.degrees(el[5:]), [12, 24, 36, 48, 60], atol=1e-12)
    az, el, sets = pr.procedure_layout(0.2, 0.3)
    assert az.tolist() == [0.2, 0.0] and el.tolist() == [0.0, 0.3]
    assert sets == ("azimuth", "pitch")


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_simulated_reading_errors_have_the_stated_spread(side):
    """No offsets: the INS axis is the optical axis, so the true absolute readings are heading =
    mirror azimuth + frame heading, pitch = elevation, roll = the mount's roll, at the two
    reference mirrors (az_c, 0) and (az_c + s 90 deg, 0) first, then the measured ones. 300
    calibrations x 12 rows = 3600 draws per reading: the sample std within 4 standard errors
    (4.7 %) of the spread given, the mean within 4 of its standard errors."""
    n, az_c, heading0 = 300, 0.3, -1.0
    noise = Noise(theodolite=3 * A, ins_heading=5 * A, ins_pitch=7 * A, ins_roll=11 * A)
    true_az = np.r_[az_c, az_c + side * math.pi / 2, AZ]
    true_el = np.r_[0.0, 0.0, EL]
    rng = np.random.default_rng(7)
    e = {k: [] for k in ("t_az", "t_el", "h", "p", "r")}
    for _ in range(n):
        d = pr.simulate_procedure(0.0, 0.0, AZ, EL, noise, rng, side=side,
                                  frame_heading=heading0, az_center=az_c)
        assert (d.center, d.roll_mirror) == (0, 1)
        e["t_az"].append(wrap(d.theodolite_az - true_az))
        e["t_el"].append(d.theodolite_el - true_el)
        e["h"].append(wrap(d.ins_az - true_az - heading0))
        e["p"].append(d.ins_el - true_el)
        e["r"].append(d.ins_roll)
    for k, s in {"t_az": 3 * A, "t_el": 3 * A, "h": 5 * A, "p": 7 * A, "r": 11 * A}.items():
        x = np.concatenate(e[k])
        assert abs(np.std(x) / s - 1) < 4 / math.sqrt(2 * x.size), k
        assert abs(np.mean(x)) < 4 * s / math.sqrt(x.size), k


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_relative_readings_carry_the_errors_read_at_the_reference_mirrors(side):
    """No offsets, level mount, INS errors only (heading 5″, pitch 7″), readings relative to the
    reference. To first order a horizontal mirror at alpha = az - az_c reads heading error
    e_h - e_hc and pitch error e_p - e_pc cos(alpha) - s e_pr sin(alpha) (the frame built from
    the axes read at C and R): variances 2 sigma_h^2 and 2 sigma_p^2, and two mirrors' heading
    errors share sigma_h^2. 1000 calibrations x 5 horizontal mirrors: each within 4 standard
    errors (variance 2 sqrt(2 / 5000), covariance 2.3 / sqrt(1000) of sigma_h^2)."""
    n, az_c = 1000, 0.3
    noise = Noise(theodolite=0.0, ins_heading=5 * A, ins_pitch=7 * A, ins_roll=0.0)
    rng = np.random.default_rng(11)
    flat = EL == 0.0
    h, p = [], []
    for _ in range(n):
        d = pr.simulate_procedure(0.0, 0.0, AZ, EL, noise, rng, side=side, az_center=az_c,
                                  reference_rows=False, with_roll=False)
        h.append(wrap(d.ins_az - (AZ - az_c))[flat])
        p.append(d.ins_el[flat])
    h, p = np.array(h), np.array(p)
    assert abs(np.var(h) / (2 * (5 * A) ** 2) - 1) < 4 * 2 * math.sqrt(2 / h.size)
    assert abs(np.var(p) / (2 * (7 * A) ** 2) - 1) < 4 * 2 * math.sqrt(2 / p.size)
    shared = np.mean([np.cov(h[:, i], h[:, j])[0, 1] for i in range(5) for j in range(i)])
    assert abs(shared / (5 * A) ** 2 - 1) < 4 * 2.3 / math.sqrt(n)


def test_relative_readings_of_an_ins_without_offsets_are_the_mirror_angles():
    """Without reference rows the readings are relative to the reference: with no offsets
    heading = az - az_c, pitch = el, roll = the mount's roll (read exactly when the INS has no
    error); no roll column when it is not written."""
    d = pr.simulate_procedure(0.0, 0.0, AZ, EL, Noise(0, 0, 0, 0, mount_roll=0.02), 3,
                              az_center=0.3, reference_rows=False)
    assert d.center is None and d.roll_mirror is None and d.ins_az.size == AZ.size
    np.testing.assert_allclose(wrap(d.ins_az - (AZ - 0.3)), 0.0, atol=1e-14)
    np.testing.assert_allclose(d.ins_el, EL, atol=1e-14)
    assert 0.005 < np.std(d.ins_roll) < 0.05
    d = pr.simulate_procedure(0.0, 0.0, AZ, EL, Noise(), 3, reference_rows=False,
                              with_roll=False)
    assert d.ins_roll is None
    # by default absolute readings in a frame of heading 0: heading = azimuth, the reference
    # mirrors at (0, 0) and (90 deg, 0) first
    d = pr.simulate_procedure(0.0, 0.0, AZ, EL, Noise(0, 0, 0, 0, 0), 3)
    np.testing.assert_allclose(wrap(d.ins_az - np.r_[0.0, math.pi / 2, AZ]), 0.0, atol=1e-14)
    np.testing.assert_allclose(d.ins_el, np.r_[0.0, 0.0, EL], atol=1e-14)


def test_residuals_without_offsets_are_the_first_order_form():
    """Reference rows, level mount recorded (rolls 0), no reading error, gamma = 120",
    lambda = -90": with the offsets held at zero nothing else is fitted, and reading minus model
    is the first-order form (docs/reference/collimation.md, s = +1, all rolls 0):
    heading ``gamma (1 - 1/cos el) + lambda tan el (sin az - cos az)``, pitch
    ``-lambda (1 - cos az - sin az)``, to second order ((|gamma| + |lambda|)^2 = 0.5")."""
    g, lam = 120 * A, -90 * A
    d = pr.simulate_procedure(g, lam, AZ, EL, Noise(0, 0, 0, 0, 0), 0, frame_heading=2.0)
    f = pr.fit_procedure(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    second = (abs(g) + abs(lam)) ** 2
    h = g * (1 - 1 / np.cos(EL)) + lam * np.tan(EL) * (np.sin(AZ) - np.cos(AZ))
    p = -lam * (1 - np.cos(AZ) - np.sin(AZ))
    np.testing.assert_allclose(f.residuals_before[:, 0], h, atol=second)
    np.testing.assert_allclose(f.residuals_before[:, 1], p, atol=second)
    assert np.abs(f.residuals).max() < 1e-6 * A
    assert f.roll_source == "recorded" and f.dof == 2 * AZ.size - 2
    np.testing.assert_array_equal(f.rolls, d.ins_roll)
    assert pr.central_azimuth(d, f) == d.theodolite_az[0]
    assert np.isnan(pr.fit_procedure(d, sigma_ins=2 * A, sigma_theodolite=2 * A,
                                     before=False).residuals_before).all()


def test_sigmas_given_estimated_or_one_missing():
    """Both None: one scale for both, estimated so that chi2 = dof; one given: the other is 0."""
    rng = np.random.default_rng(12)
    d = pr.simulate_procedure(100 * A, 80 * A, AZ, EL, Noise(3 * A, 3 * A, 3 * A, 3 * A, 0),
                              rng, reference_rows=False, with_roll=False)
    f = pr.fit_procedure(d)
    assert f.sigma_source == "a posteriori" and f.sigma_ins == f.sigma_theodolite
    assert f.chi2 == pytest.approx(f.dof, rel=1e-6) and f.dof == 2 * AZ.size - 3
    assert f.roll_source == "assumed zero (level mount)"
    np.testing.assert_array_equal(f.rolls, np.zeros(AZ.size + 2))
    assert pr.central_azimuth(d, f) == f.params["reference_az"]
    given = pr.fit_procedure(d, sigma_ins=4 * A)
    assert (given.sigma_ins, given.sigma_theodolite, given.sigma_source) == (4 * A, 0.0, "given")
    given = pr.fit_procedure(d, sigma_theodolite=4 * A)
    assert (given.sigma_ins, given.sigma_theodolite) == (0.0, 4 * A)


def test_too_few_measured_mirrors_are_counted_in_the_message():
    """At least one degree of freedom: 2 m >= p + 1, so p = 3 (relative readings) and p = 2
    (reference rows) both need 2 measured mirrors."""
    d = pr.simulate_procedure(0.0, 0.0, AZ[:1], EL[:1], Noise(), 0, reference_rows=False,
                              with_roll=False)
    with pytest.raises(pr.NotDetermined, match=r"^1 measured mirrors give 2 readings; 3 "
                                               r"parameters need at least 2 measured mirrors$"):
        pr.fit_procedure(d)
    d = pr.simulate_procedure(0.0, 0.0, AZ[:1], EL[:1], Noise(), 0)
    with pytest.raises(pr.NotDetermined, match=r"^1 measured mirrors give 2 readings; 2 "
                                               r"parameters need at least 2 measured mirrors$"):
        pr.fit_procedure(d, free_roll=True)


def test_mirrors_that_do_not_see_gamma_are_refused_with_the_reason():
    """Enough readings (three mirrors, reference rows: 6 - 2), but horizontal mirrors read
    gamma only at second order: not separable, and the message says what is missing."""
    d = pr.simulate_procedure(3e-3, 3e-3, AZ[:3], EL[:3], Noise(0, 0, 0, 0, 0), 0)
    with pytest.raises(pr.NotDetermined, match=r"^the mirrors do not determine all parameters: "
                                               r"not separable \(gamma needs pitch mirrors, "
                                               r"lambda azimuth mirrors\)$"):
        pr.fit_procedure(d, sigma_ins=2 * A, sigma_theodolite=2 * A)


def test_pitch_reach_is_none_without_pitch_mirrors_or_within_the_highest():
    d = pr.simulate_procedure(100 * A, 400 * A, AZ, EL, Noise(0, 0, 0, 0, 0), 0,
                              reference_rows=False, with_roll=False)
    f = pr.fit_procedure(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    pitch = np.array([s == "pitch" for s in SETS])
    assert pr.pitch_reach(d, f, np.zeros(AZ.size, bool), False, 1.0) is None
    assert pr.pitch_reach(d, f, pitch, False, 1.0, highest=math.radians(20.0)) is None
    # a target the layout already meets: the next whole degree above the top mirror (18 deg)
    se = f.stderr["axis_az"]
    assert pr.pitch_reach(d, f, pitch, False, 1.0, target=2 * se) == pytest.approx(
        math.radians(18.0))


def test_acceptance_trials_report_errors_against_the_truth_drawn():
    """Tiny reading errors (0.01"): each trial's fitted offsets are its drawn truth within
    5 of its sigmas, the sigmas are those of 0.01" readings (below 1": gamma is determined about
    20 times worse than one reading on this layout), and chi2_red is that
    of a correct model (below 10 for 2 to 20 degrees of freedom at 5 sigma)."""
    out = pr.acceptance_trials(3, np.random.default_rng(2), AZ, EL, noise_sigma=0.01 * A)
    assert set(out) == {"axis_az_error", "axis_el_error", "axis_az_sigma", "axis_el_sigma",
                        "chi2_red"}
    for k in ("axis_az", "axis_el"):
        assert out[f"{k}_error"].shape == (3,)
        assert np.all(np.abs(out[f"{k}_error"]) < 5 * out[f"{k}_sigma"])
        assert np.all(out[f"{k}_sigma"] < 1 * A) and np.all(out[f"{k}_sigma"] > 0)
    assert np.all(out["chi2_red"] < 10) and np.all(out["chi2_red"] > 0)
    assert len(pr.ACCEPTANCE_CASES) == 16
    assert pr.ACCEPTANCE_CASES["pitch to 60°, relative, free, left"] == (
        "pitch to 60°", False, "free", -1.0)


@pytest.mark.parametrize(("rows", "roll", "side"), [(True, "recorded", 1.0), (True, "level", 1.0),
                                                    (False, "level", 1.0),
                                                    (False, "recorded", 1.0),
                                                    (True, "recorded", -1.0),
                                                    (False, "recorded", -1.0),
                                                    (False, "level", -1.0)])
def test_corrected_readings_meet_the_mirror_angles(rows, roll, side):
    """No reading error, central mirror at azimuth 0.2, rolled mount where recorded: the
    theodolite's angles relative to the central and the roll mirror are ``(az - 0.2, el)``; the
    readings corrected with the fitted offsets meet them; with the offsets set to zero the
    corrected readings deviate by the first-order form of docs/reference/collimation.md
    (``gamma (1 - 1/cos el) + lambda tan el (sin a - s cos a)``, ``-lambda (1 - cos a - s sin a)``,
    a = az - 0.2, s the side, all rolls 0; second order below (|gamma| + |lambda|)^2 = 0.4")."""
    import dataclasses

    g, lam = 80 * A, 50 * A
    mount = 0.02 if roll == "recorded" else 0.0
    d = pr.simulate_procedure(g, lam, AZ, EL, Noise(0, 0, 0, 0, mount), 9, az_center=0.2,
                              frame_heading=0.7, reference_rows=rows,
                              with_roll=roll == "recorded", side=side)
    f = pr.fit_procedure(d, side=side, sigma_ins=2 * A, sigma_theodolite=2 * A, before=False)
    c_az, c_el, t_az, t_el, rel_roll = pr.corrected_and_theodolite(d, f)
    tol = 1e-3 * A if rows or roll == "level" else 1.0 * A  # fitted reference rolls: a prior
    center = pr.central_azimuth(d, f)
    assert center == pytest.approx(0.2, abs=tol)
    np.testing.assert_allclose(wrap(t_az - (AZ - center)), 0.0, atol=1e-14)
    np.testing.assert_allclose(t_el, EL, atol=1e-14)
    np.testing.assert_allclose(wrap(c_az - t_az), 0.0, atol=tol)
    np.testing.assert_allclose(c_el - t_el, 0.0, atol=tol)
    assert rel_roll.shape == AZ.shape
    if roll == "recorded" and not rows:  # relative readings: the roll read is the relative roll
        np.testing.assert_array_equal(rel_roll, d.ins_roll)
    if roll == "level":
        values = f.values.copy()
        values[:2] = 0.0
        zero = dataclasses.replace(f, values=values)
        c_az, c_el, t_az, t_el, _ = pr.corrected_and_theodolite(d, zero)
        a = AZ - 0.2 if rows else AZ - f.params["reference_az"]
        second = (g + lam) ** 2
        h = g * (1 - 1 / np.cos(EL)) + lam * np.tan(EL) * (np.sin(a) - side * np.cos(a))
        if rows:  # with the reference azimuth fitted, a constant heading shift is absorbed
            np.testing.assert_allclose(wrap(c_az - t_az), h, atol=second)
        np.testing.assert_allclose(c_el - t_el, -lam * (1 - np.cos(a) - side * np.sin(a)),
                                   atol=second)
