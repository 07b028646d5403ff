"""Requirement sizing: knobs and costs, Pareto corners, verdicts, the search and its confirmation.

The acceptance test: a sizing answer is confirmed by an independent run (another
seed) at the returned point, which meets the spec at the stated confidence, and at a point 10 %
cheaper in the limiting parameter, which fails.
"""

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from montecarlo.design import sizing as sz
from montecarlo.design import sizing_problem as sp
from montecarlo.design import sizing_report as sr
from montecarlo.errors import InputError
from tests.forked_cli import montecarlo_cli

REQ = sp.Requirement(limit=3.0)


def problem(*knobs, base=sp.DEFAULT_DESIGN, req=REQ):
    return sp.SizingProblem(base, req, tuple(knobs))


# --- knobs, costs, verdicts ----------------------------------------------------------------------

def test_doublings_count_from_the_cheap_end():
    L = sp.Knob("L_m", 25.0, 400.0)
    px = sp.Knob("pixel_px", 0.05, 1.0)
    assert L.doublings(25.0) == 0.0 and L.doublings(400.0) == pytest.approx(4.0)
    assert px.doublings(1.0) == 0.0 and px.doublings(0.25) == pytest.approx(2.0)
    assert list(L.levels(3)) == pytest.approx([25.0, 100.0, 400.0])
    assert list(px.levels(3)) == pytest.approx([1.0, math.sqrt(0.05), 0.05])
    assert L.cheaper_by(100.0) == pytest.approx(90.0)
    assert px.cheaper_by(0.2) == pytest.approx(0.22)
    assert not sp.Knob("H_m", 2.0, 2.0).free


@pytest.mark.parametrize("args", [("L", 1.0, 2.0), ("L_m", 2.0, 1.0), ("L_m", 0.0, 1.0),
                                  ("L_m", 1.0, 2.0, -1.0)])
def test_bad_knobs_are_input_errors(args):
    with pytest.raises(InputError):
        sp.Knob(*args)


@pytest.mark.parametrize("kwargs", [{"statistic": "max"}, {"confidence": 1.0}, {"limit": 0.0}])
def test_bad_requirements_are_input_errors(kwargs):
    with pytest.raises(InputError):
        sp.Requirement(**{"limit": 3.0, **kwargs})


def test_design_overrides_set_the_scale_of_each_distributed_source():
    base = {**sp.DEFAULT_DESIGN, "errors": {**sp.DEFAULT_DESIGN["errors"], "dy_m": 0.0,
                                            "dx_m": {"dist": "uniform", "bound": 0.1,
                                                     "center": 0.02}}}
    out = sp.design_overrides(base, {"L_m": 50.0, "pixel_px": 0.2, "survey_m": 0.03})
    assert out["geometry.L_m"] == 50.0
    assert out["errors.pixel_px"] == {"dist": "normal", "sigma": 0.2}
    assert out["errors.dx_m"] == {"dist": "uniform", "bound": 0.03, "center": 0.02}
    assert out["errors.dh1_m"] == {"dist": "uniform", "bound": 0.03}
    assert "errors.dy_m" not in out  # fixed: not an error scale
    fixed = {**base, "errors": {**base["errors"], "dh_m": 0.0}}
    with pytest.raises(InputError, match="scale_m"):
        problem(sp.Knob("scale_m", 0.001, 0.01), base=fixed)


def test_built_study_has_one_grid_point_per_design_point():
    p = problem(sp.Knob("L_m", 25.0, 400.0), sp.Knob("pixel_px", 0.1, 1.0))
    points = [{"L_m": 30.0, "pixel_px": 0.5}, {"L_m": 300.0, "pixel_px": 0.1}]
    study = sp.build_study(p, points, "independent", trials=100, seed=3, block_size=50)
    assert len(study.points) == 2
    for gp, pt in zip(study.points, points, strict=True):
        assert gp.config.geometry.L_m == pt["L_m"]
        assert gp.config.errors.pixel_px.sigma == pt["pixel_px"]
        assert gp.config.errors.pixel_relation == "independent"
    assert study.header.confidence == REQ.confidence
    assert [v for v, _ in study.metrics] == ["normalised"] * len(study.metrics)


def test_verdicts_use_the_interval_ends():
    v = sp.verdicts(np.array([2.0, 3.5, 2.9, 2.0, 2.9]), np.array([1.9, 3.1, 2.8, 1.9, 2.8]),
                    np.array([2.1, 3.9, 3.05, 2.1, np.nan]), np.array([0, 0, 0, 1, 0]), 3.0)
    assert list(v) == ["meets", "fails", "undecided", "invalid", "undecided"]


def test_replication_margin_is_sqrt2_half_widths():
    # hi = 2.9, half-width 0.05: needs 2.9 + 0.0707 <= limit
    assert sp.meets_with_margin(2.85, 2.9, 2.971)
    assert not sp.meets_with_margin(2.85, 2.9, 2.970)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3),
                          st.booleans()), min_size=1, max_size=30))
def test_pareto_minimal_is_the_set_of_undominated_feasible_points(rows):
    d = np.array([r[:3] for r in rows], float)
    feasible = np.array([r[3] for r in rows])
    mask = sz.pareto_minimal(d, feasible)

    def dominates(a, b):
        return np.all(a <= b) and np.any(a < b)

    for i in range(len(d)):
        dominated = any(feasible[j] and dominates(d[j], d[i]) for j in range(len(d)))
        assert mask[i] == (feasible[i] and not dominated)


def test_cheapest_by_weights_or_by_order():
    p = problem(sp.Knob("L_m", 25.0, 400.0), sp.Knob("pixel_px", 0.05, 1.0, weight=3.0))
    pts = pd.DataFrame({"L_m": [400.0, 50.0], "pixel_px": [1.0, 0.5]})  # costs 4 and 1 + 3
    assert p.cost(pts) == pytest.approx([4.0, 4.0])
    assert sz.cheapest(p, pts, ("pixel_px",)) == 0
    assert sz.cheapest(p, pts, ("L_m",)) == 1
    pts.loc[1, "pixel_px"] = 0.6
    assert sz.cheapest(p, pts, None) == 1


# --- the search ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def pixel_sizing():
    """Centroid accuracy needed for p95 of phi <= 3 mrad at 90 % (common pixel noise)."""
    p = problem(sp.Knob("pixel_px", 0.05, 1.0))
    opts = sp.SizingOptions(levels=3, trials=20000, seed=0, n_jobs=1, slice_levels=4)
    return sz.size(p, opts, relations=["common"], confirm_seed=1)


def test_answer_is_tight_and_confirmed_by_an_independent_run(pixel_sizing):
    """Fast acceptance: the answer meets (replication margin included) and the cheaper end of
    the final bracket does not; seed 1 confirms the answer and fails 10 % cheaper."""
    rs = pixel_sizing.relations["common"]
    a = rs.answer
    assert a["limiting"] == "pixel_px" and a["verdict"] == "meets"
    assert sp.meets_with_margin(a["value"], a["hi"], 3.0)
    assert a["bracket_bad"] / a["pixel_px"] <= 1.02 + 1e-12  # coarser and within tolerance
    conf = rs.confirmation.set_index("role")
    assert (conf["seed"] == 1).all()
    assert conf.loc["answer", "pixel_px"] == a["pixel_px"]
    assert conf.loc["answer", "verdict"] == "meets"
    assert conf.loc["cheaper", "pixel_px"] == pytest.approx(1.1 * a["pixel_px"])
    assert conf.loc["cheaper", "verdict"] == "fails"


def test_search_is_reproducible(pixel_sizing):
    p = pixel_sizing.problem
    again = sz.size(p, pixel_sizing.options, relations=["common"])
    pd.testing.assert_frame_equal(again.relations["common"].corners,
                                  pixel_sizing.relations["common"].corners)


def test_infeasible_bounds_are_reported_not_papered_over():
    """Independent noise at L = 100 m, H = 2 m: even 0.05 px misses 3 mrad
    (docs/reference/conventions.md: the
    error grows like sigma L / H)."""
    p = problem(sp.Knob("pixel_px", 0.05, 1.0))
    res = sz.size(p, sp.SizingOptions(levels=3, trials=2000, n_jobs=1, slice_levels=0),
                  relations=["independent"], confirm_seed=1)
    rs = res.relations["independent"]
    assert rs.answer is None and rs.confirmation is None
    assert (rs.grid["verdict"] == "fails").all()
    assert "no design within the bounds meets the spec" in sr.format_result(res)


def test_with_nothing_meeting_the_best_design_is_searched_between_grid_levels():
    """Independent noise, H = 5 m, 0.3 px: the error falls and then rises with range (leverage
    of the height difference at short range, sigma L / H at long range), so the best of the
    grid levels 10, 63, 400 m (L = 10 m) is not the best design."""
    p = problem(sp.Knob("L_m", 10.0, 400.0), sp.Knob("H_m", 5.0, 5.0),
                sp.Knob("pixel_px", 0.3, 0.3), req=sp.Requirement(limit=1.0))
    res = sz.size(p, sp.SizingOptions(levels=3, trials=4000, n_jobs=1, slice_levels=0),
                  relations=["independent"])
    rs = res.relations["independent"]
    assert rs.answer is None and rs.best is not None
    grid_best = rs.grid.loc[rs.grid["hi"].idxmin()]
    assert grid_best["L_m"] == 10.0
    assert 10.0 < rs.best["L_m"] < 63.0
    # better on an independent seed, not only on the one the search selected on
    assert rs.best["hi"] < 0.9 * grid_best["lo"]
    line = sz.evaluate(p, [{"L_m": v, "H_m": 5.0, "pixel_px": 0.3}
                           for v in np.geomspace(10.0, 63.0, 12)], "independent",
                       trials=4000, seed=99, n_jobs=1)
    assert rs.best["value"] < 1.05 * line["value"].min()
    assert "the best design found" in sr.format_result(res)
    assert res.answers()["best_L_m"].iloc[0] == rs.best["L_m"]


def test_outputs_are_written(pixel_sizing, tmp_path):
    files = sr.write_outputs(pixel_sizing, tmp_path)
    names = {f.name for f in files}
    assert {"report.md", "frontier.png", "answers.csv", "grid-common.csv",
            "corners-common.csv", "confirmation-common.csv"} <= names
    assert (tmp_path / "frontier.png").stat().st_size < 200_000
    report = (tmp_path / "report.md").read_text()
    assert "limiting parameter: pixel_px" in report
    answers = pd.read_csv(tmp_path / "answers.csv")
    assert answers.loc[0, "cheaper_confirm_verdict"] == "fails"


def test_confirm_seed_must_differ():
    with pytest.raises(InputError, match="confirm seed"):
        sz.size(problem(sp.Knob("pixel_px", 0.05, 1.0)), sp.SizingOptions(seed=4),
                confirm_seed=4)


# --- CLI -----------------------------------------------------------------------------------------

def run_cli(*args):
    return montecarlo_cli(*args)


def test_cli_size_writes_the_answer(tmp_path):
    out = run_cli("size", "--vary", "pixel_px=0.05:1", "--limit", "3", "--trials", "2000",
                  "--relations", "common", "--n-jobs", "1", "--out", str(tmp_path / "s"))
    assert out.returncode == 0, out.stderr
    assert "limiting parameter: pixel_px" in out.stdout
    assert "confirmation (seed 1, 8000 trials)" in out.stdout
    assert (tmp_path / "s" / "frontier.png").exists()


@pytest.mark.parametrize("args, message", [
    (("--vary", "L_m=25:x"), "--vary L_m: not a number"),
    (("--vary", "L_m=400:25"), "bounds must satisfy"),
    (("--vary", "pixel_px=0.1:1", "--weight", "L_m=2"), "--weight: L_m is not a varied knob"),
    (("--statistic", "max"), "invalid choice"),
    (("--study", "nonexistent.toml"), "no such study file"),
    (("--metric", "nonsense"), "spec.metric: unknown metric"),
])
def test_cli_size_bad_input_is_one_line_exit_2(args, message, tmp_path, capsys):
    from montecarlo.cli import main

    assert main(["size", "--limit", "3", "--out", str(tmp_path / "s"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "s").exists()


def test_cli_size_bad_input_as_subprocess(tmp_path):
    out = run_cli("size", "--vary", "L_m=400:25", "--limit", "3", "--out", str(tmp_path / "s"))
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        "error: knob L_m: bounds must satisfy 0 < lo <= hi (got 400..25)"]
    assert not (tmp_path / "s").exists()


# --- acceptance ----------------------------------------------------------------------------------

@pytest.mark.slow
def test_acceptance_sizing_confirmed_for_common_and_independent_noise():
    """Acceptance with four knobs (L, H, sigma_px, survey), 20000 trials per point: for
    each pixel relation the answer of search seed 0 (certified with its derived seed) meets in
    an independent run of seed 2024 with 80000 trials, and the point 10 % cheaper in its
    limiting knob fails there."""
    p = problem(*(sp.Knob(n, *sp.DEFAULT_BOUNDS[n]) for n in ("L_m", "H_m", "pixel_px",
                                                               "survey_m")))
    opts = sp.SizingOptions(levels=3, trials=20000, seed=0, slice_levels=0)
    res = sz.size(p, opts, confirm_seed=2024)
    print()
    print(sr.format_result(res))
    for rel, rs in res.relations.items():
        assert rs.answer is not None, rel
        conf = rs.confirmation.set_index("role")
        assert (conf["count"] == 80000).all()
        assert conf.loc["answer", "verdict"] == "meets", rel
        assert conf.loc["cheaper", "verdict"] == "fails", rel
