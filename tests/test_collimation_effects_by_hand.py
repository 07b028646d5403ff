"""The collimation system of the discrepancy workflow by hand: its layout, residuals, simulator
noise, observation names and what a report hands the study."""

import json
import math

import numpy as np
import pytest

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.io.collimation_csv import MirrorData
from montecarlo.lsq import LeastSquaresFit
from montecarlo.seed003 import model as col
from montecarlo.units import ARCSEC

A = ARCSEC


def test_paper_mirrors_are_seven_and_seven_named_by_set():
    m = ce.paper_mirrors()
    assert m.mirror == tuple(f"A{i}" for i in range(1, 8)) + tuple(f"P{i}" for i in range(1, 8))
    assert m.sets == ("azimuth",) * 7 + ("pitch",) * 7
    np.testing.assert_allclose(np.degrees(m.theodolite_az[:7]), np.arange(7) * 15.0, atol=1e-12)
    np.testing.assert_allclose(np.degrees(m.theodolite_el[7:]), np.arange(1, 8) * 60 / 7,
                               atol=1e-12)
    assert m.ins_az.shape == m.ins_el.shape == (14,)
    assert not m.ins_az.any() and not m.ins_el.any() and m.ins_roll is None
    assert ce.min_mirrors() == 2  # frame heading + 2 + 1 dof = 4 readings
    small = ce.paper_mirrors(2, 2, azimuth_span=0.6, pitch_span=0.4)
    np.testing.assert_allclose(small.theodolite_az, [0.0, 0.6, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(small.theodolite_el, [0.0, 0.0, 0.2, 0.4], atol=1e-15)


def test_mean_heading_is_circular():
    """Headings 179 deg and -179 deg average to 180 deg, not 0."""
    got = ce.mean_heading(np.radians([179.0, -179.0]))
    assert abs(abs(got) - math.pi) < 1e-12
    assert ce.mean_heading(np.radians([10.0, 30.0])) == pytest.approx(math.radians(20.0))


def test_heading_scale_acts_on_the_heading_from_the_reference():
    """Reported heading ``h + s wrap(h - h_ref)``: with h_ref 0.4 rad, a mirror read at heading
    0.4 + d gains s d."""
    layout = ce.paper_mirrors()
    h0, _ = ce.predict_readings({"frame_heading": 0.4}, layout, 0.4)
    h, _ = ce.predict_readings({"frame_heading": 0.4, "ins_heading_scale": 1e-3}, layout, 0.4)
    np.testing.assert_allclose(h - h0, 1e-3 * (h0 - 0.4), atol=1e-15)


def test_raw_residuals_are_reading_minus_model_in_radians():
    """Readings of the model plus 5" on heading and -3" on pitch at every mirror: the raw
    residuals are exactly those, whatever the heading reference (the mean of the readings)."""
    layout = ce.paper_mirrors(3, 3)
    truth = {"frame_heading": 2.0, "axis_az": 100 * A}
    h, p = ce.predict_readings(truth, layout, ce.mean_heading(layout.ins_az))
    data = MirrorData(layout.mirror, layout.sets, layout.theodolite_az, layout.theodolite_el,
                      h + 5 * A, p - 3 * A)
    r = ce.raw_residuals(data, truth)
    assert r.shape == (6, 2)
    np.testing.assert_allclose(r, np.tile([5 * A, -3 * A], (6, 1)), atol=1e-12)
    # the problem whitens them by the sigma given, headings first
    problem = ce.collimation_problem(data, 2 * A)
    assert problem.system == "collimation"
    np.testing.assert_allclose(problem.residuals(truth), np.r_[np.full(6, 2.5), np.full(6, -1.5)],
                               atol=1e-6)
    assert problem.start["frame_heading"] == pytest.approx(2.0, abs=200 * A)


def test_observation_names_tell_repeated_mirrors_apart():
    """A name used once stays; one used in two sets gets its set; one repeated within a set
    gets its row as well. Each observation is a mirror's heading and pitch residual."""
    az = np.zeros(4)
    data = MirrorData(("M", "A", "A", "M"), ("pitch", "azimuth", "pitch", "pitch"), az,
                      az + 0.1, az, az)
    obs = ce.collimation_problem(data, A).observations
    assert [o[0] for o in obs] == ["M/pitch (row 1)", "A/azimuth", "A/pitch",
                                   "M/pitch (row 4)"]
    assert [o[1] for o in obs] == [1, 2, 3, 4]
    assert [o[2] for o in obs] == [(0, 4), (1, 5), (2, 6), (3, 7)]
    assert ce.collimation_problem(ce.paper_mirrors(2, 1), A).observations[0][0] == "A1"


def test_simulated_theodolite_collimation_and_noise():
    """The theodolite with collimation c reads az + c / cos el; each reading's error has the
    spread given (3000 draws per reading: within 4 standard errors, 5.2 %, of it). No roll
    column is written for a level mount without a recorded roll."""
    layout = ce.paper_mirrors()
    c = 20 * A
    exact = ce.simulate(layout, {"theodolite_c": c}, col.Noise(0, 0, 0, 0, 0), 1)
    np.testing.assert_allclose(exact.theodolite_az - layout.theodolite_az,
                               c / np.cos(layout.theodolite_el), atol=1e-15)
    assert exact.ins_roll is None
    n = 3000 // layout.theodolite_az.size + 1
    noise = col.Noise(theodolite=3 * A, ins_heading=5 * A, ins_pitch=7 * A, ins_roll=11 * A,
                      mount_roll=0.01)
    errors = {k: [] for k in ("t_az", "t_el", "h", "p", "roll")}
    rng = np.random.default_rng(5)
    for _ in range(n):
        d = ce.simulate(layout, {}, noise, rng)
        errors["t_az"].append(d.theodolite_az - layout.theodolite_az)
        errors["t_el"].append(d.theodolite_el - layout.theodolite_el)
        errors["h"].append(col.wrap(d.ins_az - layout.theodolite_az))
        errors["p"].append(d.ins_el - layout.theodolite_el)
        errors["roll"].append(d.ins_roll)
    spread = {"t_az": 3 * A, "t_el": 3 * A, "h": 5 * A, "p": 7 * A,
              "roll": math.hypot(0.01, 11 * A)}
    for k, s in spread.items():
        e = np.concatenate(errors[k])
        assert abs(np.std(e) / s - 1) < 4 / math.sqrt(2 * e.size), k
        assert abs(np.mean(e)) < 4 * s / math.sqrt(e.size), k


def test_the_study_a_report_proposes_splits_the_residual_sigma_equally():
    """A residual's sigma combines one theodolite and one INS reading: each gets sigma/sqrt 2
    (RMS, not RSS); the fitted values and the effects fitted beyond the base are passed on."""
    layout = ce.paper_mirrors(3, 3)
    view = ce.report_view(layout, 2 * A)
    fit = LeastSquaresFit(names=("frame_heading", "axis_az", "axis_el", "theodolite_c"),
                          values=np.array([0.5, 10 * A, -20 * A, 0.0]), covariance=np.eye(4),
                          residual=np.zeros(12), jacobian=np.zeros((12, 4)),
                          effects=("frame_heading", "axis_misalignment", "outlier:A1",
                                   "theodolite_collimation"))
    params = view.study_params(fit)
    assert params["theodolite_sigma"] == pytest.approx(math.sqrt(2) * A, rel=1e-15)
    assert params["ins_sigma"] == pytest.approx(math.sqrt(2) * A, rel=1e-15)
    assert params["mount_roll_sigma"] == 0.0 and params["diagnose"] == 0
    assert params["frame_heading"] == 0.5 and params["axis_el"] == -20 * A
    assert params["theodolite_c"] == 0.0
    assert params["fit_effects"] == "axis_misalignment,theodolite_collimation"
    assert (view.system, view.rms_unit, view.rms_scale, view.components) == (
        "collimation", "arcsec", A, ("heading", "pitch"))
    assert view.study_system == "discrepancy_collimation"
    assert view.shift_unit("ins_pitch_scale") == ("ppm", 1e-6)
    data = MirrorData(layout.mirror, layout.sets, layout.theodolite_az, layout.theodolite_el,
                      layout.theodolite_az + 0.5 + 3 * A, layout.theodolite_el)
    np.testing.assert_allclose(ce.report_view(data, 2 * A).raw_residuals({"frame_heading": 0.5}),
                               np.tile([3 * A, 0.0], (6, 1)), atol=1e-12)
    assert json.loads(params["layout"]) == layout.layout()
    assert view.display_unit("axis_az") == ("arcsec", A)
    assert view.display_unit("ins_pitch_scale") == ("ppm", 1e-6)
    assert view.shift_unit("frame_heading") == ("arcsec", A)
    assert view.shift_unit("frame_heading") != view.display_unit("frame_heading")
    assert [a[0] for a in view.axes] == ["theodolite elevation [deg]",
                                         "theodolite azimuth [deg]", "mirror (file order)"]
    np.testing.assert_allclose(view.axes[0][1], np.degrees(layout.theodolite_el))


def test_simulation_is_seeded_and_draws_one_error_per_reading():
    layout = ce.paper_mirrors()
    a, b, c = (ce.simulate(layout, {}, col.Noise(), seed) for seed in (4, 4, 5))
    np.testing.assert_array_equal(a.ins_az, b.ins_az)
    assert not np.array_equal(a.ins_az, c.ins_az)
    for got, true in ((a.theodolite_az, layout.theodolite_az),
                      (a.theodolite_el, layout.theodolite_el),
                      (a.ins_az, layout.theodolite_az), (a.ins_el, layout.theodolite_el)):
        assert np.std(col.wrap(got - true)) > 0.3 * 2 * A  # 14 draws, not one shared
    rolled = ce.simulate(layout, {}, col.Noise(mount_roll=0.01), 4)
    assert np.std(rolled.ins_roll) > 0.003
    read = ce.simulate(layout, {}, col.Noise(ins_roll=11 * A, mount_roll=1e-12), 4)
    assert np.std(read.ins_roll) > 0.3 * 11 * A
    # a recorded roll column stays recorded on a level mount
    recorded = MirrorData(layout.mirror, layout.sets, layout.theodolite_az, layout.theodolite_el,
                          layout.ins_az, layout.ins_el, np.zeros(14))
    assert ce.simulate(recorded, {}, col.Noise(), 4).ins_roll is not None


def test_simulated_heading_scale_is_about_the_mean_true_heading():
    """No reading error, frame heading 0.4, heading scale 1e-3: the true headings are az + 0.4,
    their (circular) mean is ``arg(sum exp(i az)) + 0.4``, so the INS reports
    ``az + 0.4 + 1e-3 (az - arg sum exp(i az))``. The exact problem of a truth has no residual
    at it (without a heading scale: the problem takes its scale reference from the reported
    headings, a constant the frame heading absorbs)."""
    layout = ce.paper_mirrors()
    truth = {"frame_heading": 0.4, "ins_heading_scale": 1e-3}
    d = ce.simulate(layout, truth, col.Noise(0, 0, 0, 0, 0), 1)
    az = layout.theodolite_az
    mean = math.atan2(np.sin(az).sum(), np.cos(az).sum())
    np.testing.assert_allclose(d.ins_az - az - 0.4, 1e-3 * (az - mean), atol=1e-15)
    np.testing.assert_allclose(d.ins_el, layout.theodolite_el, atol=1e-15)
    truth = {"frame_heading": 0.4, "axis_el": 50 * A, "ins_pitch_scale": 1e-4}
    r = ce.exact_problem(layout, truth, 2 * A).residuals(truth)
    assert np.abs(r).max() < 1e-9
    # with a recorded roll column the exact problem's rolls carry no error either
    rolls = MirrorData(layout.mirror, layout.sets, az, layout.theodolite_el, layout.ins_az,
                       layout.ins_el, np.linspace(-0.2, 0.2, az.size))
    truth = {"frame_heading": 0.4, "axis_az": 300 * A, "axis_el": 50 * A}
    assert np.abs(ce.exact_problem(rolls, truth, 2 * A).residuals(truth)).max() < 1e-9


def test_simulated_heading_scale_reference_is_the_mean_true_heading_of_the_rolled_mount():
    """As above with an axis offset (the true heading depends on the elevation) and a rolled
    mount (and on the roll): the reference is the circular mean of the true headings, those
    of the forward model at the true rolls (reported without error)."""
    layout = ce.paper_mirrors()
    geometric = {"frame_heading": 0.4, "axis_az": 600 * A}
    d = ce.simulate(layout, {**geometric, "ins_heading_scale": 1e-3},
                    col.Noise(0, 0, 0, 0, mount_roll=0.3), 6)
    h, _ = col.predict_readings(geometric, layout.theodolite_az, layout.theodolite_el,
                                d.ins_roll)
    mean = math.atan2(np.sin(h).sum(), np.cos(h).sum())
    np.testing.assert_allclose(d.ins_az - h, 1e-3 * (h - mean), atol=1e-15)


def test_simulated_mount_roll_turns_the_offsets():
    """No reading error, rolled mount: a horizontal mirror's pitch is
    ``-(lambda cos phi - gamma sin phi)`` to first order at the roll phi the INS reports."""
    az = np.zeros(500)
    layout = MirrorData(tuple(f"M{i}" for i in range(500)), ("azimuth",) * 500, az, az, az, az)
    g, lam = 200 * A, 100 * A
    d = ce.simulate(layout, {"axis_az": g, "axis_el": lam}, col.Noise(0, 0, 0, 0, 0.3), 2)
    phi = d.ins_roll
    np.testing.assert_allclose(d.ins_el, -(lam * np.cos(phi) - g * np.sin(phi)),
                               atol=3 * (g + lam) ** 2)
    assert np.std(phi) > 0.2
