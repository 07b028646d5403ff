"""Confounded groups: the minimal parametrisation is fitted, the group and what would separate
its members are reported.

A linear toy gives closed forms: a 3-parameter candidate ``wide`` (columns u, v, w) contains a
1-parameter ``narrow`` (column u); ``other`` lies mostly in the span of v and w. Data made of
``narrow`` and ``other`` are explained by ``wide`` alone at the first step, and the chi-square
drops of numpy's lstsq decide independently whether the wide effect's further columns are
needed.
"""

import math

import numpy as np
import pytest
from scipy import stats

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.confounding import contained
from montecarlo.discrepancy.design import inject_at_mdb
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.problem import Effect, Problem
from montecarlo.discrepancy.view import GENERIC_SEPARATION, format_text, to_json
from montecarlo.geometry.camera import Camera
from montecarlo.seed003.model import Noise
from montecarlo.systems import discrepancy as sd
from montecarlo.units import ARCSEC

N = 60
RNG = np.random.default_rng(11)
U, V, W, E = RNG.standard_normal((4, N))
OTHER = (V + W) / math.sqrt(2.0) + 0.3 * E
HINT = "a second kind of data"


def toy(y):
    def residuals(values):
        p = {k: np.asarray(values.get(k, 0.0), float) for k in ("mu", "u", "v", "w", "n", "o")}
        pred = p["mu"] + (p["u"] + p["n"]) * U + p["v"] * V + p["w"] * W + p["o"] * OTHER
        return y - pred

    bound = ((-100.0, 100.0),)
    effects = (Effect("wide", ("u", "v", "w"), bound * 3, (1e-3,) * 3),
               Effect("narrow", ("n",), bound, (1e-3,)),
               Effect("other", ("o",), bound, (1e-3,)))
    return Problem("toy", Effect("base", ("mu",), ((-np.inf, np.inf),), (1e-3,)), effects,
                   residuals, {"mu": 0.0},
                   separating_data={frozenset(("narrow", "wide")): HINT})


def chi2_of(columns, y):
    A = np.column_stack([np.ones(N), *columns])
    r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    return float(r @ r)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_wide_effect_standing_in_for_two_is_replaced_by_its_minimal_member(seed):
    y = 3.0 * U + 1.5 * OTHER + np.random.default_rng(seed).standard_normal(N)
    # independent route: with narrow and other fitted, the wide effect's v, w are not needed
    drop = chi2_of([U, OTHER], y) - chi2_of([U, OTHER, V, W], y)
    assert stats.chi2.sf(drop, 2) > 0.01
    d = diagnose(toy(y))
    first = d.steps[0]
    assert min(first.tests, key=lambda t: t.log_p).name == "wide"  # the wide effect led
    tests = {t.name: t for t in first.tests}
    assert contained(tests["narrow"], tests["wide"]) and not contained(tests["wide"],
                                                                       tests["narrow"])
    assert first.winner == "narrow"
    assert sorted(d.named) == ["narrow", "other"] and not d.unexplained
    group = d.confounded[d.named.index("narrow")]
    assert group.members == ("narrow", "wide")
    assert group.correlation["wide"] == pytest.approx(1.0, abs=1e-9)
    assert group.separating_data == {"wide": HINT}


def test_a_wide_effect_needed_in_full_is_named_alone():
    y = 3.0 * U + 3.0 * V - 3.0 * W + np.random.default_rng(4).standard_normal(N)
    drop = chi2_of([U], y) - chi2_of([U, V, W], y)
    assert stats.chi2.sf(drop, 2) < 1e-6  # independent: narrow cannot carry it
    d = diagnose(toy(y))
    assert d.named == ["wide"]
    assert d.confounded[0].members == ("wide",)  # the data separate narrow from it
    assert "narrow" in d.absorbed


CAM = Camera.from_degrees(90.0, 90.0, 512, 512)
MOUNT = dict(ge.DEFAULT_MOUNTING)
LAYOUT = sd.default_layout(CAM, MOUNT)


def focal_and_range_bias():
    truth = dict(MOUNT)
    for effect in ("focal_scale", "target_range_bias"):
        truth = inject_at_mdb(lambda tr: ge.exact_problem(LAYOUT, CAM, tr, 0.3, 0.01), truth,
                              effect, 4.0)
    return truth


@pytest.mark.parametrize("seed", [0, 3, 6])
def test_focal_scale_and_range_bias_name_the_lever_arm_group(seed):
    """The seeds where a lever arm used to be named with two unneeded parameters."""
    truth = focal_and_range_bias()
    data = ge.simulate(LAYOUT, CAM, truth, 0.3, 0.01, seed)
    d = diagnose(ge.ground_problem(data, CAM, 0.3, 0.01))
    assert sorted(d.named) == ["focal_scale", "target_range_bias"]
    b_y = d.after.params["b_y"]
    assert abs(b_y - truth["b_y"]) < 3.0 * d.after.stderr["b_y"]
    report = to_json(d, ge.report_view(data, CAM, 0.3, 0.01), "data.csv")
    [group] = report["groups"]
    assert group["members"] == ["target_range_bias", "lever_arm"]
    assert group["fitted"] == "target_range_bias" and set(group["parameters"]) == {"b_y"}
    [pair] = group["cannot_separate"]
    assert pair["member"] == "lever_arm" and pair["correlation"] > 0.999
    assert pair["separating_data"] == ge.SEPARATING_DATA[frozenset(("lever_arm",
                                                                    "target_range_bias"))]
    assert ["target_range_bias", "lever_arm"] in report["confounded_groups"]
    text = format_text(report)
    assert "group [target_range_bias, lever_arm]: fitted as target_range_bias" in text
    assert "cannot separate lever_arm from target_range_bias" in text


def test_collimation_groups_use_the_generic_mechanism():
    """Seed 003's fixture without axis offsets: a theodolite collimation is named with its
    group; the collimation problem states no separating data, so the generic text is given."""
    layout = ce.paper_mirrors()
    sigma = math.hypot(2.0, 2.0) * ARCSEC
    truth = inject_at_mdb(lambda tr: ce.exact_problem(layout, tr, sigma),
                          {"frame_heading": math.radians(30.0)}, "theodolite_collimation", 3.0)
    noise = Noise(2.0 * ARCSEC, 2.0 * ARCSEC, 2.0 * ARCSEC, 2.0 * ARCSEC, 0.0)
    data = ce.simulate(layout, truth, noise, 1)
    d = diagnose(ce.collimation_problem(data, sigma))
    report = to_json(d, ce.report_view(data, sigma), "mirrors.csv")
    [group] = report["groups"]
    assert group["fitted"] == "theodolite_collimation"
    assert group["members"] == ["theodolite_collimation", "axis_misalignment"]
    assert group["cannot_separate"][0]["separating_data"] == GENERIC_SEPARATION


def test_the_text_says_which_p_value_a_named_effect_has_and_why_each_was_dropped():
    """The shipped ground diagnosis, edited: an effect swapped in at the end has its Wald test
    in the final model, not a Holm-adjusted identification p-value; an effect or observation
    left out without a p-value was not dropped for want of significance (the engine records
    NaN for an observation one effect replaced and for an adaptation that was singular)."""
    import json
    from pathlib import Path

    root = Path(__file__).parent.parent
    report = json.loads((root / "results/examples/discrepancy_ground/diagnosis.json").read_text())
    assert "identification p = 2.61e-152 (Holm)" in format_text(report)
    report["named_effects"][0]["swapped_in"] = True
    report["dropped_effects"] = [{"name": "target_range_bias", "p_value": 0.2},
                                 {"name": "outlier:T07", "p_value": math.nan},
                                 {"name": "lever_arm", "p_value": math.nan}]
    text = format_text(report)
    assert "(Wald test in the final model, swapped in at the end)" in text
    assert ("dropped: target_range_bias (named earlier, not significant given the others: "
            "p = 0.2, Holm)") in text
    assert "dropped: outlier:T07 (flagged earlier; one effect named instead explains it)" in text
    assert "dropped: lever_arm (its adapted model is singular with these data: not fitted)" \
        in text
