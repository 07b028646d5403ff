"""What a study file may contain: systems, their inputs and metrics, error-source shapes, the
JSON schema of a study file, and commented starter studies (``montecarlo list | schema | init``).

Everything here is derived from the models the loader validates with, so it cannot drift from
what :func:`montecarlo.systems.load_study` accepts.
"""

from __future__ import annotations

import textwrap
import tomllib
import typing
from typing import Any

import numpy as np
from pydantic import BaseModel, Field, create_model

from montecarlo.engine.schema import Source
from montecarlo.engine.study import SWEEP_MODES, Spec, StudyHeader
from montecarlo.errors import InputError
from montecarlo.systems import REGISTRY, study_from_dict
from montecarlo.systems.params import ParamSystem
from montecarlo.units import SUFFIXES

DESCRIPTIONS = {
    "ground": "seed 000, section 1: ground static-base two-target calibration (eqs. 1-18)",
    "air": "seed 000, section 2: air dynamic calibration by transfer alignment (eq. 19)",
    "collimation": "seed 003: autocollimator-INS axis offset fitted from mirrors",
    "stabilization": "seed 001: gimbal IMU and camera installation angles by recursive least "
                     "squares",
    "discrepancy_ground": "the diagnosis of ground data sets: detection and naming rates",
    "discrepancy_collimation": "the diagnosis of mirror data sets: detection and naming rates",
}
"""One line per system of :data:`montecarlo.systems.REGISTRY`."""

UNIT_NAMES = {"deg_per_root_h": "deg/√h", "deg_per_h": "deg/h", "deg_per_s": "deg/s",
              "hz": "Hz"}

GROUND_STARTER = '''\
# {name}: a ground static-base calibration study (seed 000, section 1).
# Units are in the key names; angles in degrees. `montecarlo validate {file}` checks this file
# and says how long it would run; `montecarlo run {file}` runs it; `montecarlo list` shows every
# system, error-source shape and metric.

[study]
name = "{name}"
description = "what this study answers"
system = "ground"
trials = 20000               # per grid point
seed = 1
# confidence = 0.95          # of the percentile intervals and the spec verdicts
# common_random_numbers = true   # the same draws at every grid point: smooth trends

[sensor]
fov_deg = [90.0, 90.0]       # full fields of view about z (yaw) and x (pitch) [deg]
pixels = [512, 512]          # pixel counts across x and z

[mounting]                   # true mounting angles (a number, or a shape to draw them from)
psi_deg = 30.0
theta_deg = 20.0
gamma_deg = 10.0

[geometry]
L_m = 50.0                   # range to the targets [m]
H_m = 1.0                    # height difference between targets A and B [m]

[errors]                     # a number (fixed) or a shape: see `montecarlo list`
evaluation = "sampled"       # or "worst_case": every bounded source at both ends
dx_m = {{ dist = "uniform", bound = 0.1 }}      # lateral survey error [m]
dy_m = {{ dist = "uniform", bound = 0.1 }}      # range survey error [m]
dh1_m = {{ dist = "uniform", bound = 0.1 }}     # height-reference error [m]
dh_m = {{ dist = "uniform", bound = 0.001 }}    # height-scale error, the paper's delta_b [m]
pixel_px = {{ dist = "normal", sigma = 0.3 }}   # image error on each axis of each target [px]
pixel_relation = "common"    # between the two targets: "common", "independent" or a correlation

[solver]
variants = ["raw", "normalised"]

[spec]                       # optional: a requirement judged at every grid point
metric = "rotation_angle"
statistic = "p95"            # mean, std, p50, p90, p95, p99 or max
limit = 3.0                  # in the metric's unit (mrad here)

[[sweep]]                    # optional: the grid; groups combine as a product
"geometry.L_m" = [25.0, 50.0, 100.0]
# mode = "zip"               # or "one_at_a_time"; the default is the product of the lists
'''


def system_names() -> list[str]:
    return list(REGISTRY)


def _system(name: str) -> Any:
    if name not in REGISTRY:
        raise InputError(f"system {name!r}: unknown (choose from {', '.join(REGISTRY)})")
    return REGISTRY[name]()


def _unit(unit: str) -> str:
    return UNIT_NAMES.get(unit, unit)


def starter_study(system: str, name: str | None = None, file: str = "STUDY.toml") -> str:
    """A commented study file for ``system`` that loads as it is."""
    name = name or f"my_{system}"
    if system == "ground":
        return GROUND_STARTER.format(name=name, file=file)
    s = _system(system)
    assert isinstance(s, ParamSystem)
    # about ten seconds of trials on one core, in round numbers
    trials = int(min(10000, max(50, float(f"{10.0 / s.seconds_per_trial:.0e}"))))
    intro = (f"{name}: a study of system {system}, {DESCRIPTIONS[system]}. Units are in the "
             f"key names. `montecarlo validate {file}` checks this file and says how long it "
             f"would run; `montecarlo run {file}` runs it.")
    lines = [*textwrap.wrap(intro, 96, initial_indent="# ", subsequent_indent="# "), "",
             "[study]", f'name = "{name}"', 'description = "what this study answers"',
             f'system = "{system}"', _commented(f"trials = {trials}", "per grid point"),
             "seed = 1", "", _commented("[params]", "every parameter, at its default")]
    for param, default in s.defaults.items():
        unit = s.units.get(param, "")
        value = default / SUFFIXES[unit] if isinstance(default, float) else default
        low, high = s.limits.get(param, (None, None))
        notes = [f"[{_unit(unit)}]" if unit else ""]
        if param in s.choices:
            notes.append("one of " + ", ".join(s.choices[param]))
        elif low is not None or high is not None:
            notes.append(f"{'' if low is None else f'{low:g} '}to"
                         f"{'' if high is None else f' {high:g}'}")
        lines.append(_commented(f"{s.key(param)} = {_toml_value(value)}",
                                " ".join(n for n in notes if n)))
    metric = s.metrics_[0]
    lines += ["", _commented("# [spec]", "optional: a requirement judged at every grid point"),
              f'# metric = "{metric.name}"', '# statistic = "p95"',
              _commented("# limit = 1.0", f"[{metric.unit}]"), "",
              _commented("# [[sweep]]", "optional: the grid; groups combine as a product"),
              f'# "params.{s.key(next(iter(s.defaults)))}" = [...]', ""]
    return "\n".join(lines)


def _commented(text: str, comment: str) -> str:
    return f"{text:<40} # {comment}" if comment else text


def _toml_value(value: Any) -> str:
    """A value as TOML: numbers in 12 significant digits (no unit-conversion noise)."""
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float | np.floating):
        return repr(float(f"{float(value):.12g}"))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


def metrics_of(system: str) -> list[dict[str, Any]]:
    """The metrics a system produces (of its starter study), with units."""
    study = study_from_dict(tomllib.loads(starter_study(system)))
    seen = dict.fromkeys(m for _, m in study.metrics)
    return [{"name": m.name, "label": m.label, "unit": m.unit,
             "of": "magnitude" if m.signed else "value"} for m in seen]


def inputs_of(system: str) -> list[dict[str, Any]]:
    """The inputs of a system: study-file key, unit, default, allowed range or choices."""
    s = _system(system)
    if isinstance(s, ParamSystem):
        out = []
        for param, default in s.defaults.items():
            unit = s.units.get(param, "")
            value = default / SUFFIXES[unit] if isinstance(default, float) else default
            low, high = s.limits.get(param, (None, None))
            out.append({"key": f"params.{s.key(param)}", "unit": _unit(unit),
                        "default": tomllib.loads(f"v = {_toml_value(value)}")["v"],
                        "range": None if low is None and high is None else [low, high],
                        "choices": list(s.choices.get(param, ())) or None})
        return out
    return [{"key": f"{section}.{key}", "unit": unit, "default": None, "range": None,
             "choices": None, "shape": shape}
            for section, key, unit, shape in GROUND_INPUTS]


GROUND_INPUTS = (
    ("sensor", "fov_deg", "deg", "two numbers"), ("sensor", "pixels", "", "two integers"),
    ("mounting", "psi_deg", "deg", "source"), ("mounting", "theta_deg", "deg", "source"),
    ("mounting", "gamma_deg", "deg", "source"), ("geometry", "L_m", "m", "number"),
    ("geometry", "H_m", "m", "number"), ("errors", "evaluation", "", "sampled | worst_case"),
    ("errors", "dx_m", "m", "source"), ("errors", "dy_m", "m", "source"),
    ("errors", "dh1_m", "m", "source"), ("errors", "dh_m", "m", "source"),
    ("errors", "pixel_px", "px", "source"),
    ("errors", "pixel_relation", "", "common | independent | correlation in [-1, 1]"),
    ("solver", "variants", "", "raw, normalised"),
)
"""The ground system's inputs (its sections are pydantic models in :mod:`.ground`)."""


def distributions() -> list[dict[str, Any]]:
    """Each error-source shape: its ``dist`` name and parameters with their defaults."""
    union = typing.get_args(typing.get_args(Source)[0])
    out = []
    for model in union:
        fields = {k: (None if f.is_required() else f.default)
                  for k, f in model.model_fields.items() if k != "dist"}
        dist = typing.get_args(model.model_fields["dist"].annotation)[0]
        out.append({"dist": dist, "parameters": fields, "meaning": SHAPES[dist]})
    return out


SHAPES = {
    "fixed": "always value (a plain number means the same)",
    "uniform": "flat on center ± bound",
    "normal": "normal with mean and sigma",
    "corners": "worst case: center - bound and center + bound only",
    "triangular": "symmetric triangle on center ± bound",
    "arcsine": "sinusoid of amplitude bound about center, at a random phase",
    "truncnormal": "normal with mean and sigma, cut at mean ± bound",
    "lognormal": "exp(ln median + sigma_ln z), z standard normal; positive",
}


def study_schema(system: str | None = None) -> dict[str, Any]:
    """JSON schema of a study file: the common sections, and ``system``'s own if given."""
    sweep = {"type": "array", "items": {
        "type": "object", "properties": {"mode": {"enum": list(SWEEP_MODES)}},
        "additionalProperties": {"type": "array", "minItems": 1},
        "description": "dotted study key -> list of values; groups combine as a product"}}
    common: dict[str, Any] = {"study": (StudyHeader, ...), "spec": (Spec | None, None),
                              "sweep": (list[dict[str, Any]], Field(default_factory=list))}
    base: type[BaseModel] = _system(system).config_model if system else BaseModel
    model = create_model(f"{system or 'any'}_study", __base__=base, **common)
    schema = model.model_json_schema()
    schema["properties"]["sweep"] = sweep
    header = schema["$defs"]["StudyHeader"]["properties"]["system"]
    header["enum"] = [system] if system else list(REGISTRY)
    _numbers_are_fixed_sources(schema)
    schema["title"] = f"montecarlo study file ({system or 'common sections'})"
    if not system:
        schema["additionalProperties"] = True
    return schema


def _numbers_are_fixed_sources(node: Any) -> None:
    """Let every error source of a schema also be a plain number (a fixed value), as the
    loader accepts."""
    if isinstance(node, dict):
        for key, value in list(node.items()):
            if isinstance(value, dict) and value.get("discriminator", {}).get(
                    "propertyName") == "dist":
                default = value.pop("default", None)
                node[key] = {"anyOf": [{"type": "number"}, value]}
                if default is not None:
                    node[key]["default"] = default
            else:
                _numbers_are_fixed_sources(value)
    elif isinstance(node, list):
        for item in node:
            _numbers_are_fixed_sources(item)
