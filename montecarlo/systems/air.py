"""The air dynamic calibration of seed 000, section 2, as a study system (``system = "air"``).

Study-file parameters are those of :func:`montecarlo.seed000.air.run_trials`, each key with its
unit suffix, in a ``[params]`` table (see :mod:`montecarlo.systems.params`).
"""

from __future__ import annotations

from montecarlo.engine.system import Metric
from montecarlo.seed000 import air
from montecarlo.systems.imu_grades import PRESETS
from montecarlo.systems.params import ParamSystem
from montecarlo.units import SUFFIXES

AIR = ParamSystem(
    name="air",
    run_trials=air.run_trials,
    defaults=air.DEFAULT_PARAMS,
    units={"heading_sigma": "arcmin", "level_sigma": "arcmin", "gyro_drift": "deg_per_h",
           "accel_bias": "g", "install_bound": "arcmin", "master_heading_sigma": "arcmin",
           "master_level_sigma": "arcmin", "mount_psi": "deg", "mount_theta": "deg",
           "mount_gamma": "deg", "aircraft_heading": "deg", "aircraft_pitch": "deg",
           "aircraft_roll": "deg", "ta_duration": "s", "ta_time_offset": "s",
           "ta_lever_arm_error": "m"},
    metrics_=(
        Metric("rotation_angle", "true rotation angle φ of D", "mrad", 1e3),
        Metric("eq18_angle", "eq. (18) as printed, = φ/2", "mrad", 1e3),
        Metric("table1_angle", "Table 1 metric arccos((1+tr D)/4) ≈ φ/√2", "mrad", 1e3),
        Metric("delta_psi", "yaw error δψ", "mrad", 1e3, signed=True),
        Metric("delta_theta", "pitch error δθ", "mrad", 1e3, signed=True),
        Metric("delta_gamma", "roll error δγ", "mrad", 1e3, signed=True),
        Metric("heading_error", "slave heading error after alignment", "arcmin",
               1.0 / SUFFIXES["arcmin"], signed=True),
        Metric("level_error", "slave level error after alignment", "arcmin",
               1.0 / SUFFIXES["arcmin"]),
    ),
    seconds_per_trial=5e-6,
    default_block_size=1 << 14,
    limits={**dict.fromkeys(("heading_sigma", "level_sigma", "gyro_drift", "accel_bias",
                             "install_bound", "master_heading_sigma", "master_level_sigma"),
                            (0.0, 1e4)),
            "ta_duration": (0.0, 3600.0), "ta_time_offset": (0.0, 1.0),
            "ta_lever_arm_error": (0.0, 100.0),
            "master_error_shared": (0.0, 1.0),
            **dict.fromkeys(("mount_psi", "mount_theta", "mount_gamma", "aircraft_heading",
                             "aircraft_pitch", "aircraft_roll"), (-360.0, 360.0))},
    choices={"ta_source": air.TA_SOURCES, "level_split": air.LEVEL_SPLITS},
    presets=PRESETS["air"],
)
"""Seed 000, section 2: air dynamic calibration (:func:`montecarlo.seed000.air.run_trials`)."""
