"""Study systems built on a ``run_trials(params, rng, n)`` function and its default parameters.

The air calibration, the autocollimator-INS calibration, the stabilisation estimator and the
discrepancy acceptance studies each have a ``run_trials`` taking SI/radian parameters. In a study
file their parameters go in one ``[params]`` table whose keys carry the unit users read (the
edge)::

    [params]
    theodolite_sigma_arcsec = 2.0     # -> theodolite_sigma [rad]
    pitch_span_deg = 60.0             # -> pitch_span [rad]
    n_pitch = 5                       # no unit

Every block of trials gets its own generator from the block's streams, so these systems share
the runner's reproducibility contract.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field, create_model

from montecarlo.engine.distributions import Streams
from montecarlo.engine.schema import Strict
from montecarlo.engine.system import BlockInvalid, BlockValues, Metric
from montecarlo.units import SUFFIXES

VARIANT = "default"
"""These systems have one estimator: their rows carry this variant name."""


@dataclass(frozen=True)
class PreparedParams:
    params: dict[str, Any]
    description: tuple[str, ...]


@dataclass(frozen=True)
class ParamSystem:
    """A :class:`montecarlo.engine.system.System` wrapping a ``run_trials`` function.

    Parameters
    ----------
    name : system name in study files.
    run_trials : ``run_trials(params, rng, n) -> {metric: (n,) array}``, params in SI units.
    defaults : every parameter of ``run_trials`` and its default (SI units, radians).
    units : run_trials parameter -> study-file unit (key suffix, see
        :data:`montecarlo.units.SUFFIXES`); omitted parameters are unitless numbers or text.
    metrics : the metrics to aggregate, with display units.
    default_block_size : trials per block (small for expensive trials).
    seconds_per_trial : rough cost of one trial on one core [s], for planning.
    reference_seconds_per_trial : the same on the literal path (``has_reference_path``) [s];
        None: the same as ``seconds_per_trial``.
    limits : parameter -> (lowest, highest) allowed, in the study-file unit (None: open), so
        that a value no trial could use is refused when the study is loaded.
    choices : parameter -> the texts a text parameter may take.
    presets : grade -> parameters it sets [SI units], chosen by ``[imu] grade = "..."``
        (:mod:`montecarlo.systems.imu_grades`); a parameter given in ``[params]`` wins.
    has_reference_path : ``run_trials`` takes ``reference=True`` for its literal path (trial
        by trial, without compiled kernels; ``run --reference``) and otherwise takes a faster
        one tested equal to it; without it, ``run_trials`` has one path, the literal one.
    """

    name: str
    run_trials: Callable[..., Mapping[str, Any]]
    defaults: Mapping[str, Any]
    units: Mapping[str, str]
    metrics_: tuple[Metric, ...]
    default_block_size: int = 256
    seconds_per_trial: float = 1e-3
    reference_seconds_per_trial: float | None = None
    limits: Mapping[str, tuple[float | None, float | None]] = field(default_factory=dict)
    choices: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    presets: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    has_reference_path: bool = False

    def key(self, param: str) -> str:
        """The study-file key of a parameter: its name and unit suffix."""
        unit = self.units.get(param, "")
        return f"{param}_{unit}" if unit else param

    @property
    def config_model(self) -> type[BaseModel]:
        fields: dict[str, Any] = {}
        for param, default in self.defaults.items():
            scale = SUFFIXES[self.units.get(param, "")]
            value = float(default) / scale if isinstance(default, float) else default
            kind: Any = float if isinstance(default, float) else type(default)
            if param in self.choices:
                kind = Literal[self.choices[param]]  # type: ignore[valid-type]
            low, high = self.limits.get(param, (None, None))
            fields[self.key(param)] = (kind, Field(default=value, ge=low, le=high))
        params = create_model(f"{self.name}_params", __base__=Strict, **fields)
        tables: dict[str, Any] = {"params": (params, params())}
        if self.presets:
            grade = Literal[tuple(self.presets)] | None  # type: ignore[valid-type]
            imu = create_model(f"{self.name}_imu", __base__=Strict,
                               grade=(grade, Field(default=None)))
            tables["imu"] = (imu, imu())
        return create_model(f"{self.name}_config", __base__=Strict, **tables)

    def prepare(self, config: Any) -> PreparedParams:
        given = config.params.model_dump()
        explicit = config.params.model_fields_set
        grade = getattr(getattr(config, "imu", None), "grade", None)
        preset = {k: v for k, v in (self.presets.get(grade, {}) if grade else {}).items()
                  if self.key(k) not in explicit}  # an explicit number wins
        params = {}
        for param in self.defaults:
            value = given[self.key(param)]
            scale = SUFFIXES[self.units.get(param, "")]
            params[param] = value * scale if isinstance(value, float) else value
        params.update(preset)
        for param, value in preset.items():
            given[self.key(param)] = value / SUFFIXES[self.units.get(param, "")]
        described = tuple(f"{k} = {v}" for k, v in given.items())
        if grade:
            described += (f"imu grade {grade} (Groves 2013, Tables 4.1-4.2) sets "
                          + (", ".join(self.key(k) for k in preset) or "nothing: every figure "
                             "it would set is given in [params]"),)
        return PreparedParams(params, described)

    def metrics(self, prepared: PreparedParams) -> list[tuple[str, Metric]]:
        return [(VARIANT, m) for m in self.metrics_]

    def is_sampled(self, prepared: PreparedParams) -> bool:
        return True

    def trials_per_point(self, prepared: PreparedParams, requested: int) -> int:
        return requested

    def simulate_block(self, prepared: PreparedParams, streams: Streams, first_trial: int,
                       n: int, reference: bool = False) -> tuple[BlockValues, BlockInvalid]:
        literal = {"reference": True} if reference and self.has_reference_path else {}
        out = self.run_trials(prepared.params, streams.generator("trials"), n, **literal)
        values = {(VARIANT, m.name): np.asarray(out[m.name], float) for m in self.metrics_}
        failed = int(np.count_nonzero(~np.isfinite(values[(VARIANT, self.metrics_[0].name)])))
        return values, {VARIANT: {"total": failed, **({"FAILED": failed} if failed else {})}}

    def describe(self, prepared: PreparedParams) -> list[str]:
        return [f"{self.name} parameters: " + ", ".join(prepared.description)]


def angle_metrics(names: tuple[str, ...], label: str, unit: str, signed: bool = False
                  ) -> tuple[Metric, ...]:
    """Metrics of the same label and display unit (a key of :data:`montecarlo.units.SUFFIXES`)."""
    return tuple(Metric(n, f"{label} {n}", unit, 1.0 / SUFFIXES[unit], signed) for n in names)


def study_params(system: ParamSystem, si: Mapping[str, Any]) -> dict[str, Any]:
    """``[params]`` keys and values of a study of ``system`` from SI/radian values."""
    out: dict[str, Any] = {}
    for param, v in si.items():
        unit = system.units.get(param, "")
        out[system.key(param)] = float(v) / SUFFIXES[unit] if isinstance(v, float) else v
    return out
