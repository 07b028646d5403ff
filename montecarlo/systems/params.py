"""Study systems built on a module's ``run_trials(params, rng, n)`` hook.

The air calibration, the autocollimator-INS calibration and the stabilisation estimator each
expose ``run_trials`` taking SI/radian parameters. In a study file their parameters go in one
``[params]`` table whose keys carry the unit users read (the edge)::

    [params]
    theodolite_sigma_arcsec = 2.0     # -> theodolite_sigma [rad]
    pitch_span_deg = 60.0             # -> pitch_span [rad]
    n_pitch = 5                       # no unit

Every block of trials gets its own generator from the block's streams, so these systems share
the runner's reproducibility contract.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, create_model

from montecarlo.engine.distributions import Streams
from montecarlo.engine.schema import Strict
from montecarlo.engine.system import BlockInvalid, BlockValues, Metric

ARCSEC = math.pi / (180.0 * 3600.0)
UNITS = {
    "": 1.0, "rad": 1.0, "deg": math.pi / 180.0, "arcmin": math.pi / (180.0 * 60.0),
    "arcsec": ARCSEC, "mrad": 1e-3, "deg_per_h": math.pi / (180.0 * 3600.0),
    "g": 9.80665, "m": 1.0, "s": 1.0, "hz": 1.0, "px": 1.0, "deg_per_s": math.pi / 180.0,
    "deg_per_root_h": math.pi / (180.0 * 60.0),
}
"""Scale from a study-file unit to SI/radians."""

VARIANT = "default"
"""These systems have one estimator: their rows carry this variant name."""


@dataclass(frozen=True)
class PreparedParams:
    params: dict[str, Any]
    description: tuple[str, ...]


@dataclass(frozen=True)
class ParamSystem:
    """A :class:`montecarlo.systems.System` wrapping ``module.run_trials``.

    Parameters
    ----------
    name : system name in study files.
    module : module with ``run_trials`` and ``DEFAULT_PARAMS``.
    units : run_trials parameter -> study-file unit (key suffix); omitted parameters are
        unitless numbers or text.
    metrics : the metrics to aggregate, with display units.
    default_block_size : trials per block (small for expensive trials).
    """

    name: str
    module: str
    units: Mapping[str, str]
    metrics_: tuple[Metric, ...]
    default_block_size: int = 256

    def _module(self) -> Any:
        return importlib.import_module(self.module)

    def _key(self, param: str) -> str:
        unit = self.units.get(param, "")
        return f"{param}_{unit}" if unit else param

    @property
    def config_model(self) -> type[BaseModel]:
        fields: dict[str, Any] = {}
        for param, default in self._module().DEFAULT_PARAMS.items():
            scale = UNITS[self.units.get(param, "")]
            value = float(default) / scale if isinstance(default, float) else default
            kind = float if isinstance(default, float) else type(default)
            fields[self._key(param)] = (kind, value)
        params = create_model(f"{self.name}_params", __base__=Strict, **fields)
        return create_model(f"{self.name}_config", __base__=Strict, params=(params, params()))

    def prepare(self, config: Any) -> PreparedParams:
        given = config.params.model_dump()
        params = {}
        for param in self._module().DEFAULT_PARAMS:
            value = given[self._key(param)]
            scale = UNITS[self.units.get(param, "")]
            params[param] = value * scale if isinstance(value, float) else value
        described = tuple(f"{k} = {v}" for k, v in given.items())
        return PreparedParams(params, described)

    def metrics(self, prepared: PreparedParams) -> list[tuple[str, Metric]]:
        return [(VARIANT, m) for m in self.metrics_]

    def trials_per_point(self, prepared: PreparedParams, requested: int) -> int:
        return requested

    def simulate_block(self, prepared: PreparedParams, streams: Streams, first_trial: int,
                       n: int) -> tuple[BlockValues, BlockInvalid]:
        out = self._module().run_trials(prepared.params, streams.generator("trials"), n)
        values = {(VARIANT, m.name): np.asarray(out[m.name], float) for m in self.metrics_}
        failed = int(np.count_nonzero(~np.isfinite(values[(VARIANT, self.metrics_[0].name)])))
        return values, {VARIANT: {"total": failed, **({"FAILED": failed} if failed else {})}}

    def describe(self, prepared: PreparedParams) -> list[str]:
        return [f"{self.name} parameters: " + ", ".join(prepared.description)]


def _angles(names: tuple[str, ...], label: str, unit: str, signed: bool = False
            ) -> tuple[Metric, ...]:
    return tuple(Metric(n, f"{label} {n}", unit, 1.0 / UNITS[unit], signed) for n in names)


AIR = ParamSystem(
    name="air",
    module="montecarlo.seed000.air",
    units={"heading_sigma": "arcmin", "level_sigma": "arcmin", "gyro_drift": "deg_per_h",
           "accel_bias": "g", "install_bound": "arcmin", "master_heading_sigma": "arcmin",
           "master_level_sigma": "arcmin", "mount_psi": "deg", "mount_theta": "deg",
           "mount_gamma": "deg", "aircraft_heading": "deg", "aircraft_pitch": "deg",
           "aircraft_roll": "deg"},
    metrics_=(
        Metric("rotation_angle", "true rotation angle φ of D", "mrad", 1e3),
        Metric("eq18_angle", "eq. (18) as printed, = φ/2", "mrad", 1e3),
        Metric("table1_angle", "Table 1 metric arccos((1+tr D)/4) ≈ φ/√2", "mrad", 1e3),
        Metric("delta_psi", "yaw error δψ", "mrad", 1e3, signed=True),
        Metric("delta_theta", "pitch error δθ", "mrad", 1e3, signed=True),
        Metric("delta_gamma", "roll error δγ", "mrad", 1e3, signed=True),
        Metric("heading_error", "slave heading error after alignment", "arcmin",
               1.0 / UNITS["arcmin"], signed=True),
        Metric("level_error", "slave level error after alignment", "arcmin",
               1.0 / UNITS["arcmin"]),
    ),
    default_block_size=1 << 14,
)
"""Seed 000, section 2: air dynamic calibration (montecarlo.air)."""

COLLIMATION = ParamSystem(
    name="collimation",
    module="montecarlo.seed003.model",
    units={"axis_az": "arcsec", "axis_el": "arcsec", "frame_heading": "deg",
           "frame_tilt_x": "arcsec", "frame_tilt_y": "arcsec", "azimuth_span": "deg",
           "pitch_span": "deg", "theodolite_sigma": "arcsec", "ins_heading_sigma": "arcsec",
           "ins_pitch_sigma": "arcsec", "ins_roll_sigma": "arcsec", "mount_roll_sigma": "deg"},
    metrics_=(
        *_angles(("axis_az_error", "axis_el_error", "frame_heading_error"),
                 "fit error", "arcsec", signed=True),
        Metric("axis_error_angle", "angle between fitted and true optical axis", "arcsec",
               1.0 / ARCSEC),
        *_angles(("axis_az_sigma", "axis_el_sigma"), "predicted σ", "arcsec"),
        *_angles(("residual_rms_before", "residual_rms_after", "consistency_max_after"),
                 "residual", "arcsec"),
        Metric("axis_az_within_2sigma", "γ within 2σ (mean = coverage)", "1", 1.0),
        Metric("axis_el_within_2sigma", "λ within 2σ (mean = coverage)", "1", 1.0),
        Metric("residual_rms_ratio", "after-fit residual RMS / injected noise", "1", 1.0),
        Metric("chi2_red", "reduced χ² of the fit", "1", 1.0),
    ),
    default_block_size=64,
)
"""Seed 003: autocollimator-INS axis calibration (montecarlo.collimation)."""

STABILIZATION = ParamSystem(
    name="stabilization",
    module="montecarlo.seed001.estimate",
    units={"duration": "s", "rate": "hz", "misalignment_min": "deg", "misalignment_max": "deg",
           "rock_amplitude": "deg", "rock_freq_yaw": "hz", "rock_freq_pitch": "hz",
           "rock_freq_roll": "hz", "aim_azimuth": "deg", "aim_pitch": "deg", "image_noise": "px",
           "gyro_noise": "deg_per_root_h", "gyro_bias": "deg_per_h", "fov": "deg"},
    metrics_=(
        *_angles(("dpx_error", "dgx_error", "dgy_error", "dz_error"), "estimation error",
                 "arcmin", signed=True),
        *(Metric(f"{q}_rel_error", f"|error| / |truth| of {q}", "1", 1.0)
          for q in ("dpx", "dgx", "dgy", "dz")),
        *_angles(("dpx_sigma", "dgx_sigma", "dgy_sigma", "dz_sigma"), "predicted σ", "arcmin"),
        Metric("within_2sigma", "all four within 2σ (mean = rate)", "1", 1.0),
        Metric("within_5pct", "all four within 5 % (mean = rate)", "1", 1.0),
        Metric("accepted", "all four within 2σ and 5 % (mean = rate)", "1", 1.0),
        *_angles(("los_rms_before", "los_rms_after"), "line-of-sight error RMS", "arcmin"),
        Metric("los_rms_ratio", "LOS error RMS after / before compensation", "1", 1.0),
        Metric("residual_rms", "image residual RMS", "px", 1.0),
    ),
    default_block_size=32,
)
"""Seed 001: gyro indirect stabilisation installation angles (montecarlo.stabilization)."""
