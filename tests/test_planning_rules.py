"""Trial planning by hand: closed forms for the order-statistic counts, and ``pilot_plan`` on a
summary written by hand (no study is run)."""

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binom

from montecarlo.design import planning
from montecarlo.engine.aggregate import order_statistic_ranks
from montecarlo.errors import InputError


def test_statistics_with_an_interval():
    assert all(planning.has_interval(s) for s in ("p50", "p90", "p95", "p99", "cvar95"))
    assert not any(planning.has_interval(s) for s in ("mean", "std", "max", "p42"))


@pytest.mark.parametrize("k, p, c", [(0, 0.95, 0.95), (1, 0.0, 0.95), (1, 1.0, 0.95),
                                     (1, 0.95, 0.0), (1, 0.95, 1.0)])
def test_order_statistic_trials_refuses_levels_outside_zero_one(k, p, c):
    with pytest.raises(ValueError, match=r"^need 0 < p < 1, 0 < confidence < 1 and k >= 1$"):
        planning.order_statistic_trials(k, p, c)


def test_order_statistic_trials_at_a_tie_and_by_wilks_formula():
    """P(B >= k) for n = k trials is (1 - p)^k: k = 3, p = 0.5 gives exactly 0.125, so at
    confidence 0.125 three trials do (ties count as covering) and at 0.126 they do not. k = 1
    is Wilks' ceil(ln(1 - c) / ln p); the k-th largest against a scan of scipy's binomial."""
    assert planning.order_statistic_trials(3, 0.5, 0.125) == 3
    assert planning.order_statistic_trials(1, 0.5, 0.5) == 1
    assert planning.order_statistic_trials(3, 0.5, 0.126) > 3
    for p, c in ((0.9, 0.9), (0.99, 0.99), (0.5, 0.95), (0.95, 0.5)):
        n = math.ceil(math.log(1 - c) / math.log(p))
        assert planning.order_statistic_trials(1, p, c) == n
    for k in (2, 3, 5, 10):
        fewest = next(n for n in range(k, 10_000) if binom.sf(k - 1, n, 0.05) >= 0.95)
        assert planning.order_statistic_trials(k, 0.95, 0.95) == fewest


def test_distribution_free_table_and_wilks_text():
    """p = 0.95, c = 0.95: the max of 59 trials (ln 0.05 / ln 0.95 = 58.40), the 2nd largest
    of 93 (Wilks' table); the others by a scan of scipy's binomial."""
    table = planning.distribution_free_table(0.95, 0.95)
    assert list(table.columns) == ["k (k-th largest)", "trials"]
    assert list(table["k (k-th largest)"]) == [1, 2, 3, 5, 10]
    expected = [next(n for n in range(k, 10_000) if binom.sf(k - 1, n, 0.05) >= 0.95)
                for k in (1, 2, 3, 5, 10)]
    assert list(table["trials"]) == expected and expected[:2] == [59, 93]
    four = next(n for n in range(4, 10_000) if binom.sf(3, n, 0.05) >= 0.95)
    assert list(planning.distribution_free_table(0.95, 0.95, (4,))["trials"]) == [four]
    assert planning.wilks_text(0.95, 0.95) == (
        "the max of 59 trials bounds the 0.95-quantile with 95% confidence "
        "(Wilks: ln(1 - 0.95) / ln(0.95) = 58.4)")
    assert planning.wilks_text(0.99, 0.9) == (
        "the max of 230 trials bounds the 0.99-quantile with 90% confidence "
        "(Wilks: ln(1 - 0.9) / ln(0.99) = 229.1)")
    assert math.ceil(math.log(0.1) / math.log(0.99)) == 230


@pytest.mark.parametrize("p, c", [(0.95, 0.95), (0.9, 0.9), (0.5, 0.95), (0.99, 0.95),
                                  (0.1, 0.95), (0.75, 0.99)])
def test_interval_trials_is_the_closed_form(p, c):
    """Both ends of the p-quantile's interval exist from n >= ln((1 - c)/2) / ln(max(p, 1 - p))
    (interval_trials' docstring): 71.9 -> 72 at p = c = 0.95, 28.4 -> 29 at 0.9, 5.3 -> 6 for
    the median, 35.0 -> 36 for p = 0.1 (the lower end decides)."""
    n = math.ceil(math.log((1 - c) / 2) / math.log(max(p, 1 - p)))
    assert planning.interval_trials(p, c) == n


@pytest.mark.parametrize("p, half, n_normal", [(0.95, 0.01, 1825), (0.5, 0.05, 384),
                                                (0.9, 0.05, 138), (0.5, 0.2, 24)])
def test_quantile_level_trials_is_a_narrow_count_just_after_a_wide_one(p, half, n_normal):
    """The count returned spans at most p +- half in quantile level and the one before it
    does not; near the normal approximation 1.96^2 p (1 - p) / half^2 (by hand: 1825, 384,
    138, 24), within the ranks' discreteness."""
    def narrow(n):
        _, r, s = order_statistic_ranks(n, p, 0.95)
        return r >= 1 and s <= n and (s - r) / n <= 2 * half

    n = planning.quantile_level_trials(p, half, 0.95)
    assert narrow(n) and not narrow(n - 1)
    assert n_normal == pytest.approx(1.959964 ** 2 * p * (1 - p) / half ** 2, abs=1)
    assert 0.9 * n_normal < n < 1.45 * n_normal
    with pytest.raises(ValueError, match=r"^need 0 < half_width < min\(p, 1 - p\)$"):
        planning.quantile_level_trials(p, min(p, 1 - p), 0.95)
    with pytest.raises(ValueError, match="half_width"):
        planning.quantile_level_trials(p, 0.0, 0.95)


def test_a_wide_quantile_level_band_needs_only_the_trials_of_an_interval():
    """The median within 0.5 +- 0.45 at 95 %: any interval that exists is narrow enough, so
    the count is the first with both ends, ln(0.025) / ln(0.5) = 5.32 -> 6 (the closed form
    of interval_trials): ranks (1, 6) span 5/6 = 0.83 <= 0.9. The search once started at 9."""
    assert planning.quantile_level_trials(0.5, 0.45, 0.95) == 6


def test_trials_to_decide_rounds_up_and_broadcasts():
    """1000 (0.2 / 0.3)^2 = 444.4 -> 445; per row n0, h0 and d; d <= 0 needs infinitely many."""
    n = planning.trials_to_decide([1000, 500, 100], [0.2, 0.2, 0.5], [0.3, 0.1, 0.5])
    np.testing.assert_array_equal(n, [445, 2000, 100])
    assert planning.trials_to_decide(1000, 0.2, -0.1) == np.inf


# --- pilot_plan on a summary written by hand ---------------------------------------------------


def _result(spec=None, confidence=0.95):
    metric = SimpleNamespace(name="rotation_angle")
    study = SimpleNamespace(spec=spec, metrics=[("m", metric)], sweep_keys=["geometry.L_m"],
                            header=SimpleNamespace(confidence=confidence))
    return SimpleNamespace(study=study)


def _summary(stat="p95", value=(4.0, 4.0, 4.0, 4.0), lo=(3.75, 3.875, 3.0, 3.875),
             hi=(4.125, 4.375, 4.25, 4.0625),
             verdict=("undecided", "undecided", "meets", "undecided"),
             sampling=("random", "random", "random", "enumerated"), trials=1000):
    rows = []
    for i in range(len(value)):
        for metric, variant in (("rotation_angle", "raw"), ("rotation_angle", "normalised"),
                                ("eq18_angle", "raw")):
            shift = 0.0 if (metric, variant) == ("rotation_angle", "raw") else 100.0
            rows.append({"point": i, "geometry.L_m": 10.0 * (i + 1), "variant": variant,
                         "metric": metric, "unit": "mrad", "trials": trials,
                         "sampling": sampling[i], stat: value[i] + shift,
                         f"{stat}_lo": lo[i] + shift, f"{stat}_hi": hi[i] + shift,
                         "verdict": verdict[i]})
    return pd.DataFrame(rows)


def test_pilot_plan_by_hand():
    """Spec p95 <= 4.5 on rotation_angle, variant raw. Half-width = the larger side of the
    interval: 0.25, 0.375, 1.0, 0.125 (binary fractions: no rounding). Trials to decide =
    ceil(1000 (h / 0.5)^2): 250, 562.5 -> 563; the decided point (meets) and the enumerated one
    keep their 1000. Trials for a full width of 0.125: ceil(1000 (2 h / 0.125)^2) = 16000,
    36000, 256000; enumerated: 1000."""
    spec = SimpleNamespace(metric="rotation_angle", statistic="p95", limit=4.5, variant="raw")
    plan = planning.pilot_plan(_result(spec), _summary(), width=0.125)
    assert list(plan.columns) == ["point", "geometry.L_m", "variant", "unit", "trials",
                                  "sampling", "p95", "p95_lo", "p95_hi", "verdict",
                                  "trials_to_decide", "trials_for_width_0.125"]
    assert list(plan["point"]) == [0, 1, 2, 3] and set(plan["variant"]) == {"raw"}
    assert list(plan["p95_lo"]) == [3.75, 3.875, 3.0, 3.875]
    assert list(plan["p95_hi"]) == [4.125, 4.375, 4.25, 4.0625]
    assert list(plan["p95"]) == [4.0] * 4
    assert list(plan["verdict"]) == ["undecided", "undecided", "meets", "undecided"]
    assert list(plan["trials_to_decide"]) == [250, 563, 1000, 1000]
    assert str(plan["trials_to_decide"].dtype) == "Int64"
    assert list(plan["trials_for_width_0.125"]) == [16000, 36000, 256000, 1000]
    assert str(plan["trials_for_width_0.125"].dtype) == "Int64"
    assert list(plan.index) == [0, 1, 2, 3]


def test_pilot_plan_decides_on_the_statistic_the_verdict_judges():
    """With 6 % of the trials without a value, the p95 over all trials (what the verdict
    judges) is 4.25 in [4.0, 4.25] and open above at point 1; over the trials with a value it is
    4.0 in [3.75, 4.125]. Against p95 <= 4.5 the plan works from the judged one: half-width 0.25
    at distance 0.25 -> 1000 trials at point 0; open above -> <NA> at point 1, for the
    decision and for any width. At point 2 more than 5 % have no value: the judged p95 is
    infinite and fails, decided with the pilot's trials, and no width can be reached."""
    spec = SimpleNamespace(metric="rotation_angle", statistic="p95", limit=4.5, variant="raw")
    summary = _summary(value=(4.0, 4.0, 4.0), lo=(3.75, 3.75, 3.75), hi=(4.125, 4.125, 4.125),
                       verdict=("undecided", "undecided", "fails"), sampling=("random",) * 3)
    summary["spec_value"] = np.where(summary["point"] < 2, summary["p95"] + 0.25, np.inf)
    summary["spec_lo"] = np.where(summary["point"] < 2, summary["p95_lo"] + 0.25, np.inf)
    summary["spec_hi"] = np.where(summary["point"] == 0, summary["p95_hi"] + 0.125, np.inf)
    plan = planning.pilot_plan(_result(spec), summary, width=0.5)
    assert list(plan["p95"]) == [4.25, 4.25, np.inf]
    assert list(plan["p95_lo"]) == [4.0, 4.0, np.inf]
    assert list(plan["p95_hi"]) == [4.25, np.inf, np.inf]
    assert list(plan["trials_to_decide"].astype(object).fillna(-1)) == [1000, -1, 1000]
    assert list(plan["trials_for_width_0.5"].astype(object).fillna(-1)) == [1000, -1, -1]


def test_pilot_plan_on_a_value_at_the_limit_and_without_a_variant():
    """A statistic exactly at the limit can never be decided (<NA>) unless it is decided or
    enumerated already; without a spec variant every variant of the metric is planned (the
    normalised rows, 100 from the limit, need ceil(1000 (0.25 / 100)^2) = 1 trial); width not
    asked: no width column."""
    spec = SimpleNamespace(metric="rotation_angle", statistic="p95", limit=4.0, variant=None)
    plan = planning.pilot_plan(_result(spec), _summary())
    assert list(plan["variant"]) == ["raw", "normalised"] * 4
    assert plan["trials_to_decide"].isna().tolist() == [True, False, True, False,
                                                        False, False, False, False]
    assert list(plan["trials_to_decide"][[1, 3, 4, 6]]) == [1, 1, 1000, 1000]
    assert not any(c.startswith("trials_for_width") for c in plan.columns)


def test_pilot_plan_of_a_statistic_without_an_interval_plans_its_p95():
    """A spec on the mean or without spec: the plan shows the p95 and no verdict; no spec
    plans the study's first metric."""
    spec = SimpleNamespace(metric="eq18_angle", statistic="mean", limit=1.0, variant=None)
    plan = planning.pilot_plan(_result(spec), _summary(), width=1.0)
    assert "verdict" not in plan.columns and "trials_to_decide" not in plan.columns
    assert list(plan["p95"]) == [104.0] * 4
    assert list(plan["trials_for_width_1"]) == [250, 563, 4000, 1000]
    plan = planning.pilot_plan(_result(None), _summary())
    assert list(plan["p95"]) == [4.0, 104.0] * 4 and "verdict" not in plan.columns


def test_pilot_plan_of_a_superquantile():
    spec = SimpleNamespace(metric="rotation_angle", statistic="cvar95", limit=4.5,
                           variant="raw")
    plan = planning.pilot_plan(_result(spec), _summary(stat="cvar95"))
    assert list(plan["trials_to_decide"]) == [250, 563, 1000, 1000]
    assert list(plan["cvar95"]) == [4.0] * 4


def test_a_pilot_that_cannot_bound_its_statistic_names_the_trials_needed():
    """p99 at 90 %: both ends from ln(0.05) / ln(0.99) = 298.1, so 299 trials; the smallest
    unbounded pilot is named; an enumerated point without an interval is no reason to refuse."""
    spec = SimpleNamespace(metric="rotation_angle", statistic="p99", limit=4.5, variant="raw")
    summary = _summary(stat="p99", hi=(np.nan, 4.375, np.nan, np.nan))
    summary.loc[summary["point"] == 2, "trials"] = 250
    with pytest.raises(InputError, match=(
            r"^plan: a pilot of 250 trials per grid point cannot bound the p99 at 90% confidence "
            r"\(its interval needs at least 299 trials\); give --trials 299 or more$")):
        planning.pilot_plan(_result(spec, confidence=0.9), summary)
    assert math.ceil(math.log(0.05) / math.log(0.99)) == 299
    bounded = _summary(stat="p99", hi=(4.125, 4.375, 4.25, np.nan))
    plan = planning.pilot_plan(_result(spec, confidence=0.9), bounded)
    assert list(plan["trials_to_decide"]) == [250, 563, 1000, 1000]
    nan_value = _summary(stat="p99", value=(np.nan, 4.0, 4.0, 4.0), lo=(np.nan, 3.875, 3.0, 3.875),
                         hi=(np.nan, 4.375, 4.25, 4.0625))
    plan = planning.pilot_plan(_result(spec, confidence=0.9), nan_value)
    assert plan["trials_to_decide"].isna().tolist() == [True, False, False, False]


def test_quantile_level_trials_stored_counts():
    """Regression (the counts ``plan`` prints): the bisection from 16 trials, doubling, returns
    these whole numbers. Near-monotone: for the median at +-0.2, 25 trials are already narrow
    but 26-32 are not all, and the bisection between 16 and 32 returns 33. At 10 trials the
    median's interval of p = 0.4 reaches rank 1 and that of p = 0.6 reaches rank n."""
    for p, half, n in ((0.4, 0.35, 10), (0.6, 0.35, 10), (0.5, 0.2, 33), (0.7, 0.2, 27),
                       (0.95, 0.01, 1900)):
        got = planning.quantile_level_trials(p, half, 0.95)
        assert type(got) is int and got == n, (p, half, got)
    _, r, s = order_statistic_ranks(10, 0.4, 0.95)
    assert r == 1
    _, r, s = order_statistic_ranks(10, 0.6, 0.95)
    assert s == 10


def test_counts_are_whole_numbers():
    assert type(planning.interval_trials(0.95, 0.95)) is int
    assert type(planning.order_statistic_trials(2, 0.95, 0.95)) is int


def test_trials_to_decide_of_a_zero_interval_at_the_limit_is_infinite_without_a_warning():
    """h = 0 and d = 0: 0/0 is not computed into the result (inf, not NaN) and warns nothing
    (the test configuration turns warnings into errors)."""
    assert planning.trials_to_decide(1000, 0.0, 0.0) == np.inf
    np.testing.assert_array_equal(planning.trials_to_decide([10, 10], [0.0, 1.0], [0.0, 0.0]),
                                  [np.inf, np.inf])


def test_a_superquantile_pilot_that_cannot_bound_it_names_the_trials_of_its_level():
    """cvar95 is read at level 0.95: both ends from ln(0.025) / ln(0.95) = 71.9, 72 trials."""
    spec = SimpleNamespace(metric="rotation_angle", statistic="cvar95", limit=4.5,
                           variant="raw")
    summary = _summary(stat="cvar95", hi=(np.nan, 4.375, 4.25, np.nan), trials=50)
    with pytest.raises(InputError, match=r"pilot of 50 trials .* cvar95 at 95% confidence "
                                         r"\(its interval needs at least 72 trials\)"):
        planning.pilot_plan(_result(spec), summary)


def test_trials_to_decide_stay_integers_when_none_can_be_given():
    """Every point exactly at the limit: the column is all <NA>, still of integer type."""
    spec = SimpleNamespace(metric="rotation_angle", statistic="p95", limit=4.0, variant="raw")
    summary = _summary(verdict=("undecided",) * 4, sampling=("random",) * 4)
    plan = planning.pilot_plan(_result(spec), summary)
    assert plan["trials_to_decide"].isna().all()
    assert str(plan["trials_to_decide"].dtype) == "Int64"
