"""Streaming statistics: exactness, chunking invariance, percentiles and their coverage."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import stats

from montecarlo.engine import accumulate
from montecarlo.engine import aggregate as agg


def _stats(x, block=1000, order=None):
    m = agg.MetricStats()
    blocks = range(0, len(x), block)
    for b in (order or list(range(len(blocks)))):
        m.add_block(b, x[b * block:(b + 1) * block])
    return m


def test_histogram_bins_contain_their_values():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(0, 1e-3, 10000), [0.0, 1e-13, -1e-13, 3e5, -3e5, 1.0, -1.0]])
    idx = agg.bin_index(x)
    assert np.all(agg.SIGNED_LOWER[idx] <= x) and np.all(x <= agg.SIGNED_UPPER[idx])
    inner = np.abs(x) > 1e-11
    width = (agg.SIGNED_UPPER[idx] - agg.SIGNED_LOWER[idx])[inner & (np.abs(x) < 1e4)]
    assert np.all(width <= 2.0**-agg.MANTISSA_BITS * np.abs(x[inner & (np.abs(x) < 1e4)]))


def test_moments_and_quantiles_match_numpy():
    rng = np.random.default_rng(1)
    x = rng.lognormal(-6, 1, 20000) * rng.choice([-1, 1], 20000)
    x[::97] = np.nan
    m = _stats(x)
    v = x[np.isfinite(x)]
    assert m.count == v.size
    mean, std = m.mean_std()
    assert mean == pytest.approx(np.mean(v), rel=1e-12, abs=1e-18)
    assert std == pytest.approx(np.std(v, ddof=1), rel=1e-12)
    for p in agg.PERCENTILES:
        for of_abs, data in ((False, v), (True, np.abs(v))):
            est, lo, hi = m.quantile(p, of_abs, 0.95)
            exact = np.quantile(data, p, method="inverted_cdf")
            # half a bin of relative width 2**-10
            assert est == pytest.approx(exact, rel=2.0**-11)
            assert lo <= exact <= hi


def test_block_order_and_grouping_do_not_change_anything():
    """Bit-identical totals whatever order blocks arrive in or how they are grouped into tasks."""
    rng = np.random.default_rng(2)
    x = rng.normal(3e-3, 1e-3, 50000)
    a = _stats(x)
    b = _stats(x, order=list(rng.permutation(50)))
    c = agg.MetricStats()
    for part in np.array_split(rng.permutation(50), 7):
        sub = agg.MetricStats()
        for blk in part:
            sub.add_block(int(blk), x[blk * 1000:(blk + 1) * 1000])
        c.merge(sub)
    for other in (b, c):
        assert other.mean_std() == a.mean_std()
        assert np.array_equal(other.hist, a.hist)
        assert [other.quantile(p, False, 0.9) for p in agg.PERCENTILES] == \
               [a.quantile(p, False, 0.9) for p in agg.PERCENTILES]


def test_merge_refuses_a_block_twice():
    m = _stats(np.ones(2000))
    with pytest.raises(ValueError, match="added twice"):
        m.merge(_stats(np.ones(1000)))


def test_ranks_match_scipy_quantile_test():
    """Order-statistic intervals equal scipy.stats.quantile_test's (an independent reference)."""
    rng = np.random.default_rng(3)
    for n, p in [(100, 0.5), (1000, 0.95), (500, 0.99), (20, 0.9)]:
        x = np.sort(rng.random(n))
        ci = stats.quantile_test(x, q=0.5, p=p).confidence_interval(0.95)
        _, r, s = agg.order_statistic_ranks(n, p, 0.95)
        assert (x[r - 1] if r >= 1 else -np.inf) == ci.low or (r < 1 and np.isnan(ci.low))
        assert (x[s - 1] if s <= n else np.inf) == ci.high or (s > n and np.isnan(ci.high))


@pytest.mark.parametrize(("n", "p"), [(200, 0.5), (1000, 0.95), (2000, 0.99)])
def test_percentile_intervals_cover_at_nominal_rate(n, p):
    """Coverage of the 95 % interval for a known distribution's true percentile.

    The exact coverage of order-statistic intervals is P(r <= B <= s - 1), B ~ Bin(n, p), which is
    at least 0.95; the observed rate over R repetitions must agree with it within 3 binomial
    standard deviations (histogram rounding only widens the interval, so allow the excess above).
    """
    rng = np.random.default_rng(4)
    reps = 1000
    true_q = stats.expon.ppf(p, scale=2e-3)
    covered = 0
    for _ in range(reps):
        m = _stats(rng.exponential(2e-3, n), block=n)
        _, lo, hi = m.quantile(p, False, 0.95)
        covered += lo <= true_q <= hi
    _, r, s = agg.order_statistic_ranks(n, p, 0.95)
    exact = stats.binom.cdf(s - 1, n, p) - stats.binom.cdf(r - 1, n, p)
    assert exact >= 0.95
    sd = math.sqrt(exact * (1 - exact) / reps)
    # histogram rounding moves the ends outwards by <= 2**-10 relative: a coverage gain of well
    # under 0.01 for these densities
    assert exact - 3 * sd <= covered / reps <= exact + 3 * sd + 0.01


def test_too_few_trials_leave_interval_open():
    m = _stats(np.random.default_rng(5).random(20), block=20)
    _, lo, hi = m.quantile(0.99, False, 0.95)
    assert np.isnan(hi) and np.isfinite(lo)


def test_point_summary_counts_invalid_by_reason():
    ps = agg.PointStats()
    ps.add_block(0, {("raw", "a"): np.array([1.0, np.nan, 3.0])},
                 {"raw": {"total": 1, "OUTSIDE_FOV": 1}}, 3)
    ps.add_block(1, {("raw", "a"): np.array([2.0])}, {"raw": {"total": 0}}, 1)
    row = ps.summary({"a": False}, 0.95).iloc[0]
    assert row["count"] == 3 and row["invalid"] == 1 and row["invalid_OUTSIDE_FOV"] == 1
    assert row["trials"] == 4 and row["invalid_fraction"] == 0.25
    assert row["mean"] == 2.0 and row["max"] == 3.0 and row["percentiles_over"] == "valid"


def _point(valid: int, invalid: int, value: float = 1.0) -> agg.PointStats:
    """One block of ``valid`` trials at ``value`` (jittered) and ``invalid`` without a value."""
    values = np.concatenate([value * (1 + 1e-3 * np.random.default_rng(0).random(valid)),
                             np.full(invalid, np.nan)])
    ps = agg.PointStats()
    ps.add_block(0, {("v", "m"): values}, {"v": {"total": invalid}}, values.size)
    return ps


@pytest.mark.parametrize(("statistic", "invalid", "verdict"), [
    ("p95", 0, "meets"),   # all 1000 trials well below the limit
    ("p95", 100, "fails"),  # rank 950 lies among the 100 trials without a value (+inf)
    ("p50", 100, "meets"),  # rank 500 and its interval lie among the valid trials
    ("max", 1, "fails"),   # one failed calibration is a failed spec on the max
    ("mean", 1, "fails"),
    ("mean", 0, "meets"),
])
def test_spec_verdict_counts_a_trial_without_a_value_as_exceeding(statistic, invalid, verdict):
    spec = agg.SpecCheck("m", None, statistic, 2.0)
    row = _point(1000 - invalid, invalid).summary({"m": False}, 0.95, spec).iloc[0]
    assert row["verdict"] == verdict
    if verdict == "fails" and statistic != "p50":
        assert row["spec_value"] == np.inf
    assert row[statistic] < 2.0  # over the valid trials the statistic alone would meet


def test_all_trials_invalid_fails_rather_than_undecided():
    spec = agg.SpecCheck("m", None, "p95", 2.0)
    row = _point(0, 50).summary({"m": False}, 0.95, spec).iloc[0]
    assert row["verdict"] == "fails" and row["invalid_fraction"] == 1.0


def test_too_few_trials_for_a_percentile_bound_are_undecided():
    spec = agg.SpecCheck("m", None, "p99", 2.0)
    row = _point(20, 0).summary({"m": False}, 0.95, spec).iloc[0]
    assert row["verdict"] == "undecided" and np.isnan(row["spec_hi"])


def test_spec_applies_only_to_its_metric_and_variant():
    ps = _point(10, 0)
    ps.add_block(0, {("w", "m"): np.ones(10)}, {"w": {"total": 0}}, 0)
    verdicts = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", "w", "max", 2.0)) \
        .set_index("variant")["verdict"]
    assert verdicts.isna()["v"] and verdicts["w"] == "meets"


def test_accumulate_equals_reference_aggregation():
    rng = np.random.default_rng(5)
    values = rng.lognormal(-7, 1, (3, 20000)) * rng.choice([-1, 1], (3, 20000))
    values[:, ::13] = np.nan
    hist = np.zeros((3, agg.N_BINS), np.int64)
    stats = accumulate.new_stats(3)
    for s in range(0, 20000, 8192):
        chunk = np.ascontiguousarray(values[:, s:s + 8192])
        accumulate.accumulate(chunk, np.arange(3), hist, stats, np.empty(chunk.shape[1], np.int64))
    for r in range(3):
        ref = agg.MetricStats()
        ref.add_block(0, values[r])
        np.testing.assert_array_equal(hist[r], ref.hist)
        n, mean, m2 = ref.moments()
        assert stats[r, 0] == n
        assert stats[r, 1] == pytest.approx(mean, rel=1e-12)
        assert stats[r, 2] == pytest.approx(m2, rel=1e-10)
        assert (stats[r, 3], stats[r, 4]) == (ref.minimum, ref.maximum)


@settings(max_examples=300, deadline=None)
@given(n=st.integers(1, 5000), p=st.floats(0.001, 0.999), q=st.floats(0.0001, 0.9999))
def test_binomial_quantile_equals_scipy_binom_ppf(n, p, q):
    k = agg.binomial_quantile(q, n, p)
    # at an exact tie CDF(k) = q both answers are within rounding; those are tested below
    assume(all(abs(stats.binom.cdf(j, n, p) - q) > 1e-9 for j in (k - 1, k)))
    assert k == int(stats.binom.ppf(q, n, p))


@pytest.mark.parametrize("n", [1, 39, 41, 401])
def test_binomial_quantile_at_an_exact_tie(n):
    """p = q = 1/2, odd n: CDF((n - 1) / 2) is exactly 1/2 (exact rational arithmetic)."""
    from fractions import Fraction

    k = (n - 1) // 2
    assert sum(Fraction(math.comb(n, j), 2**n) for j in range(k + 1)) == Fraction(1, 2)
    assert agg.binomial_quantile(0.5, n, 0.5) == k
