"""Error-source distributions and the random streams that feed them.

A source is fixed; uniform, symmetric triangular or arcsine on ``center +- bound``; normal
``N(mean, sigma^2)``, or the same truncated to ``mean +- bound``; lognormal with a median and
the standard deviation of its logarithm; or evaluated at the two corners ``center +- bound``
(worst case). Draws are unit variates first (``U[0, 1)`` for the bounded shapes, ``N(0, 1)`` for
the normal family, or corner signs), turned by a fixed monotone map into a standard variate and
then mapped affinely to the source's units. Common random numbers therefore give the same unit
draws at every grid point of a study, even where a sweep changes a source's shape.

Random streams are derived from one ``np.random.SeedSequence(seed)`` by spawn keys
``(point, block, source)`` -- or ``(block, source)`` with common random numbers -- so that a trial's
draws depend on which block of trials it belongs to, never on which worker or task ran it.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

Kind = Literal["fixed", "uniform", "triangular", "arcsine", "normal", "truncnormal",
               "lognormal", "corners"]

UNIFORM_BASED = ("uniform", "triangular", "arcsine")
"""Kinds drawn from U[0, 1) unit variates."""
NORMAL_BASED = ("normal", "truncnormal", "lognormal")
"""Kinds drawn from N(0, 1) unit variates."""


@dataclass(frozen=True)
class Distribution:
    """A scalar error source (SI units or degrees as the field's name says).

    A draw is ``location + scale * s``, with ``s`` the standard variate of the kind:

    ============  ===========================  ==========  ========================
    kind          s                            location    scale
    ============  ===========================  ==========  ========================
    fixed         0                            value       0
    uniform       uniform on [-1, 1]           centre      half-width (bound)
    triangular    triangular on [-1, 1]        centre      half-width (bound)
    arcsine       sin(phase), phase uniform    centre      amplitude (bound)
    normal        N(0, 1)                      mean        sigma
    truncnormal   N(0, 1) within +-shape       mean        sigma (shape = bound/sigma)
    lognormal     exp(shape * N(0, 1))         0           median (shape = sigma_ln)
    corners       -1 or +1                     centre      half-width (bound)
    ============  ===========================  ==========  ========================
    """

    kind: Kind
    location: float = 0.0
    scale: float = 0.0
    shape: float = 0.0

    @property
    def is_random(self) -> bool:
        return self.kind not in ("fixed", "corners") and self.scale != 0.0

    @property
    def is_corner(self) -> bool:
        return self.kind == "corners"

    @property
    def half_width(self) -> float | None:
        """Largest deviation from ``location`` (None if unbounded)."""
        if self.kind in ("uniform", "triangular", "arcsine", "corners"):
            return self.scale
        if self.kind == "truncnormal":
            return self.scale * self.shape
        if self.kind == "fixed" or not self.is_random:
            return 0.0
        return None

    def worst_case(self) -> Distribution:
        """The same bounds evaluated at their corners (uniform -> corners)."""
        if not self.is_random:
            return self
        half = self.half_width
        if half is None:
            raise ValueError(f"a {self.kind} source has no worst case; give it a bound "
                             "(uniform, triangular, arcsine or truncnormal)")
        return Distribution("corners", self.location, half)

    def standard(self, unit: np.ndarray) -> np.ndarray:
        """The kind's standard variate from its unit draws (U[0, 1) or N(0, 1)), in place."""
        if self.kind == "uniform":
            unit *= 2.0
            unit -= 1.0
        elif self.kind == "triangular":  # inverse CDF of the triangle on [-1, 1]
            low = unit < 0.5
            unit[...] = np.where(low, np.sqrt(2.0 * unit) - 1.0,
                                 1.0 - np.sqrt(2.0 * (1.0 - unit)))
        elif self.kind == "arcsine":
            unit[...] = np.sin(np.pi * (unit - 0.5))
        elif self.kind == "truncnormal":  # the normal's quantile, squeezed into +-shape
            from scipy import special

            tail = special.ndtr(-self.shape)
            width = 1.0 - 2.0 * tail
            # each half from its own tail, so that far tails keep their precision
            a = np.abs(unit)
            unit[...] = np.copysign(-special.ndtri(tail + special.ndtr(-a) * width), unit)
        elif self.kind == "lognormal":
            unit *= self.shape
            np.exp(unit, out=unit)
        return unit



def source_key(name: str) -> int:
    """Stable integer key of a source name for spawn keys (CRC-32, independent of order)."""
    return zlib.crc32(name.encode())


@dataclass(frozen=True)
class Streams:
    """Random streams of one block of trials.

    Each source has one stream per block; successive draws from a source continue its stream,
    so a block may be drawn in pieces and equal the same block drawn at once.

    Parameters
    ----------
    seed : int
        The study seed.
    point : int
        Grid point index.
    block : int
        Block index within the grid point.
    common : bool
        Common random numbers: the same streams at every grid point.
    """

    seed: int
    point: int
    block: int
    common: bool = True
    _generators: dict[str, np.random.Generator] = field(
        default_factory=dict, init=False, repr=False, compare=False)

    def generator(self, source: str) -> np.random.Generator:
        """The generator of one source in this block (created on first use, then continued)."""
        gen = self._generators.get(source)
        if gen is None:
            key: tuple[int, ...] = (self.block, source_key(source))
            if not self.common:
                key = (self.point, *key)
            seq = np.random.SeedSequence(self.seed, spawn_key=key)
            gen = self._generators[source] = np.random.Generator(np.random.PCG64(seq))
        return gen

    def fill_unit(self, dist: Distribution, source: str, out: np.ndarray) -> tuple[float, float]:
        """Fill ``out`` with draws of a random source before their affine map; return the map
        (a, b): the draws in the source's units are ``a * out + b``.

        A uniform source leaves its U[0, 1) draws (``a = 2 scale``, ``b = location - scale``);
        a normal one its N(0, 1) draws; the other kinds their standard variate
        (:meth:`Distribution.standard`) with ``a = scale``, ``b = location``.
        """
        gen = self.generator(source)
        if dist.kind in UNIFORM_BASED:
            gen.random(out=out)
        else:
            gen.standard_normal(out=out)
        if dist.kind == "uniform":
            return 2.0 * dist.scale, dist.location - dist.scale
        if dist.kind != "normal":
            dist.standard(out)
        return dist.scale, dist.location

    def fill(self, dist: Distribution, source: str, out: np.ndarray) -> np.ndarray:
        """Fill ``out`` with draws of a random source, in its own units."""
        a, b = self.fill_unit(dist, source, out)
        out *= a
        out += b
        return out


def corner_signs(first_trial: int, n: int, n_corners: int) -> np.ndarray:
    """Signs (+-1) of ``n_corners`` corner sources for trials ``first_trial .. first_trial+n-1``.

    Trial ``t`` sits at corner ``t mod 2**n_corners``: bit ``j`` of that number (0 -> -1, 1 -> +1)
    is the sign of corner source ``j``. Returns shape (n_corners, n).
    """
    if n_corners == 0:
        return np.empty((0, n))
    corner = (np.arange(first_trial, first_trial + n) % (1 << n_corners)).astype(np.int64)
    bits = (corner[None, :] >> np.arange(n_corners)[:, None]) & 1
    return 2.0 * bits - 1.0


def fill_pair(dist: Distribution, relation: str | float, streams: Streams, source: str,
              out_a: np.ndarray, out_b: np.ndarray) -> None:
    """Draws of one random error source as seen by two targets, A and B, in place.

    ``relation`` is "common" (B = A), "independent", or a correlation coefficient rho in [-1, 1].
    A's values are the same whatever the relation (they come from stream ``source + ':a'``).
    With standardised draws z: normal sources ``z_B = rho z_A + sqrt(1 - rho^2) z_2``; uniform
    sources keep uniform marginals through a Gaussian copula whose normal correlation
    ``2 sin(pi rho / 6)`` gives the uniforms a Pearson correlation of exactly rho.
    """
    rho = {"common": 1.0, "independent": 0.0}.get(relation, relation)  # type: ignore[arg-type]
    if rho not in (0.0, 1.0) and dist.kind not in ("uniform", "normal"):
        raise ValueError(f"a correlation between targets needs a uniform or normal source, "
                         f"not {dist.kind}")
    streams.fill(dist, source + ":a", out_a)
    if rho == 1.0:
        out_b[...] = out_a
        return
    streams.fill(dist, source + ":b", out_b)
    if rho == 0.0 or dist.scale == 0.0:
        return
    z_a = (out_a - dist.location) / dist.scale
    z_2 = (out_b - dist.location) / dist.scale
    if dist.kind == "normal":
        z_b = rho * z_a + np.sqrt(1.0 - rho**2) * z_2
    else:
        from scipy import special

        r = 2.0 * np.sin(np.pi * rho / 6.0)
        n_a = special.ndtri((z_a + 1.0) / 2.0)
        n_2 = special.ndtri((z_2 + 1.0) / 2.0)
        z_b = 2.0 * special.ndtr(r * n_a + np.sqrt(1.0 - r**2) * n_2) - 1.0
    out_b[...] = dist.location + dist.scale * z_b
