"""The generic DIA engine on a linear toy problem whose statistics have closed forms.

Base model a + b x; candidates are further columns. For a linear model the likelihood-ratio
statistic of a candidate equals the drop of chi2 when it is added (checked with numpy's lstsq),
its distribution under the base model is chi2(q) (checked by Monte Carlo), and its
noncentrality at the MDB is lambda0 (Baarda).
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.multitest import multipletests

from montecarlo.discrepancy.candidate_tests import (
    analyse_candidates,
    canonical_correlation,
    chi2_red_band,
    holm,
    log_chi2_sf,
    log_chi2_sf_asymptotic,
    noncentrality,
)
from montecarlo.discrepancy.confounding import separated
from montecarlo.discrepancy.design import design_mdb
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model, jacobian
from montecarlo.discrepancy.problem import Effect, Problem

X = np.linspace(-1.0, 1.0, 40)
COLUMNS = {
    "quadratic": X**2,
    "duplicate": 2.0 * X,  # the slope's column: absorbed
    "cubic": X**3,
    "near_quadratic": X**4,  # correlates 0.959 with the quadratic (both projected)
    "tiny": X**2 - X**4,
}
BOUNDS = {"quadratic": 100.0, "duplicate": 10.0, "cubic": 10.0, "near_quadratic": 10.0,
          "tiny": 1e-3}


def toy_problem(y: np.ndarray, sigma: float = 1.0) -> Problem:
    base = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)
    cands = tuple(Effect(n, (f"c_{n}",), ((-BOUNDS[n], BOUNDS[n]),), (1e-3,))
                  for n in COLUMNS)

    def residuals(v):
        def p(name):
            return np.asarray(v.get(name, 0.0), float)
        pred = p("a") + p("b") * X + sum(p(f"c_{n}") * c for n, c in COLUMNS.items())
        return (y - pred) / sigma

    return Problem("toy", base, cands, residuals, {"a": 0.0, "b": 0.0})


def chi2_of(columns, y):
    A = np.column_stack(columns)
    coef = np.linalg.lstsq(A, y, rcond=None)[0]
    r = y - A @ coef
    return float(r @ r), coef


def test_statistic_is_the_chi2_drop_of_the_refit():
    """Linear model: T = chi2(base) - chi2(base + candidate), estimate = lstsq coefficient."""
    rng = np.random.default_rng(1)
    y = 0.3 + 0.5 * X + 0.8 * X**2 + rng.standard_normal(X.size)
    problem = toy_problem(y)
    fit = fit_model(problem, ())
    tests = {t.name: t for t in analyse_candidates(problem, fit)}
    chi2_base, _ = chi2_of([np.ones_like(X), X], y)
    assert fit.chi2 == pytest.approx(chi2_base, rel=1e-9)
    for name in ("quadratic", "cubic", "near_quadratic"):
        chi2_with, coef = chi2_of([np.ones_like(X), X, COLUMNS[name]], y)
        t = tests[name]
        assert t.statistic == pytest.approx(chi2_base - chi2_with, rel=1e-7)
        assert t.estimate[f"c_{name}"] == pytest.approx(coef[2], rel=1e-7)
        A = np.column_stack([np.ones_like(X), X, COLUMNS[name]])
        assert t.stderr[f"c_{name}"] == pytest.approx(math.sqrt(np.linalg.inv(A.T @ A)[2, 2]),
                                                      rel=1e-7)
        assert t.p_value == pytest.approx(stats.chi2.sf(t.statistic, 1), rel=1e-9)


def test_absorbed_undetectable_and_correlation():
    y = 0.3 + 0.5 * X
    problem = toy_problem(y)
    fit = fit_model(problem, ())
    tests = {t.name: t for t in analyse_candidates(problem, fit)}
    assert tests["duplicate"].status == "absorbed"
    assert tests["duplicate"].absorbed_by == {"c_duplicate": ["b"]}
    assert tests["duplicate"].retained["c_duplicate"] < 1e-6
    assert tests["tiny"].status == "undetectable"
    assert tests["quadratic"].status == "testable"
    # independent: cosine of the two columns projected orthogonal to (1, x)
    Q = np.linalg.qr(np.column_stack([np.ones_like(X), X]))[0]
    g1, g2 = (c - Q @ (Q.T @ c) for c in (COLUMNS["quadratic"], COLUMNS["near_quadratic"]))
    cosine = abs(g1 @ g2) / (np.linalg.norm(g1) * np.linalg.norm(g2))
    assert cosine > 0.9
    assert canonical_correlation(tests["quadratic"], tests["near_quadratic"]) == \
        pytest.approx(cosine, rel=1e-9)
    assert canonical_correlation(tests["quadratic"], tests["cubic"]) < 1e-9


def test_mdb_has_noncentrality_lambda0():
    """|Gbar mdb|^2 = lambda0 of the candidate's own test at power 0.8, at its share of the
    family (the candidates and the global test: alpha / (m + 1))."""
    problem = toy_problem(0.3 + 0.5 * X)
    fit = fit_model(problem, ())
    tests = {t.name: t for t in analyse_candidates(problem, fit)}
    family = sum(t.status in ("testable", "undetectable") for t in tests.values())
    lam0 = noncentrality(0.01 / (family + 1), 1)
    Q = np.linalg.qr(np.column_stack([np.ones_like(X), X]))[0]
    g = COLUMNS["quadratic"] - Q @ (Q.T @ COLUMNS["quadratic"])
    t = tests["quadratic"]
    assert t.lambda0 == pytest.approx(lam0, rel=1e-12)
    assert (t.mdb["c_quadratic"] * np.linalg.norm(g)) ** 2 == pytest.approx(lam0, rel=1e-7)


def test_noncentrality_reproduces_baardas_lambda0():
    """Baarda (1968): alpha0 = 0.1 %, beta0 = 80 %, one dimension -> lambda0 = 17.075."""
    assert noncentrality(0.001, 1, 0.80) == pytest.approx(17.075, abs=2e-3)
    lam = noncentrality(0.01, 5, 0.9)
    assert stats.ncx2.sf(stats.chi2.isf(0.01, 5), 5, lam) == pytest.approx(0.9, abs=1e-8)


def test_holm_matches_statsmodels():
    rng = np.random.default_rng(3)
    for m in (1, 2, 7, 20):
        p = rng.uniform(0, 0.05, m) ** rng.uniform(0.5, 3, m)
        expected = multipletests(p, alpha=0.01, method="holm")[1]
        np.testing.assert_allclose(holm(p), expected, rtol=1e-12)


@pytest.mark.parametrize("dof", [1, 2, 3, 6])
def test_log_chi2_sf_tail_series_matches_scipy(dof):
    """The asymptotic tail used past scipy's underflow agrees where both are finite."""
    for x in (800.0, 1100.0, 1400.0):
        exact = stats.chi2.logsf(x, dof)
        assert log_chi2_sf_asymptotic(x, dof) == pytest.approx(exact, rel=1e-7)
    assert np.isfinite(log_chi2_sf(1e5, 2))
    assert log_chi2_sf(1e5, 1) < log_chi2_sf(1e5, 2)


def test_statistic_is_chi2_under_the_model():
    """Monte Carlo: p-values of the quadratic's statistic are uniform when the line is true
    (Kolmogorov-Smirnov at 1e-3, fixed seed), and the global test rejects at about alpha."""
    rng = np.random.default_rng(11)
    p, rejected = [], 0
    for _ in range(600):
        y = 0.3 + 0.5 * X + rng.standard_normal(X.size)
        problem = toy_problem(y)
        fit = fit_model(problem, ())
        t = next(t for t in analyse_candidates(problem, fit) if t.name == "quadratic")
        p.append(t.p_value)
        rejected += fit.p_value < 0.05
    assert stats.kstest(p, "uniform").pvalue > 1e-3
    assert abs(rejected - 30) <= 4 * math.sqrt(600 * 0.05 * 0.95)


def test_jacobian_equals_the_columns():
    problem = toy_problem(np.zeros_like(X))
    J = jacobian(problem, {"a": 0.1, "b": 0.2}, ["a", "b", "c_cubic"])
    np.testing.assert_allclose(J, np.column_stack([np.ones_like(X), X, X**3]), atol=1e-9)


def partner_separated(y):
    """Independent check of the separation test: fit the partner (x^4) instead, then add x^2;
    the chi2 drop is chi2(1) if x^4 were the true effect."""
    one = np.ones_like(X)
    chi2_partner, _ = chi2_of([one, X, X**4], y)
    chi2_both, _ = chi2_of([one, X, X**4, X**2], y)
    return stats.chi2.sf(chi2_partner - chi2_both, 1) < 0.01


@pytest.mark.parametrize(("multiple", "seed"), [(1.5, 5), (1.5, 6), (1.5, 7), (12.0, 5)])
def test_diagnose_names_the_injected_column_and_its_confounded_partner(multiple, seed):
    problem = toy_problem(np.zeros_like(X))
    mdb = design_mdb(problem, {"a": 0.0, "b": 0.0}, (), "quadratic")["c_quadratic"]
    rng = np.random.default_rng(seed)
    y = 0.3 + 0.5 * X + multiple * mdb * X**2 + rng.standard_normal(X.size)
    d = diagnose(toy_problem(y))
    assert d.detected and not d.unexplained
    assert d.named == ["quadratic"]
    separated = partner_separated(y)
    assert d.groups == [("quadratic",) if separated else ("quadratic", "near_quadratic")]
    if multiple > 10:
        assert separated
    assert "duplicate" in d.absorbed
    assert d.after.params["c_quadratic"] == pytest.approx(
        multiple * mdb, abs=4 * d.after.stderr["c_quadratic"])


def test_null_data_name_nothing():
    rng = np.random.default_rng(8)
    d = diagnose(toy_problem(0.3 + 0.5 * X + rng.standard_normal(X.size)))
    assert not d.detected and d.named == [] and d.before is d.after
    assert d.after.chi2_red == pytest.approx(d.before.chi2 / (X.size - 2))


def test_design_mdb_along_a_direction():
    """For a two-parameter candidate the injection along a direction has noncentrality
    lambda0, computed independently with numpy."""
    base = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)
    curve = Effect("curve", ("q", "c"), ((-10.0, 10.0),) * 2, (1e-3,) * 2,
                       direction=(1.0, -2.0))

    def residuals(v):
        a, b, q, c = (np.asarray(v.get(k, 0.0), float) for k in ("a", "b", "q", "c"))
        return -(a + b * X + q * X**2 + c * X**3)

    problem = Problem("toy", base, (curve,), residuals, {"a": 0.0, "b": 0.0})
    inj = design_mdb(problem, {}, (), "curve")
    assert inj["c"] == pytest.approx(-2.0 * inj["q"])
    Q = np.linalg.qr(np.column_stack([np.ones_like(X), X]))[0]
    g = inj["q"] * X**2 + inj["c"] * X**3
    g -= Q @ (Q.T @ g)
    lam0 = noncentrality(0.01 / 2, 2)  # its own 2-dof test, one candidate + the global test
    assert g @ g == pytest.approx(lam0, rel=1e-7)


def test_chi2_red_band():
    lo, hi = chi2_red_band(50)
    assert stats.chi2.cdf(50 * lo, 50) == pytest.approx(0.005)
    assert stats.chi2.cdf(50 * hi, 50) == pytest.approx(0.995)


def test_influence_is_the_shift_an_undetected_bias_causes():
    """External reliability: noise-free data with the cubic at its MDB, fitted by the line
    alone, move (a, b) by exactly the reported influence."""
    problem = toy_problem(np.zeros_like(X))
    fit = fit_model(problem, ())
    t = next(t for t in analyse_candidates(problem, fit) if t.name == "cubic")
    y = 0.3 + 0.5 * X + t.mdb["c_cubic"] * X**3
    _, coef = chi2_of([np.ones_like(X), X], y)
    assert t.influence["b"] == pytest.approx(abs(coef[1] - 0.5), rel=1e-6)
    assert t.influence["a"] == pytest.approx(abs(coef[0] - 0.3), abs=1e-9)


def test_estimate_beyond_its_physical_bound_stays_at_the_bound():
    """A signal the bounded effect cannot explain: named, pinned at the bound, misfit left."""
    y = 0.3 + 0.5 * X + 150.0 * X**2 + np.random.default_rng(2).standard_normal(X.size)
    d = diagnose(toy_problem(y))
    assert d.named[0] == "quadratic"
    assert d.after.params["c_quadratic"] == pytest.approx(100.0, rel=1e-6)
    assert d.unexplained


def test_mdb_uses_the_candidates_own_test_where_it_needs_more():
    """Four observations (2 degrees of freedom) and several candidates: the MDB is that of the
    candidate's own test at alpha / (m + 1) (the global test is one more member of the
    family), even where the global test would need less."""
    x = np.array([-1.0, -0.4, 0.3, 1.0])
    columns = {"quadratic": x**2, "cubic": x**3, "step": (x > 0).astype(float)}
    base = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)
    cands = tuple(Effect(n, (f"c_{n}",), ((-100.0, 100.0),), (1e-3,)) for n in columns)

    def residuals(v):
        pred = np.asarray(v.get("a", 0.0)) + np.asarray(v.get("b", 0.0)) * x + sum(
            np.asarray(v.get(f"c_{n}", 0.0)) * c for n, c in columns.items())
        return (0.2 + 0.1 * x - pred) / 1.0

    problem = Problem("few", base, cands, residuals, {"a": 0.0, "b": 0.0})
    fit = fit_model(problem, ())
    tests = [t for t in analyse_candidates(problem, fit) if t.status in ("testable",
                                                                          "undetectable")]
    m = len(tests)
    glob, own = noncentrality(0.01, fit.dof), noncentrality(0.01 / (m + 1), 1)
    assert fit.dof == 2 and m == 3 and own > glob
    for t in tests:
        assert t.lambda0 == pytest.approx(own, rel=1e-12)


def test_holm_adjusted_p_values_reach_the_report_json():
    """The JSON's named effect carries the Holm-adjusted p-value of its detection family, and
    each candidate's p_adjusted is Holm's over the family of that step: the candidates and
    the global test (equal weights without observations)."""
    from montecarlo.discrepancy.view import SystemView, to_json

    rng = np.random.default_rng(2)
    y = 0.3 + 0.5 * X + 1.6 * X**3 + 0.3 * rng.standard_normal(X.size)
    problem = toy_problem(y, sigma=0.3)
    d = diagnose(problem)
    assert d.named == ["cubic"]
    view = SystemView("toy", lambda name: ("1", 1.0), "1", 1.0, ("r", "r"),
                      lambda params: np.zeros((X.size, 2)), [], "none", lambda fit: {})
    report = to_json(d, view, "toy")
    family = [c for c in report["candidates"] if np.isfinite(c["p_adjusted"])]
    p = [c["p_value"] for c in family] + [report["steps"][0]["p_value"]]
    adjusted = multipletests(p, method="holm")[1]
    np.testing.assert_allclose([c["p_adjusted"] for c in family], adjusted[:-1], rtol=1e-12)
    assert report["steps"][0]["global_p_adjusted"] == pytest.approx(adjusted[-1], rel=1e-12)
    named = report["named_effects"][0]
    assert named["p_value"] == next(c["p_adjusted"] for c in family if c["name"] == "cubic")
    assert named["p_value"] != next(c["p_value"] for c in family if c["name"] == "cubic")


def bend_problem(y: np.ndarray) -> Problem:
    """The line plus one two-parameter candidate: a tilt 3 x (the slope's column: absorbed)
    and a bow x^2 (bounded at 100, the tilt at 1)."""
    base = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)
    bend = Effect("bend", ("c_tilt", "c_bow"), ((-1.0, 1.0), (-100.0, 100.0)), (1e-3, 1e-3))

    def residuals(v):
        a, b, t, q = (np.asarray(v.get(k, 0.0), float) for k in ("a", "b", "c_tilt", "c_bow"))
        return y - (a + b * X + t * 3.0 * X + q * X**2)

    return Problem("toy", base, (bend,), residuals, {"a": 0.0, "b": 0.0})


def test_a_candidate_with_one_absorbed_parameter_enters_with_the_other_only():
    """The tilt cannot be estimated beside the slope: the adapted model is the line plus the
    bow, whose fit equals numpy's lstsq on (1, x, x^2)."""
    rng = np.random.default_rng(4)
    y = 0.3 + 0.5 * X + 20.0 * X**2 + rng.standard_normal(X.size)
    d = diagnose(bend_problem(y))
    test = next(t for t in d.steps[0].tests if t.name == "bend")
    assert test.active == ("c_bow",) and test.absorbed_by == {"c_tilt": ["b"]}
    assert d.named == ["bend"] and not d.unexplained
    assert d.after.names == ("a", "b", "c_bow")
    chi2, coef = chi2_of([np.ones_like(X), X, X**2], y)
    assert d.after.chi2 == pytest.approx(chi2, rel=1e-9)
    np.testing.assert_allclose(d.after.values, coef, rtol=1e-7)
    result = d.effect_result("bend")
    assert result["parameters"] == {"c_bow": d.after.params["c_bow"]}
    assert result["stderr"] == {"c_bow": d.after.stderr["c_bow"]}


def test_effect_result_of_a_named_effect():
    rng = np.random.default_rng(2)
    y = 0.3 + 0.5 * X + 1.6 * X**3 + 0.3 * rng.standard_normal(X.size)
    d = diagnose(toy_problem(y, sigma=0.3))
    test = next(t for t in d.steps[0].tests if t.name == "cubic")
    assert d.effect_result("cubic") == {
        "name": "cubic", "parameters": {"c_cubic": d.after.params["c_cubic"]},
        "stderr": {"c_cubic": d.after.stderr["c_cubic"]}, "p_value": test.p_adjusted,
        "p_value_unadjusted": test.p_value, "statistic": test.statistic, "dof": 1}


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 5, 6, 8, 10])
def test_log_chi2_sf_tail_series_is_within_its_first_omitted_term(dof):
    """Three terms of the series of Gamma(a, y): exact for a = 1, 2, 3 (dof 2, 4, 6), otherwise
    off by about the first omitted term (a-1)(a-2)(a-3)/y^3 (scipy as the reference)."""
    a = dof / 2.0
    for x in (60.0, 200.0, 1000.0):
        y = x / 2.0
        omitted = abs((a - 1.0) * (a - 2.0) * (a - 3.0)) / y**3
        got, exact = log_chi2_sf_asymptotic(x, dof), stats.chi2.logsf(x, dof)
        assert abs(got - exact) <= 2.0 * omitted + 1e-12 * abs(exact)


def test_canonical_correlation_limits():
    problem = toy_problem(0.3 + 0.5 * X)
    tests = {t.name: t for t in analyse_candidates(problem, fit_model(problem, ()))}
    quadratic = tests["quadratic"]
    itself = canonical_correlation(quadratic, quadratic)  # one, to round-off, and never above
    assert itself <= 1.0 and itself == pytest.approx(1.0, abs=1e-12)
    assert tests["duplicate"].basis is None  # absorbed: no column space
    assert canonical_correlation(quadratic, tests["duplicate"]) == 0.0
    assert canonical_correlation(tests["duplicate"], quadratic) == 0.0
    empty = dataclasses.replace(quadratic, basis=np.zeros((X.size, 0)))
    assert canonical_correlation(quadratic, empty) == canonical_correlation(empty, quadratic) \
        == 0.0


def test_a_partner_that_absorbs_the_winner_is_never_separated_from_it():
    """Winner column 10 e1; the partner's column at 3 % off it, so the winner keeps 3 % of its
    norm beside the partner (below ``absorbed``): not separated however large the residual
    along the winner's own direction; at 30 % off the same residual separates them."""
    rng = np.random.default_rng(0)
    e = np.linalg.qr(rng.standard_normal((X.size, 2)))[0]
    winner = dataclasses.replace(analyse_candidates(toy_problem(0 * X), fit_model(
        toy_problem(0 * X), ()))[0], projected=10.0 * e[:, :1], basis=e[:, :1])
    for off, expected in ((0.03, False), (0.3, True)):
        u = (math.sqrt(1 - off**2) * e[:, 0] + off * e[:, 1])[:, None]
        partner = dataclasses.replace(winner, basis=u, projected=u)
        residual = 100.0 * (e[:, 0] - u[:, 0] * u[:, 0] @ e[:, 0])
        residual /= np.linalg.norm(residual) / 100.0
        assert separated(winner, partner, residual) is expected


def test_diagnose_passes_its_power_and_absorption_levels_on():
    """power = 0.5 gives the MDB of its own test's lambda0 at 50 %; absorbed = 0.99 absorbs every
    candidate (none keeps 99 % of its norm beside the line), so nothing can be named."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + np.random.default_rng(1).standard_normal(X.size)
    d = diagnose(toy_problem(y), power=0.5)
    t = next(t for t in d.steps[0].tests if t.name == "cubic")
    family = sum(s.status in ("testable", "undetectable") for s in d.steps[0].tests)
    assert t.lambda0 == pytest.approx(noncentrality(0.01 / (family + 1), 1, 0.5), rel=1e-12)
    assert [s.name for s in d.steps[0].tests] == list(COLUMNS) and d.steps[0].snoop == []
    everything = diagnose(toy_problem(y), absorbed=0.99)
    assert everything.named == [] and everything.unexplained
    assert sorted(everything.absorbed) == sorted(COLUMNS)


def test_every_status_and_its_reason():
    """Line + quadratic fitted; candidates: the quadratic (in the model), a zero column (no
    effect), the slope's column (absorbed by b), a tiny bounded one (undetectable), one the
    data lack (unavailable), and a pair (x^3 + x, x^3 - x), neither absorbed alone, whose
    first is absorbed by the model and the second together (x^3 + x = (x^3 - x) + 2 x)."""
    columns = {"quadratic": X**2, "zero": 0 * X, "duplicate": 2 * X, "tiny": X**3,
               "gone": X**4}
    base = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)
    bound = {"tiny": 1e-4}
    cands = (*(Effect(n, (f"c_{n}",), ((-bound.get(n, 10.0), bound.get(n, 10.0)),), (1e-3,))
               for n in columns),
             Effect("pair", ("p1", "p2"), ((-10.0, 10.0),) * 2, (1e-3,) * 2))
    y = 0.3 + 0.5 * X + 2.0 * X**2 + np.random.default_rng(3).standard_normal(X.size)

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        pred = p("a") + p("b") * X + sum(p(f"c_{n}") * c for n, c in columns.items())
        return y - pred - p("p1") * (X**3 + X) - p("p2") * (X**3 - X)

    problem = Problem("toy", base, cands, residuals, {"a": 0.0, "b": 0.0},
                      unavailable={"gone": "no time column"})
    tests = {t.name: t for t in analyse_candidates(problem, fit_model(problem, ("quadratic",)))}
    assert {n: (t.name, t.status, t.reason) for n, t in tests.items()
            if n not in ("tiny", "pair")} == {
        "quadratic": ("quadratic", "in_model", "already in the model"),
        "zero": ("zero", "no_effect", "its parameters do not change these data"),
        "duplicate": ("duplicate", "absorbed", "absorbed by b"),
        "gone": ("gone", "unavailable", "no time column")}
    assert tests["zero"].retained == {"c_zero": 0.0}
    assert tests["tiny"].status == "undetectable"
    assert tests["tiny"].reason.startswith("noncentrality at most ")
    assert tests["tiny"].reason.endswith(f"{tests['tiny'].lambda0:.3g} needed")
    pair = tests["pair"]
    assert pair.status == "testable" and pair.active == ("p2",) and pair.reason == ""
    assert pair.absorbed_by == {"p1": ["b"]}  # weight 2 |x| against |x^3 - x| < 0.3 of it
    Q = np.linalg.qr(np.column_stack([np.ones_like(X), X, X**2]))[0]
    for name, col in (("p1", X**3 + X), ("p2", X**3 - X)):
        kept = np.linalg.norm(col - Q @ (Q.T @ col)) / np.linalg.norm(col)
        assert pair.retained[name] == pytest.approx(kept, rel=1e-6) and kept > 0.05
    assert list(tests) == [c.name for c in cands]


def test_steps_record_what_each_one_tested_and_chose():
    """The toy with each point an observation of its own and one point 8 sigma off: step 0
    tests the line and flags the point (no group), step 1 tests the line plus the quadratic
    the data carry, the last step finds nothing more; each step keeps every candidate's test
    and every observation's."""
    rng = np.random.default_rng(5)
    y = 0.3 + 0.5 * X + 6.0 * X**2 + rng.standard_normal(X.size)
    y[7] += 8.0
    problem = dataclasses.replace(toy_problem(y), observations=tuple(
        (f"P{i}", i, (i,)) for i in range(X.size)))
    d = diagnose(problem)
    assert [s.winner for s in d.steps] == ["quadratic", "outlier:P7", None]
    assert [s.group for s in d.steps] == [("quadratic",), (), ()]
    assert d.steps[0].fit is d.before and d.steps[-1].fit is d.after
    assert d.steps[1].fit.effects == ("line", "quadratic")
    assert d.after.effects == ("line", "quadratic", "outlier:P7")
    for s in d.steps:
        assert [t.name for t in s.tests] == list(COLUMNS)
        assert [t.name for t in s.snoop] == [f"outlier:P{i}" for i in range(X.size)]
    assert d.named == ["quadratic"] and [t.name for t in d.outliers] == ["outlier:P7"]
