"""Building blocks of study files shared by all systems: strict models and error sources.

An error source in a study file is a number (a fixed value) or a table with ``dist``::

    dx_m = 0.05                                   # fixed
    dx_m = { dist = "uniform", bound = 0.1 }      # uniform on center +- bound (center = 0)
    dx_m = { dist = "normal", sigma = 0.03 }      # normal, mean 0 unless given
    dx_m = { dist = "corners", bound = 0.1 }      # worst case: both ends +-bound
    dx_m = { dist = "triangular", bound = 0.1 }   # symmetric triangle on center +- bound
    dx_m = { dist = "arcsine", bound = 0.1 }      # a sinusoid of amplitude bound, random phase
    dx_m = { dist = "truncnormal", sigma = 0.03, bound = 0.06 }  # normal cut at mean +- bound
    dx_m = { dist = "lognormal", median = 1.0, sigma_ln = 0.1 }  # exp(ln median + sigma_ln z)
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

from montecarlo.engine.distributions import Distribution


class Strict(BaseModel):
    """Base of every study-file model: unknown keys, wrong types, NaN and infinity are errors."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, validate_default=True,
                              allow_inf_nan=False)


LARGEST = 1e6
"""Largest magnitude an error source's value, bound or sigma may have (any unit): beyond it a
number is a typo, not a calibration range."""


class FixedSource(Strict):
    dist: Literal["fixed"]
    value: float = Field(ge=-LARGEST, le=LARGEST)


class UniformSource(Strict):
    dist: Literal["uniform"]
    bound: float = Field(ge=0, le=LARGEST)
    center: float = Field(default=0.0, ge=-LARGEST, le=LARGEST)


class NormalSource(Strict):
    dist: Literal["normal"]
    sigma: float = Field(ge=0, le=LARGEST)
    mean: float = Field(default=0.0, ge=-LARGEST, le=LARGEST)


class CornersSource(Strict):
    dist: Literal["corners"]
    bound: float = Field(ge=0, le=LARGEST)
    center: float = Field(default=0.0, ge=-LARGEST, le=LARGEST)


class TriangularSource(Strict):
    dist: Literal["triangular"]
    bound: float = Field(ge=0, le=LARGEST)
    center: float = Field(default=0.0, ge=-LARGEST, le=LARGEST)


class ArcsineSource(Strict):
    dist: Literal["arcsine"]
    bound: float = Field(ge=0, le=LARGEST)
    center: float = Field(default=0.0, ge=-LARGEST, le=LARGEST)


class TruncnormalSource(Strict):
    dist: Literal["truncnormal"]
    sigma: float = Field(ge=0, le=LARGEST)
    bound: float = Field(gt=0, le=LARGEST)
    mean: float = Field(default=0.0, ge=-LARGEST, le=LARGEST)


class LognormalSource(Strict):
    dist: Literal["lognormal"]
    median: float = Field(gt=0, le=LARGEST)
    sigma_ln: float = Field(ge=0, le=5.0)


def _number_is_fixed(value: Any) -> Any:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return {"dist": "fixed", "value": value}
    return value


Source = Annotated[
    FixedSource | UniformSource | NormalSource | CornersSource | TriangularSource
    | ArcsineSource | TruncnormalSource | LognormalSource,
    Field(discriminator="dist"),
    BeforeValidator(_number_is_fixed),
]
"""A scalar error source: a number or a ``{dist = ...}`` table."""


def to_distribution(source: Source, scale: float = 1.0) -> Distribution:
    """Internal :class:`Distribution`, multiplied by ``scale`` (e.g. degrees -> radians)."""
    match source:
        case FixedSource(value=v):
            return Distribution("fixed", v * scale)
        case UniformSource(bound=b, center=c):
            return Distribution("uniform", c * scale, b * scale)
        case NormalSource(sigma=s, mean=m):
            return Distribution("normal", m * scale, s * scale)
        case CornersSource(bound=b, center=c):
            return Distribution("corners", c * scale, b * scale)
        case TriangularSource(bound=b, center=c):
            return Distribution("triangular", c * scale, b * scale)
        case ArcsineSource(bound=b, center=c):
            return Distribution("arcsine", c * scale, b * scale)
        case TruncnormalSource(sigma=s, bound=b, mean=m):
            if s == 0.0:
                return Distribution("fixed", m * scale)
            return Distribution("truncnormal", m * scale, s * scale, b / s)
        case LognormalSource(median=med, sigma_ln=s):
            if s == 0.0:
                return Distribution("fixed", med * scale)
            return Distribution("lognormal", 0.0, med * scale, s)
    raise TypeError(source)  # pragma: no cover
