"""Seed 003's one-calibration fit against values derived by hand: degrees of freedom, the
weighting of heading and pitch, the a-posteriori sigma and the per-mirror consistency angle."""

import math

import numpy as np
import pytest

from montecarlo.seed003 import fit as cf
from montecarlo.seed003 import model as col
from montecarlo.units import ARCSEC

A = ARCSEC


def test_two_mirrors_at_two_elevations_are_the_fewest_for_three_parameters():
    """frame_heading, gamma, lambda: 3 parameters; 2 mirrors give 4 readings, dof 1 (gamma is
    seen through 1/cos el, so the two mirrors need different elevations); 1 mirror is refused
    with the counts written out."""
    truth = {"axis_az": 300 * A, "axis_el": -200 * A, "frame_heading": 1.2}
    az, el = np.array([0.0, 0.5]), np.array([0.1, 0.7])
    heading, pitch = col.predict_readings(truth, az, el)
    f = cf.fit(az, el, heading, pitch, sigma=2 * A)
    assert f.dof == 1 and cf.min_mirrors(3) == 2 and cf.min_mirrors(5) == 3
    for k, v in truth.items():
        assert f.params[k] == pytest.approx(v, abs=1e-6 * A), k
    with pytest.raises(cf.NotSeparable,
                       match=r"^1 mirrors give 2 readings; 3 parameters need at least 2 mirrors$"):
        cf.fit(az[:1], el[:1], heading[:1], pitch[:1])
    az10, el10, _ = col.paper_layout()
    h10, p10 = col.predict_readings(truth, az10, el10)
    assert cf.fit(az10, el10, h10, p10).dof == 17  # 20 readings, 3 parameters


def _design(el):
    """Linearised design of heading = az + h0 - gamma / cos el, pitch = el - lambda (level
    mount, small offsets): columns frame_heading, axis_az, axis_el."""
    m = el.size
    X = np.zeros((2 * m, 3))
    X[:m, 0] = 1.0
    X[:m, 1] = -1.0 / np.cos(el)
    X[m:, 2] = -1.0
    return X


def test_heading_and_pitch_are_weighted_by_their_own_sigma():
    """sigma = (1", 7"): the covariance is ``(X' W X)^-1`` with W = diag(1/sigma_h^2 for the
    headings, 1/sigma_p^2 for the pitches) of the linearised design (to 1e-3, the size of the
    linearisation error for offsets of 20")."""
    truth = {"axis_az": 20 * A, "axis_el": 20 * A, "frame_heading": 0.1}
    az, el, _ = col.paper_layout()
    heading, pitch = col.predict_readings(truth, az, el)
    s_h, s_p = 1 * A, 7 * A
    f = cf.fit(az, el, heading, pitch, sigma=(s_h, s_p))
    X = _design(el)
    w = np.concatenate([np.full(el.size, s_h ** -2), np.full(el.size, s_p ** -2)])
    ref = np.linalg.inv(X.T @ (w[:, None] * X))
    np.testing.assert_allclose(f.covariance, ref, rtol=1e-3, atol=1e-3 * ref.max())
    assert f.sigma == (s_h, s_p) and f.sigma_source == "given"
    # without the offsets, in radians (not whitened): pitch reads el - lambda, so reading minus
    # model is -lambda = -20"; the headings -gamma / cos el less their mean (the frame heading
    # absorbs the mean); both to second order, (|gamma| + |lambda|)^2 / cos^2 60deg = 0.03"
    second = (40 * A) ** 2 / math.cos(math.radians(60.0)) ** 2
    np.testing.assert_allclose(f.residuals_before[:, 1], -20 * A, atol=second)
    h = -20 * A / np.cos(el)
    np.testing.assert_allclose(f.residuals_before[:, 0], h - h.mean(), atol=second)


def test_a_posteriori_sigma_is_the_rms_residual_over_the_degrees_of_freedom():
    """sigma=None: equal weights, one sigma ``sqrt(sum r^2 / dof)`` over headings and pitches,
    and the covariance is ``s^2 (X'X)^-1``; the values are those of any equal given sigma,
    and chi2 with that sigma is the dof (to 1e-4: sigma comes from the last pass, fitted to the
    corrected readings, which weight the residuals very slightly differently)."""
    truth = {"axis_az": 40 * A, "axis_el": -30 * A, "frame_heading": -2.0}
    az, el, _ = col.paper_layout(7, 7)
    rng = np.random.default_rng(8)
    heading, pitch = col.predict_readings(truth, az, el)
    heading = heading + 3 * A * rng.standard_normal(az.size)
    pitch = pitch + 3 * A * rng.standard_normal(az.size)
    f = cf.fit(az, el, heading, pitch)
    s = math.sqrt(np.sum(f.residuals ** 2) / f.dof)
    assert f.dof == 2 * 14 - 3 and f.sigma_source == "a posteriori"
    assert f.sigma[0] == f.sigma[1] == pytest.approx(s, rel=1e-4)
    assert f.chi2 == pytest.approx(f.dof, rel=1e-4)
    X = _design(el)
    ref = s**2 * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(f.covariance, ref, rtol=1e-3, atol=1e-3 * ref.max())
    given = cf.fit(az, el, heading, pitch, sigma=5 * A)
    np.testing.assert_allclose(given.values, f.values, rtol=0, atol=1e-6 * A)
    # without the offsets (frame heading refitted) the pitch residuals are -lambda on average,
    # within 4 standard errors of a mean of 14 readings (4 x 3"/sqrt(14) = 3.2")
    assert np.mean(f.residuals_before[:, 1]) == pytest.approx(30 * A, abs=4 * 3 * A / math.sqrt(14))


def test_consistency_angle_is_the_offset_size_at_every_mirror():
    """Readings of an INS whose optical axis is its own axis (no offsets, rolled mounts), checked
    against offsets gamma, lambda: the INS attitude C puts e_y on each mirror normal w, so the
    angle between ``C u`` and w is the angle between u and e_y, ``arccos(cos gamma cos lambda)``,
    at every mirror whatever its roll."""
    az, el, _ = col.paper_layout()
    roll = np.linspace(-0.3, 0.3, az.size)
    heading, pitch = col.predict_readings({"frame_heading": 0.4}, az, el, roll)
    g, lam = 300 * A, 400 * A
    angle = cf.consistency_angles({"axis_az": g, "axis_el": lam, "frame_heading": 0.4}, az, el,
                                  heading, pitch, roll)
    assert angle.shape == az.shape
    np.testing.assert_allclose(angle, math.acos(math.cos(g) * math.cos(lam)), rtol=1e-9)


def test_an_unseparable_layout_names_the_two_parameters_it_cannot_tell_apart():
    """Horizontal mirrors only: gamma moves every heading by -gamma / cos 0 = -gamma, exactly
    as the frame heading does, so the weakest combination is theirs (equal weights)."""
    az = np.radians([0.0, 30.0, 60.0, 90.0])
    heading, pitch = col.predict_readings({"axis_az": 1e-3}, az, np.zeros(4))
    with pytest.raises(cf.NotSeparable, match=r"^parameters (frame_heading and axis_az|axis_az "
                       r"and frame_heading) are not separable with these mirrors \(axis_az "
                       r"needs mirrors at different elevations\)$"):
        cf.fit(az, np.zeros(4), heading, pitch)


def test_the_axis_offsets_must_be_fitted():
    az, el, _ = col.paper_layout()
    with pytest.raises(ValueError, match=r"^effects must include 'axis_misalignment'$"):
        cf.fit(az, el, az, el, effects=("frame_heading",))


def test_the_first_pass_fits_the_whole_offset_and_the_next_nothing():
    """Noise-free readings of gamma = 300", lambda = -400": the first pass of fit -> correct ->
    refit finds the whole offset, of size hypot(300", 400") = 500"; the readings it corrects
    then leave less than the tolerance (0.01″), so the loop stops after the second pass."""
    truth = {"axis_az": 300 * A, "axis_el": -400 * A, "frame_heading": 0.3}
    az, el, _ = col.paper_layout()
    heading, pitch = col.predict_readings(truth, az, el)
    f = cf.fit(az, el, heading, pitch, sigma=2 * A)
    assert len(f.passes) == 2
    assert f.passes[0] == pytest.approx(500 * A, rel=1e-6)
    assert f.passes[1] < 0.01 * A


def test_residuals_before_are_those_of_the_reference_terms_weighted_as_given():
    """With the frame tilts fitted, the fit without the offsets (frame heading and tilts only)
    weights headings and pitches by the sigmas given, (1", 10"). Reference: scipy's
    least_squares of the same weighted residuals of the forward model, run here."""
    from scipy.optimize import least_squares

    az, el, _ = col.paper_layout(6, 6)
    rng = np.random.default_rng(21)
    truth = {"axis_az": 60 * A, "axis_el": -40 * A, "frame_heading": 0.2,
             "frame_tilt_x": 10 * A, "frame_tilt_y": -15 * A}
    heading, pitch = col.predict_readings(truth, az, el)
    heading = heading + 1 * A * rng.standard_normal(az.size)
    pitch = pitch + 10 * A * rng.standard_normal(az.size)
    f = cf.fit(az, el, heading, pitch, sigma=(1 * A, 10 * A),
               effects=(*col.BASE_EFFECTS, "frame_misalignment"))

    def weighted(x):
        h, p = col.predict_readings({"frame_heading": x[0], "frame_tilt_x": x[1],
                                     "frame_tilt_y": x[2]}, az, el)
        return np.r_[col.wrap(heading - h) / (1 * A), (pitch - p) / (10 * A)]

    x = least_squares(weighted, [0.2, 0.0, 0.0], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    r = weighted(x)
    np.testing.assert_allclose(f.residuals_before[:, 0], r[:az.size] * A, atol=1e-4 * A)
    np.testing.assert_allclose(f.residuals_before[:, 1], r[az.size:] * 10 * A, atol=1e-4 * A)


def _normalised_ratio(el):
    """Smallest over largest singular value of the linearised design (:func:`_design`) with
    each column scaled to unit length: the quantity the separability test compares with 1e-4."""
    X = _design(el)
    s = np.linalg.svd(X / np.linalg.norm(X, axis=0), compute_uv=False)
    return s[-1] / s[0]


def test_separability_is_the_singular_value_ratio_of_the_column_normalised_jacobian():
    """Three mirrors at elevations 0.5, 0.5 + d, 0.5 + 2d rad: frame_heading moves every
    heading by 1, gamma by -1/cos el, nearly the same column for small d. Normalised, the
    two columns at an angle theta give singular values sqrt(1 +- cos theta), the lambda column
    1, so the ratio is about theta / 2, linear in d: 7.6e-5 for d = 3.4e-4 (refused) and
    1.3e-4 for d = 6e-4 (accepted), either side of the stated 1e-4 by less than a factor
    sqrt(2) = s_max, the largest singular value, so a threshold scaled by it would move the
    verdict. No offsets (the fit's Jacobian at the solution is the linearised design)."""
    az = np.array([0.0, 1.0, 2.0])
    verdicts = []
    for d, lo, hi in ((3.4e-4, 0.72e-4, 0.8e-4), (6e-4, 1.3e-4, 1.4e-4)):
        el = 0.5 + d * np.arange(3)
        assert lo < _normalised_ratio(el) < hi
        heading, pitch = col.predict_readings({"frame_heading": 0.3}, az, el)
        try:
            f = cf.fit(az, el, heading, pitch, sigma=2 * A)
        except cf.NotSeparable as err:
            assert str(err).startswith("parameters frame_heading and axis_az are not separable")
            verdicts.append("refused")
        else:
            assert f.params["frame_heading"] == pytest.approx(0.3, abs=1e-9)
            verdicts.append("accepted")
    assert verdicts == ["refused", "accepted"]


@pytest.mark.parametrize("sigma", [(1.0, 1e5), (1e-5, 1.0), (1e5 * A, A)])
def test_separability_does_not_depend_on_how_heading_and_pitch_are_weighted(sigma):
    """The paper layout separates its three parameters (normalised ratio far above 1e-4);
    whitening by sigmas 1e5 apart scales the heading columns against the pitch column by 1e5,
    and some columns to norms below 1 (sigma 1e5 rad or 1 rad against unit Jacobian entries):
    the column normalisation removes both, so the verdict and the noise-free solution stay."""
    az, el, _ = col.paper_layout()
    assert _normalised_ratio(el) > 0.1
    truth = {"axis_az": 20 * A, "axis_el": -10 * A, "frame_heading": 0.1}
    heading, pitch = col.predict_readings(truth, az, el)
    f = cf.fit(az, el, heading, pitch, sigma=sigma)
    for k, v in truth.items():
        assert f.params[k] == pytest.approx(v, abs=1e-6 * A), k


def test_a_parameter_no_mirror_sees_is_refused():
    """Three mirrors on one pointing (az 0, el 0) with the frame tilts fitted: the pointing lies
    along one tilt axis, so that tilt moves no reading and its Jacobian column is exactly zero;
    the fit refuses it as not separable (no division of the zero column by its zero norm)."""
    az, el = np.zeros(3), np.zeros(3)
    heading, pitch = col.predict_readings({"frame_heading": 0.0}, az, el)
    with pytest.raises(cf.NotSeparable, match=r"^parameters .* are not separable"):
        cf.fit(az, el, heading, pitch, sigma=A,
               effects=(*col.BASE_EFFECTS, "frame_misalignment"))
