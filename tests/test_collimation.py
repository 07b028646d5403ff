"""Seed 003 autocollimator-INS axis calibration: model, fit, Figs. 3-6, study hook."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.io.collimation_csv import MirrorData, read_mirror_csv, write_mirror_csv
from montecarlo.seed003 import figures as figs
from montecarlo.seed003 import fit as cf
from montecarlo.seed003 import model as col
from montecarlo.systems import collimation as sc
from montecarlo.units import ARCSEC
from tests.acceptance import check_coverage

A = ARCSEC
rng = np.random.default_rng(3003)


def test_attitude_matrix_is_scipy_zxy_with_negated_heading():
    """C_b^n = Rotation.from_euler('ZXY', [-heading, pitch, roll]).as_matrix(); round trip."""
    h = rng.uniform(-np.pi, np.pi, 500)
    p = rng.uniform(-1.5, 1.5, 500)
    r = rng.uniform(-np.pi, np.pi, 500)
    C = col.attitude_matrix(h, p, r)
    ref = Rotation.from_euler("ZXY", np.stack([-h, p, r], -1)).as_matrix()
    np.testing.assert_allclose(C, ref, atol=1e-15)
    for got, want in zip(col.attitude_angles(C), (h, p, r), strict=True):
        np.testing.assert_allclose(col.wrap(got - want), 0.0, atol=1e-12)


def test_direction_is_the_ins_axis_and_round_trips():
    """The second column of C_b^n is direction(heading, pitch) (heading clockwise from y)."""
    h, p = rng.uniform(-np.pi, np.pi, 100), rng.uniform(-1.5, 1.5, 100)
    np.testing.assert_allclose(col.attitude_matrix(h, p, 0.7)[..., :, 1], col.direction(h, p),
                               atol=1e-15)
    np.testing.assert_allclose(col.direction(np.pi / 2, 0.0), [1.0, 0.0, 0.0], atol=1e-16)
    az, el = col.azimuth_elevation(col.direction(h, p))
    np.testing.assert_allclose(col.wrap(az - h), 0.0, atol=1e-12)
    np.testing.assert_allclose(el, p, atol=1e-12)


def _random_params(n):
    return {"axis_az": rng.normal(0, 0.01, n), "axis_el": rng.normal(0, 0.01, n),
            "frame_heading": rng.uniform(-np.pi, np.pi, n),
            "frame_tilt_x": rng.normal(0, 1e-3, n), "frame_tilt_y": rng.normal(0, 1e-3, n)}


def test_predicted_attitude_autocollimates():
    """The predicted INS attitude turns the optical axis exactly onto the mirror normal."""
    n = 1000
    params = _random_params(n)
    az, el = rng.uniform(-np.pi, np.pi, n), rng.uniform(-1.2, 1.2, n)
    roll = rng.uniform(-0.5, 0.5, n)
    heading, pitch = col.predict_readings(params, az, el, roll)
    u = col.direction(params["axis_az"], params["axis_el"])
    axis_n = np.einsum("nij,nj->ni", col.attitude_matrix(heading, pitch, roll), u)
    w = Rotation.from_euler("ZXY", np.stack([-params["frame_heading"], params["frame_tilt_x"],
                                             params["frame_tilt_y"]], -1)).apply(
        col.direction(az, el))
    np.testing.assert_allclose(axis_n, w, atol=1e-14)


def test_readings_agree_with_an_independent_numerical_solve():
    """Heading and pitch of the closed form = a numerical solve of "the optical axis, turned by
    the INS attitude (scipy, Z-X-Y with yaw = -heading), lies along the mirror normal", written
    here without the module's direction or attitude functions."""
    from scipy.optimize import least_squares

    def unit(az, el):
        return np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])

    local = np.random.default_rng(11)
    for _ in range(20):
        gamma, lam = local.uniform(-0.02, 0.02, 2)
        az, el, roll = local.uniform(-3.0, 3.0), local.uniform(-1.0, 1.0), local.uniform(-0.5, 0.5)
        frame = local.uniform(-3.0, 3.0)
        target = Rotation.from_euler("Z", -frame).apply(unit(az, el))
        u = unit(gamma, lam)

        def miss(x, u=u, target=target, roll=roll):
            return Rotation.from_euler("ZXY", [-x[0], x[1], roll]).apply(u) - target

        guess = np.array([az + frame, el])
        solved = least_squares(miss, guess, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        heading, pitch = col.predict_readings({"axis_az": gamma, "axis_el": lam,
                                               "frame_heading": frame}, az, el, roll)
        assert col.wrap(heading - solved[0]) == pytest.approx(0.0, abs=1e-10)
        assert pitch == pytest.approx(solved[1], abs=1e-10)


def test_analytic_limits():
    """lambda only: pitch = el - lambda, heading = az + h0. gamma only: the closed forms."""
    az, el = np.radians([0.0, 40.0, 170.0]), np.radians([0.0, 30.0, 60.0])
    h0, lam, gam = 0.4, 0.002, 0.003
    heading, pitch = col.predict_readings({"axis_el": lam, "frame_heading": h0}, az, el)
    np.testing.assert_allclose(pitch, el - lam, atol=1e-15)
    np.testing.assert_allclose(col.wrap(heading - az - h0), 0.0, atol=1e-15)
    heading, pitch = col.predict_readings({"axis_az": gam, "frame_heading": h0}, az, el)
    theta = np.arcsin(np.sin(el) / np.cos(gam))
    np.testing.assert_allclose(pitch, theta, atol=1e-15)
    expected = az + h0 - np.arctan(np.tan(gam) / np.cos(theta))
    np.testing.assert_allclose(col.wrap(heading - expected), 0.0, atol=1e-15)


def test_roll_of_90_degrees_turns_azimuth_offset_into_pitch():
    """Rolled right side down by 90 deg, an optical axis gamma to the right points gamma down."""
    gam = 0.004
    heading, pitch = col.predict_readings({"axis_az": gam}, 0.3, 0.1, math.pi / 2)
    assert pitch == pytest.approx(0.1 + gam, abs=1e-15)
    assert heading == pytest.approx(0.3, abs=1e-15)


def _layout_readings(truth, roll=None):
    az, el, _ = col.paper_layout()
    heading, pitch = col.predict_readings(truth, az, el, 0.0 if roll is None else roll)
    return az, el, heading, pitch


@pytest.mark.parametrize("with_tilt", [False, True])
def test_noise_free_fit_recovers_the_truth(with_tilt):
    truth = {"axis_az": 0.1 * math.pi / 180, "axis_el": -0.05 * math.pi / 180,
             "frame_heading": 2.5, "frame_tilt_x": 3 * A if with_tilt else 0.0,
             "frame_tilt_y": -5 * A if with_tilt else 0.0}
    az, el, _ = col.paper_layout(7, 7)
    roll = rng.normal(0, 0.01, az.size)
    heading, pitch = col.predict_readings(truth, az, el, roll)
    effects = col.BASE_EFFECTS + (("frame_misalignment",) if with_tilt else ())
    f = cf.fit(az, el, heading, pitch, roll, sigma=2 * A, effects=effects)
    for k, v in f.params.items():
        assert col.wrap(v - truth[k]) == pytest.approx(0.0, abs=1e-6 * A), k
    assert np.abs(f.residuals).max() < 1e-6 * A
    assert f.passes[-1] < 0.01 * A


def test_corrected_readings_point_along_the_mirror_normals():
    truth = {"axis_az": 0.002, "axis_el": 0.001, "frame_heading": 0.3}
    az, el, heading, pitch = _layout_readings(truth)
    c_az, c_el, _ = col.correct_readings(heading, pitch, 0.0, truth["axis_az"], truth["axis_el"])
    np.testing.assert_allclose(col.wrap(c_az - az - 0.3), 0.0, atol=1e-14)
    np.testing.assert_allclose(c_el, el, atol=1e-14)
    consistency = cf.consistency_angles(truth, az, el, heading, pitch)
    assert consistency.max() < 1e-9 * A


def test_covariance_matches_the_linearised_design():
    """Small offsets: heading = az + h0 - gamma/cos(el), pitch = el - lambda (level mount)."""
    truth = {"axis_az": 20 * A, "axis_el": 20 * A, "frame_heading": 0.1}
    az, el, heading, pitch = _layout_readings(truth)
    sigma = 2.0 * A
    f = cf.fit(az, el, heading, pitch, sigma=sigma)
    m = az.size
    design = np.zeros((2 * m, 3))  # columns: frame_heading, axis_az, axis_el
    design[:m, 0] = 1.0
    design[:m, 1] = -1.0 / np.cos(el)
    design[m:, 2] = -1.0
    ref = sigma**2 * np.linalg.inv(design.T @ design)
    np.testing.assert_allclose(f.covariance, ref, rtol=1e-3, atol=1e-3 * ref.max())


def test_fit_statistics_match_the_injected_noise():
    """200 seeded trials: coverage of 2 sigma (in the binomial band of 95.45 % at 200 trials),
    chi2_red and error spread vs predicted sigma (3 standard errors of each for n = 200).
    """
    n = 200
    out = sc.run_trials({}, np.random.default_rng(11), n)
    for k in ("axis_az", "axis_el"):
        check_coverage(None, k, int(np.sum(out[f"{k}_within_2sigma"])), n)
        spread = np.std(out[f"{k}_error"]) / np.mean(out[f"{k}_sigma"])
        assert abs(spread - 1) < 3 / math.sqrt(2 * n)
    dof = 2 * 10 - 3
    assert abs(np.mean(out["chi2_red"]) - 1) < 3 * math.sqrt(2 / dof / n)


def test_not_separable_layouts_are_reported():
    az = np.radians([0.0, 30.0, 60.0, 90.0])
    el = np.zeros(4)
    heading, pitch = col.predict_readings({"axis_az": 1e-3}, az, el)
    with pytest.raises(cf.NotSeparable, match="axis_az"):
        cf.fit(az, el, heading, pitch)
    with pytest.raises(cf.NotSeparable, match="at least 2 mirrors"):
        cf.fit(az[:1], el[:1] + 0.3, heading[:1], pitch[:1])


def test_run_trials_is_deterministic_and_complete():
    a = sc.run_trials({"n_pitch": 3}, np.random.default_rng(5), 4)
    b = sc.run_trials({"n_pitch": 3}, np.random.default_rng(5), 4)
    assert set(a) == set(sc.METRICS)
    for k in a:
        assert a[k].shape == (4,) and a[k].dtype == np.float64
        np.testing.assert_array_equal(a[k], b[k])
    with pytest.raises(ValueError, match="unknown parameter"):
        sc.run_trials({"axis_azimuth": 0.0}, np.random.default_rng(5), 1)


def test_run_trials_flags_unseparable_layout_as_nan():
    out = sc.run_trials({"n_pitch": 0}, np.random.default_rng(5), 3)
    assert np.isnan(out["axis_az_error"]).all()


def test_unreported_roll_biases_the_fit():
    """A mount that rolls 1 deg while the fit assumes roll 0 leaves offsets*roll errors."""
    params = {"theodolite_sigma": 0.0, "ins_heading_sigma": 0.0, "ins_pitch_sigma": 0.0,
              "ins_roll_sigma": 0.0, "mount_roll_sigma": math.radians(1.0)}
    used = sc.run_trials({**params, "use_roll": 1}, np.random.default_rng(2), 3)
    assumed = sc.run_trials({**params, "use_roll": 0}, np.random.default_rng(2), 3)
    assert np.nanmax(used["axis_error_angle"]) < 1e-6 * A
    assert np.nanmax(assumed["axis_error_angle"]) > 0.1 * A


# ----------------------------------------------------------------- Figs. 3-6 and the text


def test_horizontal_pair_pitch_offset_gives_twice_lambda_at_180():
    """Seed 003, section 2: 'at alpha = 180 deg, delta beta is almost 2 lambda'."""
    lam = math.radians(0.1)
    da, db = figs.pair_deviation("horizontal", math.pi, axis_el=lam)
    assert db == pytest.approx(-2 * lam, rel=1e-12)
    assert abs(da) < 1e-12
    alpha = np.radians(np.linspace(0, 180, 37))
    _, db = figs.pair_deviation("horizontal", alpha, axis_el=lam)
    np.testing.assert_allclose(db, -lam * (1 - np.cos(alpha)), atol=lam**2)


def test_vertical_pair_azimuth_offset_at_60_degrees():
    """'At beta = 60 deg, delta beta is almost equal to gamma' holds for delta alpha instead."""
    gam = math.radians(0.1)
    da, db = figs.pair_deviation("vertical", math.radians(60), axis_az=gam)
    assert da == pytest.approx(-gam, rel=1e-4)
    assert abs(db) < 0.01 * gam
    beta = np.radians(np.linspace(0, 80, 17))
    da, _ = figs.pair_deviation("vertical", beta, axis_az=gam)
    np.testing.assert_allclose(da, -gam * (1 / np.cos(beta) - 1), atol=30 * gam**2)


@pytest.mark.parametrize(("kind", "offset"), [("horizontal", "axis_az"), ("vertical", "axis_el")])
def test_offsets_along_the_mirror_plane_leave_no_deviation(kind, offset):
    angle = np.radians(np.linspace(0, 85, 18))
    for view in ("body", "readings"):
        da, db = figs.pair_deviation(kind, angle, view=view, **{offset: math.radians(0.1)})
        assert np.abs(da).max() < 1e-12 and np.abs(db).max() < 1e-12


def test_body_view_matches_conjugated_mirror_rotation():
    """Independent reference: INS change = R_off M R_off^T (scipy), to second order in offsets."""
    off = math.radians(0.1)
    angle = np.radians(np.linspace(5, 80, 16))
    for kind, axis in (("horizontal", "z"), ("vertical", "x")):
        for gam, lam in ((off, 0.0), (0.0, off), (off, off)):
            r_off = Rotation.from_euler("ZX", [-gam, lam])
            mirror = Rotation.from_euler(axis, (-angle if axis == "z" else angle)[:, None])
            rel = (r_off * mirror * r_off.inv()).as_euler("ZXY")
            ref_da = -rel[:, 0] - (angle if kind == "horizontal" else 0)
            ref_db = rel[:, 1] - (angle if kind == "vertical" else 0)
            da, db = figs.pair_deviation(kind, angle, axis_az=gam, axis_el=lam)
            scale = 1 / np.cos(angle) ** 2 if kind == "vertical" else 1.0
            assert np.all(np.abs(da - ref_da) < 3 * off**2 * scale)
            assert np.all(np.abs(db - ref_db) < 3 * off**2 * scale)


def test_paper_statements_verdicts():
    rows = figs.paper_statements()
    verdicts = {(r["statement"], r["quantity"]): r["holds"] for r in rows}
    assert not verdicts[("at β = 60°, Δβ is almost equal to γ", "Δβ(60°) / γ")]
    assert verdicts[("(the same read as Δα)", "Δα(60°) / γ")]
    assert verdicts[("at α = 180°, Δβ is almost twice λ", "Δβ(180°) / λ")]
    assert sum(r["holds"] is False for r in rows) == 2
    # the azimuth part of the pitch-offset pair is the row above's claim, not one of its own
    assert verdicts[("(same)", "max |Δα| / λ")] is None


# ----------------------------------------------------------------- CSV


def test_csv_round_trip(tmp_path):
    az, el, sets = col.paper_layout(3, 2)
    data = col.simulate_readings({"axis_az": 1e-3, "frame_heading": 3.0}, az, el, col.Noise(),
                                 rng=1)
    path = tmp_path / "cal.csv"
    names = ("a", "b", "c", "d", "e")
    mirrors = MirrorData(names, tuple(sets.tolist()), data["theodolite_az"],
                         data["theodolite_el"], data["ins_az"], data["ins_el"], data["ins_roll"])
    write_mirror_csv(path, mirrors)
    got = read_mirror_csv(path)
    assert got.mirror == names and got.sets == tuple(sets.tolist())
    for key in ("theodolite_az", "theodolite_el", "ins_az", "ins_el", "ins_roll"):
        np.testing.assert_allclose(getattr(got, key), data[key], atol=1e-5 * A)
    write_mirror_csv(path, dataclasses.replace(mirrors, ins_roll=None))
    assert read_mirror_csv(path).ins_roll is None
