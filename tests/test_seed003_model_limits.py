"""Seed 003's forward model: hand values, limits, error messages and the simulator's noise.

Each test states the value it expects and where it comes from (a hand derivation in the
docstring or the noise the simulator is given), not a second call of the model.
"""

import math

import numpy as np
import pytest

from montecarlo.seed003 import model as col
from montecarlo.units import ARCSEC

A = ARCSEC


def test_autocollimate_with_the_optical_axis_on_the_ins_axis_reads_the_target():
    """u = e_y (no offsets), default roll 0: the attitude that turns e_y onto
    ``direction(0.3, 0.2)`` has heading 0.3 and pitch 0.2 (the INS axis is the second column
    of the attitude, ``direction(heading, pitch)``)."""
    heading, pitch = col.autocollimate([0.0, 1.0, 0.0], col.direction(0.3, 0.2))
    assert heading == pytest.approx(0.3, abs=1e-15)
    assert pitch == pytest.approx(0.2, abs=1e-15)
    # an optical axis 0.01 rad to the right, level (default roll 0), on a horizontal target at
    # azimuth 0.3: the INS turns 0.01 less, heading 0.29, pitch 0
    heading, pitch = col.autocollimate(col.direction(0.01, 0.0), col.direction(0.3, 0.0))
    assert heading == pytest.approx(0.29, abs=1e-15)
    assert pitch == pytest.approx(0.0, abs=1e-15)


def test_autocollimate_gives_nan_without_a_warning_where_no_pitch_reaches():
    """u = direction(0.5, 0): the pitch turns only the (y, z) part of u, of length
    ``r = cos 0.5 = 0.878``; a target at elevation 1.4 rad has ``w_z = sin 1.4 = 0.985 > r``,
    so no pitch autocollimates (NaN, documented), and no floating-point warning escapes."""
    _, pitch = col.autocollimate(col.direction(0.5, 0.0), col.direction(0.0, 1.4))
    assert np.isnan(pitch)


def test_unknown_effect_and_parameter_are_named_with_the_known_ones():
    with pytest.raises(ValueError, match=r"^unknown effect 'tilt'; known: frame_heading, "
                                         r"axis_misalignment, frame_misalignment$"):
        col.parameter_names(["axis_misalignment", "tilt"])
    with pytest.raises(ValueError, match=r"^unknown parameter\(s\) \['axis_azimuth'\]; known: "
                                         r"\['axis_az', 'axis_el', 'frame_heading', "
                                         r"'frame_tilt_x', 'frame_tilt_y'\]$"):
        col.predict_readings({"axis_azimuth": 1e-3}, 0.0, 0.0)


def test_paper_layout_by_hand():
    """Defaults 5 + 5: azimuths 0, 22.5, 45, 67.5, 90 deg at elevation 0, then the pitch mirrors
    at azimuth 0 and elevations 12, 24, 36, 48, 60 deg (60/5 steps)."""
    az, el, sets = col.paper_layout()
    np.testing.assert_allclose(np.degrees(az), [0, 22.5, 45, 67.5, 90, 0, 0, 0, 0, 0],
                               atol=1e-12)
    np.testing.assert_allclose(np.degrees(el), [0, 0, 0, 0, 0, 12, 24, 36, 48, 60], atol=1e-12)
    assert sets.tolist() == ["azimuth"] * 5 + ["pitch"] * 5
    # one pitch mirror sits at the full span; no azimuth mirror at all is allowed
    az, el, sets = col.paper_layout(0, 1, pitch_span=0.5)
    assert az.tolist() == [0.0] and el.tolist() == [0.5] and sets.tolist() == ["pitch"]
    for counts in ((-1, 3), (3, -1)):
        with pytest.raises(ValueError, match=r"^mirror counts must be >= 0$"):
            col.paper_layout(*counts)


def test_residual_sigma_combines_each_ins_reading_with_the_theodolite():
    """hypot(8, 6) = 10 and hypot(2.5, 6) = 6.5 (arc-seconds)."""
    noise = col.Noise(theodolite=6 * A, ins_heading=8 * A, ins_pitch=2.5 * A)
    assert noise.residual_sigma() == pytest.approx((10 * A, 6.5 * A), rel=1e-15)


def _spread(x):
    return float(np.mean(x)), float(np.std(x))


def test_simulated_reading_errors_have_the_stated_spread():
    """Zero offsets: the true readings are the mirror angles themselves (heading = az +
    frame_heading, pitch = el at any roll), so each reading minus its true value is that
    reading's error. 400 calibrations x 10 mirrors = 4000 draws per reading: the sample std of
    N(0, s) is within 4 standard errors (s / sqrt(2 * 4000), 4.5 %) of s, the mean within
    4 s / sqrt(4000); errors differ between mirrors and trials."""
    az, el, _ = col.paper_layout()
    n, m = 400, az.size
    noise = col.Noise(theodolite=3 * A, ins_heading=5 * A, ins_pitch=7 * A, ins_roll=11 * A)
    d = col.simulate_readings({"frame_heading": 0.7}, az, el, noise, rng=1, n=n)
    errors = {"theodolite_az": (d["theodolite_az"] - az, 3 * A),
              "theodolite_el": (d["theodolite_el"] - el, 3 * A),
              "ins_az": (col.wrap(d["ins_az"] - az - 0.7), 5 * A),
              "ins_el": (d["ins_el"] - el, 7 * A),
              "ins_roll": (d["ins_roll"], 11 * A)}
    for key, (e, s) in errors.items():
        assert e.shape == (n, m), key
        mean, std = _spread(e)
        assert abs(std / s - 1) < 4 / math.sqrt(2 * n * m), key
        assert abs(mean) < 4 * s / math.sqrt(n * m), key
        assert np.std(e[0]) > 0.3 * s and np.std(e[:, 0]) > 0.3 * s, key
    # the mount rolls alone: the reported roll is the true one, spread mount_roll
    d = col.simulate_readings({}, az, el, col.Noise(0, 0, 0, 0, mount_roll=0.02), rng=2, n=n)
    mean, std = _spread(d["ins_roll"])
    assert abs(std / 0.02 - 1) < 4 / math.sqrt(2 * n * m)
    assert np.std(d["ins_roll"][0]) > 0.006
    assert np.array_equal(d["theodolite_az"], np.broadcast_to(az, (n, m)))


def test_a_rolled_mount_turns_the_offsets_by_the_reported_roll():
    """No reading error, mount roll 90 deg would turn gamma into pitch; with small rolls phi
    the pitch of a horizontal mirror is ``-(lambda cos phi - gamma sin phi)`` to first order
    (a roll right side down by phi turns an axis gamma to the right down by gamma sin phi):
    the reported roll is the one the INS had."""
    gamma, lam = 200 * A, 100 * A
    az = np.zeros(2000)
    d = col.simulate_readings({"axis_az": gamma, "axis_el": lam}, az, az,
                              col.Noise(0, 0, 0, 0, mount_roll=0.3), rng=3)
    phi = d["ins_roll"]
    expected = -(lam * np.cos(phi) - gamma * np.sin(phi))
    np.testing.assert_allclose(d["ins_el"], expected, atol=3 * (gamma + lam) ** 2)
    assert np.std(phi) > 0.2
