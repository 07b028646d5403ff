"""Seed 003's procedure as a discrepancy problem, by hand: the candidate effects, the reading
frame and its tilt, the readings the INS reports under each effect, the residual covariance,
the simulator's draws and what a report hands the study, against values worked out in the
docstrings, scipy ``Rotation`` and finite differences written in the tests."""

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.discrepancy import procedure_effects as pe
from montecarlo.discrepancy.fit import FitError
from montecarlo.io.collimation_csv import MirrorData
from montecarlo.lsq import LeastSquaresFit
from montecarlo.seed003.model import Noise, direction
from montecarlo.units import ARCSEC

A = ARCSEC
DEG = math.pi / 180.0
EXACT = Noise(0.0, 0.0, 0.0, 0.0, 0.0)


def small_layout(rows: bool = True, side: float = 1.0) -> MirrorData:
    """Two azimuth mirrors (-30, 45 deg, level) and one pitch mirror (0, 18 deg)."""
    return pe.paper_layout(rows, (-30 * DEG, 45 * DEG), (18 * DEG,), side)


def az_el(v):
    v = np.asarray(v, float)
    return np.arctan2(v[..., 0], v[..., 1]), np.arcsin(v[..., 2] / np.linalg.norm(v, axis=-1))


# --------------------------------------------------------------------------- effects


def test_base_effect_and_candidates():
    """gamma, lambda within +-5 deg, steps 1e-7; relative readings add the central azimuth,
    unbounded. The candidates are the absolute model's but its offsets, and the reading
    model (+-1 deg, arcsec in reports)."""
    b = pe.base_effect(True)
    assert (b.name, b.parameters, b.steps) == ("offsets", ("axis_az", "axis_el"), (1e-7, 1e-7))
    assert b.bounds == ((-5 * DEG, 5 * DEG),) * 2
    r = pe.base_effect(False)
    assert r.parameters == ("axis_az", "axis_el", "reference_az") and r.steps == (1e-7,) * 3
    assert r.bounds == ((-5 * DEG, 5 * DEG),) * 2 + ((-math.inf, math.inf),)
    assert r.name == "offsets"
    assert r.description == "gamma, lambda and the theodolite azimuth of the central mirror [rad]"
    assert b.description == "optical axis vs INS axis: azimuth gamma, elevation lambda [rad]"
    names = [c.name for c in pe.CANDIDATES]
    assert names == ["frame_misalignment", "ins_scale_factor", "ins_bias",
                     "theodolite_collimation", "reading_model"]
    m = pe.READING_MODEL
    assert m.parameters == ("reading_tilt_x", "reading_tilt_y")
    assert m.bounds == ((-DEG, DEG),) * 2 and m.steps == (1e-7,) * 2
    assert m.direction == (1.0, 1.0)
    assert m.description == "tilt of the frame the readings refer to, about its x and y [rad]"
    assert pe.TRUTH_KEYS == ("frame_tilt_x", "frame_tilt_y", "ins_heading_scale",
                             "ins_pitch_scale", "ins_heading_bias", "ins_pitch_bias",
                             "theodolite_c", "reading_tilt_x", "reading_tilt_y")
    assert pe.ROLL == "ins_roll"
    assert math.isclose(pe.ROLL_PRIOR, 2 * DEG, rel_tol=1e-15)
    assert pe.min_mirrors() == 3


def test_roll_effect_one_roll_per_pointing_but_the_centre():
    """Roll parameters: the roll mirror, then the measured mirrors by name; bounds 3 priors,
    steps 1e-6, directions alternating from +1; ``only`` keeps the named ones in order with
    their own signs."""
    layout = small_layout(True)
    names = ("ins_roll_reference_roll", "ins_roll_A1", "ins_roll_A2", "ins_roll_P1")
    assert pe.roll_parameters(layout) == names
    assert pe.roll_parameters(small_layout(False)) == names
    e = pe.roll_effect(layout, 0.01)
    assert e.name == "ins_roll" and e.parameters == names
    assert e.bounds == ((-0.03, 0.03),) * 4 and e.steps == (1e-6,) * 4
    assert e.direction == (1.0, -1.0, 1.0, -1.0)
    assert e.description == ("INS roll not recorded: one roll per pointing (the central one the "
                             "reference) within +-1.72 deg [rad]")  # 3 x 0.01 rad = 1.7189 deg
    d = pe.roll_effect(layout)
    assert d.bounds[0] == pytest.approx((-6 * DEG, 6 * DEG), rel=1e-15)
    assert "+-6 deg" in d.description
    o = pe.roll_effect(layout, 0.01, ["ins_roll_P1", "ins_roll_A2", "nothing"])
    assert o.parameters == ("ins_roll_A2", "ins_roll_P1") and o.direction == (1.0, -1.0)
    assert o.bounds == ((-0.03, 0.03),) * 2 and o.steps == (1e-6,) * 2


def test_roll_offsets_are_zero_at_the_centre_and_where_not_given():
    layout = small_layout(True)
    assert pe._roll_offsets({"axis_az": 1.0}, layout) == 0.0
    got = pe._roll_offsets({"ins_roll_A2": 0.3, "ins_roll_reference_roll": 2}, layout)
    np.testing.assert_array_equal(got, [0.0, 2.0, 0.0, 0.3, 0.0])
    assert got.dtype == float
    batch = pe._roll_offsets({"ins_roll_P1": np.array([[0.1], [0.2]])}, layout)
    np.testing.assert_array_equal(batch, [[0, 0, 0, 0, 0.1], [0, 0, 0, 0, 0.2]])


def test_display_units():
    assert pe.display_unit("reference_az") == ("deg", pytest.approx(DEG, rel=1e-15))
    assert pe.display_unit("ins_roll_A1") == ("deg", pytest.approx(DEG, rel=1e-15))
    assert pe.display_unit("reading_tilt_y") == ("arcsec", A)
    assert pe.display_unit("reading_tilt_x") == ("arcsec", A)
    assert pe.display_unit("ins_pitch_scale") == ("ppm", 1e-6)
    assert pe.display_unit("axis_az") == ("arcsec", A)


# --------------------------------------------------------------------------- reading frame


@pytest.mark.parametrize("t", [(0.3, -0.2), (2e-9, -3e-9), (1e-3, 4e-4), (0.0, 0.7)])
def test_tilt_is_the_rotation_vector_x_y(t):
    """``_tilt(tx, ty)`` is scipy's ``from_rotvec([tx, ty, 0])``, below and above the
    small-angle switch at 1e-8 rad; a batch of tilts gives a batch of matrices."""
    want = Rotation.from_rotvec([t[0], t[1], 0.0]).as_matrix()
    np.testing.assert_allclose(pe._tilt(*t), want, rtol=0, atol=1e-15)
    tx = np.array([t[0], 2 * t[0], 0.5])
    ty = np.array([t[1], -t[1], -0.25])
    want = Rotation.from_rotvec(np.column_stack([tx, ty, 0 * tx])).as_matrix()
    np.testing.assert_allclose(pe._tilt(tx, ty), want, rtol=0, atol=1e-15)


def test_tilt_of_integers_is_the_float_rotation():
    np.testing.assert_allclose(pe._tilt(1, 0), Rotation.from_rotvec([1, 0, 0]).as_matrix(),
                               atol=1e-15)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_relative_readings_of_a_level_reference_are_heading_differences(side):
    """INS level at the centre (heading 0.3) and at the roll mirror (0.3 + s 90 deg): the frame
    R is the level frame turned by 0.3, so a reading is (h - 0.3, p). The reading tilt turns
    the directions by the inverse of ``from_rotvec([tx, ty, 0])`` (scipy)."""
    h = np.array([0.3, 0.3 + side * math.pi / 2, 0.5, -0.4, 0.3])
    p = np.array([0.0, 0.0, 0.0, 0.1, 0.3])
    rh, rp = pe.relative_to_reference(h, p, side)
    np.testing.assert_allclose(rh, [0.2, -0.7, 0.0], atol=1e-14)
    np.testing.assert_allclose(rp, [0.0, 0.1, 0.3], atol=1e-14)
    tilt = (2e-3, -5e-3)
    th, tp = pe.relative_to_reference(h, p, side, tilt)
    local = Rotation.from_rotvec([*tilt, 0.0]).inv().apply(direction(h[2:] - 0.3, p[2:]))
    want_h, want_p = az_el(local)
    np.testing.assert_allclose(th, want_h, atol=1e-14)
    np.testing.assert_allclose(tp, want_p, atol=1e-14)
    # parameters of k models come as (k, 1): one frame per model
    bh, bp = pe.relative_to_reference(np.tile(h, (2, 1)), np.tile(p, (2, 1)), side,
                                      (np.array([[tilt[0]], [0.0]]), np.array([[tilt[1]], [0.0]])))
    np.testing.assert_allclose(bh, [want_h, rh], atol=1e-14)
    np.testing.assert_allclose(bp, [want_p, rp], atol=1e-14)
    # a tilt about x alone, and one about y alone, are applied
    _, xp = pe.relative_to_reference(h, p, side, (0.01, 0.0))
    local = Rotation.from_rotvec([0.01, 0.0, 0.0]).inv().apply(direction(h[2:] - 0.3, p[2:]))
    np.testing.assert_allclose(xp, az_el(local)[1], atol=1e-14)
    yh, _ = pe.relative_to_reference(h, p, side, (0.0, 0.01))
    local = Rotation.from_rotvec([0.0, 0.01, 0.0]).inv().apply(direction(h[2:] - 0.3, p[2:]))
    np.testing.assert_allclose(yh, az_el(local)[0], atol=1e-14)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_reference_tilt_of_pitched_reference_pointings(side):
    """Centre read at heading h0 and pitch p0, the roll mirror level at h0 + s 90 deg: R is
    the level frame of h0 turned about its x axis by p0, ``R^T L = R_x(-p0)``, whose rotation
    vector's x component (antisymmetric part) is ``-sin p0``. The centre level and the roll
    mirror pitched by p1: ``x_R = s direction(h0 + s 90, p1)``, ``R^T L = R_y(s p1)``: y
    component ``s sin p1``."""
    h0, p0, p1 = 0.4, 0.02, -0.03
    h = np.array([h0, h0 + side * math.pi / 2, 0.9])
    tx, ty = pe.reference_tilt(h, np.array([p0, 0.0, 0.1]), side)
    assert tx == pytest.approx(-math.sin(p0), rel=1e-12) and ty == pytest.approx(0.0, abs=1e-15)
    tx, ty = pe.reference_tilt(h, np.array([0.0, p1, 0.1]), side)
    assert tx == pytest.approx(0.0, abs=1e-15)
    assert ty == pytest.approx(side * math.sin(p1), rel=1e-12)
    bx, by = pe.reference_tilt(np.tile(h, (2, 1)), np.array([[p0, 0, 0], [0, p1, 0]]), side)
    np.testing.assert_allclose(bx, [-math.sin(p0), 0.0], atol=1e-15)
    np.testing.assert_allclose(by, [0.0, side * math.sin(p1)], atol=1e-15)


# --------------------------------------------------------------------------- reported readings


def test_pointings_of_relative_readings_put_the_reference_at_its_azimuth():
    """Without reference rows the pointings are [centre (a, 0), roll mirror (a + s 90, 0),
    measured...]; a batch of central azimuths (k, 1) gives k rows of pointings."""
    layout = small_layout(False)
    for side in (1.0, -1.0):
        az, el, rows = pe._pointings({"reference_az": 0.2}, layout, side)
        np.testing.assert_allclose(az, [0.2, 0.2 + side * math.pi / 2, -30 * DEG, 45 * DEG, 0.0])
        np.testing.assert_allclose(el, [0, 0, 0, 0, 18 * DEG])
        np.testing.assert_array_equal(rows, [0, 1, 2])
    az, el, _ = pe._pointings({"reference_az": np.array([[0.1], [0.2]])}, layout, 1.0)
    assert az.shape == (2, 5)
    np.testing.assert_allclose(az[:, :2], [[0.1, 0.1 + math.pi / 2], [0.2, 0.2 + math.pi / 2]])
    np.testing.assert_allclose(az[:, 2:], np.tile([-30 * DEG, 45 * DEG, 0.0], (2, 1)))
    az, el, rows = pe._pointings({}, small_layout(True, -1.0), 1.0)
    np.testing.assert_allclose(az, [0.0, -math.pi / 2, -30 * DEG, 45 * DEG, 0.0])
    np.testing.assert_array_equal(rows, [0, 1, 2, 3, 4])


def scipy_heading_pitch(axis_az, axis_el, az, el, roll):
    """Heading and pitch of the attitude ``from_euler("ZXY", [-h, p, roll])`` that turns the
    optical axis onto ``direction(az, el)``, found by scipy's least squares on the angles."""
    from scipy.optimize import least_squares

    u = direction(axis_az, axis_el)
    w = direction(az, el)

    def res(x):
        return Rotation.from_euler("ZXY", [-x[0], x[1], roll]).apply(u) - w

    x = least_squares(res, [az, el], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    return x[0], x[1]


def test_reported_attitudes_autocollimate_at_the_given_rolls():
    """Headings and pitches at [C, R, measured...] for offsets and rolls given: those of
    scipy's ``Rotation`` that maps the optical axis onto the mirror normal."""
    layout = small_layout(True)
    g, lam = 300 * A, -200 * A
    rolls = np.array([0.01, -0.02, 0.03, 0.0, -0.01])
    h, p = pe.reported_attitudes({"axis_az": g, "axis_el": lam}, layout, 1.0, rolls)
    for i, (az, el) in enumerate(zip(layout.theodolite_az, layout.theodolite_el, strict=True)):
        wh, wp = scipy_heading_pitch(g, lam, az, el, rolls[i])
        assert h[i] == pytest.approx(wh, abs=1e-12) and p[i] == pytest.approx(wp, abs=1e-12)
    # the ins_roll candidate adds to the rolls given, pointing by pointing
    h2, p2 = pe.reported_attitudes({"axis_az": g, "axis_el": lam, "ins_roll_A2": 0.05},
                                   layout, 1.0, rolls)
    wh, wp = scipy_heading_pitch(g, lam, 45 * DEG, 0.0, 0.05)
    assert h2[3] == pytest.approx(wh, abs=1e-12) and p2[3] == pytest.approx(wp, abs=1e-12)
    np.testing.assert_array_equal(np.delete(h2, 3), np.delete(h, 3))


def test_recorded_rolls_and_a_level_mount():
    """With reference rows the recorded absolute rolls of the rows are used; with no roll
    column, zero rolls."""
    layout = small_layout(True)
    g, lam = 300 * A, -200 * A
    rolls = np.array([0.01, -0.02, 0.03, 0.0, -0.01])
    data = dataclasses.replace(layout, ins_roll=rolls)
    h, p = pe.reported_attitudes({"axis_az": g, "axis_el": lam}, data)
    for i in (0, 2, 4):
        wh, wp = scipy_heading_pitch(g, lam, layout.theodolite_az[i], layout.theodolite_el[i],
                                     rolls[i])
        assert h[i] == pytest.approx(wh, abs=1e-12) and p[i] == pytest.approx(wp, abs=1e-12)
    h0, p0 = pe.reported_attitudes({"axis_az": g, "axis_el": lam}, layout)
    wh, wp = scipy_heading_pitch(g, lam, 0.0, 18 * DEG, 0.0)
    assert h0[4] == pytest.approx(wh, abs=1e-12) and p0[4] == pytest.approx(wp, abs=1e-12)


def test_each_effect_on_the_reported_readings_at_zero_offsets():
    """Zero offsets, level mount: the INS reads the mirror's (az, el). The theodolite
    collimation c lowers the true azimuth by ``c / cos el``; a frame tilt turns the normal by
    ``from_euler("ZXY", [0, tx, ty])``; the heading scale adds ``s (h - h_c)`` wrapped, the
    pitch scale ``s p``, the biases themselves."""
    layout = pe.paper_layout(True, (-30 * DEG, 170 * DEG), (18 * DEG,))
    az, el = layout.theodolite_az, layout.theodolite_el
    h, p = pe.reported_attitudes({}, layout)
    np.testing.assert_allclose(h, az, atol=1e-15)
    np.testing.assert_allclose(p, el, atol=1e-15)
    c = 20 * A
    h, p = pe.reported_attitudes({"theodolite_c": c}, layout)
    np.testing.assert_allclose(h, az - c / np.cos(el), atol=1e-15)
    t = {"frame_tilt_x": 1e-3, "frame_tilt_y": -2e-3}
    h, p = pe.reported_attitudes(t, layout)
    wh, wp = az_el(Rotation.from_euler("ZXY", [0, 1e-3, -2e-3]).apply(direction(az, el)))
    np.testing.assert_allclose(h, wh, atol=1e-14)
    np.testing.assert_allclose(p, wp, atol=1e-14)
    # heading scale about the centre's heading; the centre at 0.5: 170 deg - 0.5 rad wraps
    lay = dataclasses.replace(layout, theodolite_az=layout.theodolite_az + 0.5)
    h, p = pe.reported_attitudes({"ins_heading_scale": 1e-3, "ins_pitch_scale": 2e-3,
                                  "ins_heading_bias": 3e-4, "ins_pitch_bias": -1e-4}, lay)
    d = np.array([0.0, math.pi / 2, -30 * DEG, 170 * DEG, 0.0])
    true_h = (lay.theodolite_az + math.pi) % (2 * math.pi) - math.pi
    np.testing.assert_allclose(h, true_h + 1e-3 * d + 3e-4, atol=1e-14)
    np.testing.assert_allclose(p, el * 1.002 - 1e-4, atol=1e-15)


def test_predicted_readings_of_relative_data_are_heading_differences():
    """Zero offsets, level, central azimuth a: relative heading ``az - a``, pitch el; the
    theodolite collimation changes a reading by ``-c (1 / cos el - 1)``; a reading tilt turns
    it as in :func:`relative_to_reference`."""
    layout = small_layout(False)
    a = 0.25
    h, p = pe.predict_relative({"reference_az": a}, layout, -1.0)
    np.testing.assert_allclose(h, [-30 * DEG - a, 45 * DEG - a, -a], atol=1e-14)
    np.testing.assert_allclose(p, [0.0, 0.0, 18 * DEG], atol=1e-14)
    c = 20 * A
    hc, _ = pe.predict_relative({"reference_az": a, "theodolite_c": c}, layout)
    np.testing.assert_allclose(hc - h, [0, 0, -c * (1 / math.cos(18 * DEG) - 1)], atol=1e-14)
    ht, pt = pe.predict_relative({"reference_az": a, "reading_tilt_x": 1e-3,
                                  "reading_tilt_y": 2e-3}, layout)
    want = az_el(Rotation.from_rotvec([1e-3, 2e-3, 0]).inv().apply(
        direction(h, p)))
    np.testing.assert_allclose(ht, want[0], atol=1e-14)
    np.testing.assert_allclose(pt, want[1], atol=1e-14)


def test_residuals_are_reading_minus_model_with_the_heading_wrapped():
    """Relative readings: the file's readings minus ``(az - a, el)``, the heading wrapped into
    [-pi, pi). Reference rows: the readings relative to the centre's heading."""
    layout = small_layout(False)
    a = 0.25
    ins_az = np.array([-30 * DEG - a + 3 * A, 45 * DEG - a, -a - 2 * math.pi])
    ins_el = np.array([0.0, -4 * A, 18 * DEG + A])
    data = dataclasses.replace(layout, ins_az=ins_az, ins_el=ins_el)
    h, p = pe.observed_relative(data)
    assert h is data.ins_az and p is data.ins_el
    r = pe.raw_residuals(data, {"reference_az": a})
    assert r.shape == (3, 2)
    np.testing.assert_allclose(r, [[3 * A, 0.0], [0.0, -4 * A], [0.0, A]], atol=1e-12)
    rows = small_layout(True)
    ins_az = np.array([0.3, 0.3 + math.pi / 2, -30 * DEG + 0.3 + 5 * A, 45 * DEG + 0.3, 0.3])
    ins_el = np.array([0.0, 0.0, 0.0, 0.0, 18 * DEG - 6 * A])
    data = dataclasses.replace(rows, ins_az=ins_az, ins_el=ins_el)
    h, p = pe.observed_relative(data)
    np.testing.assert_allclose(h, [-30 * DEG + 5 * A, 45 * DEG, 0.0], atol=1e-12)
    np.testing.assert_allclose(p, [0.0, 0.0, 18 * DEG - 6 * A], atol=1e-12)
    np.testing.assert_allclose(pe.raw_residuals(data, {}), [[5 * A, 0], [0, 0], [0, -6 * A]],
                               atol=1e-12)


# --------------------------------------------------------------------------- covariance


def test_residual_covariance_by_hand_for_level_mirrors():
    """Zero offsets, level mount, reference rows, horizontal mirrors at -30 and 45 deg: a
    relative heading is ``(h_k - h_C) - (az_k - az_C)`` (the roll mirror's heading does not
    turn R), so its variance is 4 s^2 and two headings share 2 s^2 (the centre's two
    readings). A relative pitch is ``p_k - cos(az) p_C - s sin(az) p_R`` minus the same of
    the theodolite: variance ``2 s^2 (1 + cos^2 + sin^2) = 4 s^2``, and two pitches share
    ``2 s^2 (cos a cos b + sin a sin b)``; headings and pitches do not correlate."""
    s = 1e-4
    for side in (1.0, -1.0):
        layout = pe.paper_layout(True, (-30 * DEG, 45 * DEG), (), side)
        data = pe.simulate(layout, {}, EXACT, 0, side)
        cov = pe.residual_covariance(data, {}, s, side)
        a, b = -30 * DEG, 45 * DEG
        want = s**2 * np.array([[4, 2, 0, 0], [2, 4, 0, 0],
                                [0, 0, 4, 2 * math.cos(a - b)], [0, 0, 2 * math.cos(a - b), 4]])
        np.testing.assert_allclose(cov, want, atol=1e-9 * s**2)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_residual_covariance_of_relative_readings_by_finite_differences(side):
    """Without reference rows: the file's readings (2 per mirror, the theodolite's 2) and the
    INS's four readings at the reference mirrors, each with sigma s; the Jacobian by one-sided
    differences in this test (step 1e-7), at offsets of about a degree and a central azimuth,
    the reference readings those of the model (the roll mirror on its side)."""
    layout = small_layout(False, side)
    params = {"axis_az": 1.0 * DEG, "axis_el": -0.7 * DEG, "reference_az": 0.3}
    data = pe.simulate(layout, params, EXACT, 0, side)
    s = 2e-5
    d = 1e-7
    base = pe.raw_residuals(data, params, side)
    base = np.concatenate([base[:, 0], base[:, 1]])
    cols = []
    for f in ("ins_az", "ins_el", "theodolite_az", "theodolite_el"):
        for i in range(3):
            v = getattr(data, f).copy()
            v[i] += d
            r = pe.raw_residuals(dataclasses.replace(data, **{f: v}), params, side)
            cols.append((np.concatenate([r[:, 0], r[:, 1]]) - base) / d)
    # the INS's readings at the reference mirrors: az a and a + s 90 deg, level, autocollimated
    # with the offsets (scipy); they enter the model's relative readings
    ref_az = [0.3, 0.3 + side * math.pi / 2]
    hp = [scipy_heading_pitch(params["axis_az"], params["axis_el"], a, 0.0, 0.0) for a in ref_az]
    h = np.concatenate([[hp[0][0], hp[1][0]], np.zeros(3)])
    p = np.concatenate([[hp[0][1], hp[1][1]], np.zeros(3)])
    h[2:], p[2:] = pe.reported_attitudes(params, data, side)[0][2:], \
        pe.reported_attitudes(params, data, side)[1][2:]
    rh, rp = pe.relative_to_reference(h, p, side)
    for which, j in ((0, 0), (0, 1), (1, 0), (1, 1)):
        hh, pp = h.copy(), p.copy()
        (hh if which == 0 else pp)[j] += d
        nh, np_ = pe.relative_to_reference(hh, pp, side)
        cols.append(np.concatenate([nh - rh, np_ - rp]) / d)
    G = np.array(cols).T
    want = s**2 * G @ G.T
    got = pe.residual_covariance(data, params, s, side)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * s**2)


# --------------------------------------------------------------------------- the problem


def test_start_is_the_circular_mean_of_the_azimuth_differences():
    layout = small_layout(False)
    assert pe.start_values(small_layout(True)) == {}
    data = dataclasses.replace(layout, ins_az=layout.theodolite_az - np.radians([179, -179, 180]))
    start = pe.start_values(data)
    assert abs(abs(start["reference_az"]) - math.pi) < 1e-12
    data = dataclasses.replace(layout, ins_az=layout.theodolite_az - np.array([0.1, 0.2, 0.3]))
    assert pe.start_values(data)["reference_az"] == pytest.approx(0.2, abs=1e-3)
    assert isinstance(pe.start_values(data)["reference_az"], float)


@pytest.mark.parametrize("rows", [True, False])
def test_procedure_problem_whitens_with_the_propagated_covariance(rows):
    """The whitened residuals are ``W r`` with ``W C W' = I`` for C the covariance of the
    readings at ``angle_sigma / sqrt 2`` each; the observation of measured mirror j is its
    heading j and pitch m + j; the reading model is unavailable with reference rows."""
    layout = small_layout(rows, -1.0)
    truth = {"axis_az": 300 * A, "axis_el": -200 * A, "reference_az": 0.0}
    data = pe.simulate(layout, truth, Noise(), 3, side=-1.0)
    sigma = 2 * A
    prob = pe.procedure_problem(data, sigma, -1.0, 0.01, ["ins_roll_A2"])
    assert prob.system == "collimation"
    assert prob.base == pe.base_effect(rows)
    assert [c.name for c in prob.candidates] == [c.name for c in pe.CANDIDATES] + ["ins_roll"]
    assert prob.candidates[-1] == pe.roll_effect(data, 0.01, ["ins_roll_A2"])
    assert prob.observations == (("A1", 1, (0, 3)), ("A2", 2, (1, 4)), ("P1", 3, (2, 5)))
    assert prob.start == pe.start_values(data)
    assert ("reading_model" in prob.unavailable) == rows
    if rows:
        assert prob.unavailable["reading_model"] == ("with reference rows the readings are "
                                                     "absolute by definition")
    params = {**truth, "reference_az": prob.start.get("reference_az", 0.0)}
    # the covariance is propagated at the start values (zero offsets)
    cov = pe.residual_covariance(data, pe.start_values(data), sigma / math.sqrt(2), -1.0)
    r = pe.raw_residuals(data, params, -1.0)
    r = np.concatenate([r[:, 0], r[:, 1]])
    w = prob.residuals(params)
    assert w.shape == (6,)
    # the same chi-square as r' C^-1 r (W is the symmetric inverse square root)
    assert w @ w == pytest.approx(r @ np.linalg.solve(cov, r), rel=1e-6)
    batch = prob.residuals({k: np.array([[v], [v]]) for k, v in params.items()})
    np.testing.assert_allclose(batch, [w, w], rtol=1e-12, atol=1e-12)


def test_procedure_problem_defaults():
    layout = small_layout(True)
    data = pe.simulate(layout, {"axis_az": 1e-3}, Noise(), 1)
    prob = pe.procedure_problem(data, 2 * A)
    assert prob.candidates[-1] == pe.roll_effect(data)
    truth = {"axis_az": 1e-3}
    assert np.max(np.abs(prob.residuals(truth))) < 10


def test_exact_problem_has_no_residual_at_the_truth():
    """No reading error, no mount roll, the side and the roll prior passed on."""
    layout = small_layout(False, -1.0)
    truth = {"axis_az": 300 * A, "axis_el": -200 * A, "reference_az": 0.4,
             "ins_pitch_scale": 1e-3, "reading_tilt_x": 1e-3}
    prob = pe.exact_problem(layout, truth, 2 * A, -1.0, 0.02)
    assert np.max(np.abs(prob.residuals(truth))) < 1e-6
    assert prob.candidates[-1].bounds[0] == (-0.06, 0.06)
    prob = pe.exact_problem(small_layout(True), {"axis_az": 1e-3}, 2 * A)
    assert np.max(np.abs(prob.residuals({"axis_az": 1e-3}))) < 1e-6
    assert prob.candidates[-1] == pe.roll_effect(small_layout(True))


# --------------------------------------------------------------------------- simulator


def test_simulated_reference_rows_by_hand():
    """Zero offsets, no error: the INS reads the mirrors' (az, el), turned by the frame heading
    and wrapped; the theodolite reads ``az + c / cos el``, wrapped; the roll column holds the
    mount's rolls. Each error is one draw of the generator per reading, in the order: mount
    rolls, INS headings, INS pitches (one per pointing), theodolite azimuths, elevations (one
    per row), INS rolls (one per pointing)."""
    layout = dataclasses.replace(pe.paper_layout(True, (-30 * DEG, 170 * DEG), (18 * DEG,)),
                                 ins_roll=np.zeros(5))
    az, el = layout.theodolite_az, layout.theodolite_el
    c = 20 * A
    data = pe.simulate(layout, {"theodolite_c": c}, EXACT, 0, frame_heading=0.5)
    wrapped = (az + 0.5 + math.pi) % (2 * math.pi) - math.pi
    np.testing.assert_allclose(data.ins_az, wrapped, atol=1e-14)
    np.testing.assert_allclose(data.ins_el, el, atol=1e-15)
    np.testing.assert_allclose(data.theodolite_az, az + c / np.cos(el), atol=1e-15)
    np.testing.assert_array_equal(data.theodolite_el, el)
    np.testing.assert_array_equal(data.ins_roll, np.zeros(5))
    assert data.mirror == layout.mirror and data.sets == layout.sets
    noise = Noise(theodolite=1e-3, ins_heading=2e-3, ins_pitch=3e-3, ins_roll=4e-3,
                  mount_roll=0.0)
    got = pe.simulate(layout, {}, noise, 7)
    z = np.random.default_rng(7).standard_normal(30)
    n = 5
    np.testing.assert_allclose(got.ins_az, az + 2e-3 * z[n:2 * n], atol=1e-14)
    np.testing.assert_allclose(got.ins_el, el + 3e-3 * z[2 * n:3 * n], atol=1e-14)
    np.testing.assert_allclose(got.theodolite_az, az + 1e-3 * z[3 * n:4 * n], atol=1e-14)
    np.testing.assert_allclose(got.theodolite_el, el + 1e-3 * z[4 * n:5 * n], atol=1e-14)
    np.testing.assert_allclose(got.ins_roll, 4e-3 * z[5 * n:6 * n], atol=1e-15)
    rolled = pe.simulate(layout, {}, Noise(0, 0, 0, 0, 0.02), np.random.default_rng(7))
    np.testing.assert_allclose(rolled.ins_roll, 0.02 * z[:n], atol=1e-15)
    # at zero offsets a roll about the INS axis does not change the heading and pitch read
    np.testing.assert_allclose(rolled.ins_az, az, atol=1e-14)
    without = pe.simulate(pe.paper_layout(True), {}, noise, 7)
    assert without.ins_roll is None
    # with offsets the INS autocollimates at the mount's rolls (scipy)
    g, lam = 300 * A, -200 * A
    rolled = pe.simulate(layout, {"axis_az": g, "axis_el": lam}, Noise(0, 0, 0, 0, 0.02), 7)
    for i in range(n):
        wh, wp = scipy_heading_pitch(g, lam, az[i], el[i], 0.02 * z[i])
        assert rolled.ins_az[i] == pytest.approx(wh, abs=1e-12)
        assert rolled.ins_el[i] == pytest.approx(wp, abs=1e-12)


def test_simulated_relative_readings_by_hand():
    """Without reference rows: relative readings ``(az - a, el)`` of a level mount, the reading
    tilt applied as in :func:`relative_to_reference`, the heading wrapped, no roll column;
    the reference mirrors at ``a`` and ``a + s 90 deg``, which the rolls of the mount turn."""
    layout = pe.paper_layout(False, (-30 * DEG, 170 * DEG), (18 * DEG,))
    a = -0.3
    data = pe.simulate(layout, {"reference_az": a, "reading_tilt_x": 1e-3,
                                "reading_tilt_y": -2e-3}, EXACT, 0, side=-1.0)
    assert data.ins_roll is None
    rel = direction(layout.theodolite_az - a, layout.theodolite_el)
    want_h, want_p = az_el(Rotation.from_rotvec([1e-3, -2e-3, 0]).inv().apply(rel))
    np.testing.assert_allclose(data.ins_az, want_h, atol=1e-14)
    np.testing.assert_allclose(data.ins_el, want_p, atol=1e-14)
    assert np.all(np.abs(data.ins_az) <= math.pi)
    plain = pe.simulate(layout, {"reference_az": a}, EXACT, 0)
    np.testing.assert_allclose(plain.ins_az, [-30 * DEG - a, 170 * DEG - a - 2 * math.pi, -a],
                               atol=1e-14)
    # theodolite readings of relative data are the layout's, wrapped, with c
    c = 30 * A
    withc = pe.simulate(layout, {"reference_az": a, "theodolite_c": c}, EXACT, 0)
    np.testing.assert_allclose(withc.theodolite_az, layout.theodolite_az
                               + c / np.cos(layout.theodolite_el), atol=1e-15)
    np.testing.assert_allclose(withc.ins_az, plain.ins_az, atol=1e-15)
    # a pitch error of the INS at the centre tilts R: the readings move by the tilt
    z = np.random.default_rng(5).standard_normal(21)
    noisy = pe.simulate(layout, {"reference_az": a}, Noise(0, 0, 1e-3, 0, 0), 5)
    h = np.concatenate([[a, a + math.pi / 2], layout.theodolite_az])
    p = np.concatenate([[0, 0], layout.theodolite_el]) + 1e-3 * z[10:15]
    wh, wp = pe.relative_to_reference(h, p, 1.0)
    np.testing.assert_allclose(noisy.ins_el, wp, atol=1e-14)
    np.testing.assert_allclose(noisy.ins_az, wh, atol=1e-14)
    # the theodolite's errors: azimuths then elevations, one draw per row after the INS's
    theo = pe.simulate(dataclasses.replace(layout, ins_roll=np.zeros(3)), {"reference_az": a},
                       Noise(1e-3, 0, 0, 0, 0), 5)
    np.testing.assert_allclose(theo.theodolite_az, layout.theodolite_az + 1e-3 * z[15:18],
                               atol=1e-15)
    np.testing.assert_allclose(theo.theodolite_el, layout.theodolite_el + 1e-3 * z[18:21],
                               atol=1e-15)
    assert theo.ins_roll is None  # relative readings have no roll column


def test_simulator_draws_from_a_fresh_generator_by_default():
    layout = small_layout(True)
    data = pe.simulate(layout, {}, Noise(1e-3, 0, 0, 0, 0))
    assert np.all(data.theodolite_az != layout.theodolite_az)
    assert np.all(np.abs(data.theodolite_az - layout.theodolite_az) < 1e-2)


# --------------------------------------------------------------------------- layout and report


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_paper_layout_by_hand(side):
    lay = pe.paper_layout(True, side=side)
    assert lay.mirror == ("C", "R", "A1", "A2", "A3", "A4", "A5", "P1", "P2", "P3", "P4", "P5")
    assert lay.sets == ("reference_center", "reference_roll", *("azimuth",) * 5,
                        *("pitch",) * 5)
    np.testing.assert_allclose(np.degrees(lay.theodolite_az),
                               [0, side * 90, -30, -15, 15, 30, 45, 0, 0, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.degrees(lay.theodolite_el),
                               [0, 0, 0, 0, 0, 0, 0, 4, 7.5, 11, 14.5, 18], atol=1e-12)
    assert lay.ins_az.shape == lay.ins_el.shape == (12,) and lay.ins_roll is None
    assert not lay.ins_az.any() and not lay.ins_el.any()
    assert lay.ins_az is not lay.ins_el
    rel = pe.paper_layout(False, [0.1], [0.2, 0.3], side)
    assert rel.mirror == ("A1", "P1", "P2") and rel.sets == ("azimuth", "pitch", "pitch")
    np.testing.assert_allclose(rel.theodolite_az, [0.1, 0, 0])
    np.testing.assert_allclose(rel.theodolite_el, [0, 0.2, 0.3])
    assert pe.paper_layout().mirror[:2] == ("C", "R")
    assert pe.paper_layout().theodolite_az[1] == pytest.approx(math.pi / 2)


def test_the_study_a_report_proposes():
    """The study of a diagnosis: the layout, sigma / sqrt 2 for the theodolite and the INS, no
    mount roll, the fitted values (zero where not fitted), the fitted rolls as JSON, the roll
    prior, the effects beyond the base without the outliers; residual axes in degrees and
    the mirror's index; reference_az shifts in arcsec."""
    layout = pe.simulate(small_layout(True, -1.0), {}, EXACT, 0, -1.0)
    view = pe.report_view(layout, 2 * A, -1.0, 0.03)
    names = ("axis_az", "axis_el", "ins_pitch_scale", "ins_roll_A1", "ins_roll_P1")
    fit = LeastSquaresFit(names=names, values=np.array([10 * A, -20 * A, 3e-4, 0.01, -0.02]),
                          covariance=np.eye(5), residual=np.zeros(6), jacobian=np.zeros((6, 5)),
                          effects=("offsets", "ins_scale_factor", "outlier:A2", "ins_roll"))
    params = view.study_params(fit)
    assert json.loads(params["layout"]) == layout.layout()
    assert params["readings"] == "reference" and params["roll_mirror"] == -1.0
    assert params["theodolite_sigma"] == pytest.approx(math.sqrt(2) * A, rel=1e-15)
    assert params["ins_sigma"] == pytest.approx(math.sqrt(2) * A, rel=1e-15)
    assert params["mount_roll_sigma"] == 0.0 and params["diagnose"] == 0
    assert params["axis_az"] == 10 * A and params["axis_el"] == -20 * A
    assert params["ins_pitch_scale"] == 3e-4 and params["reference_az"] == 0.0
    for k in pe.TRUTH_KEYS:
        assert k in params
    assert params["theodolite_c"] == 0.0 and params["reading_tilt_y"] == 0.0
    assert json.loads(params["ins_roll"]) == {"ins_roll_A1": 0.01, "ins_roll_P1": -0.02}
    assert params["roll_prior"] == 0.03
    assert params["fit_effects"] == "ins_scale_factor,ins_roll"
    no_roll = LeastSquaresFit(names=names[:2], values=np.array([1e-4, 0.0]),
                              covariance=np.eye(2), residual=np.zeros(6),
                              jacobian=np.zeros((6, 2)), effects=("offsets",))
    p2 = view.study_params(no_roll)
    assert p2["ins_roll"] == "" and p2["fit_effects"] == ""
    assert set(p2) == set(params)
    assert (view.system, view.rms_unit, view.rms_scale, view.components) == (
        "collimation", "arcsec", A, ("relative heading", "relative pitch"))
    assert view.study_system == "discrepancy_collimation"
    assert view.display_unit("reference_az") == ("deg", pytest.approx(DEG))
    assert view.shift_unit("reference_az") == ("arcsec", A)
    assert view.shift_unit("ins_pitch_scale") == ("ppm", 1e-6)
    labels = [x[0] for x in view.axes]
    assert labels == ["theodolite elevation [deg]", "theodolite azimuth [deg]",
                      "mirror (file order)"]
    np.testing.assert_allclose(view.axes[0][1], [0, 0, 18], atol=1e-12)
    np.testing.assert_allclose(view.axes[1][1], [-30, 45, 0], atol=1e-12)
    np.testing.assert_array_equal(view.axes[2][1], [2.0, 3.0, 4.0])
    assert all(x[2] is None for x in view.axes)
    data = dataclasses.replace(layout, ins_az=layout.ins_az + np.array([0, 0, 2 * A, 0, 0]))
    np.testing.assert_allclose(view.raw_residuals({}), np.zeros((3, 2)), atol=1e-12)
    got = pe.report_view(data, 2 * A, -1.0).raw_residuals({})
    np.testing.assert_allclose(got, [[2 * A, 0], [0, 0], [0, 0]], atol=1e-12)
    # read with the roll mirror on the other side, R is mirrored: so is the heading residual
    np.testing.assert_allclose(pe.report_view(data, 2 * A).raw_residuals({}),
                               [[-2 * A, 0], [0, 0], [0, 0]], atol=1e-12)
    assert pe.report_view(layout, 2 * A).study_params(no_roll)["roll_mirror"] == 1.0
    assert pe.report_view(layout, 2 * A).study_params(no_roll)["roll_prior"] == pe.ROLL_PRIOR


# --------------------------------------------------------------------------- conventions


class FakeFits:
    """Stands in for the problem and the fit: records what each fit is handed and gives back
    the chi-square of a table keyed by (side sign, sense of the turned azimuths)."""

    def __init__(self, table, fail=()):
        self.table, self.fail, self.calls = table, set(fail), []

    @classmethod
    def installed(cls, monkeypatch, table, fail=()):
        """A new stand-in, put in place of ``procedure_problem`` and ``fit_model``."""
        fake = cls(table, fail)
        monkeypatch.setattr(pe, "procedure_problem", fake.problem)
        monkeypatch.setattr(pe, "fit_model", fake.fit)
        return fake

    def problem(self, data, sigma, side, prior):
        a2 = data.theodolite_az[data.mirror.index("A2")]  # mirror A2 at +45 deg
        sense = "same" if a2 > 0 else "opposite"
        self.calls.append((sense, side, sigma, prior))
        return (side, sense)

    def fit(self, key, effects):
        assert effects == ()
        if key in self.fail:
            raise FitError("no")
        return SimpleNamespace(chi2=self.table[key])


def test_choose_conventions_takes_the_smallest_chi2(monkeypatch):
    """Every side under every sense is fitted with the sigma and prior given; the sense is the
    one with the smallest chi-square over the sides, the side the smallest under that sense;
    the data come back with the azimuths turned for an opposite sense."""
    layout = small_layout(False)
    table = {(1.0, "same"): 50.0, (-1.0, "same"): 40.0, (1.0, "opposite"): 3.0,
             (-1.0, "opposite"): 20.0}
    fake = FakeFits.installed(monkeypatch, table)
    turned, sign, choice = pe.choose_conventions(layout, 2 * A, roll_prior=0.02)
    assert sorted(fake.calls) == sorted((sn, sd, 2 * A, 0.02) for sn in ("same", "opposite")
                                        for sd in (1.0, -1.0))
    np.testing.assert_array_equal(turned.theodolite_az, -layout.theodolite_az)
    assert sign == 1.0
    s, r = choice["azimuth_sense"], choice["roll_mirror"]
    assert (s.name, s.chosen, s.stated, s.decided) == ("azimuth_sense", "opposite", "same", True)
    assert s.chi2 == {"same": 40.0, "opposite": 3.0}
    assert (r.name, r.chosen, r.stated, r.decided) == ("roll_mirror", "right", "right", True)
    assert r.chi2 == {"right": 3.0, "left": 20.0}
    # a tie of the sides keeps the stated right, with the reason of relative readings
    fake = FakeFits.installed(monkeypatch, {**table, (-1.0, "opposite"): 3.0})
    _, sign, choice = pe.choose_conventions(layout, 2 * A)
    assert fake.calls[0][3] == pe.ROLL_PRIOR
    assert sign == 1.0 and choice["roll_mirror"].reason == "the readings do not depend on the side"
    FakeFits.installed(monkeypatch, {**table, (-1.0, "opposite"): 3.0})
    _, _, choice = pe.choose_conventions(small_layout(True), 2 * A)
    assert choice["roll_mirror"].reason == "with reference rows the side does not change the fit"
    # a tie of the senses
    FakeFits.installed(monkeypatch, {(1.0, "same"): 3.0, (-1.0, "same"): 9.0,
                                     (1.0, "opposite"): 3.0, (-1.0, "opposite"): 9.0})
    turned, _, choice = pe.choose_conventions(layout, 2 * A)
    assert choice["azimuth_sense"].chosen == "same"
    assert choice["azimuth_sense"].reason == "the azimuth mirrors cannot tell the senses apart"
    np.testing.assert_array_equal(turned.theodolite_az, layout.theodolite_az)


def test_choose_conventions_stated_options_and_failures(monkeypatch):
    """A stated sense is fitted alone and not compared; a stated side is used even where the
    other fits better; a failed fit counts as an infinite chi-square; no fit at all: FitError."""
    layout = small_layout(False)
    table = {(1.0, "same"): 50.0, (-1.0, "same"): 4.0, (1.0, "opposite"): 3.0,
             (-1.0, "opposite"): 20.0}
    fake = FakeFits.installed(monkeypatch, table, fail={(-1.0, "opposite")})
    turned, sign, choice = pe.choose_conventions(layout, 2 * A, side="left", sense="opposite")
    assert sorted(c[:2] for c in fake.calls) == [("opposite", -1.0), ("opposite", 1.0)]
    s = choice["azimuth_sense"]
    assert (s.chosen, s.stated, s.chi2, s.decided, s.reason) == (
        "opposite", "opposite", {"opposite": 3.0}, False, "stated, not compared")
    r = choice["roll_mirror"]
    assert (r.chosen, r.stated) == ("left", "left") and r.chi2 == {"right": 3.0, "left": math.inf}
    assert sign == -1.0
    np.testing.assert_array_equal(turned.theodolite_az, -layout.theodolite_az)
    _, sign, choice = pe.choose_conventions(layout, 2 * A, sense="same")
    assert sign == -1.0 and choice["roll_mirror"].chosen == "left"
    for error in (FitError("x"), ValueError("x"), np.linalg.LinAlgError("x")):
        def fail(key, effects, error=error):
            raise error
        monkeypatch.setattr(pe, "fit_model", fail)
        with pytest.raises(FitError, match="cannot be fitted under any convention"):
            pe.choose_conventions(layout, 2 * A)


def test_choose_conventions_compares_in_variance_units_of_one_and_goes_on_after_a_failure(
        monkeypatch):
    """The chi-squares are compared as they are (variance factor 1): gaps of 10 between the
    senses and between the sides exceed the 99 % quantile of chi2(1), 6.63, and decide both
    (half of them would not). A failed first side does not stop the second from being
    fitted. A stated sense keeps its own name."""
    layout = small_layout(False)
    table = {(1.0, "same"): 12.0, (-1.0, "same"): 2.0, (1.0, "opposite"): 30.0,
             (-1.0, "opposite"): 12.0}
    FakeFits.installed(monkeypatch, table)
    _, sign, choice = pe.choose_conventions(layout, 2 * A)
    assert choice["azimuth_sense"].decided and choice["roll_mirror"].decided
    assert sign == -1.0 and choice["roll_mirror"].chosen == "left"
    fake = FakeFits.installed(monkeypatch, table, fail={(1.0, "same")})
    _, sign, choice = pe.choose_conventions(layout, 2 * A, sense="same")
    assert sorted(c[1] for c in fake.calls) == [-1.0, 1.0]
    assert choice["roll_mirror"].chi2 == {"right": math.inf, "left": 2.0} and sign == -1.0
    assert choice["azimuth_sense"].name == "azimuth_sense"
    assert choice["azimuth_sense"].chi2 == {"same": 2.0}


def test_no_convention_fits_names_the_failure(monkeypatch):
    def fail(key, effects):
        raise FitError("x")

    monkeypatch.setattr(pe, "procedure_problem", lambda *a: None)
    monkeypatch.setattr(pe, "fit_model", fail)
    with pytest.raises(FitError) as info:
        pe.choose_conventions(small_layout(False), 2 * A)
    assert str(info.value) == "the base model cannot be fitted under any convention"


def test_exact_problem_of_a_layout_with_a_roll_column_has_no_roll_error():
    """A layout that records rolls: the exact readings record the true (zero) rolls."""
    layout = dataclasses.replace(small_layout(True), ins_roll=np.zeros(5))
    truth = {"axis_az": 300 * A, "axis_el": -200 * A}
    prob = pe.exact_problem(layout, truth, 2 * A)
    assert np.max(np.abs(prob.residuals(truth))) < 1e-6


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_relative_rolls_on_either_side_and_in_a_batch(side):
    """Relative readings with their relative roll column (reference pointings level): the
    exact readings of :func:`montecarlo.seed003.reference.relative_readings` (rolls solved in
    R) have no residual at the truth on either side of the roll mirror, and a batch of two
    models (parameters (2, 1)) gives each model's residuals."""
    from montecarlo.seed003 import reference as ref

    layout = small_layout(False, side)
    g, lam, a = 300 * A, -2000 * A, 0.2
    rolls = np.array([0.03, -0.02, 0.04])
    h, p, roll = ref.relative_readings(g, lam, layout.theodolite_az, layout.theodolite_el, rolls,
                                       (a, 0.0, 0.0), (a + side * math.pi / 2, 0.0, 0.0), side,
                                       True)
    data = dataclasses.replace(layout, ins_az=h, ins_el=p, ins_roll=roll)
    truth = {"axis_az": g, "axis_el": lam, "reference_az": a}
    assert np.max(np.abs(pe.raw_residuals(data, truth, side))) < 1e-12
    other = {"axis_az": -g, "axis_el": lam, "reference_az": a}
    batch = pe.raw_residuals(data, {k: np.array([[truth[k]], [other[k]]]) for k in truth}, side)
    np.testing.assert_allclose(batch[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(batch[1], pe.raw_residuals(data, other, side), atol=1e-15)
    assert np.max(np.abs(batch[1])) > 10 * A  # the two models differ
