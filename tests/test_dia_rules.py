"""The DIA engine's adaptation rules on designs built so that the answer is known.

A line ``a + b x`` on 40 points plus candidate columns. The "noise" is a fixed random vector
projected orthogonal to every column of the design, so any model holding the true columns
fits it exactly and every chi-square difference is a number computed here with numpy's lstsq:
the rules (Akaike's criterion with a chi-square test for added parameters, Wald tests with
Holm, one effect instead of flagged observations) are then checked on margins far from their
thresholds, and against scipy's chi-square quantiles.
"""

import math

import numpy as np
import pytest
from scipy import stats

from montecarlo.discrepancy import adapt, candidate_tests, confounding, engine
from montecarlo.discrepancy.candidate_tests import analyse_candidates, holm
from montecarlo.discrepancy.confounding import separated
from montecarlo.discrepancy.engine import Diagnosis, diagnose
from montecarlo.discrepancy.fit import FitError, fit_model, jacobian
from montecarlo.discrepancy.problem import Effect, Problem, with_outliers
from montecarlo.lsq import orthonormal_basis

N = 40
X = np.linspace(-1.0, 1.0, N)
ONE = np.ones(N)
A_ROW, B_ROW = 3, 30
ENDS = np.eye(N)[A_ROW] + np.eye(N)[B_ROW]
LINE = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)


def noise(*columns, seed=0):
    """Unit-variance noise orthogonal to the line and ``columns`` (its norm^2 is ~N - p)."""
    e = np.random.default_rng(seed).standard_normal(N)
    Q = np.linalg.qr(np.column_stack([ONE, X, *columns]))[0]
    return e - Q @ (Q.T @ e)


def linear(y, candidates, bounds=None, observations=False):
    """The line plus candidates ``name -> {parameter: column}`` (bounds +-100 unless given)."""
    bounds = bounds or {}
    cols = {p: c for params in candidates.values() for p, c in params.items()}
    effects = tuple(Effect(name, tuple(params), tuple(bounds.get(p, (-100.0, 100.0))
                                                      for p in params), (1e-3,) * len(params))
                    for name, params in candidates.items())

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        return y - p("a") - p("b") * X - sum(p(k) * c for k, c in cols.items())

    obs = tuple((f"P{i}", i, (i,)) for i in range(N)) if observations else ()
    return Problem("toy", LINE, effects, residuals, {"a": 0.0, "b": 0.0}, observations=obs)


def chi2_of(y, *columns):
    A = np.column_stack([ONE, X, *columns])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    return float(r @ r), coef, np.linalg.inv(A.T @ A)


def aic(chi2, parameters):
    return chi2 + 2.0 * parameters


# --- one effect instead of the shifts of flagged observations ----------------------------------


@pytest.mark.parametrize(("left", "replaced"), [(1.0, True), (2.5, False)])
def test_one_effect_replaces_flagged_shifts_only_where_akaike_prefers_it(left, replaced):
    """Observations A and B off by 10 + d and 10 - d, both flagged (two shift parameters), a
    quadratic in the model. The effect 'ends' (one parameter, 1 at A and B) leaves ``left`` of
    chi-square (d set for it): it replaces the shifts when that is below 2 (one parameter
    fewer), so for 1.0 and not for 2.5."""
    gap = np.eye(N)[A_ROW] - np.eye(N)[B_ROW]
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2, ENDS]))[0]
    d = math.sqrt(left) / np.linalg.norm(gap - Q @ (Q.T @ gap))
    y = 0.3 + 0.5 * X + 5.0 * X**2 + 10.0 * ENDS + d * gap \
        + noise(X**2, np.eye(N)[A_ROW], np.eye(N)[B_ROW])
    weak = ENDS + 0.1 * np.eye(N)[20]  # also fits, a little worse: 'ends' is the better one
    problem = with_outliers(linear(y, {"quadratic": {"q": X**2}, "bow": {"w": X**4},
                                       "slope": {"s": 2.0 * X}, "weak": {"k": weak},
                                       "ends": {"e": ENDS}}, observations=True))
    flagged = [f"outlier:P{A_ROW}", f"outlier:P{B_ROW}"]
    fit = fit_model(problem, ("quadratic", *flagged))
    with_shifts, *_ = chi2_of(y, X**2, np.eye(N)[A_ROW], np.eye(N)[B_ROW])
    with_ends, coef, _ = chi2_of(y, X**2, ENDS)
    with_weak, *_ = chi2_of(y, X**2, weak)
    assert fit.chi2 == pytest.approx(with_shifts, rel=1e-9)
    assert with_ends - with_shifts == pytest.approx(left, rel=1e-9)
    assert with_ends < with_weak
    # 'slope' cannot be fitted beside the line (skipped); the others in this order
    got = adapt.effect_for_outliers(problem, fit, flagged, ["bow", "slope", "weak", "ends"],
                                    set())
    assert bool(aic(with_ends, 4) < aic(with_shifts, 5)) is replaced
    assert bool(aic(with_weak, 4) < aic(with_shifts, 5)) is replaced
    if not replaced:
        assert got is None
        return
    name, alt = got
    assert name == "ends" and alt.effects == ("line", "quadratic", "ends")
    assert alt.chi2 == pytest.approx(with_ends, rel=1e-9)
    np.testing.assert_allclose(alt.values, coef, rtol=1e-7)


def kink_problem(eps=0.05):
    """A nonlinear effect: ``k eps u + k^3 (e_A + e_B)``. At k = 0 its column is ``eps u``
    (zero at A and B), so the linearised test cannot see the two observations where it is
    largest: they are flagged first. The data are this effect at k0 = 10^(1/3) (A and B 10
    sigma off) and the noise."""
    u = 3.0 * np.sin(7.0 * X)
    u[[A_ROW, B_ROW]] = 0.0
    u -= np.column_stack([ONE, X]) @ np.linalg.lstsq(np.column_stack([ONE, X]), u, rcond=None)[0]
    u[[A_ROW, B_ROW]] = 0.0
    k0 = 10.0 ** (1.0 / 3.0)
    y = 0.3 + 0.5 * X + k0 * eps * u + k0**3 * ENDS \
        + noise(u, np.eye(N)[A_ROW], np.eye(N)[B_ROW], seed=1)

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        k = p("k")
        return y - p("a") - p("b") * X - k * eps * u - k**3 * ENDS

    effects = (Effect("kink", ("k",), ((-10.0, 10.0),), (1e-4,)),)
    obs = tuple((f"P{i}", i, (i,)) for i in range(N))
    return Problem("toy", LINE, effects, residuals, {"a": 0.0, "b": 0.0}, observations=obs), \
        y, eps, u


def test_an_effect_seen_first_as_two_wrong_observations_replaces_them():
    """docs/reference/discrepancy.md, Swap: before stopping with flagged observations, one effect
    fitted
    instead of all their shifts is tried. The two observations are flagged one after the other;
    the kink, fitted instead of both shifts, fits better with one parameter fewer: it is named,
    the shifts are dropped (no p-value: replaced, not tested), and the final model equals the
    least-squares minimum over k (a one-dimensional search, the line by lstsq at each k)."""
    problem, y, eps, u = kink_problem()
    d = diagnose(problem)
    flagged = [f"outlier:P{B_ROW}", f"outlier:P{A_ROW}"]  # B first: the larger residual
    assert d.named == ["kink"] and d.outliers == [] and not d.unexplained
    assert [s.winner for s in d.steps] == [*flagged, "kink", None]
    replaced = d.steps[2]
    assert replaced.group == ("kink",)
    assert [t.name for t in replaced.snoop] == [f"outlier:P{i}" for i in range(N)]
    assert replaced.fit.effects == ("line", *flagged)  # the model whose tests it records
    assert replaced.fit.chi2 == pytest.approx(chi2_of(y, np.eye(N)[A_ROW], np.eye(N)[B_ROW])[0],
                                              rel=1e-9)
    assert list(replaced.dropped) == flagged and all(map(math.isnan, replaced.dropped.values()))
    assert list(d.dropped) == flagged and all(map(math.isnan, d.dropped.values()))
    assert d.steps[3].fit is d.after and d.after.effects == ("line", "kink")

    def profile(k):
        return chi2_of(y - k * eps * u - k**3 * ENDS)[0]

    best = min(np.linspace(0.0, 4.0, 4001), key=profile)
    assert d.after.params["k"] == pytest.approx(best, abs=2e-3)
    assert d.after.chi2 == pytest.approx(profile(d.after.params["k"]), rel=1e-9)
    assert d.after.chi2 <= profile(best) + 1e-9
    assert d.effect_result("kink")["p_value"] == next(
        t.p_adjusted for t in d.steps[2].tests if t.name == "kink")


# --- swaps at the end ------------------------------------------------------------------------


CANDIDATES = {"quadratic": {"q": X**2}, "cubic": {"c": X**3},
              "wide": {"w2": X**2, "w3": X**3}}


def test_a_swap_to_fewer_parameters_gains_akaikes_two_per_parameter():
    """Data: the line and a quadratic. Named: 'wide' (quadratic + cubic). Swapping it for the
    quadratic leaves chi-square unchanged (the noise is orthogonal to x^3) and saves one
    parameter: Akaike's criterion drops by exactly 2; the cubic instead would lose the x^2
    signal. Nothing else lowers it afterwards."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + noise(X**2, X**3)
    problem = linear(y, CANDIDATES)
    fit = fit_model(problem, ("wide",))
    chi2, *_ = chi2_of(y, X**2)
    final, swaps = adapt.swap(problem, fit, ["wide"], ["cubic", "quadratic"], set())
    assert [s[:2] for s in swaps] == [("wide", "quadratic")]
    assert swaps[0][2] == pytest.approx(aic(chi2, 4), rel=1e-9)
    assert swaps[0][3] == pytest.approx(aic(chi2, 3), rel=1e-9)
    assert final.effects == ("line", "quadratic") and final.chi2 == pytest.approx(chi2, rel=1e-9)


@pytest.mark.parametrize(("drop", "swapped"), [(4.0, False), (9.0, True)])
def test_a_swap_adding_parameters_needs_the_chi2_test_of_the_extra_ones(drop, swapped):
    """Named: the quadratic; the data also hold a cubic whose part orthogonal to the model
    carries ``drop`` of chi-square. Akaike alone swaps for 'wide' whenever drop > 2; the
    swap must also pass chi2_{0.99}(1) = 6.63: 4 does not, 9 does."""
    cubic = X**3 - np.column_stack([ONE, X, X**2]) @ np.linalg.lstsq(
        np.column_stack([ONE, X, X**2]), X**3, rcond=None)[0]
    y = 0.3 + 0.5 * X + 5.0 * X**2 + math.sqrt(drop) * cubic / np.linalg.norm(cubic) \
        + noise(X**2, X**3)
    problem = linear(y, CANDIDATES)
    fit = fit_model(problem, ("quadratic",))
    assert fit.chi2 - chi2_of(y, X**2, X**3)[0] == pytest.approx(drop, rel=1e-9)
    assert drop > 2.0 and bool(drop > stats.chi2.isf(0.01, 1)) is swapped
    final, swaps = adapt.swap(problem, fit, ["quadratic"], ["wide"], set())
    assert [s[:2] for s in swaps] == ([("quadratic", "wide")] if swapped else [])
    assert final.effects == ("line", "wide" if swapped else "quadratic")


def test_every_candidate_is_tried_and_the_lowest_criterion_wins():
    """Named: the quadratic, where the data are 5 x^2 plus a cubic part worth chi-square 4.
    Offered in order: the slope's column (cannot be fitted), 'wide' (adds a parameter for 4 of
    chi-square: refused by the chi2(1) test), a rough one-parameter column and the exact one.
    Both lower Akaike's criterion; the exact one (by 4) is taken."""
    Q3 = np.linalg.qr(np.column_stack([ONE, X, X**2]))[0]
    cubic = X**3 - Q3 @ (Q3.T @ X**3)
    cubic *= 2.0 / np.linalg.norm(cubic)
    exact, rough = 5.0 * X**2 + cubic, 5.0 * X**2 + 0.5 * cubic
    y = 0.3 + 0.5 * X + exact + noise(X**2, X**3)
    problem = linear(y, {**CANDIDATES, "slope": {"s": 2.0 * X}, "rough": {"r": rough},
                         "exact": {"e": exact}})
    fit = fit_model(problem, ("quadratic",))
    chi2 = {n: chi2_of(y, col)[0] for n, col in (("quadratic", X**2), ("rough", rough),
                                                  ("exact", exact))}
    assert chi2["exact"] < chi2["rough"] < chi2["quadratic"]
    assert chi2["quadratic"] - chi2["exact"] == pytest.approx(4.0, rel=1e-9)
    final, swaps = adapt.swap(problem, fit, ["quadratic"], ["slope", "wide", "rough", "exact"],
                              set())
    assert [s[:2] for s in swaps] == [("quadratic", "exact")]
    assert final.chi2 == pytest.approx(chi2["exact"], rel=1e-9)


def test_a_candidate_absorbed_by_the_model_replaces_only_an_effect_with_more_parameters():
    """The cubic named where the data hold a quadratic: the quadratic, offered among the
    candidates absorbed by the final model, may not replace the one-parameter cubic, but it
    replaces the two-parameter 'wide'."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + noise(X**2, X**3)
    problem = linear(y, CANDIDATES)
    cubic_fit = fit_model(problem, ("cubic",))
    assert adapt.swap(problem, cubic_fit, ["cubic"], [], set(), ["quadratic"])[1] == []
    assert [s[:2] for s in adapt.swap(problem, cubic_fit, ["cubic"], ["quadratic"],
                                      set())[1]] == [("cubic", "quadratic")]
    wide_fit = fit_model(problem, ("wide",))
    assert [s[:2] for s in adapt.swap(problem, wide_fit, ["wide"], [], set(),
                                      ["quadratic"])[1]] == [("wide", "quadratic")]


def test_the_result_of_an_effect_swapped_in_is_its_wald_test_in_the_final_model():
    """An effect that no step named (swapped in at the end) reports the Wald test of its
    parameters in the final model: T = b^2 / var(b) from lstsq, its chi2(1) tail."""
    rng = np.random.default_rng(4)
    y = 0.3 + 0.5 * X + 0.8 * X**2 + rng.standard_normal(N)
    problem = linear(y, CANDIDATES)
    fit = fit_model(problem, ("quadratic",))
    d = Diagnosis(problem, 0.01, fit_model(problem, ()), fit, [], ["quadratic"], [], [])
    _, coef, cov = chi2_of(y, X**2)
    T = coef[2] ** 2 / cov[2, 2]
    got = d.effect_result("quadratic")
    assert set(got) == {"name", "parameters", "stderr", "p_value", "p_value_unadjusted",
                        "statistic", "dof", "swapped_in"}
    assert got["name"] == "quadratic" and got["swapped_in"] is True and got["dof"] == 1
    assert got["parameters"] == {"q": pytest.approx(coef[2], rel=1e-7)}
    assert got["stderr"] == {"q": pytest.approx(math.sqrt(cov[2, 2]), rel=1e-7)}
    assert got["statistic"] == pytest.approx(T, rel=1e-6)
    assert got["p_value"] == got["p_value_unadjusted"] == pytest.approx(stats.chi2.sf(T, 1),
                                                                        rel=1e-6)


# --- reconsidering what was named ------------------------------------------------------------


def test_a_named_effect_the_others_explain_is_dropped_and_the_rest_refitted():
    """Named quadratic and cubic, the data hold only the quadratic (the cubic's estimate is
    exactly 0): the cubic is dropped with Holm's adjusted p-value of its Wald test, the model
    refitted with the quadratic kept."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + noise(X**2, X**3)
    problem = linear(y, CANDIDATES)
    fit = fit_model(problem, ("quadratic", "cubic"))
    _, coef, cov = chi2_of(y, X**2, X**3)
    wald = [stats.chi2.sf(coef[k] ** 2 / cov[k, k], 1) for k in (2, 3)]
    refit, gone = adapt.reconsider(problem, fit, ["quadratic", "cubic"], set(), 0.01)
    assert list(gone) == ["cubic"]
    assert gone["cubic"] == pytest.approx(holm(wald)[1], abs=1e-9)
    assert refit.effects == ("line", "quadratic")
    assert refit.chi2 == pytest.approx(chi2_of(y, X**2)[0], rel=1e-9)


def test_one_flagged_observation_is_tested_a_single_named_effect_is_not():
    """A flagged observation that is not off (its shift is exactly 0) is dropped even when it is
    the only one; a single named effect has no others to be explained by and stays."""
    y = 0.3 + 0.5 * X + 0.5 * X**3 + noise(X**3, np.eye(N)[7])
    problem = with_outliers(linear(y, CANDIDATES, observations=True))
    fit = fit_model(problem, ("cubic", "outlier:P7"))
    refit, gone = adapt.reconsider(problem, fit, ["cubic", "outlier:P7"], set(), 0.01)
    assert list(gone) == ["outlier:P7"] and gone["outlier:P7"] == pytest.approx(1.0)
    assert refit.effects == ("line", "cubic")
    quiet = linear(0.3 + 0.5 * X + noise(), CANDIDATES)
    alone = fit_model(quiet, ("cubic",))
    assert adapt.reconsider(quiet, alone, ["cubic"], set(), 0.01)[1] == {}


def test_a_refit_after_a_drop_keeps_absorbed_parameters_out():
    """'bend' enters with its bow only (its tilt, 3 x, is the slope's column: held at zero).
    Dropping the cubic beside it refits without the tilt (with it the design is singular)."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + noise(X**2, X**3)
    problem = linear(y, {"bend": {"t": 3.0 * X, "w": X**2}, "cubic": {"c": X**3}})
    fit = adapt.fit_with_fixed(problem, ["bend", "cubic"], {}, {"t"})
    refit, gone = adapt.reconsider(problem, fit, ["bend", "cubic"], {"t"}, 0.01)
    assert list(gone) == ["cubic"] and refit.names == ("a", "b", "w")


# --- the identification statistics --------------------------------------------------------------


def test_a_zero_column_is_neither_tested_nor_absorbed():
    y = 0.3 + 0.5 * X + noise()
    problem = linear(y, {"half": {"z": 0.0 * X, "h": X**2}})
    t = analyse_candidates(problem, fit_model(problem, ()))[0]
    assert t.status == "testable" and t.active == ("h",) and t.absorbed_by == {}
    assert t.retained["z"] == 0.0


def test_retained_fraction_of_a_short_column():
    """A column of norm 0.05 keeps the same fraction of it beside the line as x^2 itself."""
    y = 0.3 + 0.5 * X + noise()
    Q = np.linalg.qr(np.column_stack([ONE, X]))[0]
    col = 0.05 * X**2 / np.linalg.norm(X**2)
    fraction = np.linalg.norm(col - Q @ (Q.T @ col)) / np.linalg.norm(col)
    problem = linear(y, {"short": {"s": col}})
    t = analyse_candidates(problem, fit_model(problem, ()))[0]
    assert t.retained["s"] == pytest.approx(fraction, rel=1e-6) and fraction < 1.0


def test_a_column_absorbed_by_two_model_parameters_names_both():
    y = 0.3 + 0.5 * X + noise()
    problem = linear(y, {"offset_tilt": {"o": 1.0 + X}})
    t = analyse_candidates(problem, fit_model(problem, ()))[0]
    assert t.status == "absorbed" and t.reason == "absorbed by a, b"
    assert t.absorbed_by == {"o": ["a", "b"]}


@pytest.mark.parametrize("bound", [(-100.0, 0.0), (0.0, 100.0)])
def test_reach_takes_the_larger_end_of_asymmetric_bounds(bound):
    """A column of norm 1 beside the line, bounded on one side only: its largest noncentrality
    is 100^2 (testable) whichever side the bound is on."""
    y = 0.3 + 0.5 * X + noise()
    Q = np.linalg.qr(np.column_stack([ONE, X]))[0]
    g = X**2 - Q @ (Q.T @ X**2)
    problem = linear(y, {"one_sided": {"s": g / np.linalg.norm(g)}}, bounds={"s": bound})
    t = analyse_candidates(problem, fit_model(problem, ()))[0]
    assert t.status == "testable"


def test_undetectable_where_the_largest_noncentrality_is_half_lambda0():
    """Bound chosen so that (bound |g|)^2 = lambda0 / 2 with |g| of order 1 (not far below):
    undetectable, and the reason quotes that largest noncentrality."""
    y = 0.3 + 0.5 * X + noise()
    Q = np.linalg.qr(np.column_stack([ONE, X]))[0]
    g = X**2 - Q @ (Q.T @ X**2)
    g /= np.linalg.norm(g)
    # its own 1-dof test at its share of the family (the global test and itself): alpha / 2
    lam0 = candidate_tests.noncentrality(0.01 / 2, 1)
    bound = math.sqrt(lam0 / 2.0)
    problem = linear(y, {"weak": {"s": g}}, bounds={"s": (-bound, bound)})
    t = analyse_candidates(problem, fit_model(problem, ()))[0]
    assert t.lambda0 == pytest.approx(lam0, rel=1e-12)
    assert t.status == "undetectable"
    assert t.reason == f"noncentrality at most {lam0 / 2:.3g} within its physical bounds, " \
                       f"{lam0:.3g} needed"


def test_one_degree_of_freedom_left_still_has_a_global_test():
    """Three points, a line: one degree of freedom. The global test is a member of the
    family: the candidate's own test has size alpha / 2, its lambda0 finite (scipy's
    noncentral chi2 checks the power)."""
    x = np.array([-1.0, 0.2, 1.0])

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        return np.array([0.3, 0.9, 0.1]) - p("a") - p("b") * x - p("q") * x**2

    problem = Problem("three", LINE, (Effect("quadratic", ("q",), ((-100.0, 100.0),),
                                             (1e-3,)),), residuals, {"a": 0.0, "b": 0.0})
    fit = fit_model(problem, ())
    t = analyse_candidates(problem, fit)[0]
    assert fit.dof == 1 and math.isfinite(t.lambda0)
    crit = stats.chi2.isf(0.01 / 2, 1)
    assert stats.ncx2.sf(crit, 1, t.lambda0) == pytest.approx(0.80, abs=1e-6)


def test_the_candidates_own_test_uses_the_power_asked_for():
    """Four points (2 dof), three candidates: the candidate's own test, at alpha/4 (three
    candidates and the global test in the family), at power 0.5 as at 0.8."""
    x = np.array([-1.0, -0.4, 0.3, 1.0])
    columns = {"quadratic": x**2, "cubic": x**3, "step": (x > 0).astype(float)}

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        return 0.2 + 0.1 * x - p("a") - p("b") * x - sum(p(n) * c for n, c in columns.items())

    problem = Problem("few", LINE, tuple(Effect(n, (n,), ((-100.0, 100.0),), (1e-3,))
                                         for n in columns), residuals, {"a": 0.0, "b": 0.0})
    fit = fit_model(problem, ())
    for power in (0.5, 0.8):
        t = analyse_candidates(problem, fit, power=power)[0]
        crit = stats.chi2.isf(0.01 / 4, 1)
        assert stats.ncx2.sf(crit, 1, t.lambda0) == pytest.approx(power, abs=1e-6)


def test_the_column_basis_has_the_same_rank_at_any_scale():
    """Singular values 1, 1e-6 and 1e-15 (relative): rank 2 whether the matrix is scaled by
    1e-9 or 1e6 (the rank tolerance is relative to the largest singular value)."""
    rng = np.random.default_rng(0)
    U = np.linalg.qr(rng.standard_normal((N, 3)))[0]
    V = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    M = U @ np.diag([1.0, 1e-6, 1e-15]) @ V.T
    for scale in (1e-9, 1.0, 1e6):
        B = orthonormal_basis(scale * M)
        assert B.shape == (N, 2)
        np.testing.assert_allclose(B.T @ B, np.eye(2), atol=1e-9)


# --- whole diagnoses ---------------------------------------------------------------------------


def alternating(*columns):
    """A misfit of 1.5 sigma alternating in sign (chi-square about 85), orthogonal to the line
    and ``columns``: no candidate follows it and no single observation stands out."""
    m = 1.5 * (-1.0) ** np.arange(N)
    Q = np.linalg.qr(np.column_stack([ONE, X, *columns]))[0]
    return m - Q @ (Q.T @ m)


def test_a_misfit_no_candidate_explains_ends_with_a_step_that_names_nothing():
    y = 0.3 + 0.5 * X + alternating(X**2, X**3) + noise(X**2, X**3)
    d = diagnose(linear(y, CANDIDATES))
    chi2, *_ = chi2_of(y)
    assert d.before.chi2 == pytest.approx(chi2, rel=1e-9) and stats.chi2.sf(chi2, N - 2) < 1e-4
    assert d.detected and d.unexplained and d.named == [] and d.outliers == []
    [last] = d.steps
    assert last.fit is d.before and last.fit is d.after
    assert last.winner is None and last.group == () and last.snoop == [] and last.dropped == {}
    assert [t.name for t in last.tests] == list(CANDIDATES)


def test_a_20_sigma_observation_comes_before_a_10_sigma_effect_it_is_not():
    """The step's winner is the smallest p-value (the observation, T ~ 400, against the
    quadratic's ~ 100); the quadratic, fitted instead, leaves the observation 20 sigma off, so it
    does not take its place. Then the quadratic is named; the final model is lstsq's."""
    Q = np.linalg.qr(np.column_stack([ONE, X]))[0]
    g = X**2 - Q @ (Q.T @ X**2)
    spike = np.eye(N)[7]
    y = 0.3 + 0.5 * X + 10.0 * X**2 / np.linalg.norm(g) + 20.0 * spike + noise(X**2, spike)
    d = diagnose(linear(y, CANDIDATES, observations=True))
    assert [s.winner for s in d.steps] == ["outlier:P7", "quadratic", None]
    assert d.named == ["quadratic"] and [t.name for t in d.outliers] == ["outlier:P7"]
    assert d.after.chi2 == pytest.approx(chi2_of(y, X**2, spike)[0], rel=1e-9)


def test_exactly_confounded_candidates_form_a_group_at_the_step_and_in_the_report():
    """'twin' is the quadratic's column doubled: the two cannot be told apart by any data of
    this design. Whichever is fitted, the other is its group partner (canonical correlation 1),
    at the step and in the final report, with no separating data stated; the cubic is not."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + noise(X**2)
    problem = linear(y, {"quadratic": {"q": X**2}, "cubic": {"c": X**3},
                         "twin": {"t": 2.0 * X**2}})
    d = diagnose(problem)
    [fitted] = d.named
    other = ({"quadratic", "twin"} - {fitted}).pop()
    assert d.steps[0].group == (fitted, other) and d.groups == [(fitted, other)]
    [group] = d.confounded
    assert group.fitted == fitted and group.members == (fitted, other)
    assert group.correlation == {other: pytest.approx(1.0, abs=1e-9)}
    assert group.separating_data == {other: ""}
    assert d.absorbed == [other] and "cubic" not in group.members


def test_an_absorbed_parameter_stays_out_when_a_second_effect_is_added():
    """'bend' (its tilt 3 x absorbed by the slope) is named first, the cubic second: the tilt
    stays out of every refit, and the final model is lstsq's on (1, x, x^2, x^3)."""
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2]))[0]
    g = X**3 - Q @ (Q.T @ X**3)
    y = 0.3 + 0.5 * X + 20.0 * X**2 + 10.0 * X**3 / np.linalg.norm(g) + noise(X**2, X**3)
    d = diagnose(linear(y, {"bend": {"t": 3.0 * X, "w": X**2}, "cubic": {"c": X**3}}))
    assert d.named == ["bend", "cubic"] and not d.unexplained
    assert d.after.names == ("a", "b", "w", "c")
    chi2, coef, _ = chi2_of(y, X**2, X**3)
    assert d.after.chi2 == pytest.approx(chi2, rel=1e-9)
    np.testing.assert_allclose(d.after.values, coef, rtol=1e-7)


def test_observation_tests_use_the_power_and_absorption_level_given():
    """Null data, every point an observation. With power 0.5 each observation's lambda0 is
    that of its own test at 50 %, at its share of the family (m effects, the global test and
    the observations together: alpha / (m + 2) / n); with absorbed = 0.99 every observation
    is absorbed (beside the line none keeps 99 % of its column)."""
    problem = linear(0.3 + 0.5 * X + noise(), CANDIDATES, observations=True)
    d = diagnose(problem, power=0.5)
    snoop = d.steps[0].snoop
    assert d.named == [] and len(snoop) == N and all(t.status == "testable" for t in snoop)
    m = sum(math.isfinite(t.statistic) for t in d.steps[0].tests)
    lam0 = candidate_tests.noncentrality(0.01 / (m + 2) / N, 1, 0.5)
    assert all(t.lambda0 == pytest.approx(lam0, rel=1e-12) for t in snoop)
    d = diagnose(problem, absorbed=0.99)
    assert all(t.status == "absorbed" for t in d.steps[0].snoop)


def stand_in_design():
    """Orthonormal columns P, Q, R beside the line; data 10 P + 10 Q. S = P + Q/2 + eps R
    correlates with the data best (named first); with S and Q fitted, P still explains
    chi-square 4 more (eps chosen for it): too little for a test (chi2_{0.99}(1) = 6.6), enough
    for Akaike at equal parameter counts."""
    rng = np.random.default_rng(7)
    basis = np.linalg.qr(np.column_stack([ONE, X, rng.standard_normal((N, 3))]))[0]
    P, Q, R = basis[:, 2], basis[:, 3], basis[:, 4]
    eps = math.sqrt(1.0 / 24.0)  # eps^2 / (1 + eps^2) * 10^2 = 4
    S = P + 0.5 * Q + eps * R
    y = 0.3 + 0.5 * X + 10.0 * P + 10.0 * Q + noise(P, Q, R, seed=3)
    return y, {"S": {"s": S}, "P": {"p": P}, "Q": {"q": Q}}


def test_an_effect_that_stood_in_for_another_is_swapped_for_it_at_the_end():
    y, candidates = stand_in_design()
    d = diagnose(linear(y, candidates))
    P, Q = candidates["P"]["p"], candidates["Q"]["q"]
    chi2, coef, cov = chi2_of(y, P, Q)
    assert d.steps[0].winner == "S"
    assert sorted(d.named) == ["P", "Q"] and not d.unexplained
    [(out, into, before, after)] = d.swaps
    assert (out, into) == ("S", "P")
    assert before - after == pytest.approx(4.0, rel=1e-6)
    assert after == pytest.approx(aic(chi2, 4), rel=1e-9)
    result = d.effect_result("P")
    T = coef[2] ** 2 / cov[2, 2]
    assert result["swapped_in"] is True
    assert result["statistic"] == pytest.approx(T, rel=1e-6)
    assert result["p_value"] == pytest.approx(stats.chi2.sf(T, 1), rel=1e-6)


def test_an_effect_replaces_flagged_observations_also_when_a_misfit_remains():
    """The kink design plus a misfit no candidate follows: after both observations are flagged
    the global test still fails and nothing is significant; before stopping, the kink is tried
    instead of the two shifts, and it is named. The misfit stays: unexplained."""
    kink, _, _, u = kink_problem()
    m = alternating(u, np.eye(N)[A_ROW], np.eye(N)[B_ROW])
    problem = Problem(kink.system, kink.base, kink.candidates,
                      lambda v: kink.residuals(v) + m, kink.start,
                      observations=kink.observations)
    d = diagnose(problem)
    assert d.named == ["kink"] and d.outliers == [] and d.unexplained
    assert d.steps[2].winner == "kink" and d.steps[2].fit.p_value < 0.01  # misfit with both
    assert sorted(d.dropped) == sorted([f"outlier:P{A_ROW}", f"outlier:P{B_ROW}"])
    assert d.steps[-1].winner is None and d.steps[-1].fit is d.after
    assert [t.name for t in d.steps[-1].snoop] == [f"outlier:P{i}" for i in range(N)]


def test_the_group_of_a_later_effect_is_found_with_the_earlier_ones_fitted():
    """'mix' = x^2 + 2 x^3: once the quadratic is fitted it is the cubic's column doubled (a
    group partner of whichever of the two is fitted); beside the line alone it correlates with
    the cubic only 0.71. The final groups are found given the rest of the final model: the
    quadratic, and the cubic's partner."""
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2]))[0]
    g = X**3 - Q @ (Q.T @ X**3)
    y = 0.3 + 0.5 * X + 20.0 * X**2 + 10.0 * X**3 / np.linalg.norm(g) + noise(X**2, X**3)
    mix = X**2 + 2.0 * X**3
    d = diagnose(linear(y, {"quadratic": {"q": X**2}, "cubic": {"c": X**3},
                            "mix": {"m": mix}}))
    first, second = d.named
    assert first == "quadratic" and second in ("cubic", "mix")
    other = ({"cubic", "mix"} - {second}).pop()
    assert d.groups[1] == (second, other)
    Q2 = np.linalg.qr(np.column_stack([ONE, X]))[0]
    a, b = (c - Q2 @ (Q2.T @ c) for c in (X**3, mix))
    assert abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b) < 0.75


# --- an effect with an absorbed parameter beside the other rules ---------------------------------
# 'bend' = t (3 x) + w x^2: its tilt is the slope's column, so it enters with its bow only and
# every later fit must hold t at zero (with it the design is singular and cannot be fitted).

BEND = {"bend": {"t": 3.0 * X, "w": X**2}}


def test_a_swap_beside_an_effect_with_an_absorbed_parameter_holds_it_at_zero():
    """Named 'bend' and the cubic where the data hold 4 Z (Z orthonormal to the line, x^2 and
    x^3): the cubic is swapped for 'zed' (same parameter count, chi-square lower by 16); the
    final model is lstsq's on (1, x, x^2, Z)."""
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2, X**3]))[0]
    Z = np.random.default_rng(5).standard_normal(N)
    Z -= Q @ (Q.T @ Z)
    Z /= np.linalg.norm(Z)
    y = 0.3 + 0.5 * X + 5.0 * X**2 + 4.0 * Z + noise(X**2, X**3, Z)
    problem = linear(y, {**BEND, "cubic": {"c": X**3}, "zed": {"z": Z}})
    fit = adapt.fit_with_fixed(problem, ["bend", "cubic"], {}, {"t"})
    final, swaps = adapt.swap(problem, fit, ["bend", "cubic"], ["zed"], {"t"})
    chi2, coef, _ = chi2_of(y, X**2, Z)
    assert fit.chi2 - chi2 == pytest.approx(16.0, rel=1e-9)
    assert [s[:2] for s in swaps] == [("cubic", "zed")]
    assert final.names == ("a", "b", "w", "z") and final.chi2 == pytest.approx(chi2, rel=1e-9)
    np.testing.assert_allclose(final.values, coef, rtol=1e-7)


def test_one_effect_replaces_flagged_shifts_beside_an_effect_with_an_absorbed_parameter():
    """The design of the first test (left = 1) with 'bend' in the model instead of the
    quadratic: 'ends' replaces the two shifts, and the fit is lstsq's on (1, x, x^2, e_A + e_B)."""
    gap = np.eye(N)[A_ROW] - np.eye(N)[B_ROW]
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2, ENDS]))[0]
    d = 1.0 / np.linalg.norm(gap - Q @ (Q.T @ gap))
    y = 0.3 + 0.5 * X + 5.0 * X**2 + 10.0 * ENDS + d * gap \
        + noise(X**2, np.eye(N)[A_ROW], np.eye(N)[B_ROW])
    problem = with_outliers(linear(y, {**BEND, "ends": {"e": ENDS}}, observations=True))
    flagged = [f"outlier:P{A_ROW}", f"outlier:P{B_ROW}"]
    fit = adapt.fit_with_fixed(problem, ["bend", *flagged], {}, {"t"})
    name, alt = adapt.effect_for_outliers(problem, fit, flagged, ["ends"], {"t"})
    chi2, coef, _ = chi2_of(y, X**2, ENDS)
    assert name == "ends" and alt.names == ("a", "b", "w", "e")
    assert alt.chi2 == pytest.approx(chi2, rel=1e-9)
    np.testing.assert_allclose(alt.values, coef, rtol=1e-7)


def test_the_group_of_an_effect_beside_one_with_an_absorbed_parameter():
    """'bend' named first, then the cubic, whose column 'twin' doubles: the cubic's group,
    found by refitting the final model without it (bend's tilt held at zero), holds the twin
    with canonical correlation 1."""
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2]))[0]
    g = X**3 - Q @ (Q.T @ X**3)
    y = 0.3 + 0.5 * X + 20.0 * X**2 + 10.0 * X**3 / np.linalg.norm(g) + noise(X**2, X**3)
    d = diagnose(linear(y, {**BEND, "cubic": {"c": X**3}, "twin": {"u": 2.0 * X**3}}))
    assert d.named == ["bend", "cubic"] and d.groups == [("bend",), ("cubic", "twin")]
    assert d.confounded[1].correlation == {"twin": pytest.approx(1.0, abs=1e-9)}
    assert d.after.chi2 == pytest.approx(chi2_of(y, X**2, X**3)[0], rel=1e-9)


def bend_basis(count, seed):
    """``count`` orthonormal columns orthogonal to the line and x^2."""
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(np.column_stack([ONE, X, X**2, rng.standard_normal((N, count))]))[0]
    return Q[:, 3:].T


def test_a_stand_in_is_swapped_out_beside_an_effect_with_an_absorbed_parameter():
    """The stand-in design with 20 x^2 added and 'bend' among the candidates: bend is named
    first, then S and Q; S is swapped for P at the end as without bend (Akaike lower by 4),
    with bend's tilt held at zero in the swap's fits."""
    P, Qc, R = bend_basis(3, 7)
    eps = math.sqrt(1.0 / 24.0)
    S = P + 0.5 * Qc + eps * R
    y = 0.3 + 0.5 * X + 20.0 * X**2 + 10.0 * P + 10.0 * Qc + noise(X**2, P, Qc, R, seed=3)
    d = diagnose(linear(y, {**BEND, "S": {"s": S}, "P": {"p": P}, "Q": {"q": Qc}}))
    chi2, *_ = chi2_of(y, X**2, P, Qc)
    assert [s.winner for s in d.steps[:2]] == ["bend", "S"]
    assert sorted(d.named) == ["P", "Q", "bend"] and not d.unexplained
    [(out, into, before, after)] = d.swaps
    assert (out, into) == ("S", "P") and before - after == pytest.approx(4.0, rel=1e-6)
    assert after == pytest.approx(aic(chi2, 5), rel=1e-9)


def test_an_effect_dropped_beside_one_with_an_absorbed_parameter():
    """As above with eps^2 = 1/3: after S, both P and Q are named, and S, whose estimate given
    them is exactly zero (the data have no R), is dropped with Wald p = 1; the refit holds
    bend's tilt at zero and is lstsq's on (1, x, x^2, P, Q)."""
    P, Qc, R = bend_basis(3, 7)
    S = P + 0.5 * Qc + math.sqrt(1.0 / 3.0) * R
    y = 0.3 + 0.5 * X + 20.0 * X**2 + 10.0 * P + 10.0 * Qc + noise(X**2, P, Qc, R, seed=3)
    d = diagnose(linear(y, {**BEND, "S": {"s": S}, "P": {"p": P}, "Q": {"q": Qc}}))
    assert d.steps[1].winner == "S" and list(d.dropped) == ["S"]
    assert d.dropped["S"] == pytest.approx(1.0, abs=1e-6)
    assert sorted(d.named) == ["P", "Q", "bend"] and d.swaps == []
    assert d.after.names[:3] == ("a", "b", "w")
    assert d.after.chi2 == pytest.approx(chi2_of(y, X**2, P, Qc)[0], rel=1e-9)


def test_the_kink_replaces_flagged_shifts_beside_an_effect_with_an_absorbed_parameter():
    """The kink design plus 20 x^2 and 'bend': bend is named first (its tilt held at zero),
    both observations are flagged, and the kink, tried instead of their shifts in the model
    holding bend, replaces them; the final chi-square is the least-squares minimum over k
    (the line and x^2 by lstsq at each k)."""
    kink, y, eps, u = kink_problem()

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        return kink.residuals(v) + 20.0 * X**2 - p("w") * X**2 - p("t") * 3.0 * X

    bend = Effect("bend", ("t", "w"), ((-100.0, 100.0),) * 2, (1e-3,) * 2)
    d = diagnose(Problem(kink.system, kink.base, (bend, *kink.candidates), residuals,
                         kink.start, observations=kink.observations))
    flagged = [f"outlier:P{B_ROW}", f"outlier:P{A_ROW}"]
    assert [s.winner for s in d.steps] == ["bend", *flagged, "kink", None]
    assert d.named == ["bend", "kink"] and d.outliers == [] and list(d.dropped) == flagged
    assert d.after.names == ("a", "b", "w", "k")

    def profile(k):
        return chi2_of(y + 20.0 * X**2 - k * eps * u - k**3 * ENDS, X**2)[0]

    assert d.after.chi2 == pytest.approx(profile(d.after.params["k"]), rel=1e-9)
    assert d.after.chi2 <= min(map(profile, np.linspace(0.0, 4.0, 4001))) + 1e-9


# --- an effect that explains a winning observation comes first -----------------------------------


@pytest.mark.parametrize(("left", "absorbed", "explains"),
                         [(10.0, 0.05, True), (20.0, 0.05, False), (20.0, 0.5, True)])
def test_an_effect_that_explains_the_observation_comes_first_at_alpha_over_n(left, absorbed,
                                                                              explains):
    """The data: a spike at P7 only. Effect E's column (beside the line) correlates 0.894
    with P7's (rho^2 = 0.8) and the spike is set so that E, fitted instead, leaves ``left`` of
    chi-square in P7's column: P7 (T = left / 0.2) beats E (T = 0.8 left / 0.2) as the step's
    smallest p-value. E explains P7's signal where ``left`` is below chi2 at alpha / n (40
    testable observations: 13.4; 10 is, 20 is not, though both exceed alpha's 6.63), or where
    P7's column keeps less than ``absorbed`` of its norm beside E (sqrt(0.2) = 0.45 < 0.5).
    But P7's shift, fitted instead, leaves nothing in E's column (the data are the spike), and
    E has as many parameters as P7: each explains the other, so P7, with the smaller p-value,
    is flagged in all three cases (:func:`effect_for_observation`)."""
    rho2 = 0.8
    Q = np.linalg.qr(np.column_stack([ONE, X, np.eye(N)[7]]))[0]
    o = Q[:, 2] * np.sign(Q[7, 2])  # the unit column of P7 beside the line
    h = np.random.default_rng(9).standard_normal(N)
    h -= Q @ (Q.T @ h)
    g = math.sqrt(rho2) * o + math.sqrt(1.0 - rho2) * h / np.linalg.norm(h)
    s = math.sqrt(left / (1.0 - rho2)) / (np.eye(N)[7] @ o)  # |spike beside the line|^2 = T
    y = 0.3 + 0.5 * X + s * np.eye(N)[7] + noise(np.eye(N)[7], g)
    lo, hi = stats.chi2.isf([0.01, 0.01 / N], 1)
    assert lo < left and bool(left < hi) is (left == 10.0)
    problem = linear(y, {"E": {"e": g}}, observations=True)
    d = diagnose(problem, absorbed=absorbed)
    first = d.steps[0]
    by_name = {t.name: t for t in (*first.tests, *first.snoop)}
    assert by_name["outlier:P7"].statistic == pytest.approx(left / (1.0 - rho2), rel=1e-9)
    assert by_name["E"].statistic == pytest.approx(rho2 * left / (1.0 - rho2), rel=1e-9)
    p7, e = by_name["outlier:P7"], by_name["E"]
    assert separated(p7, e, d.before.residual, p7.level, absorbed) is not explains
    assert first.winner == "outlier:P7" and d.named == []
    assert [t.name for t in d.outliers] == ["outlier:P7"]


# --- the final groups --------------------------------------------------------------------------


def test_a_named_effect_the_model_cannot_be_refitted_without_is_a_group_of_its_own():
    """'K' acts only through 'M' (prediction m x^2 + k m x^3): at m = 0 its column is zero,
    so it is named after M, and the final model without M cannot be fitted (K alone is not
    separable). M's group is M alone; K's, found with M fitted, is K alone."""
    y = 0.3 + 0.5 * X + 5.0 * X**2 + 10.0 * X**3 + noise(X**2, X**3)

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        return y - p("a") - p("b") * X - p("m") * X**2 - p("k") * p("m") * X**3

    effects = tuple(Effect(n, (n.lower(),), ((-100.0, 100.0),), (1e-3,)) for n in ("M", "K"))
    problem = Problem("toy", LINE, effects, residuals, {"a": 0.0, "b": 0.0})
    with pytest.raises(FitError):
        fit_model(problem, ("K",))
    d = diagnose(problem)
    assert [(t.name, t.status) for t in d.steps[0].tests] == [("M", "testable"),
                                                               ("K", "no_effect")]
    assert d.named == ["M", "K"] and d.groups == [("M",), ("K",)]
    assert d.confounded[0] == engine.Group("M", ("M",))
    assert d.after.params["k"] == pytest.approx(2.0, rel=1e-9)


def test_a_column_that_is_round_off_is_no_effect_and_a_tiny_true_one_is_kept():
    """'C' cancels exactly, as a common bias of two readings does in their difference:
    (B1 + c) - (B2 + c) - (B1 - B2) with B1, B2 of 1e5-1e6, so only the residuals' round-off
    moves (about 1e-10 per point). 'T' is a true column 1e-9 x^2. Before: C got a column of
    round-off (norm ~4e-7 at the 1e-3 step), a finite MDB and a status of its own; now it has
    no effect, and T's column is kept (to the round-off of its own differences, ~1e-5)."""
    y = 0.3 + 0.5 * X + noise()
    b1, b2 = 1e6 * (1.0 + X) + np.pi, 3e5 * (1.0 - X) + np.e

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        c = p("c")
        return y - p("a") - p("b") * X + ((b1 + c) - (b2 + c) - (b1 - b2)) \
            - p("t") * 1e-9 * X**2

    effects = tuple(Effect(n, (n.lower(),), ((-1e3, 1e3),), (1e-3,)) for n in ("C", "T"))
    problem = Problem("toy", LINE, effects, residuals, {"a": 0.0, "b": 0.0})
    fit = fit_model(problem, ())
    assert np.linalg.norm(jacobian(problem, fit.params, ["c"])) > 1e-8  # the round-off
    tests = {t.name: t for t in analyse_candidates(problem, fit)}
    assert tests["C"].status == "no_effect"
    assert tests["T"].status in ("testable", "undetectable")
    assert tests["T"].projected is not None
    np.testing.assert_allclose(np.linalg.norm(tests["T"].projected),
                               1e-9 * np.linalg.norm(X**2 - ONE * (X**2).mean()), rtol=1e-4)


def group_design(bound=100.0):
    """Orthonormal P, C beside the line; data 20 P + 5 C (noise of norm^2 ~ 64, so that the
    global test still fails once P is fitted); 'mix' = P - C / 2 keeps 0.447 of its norm
    beside P and is then C's column scaled, so it is a partner of the cubic (C)."""
    P, C = bend_basis(2, 11)
    y = 0.3 + 0.5 * X + 20.0 * P + 5.0 * C + 1.3 * noise(P, C)
    return linear(y, {"quadratic": {"q": P}, "cubic": {"c": C}, "mix": {"m": P - 0.5 * C}},
                  bounds={"c": (-bound, bound)})


def test_the_final_groups_use_the_absorption_level_given():
    """With absorbed = 0.7, 'mix' (0.447 of its norm beside P) is absorbed once the quadratic
    is fitted: the cubic's group is the cubic alone; at the default 0.05 it holds mix."""
    assert diagnose(group_design()).groups[1] == ("cubic", "mix")
    d = diagnose(group_design(), absorbed=0.7)
    assert d.named == ["quadratic", "cubic"] and d.groups[1] == ("cubic",)
    assert d.absorbed == ["mix"]


def test_the_final_groups_use_the_power_given():
    """The cubic's bound b is set so that b^2 (its largest noncentrality, |C| = 1) lies
    between lambda0 at power 0.9 and at 0.999 (geometric mean): at power 0.9 it is testable,
    named, and its final group holds mix; at 0.999 it is undetectable and mix is named
    instead."""
    problem = group_design()
    fit = fit_model(problem, ("quadratic",))
    lam = [analyse_candidates(problem, fit, power=power)[1].lambda0 for power in (0.9, 0.999)]
    bound = (lam[0] * lam[1]) ** 0.25
    assert lam[0] < bound**2 < lam[1] and bound > 5.0
    d = diagnose(group_design(bound), power=0.9)
    assert d.named == ["quadratic", "cubic"] and d.groups[1] == ("cubic", "mix")
    assert d.confounded[1].correlation == {"mix": pytest.approx(1.0, abs=1e-9)}
    assert diagnose(group_design(bound), power=0.999).named == ["quadratic", "mix"]


# --- the minimal parametrisation ---------------------------------------------------------------


def test_the_stand_in_with_fewest_parameters_counting_its_partner_then_smallest_p_value():
    """Winner W spans orthonormal P1, P2, P3; the data are 10 P1 + 10 P2. Stand-ins inside W:
    'one' (P1) explains W's signal only with 'two_b' (P2) beside it, 2 parameters in all;
    'pair' (P1, P2) alone, also 2 parameters, with the smaller p-value (chi2(2) at 200 against
    chi2(1) at 100), so it is chosen; 'twin' (the same columns as pair) ties with it exactly
    and the first one found stays."""
    P1, P2, P3 = bend_basis(3, 13)
    y = 0.3 + 0.5 * X + 10.0 * P1 + 10.0 * P2 + noise(X**2, P1, P2, P3)
    problem = linear(y, {"W": {"w1": P1, "w2": P2, "w3": P3}, "one": {"o": P1},
                         "pair": {"p1": P1, "p2": P2}, "twin": {"t1": P1, "t2": P2},
                         "two_b": {"e": P2}})
    fit = fit_model(problem, ())
    W, one, pair, twin, extra = analyse_candidates(problem, fit)
    assert stats.chi2.logsf(200.0, 2) < stats.chi2.logsf(100.0, 1)
    assert pair.log_p == twin.log_p < one.log_p
    got = confounding.minimal_member(W, [one, pair, twin], [extra], fit.residual)
    assert got is pair
    assert confounding.minimal_member(W, [one], [extra], fit.residual) is one
    assert confounding.minimal_member(W, [one], [], fit.residual) is None


@pytest.mark.parametrize(("confounded", "stands_in"), [(0.9, True), (0.99, False)])
def test_a_stand_in_must_lie_inside_the_winner_at_the_level_given(confounded, stands_in):
    """Winner W spans P1, P2; 'near' = 0.95 P1 + 0.312 P3 (canonical correlation 0.95 with
    W's space) and the data 5 P1: fitted instead, near leaves chi-square 25 (1 - 0.95^2) = 2.4 in
    W's columns (below chi2_{0.99}(2) = 9.2), so it stands in at the level 0.9, not at 0.99."""
    P1, P2, P3 = bend_basis(3, 13)
    near = 0.95 * P1 + math.sqrt(1.0 - 0.95**2) * P3
    y = 0.3 + 0.5 * X + 5.0 * P1 + noise(X**2, P1, P2, P3)
    problem = linear(y, {"W": {"w1": P1, "w2": P2}, "near": {"n": near}})
    fit = fit_model(problem, ())
    W, inner = analyse_candidates(problem, fit)
    assert candidate_tests.canonical_correlation(W, inner) == pytest.approx(0.95, rel=1e-9)
    left = chi2_of(y, near)[0] - chi2_of(y, near, P1, P2)[0]
    assert left == pytest.approx(25.0 * (1.0 - 0.95**2), rel=1e-9)
    assert left < stats.chi2.isf(0.01, 2) / 3.0
    got = confounding.minimal_member(W, [inner], [], fit.residual, confounded=confounded)
    assert (got is inner) is stands_in


def test_only_candidates_testable_at_the_step_are_tried_instead_of_flagged_observations():
    """A and B 10 sigma off and one candidate, 'cube' (k^3 at A and B): its column at k = 0 is
    zero (central differences give h^2 at step h, 4 h^2 at 2h: no effect), so it is never
    testable and not among the effects tried instead of them, though fitted it would take them
    exactly and lower Akaike's criterion: both observations stay flagged."""
    y = 0.3 + 0.5 * X + 10.0 * ENDS + noise(np.eye(N)[A_ROW], np.eye(N)[B_ROW])

    def residuals(v):
        def p(k):
            return np.asarray(v.get(k, 0.0), float)
        return y - p("a") - p("b") * X - p("k") ** 3 * ENDS

    obs = tuple((f"P{i}", i, (i,)) for i in range(N))
    problem = Problem("toy", LINE, (Effect("cube", ("k",), ((-10.0, 10.0),), (1e-4,)),),
                      residuals, {"a": 0.0, "b": 0.0}, observations=obs)
    d = diagnose(problem)
    assert [t.status for s in d.steps for t in s.tests] == ["no_effect"] * 3
    assert d.named == [] and sorted(t.name for t in d.outliers) == sorted(
        [f"outlier:P{A_ROW}", f"outlier:P{B_ROW}"])
    assert d.after.chi2 == pytest.approx(chi2_of(y, np.eye(N)[A_ROW], np.eye(N)[B_ROW])[0],
                                         rel=1e-9)
    cube = fit_model(with_outliers(problem), ("cube",), {"a": 0.0, "b": 0.0, "k": 2.0})
    assert cube.chi2 + 2.0 * 3 < d.after.chi2 + 2.0 * 4


@pytest.mark.parametrize(("alpha", "absorbed", "partner"),
                         [(0.01, 0.05, False), (0.001, 0.05, True), (0.01, 0.5, True)])
def test_the_partner_test_uses_the_levels_given(alpha, absorbed, partner):
    """Orthonormal P1, P2 beside the line; A = P1, B = 0.95 P1 + 0.312 P2 (canonical
    correlation 0.95), the data s P1 with s^2 (1 - 0.95^2) = 8.5: B, fitted instead, leaves
    chi-square 8.5 in A's column, significant at 0.01 (6.63: the data separate them), not at
    0.001 (10.8: B is A's partner). With absorbed = 0.5, A's column keeps 0.31 < 0.5 of its
    norm beside B: B explains it whatever the statistic, and is a partner."""
    P1, P2 = bend_basis(2, 17)
    s = math.sqrt(8.5 / (1.0 - 0.95**2))
    y = 0.3 + 0.5 * X + s * P1 + noise(X**2, P1, P2)
    B = 0.95 * P1 + math.sqrt(1.0 - 0.95**2) * P2
    assert chi2_of(y, B)[0] - chi2_of(y, B, P1)[0] == pytest.approx(8.5, rel=1e-9)
    assert stats.chi2.isf(0.01, 1) < 8.5 < stats.chi2.isf(0.001, 1)
    d = diagnose(linear(y, {"A": {"a1": P1}, "B": {"b1": B}}), alpha=alpha, absorbed=absorbed)
    group = ("A", "B") if partner else ("A",)
    assert d.named == ["A"] and d.steps[0].group == group and d.groups == [group]


def test_a_flagged_observation_an_effect_named_later_explains_is_dropped():
    """The kink acting at B only (``k eps u + k^3 e_B``, eps = 0.25: its linearised statistic
    about 50, B's about 100): B is flagged first, then the kink is named, and fitted (k = 10^(1/3)
    exactly) it leaves B's shift at zero: the shift is dropped (Wald p = 1) and no observation
    stays flagged. The final model is lstsq's on the line at that k."""
    u = 3.0 * np.sin(7.0 * X)
    u[B_ROW] = 0.0
    u -= np.column_stack([ONE, X]) @ np.linalg.lstsq(np.column_stack([ONE, X]), u, rcond=None)[0]
    u[B_ROW] = 0.0
    eps, k0 = 0.25, 10.0 ** (1.0 / 3.0)
    spike = np.eye(N)[B_ROW]
    y = 0.3 + 0.5 * X + k0 * eps * u + 10.0 * spike + noise(u, spike, seed=1)

    def residuals(v):
        k = np.asarray(v.get("k", 0.0), float)
        return y - v.get("a", 0.0) - v.get("b", 0.0) * X - k * eps * u - k**3 * spike

    obs = tuple((f"P{i}", i, (i,)) for i in range(N))
    problem = Problem("toy", LINE, (Effect("kink", ("k",), ((-10.0, 10.0),), (1e-4,)),),
                      residuals, {"a": 0.0, "b": 0.0}, observations=obs)
    d = diagnose(problem)
    flagged = f"outlier:P{B_ROW}"
    first = {t.name: t.statistic for t in (*d.steps[0].tests, *d.steps[0].snoop)}
    assert 40.0 < first["kink"] < 60.0 < 90.0 < first[flagged]
    assert [s.winner for s in d.steps] == [flagged, "kink", None]
    assert d.named == ["kink"] and d.outliers == []
    assert list(d.dropped) == [flagged] and d.dropped[flagged] == pytest.approx(1.0, abs=1e-6)
    assert d.after.effects == ("line", "kink") and d.after.params["k"] == pytest.approx(k0)
    assert d.after.chi2 == pytest.approx(chi2_of(y - k0 * eps * u - 10.0 * spike)[0], rel=1e-6)


@pytest.mark.parametrize(("confounded", "named"), [(0.9, "near"), (0.99, "W")])
def test_a_whole_diagnosis_takes_a_stand_in_at_the_containment_level_given(confounded, named):
    """Winner W spans P1, P2, the data 5 P1 + 2 P2 (noise of norm^2 43); 'near' =
    0.95 P1 + 0.312 P3 has the larger p-value (chi2(1) at 22.6 against chi2(2) at 29) and,
    fitted instead, leaves 6.4 in W's columns (below chi2_{0.99}(2) = 9.2): it stands in for W
    where the containment level is 0.9 (the default), not at 0.99 (their canonical correlation
    is 0.95)."""
    P1, P2, P3 = bend_basis(3, 13)
    near = 0.95 * P1 + math.sqrt(1.0 - 0.95**2) * P3
    e = noise(X**2, P1, P2, P3)
    y = 0.3 + 0.5 * X + 5.0 * P1 + 2.0 * P2 + math.sqrt(43.0) * e / np.linalg.norm(e)
    # misfit before (43 + 29 above chi2_{0.99}(38) = 61.2), none after (43 + 6.4 below 59.9)
    assert chi2_of(y)[0] == pytest.approx(72.0, rel=1e-9)
    left = chi2_of(y, near)[0] - chi2_of(y, near, P1, P2)[0]
    assert left == pytest.approx(25.0 * (1.0 - 0.95**2) + 4.0, rel=1e-9)
    assert stats.chi2.logsf(29.0, 2) < stats.chi2.logsf(25.0 * 0.95**2, 1)
    d = diagnose(linear(y, {"W": {"w1": P1, "w2": P2}, "near": {"n": near}}),
                 confounded=confounded)
    assert d.steps[0].winner == named and d.named == [named]


def test_a_named_effect_undetectable_beside_the_rest_is_a_group_of_its_own():
    """A = P1 (bound 12.5) named first; B = (0.9165 P1 + 0.4 P2, P3) second: beside B, A keeps
    0.4 of its column, so its largest noncentrality is (12.5 0.4)^2 = 25, below lambda0, while
    its Wald test given B (estimate 11.25, standard error 1 / 0.4: T = 20.25) keeps it in the
    model. Refitted without A, A's own test is undetectable at power 0.99 (lambda0 of its own
    1-dof test at alpha / 2 above 25): its group is A alone."""
    P1, P2, P3 = bend_basis(3, 23)
    b1 = math.sqrt(1.0 - 0.4**2) * P1 + 0.4 * P2
    y = 0.3 + 0.5 * X + 11.25 * P1 + 10.0 * b1 + noise(X**2, P1, P2, P3)
    problem = linear(y, {"A": {"ka": P1}, "B": {"kb": b1, "kc": P3}},
                     bounds={"ka": (-12.5, 12.5)})
    alone = analyse_candidates(problem, fit_model(problem, ("B",)), power=0.99)[0]
    assert alone.status == "undetectable" and alone.retained["ka"] == pytest.approx(0.4)
    assert alone.lambda0 > 1.04 * 25.0  # reach 25, more than 4 % below
    d = diagnose(problem, power=0.99)
    assert d.named == ["A", "B"] and d.dropped == {} and d.swaps == []
    _, coef, cov = chi2_of(y, P1, b1, P3)
    assert coef[2] ** 2 / cov[2, 2] == pytest.approx(20.25, rel=1e-9)
    assert d.after.chi2 == pytest.approx(chi2_of(y, P1, b1, P3)[0], rel=1e-9)
    assert d.confounded[0] == engine.Group("A", ("A",)) and d.groups[0] == ("A",)


def test_least_separable_is_the_parameter_the_others_reproduce():
    """Unit columns a, b and c = (a + b) / sqrt(2): the smallest singular value's right vector
    of the normalised columns is (1, 1, -sqrt(2)) / 2, so c is held; a column 10 times longer
    changes nothing (the columns are normalised); fewer than two parameters hold none."""
    from montecarlo.discrepancy.candidate_tests import CandidateTest
    from montecarlo.discrepancy.confounding import least_separable

    rng = np.random.default_rng(0)
    a, b = np.linalg.qr(rng.standard_normal((50, 2)))[0].T
    c = (a + b) / math.sqrt(2.0)
    test = CandidateTest("e", "testable", ("x", "y", "z"),
                         projected=np.column_stack([a, 10.0 * b, c]))
    assert least_separable(test) == "z"
    test = CandidateTest("e", "testable", ("x", "y", "z"), projected=np.column_stack([c, a, b]))
    assert least_separable(test) == "x"
    assert least_separable(CandidateTest("e", "testable", ("x",),
                                         projected=a[:, None])) is None
