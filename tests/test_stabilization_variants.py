"""Seed 001 on recordings of other set-ups: an off-centre target, the camera on the pitch gimbal
(inner-gimbal mount), gyro rows that are interval means.

References are independent of the code under test: scipy's Rotation and quadrature, finite
differences of the exact kinematics, the pinhole's inverse, identities between the mounts, and
statistical tolerances derived from the injected noise.
"""

import dataclasses

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.spatial.transform import Rotation

from montecarlo.geometry.camera import pixels_from_direction
from montecarlo.seed001 import estimate as se
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import linear_model as lin
from montecarlo.seed001 import simulate as sim
from montecarlo.systems import stabilization as ss
from tests.acceptance import check_coverage, check_not_inflated, check_rate, slug
from tests.test_stabilization_estimation import BIAS, DELTA_G, DELTA_P, QUIET, ROCK, SETUP, D

TRIALS = 128  # per variant in the slow acceptance (`make acceptance`)
VARIANTS = [(m, s, tp) for m in kin.MOUNTS for s in sim.GYRO_SAMPLINGS
            for tp in [(0.0, 0.0), (240.0, -180.0)]]


def _truth(mount):
    t = [DELTA_P[0], DELTA_G[0], DELTA_G[1], DELTA_P[2] - DELTA_G[2], DELTA_P[1], *BIAS]
    return np.array(t + ([DELTA_G[2]] if mount == "inner-gimbal" else []))


def _setup(base, mount, sampling, target):
    return dataclasses.replace(base, mount=mount, gyro_sampling=sampling, target_px=target)


# --- the inner-gimbal mount ------------------------------------------------------------------


def test_inner_gimbal_camera_matrix_is_the_installation_after_the_gimbal():
    """Against scipy: passive R_y(dpy) R_x(dpx) R_z(dpz) R_x(eps) R_z(eta) is the transpose of
    the active intrinsic rotation z(eta), x(eps), z(dpz), x(dpx), y(dpy)."""
    eta, eps, (dpx, dpy, dpz) = 0.4, -0.3, (0.05, -0.02, 0.07)
    active = (Rotation.from_euler("ZX", [eta, eps])
              * Rotation.from_euler("ZXY", [dpz, dpx, dpy])).as_matrix()
    ours = kin.camera_matrix(eta, eps, [dpx, dpy, dpz], mount="inner-gimbal")
    np.testing.assert_allclose(ours, active.T, atol=1e-15)
    # without dpz the two mounts are the same rotation
    np.testing.assert_allclose(kin.camera_matrix(eta, eps, [dpx, dpy, 0.0], "inner-gimbal"),
                               kin.camera_matrix(eta, eps, [dpx, dpy, 0.0]), atol=1e-15)
    with pytest.raises(ValueError, match="mount"):
        kin.camera_matrix(eta, eps, 0.0, mount="outer")


def _inner_rate_xz(omega, eta, eps, x):
    """x, z camera rates, inner-gimbal mount, for X = [dpx, dgx, dgy, delta_z, dgz]."""
    dpx, dgx, dgy, dz, dgz = x
    eta_dot, eps_dot = kin.gimbal_rates(kin.measured_rate(omega, [dgx, dgy, dgz]), eta, eps)
    return kin.camera_rate(omega, eta, eps, eta_dot, eps_dot, [dpx, 0.0, dz + dgz],
                           mount="inner-gimbal")[..., [0, 2]]


def test_inner_gimbal_rate_model_matches_finite_differences_of_the_exact_rate():
    g = np.random.default_rng(3)
    omega, eta, eps = g.normal(scale=0.2, size=(50, 3)), g.uniform(-1, 1, 50), g.uniform(-1, 1, 50)
    H = lin.los_rate_matrix(omega, eta, eps, mount="inner-gimbal")
    assert H.shape == (50, 2, 5)
    h = 1e-7
    for j, e in enumerate(np.eye(5)):
        fd = (_inner_rate_xz(omega, eta, eps, h * e) - _inner_rate_xz(omega, eta, eps, -h * e))
        np.testing.assert_allclose(H[..., j], fd / (2 * h), atol=1e-8)
    # the dgz column is not zero: dpz no longer enters only through dpz - dgz
    assert np.abs(H[..., 4]).max() > 0.1 * np.abs(H[..., 3]).max()


def test_inner_gimbal_camera_rate_is_the_derivative_of_the_simulated_attitude():
    setup = sim.Setup(duration=2.0, rate=1000.0, aim_azimuth=20 * D, aim_pitch=10 * D,
                      mount="inner-gimbal")
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, rng=0)
    C = kin.camera_matrix(run.eta, run.eps, DELTA_P, "inner-gimbal") @ ROCK.attitude(run.t)
    h = 1.0 / setup.rate
    W = -(C[2:] - C[:-2]) / (2 * h) @ np.swapaxes(C[1:-1], -1, -2)
    fd = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1)
    omega = ROCK.body_rate(run.t[1:-1])
    eta_dot, eps_dot = kin.gimbal_rates(kin.measured_rate(omega, DELTA_G), run.eta[1:-1],
                                        run.eps[1:-1])
    model = kin.camera_rate(omega, run.eta[1:-1], run.eps[1:-1], eta_dot, eps_dot, DELTA_P,
                            "inner-gimbal")
    assert np.abs(fd - model).max() < 1e-5 * np.abs(model).max()


def test_inner_gimbal_separates_dpz_from_dgz():
    """Equal dpz and dgz no longer cancel; the observability has rank 5 of 5 angles."""
    a = 0.8 * D
    setup = dataclasses.replace(QUIET, mount="inner-gimbal")
    run = sim.simulate(ROCK, setup, [0.0, 0.0, a], [0.0, 0.0, a])
    assert run.los_error.max() > 1e-5
    patent = sim.simulate(ROCK, QUIET, [0.0, 0.0, a], [0.0, 0.0, a])
    assert patent.los_error.max() < 1e-9
    base = sim.simulate(ROCK, QUIET, 0.0, 0.0)
    obs = lin.observability(base, QUIET.camera, 0.1, mount="inner-gimbal")
    assert obs.rank == 5 and obs.raw_rank == 5 and obs.raw_null_space.shape == (0, 5)
    assert np.all(np.isfinite(obs.sigma))
    assert lin.observability(base, QUIET.camera, 0.1).raw_rank == 4


def test_encoder_angles_invert_pointing_angles():
    g = np.random.default_rng(4)
    angles = g.normal(scale=0.02, size=(6, 4))
    dgz = g.normal(scale=0.02, size=6)
    eta, eps = g.uniform(-2.0, 2.0, (6, 1)), g.uniform(-1.2, 1.2, (6, 1))
    los = sim.pointing_angles(eta, eps, angles[:, None, :], dgz[:, None])
    back = sim.encoder_angles(*los, angles, dgz, eta)
    np.testing.assert_allclose(back[0], eta, atol=1e-12)
    np.testing.assert_allclose(back[1], eps, atol=1e-12)


def test_inner_gimbal_compensation_with_the_truth_restores_a_perfect_loop():
    setup = dataclasses.replace(QUIET, mount="inner-gimbal")
    truth = _truth("inner-gimbal")
    comp = sim.Compensation(truth[:4], BIAS, delta_gz=truth[8], mount="inner-gimbal")
    before = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS)
    after = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, compensation=comp)
    assert before.los_error.max() > 1e-3
    assert after.los_error.max() < 1e-8
    # the patent's compensation leaves the inner-gimbal camera drifting
    wrong = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS,
                         compensation=sim.Compensation(truth[:4], BIAS))
    assert wrong.los_error.max() > 0.05 * before.los_error.max()


# --- gyro rows as interval means -------------------------------------------------------------


def test_interval_mean_rows_are_the_delta_angles_over_the_interval():
    setup = dataclasses.replace(QUIET, gyro_sampling="interval-mean")
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS)
    h = 1.0 / setup.rate
    for k in (0, 1, 517):
        for j in range(3):
            def rate(s, j=j):
                return kin.measured_rate(ROCK.body_rate(np.array([s]))[0], DELTA_G, BIAS)[j]
            mean = quad(rate, run.t[k] - h, run.t[k], epsabs=1e-14)[0] / h
            assert run.gyro[k, j] == pytest.approx(mean, rel=1e-10, abs=1e-14)


def test_rate_spline_of_interval_means_has_those_means():
    g = np.random.default_rng(5)
    t = np.cumsum(g.uniform(0.01, 0.02, 40))
    omega = g.normal(size=(40, 3))
    spline = se.rate_spline(t, omega, "interval-mean")
    edges = np.concatenate([[2 * t[0] - t[1]], t])
    angle = spline.antiderivative()(edges)
    np.testing.assert_allclose(np.diff(angle, axis=0) / np.diff(edges)[:, None], omega,
                               rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(se.rate_spline(t, omega)(t), omega, atol=1e-12)


def test_carrier_attitude_from_interval_means_matches_the_rocking():
    t = np.arange(0.0, 30.0, 0.01)
    mean = sim.interval_mean_rate(ROCK, t, 0.01, 0.0)
    R = se.carrier_attitude(t, mean, "interval-mean")
    C = ROCK.attitude(t)
    np.testing.assert_allclose(R, C[0] @ np.swapaxes(C, -1, -2), atol=1e-8)
    # read as point samples, the same rows are late by half an interval
    late = se.carrier_attitude(t, mean)
    assert np.abs(late - C[0] @ np.swapaxes(C, -1, -2)).max() > 1e-4


# --- the target and the predictor ------------------------------------------------------------


def test_target_direction_is_the_inverse_of_the_pinhole():
    C = Rotation.from_euler("ZXY", [0.3, -0.2, 0.1]).as_matrix()
    px = np.array([[300.0, 0.0], [-120.0, 250.0], [0.0, 0.0]])
    u = sim.target_direction(C, px, sim.DEFAULT_CAMERA)
    np.testing.assert_allclose(np.linalg.norm(u, axis=-1), 1.0, atol=1e-15)
    x, z = pixels_from_direction(u @ C.T, sim.DEFAULT_CAMERA)
    np.testing.assert_allclose(np.stack([x, z], -1), px, atol=1e-10)


def test_simulated_target_starts_at_the_given_image_position():
    run = sim.simulate(ROCK, dataclasses.replace(QUIET, target_px=(300.0, -40.0)), DELTA_G,
                       DELTA_P)
    np.testing.assert_allclose(run.los_px_true[0], [300.0, -40.0], atol=1e-9)
    assert run.los_error[0] < 1e-12
    centred = sim.simulate(ROCK, QUIET, DELTA_G, DELTA_P)
    np.testing.assert_allclose(run.los_error, centred.los_error, atol=1e-12)


@pytest.mark.parametrize(("mount", "sampling", "target"), VARIANTS)
def test_exact_predictor_reproduces_the_simulator(mount, sampling, target):
    setup = _setup(QUIET, mount, sampling, target)
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS)
    predicted = se.predict_los(run.t, run.gyro, run.eta, run.eps, _truth(mount), setup.camera,
                               target, mount=mount, gyro_sampling=sampling)
    assert np.abs(predicted - run.los_px_true).max() < 1e-4


def test_exact_jacobian_at_zero_is_the_inner_gimbal_first_order_model():
    run = sim.simulate(ROCK, dataclasses.replace(QUIET, mount="inner-gimbal"), 0.0, 0.0)
    J = se.los_jacobian(run.t, run.gyro, run.eta, run.eps, np.zeros(9), SETUP.camera,
                        mount="inner-gimbal")
    M = lin.drift_matrix(run.t, run.gyro, run.eta, run.eps, SETUP.camera, mount="inner-gimbal")
    for j, k in enumerate([0, 1, 2, 3, 8, 5, 6, 7]):
        assert np.abs(J[..., k] - M[..., j]).max() < 1e-3 * np.abs(M[..., j]).max()
    # the aim point's columns: the identity at the first sample
    np.testing.assert_allclose(J[0, :, 9:], np.eye(2), atol=1e-6)


# --- estimation ------------------------------------------------------------------------------


@pytest.mark.parametrize(("mount", "sampling"), [("patent", "point"),
                                                 ("inner-gimbal", "interval-mean")])
def test_off_centre_target_does_not_bias_noise_free_data(mount, sampling):
    """Image noise only weights the fit here: the data are exact, the error is the model's."""
    setup = _setup(QUIET, mount, sampling, (300.0, 0.0))
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS)
    est = se.estimate(run.t, run.gyro, run.eta, run.eps, run.los_px, setup.camera, 0.1,
                      mount=mount, gyro_sampling=sampling)
    assert est.converged
    assert np.all(np.abs(est.observable - _truth(mount)[:4]) < 0.05 * est.sigma[:4])
    np.testing.assert_allclose(est.aim_px, [300.0, 0.0], atol=1e-3)
    assert est.residual_rms < 1e-3


def test_residual_rms_is_the_image_noise_without_gyro_noise():
    """N = 1001 frames, 2 axes: the RMS of 2002 residuals with 11 fitted parameters is the
    image noise to a relative std of 1/sqrt(2 * 2002) = 1.6 %; bound 6 %."""
    setup = _setup(dataclasses.replace(SETUP, gyro_noise=0.0), "inner-gimbal", "point",
                   (-300.0, 0.0))
    est = se.estimate_record(sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=2), setup)
    assert est.residual_rms == pytest.approx(setup.image_noise, rel=0.06)


@pytest.mark.parametrize(("mount", "sampling", "target"), VARIANTS)
def test_estimate_recovers_the_angles_in_every_variant(mount, sampling, target):
    setup = _setup(SETUP, mount, sampling, target)
    est = se.estimate_record(sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=11), setup)
    assert est.converged and len(est.names) == est.values.shape[-1]
    z = (est.values - _truth(mount)) / est.sigma
    assert np.all(np.abs(z) < 3.0), z
    np.testing.assert_allclose(est.aim_px, target, atol=0.1)


def test_patent_model_on_inner_gimbal_data_misfits():
    """At an 18 deg pitch aim, reading inner-gimbal data with eq. (2) leaves a residual many
    times the image noise and biases the angles; the inner-gimbal model fits."""
    setup = dataclasses.replace(SETUP, mount="inner-gimbal", aim_pitch=18 * D)
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=4)
    right = se.estimate_record(run, setup)
    wrong = se.estimate_record(run, dataclasses.replace(setup, mount="patent"))
    assert right.residual_rms < 2 * setup.image_noise
    assert wrong.residual_rms > 5 * setup.image_noise
    z = (wrong.observable - _truth("patent")[:4]) / wrong.sigma[:4]
    assert np.abs(z).max() > 10


# --- Monte Carlo -----------------------------------------------------------------------------


def _coverage(out, k):
    names = ("dpx", "dgx", "dgy", "dz")
    return np.array([np.mean(np.abs(out[f"{q}_error"]) <= k * out[f"{q}_sigma"])
                     for q in names])


@pytest.mark.parametrize("params", [
    {"mount": "patent", "gyro_sampling": "interval-mean", "target_offset": 300.0},
    {"mount": "inner-gimbal", "gyro_sampling": "point", "target_offset": 300.0},
])
def test_small_monte_carlo_variants(params):
    """24 trials of 20 s at 50 Hz. With honest sigmas each combination is within 2 sigma with
    probability 0.954; 19 or fewer of 24 has probability 0.5 %. 24 trials cannot bound the rate
    from above, so the mean (error/sigma)^2 is kept above chi-square's 0.001 quantile."""
    out = ss.run_trials({"duration": 20.0, "rate": 50.0, **params}, np.random.default_rng(8),
                        24)
    assert not np.isnan(out["accepted"]).any()
    assert np.all(_coverage(out, 2.0) >= 20 / 24)
    for q in ("dpx", "dgx", "dgy", "dz"):
        check_not_inflated(None, q, float(np.sum((out[f"{q}_error"] / out[f"{q}_sigma"]) ** 2)),
                           24)
    assert np.mean(out["within_spec"]) == 1.0
    assert np.all(out["aim_error"] < 0.1)
    assert np.all(out["los_rms_ratio"] <= 0.1)


@pytest.mark.slow
@pytest.mark.parametrize(("i", "mount"), list(enumerate(kin.MOUNTS)))
@pytest.mark.parametrize(("j", "sampling"), list(enumerate(sim.GYRO_SAMPLINGS)))
@pytest.mark.parametrize(("k", "offset"), list(enumerate([0.0, 300.0])))
def test_acceptance_variants(i, mount, j, sampling, k, offset, figures):
    """Acceptance at the defaults of run_trials, TRIALS trials per variant (256 took about
    4 min each).

    Each combination within max(5 %, 0.01 deg) in at least 99 % of the trials (not significantly
    fewer: one-sided binomial test at 0.001), within 2 sigma in the binomial band of 95.45 % at
    TRIALS trials, and its mean (error/sigma)^2 not below chi-square's 0.001 quantile (sigma not
    inflated), and within 3 sigma not significantly less often than 99.73 %. Pooled over the
    four combinations the fraction within 2 sigma is 0.954; the errors
    of delta_px, delta_gx and delta_gy correlate at 0.87-0.94, so the 4 x TRIALS values count as
    about 2 x TRIALS independent ones: the pooled share in the band at 2 x TRIALS.
    """
    out = ss.run_trials({"mount": mount, "gyro_sampling": sampling, "target_offset": offset},
                        np.random.default_rng(20130417 + 4 * i + 2 * j + k), TRIALS)
    assert not np.isnan(out["accepted"]).any()
    names = ("dpx", "dgx", "dgy", "dz")
    spec = np.array([np.abs(out[f"{q}_error"]) <= np.maximum(
        0.05 * np.abs(out[f"{q}_true"]), ss.SPEC_FLOOR) for q in names])
    variant = slug(mount, sampling, f"offset{offset:g}")
    two, three = _coverage(out, 2.0), _coverage(out, 3.0)
    for q, share3 in zip(names, three, strict=True):
        check_rate(figures, f"{variant}.{q}.within_3sigma", round(share3 * TRIALS), TRIALS,
                   at_least=0.9973)
    for q, within_spec, share in zip(names, spec.sum(axis=1), two, strict=True):
        check_rate(figures, f"{variant}.{q}.within_spec", int(within_spec), TRIALS,
                   at_least=0.99)
        check_coverage(figures, f"{variant}.{q}.within_2sigma", round(share * TRIALS), TRIALS)
        check_not_inflated(figures, f"{variant}.{q}.mean_z2",
                           float(np.sum((out[f"{q}_error"] / out[f"{q}_sigma"]) ** 2)), TRIALS)
    check_coverage(figures, f"{variant}.pooled_within_2sigma", round(two.mean() * 2 * TRIALS),
                   2 * TRIALS)
