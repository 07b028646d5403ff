"""Error-source distributions and the random streams that feed them.

A source is fixed, uniform on ``center +- bound``, normal ``N(mean, sigma^2)``, or evaluated at
the two corners ``center +- bound`` (worst case). Draws are unit variates first (``U[0, 1)``,
``N(0, 1)`` or corner signs) mapped affinely to the source's units, so that common random
numbers give the same unit draws at every grid point of a study.

Random streams are derived from one ``np.random.SeedSequence(seed)`` by spawn keys
``(point, block, source)`` -- or ``(block, source)`` with common random numbers -- so that a trial's
draws depend on which block of trials it belongs to, never on which worker or task ran it.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

Kind = Literal["fixed", "uniform", "normal", "corners"]


@dataclass(frozen=True)
class Distribution:
    """A scalar error source (SI units or degrees as the field's name says).

    Attributes
    ----------
    kind : {"fixed", "uniform", "normal", "corners"}
    location : float
        The fixed value, or the centre / mean.
    scale : float
        Half-width (uniform, corners), standard deviation (normal), 0 (fixed).
    """

    kind: Kind
    location: float = 0.0
    scale: float = 0.0

    @property
    def is_random(self) -> bool:
        return self.kind in ("uniform", "normal") and self.scale != 0.0

    @property
    def is_corner(self) -> bool:
        return self.kind == "corners"

    def worst_case(self) -> Distribution:
        """The same bounds evaluated at their corners (uniform -> corners)."""
        if self.kind == "normal" and self.scale != 0.0:
            raise ValueError("a normal source has no worst case; give it a bound (uniform)")
        if self.kind == "uniform":
            return Distribution("corners", self.location, self.scale)
        return self



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
        """Fill ``out`` with unit draws of a random source; return (a, b), its affine map.

        The draws in the source's units are ``a * out + b``: for a uniform source U[0, 1) with
        ``a = 2 scale``, ``b = location - scale``; for a normal source N(0, 1) with
        ``a = scale``, ``b = location``.
        """
        gen = self.generator(source)
        if dist.kind == "uniform":
            gen.random(out=out)
            return 2.0 * dist.scale, dist.location - dist.scale
        gen.standard_normal(out=out)
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
