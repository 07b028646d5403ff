"""Acceptance of ``auto`` noise: the stated 95 % interval holds the true sigma in the binomial
band of 95 % (two-sided), and on sets of at least 1,000 residuals the estimate is within 5 %
of the true sigma in at least 95 % of sets. Each set is simulated without an effect and
diagnosed as ``diagnose ... auto`` does it (:mod:`montecarlo.cli.noise_options`: the tests of
an estimated noise, the estimate from the final model). Slow: about 15 minutes of CPU.
"""

import math

import numpy as np
import pytest

from montecarlo.cli.noise_options import diagnose_collimation_auto, diagnose_ground_auto
from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.geometry.camera import Camera
from montecarlo.seed003 import model as col
from montecarlo.units import ARCSEC
from tests.acceptance import check_coverage

pytestmark = pytest.mark.slow

CAMERA = Camera.from_degrees(90.0, 90.0, 512, 512)
MOUNTING = {"psi": math.radians(30.0), "theta": math.radians(20.0),
            "gamma": math.radians(10.0)}
PIXEL, SURVEY = 0.3, 0.01  # [px], [m]


def _ground(grid, ranges, survey, sets, pixel="auto", survey_option=None, seed=0):
    """(estimates of every set, their number of residuals) on a ground layout."""
    layout = ge.field_layout(CAMERA, MOUNTING, ranges=ranges, grid=grid)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(sets):
        data = ge.simulate(layout, CAMERA, MOUNTING, PIXEL, survey, rng)
        _, _, found = diagnose_ground_auto(data, CAMERA, pixel,
                                           survey if survey_option is None else survey_option,
                                           0.13, 0.01)
        out.append({e.option: e for e in found})
    return out, 2 * layout.n


def _record_share(figures, name, estimates, option, truth):
    inside = sum(e[option].low <= truth <= e[option].high for e in estimates)
    print(f"{name}: {option} interval holds {truth:g} in {inside}/{len(estimates)}")
    return check_coverage(figures, name, inside, len(estimates), p=0.95)


def test_collimation_angle_sigma_interval_coverage(figures):
    """1,000 null sets of 7 + 7 mirrors (28 residuals), theodolite and INS 2″ each: the true
    angle sigma is 2√2″."""
    layout = ce.paper_mirrors(7, 7)
    rng = np.random.default_rng(3)
    noise = col.Noise(2 * ARCSEC, 2 * ARCSEC, 2 * ARCSEC, 2 * ARCSEC, 0.0)
    found = []
    for _ in range(1000):
        data = ce.simulate(layout, {"frame_heading": 0.5}, noise, rng)
        found.append(diagnose_collimation_auto(lambda s, x=data: ce.collimation_problem(x, s),
                                               0.01)[2][0])
    estimates = [{"angle_sigma_arcsec": e} for e in found]
    _record_share(figures, "collimation.angle_sigma.coverage_95", estimates,
                  "angle_sigma_arcsec", 2 * math.sqrt(2))


def test_ground_pixel_sigma_coverage_with_the_survey_known(figures):
    """600 null sets of 36 targets at 50 and 100 m (72 residuals), pixel 0.3 px, survey
    1 cm stated."""
    estimates, _ = _ground((6, 6), (50.0, 100.0), SURVEY, 600, seed=4)
    _record_share(figures, "ground.pixel_sigma.survey_known.coverage_95", estimates,
                  "pixel_sigma_px", PIXEL)


def test_ground_pixel_sigma_within_5_percent_on_1024_residuals(figures):
    """100 null sets of 512 targets (1,024 residuals): within 5 % of 0.3 px in >= 95 %
    (the chi-square(1,021) spread alone gives 97.7 %); the interval's coverage also."""
    estimates, n = _ground((32, 16), (50.0, 100.0), SURVEY, 100, seed=5)
    assert n >= 1000
    close = np.mean([abs(e["pixel_sigma_px"].value / PIXEL - 1) <= 0.05 for e in estimates])
    print(f"within 5 %: {close:.3f} of {len(estimates)} sets of {n} residuals")
    figures.record("ground.pixel_sigma.1024_residuals.within_5_percent", close, 0.95, None)
    assert close >= 0.95
    _record_share(figures, "ground.pixel_sigma.1024_residuals.coverage_95", estimates,
                  "pixel_sigma_px", PIXEL)


def test_ground_variance_components_coverage(figures):
    """600 null sets of 36 targets at 10 and 20 m, where a 1 cm survey error moves a target
    by about as many pixels as the 0.3 px noise: both sigma auto (REML), each component's
    Satterthwaite interval."""
    estimates, _ = _ground((6, 6), (10.0, 20.0), SURVEY, 600, survey_option="auto", seed=6)
    _record_share(figures, "ground.reml.pixel_sigma.coverage_95", estimates,
                  "pixel_sigma_px", PIXEL)
    _record_share(figures, "ground.reml.survey_sigma.coverage_95", estimates,
                  "survey_sigma_m", SURVEY)
