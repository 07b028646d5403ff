"""The superquantile (cvarNN): value, bounds from the histogram, interval coverage, spec use."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from montecarlo.engine.aggregate import MetricStats, PointStats, SpecCheck
from montecarlo.engine.superquantile import cvar_level, is_cvar_column, tail_weights

EXP_CVAR95 = 1.0 + math.log(20.0)
"""Exp(1): VaR_a = -ln(1 - a), and by memorylessness CVaR_a = VaR_a + 1 (= 3.9957 at 0.95)."""
NORMAL_CVAR95 = stats.norm.pdf(stats.norm.ppf(0.95)) / 0.05
"""N(0, 1): CVaR_a = phi(Phi^-1(a)) / (1 - a) (= 2.0627 at 0.95)."""


def _stats(x: np.ndarray, blocks: int = 1) -> MetricStats:
    m = MetricStats()
    for b, part in enumerate(np.array_split(x, blocks)):
        m.add_block(b, part)
    return m


def test_names():
    assert cvar_level("cvar95") == 0.95 and cvar_level("cvar5") == 0.05
    assert cvar_level("p95") is None and cvar_level("cvar0") is None
    assert cvar_level("cvar100") is None
    assert is_cvar_column("cvar99_lo") and not is_cvar_column("p95_lo")
    assert is_cvar_column("cvar95_hi") and is_cvar_column("cvar95")


def test_tail_weights_by_hand():
    """Bins of 3, 2, 5 values (ascending); the 6.5 largest: all 5 of the top bin, 1.5 of
    the middle one (of 2), none of the bottom."""
    np.testing.assert_allclose(tail_weights(np.array([3, 2, 5]), 6.5), [0.0, 1.5, 5.0])
    np.testing.assert_allclose(tail_weights(np.array([3, 2, 5]), 10.0), [3.0, 2.0, 5.0])


def test_value_is_within_the_bin_bounds_of_the_sample_superquantile():
    """Against the sorted sample: the mean of the 250 largest of 5000 (t = 250 exactly) and
    of 5001 (t = 250.05: the 250 largest and 0.05 of the next), within the bins' relative
    width 2**-10 and inside the bounds."""
    rng = np.random.default_rng(7)
    for n in (5000, 5001):
        x = rng.exponential(size=n)
        xs = np.sort(x)[::-1]
        t = n * 0.05
        k = math.floor(t)
        exact = (xs[:k].sum() + (t - k) * xs[k]) / t
        est, lo, hi = _stats(x).superquantile(0.95, False, 0.95)
        assert est == pytest.approx(exact, rel=2.0**-10)
        assert lo < exact < hi


def test_estimate_bounds_and_interval_by_hand():
    """Four bins [0, 1), [1, 2), [2, 3), [3, 4) holding 7, 1, 1, 1 values, the smallest 0.2
    and the largest 3.6 (the outer bins clipped to them): centres 0.6, 1.5, 2.5, 3.3. At
    a = 0.8 the tail is the 2 largest values, one in each of the top bins: estimate
    (2.5 + 3.3) / 2 = 2.9, edge bounds (2 + 3) / 2 = 2.5 and (3 + 3.6) / 2 = 3.3.
    VaR is the ceil(0.8 * 10) = 8th smallest, in bin [1, 2) (the 7th is in the first):
    centre 1.5. y = (mid - 1.5)_+ = 0, 0, 1, 1.8 with counts 7, 1, 1, 1: mean 0.28,
    variance (8 * 0.28^2 + 0.72^2 + 1.52^2) / 9 = 3.456 / 9 = 0.384; se = sqrt(0.384 / 10)
    / 0.2 = 0.97980; z = 1.95996 at 95 %."""
    from montecarlo.engine.superquantile import superquantile

    lower, upper = np.array([0.0, 1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0, 4.0])
    counts = np.array([7, 1, 1, 1])
    est, lo, hi = superquantile(counts, lower, upper, 0.2, 3.6, 0.8, 0.95)
    half = 1.959963984540054 * math.sqrt(0.384 / 10) / 0.2
    assert est == pytest.approx(2.9, rel=1e-15)
    assert lo == pytest.approx(2.5 - half, rel=1e-14)
    assert hi == pytest.approx(3.3 + half, rel=1e-14)
    # a = 0.05 with counts 1, 7, 1, 1: the tail is 9.5 values, half of the one in the clipped
    # bottom bin [0.2, 1) (centre 0.6): (0.5 * 0.6 + 7 * 1.5 + 2.5 + 3.3) / 9.5; VaR the
    # 1st smallest, centre 0.6
    est, lo, hi = superquantile(np.array([1, 7, 1, 1]), lower, upper, 0.2, 3.6, 0.05, 0.95)
    assert est == pytest.approx((0.3 + 10.5 + 5.8) / 9.5, rel=1e-15)
    y = np.array([0.0, 0.9, 1.9, 2.7])
    c = np.array([1, 7, 1, 1])
    var_y = float(np.sum(c * (y - np.sum(c * y) / 10) ** 2) / 9)
    half = 1.959963984540054 * math.sqrt(var_y / 10) / 0.95
    assert lo == pytest.approx((0.5 * 0.2 + 7 + 5) / 9.5 - half, rel=1e-14)
    assert hi == pytest.approx((0.5 * 1.0 + 14 + 6.6) / 9.5 + half, rel=1e-14)
    # one value: itself, no interval; two: an interval
    assert superquantile(np.array([0, 1, 0, 0]), lower, upper, 1.3, 1.3, 0.8, 0.95)[0] == 1.3
    assert np.isnan(superquantile(np.array([0, 1, 0, 0]), lower, upper, 1.3, 1.3, 0.8,
                                  0.95)[1])
    assert np.isfinite(superquantile(np.array([1, 0, 0, 1]), lower, upper, 0.2, 3.6, 0.5,
                                     0.95)).all()


def test_tail_averages_over_many_occupied_bins_by_exact_sums():
    """More than 10,000 occupied bins (a 10^6-trial histogram has them): the estimate and its
    bounds equal the tail-weighted averages of bin centres and edges summed exactly
    (``math.fsum``), to a few ulp; the weights by hand are ``tail_weights``' test above."""
    from montecarlo.engine.aggregate import ABS_LOWER, ABS_UPPER, abs_histogram
    from montecarlo.engine.superquantile import superquantile

    m = _stats(np.random.default_rng(8).lognormal(-7.0, 3.0, 200_000))
    counts = abs_histogram(m.hist)
    nz = np.flatnonzero(counts)
    assert nz.size > 10_000
    lo_val, hi_val = m.value_range(True)
    lower = np.clip(ABS_LOWER[nz], lo_val, hi_val)
    upper = np.clip(ABS_UPPER[nz], lo_val, hi_val)
    tail = counts.sum() * 0.05
    w = tail_weights(counts[nz].astype(float), tail)
    exact = [math.fsum(w * e) / tail for e in (0.5 * (lower + upper), lower, upper)]
    est, lo, hi = superquantile(counts, ABS_LOWER, ABS_UPPER, lo_val, hi_val, 0.95, 0.95)
    assert est == pytest.approx(exact[0], rel=1e-14)
    assert lo < exact[1] and hi > exact[2]  # the bounds widened by the interval


def test_magnitude_of_signed_values():
    """cvar of |x| for N(0, 1) values: |x| is half-normal, CVaR_0.95 = phi(z_0.975) / 0.05 * 2
    = 2.3378; from 40,000 values the estimate is within 3 of its standard errors."""
    rng = np.random.default_rng(11)
    x = rng.standard_normal(40_000)
    est, lo, hi = _stats(x).superquantile(0.95, True, 0.95)
    z = stats.norm.ppf(0.975)
    true = 2.0 * stats.norm.pdf(z) / 0.05
    se = (hi - lo) / (2 * 1.959964)
    assert abs(est - true) < 3 * se


def test_same_for_any_split_into_blocks():
    rng = np.random.default_rng(5)
    x = rng.exponential(size=10_000)
    assert _stats(x, 1).superquantile(0.9, False, 0.95) == \
        _stats(x, 7).superquantile(0.9, False, 0.95)


def _coverage(sample, true: float, n: int, reps: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(reps):
        _, lo, hi = _stats(sample(rng, n)).superquantile(0.95, False, 0.95)
        hits += lo <= true <= hi
    return hits / reps


DISTRIBUTIONS = {
    "exponential": (lambda rng, n: rng.exponential(size=n), EXP_CVAR95),
    "normal": (lambda rng, n: rng.standard_normal(n), NORMAL_CVAR95),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", DISTRIBUTIONS)
def test_interval_coverage_1000_repetitions(name, figures):
    """The 95 % interval of cvar95 from 5000 trials (250 in the tail), 1000 repetitions:
    coverage within 2 points of 95 % (the acceptance figure; the binomial standard error of
    the measured coverage is 0.7 points)."""
    sample, true = DISTRIBUTIONS[name]
    coverage = _coverage(sample, true, 5000, 1000, seed=2024)
    print(f"{name}: cvar95 interval coverage {coverage:.3f} over 1000 repetitions")
    figures.record(f"{name}.cvar95_interval_coverage", coverage, 0.93, 0.97)
    assert abs(coverage - 0.95) <= 0.02


@pytest.mark.parametrize("name", DISTRIBUTIONS)
def test_interval_coverage_quick(name):
    """200 repetitions: coverage within 4 binomial standard errors (sqrt(.95 .05 / 200) =
    1.5 points) of 95 %, i.e. ±6.2 points."""
    sample, true = DISTRIBUTIONS[name]
    coverage = _coverage(sample, true, 5000, 200, seed=99)
    assert abs(coverage - 0.95) <= 4 * math.sqrt(0.95 * 0.05 / 200)


def test_spec_on_cvar_and_invalid_trials():
    """A cvar spec: the verdict follows the interval; one trial without a value makes the
    tail mean infinite (fails), as for the mean."""
    rng = np.random.default_rng(1)
    x = rng.exponential(size=5000)
    ps = PointStats()
    ps.add_block(0, {("v", "m"): x}, {"v": {"total": 0}}, x.size)
    row = ps.summary({"m": False}, 0.95, SpecCheck("m", None, "cvar90", 4.0)).iloc[0]
    # Exp(1): CVaR_0.9 = 1 + ln 10 = 3.30
    assert row["cvar90_lo"] < 1 + math.log(10) < row["cvar90_hi"]
    assert row["verdict"] == "meets" and row["spec_value"] == row["cvar90"]
    assert row["cvar95_lo"] < EXP_CVAR95 < row["cvar95_hi"]
    tight = ps.summary({"m": False}, 0.95, SpecCheck("m", None, "cvar90", 3.3)).iloc[0]
    assert tight["verdict"] == "undecided"
    y = x.copy()
    y[0] = np.nan
    bad = PointStats()
    bad.add_block(0, {("v", "m"): y}, {"v": {"total": 1}}, y.size)
    row = bad.summary({"m": False}, 0.95, SpecCheck("m", None, "cvar95", 100.0)).iloc[0]
    assert row["spec_value"] == math.inf and row["verdict"] == "fails"
    assert np.isfinite(row["cvar95"])  # over the trials with a value
