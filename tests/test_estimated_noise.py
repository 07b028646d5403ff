"""Tests under an estimated noise and the noise estimates of ``auto``, against references the
code does not compute: least-squares F tests and externally studentised residuals by numpy
and scipy, closed forms of the F tail, simulated noncentral F tests, and a direct REML
optimisation by scipy for the variance components.
"""

import json
import math

import numpy as np
import pytest
from scipy import optimize, stats
from statsmodels.stats.multitest import multipletests

from montecarlo.discrepancy.candidate_tests import analyse_candidates, noncentrality
from montecarlo.discrepancy.engine import detection_family, diagnose
from montecarlo.discrepancy.estimated_sigma import (
    global_f,
    log_f_sf,
    noncentrality_f,
    pope_tau,
    tau_sf,
)
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.noise_estimation import pivot_estimate, reml, scale_estimate
from montecarlo.discrepancy.problem import Effect, Problem, with_outliers

INF = (-np.inf, np.inf)
X = np.linspace(-1.0, 1.0, 40)


def toy(y, sigma=1.0, observations=False):
    """Line a + b x with candidates c x^2 and (d x^3, e sin 3x), whitened by ``sigma``."""
    def residuals(v):
        g = {k: np.asarray(v.get(k, 0.0), float) for k in "abcde"}
        pred = g["a"] + g["b"] * X + g["c"] * X**2 + g["d"] * X**3 + g["e"] * np.sin(3 * X)
        return (y - pred) / sigma

    base = Effect("line", ("a", "b"), (INF, INF), (1e-3, 1e-3))
    cands = (Effect("square", ("c",), (INF,), (1e-3,)),
             Effect("wiggle", ("d", "e"), (INF, INF), (1e-3, 1e-3)))
    obs = tuple((f"p{i}", i + 1, (i,)) for i in range(X.size)) if observations else ()
    return Problem("toy", base, cands, residuals, {"a": 0.0, "b": 0.0}, observations=obs)


def sets(seed=0, scale=0.3):
    return 0.5 + 0.2 * X + scale * np.random.default_rng(seed).standard_normal(X.size)


def ssr(y, *columns):
    A = np.column_stack([np.ones_like(X), X, *columns])
    return float(np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2)), A.shape[1]


def test_candidate_f_tests_equal_nested_least_squares_f_tests():
    y = sets(1) + 0.15 * X**2
    fit = fit_model(toy(y), ())
    tests = {t.name: t for t in analyse_candidates(toy(y), fit, test="F")}
    s0, p0 = ssr(y)
    for name, cols in (("square", [X**2]), ("wiggle", [X**3, np.sin(3 * X)])):
        s1, p1 = ssr(y, *cols)
        q, d = p1 - p0, X.size - p1
        F = ((s0 - s1) / q) / (s1 / d)
        assert tests[name].test == "F" and (tests[name].dof, tests[name].dof2) == (q, d)
        assert tests[name].statistic == pytest.approx(F, rel=1e-6)
        assert tests[name].p_value == pytest.approx(stats.f.sf(F, q, d), rel=1e-5)


def test_f_tests_do_not_depend_on_the_stated_noise():
    """Whitened by 0.1 or by 10 (the truth 0.3), every F test is the same."""
    y = sets(2) + 0.1 * X**2
    a, b = (analyse_candidates(toy(y, s), fit_model(toy(y, s), ()), test="F")
            for s in (0.1, 10.0))
    for s, t in zip(a, b, strict=True):
        assert s.statistic == pytest.approx(t.statistic, rel=1e-6)
        assert s.p_value == pytest.approx(t.p_value, rel=1e-5)


def test_pope_tau_is_the_internally_studentised_residual_and_shares_the_t_test_p():
    """An observation's tau equals e_i / (s sqrt(1 - h_ii)) (numpy), and its p-value equals
    the two-sided t test of the externally studentised residual, t(n - p - 1)."""
    y = sets(3)
    y[7] += 1.5
    problem = with_outliers(toy(y, observations=True))
    fit = fit_model(problem, ())
    view = Problem("toy", problem.base, problem.candidates[2:], problem.residuals,
                   problem.start, observations=problem.observations)
    taus = {t.name: t for t in analyse_candidates(view, fit, test="tau")}
    A = np.column_stack([np.ones_like(X), X])
    H = A @ np.linalg.solve(A.T @ A, A.T)
    e = y - H @ y
    n, p = X.size, 2
    s2 = e @ e / (n - p)
    for i in (0, 7, 20):
        r = e[i] / math.sqrt(s2 * (1 - H[i, i]))
        t_ext = r * math.sqrt((n - p - 1) / (n - p - r * r))
        t = taus[f"outlier:p{i}"]
        assert t.statistic == pytest.approx(abs(r), rel=1e-6)
        assert t.p_value == pytest.approx(2 * stats.t.sf(abs(t_ext), n - p - 1), rel=1e-5)
        assert tau_sf(t.statistic, n - p, 1) == pytest.approx(t.p_value, rel=1e-5)
    assert pope_tau(4.0, 38.0, 38) == pytest.approx(2.0)


def test_global_f_is_the_least_squares_f_test_against_every_candidate():
    y = sets(4) + 0.1 * X**3
    fit = fit_model(toy(y), ())
    tests = analyse_candidates(toy(y), fit, test="F")
    f_value, q, d, p = global_f(fit.residual, [t.projected for t in tests], fit.dof)
    s0, p0 = ssr(y)
    s1, p1 = ssr(y, X**2, X**3, np.sin(3 * X))
    ref = ((s0 - s1) / (p1 - p0)) / (s1 / (X.size - p1))
    assert (q, d) == (3, X.size - 5)
    assert f_value == pytest.approx(ref, rel=1e-6)
    assert p == pytest.approx(stats.f.sf(ref, 3, X.size - 5), rel=1e-5)


def test_detection_family_under_estimated_noise_uses_the_global_f():
    y = sets(5)
    problem = toy(y)
    fit = fit_model(problem, ())
    tests, _, global_p = detection_family(problem, Problem("toy", problem.base, (),
                                          problem.residuals, problem.start), fit,
                                          noise_estimated=True)
    _, _, _, p = global_f(fit.residual, [t.projected for t in tests], fit.dof)
    # Holm over three members of equal weight (square, wiggle, global): statsmodels' Holm
    adjusted = multipletests([*(t.p_value for t in tests), p], method="holm")[1]
    assert [t.p_adjusted for t in tests] == pytest.approx(adjusted[:2].tolist(), rel=1e-12)
    assert global_p == pytest.approx(adjusted[2], rel=1e-12)
    assert all(t.test == "F" for t in tests)


def test_log_f_sf_far_in_the_tail_matches_the_closed_form_for_two_numerator_dof():
    """F(2, d): P(F > f) = (1 + 2 f / d)^(-d/2) exactly; scipy underflows far out."""
    for f, d in ((5.0, 30), (1e6, 2500), (1e12, 800)):
        exact = -(d / 2) * math.log1p(2 * f / d)
        assert log_f_sf(f, 2, d) == pytest.approx(exact, rel=1e-6)


def test_noncentral_f_mdb_by_simulation_and_its_chi2_limit():
    """The F test at lambda0 rejects in 80 % of simulated noncentral F draws (20,000; 3
    binomial sd = 0.85 %); for d -> infinity lambda0 tends to Baarda's chi2 value."""
    alpha, q, d = 0.001, 2, 30
    lam = noncentrality_f(alpha, q, d, 0.8)
    rng = np.random.default_rng(11)
    z = rng.standard_normal((20000, q))
    z[:, 0] += math.sqrt(lam)
    draws = (np.sum(z**2, axis=1) / q) / (rng.chisquare(d, 20000) / d)
    assert abs(np.mean(draws > stats.f.isf(alpha, q, d)) - 0.8) < 0.0085
    assert noncentrality_f(alpha, q, 10**7, 0.8) == pytest.approx(noncentrality(alpha, q),
                                                                   rel=1e-3)
    assert lam > noncentrality(alpha, q)


def test_scaled_diagnosis_names_the_same_at_any_stated_noise():
    """A hidden x^2 term: with the noise estimated, stated 0.03 and 3 (truth 0.3) name it
    with the same F statistic."""
    y = sets(6) + 0.6 * X**2
    ds = [diagnose(toy(y, s), noise_estimated=True) for s in (0.03, 3.0)]
    assert [d.named for d in ds] == [["square"], ["square"]]
    F = [d.steps[0].tests[0].statistic for d in ds]
    assert F[0] == pytest.approx(F[1], rel=1e-6)


def test_pivot_of_a_pure_scale_is_the_a_posteriori_variance_factor():
    y = sets(7)
    fit = fit_model(toy(y, 1.0), ())
    est = scale_estimate("s", 1.0, fit)
    value, low, high = pivot_estimate(lambda s: fit.chi2 / s**2, fit.dof, 1.0)
    lo_q, hi_q = stats.chi2.ppf([0.025, 0.975], fit.dof)
    assert value == pytest.approx(math.sqrt(fit.chi2 / fit.dof), rel=1e-9)
    assert (low, high) == pytest.approx((math.sqrt(fit.chi2 / hi_q),
                                         math.sqrt(fit.chi2 / lo_q)), rel=1e-9)
    assert (est.value, est.low, est.high) == pytest.approx((value, low, high), rel=1e-9)


def _reml_loglik(log_theta, r, A, Q):
    S = sum(math.exp(t) * q for t, q in zip(log_theta, Q, strict=True))
    Si = np.linalg.inv(S)
    N = A.T @ Si @ A
    P = Si - Si @ A @ np.linalg.solve(N, A.T @ Si)
    return 0.5 * (np.linalg.slogdet(S)[1] + np.linalg.slogdet(N)[1] + r @ P @ r)


def test_reml_fisher_scoring_equals_a_direct_reml_optimisation():
    """A line observed by 20 groups of 4 points with a group effect (variance 0.5) and white
    noise (0.2): Fisher scoring and scipy's minimisation of the REML criterion agree."""
    rng = np.random.default_rng(5)
    groups = np.repeat(np.arange(20), 4)
    x = rng.uniform(-1, 1, groups.size)
    A = np.column_stack([np.ones_like(x), x])
    Z = (groups[:, None] == np.arange(20)[None, :]).astype(float)
    r = A @ [1.0, 2.0] + math.sqrt(0.5) * Z @ rng.standard_normal(20) \
        + math.sqrt(0.2) * rng.standard_normal(x.size)
    Q = [np.eye(x.size), Z @ Z.T]
    theta, cov = reml(r, A, Q, np.array([1.0, 1.0]), [True, True])
    ref = optimize.minimize(_reml_loglik, np.log([1.0, 1.0]), args=(r, A, Q),
                            method="L-BFGS-B", options={"ftol": 1e-15, "gtol": 1e-10})
    assert theta == pytest.approx(np.exp(ref.x), rel=1e-4)
    assert cov.shape == (2, 2) and np.all(np.diag(cov) > 0)
    # one component: REML is chi2 / (n - p) of the least-squares residuals
    theta1, _ = reml(r, A, [np.eye(x.size)], np.array([1.0]), [True])
    e = r - A @ np.linalg.lstsq(A, r, rcond=None)[0]
    assert theta1[0] == pytest.approx(e @ e / (x.size - 2), rel=1e-8)


def test_ground_noise_components_add_up_to_the_whitening():
    """At the values used, pixel^2 Qw_pixel + survey^2 Qw_survey is the identity."""
    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.geometry.camera import Camera

    camera = Camera.from_degrees(90.0, 90.0, 512, 512)
    layout = ge.field_layout(camera, {"psi": 0.5, "theta": 0.3, "gamma": 0.1})
    data = ge.simulate(layout, camera, {"psi": 0.5, "theta": 0.3, "gamma": 0.1}, 0.3, 0.05, 1)
    Qp, Qs = ge.whitened_noise_components(data, camera, 0.3, 0.05)
    assert 0.09 * Qp + 0.0025 * Qs == pytest.approx(np.eye(2 * data.n), abs=1e-9)


def test_collimation_auto_reports_the_estimate_and_f_tests(capsys):
    from montecarlo.cli import main

    data = "results/examples/discrepancy_collimation/data.csv"
    assert main(["diagnose", "collimation", data, "--readings", "absolute",
                 "--angle-sigma-arcsec", "auto", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    est = report["noise_estimate"]["estimates"][0]
    assert est["option"] == "angle_sigma_arcsec" and est["low"] < est["value"] < est["high"]
    assert report["named_effects"][0]["name"] == "axis_misalignment"
    assert report["named_effects"][0]["test"] == "F"
    tests = [c["mdb_test"] for c in report["candidates_after"] if c["mdb_test"]]
    assert tests and all(t["statistic"].startswith("F(") and t["sigma"] == "estimated"
                         for t in tests)
    assert main(["diagnose", "collimation", data, "--angle-sigma-arcsec", "often"]) == 2


def test_ground_auto_prints_both_components_and_a_stated_value_the_data_reject(capsys):
    """Both sigma auto: the REML estimates and their intervals; a stated pixel sigma of
    0.15 px on data made with 0.3 px draws the warning."""
    from montecarlo.cli import main

    data = "results/examples/discrepancy_ground/data.csv"
    flags = ["--fov-deg", "90", "90", "--pixels", "512", "512"]
    assert main(["diagnose", "ground", data, *flags, "--pixel-sigma-px", "auto",
                 "--survey-sigma-m", "auto"]) == 0
    out = capsys.readouterr().out
    assert "pixel_sigma_px estimated from the data" in out
    assert "survey_sigma_m estimated from the data" in out and "REML" in out
    assert main(["diagnose", "ground", data, *flags, "--pixel-sigma-px", "0.15",
                 "--survey-sigma-m", "0.01"]) == 0
    out = capsys.readouterr().out
    assert "warning: the stated pixel_sigma_px 0.15 is rejected by the data (stated too " \
           "small)" in out


def test_a_candidate_with_no_degree_of_freedom_left_is_not_tested():
    """Four points, a line and a two-parameter candidate: n - p - q = 0, no F test."""
    x = np.array([-1.0, 0.0, 0.5, 1.0])
    y = np.array([0.1, -0.2, 0.3, 0.05])

    def residuals(v):
        g = {k: np.asarray(v.get(k, 0.0), float) for k in "abde"}
        return y - g["a"] - g["b"] * x - g["d"] * x**2 - g["e"] * x**3

    problem = Problem("toy", Effect("line", ("a", "b"), (INF, INF), (1e-3, 1e-3)),
                      (Effect("curve", ("d", "e"), (INF, INF), (1e-3, 1e-3)),), residuals,
                      {"a": 0.0, "b": 0.0})
    fit = fit_model(problem, ())
    (t,) = analyse_candidates(problem, fit, test="F")
    assert t.status == "undetectable" and "no degree of freedom" in t.reason
    assert analyse_candidates(problem, fit)[0].status == "testable"
