"""Seed 000, Table 2 explained: the superposition search and its bound, by hand and against the
full Monte Carlo (slow)."""

from dataclasses import replace

import numpy as np
import pytest

from montecarlo.seed000 import ta_budget
from montecarlo.seed000 import ta_effects as te
from montecarlo.seed000 import table2_search as ts
from montecarlo.seed000 import transfer_alignment as ta
from montecarlo.seed000.table2 import TABLE2_ROWS, grade_config
from montecarlo.units import ARCMIN

FAST = dict(dt=0.1, kf_interval=2)


def _synthetic(heading, level, matched=0.0):
    """Responses whose lever-arm effect alone gives (heading, level) [arcmin] at 1 m."""
    rows = []
    for h, lv in zip(heading, level, strict=True):
        second = {e.name: np.zeros(3) for e in ts.EFFECTS[1:]}
        second["lever_arm_error"] = np.array([lv**2 / 2, lv**2 / 2, h**2]) * ARCMIN**2
        rows.append(ts.RowResponses(np.full(3, matched**2 * ARCMIN**2), np.zeros(3), second))
    return rows


def test_search_finds_a_planted_configuration():
    """Table 2 planted exactly at 1 m of lever-arm error: found with a zero gap, one effect."""
    paper = np.array([[r.heading_arcmin, r.level_arcmin] for r in TABLE2_ROWS])
    found = ts.search({"planted": _synthetic(paper[:, 0], paper[:, 1])}, max_effects=1)
    best = found.iloc[0]
    assert best.effects == ("lever_arm_error",) and best.params == {"lever_arm_error": 1.0}
    assert best.worst_gap_arcmin == pytest.approx(0.0, abs=1e-12)
    none = found[found["size"] == 0].iloc[0]
    assert none.worst_gap_arcmin == pytest.approx(20.0)  # nothing: every row at 0


def test_search_predicts_by_root_sum_square():
    """Matched 3′ per axis plus the planted effect at 2 m: sqrt(3² + (2 x)²) on each column."""
    resp = _synthetic([1.0] * 5, [1.0] * 5, matched=3.0)[0]
    h, lv = ts.predict(resp, {"lever_arm_error": 2.0})
    assert h / ARCMIN == pytest.approx(np.hypot(3.0, 2.0), rel=1e-12)
    assert lv / ARCMIN == pytest.approx(np.sqrt(2 * 9.0 + 4.0), rel=1e-12)


def test_ratio_of_sums_never_exceeds_the_largest_source_ratio():
    """The argument of source_ratios: for any non-negative weights, the rows 2 -> 3 ratio of a
    configuration is at most the largest single source's (checked on random sources)."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        a, b, w = rng.random(6), rng.random(6), rng.random(6) * (rng.random(6) < 0.7)
        if w @ b == 0:
            continue
        assert np.sqrt(w @ a / (w @ b)) <= np.sqrt(np.max(a[w > 0] / b[w > 0])) * (1 + 1e-12)


def test_unit_responses_are_linear_to_second_order_in_the_lag_and_the_lever_arm():
    """The superposition's premise: the error is linear in a lag and a lever-arm error, its
    departure from linearity second order: r(4s) - 2 r(2s) = 4 (r(2s) - 2 r(s)) + O(s³)."""
    cfg = ta.AlignmentConfig(duration=40.0, **FAST)
    m = cfg.n_steps // cfg.kf_interval
    sizes = np.array([1.0, 2.0, 4.0])
    lag = np.repeat(np.array([0.02, 0.0])[None], 3, 0) * sizes[:, None]  # (3 sizes, 2 effects)
    arm = np.array([[0.0, 0.0, 0.0], [1.0, -0.5, 0.2]])
    draws = replace(te.EffectDraws.zeros(6, m),
                    time_tag=np.repeat(lag.reshape(6, 1), m, axis=1),
                    lever_arm_error=(sizes[:, None, None] * arm[None]).reshape(6, 3))
    r = ta.response(cfg, draws).final_error().reshape(3, 2, 3)
    d1 = np.linalg.norm(r[1] - 2 * r[0], axis=-1)
    d2 = np.linalg.norm(r[2] - 2 * r[1], axis=-1)
    np.testing.assert_allclose(d2 / d1, 4.0, rtol=0.1)
    assert np.all(d1 < 0.01 * np.linalg.norm(r[0], axis=-1))  # and small at these sizes


@pytest.mark.slow
def test_error_moments_agree_with_the_full_monte_carlo():
    """ta_budget's mean and covariance (lag 40 ms, lever arm ±2 m) against 400 simulated runs:
    mean within 4 standard errors; each variance within the chi-square 99.9 % band."""
    from scipy import stats

    cfg = ta.AlignmentConfig(duration=60.0, **FAST)
    mean, cov = ta_budget.error_moments(cfg, 0.04, 2.0)
    n = 400
    err = ta.simulate(cfg, np.random.default_rng(11), n,
                      te.TruthEffects(time_offset=0.04, lever_arm_error=2.0)).final_error()
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(err.mean(0) - mean) < 4 * sd / np.sqrt(n))
    ratio = err.var(0, ddof=1) / np.diag(cov)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n - 1) / (n - 1)
    assert np.all((lo < ratio) & (ratio < hi))
    assert np.abs(mean).max() > 3 * sd.max() / np.sqrt(n)  # the lag's mean is visible


@pytest.mark.slow
def test_search_rates_change_the_filter_by_under_a_thousandth():
    """The search's 10 Hz IMU / 5 Hz updates against the default 50 Hz: final 1σ, rows 1, 3."""
    for row in (TABLE2_ROWS[0], TABLE2_ROWS[2]):
        for matching in (False, True):
            a = grade_config(row.gyro_drift, row.accel_bias,
                             ta.AlignmentConfig(attitude_matching=matching))
            b = replace(a, **FAST)
            np.testing.assert_allclose(np.diag(ta.final_attitude_covariance(b)),
                                       np.diag(ta.final_attitude_covariance(a)), rtol=1e-3)


@pytest.mark.slow
def test_table2_explanation_end_to_end():
    """The search's closest configuration, confirmed by a full Monte Carlo: the superposition
    predicts the simulation within 4 combined standard errors (the Monte Carlo's, and the
    superposition's own from its sampled effects: a second moment from n Gaussian paths has
    relative standard error sqrt(2/n)); and the bound says why no configuration closes
    rows 2 -> 3 in every variant."""
    runs = 100
    ex = ts.explain_table2(runs=runs, confirm_runs=200, seed=3)
    best, check = ex["best"], ex["check"]
    resp = ex["responses"][best.variant]
    for i in range(5):
        sampled = sum(v**2 * resp[i].second[k] for k, v in best.params.items()
                      if k in ts.SAMPLED) + np.zeros(3)
        for col, idx in (("heading", [2]), ("level", [0, 1])):
            pred = getattr(best, col)[i]
            se_pred = sampled[idx].sum() * np.sqrt(2 / runs) / (2 * pred * ARCMIN) / ARCMIN
            mc, se = check[f"{col}_mc"].iloc[i], check[f"{col}_se"].iloc[i]
            assert abs(mc - pred) < 4 * np.hypot(se, se_pred), (i, col)
    ratios = ex["ratios"]
    for variant, sub in ratios.groupby("variant"):
        reach = {c: sub[c].max() for c in ("heading", "level")}
        if best.worst_gap_arcmin > 0.5:
            assert (reach["heading"] < ts.PAPER_RATIO_2_3["heading"]
                    or reach["level"] < ts.PAPER_RATIO_2_3["level"]), variant
    text = ts.format_explanation(ex)
    assert "13" in text and "Closest per number of effects" in text
