"""Acceptance figures: each slow test records the figures it checks, with their bounds.

``make acceptance`` runs every acceptance suite (one test file each) and writes what its tests
recorded to ``results/acceptance/<suite>.json`` (``tests/conftest.py``); the docs cite those
files and ``tests/test_docs_figures.py`` checks that each cited figure is the recorded one.

A coverage rate is bounded from both sides: the share of trials whose error lies within
2 sigma must fall in the binomial band of the nominal 95.45 % at the test's number of trials, so
a sigma reported too large fails as surely as one reported too small.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from math import erf, sqrt

from scipy.stats import binom, chi2

TWO_SIGMA = erf(2.0 / sqrt(2.0))  # 0.9545: share of a normal error within 2 sigma
ALPHA = 1e-3  # false-alarm probability of each two-sided band


@dataclass
class Figures:
    """The figures one suite's tests recorded: name -> value, bounds and the test's id."""

    items: dict[str, dict] = field(default_factory=dict)
    test: str = ""

    def record(self, name: str, value: float, low: float | None = None,
               high: float | None = None, unit: str = "") -> float:
        """Record ``value`` under ``name`` with the bounds its test asserts (None: no bound)."""
        holds = (low is None or value >= low) and (high is None or value <= high)
        self.items[name] = {"value": float(value), "low": low, "high": high, "unit": unit,
                            "holds": bool(holds), "test": self.test}
        return value


def slug(*parts: object) -> str:
    """A figure name from a case's words (letters, digits, '.', '_' and '-' only).

    >>> slug("pitch to 60°, relative, level, right", "axis_az")
    'pitch-to-60-relative-level-right.axis_az'
    """
    return ".".join(re.sub(r"[^A-Za-z0-9_]+", "-", str(p)).strip("-") for p in parts)


def coverage_band(n: int, p: float = TWO_SIGMA, alpha: float = ALPHA) -> tuple[float, float]:
    """The shares of ``n`` trials between which a coverage of nominal ``p`` falls with
    probability 1 - ``alpha`` (binomial, equal tails).

    >>> coverage_band(100)
    (0.87, 1.0)
    >>> coverage_band(1000)
    (0.931, 0.975)
    """
    lo, hi = binom.interval(1.0 - alpha, n, p)
    return float(lo) / n, float(hi) / n


def check_coverage(figures: Figures | None, name: str, inside: int, n: int,
                   p: float = TWO_SIGMA, alpha: float = ALPHA) -> float:
    """Assert that ``inside`` of ``n`` trials within 2 sigma lies in the band of
    ``coverage_band``; record the share (and its bounds) as ``name``."""
    lo, hi = coverage_band(n, p, alpha)
    share = inside / n
    if figures is not None:
        figures.record(name, share, lo, hi)
    assert lo <= share <= hi, (f"{name}: {inside}/{n} within 2 sigma, outside the binomial "
                               f"band {lo:.3f}-{hi:.3f} of {p:.4f} at alpha {alpha}")
    return share


def check_not_inflated(figures: Figures | None, name: str, sum_z2: float, dof: int,
                       alpha: float = ALPHA) -> float:
    """Assert that the errors' sum of squares in units of their reported sigma is not below the
    ``alpha`` quantile of chi-square with ``dof`` degrees of freedom (a reported sigma too large
    makes it small); record the mean (error/sigma)^2 as ``name``, with that lower bound."""
    low = float(chi2.ppf(alpha, dof)) / dof
    mean = sum_z2 / dof
    if figures is not None:
        figures.record(name, mean, low, None)
    assert mean >= low, (f"{name}: mean (error/sigma)^2 {mean:.3f} below {low:.3f}, the chi-square "
                         f"{alpha} quantile at {dof} dof: the reported sigma is inflated")
    return mean


def check_rate(figures: Figures | None, name: str, count: int, n: int,
               at_least: float | None = None, at_most: float | None = None,
               alpha: float = ALPHA) -> float:
    """Assert that ``count`` of ``n`` is not significantly below ``at_least`` (or above
    ``at_most``): a one-sided binomial test at ``alpha``, so a small suite keeps the claim's
    meaning; record the share, with the bound of the count that would fail.

    >>> check_rate(None, "x", 37, 40, at_least=0.95)
    0.925
    """
    low = high = None
    if at_least is not None:
        low = float(binom.ppf(alpha, n, at_least)) / n
    if at_most is not None:
        high = float(binom.isf(alpha, n, at_most)) / n
    share = count / n
    if figures is not None:
        figures.record(name, share, low, high)
    assert (low is None or share >= low) and (high is None or share <= high), (
        f"{name}: {count}/{n} against the claim {at_least=} {at_most=} at alpha {alpha}")
    return share
