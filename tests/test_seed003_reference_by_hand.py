"""Seed 003's procedure frame by hand: a roll mirror on the left, the first-order form with its
defaults against the exact model, and the relative roll given back."""

import math

import numpy as np
import pytest

from montecarlo.seed003 import reference as ref
from montecarlo.units import ARCSEC

A = ARCSEC
LEFT = -1.0


def test_roll_mirror_is_a_quarter_turn_to_the_side():
    assert ref.roll_mirror_azimuth(0.2) == pytest.approx(0.2 + math.pi / 2, abs=1e-15)
    assert ref.roll_mirror_azimuth(0.2, LEFT) == pytest.approx(0.2 - math.pi / 2, abs=1e-15)
    assert ref.SIDES == {"right": 1.0, "left": -1.0}


def test_a_left_roll_mirror_gives_the_same_frame_as_a_right_one_on_its_own_side():
    """Central mirror at azimuth 0.3, roll mirror on the left (0.3 - 90 deg), side -1: x_R is
    minus the direction to the left mirror, i.e. to the right of the central one, so the frame
    is the level frame turned by 0.3 and relative angles are ``(az - 0.3, el)``; an INS with
    no offsets reading heading 0.3 + a, pitch e, roll r reads (a, e, r) relative to it; its
    readings need no correction."""
    az, el = np.array([0.5, 0.9, 0.3]), np.array([0.0, 0.2, 0.6])
    t_az, t_el = ref.theodolite_relative(az, el, (0.3, 0.0), (0.3 - math.pi / 2, 0.0), LEFT)
    np.testing.assert_allclose(t_az, az - 0.3, atol=1e-15)
    np.testing.assert_allclose(t_el, el, atol=1e-15)
    a, e, r = np.array([0.2, -0.4]), np.array([0.1, 0.5]), np.array([0.05, -0.3])
    h, p, rr = ref.relative_from_absolute(0.3 + a, e, r, (0.3, 0.0, 0.0),
                                          (0.3 - math.pi / 2, 0.0, 0.0), LEFT)
    for got, want in ((h, a), (p, e), (rr, r)):
        np.testing.assert_allclose(got, want, atol=1e-14)
    c_az, c_el = ref.corrected_readings(a, e, r, 0.0, 0.0, (0.0, 0.0, 0.0),
                                        (-math.pi / 2, 0.0, 0.0), LEFT)
    np.testing.assert_allclose(c_az, a, atol=1e-15)
    np.testing.assert_allclose(c_el, e, atol=1e-15)


def test_frame_from_axes_normalises_its_inputs():
    """y along the centre's axis (0, 2, 0), x along the roll axis's part orthogonal to it,
    (3, 3, 0) -> (1, 0, 0), z = x cross y = (0, 0, 1); on the left x and z turn over. A batch:
    centre (2, 0, 0) and roll axis (1, 0, -4) give y = (1, 0, 0), x = (0, 0, -1),
    z = (0, -1, 0), each row on its own."""
    np.testing.assert_allclose(ref.frame_from_axes([0, 2, 0], [3, 3, 0]), np.eye(3), atol=1e-15)
    np.testing.assert_allclose(ref.frame_from_axes([0, 2, 0], [3, 3, 0], LEFT),
                               np.diag([-1.0, 1.0, -1.0]), atol=1e-15)
    batch = ref.frame_from_axes([[0, 2, 0], [2, 0, 0]], [[3, 3, 0], [1, 0, -4]])
    np.testing.assert_allclose(batch[0], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(batch[1], [[0, 1, 0], [0, 0, -1], [-1, 0, 0]], atol=1e-15)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_first_order_defaults_are_a_level_mount_with_the_central_mirror_at_zero(side):
    """With its defaults (every roll 0, the central mirror at azimuth 0, the roll mirror on the
    right) the first-order form is the exact model of that set-up to second order in the
    offsets (below ``(|gamma| + |lambda|)^2 / 2`` = 0.18″); the central azimuth is
    subtracted from the mirrors' azimuths."""
    g, lam = 150 * A, -120 * A
    second = (abs(g) + abs(lam)) ** 2 / 2
    az = np.radians([-40.0, 25.0, 70.0, 10.0, -5.0])
    el = np.radians([0.0, 10.0, 30.0, 50.0, 20.0])
    exact = ref.relative_readings(g, lam, az, el, 0.0, (0.0, 0.0, 0.0), (math.pi / 2, 0.0, 0.0))
    first = ref.first_order_readings(g, lam, az, el)
    np.testing.assert_allclose(ref.wrap(first[0] - exact[0]), 0.0, atol=second)
    np.testing.assert_allclose(first[1] - exact[1], 0.0, atol=second)
    assert np.abs(first[1] - el).max() > 100 * A  # the signal is first order
    # the central mirror at 0.4 rad, the roll mirror on the given side
    c = 0.4
    exact = ref.relative_readings(g, lam, az + c, el, 0.0, (c, 0.0, 0.0),
                                  (c + side * math.pi / 2, 0.0, 0.0), side)
    first = ref.first_order_readings(g, lam, az + c, el, az_center=c, side=side)
    np.testing.assert_allclose(ref.wrap(first[0] - exact[0]), 0.0, atol=second)
    np.testing.assert_allclose(first[1] - exact[1], 0.0, atol=second)


def test_relative_roll_is_given_back_as_read():
    """``roll_is_relative``: the roll given for the measured mirrors is the reading itself."""
    center, mirror = (0.0, 0.0, 0.01), (math.pi / 2, 0.0, -0.02)
    az, el = np.array([0.1, 0.0, 0.3]), np.array([0.0, 0.4, 0.2])
    _, _, roll = ref.relative_readings(300 * A, 100 * A, az, el, 0.07, center, mirror,
                                       roll_is_relative=True)
    np.testing.assert_array_equal(roll, np.full(3, 0.07))
