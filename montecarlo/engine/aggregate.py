"""Streaming statistics of per-trial metrics, identical however the trials were split into tasks.

Memory does not grow with the number of trials: each metric keeps

* its count, mean and sum of squared deviations (``n, mean, m2``), combined block after block in
  block order with Chan's formula, so the result does not depend on how blocks were grouped
  into tasks or in which order they arrived; blocks that arrive early wait until the ones before
  them are in (a window of about the tasks in flight);
* the minimum and maximum;
* an integer histogram on a logarithmic grid (1024 bins per octave, relative width 2**-10,
  from 2**-40 to 2**16 in magnitude, both signs), from which percentiles are read to within half
  a bin (0.05 %); integer counts add exactly.

Percentiles use the inverted-CDF definition (the ``ceil(p n)``-th smallest value). Their
distribution-free confidence intervals are order statistics ``[X_(r), X_(s)]`` whose ranks come
from the binomial distribution of the number of trials below the true percentile; the interval
ends are read conservatively (outer bin edges), so the coverage is at least the nominal level.
Where too few trials exist for an interval end, it is NaN: more trials are needed.

A trial without a value (an invalid geometry, a fit that failed) is counted, never dropped: the
summary gives the fraction of such trials, and a spec verdict treats them as larger than any
limit (a calibration that cannot be solved is a failed calibration).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from montecarlo.engine.superquantile import CVAR_DEFAULT, cvar_level, superquantile

if TYPE_CHECKING:  # pandas and scipy are imported only where summaries are made
    import pandas as pd

MANTISSA_BITS = 10
MIN_EXP = -40
MAX_EXP = 16
BIN_SHIFT = 52 - MANTISSA_BITS
"""Right shift of a float's bits that leaves its exponent and leading mantissa bits."""
BIN_BASE = int(np.float64(2.0**MIN_EXP).view(np.int64)) >> BIN_SHIFT
"""Shifted bits of the smallest magnitude bin's lower edge."""
N_MAG = (MAX_EXP - MIN_EXP) << MANTISSA_BITS
"""Magnitude bins per sign; the histogram has 2 * N_MAG + 3 bins (see :func:`bin_index`)."""
N_BINS = 2 * N_MAG + 3
ZERO_BIN = N_MAG + 1

PERCENTILES = (0.50, 0.90, 0.95, 0.99)
PERCENTILE_TAGS = tuple(f"p{round(100 * p)}" for p in PERCENTILES)
VALUE_COLUMNS = ["mean", "std", *(f"{t}{e}" for t in PERCENTILE_TAGS for e in ("", "_lo", "_hi")),
                 *(f"{CVAR_DEFAULT}{e}" for e in ("", "_lo", "_hi")), "max"]
"""Summary columns that carry values in the metric's unit (the rest are counts and labels)."""
SPEC_COLUMNS = ["spec_value", "spec_lo", "spec_hi"]
"""Summary columns of a spec's statistic over all trials, in the metric's unit."""


def bin_index(x: np.ndarray) -> np.ndarray:
    """Histogram bin of each finite value.

    Layout: 0 = values <= -2**MAX_EXP, 1 .. N_MAG = negative magnitudes (largest first),
    ZERO_BIN = |x| < 2**MIN_EXP, then positive magnitudes, and N_BINS - 1 = values >= 2**MAX_EXP.
    """
    a = np.abs(x)
    k = (a.view(np.int64) >> BIN_SHIFT) - BIN_BASE
    k = np.clip(k, -1, N_MAG)  # -1: below range (zero bin), N_MAG: overflow
    pos = ZERO_BIN + 1 + k
    neg = ZERO_BIN - 1 - k
    idx = np.where(x < 0, neg, pos)
    return np.where(k < 0, ZERO_BIN, idx).astype(np.int64)


def _magnitude_edges() -> np.ndarray:
    """Lower edges of the N_MAG magnitude bins and the upper edge of the last, [N_MAG + 1]."""
    bits = (np.arange(N_MAG + 1, dtype=np.int64) + BIN_BASE) << BIN_SHIFT
    return bits.view(np.float64)


MAG_EDGES = _magnitude_edges()


def abs_histogram(hist: np.ndarray) -> np.ndarray:
    """Fold a signed histogram into magnitudes: [zero bin, N_MAG magnitude bins, overflow]."""
    return np.concatenate([[hist[ZERO_BIN]], hist[ZERO_BIN + 1:] + hist[:ZERO_BIN][::-1]])


def _signed_bin_edges() -> tuple[np.ndarray, np.ndarray]:
    lo_mag, hi_mag = MAG_EDGES[:-1], MAG_EDGES[1:]
    lower = np.concatenate([[-np.inf], -hi_mag[::-1], [-MAG_EDGES[0]], lo_mag, [MAG_EDGES[-1]]])
    upper = np.concatenate([[-MAG_EDGES[-1]], -lo_mag[::-1], [MAG_EDGES[0]], hi_mag, [np.inf]])
    return lower, upper


SIGNED_LOWER, SIGNED_UPPER = _signed_bin_edges()
"""Edges of every bin of the signed histogram (infinite at the ends)."""
ABS_LOWER = np.concatenate([[0.0], MAG_EDGES])
ABS_UPPER = np.concatenate([MAG_EDGES, [np.inf]])
"""Edges of every bin of the magnitude histogram of :func:`abs_histogram`."""


@functools.lru_cache(maxsize=4096)
def order_statistic_ranks(n: int, p: float, confidence: float) -> tuple[int, int, int]:
    """1-based ranks (estimate, lower, upper) for the p-quantile of n trials.

    The estimate is rank ``ceil(p n)``. ``[X_(r), X_(s)]`` covers the true quantile with
    probability ``P(r <= B <= s - 1) >= confidence``, B ~ Binomial(n, p). A rank outside
    1..n is returned as 0 or n + 1 (that end of the interval cannot be bounded).
    """
    alpha = 1.0 - confidence
    k = max(1, math.ceil(p * n - 1e-9))
    r = binomial_quantile(alpha / 2.0, n, p)
    s = binomial_quantile(1.0 - alpha / 2.0, n, p) + 1
    return k, r, min(s, n + 1)


def binomial_quantile(q: float, n: int, p: float) -> int:
    """Smallest k with ``P(B <= k) >= q``, B ~ Binomial(n, p) (as ``scipy.stats.binom.ppf``).

    Bisection on the CDF (``scipy.special.bdtr``), which imports in a fraction of the time
    ``scipy.stats`` takes. A CDF within 1e-12 (relative) of ``q`` counts as reaching it, so
    that exact ties (n = 41, p = q = 0.5) are not lost to rounding.
    """
    from scipy.special import bdtr

    lo, hi = -1, n  # CDF(lo) < q <= CDF(hi) = 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if bdtr(mid, n, p) >= q * (1.0 - 1e-12):
            hi = mid
        else:
            lo = mid
    return hi


COARSE_SHIFT = 5
"""Plots get 2**(MANTISSA_BITS - COARSE_SHIFT) = 32 bins per octave (3 % wide)."""


Moments = tuple[int, float, float]
"""(count, mean, sum of squared deviations) of some values."""


def combine(a: Moments, b: Moments) -> Moments:
    """Moments of the union of two sets of values (Chan, Golub and LeVeque, 1979)."""
    n = a[0] + b[0]
    if a[0] == 0 or b[0] == 0:
        return a if b[0] == 0 else b
    delta = b[1] - a[1]
    return n, a[1] + delta * b[0] / n, a[2] + b[2] + delta * delta * a[0] * b[0] / n


@dataclass
class MetricStats:
    """Streaming statistics of one metric while its grid point is being computed.

    ``folded`` holds the moments of blocks ``0 .. next_block - 1``; ``pending`` the blocks that
    arrived before a block ahead of them.
    """

    pending: dict[int, Moments] = field(default_factory=dict)
    folded: Moments = (0, 0.0, 0.0)
    next_block: int = 0
    minimum: float = math.inf
    maximum: float = -math.inf
    hist: np.ndarray = field(default_factory=lambda: np.zeros(N_BINS, np.int64))

    def __getstate__(self) -> dict:
        """Pickle the histogram sparsely (tasks send their statistics between processes)."""
        nz = np.flatnonzero(self.hist)
        return {**self.__dict__, "hist": (nz, self.hist[nz])}

    def __setstate__(self, state: dict) -> None:
        nz, counts = state["hist"]
        hist = np.zeros(N_BINS, np.int64)
        hist[nz] = counts
        self.__dict__.update({**state, "hist": hist})

    def add_moments(self, block: int, moments: Moments) -> None:
        """Add the moments of one block of valid values (count 0 for a block without any)."""
        if block < self.next_block or block in self.pending:
            raise ValueError(f"block {block} added twice")
        self.pending[block] = moments
        self._fold()

    def _fold(self) -> None:
        while self.next_block in self.pending:
            self.folded = combine(self.folded, self.pending.pop(self.next_block))
            self.next_block += 1

    def add_block(self, block: int, values: np.ndarray) -> None:
        """Add the finite values of one block (NaN marks a trial without a value, skipped)."""
        x = values[np.isfinite(values)]
        if x.size:
            mean = float(np.mean(x))
            self.add_moments(block, (x.size, mean, float(np.sum((x - mean) ** 2))))
            self.minimum = min(self.minimum, float(x.min()))
            self.maximum = max(self.maximum, float(x.max()))
            self.hist += np.bincount(bin_index(x), minlength=N_BINS)
        else:
            self.add_moments(block, (0, 0.0, 0.0))

    def merge(self, other: MetricStats) -> None:
        """Add another accumulator's blocks (blocks must not overlap)."""
        if other.next_block:
            if self.next_block or any(b < other.next_block for b in self.pending):
                raise ValueError(f"blocks below {other.next_block} added twice")
            self.folded, self.next_block = other.folded, other.next_block
            self._fold()
        for b, m in sorted(other.pending.items()):
            self.add_moments(b, m)
        self.minimum = min(self.minimum, other.minimum)
        self.maximum = max(self.maximum, other.maximum)
        self.hist += other.hist

    def moments(self) -> Moments:
        """Moments of every block added, combined in block order."""
        out = self.folded
        for _, m in sorted(self.pending.items()):
            out = combine(out, m)
        return out

    @property
    def count(self) -> int:
        return self.moments()[0]

    def mean_std(self) -> tuple[float, float]:
        n, mean, m2 = self.moments()
        if n == 0:
            return math.nan, math.nan
        return mean, math.sqrt(m2 / (n - 1)) if n > 1 else math.nan

    def value_range(self, of_abs: bool) -> tuple[float, float]:
        """Smallest and largest value (or magnitude)."""
        if not of_abs:
            return self.minimum, self.maximum
        hi = max(abs(self.minimum), abs(self.maximum))
        lo = 0.0 if self.minimum <= 0.0 <= self.maximum else min(abs(self.minimum),
                                                                  abs(self.maximum))
        return lo, hi

    def quantile(self, p: float, of_abs: bool, confidence: float, censored: int = 0
                 ) -> tuple[float, float, float]:
        """(estimate, lower, upper) of the p-quantile of the values or of their magnitudes.

        ``censored`` trials without a value count as larger than every value: a rank that
        falls among them gives +inf.
        """
        return self.quantiles((p,), of_abs, confidence, censored)[0]

    def quantiles(self, ps: tuple[float, ...], of_abs: bool, confidence: float,
                  censored: int = 0) -> list[tuple[float, float, float]]:
        """:meth:`quantile` of several probabilities, the cumulative histogram built once."""
        count = self.count
        n = count + censored
        if n == 0:
            return [(math.nan, math.nan, math.nan)] * len(ps)
        if of_abs:
            counts, lower, upper = abs_histogram(self.hist), ABS_LOWER, ABS_UPPER
        else:
            counts, lower, upper = self.hist, SIGNED_LOWER, SIGNED_UPPER
        lo_val, hi_val = self.value_range(of_abs)
        cum = np.cumsum(counts)

        def lower_edge(rank: int) -> float:
            return float(max(lower[np.searchsorted(cum, rank)], lo_val)) \
                if rank <= count else math.inf

        def upper_edge(rank: int) -> float:
            return float(min(upper[np.searchsorted(cum, rank)], hi_val)) \
                if rank <= count else math.inf

        out = []
        for p in ps:
            k, r, s = order_statistic_ranks(n, p, confidence)
            if k <= count:
                b = int(np.searchsorted(cum, k))
                est = float(np.clip(0.5 * (lower[b] + upper[b]), lo_val, hi_val))
            else:
                est = math.inf
            lo = lower_edge(r) if r >= 1 else math.nan
            hi = upper_edge(s) if s <= n else math.nan
            out.append((est, lo, hi))
        return out

    def superquantile(self, level: float, of_abs: bool, confidence: float
                      ) -> tuple[float, float, float]:
        """(estimate, lower, upper) of the mean of the worst ``1 - level`` of the values (or
        magnitudes); see :mod:`.superquantile`."""
        if of_abs:
            counts, lower, upper = abs_histogram(self.hist), ABS_LOWER, ABS_UPPER
        else:
            counts, lower, upper = self.hist, SIGNED_LOWER, SIGNED_UPPER
        lo_val, hi_val = self.value_range(of_abs)
        return superquantile(counts, lower, upper, lo_val, hi_val, level, confidence)

    def coarse_histogram(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Magnitude histogram at 32 bins per octave: occupied (lower, upper, counts)."""
        a = abs_histogram(self.hist)
        mag = a[1:-1].reshape(-1, 1 << COARSE_SHIFT).sum(axis=1)
        edges = MAG_EDGES[:: 1 << COARSE_SHIFT]
        lower = np.concatenate([[0.0], edges[:-1], [MAG_EDGES[-1]]])
        upper = np.concatenate([[MAG_EDGES[0]], edges[1:], [np.inf]])
        counts = np.concatenate([[a[0]], mag, [a[-1]]])
        nz = np.flatnonzero(counts)
        return lower[nz], upper[nz], counts[nz]


@dataclass(frozen=True)
class PointResult:
    """What is kept of a finished grid point: its summary rows and coarse histograms.

    ``summary`` values are in SI units/radians; ``histograms`` maps (variant, metric) to the
    occupied magnitude bins (lower, upper, counts).
    """

    summary: pd.DataFrame
    histograms: dict[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class SpecCheck:
    """A requirement judged on every matching summary row: ``statistic`` of ``metric``
    (of ``variant``, or of every variant if None) at most ``limit`` [SI units, radians]."""

    metric: str
    variant: str | None
    statistic: str
    limit: float

    def applies(self, variant: str, metric: str) -> bool:
        return metric == self.metric and self.variant in (None, variant)


VERDICTS = ("meets", "fails", "undecided")
"""Spec verdicts: the whole confidence interval of the statistic below the limit, the whole
interval above it, or neither (more trials would decide)."""


@dataclass
class PointStats:
    """All metrics and invalid counts of one grid point, while it is being computed.

    ``metrics`` is keyed by (variant, metric); ``invalid`` by variant, holding the count of
    invalid trials per reason name plus ``"total"``; ``trials`` counts every trial added, with
    or without a value, and ``blocks`` the blocks added.
    """

    metrics: dict[tuple[str, str], MetricStats] = field(default_factory=dict)
    invalid: dict[str, dict[str, int]] = field(default_factory=dict)
    trials: int = 0
    blocks: int = 0
    hist_matrix: np.ndarray | None = None
    """Set by a fast kernel: the histograms of all metrics as rows of one matrix (each
    MetricStats.hist is a view of its row). Not pickled: each metric pickles its own row."""

    def __getstate__(self) -> dict:
        return {**self.__dict__, "hist_matrix": None}

    def add_block(self, block: int, values: dict[tuple[str, str], np.ndarray],
                  invalid: dict[str, dict[str, int]], n: int) -> None:
        """Add one block of ``n`` trials: per-trial values (NaN = no value), invalid counts."""
        for key, v in values.items():
            self.metrics.setdefault(key, MetricStats()).add_block(block, v)
        self.add_block_summary(block, {}, invalid, n)

    def histogram_matrix(self, keys: list[tuple[str, str]], wanted: set[tuple[str, str]]
                         ) -> np.ndarray:
        """The histograms of ``keys`` as rows of one matrix, for a fused kernel to fill.

        Created on first use; each wanted key's :class:`MetricStats` histogram is a view of its
        row (rows of unwanted keys are filled by the kernel and ignored).
        """
        if self.hist_matrix is None:
            self.hist_matrix = np.zeros((len(keys), N_BINS), np.int64)
            for r, key in enumerate(keys):
                if key in wanted:
                    self.metrics[key] = MetricStats(hist=self.hist_matrix[r])
        return self.hist_matrix

    def add_block_summary(self, block: int,
                          moments: dict[tuple[str, str], tuple[int, float, float, float, float]],
                          invalid: dict[str, dict[str, int]], n: int) -> None:
        """Add one block of ``n`` trials already reduced by a fused kernel.

        ``moments[key] = (count, mean, m2, minimum, maximum)`` of the key's valid values, whose
        histogram the kernel has added to :meth:`histogram_matrix`; ``invalid[variant]`` maps
        reason names (and ``"total"``) to counts.
        """
        for key, (count, mean, m2, lo, hi) in moments.items():
            ms = self.metrics.setdefault(key, MetricStats())
            ms.add_moments(block, (int(count), float(mean), float(m2)) if count
                           else (0, 0.0, 0.0))
            ms.minimum = min(ms.minimum, float(lo))
            ms.maximum = max(ms.maximum, float(hi))
        self._add_counts(invalid, n, 1)

    def _add_counts(self, invalid: dict[str, dict[str, int]], trials: int, blocks: int) -> None:
        for variant, counts in invalid.items():
            mine = self.invalid.setdefault(variant, {})
            for reason, c in counts.items():
                mine[reason] = mine.get(reason, 0) + c
        self.trials += trials
        self.blocks += blocks

    def merge(self, other: PointStats) -> None:
        for key, m in other.metrics.items():
            if key in self.metrics:
                self.metrics[key].merge(m)
            else:
                self.metrics[key] = m
        self._add_counts(other.invalid, other.trials, other.blocks)

    def summary(self, signed: dict[str, bool], confidence: float,
                spec: SpecCheck | None = None, sampled: bool = True) -> pd.DataFrame:
        """One row per (variant, metric): counts, moments, percentiles with intervals, max.

        ``signed[metric]`` True means percentiles and max are of the magnitude |x| (the mean and
        std stay signed), recorded in the column ``percentiles_of``. Moments, percentiles and
        max are over the trials with a value (``percentiles_over = "valid"``); a trial without
        one is counted in ``invalid_fraction``. Rows the ``spec`` applies to get ``spec_value``,
        ``spec_lo``, ``spec_hi`` (the statistic over all trials, those without a value counted
        as +inf) and a ``verdict`` (:data:`VERDICTS`).

        ``sampled`` False means the trials enumerate every case (the worst-case corners) rather
        than sample a distribution (column ``sampling``): statistics are then exact, with no
        confidence interval. For a spec on the max of a sampled metric, ``spec_coverage`` is the
        fraction of the population the sampled max bounds with the study's confidence (Wilks:
        ``(1 - confidence) ** (1 / trials)``).
        """
        import pandas as pd

        rows = []
        for (variant, metric), m in sorted(self.metrics.items()):
            of_abs = signed[metric]
            mean, std = m.mean_std()
            inv = self.invalid.get(variant, {})
            count = m.count
            row = {"variant": variant, "metric": metric,
                   "percentiles_of": "abs" if of_abs else "value", "percentiles_over": "valid",
                   "sampling": "random" if sampled else "enumerated",
                   "trials": self.trials, "count": count, "invalid": inv.get("total", 0),
                   "invalid_fraction": (self.trials - count) / self.trials if self.trials
                   else math.nan,
                   **{f"invalid_{k}": v for k, v in sorted(inv.items()) if k != "total"},
                   "mean": mean, "std": std}
            estimates = m.quantiles(tuple(PERCENTILES), of_abs, confidence)
            for tag, (est, lo, hi) in zip(PERCENTILE_TAGS, estimates, strict=True):
                if not sampled:
                    lo = hi = math.nan
                row.update({tag: est, f"{tag}_lo": lo, f"{tag}_hi": hi})
            levels = [CVAR_DEFAULT]
            if spec is not None and cvar_level(spec.statistic) and spec.applies(variant, metric):
                levels = list(dict.fromkeys([CVAR_DEFAULT, spec.statistic]))
            for tag in levels:
                est, lo, hi = m.superquantile(cvar_level(tag) or 0.95, of_abs, confidence)
                if not sampled:
                    lo = hi = math.nan
                row.update({tag: est, f"{tag}_lo": lo, f"{tag}_hi": hi})
            row["max"] = m.value_range(of_abs)[1] if count else math.nan
            if spec is not None and spec.applies(variant, metric):
                row.update(self._judge(m, row, spec, of_abs, confidence, sampled))
            rows.append(row)
        return pd.DataFrame(rows)

    def _judge(self, m: MetricStats, row: dict, spec: SpecCheck, of_abs: bool,
               confidence: float, sampled: bool) -> dict[str, float | str]:
        """The spec's statistic over all trials (no value = +inf) and the verdict."""
        censored = self.trials - m.count
        stat = spec.statistic
        if stat.startswith("p"):
            value, lo, hi = m.quantile(int(stat[1:]) / 100.0, of_abs, confidence, censored)
            if not sampled:  # every case enumerated: the statistic is exact
                lo = hi = value
        elif (level := cvar_level(stat)) is not None:
            # a trial without a value is +inf: any share of them makes the tail mean infinite
            value, lo, hi = (math.inf,) * 3 if censored else \
                m.superquantile(level, of_abs, confidence)
            if not sampled:
                lo = hi = value
        elif stat == "rms":  # sqrt(E[x²]), the 1σ of an RSS budget; no interval
            n, mean, m2 = m.moments()
            value = math.inf if censored else math.sqrt(mean**2 + m2 / n) if n else math.nan
            lo = hi = value
        else:  # mean, std, max: no interval; any trial without a value fails the spec
            # (a signed metric's mean by its magnitude: a bias of either sign counts)
            value = math.inf if censored else abs(row[stat]) if of_abs else row[stat]
            lo = hi = value
        if math.isnan(value) and censored == 0:  # no trials
            verdict = "undecided"
        elif not math.isnan(hi) and hi <= spec.limit:
            verdict = "meets"
        elif not math.isnan(lo) and lo > spec.limit:
            verdict = "fails"
        else:
            verdict = "undecided"
        coverage = (1.0 - confidence) ** (1.0 / self.trials) \
            if stat == "max" and sampled and self.trials else math.nan
        return {"spec_value": value, "spec_lo": lo, "spec_hi": hi, "verdict": verdict,
                "spec_coverage": coverage}

    def finalize(self, signed: dict[str, bool], confidence: float,
                 spec: SpecCheck | None = None, sampled: bool = True) -> PointResult:
        """The compact result of a finished point (the dense histograms are dropped)."""
        return PointResult(self.summary(signed, confidence, spec, sampled),
                           {k: m.coarse_histogram() for k, m in self.metrics.items()})
