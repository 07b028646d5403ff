"""The ground static-base calibration (seed 000, section 1) as a study system.

Study-file sections (units in the key names; angles in degrees at this edge only)::

    [sensor]    fov_deg = [90, 90], pixels = [512, 512]
    [mounting]  psi_deg, theta_deg, gamma_deg         true mounting angles: fixed or drawn
    [geometry]  L_m, H_m                              nominal range and height difference
    [errors]    evaluation = "sampled" | "worst_case"
                dx_m, dy_m, dh1_m                     lateral, range, height-reference errors
                dh_m                                  height-scale error (the paper's delta_b)
                pixel_px                              image error on each axis of each target
                pixel_relation = "common" | "independent" | rho   (between targets A and B)
    [solver]    variants = ["raw", "normalised"]

``evaluation = "worst_case"`` evaluates every bounded error source (uniform or corners) at both
ends of its bound; a normal source is then an error. With only corners and fixed values a grid
point runs exactly 2**k trials, the corners; its ``max`` is the worst case of Table 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from montecarlo import ground
from montecarlo.camera import Camera
from montecarlo.distributions import Distribution, Streams, corner_signs, correlated_pair
from montecarlo.invalid import count_by_reason
from montecarlo.metrics import AXIS_METRICS, ROTATION_METRICS
from montecarlo.schema import Source, Strict, to_distribution
from montecarlo.systems import BlockInvalid, BlockValues, Metric

PLACEMENT_SOURCES = ("dx_m", "dy_m", "dh1_m", "dh_m")
MOUNTING_SOURCES = ("psi_deg", "theta_deg", "gamma_deg")


class Sensor(Strict):
    fov_deg: list[float] = Field(min_length=2, max_length=2)
    pixels: list[int] = Field(min_length=2, max_length=2)

    @field_validator("fov_deg")
    @classmethod
    def _fov_below_180(cls, v: list[float]) -> list[float]:
        if not all(0.0 < f < 180.0 for f in v):
            raise ValueError("each field of view must lie in (0, 180) deg")
        return v

    @field_validator("pixels")
    @classmethod
    def _positive_pixels(cls, v: list[int]) -> list[int]:
        if not all(n > 0 for n in v):
            raise ValueError("pixel counts must be positive")
        return v


class Mounting(Strict):
    psi_deg: Source = 0.0
    theta_deg: Source = 0.0
    gamma_deg: Source = 0.0


class Geometry(Strict):
    L_m: float = Field(gt=0)
    H_m: float

    @field_validator("H_m")
    @classmethod
    def _nonzero_height(cls, v: float) -> float:
        if v == 0.0:
            raise ValueError("the height difference H must not be 0 (eq. (11) divides by it)")
        return v


class Errors(Strict):
    evaluation: Literal["sampled", "worst_case"] = "sampled"
    dx_m: Source = 0.0
    dy_m: Source = 0.0
    dh1_m: Source = 0.0
    dh_m: Source = 0.0
    pixel_px: Source = 0.0
    pixel_relation: Literal["common", "independent"] | float

    @field_validator("pixel_relation")
    @classmethod
    def _correlation_range(cls, v: str | float) -> str | float:
        if isinstance(v, float) and not -1.0 <= v <= 1.0:
            raise ValueError("a correlation must lie in [-1, 1]")
        return v

    @model_validator(mode="after")
    def _worst_case_needs_bounds(self) -> Errors:
        if self.evaluation == "worst_case":
            for name in (*PLACEMENT_SOURCES, "pixel_px"):
                try:
                    to_distribution(getattr(self, name)).worst_case()
                except ValueError as exc:
                    raise ValueError(f"{name}: {exc}") from None
            if isinstance(self.pixel_relation, float) and self.pixel_relation not in (0.0, 1.0):
                raise ValueError("worst case needs pixel_relation 'common' or 'independent'")
        return self


class Solver(Strict):
    variants: list[Literal["raw", "normalised"]] = Field(
        default_factory=lambda: ["raw", "normalised"], min_length=1)

    @field_validator("variants")
    @classmethod
    def _unique(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("variants must not repeat")
        return v


class GroundConfig(Strict):
    """The ground system's sections of a study file."""

    sensor: Sensor
    mounting: Mounting = Field(default_factory=Mounting)
    geometry: Geometry
    errors: Errors
    solver: Solver = Field(default_factory=Solver)


@dataclass(frozen=True)
class PreparedGround:
    """A grid point in internal units: radians, metres, pixels."""

    camera: Camera
    mounting: tuple[Distribution, Distribution, Distribution]
    L: float
    H: float
    placement: dict[str, Distribution]
    pixel: Distribution
    relation: str | float
    variants: tuple[str, ...]
    corners: tuple[str, ...]
    """Names of the corner sources, in the order of their sign bits."""


def _pixel_corner_names(relation: str | float) -> tuple[str, ...]:
    if relation in ("common", 1.0):
        return ("pixel_x", "pixel_z")
    return ("pixel_a_x", "pixel_a_z", "pixel_b_x", "pixel_b_z")


class GroundSystem:
    """Seed 000 ground calibration as a :class:`montecarlo.systems.System`."""

    name = "ground"
    config_model = GroundConfig
    default_block_size = 1 << 16

    def prepare(self, config: GroundConfig) -> PreparedGround:
        e = config.errors
        worst = e.evaluation == "worst_case"
        placement = {n: to_distribution(getattr(e, n)) for n in PLACEMENT_SOURCES}
        pixel = to_distribution(e.pixel_px)
        if worst:
            placement = {n: d.worst_case() for n, d in placement.items()}
            pixel = pixel.worst_case()
        mounting = tuple(to_distribution(getattr(config.mounting, n), np.pi / 180.0)
                         for n in MOUNTING_SOURCES)
        corners = [n for n, d in zip(MOUNTING_SOURCES, mounting, strict=True) if d.is_corner]
        corners += [n for n, d in placement.items() if d.is_corner]
        if pixel.is_corner:
            corners += _pixel_corner_names(e.pixel_relation)
        return PreparedGround(
            camera=Camera.from_degrees(*config.sensor.fov_deg, *config.sensor.pixels),
            mounting=mounting,  # type: ignore[arg-type]
            L=config.geometry.L_m, H=config.geometry.H_m,
            placement=placement, pixel=pixel, relation=e.pixel_relation,
            variants=tuple(config.solver.variants), corners=tuple(corners))

    def metrics(self, prepared: PreparedGround) -> list[tuple[str, Metric]]:
        rot = [Metric(n, label, "mrad", 1e3) for n, (_, label) in ROTATION_METRICS.items()]
        axis = [Metric(n, label, "mrad", 1e3, signed=True) for n, label in AXIS_METRICS.items()]
        return [(v, m) for v in prepared.variants for m in rot + axis]

    def trials_per_point(self, prepared: PreparedGround, requested: int) -> int:
        random = any(d.is_random for d in (*prepared.mounting, *prepared.placement.values(),
                                            prepared.pixel))
        return requested if random else 1 << len(prepared.corners)

    def _draw(self, prepared: PreparedGround, name: str, dist: Distribution, streams: Streams,
              signs: np.ndarray, n: int) -> np.ndarray:
        if dist.is_corner:
            return dist.from_standard(signs[prepared.corners.index(name)])
        if dist.is_random:
            return dist.from_standard(streams.standard(dist, name, n))
        return np.full(n, dist.location)

    def _pixel_errors(self, p: PreparedGround, streams: Streams, signs: np.ndarray, n: int
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Image errors of targets A and B, shape (n, 2) each [px]."""
        if p.pixel.is_corner:
            names = _pixel_corner_names(p.relation)
            s = [signs[p.corners.index(k)] for k in names]
            a = np.stack(s[:2], -1)
            b = a if len(s) == 2 else np.stack(s[2:], -1)
            return p.pixel.from_standard(a), p.pixel.from_standard(b)
        if p.pixel.is_random:
            xa, xb = correlated_pair(p.pixel, p.relation, streams, "pixel_x", n)
            za, zb = correlated_pair(p.pixel, p.relation, streams, "pixel_z", n)
            return (p.pixel.from_standard(np.stack([xa, za], -1)),
                    p.pixel.from_standard(np.stack([xb, zb], -1)))
        fixed = np.full((n, 2), p.pixel.location)
        return fixed, fixed

    def simulate_block(self, prepared: PreparedGround, streams: Streams, first_trial: int,
                       n: int) -> tuple[BlockValues, BlockInvalid]:
        p = prepared
        signs = corner_signs(first_trial, n, len(p.corners))
        true = tuple(self._draw(p, name, d, streams, signs, n)
                     for name, d in zip(MOUNTING_SOURCES, p.mounting, strict=True))
        errs = {k: self._draw(p, k, d, streams, signs, n) for k, d in p.placement.items()}
        pix_a, pix_b = self._pixel_errors(p, streams, signs, n)
        solutions = ground.simulate(
            p.camera, true, p.L, p.H, dx=errs["dx_m"], dy=errs["dy_m"], dh1=errs["dh1_m"],
            dh=errs["dh_m"], pixel_error_a=pix_a, pixel_error_b=pix_b, solvers=p.variants)
        values: BlockValues = {}
        invalid: BlockInvalid = {}
        for variant, sol in solutions.items():
            for metric, v in ground.solution_metrics(sol, true).items():
                values[(variant, metric)] = v
            counts = count_by_reason(sol.invalid)
            invalid[variant] = {"total": int(np.count_nonzero(sol.invalid)),
                                **{k: int(c) for k, c in counts.items() if c}}
        return values, invalid

    def describe(self, prepared: PreparedGround) -> list[str]:
        p = prepared
        rel = p.relation
        relation = {"common": "common to both targets (the paper's Table 1 assumption)",
                    "independent": "independent between targets (centroid noise)"}.get(
            rel, f"correlated between targets, rho = {rel}")  # type: ignore[arg-type]
        lines = [f"pixel error {relation}"]
        if p.corners:
            lines.append(f"worst case over {1 << len(p.corners)} corners of: "
                         + ", ".join(p.corners))
        return lines

