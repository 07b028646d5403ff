"""The nominal case of a grid point: every error source at its centre, one trial, no sampling.

monaco runs a zero-error case before the spread; so do we. What a design gives with every error
at its centre sits beside the statistics of the sampled trials, and a wrong geometry shows at
a glance: for a calibration whose errors are all centred on zero, the nominal error is zero.

"Centre" is the location of the source's distribution: the centre of a uniform, triangular,
arcsine or corner source, the mean of a (truncated) normal, the median of a lognormal. A
system gets its nominal case

* from :meth:`System.nominal`, if it has one (the ground system: every source made fixed at its
  location, corners included), run through its ``simulate_block``;
* otherwise by running one trial with :class:`CentredGenerator` in place of the random
  generator: a normal or uniform draw returns its centre. A system that draws anything without
  a centre (a random sign, a random choice, a permutation, an integer seed) has no nominal case;
  its nominal values are NaN.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from montecarlo.engine.distributions import Distribution, Streams


class NoCentre(Exception):
    """A draw that has no centre (a sign, a choice, a permutation, an integer)."""


class CentredGenerator:
    """Stands in for :class:`numpy.random.Generator`: every draw is its distribution's centre.

    ``standard_normal`` gives 0, ``normal(loc, scale)`` gives ``loc``, ``uniform(low, high)``
    ``(low + high) / 2``, ``random`` 0.5; ``spawn`` gives more of the same. Any other draw
    raises :class:`NoCentre`.
    """

    def standard_normal(self, size: Any = None, dtype: Any = np.float64,
                        out: np.ndarray | None = None) -> Any:
        return self._fill(0.0, size, out)

    def normal(self, loc: Any = 0.0, scale: Any = 1.0, size: Any = None) -> Any:
        return self._fill(loc, size, None)

    def uniform(self, low: Any = 0.0, high: Any = 1.0, size: Any = None) -> Any:
        return self._fill(0.5 * (np.asarray(low, float) + np.asarray(high, float)), size, None)

    def random(self, size: Any = None, dtype: Any = np.float64,
               out: np.ndarray | None = None) -> Any:
        return self._fill(0.5, size, out)

    def spawn(self, n: int) -> list[CentredGenerator]:
        return [CentredGenerator() for _ in range(n)]

    @staticmethod
    def _fill(value: Any, size: Any, out: np.ndarray | None) -> Any:
        if out is not None:
            out[...] = value
            return out
        if size is None:
            return float(value) if np.ndim(value) == 0 else np.asarray(value, float)
        return np.broadcast_to(np.asarray(value, float), size).copy()

    def __getattr__(self, name: str) -> Any:
        raise NoCentre(f"the draw {name!r} has no centre")


class NominalStreams(Streams):
    """Streams whose every draw is at its source's centre (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__(seed=0, point=0, block=0)

    def generator(self, source: str) -> Any:
        return CentredGenerator()

    def fill_unit(self, dist: Distribution, source: str, out: np.ndarray) -> tuple[float, float]:
        """The unit draw whose map is the centre: U = 0.5 for the bounded kinds, 0 for the
        normal family (a lognormal's 0 maps to its median)."""
        out[...] = 0.5 if dist.kind in ("uniform", "triangular", "arcsine") else 0.0
        if dist.kind == "uniform":
            return 2.0 * dist.scale, dist.location - dist.scale
        if dist.kind != "normal":
            dist.standard(out)
        return dist.scale, dist.location


def nominal_values(system: Any, prepared: Any) -> dict[tuple[str, str], float]:
    """Every (variant, metric) of one grid point in its nominal case [SI units, radians];
    NaN where the system has no nominal case or the case has no solution."""
    keys = [(v, m.name) for v, m in system.metrics(prepared)]
    centred = getattr(system, "nominal", None)
    try:
        values, _ = system.simulate_block(prepared if centred is None else centred(prepared),
                                          NominalStreams(), 0, 1)
    except NoCentre:
        return dict.fromkeys(keys, math.nan)
    return {k: float(np.asarray(values[k], float).reshape(-1)[0]) if k in values else math.nan
            for k in keys}
