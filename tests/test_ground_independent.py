"""``diagnose ground`` on data of a second simulator written without this package.

``tests/independent/ground_second.py`` was written by another author from the seed 000 text and
the brief beside it (``ground_second_brief.md``: the CSV format and a list of physical effects to
hide) only: never this package's modules, docs, tests, defaults or list of candidate effects.
Its conventions are its own reading of the paper (eq. 5's rotation order and signs, the image
axes of eqs. 1 and 4), its layout (targets at sensor height over 80 % of the horizontal field,
at 50 and 100 m, observed one after the other over 90 minutes), noise and hidden effects too.
Its files are read here exactly as the command line reads them, so agreement checks the
conventions of the whole chain, not only the fit.

Two of its hidden effects are among our candidates (an image-centre shift, a common error of the
surveyed heights); three are not: a focal length that drifts with time (thermal), fifth-order
radial distortion alone (no third-order term) and a centroid bias toward the image centre that
grows as 1/range. For those the right answer is "a misfit no candidate explains", or an effect
the data cannot tell from the hidden one; naming an unrelated effect is wrong.

Its world is flat (no earth curvature, straight rays): the model runs with a refraction
coefficient of 1, where the ray bends exactly with the earth.
"""

from __future__ import annotations

import collections
import math

import numpy as np
import pytest

from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.engine import diagnose
from montecarlo.geometry.camera import Camera
from montecarlo.io.ground_csv import read_ground_csv
from tests.acceptance import check_coverage, check_not_inflated, check_rate, slug
from tests.independent import ground_second as gs

PIXEL_SIGMA, SURVEY_SIGMA = 0.5, 0.03
"""The second simulator's own default noise [px], [m]."""

FLAT_WORLD = 1.0
"""Refraction coefficient at which the model's ray follows the earth: the simulator's flat world."""

IN_OUR_LIST = {  # hidden effect -> (value, the effects a diagnosis may name for it)
    "principal_point_px": ((6.0, -4.0), {("principal_point",)}),
    "height_datum_m": (0.6, {("target_height_bias",)}),
}

NOT_IN_OUR_LIST = {  # hidden effect -> (value, candidates that describe the same physics)
    "focal_drift_per_hour": (1e-2, set()),
    # k2 r^4 on a field whose normalised radius stays below 1 is close to k1 r^2: the radial
    # family is the right physics, the order is not
    "radial_k2": (-0.06, {"radial_distortion"}),
    "centroid_bias_px": (2.0, set()),
}


def _diagnosis(tmp_path, seed, fov=(90.0, 90.0), pixels=(512, 512), pixel_sigma=PIXEL_SIGMA,
               survey_sigma=SURVEY_SIGMA, **effects):
    """Simulate one data set, read its CSV as ``diagnose ground`` does and diagnose it."""
    out = gs.simulate_ground(str(tmp_path), f"set{seed}", seed=seed, fov_deg=fov, pixels=pixels,
                             pixel_sigma_px=pixel_sigma, survey_sigma_m=survey_sigma, **effects)
    camera = Camera.from_degrees(fov[0], fov[1], pixels[0], pixels[1])
    data = read_ground_csv(out["csv"], camera, ge.min_targets())
    return diagnose(ge.ground_problem(data, camera, max(pixel_sigma, 1e-3),
                                      max(survey_sigma, 1e-6), FLAT_WORLD))


def _angle_z(fit, angles_deg):
    """(estimate - truth) / sigma of psi, theta, gamma."""
    value = dict(zip(fit.names, fit.values, strict=True))
    sigma = dict(zip(fit.names, np.sqrt(np.diag(fit.covariance)), strict=True))
    return np.array([(value[k] - math.radians(a)) / sigma[k]
                     for k, a in zip(("psi", "theta", "gamma"), angles_deg, strict=True)])


@pytest.mark.parametrize(("angles", "fov", "pixels"), [
    ((30.0, 20.0, 10.0), (90.0, 90.0), (512, 512)),  # seed 000, section 1.4
    ((-12.0, 7.5, -25.0), (60.0, 45.0), (1280, 960)),
    ((3.0, 4.0, 55.0), (20.0, 15.0), (2048, 1536)),  # targets at sensor height: small pitch
])
def test_noise_free_second_data_give_its_angles(tmp_path, angles, fov, pixels):
    """Without noise the base model's fit returns the simulator's mounting angles to 1e-9 rad
    (measured: 6e-17) and names nothing: eq. 5, the image axes and the pinhole agree."""
    out = gs.simulate_ground(str(tmp_path), "clean", psi_deg=angles[0], theta_deg=angles[1],
                             gamma_deg=angles[2], fov_deg=fov, pixels=pixels,
                             pixel_sigma_px=0.0, survey_sigma_m=0.0)
    camera = Camera.from_degrees(fov[0], fov[1], pixels[0], pixels[1])
    d = diagnose(ge.ground_problem(read_ground_csv(out["csv"], camera, ge.min_targets()),
                                   camera, 1e-3, 1e-6, FLAT_WORLD))
    value = dict(zip(d.before.names, d.before.values, strict=True))
    got = [value[k] for k in ("psi", "theta", "gamma")]
    np.testing.assert_allclose(got, np.radians(angles), rtol=0, atol=1e-9)
    assert d.named == []


def test_second_null_data_name_nothing_and_fit_the_angles(tmp_path):
    """12 null sets: nothing named in at least 11 (alpha = 0.01 per set: two or more false
    alarms in 12 has probability 0.006), and of the 36 angle errors none beyond 4 sigma (the
    chance of one is 0.002)."""
    named, z = 0, []
    for seed in range(12):
        d = _diagnosis(tmp_path, 100 + seed)
        named += bool(d.named)
        z.extend(np.abs(_angle_z(d.after, (30.0, 20.0, 10.0))))
    assert named <= 1
    assert max(z) < 4.0


@pytest.mark.parametrize("effect", list(IN_OUR_LIST))
def test_a_hidden_effect_in_our_list_is_named(tmp_path, effect):
    """At about three times its minimal detectable bias (centre shift (6, -4) px, height datum
    0.6 m at 0.5 px and 3 cm) the effect is named in at least 4 of 5 sets, never another."""
    value, expected = IN_OUR_LIST[effect]
    named = collections.Counter(tuple(_diagnosis(tmp_path, 200 + s, **{effect: value}).named)
                                for s in range(5))
    assert sum(n for k, n in named.items() if k in expected) >= 4, named
    assert set(named) <= expected | {()}, named


def _wrongly_named(named: list[str], allowed: set[str]) -> bool:
    return bool(set(named) - allowed)


def test_fifth_order_distortion_is_reported_as_radial_distortion(tmp_path):
    """k2 = -0.06 alone (r' = r (1 + k2 r^4)): on this 90 deg field the base model's third-order
    term absorbs it within the noise, and the diagnosis names radial distortion (the right family,
    not the right order; its k1 is then an effective value), in each of 5 sets."""
    value, _ = NOT_IN_OUR_LIST["radial_k2"]
    for s in range(5):
        d = _diagnosis(tmp_path, 300 + s, radial_k2=value)
        assert "radial_distortion" in d.named
        assert d.after.p_value > 1e-4


@pytest.mark.xfail(strict=True, reason=(
    "the diagnosis names an effect of its list for a hidden effect outside it: a focal length "
    "drifting 1 %/h over a 90-minute left-to-right sweep is named as an image-centre shift or "
    "an aspect ratio, and the fit then passes; nothing tells it from a missing effect"))
def test_a_focal_drift_is_not_named_as_another_effect(tmp_path):
    value, allowed = NOT_IN_OUR_LIST["focal_drift_per_hour"]
    wrong = sum(_wrongly_named(_diagnosis(tmp_path, 400 + s, focal_drift_per_hour=value).named,
                               allowed) for s in range(5))
    assert wrong <= 1


@pytest.mark.xfail(strict=True, reason=(
    "a 2 px centroid bias toward the image centre, growing as 1/range, is named as a lever arm, "
    "a focal scale or target biases (it is a range-dependent shift the list has no term for)"))
def test_a_range_dependent_centroid_bias_is_not_named_as_another_effect(tmp_path):
    value, allowed = NOT_IN_OUR_LIST["centroid_bias_px"]
    wrong = sum(_wrongly_named(_diagnosis(tmp_path, 500 + s, centroid_bias_px=value).named,
                               allowed) for s in range(5))
    assert wrong <= 1


@pytest.mark.slow
def test_second_simulator_acceptance_at_100_sets_per_case(tmp_path, figures):
    """100 sets per case (``make acceptance``). Null: the share named within a one-sided
    binomial test of alpha = 0.01; each angle within 2 sigma in the two-sided binomial band of
    95.45 % and its mean (error/sigma)^2 not below its chi-square bound (a sigma not inflated).
    Effects of our list: named as expected in at least 90 %. Effects outside it: the shares
    named wrongly and left as a misfit are recorded without a bound (the validation record
    gives them); the strict expected failures above keep them visible."""
    for case, (value, expected) in {"null": (None, {()}), **IN_OUR_LIST}.items():
        named, inside, z2 = collections.Counter(), np.zeros(3, int), np.zeros(3)
        for s in range(100):
            effects = {} if case == "null" else {case: value}
            d = _diagnosis(tmp_path, 1000 + s, **effects)
            named[tuple(d.named)] += 1
            z = _angle_z(d.after, (30.0, 20.0, 10.0))
            inside += np.abs(z) <= 2.0
            z2 += z**2
        hits = sum(n for k, n in named.items() if k in expected)
        if case == "null":
            check_rate(figures, slug(case, "named_something"), 100 - hits, 100, at_most=0.01)
            for k, angle in enumerate(("psi", "theta", "gamma")):
                check_coverage(figures, slug(case, angle, "within_2sigma"), int(inside[k]), 100)
                check_not_inflated(figures, slug(case, angle, "mean_z2"), float(z2[k]), 100)
        else:
            check_rate(figures, slug(case, "named_as_expected"), hits, 100, at_least=0.9)
    for case, (value, allowed) in NOT_IN_OUR_LIST.items():
        wrong = misfit = 0
        for s in range(100):
            d = _diagnosis(tmp_path, 2000 + s, **{case: value})
            wrong += _wrongly_named(d.named, allowed)
            misfit += d.after.p_value < 0.01
        figures.record(slug(case, "named_wrongly"), wrong / 100)
        figures.record(slug(case, "misfit_left"), misfit / 100)
