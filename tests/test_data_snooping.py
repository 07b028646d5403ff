"""Data snooping in the diagnosis: a wrong observation is named by its id and left out, an
effect named early and explained later by others is dropped, and null data stay clean."""

import dataclasses
import math

import numpy as np
import pytest

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.candidate_tests import wald_test
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.problem import outlier_effect, with_outliers
from montecarlo.geometry.camera import Camera
from montecarlo.systems import discrepancy as sd

CAM = Camera.from_degrees(90.0, 90.0, 512, 512)
MOUNT = dict(ge.DEFAULT_MOUNTING)
LAYOUT = sd.default_layout(CAM, MOUNT)
SIGMA = 0.3


def ground_data(seed, truth=MOUNT):
    return ge.simulate(LAYOUT, CAM, truth, SIGMA, 0.0, rng=seed)


def shifted(data, row, shift):
    pixels = data.pixels.copy()
    pixels[row] += shift
    return dataclasses.replace(data, pixels=pixels)


def test_a_shift_of_an_observation_moves_only_its_whitened_residuals():
    problem = with_outliers(ge.ground_problem(ground_data(1), CAM, SIGMA))
    effect = problem.effect("outlier:T05")
    base = problem.residuals(dict(problem.start))
    moved = problem.residuals({**problem.start, effect.parameters[0]: 2.0})
    diff = base - moved
    assert diff[8] == pytest.approx(2.0) and np.count_nonzero(diff) == 1
    batch = problem.residuals({effect.parameters[1]: np.array([[0.0], [3.0]])})
    assert batch.shape == (2, base.size) and batch[0, 9] - batch[1, 9] == pytest.approx(3.0)
    assert outlier_effect("A", (0, 1)).parameters == ("outlier:A[0]", "outlier:A[1]")


@pytest.mark.parametrize("seed", range(5))
def test_one_target_six_pixels_off_is_named_and_nothing_else(seed):
    data = shifted(ground_data(seed), 7, [6.0, 0.0])
    d = diagnose(ge.ground_problem(data, CAM, SIGMA))
    assert [t.name for t in d.outliers] == [f"outlier:{data.targets[7]}"]
    assert d.named == [] and not d.unexplained
    est = d.outliers[0].estimate
    assert est["outlier:T08[0]"] ** 2 + est["outlier:T08[1]"] ** 2 == pytest.approx(
        (6.0 / SIGMA) ** 2, rel=0.2)
    # the mounting is no longer pulled by the wrong target
    clean = fit_model(ge.ground_problem(ground_data(seed), CAM, SIGMA), ())
    for k in ("psi", "theta", "gamma"):
        assert abs(d.after.params[k] - clean.params[k]) < 3 * clean.stderr[k]


def test_two_wrong_targets_are_both_named():
    data = shifted(shifted(ground_data(11), 7, [6.0, 0.0]), 20, [0.0, -4.0])
    d = diagnose(ge.ground_problem(data, CAM, SIGMA))
    assert {t.name for t in d.outliers} == {"outlier:T08", "outlier:T21"} and d.named == []


def test_an_outlier_and_an_effect_together():
    truth = {**MOUNT, "k1": -0.008}
    data = shifted(ground_data(3, truth), 12, [0.0, 5.0])
    d = diagnose(ge.ground_problem(data, CAM, SIGMA))
    assert d.named == ["radial_distortion"]
    assert [t.name for t in d.outliers] == ["outlier:T13"]
    assert d.after.params["k1"] == pytest.approx(-0.008, abs=4 * d.after.stderr["k1"])


def test_a_theodolite_misreading_of_one_mirror_is_named():
    """20 arc-seconds on one azimuth reading (the stated noise is 2.83 per component)."""
    from montecarlo.seed003.model import Noise

    sigma = math.radians(2.83 / 3600)
    data = ce.simulate(ce.paper_mirrors(), {}, Noise(), rng=4)
    az = data.theodolite_az.copy()
    az[3] += math.radians(20 / 3600)
    d = diagnose(ce.collimation_problem(dataclasses.replace(data, theodolite_az=az), sigma))
    assert [t.name for t in d.outliers] == [f"outlier:{data.mirror[3]}"] and d.named == []


def test_null_data_flag_and_name_nothing_in_nearly_all_sets():
    flagged = sum(bool(diagnose(ge.ground_problem(ground_data(100 + s), CAM, SIGMA)).outliers
                       or diagnose(ge.ground_problem(ground_data(100 + s), CAM, SIGMA)).named)
                  for s in range(60))
    assert flagged <= 3  # alpha = 1 %: about 0.6 expected


def test_wald_test_of_a_fitted_effect():
    truth = {**MOUNT, "k1": -0.004}
    problem = ge.ground_problem(ground_data(2, truth), CAM, SIGMA)
    fit = fit_model(problem, ("radial_distortion",))
    T, dof, p = wald_test(fit, ("k1",))
    assert dof == 1 and pytest.approx((fit.params["k1"] / fit.stderr["k1"]) ** 2) == T
    assert p < 1e-6
    assert wald_test(fit, ("nothing",)) == (0.0, 0, 1.0)


def toy_problem(seed=2, n=20):
    """Linear toy: y = 1 + 3 b + 2.2 c + noise, with a candidate a along b + c (plus a little
    of its own): a explains most of the signal at first, b and c all of it."""
    from montecarlo.discrepancy.problem import Effect, Problem

    rng = np.random.default_rng(seed)
    cb, cc = rng.standard_normal(n), rng.standard_normal(n)
    ca = (cb + cc) / math.sqrt(2) + 0.2 * rng.standard_normal(n)
    y = 1.0 + 3.0 * cb + 2.2 * cc + rng.standard_normal(n)
    columns = {"a": ca, "b": cb, "c": cc}

    def residuals(values):
        v = {k: np.asarray(values.get(k, 0.0), float) for k in ("mu", *columns)}
        return y - v["mu"] - sum(v[k] * col for k, col in columns.items())

    effects = tuple(Effect(k, (k,), ((-10.0, 10.0),), (1e-3,)) for k in columns)
    return Problem("toy", Effect("base", ("mu",), ((-np.inf, np.inf),), (1e-3,)), effects,
                   residuals, {"mu": 0.0})


def test_an_effect_named_first_and_explained_by_later_ones_is_dropped():
    d = diagnose(toy_problem())
    assert d.steps[0].winner == "a"
    assert sorted(d.named) == ["b", "c"] and list(d.dropped) == ["a"]
    assert d.dropped["a"] >= 0.01
    assert "a" not in d.after.effects and not d.unexplained
    assert any(s.dropped for s in d.steps)


def test_an_effect_standing_in_for_another_is_swapped_for_it():
    """Another camera (60 x 45 deg, 0.2 px): radial distortion and a target height scale at
    2 MDB each. Step by step, focal scale comes first and stays (the two together fit);
    swapping it for radial distortion lowers Akaike's criterion."""
    from montecarlo.discrepancy.design import inject_at_mdb
    from montecarlo.tools.acceptance import OTHER_DESIGNS

    p = {**sd.GROUND_DEFAULTS, **OTHER_DESIGNS["ground"]}
    camera = Camera(p["fov_yaw"], p["fov_pitch"], p["n_x"], p["n_z"])
    truth = {k: float(p[k]) for k in ("psi", "theta", "gamma", *ge.TRUTH_KEYS)}
    layout = sd.default_layout(camera, truth)

    def exact(tr):
        return ge.exact_problem(layout, camera, tr, p["pixel_sigma"], p["survey_sigma"])

    for effect in ("radial_distortion", "target_height_scale"):
        truth = inject_at_mdb(exact, truth, effect, 2.0)
    data = ge.simulate(layout, camera, truth, p["pixel_sigma"], p["survey_sigma"],
                       np.random.default_rng(0))
    d = diagnose(ge.ground_problem(data, camera, p["pixel_sigma"], p["survey_sigma"]))
    assert [s.winner for s in d.steps][:2] == ["focal_scale", "target_height_scale"]
    assert [(o, i) for o, i, *_ in d.swaps] == [("focal_scale", "radial_distortion")]
    assert d.swaps[0][3] < d.swaps[0][2]
    assert sorted(d.named) == ["radial_distortion", "target_height_scale"]
    assert d.effect_result("radial_distortion")["swapped_in"] is True


def other_collimation(effects, seed, multiple=2.0):
    """A calibration on the collimation design of ``OTHER_DESIGNS`` (5 + 6 mirrors) with
    ``effects`` injected at ``multiple`` MDB each (each given the ones before)."""
    from montecarlo.seed003.model import Noise
    from montecarlo.tools.acceptance import OTHER_DESIGNS

    p = {**sd.COLLIMATION_DEFAULTS, **OTHER_DESIGNS["collimation"]}
    layout = ce.paper_mirrors(p["n_azimuth"], p["n_pitch"], p["azimuth_span"],
                              p["pitch_span"])
    noise = Noise(p["theodolite_sigma"], p["ins_sigma"], p["ins_sigma"], p["ins_sigma"])
    sigma = math.hypot(p["theodolite_sigma"], p["ins_sigma"])
    truth = sd._inject(lambda tr: ce.exact_problem(layout, tr, sigma),
                       {k: float(p[k]) for k in ("frame_heading", *ce.TRUTH_KEYS)},
                       {**p, "expected": ",".join(effects), "inject_mdb": multiple})
    return ce.collimation_problem(ce.simulate(layout, truth, noise, seed), sigma)


@pytest.mark.parametrize("seed", [506, 510, 521])
def test_two_effects_at_the_outermost_mirror_are_not_taken_for_a_wrong_reading(seed):
    """Frame tilt, INS scale factor and INS pitch bias on 11 mirrors: once the tilt is in,
    the outermost azimuth mirror carries the largest residual, which neither the scale factor
    nor the bias explains alone but the two together do; the effects are named, no mirror
    is flagged."""
    problem = other_collimation(("frame_misalignment", "ins_scale_factor", "ins_bias"), seed)
    d = diagnose(problem)
    assert d.outliers == [] and not d.unexplained
    assert {"frame_misalignment", "ins_scale_factor"} <= set(d.named) and len(d.named) == 3
    assert any("ins_bias" in g for g in d.groups)


@pytest.mark.parametrize("seed", [506, 509])
def test_an_axis_offset_standing_in_for_a_pitch_bias_is_swapped_for_it(seed):
    """Same three effects, seeds where the axis offset (2 parameters) could stand in for the
    INS pitch bias: the final model holds the pitch bias (1 active parameter, its heading
    part absorbed by the frame heading), named directly or swapped in for the axis offset
    with a lower Akaike criterion."""
    d = diagnose(other_collimation(("frame_misalignment", "ins_scale_factor", "ins_bias"),
                                   seed))
    assert [(o, i) for o, i, *_ in d.swaps] in ([], [("axis_misalignment", "ins_bias")])
    assert all(after < before for *_, before, after in d.swaps)
    assert sorted(d.named) == ["frame_misalignment", "ins_bias", "ins_scale_factor"]
    assert "ins_pitch_bias" in d.after.params and "ins_heading_bias" not in d.after.params


def test_a_pair_of_effects_explains_an_observation_only_when_it_is_needed_besides_it():
    """Linear picture: observation 0 (column e0) and two effects a = e0 + u, b = e0 - u
    (u orthogonal to e0, spread over the other observations). Neither effect alone explains
    a spike at observation 0, the pair does; the pair comes first only when the data also
    carry a signal along u that the observation cannot explain."""
    from montecarlo.discrepancy.candidate_tests import CandidateTest
    from montecarlo.discrepancy.confounding import effect_for_observation

    rng = np.random.default_rng(5)
    n = 30
    e0 = np.eye(n)[:, :1]
    u = np.r_[0.0, rng.standard_normal(n - 1)][:, None]
    u /= np.linalg.norm(u)

    def candidate(name, column, log_p):
        return CandidateTest(name, "testable", statistic=1.0, dof=1, log_p=log_p,
                             basis=column / np.linalg.norm(column), projected=column)

    observation = candidate("outlier:0", e0, -30.0)
    a, b = candidate("a", e0 + u, -20.0), candidate("b", e0 - u, -10.0)
    noise = 0.5 * rng.standard_normal(n)
    spike = 8.0 * e0[:, 0] + noise
    level = 0.01 / n
    assert effect_for_observation(observation, [a], spike, level) is None
    assert effect_for_observation(observation, [a, b], spike, level) is None
    systematic = spike + 6.0 * u[:, 0]
    assert effect_for_observation(observation, [b, a], systematic, level).name == "a"
    e1 = np.eye(n)[:, 1:2]  # a pair that does not reach observation 0 never explains it
    elsewhere = [candidate("c", e1 + u, -20.0), candidate("d", e1 - u, -10.0)]
    assert effect_for_observation(observation, elsewhere, systematic, level) is None
