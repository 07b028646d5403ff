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

import dataclasses
import functools
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from montecarlo.engine.aggregate import PointStats
from montecarlo.engine.distributions import Distribution, Streams, corner_signs, fill_pair
from montecarlo.engine.schema import Source, Strict, to_distribution
from montecarlo.engine.system import BlockInvalid, BlockValues, Metric
from montecarlo.geometry.camera import Camera
from montecarlo.geometry.invalid import reason_counts
from montecarlo.geometry.metrics import AXIS_METRICS, ROTATION_METRICS
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed000 import ground
from montecarlo.seed000.ground import SOLVERS

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
    L_m: float = Field(gt=0, le=1e5)
    H_m: float = Field(ge=-1e4, le=1e4)

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
        pixel = to_distribution(self.pixel_px)
        if isinstance(self.pixel_relation, float) and self.pixel_relation not in (0.0, 1.0) \
                and pixel.is_random and pixel.kind not in ("uniform", "normal"):
            raise ValueError(f"pixel_relation {self.pixel_relation}: a correlation between "
                             f"targets needs a uniform or normal pixel_px, not {pixel.kind}")
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


STAGES = ("draws", "solve", "metrics", "accumulation")
"""Stages of the fast path, as :meth:`GroundSystem.accumulate_block` times them."""


@functools.lru_cache(maxsize=2)
def _draw_buffers(n: int) -> np.ndarray:
    """Draw buffers of one block for the fast path, reused by every block of a process."""
    return np.empty((9, n))


@functools.lru_cache(maxsize=4)
def _scratch(m: int) -> tuple[np.ndarray, ...]:
    """Work buffers of the fast kernel for m trials (flags, fields, bins, the kernel's view of
    fields), reused for every block of a process: fresh megabyte-sized buffers would cost a
    page fault per 4 KB each time."""
    from montecarlo.seed000 import ground_kernel as gk

    fields = np.empty((2 * gk.N_FIELDS, m))
    bins = np.empty(min(m, gk.SUB_CHUNK), np.int32)
    return np.empty((2, m), np.uint16), fields, bins, gk.output_rows(fields)


def _fixed_mounting(psi: float, theta: float, gamma: float) -> np.ndarray:
    """C_b^a (9,) row-major of fixed mounting angles [rad], computed once for all blocks (a
    writeable copy: a read-only array would be another numba signature to compile)."""
    return _mounting_once(psi, theta, gamma).copy()


@functools.lru_cache(maxsize=16)
def _mounting_once(psi: float, theta: float, gamma: float) -> np.ndarray:
    return mounting_matrix(psi, theta, gamma).reshape(9)


class GroundSystem:
    """Seed 000 ground calibration as a :class:`montecarlo.systems.System`."""

    name = "ground"
    config_model = GroundConfig
    default_block_size = 1 << 16
    seconds_per_trial = 2e-7
    """The fused kernel on one core (``montecarlo bench``), with some margin."""
    reference_seconds_per_trial = 4e-6
    """The literal reference path, about 20 times the kernel's."""

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

    def is_sampled(self, prepared: PreparedGround) -> bool:
        return any(d.is_random for d in (*prepared.mounting, *prepared.placement.values(),
                                         prepared.pixel))

    def trials_per_point(self, prepared: PreparedGround, requested: int) -> int:
        return requested if self.is_sampled(prepared) else 1 << len(prepared.corners)

    def nominal(self, prepared: PreparedGround) -> PreparedGround:
        """The grid point with every error source fixed at its centre (its location), corner
        sources included: the nominal case (:mod:`montecarlo.engine.nominal`)."""
        def centre(d: Distribution) -> Distribution:  # a lognormal's centre is its median
            return Distribution("fixed", d.location + (d.scale if d.kind == "lognormal" else 0.0))

        return dataclasses.replace(
            prepared, mounting=tuple(centre(d) for d in prepared.mounting),  # type: ignore
            placement={k: centre(d) for k, d in prepared.placement.items()},
            pixel=centre(prepared.pixel), corners=())

    def unit_draws(self, p: PreparedGround, streams: Streams, first_trial: int, n: int,
                   buffers: np.ndarray | None = None
                   ) -> tuple[tuple[np.ndarray | float, ...], list[np.ndarray], np.ndarray]:
        """The trials of a block as unit draws and their affine maps.

        ``buffers`` (9, n), if given, holds the draws (reused between blocks by the fast path).

        Returns
        -------
        true : (psi, theta, gamma) [rad], floats if fixed, else arrays of shape (n,)
        rows : 8 arrays of shape (n,): unit draws (U[0, 1), N(0, 1) or corner signs) of dx,
            dy, dh1, dh, then of the pixel errors of A (x, z) and of B (x, z). Rows may be
            shared (B's are A's for a common pixel error).
        affine : (2, 8): row k in its units [m] or [px] is ``affine[0, k] * rows[k] +
            affine[1, k]``.
        """
        signs = corner_signs(first_trial, n, len(p.corners))
        free = iter(np.empty((9, n)) if buffers is None else buffers)
        zeros = next(free)
        zeroed = False

        def zero_row() -> np.ndarray:  # filled only if a source is fixed
            nonlocal zeroed
            if not zeroed:
                zeros[...] = 0.0
                zeroed = True
            return zeros

        def unit(name: str, dist: Distribution) -> tuple[np.ndarray, float, float]:
            if dist.is_corner:
                return signs[p.corners.index(name)], dist.scale, dist.location
            if dist.is_random:
                u = next(free)
                return (u, *streams.fill_unit(dist, name, u))
            return zero_row(), 0.0, dist.location

        true: list[np.ndarray | float] = []
        for name, dist in zip(MOUNTING_SOURCES, p.mounting, strict=True):
            if dist.is_corner or dist.is_random:
                u = signs[p.corners.index(name)] if dist.is_corner else \
                    streams.fill(dist, name, np.empty(n))
                true.append(dist.location + dist.scale * u if dist.is_corner else u)
            else:
                true.append(dist.location)
        cols = [unit(name, dist) for name, dist in p.placement.items()]
        px = p.pixel
        if px.is_corner:
            names = _pixel_corner_names(p.relation)
            pix = [(signs[p.corners.index(k)], px.scale, px.location) for k in names]
            cols += pix if len(pix) == 4 else pix * 2
        elif px.is_random and p.relation in ("common", "independent", 0.0, 1.0):
            pix_a = [unit("pixel_x:a", px), unit("pixel_z:a", px)]
            cols += pix_a + (pix_a if p.relation in ("common", 1.0)
                             else [unit("pixel_x:b", px), unit("pixel_z:b", px)])
        elif px.is_random:  # correlated: values through the copula of fill_pair
            vals = np.empty((4, n))
            fill_pair(px, p.relation, streams, "pixel_x", vals[0], vals[2])
            fill_pair(px, p.relation, streams, "pixel_z", vals[1], vals[3])
            cols += [(v, 1.0, 0.0) for v in vals]
        else:
            cols += [(zero_row(), 0.0, px.location)] * 4
        rows = [c[0] for c in cols]
        affine = np.array([[c[1] for c in cols], [c[2] for c in cols]])
        return tuple(true), rows, affine

    def draws(self, p: PreparedGround, streams: Streams, first_trial: int, n: int
              ) -> tuple[tuple[np.ndarray | float, ...], np.ndarray]:
        """True mounting angles [rad] and the errors of a block: (8, n) rows dx, dy, dh1, dh
        [m], then the pixel errors of A (x, z) and of B (x, z) [px]."""
        true, rows, affine = self.unit_draws(p, streams, first_trial, n)
        return true, affine[0][:, None] * np.stack(rows) + affine[1][:, None]

    def simulate_block(self, prepared: PreparedGround, streams: Streams, first_trial: int,
                       n: int, reference: bool = False) -> tuple[BlockValues, BlockInvalid]:
        """Per-trial metrics through the literal reference (:mod:`montecarlo.seed000.ground`),
        whatever ``reference`` says (the fast path is :meth:`accumulate_block`)."""
        p = prepared
        true, e = self.draws(p, streams, first_trial, n)
        solutions = ground.simulate(
            p.camera, true, p.L, p.H, dx=e[0], dy=e[1], dh1=e[2], dh=e[3],
            pixel_error_a=e[4:6].T, pixel_error_b=e[6:8].T, solvers=p.variants)
        values: BlockValues = {}
        invalid: BlockInvalid = {}
        for variant, sol in solutions.items():
            for metric, v in ground.solution_metrics(sol, true).items():
                values[(variant, metric)] = v
            invalid[variant] = reason_counts(np.bincount(sol.invalid, minlength=256))
        return values, invalid

    def accumulate_block(self, prepared: PreparedGround, streams: Streams, first_trial: int,
                         n: int, block: int, stats: PointStats,
                         clock: dict[str, float] | None = None) -> None:
        """The same trials through the fused kernel, aggregated straight into ``stats``.

        ``clock``, if given, receives the CPU seconds of the calling thread spent in each stage
        (``draws``, ``solve``, ``metrics``, ``accumulation``; added to what it holds), for the
        benchmark's roofline. The kernels run in the calling thread, and its CPU time leaves
        out the time other processes take from it on a busy machine.
        """
        from montecarlo.engine import accumulate  # numba: loaded only where kernels run
        from montecarlo.seed000 import ground_kernel as gk

        p = prepared
        keys = [(SOLVERS[v], m) for v, m in gk.VALUE_ROWS]  # both variants are computed
        hist = stats.histogram_matrix(keys, {k for k in keys if k[0] in p.variants})
        cam = p.camera
        acc = accumulate.new_stats(len(keys))
        flag_counts = np.zeros((2, 256), np.int64)
        tick = time.thread_time if clock is not None else None
        # Drawn, solved and reduced to metrics SOLVE_CHUNK trials at a time (a source's
        # generator gives the same numbers in one call as in several); the statistics are
        # merged every SUB_CHUNK trials whatever SOLVE_CHUNK is, so they do not depend on it.
        for s in range(0, n, gk.SOLVE_CHUNK):
            t0 = tick() if tick else 0.0
            m = min(gk.SOLVE_CHUNK, n - s)
            flags, fields, bins, out_rows = _scratch(m)
            true, rows, affine = self.unit_draws(p, streams, first_trial + s, m,
                                                 _draw_buffers(m))
            fixed = all(isinstance(a, float) for a in true)
            C = _fixed_mounting(*true) if fixed else \
                np.ascontiguousarray(mounting_matrix(*true).reshape(m, 9).T)
            t1 = tick() if tick else 0.0
            gk.solve_chunk(C, p.L, p.H, float(cam.k_x), float(cam.k_z), cam.n_x / 2.0,
                           cam.n_z / 2.0, rows, affine, flags, fields, out_rows)
            t2 = tick() if tick else 0.0
            gk.metrics_in_place(fields)
            t3 = tick() if tick else 0.0
            for i in range(2):
                if flags[i].any():
                    flag_counts[i] += np.bincount(flags[i], minlength=256)
            accumulate.accumulate(fields, gk.METRIC_ROWS, hist, acc, bins, gk.SUB_CHUNK)
            if tick and clock is not None:
                t4 = tick()
                for stage, spent in zip(STAGES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3),
                                        strict=True):
                    clock[stage] = clock.get(stage, 0.0) + spent
        moments = {key: tuple(acc[r]) for r, key in enumerate(keys) if key[0] in p.variants}
        invalid = {v: reason_counts(flag_counts[i]) for i, v in enumerate(SOLVERS)
                   if v in p.variants}
        stats.add_block_summary(block, moments, invalid, n)

    def first_use_note(self, prepared: list[PreparedGround]) -> str | None:
        """What the first run after an install or a change of the kernel will compile."""
        from montecarlo.engine import accumulate
        from montecarlo.seed000 import ground_kernel as gk

        varying = {any(d.is_random or d.is_corner for d in p.mounting) for p in prepared}
        if accumulate.is_cached() and all(gk.is_cached(v) for v in varying):
            return None
        return ("compiling the fast ground kernel with numba (first use after an install or a "
                "change: several seconds, then cached)")

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

