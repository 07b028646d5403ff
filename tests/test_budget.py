"""Error budget: Sobol indices (SALib) against closed forms, the ground model, the allocation."""

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from montecarlo.design import budget as bg
from montecarlo.design import budget_report
from montecarlo.design import sizing_problem as sp
from montecarlo.engine.distributions import Distribution
from montecarlo.errors import InputError
from montecarlo.seed000 import ground
from montecarlo.systems import study_from_dict
from tests.forked_cli import montecarlo_cli

REQ = sp.Requirement(limit=3.0)


def linear_problem():
    """Y = sum a_i X_i with X_1 ~ U(-1, 1), X_2 ~ N(0, 0.5^2), X_3 ~ U(0, 2), and a group of
    X_4, X_5 ~ U(-1, 1). Closed form (independent inputs, additive model):
    S1_i = ST_i = a_i^2 Var X_i / sum_j a_j^2 Var X_j, a group's index the sum of its members'."""
    a = np.array([1.0, 2.0, 0.5, 1.0, 0.6])
    var = np.array([1 / 3, 0.25, 1 / 3, 1 / 3, 1 / 3])
    problem = {"num_vars": 5, "names": ["x1", "x2", "x3", "x4", "x5"],
               "groups": ["x1", "x2", "x3", "g", "g"],
               "dists": ["unif", "norm", "unif", "unif", "unif"],
               "bounds": [[-1, 1], [0, 0.5], [0, 2], [-1, 1], [-1, 1]]}
    share = a**2 * var / np.sum(a**2 * var)
    exact = pd.Series([share[0], share[1], share[2], share[3] + share[4]],
                      index=["x1", "x2", "x3", "g"])
    return problem, (lambda x: x @ a), exact


def test_sobol_indices_of_a_linear_function_match_the_closed_form():
    """Tolerance: SALib's own bootstrap intervals at a family-wise level of 99.9 % over the
    eight indices (Bonferroni), i.e. each at 1 - 0.001/8. The intervals must also be narrower
    than the gaps between distinct exact indices, so a wrong assignment would fail."""
    problem, model, exact = linear_problem()
    level = 1 - 0.001 / 8
    si = bg.sobol_indices(problem, model, 2**13, rng=11, confidence=level, resamples=500)
    assert list(si.index) == list(exact.index)
    for col in ("S1", "ST"):
        err = (si[col] - exact).abs()
        assert (err <= si[f"{col}_conf"]).all(), (col, err.to_dict(), si[f"{col}_conf"].to_dict())
    gaps = np.diff(np.sort(exact.to_numpy()))
    assert si["S1_conf"].max() < gaps.min()


def test_sobol_indices_are_reproducible_and_seeded():
    problem, model, _ = linear_problem()
    a = bg.sobol_indices(problem, model, 256, rng=5)
    b = bg.sobol_indices(problem, model, 256, rng=np.random.default_rng(5))
    pd.testing.assert_frame_equal(a, bg.sobol_indices(problem, model, 256, rng=5))
    assert not a.equals(b)


def test_sobol_needs_a_power_of_two_and_finite_outputs():
    problem, model, _ = linear_problem()
    with pytest.raises(InputError, match="power of 2"):
        bg.sobol_indices(problem, model, 1000)
    with pytest.raises(InputError, match="no valid solution"):
        bg.sobol_indices(problem, lambda x: np.where(x[:, 0] > 0.9, np.nan, x[:, 0]), 64)


def test_allocation_is_rss_consistent_and_proportional_to_total_order():
    st = pd.Series({"a": 0.6, "b": 0.3, "c": 0.1, "d": -0.01})
    out = bg.allocate(st, 3.0)
    assert np.sqrt((out["allocation"] ** 2).sum()) == pytest.approx(3.0, rel=1e-12)
    assert out["share"].to_dict() == pytest.approx({"a": 0.6, "b": 0.3, "c": 0.1, "d": 0.0})
    assert out.loc["a", "allocation"] == pytest.approx(3.0 * np.sqrt(0.6))


def prepared(relation="common", **errors):
    raw = {**sp.DEFAULT_DESIGN, "errors": {**sp.DEFAULT_DESIGN["errors"], **errors,
                                           "pixel_relation": relation}}
    return study_from_dict(raw).points[0].prepared


def test_budget_model_columns_follow_the_pixel_relation():
    common = bg.GroundBudgetModel.from_prepared(prepared(), "common", "rotation_angle",
                                                "normalised")
    indep = bg.GroundBudgetModel.from_prepared(prepared("independent"), "independent",
                                               "rotation_angle", "normalised")
    assert common.columns == ("dx_m", "dy_m", "dh1_m", "dh_m", "pixel_x", "pixel_z")
    assert indep.groups[-4:] == ("pixel_px",) * 4
    assert common.salib_problem()["dists"] == ["unif"] * 4 + ["norm"] * 2
    assert common.salib_problem()["bounds"][-1] == [0.0, 0.3]


def test_budget_model_is_the_ground_simulation():
    """Rows of the sample matrix go into ground.simulate exactly as the study system does:
    a common pixel error moves both targets, an independent one each separately."""
    rng = np.random.default_rng(2)
    p = prepared("independent")
    m = bg.GroundBudgetModel.from_prepared(p, "independent", "delta_theta", "raw")
    x = rng.normal(0.0, 0.2, (7, len(m.columns)))
    true = tuple(d.location for d in p.mounting)
    sol = ground.simulate(p.camera, true, p.L, p.H, dx=x[:, 0], dy=x[:, 1], dh1=x[:, 2],
                          dh=x[:, 3], pixel_error_a=x[:, 4:6], pixel_error_b=x[:, 6:8],
                          solvers=("raw",))["raw"]
    np.testing.assert_array_equal(m(x), ground.solution_metrics(sol, true)["delta_theta"])
    mc = bg.GroundBudgetModel.from_prepared(prepared(), "common", "rotation_angle", "normalised")
    assert np.all(mc(np.zeros((3, len(mc.columns)))) < 1e-12)  # no error, no rotation


@pytest.mark.parametrize("change, message", [
    ({"errors": {"dx_m": {"dist": "corners", "bound": 0.1}}}, "corners are a worst case"),
    ({"mounting": {"psi_deg": {"dist": "uniform", "bound": 5.0}}}, "fixed true mounting"),
])
def test_budget_refuses_sources_without_a_variance(change, message):
    raw = {**sp.DEFAULT_DESIGN}
    for section, values in change.items():
        raw[section] = {**raw[section], **values}
    with pytest.raises(InputError, match=message):
        bg.budget(raw, REQ, "common", samples=64, trials=100)


def test_a_lone_source_scales_linearly():
    """The 'scale for allocation' column assumes that a lone small error source moves the
    percentile in proportion to its scale. With common random numbers the ratio for a doubled
    bound departs from 2 only by second-order terms (relative size ~ the angle, 1e-3) and the
    histogram quantisation of each percentile (2**-11 relative each); 1 % bounds both, and a
    square law (4) or no dependence (1) would fail."""
    base = {**sp.DEFAULT_DESIGN, "errors": {**sp.DEFAULT_DESIGN["errors"], "dy_m": 0.0,
                                            "dh1_m": 0.0, "dh_m": 0.0, "pixel_px": 0.0}}
    rows = [{"errors.dx_m": {"dist": "uniform", "bound": b}} for b in (0.1, 0.2)]
    study = sp.ground_study(base, REQ, rows, "common", trials=4000, seed=3, block_size=2000)
    stats_ = sp.run_statistic(study, REQ, n_jobs=1)
    assert stats_["value"][1] / stats_["value"][0] == pytest.approx(2.0, rel=0.01)


@pytest.fixture(scope="module")
def small_budget():
    return bg.budget(sp.DEFAULT_DESIGN, REQ, "common", samples=1024, seed=4, trials=4000,
                     n_jobs=1)


def test_budget_table_is_consistent(small_budget):
    t = small_budget.table
    assert list(t.index) == ["dx_m", "dy_m", "dh1_m", "dh_m", "pixel_px"]
    assert np.sqrt((t["allocation"] ** 2).sum()) == pytest.approx(3.0, rel=1e-12)
    assert t["share"].sum() == pytest.approx(1.0)
    assert (t["ST"] + t["ST_conf"] >= t["S1"] - t["S1_conf"]).all()
    assert t.loc["pixel_px", "distribution"] == "normal σ 0.3 px"
    np.testing.assert_allclose(t["allowed_scale"], t["scale"] * t["allocation"] / t["alone"])
    assert small_budget.total["verdict"] == "meets"


def test_sobol_ranking_agrees_with_the_sources_alone(small_budget):
    """Two independent methods, SALib on a QMC sample of the model and the study runner with
    one source at a time, must agree on which source dominates."""
    t = small_budget.table
    assert t["ST"].idxmax() == t["alone"].idxmax()


def test_budget_outputs(small_budget, tmp_path):
    files = budget_report.write_budget([small_budget], tmp_path)
    assert {f.name for f in files} == {"budget-common.csv", "budget.png", "report.md"}
    assert (tmp_path / "budget.png").stat().st_size < 200_000
    report = (tmp_path / "report.md").read_text()
    assert "Allocation rule" in report and "Largest total-order share" in report


def test_cli_budget(tmp_path):
    """A budget through the command line (forked from a process with the libraries imported),
    and a refused knob in a fresh process of its own."""
    out = montecarlo_cli(
        "budget", "--limit", "3", "--samples", "256", "--trials", "1000", "--relations",
        "independent", "--point", "L_m=25", "--point", "H_m=10", "--point", "pixel_px=0.05",
        "--n-jobs", "1", "--out", tmp_path / "b", timeout=600)
    assert out.returncode == 0, out.stderr
    assert "pixel error independent" in out.stdout
    assert (tmp_path / "b" / "budget-independent.csv").exists()
    bad = subprocess.run([sys.executable, "-m", "montecarlo", "budget", "--limit", "3",
                          "--point", "Q_m=1", "--out", str(tmp_path / "c")],
                         capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "error: --point Q_m: unknown knob; choose from L_m, H_m, pixel_px, survey_m, scale_m"]
    assert not (tmp_path / "c").exists()


def test_bootstrap_level_is_the_requested_one():
    """SALib reports half-widths z * sd with z = Phi^-1(0.5 + level/2): doubling the
    normal quantile doubles the interval for the same resamples and seed."""
    problem, model, _ = linear_problem()
    lo = bg.sobol_indices(problem, model, 256, rng=1, confidence=stats.norm.cdf(1) * 2 - 1)
    hi = bg.sobol_indices(problem, model, 256, rng=1, confidence=stats.norm.cdf(2) * 2 - 1)
    np.testing.assert_allclose(hi["S1_conf"], 2 * lo["S1_conf"], rtol=1e-9)


def test_cli_budget_from_sizing_answers(tmp_path, capsys):
    from montecarlo.cli import main

    answers = tmp_path / "answers.csv"
    answers.write_text("pixel_relation,L_m,pixel_px,value,status\n"
                       "common,60.0,0.25,2.9,ok\nindependent,,,,no design meets\n")
    out = tmp_path / "b"
    common = ["budget", "--limit", "3", "--samples", "128", "--trials", "500", "--n-jobs", "1",
              "--from-sizing", str(answers), "--out", str(out)]
    assert main([*common, "--relations", "common"]) == 0
    assert "design point: L_m = 60, pixel_px = 0.25" in capsys.readouterr().out
    assert main(common) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {answers}: row 3: no answer for pixel relation 'independent' "
                   "(nothing met the spec); leave it out with --relations"]
    answers.write_text("pixel_relation,L_m\ncommon,abc\n")
    assert main([*common, "--relations", "common"]) == 2
    assert f"{answers}: row 2: column L_m: not a number: 'abc'" in capsys.readouterr().err


@pytest.mark.parametrize("dist", [Distribution("triangular", 0.2, 0.5),
                                  Distribution("truncnormal", -0.1, 0.3, 1.2),
                                  Distribution("normal", 0.1, 0.2),
                                  Distribution("uniform", 0.0, 0.4)], ids=lambda d: d.kind)
def test_salib_draws_the_same_shapes_as_the_runner(dist):
    """SALib's quantile transform of u equals the runner's map of the same unit variate."""
    from SALib.util import scale_samples
    from scipy.special import ndtri

    name, bounds = bg._salib_dist("x", dist)
    u = np.linspace(0.001, 0.999, 99)[:, None]
    salib = scale_samples(u.copy(), {"num_vars": 1, "names": ["x"], "bounds": [bounds],
                                     "dists": [name]})[:, 0]
    unit = u[:, 0].copy() if dist.kind in ("uniform", "triangular") else ndtri(u[:, 0])
    a, b = (2.0 * dist.scale, dist.location - dist.scale) if dist.kind == "uniform" \
        else (dist.scale, dist.location)
    ours = a * (dist.standard(unit) if dist.kind not in ("uniform", "normal") else unit) + b
    np.testing.assert_allclose(salib, ours, rtol=1e-9, atol=1e-12)


def test_a_budget_refuses_shapes_it_cannot_allot():
    for kind in ("arcsine", "lognormal", "corners"):
        with pytest.raises(InputError, match=f"got {kind}"):
            bg._salib_dist("errors.dx_m", Distribution(kind, 0.0, 1.0, 0.5))
