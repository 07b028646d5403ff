"""Streaming statistics: exactness, chunking invariance, percentiles and their coverage."""

import math

import numpy as np
import pandas as pd
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
        accumulate.accumulate(chunk, np.arange(3), hist, stats, np.empty(8192, np.int32), 8192)
    for r in range(3):
        ref = agg.MetricStats()
        ref.add_block(0, values[r])
        np.testing.assert_array_equal(hist[r], ref.hist)
        n, mean, m2 = ref.moments()
        assert stats[r, 0] == n
        assert stats[r, 1] == pytest.approx(mean, rel=1e-12)
        assert stats[r, 2] == pytest.approx(m2, rel=1e-10)
        assert (stats[r, 3], stats[r, 4]) == (ref.minimum, ref.maximum)


def test_accumulate_by_pieces_is_bitwise_chunk_by_chunk():
    """One call over 3.5 pieces gives the very bits of one call per piece on copies: the
    statistics depend on the piece size, never on how many columns a call is given."""
    rng = np.random.default_rng(6)
    values = rng.lognormal(-7, 1, (3, 28672)) * rng.choice([-1, 1], (3, 28672))
    values[:, ::17] = np.nan
    rows = np.array([2, 0])
    hist = np.zeros((2, agg.N_BINS), np.int64)
    stats = accumulate.new_stats(2)
    for s in range(0, values.shape[1], 8192):
        chunk = np.ascontiguousarray(values[:, s:s + 8192])
        accumulate.accumulate(chunk, rows, hist, stats, np.empty(8192, np.int32), 8192)
    hist_one = np.zeros_like(hist)
    stats_one = accumulate.new_stats(2)
    accumulate.accumulate(values, rows, hist_one, stats_one, np.empty(8192, np.int32), 8192)
    np.testing.assert_array_equal(hist_one, hist)
    assert stats_one.tobytes() == stats.tobytes()


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


# --- exact edges, boundaries and small samples (each against an independent reference) ---------


def test_bin_edges_are_the_float_grid_of_1024_bins_per_octave():
    """Edges built from ldexp, not from float bits: i-th edge = (1 + (i mod 1024) / 1024) 2**e."""
    i = np.arange(agg.N_MAG + 1)
    expected = np.ldexp(1.0 + (i % 1024) / 1024.0, agg.MIN_EXP + i // 1024)
    np.testing.assert_array_equal(agg._magnitude_edges(), expected)
    lower, upper = agg._signed_bin_edges()
    assert lower.size == upper.size == agg.N_BINS
    assert lower[0] == -np.inf and upper[-1] == np.inf
    np.testing.assert_array_equal(lower[1:], upper[:-1])  # contiguous
    np.testing.assert_array_equal(lower, -upper[::-1])  # symmetric about zero
    z = agg.ZERO_BIN
    assert (lower[z], upper[z]) == (-(2.0**agg.MIN_EXP), 2.0**agg.MIN_EXP)
    assert (lower[-1], upper[0]) == (2.0**agg.MAX_EXP, -(2.0**agg.MAX_EXP))
    np.testing.assert_array_equal(lower[z + 1:-1], expected[:-1])


def test_bin_index_at_the_ends_of_the_range():
    tiny, huge = 2.0**agg.MIN_EXP, 2.0**agg.MAX_EXP
    x = np.array([tiny, -tiny, np.nextafter(tiny, 0), -np.nextafter(tiny, 0), 0.0, -0.0,
                  huge, -huge, np.nextafter(huge, 0), 1e300, -1e300])
    z, last = agg.ZERO_BIN, agg.N_BINS - 1
    assert agg.bin_index(x).tolist() == [z + 1, z - 1, z, z, z, z, last, 0, last - 1, last, 0]


@pytest.mark.parametrize(("a", "b", "expected"), [
    ((0, 0.0, 0.0), (3, 0.1, 0.02), (3, 0.1, 0.02)),  # an empty side returns the other as is
    ((3, 0.1, 0.02), (0, 0.0, 0.0), (3, 0.1, 0.02)),
    ((0, 0.0, 0.0), (1, 5.0, 0.0), (1, 5.0, 0.0)),
    ((0, 0.0, 0.0), (2, 0.0, 2.0), (2, 0.0, 2.0)),
    ((1, 2.0, 0.0), (1, 4.0, 0.0), (2, 3.0, 2.0)),  # {2, 4}: mean 3, squared deviations 2
    ((2, 0.0, 2.0), (2, 1.0, 0.0), (4, 0.5, 3.0)),  # {-1, 1, 1, 1}
    ((2, 1.0, 0.0), (2, 0.0, 2.0), (4, 0.5, 3.0)),
])
def test_combine_by_hand(a, b, expected):
    assert agg.combine(a, b) == expected


def test_a_block_added_twice_is_refused_before_and_after_folding():
    m = agg.MetricStats()
    m.add_block(0, np.ones(3))
    m.add_block(1, np.ones(3))
    assert m.next_block == 2 and not m.pending  # blocks in order are folded, not kept
    m.add_block(3, np.ones(3))
    for block in (0, 1, 3):  # folded already, or waiting for block 2
        with pytest.raises(ValueError, match=f"block {block} added twice"):
            m.add_block(block, np.ones(3))


def test_moments_of_blocks_still_waiting_for_an_earlier_one():
    x = np.random.default_rng(6).normal(2.0, 0.5, 300)
    m = agg.MetricStats()
    m.add_block(2, x[200:])
    m.add_block(1, x[100:200])  # block 0 never came: both wait
    assert m.next_block == 0 and sorted(m.pending) == [1, 2]
    mean, std = m.mean_std()
    assert m.count == 200
    assert mean == pytest.approx(np.mean(x[100:]), rel=1e-14)
    assert std == pytest.approx(np.std(x[100:], ddof=1), rel=1e-12)


@pytest.mark.parametrize(("values", "mean", "std"), [
    ([0.25], 0.25, math.nan),  # one value: a mean, no standard deviation
    ([1.0, 4.0], 2.5, 3.0 / math.sqrt(2.0)),
    ([], math.nan, math.nan),
])
def test_mean_and_std_of_one_two_and_no_values(values, mean, std):
    got = _stats(np.array(values, float)).mean_std() if values else agg.MetricStats().mean_std()
    np.testing.assert_allclose(got, (mean, std), rtol=1e-15)


@pytest.mark.parametrize("n", [1, 2, 5, 7, 10, 20, 100, 101])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_percentiles_and_intervals_are_order_statistics_of_small_samples(n, sign):
    """Estimate X_(ceil(pn)) and interval [X_(r), X_(s)] with r, s from scipy.stats.binom; an
    end outside 1..n is NaN. Values 2**(i/16) sit in distinct bins, so each read is within half
    a bin of its order statistic (outer edge); a lower end at the smallest value or an upper
    end at the largest is that value."""
    x = sign * 2.0 ** (np.arange(n) / 16.0)
    m = _stats(np.random.default_rng(n).permutation(x), block=n)
    for of_abs in (True, False):
        data = np.sort(np.abs(x) if of_abs else x)
        for p in agg.PERCENTILES:
            est, lo, hi = m.quantile(p, of_abs, 0.95)
            k = math.ceil(round(p * n, 9))
            r = int(stats.binom.ppf(0.025, n, p))
            s = int(stats.binom.ppf(0.975, n, p)) + 1
            assert est == pytest.approx(data[k - 1], rel=2.0**-11)
            for end, rank, extreme in ((lo, r, 1), (hi, s, n)):
                if 1 <= rank <= n:
                    assert end == pytest.approx(data[rank - 1], rel=2.0**-10)
                    if rank == extreme:
                        assert end == data[rank - 1]
                else:
                    assert np.isnan(end)


@pytest.mark.parametrize("value", [1.0 + 0.9 / 1024, 1.0 + 0.1 / 1024, -(1.0 + 0.9 / 1024),
                                   -(1.0 + 0.1 / 1024), 3e-7])
def test_constant_values_give_that_value_exactly(value):
    """The bin's midpoint is clipped to the range of the values, from below or from above."""
    m = _stats(np.full(50, value), block=50)
    for of_abs, expected in ((False, value), (True, abs(value))):
        for p in agg.PERCENTILES:
            est, lo, _ = m.quantile(p, of_abs, 0.95)
            assert est == lo == expected
        assert m.value_range(of_abs) == (expected, expected)


def test_an_interval_end_on_the_last_valid_trial_is_that_trial_not_infinity():
    """100 trials, p95, 95 %: ranks r = 90, s = 100 (scipy). With 90 valid trials and 10
    censored the lower end is the largest valid value (its bin's lower edge); with 100 valid
    the upper end is the largest value."""
    _, r, s = agg.order_statistic_ranks(100, 0.95, 0.95)
    assert (r, s) == (stats.binom.ppf(0.025, 100, 0.95), stats.binom.ppf(0.975, 100, 0.95) + 1)
    x = 1.0 + np.arange(100) / 10.0
    _, lo, _ = _stats(x[:r], block=r).quantile(0.95, False, 0.95, censored=100 - r)
    assert x[r - 1] * (1 - 2.0**-10) <= lo <= x[r - 1]  # its bin's lower edge
    _, _, hi = _stats(x, block=100).quantile(0.95, False, 0.95)
    assert hi == x[-1]


SUMMARY_COLUMNS = ["variant", "metric", "percentiles_of", "percentiles_over", "sampling",
                   "trials", "count", "invalid", "invalid_fraction"]


def test_summary_of_one_to_ten_by_hand():
    """Values 1..10 (signed metric, sign flipped: percentiles of |x|): p50 = 5, p90 = 9,
    p95 = p99 = 10 (inverted CDF), within half a bin; the columns are the documented ones."""
    ps = agg.PointStats()
    ps.add_block(0, {("v", "m"): -np.arange(1.0, 11.0)}, {}, 10)  # no invalid entry at all
    row = ps.summary({"m": True}, 0.95).iloc[0]
    assert list(row.index) == [*SUMMARY_COLUMNS, *agg.VALUE_COLUMNS]
    assert (row["percentiles_of"], row["sampling"], row["invalid"]) == ("abs", "random", 0)
    for tag, expected in zip(agg.PERCENTILE_TAGS, (5.0, 9.0, 10.0, 10.0), strict=True):
        assert row[tag] == pytest.approx(expected, rel=2.0**-11)
    assert row["max"] == 10.0 and row["mean"] == -5.5
    assert row["std"] == pytest.approx(np.std(np.arange(1.0, 11.0), ddof=1), rel=1e-14)
    assert np.isfinite(row["p50_lo"]) and np.isfinite(row["p50_hi"])
    assert ps.summary({"m": False}, 0.95).iloc[0]["percentiles_of"] == "value"


def test_enumerated_cases_have_exact_statistics_without_intervals():
    ps = _point(1000, 0)
    spec = agg.SpecCheck("m", None, "p95", 2.0)
    row = ps.summary({"m": False}, 0.95, spec, sampled=False).iloc[0]
    assert row["sampling"] == "enumerated"
    assert all(np.isnan(row[f"{t}_{e}"]) for t in agg.PERCENTILE_TAGS for e in ("lo", "hi"))
    assert row["spec_lo"] == row["spec_hi"] == row["spec_value"] == row["p95"]
    assert row["verdict"] == "meets" and np.isnan(row["spec_coverage"])


def test_a_variant_without_trials_has_no_max_and_no_fraction():
    ps = agg.PointStats()
    ps.add_block(0, {("v", "m"): np.array([])}, {}, 0)
    row = ps.summary({"m": False}, 0.95).iloc[0]
    assert row["count"] == 0 and np.isnan(row["max"]) and np.isnan(row["invalid_fraction"])
    invalid = _point(0, 5).summary({"m": True}, 0.95).iloc[0]
    assert np.isnan(invalid["max"]) and np.isnan(invalid["p50"])


def test_spec_columns_value_and_wilks_coverage_of_a_max():
    """spec_value is the row's statistic when every trial has a value; a spec on the max of
    n sampled trials bounds (1 - confidence)**(1/n) of the population (Wilks)."""
    ps = _point(1000, 0)
    for stat in ("p95", "max"):
        row = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", None, stat, 2.0)).iloc[0]
        assert list(row.index)[-5:] == [*agg.SPEC_COLUMNS, "verdict", "spec_coverage"]
        assert row["spec_value"] == row[stat]
        if stat == "max":
            assert row["spec_coverage"] == pytest.approx(0.05 ** (1 / 1000), rel=1e-15)
        else:
            assert np.isnan(row["spec_coverage"])


def test_spec_on_the_magnitude_of_a_signed_metric():
    ps = agg.PointStats()
    ps.add_block(0, {("v", "m"): -np.linspace(1.0, 3.0, 1000)}, {"v": {"total": 0}}, 1000)
    for stat in ("p95", "max"):
        row = ps.summary({"m": True}, 0.95, agg.SpecCheck("m", None, stat, 3.5)).iloc[0]
        assert row["verdict"] == "meets" and row["spec_value"] == row[stat] > 2.8


@pytest.mark.parametrize(("sign", "signed", "verdict"), [
    (-1.0, True, "fails"), (1.0, True, "fails"), (-1.0, False, "meets")])
def test_a_bias_of_either_sign_fails_a_mean_spec_on_a_signed_metric(sign, signed, verdict):
    """Values 1..3, mean 2 (or -2), against mean <= 1: a signed metric's bias fails either
    way; an unsigned metric's negative mean is below the limit."""
    ps = agg.PointStats()
    ps.add_block(0, {("v", "m"): sign * np.linspace(1.0, 3.0, 1000)}, {"v": {"total": 0}},
                 1000)
    row = ps.summary({"m": signed}, 0.95, agg.SpecCheck("m", None, "mean", 1.0)).iloc[0]
    assert row["mean"] == pytest.approx(2.0 * sign, rel=1e-12)
    assert row["verdict"] == verdict
    assert row["spec_value"] == pytest.approx(2.0 if signed else 2.0 * sign, rel=1e-12)


def test_verdict_at_the_limit_itself():
    """'At most the limit': an interval ending on the limit meets it; one starting on it does
    not fail it."""
    ps = _point(1000, 0)
    row = ps.summary({"m": False}, 0.95).iloc[0]
    at_hi = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", None, "p50", row["p50_hi"]))
    at_lo = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", None, "p50", row["p50_lo"]))
    assert at_hi.iloc[0]["verdict"] == "meets" and at_lo.iloc[0]["verdict"] == "undecided"
    at_max = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", None, "max", row["max"]))
    assert at_max.iloc[0]["verdict"] == "meets"


def test_std_of_a_single_trial_is_undecided():
    row = _point(1, 0).summary({"m": False}, 0.95, agg.SpecCheck("m", None, "std", 1.0)).iloc[0]
    assert np.isnan(row["spec_value"]) and row["verdict"] == "undecided"


def _kernel_blocks(x, ps, keys):
    """Feed blocks the way a fused kernel does: histograms into the matrix, moments apart."""
    hist = ps.histogram_matrix(keys, set(keys))
    for b, block in enumerate(x):
        moments = {}
        for r, key in enumerate(keys):
            v = block[r][np.isfinite(block[r])]
            hist[r] += np.bincount(agg.bin_index(v), minlength=agg.N_BINS)
            moments[key] = (v.size, v.mean() if v.size else 0.0,
                            ((v - v.mean()) ** 2).sum() if v.size else 0.0,
                            v.min() if v.size else np.inf, v.max() if v.size else -np.inf)
        ps.add_block_summary(b, moments, {"v": {"total": int(np.isnan(block[0]).sum())}},
                             block.shape[1])


def test_fused_kernel_path_equals_the_per_trial_path_and_survives_pickling():
    import pickle

    rng = np.random.default_rng(7)
    keys = [("v", "a"), ("v", "b")]
    x = rng.normal(1e-3, 2e-4, (4, 2, 250))
    x[1] = np.nan  # a block without any value
    x[2, :, ::7] = np.nan
    fused, direct = agg.PointStats(), agg.PointStats()
    _kernel_blocks(x, fused, keys)
    for b, block in enumerate(x):
        direct.add_block(b, {k: block[r] for r, k in enumerate(keys)},
                         {"v": {"total": int(np.isnan(block[0]).sum())}}, block.shape[1])
    assert (fused.trials, fused.blocks) == (direct.trials, direct.blocks) == (1000, 4)
    signed = {"a": False, "b": True}
    expected = direct.summary(signed, 0.95)
    pd.testing.assert_frame_equal(fused.summary(signed, 0.95), expected)
    assert fused.hist_matrix.dtype == np.int64  # integer counts add exactly
    assert [c for c in expected.columns if c.startswith("invalid")] == ["invalid",
                                                                        "invalid_fraction"]
    copy = pickle.loads(pickle.dumps(fused))
    assert copy.hist_matrix is None
    assert all(m.hist.dtype == np.int64 for m in copy.metrics.values())
    pd.testing.assert_frame_equal(copy.summary(signed, 0.95), expected)
    for key in keys:
        np.testing.assert_array_equal(copy.metrics[key].hist, direct.metrics[key].hist)


def test_point_stats_merged_from_parts_equal_one_accumulator():
    rng = np.random.default_rng(8)
    x = rng.lognormal(-5, 1, (6, 300))
    whole, first, second = agg.PointStats(), agg.PointStats(), agg.PointStats()
    for b in range(6):
        invalid = {"v": {"total": b, "OUTSIDE_FOV": b}}
        whole.add_block(b, {("v", "m"): x[b]}, invalid, 300 + b)
        (first if b < 3 else second).add_block(b, {("v", "m"): x[b]}, invalid, 300 + b)
    second.add_block(0, {("w", "m"): x[0]}, {}, 0)  # a key only the second part has
    whole.add_block(0, {("w", "m"): x[0]}, {}, 0)
    first.merge(second)
    assert (first.trials, first.blocks) == (whole.trials, whole.blocks)
    pd.testing.assert_frame_equal(first.summary({"m": True}, 0.9),
                                  whole.summary({"m": True}, 0.9))
    spec = agg.SpecCheck("m", None, "p95", 1.0)
    done = first.finalize({"m": True}, 0.9, spec, sampled=False)
    pd.testing.assert_frame_equal(done.summary, whole.summary({"m": True}, 0.9, spec, False))
    assert "verdict" in done.summary and (done.summary["sampling"] == "enumerated").all()
    assert set(done.histograms) == {("v", "m"), ("w", "m")}


def test_coarse_histogram_counts_magnitudes_in_32_bins_per_octave():
    x = np.array([0.0, 1e-13, -1.0, 1.0, 1.0 + 1 / 32, 1.5, -3.0, 3e5, -7e4, 2.0**-40])
    m = _stats(x, block=x.size)
    lower, upper, counts = m.coarse_histogram()
    assert counts.sum() == x.size and np.all(lower < upper)
    a = np.abs(x)
    for lo, hi, c in zip(lower, upper, counts, strict=True):
        assert c == np.sum((a >= lo) & (a < hi)) or (lo == 0.0 and c == np.sum(a < hi))
    # zero bin, 2**-40, [1, 1+1/32) twice, [1+1/32, ...), 1.5, 3, and overflow (two values)
    assert counts.tolist() == [2, 1, 2, 1, 1, 1, 2]
    assert (lower[0], upper[0], lower[-1], upper[-1]) == (0.0, 2.0**-40, 2.0**16, np.inf)
    assert upper[2] == 1.0 + 1 / 32 and lower[2] == 1.0


@pytest.mark.parametrize(("values", "limit", "verdict"), [
    ([3.0, 4.0], 3.6, "meets"),  # rms sqrt(12.5) = 3.536 (the mean, 3.5, would also meet)
    ([3.0, 4.0], 3.5, "fails"),  # ... but not 3.5, which the mean would meet
    ([-3.0, 3.0], 2.9, "fails"),  # rms 3 of a zero-mean pair
])
def test_spec_rms_is_the_root_mean_square_by_hand(values, limit, verdict):
    """rms = sqrt(mean of squares) over all trials (the 1σ of an RSS budget), no interval."""
    ps = agg.PointStats()
    ps.add_block(0, {("v", "m"): np.array(values)}, {"v": {"total": 0}}, len(values))
    row = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", None, "rms", limit)).iloc[0]
    assert row["spec_value"] == pytest.approx(np.sqrt(np.mean(np.square(values))), rel=1e-15)
    assert row["verdict"] == verdict
    ps.add_block(1, {("v", "m"): np.array([np.nan])}, {"v": {"total": 1}}, 1)
    row = ps.summary({"m": False}, 0.95, agg.SpecCheck("m", None, "rms", 100.0)).iloc[0]
    assert row["spec_value"] == np.inf and row["verdict"] == "fails"
