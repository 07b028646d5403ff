"""Units: the size of each unit in SI units and radians (the only home of these constants).

Inside the package every angle is in radians and every quantity in SI units; the constants
below convert at the edges (study files, command line, reports)::

    value_rad = value_arcsec * ARCSEC
    value_arcsec = value_rad / ARCSEC
"""

from __future__ import annotations

import math

DEG = math.pi / 180.0
"""One degree [rad]."""
ARCMIN = DEG / 60.0
"""One arc-minute [rad]."""
ARCSEC = DEG / 3600.0
"""One arc-second [rad]."""
MRAD = 1e-3
"""One milliradian [rad]."""
DEG_PER_HOUR = DEG / 3600.0
"""One degree per hour [rad/s] (gyro drift and bias)."""
DEG_PER_ROOT_HOUR = DEG / 60.0
"""One degree per root hour [rad/s/sqrt(Hz)] (gyro angle random walk)."""
MRAD_PER_HOUR = MRAD / 3600.0
"""One milliradian per hour [rad/s]."""
G0 = 9.80665
"""Standard gravity [m/s^2] (accelerometer bias in g)."""

SUFFIXES: dict[str, float] = {
    "": 1.0, "rad": 1.0, "deg": DEG, "arcmin": ARCMIN, "arcsec": ARCSEC, "mrad": MRAD,
    "deg_per_h": DEG_PER_HOUR, "deg_per_root_h": DEG_PER_ROOT_HOUR, "deg_per_s": DEG,
    "g": G0, "m": 1.0, "s": 1.0, "hz": 1.0, "px": 1.0,
}
"""Size in SI units of each unit a study-file key may carry as its suffix (``pitch_span_deg``)."""
