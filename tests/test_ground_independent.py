"""``diagnose ground`` on data of a simulator written blind to this package.

``tests/independent/ground_blind.py`` was written by another author from the seed 000 text and
the CSV format (``tests/independent/ground_format.md``) only, never this package's modules, docs
or tests. Its conventions are its own reading of the paper (eq. 5's rotation order and signs,
the image axes of eqs. 1 and 4), its noise is its own, and so are its hidden effects: radial
distortion on focal-normalised coordinates, a shifted image centre, a focal-length error and a
projection centre away from the survey origin. Its files are read here exactly as the command
line reads them. Agreement therefore checks the conventions of the whole chain, not only the
fit.

Its world is flat (no earth curvature, straight rays) where the base model has both; at its
ranges (35-140 m) the difference is under 1e-5 rad, a few hundredths of the 0.3 px noise.
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
from tests.acceptance import check_coverage, check_not_inflated, slug
from tests.independent import ground_blind as gb

PIXEL_SIGMA, SURVEY_SIGMA = 0.3, 0.01
"""The noise of every data set below [px], [m]."""

EFFECTS = {  # hidden effect -> the effects a diagnosis may name for it
    "radial_k1": (-0.008, {("radial_distortion",)}),
    "principal_point_px": ((1.5, -1.0), {("principal_point",)}),
    "focal_scale": (0.003, {("focal_scale",)}),
    # a lever arm is minus a common shift of all targets: with l_y = 0 the two biases
    # (one parameter each) state it as well as the arm itself (docs/reference/discrepancy.md)
    "lever_arm_m": ((0.2, 0.0, 0.15), {("lever_arm",),
                                       ("target_lateral_bias", "target_height_bias"),
                                       ("target_height_bias", "target_lateral_bias")}),
}


def _diagnosis(tmp_path, angles, seed, effects=None, fov=(90.0, 90.0), pixels=(512, 512),
               pixel_sigma=PIXEL_SIGMA, survey_sigma=SURVEY_SIGMA,
               refraction_k=ge.STANDARD_REFRACTION):
    """Simulate one data set blind, read its CSV as ``diagnose ground`` does and diagnose it."""
    stem = tmp_path / f"set{seed}"
    gb.simulate(stem, psi_deg=angles[0], theta_deg=angles[1], gamma_deg=angles[2],
                fov_deg=fov, pixels=pixels, pixel_sigma_px=pixel_sigma,
                survey_sigma_m=survey_sigma, seed=seed, effects=effects)
    camera = Camera.from_degrees(fov[0], fov[1], pixels[0], pixels[1])
    data = read_ground_csv(stem.with_suffix(".csv"), camera, ge.min_targets())
    return diagnose(ge.ground_problem(data, camera, max(pixel_sigma, 1e-3),
                                      max(survey_sigma, 1e-6), refraction_k))


def _angle_z(fit, angles_deg):
    """(estimate - truth) / sigma of psi, theta, gamma."""
    value = dict(zip(fit.names, fit.values, strict=True))
    sigma = dict(zip(fit.names, np.sqrt(np.diag(fit.covariance)), strict=True))
    return np.array([(value[k] - math.radians(a)) / sigma[k]
                     for k, a in zip(("psi", "theta", "gamma"), angles_deg, strict=True)])


@pytest.mark.parametrize(("angles", "fov", "pixels"), [
    ((30.0, 20.0, 10.0), (90.0, 90.0), (512, 512)),  # seed 000, section 1.4
    ((-12.0, 7.5, -25.0), (60.0, 45.0), (1280, 960)),
    ((3.0, -40.0, 55.0), (20.0, 15.0), (2048, 1536)),
])
def test_noise_free_blind_data_give_the_blind_angles(tmp_path, angles, fov, pixels):
    """Without noise the base model's fit returns the simulator's mounting angles to 1e-9 rad.
    The model runs with a refraction coefficient of 1, where a ray bends exactly with the
    earth (apparent height z - (1 - k) L^2 / (2 R) = z): the blind simulator's flat world.
    With the standard 0.13 the pitch differs by 3-6 microradians, the curvature the blind
    world lacks."""
    d = _diagnosis(tmp_path, angles, 1, fov=fov, pixels=pixels, pixel_sigma=0.0,
                   survey_sigma=0.0, refraction_k=1.0)
    value = dict(zip(d.before.names, d.before.values, strict=True))
    got = [value[k] for k in ("psi", "theta", "gamma")]
    np.testing.assert_allclose(got, np.radians(angles), rtol=0, atol=1e-9)
    assert d.named == []


@pytest.mark.parametrize("effect", list(EFFECTS))
def test_each_hidden_effect_of_the_blind_simulator_is_named(tmp_path, effect):
    value, expected = EFFECTS[effect]
    d = _diagnosis(tmp_path, (30.0, 20.0, 10.0), 3, effects={effect: value})
    assert tuple(d.named) in expected
    assert d.after.p_value > 0.01
    assert np.all(np.abs(_angle_z(d.after, (30.0, 20.0, 10.0))) < 4.0)


@pytest.mark.parametrize(("effect", "fov", "pixels"), [
    ("principal_point_px", (20.0, 15.0), (2048, 1536)),
    ("radial_k1", (20.0, 15.0), (2048, 1536)),
    ("principal_point_px", (60.0, 45.0), (1280, 960)),
])
def test_a_blind_effect_the_design_cannot_see_is_said_to_be_so(tmp_path, effect, fov, pixels):
    """On a narrow field an image-centre shift is a turn of the mounting (the diagnosis says
    it is absorbed by psi and theta), and k1 = -0.008 moves the field's edge by a quarter of a
    pixel (its minimal detectable bias, MDB, is above 0.008); on a 60 x 45 deg field the
    (1.5, -1.0) px shift is below its MDB. None is named, and the report's candidate table
    says why."""
    value, _ = EFFECTS[effect]
    d = _diagnosis(tmp_path, (30.0, 20.0, 10.0), 2000, effects={effect: value}, fov=fov,
                   pixels=pixels)
    assert d.named == []
    test = {t.name: t for t in d.steps[-1].tests}[
        "principal_point" if effect == "principal_point_px" else "radial_distortion"]
    if effect == "radial_k1":
        assert test.status == "testable" and test.mdb["k1"] > abs(value)
    elif fov[0] < 30.0:
        assert test.status == "absorbed" and test.reason == "absorbed by psi, theta"
    else:
        assert test.status == "testable"
        assert test.mdb["c_x"] > abs(value[0]) and test.mdb["c_z"] > abs(value[1])


def test_blind_null_data_name_nothing_and_fit_the_angles(tmp_path):
    """20 null sets at angles drawn around section 1.4's: nothing named (at alpha = 0.01 per
    set, the chance of more than two false alarms in 20 is 1e-3); of the 60 angle errors at
    most one beyond 3 sigma (expected 0.16; two or more 1.2 %) and none beyond 4.5 sigma
    (4e-4 for all 60)."""
    rng = np.random.default_rng(11)
    named, z = 0, []
    for i in range(20):
        angles = np.array([30.0, 20.0, 10.0]) + rng.uniform(-5.0, 5.0, 3)
        d = _diagnosis(tmp_path, angles, 100 + i)
        named += bool(d.named)
        z.extend(np.abs(_angle_z(d.after, angles)))
    assert named <= 2
    assert sum(v > 3.0 for v in z) <= 1 and max(z) < 4.5


@pytest.mark.slow
def test_blind_acceptance_at_100_sets_per_case(tmp_path, figures):
    """100 sets per case, angles drawn around section 1.4's (about a minute). Null: nothing named in
    at least 97 sets (alpha = 0.01: at most 3 false alarms is a 98 % bound), each angle within
    2 sigma in the binomial band of 95.45 % at 100 sets (87-100 at alpha 0.001, which bounds
    only from below) and its mean (error/sigma)^2 not below chi-square's 0.001 quantile (the
    bound from above: sigma not inflated). Each hidden effect
    named as expected in at least 95 sets, the angles then as without it."""
    rng = np.random.default_rng(5)
    for effect, (value, expected) in {"null": (None, {()}), **EFFECTS}.items():
        named, cover, z2 = collections.Counter(), np.zeros(3), np.zeros(3)
        for i in range(100):
            angles = np.array([30.0, 20.0, 10.0]) + rng.uniform(-5.0, 5.0, 3)
            d = _diagnosis(tmp_path, angles, 1000 + i,
                           effects=None if effect == "null" else {effect: value})
            named[tuple(d.named)] += 1
            z = _angle_z(d.after, angles)
            cover += np.abs(z) <= 2.0
            z2 += z**2
        hits = sum(n for k, n in named.items() if k in expected)
        print(f"{effect}: named as expected in {hits}/100 {dict(named)}; "
              f"angles within 2 sigma {cover.astype(int).tolist()}/100")
        figures.record(slug(effect, "named_as_expected"), hits / 100,
                       0.97 if effect == "null" else 0.95)
        assert hits >= (97 if effect == "null" else 95), (effect, named)
        for angle, inside, sum_z2 in zip(("psi", "theta", "gamma"), cover, z2, strict=True):
            check_coverage(figures, slug(effect, f"{angle}_within_2sigma"), int(inside), 100)
            check_not_inflated(figures, slug(effect, f"{angle}_mean_z2"), float(sum_z2), 100)
