"""How many trials: distribution-free order-statistic counts, and a pilot-based plan.

Order statistics need no model of the metric's distribution. The k-th largest of n trials is
an upper bound of the p-quantile with confidence c when ``P(B >= k) >= c``, B ~ Binomial(n,
1 - p) (Wilks, 1941; monaco's ``order_stat_TI_n``). With k = 1 (the sample max), n = ln(1 - c)
/ ln(p). The two-sided interval of a percentile that the summaries report
(:func:`montecarlo.engine.aggregate.order_statistic_ranks`) narrows in quantile level like
1 / sqrt(n).

In metric units the width depends on the distribution, so a pilot run measures it: an
interval's half-width shrinks as 1 / sqrt(n), so ``n = n0 (h0 / h)^2`` trials give half-width h,
and a verdict is decided once the half-width is below the distance from the statistic to the
limit. The same holds for a superquantile (``cvarNN``), whose interval is asymptotically normal
(:mod:`montecarlo.engine.superquantile`). These are estimates from the pilot, not guarantees;
``run --until-decided`` checks.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike
from scipy.special import bdtr

from montecarlo.engine.aggregate import order_statistic_ranks
from montecarlo.engine.runner import StudyResult
from montecarlo.engine.superquantile import cvar_level
from montecarlo.errors import InputError

PERCENTILES = {"p50": 0.50, "p90": 0.90, "p95": 0.95, "p99": 0.99}


def has_interval(statistic: str) -> bool:
    """True for the statistics with a confidence interval: percentiles and ``cvarNN``."""
    return statistic in PERCENTILES or cvar_level(statistic) is not None


def order_statistic_trials(k: int, p: float, confidence: float) -> int:
    """Fewest trials n whose k-th largest value bounds the p-quantile from above with the
    given confidence: ``P(Binomial(n, 1 - p) >= k) >= confidence``.

    ``k = 1`` is Wilks' ``ceil(ln(1 - c) / ln(p))``.
    """
    if not (0.0 < p < 1.0 and 0.0 < confidence < 1.0 and k >= 1):
        raise ValueError("need 0 < p < 1, 0 < confidence < 1 and k >= 1")

    def covers(n: int) -> bool:  # P(B >= k) = 1 - P(B <= k - 1), B ~ Bin(n, 1 - p)
        return 1.0 - bdtr(k - 1, n, 1.0 - p) >= confidence * (1.0 - 1e-12)  # ties kept

    lo, hi = k - 1, k
    while not covers(hi):
        lo, hi = hi, 2 * hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if covers(mid) else (mid, hi)
    return hi


def quantile_level_trials(p: float, half_width: float, confidence: float) -> int:
    """Trials whose distribution-free interval of the p-quantile spans at most ``p +-
    half_width`` in quantile level (ranks r, s with (s - r) / n <= 2 half_width).

    Found by bisection; the discreteness of the ranks makes the condition not quite monotone
    in n, so a count a few below the one returned may also do.
    """
    if not (0.0 < p < 1.0 and 0.0 < half_width < min(p, 1.0 - p)):
        raise ValueError("need 0 < half_width < min(p, 1 - p)")

    def narrow(n: int) -> bool:
        _, r, s = order_statistic_ranks(n, p, confidence)
        return r >= 1 and s <= n and (s - r) / n <= 2.0 * half_width

    hi = 1
    while not narrow(hi):
        hi *= 2
    lo = hi // 2
    while hi - lo > 1:  # near-monotone in n; the bisection returns a count that is narrow
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if narrow(mid) else (mid, hi)
    return hi


def interval_trials(p: float, confidence: float) -> int:
    """Fewest trials whose distribution-free two-sided interval of the p-quantile is bounded
    at both ends (ranks 1 <= r and s <= n, :func:`order_statistic_ranks`).

    The upper end needs ``P(B <= n - 1) >= 1 - (1 - c)/2`` for B ~ Binomial(n, p), i.e.
    ``1 - p^n >= 1 - (1 - c)/2``, so ``n >= ln((1 - c)/2) / ln(p)``; for p = 0.99, c = 0.95
    that is ln(0.025)/ln(0.99) = 367.0, so 368 trials (the lower end, by symmetry, needs
    ``n >= ln((1 - c)/2) / ln(1 - p)``, which is smaller for p >= 0.5).
    """
    def bounded(n: int) -> bool:
        _, r, s = order_statistic_ranks(n, p, confidence)
        return r >= 1 and s <= n

    hi = 2
    while not bounded(hi):
        hi *= 2
    lo = hi // 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if bounded(mid) else (mid, hi)
    return hi


def trials_to_decide(n0: ArrayLike, half: ArrayLike, distance: ArrayLike) -> np.ndarray:
    """Trials estimated to decide a verdict: the interval's half-width shrinks as 1/sqrt(n),
    so ``n = ceil(n0 (h0 / d)^2)`` trials bring the pilot's half-width ``h0`` (from ``n0``
    trials) down to the distance ``d`` from the statistic to the limit. Halving ``d``
    quadruples n; ``d = 0`` needs infinitely many (returned as inf).

    Example: a pilot of 1000 trials with half-width 0.2 at distance 0.1 needs
    1000 (0.2/0.1)^2 = 4000 trials; at distance 0.05, 16000.
    """
    n0, half, distance = (np.asarray(x, float) for x in (n0, half, distance))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(distance > 0, np.ceil(n0 * (half / distance) ** 2), np.inf)


def pilot_plan(result: StudyResult, summary: pd.DataFrame, width: float | None = None
               ) -> pd.DataFrame:
    """Per grid point and variant of the spec's metric (or the plotted one): the pilot's
    statistic and interval, and the trials estimated to decide the spec verdict and to reach
    an interval of full ``width`` [the metric's display unit].

    Where the summary judged a spec with an interval, the statistic and interval are those it
    judged, over all trials (a trial without a value counting as exceeding: ``spec_value``,
    ``spec_lo``, ``spec_hi``), so that the trials to decide are those of its verdict; otherwise
    those over the trials with a value."""
    study = result.study
    spec = study.spec
    metric = spec.metric if spec else study.metrics[0][1].name
    stat = spec.statistic if spec and has_interval(spec.statistic) else "p95"
    rows = summary[summary["metric"] == metric]
    if spec and spec.variant:
        rows = rows[rows["variant"] == spec.variant]
    out = rows[["point", *study.sweep_keys, "variant", "unit", "trials", "sampling"]].copy()
    judged = spec is not None and stat == spec.statistic and "spec_value" in rows
    columns = ("spec_value", "spec_lo", "spec_hi") if judged else \
        (stat, f"{stat}_lo", f"{stat}_hi")
    value, lo, hi = (rows[c].to_numpy(float) for c in columns)
    n0 = rows["trials"].to_numpy(float)
    with np.errstate(invalid="ignore"):  # an infinite statistic (too many without a value)
        half = np.where(np.isinf(value), np.inf, np.maximum(value - lo, hi - value))
    out[stat], out[f"{stat}_lo"], out[f"{stat}_hi"] = value, lo, hi
    sampled = (rows["sampling"] != "enumerated").to_numpy()
    unbounded = sampled & np.isnan(half) & ~np.isnan(value)
    if unbounded.any():
        level = PERCENTILES.get(stat) or cvar_level(stat)
        needed = interval_trials(level, study.header.confidence)
        raise InputError(f"plan: a pilot of {int(n0[unbounded].min()):,} trials per grid point "
                         f"cannot bound the {stat} at {study.header.confidence:.0%} confidence "
                         f"(its interval needs at least {needed:,} trials); give --trials "
                         f"{needed:,} or more")
    if spec is not None and has_interval(spec.statistic):
        need = trials_to_decide(n0, half, np.abs(value - spec.limit))
        decided = (rows["verdict"] != "undecided").to_numpy()
        out["verdict"] = rows["verdict"].to_numpy()
        need = np.where(decided | ~sampled, n0, need)
        out["trials_to_decide"] = pd.array(
            [int(v) if np.isfinite(v) else pd.NA for v in need], dtype="Int64")
    if width is not None:  # <NA> where the interval is open (too many trials without a value)
        need = np.where(sampled, np.ceil(n0 * (2.0 * half / width) ** 2), n0)
        out[f"trials_for_width_{width:g}"] = pd.array(
            [int(v) if np.isfinite(v) else pd.NA for v in need], dtype="Int64")
    return out.reset_index(drop=True)


def distribution_free_table(p: float, confidence: float, ks: tuple[int, ...] = (1, 2, 3, 5, 10)
                            ) -> pd.DataFrame:
    """Trials for a one-sided upper bound of the p-quantile from the k-th largest trial."""
    return pd.DataFrame({"k (k-th largest)": ks,
                         "trials": [order_statistic_trials(k, p, confidence) for k in ks]})


def wilks_text(p: float, confidence: float) -> str:
    n = order_statistic_trials(1, p, confidence)
    return (f"the max of {n:,} trials bounds the {p:.4g}-quantile with {confidence:.0%} "
            f"confidence (Wilks: ln(1 - {confidence:g}) / ln({p:g}) = "
            f"{math.log(1 - confidence) / math.log(p):.1f})")
