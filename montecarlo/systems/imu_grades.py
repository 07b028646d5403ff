"""IMU-grade presets: ``[imu] grade = "tactical"`` instead of the sensor figures one by one.

A study of the air calibration (``system = "air"``) or of the stabilised gimbal
(``system = "stabilization"``) may name a grade in an ``[imu]`` table; the grade sets the
parameters below unless the study's ``[params]`` gives them itself (an explicit number always
wins). The figures are typical values per grade from Groves, *Principles of GNSS, Inertial, and
Multisensor Integrated Navigation Systems*, 2nd ed., Artech House, 2013, section 4.4.1
("Biases"): Table 4.1 (typical accelerometer biases per IMU grade) and Table 4.2 (typical gyro
biases per IMU grade). Where the book gives a range, the preset takes its lower end. The grade
names map onto the book's: ``navigation`` = its aviation (navigation) grade, ``industrial`` =
its intermediate grade, ``tactical`` = tactical, ``consumer`` = its automotive/consumer grade
(a lower bound there: ">"). These figures were written down from the book and have not been
checked against a copy of it in this repository's work: docs/reference/air.md says so; check them
before relying on them. Random-noise figures (angle random walk) are not preset, as none could be
checked; give ``gyro_noise`` yourself.
"""

from __future__ import annotations

from montecarlo.units import SUFFIXES

GRADES = ("consumer", "industrial", "tactical", "navigation")

GYRO_BIAS_DEG_PER_H = {"consumer": 100.0, "industrial": 0.1, "tactical": 1.0,
                       "navigation": 0.01}
"""Typical gyro bias per grade [deg/h] (Groves 2013, Table 4.2; lower end of a range)."""
ACCEL_BIAS_MG = {"consumer": 10.0, "industrial": 0.1, "tactical": 1.0, "navigation": 0.03}
"""Typical accelerometer bias per grade [mg] (Groves 2013, Table 4.1; lower end of a range)."""


def air_preset(grade: str) -> dict[str, float]:
    """Parameters of :func:`montecarlo.seed000.air.run_trials` a grade sets [SI units]."""
    return {"gyro_drift": GYRO_BIAS_DEG_PER_H[grade] * SUFFIXES["deg_per_h"],
            "accel_bias": ACCEL_BIAS_MG[grade] * 1e-3 * SUFFIXES["g"]}


def stabilization_preset(grade: str) -> dict[str, float]:
    """Parameters of :func:`montecarlo.systems.stabilization.run_trials` a grade sets [SI]."""
    return {"gyro_bias": GYRO_BIAS_DEG_PER_H[grade] * SUFFIXES["deg_per_h"]}


PRESETS = {"air": {g: air_preset(g) for g in GRADES},
           "stabilization": {g: stabilization_preset(g) for g in GRADES}}
"""System name -> grade -> the parameters the grade sets [SI units]."""
