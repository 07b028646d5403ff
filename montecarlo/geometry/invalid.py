"""Per-trial reasons why a geometry or a solution is invalid.

A trial is never silently turned into numbers: every function that can meet invalid geometry
returns NaN for that trial together with a bit set in an ``Invalid`` flag array, so that results
can count invalid trials by reason.
"""

from __future__ import annotations

import enum

import numpy as np
from numpy.typing import ArrayLike, NDArray

FLAG_DTYPE = np.uint16


class Invalid(enum.IntFlag):
    """Why a trial has no solution (bits may combine)."""

    NAN_INPUT = 1
    """A pixel coordinate, range or height is NaN or infinite."""
    RANGE_NOT_POSITIVE = 2
    """Nominal range L <= 0: the targets are not in front of the base (seed 000, section 1.2)."""
    ZERO_HEIGHT = 4
    """Nominal height difference H = 0: eq. (11) divides by it."""
    BEHIND_SENSOR = 8
    """A target lies behind the focal plane (y <= 0 in frame a)."""
    OUTSIDE_FOV = 16
    """A target's image falls outside the detector."""
    PITCH_OUT_OF_RANGE = 32
    """|C23| >= 1 in eq. (14): no pitch in (-pi/2, pi/2)."""
    ROLL_OUT_OF_RANGE = 64
    """C33 <= 0 in eq. (14): the roll is outside the assumed (-pi/2, pi/2)."""
    YAW_OUT_OF_RANGE = 128
    """The sine of yaw in eq. (14) exceeds 1 in magnitude."""


def reason_counts(flag_counts: np.ndarray) -> dict[str, int]:
    """Invalid trials per reason name, and "total", from counts of each flag value.

    ``flag_counts`` is ``np.bincount(flags, minlength=256)``; a trial with two reasons counts
    under both.
    """
    values = np.arange(flag_counts.size)
    counts = {"total": int(flag_counts[1:].sum())}
    for reason in Invalid:
        c = int(flag_counts[(values & reason) != 0].sum())
        if c:
            counts[str(reason.name)] = c
    return counts


def mark(flags: NDArray[np.uint16], where: ArrayLike, reason: Invalid) -> None:
    """Set ``reason`` in ``flags`` (in place) wherever ``where`` is true."""
    flags[np.asarray(where, bool)] |= FLAG_DTYPE(reason)
