"""Invalid-trial flags: marking reasons and counting them, by hand."""

import numpy as np

from montecarlo.geometry.invalid import FLAG_DTYPE, Invalid, mark, reason_counts


def test_mark_adds_a_reason_where_a_mask_is_true_keeping_earlier_ones():
    """Reasons are bits: marking BEHIND_SENSOR (8) then OUTSIDE_FOV (16) on trial 1 gives 24.
    ``where`` is a mask even when given as 0/1 integers (not the indices 0 and 1)."""
    flags = np.zeros(4, FLAG_DTYPE)
    mark(flags, [False, True, True, False], Invalid.BEHIND_SENSOR)
    mark(flags, [0, 1, 0, 1], Invalid.OUTSIDE_FOV)
    np.testing.assert_array_equal(flags, [0, 24, 8, 16])
    assert flags.dtype == np.uint16


def test_reason_counts_by_hand():
    """Trials flagged 0, 1, 3, 8, 24, 1: five invalid; NAN_INPUT (1) in three of them (1, 3,
    1), RANGE_NOT_POSITIVE (2) in one (3), BEHIND_SENSOR (8) in two (8, 24), OUTSIDE_FOV (16)
    in one (24). Reasons with no trial are left out."""
    flags = np.array([0, 1, 3, 8, 24, 1])
    counts = reason_counts(np.bincount(flags, minlength=256))
    assert counts == {"total": 5, "NAN_INPUT": 3, "RANGE_NOT_POSITIVE": 1, "BEHIND_SENSOR": 2,
                      "OUTSIDE_FOV": 1}
    assert reason_counts(np.bincount(np.zeros(3, int), minlength=256)) == {"total": 0}
