"""Acceptance of the discrepancy workflow.

Fast tests: a few dozen data sets of the realistic layouts (36 targets over the field at 50 and
100 m; seed 003's 7 + 7 mirrors). Tolerances come from binomial tails: with a true rate of
1 % false naming, 3 or more of 40 happen with probability 0.8 %; with a true 95 % success rate,
fewer than 16 of 20 happen with probability 1.6 %.

Slow tests (``-m slow``): the full acceptance, 500 data sets per scenario through the study
runner (``python -m montecarlo.tools.acceptance`` prints the same table).
"""

import numpy as np
import pytest

from montecarlo.systems import discrepancy as sd
from montecarlo.tools import acceptance as acc
from tests.acceptance import check_coverage, slug


def rates(run_trials, n, seed, **params):
    out = run_trials({"diagnose": 1, **params}, np.random.default_rng(seed), n)
    return {k: np.nanmean(v) if np.isfinite(v).any() else np.nan for k, v in out.items()}, out


def test_ground_null_names_nothing_and_never_the_atmosphere():
    r, out = rates(sd.run_ground_trials, 40, 1)
    assert np.count_nonzero(out["named_any"]) <= 2
    assert r["named_watched"] == 0.0


def test_ground_effect_at_1p5_mdb_is_named():
    _, out = rates(sd.run_ground_trials, 20, 2, expected="radial_distortion", inject_mdb=1.5)
    assert np.count_nonzero(out["named_expected_or_group"]) >= 16
    assert np.count_nonzero(out["chi2_red_after_in_band"]) >= 16


def test_collimation_null_and_confounded_collimation():
    _, out = rates(sd.run_collimation_trials, 40, 3)
    assert np.count_nonzero(out["named_any"]) <= 2
    _, out = rates(sd.run_collimation_trials, 20, 4, expected="theodolite_collimation",
                   inject_mdb=1.5)
    assert np.count_nonzero(out["named_expected_or_group"]) >= 16


def test_scenarios_cover_every_testable_effect():
    labels = [s["label"] for s in acc.scenarios("ground")]
    assert labels[0] == "null"
    assert {"radial_distortion", "focal_scale", "drift", "lever_arm"} <= set(labels)
    assert not {"refraction", "detector_rotation"} & set(labels)
    labels = [s["label"] for s in acc.scenarios("collimation")]
    assert "paper" in labels and "paper+theodolite_collimation" not in labels


def test_the_focal_scale_of_the_confounded_pair_is_below_its_mdb_given_the_range_bias():
    """The robust ground row "focal_scale + target_range_bias": the focal scale is injected
    at 2 MDB of the base model; once the range bias is in, it is below its MDB there, and its
    own test (at its share of the detection family) rejects with probability below 0.8 (the
    power at which an MDB is defined)."""
    alone = acc.power_given("focal_scale", ())
    assert alone["injected"] == pytest.approx(2.0 * alone["mdb"], rel=1e-6)
    assert alone["lambda"] == pytest.approx(4.0 * alone["lambda0"], rel=1e-4)
    given = acc.power_given("focal_scale", ("target_range_bias",))
    assert given["injected"] == alone["injected"] < given["mdb"]
    # one parameter: the noncentrality scales with the square of the size
    assert given["lambda"] / given["lambda0"] == pytest.approx(
        (given["injected"] / given["mdb"]) ** 2, rel=1e-4)
    assert 0.55 < given["power"] < 0.75


@pytest.mark.slow
@pytest.mark.parametrize("system", ["ground", "collimation"])
def test_full_acceptance(system, figures):
    """300 trials a scenario. The share of the named effect's parameters within 2 sigma is bounded
    from both sides by the binomial band of 95.45 % at the number of trials it was named in (one
    Bernoulli per trial: the mean of a trial's correlated parameters varies no more). Every
    scenario's figures are recorded before the test fails on any of them."""
    table = acc.run(system, trials=300, seed=2024, n_jobs=2)
    print("\n" + acc.to_markdown(table))
    null = table[table.scenario == "null"].iloc[0]
    assert null.trials >= 300
    if system == "ground":
        assert (table.named_watched == 0).all()  # refraction never named
    figures.record(slug(system, "null", "named_any"), null.named_any, None, 0.05)
    failed = [] if null.named_any <= 0.05 else [f"null named {null.named_any:.3f}"]
    for r in table[table.scenario != "null"].itertuples():
        name = slug(system, r.scenario)
        figures.record(f"{name}.named_or_group", r.named_or_group, 0.90)
        figures.record(f"{name}.after_in_band", r.after_in_band, 0.90)
        failed += [f"{r.scenario} {what} {value:.3f}" for what, value in (
            ("named or group", r.named_or_group), ("after in band", r.after_in_band))
            if value < 0.90]
        named = round(r.named_expected * r.trials)
        try:
            check_coverage(figures, f"{name}.within_2sigma", round(r.within_2sigma * named),
                           named)
        except AssertionError as e:
            failed.append(str(e))
    assert not failed, failed


def physics_case(label):
    case = next(c for c in acc.physics_scenarios() if c["label"] == label)
    return {k: v for k, v in case.items() if k not in ("label", "named")}


def test_long_ranges_name_no_refraction_for_the_curvature():
    """Null data at 0.5-3 km on a 30 deg camera: before curvature was in the base model a
    negative refraction was named in 70 % of such data sets; 3 or more of 30 at a true 1 %
    happen with probability 0.3 %."""
    _, out = rates(sd.run_ground_trials, 30, 5, **physics_case("null, 0.5-3 km"))
    assert np.count_nonzero(out["named_any"]) <= 2


@pytest.mark.slow
def test_long_range_acceptance(figures):
    table = acc.run("ground", trials=200, seed=2024, n_jobs=2, cases=acc.physics_scenarios())
    print("\n" + acc.to_markdown(table))
    for r in table.itertuples():
        name = slug(r.scenario)
        if r.scenario.startswith("null"):
            figures.record(f"{name}.named_any", r.named_any, None, 0.02)
            assert r.named_any <= 0.02, r.scenario
        else:
            figures.record(f"{name}.named_expected", r.named_expected, 0.90)
            assert r.named_expected >= 0.90, r.scenario
            named = round(r.named_expected * r.trials)
            check_coverage(figures, f"{name}.within_2sigma", round(r.within_2sigma * named),
                           named)
